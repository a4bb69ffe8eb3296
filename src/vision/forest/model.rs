//! Forest model files: versioned, checksummed and self-describing.
//!
//! ```text
//! 0   8  magic "MPFOREST"
//! 8   4  format version (u32, 1)
//! 12  4  kind (u32): 1 body regression forest, 2 part classification forest
//! 16  4  length of the description (u32)
//! 20  n  description: JSON (parameters, training data provenance, skeleton and engine versions)
//! ..  8  length of the compressed trees (u64)
//! ..  m  zstd-compressed trees (layout below)
//! ..  4  CRC-32 of every byte before it
//! ```
//! Trees: u32 tree count; per tree u32 node count, nodes (f32 ux, f32 uy, f32 threshold, u32
//! left, u32 leaf), u32 leaf count, leaves (body: u16 mask of the joints the leaf votes for,
//! then per voted joint 3 i16 offsets in units of 0.05 mm, u16 weight in units of 1/65535 and
//! u16 spread in units of 0.25 mm^2 (version 1: 5 f32); parts: 6 f32 class probabilities).
//! All little-endian.
//!
//! Reading checks everything a damaged or foreign file could break: the magic, the version,
//! the kind, the checksum, every length against what is left, and every child and leaf index
//! against the arrays, so a tree loaded is one that can be walked.

use super::depth::{BODY_JOINTS, DepthFeature, JointLeaf, JointVote};
use super::leaf::{SparseLeaves, VOTE_BYTES, leaf_record, vote_from_bytes};
use super::{Forest, Node, Tree};
use crate::core::skeleton::PART_COUNT;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const MAGIC: &[u8; 8] = b"MPFOREST";
/// The model format version this build writes; it also reads version 1 (votes as f32).
pub const FORMAT_VERSION: u32 = 2;
/// The zstd level of the tree section. Quantised votes hardly compress (about 1.5:1 at any
/// level), and every start-up decompresses the section: level 1 decompresses the bundled
/// body forest's 43 MB 2.5x faster than level 9 did (`hyperfine` of `zstd -d`), for a file
/// 2 % larger.
const TREES_ZSTD_LEVEL: i32 = 1;

/// The largest decompressed tree section accepted (far above any real model).
const MAX_TREES_BYTES: usize = 1 << 30;
/// The largest model file read (the bundled ones are about 9 MB).
const MAX_MODEL_BYTES: u64 = 1 << 30;

/// What a model file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// Regression of the 12 main-body joints.
    Body,
    /// Classification into the six body parts.
    Parts,
}

impl ModelKind {
    fn code(self) -> u32 {
        match self {
            ModelKind::Body => 1,
            ModelKind::Parts => 2,
        }
    }

    fn from_code(code: u32) -> Option<Self> {
        match code {
            1 => Some(ModelKind::Body),
            2 => Some(ModelKind::Parts),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Body => "body forest",
            ModelKind::Parts => "part forest",
        }
    }
}

/// The self-description stored in a model file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub kind: ModelKind,
    pub software_version: String,
    pub skeleton_version: u32,
    pub engine_version: u32,
    /// Baseline training parameters.
    pub train: super::TrainParams,
    /// Discriminative training parameters, when it was applied.
    pub discriminative: Option<super::discriminative::DiscriminativeParams>,
    /// Where the training data came from (dataset directories, their seeds and sizes).
    pub data: Vec<DataProvenance>,
    /// Training pixels sampled per image.
    pub pixels_per_image: usize,
    /// Thresholds tried per feature.
    pub thresholds: usize,
    /// Seconds the training took.
    pub training_seconds: f64,
}

/// One training data set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataProvenance {
    /// `train` (D_t) or `discriminative` (D_d).
    pub role: String,
    /// The dataset directory's name (not its full path).
    pub path: String,
    pub seed: u64,
    pub images: u64,
    pub noise: crate::core::noise::DepthNoise,
    pub engine_version: u32,
}

/// A loaded model.
#[derive(Clone, Debug, PartialEq)]
pub enum Model {
    Body(ModelInfo, Forest<DepthFeature, JointLeaf>),
    Parts(ModelInfo, Forest<DepthFeature, Vec<f32>>),
}

impl Model {
    pub fn info(&self) -> &ModelInfo {
        match self {
            Model::Body(i, _) | Model::Parts(i, _) => i,
        }
    }
}

/// Errors reading or writing model files.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("cannot {action} {path:?}")]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{path:?} is not a mousepose forest model")]
    Foreign { path: PathBuf },
    #[error("{path:?} is a forest model of format version {version}; this build reads version {FORMAT_VERSION}")]
    Version { path: PathBuf, version: u32 },
    #[error("{path:?} is damaged: {reason}")]
    Corrupt { path: PathBuf, reason: String },
    #[error("{path:?} holds a {found}, expected a {expected}")]
    WrongKind {
        path: PathBuf,
        found: &'static str,
        expected: &'static str,
    },
    #[error("{path:?} was trained for skeleton version {found}; this build uses version {expected}")]
    Skeleton { path: PathBuf, found: u32, expected: u32 },
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_f32(out: &mut Vec<u8>, v: f32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn encode_trees<L>(forest: &Forest<DepthFeature, L>, mut leaf: impl FnMut(&mut Vec<u8>, &L)) -> Vec<u8> {
    let mut out = Vec::new();
    put_u32(&mut out, forest.trees.len() as u32);
    for t in &forest.trees {
        put_u32(&mut out, t.nodes.len() as u32);
        for n in &t.nodes {
            put_f32(&mut out, n.feature[0]);
            put_f32(&mut out, n.feature[1]);
            put_f32(&mut out, n.threshold);
            put_u32(&mut out, n.left);
            put_u32(&mut out, n.leaf);
        }
        put_u32(&mut out, t.leaves.len() as u32);
        for l in &t.leaves {
            leaf(&mut out, l);
        }
    }
    out
}

/// Encodes a model file.
///
/// # Errors
/// When the description cannot be serialised or compression fails.
pub fn encode(model: &Model) -> Result<Vec<u8>, String> {
    let (info, trees) = match model {
        Model::Body(info, f) => (info, encode_trees(f, |out, leaf: &JointLeaf| leaf_record(leaf, out))),
        Model::Parts(info, f) => (
            info,
            encode_trees(f, |out, leaf: &Vec<f32>| {
                for c in 0..PART_COUNT {
                    put_f32(out, leaf.get(c).copied().unwrap_or(0.0));
                }
            }),
        ),
    };
    let description = serde_json::to_vec(info).map_err(|e| e.to_string())?;
    let compressed = zstd::bulk::compress(&trees, TREES_ZSTD_LEVEL).map_err(|e| e.to_string())?;
    Ok(framed(info.kind, &description, &compressed))
}

/// A model file: the magic, version and kind, the description, the compressed tree section,
/// and the checksum of all before it.
fn framed(kind: ModelKind, description: &[u8], compressed: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(32 + description.len() + compressed.len());
    out.extend_from_slice(MAGIC);
    put_u32(&mut out, FORMAT_VERSION);
    put_u32(&mut out, kind.code());
    put_u32(&mut out, description.len() as u32);
    out.extend_from_slice(description);
    out.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
    out.extend_from_slice(compressed);
    let crc = crc32fast::hash(&out);
    put_u32(&mut out, crc);
    out
}

/// Writes a model file (through a temporary file renamed into place, so a crash never leaves
/// half a model under the final name).
///
/// # Errors
/// When the file cannot be written.
pub fn save(model: &Model, path: &Path) -> Result<(), ModelError> {
    let bytes = encode(model).map_err(|reason| ModelError::Corrupt {
        path: path.to_owned(),
        reason,
    })?;
    let tmp = path.with_extension("forest.partial");
    let io = |action| {
        move |source| ModelError::Io {
            path: path.to_owned(),
            action,
            source,
        }
    };
    std::fs::write(&tmp, &bytes).map_err(io("write"))?;
    std::fs::rename(&tmp, path).map_err(io("write"))
}

/// A little-endian reader that names what ran short.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| format!("it ends inside the {what}"))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
}

/// Where the tree section's bytes come from: the decompressed section in memory, or the
/// decompressor's stream (a body forest is 44 MB decompressed: never held whole that way).
trait Source {
    /// The next `n` bytes.
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], String>;
    /// How many bytes are left at most.
    fn left(&self) -> usize;
    /// Whether every byte was read.
    fn at_end(&mut self) -> Result<bool, String>;

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn f32(&mut self, what: &str) -> Result<f32, String> {
        Ok(f32::from_bits(self.u32(what)?))
    }
    fn count(&mut self, what: &str, item_bytes: usize) -> Result<usize, String> {
        let n = self.u32(what)? as usize;
        if n.saturating_mul(item_bytes) > self.left() {
            return Err(format!("its {what} ({n}) do not fit in the file"));
        }
        Ok(n)
    }
}

impl Source for Reader<'_> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], String> {
        Reader::take(self, n, what)
    }
    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }
    fn at_end(&mut self) -> Result<bool, String> {
        Ok(self.at == self.bytes.len())
    }
}

/// The tree section read from the decompressor as it goes, at most `limit` bytes (the size
/// the zstd frame declares when it declares a plausible one, else [`MAX_TREES_BYTES`]),
/// through a buffer of its own: `buf[pos..end]` is read and not yet taken.
struct Stream<R> {
    inner: R,
    buf: Vec<u8>,
    pos: usize,
    end: usize,
    at: usize,
    limit: usize,
}

impl<R: std::io::Read> Stream<R> {
    fn new(inner: R, limit: usize) -> Self {
        Self {
            inner,
            buf: vec![0; 1 << 16],
            pos: 0,
            end: 0,
            at: 0,
            limit,
        }
    }

    /// Reads until `n` bytes are buffered or the stream ends; whether they are.
    fn fill(&mut self, n: usize) -> Result<bool, String> {
        if self.end - self.pos >= n {
            return Ok(true);
        }
        self.buf.copy_within(self.pos..self.end, 0);
        self.end -= self.pos;
        self.pos = 0;
        if self.buf.len() < n {
            self.buf.resize(n, 0);
        }
        while self.end < n {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => return Ok(false),
                Ok(k) => self.end += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(format!("its trees do not decompress: {e}")),
            }
        }
        Ok(true)
    }
}

impl<R: std::io::Read> Source for Stream<R> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], String> {
        if n > self.limit - self.at || !self.fill(n)? {
            return Err(format!("it ends inside the {what}"));
        }
        let start = self.pos;
        self.pos += n;
        self.at += n;
        Ok(&self.buf[start..start + n])
    }
    fn left(&self) -> usize {
        self.limit - self.at
    }
    fn at_end(&mut self) -> Result<bool, String> {
        Ok(!self.fill(1)?)
    }
}

/// Reads the trees, handing each to `convert` once read and checked (so a caller that keeps
/// another form of them never holds every tree in this one).
fn decode_trees<S: Source, L, T>(
    r: &mut S,
    leaf_bytes: usize,
    mut leaf: impl FnMut(&mut S) -> Result<L, String>,
    mut convert: impl FnMut(Tree<DepthFeature, L>) -> T,
) -> Result<Vec<T>, String> {
    let count = r.count("tree count", 8)?;
    if count == 0 {
        return Err("it has no trees".to_owned());
    }
    // Reserved up to a bound: a streamed section's counts are only checked against its limit.
    let mut trees = Vec::with_capacity(count.min(1 << 10));
    for t in 0..count {
        let n_nodes = r.count("node count", 20)?;
        let mut nodes = Vec::with_capacity(n_nodes.min(1 << 20));
        for _ in 0..n_nodes {
            // A node's 20 bytes at once (a take per field cost a quarter of loading the body forest).
            let b = r.take(20, "node")?;
            let word = |k: usize| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
            let feature = [f32::from_bits(word(0)), f32::from_bits(word(4))];
            let threshold = f32::from_bits(word(8));
            let (left, leaf) = (word(12), word(16));
            if !feature.iter().chain([&threshold]).all(|v| v.is_finite()) {
                return Err(format!("tree {t} has a node with a value that is not a number"));
            }
            nodes.push(Node {
                feature,
                threshold,
                left,
                leaf,
            });
        }
        let n_leaves = r.count("leaf count", leaf_bytes)?;
        let mut leaves = Vec::with_capacity(n_leaves.min(1 << 20));
        for _ in 0..n_leaves {
            leaves.push(leaf(r)?);
        }
        if nodes.is_empty() {
            return Err(format!("tree {t} has no nodes"));
        }
        // Every split's children exist and lie after it (so walking always ends); every leaf
        // index exists.
        let tree = Tree { nodes, leaves };
        tree.check().map_err(|e| format!("tree {t} {e}"))?;
        trees.push(convert(tree));
    }
    if !r.at_end()? {
        return Err("it has bytes after its last tree".to_owned());
    }
    Ok(trees)
}

/// The size the zstd frame of the tree section (`frame`: its first bytes at least)
/// declares, when it declares one that is
/// plausible: within [`MAX_TREES_BYTES`] and at most 8 times the compressed size (the bundled
/// models' is 1.5), so a forged size reserves no more than that.
fn declared_size(frame: &[u8], compressed_len: usize) -> Option<usize> {
    zstd::zstd_safe::get_frame_content_size(frame)
        .ok()
        .flatten()
        .and_then(|n| usize::try_from(n).ok())
        .filter(|&n| n <= MAX_TREES_BYTES && n / 8 <= compressed_len)
}

/// The tree section, decompressed as a stream: memory grows with the trees actually there,
/// never reserved up front for the largest section accepted (what `zstd::bulk` does, 1 GiB
/// for every model), and stops past [`MAX_TREES_BYTES`].
fn decompress_trees(compressed: &[u8]) -> Result<Vec<u8>, String> {
    use std::io::Read as _;
    let unreadable = |e: std::io::Error| format!("its trees do not decompress: {e}");
    // The size the frame declares reserved at once, so the section is not copied as it
    // grows; a claim not believed leaves memory growing with what is there.
    let mut trees = Vec::with_capacity(declared_size(compressed, compressed.len()).unwrap_or(0));
    zstd::stream::read::Decoder::with_buffer(compressed)
        .map_err(unreadable)?
        .take(MAX_TREES_BYTES as u64 + 1)
        .read_to_end(&mut trees)
        .map_err(unreadable)?;
    if trees.len() > MAX_TREES_BYTES {
        return Err(format!("its trees decompress to more than {MAX_TREES_BYTES} bytes"));
    }
    Ok(trees)
}

/// Reads a model file, checking it is whole, of this format, and of the expected kind.
///
/// # Errors
/// A [`ModelError`] naming the file and what is wrong with it.
pub fn load(path: &Path, expected: Option<ModelKind>) -> Result<Model, ModelError> {
    let bytes = crate::io::read_bounded_bytes(path, MAX_MODEL_BYTES).map_err(|source| ModelError::Io {
        path: path.to_owned(),
        action: "read",
        source,
    })?;
    decode(&bytes, path, expected)
}

/// The header of a model file in `bytes`, checked (magic, version, checksum, kind, description,
/// skeleton): the format version, the kind, the description and the compressed tree section.
fn header<'b>(
    bytes: &'b [u8],
    path: &Path,
    expected: Option<ModelKind>,
) -> Result<(u32, ModelKind, ModelInfo, &'b [u8]), ModelError> {
    let corrupt = |reason: String| ModelError::Corrupt {
        path: path.to_owned(),
        reason,
    };
    let version = magic_and_version(bytes, bytes.len(), path)?;
    let (body, crc) = bytes.split_at(bytes.len() - 4);
    if crc32fast::hash(body) != u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]) {
        return Err(corrupt(
            "its checksum does not match (truncated or modified)".to_owned(),
        ));
    }
    let (kind, info, start, len) = fields(body, body.len(), path, expected)?;
    Ok((version, kind, info, &body[start..start + len]))
}

/// The magic and the format version at the start of a file of `total` bytes whose first
/// bytes are `head`; a file too short to hold a checksum is refused.
fn magic_and_version(head: &[u8], total: usize, path: &Path) -> Result<u32, ModelError> {
    let corrupt = |reason: String| ModelError::Corrupt {
        path: path.to_owned(),
        reason,
    };
    if head.len() < 8 || &head[..8] != MAGIC {
        return Err(ModelError::Foreign { path: path.to_owned() });
    }
    let mut r = Reader { bytes: head, at: 8 };
    let version = r.u32("header").map_err(corrupt)?;
    if version != FORMAT_VERSION && version != 1 {
        return Err(ModelError::Version {
            path: path.to_owned(),
            version,
        });
    }
    if total < 24 {
        return Err(corrupt("it is truncated".to_owned()));
    }
    Ok(version)
}

/// The fields after the version, read from `head` (the first bytes of the file's `body_len`
/// bytes before its checksum): the kind, the description, and where the compressed tree
/// section starts and how long it is (checked to lie within the body).
fn fields(
    head: &[u8],
    body_len: usize,
    path: &Path,
    expected: Option<ModelKind>,
) -> Result<(ModelKind, ModelInfo, usize, usize), ModelError> {
    let corrupt = |reason: String| ModelError::Corrupt {
        path: path.to_owned(),
        reason,
    };
    let mut r = Reader { bytes: head, at: 12 };
    let code = r.u32("header").map_err(corrupt)?;
    let kind = ModelKind::from_code(code).ok_or_else(|| corrupt(format!("unknown model kind {code}")))?;
    if let Some(expected) = expected.filter(|&e| e != kind) {
        return Err(ModelError::WrongKind {
            path: path.to_owned(),
            found: kind.name(),
            expected: expected.name(),
        });
    }
    let desc_len = r.u32("header").map_err(corrupt)? as usize;
    let desc = r.take(desc_len, "description").map_err(corrupt)?;
    let info: ModelInfo =
        serde_json::from_slice(desc).map_err(|e| corrupt(format!("its description is unreadable: {e}")))?;
    if info.skeleton_version != crate::core::skeleton::SKELETON_VERSION {
        return Err(ModelError::Skeleton {
            path: path.to_owned(),
            found: info.skeleton_version,
            expected: crate::core::skeleton::SKELETON_VERSION,
        });
    }
    let len_bytes = r.take(8, "tree section length").map_err(corrupt)?;
    let mut l = [0u8; 8];
    l.copy_from_slice(len_bytes);
    let len = usize::try_from(u64::from_le_bytes(l)).unwrap_or(usize::MAX);
    if r.at.checked_add(len).is_none_or(|end| end > body_len) {
        return Err(corrupt("it ends inside the trees".to_owned()));
    }
    Ok((kind, info, r.at, len))
}

/// Decodes model bytes read from `path` (used in messages).
///
/// # Errors
/// As [`load`].
pub fn decode(bytes: &[u8], path: &Path, expected: Option<ModelKind>) -> Result<Model, ModelError> {
    let corrupt = |reason: String| ModelError::Corrupt {
        path: path.to_owned(),
        reason,
    };
    let (version, kind, info, compressed) = header(bytes, path, expected)?;
    let trees = decompress_trees(compressed).map_err(corrupt)?;
    let mut r = Reader { bytes: &trees, at: 0 };
    match kind {
        ModelKind::Body => {
            let trees = decode_trees(&mut r, 2, |r| body_leaf(r, version), |t| t).map_err(corrupt)?;
            Ok(Model::Body(info, Forest { trees }))
        }
        ModelKind::Parts => {
            let trees = decode_trees(
                &mut r,
                PART_COUNT * 4,
                |r| (0..PART_COUNT).map(|_| r.f32("leaf")).collect(),
                |t| t,
            )
            .map_err(corrupt)?;
            Ok(Model::Parts(info, Forest { trees }))
        }
    }
}

/// A body forest's leaf: the mask of the joints it votes for, then each vote.
fn body_leaf(r: &mut impl Source, version: u32) -> Result<JointLeaf, String> {
    let mut leaf = [JointVote::default(); BODY_JOINTS];
    let mask = leaf_mask(r)?;
    let bytes = r.take(vote_bytes(version) * mask.count_ones() as usize, "leaf")?;
    check_votes(mask, bytes, version, |j, v| leaf[j] = v)?;
    Ok(leaf)
}

/// The bytes of a vote in a file of `version`: 20 in version 1 (five `f32`), [`VOTE_BYTES`]
/// in version 2.
fn vote_bytes(version: u32) -> usize {
    if version == 1 { 20 } else { VOTE_BYTES }
}

/// A body leaf's mask of the joints it votes for, checked.
fn leaf_mask(r: &mut impl Source) -> Result<u16, String> {
    let m = r.take(2, "leaf")?;
    let mask = u16::from_le_bytes([m[0], m[1]]);
    if mask >> BODY_JOINTS != 0 {
        return Err(format!("a leaf votes for joints that do not exist (mask {mask:#06x})"));
    }
    Ok(mask)
}

/// The votes of a leaf with `mask` from their bytes in a file of `version`, each checked and
/// handed to `vote` with its joint.
fn check_votes(mask: u16, bytes: &[u8], version: u32, mut vote: impl FnMut(usize, JointVote)) -> Result<(), String> {
    let voted = (0..BODY_JOINTS).filter(|j| mask & (1 << j) != 0);
    for (j, b) in voted.zip(bytes.chunks_exact(vote_bytes(version))) {
        let v = if version == 1 {
            let f = |k: usize| f32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
            JointVote {
                offset: [f(0), f(4), f(8)],
                weight: f(12),
                spread: f(16),
            }
        } else {
            vote_from_bytes(b)
        };
        if !(v.offset.iter().all(|c| c.is_finite()) && v.weight > 0.0 && v.weight <= 1.0 && v.spread >= 0.0) {
            return Err(format!("a leaf's vote for joint {} is not valid", j + 1));
        }
        vote(j, v);
    }
    Ok(())
}

/// Reads a body forest's leaf, checked as [`body_leaf`] does, onto `out` in the form a
/// version 2 file stores it ([`leaf_record`]): a version 2 leaf's bytes as they are, a version
/// 1 leaf's votes quantised.
fn body_leaf_record(r: &mut impl Source, version: u32, out: &mut SparseLeaves) -> Result<(), String> {
    if version == 1 {
        out.push_leaf(&body_leaf(r, version)?);
        return Ok(());
    }
    let mask = leaf_mask(r)?;
    let bytes = r.take(VOTE_BYTES * mask.count_ones() as usize, "leaf")?;
    check_votes(mask, bytes, version, |_, _| {})?;
    out.push_record(mask, bytes);
    Ok(())
}

/// Loads a body forest file as [`load`] does, checking the same, but hands each tree to
/// `convert` as soon as it is read, its nodes with its leaves' votes as run time reads them,
/// and never holds the decompressed section (44 MB for the bundled forest) nor any leaf in
/// the training form (240 bytes each, for 80 in the file): the run-time form is built tree
/// by tree, straight from the bytes (see `BodyEstimator::load`).
///
/// # Errors
/// As [`load`]; a file of another kind is [`ModelError::WrongKind`].
pub fn load_body_trees<T>(
    path: &Path,
    mut convert: impl FnMut(Tree<DepthFeature, ()>, SparseLeaves) -> T,
) -> Result<(ModelInfo, Vec<T>), ModelError> {
    use std::io::{Read as _, Seek as _};
    let io = read_error(path);
    let corrupt = |reason: String| ModelError::Corrupt {
        path: path.to_owned(),
        reason,
    };
    if !std::fs::metadata(path).map_err(io)?.is_file() {
        return Err(io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "it is not a regular file",
        )));
    }
    let mut file = std::fs::File::open(path).map_err(io)?;
    let Scan {
        mut head,
        held,
        total,
        crc,
    } = scan(&mut file, path)?;
    let version = magic_and_version(&head, total, path)?;
    if crc != u32::from_le_bytes([held[0], held[1], held[2], held[3]]) {
        return Err(corrupt(
            "its checksum does not match (truncated or modified)".to_owned(),
        ));
    }
    let body_len = total - 4;
    head.truncate(body_len);
    let (_, info, start, len) = match fields(&head, body_len, path, Some(ModelKind::Body)) {
        Ok(f) => f,
        // A description longer than the bytes kept: read as a whole, as `load` does.
        Err(ModelError::Corrupt { .. }) if head.len() < body_len => {
            return match load(path, Some(ModelKind::Body))? {
                Model::Body(info, forest) => {
                    let trees = forest.trees.into_iter().map(run_form).map(|(t, l)| convert(t, l));
                    Ok((info, trees.collect()))
                }
                Model::Parts(..) => Err(corrupt("it changed while it was read".to_owned())),
            };
        }
        Err(e) => return Err(e),
    };
    // Second pass: the tree section, decompressed and decoded as it streams.
    file.seek(std::io::SeekFrom::Start(start as u64)).map_err(io)?;
    let limit = head
        .get(start..)
        .and_then(|frame| declared_size(frame, len))
        .unwrap_or(MAX_TREES_BYTES);
    let unreadable = |e: std::io::Error| corrupt(format!("its trees do not decompress: {e}"));
    let inner = zstd::stream::read::Decoder::new(file.take(len as u64)).map_err(unreadable)?;
    let trees = decode_streamed(inner, limit, version, convert).map_err(corrupt);
    Ok((info, trees?))
}

/// The error of reading the model file at `path`.
fn read_error(path: &Path) -> impl Fn(std::io::Error) -> ModelError + Copy + '_ {
    move |source| ModelError::Io {
        path: path.to_owned(),
        action: "read",
        source,
    }
}

/// What the first pass over a model file found.
struct Scan {
    /// The file's first bytes (at most [`HEAD_BYTES`]): its header.
    head: Vec<u8>,
    /// The bytes left out of the checksum: the file's last four (fewer in a shorter file).
    held: Vec<u8>,
    total: usize,
    /// The checksum of every byte before `held`.
    crc: u32,
}

/// First pass: the checksum as the file streams by, and its first bytes (the header).
fn scan(file: &mut std::fs::File, path: &Path) -> Result<Scan, ModelError> {
    use std::io::Read as _;
    let io = read_error(path);
    let mut hasher = crc32fast::Hasher::new();
    let (mut head, mut held, mut total) = (Vec::new(), Vec::with_capacity(8), 0usize);
    let mut chunk = vec![0u8; 1 << 20];
    loop {
        let n = match file.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(io(e)),
        };
        total += n;
        if total as u64 > MAX_MODEL_BYTES {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("it is larger than {MAX_MODEL_BYTES} bytes"),
            )));
        }
        let c = &chunk[..n];
        if head.len() < HEAD_BYTES {
            head.extend_from_slice(&c[..c.len().min(HEAD_BYTES - head.len())]);
        }
        // Every byte but the last four (the checksum) is hashed.
        held.extend_from_slice(c);
        let hashed = held.len().saturating_sub(4);
        if hashed > 0 {
            hasher.update(&held[..hashed]);
            held.drain(..hashed);
        }
    }
    Ok(Scan {
        head,
        held,
        total,
        crc: hasher.finalize(),
    })
}

/// Decodes a body forest's tree section from its decompressor `inner`, at most `limit`
/// bytes, handing each tree to `convert` as it ends. Decompressed on a thread of its own
/// while this one decodes what it has already: the two halves of the load overlap.
fn decode_streamed<T>(
    inner: impl std::io::Read + Send,
    limit: usize,
    version: u32,
    mut convert: impl FnMut(Tree<DepthFeature, ()>, SparseLeaves) -> T,
) -> Result<Vec<T>, String> {
    let (tx, rx) = std::sync::mpsc::sync_channel::<std::io::Result<Vec<u8>>>(4);
    let (back, spare) = std::sync::mpsc::channel::<Vec<u8>>();
    std::thread::scope(|scope| {
        scope.spawn(move || decompress_chunks(inner, &tx, &spare));
        let mut r = Stream::new(
            Chunks {
                rx,
                back,
                chunk: Vec::new(),
                pos: 0,
            },
            limit,
        );
        // Each leaf goes straight into the tree's run-time form, taken as the tree ends.
        let leaves = std::cell::RefCell::new(SparseLeaves::default());
        let leaf = |r: &mut Stream<Chunks>| body_leaf_record(r, version, &mut leaves.borrow_mut());
        let trees = decode_trees(&mut r, 2, leaf, |tree| convert(tree, leaves.take()));
        // Dropping the receiver ends the decompressing thread at its next chunk.
        drop(r);
        trees
    })
}

/// The decompressing thread's loop: chunks of 256 KiB, at most 4 ahead (`tx` is bounded);
/// each chunk read comes back (`spare`) to be filled again, so the section is not written
/// into fresh pages (the page faults of a new chunk each time cost as much as the
/// decompression).
fn decompress_chunks(
    mut inner: impl std::io::Read,
    tx: &std::sync::mpsc::SyncSender<std::io::Result<Vec<u8>>>,
    spare: &std::sync::mpsc::Receiver<Vec<u8>>,
) {
    const CHUNK: usize = 1 << 18;
    loop {
        let mut chunk = spare.try_recv().unwrap_or_default();
        chunk.resize(CHUNK, 0);
        let mut filled = 0;
        let result = loop {
            match inner.read(&mut chunk[filled..]) {
                Ok(0) => break Ok(()),
                Ok(k) => {
                    filled += k;
                    if filled == chunk.len() {
                        break Ok(());
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => break Err(e),
            }
        };
        chunk.truncate(filled);
        let done = filled == 0 || result.is_err();
        let message = match result {
            Ok(()) if filled == 0 => break,
            Ok(()) => Ok(chunk),
            Err(e) => Err(e),
        };
        // The reader stopped (an error found in what it has): nothing more is wanted.
        if tx.send(message).is_err() || done {
            break;
        }
    }
}

/// A body tree of the training form in the form [`load_body_trees`] hands on: its nodes, and
/// its leaves as run time reads them.
fn run_form(tree: Tree<DepthFeature, JointLeaf>) -> (Tree<DepthFeature, ()>, SparseLeaves) {
    let leaves = SparseLeaves::from_leaves(&tree.leaves);
    let nodes = Tree {
        nodes: tree.nodes,
        leaves: vec![(); tree.leaves.len()],
    };
    (nodes, leaves)
}

/// The decompressed chunks another thread sends, read in order, each sent back once read.
struct Chunks {
    rx: std::sync::mpsc::Receiver<std::io::Result<Vec<u8>>>,
    back: std::sync::mpsc::Sender<Vec<u8>>,
    chunk: Vec<u8>,
    pos: usize,
}

impl std::io::Read for Chunks {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        while self.pos == self.chunk.len() {
            match self.rx.recv() {
                Ok(chunk) => {
                    let read = std::mem::replace(&mut self.chunk, chunk?);
                    // The decompressing thread may have ended: the chunk is then dropped.
                    let _ = self.back.send(read);
                    self.pos = 0;
                }
                // The sender is done: the end of the section.
                Err(_) => return Ok(0),
            }
        }
        let n = out.len().min(self.chunk.len() - self.pos);
        out[..n].copy_from_slice(&self.chunk[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

/// The first bytes of a model file [`load_body_trees`] keeps for its header (the description
/// of the bundled forests is about 2 kB).
const HEAD_BYTES: usize = 1 << 16;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vision::forest::NOT_LEAF;

    fn bundled() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models/body.forest")
    }

    /// A body model file with `raw` as its (decompressed) tree section, compressed by
    /// `compress`, under the bundled forest's description.
    fn with_section(raw: &[u8], compress: impl Fn(&[u8]) -> Vec<u8>) -> Vec<u8> {
        let bytes = std::fs::read(bundled()).unwrap_or_default();
        let (_, _, info, _) = header(&bytes, &bundled(), None).unwrap_or_else(|e| panic!("{e}"));
        let description = serde_json::to_vec(&info).unwrap_or_default();
        framed(ModelKind::Body, &description, &compress(raw))
    }

    fn bulk(raw: &[u8]) -> Vec<u8> {
        zstd::bulk::compress(raw, 3).unwrap_or_default()
    }

    /// A zstd frame that does not declare its size (a streaming encoder's).
    fn streamed(raw: &[u8]) -> Vec<u8> {
        use std::io::Write as _;
        let mut e = zstd::stream::write::Encoder::new(Vec::new(), 3).unwrap_or_else(|e| panic!("{e}"));
        e.write_all(raw).unwrap_or_else(|e| panic!("{e}"));
        e.finish().unwrap_or_default()
    }

    type Trees = Result<Vec<(Tree<DepthFeature, ()>, SparseLeaves)>, String>;
    type Compress = fn(&[u8]) -> Vec<u8>;

    /// Both readings of a file: in memory ([`load`]) and streamed ([`load_body_trees`]).
    fn both(bytes: &[u8]) -> (Trees, Trees) {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("body.forest");
        std::fs::write(&path, bytes).unwrap_or_else(|e| panic!("{e}"));
        let loaded = match load(&path, Some(ModelKind::Body)) {
            Ok(Model::Body(_, f)) => Ok(f.trees),
            Ok(Model::Parts(..)) => Err("parts".to_owned()),
            Err(e) => Err(e.to_string()),
        };
        let streamed = load_body_trees(&path, |t, l| (t, l))
            .map(|(_, t)| t)
            .map_err(|e| e.to_string());
        (loaded.map(|trees| trees.into_iter().map(run_form).collect()), streamed)
    }

    /// A tree section: `trees` trees of three nodes (a split and two leaves) with two leaves
    /// voting for joints 1 and 3.
    fn section(trees: u32) -> Vec<u8> {
        let mut raw = Vec::new();
        put_u32(&mut raw, trees);
        for t in 0..trees {
            put_u32(&mut raw, 3);
            for (f, left, leaf) in [(t as f32, 1, NOT_LEAF), (0.0, 0, 0), (0.0, 0, 1)] {
                put_f32(&mut raw, f);
                put_f32(&mut raw, -f);
                put_f32(&mut raw, 0.5);
                put_u32(&mut raw, left);
                put_u32(&mut raw, leaf);
            }
            put_u32(&mut raw, 2);
            for k in 0..2u16 {
                raw.extend_from_slice(&0b101u16.to_le_bytes());
                for _ in 0..2 {
                    for v in [10i16, -20, 30 + k as i16] {
                        raw.extend_from_slice(&v.to_le_bytes());
                    }
                    raw.extend_from_slice(&40000u16.to_le_bytes());
                    raw.extend_from_slice(&12u16.to_le_bytes());
                }
            }
        }
        raw
    }

    #[test]
    fn the_bundled_body_forest_streams_to_the_trees_it_loads_to() {
        let Ok(Model::Body(_, forest)) = load(&bundled(), Some(ModelKind::Body)) else {
            panic!("the bundled body forest loads")
        };
        let (_, streamed) = load_body_trees(&bundled(), |t, l| (t, l)).unwrap_or_else(|e| panic!("{e}"));
        let loaded: Vec<_> = forest.trees.into_iter().map(run_form).collect();
        assert!(streamed == loaded, "the streamed trees differ");
    }

    #[test]
    fn streamed_and_in_memory_reading_agree_on_good_and_damaged_sections() {
        let good = section(2);
        for compress in [bulk as Compress, streamed] {
            let (a, b) = both(&with_section(&good, compress));
            let a = a.unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(a.len(), 2);
            assert!(Ok(a) == b, "streamed reading differs");
        }
        let mut trailing = good.clone();
        trailing.push(0);
        let mut too_many_nodes = good.clone();
        too_many_nodes[4..8].copy_from_slice(&1_000_000u32.to_le_bytes());
        let mut bad_mask = good.clone();
        // The first leaf's mask, after the count, three nodes and the leaf count.
        bad_mask[4 + 4 + 60 + 4] = 0xff;
        bad_mask[4 + 4 + 60 + 5] = 0xff;
        let cases: [(&str, Vec<u8>); 5] = [
            ("bytes after its last tree", trailing),
            ("ends inside the", good[..good.len() - 3].to_vec()),
            ("do not fit", too_many_nodes),
            ("no trees", section(0)),
            ("do not exist", bad_mask),
        ];
        // Damage to the file itself: the same error either way.
        let file = with_section(&good, bulk);
        let mut damaged: Vec<Vec<u8>> = [0, 7, 8, 12, 20, 40, file.len() / 2, file.len() - 1]
            .iter()
            .map(|&cut| file[..cut].to_vec())
            .collect();
        for at in [9, 14, 30, file.len() / 2, file.len() - 2] {
            let mut b = file.clone();
            b[at] ^= 0x40;
            damaged.push(b);
        }
        for b in damaged {
            let (a, b) = both(&b);
            assert!(a.is_err());
            assert_eq!(a.err(), b.err());
        }
        let compressors: [(Compress, bool); 2] = [(bulk, true), (streamed, false)];
        for (expected, raw) in cases {
            for (compress, declares_size) in compressors {
                let (a, b) = both(&with_section(&raw, compress));
                let a = a.err().unwrap_or_default();
                assert!(a.contains(expected), "{expected}: {a}");
                // Without a declared size the streamed reading only finds the end by reaching
                // it: refused all the same, for what it read as nodes past the real ones.
                if expected == "do not fit" && !declares_size {
                    assert!(b.is_err(), "{expected}: read");
                } else {
                    assert_eq!(Some(a), b.err());
                }
            }
        }
    }
}
