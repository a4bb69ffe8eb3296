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
pub mod moseq;
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
pub const ENGINE_VERSION: u32 = 2;

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
        stature: 1.0,
    }
}

/// How varied the synthetic mice are: `Standard`, the range the bundled forests were trained
/// on (what [`random_placement`] draws); `Varied`, mice well outside it, for testing how the
/// pipeline copes with real animals unlike the renderer's: sizes from small to large,
/// elongated and stout bodies, hunched and stretched backs, and tails lifted, curled or not
/// visible; `Mixed`, each item one or the other (by the parity of a dataset image's index or
/// of a session's seed: odd is varied).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mice {
    #[default]
    Standard,
    Varied,
    Mixed,
}

impl Mice {
    /// The kind of item `index` (a dataset image's index, a session's seed): `Mixed` gives
    /// `Varied` for odd ones and `Standard` for even ones.
    pub fn of_item(self, index: u64) -> Mice {
        match self {
            Mice::Mixed if index % 2 == 1 => Mice::Varied,
            Mice::Mixed => Mice::Standard,
            kind => kind,
        }
    }
}

impl std::str::FromStr for Mice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "standard" => Ok(Mice::Standard),
            "varied" => Ok(Mice::Varied),
            "mixed" => Ok(Mice::Mixed),
            _ => Err(format!("{s:?} is not a kind of mice: standard, varied or mixed")),
        }
    }
}

/// A mouse's way of holding itself, added to every pose it takes (the default, the standard
/// mice's, changes nothing).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Carriage {
    /// Added to the tail's lift above the floor (mm) and to its curl.
    pub tail_lift: f64,
    pub tail_curl: f64,
    /// How hunched the back is (positive) or stretched (negative): the back rises this much
    /// more (radians) from the rump to the mid-back and falls half as much again from there to
    /// the withers, so the hump is over the loins, behind the body's middle, as in real mice.
    pub hunch: f64,
    /// The rump's height is multiplied by this (1 for the standard mice).
    pub rump_height: f64,
}

impl Default for Carriage {
    fn default() -> Self {
        Self {
            tail_lift: 0.0,
            tail_curl: 0.0,
            hunch: 0.0,
            rump_height: 1.0,
        }
    }
}

impl Carriage {
    /// `params` as this mouse holds them.
    pub fn apply(&self, params: &mut PoseParams) {
        params.tail_lift += self.tail_lift;
        params.tail_curl += self.tail_curl;
        params.pitch[0] += self.hunch;
        params.pitch[1] -= 1.5 * self.hunch;
        params.rump_height *= self.rump_height;
    }
}

/// The build of a mouse well outside the standard range ([`Mice::Varied`]): scale 0.8-1.25
/// (about 13 to 49 g), each bone +-20 %, girth 0.75-1.45, and a carriage: the back hunched
/// or stretched, the rump carried low or high, and the tail as animated, lifted 10-30 mm,
/// curled, or not visible (4 mm long), each a quarter of the mice.
pub fn varied_build(rng: &mut impl Rng) -> (Placement, Carriage) {
    let mut placement = random_placement(rng);
    placement.scale = rng.gen_range(0.8..=1.25);
    placement.bones = crate::core::skeleton::BoneLengths::default().map(|v| v * rng.gen_range(0.8..=1.2));
    placement.girth = rng.gen_range(0.75..=1.45);
    let mut carriage = Carriage {
        hunch: rng.gen_range(-0.2..=0.3),
        rump_height: rng.gen_range(0.8..=1.3),
        ..Carriage::default()
    };
    match rng.gen_range(0..4) {
        1 => carriage.tail_lift = rng.gen_range(10.0..=30.0),
        2 => carriage.tail_curl = rng.gen_range(1.5..=3.0) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 },
        3 => placement.bones.tail = 4.0,
        _ => {}
    }
    (placement, carriage)
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

/// A mouse's build relative to the standard mouse (every factor 1): what `adapt` measures of a
/// lab's mice and renders training data with. `scale` multiplies every length (the body's
/// length grows with it), `girth` the trunk's and head's width beyond that, `height` the body's
/// height beyond that ([`Placement::stature`]), and `tail_shown` is
/// the share of mice whose tail the depth camera shows (the others' tails are 4 mm long, as a
/// camera that does not see a thin tail shows them).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Build {
    pub scale: f64,
    pub girth: f64,
    pub height: f64,
    pub tail_shown: f64,
}

impl Default for Build {
    fn default() -> Self {
        Self {
            scale: 1.0,
            girth: 1.0,
            height: 1.0,
            tail_shown: 1.0,
        }
    }
}

/// How far the mice of a dataset of one build spread around it: each factor +-this share.
const BUILD_SPREAD: f64 = 0.06;

impl Build {
    /// A mouse of exactly this build, placed at random in the cage (a session's or a test's
    /// mouse): the standard bones, no spread.
    pub fn exact(&self, rng: &mut impl Rng) -> Placement {
        let mut placement = random_placement(rng);
        placement.scale = self.scale;
        placement.girth = self.girth;
        placement.stature = self.height;
        placement.bones = crate::core::skeleton::BoneLengths::default();
        if self.tail_shown < 0.5 {
            placement.bones.tail = 4.0;
        }
        placement
    }

    /// A training image's mouse of about this build: each factor and bone within
    /// [`BUILD_SPREAD`] of it, the tail shown with probability `tail_shown`.
    pub fn around(&self, rng: &mut impl Rng) -> Placement {
        let mut placement = random_placement(rng);
        let mut spread = |v: f64| v * rng.gen_range(1.0 - BUILD_SPREAD..=1.0 + BUILD_SPREAD);
        placement.scale = spread(self.scale);
        placement.girth = spread(self.girth);
        placement.stature = spread(self.height);
        placement.bones = crate::core::skeleton::BoneLengths::default().map(&mut spread);
        if !rng.gen_bool(self.tail_shown.clamp(0.0, 1.0)) {
            placement.bones.tail = 4.0;
        }
        placement
    }
}
