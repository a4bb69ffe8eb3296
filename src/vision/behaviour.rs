//! Behaviour and gait measures from a sequence of poses: the path and speed of the body's
//! centre, time by the walls and in the centre of the cage, rearing bouts (head height), and
//! gait over walking bouts from the paws on the glass (stance and swing per paw, stride
//! length, cadence, duty factor, base of support, inter-limb phase), the measures CatWalk
//! and LocoMouse users read.
//!
//! Pure code: it takes per-frame times, positions and stance flags and returns numbers; the
//! report command reads `poses.csv`, and the tests feed it a synthetic session's truth.

use nalgebra::{Point2, Vector2};
use serde::Serialize;

/// Thresholds of the analysis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BehaviourConfig {
    /// Positions are averaged over this long before speeds are taken (the estimate's frame to
    /// frame jitter would otherwise read as motion), seconds.
    pub smooth_s: f64,
    /// Walking: smoothed speed between these (slower is standing or turning on the spot,
    /// faster is running or bounding), mm/s.
    pub walk_min_mm_s: f64,
    pub walk_max_mm_s: f64,
    /// Shortest walking bout, seconds.
    pub min_walk_s: f64,
    /// Rearing: head this high above the glass, mm.
    pub rear_head_mm: f64,
    /// Shortest rearing bout, seconds.
    pub min_rear_s: f64,
    /// By the walls: the body's centre within this of a wall, mm.
    pub wall_band_mm: f64,
    /// A paw found on the glass is in stance while it moves slower than this share of the
    /// body's speed plus the margin (planted, it stays put; in swing it overtakes the body).
    pub stance_speed_factor: f64,
    pub stance_margin_mm_s: f64,
    /// Strides with a period outside this range are not strides (a lost paw, a pause), s.
    pub min_stride_s: f64,
    pub max_stride_s: f64,
}

impl Default for BehaviourConfig {
    fn default() -> Self {
        Self {
            smooth_s: 0.2,
            walk_min_mm_s: 50.0,
            walk_max_mm_s: 200.0,
            min_walk_s: 0.4,
            rear_head_mm: 40.0,
            min_rear_s: 0.2,
            wall_band_mm: 60.0,
            stance_speed_factor: 1.2,
            stance_margin_mm_s: 20.0,
            min_stride_s: 0.08,
            max_stride_s: 1.0,
        }
    }
}

/// One frame's input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameInput {
    pub t_s: f64,
    /// The body's centre on the floor plane (mm), when the mouse was found.
    pub centre: Option<Point2<f64>>,
    /// Where the body points (tail base to neck), for the base of support.
    pub axis: Option<Vector2<f64>>,
    /// Height of the head above the glass, mm.
    pub head_z_mm: Option<f64>,
    /// Per paw (left fore, right fore, left hind, right hind): its place on the glass when
    /// the bottom camera found it there, `None` when not seen. The bottom view also finds a
    /// paw lifted a few millimetres in swing: stance is told from swing by the paw's speed.
    pub paws: [Option<Point2<f64>>; 4],
}

/// Where the body's centre was.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Zone {
    /// The central rectangle, half the cage's length and width.
    Centre,
    /// Within the wall band of a wall.
    Wall,
    /// Neither.
    Between,
    /// The mouse was not found.
    Unknown,
}

impl Zone {
    pub fn name(self) -> &'static str {
        match self {
            Zone::Centre => "centre",
            Zone::Wall => "wall",
            Zone::Between => "between",
            Zone::Unknown => "unknown",
        }
    }
}

/// Per frame results.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameResult {
    pub t_s: f64,
    pub speed_mm_s: Option<f64>,
    pub distance_mm: f64,
    pub zone: Zone,
    pub rearing: bool,
    pub walking: bool,
    /// Stance of each paw after one-frame gaps and blips are removed.
    pub stance: [bool; 4],
}

/// A bout of one behaviour.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Bout {
    pub start_s: f64,
    pub end_s: f64,
}

impl Bout {
    pub fn duration_s(&self) -> f64 {
        self.end_s - self.start_s
    }
}

/// One stride of one paw: from a touchdown to its next, within one walking bout.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Stride {
    /// 0 left fore, 1 right fore, 2 left hind, 3 right hind.
    pub paw: usize,
    pub start_s: f64,
    pub period_s: f64,
    /// Between the centres of the two stance phases' footprints, mm.
    pub length_mm: f64,
    /// Stance time over the period.
    pub duty_factor: f64,
}

/// The paws' names in the analysis's order.
pub const PAW_NAMES: [&str; 4] = ["left_fore", "right_fore", "left_hind", "right_hind"];

/// Per paw gait summary (medians over its strides).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PawGait {
    pub strides: usize,
    pub stride_length_mm: Option<f64>,
    /// Strides per second.
    pub cadence_hz: Option<f64>,
    pub duty_factor: Option<f64>,
}

/// The whole analysis.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Behaviour {
    pub duration_s: f64,
    pub distance_mm: f64,
    pub mean_speed_mm_s: Option<f64>,
    /// Seconds per zone, in [`Zone`] order: centre, wall, between, unknown.
    pub zone_s: [f64; 4],
    pub rearing: Vec<Bout>,
    pub walking: Vec<Bout>,
    pub strides: Vec<Stride>,
    pub paws: [PawGait; 4],
    /// Median distance across the body between the left and right paws both in stance, fore
    /// and hind, mm.
    pub base_of_support_fore_mm: Option<f64>,
    pub base_of_support_hind_mm: Option<f64>,
    /// Circular mean of the touchdown of each paw in the left hind paw's stride (0..1), paws
    /// in [`PAW_NAMES`] order (the left hind's own is 0).
    pub phase_to_left_hind: [Option<f64>; 4],
    pub frames: Vec<FrameResult>,
}

/// Runs of `true` as `(first, last)` index pairs.
fn runs(flags: &[bool]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &f) in flags.iter().enumerate() {
        match (f, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i - 1));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, flags.len() - 1));
    }
    out
}

/// Fills one-frame gaps in stance and removes one-frame stances (a missed or a spurious
/// detection), so that a stride is not cut in two.
fn clean_stance(flags: &[bool]) -> Vec<bool> {
    let mut out = flags.to_vec();
    for i in 1..flags.len().saturating_sub(1) {
        if !flags[i] && flags[i - 1] && flags[i + 1] {
            out[i] = true;
        }
    }
    let filled = out.clone();
    for i in 0..filled.len() {
        let before = i > 0 && filled[i - 1];
        let after = i + 1 < filled.len() && filled[i + 1];
        if filled[i] && !before && !after {
            out[i] = false;
        }
    }
    out
}

/// Centred moving average of the centres over `half` frames each side (frames without a
/// centre are left out of the average; a frame without one stays without).
fn smooth(centres: &[Option<Point2<f64>>], half: usize) -> Vec<Option<Point2<f64>>> {
    (0..centres.len())
        .map(|i| {
            centres[i]?;
            let lo = i.saturating_sub(half);
            let hi = (i + half).min(centres.len() - 1);
            let (sum, n) = centres[lo..=hi]
                .iter()
                .flatten()
                .fold((Vector2::zeros(), 0.0), |(s, n), p| (s + p.coords, n + 1.0));
            Some(Point2::from(sum / n))
        })
        .collect()
}

/// The bouts of `flags` lasting at least `min_s`, and the flags with shorter ones cleared.
fn bouts(t: &[f64], flags: &[bool], min_s: f64, dt: f64) -> (Vec<Bout>, Vec<bool>) {
    let mut kept = vec![false; flags.len()];
    let mut out = Vec::new();
    for (a, b) in runs(flags) {
        let bout = Bout {
            start_s: t[a],
            end_s: t[b] + dt,
        };
        if bout.duration_s() >= min_s {
            kept[a..=b].iter_mut().for_each(|k| *k = true);
            out.push(bout);
        }
    }
    (out, kept)
}

/// The arena the mouse moves in: a rectangle of the floor, world millimetres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Arena {
    pub x_min_mm: f64,
    pub y_min_mm: f64,
    pub x_max_mm: f64,
    pub y_max_mm: f64,
}

impl Arena {
    /// A cage of inside size `size_mm` centred on the origin.
    pub fn centred(size_mm: (f64, f64)) -> Self {
        Self {
            x_min_mm: -size_mm.0 / 2.0,
            y_min_mm: -size_mm.1 / 2.0,
            x_max_mm: size_mm.0 / 2.0,
            y_max_mm: size_mm.1 / 2.0,
        }
    }

    /// Its length and width, mm.
    pub fn size_mm(&self) -> (f64, f64) {
        (self.x_max_mm - self.x_min_mm, self.y_max_mm - self.y_min_mm)
    }

    pub fn centre(&self) -> Point2<f64> {
        Point2::new(
            (self.x_min_mm + self.x_max_mm) / 2.0,
            (self.y_min_mm + self.y_max_mm) / 2.0,
        )
    }
}

/// Directions from its centre at which an [`Outline`] gives the floor's reach (every 5 degrees).
pub const OUTLINE_RAYS: usize = 72;

/// An arena's own outline on the floor, as seen from its centre: how far the floor reaches
/// at [`OUTLINE_RAYS`] directions, counter-clockwise from the world's +x axis, so that a round
/// arena is round. Exact for any arena whose centre sees all of its floor (a disc, a
/// rectangle, a cross, a plus maze); a floor hidden behind a corner from the centre (an L or
/// a T maze's arm's far corner) is cut off.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Outline {
    /// The centre of the floor's points (world x, y, mm).
    pub centre_mm: [f64; 2],
    /// The floor's reach from the centre at each direction (mm).
    pub reach_mm: Vec<f64>,
}

impl Outline {
    /// The outline of the floor's points (world x, y, mm): at each direction, the 99th
    /// percentile of their distances from their centre within that direction's 5 degrees (a
    /// few stray points do not widen it); `None` for fewer than [`OUTLINE_RAYS`] points or a
    /// direction that holds none.
    pub fn of_points(points: &[Point2<f64>]) -> Option<Self> {
        if points.len() < OUTLINE_RAYS {
            return None;
        }
        let centre = points.iter().fold(Vector2::zeros(), |a, p| a + p.coords) / points.len() as f64;
        let mut rays: Vec<Vec<f64>> = vec![Vec::new(); OUTLINE_RAYS];
        for p in points {
            let d = p.coords - centre;
            rays[ray_of(d)].push(d.norm());
        }
        let reach_mm = rays
            .into_iter()
            .map(|mut r| {
                r.sort_by(f64::total_cmp);
                r.get(((r.len().max(1) - 1) as f64 * 0.99).round() as usize).copied()
            })
            .collect::<Option<Vec<f64>>>()?;
        Some(Self {
            centre_mm: [centre.x, centre.y],
            reach_mm,
        })
    }

    pub fn centre(&self) -> Point2<f64> {
        Point2::new(self.centre_mm[0], self.centre_mm[1])
    }

    /// The outline's corners, one per direction (world x, y, mm), counter-clockwise.
    pub fn vertices(&self) -> Vec<Point2<f64>> {
        self.reach_mm
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let a = (k as f64 + 0.5) * std::f64::consts::TAU / self.reach_mm.len() as f64;
                self.centre() + Vector2::new(a.cos(), a.sin()) * *r
            })
            .collect()
    }

    /// The rectangle around it.
    pub fn bounds(&self) -> Arena {
        let v = self.vertices();
        let (xs, ys) = (v.iter().map(|p| p.x), v.iter().map(|p| p.y));
        Arena {
            x_min_mm: xs.clone().fold(f64::INFINITY, f64::min),
            y_min_mm: ys.clone().fold(f64::INFINITY, f64::min),
            x_max_mm: xs.fold(f64::NEG_INFINITY, f64::max),
            y_max_mm: ys.fold(f64::NEG_INFINITY, f64::max),
        }
    }

    /// The zone of `p`: the centre (the outline shrunk to half its size about its centre, as
    /// the central rectangle of a rectangular arena is), the band within `wall_band_mm` of
    /// the outline (or outside it), or between.
    fn zone(&self, p: Point2<f64>, wall_band_mm: f64) -> Zone {
        let v = self.vertices();
        let d = p - self.centre();
        // The outline's reach toward p: where the ray from the centre meets the edge between
        // the two corners either side of it.
        let n = v.len();
        let step = std::f64::consts::TAU / n as f64;
        let theta = d.y.atan2(d.x).rem_euclid(std::f64::consts::TAU);
        let k = ((theta / step - 0.5).floor() as isize).rem_euclid(n as isize) as usize;
        let (a, e) = (v[k] - self.centre(), v[(k + 1) % n] - v[k]);
        let u = Vector2::new(theta.cos(), theta.sin());
        let reach = if cross(&u, &e).abs() < 1e-12 {
            a.norm()
        } else {
            cross(&a, &e) / cross(&u, &e)
        };
        let to_edge = (0..v.len())
            .map(|k| distance_to_segment(p, v[k], v[(k + 1) % v.len()]))
            .fold(f64::INFINITY, f64::min);
        if d.norm() >= reach || to_edge <= wall_band_mm {
            Zone::Wall
        } else if d.norm() <= reach / 2.0 {
            Zone::Centre
        } else {
            Zone::Between
        }
    }
}

/// The outline's direction of `d`.
fn ray_of(d: Vector2<f64>) -> usize {
    let a = d.y.atan2(d.x).rem_euclid(std::f64::consts::TAU);
    ((a / std::f64::consts::TAU * OUTLINE_RAYS as f64) as usize).min(OUTLINE_RAYS - 1)
}

fn cross(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

fn distance_to_segment(p: Point2<f64>, a: Point2<f64>, b: Point2<f64>) -> f64 {
    let e = b - a;
    let t = if e.norm_squared() > 0.0 {
        ((p - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + e * t)).norm()
}

/// The cage's zone of a centre (the cage centred on the origin, `cage_mm` its inside size).
pub fn zone(p: Option<Point2<f64>>, cage_mm: (f64, f64), wall_band_mm: f64) -> Zone {
    zone_in(p, &Arena::centred(cage_mm), None, wall_band_mm)
}

/// The zone of a centre in `arena`, or in its `outline` where the replay found one (see
/// [`Outline::zone`]): the central rectangle of half its length and width, the band along its
/// walls, or between.
pub fn zone_in(p: Option<Point2<f64>>, arena: &Arena, outline: Option<&Outline>, wall_band_mm: f64) -> Zone {
    let Some(p) = p else { return Zone::Unknown };
    if let Some(outline) = outline {
        return outline.zone(p, wall_band_mm);
    }
    let p = p - arena.centre().coords;
    let (hx, hy) = (arena.size_mm().0 / 2.0, arena.size_mm().1 / 2.0);
    if p.x.abs() <= hx / 2.0 && p.y.abs() <= hy / 2.0 {
        Zone::Centre
    } else if hx - p.x.abs() <= wall_band_mm || hy - p.y.abs() <= wall_band_mm {
        Zone::Wall
    } else {
        Zone::Between
    }
}

/// Analyses `frames` (in time order) in a cage of `cage_mm` inside size centred on the
/// origin.
pub fn analyse(frames: &[FrameInput], cage_mm: (f64, f64), config: &BehaviourConfig) -> Behaviour {
    analyse_in(frames, &Arena::centred(cage_mm), None, config)
}

/// Analyses `frames` (in time order) in `arena`, zoned by its `outline` when there is one.
pub fn analyse_in(
    frames: &[FrameInput],
    arena: &Arena,
    outline: Option<&Outline>,
    config: &BehaviourConfig,
) -> Behaviour {
    let n = frames.len();
    let t: Vec<f64> = frames.iter().map(|f| f.t_s).collect();
    let dt = frame_step(&t);
    let half = ((config.smooth_s / dt / 2.0).round() as usize).max(1);
    let centres: Vec<Option<Point2<f64>>> = frames.iter().map(|f| f.centre).collect();
    let smoothed = smooth(&centres, half);
    let speed = centre_speeds(&smoothed, &t);
    let (distance, cumulative) = distances(&smoothed);

    let rear_flags: Vec<bool> = frames
        .iter()
        .map(|f| f.head_z_mm.is_some_and(|z| z >= config.rear_head_mm))
        .collect();
    let (rearing, rear_flags) = bouts(&t, &rear_flags, config.min_rear_s, dt);
    let walk_flags: Vec<bool> = (0..n)
        .map(|i| !rear_flags[i] && speed[i].is_some_and(|v| (config.walk_min_mm_s..=config.walk_max_mm_s).contains(&v)))
        .collect();
    let (walking, walk_flags) = bouts(&t, &walk_flags, config.min_walk_s, dt);
    let walk_id = walk_ids(&walk_flags);

    let stance: [Vec<bool>; 4] = std::array::from_fn(|k| stance_of(frames, k, &t, &speed, config));
    let mut strides = Vec::new();
    let mut touchdowns: [Vec<(f64, Option<usize>)>; 4] = Default::default();
    for (k, flags) in stance.iter().enumerate() {
        let (mine, touched) = paw_strides(frames, k, flags, &t, &walk_id, dt, config);
        strides.extend(mine);
        touchdowns[k] = touched;
    }
    let paws: [PawGait; 4] = std::array::from_fn(|k| gait_of(&strides, k));
    let phase_to_left_hind = phases_to_left_hind(&strides, &touchdowns);

    let mut zone_s = [0.0; 4];
    let frames_out: Vec<FrameResult> = (0..n)
        .map(|i| {
            let z = zone_in(centres[i], arena, outline, config.wall_band_mm);
            let slot = match z {
                Zone::Centre => 0,
                Zone::Wall => 1,
                Zone::Between => 2,
                Zone::Unknown => 3,
            };
            zone_s[slot] += dt;
            FrameResult {
                t_s: t[i],
                speed_mm_s: speed[i],
                distance_mm: cumulative[i],
                zone: z,
                rearing: rear_flags[i],
                walking: walk_flags[i],
                stance: std::array::from_fn(|k| stance[k][i]),
            }
        })
        .collect();
    let mut speeds: Vec<f64> = speed.iter().flatten().copied().collect();
    let mean_speed = (!speeds.is_empty()).then(|| speeds.iter().sum::<f64>() / speeds.len() as f64);
    speeds.clear();
    Behaviour {
        duration_s: n as f64 * dt,
        distance_mm: distance,
        mean_speed_mm_s: mean_speed,
        zone_s,
        rearing,
        walking,
        base_of_support_fore_mm: base_of_support(frames, &walk_flags, &stance, 0, 1),
        base_of_support_hind_mm: base_of_support(frames, &walk_flags, &stance, 2, 3),
        phase_to_left_hind,
        strides,
        paws,
        frames: frames_out,
    }
}

/// The frames' time step: the median of the positive steps between times `t` (1/30 s when
/// there are none).
fn frame_step(t: &[f64]) -> f64 {
    if t.len() > 1 {
        let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        crate::core::median(&mut steps).unwrap_or(1.0 / 30.0)
    } else {
        1.0 / 30.0
    }
}

/// Speed: central differences of the smoothed centre.
fn centre_speeds(smoothed: &[Option<Point2<f64>>], t: &[f64]) -> Vec<Option<f64>> {
    let n = t.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
            match (smoothed.get(a).copied().flatten(), smoothed.get(b).copied().flatten()) {
                (Some(p), Some(q)) if t[b] > t[a] => Some((q - p).norm() / (t[b] - t[a])),
                _ => None,
            }
        })
        .collect()
}

/// Distance: the smoothed centre's steps, in all and up to each frame.
fn distances(smoothed: &[Option<Point2<f64>>]) -> (f64, Vec<f64>) {
    let n = smoothed.len();
    let mut distance = 0.0;
    let mut cumulative = Vec::with_capacity(n);
    for i in 0..n {
        if i > 0
            && let (Some(p), Some(q)) = (smoothed[i - 1], smoothed[i])
        {
            distance += (q - p).norm();
        }
        cumulative.push(distance);
    }
    (distance, cumulative)
}

/// Each frame's walking bout, numbered from 1 (`None` outside one).
fn walk_ids(walk_flags: &[bool]) -> Vec<Option<usize>> {
    let mut id = None;
    let mut count = 0;
    (0..walk_flags.len())
        .map(|i| {
            if walk_flags[i] {
                if i == 0 || !walk_flags[i - 1] {
                    count += 1;
                }
                id = Some(count);
                id
            } else {
                None
            }
        })
        .collect()
}

/// Paw `k`'s stance per frame: planted when it moves slower than the body allows, cleaned
/// of single-frame flickers.
fn stance_of(frames: &[FrameInput], k: usize, t: &[f64], speed: &[Option<f64>], config: &BehaviourConfig) -> Vec<bool> {
    let planted: Vec<bool> = (0..frames.len())
        .map(|i| {
            let Some(p) = frames[i].paws[k] else { return false };
            // The step to the next frame (to the one before at the end): a paw stands
            // at a frame when it stays put until the next.
            let step = |j: usize| {
                let f = frames.get(j)?;
                let q = f.paws[k]?;
                let dt = (f.t_s - t[i]).abs();
                (dt > 0.0).then(|| (q - p).norm() / dt)
            };
            let Some(paw_speed) = step(i + 1).or_else(|| i.checked_sub(1).and_then(step)) else {
                return false;
            };
            let body = speed[i].unwrap_or(0.0);
            paw_speed < config.stance_speed_factor * body + config.stance_margin_mm_s
        })
        .collect();
    clean_stance(&planted)
}

/// Paw `k`'s strides (from one touchdown to the next within a walking bout) and its
/// touchdowns (time and walking bout).
fn paw_strides(
    frames: &[FrameInput],
    k: usize,
    flags: &[bool],
    t: &[f64],
    walk_id: &[Option<usize>],
    dt: f64,
    config: &BehaviourConfig,
) -> (Vec<Stride>, Vec<(f64, Option<usize>)>) {
    let phases: Vec<(usize, usize, Option<Point2<f64>>)> = runs(flags)
        .into_iter()
        .map(|(a, b)| {
            let (sum, m) = frames[a..=b]
                .iter()
                .filter_map(|f| f.paws[k])
                .fold((Vector2::zeros(), 0.0), |(s, m), p| (s + p.coords, m + 1.0));
            (a, b, (m > 0.0).then(|| Point2::from(sum / m)))
        })
        .collect();
    let mut strides = Vec::new();
    for w in phases.windows(2) {
        let ((a, b, pa), (c, _, pc)) = (w[0], w[1]);
        // Both touchdowns in the same walking bout, and a stance that began after the
        // paw was seen in swing (not at the start of the sequence).
        if walk_id[a].is_none() || walk_id[a] != walk_id[c] || a == 0 {
            continue;
        }
        let period = t[c] - t[a];
        if !(config.min_stride_s..=config.max_stride_s).contains(&period) {
            continue;
        }
        let (Some(pa), Some(pc)) = (pa, pc) else { continue };
        strides.push(Stride {
            paw: k,
            start_s: t[a],
            period_s: period,
            length_mm: (pc - pa).norm(),
            duty_factor: ((t[b] + dt - t[a]) / period).min(1.0),
        });
    }
    let touchdowns = phases.iter().map(|&(a, _, _)| (t[a], walk_id[a])).collect();
    (strides, touchdowns)
}

/// Paw `k`'s gait: the medians of its strides.
fn gait_of(strides: &[Stride], k: usize) -> PawGait {
    let mine: Vec<&Stride> = strides.iter().filter(|s| s.paw == k).collect();
    let med = |f: fn(&Stride) -> f64| crate::core::median(&mut mine.iter().map(|s| f(s)).collect::<Vec<_>>());
    PawGait {
        strides: mine.len(),
        stride_length_mm: med(|s| s.length_mm),
        cadence_hz: med(|s| 1.0 / s.period_s),
        duty_factor: med(|s| s.duty_factor),
    }
}

/// Base of support: across the body axis, both paws of a girdle (`l`, `r`) in stance,
/// walking.
fn base_of_support(
    frames: &[FrameInput],
    walk_flags: &[bool],
    stance: &[Vec<bool>; 4],
    l: usize,
    r: usize,
) -> Option<f64> {
    let mut widths: Vec<f64> = (0..frames.len())
        .filter(|&i| walk_flags[i] && stance[l][i] && stance[r][i])
        .filter_map(|i| {
            let f = &frames[i];
            let (a, b, axis) = (f.paws[l]?, f.paws[r]?, f.axis?);
            let across = Vector2::new(-axis.y, axis.x).try_normalize(1e-9)?;
            Some((a - b).dot(&across).abs())
        })
        .collect();
    crate::core::median(&mut widths)
}

/// Inter-limb phase: each paw's touchdown within the left hind paw's strides.
fn phases_to_left_hind(strides: &[Stride], touchdowns: &[Vec<(f64, Option<usize>)>; 4]) -> [Option<f64>; 4] {
    let reference = 2;
    std::array::from_fn(|k| {
        let mut angles = Vec::new();
        for s in strides.iter().filter(|s| s.paw == reference) {
            let end = s.start_s + s.period_s;
            if let Some(&(tk, _)) = touchdowns[k].iter().find(|(tk, _)| *tk >= s.start_s && *tk < end) {
                angles.push(std::f64::consts::TAU * (tk - s.start_s) / s.period_s);
            }
        }
        if angles.is_empty() {
            return None;
        }
        let (sx, sy) = angles.iter().fold((0.0, 0.0), |(x, y), a| (x + a.cos(), y + a.sin()));
        Some((sy.atan2(sx) / std::f64::consts::TAU).rem_euclid(1.0))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mouse walking along x at `v` mm/s with a stride of `stride` mm, duty factor `duty`,
    /// paws in the diagonal pairs of a walk, every paw seen in stance and in swing.
    fn walker(v: f64, stride: f64, duty: f64, seconds: f64) -> Vec<FrameInput> {
        let fps = 30.0;
        let phases = [0.0, 0.5, 0.5, 0.0];
        let side = [10.0, -10.0, 12.0, -12.0];
        let ahead = [25.0, 25.0, -25.0, -25.0];
        (0..(seconds * fps) as usize)
            .map(|i| {
                let t = i as f64 / fps;
                let x = -200.0 + v * t;
                // A quarter frame off the cycle's start, so no frame falls on a lift-off.
                let cycle = v * t / stride + 0.025;
                let paws = std::array::from_fn(|k| {
                    let p = (cycle + phases[k]).rem_euclid(1.0);
                    // Planted at the footprint of its current cycle while in stance.
                    let footprint = (cycle + phases[k]).floor() * stride - phases[k] * stride - 200.0 + ahead[k];
                    // In swing the bottom camera still sees the paw, moving to its next footprint.
                    let swing = if p < duty {
                        0.0
                    } else {
                        stride * (p - duty) / (1.0 - duty)
                    };
                    Some(Point2::new(footprint + swing, side[k]))
                });
                FrameInput {
                    t_s: t,
                    centre: Some(Point2::new(x, 0.0)),
                    axis: Some(Vector2::x()),
                    head_z_mm: Some(if (2.0..2.5).contains(&t) { 60.0 } else { 18.0 }),
                    paws,
                }
            })
            .collect()
    }

    #[test]
    fn a_regular_walk_gives_its_stride_cadence_duty_and_phases() {
        let frames = walker(90.0, 30.0, 0.6, 4.0);
        let b = analyse(&frames, (500.0, 450.0), &BehaviourConfig::default());
        assert!((b.distance_mm - 90.0 * 4.0).abs() < 15.0, "{}", b.distance_mm);
        assert_eq!(b.rearing.len(), 1);
        assert!((b.rearing[0].duration_s() - 0.5).abs() < 0.05);
        for (k, p) in b.paws.iter().enumerate() {
            assert!(p.strides >= 5, "paw {k}: {p:?}");
            assert!((p.stride_length_mm.unwrap() - 30.0).abs() < 1.5, "paw {k}: {p:?}");
            assert!((p.cadence_hz.unwrap() - 3.0).abs() < 0.3, "paw {k}: {p:?}");
            assert!((p.duty_factor.unwrap() - 0.6).abs() < 0.08, "paw {k}: {p:?}");
        }
        let phase = b.phase_to_left_hind;
        let near = |a: Option<f64>, want: f64| {
            let d = (a.unwrap() - want).rem_euclid(1.0);
            d.min(1.0 - d) < 0.08
        };
        assert!(
            near(phase[2], 0.0) && near(phase[3], 0.5) && near(phase[1], 0.0) && near(phase[0], 0.5),
            "{phase:?}"
        );
        assert!((b.base_of_support_hind_mm.unwrap() - 24.0).abs() < 1e-6);
        assert!((b.base_of_support_fore_mm.unwrap() - 20.0).abs() < 1e-6);
    }

    #[test]
    fn zones_split_an_arena_away_from_the_origin() {
        let arena = Arena {
            x_min_mm: 100.0,
            y_min_mm: -50.0,
            x_max_mm: 400.0,
            y_max_mm: 250.0,
        };
        assert_eq!(
            zone_in(Some(Point2::new(250.0, 100.0)), &arena, None, 40.0),
            Zone::Centre
        );
        assert_eq!(zone_in(Some(Point2::new(0.0, 0.0)), &arena, None, 40.0), Zone::Wall);
        assert_eq!(zone_in(Some(Point2::new(380.0, 100.0)), &arena, None, 40.0), Zone::Wall);
        assert_eq!(
            zone_in(Some(Point2::new(330.0, 100.0)), &arena, None, 40.0),
            Zone::Between
        );
        // The synthetic cage, as before.
        assert_eq!(zone(Some(Point2::new(240.0, 0.0)), (500.0, 450.0), 60.0), Zone::Wall);
    }

    #[test]
    fn a_round_arena_is_zoned_by_its_own_outline_not_its_square() {
        // The floor of a round arena 400 mm across, centred at (50, -20), seen every 4 mm.
        let mut floor = Vec::new();
        for i in -60..=60 {
            for j in -60..=60 {
                let p = Point2::new(50.0 + 4.0 * f64::from(i), -20.0 + 4.0 * f64::from(j));
                if (p - Point2::new(50.0, -20.0)).norm() <= 200.0 {
                    floor.push(p);
                }
            }
        }
        let outline = Outline::of_points(&floor).unwrap();
        assert!((outline.centre() - Point2::new(50.0, -20.0)).norm() < 1.0);
        assert!(
            outline.reach_mm.iter().all(|r| (r - 200.0).abs() < 6.0),
            "{:?}",
            outline.reach_mm
        );
        let square = outline.bounds();
        let at = |x: f64, y: f64| Some(Point2::new(50.0 + x, -20.0 + y));
        // A corner of the square is outside the round arena: by the wall, not between.
        assert_eq!(zone_in(at(130.0, 130.0), &square, None, 40.0), Zone::Between);
        assert_eq!(zone_in(at(130.0, 130.0), &square, Some(&outline), 40.0), Zone::Wall);
        // 20 mm from the wall along a diagonal; the centre disc is half the radius.
        assert_eq!(zone_in(at(127.0, -127.0), &square, Some(&outline), 40.0), Zone::Wall);
        assert_eq!(zone_in(at(0.0, 90.0), &square, Some(&outline), 40.0), Zone::Centre);
        assert_eq!(zone_in(at(-120.0, 0.0), &square, Some(&outline), 40.0), Zone::Between);
        assert_eq!(zone_in(at(-300.0, 0.0), &square, Some(&outline), 40.0), Zone::Wall);
        // Too few points for an outline.
        assert_eq!(Outline::of_points(&floor[..10]), None);
    }

    #[test]
    fn zones_split_the_cage() {
        let cage = (500.0, 450.0);
        assert_eq!(zone(Some(Point2::new(0.0, 0.0)), cage, 60.0), Zone::Centre);
        assert_eq!(zone(Some(Point2::new(240.0, 0.0)), cage, 60.0), Zone::Wall);
        assert_eq!(zone(Some(Point2::new(150.0, 0.0)), cage, 60.0), Zone::Between);
        assert_eq!(zone(None, cage, 60.0), Zone::Unknown);
    }
}
