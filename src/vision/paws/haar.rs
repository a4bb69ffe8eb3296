//! Haar-like features: weighted sums of two or three upright rectangles of a detection window,
//! normalised by the window's contrast exactly as OpenCV's cascade evaluator does, so that a
//! threshold learnt here means the same thing to OpenCV's `CascadeClassifier`.
//!
//! The BASIC set follows OpenCV's training tool: two-rectangle edges (the whole with weight -1,
//! one half with +2), three-rectangle lines (the whole -1, the middle third +3) and the
//! four-rectangle checker (the whole -1, two diagonal quarters +2), each horizontal and
//! vertical, at every position and size inside the window.

use super::integral::Integral;

/// One weighted rectangle of a feature, in window pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HaarRect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
    pub weight: f32,
}

/// A Haar-like feature: two or three weighted rectangles (upright only).
#[derive(Clone, Debug, PartialEq)]
pub struct HaarFeature {
    pub rects: Vec<HaarRect>,
}

impl HaarFeature {
    fn new(rects: &[(u32, u32, u32, u32, f32)]) -> Self {
        Self {
            rects: rects
                .iter()
                .map(|&(x, y, width, height, weight)| HaarRect {
                    x,
                    y,
                    width,
                    height,
                    weight,
                })
                .collect(),
        }
    }

    /// Whether every rectangle lies inside a `width x height` window.
    pub fn fits(&self, width: u32, height: u32) -> bool {
        self.rects
            .iter()
            .all(|r| r.width > 0 && r.height > 0 && r.x + r.width <= width && r.y + r.height <= height)
    }

    /// The raw (not normalised) value at the window whose top-left corner is `(x, y)` of `ii`,
    /// in OpenCV's single-precision arithmetic.
    #[inline]
    pub fn raw(&self, ii: &Integral, x: usize, y: usize) -> f32 {
        let mut acc = 0.0f32;
        for r in &self.rects {
            if r.weight != 0.0 {
                let s = ii.rect_sum(x + r.x as usize, y + r.y as usize, r.width as usize, r.height as usize);
                acc += r.weight * s as f32;
            }
        }
        acc
    }
}

/// The BASIC Haar feature set of a `width x height` window.
pub fn basic_features(width: u32, height: u32) -> Vec<HaarFeature> {
    let (w, h) = (width, height);
    let mut out = Vec::new();
    for x in 0..w {
        for y in 0..h {
            for dx in 1..=w {
                for dy in 1..=h {
                    // Edge, horizontal: left half against the whole.
                    if x + 2 * dx <= w && y + dy <= h {
                        out.push(HaarFeature::new(&[(x, y, 2 * dx, dy, -1.0), (x + dx, y, dx, dy, 2.0)]));
                    }
                    // Edge, vertical.
                    if x + dx <= w && y + 2 * dy <= h {
                        out.push(HaarFeature::new(&[(x, y, dx, 2 * dy, -1.0), (x, y + dy, dx, dy, 2.0)]));
                    }
                    // Line, horizontal: the middle third.
                    if x + 3 * dx <= w && y + dy <= h {
                        out.push(HaarFeature::new(&[(x, y, 3 * dx, dy, -1.0), (x + dx, y, dx, dy, 3.0)]));
                    }
                    // Line, vertical.
                    if x + dx <= w && y + 3 * dy <= h {
                        out.push(HaarFeature::new(&[(x, y, dx, 3 * dy, -1.0), (x, y + dy, dx, dy, 3.0)]));
                    }
                    // Checker: two diagonal quarters.
                    if x + 2 * dx <= w && y + 2 * dy <= h {
                        out.push(HaarFeature::new(&[
                            (x, y, 2 * dx, 2 * dy, -1.0),
                            (x, y, dx, dy, 2.0),
                            (x + dx, y + dy, dx, dy, 2.0),
                        ]));
                    }
                }
            }
        }
    }
    out
}

/// The contrast normalisation of the `width x height` window at `(x, y)`: OpenCV's rule over
/// the window shrunk by one pixel on each side. Returns the factor that multiplies every raw
/// feature value, and whether the window has enough contrast to be classified at all (OpenCV
/// rejects windows whose standard deviation is 10 grey levels or less before any stage).
#[inline]
pub fn window_norm(ii: &Integral, x: usize, y: usize, width: usize, height: usize) -> (f32, bool) {
    let (nw, nh) = (width.saturating_sub(2), height.saturating_sub(2));
    let area = (nw * nh) as f64;
    let sum = ii.rect_sum(x + 1, y + 1, nw, nh);
    let sqsum = ii.rect_sqsum(x + 1, y + 1, nw, nh);
    let nf = area * f64::from(sqsum) - f64::from(sum) * f64::from(sum);
    if nf > 0.0 {
        let factor = (1.0 / nf.sqrt()) as f32;
        (factor, area * f64::from(factor) < 0.1)
    } else {
        (1.0, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(grey: &[u8], w: usize, f: &HaarFeature, x: usize, y: usize) -> f64 {
        f.rects
            .iter()
            .map(|r| {
                let mut s = 0.0;
                for yy in 0..r.height as usize {
                    for xx in 0..r.width as usize {
                        s += f64::from(grey[(y + r.y as usize + yy) * w + x + r.x as usize + xx]);
                    }
                }
                f64::from(r.weight) * s
            })
            .sum()
    }

    #[test]
    fn feature_values_match_brute_force_sums() {
        let (w, h) = (20, 17);
        let grey: Vec<u8> = (0..w * h).map(|i| ((i * 91 + 7) % 251) as u8).collect();
        let mut ii = Integral::default();
        ii.compute(&grey, w, h);
        let features = basic_features(6, 6);
        for f in features.iter().step_by(7) {
            for (x, y) in [(0, 0), (3, 5), (14, 11)] {
                let got = f64::from(f.raw(&ii, x, y));
                let want = brute(&grey, w, f, x, y);
                assert!((got - want).abs() < 1e-3, "{f:?} at ({x}, {y}): {got} vs {want}");
            }
        }
    }

    #[test]
    fn basic_set_fits_the_window_and_has_the_expected_size() {
        let features = basic_features(6, 6);
        assert!(features.iter().all(|f| f.fits(6, 6)));
        // Count by kind, brute force.
        let edge = |n: u32| -> u32 { (1..=n / 2).map(|d| n - 2 * d + 1).sum() };
        let line = |n: u32| -> u32 { (1..=n / 3).map(|d| n - 3 * d + 1).sum() };
        let all = |n: u32| -> u32 { (1..=n).map(|d| n - d + 1).sum() };
        let expected = 2 * edge(6) * all(6) + 2 * line(6) * all(6) + edge(6) * edge(6);
        assert_eq!(features.len() as u32, expected);
        // Every feature's weights cancel over a flat window.
        for f in &features {
            let flat: f32 = f.rects.iter().map(|r| r.weight * (r.width * r.height) as f32).sum();
            assert!(flat.abs() < 1e-6, "{f:?}");
        }
    }

    #[test]
    fn flat_windows_are_rejected_and_textured_ones_normalised() {
        let mut ii = Integral::default();
        ii.compute(&[40; 100], 10, 10);
        assert!(!window_norm(&ii, 0, 0, 10, 10).1);
        let grey: Vec<u8> = (0..100)
            .map(|i| if (i / 10 + i % 10) % 2 == 0 { 0 } else { 200 })
            .collect();
        ii.compute(&grey, 10, 10);
        let (factor, ok) = window_norm(&ii, 0, 0, 10, 10);
        assert!(ok);
        // 64 pixels with standard deviation 100: nf = area * sd * area... = 64 * 100.
        assert!((f64::from(factor) - 1.0 / 6400.0).abs() < 1e-9);
    }
}
