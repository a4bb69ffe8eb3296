//! A live run's output, chunk after chunk: `DIR/<start>/chunk-0000/`, `chunk-0001/`, ... Each
//! chunk is a session of its own (when the run records) with its own `poses.csv` and, once
//! closed, `summary.json`; a chunk cut by a crash reads back up to its last frame and row.
//!
//! [`Chunks`] is the one place that decides where chunks begin (every `period`, and early
//! when a camera appears that the current chunk's session does not hold) and creates their
//! directories; the recorder ([`ChunkRecorder`]) and the pose sink ([`ChunkPoses`]) each follow
//! it by the host time of what they write. A full disk pauses raw recording ([`DiskWatch`]);
//! a write error pauses it, and it resumes once the disk has room again: in a new chunk when
//! the broken session had frames, otherwise by starting the current chunk's session again
//! (a session that could not start leaves nothing behind). Summaries are written whole or
//! not at all, and tried again while the run goes on. Poses go on either way, and none of
//! this stops the run.

use crate::core::frame::FramePair;
use crate::io::session::{
    CameraRole, SessionError, SessionEvent, SessionMeta, SessionSource, SessionSummary, SessionWriter,
};
use crate::runtime::capture::supervise::{SharedHealth, lock};
use crate::runtime::capture::{Captured, Stamped, error_chain};
use crate::runtime::pipeline::{Sink, StageError};
use crate::runtime::pose_record::PoseRecord;
use crate::runtime::sink::poses::{PoseTally, PoseWriter, TailsSeen};
use crate::runtime::stages::Fused;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// The summary of a closed chunk.
pub const CHUNK_SUMMARY_FILE: &str = "summary.json";

/// What every chunk's session says of the rig.
#[derive(Clone, Debug)]
pub struct ChunkPlan {
    /// The run's directory (`DIR/<start>`).
    pub root: PathBuf,
    pub period: Duration,
    /// Whether raw frames are recorded.
    pub record: bool,
    /// The cameras, whose metadata the chunks' sessions carry.
    pub cameras: Vec<SharedHealth>,
    /// The rest of each session's metadata (cameras and creation time are filled per chunk).
    pub meta: SessionMeta,
    /// The body forest and the paw cascade the poses come from, named in each chunk's
    /// `summary.json` (as a replay's names them).
    pub body_model: PathBuf,
    pub paw_model: Option<PathBuf>,
    /// Which models, with each file's hash.
    pub models: Option<crate::runtime::models::ModelsUsed>,
    /// How many mice share the cage (`[mice] count`): the columns of each chunk's `poses.csv`.
    pub mice: usize,
}

#[derive(Debug, Default)]
struct Opened {
    /// Host time each chunk begins at.
    starts: Vec<u64>,
    /// Sessions created for the recorder, not taken yet.
    writers: HashMap<usize, SessionWriter>,
}

/// Where chunks begin; see the module documentation.
#[derive(Debug)]
pub struct Chunks {
    plan: ChunkPlan,
    opened: Mutex<Opened>,
}

impl Chunks {
    pub fn new(plan: ChunkPlan) -> Arc<Self> {
        Arc::new(Self {
            plan,
            opened: Mutex::default(),
        })
    }

    /// The directory of chunk `index`.
    pub fn dir(&self, index: usize) -> PathBuf {
        self.plan.root.join(format!("chunk-{index:04}"))
    }

    /// The directory of chunk `index`, made (with the run's) if it is not there: one that could
    /// not be made when the chunk began (a full disk) is made once there is room, so the
    /// chunk's session and poses begin in it then.
    ///
    /// # Errors
    /// It cannot be made.
    pub fn make_dir(&self, index: usize) -> std::io::Result<PathBuf> {
        let dir = self.dir(index);
        std::fs::create_dir_all(&dir)?;
        Ok(dir)
    }

    /// Chunks begun so far.
    pub fn count(&self) -> usize {
        self.opened.lock().unwrap_or_else(PoisonError::into_inner).starts.len()
    }

    /// The chunk that holds `host_ns`, beginning a new one when the current one is over.
    pub fn at(&self, host_ns: u64) -> usize {
        let mut opened = self.opened.lock().unwrap_or_else(PoisonError::into_inner);
        let period = u64::try_from(self.plan.period.as_nanos()).unwrap_or(u64::MAX);
        match opened.starts.last() {
            Some(&last) if host_ns < last.saturating_add(period) => {}
            _ => self.begin(&mut opened, host_ns),
        }
        opened.starts.partition_point(|&s| s <= host_ns).saturating_sub(1)
    }

    /// Begins a new chunk at `host_ns` now, whatever the period says; returns its index.
    pub fn split(&self, host_ns: u64) -> usize {
        let mut opened = self.opened.lock().unwrap_or_else(PoisonError::into_inner);
        self.begin(&mut opened, host_ns);
        opened.starts.len() - 1
    }

    /// A chunk in place of chunk `index`, whose files were removed under the run: begun at
    /// `host_ns` now (its directory, and the run's, created again), unless a chunk was begun
    /// after `index` already (the other writer found the removal first); returns its index.
    pub fn replace(&self, index: usize, host_ns: u64) -> usize {
        let mut opened = self.opened.lock().unwrap_or_else(PoisonError::into_inner);
        if opened.starts.len() <= index + 1 {
            self.begin(&mut opened, host_ns);
        }
        opened.starts.len() - 1
    }

    /// The session created for chunk `index`, for the recorder to take.
    pub fn take_writer(&self, index: usize) -> Option<SessionWriter> {
        self.opened
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .writers
            .remove(&index)
    }

    fn begin(&self, opened: &mut Opened, host_ns: u64) {
        let index = opened.starts.len();
        let start = opened.starts.last().map_or(host_ns, |&last| host_ns.max(last));
        opened.starts.push(start);
        let dir = match self.make_dir(index) {
            Ok(dir) => dir,
            Err(e) => {
                tracing::error!(chunk = index, "cannot create {:?}: {e}", self.dir(index));
                return;
            }
        };
        tracing::info!(chunk = index, "chunk {dir:?} begun");
        if !self.plan.record {
            return;
        }
        match self.new_session(index, start) {
            Ok(w) => {
                opened.writers.insert(index, w);
            }
            Err(e) => tracing::error!(chunk = index, "cannot start the chunk's session: {}", error_chain(&e)),
        }
    }

    /// Starts the session of chunk `index` at `host_ns` (beside the chunk's `poses.csv`, when
    /// it is started again after a failed start). Nothing of it is left on failure: a
    /// `session.toml` cut by a full disk would make the chunk unreadable.
    ///
    /// # Errors
    /// The session's files cannot be created or written.
    pub fn new_session(&self, index: usize, host_ns: u64) -> Result<SessionWriter, SessionError> {
        let mut meta = self.plan.meta.clone();
        meta.created = crate::runtime::capture::clock::utc_now();
        meta.cameras = self.plan.cameras.iter().filter_map(|h| lock(h).meta.clone()).collect();
        let dir = self.make_dir(index).map_err(|source| SessionError::Io {
            path: self.dir(index),
            action: "create directory",
            source,
        })?;
        let mut w = SessionWriter::create_beside(dir, &meta)?;
        match w.log_event(&SessionEvent::SessionStarted { host_ns }) {
            Ok(()) => Ok(w),
            Err(e) => {
                if let Err(cleanup) = w.abandon() {
                    tracing::debug!(
                        chunk = index,
                        "cannot remove the session begun: {}",
                        error_chain(&cleanup)
                    );
                }
                Err(e)
            }
        }
    }
}

/// Free space on the output's file system, checked once a second: below the threshold
/// recording pauses, and resumes above it plus a margin.
#[derive(Debug)]
pub struct DiskWatch {
    path: PathBuf,
    /// The threshold is the larger of these.
    min_free_bytes: u64,
    min_free_share: f64,
    low: bool,
    checked: Option<Instant>,
    /// Free bytes at the last check.
    free: Option<u64>,
}

/// Space above the threshold before recording resumes, as a share of the threshold.
const DISK_MARGIN: f64 = 0.1;

impl DiskWatch {
    pub fn new(path: &Path, min_free_bytes: u64, min_free_share: f64) -> Self {
        Self {
            path: path.to_owned(),
            min_free_bytes,
            min_free_share,
            low: false,
            checked: None,
            free: None,
        }
    }

    /// Free bytes on the output's file system at the last check.
    pub fn free_bytes(&self) -> Option<u64> {
        self.free
    }

    /// Whether free space is low now (logging each change).
    pub fn low(&mut self) -> bool {
        if self.checked.is_some_and(|t| t.elapsed() < Duration::from_secs(1)) {
            return self.low;
        }
        self.checked = Some(Instant::now());
        let Ok(st) = rustix::fs::statvfs(&self.path) else {
            return self.low;
        };
        let free = st.f_bavail.saturating_mul(st.f_frsize);
        self.free = Some(free);
        let total = st.f_blocks.saturating_mul(st.f_frsize);
        let threshold = self.min_free_bytes.max((total as f64 * self.min_free_share) as u64);
        let gb = |b: u64| b as f64 / 1e9;
        if !self.low && free < threshold {
            self.low = true;
            tracing::warn!(
                free_gb = gb(free),
                threshold_gb = gb(threshold),
                "disk space low: raw recording paused, poses go on"
            );
        } else if self.low && free as f64 > threshold as f64 * (1.0 + DISK_MARGIN) {
            self.low = false;
            tracing::info!(free_gb = gb(free), "disk space back: raw recording resumed");
        }
        self.low
    }
}

/// How long recording pauses after a write error (or a session that cannot be started)
/// before it tries again.
const WRITE_RETRY: Duration = Duration::from_secs(5);

/// Free bytes needed before recording tries again after a write error (statvfs, checked at
/// each try): a disk that is still full is not worth a new chunk.
const RESUME_FREE_BYTES: u64 = 8 << 20;

/// What the recorder branch of a live run shows while it runs (the daemon's status and
/// metrics read it; the recorder thread writes it).
#[derive(Debug, Default)]
pub struct RecorderGauges {
    /// Encoded frame bytes written, all chunks (it only grows: bytes of a chunk gone from the
    /// run's directory later are counted in `lost_bytes` as well).
    pub frame_bytes: AtomicU64,
    /// Of `frame_bytes`, those of chunks whose session was removed or moved away under the
    /// recorder, by reason (`removed`, `moved`).
    pub lost_bytes: Mutex<BTreeMap<&'static str, u64>>,
    /// Free bytes on the output's file system at the last check (once a second).
    pub disk_free_bytes: AtomicU64,
    /// Raw recording paused (disk low, or after a write error).
    pub paused: AtomicBool,
    /// Session events (a camera's gap or outage, a pause) not yet written, waiting for room.
    pub events_waiting: AtomicU64,
    /// Session events never written: more waited than [`EVENTS_WAITING_MAX`], or the run
    /// ended before there was room.
    pub events_lost: AtomicU64,
}

/// The most session events that wait for room on the disk; beyond it, the newest are counted
/// as lost (an hour of a camera's gaps every second while the disk is full is about 3,600).
pub const EVENTS_WAITING_MAX: usize = 4096;

/// The sessions closed in a run directory: the directory (open, to tell when it is moved away
/// or removed), its path, and their frames (depth, colour) and bytes.
#[derive(Debug)]
struct ClosedHere {
    dir: std::fs::File,
    root: PathBuf,
    frames: [u64; 2],
    bytes: u64,
}

/// The recorder branch of a live run: frames into the current chunk's session.
#[derive(Debug)]
pub struct ChunkRecorder {
    chunks: Arc<Chunks>,
    index: usize,
    writer: Option<SessionWriter>,
    /// Frame bytes of the current writer already added to the gauges.
    counted: u64,
    disk: DiskWatch,
    /// Set after a write error: nothing is written before then.
    paused_until: Option<Instant>,
    /// The session broke after frames were written in it: the next try begins a new chunk.
    /// Otherwise (no session, or one without a frame) it starts a session in this chunk.
    broken: bool,
    /// While recording is paused: the host time of the first frame not recorded, and why.
    /// A pause is logged once when it begins and once when it ends, and both go into the
    /// `events.jsonl` of the session recording resumes in (`recording_paused`,
    /// `recording_resumed`): the one it paused in may not be writable.
    paused: Option<(u64, &'static str)>,
    /// Frames counted as recorded in a session whose files were removed or moved away since,
    /// per camera and reason, not yet handed to the accounting
    /// ([`crate::runtime::sink::session::FrameRecorder::take_lost`]).
    lost: Vec<(CameraRole, &'static str, u64)>,
    /// Sessions (with their chunks) that could not be closed, the disk full: closed once
    /// frames are written again, or at the end.
    unclosed: Vec<(usize, SessionWriter)>,
    /// The sessions closed in the run directory as it is now: when it is moved away (or
    /// removed), they went with it, as the session being written did.
    closed_here: Option<ClosedHere>,
    /// Session events not yet written (the disk full, or no session open), oldest first:
    /// written into the current session as soon as one takes them.
    waiting: std::collections::VecDeque<SessionEvent>,
    cameras: Vec<SharedHealth>,
    gauges: Arc<RecorderGauges>,
}

impl ChunkRecorder {
    pub fn new(chunks: Arc<Chunks>, disk: DiskWatch, cameras: Vec<SharedHealth>, gauges: Arc<RecorderGauges>) -> Self {
        Self {
            chunks,
            index: usize::MAX,
            writer: None,
            counted: 0,
            disk,
            paused_until: None,
            broken: false,
            paused: None,
            lost: Vec::new(),
            unclosed: Vec::new(),
            closed_here: None,
            waiting: std::collections::VecDeque::new(),
            cameras,
            gauges,
        }
    }

    /// Queues a session event; when [`EVENTS_WAITING_MAX`] already wait, it is counted as lost.
    fn wait_to_log(&mut self, event: SessionEvent) {
        if self.waiting.len() < EVENTS_WAITING_MAX {
            self.waiting.push_back(event);
        } else {
            let lost_before = self.gauges.events_lost.fetch_add(1, Ordering::Relaxed);
            if lost_before == 0 {
                tracing::error!(
                    waiting = EVENTS_WAITING_MAX,
                    "session events are lost: too many wait for room on the disk (counted in \
                     mousepose_session_events_lost_total)"
                );
            }
        }
        self.gauges
            .events_waiting
            .store(self.waiting.len() as u64, Ordering::Relaxed);
    }

    /// Writes the waiting events into the current session, oldest first, until one cannot be
    /// written (a full disk: it waits on; one the session took whole into its buffer before
    /// failing is written with the buffer, so it is not written twice). Nothing is tried
    /// without a session or while recording waits after a write error.
    fn log_waiting(&mut self) {
        if self.paused_until.is_some_and(|t| Instant::now() < t) {
            return;
        }
        let Some(w) = &mut self.writer else {
            return;
        };
        while let Some(event) = self.waiting.front() {
            let before = w.events_logged();
            match w.log_event(event) {
                Ok(()) => {}
                Err(e) => {
                    if matches!(e, SessionError::EventEncode { .. }) {
                        // Never written, whatever the room: lost (no event of ours fails so).
                        tracing::error!("a session event is lost: {}", error_chain(&e));
                        self.gauges.events_lost.fetch_add(1, Ordering::Relaxed);
                        self.waiting.pop_front();
                        continue;
                    }
                    if w.events_logged() > before {
                        self.waiting.pop_front();
                    }
                    tracing::debug!(
                        chunk = self.index,
                        waiting = self.waiting.len(),
                        "session events wait for room: {}",
                        error_chain(&e)
                    );
                    break;
                }
            }
            self.waiting.pop_front();
        }
        self.gauges
            .events_waiting
            .store(self.waiting.len() as u64, Ordering::Relaxed);
    }

    /// Starts a session in the current chunk, which has none (its start failed, or the one
    /// it had broke before its first frame); `false` when it cannot, and then pauses.
    fn start_here(&mut self, host_ns: u64) -> bool {
        match self.chunks.new_session(self.index, host_ns) {
            Ok(w) => {
                self.writer = Some(w);
                self.counted = 0;
                true
            }
            Err(e) => {
                self.pause_on_error(
                    host_ns,
                    &format!("cannot start the chunk's session: {}", error_chain(&e)),
                );
                false
            }
        }
    }

    /// Pauses recording after a write error for [`WRITE_RETRY`]; logs the pause when it
    /// begins (later errors of the same pause at debug level).
    fn pause_on_error(&mut self, host_ns: u64, why: &str) {
        if self.paused.is_none() {
            tracing::error!(
                chunk = self.index,
                retry_s = WRITE_RETRY.as_secs(),
                "recording paused: {why}"
            );
            self.paused = Some((host_ns, "write_error"));
        } else {
            tracing::debug!(chunk = self.index, "recording still paused: {why}");
        }
        self.paused_until = Some(Instant::now() + WRITE_RETRY);
    }

    /// The frame at `host_ns` is the first recorded after a pause: the pause and its end go
    /// into the session, and the end into the log (a pause for low disk space is logged by
    /// [`DiskWatch`]).
    fn log_resume(&mut self, host_ns: u64) {
        let (Some((since_ns, reason)), Some(_)) = (self.paused, &self.writer) else {
            return;
        };
        self.wait_to_log(SessionEvent::RecordingPaused {
            host_ns: since_ns,
            reason: reason.to_owned(),
        });
        self.wait_to_log(SessionEvent::RecordingResumed { host_ns });
        if reason != "disk_low" {
            tracing::info!(
                chunk = self.index,
                paused_s = host_ns.saturating_sub(since_ns) as f64 * 1e-9,
                "recording resumed"
            );
        }
        self.paused = None;
    }

    /// Brings the gauges up to date after a frame was offered.
    fn update_gauges(&mut self, paused: bool) {
        if let Some(w) = &self.writer {
            let bytes = w.frame_bytes();
            self.gauges
                .frame_bytes
                .fetch_add(bytes.saturating_sub(self.counted), Ordering::Relaxed);
            self.counted = bytes;
        }
        if let Some(free) = self.disk.free_bytes() {
            self.gauges.disk_free_bytes.store(free, Ordering::Relaxed);
        }
        self.gauges.paused.store(paused, Ordering::Relaxed);
    }

    /// Closes the current chunk's session cleanly.
    fn close(&mut self) -> Option<SessionSummary> {
        let writer = self.writer.take()?;
        self.close_or_keep(self.index, writer)
    }

    /// Closes a session; one that cannot be closed now (a full disk) is kept and closed later
    /// ([`ChunkRecorder::close_unclosed`]), so that every chunk ends closed.
    fn close_or_keep(&mut self, index: usize, mut writer: SessionWriter) -> Option<SessionSummary> {
        let held = [writer.depth_frames(), writer.color_frames(), writer.frame_bytes()];
        match writer.close() {
            Ok(s) => {
                self.note_closed(index, held);
                Some(s)
            }
            Err(e) => {
                tracing::warn!(
                    chunk = index,
                    "cannot close the chunk's session yet (tried again once frames are written \
                     again): {}",
                    error_chain(&e)
                );
                self.unclosed.push((index, writer));
                None
            }
        }
    }

    /// Closes the sessions left unclosed (a full disk), now that there is room; one removed or
    /// moved away meanwhile is counted as lost, as the current one is.
    fn close_unclosed(&mut self) {
        for (index, writer) in std::mem::take(&mut self.unclosed) {
            if let Some(gone) = writer.gone() {
                let bytes = writer.frame_bytes();
                self.forget(index, writer, gone, bytes);
            } else if self.close_or_keep(index, writer).is_some() {
                tracing::info!(chunk = index, "the chunk's session closed, the disk having room again");
            }
        }
    }

    fn switch(&mut self, index: usize) {
        self.update_gauges(false);
        self.close();
        self.index = index;
        self.writer = self.chunks.take_writer(index);
        self.counted = 0;
        self.broken = false;
    }

    /// The cameras' events (openings, outages) into the queue of events waiting, which the
    /// session takes when it can (without one, recording paused, they wait for the next, so
    /// that a chunk begun on a full disk still gets them).
    fn log_camera_events(&mut self) {
        let mut taken = Vec::new();
        let Ok(()) = crate::runtime::capture::supervise::log_camera_events(&self.cameras, |e| {
            taken.push(e.clone());
            Ok::<(), std::convert::Infallible>(())
        });
        for event in taken {
            self.wait_to_log(event);
        }
    }

    /// When the current session's files were removed under the recorder (its chunk's
    /// directory deleted) or moved away (the run directory renamed): its frames are gone from
    /// the run's directory, so counted as lost after recording (`removed`, `moved`; they stay
    /// counted as recorded), and nothing more is written into it; recording goes on in a new
    /// chunk at once, in the run directory made again (or pauses if that cannot be created).
    fn check_removed(&mut self, host_ns: u64) {
        if self.forget_gone() {
            let index = self.chunks.replace(self.index, host_ns);
            self.switch(index);
        } else if self.writer.is_none() {
            // No session to find gone (recording paused): the run directory may be.
            self.forget_closed_here();
        }
    }

    /// Whether the current session is gone (removed or moved away); if so its frames are
    /// counted as lost after recording and it is dropped, never closed into where it went.
    fn forget_gone(&mut self) -> bool {
        let Some(gone) = self.writer.as_ref().and_then(SessionWriter::gone) else {
            return false;
        };
        let Some(w) = self.writer.take() else {
            return false;
        };
        let bytes = std::mem::take(&mut self.counted);
        self.forget(self.index, w, gone, bytes);
        true
    }

    /// Adds a session closed in chunk `index` (its depth and colour frames, and bytes) to those
    /// of the run directory as it is now, which is opened the first time.
    fn note_closed(&mut self, index: usize, [depth, color, bytes]: [u64; 3]) {
        if self.closed_here.is_none() {
            let Some(root) = self.chunks.dir(index).parent().map(Path::to_path_buf) else {
                return;
            };
            match std::fs::File::open(&root) {
                Ok(dir) => {
                    self.closed_here = Some(ClosedHere {
                        dir,
                        root,
                        frames: [0; 2],
                        bytes: 0,
                    });
                }
                // Unseen, a move of it leaves these frames counted where they no longer are.
                Err(e) => tracing::warn!("cannot watch the run directory {root:?} for a move: {e}"),
            }
        }
        if let Some(c) = &mut self.closed_here {
            c.frames[0] += depth;
            c.frames[1] += color;
            c.bytes += bytes;
        }
    }

    /// After a session was found gone: when the run directory it was in is gone too (moved
    /// away, or removed), so are the sessions closed in it, counted as lost after recording.
    fn forget_closed_here(&mut self) {
        let Some(gone) = self.closed_here.as_ref().and_then(|c| crate::io::gone(&c.dir, &c.root)) else {
            return;
        };
        let Some(c) = self.closed_here.take() else {
            return;
        };
        let reason = gone.reason();
        tracing::info!(
            depth_frames = c.frames[0],
            color_frames = c.frames[1],
            "the run directory went with its closed chunks too ({reason}): their frames are counted as lost after recording"
        );
        self.lost.extend([
            (CameraRole::Depth, reason, c.frames[0]),
            (CameraRole::Color, reason, c.frames[1]),
        ]);
        *self
            .gauges
            .lost_bytes
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .entry(reason)
            .or_default() += c.bytes;
    }

    /// Counts the frames of a session that is gone (and `bytes` of it that the gauges have
    /// counted) as lost after recording, and drops it; so are the sessions closed in its run
    /// directory, when that went with it.
    fn forget(&mut self, index: usize, w: SessionWriter, gone: crate::io::Gone, bytes: u64) {
        let (depth, color) = (w.depth_frames(), w.color_frames());
        let reason = gone.reason();
        match gone {
            crate::io::Gone::Removed => tracing::error!(
                chunk = index,
                depth_frames = depth,
                color_frames = color,
                "the chunk's session was removed from the disk: its frames are lost (counted as lost \
                 after recording: removed); recording goes on in a new chunk"
            ),
            crate::io::Gone::Moved => tracing::info!(
                chunk = index,
                depth_frames = depth,
                color_frames = color,
                "the chunk's session was moved away: nothing more is written into it (its frames \
                 counted as lost after recording: moved); recording goes on in a new chunk"
            ),
        }
        drop(w);
        self.lost
            .extend([(CameraRole::Depth, reason, depth), (CameraRole::Color, reason, color)]);
        self.forget_closed_here();
        *self
            .gauges
            .lost_bytes
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .entry(reason)
            .or_default() += bytes;
    }

    /// Writes `frame` into its chunk's session, or says why not.
    fn write_frame(&mut self, frame: &Captured) -> Result<Option<&'static str>, SessionError> {
        let host_ns = frame.stamp().host_ns;
        let role = match frame {
            Captured::Depth(_) => CameraRole::Depth,
            Captured::Color(_) => CameraRole::Color,
        };
        if self.paused_until.is_some_and(|t| Instant::now() < t) {
            return Ok(Some("write_error"));
        }
        let retry = self.paused_until.is_some();
        if retry {
            // A disk still full is not tried (nor is a new chunk begun on it).
            self.disk.low();
            if self.disk.free_bytes().is_some_and(|free| free < RESUME_FREE_BYTES) {
                self.paused_until = Some(Instant::now() + WRITE_RETRY);
                return Ok(Some("write_error"));
            }
            self.paused_until = None;
        }
        if self.index != usize::MAX {
            self.check_removed(host_ns);
        }
        let mut index = self.chunks.at(host_ns);
        // A chunk begun while recording was paused serves as the new chunk.
        let broken = retry && std::mem::take(&mut self.broken) && index <= self.index;
        if broken || (self.index != usize::MAX && self.writer.as_ref().is_some_and(|w| !w.has_camera(role))) {
            // After a write error in a session with frames, or for a camera the chunk's
            // session does not hold (one that opened after the chunk began): a new chunk.
            index = self.chunks.split(host_ns);
        }
        if self.index == usize::MAX || index > self.index {
            self.switch(index);
        }
        if self.disk.low() {
            return Ok(Some("disk_low"));
        }
        if self.writer.is_none() && !self.start_here(host_ns) {
            return Ok(Some("write_error"));
        }
        self.log_camera_events();
        self.log_resume(host_ns);
        self.log_waiting();
        let result = match &mut self.writer {
            Some(w) => crate::runtime::sink::session::FrameRecorder::write(w, frame).map(|_| true),
            None => Ok(false),
        };
        match result {
            Ok(true) => {
                if !self.unclosed.is_empty() {
                    self.close_unclosed();
                }
                Ok(None)
            }
            Ok(false) => Ok(Some("write_error")),
            Err(e) => {
                // The frames written so far stay readable: the store appends whole records.
                // A session without a frame is removed (its chunk gets a session again when
                // the disk has room); one with frames is kept and the next try begins a new
                // chunk.
                self.pause_on_error(host_ns, &error_chain(&e));
                if let Some(w) = self.writer.take() {
                    if w.depth_frames() + w.color_frames() == 0 {
                        if let Err(e) = w.abandon() {
                            tracing::warn!(
                                chunk = self.index,
                                "cannot remove the session without frames: {}",
                                error_chain(&e)
                            );
                        }
                    } else {
                        // Closed once the disk has room: its whole frames kept.
                        self.broken = true;
                        self.unclosed.push((self.index, w));
                    }
                }
                Ok(Some("write_error"))
            }
        }
    }
}

impl crate::runtime::sink::session::FrameRecorder for ChunkRecorder {
    fn write(&mut self, frame: &Captured) -> Result<Option<&'static str>, SessionError> {
        let outcome = self.write_frame(frame);
        if let Ok(Some(reason)) = &outcome {
            self.paused.get_or_insert((frame.stamp().host_ns, reason));
        }
        self.update_gauges(matches!(outcome, Ok(Some(_))));
        outcome
    }

    /// Never fails: an event the disk has no room for waits ([`ChunkRecorder::log_waiting`]).
    fn log_event(&mut self, event: &SessionEvent) -> Result<(), SessionError> {
        self.wait_to_log(event.clone());
        self.log_waiting();
        Ok(())
    }

    fn take_lost(&mut self) -> Vec<(CameraRole, &'static str, u64)> {
        std::mem::take(&mut self.lost)
    }

    fn notice_gone(&mut self) {
        self.forget_gone();
        self.forget_closed_here();
    }

    fn finish(mut self: Box<Self>) -> Result<Option<SessionSummary>, SessionError> {
        // Events of a camera lost at the very end still belong to the last chunk.
        self.log_camera_events();
        self.log_waiting();
        if !self.waiting.is_empty() {
            tracing::error!(
                events = self.waiting.len(),
                "session events never written (the disk full to the end): counted in \
                 mousepose_session_events_lost_total"
            );
            self.gauges
                .events_lost
                .fetch_add(self.waiting.len() as u64, Ordering::Relaxed);
            self.waiting.clear();
            self.gauges.events_waiting.store(0, Ordering::Relaxed);
        }
        // The sessions left by a full disk earlier, then the current one: each tried once.
        self.close_unclosed();
        let summary = self.close();
        for (index, _) in &self.unclosed {
            tracing::error!(
                chunk = index,
                "the chunk's session is left unclosed (the disk is full): its whole frames read back, \
                 its indexes are made again when it is read"
            );
        }
        Ok(summary)
    }
}

/// What `summary.json` of a chunk says.
#[derive(Debug, Serialize)]
pub struct ChunkSummary {
    pub chunk: usize,
    pub rows: u64,
    pub statuses: BTreeMap<&'static str, u64>,
    /// Host times (ns) of the first and last pose.
    pub first_host_ns: Option<u64>,
    pub last_host_ns: Option<u64>,
    /// Rows that could not be written.
    pub rows_lost: u64,
    pub software_version: &'static str,
    pub body_model: PathBuf,
    pub paw_model: Option<PathBuf>,
    /// Which models made the poses: their directory and each file's hash.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub models: Option<crate::runtime::models::ModelsUsed>,
    /// In how many of its frames with a heading chosen a tail was seen (as a replay's
    /// `summary.json` says); absent when no frame had a mouse.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tails: Option<TailsSeen>,
}

/// The latest pose and counts, for the status line (and the live page).
#[derive(Clone, Debug, Default)]
pub struct Live {
    /// Poses made, and those of them that could not be written (disk full, write error).
    pub rows: u64,
    pub rows_lost: u64,
    pub latest: Option<PoseRecord>,
    /// The latest pose's frames (shared with the pipeline, not copied).
    pub frames: Option<FramePair>,
    /// While the latest pose has no colour frame: the latest one that had, and its frames, for
    /// the bottom view (one depth frame paired with no colour frame does not blank the
    /// operator's picture). Kept by moving the latest pose here, never by copying it.
    pub with_color: Option<(PoseRecord, FramePair)>,
    pub statuses: BTreeMap<&'static str, u64>,
    pub chunk: usize,
}

impl Live {
    /// Makes `record` the latest pose; the one before it stays for the bottom view when it had
    /// a colour frame and `record` has none.
    pub fn set_latest(&mut self, record: PoseRecord, frames: FramePair) {
        let previous = (self.latest.replace(record), self.frames.replace(frames));
        if self.frames.as_ref().is_some_and(|f| f.color.is_some()) {
            self.with_color = None;
        } else if let (Some(record), Some(frames)) = previous
            && frames.color.is_some()
        {
            self.with_color = Some((record, frames));
        }
    }

    /// The latest pose that had a colour frame, and its frames.
    pub fn latest_with_color(&self) -> Option<(PoseRecord, FramePair)> {
        match (&self.latest, &self.frames) {
            (Some(record), Some(frames)) if frames.color.is_some() => Some((record.clone(), frames.clone())),
            _ => self.with_color.clone(),
        }
    }
}

/// The pose sink of a live run: `poses.csv` of the current chunk, and the live status.
#[derive(Debug)]
pub struct ChunkPoses {
    chunks: Arc<Chunks>,
    index: usize,
    writer: Option<PoseWriter>,
    /// The current chunk's tally, kept when its `poses.csv` breaks.
    tally: Option<Arc<Mutex<PoseTally>>>,
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    rows_lost: u64,
    /// Set when the current chunk's `poses.csv` could not be created or broke: no rows are
    /// written before then, when it is tried again (see [`ChunkPoses::try_again`]).
    retry_at: Option<Instant>,
    live: Arc<Mutex<Live>>,
    /// Summaries of closed chunks that could not be written yet (a full disk), with when
    /// they were last tried: tried again every [`SUMMARY_RETRY`] and at the end.
    unwritten: Vec<(PathBuf, Vec<u8>)>,
    tried: Option<Instant>,
}

/// How often summaries that could not be written are tried again.
const SUMMARY_RETRY: Duration = Duration::from_secs(1);

/// Writes `bytes` to `path` whole or not at all: into a hidden file beside it, renamed into
/// place (a full disk leaves no empty or cut file behind).
///
/// # Errors
/// The file cannot be written or renamed (the hidden file is removed then).
pub fn write_whole(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.partial-{}", std::process::id()));
    let written = std::fs::File::create(&tmp).and_then(|mut f| {
        std::io::Write::write_all(&mut f, bytes)?;
        f.sync_all()
    });
    let result = written.and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

impl ChunkPoses {
    pub fn new(chunks: Arc<Chunks>, live: Arc<Mutex<Live>>) -> Self {
        Self {
            chunks,
            index: usize::MAX,
            writer: None,
            tally: None,
            first_ns: None,
            last_ns: None,
            rows_lost: 0,
            retry_at: None,
            live,
            unwritten: Vec::new(),
            tried: None,
        }
    }

    /// Tries again to write the summaries that could not be written; `force`: now, whenever
    /// the last try was.
    fn write_unwritten(&mut self, force: bool) {
        if self.unwritten.is_empty() || (!force && self.tried.is_some_and(|t| t.elapsed() < SUMMARY_RETRY)) {
            return;
        }
        self.tried = Some(Instant::now());
        self.unwritten.retain(|(path, text)| match write_whole(path, text) {
            Ok(()) => {
                tracing::info!("{path:?} written after all");
                false
            }
            Err(e) => {
                if force {
                    tracing::error!("cannot write {path:?}: {e}");
                }
                true
            }
        });
    }

    /// Finishes the current chunk's `poses.csv` and writes its `summary.json`.
    fn close(&mut self) {
        if self.index == usize::MAX || self.forget_removed() {
            return;
        }
        if let Some(mut w) = self.writer.take() {
            if let Err(e) = w.flush() {
                tracing::error!(chunk = self.index, "cannot finish poses.csv: {e}");
            }
        }
        self.retry_at = None;
        let tally = self
            .tally
            .take()
            .map(|t| t.lock().unwrap_or_else(PoisonError::into_inner).clone())
            .unwrap_or_default();
        let summary = ChunkSummary {
            chunk: self.index,
            rows: tally.rows,
            statuses: tally.statuses,
            first_host_ns: self.first_ns.take(),
            last_host_ns: self.last_ns.take(),
            rows_lost: std::mem::take(&mut self.rows_lost),
            software_version: env!("CARGO_PKG_VERSION"),
            body_model: self.chunks.plan.body_model.clone(),
            paw_model: self.chunks.plan.paw_model.clone(),
            models: self.chunks.plan.models.clone(),
            tails: (tally.tails.frames > 0).then_some(tally.tails),
        };
        let path = self.chunks.dir(self.index).join(CHUNK_SUMMARY_FILE);
        match serde_json::to_vec_pretty(&summary) {
            Ok(text) => {
                if let Err(e) = write_whole(&path, &text) {
                    tracing::error!(
                        chunk = self.index,
                        "cannot write {path:?} (tried again while the run goes on): {e}"
                    );
                    self.unwritten.push((path, text));
                    self.tried = Some(Instant::now());
                }
            }
            Err(e) => tracing::error!(chunk = self.index, "cannot write {path:?}: {e}"),
        }
        tracing::info!(chunk = self.index, rows = summary.rows, "chunk closed");
    }

    fn open(&mut self, index: usize) {
        self.close();
        self.close_empty_until(index);
        self.index = index;
        self.create();
    }

    /// Gives each chunk begun before `index` that no pose reached (begun by the recorder, as
    /// when a camera came back, and ended before a pose of its time came out) its empty
    /// `poses.csv` and its `summary.json`: a chunk without a pose is a complete chunk too.
    fn close_empty_until(&mut self, index: usize) {
        let first = self.index.wrapping_add(1);
        for empty in first..index {
            self.index = empty;
            self.create();
            self.close();
        }
    }

    /// Creates the current chunk's `poses.csv` and `poses_raw.csv` (anew: what was there holds
    /// no row); on failure, tries again later.
    fn create(&mut self) {
        let dir = self.chunks.dir(self.index);
        let made = self.chunks.make_dir(self.index);
        match made
            .and_then(|dir| PoseWriter::create(&dir, HashMap::new(), u64::MAX, self.chunks.plan.mice))
            .and_then(PoseWriter::with_raw_file)
            .and_then(PoseWriter::handing_over_each_row)
        {
            Ok(w) => {
                if self.retry_at.take().is_some() || self.rows_lost > 0 {
                    tracing::info!(chunk = self.index, "poses written again");
                }
                self.tally = Some(w.tally());
                self.writer = Some(w);
            }
            Err(e) => {
                if self.retry_at.is_none() {
                    tracing::error!(chunk = self.index, "cannot create poses.csv in {dir:?}: {e}");
                }
                self.retry_at = Some(Instant::now() + WRITE_RETRY);
            }
        }
    }

    /// After `poses.csv` could not be created or broke, once its time has come and the disk
    /// has room: a new chunk when the broken file holds rows (a cut last row cannot be
    /// appended to), otherwise the file created again in this chunk.
    fn try_again(&mut self, host_ns: u64) {
        if self.writer.is_some() || self.retry_at.is_none_or(|t| Instant::now() < t) {
            return;
        }
        let dir = self.chunks.dir(self.index);
        let free = rustix::fs::statvfs(&dir).map(|st| st.f_bavail.saturating_mul(st.f_frsize));
        if free.is_ok_and(|free| free < RESUME_FREE_BYTES) {
            self.retry_at = Some(Instant::now() + WRITE_RETRY);
            return;
        }
        if holds_rows(&dir.join(crate::runtime::sink::poses::POSES_FILE)) {
            let index = self.chunks.split(host_ns);
            self.open(index);
        } else {
            self.create();
        }
    }
}

impl ChunkPoses {
    /// When the current chunk's `poses.csv` was removed under the run (its directory
    /// deleted): its rows are lost, so counted as not written, and the chunk (whose summary
    /// could only lie) is left without one; poses go on in a new chunk at once (or are tried
    /// again later if it cannot be created). Likewise when it was moved away (the run
    /// directory renamed), but its rows, where it went, stay counted as written.
    fn check_removed(&mut self, host_ns: u64) {
        if self.forget_removed() {
            self.index = self.chunks.replace(self.index, host_ns);
            self.create();
        }
    }

    /// Whether the current chunk's `poses.csv` was removed or moved away under the run; if so
    /// the chunk is forgotten (no summary: it could only lie, or land where the run is not),
    /// and the rows of a removed one are counted as not written.
    fn forget_removed(&mut self) -> bool {
        let Some(gone) = self.writer.as_ref().and_then(PoseWriter::gone) else {
            return false;
        };
        self.writer = None;
        let rows = self
            .tally
            .take()
            .map_or(0, |t| t.lock().unwrap_or_else(PoisonError::into_inner).rows);
        match gone {
            crate::io::Gone::Removed => {
                tracing::error!(
                    chunk = self.index,
                    rows,
                    "poses.csv was removed from the disk: its rows are lost (counted as not written); poses go on in a new chunk"
                );
                self.live.lock().unwrap_or_else(PoisonError::into_inner).rows_lost += rows;
            }
            crate::io::Gone::Moved => tracing::info!(
                chunk = self.index,
                rows,
                "poses.csv was moved away: nothing more is written into it; poses go on in a new chunk"
            ),
        }
        (self.first_ns, self.last_ns, self.rows_lost, self.retry_at) = (None, None, 0, None);
        true
    }
}

/// Whether the `poses.csv` at `path` holds a row after its header (looking at its start only).
fn holds_rows(path: &Path) -> bool {
    use std::io::Read as _;
    let mut start = Vec::new();
    let read = std::fs::File::open(path).and_then(|f| f.take(1 << 16).read_to_end(&mut start));
    read.is_ok() && start.iter().filter(|&&b| b == b'\n').count() >= 2
}

impl Sink for ChunkPoses {
    type In = Fused;

    fn write(&mut self, item: Fused) -> Result<(), StageError> {
        self.write_unwritten(false);
        let host_ns = item.record.depth.host_ns;
        self.check_removed(host_ns);
        let index = self.chunks.at(host_ns);
        if self.index == usize::MAX || index > self.index {
            self.open(index);
        }
        self.try_again(host_ns);
        self.first_ns.get_or_insert(host_ns);
        self.last_ns = Some(host_ns);
        let record = item.record.clone();
        let frames = item.frames.clone();
        let written = match &mut self.writer {
            Some(w) => w.write(item),
            None => Err("no poses.csv open".into()),
        };
        if let Err(e) = written {
            if self.rows_lost == 0 {
                tracing::error!(chunk = self.index, "cannot write poses: {e}");
            }
            self.rows_lost += 1;
            if self.writer.take().is_some() {
                // Tried again once the disk has room (see `try_again`).
                self.retry_at = Some(Instant::now() + WRITE_RETRY);
            }
        }
        let lost = self.writer.is_none();
        let mut live = self.live.lock().unwrap_or_else(PoisonError::into_inner);
        live.rows += 1;
        live.rows_lost += u64::from(lost);
        *live.statuses.entry(record.status.name()).or_default() += 1;
        live.set_latest(record, frames);
        live.chunk = self.index;
        Ok(())
    }

    fn flush(&mut self) -> Result<(), StageError> {
        self.close();
        self.close_empty_until(self.chunks.count());
        self.write_unwritten(true);
        Ok(())
    }
}

/// The metadata every chunk's session starts from (cameras and start time are added per
/// chunk).
pub fn chunk_meta(
    notes: String,
    rig: Option<crate::core::geometry::Rig>,
    color_latency_ns: Option<i64>,
) -> SessionMeta {
    let mut meta = SessionMeta::new(String::new(), SessionSource::Recorded, Vec::new());
    meta.notes = notes;
    meta.rig = rig;
    meta.color_latency_ns = color_latency_ns;
    meta
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::{ColorFrame, DepthFrame, PixelFormat, Stamp};
    use crate::core::pose::Pose;
    use crate::runtime::pose_record::PoseStatus;

    /// Pose `seq` and its frames, with a colour frame when `color`.
    fn pose(seq: u64, color: bool) -> (PoseRecord, FramePair) {
        let stamp = Stamp {
            seq,
            device_ns: seq,
            host_ns: seq,
        };
        let color = color.then(|| {
            Arc::new(ColorFrame {
                stamp,
                width: 1,
                height: 1,
                format: PixelFormat::Mono8,
                data: vec![0],
            })
        });
        let record = PoseRecord {
            depth: stamp,
            color: color.as_ref().map(|c| c.stamp),
            skew_ns: 0,
            status: PoseStatus::Ok,
            pose: Pose::default(),
            paws: Vec::new(),
            headings: None,
            orientation: None,
            raw_body: None,
            velocities: None,
            identity: None,
        };
        let frames = FramePair {
            color_again: false,
            depth: Arc::new(DepthFrame {
                stamp,
                width: 1,
                height: 1,
                data: vec![0],
            }),
            color,
            skew_ns: 0,
        };
        (record, frames)
    }

    #[test]
    fn the_bottom_view_keeps_the_latest_pose_that_had_a_colour_frame() {
        let mut live = Live::default();
        let seq = |live: &Live| live.latest_with_color().map(|(r, _)| r.depth.seq);
        assert_eq!(seq(&live), None);
        let (r, f) = pose(1, false);
        live.set_latest(r, f);
        assert_eq!(seq(&live), None, "no colour frame yet");
        for (n, color, expected) in [(2, true, 2), (3, false, 2), (4, false, 2), (5, true, 5), (6, false, 5)] {
            let (r, f) = pose(n, color);
            live.set_latest(r, f);
            assert_eq!(seq(&live), Some(expected), "after pose {n}");
            assert_eq!(live.latest.as_ref().map(|r| r.depth.seq), Some(n));
        }
        // While the latest pose has its colour frame, nothing else is held.
        let (r, f) = pose(7, true);
        live.set_latest(r, f);
        assert!(live.with_color.is_none());
    }

    /// Issue 48: a chunk that no pose reached (begun by the recorder, as when a camera came
    /// back, and over before a pose of its time came out) is complete with an empty
    /// `poses.csv` and its `summary.json`, in the middle of a run and at its end.
    #[test]
    fn a_chunk_no_pose_reached_is_complete_with_its_summary() {
        let tmp = tempfile::tempdir().unwrap();
        let chunks = Chunks::new(ChunkPlan {
            root: tmp.path().to_owned(),
            period: Duration::from_secs(3600),
            record: false,
            cameras: Vec::new(),
            meta: chunk_meta(String::new(), None, None),
            body_model: PathBuf::from("body.forest"),
            paw_model: None,
            models: None,
            mice: 1,
        });
        let mut sink = ChunkPoses::new(Arc::clone(&chunks), Arc::default());
        let write = |sink: &mut ChunkPoses, seq| {
            let (record, frames) = pose(seq, false);
            sink.write(Fused {
                record,
                others: Vec::new(),
                frames,
                overlay: None,
            })
            .unwrap();
        };
        write(&mut sink, 10);
        let (mut record, frames) = pose(11, false);
        record.orientation = Some(crate::vision::orientation::Orientation {
            confidence: 1.0,
            frame_alone: None,
            forest: None,
            shape: None,
            tail: Some(nalgebra::Vector2::x()),
        });
        sink.write(Fused {
            record,
            others: Vec::new(),
            frames,
            overlay: None,
        })
        .unwrap();
        // The recorder begins chunks 1 and 2 (a camera back twice); poses go on in chunk 2.
        assert_eq!(chunks.split(20), 1);
        assert_eq!(chunks.split(30), 2);
        write(&mut sink, 31);
        // And chunk 3, just before the end.
        assert_eq!(chunks.split(40), 3);
        sink.flush().unwrap();
        let summaries: Vec<serde_json::Value> = (0..4)
            .map(|k| {
                let dir = chunks.dir(k);
                let lines = std::fs::read_to_string(dir.join("poses.csv")).unwrap().lines().count() as u64;
                let summary: serde_json::Value =
                    serde_json::from_slice(&std::fs::read(dir.join(CHUNK_SUMMARY_FILE)).unwrap()).unwrap();
                assert_eq!(summary["rows"].as_u64(), Some(lines - 1), "chunk {k}");
                // Issue 49: the joints before smoothing beside them, row for row, as a replay.
                let raw = std::fs::read_to_string(dir.join(crate::runtime::sink::poses::RAW_POSES_FILE)).unwrap();
                assert_eq!(raw.lines().count() as u64, lines, "chunk {k}");
                summary
            })
            .collect();
        let rows: Vec<u64> = summaries.iter().map(|s| s["rows"].as_u64().unwrap()).collect();
        assert_eq!(rows, [2, 0, 1, 0]);
        // Issue 49: a chunk says in how many frames a tail was seen, as a replay does; not
        // at all without a frame with a heading.
        assert_eq!(summaries[0]["tails"], serde_json::json!({"frames": 1, "seen": 1}));
        assert!(summaries[2].get("tails").is_none());
    }
}
