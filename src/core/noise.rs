//! How a depth image was noised: the camera model imitated and any added Gaussian noise.
//! Datasets and model files record it as provenance; the synthesis engine applies it.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// The kind of depth camera to imitate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseModel {
    /// Exact depth (plus any Gaussian noise asked for).
    #[default]
    None,
    /// Primesense, Kinect v1, Xtion: disparity quantised to 1/8 pixel (depth steps growing with
    /// the square of the distance), projector shadows, missing pixels on steep edges.
    StructuredLight,
    /// Time of flight: flying pixels across depth edges, noise growing with distance.
    Tof,
}

impl NoiseModel {
    pub fn name(self) -> &'static str {
        match self {
            NoiseModel::None => "none",
            NoiseModel::StructuredLight => "structured-light",
            NoiseModel::Tof => "tof",
        }
    }
}

impl fmt::Display for NoiseModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for NoiseModel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "none" => Ok(NoiseModel::None),
            "structured-light" => Ok(NoiseModel::StructuredLight),
            "tof" => Ok(NoiseModel::Tof),
            other => Err(format!(
                "unknown noise model {other:?} (expected none, structured-light or tof)"
            )),
        }
    }
}

/// A depth noise configuration.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DepthNoise {
    pub model: NoiseModel,
    /// Standard deviation of additive Gaussian noise, millimetres.
    pub gaussian_mm: f64,
}
