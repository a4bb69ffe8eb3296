//! The segmented mouse ([`Mouse`]) and the last steps of a frame: the grown mask tidied
//! inside its box (pixels on jumps decided by their neighbours, dropouts and small holes
//! filled, the body core opened out of it), then the figures MoSeq users know from its 3D
//! points: area, mean height, and the body's centroid, heading, length and width.

use super::{Bounds, Grid, Scratch, SegmentError, Segmenter};
use crate::core::image::Region;
use nalgebra::{Matrix2, Point3, SymmetricEigen, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::fmt;

/// The ends of the body along its axis must differ by this much for the longer one to be taken
/// for the tail's side.
const TAIL_SIDE_MM: f64 = 12.0;
/// A pixel without a reading joins the mask when at least this many of its neighbours are in
/// it (and more of them than read the floor).
const FILL_MIN_NEIGHBOURS: usize = 4;

/// Which frame the mouse's centroid and heading are given in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseFrame {
    /// The world frame (origin on the glass, z up), when the segmenter knows the camera's pose.
    World,
    /// The depth camera's frame.
    Camera,
}

/// The segmented mouse of one frame.
#[derive(Clone, PartialEq)]
pub struct Mouse {
    /// The mouse's bounding box in the image.
    pub region: Region,
    /// 1 where a pixel shows the mouse, 0 elsewhere, row-major over `region`.
    pub mask: Vec<u8>,
    /// Pixels in the mask.
    pub pixel_count: usize,
    /// The mask's pixels that have a reading, as points in the camera frame (mm), in row-major
    /// order. Filled holes have no reading and no point.
    pub points_mm: Vec<Point3<f32>>,
    /// The frame of `centroid_mm` and `heading_rad`.
    pub frame: PoseFrame,
    /// Mean of the body's 3D surface points (the tail left out), mm.
    pub centroid_mm: Point3<f64>,
    /// Direction of the body's long axis in the floor plane, radians from the frame's x axis
    /// towards its y axis (world: counter-clockwise seen from above). The axis alone has no
    /// front: when one end of the mask reaches clearly further from the centroid than the other
    /// (the tail's side) the heading points to the other end and `heading_resolved` is true;
    /// otherwise it may point backwards (it lies in (-pi/2, pi/2]).
    pub heading_rad: f64,
    pub heading_resolved: bool,
    /// Length and width of the body (the tail left out) along and across its axis: those of
    /// the ellipse with the same second moments (MoSeq's), mm in the floor plane.
    pub length_mm: f64,
    pub width_mm: f64,
    /// Area seen from above: each pixel's footprint at its depth, summed (mm^2).
    pub area_mm2: f64,
    /// Mean height of the mask's readings above the floor (mm).
    pub mean_height_mm: f64,
    /// 1 where a pixel of `region` lies within [`super::WALL_REACH_MM`] of the cage's walls,
    /// something fixed on its floor or the arena's rim (clutter gathers there), row-major.
    pub wall: Vec<u8>,
}

impl fmt::Debug for Mouse {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Mouse")
            .field("region", &self.region)
            .field("pixel_count", &self.pixel_count)
            .field("frame", &self.frame)
            .field("centroid_mm", &self.centroid_mm)
            .field("heading_rad", &self.heading_rad)
            .field("heading_resolved", &self.heading_resolved)
            .field("length_mm", &self.length_mm)
            .field("width_mm", &self.width_mm)
            .field("area_mm2", &self.area_mm2)
            .field("mean_height_mm", &self.mean_height_mm)
            .finish_non_exhaustive()
    }
}

impl Mouse {
    /// Whether the pixel `(x, y)` of the image is in the mask.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        if !self.region.contains(x, y) {
            return false;
        }
        let i = (y - self.region.y0) as usize * self.region.width as usize + (x - self.region.x0) as usize;
        self.mask.get(i).is_some_and(|&m| m != 0)
    }

    /// The mean position of the mask's pixels in the image (pixels): where a split of touching
    /// mice starts from in the next frame ([`super::Segmenter::segment_mice`]).
    pub fn image_centre(&self) -> (f64, f64) {
        let w = self.region.width as usize;
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0f64);
        for (i, _) in self.mask.iter().enumerate().filter(|(_, m)| **m != 0) {
            sx += f64::from(self.region.x0) + (i % w) as f64;
            sy += f64::from(self.region.y0) + (i / w) as f64;
            n += 1.0;
        }
        (sx / n.max(1.0), sy / n.max(1.0))
    }
}

/// The mask's box with a border of one empty pixel, as a local image of `lw` x `lh` pixels
/// (the box itself is `bw` x `bh`).
#[derive(Clone, Copy, Debug)]
struct LocalBox {
    b: Bounds,
    /// The region's size.
    w: usize,
    h: usize,
    bw: usize,
    bh: usize,
    lw: usize,
    lh: usize,
}

impl LocalBox {
    fn new(g: &Grid, b: Bounds) -> Self {
        let (bw, bh) = (b.width(), b.height());
        Self {
            b,
            w: g.w,
            h: g.h,
            bw,
            bh,
            lw: bw + 2,
            lh: bh + 2,
        }
    }

    /// The local image's pixel count.
    fn pixels(&self) -> usize {
        self.lw * self.lh
    }

    /// Pixel (lx, ly) of the local image is pixel (x0 + lx, y0 + ly) of the region, where
    /// x0 = b.x0 - 1 may be -1: the border may lie outside the region but stays empty.
    fn region_pixel(&self, lx: usize, ly: usize) -> Option<usize> {
        let x = (self.b.x0 + lx).checked_sub(1)?;
        let y = (self.b.y0 + ly).checked_sub(1)?;
        (x < self.w && y < self.h).then_some(y * self.w + x)
    }

    /// An inner pixel of the local image (not its border) is always in the region.
    fn inner(&self, lx: usize, ly: usize) -> usize {
        (self.b.y0 + ly - 1) * self.w + self.b.x0 + lx - 1
    }
}

/// What the mask's readings add up to, in row-major order over the box.
struct Readings {
    /// The mask over the box (without the local image's border).
    mask: Vec<u8>,
    points: Vec<Point3<f32>>,
    pixel_count: usize,
    /// Mask pixels without a reading.
    missing: usize,
    /// The readings' footprints, summed (mm^2).
    area: f64,
    height_sum: f64,
    /// The body core's points: their sum and count, and their first and second moments in
    /// the floor plane's coordinates `u`, `v`.
    core_sum: Vector3<f64>,
    core_points: usize,
    u: Vector3<f64>,
    v: Vector3<f64>,
    m1: Vector2<f64>,
    m2: Matrix2<f64>,
}

/// The body's figures in the camera frame, from its core.
struct BodyAxis {
    centroid: Vector3<f64>,
    length: f64,
    width: f64,
    /// The long axis, pointing away from the tail's side when `heading_resolved`.
    axis: Vector3<f64>,
    heading_resolved: bool,
}

impl Segmenter {
    /// Closing, hole filling and the scalars, inside the mask's box; clears `scratch.mask`.
    pub(super) fn finish(
        &mut self,
        depth: &[u16],
        region: Region,
        g: &Grid,
        b: Bounds,
    ) -> Result<Option<Mouse>, SegmentError> {
        let lb = self.scratch.take_box(g, b);
        let fx = self.background.intrinsics.fx;
        let fy = self.background.intrinsics.fy;
        // The mouse's typical depth sets the size of a pixel.
        let Some(mean_z) = self.scratch.mean_depth(depth, &lb) else {
            return Ok(None);
        };
        let pixel_mm2 = (mean_z / fx) * (mean_z / fy);
        self.scratch.settle_edges(depth, &lb);
        let max_hole = (f64::from(self.config.max_hole_mm2) / pixel_mm2).floor() as usize;
        if max_hole > 0 {
            self.scratch.fill_holes(&lb, max_hole);
        }
        let radius = (f64::from(self.config.body_core_mm) * fx / mean_z).round() as i32;
        self.scratch.open_core(&lb, radius);

        // Figures from the 3D points.
        let sums = self.readings(depth, g, &lb);
        if sums.points.is_empty() || sums.core_points == 0 {
            return Ok(None);
        }
        let area = sums.area + sums.missing as f64 * pixel_mm2;
        let body = body_axis(&sums);
        let (frame, centroid_out, axis_out) = match &self.world_from_camera {
            Some(iso) => (PoseFrame::World, iso * Point3::from(body.centroid), iso * body.axis),
            None => (PoseFrame::Camera, Point3::from(body.centroid), body.axis),
        };
        let mut heading = axis_out.y.atan2(axis_out.x);
        if !body.heading_resolved {
            // Only the axis is known: give it in (-pi/2, pi/2].
            if heading > std::f64::consts::FRAC_PI_2 {
                heading -= std::f64::consts::PI;
            } else if heading <= -std::f64::consts::FRAC_PI_2 {
                heading += std::f64::consts::PI;
            }
        }
        let n_points = sums.points.len() as f64;
        let wall = (0..lb.bh)
            .flat_map(|y| {
                let at = (g.oy + b.y0 + y) * g.bg_w + g.ox + b.x0;
                self.near_wall[at..at + lb.bw].iter().copied()
            })
            .collect();
        Ok(Some(Mouse {
            region: Region {
                x0: region.x0 + b.x0 as u32,
                y0: region.y0 + b.y0 as u32,
                width: lb.bw as u32,
                height: lb.bh as u32,
            },
            wall,
            mask: sums.mask,
            pixel_count: sums.pixel_count,
            points_mm: sums.points,
            frame,
            centroid_mm: centroid_out,
            heading_rad: heading,
            heading_resolved: body.heading_resolved,
            length_mm: body.length,
            width_mm: body.width,
            area_mm2: area,
            mean_height_mm: sums.height_sum / n_points,
        }))
    }

    /// The mask's pixels in 3D: the points, the mask's area and height, and the body core's
    /// sums (in the floor plane's coordinates: `u`, `v` orthonormal, across its normal).
    fn readings(&self, depth: &[u16], g: &Grid, lb: &LocalBox) -> Readings {
        let (lw, lh) = (lb.lw, lb.lh);
        let s = &self.scratch;
        let fx = self.background.intrinsics.fx;
        let fy = self.background.intrinsics.fy;
        let floor = self.background.floor;
        let rays = &self.background.rays;
        let ray_at = |i: usize| {
            let (x, y) = (i % g.w, i / g.w);
            rays.get((g.oy + y) * g.bg_w + g.ox + x).copied().unwrap_or([0.0, 0.0])
        };
        let n = floor.normal;
        let u = {
            let x = Vector3::x() - n * n.x;
            if x.norm() > 1e-6 {
                x.normalize()
            } else {
                (Vector3::y() - n * n.y).normalize()
            }
        };
        let mut r = Readings {
            mask: Vec::with_capacity(lb.bw * lb.bh),
            points: Vec::with_capacity(lb.bw * lb.bh),
            pixel_count: 0,
            missing: 0,
            area: 0.0,
            height_sum: 0.0,
            core_sum: Vector3::zeros(),
            core_points: 0,
            u,
            v: n.cross(&u),
            m1: Vector2::zeros(),
            m2: Matrix2::zeros(),
        };
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let l = ly * lw + lx;
                let inside = s.local[l] != 0;
                r.mask.push(u8::from(inside));
                if !inside {
                    continue;
                }
                r.pixel_count += 1;
                let i = lb.inner(lx, ly);
                let z = depth[i];
                if z == 0 {
                    r.missing += 1;
                    continue;
                }
                let z = f64::from(z);
                let ray = ray_at(i);
                let p = Vector3::new(f64::from(ray[0]) * z, f64::from(ray[1]) * z, z);
                r.points.push(Point3::new(p.x as f32, p.y as f32, p.z as f32));
                r.area += (z / fx) * (z / fy);
                r.height_sum += n.dot(&p) + floor.offset_mm;
                if s.core[l] != 0 {
                    r.core_sum += p;
                    r.core_points += 1;
                    let q = Vector2::new(r.u.dot(&p), r.v.dot(&p));
                    r.m1 += q;
                    r.m2 += q * q.transpose();
                }
            }
        }
        r
    }
}

/// The body's centroid, length and width (those of the ellipse with the core's second
/// moments) and its long axis, turned away from the tail's side when one end of the mask
/// reaches clearly further from the centroid than the other.
fn body_axis(r: &Readings) -> BodyAxis {
    let k = r.core_points as f64;
    let centroid = r.core_sum / k;
    let mean = r.m1 / k;
    let cov = r.m2 / k - mean * mean.transpose();
    let eig = SymmetricEigen::new(cov);
    let (major, minor) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    let length = 4.0 * eig.eigenvalues[major].max(0.0).sqrt();
    let width = 4.0 * eig.eigenvalues[minor].max(0.0).sqrt();
    let e = eig.eigenvectors.column(major);
    let mut axis = r.u * e[0] + r.v * e[1];
    // The tail's end reaches further from the centroid than the snout.
    let (mut ahead, mut behind) = (0.0f64, 0.0f64);
    for p in &r.points {
        let t = axis.dot(&(p.coords.cast::<f64>() - centroid));
        ahead = ahead.max(t);
        behind = behind.max(-t);
    }
    let heading_resolved = (ahead - behind).abs() > TAIL_SIDE_MM;
    if heading_resolved && ahead > behind {
        axis = -axis;
    }
    BodyAxis {
        centroid,
        length,
        width,
        axis,
        heading_resolved,
    }
}

impl Scratch {
    /// Moves the mask's box out of `mask` (cleared) into `local`, with a border of one empty
    /// pixel.
    fn take_box(&mut self, g: &Grid, b: Bounds) -> LocalBox {
        let lb = LocalBox::new(g, b);
        self.local[..lb.pixels()].fill(0);
        for y in b.y0..b.y1 {
            let src = &mut self.mask[y * g.w + b.x0..y * g.w + b.x1];
            let l = (y - b.y0 + 1) * lb.lw + 1;
            self.local[l..l + lb.bw].copy_from_slice(src);
            src.fill(0);
        }
        lb
    }

    /// The mean depth (mm) of the mask's readings; `None` when it has none.
    fn mean_depth(&self, depth: &[u16], lb: &LocalBox) -> Option<f64> {
        let mut sum_z = 0.0;
        let mut n_z = 0usize;
        for ly in 1..lb.lh - 1 {
            for lx in 1..lb.lw - 1 {
                if self.local[ly * lb.lw + lx] != 0
                    && let i = lb.inner(lx, ly)
                    && depth[i] > 0
                {
                    sum_z += f64::from(depth[i]);
                    n_z += 1;
                }
            }
        }
        (n_z != 0).then(|| sum_z / n_z as f64)
    }

    /// Pixels on a depth jump go with the majority of their neighbours off jumps (mouse or
    /// floor reading); pixels without a reading join the mask when most of their
    /// neighbours are in it: dropouts along the mouse's edge. Only ever one pixel deep, so
    /// nothing thin is cut.
    fn settle_edges(&mut self, depth: &[u16], lb: &LocalBox) {
        let (lw, lh) = (lb.lw, lb.lh);
        let s = self;
        s.before[..lw * lh].copy_from_slice(&s.local[..lw * lh]);
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let l = ly * lw + lx;
                let i = lb.inner(lx, ly);
                let on_jump = s.jump[i] != 0;
                if !on_jump && (s.before[l] != 0 || depth[i] != 0) {
                    continue;
                }
                let (mut mouse, mut floor) = (0usize, 0usize);
                for (nx, ny) in [
                    (lx - 1, ly - 1),
                    (lx, ly - 1),
                    (lx + 1, ly - 1),
                    (lx - 1, ly),
                    (lx + 1, ly),
                    (lx - 1, ly + 1),
                    (lx, ly + 1),
                    (lx + 1, ly + 1),
                ] {
                    let Some(j) = lb.region_pixel(nx, ny) else {
                        continue;
                    };
                    if s.jump[j] != 0 {
                        continue;
                    }
                    if s.before[ny * lw + nx] != 0 {
                        mouse += 1;
                    } else if depth[j] != 0 {
                        floor += 1;
                    }
                }
                if on_jump {
                    if mouse != floor {
                        s.local[l] = u8::from(mouse > floor);
                    }
                } else if mouse >= FILL_MIN_NEIGHBOURS && mouse > floor {
                    s.local[l] = 1;
                }
            }
        }
    }

    /// Holes: background (4-connected) that the border of the local image does not reach,
    /// filled when they hold at most `max_hole` pixels. Background with mask on both sides
    /// along its row and along its column may be in a hole; anything else sees the border
    /// along a row or a column. A group of such candidates is a hole when none of it touches
    /// other background.
    fn fill_holes(&mut self, lb: &LocalBox, max_hole: usize) {
        self.mark_hole_candidates(lb);
        let (lw, lh) = (lb.lw, lb.lh);
        let s = self;
        for start in 0..lw * lh {
            if s.before[start] != 2 {
                continue;
            }
            s.before[start] = 3;
            s.stack.clear();
            s.stack.push(start as u32);
            s.branch.clear();
            let mut closed = true;
            while let Some(l) = s.stack.pop() {
                let l = l as usize;
                s.branch.push(l as u32);
                // Candidates never lie on the local image's border.
                for n in [l - 1, l + 1, l - lw, l + lw] {
                    match s.before[n] {
                        0 => closed = false,
                        2 => {
                            s.before[n] = 3;
                            s.stack.push(n as u32);
                        }
                        _ => {}
                    }
                }
            }
            if closed && s.branch.len() <= max_hole {
                for &l in &s.branch {
                    s.local[l as usize] = 1;
                }
            }
        }
    }

    /// Marks in `before` the candidates of holes: 0 background, 1 mask, 2 a candidate (mask
    /// on both sides along its row and its column); `fill_holes` marks 3 a candidate
    /// already looked at.
    fn mark_hole_candidates(&mut self, lb: &LocalBox) {
        let (lw, lh) = (lb.lw, lb.lh);
        let s = self;
        s.before[..lw * lh].fill(0);
        for ly in 1..lh - 1 {
            let row = &s.local[ly * lw..(ly + 1) * lw];
            if let (Some(first), Some(last)) = (row.iter().position(|&v| v != 0), row.iter().rposition(|&v| v != 0)) {
                for (b, &m) in s.before[ly * lw + first..=ly * lw + last]
                    .iter_mut()
                    .zip(&row[first..=last])
                {
                    *b = if m != 0 { 1 } else { 2 };
                }
            }
        }
        // Column limits, one row at a time: the first and last mask row of each column.
        s.column_first.clear();
        s.column_first.resize(lw, usize::MAX);
        s.column_last.clear();
        s.column_last.resize(lw, 0);
        for ly in 1..lh - 1 {
            for (lx, &m) in s.local[ly * lw..(ly + 1) * lw].iter().enumerate() {
                if m != 0 {
                    s.column_first[lx] = s.column_first[lx].min(ly);
                    s.column_last[lx] = ly;
                }
            }
        }
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let b = &mut s.before[ly * lw + lx];
                if *b == 2 && !(s.column_first[lx] < ly && ly < s.column_last[lx]) {
                    *b = 0;
                }
            }
        }
    }

    /// The body core into `core`: the mask opened by a square of `radius` pixels (separable,
    /// so fast), for the body's figures only; the mask itself when that leaves nothing.
    fn open_core(&mut self, lb: &LocalBox, radius: i32) {
        let (lw, lh) = (lb.lw, lb.lh);
        let s = self;
        let mut core_empty = true;
        if radius > 0 {
            super::components::open_square(&s.local, &mut s.core, lw, lh, radius as usize, &mut s.open_tmp);
            core_empty = s.core[..lw * lh].iter().all(|&v| v == 0);
        }
        if core_empty {
            s.core[..lw * lh].copy_from_slice(&s.local[..lw * lh]);
        }
    }
}
