//! A mouse and its camera measured from the segmented frames alone, without labels: the
//! body's length and width (MoSeq's second moments, the tail left out), its back's height, a
//! visible tail, the floor's noise; and the figures that judge a run's poses without labels
//! (`adapt` reports them before and after fitting the models to a lab's mice). Pure code.

use crate::vision::segment::Mouse;
use crate::vision::tail::{TailSearch, find_tail};
use nalgebra::{Isometry3, Point2, Point3, Vector2};
use serde::Serialize;

/// A body shorter than this many times its width is taken for curled up (grooming, sleeping,
/// turning on the spot), and is left out of the body's measures.
pub const CURLED_RATIO: f64 = 1.3;
/// The back's height: this percentile of the body's readings above the floor.
const BACK_PERCENTILE: f64 = 0.95;

/// One frame's mouse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyMeasure {
    /// Length and width along and across the body (mm, the tail left out).
    pub length_mm: f64,
    pub width_mm: f64,
    /// The back's height above the floor (mm): the 95th percentile of the body's readings.
    pub height_mm: f64,
    /// The visible tail's length (mm), when a tail is seen.
    pub tail_mm: Option<f64>,
    /// The body is curled up ([`CURLED_RATIO`]).
    pub curled: bool,
}

/// Measures the segmented `mouse` of a camera of focal length `fx` (px) placed at
/// `world_from_camera` (the world's z: height above the floor). `None` without readings.
pub fn measure_mouse(mouse: &Mouse, world_from_camera: &Isometry3<f64>, fx: f64) -> Option<BodyMeasure> {
    if mouse.points_mm.is_empty() || fx <= 0.0 || mouse.width_mm <= 0.0 {
        return None;
    }
    let mut heights: Vec<f64> = mouse
        .points_mm
        .iter()
        .map(|p| (world_from_camera * Point3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))).z)
        .collect();
    heights.sort_by(f64::total_cmp);
    let height_mm = quantile(&heights, BACK_PERCENTILE)?;
    let depth = mouse.points_mm.iter().map(|p| f64::from(p.z)).sum::<f64>() / mouse.points_mm.len() as f64;
    let mm_per_px = depth / fx;
    let mask: Vec<bool> = mouse.mask.iter().map(|&m| m != 0).collect();
    let (w, h) = (mouse.region.width as usize, mouse.region.height as usize);
    let tail = find_tail(&mask, w, h, &TailSearch::at_scale(mm_per_px));
    Some(BodyMeasure {
        length_mm: mouse.length_mm,
        width_mm: mouse.width_mm,
        height_mm,
        tail_mm: tail.map(|t| t.length_px * mm_per_px),
        curled: mouse.length_mm < CURLED_RATIO * mouse.width_mm,
    })
}

/// The `q` quantile (0-1) of sorted values, by the nearest rank; `None` when empty.
pub fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let k = ((sorted.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    sorted.get(k).copied()
}

/// The 25th, 50th and 75th percentiles of some values.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Spread {
    pub p25: f64,
    pub p50: f64,
    pub p75: f64,
}

impl Spread {
    /// The spread of `values`; `None` when there are none.
    pub fn of(values: impl IntoIterator<Item = f64>) -> Option<Self> {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        Some(Self {
            p25: quantile(&v, 0.25)?,
            p50: quantile(&v, 0.5)?,
            p75: quantile(&v, 0.75)?,
        })
    }
}

/// A mouse measured over many frames.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BodySummary {
    /// Frames measured, and of those the ones curled up (left out of the body's measures).
    pub frames: usize,
    pub curled: usize,
    pub length_mm: Spread,
    pub width_mm: Spread,
    pub height_mm: Spread,
    /// The share of the frames measured that show a tail, and the tail's length where seen.
    pub tail_seen: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tail_mm: Option<Spread>,
}

impl BodySummary {
    /// The summary of `frames`; `None` when no frame shows the mouse stretched out.
    pub fn of(frames: &[BodyMeasure]) -> Option<Self> {
        let stretched: Vec<&BodyMeasure> = frames.iter().filter(|m| !m.curled).collect();
        let tails: Vec<f64> = frames.iter().filter_map(|m| m.tail_mm).collect();
        Some(Self {
            frames: frames.len(),
            curled: frames.len() - stretched.len(),
            length_mm: Spread::of(stretched.iter().map(|m| m.length_mm))?,
            width_mm: Spread::of(stretched.iter().map(|m| m.width_mm))?,
            height_mm: Spread::of(stretched.iter().map(|m| m.height_mm))?,
            tail_seen: tails.len() as f64 / frames.len().max(1) as f64,
            tail_mm: Spread::of(tails),
        })
    }
}

/// The floor's noise in one frame (mm, one standard deviation by the median absolute
/// deviation): each `step`-th pixel of the arena (`arena`, non-zero inside, over the frame)
/// outside `keep_out` (the mouse's box, widened) that reads both in `depth` and in the empty
/// cage's `background`. `None` with fewer than 100 such pixels.
pub fn floor_noise_mm(
    depth: &[u16],
    background: &[f32],
    arena: &[u8],
    width: usize,
    keep_out: Option<(usize, usize, usize, usize)>,
    step: usize,
) -> Option<f64> {
    let mut diffs: Vec<f64> = Vec::new();
    for k in (0..depth.len().min(background.len()).min(arena.len())).step_by(step.max(1)) {
        let (x, y) = (k % width.max(1), k / width.max(1));
        if keep_out.is_some_and(|(x0, y0, x1, y1)| (x0..x1).contains(&x) && (y0..y1).contains(&y)) {
            continue;
        }
        let (d, b) = (depth[k], background[k]);
        if arena[k] == 0 || d == 0 || b <= 0.0 {
            continue;
        }
        diffs.push(f64::from(d) - f64::from(b));
    }
    if diffs.len() < 100 {
        return None;
    }
    diffs.sort_by(f64::total_cmp);
    let median = quantile(&diffs, 0.5)?;
    let mut dev: Vec<f64> = diffs.iter().map(|d| (d - median).abs()).collect();
    dev.sort_by(f64::total_cmp);
    Some(1.4826 * quantile(&dev, 0.5)?)
}

/// One frame of a run as the figures without labels see it: the body's joints projected
/// into the depth image, and the segmented mask there.
#[derive(Clone, Debug, PartialEq)]
pub struct JudgedFrame {
    /// The frame's time (s).
    pub time_s: f64,
    /// The segmented body's centroid on the floor (mm), and the pose's direction
    /// `tail_base -> snout` (mm).
    pub centre_mm: Point2<f64>,
    pub forward: Vector2<f64>,
    /// How many of the body's joints fall on the mask (widened by a pixel), of those given.
    pub joints_on_mask: usize,
    pub joints: usize,
    /// The angle between the body's axis projected into the image and the mask's own long
    /// axis (degrees, 0-90), when the mask has one.
    pub axis_deg: Option<f64>,
}

/// The figures of a run judged without labels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Unlabelled {
    /// Frames judged (with a pose and a mask).
    pub frames: usize,
    /// Frames where the mouse travels faster than [`TRAVEL_MM_S`], and of those the share
    /// where the head leads (the body points the way it goes).
    pub moving_frames: usize,
    pub head_leading: f64,
    /// Frames in brief reversals: the heading turned past 90 degrees for one or two frames
    /// and back, which no mouse does in 67 ms.
    pub brief_reversals: usize,
    /// Turns of the heading past 90 degrees from one frame to the next (flips, whether they
    /// came back or not), per 1,000 frames.
    pub flips_per_1000: f64,
    /// The share of the body's joints that fall on the mask.
    pub joints_on_mouse: f64,
    /// The body's axis against the mask's: median and 95th percentile (degrees).
    pub axis_deg_median: f64,
    pub axis_deg_p95: f64,
}

/// Travel faster than this (mm/s) says which way the mouse faces.
pub const TRAVEL_MM_S: f64 = 100.0;
/// Travel is measured over this many frames, centred.
const TRAVEL_FRAMES: usize = 9;

/// The figures of `frames` (in time order, consecutive frames of a run).
pub fn unlabelled(frames: &[JudgedFrame]) -> Unlabelled {
    let n = frames.len();
    let half = TRAVEL_FRAMES / 2;
    let (mut moving, mut leading) = (0usize, 0usize);
    for i in half..n.saturating_sub(half) {
        let (a, b) = (&frames[i - half], &frames[i + half]);
        let dt = b.time_s - a.time_s;
        if dt <= 0.0 {
            continue;
        }
        let v = (b.centre_mm - a.centre_mm) / dt;
        if v.norm() <= TRAVEL_MM_S {
            continue;
        }
        moving += 1;
        leading += usize::from(frames[i].forward.dot(&v) > 0.0);
    }
    let dirs: Vec<Vector2<f64>> = frames.iter().map(|f| f.forward).collect();
    let mut reversed = vec![false; n];
    for a in 1..n.saturating_sub(1) {
        for length in 1..=2 {
            if a + length >= n {
                continue;
            }
            let (before, after) = (dirs[a - 1], dirs[a + length]);
            if before.dot(&after) > 0.0
                && (0..length).all(|j| dirs[a + j].dot(&before) < 0.0 && dirs[a + j].dot(&after) < 0.0)
            {
                for j in 0..length {
                    reversed[a + j] = true;
                }
            }
        }
    }
    let flips = dirs.windows(2).filter(|w| w[0].dot(&w[1]) < 0.0).count();
    let (on, given) = frames
        .iter()
        .fold((0, 0), |(o, g), f| (o + f.joints_on_mask, g + f.joints));
    let mut axis: Vec<f64> = frames.iter().filter_map(|f| f.axis_deg).collect();
    axis.sort_by(f64::total_cmp);
    Unlabelled {
        frames: n,
        moving_frames: moving,
        head_leading: leading as f64 / moving.max(1) as f64,
        brief_reversals: reversed.iter().filter(|&&r| r).count(),
        flips_per_1000: 1000.0 * flips as f64 / n.max(1) as f64,
        joints_on_mouse: on as f64 / given.max(1) as f64,
        axis_deg_median: quantile(&axis, 0.5).unwrap_or(f64::NAN),
        axis_deg_p95: quantile(&axis, 0.95).unwrap_or(f64::NAN),
    }
}

/// The angle (degrees, 0-90) between two axes of the image, whatever their signs.
pub fn axis_angle_deg(a: &Vector2<f64>, b: &Vector2<f64>) -> f64 {
    let cos = (a.dot(b) / (a.norm() * b.norm()).max(1e-12)).abs().min(1.0);
    cos.acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(t: f64, x: f64, forward: (f64, f64)) -> JudgedFrame {
        JudgedFrame {
            time_s: t,
            centre_mm: Point2::new(x, 0.0),
            forward: Vector2::new(forward.0, forward.1),
            joints_on_mask: 10,
            joints: 12,
            axis_deg: Some(5.0),
        }
    }

    #[test]
    fn a_mouse_walking_head_first_leads_and_one_flipped_frame_is_a_brief_reversal() {
        // 200 mm/s along +x, facing +x, one frame facing back.
        let mut frames: Vec<JudgedFrame> = (0..30)
            .map(|i| frame(i as f64 / 30.0, 200.0 * i as f64 / 30.0, (1.0, 0.0)))
            .collect();
        frames[15].forward = Vector2::new(-1.0, 0.0);
        let u = unlabelled(&frames);
        assert_eq!(u.frames, 30);
        assert_eq!(u.moving_frames, 22);
        assert!((u.head_leading - 21.0 / 22.0).abs() < 1e-9, "{u:?}");
        assert_eq!(u.brief_reversals, 1);
        assert!((u.flips_per_1000 - 2000.0 / 30.0).abs() < 1e-9);
        assert!((u.joints_on_mouse - 10.0 / 12.0).abs() < 1e-9);
        assert_eq!(u.axis_deg_median, 5.0);
    }

    #[test]
    fn spreads_take_the_nearest_rank_and_the_floor_noise_is_the_deviations_median() {
        let s = Spread::of((1..=5).map(f64::from)).unwrap_or_else(|| panic!("values"));
        assert_eq!((s.p25, s.p50, s.p75), (2.0, 3.0, 4.0));
        assert!(Spread::of([]).is_none());
        let background = vec![600.0f32; 400];
        // Readings 2 mm below, at and above the floor in turn: the deviations' median is 2 mm.
        let depth: Vec<u16> = (0..400).map(|k| 598 + 2 * (k % 3) as u16).collect();
        let arena = vec![1u8; 400];
        let sigma = floor_noise_mm(&depth, &background, &arena, 20, None, 1).unwrap_or(0.0);
        assert!((sigma - 2.0 * 1.4826).abs() < 1e-9, "{sigma}");
        assert_eq!(
            floor_noise_mm(&depth, &background, &arena, 20, Some((0, 0, 20, 19)), 1),
            None
        );
        assert!((axis_angle_deg(&Vector2::new(1.0, 0.0), &Vector2::new(-1.0, 1.0)) - 45.0).abs() < 1e-9);
    }
}
