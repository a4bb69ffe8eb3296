//! A paw model of either kind: the paper's boosted cascade ([`PawDetector`], an OpenCV
//! cascade XML file) or the small convolutional network ([`NetDetector`], a `safetensors`
//! file), told apart by the file's name.

use super::detect::{FoundScale, FrameRegion, PawDetector, find_scale_with};
use super::net::{NetDetector, PawNet};
use super::{PawDetection, PawError};
use crate::core::frame::ColorFrame;
use std::path::Path;

/// A paw model ready to run. Cheap to clone: one per worker thread.
#[derive(Clone, Debug)]
pub enum PawModel {
    // Both boxed: each detector holds its buffers inline, hundreds of bytes.
    Cascade(Box<PawDetector>),
    Net(Box<NetDetector>),
}

impl PawModel {
    /// Reads a model file: a network when its name ends in `.safetensors`, else a cascade.
    ///
    /// # Errors
    /// As [`PawDetector::load`] and [`PawNet::load`].
    pub fn load(path: &Path) -> Result<Self, PawError> {
        if path.extension().is_some_and(|e| e == "safetensors") {
            Ok(Self::Net(Box::new(NetDetector::new(&PawNet::load(path)?)?)))
        } else {
            Ok(Self::Cascade(Box::new(PawDetector::load(path)?)))
        }
    }

    /// The same model keeping every candidate it finds, for a score curve: a cascade grouping
    /// no raw windows, a network reporting peaks of any probability from 0.05.
    pub fn permissive(&self) -> Self {
        match self {
            Self::Cascade(d) => {
                let mut d = d.clone();
                d.set_min_neighbors(0);
                Self::Cascade(d)
            }
            Self::Net(d) => {
                let mut d = d.clone();
                d.set_threshold(0.05);
                Self::Net(d)
            }
        }
    }

    /// `cascade` or `network`, for reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Cascade(_) => "cascade",
            Self::Net(_) => "network",
        }
    }

    /// Detects paws in `frame` within `roi`, the glass seen at `px_per_mm`: clears `out` and
    /// pushes the paws found, surest first ([`PawDetector::detect`], [`NetDetector::detect`]).
    pub fn detect(
        &mut self,
        frame: &ColorFrame,
        roi: (u32, u32, u32, u32),
        px_per_mm: f64,
        out: &mut Vec<PawDetection>,
    ) {
        match self {
            Self::Cascade(d) => d.detect(frame, roi, px_per_mm, out),
            Self::Net(d) => d.detect(frame, roi, px_per_mm, out),
        }
    }

    /// The scale at which the regions of `frames` show paws ([`find_scale_with`]).
    pub fn find_scale(&mut self, frames: &[FrameRegion<'_>], lowest: f64, highest: f64) -> Option<FoundScale> {
        match self {
            Self::Cascade(d) => d.find_scale(frames, lowest, highest),
            Self::Net(d) => find_scale_with(frames, lowest, highest, |frame, roi, px_per_mm, out| {
                d.detect(frame, roi, px_per_mm, out);
            }),
        }
    }
}
