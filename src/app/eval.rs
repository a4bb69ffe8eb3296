//! `mousepose eval body|parts|paws`: the arguments, handed to [`crate::engine::eval`], and the
//! figures printed.

use crate::app::ModelTarget;
use crate::app::output::{print, print_json};
use crate::engine::eval::{BodyFigures, EvalOptions, EvalSummary, RealPawsFigures, RealPawsOptions};
use crate::training;
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Which model.
    #[arg(value_enum)]
    pub target: ModelTarget,
    /// The model file (with `--labels`: the cascade judged on every labelled frame).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// The held-back test dataset (with `--labels --folds`: rendered views mixed into each
    /// fold's training).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Paws: judge on real frames a lab labelled instead of a rendered dataset, told the view's
    /// scale and not told it (then found between 0.5 and 8 px/mm).
    #[command(flatten)]
    pub labels: crate::app::parse::LabelArgs,
    /// With `--labels`: cross-validate over the frames instead of judging `--model`: train a
    /// cascade on all folds but one (contiguous runs of frames) and judge it on that one.
    #[arg(long, value_name = "K", requires = "labels", value_parser = clap::value_parser!(u32).range(2..=100))]
    pub folds: Option<u32>,
    /// With `--folds`: cascade stages at most.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=50))]
    pub stages: u32,
    /// With `--folds`: the training's seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// With `--folds`: train the small convolutional paw network on each fold instead of a
    /// cascade.
    #[arg(long, requires = "folds")]
    pub net: bool,
    #[command(flatten)]
    pub net_settings: crate::app::parse::NetArgs,
    /// With `--labels`: group with this `minNeighbors` instead of the cascade's own (or the
    /// detector's default, 1); the score curve shows every choice.
    #[arg(long, value_name = "N", requires = "labels", value_parser = clap::value_parser!(u32).range(0..=50))]
    pub min_neighbors: Option<u32>,
    #[command(flatten)]
    pub find_scale: crate::app::parse::FindScaleArg,
    #[command(flatten)]
    pub max_paws: crate::app::parse::MaxPawsArg,
    /// Write tables and PNG charts into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// A baseline model to compare against in the report (body).
    #[arg(long, value_name = "FILE")]
    pub baseline: Option<PathBuf>,
    /// See the bottom views as a colour camera binned by this factor sees them (1, 2 or 4;
    /// paws).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = crate::app::parse::binning)]
    pub color_binning: u32,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose eval body|parts|paws`.
pub fn command(args: &EvalArgs) -> crate::app::Outcome {
    use crate::engine::Failure;
    if let Some(labels) = args.labels.options().map_err(Failure::usage)? {
        if args.target != ModelTarget::Paws {
            return Err(Failure::usage(anyhow::anyhow!("--labels judges paws only")));
        }
        let figures = crate::engine::eval::eval_real_paws(
            &RealPawsOptions {
                labels,
                model: args.model.clone(),
                folds: args.folds,
                renders: args.data.clone(),
                stages: args.stages,
                seed: args.seed,
                min_neighbors: args.min_neighbors,
                scale_range: args.find_scale.range(),
                max_paws: args.max_paws.max_paws,
                net: args.net.then(|| args.net_settings.params(args.seed)),
                report: args.report.clone(),
            },
            &crate::app::progress::Bars::default(),
        )?;
        if args.json {
            return Ok(print_json(&figures)?);
        }
        return Ok(print(&real_paws_text(&figures))?);
    }
    let (Some(model), Some(data)) = (&args.model, &args.data) else {
        return Err(Failure::usage(anyhow::anyhow!(
            "eval needs --model FILE and --data DIR (for paws, or --labels FILE)"
        )));
    };
    let summary = crate::engine::eval::eval(&EvalOptions {
        target: args.target.into(),
        model: model.clone(),
        data: data.clone(),
        report: args.report.clone(),
        baseline: args.baseline.clone(),
        color_binning: args.color_binning,
        max_paws: args.max_paws.max_paws,
    })?;
    if args.json {
        return Ok(print_json(&summary)?);
    }
    Ok(print(&summary_text(&summary))?)
}

/// The table `eval` prints without `--json`.
fn summary_text(summary: &EvalSummary) -> String {
    match summary {
        EvalSummary::Body(report) => body_text(report),
        EvalSummary::Parts(report) => parts_text(report),
        EvalSummary::Paws(report) => paws_text(report),
        EvalSummary::Orientation(f) => format!(
            "head end right in {:.2} % of {} views (tail hidden {:.2} %, tail shown {:.2} %; full resolution {:.2} %, half {:.2} %)\n",
            100.0 * f.accuracy,
            f.views,
            100.0 * f.tail_hidden,
            100.0 * f.tail_shown,
            100.0 * f.full_resolution,
            100.0 * f.half_resolution,
        ),
    }
}

fn body_text(report: &BodyFigures) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "{:<16} {:>9} {:>13}", "joint", "error mm", "paper's mm");
    for (name, e) in &report.report.per_joint_mm {
        let paper = report.paper_method.per_joint_mm.get(name).copied().unwrap_or(f64::NAN);
        let _ = writeln!(t, "{name:<16} {e:>9.2} {paper:>13.2}");
    }
    let _ = writeln!(
        t,
        "{:<16} {:>9.2} {:>13.2}",
        "mean (1-12)", report.report.mean_error_mm, report.paper_method.mean_error_mm
    );
    let _ = writeln!(
        t,
        "{} images, {} without a mouse found; \"paper's\": votes and mean-shift alone, without \
         the step along the segmented tail",
        report.report.images, report.report.no_mouse
    );
    t
}

fn parts_text(report: &training::PartsReport) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "{:<12} {:>9}", "class", "accuracy");
    for (name, a) in &report.per_class_accuracy {
        let _ = writeln!(t, "{name:<12} {:>8.1}%", 100.0 * a);
    }
    let _ = writeln!(t, "{:<12} {:>8.1}%", "mean", 100.0 * report.mean_class_accuracy);
    let _ = writeln!(t, "{:<12} {:>8.1}%", "all pixels", 100.0 * report.pixel_accuracy);
    t
}

fn real_paws_text(f: &RealPawsFigures) -> String {
    let mut t = String::new();
    let how = if f.folds > 0 {
        format!("{}s cross-validated over {} folds of frames", f.detector, f.folds)
    } else {
        format!(
            "the {} {:?}",
            f.detector,
            f.model.as_deref().unwrap_or(std::path::Path::new("?"))
        )
    };
    let _ = writeln!(t, "{how}, on {:?}", f.label_file);
    let _ = writeln!(t, "bottom view: {}", f.bottom_view);
    if let Some(n) = f.min_neighbors {
        let _ = writeln!(t, "grouping: minNeighbors {n}");
    }
    if f.max_paws > 0 {
        let _ = writeln!(t, "kept: the {} surest detections of a view", f.max_paws);
    }
    let _ = writeln!(t, "{:<22} {:>12} {:>12}", "", "scale told", "scale found");
    let (a, b) = (&f.told_scale, &f.found_scale);
    let _ = writeln!(t, "{:<22} {:>12} {:>12}", "frames", a.frames, b.frames);
    let _ = writeln!(t, "{:<22} {:>12} {:>12}", "labelled paws", a.paws, b.paws);
    let _ = writeln!(t, "{:<22} {:>12} {:>12}", "found", a.found, b.found);
    let _ = writeln!(
        t,
        "{:<22} {:>12} {:>12}",
        "false detections", a.false_detections, b.false_detections
    );
    let _ = writeln!(t, "{:<22} {:>12.3} {:>12.3}", "recall", a.recall, b.recall);
    let _ = writeln!(t, "{:<22} {:>12.3} {:>12.3}", "precision", a.precision, b.precision);
    for (paw, told) in &a.per_paw {
        let found = b.per_paw.get(paw).map_or(0.0, |p| p.recall);
        let _ = writeln!(
            t,
            "{:<22} {:>12.3} {:>12.3}",
            format!("recall {paw}"),
            told.recall,
            found
        );
    }
    let scales: Vec<String> = b
        .px_per_mm
        .iter()
        .map(|s| s.map_or_else(|| "none".to_owned(), |s| format!("{s:.2}")))
        .collect();
    let _ = writeln!(
        t,
        "scale found: {} px/mm (true {:.2}); centre error {:.2} mm",
        scales.join(", "),
        a.true_px_per_mm,
        a.mean_centre_error_mm
    );
    t
}

fn paws_text(report: &training::paws_eval::PawReport) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "{:<28} {:>9}", "images", report.images);
    let _ = writeln!(t, "{:<28} {:>9}", "paws on the glass", report.contact_paws);
    let _ = writeln!(t, "{:<28} {:>9}", "detections", report.detections);
    let _ = writeln!(t, "{:<28} {:>9.3}", "precision", report.precision);
    let _ = writeln!(t, "{:<28} {:>9.3}", "recall (paws on the glass)", report.recall);
    let _ = writeln!(t, "{:<28} {:>9.3}", "F1", report.f1);
    let _ = writeln!(
        t,
        "{:<28} {:>9.2}",
        "mean centre error (px)", report.mean_centre_error_px
    );
    let _ = writeln!(
        t,
        "{} true, {} false ({} on marks of the view, {} on the body's look-alikes of paws), {} of lifted or hidden paws (neither)",
        report.true_positives, report.false_positives, report.false_on_marks, report.false_on_body, report.neutral
    );
    t
}
