//! The synchronisation stage: the head of the processing chain. It pairs the frames of both
//! cameras (the pure [`Synchronizer`] does the pairing), relearns a camera's clock when the
//! camera was reopened, and counts what becomes of each frame (paired, unpaired, rejected) in
//! the run's [`Accounting`]. A [`FlatMap`]: frames in, fewer pairs out; the runner numbers the
//! pairs for the stages behind it.

use crate::core::frame::FramePair;
use crate::runtime::accounting::{Accounting, bump};
use crate::runtime::capture::Captured;
use crate::runtime::pairing::{Role, SyncConfig, SyncOutput, Synchronizer};
use crate::runtime::pipeline::{FlatMap, StageError};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::runtime::capture::supervise::Epochs;

/// Where the frames come from, as the synchroniser needs to know it: how it learns that a
/// camera was reopened (its clock and counter then start again, and are learnt again), and
/// which clock ends a partner wait.
#[derive(Debug)]
pub enum Reopens {
    /// Live: the supervisors' reopen counters (depth, colour), read at each frame. The frames'
    /// host stamps are this machine's clock, which also ends a partner wait between frames.
    Live { epochs: Epochs, seen: [u64; 2] },
    /// Replayed: per camera (depth, colour), the host times of its first frames after a
    /// reopen, as the session's `camera_reconnected` events recorded them, earliest first.
    /// Known before the first frame, so a reopen is learnt at its very frame, never early.
    /// The host stamps are of the recording's clock: a partner wait ends by the stamps of the
    /// frames that follow (as the live run's ticks ended it), never by this machine's clock.
    Recorded([VecDeque<u64>; 2]),
}

impl Reopens {
    pub fn live(epochs: Epochs) -> Self {
        Reopens::Live { epochs, seen: [0; 2] }
    }

    /// None: a recording whose cameras were never reopened.
    pub fn none() -> Self {
        Reopens::Recorded(Default::default())
    }

    /// Whether the camera in `slot` was reopened since its last frame, this one at `host_ns`.
    fn since_last(&mut self, slot: usize, host_ns: u64) -> bool {
        match self {
            Reopens::Live { epochs, seen } => {
                let epoch = epochs[slot].load(Ordering::Acquire);
                let reopened = epoch != seen[slot];
                seen[slot] = epoch;
                reopened
            }
            Reopens::Recorded(at) => {
                let mut reopened = false;
                while at[slot].front().is_some_and(|&ns| ns <= host_ns) {
                    at[slot].pop_front();
                    reopened = true;
                }
                reopened
            }
        }
    }
}

/// Runs a [`Synchronizer`] on the captured frames.
#[derive(Debug)]
pub struct SyncStage {
    sync: Synchronizer,
    acct: Arc<Accounting>,
    reopens: Reopens,
    outputs: Vec<SyncOutput>,
    /// The synchroniser's unproven decisions already counted (paired, depth-only).
    unproven: (u64, u64),
}

impl SyncStage {
    pub fn new(config: SyncConfig, acct: Arc<Accounting>, reopens: Reopens) -> Self {
        Self {
            sync: Synchronizer::new(config),
            acct,
            reopens,
            outputs: Vec::new(),
            unproven: (0, 0),
        }
    }

    /// Counts the synchroniser's outputs and passes the pairs on.
    fn emit(&mut self, out: &mut Vec<FramePair>) {
        let acct = &self.acct;
        let (paired, alone) = self.sync.unproven();
        acct.depth
            .paired_unproven
            .fetch_add(paired - self.unproven.0, Ordering::Relaxed);
        acct.depth
            .unpaired_unproven
            .fetch_add(alone - self.unproven.1, Ordering::Relaxed);
        self.unproven = (paired, alone);
        for o in self.outputs.drain(..) {
            match o {
                SyncOutput::Pair(pair) => {
                    if pair.color_again {
                        // Its colour frame was counted paired with the depth frame before.
                        acct.depth.paired.fetch_add(1, Ordering::Relaxed);
                        acct.depth.paired_again.fetch_add(1, Ordering::Relaxed);
                    } else if pair.color.is_some() {
                        acct.depth.paired.fetch_add(1, Ordering::Relaxed);
                        acct.color.paired.fetch_add(1, Ordering::Relaxed);
                    } else {
                        acct.depth.unpaired.fetch_add(1, Ordering::Relaxed);
                    }
                    out.push(pair);
                }
                SyncOutput::UnpairedColor(_) => {
                    acct.color.unpaired.fetch_add(1, Ordering::Relaxed);
                }
                SyncOutput::Rejected { role, reason, .. } => {
                    let counters = match role {
                        Role::Depth => &acct.depth,
                        Role::Color => &acct.color,
                    };
                    bump(&counters.dropped, reason.name(), 1);
                }
            }
        }
    }
}

impl FlatMap for SyncStage {
    type In = Captured;
    type Out = FramePair;
    const NAME: &'static str = "sync";

    fn process(&mut self, captured: Captured, out: &mut Vec<FramePair>) -> Result<(), StageError> {
        let (slot, role, host_ns) = match &captured {
            Captured::Depth(f) => (0, Role::Depth, f.stamp.host_ns),
            Captured::Color(f) => (1, Role::Color, f.stamp.host_ns),
        };
        // A camera reopened since its last frame: its clock and counter start again.
        if self.reopens.since_last(slot, host_ns) {
            self.sync.restart(role);
        }
        match captured {
            Captured::Depth(f) => self.sync.push_depth(f, &mut self.outputs),
            Captured::Color(f) => self.sync.push_color(f, &mut self.outputs),
        }
        self.emit(out);
        Ok(())
    }

    fn finish(&mut self, out: &mut Vec<FramePair>) -> Result<(), StageError> {
        self.sync.flush(&mut self.outputs);
        self.emit(out);
        Ok(())
    }

    fn due_ns(&self) -> Option<u64> {
        self.sync
            .due_ns()
            .filter(|_| matches!(self.reopens, Reopens::Live { .. }))
    }

    fn tick(&mut self, now_ns: u64, out: &mut Vec<FramePair>) -> Result<(), StageError> {
        self.sync.tick(now_ns, &mut self.outputs);
        self.emit(out);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::{DepthFrame, Stamp};

    fn depth(seq: u64) -> Captured {
        let ns = seq * 33_000_000;
        stamped(seq, ns, ns)
    }

    fn stamped(seq: u64, device_ns: u64, host_ns: u64) -> Captured {
        let stamp = Stamp {
            seq,
            device_ns,
            host_ns,
        };
        Captured::Depth(Arc::new(DepthFrame::empty(stamp, 1, 1)))
    }

    /// Depth-only pairs out of a recording of six frames whose camera was reopened before its
    /// fourth, as the supervisor recorded it: the numbers go on, the device clock starts again.
    fn replayed(reopens: Reopens) -> (usize, u64) {
        let acct = Arc::new(Accounting::default());
        let config = SyncConfig {
            color: false,
            ..SyncConfig::default()
        };
        let mut stage = SyncStage::new(config, Arc::clone(&acct), reopens);
        let mut out = Vec::new();
        for seq in 0..6 {
            let device_ns = (seq % 3) * 33_000_000;
            let host_ns = seq * 33_000_000 + if seq >= 3 { 2_000_000_000 } else { 0 };
            stage.process(stamped(seq, device_ns, host_ns), &mut out).unwrap();
        }
        stage.finish(&mut out).unwrap();
        let dropped = acct.depth.dropped.lock().unwrap().values().sum();
        (out.len(), dropped)
    }

    #[test]
    fn a_reopen_a_recording_tells_of_is_learnt_at_its_frame_and_no_frame_is_refused() {
        let reopened_at = 3 * 33_000_000 + 2_000_000_000;
        let told = Reopens::Recorded([VecDeque::from([reopened_at]), VecDeque::new()]);
        assert_eq!(replayed(told), (6, 0));
        // Untold, the restarted clock refuses frames until the synchroniser learns it again.
        let (pairs, refused) = replayed(Reopens::none());
        assert!(
            refused > 0 && pairs + refused as usize == 6,
            "{pairs} pairs, {refused} refused"
        );
    }

    #[test]
    fn a_reopened_camera_is_learnt_again_and_every_frame_is_counted() {
        let acct = Arc::new(Accounting::default());
        let epochs = Epochs::default();
        let config = SyncConfig {
            color: false,
            ..SyncConfig::default()
        };
        let mut stage = SyncStage::new(config, Arc::clone(&acct), Reopens::live(epochs.clone()));
        let mut out = Vec::new();
        for seq in 0..3 {
            stage.process(depth(seq), &mut out).unwrap();
        }
        // The counter starting again without a reopen: a frame out of order.
        stage.process(depth(0), &mut out).unwrap();
        assert_eq!(out.len(), 3);
        // Reopened: the camera's counter and clock start again, and its frames go on.
        epochs[0].fetch_add(1, Ordering::Release);
        stage.process(depth(0), &mut out).unwrap();
        stage.process(depth(1), &mut out).unwrap();
        stage.finish(&mut out).unwrap();
        let seqs: Vec<u64> = out.iter().map(|p| p.depth.stamp.seq).collect();
        assert_eq!(seqs, [0, 1, 2, 0, 1]);
        assert_eq!(acct.depth.unpaired.load(Ordering::Relaxed), 5);
        let dropped = acct.depth.dropped.lock().unwrap().clone();
        assert_eq!(dropped.values().sum::<u64>(), 1, "{dropped:?}");
    }
}
