//! The recorder: frames from the capture threads written to a session as they arrive,
//! lossless, each handed to the operating system at once so that a recorder killed at any
//! moment leaves a session that reads up to its last complete frame.

use crate::io::session::{CameraRole, SessionEvent, SessionWriter};
use crate::runtime::accounting::Accounting;
use crate::runtime::capture::{Captured, SeqGaps};
use crate::runtime::pipeline::StageError;

/// The recorder thread: writes each frame as it arrives, logging gaps in the cameras'
/// sequence numbers as dropped frames.
pub fn write_frames(
    writer: &mut SessionWriter,
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
        let missing = gaps[slot].observe(stamp.seq);
        if missing > 0 {
            writer.log_event(&SessionEvent::FramesDropped {
                host_ns: stamp.host_ns,
                role,
                seq_from: stamp.seq - missing,
                count: missing,
                reason: "not delivered (camera gap or full capture queue)".to_owned(),
            })?;
        }
        match &captured {
            Captured::Depth(f) => writer.write_depth(f)?,
            Captured::Color(f) => writer.write_color(f)?,
        }
        // Kept frames are counted as paired (see `RecordedCamera::from`).
        acct.camera(role)
            .paired
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
    Ok(())
}
