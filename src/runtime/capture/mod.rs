//! Camera sources: one trait, one implementation per driver, each run alone on its own named
//! thread by the pipeline.
//!
//! A source keeps the driver's metadata on every frame ([`Stamp`]: the device's frame counter,
//! the device clock and the host's monotonic clock at arrival) and counts, by reason, the frames
//! it saw but could not pass on (a GigE buffer with missing packets, a timeout). Gaps in the
//! device counter are counted by the runner, not here.

pub mod aravis;
pub mod clock;
pub mod moseq;
pub mod openni;
pub mod rig;
pub mod session;
pub mod supervise;
pub mod v4l2;

pub use clock::Clock;
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

pub use crate::core::error_chain;

/// Frames missing from one camera's sequence numbers (the camera's own drops, or frames lost
/// on the way).
#[derive(Clone, Copy, Debug, Default)]
pub struct SeqGaps {
    last: Option<u64>,
}

impl SeqGaps {
    /// How many numbers are missing between the highest one seen so far and `seq` (0 for the
    /// first frame, and for a frame that does not move forward).
    pub fn observe(&mut self, seq: u64) -> u64 {
        let missing = self.last.map_or(0, |l| seq.saturating_sub(l).saturating_sub(1));
        self.last = Some(self.last.map_or(seq, |l| l.max(seq)));
        missing
    }
}

/// A frame from either camera of the rig, as the synchroniser takes them.
#[derive(Clone, Debug)]
pub enum Captured {
    Depth(Arc<DepthFrame>),
    Color(Arc<ColorFrame>),
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
