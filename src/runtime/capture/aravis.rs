//! The colour camera read through Aravis: GenICam cameras on GigE Vision (or USB3 Vision).
//!
//! A GigE Vision camera is opened by its IPv4 address, by unicast only: the control channel
//! goes from the local address that routes to the camera, and nothing is broadcast. Aravis 0.8
//! cannot restrict its GigE Vision discovery to one network interface (its discovery
//! broadcasts on every interface of the host; a per-interface setting only came with 0.9), so
//! this module never runs it: [`list_devices`] probes the configured addresses one by one, and
//! a camera named by serial alone is looked up on USB3 Vision only (which enumerates the USB
//! bus, no network). A GigE Vision camera named by serial needs its address too; the serial is
//! then checked.
//!
//! The settings of [`AravisConfig`] are applied when the camera is opened, each checked
//! against what the camera allows first, so that a refused setting names the setting and the
//! camera's range. Frames come from a pool of `buffers` stream buffers, each copied out once
//! into a [`ColorFrame`] and pushed back. Buffers Aravis hands back damaged (missing packets,
//! timeout, wrong size) are counted by reason in [`FrameSource::losses`] and never returned.

use super::backend::{self, Backend, BackendDevices, CameraConfig, ColorBackend, TableError};
use super::beat::DepthBeat;
use super::{CaptureError, Clock, DeviceInfo, FrameSource};
use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::io::session::codec::FrameFormat;
use crate::io::session::meta::{BackendName, CameraMeta, CameraRole};
use aravis_ext::aravis;
use aravis_ext::aravis::prelude::*;
use aravis_ext::aravis::{BufferStatus, Camera, Stream};
use aravis_ext::{Interface, use_only_interfaces};
use std::net::Ipv4Addr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

const BACKEND: &str = "aravis";

/// How the camera starts each frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Trigger {
    /// The camera runs at its own frame rate.
    #[default]
    FreeRun,
    /// Each frame starts on a rising edge of this input line (`Line0`, `Line1`, ...).
    Line(String),
    /// Each frame starts on a software trigger sent so that the frame is delivered just before
    /// the depth camera's next frame (`trigger = "depth"`, [`super::beat`]). Before the first
    /// depth frames, and while the depth camera is away, the camera is triggered at its `fps`
    /// (30 frames/s when not set), so that it is never taken for away itself.
    Depth,
}

/// Which camera to open and how to set it up. Plain data: [`AravisColor::open`] does the I/O.
#[derive(Clone, Debug, PartialEq)]
pub struct AravisConfig {
    /// The camera's IPv4 address (GigE Vision). Opened by unicast, without discovery.
    pub address: Option<String>,
    /// The camera's serial number: checked against the camera at `address`, or, without an
    /// address, looked up among USB3 Vision cameras only (see the module header).
    pub serial: Option<String>,
    pub pixel_format: PixelFormat,
    /// `(x, y, width, height)` in pixels; the camera's current region when `None`.
    pub region: Option<(u32, u32, u32, u32)>,
    pub exposure_us: Option<f64>,
    pub gain_db: Option<f64>,
    pub fps: Option<f64>,
    pub trigger: Trigger,
    /// The number of stream buffers in the pool (at least 1).
    pub buffers: usize,
}

impl Default for AravisConfig {
    fn default() -> Self {
        Self {
            address: None,
            serial: None,
            pixel_format: PixelFormat::Mono8,
            region: None,
            exposure_us: None,
            gain_db: None,
            fps: None,
            trigger: Trigger::FreeRun,
            buffers: 8,
        }
    }
}

/// The colour camera, read through Aravis.
pub struct AravisColor {
    id: String,
    buffers: usize,
    camera: Option<Camera>,
    stream: Option<Stream>,
    clock: Clock,
    meta: CameraMeta,
    format: PixelFormat,
    payload: usize,
    frame_ids: FrameIdExtender,
    losses: Vec<(&'static str, u64)>,
    connected: Arc<AtomicBool>,
    /// For a camera triggered in step with the depth camera: the depth camera's arrivals, the
    /// rate to trigger at without them (ns between frames), and the triggering thread once
    /// started.
    in_step: Option<(Arc<DepthBeat>, u64)>,
    pacer: Option<Pacer>,
}

impl std::fmt::Debug for AravisColor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AravisColor")
            .field("id", &self.id)
            .field("meta", &self.meta)
            .field("streaming", &self.stream.is_some())
            .finish_non_exhaustive()
    }
}

/// A [`CaptureError::Driver`] builder for `glib` errors.
fn driver(id: &str, what: impl Into<String>) -> impl FnOnce(aravis::glib::Error) -> CaptureError {
    let id = id.to_owned();
    let what = what.into();
    move |error| CaptureError::Driver {
        backend: BACKEND,
        id,
        what,
        source: Some(Box::new(error)),
    }
}

fn refused(id: &str, what: impl Into<String>, reason: impl Into<String>) -> CaptureError {
    CaptureError::Refused {
        backend: BACKEND,
        id: id.to_owned(),
        what: what.into(),
        reason: reason.into(),
    }
}

fn parse_address(id: &str, address: &str) -> Result<Ipv4Addr, CaptureError> {
    address.trim().parse().map_err(|_| {
        refused(
            id,
            format!("address {address:?}"),
            "it is not an IPv4 address (GigE Vision cameras are opened by address only)",
        )
    })
}

/// Opens the GigE Vision camera at `address` by unicast, with every Aravis discovery
/// interface disabled.
fn open_by_address(id: &str, address: &str) -> Result<Camera, CaptureError> {
    let ip = parse_address(id, address)?;
    use_only_interfaces(&[]);
    aravis_ext::open_gv_camera(ip).map_err(|error| match error {
        aravis_ext::OpenError::NoRoute { .. } => CaptureError::NotFound {
            backend: BACKEND,
            id: id.to_owned(),
        },
        aravis_ext::OpenError::Held { .. } => CaptureError::Held {
            backend: BACKEND,
            id: id.to_owned(),
            reason: "another application controls it (or one that ended less than the camera's heartbeat timeout ago)"
                .into(),
        },
        aravis_ext::OpenError::Device { source, .. } => {
            driver(id, format!("no GigE Vision camera answers at {ip}"))(source)
        }
    })
}

/// The GenICam pixel format names for one of ours (PFNC, then the GigE Vision 1.x name).
fn genicam_names(format: PixelFormat) -> &'static [&'static str] {
    match format {
        PixelFormat::Mono8 => &["Mono8"],
        PixelFormat::Rgb8 => &["RGB8", "RGB8Packed"],
        PixelFormat::BayerRg8 => &["BayerRG8"],
        PixelFormat::BayerGr8 => &["BayerGR8"],
        PixelFormat::BayerGb8 => &["BayerGB8"],
        PixelFormat::BayerBg8 => &["BayerBG8"],
    }
}

/// Our pixel format for an Aravis (PFNC) pixel format code.
pub fn pixel_format_from_aravis(format: aravis::PixelFormat) -> Option<PixelFormat> {
    Some(match format {
        aravis::PixelFormat::MONO_8 => PixelFormat::Mono8,
        aravis::PixelFormat::RGB_8_PACKED => PixelFormat::Rgb8,
        aravis::PixelFormat::BAYER_RG_8 => PixelFormat::BayerRg8,
        aravis::PixelFormat::BAYER_GR_8 => PixelFormat::BayerGr8,
        aravis::PixelFormat::BAYER_GB_8 => PixelFormat::BayerGb8,
        aravis::PixelFormat::BAYER_BG_8 => PixelFormat::BayerBg8,
        _ => return None,
    })
}

/// The name a loss reason is counted under, for a buffer status other than success.
fn loss_reason(status: BufferStatus) -> &'static str {
    match status {
        BufferStatus::MissingPackets => "incomplete",
        BufferStatus::Timeout => "timeout",
        BufferStatus::SizeMismatch => "size_mismatch",
        BufferStatus::WrongPacketId => "wrong_packet_id",
        BufferStatus::Aborted => "aborted",
        BufferStatus::PayloadNotSupported => "payload_not_supported",
        _ => "unknown_status",
    }
}

impl AravisColor {
    /// Opens the camera and applies the settings of `config`.
    ///
    /// # Errors
    /// No camera at the address or with the serial ([`CaptureError::NotFound`] or
    /// [`CaptureError::Driver`] with Aravis's cause), a setting the camera does not allow
    /// ([`CaptureError::Refused`], naming the setting and what the camera allows), or a
    /// failure reading or writing a feature.
    pub fn open(config: &AravisConfig) -> Result<Self, CaptureError> {
        let id = match (&config.address, &config.serial) {
            (Some(address), _) => address.clone(),
            (None, Some(serial)) => serial.clone(),
            (None, None) => String::new(),
        };
        if config.buffers == 0 {
            return Err(refused(&id, "buffers = 0", "the stream needs at least 1 buffer"));
        }
        let camera = match (&config.address, &config.serial) {
            (Some(address), serial) => {
                let camera = open_by_address(&id, address)?;
                if let Some(serial) = serial {
                    let found = camera
                        .device_serial_number()
                        .map_err(driver(&id, "reading the serial number"))?;
                    if found.as_str() != serial.as_str() {
                        return Err(CaptureError::NotFound {
                            backend: BACKEND,
                            id: format!("{serial} at {address} (the camera there is {found})"),
                        });
                    }
                }
                camera
            }
            (None, Some(serial)) => {
                use_only_interfaces(&[Interface::Usb3Vision]);
                Camera::new(Some(serial)).map_err(driver(
                    &id,
                    "no USB3 Vision camera with this serial (a GigE Vision camera needs its address)",
                ))?
            }
            (None, None) => {
                return Err(refused(
                    "",
                    "the camera selection",
                    "the config names neither an address nor a serial",
                ));
            }
        };
        let format = apply_settings(&camera, &id, config)?;
        let meta = read_meta(&camera, &id, format)?;
        let payload = camera.payload().map_err(driver(&id, "reading the payload size"))? as usize;
        tracing::info!(
            message = "Aravis camera opened.",
            camera = %id,
            model = %meta.model,
            serial = %meta.serial,
            width = meta.width,
            height = meta.height,
            pixel_format = %format,
            fps = meta.fps,
        );
        Ok(Self {
            id,
            buffers: config.buffers,
            camera: Some(camera),
            stream: None,
            clock: Clock::Monotonic,
            meta,
            format,
            payload,
            frame_ids: FrameIdExtender::default(),
            losses: Vec::new(),
            connected: Arc::new(AtomicBool::new(true)),
            in_step: (config.trigger == Trigger::Depth).then(|| {
                let fps = config.fps.unwrap_or(DEFAULT_STEP_FPS);
                (Arc::new(DepthBeat::default()), (1e9 / fps).round() as u64)
            }),
            pacer: None,
        })
    }

    /// Keeps a camera triggered in step with the depth camera (`trigger = "depth"`) in step
    /// with `beat`'s arrivals; any other camera is left as it is. Call before `start`.
    pub fn in_step_with(&mut self, beat: &Arc<DepthBeat>) {
        if let Some((own, _)) = &mut self.in_step {
            *own = Arc::clone(beat);
        }
    }

    /// Stops the triggering thread, if there is one.
    fn stop_pacer(&mut self) {
        if let Some(pacer) = self.pacer.take() {
            let failed = pacer.stop();
            if failed > 0 {
                self.losses.push(("trigger_failed", failed));
            }
        }
    }

    fn count_loss(&mut self, reason: &'static str) {
        match self.losses.iter_mut().find(|(r, _)| *r == reason) {
            Some(entry) => entry.1 += 1,
            None => self.losses.push((reason, 1)),
        }
        if first_loss(&self.id, reason) {
            tracing::warn!(
                message = "Aravis buffer dropped (logged once per reason, counted in losses).",
                camera = %self.id,
                reason,
            );
        } else {
            tracing::trace!(message = "Aravis buffer dropped.", camera = %self.id, reason);
        }
    }

    /// The host time a buffer arrived: the clock now, less the buffer's age on the system
    /// clock Aravis stamped it with at its first packet (on a live clock only; a replay clock
    /// is used as it stands).
    fn host_ns(&self, system_timestamp_ns: u64) -> u64 {
        let now_ns = self.clock.now_ns();
        if !matches!(self.clock, Clock::Monotonic) || system_timestamp_ns == 0 {
            return now_ns;
        }
        let realtime_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        let age_ns = realtime_ns.saturating_sub(system_timestamp_ns).min(10_000_000_000);
        now_ns.saturating_sub(age_ns)
    }

    /// Turns a good buffer into a frame, or names why it cannot be one.
    fn frame_from(&mut self, buffer: &aravis::Buffer) -> Result<ColorFrame, &'static str> {
        if buffer.payload_type() != aravis::BufferPayloadType::Image {
            return Err("payload_not_supported");
        }
        let format = pixel_format_from_aravis(buffer.image_pixel_format()).ok_or("format_mismatch")?;
        if format != self.format {
            return Err("format_mismatch");
        }
        let width = u32::try_from(buffer.image_width()).map_err(|_| "size_mismatch")?;
        let height = u32::try_from(buffer.image_height()).map_err(|_| "size_mismatch")?;
        let (x_padding, _) = buffer.image_padding();
        let row_len = width as usize * format.bytes_per_pixel();
        let expected = ColorFrame::expected_len(width, height, format);
        let mut data = buffer.image_data();
        if x_padding > 0 {
            let stride = row_len + x_padding as usize;
            data = data
                .chunks(stride)
                .take(height as usize)
                .flat_map(|row| row.iter().take(row_len))
                .copied()
                .collect();
        }
        if data.len() < expected {
            return Err("size_mismatch");
        }
        data.truncate(expected);
        let seq = self.frame_ids.extend(buffer.frame_id()).ok_or("out_of_order")?;
        Ok(ColorFrame {
            stamp: Stamp {
                seq,
                device_ns: buffer.timestamp(),
                host_ns: self.host_ns(buffer.system_timestamp()),
            },
            width,
            height,
            format,
            data,
        })
    }
}

/// Checks each setting against the camera's range, then applies it. Returns the pixel format.
fn apply_settings(camera: &Camera, id: &str, config: &AravisConfig) -> Result<PixelFormat, CaptureError> {
    // Best effort: a camera without the feature is continuous anyway.
    if let Err(error) = camera.set_acquisition_mode(aravis::AcquisitionMode::Continuous) {
        tracing::debug!(message = "AcquisitionMode not set.", camera = %id, %error);
    }
    apply_pixel_format(camera, id, config.pixel_format)?;
    if let Some(region) = config.region {
        apply_region(camera, id, region)?;
    }
    if let Some(exposure_us) = config.exposure_us {
        apply_exposure(camera, id, exposure_us)?;
    }
    if let Some(gain_db) = config.gain_db {
        apply_gain(camera, id, gain_db)?;
    }
    if let Some(fps) = config.fps {
        apply_frame_rate(camera, id, fps)?;
    }
    // Last: Aravis switches the trigger off when it sets the frame rate.
    apply_trigger(camera, id, &config.trigger)?;
    Ok(config.pixel_format)
}

/// The trigger: free run, or the named line when the camera offers it.
fn apply_trigger(camera: &Camera, id: &str, trigger: &Trigger) -> Result<(), CaptureError> {
    match trigger {
        Trigger::FreeRun => {
            // A camera without trigger control always runs free.
            if camera.is_feature_available("TriggerMode").unwrap_or(false) {
                camera.clear_triggers().map_err(driver(id, "switching triggers off"))?;
            }
        }
        Trigger::Line(line) => {
            let sources = camera.dup_available_trigger_sources().unwrap_or_default();
            if !sources.iter().any(|s| s.as_str() == line) {
                let offered: Vec<&str> = sources.iter().map(|s| s.as_str()).collect();
                return Err(refused(
                    id,
                    format!("trigger line {line:?}"),
                    format!("the camera's trigger sources are [{}]", offered.join(", ")),
                ));
            }
            camera
                .set_trigger(line)
                .map_err(driver(id, format!("setting trigger source {line}")))?;
        }
        Trigger::Depth => {
            let sources = camera.dup_available_trigger_sources().unwrap_or_default();
            if !sources.iter().any(|s| s.as_str() == SOFTWARE) {
                let offered: Vec<&str> = sources.iter().map(|s| s.as_str()).collect();
                return Err(refused(
                    id,
                    "trigger \"depth\"",
                    format!(
                        "it needs the camera's software trigger, and its trigger sources are [{}]",
                        offered.join(", ")
                    ),
                ));
            }
            camera
                .set_trigger(SOFTWARE)
                .map_err(driver(id, "setting trigger source Software"))?;
        }
    }
    Ok(())
}

/// GenICam's name for the trigger a host sends (`TriggerSoftware`).
const SOFTWARE: &str = "Software";

/// The frame rate a camera triggered in step with the depth camera keeps without depth frames,
/// when its table sets none.
const DEFAULT_STEP_FPS: f64 = 30.0;

/// How long before the depth frame's expected arrival a triggered frame should be delivered:
/// room for the depth camera's own jitter.
const STEP_MARGIN_NS: u64 = 1_000_000;

/// After this many periods without a depth frame the depth camera is taken for away, and the
/// colour camera is triggered at its own rate.
const STEP_SILENT_PERIODS: u64 = 4;

/// The thread that triggers a camera in step with the depth camera: for each depth frame due,
/// one trigger, sent the camera's trigger-to-delivery time (exposure, read-out, transfer, the
/// host's scheduling: [`STEP_DELAYS`]) plus [`STEP_MARGIN_NS`] before it.
struct Pacer {
    stop: Arc<AtomicBool>,
    shared: Arc<PaceShared>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// The last trigger-to-delivery times, ns (at most [`STEP_DELAYS`]).
    delays: std::collections::VecDeque<u64>,
}

/// Trigger-to-delivery times the lead is taken from: the 9th longest of the last 31 (their
/// 75th percentile), so that one late delivery (the host busy) does not move it.
const STEP_DELAYS: usize = 31;

/// What the triggering thread and the capture thread share.
#[derive(Debug, Default)]
struct PaceShared {
    /// Host time the last trigger was sent, ns (0: none yet).
    fired_ns: AtomicU64,
    /// The camera's trigger-to-delivery time, ns, as followed.
    delay_ns: AtomicU64,
    /// Triggers the camera refused (each a frame not made).
    failed: AtomicU64,
}

impl Pacer {
    fn start(camera: Camera, beat: Arc<DepthBeat>, own_period_ns: u64, clock: Clock, id: &str) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let shared = Arc::new(PaceShared {
            delay_ns: AtomicU64::new(STEP_MARGIN_NS),
            ..PaceShared::default()
        });
        let (thread_stop, thread_shared, id) = (Arc::clone(&stop), Arc::clone(&shared), id.to_owned());
        let thread = std::thread::Builder::new()
            .name("color-trigger".into())
            .spawn(move || pace(&camera, &beat, own_period_ns, &clock, &thread_shared, &thread_stop, &id))
            .map_err(|error| tracing::error!(message = "The colour trigger thread did not start.", %error))
            .ok();
        Self {
            stop,
            shared,
            thread,
            delays: std::collections::VecDeque::with_capacity(STEP_DELAYS),
        }
    }

    /// Notes a frame delivered at `now_ns`: the time since the last trigger is the camera's
    /// trigger-to-delivery time (when under 100 ms).
    fn delivered(&mut self, now_ns: u64) {
        let fired = self.shared.fired_ns.load(Ordering::Acquire);
        let delay = now_ns.saturating_sub(fired);
        if fired == 0 || delay > 100_000_000 {
            return;
        }
        if self.delays.len() == STEP_DELAYS {
            self.delays.pop_front();
        }
        self.delays.push_back(delay);
        let mut sorted = [0u64; STEP_DELAYS];
        let sorted = &mut sorted[..self.delays.len()];
        for (slot, &delay) in sorted.iter_mut().zip(&self.delays) {
            *slot = delay;
        }
        let at = (sorted.len() * 3 / 4).min(sorted.len() - 1);
        let (_, &mut lead, _) = sorted.select_nth_unstable(at);
        self.shared.delay_ns.store(lead, Ordering::Release);
    }

    fn failed(&self) -> u64 {
        self.shared.failed.load(Ordering::Acquire)
    }

    /// Stops the thread; returns the triggers that failed.
    fn stop(mut self) -> u64 {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        self.failed()
    }
}

/// The triggering loop of [`Pacer`].
fn pace(
    camera: &Camera,
    beat: &DepthBeat,
    own_period_ns: u64,
    clock: &Clock,
    shared: &PaceShared,
    stop: &AtomicBool,
    id: &str,
) {
    let (mut served, mut last_fire) = (0u64, 0u64);
    while !stop.load(Ordering::Acquire) {
        let now = clock.now_ns();
        let period = beat.period_ns().unwrap_or(own_period_ns);
        let lead = (shared.delay_ns.load(Ordering::Acquire) + STEP_MARGIN_NS).min(period / 2);
        let fire_at = match beat.next_after(now + lead, STEP_SILENT_PERIODS) {
            Some(mut due) => {
                // One trigger per depth frame: never the one served already.
                while due < served + period / 2 {
                    due += period;
                }
                served = due;
                due - lead
            }
            None => {
                served = 0;
                (last_fire + own_period_ns).max(now)
            }
        };
        // Slept in slices, so that a stop is seen within 50 ms.
        loop {
            let left = fire_at.saturating_sub(clock.now_ns());
            if left == 0 || stop.load(Ordering::Acquire) {
                break;
            }
            std::thread::sleep(Duration::from_nanos(left.min(50_000_000)));
        }
        if stop.load(Ordering::Acquire) {
            break;
        }
        last_fire = fire_at;
        shared.fired_ns.store(clock.now_ns(), Ordering::Release);
        if let Err(error) = camera.software_trigger() {
            if shared.failed.fetch_add(1, Ordering::AcqRel) == 0 {
                tracing::warn!(
                    message = "Colour camera trigger refused (logged once, counted in losses as trigger_failed).",
                    camera = %id,
                    %error,
                );
            }
        }
    }
}

/// The pixel format, by the first of its GenICam names the camera offers, checked once set.
fn apply_pixel_format(camera: &Camera, id: &str, wanted: PixelFormat) -> Result<(), CaptureError> {
    let available = camera
        .dup_available_pixel_formats_as_strings()
        .map_err(driver(id, "reading the pixel formats"))?;
    let name = genicam_names(wanted)
        .iter()
        .find(|name| available.iter().any(|a| a.as_str() == **name))
        .ok_or_else(|| {
            let offered: Vec<&str> = available.iter().map(|s| s.as_str()).collect();
            refused(
                id,
                format!("pixel format {wanted}"),
                format!("the camera offers [{}]", offered.join(", ")),
            )
        })?;
    camera
        .set_pixel_format_from_string(name)
        .map_err(driver(id, format!("setting pixel format {name}")))?;
    let set = camera.pixel_format().map_err(driver(id, "reading the pixel format"))?;
    if pixel_format_from_aravis(set) != Some(wanted) {
        return Err(refused(
            id,
            format!("pixel format {wanted}"),
            format!("the camera kept format 0x{:08x}", set.raw()),
        ));
    }
    Ok(())
}

/// The region `(x, y, width, height)`, within the camera's ranges, checked once set.
fn apply_region(camera: &Camera, id: &str, region: (u32, u32, u32, u32)) -> Result<(), CaptureError> {
    let (x, y, width, height) = region;
    let (w_min, w_max) = camera.width_bounds().map_err(driver(id, "reading the width range"))?;
    let (h_min, h_max) = camera.height_bounds().map_err(driver(id, "reading the height range"))?;
    let (sensor_w, sensor_h) = camera.sensor_size().unwrap_or((w_max, h_max));
    let allowed = format!(
        "the camera allows width {w_min} to {w_max}, height {h_min} to {h_max}, within a {sensor_w}x{sensor_h} sensor"
    );
    let what = format!("region x {x} y {y} width {width} height {height}");
    let fits = |offset: u32, len: u32, min: i32, max: i32, sensor: i32| {
        i64::from(len) >= i64::from(min)
            && i64::from(len) <= i64::from(max)
            && i64::from(offset) + i64::from(len) <= i64::from(sensor.max(max))
    };
    if !fits(x, width, w_min, w_max, sensor_w) || !fits(y, height, h_min, h_max, sensor_h) {
        return Err(refused(id, what, allowed));
    }
    let as_i32 = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
    camera
        .set_region(as_i32(x), as_i32(y), as_i32(width), as_i32(height))
        .map_err(driver(id, format!("setting {what}")))?;
    let got = camera.region().map_err(driver(id, "reading the region"))?;
    if got != (as_i32(x), as_i32(y), as_i32(width), as_i32(height)) {
        let (gx, gy, gw, gh) = got;
        return Err(refused(
            id,
            what,
            format!("the camera set x {gx} y {gy} width {gw} height {gh} instead ({allowed}, in its increments)"),
        ));
    }
    Ok(())
}

/// The exposure time (auto exposure off), within the camera's range.
fn apply_exposure(camera: &Camera, id: &str, exposure_us: f64) -> Result<(), CaptureError> {
    let what = format!("exposure {exposure_us} us");
    if !camera.is_exposure_time_available().unwrap_or(false) {
        return Err(refused(id, what, "the camera has no exposure time control"));
    }
    let (min, max) = camera
        .exposure_time_bounds()
        .map_err(driver(id, "reading the exposure range"))?;
    if !(min..=max).contains(&exposure_us) {
        return Err(refused(id, what, format!("the camera allows {min} to {max} us")));
    }
    if camera.is_exposure_auto_available().unwrap_or(false) {
        camera
            .set_exposure_time_auto(aravis::Auto::Off)
            .map_err(driver(id, "switching auto exposure off"))?;
    }
    camera
        .set_exposure_time(exposure_us)
        .map_err(driver(id, format!("setting {what}")))?;
    Ok(())
}

/// The gain (auto gain off), within the camera's range.
fn apply_gain(camera: &Camera, id: &str, gain_db: f64) -> Result<(), CaptureError> {
    let what = format!("gain {gain_db} dB");
    if !camera.is_gain_available().unwrap_or(false) {
        return Err(refused(id, what, "the camera has no gain control"));
    }
    let (min, max) = camera.gain_bounds().map_err(driver(id, "reading the gain range"))?;
    if !(min..=max).contains(&gain_db) {
        return Err(refused(id, what, format!("the camera allows {min} to {max} dB")));
    }
    if camera.is_gain_auto_available().unwrap_or(false) {
        camera
            .set_gain_auto(aravis::Auto::Off)
            .map_err(driver(id, "switching auto gain off"))?;
    }
    camera
        .set_gain(gain_db)
        .map_err(driver(id, format!("setting {what}")))?;
    Ok(())
}

/// The frame rate, within the camera's range.
fn apply_frame_rate(camera: &Camera, id: &str, fps: f64) -> Result<(), CaptureError> {
    let what = format!("frame rate {fps} fps");
    if !camera.is_frame_rate_available().unwrap_or(false) {
        return Err(refused(id, what, "the camera has no frame rate control"));
    }
    let (min, max) = camera
        .frame_rate_bounds()
        .map_err(driver(id, "reading the frame rate range"))?;
    if !(min..=max).contains(&fps) {
        return Err(refused(id, what, format!("the camera allows {min} to {max} fps")));
    }
    camera
        .set_frame_rate(fps)
        .map_err(driver(id, format!("setting {what}")))?;
    Ok(())
}

fn read_meta(camera: &Camera, id: &str, format: PixelFormat) -> Result<CameraMeta, CaptureError> {
    let model = camera.model_name().map_err(driver(id, "reading the model name"))?;
    let serial = camera
        .device_serial_number()
        .map_err(driver(id, "reading the serial number"))?;
    let firmware = ["DeviceFirmwareVersion", "DeviceVersion"]
        .iter()
        .find(|feature| camera.is_feature_available(feature).unwrap_or(false))
        .and_then(|feature| camera.string(feature).ok())
        .map(|s| s.to_string())
        .unwrap_or_default();
    let (_, _, width, height) = camera.region().map_err(driver(id, "reading the region"))?;
    let fps = if camera.is_frame_rate_available().unwrap_or(false) {
        camera.frame_rate().map_err(driver(id, "reading the frame rate"))?
    } else {
        0.0
    };
    Ok(CameraMeta {
        role: CameraRole::Color,
        backend: BackendName::new(BACKEND),
        model: model.to_string(),
        serial: serial.to_string(),
        firmware,
        width: u32::try_from(width).unwrap_or(0),
        height: u32::try_from(height).unwrap_or(0),
        pixel_format: FrameFormat::Color(format),
        fps,
    })
}

impl FrameSource for AravisColor {
    type Frame = ColorFrame;

    fn meta(&self) -> CameraMeta {
        self.meta.clone()
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        let id = self.id.clone();
        let Some(camera) = &self.camera else {
            return Err(CaptureError::Disconnected {
                backend: BACKEND,
                id,
                reason: "the camera was stopped and released".into(),
            });
        };
        self.clock = clock.clone();
        if let Some(device) = camera.device() {
            let connected = Arc::clone(&self.connected);
            device.connect_control_lost(move |_| connected.store(false, Ordering::Release));
        }
        let stream = camera.create_stream().map_err(driver(&id, "creating the stream"))?;
        for _ in 0..self.buffers {
            stream.push_buffer(aravis::Buffer::new_allocate(self.payload));
        }
        camera
            .start_acquisition()
            .map_err(driver(&id, "starting acquisition"))?;
        if let Some((beat, own_period_ns)) = &self.in_step {
            self.pacer = Some(Pacer::start(
                camera.clone(),
                Arc::clone(beat),
                *own_period_ns,
                clock.clone(),
                &id,
            ));
        }
        self.stream = Some(stream);
        self.losses.clear();
        self.frame_ids = FrameIdExtender::default();
        tracing::info!(message = "Aravis camera streaming.", camera = %id, buffers = self.buffers);
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<ColorFrame>, CaptureError> {
        let deadline = Instant::now() + timeout;
        loop {
            if !self.connected.load(Ordering::Acquire) {
                return Err(CaptureError::Disconnected {
                    backend: BACKEND,
                    id: self.id.clone(),
                    reason: "the camera stopped answering (control channel lost)".into(),
                });
            }
            let Some(stream) = self.stream.clone() else {
                return Err(CaptureError::Disconnected {
                    backend: BACKEND,
                    id: self.id.clone(),
                    reason: "the camera is not streaming (start was not called)".into(),
                });
            };
            let left = deadline.saturating_duration_since(Instant::now());
            let left_us = u64::try_from(left.as_micros()).unwrap_or(u64::MAX);
            let Some(buffer) = stream.timeout_pop_buffer(left_us) else {
                return Ok(None);
            };
            let frame = match buffer.status() {
                BufferStatus::Success => self.frame_from(&buffer),
                status => {
                    // Keep the frame counter's wraps even across damaged buffers.
                    self.frame_ids.observe(buffer.frame_id());
                    Err(loss_reason(status))
                }
            };
            stream.push_buffer(buffer);
            if let Some(pacer) = &mut self.pacer {
                pacer.delivered(self.clock.now_ns());
            }
            match frame {
                Ok(frame) => return Ok(Some(frame)),
                Err(reason) => self.count_loss(reason),
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        let mut losses = self.losses.clone();
        if let Some(failed) = self.pacer.as_ref().map(Pacer::failed).filter(|&n| n > 0) {
            losses.push(("trigger_failed", failed));
        }
        losses
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        self.stop_pacer();
        let result = match &self.camera {
            Some(camera) if self.stream.is_some() => camera
                .stop_acquisition()
                .map_err(driver(&self.id, "stopping acquisition")),
            _ => Ok(()),
        };
        // Dropping the stream stops its thread; dropping the camera releases control.
        self.stream = None;
        self.camera = None;
        tracing::info!(message = "Aravis camera stopped.", camera = %self.id);
        result
    }
}

impl Drop for AravisColor {
    fn drop(&mut self) {
        self.stop_pacer();
        let (Some(camera), Some(_)) = (&self.camera, &self.stream) else {
            return;
        };
        if let Err(error) = camera.stop_acquisition() {
            tracing::warn!(message = "Aravis acquisition not stopped on drop.", camera = %self.id, %error);
        }
    }
}

/// Extends GigE Vision's 16-bit frame ids (1 to 65535, then 1 again: 0 is never used) to a
/// monotonic `u64`. Ids above 65535 (GigE Vision 2 extended ids) are used as they are.
#[derive(Clone, Copy, Debug, Default)]
struct FrameIdExtender {
    last_raw: Option<u64>,
    wraps: u64,
    last_seq: Option<u64>,
}

impl FrameIdExtender {
    const PERIOD: u64 = 65_535;

    /// Notes an id (of any buffer, good or not), counting a wrap when it goes back by more
    /// than half the range. Returns the extended id.
    fn observe(&mut self, raw: u64) -> u64 {
        if raw > Self::PERIOD {
            return raw;
        }
        const HALF: u64 = FrameIdExtender::PERIOD / 2;
        let Some(last) = self.last_raw else {
            self.last_raw = Some(raw);
            return raw;
        };
        if raw < last && last - raw > HALF {
            // Went round: 65535 is followed by 1.
            self.wraps += 1;
            self.last_raw = Some(raw);
        } else if raw > last && raw - last > HALF && self.wraps > 0 {
            // A late id from before the last wrap.
            return (self.wraps - 1) * Self::PERIOD + raw;
        } else if raw > last {
            self.last_raw = Some(raw);
        }
        self.wraps * Self::PERIOD + raw
    }

    /// The extended id of a frame to pass on, or `None` when it would not be after the last
    /// one passed on (a late or repeated frame).
    fn extend(&mut self, raw: u64) -> Option<u64> {
        let seq = self.observe(raw);
        if self.last_seq.is_some_and(|last| seq <= last) {
            return None;
        }
        self.last_seq = Some(seq);
        Some(seq)
    }
}

/// The cameras answering at the given IPv4 addresses, probed one by one by unicast.
///
/// This never runs Aravis's GigE Vision discovery: in Aravis 0.8 it broadcasts on every
/// network interface of the host and cannot be restricted to one. Addresses where nothing
/// answers (or that are not IPv4 addresses) are left out. Each silent address costs Aravis's
/// control timeout (a few seconds).
pub fn list_devices(addresses: &[String]) -> Vec<DeviceInfo> {
    let mut devices = Vec::new();
    for address in addresses {
        let camera = match open_by_address(address, address) {
            Ok(camera) => camera,
            Err(error) => {
                tracing::debug!(message = "No Aravis camera at address.", address = %address, %error);
                continue;
            }
        };
        let text = |value: Result<aravis::glib::GString, aravis::glib::Error>| {
            value.map(|s| s.to_string()).unwrap_or_default()
        };
        let vendor = text(camera.vendor_name());
        devices.push(DeviceInfo {
            backend: BACKEND,
            id: address.clone(),
            model: text(camera.model_name()),
            serial: text(camera.device_serial_number()),
            details: format!("vendor {vendor}, GigE Vision at {address}"),
        });
    }
    devices
}

/// Whether buffers of camera `id` were not dropped for `reason` before in this process: a
/// reason is logged once per camera for the life of the process, however often the camera is
/// reopened (each opening counts its losses afresh).
fn first_loss(id: &str, reason: &'static str) -> bool {
    static LOGGED: std::sync::Mutex<std::collections::BTreeSet<(String, &'static str)>> =
        std::sync::Mutex::new(std::collections::BTreeSet::new());
    LOGGED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .insert((id.to_owned(), reason))
}

// ---- its table in the rig config ------------------------------------------------------------

/// The longest exposure, µs.
const MAX_EXPOSURE_US: f64 = 10_000_000.0;
/// The highest analogue gain a GenICam camera offers, dB (Basler's and FLIR's reach 24-48).
const MAX_GAIN_DB: f64 = 48.0;

/// The backend, registered in `capture::backend`.
pub const REGISTERED: ColorBackend = Backend {
    name: BACKEND,
    table: read_table,
    list: Some(list_unconfigured),
};

/// `[color] backend = "aravis"`, as written.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAravis {
    address: Option<String>,
    serial: Option<String>,
    #[serde(default = "default_pixel_format")]
    pixel_format: String,
    region: Option<[u32; 4]>,
    exposure_us: Option<f64>,
    gain_db: Option<f64>,
    fps: Option<f64>,
    #[serde(default = "default_trigger")]
    trigger: String,
    #[serde(default = "default_buffers")]
    buffers: usize,
}

fn default_pixel_format() -> String {
    "bayer_rg8".to_owned()
}
fn default_trigger() -> String {
    "free_run".to_owned()
}
fn default_buffers() -> usize {
    16
}

fn read_table(table: toml::Table) -> Result<Arc<dyn CameraConfig<Frame = ColorFrame>>, TableError> {
    Ok(Arc::new(check_table(table)?))
}

fn check_table(table: toml::Table) -> Result<AravisConfig, TableError> {
    let c: RawAravis = backend::deserialize(BACKEND, table)?;
    let fps = c.fps.map(|f| backend::positive("fps", f, 1000.0)).transpose()?;
    if c.address.is_none() && c.serial.is_none() {
        return Err(TableError::new("", "needs `address` or `serial` to say which camera"));
    }
    if let Some(a) = &c.address {
        if a.parse::<Ipv4Addr>().is_err() {
            return Err(TableError::new(
                "address",
                format!("must be an IPv4 address, not {a:?}"),
            ));
        }
    }
    let pixel_format = PixelFormat::ALL
        .into_iter()
        .find(|f| f.name() == c.pixel_format)
        .ok_or_else(|| {
            let names: Vec<&str> = PixelFormat::ALL.iter().map(|f| f.name()).collect();
            TableError::new(
                "pixel_format",
                format!("must be one of {}, not {:?}", names.join(", "), c.pixel_format),
            )
        })?;
    if let Some(region) = c.region {
        check_region(region)?;
    }
    if let Some(e) = c.exposure_us {
        if !(e.is_finite() && e > 0.0 && e <= MAX_EXPOSURE_US) {
            return Err(TableError::new(
                "exposure_us",
                format!("must be above 0 and at most {MAX_EXPOSURE_US} (10 s), not {e}"),
            ));
        }
    }
    if let Some(g) = c.gain_db {
        if !(g.is_finite() && (0.0..=MAX_GAIN_DB).contains(&g)) {
            return Err(TableError::new(
                "gain_db",
                format!("must be from 0 to {MAX_GAIN_DB} dB, not {g}"),
            ));
        }
    }
    if !(1..=256).contains(&c.buffers) {
        return Err(TableError::new(
            "buffers",
            format!("must be from 1 to 256, not {}", c.buffers),
        ));
    }
    Ok(AravisConfig {
        address: c.address,
        serial: c.serial,
        pixel_format,
        region: c.region.map(|[x, y, w, h]| (x, y, w, h)),
        exposure_us: c.exposure_us,
        gain_db: c.gain_db,
        fps,
        trigger: parse_trigger(&c.trigger)?,
        buffers: c.buffers,
    })
}

/// A region of the sensor: not empty, within the largest sensor.
fn check_region([x, y, w, h]: [u32; 4]) -> Result<(), TableError> {
    if w == 0 || h == 0 {
        return Err(TableError::new("region", "must have a width and height above 0"));
    }
    let max = backend::MAX_SENSOR_PX;
    if u64::from(x) + u64::from(w) > max || u64::from(y) + u64::from(h) > max {
        return Err(TableError::new(
            "region",
            format!("must lie within {max}x{max} pixels, not [{x}, {y}, {w}, {h}]"),
        ));
    }
    Ok(())
}

/// `free_run`, `depth`, or `line:<LINE>` with a GenICam line name.
fn parse_trigger(text: &str) -> Result<Trigger, TableError> {
    match text {
        "free_run" => return Ok(Trigger::FreeRun),
        "depth" => return Ok(Trigger::Depth),
        _ => {}
    }
    match text.strip_prefix("line:") {
        Some(line)
            if !line.is_empty()
                && line.len() <= 32
                && line.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_') =>
        {
            Ok(Trigger::Line(line.to_owned()))
        }
        _ => Err(TableError::new(
            "trigger",
            format!(
                "must be \"free_run\", \"depth\" or \"line:<LINE>\" with a GenICam line name of letters, digits and _ (e.g. \"line:Line1\"), not {text:?}"
            ),
        )),
    }
}

impl CameraConfig for AravisConfig {
    type Frame = ColorFrame;

    fn backend(&self) -> &'static str {
        BACKEND
    }

    fn open(&self) -> Result<Box<dyn FrameSource<Frame = ColorFrame>>, CaptureError> {
        Ok(Box::new(AravisColor::open(self)?))
    }

    fn open_in_step(&self, beat: &Arc<DepthBeat>) -> Result<Box<dyn FrameSource<Frame = ColorFrame>>, CaptureError> {
        let mut camera = AravisColor::open(self)?;
        camera.in_step_with(beat);
        Ok(Box::new(camera))
    }

    fn frame_size(&self) -> Option<(u32, u32)> {
        self.region.map(|(_, _, w, h)| (w, h))
    }

    fn devices(&self) -> Option<BackendDevices> {
        Some(listing(self.address.as_slice()))
    }
}

fn list_unconfigured() -> BackendDevices {
    listing(&[])
}

/// The cameras at `addresses`: GigE Vision cameras are looked for nowhere else.
fn listing(addresses: &[String]) -> BackendDevices {
    BackendDevices {
        backend: BACKEND,
        devices: list_devices(addresses),
        error: None,
        scope: if addresses.is_empty() {
            "no GigE Vision address configured (no broadcast discovery is ever sent; name the \
             camera's address in the rig config's [color] table and pass --config)"
                .to_owned()
        } else {
            format!("GigE Vision cameras at {}", addresses.join(", "))
        },
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn the_table_defaults_and_reads_its_settings() {
        let table: toml::Table =
            toml::from_str("address = \"127.0.0.1\"\ngain_db = 12.0\ntrigger = \"line:Line1\"\n").unwrap();
        let c = check_table(table).unwrap();
        assert_eq!(
            (c.gain_db, c.trigger, c.buffers),
            (Some(12.0), Trigger::Line("Line1".into()), 16)
        );
        let table: toml::Table = toml::from_str("address = \"127.0.0.1\"\ntrigger = \"depth\"\n").unwrap();
        assert_eq!(check_table(table).unwrap().trigger, Trigger::Depth);
        let table: toml::Table = toml::from_str("address = \"127.0.0.1\"\ntrigger = \"depths\"\n").unwrap();
        let error = check_table(table).unwrap_err().reason;
        assert!(error.contains("\"depth\"") && error.contains("\"depths\""), "{error}");
        assert_eq!(c.pixel_format, PixelFormat::BayerRg8);
    }

    use super::*;

    /// Issue 37 item 5: a reason buffers are dropped for is logged once per camera, not once
    /// per opening (a camera reopened after each outage logged it again each time).
    #[test]
    fn issue37_a_loss_reason_is_logged_once_per_camera_whatever_the_reopenings() {
        assert!(first_loss("issue37-a", "missing_packets"));
        assert!(!first_loss("issue37-a", "missing_packets"));
        assert!(first_loss("issue37-a", "timeout"));
        assert!(first_loss("issue37-b", "missing_packets"));
    }

    #[test]
    fn frame_ids_extend_across_the_16_bit_wrap() {
        let mut ids = FrameIdExtender::default();
        let raws = [65_533, 65_534, 65_535, 1, 2, 3];
        let seqs: Vec<u64> = raws.iter().map(|&r| ids.extend(r).unwrap()).collect();
        assert_eq!(seqs, [65_533, 65_534, 65_535, 65_536, 65_537, 65_538]);
    }

    #[test]
    fn damaged_buffers_keep_the_wrap_and_late_frames_are_refused() {
        let mut ids = FrameIdExtender::default();
        assert_eq!(ids.extend(65_534), Some(65_534));
        ids.observe(65_535);
        ids.observe(1);
        assert_eq!(ids.extend(2), Some(65_537));
        assert_eq!(ids.extend(2), None);
        assert_eq!(ids.extend(1), None);
        assert_eq!(ids.extend(100_000), Some(100_000));
    }

    #[test]
    fn a_late_id_from_before_the_wrap_does_not_count_a_second_wrap() {
        let mut ids = FrameIdExtender::default();
        assert_eq!(ids.extend(65_534), Some(65_534));
        assert_eq!(ids.extend(2), Some(65_537));
        assert_eq!(ids.observe(65_535), 65_535);
        assert_eq!(ids.extend(3), Some(65_538));
    }

    #[test]
    fn pixel_formats_map_both_ways() {
        for format in PixelFormat::ALL {
            assert!(!genicam_names(format).is_empty());
        }
        assert_eq!(
            pixel_format_from_aravis(aravis::PixelFormat::BAYER_RG_8),
            Some(PixelFormat::BayerRg8)
        );
        assert_eq!(pixel_format_from_aravis(aravis::PixelFormat::MONO_16), None);
    }
}
