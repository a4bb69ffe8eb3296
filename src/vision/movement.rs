//! Heading, turning, immobility and the variability of strides: the measures of a run that
//! [`crate::vision::behaviour`] leaves out, taken from the same per-frame input and from its
//! results (the smoothed body speed, the strides).
//!
//! Pure code, like `behaviour`: times, positions and the analysis in, numbers out.

use crate::vision::behaviour::{Behaviour, Bout, FrameInput};
use serde::Serialize;

/// Thresholds of the activity measures.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ActivityConfig {
    /// Immobile: the body's centre slower than this, mm/s (smoothed as for walking)...
    pub immobile_mm_s: f64,
    /// ...and the body axis turning slower than this, degrees/s...
    pub immobile_turn_deg_s: f64,
    /// ...for at least this long, s.
    pub min_immobile_s: f64,
    /// Freezing: an immobility bout at least this long, s.
    pub min_freezing_s: f64,
}

impl Default for ActivityConfig {
    fn default() -> Self {
        Self {
            immobile_mm_s: 10.0,
            immobile_turn_deg_s: 30.0,
            min_immobile_s: 0.5,
            min_freezing_s: 2.0,
        }
    }
}

/// The variability of one paw's strides: coefficients of variation (standard deviation over
/// mean) of their lengths and periods; `None` with fewer than 3 strides.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct StrideVariability {
    pub strides: usize,
    pub length_cv: Option<f64>,
    pub period_cv: Option<f64>,
}

/// The activity measures of a run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Activity {
    /// Per frame: where the body points (tail base to neck) seen from above, degrees
    /// counter-clockwise from the world's +x axis, in (-180, 180]; `None` without an axis.
    pub heading_deg: Vec<Option<f64>>,
    /// Per frame: how fast the heading turns (counter-clockwise positive), degrees/s,
    /// smoothed over the analysis's smoothing window; `None` where the heading is unknown.
    pub angular_speed_deg_s: Vec<Option<f64>>,
    /// Mean of the absolute angular speed over the frames that have one, degrees/s.
    pub mean_angular_speed_deg_s: Option<f64>,
    /// The heading's changes added up, the heading averaged over the smoothing window first:
    /// all of them (`turned_deg`) and with their signs (`net_turn_deg`, counter-clockwise
    /// positive), degrees.
    pub turned_deg: f64,
    pub net_turn_deg: f64,
    /// Per frame: immobile (in an immobility bout).
    pub immobile: Vec<bool>,
    pub immobility: Vec<Bout>,
    /// The immobility bouts long enough to count as freezing.
    pub freezing: Vec<Bout>,
    /// Per paw, in [`crate::vision::behaviour::PAW_NAMES`] order.
    pub stride_variability: [StrideVariability; 4],
}

impl Activity {
    pub fn immobile_s(&self) -> f64 {
        self.immobility.iter().map(Bout::duration_s).fold(0.0, |a, b| a + b)
    }

    pub fn freezing_s(&self) -> f64 {
        self.freezing.iter().map(Bout::duration_s).fold(0.0, |a, b| a + b)
    }
}

/// Wraps an angle to (-180, 180] degrees.
fn wrap_deg(a: f64) -> f64 {
    let w = a.rem_euclid(360.0);
    if w > 180.0 { w - 360.0 } else { w }
}

/// Coefficient of variation of `v`: sample standard deviation over the mean; `None` with
/// fewer than 3 values or a mean of 0.
fn cv(v: &[f64]) -> Option<f64> {
    if v.len() < 3 {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    if mean.abs() < 1e-12 {
        return None;
    }
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    Some(var.sqrt() / mean.abs())
}

/// The activity of `frames`, whose behaviour analysis is `b` (same frames, same order);
/// `smooth_s` is the analysis's smoothing window.
pub fn activity(frames: &[FrameInput], b: &Behaviour, smooth_s: f64, config: &ActivityConfig) -> Activity {
    let n = frames.len();
    let t: Vec<f64> = frames.iter().map(|f| f.t_s).collect();
    let heading: Vec<Option<f64>> = frames
        .iter()
        .map(|f| f.axis.map(|a| a.y.atan2(a.x).to_degrees()))
        .collect();
    let unwrapped = unwrap_headings(&heading);
    let dt = {
        let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        crate::core::median(&mut steps).unwrap_or(1.0 / 30.0)
    };
    let half = ((smooth_s / dt / 2.0).round() as usize).max(1);
    // The joints come smoothed over time already (`vision::smoothing`): the turning is
    // summed over half the analysis's window, so that the two do not smooth turns away twice.
    let turning_half = ((smooth_s / 2.0 / dt / 2.0).round() as usize).max(1);
    let (turned, net) = turning(&unwrapped, turning_half);
    let angular = angular_speeds(&unwrapped, &t, half);
    let known: Vec<f64> = angular.iter().flatten().map(|a| a.abs()).collect();
    let mean_angular = (!known.is_empty()).then(|| known.iter().sum::<f64>() / known.len() as f64);

    let still: Vec<bool> = (0..n)
        .map(|i| {
            let slow = b
                .frames
                .get(i)
                .and_then(|f| f.speed_mm_s)
                .is_some_and(|v| v < config.immobile_mm_s);
            // Without a heading the body's turning is unknown: speed alone decides.
            slow && angular[i].is_none_or(|a| a.abs() < config.immobile_turn_deg_s)
        })
        .collect();
    let (immobile, immobility) = immobility_bouts(&still, &t, dt, config.min_immobile_s);
    let freezing = immobility
        .iter()
        .filter(|x| x.duration_s() >= config.min_freezing_s)
        .copied()
        .collect();
    let stride_variability = std::array::from_fn(|k| {
        let mine: Vec<_> = b.strides.iter().filter(|s| s.paw == k).collect();
        let lengths: Vec<f64> = mine.iter().map(|s| s.length_mm).collect();
        let periods: Vec<f64> = mine.iter().map(|s| s.period_s).collect();
        StrideVariability {
            strides: mine.len(),
            length_cv: cv(&lengths),
            period_cv: cv(&periods),
        }
    });
    Activity {
        heading_deg: heading,
        angular_speed_deg_s: angular,
        mean_angular_speed_deg_s: mean_angular,
        turned_deg: turned,
        net_turn_deg: net,
        immobile,
        immobility,
        freezing,
        stride_variability,
    }
}

/// The heading unwrapped along each run of frames that have one, so a turn through 180
/// degrees is not a jump of 360.
fn unwrap_headings(heading: &[Option<f64>]) -> Vec<Option<f64>> {
    let mut unwrapped: Vec<Option<f64>> = vec![None; heading.len()];
    for (i, h) in heading.iter().enumerate() {
        let Some(h) = *h else { continue };
        unwrapped[i] = Some(match i.checked_sub(1).and_then(|p| unwrapped[p]) {
            Some(prev) => prev + wrap_deg(h - prev),
            None => h,
        });
    }
    unwrapped
}

/// Turned in all and net: the changes of the heading averaged over the smoothing window
/// (`half` frames each side, within its run of frames), as the body turns; each frame's own
/// estimate wobbles by a few degrees, and those wobbles added up frame by frame would count
/// several times the real turning (on a real mouse, 3.6 times the turning of MoSeq's own
/// angle).
fn turning(unwrapped: &[Option<f64>], half: usize) -> (f64, f64) {
    let n = unwrapped.len();
    let (mut turned, mut net) = (0.0, 0.0);
    let mut previous: Option<f64> = None;
    for i in 0..n {
        if unwrapped[i].is_none() {
            previous = None;
            continue;
        }
        // The smoothing window's reach within the run of frames around this one that have a
        // heading.
        let lo = (i.saturating_sub(half)..=i)
            .find(|&j| (j..=i).all(|k| unwrapped[k].is_some()))
            .unwrap_or(i);
        let hi = (i..=(i + half).min(n - 1))
            .rev()
            .find(|&j| (i..=j).all(|k| unwrapped[k].is_some()))
            .unwrap_or(i);
        // Centred on this frame, narrower toward the run's ends, so a steady turn counts in full.
        let m = (i - lo).min(hi - i);
        let mean = (i - m..=i + m).filter_map(|j| unwrapped[j]).sum::<f64>() / (2 * m + 1) as f64;
        if let Some(p) = previous {
            turned += (mean - p).abs();
            net += mean - p;
        }
        previous = Some(mean);
    }
    (turned, net)
}

/// Angular speed: the unwrapped heading's change across the smoothing window, over the
/// frames of the window that have a heading on both ends.
fn angular_speeds(unwrapped: &[Option<f64>], t: &[f64], half: usize) -> Vec<Option<f64>> {
    let n = unwrapped.len();
    (0..n)
        .map(|i| {
            unwrapped[i]?;
            let lo = (i.saturating_sub(half)..=i)
                .find(|&j| unwrapped[j].is_some() && (j..=i).all(|k| unwrapped[k].is_some()))?;
            let hi = (i..=(i + half).min(n - 1))
                .rev()
                .find(|&j| (i..=j).all(|k| unwrapped[k].is_some()))?;
            if t[hi] <= t[lo] {
                return None;
            }
            Some((unwrapped[hi]? - unwrapped[lo]?) / (t[hi] - t[lo]))
        })
        .collect()
}

/// The runs of `still` frames lasting at least `min_s`: each frame's flag, and the bouts.
fn immobility_bouts(still: &[bool], t: &[f64], dt: f64, min_s: f64) -> (Vec<bool>, Vec<Bout>) {
    let n = still.len();
    let mut immobile = vec![false; n];
    let mut immobility = Vec::new();
    let mut start = None;
    for i in 0..=n {
        let on = i < n && still[i];
        match (on, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                let bout = Bout {
                    start_s: t[s],
                    end_s: t[i - 1] + dt,
                };
                if bout.duration_s() >= min_s {
                    immobile[s..i].iter_mut().for_each(|x| *x = true);
                    immobility.push(bout);
                }
                start = None;
            }
            _ => {}
        }
    }
    (immobile, immobility)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::behaviour::{BehaviourConfig, analyse};
    use nalgebra::{Point2, Vector2};

    /// A mouse at `centre(t)` pointing at `heading(t)` degrees, 30 frames a second.
    fn frames(seconds: f64, centre: impl Fn(f64) -> Point2<f64>, heading: impl Fn(f64) -> f64) -> Vec<FrameInput> {
        (0..(seconds * 30.0) as usize)
            .map(|i| {
                let t = i as f64 / 30.0;
                let h = heading(t).to_radians();
                FrameInput {
                    t_s: t,
                    centre: Some(centre(t)),
                    axis: Some(Vector2::new(h.cos(), h.sin())),
                    head_z_mm: Some(18.0),
                    paws: [None; 4],
                }
            })
            .collect()
    }

    #[test]
    fn a_mouse_turning_on_the_spot_has_its_heading_and_angular_speed() {
        // Two full turns counter-clockwise at 90 deg/s, through +-180 degrees.
        let f = frames(8.0, |_| Point2::origin(), |t| 170.0 + 90.0 * t);
        let config = BehaviourConfig::default();
        let b = analyse(&f, (500.0, 450.0), &config);
        let a = activity(&f, &b, config.smooth_s, &ActivityConfig::default());
        assert!((a.heading_deg[0].unwrap() - 170.0).abs() < 1e-9);
        assert!((a.heading_deg[10].unwrap() - wrap_deg(170.0 + 30.0)).abs() < 1e-9);
        for (i, w) in a.angular_speed_deg_s.iter().enumerate() {
            assert!((w.unwrap() - 90.0).abs() < 1e-6, "frame {i}: {w:?}");
        }
        assert!((a.mean_angular_speed_deg_s.unwrap() - 90.0).abs() < 1e-6);
        let total = 90.0 * (f.len() - 1) as f64 / 30.0;
        assert!((a.net_turn_deg - total).abs() < 1e-6, "{}", a.net_turn_deg);
        assert!((a.turned_deg - total).abs() < 1e-6);
        // A heading that wobbles 5 degrees either way from frame to frame as it turns: what
        // was turned is the steady turn, not the wobbles added up.
        let wobbly = frames(
            8.0,
            |_| Point2::origin(),
            |t| 170.0 + 90.0 * t + 5.0 * (t * 30.0 * std::f64::consts::PI).cos(),
        );
        let w = activity(
            &wobbly,
            &analyse(&wobbly, (500.0, 450.0), &config),
            config.smooth_s,
            &ActivityConfig::default(),
        );
        // The runs' end frames keep their own wobble (5 degrees each way at either end).
        assert!((w.net_turn_deg - total).abs() < 15.0, "{}", w.net_turn_deg);
        assert!(
            (w.turned_deg - total).abs() < 0.1 * total,
            "{} for {total}",
            w.turned_deg
        );
        // Still, but turning: not immobile.
        assert!(a.immobility.is_empty(), "{:?}", a.immobility);
    }

    #[test]
    fn still_stretches_are_immobility_and_the_long_ones_freezing() {
        // Walks 1 s, stays put 3 s, walks 1 s, stays put 1 s, walks 1 s.
        let x = |t: f64| {
            let moving = [(0.0, 1.0), (4.0, 5.0), (6.0, 7.0)];
            moving.iter().map(|&(a, b)| 100.0 * (t.clamp(a, b) - a)).sum::<f64>()
        };
        let f = frames(7.0, |t| Point2::new(x(t), 0.0), |t| if t < 2.0 { 0.0 } else { 5.0 });
        let config = BehaviourConfig::default();
        let b = analyse(&f, (500.0, 450.0), &config);
        let a = activity(&f, &b, config.smooth_s, &ActivityConfig::default());
        assert_eq!(a.immobility.len(), 2, "{:?}", a.immobility);
        assert!((a.immobility[0].duration_s() - 3.0).abs() < 0.3, "{:?}", a.immobility);
        assert!((a.immobility[1].duration_s() - 1.0).abs() < 0.3, "{:?}", a.immobility);
        assert_eq!(a.freezing, vec![a.immobility[0]]);
        assert!((a.immobile_s() - 4.0).abs() < 0.5);
        let flagged = a.immobile.iter().filter(|x| **x).count() as f64 / 30.0;
        assert!((flagged - a.immobile_s()).abs() < 1e-9, "{flagged} {}", a.immobile_s());
    }

    #[test]
    fn stride_variability_is_the_coefficient_of_variation() {
        assert_eq!(cv(&[1.0, 2.0]), None);
        let v = cv(&[10.0, 12.0, 14.0]).unwrap();
        assert!((v - 2.0 / 12.0).abs() < 1e-12, "{v}");
        assert!(cv(&[30.0, 30.0, 30.0]).unwrap().abs() < 1e-12);
    }
}
