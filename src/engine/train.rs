//! The engine of `mousepose train body|parts|paws|orientation`: forests, the paw cascade and the
//! orientation model from synthetic datasets.

use crate::engine::progress::Progress;
use crate::engine::{Exists, Failure};
use crate::training::paws_real::RealViews;
use crate::training::{self, PixelParams, Target, TrainJob, TrainProgress};
use crate::vision::forest::discriminative::{DiscriminativeParams, ErrorScope, Scoring};
use crate::vision::forest::model::{self, Model, ModelKind};
use crate::vision::forest::{Forest, TrainParams};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// What `train` and `eval` work on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelTarget {
    /// The body forest: joints 1-12 from the top depth image.
    Body,
    /// The part forest: six body-part labels per depth pixel.
    Parts,
    /// The paw detector: a boosted cascade of Haar features on the bottom colour view.
    Paws,
    /// Which end of the mouse is its head from the shape of its body seen from above: a
    /// logistic model on the silhouette and height profile along the body, learnt from the
    /// dataset's mice with their tails hidden and shown (JSON, a few KB).
    Orientation,
}

/// What `train` trains, on what, and where it writes it (see its `--help`).
#[derive(Clone, Debug)]
pub struct TrainOptions {
    pub target: ModelTarget,
    /// The training dataset (D_t); for paws, renders mixed with `labels` (either or both).
    pub data: Option<PathBuf>,
    /// Paws: real frames a lab labelled.
    pub labels: Option<LabelOptions>,
    /// The model file to write.
    pub out: PathBuf,
    pub trees: u32,
    pub depth: u32,
    pub tests: u32,
    pub leaf: u32,
    /// A second dataset (D_d) for discriminative training.
    pub discriminative: Option<PathBuf>,
    /// Refine this trained baseline instead of training one first.
    pub from: Option<PathBuf>,
    pub iterations: u32,
    pub start_level: u32,
    pub subset: f64,
    pub bootstrap: bool,
    pub keep_leaves: bool,
    pub keep_current: bool,
    pub error: ErrorScope,
    pub score_pixels: usize,
    pub pixels: u32,
    pub seed: u64,
    /// Cascade stages at most (paws).
    pub stages: u32,
    /// Paws: the grouping kept in the cascade's file ([`crate::vision::paws::Cascade::min_neighbors`]).
    pub min_neighbors: Option<u32>,
    /// Paws: train the network with these settings instead of the cascade.
    pub net: Option<training::paws_net::NetParams>,
    /// Replace the model file if it exists.
    pub force: bool,
}

/// Real frames a lab labelled, for `train paws` and `eval paws`.
#[derive(Clone, Debug)]
pub struct LabelOptions {
    /// DeepLabCut's `CollectedData_*.csv`.
    pub file: PathBuf,
    /// `NAME=PAW,...`; guessed from the body parts' names when `None`.
    pub map: Option<String>,
    /// Pixels per millimetre of the frames' bottom view.
    pub px_per_mm: f64,
    /// The first row of the bottom view; found from the labels when `None`.
    pub view_top: Option<u32>,
}

impl LabelOptions {
    /// Reads the label file and its frames.
    ///
    /// # Errors
    /// One sentence naming the file and what is wrong ([`RealViews::open`]).
    pub fn open(&self) -> Result<RealViews, Failure> {
        let views = RealViews::open(&self.file, self.map.as_deref(), self.px_per_mm, self.view_top)
            .map_err(|e| Failure::usage(anyhow::Error::new(e)))?;
        tracing::info!(
            message = "Labelled frames read.",
            file = %self.file.display(),
            frames = views.frames.len(),
            paws = views.paw_count(&(0..views.frames.len()).collect::<Vec<_>>()),
            bottom_view = %views.view_top_how,
        );
        Ok(views)
    }
}

/// What `train` wrote.
#[derive(Clone, Debug)]
pub enum TrainSummary {
    /// A forest: `kind` is `body` or `parts`.
    Forest {
        out: PathBuf,
        kind: &'static str,
        trees: usize,
        nodes: usize,
        leaves: usize,
        training_seconds: f64,
        discriminative_tests_changed: usize,
    },
    /// The paw cascade.
    Paws {
        out: PathBuf,
        stages: usize,
        weak: usize,
        features: usize,
        hard_negative_windows: usize,
        training_seconds: f64,
    },
    /// The paw network.
    PawNet {
        out: PathBuf,
        /// Labelled frames it learnt from.
        frames: usize,
        iterations: usize,
        width: usize,
        training_seconds: f64,
    },
    /// The orientation model.
    Orientation {
        out: PathBuf,
        views: usize,
        training_accuracy: f64,
        training_seconds: f64,
    },
}

/// The engine's progress as the forest trainer reports it: each stage a label and a count.
struct Stages<'a>(&'a dyn Progress);

impl TrainProgress for Stages<'_> {
    fn stage(&self, what: &str, total: u64) {
        self.0.label(what);
        self.0.set_total(total);
        self.0.set_done(0);
    }

    fn tick(&self) {
        self.0.advance(1);
    }
}

/// `mousepose train body|parts|paws`: trains the model and writes it to `options.out`.
///
/// # Errors
/// A model file in the way (the user's), or a dataset or model that cannot be read or written.
pub fn train(options: &TrainOptions, progress: &dyn Progress) -> Result<TrainSummary, Failure> {
    if options.out.exists() && !options.force {
        return Err(Failure::usage(Exists(options.out.clone())));
    }
    if options.target == ModelTarget::Paws {
        return train_paws(options, progress);
    }
    if options.labels.is_some() || options.min_neighbors.is_some() {
        return Err(Failure::usage(anyhow::anyhow!(
            "--labels and --min-neighbors are for paws only (the body, part and orientation models learn from renders)"
        )));
    }
    let Some(data) = &options.data else {
        return Err(Failure::usage(anyhow::anyhow!(
            "train needs --data DIR, the training dataset"
        )));
    };
    if options.target == ModelTarget::Orientation {
        return Ok(train_orientation(options, data)?);
    }
    let params = TrainParams {
        trees: options.trees as usize,
        max_depth: options.depth,
        tests: options.tests as usize,
        min_leaf: options.leaf as usize,
        seed: options.seed,
        score_sample: options.score_pixels,
    };
    let job = TrainJob {
        target: match options.target {
            ModelTarget::Body => Target::Body,
            ModelTarget::Parts | ModelTarget::Paws | ModelTarget::Orientation => Target::Parts,
        },
        train: data,
        discriminative: options.discriminative.as_deref(),
        params,
        disc: DiscriminativeParams {
            tests: params.tests,
            min_leaf: params.min_leaf,
            start_level: options.start_level,
            iterations: options.iterations as usize,
            subset: options.subset,
            bootstrap: options.bootstrap,
            refit_leaves: !options.keep_leaves,
            keep_current: options.keep_current,
            error: options.error,
            scoring: Scoring::SubtreeError,
            score_sample: params.score_sample,
            max_depth: params.max_depth,
            seed: options.seed ^ 0xD15C,
        },
        pixels: PixelParams {
            per_image: options.pixels as usize,
            thresholds: 12,
            seed: options.seed,
        },
        from: match &options.from {
            Some(path) => {
                let kind = match options.target {
                    ModelTarget::Body => ModelKind::Body,
                    ModelTarget::Parts | ModelTarget::Paws | ModelTarget::Orientation => ModelKind::Parts,
                };
                Some(model::load(path, Some(kind))?)
            }
            None => None,
        },
    };
    progress.start("loading", 0);
    let (model, passes) = training::train(&job, &Stages(progress)).context("training")?;
    progress.finish();
    if let Some(parent) = options.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    model::save(&model, &options.out)?;
    let info = model.info();
    let (trees, nodes, leaves) = match &model {
        Model::Body(_, f) => counts(f),
        Model::Parts(_, f) => counts(f),
    };
    let changed: usize = passes.iter().map(|p| p.tests_changed).sum();
    tracing::info!(
        message = "Model written.",
        path = %options.out.display(),
        kind = info.kind.name(),
        trees,
        nodes,
        leaves,
        seconds = format!("{:.0}", info.training_seconds),
        discriminative_tests_changed = changed,
    );
    Ok(TrainSummary::Forest {
        out: options.out.clone(),
        kind: match options.target {
            ModelTarget::Body => "body",
            ModelTarget::Parts | ModelTarget::Paws | ModelTarget::Orientation => "parts",
        },
        trees,
        nodes,
        leaves,
        training_seconds: info.training_seconds,
        discriminative_tests_changed: changed,
    })
}

fn counts<F, L>(f: &Forest<F, L>) -> (usize, usize, usize) {
    (
        f.trees.len(),
        f.trees.iter().map(|t| t.nodes.len()).sum(),
        f.trees.iter().map(|t| t.leaves.len()).sum(),
    )
}

/// Augmented copies of each paw window besides the plain one.
const PAW_AUGMENT: usize = 3;
/// Hard negative windows cut around each of a view's look-alikes of paws.
const HARD_PER_PLACE: usize = 2;
/// The colour binnings training views are seen at: the full sensor, 2x2 and 4x4, as small
/// rigs and the fixture sessions bin it (at 2x2 the Bayer blocks are the canonical scale's
/// pixels; the detector enlarges 4x4's 0.5 px/mm views, blurring paws).
const PAW_BINNINGS: &[u32] = &[1, 2, 4];
/// Each stage keeps this share of the paws it is trained on: blurred paws of binned views are
/// the ones the stages lose first (at OpenCV's 0.995, 20 stages found 78 % of the paws of
/// views binned 4x4 and 99.6 % at full size; at 0.998 and 25 stages 88 % and 99.8 %).
const PAW_MIN_HIT_RATE: f64 = 0.998;

/// Augmented copies of each labelled real paw besides the plain one, at least: a lab labels a
/// few hundred paws.
const REAL_PAW_AUGMENT: usize = 15;

/// Hard negative windows cut around each body part a lab labelled in the bottom view that is
/// not a paw (the nose, the tail): a few labelled frames give few places.
const REAL_HARD_PER_PLACE: usize = 8;

/// The cutting of paw windows: `augment` copies of each paw, `hard_per_place` windows around
/// each look-alike.
fn paw_cut(augment: usize, hard_per_place: usize, seed: u64) -> training::paws_data::CutParams {
    training::paws_data::CutParams {
        width: crate::vision::paws::WINDOW_PX as usize,
        height: crate::vision::paws::WINDOW_PX as usize,
        augment,
        hard_per_place,
        binnings: PAW_BINNINGS,
        seed,
    }
}

/// The rendered bottom views of the dataset `dir` cut into paw training material.
///
/// # Errors
/// A dataset that cannot be read or holds no paw.
pub fn render_material(dir: &std::path::Path, seed: u64) -> Result<crate::vision::paws::train::TrainingSet> {
    training::paws_data::load(dir, paw_cut(PAW_AUGMENT, HARD_PER_PLACE, seed))
        .with_context(|| format!("reading training dataset {dir:?}"))
}

/// The rendered views of the dataset `dir` as the paw network learns them.
///
/// # Errors
/// The dataset cannot be read, or holds no visible paw on the glass.
pub fn render_views(dir: &std::path::Path) -> Result<Vec<training::paws_net::NetView>> {
    training::paws_net::render_views(dir).with_context(|| format!("reading training dataset {dir:?}"))
}

/// The paw cascade's training material: `renders` ([`render_material`]) and the labelled real
/// frames `which` of `real`, together. Mixed, each real paw is copied (turned, resized,
/// shifted) until the real paws give about as many positives as the renders: a lab's few
/// hundred paws weigh as much as the renders' thousands.
///
/// # Errors
/// Labelled frames that hold no paw.
pub fn paw_material(
    renders: Option<&crate::vision::paws::train::TrainingSet>,
    real: Option<(&RealViews, &[usize])>,
    seed: u64,
) -> Result<crate::vision::paws::train::TrainingSet> {
    let mut set = renders.cloned().unwrap_or_default();
    if let Some((views, which)) = real {
        let balanced = set.positive_count() / views.paw_count(which).max(1);
        let augment = REAL_PAW_AUGMENT.max(balanced.saturating_sub(1));
        let more = views
            .material(which, paw_cut(augment, REAL_HARD_PER_PLACE, seed))
            .with_context(|| format!("cutting the labelled frames of {:?}", views.labels.path))?;
        set.append(more);
    }
    tracing::info!(
        message = "Training windows cut.",
        paws = set.paws,
        positives = set.positive_count(),
        hard_negatives = set.hard_count(),
        backgrounds = set.backgrounds.len(),
    );
    Ok(set)
}

/// Trains the paw cascade on `set`, its stages counted on `progress`.
///
/// # Errors
/// When training stops for want of positives.
pub fn fit_paw_cascade(
    set: &crate::vision::paws::train::TrainingSet,
    stages: u32,
    seed: u64,
    progress: &dyn Progress,
) -> Result<crate::vision::paws::train::Trained> {
    use crate::vision::paws::train;
    let params = train::TrainParams {
        stages: stages as usize,
        seed,
        min_hit_rate: PAW_MIN_HIT_RATE,
        ..train::TrainParams::default()
    };
    progress.start("stages", params.stages as u64);
    let trained = train::train(set, &params, &mut |r| {
        progress.advance(1);
        progress.label(&format!("fa {:.4}", r.false_alarm));
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
    progress.finish();
    if let train::StopReason::NoNegatives { found, scanned } = &trained.stop {
        tracing::info!(
            message = "Training stopped early: the backgrounds no longer yield enough windows the cascade accepts.",
            found,
            scanned,
        );
    }
    Ok(trained)
}

/// Trains the paw network on the labelled frames `which` of `views` and the rendered views
/// `renders` ([`training::paws_net::render_views`]; none, real frames only), its iterations
/// counted on `progress` with the loss's running mean.
///
/// # Errors
/// The frames hold no labelled paw, or the training's arithmetic fails.
pub fn fit_paw_net(
    views: &RealViews,
    which: &[usize],
    renders: &[training::paws_net::NetView],
    params: &training::paws_net::NetParams,
    progress: &dyn Progress,
) -> Result<crate::vision::paws::net::PawNet> {
    let material = training::paws_net::real_views(views, which);
    // candle makes and frees a tensor of up to a few megabytes per operation, which glibc
    // would map and unmap each time: two thirds of the training's time went to the kernel
    // faulting those pages in again. Kept, they are reused (the same network, three times
    // sooner); this process only trains and ends.
    glibc_malloc::keep_freed(32 << 20, 512 << 20);
    progress.start("iterations", params.iterations as u64);
    let net = training::paws_net::train(&material, renders, params, &mut |done, loss| {
        progress.advance(1);
        if done % 50 == 0 {
            progress.label(&format!("loss {loss:.3}"));
        }
    })
    .context("training the paw network")?;
    progress.finish();
    Ok(net)
}

/// `mousepose train paws`.
fn train_paws(options: &TrainOptions, progress: &dyn Progress) -> Result<TrainSummary, Failure> {
    use crate::vision::paws::xml;
    if let Some(params) = &options.net {
        return train_paw_net(options, params, progress);
    }
    let real = options.labels.as_ref().map(LabelOptions::open).transpose()?;
    if options.data.is_none() && real.is_none() {
        return Err(Failure::usage(anyhow::anyhow!(
            "train paws needs --data DIR (rendered views), --labels FILE (real frames a lab labelled) or both"
        )));
    }
    let all: Vec<usize> = real.as_ref().map_or_else(Vec::new, |v| (0..v.frames.len()).collect());
    let renders = options
        .data
        .as_deref()
        .map(|dir| render_material(dir, options.seed))
        .transpose()?;
    let set = paw_material(
        renders.as_ref(),
        real.as_ref().map(|v| (v, all.as_slice())),
        options.seed,
    )?;
    let started = std::time::Instant::now();
    let mut trained = fit_paw_cascade(&set, options.stages, options.seed, progress)?;
    trained.cascade.min_neighbors = options.min_neighbors;
    if let Some(parent) = options.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    xml::save(&trained.cascade, &options.out)?;
    let weak: usize = trained.cascade.stages.iter().map(|s| s.weak.len()).sum();
    let last = trained.stages.last();
    let training_seconds = started.elapsed().as_secs_f64();
    tracing::info!(
        message = "Paw cascade written.",
        path = %options.out.display(),
        stages = trained.cascade.stages.len(),
        weak,
        features = trained.cascade.features.len(),
        flat_positives = trained.flat_positives,
        last_acceptance = last.map_or(0.0, |r| r.windows_accepted as f64 / r.windows_scanned.max(1) as f64),
        seconds = format!("{:.0}", training_seconds),
    );
    Ok(TrainSummary::Paws {
        out: options.out.clone(),
        stages: trained.cascade.stages.len(),
        weak,
        features: trained.cascade.features.len(),
        hard_negative_windows: set.hard_count(),
        training_seconds,
    })
}

/// `mousepose train paws --net`: the network from every labelled frame.
fn train_paw_net(
    options: &TrainOptions,
    params: &training::paws_net::NetParams,
    progress: &dyn Progress,
) -> Result<TrainSummary, Failure> {
    let Some(labels) = &options.labels else {
        return Err(Failure::usage(anyhow::anyhow!(
            "train paws --net learns from labelled real frames: give --labels FILE"
        )));
    };
    if options.out.extension().is_none_or(|e| e != "safetensors") {
        return Err(Failure::usage(anyhow::anyhow!(
            "train paws --net writes a safetensors file: name --out FILE.safetensors, not {:?}",
            options.out
        )));
    }
    let views = labels.open()?;
    let renders = options
        .data
        .as_deref()
        .map(render_views)
        .transpose()?
        .unwrap_or_default();
    let all: Vec<usize> = (0..views.frames.len()).collect();
    let started = std::time::Instant::now();
    let net = fit_paw_net(&views, &all, &renders, params, progress)?;
    if let Some(parent) = options.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    net.save(&options.out)?;
    let training_seconds = started.elapsed().as_secs_f64();
    tracing::info!(
        message = "Paw network written.",
        path = %options.out.display(),
        frames = all.len(),
        seconds = format!("{training_seconds:.0}"),
    );
    Ok(TrainSummary::PawNet {
        out: options.out.clone(),
        frames: all.len(),
        iterations: params.iterations,
        width: params.width,
        training_seconds,
    })
}

/// L2 penalty on the orientation model's scaled weights.
const ORIENTATION_L2: f64 = 1.0;

fn train_orientation(options: &TrainOptions, data: &std::path::Path) -> Result<TrainSummary> {
    use crate::training::orientation::views;
    use crate::vision::body_shape::{Provenance, ShapeModel};
    let (ds, samples) = training::load(data).with_context(|| format!("reading training dataset {data:?}"))?;
    if samples.is_empty() {
        anyhow::bail!("training dataset {data:?} has no images");
    }
    let rig = ds.meta.rig.unwrap_or_else(crate::core::geometry::Rig::default_rig);
    let views = views(&samples, &rig, options.seed).context("segmenting the dataset's mice")?;
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
    if let Some(parent) = options.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    model
        .save(&options.out)
        .with_context(|| format!("writing {:?}", options.out))?;
    tracing::info!(
        message = "Orientation model written.",
        path = %options.out.display(),
        views = labelled.len(),
        training_accuracy = format!("{:.4}", model.provenance.training_accuracy),
    );
    Ok(TrainSummary::Orientation {
        out: options.out.clone(),
        views: labelled.len(),
        training_accuracy: model.provenance.training_accuracy,
        training_seconds: started.elapsed().as_secs_f64(),
    })
}
