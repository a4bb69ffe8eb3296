//! `mousepose report RUN --out DIR`: the arguments, handed to [`crate::engine::report`], and
//! what it found printed.

use crate::app::output::{print, print_json};
use crate::engine::Failure;
use crate::engine::report::{ReportOptions, report, summary};
use crate::vision::behaviour::{Arena, BehaviourConfig};
use crate::vision::movement::ActivityConfig;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The run: a replay's output directory (or a daemon's chunk), with its poses.csv.
    #[arg(value_name = "RUN")]
    pub run: PathBuf,
    /// The directory to write the page, charts and tables into.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The arena (cage floor) as X0,Y0,X1,Y1 in world millimetres. Default: the arena the
    /// replay found (`world.arena_mm` of the run's summary), else the synthetic 500 x 450 mm
    /// cage centred on the origin.
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_arena, allow_hyphen_values = true)]
    pub arena: Option<Arena>,
    /// Walking: the slowest speed of a walking bout, mm/s.
    #[arg(long, value_name = "MM_S", default_value_t = 50.0, value_parser = parse_speed)]
    pub walk_min: f64,
    /// Walking: the fastest speed of a walking bout (faster is running), mm/s.
    #[arg(long, value_name = "MM_S", default_value_t = 200.0, value_parser = parse_speed)]
    pub walk_max: f64,
    /// Rearing: the head at least this high above the floor, mm.
    #[arg(long, value_name = "MM", default_value_t = 40.0, value_parser = parse_mm)]
    pub rearing: f64,
    /// By the walls: the body's centre within this of a wall, mm.
    #[arg(long, value_name = "MM", default_value_t = 60.0, value_parser = parse_mm)]
    pub wall: f64,
    /// Immobile: the body slower than this (and turning slower than 30 degrees/s) for 0.5 s
    /// or more, mm/s.
    #[arg(long, value_name = "MM_S", default_value_t = 10.0, value_parser = parse_speed)]
    pub immobile: f64,
    /// Freezing: immobile for at least this long, seconds.
    #[arg(long, value_name = "S", default_value_t = 2.0, value_parser = parse_seconds)]
    pub freezing: f64,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

fn parse_speed(s: &str) -> Result<f64, String> {
    crate::app::parse::ranged(s, "a speed in mm/s", 0.0, 10_000.0)
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    crate::app::parse::ranged(s, "a duration in seconds", 0.0, 3600.0)
}

fn parse_mm(s: &str) -> Result<f64, String> {
    crate::app::parse::ranged(s, "a distance in millimetres", 0.0, 10_000.0)
}

/// `--arena X0,Y0,X1,Y1`: a rectangle with X0 < X1 and Y0 < Y1.
fn parse_arena(s: &str) -> Result<Arena, String> {
    let wrong = || format!("expected the arena as X0,Y0,X1,Y1 in millimetres with X0 < X1 and Y0 < Y1, got {s:?}");
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| wrong())?;
    let [x0, y0, x1, y1] = v[..] else {
        return Err(wrong());
    };
    if !(x0.is_finite() && y0.is_finite() && x1.is_finite() && y1.is_finite() && x0 < x1 && y0 < y1) {
        return Err(wrong());
    }
    Ok(Arena {
        x_min_mm: x0,
        y_min_mm: y0,
        x_max_mm: x1,
        y_max_mm: y1,
    })
}

/// `mousepose report`.
pub fn command(args: &ReportArgs) -> crate::app::Outcome {
    if args.walk_min >= args.walk_max {
        return Err(Failure::usage(anyhow::anyhow!(
            "--walk-min {} mm/s is not below --walk-max {} mm/s",
            args.walk_min,
            args.walk_max
        )));
    }
    let options = ReportOptions {
        run: args.run.clone(),
        out: args.out.clone(),
        force: args.force,
        config: BehaviourConfig {
            walk_min_mm_s: args.walk_min,
            walk_max_mm_s: args.walk_max,
            rear_head_mm: args.rearing,
            wall_band_mm: args.wall,
            ..BehaviourConfig::default()
        },
        activity: ActivityConfig {
            immobile_mm_s: args.immobile,
            min_freezing_s: args.freezing,
            ..ActivityConfig::default()
        },
        arena: args.arena,
    };
    let reported = report(&options).map_err(|f| f.context(format!("reporting on {:?}", args.run)))?;
    if args.json {
        return Ok(print_json(&summary(&options, &reported))?);
    }
    let (b, arena) = (&reported.behaviour, reported.arena);
    let stride = |k: usize| {
        b.paws[k]
            .stride_length_mm
            .map_or_else(|| "-".to_owned(), |v| format!("{v:.1}"))
    };
    Ok(print(&format!(
        "{:.1} s, {:.0} mm travelled, {} rearing and {} walking bouts, {} immobile ({:.1} s, {} freezing), {}; {}; report in {:?}\n",
        b.duration_s,
        b.distance_mm,
        b.rearing.len(),
        b.walking.len(),
        reported.activity.immobility.len(),
        reported.activity.immobile_s(),
        reported.activity.freezing.len(),
        match reported.gait_unavailable {
            Some(_) => "no gait (needs the bottom camera: the run has no colour frames)".to_owned(),
            None => format!(
                "{} strides (stride length mm: {} {} {} {})",
                b.strides.len(),
                stride(0),
                stride(1),
                stride(2),
                stride(3)
            ),
        },
        match arena.from {
            "default" => "arena: the synthetic 500 x 450 mm cage (the run names none; give --arena)".to_owned(),
            from => {
                let (l, w) = arena.arena.size_mm();
                format!("arena {l:.0} x {w:.0} mm ({from})")
            }
        },
        args.out.join("index.html")
    ))?)
}
