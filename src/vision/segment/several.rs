//! Several mice in one depth frame: which of the frame's strong pixels belong to which mouse
//! ([`Segmenter::claim`]), and each mouse segmented as if it were alone in the cage
//! ([`Segmenter::segment_mice`]): the other mice's pixels, and a margin around them, read as
//! the empty cage does, and the one-mouse segmentation ([`Segmenter::segment`]) runs on that.
//!
//! The strong pixels (step 1 of a frame) fall into 8-connected components. Mice apart are
//! components of their own; pieces smaller than [`PIECE_SHARE`] of the smallest mouse
//! (`min_area_mm2`) are noise or a tail and claim nothing. When fewer components than mice are
//! seen, touching mice share one: the components are given mice one at a time, each next mouse
//! to the component with the most pixels a mouse, while that is at least [`SPLIT_SHARE`] mice'
//! worth of the smallest mouse; a component of several mice is split by k-means on the pixels'
//! image positions, started from where the mice were seen last when that is inside it (so a
//! mouse keeps its side through a contact), or else from points spread along the component's
//! long axis.

use super::Mouse;
use super::{Grid, SegmentError, Segmenter, check_frame};
use crate::core::frame::DepthFrame;

/// A component smaller than this share of `min_area_mm2` claims no mouse.
pub const PIECE_SHARE: f64 = 0.25;
/// A component is split into one more mouse only while it holds at least this many times
/// `min_area_mm2` a mouse.
pub const SPLIT_SHARE: f64 = 1.5;
/// Pixels around another mouse's claim that read as the empty cage when a mouse is segmented
/// alone (its edges below the strong height, mixed pixels).
pub const CLAIM_MARGIN_PX: usize = 3;
/// Rounds of k-means when a component is split.
const KMEANS_ROUNDS: usize = 12;

/// The strong pixels one mouse claims in a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Claim {
    /// Indices into the frame (row-major), in raster order.
    pub pixels: Vec<u32>,
    /// Their mean position in the image (pixels).
    pub centre: (f64, f64),
}

impl Segmenter {
    /// The frame's strong pixels split among at most `count` mice (see the module
    /// documentation); `last` are where mice were seen in the frame before (image pixels), to
    /// start splits from. Fewer claims than `count` when fewer mice can be told apart; the
    /// claims are in no particular order of identity.
    ///
    /// # Errors
    /// A frame of another size than the background.
    pub fn claim(&mut self, frame: &DepthFrame, count: usize, last: &[(f64, f64)]) -> Result<Vec<Claim>, SegmentError> {
        check_frame(frame, self.background.region)?;
        let region = self.background.region;
        let (w, h) = (region.width as usize, region.height as usize);
        let grid = Grid {
            w,
            h,
            ox: 0,
            oy: 0,
            bg_w: w,
        };
        self.classify(&frame.data, &grid);
        let s = &mut self.scratch;
        let components = s.components.label(&s.strong, w, (0, 0, w, h), &mut s.labels);
        // Pixels per component, and the footprint of a pixel there (mm^2) from its mean depth.
        let mut pixels: Vec<Vec<u32>> = vec![Vec::new(); components + 1];
        for (i, &l) in s.labels[..w * h].iter().enumerate() {
            if l > 0 {
                pixels[l as usize].push(i as u32);
            }
        }
        let intrinsics = &self.background.intrinsics;
        let footprint = |px: &[u32]| -> f64 {
            px.iter()
                .map(|&i| {
                    let z = f64::from(frame.data[i as usize]);
                    (z / intrinsics.fx) * (z / intrinsics.fy)
                })
                .sum()
        };
        let smallest = f64::from(self.config.min_area_mm2);
        let mut blobs: Vec<(Vec<u32>, f64, usize)> = pixels
            .into_iter()
            .skip(1)
            .map(|px| {
                let area = footprint(&px);
                (px, area, 0)
            })
            .filter(|(_, area, _)| *area >= PIECE_SHARE * smallest)
            .collect();
        blobs.sort_by(|a, b| b.1.total_cmp(&a.1));
        blobs.truncate(count);
        for b in &mut blobs {
            b.2 = 1;
        }
        // More mice than components: the component with the most area a mouse takes one more.
        let mut given = blobs.len();
        while given < count {
            let Some(b) = blobs
                .iter_mut()
                .filter(|b| b.1 / b.2 as f64 >= SPLIT_SHARE * smallest)
                .max_by(|a, b| (a.1 / a.2 as f64).total_cmp(&(b.1 / b.2 as f64)))
            else {
                break;
            };
            b.2 += 1;
            given += 1;
        }
        let mut claims = Vec::new();
        for (px, _, mice) in blobs {
            if mice == 1 {
                claims.push(claim_of(px, w));
            } else {
                claims.extend(split(&px, w, mice, last).into_iter().map(|p| claim_of(p, w)));
            }
        }
        Ok(claims)
    }

    /// Each of the frame's mice (at most `count`) segmented alone (see the module
    /// documentation), in the order of their claims; `last` as [`Self::claim`] takes it.
    ///
    /// # Errors
    /// As [`Self::segment`].
    pub fn segment_mice(
        &mut self,
        frame: &DepthFrame,
        count: usize,
        last: &[(f64, f64)],
    ) -> Result<Vec<Mouse>, SegmentError> {
        let claims = self.claim(frame, count, last)?;
        if claims.len() <= 1 {
            return Ok(self.segment(frame)?.into_iter().collect());
        }
        let (w, h) = (frame.width as usize, frame.height as usize);
        let mut owner = vec![0u8; w * h];
        for (k, c) in claims.iter().enumerate() {
            for &i in &c.pixels {
                owner[i as usize] = k as u8 + 1;
            }
        }
        let near = spread(&owner, w, h, CLAIM_MARGIN_PX);
        let mut mice = Vec::with_capacity(claims.len());
        let mut alone = frame.clone();
        for k in 0..claims.len() {
            let me = k as u8 + 1;
            for (i, (out, &d)) in alone.data.iter_mut().zip(&frame.data).enumerate() {
                let other = near[i] != 0 && near[i] != me && owner[i] != me;
                *out = if other {
                    self.background.depth.get(i).map_or(0, |&b| b.round() as u16)
                } else {
                    d
                };
            }
            if let Some(m) = self.segment(&alone)? {
                mice.push(m);
            }
        }
        Ok(mice)
    }
}

/// The claim of `pixels` (frame indices) in a frame `w` pixels wide.
fn claim_of(mut pixels: Vec<u32>, w: usize) -> Claim {
    pixels.sort_unstable();
    let n = pixels.len().max(1) as f64;
    let (sx, sy) = pixels.iter().fold((0.0, 0.0), |(sx, sy), &i| {
        (sx + (i as usize % w) as f64, sy + (i as usize / w) as f64)
    });
    Claim {
        pixels,
        centre: (sx / n, sy / n),
    }
}

/// `pixels` split into `k` groups by k-means on their positions, started from the points of
/// `last` that lie near them when there are `k` such, or else from points spread along their
/// long axis.
fn split(pixels: &[u32], w: usize, k: usize, last: &[(f64, f64)]) -> Vec<Vec<u32>> {
    let at = |i: u32| ((i as usize % w) as f64, (i as usize / w) as f64);
    let n = pixels.len() as f64;
    let (mx, my) = pixels.iter().fold((0.0, 0.0), |(sx, sy), &i| {
        let (x, y) = at(i);
        (sx + x / n, sy + y / n)
    });
    // The long axis from the second moments.
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &i in pixels {
        let (x, y) = at(i);
        let (dx, dy) = (x - mx, y - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let (ux, uy) = (angle.cos(), angle.sin());
    for &i in pixels {
        let (x, y) = at(i);
        let t = (x - mx) * ux + (y - my) * uy;
        lo = f64::min(lo, t);
        hi = f64::max(hi, t);
    }
    // `last`'s points inside the component's box, nearest first.
    let (mut x0, mut y0, mut x1, mut y1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for &i in pixels {
        let (x, y) = at(i);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    let inside: Vec<(f64, f64)> = last
        .iter()
        .copied()
        .filter(|&(x, y)| (x0..=x1).contains(&x) && (y0..=y1).contains(&y))
        .collect();
    let mut centres: Vec<(f64, f64)> = if inside.len() == k {
        inside
    } else {
        (0..k)
            .map(|j| {
                let t = lo + (hi - lo) * (j as f64 + 0.5) / k as f64;
                (mx + t * ux, my + t * uy)
            })
            .collect()
    };
    let mut group = vec![0usize; pixels.len()];
    for _ in 0..KMEANS_ROUNDS {
        for (g, &i) in group.iter_mut().zip(pixels) {
            let (x, y) = at(i);
            *g = (0..k)
                .min_by(|&a, &b| {
                    let da = (x - centres[a].0).powi(2) + (y - centres[a].1).powi(2);
                    let db = (x - centres[b].0).powi(2) + (y - centres[b].1).powi(2);
                    da.total_cmp(&db)
                })
                .unwrap_or(0);
        }
        let mut sums = vec![(0.0, 0.0, 0usize); k];
        for (&g, &i) in group.iter().zip(pixels) {
            let (x, y) = at(i);
            sums[g].0 += x;
            sums[g].1 += y;
            sums[g].2 += 1;
        }
        for (c, s) in centres.iter_mut().zip(&sums) {
            if s.2 > 0 {
                *c = (s.0 / s.2 as f64, s.1 / s.2 as f64);
            }
        }
    }
    let mut out = vec![Vec::new(); k];
    for (&g, &i) in group.iter().zip(pixels) {
        out[g].push(i);
    }
    out.retain(|p| !p.is_empty());
    out
}

/// Each pixel's owner (`owner`, 0 = none) spread `radius` pixels into its neighbours that have
/// none (a square's reach; where two spread into the same pixel, either).
fn spread(owner: &[u8], w: usize, h: usize, radius: usize) -> Vec<u8> {
    let mut rows = owner.to_vec();
    for y in 0..h {
        let row = &owner[y * w..(y + 1) * w];
        for x in 0..w {
            if row[x] == 0 {
                let from = x.saturating_sub(radius);
                let to = (x + radius + 1).min(w);
                rows[y * w + x] = row[from..to].iter().copied().find(|&o| o != 0).unwrap_or(0);
            }
        }
    }
    let mut out = rows.clone();
    for y in 0..h {
        for x in 0..w {
            if out[y * w + x] == 0 {
                let from = y.saturating_sub(radius);
                let to = (y + radius + 1).min(h);
                out[y * w + x] = (from..to).map(|yy| rows[yy * w + x]).find(|&o| o != 0).unwrap_or(0);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_component_splits_across_its_long_axis_and_from_where_the_mice_were() {
        // A 40 x 10 bar: two mice nose to tail.
        let w = 50;
        let pixels: Vec<u32> = (0..10).flat_map(|y| (5..45).map(move |x| (y * w + x) as u32)).collect();
        let parts = split(&pixels, w, 2, &[]);
        assert_eq!(parts.len(), 2);
        for p in &parts {
            assert_eq!(p.len(), 200);
            let xs: Vec<usize> = p.iter().map(|&i| i as usize % w).collect();
            assert!(xs.iter().all(|&x| x < 25) || xs.iter().all(|&x| x >= 25), "{xs:?}");
        }
        // Side by side instead, told where they were: split along the bar.
        let parts = split(&pixels, w, 2, &[(25.0, 1.0), (25.0, 8.0)]);
        for p in &parts {
            let ys: Vec<usize> = p.iter().map(|&i| i as usize / w).collect();
            assert!(ys.iter().all(|&y| y < 5) || ys.iter().all(|&y| y >= 5), "{ys:?}");
        }
    }

    #[test]
    fn owners_spread_into_unowned_neighbours_only() {
        let (w, h) = (7, 5);
        let mut owner = vec![0u8; w * h];
        owner[2 * w + 1] = 1;
        owner[2 * w + 5] = 2;
        let near = spread(&owner, w, h, 1);
        assert_eq!(near[2 * w + 1], 1);
        assert_eq!(near[w], 1);
        assert_eq!(near[3 * w + 6], 2);
        assert_eq!(near[2 * w + 3], 0);
    }
}
