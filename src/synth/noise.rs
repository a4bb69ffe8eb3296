//! Depth sensor noise: Gaussian noise, the structured-light camera's disparity quantisation
//! and projector shadows, missing pixels at edges, and the time-of-flight camera's flying
//! pixels at depth discontinuities.
//!
//! Noise works on a depth buffer of `f32` millimetres (0 = no reading) covering a region of
//! the image; it needs the region's place in the image for the projector's geometry.

use crate::core::geometry::Intrinsics;
use crate::core::image::Region;
use crate::core::noise::{DepthNoise, NoiseModel};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// Projector-camera baseline of a Primesense-like camera, millimetres.
pub const BASELINE_MM: f64 = 75.0;
/// A jump bigger than this between neighbours is a depth edge.
const EDGE_MM: f32 = 12.0;

impl DepthNoise {
    /// Applies the noise to `depth` (row-major over `region`) in place.
    pub fn apply(&self, depth: &mut [f32], region: Region, intrinsics: &Intrinsics, rng: &mut impl Rng) {
        let w = region.width as usize;
        let h = region.height as usize;
        debug_assert_eq!(depth.len(), w * h);
        match self.model {
            NoiseModel::None => {}
            NoiseModel::StructuredLight => structured_light(depth, region, intrinsics, rng),
            NoiseModel::Tof => tof(depth, w, h, rng),
        }
        if self.gaussian_mm > 0.0 {
            let sigma = self.gaussian_mm as f32;
            for z in depth.iter_mut().filter(|z| **z > 0.0) {
                let n: f32 = StandardNormal.sample(rng);
                *z = (*z + sigma * n).max(1.0);
            }
        }
    }
}

/// Converts a noisy depth buffer to the camera's u16 millimetres (0 = no reading).
pub fn quantise(depth: &[f32]) -> Vec<u16> {
    depth
        .iter()
        .map(|&z| {
            if z > 0.0 && z.is_finite() {
                z.round().min(65535.0) as u16
            } else {
                0
            }
        })
        .collect()
}

/// True where a pixel differs from a 4-neighbour by more than an edge's jump.
fn edges(depth: &[f32], w: usize, h: usize) -> Vec<bool> {
    let mut out = vec![false; depth.len()];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let z = depth[i];
            let jump = |j: usize| (depth[j] - z).abs() > EDGE_MM;
            out[i] = (x > 0 && jump(i - 1))
                || (x + 1 < w && jump(i + 1))
                || (y > 0 && jump(i - w))
                || (y + 1 < h && jump(i + w));
        }
    }
    out
}

fn structured_light(depth: &mut [f32], region: Region, intrinsics: &Intrinsics, rng: &mut impl Rng) {
    let w = region.width as usize;
    let h = region.height as usize;
    let fb = (intrinsics.fx * BASELINE_MM) as f32;
    let edge = edges(depth, w, h);
    for y in 0..h {
        let row = &mut depth[y * w..(y + 1) * w];
        // Projector shadows: the projector sits `BASELINE_MM` to the camera's right, so scanning
        // from the right a point is lit only if its projector column is left of all seen so far.
        let mut min_proj = f32::INFINITY;
        for x in (0..w).rev() {
            let z = row[x];
            if z <= 0.0 {
                continue;
            }
            let u = (region.x0 as usize + x) as f32;
            let u_proj = u - fb / z;
            if u_proj >= min_proj - 0.25 {
                row[x] = 0.0;
            } else {
                min_proj = u_proj;
            }
        }
    }
    for (i, z) in depth.iter_mut().enumerate() {
        if *z <= 0.0 {
            continue;
        }
        // Steep edges often give no reading; a few pixels drop out anywhere.
        let p_drop = if edge[i] { 0.35 } else { 0.001 };
        if rng.gen_bool(p_drop) {
            *z = 0.0;
            continue;
        }
        // Disparity with a little matching noise, quantised to 1/8 pixel.
        let n: f32 = StandardNormal.sample(rng);
        let disparity = fb / *z + 0.04 * n;
        let q = (disparity * 8.0).round() / 8.0;
        *z = if q > 0.0 { fb / q } else { 0.0 };
    }
}

fn tof(depth: &mut [f32], w: usize, h: usize, rng: &mut impl Rng) {
    let edge = edges(depth, w, h);
    let source = depth.to_vec();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let z = source[i];
            if z <= 0.0 {
                continue;
            }
            if edge[i] && rng.gen_bool(0.7) {
                // A flying pixel: the pixel mixes the two surfaces it straddles.
                let mut far = z;
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                        let nz = source[ny as usize * w + nx as usize];
                        if (nz - z).abs() > (far - z).abs() {
                            far = nz;
                        }
                    }
                }
                let t: f32 = rng.r#gen();
                depth[i] = z + (far - z) * t;
                continue;
            }
            let sigma = 0.6 + 2.0 * (z / 1000.0) * (z / 1000.0);
            let n: f32 = StandardNormal.sample(rng);
            depth[i] = z + sigma * n;
            if rng.gen_bool(0.0005) {
                depth[i] = 0.0;
            }
        }
    }
}
