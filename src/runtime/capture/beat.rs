//! When the depth camera's frames arrive, told to a colour camera the daemon triggers in step
//! with them (`[color] trigger = "depth"`).
//!
//! Most depth cameras (Kinect, Astra, RealSense in their common modes) cannot be triggered;
//! many colour cameras can. A free-running colour camera's frames fall anywhere in the depth
//! camera's frame period, so a depth frame may wait up to half a period for its partner. A
//! colour camera triggered so that its frame is delivered just before the depth frame it
//! pairs with costs the depth frame no wait. The depth source's thread notes each arrival
//! here ([`DepthBeat::beat`]); the colour camera's trigger thread asks when the next one is
//! due ([`DepthBeat::next_after`]).

use super::{CaptureError, Clock, FrameSource};
use crate::core::frame::DepthFrame;
use crate::io::session::meta::CameraMeta;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// The depth camera's arrivals: the last one and the period between them. One writer (the
/// depth source's thread), any number of readers.
#[derive(Debug, Default)]
pub struct DepthBeat {
    /// Host time of the last arrival, ns (0: none yet).
    last_ns: AtomicU64,
    /// The period between arrivals, ns, as followed so far (0: not known yet).
    period_ns: AtomicU64,
}

/// A period is followed with this weight on each new interval (an exponential average).
const PERIOD_WEIGHT: f64 = 1.0 / 8.0;

impl DepthBeat {
    /// Notes a depth frame's arrival. An interval within a quarter of the period moves the
    /// period; a longer one (frames dropped, or a late frame) or a shorter one (a prompt frame
    /// after a late one) only moves the last arrival.
    pub fn beat(&self, host_ns: u64) {
        let last = self.last_ns.swap(host_ns, Ordering::AcqRel);
        if last == 0 || host_ns <= last {
            return;
        }
        let interval = (host_ns - last) as f64;
        let period = self.period_ns.load(Ordering::Acquire) as f64;
        let next = if period == 0.0 {
            interval
        } else if (0.75 * period..=1.25 * period).contains(&interval) {
            period + PERIOD_WEIGHT * (interval - period)
        } else {
            return;
        };
        self.period_ns.store(next.round() as u64, Ordering::Release);
    }

    /// The period between arrivals, ns, once two frames have come.
    pub fn period_ns(&self) -> Option<u64> {
        Some(self.period_ns.load(Ordering::Acquire)).filter(|&p| p > 0)
    }

    /// The first arrival expected after `after_ns`, counted on from the last arrival by whole
    /// periods; `None` before the period is known, or when no frame came for `silent_periods`
    /// periods (the camera is away: there is nothing to keep in step with).
    pub fn next_after(&self, after_ns: u64, silent_periods: u64) -> Option<u64> {
        let period = self.period_ns()?;
        let last = self.last_ns.load(Ordering::Acquire);
        if last == 0 || after_ns.saturating_sub(last) > period.saturating_mul(silent_periods) {
            return None;
        }
        if after_ns < last {
            return Some(last);
        }
        Some(last + ((after_ns - last) / period + 1) * period)
    }
}

/// A depth source that notes each frame's arrival in a [`DepthBeat`]; otherwise the source
/// itself.
#[derive(Debug)]
pub struct Beating<S> {
    source: S,
    beat: Arc<DepthBeat>,
}

impl<S> Beating<S> {
    pub fn new(source: S, beat: Arc<DepthBeat>) -> Self {
        Self { source, beat }
    }
}

impl<S: FrameSource<Frame = DepthFrame>> FrameSource for Beating<S> {
    type Frame = DepthFrame;
    fn meta(&self) -> CameraMeta {
        self.source.meta()
    }
    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        self.source.start(clock)
    }
    fn next_frame(&mut self, timeout: Duration) -> Result<Option<DepthFrame>, CaptureError> {
        let frame = self.source.next_frame(timeout)?;
        if let Some(frame) = &frame {
            self.beat.beat(frame.stamp.host_ns);
        }
        Ok(frame)
    }
    fn finished(&self) -> bool {
        self.source.finished()
    }
    fn losses(&self) -> Vec<(&'static str, u64)> {
        self.source.losses()
    }
    fn stop(&mut self) -> Result<(), CaptureError> {
        self.source.stop()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn the_next_arrival_is_counted_on_from_the_last_by_the_period() {
        let beat = DepthBeat::default();
        assert_eq!(beat.next_after(0, 4), None);
        beat.beat(1_000 * MS);
        assert_eq!(beat.next_after(1_001 * MS, 4), None, "one arrival gives no period");
        beat.beat(1_033 * MS);
        assert_eq!(beat.period_ns(), Some(33 * MS));
        assert_eq!(beat.next_after(1_040 * MS, 4), Some(1_066 * MS));
        assert_eq!(beat.next_after(1_070 * MS, 4), Some(1_099 * MS));
        assert_eq!(
            beat.next_after(1_020 * MS, 4),
            Some(1_033 * MS),
            "an instant before the last"
        );
        assert_eq!(beat.next_after(1_200 * MS, 4), None, "silent for more than 4 periods");
    }

    #[test]
    fn dropped_and_late_frames_do_not_move_the_period() {
        let beat = DepthBeat::default();
        for i in 0..10 {
            beat.beat(i * 30 * MS);
        }
        assert_eq!(beat.period_ns(), Some(30 * MS));
        beat.beat(310 * MS); // 10 ms late...
        beat.beat(330 * MS); // ... then on time
        beat.beat(390 * MS); // one frame lost
        assert_eq!(beat.period_ns(), Some(30 * MS));
        assert_eq!(beat.next_after(391 * MS, 4), Some(420 * MS));
        beat.beat(422 * MS); // 32 ms: followed a little
        let period = beat.period_ns().unwrap();
        assert!(period > 30 * MS && period < 31 * MS, "{period}");
    }
}
