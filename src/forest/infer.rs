//! Running the body forest on a segmented depth image: every sampled mouse pixel goes down
//! every tree, each leaf votes for each joint it knows (the pixel's 3D point plus the leaf's
//! mean offset), and each joint is found as the densest mode of its votes: the mean of the
//! confident votes refined by mean-shift, started also from the strongest votes so a
//! multi-modal vote cloud settles on its main mode rather than between modes.
//!
//! Buffers live in the estimator and are reused, so estimating a frame allocates nothing once
//! the first frame has sized them.

use super::Forest;
use super::depth::{BODY_JOINTS, DepthFeature, DepthImage, JointLeaf};
use crate::geometry::Intrinsics;
use nalgebra::{Point2, Vector3};

/// A mouse pixel to run through the forest: full-image position and depth (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pixel {
    pub x: f32,
    pub y: f32,
    pub depth: f32,
}

/// One joint's estimate in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointGuess {
    pub position_mm: Vector3<f32>,
    /// Fraction of the joint's vote weight near the chosen mode, in `[0, 1]`.
    pub score: f32,
}

/// Settings of vote aggregation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoteSettings {
    /// Votes whose leaf spread (largest eigenvalue, mm^2) exceeds this are low-confidence:
    /// used only when a joint has no confident vote.
    pub max_spread_mm2: f32,
    /// Mean-shift bandwidth, mm.
    pub bandwidth_mm: f32,
    /// Mean-shift iterations at most.
    pub iterations: usize,
}

impl Default for VoteSettings {
    fn default() -> Self {
        Self {
            max_spread_mm2: 200.0,
            bandwidth_mm: 6.0,
            iterations: 8,
        }
    }
}

/// The body forest ready to run.
#[derive(Clone, Debug)]
pub struct BodyEstimator {
    pub forest: Forest<DepthFeature, JointLeaf>,
    pub settings: VoteSettings,
    votes: Vec<Vec<(Vector3<f32>, f32, bool)>>,
    chosen: Vec<(Vector3<f32>, f32)>,
}

impl BodyEstimator {
    pub fn new(forest: Forest<DepthFeature, JointLeaf>, settings: VoteSettings) -> Self {
        Self {
            forest,
            settings,
            votes: vec![Vec::new(); BODY_JOINTS],
            chosen: Vec::new(),
        }
    }

    /// Runs the forest on `pixels` of `image` and returns each joint's estimate (camera frame),
    /// `None` for a joint no leaf voted for.
    pub fn estimate(
        &mut self,
        image: &DepthImage,
        pixels: &[Pixel],
        intrinsics: &Intrinsics,
    ) -> [Option<JointGuess>; BODY_JOINTS] {
        for v in &mut self.votes {
            v.clear();
        }
        let max_spread = self.settings.max_spread_mm2;
        for px in pixels {
            let p = intrinsics.unproject(&Point2::new(f64::from(px.x), f64::from(px.y)), f64::from(px.depth));
            let p = Vector3::new(p.x as f32, p.y as f32, p.z as f32);
            for tree in &self.forest.trees {
                let leaf = tree.leaf(|u| image.feature(px.x, px.y, px.depth, u));
                for (j, v) in leaf.iter().enumerate() {
                    if v.weight > 0.0 {
                        self.votes[j].push((p + Vector3::from(v.offset), v.weight, v.spread <= max_spread));
                    }
                }
            }
        }
        std::array::from_fn(|j| self.aggregate(j))
    }

    fn aggregate(&mut self, joint: usize) -> Option<JointGuess> {
        let votes = &self.votes[joint];
        let confident = votes.iter().any(|v| v.2);
        self.chosen.clear();
        self.chosen
            .extend(votes.iter().filter(|v| v.2 || !confident).map(|v| (v.0, v.1)));
        let chosen = &self.chosen;
        let total: f32 = chosen.iter().map(|v| v.1).sum();
        if chosen.is_empty() || total <= 0.0 {
            return None;
        }
        let mean = chosen.iter().fold(Vector3::zeros(), |a: Vector3<f32>, v| a + v.0 * v.1) / total;
        let h2 = self.settings.bandwidth_mm * self.settings.bandwidth_mm;
        let density =
            |x: &Vector3<f32>| -> f32 { chosen.iter().map(|v| v.1 * kernel((v.0 - x).norm_squared(), h2)).sum() };
        let shift = |start: Vector3<f32>| -> Vector3<f32> {
            let mut x = start;
            for _ in 0..self.settings.iterations {
                let (mut acc, mut w) = (Vector3::zeros(), 0.0f32);
                for v in chosen {
                    let k = v.1 * kernel((v.0 - x).norm_squared(), h2);
                    acc += v.0 * k;
                    w += k;
                }
                if w <= 1e-12 {
                    break;
                }
                let next = acc / w;
                let moved = (next - x).norm_squared();
                x = next;
                if moved < 0.01 {
                    break;
                }
            }
            x
        };
        // Seeds: the mean and the three heaviest votes.
        let mut seeds = [mean; 4];
        let mut heaviest: [(f32, usize); 3] = [(-1.0, 0); 3];
        for (i, v) in chosen.iter().enumerate() {
            if v.1 > heaviest[2].0 {
                heaviest[2] = (v.1, i);
                heaviest.sort_by(|a, b| b.0.total_cmp(&a.0));
            }
        }
        for (k, (w, i)) in heaviest.iter().enumerate() {
            if *w > 0.0 {
                seeds[k + 1] = chosen[*i].0;
            }
        }
        let mut best = (f32::NEG_INFINITY, mean);
        for seed in seeds {
            let mode = shift(seed);
            let d = density(&mode);
            if d > best.0 {
                best = (d, mode);
            }
        }
        // Score: the share of the weight within two bandwidths of the mode.
        let near: f32 = chosen
            .iter()
            .filter(|v| (v.0 - best.1).norm_squared() <= 4.0 * h2)
            .map(|v| v.1)
            .sum();
        Some(JointGuess {
            position_mm: best.1,
            score: (near / total).clamp(0.0, 1.0),
        })
    }
}

/// The mean-shift kernel at squared distance `d2` for squared bandwidth `h2`: the biweight
/// kernel `(1 - d2 / 7h2)^2`, whose spread matches a Gaussian of standard deviation `h` and
/// which vanishes beyond `sqrt(7) h`. It costs no `exp` (a quarter of the pipeline's time with
/// the Gaussian) and gives the same errors.
#[inline]
fn kernel(d2: f32, h2: f32) -> f32 {
    let t = 1.0 - d2 / (7.0 * h2);
    if t <= 0.0 { 0.0 } else { t * t }
}

/// Up to `budget` mouse pixels of `image` on a regular grid (every k-th pixel in both
/// directions), written into `out`.
pub fn sample_pixels(image: &DepthImage, budget: usize, out: &mut Vec<Pixel>) {
    out.clear();
    let on_mouse = image.depth.iter().filter(|&&d| d < super::depth::BACKGROUND_MM).count();
    let mut step = 1usize;
    while on_mouse / (step * step) > budget.max(1) {
        step += 1;
    }
    let r = image.region;
    for y in (0..r.height as usize).step_by(step) {
        for x in (0..r.width as usize).step_by(step) {
            let d = image.depth[y * r.width as usize + x];
            if d < super::depth::BACKGROUND_MM {
                out.push(Pixel {
                    x: (r.x0 as usize + x) as f32,
                    y: (r.y0 as usize + y) as f32,
                    depth: d,
                });
            }
        }
    }
}
