//! The engine of `mousepose experiment gauss2d`: the paper's running example.

use crate::engine::chart::line_chart;
use crate::engine::progress::Progress;
use crate::engine::{Failure, report_dir, write_report_file};
use crate::experiment::gauss2d::{self, Setup};
use crate::vision::forest::discriminative::{DiscriminativeParams, Scoring};
use crate::vision::forest::{Forest, TrainParams};
use anyhow::Result;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;

/// What `experiment gauss2d` runs (see its `--help`).
#[derive(Clone, Debug)]
pub struct Gauss2dOptions {
    /// A tenth of the data and shorter sweeps.
    pub quick: bool,
    /// Seed of the Gaussians and all draws.
    pub seed: u64,
    /// Write tables and PNG plots of the sweeps into this directory.
    pub report: Option<PathBuf>,
}

/// One point of a sweep.
#[derive(Clone, Debug, Serialize)]
pub struct SweepPoint {
    pub value: f64,
    pub baseline_accuracy: f64,
    pub discriminative_accuracy: f64,
}

/// What `experiment gauss2d --json` prints.
#[derive(Clone, Debug, Serialize)]
pub struct Gauss2dReport {
    pub setup: Setup,
    pub bayes_accuracy: f64,
    pub baseline_accuracy: f64,
    pub union_baseline_accuracy: f64,
    pub discriminative_gain_accuracy: f64,
    pub discriminative_accuracy: f64,
    /// Ours: the node's current test kept among the candidates, winning ties.
    pub discriminative_keep_current_accuracy: f64,
    pub paper: PaperFigures,
    pub sweeps: std::collections::BTreeMap<String, Vec<SweepPoint>>,
}

/// The paper's figures, beside ours.
#[derive(Clone, Debug, Serialize)]
pub struct PaperFigures {
    pub baseline_accuracy: f64,
    pub union_baseline_accuracy: f64,
    pub discriminative_gain_accuracy: f64,
    pub discriminative_accuracy: f64,
}

const PAPER: PaperFigures = PaperFigures {
    baseline_accuracy: 0.794,
    union_baseline_accuracy: 0.796,
    discriminative_gain_accuracy: 0.804,
    discriminative_accuracy: 0.812,
};

/// `mousepose experiment gauss2d`: the figures, and the tables and plots in `options.report`;
/// `progress` follows the forests trained.
///
/// # Errors
/// The report cannot be written.
pub fn gauss2d(options: &Gauss2dOptions, progress: &dyn Progress) -> Result<Gauss2dReport, Failure> {
    Ok(run_gauss2d(options, progress)?)
}

fn run_gauss2d(options: &Gauss2dOptions, progress: &dyn Progress) -> Result<Gauss2dReport> {
    let setup = Setup::new(options.quick, options.seed);
    let steps = if options.quick { 30 } else { 40 };
    progress.start("gauss2d", steps);
    let blobs = gauss2d::blobs(setup.seed);
    let data = Sets {
        t: gauss2d::sample(&blobs, setup.points, setup.seed, 0),
        d: gauss2d::sample(&blobs, setup.points, setup.seed, 1),
        e: gauss2d::sample(&blobs, setup.points, setup.seed, 2),
    };
    let forests = Compared::train(&setup, &data, progress);
    let base_acc = data.accuracy(&forests.base);
    let disc_params = setup.discriminative_params(Scoring::SubtreeError);
    let mut sweeps = std::collections::BTreeMap::new();
    sweeps.insert(
        "forest_size".to_owned(),
        forest_size_sweep(options.quick, &setup, &data, progress),
    );
    parameter_sweeps(
        options.quick,
        &setup,
        &forests.base,
        base_acc,
        &data,
        progress,
        &mut sweeps,
    );
    sweeps.insert(
        "iterations".to_owned(),
        iterations_sweep(options.quick, &forests.base, base_acc, &disc_params, &data, progress),
    );
    progress.finish();

    let report = Gauss2dReport {
        setup,
        bayes_accuracy: gauss2d::bayes_accuracy(&blobs, &data.e),
        baseline_accuracy: base_acc,
        union_baseline_accuracy: data.accuracy(&forests.union),
        discriminative_gain_accuracy: data.accuracy(&forests.disc_gain),
        discriminative_accuracy: data.accuracy(&forests.disc),
        discriminative_keep_current_accuracy: data.accuracy(&forests.disc_keep),
        paper: PAPER,
        sweeps,
    };
    if let Some(dir) = &options.report {
        write_gauss2d_report(dir, &report)?;
    }
    Ok(report)
}

/// The three sets of points: D_t to train, D_d to refine, D_e to evaluate.
struct Sets {
    t: gauss2d::Points,
    d: gauss2d::Points,
    e: gauss2d::Points,
}

impl Sets {
    /// A forest's accuracy on D_e.
    fn accuracy(&self, forest: &gauss2d::AxisForest) -> f64 {
        gauss2d::accuracy(forest, &self.e)
    }
}

/// The forests the paper's table compares.
struct Compared {
    base: gauss2d::AxisForest,
    union: gauss2d::AxisForest,
    disc_gain: gauss2d::AxisForest,
    disc: gauss2d::AxisForest,
    disc_keep: gauss2d::AxisForest,
}

impl Compared {
    /// Trains them, one step of `progress` each.
    fn train(setup: &Setup, data: &Sets, progress: &dyn Progress) -> Self {
        let base = gauss2d::baseline(&data.t, &setup.train_params());
        progress.advance(1);
        let mut union_params = setup.train_params();
        union_params.min_leaf *= 2;
        let union = gauss2d::baseline(&data.t.union(&data.d), &union_params);
        progress.advance(1);
        let (disc_gain, _) = gauss2d::discriminative(&base, &data.d, &setup.discriminative_params(Scoring::Gain));
        progress.advance(1);
        let disc_params = setup.discriminative_params(Scoring::SubtreeError);
        let (disc, _) = gauss2d::discriminative(&base, &data.d, &disc_params);
        progress.advance(1);
        let keep_current = DiscriminativeParams {
            keep_current: true,
            ..disc_params
        };
        let (disc_keep, _) = gauss2d::discriminative(&base, &data.d, &keep_current);
        progress.advance(1);
        Self {
            base,
            union,
            disc_gain,
            disc,
            disc_keep,
        }
    }
}

/// Forest size: trees are independent, so a k-tree forest is the first k of a larger one.
fn forest_size_sweep(quick: bool, setup: &Setup, data: &Sets, progress: &dyn Progress) -> Vec<SweepPoint> {
    let sizes: Vec<usize> = if quick {
        vec![1, 3, 5, 9]
    } else {
        vec![1, 3, 5, 7, 9, 13, 17]
    };
    let max_trees = sizes.iter().copied().max().unwrap_or(5);
    let big = gauss2d::baseline(
        &data.t,
        &TrainParams {
            trees: max_trees,
            ..setup.train_params()
        },
    );
    let disc_params = setup.discriminative_params(Scoring::SubtreeError);
    let (big_disc, _) = gauss2d::discriminative(&big, &data.d, &disc_params);
    let first = |f: &gauss2d::AxisForest, k: usize| Forest {
        trees: f.trees[..k].to_vec(),
    };
    sizes
        .iter()
        .map(|&k| {
            progress.advance(1);
            SweepPoint {
                value: k as f64,
                baseline_accuracy: data.accuracy(&first(&big, k)),
                discriminative_accuracy: data.accuracy(&first(&big_disc, k)),
            }
        })
        .collect()
}

/// The sweeps of one discriminative parameter each (m, l_n, the start level, the subset),
/// the baseline `base` refined with each value.
fn parameter_sweeps(
    quick: bool,
    setup: &Setup,
    base: &gauss2d::AxisForest,
    base_acc: f64,
    data: &Sets,
    progress: &dyn Progress,
    sweeps: &mut std::collections::BTreeMap<String, Vec<SweepPoint>>,
) {
    let disc_params = setup.discriminative_params(Scoring::SubtreeError);
    let mut sweep = |name: &str, values: &[f64], set: &dyn Fn(&mut DiscriminativeParams, f64)| {
        let points = values
            .iter()
            .map(|&v| {
                let mut p = disc_params;
                set(&mut p, v);
                let (f, _) = gauss2d::discriminative(base, &data.d, &p);
                progress.advance(1);
                SweepPoint {
                    value: v,
                    baseline_accuracy: base_acc,
                    discriminative_accuracy: data.accuracy(&f),
                }
            })
            .collect();
        sweeps.insert(name.to_owned(), points);
    };
    let ms: &[f64] = if quick {
        &[10.0, 50.0, 200.0, 640.0]
    } else {
        &[10.0, 20.0, 50.0, 100.0, 200.0, 320.0, 640.0]
    };
    sweep("m", ms, &|p, v| p.tests = v as usize);
    let lns: &[f64] = if quick {
        &[10.0, 60.0, 1000.0, 10000.0]
    } else {
        &[10.0, 30.0, 60.0, 250.0, 1000.0, 2500.0, 10000.0]
    };
    sweep("l_n", lns, &|p, v| p.min_leaf = v as usize);
    let levels: &[f64] = if quick {
        &[0.0, 4.0, 8.0, 12.0]
    } else {
        &[0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]
    };
    sweep("start_level", levels, &|p, v| p.start_level = v as u32);
    sweep("subset", &[0.25, 0.5, 1.0], &|p, v| p.subset = v);
}

/// Iterations: each pass refines the previous pass's forest with a fresh subset.
fn iterations_sweep(
    quick: bool,
    base: &gauss2d::AxisForest,
    base_acc: f64,
    disc_params: &DiscriminativeParams,
    data: &Sets,
    progress: &dyn Progress,
) -> Vec<SweepPoint> {
    let iterations = if quick { 3 } else { 5 };
    let mut forest = base.clone();
    let mut points = vec![SweepPoint {
        value: 0.0,
        baseline_accuracy: base_acc,
        discriminative_accuracy: base_acc,
    }];
    for it in 0..iterations {
        forest = gauss2d::discriminative_from(
            &forest,
            &data.d,
            &DiscriminativeParams {
                iterations: 1,
                ..*disc_params
            },
            it,
        )
        .0;
        progress.advance(1);
        points.push(SweepPoint {
            value: (it + 1) as f64,
            baseline_accuracy: base_acc,
            discriminative_accuracy: data.accuracy(&forest),
        });
    }
    points
}

/// Writes `gauss2d.json`, `gauss2d.txt` and a plot per sweep into `dir`.
fn write_gauss2d_report(dir: &std::path::Path, report: &Gauss2dReport) -> Result<()> {
    report_dir(dir)?;
    write_report_file(dir, "gauss2d.json", serde_json::to_string_pretty(report)?.as_bytes())?;
    write_report_file(dir, "gauss2d.txt", gauss2d_tables(report).as_bytes())?;
    for (name, points) in &report.sweeps {
        let x: Vec<f64> = points.iter().map(|p| p.value).collect();
        let b: Vec<f64> = points.iter().map(|p| p.baseline_accuracy).collect();
        let d: Vec<f64> = points.iter().map(|p| p.discriminative_accuracy).collect();
        let bayes = vec![report.bayes_accuracy; x.len()];
        line_chart(
            &format!("gauss2d: accuracy vs {name}"),
            name,
            "accuracy",
            &x,
            &[
                ("baseline", [120, 120, 120], &b),
                ("discriminative", [40, 90, 220], &d),
                ("Bayes-optimal", [40, 160, 60], &bayes),
            ],
        )
        .write_png(&dir.join(format!("sweep_{name}.png")))?;
    }
    Ok(())
}

/// The tables `experiment gauss2d` prints (and writes to `gauss2d.txt`).
pub fn gauss2d_tables(r: &Gauss2dReport) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "gauss2d: {} points per set, {} trees, L = {}, m = {}, l_n = {}, each tree's D'_d {} x |D_d| \
         drawn with replacement, seed {}",
        r.setup.points, r.setup.trees, r.setup.max_depth, r.setup.tests, r.setup.min_leaf, r.setup.subset, r.setup.seed
    );
    let _ = writeln!(t, "{:<44} {:>8} {:>8}", "forest", "ours", "paper");
    let rows = [
        ("baseline on D_t", r.baseline_accuracy, r.paper.baseline_accuracy),
        (
            "baseline on D_t u D_d, l_n doubled",
            r.union_baseline_accuracy,
            r.paper.union_baseline_accuracy,
        ),
        (
            "discriminative, nodes scored by gain I",
            r.discriminative_gain_accuracy,
            r.paper.discriminative_gain_accuracy,
        ),
        (
            "discriminative, subtrees scored by E",
            r.discriminative_accuracy,
            r.paper.discriminative_accuracy,
        ),
    ];
    for (name, ours, paper) in rows {
        let _ = writeln!(t, "{name:<44} {ours:>8.4} {paper:>8.3}");
    }
    let _ = writeln!(
        t,
        "{:<44} {:>8.4} {:>8}",
        "the same, current test kept (ours)", r.discriminative_keep_current_accuracy, "-"
    );
    let _ = writeln!(
        t,
        "{:<44} {:>8.4} {:>8}",
        "Bayes-optimal (true densities)", r.bayes_accuracy, "-"
    );
    for (name, points) in &r.sweeps {
        let _ = writeln!(
            t,
            "\nsweep {name}\n{:>10} {:>10} {:>15} {:>8}",
            name, "baseline", "discriminative", "Bayes"
        );
        for p in points {
            let _ = writeln!(
                t,
                "{:>10} {:>10.4} {:>15.4} {:>8.4}",
                p.value, p.baseline_accuracy, p.discriminative_accuracy, r.bayes_accuracy
            );
        }
    }
    t
}
