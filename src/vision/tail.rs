//! A visible tail found as a tail: a thin appendage that leaves one end of the segmented mouse.
//!
//! Real depth cameras show a mouse's tail in every way: not at all, faint, or blurred and raised
//! by mixed pixels to half the height of the back (a strip a few pixels wide reading 10-30 mm
//! above the floor while the back reads 30-40 mm). A shape judged with its tail in it reads the
//! tail's end as the narrow, low end of the body, which is what a head looks like from above;
//! so the tail is taken out of the body first, by what it is whatever height it reads: what a
//! morphological opening of the mask (a disc a little wider than a tail) removes, where that is
//! a long, thin piece joined to the body near one of its ends. MoSeq's extractor removes the
//! tail by an opening too (an ellipse of 9 x 9 pixels); here the disc is sized in millimetres,
//! and the piece removed is kept, since where it leaves the body says which end is the rear.
//!
//! Pure code over a region's mask (or a segmented depth image).

use crate::vision::forest::depth::DepthImage;
use std::collections::{BinaryHeap, VecDeque};

/// How the tail is looked for, in pixels of the mask.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TailSearch {
    /// Radius of the opening's disc: a strip narrower than its diameter is not body.
    pub radius_px: f64,
    /// The shortest tail (along itself, from where it leaves the body).
    pub min_length_px: f64,
    /// The widest mean width a tail may have (its area over its length).
    pub max_width_px: f64,
    /// The widest gap between two pieces of one tail.
    pub gap_px: f64,
}

impl TailSearch {
    /// The search for a mouse seen at `mm_per_px` millimetres a pixel: an opening of
    /// [`OPENING_RADIUS_MM`] (at least 1.5 pixels), tails of at least [`MIN_TAIL_MM`] and at
    /// most [`MAX_TAIL_WIDTH_MM`] wide, cut by gaps of at most [`MAX_GAP_MM`].
    pub fn at_scale(mm_per_px: f64) -> Self {
        let mm_per_px = mm_per_px.max(1e-3);
        Self {
            radius_px: (OPENING_RADIUS_MM / mm_per_px).max(1.5),
            min_length_px: MIN_TAIL_MM / mm_per_px,
            max_width_px: (MAX_TAIL_WIDTH_MM / mm_per_px).max(2.0),
            gap_px: MAX_GAP_MM / mm_per_px,
        }
    }
}

/// The opening's disc radius (mm): it removes strips up to about 8 mm wide (a tail of 3-5 mm,
/// blurred by a pixel each side), and keeps the muzzle's 9 mm and everything wider.
pub const OPENING_RADIUS_MM: f64 = 4.0;
/// A thin piece shorter than this (mm) is a paw, an ear's rim or noise, not a tail.
pub const MIN_TAIL_MM: f64 = 20.0;
/// A tail's mean width is at most this (mm).
pub const MAX_TAIL_WIDTH_MM: f64 = 9.0;
/// A tail's mean width is at least this (pixels): a chain of specks of noise a gap apart
/// fills less.
const MIN_TAIL_WIDTH_PX: f64 = 1.0;
/// A tail's pieces may lie this far apart (mm): a Kinect's tail reads broken by noise.
pub const MAX_GAP_MM: f64 = 8.0;
/// The tail leaves the body within this share of the body's half-length from one of its ends.
const END_SHARE: f64 = 0.5;

/// A tail found in a mask.
#[derive(Clone, Debug, PartialEq)]
pub struct Tail {
    /// Its pixels: indices into the region's mask (row-major).
    pub pixels: Vec<usize>,
    /// Where it leaves the body (the mean of its pixels next to the body) and its far end,
    /// region pixels (x, y).
    pub base: (f64, f64),
    pub tip: (f64, f64),
    /// Its length along itself from where it leaves the body, pixels.
    pub length_px: f64,
}

/// The tail of the segmented mouse of `image`, seen by a camera of focal length `fx` pixels,
/// searched at the scale of its mean depth; with the millimetres a pixel spans there.
pub fn find_tail_in(image: &DepthImage, fx: f64) -> Option<(Tail, f64)> {
    let mask: Vec<bool> = (0..image.depth.len()).map(|k| image.mouse_depth(k).is_some()).collect();
    let mm_per_px = mm_per_px(image, fx)?;
    let r = image.region;
    let tail = find_tail(
        &mask,
        r.width as usize,
        r.height as usize,
        &TailSearch::at_scale(mm_per_px),
    )?;
    Some((tail, mm_per_px))
}

/// The millimetres a pixel spans at the mean depth of the segmented mouse of `image`, seen by
/// a camera of focal length `fx` pixels (`None` without a reading or a focal length).
pub fn mm_per_px(image: &DepthImage, fx: f64) -> Option<f64> {
    let (sum, n) = image
        .on_mouse()
        .fold((0.0, 0usize), |(s, n), (_, d)| (s + f64::from(d), n + 1));
    (n > 0 && fx > 0.0).then(|| sum / n as f64 / fx)
}

/// The tail of the mouse in `mask` (`width` x `height`, row-major), or `None` when no thin
/// piece of it is long enough, or it does not leave the body near an end.
///
/// A real depth camera's tail is often cut by noise into pieces a few pixels apart: the tail is
/// measured along itself across gaps up to [`TailSearch::gap_px`] wide, from a piece that
/// touches the body to pieces beyond it (the segmenter keeps such pieces, `vision::segment`).
/// Its pixels are the pieces it passes through; where it leaves the body, the pixels of its
/// first piece that touch the body.
pub fn find_tail(mask: &[bool], width: usize, height: usize, search: &TailSearch) -> Option<Tail> {
    if width == 0 || mask.len() != width * height {
        return None;
    }
    // Where a tail reads a pixel wider, a disc fits in it here and there: those blobs, apart
    // from the body's main part, are not body.
    let body = largest_part(&opening(mask, width, height, search.radius_px), width, height);
    if !body.iter().any(|&b| b) {
        return None;
    }
    let body_axis = body_axis(&body, width)?;
    let pieces = removed_pieces(mask, &body, width, height);
    let reach = measure_pieces(&pieces, &body, width, height, search.gap_px);
    let mut best: Option<Tail> = None;
    for (root, base) in reach.bases.iter().enumerate() {
        let Some(base) = *base else { continue };
        // The farthest pixel reached from this piece, and the pieces on the way to it.
        let Some((far, length)) = reach
            .distance
            .iter()
            .enumerate()
            .filter(|&(i, d)| d.is_finite() && reach.root[i] == root)
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, d)| (i, *d))
        else {
            continue;
        };
        // The gaps do not count: the pieces themselves must be as long as a tail (specks of
        // noise a gap apart are not a tail).
        let solid = length - reach.gaps[far];
        if solid < search.min_length_px {
            continue;
        }
        let mut on_path = vec![pieces.piece_of[pieces.pixels[far]]];
        let mut at = far;
        while let Some(before) = reach.before[at] {
            let piece = pieces.piece_of[pieces.pixels[before]];
            if on_path.last() != Some(&piece) {
                on_path.push(piece);
            }
            at = before;
        }
        let pixels: Vec<usize> = on_path
            .iter()
            .flat_map(|&p| pieces.pieces[p].iter().map(|&i| pieces.pixels[i]))
            .collect();
        let width_px = pixels.len() as f64 / solid.max(1.0);
        if !(MIN_TAIL_WIDTH_PX..=search.max_width_px).contains(&width_px) {
            continue;
        }
        let base_xy = (base.0 / base.2 as f64, base.1 / base.2 as f64);
        // It must leave the body near one of its ends, not from its side.
        let (c, a) = (body_axis.centre, body_axis.axis);
        let along = (base_xy.0 - c.0) * a.0 + (base_xy.1 - c.1) * a.1;
        if along.abs() < (1.0 - END_SHARE) * body_axis.half_length {
            continue;
        }
        if best.as_ref().is_none_or(|b| length > b.length_px) {
            let k = pieces.pixels[far];
            best = Some(Tail {
                pixels,
                base: base_xy,
                tip: ((k % width) as f64, (k / width) as f64),
                length_px: length,
            });
        }
    }
    best
}

/// The thin pieces of the mouse in `mask` (what the opening of `search` takes off its body, in
/// 8-connected pieces) that touch a pixel set in `wall` (row-major over the mask): strands of
/// clutter lying at a wall or the arena's rim joined to the mouse, which are not its body.
pub fn thin_pieces_at(mask: &[bool], wall: &[bool], width: usize, height: usize, search: &TailSearch) -> Vec<usize> {
    if width == 0 || mask.len() != width * height || wall.len() != mask.len() {
        return Vec::new();
    }
    let body = largest_part(&opening(mask, width, height, search.radius_px), width, height);
    let pieces = removed_pieces(mask, &body, width, height);
    pieces
        .pieces
        .iter()
        .filter(|piece| piece.iter().any(|&i| wall[pieces.pixels[i]]))
        .flat_map(|piece| piece.iter().map(|&i| pieces.pixels[i]))
        .collect()
}

/// The 8 neighbours of pixel `k` of a `width` x `height` image, with the length of the step
/// to each.
fn neighbours(k: usize, width: usize, height: usize) -> impl Iterator<Item = (usize, f64)> {
    let (x, y) = ((k % width) as isize, (k / width) as isize);
    NEIGHBOURS.iter().filter_map(move |&(dx, dy, step)| {
        let (nx, ny) = (x + dx, y + dy);
        (nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height)
            .then(|| (ny as usize * width + nx as usize, step))
    })
}

/// The largest 8-connected part of `set` (all false when it is empty).
fn largest_part(set: &[bool], width: usize, height: usize) -> Vec<bool> {
    let mut part = vec![usize::MAX; set.len()];
    let (mut best, mut best_size, mut count) = (usize::MAX, 0, 0);
    for start in 0..set.len() {
        if !set[start] || part[start] != usize::MAX {
            continue;
        }
        let mut size = 0;
        let mut queue = VecDeque::from([start]);
        part[start] = count;
        while let Some(k) = queue.pop_front() {
            size += 1;
            for (n, _) in neighbours(k, width, height) {
                if set[n] && part[n] == usize::MAX {
                    part[n] = count;
                    queue.push_back(n);
                }
            }
        }
        if size > best_size {
            (best, best_size) = (count, size);
        }
        count += 1;
    }
    part.iter().map(|&p| p == best).collect()
}

/// What the opening removed from the mask, in pieces (8-connected).
struct Pieces {
    /// The removed pixels (indices into the mask).
    pixels: Vec<usize>,
    /// Each mask pixel's index into `pixels` (`usize::MAX`: not removed).
    place: Vec<usize>,
    /// Each removed mask pixel's piece (by mask index; `usize::MAX` elsewhere).
    piece_of: Vec<usize>,
    /// Each piece's pixels (indices into `pixels`).
    pieces: Vec<Vec<usize>>,
}

/// The pixels of `mask` off the `body`, in 8-connected pieces.
fn removed_pieces(mask: &[bool], body: &[bool], width: usize, height: usize) -> Pieces {
    let mut out = Pieces {
        pixels: Vec::new(),
        place: vec![usize::MAX; mask.len()],
        piece_of: vec![usize::MAX; mask.len()],
        pieces: Vec::new(),
    };
    for start in 0..mask.len() {
        if !mask[start] || body[start] || out.piece_of[start] != usize::MAX {
            continue;
        }
        let piece = out.pieces.len();
        let mut members = Vec::new();
        let mut queue = VecDeque::from([start]);
        out.piece_of[start] = piece;
        while let Some(k) = queue.pop_front() {
            out.place[k] = out.pixels.len();
            members.push(out.pixels.len());
            out.pixels.push(k);
            for (n, _) in neighbours(k, width, height) {
                if mask[n] && !body[n] && out.piece_of[n] == usize::MAX {
                    out.piece_of[n] = piece;
                    queue.push_back(n);
                }
            }
        }
        out.pieces.push(members);
    }
    out
}

/// How far along itself each removed pixel lies from the body.
struct Reach {
    /// Per removed pixel (as [`Pieces::pixels`]): its distance, the pixel before it on the
    /// way (`None` at the body) and the piece the way starts from.
    distance: Vec<f64>,
    /// How much of `distance` is gaps leapt.
    gaps: Vec<f64>,
    before: Vec<Option<usize>>,
    root: Vec<usize>,
    /// Per piece: the sum of the coordinates of its pixels that touch the body, and their
    /// count (`None`: it does not touch the body).
    bases: Vec<Option<(f64, f64, usize)>>,
}

/// Each removed pixel's distance from the body along the pieces (Dijkstra, steps of 1 and
/// sqrt 2 within a piece; from a piece to another, a leap across a gap of at most `gap_px`,
/// counted at its length), from the pixels that touch the body.
fn measure_pieces(pieces: &Pieces, body: &[bool], width: usize, height: usize, gap_px: f64) -> Reach {
    let n = pieces.pixels.len();
    let mut reach = Reach {
        distance: vec![f64::INFINITY; n],
        gaps: vec![0.0; n],
        before: vec![None; n],
        root: vec![usize::MAX; n],
        bases: vec![None; pieces.pieces.len()],
    };
    let mut heap = BinaryHeap::new();
    for (i, &k) in pieces.pixels.iter().enumerate() {
        if neighbours(k, width, height).any(|(m, _)| body[m]) {
            let piece = pieces.piece_of[k];
            reach.distance[i] = 0.0;
            reach.root[i] = piece;
            heap.push(Reverse(0.0, i));
            let b = reach.bases[piece].get_or_insert((0.0, 0.0, 0));
            *b = (b.0 + (k % width) as f64, b.1 + (k / width) as f64, b.2 + 1);
        }
    }
    let leap = gap_px.max(0.0).floor() as isize;
    while let Some(Reverse(d, i)) = heap.pop() {
        if d > reach.distance[i] {
            continue;
        }
        let k = pieces.pixels[i];
        let mut relax = |m: usize, step: f64, leap: bool, heap: &mut BinaryHeap<Reverse>| {
            let j = pieces.place[m];
            if j != usize::MAX && d + step < reach.distance[j] {
                reach.distance[j] = d + step;
                reach.gaps[j] = reach.gaps[i] + if leap { step } else { 0.0 };
                reach.before[j] = Some(i);
                reach.root[j] = reach.root[i];
                heap.push(Reverse(d + step, j));
            }
        };
        for (m, step) in neighbours(k, width, height) {
            relax(m, step, false, &mut heap);
        }
        // Leaps to the other pieces within the gap.
        let (x, y) = ((k % width) as isize, (k / width) as isize);
        for dy in -leap..=leap {
            for dx in -leap..=leap {
                let (nx, ny) = (x + dx, y + dy);
                let step = ((dx * dx + dy * dy) as f64).sqrt();
                if nx < 0 || ny < 0 || nx as usize >= width || ny as usize >= height || step > gap_px || step < 1.5 {
                    continue;
                }
                let m = ny as usize * width + nx as usize;
                if pieces.piece_of[m] != usize::MAX && pieces.piece_of[m] != pieces.piece_of[k] {
                    relax(m, step, true, &mut heap);
                }
            }
        }
    }
    reach
}

/// The 8 neighbours of a pixel and the length of the step to each.
const NEIGHBOURS: [(isize, isize, f64); 8] = [
    (-1, 0, 1.0),
    (1, 0, 1.0),
    (0, -1, 1.0),
    (0, 1, 1.0),
    (-1, -1, std::f64::consts::SQRT_2),
    (1, -1, std::f64::consts::SQRT_2),
    (-1, 1, std::f64::consts::SQRT_2),
    (1, 1, std::f64::consts::SQRT_2),
];

/// A heap entry ordered by its distance, smallest first.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Reverse(f64, usize);

impl Eq for Reverse {}

impl PartialOrd for Reverse {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Reverse {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// The body's centre (x, y, pixels), its long axis (unit) and its half-length along it.
struct BodyAxis {
    centre: (f64, f64),
    axis: (f64, f64),
    half_length: f64,
}

/// The [`BodyAxis`] of the pixels of `body`, `None` when it has none.
fn body_axis(body: &[bool], width: usize) -> Option<BodyAxis> {
    let points: Vec<(f64, f64)> = body
        .iter()
        .enumerate()
        .filter(|&(_, &b)| b)
        .map(|(k, _)| ((k % width) as f64, (k / width) as f64))
        .collect();
    let n = points.len() as f64;
    if n < 1.0 {
        return None;
    }
    let (cx, cy) = points.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in &points {
        sxx += (x - cx) * (x - cx);
        sxy += (x - cx) * (y - cy);
        syy += (y - cy) * (y - cy);
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let axis = (angle.cos(), angle.sin());
    let half = points
        .iter()
        .map(|(x, y)| ((x - cx) * axis.0 + (y - cy) * axis.1).abs())
        .fold(0.0, f64::max);
    Some(BodyAxis {
        centre: (cx, cy),
        axis,
        half_length: half.max(1.0),
    })
}

/// The morphological opening of `mask` by a disc of `radius` pixels: the union of the discs
/// that fit inside it (the region's edge counts as outside). Row by row: the disc is a stack
/// of horizontal spans, and each row's runs say at once whether a span lies in the mask
/// (erosion) or holds a pixel of the eroded mask (dilation).
pub fn opening(mask: &[bool], width: usize, height: usize, radius: f64) -> Vec<bool> {
    let reach = radius.max(0.0).floor() as usize;
    // The disc's half-width at each row offset 0..=reach.
    let spans: Vec<usize> = (0..=reach)
        .map(|dy| (radius * radius - (dy * dy) as f64).max(0.0).sqrt().floor() as usize)
        .collect();
    let rows = |y: usize| {
        (y.saturating_sub(reach)..=(y + reach).min(height.saturating_sub(1))).map(move |r| (r, r.abs_diff(y)))
    };
    // Erosion: every span of the disc inside the mask (the mask's runs through the pixel reach
    // the span's ends), and no span off the region.
    let (left, right) = runs(mask, width, |m| m);
    let core: Vec<bool> = (0..mask.len())
        .map(|k| {
            let (x, y) = (k % width, k / width);
            mask[k]
                && y >= reach
                && y + reach < height
                && rows(y).all(|(r, dy)| {
                    let i = r * width + x;
                    left[i] > spans[dy] && right[i] > spans[dy]
                })
        })
        .collect();
    // Dilation: a mask pixel with an eroded pixel within a span of the disc (the nearest one
    // of its row on either side).
    let (before, after) = nearest(&core, width);
    (0..mask.len())
        .map(|k| {
            let (x, y) = (k % width, k / width);
            mask[k]
                && rows(y).any(|(r, dy)| {
                    let i = r * width + x;
                    before[i] <= spans[dy] || after[i] <= spans[dy]
                })
        })
        .collect()
}

/// Per pixel, how many pixels in a row where `keep` holds end at it from the left and from the
/// right (itself included; 0 where it does not hold).
fn runs(values: &[bool], width: usize, keep: impl Fn(bool) -> bool) -> (Vec<usize>, Vec<usize>) {
    let (mut left, mut right) = (vec![0; values.len()], vec![0; values.len()]);
    for row in 0..values.len() / width.max(1) {
        let base = row * width;
        for x in 0..width {
            let i = base + x;
            left[i] = if keep(values[i]) {
                1 + if x > 0 { left[i - 1] } else { 0 }
            } else {
                0
            };
            let j = base + width - 1 - x;
            right[j] = if keep(values[j]) {
                1 + if x > 0 { right[j + 1] } else { 0 }
            } else {
                0
            };
        }
    }
    (left, right)
}

/// Per pixel, the distance along its row to the nearest pixel that is set, on its left and on
/// its right (itself included; `usize::MAX` where there is none).
fn nearest(values: &[bool], width: usize) -> (Vec<usize>, Vec<usize>) {
    let (mut before, mut after) = (vec![usize::MAX; values.len()], vec![usize::MAX; values.len()]);
    for row in 0..values.len() / width.max(1) {
        let base = row * width;
        for x in 0..width {
            let i = base + x;
            before[i] = if values[i] {
                0
            } else if x > 0 {
                before[i - 1].saturating_add(1)
            } else {
                usize::MAX
            };
            let j = base + width - 1 - x;
            after[j] = if values[j] {
                0
            } else if x > 0 {
                after[j + 1].saturating_add(1)
            } else {
                usize::MAX
            };
        }
    }
    (before, after)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A body: an ellipse of semi-axes `a` x `b` pixels centred at (cx, cy), with a strip
    /// `thick` pixels wide and `length` long leaving its end at +x (when `length` > 0).
    fn mouse(width: usize, height: usize, a: f64, b: f64, length: usize, thick: usize) -> Vec<bool> {
        let (cx, cy) = (width as f64 / 3.0, height as f64 / 2.0);
        let mut mask = vec![false; width * height];
        for y in 0..height {
            for x in 0..width {
                let (dx, dy) = ((x as f64 - cx) / a, (y as f64 - cy) / b);
                mask[y * width + x] = dx * dx + dy * dy <= 1.0;
            }
        }
        let x0 = (cx + a - 1.0) as usize;
        for x in x0..(x0 + length).min(width) {
            for t in 0..thick {
                mask[(cy as usize - thick / 2 + t) * width + x] = true;
            }
        }
        mask
    }

    /// Clears the pixels of `mask` (`width` wide) in columns `from..to` (a gap across a tail
    /// running along +x).
    fn cut(mask: &mut [bool], width: usize, from: usize, to: usize) {
        for (k, m) in mask.iter_mut().enumerate() {
            if (from..to).contains(&(k % width)) {
                *m = false;
            }
        }
    }

    /// Issue 49: tails as a real Kinect reads them (the real-depth versions are in the
    /// integration tests, on the real MoSeq mouse with such tails drawn on): cut by noise into
    /// two or three pieces, 2 px wide, a pixel wider here and there; and specks of noise a gap
    /// apart are no tail.
    #[test]
    fn a_tail_broken_thin_or_uneven_is_found_whole_and_specks_are_not_a_tail() {
        let (w, h) = (140, 60);
        let search = TailSearch::at_scale(1.6);
        let (cx, a) = (w as f64 / 3.0, 28.0);
        let end = (cx + a) as usize;
        let whole = find_tail(&mouse(w, h, 28.0, 11.0, 60, 3), w, h, &search).expect("the whole tail");
        // Two gaps of 3 px (4.8 mm): three pieces, found as one tail as long as the whole.
        let mut broken = mouse(w, h, 28.0, 11.0, 60, 3);
        cut(&mut broken, w, end + 15, end + 18);
        cut(&mut broken, w, end + 35, end + 38);
        let tail = find_tail(&broken, w, h, &search).expect("the broken tail");
        assert!(
            (tail.length_px - whole.length_px).abs() < 2.0,
            "{} against {}",
            tail.length_px,
            whole.length_px
        );
        assert_eq!(tail.pixels.len(), whole.pixels.len() - 3 * 3 * 2);
        assert!(tail.tip.0 > cx + a + 55.0, "{:?}", tail.tip);
        // A gap wider than a tail's (6 px, 9.6 mm): the tail ends before it.
        let mut apart = mouse(w, h, 28.0, 11.0, 60, 3);
        cut(&mut apart, w, end + 25, end + 31);
        let tail = find_tail(&apart, w, h, &search).expect("the tail before the gap");
        assert!(tail.tip.0 < (end + 25) as f64, "{:?}", tail.tip);
        // 2 px wide.
        let thin = find_tail(&mouse(w, h, 28.0, 11.0, 60, 2), w, h, &search).expect("the thin tail");
        assert!((thin.length_px - 60.0).abs() < 6.0, "{}", thin.length_px);
        // A pixel wider for a stretch, so that the opening's disc fits in it: still one tail,
        // and the blob is no body.
        let mut uneven = mouse(w, h, 28.0, 11.0, 60, 3);
        let cy = h / 2;
        for x in end + 20..end + 26 {
            for y in cy - 3..=cy + 3 {
                uneven[y * w + x] = true;
            }
        }
        let tail = find_tail(&uneven, w, h, &search).expect("the uneven tail");
        assert!(
            tail.tip.0 > cx + a + 55.0 && (tail.length_px - 60.0).abs() < 6.0,
            "{tail:?}"
        );
        // Specks a gap apart leaving the body's end: too little of them to be a tail.
        let mut specks = mouse(w, h, 28.0, 11.0, 0, 3);
        for x in (end + 1..end + 60).step_by(4) {
            specks[cy * w + x] = true;
        }
        assert_eq!(find_tail(&specks, w, h, &search), None);
    }

    /// The opening by its definition: every offset of the disc checked.
    fn opening_by_offsets(mask: &[bool], width: usize, height: usize, radius: f64) -> Vec<bool> {
        let reach = radius.floor() as isize;
        let disc: Vec<(isize, isize)> = (-reach..=reach)
            .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
            .filter(|&(dx, dy)| ((dx * dx + dy * dy) as f64) <= radius * radius)
            .collect();
        let at = |values: &[bool], k: usize, (dx, dy): (isize, isize)| {
            let (nx, ny) = ((k % width) as isize + dx, (k / width) as isize + dy);
            nx >= 0
                && ny >= 0
                && (nx as usize) < width
                && (ny as usize) < height
                && values[ny as usize * width + nx as usize]
        };
        let core: Vec<bool> = (0..mask.len()).map(|k| disc.iter().all(|&d| at(mask, k, d))).collect();
        (0..mask.len())
            .map(|k| mask[k] && disc.iter().any(|&d| at(&core, k, d)))
            .collect()
    }

    #[test]
    fn the_opening_by_rows_is_the_opening_by_offsets() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for round in 0..200 {
            let (w, h) = (rng.gen_range(1..40), rng.gen_range(1..40));
            let fill = rng.gen_range(0.3..0.95);
            let mask: Vec<bool> = (0..w * h).map(|_| rng.gen_bool(fill)).collect();
            let radius = rng.gen_range(0.0..4.5);
            assert_eq!(
                opening(&mask, w, h, radius),
                opening_by_offsets(&mask, w, h, radius),
                "round {round}: {w}x{h}, radius {radius}"
            );
        }
    }

    #[test]
    fn a_thin_strip_leaving_one_end_is_the_tail_and_nothing_else_is() {
        let (w, h) = (140, 60);
        let search = TailSearch::at_scale(1.6);
        // A mouse 56 x 22 px (about 90 x 35 mm at 1.6 mm a pixel) with a tail 4 px wide and
        // 60 px long.
        let with = mouse(w, h, 28.0, 11.0, 60, 4);
        let tail = find_tail(&with, w, h, &search).expect("the tail");
        let (cx, a) = (w as f64 / 3.0, 28.0);
        assert!(
            tail.base.0 > cx + a - 4.0 && tail.base.0 < cx + a + 4.0,
            "{:?}",
            tail.base
        );
        assert!(tail.tip.0 > cx + a + 55.0, "{:?}", tail.tip);
        assert!((tail.length_px - 60.0).abs() < 6.0, "{}", tail.length_px);
        // No tail, a tail too short to tell from the body's rim, and a strip as wide as a body.
        assert_eq!(find_tail(&mouse(w, h, 28.0, 11.0, 0, 4), w, h, &search), None);
        assert_eq!(find_tail(&mouse(w, h, 28.0, 11.0, 8, 4), w, h, &search), None);
        assert_eq!(find_tail(&mouse(w, h, 28.0, 11.0, 60, 12), w, h, &search), None);
        // The opening keeps exactly the discs that fit: a square of 5 x 5 pixels holds one disc
        // of radius 2 (13 pixels), none of radius 3.
        let square: Vec<bool> = (0..81)
            .map(|k| (2..7).contains(&(k % 9)) && (2..7).contains(&(k / 9)))
            .collect();
        assert_eq!(opening(&square, 9, 9, 2.0).iter().filter(|&&b| b).count(), 13);
        assert!(!opening(&square, 9, 9, 3.0).iter().any(|&b| b));
        // The opening keeps the body whole.
        let body = opening(&mouse(w, h, 28.0, 11.0, 0, 4), w, h, search.radius_px);
        let kept = body.iter().filter(|&&b| b).count() as f64;
        let all = mouse(w, h, 28.0, 11.0, 0, 4).iter().filter(|&&b| b).count() as f64;
        assert!(kept / all > 0.95, "{kept} of {all}");
    }
}
