//! `mousepose bench`: the speed of mousepose's parts on this machine; the work is
//! [`crate::engine::bench`].

use crate::app::Outcome;
use crate::app::output::{print, print_json};
use crate::engine::bench::{BenchOptions, BenchReport, bench};
use std::fmt::Write as _;

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// A short run (a few seconds) instead of the full measurement.
    #[arg(long)]
    quick: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// `mousepose bench`.
pub fn command(args: &BenchArgs) -> Outcome {
    let report = bench(&BenchOptions { quick: args.quick });
    if args.json {
        return Ok(print_json(&report)?);
    }
    Ok(print(&table(&report))?)
}

/// What `bench` prints without `--json`: a table of the measures.
fn table(report: &BenchReport) -> String {
    let mut s = String::new();
    let rows = [
        (
            "render depth images/s, 1 core",
            report.render_depth_images_per_s_one_core,
        ),
        ("render depth images/s, all cores", report.render_depth_images_per_s),
        ("mean rendered region, pixels", report.mean_region_px),
        ("dataset samples/s with bottom views", report.dataset_samples_per_s),
        ("training pixel-trees/s, all cores", report.train_pixel_trees_per_s),
        ("segment one depth frame, ms", report.segment_ms_per_frame),
    ];
    let _ = writeln!(
        s,
        "{:<40} {:>12}",
        format!("measure ({} threads)", report.threads),
        "value"
    );
    for (name, v) in rows {
        let digits = if v.abs() < 10.0 { 3 } else { 1 };
        let _ = writeln!(s, "{name:<40} {v:>12.digits$}");
    }
    match &report.forest {
        Some(f) => {
            let _ = writeln!(
                s,
                "{:<40} {:>12.1}",
                format!("mouse pixels per frame ({} trees)", f.trees),
                f.pixels_per_frame
            );
            let _ = writeln!(
                s,
                "{:<40} {:>12.3}",
                format!("forest traversal ms/frame, 1 core, {}", f.kernel),
                f.traverse_ms_per_frame
            );
            let _ = writeln!(
                s,
                "{:<40} {:>12.3}",
                "forest traversal ms/frame, portable", f.traverse_portable_ms_per_frame
            );
            let _ = writeln!(
                s,
                "{:<40} {:>12.3}",
                "body estimate ms/frame, 1 core", f.estimate_ms_per_frame
            );
        }
        None => {
            let _ = writeln!(s, "(no bundled body model found: forest inference not measured)");
        }
    }
    if let Some(p) = &report.paws {
        let _ = writeln!(
            s,
            "{:<40} {:>12.3}",
            format!(
                "paw detection ms/frame ({}x{} px)",
                p.roi_px[2] - p.roi_px[0],
                p.roi_px[3] - p.roi_px[1]
            ),
            p.detect_ms_per_frame
        );
    }
    if let Some(p) = &report.pipeline {
        let rows = [
            ("replay pairs/s (all stages, all cores)", p.replay_pairs_per_s),
            ("paced 30 fps latency p50, ms", p.paced_latency_p50_ms),
            ("paced 30 fps latency p99, ms", p.paced_latency_p99_ms),
            ("recording, cores used at 30 fps", p.record_cores),
        ];
        for (name, v) in rows {
            let _ = writeln!(s, "{name:<40} {v:>12.3}");
        }
    }
    s
}
