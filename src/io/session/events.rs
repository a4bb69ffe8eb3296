//! `events.jsonl`: what happened during a session besides frames arriving, one JSON object a
//! line, each with the host's monotonic time (`host_ns`, the clock of the frames' `host_ns`)
//! and a `kind`.

use super::meta::CameraRole;
use serde::{Deserialize, Serialize};

/// One line of `events.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SessionEvent {
    /// Recording (or generation) started.
    SessionStarted { host_ns: u64 },
    /// A camera was opened and started streaming.
    CameraOpened {
        host_ns: u64,
        role: CameraRole,
        model: String,
        serial: String,
    },
    /// Frames that never reached the file: `count` frames from device sequence `seq_from`.
    FramesDropped {
        host_ns: u64,
        role: CameraRole,
        seq_from: u64,
        count: u64,
        reason: String,
    },
    /// A camera stopped delivering frames.
    CameraDisconnected {
        host_ns: u64,
        role: CameraRole,
        reason: String,
    },
    /// A disconnected camera delivers frames again.
    CameraReconnected { host_ns: u64, role: CameraRole },
    /// Recording paused at `host_ns` (its first frame not recorded), for `reason` (`disk_low`,
    /// `write_error`): logged, with its [`SessionEvent::RecordingResumed`], in the session
    /// recording resumes in.
    RecordingPaused { host_ns: u64, reason: String },
    /// Recording resumed: `host_ns` is the first frame recorded again.
    RecordingResumed { host_ns: u64 },
    /// A free-form remark (an operator's note, a warning worth keeping with the data).
    Note { host_ns: u64, message: String },
    /// The writer finished cleanly; the counts are the frames in the files.
    SessionEnded {
        host_ns: u64,
        depth_frames: u64,
        color_frames: u64,
    },
    /// An event kind this version does not know (written by a newer version); its fields are
    /// not kept.
    #[serde(other)]
    Unknown,
}

impl SessionEvent {
    /// The host time of the event; `None` for [`SessionEvent::Unknown`].
    pub fn host_ns(&self) -> Option<u64> {
        match *self {
            SessionEvent::SessionStarted { host_ns }
            | SessionEvent::CameraOpened { host_ns, .. }
            | SessionEvent::FramesDropped { host_ns, .. }
            | SessionEvent::CameraDisconnected { host_ns, .. }
            | SessionEvent::CameraReconnected { host_ns, .. }
            | SessionEvent::RecordingPaused { host_ns, .. }
            | SessionEvent::RecordingResumed { host_ns }
            | SessionEvent::Note { host_ns, .. }
            | SessionEvent::SessionEnded { host_ns, .. } => Some(host_ns),
            SessionEvent::Unknown => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_shape() {
        let e = SessionEvent::FramesDropped {
            host_ns: 5,
            role: CameraRole::Color,
            seq_from: 10,
            count: 2,
            reason: "queue full".into(),
        };
        let line = serde_json::to_string(&e).unwrap();
        assert_eq!(
            line,
            r#"{"kind":"frames_dropped","host_ns":5,"role":"color","seq_from":10,"count":2,"reason":"queue full"}"#
        );
        assert_eq!(serde_json::from_str::<SessionEvent>(&line).unwrap(), e);
        let future: SessionEvent = serde_json::from_str(r#"{"kind":"laser_on","host_ns":1,"power":3}"#).unwrap();
        assert_eq!(future, SessionEvent::Unknown);
        let extra: SessionEvent = serde_json::from_str(r#"{"kind":"session_started","host_ns":1,"pid":3}"#).unwrap();
        assert_eq!(extra, SessionEvent::SessionStarted { host_ns: 1 });
    }
}
