//! Training and evaluating the depth forests on synthesis-engine datasets: the body forest
//! (joints 1-12, regression) and the part forest (six labels, classification).
//!
//! Both start from the same training pixels: each image's mouse pixels (as the segmenter finds
//! them), a random subset per image, with the image itself kept for the depth features.

pub mod orientation;
pub mod paws_data;
pub mod paws_eval;
pub mod paws_net;
pub mod paws_real;

use crate::core::geometry::Rig;
use crate::core::image::Region;
use crate::core::rng::item_rng;
use crate::core::skeleton::{BACKGROUND_LABEL, Joint, PART_COUNT, Part, SKELETON_VERSION};
use crate::synth::dataset::{Dataset, DatasetError, Sample};
use crate::synth::render::Cage;
use crate::vision::forest::classify::{ClassObjective, argmax};
use crate::vision::forest::depth::{BODY_JOINTS, DepthImage, DepthSpace, JointObjective, JointTargets, PixelSet};
use crate::vision::forest::discriminative::{DiscriminativeParams, PassStats, refine_tree, subset};
use crate::vision::forest::infer::{BodyEstimator, Pixel, TAIL_TIP, sample_pixels};
use crate::vision::forest::model::{DataProvenance, Model, ModelInfo, ModelKind};
use crate::vision::forest::train::train_forest;
use crate::vision::forest::{Forest, Objective, SplitSpace, TrainParams};
use crate::vision::segment::{Background, SegmentError, Segmenter, SegmenterConfig};
use rand::seq::SliceRandom;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

/// How training pixels are drawn and features scored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelParams {
    /// Mouse pixels drawn per training image.
    pub per_image: usize,
    /// Thresholds tried per candidate feature.
    pub thresholds: usize,
    pub seed: u64,
}

impl Default for PixelParams {
    fn default() -> Self {
        Self {
            per_image: 150,
            thresholds: 12,
            seed: 0,
        }
    }
}

/// The mouse's true pixels in a sample's top view (the rendered labels), as a mask over its
/// region. Training uses them; evaluation of the body forest uses the segmenter instead.
pub fn true_mask(sample: &Sample) -> Vec<bool> {
    sample.top.label.iter().map(|&l| l != BACKGROUND_LABEL).collect()
}

/// A sample's depth image for the features, on its true mask.
pub fn depth_image(sample: &Sample) -> DepthImage {
    DepthImage::from_mask(sample.top.region, &sample.top.depth, &true_mask(sample))
}

/// A sample's top-view depth crop with extra Gaussian noise (readings only; 0 stays 0).
pub fn noisy_depth(sample: &Sample, noise_mm: f64, seed: u64) -> Vec<u16> {
    if noise_mm <= 0.0 {
        return sample.top.depth.clone();
    }
    let mut rng = item_rng(seed, 0xE0, sample.index);
    sample
        .top
        .depth
        .iter()
        .map(|&d| {
            if d == 0 {
                return 0;
            }
            let n: f64 = StandardNormal.sample(&mut rng);
            (f64::from(d) + noise_mm * n).round().clamp(1.0, 65535.0) as u16
        })
        .collect()
}

/// The segmenter set up for a rig's empty cage, ready to hand out one segmenter per thread.
#[derive(Debug)]
pub struct MaskSource {
    config: SegmenterConfig,
    background: Background,
}

impl MaskSource {
    /// The segmenter's background: the noiseless empty cage over the whole depth image.
    ///
    /// # Errors
    /// When the cage gives no usable background (no floor in view).
    pub fn for_rig(rig: &Rig) -> Result<Self, SegmentError> {
        let config = SegmenterConfig::default();
        let full = Region::full(&rig.depth.intrinsics);
        let cage = Cage::new(&rig.depth).depth(full);
        let background = Background::from_depth(&cage, full, &rig.depth.intrinsics, &config)?;
        let source = Self { config, background };
        source.segmenter()?;
        Ok(source)
    }

    /// A segmenter of its own (they hold per-frame buffers).
    ///
    /// # Errors
    /// As [`SegmenterConfig::build`].
    pub fn segmenter(&self) -> Result<Segmenter, SegmentError> {
        self.config.build(self.background.clone())
    }
}

/// Segments a depth crop at `region` and returns the mouse as a depth image for the forest,
/// `None` when the segmenter finds no mouse.
///
/// # Errors
/// As [`Segmenter::segment_region`].
pub fn segmented_image(
    segmenter: &mut Segmenter,
    depth: &[u16],
    region: Region,
) -> Result<Option<DepthImage>, SegmentError> {
    let Some(mouse) = segmenter.segment_region(depth, region)? else {
        return Ok(None);
    };
    let mask: Vec<bool> = (0..region.len())
        .map(|k| {
            let x = region.x0 + (k % region.width as usize) as u32;
            let y = region.y0 + (k / region.width as usize) as u32;
            mouse.contains(x, y)
        })
        .collect();
    Ok(Some(DepthImage::from_mask(region, depth, &mask)))
}

/// An image and the `(x, y, depth)` of its drawn mouse pixels.
type ImagePixels = (DepthImage, Vec<(f32, f32, f32)>);

/// Training pixels of a set of samples, with what each pixel's targets need: the image index,
/// its pixel, and the sample it came from.
pub fn draw_pixels(samples: &[Sample], params: &PixelParams) -> PixelSet {
    let per: Vec<ImagePixels> = samples
        .par_iter()
        .map(|s| {
            let image = depth_image(s);
            let r = image.region;
            let mut on: Vec<(f32, f32, f32)> = image
                .on_mouse()
                .map(|(k, d)| {
                    let x = r.x0 as usize + k % r.width as usize;
                    let y = r.y0 as usize + k / r.width as usize;
                    (x as f32, y as f32, d)
                })
                .collect();
            let mut rng = item_rng(params.seed, 0x91C5, s.index);
            on.shuffle(&mut rng);
            on.truncate(params.per_image);
            (image, on)
        })
        .collect();
    let mut set = PixelSet::default();
    for (i, (image, pixels)) in per.into_iter().enumerate() {
        set.images.push(image);
        for (x, y, d) in pixels {
            set.image.push(i as u32);
            set.x.push(x);
            set.y.push(y);
            set.depth.push(d);
        }
    }
    set
}

/// A tail tip closer than this to the tail base (mm) is taken as a tail not visible.
const HIDDEN_TAIL_MM: f64 = 15.0;

/// The offsets of every training pixel to the main-body joints (camera frame), and the joints
/// each is near (within the joint's vote radius; never the tail tip of a mouse whose tail is
/// not visible).
pub fn joint_targets(set: &PixelSet, samples: &[Sample], rig: &Rig) -> JointTargets {
    let cam = rig.depth.camera_from_world();
    let joints_cam: Vec<[nalgebra::Point3<f64>; BODY_JOINTS]> = samples
        .iter()
        .map(|s| std::array::from_fn(|j| cam * s.joints[Joint::MAIN_BODY[j].index()]))
        .collect();
    let radius: [f32; BODY_JOINTS] = std::array::from_fn(|j| Joint::MAIN_BODY[j].vote_radius_mm() as f32);
    // A mouse whose tail is not visible teaches nothing about where a tail tip is seen: its
    // pixels near the tail base would otherwise teach the leaves to put the tip there.
    let taught: Vec<u16> = samples
        .iter()
        .map(|s| {
            let tail = s.joints[Joint::TailTip.index()] - s.joints[Joint::TailBase.index()];
            if tail.norm() < HIDDEN_TAIL_MM {
                !(1 << TAIL_TIP)
            } else {
                u16::MAX
            }
        })
        .collect();
    let i = &rig.depth.intrinsics;
    let mut t = JointTargets::default();
    for k in 0..set.len() {
        let p = i.unproject(
            &nalgebra::Point2::new(f64::from(set.x[k]), f64::from(set.y[k])),
            f64::from(set.depth[k]),
        );
        let joints = &joints_cam[set.image[k] as usize];
        let mut near = 0u16;
        let offsets = std::array::from_fn(|j| {
            let o = joints[j] - p;
            let o = [o.x as f32, o.y as f32, o.z as f32];
            if (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt() < radius[j] {
                near |= 1 << j;
            }
            o
        });
        t.offsets.push(offsets);
        t.near.push(near & taught[set.image[k] as usize]);
    }
    t
}

/// The part label of every training pixel.
fn part_labels(set: &PixelSet, samples: &[Sample]) -> Vec<u8> {
    (0..set.len())
        .map(|k| {
            let s = &samples[set.image[k] as usize];
            let r = s.top.region;
            let x = set.x[k] as u32 - r.x0;
            let y = set.y[k] as u32 - r.y0;
            s.top.label[(y * r.width + x) as usize]
        })
        .collect()
}

/// Loads a dataset's samples.
///
/// # Errors
/// When the dataset cannot be read.
pub fn load(dir: &Path) -> Result<(Dataset, Vec<Sample>), DatasetError> {
    let ds = Dataset::open(dir)?;
    let samples = ds.load()?;
    Ok((ds, samples))
}

/// The name a model file records for a dataset: its directory's own name, not the full path,
/// so that shared model files do not carry the trainer's file-system layout (the seed, size
/// and noise recorded beside it identify the data).
pub fn dataset_name(dir: &Path) -> String {
    dir.file_name()
        .map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned())
}

fn provenance(role: &str, ds: &Dataset) -> DataProvenance {
    DataProvenance {
        role: role.to_owned(),
        path: dataset_name(&ds.dir),
        seed: ds.meta.seed,
        images: ds.meta.count,
        noise: ds.meta.noise,
        engine_version: ds.meta.engine_version,
    }
}

fn rig_of(ds: &Dataset) -> Rig {
    ds.meta.rig.unwrap_or_else(Rig::default_rig)
}

/// Which forest to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    Body,
    Parts,
}

/// Everything `train` needs.
#[derive(Clone, Debug)]
pub struct TrainJob<'a> {
    pub target: Target,
    pub train: &'a Path,
    pub discriminative: Option<&'a Path>,
    pub params: TrainParams,
    pub disc: DiscriminativeParams,
    pub pixels: PixelParams,
    /// A trained baseline to refine instead of training one (it must have been trained on
    /// `train` with these parameters; only discriminative training runs).
    pub from: Option<Model>,
}

/// Progress callbacks of training.
pub trait TrainProgress: Sync {
    fn stage(&self, what: &str, total: u64);
    fn tick(&self);
}

/// Trains a forest as `job` says.
///
/// # Errors
/// When a dataset cannot be read.
pub fn train(job: &TrainJob<'_>, progress: &dyn TrainProgress) -> Result<(Model, Vec<PassStats>), DatasetError> {
    let start = Instant::now();
    let (ds_t, samples_t) = load(job.train)?;
    let rig = rig_of(&ds_t);
    let set_t = draw_pixels(&samples_t, &job.pixels);
    let dd = match job.discriminative {
        Some(dir) => {
            let (ds, samples) = load(dir)?;
            let set = draw_pixels(
                &samples,
                &PixelParams {
                    seed: job.pixels.seed ^ 0xDD,
                    ..job.pixels
                },
            );
            Some((ds, samples, set))
        }
        None => None,
    };
    let space_t = DepthSpace {
        pixels: &set_t,
        thresholds: job.pixels.thresholds,
    };
    let mut info = model_info(job, &ds_t, dd.as_ref().map(|(ds, ..)| ds));
    progress.stage("training", job.params.trees as u64);
    let (model, passes) = match job.target {
        Target::Body => {
            let targets = joint_targets(&set_t, &samples_t, &rig);
            let targets_d = dd
                .as_ref()
                .map(|(_, samples_d, set_d)| joint_targets(set_d, samples_d, &rig));
            let from = match &job.from {
                Some(Model::Body(_, f)) => Some(f.clone()),
                _ => None,
            };
            let second = dd.as_ref().zip(targets_d.as_ref()).map(|((_, _, set), t)| {
                (
                    set,
                    JointObjective {
                        targets: t,
                        scope: job.disc.error,
                    },
                )
            });
            let (forest, passes) = fit_forest(
                &space_t,
                &JointObjective {
                    targets: &targets,
                    scope: job.disc.error,
                },
                from,
                second,
                job,
                progress,
            );
            info.training_seconds = start.elapsed().as_secs_f64();
            (Model::Body(info, forest), passes)
        }
        Target::Parts => {
            let labels = part_labels(&set_t, &samples_t);
            let labels_d = dd.as_ref().map(|(_, samples_d, set_d)| part_labels(set_d, samples_d));
            let from = match &job.from {
                Some(Model::Parts(_, f)) => Some(f.clone()),
                _ => None,
            };
            let second = dd.as_ref().zip(labels_d.as_ref()).map(|((_, _, set), l)| {
                (
                    set,
                    ClassObjective {
                        labels: l,
                        classes: PART_COUNT,
                    },
                )
            });
            let objective = ClassObjective {
                labels: &labels,
                classes: PART_COUNT,
            };
            let (forest, passes) = fit_forest(&space_t, &objective, from, second, job, progress);
            info.training_seconds = start.elapsed().as_secs_f64();
            (Model::Parts(info, forest), passes)
        }
    };
    Ok((model, passes))
}

/// The description of the model `job` trains on `ds_t` (and, for the discriminative pass,
/// `ds_d`), its training time still to be set.
fn model_info(job: &TrainJob<'_>, ds_t: &Dataset, ds_d: Option<&Dataset>) -> ModelInfo {
    ModelInfo {
        kind: match job.target {
            Target::Body => ModelKind::Body,
            Target::Parts => ModelKind::Parts,
        },
        software_version: env!("CARGO_PKG_VERSION").to_owned(),
        skeleton_version: SKELETON_VERSION,
        engine_version: ds_t.meta.engine_version,
        train: job.from.as_ref().map_or(job.params, |m| m.info().train),
        discriminative: ds_d.map(|_| job.disc),
        data: std::iter::once(provenance("train", ds_t))
            .chain(ds_d.map(|ds| provenance("discriminative", ds)))
            .collect(),
        pixels_per_image: job.pixels.per_image,
        thresholds: job.pixels.thresholds,
        training_seconds: 0.0,
    }
}

/// Trains the baseline on D_t (or takes `from`) and, given D_d, refines it discriminatively.
fn fit_forest<O: Objective>(
    space_t: &DepthSpace<'_>,
    objective_t: &O,
    from: Option<Forest<[f32; 2], O::Leaf>>,
    second: Option<(&PixelSet, O)>,
    job: &TrainJob<'_>,
    progress: &dyn TrainProgress,
) -> (Forest<[f32; 2], O::Leaf>, Vec<PassStats>) {
    let tick = || progress.tick();
    let mut forest = from.unwrap_or_else(|| {
        let all: Vec<u32> = (0..space_t.pixels.len() as u32).collect();
        train_forest(
            space_t,
            objective_t,
            vec![all; job.params.trees],
            &job.params,
            [0.0; 2],
            &tick,
        )
    });
    let passes = match second {
        Some((set_d, objective_d)) => {
            let space_d = DepthSpace {
                pixels: set_d,
                thresholds: job.pixels.thresholds,
            };
            refine(&space_d, &objective_d, &mut forest, set_d.len(), &job.disc, progress)
        }
        None => Vec::new(),
    };
    (forest, passes)
}

/// Discriminative training of every tree, trees in parallel, `params.iterations` passes each.
fn refine<S: SplitSpace, O: Objective>(
    space: &S,
    objective: &O,
    forest: &mut Forest<S::Feature, O::Leaf>,
    samples: usize,
    params: &DiscriminativeParams,
    progress: &dyn TrainProgress,
) -> Vec<PassStats>
where
    S::Feature: Send,
    O::Leaf: Send,
{
    progress.stage("discriminative", (forest.trees.len() * params.iterations) as u64);
    let all: Vec<u32> = (0..samples as u32).collect();
    forest
        .trees
        .par_iter_mut()
        .enumerate()
        .flat_map_iter(|(t, tree)| {
            (0..params.iterations)
                .map(|it| {
                    let mut s = subset(&all, params, t, it);
                    let p = refine_tree(space, objective, tree, &mut s, params, t, it);
                    progress.tick();
                    p
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Per-joint errors of the body forest on a test set.
#[derive(Clone, Debug, Serialize)]
pub struct BodyReport {
    pub images: usize,
    /// Images where the segmenter found no mouse (their joints are not counted).
    pub no_mouse: usize,
    /// Mean 3D error per joint name, mm.
    pub per_joint_mm: BTreeMap<String, f64>,
    /// Mean over joints 1-12, mm.
    pub mean_error_mm: f64,
    /// Extra Gaussian noise added to the test depth, mm.
    pub noise_mm: f64,
    /// Mean time to estimate one image's joints (votes and aggregation), ms.
    pub ms_per_image: f64,
}

/// Pixels voting per image at evaluation and run time.
pub const VOTE_BUDGET: usize = 1200;

/// Evaluates a body forest on samples, with `noise_mm` of extra Gaussian noise: each image is
/// segmented as at run time, so the error includes segmentation.
///
/// # Errors
/// When the segmenter cannot be set up or fails on an image.
pub fn eval_body(
    estimator: &BodyEstimator,
    samples: &[Sample],
    rig: &Rig,
    noise_mm: f64,
) -> Result<BodyReport, SegmentError> {
    let cam_to_world = rig.depth.world_from_camera;
    let masks = MaskSource::for_rig(rig)?;
    // One segmenter per thread (they hold buffers), each over a contiguous share of the images.
    let threads = rayon::current_num_threads().max(1);
    let mut segmenters: Vec<Segmenter> = (0..threads).map(|_| masks.segmenter()).collect::<Result<_, _>>()?;
    let share = samples.len().div_ceil(threads).max(1);
    let start = Instant::now();
    let results: Vec<Result<Vec<Option<[f64; BODY_JOINTS]>>, SegmentError>> = samples
        .par_chunks(share)
        .zip(segmenters.par_iter_mut())
        .map(|(chunk, segmenter)| {
            let mut est = estimator.clone();
            let mut pixels = Vec::<Pixel>::new();
            chunk
                .iter()
                .map(|s| {
                    let depth = noisy_depth(s, noise_mm, 0xE7A1);
                    let Some(image) = segmented_image(segmenter, &depth, s.top.region)? else {
                        return Ok(None);
                    };
                    sample_pixels(&image, VOTE_BUDGET, &mut pixels);
                    if pixels.is_empty() {
                        return Ok(None);
                    }
                    let guesses = est.estimate(&image, &pixels, &rig.depth.intrinsics);
                    Ok(Some(std::array::from_fn(|j| {
                        let truth = s.joints[Joint::MAIN_BODY[j].index()];
                        match guesses[j] {
                            Some(g) => {
                                let p = nalgebra::Point3::from(g.position_mm.cast::<f64>());
                                (cam_to_world * p - truth).norm()
                            }
                            // No vote at all: as far off as the mouse is long.
                            None => 100.0,
                        }
                    })))
                })
                .collect()
        })
        .collect();
    let results: Vec<Option<[f64; BODY_JOINTS]>> = results
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .flatten()
        .collect();
    let elapsed = start.elapsed().as_secs_f64();
    let found: Vec<&[f64; BODY_JOINTS]> = results.iter().flatten().collect();
    let per_joint: Vec<f64> = (0..BODY_JOINTS)
        .map(|j| found.iter().map(|e| e[j]).sum::<f64>() / found.len().max(1) as f64)
        .collect();
    Ok(BodyReport {
        images: samples.len(),
        no_mouse: results.iter().filter(|r| r.is_none()).count(),
        per_joint_mm: Joint::MAIN_BODY
            .iter()
            .zip(&per_joint)
            .map(|(j, &e)| (j.name().to_owned(), e))
            .collect(),
        mean_error_mm: per_joint.iter().sum::<f64>() / BODY_JOINTS as f64,
        noise_mm,
        ms_per_image: elapsed * 1000.0 * rayon::current_num_threads() as f64 / samples.len().max(1) as f64,
    })
}

/// Per-class accuracy of the part forest on a test set.
#[derive(Clone, Debug, Serialize)]
pub struct PartsReport {
    pub images: usize,
    pub pixels: u64,
    /// Fraction of each class's pixels labelled right, by class name.
    pub per_class_accuracy: BTreeMap<String, f64>,
    pub mean_class_accuracy: f64,
    pub pixel_accuracy: f64,
    /// `confusion[truth][predicted]` pixel counts, classes in label order.
    pub confusion: Vec<Vec<u64>>,
    pub classes: Vec<String>,
}

/// Evaluates a part forest on every mouse pixel of the samples: each pixel's class is the
/// argmax of the trees' averaged histograms.
pub fn eval_parts(forest: &Forest<[f32; 2], Vec<f32>>, samples: &[Sample]) -> PartsReport {
    let confusions: Vec<Vec<Vec<u64>>> = samples
        .par_iter()
        .map(|s| {
            let image = depth_image(s);
            let r = image.region;
            let mut c = vec![vec![0u64; PART_COUNT]; PART_COUNT];
            let mut hist = [0f32; PART_COUNT];
            for (k, d) in image.on_mouse() {
                let truth = s.top.label[k];
                if truth == BACKGROUND_LABEL {
                    continue;
                }
                let (x, y) = (
                    (r.x0 as usize + k % r.width as usize) as f32,
                    (r.y0 as usize + k / r.width as usize) as f32,
                );
                hist.fill(0.0);
                for t in &forest.trees {
                    for (h, p) in hist.iter_mut().zip(t.leaf(|u| image.feature(x, y, d, u))) {
                        *h += p;
                    }
                }
                c[usize::from(truth)][argmax(&hist)] += 1;
            }
            c
        })
        .collect();
    let mut confusion = vec![vec![0u64; PART_COUNT]; PART_COUNT];
    for c in confusions {
        for (row, add) in confusion.iter_mut().zip(c) {
            for (x, y) in row.iter_mut().zip(add) {
                *x += y;
            }
        }
    }
    let per_class: Vec<f64> = confusion
        .iter()
        .enumerate()
        .map(|(t, row)| row[t] as f64 / row.iter().sum::<u64>().max(1) as f64)
        .collect();
    let pixels: u64 = confusion.iter().flatten().sum();
    let correct: u64 = (0..PART_COUNT).map(|t| confusion[t][t]).sum();
    PartsReport {
        images: samples.len(),
        pixels,
        per_class_accuracy: Part::ALL
            .iter()
            .zip(&per_class)
            .map(|(p, &a)| (p.name().to_owned(), a))
            .collect(),
        mean_class_accuracy: per_class.iter().sum::<f64>() / PART_COUNT as f64,
        pixel_accuracy: correct as f64 / pixels.max(1) as f64,
        confusion,
        classes: Part::ALL.iter().map(|p| p.name().to_owned()).collect(),
    }
}
