//! `mousepose detect paws IMAGE... --out DIR`: the arguments, handed to
//! [`crate::engine::detect`], and the detections printed.

use crate::app::output::{print, print_json};
use crate::engine::detect::{DETECTIONS_FILE, DetectPawsOptions, ScaleSource};
use clap::{Args, Subcommand};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum DetectCommand {
    /// Run the paw cascade on bottom-view images (PNG, JPEG, ...).
    Paws(DetectPawsArgs),
}

#[derive(Debug, Args)]
pub struct DetectPawsArgs {
    /// The images, seen from below through the glass.
    #[arg(value_name = "IMAGE", required = true)]
    pub images: Vec<PathBuf>,
    /// The directory to write detections.json and the pictures into.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The paw cascade (OpenCV cascade XML); the bundled one by default.
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// How many image pixels a millimetre on the glass spans; without it (and without
    /// --calibration) the cascade finds the scale over all the images together, taken to
    /// come from one camera, between 0.5 and 8 px/mm, and says what it found.
    #[arg(long, value_name = "S", value_parser = crate::app::parse::px_per_mm, allow_negative_numbers = true)]
    pub px_per_mm: Option<f64>,
    /// Take the scale from a rig calibration's colour camera (`calibrate extrinsics`).
    #[arg(long, value_name = "FILE", conflicts_with = "px_per_mm")]
    pub calibration: Option<PathBuf>,
    #[command(flatten)]
    pub find_scale: crate::app::parse::FindScaleArg,
    #[command(flatten)]
    pub max_paws: crate::app::parse::MaxPawsArg,
    /// Print the detections as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

/// `mousepose detect ...`.
///
/// # Errors
/// See each detector.
pub fn command(command: &DetectCommand) -> crate::app::Outcome {
    match command {
        DetectCommand::Paws(args) => paws(args),
    }
}

/// `mousepose detect paws`.
///
/// # Errors
/// A missing or unreadable image or model, or an output directory in the way (exit code 1);
/// a failure writing the output (2).
fn paws(args: &DetectPawsArgs) -> crate::app::Outcome {
    if args.find_scale.find_scale.is_some() && (args.px_per_mm.is_some() || args.calibration.is_some()) {
        return Err(crate::engine::Failure::usage(anyhow::anyhow!(
            "--find-scale searches for a scale that --px-per-mm or --calibration already gives: give one of them"
        )));
    }
    let detections = crate::engine::detect::paws(&DetectPawsOptions {
        images: args.images.clone(),
        out: args.out.clone(),
        model: args.model.clone(),
        scale: match (args.px_per_mm, &args.calibration) {
            (Some(s), _) => ScaleSource::Told(s),
            (None, Some(path)) => ScaleSource::Calibration(path.clone()),
            (None, None) => {
                let (lowest, highest) = args.find_scale.range();
                ScaleSource::Find { lowest, highest }
            }
        },
        max_paws: args.max_paws.max_paws,
        force: args.force,
    })?;
    if args.json {
        return Ok(print_json(&detections)?);
    }
    let mut text = String::new();
    for i in &detections.images {
        let _ = writeln!(text, "{:?}: {} paws", i.image, i.paws.len());
    }
    let _ = writeln!(
        text,
        "scale {:.2} px/mm ({}); boxes in {:?}",
        detections.px_per_mm,
        detections.scale_from,
        args.out.join(DETECTIONS_FILE)
    );
    Ok(print(&text)?)
}
