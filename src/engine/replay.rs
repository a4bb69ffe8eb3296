//! `mousepose replay`: a recorded or synthetic session (or a MoSeq recording) through the same
//! pipeline the daemon runs, with the cameras swapped for the recording's reader.
//!
//! Every frame is accounted for: per camera, captured = paired + unpaired + dropped (by
//! reason); frames lost before capture (gaps in the camera's sequence numbers, records that
//! do not decode) are counted apart. `summary.json` holds those counts, the per-stage latency,
//! the throughput and, for synthetic sessions, the error against the ground truth.

use crate::core::frame::DepthFrame;
use crate::core::geometry::Rig;
use crate::core::image::RgbImage;
use crate::core::pose::JointPositions;
use crate::engine::{Interrupt, project_python};
use crate::io::mask::{MaskError, read_mask_png};
use crate::io::output::{OutputError, Staging};
use crate::io::session::SessionSource;
use crate::runtime::accounting::{CameraSummary, EdgeSummary};
use crate::runtime::models::{Models, ModelsError};
use crate::runtime::pipeline::{LatencySummary, PipelineError, StageReport};
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crate::runtime::recording::{Recording, RecordingError, RecordingRig};
use crate::runtime::sink::poses::{POSES_FILE, PoseTally, PoseWriter};
use crate::runtime::stages::segment::SegmentStage;
use crate::runtime::stream::lsl::{LslConfig, LslOutlet, LslStartError, LslSummary};
use crate::runtime::stream::{Publisher, StreamConfig, StreamError, StreamSummary};
use crate::runtime::topology::{Edges, Finished, Processing, Sources, Topology, TopologyError};
use crate::vision::segment::{ArenaCheck, Background, SegmentError, Segmenter, SegmenterConfig};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::{Mutex, PoisonError};

/// The file with the run's summary.
pub const SUMMARY_FILE: &str = "summary.json";
/// The picture of one frame with its skeleton.
pub const PICTURE_FILE: &str = "frame.png";

/// What to replay and how.
#[derive(Clone, Debug)]
pub struct ReplayOptions {
    pub session: PathBuf,
    pub out: PathBuf,
    /// The models directory; `None`: the bundled defaults.
    pub models: Option<PathBuf>,
    pub realtime: bool,
    /// Body-forest workers; 0: one per core.
    pub workers: usize,
    /// Draw every n-th frame (by depth sequence number) into `overlays/`.
    pub overlays: Option<u64>,
    /// A rig calibration to use instead of the one the session carries.
    pub calibration: Option<PathBuf>,
    /// The depth camera's intrinsics (as `calibrate intrinsics` writes) for a recording
    /// without a rig calibration, instead of the camera table's.
    pub intrinsics: Option<PathBuf>,
    /// A PNG mask of the arena (non-black = inside), instead of the arena found automatically.
    pub roi: Option<PathBuf>,
    pub force: bool,
    /// Publish each pose on this live stream as it is made (`--stream`).
    pub stream: Option<StreamConfig>,
    /// Offer each pose as this LSL stream as it is made (`--lsl`).
    pub lsl: Option<LslConfig>,
    /// Also write `poses_predicted.csv`: each pose predicted this long (ns) after its depth
    /// frame (`--lead`).
    pub lead_ns: Option<u64>,
    /// Pair as a live run with `[sync] partner_wait_ms` (and `partner_reach_ms`) does, from
    /// the recorded arrival stamps: the wait and the reach (ns; `--partner-wait`,
    /// `--partner-reach`). `None`: each depth frame with its nearest partner.
    pub partner_wait: Option<(u64, Option<u64>)>,
    /// How many mice share the cage (`--mice`, 1 to [`crate::vision::identity::MOST_MICE`]).
    pub mice: usize,
}

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error("the session {0:?} has no depth frames")]
    Empty(PathBuf),
    #[error(transparent)]
    Models(#[from] ModelsError),
    #[error("cannot model the empty cage from the session's depth frames")]
    Background(#[source] SegmentError),
    #[error(transparent)]
    Mask(#[from] MaskError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("cannot write {path:?}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Start(#[from] TopologyError),
    #[error("the pipeline stopped")]
    Pipeline(#[from] PipelineError),
    #[error("stopped by a signal before the end: nothing was written")]
    Interrupted,
    #[error("cannot install the signal handlers")]
    Signals(#[source] std::io::Error),
    #[error(transparent)]
    Stream(#[from] StreamError),
    #[error(transparent)]
    Lsl(#[from] LslStartError),
}

impl ReplayError {
    /// Whether what the user asked for is what cannot work (an output directory in the way,
    /// a recording or mask that is not one), not the work itself.
    pub fn is_usage(&self) -> bool {
        match self {
            Self::Output(OutputError::NotEmpty(_) | OutputError::NotADirectory(_)) => true,
            Self::Recording(r) => r.is_input_problem(),
            Self::Mask(_) | Self::Stream(StreamError::Bind { .. }) | Self::Lsl(_) => true,
            _ => false,
        }
    }
}

/// How the pairs compare with a synthetic session's true pairs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct PairingCheck {
    pub truth_pairs: u64,
    pub matched: u64,
    pub mismatched: u64,
}

/// The world frame a replay used and the depth camera in it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WorldSummary {
    /// `calibration` (the rig calibration's world frame) or `floor` (z up from the floor
    /// fitted to the recording, origin under the image centre).
    pub frame: &'static str,
    /// The depth camera's height above the fitted floor (mm) and its tilt from looking
    /// straight down (degrees).
    pub camera_height_mm: f64,
    pub camera_tilt_deg: f64,
    /// Where the depth intrinsics come from, and their focal length and centre (px).
    pub intrinsics_from: String,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// The depth camera's pose in this world frame: the 4x4 matrix taking a point of the
    /// camera's frame (mm) to the world's, row by row, to project joints back into the depth
    /// image.
    pub world_from_camera: [[f64; 4]; 4],
    /// The arena's share of the depth image, and whether it was given (`--roi`) or found.
    pub arena_share: f64,
    pub arena_from: &'static str,
    /// Of the depth frames sampled for the background, how many showed something of a
    /// mouse's size inside the arena and outside it; absent when the background is a
    /// synthetic session's rendered cage.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arena_check: Option<ArenaCheck>,
    /// The arena's floor in this world frame: the rectangle that holds all but the outermost
    /// 0.5 % of the floor points it sees on each side, mm (what `report` takes as the cage).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arena_mm: Option<crate::vision::behaviour::Arena>,
    /// The same floor's own outline (a round arena is round), which `report` zones by.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arena_outline_mm: Option<crate::vision::behaviour::Outline>,
}

/// Floor points of the background lie within this of the world's z = 0, mm.
const FLOOR_BAND_MM: f64 = 15.0;

/// The rectangle of the floor that the arena's pixels (`mask` over `region` of the depth
/// image, non-zero inside) see, from the background's depth there (`depth`, 0 = no reading):
/// only the points on the floor (within [`FLOOR_BAND_MM`] of z = 0; walls and what stands on
/// the floor left out), each side at the 0.5th percentile of the points so that a few stray
/// pixels do not widen it; and the floor's own outline
/// ([`crate::vision::behaviour::Outline`]). `None` when no arena pixel sees the floor.
fn arena_on_floor(
    mask: &[u8],
    depth: &[f32],
    region: crate::core::image::Region,
    camera: &crate::core::geometry::Camera,
) -> Option<(
    crate::vision::behaviour::Arena,
    Option<crate::vision::behaviour::Outline>,
)> {
    let width = region.width.max(1);
    let mut points = Vec::new();
    for (k, (&m, &z)) in mask.iter().zip(depth).enumerate() {
        if m == 0 || z <= 0.0 {
            continue;
        }
        let (x, y) = (k as u32 % width, k as u32 / width);
        let pixel = nalgebra::Point2::new(f64::from(region.x0 + x), f64::from(region.y0 + y));
        let p = camera.world_from_camera * camera.intrinsics.unproject(&pixel, f64::from(z));
        if p.z.abs() <= FLOOR_BAND_MM {
            points.push(nalgebra::Point2::new(p.x, p.y));
        }
    }
    if points.is_empty() {
        return None;
    }
    let mut xs: Vec<f64> = points.iter().map(|p| p.x).collect();
    let mut ys: Vec<f64> = points.iter().map(|p| p.y).collect();
    xs.sort_by(f64::total_cmp);
    ys.sort_by(f64::total_cmp);
    let at = |v: &[f64], q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let rectangle = crate::vision::behaviour::Arena {
        x_min_mm: at(&xs, 0.005),
        y_min_mm: at(&ys, 0.005),
        x_max_mm: at(&xs, 0.995),
        y_max_mm: at(&ys, 0.995),
    };
    Some((rectangle, crate::vision::behaviour::Outline::of_points(&points)))
}

/// One of several mice in `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct MouseSummary {
    /// Its number (1..N).
    pub mouse: usize,
    /// Pairs it was found in.
    pub found: u64,
    /// Its mean error per group of joints against the true mouse nearest it in each frame,
    /// as the summary's own (`group_error_mm`), where there is truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub group_error_mm: Option<BTreeMap<&'static str, f64>>,
    /// How often the true mouse its number follows changed, where there is truth.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub identity_swaps: Option<u64>,
    /// Times it came into contact with another mouse (their nearest main-body joints within
    /// [`crate::vision::identity::CONTACT_MM`]).
    pub contacts: u64,
}

impl MouseSummary {
    /// Each mouse's figures from the pose writer's tally; `truth`: whether the recording has
    /// ground truth.
    fn of_tally(tally: &PoseTally, truth: bool) -> Vec<Self> {
        (tally.mice.iter().zip(1..))
            .map(|(m, mouse)| Self {
                mouse,
                found: m.rows.statuses.get(PoseStatus::Ok.name()).copied().unwrap_or(0),
                group_error_mm: truth.then(|| m.rows.group_error_mm()),
                identity_swaps: truth.then_some(m.identity_swaps),
                contacts: m.contacts,
            })
            .collect()
    }
}

/// A frame where two mice could have swapped numbers (the next best numbering, nearly as
/// good, would have).
#[derive(Clone, Debug, Serialize)]
pub struct PossibleSwap {
    pub depth_seq: u64,
    pub mice: [usize; 2],
}

impl PossibleSwap {
    /// The frames the pose writer found that could have swapped two mice.
    fn of_tally(tally: &PoseTally) -> Vec<Self> {
        (tally.possible_swaps.iter())
            .map(|&(depth_seq, a, b)| Self {
                depth_seq,
                mice: [a, b],
            })
            .collect()
    }
}

/// The writer of `poses.csv` (and the files beside it) in `staging`, for `options.mice` mice,
/// with the recording's `truth`.
fn pose_writer(
    options: &ReplayOptions,
    staging: &Staging,
    recording: &Recording,
    truth: Option<&crate::io::session::Truth>,
) -> Result<PoseWriter, ReplayError> {
    let truth_joints = truth.map(by_frame).unwrap_or_default();
    let snapshot_row = recording.depth_count() as u64 / 2;
    PoseWriter::create(staging.path(), truth_joints, snapshot_row, options.mice.max(1))
        .and_then(PoseWriter::with_raw_file)
        .and_then(|w| match options.lead_ns {
            Some(ns) => w.with_predicted_file(ns as f64 * 1e-9),
            None => Ok(w),
        })
        .map_err(|source| ReplayError::Write {
            path: staging.path().join(POSES_FILE),
            source,
        })
}

/// The true joints of each mouse by depth sequence number, mouse 1's first.
fn by_frame(truth: &crate::io::session::Truth) -> HashMap<u64, Vec<JointPositions>> {
    let mut frames: HashMap<u64, Vec<JointPositions>> = HashMap::new();
    for rows in std::iter::once(&truth.joints).chain(&truth.others) {
        for (seq, _, joints) in rows {
            frames.entry(*seq).or_default().push(*joints);
        }
    }
    frames
}

/// `summary.json`.
#[derive(Clone, Debug, Serialize)]
pub struct ReplaySummary {
    /// The session replayed (absolute, so that `export video` finds it from anywhere).
    pub session: PathBuf,
    /// The calibration used instead of the session's own (`--calibration`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<PathBuf>,
    pub software_version: &'static str,
    pub body_model: PathBuf,
    /// The paw cascade, when the models directory has one and the recording colour frames.
    pub paw_model: Option<PathBuf>,
    /// The orientation model (which end is the head from the body's shape), when the models
    /// directory has one.
    pub orientation_model: Option<PathBuf>,
    /// Which models made the poses: their directory and each file's hash.
    pub models: crate::runtime::models::ModelsUsed,
    pub realtime: bool,
    pub world: WorldSummary,
    /// Lines of a MoSeq `depth_ts.txt` repeating the timestamp before them: their frames are
    /// dropped (`time_out_of_order`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duplicate_timestamps: Option<usize>,
    pub pairs: u64,
    pub statuses: BTreeMap<&'static str, u64>,
    pub elapsed_s: f64,
    pub throughput_pairs_per_s: f64,
    pub cameras: BTreeMap<&'static str, CameraSummary>,
    pub stages: Vec<StageReport>,
    /// From a pair leaving the synchroniser to its row written.
    pub end_to_end_latency: LatencySummary,
    pub edges: BTreeMap<String, EdgeSummary>,
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
    /// Frames whose head and tail were swapped, against the truth: after the orientation
    /// tracker, by each frame's own evidence, and by the body forest alone.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation: Option<crate::runtime::sink::poses::OrientationCheck>,
    /// In how many frames with a mouse a tail was seen, on any recording (truth or not).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tails: Option<crate::runtime::sink::poses::TailsSeen>,
    /// With several mice (`--mice`), each one's own figures; absent with one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mice: Option<Vec<MouseSummary>>,
    /// With several mice, the frames where two of them could have swapped numbers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub possible_swaps: Option<Vec<PossibleSwap>>,
    /// With several mice, the pairs whose depth frame showed more mouse-sized things than
    /// mice (the largest were taken as the mice).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub more_mice_seen: Option<u64>,
    /// What the user should know about the replay (the arena missing the mouse), one
    /// sentence each; also printed on stderr.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// The picture written beside the results (`frame.png`); `None` when it could not be
    /// drawn or written, and then `picture_error` says why (the results are whole without it).
    pub picture: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub picture_error: Option<String>,
    /// The live stream (`--stream`): subscribers at the end, messages published, sent, dropped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stream: Option<StreamSummary>,
    /// The LSL outlet (`--lsl`): whether a reader was connected at the end, samples sent,
    /// dropped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lsl: Option<LslSummary>,
}

/// The picture of the frame pair of `pose` (see [`crate::runtime::overlay`]) with
/// the arena's outline; `None` when its frames cannot be read again.
fn picture(recording: &Recording, rig: &Rig, pose: &PoseRecord, arena: &[u8]) -> Option<RgbImage> {
    let depth = recording.depth_frame(pose.depth.seq)?;
    let color = pose.color.and_then(|c| recording.color_frame(c.seq));
    Some(crate::runtime::overlay::draw_in_arena(
        rig,
        &depth,
        color.as_ref(),
        pose,
        Some(arena),
    ))
}

/// The picture of a recording where no frame had a mouse: its first depth frame that reads
/// back and has the size of most frames, with the arena's outline, saying so, and saying when
/// something of a mouse's size moved outside the arena.
fn picture_without_mouse(recording: &Recording, rig: &Rig, arena: &[u8], outside: bool) -> Option<RgbImage> {
    let frames = recording.sample_depth(BACKGROUND_FRAMES).ok()?;
    let size = common_size(&frames)?;
    let depth = frames.iter().find(|f| (f.width, f.height) == size)?;
    let note = if outside {
        "no mouse found in any frame inside the arena (outlined), but a mouse-sized thing moved outside it: pass --roi"
    } else {
        "no mouse found in any frame (arena outlined)"
    };
    Some(crate::runtime::overlay::draw_note(rig, depth, note, Some(arena)))
}

/// The warnings of a replay: something of a mouse's size outside the arena as often as
/// inside it (or with no mouse found at all), and a recording in which no frame had a mouse.
fn arena_warnings(check: Option<&ArenaCheck>, from: &str, pairs: u64, found: u64) -> Vec<String> {
    let mut warnings = Vec::new();
    if let Some(c) = check
        && c.mouse_sized_outside > 0
        && (c.mouse_sized_outside >= c.mouse_sized_inside || found == 0)
    {
        warnings.push(format!(
            "something of a mouse's size moved outside the arena {from} in {} of {} sampled frames (inside it in {}): if the mouse is there, give the arena with --roi",
            c.mouse_sized_outside, c.sampled_frames, c.mouse_sized_inside
        ));
    }
    if pairs > 0 && found == 0 {
        warnings.push(format!(
            "no mouse found in any of {pairs} frames: if the mouse is in view, the arena {from} (outlined in {PICTURE_FILE}) may miss it; give it with --roi"
        ));
    }
    warnings
}

/// Frames the background model is built from, spread over the session.
const BACKGROUND_FRAMES: usize = 31;

/// The empty cage: for a synthetic session the rendered empty cage; otherwise the far
/// readings of each pixel over frames spread across the whole recording (see
/// [`Background::from_frames`]: a mouse that sits still for the first minutes drops out).
pub(crate) fn background(recording: &Recording, rig: &Rig) -> Result<Background, ReplayError> {
    background_in(recording, rig, None)
}

/// [`background`] with the arena given (a mask over the depth image, non-zero = inside): the
/// floor is fitted inside it.
fn background_in(recording: &Recording, rig: &Rig, arena: Option<&[u8]>) -> Result<Background, ReplayError> {
    if recording.depth_count() == 0 {
        return Err(ReplayError::Empty(recording.dir()));
    }
    if let Recording::Session(reader) = recording {
        if reader.meta().source == SessionSource::Synthetic && reader.meta().rig.is_some() {
            // The generator's empty cage is known exactly: the reference a rig records before
            // the mouse goes in.
            let full = crate::core::image::Region::full(&rig.depth.intrinsics);
            let cage = crate::synth::render::Cage::new(&rig.depth).depth(full);
            return Background::from_depth_in(&cage, full, &rig.depth.intrinsics, &SegmenterConfig::default(), arena)
                .map_err(ReplayError::Background);
        }
    }
    let mut frames = recording.sample_depth(BACKGROUND_FRAMES)?;
    // A frame of another size (a camera that changed its mode for a moment) is left out: the
    // model covers the size most frames have, and the replay skips the others.
    let mut intrinsics = rig.depth.intrinsics;
    if let Some((width, height)) = common_size(&frames) {
        frames.retain(|f| (f.width, f.height) == (width, height));
        intrinsics.width = width;
        intrinsics.height = height;
    }
    Background::from_frames_in(&frames, &intrinsics, &SegmenterConfig::default(), arena)
        .map_err(ReplayError::Background)
}

/// The size most of `frames` have (the earliest of them on a tie); `None` without frames.
fn common_size(frames: &[DepthFrame]) -> Option<(u32, u32)> {
    let mut counts: Vec<((u32, u32), usize)> = Vec::new();
    for f in frames {
        let size = (f.width, f.height);
        match counts.iter_mut().find(|(s, _)| *s == size) {
            Some((_, n)) => *n += 1,
            None => counts.push((size, 1)),
        }
    }
    // `max_by_key` keeps the last of equal counts: look from the end to keep the earliest.
    counts.iter().rev().max_by_key(|(_, n)| *n).map(|(s, _)| *s)
}

/// Runs the replay and writes `poses.csv` and `summary.json` into `options.out`.
///
/// # Errors
/// See [`ReplayError`]; nothing is left at `options.out` on failure.
pub fn replay(options: &ReplayOptions) -> Result<ReplaySummary, ReplayError> {
    replay_with(options, &Interrupt::default(), |_, _| {})
}

/// [`replay`], stopped early by `interrupt` (SIGINT, SIGTERM): then
/// [`ReplayError::Interrupted`], and nothing is left behind, not even the hidden staging
/// directory.
///
/// # Errors
/// See [`ReplayError`]; nothing is left at `options.out` on failure.
pub fn replay_until(options: &ReplayOptions, interrupt: &Interrupt) -> Result<ReplaySummary, ReplayError> {
    replay_with(options, interrupt, |_, _| {})
}

/// How often a replay reports its progress.
const PROGRESS_EVERY: std::time::Duration = std::time::Duration::from_millis(200);

/// [`replay_until`], calling `progress` with the rows written and the depth frames of the
/// recording every [`PROGRESS_EVERY`] while the pipeline runs (from a thread of its own), and
/// once at the end.
///
/// # Errors
/// See [`ReplayError`]; nothing is left at `options.out` on failure.
pub fn replay_with(
    options: &ReplayOptions,
    interrupt: &Interrupt,
    progress: impl Fn(u64, u64) + Sync,
) -> Result<ReplaySummary, ReplayError> {
    let recording = Recording::open(&options.session)?;
    let (models, models_used, chosen, background) = load_models_and_scene(options, &recording)?;
    let (body_model, paw_model, orientation_model) =
        (models.body_path(), models.paws_path(), models.orientation_path());
    let scene = Scene::place(options, chosen, background)?;
    let truth = recording.truth()?;
    let staging = Staging::new(&options.out, options.force)?;
    let mice = options.mice.max(1);
    let writer = pose_writer(options, &staging, &recording, truth.as_ref())?;
    let tally = writer.tally();
    let Scene {
        rig,
        world,
        arena,
        depth_size,
        segmenter,
    } = scene;
    let publisher = options.stream.as_ref().map(Publisher::start).transpose()?;
    let mut topology = replay_topology(&recording, options, depth_size, segmenter, models, rig, writer);
    let outlet = (options.lsl.as_ref())
        .map(|c| LslOutlet::start(c, &project_python()))
        .transpose()?;
    if let Some(p) = topology.processing.as_mut() {
        p.stream = publisher.as_ref().map(Publisher::handle);
        p.lsl = outlet.as_ref().map(LslOutlet::handle);
    }
    let finished = run_pipeline(topology, interrupt, &tally, recording.depth_count() as u64, &progress)?;
    // Stopped once what it queued is sent, so that its counts are final.
    let stream = publisher.map(|p| {
        let handle = p.handle();
        p.stop();
        handle.summary()
    });
    let lsl = outlet.map(|o| {
        let handle = o.handle();
        o.stop();
        handle.summary()
    });
    let stages = finished.outcome?;
    if interrupt.requested() {
        return Err(ReplayError::Interrupted);
    }

    let tally: PoseTally = tally.lock().unwrap_or_else(PoisonError::into_inner).clone();
    let pairing = truth.as_ref().map(|t| {
        let ours: HashMap<u64, Option<u64>> = tally.pairs.iter().copied().collect();
        let matched = t.pairs.iter().filter(|(d, c)| ours.get(d) == Some(c)).count() as u64;
        PairingCheck {
            truth_pairs: t.pairs.len() as u64,
            matched,
            mismatched: t.pairs.len() as u64 - matched,
        }
    });
    let summary = ReplaySummary {
        session: std::fs::canonicalize(&options.session).unwrap_or_else(|_| options.session.clone()),
        calibration: options
            .calibration
            .as_ref()
            .map(|c| std::fs::canonicalize(c).unwrap_or_else(|_| c.clone())),
        software_version: env!("CARGO_PKG_VERSION"),
        body_model,
        paw_model,
        orientation_model,
        models: models_used,
        realtime: options.realtime,
        world: world.clone(),
        duplicate_timestamps: recording.duplicate_timestamps(),
        pairs: tally.rows,
        statuses: tally.statuses.clone(),
        elapsed_s: finished.elapsed_s,
        throughput_pairs_per_s: tally.rows as f64 / finished.elapsed_s.max(1e-9),
        cameras: finished.cameras,
        stages,
        end_to_end_latency: finished.end_to_end_latency,
        edges: finished.edges,
        pairing,
        per_joint_error_mm: tally.per_joint_error_mm(),
        mean_error_mm: tally.mean_error_mm(),
        group_error_mm: tally.group_error_mm(),
        orientation: (tally.orientation.frames > 0).then_some(tally.orientation),
        tails: (tally.tails.frames > 0).then_some(tally.tails),
        mice: (mice > 1).then(|| MouseSummary::of_tally(&tally, truth.is_some())),
        possible_swaps: (mice > 1).then(|| PossibleSwap::of_tally(&tally)),
        more_mice_seen: (mice > 1).then_some(tally.more_mice_seen),
        warnings: arena_warnings(
            world.arena_check.as_ref(),
            if options.roi.is_some() { "given" } else { "found" },
            tally.rows,
            tally.statuses.get("ok").copied().unwrap_or(0),
        ),
        picture: None,
        picture_error: None,
        stream,
        lsl,
    };
    for warning in &summary.warnings {
        tracing::warn!(message = "The arena may miss the mouse.", detail = %warning);
    }
    let summary = with_picture(summary, &staging, &recording, &rig, &tally, &arena);
    let path = staging.path().join(SUMMARY_FILE);
    let json = serde_json::to_vec_pretty(&summary).map_err(std::io::Error::from);
    json.and_then(|j| std::fs::write(&path, j))
        .map_err(|source| ReplayError::Write { path, source })?;
    staging.commit()?;
    Ok(summary)
}

/// Loads the models (and hashes their files) on a thread of their own while the rig is chosen
/// and the empty cage is modelled from the recording (the two longest steps of a MoSeq
/// recording's start-up); the models' errors come first, as when they were loaded first.
/// Without colour frames the paw cascade is not read.
fn load_models_and_scene(
    options: &ReplayOptions,
    recording: &Recording,
) -> Result<(Models, crate::runtime::models::ModelsUsed, RecordingRig, Background), ReplayError> {
    let color = recording.has_color();
    let (models, scene) = std::thread::scope(|scope| {
        // The models' files hashed there too (the body forest's 28 MB), beside the background.
        let models = scope.spawn(|| {
            Models::load_for(options.models.as_deref(), color).map(|m| {
                let used = m.used();
                (m, used)
            })
        });
        let scene = rig_and_background(options, recording);
        let models = models.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (models, scene)
    });
    let (models, used) = models?;
    let (chosen, background) = scene?;
    Ok((models, used, chosen, background))
}

/// The recording's rig (its calibration, `--calibration`, or uncalibrated with `--intrinsics`
/// or the camera table's) and the empty cage modelled from it (in `--roi` when given).
fn rig_and_background(
    options: &ReplayOptions,
    recording: &Recording,
) -> Result<(RecordingRig, Background), ReplayError> {
    let chosen = match &options.calibration {
        Some(path) => RecordingRig {
            rig: recording.calibrated_rig(path)?,
            calibrated: true,
            intrinsics_from: "rig calibration".to_owned(),
        },
        None => recording.rig(options.intrinsics.as_deref())?,
    };
    let roi = match &options.roi {
        Some(path) => {
            let (w, h) = recording.depth_size();
            Some(read_mask_png(path, w, h)?)
        }
        None => None,
    };
    let background = background_in(recording, &chosen.rig, roi.as_deref())?;
    Ok((chosen, background))
}

/// The world a replay of `recording` with `options` works in, without its models: what
/// `adapt` measures the mouse in.
///
/// # Errors
/// As [`replay`]'s, for the rig, the background and the arena.
pub(crate) fn scene_of(options: &ReplayOptions, recording: &Recording) -> Result<Scene, ReplayError> {
    let (chosen, background) = rig_and_background(options, recording)?;
    Scene::place(options, chosen, background)
}

/// The replay's world: the rig placed (on the fitted floor when uncalibrated), the arena, and
/// the segmenter built on the background.
pub(crate) struct Scene {
    pub(crate) rig: Rig,
    pub(crate) world: WorldSummary,
    pub(crate) arena: Vec<u8>,
    pub(crate) depth_size: (u32, u32),
    pub(crate) segmenter: Segmenter,
}

impl Scene {
    fn place(options: &ReplayOptions, mut chosen: RecordingRig, background: Background) -> Result<Self, ReplayError> {
        let depth_size = (background.region().width, background.region().height);
        let floor = background.floor_plane();
        if !chosen.calibrated {
            // No calibration: the world is the floor's, z the height above it.
            chosen.rig.depth.world_from_camera = floor.world_from_camera();
        }
        let rig = chosen.rig;
        let arena = background.arena();
        let on_floor = arena_on_floor(arena, background.depth(), background.region(), &rig.depth);
        let world = WorldSummary {
            frame: if chosen.calibrated { "calibration" } else { "floor" },
            camera_height_mm: floor.camera_height_mm(),
            camera_tilt_deg: floor.camera_tilt_deg(),
            intrinsics_from: chosen.intrinsics_from,
            fx: rig.depth.intrinsics.fx,
            fy: rig.depth.intrinsics.fy,
            cx: rig.depth.intrinsics.cx,
            cy: rig.depth.intrinsics.cy,
            world_from_camera: {
                let m = rig.depth.world_from_camera.to_homogeneous();
                std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
            },
            arena_share: arena.iter().filter(|&&m| m != 0).count() as f64 / arena.len().max(1) as f64,
            arena_from: if options.roi.is_some() { "roi" } else { "found" },
            arena_check: background.arena_check(),
            arena_mm: on_floor.as_ref().map(|f| f.0),
            arena_outline_mm: on_floor.and_then(|f| f.1),
        };
        let arena = arena.to_vec();
        let segmenter = SegmenterConfig::default()
            .build(background)
            .map_err(ReplayError::Background)?
            .with_world(rig.depth.world_from_camera);
        Ok(Self {
            rig,
            world,
            arena,
            depth_size,
            segmenter,
        })
    }
}

/// The replay's topology: the recording as its source, the processing branch, no recorder.
fn replay_topology<'a>(
    recording: &'a Recording,
    options: &ReplayOptions,
    depth_size: (u32, u32),
    segmenter: Segmenter,
    models: Models,
    rig: Rig,
    writer: PoseWriter,
) -> Topology<'a> {
    Topology {
        sources: Sources::Recording {
            recording,
            realtime: options.realtime,
            depth_size: Some(depth_size),
        },
        sync: crate::runtime::pairing::SyncConfig {
            partner_wait_ns: options.partner_wait.map(|(wait, _)| wait),
            partner_reach_ns: options.partner_wait.and_then(|(_, reach)| reach),
            ..recording.sync_config()
        },
        edges: Edges::replay(),
        processing: Some(Processing {
            segment: SegmentStage::new(segmenter).with_mice(options.mice),
            models,
            rig,
            workers: options.workers,
            overlays: options.overlays,
            poses: Box::new(writer),
            stream: None,
            lsl: None,
        }),
        recorder: None,
    }
}

/// Starts `topology` and waits for it, calling `progress` with the rows written (in `tally`)
/// and the recording's `total` depth frames every [`PROGRESS_EVERY`] from a thread of its
/// own, and once at the end. A signal stops the reader; the stages drain what it sent.
fn run_pipeline(
    topology: Topology<'_>,
    interrupt: &Interrupt,
    tally: &Mutex<PoseTally>,
    total: u64,
    progress: &(impl Fn(u64, u64) + Sync),
) -> Result<Finished, ReplayError> {
    if interrupt.requested() {
        return Err(ReplayError::Interrupted);
    }
    let running = topology.start()?;
    // A signal stops the reader; the stages drain what it sent, then the staging directory
    // is removed (dropped uncommitted).
    let forwarded = interrupt
        .forward_to(&running.shutdown().flag())
        .map_err(ReplayError::Signals);
    if forwarded.is_err() {
        running.shutdown().request();
    }
    // Dropping `stop` ends the watcher at once.
    let (stop, stopped) = crossbeam_channel::bounded::<()>(1);
    let finished = std::thread::scope(|scope| {
        let watcher = std::thread::Builder::new()
            .name("progress".to_owned())
            .spawn_scoped(scope, || {
                loop {
                    let rows = tally.lock().unwrap_or_else(PoisonError::into_inner).rows;
                    progress(rows, total);
                    if !matches!(
                        stopped.recv_timeout(PROGRESS_EVERY),
                        Err(crossbeam_channel::RecvTimeoutError::Timeout)
                    ) {
                        break;
                    }
                }
            });
        let finished = running.join();
        drop(stop);
        if let Ok(w) = watcher {
            drop(w.join());
        }
        finished
    });
    drop(forwarded?);
    progress(tally.lock().unwrap_or_else(PoisonError::into_inner).rows, total);
    Ok(finished)
}

/// `summary` with the picture of one frame written into the staging directory; the picture
/// is a convenience: without it (no frame that reads back, a write error) the results are
/// still whole, and written, and the summary says why there is none.
fn with_picture(
    mut summary: ReplaySummary,
    staging: &Staging,
    recording: &Recording,
    rig: &Rig,
    tally: &PoseTally,
    arena: &[u8],
) -> ReplaySummary {
    let outside = summary.world.arena_check.is_some_and(|c| c.mouse_sized_outside > 0);
    let img = match &tally.snapshot {
        Some(pose) => picture(recording, rig, pose, arena),
        None => picture_without_mouse(recording, rig, arena, outside),
    };
    let written = match img {
        Some(img) => img
            .write_png(&staging.path().join(PICTURE_FILE))
            .map_err(|e| format!("cannot write {PICTURE_FILE}: {e}")),
        None => Err("no depth frame of the session reads back to draw it".to_owned()),
    };
    match written {
        Ok(()) => summary.picture = Some(PICTURE_FILE),
        Err(error) => {
            tracing::warn!(message = "No picture; the results are complete without it.", %error);
            summary.picture_error = Some(error);
        }
    }
    summary
}
