//! A recorded session read back as the pipeline's source: both cameras' frames merged in the
//! order they reached the host (`host_ns`), as fast as possible or at the recorded pace.
//!
//! Deterministic: the frames come out in the same order on every run, and the replay clock
//! is moved to each frame's recorded host time as it is delivered.

use crate::core::frame::{ColorFrame, DepthFrame};
use crate::io::session::meta::{CameraMeta, CameraRole};
use crate::io::session::{ColorFrames, DepthFrames};
use crate::io::session::{SessionError, SessionEvent, SessionReader};
use crate::runtime::capture::{CaptureError, Captured, Clock, FrameSource};
use crate::runtime::stages::sync::Reopens;
use std::collections::VecDeque;
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

/// The camera reopens a session's events tell of, for the synchroniser to learn each camera's
/// clock again at the frame where it started again, as the live run did. Events that cannot
/// be read are said and go without: the synchroniser then learns a restarted clock late,
/// refusing the frames between (counted, `time_not_increasing`).
pub fn recorded_reopens(reader: &SessionReader) -> Reopens {
    let events = reader.events().unwrap_or_else(|e| {
        tracing::warn!(
            "cannot read the events of {:?}, so reopened cameras are not known: {e}",
            reader.dir()
        );
        Vec::new()
    });
    let mut at: [VecDeque<u64>; 2] = Default::default();
    for event in events {
        if let SessionEvent::CameraReconnected { host_ns, role } = event {
            let slot = match role {
                CameraRole::Depth => 0,
                CameraRole::Color => 1,
            };
            at[slot].push_back(host_ns);
        }
    }
    for times in &mut at {
        times.make_contiguous().sort_unstable();
    }
    Reopens::Recorded(at)
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
