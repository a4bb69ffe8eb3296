//! The body forest's traversal in AVX2: eight pixels go down a tree together, their nodes and
//! probed depths fetched with gather instructions; mean-shift's kernel sums over its votes
//! eight at a time in 256-bit registers ([`kernel_lanes`]); and the paw network's
//! convolutions ([`conv`]), the same loops compiled for AVX2, eight columns a register. The
//! one module of mousepose outside the camera crates with `unsafe`, for the intrinsics and
//! the calls into code compiled for AVX2.
//!
//! [`Kernel::detect`] picks AVX2 at run time when the processor has it; every other processor
//! takes the portable path ([`PackedTree::leaf_indices`]). Both give the same leaf for every
//! pixel, bit for bit: the arithmetic is the portable path's, operation by operation (a
//! multiply then an add, never fused; the same truncation to a pixel index; the same
//! comparison), which the tests check on random trees and images.
//!
//! The AVX2 code reads nodes, pixels and depths without bounds checks, so what it reads is
//! vouched for by types rather than by callers, and [`leaf_indices`] is sound whatever it is
//! given: a [`Kernel::Avx2`] exists only where [`Kernel::detect`] found AVX2, a [`PackedTree`]
//! only once its child indices were checked ([`super::Tree::check`]),
//! [`PixelLanes`] keep their arrays one length, and an image whose depth array does not cover
//! its region takes the portable path. The convolutions index their slices checked.
#![allow(unsafe_code)]

use super::PackedTree;
use super::depth::{DepthFeature, DepthImage};

/// Which code runs (the traversal, the kernel sums, the convolutions). Only [`Kernel::detect`] makes [`Kernel::Avx2`] (its
/// [`Avx2Detected`] cannot be built anywhere else), so holding one means the processor was
/// found to have AVX2.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// Plain Rust, any processor.
    Portable,
    /// AVX2 gathers, eight pixels at a time (x86-64 processors that have it).
    Avx2(Avx2Detected),
}

/// Proof that [`Kernel::detect`] found AVX2 on this processor: the field is private, so
/// nothing outside this module makes one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Avx2Detected(());

impl Kernel {
    /// The fastest kernel this processor runs.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") {
            return Kernel::Avx2(Avx2Detected(()));
        }
        Kernel::Portable
    }
}

/// `Portable` or `Avx2`, the variant's name alone (benchmarks print it).
impl std::fmt::Debug for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Kernel::Portable => "Portable",
            Kernel::Avx2(_) => "Avx2",
        })
    }
}

/// Pixels to route, one array per coordinate (what vector loads want). The four arrays
/// always have the same length: they are private and [`Self::push`] grows them together,
/// which the AVX2 loads rely on.
#[derive(Clone, Debug, Default)]
pub struct PixelLanes {
    x: Vec<f32>,
    y: Vec<f32>,
    depth: Vec<f32>,
    /// `1 / depth`, which scales every probe offset.
    inverse: Vec<f32>,
}

impl PixelLanes {
    pub fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.depth.clear();
        self.inverse.clear();
    }

    pub fn push(&mut self, x: f32, y: f32, depth: f32) {
        self.x.push(x);
        self.y.push(y);
        self.depth.push(depth);
        self.inverse.push(1.0 / depth);
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// The value of feature `u` for pixel `s`: the portable path's arithmetic.
    #[inline]
    pub fn feature(&self, image: &DepthImage, s: usize, u: &DepthFeature) -> f32 {
        image.feature_scaled(self.x[s], self.y[s], self.depth[s], self.inverse[s], u)
    }
}

/// The leaf index each pixel of `lanes` reaches in `tree`, into `leaves` (resized to the
/// number of pixels), with `kernel`; the portable path uses `scratch`.
///
/// An image whose depth array is shorter than its region (or whose region has more than
/// `i32::MAX` pixels) takes the portable path whatever `kernel` says, which panics on a probe
/// past the array's end rather than reading past it.
pub fn leaf_indices(
    kernel: Kernel,
    tree: &PackedTree<DepthFeature>,
    image: &DepthImage,
    lanes: &PixelLanes,
    scratch: &mut super::Traversal,
    leaves: &mut Vec<u32>,
) {
    let n = lanes.len();
    leaves.clear();
    match kernel {
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2(_) if !tree.nodes().is_empty() && gatherable(image) => {
            leaves.resize(n, 0);
            let whole = n - n % 8;
            // SAFETY: `Kernel::Avx2` holds an `Avx2Detected`, which only `Kernel::detect` makes
            // after finding AVX2 on this processor. `leaves[..whole]` is no longer than `lanes`,
            // whose four arrays have one length. `gatherable` checked that every pixel of the
            // region has an index in `i32` and inside `image.depth`. `tree` is a `PackedTree`,
            // which `PackedTree::new` only builds with every child index after its node and
            // inside the tree, and it is not empty.
            unsafe { avx2::leaves(tree, image, lanes, &mut leaves[..whole]) };
            for (s, leaf) in leaves.iter_mut().enumerate().skip(whole) {
                *leaf = tree.leaf_index_of(|u| lanes.feature(image, s, u));
            }
        }
        _ => {
            tree.leaf_indices(n, |s, u| lanes.feature(image, s, u), scratch);
            leaves.extend_from_slice(scratch.leaves());
        }
    }
}

/// The mean-shift sums over the votes `x`, `y`, `z` with weights `w` (one length), taken at
/// `at` with the biweight kernel `max(1 - d2 * scale, 0)^2` (`infer`'s `kernel`): per lane `l`
/// of eight, the sums over the votes `8i + l` of `k x`, `k y`, `k z` and `k`, with `k` the
/// vote's weight times the kernel. Only whole groups of eight are summed; the caller adds the
/// rest. Both kernels give the same sums, bit for bit: each lane's multiplies, adds and maximum
/// in the same order, never fused, and lanes summed in the same order.
pub fn kernel_lanes(kernel: Kernel, [x, y, z, w]: [&[f32]; 4], at: [f32; 3], scale: f32) -> [wide::f32x8; 4] {
    let n = x.len().min(y.len()).min(z.len()).min(w.len()) / 8 * 8;
    let groups = x[..n]
        .chunks_exact(8)
        .zip(y[..n].chunks_exact(8))
        .zip(z[..n].chunks_exact(8).zip(w[..n].chunks_exact(8)));
    match kernel {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::Avx2` holds an `Avx2Detected`, which only `Kernel::detect` makes
        // after finding AVX2 (and so AVX) on this processor; every group holds eight floats.
        Kernel::Avx2(_) => unsafe { avx2::kernel_lanes(groups, at, scale) },
        _ => {
            use wide::f32x8;
            let lanes = |s: &[f32]| {
                let mut a = [0.0f32; 8];
                a.copy_from_slice(s);
                f32x8::new(a)
            };
            let (ax, ay, az) = (f32x8::splat(at[0]), f32x8::splat(at[1]), f32x8::splat(at[2]));
            let (one, zero, scale8) = (f32x8::splat(1.0), f32x8::splat(0.0), f32x8::splat(scale));
            let mut sums = [zero; 4];
            for ((x, y), (z, w)) in groups {
                let (x, y, z, w) = (lanes(x), lanes(y), lanes(z), lanes(w));
                let (dx, dy, dz) = (x - ax, y - ay, z - az);
                let t = (one - (dx * dx + dy * dy + dz * dz) * scale8).fast_max(zero);
                let k = w * t * t;
                sums[0] += k * x;
                sums[1] += k * y;
                sums[2] += k * z;
                sums[3] += k;
            }
            sums
        }
    }
}

/// Output channels [`conv`] computes together, their sums held in registers.
pub const CONV_BLOCK: usize = 12;

/// Columns the widest path of [`conv`] computes together: each padded input row holds whole
/// groups of them ([`ConvLayer::padded_width`]).
pub const CONV_LANES: usize = 8;

/// One layer of a small convolutional network, as [`conv`] reads it.
#[derive(Clone, Copy, Debug)]
pub struct ConvLayer<'a> {
    pub inputs: usize,
    pub outputs: usize,
    /// The kernel's side (1 or 3) and the spacing of its taps.
    pub kernel: usize,
    pub dilation: usize,
    /// `[block of outputs][input][ky][kx][output in the block]`, each block [`CONV_BLOCK`]
    /// outputs wide (the last one filled out with zeros).
    pub weights: &'a [f32],
    /// One per output.
    pub bias: &'a [f32],
    /// Zero what is below zero.
    pub relu: bool,
}

impl ConvLayer<'_> {
    /// How far the kernel reaches from its centre (pixels).
    pub fn reach(&self) -> usize {
        self.kernel / 2 * self.dilation
    }

    /// The row length of the input's padded copy for an output `w` columns wide: the border
    /// of zeros on both sides and whole groups of [`CONV_LANES`] columns.
    pub fn padded_width(&self, w: usize) -> usize {
        w.div_ceil(CONV_LANES) * CONV_LANES + 2 * self.reach()
    }
}

/// `out` (`outputs` planes of `w` x `h`) = `layer` on `padded`, its `inputs` planes of `w` x
/// `h` each copied into a plane of `h + 2 reach` rows [`ConvLayer::padded_width`] long, from
/// row and column [`ConvLayer::reach`] on, zeros all round. Each output is its bias plus its weighted inputs added
/// input by input, tap by tap, never fused: AVX2 and the portable path give the same
/// planes, bit for bit (eight columns at a time, or four).
///
/// # Panics
/// `padded` or `out` is shorter than that, or `weights` or `bias` short of `layer`'s sizes.
pub fn conv(kernel: Kernel, layer: &ConvLayer<'_>, padded: &[f32], w: usize, h: usize, out: &mut [f32]) {
    match kernel {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Kernel::Avx2` holds an `Avx2Detected`, which only `Kernel::detect` makes
        // after finding AVX2 on this processor; the loops index their slices checked.
        Kernel::Avx2(_) => unsafe { avx2::conv(layer, padded, w, h, out) },
        _ => conv_columns::<4>(layer, padded, w, h, out),
    }
}

/// [`conv`], `LANES` columns at a time: inlined into each path so that each is compiled for
/// its own instructions.
#[inline(always)]
fn conv_columns<const LANES: usize>(layer: &ConvLayer<'_>, padded: &[f32], w: usize, h: usize, out: &mut [f32]) {
    let (k, d) = (layer.kernel, layer.dilation);
    let pw = layer.padded_width(w);
    let pplane = pw * (h + 2 * layer.reach());
    let plane = w * h;
    let block_weights = layer.inputs * k * k * CONV_BLOCK;
    for (b, weights) in layer.weights.chunks_exact(block_weights).enumerate() {
        let first = b * CONV_BLOCK;
        let count = layer.outputs.saturating_sub(first).min(CONV_BLOCK);
        for y in 0..h {
            for x in (0..w).step_by(LANES) {
                let mut sums = [[0.0f32; LANES]; CONV_BLOCK];
                for (s, &bias) in sums.iter_mut().zip(&layer.bias[first..first + count]) {
                    *s = [bias; LANES];
                }
                for (source, weights) in padded
                    .chunks_exact(pplane)
                    .take(layer.inputs)
                    .zip(weights.chunks_exact(k * k * CONV_BLOCK))
                {
                    for ky in 0..k {
                        let row = &source[(y + ky * d) * pw + x..];
                        for kx in 0..k {
                            let v: [f32; LANES] = row[kx * d..][..LANES].try_into().unwrap_or([0.0; LANES]);
                            let tap: [f32; CONV_BLOCK] = weights[(ky * k + kx) * CONV_BLOCK..][..CONV_BLOCK]
                                .try_into()
                                .unwrap_or([0.0; CONV_BLOCK]);
                            for (s, weight) in sums.iter_mut().zip(tap) {
                                for (s, v) in s.iter_mut().zip(v) {
                                    *s += weight * v;
                                }
                            }
                        }
                    }
                }
                let columns = (w - x).min(LANES);
                for (j, s) in sums[..count].iter().enumerate() {
                    let dst = &mut out[(first + j) * plane + y * w + x..][..columns];
                    for (o, &v) in dst.iter_mut().zip(s) {
                        *o = if layer.relu { v.max(0.0) } else { v };
                    }
                }
            }
        }
    }
}

/// Whether the AVX2 gathers can read `image`: the region's pixel count fits in an `i32` (the
/// gathers' indices) and `image.depth` holds them all.
#[cfg(target_arch = "x86_64")]
fn gatherable(image: &DepthImage) -> bool {
    let pixels = u64::from(image.region.width) * u64::from(image.region.height);
    pixels <= i32::MAX as u64 && pixels <= image.depth.len() as u64
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::super::depth::{BACKGROUND_MM, DepthFeature, DepthImage};
    use super::super::packed::{PACKED_LEAF, PackedNode, PackedTree};
    use super::PixelLanes;
    use std::arch::x86_64::*;

    // A node is four 32-bit words: the feature's two offsets, the threshold, then the child
    // or flagged leaf index (`PackedNode` is `repr(C)`).
    const _: () = assert!(size_of::<PackedNode<DepthFeature>>() == 16);

    /// Groups of eight pixels that go down the tree side by side: their gathers are
    /// independent, so the processor overlaps their memory loads.
    const GROUPS: usize = 4;

    /// What every step reads: the tree, the image and constants.
    struct Walk<'a> {
        nodes: *const f32,
        depth: &'a [f32],
        corner: (__m256, __m256),
        size: (__m256i, __m256i),
        background: __m256,
        leaf_bit: __m256i,
    }

    /// Eight pixels on their way: their coordinates, their nodes (a lane stays on its leaf
    /// once there) and, once there, their flagged leaf indices.
    #[derive(Clone, Copy)]
    struct Group {
        x: __m256,
        y: __m256,
        depth: __m256,
        inverse: __m256,
        at: __m256i,
        result: __m256i,
    }

    /// [`super::conv`] eight columns at a time, compiled for AVX2.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn conv(layer: &super::ConvLayer<'_>, padded: &[f32], w: usize, h: usize, out: &mut [f32]) {
        super::conv_columns::<{ super::CONV_LANES }>(layer, padded, w, h, out);
    }

    /// [`super::kernel_lanes`] over `groups` of eight votes each (x, y, z, weight), in AVX:
    /// the portable path's operations lane by lane.
    ///
    /// # Safety
    /// The processor must have AVX; every slice of `groups` must hold eight floats.
    #[target_feature(enable = "avx")]
    pub(super) unsafe fn kernel_lanes<'a>(
        groups: impl Iterator<Item = ((&'a [f32], &'a [f32]), (&'a [f32], &'a [f32]))>,
        at: [f32; 3],
        scale: f32,
    ) -> [wide::f32x8; 4] {
        let (ax, ay, az) = (_mm256_set1_ps(at[0]), _mm256_set1_ps(at[1]), _mm256_set1_ps(at[2]));
        let (one, zero, scale8) = (_mm256_set1_ps(1.0), _mm256_setzero_ps(), _mm256_set1_ps(scale));
        let (mut sx, mut sy, mut sz, mut sw) = (zero, zero, zero, zero);
        for ((x, y), (z, w)) in groups {
            // SAFETY: each slice holds eight floats (the caller's promise), which an unaligned
            // load reads.
            let (x, y, z, w) = unsafe {
                (
                    _mm256_loadu_ps(x.as_ptr()),
                    _mm256_loadu_ps(y.as_ptr()),
                    _mm256_loadu_ps(z.as_ptr()),
                    _mm256_loadu_ps(w.as_ptr()),
                )
            };
            let (dx, dy, dz) = (_mm256_sub_ps(x, ax), _mm256_sub_ps(y, ay), _mm256_sub_ps(z, az));
            let d2 = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                _mm256_mul_ps(dz, dz),
            );
            let t = _mm256_max_ps(_mm256_sub_ps(one, _mm256_mul_ps(d2, scale8)), zero);
            let k = _mm256_mul_ps(_mm256_mul_ps(w, t), t);
            sx = _mm256_add_ps(sx, _mm256_mul_ps(k, x));
            sy = _mm256_add_ps(sy, _mm256_mul_ps(k, y));
            sz = _mm256_add_ps(sz, _mm256_mul_ps(k, z));
            sw = _mm256_add_ps(sw, k);
        }
        [sx, sy, sz, sw].map(|v| {
            let mut lanes = [0.0f32; 8];
            // SAFETY: `lanes` holds eight floats, which an unaligned store writes.
            unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), v) };
            wide::f32x8::new(lanes)
        })
    }

    /// Routes the first `out.len()` pixels (a multiple of 8) down `tree`.
    ///
    /// # Safety
    /// The processor must have AVX2; `lanes` must hold at least `out.len()` pixels; the
    /// region of `image` must have at most `i32::MAX` pixels and `image.depth` at least that
    /// many; `tree` must not be empty (its child indices point after their node and inside
    /// it, as in every `PackedTree`).
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn leaves(
        tree: &PackedTree<DepthFeature>,
        image: &DepthImage,
        lanes: &PixelLanes,
        out: &mut [u32],
    ) {
        let region = image.region;
        let walk = Walk {
            nodes: tree.nodes().as_ptr().cast::<f32>(),
            depth: &image.depth,
            corner: (_mm256_set1_ps(region.x0 as f32), _mm256_set1_ps(region.y0 as f32)),
            size: (
                _mm256_set1_epi32(region.width as i32),
                _mm256_set1_epi32(region.height as i32),
            ),
            background: _mm256_set1_ps(BACKGROUND_MM),
            leaf_bit: _mm256_set1_epi32(PACKED_LEAF as i32),
        };
        for (b, block) in out.chunks_mut(8 * GROUPS).enumerate() {
            let count = block.len() / 8;
            let load = |k: usize, v: &[f32]| {
                let o = (b * GROUPS + k.min(count - 1)) * 8;
                // SAFETY: `o + 8 <= out.len() <= v.len()` (a missing group repeats the last).
                unsafe { _mm256_loadu_ps(v.as_ptr().add(o)) }
            };
            let mut groups: [Group; GROUPS] = std::array::from_fn(|k| Group {
                x: load(k, &lanes.x),
                y: load(k, &lanes.y),
                depth: load(k, &lanes.depth),
                inverse: load(k, &lanes.inverse),
                at: _mm256_setzero_si256(),
                result: _mm256_setzero_si256(),
            });
            loop {
                let mut moving = false;
                for g in &mut groups {
                    // SAFETY: AVX2 is the caller's promise. Every lane starts at the root (the
                    // tree is not empty) and `step` only moves a lane to a child index read from
                    // a split node, which a `PackedTree` keeps inside the tree.
                    moving |= unsafe { step(&walk, g) };
                }
                if !moving {
                    break;
                }
            }
            for (g, chunk) in groups.iter().zip(block.chunks_exact_mut(8)) {
                let leaf = _mm256_andnot_si256(walk.leaf_bit, g.result);
                // SAFETY: `chunk` is eight u32s.
                unsafe { _mm256_storeu_si256(chunk.as_mut_ptr().cast(), leaf) };
            }
        }
    }

    /// Moves each lane of `g` not on a leaf one level down; whether any lane moved.
    ///
    /// # Safety
    /// AVX2; every lane's node index is inside the tree (the root, a child index read from a
    /// split node, or a leaf it stays on); the region's pixel count within `i32` and `depth`
    /// at least that long.
    #[inline]
    #[target_feature(enable = "avx2")]
    unsafe fn step(walk: &Walk<'_>, g: &mut Group) -> bool {
        let zero = _mm256_setzero_si256();
        // Each lane's node as one 16-byte load, then transposed: faster than four gathers.
        let mut at = [0u32; 8];
        // SAFETY: `at` is eight u32s.
        unsafe { _mm256_storeu_si256(at.as_mut_ptr().cast(), g.at) };
        // SAFETY: the nodes of `g.at` are inside the tree, so are their four words.
        let node = |k: usize| unsafe { _mm_loadu_ps(walk.nodes.add(at[k] as usize * 4)) };
        let (r0, r1) = (_mm256_set_m128(node(4), node(0)), _mm256_set_m128(node(5), node(1)));
        let (r2, r3) = (_mm256_set_m128(node(6), node(2)), _mm256_set_m128(node(7), node(3)));
        let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
        let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
        let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
        let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
        let threshold = _mm256_shuffle_ps::<0x44>(t1, t3);
        let next = _mm256_castps_si256(_mm256_shuffle_ps::<0xEE>(t1, t3));
        let moving = _mm256_cmpeq_epi32(_mm256_and_si256(next, walk.leaf_bit), zero);
        g.result = _mm256_blendv_epi8(next, g.result, moving);
        if _mm256_movemask_ps(_mm256_castsi256_ps(moving)) == 0 {
            return false;
        }
        // `probe(x + u0 * inv, y + u1 * inv)`, relative to the region's corner: a multiply
        // then an add, as the portable path computes it.
        let rx = _mm256_sub_ps(_mm256_add_ps(g.x, _mm256_mul_ps(u0, g.inverse)), walk.corner.0);
        let ry = _mm256_sub_ps(_mm256_add_ps(g.y, _mm256_mul_ps(u1, g.inverse)), walk.corner.1);
        let nonnegative = _mm256_castps_si256(_mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GE_OQ>(rx, _mm256_setzero_ps()),
            _mm256_cmp_ps::<_CMP_GE_OQ>(ry, _mm256_setzero_ps()),
        ));
        // Truncation as `as u32` does for what is inside; too large a value becomes i32::MIN,
        // outside like the saturated u32 of the portable path.
        let (xi, yi) = (_mm256_cvttps_epi32(rx), _mm256_cvttps_epi32(ry));
        let minus_one = _mm256_set1_epi32(-1);
        let inside = _mm256_and_si256(
            _mm256_and_si256(_mm256_cmpgt_epi32(walk.size.0, xi), _mm256_cmpgt_epi32(xi, minus_one)),
            _mm256_and_si256(_mm256_cmpgt_epi32(walk.size.1, yi), _mm256_cmpgt_epi32(yi, minus_one)),
        );
        let read = _mm256_and_si256(_mm256_and_si256(inside, nonnegative), moving);
        let pixel = _mm256_add_epi32(_mm256_mullo_epi32(yi, walk.size.0), xi);
        // SAFETY: only the lanes of `read` are loaded, whose pixel is inside the region
        // (`0 <= xi < width`, `0 <= yi < height`), so `yi * width + xi` is below
        // `width * height`, which the caller keeps within `i32` (no overflow) and within
        // `depth`'s length.
        let probed = unsafe {
            _mm256_mask_i32gather_ps::<4>(walk.background, walk.depth.as_ptr(), pixel, _mm256_castsi256_ps(read))
        };
        let value = _mm256_sub_ps(probed, g.depth);
        // The right child (left + 1) when value <= threshold: subtracting the all-ones mask
        // adds one.
        let right = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(value, threshold));
        g.at = _mm256_blendv_epi8(g.at, _mm256_sub_epi32(next, right), moving);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::super::depth::{BACKGROUND_MM, DepthImage};
    use super::super::{BadTree, NOT_LEAF, Node, Traversal, Tree};
    use super::*;
    use crate::core::image::Region;
    use rand::{Rng, SeedableRng};

    /// A random tree of up to `depth` levels with probe offsets up to ±40,000 px·mm (about ±70 px at 570 mm) and thresholds
    /// around the depth differences a mouse shows (some infinite and NaN).
    fn random_tree(rng: &mut impl Rng, depth: u32) -> Tree<DepthFeature, ()> {
        let mut nodes = Vec::new();
        let mut leaves = Vec::new();
        // Breadth-first: node i's children at 2i + 1 and 2i + 2.
        let count = (1usize << (depth + 1)) - 1;
        for i in 0..count {
            let leaf = 2 * i + 1 >= count || rng.gen_bool(0.05);
            // Whole millimetres half of the time, so that values equal to the threshold occur.
            let threshold = match rng.gen_range(0..50) {
                0 => f32::NAN,
                1 => f32::INFINITY,
                k if k % 2 == 0 => rng.gen_range(-80..80) as f32,
                _ => rng.gen_range(-80.0..80.0),
            };
            nodes.push(Node {
                feature: [rng.gen_range(-40_000.0..40_000.0), rng.gen_range(-40_000.0..40_000.0)],
                threshold,
                left: (2 * i + 1) as u32,
                leaf: if leaf {
                    leaves.push(());
                    leaves.len() as u32 - 1
                } else {
                    NOT_LEAF
                },
            });
        }
        let mut tree = Tree { nodes, leaves };
        tree.compact();
        tree
    }

    fn random_image(rng: &mut impl Rng) -> DepthImage {
        let region = Region {
            x0: rng.gen_range(0..300),
            y0: rng.gen_range(0..200),
            width: rng.gen_range(1..120),
            height: rng.gen_range(1..90),
        };
        let depth = (0..region.width * region.height)
            .map(|_| {
                if rng.gen_bool(0.3) {
                    BACKGROUND_MM
                } else {
                    rng.gen_range(540..600) as f32
                }
            })
            .collect();
        DepthImage { region, depth }
    }

    /// The AVX2 kernel, or `None` (the test is skipped, and says so) on a processor without.
    fn avx2_or_skip() -> Option<Kernel> {
        let kernel = Kernel::detect();
        if kernel == Kernel::Portable {
            eprintln!("skipped: this processor has no AVX2");
            return None;
        }
        Some(kernel)
    }

    #[test]
    fn avx_and_portable_kernel_sums_agree_bit_for_bit() {
        let Some(avx) = avx2_or_skip() else { return };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5EED);
        for round in 0..500 {
            // Votes around a joint (mm, camera frame), some far beyond the kernel's reach, some
            // of weight zero; lengths that are not whole groups of eight too.
            let n = rng.gen_range(0..300);
            let centre = [
                rng.gen_range(-80.0..80.0),
                rng.gen_range(-80.0..80.0),
                rng.gen_range(500.0..700.0),
            ];
            let spread = if round % 5 == 0 { 40.0 } else { 6.0 };
            let mut votes: [Vec<f32>; 4] = Default::default();
            for _ in 0..n {
                for (c, v) in centre.iter().zip(votes.iter_mut()) {
                    v.push(c + rng.gen_range(-spread..spread));
                }
                votes[3].push(if rng.gen_bool(0.1) {
                    0.0
                } else {
                    rng.gen_range(0.0..0.05)
                });
            }
            let at = centre.map(|c: f32| c + rng.gen_range(-3.0..3.0));
            let scale = 1.0 / (7.0 * rng.gen_range(1.0f32..25.0));
            let slices = [&votes[0][..], &votes[1], &votes[2], &votes[3]];
            let portable = kernel_lanes(Kernel::Portable, slices, at, scale).map(|v| v.to_array().map(f32::to_bits));
            let fast = kernel_lanes(avx, slices, at, scale).map(|v| v.to_array().map(f32::to_bits));
            assert_eq!(portable, fast, "round {round}: the kernels' sums differ");
        }
    }

    #[test]
    fn avx2_and_portable_reach_the_same_leaves() {
        let Some(avx2) = avx2_or_skip() else { return };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x51AD);
        let (mut scratch, mut lanes) = (Traversal::default(), PixelLanes::default());
        let (mut portable, mut fast) = (Vec::new(), Vec::new());
        for round in 0..200 {
            let depth = rng.gen_range(0..12);
            let tree = random_tree(&mut rng, depth).packed().expect("a walkable tree");
            let image = random_image(&mut rng);
            lanes.clear();
            for _ in 0..rng.gen_range(0..100) {
                // Pixels on and around the region, some on its exact edges.
                let r = image.region;
                let x = r.x0 as f32 + rng.gen_range(-5..r.width as i32 + 5) as f32 + 0.5;
                let y = r.y0 as f32 + rng.gen_range(-5..r.height as i32 + 5) as f32 + 0.5;
                lanes.push(x, y, rng.gen_range(530..610) as f32);
            }
            leaf_indices(Kernel::Portable, &tree, &image, &lanes, &mut scratch, &mut portable);
            leaf_indices(avx2, &tree, &image, &lanes, &mut scratch, &mut fast);
            assert_eq!(portable, fast, "round {round}");
        }
    }

    /// The program of issue 28, which once crashed in safe code: a tree whose root points
    /// 50,000,000 nodes away is refused when packed, so the kernels never see it.
    #[test]
    fn a_tree_pointing_outside_itself_is_refused_when_packed() {
        let split = |left| Node {
            feature: [0.0, 0.0],
            threshold: 0.0,
            left,
            leaf: NOT_LEAF,
        };
        let leaf = |leaf| Node {
            feature: [0.0, 0.0],
            threshold: 0.0,
            left: 0,
            leaf,
        };
        let far = Tree {
            nodes: vec![split(50_000_000), leaf(0), leaf(1)],
            leaves: vec![(), ()],
        };
        let error = far.packed().expect_err("a root pointing outside the tree");
        assert_eq!(error.to_string(), "node 0 points outside the tree");
        // Every other way out of the tree: the last node's children, a child before its node
        // (a walk that would never end), a leaf index past the leaves.
        for (nodes, bad) in [
            (vec![split(1), leaf(0), split(2)], 2),
            (vec![split(1), split(0), leaf(0), leaf(1)], 1),
            (vec![split(1), leaf(0), leaf(2)], 2),
        ] {
            let tree = Tree {
                nodes,
                leaves: vec![(), ()],
            };
            assert_eq!(tree.packed().map(|_| ()), Err(BadTree { node: bad }));
        }
        let fine = Tree {
            nodes: vec![split(1), leaf(0), leaf(1)],
            leaves: vec![(), ()],
        };
        let packed = fine.packed().expect("a walkable tree");
        // The root sends a value of 1 left (to leaf 0) and a value of 0 right (to leaf 1).
        assert_eq!(packed.leaf_index_of(|_| 1.0), 0);
        assert_eq!(packed.leaf_index_of(|_| 0.0), 1);
    }

    /// An image whose depth array is shorter than its region is not read past its end by the
    /// gathers: the detected kernel falls back to the portable path, whose probe panics.
    #[test]
    #[should_panic(expected = "index out of bounds")]
    fn a_depth_image_shorter_than_its_region_is_not_read_past_its_end() {
        let region = Region {
            x0: 0,
            y0: 0,
            width: 1000,
            height: 1000,
        };
        let image = DepthImage {
            region,
            depth: vec![500.0; 16],
        };
        // One split that probes each pixel itself, then two leaves.
        let tree = Tree {
            nodes: vec![
                Node {
                    feature: [0.0, 0.0],
                    threshold: 0.0,
                    left: 1,
                    leaf: NOT_LEAF,
                },
                Node {
                    feature: [0.0, 0.0],
                    threshold: 0.0,
                    left: 0,
                    leaf: 0,
                },
                Node {
                    feature: [0.0, 0.0],
                    threshold: 0.0,
                    left: 0,
                    leaf: 1,
                },
            ],
            leaves: vec![(), ()],
        };
        let tree = tree.packed().expect("a walkable tree");
        let mut lanes = PixelLanes::default();
        // Sixteen pixels far down the region, a million floats past the array.
        for k in 0..16 {
            lanes.push(500.5 + k as f32, 999.5, 500.0);
        }
        let (mut scratch, mut leaves) = (Traversal::default(), Vec::new());
        leaf_indices(Kernel::detect(), &tree, &image, &lanes, &mut scratch, &mut leaves);
    }

    #[test]
    fn a_convolution_gives_the_same_planes_bit_for_bit_in_avx2_and_portably() {
        let Some(avx2) = avx2_or_skip() else { return };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(45);
        // Blocks of outputs whole and part-filled, odd sizes, dilated taps, 1x1 heads.
        for (inputs, outputs, kernel, dilation, w, h) in [
            (1usize, 6usize, 3usize, 1usize, 37usize, 21usize),
            (6, 12, 3, 1, 19, 11),
            (12, 12, 3, 4, 23, 17),
            (5, 13, 3, 2, 8, 9),
            (12, 1, 1, 1, 31, 7),
            (3, 25, 3, 1, 1, 1),
        ] {
            let weights: Vec<f32> = (0..outputs.div_ceil(CONV_BLOCK) * inputs * kernel * kernel * CONV_BLOCK)
                .map(|_| rng.gen_range(-1.0..1.0))
                .collect();
            let bias: Vec<f32> = (0..outputs).map(|_| rng.gen_range(-1.0..1.0)).collect();
            for relu in [false, true] {
                let layer = ConvLayer {
                    inputs,
                    outputs,
                    kernel,
                    dilation,
                    weights: &weights,
                    bias: &bias,
                    relu,
                };
                let (pw, reach) = (layer.padded_width(w), layer.reach());
                let pplane = pw * (h + 2 * reach);
                let mut padded = vec![0.0f32; inputs * pplane];
                for (i, plane) in padded.chunks_exact_mut(pplane).enumerate() {
                    for y in 0..h {
                        for x in 0..w {
                            // Values of very different sizes, so that a change of order shows.
                            plane[(y + reach) * pw + reach + x] =
                                rng.gen_range(-1.0f32..1.0) * 10f32.powi((i + x) as i32 % 7 - 3);
                        }
                    }
                }
                let mut portable = vec![0.0; outputs * w * h];
                let mut fast = vec![1.0; outputs * w * h];
                conv(Kernel::Portable, &layer, &padded, w, h, &mut portable);
                conv(avx2, &layer, &padded, w, h, &mut fast);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&portable),
                    bits(&fast),
                    "{inputs} -> {outputs}, {kernel}x{kernel} / {dilation}, {w}x{h}"
                );
            }
        }
    }
}
