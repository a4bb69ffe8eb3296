//! The segmented mouse ([`Mouse`]) and the last steps of a frame: the grown mask tidied
//! inside its box (pixels on jumps decided by their neighbours, dropouts and small holes
//! filled, the body core opened out of it), then the figures MoSeq users know from its 3D
//! points: area, mean height, and the body's centroid, heading, length and width.

use super::{Bounds, Grid, SegmentError, Segmenter, cv_err, mat_over, mat_over_mut, same_buffer};
use crate::core::image::Region;
use nalgebra::{Matrix2, Point3, SymmetricEigen, Vector2, Vector3};
use opencv::core::{self as cv, Mat};
use opencv::imgproc;
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
        // The mask's box with a border of one empty pixel, as a local image.
        let (bw, bh) = (b.width(), b.height());
        let (lw, lh) = (bw + 2, bh + 2);
        let s = &mut self.scratch;
        s.local[..lw * lh].fill(0);
        for y in b.y0..b.y1 {
            let src = &mut s.mask[y * g.w + b.x0..y * g.w + b.x1];
            let l = (y - b.y0 + 1) * lw + 1;
            s.local[l..l + bw].copy_from_slice(src);
            src.fill(0);
        }
        // Pixel (lx, ly) of the local image is pixel (x0 + lx, y0 + ly) of the region, where
        // x0 = b.x0 - 1 may be -1: the border may lie outside the region but stays empty.
        let to_region = |lx: usize, ly: usize| -> Option<usize> {
            let x = (b.x0 + lx).checked_sub(1)?;
            let y = (b.y0 + ly).checked_sub(1)?;
            (x < g.w && y < g.h).then_some(y * g.w + x)
        };
        // An inner pixel of the local image (not its border) is always in the region.
        let inner = |lx: usize, ly: usize| (b.y0 + ly - 1) * g.w + b.x0 + lx - 1;
        let fx = self.background.intrinsics.fx;
        let fy = self.background.intrinsics.fy;
        // The mouse's typical depth sets the size of a pixel.
        let mut sum_z = 0.0;
        let mut n_z = 0usize;
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                if s.local[ly * lw + lx] != 0
                    && let i = inner(lx, ly)
                    && depth[i] > 0
                {
                    sum_z += f64::from(depth[i]);
                    n_z += 1;
                }
            }
        }
        if n_z == 0 {
            return Ok(None);
        }
        let mean_z = sum_z / n_z as f64;
        let pixel_mm2 = (mean_z / fx) * (mean_z / fy);

        // Pixels on a depth jump go with the majority of their neighbours off jumps (mouse or
        // floor reading); pixels without a reading join the mask when most of their
        // neighbours are in it: dropouts along the mouse's edge. Only ever one pixel deep, so
        // nothing thin is cut.
        s.before[..lw * lh].copy_from_slice(&s.local[..lw * lh]);
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let l = ly * lw + lx;
                let i = inner(lx, ly);
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
                    let Some(j) = to_region(nx, ny) else {
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

        // Holes: background (4-connected) that the border of the local image does not reach.
        // Background with mask on both sides along its row and along its column may be in a
        // hole; anything else sees the border along a row or a column. A group of such
        // candidates is a hole when none of it touches other background. `before` marks: 0
        // background, 1 mask, 2 a candidate, 3 a candidate already looked at.
        let max_hole = (f64::from(self.config.max_hole_mm2) / pixel_mm2).floor() as usize;
        if max_hole > 0 {
            s.before[..lw * lh].fill(0);
            for ly in 1..lh - 1 {
                let row = &s.local[ly * lw..(ly + 1) * lw];
                if let (Some(first), Some(last)) = (row.iter().position(|&v| v != 0), row.iter().rposition(|&v| v != 0))
                {
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

        // The body core: the mask opened by a square (separable, so fast), for the body's
        // figures only.
        let radius = (f64::from(self.config.body_core_mm) * fx / mean_z).round() as i32;
        let mut core_empty = true;
        if radius > 0 {
            if s.core_kernel.as_ref().is_none_or(|(r, _)| *r != radius) {
                let k = imgproc::get_structuring_element(
                    imgproc::MORPH_RECT,
                    cv::Size::new(2 * radius + 1, 2 * radius + 1),
                    cv::Point::new(-1, -1),
                )
                .map_err(cv_err("getStructuringElement"))?;
                s.core_kernel = Some((radius, k));
            }
            if let Some((_, kernel)) = &s.core_kernel {
                let src = mat_over(&s.local, lh, lw)?;
                let dst_ptr = s.core.as_ptr();
                let mut dst = mat_over_mut(&mut s.core, lh, lw)?;
                morphology(&src, &mut dst, imgproc::MORPH_OPEN, kernel)?;
                same_buffer(&dst, dst_ptr, "morphologyEx")?;
                drop(dst);
                drop(src);
                core_empty = s.core[..lw * lh].iter().all(|&v| v == 0);
            }
        }
        if core_empty {
            s.core[..lw * lh].copy_from_slice(&s.local[..lw * lh]);
        }

        // Figures from the 3D points.
        let floor = self.background.floor;
        let rays = &self.background.rays;
        let ray_at = |i: usize| {
            let (x, y) = (i % g.w, i / g.w);
            rays.get((g.oy + y) * g.bg_w + g.ox + x).copied().unwrap_or([0.0, 0.0])
        };
        let mut mask = Vec::with_capacity(bw * bh);
        let mut points = Vec::with_capacity(bw * bh);
        let mut pixel_count = 0usize;
        let mut missing = 0usize;
        let mut area = 0.0;
        let mut height_sum = 0.0;
        let mut core_sum = Vector3::zeros();
        let mut core_points = 0usize;
        // Body core coordinates in the floor plane: u, v orthonormal, across the normal.
        let n = floor.normal;
        let u = {
            let x = Vector3::x() - n * n.x;
            if x.norm() > 1e-6 {
                x.normalize()
            } else {
                (Vector3::y() - n * n.y).normalize()
            }
        };
        let v = n.cross(&u);
        let mut m1 = Vector2::zeros();
        let mut m2 = Matrix2::zeros();
        for ly in 1..lh - 1 {
            for lx in 1..lw - 1 {
                let l = ly * lw + lx;
                let inside = s.local[l] != 0;
                mask.push(u8::from(inside));
                if !inside {
                    continue;
                }
                pixel_count += 1;
                let i = inner(lx, ly);
                let z = depth[i];
                if z == 0 {
                    missing += 1;
                    continue;
                }
                let z = f64::from(z);
                let r = ray_at(i);
                let p = Vector3::new(f64::from(r[0]) * z, f64::from(r[1]) * z, z);
                points.push(Point3::new(p.x as f32, p.y as f32, p.z as f32));
                area += (z / fx) * (z / fy);
                height_sum += n.dot(&p) + floor.offset_mm;
                if s.core[l] != 0 {
                    core_sum += p;
                    core_points += 1;
                    let q = Vector2::new(u.dot(&p), v.dot(&p));
                    m1 += q;
                    m2 += q * q.transpose();
                }
            }
        }
        if points.is_empty() || core_points == 0 {
            return Ok(None);
        }
        area += missing as f64 * pixel_mm2;
        let k = core_points as f64;
        let centroid = core_sum / k;
        let mean = m1 / k;
        let cov = m2 / k - mean * mean.transpose();
        let eig = SymmetricEigen::new(cov);
        let (major, minor) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
            (0, 1)
        } else {
            (1, 0)
        };
        let length = 4.0 * eig.eigenvalues[major].max(0.0).sqrt();
        let width = 4.0 * eig.eigenvalues[minor].max(0.0).sqrt();
        let e = eig.eigenvectors.column(major);
        let mut axis = u * e[0] + v * e[1];
        // The tail's end reaches further from the centroid than the snout.
        let (mut ahead, mut behind) = (0.0f64, 0.0f64);
        for p in &points {
            let t = axis.dot(&(p.coords.cast::<f64>() - centroid));
            ahead = ahead.max(t);
            behind = behind.max(-t);
        }
        let heading_resolved = (ahead - behind).abs() > TAIL_SIDE_MM;
        if heading_resolved && ahead > behind {
            axis = -axis;
        }
        let (frame, centroid_out, axis_out) = match &self.world_from_camera {
            Some(iso) => (PoseFrame::World, iso * Point3::from(centroid), iso * axis),
            None => (PoseFrame::Camera, Point3::from(centroid), axis),
        };
        let mut heading = axis_out.y.atan2(axis_out.x);
        if !heading_resolved {
            // Only the axis is known: give it in (-pi/2, pi/2].
            if heading > std::f64::consts::FRAC_PI_2 {
                heading -= std::f64::consts::PI;
            } else if heading <= -std::f64::consts::FRAC_PI_2 {
                heading += std::f64::consts::PI;
            }
        }
        let n_points = points.len() as f64;
        Ok(Some(Mouse {
            region: Region {
                x0: region.x0 + b.x0 as u32,
                y0: region.y0 + b.y0 as u32,
                width: bw as u32,
                height: bh as u32,
            },
            mask,
            pixel_count,
            points_mm: points,
            frame,
            centroid_mm: centroid_out,
            heading_rad: heading,
            heading_resolved,
            length_mm: length,
            width_mm: width,
            area_mm2: area,
            mean_height_mm: height_sum / n_points,
        }))
    }
}

fn morphology(
    src: &impl cv::ToInputArray,
    dst: &mut impl cv::ToOutputArray,
    op: i32,
    kernel: &Mat,
) -> Result<(), SegmentError> {
    let border = imgproc::morphology_default_border_value().map_err(cv_err("morphologyDefaultBorderValue"))?;
    imgproc::morphology_ex(
        src,
        dst,
        op,
        kernel,
        cv::Point::new(-1, -1),
        1,
        cv::BORDER_CONSTANT,
        border,
    )
    .map_err(cv_err("morphologyEx"))
}
