//! A dequeued buffer turned into a frame, pure: its stamp ([`stamp_from_buffer`]), the checks
//! of its flags and of the bytes it uses against the negotiated mode, and its rows converted
//! into the frame's pixels ([`BufferDecoder`], [`yuv_to_rgb`]).

use super::{Chosen, Conversion};
use crate::core::frame::{ColorFrame, Stamp};
use crate::runtime::capture::Clock;
use serde::{Deserialize, Serialize};

/// `V4L2_BUF_FLAG_ERROR`: the buffer was filled but its data may be corrupt.
pub const BUF_FLAG_ERROR: u32 = 0x0000_0040;
/// `V4L2_BUF_FLAG_TIMESTAMP_MASK`: which clock the buffer's timestamp is on.
pub const BUF_FLAG_TIMESTAMP_MASK: u32 = 0x0000_e000;
/// `V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC`: the timestamp is `CLOCK_MONOTONIC`.
pub const BUF_FLAG_TIMESTAMP_MONOTONIC: u32 = 0x0000_2000;

/// The loss reason of a buffer whose `bytesused` does not cover a whole frame.
pub const LOSS_SHORT_BUFFER: &str = "short_buffer";
/// The loss reason of a buffer the driver flagged with `V4L2_BUF_FLAG_ERROR`.
pub const LOSS_ERROR_FLAG: &str = "error_flag";

/// What the kernel says about one dequeued buffer (`struct v4l2_buffer`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BufferMeta {
    pub sequence: u32,
    pub timestamp_sec: i64,
    pub timestamp_usec: i64,
    pub flags: u32,
    pub bytesused: u32,
}

impl BufferMeta {
    /// The kernel timestamp in nanoseconds, `None` when it is negative or malformed.
    pub fn timestamp_ns(&self) -> Option<u64> {
        let sec = u64::try_from(self.timestamp_sec).ok()?;
        let usec = u64::try_from(self.timestamp_usec).ok().filter(|&u| u < 1_000_000)?;
        sec.checked_mul(1_000_000_000)?.checked_add(usec * 1000)
    }

    /// Whether the timestamp is on `CLOCK_MONOTONIC`.
    pub fn monotonic(&self) -> bool {
        self.flags & BUF_FLAG_TIMESTAMP_MASK == BUF_FLAG_TIMESTAMP_MONOTONIC
    }
}

/// The stamp of a dequeued buffer: `seq` its sequence number, `device_ns` the kernel
/// timestamp (0 when malformed), `host_ns` the kernel timestamp when it is monotonic and the
/// host clock is the monotonic clock, otherwise `clock.now_ns()` (a replay clock is never
/// mixed with kernel time).
pub fn stamp_from_buffer(meta: &BufferMeta, clock: &Clock) -> Stamp {
    let kernel_ns = meta.timestamp_ns();
    let host_ns = match (kernel_ns, clock) {
        (Some(ns), Clock::Monotonic) if meta.monotonic() && ns > 0 => ns,
        _ => clock.now_ns(),
    };
    Stamp {
        seq: u64::from(meta.sequence),
        device_ns: kernel_ns.unwrap_or(0),
        host_ns,
    }
}

/// Why a buffer was not turned into a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BufferProblem {
    #[error("buffer holds {bytesused} bytes, a frame needs {needed}")]
    Short { bytesused: usize, needed: usize },
    #[error("buffer says {bytesused} bytes are used but is {len} bytes long")]
    Overlong { bytesused: usize, len: usize },
    #[error("the driver flagged the buffer as erroneous")]
    ErrorFlag,
}

impl BufferProblem {
    /// The loss reason counted for this problem.
    pub fn reason(self) -> &'static str {
        match self {
            BufferProblem::Short { .. } | BufferProblem::Overlong { .. } => LOSS_SHORT_BUFFER,
            BufferProblem::ErrorFlag => LOSS_ERROR_FLAG,
        }
    }
}

/// The driver's line stride is shorter than a row of the chosen format.
#[derive(Debug, thiserror::Error)]
#[error("stride of {bytes_per_line} bytes is shorter than a {width}-pixel {fourcc} row")]
pub struct BadStride {
    pub bytes_per_line: u32,
    pub width: u32,
    pub fourcc: String,
}

/// Turns the buffers of one negotiated mode into frames and counts those it refuses.
#[derive(Debug)]
pub struct BufferDecoder {
    chosen: Chosen,
    bytes_per_line: usize,
    row_in: usize,
    short_buffers: u64,
    error_flags: u64,
}

impl BufferDecoder {
    /// A decoder for buffers of `chosen` with the driver's `bytes_per_line` (0 means packed).
    ///
    /// # Errors
    /// The stride is shorter than a row.
    pub fn new(chosen: Chosen, bytes_per_line: u32) -> Result<Self, BadStride> {
        let row_in = chosen.width as usize * chosen.conversion.input_bytes_per_pixel(chosen.output);
        let stride = if bytes_per_line == 0 {
            row_in
        } else {
            bytes_per_line as usize
        };
        if stride < row_in {
            return Err(BadStride {
                bytes_per_line,
                width: chosen.width,
                fourcc: chosen.fourcc.clone(),
            });
        }
        Ok(Self {
            chosen,
            bytes_per_line: stride,
            row_in,
            short_buffers: 0,
            error_flags: 0,
        })
    }

    /// The mode this decoder reads.
    pub fn chosen(&self) -> &Chosen {
        &self.chosen
    }

    /// The bytes a buffer must use: every row at its stride, the last one without padding.
    pub fn needed_bytes(&self) -> usize {
        match self.chosen.height as usize {
            0 => 0,
            h => self.bytes_per_line * (h - 1) + self.row_in,
        }
    }

    /// Checks a buffer (`data` is the whole mapped buffer, `bytesused` what the kernel filled)
    /// and converts it into `out`, which is cleared first; no allocation happens when `out`
    /// already has the frame's capacity.
    ///
    /// # Errors
    /// The problem with the buffer; `out` is then left empty.
    pub fn convert_into(&self, data: &[u8], meta: &BufferMeta, out: &mut Vec<u8>) -> Result<(), BufferProblem> {
        out.clear();
        if meta.flags & BUF_FLAG_ERROR != 0 {
            return Err(BufferProblem::ErrorFlag);
        }
        let bytesused = meta.bytesused as usize;
        let needed = self.needed_bytes();
        if bytesused > data.len() {
            return Err(BufferProblem::Overlong {
                bytesused,
                len: data.len(),
            });
        }
        if bytesused < needed {
            return Err(BufferProblem::Short { bytesused, needed });
        }
        let used = data.get(..bytesused).unwrap_or_default();
        out.reserve(ColorFrame::expected_len(
            self.chosen.width,
            self.chosen.height,
            self.chosen.output,
        ));
        for row in used.chunks(self.bytes_per_line).take(self.chosen.height as usize) {
            let row = row.get(..self.row_in).unwrap_or(row);
            match self.chosen.conversion {
                Conversion::Copy => out.extend_from_slice(row),
                Conversion::YuyvToMono8 => out.extend(row.iter().step_by(2)),
                Conversion::YuyvToRgb8 => {
                    for quad in row.chunks_exact(4) {
                        if let &[y0, u, y1, v] = quad {
                            out.extend_from_slice(&yuv_to_rgb(y0, u, v));
                            out.extend_from_slice(&yuv_to_rgb(y1, u, v));
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Checks and converts one buffer into a frame; a refused buffer is counted and gives
    /// `None`.
    pub fn decode(&mut self, data: &[u8], meta: &BufferMeta, clock: &Clock) -> Option<ColorFrame> {
        let mut pixels = Vec::with_capacity(ColorFrame::expected_len(
            self.chosen.width,
            self.chosen.height,
            self.chosen.output,
        ));
        if let Err(problem) = self.convert_into(data, meta, &mut pixels) {
            match problem.reason() {
                LOSS_ERROR_FLAG => self.error_flags += 1,
                _ => self.short_buffers += 1,
            }
            tracing::trace!(message = "V4L2 buffer refused.", seq = meta.sequence, %problem);
            return None;
        }
        Some(ColorFrame {
            stamp: stamp_from_buffer(meta, clock),
            width: self.chosen.width,
            height: self.chosen.height,
            format: self.chosen.output,
            data: pixels,
        })
    }

    /// Buffers refused so far, by reason (only reasons that occurred).
    pub fn losses(&self) -> Vec<(&'static str, u64)> {
        [
            (LOSS_SHORT_BUFFER, self.short_buffers),
            (LOSS_ERROR_FLAG, self.error_flags),
        ]
        .into_iter()
        .filter(|&(_, n)| n > 0)
        .collect()
    }
}

/// One YUV sample to RGB, BT.601 limited range ("studio swing"), in 8.8 fixed point.
pub fn yuv_to_rgb(y: u8, u: u8, v: u8) -> [u8; 3] {
    let c = i32::from(y) - 16;
    let d = i32::from(u) - 128;
    let e = i32::from(v) - 128;
    let clamp = |x: i32| ((x + 128) >> 8).clamp(0, 255) as u8;
    [
        clamp(298 * c + 409 * e),
        clamp(298 * c - 100 * d - 208 * e),
        clamp(298 * c + 516 * d),
    ]
}
