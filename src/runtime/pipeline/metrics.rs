//! Lock-free counters and latency histograms shared between a running pipeline's threads and
//! whoever reports on it.

use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// Sub-buckets per power of two: a recorded value is known to within 1/16 (6 %).
const SUB: u64 = 16;
const SUB_BITS: u32 = 4;
const BUCKETS: usize = (SUB as usize) * 32;

/// A histogram of durations in microseconds, log-linear buckets, safe to record from many
/// threads at once.
#[derive(Debug)]
pub struct Histogram {
    buckets: Box<[AtomicU64]>,
    count: AtomicU64,
    sum_us: AtomicU64,
    max_us: AtomicU64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            buckets: (0..BUCKETS).map(|_| AtomicU64::new(0)).collect(),
            count: AtomicU64::new(0),
            sum_us: AtomicU64::new(0),
            max_us: AtomicU64::new(0),
        }
    }
}

fn bucket_of(us: u64) -> usize {
    if us < SUB {
        return us as usize;
    }
    let e = 63 - us.leading_zeros();
    let sub = (us >> (e - SUB_BITS)) & (SUB - 1);
    ((SUB + u64::from(e - SUB_BITS) * SUB + sub) as usize).min(BUCKETS - 1)
}

/// The smallest value that falls in bucket `i`.
fn bucket_floor(i: usize) -> u64 {
    let i = i as u64;
    if i < SUB {
        return i;
    }
    let e = (i - SUB) / SUB;
    let sub = (i - SUB) % SUB;
    (SUB + sub) << e
}

impl Histogram {
    pub fn record(&self, d: Duration) {
        let us = u64::try_from(d.as_micros()).unwrap_or(u64::MAX);
        if let Some(b) = self.buckets.get(bucket_of(us)) {
            b.fetch_add(1, Ordering::Relaxed);
        }
        self.count.fetch_add(1, Ordering::Relaxed);
        self.sum_us.fetch_add(us, Ordering::Relaxed);
        self.max_us.fetch_max(us, Ordering::Relaxed);
    }

    pub fn count(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// The number of recordings and their sum in microseconds.
    pub fn totals(&self) -> (u64, u64) {
        (self.count(), self.sum_us.load(Ordering::Relaxed))
    }

    /// Recordings per bucket of a coarser histogram whose upper bounds (inclusive, ascending,
    /// microseconds) are `bounds_us`, plus one last bucket for the rest: a fine bucket counts
    /// under the first bound its whole range is at or below.
    pub fn counts_under(&self, bounds_us: &[u64]) -> Vec<u64> {
        let mut counts = vec![0; bounds_us.len() + 1];
        for (i, b) in self.buckets.iter().enumerate() {
            let n = b.load(Ordering::Relaxed);
            if n == 0 {
                continue;
            }
            let top = bucket_floor(i + 1).saturating_sub(1).max(bucket_floor(i));
            let k = bounds_us
                .iter()
                .position(|&bound| top <= bound)
                .unwrap_or(bounds_us.len());
            counts[k] += n;
        }
        counts
    }

    /// The value below which a fraction `q` of the recordings fall, in milliseconds (the
    /// upper edge of its bucket, capped at the largest value recorded); 0 when empty.
    pub fn quantile_ms(&self, q: f64) -> f64 {
        let n = self.count();
        if n == 0 {
            return 0.0;
        }
        let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, b) in self.buckets.iter().enumerate() {
            seen += b.load(Ordering::Relaxed);
            if seen >= rank {
                let upper = bucket_floor(i + 1).saturating_sub(1).max(bucket_floor(i));
                return upper.min(self.max_us.load(Ordering::Relaxed)) as f64 / 1000.0;
            }
        }
        self.max_us.load(Ordering::Relaxed) as f64 / 1000.0
    }

    /// Count, mean, p50, p99 and max, in milliseconds.
    pub fn summary(&self) -> LatencySummary {
        let n = self.count();
        LatencySummary {
            count: n,
            mean_ms: if n == 0 {
                0.0
            } else {
                self.sum_us.load(Ordering::Relaxed) as f64 / n as f64 / 1000.0
            },
            p50_ms: self.quantile_ms(0.5),
            p99_ms: self.quantile_ms(0.99),
            max_ms: self.max_us.load(Ordering::Relaxed) as f64 / 1000.0,
        }
    }
}

/// A histogram reduced to the figures a summary shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LatencySummary {
    pub count: u64,
    pub mean_ms: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_counts_add_up_and_fall_under_their_bounds() {
        let h = Histogram::default();
        for us in [3, 900, 1000, 1500, 4000, 250_000] {
            h.record(Duration::from_micros(us));
        }
        let counts = h.counts_under(&[1000, 2000, 5000]);
        assert_eq!(counts.iter().sum::<u64>(), 6);
        // 3 and 900 are within 1 ms; 1000's bucket reaches past 1000 us, so it and 1500
        // count under 2 ms; 4000 under 5 ms; 250 ms above every bound.
        assert_eq!(counts, vec![2, 2, 1, 1]);
        assert_eq!(h.totals(), (6, 3 + 900 + 1000 + 1500 + 4000 + 250_000));
    }

    #[test]
    fn buckets_are_ordered_and_tight() {
        let mut last = 0;
        for us in [0u64, 1, 15, 16, 17, 31, 32, 100, 1000, 12_345, 1 << 30] {
            let b = bucket_of(us);
            assert!(b >= last);
            last = b;
            assert!(bucket_floor(b) <= us, "{us}");
            assert!(us < 16 || (us - bucket_floor(b)) * 16 <= us, "{us}");
        }
    }

    #[test]
    fn quantiles_of_a_known_spread() {
        let h = Histogram::default();
        for ms in 1..=100u64 {
            h.record(Duration::from_millis(ms));
        }
        let s = h.summary();
        assert_eq!(s.count, 100);
        assert!((s.p50_ms - 50.0).abs() < 4.0, "{s:?}");
        assert!((s.p99_ms - 99.0).abs() < 7.0, "{s:?}");
        assert_eq!(s.max_ms, 100.0);
        assert!((s.mean_ms - 50.5).abs() < 0.01);
    }
}
