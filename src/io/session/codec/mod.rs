//! The payload of one frame record: a 40-byte frame header (stamp, size, pixel format, codec)
//! followed by the pixels, raw or zstd-compressed, optionally after a horizontal delta filter.
//!
//! The delta filter replaces each sample by its difference to its left neighbour (wrapping,
//! the first sample of each row kept): depth and colour images are smooth along rows, so the
//! differences are small numbers that zstd at its fastest level packs well, fast enough to
//! record 30 frames a second on one core. Depth samples are `u16`, colour samples bytes.
//!
//! Decoding trusts nothing: the header's size, format and length must agree, and
//! decompression is bounded by the length the header announces (itself capped).
//!
//! This file holds the encoder and the decoders; `header` holds the frame header and what its
//! codes mean (pixel formats, codecs), and `delta` the undoing of the delta filter, with SSE2
//! where the target has it.

mod delta;
mod header;

pub use header::{Codec, FRAME_HEADER_LEN, FrameFormat, FrameHeader, MAX_PIXEL_BYTES, UnknownFormatName, peek_seq};

use delta::{undo_byte_delta, undo_sample_delta};

use crate::core::frame::{ColorFrame, DepthFrame, Stamp};
use std::fmt;
use std::io;

/// Errors of encoding and decoding frame payloads. The session reader adds the file and the
/// frame's position.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    #[error("frame of {width}x{height} exceeds the 65535x65535 the format can hold")]
    TooLarge { width: u32, height: u32 },
    #[error("frame data holds {actual} samples, expected {expected} for {width}x{height}")]
    DataLength {
        width: u32,
        height: u32,
        expected: usize,
        actual: usize,
    },
    #[error("payload of {len} bytes is shorter than the 40-byte frame header")]
    ShortPayload { len: usize },
    #[error("unknown pixel format code {0}")]
    UnknownFormat(u8),
    #[error("unknown codec {0}")]
    UnknownCodec(u8),
    #[error("holds {found} pixels, expected {expected}")]
    WrongFormat { found: FrameFormat, expected: &'static str },
    #[error("{width}x{height} {format} takes {expected} bytes but the header says {stated}")]
    LengthMismatch {
        width: u16,
        height: u16,
        format: FrameFormat,
        expected: u64,
        stated: u32,
    },
    #[error("pixel data of {0} bytes exceeds the {MAX_PIXEL_BYTES} byte limit")]
    TooManyBytes(u64),
    #[error("raw pixel data is {actual} bytes, expected {expected}")]
    RawLength { expected: usize, actual: usize },
    #[error("zstd decompression failed")]
    Decompress(#[source] io::Error),
    #[error("pixel data decompressed to {actual} bytes, expected {expected}")]
    DecompressedLength { expected: usize, actual: usize },
    #[error("zstd compression failed")]
    Compress(#[source] io::Error),
}

type Result<T, E = CodecError> = std::result::Result<T, E>;

/// Encodes frames into payloads with one codec and zstd level, reusing its compression
/// context between frames. Equal frames always give equal payloads.
pub struct FrameEncoder {
    codec: Codec,
    compressor: zstd::bulk::Compressor<'static>,
    pixels: Vec<u8>,
}

impl fmt::Debug for FrameEncoder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FrameEncoder")
            .field("codec", &self.codec)
            .finish_non_exhaustive()
    }
}

impl FrameEncoder {
    /// An encoder for `codec`; `level` is zstd's compression level (1 is fastest, negative
    /// levels are faster still, up to 22 is smaller), unused by [`Codec::Raw`].
    ///
    /// # Errors
    /// [`CodecError::Compress`] when zstd rejects the level.
    pub fn new(codec: Codec, level: i32) -> Result<Self> {
        let compressor = zstd::bulk::Compressor::new(level).map_err(CodecError::Compress)?;
        Ok(Self {
            codec,
            compressor,
            pixels: Vec::new(),
        })
    }

    pub fn codec(&self) -> Codec {
        self.codec
    }

    /// The payload of a depth frame.
    ///
    /// # Errors
    /// [`CodecError::TooLarge`] when a side exceeds 65535, [`CodecError::DataLength`] when
    /// `data` does not hold `width * height` samples, [`CodecError::Compress`].
    pub fn encode_depth(&mut self, frame: &DepthFrame) -> Result<Vec<u8>> {
        let (width, height) = check_size(frame.width, frame.height, frame.data.len(), 1)?;
        let row = usize::from(width);
        self.pixels.clear();
        self.pixels.reserve(frame.data.len() * 2);
        if self.codec == Codec::DeltaZstd && row > 0 {
            for line in frame.data.chunks_exact(row) {
                let mut left = 0u16;
                for &v in line {
                    self.pixels.extend_from_slice(&v.wrapping_sub(left).to_le_bytes());
                    left = v;
                }
            }
        } else {
            for &v in &frame.data {
                self.pixels.extend_from_slice(&v.to_le_bytes());
            }
        }
        self.finish(frame.stamp, width, height, FrameFormat::Depth16)
    }

    /// The payload of a colour frame.
    ///
    /// # Errors
    /// [`CodecError::TooLarge`] when a side exceeds 65535, [`CodecError::DataLength`] when
    /// `data` does not hold `width * height * bytes_per_pixel` bytes, [`CodecError::Compress`].
    pub fn encode_color(&mut self, frame: &ColorFrame) -> Result<Vec<u8>> {
        let bpp = frame.format.bytes_per_pixel();
        let (width, height) = check_size(frame.width, frame.height, frame.data.len(), bpp)?;
        let row = usize::from(width) * bpp;
        self.pixels.clear();
        if self.codec == Codec::DeltaZstd && row > 0 {
            self.pixels.reserve(frame.data.len());
            for line in frame.data.chunks_exact(row) {
                let mut left = 0u8;
                for &v in line {
                    self.pixels.push(v.wrapping_sub(left));
                    left = v;
                }
            }
        } else {
            self.pixels.extend_from_slice(&frame.data);
        }
        self.finish(frame.stamp, width, height, FrameFormat::Color(frame.format))
    }

    fn finish(&mut self, stamp: Stamp, width: u16, height: u16, format: FrameFormat) -> Result<Vec<u8>> {
        let pixel_bytes = u32::try_from(self.pixels.len())
            .ok()
            .filter(|&n| n <= MAX_PIXEL_BYTES)
            .ok_or(CodecError::TooManyBytes(self.pixels.len() as u64))?;
        let header = FrameHeader {
            stamp,
            width,
            height,
            format,
            codec: self.codec,
            pixel_bytes,
        };
        let body = match self.codec {
            Codec::Raw => None,
            Codec::Zstd | Codec::DeltaZstd => {
                Some(self.compressor.compress(&self.pixels).map_err(CodecError::Compress)?)
            }
        };
        let body = body.as_deref().unwrap_or(&self.pixels);
        let mut payload = Vec::with_capacity(FRAME_HEADER_LEN + body.len());
        payload.extend_from_slice(&header.to_bytes());
        payload.extend_from_slice(body);
        Ok(payload)
    }
}

/// Checks a frame's size against the format's limits and its data length.
fn check_size(width: u32, height: u32, samples: usize, per_pixel: usize) -> Result<(u16, u16)> {
    let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
        return Err(CodecError::TooLarge { width, height });
    };
    let expected = width as usize * height as usize * per_pixel;
    if samples != expected {
        return Err(CodecError::DataLength {
            width,
            height,
            expected,
            actual: samples,
        });
    }
    Ok((w, h))
}

thread_local! {
    /// Each thread's zstd decompression context, made once: making one per frame costs as
    /// much as decoding a small frame.
    static DECOMPRESSOR: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
        const { std::cell::RefCell::new(None) };
}

/// The pixel bytes of a payload as they were before compression and filtering (filter not
/// yet undone), with the checked header.
fn unpack(payload: &[u8]) -> Result<(FrameHeader, Vec<u8>)> {
    let header = FrameHeader::parse(payload)?;
    let body = payload.get(FRAME_HEADER_LEN..).unwrap_or_default();
    let expected = header.pixel_bytes as usize;
    let pixels = match header.codec {
        Codec::Raw => {
            if body.len() != expected {
                return Err(CodecError::RawLength {
                    expected,
                    actual: body.len(),
                });
            }
            body.to_vec()
        }
        Codec::Zstd | Codec::DeltaZstd => {
            // Bounded: zstd fails rather than write more than `expected` bytes.
            let out = DECOMPRESSOR.with_borrow_mut(|d| match d {
                Some(d) => d.decompress(body, expected),
                None => zstd::bulk::Decompressor::new().and_then(|fresh| d.insert(fresh).decompress(body, expected)),
            });
            let out = out.map_err(CodecError::Decompress)?;
            if out.len() != expected {
                return Err(CodecError::DecompressedLength {
                    expected,
                    actual: out.len(),
                });
            }
            out
        }
    };
    Ok((header, pixels))
}

/// Decodes a depth frame payload.
///
/// # Errors
/// [`CodecError::WrongFormat`] for a colour payload, and any of the header, length and
/// decompression errors.
pub fn decode_depth(payload: &[u8]) -> Result<DepthFrame> {
    let (header, pixels) = unpack(payload)?;
    if header.format != FrameFormat::Depth16 {
        return Err(CodecError::WrongFormat {
            found: header.format,
            expected: "depth16",
        });
    }
    let row = usize::from(header.width);
    let data = if header.codec == Codec::DeltaZstd && row > 0 {
        let mut data = vec![0u16; pixels.len() / 2];
        // The filter is undone in the same pass: a running sum that restarts at each row.
        for (line, bytes) in data.chunks_exact_mut(row).zip(pixels.chunks_exact(2 * row)) {
            undo_sample_delta(bytes, line);
        }
        data
    } else {
        crate::io::u16_samples(&pixels)
    };
    Ok(DepthFrame {
        stamp: header.stamp,
        width: header.width.into(),
        height: header.height.into(),
        data,
    })
}

/// Decodes a colour frame payload.
///
/// # Errors
/// [`CodecError::WrongFormat`] for a depth payload, and any of the header, length and
/// decompression errors.
pub fn decode_color(payload: &[u8]) -> Result<ColorFrame> {
    let (header, mut data) = unpack(payload)?;
    let FrameFormat::Color(format) = header.format else {
        return Err(CodecError::WrongFormat {
            found: header.format,
            expected: "a colour format",
        });
    };
    let row = usize::from(header.width) * format.bytes_per_pixel();
    if header.codec == Codec::DeltaZstd && row > 0 {
        for line in data.chunks_exact_mut(row) {
            undo_byte_delta(line);
        }
    }
    Ok(ColorFrame {
        stamp: header.stamp,
        width: header.width.into(),
        height: header.height.into(),
        format,
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::PixelFormat;

    fn depth(w: u32, h: u32) -> DepthFrame {
        let data = (0..w * h)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 20) as u16)
            .collect();
        DepthFrame {
            stamp: Stamp {
                seq: 7,
                device_ns: 8,
                host_ns: 9,
            },
            width: w,
            height: h,
            data,
        }
    }

    #[test]
    fn depth_round_trips_with_every_codec() {
        for codec in [Codec::Raw, Codec::Zstd, Codec::DeltaZstd] {
            let mut enc = FrameEncoder::new(codec, 1).unwrap();
            for (w, h) in [(640, 480), (3, 2), (0, 0), (1, 5)] {
                let frame = depth(w, h);
                let payload = enc.encode_depth(&frame).unwrap();
                assert_eq!(decode_depth(&payload).unwrap(), frame, "{codec:?} {w}x{h}");
                assert!(matches!(decode_color(&payload), Err(CodecError::WrongFormat { .. })));
            }
        }
    }

    #[test]
    fn colour_round_trips_in_every_format() {
        for format in PixelFormat::ALL {
            let (w, h) = (33, 17);
            let data = (0..ColorFrame::expected_len(w, h, format))
                .map(|i| (i * i / 7) as u8)
                .collect();
            let frame = ColorFrame {
                stamp: Stamp {
                    seq: 1,
                    device_ns: 2,
                    host_ns: 3,
                },
                width: w,
                height: h,
                format,
                data,
            };
            for codec in [Codec::Raw, Codec::Zstd, Codec::DeltaZstd] {
                let payload = FrameEncoder::new(codec, 3).unwrap().encode_color(&frame).unwrap();
                assert_eq!(payload[28], FrameFormat::Color(format).code());
                assert_eq!(decode_color(&payload).unwrap(), frame);
            }
        }
    }

    #[test]
    fn delta_layout_matches_the_documented_filter() {
        let frame = DepthFrame {
            stamp: Stamp::default(),
            width: 3,
            height: 2,
            data: vec![10, 12, 9, 500, 400, 65535],
        };
        let payload = FrameEncoder::new(Codec::DeltaZstd, 1)
            .unwrap()
            .encode_depth(&frame)
            .unwrap();
        let raw = zstd::bulk::decompress(&payload[FRAME_HEADER_LEN..], 12).unwrap();
        let samples: Vec<u16> = raw.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
        assert_eq!(samples, vec![10, 2, 65533, 500, 65436, 65135]);
    }

    #[test]
    fn bad_payloads_are_rejected() {
        let mut enc = FrameEncoder::new(Codec::DeltaZstd, 1).unwrap();
        let good = enc.encode_depth(&depth(16, 8)).unwrap();
        assert!(matches!(
            decode_depth(&good[..39]),
            Err(CodecError::ShortPayload { len: 39 })
        ));
        let mut bad = good.clone();
        bad[28] = 9;
        assert!(matches!(decode_depth(&bad), Err(CodecError::UnknownFormat(9))));
        let mut bad = good.clone();
        bad[29] = 3;
        assert!(matches!(decode_depth(&bad), Err(CodecError::UnknownCodec(3))));
        let mut bad = good.clone();
        bad[24] = 17;
        assert!(matches!(decode_depth(&bad), Err(CodecError::LengthMismatch { .. })));
        // A header claiming a bigger frame, consistently: decompression must stop at the data.
        let mut bad = good.clone();
        bad[24..26].copy_from_slice(&32u16.to_le_bytes());
        bad[32..36].copy_from_slice(&(32u32 * 8 * 2).to_le_bytes());
        assert!(matches!(decode_depth(&bad), Err(CodecError::DecompressedLength { .. })));
        // Claiming a smaller one: zstd must not write past the announced length.
        let mut bad = good.clone();
        bad[24..26].copy_from_slice(&8u16.to_le_bytes());
        bad[32..36].copy_from_slice(&(8u32 * 8 * 2).to_le_bytes());
        assert!(matches!(decode_depth(&bad), Err(CodecError::Decompress(_))));
        let mut bad = good.clone();
        bad.truncate(60);
        assert!(decode_depth(&bad).is_err());
        // Over the byte cap.
        let mut bad = good;
        bad[24..26].copy_from_slice(&16384u16.to_le_bytes());
        bad[26..28].copy_from_slice(&16384u16.to_le_bytes());
        bad[32..36].copy_from_slice(&(16384u32 * 16384 * 2).to_le_bytes());
        assert!(matches!(decode_depth(&bad), Err(CodecError::TooManyBytes(_))));
    }

    #[test]
    fn oversized_or_inconsistent_frames_are_refused() {
        let mut enc = FrameEncoder::new(Codec::Raw, 1).unwrap();
        let mut frame = depth(4, 4);
        frame.data.pop();
        assert!(matches!(enc.encode_depth(&frame), Err(CodecError::DataLength { .. })));
        let frame = DepthFrame {
            stamp: Stamp::default(),
            width: 70_000,
            height: 0,
            data: vec![],
        };
        assert!(matches!(enc.encode_depth(&frame), Err(CodecError::TooLarge { .. })));
    }
}
