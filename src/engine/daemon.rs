//! The daemon (`mousepose run`). Opens the configured cameras, processes live, records, and
//! keeps going through camera faults and a full disk until SIGTERM (or `--seconds`).
//! SIGHUP does not stop it (there is nothing it could reload: it says so); any other signal
//! that would end the process stops it cleanly, with its report.
//!
//! Under systemd (`Type=notify`) it says READY=1 once the cameras were tried (running degraded
//! when one cannot be opened, with STATUS= saying why), WATCHDOG=1 only while the pipeline
//! makes progress, and STATUS= with the frame rate and counts every few seconds.

use crate::core::geometry::Rig;
use crate::engine::{Failure, Signals, project_python, signal_name};
use crate::io::session::CameraRole;
use crate::runtime::capture::rig::RigCameras;
use crate::runtime::capture::supervise::{CameraState, SharedHealth, StallWatch, lock};
use crate::runtime::capture::{CaptureError, Clock};
use crate::runtime::config::{Config, DepthCamera};
use crate::runtime::http::HttpServer;
use crate::runtime::models::Models;
use crate::runtime::pipeline::Shutdown;
use crate::runtime::pose_record::PoseStatus;
use crate::runtime::recording::Recording;
use crate::runtime::sink::chunks::{
    ChunkPlan, ChunkPoses, ChunkRecorder, Chunks, DiskWatch, Live, RecorderGauges, chunk_meta,
};
use crate::runtime::sink::session::FrameRecorder;
use crate::runtime::stages::segment::{FloorSlot, SegmentStage};
use crate::runtime::status::{RunInfo, RunReport, Watch, Watched};
use crate::runtime::stream::lsl::{LslOutlet, LslStartError};
use crate::runtime::stream::message::{self, StreamEvent};
use crate::runtime::stream::{Publisher, StreamError, StreamHandle, Topic};
use crate::runtime::topology::{Edges, Processing, Topology};
use crate::vision::calibrate::RigCalibration;
use crate::vision::segment::{Segmenter, SegmenterConfig};
use anyhow::Context as _;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// The rig: the configured calibration, the one a replayed session was made with, or the
/// default rig with the depth intrinsics scaled to the configured depth mode.
fn live_rig(config: &Config) -> anyhow::Result<Rig> {
    if let Some(path) = &config.calibration {
        return Ok(RigCalibration::load(path)
            .with_context(|| format!("the calibration named by {:?}", config.path))?
            .rig());
    }
    if let Some(rig) = config.depth.rig() {
        return Ok(rig);
    }
    let mut rig = Rig::default_rig();
    let (width, height, _) = config.depth.mode();
    let i = &mut rig.depth.intrinsics;
    let scale = f64::from(width) / f64::from(i.width);
    (i.fx, i.fy, i.cx, i.cy) = (i.fx * scale, i.fy * scale, i.cx * scale, i.cy * scale);
    (i.width, i.height) = (width, height);
    Ok(rig)
}

/// Creates the run's directory, named by its start (UTC, sortable, without colons); a run
/// started within the same second as the previous one (a restart) gets `-2`, `-3`...
fn create_run_dir(output: &std::path::Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(output).with_context(|| format!("cannot create the output directory {output:?}"))?;
    let name = crate::runtime::capture::clock::utc_now().replace([':', '-'], "");
    for k in 1..=100 {
        let dir = match k {
            1 => output.join(&name),
            k => output.join(format!("{name}-{k}")),
        };
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e).with_context(|| format!("cannot create the run directory {dir:?}")),
        }
    }
    anyhow::bail!("cannot create a run directory in {output:?}: 100 runs began within the second {name}")
}

fn notify(states: &[sd_notify::NotifyState<'_>]) {
    if let Err(e) = sd_notify::notify(states) {
        tracing::debug!("cannot notify systemd: {e}");
    }
}

/// One line on the cameras and the poses, for STATUS= and the log.
fn status_line(healths: &[(&str, SharedHealth)], live: &Live, fps: f64) -> String {
    let cams: Vec<String> = healths
        .iter()
        .map(|(name, h)| match &lock(h).state {
            Some(CameraState::Streaming) => format!("{name} streaming"),
            Some(CameraState::Opening) => format!("{name} opening"),
            Some(CameraState::Away(why)) => format!("{name} away ({why})"),
            None => format!("{name} ?"),
        })
        .collect();
    let degraded = if live
        .latest
        .as_ref()
        .is_some_and(|p| p.status == PoseStatus::NoBackground)
    {
        ", degraded: no floor in the depth view yet"
    } else {
        ""
    };
    format!(
        "{}; {fps:.1} poses/s, {} poses, chunk {}{degraded}",
        cams.join(", "),
        live.rows,
        live.chunk
    )
}

/// Segmentation against the configured background reference, or learning the background live.
///
/// # Errors
/// The reference cannot be read, or is not of the depth camera's size.
pub fn segment_stage(config: &Config, rig: &Rig) -> anyhow::Result<SegmentStage> {
    let stage = match &config.background {
        Some(dir) => SegmentStage::new(reference_background(dir, &config.depth, rig)?),
        None => SegmentStage::learning(
            SegmenterConfig::default(),
            rig.depth.intrinsics,
            rig.depth.world_from_camera,
        ),
    };
    Ok(stage.with_mice(config.mice))
}

/// The segmenter with the empty cage of the reference session `dir`.
fn reference_background(dir: &std::path::Path, depth: &DepthCamera, rig: &Rig) -> anyhow::Result<Segmenter> {
    let what = || format!("the background reference {dir:?}");
    let recording = Recording::open(dir).with_context(what)?;
    let background = crate::engine::replay::background(&recording, rig).with_context(what)?;
    let (width, height, _) = depth.mode();
    let i = background.intrinsics();
    if (i.width, i.height) != (width, height) {
        anyhow::bail!(
            "{} is {}x{} but the depth camera is configured for {width}x{height}",
            what(),
            i.width,
            i.height
        );
    }
    tracing::info!(reference = ?dir, "background from a reference recorded with the cage empty");
    Ok(SegmenterConfig::default()
        .build(background)
        .with_context(what)?
        .with_world(rig.depth.world_from_camera))
}

/// A camera whose configuration can never work (a setting it does not have, an unreadable
/// recording): refused at start, the user's to fix; a camera absent now is not one (the daemon
/// runs without it, and takes it when it comes).
#[derive(Debug, thiserror::Error)]
#[error("the {role} camera cannot work as {config:?} configures it")]
pub struct CameraUnusable {
    role: CameraRole,
    config: PathBuf,
    #[source]
    source: CaptureError,
}

/// What a running daemon keeps an eye on from its own thread: the cameras' health and stall
/// watches, the live pose, and the pipeline's watch.
struct Lookout<'a> {
    healths: &'a [(&'static str, SharedHealth)],
    stall_watches: &'a [StallWatch],
    live: &'a Mutex<Live>,
    watch: &'a Watch,
    /// The events the live stream publishes, when there is one.
    events: Option<Mutex<StreamEvents<'a>>>,
}

/// The daemon's events on the live stream's `events` topic: the states seen last (cameras,
/// chunks, recording), compared with the states now every lookout tick (100 ms).
struct StreamEvents<'a> {
    stream: StreamHandle,
    chunks: &'a Chunks,
    gauges: Option<&'a RecorderGauges>,
    cameras: Vec<Option<bool>>,
    chunk_count: usize,
    paused: bool,
}

impl<'a> StreamEvents<'a> {
    fn new(stream: StreamHandle, chunks: &'a Chunks, gauges: Option<&'a RecorderGauges>) -> Self {
        Self {
            stream,
            chunks,
            gauges,
            cameras: Vec::new(),
            chunk_count: 0,
            paused: false,
        }
    }

    /// Publishes what changed since the last call.
    fn check(&mut self, healths: &[(&'static str, SharedHealth)]) {
        let mut events = Vec::new();
        self.cameras.resize(healths.len(), None);
        for ((camera, health), seen) in healths.iter().zip(&mut self.cameras) {
            let streaming = match &lock(health).state {
                Some(CameraState::Streaming) => Some((true, String::new())),
                Some(CameraState::Away(why)) => Some((false, why.clone())),
                _ => None,
            };
            let Some((streaming, reason)) = streaming else { continue };
            match (*seen, streaming) {
                (Some(true), false) => events.push(StreamEvent::CameraAway { camera, reason }),
                (Some(false), true) => events.push(StreamEvent::CameraBack { camera }),
                _ => {}
            }
            *seen = Some(streaming);
        }
        let chunk_count = self.chunks.count();
        events.extend((self.chunk_count..chunk_count).map(|chunk| StreamEvent::ChunkBegun { chunk }));
        self.chunk_count = chunk_count;
        let paused = self
            .gauges
            .is_some_and(|g| g.paused.load(std::sync::atomic::Ordering::Relaxed));
        if paused != self.paused {
            events.push(match paused {
                true => StreamEvent::RecordingPaused,
                false => StreamEvent::RecordingResumed,
            });
            self.paused = paused;
        }
        for event in &events {
            self.stream.publish(Topic::Events, |seq| message::event(seq, event));
        }
    }
}

impl Lookout<'_> {
    fn snapshot(&self) -> Live {
        self.live.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    fn status_line(&self, fps: f64) -> String {
        status_line(self.healths, &self.snapshot(), fps)
    }

    /// Ready once every camera was tried (opened, or known to be away).
    fn wait_ready(&self, stop: &Shutdown) {
        while !stop.requested()
            && self
                .healths
                .iter()
                .any(|(_, h)| lock(h).state == Some(CameraState::Opening))
        {
            std::thread::sleep(Duration::from_millis(20));
        }
        let status = self.status_line(0.0);
        notify(&[sd_notify::NotifyState::Ready, sd_notify::NotifyState::Status(&status)]);
        tracing::info!("ready: {status}");
    }

    /// Watches the run until a stop, a failure, or the time given: the cameras' stalls,
    /// SIGHUP, the watchdog and STATUS=. Returns the last status line sent.
    fn keep_watch(
        &self,
        stop: &Shutdown,
        shutdown: &Shutdown,
        until: Option<Instant>,
        signals: Option<&Signals>,
    ) -> String {
        let (mut last_rows, mut last_captured, mut last_tick) = (0u64, 0u64, Instant::now());
        let mut last_status = Instant::now();
        let mut last_line = String::new();
        while !stop.requested() && !shutdown.requested() && until.is_none_or(|u| Instant::now() < u) {
            std::thread::sleep(Duration::from_millis(100));
            for watch in self.stall_watches {
                watch.check();
            }
            if let Some(events) = &self.events {
                events
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .check(self.healths);
            }
            if signals.is_some_and(Signals::take_hangup) {
                answer_hangup();
            }
            if last_tick.elapsed() < Duration::from_secs(1) {
                continue;
            }
            let now = self.snapshot();
            let depth = lock(&self.healths[0].1);
            let captured = depth.frames;
            let capture_alive = depth.alive.is_some_and(|t| t.elapsed() < Duration::from_secs(5));
            drop(depth);
            // Alive: poses came out, or no depth frame went in (camera away; the capture thread
            // itself still comes by). Frames going in without poses coming out is a stuck stage:
            // no ping, and systemd restarts the daemon.
            if now.rows > last_rows || (captured == last_captured && capture_alive) {
                notify(&[sd_notify::NotifyState::Watchdog]);
            }
            let fps = self.watch.sample().poses_per_s;
            (last_rows, last_captured, last_tick) = (now.rows, captured, Instant::now());
            if last_status.elapsed() >= Duration::from_secs(5) {
                let line = status_line(self.healths, &now, fps);
                notify(&[sd_notify::NotifyState::Status(&line)]);
                last_line = line;
                last_status = Instant::now();
            }
        }
        last_line
    }
}

/// What systemd expects of a reload, though nothing is reloaded: the configuration is read at
/// start only. `RELOADING=1` comes with `MONOTONIC_USEC=` in the same message, as systemd 253
/// and later require of a `Type=notify-reload` service.
fn answer_hangup() {
    match sd_notify::NotifyState::monotonic_usec_now() {
        Ok(now) => notify(&[sd_notify::NotifyState::Reloading, now]),
        Err(e) => {
            tracing::debug!("cannot read the monotonic clock for MONOTONIC_USEC: {e}");
            notify(&[sd_notify::NotifyState::Reloading]);
        }
    }
    tracing::info!(
        "SIGHUP: nothing to reload (the configuration is read at start; restart the daemon to apply a change); the run goes on"
    );
    notify(&[sd_notify::NotifyState::Ready]);
}

/// The rig's cameras, supervised and each tried once before the pipeline starts them, so that
/// the first chunk's session holds both: a colour camera opening a moment after depth frames
/// began to flow would end that chunk at once (a chunk holds the cameras open when it
/// began). A camera that can never work removes the (empty) run directory.
fn start_cameras(config: &Config, root: &std::path::Path) -> Result<RigCameras, CameraUnusable> {
    let mut cameras = RigCameras::supervised(&config.depth, config.color.as_ref(), config.reconnect);
    if let Err((role, source)) = cameras.try_start(&Clock::Monotonic) {
        // Nothing was recorded: the run's directory goes (removed only while empty).
        if let Err(cleanup) = std::fs::remove_dir(root) {
            tracing::debug!("cannot remove the run directory {root:?}: {cleanup}");
        }
        return Err(CameraUnusable {
            role,
            config: config.path.clone(),
            source,
        });
    }
    Ok(cameras)
}

/// Where a live run's poses and frames go: chunk after chunk under `root`.
struct ChunkSinks {
    chunks: Arc<Chunks>,
    live: Arc<Mutex<Live>>,
    gauges: Option<Arc<RecorderGauges>>,
    recorder: Option<Box<dyn FrameRecorder>>,
}

impl ChunkSinks {
    fn new(config: &Config, models: &Models, rig: Rig, root: &std::path::Path, cameras: &[SharedHealth]) -> Self {
        let notes = format!("recorded by `mousepose run` with rig config {:?}", config.path);
        let latency = config.color.as_ref().map(|_| config.sync.color_latency_ns);
        let chunks = Chunks::new(ChunkPlan {
            root: root.to_owned(),
            period: config.chunk,
            record: config.record,
            cameras: cameras.to_vec(),
            meta: chunk_meta(notes, config.calibration.as_ref().map(|_| rig), latency),
            body_model: models.body_path(),
            paw_model: models.paws_path(),
            models: Some(models.used()),
            mice: config.mice,
        });
        let gauges = config.record.then(|| Arc::new(RecorderGauges::default()));
        let recorder = gauges.as_ref().map(|gauges| {
            let disk = DiskWatch::new(root, config.min_free_bytes, config.min_free_share);
            Box::new(ChunkRecorder::new(
                Arc::clone(&chunks),
                disk,
                cameras.to_vec(),
                Arc::clone(gauges),
            )) as Box<dyn FrameRecorder>
        });
        Self {
            chunks,
            live: Arc::new(Mutex::new(Live::default())),
            gauges,
            recorder,
        }
    }
}

/// Runs the daemon until `stop` (a signal), `seconds`, or a failure of the pipeline itself;
/// `signals`, when given, are the process's (SIGHUP is answered, the stop signal named).
///
/// # Errors
/// The output directory cannot be made, or a pipeline component failed (the report is still
/// logged).
pub fn serve(
    config: &Config,
    models: Models,
    rig: Rig,
    segment: SegmentStage,
    seconds: Option<f64>,
    stop: &Shutdown,
    signals: Option<&Signals>,
) -> anyhow::Result<RunReport> {
    let listener = config.http.address.map(HttpServer::bind).transpose()?;
    let publisher = config.stream.as_ref().map(Publisher::start).transpose()?;
    let stream = publisher.as_ref().map(Publisher::handle);
    let outlet = (config.lsl.as_ref())
        .map(|c| LslOutlet::start(c, &project_python()))
        .transpose()?;
    let lsl = outlet.as_ref().map(LslOutlet::handle);
    crate::runtime::sink::left_open::close_chunks_left_open(&config.output_dir);
    let root = create_run_dir(&config.output_dir)?;
    tracing::info!(dir = ?root, record = config.record, "run started");
    let info = RunInfo {
        version: env!("CARGO_PKG_VERSION"),
        started_utc: crate::runtime::capture::clock::utc_now(),
        config: config.path.clone(),
        models: models.dir.clone(),
        paw_model: models.paws.is_some(),
        calibration: config.calibration.clone(),
    };
    let cameras = start_cameras(config, &root)?;
    // The cameras' states are taken from these, in this thread, whatever the capture threads
    // are doing.
    let (stall_watches, healths) = (cameras.stall_watches(), cameras.healths());
    let shared: Vec<SharedHealth> = healths.iter().map(|(_, h)| Arc::clone(h)).collect();
    let sinks = ChunkSinks::new(config, &models, rig, &root, &shared);
    let floor = FloorSlot::default();
    let topology = Topology {
        sources: cameras.into(),
        sync: config.sync,
        edges: Edges {
            capture: config.capture_edge,
            stage: config.stage_edge,
        },
        processing: Some(Processing {
            segment: segment.with_floor_slot(Arc::clone(&floor)),
            models,
            rig,
            workers: config.body_workers,
            overlays: None,
            poses: Box::new(ChunkPoses::new(Arc::clone(&sinks.chunks), Arc::clone(&sinks.live))),
            stream: stream.clone(),
            lsl: lsl.clone(),
        }),
        recorder: sinks.recorder,
    };
    let started = Instant::now();
    let running = topology.start()?;
    let shutdown = running.shutdown();
    let watch = Arc::new(Watch::new(Watched {
        dir: root,
        info,
        pipeline: running.watch(),
        cameras: healths.clone(),
        live: Arc::clone(&sinks.live),
        chunks: Arc::clone(&sinks.chunks),
        recorder: sinks.gauges.clone(),
        floor,
        stream: stream.clone(),
        lsl,
    }));
    let server = match listener.map(|l| HttpServer::start(l, config.http.token.clone(), Arc::clone(&watch), rig)) {
        Some(Err(e)) => {
            shutdown.request();
            drop(running.join());
            return Err(e.into());
        }
        Some(Ok(server)) => Some(server),
        None => None,
    };
    let lookout = Lookout {
        healths: &healths,
        stall_watches: &stall_watches,
        live: &sinks.live,
        watch: &watch,
        events: stream.map(|s| Mutex::new(StreamEvents::new(s, &sinks.chunks, sinks.gauges.as_deref()))),
    };
    lookout.wait_ready(stop);
    let until = seconds.map(|s| started + Duration::from_secs_f64(s));
    let last_line = lookout.keep_watch(stop, &shutdown, until, signals);
    notify(&[sd_notify::NotifyState::Stopping]);
    let why = match signals.and_then(Signals::caught) {
        Some(signal) => signal_name(signal),
        None if stop.requested() => "a signal".to_owned(),
        None if shutdown.requested() => "a failure of the pipeline".to_owned(),
        None => "the time given".to_owned(),
    };
    tracing::info!(last = %last_line, "stopping: {why}");
    shutdown.request();
    let finished = running.join();
    if let Some(recorder) = finished.recorder {
        if let Err(e) = recorder.finish() {
            tracing::error!("cannot close the last chunk's session: {e}");
        }
    }
    if let Some(server) = server {
        server.stop();
    }
    if let Some(publisher) = publisher {
        publisher.stop();
    }
    if let Some(outlet) = outlet {
        outlet.stop();
    }
    finished.outcome?;
    let report = watch.report();
    tracing::info!(poses = report.poses, chunks = report.chunks, "run ended");
    Ok(report)
}

/// What the daemon runs.
#[derive(Clone, Debug)]
pub struct DaemonOptions {
    /// The rig configuration file.
    pub config: PathBuf,
    /// Stop after this many seconds (a daemon runs until SIGTERM).
    pub seconds: Option<f64>,
    /// A session recorded with the cage empty, as the background reference (instead of the
    /// config's `[segment] background`).
    pub background: Option<PathBuf>,
    /// A models directory (an adapted one: `mousepose adapt`) instead of the config's
    /// `[models] dir`.
    pub models: Option<PathBuf>,
}

/// Loads the configuration, the models, the rig and the background, then runs the daemon
/// until a stop signal (SIGTERM, SIGINT, ...: [`crate::engine::stop_signals`]) or `seconds`.
/// Returns its report and, when a signal other than SIGTERM or SIGINT stopped it, the
/// sentence that says so (the run then fails, after its report).
///
/// # Errors
/// The configuration, models, rig or background cannot be used (the user's), or the run
/// failed.
pub fn daemon(options: &DaemonOptions) -> Result<(RunReport, Option<String>), Failure> {
    let mut config = Config::load(&options.config).map_err(Failure::usage)?;
    if let Some(dir) = &options.background {
        config.background = Some(dir.clone());
    }
    if let Some(dir) = &options.models {
        config.models_dir = Some(dir.clone());
    }
    let models = Models::load(config.models_dir.as_deref()).map_err(Failure::usage)?;
    let rig = live_rig(&config).map_err(Failure::usage)?;
    let segment = segment_stage(&config, &rig).map_err(Failure::usage)?;
    let stop = Shutdown::default();
    let signals = Signals::install(&stop, false).context("installing the signal handlers")?;
    let report = serve(&config, models, rig, segment, options.seconds, &stop, Some(&signals)).map_err(|e| {
        let bad_endpoint = e
            .downcast_ref::<StreamError>()
            .is_some_and(|s| matches!(s, StreamError::Bind { .. }));
        Failure::classed(e.is::<CameraUnusable>() || bad_endpoint || e.is::<LslStartError>(), e)
    })?;
    Ok((report, signals.unexpected_stop()))
}
