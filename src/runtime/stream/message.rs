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

/// One joint: millimetres in the rig's world frame, its score and source, and its velocity
/// (mm/s) where the smoothing follows it; `null` when missing.
#[derive(Serialize)]
struct JointOut {
    x: f64,
    y: f64,
    z: f64,
    score: f64,
    source: &'static str,
    velocity: Option<[f64; 3]>,
}

/// A joint of the predicted pose: millimetres in the rig's world frame.
#[derive(Serialize)]
struct PlaceOut {
    x: f64,
    y: f64,
    z: f64,
}

/// The pose predicted `lead_ms` after the depth frame was taken, for `for_ns` (the host
/// clock of the frames' stamps).
#[derive(Serialize)]
struct PredictedOut {
    lead_ms: f64,
    for_ns: u64,
    joints: BTreeMap<&'static str, Option<PlaceOut>>,
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
    /// With several mice: which one (1..N); absent with one.
    #[serde(skip_serializing_if = "Option::is_none")]
    mouse: Option<usize>,
    status: &'static str,
    /// With several mice: how sure its number is (0-1); absent with one.
    #[serde(skip_serializing_if = "Option::is_none")]
    identity_confidence: Option<f64>,
    orientation_confidence: Option<f64>,
    joints: BTreeMap<&'static str, Option<JointOut>>,
    predicted: Option<PredictedOut>,
}

/// The `poses` message of `record`, numbered `seq`; `host_clock` says what its frames' host
/// stamps are (`monotonic` or `recording`); with a `lead_ns`, the pose predicted that long
/// after the depth frame was taken is beside it ([`PoseRecord::predicted`]).
pub fn pose(seq: u64, record: &PoseRecord, host_clock: &'static str, lead_ns: Option<u64>) -> Vec<u8> {
    let known = |joint: Joint| record.pose.joint(joint).source != crate::core::pose::JointSource::Missing;
    let joints = Joint::ALL
        .iter()
        .map(|&joint| {
            let j = record.pose.joint(joint);
            let out = known(joint).then(|| JointOut {
                x: round(j.position_mm.x, 100.0),
                y: round(j.position_mm.y, 100.0),
                z: round(j.position_mm.z, 100.0),
                score: round(j.score, 1000.0),
                source: j.source.name(),
                velocity: record.velocity(joint).map(|v| v.map(|c| round(c, 10.0)).into()),
            });
            (joint.name(), out)
        })
        .collect();
    let predicted = lead_ns.map(|lead_ns| {
        let pose = record.predicted(lead_ns as f64 * 1e-9);
        PredictedOut {
            lead_ms: lead_ns as f64 * 1e-6,
            for_ns: record.depth.host_ns.saturating_add(lead_ns),
            joints: Joint::ALL
                .iter()
                .map(|&joint| {
                    let p = pose.joint(joint).position_mm;
                    let out = known(joint).then(|| PlaceOut {
                        x: round(p.x, 100.0),
                        y: round(p.y, 100.0),
                        z: round(p.z, 100.0),
                    });
                    (joint.name(), out)
                })
                .collect(),
        }
    });
    let message = PoseMessage {
        topic: "poses",
        version: VERSION,
        seq,
        published_ns: monotonic_ns(),
        host_clock,
        depth: record.depth.into(),
        color: record.color.map(Into::into),
        skew_ns: record.skew_ns,
        mouse: record.identity.map(|i| i.mouse),
        status: record.status.name(),
        identity_confidence: record.identity.map(|i| round(i.confidence, 1000.0)),
        orientation_confidence: record.orientation.as_ref().map(|o| round(o.confidence, 1000.0)),
        joints,
        predicted,
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

    #[test]
    fn a_pose_message_carries_the_velocities_and_the_pose_predicted_for_the_lead() {
        use crate::core::pose::{JointSource, Pose};
        let mut pose = Pose::default();
        for (joint, x) in [(Joint::Snout, 10.0), (Joint::LeftForePaw, -5.0)] {
            let j = pose.joint_mut(joint);
            j.position_mm = nalgebra::Point3::new(x, 0.0, 20.0);
            j.source = JointSource::Depth;
        }
        let mut velocities = [None; 12];
        velocities[0] = Some(nalgebra::Vector3::new(200.0, -100.0, 0.0));
        let record = PoseRecord {
            depth: crate::core::frame::Stamp {
                seq: 3,
                device_ns: 5,
                host_ns: 1_000_000_000,
            },
            color: None,
            skew_ns: 0,
            status: crate::runtime::pose_record::PoseStatus::Ok,
            pose,
            paws: Vec::new(),
            headings: None,
            orientation: None,
            raw_body: None,
            velocities: Some(Box::new(velocities)),
            identity: None,
        };
        let v: serde_json::Value = serde_json::from_slice(&pose_message(&record, None)).unwrap();
        assert_eq!(
            v["joints"]["snout"]["velocity"],
            serde_json::json!([200.0, -100.0, 0.0])
        );
        assert_eq!(v["joints"]["left_fore_paw"]["velocity"], serde_json::Value::Null);
        assert_eq!(v["predicted"], serde_json::Value::Null);
        let v: serde_json::Value = serde_json::from_slice(&pose_message(&record, Some(50_000_000))).unwrap();
        let predicted = &v["predicted"];
        assert_eq!(
            (predicted["lead_ms"].as_f64(), predicted["for_ns"].as_u64()),
            (Some(50.0), Some(1_050_000_000))
        );
        assert_eq!(
            predicted["joints"]["snout"],
            serde_json::json!({"x": 20.0, "y": -5.0, "z": 20.0})
        );
        // A paw has no velocity: predicted where it was placed; a joint not estimated is null.
        assert_eq!(predicted["joints"]["left_fore_paw"]["x"], -5.0);
        assert_eq!(predicted["joints"]["head"], serde_json::Value::Null);
    }

    fn pose_message(record: &PoseRecord, lead_ns: Option<u64>) -> Vec<u8> {
        pose(0, record, "monotonic", lead_ns)
    }
}
