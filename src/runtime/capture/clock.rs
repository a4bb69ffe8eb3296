//! The host clock frames are stamped with: the kernel's monotonic clock when running live (the
//! clock V4L2 and most drivers stamp with too), or a replay clock that only moves when told, so
//! that replays and tests are deterministic.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// A source of host time in nanoseconds.
#[derive(Clone, Debug)]
pub enum Clock {
    /// `CLOCK_MONOTONIC`: nanoseconds since boot, not counting suspend.
    Monotonic,
    /// Time set by whoever drives the replay.
    Replay(Arc<AtomicU64>),
}

impl Clock {
    /// A replay clock starting at `ns`.
    pub fn replay(ns: u64) -> Self {
        Clock::Replay(Arc::new(AtomicU64::new(ns)))
    }

    /// The current time in nanoseconds.
    pub fn now_ns(&self) -> u64 {
        match self {
            Clock::Monotonic => monotonic_ns(),
            Clock::Replay(t) => t.load(Ordering::Acquire),
        }
    }

    /// Moves a replay clock to `ns` (never backwards); does nothing to the monotonic clock.
    pub fn advance_to(&self, ns: u64) {
        if let Clock::Replay(t) = self {
            t.fetch_max(ns, Ordering::AcqRel);
        }
    }
}

/// `CLOCK_MONOTONIC` in nanoseconds.
pub fn monotonic_ns() -> u64 {
    read_ns(rustix::time::ClockId::Monotonic)
}

/// Nanoseconds of the kernel clock `id`.
pub(crate) fn read_ns(id: rustix::time::ClockId) -> u64 {
    let t = rustix::time::clock_gettime(id);
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

/// The current time as RFC 3339 UTC (`2026-11-23T10:00:00Z`), for session metadata.
pub fn utc_now() -> String {
    // Seconds since the epoch, rendered as RFC 3339 without a date library.
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let days = secs / 86_400;
    let (h, m, s) = (secs % 86_400 / 3600, secs % 3600 / 60, secs % 60);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let mo = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(mo <= 2);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}:{m:02}:{s:02}Z")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_moves_forward() {
        let a = Clock::Monotonic.now_ns();
        let b = Clock::Monotonic.now_ns();
        assert!(b >= a && a > 0);
    }

    #[test]
    fn replay_clock_only_moves_when_told_and_never_back() {
        let c = Clock::replay(10);
        assert_eq!(c.now_ns(), 10);
        c.advance_to(50);
        c.advance_to(20);
        assert_eq!(c.clone().now_ns(), 50);
    }

    #[test]
    fn utc_dates_render_as_rfc3339() {
        let s = utc_now();
        assert_eq!(s.len(), 20, "{s}");
        assert!(s.starts_with("20") && s.ends_with('Z'));
    }
}
