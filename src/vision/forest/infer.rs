//! Running the body forest on a segmented depth image: every sampled mouse pixel goes down
//! every tree, each leaf votes for each joint it knows (the pixel's 3D point plus the leaf's
//! mean offset), weighted by how many of the leaf's samples were near the joint and how
//! tightly their offsets agreed, and each joint is found as the densest mode of its votes: the
//! mean of the confident votes refined by mean-shift, started also from the strongest votes so
//! a multi-modal vote cloud settles on its main mode rather than between modes.
//!
//! The tail tip then moves to the far end of the segmented tail ([`TailEnd`]): few training
//! pixels lie on the thin tail, so its votes are the loosest of all, while the end of the
//! segmented tail is where the tip is, whenever the tail was segmented to its end.
//!
//! Buffers live in the estimator and are reused, so estimating a frame allocates nothing once
//! the first frame has sized them.

use super::depth::{BODY_JOINTS, DepthFeature, DepthImage, JointLeaf};
use super::simd::{self, Kernel, PixelLanes};
use super::{Forest, PackedTree, Traversal, Tree};
use crate::core::geometry::Intrinsics;
use crate::core::skeleton::Joint;
use nalgebra::{Point2, Point3, Vector3};
use std::collections::VecDeque;
use wide::f32x8;

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

/// A joint's score is the share of its vote weight within this distance of its estimate.
pub const SCORE_RADIUS_MM: f32 = 12.0;

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
    /// A vote's weight is its leaf's share of samples near the joint divided by its spread
    /// plus this (mm^2): tight leaves count more, and no spread near zero dominates.
    pub spread_prior_mm2: f32,
    /// Move the tail tip to the far end of the segmented tail, when the votes put it on the
    /// tail near that end ([`TailEnd`]).
    pub follow_tail: bool,
}

impl Default for VoteSettings {
    fn default() -> Self {
        Self {
            max_spread_mm2: 100.0,
            bandwidth_mm: 3.0,
            iterations: 32,
            spread_prior_mm2: 100.0,
            follow_tail: true,
        }
    }
}

/// The body forest ready to run.
#[derive(Clone, Debug)]
pub struct BodyEstimator {
    /// The trees (private: the router holds them packed, and the two must agree).
    forest: Forest<DepthFeature, JointLeaf>,
    pub settings: VoteSettings,
    /// Per joint: the confident votes, and the others (used only when a joint has no
    /// confident vote).
    confident: Vec<VoteCloud>,
    doubtful: Vec<VoteCloud>,
    /// Each pixel's 3D point (camera frame).
    points: Vec<Vector3<f32>>,
    router: Router,
    tail_end: TailEnd,
}

/// Runs pixels down the trees: the trees in their packed form, and buffers kept between
/// frames.
#[derive(Clone, Debug)]
struct Router {
    trees: Vec<PackedTree<DepthFeature>>,
    kernel: Kernel,
    traversal: Traversal,
    lanes: PixelLanes,
    leaves: Vec<u32>,
}

impl Router {
    /// Sends every pixel down every tree of `forest` (whose packed form this router holds)
    /// and hands each tree with the leaf index of each pixel to `visit`.
    fn route<'f>(
        &mut self,
        forest: &'f Forest<DepthFeature, JointLeaf>,
        image: &DepthImage,
        pixels: &[Pixel],
        mut visit: impl FnMut(&'f Tree<DepthFeature, JointLeaf>, &[u32]),
    ) {
        self.lanes.clear();
        for px in pixels {
            self.lanes.push(px.x, px.y, px.depth);
        }
        for (tree, packed) in forest.trees.iter().zip(&self.trees) {
            simd::leaf_indices(
                self.kernel,
                packed,
                image,
                &self.lanes,
                &mut self.traversal,
                &mut self.leaves,
            );
            visit(tree, &self.leaves);
        }
    }
}

impl BodyEstimator {
    pub fn new(forest: Forest<DepthFeature, JointLeaf>, settings: VoteSettings) -> Self {
        let router = Router {
            trees: forest.trees.iter().map(Tree::packed).collect(),
            kernel: Kernel::detect(),
            traversal: Traversal::default(),
            lanes: PixelLanes::default(),
            leaves: Vec::new(),
        };
        Self {
            forest,
            settings,
            confident: vec![VoteCloud::default(); BODY_JOINTS],
            doubtful: vec![VoteCloud::default(); BODY_JOINTS],
            points: Vec::new(),
            router,
            tail_end: TailEnd::default(),
        }
    }

    /// The traversal code in use: AVX2 where the processor has it (see [`simd`]).
    pub fn kernel(&self) -> Kernel {
        self.router.kernel
    }

    /// Traverses with `kernel` from now on (benchmarks compare them; [`Kernel::Avx2`] only on a
    /// processor that has it, or it is ignored).
    pub fn set_kernel(&mut self, kernel: Kernel) {
        if kernel == Kernel::Portable || Kernel::detect() == kernel {
            self.router.kernel = kernel;
        }
    }

    /// The leaf each pixel reaches in each tree, without voting (for benchmarks): `visit` gets
    /// each tree's leaf indices in turn.
    pub fn leaves(&mut self, image: &DepthImage, pixels: &[Pixel], mut visit: impl FnMut(&[u32])) {
        self.router
            .route(&self.forest, image, pixels, |_, leaves| visit(leaves));
    }

    /// Runs the forest on `pixels` of `image` and returns each joint's estimate (camera frame),
    /// `None` for a joint no leaf voted for.
    pub fn estimate(
        &mut self,
        image: &DepthImage,
        pixels: &[Pixel],
        intrinsics: &Intrinsics,
    ) -> [Option<JointGuess>; BODY_JOINTS] {
        for cloud in self.confident.iter_mut().chain(&mut self.doubtful) {
            cloud.clear();
        }
        self.points.clear();
        self.points.extend(pixels.iter().map(|px| {
            let p = intrinsics.unproject(&Point2::new(f64::from(px.x), f64::from(px.y)), f64::from(px.depth));
            Vector3::new(p.x as f32, p.y as f32, p.z as f32)
        }));
        let VoteSettings {
            max_spread_mm2: max_spread,
            spread_prior_mm2: prior,
            ..
        } = self.settings;
        let (points, confident, doubtful) = (&self.points, &mut self.confident, &mut self.doubtful);
        self.router.route(&self.forest, image, pixels, |tree, leaves| {
            for (p, &leaf) in points.iter().zip(leaves) {
                for (j, v) in tree.leaves[leaf as usize].iter().enumerate() {
                    if v.weight > 0.0 {
                        let cloud = if v.spread <= max_spread {
                            &mut confident[j]
                        } else {
                            &mut doubtful[j]
                        };
                        cloud.push(p + Vector3::from(v.offset), v.weight / (v.spread + prior));
                    }
                }
            }
        });
        let mut guesses: [Option<JointGuess>; BODY_JOINTS] = std::array::from_fn(|j| self.aggregate(j));
        if self.settings.follow_tail
            && let (Some(base), Some(tip)) = (guesses[TAIL_BASE], &mut guesses[TAIL_TIP])
            && let Some(end) = self.tail_end.find(image, intrinsics, base.position_mm, tip.position_mm)
        {
            tip.position_mm = end;
        }
        guesses
    }

    fn aggregate(&self, joint: usize) -> Option<JointGuess> {
        let votes = if self.confident[joint].is_empty() {
            &self.doubtful[joint]
        } else {
            &self.confident[joint]
        };
        let [x, y, z, total] = votes.sum(|x, y, z, w| [w * x, w * y, w * z, w]);
        if votes.is_empty() || total <= 0.0 {
            return None;
        }
        let mean = Vector3::new(x, y, z) / total;
        let h2 = self.settings.bandwidth_mm * self.settings.bandwidth_mm;
        let shift = |start: Vector3<f32>| -> Vector3<f32> {
            let mut at = start;
            for _ in 0..self.settings.iterations {
                let (acc, w) = votes.kernel_sums(&at, h2);
                if w <= 1e-12 {
                    break;
                }
                let next = acc / w;
                let moved = (next - at).norm_squared();
                at = next;
                if moved < 0.01 {
                    break;
                }
            }
            at
        };
        // Seeds: the mean and the three heaviest votes.
        let mut seeds = [mean; 4];
        let mut heaviest: [(f32, usize); 3] = [(-1.0, 0); 3];
        for (i, &w) in votes.w.iter().enumerate() {
            if w > heaviest[2].0 {
                heaviest[2] = (w, i);
                heaviest.sort_by(|a, b| b.0.total_cmp(&a.0));
            }
        }
        for (k, (w, i)) in heaviest.iter().enumerate() {
            if *w > 0.0 {
                seeds[k + 1] = votes.point(*i);
            }
        }
        let mut best = (f32::NEG_INFINITY, mean);
        for seed in seeds {
            let mode = shift(seed);
            let density = votes.kernel_sums(&mode, h2).1;
            if density > best.0 {
                best = (density, mode);
            }
        }
        // Score: the share of the weight within a fixed radius of the mode.
        let (m, r2) = (best.1, SCORE_RADIUS_MM * SCORE_RADIUS_MM);
        let [near, ..] = votes.sum(|x, y, z, w| {
            let d2 = (x - m.x) * (x - m.x) + (y - m.y) * (y - m.y) + (z - m.z) * (z - m.z);
            [if d2 <= r2 { w } else { 0.0 }, 0.0, 0.0, 0.0]
        });
        Some(JointGuess {
            position_mm: best.1,
            score: (near / total).clamp(0.0, 1.0),
        })
    }
}

/// Where the tail base and the tail tip sit among the main-body joints.
const TAIL_BASE: usize = Joint::TailBase as usize;
const TAIL_TIP: usize = Joint::TailTip as usize;
const _: () = assert!(matches!(Joint::MAIN_BODY[TAIL_BASE], Joint::TailBase));
const _: () = assert!(matches!(Joint::MAIN_BODY[TAIL_TIP], Joint::TailTip));

/// How far (mm) the tail tip may move from the votes' estimate to the end of the segmented tail.
const TAIL_END_REACH_MM: f32 = 20.0;
/// The tail tip moves only when the votes put it within this distance (mm) of a segmented
/// pixel: an estimate off the mask means the tail's last part was lost in the noise (as a
/// time-of-flight camera loses it), and then the votes know better than the mask where it ends.
const TAIL_ON_MASK_MM: f32 = 3.0;

/// Finds the far end of the segmented tail: of the mouse's pixels near the votes' tail tip, the
/// one furthest from the tail base along the mouse (8-connected steps over its pixels, so a
/// curled tail is followed rather than cut across). Buffers are kept between frames.
#[derive(Clone, Debug, Default)]
struct TailEnd {
    /// Per pixel of the region: steps from the pixel nearest the tail base, `u32::MAX` when not
    /// reached.
    steps: Vec<u32>,
    queue: VecDeque<u32>,
}

impl TailEnd {
    /// The 3D point (camera frame) of the tail's far end, or `None` when the tip should stay
    /// where the votes put it: no mouse pixel within [`TAIL_END_REACH_MM`] of it, or none
    /// within [`TAIL_ON_MASK_MM`].
    fn find(
        &mut self,
        image: &DepthImage,
        intrinsics: &Intrinsics,
        base: Vector3<f32>,
        tip: Vector3<f32>,
    ) -> Option<Vector3<f32>> {
        let r = image.region;
        let (w, h) = (r.width as usize, r.height as usize);
        let point = |k: usize, d: f32| -> Vector3<f32> {
            let pixel = Point2::new((r.x0 as usize + k % w) as f64, (r.y0 as usize + k / w) as f64);
            intrinsics.unproject(&pixel, f64::from(d)).coords.cast()
        };
        let b = intrinsics.project(&Point3::from(base.cast::<f64>()))?;
        let (bx, by) = (b.x - f64::from(r.x0), b.y - f64::from(r.y0));
        let from_base = |k: usize| ((k % w) as f64 - bx).powi(2) + ((k / w) as f64 - by).powi(2);
        let (start, _) = image
            .on_mouse()
            .min_by(|(a, _), (b, _)| from_base(*a).total_cmp(&from_base(*b)))?;
        self.steps.clear();
        self.steps.resize(w * h, u32::MAX);
        self.queue.clear();
        self.steps[start] = 0;
        self.queue.push_back(start as u32);
        // The furthest pixel within reach of the tip (steps, index), and how near the tip the
        // nearest pixel lies.
        let mut end: Option<(u32, usize)> = None;
        let mut nearest = f32::INFINITY;
        while let Some(k) = self.queue.pop_front() {
            let k = k as usize;
            let Some(d) = image.mouse_depth(k) else { continue };
            let off = (point(k, d) - tip).norm();
            nearest = nearest.min(off);
            let steps = self.steps[k];
            if off <= TAIL_END_REACH_MM && end.is_none_or(|(s, _)| steps > s) {
                end = Some((steps, k));
            }
            let (x, y) = (k % w, k / w);
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    let n = ny * w + nx;
                    if self.steps[n] == u32::MAX && image.mouse_depth(n).is_some() {
                        self.steps[n] = steps + 1;
                        self.queue.push_back(n as u32);
                    }
                }
            }
        }
        let (_, k) = end.filter(|_| nearest <= TAIL_ON_MASK_MM)?;
        Some(point(k, image.mouse_depth(k)?))
    }
}

/// One joint's votes, weighted points stored as separate coordinate arrays so that sums over
/// them run several votes per instruction.
#[derive(Clone, Debug, Default)]
struct VoteCloud {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    w: Vec<f32>,
}

impl VoteCloud {
    /// Votes summed side by side; a multiple of the vector width.
    const LANES: usize = 8;

    fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.w.clear();
    }

    fn is_empty(&self) -> bool {
        self.w.is_empty()
    }

    fn push(&mut self, p: Vector3<f32>, weight: f32) {
        self.x.push(p.x);
        self.y.push(p.y);
        self.z.push(p.z);
        self.w.push(weight);
    }

    fn point(&self, i: usize) -> Vector3<f32> {
        Vector3::new(self.x[i], self.y[i], self.z[i])
    }

    /// Sums `f(x, y, z, weight)` over the votes.
    fn sum(&self, f: impl Fn(f32, f32, f32, f32) -> [f32; 4]) -> [f32; 4] {
        let votes = self.x.iter().zip(&self.y).zip(self.z.iter().zip(&self.w));
        votes.fold([0.0; 4], |mut acc, ((&x, &y), (&z, &w))| {
            for (a, r) in acc.iter_mut().zip(f(x, y, z, w)) {
                *a += r;
            }
            acc
        })
    }

    /// The mean-shift sums at `at`: the kernel-weighted sum of the votes and the sum of the
    /// kernel weights (the density there). The hot loop of vote aggregation, so it runs
    /// [`Self::LANES`] votes per vector instruction, in that many interleaved partial sums (a
    /// fixed order, so the result is reproducible).
    fn kernel_sums(&self, at: &Vector3<f32>, h2: f32) -> (Vector3<f32>, f32) {
        const L: usize = VoteCloud::LANES;
        let scale = kernel_scale(h2);
        let n = self.w.len() / L * L;
        let lanes = |s: &[f32]| {
            let mut a = [0.0f32; L];
            a.copy_from_slice(s);
            f32x8::new(a)
        };
        let (ax, ay, az) = (f32x8::splat(at.x), f32x8::splat(at.y), f32x8::splat(at.z));
        let (one, zero, scale8) = (f32x8::splat(1.0), f32x8::splat(0.0), f32x8::splat(scale));
        let (mut sx, mut sy, mut sz, mut sw) = (zero, zero, zero, zero);
        let chunks = self.x[..n]
            .chunks_exact(L)
            .zip(self.y[..n].chunks_exact(L))
            .zip(self.z[..n].chunks_exact(L).zip(self.w[..n].chunks_exact(L)));
        for ((x, y), (z, w)) in chunks {
            let (x, y, z, w) = (lanes(x), lanes(y), lanes(z), lanes(w));
            let (dx, dy, dz) = (x - ax, y - ay, z - az);
            // `kernel`, eight at a time.
            let t = (one - (dx * dx + dy * dy + dz * dz) * scale8).fast_max(zero);
            let k = w * t * t;
            sx += k * x;
            sy += k * y;
            sz += k * z;
            sw += k;
        }
        let (mut x, mut y, mut z, mut w) = (sx.reduce_add(), sy.reduce_add(), sz.reduce_add(), sw.reduce_add());
        for i in n..self.w.len() {
            let (dx, dy, dz) = (self.x[i] - at.x, self.y[i] - at.y, self.z[i] - at.z);
            let k = self.w[i] * kernel(dx * dx + dy * dy + dz * dz, scale);
            x += k * self.x[i];
            y += k * self.y[i];
            z += k * self.z[i];
            w += k;
        }
        (Vector3::new(x, y, z), w)
    }
}

/// The mean-shift kernel at squared distance `d2`, given `scale` = [`kernel_scale`] of the
/// squared bandwidth `h2`: the biweight kernel `(1 - d2 / 7h2)^2`, whose spread matches a
/// Gaussian of standard deviation `h` and which vanishes beyond `sqrt(7) h`. It costs no `exp`
/// (a quarter of the pipeline's time with the Gaussian) and gives the same errors.
#[inline]
fn kernel(d2: f32, scale: f32) -> f32 {
    let t = 1.0 - d2 * scale;
    let t = if t > 0.0 { t } else { 0.0 };
    t * t
}

/// The factor of the squared distance in [`kernel`] for squared bandwidth `h2`.
fn kernel_scale(h2: f32) -> f32 {
    1.0 / (7.0 * h2)
}

/// Up to `budget` mouse pixels of `image` on a regular grid (every k-th pixel in both
/// directions), written into `out`.
pub fn sample_pixels(image: &DepthImage, budget: usize, out: &mut Vec<Pixel>) {
    out.clear();
    let on_mouse = image.on_mouse().count();
    let mut step = 1usize;
    while on_mouse / (step * step) > budget.max(1) {
        step += 1;
    }
    let r = image.region;
    for y in (0..r.height as usize).step_by(step) {
        for x in (0..r.width as usize).step_by(step) {
            if let Some(d) = image.mouse_depth(y * r.width as usize + x) {
                out.push(Pixel {
                    x: (r.x0 as usize + x) as f32,
                    y: (r.y0 as usize + y) as f32,
                    depth: d,
                });
            }
        }
    }
}
