//! The grey image the cascade runs on: a region of a colour frame at a chosen scale in pixels
//! per millimetre on the glass.
//!
//! Bayer frames are averaged over 2x2 blocks (one red, two green, one blue sample each), which
//! demosaics and halves the resolution in one step; RGB frames are weighted the same way
//! ((R + 2G + B) / 4); mono frames are used as they are. The result is then resampled to the
//! requested scale: area averaging when shrinking, bilinear interpolation when enlarging.

use crate::core::frame::{ColorFrame, PixelFormat};

/// The largest grey image [`Greyer::convert`] makes (pixels).
pub const MAX_PIXELS: f64 = 16.0 * 1024.0 * 1024.0;

/// An 8-bit grey image, row-major, no padding.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u8>,
}

/// Where a grey image's pixels lie in its frame: frame `x = x0 + u * frame_px_per_px`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub x0: f64,
    pub y0: f64,
    /// Frame pixels per grey pixel.
    pub frame_px_per_px: f64,
}

impl Placement {
    /// The frame point of grey-image point `(u, v)`.
    pub fn to_frame(&self, u: f64, v: f64) -> (f64, f64) {
        (self.x0 + u * self.frame_px_per_px, self.y0 + v * self.frame_px_per_px)
    }
}

/// Converts frames to grey images at a scale, keeping its buffers between calls.
#[derive(Clone, Debug, Default)]
pub struct Greyer {
    native: GreyImage,
    scratch: ResampleScratch,
}

impl Greyer {
    /// Writes the region `roi` = `(x0, y0, x1, y1)` (clipped to the frame) of `frame`, seen at
    /// `px_per_mm`, into `out` at `target_px_per_mm`. Returns where `out` lies in the frame, or
    /// `None` when the region is empty, the scales are not positive or the frame's data is
    /// shorter than its size says.
    pub fn convert(
        &mut self,
        frame: &ColorFrame,
        roi: (u32, u32, u32, u32),
        px_per_mm: f64,
        target_px_per_mm: f64,
        out: &mut GreyImage,
    ) -> Option<Placement> {
        if !(px_per_mm > 0.0 && target_px_per_mm > 0.0 && px_per_mm.is_finite() && target_px_per_mm.is_finite()) {
            return None;
        }
        let (fw, fh) = (frame.width as usize, frame.height as usize);
        if frame.data.len() < ColorFrame::expected_len(frame.width, frame.height, frame.format) {
            return None;
        }
        let (mut x0, mut y0) = (roi.0 as usize, roi.1 as usize);
        let (mut x1, mut y1) = ((roi.2 as usize).min(fw), (roi.3 as usize).min(fh));
        let bayer = frame.format.bayer_channel(0, 0).is_some();
        if bayer {
            // Whole 2x2 blocks only.
            x0 &= !1;
            y0 &= !1;
            x1 &= !1;
            y1 &= !1;
        }
        if x1 <= x0 || y1 <= y0 {
            return None;
        }
        let n = &mut self.native;
        let native_px_per_mm;
        match frame.format {
            PixelFormat::Mono8 => {
                native_px_per_mm = px_per_mm;
                n.width = x1 - x0;
                n.height = y1 - y0;
                n.data.clear();
                for y in y0..y1 {
                    n.data.extend_from_slice(&frame.data[y * fw + x0..y * fw + x1]);
                }
            }
            PixelFormat::Rgb8 => {
                native_px_per_mm = px_per_mm;
                n.width = x1 - x0;
                n.height = y1 - y0;
                n.data.clear();
                for y in y0..y1 {
                    for p in frame.data[(y * fw + x0) * 3..(y * fw + x1) * 3].chunks_exact(3) {
                        let v = u32::from(p[0]) + 2 * u32::from(p[1]) + u32::from(p[2]);
                        n.data.push(((v + 2) / 4) as u8);
                    }
                }
            }
            _ => {
                native_px_per_mm = px_per_mm / 2.0;
                n.width = (x1 - x0) / 2;
                n.height = (y1 - y0) / 2;
                n.data.clear();
                for y in (y0..y1).step_by(2) {
                    let a = &frame.data[y * fw + x0..y * fw + x1];
                    let b = &frame.data[(y + 1) * fw + x0..(y + 1) * fw + x1];
                    for (pa, pb) in a.chunks_exact(2).zip(b.chunks_exact(2)) {
                        let v = u32::from(pa[0]) + u32::from(pa[1]) + u32::from(pb[0]) + u32::from(pb[1]);
                        n.data.push(((v + 2) / 4) as u8);
                    }
                }
            }
        }
        let ratio = native_px_per_mm / target_px_per_mm;
        // An absurd scale (a tiny `px_per_mm`) must not ask for a gigantic image.
        let pixels = (n.width as f64 / ratio) * (n.height as f64 / ratio);
        if pixels > MAX_PIXELS {
            return None;
        }
        resample(&self.native, ratio, out, &mut self.scratch);
        if out.width == 0 || out.height == 0 {
            return None;
        }
        Some(Placement {
            x0: x0 as f64,
            y0: y0 as f64,
            frame_px_per_px: px_per_mm / target_px_per_mm,
        })
    }
}

/// Scratch buffers of [`resample`], kept between calls so resampling does not allocate.
#[derive(Clone, Debug, Default)]
pub struct ResampleScratch {
    columns: Taps,
    lines: Taps,
    /// The horizontal pass: one row of output width per source row.
    rows: Vec<f32>,
    /// One output row being summed.
    acc: Vec<f32>,
}

/// What each output sample of a one-dimensional resampling reads: source indices with
/// weights, and the divisor of their weighted sum.
#[derive(Clone, Debug, Default)]
struct Taps {
    /// Per output sample: the range of its taps in `taps`, and its divisor.
    spans: Vec<(usize, usize, f32)>,
    /// (source index, weight).
    taps: Vec<(usize, f32)>,
}

impl Taps {
    /// The taps of `n` output samples from `len` source samples, `ratio` source samples per
    /// output sample: partial-pixel area weights when shrinking, bilinear when enlarging.
    fn build(&mut self, len: usize, n: usize, ratio: f64) {
        self.spans.clear();
        self.taps.clear();
        for k in 0..n {
            let first = self.taps.len();
            let divisor = if ratio > 1.0 {
                // The mean of source samples `[k * ratio, (k + 1) * ratio)`.
                let start = k as f64 * ratio;
                let end = ((k + 1) as f64 * ratio).min(len as f64);
                let mut i = start.floor() as usize;
                while (i as f64) < end && i < len {
                    let cover = (end.min(i as f64 + 1.0) - start.max(i as f64)) as f32;
                    self.taps.push((i, cover));
                    i += 1;
                }
                (end - start) as f32
            } else {
                let s = ((k as f64 + 0.5) * ratio - 0.5).max(0.0);
                let i0 = (s.floor() as usize).min(len - 1);
                let i1 = (i0 + 1).min(len - 1);
                let f = (s - i0 as f64) as f32;
                self.taps.push((i0, 1.0 - f));
                self.taps.push((i1, f));
                1.0
            };
            self.spans.push((first, self.taps.len(), divisor));
        }
    }
}

/// Resamples `src` so that `ratio` source pixels become one output pixel: area averaging for
/// `ratio > 1`, bilinear interpolation for `ratio < 1`, a copy for 1. Separable: a horizontal
/// pass over every source row, then a vertical pass one output row at a time.
pub fn resample(src: &GreyImage, ratio: f64, out: &mut GreyImage, scratch: &mut ResampleScratch) {
    let w = (src.width as f64 / ratio).floor() as usize;
    let h = (src.height as f64 / ratio).floor() as usize;
    out.width = w;
    out.height = h;
    out.data.clear();
    if w == 0 || h == 0 {
        return;
    }
    if (ratio - 1.0).abs() < 1e-9 {
        out.data.extend_from_slice(&src.data[..w * h]);
        return;
    }
    let ResampleScratch {
        columns,
        lines,
        rows,
        acc,
    } = scratch;
    columns.build(src.width, w, ratio);
    lines.build(src.height, h, ratio);
    rows.clear();
    rows.resize(src.height * w, 0.0);
    for (line, row) in src.data.chunks_exact(src.width).zip(rows.chunks_exact_mut(w)) {
        for (r, &(a, b, divisor)) in row.iter_mut().zip(&columns.spans) {
            let mut sum = 0.0f32;
            for &(i, weight) in &columns.taps[a..b] {
                sum += weight * f32::from(line[i]);
            }
            *r = sum / divisor;
        }
    }
    out.data.resize(w * h, 0);
    for (dst, &(a, b, divisor)) in out.data.chunks_exact_mut(w).zip(&lines.spans) {
        acc.clear();
        acc.resize(w, 0.0);
        for &(i, weight) in &lines.taps[a..b] {
            for (s, &r) in acc.iter_mut().zip(&rows[i * w..(i + 1) * w]) {
                *s += weight * r;
            }
        }
        for (d, &s) in dst.iter_mut().zip(acc.iter()) {
            *d = (s / divisor + 0.5).clamp(0.0, 255.0) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::Stamp;

    fn frame(format: PixelFormat, w: u32, h: u32, f: impl Fn(usize, usize, usize) -> u8) -> ColorFrame {
        let bpp = format.bytes_per_pixel();
        let mut data = Vec::new();
        for y in 0..h as usize {
            for x in 0..w as usize {
                if bpp == 3 {
                    data.extend((0..3).map(|c| f(x, y, c)));
                } else {
                    data.push(f(x, y, format.bayer_channel(x, y).unwrap_or(1)));
                }
            }
        }
        ColorFrame {
            stamp: Stamp::default(),
            width: w,
            height: h,
            format,
            data,
        }
    }

    #[test]
    fn bayer_blocks_average_to_the_rgb_weighting() {
        let colour = |_x: usize, _y: usize, c: usize| [200u8, 100, 20][c];
        let bayer = frame(PixelFormat::BayerRg8, 16, 12, colour);
        let rgb = frame(PixelFormat::Rgb8, 8, 6, colour);
        let mut g = Greyer::default();
        let (mut a, mut b) = (GreyImage::default(), GreyImage::default());
        let pa = g.convert(&bayer, (0, 0, 16, 12), 2.0, 1.0, &mut a).unwrap();
        let pb = g.convert(&rgb, (0, 0, 8, 6), 1.0, 1.0, &mut b).unwrap();
        assert_eq!((a.width, a.height), (8, 6));
        assert_eq!(a, b);
        assert_eq!(a.data[0], 105);
        assert_eq!(pa.frame_px_per_px, 2.0);
        assert_eq!(pb.frame_px_per_px, 1.0);
    }

    #[test]
    fn region_and_scale_map_back_to_the_frame() {
        let f = frame(PixelFormat::Mono8, 40, 30, |x, _, _| (x * 5) as u8);
        let mut g = Greyer::default();
        let mut out = GreyImage::default();
        let p = g.convert(&f, (4, 6, 36, 26), 2.0, 1.0, &mut out).unwrap();
        assert_eq!((out.width, out.height), (16, 10));
        assert_eq!(p.to_frame(1.0, 1.0), (6.0, 8.0));
        // Pixel 0 averages frame columns 4 and 5: 22.5 rounds to 23.
        assert_eq!(out.data[0], 23);
        let up = g.convert(&f, (0, 0, 40, 30), 1.0, 2.0, &mut out).unwrap();
        assert_eq!((out.width, out.height), (80, 60));
        assert_eq!(up.frame_px_per_px, 0.5);
        assert!(g.convert(&f, (10, 10, 10, 20), 1.0, 1.0, &mut out).is_none());
        assert!(g.convert(&f, (0, 0, 40, 30), f64::NAN, 1.0, &mut out).is_none());
        assert!(g.convert(&f, (0, 0, 40, 30), 1e-6, 1.0, &mut out).is_none());
    }
}
