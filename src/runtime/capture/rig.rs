//! The cameras of a rig, supervised: the one constructor of every command that runs cameras
//! (`run`, `record`). Each camera is opened through its backend (`capture::backend`) and
//! reopened by its [`Supervised`] wrapper whenever it fails.

use crate::core::frame::{ColorFrame, DepthFrame};
use crate::io::session::{CameraMeta, CameraRole};
use crate::runtime::capture::backend::{ColorCamera, DepthCamera};
use crate::runtime::capture::beat::{Beating, DepthBeat};
use crate::runtime::capture::supervise::{Epochs, Reconnect, SharedHealth, StallWatch, Supervised};
use crate::runtime::capture::{CaptureError, Clock, FrameSource};
use std::sync::Arc;

/// A depth camera of any backend.
pub type DepthSource = Box<dyn FrameSource<Frame = DepthFrame>>;
/// A colour camera of any backend.
pub type ColorSource = Box<dyn FrameSource<Frame = ColorFrame>>;

/// The rig's cameras, each supervised; they start on their capture threads. The depth camera's
/// arrivals are told to the colour camera (a camera triggered in step with them uses them).
#[derive(Debug)]
pub struct RigCameras {
    pub depth: Supervised<DepthSource>,
    pub color: Option<Supervised<ColorSource>>,
    /// Per camera (depth, colour): goes up each time the camera is reopened, so that the
    /// synchroniser learns its clock again.
    pub epochs: Epochs,
}

/// A camera that failed, and which.
pub type CameraFailure = (CameraRole, CaptureError);

impl RigCameras {
    /// The cameras `depth` and `color` configure, none opened yet: each opens when started,
    /// and again after each failure, as `policy` says.
    pub fn supervised(depth: &DepthCamera, color: Option<&ColorCamera>, policy: Reconnect) -> Self {
        Self::in_step(depth, color, policy, &Arc::new(DepthBeat::default()))
    }

    /// As [`RigCameras::supervised`], the depth camera's arrivals told to `beat`.
    fn in_step(depth: &DepthCamera, color: Option<&ColorCamera>, policy: Reconnect, beat: &Arc<DepthBeat>) -> Self {
        let epochs = Epochs::default();
        let (depth, depth_beat) = (Arc::clone(depth), Arc::clone(beat));
        let depth = Supervised::new(
            CameraRole::Depth,
            Box::new(move || depth.open().map(|source| beating(source, &depth_beat))),
            policy,
            Arc::clone(&epochs[0]),
        );
        let color = color.map(|color| {
            let (color, beat) = (Arc::clone(color), Arc::clone(beat));
            Supervised::new(
                CameraRole::Color,
                Box::new(move || color.open_in_step(&beat)),
                policy,
                Arc::clone(&epochs[1]),
            )
        });
        Self { depth, color, epochs }
    }

    /// The cameras opened now, both of them (a recording needs both from its start), the depth
    /// camera started so that its metadata is known; later openings go through the config.
    /// Returns the cameras' metadata as opened.
    ///
    /// # Errors
    /// A camera cannot be opened (or the depth camera started).
    pub fn opened(
        depth: &DepthCamera,
        color: Option<&ColorCamera>,
        policy: Reconnect,
        clock: &Clock,
    ) -> Result<(Self, Vec<CameraMeta>), CameraFailure> {
        let failed = |role| move |e| (role, e);
        let beat = Arc::new(DepthBeat::default());
        let mut first_depth = beating(depth.open().map_err(failed(CameraRole::Depth))?, &beat);
        let first_color = color
            .map(|c| c.open_in_step(&beat))
            .transpose()
            .map_err(failed(CameraRole::Color))?;
        first_depth.start(clock).map_err(failed(CameraRole::Depth))?;
        let mut metas = vec![first_depth.meta()];
        metas.extend(first_color.as_ref().map(FrameSource::meta));
        let mut cameras = Self::in_step(depth, None, policy, &beat);
        cameras.depth = cameras.depth.opened(first_depth, clock);
        cameras.color = first_color.zip(color).map(|(first, color)| {
            // The first opening is the camera opened above; later ones open it again.
            let (mut first, color) = (Some(first), Arc::clone(color));
            Supervised::new(
                CameraRole::Color,
                Box::new(move || first.take().map_or_else(|| color.open_in_step(&beat), Ok)),
                policy,
                Arc::clone(&cameras.epochs[1]),
            )
        });
        Ok((cameras, metas))
    }

    /// Tries each camera once, before the pipeline starts them (a camera absent now is away,
    /// and taken when it comes).
    ///
    /// # Errors
    /// A camera whose configuration can never work ([`CaptureError::never_works`]).
    pub fn try_start(&mut self, clock: &Clock) -> Result<(), CameraFailure> {
        self.depth.start(clock).map_err(|e| (CameraRole::Depth, e))?;
        if let Some(color) = &mut self.color {
            color.start(clock).map_err(|e| (CameraRole::Color, e))?;
        }
        Ok(())
    }

    /// The watches that take a silent camera for away, checked by the command's own loop.
    pub fn stall_watches(&self) -> Vec<StallWatch> {
        let mut watches = vec![self.depth.stall_watch()];
        watches.extend(self.color.as_ref().map(Supervised::stall_watch));
        watches
    }

    /// Each camera's health, by name (`depth`, `color`).
    pub fn healths(&self) -> Vec<(&'static str, SharedHealth)> {
        let mut healths = vec![("depth", self.depth.health())];
        healths.extend(self.color.as_ref().map(|c| ("color", c.health())));
        healths
    }
}

/// A depth source that tells `beat` when its frames arrive.
fn beating(source: DepthSource, beat: &Arc<DepthBeat>) -> DepthSource {
    Box::new(Beating::new(source, Arc::clone(beat)))
}
