//! The empty cage as the depth camera sees it ([`Background`]): a per-pixel depth made from
//! frames spread over a recording (the far readings of each pixel: see
//! [`Background::from_frames`]) or from one depth image of the empty cage (a rendered cage),
//! with the rays of its pixels, the arena and the floor plane fitted inside it (`arena`), and
//! refreshed from frames without a mouse.

use super::activity::{ArenaCheck, Blob, mouse_blobs};
use super::arena::{FloorFit, Heights, find_arena};
use super::floor::fit_floor;
use super::{FloorPlane, SegmentError, SegmenterConfig, check_buffer, check_frame};
use crate::core::frame::DepthFrame;
use crate::core::geometry::Intrinsics;
use crate::core::image::Region;
use nalgebra::Point2;
use std::fmt;

/// The empty cage as the depth camera sees it: a per-pixel median depth over a region of the
/// image (the whole image, or a crop), the rays of its pixels, and the floor plane fitted to it.
#[derive(Clone)]
pub struct Background {
    pub(super) region: Region,
    pub(super) intrinsics: Intrinsics,
    /// Median depth (mm), 0 where the empty cage gives no reading.
    pub(super) depth: Vec<f32>,
    /// Each pixel's ray `(x, y, 1)` in the camera frame.
    pub(super) rays: Vec<[f32; 2]>,
    pub(super) floor: FloorPlane,
    /// 1 where the mouse can be (the arena), row-major over the region.
    pub(super) arena: Vec<u8>,
    updates: usize,
    pub(super) refit_every: usize,
    pub(super) step_mm: f32,
    pub(super) floor_tolerance_mm: f32,
    /// What the frames the model was made from say about the arena (none for a model made
    /// from one image of the empty cage).
    check: Option<ArenaCheck>,
}

/// Of a pixel's readings, those within this (mm) of its far readings make its model.
const FAR_BAND_MM: u16 = 15;

/// Readings spread over at most this many millimetres are counted rather than sorted.
const COUNTED_SPAN_MM: usize = 128;

/// A pixel's model from its readings (`values`, at least one, none zero): the median of those
/// within [`FAR_BAND_MM`] of its far reading, the one a fifth of the way from the farthest.
/// Readings that lie close together (a floor's, a still mouse's) are counted in `counts`, in
/// one pass and without sorting; the answer is the one sorting gives.
fn far_median(values: &mut [u16], counts: &mut Vec<u32>) -> u16 {
    let far_rank = (values.len() - 1) * 4 / 5;
    let (lo, hi) = values.iter().fold((u16::MAX, 0), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let span = usize::from(hi - lo) + 1;
    if span > COUNTED_SPAN_MM {
        values.sort_unstable();
        let far = values[far_rank];
        let near_far = values.partition_point(|&v| v < far.saturating_sub(FAR_BAND_MM));
        let kept = &values[near_far..];
        return kept[kept.len() / 2];
    }
    counts.clear();
    counts.resize(span, 0);
    for &v in values.iter() {
        counts[usize::from(v - lo)] += 1;
    }
    // The offset from `lo` of the reading of rank `rank` (from 0) among those at `from` or
    // above.
    let nth = |from: usize, rank: usize| {
        let mut seen = 0;
        for (k, &c) in counts[from..].iter().enumerate() {
            seen += c as usize;
            if seen > rank {
                return from + k;
            }
        }
        span - 1
    };
    let far = lo + nth(0, far_rank) as u16;
    let from = usize::from(far.saturating_sub(FAR_BAND_MM).max(lo) - lo);
    let kept: u32 = counts[from..].iter().sum();
    lo + nth(from, kept as usize / 2) as u16
}

impl fmt::Debug for Background {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Background")
            .field("region", &self.region)
            .field("floor", &self.floor)
            .field("updates", &self.updates)
            .finish_non_exhaustive()
    }
}

impl Background {
    /// A background from `frames` (full images from the camera with `intrinsics`, best spread
    /// over the whole recording). Per pixel: the readings within 15 mm of its far readings
    /// (the 80th percentile of depth), and their median. The floor and the walls are always
    /// behind the mouse, so a mouse that sits still in a fifth of the frames or more (the first
    /// minutes of a recording) does not enter the model, where a median would keep it once it
    /// is in half of them. A pixel with a reading in fewer than half the frames has none in the
    /// model.
    ///
    /// # Errors
    /// No frames, a frame of another size than `intrinsics`, bad settings, or no floor plane
    /// (see [`Background::from_depth`]).
    pub fn from_frames(
        frames: &[DepthFrame],
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
    ) -> Result<Self, SegmentError> {
        Self::from_frames_in(frames, intrinsics, config, None)
    }

    /// [`Background::from_frames`] with the arena given (see [`Background::from_depth_in`]).
    ///
    /// # Errors
    /// As [`Background::from_frames`] and [`Background::from_depth_in`].
    pub fn from_frames_in(
        frames: &[DepthFrame],
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
        arena: Option<&[u8]>,
    ) -> Result<Self, SegmentError> {
        if frames.is_empty() {
            return Err(SegmentError::NoFrames);
        }
        let region = Region::full(intrinsics);
        for f in frames {
            check_frame(f, region)?;
        }
        let (mut values, mut counts) = (Vec::with_capacity(frames.len()), Vec::new());
        let model: Vec<f32> = (0..region.len())
            .map(|i| {
                values.clear();
                values.extend(frames.iter().filter_map(|f| f.data.get(i).copied().filter(|&v| v > 0)));
                if values.len() * 2 < frames.len() {
                    return 0.0;
                }
                f32::from(far_median(&mut values, &mut counts))
            })
            .collect();
        let width = region.width as usize;
        let focal = (intrinsics.fx, intrinsics.fy);
        let min_area = f64::from(config.min_area_mm2);
        let blobs: Vec<Blob> = frames
            .iter()
            .enumerate()
            .flat_map(|(k, f)| mouse_blobs(k, &f.data, &model, width, focal, min_area))
            .collect();
        let mut background = Self::build(&model, region, intrinsics, config, arena, &blobs)?;
        background.check = Some(ArenaCheck::of(&blobs, frames.len(), &background.arena));
        Ok(background)
    }

    /// A background from one depth image of the empty cage over `region` of the camera's image
    /// (mm, 0 = no reading), such as a rendered cage: `Cage::new(&rig.depth).depth(region)`.
    ///
    /// The arena and the floor are found in it (see the `arena` module): the floor is fitted
    /// inside the arena only.
    ///
    /// # Errors
    /// A region outside the image, a buffer of the wrong length, bad intrinsics or settings,
    /// or no floor plane: no plane facing the camera with a flat region of one reading in 20.
    pub fn from_depth(
        depth: &[f32],
        region: Region,
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
    ) -> Result<Self, SegmentError> {
        Self::from_depth_in(depth, region, intrinsics, config, None)
    }

    /// [`Background::from_depth`], with the arena given when `arena` is (row-major over
    /// `region`, non-zero = inside, such as a region of interest drawn by hand): the floor is
    /// then fitted inside it and must hold a fifth of its readings.
    ///
    /// # Errors
    /// As [`Background::from_depth`], or a mask of another size than the region.
    pub fn from_depth_in(
        depth: &[f32],
        region: Region,
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
        arena: Option<&[u8]>,
    ) -> Result<Self, SegmentError> {
        Self::build(depth, region, intrinsics, config, arena, &[])
    }

    /// [`Background::from_depth_in`], the arena chosen with the help of the mouse-sized
    /// things seen in the recording's frames when it is not given (see `find_arena`).
    fn build(
        depth: &[f32],
        region: Region,
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
        arena: Option<&[u8]>,
        evidence: &[Blob],
    ) -> Result<Self, SegmentError> {
        config.validate()?;
        check_intrinsics(intrinsics)?;
        check_buffer(depth.len(), region, Region::full(intrinsics))?;
        let depth: Vec<f32> = depth
            .iter()
            .map(|&z| if z.is_finite() && z > 0.0 { z } else { 0.0 })
            .collect();
        let mut rays = Vec::with_capacity(region.len());
        for y in region.y0..region.y0 + region.height {
            for x in region.x0..region.x0 + region.width {
                let r = intrinsics.ray(&Point2::new(f64::from(x), f64::from(y)));
                rays.push([r.x as f32, r.y as f32]);
            }
        }
        let tolerance = f64::from(config.floor_tolerance_mm);
        let fit = match arena {
            Some(mask) => {
                check_buffer(mask.len(), region, region)?;
                let inside: Vec<u8> = mask.iter().map(|&m| u8::from(m != 0)).collect();
                FloorFit {
                    floor: fit_floor(&depth, &rays, tolerance, Some(&inside))?,
                    arena: inside,
                }
            }
            None => find_arena(
                &depth,
                &rays,
                region.width as usize,
                region.height as usize,
                intrinsics.fx,
                tolerance,
                evidence,
                Heights {
                    min_mm: f64::from(config.min_height_mm),
                    max_mm: f64::from(config.max_height_mm),
                },
            )?,
        };
        Ok(Self {
            region,
            intrinsics: *intrinsics,
            depth,
            rays,
            floor: fit.floor,
            arena: fit.arena,
            updates: 0,
            refit_every: config.background_frames,
            step_mm: config.background_step_mm,
            floor_tolerance_mm: config.floor_tolerance_mm,
            check: None,
        })
    }

    /// What the frames the model was made from say about the arena: in how many something of
    /// a mouse's size stood inside it and outside it. `None` for a model made from one image.
    pub fn arena_check(&self) -> Option<ArenaCheck> {
        self.check
    }

    /// The part of the image the model covers.
    pub fn region(&self) -> Region {
        self.region
    }

    /// The camera's intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The fitted floor plane, in the camera frame.
    pub fn floor_plane(&self) -> FloorPlane {
        self.floor
    }

    /// The arena: 1 where the mouse can be, row-major over [`Background::region`].
    pub fn arena(&self) -> &[u8] {
        &self.arena
    }

    /// The model's depth (mm, 0 = no reading), row-major over [`Background::region`].
    pub fn depth(&self) -> &[f32] {
        &self.depth
    }

    /// Refreshes the model with a full frame. Only frames without a mouse count
    /// (`mouse_present` false): each moves every pixel's running median towards the new
    /// reading by at most `background_step_mm`, and the floor is fitted again after
    /// `background_frames` such updates. Returns whether the model changed.
    ///
    /// # Errors
    /// A frame of another size than the model, or no floor plane in the refreshed model (the
    /// model keeps the new depths and its previous plane).
    pub fn update(&mut self, frame: &DepthFrame, mouse_present: bool) -> Result<bool, SegmentError> {
        check_frame(frame, self.region)?;
        if mouse_present {
            return Ok(false);
        }
        let step = self.step_mm;
        for (b, &d) in self.depth.iter_mut().zip(&frame.data) {
            if d == 0 {
                continue;
            }
            let d = f32::from(d);
            if *b <= 0.0 {
                *b = d;
            } else {
                *b += (d - *b).clamp(-step, step);
            }
        }
        self.updates += 1;
        if self.updates >= self.refit_every {
            self.updates = 0;
            self.floor = fit_floor(
                &self.depth,
                &self.rays,
                f64::from(self.floor_tolerance_mm),
                Some(&self.arena),
            )?;
        }
        Ok(true)
    }
}

fn check_intrinsics(i: &Intrinsics) -> Result<(), SegmentError> {
    let ok = i.width > 0
        && i.height > 0
        && i.fx.is_finite()
        && i.fy.is_finite()
        && i.fx > 0.0
        && i.fy > 0.0
        && i.cx.is_finite()
        && i.cy.is_finite()
        && i.distortion.iter().all(|k| k.is_finite());
    if ok {
        Ok(())
    } else {
        Err(SegmentError::Intrinsics {
            reason: format!(
                "{}x{} pixels, focal lengths {} and {} px, centre ({}, {})",
                i.width, i.height, i.fx, i.fy, i.cx, i.cy
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The model by sorting every pixel's readings, as it was first written.
    fn sorted_far_median(values: &[u16]) -> u16 {
        let mut values = values.to_vec();
        values.sort_unstable();
        let far = values[(values.len() - 1) * 4 / 5];
        let near_far = values.partition_point(|&v| v < far.saturating_sub(FAR_BAND_MM));
        let kept = &values[near_far..];
        kept[kept.len() / 2]
    }

    #[test]
    fn counting_gives_the_model_sorting_gives() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut counts = Vec::new();
        for case in 0..20_000 {
            let n = rng.gen_range(1..=40);
            // Floors with a millimetre or two of noise, a mouse passing over some frames,
            // spreads wider than the counted span, and readings near zero and the top.
            let (base, spread) = match case % 4 {
                0 => (rng.gen_range(400..900), 3),
                1 => (rng.gen_range(400..900), 60),
                2 => (rng.gen_range(400..900), 400),
                _ => (rng.gen_range(1..20), 30),
            };
            let mut values: Vec<u16> = (0..n).map(|_| base + rng.gen_range(0..spread)).collect();
            if case % 7 == 0 {
                values.push(u16::MAX);
            }
            let expected = sorted_far_median(&values);
            assert_eq!(far_median(&mut values, &mut counts), expected, "{values:?}");
        }
    }
}
