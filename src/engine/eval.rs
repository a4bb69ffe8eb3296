//! The engine of `mousepose eval body|parts|paws|orientation`: a model's figures on a held-back
//! dataset, with reports.

use crate::engine::chart::{bar_chart, confusion_chart, line_chart};
use crate::engine::train::ModelTarget;
use crate::engine::{Failure, report_dir, write_report_file};
use crate::io::table::{Exact, Fixed, table};
use crate::training;
use crate::vision::forest::Forest;
use crate::vision::forest::infer::{BodyEstimator, VoteSettings};
use crate::vision::forest::model::{self, Model, ModelKind};
use anyhow::{Context, Result, bail};
use std::path::PathBuf;

/// What `eval` evaluates, on what (see its `--help`).
#[derive(Clone, Debug)]
pub struct EvalOptions {
    pub target: ModelTarget,
    /// The model file.
    pub model: PathBuf,
    /// The held-back test dataset.
    pub data: PathBuf,
    /// Write tables and PNG charts into this directory.
    pub report: Option<PathBuf>,
    /// A baseline model to compare against in the report (body).
    pub baseline: Option<PathBuf>,
    /// The colour camera's binning the bottom views are seen at (paws; 1 is the full sensor).
    pub color_binning: u32,
    /// Detections a bottom view keeps at most, the surest (paws; 0: all).
    pub max_paws: usize,
}

/// A model's figures: what `eval --json` prints (the command line prints them as a table
/// otherwise).
#[derive(Debug, serde::Serialize)]
#[serde(untagged)]
pub enum EvalSummary {
    Body(BodyFigures),
    Parts(training::PartsReport),
    Paws(training::paws_eval::PawReport),
    Orientation(OrientationFigures),
}

/// `mousepose eval body|parts|paws`: the figures, and the tables and charts in
/// `options.report`.
///
/// # Errors
/// The model or dataset cannot be read, or the report cannot be written.
pub fn eval(options: &EvalOptions) -> Result<EvalSummary, Failure> {
    if options.color_binning != 1 && options.target != ModelTarget::Paws {
        return Err(Failure::usage(anyhow::anyhow!(
            "--color-binning applies to eval paws only (the bottom colour views)"
        )));
    }
    if options.target == ModelTarget::Orientation {
        return eval_orientation(options);
    }
    Ok(eval_forest(options)?)
}

/// `eval body|parts|paws`: the model the target names, on the test dataset.
fn eval_forest(options: &EvalOptions) -> Result<EvalSummary> {
    let kind = match options.target {
        ModelTarget::Body => ModelKind::Body,
        ModelTarget::Parts => ModelKind::Parts,
        ModelTarget::Paws => return eval_paws(options),
        // `eval` sends it to `eval_orientation` before this.
        ModelTarget::Orientation => bail!("an orientation model is evaluated by eval_orientation"),
    };
    let model = model::load(&options.model, Some(kind))?;
    let (ds, samples) =
        training::load(&options.data).with_context(|| format!("reading test dataset {:?}", options.data))?;
    if samples.is_empty() {
        bail!("test dataset {:?} has no images", options.data);
    }
    let rig = ds.meta.rig.unwrap_or_else(crate::core::geometry::Rig::default_rig);
    if let Some(train_seed) = model.info().data.iter().find(|d| d.seed == ds.meta.seed) {
        tracing::warn!(
            message = "The test dataset has the seed of a training dataset; its figures are not held-back figures.",
            seed = train_seed.seed,
        );
    }
    match model {
        Model::Body(_, forest) => eval_body(options, forest, &samples, &rig),
        Model::Parts(_, forest) => eval_parts(options, &forest, &samples),
    }
}

/// What `eval body` prints: our estimate's figures, and the paper's method's beside them.
#[derive(Debug, serde::Serialize)]
pub struct BodyFigures {
    #[serde(flatten)]
    pub report: training::BodyReport,
    pub paper_method: PaperMethod,
}

/// The figures of the paper's method alone (votes and mean-shift, no step along the tail).
#[derive(Debug, serde::Serialize)]
pub struct PaperMethod {
    pub mean_error_mm: f64,
    pub per_joint_mm: std::collections::BTreeMap<String, f64>,
}

fn eval_body(
    options: &EvalOptions,
    forest: Forest<[f32; 2], crate::vision::forest::depth::JointLeaf>,
    samples: &[crate::synth::dataset::Sample],
    rig: &crate::core::geometry::Rig,
) -> Result<EvalSummary> {
    let estimator = BodyEstimator::new(forest.clone(), VoteSettings::default())?;
    let report = training::eval_body(&estimator, samples, rig, 0.0)?;
    // The paper's method alone: votes and mean-shift, without our step along the tail.
    let paper_only = BodyEstimator::new(
        forest,
        VoteSettings {
            follow_tail: false,
            ..VoteSettings::default()
        },
    )?;
    let paper = training::eval_body(&paper_only, samples, rig, 0.0)?;
    let report = BodyFigures {
        paper_method: PaperMethod {
            mean_error_mm: paper.mean_error_mm,
            per_joint_mm: paper.per_joint_mm,
        },
        report,
    };
    if let Some(dir) = &options.report {
        report_dir(dir)?;
        // In the paper's joint order, not the map's alphabetical one.
        let in_order = |r: &training::BodyReport| -> Vec<f64> {
            crate::core::skeleton::Joint::MAIN_BODY
                .iter()
                .map(|j| r.per_joint_mm.get(j.name()).copied().unwrap_or(f64::NAN))
                .collect()
        };
        let names: Vec<String> = crate::core::skeleton::Joint::MAIN_BODY
            .iter()
            .map(|j| j.name().to_owned())
            .collect();
        let ours = in_order(&report.report);
        let mut series = Vec::new();
        let baseline = match &options.baseline {
            Some(path) => match model::load(path, Some(ModelKind::Body))? {
                Model::Body(_, f) => Some(training::eval_body(
                    &BodyEstimator::new(f, VoteSettings::default())?,
                    samples,
                    rig,
                    0.0,
                )?),
                Model::Parts(..) => None,
            },
            None => None,
        };
        let base_values: Vec<f64> = baseline.as_ref().map(in_order).unwrap_or_default();
        if baseline.is_some() {
            series.push(("baseline", [120, 120, 120], base_values.as_slice()));
        }
        series.push(("this model", [40, 90, 220], ours.as_slice()));
        let chart = bar_chart("joint error per joint (mm)", "mm", &names, &series);
        chart.write_png(&dir.join("joint_error.png"))?;
        // Error against added Gaussian noise.
        let sigmas = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let noisy: Vec<f64> = sigmas
            .iter()
            .map(|&s| training::eval_body(&estimator, samples, rig, s).map(|r| r.mean_error_mm))
            .collect::<Result<_, _>>()?;
        line_chart(
            "mean joint error vs depth noise",
            "noise sigma (mm)",
            "mm",
            &sigmas,
            &[("mean error", [200, 40, 40], &noisy)],
        )
        .write_png(&dir.join("error_vs_noise.png"))?;
        // A row per joint: its error, and the baseline's when there is one.
        let rows: Vec<Vec<String>> = names
            .iter()
            .enumerate()
            .map(|(k, name)| {
                let errors = std::iter::once(ours[k]).chain(base_values.get(k).copied());
                std::iter::once(name.clone())
                    .chain(errors.map(|e| format!("{e:.3}")))
                    .collect()
            })
            .collect();
        let columns: &[&str] = if baseline.is_some() {
            &["joint", "error_mm", "baseline_mm"]
        } else {
            &["joint", "error_mm"]
        };
        write_report_file(dir, "joint_error.csv", &table(columns, &rows)?)?;
        let rows: Vec<(Exact, Fixed<3>)> = sigmas.iter().zip(&noisy).map(|(&s, &e)| (Exact(s), Fixed(e))).collect();
        write_report_file(
            dir,
            "error_vs_noise.csv",
            &table(&["noise_mm", "mean_error_mm"], &rows)?,
        )?;
        write_report_file(dir, "summary.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(EvalSummary::Body(report))
}

fn eval_parts(
    options: &EvalOptions,
    forest: &Forest<[f32; 2], Vec<f32>>,
    samples: &[crate::synth::dataset::Sample],
) -> Result<EvalSummary> {
    let report = training::eval_parts(forest, samples);
    if let Some(dir) = &options.report {
        report_dir(dir)?;
        confusion_chart(
            "part labels: confusion (% of true class)",
            &report.classes,
            &report.confusion,
        )
        .write_png(&dir.join("confusion.png"))?;
        let columns: Vec<&str> = std::iter::once("truth\\predicted")
            .chain(report.classes.iter().map(String::as_str))
            .collect();
        let rows: Vec<(&str, &[u64])> = report
            .classes
            .iter()
            .zip(&report.confusion)
            .map(|(c, row)| (c.as_str(), row.as_slice()))
            .collect();
        write_report_file(dir, "confusion.csv", &table(&columns, &rows)?)?;
        write_report_file(dir, "summary.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(EvalSummary::Parts(report))
}

/// `mousepose eval paws`.
fn eval_paws(options: &EvalOptions) -> Result<EvalSummary> {
    use crate::training::paws_eval as eval;
    let detector = crate::vision::paws::PawModel::load(&options.model)?;
    let report = eval::evaluate(&detector, &options.data, options.color_binning, options.max_paws)
        .with_context(|| format!("evaluating on test dataset {:?}", options.data))?;
    if let Some(dir) = &options.report {
        report_dir(dir)?;
        let mut points = report.curve.clone();
        points.sort_by(|a, b| a.recall.total_cmp(&b.recall).then(b.precision.total_cmp(&a.precision)));
        let stride = points.len().div_ceil(10).max(1);
        let picked: Vec<_> = points
            .iter()
            .enumerate()
            .filter(|(i, _)| i % stride == 0 || i + 1 == points.len())
            .map(|(_, p)| *p)
            .collect();
        let recall: Vec<f64> = picked.iter().map(|p| (p.recall * 1000.0).round() / 1000.0).collect();
        let precision: Vec<f64> = picked.iter().map(|p| p.precision).collect();
        line_chart(
            "paws on the glass: precision vs recall (minimum score varied)",
            "recall",
            "precision",
            &recall,
            &[("precision", [40, 90, 220], &precision)],
        )
        .write_png(&dir.join("precision_recall.png"))?;
        let rows: Vec<[Fixed<4>; 3]> = report
            .curve
            .iter()
            .map(|p| [Fixed(p.min_score), Fixed(p.precision), Fixed(p.recall)])
            .collect();
        write_report_file(
            dir,
            "precision_recall.csv",
            &table(&["min_score", "precision", "recall"], &rows)?,
        )?;
        write_report_file(dir, "summary.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(EvalSummary::Paws(report))
}

/// What `eval orientation` prints: the share of views whose head end the model gets right,
/// over all and by the tail hidden or shown and the resolution.
#[derive(Debug, serde::Serialize)]
pub struct OrientationFigures {
    pub views: usize,
    pub accuracy: f64,
    pub tail_hidden: f64,
    pub tail_shown: f64,
    pub full_resolution: f64,
    pub half_resolution: f64,
}

fn eval_orientation(options: &EvalOptions) -> Result<EvalSummary, Failure> {
    use crate::vision::body_shape::ShapeModel;
    if options.report.is_some() || options.baseline.is_some() {
        return Err(Failure::usage(anyhow::anyhow!(
            "eval orientation takes no --report or --baseline; it prints its figures (--json for JSON)"
        )));
    }
    let model = ShapeModel::load(&options.model).map_err(Failure::usage)?;
    let (ds, samples) =
        training::load(&options.data).with_context(|| format!("reading test dataset {:?}", options.data))?;
    if samples.is_empty() {
        return Err(Failure::usage(anyhow::anyhow!(
            "test dataset {:?} has no images",
            options.data
        )));
    }
    if ds.meta.seed == model.provenance.dataset_seed {
        tracing::warn!(
            message = "The test dataset has the seed of the training dataset; its figures are not held-back figures.",
            seed = ds.meta.seed,
        );
    }
    let rig = ds.meta.rig.unwrap_or_else(crate::core::geometry::Rig::default_rig);
    let views = training::orientation::views(&samples, &rig, 0x7E57)?;
    let share = |keep: &dyn Fn(&training::orientation::View) -> bool| {
        let kept: Vec<_> = views
            .iter()
            .filter(|v| keep(v))
            .map(|v| (v.features, v.head_plus))
            .collect();
        model.accuracy(&kept)
    };
    let figures = OrientationFigures {
        views: views.len(),
        accuracy: share(&|_| true),
        tail_hidden: share(&|v| v.tail_hidden),
        tail_shown: share(&|v| !v.tail_hidden),
        full_resolution: share(&|v| !v.coarse),
        half_resolution: share(&|v| v.coarse),
    };
    Ok(EvalSummary::Orientation(figures))
}

/// What `eval paws --labels` judges: a cascade, or a cascade trained per fold, on real frames
/// a lab labelled (see its `--help`).
#[derive(Clone, Debug)]
pub struct RealPawsOptions {
    pub labels: crate::engine::train::LabelOptions,
    /// The cascade to judge on every labelled frame; `None` with `folds`.
    pub model: Option<PathBuf>,
    /// Cross-validate over frames: train a cascade on all folds but one, judge it on that one.
    pub folds: Option<u32>,
    /// Rendered views mixed into each fold's training.
    pub renders: Option<PathBuf>,
    /// Cascade stages at most, and the training's seed (with `folds`).
    pub stages: u32,
    pub seed: u64,
    /// Group with this `minNeighbors` instead of the cascade's own.
    pub min_neighbors: Option<u32>,
    /// Where the detector looks for the scale it is not told (px/mm).
    pub scale_range: (f64, f64),
    /// Detections a view keeps at most, the surest (0: all).
    pub max_paws: usize,
    /// With `folds`: train the paw network with these settings instead of a cascade.
    pub net: Option<training::paws_net::NetParams>,
    /// Write `summary.json` and each frame with its paws found, missed and false drawn here.
    pub report: Option<PathBuf>,
}

/// What `eval paws --labels` reports: the figures told the view's scale and not told it.
#[derive(Debug, serde::Serialize)]
pub struct RealPawsFigures {
    pub label_file: PathBuf,
    /// How the bottom view was found in the frames.
    pub bottom_view: String,
    pub model: Option<PathBuf>,
    /// Folds of the cross-validation (frames in contiguous runs); 0 when a given cascade was
    /// judged.
    pub folds: u32,
    pub renders: Option<PathBuf>,
    pub told_scale: training::paws_real::RealPawReport,
    pub found_scale: training::paws_real::RealPawReport,
    pub training_seconds: f64,
    /// What kind of model was judged: `cascade` or `network`.
    pub detector: &'static str,
    /// The grouping a cascade's figures were judged with (`minNeighbors`); `None` for a
    /// network.
    pub min_neighbors: Option<usize>,
    /// Detections a view kept at most, the surest (0: all).
    pub max_paws: usize,
    /// Per frame (told the scale): its image, paws found and missed, false detections.
    pub per_frame: Vec<RealPawsFrame>,
}

/// One judged frame's counts in [`RealPawsFigures`].
#[derive(Debug, serde::Serialize)]
pub struct RealPawsFrame {
    pub image: PathBuf,
    pub found: usize,
    pub missed: usize,
    pub false_detections: usize,
}

/// `mousepose eval paws --labels`: a cascade's figures on labelled real frames, or
/// cross-validated cascades' (each judged on frames it did not learn from).
///
/// # Errors
/// A label file, frame or model that cannot be read (the user's); training that fails; a
/// report that cannot be written.
pub fn eval_real_paws(
    options: &RealPawsOptions,
    progress: &dyn crate::engine::progress::Progress,
) -> Result<RealPawsFigures, Failure> {
    use crate::training::paws_real::{RealPawReport, Scale, fold_frames, judge};
    use crate::vision::paws::PawModel;
    let views = options.labels.open()?;
    let n = views.frames.len();
    let found = Scale::Found {
        lowest: options.scale_range.0,
        highest: options.scale_range.1,
    };
    let mut figures = RealPawsFigures {
        label_file: options.labels.file.clone(),
        bottom_view: views.view_top_how.clone(),
        model: options.model.clone(),
        folds: 0,
        renders: options.renders.clone(),
        told_scale: RealPawReport::default(),
        found_scale: RealPawReport::default(),
        training_seconds: 0.0,
        detector: if options.net.is_some() { "network" } else { "cascade" },
        min_neighbors: options.net.is_none().then(|| {
            options
                .min_neighbors
                .map_or(crate::vision::paws::detect::DEFAULT_MIN_NEIGHBORS, |n| n as usize)
        }),
        max_paws: options.max_paws,
        per_frame: Vec::new(),
    };
    let mut outcomes = Vec::new();
    match (&options.model, options.folds) {
        (Some(model), None) => {
            let mut detector = PawModel::load(model)
                .map_err(Failure::usage)
                .map_err(|f| f.context(format!("loading the paw model {model:?}")))?;
            if let PawModel::Cascade(cascade) = &mut detector {
                if let Some(n) = options.min_neighbors {
                    cascade.set_min_neighbors(n as usize);
                }
            }
            figures.min_neighbors = match &detector {
                PawModel::Cascade(cascade) => Some(cascade.min_neighbors()),
                PawModel::Net(_) => None,
            };
            figures.detector = detector.kind();
            let all: Vec<usize> = (0..n).collect();
            let (told, frames) = judge(&mut detector, &views, &all, Scale::Told, options.max_paws);
            figures.told_scale = told;
            figures.found_scale = judge(&mut detector, &views, &all, found, options.max_paws).0;
            outcomes = frames;
        }
        (None, Some(folds)) => {
            let folds = folds.clamp(2, n.max(2) as u32);
            figures.folds = folds;
            // The renders as the kind of model trained learns them.
            let (renders, render_views) = match (&options.renders, &options.net) {
                (Some(dir), Some(_)) => (None, crate::engine::train::render_views(dir)?),
                (Some(dir), None) => (
                    Some(crate::engine::train::render_material(dir, options.seed)?),
                    Vec::new(),
                ),
                (None, _) => (None, Vec::new()),
            };
            let started = std::time::Instant::now();
            for fold in 0..folds as usize {
                let judged = fold_frames(n, folds as usize, fold);
                let learnt: Vec<usize> = (0..n).filter(|k| !judged.contains(k)).collect();
                tracing::info!(
                    message = "Training a fold's paw model.",
                    fold = fold + 1,
                    folds,
                    judged = judged.len()
                );
                let training = FoldTraining {
                    views: &views,
                    renders: renders.as_ref(),
                    render_views: &render_views,
                };
                let mut detector = fold_detector(options, &training, &learnt, progress)?;
                let (told, frames) = judge(&mut detector, &views, &judged, Scale::Told, options.max_paws);
                figures.told_scale.merge(&told);
                figures
                    .found_scale
                    .merge(&judge(&mut detector, &views, &judged, found, options.max_paws).0);
                outcomes.extend(frames);
            }
            figures.training_seconds = started.elapsed().as_secs_f64();
        }
        _ => {
            return Err(Failure::usage(anyhow::anyhow!(
                "eval paws --labels judges either a cascade (--model FILE) or cascades trained per fold (--folds K), one of them"
            )));
        }
    }
    figures.per_frame = outcomes
        .iter()
        .map(|o| RealPawsFrame {
            image: views.labels.images[o.frame].image.clone(),
            found: o.found.len(),
            missed: o.missed.len(),
            false_detections: o.false_detections.len(),
        })
        .collect();
    if let Some(dir) = &options.report {
        write_real_paws_report(dir, &views, &outcomes, &figures)?;
    }
    Ok(figures)
}

/// What a fold's paw detector learns from besides its labelled frames: the labelled views,
/// and the renders as a cascade learns them (`renders`) or as the network does
/// (`render_views`).
struct FoldTraining<'a> {
    views: &'a training::paws_real::RealViews,
    renders: Option<&'a crate::vision::paws::train::TrainingSet>,
    render_views: &'a [training::paws_net::NetView],
}

/// The paw detector one fold of `eval paws --labels --folds` trains on the frames `learnt`:
/// the network with `options.net`, else a cascade.
fn fold_detector(
    options: &RealPawsOptions,
    training: &FoldTraining<'_>,
    learnt: &[usize],
    progress: &dyn crate::engine::progress::Progress,
) -> Result<crate::vision::paws::PawModel, Failure> {
    use crate::vision::paws::{PawDetector, PawModel};
    let views = training.views;
    Ok(if let Some(params) = &options.net {
        let net = crate::engine::train::fit_paw_net(views, learnt, training.render_views, params, progress)?;
        PawModel::Net(Box::new(crate::vision::paws::net::NetDetector::new(&net)?))
    } else {
        let set = crate::engine::train::paw_material(training.renders, Some((views, learnt)), options.seed)?;
        let trained = crate::engine::train::fit_paw_cascade(&set, options.stages, options.seed, progress)?;
        let mut cascade = trained.cascade;
        cascade.min_neighbors = options.min_neighbors;
        PawModel::Cascade(Box::new(PawDetector::from_cascade(cascade)))
    })
}

/// `eval paws --labels --report DIR`: each judged frame drawn with its paws found, missed and
/// false, and `summary.json`.
fn write_real_paws_report(
    dir: &std::path::Path,
    views: &training::paws_real::RealViews,
    outcomes: &[training::paws_real::FrameOutcome],
    figures: &RealPawsFigures,
) -> Result<(), Failure> {
    report_dir(dir)?;
    for outcome in outcomes {
        let name = views.labels.images[outcome.frame].image.file_stem().map_or_else(
            || format!("frame{}", outcome.frame),
            |s| s.to_string_lossy().into_owned(),
        );
        let path = dir.join(format!("{:03}-{name}.png", outcome.frame));
        real_paws_picture(&views.frames[outcome.frame], outcome, views.px_per_mm)
            .write_png(&path)
            .with_context(|| format!("writing {path:?}"))?;
    }
    write_report_file(dir, "summary.json", serde_json::to_string_pretty(figures)?.as_bytes())?;
    Ok(())
}

/// A judged frame: found paws' boxes in green, false detections' in red, missed paws circled
/// in blue at their labels.
fn real_paws_picture(
    frame: &crate::core::frame::ColorFrame,
    outcome: &training::paws_real::FrameOutcome,
    px_per_mm: f64,
) -> crate::core::image::RgbImage {
    let mut img = crate::core::image::RgbImage {
        width: frame.width,
        height: frame.height,
        data: frame.data.iter().flat_map(|&v| [v, v, v]).collect(),
    };
    let corners = |d: &crate::vision::paws::PawDetection| {
        ((f64::from(d.x0), f64::from(d.y0)), (f64::from(d.x1), f64::from(d.y1)))
    };
    for (_, d) in &outcome.found {
        let (a, b) = corners(d);
        img.rect(a, b, [60, 220, 60], 2.0);
    }
    for d in &outcome.false_detections {
        let (a, b) = corners(d);
        img.rect(a, b, [230, 50, 50], 2.0);
    }
    let r = training::paws_real::MATCH_RADIUS_MM * px_per_mm;
    for &(_, x, y) in &outcome.missed {
        let steps = 24;
        for s in 0..steps {
            let (a0, a1) = (
                std::f64::consts::TAU * f64::from(s) / f64::from(steps),
                std::f64::consts::TAU * f64::from(s + 1) / f64::from(steps),
            );
            img.line(
                (x + r * a0.cos(), y + r * a0.sin()),
                (x + r * a1.cos(), y + r * a1.sin()),
                [70, 120, 255],
                2.0,
            );
        }
    }
    img
}
