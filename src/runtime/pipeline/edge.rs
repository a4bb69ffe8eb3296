//! Edges: bounded channels between threads, each with a policy for when it is full and its
//! own counters.
//!
//! Edges out of capture drop the newest frame when full (a slow stage must never stall a
//! camera driver), and count each drop with the camera it came from; every other edge blocks.

use crossbeam_channel::{Receiver, Sender, TrySendError};
use serde::{Deserialize, Serialize};
use std::num::NonZeroUsize;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// What a sender does when the channel is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WhenFull {
    /// Wait for room.
    #[default]
    Block,
    /// Drop the item being sent, and count it.
    DropNewest,
}

/// An edge's capacity and policy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EdgeConfig {
    pub capacity: NonZeroUsize,
    pub when_full: WhenFull,
}

impl EdgeConfig {
    /// A blocking edge of `capacity` items (at least one).
    pub fn block(capacity: usize) -> Self {
        Self {
            capacity: NonZeroUsize::new(capacity).unwrap_or(NonZeroUsize::MIN),
            when_full: WhenFull::Block,
        }
    }

    /// A dropping edge of `capacity` items (at least one).
    pub fn drop_newest(capacity: usize) -> Self {
        Self {
            when_full: WhenFull::DropNewest,
            ..Self::block(capacity)
        }
    }
}

/// Counters of one edge, shared by its senders and whoever reports on it.
#[derive(Debug, Default)]
pub struct EdgeStats {
    pub sent: AtomicU64,
    pub dropped_full: AtomicU64,
    /// Largest number of items seen waiting in the channel.
    pub max_depth: AtomicU64,
    /// Items waiting in the channel after the last send (a gauge for the live metrics).
    pub depth: AtomicU64,
}

/// The sending end of an edge.
#[derive(Debug)]
pub struct EdgeSender<T> {
    tx: Sender<T>,
    when_full: WhenFull,
    stats: Arc<EdgeStats>,
}

impl<T> Clone for EdgeSender<T> {
    fn clone(&self) -> Self {
        Self {
            tx: self.tx.clone(),
            when_full: self.when_full,
            stats: Arc::clone(&self.stats),
        }
    }
}

/// What happened to an item sent on an edge.
#[derive(Debug, PartialEq, Eq)]
pub enum Sent {
    Delivered,
    /// The channel was full and the edge drops.
    DroppedFull,
    /// Every receiver is gone: the downstream stage stopped.
    Closed,
}

impl<T> EdgeSender<T> {
    /// Sends `item` under the edge's policy.
    pub fn send(&self, item: T) -> Sent {
        let result = match self.when_full {
            WhenFull::Block => self.tx.send(item).map_err(|_| Sent::Closed),
            WhenFull::DropNewest => self.tx.try_send(item).map_err(|e| match e {
                TrySendError::Full(_) => Sent::DroppedFull,
                TrySendError::Disconnected(_) => Sent::Closed,
            }),
        };
        match result {
            Ok(()) => {
                let depth = self.tx.len() as u64;
                self.stats.sent.fetch_add(1, Ordering::Relaxed);
                self.stats.depth.store(depth, Ordering::Relaxed);
                self.stats.max_depth.fetch_max(depth, Ordering::Relaxed);
                Sent::Delivered
            }
            Err(Sent::DroppedFull) => {
                self.stats.dropped_full.fetch_add(1, Ordering::Relaxed);
                Sent::DroppedFull
            }
            Err(other) => other,
        }
    }

    /// A sender with another policy on the same channel and counters (several cameras feed
    /// one channel, each under its own policy).
    pub fn with_policy(&self, when_full: WhenFull) -> Self {
        Self {
            when_full,
            ..self.clone()
        }
    }

    /// The channel's current queue depth.
    pub fn depth(&self) -> usize {
        self.tx.len()
    }
}

/// A named bounded edge: its sender, its receiver and its counters.
pub fn edge<T>(config: EdgeConfig) -> (EdgeSender<T>, Receiver<T>, Arc<EdgeStats>) {
    let (tx, rx) = crossbeam_channel::bounded(config.capacity.get());
    let stats = Arc::new(EdgeStats::default());
    (
        EdgeSender {
            tx,
            when_full: config.when_full,
            stats: Arc::clone(&stats),
        },
        rx,
        stats,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dropping_edge_counts_what_it_drops_and_never_blocks() {
        let (tx, rx, stats) = edge::<u32>(EdgeConfig::drop_newest(2));
        assert_eq!(tx.send(1), Sent::Delivered);
        assert_eq!(tx.send(2), Sent::Delivered);
        assert_eq!(tx.send(3), Sent::DroppedFull);
        assert_eq!(stats.dropped_full.load(Ordering::Relaxed), 1);
        assert_eq!(stats.max_depth.load(Ordering::Relaxed), 2);
        assert_eq!(rx.try_iter().collect::<Vec<_>>(), vec![1, 2]);
        drop(rx);
        assert_eq!(tx.send(4), Sent::Closed);
    }
}
