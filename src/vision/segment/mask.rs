//! Steps 1 to 4 of a frame: the strong mask with its pixels counted in tiles, the box of the
//! densest cluster of tiles, the pixels on depth jumps around it, the floor's noise, the
//! largest strong component in the box, and that component grown into the tail
//! (across the gaps noise cuts in a tail). What comes out is the grown mask, left in the
//! segmenter's buffers for the last steps.

use super::{Background, Bounds, FloorPlane, Grid, Scratch, Segmenter};

/// Side of the square tiles in which strong pixels are counted to find the mouse.
const TILE: usize = 16;
/// A tile with at least this many strong pixels may hold the mouse.
const DENSE_TILE_PX: u32 = 8;
/// A reading further than this (mm) from one of its four neighbours' lies on a depth jump,
/// where a time-of-flight camera mixes the two depths ("flying pixels").
const JUMP_MM: u16 = 6;
/// Half the length (pixels) of the lines along which a ridge is looked for.
const RIDGE_HALF_PX: isize = 2;
/// Grown pixels connected among themselves in smaller groups than this are noise along the
/// body's edge, not a tail.
const MIN_BRANCH_PX: usize = 8;

impl Segmenter {
    /// Pass 1: the strong mask over the region, its pixels counted per tile.
    pub(super) fn classify(&mut self, depth: &[u16], g: &Grid) {
        let tiles_x = g.w.div_ceil(TILE);
        let tiles_y = g.h.div_ceil(TILE);
        let s = &mut self.scratch;
        s.tiles.clear();
        s.tiles.resize(tiles_x * tiles_y, 0);
        s.column_counts.clear();
        s.column_counts.resize(g.w, 0);
        for y in 0..g.h {
            let src = &depth[y * g.w..(y + 1) * g.w];
            let at = (g.oy + y) * g.bg_w + g.ox;
            let lo = &self.lo[at..at + g.w];
            let hs = &self.hi_strong[at..at + g.w];
            let strong = &mut s.strong[y * g.w..(y + 1) * g.w];
            for (((o, &d), &l), &h) in strong.iter_mut().zip(src).zip(lo).zip(hs) {
                *o = u8::from((d >= l) & (d <= h));
            }
            // Column counts over a row of tiles (at most 16 each, so bytes do), summed per
            // tile at its last row.
            for (c, &v) in s.column_counts.iter_mut().zip(strong.iter()) {
                *c += v;
            }
            if y % TILE == TILE - 1 || y + 1 == g.h {
                let row = &mut s.tiles[(y / TILE) * tiles_x..(y / TILE + 1) * tiles_x];
                for (t, chunk) in row.iter_mut().zip(s.column_counts.chunks(TILE)) {
                    *t = chunk.iter().map(|&v| u32::from(v)).sum();
                }
                s.column_counts.fill(0);
            }
        }
    }

    /// The box (region pixels) of the 8-connected cluster of dense tiles holding the most
    /// strong pixels, and that box grown by one tile; `None` when no tile is dense. (Strong
    /// pixels of the mouse outside the first box join it when it grows.)
    pub(super) fn densest_tiles(&mut self, g: &Grid) -> Option<(Bounds, Bounds)> {
        let tiles_x = g.w.div_ceil(TILE);
        let tiles_y = g.h.div_ceil(TILE);
        let s = &mut self.scratch;
        s.tile_cluster.clear();
        s.tile_cluster.resize(s.tiles.len(), 0);
        let mut best: Option<(u32, Bounds)> = None;
        let mut next = 0;
        for start in 0..s.tiles.len() {
            if s.tiles[start] < DENSE_TILE_PX || s.tile_cluster[start] != 0 {
                continue;
            }
            next += 1;
            s.tile_cluster[start] = next;
            s.stack.clear();
            s.stack.push(start as u32);
            let mut sum = 0;
            let mut b = Bounds::empty();
            while let Some(t) = s.stack.pop() {
                let t = t as usize;
                let (tx, ty) = (t % tiles_x, t / tiles_x);
                sum += s.tiles[t];
                b.add(tx, ty);
                let mut around = [0; 8];
                let count = neighbours8(t, tiles_x, tiles_y, &mut around);
                for &n in &around[..count] {
                    if s.tiles[n] >= DENSE_TILE_PX && s.tile_cluster[n] == 0 {
                        s.tile_cluster[n] = next;
                        s.stack.push(n as u32);
                    }
                }
            }
            if best.is_none_or(|(s, _)| sum > s) {
                best = Some((sum, b));
            }
        }
        let (_, t) = best?;
        let core = Bounds {
            x0: t.x0 * TILE,
            y0: t.y0 * TILE,
            x1: (t.x1 * TILE).min(g.w),
            y1: (t.y1 * TILE).min(g.h),
        };
        let around = Bounds {
            x0: t.x0.saturating_sub(1) * TILE,
            y0: t.y0.saturating_sub(1) * TILE,
            x1: ((t.x1 + 1) * TILE).min(g.w),
            y1: ((t.y1 + 1) * TILE).min(g.h),
        };
        Some((core, around))
    }

    /// Marks (`scratch.jump`) the pixels inside `search` on a depth jump: their reading may
    /// mix the two sides, so their neighbours off the jump decide them later.
    pub(super) fn mark_jumps(&mut self, depth: &[u16], g: &Grid, search: Bounds) {
        let s = &mut self.scratch;
        if let Some(old) = s.jump.get_mut(s.jump_span.clone()) {
            old.fill(0);
        }
        s.jump_span = search.y0 * g.w..search.y1 * g.w;
        let (x0, x1) = (search.x0.max(1), search.x1.min(g.w.saturating_sub(1)));
        if x0 >= x1 {
            return;
        }
        for y in search.y0.max(1)..search.y1.min(g.h.saturating_sub(1)) {
            let row = y * g.w;
            let up = &depth[row - g.w + x0..row - g.w + x1];
            let down = &depth[row + g.w + x0..row + g.w + x1];
            let left = &depth[row + x0 - 1..row + x1 - 1];
            let right = &depth[row + x0 + 1..row + x1 + 1];
            let centre = &depth[row + x0..row + x1];
            let out = &mut s.jump[row + x0..row + x1];
            let cells = out.iter_mut().zip(centre).zip(left).zip(right).zip(up).zip(down);
            for (((((o, &d), &l), &r), &u), &w) in cells {
                let far = |v: u16| (v != 0) & (v.abs_diff(d) > JUMP_MM);
                *o = u8::from((d != 0) & (far(l) | far(r) | far(u) | far(w)));
            }
        }
    }

    /// The standard deviation (mm) of the floor's readings around the mouse.
    pub(super) fn floor_noise(&self, depth: &[u16], g: &Grid, search: Bounds) -> f32 {
        let FloorPlane { normal, offset_mm } = self.background.floor;
        let (nx, ny, nz, c) = (normal.x as f32, normal.y as f32, normal.z as f32, offset_mm as f32);
        let top = self.config.min_height_mm;
        // Readings below the floor are floor and noise, never the mouse: with the noise
        // symmetric, `sigma^2 = 2 * sum(h^2, h < 0) / floor readings`. (Depths come in whole
        // millimetres, so this, not a median, is what measures a noise of a millimetre or two.)
        // Every other row is enough.
        let (mut sum, mut below, mut level) = (0f64, 0usize, 0usize);
        for y in (search.y0..search.y1).step_by(2) {
            let at = (g.oy + y) * g.bg_w + g.ox;
            let rays = &self.background.rays[at + search.x0..at + search.x1];
            let row = &depth[y * g.w + search.x0..y * g.w + search.x1];
            let (mut row_sum, mut row_below, mut row_level) = (0f32, 0u32, 0u32);
            for (&d, r) in row.iter().zip(rays) {
                let h = (nx * r[0] + ny * r[1] + nz) * f32::from(d) + c;
                let read = d != 0;
                let under = read & (h < -0.5) & (h > -top);
                row_sum += if under { h * h } else { 0.0 };
                row_below += u32::from(under);
                row_level += u32::from(read & (h.abs() <= 0.5));
            }
            sum += f64::from(row_sum);
            below += row_below as usize;
            level += row_level as usize;
        }
        let floor = 2 * below + level;
        if floor < 100 {
            return 0.0;
        }
        (2.0 * sum / floor as f64).sqrt() as f32
    }

    /// The largest 8-connected component of strong pixels inside `search`: its label in
    /// `scratch.labels` (laid out over `search`), or `None` when there is none.
    pub(super) fn largest_component(&mut self, g: &Grid, search: Bounds) -> Option<i32> {
        let s = &mut self.scratch;
        let area = (search.x0, search.y0, search.width(), search.height());
        s.components.label(&s.strong, g.w, area, &mut s.labels);
        s.components.largest().map(|l| l as i32)
    }

    /// Puts the seed component into the mask and grows it into connected pixels at least
    /// `grow_mm` above the floor, or on a ridge at least `ridge_mm` high, then drops small
    /// groups of grown pixels. Returns the mask's box; the mask is left in `scratch.mask`.
    pub(super) fn grow(
        &mut self,
        depth: &[u16],
        g: &Grid,
        search: Bounds,
        seed: i32,
        grow_mm: f32,
        ridge_mm: f32,
    ) -> Bounds {
        let FloorPlane { normal, offset_mm } = self.background.floor;
        let growth = Growth {
            depth,
            g,
            bg: &self.background,
            plane: (normal.x as f32, normal.y as f32, normal.z as f32, offset_mm as f32),
            margin: grow_mm.min(self.config.background_margin_mm),
            grow_mm,
            ridge_mm,
            gap_at_1mm: (crate::vision::tail::MAX_GAP_MM * self.background.intrinsics.fx) as f32,
        };
        let s = &mut self.scratch;
        let mut b = s.seed_mask(g, search, seed);
        s.grow_from_seed(g, &growth);
        s.keep_long_branches(g, &mut b);
        b
    }
}

/// What decides whether a pixel joins the grown mask: its depth against the floor plane
/// (`nx`, `ny`, `nz`, offset) and the background.
struct Growth<'a> {
    depth: &'a [u16],
    g: &'a Grid,
    bg: &'a Background,
    plane: (f32, f32, f32, f32),
    /// How much nearer than the background a pixel must be.
    margin: f32,
    grow_mm: f32,
    ridge_mm: f32,
    /// The widest gap in a tail (`vision::tail::MAX_GAP_MM`) in pixels, times the depth (mm).
    gap_at_1mm: f32,
}

impl Growth<'_> {
    /// The background's index of pixel `i` of the region.
    fn at(&self, i: usize) -> usize {
        let g = self.g;
        (g.oy + i / g.w) * g.bg_w + g.ox + i % g.w
    }

    /// Height above the floor of pixel `i` at depth `d`.
    fn height(&self, i: usize, d: f32) -> f32 {
        let (nx, ny, nz, c) = self.plane;
        self.bg
            .rays
            .get(self.at(i))
            .map_or(f32::NEG_INFINITY, |r| (nx * r[0] + ny * r[1] + nz) * d + c)
    }

    /// Height above the floor, or above the background where that is nearer (a wall).
    fn above(&self, i: usize, d: f32) -> f32 {
        let (nx, ny, nz, c) = self.plane;
        let at = self.at(i);
        let (Some(r), Some(&b)) = (self.bg.rays.get(at), self.bg.depth.get(at)) else {
            return f32::NEG_INFINITY;
        };
        let a = nx * r[0] + ny * r[1] + nz;
        let h = a * d + c;
        if b > 0.0 { h.min(a * (d - b)) } else { h }
    }

    fn bg_at(&self, i: usize) -> f32 {
        self.bg.depth.get(self.at(i)).copied().unwrap_or(0.0)
    }

    /// Whether pixel `i` joins the mask: high enough and nearer than the background, or on
    /// a ridge.
    fn accepts(&self, i: usize, strong: &[u8], jump: &[u8]) -> bool {
        let d = self.depth[i];
        if d == 0 {
            return false;
        }
        let d = f32::from(d);
        let h = self.height(i, d);
        let b = self.bg_at(i);
        if h >= self.grow_mm && (b <= 0.0 || d <= b - self.margin) {
            return true;
        }
        if !self.ridge_mm.is_finite() || self.above(i, d) < 0.0 {
            return false;
        }
        self.ridge_height(i, strong, jump) >= self.ridge_mm
    }

    /// A tail cut by noise: the first strong pixel beyond the refused pixel `n` on the line
    /// from the mask's pixel `i` through it, within the widest gap of a tail, when it is not
    /// in the mask yet and would join it.
    fn across_gap(&self, i: usize, n: usize, strong: &[u8], jump: &[u8], mask: &[u8]) -> Option<usize> {
        let (g, d) = (self.g, self.depth[i]);
        if d == 0 {
            return None;
        }
        let reach = (self.gap_at_1mm / f32::from(d)).floor() as isize + 1;
        let (x, y) = ((i % g.w) as isize, (i / g.w) as isize);
        let (dx, dy) = ((n % g.w) as isize - x, (n / g.w) as isize - y);
        for k in 2..=reach {
            let (px, py) = (x + k * dx, y + k * dy);
            if px < 0 || py < 0 || px >= g.w as isize || py >= g.h as isize {
                return None;
            }
            let p = py as usize * g.w + px as usize;
            if matches!(mask[p], 1..=3) {
                return None;
            }
            if strong[p] != 0 && jump[p] == 0 && self.accepts(p, strong, jump) {
                return Some(p);
            }
        }
        None
    }

    /// A ridge: along some direction, the median height of the five pixels centred at `i`
    /// (without the body's strong pixels) is high enough; the highest such median.
    fn ridge_height(&self, i: usize, strong: &[u8], jump: &[u8]) -> f32 {
        let (g, depth) = (self.g, self.depth);
        let (x, y) = ((i % g.w) as isize, (i / g.w) as isize);
        let mut best = f32::NEG_INFINITY;
        for (dx, dy) in [(1isize, 0isize), (0, 1), (1, 1), (1, -1)] {
            let mut v = [0f32; 11];
            let mut n = 0;
            for k in -RIDGE_HALF_PX..=RIDGE_HALF_PX {
                let (px, py) = (x + k * dx, y + k * dy);
                if px < 0 || py < 0 || px >= g.w as isize || py >= g.h as isize {
                    continue;
                }
                let j = py as usize * g.w + px as usize;
                if depth[j] == 0 || strong[j] != 0 || jump[j] != 0 {
                    continue;
                }
                v[n] = self.above(j, f32::from(depth[j]));
                n += 1;
            }
            if n as isize > RIDGE_HALF_PX {
                let vs = &mut v[..n];
                vs.sort_by(f32::total_cmp);
                best = best.max(vs[n / 2]);
            }
        }
        best
    }
}

impl Scratch {
    /// Puts the `seed` component (labelled over `search`) into the mask and onto the stack;
    /// returns its box.
    fn seed_mask(&mut self, g: &Grid, search: Bounds, seed: i32) -> Bounds {
        let s = self;
        let sw = search.width();
        let mut b = Bounds::empty();
        s.stack.clear();
        for y in search.y0..search.y1 {
            let labels = &s.labels[(y - search.y0) * sw..(y - search.y0 + 1) * sw];
            for (x, &l) in (search.x0..search.x1).zip(labels) {
                if l == seed {
                    let i = y * g.w + x;
                    s.mask[i] = 1;
                    s.stack.push(i as u32);
                    b.add(x, y);
                }
            }
        }
        b
    }

    /// Grows the mask from the stack into the neighbours `growth` accepts, and across the
    /// gaps of a tail cut by noise to the pieces beyond them, noting them in `grown`. Mask values while growing: 1 seed, 2 grown, 4 tried and refused (cleared at
    /// the end).
    fn grow_from_seed(&mut self, g: &Grid, growth: &Growth<'_>) {
        let s = self;
        s.grown.clear();
        s.refused.clear();
        while let Some(i) = s.stack.pop() {
            let mut around = [0; 8];
            let count = neighbours8(i as usize, g.w, g.h, &mut around);
            for &n in &around[..count] {
                match s.mask[n] {
                    0 if growth.accepts(n, &s.strong, &s.jump) => {
                        s.mask[n] = 2;
                        s.stack.push(n as u32);
                        s.grown.push(n as u32);
                        continue;
                    }
                    0 => {
                        s.mask[n] = 4;
                        s.refused.push(n as u32);
                    }
                    4 => {}
                    _ => continue,
                }
                // Refused: a piece of a tail cut by noise may lie beyond it.
                if let Some(p) = growth.across_gap(i as usize, n, &s.strong, &s.jump, &s.mask) {
                    s.mask[p] = 2;
                    s.stack.push(p as u32);
                    s.grown.push(p as u32);
                }
            }
        }
        for &i in &s.refused {
            s.mask[i as usize] = 0;
        }
    }

    /// Grown pixels form branches (8-connected among themselves); the small ones are noise
    /// along the body's edge, dropped, the long ones the tail, kept and added to the box `b`.
    fn keep_long_branches(&mut self, g: &Grid, b: &mut Bounds) {
        let s = self;
        for k in 0..s.grown.len() {
            let start = s.grown[k] as usize;
            if s.mask[start] != 2 {
                continue;
            }
            s.mask[start] = 3;
            s.branch.clear();
            s.branch.push(start as u32);
            let mut next = 0;
            while let Some(&i) = s.branch.get(next) {
                next += 1;
                let mut around = [0; 8];
                let count = neighbours8(i as usize, g.w, g.h, &mut around);
                for &n in &around[..count] {
                    if s.mask[n] == 2 {
                        s.mask[n] = 3;
                        s.branch.push(n as u32);
                    }
                }
            }
            let keep = s.branch.len() >= MIN_BRANCH_PX;
            for &i in &s.branch {
                let i = i as usize;
                s.mask[i] = u8::from(keep);
                if keep {
                    b.add(i % g.w, i / g.w);
                }
            }
        }
    }
}

/// The indices of the neighbours of cell `i` of a row-major `w` x `h` grid: fills `out` and
/// returns how many there are (8 inside, fewer along the edges).
#[inline]
fn neighbours8(i: usize, w: usize, h: usize, out: &mut [usize; 8]) -> usize {
    let (x, y) = (i % w, i / w);
    if x > 0 && y > 0 && x + 1 < w && y + 1 < h {
        *out = [i - w - 1, i - w, i - w + 1, i - 1, i + 1, i + w - 1, i + w, i + w + 1];
        return 8;
    }
    let mut n = 0;
    for (dx, dy) in [
        (-1isize, -1isize),
        (0, -1),
        (1, -1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (0, 1),
        (1, 1),
    ] {
        if let (Some(nx), Some(ny)) = (x.checked_add_signed(dx), y.checked_add_signed(dy))
            && nx < w
            && ny < h
        {
            out[n] = ny * w + nx;
            n += 1;
        }
    }
    n
}
