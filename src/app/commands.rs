//! The offline commands that train, evaluate and experiment: `train`, `eval` and
//! `experiment gauss2d`. Argument parsing is in [`crate::app`].

use crate::app::chart::{bar_chart, confusion_chart, line_chart};
use crate::app::progress;
use crate::app::{EvalArgs, Gauss2dArgs, ModelTarget, TrainArgs};
use crate::experiment::gauss2d::{self, Setup};
use crate::training::{self, PixelParams, Target, TrainJob, TrainProgress};
use crate::vision::forest::discriminative::{DiscriminativeParams, Scoring};
use crate::vision::forest::infer::{BodyEstimator, VoteSettings};
use crate::vision::forest::model::{self, Model, ModelKind};
use crate::vision::forest::{Forest, TrainParams};
use anyhow::{Context, Result, bail};
use indicatif::ProgressBar;
use serde::Serialize;
use std::fmt::Write as _;
use std::io::Write;
use std::path::Path;

/// Refused to overwrite a file; an argument problem (exit code 1).
#[derive(Debug, thiserror::Error)]
#[error("{0:?} exists (use --force to replace it)")]
pub struct Exists(pub std::path::PathBuf);

struct Bar(ProgressBar);

impl TrainProgress for Bar {
    fn stage(&self, what: &str, total: u64) {
        self.0.set_message(what.to_owned());
        self.0.set_length(total);
        self.0.set_position(0);
    }

    fn tick(&self) {
        self.0.inc(1);
    }
}

fn print(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())?;
    out.flush()?;
    Ok(())
}

fn print_json(value: &impl Serialize) -> Result<()> {
    print(&format!("{}\n", serde_json::to_string_pretty(value)?))
}

fn write_report_file(dir: &Path, name: &str, bytes: &[u8]) -> Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).with_context(|| format!("writing {path:?}"))
}

fn report_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating report directory {dir:?}"))
}

/// `mousepose train body|parts|paws`.
pub fn train(args: &TrainArgs) -> Result<()> {
    if args.out.exists() && !args.force {
        return Err(Exists(args.out.clone()).into());
    }
    if args.target == ModelTarget::Paws {
        return train_paws(args);
    }
    let params = TrainParams {
        trees: args.trees as usize,
        max_depth: args.depth,
        tests: args.tests as usize,
        min_leaf: args.leaf as usize,
        seed: args.seed,
    };
    let job = TrainJob {
        target: match args.target {
            ModelTarget::Body => Target::Body,
            ModelTarget::Parts | ModelTarget::Paws => Target::Parts,
        },
        train: &args.data,
        discriminative: args.discriminative.as_deref(),
        params,
        disc: DiscriminativeParams {
            tests: params.tests,
            min_leaf: params.min_leaf,
            start_level: args.start_level,
            iterations: args.iterations as usize,
            subset: args.subset,
            refit_leaves: args.refit_leaves,
            scoring: Scoring::SubtreeError,
            max_depth: params.max_depth,
            seed: args.seed ^ 0xD15C,
        },
        pixels: PixelParams {
            per_image: args.pixels as usize,
            thresholds: 12,
            seed: args.seed,
        },
        from: match &args.from {
            Some(path) => {
                let kind = match args.target {
                    ModelTarget::Body => ModelKind::Body,
                    ModelTarget::Parts | ModelTarget::Paws => ModelKind::Parts,
                };
                Some(model::load(path, Some(kind))?)
            }
            None => None,
        },
    };
    let bar = Bar(progress::bar(0, "loading"));
    let (model, passes) = training::train(&job, &bar).context("training")?;
    bar.0.finish_and_clear();
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    model::save(&model, &args.out)?;
    let info = model.info();
    let (trees, nodes, leaves) = match &model {
        Model::Body(_, f) => counts(f),
        Model::Parts(_, f) => counts(f),
    };
    let changed: usize = passes.iter().map(|p| p.tests_changed).sum();
    tracing::info!(
        message = "Model written.",
        path = %args.out.display(),
        kind = info.kind.name(),
        trees,
        nodes,
        leaves,
        seconds = format!("{:.0}", info.training_seconds),
        discriminative_tests_changed = changed,
    );
    Ok(())
}

fn counts<F, L>(f: &Forest<F, L>) -> (usize, usize, usize) {
    (
        f.trees.len(),
        f.trees.iter().map(|t| t.nodes.len()).sum(),
        f.trees.iter().map(|t| t.leaves.len()).sum(),
    )
}

/// `mousepose eval body|parts|paws`.
pub fn eval(args: &EvalArgs) -> Result<()> {
    let kind = match args.target {
        ModelTarget::Body => ModelKind::Body,
        ModelTarget::Parts => ModelKind::Parts,
        ModelTarget::Paws => return eval_paws(args),
    };
    let model = model::load(&args.model, Some(kind))?;
    let (ds, samples) = training::load(&args.data).with_context(|| format!("reading test dataset {:?}", args.data))?;
    if samples.is_empty() {
        bail!("test dataset {:?} has no images", args.data);
    }
    let rig = ds.meta.rig.unwrap_or_else(crate::core::geometry::Rig::default_rig);
    if let Some(train_seed) = model.info().data.iter().find(|d| d.seed == ds.meta.seed) {
        tracing::warn!(
            message = "The test dataset has the seed of a training dataset; its figures are not held-back figures.",
            seed = train_seed.seed,
        );
    }
    match model {
        Model::Body(_, forest) => eval_body(args, forest, &samples, &rig),
        Model::Parts(_, forest) => eval_parts(args, &forest, &samples),
    }
}

fn eval_body(
    args: &EvalArgs,
    forest: Forest<[f32; 2], crate::vision::forest::depth::JointLeaf>,
    samples: &[crate::synth::dataset::Sample],
    rig: &crate::core::geometry::Rig,
) -> Result<()> {
    let estimator = BodyEstimator::new(forest, VoteSettings::default());
    let report = training::eval_body(&estimator, samples, rig, 0.0)?;
    if let Some(dir) = &args.report {
        report_dir(dir)?;
        // In the paper's joint order, not the map's alphabetical one.
        let in_order = |r: &training::BodyReport| -> Vec<f64> {
            crate::core::skeleton::Joint::MAIN_BODY
                .iter()
                .map(|j| r.per_joint_mm.get(j.name()).copied().unwrap_or(f64::NAN))
                .collect()
        };
        let names: Vec<String> = crate::core::skeleton::Joint::MAIN_BODY
            .iter()
            .map(|j| j.name().to_owned())
            .collect();
        let ours = in_order(&report);
        let mut series = Vec::new();
        let baseline = match &args.baseline {
            Some(path) => match model::load(path, Some(ModelKind::Body))? {
                Model::Body(_, f) => Some(training::eval_body(
                    &BodyEstimator::new(f, VoteSettings::default()),
                    samples,
                    rig,
                    0.0,
                )?),
                Model::Parts(..) => None,
            },
            None => None,
        };
        let base_values: Vec<f64> = baseline.as_ref().map(in_order).unwrap_or_default();
        if baseline.is_some() {
            series.push(("baseline", [120, 120, 120], base_values.as_slice()));
        }
        series.push(("this model", [40, 90, 220], ours.as_slice()));
        let chart = bar_chart("joint error per joint (mm)", "mm", &names, &series);
        chart.write_png(&dir.join("joint_error.png"))?;
        // Error against added Gaussian noise.
        let sigmas = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let noisy: Vec<f64> = sigmas
            .iter()
            .map(|&s| training::eval_body(&estimator, samples, rig, s).map(|r| r.mean_error_mm))
            .collect::<Result<_, _>>()?;
        line_chart(
            "mean joint error vs depth noise",
            "noise sigma (mm)",
            "mm",
            &sigmas,
            &[("mean error", [200, 40, 40], &noisy)],
        )
        .write_png(&dir.join("error_vs_noise.png"))?;
        let mut table = String::from("joint,error_mm");
        if baseline.is_some() {
            table.push_str(",baseline_mm");
        }
        table.push('\n');
        for (k, name) in names.iter().enumerate() {
            let _ = write!(table, "{name},{:.3}", ours[k]);
            if let Some(b) = base_values.get(k) {
                let _ = write!(table, ",{b:.3}");
            }
            table.push('\n');
        }
        write_report_file(dir, "joint_error.csv", table.as_bytes())?;
        let mut noise_table = String::from("noise_mm,mean_error_mm\n");
        for (s, e) in sigmas.iter().zip(&noisy) {
            let _ = writeln!(noise_table, "{s},{e:.3}");
        }
        write_report_file(dir, "error_vs_noise.csv", noise_table.as_bytes())?;
        write_report_file(dir, "summary.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if args.json {
        return print_json(&report);
    }
    let mut t = String::new();
    let _ = writeln!(t, "{:<16} {:>9}", "joint", "error mm");
    for (name, e) in &report.per_joint_mm {
        let _ = writeln!(t, "{name:<16} {e:>9.2}");
    }
    let _ = writeln!(t, "{:<16} {:>9.2}", "mean (1-12)", report.mean_error_mm);
    let _ = writeln!(t, "{} images, {} without a mouse found", report.images, report.no_mouse);
    print(&t)
}

fn eval_parts(
    args: &EvalArgs,
    forest: &Forest<[f32; 2], Vec<f32>>,
    samples: &[crate::synth::dataset::Sample],
) -> Result<()> {
    let report = training::eval_parts(forest, samples);
    if let Some(dir) = &args.report {
        report_dir(dir)?;
        confusion_chart(
            "part labels: confusion (% of true class)",
            &report.classes,
            &report.confusion,
        )
        .write_png(&dir.join("confusion.png"))?;
        let mut table = String::from("truth\\predicted");
        for c in &report.classes {
            let _ = write!(table, ",{c}");
        }
        table.push('\n');
        for (c, row) in report.classes.iter().zip(&report.confusion) {
            let _ = write!(table, "{c}");
            for v in row {
                let _ = write!(table, ",{v}");
            }
            table.push('\n');
        }
        write_report_file(dir, "confusion.csv", table.as_bytes())?;
        write_report_file(dir, "summary.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if args.json {
        return print_json(&report);
    }
    let mut t = String::new();
    let _ = writeln!(t, "{:<12} {:>9}", "class", "accuracy");
    for (name, a) in &report.per_class_accuracy {
        let _ = writeln!(t, "{name:<12} {:>8.1}%", 100.0 * a);
    }
    let _ = writeln!(t, "{:<12} {:>8.1}%", "mean", 100.0 * report.mean_class_accuracy);
    let _ = writeln!(t, "{:<12} {:>8.1}%", "all pixels", 100.0 * report.pixel_accuracy);
    print(&t)
}

/// One point of a sweep.
#[derive(Clone, Debug, Serialize)]
struct SweepPoint {
    value: f64,
    baseline_accuracy: f64,
    discriminative_accuracy: f64,
}

/// What `experiment gauss2d --json` prints.
#[derive(Clone, Debug, Serialize)]
struct Gauss2dReport {
    setup: Setup,
    bayes_accuracy: f64,
    baseline_accuracy: f64,
    union_baseline_accuracy: f64,
    discriminative_gain_accuracy: f64,
    discriminative_accuracy: f64,
    paper: PaperFigures,
    sweeps: std::collections::BTreeMap<String, Vec<SweepPoint>>,
}

#[derive(Clone, Debug, Serialize)]
struct PaperFigures {
    baseline_accuracy: f64,
    union_baseline_accuracy: f64,
    discriminative_gain_accuracy: f64,
    discriminative_accuracy: f64,
}

const PAPER: PaperFigures = PaperFigures {
    baseline_accuracy: 0.794,
    union_baseline_accuracy: 0.796,
    discriminative_gain_accuracy: 0.804,
    discriminative_accuracy: 0.812,
};

/// `mousepose experiment gauss2d`.
pub fn gauss2d(args: &Gauss2dArgs) -> Result<()> {
    let setup = Setup::new(args.quick, args.seed);
    let steps = if args.quick { 26 } else { 36 };
    let bar = progress::bar(steps, "gauss2d");
    let blobs = gauss2d::blobs(setup.seed);
    let d_t = gauss2d::sample(&blobs, setup.points, setup.seed, 0);
    let d_d = gauss2d::sample(&blobs, setup.points, setup.seed, 1);
    let d_e = gauss2d::sample(&blobs, setup.points, setup.seed, 2);
    let acc = |f: &gauss2d::AxisForest| gauss2d::accuracy(f, &d_e);
    let base = gauss2d::baseline(&d_t, &setup.train_params());
    bar.inc(1);
    let mut union_params = setup.train_params();
    union_params.min_leaf *= 2;
    let union = gauss2d::baseline(&d_t.union(&d_d), &union_params);
    bar.inc(1);
    let (disc_gain, _) = gauss2d::discriminative(&base, &d_d, &setup.discriminative_params(Scoring::Gain));
    bar.inc(1);
    let disc_params = setup.discriminative_params(Scoring::SubtreeError);
    let (disc, _) = gauss2d::discriminative(&base, &d_d, &disc_params);
    bar.inc(1);
    let base_acc = acc(&base);
    let mut sweeps = std::collections::BTreeMap::new();

    // Forest size: trees are independent, so a k-tree forest is the first k of a larger one.
    let sizes: Vec<usize> = if args.quick {
        vec![1, 3, 5, 9]
    } else {
        vec![1, 3, 5, 7, 9, 13, 17]
    };
    let max_trees = sizes.iter().copied().max().unwrap_or(5);
    let big = gauss2d::baseline(
        &d_t,
        &TrainParams {
            trees: max_trees,
            ..setup.train_params()
        },
    );
    let (big_disc, _) = gauss2d::discriminative(&big, &d_d, &disc_params);
    let first = |f: &gauss2d::AxisForest, k: usize| Forest {
        trees: f.trees[..k].to_vec(),
    };
    sweeps.insert(
        "forest_size".to_owned(),
        sizes
            .iter()
            .map(|&k| {
                bar.inc(1);
                SweepPoint {
                    value: k as f64,
                    baseline_accuracy: acc(&first(&big, k)),
                    discriminative_accuracy: acc(&first(&big_disc, k)),
                }
            })
            .collect(),
    );
    let mut sweep = |name: &str, values: &[f64], set: &dyn Fn(&mut DiscriminativeParams, f64)| {
        let points = values
            .iter()
            .map(|&v| {
                let mut p = disc_params;
                set(&mut p, v);
                let (f, _) = gauss2d::discriminative(&base, &d_d, &p);
                bar.inc(1);
                SweepPoint {
                    value: v,
                    baseline_accuracy: base_acc,
                    discriminative_accuracy: acc(&f),
                }
            })
            .collect();
        sweeps.insert(name.to_owned(), points);
    };
    let ms: &[f64] = if args.quick {
        &[10.0, 50.0, 200.0, 640.0]
    } else {
        &[10.0, 20.0, 50.0, 100.0, 200.0, 320.0, 640.0]
    };
    sweep("m", ms, &|p, v| p.tests = v as usize);
    let lns: &[f64] = if args.quick {
        &[10.0, 60.0, 1000.0, 10000.0]
    } else {
        &[10.0, 30.0, 60.0, 250.0, 1000.0, 2500.0, 10000.0]
    };
    sweep("l_n", lns, &|p, v| p.min_leaf = v as usize);
    let levels: &[f64] = if args.quick {
        &[0.0, 4.0, 8.0, 12.0]
    } else {
        &[0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]
    };
    sweep("start_level", levels, &|p, v| p.start_level = v as u32);
    // Iterations: each pass refines the previous pass's forest with a fresh subset.
    let iterations = if args.quick { 3 } else { 5 };
    let mut forest = base.clone();
    let mut points = vec![SweepPoint {
        value: 0.0,
        baseline_accuracy: base_acc,
        discriminative_accuracy: base_acc,
    }];
    for it in 0..iterations {
        forest = gauss2d::discriminative_from(
            &forest,
            &d_d,
            &DiscriminativeParams {
                iterations: 1,
                ..disc_params
            },
            it,
        )
        .0;
        bar.inc(1);
        points.push(SweepPoint {
            value: (it + 1) as f64,
            baseline_accuracy: base_acc,
            discriminative_accuracy: acc(&forest),
        });
    }
    sweeps.insert("iterations".to_owned(), points);
    bar.finish_and_clear();

    let report = Gauss2dReport {
        setup,
        bayes_accuracy: gauss2d::bayes_accuracy(&blobs, &d_e),
        baseline_accuracy: base_acc,
        union_baseline_accuracy: acc(&union),
        discriminative_gain_accuracy: acc(&disc_gain),
        discriminative_accuracy: acc(&disc),
        paper: PAPER,
        sweeps,
    };
    if let Some(dir) = &args.report {
        report_dir(dir)?;
        write_report_file(dir, "gauss2d.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
        write_report_file(dir, "gauss2d.txt", gauss2d_tables(&report).as_bytes())?;
        for (name, points) in &report.sweeps {
            let x: Vec<f64> = points.iter().map(|p| p.value).collect();
            let b: Vec<f64> = points.iter().map(|p| p.baseline_accuracy).collect();
            let d: Vec<f64> = points.iter().map(|p| p.discriminative_accuracy).collect();
            line_chart(
                &format!("gauss2d: accuracy vs {name}"),
                name,
                "accuracy",
                &x,
                &[("baseline", [120, 120, 120], &b), ("discriminative", [40, 90, 220], &d)],
            )
            .write_png(&dir.join(format!("sweep_{name}.png")))?;
        }
    }
    if args.json {
        return print_json(&report);
    }
    print(&gauss2d_tables(&report))
}

fn gauss2d_tables(r: &Gauss2dReport) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "gauss2d: {} points per set, {} trees, L = {}, m = {}, l_n = {}, seed {}",
        r.setup.points, r.setup.trees, r.setup.max_depth, r.setup.tests, r.setup.min_leaf, r.setup.seed
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
        "Bayes-optimal (true densities)", r.bayes_accuracy, "-"
    );
    for (name, points) in &r.sweeps {
        let _ = writeln!(
            t,
            "\nsweep {name}\n{:>10} {:>10} {:>15}",
            name, "baseline", "discriminative"
        );
        for p in points {
            let _ = writeln!(
                t,
                "{:>10} {:>10.4} {:>15.4}",
                p.value, p.baseline_accuracy, p.discriminative_accuracy
            );
        }
    }
    t
}

/// `mousepose replay`.
pub fn replay(args: &crate::app::ReplayArgs) -> Result<()> {
    use crate::runtime::topology::{ReplayOptions, replay};
    let options = ReplayOptions {
        session: args.session.clone(),
        out: args.out.clone(),
        models: args.models.clone(),
        realtime: args.realtime,
        workers: args.workers as usize,
        overlays: args.overlays,
        calibration: args.calibration.clone(),
        force: args.force,
    };
    let summary = replay(&options).with_context(|| format!("replaying {:?}", args.session))?;
    if args.json {
        return print_json(&summary);
    }
    let mut text = String::new();
    let _ = writeln!(
        text,
        "{} pairs in {:.2} s ({:.0} pairs/s); poses in {:?}",
        summary.pairs,
        summary.elapsed_s,
        summary.throughput_pairs_per_s,
        args.out.join(crate::runtime::sink::poses::POSES_FILE)
    );
    for (name, c) in &summary.cameras {
        let _ = writeln!(
            text,
            "{name:>6}: captured {}, paired {}, unpaired {}, dropped {} {:?}, lost before capture {:?}",
            c.captured, c.paired, c.unpaired, c.dropped_total, c.dropped, c.lost_before_capture
        );
    }
    for s in &summary.stages {
        let _ = writeln!(
            text,
            "{:>8}: {} in, {} out, p50 {:.2} ms, p99 {:.2} ms",
            s.name, s.items_in, s.items_out, s.latency.p50_ms, s.latency.p99_ms
        );
    }
    let _ = writeln!(
        text,
        "end to end: p50 {:.2} ms, p99 {:.2} ms",
        summary.end_to_end_latency.p50_ms, summary.end_to_end_latency.p99_ms
    );
    if let Some(p) = &summary.pairing {
        let _ = writeln!(text, "pairing vs truth: {} of {} pairs match", p.matched, p.truth_pairs);
    }
    if summary.paw_model.is_none() && summary.cameras.contains_key("color") {
        let _ = writeln!(
            text,
            "no paw cascade ({}) among the models: paws and limbs are in their default configuration",
            crate::runtime::topology::PAWS_MODEL
        );
    }
    if let Some(mean) = summary.mean_error_mm {
        let _ = writeln!(text, "mean joint error vs truth: {mean:.2} mm");
        for (group, e) in &summary.group_error_mm {
            let _ = writeln!(text, "{group:>14}: {e:.2} mm");
        }
    }
    print(&text)
}

/// `mousepose record`.
pub fn record(args: &crate::app::RecordArgs) -> Result<()> {
    let config = crate::runtime::config::Config::load(&args.config)?;
    let stop = crate::runtime::pipeline::Shutdown::default();
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, stop.flag()).context("installing the signal handlers")?;
    }
    let summary = crate::runtime::record::record(&config, &args.out, args.seconds, args.force, &stop)
        .with_context(|| format!("recording to {:?}", args.out))?;
    if args.json {
        return print_json(&summary);
    }
    let mut text = format!(
        "recorded {:.1} s to {:?}: {} depth frames ({:.1} MB), {} colour frames ({:.1} MB), {:.2} cores\n",
        summary.seconds,
        summary.dir,
        summary.depth_frames,
        summary.depth_bytes as f64 / 1e6,
        summary.color_frames,
        summary.color_bytes as f64 / 1e6,
        summary.cpu_cores
    );
    for (name, c) in &summary.cameras {
        let _ = writeln!(
            text,
            "{name:>6}: captured {}, recorded {}, dropped {} {:?}, lost before capture {:?}",
            c.captured, c.recorded, c.dropped_total, c.dropped, c.lost_before_capture
        );
    }
    print(&text)
}

/// `mousepose devices`.
pub fn devices(args: &crate::app::DevicesArgs) -> Result<()> {
    let config = args
        .config
        .as_deref()
        .map(crate::runtime::config::Config::load)
        .transpose()?;
    let found = crate::runtime::devices::list(config.as_ref());
    if args.json {
        return print_json(&serde_json::json!({ "backends": found }));
    }
    let mut text = String::new();
    for b in &found {
        let _ = writeln!(text, "{} ({}):", b.backend, b.scope);
        if let Some(e) = &b.error {
            let _ = writeln!(text, "  cannot list: {e}");
        }
        if b.devices.is_empty() && b.error.is_none() {
            let _ = writeln!(text, "  none");
        }
        for d in &b.devices {
            let _ = writeln!(text, "  {:<24} {} serial {:?} {}", d.id, d.model, d.serial, d.details);
        }
    }
    print(&text)
}

/// The training parameters `train paws` uses besides its arguments.
fn paw_params(args: &TrainArgs) -> crate::vision::paws::train::TrainParams {
    crate::vision::paws::train::TrainParams {
        stages: args.stages as usize,
        seed: args.seed,
        ..crate::vision::paws::train::TrainParams::default()
    }
}

/// Augmented copies of each paw window besides the plain one.
const PAW_AUGMENT: usize = 3;

/// `mousepose train paws`.
fn train_paws(args: &TrainArgs) -> Result<()> {
    use crate::training::paws_data as data;
    use crate::vision::paws::{WINDOW_PX, train, xml};
    let set = data::load(
        &args.data,
        data::CutParams {
            width: WINDOW_PX as usize,
            height: WINDOW_PX as usize,
            augment: PAW_AUGMENT,
            seed: args.seed,
        },
    )
    .with_context(|| format!("reading training dataset {:?}", args.data))?;
    tracing::info!(
        message = "Training windows cut.",
        paws = set.paws,
        positives = set.positive_count(),
        backgrounds = set.backgrounds.len(),
    );
    let params = paw_params(args);
    let bar = progress::bar(params.stages as u64, "stages");
    let started = std::time::Instant::now();
    let trained = train::train(&set, &params, &mut |r| {
        bar.inc(1);
        bar.set_message(format!("fa {:.4}", r.false_alarm));
        tracing::debug!(
            message = "Stage trained.",
            stage = r.stage,
            positives = r.positives,
            negatives = r.negatives,
            weak = r.weak,
            hit_rate = r.hit_rate,
            false_alarm = r.false_alarm,
            windows_scanned = r.windows_scanned,
            windows_accepted = r.windows_accepted,
        );
    })
    .context("training the paw cascade")?;
    bar.finish_and_clear();
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| format!("creating {parent:?}"))?;
    }
    xml::save(&trained.cascade, &args.out)?;
    let weak: usize = trained.cascade.stages.iter().map(|s| s.weak.len()).sum();
    if let train::StopReason::NoNegatives { found, scanned } = &trained.stop {
        tracing::info!(
            message = "Training stopped early: the backgrounds no longer yield enough windows the cascade accepts.",
            found,
            scanned,
        );
    }
    let last = trained.stages.last();
    tracing::info!(
        message = "Paw cascade written.",
        path = %args.out.display(),
        stages = trained.cascade.stages.len(),
        weak,
        features = trained.cascade.features.len(),
        flat_positives = trained.flat_positives,
        last_acceptance = last.map_or(0.0, |r| r.windows_accepted as f64 / r.windows_scanned.max(1) as f64),
        seconds = format!("{:.0}", started.elapsed().as_secs_f64()),
    );
    Ok(())
}

/// `mousepose eval paws`.
fn eval_paws(args: &EvalArgs) -> Result<()> {
    use crate::training::paws_eval as eval;
    use crate::vision::paws::PawDetector;
    let detector = PawDetector::load(&args.model)?;
    let report =
        eval::evaluate(&detector, &args.data).with_context(|| format!("evaluating on test dataset {:?}", args.data))?;
    if let Some(dir) = &args.report {
        report_dir(dir)?;
        let mut points = report.curve.clone();
        points.sort_by(|a, b| a.recall.total_cmp(&b.recall).then(b.precision.total_cmp(&a.precision)));
        let stride = points.len().div_ceil(10).max(1);
        let picked: Vec<_> = points
            .iter()
            .enumerate()
            .filter(|(i, _)| i % stride == 0 || i + 1 == points.len())
            .map(|(_, p)| *p)
            .collect();
        let recall: Vec<f64> = picked.iter().map(|p| (p.recall * 1000.0).round() / 1000.0).collect();
        let precision: Vec<f64> = picked.iter().map(|p| p.precision).collect();
        line_chart(
            "paws on the glass: precision vs recall (minimum score varied)",
            "recall",
            "precision",
            &recall,
            &[("precision", [40, 90, 220], &precision)],
        )
        .write_png(&dir.join("precision_recall.png"))?;
        let mut table = String::from("min_score,precision,recall\n");
        for p in &report.curve {
            let _ = writeln!(table, "{:.4},{:.4},{:.4}", p.min_score, p.precision, p.recall);
        }
        write_report_file(dir, "precision_recall.csv", table.as_bytes())?;
        write_report_file(dir, "summary.json", serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if args.json {
        return print_json(&report);
    }
    let mut t = String::new();
    let _ = writeln!(t, "{:<28} {:>9}", "images", report.images);
    let _ = writeln!(t, "{:<28} {:>9}", "paws on the glass", report.contact_paws);
    let _ = writeln!(t, "{:<28} {:>9}", "detections", report.detections);
    let _ = writeln!(t, "{:<28} {:>9.3}", "precision", report.precision);
    let _ = writeln!(t, "{:<28} {:>9.3}", "recall (paws on the glass)", report.recall);
    let _ = writeln!(t, "{:<28} {:>9.3}", "F1", report.f1);
    let _ = writeln!(
        t,
        "{:<28} {:>9.2}",
        "mean centre error (px)", report.mean_centre_error_px
    );
    let _ = writeln!(
        t,
        "{} true, {} false, {} of lifted or hidden paws (neither)",
        report.true_positives, report.false_positives, report.neutral
    );
    print(&t)
}
