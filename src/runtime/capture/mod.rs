//! Camera sources: one trait, one implementation per driver, each run alone on its own named
//! thread by the pipeline.
//!
//! A source keeps the driver's metadata on every frame ([`Stamp`]: the device's frame counter,
//! the device clock and the host's monotonic clock at arrival) and counts, by reason, the frames
//! it saw but could not pass on (a GigE buffer with missing packets, a timeout). Gaps in the
//! device counter are counted by the runner, not here.
//!
//! The backends are registered here, one line each ([`DEPTH_BACKENDS`], [`COLOR_BACKENDS`]);
//! what a backend is: [`backend`].

pub mod aravis;
pub mod backend;
pub mod beat;
pub mod clock;
pub mod openni;
pub mod rig;
pub mod session;
pub mod supervise;
#[cfg(test)]
mod test_pattern;
pub mod v4l2;

pub use clock::Clock;

use backend::{ColorBackend, DepthBackend};

/// The depth camera backends: `[depth] backend = "..."` names one.
pub const DEPTH_BACKENDS: &[DepthBackend] = &[openni::REGISTERED, session::REGISTERED];

/// The colour camera backends: `[color] backend = "..."` names one.
pub const COLOR_BACKENDS: &[ColorBackend] = &[
    aravis::REGISTERED,
    v4l2::REGISTERED,
    #[cfg(test)]
    test_pattern::REGISTERED,
];

pub use openni::{OpenNiConfig, OpenNiDepth};

use crate::core::frame::{ColorFrame, DepthFrame, Stamp};
use crate::io::session::meta::CameraMeta;
use std::sync::Arc;
use std::time::Duration;

/// Why a source failed. A bad frame is not an error (it is counted in [`FrameSource::losses`]);
/// these are the failures that end the source: the camera cannot be opened, configured or read.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// No camera answers to the name or address in the config.
    #[error("no {backend} camera {id:?} found")]
    NotFound { backend: &'static str, id: String },
    /// The camera refused a setting (mode, pixel format, region, exposure...).
    #[error("{backend} camera {id:?} refused {what}: {reason}")]
    Refused {
        backend: &'static str,
        id: String,
        what: String,
        reason: String,
    },
    /// The driver reported a failure.
    #[error("{backend} camera {id:?}: {what}")]
    Driver {
        backend: &'static str,
        id: String,
        what: String,
        #[source]
        source: Option<Box<dyn std::error::Error + Send + Sync>>,
    },
    /// Another application controls the camera; it may be free again later.
    #[error("{backend} camera {id:?} is held: {reason}")]
    Held {
        backend: &'static str,
        id: String,
        reason: String,
    },
    /// The camera stopped delivering frames (unplugged, powered off, network lost).
    #[error("{backend} camera {id:?} disconnected: {reason}")]
    Disconnected {
        backend: &'static str,
        id: String,
        reason: String,
    },
    /// A recording being read as a camera is unreadable.
    #[error("reading {path:?}")]
    Recording {
        path: std::path::PathBuf,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl CaptureError {
    /// Whether the configuration itself is at fault, so that trying again cannot help: the
    /// camera is there and refuses a setting it does not have (a mode, a trigger line, a
    /// range), or a recording played as the camera cannot be read. A camera absent, held or
    /// failing may come back; these never do.
    pub fn never_works(&self) -> bool {
        matches!(self, CaptureError::Refused { .. } | CaptureError::Recording { .. })
    }
}

pub use crate::core::error_chain;

/// Frames missing from one camera's sequence numbers (the camera's own drops, or frames lost
/// on the way).
///
/// A counter does not always just grow: a 32-bit counter wraps, a camera that restarts counts
/// from 0 again, and a damaged stamp can carry a wild number. A frame whose number goes back,
/// or jumps ahead much further than the time since the last frame allows, is set aside; three
/// such frames in a row mean the counter really started again (the frames lost at the restart
/// are then estimated from the time between the frames), while a lone one is ignored. A number
/// that goes round 2^32 is a wrap and counts the numbers in between.
#[derive(Clone, Copy, Debug, Default)]
pub struct SeqGaps {
    /// The newest frame of the counter in use.
    last: Option<Stamp>,
    /// The shortest host time per counter step seen (the frame interval).
    interval_ns: Option<u64>,
    /// The first of the frames set aside in a row, and how many there are.
    aside: Option<(Stamp, u32)>,
}

/// Frames set aside in a row that mean a counter started again.
const COUNTER_RESTART_AFTER: u32 = 3;

/// Frames between `last` and `next` (exclusive) by the time between them, for a camera
/// delivering a frame every `interval_ns`.
pub fn frames_between_by_time(last: Stamp, next: Stamp, interval_ns: u64) -> u64 {
    let dt = next.host_ns.saturating_sub(last.host_ns);
    ((dt + interval_ns / 2) / interval_ns.max(1)).saturating_sub(1)
}

/// Counter steps from `last` to `next` when `next` went round a 32-bit counter's end.
pub fn wrapped_steps(last: u64, next: u64) -> Option<u64> {
    const END: u64 = 1 << 32;
    const NEAR: u64 = 1 << 24;
    ((END - NEAR..END).contains(&last) && next < NEAR).then(|| END - last + next)
}

impl SeqGaps {
    /// How many numbers are missing before `stamp` (0 for the first frame, and for a frame set
    /// aside); see the type's documentation.
    pub fn observe(&mut self, stamp: Stamp) -> u64 {
        let Some(last) = self.last else {
            self.last = Some(stamp);
            return 0;
        };
        let steps = match stamp.seq.checked_sub(last.seq).filter(|&d| d > 0) {
            Some(d) => Some(d),
            None => wrapped_steps(last.seq, stamp.seq),
        };
        let by_time = self.interval_ns.map(|i| frames_between_by_time(last, stamp, i) + 1);
        let plausible = steps.is_some_and(|d| by_time.is_none_or(|t| d <= 2 * t + 8));
        if !plausible {
            let (first, n) = self.aside.get_or_insert((stamp, 0));
            *n += 1;
            if *n < COUNTER_RESTART_AFTER {
                return 0;
            }
            // The counter started again at the first frame set aside: the frames lost there
            // by the time, and the ones between the frames set aside by their numbers.
            let (first, n) = (*first, *n);
            self.aside = None;
            self.last = Some(first);
            let at_restart = self.interval_ns.map_or(0, |i| frames_between_by_time(last, first, i));
            // The frames set aside between the first and this one were delivered.
            return at_restart + self.observe(stamp).saturating_sub(u64::from(n - 2));
        }
        // Frames set aside since the last one were delivered: not missing (a wild number on
        // a frame in its place).
        let aside = self.aside.take().map_or(0, |(_, n)| u64::from(n));
        let steps = steps.unwrap_or(1);
        let per_step = stamp.host_ns.saturating_sub(last.host_ns) / steps;
        if per_step > 0 {
            self.interval_ns = Some(self.interval_ns.map_or(per_step, |i| i.min(per_step)));
        }
        self.last = Some(stamp);
        (steps - 1).saturating_sub(aside)
    }
}

/// A frame from either camera of the rig, as the synchroniser takes them.
#[derive(Clone, Debug)]
pub enum Captured {
    Depth(Arc<DepthFrame>),
    Color(Arc<ColorFrame>),
}

impl Captured {
    /// A depth camera's frame.
    pub fn depth(frame: DepthFrame) -> Self {
        Captured::Depth(Arc::new(frame))
    }

    /// A colour camera's frame.
    pub fn color(frame: ColorFrame) -> Self {
        Captured::Color(Arc::new(frame))
    }
}

impl Stamped for Captured {
    fn stamp(&self) -> Stamp {
        match self {
            Captured::Depth(f) => f.stamp,
            Captured::Color(f) => f.stamp,
        }
    }
}

/// What every frame type a source can produce has: its stamp.
pub trait Stamped {
    fn stamp(&self) -> Stamp;
}

impl Stamped for DepthFrame {
    fn stamp(&self) -> Stamp {
        self.stamp
    }
}

impl Stamped for ColorFrame {
    fn stamp(&self) -> Stamp {
        self.stamp
    }
}

/// A camera, a recording read as a camera, or anything else that yields stamped frames.
///
/// Lifecycle: `start` once, `next_frame` until shutdown or an error, `stop` once. Each call
/// happens on the source's own thread; nothing else touches the source meanwhile.
pub trait FrameSource: Send + std::fmt::Debug + 'static {
    type Frame: Stamped + Send + 'static;

    /// What the session metadata says of this camera (model, serial, mode). Valid after `start`.
    fn meta(&self) -> CameraMeta;

    /// Starts streaming. `clock` is the host clock frames are stamped with (`host_ns`); a source
    /// that knows its driver's clock works out the offset here.
    ///
    /// # Errors
    /// The camera cannot be started in the configured mode.
    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError>;

    /// Waits at most `timeout` for the next good frame; `Ok(None)` means none arrived yet (never
    /// spins). Frames the driver delivered damaged are counted in [`FrameSource::losses`] and not
    /// returned.
    ///
    /// # Errors
    /// The camera is lost; the source cannot go on.
    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Self::Frame>, CaptureError>;

    /// True when the source has no more frames (the end of a recording). Cameras never end.
    fn finished(&self) -> bool {
        false
    }

    /// Frames the driver delivered that were not passed on, by reason, counted since `start`
    /// (e.g. `("incomplete", 3)` for GigE buffers with missing packets).
    fn losses(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }

    /// Stops streaming and releases the device.
    ///
    /// # Errors
    /// The driver failed to stop cleanly (the frames already returned stay valid).
    fn stop(&mut self) -> Result<(), CaptureError>;
}

/// A source chosen at run time (a camera started by the caller, or a supervised one).
impl<S: FrameSource + ?Sized> FrameSource for Box<S> {
    type Frame = S::Frame;
    fn meta(&self) -> CameraMeta {
        (**self).meta()
    }
    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        (**self).start(clock)
    }
    fn next_frame(&mut self, timeout: Duration) -> Result<Option<Self::Frame>, CaptureError> {
        (**self).next_frame(timeout)
    }
    fn finished(&self) -> bool {
        (**self).finished()
    }
    fn losses(&self) -> Vec<(&'static str, u64)> {
        (**self).losses()
    }
    fn stop(&mut self) -> Result<(), CaptureError> {
        (**self).stop()
    }
}

/// A camera a backend can see, as `mousepose devices` lists it.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct DeviceInfo {
    /// `openni2`, `aravis` or `v4l2`.
    pub backend: &'static str,
    /// What to put in the config to open this camera (URI, serial, address or device path).
    pub id: String,
    pub model: String,
    pub serial: String,
    /// Other facts worth showing (vendor, address, driver), free-form.
    pub details: String,
}

#[cfg(test)]
mod seq_gaps_tests {
    use super::*;

    /// Frames at 30 fps: (counter, frame index in time).
    fn gaps(frames: &[(u64, u64)]) -> Vec<u64> {
        let mut g = SeqGaps::default();
        frames
            .iter()
            .map(|&(seq, k)| {
                g.observe(Stamp {
                    seq,
                    device_ns: k * 33_333_333,
                    host_ns: 1_000_000_000 + k * 33_333_333,
                })
            })
            .collect()
    }

    #[test]
    fn gaps_in_a_growing_counter_are_its_missing_numbers() {
        assert_eq!(gaps(&[(5, 0), (6, 1), (9, 4), (10, 5)]), [0, 0, 2, 0]);
    }

    #[test]
    fn a_32_bit_wrap_counts_the_frames_lost_across_it() {
        let end = 1u64 << 32;
        // end-2, end-1, [0, 1 lost], 2
        assert_eq!(
            gaps(&[(end - 3, 0), (end - 2, 1), (end - 1, 2), (2, 5), (3, 6)]),
            [0, 0, 0, 2, 0]
        );
    }

    #[test]
    fn a_counter_that_starts_again_counts_the_frames_lost_at_the_restart_by_time() {
        // 100..103, then 4 frame times without a frame, then the counter from 0.
        let out = gaps(&[(100, 0), (101, 1), (102, 2), (103, 3), (0, 8), (1, 9), (2, 10), (4, 12)]);
        assert_eq!(out.iter().sum::<u64>(), 4 + 1, "{out:?}");
        assert_eq!(out[7], 1, "gaps after the restart are counted again: {out:?}");
    }

    #[test]
    fn one_frame_with_a_wild_counter_counts_no_gap() {
        let out = gaps(&[(10, 0), (11, 1), (12, 2), (1 << 40, 3), (14, 4), (15, 5)]);
        assert_eq!(out, [0, 0, 0, 0, 0, 0], "the wild frame's own number is ignored");
    }
}
