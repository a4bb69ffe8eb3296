//! The body stage: the body forest on the segmented mouse, joints 1-12 in the world frame, and
//! the evidence of which end is the head (the forest's votes, the learnt body shape judged
//! without the tail, and a visible tail found as one).

use super::{Found, Posed, Segmented};
use crate::core::frame::FramePair;
use crate::core::geometry::Camera;
use crate::core::pose::{JointEstimate, JointSource, Pose};
use crate::core::skeleton::Joint;
use crate::runtime::pipeline::{Map, StageError};
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crate::vision::body_shape::{ShapeModel, aligned};
use crate::vision::forest::depth::{BODY_JOINTS, DepthImage};
use crate::vision::forest::infer::{BodyEstimator, JointGuess, Oriented, Pixel, sample_pixels};
use crate::vision::orientation::{self, BodyJoints, Headings, TrackerConfig};
use crate::vision::tail::{Tail, TailSearch, find_tail_in, mm_per_px, thin_pieces_at};
use nalgebra::{Point2, Point3, Vector2, Vector3};

/// Pixels of the mouse run through the forest per frame in the pipeline, at most. Fewer than
/// the evaluation's vote budget (1,200, `VOTE_BUDGET` of the training module): on a 10 s synthetic session the
/// mean error goes from 2.81 mm to 2.92 mm while the stage runs about 4 times faster, which
/// is what lets replay reach hundreds of pairs per second on two cores.
pub const PIPELINE_VOTE_BUDGET: usize = 200;

/// A visible tail's log-odds for the head at the body's other end, when the tail is at least
/// [`FULL_TAIL_MM`] long (a shorter one counts in proportion). More than the votes and the
/// body's shape together can say against it: a long thin piece leaving one end of the body is
/// what a tail is, while the votes and the shape were learnt on rendered mice.
pub const TAIL_LOG_ODDS: f64 = 16.0;
/// See [`TAIL_LOG_ODDS`] (mm).
pub const FULL_TAIL_MM: f64 = 40.0;

/// Runs a [`BodyEstimator`] on each segmented mouse.
#[derive(Debug, Clone)]
pub struct BodyStage {
    estimator: BodyEstimator,
    orientation: Option<ShapeModel>,
    camera: Camera,
    budget: usize,
    pixels: Vec<Pixel>,
    mask: Vec<bool>,
    /// The region's pixels left out of the body: a tail found as one, and the thin pieces
    /// joined to the mouse at a wall or the arena's rim (clutter, `vision::segment::walls`).
    left_out: Vec<bool>,
    /// The region's pixels near a wall ([`crate::vision::segment::Mouse::wall`]).
    wall: Vec<bool>,
    crop: Vec<u16>,
    points: Vec<Point3<f64>>,
}

impl BodyStage {
    /// A stage for the depth camera `camera` (its intrinsics and pose in the world), running
    /// at most `budget` mouse pixels per frame through the forest, with the body-shape model
    /// `orientation` when there is one.
    pub fn new(estimator: BodyEstimator, orientation: Option<ShapeModel>, camera: Camera, budget: usize) -> Self {
        Self {
            estimator,
            orientation,
            camera,
            budget: budget.max(1),
            pixels: Vec::new(),
            mask: Vec::new(),
            left_out: Vec::new(),
            wall: Vec::new(),
            crop: Vec::new(),
            points: Vec::new(),
        }
    }

    /// Puts every mouse pixel of `image` that reads and is not left out (its tail, clutter at a
    /// wall) into `self.points`, in the world frame.
    fn body_points(&mut self, image: &DepthImage) {
        let r = image.region;
        let (intrinsics, world) = (&self.camera.intrinsics, &self.camera.world_from_camera);
        let left_out = &self.left_out;
        self.points.clear();
        self.points.extend(
            image
                .on_mouse()
                .filter(|(k, _)| !left_out.get(*k).copied().unwrap_or(false))
                .map(|(k, d)| {
                    let pixel = Point2::new(
                        f64::from(r.x0) + (k % r.width as usize) as f64,
                        f64::from(r.y0) + (k / r.width as usize) as f64,
                    );
                    world * intrinsics.unproject(&pixel, f64::from(d))
                }),
        );
    }

    /// The body-shape model's log-odds that the head lies toward `axis` (world x, y), from
    /// the body's points (`self.points`, see [`Self::body_points`]); 0 without a model or
    /// features.
    fn shape(&self, axis: &Vector2<f64>) -> f64 {
        let Some(model) = &self.orientation else {
            return 0.0;
        };
        // The model's axis and the forest's may differ a little: its evidence counts as much
        // as they agree.
        aligned(&self.points).map_or(0.0, |a| model.log_odds(&a.features) * a.axis.dot(axis))
    }

    /// Looks for a visible tail on the mouse of `image`, marks its pixels in `self.left_out`
    /// with the thin pieces joined to the mouse where it lies near a wall (`wall`, over the
    /// region), and returns the tail with the millimetres a pixel spans at the mouse.
    fn find_tail(&mut self, image: &DepthImage, wall: &[u8]) -> Option<(Tail, f64)> {
        self.left_out.clear();
        self.left_out.resize(image.depth.len(), false);
        let found = find_tail_in(image, self.camera.intrinsics.fx);
        for &k in found.iter().flat_map(|(tail, _)| &tail.pixels) {
            self.left_out[k] = true;
        }
        if wall.len() == self.mask.len() && wall.iter().any(|&w| w != 0) {
            if let Some(scale) = mm_per_px(image, self.camera.intrinsics.fx) {
                self.wall.clear();
                self.wall.extend(wall.iter().map(|&w| w != 0));
                let r = image.region;
                let search = TailSearch::at_scale(scale);
                for k in thin_pieces_at(&self.mask, &self.wall, r.width as usize, r.height as usize, &search) {
                    self.left_out[k] = true;
                }
            }
        }
        found
    }

    /// A visible tail's log-odds that the head lies toward `+axis` of `headings` (see
    /// [`Headings::tail`]): where the tail leaves the body, against the body's centre.
    fn tail_evidence(&self, image: &DepthImage, tail: &Tail, mm_per_px: f64, headings: &Headings) -> f64 {
        let r = image.region;
        let (bx, by) = (tail.base.0.round() as usize, tail.base.1.round() as usize);
        // The base's depth: the nearest of the tail's pixels to it that reads.
        let Some(depth) = tail
            .pixels
            .iter()
            .filter_map(|&k| image.mouse_depth(k).map(|d| (k, d)))
            .min_by_key(|(k, _)| {
                let (x, y) = (k % r.width as usize, k / r.width as usize);
                x.abs_diff(bx).pow(2) + y.abs_diff(by).pow(2)
            })
            .map(|(_, d)| f64::from(d))
        else {
            return 0.0;
        };
        let pixel = Point2::new(f64::from(r.x0) + tail.base.0, f64::from(r.y0) + tail.base.1);
        let base = self.camera.world_from_camera * self.camera.intrinsics.unproject(&pixel, depth);
        let side = (Vector2::new(base.x, base.y) - headings.centre.coords).dot(&headings.axis);
        if side.abs() < 1e-6 {
            return 0.0;
        }
        let strength = TAIL_LOG_ODDS * (tail.length_px * mm_per_px / FULL_TAIL_MM).min(1.0);
        -side.signum() * strength
    }

    /// The world-frame joints and evidence of a frame's [`Oriented`] estimate.
    fn headings(&self, oriented: &Oriented) -> Headings {
        let to_world = |guesses: &[Option<JointGuess>; BODY_JOINTS]| -> BodyJoints {
            guesses.map(|guess| {
                guess.map_or_else(JointEstimate::default, |g| JointEstimate {
                    position_mm: self.camera.world_from_camera * Point3::from(g.position_mm.cast::<f64>()),
                    score: f64::from(g.score),
                    source: JointSource::Depth,
                })
            })
        };
        let axis = self.camera.world_from_camera.rotation * oriented.axis.cast::<f64>();
        let centre = self.camera.world_from_camera * Point3::from(oriented.centre.cast::<f64>());
        Headings {
            axis: Vector2::new(axis.x, axis.y)
                .try_normalize(1e-9)
                .unwrap_or_else(Vector2::x),
            centre: Point2::new(centre.x, centre.y),
            votes: f64::from(oriented.votes),
            shape: 0.0,
            tail: 0.0,
            tail_at_wall: false,
            joints: oriented.ahead.each_ref().map(to_world),
            forest_heading: orientation::heading(&to_world(&oriented.raw)),
            body: Vec::new(),
        }
    }
}

impl BodyStage {
    /// The pose of one mouse `found` in `pair` (`background`: whether there is a model of the
    /// empty cage yet).
    fn pose(&mut self, pair: &FramePair, found: Found, background: bool) -> PoseRecord {
        let Found { mouse, identity } = found;
        let mut record = PoseRecord {
            depth: pair.depth.stamp,
            color: pair.color.as_ref().map(|c| c.stamp),
            skew_ns: pair.skew_ns,
            status: if background {
                PoseStatus::NoMouse
            } else {
                PoseStatus::NoBackground
            },
            pose: Pose::default(),
            paws: Vec::new(),
            headings: None,
            orientation: None,
            raw_body: None,
            velocities: None,
            identity,
        };
        if let Some(mouse) = mouse {
            let r = mouse.region;
            self.crop.clear();
            self.mask.clear();
            let width = pair.depth.width as usize;
            for y in r.y0..r.y0 + r.height {
                let row = y as usize * width + r.x0 as usize;
                self.crop
                    .extend_from_slice(pair.depth.data.get(row..row + r.width as usize).unwrap_or_default());
            }
            self.mask.extend(mouse.mask.iter().map(|&m| m != 0));
            if self.crop.len() == self.mask.len() {
                let image = DepthImage::from_mask(r, &self.crop, &self.mask);
                let tail = self.find_tail(&image, &mouse.wall);
                sample_pixels(&image, self.budget, &mut self.pixels);
                let up = (self.camera.world_from_camera.rotation.inverse() * Vector3::z()).cast::<f32>();
                let oriented = self.estimator.estimate_oriented(
                    &image,
                    &self.pixels,
                    &self.camera.intrinsics,
                    &up,
                    &self.left_out,
                );
                let mut headings = self.headings(&oriented);
                self.body_points(&image);
                headings.shape = self.shape(&headings.axis);
                // The points go with the frame; the next frame's start at their size.
                let next = Vec::with_capacity(self.points.len());
                headings.body = std::mem::replace(&mut self.points, next);
                if let Some((tail, mm_per_px)) = &tail {
                    headings.tail = self.tail_evidence(&image, tail, *mm_per_px, &headings);
                    headings.tail_at_wall = tail.pixels.iter().any(|&k| mouse.wall.get(k).is_some_and(|&w| w != 0));
                }
                let alone = TrackerConfig::default().frame_evidence(&headings) < 0.0;
                for (joint, estimate) in Joint::MAIN_BODY.iter().zip(headings.joints[usize::from(alone)]) {
                    *record.pose.joint_mut(*joint) = estimate;
                }
                record.headings = Some(Box::new(headings));
                record.status = PoseStatus::Ok;
            }
        }
        record
    }
}

impl Map for BodyStage {
    type In = Segmented;
    type Out = Posed;
    const NAME: &'static str = "body";

    fn process(&mut self, input: Segmented) -> Result<Posed, StageError> {
        let Segmented { pair, mice, background } = input;
        let records: Vec<PoseRecord> = mice
            .into_iter()
            .map(|found| self.pose(&pair, found, background))
            .collect();
        let mut records = records.into_iter();
        let nobody = Found {
            mouse: None,
            identity: None,
        };
        let record = match records.next() {
            Some(record) => record,
            None => self.pose(&pair, nobody, background),
        };
        let others = records.collect();
        Ok(Posed { pair, record, others })
    }
}
