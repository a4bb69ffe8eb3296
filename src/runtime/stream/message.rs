//! The stream's messages, version [`VERSION`]: two ZeroMQ frames, the topic (`poses` or
//! `events`) then one JSON object. `docs/FORMATS.md` documents every key.

use crate::core::skeleton::Joint;
use crate::runtime::capture::clock::monotonic_ns;
use crate::runtime::pose_record::PoseRecord;
use serde::Serialize;
use std::collections::BTreeMap;

/// The version of the messages' format, in each message (`version`).
pub const VERSION: u32 = 1;

/// A frame's stamps.
#[derive(Serialize)]
struct Stamp {
    seq: u64,
    device_ns: u64,
    host_ns: u64,
}

impl From<crate::core::frame::Stamp> for Stamp {
    fn from(s: crate::core::frame::Stamp) -> Self {
        Self {
            seq: s.seq,
            device_ns: s.device_ns,
            host_ns: s.host_ns,
        }
    }
}

/// One joint: millimetres in the rig's world frame, its score and source; `null` when missing.
#[derive(Serialize)]
struct JointOut {
    x: f64,
    y: f64,
    z: f64,
    score: f64,
    source: &'static str,
}

#[derive(Serialize)]
struct PoseMessage {
    topic: &'static str,
    version: u32,
    seq: u64,
    /// `CLOCK_MONOTONIC` when the message was made.
    published_ns: u64,
    host_clock: &'static str,
    depth: Stamp,
    color: Option<Stamp>,
    skew_ns: i64,
    status: &'static str,
    orientation_confidence: Option<f64>,
    joints: BTreeMap<&'static str, Option<JointOut>>,
}

/// The `poses` message of `record`, numbered `seq`; `host_clock` says what its frames' host
/// stamps are (`monotonic` or `recording`).
pub fn pose(seq: u64, record: &PoseRecord, host_clock: &'static str) -> Vec<u8> {
    let joints = Joint::ALL
        .iter()
        .map(|&joint| {
            let j = record.pose.joint(joint);
            let known = j.source != crate::core::pose::JointSource::Missing;
            let out = known.then(|| JointOut {
                x: round(j.position_mm.x, 100.0),
                y: round(j.position_mm.y, 100.0),
                z: round(j.position_mm.z, 100.0),
                score: round(j.score, 1000.0),
                source: j.source.name(),
            });
            (joint.name(), out)
        })
        .collect();
    let message = PoseMessage {
        topic: "poses",
        version: VERSION,
        seq,
        published_ns: monotonic_ns(),
        host_clock,
        depth: record.depth.into(),
        color: record.color.map(Into::into),
        skew_ns: record.skew_ns,
        status: record.status.name(),
        orientation_confidence: record.orientation.as_ref().map(|o| round(o.confidence, 1000.0)),
        joints,
    };
    to_json(&message)
}

/// What an `events` message says.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum StreamEvent {
    /// A camera stopped delivering frames (`reason`: why, as the status says it).
    CameraAway {
        camera: &'static str,
        reason: String,
    },
    /// A camera delivers frames again.
    CameraBack {
        camera: &'static str,
    },
    /// A new chunk (directory `chunk-NNNN`) begun.
    ChunkBegun {
        chunk: usize,
    },
    /// Raw recording paused (disk full, a write error); poses go on.
    RecordingPaused,
    RecordingResumed,
}

#[derive(Serialize)]
struct EventMessage<'a> {
    topic: &'static str,
    version: u32,
    seq: u64,
    published_ns: u64,
    #[serde(flatten)]
    event: &'a StreamEvent,
}

/// The `events` message of `event`, numbered `seq`.
pub fn event(seq: u64, event: &StreamEvent) -> Vec<u8> {
    to_json(&EventMessage {
        topic: "events",
        version: VERSION,
        seq,
        published_ns: monotonic_ns(),
        event,
    })
}

fn round(v: f64, scale: f64) -> f64 {
    (v * scale).round() / scale
}

fn to_json(value: &impl Serialize) -> Vec<u8> {
    // Plain structs of numbers and strings: serialising them cannot fail.
    serde_json::to_vec(value).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_event_message_is_flat_and_versioned() {
        let text = event(
            7,
            &StreamEvent::CameraAway {
                camera: "depth",
                reason: "no frame for 2 s".into(),
            },
        );
        let v: serde_json::Value = serde_json::from_slice(&text).unwrap();
        assert_eq!(v["version"], 1);
        assert_eq!(v["seq"], 7);
        assert_eq!(v["event"], "camera_away");
        assert_eq!(v["camera"], "depth");
        assert!(v["published_ns"].as_u64().unwrap() > 0);
    }
}
