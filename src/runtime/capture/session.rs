//! The `session` depth backend: a recorded session's depth frames played as a live depth
//! camera (`[depth] backend = "session"`), for trying the daemon without cameras,
//! demonstrations and benchmarks fed at camera pace.

use super::backend::{self, Backend, CameraConfig, DepthBackend, DepthConfig, TableError};
use super::{CaptureError, Clock, FrameSource};
use crate::core::frame::DepthFrame;
use crate::io::session::DepthFrames;
use crate::io::session::meta::{CameraMeta, CameraRole};
use crate::io::session::{SessionError, SessionReader};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

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
    /// While this file exists no frame is given, as a camera that stalls gives none.
    stall_while: Option<PathBuf>,
    /// Whether the last call found the camera stalled.
    stalled: bool,
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
            stall_while: None,
            stalled: false,
        })
    }

    /// Gives no frame while `file` exists (as a camera that stalls, its device clock running
    /// on), and goes on at camera pace once it is gone: for rehearsing a rig's faults.
    #[must_use]
    pub fn stalled_while(mut self, file: Option<PathBuf>) -> Self {
        self.stall_while = file;
        self
    }

    /// Whether the camera is stalled now; on its end, the frames that fell due meanwhile are
    /// skipped (the device clock and counter moved on), not delivered in a burst.
    fn stall(&mut self, timeout: Duration) -> bool {
        let Some(file) = &self.stall_while else {
            return false;
        };
        if file.exists() {
            self.stalled = true;
            std::thread::sleep(timeout.min(Duration::from_millis(20)));
            return true;
        }
        if let (true, Some((seq, device_ns, due))) = (std::mem::take(&mut self.stalled), self.last) {
            // The next frame starts a stretch of its own, due now, its stamps moved on by the
            // frames missed (as at a loop's end).
            let interval = Duration::from_nanos(self.interval_ns);
            let now = Instant::now();
            let missed = now.saturating_duration_since(due + interval);
            let skipped = (missed.as_nanos() / u128::from(self.interval_ns.max(1))) as u64;
            let missed_ns = missed.as_nanos() as u64;
            self.offset = (seq + 1 + skipped, device_ns + self.interval_ns + missed_ns);
            self.last = Some((seq + skipped, device_ns + missed_ns, now - interval));
            self.first = None;
        }
        false
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
        if self.stall(timeout) {
            return Ok(None);
        }
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
    /// While this file exists, the played camera stalls.
    stall_while: Option<PathBuf>,
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
    /// While this file exists, no frame is given (a stalled camera, for rehearsing faults).
    pub stall_while: Option<PathBuf>,
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
        stall_while: d.stall_while,
    }))
}

impl CameraConfig for SessionCamera {
    type Frame = DepthFrame;

    fn backend(&self) -> &'static str {
        "session"
    }

    fn open(&self) -> Result<Box<dyn FrameSource<Frame = DepthFrame>>, CaptureError> {
        Ok(Box::new(
            LoopedDepth::open(&self.path)?.stalled_while(self.stall_while.clone()),
        ))
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

    #[test]
    fn a_stalled_camera_gives_nothing_then_goes_on_at_pace_without_a_burst() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/sessions/synthetic-small");
        let tmp = tempfile::tempdir().unwrap();
        let stall = tmp.path().join("stall");
        let mut source = LoopedDepth::open(&dir).unwrap().stalled_while(Some(stall.clone()));
        source.start(&Clock::Monotonic).unwrap();
        let mut next = || loop {
            if let Some(f) = source.next_frame(Duration::from_millis(100)).unwrap() {
                return f.stamp;
            }
        };
        let before = next();
        std::fs::write(&stall, b"").unwrap();
        let stalled_at = Instant::now();
        let mut source_frames = 0;
        while stalled_at.elapsed() < Duration::from_millis(400) {
            // Nothing while the file is there.
            source_frames += usize::from(source.next_frame(Duration::from_millis(50)).unwrap().is_some());
        }
        assert_eq!(source_frames, 0);
        std::fs::remove_file(&stall).unwrap();
        let mut next = || loop {
            if let Some(f) = source.next_frame(Duration::from_millis(100)).unwrap() {
                return f.stamp;
            }
        };
        let (after, then, third) = (next(), next(), next());
        // The device clock and counter ran on through the stall (about 12 frames at 30 fps);
        // the frames after it come at camera pace, not in a burst: two intervals after the
        // first take most of two periods (67 ms). (One interval alone is shorter when this
        // thread takes the first frame late on a busy machine: 22 ms was seen.)
        assert!(after.seq >= before.seq + 10, "{before:?} {after:?}");
        let gap_ms = (after.device_ns - before.device_ns) as f64 * 1e-6;
        assert!(gap_ms >= 390.0, "{gap_ms} ms");
        assert_eq!((then.seq, third.seq), (after.seq + 1, after.seq + 2));
        assert!(third.host_ns - after.host_ns >= 45_000_000, "{after:?} {third:?}");
    }
}
