//! The engine of `mousepose report RUN --out DIR`: a run's behaviour and gait as a page of PNG charts and
//! CSV tables that opens without a network:
//!
//! ```text
//! DIR/index.html     the page: figures, tables, how each measure is taken
//! DIR/path.png       the body's path in the arena (blue at the start, red at the end)
//! DIR/speed.png      speed over time; distance.png: distance travelled
//! DIR/zones.png      time in the centre, between, and by the walls
//! DIR/rearing.png    head height over time, with the rearing threshold
//! DIR/stance.png     stance of each paw over time (a gait diagram), walking bouts marked
//! DIR/gait.png       stride length, cadence and duty factor per paw
//! DIR/frames.csv     per frame: time, centre, speed, distance, zone, rearing, walking, stance
//! DIR/strides.csv    per stride: paw, start, period, length, cadence, duty factor
//! DIR/bouts.csv      walking and rearing bouts
//! DIR/summary.json   every measure of the page
//! ```
//!
//! The measures come from [`crate::vision::behaviour`]: the body's centre is `mid_back`, the
//! head height `head`'s z, and a paw is in stance while the bottom camera found it on the glass
//! (its source is `paw`).

use crate::core::geometry::{CAGE_X_MM, CAGE_Y_MM};
use crate::core::pose::JointSource;
use crate::core::skeleton::Joint;
use crate::engine::chart::{ChartOutline, Series, bar_chart, path_chart, raster_chart, series_chart};
use crate::engine::{Failure, output_failure};
use crate::io::output::Staging;
use crate::io::table::{Fixed, table};
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crate::runtime::sink::poses::{POSES_FILE, read_poses};
use crate::vision::behaviour::{
    Arena, Behaviour, BehaviourConfig, FrameInput, OUTLINE_RAYS, Outline, PAW_NAMES, analyse_in,
};
use crate::vision::movement::{Activity, ActivityConfig, StrideVariability, activity};
use anyhow::Context as _;
use nalgebra::{Point2, Vector2};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A paw placed from a detection is on the glass when it is at most this high, mm (fusion
/// places a paw the leg cannot reach on the glass up its ray instead).
const ON_GLASS_MM: f64 = 6.0;

/// What `report` reads, where it writes, and what it measures with.
#[derive(Clone, Debug, Default)]
pub struct ReportOptions {
    /// The run: a replay's output directory (or a daemon's chunk), with its `poses.csv`.
    pub run: PathBuf,
    /// The directory to write the page, charts and tables into.
    pub out: PathBuf,
    /// Replace `out` if it is not empty.
    pub force: bool,
    pub config: BehaviourConfig,
    pub activity: ActivityConfig,
    /// The arena (`None`: the run's own, else the synthetic cage).
    pub arena: Option<Arena>,
}

impl ReportOptions {
    /// A report of `run` into `out` with the default thresholds and the run's arena.
    pub fn new(run: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            run: run.into(),
            out: out.into(),
            ..Self::default()
        }
    }
}

/// The arena a report used, and where it came from: `flag`, `recording` (the replay's
/// `world.arena_mm`, and its `world.arena_outline_mm` when it has one) or `default` (the
/// synthetic cage).
#[derive(Clone, Debug, serde::Serialize)]
pub struct ArenaUsed {
    #[serde(flatten)]
    pub arena: Arena,
    /// The floor's own outline, which the zones follow (a round arena is round).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outline: Option<Outline>,
    pub from: &'static str,
}

/// The run's `summary.json` (a replay's or a chunk's), when it reads.
fn run_summary(run: &Path) -> Option<serde_json::Value> {
    std::fs::read(run.join(crate::engine::replay::SUMMARY_FILE))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
}

/// Which models made the run, as its `summary.json` names them (absent in runs made before
/// outputs named them).
fn models_of(run: &Path) -> Option<crate::runtime::models::ModelsUsed> {
    run_summary(run)
        .and_then(|v| v.get("models").cloned())
        .and_then(|m| serde_json::from_value(m).ok())
}

/// The arena of `options`, else the run's summary's, else the synthetic cage.
fn arena_of(run: &Path, options: &ReportOptions) -> ArenaUsed {
    if let Some(arena) = options.arena {
        return ArenaUsed {
            arena,
            outline: None,
            from: "flag",
        };
    }
    let world = run_summary(run).and_then(|v| v.get("world").cloned());
    let outline = world
        .as_ref()
        .and_then(|w| w.get("arena_outline_mm"))
        .and_then(|o| serde_json::from_value::<Outline>(o.clone()).ok())
        .filter(|o| o.reach_mm.len() == OUTLINE_RAYS && o.reach_mm.iter().all(|r| r.is_finite() && *r > 0.0));
    let recorded = world
        .as_ref()
        .and_then(|w| {
            let a = w.get("arena_mm")?;
            let get = |k: &str| a.get(k).and_then(serde_json::Value::as_f64);
            Some(Arena {
                x_min_mm: get("x_min_mm")?,
                y_min_mm: get("y_min_mm")?,
                x_max_mm: get("x_max_mm")?,
                y_max_mm: get("y_max_mm")?,
            })
        })
        .filter(|a| a.size_mm().0 > 0.0 && a.size_mm().1 > 0.0);
    match recorded {
        Some(arena) => ArenaUsed {
            arena,
            outline,
            from: "recording",
        },
        None => ArenaUsed {
            arena: Arena::centred((CAGE_X_MM, CAGE_Y_MM)),
            outline: None,
            from: "default",
        },
    }
}

/// The analysis's input of one row of `poses.csv`.
pub fn frame_input(t0_ns: u64, r: &PoseRecord) -> FrameInput {
    let t_s = r.depth.device_ns.saturating_sub(t0_ns) as f64 / 1e9;
    let seen = |j: Joint| {
        let e = r.pose.joint(j);
        (r.status == PoseStatus::Ok && e.source != JointSource::Missing).then_some(e)
    };
    let xy = |j: Joint| seen(j).map(|e| Point2::new(e.position_mm.x, e.position_mm.y));
    let axis = match (xy(Joint::Neck), xy(Joint::TailBase)) {
        (Some(n), Some(t)) => Some(n - t),
        _ => None,
    };
    let paws = [
        Joint::LeftForePaw,
        Joint::RightForePaw,
        Joint::LeftHindPaw,
        Joint::RightHindPaw,
    ]
    .map(|j| {
        seen(j)
            .filter(|e| e.source == JointSource::Paw && e.position_mm.z <= ON_GLASS_MM)
            .map(|e| Point2::new(e.position_mm.x, e.position_mm.y))
    });
    FrameInput {
        t_s,
        centre: xy(Joint::MidBack),
        axis: axis.filter(|a: &Vector2<f64>| a.norm() > 1e-6),
        head_z_mm: seen(Joint::Head).map(|e| e.position_mm.z),
        paws,
    }
}

fn nan(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

/// `frames.csv`: per frame its time, centre, speed, distance, zone, head height, bouts, stance
/// of each paw, heading, angular speed and immobility.
fn frames_csv(b: &Behaviour, a: &Activity, inputs: &[FrameInput]) -> Result<Vec<u8>, csv::Error> {
    let stance: Vec<String> = PAW_NAMES.iter().map(|p| format!("{p}_stance")).collect();
    let columns: Vec<&str> = [
        "t_s",
        "x_mm",
        "y_mm",
        "speed_mm_s",
        "distance_mm",
        "zone",
        "head_z_mm",
        "rearing",
        "walking",
    ]
    .into_iter()
    .chain(stance.iter().map(String::as_str))
    .chain(["heading_deg", "angular_speed_deg_s", "immobile"])
    .collect();
    let rows: Vec<_> = b
        .frames
        .iter()
        .zip(inputs)
        .enumerate()
        .map(|(k, (f, i))| {
            (
                (
                    Fixed::<4>(f.t_s),
                    i.centre.map(|c| Fixed::<2>(c.x)),
                    i.centre.map(|c| Fixed::<2>(c.y)),
                    f.speed_mm_s.map(Fixed::<1>),
                    Fixed::<1>(f.distance_mm),
                    f.zone.name(),
                    i.head_z_mm.map(Fixed::<2>),
                    u8::from(f.rearing),
                    u8::from(f.walking),
                ),
                f.stance.map(u8::from),
                (
                    a.heading_deg[k].map(Fixed::<1>),
                    a.angular_speed_deg_s[k].map(Fixed::<1>),
                    u8::from(a.immobile[k]),
                ),
            )
        })
        .collect();
    table(&columns, &rows)
}

/// `strides.csv`: per stride its paw, start, period, length, cadence and duty factor.
fn strides_csv(b: &Behaviour) -> Result<Vec<u8>, csv::Error> {
    let rows: Vec<_> = b
        .strides
        .iter()
        .map(|st| {
            (
                PAW_NAMES[st.paw],
                Fixed::<4>(st.start_s),
                Fixed::<4>(st.period_s),
                Fixed::<2>(st.length_mm),
                Fixed::<3>(1.0 / st.period_s),
                Fixed::<3>(st.duty_factor),
            )
        })
        .collect();
    table(
        &["paw", "start_s", "period_s", "length_mm", "cadence_hz", "duty_factor"],
        &rows,
    )
}

/// `bouts.csv`: the walking, rearing, immobility and freezing bouts.
fn bouts_csv(b: &Behaviour, a: &Activity) -> Result<Vec<u8>, csv::Error> {
    let rows: Vec<_> = [
        ("walking", &b.walking),
        ("rearing", &b.rearing),
        ("immobility", &a.immobility),
        ("freezing", &a.freezing),
    ]
    .into_iter()
    .flat_map(|(kind, bouts)| {
        bouts.iter().map(move |x| {
            (
                kind,
                Fixed::<4>(x.start_s),
                Fixed::<4>(x.end_s),
                Fixed::<4>(x.duration_s()),
            )
        })
    })
    .collect();
    table(&["kind", "start_s", "end_s", "duration_s"], &rows)
}

/// A measure and its unit for the page, or "none" (no unit) when there is none.
fn measure(v: Option<f64>, decimals: usize, unit: &str) -> String {
    v.map_or_else(
        || "none".to_owned(),
        |v| format!("{v:.decimals$}{}{unit}", if unit.is_empty() { "" } else { " " }),
    )
}

/// Why the run has no gait, when it cannot have one: no colour frame (a depth-only run).
fn no_gait(rows: &[PoseRecord]) -> Option<&'static str> {
    rows.iter().all(|r| r.color.is_none()).then_some(
        "Gait needs the bottom camera: this run has no colour frames, so no paw was seen on the glass and there are no stance phases or strides.",
    )
}

fn html_escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// The page, `index.html`: the figures, the charts, the gait, and how each measure is taken.
fn page(
    run: &Path,
    (b, a): (&Behaviour, &Activity),
    (config, activity): (&BehaviourConfig, &ActivityConfig),
    arena: &ArenaUsed,
    no_gait: Option<&str>,
) -> String {
    let mut h = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>mousepose report</title>\n<style>body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}th{background:#f3f3f3}img{max-width:100%;border:1px solid #eee}</style></head><body>\n",
    );
    let _ = writeln!(
        h,
        "<h1>Behaviour and gait</h1><p>Run: <code>{}</code></p>",
        html_escape(&run.display().to_string())
    );
    overview_section(&mut h, b, a);
    if let Some(why) = no_gait {
        let _ = writeln!(h, "<h2>Gait</h2>\n<p>{}</p>", html_escape(why));
    } else {
        gait_section(&mut h, b, a);
    }
    how_section(&mut h, config, activity, arena);
    h.push_str("<p>Tables: <a href=\"frames.csv\">frames.csv</a>, <a href=\"strides.csv\">strides.csv</a>, <a href=\"bouts.csv\">bouts.csv</a>, <a href=\"summary.json\">summary.json</a>.</p>\n</body></html>\n");
    h
}

/// The page's tables of the whole run (distance, zones, bouts, turning, immobility) and its
/// charts over time.
fn overview_section(h: &mut String, b: &Behaviour, a: &Activity) {
    let total: f64 = b.zone_s.iter().sum::<f64>().max(1e-9);
    let _ = writeln!(
        h,
        "<table><tr><th>duration</th><th>distance</th><th>mean speed</th><th>in the centre</th><th>by the walls</th><th>between</th><th>mouse not found</th><th>rearing bouts</th><th>walking bouts</th></tr>\
         <tr><td>{:.1} s</td><td>{:.0} mm</td><td>{}</td><td>{:.1} s ({:.0} %)</td><td>{:.1} s ({:.0} %)</td><td>{:.1} s ({:.0} %)</td><td>{:.1} s</td><td>{} ({:.1} s)</td><td>{} ({:.1} s)</td></tr></table>",
        b.duration_s,
        b.distance_mm,
        measure(b.mean_speed_mm_s, 0, "mm/s"),
        b.zone_s[0],
        100.0 * b.zone_s[0] / total,
        b.zone_s[1],
        100.0 * b.zone_s[1] / total,
        b.zone_s[2],
        100.0 * b.zone_s[2] / total,
        b.zone_s[3],
        b.rearing.len(),
        b.rearing.iter().map(|x| x.duration_s()).fold(0.0, |a, d| a + d),
        b.walking.len(),
        b.walking.iter().map(|x| x.duration_s()).fold(0.0, |a, d| a + d),
    );
    let _ = writeln!(
        h,
        "<table><tr><th>turning (mean angular speed)</th><th>turned in all</th><th>net turn (counter-clockwise)</th><th>immobile</th><th>freezing</th></tr>\
         <tr><td>{}</td><td>{:.0} deg</td><td>{:.0} deg</td><td>{} bouts, {:.1} s</td><td>{} bouts, {:.1} s</td></tr></table>",
        measure(a.mean_angular_speed_deg_s, 0, "deg/s"),
        a.turned_deg,
        a.net_turn_deg,
        a.immobility.len(),
        a.immobile_s(),
        a.freezing.len(),
        a.freezing_s(),
    );
    for (img, alt) in [
        ("path.png", "path in the arena"),
        ("speed.png", "speed over time"),
        ("distance.png", "distance over time"),
        ("zones.png", "time per zone"),
        ("rearing.png", "head height and rearing"),
    ] {
        let _ = writeln!(h, "<p><img src=\"{img}\" alt=\"{alt}\"></p>");
    }
}

/// The page's account of how each measure is taken, with the thresholds used.
fn how_section(h: &mut String, config: &BehaviourConfig, activity: &ActivityConfig, arena: &ArenaUsed) {
    let _ = writeln!(
        h,
        "<h2>How</h2><ul>\
         <li>Body centre: <code>mid_back</code>, averaged over {:.2} s; speed from it, distance its path.</li>\
         <li>Centre: {}; walls: within {:.0} mm of a wall (arena {:.0} x {:.0} mm from x {:.0}, y {:.0} mm, {}).</li>\
         <li>Rearing: the head at least {:.0} mm above the glass for {:.2} s or more.</li>\
         <li>Walking: speed between {:.0} and {:.0} mm/s for {:.1} s or more, not rearing.</li>\
         <li>Stance: the paw found on the glass by the bottom camera (source <code>paw</code>) and moving slower than {:.1} times the body plus {:.0} mm/s \
         (planted, a paw stays put; in swing it overtakes the body); one-frame gaps and blips are smoothed over. \
         A stride runs from a touchdown to the paw's next one in the same walking bout ({:.2}-{:.1} s); its length is the distance between the two footprints, \
         its duty factor the stance time over the period. Base of support: the distance across the body axis between the left and right paws both in stance. \
         Phase: where in the left hind paw's stride each paw touches down (0.5: half a stride later). \
         Stride variability: the coefficient of variation (standard deviation over mean) of a paw's stride lengths and periods, with 3 strides or more.</li>\
         <li>Heading: where the body points seen from above (tail base to neck), degrees counter-clockwise from the world's x axis; \
         turning: its rate of change over {:.2} s; turned in all and net: the changes of the heading averaged over that window.</li>\
         <li>Immobile: the body slower than {:.0} mm/s and turning slower than {:.0} deg/s for {:.1} s or more; freezing: immobile for {:.1} s or more.</li></ul>",
        config.smooth_s,
        if arena.outline.is_some() {
            "the arena's own outline (the floor the replay saw, as far as it reaches in each direction from its centre) at half its size about its centre"
        } else {
            "the central rectangle of half the arena's length and width"
        },
        config.wall_band_mm,
        arena.arena.size_mm().0,
        arena.arena.size_mm().1,
        arena.arena.x_min_mm,
        arena.arena.y_min_mm,
        match arena.from {
            "flag" => "given by --arena",
            "recording" => "the arena the replay found",
            _ => "the synthetic cage: the run names no arena; give --arena for a real rig",
        },
        config.rear_head_mm,
        config.min_rear_s,
        config.walk_min_mm_s,
        config.walk_max_mm_s,
        config.min_walk_s,
        config.stance_speed_factor,
        config.stance_margin_mm_s,
        config.min_stride_s,
        config.max_stride_s,
        config.smooth_s,
        activity.immobile_mm_s,
        activity.immobile_turn_deg_s,
        activity.min_immobile_s,
        activity.min_freezing_s,
    );
}

/// The page's gait table and charts.
fn gait_section(h: &mut String, b: &Behaviour, a: &Activity) {
    h.push_str("<h2>Gait (walking bouts only)</h2>\n<table><tr><th>paw</th><th>strides</th><th>stride length</th><th>cadence</th><th>duty factor</th><th>phase to left hind</th><th>stride length CV</th><th>stride period CV</th></tr>\n");
    for (k, p) in b.paws.iter().enumerate() {
        let v = a.stride_variability[k];
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            PAW_NAMES[k].replace('_', " "),
            p.strides,
            measure(p.stride_length_mm, 1, "mm"),
            measure(p.cadence_hz, 2, "Hz"),
            measure(p.duty_factor, 2, ""),
            measure(b.phase_to_left_hind[k], 2, ""),
            measure(v.length_cv, 2, ""),
            measure(v.period_cv, 2, ""),
        );
    }
    let _ = writeln!(
        h,
        "</table><p>Base of support: fore {}, hind {}.</p>",
        measure(b.base_of_support_fore_mm, 1, "mm"),
        measure(b.base_of_support_hind_mm, 1, "mm")
    );
    if b.strides.is_empty() {
        h.push_str("<p>No strides: no walking bout had its paws found on the glass long enough.</p>\n");
    }
    for (img, alt) in [("stance.png", "stance of each paw"), ("gait.png", "gait per paw")] {
        let _ = writeln!(h, "<p><img src=\"{img}\" alt=\"{alt}\"></p>");
    }
}

/// What the summary holds: the analysis without its per-frame rows.
#[derive(Debug, serde::Serialize)]
pub struct Summary<'a> {
    run: &'a Path,
    /// Which models made the run's poses (from its `summary.json`).
    #[serde(skip_serializing_if = "Option::is_none")]
    models: Option<crate::runtime::models::ModelsUsed>,
    config: &'a BehaviourConfig,
    arena: &'a ArenaUsed,
    duration_s: f64,
    distance_mm: f64,
    mean_speed_mm_s: Option<f64>,
    centre_s: f64,
    wall_s: f64,
    between_s: f64,
    unknown_s: f64,
    rearing_bouts: usize,
    walking_bouts: usize,
    strides: usize,
    paws: std::collections::BTreeMap<&'static str, crate::vision::behaviour::PawGait>,
    phase_to_left_hind: std::collections::BTreeMap<&'static str, Option<f64>>,
    base_of_support_fore_mm: Option<f64>,
    base_of_support_hind_mm: Option<f64>,
    /// Why there is no gait (a depth-only run), absent when there can be.
    #[serde(skip_serializing_if = "Option::is_none")]
    gait_unavailable: Option<&'static str>,
    stride_variability: std::collections::BTreeMap<&'static str, StrideVariability>,
    activity_config: &'a ActivityConfig,
    mean_angular_speed_deg_s: Option<f64>,
    turned_deg: f64,
    net_turn_deg: f64,
    immobility_bouts: usize,
    immobile_s: f64,
    freezing_bouts: usize,
    freezing_s: f64,
}

/// What [`report`] measured.
#[derive(Clone, Debug)]
pub struct Reported {
    pub behaviour: Behaviour,
    pub activity: Activity,
    /// The arena it used.
    pub arena: ArenaUsed,
    /// Why the run has no gait (a depth-only run), if so.
    pub gait_unavailable: Option<&'static str>,
}

/// `mousepose report`: reads `options.run`'s `poses.csv`, analyses it and writes the report
/// into `options.out`; says what it measured and which arena it used.
///
/// # Errors
/// The poses cannot be read (or there are none), or `out` cannot be written.
pub fn report(options: &ReportOptions) -> Result<Reported, Failure> {
    let run = options.run.as_path();
    let rows = read_poses(&run.join(POSES_FILE)).map_err(Failure::usage)?;
    let Some(first) = rows.first() else {
        return Err(Failure::usage(anyhow::anyhow!(
            "{:?} has no rows",
            run.join(POSES_FILE)
        )));
    };
    let t0 = first.depth.device_ns;
    let inputs: Vec<FrameInput> = rows.iter().map(|r| frame_input(t0, r)).collect();
    let config = options.config;
    let arena = arena_of(run, options);
    let b = analyse_in(&inputs, &arena.arena, arena.outline.as_ref(), &config);
    let act = activity(&inputs, &b, config.smooth_s, &options.activity);
    let reported = Reported {
        behaviour: b,
        activity: act,
        arena,
        gait_unavailable: no_gait(&rows),
    };
    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    let dir = staging.path();
    write_charts(dir, &inputs, &reported, &config)?;
    let (b, act) = (&reported.behaviour, &reported.activity);
    crate::engine::write_report_file(dir, "frames.csv", &frames_csv(b, act, &inputs)?)?;
    crate::engine::write_report_file(dir, "strides.csv", &strides_csv(b)?)?;
    crate::engine::write_report_file(dir, "bouts.csv", &bouts_csv(b, act)?)?;
    let summary = summary(options, &reported);
    crate::engine::write_report_file(dir, "summary.json", &serde_json::to_vec_pretty(&summary)?)?;
    crate::engine::write_report_file(
        dir,
        "index.html",
        page(
            run,
            (b, act),
            (&config, &options.activity),
            &reported.arena,
            reported.gait_unavailable,
        )
        .as_bytes(),
    )?;
    staging.commit().map_err(output_failure)?;
    Ok(reported)
}

/// Writes the report's charts into `dir`: the path, speed, distance, zones and head height;
/// the stance and gait charts when the run can have a gait.
fn write_charts(
    dir: &Path,
    inputs: &[FrameInput],
    reported: &Reported,
    config: &BehaviourConfig,
) -> anyhow::Result<()> {
    let (b, act, arena) = (&reported.behaviour, &reported.activity, &reported.arena);
    let t: Vec<f64> = b.frames.iter().map(|f| f.t_s).collect();
    let write_png = |name: &str, img: crate::core::image::RgbImage| -> anyhow::Result<()> {
        img.write_png(&dir.join(name))
            .with_context(|| format!("writing {name}"))
    };
    write_png("path.png", path_picture(inputs, arena))?;
    let speed: Vec<f64> = b.frames.iter().map(|f| nan(f.speed_mm_s)).collect();
    write_png(
        "speed.png",
        series_chart(
            "SPEED",
            "TIME (S)",
            "MM/S",
            &t,
            &[("speed", [40, 90, 200], &speed)],
            &[config.walk_min_mm_s, config.walk_max_mm_s],
        ),
    )?;
    let distance: Vec<f64> = b.frames.iter().map(|f| f.distance_mm).collect();
    write_png(
        "distance.png",
        series_chart(
            "DISTANCE TRAVELLED",
            "TIME (S)",
            "MM",
            &t,
            &[("distance", [40, 140, 80], &distance)],
            &[],
        ),
    )?;
    let zones = ["centre", "wall", "between", "not found"].map(str::to_owned);
    write_png(
        "zones.png",
        bar_chart("TIME PER ZONE", "S", &zones, &[("time", [40, 90, 200], &b.zone_s)]),
    )?;
    let head: Vec<f64> = inputs.iter().map(|i| nan(i.head_z_mm)).collect();
    write_png(
        "rearing.png",
        series_chart(
            "HEAD HEIGHT (REARING ABOVE THE LINE)",
            "TIME (S)",
            "MM",
            &t,
            &[("head", [200, 80, 40], &head)],
            &[config.rear_head_mm],
        ),
    )?;
    let mut rows_raster: Vec<(&str, Vec<bool>)> = PAW_NAMES
        .iter()
        .enumerate()
        .map(|(k, name)| (*name, b.frames.iter().map(|f| f.stance[k]).collect()))
        .collect();
    rows_raster.push(("walking", b.frames.iter().map(|f| f.walking).collect()));
    rows_raster.push(("rearing", b.frames.iter().map(|f| f.rearing).collect()));
    rows_raster.push(("immobile", act.immobile.clone()));
    if reported.gait_unavailable.is_none() {
        write_png(
            "stance.png",
            raster_chart("STANCE PER PAW", "TIME (S)", &t, &rows_raster),
        )?;
    }
    let paws: Vec<String> = PAW_NAMES.iter().map(|p| p.replace('_', " ")).collect();
    let length: Vec<f64> = b.paws.iter().map(|p| p.stride_length_mm.unwrap_or(0.0)).collect();
    let cadence10: Vec<f64> = b.paws.iter().map(|p| 10.0 * p.cadence_hz.unwrap_or(0.0)).collect();
    let duty100: Vec<f64> = b.paws.iter().map(|p| 100.0 * p.duty_factor.unwrap_or(0.0)).collect();
    let series: [Series<'_>; 3] = [
        ("stride length mm", [40, 90, 200], &length),
        ("cadence x10 hz", [40, 140, 80], &cadence10),
        ("duty factor %", [200, 80, 40], &duty100),
    ];
    if reported.gait_unavailable.is_none() {
        write_png("gait.png", bar_chart("GAIT PER PAW (WALKING)", "", &paws, &series))?;
    }
    Ok(())
}

/// The body's path in the arena (its outline drawn when it has one), about the arena's middle.
fn path_picture(inputs: &[FrameInput], arena: &ArenaUsed) -> crate::core::image::RgbImage {
    // The chart draws its arena around the origin.
    let middle = arena.arena.centre();
    let path: Vec<Option<(f64, f64)>> = inputs
        .iter()
        .map(|i| i.centre.map(|c| (c.x - middle.x, c.y - middle.y)))
        .collect();
    let (length, width) = arena.arena.size_mm();
    let corners: Vec<(f64, f64)> = arena.outline.as_ref().map_or_else(Vec::new, |o| {
        o.vertices().iter().map(|v| (v.x - middle.x, v.y - middle.y)).collect()
    });
    let outline = arena.outline.as_ref().map(|o| ChartOutline {
        corners: &corners,
        centre: (o.centre().x - middle.x, o.centre().y - middle.y),
    });
    path_chart("PATH IN THE ARENA", &path, (length / 2.0, width / 2.0), outline)
}

/// The summary of a report: every measure of the page.
pub fn summary<'a>(options: &'a ReportOptions, r: &'a Reported) -> Summary<'a> {
    let (config, arena, b, a) = (&options.config, &r.arena, &r.behaviour, &r.activity);
    Summary {
        run: &options.run,
        models: models_of(&options.run),
        config,
        arena,
        duration_s: b.duration_s,
        distance_mm: b.distance_mm,
        mean_speed_mm_s: b.mean_speed_mm_s,
        centre_s: b.zone_s[0],
        wall_s: b.zone_s[1],
        between_s: b.zone_s[2],
        unknown_s: b.zone_s[3],
        rearing_bouts: b.rearing.len(),
        walking_bouts: b.walking.len(),
        strides: b.strides.len(),
        paws: PAW_NAMES.iter().copied().zip(b.paws).collect(),
        phase_to_left_hind: PAW_NAMES.iter().copied().zip(b.phase_to_left_hind).collect(),
        base_of_support_fore_mm: b.base_of_support_fore_mm,
        base_of_support_hind_mm: b.base_of_support_hind_mm,
        gait_unavailable: r.gait_unavailable,
        stride_variability: PAW_NAMES.iter().copied().zip(a.stride_variability).collect(),
        activity_config: &options.activity,
        mean_angular_speed_deg_s: a.mean_angular_speed_deg_s,
        turned_deg: a.turned_deg,
        net_turn_deg: a.net_turn_deg,
        immobility_bouts: a.immobility.len(),
        immobile_s: a.immobile_s(),
        freezing_bouts: a.freezing.len(),
        freezing_s: a.freezing_s(),
    }
}
