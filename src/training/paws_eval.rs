//! Evaluation of a paw detector on a held-back dataset's bottom views.
//!
//! Rules, fixed here and documented with the command:
//! * A detection matches a paw when its centre lies within half the paw box's larger side of
//!   the box's centre. Detections are matched greedily, surest first, each to the nearest
//!   paw not matched yet.
//! * Recall is over paws on the glass that the bottom camera sees (`contact && visible`).
//! * Precision is over detections: one matching a paw on the glass is a true positive; one
//!   matching a paw off the glass (or hidden) is neither true nor false, since the paw is
//!   really there; any other (including a second detection of a matched paw) is false.
//! * The centre error is the distance, in full-frame pixels, from a true positive's centre
//!   to its paw box's centre.
//! * A false detection is counted as on a mark when its centre lies in the box of one of the
//!   view's marks (glare, glass marks, pale belly fur: `synth dataset --bottom-clutter`),
//!   else as on the body when it lies within [`LANDMARK_RADIUS_MM`] of one of the body's
//!   look-alikes of paws (snout, chin, throat, belly, genitals, tail base,
//!   [`super::paws_data::hard_places`]), else as elsewhere.

use super::paws_data::{DATASET_PX_PER_MM, PawDataError, bottom_frame, hard_places};
use crate::synth::dataset::Dataset;
use crate::synth::views::Mark;
use crate::vision::paws::{PawDetection, PawModel};
use serde::Serialize;
use std::path::Path;

/// One point of the precision-recall curve: detections with `score >= min_score`.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct CurvePoint {
    pub min_score: f64,
    pub precision: f64,
    pub recall: f64,
}

/// What `eval paws` reports.
#[derive(Clone, Debug, Serialize)]
pub struct PawReport {
    pub images: usize,
    /// Paws on the glass and visible (the recall's denominator).
    pub contact_paws: usize,
    pub found_contact_paws: usize,
    pub detections: usize,
    pub true_positives: usize,
    pub false_positives: usize,
    /// Of the false positives, those on a mark of the view (glare, a glass mark, pale belly fur).
    pub false_on_marks: usize,
    /// Of the false positives, those on the body's look-alikes of paws (snout, chin, throat,
    /// belly, genitals, tail base).
    pub false_on_body: usize,
    /// Detections of lifted or hidden paws: neither true nor false.
    pub neutral: usize,
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
    pub mean_centre_error_px: f64,
    /// The colour camera's binning the views were seen at (1: the full sensor).
    pub color_binning: u32,
    /// A cascade's settings used for the figures above: the grouping at the views' scale (less
    /// than the cascade's own for binned views,
    /// [`crate::vision::paws::PawDetector::min_neighbors_at`]), the scales; `None` and none
    /// for a network.
    pub min_neighbors: Option<usize>,
    pub scales: Vec<f64>,
    /// Detections a view kept at most, the surest (0: all).
    pub max_paws: usize,
    /// Precision and recall as the minimum score varies (grouping with `minNeighbors = 0`).
    pub curve: Vec<CurvePoint>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Outcome {
    True(f64),
    False(FalseAt),
    Neutral,
}

/// Where a false detection lies.
#[derive(Clone, Copy, Debug, PartialEq)]
enum FalseAt {
    Mark,
    Body,
    Elsewhere,
}

/// How near (mm on the glass) to a body's look-alike of a paw a false detection is counted
/// as on it.
pub const LANDMARK_RADIUS_MM: f64 = 6.0;

/// What one image holds besides its paws: its marks and its body's look-alikes of paws
/// (full-frame pixels).
struct LookAlikes<'a> {
    marks: &'a [Mark],
    places: Vec<(f64, f64)>,
}

impl LookAlikes<'_> {
    fn classify(&self, (x, y): (f64, f64)) -> FalseAt {
        let on_mark = self.marks.iter().any(|m| {
            (f64::from(m.x0)..=f64::from(m.x1)).contains(&x) && (f64::from(m.y0)..=f64::from(m.y1)).contains(&y)
        });
        let radius = LANDMARK_RADIUS_MM * DATASET_PX_PER_MM;
        if on_mark {
            FalseAt::Mark
        } else if self.places.iter().any(|&(px, py)| (x - px).hypot(y - py) <= radius) {
            FalseAt::Body
        } else {
            FalseAt::Elsewhere
        }
    }
}

/// Matches one image's detections to its paws (see the module's rules).
fn match_image(
    dets: &mut [PawDetection],
    paws: &[crate::synth::views::PawBox; 4],
    look_alikes: &LookAlikes,
    out: &mut Vec<(f32, Outcome)>,
) {
    dets.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut taken = [false; 4];
    for d in dets.iter() {
        let (cx, cy) = d.centre();
        let mut best: Option<(usize, f64)> = None;
        for (k, p) in paws.iter().enumerate() {
            if p.x1 <= p.x0 || taken[k] {
                continue;
            }
            let (px, py) = (f64::from(p.x0 + p.x1) / 2.0, f64::from(p.y0 + p.y1) / 2.0);
            let radius = f64::from((p.x1 - p.x0).max(p.y1 - p.y0)) / 2.0;
            let dist = (cx - px).hypot(cy - py);
            if dist <= radius && best.is_none_or(|(_, b)| dist < b) {
                best = Some((k, dist));
            }
        }
        let outcome = match best {
            Some((k, dist)) => {
                taken[k] = true;
                if paws[k].contact && paws[k].visible {
                    Outcome::True(dist)
                } else {
                    Outcome::Neutral
                }
            }
            None => Outcome::False(look_alikes.classify((cx, cy))),
        };
        out.push((d.score, outcome));
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 { 0.0 } else { a as f64 / b as f64 }
}

/// Runs `detector` (as configured) on every bottom view of the dataset at `dir`, each seen by
/// a colour camera binned by `binning` ([`crate::synth::views::BottomView::binned`]; 1 is the
/// full sensor), keeping the `max_paws` surest detections of a view (all at 0;
/// [`crate::vision::paws::keep_surest`]). Boxes are matched in the full sensor's pixels.
///
/// # Errors
/// When the dataset cannot be read or has no visible paw on the glass.
pub fn evaluate(detector: &PawModel, dir: &Path, binning: u32, max_paws: usize) -> Result<PawReport, PawDataError> {
    let binning = binning.max(1);
    let ds = Dataset::open(dir)?;
    let rig = ds.meta.rig.unwrap_or_else(crate::core::geometry::Rig::default_rig);
    let mut headline = detector.clone();
    let mut all = detector.permissive();
    let mut dets = Vec::new();
    let mut outcomes = Vec::new();
    let mut curve_outcomes = Vec::new();
    let (mut images, mut contact) = (0, 0);
    ds.for_each(|sample| {
        let Some(view) = &sample.bottom else {
            return Ok(());
        };
        images += 1;
        contact += view
            .paws
            .iter()
            .filter(|p| p.contact && p.visible && p.x1 > p.x0)
            .count();
        let seen = view.binned(binning);
        let frame = bottom_frame(&seen);
        let roi = (0, 0, frame.width, frame.height);
        let (rx, ry, k) = (seen.region.x0 as f32, seen.region.y0 as f32, binning as f32);
        let shift = |d: &mut PawDetection| {
            d.x0 = (d.x0 + rx) * k;
            d.x1 = (d.x1 + rx) * k;
            d.y0 = (d.y0 + ry) * k;
            d.y1 = (d.y1 + ry) * k;
        };
        // Only the body's landmarks: the marks are classified by their boxes.
        let places = hard_places(&sample, &rig.color, &[]);
        let look_alikes = LookAlikes {
            marks: &view.marks,
            places,
        };
        let px_per_mm = DATASET_PX_PER_MM / f64::from(binning);
        headline.detect(&frame, roi, px_per_mm, &mut dets);
        crate::vision::paws::keep_surest(&mut dets, max_paws);
        dets.iter_mut().for_each(shift);
        match_image(&mut dets, &view.paws, &look_alikes, &mut outcomes);
        all.detect(&frame, roi, px_per_mm, &mut dets);
        crate::vision::paws::keep_surest(&mut dets, max_paws);
        dets.iter_mut().for_each(shift);
        match_image(&mut dets, &view.paws, &look_alikes, &mut curve_outcomes);
        Ok(())
    })?;
    if contact == 0 {
        return Err(PawDataError::NoPaws { path: dir.to_owned() });
    }
    let (tp, fp_at, neutral, err) = tally(&outcomes, f32::NEG_INFINITY);
    let fp = fp_at.iter().sum();
    let precision = ratio(tp, tp + fp);
    let recall = ratio(tp, contact);
    let f1 = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    let curve = precision_recall_curve(&curve_outcomes, contact);
    Ok(PawReport {
        images,
        contact_paws: contact,
        found_contact_paws: tp,
        detections: outcomes.len(),
        true_positives: tp,
        false_positives: fp,
        false_on_marks: fp_at[FalseAt::Mark as usize],
        false_on_body: fp_at[FalseAt::Body as usize],
        neutral,
        precision,
        recall,
        f1,
        mean_centre_error_px: if tp > 0 { err / tp as f64 } else { 0.0 },
        color_binning: binning,
        min_neighbors: match detector {
            PawModel::Cascade(c) => Some(c.min_neighbors_at(DATASET_PX_PER_MM / f64::from(binning))),
            PawModel::Net(_) => None,
        },
        scales: match detector {
            PawModel::Cascade(c) => c.scales().to_vec(),
            PawModel::Net(_) => Vec::new(),
        },
        max_paws,
        curve,
    })
}

/// The outcomes scored at least `min`: true detections, false ones by where they lie
/// ([`FalseAt`]), neutral ones, and the true ones' summed centre error (pixels).
fn tally(o: &[(f32, Outcome)], min: f32) -> (usize, [usize; 3], usize, f64) {
    let (mut t, mut f, mut n, mut err) = (0, [0usize; 3], 0, 0.0);
    for &(s, outcome) in o {
        if s < min {
            continue;
        }
        match outcome {
            Outcome::True(d) => {
                t += 1;
                err += d;
            }
            Outcome::False(at) => f[at as usize] += 1,
            Outcome::Neutral => n += 1,
        }
    }
    (t, f, n, err)
}

/// Precision and recall (of `contact` paws) at each score threshold the `outcomes` of every
/// raw window give: at most ~60 points, always including the extremes.
fn precision_recall_curve(outcomes: &[(f32, Outcome)], contact: usize) -> Vec<CurvePoint> {
    let mut thresholds: Vec<f32> = outcomes.iter().map(|o| o.0).collect();
    thresholds.sort_by(f32::total_cmp);
    thresholds.dedup();
    let stride = (thresholds.len() / 60).max(1);
    let mut curve = Vec::new();
    for (i, &t) in thresholds.iter().enumerate() {
        if i % stride != 0 && i + 1 != thresholds.len() {
            continue;
        }
        let (ct, cf, _, _) = tally(outcomes, t);
        let cf: usize = cf.iter().sum();
        curve.push(CurvePoint {
            min_score: f64::from(t),
            precision: ratio(ct, ct + cf),
            recall: ratio(ct, contact),
        });
    }
    curve
}
