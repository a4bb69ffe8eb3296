//! What became of every frame, per camera: on the processing branch captured = paired +
//! unpaired + dropped (by reason); on the recorder branch captured = recorded + not recorded
//! (by reason); frames lost before capture (gaps in the camera's frame counter, damaged buffers or records)
//! are counted apart, and so are frames recorded and then lost (their chunk's files removed
//! or moved away under the recorder): every count only grows. The capture threads, the edges and the sync thread count into one
//! [`Accounting`]; summaries read it as [`CameraSummary`].

use crate::io::session::CameraRole;
use crate::runtime::pipeline::{EdgeConfig, EdgeStats};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};

/// Frames per camera, by what became of them.
#[derive(Debug, Default)]
pub struct CameraCounters {
    /// Frames the source delivered.
    pub captured: AtomicU64,
    /// In a pair with a frame of the other camera.
    pub paired: AtomicU64,
    /// Processed without a partner (depth-only pairs; colour frames no depth frame claimed).
    pub unpaired: AtomicU64,
    /// Depth frames among `paired` and `unpaired` decided at the end of the partner wait
    /// (`[sync] partner_wait_ms`) before their nearest partner was known: paired with the
    /// nearest colour frame in, or depth-only while a partner could still have come.
    pub paired_unproven: AtomicU64,
    pub unpaired_unproven: AtomicU64,
    /// Depth frames among `paired` whose colour frame had paired with the depth frame before
    /// (`[sync] partner_reach_ms`: none other in reach at the end of the wait), counted
    /// `paired` once, with that depth frame.
    pub paired_again: AtomicU64,
    /// Delivered but not processed, by reason.
    pub dropped: Mutex<BTreeMap<String, u64>>,
    /// Written by the recorder.
    pub recorded: AtomicU64,
    /// Delivered but not written by the recorder, by reason (its queue full, disk low, a
    /// write error).
    pub not_recorded: Mutex<BTreeMap<String, u64>>,
    /// Never delivered, by reason (`camera_gap`: missing sequence numbers; the source's own
    /// losses such as damaged buffers or records).
    pub lost: Mutex<BTreeMap<String, u64>>,
    /// Written by the recorder (so counted in `recorded`), then gone from the run's directory,
    /// by reason ([`LOST_AFTER_RECORDING_REASONS`]).
    pub lost_after_recording: Mutex<BTreeMap<String, u64>>,
}

/// The reasons a frame is dropped, lost before capture or not recorded that any rig can meet;
/// the metrics show each from the start at 0, so that an alert on its increase sees the first
/// one. (Sources add reasons of their own, such as damaged buffers, as they meet them.)
pub const DROPPED_REASONS: [&str; 3] = ["queue_full", "seq_out_of_order", "time_out_of_order"];
pub const LOST_REASONS: [&str; 2] = ["camera_gap", "wrong_size"];
pub const NOT_RECORDED_REASONS: [&str; 3] = ["queue_full", "disk_low", "write_error"];
/// Why recorded frames left the run's directory: their chunk's files `removed` under the
/// recorder, or `moved` away (the run directory renamed; the frames are where it went).
pub const LOST_AFTER_RECORDING_REASONS: [&str; 2] = ["removed", "moved"];

/// Adds `n` to `reason`'s count (nothing for 0).
pub fn bump(map: &Mutex<BTreeMap<String, u64>>, reason: &str, n: u64) {
    if n > 0 {
        *map.lock()
            .unwrap_or_else(PoisonError::into_inner)
            .entry(reason.to_owned())
            .or_default() += n;
    }
}

/// Both cameras' counters.
#[derive(Debug, Default)]
pub struct Accounting {
    pub depth: CameraCounters,
    pub color: CameraCounters,
}

impl Accounting {
    pub fn camera(&self, role: CameraRole) -> &CameraCounters {
        match role {
            CameraRole::Depth => &self.depth,
            CameraRole::Color => &self.color,
        }
    }
}

/// One camera in a run's report (`record`, `replay` and `run` alike). With processing,
/// `captured = paired + unpaired + dropped_total`; with a recorder,
/// `captured = recorded + not_recorded_total`; of the recorded frames, those in the run's
/// directory are `recorded - lost_after_recording` (all reasons).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CameraSummary {
    pub captured: u64,
    pub paired: u64,
    pub unpaired: u64,
    /// Of `paired` and `unpaired` (depth frames): decided at the end of the partner wait, not
    /// known to be with the nearest partner.
    pub paired_unproven: u64,
    pub unpaired_unproven: u64,
    /// Of `paired` (depth frames): with the colour frame the depth frame before had.
    pub paired_again: u64,
    pub dropped: BTreeMap<String, u64>,
    pub dropped_total: u64,
    pub lost_before_capture: BTreeMap<String, u64>,
    /// Frames the recorder wrote, when there was one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recorded: Option<u64>,
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub not_recorded: BTreeMap<String, u64>,
    pub not_recorded_total: u64,
    /// Frames recorded and then gone from the run's directory, by reason (with a recorder).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub lost_after_recording: BTreeMap<String, u64>,
}

impl CameraSummary {
    /// The counters of a run with or without processing and a recorder.
    pub fn of(c: &CameraCounters, processing: bool, recorder: bool) -> Self {
        let read = |m: &Mutex<BTreeMap<String, u64>>| m.lock().unwrap_or_else(PoisonError::into_inner).clone();
        let dropped = if processing { read(&c.dropped) } else { BTreeMap::new() };
        let (not_recorded, lost_after_recording) = if recorder {
            (read(&c.not_recorded), read(&c.lost_after_recording))
        } else {
            (BTreeMap::new(), BTreeMap::new())
        };
        Self {
            captured: c.captured.load(Ordering::Relaxed),
            paired: c.paired.load(Ordering::Relaxed),
            unpaired: c.unpaired.load(Ordering::Relaxed),
            paired_unproven: c.paired_unproven.load(Ordering::Relaxed),
            unpaired_unproven: c.unpaired_unproven.load(Ordering::Relaxed),
            paired_again: c.paired_again.load(Ordering::Relaxed),
            dropped_total: dropped.values().sum(),
            dropped,
            lost_before_capture: read(&c.lost),
            recorded: recorder.then(|| c.recorded.load(Ordering::Relaxed)),
            not_recorded_total: not_recorded.values().sum(),
            not_recorded,
            lost_after_recording,
        }
    }

    /// Whether every captured frame is accounted for on the processing branch.
    pub fn adds_up(&self) -> bool {
        self.captured == self.paired + self.unpaired + self.dropped_total
    }

    /// Whether every captured frame is accounted for on the recorder branch.
    pub fn recording_adds_up(&self) -> bool {
        self.recorded
            .is_some_and(|r| self.captured == r + self.not_recorded_total)
    }
}

/// An edge in a summary.
#[derive(Clone, Debug, Serialize)]
pub struct EdgeSummary {
    pub capacity: usize,
    /// Items waiting after the last send.
    pub depth: u64,
    pub max_depth: u64,
    pub dropped_full: u64,
}

impl EdgeSummary {
    pub fn of(config: EdgeConfig, stats: &EdgeStats) -> Self {
        Self {
            capacity: config.capacity.get(),
            depth: stats.depth.load(Ordering::Relaxed),
            max_depth: stats.max_depth.load(Ordering::Relaxed),
            dropped_full: stats.dropped_full.load(Ordering::Relaxed),
        }
    }
}
