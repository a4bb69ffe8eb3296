//! Which end of the mouse is its head, from the shape of its body seen from above: a small
//! logistic model over the silhouette and the height profile aligned along the body's long
//! axis, learnt on rendered mice whose tails were hidden (`mousepose train orientation`).
//! MoSeq decides the same question with a classifier on the aligned height map. No rule here
//! says which end is which: the features are symmetric in the two ends and the weights are
//! learnt.
//!
//! The features are antisymmetric: reversing the axis negates every one of them, and the model
//! has no intercept, so it gives exactly opposite log-odds for the two directions of the same
//! axis and cannot prefer one direction of the image over another.

use nalgebra::{DMatrix, DVector, Point2, Point3, Vector2};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Slices along the body's length.
pub const BINS: usize = 8;
/// Measures per slice: its share of the body's area, its mean and highest points, its width
/// and its share of low points.
const PER_BIN: usize = 5;
/// Features of one view: each slice measure at one end less the same at the other end, for
/// the outer [`BINS`]` / 2` pairs of slices, then the skew of the body along its axis and the
/// correlation of height with the position along it.
pub const FEATURES: usize = PER_BIN * BINS / 2 + 2;
/// Fewest mouse points a view needs for features.
pub const MIN_POINTS: usize = 30;
/// The points below this share of the body's height count as low (tail, snout, feet).
const LOW_SHARE: f64 = 0.4;
/// The model file's name in a models directory.
pub const MODEL_FILE: &str = "orientation.json";
const FORMAT: &str = "mousepose-orientation";
const FORMAT_VERSION: u32 = 1;

/// The features of one view.
pub type Features = [f64; FEATURES];

/// The body's long axis seen from above (unit length, its sign arbitrary but fixed by the
/// features), its centre, and the features that go with that axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aligned {
    pub axis: Vector2<f64>,
    pub centre: Point2<f64>,
    pub features: Features,
}

/// The aligned features of a mouse's points (world frame, mm; z is the height above the
/// floor), or `None` for fewer than [`MIN_POINTS`] or a body with no length or height.
pub fn aligned(points: &[Point3<f64>]) -> Option<Aligned> {
    let n = points.len();
    if n < MIN_POINTS {
        return None;
    }
    let nf = n as f64;
    let centre = points.iter().fold(Vector2::zeros(), |a, p| a + Vector2::new(p.x, p.y)) / nf;
    let axis = main_direction(points, centre);
    let across = Vector2::new(-axis.y, axis.x);
    let rows: Vec<[f64; 3]> = points
        .iter()
        .map(|p| {
            let d = Vector2::new(p.x, p.y) - centre;
            [d.dot(&axis), d.dot(&across), p.z]
        })
        .collect();
    let mut heights: Vec<f64> = rows.iter().map(|r| r[2]).collect();
    heights.sort_by(f64::total_cmp);
    let top = heights[(0.95 * (n - 1) as f64) as usize];
    if top <= 1.0 {
        return None;
    }
    let (lo, hi, mass) = body_ends(&rows);
    let length = hi - lo;
    if length < 1.0 || mass <= 0.0 {
        return None;
    }
    let mut features = bin_features(&rows, lo, length, top);
    let (skew, slope) = skew_and_slope(&rows);
    features[FEATURES - 2] = skew;
    features[FEATURES - 1] = slope;
    Some(Aligned {
        axis,
        centre: Point2::from(centre),
        features,
    })
}

/// The main direction of the points' 2x2 scatter (in the floor plane) about `centre`.
fn main_direction(points: &[Point3<f64>], centre: Vector2<f64>) -> Vector2<f64> {
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in points {
        let (dx, dy) = (p.x - centre.x, p.y - centre.y);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Vector2::new(angle.cos(), angle.sin())
}

/// The body's ends along its axis (`rows`: along, across, height): where 1 % of its
/// height-weighted mass lies beyond (a thin tail on the floor weighs little, so it does not
/// stretch the body); and that mass.
fn body_ends(rows: &[[f64; 3]]) -> (f64, f64, f64) {
    let n = rows.len();
    let mut by_s: Vec<(f64, f64)> = rows.iter().map(|r| (r[0], r[2].max(0.0))).collect();
    by_s.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mass: f64 = by_s.iter().map(|x| x.1).sum();
    let quantile = |q: f64| {
        let mut acc = 0.0;
        for &(s, w) in &by_s {
            acc += w;
            if acc >= q * mass {
                return s;
            }
        }
        by_s[n - 1].0
    };
    (quantile(0.01), quantile(0.99), mass)
}

/// The per-bin features along the body (from `lo`, over `length`; `top` its height): each
/// bin's measures at the front half minus the mirrored bin's at the back.
fn bin_features(rows: &[[f64; 3]], lo: f64, length: f64, top: f64) -> [f64; FEATURES] {
    let nf = rows.len() as f64;
    // count, sum z, max z, sum t, sum t^2, low count
    let mut bins = [[0.0f64; 6]; BINS];
    for r in rows {
        let b = (((r[0] - lo) / length * BINS as f64).floor().max(0.0) as usize).min(BINS - 1);
        let bin = &mut bins[b];
        bin[0] += 1.0;
        bin[1] += r[2];
        bin[2] = bin[2].max(r[2]);
        bin[3] += r[1];
        bin[4] += r[1] * r[1];
        bin[5] += f64::from(u8::from(r[2] < LOW_SHARE * top));
    }
    let measures = |bin: &[f64; 6]| -> [f64; PER_BIN] {
        let c = bin[0];
        if c < 1.0 {
            return [0.0; PER_BIN];
        }
        let mean_t = bin[3] / c;
        let spread = (bin[4] / c - mean_t * mean_t).max(0.0).sqrt();
        [
            c / nf * BINS as f64,
            bin[1] / c / top,
            bin[2] / top,
            4.0 * spread / length,
            bin[5] / c,
        ]
    };
    let mut features = [0.0; FEATURES];
    for k in 0..BINS / 2 {
        let (plus, minus) = (measures(&bins[BINS - 1 - k]), measures(&bins[k]));
        for m in 0..PER_BIN {
            features[k * PER_BIN + m] = plus[m] - minus[m];
        }
    }
    features
}

/// The skewness of the points along the axis, and the correlation of height with the
/// position along it.
fn skew_and_slope(rows: &[[f64; 3]]) -> (f64, f64) {
    let nf = rows.len() as f64;
    let mean_s = rows.iter().map(|r| r[0]).sum::<f64>() / nf;
    let mean_z = rows.iter().map(|r| r[2]).sum::<f64>() / nf;
    let (mut m2, mut m3, mut zz, mut sz) = (0.0, 0.0, 0.0, 0.0);
    for r in rows {
        let (ds, dz) = (r[0] - mean_s, r[2] - mean_z);
        m2 += ds * ds;
        m3 += ds * ds * ds;
        zz += dz * dz;
        sz += ds * dz;
    }
    let sd = (m2 / nf).sqrt();
    let skew = if sd > 1e-9 { m3 / nf / sd.powi(3) } else { 0.0 };
    let slope = if m2 > 1e-9 && zz > 1e-9 {
        sz / (m2 * zz).sqrt()
    } else {
        0.0
    };
    (skew, slope)
}

/// How the model was made, for the record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The training dataset's seed and number of images, and the engine that rendered it.
    pub dataset_seed: u64,
    pub images: u64,
    pub engine_version: u32,
    /// Views the model was fitted on (each image with its tail hidden and as rendered, at the
    /// dataset's resolution and at half of it).
    pub views: usize,
    /// Share of those views it gets right.
    pub training_accuracy: f64,
}

/// The learnt model: log-odds of the head toward `+axis` = `sum(weights[k] * features[k] /
/// scale[k])`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeModel {
    pub format: String,
    pub format_version: u32,
    pub bins: usize,
    pub scale: Vec<f64>,
    pub weights: Vec<f64>,
    pub provenance: Provenance,
}

/// Why a model file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ShapeModelError {
    #[error("cannot read {path:?}")]
    Read {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path:?} is not an orientation model: {reason}")]
    Invalid { path: std::path::PathBuf, reason: String },
}

impl ShapeModel {
    /// The log-odds that the head lies toward `+axis` of `aligned`.
    pub fn log_odds(&self, features: &Features) -> f64 {
        features
            .iter()
            .zip(&self.scale)
            .zip(&self.weights)
            .map(|((f, s), w)| w * f / s)
            .sum()
    }

    /// Fits the model to `views` (features, and whether the head lies toward `+axis`) by
    /// Newton's method on the L2-penalised log-likelihood (`l2` on the scaled weights).
    pub fn fit(views: &[(Features, bool)], l2: f64, provenance: Provenance) -> Self {
        let n = views.len().max(1);
        let scale: Vec<f64> = (0..FEATURES)
            .map(|k| {
                let ms = views.iter().map(|v| v.0[k] * v.0[k]).sum::<f64>() / n as f64;
                if ms.sqrt() > 1e-9 { ms.sqrt() } else { 1.0 }
            })
            .collect();
        let x = DMatrix::from_fn(views.len(), FEATURES, |i, k| views[i].0[k] / scale[k]);
        let y = DVector::from_fn(views.len(), |i, _| f64::from(u8::from(views[i].1)));
        let mut w = DVector::<f64>::zeros(FEATURES);
        for _ in 0..30 {
            let p = (&x * &w).map(sigmoid);
            let gradient = x.transpose() * (&p - &y) + &w * l2;
            let weights = p.map(|p| (p * (1.0 - p)).max(1e-9));
            let mut hessian = x.transpose() * DMatrix::from_diagonal(&weights) * &x;
            for k in 0..FEATURES {
                hessian[(k, k)] += l2;
            }
            let Some(step) = hessian.lu().solve(&gradient) else {
                break;
            };
            w -= &step;
            if step.norm() < 1e-8 {
                break;
            }
        }
        Self {
            format: FORMAT.to_owned(),
            format_version: FORMAT_VERSION,
            bins: BINS,
            scale,
            weights: w.iter().copied().collect(),
            provenance,
        }
    }

    /// The share of `views` the model gets right.
    pub fn accuracy(&self, views: &[(Features, bool)]) -> f64 {
        let right = views
            .iter()
            .filter(|(f, head)| (self.log_odds(f) > 0.0) == *head)
            .count();
        right as f64 / views.len().max(1) as f64
    }

    /// Reads a model file.
    ///
    /// # Errors
    /// The file cannot be read, or is not a model of this version and size.
    pub fn load(path: &Path) -> Result<Self, ShapeModelError> {
        let text = std::fs::read_to_string(path).map_err(|source| ShapeModelError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let invalid = |reason: String| ShapeModelError::Invalid {
            path: path.to_path_buf(),
            reason,
        };
        let model: Self = serde_json::from_str(&text).map_err(|e| invalid(e.to_string()))?;
        if model.format != FORMAT || model.format_version != FORMAT_VERSION {
            return Err(invalid(format!(
                "format {:?} version {}, expected {FORMAT:?} version {FORMAT_VERSION}",
                model.format, model.format_version
            )));
        }
        if model.bins != BINS || model.weights.len() != FEATURES || model.scale.len() != FEATURES {
            return Err(invalid(format!(
                "{} slices and {} weights, expected {BINS} and {FEATURES}",
                model.bins,
                model.weights.len()
            )));
        }
        if model.weights.iter().chain(&model.scale).any(|v| !v.is_finite()) || model.scale.iter().any(|&s| s <= 0.0) {
            return Err(invalid("a weight or scale is not a finite number".to_owned()));
        }
        Ok(model)
    }

    /// Writes the model as JSON.
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(path, text + "\n")
    }
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body seen from above: an ellipse-like blob along x from -50 to 50 mm whose width and
    /// height follow `profile(u)` (u from 0 at -x to 1 at +x).
    fn blob(profile: impl Fn(f64) -> (f64, f64), turn: f64) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        let (c, s) = (turn.cos(), turn.sin());
        for i in 0..100 {
            let u = (f64::from(i) + 0.5) / 100.0;
            let (half_width, height) = profile(u);
            let mut y = -half_width;
            while y <= half_width {
                let x = 100.0 * u - 50.0;
                let z = height * (1.0 - (y / half_width.max(1e-3)).powi(2)).max(0.0).sqrt();
                out.push(Point3::new(c * x - s * y + 7.0, s * x + c * y - 3.0, z));
                y += 1.0;
            }
        }
        out
    }

    #[test]
    fn reversing_the_body_negates_every_feature() {
        let rear_heavy = |u: f64| (14.0 * (1.0 - (u - 0.35).abs()), 30.0 - 15.0 * u);
        let a = aligned(&blob(rear_heavy, 0.3)).unwrap();
        let b = aligned(&blob(rear_heavy, 0.3 + std::f64::consts::PI)).unwrap();
        let same_way = a.axis.dot(&b.axis) > 0.0;
        for k in 0..FEATURES {
            // The body turned round: against the same axis every feature changes sign.
            let (fa, fb) = (a.features[k], if same_way { b.features[k] } else { -b.features[k] });
            assert!((fa + fb).abs() < 1e-6 * (1.0 + fa.abs()), "feature {k}: {fa} and {fb}");
        }
        assert!(a.features.iter().any(|f| f.abs() > 0.05), "{:?}", a.features);
        assert!(aligned(&blob(rear_heavy, 0.0)[..MIN_POINTS - 1]).is_none());
    }

    #[test]
    fn a_fitted_model_learns_which_end_is_which_and_survives_its_file() {
        // Bodies whose heavy end is their head (as made up here, not as mice are): the model
        // is told nothing but the examples.
        let mut views = Vec::new();
        for i in 0..60 {
            let k = f64::from(i);
            let peak = 0.55 + 0.3 * (k * 0.37).sin().abs();
            let profile = move |u: f64| (8.0 + 6.0 * (1.0 - (u - peak).abs()), 18.0 + 10.0 * u);
            let a = aligned(&blob(profile, k * 0.41)).unwrap();
            // The head at +x of the blob: toward +axis when the axis points that way.
            let x_of_blob = Vector2::new((k * 0.41).cos(), (k * 0.41).sin());
            views.push((a.features, a.axis.dot(&x_of_blob) > 0.0));
        }
        let provenance = Provenance {
            dataset_seed: 0,
            images: 60,
            engine_version: 0,
            views: views.len(),
            training_accuracy: 0.0,
        };
        let model = ShapeModel::fit(&views, 1.0, provenance);
        assert_eq!(model.accuracy(&views), 1.0);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(MODEL_FILE);
        model.save(&path).unwrap();
        let back = ShapeModel::load(&path).unwrap();
        assert!(
            views
                .iter()
                .all(|(f, _)| (back.log_odds(f) - model.log_odds(f)).abs() < 1e-9)
        );
        std::fs::write(&path, "{\"format\": \"something else\"}").unwrap();
        assert!(matches!(ShapeModel::load(&path), Err(ShapeModelError::Invalid { .. })));
    }
}
