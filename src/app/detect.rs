//! `mousepose detect paws IMAGE... --out DIR`: the arguments, handed to
//! [`crate::engine::detect`], and the detections printed.

use crate::app::output::{print, print_json};
use crate::core::geometry::Rig;
use crate::engine::detect::{DETECTIONS_FILE, DetectPawsOptions};
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
    /// How many image pixels a millimetre on the glass spans (the default rig's colour camera:
    /// 2 at full resolution).
    #[arg(long, value_name = "S", default_value_t = default_px_per_mm(), value_parser = crate::app::parse::px_per_mm, allow_negative_numbers = true)]
    pub px_per_mm: f64,
    /// Print the detections as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

/// The default rig's colour camera: its focal length over its distance to the glass.
fn default_px_per_mm() -> f64 {
    let c = Rig::default_rig().color;
    c.intrinsics.fx / c.centre().coords.norm()
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
    let detections = crate::engine::detect::paws(&DetectPawsOptions {
        images: args.images.clone(),
        out: args.out.clone(),
        model: args.model.clone(),
        px_per_mm: args.px_per_mm,
        force: args.force,
    })?;
    if args.json {
        return Ok(print_json(&detections)?);
    }
    let mut text = String::new();
    for i in &detections.images {
        let _ = writeln!(text, "{:?}: {} paws", i.image, i.paws.len());
    }
    let _ = writeln!(text, "boxes in {:?}", args.out.join(DETECTIONS_FILE));
    Ok(print(&text)?)
}
