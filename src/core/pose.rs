//! Poses: the 24 joints of one frame with where each came from and how sure we are.

use crate::core::skeleton::{JOINT_COUNT, Joint};
use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Where a joint's position came from: each joint of a pose records it, beside its score.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointSource {
    /// The body forest on the top depth image (joints 1-12).
    Depth,
    /// The paw detector on the bottom colour image (joints 21-24).
    Paw,
    /// Inverse kinematics between the body and a paw (joints 13-20).
    Ik,
    /// The kinematic chain's default configuration: nothing saw it.
    #[default]
    Default,
    /// Not estimated at all (e.g. depth-only mode for joints 13-24, or no mouse).
    Missing,
}

impl JointSource {
    pub fn name(self) -> &'static str {
        match self {
            JointSource::Depth => "depth",
            JointSource::Paw => "paw",
            JointSource::Ik => "ik",
            JointSource::Default => "default",
            JointSource::Missing => "missing",
        }
    }

    /// The source a name of [`JointSource::name`] stands for.
    pub fn from_name(name: &str) -> Option<Self> {
        [
            JointSource::Depth,
            JointSource::Paw,
            JointSource::Ik,
            JointSource::Default,
            JointSource::Missing,
        ]
        .into_iter()
        .find(|s| s.name() == name)
    }
}

impl fmt::Display for JointSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One joint's estimate: position in the world frame (mm), a score in `[0, 1]` and its source.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointEstimate {
    pub position_mm: Point3<f64>,
    pub score: f64,
    pub source: JointSource,
}

impl Default for JointEstimate {
    fn default() -> Self {
        Self {
            position_mm: Point3::origin(),
            score: 0.0,
            source: JointSource::Missing,
        }
    }
}

/// The full skeleton of one frame pair.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub joints: [JointEstimate; JOINT_COUNT],
}

impl Pose {
    pub fn joint(&self, joint: Joint) -> &JointEstimate {
        &self.joints[joint.index()]
    }

    pub fn joint_mut(&mut self, joint: Joint) -> &mut JointEstimate {
        &mut self.joints[joint.index()]
    }
}

/// Ground-truth (or any exact) joint positions in the world frame, millimetres.
pub type JointPositions = [Point3<f64>; JOINT_COUNT];
