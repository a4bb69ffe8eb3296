//! The two image operations the segmenter once asked OpenCV for, done here on its own
//! buffers: the 8-connected components of a mask (with their areas) and the opening of a mask
//! by a square. Both give what OpenCV's `connectedComponentsWithStats` and `morphologyEx`
//! (`MORPH_OPEN`, a rectangle, the default border) give: the same pixels, and the components
//! in the order OpenCV numbers them (see [`Components::label`]).

/// The 8-connected components of a mask, labelled into a buffer reused from frame to frame.
#[derive(Debug, Default)]
pub(super) struct Components {
    /// Union-find over provisional labels (index 0 is the background).
    parent: Vec<u32>,
    /// Per final label (index 0 unused): its pixels.
    area: Vec<u32>,
    /// Provisional label to final label.
    final_of: Vec<u32>,
}

impl Components {
    fn find(&mut self, mut a: u32) -> u32 {
        while self.parent[a as usize] != a {
            let up = self.parent[self.parent[a as usize] as usize];
            self.parent[a as usize] = up;
            a = up;
        }
        a
    }

    fn union(&mut self, a: u32, b: u32) -> u32 {
        let (ra, rb) = (self.find(a), self.find(b));
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        self.parent[hi as usize] = lo;
        lo
    }

    /// Labels the pixels of the `width` x `height` box at `(x0, y0)` of `mask` (rows `stride`
    /// wide) that are not 0: `labels` (laid out over the box) gets each pixel's component,
    /// 1.. in the order OpenCV numbers them (by the first 2x2 block of the box a component
    /// touches, blocks taken row pair by row pair), 0 for the background. Returns how many
    /// components there are; [`Self::area`] gives their sizes.
    pub(super) fn label(
        &mut self,
        mask: &[u8],
        stride: usize,
        (x0, y0, width, height): (usize, usize, usize, usize),
        labels: &mut [i32],
    ) -> usize {
        self.parent.clear();
        self.parent.push(0);
        let labels = &mut labels[..width * height];
        for y in 0..height {
            let row = &mask[(y0 + y) * stride + x0..(y0 + y) * stride + x0 + width];
            for x in 0..width {
                if row[x] == 0 {
                    labels[y * width + x] = 0;
                    continue;
                }
                let mut label = 0u32;
                let mut see = |l: i32, this: &mut Self| {
                    if l > 0 {
                        label = if label == 0 {
                            l as u32
                        } else {
                            this.union(label, l as u32)
                        };
                    }
                };
                if x > 0 {
                    see(labels[y * width + x - 1], self);
                }
                if y > 0 {
                    let up = (y - 1) * width;
                    if x > 0 {
                        see(labels[up + x - 1], self);
                    }
                    see(labels[up + x], self);
                    if x + 1 < width {
                        see(labels[up + x + 1], self);
                    }
                }
                if label == 0 {
                    label = self.parent.len() as u32;
                    self.parent.push(label);
                }
                labels[y * width + x] = label as i32;
            }
        }
        // Each set's first block, then final labels in the order of those blocks.
        let provisional = self.parent.len();
        let blocks_across = width.div_ceil(2) as u64;
        let mut first = vec![u64::MAX; provisional];
        for y in 0..height {
            for x in 0..width {
                let l = labels[y * width + x];
                if l > 0 {
                    let root = self.find(l as u32) as usize;
                    let block = (y / 2) as u64 * blocks_across + (x / 2) as u64;
                    first[root] = first[root].min(block);
                }
            }
        }
        let mut roots: Vec<u32> = (1..provisional as u32).filter(|&l| self.find(l) == l).collect();
        roots.sort_by_key(|&r| first[r as usize]);
        self.final_of.clear();
        self.final_of.resize(provisional, 0);
        self.area.clear();
        self.area.resize(roots.len() + 1, 0);
        for (k, &r) in roots.iter().enumerate() {
            self.final_of[r as usize] = k as u32 + 1;
        }
        for l in labels.iter_mut() {
            if *l > 0 {
                let root = self.find(*l as u32);
                let f = self.final_of[root as usize];
                *l = f as i32;
                self.area[f as usize] += 1;
            }
        }
        roots.len()
    }

    /// The pixels of component `label` (1..), as the last [`Self::label`] found them.
    #[cfg(test)]
    pub(super) fn area(&self, label: usize) -> u32 {
        self.area.get(label).copied().unwrap_or(0)
    }

    /// The largest component of the last [`Self::label`], the first in OpenCV's order among
    /// equals; `None` when there was none.
    pub(super) fn largest(&self) -> Option<usize> {
        let mut best = None;
        let mut best_area = 0;
        for (label, &area) in self.area.iter().enumerate().skip(1) {
            if area > best_area {
                best_area = area;
                best = Some(label);
            }
        }
        best
    }
}

/// `src` (`width` x `height`, row-major) opened by a square of side `2 radius + 1` into `dst`:
/// the minimum over the square, then the maximum over it, pixels outside the image counting
/// for neither (OpenCV's default border for morphology). Separable: a pass along the rows and
/// one along the columns for each, through `tmp`.
pub(super) fn open_square(src: &[u8], dst: &mut [u8], width: usize, height: usize, radius: usize, tmp: &mut Vec<u8>) {
    let n = width * height;
    tmp.clear();
    tmp.resize(n, 0);
    let (src, dst) = (&src[..n], &mut dst[..n]);
    // Erosion: rows into tmp, columns into dst; dilation: rows into tmp, columns into dst.
    along_rows(src, tmp, width, radius, u8::min);
    along_columns(tmp, dst, width, height, radius, u8::min);
    along_rows(dst, tmp, width, radius, u8::max);
    along_columns(tmp, dst, width, height, radius, u8::max);
}

fn along_rows(src: &[u8], dst: &mut [u8], width: usize, radius: usize, pick: fn(u8, u8) -> u8) {
    for (row_in, row_out) in src.chunks_exact(width).zip(dst.chunks_exact_mut(width)) {
        for (x, out) in row_out.iter_mut().enumerate() {
            let window = &row_in[x.saturating_sub(radius)..(x + radius + 1).min(width)];
            *out = window.iter().copied().reduce(pick).unwrap_or(0);
        }
    }
}

fn along_columns(src: &[u8], dst: &mut [u8], width: usize, height: usize, radius: usize, pick: fn(u8, u8) -> u8) {
    for y in 0..height {
        let (from, to) = (y.saturating_sub(radius), (y + radius + 1).min(height));
        let out = &mut dst[y * width..(y + 1) * width];
        out.copy_from_slice(&src[from * width..(from + 1) * width]);
        for yy in from + 1..to {
            for (o, &v) in out.iter_mut().zip(&src[yy * width..(yy + 1) * width]) {
                *o = pick(*o, v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The components by a flood fill, for comparison: each pixel's component as the set of
    /// pixels it is joined to.
    fn flood(mask: &[u8], w: usize, h: usize) -> Vec<usize> {
        let mut comp = vec![usize::MAX; w * h];
        let mut next = 0;
        for start in 0..w * h {
            if mask[start] == 0 || comp[start] != usize::MAX {
                continue;
            }
            let mut stack = vec![start];
            comp[start] = next;
            while let Some(p) = stack.pop() {
                let (x, y) = ((p % w) as i64, (p / w) as i64);
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                            continue;
                        }
                        let q = ny as usize * w + nx as usize;
                        if mask[q] != 0 && comp[q] == usize::MAX {
                            comp[q] = next;
                            stack.push(q);
                        }
                    }
                }
            }
            next += 1;
        }
        comp
    }

    #[test]
    fn components_are_the_flood_fills_and_their_areas_add_up() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut c = Components::default();
        for _ in 0..50 {
            let (w, h) = (rng.gen_range(1..40), rng.gen_range(1..40));
            let share = rng.gen_range(0.1..0.7);
            let mask: Vec<u8> = (0..w * h).map(|_| u8::from(rng.gen_bool(share))).collect();
            let mut labels = vec![-1; w * h];
            let count = c.label(&mask, w, (0, 0, w, h), &mut labels);
            let comp = flood(&mask, w, h);
            for p in 0..w * h {
                for q in 0..w * h {
                    if mask[p] != 0 && mask[q] != 0 {
                        assert_eq!(comp[p] == comp[q], labels[p] == labels[q]);
                    }
                }
                assert_eq!(mask[p] == 0, labels[p] == 0);
            }
            let total: u32 = (1..=count).map(|l| c.area(l)).sum();
            assert_eq!(total as usize, mask.iter().filter(|&&m| m != 0).count());
        }
    }

    #[test]
    fn components_are_numbered_by_their_first_block_not_their_first_pixel() {
        // B's first pixel (1, 1) comes after A's (4, 0) in pixel order, but B's block (0, 0)
        // comes before A's (2, 0), and OpenCV numbers B first.
        let (w, h) = (6, 4);
        let mut mask = vec![0u8; w * h];
        mask[4] = 1; // A at (4, 0)
        mask[w + 1] = 1; // B at (1, 1)
        let mut labels = vec![0; w * h];
        let mut c = Components::default();
        assert_eq!(c.label(&mask, w, (0, 0, w, h), &mut labels), 2);
        assert_eq!((labels[w + 1], labels[4]), (1, 2));
        // Equal areas: the first in that order is the largest.
        assert_eq!(c.largest(), Some(1));
    }

    #[test]
    fn a_box_inside_a_wider_mask_is_labelled_alone() {
        let (w, h) = (8, 5);
        let mut mask = vec![1u8; w * h];
        mask[2 * w + 3] = 0;
        let mut labels = vec![0; 4 * 3];
        let mut c = Components::default();
        assert_eq!(c.label(&mask, w, (2, 1, 4, 3), &mut labels), 1);
        assert_eq!(c.area(1), 11);
        assert_eq!(labels[4 + 1], 0);
    }

    /// The opening by its definition: the minimum over each square, then the maximum, over
    /// the pixels inside the image.
    fn open_by_definition(src: &[u8], w: usize, h: usize, r: usize) -> Vec<u8> {
        let over = |img: &[u8], x: usize, y: usize, pick: fn(u8, u8) -> u8| {
            let mut v: Option<u8> = None;
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    let p = img[yy * w + xx];
                    v = Some(v.map_or(p, |v| pick(v, p)));
                }
            }
            v.unwrap_or(0)
        };
        let eroded: Vec<u8> = (0..w * h).map(|p| over(src, p % w, p / w, u8::min)).collect();
        (0..w * h).map(|p| over(&eroded, p % w, p / w, u8::max)).collect()
    }

    #[test]
    fn the_separable_opening_is_the_opening() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut tmp = Vec::new();
        for _ in 0..40 {
            let (w, h, r) = (rng.gen_range(1..30), rng.gen_range(1..30), rng.gen_range(0..5));
            let src: Vec<u8> = (0..w * h).map(|_| if rng.gen_bool(0.7) { 1 } else { 0 }).collect();
            let mut dst = vec![9u8; w * h];
            open_square(&src, &mut dst, w, h, r, &mut tmp);
            assert_eq!(dst, open_by_definition(&src, w, h, r), "{w}x{h} r {r}");
        }
    }
}
