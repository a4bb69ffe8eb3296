//! Frames as they come off the cameras: depth in millimetres, colour in the camera's pixel
//! format, each with the driver's metadata kept intact ([`Stamp`]).
//!
//! Every other part of mousepose (capture, the synchroniser, the stages, the recorder and the
//! session reader) passes these types around, so they stay plain data.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::sync::Arc;

/// When and in which order a frame was produced.
///
/// `seq` is the device's frame counter: a gap between consecutive frames of one camera is a
/// frame the camera dropped. `device_ns` is the device clock (its epoch and rate are the
/// device's own), `host_ns` is the host's monotonic clock when the frame arrived.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Stamp {
    pub seq: u64,
    pub device_ns: u64,
    pub host_ns: u64,
}

/// One depth image: `z` in millimetres along the optical axis, 0 where there is no reading.
#[derive(Clone, PartialEq, Eq)]
pub struct DepthFrame {
    pub stamp: Stamp,
    pub width: u32,
    pub height: u32,
    /// Row-major, `width * height` values.
    pub data: Vec<u16>,
}

impl DepthFrame {
    /// A frame of the given size filled with "no reading".
    pub fn empty(stamp: Stamp, width: u32, height: u32) -> Self {
        Self {
            stamp,
            width,
            height,
            data: vec![0; width as usize * height as usize],
        }
    }

    /// The depth at `(x, y)`, or `None` outside the image.
    pub fn get(&self, x: i64, y: i64) -> Option<u16> {
        if x < 0 || y < 0 || x >= i64::from(self.width) || y >= i64::from(self.height) {
            return None;
        }
        self.data.get(y as usize * self.width as usize + x as usize).copied()
    }
}

impl fmt::Debug for DepthFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DepthFrame")
            .field("stamp", &self.stamp)
            .field("width", &self.width)
            .field("height", &self.height)
            .finish_non_exhaustive()
    }
}

/// Pixel layouts of colour frames. Bayer formats name the colours of the top-left 2x2 block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelFormat {
    Mono8,
    Rgb8,
    BayerRg8,
    BayerGr8,
    BayerGb8,
    BayerBg8,
}

impl PixelFormat {
    pub const ALL: [PixelFormat; 6] = [
        PixelFormat::Mono8,
        PixelFormat::Rgb8,
        PixelFormat::BayerRg8,
        PixelFormat::BayerGr8,
        PixelFormat::BayerGb8,
        PixelFormat::BayerBg8,
    ];

    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Rgb8 => 3,
            _ => 1,
        }
    }

    /// The name used in configs and session metadata (GenICam's PFNC names, lower case).
    pub fn name(self) -> &'static str {
        match self {
            PixelFormat::Mono8 => "mono8",
            PixelFormat::Rgb8 => "rgb8",
            PixelFormat::BayerRg8 => "bayer_rg8",
            PixelFormat::BayerGr8 => "bayer_gr8",
            PixelFormat::BayerGb8 => "bayer_gb8",
            PixelFormat::BayerBg8 => "bayer_bg8",
        }
    }

    /// The colour channel (0 red, 1 green, 2 blue) a Bayer sensor records at `(x, y)`;
    /// `None` for formats that are not Bayer mosaics.
    pub fn bayer_channel(self, x: usize, y: usize) -> Option<usize> {
        let pattern: [usize; 4] = match self {
            PixelFormat::BayerRg8 => [0, 1, 1, 2],
            PixelFormat::BayerGr8 => [1, 0, 2, 1],
            PixelFormat::BayerGb8 => [1, 2, 0, 1],
            PixelFormat::BayerBg8 => [2, 1, 1, 0],
            PixelFormat::Mono8 | PixelFormat::Rgb8 => return None,
        };
        Some(pattern[(y % 2) * 2 + (x % 2)])
    }
}

impl fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One colour image in the camera's own pixel format.
#[derive(Clone, PartialEq, Eq)]
pub struct ColorFrame {
    pub stamp: Stamp,
    pub width: u32,
    pub height: u32,
    pub format: PixelFormat,
    /// Row-major, `width * height * format.bytes_per_pixel()` bytes, no row padding.
    pub data: Vec<u8>,
}

impl ColorFrame {
    /// The number of bytes a frame of this size and format holds.
    pub fn expected_len(width: u32, height: u32, format: PixelFormat) -> usize {
        width as usize * height as usize * format.bytes_per_pixel()
    }
}

impl fmt::Debug for ColorFrame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ColorFrame")
            .field("stamp", &self.stamp)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("format", &self.format)
            .finish_non_exhaustive()
    }
}

/// A depth frame and the colour frame the synchroniser matched with it, if any.
///
/// `color` is `None` in depth-only mode (no colour camera, or no colour frame within the
/// tolerance): the pose then has joints 1-12 only.
#[derive(Clone, Debug, PartialEq)]
pub struct FramePair {
    /// Shared with the recorder branch, never copied.
    pub depth: Arc<DepthFrame>,
    pub color: Option<Arc<ColorFrame>>,
    /// Colour time minus depth time on the depth device's clock, after offset and drift
    /// correction; 0 without colour.
    pub skew_ns: i64,
    /// Whether `color` was the depth frame before's partner too: with a partner wait and
    /// reach (`[sync] partner_reach_ms`), no other colour frame was left in reach, so its paws
    /// are seen again, as they were up to a frame earlier.
    pub color_again: bool,
}
