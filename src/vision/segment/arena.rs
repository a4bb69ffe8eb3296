//! The arena: the part of the view where the mouse can be, found MoSeq's way (the readings
//! near the floor's depth, and of them the largest flat region) or given as a mask. The floor
//! is fitted inside the arena only, so an arena that fills a small part of the view (a round
//! arena in a larger box, the lab around it) still gives its floor; and the mouse is looked for
//! inside the arena only.
//!
//! Found automatically ([`find_arena`]): the plane holding the most readings, then the
//! connected regions (8-connected) of the readings within the floor tolerance of it. The floor
//! region is the largest solid one (its centroid on itself: a ring of floor around a round
//! arena's wall is not the arena), else the largest; it must hold at least one reading in 20.
//! When the mouse-sized movers seen in the recording do not all stand in it, the same plane's
//! region holding the most of them is tried too (a small arena standing on the room's floor).
//! When the plane holds fewer than a fifth of the view's readings, the floor is fitted again
//! to that region alone (otherwise its fit is already the floor's, to the same readings). The arena is the region with its holes
//! filled (whatever stands on the floor), widened by [`ARENA_MARGIN_MM`] so that a mouse
//! rearing at the wall stays inside, and over the mouse-sized movers seen within a mouse's length of it
//! (a mouse on a sloping rim, which is not flat floor).

use super::SegmentError;
use super::activity::Blob;
use super::floor::{FLOOR_MIN_INLIERS, FloorPlane, best_plane, best_plane_local, fit_floor};

/// The floor region holds at least this share of the readings.
const MIN_FLOOR_SHARE: f64 = 0.05;
/// The arena reaches this far (mm on the floor) past its floor region.
pub const ARENA_MARGIN_MM: f64 = 40.0;
/// A mouse-sized mover this near the arena (mm on the floor, a mouse's length) and at a
/// mouse's heights above its floor is taken into it (see [`find_arena`]).
const MOVER_REACH_MM: f64 = 100.0;
/// Flat regions besides the largest one weighed against the mouse's whereabouts, at most.
const MORE_CANDIDATES: usize = 4;

/// Where the mouse can stand: the heights above a floor (mm) at which a reading may be it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Heights {
    pub min_mm: f64,
    pub max_mm: f64,
}

impl Heights {
    fn holds(&self, height_mm: f64) -> bool {
        (self.min_mm..=self.max_mm).contains(&height_mm)
    }
}

/// The floor and the arena (1 = inside, row-major over the background's region).
pub(super) struct FloorFit {
    pub floor: FloorPlane,
    pub arena: Vec<u8>,
}

/// Finds the floor and the arena of a background of `width` x `height` readings (mm, 0 = none)
/// whose rays are `rays`, with a camera of focal length `focal_px`.
///
/// `evidence` holds the mouse-sized things seen in frames of the recording (see
/// [`super::activity`]). When the largest flat region of the view does not carry all of them
/// at a mouse's heights (`heights`: a floor beside the arena, a table, the lab's floor below
/// a raised or sloping arena), other flat regions are tried (planes found from nearby
/// readings, so that a region a tenth of the view is found too), and the one that carries
/// the most of them is the arena; the largest one keeps it unless another carries more.
///
/// # Errors
/// No plane facing the camera, or no flat region of it holding one reading in 20.
#[allow(clippy::too_many_arguments)]
pub(super) fn find_arena(
    depth: &[f32],
    rays: &[[f32; 2]],
    width: usize,
    height: usize,
    focal_px: f64,
    tolerance: f64,
    evidence: &[Blob],
    heights: Heights,
) -> Result<FloorFit, SegmentError> {
    let (plane, held, sampled) = best_plane(depth, rays, tolerance, None)?;
    let valid = depth.iter().filter(|&&z| z > 0.0).count();
    let region = floor_region(&near_plane(depth, rays, &plane, tolerance), width, height);
    let count = region.iter().filter(|&&v| v != 0).count();
    if (count as f64) < MIN_FLOOR_SHARE * valid as f64 {
        return Err(SegmentError::Floor {
            reason: format!(
                "the largest flat region of the best plane holds {count} of {valid} readings, fewer than one in 20"
            ),
        });
    }
    // A floor that holds a fifth of the whole view is fitted well there already (and to the
    // same readings); a smaller one is fitted again inside its region alone.
    let floor = if (held as f64) >= FLOOR_MIN_INLIERS * sampled as f64 {
        plane
    } else {
        fit_floor(depth, rays, tolerance, Some(&region))?
    };
    let first = FloorFit {
        arena: arena_of(depth, &region, width, height, focal_px),
        floor,
    };
    if evidence.is_empty() {
        return Ok(first);
    }
    let carried = |fit: &FloorFit| evidence.iter().filter(|b| stands_on(b, fit, rays, heights)).count();
    let mut best = (carried(&first), first);
    if best.0 == evidence.len() {
        return Ok(best.1);
    }
    // The same plane's other regions: a small arena standing on the room's floor, its own
    // floor cut off from the room's by its wall.
    if let Some(fit) = region_holding_movers(depth, rays, (width, height), focal_px, tolerance, &plane, evidence) {
        let n = carried(&fit);
        if n > best.0 {
            best = (n, fit);
        }
    }
    // Other flat regions: planes of the readings not yet explained, one after the other.
    let mut left: Vec<u8> = near_plane(depth, rays, &plane, tolerance)
        .iter()
        .zip(depth)
        .map(|(&near, &z)| u8::from(near == 0 && z > 0.0))
        .collect();
    for round in 0..MORE_CANDIDATES {
        let remaining = left.iter().filter(|&&v| v != 0).count();
        if (remaining as f64) < MIN_FLOOR_SHARE * valid as f64 {
            break;
        }
        let Ok(plane) = best_plane_local(depth, rays, width, tolerance, &left, round as u64) else {
            break;
        };
        let near = near_plane(depth, rays, &plane, tolerance);
        for (l, &n) in left.iter_mut().zip(&near) {
            if n != 0 {
                *l = 0;
            }
        }
        let region = floor_region(&near, width, height);
        let count = region.iter().filter(|&&v| v != 0).count();
        if (count as f64) < MIN_FLOOR_SHARE * valid as f64 {
            continue;
        }
        let Ok(floor) = fit_floor(depth, rays, tolerance, Some(&region)) else {
            continue;
        };
        let fit = FloorFit {
            arena: arena_of(depth, &region, width, height, focal_px),
            floor,
        };
        let n = carried(&fit);
        if n > best.0 {
            best = (n, fit);
        }
    }
    let mut fit = best.1;
    take_in_movers(&mut fit, evidence, rays, heights, (width, height), focal_px);
    Ok(fit)
}

/// The region of `plane`'s readings (at least one in 20 of the view's) on which the most
/// mouse-sized movers stand, with its floor fitted; `None` when no such region holds one.
fn region_holding_movers(
    depth: &[f32],
    rays: &[[f32; 2]],
    (width, height): (usize, usize),
    focal_px: f64,
    tolerance: f64,
    plane: &FloorPlane,
    evidence: &[Blob],
) -> Option<FloorFit> {
    let (labels, stats) = regions(&near_plane(depth, rays, plane, tolerance), width, height);
    let valid = depth.iter().filter(|&&z| z > 0.0).count();
    let mut held = vec![0usize; stats.len()];
    for blob in evidence {
        let mut on = vec![0usize; stats.len()];
        for &(i, _) in &blob.pixels {
            if let Some(n) = labels
                .get(i as usize)
                .and_then(|&l| on.get_mut((l as usize).wrapping_sub(1)))
            {
                *n += 1;
            }
        }
        if let Some(k) = on.iter().position(|&n| 2 * n >= blob.pixels.len()) {
            held[k] += 1;
        }
    }
    let (k, _) = held
        .iter()
        .enumerate()
        .filter(|&(k, &n)| {
            n > 0
                && stats
                    .get(k)
                    .is_some_and(|s| (s.0 as f64) >= MIN_FLOOR_SHARE * valid as f64)
        })
        .max_by_key(|&(_, &n)| n)?;
    let label = k as u32 + 1;
    let region: Vec<u8> = labels.iter().map(|&l| u8::from(l == label)).collect();
    let floor = fit_floor(depth, rays, tolerance, Some(&region)).ok()?;
    Some(FloorFit {
        arena: arena_of(depth, &region, width, height, focal_px),
        floor,
    })
}

/// Widens the arena over the movers seen beside it: a mouse on a sloping rim, which the flat
/// floor region leaves out. A mouse-sized mover that the arena does not hold, within
/// [`MOVER_REACH_MM`] of it and with most of its pixels at a mouse's heights above its floor,
/// is taken in with [`ARENA_MARGIN_MM`] around it. A mover farther away (a hand beside the
/// box, a second arena) or higher (the experimenter) is left out.
fn take_in_movers(
    fit: &mut FloorFit,
    evidence: &[Blob],
    rays: &[[f32; 2]],
    heights: Heights,
    (width, height): (usize, usize),
    focal_px: f64,
) {
    let mut taken = vec![false; evidence.len()];
    // A mover taken in may bring another one within reach (the mouse further up the rim).
    loop {
        let mut reach = fit.arena.clone();
        widen(&mut reach, width, height, reach_px(fit, rays, focal_px));
        let mut movers = vec![0u8; fit.arena.len()];
        let mut depths = Vec::new();
        for (blob, taken) in evidence.iter().zip(taken.iter_mut()) {
            if *taken || stands_on(blob, fit, rays, heights) {
                continue;
            }
            let touches = blob.pixels.iter().any(|&(i, _)| reach.get(i as usize) == Some(&1));
            let at_heights = blob
                .pixels
                .iter()
                .filter(|&&(i, z)| {
                    rays.get(i as usize)
                        .is_some_and(|r| heights.holds(height_above(fit, r, z)))
                })
                .count();
            if !touches || 2 * at_heights < blob.pixels.len() {
                continue;
            }
            *taken = true;
            for &(i, z) in &blob.pixels {
                if let Some(m) = movers.get_mut(i as usize) {
                    *m = 1;
                    depths.push(z);
                }
            }
        }
        if depths.is_empty() {
            return;
        }
        let mid = depths.len() / 2;
        let depth = f64::from(*depths.select_nth_unstable_by(mid, f32::total_cmp).1);
        widen(&mut movers, width, height, margin_px(depth, focal_px));
        for (a, m) in fit.arena.iter_mut().zip(&movers) {
            *a |= m;
        }
    }
}

/// [`MOVER_REACH_MM`] in pixels at the depth of the arena's farthest floor reading from the
/// camera (the fewest pixels).
fn reach_px(fit: &FloorFit, rays: &[[f32; 2]], focal_px: f64) -> usize {
    // The floor's depth along the optical axis where the arena's rays meet it.
    let depth = fit
        .arena
        .iter()
        .zip(rays)
        .filter(|&(&a, _)| a != 0)
        .map(|(_, r)| {
            let n = &fit.floor.normal;
            -fit.floor.offset_mm / n.dot(&nalgebra::Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0))
        })
        .filter(|d| d.is_finite() && *d > 0.0)
        .fold(0.0, f64::max);
    (MOVER_REACH_MM * focal_px / depth.max(1.0)).ceil() as usize
}

/// The height (mm) above the fit's floor of the reading `z` along `ray`.
fn height_above(fit: &FloorFit, ray: &[f32; 2], z: f32) -> f64 {
    fit.floor
        .normal
        .dot(&nalgebra::Vector3::new(f64::from(ray[0]), f64::from(ray[1]), 1.0))
        * f64::from(z)
        + fit.floor.offset_mm
}

/// [`ARENA_MARGIN_MM`] in pixels at `depth_mm` from the camera.
fn margin_px(depth_mm: f64, focal_px: f64) -> usize {
    (ARENA_MARGIN_MM * focal_px / depth_mm.max(1.0)).ceil() as usize
}

/// 1 where a reading lies within `tolerance` of `plane`.
fn near_plane(depth: &[f32], rays: &[[f32; 2]], plane: &FloorPlane, tolerance: f64) -> Vec<u8> {
    depth
        .iter()
        .zip(rays)
        .map(|(&z, r)| {
            let h = plane
                .normal
                .dot(&nalgebra::Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0))
                * f64::from(z)
                + plane.offset_mm;
            u8::from(z > 0.0 && h.abs() <= tolerance)
        })
        .collect()
}

/// Whether most of `blob` lies inside the arena of `fit`, at a mouse's heights above its floor.
fn stands_on(blob: &Blob, fit: &FloorFit, rays: &[[f32; 2]], heights: Heights) -> bool {
    let on = blob
        .pixels
        .iter()
        .filter(|&&(i, z)| {
            let i = i as usize;
            let (Some(&inside), Some(r)) = (fit.arena.get(i), rays.get(i)) else {
                return false;
            };
            inside != 0 && heights.holds(height_above(fit, r, z))
        })
        .count();
    2 * on >= blob.pixels.len()
}

/// The arena of a floor region: its holes filled (whatever stands on the floor), widened by
/// [`ARENA_MARGIN_MM`] at the floor's median depth.
fn arena_of(depth: &[f32], region: &[u8], width: usize, height: usize, focal_px: f64) -> Vec<u8> {
    let mut floor_depths: Vec<f32> = depth
        .iter()
        .zip(region)
        .filter(|&(_, &m)| m != 0)
        .map(|(&z, _)| z)
        .collect();
    let floor_depth = if floor_depths.is_empty() {
        1.0
    } else {
        let mid = floor_depths.len() / 2;
        f64::from(*floor_depths.select_nth_unstable_by(mid, f32::total_cmp).1)
    };
    let mut arena = fill_holes(region, width, height);
    widen(&mut arena, width, height, margin_px(floor_depth, focal_px));
    arena
}

/// The floor region among the connected regions of `mask`: the largest solid one, else the
/// largest (see the module documentation); all zero when `mask` is.
fn floor_region(mask: &[u8], width: usize, height: usize) -> Vec<u8> {
    let (labels, stats) = regions(mask, width, height);
    let solid = |k: usize, &(n, sx, sy): &(usize, usize, usize)| {
        let (cx, cy) = (sx / n.max(1), sy / n.max(1));
        labels.get(cy * width + cx) == Some(&(k as u32 + 1))
    };
    let largest = |only_solid: bool| {
        stats
            .iter()
            .enumerate()
            .filter(|(k, s)| !only_solid || solid(*k, s))
            .max_by_key(|(_, s)| s.0)
            .map(|(k, s)| (k, s.0))
    };
    let biggest = largest(false);
    // A solid region that is not tiny beside the largest: the arena's floor inside a ring.
    let chosen = match (largest(true), biggest) {
        (Some((k, n)), Some((_, m))) if n * 10 >= m => Some(k),
        (_, b) => b.map(|(k, _)| k),
    };
    let Some(k) = chosen else {
        return vec![0; mask.len()];
    };
    let label = k as u32 + 1;
    labels.iter().map(|&l| u8::from(l == label)).collect()
}

/// The connected regions (8-connected) of `mask`: each pixel's region label (0 outside the
/// mask, `k + 1` for the k-th region), and per region its pixel count and its sums of x and y.
fn regions(mask: &[u8], width: usize, height: usize) -> (Vec<u32>, Vec<(usize, usize, usize)>) {
    let mut labels = vec![0u32; mask.len()];
    // Per region: pixel count, and sums of x and y.
    let mut stats: Vec<(usize, usize, usize)> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..mask.len() {
        if mask[start] == 0 || labels[start] != 0 {
            continue;
        }
        stats.push((0, 0, 0));
        let label = stats.len() as u32;
        labels[start] = label;
        stack.push(start);
        let mut s = (0, 0, 0);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % width, i / width);
            s = (s.0 + 1, s.1 + x, s.2 + y);
            for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || ny < 0 || nx >= width as i64 || ny >= height as i64 {
                    continue;
                }
                let j = ny as usize * width + nx as usize;
                if mask[j] != 0 && labels[j] == 0 {
                    labels[j] = label;
                    stack.push(j);
                }
            }
        }
        if let Some(last) = stats.last_mut() {
            *last = s;
        }
    }
    (labels, stats)
}

/// `region` with its holes filled: every pixel not reachable from the image's border without
/// crossing the region.
fn fill_holes(region: &[u8], width: usize, height: usize) -> Vec<u8> {
    let mut outside = vec![false; region.len()];
    let mut stack: Vec<usize> = (0..width)
        .flat_map(|x| [x, (height - 1) * width + x])
        .chain((0..height).flat_map(|y| [y * width, y * width + width - 1]))
        .filter(|&i| region.get(i) == Some(&0))
        .collect();
    for &i in &stack {
        outside[i] = true;
    }
    while let Some(i) = stack.pop() {
        let (x, y) = (i % width, i / width);
        let mut visit = |j: usize| {
            if region[j] == 0 && !outside[j] {
                outside[j] = true;
                stack.push(j);
            }
        };
        if x > 0 {
            visit(i - 1);
        }
        if x + 1 < width {
            visit(i + 1);
        }
        if y > 0 {
            visit(i - width);
        }
        if y + 1 < height {
            visit(i + width);
        }
    }
    outside.iter().map(|&o| u8::from(!o)).collect()
}

/// Widens the 1s of `mask` by `r` pixels (a square of side `2r + 1` around each).
fn widen(mask: &mut [u8], width: usize, height: usize, r: usize) {
    if r == 0 {
        return;
    }
    // Distance (in pixels, the larger of the two axes) to the nearest 1, in two passes.
    let far = u32::MAX / 2;
    let mut d: Vec<u32> = mask.iter().map(|&m| if m != 0 { 0 } else { far }).collect();
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let mut v = d[i];
            if x > 0 {
                v = v.min(d[i - 1] + 1);
            }
            if y > 0 {
                v = v.min(d[i - width] + 1);
                if x > 0 {
                    v = v.min(d[i - width - 1] + 1);
                }
                if x + 1 < width {
                    v = v.min(d[i - width + 1] + 1);
                }
            }
            d[i] = v;
        }
    }
    for y in (0..height).rev() {
        for x in (0..width).rev() {
            let i = y * width + x;
            let mut v = d[i];
            if x + 1 < width {
                v = v.min(d[i + 1] + 1);
            }
            if y + 1 < height {
                v = v.min(d[i + width] + 1);
                if x + 1 < width {
                    v = v.min(d[i + width + 1] + 1);
                }
                if x > 0 {
                    v = v.min(d[i + width - 1] + 1);
                }
            }
            d[i] = v;
        }
    }
    for (m, &v) in mask.iter_mut().zip(&d) {
        *m = u8::from(v as usize <= r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ring_around_a_disc_leaves_the_disc_as_the_floor() {
        let (w, h) = (60usize, 60usize);
        let mask: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64 - 30.0, (i / w) as f64 - 30.0);
                let r = (x * x + y * y).sqrt();
                u8::from(r < 12.0 || (r > 16.0 && r < 29.0))
            })
            .collect();
        let region = floor_region(&mask, w, h);
        assert_eq!(region[30 * w + 30], 1);
        assert_eq!(region[30 * w + 50], 0);
        let mut filled = fill_holes(&[1, 1, 1, 1, 0, 1, 1, 1, 1], 3, 3);
        assert_eq!(filled, vec![1; 9]);
        filled = vec![0; 25];
        filled[12] = 1;
        widen(&mut filled, 5, 5, 1);
        assert_eq!(filled.iter().filter(|&&v| v == 1).count(), 9);
    }
}
