//! `mousepose replay`: a recorded or synthetic session through the same pipeline the daemon
//! runs, with the cameras swapped for the session reader.
//!
//! ```text
//!  replay (session reader, both cameras in host order) ─Captured─▶ sync ─FramePair─▶ segment
//!      ─Segmented─▶ body (one worker per core) ─Posed─▶ paws (one worker per core)
//!      ─Posed─▶ fuse (frames in order) ─Fused─▶ poses (poses.csv, overlays, in order)
//! ```
//!
//! Every frame is accounted for: per camera, captured = paired + unpaired + dropped (by
//! reason); frames lost before capture (gaps in the camera's sequence numbers, records that
//! do not decode) are counted apart. `summary.json` holds those counts, the per-stage latency,
//! the throughput and, for synthetic sessions, the error against the ground truth.

use crate::core::frame::DepthFrame;
use crate::core::geometry::Rig;
use crate::io::output::{OutputError, Staging};
use crate::io::session::{CameraRole, SessionError, SessionReader, SessionSource};
use crate::runtime::capture::moseq::{MoseqConfig, MoseqDepth};
use crate::runtime::capture::session::SessionPlayer;
use crate::runtime::capture::{Captured, Clock, FrameSource, SeqGaps};
use crate::runtime::pipeline::{
    EdgeConfig, EdgeSender, EdgeStats, Histogram, LatencySummary, PipelineError, Runner, Sent, Shutdown, StageError,
    StageReport, Tracked, edge,
};
use crate::runtime::sink::poses::{PoseTally, PoseWriter};
use crate::runtime::stages::body::{BodyStage, PIPELINE_VOTE_BUDGET};
use crate::runtime::stages::fuse::FuseStage;
use crate::runtime::stages::paws::PawStage;
use crate::runtime::stages::segment::SegmentStage;
use crate::runtime::sync::{Role, SyncConfig, SyncOutput, Synchronizer};
use crate::vision::forest::infer::{BodyEstimator, VoteSettings};
use crate::vision::forest::model::{self, Model, ModelError, ModelKind};
use crate::vision::fusion::{Fuser, FusionConfig};
use crate::vision::paws::PawDetector;
use crate::vision::segment::{Background, SegmentError, SegmenterConfig};
use crossbeam_channel::Receiver;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// The file with the run's summary.
pub const SUMMARY_FILE: &str = "summary.json";
/// The body forest's file name in a models directory.
pub const BODY_MODEL: &str = "body.forest";
/// The paw cascade's file name in a models directory.
pub const PAWS_MODEL: &str = "paws.xml";

/// What to replay and how.
#[derive(Clone, Debug)]
pub struct ReplayOptions {
    pub session: PathBuf,
    pub out: PathBuf,
    /// The models directory; `None`: the bundled defaults (see [`default_models_dir`]).
    pub models: Option<PathBuf>,
    pub realtime: bool,
    /// Body-forest workers; 0: one per core.
    pub workers: usize,
    /// Draw every n-th frame (by depth sequence number) into `overlays/`.
    pub overlays: Option<u64>,
    /// A rig calibration to use instead of the one the session carries.
    pub calibration: Option<PathBuf>,
    pub force: bool,
}

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("cannot open the session")]
    Session(#[from] SessionError),
    #[error("the session {0:?} has no depth frames")]
    Empty(PathBuf),
    #[error("no models directory given and no bundled models found (looked in {0})")]
    NoModels(String),
    #[error("cannot load the model {path:?}")]
    Model {
        path: PathBuf,
        #[source]
        source: ModelError,
    },
    #[error("cannot load the paw cascade")]
    PawModel(#[source] crate::vision::paws::PawError),
    #[error(transparent)]
    Calibration(#[from] crate::vision::calibrate::CalibrationError),
    #[error("cannot read the MoSeq recording")]
    Moseq(#[source] crate::runtime::capture::CaptureError),
    #[error("cannot model the empty cage from the session's depth frames")]
    Background(#[source] SegmentError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("cannot write {path:?}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start the pipeline's threads")]
    Threads(#[source] std::io::Error),
    #[error("the pipeline stopped")]
    Pipeline(#[from] PipelineError),
}

/// Where the bundled models are: `$MOUSEPOSE_MODELS`, then beside an installed binary
/// (`<prefix>/share/mousepose/models`), then the source checkout the binary was built from.
pub fn default_models_dir() -> Result<PathBuf, ReplayError> {
    let mut candidates = Vec::new();
    if let Some(dir) = std::env::var_os("MOUSEPOSE_MODELS") {
        candidates.push(PathBuf::from(dir));
    }
    if let Ok(exe) = std::env::current_exe() {
        if let Some(prefix) = exe.parent().and_then(Path::parent) {
            candidates.push(prefix.join("share/mousepose/models"));
        }
    }
    candidates.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models"));
    candidates
        .iter()
        .find(|d| d.join(BODY_MODEL).is_file())
        .cloned()
        .ok_or_else(|| {
            ReplayError::NoModels(
                candidates
                    .iter()
                    .map(|d| format!("{d:?}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            )
        })
}

/// Loads the body forest of a models directory.
///
/// # Errors
/// The file is missing, damaged, or not a body forest.
pub fn load_body(models: &Path) -> Result<BodyEstimator, ReplayError> {
    let path = models.join(BODY_MODEL);
    match model::load(&path, Some(ModelKind::Body)) {
        Ok(Model::Body(_, forest)) => Ok(BodyEstimator::new(forest, VoteSettings::default())),
        Ok(Model::Parts(..)) => Err(ReplayError::Model {
            source: ModelError::WrongKind {
                path: path.clone(),
                found: "parts",
                expected: "body",
            },
            path,
        }),
        Err(source) => Err(ReplayError::Model { path, source }),
    }
}

/// Loads the paw cascade of a models directory; `None` when the directory has none, so that
/// older model directories still work (the limbs then take their default configuration, and
/// the summary's `paw_model` is empty).
///
/// # Errors
/// The file is there but is not a cascade we can run.
pub fn load_paws(models: &Path) -> Result<Option<PawDetector>, ReplayError> {
    let path = models.join(PAWS_MODEL);
    if !path.exists() {
        return Ok(None);
    }
    PawDetector::load(&path).map(Some).map_err(ReplayError::PawModel)
}

/// Frames per camera, by what became of them.
#[derive(Debug, Default)]
pub struct CameraCounters {
    /// Frames the source delivered.
    pub captured: AtomicU64,
    /// In a pair with a frame of the other camera.
    pub paired: AtomicU64,
    /// Processed without a partner (depth-only pairs; colour frames no depth frame claimed).
    pub unpaired: AtomicU64,
    /// Delivered but not processed, by reason.
    pub dropped: Mutex<BTreeMap<String, u64>>,
    /// Never delivered, by reason (`camera_gap`: missing sequence numbers; the source's own
    /// losses such as damaged buffers or records).
    pub lost: Mutex<BTreeMap<String, u64>>,
}

fn bump(map: &Mutex<BTreeMap<String, u64>>, reason: &str, n: u64) {
    if n > 0 {
        *map.lock()
            .unwrap_or_else(PoisonError::into_inner)
            .entry(reason.to_owned())
            .or_default() += n;
    }
}

/// Both cameras' counters.
#[derive(Debug, Default)]
pub struct Accounting {
    pub depth: CameraCounters,
    pub color: CameraCounters,
}

impl Accounting {
    pub fn camera(&self, role: CameraRole) -> &CameraCounters {
        match role {
            CameraRole::Depth => &self.depth,
            CameraRole::Color => &self.color,
        }
    }
}

fn role_of(c: &Captured) -> CameraRole {
    match c {
        Captured::Depth(_) => CameraRole::Depth,
        Captured::Color(_) => CameraRole::Color,
    }
}

/// The body of a capture thread: runs `source` until it ends, fails or `shutdown` is
/// requested, sending each frame (as `wrap` makes it) to `tx` and counting what happens to it.
///
/// # Errors
/// The source failed to start, deliver or stop.
pub fn run_source<S: FrameSource>(
    mut source: S,
    clock: &Clock,
    wrap: fn(S::Frame) -> Captured,
    tx: &EdgeSender<Captured>,
    acct: &Accounting,
    shutdown: &Shutdown,
) -> Result<(), StageError> {
    let own_role = source.meta().role;
    source.start(clock)?;
    let mut gaps = [SeqGaps::default(); 2];
    while !shutdown.requested() && !source.finished() {
        let Some(frame) = source.next_frame(Duration::from_millis(100))? else {
            continue;
        };
        let frame = wrap(frame);
        let role = role_of(&frame);
        let counters = acct.camera(role);
        counters.captured.fetch_add(1, Ordering::Relaxed);
        let seq = crate::runtime::capture::Stamped::stamp(&frame).seq;
        let slot = usize::from(role == CameraRole::Color);
        bump(&counters.lost, "camera_gap", gaps[slot].observe(seq));
        match tx.send(frame) {
            Sent::Delivered => {}
            Sent::DroppedFull => bump(&counters.dropped, "queue_full", 1),
            Sent::Closed => break,
        }
    }
    for (reason, n) in source.losses() {
        let (role, reason) = match reason.split_once('_') {
            Some(("depth", r)) => (CameraRole::Depth, r),
            Some(("color", r)) => (CameraRole::Color, r),
            _ => (own_role, reason),
        };
        bump(&acct.camera(role).lost, reason, n);
    }
    source.stop()?;
    Ok(())
}

/// The body of the sync thread: pairs what arrives on `rx` and sends the pairs on, numbered.
///
/// # Errors
/// Never, today; the signature leaves room for a synchroniser that can fail.
pub fn run_sync(
    config: SyncConfig,
    rx: &Receiver<Captured>,
    tx: &EdgeSender<Tracked<crate::core::frame::FramePair>>,
    acct: &Accounting,
) -> Result<(), StageError> {
    let mut sync = Synchronizer::new(config);
    let mut out = Vec::new();
    let mut index = 0u64;
    let mut emit = |out: &mut Vec<SyncOutput>| -> bool {
        for o in out.drain(..) {
            match o {
                SyncOutput::Pair(pair) => {
                    if pair.color.is_some() {
                        acct.depth.paired.fetch_add(1, Ordering::Relaxed);
                        acct.color.paired.fetch_add(1, Ordering::Relaxed);
                    } else {
                        acct.depth.unpaired.fetch_add(1, Ordering::Relaxed);
                    }
                    if tx.send(Tracked::new(index, pair)) == Sent::Closed {
                        return false;
                    }
                    index += 1;
                }
                SyncOutput::UnpairedColor(_) => {
                    acct.color.unpaired.fetch_add(1, Ordering::Relaxed);
                }
                SyncOutput::Rejected { role, reason, .. } => {
                    let counters = match role {
                        Role::Depth => &acct.depth,
                        Role::Color => &acct.color,
                    };
                    bump(&counters.dropped, reason.name(), 1);
                }
            }
        }
        true
    };
    for captured in rx.iter() {
        match captured {
            Captured::Depth(f) => sync.push_depth(f, &mut out),
            Captured::Color(f) => sync.push_color(f, &mut out),
        }
        if !emit(&mut out) {
            return Ok(());
        }
    }
    sync.flush(&mut out);
    emit(&mut out);
    Ok(())
}

/// One camera in the summary. `captured = paired + unpaired + dropped_total`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CameraSummary {
    pub captured: u64,
    pub paired: u64,
    pub unpaired: u64,
    pub dropped: BTreeMap<String, u64>,
    pub dropped_total: u64,
    pub lost_before_capture: BTreeMap<String, u64>,
}

impl CameraSummary {
    pub fn of(c: &CameraCounters) -> Self {
        let dropped = c.dropped.lock().unwrap_or_else(PoisonError::into_inner).clone();
        Self {
            captured: c.captured.load(Ordering::Relaxed),
            paired: c.paired.load(Ordering::Relaxed),
            unpaired: c.unpaired.load(Ordering::Relaxed),
            dropped_total: dropped.values().sum(),
            dropped,
            lost_before_capture: c.lost.lock().unwrap_or_else(PoisonError::into_inner).clone(),
        }
    }

    /// Whether every captured frame is accounted for.
    pub fn adds_up(&self) -> bool {
        self.captured == self.paired + self.unpaired + self.dropped_total
    }
}

/// An edge in the summary.
#[derive(Clone, Debug, Serialize)]
pub struct EdgeSummary {
    pub capacity: usize,
    pub max_depth: u64,
    pub dropped_full: u64,
}

fn edge_summary(config: EdgeConfig, stats: &EdgeStats) -> EdgeSummary {
    EdgeSummary {
        capacity: config.capacity.get(),
        max_depth: stats.max_depth.load(Ordering::Relaxed),
        dropped_full: stats.dropped_full.load(Ordering::Relaxed),
    }
}

/// How the pairs compare with a synthetic session's true pairs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct PairingCheck {
    pub truth_pairs: u64,
    pub matched: u64,
    pub mismatched: u64,
}

/// `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct ReplaySummary {
    pub session: PathBuf,
    pub software_version: &'static str,
    pub body_model: PathBuf,
    /// The paw cascade, when the models directory has one.
    pub paw_model: Option<PathBuf>,
    pub realtime: bool,
    pub pairs: u64,
    pub statuses: BTreeMap<&'static str, u64>,
    pub elapsed_s: f64,
    pub throughput_pairs_per_s: f64,
    pub cameras: BTreeMap<&'static str, CameraSummary>,
    pub stages: Vec<StageReport>,
    /// From a pair leaving the synchroniser to its row written.
    pub end_to_end_latency: LatencySummary,
    pub edges: BTreeMap<&'static str, EdgeSummary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pairing: Option<PairingCheck>,
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub per_joint_error_mm: BTreeMap<&'static str, f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_error_mm: Option<f64>,
    /// Mean error per group of joints (`body` 1-12, `limbs` 13-20, `paws` 21-24) and of the
    /// paws the bottom camera found (`detected_paws`).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub group_error_mm: BTreeMap<&'static str, f64>,
}

/// The picture of one frame with its skeleton.
pub const PICTURE_FILE: &str = "frame.png";

/// The picture of the frame pair of `pose` (see [`crate::runtime::overlay`]); `None` when its frames
/// cannot be read again.
fn picture(
    input: &Input,
    rig: &Rig,
    pose: &crate::runtime::stages::PoseRecord,
) -> Option<crate::core::image::RgbImage> {
    let depth = input.depth_frame(pose.depth.seq)?;
    let color = pose.color.and_then(|c| input.color_frame(c.seq));
    Some(crate::runtime::overlay::draw(rig, &depth, color.as_ref(), pose))
}

/// Frames the background model is built from, spread over the session.
const BACKGROUND_FRAMES: usize = 31;

/// The empty cage: for a synthetic session the rendered empty cage; otherwise the per-pixel
/// median of frames spread over the session (a mouse that moves drops out of the median, as
/// in MoSeq's extraction).
fn background(input: &Input, rig: &Rig) -> Result<Background, ReplayError> {
    if input.depth_count() == 0 {
        return Err(ReplayError::Empty(match input {
            Input::Session(r) => r.dir().to_path_buf(),
            Input::Moseq { config, .. } => config.dir.clone(),
        }));
    }
    if let Input::Session(reader) = input {
        if reader.meta().source == SessionSource::Synthetic && reader.meta().rig.is_some() {
            // The generator's empty cage is known exactly: the reference a rig records before
            // the mouse goes in.
            let full = crate::core::image::Region::full(&rig.depth.intrinsics);
            let cage = crate::synth::render::Cage::new(&rig.depth).depth(full);
            return Background::from_depth(&cage, full, &rig.depth.intrinsics, &SegmenterConfig::default())
                .map_err(ReplayError::Background);
        }
    }
    let frames = input.sample_depth(BACKGROUND_FRAMES)?;
    let mut intrinsics = rig.depth.intrinsics;
    if let Some(f) = frames.first() {
        intrinsics.width = f.width;
        intrinsics.height = f.height;
    }
    Background::from_frames(&frames, &intrinsics, &SegmenterConfig::default()).map_err(ReplayError::Background)
}

/// Runs the replay and writes `poses.csv` and `summary.json` into `options.out`.
///
/// # Errors
/// See [`ReplayError`]; nothing is left at `options.out` on failure.
pub fn replay(options: &ReplayOptions) -> Result<ReplaySummary, ReplayError> {
    if is_moseq(&options.session) {
        let config = MoseqConfig::new(&options.session);
        let recording = Input::moseq(&config)?;
        let (size, count) = (recording.size(), recording.frame_count());
        return replay_input(options, &Input::Moseq { config, size, count });
    }
    replay_input(
        options,
        &Input::Session(Box::new(SessionReader::open(&options.session)?)),
    )
}

/// Whether `dir` holds a MoSeq-layout recording rather than a session.
fn is_moseq(dir: &Path) -> bool {
    !dir.join(crate::io::session::META_FILE).exists()
        && (dir.join("depth.dat").is_file() || dir.join("depth.avi").is_file())
}

/// What a replay reads.
enum Input {
    Session(Box<SessionReader>),
    /// A depth-only recording in MoSeq's layout, its frame size and number of frames.
    Moseq {
        config: MoseqConfig,
        size: (u32, u32),
        count: usize,
    },
}

impl Input {
    fn moseq(config: &MoseqConfig) -> Result<MoseqDepth, ReplayError> {
        MoseqDepth::open(config.clone()).map_err(ReplayError::Moseq)
    }

    /// The rig: the session's calibration, or the default rig (for MoSeq recordings with the
    /// intrinsics of their frame size: Kinect v2's for 512x424, the default's scaled otherwise).
    fn rig(&self) -> Rig {
        let mut rig = Rig::default_rig();
        match self {
            Input::Session(r) => r.meta().rig.unwrap_or(rig),
            &Input::Moseq { size: (w, h), .. } => {
                let i = &mut rig.depth.intrinsics;
                let f = if (w, h) == (512, 424) {
                    365.0
                } else {
                    i.fx * f64::from(w) / f64::from(i.width)
                };
                (i.width, i.height, i.fx, i.fy) = (w, h, f, f);
                (i.cx, i.cy) = (f64::from(w) / 2.0, f64::from(h) / 2.0);
                rig
            }
        }
    }

    /// The rig of a calibration file, refused when it was made for other cameras than the
    /// input's (their image sizes, and serials when both are known).
    fn calibrated_rig(&self, path: &Path) -> Result<Rig, ReplayError> {
        let calibration = crate::vision::calibrate::RigCalibration::load(path)?;
        match self {
            Input::Session(r) => calibration.check_matches(r.meta())?,
            &Input::Moseq { size: (w, h), .. } => {
                calibration.check_camera(CameraRole::Depth, w, h, None, "the MoSeq recording")?;
            }
        }
        Ok(calibration.rig())
    }

    fn depth_count(&self) -> usize {
        match self {
            Input::Session(r) => r.depth_count(),
            Input::Moseq { count, .. } => *count,
        }
    }

    /// Up to `n` depth frames spread over the session (MoSeq: over its first frames).
    fn sample_depth(&self, n: usize) -> Result<Vec<DepthFrame>, ReplayError> {
        let count = self.depth_count();
        let picks = n.min(count);
        match self {
            Input::Session(r) => Ok((0..picks)
                .filter_map(|k| r.depth_frame(k * count / picks).ok())
                .collect()),
            Input::Moseq { config: c, .. } => {
                // One frame in ten of the first ones: a pass over the whole file would cost a
                // full decode of a long video.
                let mut source = Self::moseq(c)?;
                source.start(&Clock::replay(0)).map_err(ReplayError::Moseq)?;
                let mut frames = Vec::new();
                let mut k = 0usize;
                while frames.len() < picks && k < count && !source.finished() {
                    if let Some(f) = source.next_frame(Duration::from_secs(5)).map_err(ReplayError::Moseq)? {
                        if k % 10 == 0 {
                            frames.push(f);
                        }
                        k += 1;
                    }
                }
                source.stop().map_err(ReplayError::Moseq)?;
                Ok(frames)
            }
        }
    }

    /// The colour frame with sequence number `seq` (sessions only).
    fn color_frame(&self, seq: u64) -> Option<crate::core::frame::ColorFrame> {
        match self {
            Input::Session(r) => {
                let index = r.seqs(CameraRole::Color).iter().position(|&s| s == seq)?;
                r.color_frame(index).ok()
            }
            Input::Moseq { .. } => None,
        }
    }

    /// The depth frame with sequence number `seq`.
    fn depth_frame(&self, seq: u64) -> Option<DepthFrame> {
        match self {
            Input::Session(r) => {
                let index = r.seqs(CameraRole::Depth).iter().position(|&s| s == seq)?;
                r.depth_frame(index).ok()
            }
            Input::Moseq { config: c, .. } => {
                let mut source = Self::moseq(c).ok()?;
                source.start(&Clock::replay(0)).ok()?;
                while !source.finished() {
                    if let Some(f) = source.next_frame(Duration::from_secs(5)).ok()? {
                        if f.stamp.seq >= seq {
                            let _ = source.stop();
                            return (f.stamp.seq == seq).then_some(f);
                        }
                    }
                }
                None
            }
        }
    }
}

fn replay_input(options: &ReplayOptions, input: &Input) -> Result<ReplaySummary, ReplayError> {
    let models = match &options.models {
        Some(dir) => dir.clone(),
        None => default_models_dir()?,
    };
    let estimator = load_body(&models)?;
    let paws = load_paws(&models)?;
    let rig = match &options.calibration {
        Some(path) => input.calibrated_rig(path)?,
        None => input.rig(),
    };
    let background = background(input, &rig)?;
    let segmenter = SegmenterConfig::default()
        .build(background)
        .map_err(ReplayError::Background)?
        .with_world(rig.depth.world_from_camera);
    let truth = match input {
        Input::Session(reader) => reader.truth()?,
        Input::Moseq { .. } => None,
    };
    let staging = Staging::new(&options.out, options.force)?;
    let truth_joints: HashMap<u64, _> = truth
        .as_ref()
        .map(|t| t.joints.iter().map(|(seq, _, j)| (*seq, *j)).collect())
        .unwrap_or_default();
    let writer =
        PoseWriter::create(staging.path(), truth_joints, input.depth_count() as u64 / 2).map_err(|source| {
            ReplayError::Write {
                path: staging.path().join(crate::runtime::sink::poses::POSES_FILE),
                source,
            }
        })?;
    let tally = writer.tally();

    let workers = match options.workers {
        0 => std::thread::available_parallelism().map_or(1, usize::from),
        n => n,
    };
    let capture_edge = EdgeConfig::block(64);
    let stage_edge = EdgeConfig::block(8);
    let (cap_tx, cap_rx, cap_stats) = edge::<Captured>(capture_edge);
    let (pair_tx, pair_rx, pair_stats) = edge(stage_edge);
    let (seg_tx, seg_rx, seg_stats) = edge(stage_edge);
    let (body_tx, body_rx, body_stats) = edge(stage_edge);
    let (paws_tx, paws_rx, paws_stats) = edge(stage_edge);
    let (pose_tx, pose_rx, pose_stats) = edge(stage_edge);
    let acct = Arc::new(Accounting::default());
    let end_to_end = Arc::new(Histogram::default());
    let sync_config = match input {
        Input::Session(r) => SyncConfig {
            color: r.meta().camera(CameraRole::Color).is_some(),
            color_latency_ns: r.meta().color_latency_ns.unwrap_or(0),
            ..SyncConfig::default()
        },
        Input::Moseq { .. } => SyncConfig {
            color: false,
            ..SyncConfig::default()
        },
    };

    let mut runner = Runner::new();
    let start = Instant::now();
    let clock = Clock::replay(0);
    let (acct_src, shutdown) = (Arc::clone(&acct), runner.shutdown());
    let threads = ReplayError::Threads;
    match input {
        Input::Session(reader) => {
            let source = SessionPlayer::new(reader, options.realtime);
            runner.spawn("replay", move || {
                run_source(source, &clock, |c| c, &cap_tx, &acct_src, &shutdown)
            })
        }
        Input::Moseq { config, .. } => {
            let source = Input::moseq(config)?;
            runner.spawn("replay", move || {
                run_source(source, &clock, Captured::Depth, &cap_tx, &acct_src, &shutdown)
            })
        }
    }
    .map_err(threads)?;
    let acct_sync = Arc::clone(&acct);
    runner
        .spawn("sync", move || run_sync(sync_config, &cap_rx, &pair_tx, &acct_sync))
        .map_err(threads)?;
    runner
        .stage("segment", vec![SegmentStage::new(segmenter)], &pair_rx, &seg_tx)
        .map_err(threads)?;
    drop((pair_rx, seg_tx));
    let body = BodyStage::new(estimator, rig.depth, PIPELINE_VOTE_BUDGET);
    runner
        .stage("body", vec![body; workers], &seg_rx, &body_tx)
        .map_err(threads)?;
    drop((seg_rx, body_tx));
    let paw_model = paws.is_some().then(|| models.join(PAWS_MODEL));
    let paw_stage = PawStage::new(paws, rig.color);
    runner
        .stage("paws", vec![paw_stage; workers], &body_rx, &paws_tx)
        .map_err(threads)?;
    drop((body_rx, paws_tx));
    let fuse = FuseStage::new(Fuser::new(rig.color, FusionConfig::default()), rig, options.overlays);
    runner
        .stage_in_order("fuse", fuse, &paws_rx, &pose_tx)
        .map_err(threads)?;
    drop((paws_rx, pose_tx));
    runner
        .sink("poses", writer, pose_rx, Arc::clone(&end_to_end))
        .map_err(threads)?;
    let stages = runner.join()?;
    let elapsed_s = start.elapsed().as_secs_f64();

    let tally: PoseTally = tally.lock().unwrap_or_else(PoisonError::into_inner).clone();
    let mut cameras = BTreeMap::new();
    cameras.insert("depth", CameraSummary::of(&acct.depth));
    if sync_config.color {
        cameras.insert("color", CameraSummary::of(&acct.color));
    }
    let pairing = truth.as_ref().map(|t| {
        let ours: HashMap<u64, Option<u64>> = tally.pairs.iter().copied().collect();
        let matched = t.pairs.iter().filter(|(d, c)| ours.get(d) == Some(c)).count() as u64;
        PairingCheck {
            truth_pairs: t.pairs.len() as u64,
            matched,
            mismatched: t.pairs.len() as u64 - matched,
        }
    });
    let edges = BTreeMap::from([
        ("capture", edge_summary(capture_edge, &cap_stats)),
        ("sync->segment", edge_summary(stage_edge, &pair_stats)),
        ("segment->body", edge_summary(stage_edge, &seg_stats)),
        ("body->paws", edge_summary(stage_edge, &body_stats)),
        ("paws->fuse", edge_summary(stage_edge, &paws_stats)),
        ("fuse->poses", edge_summary(stage_edge, &pose_stats)),
    ]);
    let summary = ReplaySummary {
        session: options.session.clone(),
        software_version: env!("CARGO_PKG_VERSION"),
        body_model: models.join(BODY_MODEL),
        paw_model,
        realtime: options.realtime,
        pairs: tally.rows,
        statuses: tally.statuses.clone(),
        elapsed_s,
        throughput_pairs_per_s: tally.rows as f64 / elapsed_s.max(1e-9),
        cameras,
        stages,
        end_to_end_latency: end_to_end.summary(),
        edges,
        pairing,
        per_joint_error_mm: tally.per_joint_error_mm(),
        mean_error_mm: tally.mean_error_mm(),
        group_error_mm: tally.group_error_mm(),
    };
    if let Some(pose) = &tally.snapshot {
        let path = staging.path().join(PICTURE_FILE);
        picture(input, &rig, pose)
            .and_then(|img| img.write_png(&path).ok())
            .ok_or_else(|| ReplayError::Write {
                path: path.clone(),
                source: std::io::Error::other("cannot draw or write the picture"),
            })?;
    }
    let path = staging.path().join(SUMMARY_FILE);
    let json = serde_json::to_vec_pretty(&summary).map_err(std::io::Error::from);
    json.and_then(|j| std::fs::write(&path, j))
        .map_err(|source| ReplayError::Write { path, source })?;
    staging.commit()?;
    Ok(summary)
}
