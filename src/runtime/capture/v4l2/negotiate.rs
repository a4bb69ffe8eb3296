//! Format negotiation, pure: what the device offers ([`OfferedFormat`]), what each fourcc
//! becomes and how ([`conversion_for`]), and the mode to stream ([`choose_format`]), in the
//! order of preference the module documentation gives.

use super::V4l2Config;
use crate::core::frame::PixelFormat;
use serde::{Deserialize, Serialize};
use std::fmt;

/// One pixel format the device offers, with its sizes and frame intervals, as the
/// `VIDIOC_ENUM_FMT`, `VIDIOC_ENUM_FRAMESIZES` and `VIDIOC_ENUM_FRAMEINTERVALS` ioctls report
/// them (stepwise ranges reduced to the wanted mode when it fits them).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OfferedFormat {
    pub fourcc: String,
    #[serde(default)]
    pub description: String,
    pub sizes: Vec<OfferedSize>,
}

/// One frame size of an offered format.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OfferedSize {
    pub width: u32,
    pub height: u32,
    /// Frame intervals as `[numerator, denominator]` seconds (`[1, 30]` is 30 frames/s).
    pub intervals: Vec<[u32; 2]>,
}

/// How a buffer becomes a [`ColorFrame`](crate::core::frame::ColorFrame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Conversion {
    /// Rows copied as they are (GREY, RGB3, Bayer).
    Copy,
    /// YUYV 4:2:2 to RGB, BT.601 limited range.
    YuyvToRgb8,
    /// The luma of YUYV, exactly.
    YuyvToMono8,
}

impl Conversion {
    /// Bytes per pixel in the device's buffer.
    pub(super) fn input_bytes_per_pixel(self, output: PixelFormat) -> usize {
        match self {
            Conversion::Copy => output.bytes_per_pixel(),
            Conversion::YuyvToRgb8 | Conversion::YuyvToMono8 => 2,
        }
    }
}

/// What we do with a fourcc: the pixel format it becomes, how, and its rank (lower is
/// preferred: lossless first). `None` for formats we cannot use.
pub fn conversion_for(fourcc: &str) -> Option<(PixelFormat, Conversion, u8)> {
    Some(match fourcc {
        "GREY" => (PixelFormat::Mono8, Conversion::Copy, 0),
        "RGB3" => (PixelFormat::Rgb8, Conversion::Copy, 1),
        "BA81" => (PixelFormat::BayerBg8, Conversion::Copy, 2),
        "GBRG" => (PixelFormat::BayerGb8, Conversion::Copy, 2),
        "GRBG" => (PixelFormat::BayerGr8, Conversion::Copy, 2),
        "RGGB" => (PixelFormat::BayerRg8, Conversion::Copy, 2),
        "YUYV" => (PixelFormat::Rgb8, Conversion::YuyvToRgb8, 3),
        _ => return None,
    })
}

/// The mode negotiation settled on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chosen {
    pub fourcc: String,
    pub width: u32,
    pub height: u32,
    /// `[numerator, denominator]` seconds per frame.
    pub interval: [u32; 2],
    /// What frames come out as.
    pub output: PixelFormat,
    pub conversion: Conversion,
}

impl Chosen {
    /// Frames per second of the chosen interval.
    pub fn fps(&self) -> f64 {
        fps_of(self.interval)
    }
}

pub(super) fn fps_of([num, den]: [u32; 2]) -> f64 {
    if num == 0 { 0.0 } else { f64::from(den) / f64::from(num) }
}

/// No offered mode fits the config.
#[derive(Debug, thiserror::Error)]
#[error("no offered mode fits {wanted} ({reason}); the device offers {offered}")]
pub struct NoMode {
    /// The wanted mode, `640x480@30` or `YUYV 640x480@30`.
    pub wanted: String,
    pub reason: String,
    /// Every offered mode, `YUYV 640x480@30/15, MJPG 1280x720@30`.
    pub offered: String,
}

/// Lists offered modes for messages: `YUYV 640x480@30/15, MJPG 1280x720@30`.
pub fn describe_offered(offered: &[OfferedFormat]) -> String {
    let modes: Vec<String> = offered
        .iter()
        .flat_map(|format| {
            format.sizes.iter().map(move |size| {
                let rates: Vec<String> = size.intervals.iter().map(|&i| format!("{}", Rate(fps_of(i)))).collect();
                format!("{} {}x{}@{}", format.fourcc, size.width, size.height, rates.join("/"))
            })
        })
        .collect();
    if modes.is_empty() {
        "nothing".to_owned()
    } else {
        modes.join(", ")
    }
}

/// A frame rate printed without needless decimals (`30`, `7.5`).
struct Rate(f64);

impl fmt::Display for Rate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if (self.0 - self.0.round()).abs() < 1e-9 {
            write!(f, "{}", self.0.round())
        } else {
            write!(f, "{:.3}", self.0)
        }
    }
}

/// Whether a frame interval gives `fps` within 1 % (cameras report 30 fps as 1/30 or as
/// 333333/10000000).
pub(super) fn rate_matches(interval: [u32; 2], fps: f64) -> bool {
    let rate = fps_of(interval);
    fps > 0.0 && (rate - fps).abs() <= 0.01 * fps
}

/// Picks the mode to stream: the exact size and a frame rate within 1 % of the config's, in the
/// config's fourcc when it names one, else in the most preferred format offering that mode
/// (see the module documentation).
///
/// # Errors
/// [`NoMode`] naming the wanted mode, why nothing fits and every offered mode.
pub fn choose_format(offered: &[OfferedFormat], wanted: &V4l2Config) -> Result<Chosen, NoMode> {
    let fourcc_wanted = wanted.format.as_deref().map(str::trim);
    let no_mode = |reason: String| NoMode {
        wanted: match fourcc_wanted {
            Some(f) => format!("{f} {}x{}@{}", wanted.width, wanted.height, Rate(wanted.fps)),
            None => format!("{}x{}@{}", wanted.width, wanted.height, Rate(wanted.fps)),
        },
        reason,
        offered: describe_offered(offered),
    };
    if let Some(fourcc) = fourcc_wanted {
        if !offered.iter().any(|f| f.fourcc == fourcc) {
            return Err(no_mode(format!("the device does not offer {fourcc}")));
        }
        if conversion_for(fourcc).is_none() {
            return Err(no_mode(format!("mousepose cannot convert {fourcc} frames")));
        }
    }
    let mut best: Option<(u8, Chosen)> = None;
    let mut unusable = Vec::new();
    for format in offered {
        if fourcc_wanted.is_some_and(|f| f != format.fourcc) {
            continue;
        }
        for size in &format.sizes {
            if (size.width, size.height) != (wanted.width, wanted.height) {
                continue;
            }
            let Some(&interval) = size.intervals.iter().find(|&&i| rate_matches(i, wanted.fps)) else {
                continue;
            };
            let Some((output, conversion, rank)) = conversion_for(&format.fourcc) else {
                unusable.push(format.fourcc.clone());
                continue;
            };
            if matches!(conversion, Conversion::YuyvToRgb8 | Conversion::YuyvToMono8) && size.width % 2 != 0 {
                continue;
            }
            if best.as_ref().is_none_or(|(r, _)| rank < *r) {
                best = Some((
                    rank,
                    Chosen {
                        fourcc: format.fourcc.clone(),
                        width: size.width,
                        height: size.height,
                        interval,
                        output,
                        conversion,
                    },
                ));
            }
        }
    }
    match best {
        Some((_, chosen)) => Ok(chosen),
        None if !unusable.is_empty() => Err(no_mode(format!(
            "only in {}, which mousepose cannot convert",
            unusable.join(", ")
        ))),
        None => Err(no_mode("no format offers that size and rate".to_owned())),
    }
}
