//! The one builder of the pipeline's threads and edges: `record`, `replay`, `run` (the daemon)
//! and `bench` (through replay) describe what they want as a [`Topology`] and
//! [`Topology::start`] wires it.
//!
//! ```text
//!  sources: the rig's cameras ("cap-depth", "cap-color")   capture edge: bounded; cameras
//!           or a recording read back ("replay")            drop when full, replay waits
//!      │ Captured (Depth | Color)
//!      ├──────────────────────────────────────────────▶ "recorder" (lossless session)   [recorder]
//!      ▼
//!  "sync" (Synchronizer) ─FramePair─▶ "segment" ─Segmented─▶ "body-N" (one per worker)
//!      ─Posed─▶ "paws-N" ─Posed─▶ "fuse" (in index order) ─Fused─▶ "poses" (poses.csv)  [processing]
//! ```
//!
//! The processing branch is declared in [`declare_processing`], one line per stage: each
//! stage says what it takes, gives and is called (`pipeline::Map`), and the chain builder
//! (`pipeline::Chain`) makes the edges between them and names them after the two stages
//! (`segment->body`). A new stage is a file in `stages/` and a line there.
//!
//! Every frame is accounted for in [`Accounting`]: the capture threads count what the sources
//! deliver and the gaps in their frame counters, the edges what they drop, the sync thread
//! what it pairs, leaves unpaired or rejects.

use crate::core::frame::FramePair;
use crate::core::geometry::Rig;
use crate::io::session::CameraRole;
use crate::runtime::accounting::{Accounting, CameraCounters, CameraSummary, EdgeSummary, bump};
use crate::runtime::capture::rig::{ColorSource, DepthSource, RigCameras};
pub use crate::runtime::capture::supervise::Epochs;
use crate::runtime::capture::{Captured, Clock, FrameSource, SeqGaps, Stamped};
use crate::runtime::models::Models;
use crate::runtime::pairing::SyncConfig;
use crate::runtime::pipeline::{
    Chain, EdgeConfig, EdgeSender, Histogram, LatencySummary, NamedEdge, PipelineError, Runner, Sent, Shutdown, Sink,
    StageError, StageReport, StageStats, edge,
};
use crate::runtime::recording::session::{SessionPlayer, recorded_reopens};
use crate::runtime::recording::{Recording, RecordingError};
use crate::runtime::sink::session::{FrameRecorder, write_frames};
use crate::runtime::stages::Fused;
use crate::runtime::stages::body::{BodyStage, PIPELINE_VOTE_BUDGET};
use crate::runtime::stages::fuse::FuseStage;
use crate::runtime::stages::paws::PawStage;
use crate::runtime::stages::segment::SegmentStage;
use crate::runtime::stages::sync::{Reopens, SyncStage};
use crate::runtime::stream::lsl::LslHandle;
use crate::runtime::stream::{Published, StreamHandle};
use crate::vision::fusion::{Fuser, FusionConfig};
use crossbeam_channel::Receiver;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Where the frames come from.
#[derive(Debug)]
pub enum Sources<'a> {
    /// The rig's cameras, both supervised (`capture::supervise`): for `record` opened (and the
    /// depth camera started, so that its metadata is known) before the pipeline starts.
    Cameras {
        depth: DepthSource,
        color: Option<ColorSource>,
        /// Per camera (depth, colour): goes up each time the camera is reopened, so that the
        /// synchroniser learns its clock again (see `capture::supervise`).
        epochs: Epochs,
    },
    /// A recording read back: as fast as the pipeline takes it, or at its recorded pace.
    /// Depth frames of another size than `depth_size` (when given: what the background
    /// model covers) are skipped and counted `wrong_size`.
    Recording {
        recording: &'a Recording,
        realtime: bool,
        depth_size: Option<(u32, u32)>,
    },
}

/// The sizes and policies of the edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edges {
    /// Out of the capture threads.
    pub capture: EdgeConfig,
    /// Between the stages.
    pub stage: EdgeConfig,
}

impl Edges {
    /// Replay's: nothing is ever dropped, the reader waits for the pipeline. A replay's
    /// reader is always ahead, so every edge stays full and each frame on one is memory held:
    /// 4 frames an edge keep every stage fed (64 on the capture edge and 8 on the others
    /// held 35 MB of 512x424 depth frames, about 150 MB of full-size frame pairs, for
    /// nothing: the order of the frames, hence the poses, does not depend on it).
    pub fn replay() -> Self {
        Self {
            capture: EdgeConfig::block(4),
            stage: EdgeConfig::block(4),
        }
    }
}

/// The processing branch: segmentation, the body forest, the paw cascade, fusion, poses
/// (see [`declare_processing`]).
#[derive(Debug)]
pub struct Processing {
    /// Segmentation with a known background, or one learnt live.
    pub segment: SegmentStage,
    /// The body forest and the paw cascade.
    pub models: Models,
    pub rig: Rig,
    /// Workers of each stage declared `map_parallel` (body, paws); 0: one per core.
    pub workers: usize,
    /// Draw every n-th frame (by depth sequence number) into the pose writer's `overlays/`.
    pub overlays: Option<u64>,
    /// Where the poses go: `poses.csv` of one directory, or chunk after chunk.
    pub poses: Box<dyn Sink<In = Fused>>,
    /// The live pose stream, when one is bound: each pose is published before it is written.
    pub stream: Option<StreamHandle>,
    /// The LSL outlet, when one is offered: the same.
    pub lsl: Option<LslHandle>,
}

/// A pipeline to start.
#[derive(Debug)]
pub struct Topology<'a> {
    pub sources: Sources<'a>,
    pub sync: SyncConfig,
    pub edges: Edges,
    /// The processing branch; `None` to only record.
    pub processing: Option<Processing>,
    /// The lossless recorder branch, fed straight from the capture threads.
    pub recorder: Option<Box<dyn FrameRecorder>>,
}

/// Why a pipeline could not start.
#[derive(Debug, thiserror::Error)]
pub enum TopologyError {
    #[error("cannot start the pipeline's threads")]
    Threads(#[source] std::io::Error),
    #[error(transparent)]
    Recording(#[from] RecordingError),
}

/// A started pipeline.
#[derive(Debug)]
pub struct Running {
    runner: Runner,
    watch: PipelineWatch,
    recorder: Option<Receiver<Box<dyn FrameRecorder>>>,
}

/// A running pipeline's counters, to read while it runs (the daemon's status and metrics) and
/// once it has ended: lock-free counters only, so reading never waits on a stage.
#[derive(Clone, Debug)]
pub struct PipelineWatch {
    acct: Arc<Accounting>,
    color: bool,
    /// Whether the run processes frames, and whether it records them.
    branches: (bool, bool),
    started: Instant,
    edges: Vec<NamedEdge>,
    end_to_end: Arc<Histogram>,
    stages: Vec<(String, Arc<StageStats>)>,
}

impl PipelineWatch {
    /// Per camera: captured = paired + unpaired + dropped (so far).
    pub fn cameras(&self) -> BTreeMap<&'static str, CameraSummary> {
        let (processing, recording) = self.branches;
        let mut cameras = BTreeMap::new();
        cameras.insert("depth", CameraSummary::of(&self.acct.depth, processing, recording));
        if self.color {
            cameras.insert("color", CameraSummary::of(&self.acct.color, processing, recording));
        }
        cameras
    }

    /// Each edge's capacity, queue depth and drops.
    pub fn edges(&self) -> BTreeMap<String, EdgeSummary> {
        self.edges
            .iter()
            .map(|(name, config, stats)| (name.clone(), EdgeSummary::of(*config, stats)))
            .collect()
    }

    /// Each stage's and sink's live counters and time per item.
    pub fn stages(&self) -> &[(String, Arc<StageStats>)] {
        &self.stages
    }

    /// From a pair leaving the synchroniser to its row written.
    pub fn end_to_end(&self) -> &Histogram {
        &self.end_to_end
    }

    pub fn elapsed_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }
}

/// What a finished pipeline did.
#[derive(Debug)]
pub struct Finished {
    /// The stages' reports, or the component that stopped the run.
    pub outcome: Result<Vec<StageReport>, PipelineError>,
    /// Per camera: captured = paired + unpaired + dropped.
    pub cameras: BTreeMap<&'static str, CameraSummary>,
    /// From a pair leaving the synchroniser to its row written.
    pub end_to_end_latency: LatencySummary,
    pub edges: BTreeMap<String, EdgeSummary>,
    pub elapsed_s: f64,
    /// The recorder, handed back to be finished.
    pub recorder: Option<Box<dyn FrameRecorder>>,
}

impl Topology<'_> {
    /// Starts every thread: the sources first, then the recorder and the processing chain.
    ///
    /// # Errors
    /// A thread cannot be created, or the recording cannot be opened for reading.
    pub fn start(self) -> Result<Running, TopologyError> {
        let Topology {
            sources,
            sync,
            edges,
            processing,
            recorder,
        } = self;
        let started = Instant::now();
        let threads = TopologyError::Threads;
        let mut runner = Runner::new();
        let acct = Arc::new(Accounting::default());
        let end_to_end = Arc::new(Histogram::default());
        let branches = (processing.is_some(), recorder.is_some());
        let (tee, mut edge_stats, frames, recorded) = Tee::declare(edges.capture, branches);
        let (capture, color, reopens) = sources.declare(sync.color)?;
        for thread in capture {
            thread.spawn(&mut runner, &tee, &acct).map_err(threads)?;
        }
        drop(tee);
        let recorder = match recorder.zip(recorded) {
            Some((writer, rx)) => Some(spawn_recorder(&mut runner, writer, rx, &acct).map_err(threads)?),
            None => None,
        };
        if let (Some(p), Some(frames)) = (processing, frames) {
            // A partner wait ends by the host clock live; a replay's stamps are of another
            // clock (`Reopens::Recorded`).
            let sync = SyncStage::new(sync, Arc::clone(&acct), reopens);
            let chain = Chain::head(&mut runner, edges.stage, p.workers(), sync, frames);
            edge_stats.extend(declare_processing(chain, p, Arc::clone(&end_to_end)).map_err(threads)?);
        }
        let watch = PipelineWatch {
            acct,
            color,
            branches,
            started,
            edges: edge_stats,
            end_to_end,
            stages: runner.stage_stats(),
        };
        Ok(Running {
            runner,
            watch,
            recorder,
        })
    }
}

impl Sources<'_> {
    /// The capture threads these sources run, whether a colour camera feeds the pipeline, and
    /// the cameras' reopen counters. `color` is the configuration's word for a recording.
    fn declare(self, color: bool) -> Result<(Vec<CaptureThread>, bool, Reopens), RecordingError> {
        Ok(match self {
            Sources::Cameras { depth, color, epochs } => {
                let clock = Clock::Monotonic;
                let has_color = color.is_some();
                let mut threads = vec![CaptureThread::new("cap-depth", depth, &clock, Captured::depth)];
                threads.extend(color.map(|c| CaptureThread::new("cap-color", c, &clock, Captured::color)));
                (threads, has_color, Reopens::live(epochs))
            }
            Sources::Recording {
                recording,
                realtime,
                depth_size,
            } => {
                let clock = Clock::replay(0);
                let (thread, reopens) = match recording {
                    Recording::Session(reader) => {
                        let player = SessionPlayer::new(reader, realtime).with_depth_size(depth_size);
                        let thread = CaptureThread::new("replay", player, &clock, |c| c);
                        (thread, recorded_reopens(reader))
                    }
                    Recording::Moseq { config, .. } => {
                        let player = Recording::moseq(config)?;
                        (
                            CaptureThread::new("replay", player, &clock, Captured::depth),
                            Reopens::none(),
                        )
                    }
                };
                (vec![thread], color, reopens)
            }
        })
    }
}

impl From<RigCameras> for Sources<'_> {
    fn from(cameras: RigCameras) -> Self {
        Sources::Cameras {
            depth: Box::new(cameras.depth),
            color: cameras.color.map(|c| Box::new(c) as ColorSource),
            epochs: cameras.epochs,
        }
    }
}

/// Where the capture threads send each frame: the processing branch (a full edge drops the
/// frame, counted `dropped`) and the recorder (a full edge: counted `not_recorded`).
#[derive(Clone)]
struct Tee {
    processing: Option<EdgeSender<Captured>>,
    recorder: Option<EdgeSender<Captured>>,
}

/// A tee, its edges, and their receiving ends (processing, recorder).
type Declared = (
    Tee,
    Vec<NamedEdge>,
    Option<Receiver<Captured>>,
    Option<Receiver<Captured>>,
);

impl Tee {
    /// The capture edges of the branches a run has (processing, recording).
    fn declare(config: EdgeConfig, (processing, recording): (bool, bool)) -> Declared {
        let mut named = Vec::new();
        let mut branch = |wanted: bool, name: &str| {
            wanted.then(|| {
                let (tx, rx, stats) = edge::<Captured>(config);
                named.push((name.to_owned(), config, stats));
                (tx, rx)
            })
        };
        let (processing, frames) = branch(processing, "capture").unzip();
        let (recorder, recorded) = branch(recording, "recorder").unzip();
        (Tee { processing, recorder }, named, frames, recorded)
    }

    /// Sends `frame` to each branch, counting what a full edge drops; false once a branch
    /// has closed (the pipeline is ending).
    fn send(&self, frame: Captured, counters: &CameraCounters) -> bool {
        let branches = [
            self.processing.as_ref().map(|tx| (tx, &counters.dropped)),
            self.recorder.as_ref().map(|tx| (tx, &counters.not_recorded)),
        ];
        let mut branches = branches.into_iter().flatten().peekable();
        let mut frame = Some(frame);
        while let Some((tx, dropped)) = branches.next() {
            let item = if branches.peek().is_none() {
                frame.take()
            } else {
                frame.clone()
            };
            let Some(item) = item else { break };
            match tx.send(item) {
                Sent::Delivered => {}
                Sent::DroppedFull => bump(dropped, "queue_full", 1),
                Sent::Closed => return false,
            }
        }
        true
    }
}

/// The body of a capture thread: the source run into the tee.
type CaptureBody = Box<dyn FnOnce(&Tee, &Accounting, &Shutdown) -> Result<(), StageError> + Send>;

/// One capture thread, declared: its name and the source it runs.
struct CaptureThread {
    name: &'static str,
    run: CaptureBody,
}

impl CaptureThread {
    /// A thread running `source` on `clock`, each frame made a [`Captured`] by `wrap`.
    fn new<S: FrameSource>(name: &'static str, source: S, clock: &Clock, wrap: fn(S::Frame) -> Captured) -> Self {
        let clock = clock.clone();
        Self {
            name,
            run: Box::new(move |tee, acct, shutdown| run_source(source, &clock, wrap, tee, acct, shutdown)),
        }
    }

    fn spawn(self, runner: &mut Runner, tee: &Tee, acct: &Arc<Accounting>) -> std::io::Result<()> {
        let (tee, acct, shutdown, run) = (tee.clone(), Arc::clone(acct), runner.shutdown(), self.run);
        runner.spawn(self.name, move || run(&tee, &acct, &shutdown))
    }
}

/// The recorder thread: writes every frame it is sent, then hands the writer back (to be
/// finished) on the channel returned, whatever happened.
fn spawn_recorder(
    runner: &mut Runner,
    mut writer: Box<dyn FrameRecorder>,
    frames: Receiver<Captured>,
    acct: &Arc<Accounting>,
) -> std::io::Result<Receiver<Box<dyn FrameRecorder>>> {
    let acct = Arc::clone(acct);
    let (done_tx, done_rx) = crossbeam_channel::bounded(1);
    runner.spawn("recorder", move || {
        let result = write_frames(writer.as_mut(), &frames, &acct);
        let _ = done_tx.send(writer);
        result
    })?;
    Ok(done_rx)
}

impl Processing {
    /// Workers of each parallel stage.
    fn workers(&self) -> usize {
        match self.workers {
            0 => std::thread::available_parallelism().map_or(1, usize::from),
            n => n,
        }
    }
}

/// The processing stages, in order, after the synchroniser at the head of `chain`: one line
/// per stage. `map` runs a stage on one thread in index order (a stage with memory from frame
/// to frame), `map_parallel` on the chain's workers; each stage's `In` must be the `Out` of the
/// one before it, and the builder names the edge between them after both.
fn declare_processing(
    chain: Chain<'_, FramePair>,
    p: Processing,
    end_to_end: Arc<Histogram>,
) -> std::io::Result<Vec<NamedEdge>> {
    let Processing {
        segment,
        models,
        rig,
        overlays,
        poses,
        stream,
        lsl,
        ..
    } = p;
    let poses = if stream.is_some() || lsl.is_some() {
        Box::new(Published {
            inner: poses,
            stream,
            lsl,
        })
    } else {
        poses
    };
    let fuser = Fuser::new(rig.color, FusionConfig::default());
    chain
        .map(segment)?
        .map_parallel(BodyStage::new(
            models.body,
            models.orientation,
            rig.depth,
            PIPELINE_VOTE_BUDGET,
        ))?
        .map_parallel(PawStage::new(models.paws, rig.color))?
        .map(FuseStage::new(fuser, rig, overlays))?
        .sink("poses", poses, end_to_end)
}

impl Running {
    /// The signal that stops the sources; any thread that fails sets it too.
    pub fn shutdown(&self) -> Shutdown {
        self.runner.shutdown()
    }

    /// The pipeline's counters, to read while it runs.
    pub fn watch(&self) -> PipelineWatch {
        self.watch.clone()
    }

    /// Waits for every thread and reports what the run did.
    pub fn join(self) -> Finished {
        let outcome = self.runner.join();
        let w = self.watch;
        Finished {
            outcome,
            cameras: w.cameras(),
            end_to_end_latency: w.end_to_end.summary(),
            edges: w.edges(),
            elapsed_s: w.elapsed_s(),
            recorder: self.recorder.and_then(|rx| rx.recv().ok()),
        }
    }
}

/// The camera and reason of a source's loss: `depth_corrupt` is the depth camera's
/// `corrupt` (a recording reports both cameras'), anything else the source's own camera's.
fn loss_of(reason: &'static str, own_role: CameraRole) -> (CameraRole, &'static str) {
    match reason.split_once('_') {
        Some(("depth", r)) => (CameraRole::Depth, r),
        Some(("color", r)) => (CameraRole::Color, r),
        _ => (own_role, reason),
    }
}

fn role_of(c: &Captured) -> CameraRole {
    match c {
        Captured::Depth(_) => CameraRole::Depth,
        Captured::Color(_) => CameraRole::Color,
    }
}

/// The body of a capture thread: runs `source` until it ends, fails or `shutdown` is
/// requested, sending each frame (as `wrap` makes it) to every branch and counting what
/// happens to it.
fn run_source<S: FrameSource>(
    mut source: S,
    clock: &Clock,
    wrap: fn(S::Frame) -> Captured,
    tee: &Tee,
    acct: &Accounting,
    shutdown: &Shutdown,
) -> Result<(), StageError> {
    let own_role = source.meta().role;
    source.start(clock)?;
    let mut gaps = [SeqGaps::default(); 2];
    // Per camera, the source's own losses already set against gaps in its frame numbers, and
    // the ones that came between two frames without a gap between them (damaged bytes that
    // were no frame, such as garbage between a recording's records): not frames lost.
    let mut accounted = [0u64; 2];
    let mut not_frames = [0u64; 2];
    let mut seen = [false; 2];
    while !shutdown.requested() && !source.finished() {
        let Some(frame) = source.next_frame(Duration::from_millis(100))? else {
            continue;
        };
        let frame = wrap(frame);
        let role = role_of(&frame);
        let counters = acct.camera(role);
        counters.captured.fetch_add(1, Ordering::Relaxed);
        let slot = usize::from(role == CameraRole::Color);
        let missing = gaps[slot].observe(frame.stamp());
        // A frame the source counted as lost (a damaged buffer or record) since this camera's
        // previous frame had its frame number too: counted once, by the source's reason, not
        // again as a gap. Losses before a camera's first frame explain no later gap.
        let lost: u64 = source
            .losses()
            .into_iter()
            .filter_map(|(reason, n)| (loss_of(reason, own_role).0 == role).then_some(n))
            .sum();
        let explained = lost.saturating_sub(accounted[slot]);
        accounted[slot] = lost;
        bump(&counters.lost, "camera_gap", missing.saturating_sub(explained));
        // Before a camera's first frame there is no number to tell: those losses count.
        if std::mem::replace(&mut seen[slot], true) {
            not_frames[slot] += explained.saturating_sub(missing);
        }
        if !tee.send(frame, counters) {
            break;
        }
    }
    for (reason, n) in source.losses() {
        let (role, reason) = loss_of(reason, own_role);
        let slot = usize::from(role == CameraRole::Color);
        let not_frame = n.min(not_frames[slot]);
        not_frames[slot] -= not_frame;
        bump(&acct.camera(role).lost, reason, n - not_frame);
    }
    // Every frame is in by now: a camera that cannot be stopped cleanly (gone at the same
    // moment, as when a rig powers down) is worth a warning, not the run.
    if let Err(e) = source.stop() {
        tracing::warn!(camera = %own_role, "the camera did not stop cleanly: {}", crate::core::error_chain(&e));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::{DepthFrame, Stamp};
    use crate::io::session::CameraMeta;
    use crate::runtime::capture::CaptureError;

    /// A depth camera delivering frames numbered `seqs`, of which it reports `damaged` as
    /// lost (damaged) once it has delivered `damaged_from` frames.
    #[derive(Debug)]
    struct Numbered {
        seqs: Vec<u64>,
        delivered: usize,
        damaged: u64,
        damaged_from: usize,
    }

    impl FrameSource for Numbered {
        type Frame = DepthFrame;
        fn meta(&self) -> CameraMeta {
            CameraMeta {
                role: CameraRole::Depth,
                backend: crate::io::session::BackendName::SYNTHETIC,
                model: String::new(),
                serial: String::new(),
                firmware: String::new(),
                width: 1,
                height: 1,
                pixel_format: crate::io::session::codec::FrameFormat::Depth16,
                fps: 30.0,
            }
        }
        fn start(&mut self, _clock: &Clock) -> Result<(), CaptureError> {
            Ok(())
        }
        fn next_frame(&mut self, _timeout: Duration) -> Result<Option<DepthFrame>, CaptureError> {
            let Some(&seq) = self.seqs.get(self.delivered) else {
                return Ok(None);
            };
            self.delivered += 1;
            let stamp = Stamp {
                seq,
                device_ns: seq * 33_000_000,
                host_ns: seq * 33_000_000,
            };
            Ok(Some(DepthFrame::empty(stamp, 1, 1)))
        }
        fn finished(&self) -> bool {
            self.delivered == self.seqs.len()
        }
        fn losses(&self) -> Vec<(&'static str, u64)> {
            vec![(
                "incomplete",
                if self.delivered >= self.damaged_from {
                    self.damaged
                } else {
                    0
                },
            )]
        }
        fn stop(&mut self) -> Result<(), CaptureError> {
            Ok(())
        }
    }

    #[test]
    fn a_frame_the_source_counts_as_lost_is_not_counted_again_as_a_gap() {
        // 2 is damaged (counted by the source), 4 and 5 never came.
        let lost = lost_of(Numbered {
            seqs: vec![0, 1, 3, 6],
            delivered: 0,
            damaged: 1,
            damaged_from: 3,
        });
        assert_eq!(lost.get("incomplete"), Some(&1), "{lost:?}");
        assert_eq!(lost.get("camera_gap"), Some(&2), "{lost:?}");
    }

    #[test]
    fn a_damaged_first_frame_does_not_hide_a_later_gap() {
        // 0 is damaged (known with the first frame delivered), 4 never came.
        let lost = lost_of(Numbered {
            seqs: vec![1, 2, 3, 5],
            delivered: 0,
            damaged: 1,
            damaged_from: 1,
        });
        assert_eq!(lost.get("incomplete"), Some(&1), "{lost:?}");
        assert_eq!(lost.get("camera_gap"), Some(&1), "{lost:?}");
    }

    #[test]
    fn damage_between_two_frames_without_a_gap_is_no_frame_lost() {
        // Garbage between the records of 1 and 2 (the source steps over it and counts it),
        // and no number missing: nothing was lost; 5 never came.
        let lost = lost_of(Numbered {
            seqs: vec![0, 1, 2, 3, 4, 6],
            delivered: 0,
            damaged: 1,
            damaged_from: 3,
        });
        assert_eq!(lost.get("incomplete"), None, "{lost:?}");
        assert_eq!(lost.get("camera_gap"), Some(&1), "{lost:?}");
    }

    /// A new camera backend is one module and one registration line: the test-only
    /// `test_pattern` colour backend, named in a rig config, is read by its own table, opened
    /// and run by the topology like any camera.
    #[test]
    fn a_registered_backend_is_configured_opened_and_captured() {
        let text = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n\
                    [color]\nbackend = \"test_pattern\"\nwidth = 8\nheight = 6\nframes = 5\n";
        let config = crate::runtime::config::Config::parse(text, std::path::Path::new("rig.toml")).unwrap();
        let color = config.color.as_ref().expect("a colour camera");
        assert_eq!((color.backend(), color.frame_size()), ("test_pattern", Some((8, 6))));
        let bad = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n\
                   [color]\nbackend = \"test_pattern\"\nwidth = 8\nheight = 6\nframes = 5\naddress = \"x\"\n";
        let e = crate::runtime::config::Config::parse(bad, std::path::Path::new("rig.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("color.address") && e.contains("test_pattern"), "{e}");
        let depth = Numbered {
            seqs: vec![0, 1, 2],
            delivered: 0,
            damaged: 0,
            damaged_from: 0,
        };
        let finished = captured(depth, Some(color.open().unwrap()));
        assert!(finished.outcome.is_ok());
        assert_eq!(finished.cameras["color"].captured, 5);
        assert_eq!(finished.cameras["depth"].captured, 3);
    }

    /// The frames `depth` lost before capture, by reason, once the pipeline has run it.
    fn lost_of(depth: Numbered) -> BTreeMap<String, u64> {
        captured(depth, None).cameras["depth"].lost_before_capture.clone()
    }

    /// A capture-only pipeline run on these cameras until they end.
    fn captured(depth: Numbered, color: Option<ColorSource>) -> Finished {
        let topology = Topology {
            sources: Sources::Cameras {
                depth: Box::new(depth),
                color,
                epochs: Epochs::default(),
            },
            sync: SyncConfig::default(),
            edges: Edges::replay(),
            processing: None,
            recorder: None,
        };
        topology.start().unwrap().join()
    }
}
