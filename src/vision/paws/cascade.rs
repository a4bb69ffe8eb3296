//! A trained cascade held in memory: stages of boosted weak trees over Haar features, and the
//! classification of one window exactly as OpenCV's cascade evaluator classifies it.

use super::haar::{HaarFeature, window_norm};
use super::integral::Integral;

/// One node of a weak tree: `value < threshold` goes left. A child index `<= 0` names the
/// leaf `-child`; a positive one names another node of the same tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    pub left: i32,
    pub right: i32,
    pub feature: usize,
    pub threshold: f32,
}

/// A weak classifier: a small tree (a stump has one node and two leaves).
#[derive(Clone, Debug, PartialEq)]
pub struct WeakTree {
    pub nodes: Vec<Node>,
    pub leaves: Vec<f32>,
}

impl WeakTree {
    /// A decision stump: `left` below `threshold`, `right` at or above it.
    pub fn stump(feature: usize, threshold: f32, left: f32, right: f32) -> Self {
        Self {
            nodes: vec![Node {
                left: 0,
                right: -1,
                feature,
                threshold,
            }],
            leaves: vec![left, right],
        }
    }
}

/// OpenCV lowers every stage threshold it reads by this much (in single precision).
pub const STAGE_EPS: f32 = 1e-5;

/// One stage: the window passes when the sum of its weak trees' leaves reaches `threshold`
/// (as stored in the file) less [`STAGE_EPS`], as OpenCV applies it.
#[derive(Clone, Debug, PartialEq)]
pub struct BoostStage {
    pub threshold: f32,
    pub weak: Vec<WeakTree>,
}

impl BoostStage {
    /// The threshold a window's sum is compared with, in double precision.
    pub fn applied_threshold(&self) -> f64 {
        applied_threshold(self.threshold)
    }
}

/// The threshold OpenCV applies for a stored stage threshold.
pub fn applied_threshold(stored: f32) -> f64 {
    f64::from(stored - STAGE_EPS)
}

/// What the cascade was trained with, written to and read from the XML's `stageParams` and
/// `featureParams` (informative only: detection does not use them).
#[derive(Clone, Debug, PartialEq)]
pub struct CascadeParams {
    /// `GAB` (Gentle AdaBoost), `DAB`, `RAB` or `LB`.
    pub boost_type: String,
    pub min_hit_rate: f32,
    pub max_false_alarm: f32,
    pub weight_trim_rate: f32,
    pub max_depth: u32,
    pub max_weak_count: u32,
    /// `BASIC`, `CORE` or `ALL`.
    pub mode: String,
}

impl Default for CascadeParams {
    fn default() -> Self {
        Self {
            boost_type: "GAB".to_owned(),
            min_hit_rate: 0.995,
            max_false_alarm: 0.5,
            weight_trim_rate: 0.95,
            max_depth: 1,
            max_weak_count: 100,
            mode: "BASIC".to_owned(),
        }
    }
}

/// A boosted cascade of Haar-feature classifiers over a `width x height` window.
#[derive(Clone, Debug, PartialEq)]
pub struct Cascade {
    pub width: u32,
    pub height: u32,
    pub params: CascadeParams,
    pub stages: Vec<BoostStage>,
    pub features: Vec<HaarFeature>,
    /// The grouping its trainer chose (raw windows a detection needs beyond the first, as
    /// OpenCV's `minNeighbors`), kept in the XML after the cascade where OpenCV does not look
    /// ([`super::xml`]); the detector's default when `None`.
    pub min_neighbors: Option<u32>,
}

/// A window's fate: rejected by its contrast, rejected at a stage, or accepted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// Too flat to classify (standard deviation of 10 grey levels or less).
    Flat,
    /// Rejected by stage `stage` (0-based).
    Rejected { stage: usize },
    /// Passed every stage; `margin` is the last stage's sum minus its threshold (>= 0).
    Accepted { margin: f64 },
}

impl Cascade {
    /// Keeps the first `n` stages (and only the features they use).
    pub fn truncated(&self, n: usize) -> Cascade {
        let mut out = self.clone();
        out.stages.truncate(n);
        out.compact_features();
        out
    }

    /// Drops features no weak tree uses and renumbers the rest in order of first use.
    pub fn compact_features(&mut self) {
        let mut map = vec![usize::MAX; self.features.len()];
        let mut kept = Vec::new();
        for stage in &mut self.stages {
            for tree in &mut stage.weak {
                for node in &mut tree.nodes {
                    if map[node.feature] == usize::MAX {
                        map[node.feature] = kept.len();
                        kept.push(self.features[node.feature].clone());
                    }
                    node.feature = map[node.feature];
                }
            }
        }
        self.features = kept;
    }

    /// The largest number of nodes of any weak tree (1 for stumps).
    pub fn max_nodes(&self) -> usize {
        self.stages
            .iter()
            .flat_map(|s| s.weak.iter().map(|t| t.nodes.len()))
            .max()
            .unwrap_or(1)
    }

    /// Classifies the window whose top-left corner is `(x, y)` of `ii`, with OpenCV's
    /// arithmetic (features in single precision, stage sums in double precision).
    pub fn classify(&self, ii: &Integral, x: usize, y: usize) -> Verdict {
        let (factor, ok) = window_norm(ii, x, y, self.width as usize, self.height as usize);
        if !ok {
            return Verdict::Flat;
        }
        let mut margin = 0.0;
        for (k, stage) in self.stages.iter().enumerate() {
            let mut sum = 0.0f64;
            for tree in &stage.weak {
                sum += f64::from(tree_value(tree, &self.features, ii, x, y, factor));
            }
            let threshold = stage.applied_threshold();
            if sum < threshold {
                return Verdict::Rejected { stage: k };
            }
            margin = sum - threshold;
        }
        Verdict::Accepted { margin }
    }
}

/// The leaf a tree gives the window at `(x, y)`.
#[inline]
fn tree_value(tree: &WeakTree, features: &[HaarFeature], ii: &Integral, x: usize, y: usize, factor: f32) -> f32 {
    let mut idx = 0i32;
    loop {
        let node = &tree.nodes[idx as usize];
        let value = features[node.feature].raw(ii, x, y) * factor;
        idx = if value < node.threshold { node.left } else { node.right };
        if idx <= 0 {
            return tree.leaves[(-idx) as usize];
        }
    }
}
