//! The baseline method: grow each tree from the root, choosing at every split node the test
//! with the largest gain among `m` random candidates, until `L` levels or fewer than `l_n`
//! samples.
//!
//! With [`TrainParams::score_sample`], a node's candidates are scored on a bounded random
//! sample of its samples (the standard speed-up for large test budgets), and all of them are
//! routed by the chosen test.
//!
//! Candidate thresholds are scored in one pass over the node's samples per feature: samples
//! are binned between the sorted thresholds, the bins' statistics summed from one end, and the
//! gain of every threshold read off the running sums.

use super::{NOT_LEAF, Node, Objective, SplitSpace, TrainParams, Tree, node_rng, scoring_sample};
use rayon::prelude::*;

/// A chosen split: feature, threshold and gain.
pub type Split<F> = (F, f32, f64);

/// Samples are binned in chunks of this many; chunks are summed in order, so the result does
/// not depend on how many threads did the work.
const CHUNK: usize = 8192;

/// Scores every threshold of every candidate on `samples` and returns the best split, if any
/// separates them.
///
/// The loop runs sample by sample over all candidates, so each sample's image stays in cache
/// while its probes are read: for depth features this is what bounds the speed.
pub fn best_split<S: SplitSpace, O: Objective>(
    space: &S,
    objective: &O,
    samples: &[u32],
    candidates: &[(S::Feature, Vec<f32>)],
) -> Option<Split<S::Feature>> {
    let sorted: Vec<Vec<f32>> = candidates
        .iter()
        .map(|(_, t)| {
            let mut t = t.clone();
            t.sort_by(f32::total_cmp);
            t.dedup();
            t
        })
        .collect();
    // Bins of candidate c start at offsets[c]; it has sorted[c].len() + 1 of them.
    let mut offsets = Vec::with_capacity(sorted.len() + 1);
    let mut total = 0;
    for t in &sorted {
        offsets.push(total);
        total += t.len() + 1;
    }
    let bin_chunk = |chunk: &[u32]| {
        let mut bins = vec![objective.empty_stats(); total];
        for &s in chunk {
            for (c, (feature, _)) in candidates.iter().enumerate() {
                let v = space.value(s, feature);
                let b = sorted[c].partition_point(|&t| t < v);
                objective.add(&mut bins[offsets[c] + b], s);
            }
        }
        bins
    };
    let chunks: Vec<&[u32]> = samples.chunks(CHUNK).collect();
    let partials: Vec<Vec<O::Stats>> = if chunks.len() > 1 {
        chunks.par_iter().map(|c| bin_chunk(c)).collect()
    } else {
        chunks.iter().map(|c| bin_chunk(c)).collect()
    };
    let mut partials = partials.into_iter();
    let mut bins = partials.next()?;
    for p in partials {
        for (a, b) in bins.iter_mut().zip(&p) {
            objective.merge(a, b);
        }
    }
    let mut parent = objective.empty_stats();
    for b in &bins[..offsets.get(1).copied().unwrap_or(total)] {
        objective.merge(&mut parent, b);
    }
    let n = objective.count(&parent);
    let e_parent = objective.impurity(&parent);
    let mut best: Option<Split<S::Feature>> = None;
    for (c, (feature, _)) in candidates.iter().enumerate() {
        let mut right = objective.empty_stats();
        for (k, &t) in sorted[c].iter().enumerate() {
            // Right: values <= t, the bins up to k.
            objective.merge(&mut right, &bins[offsets[c] + k]);
            let left = objective.minus(&parent, &right);
            let (nl, nr) = (objective.count(&left), objective.count(&right));
            if nl < 0.5 || nr < 0.5 {
                continue;
            }
            let gain = e_parent - (nl / n) * objective.impurity(&left) - (nr / n) * objective.impurity(&right);
            if best.as_ref().is_none_or(|b| gain > b.2) {
                best = Some((*feature, t, gain));
            }
        }
    }
    best
}

/// Moves the samples whose value is greater than the threshold to the front and returns how
/// many there are. The partition is stable: samples keep their relative order on each side,
/// so samples of the same image stay together and feature probes stay cache-friendly.
pub fn partition<S: SplitSpace>(space: &S, samples: &mut [u32], feature: &S::Feature, threshold: f32) -> usize {
    let mut right = Vec::with_capacity(samples.len() / 2);
    let mut left = 0;
    for i in 0..samples.len() {
        let s = samples[i];
        if space.value(s, feature) > threshold {
            samples[left] = s;
            left += 1;
        } else {
            right.push(s);
        }
    }
    samples[left..].copy_from_slice(&right);
    left
}

/// Grows trees into a tree's arrays (used for whole trees and for subtrees that
/// discriminative training grows at leaves).
#[allow(missing_debug_implementations)]
pub struct Grower<'a, S: SplitSpace, O: Objective> {
    pub space: &'a S,
    pub objective: &'a O,
    pub params: TrainParams,
    pub tree_index: usize,
}

impl<S: SplitSpace, O: Objective> Grower<'_, S, O> {
    /// Grows the subtree for `samples` at node `index` (which must exist) of `tree`.
    pub fn grow(&self, tree: &mut Tree<S::Feature, O::Leaf>, index: usize, samples: &mut [u32], depth: u32, path: u64) {
        let split = if depth < self.params.max_depth && samples.len() >= self.params.min_leaf.max(2) {
            let mut rng = node_rng(self.params.seed, self.tree_index, path);
            let scored = scoring_sample(samples, self.params.score_sample, &mut rng);
            let candidates = self.space.candidates(depth, &scored, self.params.tests, &mut rng);
            best_split(self.space, self.objective, &scored, &candidates).filter(|s| s.2 > 0.0)
        } else {
            None
        };
        let Some((feature, threshold, _)) = split else {
            self.make_leaf(tree, index, samples);
            return;
        };
        let n_left = partition(self.space, samples, &feature, threshold);
        if n_left == 0 || n_left == samples.len() {
            self.make_leaf(tree, index, samples);
            return;
        }
        let left = tree.nodes.len();
        let placeholder = Node {
            feature,
            threshold: 0.0,
            left: 0,
            leaf: NOT_LEAF,
        };
        tree.nodes.push(placeholder);
        tree.nodes.push(placeholder);
        tree.nodes[index] = Node {
            feature,
            threshold,
            left: left as u32,
            leaf: NOT_LEAF,
        };
        let (l, r) = samples.split_at_mut(n_left);
        self.grow(tree, left, l, depth + 1, path.wrapping_mul(2));
        self.grow(tree, left + 1, r, depth + 1, path.wrapping_mul(2).wrapping_add(1));
    }

    fn make_leaf(&self, tree: &mut Tree<S::Feature, O::Leaf>, index: usize, samples: &[u32]) {
        let leaf = tree.leaves.len() as u32;
        tree.leaves.push(self.objective.leaf(samples));
        let feature = tree.nodes[index].feature;
        tree.nodes[index] = Node {
            feature,
            threshold: 0.0,
            left: 0,
            leaf,
        };
    }
}

/// Trains one tree on `samples` (reordered in place). `root_feature` fills the root before it
/// is grown (any value of the feature type).
pub fn train_tree<S: SplitSpace, O: Objective>(
    space: &S,
    objective: &O,
    samples: &mut [u32],
    params: &TrainParams,
    tree_index: usize,
    root_feature: S::Feature,
) -> Tree<S::Feature, O::Leaf> {
    let mut tree = Tree {
        nodes: vec![Node {
            feature: root_feature,
            threshold: 0.0,
            left: 0,
            leaf: NOT_LEAF,
        }],
        leaves: Vec::new(),
    };
    let grower = Grower {
        space,
        objective,
        params: *params,
        tree_index,
    };
    grower.grow(&mut tree, 0, samples, 0, 1);
    tree
}

/// Trains a forest, tree `t` on `pools[t]`, trees in parallel.
pub fn train_forest<S: SplitSpace, O: Objective>(
    space: &S,
    objective: &O,
    pools: Vec<Vec<u32>>,
    params: &TrainParams,
    root_feature: S::Feature,
    progress: &(dyn Fn() + Sync),
) -> super::Forest<S::Feature, O::Leaf> {
    let trees = pools
        .into_par_iter()
        .enumerate()
        .map(|(t, mut pool)| {
            let tree = train_tree(space, objective, &mut pool, params, t, root_feature);
            progress();
            tree
        })
        .collect();
    super::Forest { trees }
}
