//! The paper's running example (sec. 2.1-2.4): two classes drawn from nine pairs of 2D
//! Gaussians, a baseline classification forest with axis-aligned splits (horizontal at even
//! levels, vertical at odd ones, thresholds with three decimals), and its discriminative
//! training on a second data set.

use crate::core::rng::item_rng;
use crate::vision::forest::classify::{ClassObjective, argmax};
use crate::vision::forest::discriminative::{
    DiscriminativeParams, ErrorScope, PassStats, Scoring, refine_tree, subset,
};
use crate::vision::forest::train::train_forest;
use crate::vision::forest::{Forest, SplitSpace, TrainParams};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::Serialize;

/// The split axis: 0 tests y (a horizontal line), 1 tests x (a vertical one).
pub type Axis = u8;

/// Points in the unit square with their classes.
#[derive(Clone, Debug, Default)]
pub struct Points {
    pub xy: Vec<[f32; 2]>,
    pub labels: Vec<u8>,
}

impl Points {
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// The points of `self` followed by those of `other`.
    pub fn union(&self, other: &Points) -> Points {
        Points {
            xy: self.xy.iter().chain(&other.xy).copied().collect(),
            labels: self.labels.iter().chain(&other.labels).copied().collect(),
        }
    }
}

/// One Gaussian of the mixture.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Blob {
    pub mean: [f64; 2],
    pub sigma: f64,
    pub class: u8,
}

/// Nine pairs of Gaussians, as the paper sets them up: the two of a pair are of opposite
/// classes and overlap (their means lie 1 to 3 times their mean sigma apart, in a random
/// direction), means in (0, 1), sigma in (0.02, 0.2).
pub fn blobs(seed: u64) -> Vec<Blob> {
    let mut rng = item_rng(seed, 0x6A55, 1);
    let mut out = Vec::with_capacity(18);
    for _ in 0..9 {
        let centre = [rng.gen_range(0.15..0.85), rng.gen_range(0.15..0.85)];
        let sigmas: [f64; 2] = [rng.gen_range(0.02..0.2), rng.gen_range(0.02..0.2)];
        let gap = rng.gen_range(1.0..3.0) * (sigmas[0] + sigmas[1]) / 2.0;
        let angle = rng.gen_range(0.0..std::f64::consts::TAU);
        for (class, (sigma, side)) in sigmas.into_iter().zip([-0.5, 0.5]).enumerate() {
            let along = [angle.cos(), angle.sin()];
            out.push(Blob {
                mean: std::array::from_fn(|k| (centre[k] + side * gap * along[k]).clamp(0.01, 0.99)),
                sigma,
                class: class as u8,
            });
        }
    }
    out
}

/// `n` points drawn from the mixture (each from a Gaussian chosen uniformly), stream `stream`.
pub fn sample(blobs: &[Blob], n: usize, seed: u64, stream: u64) -> Points {
    let chunk = 65_536;
    let parts: Vec<Points> = (0..n.div_ceil(chunk))
        .into_par_iter()
        .map(|c| {
            let mut rng = item_rng(seed, 0x6A56 + stream, c as u64);
            let count = chunk.min(n - c * chunk);
            let mut p = Points {
                xy: Vec::with_capacity(count),
                labels: Vec::with_capacity(count),
            };
            for _ in 0..count {
                let b = &blobs[rng.gen_range(0..blobs.len())];
                let nx: f64 = StandardNormal.sample(&mut rng);
                let ny: f64 = StandardNormal.sample(&mut rng);
                p.xy.push([(b.mean[0] + b.sigma * nx) as f32, (b.mean[1] + b.sigma * ny) as f32]);
                p.labels.push(b.class);
            }
            p
        })
        .collect();
    let mut out = Points::default();
    for p in parts {
        out.xy.extend(p.xy);
        out.labels.extend(p.labels);
    }
    out
}

/// The split space of the example: the axis is fixed by the node's level, thresholds are
/// drawn uniformly from (0, 1) with three decimals.
#[derive(Clone, Copy, Debug)]
pub struct AxisSplits<'a> {
    pub points: &'a Points,
}

impl SplitSpace for AxisSplits<'_> {
    type Feature = Axis;

    #[inline]
    fn value(&self, sample: u32, axis: &Axis) -> f32 {
        self.points.xy[sample as usize][usize::from(1 - *axis)]
    }

    fn candidates(
        &self,
        depth: u32,
        _samples: &[u32],
        m: usize,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Vec<(Axis, Vec<f32>)> {
        let axis = (depth % 2) as Axis;
        let thresholds = (0..m).map(|_| f32::from(rng.gen_range(1u16..1000)) / 1000.0).collect();
        vec![(axis, thresholds)]
    }
}

/// A forest of the example.
pub type AxisForest = Forest<Axis, Vec<f32>>;

/// Accuracy of a forest on points: each tree votes its leaf's class, the majority wins.
pub fn accuracy(forest: &AxisForest, points: &Points) -> f64 {
    let space = AxisSplits { points };
    let correct: usize = (0..points.len())
        .into_par_iter()
        .filter(|&i| {
            let mut votes = [0u32; 2];
            for t in &forest.trees {
                let c = argmax(t.leaf(|axis| space.value(i as u32, axis)));
                votes[c.min(1)] += 1;
            }
            usize::from(votes[1] > votes[0]) == usize::from(points.labels[i])
        })
        .count();
    correct as f64 / points.len().max(1) as f64
}

/// Trains the baseline forest on `data`.
pub fn baseline(data: &Points, params: &TrainParams) -> AxisForest {
    let space = AxisSplits { points: data };
    let objective = ClassObjective {
        labels: &data.labels,
        classes: 2,
    };
    let all: Vec<u32> = (0..data.len() as u32).collect();
    train_forest(&space, &objective, vec![all; params.trees], params, 0, &|| {})
}

/// Discriminatively trains a copy of `forest` on `data` (D_d); each tree sees its own subset
/// per pass.
pub fn discriminative(forest: &AxisForest, data: &Points, params: &DiscriminativeParams) -> (AxisForest, PassStats) {
    discriminative_from(forest, data, params, 0)
}

/// As [`discriminative`], numbering the passes from `first` (each pass draws its own subsets).
pub fn discriminative_from(
    forest: &AxisForest,
    data: &Points,
    params: &DiscriminativeParams,
    first: usize,
) -> (AxisForest, PassStats) {
    let space = AxisSplits { points: data };
    let objective = ClassObjective {
        labels: &data.labels,
        classes: 2,
    };
    let all: Vec<u32> = (0..data.len() as u32).collect();
    let results: Vec<_> = forest
        .trees
        .par_iter()
        .enumerate()
        .map(|(t, tree)| {
            let mut tree = tree.clone();
            let mut total = PassStats::default();
            for it in first..first + params.iterations {
                let mut s = subset(&all, params, t, it);
                total += refine_tree(&space, &objective, &mut tree, &mut s, params, t, it);
            }
            (tree, total)
        })
        .collect();
    let mut stats = PassStats::default();
    let mut trees = Vec::with_capacity(results.len());
    for (tree, p) in results {
        trees.push(tree);
        stats += p;
    }
    (AxisForest { trees }, stats)
}

/// Sizes and defaults of one run of the experiment.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Setup {
    pub points: usize,
    pub trees: usize,
    pub max_depth: u32,
    pub tests: usize,
    /// l_n: the paper gives none for this example; 60 is its value for the mouse forests.
    pub min_leaf: usize,
    /// Each tree's D'_d: this many times |D_d| points drawn from D_d with replacement. The
    /// paper says only "a randomly sampled subset"; a bootstrap sample differs from tree to
    /// tree and is as large as D_t, so the shrink rule compares node sizes with l_n as the
    /// baseline did (the `subset` sweep shows the other sizes).
    pub subset: f64,
    pub seed: u64,
}

impl Setup {
    /// The paper's sizes (10^6 points per set), or a tenth of them for `--quick`.
    pub fn new(quick: bool, seed: u64) -> Self {
        Self {
            points: if quick { 100_000 } else { 1_000_000 },
            trees: 5,
            max_depth: 20,
            tests: 50,
            min_leaf: 60,
            subset: 1.0,
            seed,
        }
    }

    pub fn train_params(&self) -> TrainParams {
        TrainParams {
            trees: self.trees,
            max_depth: self.max_depth,
            tests: self.tests,
            min_leaf: self.min_leaf,
            seed: self.seed,
            score_sample: 0,
        }
    }

    pub fn discriminative_params(&self, scoring: Scoring) -> DiscriminativeParams {
        DiscriminativeParams {
            tests: self.tests,
            min_leaf: self.min_leaf,
            start_level: 0,
            iterations: 1,
            subset: self.subset,
            bootstrap: true,
            // A class leaf refitted to D'_d is the paper's leaf rule applied to the new data.
            refit_leaves: true,
            keep_current: false,
            error: ErrorScope::AllJoints,
            scoring,
            score_sample: 0,
            max_depth: self.max_depth,
            seed: self.seed ^ 0xD1,
        }
    }
}

/// The best accuracy any classifier can reach on `points`: each point labelled with the class
/// of larger true density.
pub fn bayes_accuracy(blobs: &[Blob], points: &Points) -> f64 {
    let correct = (0..points.len())
        .into_par_iter()
        .filter(|&i| {
            let [x, y] = points.xy[i].map(f64::from);
            let mut density = [0.0f64; 2];
            for b in blobs {
                let d2 = (x - b.mean[0]).powi(2) + (y - b.mean[1]).powi(2);
                density[usize::from(b.class)] += (-d2 / (2.0 * b.sigma * b.sigma)).exp() / (b.sigma * b.sigma);
            }
            usize::from(density[1] > density[0]) == usize::from(points.labels[i])
        })
        .count();
    correct as f64 / points.len().max(1) as f64
}
