//! Integral images of an 8-bit grey image: the sum and the sum of squares of the pixels above
//! and to the left of each corner, so that any upright rectangle's sum costs four reads.
//!
//! The layout is OpenCV's: `(width + 1) x (height + 1)` corners, the first row and column zero.
//! Sums are 32-bit with wrap-around, as OpenCV keeps them: a rectangle's sum is exact as long
//! as it fits (any window of a cascade does; a whole frame's sum of squares may wrap).

/// Sum and squared-sum integral images, reusable across images of any size.
#[derive(Clone, Debug, Default)]
pub struct Integral {
    /// Corners per row: the image's width plus one, or more when asked
    /// ([`Self::compute_strided`]; the corners past the image's are never read).
    pub stride: usize,
    /// Corner rows: the image's height plus one.
    pub rows: usize,
    /// `sum[y * stride + x]` = sum of pixels `[0, x) x [0, y)`.
    pub sum: Vec<i32>,
    /// The same for squared pixels.
    pub sqsum: Vec<u32>,
}

impl Integral {
    /// Computes the integral images of `grey` (`width * height` bytes, row-major), reusing
    /// the buffers.
    ///
    /// # Panics
    /// When `grey` holds fewer than `width * height` bytes.
    pub fn compute(&mut self, grey: &[u8], width: usize, height: usize) {
        self.compute_strided(grey, width, height, width + 1);
    }

    /// [`Self::compute`] with `stride` corners per row (at least `width + 1`), so that images
    /// of different widths can share one layout.
    ///
    /// # Panics
    /// When `grey` holds fewer than `width * height` bytes or `stride` is not above `width`.
    pub fn compute_strided(&mut self, grey: &[u8], width: usize, height: usize, stride: usize) {
        assert!(grey.len() >= width * height, "grey image smaller than its size");
        assert!(stride > width, "a stride of {stride} corners for an image {width} wide");
        self.stride = stride;
        self.rows = height + 1;
        let n = self.stride * self.rows;
        // Only the first row and column must start at zero: the rest of each row up to the
        // image's width is written below, and the corners past it are never read (a wide
        // stride must not cost a wide clear).
        self.sum.resize(n, 0);
        self.sqsum.resize(n, 0);
        self.sum[..stride].fill(0);
        self.sqsum[..stride].fill(0);
        for y in 1..self.rows {
            self.sum[y * stride] = 0;
            self.sqsum[y * stride] = 0;
        }
        for y in 0..height {
            let row = &grey[y * width..(y + 1) * width];
            let (above, below) = self.sum.split_at_mut((y + 1) * self.stride);
            let above = &above[y * self.stride..];
            let below = &mut below[..self.stride];
            let (sq_above, sq_below) = self.sqsum.split_at_mut((y + 1) * self.stride);
            let sq_above = &sq_above[y * self.stride..];
            let sq_below = &mut sq_below[..self.stride];
            let mut run = 0i32;
            let mut sq_run = 0u32;
            for (x, &p) in row.iter().enumerate() {
                run = run.wrapping_add(i32::from(p));
                sq_run = sq_run.wrapping_add(u32::from(p) * u32::from(p));
                below[x + 1] = above[x + 1].wrapping_add(run);
                sq_below[x + 1] = sq_above[x + 1].wrapping_add(sq_run);
            }
        }
    }

    /// The sum of the pixels of the rectangle `(x, y, w, h)`.
    #[inline]
    pub fn rect_sum(&self, x: usize, y: usize, w: usize, h: usize) -> i32 {
        let s = self.stride;
        let a = y * s + x;
        let b = (y + h) * s + x;
        self.sum[a]
            .wrapping_sub(self.sum[a + w])
            .wrapping_sub(self.sum[b])
            .wrapping_add(self.sum[b + w])
    }

    /// The sum of the squared pixels of the rectangle `(x, y, w, h)`.
    #[inline]
    pub fn rect_sqsum(&self, x: usize, y: usize, w: usize, h: usize) -> u32 {
        let s = self.stride;
        let a = y * s + x;
        let b = (y + h) * s + x;
        self.sqsum[a]
            .wrapping_sub(self.sqsum[a + w])
            .wrapping_sub(self.sqsum[b])
            .wrapping_add(self.sqsum[b + w])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_sums_match_brute_force() {
        let (w, h) = (13, 9);
        let grey: Vec<u8> = (0..w * h).map(|i| ((i * 37 + 11) % 256) as u8).collect();
        // A reused buffer, filled before in another layout: its first column and row must be
        // cleared, not only found zero.
        let mut wide = Integral::default();
        wide.compute(&[255; 70 * 12], 70, 12);
        wide.compute_strided(&grey, w, h, 64);
        assert_eq!(wide.stride, 64);
        let mut ii = Integral::default();
        ii.compute(&grey, w, h);
        for ii in [ii, wide] {
            for y in 0..h {
                for x in 0..w {
                    for rh in 1..=h - y {
                        for rw in 1..=w - x {
                            let mut s = 0i64;
                            let mut sq = 0i64;
                            for yy in y..y + rh {
                                for xx in x..x + rw {
                                    let p = i64::from(grey[yy * w + xx]);
                                    s += p;
                                    sq += p * p;
                                }
                            }
                            assert_eq!(i64::from(ii.rect_sum(x, y, rw, rh)), s);
                            assert_eq!(i64::from(ii.rect_sqsum(x, y, rw, rh)), sq);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn buffers_are_reused_across_sizes() {
        let mut ii = Integral::default();
        ii.compute(&[255; 64], 8, 8);
        ii.compute(&[1, 2, 3, 4], 2, 2);
        assert_eq!(ii.rect_sum(0, 0, 2, 2), 10);
        assert_eq!(ii.rect_sqsum(0, 0, 2, 2), 30);
    }
}
