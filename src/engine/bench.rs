//! The benchmark (`mousepose bench`): measures the speed of mousepose's parts on this machine. Speed figures
//! come from here, never from timed tests.

use crate::core::frame::{DepthFrame, Stamp};
use crate::core::geometry::Rig;
use crate::core::image::Region;
use crate::core::noise::DepthNoise;
use crate::core::noise::NoiseModel;
use crate::core::rng::item_rng;
use crate::synth::body::skin;
use crate::synth::dataset::{DatasetSpec, encode_sample, render_sample};
use crate::synth::mouse::{fit_in_cage, pose_library, pose_mouse};
use crate::synth::random_placement;
use crate::synth::render::Cage;
use crate::synth::views::render_top_frame;
use crate::vision::segment::{Background, SegmentError, SegmenterConfig};
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// What `bench` measured.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Worker threads available (the machine's cores).
    pub threads: usize,
    /// Top depth images rendered per second on one core: pose, skin, ray casting of the
    /// mouse's region, cage background and structured-light noise.
    pub render_depth_images_per_s_one_core: f64,
    /// The same on all cores.
    pub render_depth_images_per_s: f64,
    /// Mean number of pixels of the rendered regions.
    pub mean_region_px: f64,
    /// Dataset samples with bottom views per second on all cores, encoded and compressed.
    pub dataset_samples_per_s: f64,
    /// Milliseconds to segment one 640x480 depth frame with a mouse (structured-light noise),
    /// on one core: the mean over the fastest of ten batches; NaN when the segmenter could not
    /// be set up.
    pub segment_ms_per_frame: f64,
    /// Body forest training throughput on all cores: training pixels times trees per second.
    pub train_pixel_trees_per_s: f64,
    /// Body forest inference with the bundled model (when present), one core.
    pub forest: Option<ForestBench>,
    /// The replay pipeline and the recorder on a synthetic session (with the bundled models).
    pub pipeline: Option<PipelineBench>,
    /// The bundled paw cascade on a full bottom frame; `None` without the model.
    pub paws: Option<PawBench>,
}

/// The pipeline end to end.
#[derive(Clone, Debug, Serialize)]
pub struct PipelineBench {
    /// Length of the synthetic session (30 fps, full-size 640x480 depth and 1280x1024 Bayer
    /// colour frames).
    pub session_seconds: f64,
    /// `replay` as fast as possible, all stages, default workers: the median of three runs.
    pub replay_pairs_per_s: f64,
    /// `replay --realtime` (paced at the recorded 30 fps): from a pair leaving the
    /// synchroniser to its row written.
    pub paced_latency_p50_ms: f64,
    pub paced_latency_p99_ms: f64,
    /// Writing the session's frames as the recorder does (zstd, checksums, timestamps): CPU
    /// seconds per second of footage (1.0 = one core busy).
    pub record_cores: f64,
}

/// Speed of the bundled paw detector on one core.
#[derive(Clone, Debug, Serialize)]
pub struct PawBench {
    pub model: String,
    /// The region searched: the mouse's joints projected on the glass, grown by 15 mm, in
    /// pixels of the full 1280x1024 BayerRG8 frame.
    pub roi_px: [u32; 4],
    /// The glass's scale in that frame.
    pub px_per_mm: f64,
    /// `PawModel::detect` on the region (a cascade: grey conversion, every scale, grouping;
    /// a network: grey conversion, the network, the heatmap's peaks), ms.
    pub detect_ms_per_frame: f64,
    pub detections: usize,
}

/// Speed of the bundled body forest on one core.
#[derive(Clone, Debug, Serialize)]
pub struct ForestBench {
    pub model: String,
    pub trees: usize,
    /// Mouse pixels per frame in the measurement.
    pub pixels_per_frame: f64,
    /// The traversal kernel in use on this processor (`avx2` or `portable`).
    pub kernel: String,
    /// All of a frame's mouse pixels through every tree to a leaf, ms, with that kernel...
    pub traverse_ms_per_frame: f64,
    /// ...and with the portable one.
    pub traverse_portable_ms_per_frame: f64,
    /// The run-time estimate (sampled pixels, votes, aggregation), ms.
    pub estimate_ms_per_frame: f64,
}

fn rate(n: u64, f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    n as f64 / t.elapsed().as_secs_f64().max(1e-9)
}

/// `count` standard mice seen from above only, structured-light noise without Gaussian noise:
/// what every benchmark here renders.
fn clean_top_views(count: u64, seed: u64) -> DatasetSpec {
    DatasetSpec {
        count,
        seed,
        noise: DepthNoise {
            model: NoiseModel::StructuredLight,
            gaussian_mm: 0.0,
        },
        bottom_views: false,
        bottom_clutter: false,
        mice: crate::synth::Mice::Standard,
        build: None,
    }
}

/// What `bench` measures.
#[derive(Clone, Copy, Debug, Default)]
pub struct BenchOptions {
    /// A few seconds instead of about a minute.
    pub quick: bool,
}

/// `mousepose bench`: runs the benchmarks.
pub fn bench(options: &BenchOptions) -> BenchReport {
    let quick = options.quick;
    let rig = Rig::default_rig();
    let library = pose_library();
    let n: u64 = if quick { 400 } else { 6000 };
    let spec = clean_top_views(n, 0xBE7C);
    // Warm up caches and the thread pool.
    (0..32)
        .into_par_iter()
        .for_each(|i| drop(render_sample(&rig, &spec, &library, i)));
    let mut pixels = 0usize;
    let one = rate(n / 2, || {
        for i in 0..n / 2 {
            pixels += render_sample(&rig, &spec, &library, i).top.region.len();
        }
    });
    let all = rate(n, || {
        (0..n)
            .into_par_iter()
            .for_each(|i| drop(render_sample(&rig, &spec, &library, i)));
    });
    let with_bottom = DatasetSpec {
        bottom_views: true,
        ..spec
    };
    let m = n / 4;
    let samples = rate(m, || {
        (0..m)
            .into_par_iter()
            .for_each(|i| drop(encode_sample(&render_sample(&rig, &with_bottom, &library, i))));
    });
    let train_pixel_trees_per_s = bench_training(&rig, &library, quick);
    let forest = bench_forest(&rig, &library, quick);
    let segment_ms_per_frame = segment_ms(&rig, if quick { 300 } else { 3000 }).unwrap_or_else(|e| {
        tracing::warn!(error = %e, "cannot measure the segmenter");
        f64::NAN
    });
    let pipeline = bench_pipeline(quick)
        .map_err(|e| tracing::warn!(error = %e, "cannot measure the pipeline"))
        .ok();
    let paws = bench_paws(&rig, if quick { 50 } else { 500 });
    BenchReport {
        paws,
        train_pixel_trees_per_s,
        forest,
        pipeline,
        threads: rayon::current_num_threads(),
        render_depth_images_per_s_one_core: one,
        render_depth_images_per_s: all,
        mean_region_px: pixels as f64 / (n / 2).max(1) as f64,
        dataset_samples_per_s: samples,
        segment_ms_per_frame,
    }
}

/// Trains a small body forest on freshly rendered images and returns pixel-trees per second.
fn bench_training(rig: &Rig, library: &[crate::synth::mouse::PoseParams], quick: bool) -> f64 {
    use crate::training::{PixelParams, draw_pixels, joint_targets};
    use crate::vision::forest::TrainParams;
    use crate::vision::forest::depth::{DepthSpace, JointObjective};
    use crate::vision::forest::discriminative::ErrorScope;
    let images = if quick { 100 } else { 600 };
    let spec = clean_top_views(images, 0x7EA1);
    let samples: Vec<_> = (0..images)
        .into_par_iter()
        .map(|i| render_sample(rig, &spec, library, i))
        .collect();
    let pixels = PixelParams::default();
    let set = draw_pixels(&samples, &pixels);
    let targets = joint_targets(&set, &samples, rig);
    let params = TrainParams {
        trees: 2,
        ..TrainParams::default()
    };
    let all: Vec<u32> = (0..set.len() as u32).collect();
    let space = DepthSpace {
        pixels: &set,
        thresholds: pixels.thresholds,
    };
    let objective = JointObjective {
        targets: &targets,
        scope: ErrorScope::AllJoints,
    };
    rate((set.len() * params.trees) as u64, || {
        drop(crate::vision::forest::train::train_forest(
            &space,
            &objective,
            vec![all; params.trees],
            &params,
            [0.0; 2],
            &|| {},
        ));
    })
}

/// Where the bundled paw model is looked for: the checkout's fixtures
/// ([`crate::runtime::models::paws_file`]).
pub fn bundled_paw_model() -> Option<std::path::PathBuf> {
    crate::runtime::models::paws_file(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models"))
}

/// Times the paw detector on a full-size synthetic BayerRG8 bottom frame, within the mouse's
/// footprint on the glass grown by 15 mm; the fastest of ten batches.
fn bench_paws(rig: &Rig, iterations: u32) -> Option<PawBench> {
    use crate::core::frame::{ColorFrame, PixelFormat};
    use crate::synth::views::render_bottom_frame;
    use crate::vision::paws::PawModel;
    use nalgebra::Point3;
    let path = bundled_paw_model()?;
    let mut detector = match PawModel::load(&path) {
        Ok(d) => d,
        Err(e) => {
            tracing::warn!(error = %e, "cannot measure the paw detector");
            return None;
        }
    };
    let mut rng = item_rng(0xBE7C, 9, 0);
    let library = pose_library();
    let pose = library.get(library.len() / 2).copied().unwrap_or_default();
    let mut mouse = pose_mouse(&pose, &random_placement(&mut rng));
    fit_in_cage(&mut mouse, 3.0);
    let camera = &rig.color;
    let i = &camera.intrinsics;
    let (data, _) = render_bottom_frame(camera, &mouse, &skin(&mouse), PixelFormat::BayerRg8, &mut rng);
    let frame = ColorFrame {
        stamp: Stamp::default(),
        width: i.width,
        height: i.height,
        format: PixelFormat::BayerRg8,
        data,
    };
    // The joints' footprint on the glass, and the glass's scale there.
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut centre = Point3::origin();
    for p in &mouse.joints {
        let on_glass = Point3::new(p.x, p.y, 0.0);
        centre.coords += on_glass.coords / mouse.joints.len() as f64;
        if let Some(q) = camera.project_world(&on_glass) {
            lo = [lo[0].min(q.x), lo[1].min(q.y)];
            hi = [hi[0].max(q.x), hi[1].max(q.y)];
        }
    }
    let a = camera.project_world(&centre)?;
    let b = camera.project_world(&Point3::new(centre.x + 10.0, centre.y, 0.0))?;
    let px_per_mm = (b - a).norm() / 10.0;
    let grow = 15.0 * px_per_mm;
    let clamp = |v: f64, max: u32| v.clamp(0.0, f64::from(max)) as u32;
    let roi = (
        clamp(lo[0] - grow, i.width),
        clamp(lo[1] - grow, i.height),
        clamp(hi[0] + grow, i.width),
        clamp(hi[1] + grow, i.height),
    );
    let mut out = Vec::new();
    for _ in 0..20 {
        detector.detect(&frame, roi, px_per_mm, &mut out);
    }
    let batch = (iterations / 10).max(1);
    let mut best = f64::INFINITY;
    for _ in 0..10 {
        let t = Instant::now();
        for _ in 0..batch {
            detector.detect(&frame, roi, px_per_mm, &mut out);
            std::hint::black_box(&out);
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e3 / f64::from(batch));
    }
    Some(PawBench {
        model: path.display().to_string(),
        roi_px: [roi.0, roi.1, roi.2, roi.3],
        px_per_mm,
        detect_ms_per_frame: best,
        detections: out.len(),
    })
}

/// Where the bundled body model is looked for: the checkout's fixtures.
pub fn bundled_body_model() -> Option<std::path::PathBuf> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models/body.forest");
    path.exists().then_some(path)
}

fn bench_forest(rig: &Rig, library: &[crate::synth::mouse::PoseParams], quick: bool) -> Option<ForestBench> {
    use crate::vision::forest::infer::{BodyEstimator, Pixel, VoteSettings, sample_pixels};
    use crate::vision::forest::model::{Model, ModelKind, load};
    use crate::vision::forest::simd::Kernel;
    let path = bundled_body_model()?;
    let Ok(Model::Body(_, forest)) = load(&path, Some(ModelKind::Body)) else {
        return None;
    };
    let spec = clean_top_views(50, 0xB0D1);
    let frames: Vec<_> = (0..50)
        .map(|i| {
            let s = render_sample(rig, &spec, library, i);
            crate::training::depth_image(&s)
        })
        .collect();
    let trees = forest.trees.len();
    let mut estimator = BodyEstimator::new(forest, VoteSettings::default()).ok()?;
    let all: Vec<Vec<Pixel>> = frames
        .iter()
        .map(|f| {
            let mut p = Vec::new();
            sample_pixels(f, usize::MAX, &mut p);
            p
        })
        .collect();
    // Each round runs every frame; the fastest round counts (the others met other work).
    let rounds = if quick { 3 } else { 10 };
    let mut sink = 0usize;
    let per_frame = |start: Instant| start.elapsed().as_secs_f64() * 1000.0 / frames.len() as f64;
    let kernel = estimator.kernel();
    let mut traverse = |estimator: &mut BodyEstimator| {
        let mut best = f64::INFINITY;
        for _ in 0..rounds {
            let start = Instant::now();
            for (f, pixels) in frames.iter().zip(&all) {
                estimator.leaves(f, pixels, |leaves| {
                    sink = sink.wrapping_add(leaves.iter().map(|&l| l as usize).sum::<usize>());
                });
            }
            best = best.min(per_frame(start));
        }
        best
    };
    estimator.set_kernel(Kernel::Portable);
    let traverse_portable_ms = traverse(&mut estimator);
    estimator.set_kernel(kernel);
    let traverse_ms = traverse(&mut estimator);
    let mut buffer = Vec::new();
    let mut estimate_ms = f64::INFINITY;
    for _ in 0..rounds {
        let start = Instant::now();
        for f in &frames {
            sample_pixels(f, crate::training::VOTE_BUDGET, &mut buffer);
            let guesses = estimator.estimate(f, &buffer, &rig.depth.intrinsics);
            sink = sink.wrapping_add(guesses.iter().flatten().count());
        }
        estimate_ms = estimate_ms.min(per_frame(start));
    }
    std::hint::black_box(sink);
    Some(ForestBench {
        model: path.display().to_string(),
        trees,
        pixels_per_frame: all.iter().map(Vec::len).sum::<usize>() as f64 / all.len() as f64,
        kernel: format!("{kernel:?}").to_lowercase(),
        traverse_ms_per_frame: traverse_ms,
        traverse_portable_ms_per_frame: traverse_portable_ms,
        estimate_ms_per_frame: estimate_ms,
    })
}

/// Mean time (ms) to segment one full depth frame: the cage with a mouse in it and
/// structured-light noise, against the noiseless cage as background.
fn segment_ms(rig: &Rig, iterations: u32) -> Result<f64, SegmentError> {
    let i = &rig.depth.intrinsics;
    let full = Region::full(i);
    let mut rng = item_rng(0xBE7C, 7, 0);
    let library = pose_library();
    let pose = library.get(library.len() / 3).copied().unwrap_or_default();
    let mut mouse = pose_mouse(&pose, &random_placement(&mut rng));
    fit_in_cage(&mut mouse, 3.0);
    let background = Cage::new(&rig.depth).depth(full);
    let noise = DepthNoise {
        model: NoiseModel::StructuredLight,
        gaussian_mm: 0.0,
    };
    let frame = DepthFrame {
        stamp: Stamp::default(),
        width: i.width,
        height: i.height,
        data: render_top_frame(&rig.depth, &background, &skin(&mouse), &noise, &mut rng),
    };
    let config = SegmenterConfig::default();
    let mut segmenter = config
        .build(Background::from_depth(&background, full, i, &config)?)?
        .with_world(rig.depth.world_from_camera);
    for _ in 0..20 {
        std::hint::black_box(segmenter.segment(&frame)?);
    }
    // The fastest of ten batches: other work on the machine should not count.
    let batch = (iterations / 10).max(1);
    let mut best = f64::INFINITY;
    for _ in 0..10 {
        let t = Instant::now();
        for _ in 0..batch {
            std::hint::black_box(segmenter.segment(std::hint::black_box(&frame))?);
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e3 / f64::from(batch));
    }
    Ok(best)
}

/// Replays a synthetic session fast and paced, and rewrites its frames as the recorder does.
fn bench_pipeline(quick: bool) -> Result<PipelineBench, Box<dyn std::error::Error>> {
    use crate::engine::replay::{ReplayOptions, replay};
    use crate::io::session::{SessionReader, SessionWriter};
    use crate::synth::session::{SessionSpec, write_session};
    let root = std::env::temp_dir().join(format!(".mousepose-bench-{}", std::process::id()));
    let _cleanup = RemoveOnDrop(root.clone());
    let session = root.join("session");
    std::fs::create_dir_all(&session)?;
    let seconds = if quick { 3.0 } else { 10.0 };
    let spec = SessionSpec {
        seconds,
        seed: 0xBE7C,
        ..SessionSpec::default()
    };
    write_session(&session, &spec, |_, _| {})?;
    let options = |out: &str, realtime: bool| ReplayOptions {
        stream: None,
        lsl: None,
        lead_ns: None,
        partner_wait: None,
        mice: 1,
        session: session.clone(),
        out: root.join(out),
        models: None,
        realtime,
        workers: 0,
        overlays: None,
        calibration: None,
        intrinsics: None,
        roi: None,
        force: true,
    };
    // The median of three fast replays: one replay lasts about a second, and a shared
    // machine's speed can change by a third from one minute to the next.
    let mut fast = (0..if quick { 1 } else { 3 })
        .map(|_| replay(&options("fast", false)).map(|s| s.throughput_pairs_per_s))
        .collect::<Result<Vec<_>, _>>()?;
    fast.sort_by(f64::total_cmp);
    let paced = replay(&options("paced", true))?;
    // The recorder's work: every frame encoded, checksummed and written, on one thread.
    let reader = SessionReader::open(&session)?;
    let copy = root.join("copy");
    std::fs::create_dir_all(&copy)?;
    let depth: Vec<_> = reader.depth_frames().collect::<Result<_, _>>()?;
    let color: Vec<_> = reader.color_frames().into_iter().flatten().collect::<Result<_, _>>()?;
    let cpu0 = crate::runtime::usage::thread_cpu_s();
    let mut writer = SessionWriter::create(&copy, reader.meta())?;
    for (d, c) in depth.iter().zip(color.iter()) {
        writer.write_depth(d)?;
        writer.write_color(c)?;
    }
    writer.finish()?;
    let record_cores =
        (crate::runtime::usage::thread_cpu_s() - cpu0) / (depth.len().min(color.len()) as f64 / spec.fps);
    Ok(PipelineBench {
        session_seconds: seconds,
        replay_pairs_per_s: fast[fast.len() / 2],
        paced_latency_p50_ms: paced.end_to_end_latency.p50_ms,
        paced_latency_p99_ms: paced.end_to_end_latency.p99_ms,
        record_cores,
    })
}

/// Removes a scratch directory when dropped.
struct RemoveOnDrop(std::path::PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        // Best effort: a leftover scratch directory in the temporary directory is harmless.
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
