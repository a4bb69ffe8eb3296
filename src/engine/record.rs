//! Recording (`mousepose record`): the cameras of a rig config written to a session, lossless, as they
//! deliver (the topology with the recorder branch only).
//!
//! The session is written in place (not staged): every frame is handed to the operating
//! system as it is written, so a recorder killed at any moment leaves a session that reads up
//! to its last complete frame (without the `session_ended` event that marks it complete).

use crate::engine::{Failure, Signals, signal_name};
use crate::io::output::Staging;
use crate::io::session::{
    CameraMeta, CameraRole, SessionError, SessionEvent, SessionMeta, SessionSource, SessionSummary, SessionWriter,
};
use crate::runtime::accounting::CameraSummary;
use crate::runtime::capture::rig::RigCameras;
use crate::runtime::capture::supervise::{SharedHealth, lock, log_camera_events};
use crate::runtime::capture::{CaptureError, Captured, Clock};
use crate::runtime::config::Config;
use crate::runtime::pipeline::{PipelineError, Shutdown};
use crate::runtime::sink::session::FrameRecorder;
use crate::runtime::topology::{Edges, Topology, TopologyError};
use crate::vision::calibrate::RigCalibration;
use anyhow::Context as _;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
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
    #[error("a recording lasts more than 0 and at most 86400 seconds, not {0}")]
    Seconds(f64),
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
    Threads(#[from] TopologyError),
    #[error("the recorder thread ended early")]
    RecorderEnded,
    #[error("recording stopped")]
    Pipeline(#[from] PipelineError),
    #[error(transparent)]
    Staging(#[from] crate::io::output::OutputError),
    #[error("cannot use the rig's calibration")]
    Calibration(#[from] crate::vision::calibrate::CalibrationError),
}

impl RecordError {
    /// Whether what the user asked for is what cannot work (a directory in the way, a
    /// calibration that cannot be read, a duration out of range), not the recording.
    pub fn is_usage(&self) -> bool {
        matches!(self, Self::NotEmpty(_) | Self::Calibration(_) | Self::Seconds(_))
    }
}

/// What a recording wrote, per camera.
#[derive(Clone, Debug, Serialize)]
pub struct RecordSummary {
    pub dir: PathBuf,
    pub seconds: f64,
    /// Per camera: captured = recorded + not recorded.
    pub cameras: BTreeMap<&'static str, CameraSummary>,
    /// Per camera, the times it was away (each logged in the session's events).
    pub outages: BTreeMap<&'static str, usize>,
    pub depth_frames: u64,
    pub color_frames: u64,
    pub depth_bytes: u64,
    pub color_bytes: u64,
    /// CPU time the whole process used per second recorded (1.0 = one core busy).
    pub cpu_cores: f64,
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
    let limit = match seconds {
        Some(s) if !(s > 0.0 && s <= 86_400.0) => return Err(RecordError::Seconds(s)),
        s => s.map(Duration::from_secs_f64),
    };
    let calibration = load_calibration(config)?;
    // A session replaced with --force is written beside it and moved into place only once
    // frames were recorded: a camera that fails to open leaves the old session as it was.
    let staging = prepare_output(out, force)?;
    let dir = staging.as_ref().map_or(out, Staging::path);
    let clock = Clock::Monotonic;
    // Both cameras must open now (the depth camera started, so that its metadata is known);
    // once recording, they are supervised as the daemon's are (closed, reopened, their
    // outages logged in the session) and recording rides out their outages.
    let (cameras, metas) = RigCameras::opened(&config.depth, config.color.as_ref(), config.reconnect, &clock)
        .map_err(|(role, source)| RecordError::Camera { role, source })?;
    let writer = create_session(config, calibration.as_ref(), dir, metas, &clock)?;
    let stall_watches = cameras.stall_watches();
    let healths: Vec<SharedHealth> = cameras.healths().into_iter().map(|(_, h)| h).collect();
    let topology = Topology {
        sources: cameras.into(),
        sync: config.sync,
        edges: Edges {
            capture: config.capture_edge,
            stage: config.stage_edge,
        },
        processing: None,
        recorder: Some(Box::new(SupervisedSession {
            writer,
            cameras: healths.clone(),
        })),
    };
    let running = topology.start()?;
    let shutdown = running.shutdown();
    let start = Instant::now();
    let cpu0 = crate::runtime::usage::process_cpu_s();
    while !stop.requested() && !shutdown.requested() && limit.is_none_or(|l| start.elapsed() < l) {
        std::thread::sleep(Duration::from_millis(20));
        for watch in &stall_watches {
            watch.check();
        }
    }
    shutdown.request();
    let finished = running.join();
    let elapsed = start.elapsed().as_secs_f64();
    let cpu = crate::runtime::usage::process_cpu_s() - cpu0;
    let joined = finished.outcome;
    let cams = finished.cameras;
    let Some(mut writer) = finished.recorder else {
        joined?;
        return Err(RecordError::RecorderEnded);
    };
    log_camera_events(&healths, |e| writer.log_event(e))?;
    let outages: BTreeMap<&'static str, usize> = [("depth", 0), ("color", 1)]
        .into_iter()
        .filter_map(|(name, i)| Some((name, lock(healths.get(i)?).outages.len())))
        .collect();
    for (role, c) in &cams {
        let lost: Vec<String> = c.lost_before_capture.iter().map(|(k, v)| format!("{k} {v}")).collect();
        let dropped: Vec<String> = c.not_recorded.iter().map(|(k, v)| format!("{k} {v}")).collect();
        writer.log_event(&SessionEvent::Note {
            host_ns: clock.now_ns(),
            message: format!(
                "{role}: captured {}, recorded {}, not recorded [{}], lost before capture [{}]",
                c.captured,
                c.recorded.unwrap_or(0),
                dropped.join(", "),
                lost.join(", ")
            ),
        })?;
    }
    let finished = writer.finish();
    // What was recorded is kept even when the run failed.
    if let Some(staging) = staging {
        staging.commit()?;
    }
    joined?;
    let summary = finished?.ok_or(RecordError::RecorderEnded)?;
    Ok(RecordSummary {
        dir: out.to_owned(),
        seconds: elapsed,
        cameras: cams,
        outages,
        depth_frames: summary.depth_frames,
        color_frames: summary.color_frames,
        depth_bytes: summary.depth_bytes,
        color_bytes: summary.color_bytes,
        cpu_cores: cpu / elapsed.max(1e-9),
    })
}

/// The session of a recording, begun: the cameras as they opened, the configuration's notes
/// and colour latency, the calibration checked against the cameras (the modes and serials
/// they actually opened with).
fn create_session(
    config: &Config,
    calibration: Option<&RigCalibration>,
    dir: &Path,
    cameras: Vec<CameraMeta>,
    clock: &Clock,
) -> Result<SessionWriter, RecordError> {
    let mut meta = SessionMeta::new(
        crate::runtime::capture::clock::utc_now(),
        SessionSource::Recorded,
        cameras,
    );
    meta.notes = format!("recorded with rig config {:?}", config.path);
    if meta.camera(CameraRole::Color).is_some() {
        meta.color_latency_ns = Some(config.sync.color_latency_ns);
    }
    if let Some(calibration) = calibration {
        calibration.check_matches(&meta)?;
        meta.rig = Some(calibration.rig());
    }
    let mut writer = SessionWriter::create(dir, &meta)?;
    writer.log_event(&SessionEvent::SessionStarted {
        host_ns: clock.now_ns(),
    })?;
    Ok(writer)
}

/// The session being recorded, with the supervised cameras' events (outages, reopenings)
/// logged into it before each frame.
#[derive(Debug)]
struct SupervisedSession {
    writer: SessionWriter,
    cameras: Vec<SharedHealth>,
}

impl FrameRecorder for SupervisedSession {
    fn write(&mut self, frame: &Captured) -> Result<Option<&'static str>, SessionError> {
        let writer = &mut self.writer;
        log_camera_events(&self.cameras, |e| writer.log_event(e))?;
        FrameRecorder::write(writer, frame)
    }

    fn log_event(&mut self, event: &SessionEvent) -> Result<(), SessionError> {
        self.writer.log_event(event)
    }

    fn finish(self: Box<Self>) -> Result<Option<SessionSummary>, SessionError> {
        let mut writer = self.writer;
        log_camera_events(&self.cameras, |e| writer.log_event(e))?;
        writer.finish().map(Some)
    }
}

/// The rig config's calibration file, loaded and checked against the configured camera sizes
/// (before any camera opens); `None` when the config names none.
fn load_calibration(config: &Config) -> Result<Option<RigCalibration>, RecordError> {
    let Some(path) = &config.calibration else {
        return Ok(None);
    };
    let calibration = RigCalibration::load(path)?;
    let target = format!("rig config {:?}", config.path);
    let (width, height, _) = config.depth.mode();
    calibration.check_camera(CameraRole::Depth, width, height, None, &target)?;
    let color_size = config.color.as_ref().and_then(|c| c.frame_size());
    if let Some((width, height)) = color_size {
        calibration.check_camera(CameraRole::Color, width, height, None, &target)?;
    }
    Ok(Some(calibration))
}

/// Makes `out` ready: an absent or empty directory is written in place (so that a recorder
/// killed at any moment leaves its frames where the user looks); one to replace (`force`) gets
/// a staging directory beside it.
fn prepare_output(out: &Path, force: bool) -> Result<Option<Staging>, RecordError> {
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
            return Ok(Some(Staging::new(out, true)?));
        }
    }
    std::fs::create_dir_all(out).map_err(io)?;
    Ok(None)
}

/// What `mousepose record` records.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    /// The rig configuration file.
    pub config: PathBuf,
    /// The session directory to write.
    pub out: PathBuf,
    /// Stop after this many seconds (otherwise at SIGINT or SIGTERM).
    pub seconds: Option<f64>,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

/// Loads the configuration and records its cameras until `seconds` or a stop signal
/// (SIGINT, SIGTERM, SIGHUP: [`crate::engine::stop_signals`]), then closes the session.
/// Returns its summary and, when a signal other than SIGINT, SIGTERM or SIGHUP stopped it, the
/// sentence that says so (the command then fails, after its summary).
///
/// # Errors
/// The configuration or the request cannot work (the user's), or the recording failed.
pub fn record_until_signal(options: &RecordOptions) -> Result<(RecordSummary, Option<String>), Failure> {
    let config = Config::load(&options.config).map_err(Failure::usage)?;
    let stop = Shutdown::default();
    let signals = Signals::install(&stop, true).context("installing the signal handlers")?;
    let summary = record(&config, &options.out, options.seconds, options.force, &stop)
        .map_err(|e| Failure::classed(e.is_usage(), e).context(format!("recording to {:?}", options.out)))?;
    if let Some(signal) = signals.caught() {
        tracing::info!(dir = ?options.out, "recording stopped by {}: session closed", signal_name(signal));
    }
    Ok((summary, signals.unexpected_stop()))
}

impl RecordSummary {
    /// A configured camera that gave nothing makes a failed recording, however complete the
    /// session is otherwise (e.g. a GigE camera losing half its packets: no whole frame):
    /// one sentence per such camera.
    pub fn silent_cameras(&self) -> Vec<String> {
        self.cameras
            .iter()
            .filter(|(_, c)| c.recorded == Some(0))
            .map(|(name, c)| {
                format!(
                    "the {name} camera recorded no frame (lost before capture: {:?})",
                    c.lost_before_capture
                )
            })
            .collect()
    }
}
