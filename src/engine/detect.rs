//! The engine of `mousepose detect paws IMAGE... --out DIR`: the paw cascade on single
//! bottom-view images, for a lab checking what its own colour camera sees. Writes `detections.json` (per image its
//! size and the paws' boxes with their scores) and, per image, a copy with the boxes drawn.

use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::core::image::RgbImage;
use crate::engine::{Failure, output_failure};
use crate::io::output::Staging;
use crate::runtime::models::{PAWS_MODEL, default_models_dir, paws_file};
use crate::vision::paws::{PawDetection, PawModel};
use anyhow::Context as _;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The file with every image's detections.
pub const DETECTIONS_FILE: &str = "detections.json";

/// What `detect paws` works on (see its `--help`).
#[derive(Clone, Debug)]
pub struct DetectPawsOptions {
    /// The images, seen from below through the glass.
    pub images: Vec<PathBuf>,
    /// The directory to write detections.json and the pictures into.
    pub out: PathBuf,
    /// The paw cascade; the bundled one when `None`.
    pub model: Option<PathBuf>,
    /// How many image pixels a millimetre on the glass spans, or where to learn it.
    pub scale: ScaleSource,
    /// Detections an image keeps at most, the surest (0: all).
    pub max_paws: usize,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

/// Where `detect paws` takes the images' scale on the glass from.
#[derive(Clone, Debug)]
pub enum ScaleSource {
    /// The user said it (px/mm).
    Told(f64),
    /// A rig calibration's colour camera (from `calibrate extrinsics`).
    Calibration(PathBuf),
    /// Found by the paw model over all the images together, between these px/mm
    /// ([`PawModel::find_scale`]): the images are taken to come from one camera.
    Find { lowest: f64, highest: f64 },
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
    /// Where the scale came from: `told`, `calibration` or `found`.
    pub scale_from: &'static str,
    pub images: Vec<ImageDetections>,
}

/// Reads an image file as an RGB colour frame.
fn read_image(path: &Path) -> anyhow::Result<ColorFrame> {
    if !path.is_file() {
        anyhow::bail!("{path:?} does not exist or is not a file");
    }
    let picture = RgbImage::read(path)?;
    Ok(ColorFrame {
        stamp: Stamp::default(),
        width: picture.width,
        height: picture.height,
        format: PixelFormat::Rgb8,
        data: picture.data,
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

/// `mousepose detect paws`: writes `detections.json` and the pictures, returns the detections.
///
/// # Errors
/// A missing or unreadable image or model, or an output directory in the way (the user's);
/// a failure writing the output.
pub fn paws(options: &DetectPawsOptions) -> Result<Detections, Failure> {
    let model = match &options.model {
        Some(path) => path.clone(),
        None => {
            let dir = default_models_dir().map_err(Failure::usage)?;
            paws_file(&dir).unwrap_or_else(|| dir.join(PAWS_MODEL))
        }
    };
    let mut detector = PawModel::load(&model)
        .map_err(Failure::usage)
        .map_err(|f| f.context(format!("loading the paw model {model:?}")))?;
    let frames = options
        .images
        .iter()
        .map(|p| read_image(p))
        .collect::<anyhow::Result<Vec<_>>>()
        .map_err(Failure::usage)?;
    let (px_per_mm, scale_from) = match &options.scale {
        ScaleSource::Told(s) => (*s, "told"),
        ScaleSource::Calibration(path) => {
            let rig = crate::vision::calibrate::RigCalibration::load(path)
                .map_err(Failure::usage)?
                .rig();
            let s = rig.color.glass_px_per_mm().ok_or_else(|| {
                Failure::usage(anyhow::anyhow!(
                    "the calibration {path:?} puts the colour camera on or below the glass: it gives no scale"
                ))
            })?;
            (s, "calibration")
        }
        &ScaleSource::Find { lowest, highest } => {
            let whole: Vec<crate::vision::paws::detect::FrameRegion<'_>> =
                frames.iter().map(|f| (f, (0, 0, f.width, f.height))).collect();
            let found = detector.find_scale(&whole, lowest, highest).ok_or_else(|| {
                Failure::usage(anyhow::anyhow!(
                    "the paw model finds no paw in these images at any scale from {lowest} to {highest} px/mm: say the scale with --px-per-mm"
                ))
            })?;
            tracing::info!(
                message = "Scale found from the paws' own size.",
                px_per_mm = format!("{:.2}", found.px_per_mm),
                images = frames.len(),
            );
            (found.px_per_mm, "found")
        }
    };
    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    let mut found = Vec::new();
    let mut images = Vec::new();
    for (k, (path, frame)) in options.images.iter().zip(&frames).enumerate() {
        detector.detect(frame, (0, 0, frame.width, frame.height), px_per_mm, &mut found);
        crate::vision::paws::keep_surest(&mut found, options.max_paws);
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
        px_per_mm,
        scale_from,
        images,
    };
    let path = staging.path().join(DETECTIONS_FILE);
    let json = serde_json::to_vec_pretty(&detections).context("encoding the detections")?;
    std::fs::write(&path, json).with_context(|| format!("writing {path:?}"))?;
    staging.commit().map_err(output_failure)?;
    Ok(detections)
}
