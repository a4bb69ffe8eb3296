//! Training and test datasets: many independent rendered instants, each stored as the mouse's
//! region of the top depth image (not the empty cage) with its part labels, the 24 joints,
//! and optionally the bottom view around the mouse with the paws' boxes.
//!
//! A dataset is a directory with `dataset.toml` (what made it) and `samples.mpstore`, a record
//! file of zstd-compressed samples. `docs/FORMATS.md` describes both byte by byte.

use super::body::skin;
use super::mouse::{Behaviour, fit_in_cage, pose_library, pose_mouse};
use super::render::Cage;
use super::views::{BottomClutter, BottomView, Mark, MarkKind, PawBox, TopView, render_bottom_with, render_top};
use super::{ENGINE_VERSION, Mice, item_rng, jitter_pose, random_placement, varied_build};
use crate::core::geometry::Rig;
use crate::core::image::Region;
use crate::core::noise::DepthNoise;
use crate::core::pose::JointPositions;
use crate::core::skeleton::{JOINT_COUNT, Joint, SKELETON_VERSION};
use crate::io::store::{Kind, RecordReader, RecordWriter, StoreError};
use nalgebra::Point3;
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The dataset directory's metadata file.
pub const META_FILE: &str = "dataset.toml";
/// The dataset directory's sample store.
pub const SAMPLES_FILE: &str = "samples.mpstore";
/// Version of the sample layout.
pub const FORMAT_VERSION: u32 = 1;
const FORMAT_NAME: &str = "mousepose-dataset";
/// Pixels of floor kept around the mouse in the top crop.
pub const TOP_MARGIN_PX: u32 = 6;
/// Pixels kept around the mouse in the bottom crop.
pub const BOTTOM_MARGIN_PX: u32 = 12;
/// RNG stream of dataset images (sessions use others).
const STREAM: u64 = 1;

/// What made a dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetMeta {
    pub format: String,
    pub format_version: u32,
    pub software_version: String,
    pub engine_version: u32,
    pub skeleton_version: u32,
    pub count: u64,
    pub seed: u64,
    pub noise: DepthNoise,
    pub bottom_views: bool,
    /// Whether the bottom views show glare, marks on the glass and pale belly fur besides
    /// the paws (written only when they do; datasets without the key have none).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub bottom_clutter: bool,
    /// Which mice (datasets written before this key have the standard ones).
    #[serde(default)]
    pub mice: Mice,
    /// The build the mice were drawn around instead (`adapt`'s measured mice), when one was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build: Option<super::Build>,
    #[serde(with = "crate::io::session::meta::rig_repr")]
    pub rig: Option<Rig>,
}

/// What to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DatasetSpec {
    pub count: u64,
    pub seed: u64,
    pub noise: DepthNoise,
    pub bottom_views: bool,
    /// Glare, marks on the glass and pale belly fur in the bottom views (hard negatives for
    /// the paw detector).
    pub bottom_clutter: bool,
    pub mice: Mice,
    /// Mice drawn around this build ([`super::Build::around`]) instead of `mice`.
    pub build: Option<super::Build>,
}

/// One rendered instant.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub index: u64,
    /// Index of the pose in the pose library, and its behaviour.
    pub pose_id: u32,
    pub behaviour: Behaviour,
    /// The mouse's size factor.
    pub scale: f32,
    /// The 24 joints in the world frame, millimetres.
    pub joints: JointPositions,
    pub top: TopView,
    pub bottom: Option<BottomView>,
}

/// Errors reading or writing a dataset.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("cannot {action} {path:?}")]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("{path:?} is not a mousepose dataset: {reason}")]
    Format { path: PathBuf, reason: String },
    #[error("{path:?}: sample at byte {offset} is corrupt: {reason}")]
    Corrupt { path: PathBuf, offset: u64, reason: String },
}

/// Renders sample `index` of a dataset.
pub fn render_sample(rig: &Rig, spec: &DatasetSpec, library: &[super::mouse::PoseParams], index: u64) -> Sample {
    let mut rng = item_rng(spec.seed, STREAM, index);
    let pose_id = rng.gen_range(0..library.len());
    let mut params = jitter_pose(&library[pose_id], &mut rng);
    let placement = match (spec.build, spec.mice.of_item(index)) {
        (Some(build), _) => build.around(&mut rng),
        (None, Mice::Standard | Mice::Mixed) => random_placement(&mut rng),
        (None, Mice::Varied) => {
            let (placement, carriage) = varied_build(&mut rng);
            carriage.apply(&mut params);
            placement
        }
    };
    let mut m = pose_mouse(&params, &placement);
    fit_in_cage(&mut m, 3.0);
    let skin = skin(&m);
    let top = render_top(
        &rig.depth,
        &Cage::new(&rig.depth),
        &skin,
        None,
        TOP_MARGIN_PX,
        &spec.noise,
        &mut rng,
    );
    let clutter = if spec.bottom_clutter {
        BottomClutter::GlassAndBelly
    } else {
        BottomClutter::None
    };
    let bottom = spec
        .bottom_views
        .then(|| render_bottom_with(&rig.color, &m, &skin, BOTTOM_MARGIN_PX, clutter, &mut rng));
    Sample {
        index,
        pose_id: pose_id as u32,
        behaviour: params.behaviour,
        scale: placement.scale as f32,
        joints: m.joints,
        top,
        bottom,
    }
}

/// Writes a whole dataset into `dir` (which must exist and be empty), calling `progress`
/// with the number of samples written so far.
///
/// # Errors
/// When a file cannot be written.
pub fn write_dataset(
    dir: &Path,
    rig: &Rig,
    spec: &DatasetSpec,
    mut progress: impl FnMut(u64),
) -> Result<DatasetMeta, DatasetError> {
    let library = pose_library();
    let mut writer = RecordWriter::create(dir.join(SAMPLES_FILE), Kind::DatasetSamples)?;
    const CHUNK: u64 = 256;
    let mut start = 0;
    while start < spec.count {
        let end = (start + CHUNK).min(spec.count);
        let payloads: Vec<Vec<u8>> = (start..end)
            .into_par_iter()
            .map(|i| encode_sample(&render_sample(rig, spec, &library, i)))
            .collect();
        for p in &payloads {
            writer.append(p)?;
        }
        writer.flush()?;
        start = end;
        progress(end);
    }
    writer.sync()?;
    let meta = DatasetMeta {
        format: FORMAT_NAME.to_owned(),
        format_version: FORMAT_VERSION,
        software_version: env!("CARGO_PKG_VERSION").to_owned(),
        engine_version: ENGINE_VERSION,
        skeleton_version: SKELETON_VERSION,
        count: spec.count,
        seed: spec.seed,
        noise: spec.noise,
        bottom_views: spec.bottom_views,
        bottom_clutter: spec.bottom_views && spec.bottom_clutter,
        mice: spec.mice,
        build: spec.build,
        rig: Some(*rig),
    };
    let path = dir.join(META_FILE);
    let text = toml::to_string_pretty(&meta).map_err(|e| DatasetError::Format {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    std::fs::write(&path, text).map_err(|source| DatasetError::Io {
        path,
        action: "write",
        source,
    })?;
    Ok(meta)
}

// Sample payload: u32 uncompressed length, u32 reserved, then a zstd frame of the body below.
const BODY_PREFIX: usize = 8;
/// Largest body accepted when decoding (a 640x480 crop with a 1280x1024 RGB crop is far less).
const MAX_BODY: usize = 64 << 20;

fn put_region(out: &mut Vec<u8>, r: &Region) {
    for v in [r.x0, r.y0, r.width, r.height] {
        out.extend_from_slice(&(v as u16).to_le_bytes());
    }
}

/// Encodes a sample as a record payload (see `docs/FORMATS.md`).
pub fn encode_sample(s: &Sample) -> Vec<u8> {
    let mut body = Vec::with_capacity(64 + s.top.depth.len() * 3);
    body.extend_from_slice(&s.index.to_le_bytes());
    body.extend_from_slice(&s.pose_id.to_le_bytes());
    body.push(s.behaviour.code());
    body.push(u8::from(s.bottom.is_some()));
    let marks = s
        .bottom
        .as_ref()
        .map_or(0, |b| b.marks.len().min(usize::from(u16::MAX)));
    body.extend_from_slice(&(marks as u16).to_le_bytes());
    body.extend_from_slice(&s.scale.to_le_bytes());
    for p in &s.joints {
        for c in [p.x, p.y, p.z] {
            body.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    put_region(&mut body, &s.top.region);
    for d in &s.top.depth {
        body.extend_from_slice(&d.to_le_bytes());
    }
    body.extend_from_slice(&s.top.label);
    if let Some(b) = &s.bottom {
        put_region(&mut body, &b.region);
        body.extend_from_slice(&b.rgb);
        for paw in &b.paws {
            for v in [paw.x0, paw.y0, paw.x1, paw.y1] {
                body.extend_from_slice(&v.to_le_bytes());
            }
            body.push(u8::from(paw.contact));
            body.push(u8::from(paw.visible));
            body.extend_from_slice(&0u16.to_le_bytes());
        }
        for mark in b.marks.iter().take(marks) {
            for v in [mark.x0, mark.y0, mark.x1, mark.y1] {
                body.extend_from_slice(&v.to_le_bytes());
            }
            body.push(mark.kind.code());
            body.push(0);
            body.extend_from_slice(&0u16.to_le_bytes());
        }
    }
    let compressed = zstd::bulk::compress(&body, 3).unwrap_or_default();
    let mut out = Vec::with_capacity(BODY_PREFIX + compressed.len());
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&compressed);
    out
}

/// A little-endian reader over a byte slice that reports running out as an error.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| format!("ends early (needs {n} bytes at byte {})", self.at))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.array::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    fn f32(&mut self) -> Result<f32, String> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    fn region(&mut self) -> Result<Region, String> {
        Ok(Region {
            x0: u32::from(self.u16()?),
            y0: u32::from(self.u16()?),
            width: u32::from(self.u16()?),
            height: u32::from(self.u16()?),
        })
    }
}

/// Decodes a record payload written by [`encode_sample`].
///
/// # Errors
/// A sentence saying what is wrong when the payload is not a valid sample.
pub fn decode_sample(payload: &[u8]) -> Result<Sample, String> {
    let mut head = Cursor { bytes: payload, at: 0 };
    let len = head.u32()? as usize;
    head.u32()?;
    if len > MAX_BODY {
        return Err(format!("declares {len} bytes, more than a sample can hold"));
    }
    let body = zstd::bulk::decompress(&payload[BODY_PREFIX..], len).map_err(|e| format!("does not decompress: {e}"))?;
    if body.len() != len {
        return Err(format!("decompresses to {} bytes, expected {len}", body.len()));
    }
    let mut c = Cursor { bytes: &body, at: 0 };
    let index = c.u64()?;
    let pose_id = c.u32()?;
    let code = c.u8()?;
    let behaviour = Behaviour::ALL
        .into_iter()
        .find(|b| b.code() == code)
        .ok_or_else(|| format!("unknown behaviour code {code}"))?;
    let has_bottom = c.u8()? != 0;
    let mark_count = c.u16()?;
    let scale = c.f32()?;
    let mut joints = [Point3::origin(); JOINT_COUNT];
    for p in &mut joints {
        *p = Point3::new(f64::from(c.f32()?), f64::from(c.f32()?), f64::from(c.f32()?));
    }
    let region = c.region()?;
    let depth = crate::io::u16_samples(c.take(region.len() * 2)?);
    let label = c.take(region.len())?.to_vec();
    let top = TopView { region, depth, label };
    let bottom = if has_bottom {
        let region = c.region()?;
        let rgb = c.take(region.len() * 3)?.to_vec();
        let mut paws = [PawBox {
            joint: Joint::LeftForePaw,
            x0: 0.0,
            y0: 0.0,
            x1: 0.0,
            y1: 0.0,
            contact: false,
            visible: false,
        }; 4];
        for (paw, joint) in paws.iter_mut().zip(Joint::PAWS) {
            *paw = PawBox {
                joint,
                x0: c.f32()?,
                y0: c.f32()?,
                x1: c.f32()?,
                y1: c.f32()?,
                contact: c.u8()? != 0,
                visible: c.u8()? != 0,
            };
            c.u16()?;
        }
        let mut marks = Vec::with_capacity(usize::from(mark_count));
        for _ in 0..mark_count {
            let (x0, y0, x1, y1) = (c.f32()?, c.f32()?, c.f32()?, c.f32()?);
            let code = c.u8()?;
            let kind = MarkKind::from_code(code).ok_or_else(|| format!("unknown mark kind {code}"))?;
            c.u8()?;
            c.u16()?;
            marks.push(Mark { kind, x0, y0, x1, y1 });
        }
        Some(BottomView {
            region,
            rgb,
            paws,
            marks,
        })
    } else {
        None
    };
    if c.at != body.len() {
        return Err(format!("has {} unexpected trailing bytes", body.len() - c.at));
    }
    Ok(Sample {
        index,
        pose_id,
        behaviour,
        scale,
        joints,
        top,
        bottom,
    })
}

/// An open dataset.
#[derive(Debug)]
pub struct Dataset {
    pub dir: PathBuf,
    pub meta: DatasetMeta,
}

impl Dataset {
    /// Opens a dataset directory and checks its metadata.
    ///
    /// # Errors
    /// When `dataset.toml` is missing, unreadable, of another format or version.
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        let path = dir.join(META_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| DatasetError::Io {
            path: path.clone(),
            action: "read",
            source,
        })?;
        let format_error = |reason: String| DatasetError::Format {
            path: path.clone(),
            reason,
        };
        let meta: DatasetMeta = toml::from_str(&text).map_err(|e| format_error(e.message().to_owned()))?;
        if meta.format != FORMAT_NAME {
            return Err(format_error(format!("format is {:?}", meta.format)));
        }
        if meta.format_version != FORMAT_VERSION {
            return Err(format_error(format!(
                "format version {} is not supported (this build reads {FORMAT_VERSION})",
                meta.format_version
            )));
        }
        if meta.skeleton_version != SKELETON_VERSION {
            return Err(format_error(format!(
                "it uses skeleton version {}",
                meta.skeleton_version
            )));
        }
        Ok(Self {
            dir: dir.to_owned(),
            meta,
        })
    }

    /// Reads every sample in order, calling `f` on each.
    ///
    /// # Errors
    /// On a damaged store or sample, or when `f` fails.
    pub fn for_each(&self, mut f: impl FnMut(Sample) -> Result<(), DatasetError>) -> Result<(), DatasetError> {
        let path = self.dir.join(SAMPLES_FILE);
        let mut reader = RecordReader::open(&path, Kind::DatasetSamples)?;
        let mut seen = 0;
        while let Some(record) = reader.next_record() {
            let record = record?;
            let sample = decode_sample(&record.payload).map_err(|reason| DatasetError::Corrupt {
                path: path.clone(),
                offset: record.offset,
                reason,
            })?;
            seen += 1;
            f(sample)?;
        }
        if !reader.damage().is_clean() || seen != self.meta.count {
            return Err(DatasetError::Format {
                path,
                reason: format!(
                    "holds {seen} intact samples where {} were written ({} damaged records, {} bytes of truncated tail)",
                    self.meta.count,
                    reader.skipped_records(),
                    reader.tail()
                ),
            });
        }
        Ok(())
    }

    /// Reads all samples into memory.
    ///
    /// # Errors
    /// As [`Dataset::for_each`].
    pub fn load(&self) -> Result<Vec<Sample>, DatasetError> {
        let mut out = Vec::with_capacity(self.meta.count as usize);
        self.for_each(|s| {
            out.push(s);
            Ok(())
        })?;
        Ok(out)
    }
}
