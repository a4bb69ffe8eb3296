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

use crate::core::frame::{ColorFrame, DepthFrame, PixelFormat, Stamp};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::io;
use std::str::FromStr;

/// Length of the frame header at the start of every frame payload.
pub const FRAME_HEADER_LEN: usize = 40;

/// The most pixel bytes one frame may hold (256 MiB).
pub const MAX_PIXEL_BYTES: u32 = 256 << 20;

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
    fn to_bytes(self) -> [u8; FRAME_HEADER_LEN] {
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
    let mut data = vec![0u16; pixels.len() / 2];
    if header.codec == Codec::DeltaZstd && row > 0 {
        // The filter is undone in the same pass: a running sum that restarts at each row.
        for (line, bytes) in data.chunks_exact_mut(row).zip(pixels.chunks_exact(2 * row)) {
            undo_sample_delta(bytes, line);
        }
    } else {
        for (v, b) in data.iter_mut().zip(pixels.chunks_exact(2)) {
            *v = u16::from_le_bytes([b[0], b[1]]);
        }
    }
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

/// Undoes the horizontal delta filter on one row of bytes: each byte becomes the wrapping sum
/// of itself and every byte to its left. Sixteen bytes at a time with SSE2: a byte-wise prefix
/// sum in four shifted additions, plus the running total of the row so far, which is carried
/// in a register (one addition per sixteen bytes on the loop's critical path). Several times
/// faster than byte by byte.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
fn undo_byte_delta(line: &mut [u8]) {
    use safe_arch::{
        add_i8_m128i, byte_shl_imm_u128_m128i, m128i, shuffle_ai_f32_all_m128i, unpack_high_i8_m128i,
        unpack_high_i16_m128i, zeroed_m128i,
    };
    // Every byte of `carry` holds the row's sum up to the current chunk.
    let mut carry = zeroed_m128i();
    let mut left = 0u8;
    let mut chunks = line.chunks_exact_mut(16);
    for chunk in &mut chunks {
        let mut bytes = [0u8; 16];
        bytes.copy_from_slice(chunk);
        let mut x = m128i::from(bytes);
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<1>(x));
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<2>(x));
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<4>(x));
        x = add_i8_m128i(x, byte_shl_imm_u128_m128i::<8>(x));
        chunk.copy_from_slice(&<[u8; 16]>::from(add_i8_m128i(x, carry)));
        left = chunk[15];
        // The chunk's own total (its last byte) in every byte.
        let high = unpack_high_i16_m128i(unpack_high_i8_m128i(x, x), unpack_high_i8_m128i(x, x));
        carry = add_i8_m128i(carry, shuffle_ai_f32_all_m128i::<0xFF>(high));
    }
    undo_byte_delta_tail(chunks.into_remainder(), left);
}

/// Undoes the horizontal delta filter on one row of bytes: each byte becomes the wrapping sum
/// of itself and every byte to its left. Eight bytes at a time (a byte-wise prefix sum inside
/// a `u64`, without carries between bytes), several times faster than byte by byte.
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
fn undo_byte_delta(line: &mut [u8]) {
    /// Byte-wise wrapping addition of two `u64`s.
    fn add_bytes(a: u64, b: u64) -> u64 {
        const LOW: u64 = 0x7f7f_7f7f_7f7f_7f7f;
        ((a & LOW) + (b & LOW)) ^ ((a ^ b) & !LOW)
    }
    let mut left = 0u8;
    let mut chunks = line.chunks_exact_mut(8);
    for chunk in &mut chunks {
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(chunk);
        let mut x = u64::from_le_bytes(bytes);
        x = add_bytes(x, x << 8);
        x = add_bytes(x, x << 16);
        x = add_bytes(x, x << 32);
        x = add_bytes(x, u64::from_le_bytes([left; 8]));
        chunk.copy_from_slice(&x.to_le_bytes());
        left = chunk[7];
    }
    undo_byte_delta_tail(chunks.into_remainder(), left);
}

/// Undoes the horizontal delta filter on one row of depth samples: `bytes` holds the row's
/// little-endian `u16` differences, `out` receives the samples, each the wrapping sum of its
/// difference and every difference to its left. Eight samples at a time with SSE2, as
/// [`undo_byte_delta`] does sixteen bytes.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
fn undo_sample_delta(bytes: &[u8], out: &mut [u16]) {
    use safe_arch::{
        add_i16_m128i, byte_shl_imm_u128_m128i, m128i, shuffle_ai_f32_all_m128i, unpack_high_i16_m128i, zeroed_m128i,
    };
    let mut carry = zeroed_m128i();
    let mut left = 0u16;
    let mut chunks = bytes.chunks_exact(16);
    let mut outs = out.chunks_exact_mut(8);
    for (chunk, o) in (&mut chunks).zip(&mut outs) {
        let mut b = [0u8; 16];
        b.copy_from_slice(chunk);
        let mut x = m128i::from(b);
        x = add_i16_m128i(x, byte_shl_imm_u128_m128i::<2>(x));
        x = add_i16_m128i(x, byte_shl_imm_u128_m128i::<4>(x));
        x = add_i16_m128i(x, byte_shl_imm_u128_m128i::<8>(x));
        o.copy_from_slice(&<[u16; 8]>::from(add_i16_m128i(x, carry)));
        left = o[7];
        carry = add_i16_m128i(carry, shuffle_ai_f32_all_m128i::<0xFF>(unpack_high_i16_m128i(x, x)));
    }
    undo_sample_delta_tail(chunks.remainder(), outs.into_remainder(), left);
}

/// Undoes the horizontal delta filter on one row of depth samples (see the SSE2 version).
#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
fn undo_sample_delta(bytes: &[u8], out: &mut [u16]) {
    undo_sample_delta_tail(bytes, out, 0);
}

/// The last samples of a row that do not fill a vector, `left` the sample before them.
fn undo_sample_delta_tail(bytes: &[u8], out: &mut [u16], mut left: u16) {
    for (v, b) in out.iter_mut().zip(bytes.chunks_exact(2)) {
        left = left.wrapping_add(u16::from_le_bytes([b[0], b[1]]));
        *v = left;
    }
}

/// The last bytes of a row that do not fill a vector, `left` the byte before them.
fn undo_byte_delta_tail(rest: &mut [u8], mut left: u8) {
    for v in rest {
        *v = v.wrapping_add(left);
        left = *v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn the_fast_sample_delta_undo_matches_the_sample_by_sample_one() {
        for len in [0usize, 1, 7, 8, 9, 17, 640, 1283] {
            let deltas: Vec<u16> = (0..len).map(|i| (i.wrapping_mul(2_654_435_761) >> 11) as u16).collect();
            let bytes: Vec<u8> = deltas.iter().flat_map(|d| d.to_le_bytes()).collect();
            let mut fast = vec![0u16; len];
            undo_sample_delta(&bytes, &mut fast);
            let mut left = 0u16;
            let slow: Vec<u16> = deltas
                .iter()
                .map(|&d| {
                    left = left.wrapping_add(d);
                    left
                })
                .collect();
            assert_eq!(fast, slow, "row of {len}");
        }
    }

    #[test]
    fn the_fast_delta_undo_matches_the_byte_by_byte_one() {
        for len in [0usize, 1, 7, 8, 9, 17, 640, 1283] {
            let deltas: Vec<u8> = (0..len).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
            let mut fast = deltas.clone();
            undo_byte_delta(&mut fast);
            let mut left = 0u8;
            let slow: Vec<u8> = deltas
                .iter()
                .map(|d| {
                    left = left.wrapping_add(*d);
                    left
                })
                .collect();
            assert_eq!(fast, slow, "{len} bytes");
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
