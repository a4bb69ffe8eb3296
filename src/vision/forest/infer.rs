//! Running the body forest on a segmented depth image: every sampled mouse pixel goes down
//! every tree, each leaf votes for each joint it knows (the pixel's 3D point plus the leaf's
//! mean offset), weighted by how many of the leaf's samples were near the joint and how
//! tightly their offsets agreed, and each joint is found as the densest mode of its votes: the
//! mean of the confident votes refined by mean-shift, started also from the strongest votes so
//! a multi-modal vote cloud settles on its main mode rather than between modes.
//!
//! The tail tip then moves to the far end of the segmented tail ([`TailEnd`]): few training
//! pixels lie on the thin tail, so its votes are the loosest of all, while the end of the
//! segmented tail is where the tip is, whenever the tail was segmented to its end. Under
//! either orientation ([`BodyEstimator::estimate_oriented`], what the pipeline runs), a joint
//! the votes put off the mouse ([`OFF_MOUSE_MM`] from every pixel of it) is not taken for a
//! seen one: the tail tip is then withdrawn (no tail seen there), any other joint scored low;
//! and the tail tip is withdrawn too where the mask near it is not thin as a tail is
//! ([`TailView::Unseen`]: the votes put it on the body's rim, as they do when no tail is seen).
//!
//! Buffers live in the estimator and are reused, so estimating a frame allocates nothing once
//! the first frame has sized them.

use super::depth::{BODY_JOINTS, DepthFeature, DepthImage, JointLeaf};
use super::leaf::{Located, SparseLeaves};
use super::simd::{self, Kernel, PixelLanes};
use super::{BadTree, Forest, PackedTree, Traversal, Tree, model};
use crate::core::geometry::Intrinsics;
use crate::core::skeleton::Joint;
use crate::vision::orientation;
use nalgebra::{Point2, Point3, Vector3};
use std::collections::VecDeque;
use std::sync::Arc;

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

/// The vote radius [`VoteSettings::max_spread_mm2`] is stated for (mm).
const SPREAD_RADIUS_MM: f32 = 25.0;

/// Settings of vote aggregation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoteSettings {
    /// Votes whose leaf spread (largest eigenvalue, mm^2) exceeds this are low-confidence:
    /// used only when a joint has no confident vote. The bound is for a joint whose votes come
    /// from within 25 mm of it (the paper's epsilon for most joints); each joint's bound is
    /// this scaled by the square of its own radius over 25 mm: the tail's leaves, which
    /// gather pixels from twice as far (50 mm), may spread twice as wide (four times the
    /// variance), the ears' (15 mm) three fifths as wide.
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

/// The body forest ready to run. Cloning it (one per worker) shares the trees: only the
/// buffers of a frame are its own.
#[derive(Clone, Debug)]
pub struct BodyEstimator {
    /// The trees as run time reads them, shared by every clone.
    trees: Arc<RunTrees>,
    pub settings: VoteSettings,
    /// Per joint: the confident votes, and the others (used only when a joint has no
    /// confident vote).
    confident: Vec<VoteCloud>,
    doubtful: Vec<VoteCloud>,
    /// Each pixel's 3D point (camera frame).
    points: Vec<Vector3<f32>>,
    /// The points of `points` not on a tail found as one (the body's long axis).
    body_points: Vec<Vector3<f32>>,
    /// Each pixel's leaf in the tree being read ([`SparseLeaves::locate`]).
    located: Vec<Located>,
    router: Router,
    tail_end: TailEnd,
    /// The mouse's surface points (camera frame) of the frame being judged ([`Self::judge_placement`]).
    surface: Vec<Vector3<f32>>,
}

/// The forest in the form run time reads, built once and shared by the workers: per tree its
/// split nodes packed ([`PackedTree`]) and its leaves' votes, only those with a weight (a
/// leaf of the bundled forest votes for 7.8 of the 12 joints on average), joint by joint in
/// joint order. The training form's nodes are not kept.
#[derive(Debug)]
struct RunTrees {
    trees: Vec<(PackedTree<DepthFeature>, SparseLeaves)>,
}

impl RunTrees {
    /// Converts `forest` tree by tree, each tree's training form dropped once converted.
    fn new(forest: Forest<DepthFeature, JointLeaf>) -> Result<Self, BadTree> {
        let trees = forest
            .trees
            .into_iter()
            .map(|tree| Self::tree(&tree))
            .collect::<Result<_, _>>()?;
        Ok(Self { trees })
    }

    fn tree(tree: &Tree<DepthFeature, JointLeaf>) -> Result<(PackedTree<DepthFeature>, SparseLeaves), BadTree> {
        Ok((tree.packed()?, SparseLeaves::from_leaves(&tree.leaves)))
    }
}

/// Runs pixels down the trees, with buffers kept between frames.
#[derive(Clone, Debug)]
struct Router {
    kernel: Kernel,
    traversal: Traversal,
    lanes: PixelLanes,
    leaves: Vec<u32>,
}

impl Router {
    /// Sends every pixel down every tree of `trees` and hands each tree's leaves with the
    /// leaf index of each pixel to `visit`.
    fn route<'f>(
        &mut self,
        trees: &'f RunTrees,
        image: &DepthImage,
        pixels: &[Pixel],
        mut visit: impl FnMut(&'f SparseLeaves, &[u32]),
    ) {
        self.lanes.clear();
        for px in pixels {
            self.lanes.push(px.x, px.y, px.depth);
        }
        for (packed, leaves) in &trees.trees {
            simd::leaf_indices(
                self.kernel,
                packed,
                image,
                &self.lanes,
                &mut self.traversal,
                &mut self.leaves,
            );
            visit(leaves, &self.leaves);
        }
    }
}

impl BodyEstimator {
    /// The estimator of `forest`.
    ///
    /// # Errors
    /// A tree of `forest` that cannot be walked ([`Tree::check`]), as a tree put together by
    /// hand may be (training never builds one).
    pub fn new(forest: Forest<DepthFeature, JointLeaf>, settings: VoteSettings) -> Result<Self, BadTree> {
        Ok(Self::with_trees(RunTrees::new(forest)?, settings))
    }

    /// The body forest of a model file, read straight into the form run time reads, tree by
    /// tree ([`model::load_body_trees`]): the same estimator as [`Self::new`] of the file's
    /// forest, without ever holding the file's decompressed trees or the training form.
    ///
    /// # Errors
    /// As [`model::load`].
    pub fn load(path: &std::path::Path, settings: VoteSettings) -> Result<Self, model::ModelError> {
        let (_, trees) = model::load_body_trees(path, |tree, leaves| Ok::<_, BadTree>((tree.packed()?, leaves)))?;
        // The reader checks every tree as `packed` does, so this error is not expected.
        let trees = trees
            .into_iter()
            .collect::<Result<_, _>>()
            .map_err(|e| model::ModelError::Corrupt {
                path: path.to_owned(),
                reason: e.to_string(),
            })?;
        Ok(Self::with_trees(RunTrees { trees }, settings))
    }

    fn with_trees(trees: RunTrees, settings: VoteSettings) -> Self {
        let router = Router {
            kernel: Kernel::detect(),
            traversal: Traversal::default(),
            lanes: PixelLanes::default(),
            leaves: Vec::new(),
        };
        Self {
            trees: Arc::new(trees),
            settings,
            confident: vec![VoteCloud::default(); BODY_JOINTS],
            doubtful: vec![VoteCloud::default(); BODY_JOINTS],
            points: Vec::new(),
            body_points: Vec::new(),
            located: Vec::new(),
            router,
            tail_end: TailEnd::default(),
            surface: Vec::new(),
        }
    }

    /// The traversal code in use: AVX2 where the processor has it (see [`simd`]).
    pub fn kernel(&self) -> Kernel {
        self.router.kernel
    }

    /// Traverses with `kernel` from now on (benchmarks compare them; a [`Kernel::Avx2`] comes
    /// only from [`Kernel::detect`] on a processor that has it).
    pub fn set_kernel(&mut self, kernel: Kernel) {
        self.router.kernel = kernel;
    }

    /// The leaf each pixel reaches in each tree, without voting (for benchmarks): `visit` gets
    /// each tree's leaf indices in turn.
    pub fn leaves(&mut self, image: &DepthImage, pixels: &[Pixel], mut visit: impl FnMut(&[u32])) {
        self.router.route(&self.trees, image, pixels, |_, leaves| visit(leaves));
    }

    /// Runs the forest on `pixels` of `image` and returns each joint's estimate (camera frame),
    /// `None` for a joint no leaf voted for.
    pub fn estimate(
        &mut self,
        image: &DepthImage,
        pixels: &[Pixel],
        intrinsics: &Intrinsics,
    ) -> [Option<JointGuess>; BODY_JOINTS] {
        let (mut guesses, _) = self.estimate_votes(image, pixels, intrinsics);
        if self.settings.follow_tail {
            self.follow_tail(image, intrinsics, &mut guesses);
        }
        guesses
    }

    /// Gathers the votes of `pixels` and finds each joint at their densest mode; also returns
    /// each joint's modes ([`Self::modes`]).
    fn estimate_votes(
        &mut self,
        image: &DepthImage,
        pixels: &[Pixel],
        intrinsics: &Intrinsics,
    ) -> ([Option<JointGuess>; BODY_JOINTS], [Option<Modes>; BODY_JOINTS]) {
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
        let bounds: [f32; BODY_JOINTS] = std::array::from_fn(|j| {
            let r = Joint::MAIN_BODY[j].vote_radius_mm() as f32 / SPREAD_RADIUS_MM;
            max_spread * r * r
        });
        let (points, confident, doubtful) = (&self.points, &mut self.confident, &mut self.doubtful);
        let located = &mut self.located;
        self.router.route(&self.trees, image, pixels, |tree, leaves| {
            // Each pixel's leaf lies anywhere in megabytes of leaves, and waiting for each in
            // turn was a third of this stage: they are all looked up first, loads that do
            // not wait for one another, and then read from the cache.
            located.clear();
            located.extend(leaves.iter().map(|&leaf| tree.locate(leaf)));
            for (p, &at) in points.iter().zip(located.iter()) {
                // Only the votes with a weight are kept, in joint order.
                for (j, v) in tree.votes(at) {
                    let cloud = if v.spread <= bounds[j] {
                        &mut confident[j]
                    } else {
                        &mut doubtful[j]
                    };
                    cloud.push(p + Vector3::from(v.offset), v.weight / (v.spread + prior));
                }
            }
        });
        let modes: [Option<Modes>; BODY_JOINTS] = std::array::from_fn(|j| self.modes(j));
        let guesses = std::array::from_fn(|j| {
            let (modes, total) = modes[j]?;
            let best = modes.iter().fold((Vector3::zeros(), f32::NEG_INFINITY), |best, m| {
                if m.1 > best.1 { *m } else { best }
            });
            Some(self.guess_at(j, best.0, total))
        });
        (guesses, modes)
    }

    /// The votes a joint is found from: its confident ones, or the others when it has none.
    fn cloud(&self, joint: usize) -> &VoteCloud {
        if self.confident[joint].is_empty() {
            &self.doubtful[joint]
        } else {
            &self.confident[joint]
        }
    }

    /// Mean-shift over `votes` from `start`: the mode it settles on and the density there.
    fn shift(&self, votes: &VoteCloud, start: Vector3<f32>) -> Mode {
        let h2 = self.settings.bandwidth_mm * self.settings.bandwidth_mm;
        let mut at = start;
        for _ in 0..self.settings.iterations {
            let (acc, w) = votes.kernel_sums(self.router.kernel, &at, h2);
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
        (at, votes.kernel_sums(self.router.kernel, &at, h2).1)
    }

    /// The modes mean-shift finds from the mean of a joint's votes and from its three
    /// heaviest votes, each with its density, and the votes' total weight; `None` without votes.
    fn modes(&self, joint: usize) -> Option<Modes> {
        let votes = self.cloud(joint);
        let [x, y, z, total] = votes.sum(|x, y, z, w| [w * x, w * y, w * z, w]);
        if votes.is_empty() || total <= 0.0 {
            return None;
        }
        let mean = Vector3::new(x, y, z) / total;
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
        Some((seeds.map(|seed| self.shift(votes, seed)), total))
    }

    /// The joint's estimate at `position`: scored by the share of its vote weight within
    /// [`SCORE_RADIUS_MM`].
    fn guess_at(&self, joint: usize, position: Vector3<f32>, total: f32) -> JointGuess {
        let (m, r2) = (position, SCORE_RADIUS_MM * SCORE_RADIUS_MM);
        let [near, ..] = self.cloud(joint).sum(|x, y, z, w| {
            let d2 = (x - m.x) * (x - m.x) + (y - m.y) * (y - m.y) + (z - m.z) * (z - m.z);
            [if d2 <= r2 { w } else { 0.0 }, 0.0, 0.0, 0.0]
        });
        JointGuess {
            position_mm: position,
            score: (near / total).clamp(0.0, 1.0),
        }
    }

    /// Like [`Self::estimate`], and the joints again under either orientation of the body: the
    /// long axis of the mouse seen along `up` (the world's up in the camera frame), and for
    /// each end of it the joints with the head at that end. A front joint (see
    /// [`orientation::end_of`]) takes the densest of its modes on the head's side of the
    /// centre, a rear joint on the other; where the votes have no mode on that side (the
    /// forest put all of them at the wrong end), the joint is the forest's estimate mirrored
    /// across the centre, scored by the votes near it. Last, the joints off the mouse are
    /// judged ([`judge_placement`]): a tail tip off it is `None`.
    ///
    /// `tail` marks the region's pixels left out of the body: a tail found as one
    /// (`vision::tail::find_tail`) and thin pieces of clutter joined to the mouse at a wall
    /// (`vision::tail::thin_pieces_at`); empty when there are none. They vote like every other
    /// pixel, but the long axis and its centre are the body's alone, as a long tail or a strand
    /// of bedding would swing them toward itself.
    pub fn estimate_oriented(
        &mut self,
        image: &DepthImage,
        pixels: &[Pixel],
        intrinsics: &Intrinsics,
        up: &Vector3<f32>,
        tail: &[bool],
    ) -> Oriented {
        let (raw, all_modes) = self.estimate_votes(image, pixels, intrinsics);
        let r = image.region;
        let on_tail = |px: &Pixel| {
            let (x, y) = (px.x as i64 - i64::from(r.x0), px.y as i64 - i64::from(r.y0));
            x >= 0
                && y >= 0
                && (x as u32) < r.width
                && tail
                    .get(y as usize * r.width as usize + x as usize)
                    .copied()
                    .unwrap_or(false)
        };
        self.body_points.clear();
        self.body_points.extend(
            pixels
                .iter()
                .zip(&self.points)
                .filter(|(px, _)| !on_tail(px))
                .map(|(_, p)| *p),
        );
        let body = if self.body_points.is_empty() {
            &self.points
        } else {
            &self.body_points
        };
        let (centre, axis) = long_axis(body, up);
        let side = |p: &Vector3<f32>| (p - centre).dot(&axis);
        let mut oriented = Oriented {
            raw,
            ahead: [raw; 2],
            axis,
            centre,
            votes: 0.0,
        };
        let (mut agree, mut weight) = (0.0f32, 0.0f32);
        for (j, joint) in Joint::MAIN_BODY.iter().enumerate() {
            let end = orientation::end_of(*joint);
            if end == 0.0 {
                continue;
            }
            let [along, w, ..] = self.cloud(j).sum(|x, y, z, w| {
                let s = side(&Vector3::new(x, y, z));
                [w * end * s.signum(), w, 0.0, 0.0]
            });
            agree += along / w.max(1e-12);
            weight += 1.0;
            let (Some((modes, total)), Some(forest)) = (all_modes[j], raw[j]) else {
                continue;
            };
            let mirrored = forest.position_mm - 2.0 * side(&forest.position_mm) * axis;
            let from_mirror = self.shift(self.cloud(j), mirrored);
            for (h, sign) in [1.0f32, -1.0].into_iter().enumerate() {
                let fits = |p: &Vector3<f32>| side(p) * end * sign > 0.0;
                let best = modes
                    .iter()
                    .chain(std::iter::once(&from_mirror))
                    .filter(|m| fits(&m.0))
                    .fold(None::<Mode>, |best, m| match best {
                        Some(b) if b.1 >= m.1 => Some(b),
                        _ => Some(*m),
                    });
                let position = match best {
                    Some((p, _)) => p,
                    None if fits(&forest.position_mm) => forest.position_mm,
                    None => mirrored,
                };
                oriented.ahead[h][j] = Some(self.guess_at(j, position, total));
            }
        }
        oriented.votes = if weight > 0.0 { agree / weight } else { 0.0 };
        if self.settings.follow_tail {
            for guesses in &mut oriented.ahead {
                if self.follow_tail(image, intrinsics, guesses) == TailView::Unseen {
                    guesses[TAIL_TIP] = None;
                }
            }
        }
        self.surface.clear();
        self.surface.extend(image.on_mouse().map(|(k, d)| {
            let r = image.region;
            let pixel = Point2::new(
                f64::from(r.x0) + (k % r.width as usize) as f64,
                f64::from(r.y0) + (k / r.width as usize) as f64,
            );
            intrinsics.unproject(&pixel, f64::from(d)).coords.cast::<f32>()
        }));
        for guesses in &mut oriented.ahead {
            judge_placement(&self.surface, guesses);
        }
        oriented
    }

    /// Moves the tail tip to the far end of the segmented tail ([`TailEnd`]), and says what
    /// the mask shows near the tip ([`TailView::Lost`] when there is no tip or base to judge).
    fn follow_tail(
        &mut self,
        image: &DepthImage,
        intrinsics: &Intrinsics,
        guesses: &mut [Option<JointGuess>; BODY_JOINTS],
    ) -> TailView {
        let (Some(base), Some(tip)) = (guesses[TAIL_BASE], &mut guesses[TAIL_TIP]) else {
            return TailView::Lost;
        };
        let view = self.tail_end.find(image, intrinsics, base.position_mm, tip.position_mm);
        if let TailView::End(end) = view {
            tip.position_mm = end;
        }
        view
    }
}

/// A joint further than this (mm) from every point of the mouse's surface is not placed by
/// what the camera saw. On real depth rigs the tail is often not seen at all (3-5 mm thick,
/// at about 1.9 mm a pixel and 2 mm of noise), yet the forest still votes for a tip behind the
/// body, on the floor or the wall. Joints inside the body lie within about 10 mm of its
/// surface.
pub const OFF_MOUSE_MM: f32 = 15.0;

/// The score, at most, of a joint other than the tail tip that lies off the mouse.
pub const OFF_MOUSE_SCORE: f32 = 0.05;

/// Withdraws what the evidence cannot place (see [`OFF_MOUSE_MM`]): the tail tip off the
/// mouse is not reported (no tail is seen there), and any other joint off it keeps its place
/// (the skeleton needs it) with a score of at most [`OFF_MOUSE_SCORE`]. `surface` holds the
/// mouse's 3D points in the frame of `guesses`; without any, nothing is judged.
fn judge_placement(surface: &[Vector3<f32>], guesses: &mut [Option<JointGuess>; BODY_JOINTS]) {
    if surface.is_empty() {
        return;
    }
    let reach2 = OFF_MOUSE_MM * OFF_MOUSE_MM;
    for (j, guess) in guesses.iter_mut().enumerate() {
        let Some(g) = guess else { continue };
        if surface.iter().any(|p| (p - g.position_mm).norm_squared() <= reach2) {
            continue;
        }
        if j == TAIL_TIP {
            *guess = None;
        } else {
            g.score = g.score.min(OFF_MOUSE_SCORE);
        }
    }
}

/// A mode of a joint's votes and the votes' density there.
type Mode = (Vector3<f32>, f32);

/// The modes mean-shift finds from a joint's four seeds, and the votes' total weight.
type Modes = ([Mode; 4], f32);

/// The joints of one frame under the forest alone and under either orientation (see
/// [`BodyEstimator::estimate_oriented`]), in the camera frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Oriented {
    /// The forest's own estimate, before the tail tip follows the tail.
    pub raw: [Option<JointGuess>; BODY_JOINTS],
    /// The joints with the head toward `+axis` (`[0]`) and toward `-axis` (`[1]`).
    pub ahead: [[Option<JointGuess>; BODY_JOINTS]; 2],
    /// The body's long axis across `up` (unit length, sign arbitrary) and its centre.
    pub axis: Vector3<f32>,
    pub centre: Vector3<f32>,
    /// The front and rear joints' votes: share of weight on the side that puts the head toward
    /// `+axis` less the share on the other (-1 to 1).
    pub votes: f32,
}

/// The centre of `points` and their long axis seen along `up`: the main direction of the
/// points projected on the plane across `up` (any unit vector across `up` for fewer than two
/// points).
fn long_axis(points: &[Vector3<f32>], up: &Vector3<f32>) -> (Vector3<f32>, Vector3<f32>) {
    let n = points.len().max(1) as f32;
    let centre = points.iter().sum::<Vector3<f32>>() / n;
    let flat = |p: &Vector3<f32>| {
        let d = p - centre;
        d - up * d.dot(up)
    };
    let mut cov = nalgebra::Matrix3::<f32>::zeros();
    for p in points {
        let d = flat(p);
        cov += d * d.transpose();
    }
    let eigen = nalgebra::SymmetricEigen::new(cov);
    let k = eigen.eigenvalues.imax();
    let axis = flat(&(centre + eigen.eigenvectors.column(k).into_owned()));
    let axis = if axis.norm() > 1e-6 {
        axis.normalize()
    } else {
        up.cross(&Vector3::x()).try_normalize(1e-6).unwrap_or_else(Vector3::y)
    };
    (centre, axis)
}

/// Where the tail base and the tail tip sit among the main-body joints.
const TAIL_BASE: usize = Joint::TailBase as usize;
pub(crate) const TAIL_TIP: usize = Joint::TailTip as usize;
const _: () = assert!(matches!(Joint::MAIN_BODY[TAIL_BASE], Joint::TailBase));
const _: () = assert!(matches!(Joint::MAIN_BODY[TAIL_TIP], Joint::TailTip));

/// How far (mm) the tail tip may move from the votes' estimate to the end of the segmented tail.
const TAIL_END_REACH_MM: f32 = 20.0;
/// The segmented tail's end is judged over a square this many mm either side of it.
const TAIL_THIN_RADIUS_MM: f32 = 4.0;
/// A tail's end is thin: under this share of the square around it is mouse (a 3-5 mm tail
/// fills about a tenth; the rim of the body, where the votes' tip lands when no tail is seen,
/// a third to two thirds).
const TAIL_THIN_SHARE: f32 = 0.25;

/// The tail tip moves only when the votes put it within this distance (mm) of a segmented
/// pixel: an estimate off the mask means the tail's last part was lost in the noise (as a
/// time-of-flight camera loses it), and then the votes know better than the mask where it ends.
const TAIL_ON_MASK_MM: f32 = 3.0;

/// What the segmented mouse shows where the votes put the tail tip.
#[derive(Clone, Copy, Debug, PartialEq)]
enum TailView {
    /// A tail, reaching the tip: its far end (camera frame), where the tip moves.
    End(Vector3<f32>),
    /// A tail that stops short of the tip (its last part lost in the noise, as a time-of-flight
    /// camera loses it), or nothing to judge: the votes' tip stays.
    Lost,
    /// No tail near the tip, only the body's rim or nothing of the mouse: no tail is seen
    /// there, so no tip is.
    Unseen,
}

/// Finds the far end of the segmented tail: of the mouse's pixels near the votes' tail tip, the
/// one furthest from the tail base along the mouse (8-connected steps over its pixels, so a
/// curled tail is followed rather than cut across), and whether the mask is thin there, as a
/// tail is. Buffers are kept between frames.
#[derive(Clone, Debug, Default)]
struct TailEnd {
    /// Per pixel of the region: steps from the pixel nearest the tail base, `u32::MAX` when not
    /// reached.
    steps: Vec<u32>,
    queue: VecDeque<u32>,
}

impl TailEnd {
    /// What the mask shows near `tip` ([`TailView`]): `Unseen` when no mouse pixel lies
    /// within [`TAIL_END_REACH_MM`] of it or the furthest one is not thin
    /// ([`TAIL_THIN_SHARE`]); `Lost` when it is thin but no mouse pixel lies within
    /// [`TAIL_ON_MASK_MM`] of the tip (or there is nothing to judge); else `End`.
    fn find(&mut self, image: &DepthImage, intrinsics: &Intrinsics, base: Vector3<f32>, tip: Vector3<f32>) -> TailView {
        let r = image.region;
        let (w, h) = (r.width as usize, r.height as usize);
        let point = |k: usize, d: f32| -> Vector3<f32> {
            let pixel = Point2::new((r.x0 as usize + k % w) as f64, (r.y0 as usize + k / w) as f64);
            intrinsics.unproject(&pixel, f64::from(d)).coords.cast()
        };
        let Some(b) = intrinsics.project(&Point3::from(base.cast::<f64>())) else {
            return TailView::Lost;
        };
        let (bx, by) = (b.x - f64::from(r.x0), b.y - f64::from(r.y0));
        let from_base = |k: usize| ((k % w) as f64 - bx).powi(2) + ((k / w) as f64 - by).powi(2);
        let Some((start, _)) = image
            .on_mouse()
            .min_by(|(a, _), (b, _)| from_base(*a).total_cmp(&from_base(*b)))
        else {
            return TailView::Lost;
        };
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
        let Some((_, k)) = end else {
            return TailView::Unseen;
        };
        let Some(d) = image.mouse_depth(k) else {
            return TailView::Unseen;
        };
        // The share of mouse pixels in the square around the end.
        let radius = (TAIL_THIN_RADIUS_MM * intrinsics.fx as f32 / d).round().max(1.0) as usize;
        let (x, y) = (k % w, k / w);
        let mut on = 0usize;
        for ny in y.saturating_sub(radius)..(y + radius + 1).min(h) {
            for nx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
                on += usize::from(image.mouse_depth(ny * w + nx).is_some());
            }
        }
        let side = 2 * radius + 1;
        if on as f32 >= TAIL_THIN_SHARE * (side * side) as f32 {
            TailView::Unseen
        } else if nearest > TAIL_ON_MASK_MM {
            TailView::Lost
        } else {
            TailView::End(point(k, d))
        }
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
    /// [`Self::LANES`] votes per vector instruction ([`simd::kernel_lanes`], in AVX where the
    /// processor has it), in that many interleaved partial sums (a fixed order, so the result
    /// is reproducible, and the same with either kernel).
    fn kernel_sums(&self, code: Kernel, at: &Vector3<f32>, h2: f32) -> (Vector3<f32>, f32) {
        const L: usize = VoteCloud::LANES;
        let scale = kernel_scale(h2);
        let n = self.w.len() / L * L;
        let votes = [&self.x[..], &self.y, &self.z, &self.w];
        let [sx, sy, sz, sw] = simd::kernel_lanes(code, votes, [at.x, at.y, at.z], scale);
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
