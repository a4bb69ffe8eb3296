//! Several mice in one depth frame: which of the frame's strong pixels belong to which mouse
//! ([`Segmenter::claim`]), and each mouse segmented as if it were alone in the cage
//! ([`Segmenter::segment_mice`]): the other mice's pixels, and a margin around them, read as
//! the empty cage does, and the one-mouse segmentation ([`Segmenter::segment`]) runs on that.
//!
//! The strong pixels (step 1 of a frame) fall into 8-connected components. Mice apart are
//! components of their own; pieces smaller than [`PIECE_SHARE`] of the smallest mouse
//! (`min_area_mm2`) are noise or a tail and claim nothing. When fewer components than mice are
//! seen, touching mice share one: the components are given mice one at a time, each next mouse
//! to the component with the most area a mouse, while that is at least [`SPLIT_SHARE`] mice'
//! worth of one mouse (the area a mouse of this cage covers, as the caller has seen it, else
//! the smallest mouse's), so that a mouse alone is not split when fewer mice are in view than
//! counted; a component of several mice is split by k-means on the pixels'
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

/// A frame's claims, and what was left unclaimed.
#[derive(Clone, Debug, PartialEq)]
pub struct Claims {
    pub claims: Vec<Claim>,
    /// Components of a whole mouse's area (`min_area_mm2`) beyond the mice counted: more mice
    /// seen than there are (clutter of a mouse's size, or a count set too low).
    pub beyond: usize,
    /// The area (mm^2, seen from above) of each component that claimed one mouse alone.
    pub areas: Vec<f64>,
}

/// A frame's mice, each segmented alone ([`Segmenter::segment_mice`]).
#[derive(Debug)]
pub struct SeveralMice {
    /// In the order of their claims.
    pub mice: Vec<Mouse>,
    /// As [`Claims::beyond`].
    pub beyond: usize,
    /// As [`Claims::areas`].
    pub areas: Vec<f64>,
}

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
    /// start splits from; `mouse_area` the area (mm^2) one mouse of the cage covers, when
    /// known. Fewer claims than `count` when fewer mice can be told apart; the claims are in
    /// no particular order of identity.
    ///
    /// # Errors
    /// A frame of another size than the background.
    pub fn claim(
        &mut self,
        frame: &DepthFrame,
        count: usize,
        last: &[(f64, f64)],
        mouse_area: Option<f64>,
    ) -> Result<Claims, SegmentError> {
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
        let beyond = blobs.iter().skip(count).filter(|b| b.1 >= smallest).count();
        blobs.truncate(count);
        for b in &mut blobs {
            b.2 = 1;
        }
        // More mice than components: the component with the most area a mouse takes one more.
        let mut given = blobs.len();
        while given < count {
            let Some(b) = blobs
                .iter_mut()
                .filter(|b| b.1 / b.2 as f64 >= SPLIT_SHARE * mouse_area.unwrap_or(smallest).max(smallest))
                .max_by(|a, b| (a.1 / a.2 as f64).total_cmp(&(b.1 / b.2 as f64)))
            else {
                break;
            };
            b.2 += 1;
            given += 1;
        }
        let areas = blobs.iter().filter(|b| b.2 == 1).map(|b| b.1).collect();
        let mut claims = Vec::new();
        for (px, _, mice) in blobs {
            if mice == 1 {
                claims.push(claim_of(px, w));
            } else {
                claims.extend(split(&px, w, mice, last).into_iter().map(|p| claim_of(p, w)));
            }
        }
        Ok(Claims { claims, beyond, areas })
    }

    /// Each of the frame's mice (at most `count`) segmented alone (see the module
    /// documentation), in the order of their claims, and how many more were seen; `last` and
    /// `mouse_area` as [`Self::claim`] takes them.
    ///
    /// # Errors
    /// As [`Self::segment`].
    pub fn segment_mice(
        &mut self,
        frame: &DepthFrame,
        count: usize,
        last: &[(f64, f64)],
        mouse_area: Option<f64>,
    ) -> Result<SeveralMice, SegmentError> {
        let Claims { claims, beyond, areas } = self.claim(frame, count, last, mouse_area)?;
        if claims.len() <= 1 {
            let mice = self.segment(frame)?.into_iter().collect();
            return Ok(SeveralMice { mice, beyond, areas });
        }
        let (w, h) = (frame.width as usize, frame.height as usize);
        let mut owner = vec![0u8; w * h];
        for (k, c) in claims.iter().enumerate() {
            for &i in &c.pixels {
                owner[i as usize] = k as u8 + 1;
            }
        }
        let zones: Vec<Vec<u32>> = claims.iter().map(|c| zone(&c.pixels, w, h, CLAIM_MARGIN_PX)).collect();
        let mut mice = Vec::with_capacity(claims.len());
        let mut alone = frame.clone();
        let mut emptied = Vec::new();
        for k in 0..claims.len() {
            let me = k as u8 + 1;
            // The other mice's pixels and their margins read as the empty cage, but for this
            // mouse's own; they are put back after.
            emptied.clear();
            for (j, zone) in zones.iter().enumerate() {
                if j != k {
                    emptied.extend(zone.iter().copied().filter(|&i| owner[i as usize] != me));
                }
            }
            for &i in &emptied {
                let i = i as usize;
                alone.data[i] = self.background.depth.get(i).map_or(0, |&b| b.round() as u16);
            }
            let found = self.segment(&alone)?;
            for &i in &emptied {
                alone.data[i as usize] = frame.data[i as usize];
            }
            if let Some(m) = found {
                mice.push(m);
            }
        }
        Ok(SeveralMice { mice, beyond, areas })
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

/// The pixels (frame indices, raster order) within `radius` of any of `pixels` (a square's
/// reach), `pixels` among them, in a frame `w` x `h`: worked out in their bounding box only.
fn zone(pixels: &[u32], w: usize, h: usize, radius: usize) -> Vec<u32> {
    let Some((x0, y0, x1, y1)) = pixels.iter().fold(None, |b: Option<(usize, usize, usize, usize)>, &i| {
        let (x, y) = (i as usize % w, i as usize / w);
        Some(b.map_or((x, y, x, y), |(x0, y0, x1, y1)| {
            (x0.min(x), y0.min(y), x1.max(x), y1.max(y))
        }))
    }) else {
        return Vec::new();
    };
    let (bx, by) = (x0.saturating_sub(radius), y0.saturating_sub(radius));
    let (bw, bh) = ((x1 + radius + 1).min(w) - bx, (y1 + radius + 1).min(h) - by);
    let mut mark = vec![false; bw * bh];
    for &i in pixels {
        let (x, y) = (i as usize % w - bx, i as usize / w - by);
        mark[y * bw + x] = true;
    }
    // Along the rows, then down the columns.
    let mut rows = vec![false; bw * bh];
    for y in 0..bh {
        let row = &mark[y * bw..(y + 1) * bw];
        for x in 0..bw {
            rows[y * bw + x] = row[x.saturating_sub(radius)..(x + radius + 1).min(bw)].contains(&true);
        }
    }
    let mut out = Vec::new();
    for y in 0..bh {
        for x in 0..bw {
            let near = (y.saturating_sub(radius)..(y + radius + 1).min(bh)).any(|yy| rows[yy * bw + x]);
            if near {
                out.push(((by + y) * w + bx + x) as u32);
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
    fn a_zone_reaches_its_radius_around_its_pixels_and_no_further() {
        let (w, h) = (7, 5);
        let pixels = [(2 * w + 1) as u32, (2 * w + 5) as u32];
        let zone = zone(&pixels, w, h, 1);
        let expected: Vec<u32> = (0..(w * h) as u32)
            .filter(|&i| {
                let (x, y) = ((i as usize % w) as i64, (i as usize / w) as i64);
                pixels.iter().any(|&p| {
                    let (px, py) = ((p as usize % w) as i64, (p as usize / w) as i64);
                    (x - px).abs() <= 1 && (y - py).abs() <= 1
                })
            })
            .collect();
        assert_eq!(zone, expected);
        assert!(!zone.contains(&((2 * w + 3) as u32)));
        // At the frame's corner, clipped.
        assert_eq!(super::zone(&[0], w, h, 2).len(), 9);
        assert!(super::zone(&[], w, h, 2).is_empty());
    }
}
