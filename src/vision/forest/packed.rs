//! The form of a tree that run-time traversal reads: split nodes and leaf indices in one flat
//! array of [`PackedNode`]s. Only [`PackedTree::new`] builds one, from a [`Tree`] it has
//! checked ([`Tree::check`]), so every packed tree can be walked: each split node's children
//! lie after it and inside the array. The AVX2 traversal ([`super::simd`]) reads nodes without
//! bounds checks and relies on that.

use super::{BadTree, Tree};

/// The buffers of [`PackedTree::leaf_indices`], kept between calls so traversal does not
/// allocate.
#[derive(Clone, Debug, Default)]
pub struct Traversal {
    /// Per sample: its node while on its way, its leaf index at the end.
    at: Vec<u32>,
    /// The samples not yet at a leaf.
    moving: Vec<u32>,
}

impl Traversal {
    /// The leaf index each sample reached in the last traversal.
    pub fn leaves(&self) -> &[u32] {
        &self.at
    }
}

/// Asks the processor to bring `x` into its caches, without waiting for it.
#[inline(always)]
fn prefetch<T>(x: &T) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
    safe_arch::prefetch_t0(x);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
    let _ = x;
}

/// Marks a [`PackedNode`] that is a leaf; the other bits are its leaf index.
pub(super) const PACKED_LEAF: u32 = 1 << 31;

/// A node as traversal reads it: the child index and the leaf index share one word, so a
/// node with a two-float feature fills 16 bytes and four share a cache line. `repr(C)`: the
/// AVX2 traversal ([`super::simd`]) gathers the fields by their offsets.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct PackedNode<F> {
    feature: F,
    threshold: f32,
    /// The left child's index, or the leaf index with [`PACKED_LEAF`] set.
    next: u32,
}

/// A tree's split nodes and leaf indices in [`PackedNode`]s, same order as the tree's nodes;
/// the leaf payloads stay in the [`Tree`].
///
/// Invariant (what [`Self::new`] checks, and the AVX2 traversal relies on): every split
/// node's `next` is greater than its own index and `next + 1` is inside `nodes`.
#[derive(Clone, Debug, PartialEq)]
pub struct PackedTree<F> {
    nodes: Vec<PackedNode<F>>,
}

impl<F: Copy> PackedTree<F> {
    /// Packs `tree`, once [`Tree::check`] found every child and leaf index inside it.
    ///
    /// # Errors
    /// The first node of `tree` whose child or leaf index points outside it.
    pub fn new<L>(tree: &Tree<F, L>) -> Result<Self, BadTree> {
        tree.check()?;
        let nodes = tree
            .nodes
            .iter()
            .map(|n| PackedNode {
                feature: n.feature,
                threshold: n.threshold,
                // `check` keeps leaf indices below `PACKED_LEAF`.
                next: if n.is_leaf() { n.leaf | PACKED_LEAF } else { n.left },
            })
            .collect();
        Ok(Self { nodes })
    }
}

impl<F> PackedTree<F> {
    /// The nodes, root first (for the AVX2 traversal, which reads them by address).
    pub(super) fn nodes(&self) -> &[PackedNode<F>] {
        &self.nodes
    }

    /// The leaf index one sample reaches (`value(feature)` is the feature's value for it).
    #[inline]
    pub fn leaf_index_of(&self, mut value: impl FnMut(&F) -> f32) -> u32 {
        let mut i = 0usize;
        loop {
            let node = &self.nodes[i];
            if node.next & PACKED_LEAF != 0 {
                return node.next & !PACKED_LEAF;
            }
            i = (node.next + u32::from(value(&node.feature) <= node.threshold)) as usize;
        }
    }

    /// The leaf index each of `count` samples reaches, in `scratch.leaves()` (`value(s,
    /// feature)` is the feature's value for sample `s`). Level by level: every sample still
    /// on its way takes one step down per pass, so the memory loads of many samples overlap
    /// instead of waiting on one sample's chain of dependent loads, and one tree's nodes stay
    /// in cache. Each sample's next node is asked into the cache as soon as it is known, a
    /// whole pass before it is read.
    pub fn leaf_indices(&self, count: usize, mut value: impl FnMut(usize, &F) -> f32, scratch: &mut Traversal) {
        let Traversal { at, moving } = scratch;
        at.clear();
        moving.clear();
        if self.nodes.is_empty() {
            return;
        }
        // Node indices while on the way, leaf indices (flagged) on arrival.
        at.resize(count, 0);
        moving.extend(0..count as u32);
        while !moving.is_empty() {
            let mut kept = 0;
            for k in 0..moving.len() {
                let s = moving[k] as usize;
                let node = &self.nodes[at[s] as usize];
                let next = if node.next & PACKED_LEAF == 0 {
                    let next = node.next + u32::from(value(s, &node.feature) <= node.threshold);
                    // Wanted on the next pass, after every other moving sample's step.
                    if let Some(n) = self.nodes.get(next as usize) {
                        prefetch(n);
                    }
                    moving[kept] = s as u32;
                    kept += 1;
                    next
                } else {
                    node.next & !PACKED_LEAF
                };
                at[s] = next;
            }
            moving.truncate(kept);
        }
    }
}
