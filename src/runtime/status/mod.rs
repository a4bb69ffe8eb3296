//! What a running daemon shows of itself: the run report so far ([`RunReport`], the same type
//! `mousepose run` prints at the end and `GET /status` serves), the latest pose and its frames,
//! the last minutes of frame rate and latency, and the last events. The HTTP server, the
//! daemon's status line and its final report all read one [`Watch`].
//!
//! Everything here is read from counters and snapshots the pipeline keeps anyway (atomics, and
//! mutexes held only for a few field copies): reading never waits on a stage.

pub mod events;

use crate::core::frame::FramePair;
use crate::runtime::accounting::{CameraSummary, EdgeSummary};
use crate::runtime::capture::supervise::{CameraState, Outage, SharedHealth, lock};
use crate::runtime::pipeline::{LatencySummary, StageReport, reports_of};
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crate::runtime::sink::chunks::{Live, RecorderGauges};
use crate::runtime::stages::segment::FloorSlot;
use crate::runtime::stream::lsl::{LslHandle, LslSummary};
use crate::runtime::stream::{StreamHandle, StreamSummary};
use crate::runtime::topology::PipelineWatch;
use crate::runtime::usage::{process_cpu_s, process_resident_bytes};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex, PoisonError};

/// One camera in the report.
#[derive(Clone, Debug, Serialize)]
pub struct RunCamera {
    #[serde(flatten)]
    pub frames: CameraSummary,
    pub state: Option<CameraState>,
    pub outages: Vec<Outage>,
}

/// The raw recording, while a run records.
#[derive(Clone, Debug, Serialize)]
pub struct RecordingReport {
    /// Encoded frame bytes written, all chunks (it only grows).
    pub frame_bytes: u64,
    /// Of those, the bytes of chunks removed or moved away under the run, by reason.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub frame_bytes_lost_after_recording: BTreeMap<&'static str, u64>,
    /// Free bytes on the output's file system at the last check.
    pub disk_free_bytes: u64,
    /// Paused: disk low, or after a write error (poses go on).
    pub paused: bool,
    /// Session events (camera gaps and outages, pauses) waiting for room on the disk, and
    /// those never written (too many waited, or the run ended first).
    pub events_waiting: u64,
    pub events_lost: u64,
}

/// What the run was started with.
#[derive(Clone, Debug, Serialize)]
pub struct RunInfo {
    pub version: &'static str,
    /// Start time, RFC 3339 UTC.
    pub started_utc: String,
    pub config: PathBuf,
    /// The models' directory, and whether it had a paw cascade.
    pub models: PathBuf,
    pub paw_model: bool,
    /// The rig calibration file, or `None` for the default rig.
    pub calibration: Option<PathBuf>,
}

/// What a run did (so far, while it runs).
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    /// The run's directory, holding its chunks.
    pub dir: PathBuf,
    pub info: RunInfo,
    pub seconds: f64,
    pub chunks: usize,
    /// The chunk poses are written to now.
    pub chunk: usize,
    pub poses: u64,
    /// Poses that could not be written to `poses.csv` (a full disk, a write error).
    pub poses_not_written: u64,
    pub statuses: BTreeMap<&'static str, u64>,
    /// Status of the latest pose, and whether the segmenter works without a floor yet.
    pub latest_status: Option<&'static str>,
    pub degraded: bool,
    pub cameras: BTreeMap<&'static str, RunCamera>,
    pub stages: Vec<StageReport>,
    pub edges: BTreeMap<String, EdgeSummary>,
    /// From a pair leaving the synchroniser to its row handed to the operating system.
    pub end_to_end_latency: LatencySummary,
    /// CPU time the process used per second (1.0 = one core busy).
    pub cpu_cores: f64,
    pub resident_memory_bytes: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recording: Option<RecordingReport>,
    /// The live pose stream (`[stream]`): subscribers connected, messages sent and dropped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stream: Option<StreamSummary>,
    /// The LSL outlet (`[lsl]`): whether a reader is connected, samples sent and dropped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lsl: Option<LslSummary>,
}

impl RunReport {
    /// The report as a few lines for a terminal.
    pub fn text(&self) -> String {
        use std::fmt::Write as _;
        let mut text = format!(
            "{:.1} s into {:?}: {} chunks, {} poses {:?}, {:.2} cores, latency p99 {:.2} ms\n",
            self.seconds,
            self.dir,
            self.chunks,
            self.poses,
            self.statuses,
            self.cpu_cores,
            self.end_to_end_latency.p99_ms
        );
        for (name, c) in &self.cameras {
            let state = match &c.state {
                Some(CameraState::Streaming) => "streaming".to_owned(),
                Some(CameraState::Opening) | None => "opening".to_owned(),
                Some(CameraState::Away(why)) => format!("away ({why})"),
            };
            let _ = writeln!(
                text,
                "{name:>6}: {state}; captured {}, paired {}, unpaired {}, dropped {:?}, recorded {}, not recorded {:?}, outages {}",
                c.frames.captured,
                c.frames.paired,
                c.frames.unpaired,
                c.frames.dropped,
                c.frames.recorded.unwrap_or(0),
                c.frames.not_recorded,
                c.outages.len()
            );
            if !c.frames.lost_after_recording.is_empty() {
                let _ = writeln!(
                    text,
                    "{name:>6}: recorded then lost (chunks removed or moved away) {:?}",
                    c.frames.lost_after_recording
                );
            }
        }
        if let Some(r) = &self.recording {
            let size = |b: u64| match b {
                0..1_000_000_000 => format!("{:.0} MB", b as f64 / 1e6),
                _ => format!("{:.1} GB", b as f64 / 1e9),
            };
            let _ = writeln!(
                text,
                "recording: {} written, {} free{}",
                size(r.frame_bytes),
                size(r.disk_free_bytes),
                if r.paused { ", PAUSED" } else { "" }
            );
            if r.events_waiting + r.events_lost > 0 {
                let _ = writeln!(
                    text,
                    "recording: {} session events waiting for room, {} lost",
                    r.events_waiting, r.events_lost
                );
            }
        }
        if let Some(s) = &self.stream {
            let _ = writeln!(
                text,
                "stream: {}, {} subscribers, sent {:?}, dropped {:?}",
                s.endpoint, s.subscribers, s.sent, s.dropped
            );
        }
        if let Some(l) = &self.lsl {
            let _ = writeln!(
                text,
                "lsl: {}, {}, sent {}, dropped {:?}",
                l.name,
                if l.consumers { "a reader connected" } else { "no reader" },
                l.sent,
                l.dropped
            );
        }
        text
    }
}

/// One second of the run, for the live page's plots.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Sample {
    /// Seconds since the run started.
    pub t_s: f64,
    pub poses_per_s: f64,
    /// Mean end-to-end latency over the second, ms (0 without poses).
    pub latency_ms: f64,
    pub depth_fps: f64,
    pub color_fps: f64,
}

/// Samples kept: ten minutes at one a second.
const HISTORY: usize = 600;

#[derive(Debug, Default)]
struct History {
    samples: VecDeque<Sample>,
    /// Totals at the last sample: time, poses, latency count and sum, frames per camera.
    last: Option<(f64, u64, u64, u64, u64, u64)>,
}

/// What a [`Watch`] reads.
#[derive(Debug)]
pub struct Watched {
    pub dir: PathBuf,
    pub info: RunInfo,
    pub pipeline: PipelineWatch,
    pub cameras: Vec<(&'static str, SharedHealth)>,
    pub live: Arc<Mutex<Live>>,
    pub chunks: Arc<crate::runtime::sink::chunks::Chunks>,
    pub recorder: Option<Arc<RecorderGauges>>,
    /// The floor the segmenter fitted, for the live view.
    pub floor: FloorSlot,
    /// The live pose stream, when one is bound.
    pub stream: Option<StreamHandle>,
    /// The LSL outlet, when one is offered.
    pub lsl: Option<LslHandle>,
}

/// A running daemon, as its readers see it.
#[derive(Debug)]
pub struct Watch {
    pub parts: Watched,
    cpu0: f64,
    history: Mutex<History>,
}

impl Watch {
    pub fn new(parts: Watched) -> Self {
        Self {
            parts,
            cpu0: process_cpu_s(),
            history: Mutex::default(),
        }
    }

    /// A copy of the live pose counts (the frames stay shared).
    pub fn live(&self) -> Live {
        self.parts.live.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// The floor fitted last, if any.
    pub fn floor(&self) -> Option<crate::vision::segment::FloorPlane> {
        *self.parts.floor.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The latest pose and its frames.
    pub fn latest(&self) -> Option<(PoseRecord, FramePair)> {
        let live = self.parts.live.lock().unwrap_or_else(PoisonError::into_inner);
        Some((live.latest.clone()?, live.frames.clone()?))
    }

    /// The latest pose that had a colour frame, and its frames.
    pub fn latest_with_color(&self) -> Option<(PoseRecord, FramePair)> {
        let live = self.parts.live.lock().unwrap_or_else(PoisonError::into_inner);
        live.latest_with_color()
    }

    /// The run report so far.
    pub fn report(&self) -> RunReport {
        let live = self.live();
        let seconds = self.parts.pipeline.elapsed_s();
        let mut cameras = BTreeMap::new();
        for (name, frames) in self.parts.pipeline.cameras() {
            let (state, outages) = match self.parts.cameras.iter().find(|(n, _)| *n == name) {
                Some((_, h)) => {
                    let h = lock(h);
                    (h.state.clone(), h.outages.clone())
                }
                None => (None, Vec::new()),
            };
            cameras.insert(name, RunCamera { frames, state, outages });
        }
        let latest_status = live.latest.as_ref().map(|p| p.status.name());
        RunReport {
            dir: self.parts.dir.clone(),
            info: self.parts.info.clone(),
            seconds,
            chunks: self.parts.chunks.count(),
            chunk: live.chunk,
            poses: live.rows,
            poses_not_written: live.rows_lost,
            degraded: live
                .latest
                .as_ref()
                .is_some_and(|p| p.status == PoseStatus::NoBackground),
            statuses: live.statuses,
            latest_status,
            cameras,
            stages: reports_of(self.parts.pipeline.stages()),
            edges: self.parts.pipeline.edges(),
            end_to_end_latency: self.parts.pipeline.end_to_end().summary(),
            cpu_cores: (process_cpu_s() - self.cpu0) / seconds.max(1e-9),
            resident_memory_bytes: process_resident_bytes(),
            recording: self.parts.recorder.as_ref().map(|g| RecordingReport {
                frame_bytes: g.frame_bytes.load(Ordering::Relaxed),
                frame_bytes_lost_after_recording: g.lost_bytes.lock().unwrap_or_else(PoisonError::into_inner).clone(),
                disk_free_bytes: g.disk_free_bytes.load(Ordering::Relaxed),
                paused: g.paused.load(Ordering::Relaxed),
                events_waiting: g.events_waiting.load(Ordering::Relaxed),
                events_lost: g.events_lost.load(Ordering::Relaxed),
            }),
            stream: self.parts.stream.as_ref().map(StreamHandle::summary),
            lsl: self.parts.lsl.as_ref().map(LslHandle::summary),
        }
    }

    /// Takes one sample of rates and latency since the previous call (the daemon calls this
    /// once a second) and returns it.
    pub fn sample(&self) -> Sample {
        let t = self.parts.pipeline.elapsed_s();
        let rows = self.parts.live.lock().unwrap_or_else(PoisonError::into_inner).rows;
        let (count, sum_us) = self.parts.pipeline.end_to_end().totals();
        let cams = self.parts.pipeline.cameras();
        let captured = |name: &str| cams.get(name).map_or(0, |c| c.captured);
        let now = (t, rows, count, sum_us, captured("depth"), captured("color"));
        let mut history = self.history.lock().unwrap_or_else(PoisonError::into_inner);
        let (t0, rows0, count0, sum0, depth0, color0) = history.last.unwrap_or((0.0, 0, 0, 0, 0, 0));
        let dt = (t - t0).max(1e-3);
        let rate = |a: u64, b: u64| a.saturating_sub(b) as f64 / dt;
        let sample = Sample {
            t_s: t,
            poses_per_s: rate(rows, rows0),
            latency_ms: match count.saturating_sub(count0) {
                0 => 0.0,
                n => sum_us.saturating_sub(sum0) as f64 / n as f64 / 1000.0,
            },
            depth_fps: rate(now.4, depth0),
            color_fps: rate(now.5, color0),
        };
        history.last = Some(now);
        if history.samples.len() == HISTORY {
            history.samples.pop_front();
        }
        history.samples.push_back(sample);
        sample
    }

    /// The samples of the last ten minutes, oldest first.
    pub fn history(&self) -> Vec<Sample> {
        let history = self.history.lock().unwrap_or_else(PoisonError::into_inner);
        history.samples.iter().copied().collect()
    }
}
