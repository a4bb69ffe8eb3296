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
use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::runtime::capture::supervise::Epochs;

/// Runs a [`Synchronizer`] on the captured frames.
#[derive(Debug)]
pub struct SyncStage {
    sync: Synchronizer,
    acct: Arc<Accounting>,
    epochs: Epochs,
    seen_epochs: [u64; 2],
    outputs: Vec<SyncOutput>,
    /// The synchroniser's unproven decisions already counted (paired, depth-only).
    unproven: (u64, u64),
    /// Whether the frames' host stamps are this machine's clock, which then tells the end of
    /// a partner wait between frames ([`SyncStage::replaying`]: not).
    live_clock: bool,
}

impl SyncStage {
    pub fn new(config: SyncConfig, acct: Arc<Accounting>, epochs: Epochs) -> Self {
        Self {
            sync: Synchronizer::new(config),
            acct,
            epochs,
            seen_epochs: [0; 2],
            outputs: Vec::new(),
            unproven: (0, 0),
            live_clock: true,
        }
    }

    /// For recorded frames, whose host stamps are of the recording's clock: a partner wait
    /// ends by the stamps of the frames that follow (as the live run's ticks ended it), never
    /// by this machine's clock.
    pub fn replaying(self) -> Self {
        Self {
            live_clock: false,
            ..self
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
                    if pair.color.is_some() {
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
        let (slot, role) = match &captured {
            Captured::Depth(_) => (0, Role::Depth),
            Captured::Color(_) => (1, Role::Color),
        };
        // A camera reopened since its last frame: its clock and counter start again.
        let epoch = self.epochs[slot].load(Ordering::Acquire);
        if epoch != self.seen_epochs[slot] {
            self.seen_epochs[slot] = epoch;
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
        self.sync.due_ns().filter(|_| self.live_clock)
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
        let stamp = Stamp {
            seq,
            device_ns: ns,
            host_ns: ns,
        };
        Captured::Depth(Arc::new(DepthFrame::empty(stamp, 1, 1)))
    }

    #[test]
    fn a_reopened_camera_is_learnt_again_and_every_frame_is_counted() {
        let acct = Arc::new(Accounting::default());
        let epochs = Epochs::default();
        let config = SyncConfig {
            color: false,
            ..SyncConfig::default()
        };
        let mut stage = SyncStage::new(config, Arc::clone(&acct), epochs.clone());
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
