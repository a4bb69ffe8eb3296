//! `mousepose adapt`: models fitted to a lab's own mice from its unlabelled recordings.
//!
//! 1. Each recording is opened as `replay` opens it (sessions and MoSeq layouts; the rig, the
//!    empty cage and the arena found the same way), and the mouse is segmented in up to
//!    `--frames` frames spread over the frames to learn from: its length and width (the
//!    second moments, the tail left out), its back's height, a visible tail, and the floor's
//!    noise around it ([`crate::vision::measure`]); the camera's height and pixel size come
//!    from the fitted floor.
//! 2. Our standard mouse is rendered under the same camera and measured the same way; the
//!    build (size, girth, back height, how often the tail shows) is corrected over a few
//!    rounds until the rendered mouse measures as the lab's does.
//! 3. A training set of mice around that build is rendered under that camera with that noise,
//!    and the body forest and the orientation model are trained on it into the output
//!    directory (the paw cascade is copied from the bundled models: the bottom camera is not
//!    measured). The bundled models are never written.
//! 4. Each recording is replayed with the bundled models and with the adapted ones, and the
//!    frames to judge are judged without labels ([`crate::vision::measure::unlabelled`]).
//!
//! `DIR/adapt.json` holds everything measured, the build, the training and the judgement.

use crate::core::geometry::{Camera, Intrinsics, Rig, look_at};
use crate::core::noise::{DepthNoise, NoiseModel};
use crate::core::pose::JointSource;
use crate::core::skeleton::Joint;
use crate::engine::progress::Progress;
use crate::engine::replay::{ReplayOptions, replay_with, scene_of};
use crate::engine::train::{ModelTarget, TrainOptions, TrainSummary, train};
use crate::engine::{Exists, Failure, Interrupt, output_failure};
use crate::io::output::Staging;
use crate::runtime::models::{BODY_MODEL, ORIENTATION_MODEL, default_models_dir, paws_file};
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crate::runtime::recording::Recording;
use crate::runtime::sink::poses::{POSES_FILE, PosesRows};
use crate::synth::Build;
use crate::synth::dataset::{DatasetSpec, render_sample, write_dataset};
use crate::synth::mouse::pose_library;
use crate::vision::forest::discriminative::ErrorScope;
use crate::vision::measure::{
    BodyMeasure, BodySummary, JudgedFrame, Unlabelled, axis_angle_deg, floor_noise_mm, measure_mouse, unlabelled,
};
use crate::vision::segment::{Mouse, PoseFrame, Segmenter};
use anyhow::Context as _;
use nalgebra::{Point2, Point3, Vector2, Vector3};
use rayon::prelude::*;
use serde::Serialize;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// What `adapt` writes beside the models.
pub const ADAPT_FILE: &str = "adapt.json";
/// A recording must give at least this many frames to learn from (a second at 30 fps).
pub const MIN_FRAMES: usize = 30;
/// The mouse must be found stretched out in at least this many of the frames measured.
pub const MIN_MOUSE_FRAMES: usize = 10;
/// Rendered mice measured per round of the build's fit.
const PROBE_IMAGES: u64 = 240;
/// Rounds of the build's fit.
const FIT_ROUNDS: usize = 3;
/// The build's factors stay within this range of the standard mouse's.
const BUILD_RANGE: (f64, f64) = (0.5, 2.0);
/// Frames read from a recording at a time.
const READ_CHUNK: usize = 64;
/// The joints that lie on the body seen from above (the tail tip and the limbs left out).
const ON_BODY: [Joint; 11] = [
    Joint::Snout,
    Joint::Head,
    Joint::Neck,
    Joint::Withers,
    Joint::MidBack,
    Joint::Rump,
    Joint::TailBase,
    Joint::LeftEar,
    Joint::RightEar,
    Joint::LeftHip,
    Joint::RightHip,
];

/// Frames `first..last` of a recording (`last` `None`: to its end).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FrameRange {
    pub first: usize,
    pub last: Option<usize>,
}

impl FrameRange {
    /// The range within a recording of `count` frames.
    pub fn within(&self, count: usize) -> Range<usize> {
        let last = self.last.unwrap_or(count).min(count);
        self.first.min(last)..last
    }
}

impl std::str::FromStr for FrameRange {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("expected frames FIRST:LAST such as 0:450 or 450: (either may be left out), got {s:?}");
        let (a, b) = s.split_once(':').ok_or_else(bad)?;
        let first = if a.trim().is_empty() {
            0
        } else {
            a.trim().parse().map_err(|_| bad())?
        };
        let last = if b.trim().is_empty() {
            None
        } else {
            Some(b.trim().parse().map_err(|_| bad())?)
        };
        if last.is_some_and(|l| l <= first) {
            return Err(bad());
        }
        Ok(Self { first, last })
    }
}

/// What `adapt` reads, how much it renders and trains, and where it writes.
#[derive(Clone, Debug)]
pub struct AdaptOptions {
    pub recordings: Vec<PathBuf>,
    /// The models directory to write (never the bundled one).
    pub out: PathBuf,
    pub force: bool,
    /// The frames of each recording to learn from, and to judge the models on.
    pub learn: FrameRange,
    pub judge: FrameRange,
    /// Judge the models before and after (replays of each recording with both).
    pub judge_models: bool,
    /// Frames measured per recording, at most (spread over the frames to learn from).
    pub frames: usize,
    /// Training images rendered, and the body forest's size.
    pub images: u64,
    pub trees: u32,
    pub depth: u32,
    pub tests: u32,
    pub pixels: u32,
    pub seed: u64,
    /// As `replay`'s: the depth intrinsics for uncalibrated recordings, the arena's mask.
    pub intrinsics: Option<PathBuf>,
    pub roi: Option<PathBuf>,
    /// Body-forest workers of the judging replays; 0: one per core.
    pub workers: usize,
}

/// What was measured of one recording.
#[derive(Clone, Debug, Serialize)]
pub struct RecordingMeasured {
    pub recording: PathBuf,
    pub frames: usize,
    /// The frames learnt from, those measured, and those of them with a mouse found.
    pub learn: Range<usize>,
    pub measured: usize,
    pub found: usize,
    /// The depth camera: its height above the fitted floor (mm), its focal length (px), its
    /// frame size, and the millimetres a pixel spans on the floor.
    pub camera_height_mm: f64,
    pub fx: f64,
    pub width: u32,
    pub height: u32,
    pub mm_per_px: f64,
    /// The floor's noise (mm, one standard deviation, median over the frames).
    pub floor_noise_mm: Option<f64>,
    /// This recording's mouse.
    pub mouse: Option<BodySummary>,
}

/// The models before and after, judged without labels on one recording's frames.
#[derive(Clone, Debug, Serialize)]
pub struct Judged {
    pub recording: PathBuf,
    pub frames: Range<usize>,
    /// `None` when the bundled models cannot be found.
    pub bundled: Option<Unlabelled>,
    pub adapted: Unlabelled,
    /// The replays' output directories (their `poses.csv` and `summary.json`).
    pub bundled_run: Option<PathBuf>,
    pub adapted_run: PathBuf,
}

/// The models trained.
#[derive(Clone, Debug, Serialize)]
pub struct Trained {
    pub images: u64,
    pub render_seconds: f64,
    pub body_trees: usize,
    pub body_nodes: usize,
    pub body_seconds: f64,
    pub orientation_views: usize,
    pub orientation_training_accuracy: f64,
    /// Copied from the bundled models (the bottom camera is not measured), when there is one.
    pub paws_copied_from: Option<PathBuf>,
}

/// `adapt.json`.
#[derive(Clone, Debug, Serialize)]
pub struct AdaptSummary {
    pub out: PathBuf,
    pub software_version: &'static str,
    pub recordings: Vec<RecordingMeasured>,
    /// The lab's mice over every recording; our standard mouse rendered under the same camera
    /// and measured the same way; the fitted build rendered and measured again.
    pub measured: BodySummary,
    pub standard: BodySummary,
    pub fitted: BodySummary,
    pub build: Build,
    /// The camera and noise the training data were rendered with.
    pub render_camera_height_mm: f64,
    pub render_fx: f64,
    pub render_noise_mm: f64,
    pub trained: Trained,
    pub judged: Vec<Judged>,
    pub elapsed_s: f64,
}

/// The mouse and camera of one recording, and the world it was measured in.
struct Measured {
    summary: RecordingMeasured,
    frames: Vec<BodyMeasure>,
    rig: Rig,
}

/// `mousepose adapt`.
///
/// # Errors
/// A recording that cannot be read, is too short, or shows no mouse; an output in the way
/// (the user's); rendering, training or writing failing (the work's).
pub fn adapt(options: &AdaptOptions, progress: &dyn Progress) -> Result<AdaptSummary, Failure> {
    let started = std::time::Instant::now();
    if options.recordings.is_empty() {
        return Err(Failure::usage(anyhow::anyhow!("no recording given to adapt to")));
    }
    if options.out.exists() && !options.force && std::fs::read_dir(&options.out).is_ok_and(|mut d| d.next().is_some()) {
        return Err(Failure::usage(Exists(options.out.clone())));
    }
    if let Ok(bundled) = default_models_dir() {
        let same = |p: &Path| std::fs::canonicalize(p).ok();
        if same(&options.out).is_some() && same(&options.out) == same(&bundled) {
            return Err(Failure::usage(anyhow::anyhow!(
                "{:?} holds the bundled models: adapted models go into a directory of their own",
                options.out
            )));
        }
    }
    if options.judge_models {
        // Refused now rather than after the training.
        for path in &options.recordings {
            open(path, options.judge, "judge on")?;
        }
    }
    let mut measured = Vec::new();
    for path in &options.recordings {
        measured.push(measure_recording(path, options, progress)?);
    }
    let all: Vec<BodyMeasure> = measured.iter().flat_map(|m| m.frames.iter().copied()).collect();
    let target = BodySummary::of(&all).ok_or_else(|| {
        Failure::usage(anyhow::anyhow!(
            "the mouse was never found stretched out in the frames measured"
        ))
    })?;
    let first = &measured[0];
    let noises: Vec<f64> = measured.iter().filter_map(|m| m.summary.floor_noise_mm).collect();
    let noise_mm = crate::vision::measure::Spread::of(noises).map_or(0.0, |s| s.p50);
    let camera_height_mm = first.summary.camera_height_mm;
    let rig = render_rig(first.rig.depth.intrinsics, camera_height_mm);
    let noise = DepthNoise {
        model: NoiseModel::None,
        gaussian_mm: noise_mm,
    };
    progress.start("fitting the build", (FIT_ROUNDS + 1) as u64);
    let (build, standard, fitted) = fit_build(&rig, &noise, &target, options.seed, progress)?;
    progress.finish();
    tracing::info!(
        message = "Build fitted.",
        scale = format!("{:.3}", build.scale),
        girth = format!("{:.3}", build.girth),
        height = format!("{:.3}", build.height),
        tail_shown = format!("{:.2}", build.tail_shown),
    );

    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    let trained = train_models(staging.path(), &rig, &noise, build, options, progress)?;
    let out = staging.commit().map_err(output_failure)?;
    let mut summary = AdaptSummary {
        out: std::fs::canonicalize(&out).unwrap_or(out),
        software_version: env!("CARGO_PKG_VERSION"),
        recordings: measured.into_iter().map(|m| m.summary).collect(),
        measured: target,
        standard,
        fitted,
        build,
        render_camera_height_mm: camera_height_mm,
        render_fx: rig.depth.intrinsics.fx,
        render_noise_mm: noise_mm,
        trained,
        judged: Vec::new(),
        elapsed_s: 0.0,
    };
    write_summary(&mut summary, started)?;
    if options.judge_models {
        for path in &options.recordings {
            let judged = judge_recording(path, options, &summary.out, progress)?;
            summary.judged.push(judged);
        }
        write_summary(&mut summary, started)?;
    }
    Ok(summary)
}

fn write_summary(summary: &mut AdaptSummary, started: std::time::Instant) -> Result<(), Failure> {
    summary.elapsed_s = started.elapsed().as_secs_f64();
    let path = summary.out.join(ADAPT_FILE);
    let json = serde_json::to_vec_pretty(summary).context("serialising adapt.json")?;
    std::fs::write(&path, json).with_context(|| format!("writing {path:?}"))?;
    Ok(())
}

/// The options of a replay of `recording` as `adapt` runs it.
fn replay_options(recording: &Path, options: &AdaptOptions, out: PathBuf, models: Option<PathBuf>) -> ReplayOptions {
    ReplayOptions {
        session: recording.to_owned(),
        out,
        models,
        realtime: false,
        workers: options.workers,
        overlays: None,
        calibration: None,
        intrinsics: options.intrinsics.clone(),
        roi: options.roi.clone(),
        force: true,
        stream: None,
        lsl: None,
        lead_ns: None,
        partner_wait: None,
        mice: 1,
    }
}

/// Opens `path` and checks it has enough frames in `range`.
fn open(path: &Path, range: FrameRange, what: &str) -> Result<(Recording, Range<usize>), Failure> {
    let recording = Recording::open(path).map_err(|e| {
        let usage = e.is_input_problem();
        Failure::classed(
            usage,
            anyhow::Error::new(e).context(format!("cannot read the recording {path:?}")),
        )
    })?;
    let count = recording.depth_count();
    let frames = range.within(count);
    if frames.len() < MIN_FRAMES {
        return Err(Failure::usage(anyhow::anyhow!(
            "the recording {path:?} has {} frames to {what} (frames {}..{} of {count}); adapt needs at least {MIN_FRAMES}",
            frames.len(),
            frames.start,
            frames.end
        )));
    }
    Ok((recording, frames))
}

/// The frames at `indices` read a chunk at a time, each handed to `each`.
fn for_frames(
    recording: &Recording,
    indices: &[usize],
    mut each: impl FnMut(&crate::core::frame::DepthFrame),
) -> Result<(), Failure> {
    for chunk in indices.chunks(READ_CHUNK) {
        let frames = recording
            .depth_frames_at(chunk)
            .with_context(|| format!("reading frames of {:?}", recording.dir()))?;
        for frame in &frames {
            each(frame);
        }
    }
    Ok(())
}

/// Measures the mouse and camera of one recording.
fn measure_recording(path: &Path, options: &AdaptOptions, progress: &dyn Progress) -> Result<Measured, Failure> {
    let (recording, range) = open(path, options.learn, "learn from")?;
    let scene = scene_of(&replay_options(path, options, PathBuf::new(), None), &recording)
        .map_err(|e| Failure::classed(e.is_usage(), anyhow::Error::new(e).context(format!("in {path:?}"))))?;
    let rig = scene.rig;
    let fx = rig.depth.intrinsics.fx;
    let picks = options.frames.clamp(1, range.len());
    let indices: Vec<usize> = (0..picks).map(|k| range.start + k * range.len() / picks).collect();
    let mut segmenter = scene.segmenter;
    let background = segmenter.background().depth().to_vec();
    let bg_region = segmenter.background().region();
    let arena = scene.arena;
    let (mut frames, mut noises, mut found) = (Vec::new(), Vec::new(), 0usize);
    progress.start("measuring", indices.len() as u64);
    progress.label(&format!(
        "measuring {}",
        path.file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    ));
    for_frames(&recording, &indices, |frame| {
        progress.advance(1);
        let Ok(mouse) = segmenter.segment(frame) else { return };
        let keep_out = mouse.as_ref().map(|m| {
            let r = m.region;
            let pad = 20;
            (
                (r.x0 as usize).saturating_sub(pad),
                (r.y0 as usize).saturating_sub(pad),
                (r.x0 + r.width) as usize + pad,
                (r.y0 + r.height) as usize + pad,
            )
        });
        if (bg_region.width, bg_region.height) == (frame.width, frame.height)
            && let Some(n) = floor_noise_mm(&frame.data, &background, &arena, frame.width as usize, keep_out, 3)
        {
            noises.push(n);
        }
        if let Some(m) = mouse
            .as_ref()
            .and_then(|m| measure_mouse(m, &rig.depth.world_from_camera, fx))
        {
            found += 1;
            frames.push(m);
        }
    })?;
    progress.finish();
    let stretched = frames.iter().filter(|m| !m.curled).count();
    if stretched < MIN_MOUSE_FRAMES {
        return Err(Failure::usage(anyhow::anyhow!(
            "no mouse found in the recording {path:?}: stretched out in {stretched} of {} frames measured (found at all in {found}); if it is in view, give the arena with --roi",
            indices.len()
        )));
    }
    let camera_height_mm = scene.world.camera_height_mm;
    let summary = RecordingMeasured {
        recording: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned()),
        frames: recording.depth_count(),
        learn: range,
        measured: indices.len(),
        found,
        camera_height_mm,
        fx,
        width: rig.depth.intrinsics.width,
        height: rig.depth.intrinsics.height,
        mm_per_px: camera_height_mm / fx,
        floor_noise_mm: crate::vision::measure::Spread::of(noises).map(|s| s.p50),
        mouse: BodySummary::of(&frames),
    };
    Ok(Measured { summary, frames, rig })
}

/// The rig training data are rendered with: the recording's depth camera, looking straight
/// down from its height above the floor (a tilt is not rendered).
fn render_rig(intrinsics: Intrinsics, height_mm: f64) -> Rig {
    Rig {
        depth: Camera {
            intrinsics,
            world_from_camera: look_at(Point3::new(0.0, 0.0, height_mm), Point3::origin(), -Vector3::y()),
        },
        ..Rig::default_rig()
    }
}

/// The rendered mice of `build` under `rig`, measured as a recording's are.
fn measure_rendered(rig: &Rig, noise: &DepthNoise, build: Build, seed: u64) -> Result<BodySummary, Failure> {
    let spec = DatasetSpec {
        count: PROBE_IMAGES,
        seed,
        noise: *noise,
        bottom_views: false,
        bottom_clutter: false,
        mice: crate::synth::Mice::Standard,
        build: Some(build),
    };
    let library = pose_library();
    let masks = crate::training::MaskSource::for_rig(rig).context("modelling the rendered cage")?;
    let threads = rayon::current_num_threads().max(1);
    let indices: Vec<u64> = (0..PROBE_IMAGES).collect();
    let share = indices.len().div_ceil(threads).max(1);
    let fx = rig.depth.intrinsics.fx;
    let chunks: Vec<Result<Vec<BodyMeasure>, crate::vision::segment::SegmentError>> = indices
        .par_chunks(share)
        .map(|chunk| {
            let mut segmenter: Segmenter = masks.segmenter()?;
            let mut out = Vec::new();
            for &i in chunk {
                let s = render_sample(rig, &spec, &library, i);
                if let Some(mouse) = segmenter.segment_region(&s.top.depth, s.top.region)?
                    && let Some(m) = measure_mouse(&mouse, &rig.depth.world_from_camera, fx)
                {
                    out.push(m);
                }
            }
            Ok(out)
        })
        .collect();
    let mut all = Vec::new();
    for c in chunks {
        all.extend(c.context("segmenting the rendered mice")?);
    }
    BodySummary::of(&all).ok_or_else(|| Failure::from(anyhow::anyhow!("no rendered mouse was found stretched out")))
}

/// The build whose rendered mice measure as `target` does, by rounds of multiplicative
/// corrections from the standard mouse; with the standard mouse's and the fitted build's
/// measures.
fn fit_build(
    rig: &Rig,
    noise: &DepthNoise,
    target: &BodySummary,
    seed: u64,
    progress: &dyn Progress,
) -> Result<(Build, BodySummary, BodySummary), Failure> {
    let clamp = |v: f64| v.clamp(BUILD_RANGE.0, BUILD_RANGE.1);
    let standard = measure_rendered(rig, noise, Build::default(), seed)?;
    progress.advance(1);
    let mut build = Build {
        tail_shown: (target.tail_seen / standard.tail_seen.max(0.01)).clamp(0.0, 1.0),
        ..Build::default()
    };
    let mut current = standard;
    for _ in 0..FIT_ROUNDS {
        let l = target.length_mm.p50 / current.length_mm.p50;
        let w = target.width_mm.p50 / current.width_mm.p50;
        let h = target.height_mm.p50 / current.height_mm.p50;
        build.scale = clamp(build.scale * l);
        build.girth = clamp(build.girth * w / l);
        build.height = clamp(build.height * h / l);
        current = measure_rendered(rig, noise, build, seed)?;
        progress.advance(1);
    }
    Ok((build, standard, current))
}

/// Renders the training set into `dir/.dataset` (removed after), trains the body forest and
/// the orientation model into `dir`, and copies the bundled paw cascade.
fn train_models(
    dir: &Path,
    rig: &Rig,
    noise: &DepthNoise,
    build: Build,
    options: &AdaptOptions,
    progress: &dyn Progress,
) -> Result<Trained, Failure> {
    let data = dir.join(".dataset");
    std::fs::create_dir_all(&data).with_context(|| format!("creating {data:?}"))?;
    let spec = DatasetSpec {
        count: options.images,
        seed: options.seed,
        noise: *noise,
        bottom_views: false,
        bottom_clutter: false,
        mice: crate::synth::Mice::Standard,
        build: Some(build),
    };
    let render_started = std::time::Instant::now();
    progress.start("rendering", options.images);
    write_dataset(&data, rig, &spec, |done| progress.set_done(done)).context("rendering the training set")?;
    progress.finish();
    let render_seconds = render_started.elapsed().as_secs_f64();
    let train_options = |target: ModelTarget, out: &str| TrainOptions {
        target,
        data: Some(data.clone()),
        labels: None,
        out: dir.join(out),
        trees: options.trees,
        depth: options.depth,
        tests: options.tests,
        leaf: 60,
        discriminative: None,
        from: None,
        iterations: 1,
        start_level: 0,
        subset: 0.5,
        bootstrap: false,
        keep_leaves: false,
        keep_current: false,
        error: ErrorScope::AllJoints,
        score_pixels: 0,
        pixels: options.pixels,
        seed: options.seed,
        stages: 20,
        min_neighbors: None,
        net: None,
        force: true,
    };
    let (body_trees, body_nodes, body_seconds) = match train(&train_options(ModelTarget::Body, BODY_MODEL), progress)? {
        TrainSummary::Forest {
            trees,
            nodes,
            training_seconds,
            ..
        } => (trees, nodes, training_seconds),
        _ => (0, 0, 0.0),
    };
    progress.start("orientation model", 0);
    let (orientation_views, orientation_training_accuracy) =
        match train(&train_options(ModelTarget::Orientation, ORIENTATION_MODEL), progress)? {
            TrainSummary::Orientation {
                views,
                training_accuracy,
                ..
            } => (views, training_accuracy),
            _ => (0, 0.0),
        };
    progress.finish();
    std::fs::remove_dir_all(&data).with_context(|| format!("removing {data:?}"))?;
    let paws = default_models_dir().ok().and_then(|d| paws_file(&d));
    if let Some(p) = &paws
        && let Some(name) = p.file_name()
    {
        std::fs::copy(p, dir.join(name)).with_context(|| format!("copying {p:?}"))?;
    }
    Ok(Trained {
        images: options.images,
        render_seconds,
        body_trees,
        body_nodes,
        body_seconds,
        orientation_views,
        orientation_training_accuracy,
        paws_copied_from: paws,
    })
}

/// A frame of a run judged against its segmented mouse (whose centroid, not the pose's, says
/// where it travels, so that both models are judged on the same travel): `None` without a
/// pose or its body's axis.
fn judged_frame(record: &PoseRecord, mouse: &Mouse, rig: &Rig) -> Option<JudgedFrame> {
    if record.status != PoseStatus::Ok {
        return None;
    }
    let at = |j: Joint| {
        let e = record.pose.joint(j);
        (e.source != JointSource::Missing).then_some(e.position_mm)
    };
    let (snout, tail) = (at(Joint::Snout)?, at(Joint::TailBase)?);
    let forward = Vector2::new(snout.x - tail.x, snout.y - tail.y);
    let (mut on, mut given) = (0, 0);
    for p in ON_BODY.iter().filter_map(|&j| at(j)) {
        given += 1;
        if let Some(px) = rig.depth.project_world(&p) {
            let (x, y) = (px.x.round() as i64, px.y.round() as i64);
            let near = (-1..=1).any(|dy| {
                (-1..=1).any(|dx| {
                    let (u, v) = (x + dx, y + dy);
                    u >= 0 && v >= 0 && mouse.contains(u as u32, v as u32)
                })
            });
            on += usize::from(near);
        }
    }
    let axis_deg = (mouse.frame == PoseFrame::World).then(|| {
        axis_angle_deg(
            &forward,
            &Vector2::new(mouse.heading_rad.cos(), mouse.heading_rad.sin()),
        )
    });
    Some(JudgedFrame {
        time_s: record.depth.device_ns as f64 / 1e9,
        centre_mm: Point2::new(mouse.centroid_mm.x, mouse.centroid_mm.y),
        forward,
        joints_on_mask: on,
        joints: given,
        axis_deg,
    })
}

/// Replays `path` with the bundled models and with the adapted ones in `models`, and judges
/// both on the frames to judge.
fn judge_recording(
    path: &Path,
    options: &AdaptOptions,
    models: &Path,
    progress: &dyn Progress,
) -> Result<Judged, Failure> {
    let (recording, range) = open(path, options.judge, "judge on")?;
    let name = path
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "recording".to_owned());
    let runs = models.join("judge").join(name);
    let bundled = default_models_dir().ok();
    let mut runs_made: Vec<PathBuf> = Vec::new();
    for (label, dir) in [("bundled", bundled.clone()), ("adapted", Some(models.to_path_buf()))] {
        let Some(dir) = dir else { continue };
        let out = runs.join(label);
        progress.start(&format!("replay, {label}"), recording.depth_count() as u64);
        replay_with(
            &replay_options(path, options, out.clone(), Some(dir)),
            &Interrupt::default(),
            |done, total| {
                progress.set_total(total);
                progress.set_done(done);
            },
        )
        .map_err(|e| Failure::classed(e.is_usage(), e))?;
        progress.finish();
        runs_made.push(out);
    }
    let scene = scene_of(&replay_options(path, options, PathBuf::new(), None), &recording)
        .map_err(|e| Failure::classed(e.is_usage(), e))?;
    let (rig, mut segmenter) = (scene.rig, scene.segmenter);
    // Each run's rows read beside the frames, both in the recording's order: neither the
    // frames nor the runs' poses are ever all in memory, however long the recording.
    let mut rows = runs_made
        .iter()
        .map(|run| PosesRows::open(&run.join(POSES_FILE)).map(Iterator::peekable))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::from(anyhow::Error::new(e)))?;
    let mut judged: Vec<Vec<JudgedFrame>> = vec![Vec::new(); rows.len()];
    let mut unreadable = None;
    progress.start("judging", range.len() as u64);
    recording
        .for_each_depth_frame(range.clone(), |frame| {
            progress.advance(1);
            let seq = frame.stamp.seq;
            let mouse = segmenter.segment(&frame).ok().flatten();
            for (run, out) in rows.iter_mut().zip(judged.iter_mut()) {
                // The run's rows before this frame (frames outside those judged, or not paired).
                while run.next_if(|r| r.as_ref().is_ok_and(|r| r.depth.seq < seq)).is_some() {}
                let row = match run.next_if(|r| r.as_ref().map_or(true, |r| r.depth.seq == seq)) {
                    Some(Ok(row)) => row,
                    Some(Err(e)) => {
                        unreadable.get_or_insert(e);
                        continue;
                    }
                    None => continue,
                };
                if let Some(j) = mouse.as_ref().and_then(|m| judged_frame(&row, m, &rig)) {
                    out.push(j);
                }
            }
        })
        .with_context(|| format!("reading frames of {:?}", recording.dir()))?;
    progress.finish();
    if let Some(e) = unreadable {
        return Err(Failure::from(anyhow::Error::new(e)));
    }
    let mut figures = judged.iter().map(|f| unlabelled(f));
    let mut dirs = runs_made.into_iter();
    let (bundled_figures, bundled_run) = if bundled.is_some() {
        (figures.next(), dirs.next())
    } else {
        (None, None)
    };
    Ok(Judged {
        recording: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_owned()),
        frames: range,
        bundled: bundled_figures,
        adapted: figures.next().unwrap_or_default(),
        bundled_run,
        adapted_run: dirs.next().unwrap_or_default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ranges_read_as_pythons_slices_and_are_clamped_to_the_recording() {
        let r: FrameRange = "0:450".parse().unwrap_or_default();
        assert_eq!(r.within(900), 0..450);
        let r: FrameRange = "450:".parse().unwrap_or_default();
        assert_eq!(r.within(900), 450..900);
        assert_eq!(r.within(300), 300..300);
        assert!("5:5".parse::<FrameRange>().is_err());
        assert!("five".parse::<FrameRange>().is_err());
    }
}
