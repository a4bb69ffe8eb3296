//! A recorded session read as a camera pair: both cameras' frames merged in the order they
//! reached the host (`host_ns`), as fast as possible or at the recorded pace.
//!
//! Deterministic: the frames come out in the same order on every run, and the replay clock
//! is moved to each frame's recorded host time as it is delivered.

use super::backend::{self, Backend, CameraConfig, DepthBackend, DepthConfig, TableError};
use super::{CaptureError, Captured, Clock, FrameSource};
use crate::core::frame::{ColorFrame, DepthFrame};
use crate::io::session::meta::{CameraMeta, CameraRole};
use crate::io::session::{ColorFrames, DepthFrames};
use crate::io::session::{SessionError, SessionReader};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Both cameras of a session, merged by host arrival time.
#[derive(Debug)]
pub struct SessionPlayer {
    dir: PathBuf,
    meta: Vec<CameraMeta>,
    depth: DepthFrames,
    color: Option<ColorFrames>,
    next_depth: Option<DepthFrame>,
    next_color: Option<ColorFrame>,
    realtime: bool,
    /// Wall instant and recorded host time of the first frame (pacing).
    start: Option<(Instant, u64)>,
    clock: Option<Clock>,
    corrupt: [u64; 2],
    /// The size depth frames must have (what the background model covers); `None`: any.
    depth_size: Option<(u32, u32)>,
    /// Depth frames of another size, skipped (a live run's `wrong_size`).
    wrong_size: u64,
    done: bool,
}

impl SessionPlayer {
    /// A source over an open session. With `realtime`, frames come out at the pace they were
    /// recorded; otherwise as fast as they can be read.
    pub fn new(reader: &SessionReader, realtime: bool) -> Self {
        Self {
            dir: reader.dir().to_path_buf(),
            meta: reader.meta().cameras.clone(),
            depth: reader.depth_frames(),
            color: reader.color_frames(),
            next_depth: None,
            next_color: None,
            realtime,
            start: None,
            clock: None,
            corrupt: [0; 2],
            depth_size: None,
            wrong_size: 0,
            done: false,
        }
    }

    /// The same source, skipping depth frames of another size than `width` x `height` and
    /// counting them as `wrong_size`, as a live run does (a camera that changed its mode for
    /// a frame).
    #[must_use]
    pub fn with_depth_size(mut self, size: Option<(u32, u32)>) -> Self {
        self.depth_size = size;
        self
    }

    /// The metadata of the camera with `role`, if the session has one.
    pub fn camera(&self, role: CameraRole) -> Option<&CameraMeta> {
        self.meta.iter().find(|c| c.role == role)
    }

    /// Records stepped over as damaged so far (depth, colour).
    pub fn damaged_records(&self) -> (u64, u64) {
        (
            self.depth.damage().skipped_records(),
            self.color.as_ref().map_or(0, |c| c.damage().skipped_records()),
        )
    }

    /// Whether each camera's frame file ended in a cut record (depth, colour): the last frame
    /// of a session that was not closed (a crash, a full disk), lost.
    pub fn truncated(&self) -> (bool, bool) {
        (
            self.depth.damage().truncated_tail_bytes > 0,
            self.color.as_ref().is_some_and(|c| c.damage().truncated_tail_bytes > 0),
        )
    }

    /// Reads ahead so that each camera has its next frame at hand. A frame whose contents do
    /// not decode is counted and stepped over; a file that cannot be read ends the source.
    fn fill(&mut self) -> Result<(), CaptureError> {
        while self.next_depth.is_none() {
            match self.depth.next() {
                None => break,
                Some(Ok(f)) if self.depth_size.is_some_and(|size| size != (f.width, f.height)) => {
                    if self.wrong_size == 0 {
                        tracing::warn!(
                            seq = f.stamp.seq,
                            size = ?(f.width, f.height),
                            expected = ?self.depth_size,
                            "depth frames of another size are skipped and counted (wrong_size)"
                        );
                    }
                    self.wrong_size += 1;
                }
                Some(Ok(f)) => self.next_depth = Some(f),
                Some(Err(SessionError::Frame { .. })) => self.corrupt[0] += 1,
                Some(Err(e)) => return Err(self.recording_error(e)),
            }
        }
        while self.next_color.is_none() {
            let Some(frames) = &mut self.color else {
                break;
            };
            match frames.next() {
                None => break,
                Some(Ok(f)) => self.next_color = Some(f),
                Some(Err(SessionError::Frame { .. })) => self.corrupt[1] += 1,
                Some(Err(e)) => return Err(self.recording_error(e)),
            }
        }
        Ok(())
    }

    fn recording_error(&self, e: SessionError) -> CaptureError {
        CaptureError::Recording {
            path: self.dir.clone(),
            source: Box::new(e),
        }
    }
}

impl FrameSource for SessionPlayer {
    type Frame = Captured;

    fn meta(&self) -> CameraMeta {
        self.camera(CameraRole::Depth)
            .cloned()
            .or_else(|| self.meta.first().cloned())
            .expect("a session reader only opens sessions with a depth camera")
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        self.clock = Some(clock.clone());
        self.fill()
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Captured>, CaptureError> {
        self.fill()?;
        let depth_first = match (&self.next_depth, &self.next_color) {
            (Some(d), Some(c)) => d.stamp.host_ns <= c.stamp.host_ns,
            (Some(_), None) => true,
            (None, Some(_)) => false,
            (None, None) => {
                self.done = true;
                for (role, cut) in [("depth", self.truncated().0), ("colour", self.truncated().1)] {
                    if cut {
                        tracing::warn!(
                            "the {role} frames of {:?} end in a cut record: the session was not closed (a crash or a full disk), its last {role} frame is lost",
                            self.dir
                        );
                    }
                }
                return Ok(None);
            }
        };
        let host_ns = if depth_first {
            self.next_depth.as_ref().map(|f| f.stamp.host_ns)
        } else {
            self.next_color.as_ref().map(|f| f.stamp.host_ns)
        }
        .unwrap_or(0);
        if self.realtime {
            let (wall0, host0) = *self.start.get_or_insert((Instant::now(), host_ns));
            let due = wall0 + Duration::from_nanos(host_ns.saturating_sub(host0));
            let now = Instant::now();
            if due > now {
                let wait = due - now;
                std::thread::sleep(wait.min(timeout));
                if wait > timeout {
                    return Ok(None);
                }
            }
        }
        if let Some(clock) = &self.clock {
            clock.advance_to(host_ns);
        }
        Ok(if depth_first {
            self.next_depth.take().map(|f| Captured::Depth(Arc::new(f)))
        } else {
            self.next_color.take().map(|f| Captured::Color(Arc::new(f)))
        })
    }

    fn finished(&self) -> bool {
        self.done
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        let (dd, dc) = self.damaged_records();
        let (td, tc) = self.truncated();
        vec![
            ("depth_corrupt", self.corrupt[0] + dd),
            ("color_corrupt", self.corrupt[1] + dc),
            ("depth_truncated", u64::from(td)),
            ("color_truncated", u64::from(tc)),
            ("depth_wrong_size", self.wrong_size),
        ]
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        Ok(())
    }
}

/// The depth camera of a recorded session, played as a live camera: at the recorded pace,
/// stamped with the live host clock, from the start again when it ends. A rig without a depth
/// camera (`[depth] backend = "session"`): for trying the daemon, demonstrations and
/// benchmarks fed at camera pace.
///
/// Frame counters and device times keep growing across loops, so the synchroniser sees one
/// long, steady stream; gaps in the recorded frame counter are kept.
#[derive(Debug)]
pub struct LoopedDepth {
    dir: PathBuf,
    meta: CameraMeta,
    reader: Option<SessionReader>,
    frames: Option<DepthFrames>,
    clock: Option<Clock>,
    /// A frame read but not yet due.
    pending: Option<DepthFrame>,
    /// Recorded (seq, device time) of this loop's first frame, and when that frame was due.
    first: Option<(u64, u64, Instant)>,
    /// Added to this loop's (seq, device time) so that both keep growing across loops.
    offset: (u64, u64),
    /// The last frame delivered: (seq, device time, when it was due).
    last: Option<(u64, u64, Instant)>,
    interval_ns: u64,
    corrupt: u64,
}

impl LoopedDepth {
    /// A source over the depth frames of the session in `dir`.
    ///
    /// # Errors
    /// The session cannot be opened, or has no depth frames.
    pub fn open(dir: &std::path::Path) -> Result<Self, CaptureError> {
        let reader = open_reader(dir)?;
        let none = |what: &str| CaptureError::NotFound {
            backend: "session",
            id: format!("{} in {dir:?}", what),
        };
        let mut meta = reader
            .meta()
            .camera(CameraRole::Depth)
            .cloned()
            .ok_or_else(|| none("a depth camera"))?;
        if reader.depth_count() == 0 {
            return Err(none("a depth frame"));
        }
        meta.model = format!("{} (replayed)", meta.model);
        let interval_ns = (1e9 / meta.fps.max(1.0)) as u64;
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            reader: Some(reader),
            frames: None,
            clock: None,
            pending: None,
            first: None,
            offset: (0, 0),
            last: None,
            interval_ns,
            corrupt: 0,
        })
    }

    /// The next recorded frame, from the start again after the last one.
    fn next_recorded(&mut self) -> Result<DepthFrame, CaptureError> {
        let Some(reader) = &self.reader else {
            return Err(CaptureError::Disconnected {
                backend: "session",
                id: format!("{:?}", self.dir),
                reason: "stopped".into(),
            });
        };
        for _ in 0..2 {
            let frames = self.frames.get_or_insert_with(|| reader.depth_frames());
            for item in frames.by_ref() {
                match item {
                    Ok(frame) => return Ok(frame),
                    Err(SessionError::Frame { .. }) => self.corrupt += 1,
                    Err(source) => {
                        return Err(CaptureError::Recording {
                            path: self.dir.clone(),
                            source: Box::new(source),
                        });
                    }
                }
            }
            // The end: the next loop starts one frame interval after this one's last frame.
            self.frames = None;
            self.first = None;
            if let Some((seq, device_ns, _)) = self.last {
                self.offset = (seq + 1, device_ns + self.interval_ns);
            }
        }
        Err(CaptureError::NotFound {
            backend: "session",
            id: format!("a readable depth frame in {:?}", self.dir),
        })
    }
}

fn open_reader(dir: &std::path::Path) -> Result<SessionReader, CaptureError> {
    SessionReader::open(dir).map_err(|source| CaptureError::Recording {
        path: dir.to_path_buf(),
        source: Box::new(source),
    })
}

impl FrameSource for LoopedDepth {
    type Frame = DepthFrame;

    fn meta(&self) -> CameraMeta {
        self.meta.clone()
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        if self.reader.is_none() {
            self.reader = Some(open_reader(&self.dir)?);
        }
        self.clock = Some(clock.clone());
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<DepthFrame>, CaptureError> {
        let mut frame = match self.pending.take() {
            Some(f) => f,
            None => self.next_recorded()?,
        };
        let interval = Duration::from_nanos(self.interval_ns);
        let after_last = self.last.map_or_else(Instant::now, |(_, _, due)| due + interval);
        let (seq0, device0, due0) = *self
            .first
            .get_or_insert((frame.stamp.seq, frame.stamp.device_ns, after_last));
        let since = frame.stamp.device_ns.saturating_sub(device0);
        let due = due0 + Duration::from_nanos(since);
        let wait = due.saturating_duration_since(Instant::now());
        if wait > timeout {
            std::thread::sleep(timeout);
            self.pending = Some(frame);
            return Ok(None);
        }
        std::thread::sleep(wait);
        frame.stamp.seq = self.offset.0 + frame.stamp.seq.saturating_sub(seq0);
        frame.stamp.device_ns = self.offset.1 + since;
        frame.stamp.host_ns = self.clock.as_ref().map_or(0, Clock::now_ns);
        self.last = Some((frame.stamp.seq, frame.stamp.device_ns, due));
        Ok(Some(frame))
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        vec![("corrupt", self.corrupt)]
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        self.reader = None;
        self.frames = None;
        self.pending = None;
        Ok(())
    }
}

// ---- its table in the rig config ------------------------------------------------------------

/// The backend, registered in `capture::backend`: a recorded session's depth frames as the
/// depth camera.
pub const REGISTERED: DepthBackend = Backend {
    name: "session",
    table: read_table,
    list: None,
};

/// `[depth] backend = "session"`, as written.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSession {
    /// The session directory to play.
    path: Option<PathBuf>,
}

/// A recorded session played as the depth camera; its mode and rig are the session's.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionCamera {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    /// The rig the session was recorded or rendered with, if it says.
    pub rig: Option<crate::core::geometry::Rig>,
}

fn read_table(table: toml::Table) -> Result<Arc<dyn DepthConfig>, TableError> {
    let d: RawSession = backend::deserialize("session", table)?;
    let Some(path) = d.path else {
        return Err(TableError::new("", "needs `path`: the recorded session to play"));
    };
    let reader = SessionReader::open(&path).map_err(|e| {
        TableError::new(
            "path",
            format!("is not a readable session: {}", crate::core::error_chain(&e)),
        )
    })?;
    let Some(camera) = reader.meta().camera(CameraRole::Depth) else {
        return Err(TableError::new("path", format!("{path:?} has no depth camera")));
    };
    Ok(Arc::new(SessionCamera {
        width: camera.width,
        height: camera.height,
        fps: camera.fps,
        rig: reader.meta().rig,
        path,
    }))
}

impl CameraConfig for SessionCamera {
    type Frame = DepthFrame;

    fn backend(&self) -> &'static str {
        "session"
    }

    fn open(&self) -> Result<Box<dyn FrameSource<Frame = DepthFrame>>, CaptureError> {
        Ok(Box::new(LoopedDepth::open(&self.path)?))
    }

    fn frame_size(&self) -> Option<(u32, u32)> {
        Some((self.width, self.height))
    }
}

impl DepthConfig for SessionCamera {
    fn mode(&self) -> (u32, u32, f64) {
        (self.width, self.height, self.fps)
    }

    fn rig(&self) -> Option<crate::core::geometry::Rig> {
        self.rig
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_looped_session_keeps_counting_across_its_end_at_camera_pace() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/sessions/synthetic-small");
        let mut source = LoopedDepth::open(&dir).unwrap();
        let frames = SessionReader::open(&dir).unwrap().depth_count();
        source.start(&Clock::Monotonic).unwrap();
        let started = Instant::now();
        let mut stamps = Vec::new();
        while stamps.len() < frames + 5 {
            if let Some(f) = source.next_frame(Duration::from_millis(100)).unwrap() {
                stamps.push(f.stamp);
            }
        }
        for pair in stamps.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            assert!(
                b.seq > a.seq && b.device_ns > a.device_ns && b.host_ns >= a.host_ns,
                "{a:?} {b:?}"
            );
        }
        // Paced: (frames + 4) intervals of a 30 fps camera, give or take a slow machine.
        let span = stamps[stamps.len() - 1].device_ns - stamps[0].device_ns;
        assert!(started.elapsed() >= Duration::from_nanos(span) - Duration::from_millis(50));
        assert_eq!(source.losses(), vec![("corrupt", 0)]);
    }
}
