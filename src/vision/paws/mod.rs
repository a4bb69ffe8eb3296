//! Step 2 of the paper: the paws in the bottom colour view, found by a boosted cascade of
//! Haar-like features (Viola-Jones) stored in OpenCV's cascade XML.
//!
//! The parts, one idea per file: [`integral`] images, [`haar`] features and OpenCV's window
//! normalisation, the in-memory [`cascade`], its [`xml`] form, [`boost`]ing of one stage,
//! [`train`]ing of the whole cascade with bootstrapped negatives, the training windows cut
//! from synthetic datasets ([`data`]), the grey image at the detector's canonical scale
//! ([`grey`]), the run-time [`detect`]or and its evaluation ([`eval`]).
//!
//! The detector works on a grey image at [`CANONICAL_PX_PER_MM`] (1 pixel per millimetre on
//! the glass); [`PawDetector::detect`] converts any colour frame's region to that scale first.

pub mod boost;
pub mod cascade;
pub mod detect;
pub mod footprint;
pub mod grey;
pub mod haar;
pub mod integral;
pub mod model;
pub mod net;
pub mod train;
pub mod xml;

pub use cascade::Cascade;
pub use detect::PawDetector;
pub use footprint::{FOOTPRINT_MARGIN_MM, footprint};
pub use model::PawModel;

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The scale of the grey image the cascade runs on: pixels per millimetre on the glass.
pub const CANONICAL_PX_PER_MM: f64 = 1.0;

/// The detection window's side, pixels at the canonical scale (millimetres on the glass).
pub const WINDOW_PX: u32 = 12;

/// A mouse's paws: how many detections a view of one mouse keeps by default, the surest
/// ([`keep_surest`]).
pub const PAWS_PER_VIEW: usize = 4;

/// Keeps the `n` surest of `found` (all when `n` is 0), surest first.
pub fn keep_surest(found: &mut Vec<PawDetection>, n: usize) {
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    if n > 0 {
        found.truncate(n);
    }
}

/// One paw found in a bottom colour frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PawDetection {
    /// Box in the full colour frame's pixel coordinates.
    pub x0: f32,
    pub y0: f32,
    pub x1: f32,
    pub y1: f32,
    /// The detector's confidence: higher is surer; comparable between detections of one model.
    pub score: f32,
}

impl PawDetection {
    /// The box's centre, in the colour frame's pixel coordinates.
    pub fn centre(&self) -> (f64, f64) {
        (f64::from(self.x0 + self.x1) / 2.0, f64::from(self.y0 + self.y1) / 2.0)
    }
}

/// Errors reading, writing or training a paw cascade.
#[derive(Debug, thiserror::Error)]
pub enum PawError {
    #[error("cannot {action} cascade {path:?}")]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("cascade {path:?} is not well-formed XML")]
    Xml {
        path: PathBuf,
        #[source]
        source: roxmltree::Error,
    },
    #[error("cascade {path:?} is damaged: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error("cascade {path:?} uses {what}, which mousepose does not support")]
    Unsupported { path: PathBuf, what: String },
    #[error("training stopped: {reason}")]
    Training { reason: String },
}
