//! The recorder: frames from the capture threads written to a session as they arrive,
//! lossless, each handed to the operating system at once so that a recorder killed at any
//! moment leaves a session that reads up to its last complete frame.

use crate::io::session::{CameraRole, SessionError, SessionEvent, SessionSummary, SessionWriter};
use crate::runtime::accounting::{Accounting, bump};
use crate::runtime::capture::{Captured, SeqGaps};
use crate::runtime::pipeline::StageError;

/// Where the recorder branch writes: one session ([`SessionWriter`]), or chunk after chunk.
pub trait FrameRecorder: Send + std::fmt::Debug + 'static {
    /// Writes a frame. `Ok(Some(reason))`: the frame was deliberately not written (recording
    /// paused), and is counted as dropped for that reason.
    ///
    /// # Errors
    /// The frame cannot be written and recording cannot go on.
    fn write(&mut self, frame: &Captured) -> Result<Option<&'static str>, SessionError>;

    /// Logs an event in the session being written.
    ///
    /// # Errors
    /// The event cannot be written.
    fn log_event(&mut self, event: &SessionEvent) -> Result<(), SessionError>;

    /// Frames counted as recorded that left the run's directory since the last call (a
    /// session whose files were removed or moved away under the recorder), per camera and
    /// reason: the caller counts them as lost after recording (they stay recorded: a
    /// count never goes down).
    fn take_lost(&mut self) -> Vec<(CameraRole, &'static str, u64)> {
        Vec::new()
    }

    /// At the end, once the last frame was written: notices a session gone since (removed or
    /// moved away), whose frames [`FrameRecorder::take_lost`] then gives, and which is not
    /// closed into where it went.
    fn notice_gone(&mut self) {}

    /// Closes the (last) session cleanly and says what it holds (`None`: no session was open).
    ///
    /// # Errors
    /// The session cannot be closed.
    fn finish(self: Box<Self>) -> Result<Option<SessionSummary>, SessionError>;
}

impl FrameRecorder for SessionWriter {
    fn write(&mut self, frame: &Captured) -> Result<Option<&'static str>, SessionError> {
        match frame {
            Captured::Depth(f) => self.write_depth(f)?,
            Captured::Color(f) => self.write_color(f)?,
        }
        Ok(None)
    }

    fn log_event(&mut self, event: &SessionEvent) -> Result<(), SessionError> {
        SessionWriter::log_event(self, event)
    }

    fn finish(self: Box<Self>) -> Result<Option<SessionSummary>, SessionError> {
        SessionWriter::finish(*self).map(Some)
    }
}

/// The recorder thread: writes each frame as it arrives, logging gaps in the cameras'
/// sequence numbers as dropped frames. Written frames are counted as `recorded`, and those
/// of a session gone from the run's directory later also as `lost_after_recording`.
pub fn write_frames(
    writer: &mut dyn FrameRecorder,
    rx: &crossbeam_channel::Receiver<Captured>,
    acct: &Accounting,
) -> Result<(), StageError> {
    let mut gaps = [SeqGaps::default(); 2];
    for captured in rx.iter() {
        let (role, stamp) = match &captured {
            Captured::Depth(f) => (CameraRole::Depth, f.stamp),
            Captured::Color(f) => (CameraRole::Color, f.stamp),
        };
        let slot = usize::from(role == CameraRole::Color);
        let missing = gaps[slot].observe(stamp);
        if missing > 0 {
            writer.log_event(&SessionEvent::FramesDropped {
                host_ns: stamp.host_ns,
                role,
                seq_from: stamp.seq - missing,
                count: missing,
                reason: "not delivered (camera gap or full capture queue)".to_owned(),
            })?;
        }
        let counters = acct.camera(role);
        let outcome = writer.write(&captured)?;
        for (role, reason, n) in writer.take_lost() {
            bump(&acct.camera(role).lost_after_recording, reason, n);
        }
        match outcome {
            None => {
                counters.recorded.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
            Some(reason) => bump(&counters.not_recorded, reason, 1),
        }
    }
    writer.notice_gone();
    for (role, reason, n) in writer.take_lost() {
        bump(&acct.camera(role).lost_after_recording, reason, n);
    }
    Ok(())
}
