//! Segmentation of the mouse in the top depth image: a background model of
//! the empty cage, its arena and the floor plane fitted inside it, foreground inside the arena between a minimum and a maximum
//! height above that floor (and nearer than the background by a margin, so walls and fixed
//! objects never count), the largest connected component grown along its thin low parts (the
//! tail), small holes filled, and the scalars MoSeq users know.
//!
//! # How a frame is segmented
//!
//! [`Segmenter`] precomputes, for every pixel, the depth interval in which a reading is
//! foreground: height above the floor is `a * z + c` along the pixel's ray, so "between the two
//! heights and nearer than the background" is one interval of `z`. A frame then costs:
//!
//! 1. one pass over the pixels comparing each reading with its interval (the *strong* mask),
//!    counting strong pixels in 16x16 tiles;
//! 2. the densest cluster of tiles gives a box, and the connected components (8-connected)
//!    inside it give the largest strong component;
//! 3. around it, readings that differ from a neighbour's by more than a few millimetres are
//!    marked as lying on a depth jump (a time-of-flight camera mixes both sides there), and the
//!    floor's noise is measured from the readings below the floor;
//! 4. the component grows (hysteresis, as in edge detection) into connected pixels a little
//!    above the floor (`grow_height_mm`, more on a noisy floor), or along a *ridge*: the median
//!    of five readings in a line through the pixel is above `ridge_height_mm` (the tail lies on
//!    the floor and is only a millimetre or two high at its tip). Small groups of grown pixels
//!    (noise along the body's edge) are dropped;
//! 5. inside the mouse's box only: pixels on a jump go with the majority of their neighbours
//!    off jumps, pixels without a reading join the mask when most neighbours are in it, and
//!    holes smaller than `max_hole_mm2` are filled. No step removes more than a single pixel
//!    on a jump, so the 2-4 pixel tail is never cut (there is no morphological opening);
//! 6. the figures, from the mask's 3D points: area, mean height, and, from the body without the
//!    tail (an opening of the mask used for these figures only), centroid, heading, length and
//!    width.
//!
//! Missing readings (0) are never foreground, but holes of them inside the mouse are filled.
//! `segment` is pure: no threads, no clock, no I/O; the buffers it needs live in the
//! [`Segmenter`] and are reused from frame to frame.
//!
//! # Where the parts are
//!
//! This file holds the front, [`Segmenter`], with its errors, the buffers it reuses and the
//! checks of what it is given. The rest is one job a file: `config` (the settings, and a
//! segmenter built from them), `background` (the empty-cage model), `arena` (where the mouse
//! can be: the flat region the mouse is seen on, or a given mask), `walls` (the pixels near
//! the cage's walls and the arena's rim, where clutter lies), `activity` (the
//! mouse-sized things that moved in the frames the background is made of), `floor` (the floor
//! plane fitted inside it), `mask` (steps 1 to 4: the strong mask, the densest tiles, depth jumps, the
//! floor's noise, the largest component and its growth) and `mouse` (steps 5 and 6: the mask
//! tidied inside its box, and the [`Mouse`] with its figures); `components` labels a mask's
//! connected components and opens a mask by a square; `picture` colours a depth image by
//! height above the fitted floor for every picture the program draws.

mod activity;
mod arena;
mod background;
mod components;
mod config;
mod floor;
mod mask;
mod mouse;
mod picture;
mod several;
mod walls;

pub use activity::{ArenaCheck, MOUSE_MAX_AREA_MM2};
pub use arena::ARENA_MARGIN_MM;
pub use background::Background;
pub use config::SegmenterConfig;
pub use floor::FloorPlane;
pub use mouse::{Mouse, PoseFrame};
pub use picture::{PICTURE_HEIGHT_MM, caption, frame_picture, height_picture};
pub use several::{CLAIM_MARGIN_PX, Claim, Claims, PIECE_SHARE, SPLIT_SHARE, SeveralMice};
pub use walls::{WALL_HEIGHT_MM, WALL_REACH_MM};

use crate::core::frame::DepthFrame;
use crate::core::image::Region;
use nalgebra::{Isometry3, Vector3};
use std::fmt;

/// The raw growing height is this many times the floor's noise (about one floor reading in a
/// hundred lies higher).
const GROW_SIGMAS: f32 = 2.33;
/// The ridge height is this many times the floor's noise: the median of five readings varies
/// about half as much as one, and the best of four directions is taken.
const RIDGE_SIGMAS: f32 = 1.6;

/// Errors of the segmenter.
#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    #[error("segmenter setting {name} = {value} is invalid: {expected}")]
    Config {
        name: &'static str,
        value: f64,
        expected: &'static str,
    },
    #[error("camera intrinsics are unusable: {reason}")]
    Intrinsics { reason: String },
    #[error("depth frame is {width}x{height} but the background covers {expected_width}x{expected_height} pixels")]
    FrameSize {
        width: u32,
        height: u32,
        expected_width: u32,
        expected_height: u32,
    },
    #[error("depth buffer holds {len} values where its {width}x{height} region needs {expected}")]
    BufferLength {
        len: usize,
        width: u32,
        height: u32,
        expected: usize,
    },
    #[error("depth region {region:?} is empty or lies outside the background's {background:?}")]
    RegionOutside { region: Region, background: Region },
    #[error("background needs at least one depth frame")]
    NoFrames,
    #[error("floor plane cannot be fitted to the background: {reason}")]
    Floor { reason: String },
}

/// The mouse segmenter: a background model, the per-pixel foreground intervals derived from it
/// and the settings, and buffers reused between frames.
pub struct Segmenter {
    config: SegmenterConfig,
    background: Background,
    world_from_camera: Option<Isometry3<f64>>,
    /// Per background pixel: a reading `z` is foreground when `lo <= z <= hi` (`lo` is at
    /// least 1, so no reading is never foreground).
    lo: Vec<u16>,
    hi_strong: Vec<u16>,
    /// Per background pixel: 1 within [`walls::WALL_REACH_MM`] of a wall or the arena's rim.
    near_wall: Vec<u8>,
    scratch: Scratch,
}

impl fmt::Debug for Segmenter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Segmenter")
            .field("config", &self.config)
            .field("background", &self.background)
            .field("world_from_camera", &self.world_from_camera)
            .finish_non_exhaustive()
    }
}

impl Segmenter {
    /// Reports the mouse's centroid and heading in the world frame, given the depth camera's
    /// pose (`Camera::world_from_camera`).
    pub fn with_world(mut self, world_from_camera: Isometry3<f64>) -> Self {
        self.world_from_camera = Some(world_from_camera);
        self
    }

    pub fn config(&self) -> &SegmenterConfig {
        &self.config
    }

    pub fn background(&self) -> &Background {
        &self.background
    }

    /// Refreshes the background with a frame (see [`Background::update`]) and the foreground
    /// intervals with it.
    ///
    /// # Errors
    /// As [`Background::update`].
    pub fn update_background(&mut self, frame: &DepthFrame, mouse_present: bool) -> Result<(), SegmentError> {
        let changed = self.background.update(frame, mouse_present);
        if matches!(changed, Ok(true) | Err(SegmentError::Floor { .. })) {
            self.update_thresholds();
        }
        changed.map(|_| ())
    }

    /// Derives each pixel's foreground intervals from the background and the settings.
    fn update_thresholds(&mut self) {
        let FloorPlane { normal, offset_mm: c } = self.background.floor;
        let cfg = &self.config;
        let z_at = |a: f64, h: f32| (f64::from(h) - c) / a;
        let to_u16 = |z: f64| z.clamp(0.0, f64::from(u16::MAX)) as u16;
        let iter = self
            .background
            .rays
            .iter()
            .zip(&self.background.depth)
            .zip(&self.background.arena)
            .zip(self.lo.iter_mut().zip(self.hi_strong.iter_mut()));
        for (((r, &bg), &inside), (lo, hs)) in iter {
            let a = normal.dot(&Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0));
            if !a.is_finite() || a >= -1e-6 || inside == 0 {
                // Outside the arena, or the ray never meets the floor: nothing seen along it
                // is the mouse.
                (*lo, *hs) = (u16::MAX, 0);
                continue;
            }
            let mut hi = z_at(a, cfg.min_height_mm).floor();
            if bg > 0.0 {
                hi = hi.min(f64::from(bg - cfg.background_margin_mm).floor());
            }
            *lo = to_u16(z_at(a, cfg.max_height_mm).ceil()).max(1);
            *hs = to_u16(hi);
        }
        let bg = &self.background;
        let reach_px = (WALL_REACH_MM * bg.intrinsics.fx / bg.floor.camera_height_mm().max(1.0)).ceil();
        self.near_wall = walls::near_walls(
            &bg.depth,
            &bg.rays,
            &bg.arena,
            &bg.floor,
            bg.region.width as usize,
            reach_px.max(1.0) as usize,
        );
    }

    /// Segments a full depth frame.
    ///
    /// # Errors
    /// A frame of another size than the background (which must cover the whole image). An
    /// empty cage or a mouse smaller than `min_area_mm2` is `Ok(None)`.
    pub fn segment(&mut self, frame: &DepthFrame) -> Result<Option<Mouse>, SegmentError> {
        check_frame(frame, self.background.region)?;
        self.segment_region(&frame.data, self.background.region)
    }

    /// Segments a depth crop (mm, 0 = no reading) at `region` of the image, such as a dataset's
    /// top view (`TopView { region, depth, .. }`). The background must cover `region`: a
    /// full-image background serves every crop; one made from the crop's own region serves
    /// that crop.
    ///
    /// # Errors
    /// A region outside the background, or a buffer of the wrong length.
    pub fn segment_region(&mut self, depth: &[u16], region: Region) -> Result<Option<Mouse>, SegmentError> {
        let bg_region = self.background.region;
        check_buffer(depth.len(), region, bg_region)?;
        let grid = Grid {
            w: region.width as usize,
            h: region.height as usize,
            ox: (region.x0 - bg_region.x0) as usize,
            oy: (region.y0 - bg_region.y0) as usize,
            bg_w: bg_region.width as usize,
        };
        self.classify(depth, &grid);
        let Some((search, around)) = self.densest_tiles(&grid) else {
            return Ok(None);
        };
        self.mark_jumps(depth, &grid, around);
        let sigma = self.floor_noise(depth, &grid, around);
        let cfg = &self.config;
        let grow_mm = (GROW_SIGMAS * sigma).clamp(cfg.grow_height_mm, cfg.min_height_mm);
        let ridge_mm = (RIDGE_SIGMAS * sigma).max(cfg.ridge_height_mm);
        let Some(seed) = self.largest_component(&grid, search) else {
            return Ok(None);
        };
        let bounds = self.grow(depth, &grid, search, seed, grow_mm, ridge_mm);
        let mouse = self.finish(depth, region, &grid, bounds)?;
        Ok(mouse.filter(|m| f64::from(self.config.min_area_mm2) <= m.area_mm2))
    }
}

/// Buffers reused from frame to frame.
struct Scratch {
    /// Over the segmented region, row-major with its width: 1 where a reading is at least
    /// `min_height_mm` above the floor (and nearer than the background).
    strong: Vec<u8>,
    /// Over the segmented region: 1 where a reading lies on a depth jump (set around the
    /// mouse only, in `jump_span`; zero elsewhere).
    jump: Vec<u8>,
    jump_span: std::ops::Range<usize>,
    /// The grown component, over the segmented region; all zero between frames.
    mask: Vec<u8>,
    /// Strong pixels per tile, and the tiles' cluster numbers.
    tiles: Vec<u32>,
    column_counts: Vec<u8>,
    tile_cluster: Vec<u32>,
    /// Connected-component labels (a box's worth at a time).
    labels: Vec<i32>,
    /// The mouse's box with a one-pixel border: its mask, a copy of it, the body core.
    local: Vec<u8>,
    before: Vec<u8>,
    core: Vec<u8>,
    stack: Vec<u32>,
    /// Pixels grown from the seed component, and one branch of them.
    grown: Vec<u32>,
    refused: Vec<u32>,
    branch: Vec<u32>,
    /// Per column of the local image: its first and last row in the mask.
    column_first: Vec<usize>,
    column_last: Vec<usize>,
    components: components::Components,
    /// The opening's pass between rows and columns.
    open_tmp: Vec<u8>,
}

/// Geometry of a segmented region inside the background.
struct Grid {
    /// The region's size.
    w: usize,
    h: usize,
    /// Its offset in the background, and the background's width.
    ox: usize,
    oy: usize,
    bg_w: usize,
}

/// A box in a buffer's own pixel coordinates, end-exclusive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Bounds {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl Bounds {
    fn empty() -> Self {
        Self {
            x0: usize::MAX,
            y0: usize::MAX,
            x1: 0,
            y1: 0,
        }
    }
    fn add(&mut self, x: usize, y: usize) {
        self.x0 = self.x0.min(x);
        self.y0 = self.y0.min(y);
        self.x1 = self.x1.max(x + 1);
        self.y1 = self.y1.max(y + 1);
    }
    fn width(&self) -> usize {
        self.x1.saturating_sub(self.x0)
    }
    fn height(&self) -> usize {
        self.y1.saturating_sub(self.y0)
    }
}

/// Checks that a full frame matches a region that starts at the image's corner.
fn check_frame(frame: &DepthFrame, region: Region) -> Result<(), SegmentError> {
    if region.x0 != 0 || region.y0 != 0 || frame.width != region.width || frame.height != region.height {
        return Err(SegmentError::FrameSize {
            width: frame.width,
            height: frame.height,
            expected_width: region.width,
            expected_height: region.height,
        });
    }
    if frame.data.len() != region.len() {
        return Err(SegmentError::BufferLength {
            len: frame.data.len(),
            width: frame.width,
            height: frame.height,
            expected: region.len(),
        });
    }
    Ok(())
}

/// Checks that a buffer of `len` values covers `region`, which must lie inside `within`.
fn check_buffer(len: usize, region: Region, within: Region) -> Result<(), SegmentError> {
    if region.is_empty() || region.intersect(&within) != region {
        return Err(SegmentError::RegionOutside {
            region,
            background: within,
        });
    }
    if len != region.len() {
        return Err(SegmentError::BufferLength {
            len,
            width: region.width,
            height: region.height,
            expected: region.len(),
        });
    }
    Ok(())
}
