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
//!
//! This file holds the driver-facing part: the config, the device list, and the camera that
//! opens a device, sets the negotiated mode and streams. `negotiate` picks the mode, `buffer`
//! turns a dequeued buffer into a frame.

mod buffer;
mod negotiate;

pub use buffer::{
    BUF_FLAG_ERROR, BUF_FLAG_TIMESTAMP_MASK, BUF_FLAG_TIMESTAMP_MONOTONIC, BadStride, BufferDecoder, BufferMeta,
    BufferProblem, LOSS_ERROR_FLAG, LOSS_SHORT_BUFFER, stamp_from_buffer, yuv_to_rgb,
};
pub use negotiate::{
    Chosen, Conversion, NoMode, OfferedFormat, OfferedSize, choose_format, conversion_for, describe_offered,
};

use negotiate::{fps_of, rate_matches};

use super::backend::{self, Backend, BackendDevices, CameraConfig, ColorBackend, TableError};
use super::{CaptureError, Clock, DeviceInfo, FrameSource};
use crate::core::frame::ColorFrame;
use crate::io::session::codec::FrameFormat;
use crate::io::session::meta::{BackendName, CameraMeta, CameraRole};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use v4l::buffer::Type as BufferType;
use v4l::frameinterval::FrameIntervalEnum;
use v4l::framesize::FrameSizeEnum;
use v4l::io::traits::{CaptureStream, Stream as _};
use v4l::prelude::{Device, MmapStream};
use v4l::video::Capture;
use v4l::{Format, FourCC, Fraction};

const BACKEND: &str = "v4l2";

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
            backend: BackendName::new(BACKEND),
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

// ---- its table in the rig config ------------------------------------------------------------

/// The backend, registered in `capture::backend`.
pub const REGISTERED: ColorBackend = Backend {
    name: BACKEND,
    table: read_table,
    list: Some(listing),
};

/// `[color] backend = "v4l2"`, as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawV4l2 {
    device: Option<PathBuf>,
    #[serde(default = "default_width")]
    width: u32,
    #[serde(default = "default_height")]
    height: u32,
    fps: Option<f64>,
}

fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}

fn read_table(table: toml::Table) -> Result<Arc<dyn CameraConfig<Frame = ColorFrame>>, TableError> {
    let c: RawV4l2 = backend::deserialize(BACKEND, table)?;
    let fps = c.fps.map(|f| backend::positive("fps", f, 1000.0)).transpose()?;
    let device = c
        .device
        .ok_or_else(|| TableError::new("device", "is needed for a v4l2 camera (e.g. /dev/video0)"))?;
    let (width, height) = (c.width, c.height);
    let max = backend::MAX_SENSOR_PX;
    if !(1..=max).contains(&u64::from(width)) || !(1..=max).contains(&u64::from(height)) {
        return Err(TableError::new(
            "width",
            format!("width and height must be from 1 to {max}, not {width}x{height}"),
        ));
    }
    Ok(Arc::new(V4l2Config {
        device,
        width,
        height,
        fps: fps.unwrap_or(30.0),
        format: None,
    }))
}

impl CameraConfig for V4l2Config {
    type Frame = ColorFrame;

    fn backend(&self) -> &'static str {
        BACKEND
    }

    fn open(&self) -> Result<Box<dyn FrameSource<Frame = ColorFrame>>, CaptureError> {
        Ok(Box::new(V4l2Color::open(self.clone())?))
    }

    fn frame_size(&self) -> Option<(u32, u32)> {
        Some((self.width, self.height))
    }
}

fn listing() -> BackendDevices {
    BackendDevices {
        backend: BACKEND,
        devices: list_devices(),
        error: None,
        scope: "video capture nodes under /dev".to_owned(),
    }
}
