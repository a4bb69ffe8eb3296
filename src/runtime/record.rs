//! `mousepose record`: the cameras of a rig config written to a session, lossless, as they
//! deliver.
//!
//! ```text
//!  cap-depth (OpenNI2) ──┐  capture edge (drops when full, counted)
//!                        ├──────────────────────────────────────────▶ recorder (SessionWriter)
//!  cap-color (Aravis/V4L2)┘
//! ```
//!
//! The session is written in place (not staged): every frame is handed to the operating
//! system as it is written, so a recorder killed at any moment leaves a session that reads up
//! to its last complete frame (without the `session_ended` event that marks it complete).

use crate::core::frame::ColorFrame;
use crate::io::session::{
    CameraMeta, CameraRole, SessionError, SessionEvent, SessionMeta, SessionSource, SessionWriter,
};
use crate::runtime::capture::aravis::{AravisColor, AravisConfig, Trigger};
use crate::runtime::capture::openni::{OpenNiConfig, OpenNiDepth};
use crate::runtime::capture::v4l2::{V4l2Color, V4l2Config};
use crate::runtime::capture::{CaptureError, Captured, Clock, FrameSource, SeqGaps};
use crate::runtime::config::{ColorCamera, Config, DepthCamera, TriggerMode};
use crate::runtime::pipeline::{PipelineError, Runner, Shutdown, StageError, edge};
use crate::runtime::topology::{Accounting, CameraSummary, run_source};
use crate::vision::calibrate::RigCalibration;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Why recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("cannot open the {role} camera")]
    Camera {
        role: CameraRole,
        #[source]
        source: CaptureError,
    },
    #[error("the output {0:?} exists and is not empty (use --force to replace it)")]
    NotEmpty(PathBuf),
    #[error("cannot create the output {path:?}")]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write the session")]
    Session(#[from] SessionError),
    #[error("cannot start the recording threads")]
    Threads(#[source] std::io::Error),
    #[error("recording stopped")]
    Pipeline(#[from] PipelineError),
    #[error("cannot use the rig's calibration")]
    Calibration(#[from] crate::vision::calibrate::CalibrationError),
}

/// The colour camera of a rig, whichever its driver.
#[derive(Debug)]
pub enum ColorSource {
    Aravis(AravisColor),
    V4l2(V4l2Color),
}

impl FrameSource for ColorSource {
    type Frame = ColorFrame;

    fn meta(&self) -> CameraMeta {
        match self {
            ColorSource::Aravis(s) => s.meta(),
            ColorSource::V4l2(s) => s.meta(),
        }
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        match self {
            ColorSource::Aravis(s) => s.start(clock),
            ColorSource::V4l2(s) => s.start(clock),
        }
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<ColorFrame>, CaptureError> {
        match self {
            ColorSource::Aravis(s) => s.next_frame(timeout),
            ColorSource::V4l2(s) => s.next_frame(timeout),
        }
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        match self {
            ColorSource::Aravis(s) => s.losses(),
            ColorSource::V4l2(s) => s.losses(),
        }
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        match self {
            ColorSource::Aravis(s) => s.stop(),
            ColorSource::V4l2(s) => s.stop(),
        }
    }
}

/// The depth camera a config names, ready to start (the camera is opened by `start`).
pub fn open_depth(camera: &DepthCamera) -> OpenNiDepth {
    match camera {
        DepthCamera::Openni2 {
            uri,
            serial,
            width,
            height,
            fps,
        } => OpenNiDepth::new(OpenNiConfig {
            uri: uri.clone(),
            serial: serial.clone(),
            width: *width,
            height: *height,
            fps: fps.round() as u32,
        }),
    }
}

/// Opens the colour camera a config names (settings are checked against the camera here).
///
/// # Errors
/// The camera cannot be found, opened or configured.
pub fn open_color(camera: &ColorCamera) -> Result<ColorSource, CaptureError> {
    match camera {
        ColorCamera::Aravis {
            address,
            serial,
            pixel_format,
            region,
            exposure_us,
            gain_db,
            fps,
            trigger,
            buffers,
        } => AravisColor::open(&AravisConfig {
            address: address.clone(),
            serial: serial.clone(),
            pixel_format: *pixel_format,
            region: *region,
            exposure_us: *exposure_us,
            gain_db: *gain_db,
            fps: *fps,
            trigger: match trigger {
                TriggerMode::FreeRun => Trigger::FreeRun,
                TriggerMode::Line(l) => Trigger::Line(l.clone()),
            },
            buffers: *buffers,
        })
        .map(ColorSource::Aravis),
        ColorCamera::V4l2 {
            device,
            width,
            height,
            fps,
        } => V4l2Color::open(V4l2Config {
            device: device.clone(),
            width: *width,
            height: *height,
            fps: *fps,
            format: None,
        })
        .map(ColorSource::V4l2),
    }
}

/// One camera of a recording. `captured = recorded + dropped_total`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RecordedCamera {
    pub captured: u64,
    pub recorded: u64,
    pub dropped: BTreeMap<String, u64>,
    pub dropped_total: u64,
    pub lost_before_capture: BTreeMap<String, u64>,
}

impl From<CameraSummary> for RecordedCamera {
    /// The recorder counts each frame written as "paired" (kept).
    fn from(c: CameraSummary) -> Self {
        Self {
            captured: c.captured,
            recorded: c.paired,
            dropped: c.dropped,
            dropped_total: c.dropped_total,
            lost_before_capture: c.lost_before_capture,
        }
    }
}

/// What a recording wrote, per camera.
#[derive(Clone, Debug, Serialize)]
pub struct RecordSummary {
    pub dir: PathBuf,
    pub seconds: f64,
    /// Per camera: captured = recorded + dropped.
    pub cameras: BTreeMap<&'static str, RecordedCamera>,
    pub depth_frames: u64,
    pub color_frames: u64,
    pub depth_bytes: u64,
    pub color_bytes: u64,
    /// CPU time the whole process used per second recorded (1.0 = one core busy).
    pub cpu_cores: f64,
}

fn now_utc() -> String {
    // Seconds since the epoch, rendered as RFC 3339 without a date library.
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let days = secs / 86_400;
    let (h, m, s) = (secs % 86_400 / 3600, secs % 3600 / 60, secs % 60);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let mo = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(mo <= 2);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}:{m:02}:{s:02}Z")
}

/// Records the cameras of `config` into `out` until `seconds` have passed (if given) or
/// `stop` is requested (a signal), whichever comes first.
///
/// # Errors
/// See [`RecordError`].
pub fn record(
    config: &Config,
    out: &Path,
    seconds: Option<f64>,
    force: bool,
    stop: &Shutdown,
) -> Result<RecordSummary, RecordError> {
    let calibration = load_calibration(config)?;
    prepare_output(out, force)?;
    let mut depth = open_depth(&config.depth);
    let color = config
        .color
        .as_ref()
        .map(open_color)
        .transpose()
        .map_err(|source| RecordError::Camera {
            role: CameraRole::Color,
            source,
        })?;
    let clock = Clock::Monotonic;
    // Start the depth camera here so that its metadata (model, serial, mode) is known.
    depth.start(&clock).map_err(|source| RecordError::Camera {
        role: CameraRole::Depth,
        source,
    })?;
    let mut cameras = vec![depth.meta()];
    cameras.extend(color.as_ref().map(FrameSource::meta));
    let mut meta = SessionMeta::new(now_utc(), SessionSource::Recorded, cameras);
    meta.notes = format!("recorded with rig config {:?}", config.path);
    if meta.camera(CameraRole::Color).is_some() {
        meta.color_latency_ns = Some(config.sync.color_latency_ns);
    }
    if let Some(calibration) = &calibration {
        // The modes and serials the cameras actually opened with.
        calibration.check_matches(&meta)?;
        meta.rig = Some(calibration.rig());
    }
    let mut writer = SessionWriter::create(out, &meta)?;
    let host_ns = clock.now_ns();
    writer.log_event(&SessionEvent::SessionStarted { host_ns })?;
    for c in &meta.cameras {
        writer.log_event(&SessionEvent::CameraOpened {
            host_ns,
            role: c.role,
            model: c.model.clone(),
            serial: c.serial.clone(),
        })?;
    }

    let (tx, rx, _) = edge::<Captured>(config.capture_edge);
    let acct = Arc::new(Accounting::default());
    let mut runner = Runner::new();
    let shutdown = runner.shutdown();
    let threads = RecordError::Threads;
    {
        let (tx, acct, shutdown, clock) = (tx.clone(), Arc::clone(&acct), shutdown.clone(), clock.clone());
        runner
            .spawn("cap-depth", move || {
                run_source(Started(depth), &clock, Captured::Depth, &tx, &acct, &shutdown)
            })
            .map_err(threads)?;
    }
    if let Some(color) = color {
        let (tx, acct, shutdown, clock) = (tx.clone(), Arc::clone(&acct), shutdown.clone(), clock.clone());
        runner
            .spawn("cap-color", move || {
                run_source(color, &clock, Captured::Color, &tx, &acct, &shutdown)
            })
            .map_err(threads)?;
    }
    drop(tx);
    let acct_rec = Arc::clone(&acct);
    let (done_tx, done_rx) = crossbeam_channel::bounded(1);
    runner
        .spawn("recorder", move || {
            let result = write_frames(&mut writer, &rx, &acct_rec);
            // Hand the writer back to finish it, whatever happened.
            let _ = done_tx.send(writer);
            result
        })
        .map_err(threads)?;

    let start = Instant::now();
    let cpu0 = crate::runtime::capture::clock::process_cpu_s();
    let limit = seconds.map(Duration::from_secs_f64);
    while !stop.requested() && !shutdown.requested() && limit.is_none_or(|l| start.elapsed() < l) {
        std::thread::sleep(Duration::from_millis(20));
    }
    shutdown.request();
    let joined = runner.join();
    let elapsed = start.elapsed().as_secs_f64();
    let cpu = crate::runtime::capture::clock::process_cpu_s() - cpu0;
    let writer = done_rx.recv().ok();
    let mut cams = BTreeMap::new();
    cams.insert("depth", RecordedCamera::from(CameraSummary::of(&acct.depth)));
    if config.color.is_some() {
        cams.insert("color", RecordedCamera::from(CameraSummary::of(&acct.color)));
    }
    let Some(mut writer) = writer else {
        joined?;
        return Err(RecordError::Threads(std::io::Error::other(
            "the recorder thread ended early",
        )));
    };
    for (role, c) in &cams {
        let lost: Vec<String> = c.lost_before_capture.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let dropped: Vec<String> = c.dropped.iter().map(|(k, v)| format!("{k} {v}")).collect();
        writer.log_event(&SessionEvent::Note {
            host_ns: clock.now_ns(),
            message: format!(
                "{role}: captured {}, recorded {}, dropped [{}], lost before capture [{}]",
                c.captured,
                c.recorded,
                dropped.join(", "),
                lost.join(", ")
            ),
        })?;
    }
    joined?;
    let summary = writer.finish()?;
    Ok(RecordSummary {
        dir: summary.dir,
        seconds: elapsed,
        cameras: cams,
        depth_frames: summary.depth_frames,
        color_frames: summary.color_frames,
        depth_bytes: summary.depth_bytes,
        color_bytes: summary.color_bytes,
        cpu_cores: cpu / elapsed.max(1e-9),
    })
}

/// A source already started by the caller: `start` does nothing more.
struct Started<S>(S);

impl<S: FrameSource> FrameSource for Started<S> {
    type Frame = S::Frame;

    fn meta(&self) -> CameraMeta {
        self.0.meta()
    }

    fn start(&mut self, _clock: &Clock) -> Result<(), CaptureError> {
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<S::Frame>, CaptureError> {
        self.0.next_frame(timeout)
    }

    fn finished(&self) -> bool {
        self.0.finished()
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        self.0.losses()
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        self.0.stop()
    }
}

/// The recorder thread: writes each frame as it arrives, logging gaps in the cameras'
/// sequence numbers as dropped frames.
fn write_frames(
    writer: &mut SessionWriter,
    rx: &crossbeam_channel::Receiver<Captured>,
    acct: &Accounting,
) -> Result<(), StageError> {
    let mut gaps = [SeqGaps::default(); 2];
    for captured in rx.iter() {
        let (role, stamp) = match &captured {
            Captured::Depth(f) => (CameraRole::Depth, f.stamp),
            Captured::Color(f) => (CameraRole::Color, f.stamp),
        };
        let slot = usize::from(role == CameraRole::Color);
        let missing = gaps[slot].observe(stamp.seq);
        if missing > 0 {
            writer.log_event(&SessionEvent::FramesDropped {
                host_ns: stamp.host_ns,
                role,
                seq_from: stamp.seq - missing,
                count: missing,
                reason: "not delivered (camera gap or full capture queue)".to_owned(),
            })?;
        }
        match &captured {
            Captured::Depth(f) => writer.write_depth(f)?,
            Captured::Color(f) => writer.write_color(f)?,
        }
        // Kept frames are counted as paired (see `RecordedCamera::from`).
        acct.camera(role)
            .paired
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
    Ok(())
}

/// The rig config's calibration file, loaded and checked against the configured camera sizes
/// (before any camera opens); `None` when the config names none.
fn load_calibration(config: &Config) -> Result<Option<RigCalibration>, RecordError> {
    let Some(path) = &config.calibration else {
        return Ok(None);
    };
    let calibration = RigCalibration::load(path)?;
    let target = format!("rig config {:?}", config.path);
    let DepthCamera::Openni2 { width, height, .. } = &config.depth;
    calibration.check_camera(CameraRole::Depth, *width, *height, None, &target)?;
    let color_size = match &config.color {
        Some(ColorCamera::V4l2 { width, height, .. }) => Some((*width, *height)),
        Some(ColorCamera::Aravis { region, .. }) => region.map(|(_, _, w, h)| (w, h)),
        None => None,
    };
    if let Some((width, height)) = color_size {
        calibration.check_camera(CameraRole::Color, width, height, None, &target)?;
    }
    Ok(Some(calibration))
}

fn prepare_output(out: &Path, force: bool) -> Result<(), RecordError> {
    let io = |source| RecordError::Output {
        path: out.to_owned(),
        source,
    };
    if out.exists() {
        let mut entries = std::fs::read_dir(out).map_err(io)?;
        if entries.next().is_some() {
            if !force {
                return Err(RecordError::NotEmpty(out.to_owned()));
            }
            std::fs::remove_dir_all(out).map_err(io)?;
        }
    }
    std::fs::create_dir_all(out).map_err(io)
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_dates_render_as_rfc3339() {
        let s = super::now_utc();
        assert_eq!(s.len(), 20, "{s}");
        assert!(s.starts_with("20") && s.ends_with('Z'));
    }
}
