//! `mousepose train body|parts|paws`: the arguments, handed to [`crate::engine::train`], and
//! what was written printed with `--json`.

use crate::app::parse;
use crate::app::progress::Bars;
use crate::app::{ModelTarget, Outcome};
use crate::engine::train::{TrainOptions, TrainSummary};
use crate::vision::forest::discriminative::ErrorScope;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Which model.
    #[arg(value_enum)]
    pub target: ModelTarget,
    /// The training dataset (D_t); for paws, rendered views (optional with --labels, then
    /// mixed with the labelled frames).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    #[command(flatten)]
    pub labels: parse::LabelArgs,
    /// The model file to write.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Trees in the forest.
    #[arg(long, default_value_t = 7, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub trees: u32,
    /// Maximum tree depth (L).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub depth: u32,
    /// Random tests per split node (m).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// Fewest samples to split a node (l_n).
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=1_000_000))]
    pub leaf: u32,
    /// A second dataset (D_d) for the paper's discriminative training of the trained forest.
    #[arg(long, value_name = "DIR")]
    pub discriminative: Option<PathBuf>,
    /// Refine this trained baseline (trained on --data) instead of training one first.
    #[arg(long, value_name = "FILE", requires = "discriminative")]
    pub from: Option<PathBuf>,
    /// Passes of discriminative training.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub iterations: u32,
    /// Tree level where discriminative training starts.
    #[arg(long, default_value_t = 0)]
    pub start_level: u32,
    /// Fraction of D_d each tree sees (D'_d); it should hold about as many pixels as D_t, or
    /// the shrink rule coarsens the trees.
    #[arg(long, default_value_t = 0.5, value_parser = parse::subset, allow_negative_numbers = true)]
    pub subset: f64,
    /// Draw each tree's D'_d with replacement (`--subset` x |D_d| draws; a bootstrap sample
    /// at 1) instead of keeping each pixel of D_d with probability `--subset`.
    #[arg(long)]
    pub bootstrap: bool,
    /// In discriminative training, keep what D_t taught the leaves that stay leaves instead
    /// of refitting them to D'_d (the paper refits them).
    #[arg(long)]
    pub keep_leaves: bool,
    /// Refit the leaves (the default since the paper does; accepted for older scripts).
    #[arg(long, hide = true, conflicts_with = "keep_leaves")]
    pub refit_leaves: bool,
    /// In discriminative training, put each node's current test among its candidates,
    /// winning ties, so no node's error rises when its test is chosen (the paper draws
    /// fresh tests only).
    #[arg(long)]
    pub keep_current: bool,
    /// Which joints a body pixel's error E counts in discriminative training: all of them,
    /// as the paper defines E, or only those within the pixel's vote radius.
    #[arg(long, default_value = "all-joints", value_name = "all-joints|near-joints")]
    pub error: ErrorScope,
    /// Score each node's candidate tests on at most this many of its pixels, drawn at random
    /// (all of them are still routed by the chosen test); 0 scores them on all. Makes large
    /// test budgets such as the paper's 20,000 for part labels affordable.
    #[arg(long, default_value_t = 0)]
    pub score_pixels: usize,
    /// Mouse pixels drawn per training image.
    #[arg(long, default_value_t = 150, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub pixels: u32,
    /// Seed of the pixel draws and the random tests (paws: of the augmentation and the
    /// negatives' draws).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Cascade stages at most (paws).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=50))]
    pub stages: u32,
    /// Paws: the grouping the detector runs the cascade with (raw windows a detection needs
    /// beyond the first, as OpenCV's `minNeighbors`), kept in the cascade's file; choose it from
    /// `eval paws --labels --folds`' curve. The detector's default (1) when not given.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(0..=50))]
    pub min_neighbors: Option<u32>,
    /// Paws: train the small convolutional paw network instead of the cascade, from the
    /// labelled real frames (`--labels`) alone; `--out` then ends in `.safetensors`.
    #[arg(long, requires = "labels")]
    pub net: bool,
    #[command(flatten)]
    pub net_settings: parse::NetArgs,
    /// Replace the model file if it exists.
    #[arg(long)]
    pub force: bool,
    /// Print what was written as one JSON object (`out`, `kind`, the model's size,
    /// `training_seconds`).
    #[arg(long)]
    pub json: bool,
}

/// `mousepose train body|parts|paws`.
pub fn command(args: &TrainArgs) -> Outcome {
    let options = TrainOptions {
        target: args.target.into(),
        data: args.data.clone(),
        labels: args.labels.options().map_err(crate::engine::Failure::usage)?,
        out: args.out.clone(),
        trees: args.trees,
        depth: args.depth,
        tests: args.tests,
        leaf: args.leaf,
        discriminative: args.discriminative.clone(),
        from: args.from.clone(),
        iterations: args.iterations,
        start_level: args.start_level,
        subset: args.subset,
        bootstrap: args.bootstrap,
        keep_leaves: args.keep_leaves,
        keep_current: args.keep_current,
        error: args.error,
        score_pixels: args.score_pixels,
        pixels: args.pixels,
        seed: args.seed,
        stages: args.stages,
        min_neighbors: args.min_neighbors,
        net: args.net.then(|| args.net_settings.params(args.seed)),
        force: args.force,
    };
    let summary = crate::engine::train::train(&options, &Bars::default())?;
    if !args.json {
        return Ok(());
    }
    let json = match summary {
        TrainSummary::Forest {
            out,
            kind,
            trees,
            nodes,
            leaves,
            training_seconds,
            discriminative_tests_changed,
        } => serde_json::json!({
            "out": out,
            "kind": kind,
            "trees": trees,
            "nodes": nodes,
            "leaves": leaves,
            "training_seconds": training_seconds,
            "discriminative_tests_changed": discriminative_tests_changed,
        }),
        TrainSummary::Paws {
            out,
            stages,
            weak,
            features,
            hard_negative_windows,
            training_seconds,
        } => serde_json::json!({
            "out": out,
            "kind": "paws",
            "stages": stages,
            "weak": weak,
            "features": features,
            "hard_negative_windows": hard_negative_windows,
            "training_seconds": training_seconds,
        }),
        TrainSummary::PawNet {
            out,
            frames,
            iterations,
            width,
            training_seconds,
        } => serde_json::json!({
            "out": out,
            "kind": "paws",
            "network": true,
            "frames": frames,
            "iterations": iterations,
            "width": width,
            "training_seconds": training_seconds,
        }),
        TrainSummary::Orientation {
            out,
            views,
            training_accuracy,
            training_seconds,
        } => serde_json::json!({
            "out": out,
            "kind": "orientation",
            "views": views,
            "training_accuracy": training_accuracy,
            "training_seconds": training_seconds,
        }),
    };
    Ok(crate::app::output::print_json(&json)?)
}
