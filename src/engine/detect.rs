//! `mousepose detect paws IMAGE... --out DIR`: the paw cascade on single bottom-view images,
//! for a lab checking what its own colour camera sees. Writes `detections.json` (per image its
//! size and the paws' boxes with their scores) and, per image, a copy with the boxes drawn.

use crate::app::{print, print_json};
use crate::engine::{Failure, output_failure};
use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::core::geometry::Rig;
use crate::core::image::RgbImage;
use crate::io::output::Staging;
use crate::runtime::models::{PAWS_MODEL, default_models_dir};
use crate::vision::paws::{PawDetection, PawDetector};
use anyhow::Context as _;
use clap::{Args, Subcommand};
use opencv::core::{Mat, MatTraitConst, MatTraitConstManual};
use opencv::imgcodecs;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The file with every image's detections.
pub const DETECTIONS_FILE: &str = "detections.json";

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
    #[arg(long, value_name = "S", default_value_t = default_px_per_mm(), value_parser = parse_px_per_mm, allow_negative_numbers = true)]
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

fn parse_px_per_mm(s: &str) -> Result<f64, String> {
    crate::app::parse_ranged(s, "pixels per millimetre", 0.05, 50.0)
}

/// One image's detections.
#[derive(Clone, Debug, Serialize)]
pub struct ImageDetections {
    pub image: PathBuf,
    pub width: u32,
    pub height: u32,
    /// The picture with the boxes, in the output directory.
    pub picture: String,
    pub paws: Vec<PawDetection>,
}

/// `detections.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Detections {
    pub model: PathBuf,
    pub px_per_mm: f64,
    pub images: Vec<ImageDetections>,
}

/// Reads an image file as an RGB colour frame.
fn read_image(path: &Path) -> anyhow::Result<ColorFrame> {
    let unreadable = || format!("{path:?} is not an image OpenCV can read");
    if !path.is_file() {
        anyhow::bail!("{path:?} does not exist or is not a file");
    }
    let bgr: Mat = imgcodecs::imread(path, imgcodecs::IMREAD_COLOR).with_context(unreadable)?;
    if bgr.empty() {
        anyhow::bail!(unreadable());
    }
    let (width, height) = (
        u32::try_from(bgr.cols()).with_context(unreadable)?,
        u32::try_from(bgr.rows()).with_context(unreadable)?,
    );
    let bytes = bgr.data_bytes().with_context(unreadable)?;
    let data: Vec<u8> = bytes.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect();
    Ok(ColorFrame {
        stamp: Stamp::default(),
        width,
        height,
        format: PixelFormat::Rgb8,
        data,
    })
}

/// The image with the boxes drawn in yellow.
fn picture(frame: &ColorFrame, paws: &[PawDetection]) -> RgbImage {
    let mut img = RgbImage {
        width: frame.width,
        height: frame.height,
        data: frame.data.clone(),
    };
    for d in paws {
        img.rect(
            (f64::from(d.x0), f64::from(d.y0)),
            (f64::from(d.x1), f64::from(d.y1)),
            [255, 220, 40],
            2.0,
        );
    }
    img
}

/// `mousepose detect paws`.
///
/// # Errors
/// A missing or unreadable image or model, or an output directory in the way (exit code 1);
/// a failure writing the output (2).
pub fn paws(args: &DetectPawsArgs) -> crate::app::Outcome {
    let model = match &args.model {
        Some(path) => path.clone(),
        None => default_models_dir().map_err(Failure::usage)?.join(PAWS_MODEL),
    };
    let mut detector = PawDetector::load(&model)
        .map_err(Failure::usage)
        .map_err(|f| f.context(format!("loading the paw cascade {model:?}")))?;
    let frames = args
        .images
        .iter()
        .map(|p| read_image(p))
        .collect::<anyhow::Result<Vec<_>>>()
        .map_err(Failure::usage)?;
    let staging = Staging::new(&args.out, args.force).map_err(output_failure)?;
    let mut found = Vec::new();
    let mut images = Vec::new();
    for (k, (path, frame)) in args.images.iter().zip(&frames).enumerate() {
        detector.detect(frame, (0, 0, frame.width, frame.height), args.px_per_mm, &mut found);
        let stem = path.file_stem().map_or_else(|| "image".into(), |s| s.to_string_lossy());
        let name = format!("{k:03}-{stem}.png");
        let out = staging.path().join(&name);
        picture(frame, &found)
            .write_png(&out)
            .with_context(|| format!("writing {out:?}"))?;
        images.push(ImageDetections {
            image: path.clone(),
            width: frame.width,
            height: frame.height,
            picture: name,
            paws: found.clone(),
        });
    }
    let detections = Detections {
        model,
        px_per_mm: args.px_per_mm,
        images,
    };
    let path = staging.path().join(DETECTIONS_FILE);
    let json = serde_json::to_vec_pretty(&detections).context("encoding the detections")?;
    std::fs::write(&path, json).with_context(|| format!("writing {path:?}"))?;
    staging.commit().map_err(output_failure)?;
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
