//! Training of the attentional cascade: stage after stage of boosted stumps
//! ([`super::boost`]), each trained on the positives the cascade so far still accepts and on
//! negatives the cascade so far still (wrongly) accepts: first hard negatives (windows cut
//! on things known to look like paws: the snout, the chin, the tail base, the genitals,
//! glare and marks on the glass, pale belly fur), up to a share of the stage's negatives,
//! then windows bootstrapped from background images that touch no paw. Training stops after the requested number of
//! stages, or early when the backgrounds no longer yield enough such windows (the cascade
//! then rejects almost everything that is not a paw) and says so.
//!
//! Reproducible from the seed whatever the number of rayon threads: work is split by
//! feature or by image and gathered in a fixed order.

use super::PawError;
use super::boost::{Binned, boost_stage};
use super::cascade::{BoostStage, Cascade, CascadeParams, Verdict, WeakTree};
use super::detect::DEFAULT_SCALES;
use super::grey::{GreyImage, ResampleScratch, resample};
use super::haar::{basic_features, window_norm};
use super::integral::Integral;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// A background image: grey at the canonical scale, with the boxes no negative may touch.
#[derive(Clone, Debug)]
pub struct Background {
    pub grey: GreyImage,
    /// `[x0, y0, x1, y1]` in the grey image's pixels.
    pub excluded: Vec<[f32; 4]>,
}

impl Background {
    /// The background turned and mirrored in the 8 ways a square's symmetries allow (itself
    /// first), its excluded boxes with it: more negatives from the few frames a lab labels,
    /// none of them made up.
    pub fn dihedral(&self) -> Vec<Background> {
        let (w, h) = (self.grey.width, self.grey.height);
        (0..8)
            .map(|k| {
                let transpose = k & 4 != 0;
                let (flip_x, flip_y) = (k & 1 != 0, k & 2 != 0);
                let (ow, oh) = if transpose { (h, w) } else { (w, h) };
                // Where an output point (u, v) comes from in the input, for pixels and edges.
                let source = |u: f64, v: f64, ew: f64, eh: f64| {
                    let (x, y) = if transpose { (v, u) } else { (u, v) };
                    let x = if flip_x { ew - x } else { x };
                    let y = if flip_y { eh - y } else { y };
                    (x, y)
                };
                let mut data = Vec::with_capacity(w * h);
                for v in 0..oh {
                    for u in 0..ow {
                        let (x, y) = source(u as f64, v as f64, (w - 1) as f64, (h - 1) as f64);
                        data.push(self.grey.data[y as usize * w + x as usize]);
                    }
                }
                // Boxes map corner to corner (edges run 0..w): the inverse of `source`.
                let excluded = self
                    .excluded
                    .iter()
                    .map(|b| {
                        let corner = |x: f32, y: f32| {
                            let x = if flip_x { w as f32 - x } else { x };
                            let y = if flip_y { h as f32 - y } else { y };
                            if transpose { (y, x) } else { (x, y) }
                        };
                        let (a, c) = (corner(b[0], b[1]), corner(b[2], b[3]));
                        [a.0.min(c.0), a.1.min(c.1), a.0.max(c.0), a.1.max(c.1)]
                    })
                    .collect();
                Background {
                    grey: GreyImage {
                        width: ow,
                        height: oh,
                        data,
                    },
                    excluded,
                }
            })
            .collect()
    }
}

/// Positive windows (each `width * height` bytes, concatenated) and background images.
#[derive(Clone, Debug, Default)]
pub struct TrainingSet {
    pub width: usize,
    pub height: usize,
    pub positives: Vec<u8>,
    pub backgrounds: Vec<Background>,
    /// Paws on the glass and visible that the positives were cut around.
    pub paws: usize,
    /// Hard negative windows (each `width * height` bytes, concatenated): cut on things that
    /// look like paws and are not.
    pub hard: Vec<u8>,
}

impl TrainingSet {
    /// The number of positive windows.
    pub fn positive_count(&self) -> usize {
        self.positives.len() / (self.width * self.height).max(1)
    }

    /// The number of hard negative windows.
    pub fn hard_count(&self) -> usize {
        self.hard.len() / (self.width * self.height).max(1)
    }

    /// Adds `other`'s windows and backgrounds (cut at the same window size; an empty set takes
    /// `other`'s size).
    pub fn append(&mut self, other: TrainingSet) {
        if self.width * self.height == 0 {
            self.width = other.width;
            self.height = other.height;
        }
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        self.positives.extend(other.positives);
        self.hard.extend(other.hard);
        self.backgrounds.extend(other.backgrounds);
        self.paws += other.paws;
    }
}

/// Training parameters (all of them; seeded and serialisable into the report).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct TrainParams {
    pub stages: usize,
    pub min_hit_rate: f64,
    pub max_false_alarm: f64,
    pub max_weak: usize,
    /// Positives per stage (at most).
    pub positives: usize,
    /// Negatives per stage (at most).
    pub negatives: usize,
    /// Negatives taken from one background image per stage (at most; more when there are too
    /// few backgrounds to give a stage's negatives twice over at this rate).
    pub per_image: usize,
    /// The share of a stage's negatives that hard negatives may take (at most).
    pub hard_share: f64,
    pub seed: u64,
}

impl Default for TrainParams {
    fn default() -> Self {
        Self {
            stages: 20,
            min_hit_rate: 0.995,
            max_false_alarm: 0.5,
            max_weak: 100,
            positives: 3000,
            negatives: 3000,
            per_image: 4,
            hard_share: 0.5,
            seed: 0,
        }
    }
}

/// What happened in one stage.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageReport {
    pub stage: usize,
    pub positives: usize,
    pub negatives: usize,
    /// Of the negatives, hard ones.
    pub hard_negatives: usize,
    pub weak: usize,
    pub hit_rate: f64,
    pub false_alarm: f64,
    /// Windows of the backgrounds the cascade before this stage was run on, and accepted.
    pub windows_scanned: u64,
    pub windows_accepted: u64,
}

/// Why training ended.
#[derive(Clone, Debug, serde::Serialize)]
pub enum StopReason {
    /// All requested stages were trained.
    Done,
    /// The backgrounds yielded fewer negatives than a stage needs.
    NoNegatives { found: usize, scanned: u64 },
    /// Fewer positives than a stage needs are still accepted.
    NoPositives { found: usize },
}

/// A trained cascade and its history.
#[derive(Clone, Debug)]
pub struct Trained {
    pub cascade: Cascade,
    pub stages: Vec<StageReport>,
    pub stop: StopReason,
    /// Positive windows too flat for the evaluator to ever classify.
    pub flat_positives: usize,
}

/// Windows of one size, with their integral images.
struct Windows {
    width: usize,
    height: usize,
    /// Per window, `(width + 1) * (height + 1)` corners.
    sums: Vec<i32>,
    factors: Vec<f32>,
}

impl Windows {
    fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            sums: Vec::new(),
            factors: Vec::new(),
        }
    }

    fn len(&self) -> usize {
        self.factors.len()
    }

    fn push(&mut self, ii: &Integral, factor: f32) {
        self.sums.extend_from_slice(&ii.sum);
        self.factors.push(factor);
    }

    fn corners(&self) -> usize {
        (self.width + 1) * (self.height + 1)
    }
}

/// Trains a cascade on `set`, calling `progress` after each stage.
///
/// # Errors
/// When the set has too few usable positives to train a stage.
pub fn train(
    set: &TrainingSet,
    params: &TrainParams,
    progress: &mut dyn FnMut(&StageReport),
) -> Result<Trained, PawError> {
    let (w, h) = (set.width, set.height);
    let per_image = params
        .per_image
        .max((2 * params.negatives).div_ceil(set.backgrounds.len().max(1)));
    let params = &TrainParams { per_image, ..*params };
    let features = basic_features(w as u32, h as u32);
    let mut rng = ChaCha8Rng::seed_from_u64(params.seed);
    let mut ii = Integral::default();
    let (pool, flat_positives) = positive_pool(set, &mut rng, &mut ii);
    let mut image_order: Vec<usize> = (0..set.backgrounds.len()).collect();
    image_order.shuffle(&mut rng);
    let hard_pool = hard_pool(set, &mut rng, &mut ii);
    let hard_limit = (params.negatives as f64 * params.hard_share.clamp(0.0, 1.0)) as usize;
    let mut cascade = Cascade {
        width: w as u32,
        height: h as u32,
        params: CascadeParams {
            min_hit_rate: params.min_hit_rate as f32,
            max_false_alarm: params.max_false_alarm as f32,
            weight_trim_rate: 0.0,
            max_weak_count: params.max_weak as u32,
            ..CascadeParams::default()
        },
        stages: Vec::new(),
        features: features.clone(),
        min_neighbors: None,
    };
    let mut reports = Vec::new();
    let mut stop = StopReason::Done;
    for stage_index in 0..params.stages {
        // Positives the cascade still accepts.
        let pos = still_accepted(&cascade, &pool, params.positives, &mut ii);
        if pos.len() < 10 {
            stop = StopReason::NoPositives { found: pos.len() };
            break;
        }
        // Negatives the cascade still accepts: hard ones first, then the backgrounds'.
        let mut neg = still_accepted(&cascade, &hard_pool, hard_limit, &mut ii);
        let hard_negatives = neg.len();
        let (scanned, accepted) = bootstrap(&cascade, &set.backgrounds, &image_order, params, stage_index, &mut neg);
        if neg.len() < (params.negatives / 20).max(10) {
            stop = StopReason::NoNegatives {
                found: neg.len(),
                scanned,
            };
            break;
        }
        let npos = pos.len();
        let binned = feature_values(&features, &pos, &neg, w);
        let boosted = boost_stage(
            &binned,
            npos,
            params.min_hit_rate,
            params.max_false_alarm,
            params.max_weak,
        );
        cascade.stages.push(BoostStage {
            threshold: boosted.threshold,
            weak: boosted
                .stumps
                .iter()
                .map(|s| WeakTree::stump(s.feature, s.threshold, s.left, s.right))
                .collect(),
        });
        let report = StageReport {
            stage: stage_index,
            positives: npos,
            negatives: neg.len(),
            hard_negatives,
            weak: boosted.stumps.len(),
            hit_rate: boosted.hit_rate,
            false_alarm: boosted.false_alarm,
            windows_scanned: scanned,
            windows_accepted: accepted,
        };
        progress(&report);
        reports.push(report);
    }
    if cascade.stages.is_empty() {
        return Err(PawError::Training {
            reason: match &stop {
                StopReason::NoPositives { found } => format!("only {found} usable positive windows"),
                StopReason::NoNegatives { found, .. } => format!("only {found} negative windows in the backgrounds"),
                StopReason::Done => "no stage was trained".to_owned(),
            },
        });
    }
    cascade.compact_features();
    Ok(Trained {
        cascade,
        stages: reports,
        stop,
        flat_positives,
    })
}

/// The positive pool, shuffled once; flat windows can never be detected (how many there
/// were is the second value).
fn positive_pool(set: &TrainingSet, rng: &mut ChaCha8Rng, ii: &mut Integral) -> (Windows, usize) {
    let (w, h) = (set.width, set.height);
    let mut order: Vec<usize> = (0..set.positive_count()).collect();
    order.shuffle(rng);
    let mut pool = Windows::new(w, h);
    let mut flat_positives = 0;
    for &k in &order {
        ii.compute(&set.positives[k * w * h..(k + 1) * w * h], w, h);
        let (factor, ok) = window_norm(ii, 0, 0, w, h);
        if ok {
            pool.push(ii, factor);
        } else {
            flat_positives += 1;
        }
    }
    (pool, flat_positives)
}

/// The hard negatives, shuffled once (no draw when there are none), flat ones left out.
fn hard_pool(set: &TrainingSet, rng: &mut ChaCha8Rng, ii: &mut Integral) -> Windows {
    let (w, h) = (set.width, set.height);
    let mut hard_order: Vec<usize> = (0..set.hard_count()).collect();
    hard_order.shuffle(rng);
    let mut hard_pool = Windows::new(w, h);
    for &k in &hard_order {
        ii.compute(&set.hard[k * w * h..(k + 1) * w * h], w, h);
        let (factor, ok) = window_norm(ii, 0, 0, w, h);
        if ok {
            hard_pool.push(ii, factor);
        }
    }
    hard_pool
}

/// Every feature's value on a stage's windows, positives (`pos`) then negatives, binned for
/// boosting (windows `w` pixels wide).
fn feature_values(features: &[super::haar::HaarFeature], pos: &Windows, neg: &Windows, w: usize) -> Binned {
    let npos = pos.len();
    let n = npos + neg.len();
    Binned::build(features.len(), n, |f, out| {
        let feature = &features[f];
        for (i, v) in out.iter_mut().enumerate() {
            let (src, k) = if i < npos { (pos, i) } else { (neg, i - npos) };
            let c = src.corners();
            let sums = &src.sums[k * c..(k + 1) * c];
            *v = raw_value(feature, sums, w + 1) * src.factors[k];
        }
    })
}

/// A feature's raw value over a window's own integral image (row stride `stride`), in the
/// evaluator's arithmetic.
fn raw_value(f: &super::haar::HaarFeature, sums: &[i32], stride: usize) -> f32 {
    let mut acc = 0.0f32;
    for r in &f.rects {
        if r.weight == 0.0 {
            continue;
        }
        let (x, y, rw, rh) = (r.x as usize, r.y as usize, r.width as usize, r.height as usize);
        let a = y * stride + x;
        let b = (y + rh) * stride + x;
        let s = sums[a]
            .wrapping_sub(sums[a + rw])
            .wrapping_sub(sums[b])
            .wrapping_add(sums[b + rw]);
        acc += r.weight * s as f32;
    }
    acc
}

/// The first `limit` windows of `pool` that every stage of `cascade` accepts.
fn still_accepted(cascade: &Cascade, pool: &Windows, limit: usize, ii: &mut Integral) -> Windows {
    let mut out = Windows::new(pool.width, pool.height);
    let corners = pool.corners();
    for i in 0..pool.len() {
        if out.len() >= limit {
            break;
        }
        let sums = &pool.sums[i * corners..(i + 1) * corners];
        ii.stride = pool.width + 1;
        ii.rows = pool.height + 1;
        ii.sum.clear();
        ii.sum.extend_from_slice(sums);
        ii.sqsum.clear();
        ii.sqsum.resize(corners, 0);
        if accepts_stages(cascade, ii, pool.factors[i]) {
            out.push(ii, pool.factors[i]);
        }
    }
    out
}

/// Whether every stage trained so far accepts a window with known normalisation.
fn accepts_stages(c: &Cascade, ii: &Integral, factor: f32) -> bool {
    for stage in &c.stages {
        let mut sum = 0.0f64;
        for tree in &stage.weak {
            let node = tree.nodes[0];
            let value = c.features[node.feature].raw(ii, 0, 0) * factor;
            sum += f64::from(if value < node.threshold {
                tree.leaves[0]
            } else {
                tree.leaves[1]
            });
        }
        if sum < stage.applied_threshold() {
            return false;
        }
    }
    true
}

/// Adds to `out`, until it holds `params.negatives`, windows of the backgrounds, at the
/// detector's scales, that touch no excluded box and that `cascade` accepts: at most
/// `per_image` from one image, images visited in `order`. Returns the windows scanned and
/// accepted.
fn bootstrap(
    cascade: &Cascade,
    backgrounds: &[Background],
    order: &[usize],
    params: &TrainParams,
    stage: usize,
    out: &mut Windows,
) -> (u64, u64) {
    let (mut scanned, mut accepted) = (0u64, 0u64);
    if out.len() >= params.negatives {
        return (scanned, accepted);
    }
    let batch = 64;
    for chunk in order.chunks(batch) {
        let found: Vec<(Vec<Integral>, Vec<f32>, u64, u64)> = chunk
            .par_iter()
            .map(|&k| negatives_of(cascade, &backgrounds[k], params, stage, k))
            .collect();
        for (windows, factors, s, a) in found {
            scanned += s;
            accepted += a;
            for (ii, f) in windows.iter().zip(factors) {
                if out.len() < params.negatives {
                    out.push(ii, f);
                }
            }
        }
        if out.len() >= params.negatives {
            break;
        }
    }
    (scanned, accepted)
}

fn negatives_of(
    cascade: &Cascade,
    bg: &Background,
    params: &TrainParams,
    stage: usize,
    image: usize,
) -> (Vec<Integral>, Vec<f32>, u64, u64) {
    let (w, h) = (cascade.width as usize, cascade.height as usize);
    let mut rng =
        ChaCha8Rng::seed_from_u64(params.seed ^ ((stage as u64) << 40) ^ (image as u64).wrapping_mul(0x9E37_79B9));
    let mut scaled = GreyImage::default();
    let mut rows = ResampleScratch::default();
    let mut ii = Integral::default();
    let mut hits: Vec<(usize, usize, usize)> = Vec::new();
    let (mut scanned, mut accepted) = (0u64, 0u64);
    let mut images = Vec::with_capacity(DEFAULT_SCALES.len());
    for (si, &scale) in DEFAULT_SCALES.iter().enumerate() {
        let img = if (scale - 1.0).abs() < 1e-9 {
            bg.grey.clone()
        } else {
            resample(&bg.grey, scale, &mut scaled, &mut rows);
            scaled.clone()
        };
        if img.width < w || img.height < h {
            images.push(img);
            continue;
        }
        ii.compute(&img.data, img.width, img.height);
        let s = scale as f32;
        for y in 0..=img.height - h {
            for x in 0..=img.width - w {
                let (x0, y0, size) = (x as f32 * s, y as f32 * s, w as f32 * s);
                let touches = bg
                    .excluded
                    .iter()
                    .any(|b| x0 < b[2] && x0 + size > b[0] && y0 < b[3] && y0 + size > b[1]);
                if touches {
                    continue;
                }
                scanned += 1;
                if let Verdict::Accepted { .. } = cascade.classify(&ii, x, y) {
                    accepted += 1;
                    hits.push((si, x, y));
                }
            }
        }
        images.push(img);
    }
    // A random few of the accepted windows.
    let keep = params.per_image.min(hits.len());
    for i in 0..keep {
        let j = rng.gen_range(i..hits.len());
        hits.swap(i, j);
    }
    hits.truncate(keep);
    let mut windows = Vec::with_capacity(keep);
    let mut factors = Vec::with_capacity(keep);
    let mut patch = vec![0u8; w * h];
    for &(si, x, y) in &hits {
        let img = &images[si];
        for r in 0..h {
            patch[r * w..(r + 1) * w].copy_from_slice(&img.data[(y + r) * img.width + x..(y + r) * img.width + x + w]);
        }
        let mut wi = Integral::default();
        wi.compute(&patch, w, h);
        let (f, _) = window_norm(&wi, 0, 0, w, h);
        windows.push(wi);
        factors.push(f);
    }
    (windows, factors, scanned, accepted)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every turn and mirror of a background keeps its pixels and carries its excluded box with
    /// them: the box's pixels, and only they, stay inside it.
    #[test]
    fn turned_backgrounds_carry_their_excluded_boxes() {
        let (w, h) = (7usize, 4usize);
        let bg = Background {
            grey: GreyImage {
                width: w,
                height: h,
                data: (0..w * h).map(|i| i as u8).collect(),
            },
            excluded: vec![[1.0, 0.0, 3.0, 2.0]],
        };
        let inside = |b: &Background, x: usize, y: usize| {
            let e = b.excluded[0];
            (x as f32) >= e[0] && (x as f32) < e[2] && (y as f32) >= e[1] && (y as f32) < e[3]
        };
        let boxed: Vec<u8> = (0..w * h)
            .filter(|&i| inside(&bg, i % w, i / w))
            .map(|i| bg.grey.data[i])
            .collect();
        let turned = bg.dihedral();
        assert_eq!(turned.len(), 8);
        assert_eq!(turned[0].grey, bg.grey);
        let mut seen = std::collections::BTreeSet::new();
        for t in &turned {
            let mut sorted = t.grey.data.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, bg.grey.data, "every pixel kept once");
            let mut inner: Vec<u8> = (0..t.grey.width * t.grey.height)
                .filter(|&i| inside(t, i % t.grey.width, i / t.grey.width))
                .map(|i| t.grey.data[i])
                .collect();
            inner.sort_unstable();
            assert_eq!(inner, boxed, "{:?}", t.excluded);
            seen.insert(t.grey.data.clone());
        }
        assert_eq!(seen.len(), 8, "eight different images");
    }

    /// Bright blobs on a dark, noisy floor: a tiny cascade learns them in a moment.
    #[test]
    fn a_tiny_cascade_learns_bright_blobs() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (w, h) = (8, 8);
        let mut set = TrainingSet {
            width: w,
            height: h,
            ..TrainingSet::default()
        };
        let blob =
            |x: f64, y: f64, cx: f64, cy: f64| -> f64 { 200.0 * (-((x - cx).powi(2) + (y - cy).powi(2)) / 4.0).exp() };
        for _ in 0..300 {
            let (cx, cy) = (rng.gen_range(3.0..5.0), rng.gen_range(3.0..5.0));
            for y in 0..h {
                for x in 0..w {
                    let v = 40.0 + blob(x as f64, y as f64, cx, cy) + rng.gen_range(-5.0..5.0);
                    set.positives.push(v as u8);
                }
            }
        }
        for _ in 0..20 {
            let (gw, gh) = (40, 30);
            let mut grey = GreyImage {
                width: gw,
                height: gh,
                data: Vec::new(),
            };
            let stripe = rng.gen_range(0..gw);
            for _ in 0..gh {
                for x in 0..gw {
                    let edge = if x >= stripe { 60.0 } else { 0.0 };
                    grey.data.push((30.0 + edge + rng.gen_range(-8.0..8.0)) as u8);
                }
            }
            set.backgrounds.push(Background {
                grey,
                excluded: Vec::new(),
            });
        }
        let params = TrainParams {
            stages: 3,
            positives: 300,
            negatives: 300,
            per_image: 30,
            max_weak: 10,
            seed: 1,
            ..TrainParams::default()
        };
        let mut seen = 0;
        let trained = train(&set, &params, &mut |_| seen += 1).unwrap();
        assert!(!trained.cascade.stages.is_empty());
        assert_eq!(seen, trained.stages.len());
        // Every stage meets the hit rate on its positives.
        for s in &trained.stages {
            assert!(s.hit_rate >= 0.995, "{s:?}");
        }
        // The same seed gives the same cascade.
        let again = train(&set, &params, &mut |_| {}).unwrap();
        assert_eq!(again.cascade, trained.cascade);
    }

    /// Bright squares look enough like the blobs that a cascade trained on the plain
    /// backgrounds takes them; given as hard negatives, it learns to reject them and keeps
    /// the blobs.
    #[test]
    fn hard_negatives_teach_the_cascade_what_is_not_a_paw() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let (w, h) = (8usize, 8usize);
        let blob = |x: f64, y: f64, cx: f64, cy: f64| 200.0 * (-((x - cx).powi(2) + (y - cy).powi(2)) / 4.0).exp();
        // A hard-edged bright square: a glint on the glass rather than a soft paw.
        let square = |x: f64, y: f64, cx: f64, cy: f64| {
            if (x - cx).abs() < 2.0 && (y - cy).abs() < 2.0 {
                200.0
            } else {
                0.0
            }
        };
        let windows = |rng: &mut ChaCha8Rng, n: usize, squares: bool| {
            let mut out = Vec::new();
            for _ in 0..n {
                let (cx, cy) = (rng.gen_range(3.0..5.0), rng.gen_range(3.0..5.0));
                for y in 0..h {
                    for x in 0..w {
                        let v = if squares {
                            square(x as f64, y as f64, cx, cy)
                        } else {
                            blob(x as f64, y as f64, cx, cy)
                        };
                        out.push((40.0 + v + rng.gen_range(-5.0..5.0)) as u8);
                    }
                }
            }
            out
        };
        let positives = windows(&mut rng, 300, false);
        let hard = windows(&mut rng, 300, true);
        let test_blobs = windows(&mut rng, 200, false);
        let test_squares = windows(&mut rng, 200, true);
        let mut backgrounds = Vec::new();
        for _ in 0..20 {
            let (gw, gh) = (40, 30);
            let stripe = rng.gen_range(0..gw);
            let data = (0..gw * gh)
                .map(|i| (30.0 + if i % gw >= stripe { 60.0 } else { 0.0 } + rng.gen_range(-8.0..8.0)) as u8)
                .collect();
            backgrounds.push(Background {
                grey: GreyImage {
                    width: gw,
                    height: gh,
                    data,
                },
                excluded: Vec::new(),
            });
        }
        let params = TrainParams {
            stages: 4,
            positives: 300,
            negatives: 300,
            per_image: 30,
            max_weak: 10,
            seed: 1,
            ..TrainParams::default()
        };
        let accepted = |c: &Cascade, windows: &[u8]| {
            let mut ii = Integral::default();
            windows
                .chunks_exact(w * h)
                .filter(|win| {
                    ii.compute(win, w, h);
                    matches!(c.classify(&ii, 0, 0), Verdict::Accepted { .. })
                })
                .count()
        };
        let plain = TrainingSet {
            width: w,
            height: h,
            positives: positives.clone(),
            backgrounds: backgrounds.clone(),
            ..TrainingSet::default()
        };
        let without = train(&plain, &params, &mut |_| {}).unwrap();
        let with_hard = TrainingSet { hard, ..plain };
        let mut used = 0;
        let with = train(&with_hard, &params, &mut |r| used += r.hard_negatives).unwrap();
        assert!(used > 0);
        let without = accepted(&without.cascade, &test_squares);
        let with_hard = accepted(&with.cascade, &test_squares);
        assert!(
            without >= 100,
            "without hard negatives {without} of 200 squares accepted"
        );
        assert!(
            with_hard <= 10,
            "with hard negatives {with_hard} of 200 squares accepted"
        );
        assert!(accepted(&with.cascade, &test_blobs) >= 180, "blobs lost");
    }
}
