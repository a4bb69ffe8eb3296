//! The segmentation stage: finds the mouse in each depth frame, and refreshes the background
//! model with frames where there is none.
//!
//! A replay knows its empty cage before it starts (the median over the whole recording). A
//! live run cannot sample the future: it either loads a reference recorded with the cage
//! empty, or learns the background as it goes ([`SegmentStage::learning`]). Learning keeps,
//! per pixel, the farthest depth seen (moving out by at most a step per frame, so that a
//! single bad reading does not count): the floor and walls are always behind the mouse, so a
//! mouse present from the first frame drops out of the model as soon as it has moved off each
//! place. While no floor can be found in what was learnt (a camera pointed wrong, a test
//! device), frames go on with the status `no_background`, and learning goes on.

use super::{Found, Segmented};
use crate::core::frame::{DepthFrame, FramePair};
use crate::core::geometry::Intrinsics;
use crate::core::image::Region;
use crate::runtime::pipeline::{Map, StageError};
use crate::runtime::pose_record::Identity;
use crate::vision::identity::{MiceTracker, NumberedMice};
use crate::vision::segment::{Background, FloorPlane, SegmentError, Segmenter, SegmenterConfig};
use nalgebra::Isometry3;
use std::sync::{Arc, Mutex, PoisonError};

/// The floor the segmenter fitted last (in the depth camera's frame), for whoever draws the
/// live view; `None` before any.
pub type FloorSlot = Arc<Mutex<Option<FloorPlane>>>;

/// Runs a [`Segmenter`] on each pair's depth frame.
#[derive(Debug)]
pub struct SegmentStage {
    segmenter: Option<Segmenter>,
    learner: Option<Learner>,
    floor: Option<FloorSlot>,
    /// With several mice in the cage: their tracks ([`SegmentStage::with_mice`]).
    mice: Option<MiceTracker>,
}

/// The background learnt online; see the module documentation.
#[derive(Debug)]
struct Learner {
    config: SegmenterConfig,
    intrinsics: Intrinsics,
    world: Isometry3<f64>,
    /// Farthest depth seen per pixel (mm, 0 = none yet).
    far: Vec<f32>,
    /// Pixels that moved out by a margin since the model was last built.
    moved: usize,
    frames: u64,
}

/// How far a pixel of the learnt background may move out per frame (mm).
const LEARN_STEP_MM: f32 = 8.0;
/// The model is rebuilt when this share of the pixels moved out by a margin since it was
/// built (rebuilding fits the floor again: a few milliseconds).
const REBUILD_SHARE: f64 = 0.002;
/// Frames between two tries to build a model while there is none.
const RETRY_FRAMES: u64 = 15;

impl SegmentStage {
    /// A stage with a known background.
    pub fn new(segmenter: Segmenter) -> Self {
        Self {
            segmenter: Some(segmenter),
            learner: None,
            floor: None,
            mice: None,
        }
    }

    /// The same stage, telling `slot` each floor it fits.
    #[must_use]
    pub fn with_floor_slot(mut self, slot: FloorSlot) -> Self {
        self.floor = Some(slot);
        self.publish_floor();
        self
    }

    fn publish_floor(&self) {
        if let (Some(slot), Some(segmenter)) = (&self.floor, &self.segmenter) {
            *slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(segmenter.background().floor_plane());
        }
    }

    /// A stage that learns the background from the frames it sees, for a camera with
    /// `intrinsics` placed at `world` (the rig's `world_from_camera`).
    pub fn learning(config: SegmenterConfig, intrinsics: Intrinsics, world: Isometry3<f64>) -> Self {
        Self {
            segmenter: None,
            learner: Some(Learner {
                config,
                intrinsics,
                world,
                far: Vec::new(),
                moved: 0,
                frames: 0,
            }),
            floor: None,
            mice: None,
        }
    }

    /// The same stage, finding `count` mice in each frame and numbering them (1 to
    /// [`crate::vision::identity::MOST_MICE`]); one is what it does without.
    #[must_use]
    pub fn with_mice(mut self, count: usize) -> Self {
        self.mice = (count > 1).then(|| MiceTracker::new(count));
        self
    }

    /// What a frame without a segmenter gives: no mouse, each numbered as ever.
    fn nothing_found(&self) -> Vec<Found> {
        match &self.mice {
            None => vec![Found {
                mouse: None,
                identity: None,
            }],
            Some(tracker) => (1..=tracker.count())
                .map(|mouse| Found {
                    mouse: None,
                    identity: Some(Identity {
                        mouse,
                        confidence: 0.0,
                        swap_with: None,
                        beyond: 0,
                    }),
                })
                .collect(),
        }
    }

    /// Whether a background model is in use.
    pub fn has_background(&self) -> bool {
        self.segmenter.is_some()
    }
}

impl Learner {
    /// Takes a frame in; whether the model should be built again.
    fn observe(&mut self, frame: &DepthFrame, have_model: bool) -> bool {
        let n = frame.data.len();
        if self.far.len() != n || self.intrinsics.width != frame.width || self.intrinsics.height != frame.height {
            // The first frame, or a camera that came back in another mode: start again.
            self.intrinsics.width = frame.width;
            self.intrinsics.height = frame.height;
            self.far = frame.data.iter().map(|&d| f32::from(d)).collect();
            self.moved = n;
            self.frames = 0;
        } else {
            let margin = self.config.background_margin_mm;
            for (b, &d) in self.far.iter_mut().zip(&frame.data) {
                let d = f32::from(d);
                if d > *b {
                    let before = *b;
                    *b = if *b <= 0.0 { d } else { (*b + LEARN_STEP_MM).min(d) };
                    if *b - before >= margin.min(LEARN_STEP_MM) {
                        self.moved += 1;
                    }
                }
            }
        }
        self.frames += 1;
        if have_model {
            self.moved as f64 >= REBUILD_SHARE * n as f64
        } else {
            self.frames % RETRY_FRAMES == 1
        }
    }

    fn build(&mut self) -> Result<Segmenter, SegmentError> {
        let full = Region::full(&self.intrinsics);
        let background = Background::from_depth(&self.far, full, &self.intrinsics, &self.config)?;
        self.moved = 0;
        Ok(self.config.build(background)?.with_world(self.world))
    }
}

impl Map for SegmentStage {
    type In = FramePair;
    type Out = Segmented;
    const NAME: &'static str = "segment";

    fn process(&mut self, pair: FramePair) -> Result<Segmented, StageError> {
        if let Some(learner) = &mut self.learner {
            if learner.observe(&pair.depth, self.segmenter.is_some()) {
                match learner.build() {
                    Ok(s) => {
                        if self.segmenter.is_none() {
                            tracing::info!(
                                frames = learner.frames,
                                "background found: floor fitted to the depth view"
                            );
                        }
                        self.segmenter = Some(s);
                        self.publish_floor();
                    }
                    Err(e) if self.segmenter.is_none() && learner.frames == 1 => {
                        tracing::warn!("no background yet, learning it from the frames (status no_background): {e}");
                    }
                    Err(e) => tracing::debug!("background not rebuilt: {e}"),
                }
            }
        }
        let Some(segmenter) = &mut self.segmenter else {
            return Ok(Segmented {
                mice: self.nothing_found(),
                pair,
                background: false,
            });
        };
        let found = match &mut self.mice {
            None => segmenter
                .segment(&pair.depth)
                .map(|mouse| vec![Found { mouse, identity: None }]),
            Some(tracker) => tracker.next(segmenter, &pair.depth).map(numbered),
        };
        let mice = match found {
            Ok(mice) => mice,
            // A live camera that came back in another mode: the learner starts again.
            Err(SegmentError::FrameSize { .. }) if self.learner.is_some() => {
                self.segmenter = None;
                return Ok(Segmented {
                    mice: self.nothing_found(),
                    pair,
                    background: false,
                });
            }
            Err(e) => return Err(e.into()),
        };
        if mice.iter().all(|m| m.mouse.is_none()) {
            segmenter.update_background(&pair.depth, false)?;
        }
        Ok(Segmented {
            pair,
            mice,
            background: true,
        })
    }
}

/// A frame's mice by number as the pipeline carries them, each with its identity.
fn numbered(numbered: NumberedMice) -> Vec<Found> {
    let (swap, beyond) = (numbered.possible_swap, numbered.beyond);
    let other_of = |k: usize| match swap {
        Some((a, b)) if a == k => Some(b),
        Some((a, b)) if b == k => Some(a),
        _ => None,
    };
    numbered
        .mice
        .into_iter()
        .zip(1..)
        .map(|(found, k)| {
            let (mouse, confidence) = found.map_or((None, 0.0), |(m, c)| (Some(m), c));
            Found {
                mouse,
                identity: Some(Identity {
                    mouse: k,
                    confidence,
                    swap_with: other_of(k),
                    beyond,
                }),
            }
        })
        .collect()
}
