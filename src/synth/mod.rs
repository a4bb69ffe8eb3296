//! The synthesis engine: a kinematic mouse with a labelled skin, a procedural pose library,
//! renderers of the top depth and bottom colour views, depth noise models, and the writers of
//! training datasets and synthetic sessions.
//!
//! It stands in for the paper's 3D mouse engine: it is the ground truth for training and for
//! every accuracy figure mousepose reports.

pub mod animate;
pub mod body;
pub mod chessboard;
pub mod dataset;
pub mod mouse;
pub mod noise;
pub mod preview;
pub mod render;
pub mod session;
pub mod views;

use crate::core::geometry::{CAGE_X_MM, CAGE_Y_MM};
use crate::core::rng::item_rng;
use mouse::{Placement, PoseParams};
use rand::Rng;

/// Version of the synthesis engine's model and renderers; data files record it so a dataset
/// made by another version is recognised as such.
pub const ENGINE_VERSION: u32 = 1;

/// Random variation of a library pose for a training image: placement anywhere in the cage,
/// any heading, pitch and roll up to 10 degrees, scale 0.85-1.15, bone lengths +-10 %.
pub fn random_placement(rng: &mut impl Rng) -> Placement {
    let margin = 45.0;
    let bones = crate::core::skeleton::BoneLengths::default().map(|v| v * rng.gen_range(0.9..=1.1));
    Placement {
        x_mm: rng.gen_range(-(CAGE_X_MM / 2.0 - margin)..=(CAGE_X_MM / 2.0 - margin)),
        y_mm: rng.gen_range(-(CAGE_Y_MM / 2.0 - margin)..=(CAGE_Y_MM / 2.0 - margin)),
        heading: rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI),
        pitch: rng.gen_range(-10f64..=10.0).to_radians(),
        roll: rng.gen_range(-10f64..=10.0).to_radians(),
        scale: rng.gen_range(0.85..=1.15),
        bones,
        girth: rng.gen_range(0.9..=1.1),
    }
}

/// Small random changes to a library pose (so no two images share exact joint angles).
pub fn jitter_pose(p: &PoseParams, rng: &mut impl Rng) -> PoseParams {
    let mut q = *p;
    for y in &mut q.yaw {
        *y += rng.gen_range(-0.04..=0.04);
    }
    for x in &mut q.pitch {
        *x += rng.gen_range(-0.03..=0.03);
    }
    q.tail_curl += rng.gen_range(-0.5..=0.5);
    q.tail_yaw += rng.gen_range(-0.2..=0.2);
    q.ankle_angle += rng.gen_range(-10f64..=10.0).to_radians();
    q
}
