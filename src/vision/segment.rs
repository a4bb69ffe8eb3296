//! Segmentation of the mouse in the top depth image (DESIGN.md sec. 4): a background model of
//! the empty cage, the floor plane fitted to it, foreground between a minimum and a maximum
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
//! 2. the densest cluster of tiles gives a box, and OpenCV's connected components (8-connected)
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
//! `segment` is pure: no threads (OpenCV is told to use none of its own), no clock, no I/O;
//! the buffers it needs live in the [`Segmenter`] and are reused from frame to frame.

use crate::core::frame::DepthFrame;
use crate::core::geometry::Intrinsics;
use crate::core::image::Region;
use nalgebra::{Isometry3, Matrix2, Matrix3, Point2, Point3, SymmetricEigen, Vector2, Vector3};
use opencv::core::{self as cv, Mat, MatTraitConst, Rect};
use opencv::imgproc;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Side of the square tiles in which strong pixels are counted to find the mouse.
const TILE: usize = 16;
/// A tile with at least this many strong pixels may hold the mouse.
const DENSE_TILE_PX: u32 = 8;
/// Random plane hypotheses tried when fitting the floor.
const RANSAC_ITERATIONS: usize = 128;
/// Background pixels used to fit the floor (a regular subsample when there are more).
const FLOOR_SAMPLES: usize = 20_000;
/// Of those, the ones used to score a hypothesis.
const FLOOR_SCORE_SAMPLES: usize = 2_000;
/// The floor's normal must lie within this angle of the camera's line of sight to it (the
/// camera looks down at the floor; a wall seen at a grazing angle is never taken for it).
const FLOOR_MAX_TILT_DEG: f64 = 60.0;
/// The floor lies at least this far (mm) from the camera.
const MIN_FLOOR_DISTANCE_MM: f64 = 100.0;
/// The floor must hold at least this fraction of the background's readings.
const FLOOR_MIN_INLIERS: f64 = 0.2;
/// The ends of the body along its axis must differ by this much for the longer one to be taken
/// for the tail's side.
const TAIL_SIDE_MM: f64 = 12.0;
/// A reading further than this (mm) from one of its four neighbours' lies on a depth jump,
/// where a time-of-flight camera mixes the two depths ("flying pixels").
const JUMP_MM: u16 = 6;
/// The raw growing height is this many times the floor's noise (about one floor reading in a
/// hundred lies higher).
const GROW_SIGMAS: f32 = 2.33;
/// The ridge height is this many times the floor's noise: the median of five readings varies
/// about half as much as one, and the best of four directions is taken.
const RIDGE_SIGMAS: f32 = 1.6;
/// Half the length (pixels) of the lines along which a ridge is looked for.
const RIDGE_HALF_PX: isize = 2;
/// Grown pixels connected among themselves in smaller groups than this are noise along the
/// body's edge, not a tail.
const MIN_BRANCH_PX: usize = 8;
/// A pixel without a reading joins the mask when at least this many of its neighbours are in
/// it (and more of them than read the floor).
const FILL_MIN_NEIGHBOURS: usize = 4;

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
    #[error("opencv {operation} failed")]
    OpenCv {
        operation: &'static str,
        #[source]
        source: opencv::Error,
    },
    #[error("opencv {operation} wrote its result outside the buffer it was given")]
    OpenCvBuffer { operation: &'static str },
}

fn cv_err(operation: &'static str) -> impl FnOnce(opencv::Error) -> SegmentError {
    move |source| SegmentError::OpenCv { operation, source }
}

/// The segmenter's settings: plain data, read from a config file (missing fields take their
/// defaults), checked and turned into a [`Segmenter`] by [`SegmenterConfig::build`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SegmenterConfig {
    /// A pixel this high above the floor (mm) is the mouse.
    pub min_height_mm: f32,
    /// Nothing higher than this above the floor (mm) is the mouse (a hand, the lid).
    pub max_height_mm: f32,
    /// The mouse is nearer to the camera than the background model by at least this much (mm):
    /// walls and objects fixed in the cage are never foreground.
    pub background_margin_mm: f32,
    /// The mouse's component grows into connected pixels at least this high above the floor
    /// (and nearer than the background by as much, or by `background_margin_mm` if less): the
    /// tail lying on the floor. On a noisy floor the segmenter raises it for the frame.
    pub grow_height_mm: f32,
    /// A mouse smaller than this (mm^2 seen from above) is no mouse.
    pub min_area_mm2: f32,
    /// Along thin parts the mouse also grows into pixels where the median of five readings in
    /// a line is at least this high (mm; more on a noisier floor): the tail's tip.
    pub ridge_height_mm: f32,
    /// Holes inside the mouse up to this size (mm^2) are filled.
    pub max_hole_mm2: f32,
    /// Parts of the mask narrower than twice this (mm), the tail and thin limbs, are left out
    /// of the body's centroid, heading, length and width.
    pub body_core_mm: f32,
    /// Empty frames a background model is made of; the floor plane is fitted again after this
    /// many updates.
    pub background_frames: usize,
    /// How far (mm) one empty frame moves the background's running median at a pixel.
    pub background_step_mm: f32,
    /// Background readings within this distance (mm) of a floor plane hypothesis support it.
    pub floor_tolerance_mm: f32,
}

impl Default for SegmenterConfig {
    fn default() -> Self {
        Self {
            min_height_mm: 5.0,
            max_height_mm: 120.0,
            background_margin_mm: 5.0,
            grow_height_mm: 2.5,
            ridge_height_mm: 1.5,
            min_area_mm2: 400.0,
            max_hole_mm2: 150.0,
            body_core_mm: 4.0,
            background_frames: 30,
            background_step_mm: 0.5,
            floor_tolerance_mm: 4.0,
        }
    }
}

impl SegmenterConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`SegmentError::Config`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), SegmentError> {
        let check = |name: &'static str, value: f32, ok: bool, expected: &'static str| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(SegmentError::Config {
                    name,
                    value: f64::from(value),
                    expected,
                })
            }
        };
        check(
            "min_height_mm",
            self.min_height_mm,
            self.min_height_mm > 0.0,
            "a height above 0 mm",
        )?;
        check(
            "max_height_mm",
            self.max_height_mm,
            self.max_height_mm > self.min_height_mm,
            "more than min_height_mm",
        )?;
        check(
            "background_margin_mm",
            self.background_margin_mm,
            self.background_margin_mm >= 0.0,
            "0 mm or more",
        )?;
        check(
            "grow_height_mm",
            self.grow_height_mm,
            self.grow_height_mm > 0.0 && self.grow_height_mm <= self.min_height_mm,
            "above 0 mm and at most min_height_mm",
        )?;
        check(
            "ridge_height_mm",
            self.ridge_height_mm,
            self.ridge_height_mm > 0.0,
            "above 0 mm",
        )?;
        check(
            "min_area_mm2",
            self.min_area_mm2,
            self.min_area_mm2 >= 0.0,
            "0 mm^2 or more",
        )?;
        check(
            "max_hole_mm2",
            self.max_hole_mm2,
            self.max_hole_mm2 >= 0.0,
            "0 mm^2 or more",
        )?;
        check(
            "body_core_mm",
            self.body_core_mm,
            (0.0..=50.0).contains(&self.body_core_mm),
            "between 0 and 50 mm",
        )?;
        check(
            "background_step_mm",
            self.background_step_mm,
            self.background_step_mm > 0.0,
            "above 0 mm",
        )?;
        check(
            "floor_tolerance_mm",
            self.floor_tolerance_mm,
            self.floor_tolerance_mm > 0.0,
            "above 0 mm",
        )?;
        if self.background_frames == 0 {
            return Err(SegmentError::Config {
                name: "background_frames",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }

    /// Checks the settings and makes a segmenter for `background`. It also tells OpenCV to
    /// run on the calling thread only (a setting of the whole process): a pipeline stage has
    /// one thread and OpenCV's own workers would compete with the other stages.
    ///
    /// # Errors
    /// [`SegmentError::Config`] when a setting is out of range.
    pub fn build(&self, background: Background) -> Result<Segmenter, SegmentError> {
        self.validate()?;
        // The segmenter runs on its pipeline stage's one thread: OpenCV is not to start
        // worker threads of its own (this setting is the process's).
        cv::set_num_threads(1).map_err(cv_err("setNumThreads"))?;
        let n = background.region.len();
        let padded = (background.region.width as usize + 2) * (background.region.height as usize + 2);
        let mut segmenter = Segmenter {
            config: self.clone(),
            background,
            world_from_camera: None,
            lo: vec![0; n],
            hi_strong: vec![0; n],
            scratch: Scratch {
                strong: vec![0; n],
                jump: vec![0; n],
                jump_span: 0..0,
                mask: vec![0; n],
                tiles: Vec::new(),
                column_counts: Vec::new(),
                tile_cluster: Vec::new(),
                labels: vec![0; padded],
                local: vec![0; padded],
                before: vec![0; padded],
                core: vec![0; padded],
                stack: Vec::new(),
                grown: Vec::new(),
                refused: Vec::new(),
                column_first: Vec::new(),
                column_last: Vec::new(),
                branch: Vec::new(),
                stats: Mat::default(),
                centroids: Mat::default(),
                core_kernel: None,
            },
        };
        segmenter.background.refit_every = self.background_frames;
        segmenter.background.step_mm = self.background_step_mm;
        segmenter.background.floor_tolerance_mm = self.floor_tolerance_mm;
        segmenter.update_thresholds();
        Ok(segmenter)
    }
}

/// The floor: `height_mm(p) = normal . p + offset_mm` for a point `p` in the camera frame, with
/// `normal` a unit vector pointing up (towards the camera), so the camera is `offset_mm` above
/// the floor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FloorPlane {
    pub normal: Vector3<f64>,
    pub offset_mm: f64,
}

impl FloorPlane {
    /// The height (mm) of a camera-frame point above the floor.
    pub fn height_mm(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) + self.offset_mm
    }
}

/// The empty cage as the depth camera sees it: a per-pixel median depth over a region of the
/// image (the whole image, or a crop), the rays of its pixels, and the floor plane fitted to it.
#[derive(Clone)]
pub struct Background {
    region: Region,
    intrinsics: Intrinsics,
    /// Median depth (mm), 0 where the empty cage gives no reading.
    depth: Vec<f32>,
    /// Each pixel's ray `(x, y, 1)` in the camera frame.
    rays: Vec<[f32; 2]>,
    floor: FloorPlane,
    updates: usize,
    refit_every: usize,
    step_mm: f32,
    floor_tolerance_mm: f32,
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
    /// A background from the per-pixel median of `frames` (full images from the camera with
    /// `intrinsics`) of the empty cage. A pixel with a reading in fewer than half the frames
    /// has none in the model. A mouse that moves while the frames are taken does not matter; a
    /// still one sits in the model (and its place never counts as foreground).
    ///
    /// # Errors
    /// No frames, a frame of another size than `intrinsics`, bad settings, or no floor plane
    /// in the median (see [`Background::from_depth`]).
    pub fn from_frames(
        frames: &[DepthFrame],
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
    ) -> Result<Self, SegmentError> {
        if frames.is_empty() {
            return Err(SegmentError::NoFrames);
        }
        let region = Region::full(intrinsics);
        for f in frames {
            check_frame(f, region)?;
        }
        let mut values = Vec::with_capacity(frames.len());
        let median: Vec<f32> = (0..region.len())
            .map(|i| {
                values.clear();
                values.extend(frames.iter().filter_map(|f| f.data.get(i).copied().filter(|&v| v > 0)));
                if values.len() * 2 < frames.len() {
                    return 0.0;
                }
                let mid = values.len() / 2;
                values.select_nth_unstable(mid).1.to_owned().into()
            })
            .collect();
        Self::from_depth(&median, region, intrinsics, config)
    }

    /// A background from one depth image of the empty cage over `region` of the camera's image
    /// (mm, 0 = no reading), such as a rendered cage: `Cage::new(&rig.depth).depth(region)`.
    ///
    /// # Errors
    /// A region outside the image, a buffer of the wrong length, bad intrinsics or settings,
    /// or no floor plane: fewer than a fifth of the readings on one plane facing the camera.
    pub fn from_depth(
        depth: &[f32],
        region: Region,
        intrinsics: &Intrinsics,
        config: &SegmenterConfig,
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
        let floor = fit_floor(&depth, &rays, f64::from(config.floor_tolerance_mm))?;
        Ok(Self {
            region,
            intrinsics: *intrinsics,
            depth,
            rays,
            floor,
            updates: 0,
            refit_every: config.background_frames,
            step_mm: config.background_step_mm,
            floor_tolerance_mm: config.floor_tolerance_mm,
        })
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
            self.floor = fit_floor(&self.depth, &self.rays, f64::from(self.floor_tolerance_mm))?;
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

/// The least-squares plane through `points` (`normal . p + offset = 0`, the normal oriented
/// towards the camera), or `None` when they do not span a plane.
fn plane_through(points: &[Vector3<f64>]) -> Option<FloorPlane> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p - mean;
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let k = eig.eigenvalues.imin();
    let normal = eig.eigenvectors.column(k).into_owned();
    oriented(normal, mean)
}

/// The plane with `normal` through `point`, its normal turned towards the camera (the origin);
/// `None` for a degenerate normal or a plane through the camera.
fn oriented(normal: Vector3<f64>, point: Vector3<f64>) -> Option<FloorPlane> {
    let len = normal.norm();
    if !len.is_finite() || len <= 1e-9 {
        return None;
    }
    let mut n = normal / len;
    let mut c = -n.dot(&point);
    if c < 0.0 {
        n = -n;
        c = -c;
    }
    (c > 1e-6).then_some(FloorPlane {
        normal: n,
        offset_mm: c,
    })
}

/// Fits the floor to a background: RANSAC over a subsample of its readings, then least
/// squares over the inliers. Deterministic (a fixed seed).
fn fit_floor(depth: &[f32], rays: &[[f32; 2]], tolerance: f64) -> Result<FloorPlane, SegmentError> {
    let valid = depth.iter().filter(|&&z| z > 0.0).count();
    if valid < 3 {
        return Err(SegmentError::Floor {
            reason: format!("only {valid} pixels have a reading"),
        });
    }
    let stride = valid.div_ceil(FLOOR_SAMPLES).max(1);
    let points: Vec<Vector3<f64>> = depth
        .iter()
        .zip(rays)
        .filter(|(z, _)| **z > 0.0)
        .step_by(stride)
        .map(|(&z, r)| Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0) * f64::from(z))
        .collect();
    let score_stride = points.len().div_ceil(FLOOR_SCORE_SAMPLES).max(1);
    let scoring: Vec<Vector3<f64>> = points.iter().step_by(score_stride).copied().collect();
    let min_facing = FLOOR_MAX_TILT_DEG.to_radians().cos();
    // The camera looks down at the floor: along the mean ray to the readings, the floor's
    // normal (pointing up, towards the camera) is seen nearly head-on, and the floor is not
    // right at the camera.
    let sight = points.iter().map(|p| p.normalize()).sum::<Vector3<f64>>().normalize();
    let faces_camera = |p: &FloorPlane| -p.normal.dot(&sight) >= min_facing && p.offset_mm >= MIN_FLOOR_DISTANCE_MM;
    let inliers = |plane: &FloorPlane, pts: &[Vector3<f64>]| {
        pts.iter()
            .filter(|p| (plane.normal.dot(p) + plane.offset_mm).abs() <= tolerance)
            .count()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0x00F1_0012);
    let mut best: Option<(usize, FloorPlane)> = None;
    for _ in 0..RANSAC_ITERATIONS {
        let [a, b, c] = [0; 3].map(|_| points[rng.gen_range(0..points.len())]);
        let Some(plane) = oriented((b - a).cross(&(c - a)), a) else {
            continue;
        };
        if !faces_camera(&plane) {
            continue;
        }
        let score = inliers(&plane, &scoring);
        if best.is_none_or(|(s, _)| score > s) {
            best = Some((score, plane));
        }
    }
    let Some((_, mut plane)) = best else {
        return Err(SegmentError::Floor {
            reason: "no plane facing the camera".to_owned(),
        });
    };
    let mut support = Vec::with_capacity(points.len());
    for _ in 0..3 {
        support.clear();
        support.extend(
            points
                .iter()
                .filter(|p| (plane.normal.dot(p) + plane.offset_mm).abs() <= tolerance),
        );
        match plane_through(&support) {
            Some(p) if faces_camera(&p) => plane = p,
            _ => break,
        }
    }
    let count = inliers(&plane, &points);
    if (count as f64) < FLOOR_MIN_INLIERS * points.len() as f64 {
        return Err(SegmentError::Floor {
            reason: format!(
                "the best plane holds {count} of {} sampled readings, fewer than a fifth",
                points.len()
            ),
        });
    }
    Ok(plane)
}

/// Which frame the mouse's centroid and heading are given in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseFrame {
    /// The world frame (origin on the glass, z up), when the segmenter knows the camera's pose.
    World,
    /// The depth camera's frame.
    Camera,
}

/// The segmented mouse of one frame.
#[derive(Clone, PartialEq)]
pub struct Mouse {
    /// The mouse's bounding box in the image.
    pub region: Region,
    /// 1 where a pixel shows the mouse, 0 elsewhere, row-major over `region`.
    pub mask: Vec<u8>,
    /// Pixels in the mask.
    pub pixel_count: usize,
    /// The mask's pixels that have a reading, as points in the camera frame (mm), in row-major
    /// order. Filled holes have no reading and no point.
    pub points_mm: Vec<Point3<f32>>,
    /// The frame of `centroid_mm` and `heading_rad`.
    pub frame: PoseFrame,
    /// Mean of the body's 3D surface points (the tail left out), mm.
    pub centroid_mm: Point3<f64>,
    /// Direction of the body's long axis in the floor plane, radians from the frame's x axis
    /// towards its y axis (world: counter-clockwise seen from above). The axis alone has no
    /// front: when one end of the mask reaches clearly further from the centroid than the other
    /// (the tail's side) the heading points to the other end and `heading_resolved` is true;
    /// otherwise it may point backwards (it lies in (-pi/2, pi/2]).
    pub heading_rad: f64,
    pub heading_resolved: bool,
    /// Length and width of the body (the tail left out) along and across its axis: those of
    /// the ellipse with the same second moments (MoSeq's), mm in the floor plane.
    pub length_mm: f64,
    pub width_mm: f64,
    /// Area seen from above: each pixel's footprint at its depth, summed (mm^2).
    pub area_mm2: f64,
    /// Mean height of the mask's readings above the floor (mm).
    pub mean_height_mm: f64,
}

impl fmt::Debug for Mouse {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Mouse")
            .field("region", &self.region)
            .field("pixel_count", &self.pixel_count)
            .field("frame", &self.frame)
            .field("centroid_mm", &self.centroid_mm)
            .field("heading_rad", &self.heading_rad)
            .field("heading_resolved", &self.heading_resolved)
            .field("length_mm", &self.length_mm)
            .field("width_mm", &self.width_mm)
            .field("area_mm2", &self.area_mm2)
            .field("mean_height_mm", &self.mean_height_mm)
            .finish_non_exhaustive()
    }
}

impl Mouse {
    /// Whether the pixel `(x, y)` of the image is in the mask.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        if !self.region.contains(x, y) {
            return false;
        }
        let i = (y - self.region.y0) as usize * self.region.width as usize + (x - self.region.x0) as usize;
        self.mask.get(i).is_some_and(|&m| m != 0)
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
    stats: Mat,
    centroids: Mat,
    /// The body core's structuring element and its radius in pixels.
    core_kernel: Option<(i32, Mat)>,
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
    fn rect(&self) -> Result<Rect, SegmentError> {
        let c = |v: usize| i32::try_from(v).map_err(|_| SegmentError::OpenCvBuffer { operation: "rect" });
        Ok(Rect::new(c(self.x0)?, c(self.y0)?, c(self.width())?, c(self.height())?))
    }
}

fn cv_dim(v: usize) -> Result<i32, SegmentError> {
    i32::try_from(v).map_err(|_| SegmentError::OpenCvBuffer { operation: "mat" })
}

/// A header over `data` as a `rows` x `cols` matrix of one channel.
fn mat_over<T: cv::DataType>(
    data: &[T],
    rows: usize,
    cols: usize,
) -> Result<opencv::boxed_ref::BoxedRef<'_, Mat>, SegmentError> {
    let slice = data
        .get(..rows * cols)
        .ok_or(SegmentError::OpenCvBuffer { operation: "mat" })?;
    Mat::new_rows_cols_with_data(cv_dim(rows)?, cv_dim(cols)?, slice).map_err(cv_err("Mat"))
}

fn mat_over_mut<T: cv::DataType>(
    data: &mut [T],
    rows: usize,
    cols: usize,
) -> Result<opencv::boxed_ref::BoxedRefMut<'_, Mat>, SegmentError> {
    let slice = data
        .get_mut(..rows * cols)
        .ok_or(SegmentError::OpenCvBuffer { operation: "mat" })?;
    Mat::new_rows_cols_with_data_mut(cv_dim(rows)?, cv_dim(cols)?, slice).map_err(cv_err("Mat"))
}

/// Fails when OpenCV put an output somewhere other than the buffer `expected` it was given.
fn same_buffer<T>(mat: &impl MatTraitConst, expected: *const T, operation: &'static str) -> Result<(), SegmentError> {
    if std::ptr::eq(mat.data(), expected.cast::<u8>()) {
        Ok(())
    } else {
        Err(SegmentError::OpenCvBuffer { operation })
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
            .zip(self.lo.iter_mut().zip(self.hi_strong.iter_mut()));
        for ((r, &bg), (lo, hs)) in iter {
            let a = normal.dot(&Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0));
            if !a.is_finite() || a >= -1e-6 {
                // The ray never meets the floor: nothing seen along it is above the floor.
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
    }

    /// Segments a full depth frame.
    ///
    /// # Errors
    /// A frame of another size than the background (which must cover the whole image), or an
    /// OpenCV failure. An empty cage or a mouse smaller than `min_area_mm2` is `Ok(None)`.
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
    /// A region outside the background, a buffer of the wrong length, or an OpenCV failure.
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
        let Some(seed) = self.largest_component(&grid, search)? else {
            return Ok(None);
        };
        let bounds = self.grow(depth, &grid, search, seed, grow_mm, ridge_mm);
        let mouse = self.finish(depth, region, &grid, bounds)?;
        Ok(mouse.filter(|m| f64::from(self.config.min_area_mm2) <= m.area_mm2))
    }

    /// Pass 1: the strong mask over the region, its pixels counted per tile.
    fn classify(&mut self, depth: &[u16], g: &Grid) {
        let tiles_x = g.w.div_ceil(TILE);
        let tiles_y = g.h.div_ceil(TILE);
        let s = &mut self.scratch;
        s.tiles.clear();
        s.tiles.resize(tiles_x * tiles_y, 0);
        s.column_counts.clear();
        s.column_counts.resize(g.w, 0);
        for y in 0..g.h {
            let src = &depth[y * g.w..(y + 1) * g.w];
            let at = (g.oy + y) * g.bg_w + g.ox;
            let lo = &self.lo[at..at + g.w];
            let hs = &self.hi_strong[at..at + g.w];
            let strong = &mut s.strong[y * g.w..(y + 1) * g.w];
            for (((o, &d), &l), &h) in strong.iter_mut().zip(src).zip(lo).zip(hs) {
                *o = u8::from((d >= l) & (d <= h));
            }
            // Column counts over a row of tiles (at most 16 each, so bytes do), summed per
            // tile at its last row.
            for (c, &v) in s.column_counts.iter_mut().zip(strong.iter()) {
                *c += v;
            }
            if y % TILE == TILE - 1 || y + 1 == g.h {
                let row = &mut s.tiles[(y / TILE) * tiles_x..(y / TILE + 1) * tiles_x];
                for (t, chunk) in row.iter_mut().zip(s.column_counts.chunks(TILE)) {
                    *t = chunk.iter().map(|&v| u32::from(v)).sum();
                }
                s.column_counts.fill(0);
            }
        }
    }

    /// The box (region pixels) of the 8-connected cluster of dense tiles holding the most
    /// strong pixels, and that box grown by one tile; `None` when no tile is dense. (Strong
    /// pixels of the mouse outside the first box join it when it grows.)
    fn densest_tiles(&mut self, g: &Grid) -> Option<(Bounds, Bounds)> {
        let tiles_x = g.w.div_ceil(TILE);
        let tiles_y = g.h.div_ceil(TILE);
        let s = &mut self.scratch;
        s.tile_cluster.clear();
        s.tile_cluster.resize(s.tiles.len(), 0);
        let mut best: Option<(u32, Bounds)> = None;
        let mut next = 0;
        for start in 0..s.tiles.len() {
            if s.tiles[start] < DENSE_TILE_PX || s.tile_cluster[start] != 0 {
                continue;
            }
            next += 1;
            s.tile_cluster[start] = next;
            s.stack.clear();
            s.stack.push(start as u32);
            let mut sum = 0;
            let mut b = Bounds::empty();
            while let Some(t) = s.stack.pop() {
                let t = t as usize;
                let (tx, ty) = (t % tiles_x, t / tiles_x);
                sum += s.tiles[t];
                b.add(tx, ty);
                let mut around = [0; 8];
                let count = neighbours8(t, tiles_x, tiles_y, &mut around);
                for &n in &around[..count] {
                    if s.tiles[n] >= DENSE_TILE_PX && s.tile_cluster[n] == 0 {
                        s.tile_cluster[n] = next;
                        s.stack.push(n as u32);
                    }
                }
            }
            if best.is_none_or(|(s, _)| sum > s) {
                best = Some((sum, b));
            }
        }
        let (_, t) = best?;
        let core = Bounds {
            x0: t.x0 * TILE,
            y0: t.y0 * TILE,
            x1: (t.x1 * TILE).min(g.w),
            y1: (t.y1 * TILE).min(g.h),
        };
        let around = Bounds {
            x0: t.x0.saturating_sub(1) * TILE,
            y0: t.y0.saturating_sub(1) * TILE,
            x1: ((t.x1 + 1) * TILE).min(g.w),
            y1: ((t.y1 + 1) * TILE).min(g.h),
        };
        Some((core, around))
    }

    /// Marks (`scratch.jump`) the pixels inside `search` on a depth jump: their reading may
    /// mix the two sides, so their neighbours off the jump decide them later.
    fn mark_jumps(&mut self, depth: &[u16], g: &Grid, search: Bounds) {
        let s = &mut self.scratch;
        if let Some(old) = s.jump.get_mut(s.jump_span.clone()) {
            old.fill(0);
        }
        s.jump_span = search.y0 * g.w..search.y1 * g.w;
        let (x0, x1) = (search.x0.max(1), search.x1.min(g.w.saturating_sub(1)));
        if x0 >= x1 {
            return;
        }
        for y in search.y0.max(1)..search.y1.min(g.h.saturating_sub(1)) {
            let row = y * g.w;
            let up = &depth[row - g.w + x0..row - g.w + x1];
            let down = &depth[row + g.w + x0..row + g.w + x1];
            let left = &depth[row + x0 - 1..row + x1 - 1];
            let right = &depth[row + x0 + 1..row + x1 + 1];
            let centre = &depth[row + x0..row + x1];
            let out = &mut s.jump[row + x0..row + x1];
            let cells = out.iter_mut().zip(centre).zip(left).zip(right).zip(up).zip(down);
            for (((((o, &d), &l), &r), &u), &w) in cells {
                let far = |v: u16| (v != 0) & (v.abs_diff(d) > JUMP_MM);
                *o = u8::from((d != 0) & (far(l) | far(r) | far(u) | far(w)));
            }
        }
    }

    /// The standard deviation (mm) of the floor's readings around the mouse.
    fn floor_noise(&self, depth: &[u16], g: &Grid, search: Bounds) -> f32 {
        let FloorPlane { normal, offset_mm } = self.background.floor;
        let (nx, ny, nz, c) = (normal.x as f32, normal.y as f32, normal.z as f32, offset_mm as f32);
        let top = self.config.min_height_mm;
        // Readings below the floor are floor and noise, never the mouse: with the noise
        // symmetric, `sigma^2 = 2 * sum(h^2, h < 0) / floor readings`. (Depths come in whole
        // millimetres, so this, not a median, is what measures a noise of a millimetre or two.)
        // Every other row is enough.
        let (mut sum, mut below, mut level) = (0f64, 0usize, 0usize);
        for y in (search.y0..search.y1).step_by(2) {
            let at = (g.oy + y) * g.bg_w + g.ox;
            let rays = &self.background.rays[at + search.x0..at + search.x1];
            let row = &depth[y * g.w + search.x0..y * g.w + search.x1];
            let (mut row_sum, mut row_below, mut row_level) = (0f32, 0u32, 0u32);
            for (&d, r) in row.iter().zip(rays) {
                let h = (nx * r[0] + ny * r[1] + nz) * f32::from(d) + c;
                let read = d != 0;
                let under = read & (h < -0.5) & (h > -top);
                row_sum += if under { h * h } else { 0.0 };
                row_below += u32::from(under);
                row_level += u32::from(read & (h.abs() <= 0.5));
            }
            sum += f64::from(row_sum);
            below += row_below as usize;
            level += row_level as usize;
        }
        let floor = 2 * below + level;
        if floor < 100 {
            return 0.0;
        }
        (2.0 * sum / floor as f64).sqrt() as f32
    }

    /// The largest 8-connected component of strong pixels inside `search` (OpenCV): its label
    /// in `scratch.labels` (laid out over `search`), or `None` when there is none.
    fn largest_component(&mut self, g: &Grid, search: Bounds) -> Result<Option<i32>, SegmentError> {
        let s = &mut self.scratch;
        let full = mat_over(&s.strong, g.h, g.w)?;
        let roi = Mat::roi(&full, search.rect()?).map_err(cv_err("Mat::roi"))?;
        let labels_ptr = s.labels.as_ptr();
        let mut labels = mat_over_mut(&mut s.labels, search.height(), search.width())?;
        let count =
            imgproc::connected_components_with_stats(&roi, &mut labels, &mut s.stats, &mut s.centroids, 8, cv::CV_32S)
                .map_err(cv_err("connectedComponentsWithStats"))?;
        same_buffer(&labels, labels_ptr, "connectedComponentsWithStats")?;
        drop(labels);
        let mut best = None;
        let mut best_area = 0;
        for label in 1..count {
            let area = *s
                .stats
                .at_2d::<i32>(label, imgproc::CC_STAT_AREA)
                .map_err(cv_err("Mat::at_2d"))?;
            if area > best_area {
                best_area = area;
                best = Some(label);
            }
        }
        Ok(best)
    }

    /// Puts the seed component into the mask and grows it into connected pixels at least
    /// `grow_mm` above the floor, or on a ridge at least `ridge_mm` high, then drops small
    /// groups of grown pixels. Returns the mask's box; the mask is left in `scratch.mask`.
    fn grow(&mut self, depth: &[u16], g: &Grid, search: Bounds, seed: i32, grow_mm: f32, ridge_mm: f32) -> Bounds {
        let FloorPlane { normal, offset_mm } = self.background.floor;
        let (nx, ny, nz, c) = (normal.x as f32, normal.y as f32, normal.z as f32, offset_mm as f32);
        let margin = grow_mm.min(self.config.background_margin_mm);
        let bg = &self.background;
        let height = |i: usize, d: f32| -> f32 {
            let at = (g.oy + i / g.w) * g.bg_w + g.ox + i % g.w;
            bg.rays
                .get(at)
                .map_or(f32::NEG_INFINITY, |r| (nx * r[0] + ny * r[1] + nz) * d + c)
        };
        // Height above the floor, or above the background where that is nearer (a wall).
        let above = |i: usize, d: f32| -> f32 {
            let at = (g.oy + i / g.w) * g.bg_w + g.ox + i % g.w;
            let (Some(r), Some(&b)) = (bg.rays.get(at), bg.depth.get(at)) else {
                return f32::NEG_INFINITY;
            };
            let a = nx * r[0] + ny * r[1] + nz;
            let h = a * d + c;
            if b > 0.0 { h.min(a * (d - b)) } else { h }
        };
        let bg_at = |i: usize| {
            bg.depth
                .get((g.oy + i / g.w) * g.bg_w + g.ox + i % g.w)
                .copied()
                .unwrap_or(0.0)
        };
        let accept = |i: usize, strong: &[u8], jump: &[u8]| -> bool {
            let d = depth[i];
            if d == 0 {
                return false;
            }
            let d = f32::from(d);
            let h = height(i, d);
            let b = bg_at(i);
            if h >= grow_mm && (b <= 0.0 || d <= b - margin) {
                return true;
            }
            if !ridge_mm.is_finite() || above(i, d) < 0.0 {
                return false;
            }
            // A ridge: along some direction, the median height of the five pixels centred
            // here (without the body's strong pixels) is high enough.
            let (x, y) = ((i % g.w) as isize, (i / g.w) as isize);
            let mut best = f32::NEG_INFINITY;
            for (dx, dy) in [(1isize, 0isize), (0, 1), (1, 1), (1, -1)] {
                let mut v = [0f32; 11];
                let mut n = 0;
                for k in -RIDGE_HALF_PX..=RIDGE_HALF_PX {
                    let (px, py) = (x + k * dx, y + k * dy);
                    if px < 0 || py < 0 || px >= g.w as isize || py >= g.h as isize {
                        continue;
                    }
                    let j = py as usize * g.w + px as usize;
                    if depth[j] == 0 || strong[j] != 0 || jump[j] != 0 {
                        continue;
                    }
                    v[n] = above(j, f32::from(depth[j]));
                    n += 1;
                }
                if n as isize > RIDGE_HALF_PX {
                    let vs = &mut v[..n];
                    vs.sort_by(f32::total_cmp);
                    best = best.max(vs[n / 2]);
                }
            }
            best >= ridge_mm
        };
        let s = &mut self.scratch;
        let sw = search.width();
        let mut b = Bounds::empty();
        s.stack.clear();
        for y in search.y0..search.y1 {
            let labels = &s.labels[(y - search.y0) * sw..(y - search.y0 + 1) * sw];
            for (x, &l) in (search.x0..search.x1).zip(labels) {
                if l == seed {
                    let i = y * g.w + x;
                    s.mask[i] = 1;
                    s.stack.push(i as u32);
                    b.add(x, y);
                }
            }
        }
        // Mask values while growing: 1 seed, 2 grown, 4 tried and refused.
        s.grown.clear();
        s.refused.clear();
        while let Some(i) = s.stack.pop() {
            let mut around = [0; 8];
            let count = neighbours8(i as usize, g.w, g.h, &mut around);
            for &n in &around[..count] {
                if s.mask[n] != 0 {
                    continue;
                }
                if accept(n, &s.strong, &s.jump) {
                    s.mask[n] = 2;
                    s.stack.push(n as u32);
                    s.grown.push(n as u32);
                } else {
                    s.mask[n] = 4;
                    s.refused.push(n as u32);
                }
            }
        }
        for &i in &s.refused {
            s.mask[i as usize] = 0;
        }
        // Grown pixels form branches (8-connected among themselves); the small ones are noise
        // along the body's edge, the long ones the tail.
        for k in 0..s.grown.len() {
            let start = s.grown[k] as usize;
            if s.mask[start] != 2 {
                continue;
            }
            s.mask[start] = 3;
            s.branch.clear();
            s.branch.push(start as u32);
            let mut next = 0;
            while let Some(&i) = s.branch.get(next) {
                next += 1;
                let mut around = [0; 8];
                let count = neighbours8(i as usize, g.w, g.h, &mut around);
                for &n in &around[..count] {
                    if s.mask[n] == 2 {
                        s.mask[n] = 3;
                        s.branch.push(n as u32);
                    }
                }
            }
            let keep = s.branch.len() >= MIN_BRANCH_PX;
            for &i in &s.branch {
                let i = i as usize;
                s.mask[i] = u8::from(keep);
                if keep {
                    b.add(i % g.w, i / g.w);
                }
            }
        }
        b
    }

    /// Closing, hole filling and the scalars, inside the mask's box; clears `scratch.mask`.
    fn finish(&mut self, depth: &[u16], region: Region, g: &Grid, b: Bounds) -> Result<Option<Mouse>, SegmentError> {
        // The mask's box with a border of one empty pixel, as a local image.
        let (bw, bh) = (b.width(), b.height());
        let (lw, lh) = (bw + 2, bh + 2);
        let s = &mut self.scratch;
        s.local[..lw * lh].fill(0);
        for y in b.y0..b.y1 {
            let src = &mut s.mask[y * g.w + b.x0..y * g.w + b.x1];
            let l = (y - b.y0 + 1) * lw + 1;
            s.local[l..l + bw].copy_from_slice(src);
            src.fill(0);
        }
        // Pixel (lx, ly) of the local image is pixel (x0 + lx, y0 + ly) of the region, where
        // x0 = b.x0 - 1 may be -1: the border may lie outside the region but stays empty.
        let to_region = |lx: usize, ly: usize| -> Option<usize> {
            let x = (b.x0 + lx).checked_sub(1)?;
            let y = (b.y0 + ly).checked_sub(1)?;
            (x < g.w && y < g.h).then_some(y * g.w + x)
        };
        // An inner pixel of the local image (not its border) is always in the region.
        let inner = |lx: usize, ly: usize| (b.y0 + ly - 1) * g.w + b.x0 + lx - 1;
        let fx = self.background.intrinsics.fx;
        let fy = self.background.intrinsics.fy;
        // The mouse's typical depth sets the size of a pixel.
        let mut sum_z = 0.0;
        let mut n_z = 0usize;
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                if s.local[ly * lw + lx] != 0
                    && let i = inner(lx, ly)
                    && depth[i] > 0
                {
                    sum_z += f64::from(depth[i]);
                    n_z += 1;
                }
            }
        }
        if n_z == 0 {
            return Ok(None);
        }
        let mean_z = sum_z / n_z as f64;
        let pixel_mm2 = (mean_z / fx) * (mean_z / fy);

        // Pixels on a depth jump go with the majority of their neighbours off jumps (mouse or
        // floor reading); pixels without a reading join the mask when most of their
        // neighbours are in it: dropouts along the mouse's edge. Only ever one pixel deep, so
        // nothing thin is cut.
        s.before[..lw * lh].copy_from_slice(&s.local[..lw * lh]);
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let l = ly * lw + lx;
                let i = inner(lx, ly);
                let on_jump = s.jump[i] != 0;
                if !on_jump && (s.before[l] != 0 || depth[i] != 0) {
                    continue;
                }
                let (mut mouse, mut floor) = (0usize, 0usize);
                for (nx, ny) in [
                    (lx - 1, ly - 1),
                    (lx, ly - 1),
                    (lx + 1, ly - 1),
                    (lx - 1, ly),
                    (lx + 1, ly),
                    (lx - 1, ly + 1),
                    (lx, ly + 1),
                    (lx + 1, ly + 1),
                ] {
                    let Some(j) = to_region(nx, ny) else {
                        continue;
                    };
                    if s.jump[j] != 0 {
                        continue;
                    }
                    if s.before[ny * lw + nx] != 0 {
                        mouse += 1;
                    } else if depth[j] != 0 {
                        floor += 1;
                    }
                }
                if on_jump {
                    if mouse != floor {
                        s.local[l] = u8::from(mouse > floor);
                    }
                } else if mouse >= FILL_MIN_NEIGHBOURS && mouse > floor {
                    s.local[l] = 1;
                }
            }
        }

        // Holes: background (4-connected) that the border of the local image does not reach.
        // Background with mask on both sides along its row and along its column may be in a
        // hole; anything else sees the border along a row or a column. A group of such
        // candidates is a hole when none of it touches other background. `before` marks: 0
        // background, 1 mask, 2 a candidate, 3 a candidate already looked at.
        let max_hole = (f64::from(self.config.max_hole_mm2) / pixel_mm2).floor() as usize;
        if max_hole > 0 {
            s.before[..lw * lh].fill(0);
            for ly in 1..lh - 1 {
                let row = &s.local[ly * lw..(ly + 1) * lw];
                if let (Some(first), Some(last)) = (row.iter().position(|&v| v != 0), row.iter().rposition(|&v| v != 0))
                {
                    for (b, &m) in s.before[ly * lw + first..=ly * lw + last]
                        .iter_mut()
                        .zip(&row[first..=last])
                    {
                        *b = if m != 0 { 1 } else { 2 };
                    }
                }
            }
            // Column limits, one row at a time: the first and last mask row of each column.
            s.column_first.clear();
            s.column_first.resize(lw, usize::MAX);
            s.column_last.clear();
            s.column_last.resize(lw, 0);
            for ly in 1..lh - 1 {
                for (lx, &m) in s.local[ly * lw..(ly + 1) * lw].iter().enumerate() {
                    if m != 0 {
                        s.column_first[lx] = s.column_first[lx].min(ly);
                        s.column_last[lx] = ly;
                    }
                }
            }
            for ly in 1..lh - 1 {
                for lx in 1..lw - 1 {
                    let b = &mut s.before[ly * lw + lx];
                    if *b == 2 && !(s.column_first[lx] < ly && ly < s.column_last[lx]) {
                        *b = 0;
                    }
                }
            }
            for start in 0..lw * lh {
                if s.before[start] != 2 {
                    continue;
                }
                s.before[start] = 3;
                s.stack.clear();
                s.stack.push(start as u32);
                s.branch.clear();
                let mut closed = true;
                while let Some(l) = s.stack.pop() {
                    let l = l as usize;
                    s.branch.push(l as u32);
                    // Candidates never lie on the local image's border.
                    for n in [l - 1, l + 1, l - lw, l + lw] {
                        match s.before[n] {
                            0 => closed = false,
                            2 => {
                                s.before[n] = 3;
                                s.stack.push(n as u32);
                            }
                            _ => {}
                        }
                    }
                }
                if closed && s.branch.len() <= max_hole {
                    for &l in &s.branch {
                        s.local[l as usize] = 1;
                    }
                }
            }
        }

        // The body core: the mask opened by a square (separable, so fast), for the body's
        // figures only.
        let radius = (f64::from(self.config.body_core_mm) * fx / mean_z).round() as i32;
        let mut core_empty = true;
        if radius > 0 {
            if s.core_kernel.as_ref().is_none_or(|(r, _)| *r != radius) {
                let k = imgproc::get_structuring_element(
                    imgproc::MORPH_RECT,
                    cv::Size::new(2 * radius + 1, 2 * radius + 1),
                    cv::Point::new(-1, -1),
                )
                .map_err(cv_err("getStructuringElement"))?;
                s.core_kernel = Some((radius, k));
            }
            if let Some((_, kernel)) = &s.core_kernel {
                let src = mat_over(&s.local, lh, lw)?;
                let dst_ptr = s.core.as_ptr();
                let mut dst = mat_over_mut(&mut s.core, lh, lw)?;
                morphology(&src, &mut dst, imgproc::MORPH_OPEN, kernel)?;
                same_buffer(&dst, dst_ptr, "morphologyEx")?;
                drop(dst);
                drop(src);
                core_empty = s.core[..lw * lh].iter().all(|&v| v == 0);
            }
        }
        if core_empty {
            s.core[..lw * lh].copy_from_slice(&s.local[..lw * lh]);
        }

        // Figures from the 3D points.
        let floor = self.background.floor;
        let rays = &self.background.rays;
        let ray_at = |i: usize| {
            let (x, y) = (i % g.w, i / g.w);
            rays.get((g.oy + y) * g.bg_w + g.ox + x).copied().unwrap_or([0.0, 0.0])
        };
        let mut mask = Vec::with_capacity(bw * bh);
        let mut points = Vec::with_capacity(bw * bh);
        let mut pixel_count = 0usize;
        let mut missing = 0usize;
        let mut area = 0.0;
        let mut height_sum = 0.0;
        let mut core_sum = Vector3::zeros();
        let mut core_points = 0usize;
        // Body core coordinates in the floor plane: u, v orthonormal, across the normal.
        let n = floor.normal;
        let u = {
            let x = Vector3::x() - n * n.x;
            if x.norm() > 1e-6 {
                x.normalize()
            } else {
                (Vector3::y() - n * n.y).normalize()
            }
        };
        let v = n.cross(&u);
        let mut m1 = Vector2::zeros();
        let mut m2 = Matrix2::zeros();
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let l = ly * lw + lx;
                let inside = s.local[l] != 0;
                mask.push(u8::from(inside));
                if !inside {
                    continue;
                }
                pixel_count += 1;
                let i = inner(lx, ly);
                let z = depth[i];
                if z == 0 {
                    missing += 1;
                    continue;
                }
                let z = f64::from(z);
                let r = ray_at(i);
                let p = Vector3::new(f64::from(r[0]) * z, f64::from(r[1]) * z, z);
                points.push(Point3::new(p.x as f32, p.y as f32, p.z as f32));
                area += (z / fx) * (z / fy);
                height_sum += n.dot(&p) + floor.offset_mm;
                if s.core[l] != 0 {
                    core_sum += p;
                    core_points += 1;
                    let q = Vector2::new(u.dot(&p), v.dot(&p));
                    m1 += q;
                    m2 += q * q.transpose();
                }
            }
        }
        if points.is_empty() || core_points == 0 {
            return Ok(None);
        }
        area += missing as f64 * pixel_mm2;
        let k = core_points as f64;
        let centroid = core_sum / k;
        let mean = m1 / k;
        let cov = m2 / k - mean * mean.transpose();
        let eig = SymmetricEigen::new(cov);
        let (major, minor) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
            (0, 1)
        } else {
            (1, 0)
        };
        let length = 4.0 * eig.eigenvalues[major].max(0.0).sqrt();
        let width = 4.0 * eig.eigenvalues[minor].max(0.0).sqrt();
        let e = eig.eigenvectors.column(major);
        let mut axis = u * e[0] + v * e[1];
        // The tail's end reaches further from the centroid than the snout.
        let (mut ahead, mut behind) = (0.0f64, 0.0f64);
        for p in &points {
            let t = axis.dot(&(p.coords.cast::<f64>() - centroid));
            ahead = ahead.max(t);
            behind = behind.max(-t);
        }
        let heading_resolved = (ahead - behind).abs() > TAIL_SIDE_MM;
        if heading_resolved && ahead > behind {
            axis = -axis;
        }
        let (frame, centroid_out, axis_out) = match &self.world_from_camera {
            Some(iso) => (PoseFrame::World, iso * Point3::from(centroid), iso * axis),
            None => (PoseFrame::Camera, Point3::from(centroid), axis),
        };
        let mut heading = axis_out.y.atan2(axis_out.x);
        if !heading_resolved {
            // Only the axis is known: give it in (-pi/2, pi/2].
            if heading > std::f64::consts::FRAC_PI_2 {
                heading -= std::f64::consts::PI;
            } else if heading <= -std::f64::consts::FRAC_PI_2 {
                heading += std::f64::consts::PI;
            }
        }
        let n_points = points.len() as f64;
        Ok(Some(Mouse {
            region: Region {
                x0: region.x0 + b.x0 as u32,
                y0: region.y0 + b.y0 as u32,
                width: bw as u32,
                height: bh as u32,
            },
            mask,
            pixel_count,
            points_mm: points,
            frame,
            centroid_mm: centroid_out,
            heading_rad: heading,
            heading_resolved,
            length_mm: length,
            width_mm: width,
            area_mm2: area,
            mean_height_mm: height_sum / n_points,
        }))
    }
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

fn morphology(
    src: &impl cv::ToInputArray,
    dst: &mut impl cv::ToOutputArray,
    op: i32,
    kernel: &Mat,
) -> Result<(), SegmentError> {
    let border = imgproc::morphology_default_border_value().map_err(cv_err("morphologyDefaultBorderValue"))?;
    imgproc::morphology_ex(
        src,
        dst,
        op,
        kernel,
        cv::Point::new(-1, -1),
        1,
        cv::BORDER_CONSTANT,
        border,
    )
    .map_err(cv_err("morphologyEx"))
}

/// The indices of the neighbours of cell `i` of a row-major `w` x `h` grid: fills `out` and
/// returns how many there are (8 inside, fewer along the edges).
#[inline]
fn neighbours8(i: usize, w: usize, h: usize, out: &mut [usize; 8]) -> usize {
    let (x, y) = (i % w, i / w);
    if x > 0 && y > 0 && x + 1 < w && y + 1 < h {
        *out = [i - w - 1, i - w, i - w + 1, i - 1, i + 1, i + w - 1, i + w, i + w + 1];
        return 8;
    }
    let mut n = 0;
    for (dx, dy) in [
        (-1isize, -1isize),
        (0, -1),
        (1, -1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (0, 1),
        (1, 1),
    ] {
        if let (Some(nx), Some(ny)) = (x.checked_add_signed(dx), y.checked_add_signed(dy))
            && nx < w
            && ny < h
        {
            out[n] = ny * w + nx;
            n += 1;
        }
    }
    n
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
