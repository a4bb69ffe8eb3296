//! Random forests as the paper builds them: binary trees stored as flat node arrays, generic
//! over what a split tests ([`SplitSpace`]) and what a leaf predicts ([`Objective`]), trained
//! with the paper's random tests and gain ([`train`]) and refined by its discriminative
//! training ([`discriminative`]).
//!
//! A split node sends a sample to its left child when the feature's value is greater than the
//! threshold, to the right child otherwise (the paper's convention). Children are stored next
//! to each other: `right == left + 1`.

pub mod classify;
pub mod depth;
pub mod discriminative;
pub mod infer;
pub mod leaf;
pub mod model;
mod packed;
pub mod simd;
pub mod train;

pub use packed::{PackedNode, PackedTree, Traversal};

use rand::Rng;
use serde::{Deserialize, Serialize};

/// Marks a node that is not a leaf.
pub const NOT_LEAF: u32 = u32::MAX;

/// One node of a tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node<F> {
    pub feature: F,
    pub threshold: f32,
    /// Index of the left child (the right one follows it); unused in leaves.
    pub left: u32,
    /// Index into the tree's leaves, or [`NOT_LEAF`].
    pub leaf: u32,
}

impl<F> Node<F> {
    pub fn is_leaf(&self) -> bool {
        self.leaf != NOT_LEAF
    }
}

/// A tree with a node whose child or leaf index points outside it ([`Tree::check`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("node {node} points outside the tree")]
pub struct BadTree {
    /// The node's index.
    pub node: usize,
}

/// A binary tree in two flat arrays: nodes (root first) and leaf payloads.
#[derive(Clone, Debug, PartialEq)]
pub struct Tree<F, L> {
    pub nodes: Vec<Node<F>>,
    pub leaves: Vec<L>,
}

impl<F: Copy, L> Tree<F, L> {
    /// The leaf a sample reaches, given the value of each feature for it.
    #[inline]
    pub fn leaf_index(&self, mut value: impl FnMut(&F) -> f32) -> usize {
        let mut i = 0usize;
        loop {
            let node = &self.nodes[i];
            if node.is_leaf() {
                return node.leaf as usize;
            }
            i = node.left as usize + usize::from(value(&node.feature) <= node.threshold);
        }
    }

    /// The leaf payload a sample reaches.
    #[inline]
    pub fn leaf(&self, value: impl FnMut(&F) -> f32) -> &L {
        &self.leaves[self.leaf_index(value)]
    }

    /// Whether the tree can be walked: every split node's children lie after it and inside
    /// the tree (so a walk always ends, inside it), every leaf's index inside the leaves and
    /// below 2^31 (what [`PackedTree`] can hold). A tree that training builds always can; a
    /// tree put together by hand or read from elsewhere may not.
    ///
    /// # Errors
    /// The first node that points outside the tree.
    pub fn check(&self) -> Result<(), BadTree> {
        for (i, n) in self.nodes.iter().enumerate() {
            let ok = if n.is_leaf() {
                (n.leaf as usize) < self.leaves.len() && n.leaf < packed::PACKED_LEAF
            } else {
                (n.left as usize) > i && (n.left as usize) + 1 < self.nodes.len()
            };
            if !ok {
                return Err(BadTree { node: i });
            }
        }
        Ok(())
    }

    /// The tree in the compact form that run-time traversal reads.
    ///
    /// # Errors
    /// As [`Self::check`]: a tree that cannot be walked is not packed.
    pub fn packed(&self) -> Result<PackedTree<F>, BadTree> {
        PackedTree::new(self)
    }

    /// Number of levels below the root of the deepest leaf.
    pub fn depth(&self) -> usize {
        fn walk<F, L>(t: &Tree<F, L>, i: usize) -> usize {
            let n = &t.nodes[i];
            if n.is_leaf() {
                0
            } else {
                1 + walk(t, n.left as usize).max(walk(t, n.left as usize + 1))
            }
        }
        if self.nodes.is_empty() { 0 } else { walk(self, 0) }
    }

    /// Rebuilds the arrays keeping only what the root reaches, in depth-first order.
    pub fn compact(&mut self)
    where
        L: Clone,
    {
        if self.nodes.is_empty() {
            return;
        }
        let mut nodes = Vec::with_capacity(self.nodes.len());
        let mut leaves = Vec::with_capacity(self.leaves.len());
        nodes.push(self.nodes[0]);
        // (new index, old index) of nodes whose children still need copying.
        let mut stack = vec![(0usize, 0usize)];
        while let Some((new_i, old_i)) = stack.pop() {
            let old = self.nodes[old_i];
            if old.is_leaf() {
                nodes[new_i].leaf = leaves.len() as u32;
                leaves.push(self.leaves[old.leaf as usize].clone());
                continue;
            }
            let left = nodes.len();
            nodes.push(self.nodes[old.left as usize]);
            nodes.push(self.nodes[old.left as usize + 1]);
            nodes[new_i].left = left as u32;
            stack.push((left + 1, old.left as usize + 1));
            stack.push((left, old.left as usize));
        }
        self.nodes = nodes;
        self.leaves = leaves;
    }
}

/// A forest: trees of the same kind.
#[derive(Clone, Debug, PartialEq)]
pub struct Forest<F, L> {
    pub trees: Vec<Tree<F, L>>,
}

/// What split nodes test: a feature with a value per sample, and how to draw random tests.
pub trait SplitSpace: Sync {
    type Feature: Copy + Send + Sync + std::fmt::Debug + PartialEq;

    /// The feature's value for a sample.
    fn value(&self, sample: u32, feature: &Self::Feature) -> f32;

    /// Draws `m` random candidate tests for a node at `depth` whose samples are `samples`:
    /// features with the thresholds to try for each.
    fn candidates(
        &self,
        depth: u32,
        samples: &[u32],
        m: usize,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Vec<(Self::Feature, Vec<f32>)>;
}

/// Thresholds drawn uniformly over `[lo, hi]`, the paper's rule for depth features.
pub fn uniform_thresholds(lo: f32, hi: f32, k: usize, rng: &mut impl Rng) -> Vec<f32> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return vec![lo];
    }
    (0..k).map(|_| rng.gen_range(lo..hi)).collect()
}

/// What leaves predict and how good a split or a prediction is.
pub trait Objective: Sync {
    /// Sufficient statistics of a set of samples, additive.
    type Stats: Clone + Send + Sync;
    type Leaf: Clone + Send + Sync;

    fn empty_stats(&self) -> Self::Stats;
    fn add(&self, stats: &mut Self::Stats, sample: u32);
    /// `a += b`.
    fn merge(&self, a: &mut Self::Stats, b: &Self::Stats);
    /// `a - b` where `b` is a subset of `a`.
    fn minus(&self, a: &Self::Stats, b: &Self::Stats) -> Self::Stats;
    fn count(&self, stats: &Self::Stats) -> f64;
    /// The impurity `E(S)` per sample: lower is more compact (entropy, or the spread of the
    /// joint offsets). The gain of a split is `E(S) - sum |S_i|/|S| E(S_i)`.
    fn impurity(&self, stats: &Self::Stats) -> f64;
    /// The leaf built from a set of samples.
    fn leaf(&self, samples: &[u32]) -> Self::Leaf;
    /// The leaf refitted to new samples (discriminative training); what the new samples say
    /// nothing about stays as in `old`.
    fn refit(&self, old: &Self::Leaf, samples: &[u32]) -> Self::Leaf;
    /// How wrong a leaf's prediction is for one sample (the paper's E is the inverse of the
    /// summed error): joint error in mm for regression, 0 or 1 for classification.
    fn error(&self, leaf: &Self::Leaf, sample: u32) -> f64;
}

/// Training parameters of the baseline method.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainParams {
    pub trees: usize,
    /// Maximum levels below the root (L).
    pub max_depth: u32,
    /// Random tests per split node (m).
    pub tests: usize,
    /// A node with fewer samples than this becomes a leaf (l_n).
    pub min_leaf: usize,
    pub seed: u64,
    /// Score a node's candidate tests on at most this many of its samples, drawn at random
    /// (all of them still go down the chosen test); 0 scores them on all.
    #[serde(default)]
    pub score_sample: usize,
}

impl Default for TrainParams {
    fn default() -> Self {
        Self {
            trees: 7,
            max_depth: 20,
            tests: 100,
            min_leaf: 60,
            seed: 0,
            score_sample: 0,
        }
    }
}

/// The samples a node's candidate tests are scored on: all of `samples`, or `bound` of them
/// drawn at random without replacement when there are more (kept in their order, so samples
/// of one image stay together). `rng` is used only when it draws.
pub fn scoring_sample<'s>(
    samples: &'s [u32],
    bound: usize,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> std::borrow::Cow<'s, [u32]> {
    if bound == 0 || samples.len() <= bound {
        return std::borrow::Cow::Borrowed(samples);
    }
    let mut picked = rand::seq::index::sample(rng, samples.len(), bound).into_vec();
    picked.sort_unstable();
    std::borrow::Cow::Owned(picked.into_iter().map(|i| samples[i]).collect())
}

/// The RNG of one node: a function of the seed, the tree and the node's path from the root
/// (1 for the root, then `2k` left and `2k + 1` right), so training is reproducible whatever
/// the thread count and order of work.
pub fn node_rng(seed: u64, tree: usize, path: u64) -> rand_chacha::ChaCha8Rng {
    crate::core::rng::item_rng(seed ^ 0xF0_4E57, tree as u64, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scoring_sample_is_bounded_ordered_and_drawn_from_the_node() {
        let samples: Vec<u32> = (0..1000).map(|i| i * 3).collect();
        let mut rng = node_rng(1, 0, 1);
        assert_eq!(*scoring_sample(&samples, 0, &mut rng), samples[..]);
        assert_eq!(*scoring_sample(&samples, 1000, &mut rng), samples[..]);
        let drawn = scoring_sample(&samples, 100, &mut rng);
        assert_eq!(drawn.len(), 100);
        assert!(drawn.windows(2).all(|w| w[0] < w[1]), "in order, no repeats");
        assert!(drawn.iter().all(|s| s % 3 == 0 && *s < 3000));
    }
}
