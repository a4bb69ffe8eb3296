//! `mousepose train body|parts|paws|orientation`: forests, the paw cascade and the orientation
//! model from synthetic datasets.

use crate::app::progress;
use crate::app::{Exists, Failure, Outcome, parse_subset};
use crate::training::{self, PixelParams, Target, TrainJob, TrainProgress};
use crate::vision::forest::discriminative::{DiscriminativeParams, ErrorScope, Scoring};
use crate::vision::forest::model::{self, Model, ModelKind};
use crate::vision::forest::{Forest, TrainParams};
use anyhow::{Context, Result};
use clap::Args;
use indicatif::ProgressBar;
use std::path::PathBuf;

/// What `train` and `eval` work on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModelTarget {
    /// The body forest: joints 1-12 from the top depth image.
    Body,
    /// The part forest: six body-part labels per depth pixel.
    Parts,
    /// The paw detector: a boosted cascade of Haar features on the bottom colour view,
    /// stored as OpenCV cascade XML.
    Paws,
    /// Which end of the mouse is its head from the shape of its body seen from above: a
    /// logistic model on the silhouette and height profile along the body, learnt from the
    /// dataset's mice with their tails hidden and shown (JSON, a few KB).
    Orientation,
}

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Which model.
    #[arg(value_enum)]
    pub target: ModelTarget,
    /// The training dataset (D_t).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
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
    #[arg(long, default_value_t = 0.5, value_parser = parse_subset, allow_negative_numbers = true)]
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
    /// Replace the model file if it exists.
    #[arg(long)]
    pub force: bool,
    /// Print what was written as one JSON object (`out`, `kind`, the model's size,
    /// `training_seconds`).
    #[arg(long)]
    pub json: bool,
}

struct Bar(ProgressBar);

impl TrainProgress for Bar {
    fn stage(&self, what: &str, total: u64) {
        self.0.set_message(what.to_owned());
        self.0.set_length(total);
        self.0.set_position(0);
    }

    fn tick(&self) {
        self.0.inc(1);
    }
}

/// `mousepose train body|parts|paws`.
pub fn run(args: &TrainArgs) -> Outcome {
    if args.out.exists() && !args.force {
        return Err(Failure::usage(Exists(args.out.clone())));
    }
    if args.target == ModelTarget::Paws {
        return Ok(train_paws(args)?);
    }
    if args.target == ModelTarget::Orientation {
        return Ok(train_orientation(args)?);
    }
    let params = TrainParams {
        trees: args.trees as usize,
        max_depth: args.depth,
        tests: args.tests as usize,
        min_leaf: args.leaf as usize,
        seed: args.seed,
        score_sample: args.score_pixels,
    };
    let job = TrainJob {
        target: match args.target {
            ModelTarget::Body => Target::Body,
            ModelTarget::Parts | ModelTarget::Paws | ModelTarget::Orientation => Target::Parts,
        },
        train: &args.data,
        discriminative: args.discriminative.as_deref(),
        params,
        disc: DiscriminativeParams {
            tests: params.tests,
            min_leaf: params.min_leaf,
            start_level: args.start_level,
            iterations: args.iterations as usize,
            subset: args.subset,
            bootstrap: args.bootstrap,
            refit_leaves: !args.keep_leaves,
            keep_current: args.keep_current,
            error: args.error,
            scoring: Scoring::SubtreeError,
            score_sample: params.score_sample,
            max_depth: params.max_depth,
            seed: args.seed ^ 0xD15C,
        },
        pixels: PixelParams {
            per_image: args.pixels as usize,
            thresholds: 12,
            seed: args.seed,
        },
        from: match &args.from {
            Some(path) => {
                let kind = match args.target {
                    ModelTarget::Body => ModelKind::Body,
                    ModelTarget::Parts | ModelTarget::Paws | ModelTarget::Orientation => ModelKind::Parts,
                };
                Some(model::load(path, Some(kind))?)
            }
            None => None,
        },
    };
    let bar = Bar(progress::bar(0, "loading"));
    let (model, passes) = training::train(&job, &bar).context("training")?;
    bar.0.finish_and_clear();
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    model::save(&model, &args.out)?;
    let info = model.info();
    let (trees, nodes, leaves) = match &model {
        Model::Body(_, f) => counts(f),
        Model::Parts(_, f) => counts(f),
    };
    let changed: usize = passes.iter().map(|p| p.tests_changed).sum();
    if args.json {
        crate::app::print_json(&serde_json::json!({
            "out": args.out,
            "kind": match args.target {
                ModelTarget::Body => "body",
                ModelTarget::Parts | ModelTarget::Paws | ModelTarget::Orientation => "parts",
            },
            "trees": trees,
            "nodes": nodes,
            "leaves": leaves,
            "training_seconds": info.training_seconds,
            "discriminative_tests_changed": changed,
        }))?;
    }
    tracing::info!(
        message = "Model written.",
        path = %args.out.display(),
        kind = info.kind.name(),
        trees,
        nodes,
        leaves,
        seconds = format!("{:.0}", info.training_seconds),
        discriminative_tests_changed = changed,
    );
    Ok(())
}

fn counts<F, L>(f: &Forest<F, L>) -> (usize, usize, usize) {
    (
        f.trees.len(),
        f.trees.iter().map(|t| t.nodes.len()).sum(),
        f.trees.iter().map(|t| t.leaves.len()).sum(),
    )
}

/// The training parameters `train paws` uses besides its arguments.
fn paw_params(args: &TrainArgs) -> crate::vision::paws::train::TrainParams {
    crate::vision::paws::train::TrainParams {
        stages: args.stages as usize,
        seed: args.seed,
        ..crate::vision::paws::train::TrainParams::default()
    }
}

/// Augmented copies of each paw window besides the plain one.
const PAW_AUGMENT: usize = 3;
/// Hard negative windows cut around each of a view's look-alikes of paws.
const HARD_PER_PLACE: usize = 2;

/// `mousepose train paws`.
fn train_paws(args: &TrainArgs) -> Result<()> {
    use crate::training::paws_data as data;
    use crate::vision::paws::{WINDOW_PX, train, xml};
    let set = data::load(
        &args.data,
        data::CutParams {
            width: WINDOW_PX as usize,
            height: WINDOW_PX as usize,
            augment: PAW_AUGMENT,
            hard_per_place: HARD_PER_PLACE,
            seed: args.seed,
        },
    )
    .with_context(|| format!("reading training dataset {:?}", args.data))?;
    tracing::info!(
        message = "Training windows cut.",
        paws = set.paws,
        positives = set.positive_count(),
        hard_negatives = set.hard_count(),
        backgrounds = set.backgrounds.len(),
    );
    let params = paw_params(args);
    let bar = progress::bar(params.stages as u64, "stages");
    let started = std::time::Instant::now();
    let trained = train::train(&set, &params, &mut |r| {
        bar.inc(1);
        bar.set_message(format!("fa {:.4}", r.false_alarm));
        tracing::debug!(
            message = "Stage trained.",
            stage = r.stage,
            positives = r.positives,
            negatives = r.negatives,
            hard_negatives = r.hard_negatives,
            weak = r.weak,
            hit_rate = r.hit_rate,
            false_alarm = r.false_alarm,
            windows_scanned = r.windows_scanned,
            windows_accepted = r.windows_accepted,
        );
    })
    .context("training the paw cascade")?;
    bar.finish_and_clear();
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    xml::save(&trained.cascade, &args.out)?;
    let weak: usize = trained.cascade.stages.iter().map(|s| s.weak.len()).sum();
    if let train::StopReason::NoNegatives { found, scanned } = &trained.stop {
        tracing::info!(
            message = "Training stopped early: the backgrounds no longer yield enough windows the cascade accepts.",
            found,
            scanned,
        );
    }
    let last = trained.stages.last();
    if args.json {
        crate::app::print_json(&serde_json::json!({
            "out": args.out,
            "kind": "paws",
            "stages": trained.cascade.stages.len(),
            "weak": weak,
            "features": trained.cascade.features.len(),
            "hard_negative_windows": set.hard_count(),
            "training_seconds": started.elapsed().as_secs_f64(),
        }))?;
    }
    tracing::info!(
        message = "Paw cascade written.",
        path = %args.out.display(),
        stages = trained.cascade.stages.len(),
        weak,
        features = trained.cascade.features.len(),
        flat_positives = trained.flat_positives,
        last_acceptance = last.map_or(0.0, |r| r.windows_accepted as f64 / r.windows_scanned.max(1) as f64),
        seconds = format!("{:.0}", started.elapsed().as_secs_f64()),
    );
    Ok(())
}

/// L2 penalty on the orientation model's scaled weights.
const ORIENTATION_L2: f64 = 1.0;

fn train_orientation(args: &TrainArgs) -> Result<()> {
    use crate::training::orientation::views;
    use crate::vision::body_shape::{Provenance, ShapeModel};
    let (ds, samples) =
        training::load(&args.data).with_context(|| format!("reading training dataset {:?}", args.data))?;
    if samples.is_empty() {
        anyhow::bail!("training dataset {:?} has no images", args.data);
    }
    let rig = ds.meta.rig.unwrap_or_else(crate::core::geometry::Rig::default_rig);
    let views = views(&samples, &rig, args.seed).context("segmenting the dataset's mice")?;
    let labelled: Vec<_> = views.iter().map(|v| (v.features, v.head_plus)).collect();
    let provenance = Provenance {
        dataset_seed: ds.meta.seed,
        images: samples.len() as u64,
        engine_version: ds.meta.engine_version,
        views: labelled.len(),
        training_accuracy: 0.0,
    };
    let started = std::time::Instant::now();
    let mut model = ShapeModel::fit(&labelled, ORIENTATION_L2, provenance);
    model.provenance.training_accuracy = model.accuracy(&labelled);
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    model
        .save(&args.out)
        .with_context(|| format!("writing {:?}", args.out))?;
    if args.json {
        crate::app::print_json(&serde_json::json!({
            "out": args.out,
            "kind": "orientation",
            "views": labelled.len(),
            "training_accuracy": model.provenance.training_accuracy,
            "training_seconds": started.elapsed().as_secs_f64(),
        }))?;
    }
    tracing::info!(
        message = "Orientation model written.",
        path = %args.out.display(),
        views = labelled.len(),
        training_accuracy = format!("{:.4}", model.provenance.training_accuracy),
    );
    Ok(())
}
