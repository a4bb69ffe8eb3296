//! `mousepose bench`: measures the speed of mousepose's parts on this machine. Speed figures
//! come from here, never from timed tests.

use crate::geometry::Rig;
use crate::synth::dataset::{DatasetSpec, encode_sample, render_sample};
use crate::synth::mouse::pose_library;
use crate::synth::noise::{DepthNoise, NoiseModel};
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
        ];
        let _ = writeln!(
            s,
            "{:<40} {:>12}",
            format!("measure ({} threads)", self.threads),
            "value"
        );
        for (name, v) in rows {
            let _ = writeln!(s, "{name:<40} {v:>12.1}");
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
    BenchReport {
        threads: rayon::current_num_threads(),
        render_depth_images_per_s_one_core: one,
        render_depth_images_per_s: all,
        mean_region_px: pixels as f64 / (n / 2).max(1) as f64,
        dataset_samples_per_s: samples,
    }
}
