//! Depth-difference features and the training sets built from depth images: the paper's
//! `phi(x) = d(x + u / d(x)) - d(x)`, with the offset `u` scaled by the pixel's own depth so the
//! same feature means the same thing at any distance, and probes that leave the mouse or the
//! image reading a large constant.
//!
//! Also the regression objective of the body forest: per joint, the offsets from each pixel's
//! 3D point to the joint, counted only for pixels within the joint's radius (the paper's
//! epsilon), with leaves that keep the mean offset and the spread of those offsets.

use super::discriminative::ErrorScope;
use super::{Objective, SplitSpace, uniform_thresholds};
use crate::core::image::Region;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// What a probe reads outside the mouse or the image, millimetres: beyond any 16-bit depth
/// reading, so that a mouse at any distance from the camera is on the mouse, and a probe off
/// it always gives a feature value far above any value on it. (It was once 1 m, which lost
/// mice seen from 1 m or more and confused probes off the mouse with probes on it beyond
/// 75 cm; models trained then route every pixel nearer than that exactly as now.)
pub const BACKGROUND_MM: f32 = 100_000.0;
/// A feature value above this means the probe left the mouse: no part of a mouse stands this
/// high (mm) above another.
const OFF_MOUSE_MM: f32 = 250.0;
/// The threshold of the test that separates probes off the mouse from probes on it.
const OFF_MOUSE_SPLIT_MM: f32 = 200.0;
/// Probe offsets reach this far at 1 m (in pixel-millimetres: pixels at a depth of 1 mm).
pub const MAX_OFFSET: f32 = 60.0 * 600.0;
/// The number of main-body joints the body forest estimates.
pub const BODY_JOINTS: usize = 12;

/// A probe offset `u` in pixel-millimetres: at depth `d` the probe lands `u / d` pixels away.
pub type DepthFeature = [f32; 2];

/// The mouse's region of one depth image: depth in mm on the mouse, [`BACKGROUND_MM`]
/// elsewhere, in the floats the probes return (whole millimetres in 16 bits would halve the
/// image's cache footprint, but converting on every probe measured 1.5 times slower).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    pub region: Region,
    pub depth: Vec<f32>,
}

impl DepthImage {
    /// Builds the image from a depth crop and its foreground mask (same size as `region`).
    pub fn from_mask(region: Region, depth: &[u16], mask: &[bool]) -> Self {
        let depth = depth
            .iter()
            .zip(mask)
            .map(|(&d, &m)| if m && d > 0 { f32::from(d) } else { BACKGROUND_MM })
            .collect();
        Self { region, depth }
    }

    /// The depth (mm) of the pixel at index `k` of the region (row-major), when it is on the
    /// mouse.
    #[inline]
    pub fn mouse_depth(&self, k: usize) -> Option<f32> {
        self.depth.get(k).copied().filter(|&d| d < BACKGROUND_MM)
    }

    /// The mouse's pixels: index in the region (row-major) and depth in mm.
    pub fn on_mouse(&self) -> impl Iterator<Item = (usize, f32)> + '_ {
        (0..self.depth.len()).filter_map(|k| self.mouse_depth(k).map(|d| (k, d)))
    }

    /// The depth at a full-image pixel position (the pixel that contains it),
    /// [`BACKGROUND_MM`] outside.
    #[inline]
    pub fn probe(&self, x: f32, y: f32) -> f32 {
        // Relative to the region's corner, exactly (whole-number origin, and the difference is
        // never finer than x's own precision); a negative or NaN position fails `>= 0`.
        let (rx, ry) = (x - self.region.x0 as f32, y - self.region.y0 as f32);
        if !(rx >= 0.0 && ry >= 0.0) {
            return BACKGROUND_MM;
        }
        let (xi, yi) = (rx as u32, ry as u32);
        if xi >= self.region.width || yi >= self.region.height {
            return BACKGROUND_MM;
        }
        self.depth[yi as usize * self.region.width as usize + xi as usize]
    }

    /// The value of feature `u` at pixel `(x, y)` with depth `d`.
    #[inline]
    pub fn feature(&self, x: f32, y: f32, d: f32, u: &DepthFeature) -> f32 {
        self.feature_scaled(x, y, d, 1.0 / d, u)
    }

    /// [`Self::feature`] given `inv = 1 / d` already (the same value, bit for bit).
    #[inline]
    pub fn feature_scaled(&self, x: f32, y: f32, d: f32, inv: f32, u: &DepthFeature) -> f32 {
        self.probe(x + u[0] * inv, y + u[1] * inv) - d
    }
}

/// Training pixels: where each is and which image it is in.
#[derive(Clone, Debug, Default)]
pub struct PixelSet {
    pub images: Vec<DepthImage>,
    pub image: Vec<u32>,
    /// Full-image pixel centres.
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub depth: Vec<f32>,
}

impl PixelSet {
    pub fn len(&self) -> usize {
        self.image.len()
    }

    pub fn is_empty(&self) -> bool {
        self.image.is_empty()
    }
}

/// Random depth-difference tests over a pixel set.
#[derive(Clone, Copy, Debug)]
pub struct DepthSpace<'a> {
    pub pixels: &'a PixelSet,
    /// Thresholds tried per feature.
    pub thresholds: usize,
}

/// A random probe offset: uniform direction, radius uniform up to [`MAX_OFFSET`] (so near
/// probes are as likely as far ones).
pub fn random_feature(rng: &mut impl Rng) -> DepthFeature {
    let angle = rng.gen_range(0.0..std::f32::consts::TAU);
    let r = rng.gen_range(0.0..MAX_OFFSET);
    [r * angle.cos(), r * angle.sin()]
}

impl SplitSpace for DepthSpace<'_> {
    type Feature = DepthFeature;

    #[inline]
    fn value(&self, sample: u32, u: &DepthFeature) -> f32 {
        let s = sample as usize;
        let p = self.pixels;
        p.images[p.image[s] as usize].feature(p.x[s], p.y[s], p.depth[s], u)
    }

    /// `m` features, each with thresholds drawn uniformly over the range its probes on the
    /// mouse take among the node's samples, plus one that separates probes off the mouse.
    fn candidates(
        &self,
        _depth: u32,
        samples: &[u32],
        m: usize,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Vec<(DepthFeature, Vec<f32>)> {
        // The range is estimated on an evenly spread subset of at most 256 samples.
        let stride = samples.len().div_ceil(256).max(1);
        (0..m)
            .map(|_| {
                let u = random_feature(rng);
                let (mut lo, mut hi, mut off_mouse) = (f32::INFINITY, f32::NEG_INFINITY, false);
                for &s in samples.iter().step_by(stride) {
                    let v = self.value(s, &u);
                    if v > OFF_MOUSE_MM {
                        off_mouse = true;
                    } else {
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
                let mut t = if lo < hi {
                    uniform_thresholds(lo, hi, self.thresholds.saturating_sub(1).max(1), rng)
                } else {
                    Vec::new()
                };
                if off_mouse {
                    t.push(OFF_MOUSE_SPLIT_MM);
                }
                if t.is_empty() {
                    t.push(0.0);
                }
                (u, t)
            })
            .collect()
    }
}

/// One joint's estimate in a leaf.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointVote {
    /// Mean offset from the pixel's 3D point to the joint (camera frame, mm).
    pub offset: [f32; 3],
    /// Fraction of the leaf's samples that were within the joint's radius: 0 means the leaf
    /// has no estimate for the joint.
    pub weight: f32,
    /// Largest eigenvalue of the offsets' covariance (mm^2): the vote's spread.
    pub spread: f32,
}

/// A body-forest leaf: one vote per main-body joint.
pub type JointLeaf = [JointVote; BODY_JOINTS];

/// Regression targets of a pixel set: offsets to each joint and which joints are near.
#[derive(Clone, Debug, Default)]
pub struct JointTargets {
    pub offsets: Vec<[[f32; 3]; BODY_JOINTS]>,
    /// Bit `j` set when the pixel is within joint `j`'s radius.
    pub near: Vec<u16>,
}

/// The body forest's objective over [`JointTargets`].
#[derive(Clone, Copy, Debug)]
pub struct JointObjective<'a> {
    pub targets: &'a JointTargets,
    /// The joints a pixel's error sums (discriminative training's E; training ignores it).
    pub scope: ErrorScope,
}

/// Per joint: count, sum of offsets (3), sum of squared norms; then the sample count.
const STATS: usize = BODY_JOINTS * 5 + 1;

impl Objective for JointObjective<'_> {
    type Stats = [f64; STATS];
    type Leaf = JointLeaf;

    fn empty_stats(&self) -> Self::Stats {
        [0.0; STATS]
    }

    #[inline]
    fn add(&self, stats: &mut Self::Stats, sample: u32) {
        let s = sample as usize;
        stats[STATS - 1] += 1.0;
        let near = self.targets.near[s];
        if near == 0 {
            return;
        }
        let offsets = &self.targets.offsets[s];
        for (j, o) in offsets.iter().enumerate() {
            if near & (1 << j) != 0 {
                let b = j * 5;
                let (x, y, z) = (f64::from(o[0]), f64::from(o[1]), f64::from(o[2]));
                stats[b] += 1.0;
                stats[b + 1] += x;
                stats[b + 2] += y;
                stats[b + 3] += z;
                stats[b + 4] += x * x + y * y + z * z;
            }
        }
    }

    fn merge(&self, a: &mut Self::Stats, b: &Self::Stats) {
        for (x, y) in a.iter_mut().zip(b) {
            *x += y;
        }
    }

    fn minus(&self, a: &Self::Stats, b: &Self::Stats) -> Self::Stats {
        std::array::from_fn(|i| a[i] - b[i])
    }

    fn count(&self, stats: &Self::Stats) -> f64 {
        stats[STATS - 1]
    }

    /// The summed squared deviation of each joint's near offsets from their mean, per sample
    /// (the paper's compactness E with squared distances, so candidate splits can be scored
    /// from running sums).
    fn impurity(&self, stats: &Self::Stats) -> f64 {
        let n = stats[STATS - 1];
        if n <= 0.0 {
            return 0.0;
        }
        let mut e = 0.0;
        for j in 0..BODY_JOINTS {
            let b = j * 5;
            let c = stats[b];
            if c > 0.0 {
                let mean_sq = (stats[b + 1].powi(2) + stats[b + 2].powi(2) + stats[b + 3].powi(2)) / c;
                e += (stats[b + 4] - mean_sq).max(0.0);
            }
        }
        e / n
    }

    fn leaf(&self, samples: &[u32]) -> JointLeaf {
        self.refit(&[JointVote::default(); BODY_JOINTS], samples)
    }

    fn refit(&self, old: &JointLeaf, samples: &[u32]) -> JointLeaf {
        let mut out = *old;
        if samples.is_empty() {
            return out;
        }
        for (j, vote) in out.iter_mut().enumerate() {
            let near: Vec<&[f32; 3]> = samples
                .iter()
                .filter(|&&s| self.targets.near[s as usize] & (1 << j) != 0)
                .map(|&s| &self.targets.offsets[s as usize][j])
                .collect();
            if near.is_empty() {
                // The new samples say nothing about this joint here.
                if old[j].weight > 0.0 {
                    continue;
                }
                *vote = JointVote::default();
                continue;
            }
            let n = near.len() as f32;
            let mean = near
                .iter()
                .fold(Vector3::zeros(), |acc: Vector3<f32>, o| acc + Vector3::from(**o))
                / n;
            let cov = near.iter().fold(Matrix3::zeros(), |acc: Matrix3<f32>, o| {
                let d = Vector3::from(**o) - mean;
                acc + d * d.transpose()
            }) / n;
            let spread = SymmetricEigen::new(cov).eigenvalues.max();
            *vote = JointVote {
                offset: [mean.x, mean.y, mean.z],
                weight: n / samples.len() as f32,
                spread,
            };
        }
        out
    }

    /// The summed error of the leaf's estimates for the joints [`Self::scope`] counts; a joint
    /// the leaf has no estimate for counts as if the pixel itself were the estimate.
    fn error(&self, leaf: &JointLeaf, sample: u32) -> f64 {
        let s = sample as usize;
        let counted = match self.scope {
            ErrorScope::AllJoints => u16::MAX,
            ErrorScope::NearJoints => self.targets.near[s],
        };
        let mut e = 0.0;
        for (j, o) in self.targets.offsets[s].iter().enumerate() {
            if counted & (1 << j) == 0 {
                continue;
            }
            let v = &leaf[j];
            let d = if v.weight > 0.0 {
                [o[0] - v.offset[0], o[1] - v.offset[1], o[2] - v.offset[2]]
            } else {
                *o
            };
            e += f64::from((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt());
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn probes_read_the_pixel_that_contains_them_and_the_background_outside() {
        let region = Region {
            x0: 30,
            y0: 20,
            width: 7,
            height: 5,
        };
        let image = DepthImage {
            region,
            depth: (0..35).map(|i| 500.0 + i as f32).collect(),
        };
        // By whole pixels, with wide integers: the pixel that contains the position, or none.
        let reference = |x: f32, y: f32| -> f32 {
            let (xi, yi) = (x.floor() as i64 - 30, y.floor() as i64 - 20);
            if (0..7).contains(&xi) && (0..5).contains(&yi) {
                500.0 + (yi * 7 + xi) as f32
            } else {
                BACKGROUND_MM
            }
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let edges = [
            -1.0, -0.5, -0.0, 0.0, 19.999, 20.0, 29.9999, 30.0, 36.999, 37.0, 24.99, 25.0, 1e9,
        ];
        for &x in &edges {
            for &y in &edges {
                assert_eq!(image.probe(x, y), reference(x, y), "at ({x}, {y})");
            }
        }
        for _ in 0..10_000 {
            let (x, y) = (rng.gen_range(-5.0..45.0f32), rng.gen_range(-5.0..30.0f32));
            assert_eq!(image.probe(x, y), reference(x, y), "at ({x}, {y})");
        }
        assert_eq!(image.probe(f32::NAN, 22.0), BACKGROUND_MM);
    }
}
