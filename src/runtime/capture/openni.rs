//! The depth camera read through OpenNI2 (Asus Xtion, PrimeSense, Orbbec and the like), or a
//! `.oni` recording played back through the same driver layer.
//!
//! The device is opened by URI (a camera's URI, `"Dummy"` for Debian's test device, or the path
//! of a `.oni` file), by serial number (every listed device is opened in turn and asked), or,
//! with neither, as the first device the drivers list. `start` picks the depth mode the config
//! asks for among the sensor's modes (16-bit millimetres only) and refuses, naming the modes
//! there are, when none matches.
//!
//! Frames keep OpenNI2's metadata: `seq` is the driver's `frameIndex`, `device_ns` its
//! `timestamp` (device microseconds) in nanoseconds, `host_ns` the host clock when the frame was
//! read. Each frame is copied once, from the driver's buffer straight into the frame that is
//! passed on.
//!
//! A recording plays back one frame per read (OpenNI2's "manual" speed), so none is lost
//! whatever the reader's pace, without repeat, and [`FrameSource::finished`] turns true after its
//! last frame. OpenNI2's recorder numbers a file's frames from 1 and starts its clock at 0, so a
//! recording's `seq` and `device_ns` are the camera's shifted by constants.

use super::backend::{self, Backend, BackendDevices, CameraConfig, DepthBackend, DepthConfig, TableError};
use super::{CaptureError, DeviceInfo, FrameSource};
use crate::core::frame::{DepthFrame, Stamp};
use crate::io::session::{BackendName, CameraMeta, CameraRole, FrameFormat};
use crate::runtime::capture::Clock;
use crate::vision::calibrate::field_of_view::{FieldOfViewIntrinsics, from_field_of_view};
use openni2 as ni;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// The backend name in errors and device lists.
const BACKEND: &str = "openni2";

/// What to open and in which mode.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OpenNiConfig {
    /// The device URI: from `mousepose devices`, `"Dummy"`, or a `.oni` file path. Takes
    /// precedence over `serial`; when both are set, the device's serial must match.
    pub uri: Option<String>,
    /// The serial number of the camera to open, when no URI is given.
    pub serial: Option<String>,
    /// The depth mode: width and height in pixels and frames per second. 0 accepts any value
    /// (the driver's current mode is preferred among those that match).
    pub width: u32,
    pub height: u32,
    pub fps: u32,
}

impl OpenNiConfig {
    /// What the config names, for error messages.
    fn id(&self) -> String {
        match (&self.uri, &self.serial) {
            (Some(uri), _) => uri.clone(),
            (None, Some(serial)) => format!("serial {serial}"),
            (None, None) => "(first device)".to_owned(),
        }
    }

    fn matches(&self, mode: &ni::VideoMode) -> bool {
        mode.pixel_format == ni::PixelFormat::Depth1Mm
            && (self.width == 0 || mode.width == self.width)
            && (self.height == 0 || mode.height == self.height)
            && (self.fps == 0 || mode.fps == self.fps)
    }
}

/// What `start` opened.
#[derive(Debug)]
struct Running {
    /// Kept open for the stream's sake and for metadata.
    device: ni::Device,
    stream: ni::DepthStream,
    clock: Clock,
}

/// A depth source on OpenNI2. Plain data until [`FrameSource::start`].
#[derive(Debug)]
pub struct OpenNiDepth {
    config: OpenNiConfig,
    meta: CameraMeta,
    running: Option<Running>,
    /// A buffer left over from a read that timed out, reused by the next read.
    spare: Vec<u16>,
    finished: bool,
    bad_frames: u64,
    wrong_size: u64,
}

impl OpenNiDepth {
    /// A source for `config`; nothing is opened until `start`.
    pub fn new(config: OpenNiConfig) -> Self {
        let meta = CameraMeta {
            role: CameraRole::Depth,
            backend: BackendName::new(BACKEND),
            model: String::new(),
            serial: config.serial.clone().unwrap_or_default(),
            firmware: String::new(),
            width: config.width,
            height: config.height,
            pixel_format: FrameFormat::Depth16,
            fps: f64::from(config.fps),
        };
        Self {
            config,
            meta,
            running: None,
            spare: Vec::new(),
            finished: false,
            bad_frames: 0,
            wrong_size: 0,
        }
    }

    /// The number of frames of a recording being played back; `None` for a camera or before
    /// `start`.
    pub fn recording_frames(&self) -> Option<u64> {
        let running = self.running.as_ref()?;
        if !running.device.is_file() {
            return None;
        }
        running.stream.number_of_frames().ok()
    }

    /// The config the source was made with.
    pub fn config(&self) -> &OpenNiConfig {
        &self.config
    }

    fn driver_error(&self, what: impl Into<String>, error: ni::Error) -> CaptureError {
        driver_error(self.config.id(), what, error)
    }

    /// Opens the configured device.
    fn open(&self) -> Result<ni::Device, CaptureError> {
        let id = self.config.id();
        if let Some(uri) = &self.config.uri {
            let device = open_uri(uri)?;
            if let Some(wanted) = &self.config.serial {
                let serial = device.serial().unwrap_or_default();
                if &serial != wanted {
                    return Err(CaptureError::Refused {
                        backend: BACKEND,
                        id,
                        what: format!("serial {wanted}"),
                        reason: format!("the device's serial is {serial:?}"),
                    });
                }
            }
            return Ok(device);
        }
        let openni = ni::OpenNI::init().map_err(|e| driver_error(id.clone(), "initialising OpenNI2", e))?;
        let devices = openni
            .devices()
            .map_err(|e| driver_error(id.clone(), "listing devices", e))?;
        match &self.config.serial {
            None => match devices.first() {
                Some(info) => open_uri(&info.uri),
                None => Err(CaptureError::NotFound { backend: BACKEND, id }),
            },
            Some(wanted) => {
                for info in &devices {
                    // A device that cannot be opened (in use elsewhere) is not the one.
                    let Ok(device) = ni::Device::open(&info.uri) else {
                        continue;
                    };
                    if device.serial().is_ok_and(|s| &s == wanted) {
                        return Ok(device);
                    }
                }
                Err(CaptureError::NotFound { backend: BACKEND, id })
            }
        }
    }

    /// Picks the configured mode among the stream's, preferring the current one.
    fn pick_mode(&self, stream: &ni::DepthStream) -> Result<ni::VideoMode, CaptureError> {
        let modes = stream.sensor_info().map(|s| s.modes).unwrap_or_default();
        let current = stream.video_mode().ok();
        if let Some(mode) = current.filter(|m| self.config.matches(m)) {
            return Ok(mode);
        }
        if let Some(mode) = modes.iter().find(|m| self.config.matches(m)) {
            return Ok(*mode);
        }
        let mut available: Vec<String> = modes.iter().map(ToString::to_string).collect();
        if available.is_empty() {
            available.extend(current.map(|m| m.to_string()));
        }
        let any = |v: u32| if v == 0 { "any".to_owned() } else { v.to_string() };
        Err(CaptureError::Refused {
            backend: BACKEND,
            id: self.config.id(),
            what: format!(
                "depth mode {}x{}@{} depth_1_mm",
                any(self.config.width),
                any(self.config.height),
                any(self.config.fps)
            ),
            reason: if available.is_empty() {
                "the sensor lists no mode".to_owned()
            } else {
                format!("available modes: {}", available.join(", "))
            },
        })
    }

    /// Fills the metadata from the open device and the chosen mode.
    fn describe(&mut self, device: &ni::Device, mode: &ni::VideoMode) {
        let info = device.info().ok();
        let model = info
            .as_ref()
            .map(|i| {
                if i.name.is_empty() {
                    i.vendor.clone()
                } else {
                    i.name.clone()
                }
            })
            .unwrap_or_default();
        self.meta = CameraMeta {
            role: CameraRole::Depth,
            backend: BackendName::new(BACKEND),
            model,
            serial: device.serial().unwrap_or_default(),
            firmware: device.firmware().unwrap_or_default(),
            width: mode.width,
            height: mode.height,
            pixel_format: FrameFormat::Depth16,
            fps: f64::from(mode.fps),
        };
    }
}

impl FrameSource for OpenNiDepth {
    type Frame = DepthFrame;

    /// Model (the device's name, or its vendor when the driver gives no name, as Dummy does),
    /// serial and firmware when the driver reports them (empty otherwise), and the mode. Before
    /// `start`, the configured mode and serial.
    fn meta(&self) -> CameraMeta {
        self.meta.clone()
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        if self.running.is_some() {
            return Ok(());
        }
        let device = self.open()?;
        let mut stream = device
            .create_depth_stream()
            .map_err(|e| self.driver_error("creating the depth stream", e))?;
        let mode = self.pick_mode(&stream)?;
        if stream.video_mode().ok() != Some(mode) {
            stream
                .set_video_mode(mode)
                .map_err(|e| self.driver_error(format!("setting depth mode {mode}"), e))?;
        }
        if device.is_file() {
            device
                .set_playback_speed(ni::PlaybackSpeed::Manual)
                .map_err(|e| self.driver_error("setting the playback speed", e))?;
            device
                .set_playback_repeat(false)
                .map_err(|e| self.driver_error("turning playback repeat off", e))?;
        }
        stream
            .start()
            .map_err(|e| self.driver_error("starting the depth stream", e))?;
        self.describe(&device, &mode);
        tracing::info!(
            message = "Depth camera started.",
            backend = BACKEND,
            uri = device.uri(),
            model = %self.meta.model,
            serial = %self.meta.serial,
            mode = %mode,
        );
        self.finished = false;
        self.bad_frames = 0;
        self.wrong_size = 0;
        self.running = Some(Running {
            device,
            stream,
            clock: clock.clone(),
        });
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<DepthFrame>, CaptureError> {
        if self.finished {
            return Ok(None);
        }
        let id = self.config.id();
        let Some(running) = self.running.as_mut() else {
            return Err(CaptureError::Driver {
                backend: BACKEND,
                id,
                what: "reading a frame before start".to_owned(),
                source: None,
            });
        };
        let mut raw = ni::DepthFrame {
            data: std::mem::take(&mut self.spare),
            ..ni::DepthFrame::default()
        };
        let outcome = match running.stream.read_frame(timeout, &mut raw) {
            Ok(outcome) => outcome,
            Err(ni::Error::BadFrame(reason)) => {
                self.spare = raw.data;
                self.bad_frames += 1;
                tracing::trace!(message = "Depth frame dropped.", backend = BACKEND, %reason);
                return Ok(None);
            }
            Err(error) => return Err(driver_error(id, "reading a depth frame", error)),
        };
        match outcome {
            ni::ReadOutcome::Timeout => {
                self.spare = raw.data;
                Ok(None)
            }
            ni::ReadOutcome::EndOfFile => {
                self.finished = true;
                Ok(None)
            }
            ni::ReadOutcome::Frame => {
                let host_ns = running.clock.now_ns();
                if raw.pixel_format != ni::PixelFormat::Depth1Mm {
                    self.spare = raw.data;
                    self.bad_frames += 1;
                    return Ok(None);
                }
                if raw.width != self.meta.width || raw.height != self.meta.height {
                    self.spare = raw.data;
                    self.wrong_size += 1;
                    return Ok(None);
                }
                Ok(Some(DepthFrame {
                    stamp: Stamp {
                        seq: raw.index,
                        device_ns: raw.timestamp_us.saturating_mul(1000),
                        host_ns,
                    },
                    width: raw.width,
                    height: raw.height,
                    data: raw.data,
                }))
            }
        }
    }

    fn finished(&self) -> bool {
        self.finished
    }

    /// `bad_frame`: not 16-bit millimetres or inconsistent geometry; `wrong_size`: not the
    /// mode's size (a driver that crops).
    fn losses(&self) -> Vec<(&'static str, u64)> {
        vec![("bad_frame", self.bad_frames), ("wrong_size", self.wrong_size)]
    }

    /// Stops the stream and closes the device (the stream is given a moment to settle first,
    /// see [`ni::STOP_SETTLE`]).
    fn stop(&mut self) -> Result<(), CaptureError> {
        if let Some(mut running) = self.running.take() {
            running.stream.stop();
            drop(running);
            tracing::info!(message = "Depth camera stopped.", backend = BACKEND, id = %self.config.id());
        }
        Ok(())
    }
}

/// Opens a URI, telling a missing camera or file from a driver failure.
fn open_uri(uri: &str) -> Result<ni::Device, CaptureError> {
    let is_file = Path::new(uri)
        .extension()
        .is_some_and(|ext| ext.eq_ignore_ascii_case("oni"));
    if is_file && !Path::new(uri).is_file() {
        return Err(CaptureError::NotFound {
            backend: BACKEND,
            id: uri.to_owned(),
        });
    }
    ni::Device::open(uri).map_err(|error| match error {
        _ if is_file => CaptureError::Recording {
            path: uri.into(),
            source: Box::new(error),
        },
        ni::Error::Call {
            status: ni::Status::NoDevice,
            ..
        } => {
            tracing::debug!(message = "No OpenNI2 device.", uri, %error);
            CaptureError::NotFound {
                backend: BACKEND,
                id: uri.to_owned(),
            }
        }
        error => driver_error(uri.to_owned(), "opening the device", error),
    })
}

fn driver_error(id: String, what: impl Into<String>, error: ni::Error) -> CaptureError {
    CaptureError::Driver {
        backend: BACKEND,
        id,
        what: what.into(),
        source: Some(Box::new(error)),
    }
}

/// The devices OpenNI2's drivers see, each opened briefly to read its serial number (empty when
/// it cannot be read, e.g. a device in use by another process). Files and the Dummy device are
/// not listed (Dummy appears once it has been opened in this process).
///
/// # Errors
/// OpenNI2 cannot be initialised or cannot list its devices.
pub fn list_devices() -> Result<Vec<DeviceInfo>, CaptureError> {
    let id = "(devices)".to_owned();
    let openni = ni::OpenNI::init().map_err(|e| driver_error(id.clone(), "initialising OpenNI2", e))?;
    let devices = openni.devices().map_err(|e| driver_error(id, "listing devices", e))?;
    Ok(devices
        .into_iter()
        .map(|info| {
            let serial = ni::Device::open(&info.uri)
                .and_then(|device| device.serial())
                .unwrap_or_default();
            DeviceInfo {
                backend: BACKEND,
                model: if info.name.is_empty() {
                    info.vendor.clone()
                } else {
                    info.name.clone()
                },
                serial,
                details: format!(
                    "vendor {}, usb {:04x}:{:04x}",
                    info.vendor, info.usb_vendor_id, info.usb_product_id
                ),
                id: info.uri,
            }
        })
        .collect())
}

/// Errors reading intrinsics from OpenNI2 ([`depth_intrinsics`]).
#[derive(Debug, thiserror::Error)]
pub enum OpenNiIntrinsicsError {
    #[error("cannot open OpenNI2 device {uri:?}")]
    Open {
        uri: String,
        #[source]
        source: ni::Error,
    },
    #[error("OpenNI2 device {uri:?} does not report its depth stream's field of view")]
    NoFieldOfView {
        uri: String,
        #[source]
        source: ni::Error,
    },
    #[error("OpenNI2 device {uri:?} reports an impossible field of view ({hfov_rad} x {vfov_rad} rad)")]
    BadFieldOfView { uri: String, hfov_rad: f32, vfov_rad: f32 },
}

/// The depth camera's intrinsics as OpenNI2 reports them (the `calibrate intrinsics --openni`
/// path): opens the device at `uri` and reads its depth stream's mode and fields of view, which
/// [`from_field_of_view`] turns into a pinhole camera.
///
/// # Errors
/// The device cannot be opened, has no depth stream, or does not report a plausible field of view.
pub fn depth_intrinsics(uri: &str) -> Result<FieldOfViewIntrinsics, OpenNiIntrinsicsError> {
    let open = |source| OpenNiIntrinsicsError::Open {
        uri: uri.to_owned(),
        source,
    };
    ni::OpenNI::init().map_err(open)?;
    let device = ni::Device::open(uri).map_err(open)?;
    let stream = device.create_depth_stream().map_err(open)?;
    let mode = stream.video_mode().map_err(open)?;
    let (h, v) = stream
        .field_of_view()
        .map_err(|source| OpenNiIntrinsicsError::NoFieldOfView {
            uri: uri.to_owned(),
            source,
        })?;
    let plausible = |a: f32| a.is_finite() && a > 0.01 && a < 3.0;
    if !plausible(h) || !plausible(v) {
        return Err(OpenNiIntrinsicsError::BadFieldOfView {
            uri: uri.to_owned(),
            hfov_rad: h,
            vfov_rad: v,
        });
    }
    Ok(FieldOfViewIntrinsics {
        intrinsics: from_field_of_view(mode.width, mode.height, f64::from(h), f64::from(v)),
        hfov_deg: f64::from(h).to_degrees(),
        vfov_deg: f64::from(v).to_degrees(),
    })
}

// ---- its table in the rig config ------------------------------------------------------------

/// The backend, registered in `capture::backend`.
pub const REGISTERED: DepthBackend = Backend {
    name: BACKEND,
    table: read_table,
    list: Some(listing),
};

/// `[depth] backend = "openni2"`, as written.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOpenNi {
    uri: Option<String>,
    serial: Option<String>,
    #[serde(default = "default_width")]
    width: u32,
    #[serde(default = "default_height")]
    height: u32,
    #[serde(default = "default_fps")]
    fps: f64,
}

fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}
fn default_fps() -> f64 {
    30.0
}

/// An OpenNI2 depth camera as the rig config names it: the driver's config, and the frame rate
/// as configured (the driver is asked for the nearest whole rate).
#[derive(Clone, Debug, PartialEq)]
pub struct OpenNiCamera {
    pub config: OpenNiConfig,
    pub fps: f64,
}

fn read_table(table: toml::Table) -> Result<Arc<dyn DepthConfig>, TableError> {
    let d: RawOpenNi = backend::deserialize(BACKEND, table)?;
    if d.uri.is_none() && d.serial.is_none() {
        return Err(TableError::new("", "needs `uri` or `serial` to say which camera"));
    }
    if let Some(uri) = &d.uri {
        check_uri(uri)?;
    }
    if !(1..=4096).contains(&d.width) || !(1..=4096).contains(&d.height) {
        return Err(TableError::new(
            "width/height",
            format!("must be from 1 to 4096, not {}x{}", d.width, d.height),
        ));
    }
    let fps = backend::frame_rate("fps", d.fps)?;
    Ok(Arc::new(OpenNiCamera {
        config: OpenNiConfig {
            uri: d.uri,
            serial: d.serial,
            width: d.width,
            height: d.height,
            fps: fps.round() as u32,
        },
        fps,
    }))
}

/// A URI OpenNI2 could open, told apart before opening (OpenNI2 says "no device" both for a
/// camera absent now and for a URI no driver can ever take): a recording (`.oni`, which must
/// be there: it cannot come later, as a camera can), Debian's test device (`Dummy`), a USB
/// camera as the PrimeSense and Orbbec drivers name it (`VID/PID@BUS/ADDRESS`, as
/// `mousepose devices` lists it), or another driver's `scheme://...`.
fn check_uri(uri: &str) -> Result<(), TableError> {
    let path = Path::new(uri);
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("oni")) {
        if !path.is_file() {
            return Err(TableError::new(
                "uri",
                format!("names the recording {uri:?}, which is not a file"),
            ));
        }
        return Ok(());
    }
    let hex = |s: &str| (1..=4).contains(&s.len()) && s.chars().all(|c| c.is_ascii_hexdigit());
    let number = |s: &str| (1..=3).contains(&s.len()) && s.chars().all(|c| c.is_ascii_digit());
    let usb = uri.split_once('@').is_some_and(|(ids, place)| {
        ids.split_once('/').is_some_and(|(v, p)| hex(v) && hex(p))
            && place.split_once('/').is_some_and(|(b, a)| number(b) && number(a))
    });
    let scheme = uri.split_once("://").is_some_and(|(scheme, _)| {
        !scheme.is_empty()
            && scheme
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '+' || c == '-')
    });
    if uri == "Dummy" || usb || scheme {
        return Ok(());
    }
    Err(TableError::new(
        "uri",
        format!(
            "{uri:?} is no OpenNI2 device URI: give a camera's VID/PID@BUS/ADDRESS as `mousepose devices` lists it, \"Dummy\", a driver's scheme://..., or a .oni recording (or `serial` instead)"
        ),
    ))
}

impl CameraConfig for OpenNiCamera {
    type Frame = DepthFrame;

    fn backend(&self) -> &'static str {
        BACKEND
    }

    /// The camera is opened by `start`.
    fn open(&self) -> Result<Box<dyn FrameSource<Frame = DepthFrame>>, CaptureError> {
        Ok(Box::new(OpenNiDepth::new(self.config.clone())))
    }

    fn frame_size(&self) -> Option<(u32, u32)> {
        Some((self.config.width, self.config.height))
    }
}

impl DepthConfig for OpenNiCamera {
    fn mode(&self) -> (u32, u32, f64) {
        (self.config.width, self.config.height, self.fps)
    }
}

fn listing() -> BackendDevices {
    let devices = list_devices();
    BackendDevices {
        backend: BACKEND,
        error: devices.as_ref().err().map(|e| super::error_chain(e)),
        devices: devices.unwrap_or_default(),
        scope: "USB depth cameras and the drivers' virtual devices".to_owned(),
    }
}
