//! `mousepose bench`: measures the speed of mousepose's parts on this machine. Speed figures
//! come from here, never from timed tests.

use crate::frame::{DepthFrame, Stamp};
use crate::geometry::Rig;
use crate::segment::{Background, SegmentError, SegmenterConfig};
use crate::synth::body::skin;
use crate::synth::dataset::{DatasetSpec, encode_sample, render_sample};
use crate::synth::mouse::{fit_in_cage, pose_library, pose_mouse};
use crate::synth::noise::{DepthNoise, NoiseModel, quantise};
use crate::synth::render::{Cage, Region, Scene};
use crate::synth::{item_rng, random_placement};
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
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
}

impl BenchReport {
    /// A human-readable table.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let rows = [
            ("render depth images/s, 1 core", self.render_depth_images_per_s_one_core),
            ("render depth images/s, all cores", self.render_depth_images_per_s),
            ("mean rendered region, pixels", self.mean_region_px),
            ("dataset samples/s with bottom views", self.dataset_samples_per_s),
            ("segment one depth frame, ms", self.segment_ms_per_frame),
        ];
        let _ = writeln!(
            s,
            "{:<40} {:>12}",
            format!("measure ({} threads)", self.threads),
            "value"
        );
        for (name, v) in rows {
            let digits = if v.abs() < 10.0 { 3 } else { 1 };
            let _ = writeln!(s, "{name:<40} {v:>12.digits$}");
        }
        s
    }
}

fn rate(n: u64, f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    n as f64 / t.elapsed().as_secs_f64().max(1e-9)
}

/// Runs the benchmarks; `quick` takes a few seconds instead of about a minute.
pub fn run(quick: bool) -> BenchReport {
    let rig = Rig::default_rig();
    let library = pose_library();
    let n: u64 = if quick { 400 } else { 6000 };
    let spec = DatasetSpec {
        count: n,
        seed: 0xBE7C,
        noise: DepthNoise {
            model: NoiseModel::StructuredLight,
            gaussian_mm: 0.0,
        },
        bottom_views: false,
    };
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
    let segment_ms_per_frame = segment_ms(&rig, if quick { 300 } else { 3000 }).unwrap_or_else(|e| {
        tracing::warn!(error = %e, "cannot measure the segmenter");
        f64::NAN
    });
    BenchReport {
        threads: rayon::current_num_threads(),
        render_depth_images_per_s_one_core: one,
        render_depth_images_per_s: all,
        mean_region_px: pixels as f64 / (n / 2).max(1) as f64,
        dataset_samples_per_s: samples,
        segment_ms_per_frame,
    }
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
    let scene = Scene::new(&rig.depth, &skin(&mouse));
    let region = scene.bounds.grown(2, i.width, i.height);
    let hits = scene.cast(region);
    let background = Cage::new(&rig.depth).depth(full);
    let mut depth = background.clone();
    for y in 0..region.height {
        for x in 0..region.width {
            let z = hits.z[(y * region.width + x) as usize];
            if z.is_finite() {
                depth[((region.y0 + y) * i.width + region.x0 + x) as usize] = z;
            }
        }
    }
    let noise = DepthNoise {
        model: NoiseModel::StructuredLight,
        gaussian_mm: 0.0,
    };
    noise.apply(&mut depth, full, i, &mut rng);
    let frame = DepthFrame {
        stamp: Stamp::default(),
        width: i.width,
        height: i.height,
        data: quantise(&depth),
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
