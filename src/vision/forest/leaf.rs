//! The body forest's leaves in the form a version 2 model file stores them and run time reads
//! them: the leaf record (the mask of the joints a leaf votes for, then each vote quantised to
//! 10 bytes), its codec, and [`SparseLeaves`], a tree's leaves as records one after the other.
//!
//! `model` writes and reads these records in files; `infer` reads the votes from
//! [`SparseLeaves`]; the votes' training form ([`JointLeaf`]) is `depth`'s.

use super::depth::{JointLeaf, JointVote};

/// Resolution of stored vote offsets (mm) and spreads (mm^2) in version 2.
const OFFSET_UNIT_MM: f32 = 0.05;
const SPREAD_UNIT_MM2: f32 = 0.25;

/// `v / unit` rounded to the nearest `i16`, saturating.
fn quantise_i16(v: f32, unit: f32) -> i16 {
    (v / unit).round().clamp(f32::from(i16::MIN), f32::from(i16::MAX)) as i16
}

/// `v / unit` rounded into `[lo, u16::MAX]`.
fn quantise_u16(v: f32, unit: f32, lo: u16) -> u16 {
    (v / unit).round().clamp(f32::from(lo), f32::from(u16::MAX)) as u16
}
/// Bytes of a vote in a leaf of a version 2 file.
pub(super) const VOTE_BYTES: usize = 10;

/// A body leaf as a version 2 file stores it, appended to `out`: a bit mask of the joints the
/// leaf votes for (those with a weight), then their votes in joint order, each 3 offsets, its
/// weight and its spread ([`vote_from_bytes`] reads one).
pub(super) fn leaf_record(leaf: &JointLeaf, out: &mut Vec<u8>) {
    let mask = leaf
        .iter()
        .enumerate()
        .filter(|(_, v)| v.weight > 0.0)
        .fold(0u16, |m, (j, _)| m | (1 << j));
    out.extend_from_slice(&mask.to_le_bytes());
    for v in leaf.iter().filter(|v| v.weight > 0.0) {
        for c in v.offset {
            out.extend_from_slice(&quantise_i16(c, OFFSET_UNIT_MM).to_le_bytes());
        }
        out.extend_from_slice(&quantise_u16(v.weight, 1.0 / 65535.0, 1).to_le_bytes());
        out.extend_from_slice(&quantise_u16(v.spread, SPREAD_UNIT_MM2, 0).to_le_bytes());
    }
}

/// A vote of a version 2 leaf from its [`VOTE_BYTES`] bytes.
#[inline]
pub(super) fn vote_from_bytes(b: &[u8]) -> JointVote {
    let i = |k: usize| i16::from_le_bytes([b[k], b[k + 1]]);
    let u = |k: usize| u16::from_le_bytes([b[k], b[k + 1]]);
    JointVote {
        offset: [0, 2, 4].map(|k| f32::from(i(k)) * OFFSET_UNIT_MM),
        weight: f32::from(u(6)) / 65535.0,
        spread: f32::from(u(8)) * SPREAD_UNIT_MM2,
    }
}

/// A tree's leaves in the form run time reads: each leaf's record as a version 2 model file
/// stores it ([`leaf_record`]: the mask of the joints it votes for, then 10 bytes per
/// vote), one after the other, so a leaf is one short run of memory (80 bytes on average for
/// the bundled forest, where the votes as `f32`s took 160 in three arrays). Leaf `l`'s record
/// is `records[start[l]..start[l + 1]]`. Its votes are decoded as they are read, exactly as
/// the file's reader decodes them.
#[derive(Clone, Debug, PartialEq)]
pub struct SparseLeaves {
    start: Vec<u32>,
    records: Vec<u8>,
}

impl Default for SparseLeaves {
    fn default() -> Self {
        Self {
            start: vec![0],
            records: Vec::new(),
        }
    }
}

impl SparseLeaves {
    /// The leaves of a tree in the training form, their votes quantised as a model file's.
    pub fn from_leaves(leaves: &[JointLeaf]) -> Self {
        let mut out = Self::default();
        out.start.reserve(leaves.len());
        for leaf in leaves {
            out.push_leaf(leaf);
        }
        out
    }

    /// Adds a leaf of the training form, its votes quantised as a model file's.
    pub fn push_leaf(&mut self, leaf: &JointLeaf) {
        leaf_record(leaf, &mut self.records);
        self.start.push(self.records.len() as u32);
    }

    /// Adds a leaf from its record in a version 2 model file: its joints' `mask` and its
    /// votes' bytes, checked by the caller.
    pub(super) fn push_record(&mut self, mask: u16, votes: &[u8]) {
        self.records.extend_from_slice(&mask.to_le_bytes());
        self.records.extend_from_slice(votes);
        self.start.push(self.records.len() as u32);
    }

    /// Where leaf `leaf`'s votes lie, and which joints they are for (this reads the leaf's
    /// first bytes); [`Self::votes`] then reads the votes.
    #[inline]
    pub fn locate(&self, leaf: u32) -> Located {
        // Every record starts with its two bytes of mask.
        let (start, end) = (self.start[leaf as usize], self.start[leaf as usize + 1]);
        let mask = &self.records[start as usize..start as usize + 2];
        Located {
            start: start + 2,
            end,
            mask: u16::from_le_bytes([mask[0], mask[1]]),
        }
    }

    /// The votes of a leaf [`Self::locate`] found, with their joints, in joint order.
    #[inline]
    pub fn votes(&self, at: Located) -> LeafVotes<'_> {
        LeafVotes {
            mask: at.mask,
            votes: &self.records[at.start as usize..at.end as usize],
        }
    }
}

/// A leaf of [`SparseLeaves`] found ([`SparseLeaves::locate`]): where its votes' bytes lie
/// and the mask of the joints they are for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Located {
    start: u32,
    end: u32,
    mask: u16,
}

/// The votes of one leaf of [`SparseLeaves`], decoded one by one.
#[derive(Clone, Debug)]
pub struct LeafVotes<'a> {
    /// The joints whose votes are still to come.
    mask: u16,
    votes: &'a [u8],
}

impl Iterator for LeafVotes<'_> {
    type Item = (usize, JointVote);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.mask == 0 || self.votes.len() < VOTE_BYTES {
            return None;
        }
        let joint = self.mask.trailing_zeros() as usize;
        self.mask &= self.mask - 1;
        let (vote, rest) = self.votes.split_at(VOTE_BYTES);
        self.votes = rest;
        Some((joint, vote_from_bytes(vote)))
    }
}
