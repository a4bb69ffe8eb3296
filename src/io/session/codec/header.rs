//! The 40-byte frame header at the start of every frame payload ([`FrameHeader`]), and what
//! its codes mean: the pixel format ([`FrameFormat`], whose names session metadata uses) and
//! how the pixels are stored ([`Codec`]).

use super::{CodecError, Result};
use crate::core::frame::{PixelFormat, Stamp};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::str::FromStr;

/// Length of the frame header at the start of every frame payload.
pub const FRAME_HEADER_LEN: usize = 40;

/// The most pixel bytes one frame may hold (256 MiB).
pub const MAX_PIXEL_BYTES: u32 = 256 << 20;

/// The pixel format of a stored frame: depth (`u16` millimetres) or one of the colour
/// formats. Its name (`depth16`, `mono8`, `bayer_rg8`, ...) is what session metadata uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FrameFormat {
    Depth16,
    Color(PixelFormat),
}

impl FrameFormat {
    /// The code in the frame header.
    pub fn code(self) -> u8 {
        match self {
            FrameFormat::Depth16 => 0,
            FrameFormat::Color(PixelFormat::Mono8) => 1,
            FrameFormat::Color(PixelFormat::Rgb8) => 2,
            FrameFormat::Color(PixelFormat::BayerRg8) => 3,
            FrameFormat::Color(PixelFormat::BayerGr8) => 4,
            FrameFormat::Color(PixelFormat::BayerGb8) => 5,
            FrameFormat::Color(PixelFormat::BayerBg8) => 6,
        }
    }

    /// The format with a header code, if there is one.
    pub fn from_code(code: u8) -> Option<FrameFormat> {
        Some(match code {
            0 => FrameFormat::Depth16,
            1 => FrameFormat::Color(PixelFormat::Mono8),
            2 => FrameFormat::Color(PixelFormat::Rgb8),
            3 => FrameFormat::Color(PixelFormat::BayerRg8),
            4 => FrameFormat::Color(PixelFormat::BayerGr8),
            5 => FrameFormat::Color(PixelFormat::BayerGb8),
            6 => FrameFormat::Color(PixelFormat::BayerBg8),
            _ => return None,
        })
    }

    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            FrameFormat::Depth16 => 2,
            FrameFormat::Color(format) => format.bytes_per_pixel(),
        }
    }

    /// `depth16` or the colour format's name.
    pub fn name(self) -> &'static str {
        match self {
            FrameFormat::Depth16 => "depth16",
            FrameFormat::Color(format) => format.name(),
        }
    }
}

impl fmt::Display for FrameFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is not a stored pixel format.
#[derive(Debug, thiserror::Error)]
#[error("unknown pixel format {0:?} (expected depth16, mono8, rgb8, bayer_rg8, bayer_gr8, bayer_gb8 or bayer_bg8)")]
pub struct UnknownFormatName(pub String);

impl FromStr for FrameFormat {
    type Err = UnknownFormatName;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "depth16" {
            return Ok(FrameFormat::Depth16);
        }
        PixelFormat::ALL
            .iter()
            .find(|f| f.name() == s)
            .map(|&f| FrameFormat::Color(f))
            .ok_or_else(|| UnknownFormatName(s.to_owned()))
    }
}

impl Serialize for FrameFormat {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for FrameFormat {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

/// How the pixels of a frame payload are stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Codec {
    /// As they are.
    Raw,
    /// zstd-compressed.
    Zstd,
    /// zstd-compressed after the horizontal delta filter (the default).
    #[default]
    DeltaZstd,
}

impl Codec {
    /// The code in the frame header.
    pub fn code(self) -> u8 {
        match self {
            Codec::Raw => 0,
            Codec::Zstd => 1,
            Codec::DeltaZstd => 2,
        }
    }

    /// The codec with a header code, if there is one.
    pub fn from_code(code: u8) -> Option<Codec> {
        match code {
            0 => Some(Codec::Raw),
            1 => Some(Codec::Zstd),
            2 => Some(Codec::DeltaZstd),
            _ => None,
        }
    }
}

/// The decoded frame header of a payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameHeader {
    pub stamp: Stamp,
    pub width: u16,
    pub height: u16,
    pub format: FrameFormat,
    pub codec: Codec,
    /// Length of the pixel data before compression and filtering.
    pub pixel_bytes: u32,
}

impl FrameHeader {
    pub(super) fn to_bytes(self) -> [u8; FRAME_HEADER_LEN] {
        let mut b = [0u8; FRAME_HEADER_LEN];
        b[0..8].copy_from_slice(&self.stamp.seq.to_le_bytes());
        b[8..16].copy_from_slice(&self.stamp.device_ns.to_le_bytes());
        b[16..24].copy_from_slice(&self.stamp.host_ns.to_le_bytes());
        b[24..26].copy_from_slice(&self.width.to_le_bytes());
        b[26..28].copy_from_slice(&self.height.to_le_bytes());
        b[28] = self.format.code();
        b[29] = self.codec.code();
        b[32..36].copy_from_slice(&self.pixel_bytes.to_le_bytes());
        b
    }

    /// Parses and checks the header at the start of a payload: known format and codec, and a
    /// pixel length that matches the size and format and is within [`MAX_PIXEL_BYTES`].
    ///
    /// # Errors
    /// The [`CodecError`] naming the first check that fails.
    pub fn parse(payload: &[u8]) -> Result<Self> {
        let b: &[u8; FRAME_HEADER_LEN] = payload
            .get(..FRAME_HEADER_LEN)
            .and_then(|h| h.try_into().ok())
            .ok_or(CodecError::ShortPayload { len: payload.len() })?;
        let u64_at = |at: usize| {
            u64::from_le_bytes([
                b[at],
                b[at + 1],
                b[at + 2],
                b[at + 3],
                b[at + 4],
                b[at + 5],
                b[at + 6],
                b[at + 7],
            ])
        };
        let stamp = Stamp {
            seq: u64_at(0),
            device_ns: u64_at(8),
            host_ns: u64_at(16),
        };
        let width = u16::from_le_bytes([b[24], b[25]]);
        let height = u16::from_le_bytes([b[26], b[27]]);
        let format = FrameFormat::from_code(b[28]).ok_or(CodecError::UnknownFormat(b[28]))?;
        let codec = Codec::from_code(b[29]).ok_or(CodecError::UnknownCodec(b[29]))?;
        let pixel_bytes = u32::from_le_bytes([b[32], b[33], b[34], b[35]]);
        let expected = u64::from(width) * u64::from(height) * format.bytes_per_pixel() as u64;
        if expected != u64::from(pixel_bytes) {
            return Err(CodecError::LengthMismatch {
                width,
                height,
                format,
                expected,
                stated: pixel_bytes,
            });
        }
        if pixel_bytes > MAX_PIXEL_BYTES {
            return Err(CodecError::TooManyBytes(expected));
        }
        Ok(Self {
            stamp,
            width,
            height,
            format,
            codec,
            pixel_bytes,
        })
    }
}

/// The sequence number at the start of a payload, if it is long enough to hold one; for
/// naming a frame in errors even when the rest of its header is bad.
pub fn peek_seq(payload: &[u8]) -> Option<u64> {
    payload.get(..8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_names_parse_back() {
        for code in 0..7 {
            let f = FrameFormat::from_code(code).unwrap();
            assert_eq!(f.name().parse::<FrameFormat>().unwrap(), f);
        }
        assert!(FrameFormat::from_code(7).is_none());
        assert!("yuv422".parse::<FrameFormat>().is_err());
    }
}
