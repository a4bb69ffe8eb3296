//! The poses as a Lab Streaming Layer (LSL) stream: what a lab's LabRecorder records into its
//! XDF file beside its other streams (neural data, behaviour events), all on LSL's clock.
//!
//! liblsl is loaded at run time (crate `lsl-outlet`) from the config's `[lsl] library`, else
//! from pylsl in the project's Python environment (which ships it), else from the dynamic
//! loader's search path. One sample per pose, [`CHANNELS`] `double64` channels: the 24 joints'
//! x, y, z in millimetres (NaN when unknown), the status code, the orientation confidence and
//! the depth frame's counter; stamped with the depth frame's arrival on LSL's clock.
//!
//! Never slower for a reader, as the ZeroMQ stream: the pose sink hands each sample to the
//! `lsl` thread through a bounded queue (`try_send`; full: dropped, counted `queue_full`), and
//! with no reader connected no sample is even made. liblsl keeps at most
//! [`MAX_BUFFERED_SAMPLES`] per reader and drops the oldest past that.

use super::SendThread;
use crate::core::skeleton::Joint;
use crate::runtime::capture::clock::monotonic_ns;
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crossbeam_channel::{Receiver, Sender, TrySendError};
use lsl_outlet::{Channel, Lsl, LslError, Outlet, StreamSpec};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// Channels of a sample: x, y, z of each joint, then status, orientation confidence, depth
/// frame counter.
pub const CHANNELS: usize = 3 * Joint::ALL.len() + 3;

/// Channels after those with a lead (`[lsl] lead_ms`): x, y, z of each joint of the pose
/// predicted for the lead ([`PoseRecord::predicted`]).
pub const PREDICTED_CHANNELS: usize = 3 * Joint::ALL.len();

/// Samples waiting for the `lsl` thread; more are dropped (`queue_full`).
pub const DEFAULT_QUEUE: usize = 64;

/// Samples liblsl keeps for a reader that does not keep up (about 33 s at 30 frames/s).
pub const MAX_BUFFERED_SAMPLES: i32 = 1000;

/// Why a sample did not go out (the label of `mousepose_lsl_dropped_total`).
pub const DROP_REASONS: [&str; 2] = ["queue_full", "push_failed"];

/// The outlet's settings (the rig config's `[lsl]`, or `replay --lsl`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LslConfig {
    /// liblsl's file; `None`: pylsl's copy in the Python environment, else the loader's search.
    pub library: Option<PathBuf>,
    /// The stream's name, what readers resolve it by.
    pub name: String,
    /// Its content type.
    pub kind: String,
    /// Identifies this rig's stream across restarts (LabRecorder reconnects by it).
    pub source_id: String,
    pub queue: usize,
    /// Whether the frames' host stamps are this machine's monotonic clock (live) or a
    /// recording's (a replay: samples are then stamped when they are sent).
    pub live_clock: bool,
    /// With each pose, the pose predicted this long after its depth frame was taken, in
    /// [`PREDICTED_CHANNELS`] more channels; `None`: no prediction.
    pub lead_ns: Option<u64>,
}

impl LslConfig {
    /// The defaults: stream `mousepose`, type `MoCap`, source id `mousepose`.
    pub fn named(name: &str) -> Self {
        Self {
            library: None,
            name: name.to_owned(),
            kind: "MoCap".to_owned(),
            source_id: "mousepose".to_owned(),
            queue: DEFAULT_QUEUE,
            live_clock: true,
            lead_ns: None,
        }
    }
}

/// Why the outlet could not start.
#[derive(Debug, thiserror::Error)]
pub enum LslStartError {
    #[error(
        "cannot use liblsl for the LSL outlet (install pylsl with scripts/setup.sh, or name the library in [lsl] library)"
    )]
    Library {
        #[source]
        source: LslError,
    },
    #[error("cannot make the LSL outlet {name:?}")]
    Outlet {
        name: String,
        #[source]
        source: LslError,
    },
    #[error("cannot start the LSL outlet's thread")]
    Thread(#[source] std::io::Error),
}

/// The outlet's counters, read by the status and `/metrics`.
#[derive(Debug, Default)]
pub struct LslStats {
    sent: AtomicU64,
    /// Per [`DROP_REASONS`].
    dropped: [AtomicU64; 2],
    /// Whether a reader is connected (looked at by the `lsl` thread).
    consumers: AtomicBool,
}

impl LslStats {
    pub fn sent(&self) -> u64 {
        self.sent.load(Ordering::Relaxed)
    }

    pub fn has_consumers(&self) -> bool {
        self.consumers.load(Ordering::Relaxed)
    }

    /// Samples dropped for `reason` (one of [`DROP_REASONS`]).
    pub fn dropped(&self, reason: &str) -> u64 {
        DROP_REASONS
            .iter()
            .position(|r| *r == reason)
            .map_or(0, |i| self.dropped[i].load(Ordering::Relaxed))
    }
}

/// What the status shows of the outlet.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LslSummary {
    pub name: String,
    /// Whether a reader (LabRecorder, an inlet) is connected now.
    pub consumers: bool,
    /// Samples handed to liblsl.
    pub sent: u64,
    /// Per reason.
    pub dropped: std::collections::BTreeMap<&'static str, u64>,
}

/// A sample and its stamp (LSL's clock, seconds).
type Outgoing = (Vec<f64>, f64);

/// Where the pose sink publishes: cheap to clone, never waits.
#[derive(Clone, Debug)]
pub struct LslHandle {
    tx: Sender<Outgoing>,
    stats: Arc<LslStats>,
    name: Arc<str>,
    /// LSL's clock minus `CLOCK_MONOTONIC` (seconds).
    clock_offset_s: f64,
    live_clock: bool,
    lead_ns: Option<u64>,
}

impl LslHandle {
    /// Publishes the pose of `record` when a reader is connected; a full queue drops it
    /// (counted `queue_full`). Never waits.
    pub fn publish(&self, record: &PoseRecord) {
        if !self.stats.has_consumers() {
            return;
        }
        // Live: the depth frame's arrival; a replay's stamps are of another clock, so now.
        let host_ns = if self.live_clock {
            record.depth.host_ns
        } else {
            monotonic_ns()
        };
        let stamp = host_ns as f64 * 1e-9 + self.clock_offset_s;
        if let Err(TrySendError::Full(_)) = self.tx.try_send((sample(record, self.lead_ns), stamp)) {
            self.stats.dropped[0].fetch_add(1, Ordering::Relaxed);
        }
    }

    pub fn stats(&self) -> &Arc<LslStats> {
        &self.stats
    }

    /// The counters, for the status.
    pub fn summary(&self) -> LslSummary {
        LslSummary {
            name: self.name.to_string(),
            consumers: self.stats.has_consumers(),
            sent: self.stats.sent(),
            dropped: DROP_REASONS.iter().map(|r| (*r, self.stats.dropped(r))).collect(),
        }
    }
}

/// The sample of a pose, with the pose predicted `lead_ns` after it when there is a lead; see
/// [`channels`] for the order.
pub fn sample(record: &PoseRecord, lead_ns: Option<u64>) -> Vec<f64> {
    let mut values = Vec::with_capacity(CHANNELS + PREDICTED_CHANNELS);
    let push_joints = |values: &mut Vec<f64>, pose: &crate::core::pose::Pose| {
        for &joint in &Joint::ALL {
            if record.pose.joint(joint).source == crate::core::pose::JointSource::Missing {
                values.extend([f64::NAN; 3]);
            } else {
                let p = pose.joint(joint).position_mm;
                values.extend([p.x, p.y, p.z]);
            }
        }
    };
    push_joints(&mut values, &record.pose);
    let status = PoseStatus::ALL.iter().position(|s| *s == record.status).unwrap_or(0);
    values.push(status as f64);
    values.push(record.orientation.as_ref().map_or(f64::NAN, |o| o.confidence));
    values.push(record.depth.seq as f64);
    if let Some(lead_ns) = lead_ns {
        push_joints(&mut values, &record.predicted(lead_ns as f64 * 1e-9));
    }
    values
}

/// The channels' labels, units and types, in a sample's order (what the stream's description
/// says, and XDF readers show); with a lead, the predicted joints' after the rest
/// (`snout_predicted_x`, ...).
pub fn channels(lead: bool) -> Vec<Channel> {
    let channel = |label: String, unit: &str, kind: &str| Channel {
        label,
        unit: unit.to_owned(),
        kind: kind.to_owned(),
    };
    let joints = |out: &mut Vec<Channel>, suffix: &str| {
        for joint in Joint::ALL {
            for (axis, kind) in [("x", "PositionX"), ("y", "PositionY"), ("z", "PositionZ")] {
                out.push(channel(format!("{}{suffix}_{axis}", joint.name()), "millimeters", kind));
            }
        }
    };
    let mut out = Vec::with_capacity(CHANNELS + PREDICTED_CHANNELS);
    joints(&mut out, "");
    out.push(channel("status".into(), "code", "Status"));
    out.push(channel("orientation_confidence".into(), "probability", "Confidence"));
    out.push(channel("depth_seq".into(), "count", "FrameNumber"));
    if lead {
        joints(&mut out, "_predicted");
    }
    out
}

/// The liblsl to load: `configured`, else pylsl's copy in the Python environment of
/// `python` (its `lib/python3*/site-packages/pylsl/lib/liblsl.so`), else the bare name for the
/// dynamic loader to search.
pub fn find_library(configured: Option<&Path>, python: &Path) -> PathBuf {
    if let Some(path) = configured {
        return path.to_owned();
    }
    let env_lib = python.parent().and_then(Path::parent).map(|env| env.join("lib"));
    let mut found: Vec<PathBuf> = env_lib
        .and_then(|lib| std::fs::read_dir(lib).ok())
        .into_iter()
        .flatten()
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with("python3"))
        .map(|e| e.path().join("site-packages/pylsl/lib/liblsl.so"))
        .filter(|p| p.is_file())
        .collect();
    found.sort();
    found.pop().unwrap_or_else(|| PathBuf::from("liblsl.so"))
}

/// The running outlet: its stream on the `lsl` thread. Dropping it withdraws the stream.
#[derive(Debug)]
pub struct LslOutlet {
    handle: LslHandle,
    thread: SendThread,
}

/// How often the `lsl` thread asks whether a reader is connected when no sample comes.
const CONSUMER_PERIOD: Duration = Duration::from_millis(100);

/// How long the outlet stays after its last sample when a reader is connected: liblsl cuts
/// off what it has not yet sent when an outlet goes (as ZeroMQ's linger, but bounded).
const LINGER: Duration = Duration::from_millis(500);

impl LslOutlet {
    /// Loads liblsl (the config's, else [`find_library`] in the environment of `python`),
    /// offers the stream and starts the `lsl` thread.
    ///
    /// # Errors
    /// liblsl cannot be loaded, refuses the stream, or the thread cannot start.
    pub fn start(config: &LslConfig, python: &Path) -> Result<Self, LslStartError> {
        let library = find_library(config.library.as_deref(), python);
        let lsl = Lsl::open(library.as_os_str()).map_err(|source| LslStartError::Library { source })?;
        let spec = StreamSpec {
            name: config.name.clone(),
            kind: config.kind.clone(),
            nominal_rate: 0.0,
            source_id: config.source_id.clone(),
            channels: channels(config.lead_ns.is_some()),
            desc: [
                ("manufacturer".into(), "mousepose".into()),
                ("version".into(), env!("CARGO_PKG_VERSION").into()),
                (
                    "coordinates".into(),
                    "the rig's world frame: origin on the glass, z up".into(),
                ),
            ]
            .into_iter()
            .chain(
                config
                    .lead_ns
                    .map(|ns| ("lead_ms".into(), format!("{}", ns as f64 * 1e-6))),
            )
            .collect(),
            // Irregular rate: liblsl counts this in hundreds of samples.
            max_buffered: MAX_BUFFERED_SAMPLES / 100,
        };
        let outlet = Outlet::new(&lsl, &spec).map_err(|source| LslStartError::Outlet {
            name: config.name.clone(),
            source,
        })?;
        // Both clocks read back to back; on Linux LSL's is CLOCK_MONOTONIC and this is 0.
        let before = monotonic_ns();
        let lsl_now = lsl.local_clock();
        let after = monotonic_ns();
        let clock_offset_s = lsl_now - (before / 2 + after / 2) as f64 * 1e-9;
        tracing::info!(
            name = %config.name,
            library = lsl.path(),
            version = lsl.version(),
            "LSL outlet offered"
        );
        let (tx, rx) = crossbeam_channel::bounded(config.queue);
        let stats = Arc::new(LslStats::default());
        let thread = {
            let stats = Arc::clone(&stats);
            SendThread::spawn("lsl", move |stop| push_loop(&outlet, &rx, &stats, stop))
                .map_err(LslStartError::Thread)?
        };
        Ok(Self {
            handle: LslHandle {
                tx,
                stats,
                name: config.name.as_str().into(),
                clock_offset_s,
                live_clock: config.live_clock,
                lead_ns: config.lead_ns,
            },
            thread,
        })
    }

    pub fn handle(&self) -> LslHandle {
        self.handle.clone()
    }

    /// Ends the `lsl` thread (samples still queued are sent first, and a connected reader gets
    /// [`LINGER`] to receive them) and withdraws the stream.
    pub fn stop(mut self) {
        self.thread.end();
    }
}

/// The `lsl` thread: pushes what comes, notes whether a reader is connected, until stopped.
fn push_loop(outlet: &Outlet, rx: &Receiver<Outgoing>, stats: &LslStats, stop: &AtomicBool) {
    let mut failed_once = false;
    loop {
        let item = rx.recv_timeout(CONSUMER_PERIOD);
        stats.consumers.store(outlet.has_consumers(), Ordering::Relaxed);
        match item {
            Ok((values, stamp)) => match outlet.push(&values, stamp) {
                Ok(()) => {
                    stats.sent.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    stats.dropped[1].fetch_add(1, Ordering::Relaxed);
                    if !failed_once {
                        tracing::warn!(error = %e, "an LSL sample could not be sent (counted, further ones not logged)");
                        failed_once = true;
                    }
                }
            },
            Err(_) if stop.load(Ordering::Relaxed) && rx.is_empty() => {
                if outlet.has_consumers() {
                    std::thread::sleep(LINGER);
                }
                return;
            }
            Err(_) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::Stamp;
    use crate::core::pose::{JointSource, Pose};

    #[test]
    fn a_sample_has_a_value_per_channel_in_the_channels_order() {
        let mut pose = Pose::default();
        let snout = pose.joint_mut(Joint::ALL[0]);
        snout.position_mm = nalgebra::Point3::new(1.5, -2.0, 30.25);
        snout.source = JointSource::Depth;
        let record = PoseRecord {
            depth: Stamp {
                seq: 77,
                device_ns: 1,
                host_ns: 2,
            },
            color: None,
            skew_ns: 0,
            status: PoseStatus::NoMouse,
            pose,
            paws: Vec::new(),
            headings: None,
            orientation: None,
            raw_body: None,
            velocities: None,
            identity: None,
        };
        let values = sample(&record, None);
        let labels: Vec<String> = channels(false).into_iter().map(|c| c.label).collect();
        assert_eq!((values.len(), labels.len()), (CHANNELS, CHANNELS));
        assert_eq!(&values[..3], [1.5, -2.0, 30.25]);
        assert_eq!(labels[0], format!("{}_x", Joint::ALL[0].name()));
        // A joint not estimated, and no orientation: NaN.
        assert!(values[3..72].iter().all(|v| v.is_nan()));
        assert_eq!(labels[72..], ["status", "orientation_confidence", "depth_seq"]);
        assert_eq!(values[72], 1.0);
        assert!(values[73].is_nan());
        assert_eq!(values[74], 77.0);

        // With a lead, the predicted pose after the rest: the snout moved on by its velocity.
        let mut velocities = [None; 12];
        velocities[0] = Some(nalgebra::Vector3::new(100.0, 0.0, -10.0));
        let record = PoseRecord {
            velocities: Some(Box::new(velocities)),
            identity: None,
            ..record
        };
        let values = sample(&record, Some(50_000_000));
        let labels: Vec<String> = channels(true).into_iter().map(|c| c.label).collect();
        let all = CHANNELS + PREDICTED_CHANNELS;
        assert_eq!((values.len(), labels.len()), (all, all));
        assert_eq!(&values[..3], [1.5, -2.0, 30.25]);
        assert_eq!(labels[CHANNELS], format!("{}_predicted_x", Joint::ALL[0].name()));
        assert_eq!(&values[CHANNELS..CHANNELS + 3], [6.5, -2.0, 29.75]);
        assert!(values[CHANNELS + 3..].iter().all(|v| v.is_nan()));
    }

    #[test]
    fn liblsl_is_pylsls_copy_unless_the_config_names_one() {
        let tmp = tempfile::tempdir().unwrap();
        let python = tmp.path().join("bin/python3");
        let bare = find_library(None, &python);
        assert_eq!(bare, PathBuf::from("liblsl.so"));
        let lib = tmp.path().join("lib/python3.11/site-packages/pylsl/lib");
        std::fs::create_dir_all(&lib).unwrap();
        std::fs::write(lib.join("liblsl.so"), b"").unwrap();
        assert_eq!(find_library(None, &python), lib.join("liblsl.so"));
        let own = Path::new("/usr/local/lib/liblsl.so");
        assert_eq!(find_library(Some(own), &python), own);
    }
}
