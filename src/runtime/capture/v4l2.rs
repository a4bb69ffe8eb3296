//! The colour camera through Video4Linux2 (UVC webcams and other V4L2 capture devices), read
//! with memory-mapped streaming through the `v4l` crate.
//!
//! The driver-facing part ([`V4l2Color`]) is thin; what can go wrong with data is in pure
//! functions tested on fixtures shaped like what the kernel returns:
//! - [`choose_format`]: picks a (fourcc, size, frame interval) among what the device offers,
//!   preferring formats that convert to ours losslessly: `GREY` (Mono8), `RGB3` (Rgb8), the
//!   8-bit Bayer formats `BA81`/`GBRG`/`GRBG`/`RGGB` (our Bayer formats), then `YUYV`. `YUYV`
//!   becomes Rgb8 (BT.601 limited range): it keeps the colour the paw detector may use, at the
//!   cost of the 4:2:2 chroma subsampling and rounding. (Its luma alone would give Mono8
//!   losslessly; [`Conversion::YuyvToMono8`] does that but negotiation does not pick it.)
//!   `MJPG` is refused: mousepose has no JPEG decoder on the capture path.
//! - [`stamp_from_buffer`]: `seq` is the buffer's sequence number (a gap is a frame the
//!   kernel dropped), `device_ns` the kernel timestamp, and `host_ns` that same timestamp when
//!   the buffer says it is `CLOCK_MONOTONIC` (the host clock, see [`super::clock`]), otherwise
//!   the host clock read at dequeue.
//! - [`BufferDecoder`]: checks `bytesused` against the negotiated stride and height and
//!   converts into the frame's buffer without intermediate allocation; buffers that are too
//!   short or flagged as erroneous are counted as losses, never returned.
//! - [`list_devices`]: the `/dev/video*` nodes that can capture video, with card name and bus.

use super::{CaptureError, Clock, DeviceInfo, FrameSource};
use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::io::session::codec::FrameFormat;
use crate::io::session::meta::{Backend, CameraMeta, CameraRole};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;
use v4l::buffer::Type as BufferType;
use v4l::frameinterval::FrameIntervalEnum;
use v4l::framesize::FrameSizeEnum;
use v4l::io::traits::{CaptureStream, Stream as _};
use v4l::prelude::{Device, MmapStream};
use v4l::video::Capture;
use v4l::{Format, FourCC, Fraction};

const BACKEND: &str = "v4l2";

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

/// Buffers asked of the driver for streaming.
const BUFFER_COUNT: u32 = 4;
/// `POLLIN` (the same value on every Linux architecture).
const POLLIN: i16 = 0x0001;

/// Which V4L2 camera to open and in which mode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct V4l2Config {
    /// The device node (a `/dev/videoN` or a stable udev symlink).
    pub device: PathBuf,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    /// A V4L2 fourcc (`YUYV`, `GREY`, ...) to insist on; `None` lets negotiation choose.
    #[serde(default)]
    pub format: Option<String>,
}

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

/// How a buffer becomes a [`ColorFrame`].
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
    fn input_bytes_per_pixel(self, output: PixelFormat) -> usize {
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

fn fps_of([num, den]: [u32; 2]) -> f64 {
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
fn rate_matches(interval: [u32; 2], fps: f64) -> bool {
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

/// The V4L2 capture devices under `/dev`, with the driver's card name and bus; empty when
/// there are none.
pub fn list_devices() -> Vec<DeviceInfo> {
    list_devices_in(Path::new("/dev"))
}

/// The V4L2 capture devices among the `video*` entries of `dir`. Entries that cannot be opened
/// or are not video capture devices (a UVC camera's metadata node) are left out.
pub fn list_devices_in(dir: &Path) -> Vec<DeviceInfo> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with("video"))
        .map(|e| e.path())
        .collect();
    paths.sort();
    paths
        .into_iter()
        .filter_map(|path| {
            let device = open_device(&path).ok()?;
            let caps = device.query_caps().ok()?;
            if !caps.capabilities.contains(v4l::capability::Flags::VIDEO_CAPTURE) {
                return None;
            }
            Some(DeviceInfo {
                backend: BACKEND,
                id: path.display().to_string(),
                model: caps.card.clone(),
                serial: String::new(),
                details: format!("driver {}, bus {}", caps.driver, caps.bus),
            })
        })
        .collect()
}

fn open_device(path: &Path) -> io::Result<Device> {
    // The crate panics on a path with a NUL byte; no device has one.
    if path.as_os_str().as_encoded_bytes().contains(&0) {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, "path holds a NUL byte"));
    }
    Device::with_path(path)
}

/// What the device offers, in the form [`choose_format`] reads; stepwise sizes and intervals
/// are reduced to the wanted ones when they fit.
fn enumerate(device: &Device, wanted: &V4l2Config) -> io::Result<Vec<OfferedFormat>> {
    let mut offered = Vec::new();
    for description in device.enum_formats()? {
        let fourcc = String::from_utf8_lossy(&description.fourcc.repr).into_owned();
        let mut sizes = Vec::new();
        for size in device.enum_framesizes(description.fourcc).unwrap_or_default() {
            let (width, height) = match size.size {
                FrameSizeEnum::Discrete(d) => (d.width, d.height),
                FrameSizeEnum::Stepwise(s) => {
                    let fits = |v: u32, min: u32, max: u32, step: u32| {
                        (min..=max).contains(&v) && (step == 0 || (v - min) % step == 0)
                    };
                    if fits(wanted.width, s.min_width, s.max_width, s.step_width)
                        && fits(wanted.height, s.min_height, s.max_height, s.step_height)
                    {
                        (wanted.width, wanted.height)
                    } else {
                        continue;
                    }
                }
            };
            let mut intervals = Vec::new();
            for interval in device
                .enum_frameintervals(description.fourcc, width, height)
                .unwrap_or_default()
            {
                match interval.interval {
                    FrameIntervalEnum::Discrete(f) => intervals.push([f.numerator, f.denominator]),
                    FrameIntervalEnum::Stepwise(s) => {
                        let (fast, slow) = (
                            fps_of([s.min.numerator, s.min.denominator]),
                            fps_of([s.max.numerator, s.max.denominator]),
                        );
                        if wanted.fps > 0.0 && wanted.fps <= fast * 1.01 && wanted.fps >= slow * 0.99 {
                            // The wanted rate as a fraction of microseconds.
                            intervals.push([(1e6 / wanted.fps).round() as u32, 1_000_000]);
                        }
                    }
                }
            }
            sizes.push(OfferedSize {
                width,
                height,
                intervals,
            });
        }
        offered.push(OfferedFormat {
            fourcc,
            description: description.description,
            sizes,
        });
    }
    Ok(offered)
}

/// A V4L2 colour camera streaming through memory-mapped buffers.
pub struct V4l2Color {
    config: V4l2Config,
    id: String,
    device: Device,
    card: String,
    bus: String,
    decoder: BufferDecoder,
    stream: Option<MmapStream<'static>>,
    clock: Clock,
}

impl fmt::Debug for V4l2Color {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("V4l2Color")
            .field("config", &self.config)
            .field("card", &self.card)
            .field("bus", &self.bus)
            .field("decoder", &self.decoder)
            .field("streaming", &self.stream.is_some())
            .finish_non_exhaustive()
    }
}

impl V4l2Color {
    /// Opens the device, negotiates the mode (see [`choose_format`]) and sets it.
    ///
    /// # Errors
    /// [`CaptureError::NotFound`] when the path does not exist, [`CaptureError::Driver`] when
    /// it is not a V4L2 capture device or an ioctl fails, [`CaptureError::Refused`] when no
    /// offered mode fits or the driver does not take the chosen one.
    pub fn open(config: V4l2Config) -> Result<Self, CaptureError> {
        let id = config.device.display().to_string();
        let driver = |what: &str, source: io::Error| CaptureError::Driver {
            backend: BACKEND,
            id: id.clone(),
            what: what.to_owned(),
            source: Some(Box::new(source)),
        };
        let device = match open_device(&config.device) {
            Ok(device) => device,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(CaptureError::NotFound { backend: BACKEND, id });
            }
            Err(e) => return Err(driver("cannot open the device", e)),
        };
        let caps = device
            .query_caps()
            .map_err(|e| driver("not a V4L2 device (VIDIOC_QUERYCAP failed)", e))?;
        if !caps.capabilities.contains(v4l::capability::Flags::VIDEO_CAPTURE)
            || !caps.capabilities.contains(v4l::capability::Flags::STREAMING)
        {
            return Err(CaptureError::Refused {
                backend: BACKEND,
                id,
                what: "video capture".to_owned(),
                reason: format!("{} ({}) cannot stream video capture", caps.card, caps.driver),
            });
        }
        let offered = enumerate(&device, &config).map_err(|e| driver("cannot list formats", e))?;
        let refused = |what: String, reason: String| CaptureError::Refused {
            backend: BACKEND,
            id: id.clone(),
            what,
            reason,
        };
        let chosen =
            choose_format(&offered, &config).map_err(|e| refused(format!("mode {}", e.wanted), e.to_string()))?;
        let mut fourcc = [0u8; 4];
        for (slot, byte) in fourcc.iter_mut().zip(chosen.fourcc.bytes()) {
            *slot = byte;
        }
        let set = device
            .set_format(&Format::new(chosen.width, chosen.height, FourCC::new(&fourcc)))
            .map_err(|e| driver("VIDIOC_S_FMT failed", e))?;
        if (set.width, set.height, set.fourcc.repr) != (chosen.width, chosen.height, fourcc) {
            return Err(refused(
                format!("mode {} {}x{}", chosen.fourcc, chosen.width, chosen.height),
                format!("the driver set {} {}x{} instead", set.fourcc, set.width, set.height),
            ));
        }
        let [num, den] = chosen.interval;
        match device.set_params(&v4l::video::capture::Parameters::new(Fraction::new(num, den))) {
            Ok(params) if !rate_matches([params.interval.numerator, params.interval.denominator], chosen.fps()) => {
                tracing::warn!(
                    message = "V4L2 camera kept another frame rate.",
                    device = %id,
                    wanted_fps = chosen.fps(),
                    fps = fps_of([params.interval.numerator, params.interval.denominator]),
                );
            }
            Ok(_) => {}
            Err(error) => {
                tracing::warn!(message = "V4L2 camera refused the frame rate.", device = %id, %error);
            }
        }
        tracing::info!(
            message = "V4L2 camera mode set.",
            device = %id,
            card = %caps.card,
            fourcc = %chosen.fourcc,
            width = chosen.width,
            height = chosen.height,
            fps = chosen.fps(),
            output = %chosen.output,
            bytes_per_line = set.stride,
        );
        let decoder =
            BufferDecoder::new(chosen, set.stride).map_err(|e| refused("stride".to_owned(), e.to_string()))?;
        Ok(Self {
            config,
            id,
            device,
            card: caps.card,
            bus: caps.bus,
            decoder,
            stream: None,
            clock: Clock::Monotonic,
        })
    }

    fn driver_error(&self, what: &str, source: io::Error) -> CaptureError {
        if source.raw_os_error() == Some(19) {
            // ENODEV: the camera was unplugged.
            return CaptureError::Disconnected {
                backend: BACKEND,
                id: self.id.clone(),
                reason: source.to_string(),
            };
        }
        CaptureError::Driver {
            backend: BACKEND,
            id: self.id.clone(),
            what: what.to_owned(),
            source: Some(Box::new(source)),
        }
    }
}

impl FrameSource for V4l2Color {
    type Frame = ColorFrame;

    fn meta(&self) -> CameraMeta {
        let chosen = self.decoder.chosen();
        CameraMeta {
            role: CameraRole::Color,
            backend: Backend::V4l2,
            model: self.card.clone(),
            serial: self.bus.clone(),
            firmware: String::new(),
            width: chosen.width,
            height: chosen.height,
            pixel_format: FrameFormat::Color(chosen.output),
            fps: chosen.fps(),
        }
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        self.stop()?;
        self.clock = clock.clone();
        let mut stream = MmapStream::with_buffers(&self.device, BufferType::VideoCapture, BUFFER_COUNT)
            .map_err(|e| self.driver_error("cannot map buffers", e))?;
        // Buffer 0 is left for the first `next()`, which queues the buffer it last returned
        // before dequeuing; all others are queued now so that `next()` is only called once
        // `poll` says a buffer is ready (the crate's own timeout would re-queue a queued buffer).
        for index in 1..BUFFER_COUNT as usize {
            if let Err(e) = CaptureStream::queue(&mut stream, index) {
                if index >= 2 && e.kind() == io::ErrorKind::InvalidInput {
                    break; // the driver gave fewer buffers
                }
                return Err(self.driver_error("VIDIOC_QBUF failed", e));
            }
        }
        stream
            .start()
            .map_err(|e| self.driver_error("VIDIOC_STREAMON failed", e))?;
        self.stream = Some(stream);
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<ColorFrame>, CaptureError> {
        let Some(stream) = self.stream.as_mut() else {
            return Ok(None);
        };
        let timeout_ms = i32::try_from(timeout.as_millis()).unwrap_or(i32::MAX);
        let ready = stream.handle().poll(POLLIN, timeout_ms);
        match ready {
            Ok(0) => return Ok(None),
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::Interrupted => return Ok(None),
            Err(e) => return Err(self.driver_error("poll failed", e)),
        }
        let (data, meta) = match stream.next() {
            Ok((data, meta)) => (
                data,
                BufferMeta {
                    sequence: meta.sequence,
                    timestamp_sec: meta.timestamp.sec,
                    timestamp_usec: meta.timestamp.usec,
                    flags: meta.flags.bits(),
                    bytesused: meta.bytesused,
                },
            ),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(None),
            Err(e) => {
                let error = self.driver_error("VIDIOC_DQBUF failed", e);
                return Err(error);
            }
        };
        Ok(self.decoder.decode(data, &meta, &self.clock))
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        self.decoder.losses()
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        if let Some(mut stream) = self.stream.take() {
            stream
                .stop()
                .map_err(|e| self.driver_error("VIDIOC_STREAMOFF failed", e))?;
        }
        Ok(())
    }
}
