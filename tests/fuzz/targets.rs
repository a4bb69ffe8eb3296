//! The fuzz targets: for each file format mousepose reads, seed inputs made by its own
//! writers (or, for formats it only reads, written as the recorders that make them do), and
//! a run that writes an input's files and reads them with the real reader, checking that
//! what it returns holds up.
//!
//! Checksummed formats would refuse nearly every mutated input at the checksum; their inputs
//! carry an `@mode` part whose bits ask the run to set the checksums right first (and the
//! forest's inputs keep the tree section uncompressed, assembled into a file by the run), so
//! the mutations reach the code behind the checksum too.

use super::{Input, Outcome, Target, outcome_of};
use mousepose::core::frame::{ColorFrame, DepthFrame, PixelFormat, Stamp};
use mousepose::core::geometry::Rig;
use mousepose::core::image::Region;
use mousepose::io::session::{
    BackendName, CameraMeta, CameraRole, FrameFormat, SessionEvent, SessionMeta, SessionReader, SessionSource,
    SessionWriter,
};
use mousepose::io::store::{self, Kind, RecordReader, RecordWriter};
use mousepose::runtime::capture::{Clock, FrameSource};
use mousepose::runtime::config::Config;
use mousepose::runtime::recording::moseq::{MoseqConfig, MoseqDepth};
use mousepose::runtime::recording::session::SessionPlayer;
use mousepose::vision::calibrate::{Board, IntrinsicsCalibration, RigCalibration, load_intrinsics};
use mousepose::vision::forest::depth::{BODY_JOINTS, DepthImage, JointLeaf, JointVote};
use mousepose::vision::forest::infer::{BodyEstimator, Pixel, VoteSettings};
use mousepose::vision::forest::model::{self, Model, ModelInfo, ModelKind};
use mousepose::vision::forest::{Forest, NOT_LEAF, Node, Tree};
use mousepose::vision::paws::cascade::{BoostStage, Cascade, CascadeParams, WeakTree};
use mousepose::vision::paws::detect::scan_like_opencv;
use mousepose::vision::paws::grey::GreyImage;
use mousepose::vision::paws::haar::{HaarFeature, HaarRect};
use mousepose::vision::paws::xml;
use nalgebra::Point3;
use std::path::Path;
use std::time::Duration;

pub static ALL: [Target; 7] = [
    Target {
        name: "store",
        seeds: store_seeds,
        run: store_run,
        words: &["MPRC", "MPSTORE\0", "MPINDEX\0"],
    },
    Target {
        name: "session",
        seeds: session_seeds,
        run: session_run,
        words: &["depth16", "bayer_rg8", "rgb8", "mono8", "null", "session_ended"],
    },
    Target {
        name: "moseq",
        seeds: moseq_seeds,
        run: moseq_run,
        words: &[
            "DepthResolution",
            "\n",
            " ",
            "\t",
            ".",
            "e",
            "+",
            "1e",
            "[",
            "]",
            "null",
        ],
    },
    Target {
        name: "forest",
        seeds: forest_seeds,
        run: forest_run,
        words: &["MPFOREST", "\u{0}\u{0}\u{0}\u{0}", "null", "body", "parts"],
    },
    Target {
        name: "cascade",
        seeds: cascade_seeds,
        run: cascade_run,
        words: &[
            "<_>",
            "</_>",
            "<!--",
            "-->",
            "<![CDATA[",
            "]]>",
            "&amp;",
            "&#x10FFFF;",
            "<!DOCTYPE a [<!ENTITY e \"x\">]>",
        ],
    },
    Target {
        name: "calibration",
        seeds: calibration_seeds,
        run: calibration_run,
        words: &[
            "!!opencv-matrix",
            "%YAML:1.0",
            "---",
            "rows",
            "cols",
            "dt",
            "data",
            "d",
            "f",
            "i",
            "u",
            "&a",
            "*a",
            "!!",
            "[",
            "]",
            "{",
            "}",
            "\n  ",
            "- ",
        ],
    },
    Target {
        name: "config",
        seeds: config_seeds,
        run: config_run,
        words: &[
            "[depth]", "[color]", "[sync]", "[[", "]]", "\"\"\"", "'''", "inf", "nan", "\n",
        ],
    },
];

fn bucket(n: u64) -> u32 {
    64 - n.leading_zeros()
}

fn files(input: &Input, dir: &Path) {
    input.write_files(dir).expect("writes the input's files");
}

// ---- the record store ---------------------------------------------------------------------

fn payload(i: usize, len: usize) -> Vec<u8> {
    (0..len).map(|j| (i * 31 + j * 7) as u8).collect()
}

fn store_seeds(scratch: &Path) -> Vec<Input> {
    [
        (Kind::DepthFrames, 1u8),
        (Kind::ColorFrames, 3),
        (Kind::DatasetSamples, 0),
    ]
    .into_iter()
    .enumerate()
    .map(|(k, (kind, mode))| {
        let dir = scratch.join(k.to_string());
        std::fs::create_dir_all(&dir).expect("seed directory");
        let path = dir.join("frames.mpstore");
        let mut w = RecordWriter::create(&path, kind).expect("record file");
        let mut entries = Vec::new();
        for (i, len) in [0usize, 1, 40, 300, 17, 70].into_iter().enumerate() {
            let mut p = payload(i, len);
            if p.len() >= 8 {
                p[..8].copy_from_slice(&(i as u64 + 100).to_le_bytes());
            }
            entries.push((i as u64 + 100, w.append(&p).expect("record")));
        }
        w.sync().expect("sync");
        let len = std::fs::metadata(&path).expect("record file").len();
        store::write_index(dir.join("index.mpindex"), len, &entries).expect("index");
        Input {
            parts: vec![
                ("@mode".to_owned(), vec![mode]),
                ("frames.mpstore".to_owned(), std::fs::read(&path).expect("record file")),
                (
                    "index.mpindex".to_owned(),
                    std::fs::read(dir.join("index.mpindex")).expect("index"),
                ),
            ],
        }
    })
    .collect()
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    b.get(at..at + 4)
        .map_or(0, |s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

/// Sets every record's checksums right (and its length, when it runs past the end), walking
/// the records by their lengths.
fn repair_records(b: &mut [u8]) {
    let mut pos = 16usize;
    while pos + 16 <= b.len() {
        if &b[pos..pos + 4] != b"MPRC" {
            return;
        }
        let len = (le_u32(b, pos + 4) as usize).min(b.len() - pos - 16);
        b[pos + 4..pos + 8].copy_from_slice(&(len as u32).to_le_bytes());
        let crc = crc32fast::hash(&b[pos + 16..pos + 16 + len]);
        b[pos + 8..pos + 12].copy_from_slice(&crc.to_le_bytes());
        let header_crc = crc32fast::hash(&b[pos..pos + 12]);
        b[pos + 12..pos + 16].copy_from_slice(&header_crc.to_le_bytes());
        pos += 16 + len;
    }
}

/// Sets an index file's entry count (when `count` is set) and checksum right.
fn repair_index(b: &mut Vec<u8>, count: bool) {
    if b.len() < 28 {
        return;
    }
    if count {
        let n = (b.len() - 28) / 16;
        b.truncate(28 + 16 * n);
        b[12..16].copy_from_slice(&(n as u32).to_le_bytes());
    }
    let end = b.len() - 4;
    let crc = crc32fast::hash(&b[..end]);
    b[end..].copy_from_slice(&crc.to_le_bytes());
}

/// The input with its checksums set right as its `@mode` asks: bit 0 the records of every
/// record file, bit 1 every index's checksum, bit 2 its entry count too.
fn repaired(input: &Input) -> Input {
    let mode = input.part("@mode").first().copied().unwrap_or(0);
    let mut input = input.clone();
    for (name, bytes) in &mut input.parts {
        if name.ends_with(".mpstore") && mode & 1 != 0 {
            repair_records(bytes);
        }
        if name.ends_with(".mpindex") && mode & 2 != 0 {
            repair_index(bytes, mode & 4 != 0);
        }
    }
    input
}

fn peek_key(p: &[u8]) -> Option<u64> {
    p.get(..8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
}

fn store_run(input: &Input, dir: &Path) -> Outcome {
    let input = repaired(input);
    files(&input, dir);
    let path = dir.join("frames.mpstore");
    let file_len = input.part("frames.mpstore").len() as u64;
    let mut outcome = String::new();
    for kind in [Kind::DepthFrames, Kind::ColorFrames, Kind::DatasetSamples] {
        let mut r = match RecordReader::open(&path, kind) {
            Ok(r) => r,
            Err(e) => {
                outcome = outcome_of(&e, dir);
                continue;
            }
        };
        let mut records = Vec::new();
        for record in r.records() {
            match record {
                Ok(record) => records.push(record),
                Err(e) => return Ok(outcome_of(&e, dir)),
            }
        }
        let damage = r.damage().clone();
        // Every byte after the file header is in a record, a stretch stepped over, or the tail.
        let in_records: u64 = records.iter().map(|x| 16 + x.payload.len() as u64).sum();
        let accounted = in_records + damage.skipped_bytes() + damage.truncated_tail_bytes;
        if accounted != file_len - 16 {
            return Err(format!(
                "{accounted} bytes accounted for in a file of {file_len} ({} records, {damage:?})",
                records.len()
            ));
        }
        if records.windows(2).any(|w| w[0].offset >= w[1].offset) {
            return Err("records out of file order".to_owned());
        }
        for x in &records {
            match r.read_at(x.offset) {
                Ok(p) if p == x.payload => {}
                other => return Err(format!("the record at {} reads back as {other:?}", x.offset)),
            }
        }
        let (entries, status) = match r.load_index(dir.join("index.mpindex"), peek_key) {
            Ok(loaded) => loaded,
            Err(e) => return Ok(outcome_of(&e, dir)),
        };
        if status.rebuilt() {
            let want: Vec<(u64, u64)> = records
                .iter()
                .filter_map(|x| peek_key(&x.payload).map(|k| (k, x.offset)))
                .collect();
            if entries != want {
                return Err(format!("rebuilt index {entries:?} is not the records' {want:?}"));
            }
        }
        // Offsets from a loaded index are the file's word: each one reads or is refused.
        let readable = entries.iter().take(5000).filter(|e| r.read_at(e.1).is_ok()).count();
        return Ok(format!(
            "ok: {kind} records~{} skipped~{} tail~{} index {} readable~{}",
            bucket(records.len() as u64),
            bucket(damage.skipped_records()),
            bucket(damage.truncated_tail_bytes),
            if status.rebuilt() { "rebuilt" } else { "loaded" },
            bucket(readable as u64)
        ));
    }
    Ok(outcome)
}

// ---- sessions -----------------------------------------------------------------------------

const SESSION_W: u32 = 16;
const SESSION_H: u32 = 12;

fn stamp(seq: u64, base_ns: u64) -> Stamp {
    Stamp {
        seq,
        device_ns: base_ns + seq * 33_333_333,
        host_ns: 1_000_000_000 + seq * 33_366_000 + base_ns / 7,
    }
}

fn camera(role: CameraRole, pixel_format: FrameFormat) -> CameraMeta {
    CameraMeta {
        role,
        backend: BackendName::SYNTHETIC,
        model: format!("synthetic {role}"),
        serial: format!("SYN-{role}"),
        firmware: String::new(),
        width: SESSION_W,
        height: SESSION_H,
        pixel_format,
        fps: 30.0,
    }
}

/// A small session written by the session writer: five depth frames and (with `color`) five
/// Bayer colour frames, events and ground truth.
fn write_session(dir: &Path, color: bool, finish: bool) {
    std::fs::create_dir_all(dir).expect("session directory");
    let mut cameras = vec![camera(CameraRole::Depth, FrameFormat::Depth16)];
    if color {
        cameras.push(camera(CameraRole::Color, FrameFormat::Color(PixelFormat::BayerRg8)));
    }
    let mut meta = SessionMeta::new("2026-11-24T09:00:00Z", SessionSource::Synthetic, cameras);
    meta.rig = Some(Rig::default_rig());
    let mut w = SessionWriter::create(dir, &meta).expect("session");
    w.log_event(&SessionEvent::Note {
        host_ns: 5,
        message: "fuzz seed".into(),
    })
    .expect("event");
    let n = (SESSION_W * SESSION_H) as usize;
    for seq in 0..5u64 {
        let data = (0..n).map(|i| 500 + ((i as u64 * 7 + seq * 3) % 40) as u16).collect();
        w.write_depth(&DepthFrame {
            stamp: stamp(seq, 5_000),
            width: SESSION_W,
            height: SESSION_H,
            data,
        })
        .expect("depth frame");
        let joints = std::array::from_fn(|j| Point3::new(j as f64, seq as f64, 12.5));
        w.write_truth(seq, stamp(seq, 5_000).device_ns, &joints).expect("truth");
        w.write_truth_pair(seq, (seq != 3).then_some(seq)).expect("truth pair");
        if color {
            let data = (0..n).map(|i| ((i as u64 * 13 + seq) % 256) as u8).collect();
            w.write_color(&ColorFrame {
                stamp: stamp(seq, 900),
                width: SESSION_W,
                height: SESSION_H,
                format: PixelFormat::BayerRg8,
                data,
            })
            .expect("colour frame");
        }
    }
    if finish {
        w.finish().expect("finished session");
    }
}

fn session_seeds(scratch: &Path) -> Vec<Input> {
    [(true, true, 3u8), (false, true, 7), (true, false, 1)]
        .into_iter()
        .enumerate()
        .map(|(k, (color, finish, mode))| {
            let dir = scratch.join(k.to_string());
            write_session(&dir, color, finish);
            let mut input = Input::load(&dir).expect("seed session");
            input.parts.push(("@mode".to_owned(), vec![mode]));
            input
        })
        .collect()
}

fn session_run(input: &Input, dir: &Path) -> Outcome {
    let input = repaired(input);
    files(&input, dir);
    let r = match SessionReader::open(dir) {
        Ok(r) => r,
        Err(e) => return Ok(outcome_of(&e, dir)),
    };
    let mut outcome = Vec::new();
    // Sequential reads, then every frame by position through the index.
    let mut frames = r.depth_frames();
    let (mut good, mut bad) = (0u64, 0u64);
    for f in frames.by_ref().take(5000) {
        match f {
            Ok(f) if f.data.len() == f.width as usize * f.height as usize => good += 1,
            Ok(f) => {
                return Err(format!(
                    "a {}x{} depth frame of {} samples",
                    f.width,
                    f.height,
                    f.data.len()
                ));
            }
            Err(e) => {
                bad += 1;
                outcome.push(outcome_of(&e, dir));
            }
        }
    }
    outcome.push(format!("depth ok~{} bad~{}", bucket(good), bucket(bad)));
    if let Some(frames) = r.color_frames() {
        let (mut good, mut bad) = (0u64, 0u64);
        for f in frames.take(5000) {
            match f {
                Ok(f) if f.data.len() == ColorFrame::expected_len(f.width, f.height, f.format) => good += 1,
                Ok(f) => {
                    return Err(format!(
                        "a {}x{} {:?} colour frame of {} bytes",
                        f.width,
                        f.height,
                        f.format,
                        f.data.len()
                    ));
                }
                Err(e) => {
                    bad += 1;
                    outcome.push(outcome_of(&e, dir));
                }
            }
        }
        outcome.push(format!("colour ok~{} bad~{}", bucket(good), bucket(bad)));
    }
    for i in 0..r.depth_count().min(2000) {
        match r.depth_frame(i) {
            Ok(f) if f.data.len() != f.width as usize * f.height as usize => {
                return Err(format!(
                    "depth frame {i} is {}x{} with {} samples",
                    f.width,
                    f.height,
                    f.data.len()
                ));
            }
            Ok(_) => {}
            Err(e) => outcome.push(outcome_of(&e, dir)),
        }
    }
    for i in 0..r.color_count().min(2000) {
        match r.color_frame(i) {
            Ok(f) if f.data.len() != ColorFrame::expected_len(f.width, f.height, f.format) => {
                return Err(format!(
                    "colour frame {i} is {}x{} with {} bytes",
                    f.width,
                    f.height,
                    f.data.len()
                ));
            }
            Ok(_) => {}
            Err(e) => outcome.push(outcome_of(&e, dir)),
        }
    }
    for role in [CameraRole::Depth, CameraRole::Color] {
        if let Err(e) = r.timestamps(role) {
            outcome.push(outcome_of(&e, dir));
        }
    }
    match r.events() {
        Ok(events) => outcome.push(format!("events~{}", bucket(events.len() as u64))),
        Err(e) => outcome.push(outcome_of(&e, dir)),
    }
    match r.truth() {
        Ok(Some(truth)) => outcome.push(format!("truth~{}", bucket(truth.joints.len() as u64))),
        Ok(None) => {}
        Err(e) => outcome.push(outcome_of(&e, dir)),
    }
    if let Err(e) = r.verify() {
        outcome.push(outcome_of(&e, dir));
    }
    // What replay reads: both cameras merged by arrival.
    let mut player = SessionPlayer::new(&r, false);
    let clock = Clock::replay(0);
    match player.start(&clock) {
        Ok(()) => {
            let mut delivered = 0u64;
            loop {
                match player.next_frame(Duration::ZERO) {
                    Ok(Some(_)) => delivered += 1,
                    Ok(None) if player.finished() => break,
                    Ok(None) => return Err("the session player gave no frame but is not finished".to_owned()),
                    Err(e) => {
                        outcome.push(outcome_of(&e, dir));
                        break;
                    }
                }
                if delivered > 20_000 {
                    return Err("the session player does not end".to_owned());
                }
            }
            outcome.push(format!(
                "played~{} losses {:?}",
                bucket(delivered),
                player.losses().iter().map(|l| bucket(l.1)).collect::<Vec<_>>()
            ));
        }
        Err(e) => outcome.push(outcome_of(&e, dir)),
    }
    outcome.sort();
    outcome.dedup();
    Ok(format!("ok: {}", outcome.join("; ")))
}

// ---- MoSeq recordings ---------------------------------------------------------------------

fn moseq_seeds(_scratch: &Path) -> Vec<Input> {
    let (w, h, n) = (8usize, 6usize, 3usize);
    let dat: Vec<u8> = (0..w * h * n)
        .flat_map(|i| (600 + (i % 50) as u16).to_le_bytes())
        .collect();
    let meta = br#"{"DepthResolution": [8, 6], "SerialNumber": "000123", "IsLittleEndian": true}"#.to_vec();
    vec![
        Input {
            parts: vec![
                ("depth.dat".to_owned(), dat.clone()),
                ("depth_ts.txt".to_owned(), b"1000.0\n1033.3333\n1066.6667\n".to_vec()),
                ("metadata.json".to_owned(), meta.clone()),
            ],
        },
        Input {
            parts: vec![
                ("depth.dat".to_owned(), dat),
                (
                    "depth_ts.txt".to_owned(),
                    b"10 1700000000000.25\n43 1700000000033.5\n\n77 1700000000067\n".to_vec(),
                ),
                ("metadata.json".to_owned(), meta),
            ],
        },
    ]
}

fn moseq_run(input: &Input, dir: &Path) -> Outcome {
    files(input, dir);
    let mut source = match MoseqDepth::open(MoseqConfig::new(dir)) {
        Ok(s) => s,
        Err(e) => return Ok(outcome_of(&e, dir)),
    };
    let (w, h) = source.size();
    if let Err(e) = source.start(&Clock::replay(0)) {
        return Ok(outcome_of(&e, dir));
    }
    let mut frames = 0u64;
    let mut last_device_ns = 0;
    loop {
        match source.next_frame(Duration::ZERO) {
            Ok(Some(f)) => {
                if f.data.len() != w as usize * h as usize || (f.width, f.height) != (w, h) {
                    return Err(format!(
                        "a {}x{} frame of {} samples from a {w}x{h} recording",
                        f.width,
                        f.height,
                        f.data.len()
                    ));
                }
                if f.stamp.seq != frames || f.stamp.device_ns < last_device_ns {
                    return Err(format!("frame {frames} is stamped {:?}", f.stamp));
                }
                last_device_ns = f.stamp.device_ns;
                frames += 1;
            }
            Ok(None) => break,
            Err(e) => return Ok(outcome_of(&e, dir)),
        }
    }
    if frames as usize != source.frame_count() {
        return Err(format!("{frames} frames read of {}", source.frame_count()));
    }
    Ok(format!("ok: {frames}~{} frames", bucket(frames)))
}

// ---- forest models ------------------------------------------------------------------------

fn fixture_info() -> ModelInfo {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models/parts.forest");
    model::load(&path, None)
        .expect("the fixture part forest")
        .info()
        .clone()
}

/// A tree of one split and two leaves.
fn tiny_tree<L>(leaves: Vec<L>) -> Tree<[f32; 2], L> {
    let leaf = |i| Node {
        feature: [0.0, 0.0],
        threshold: 0.0,
        left: 0,
        leaf: i,
    };
    Tree {
        nodes: vec![
            Node {
                feature: [120.0, -40.0],
                threshold: 15.0,
                left: 1,
                leaf: NOT_LEAF,
            },
            leaf(0),
            leaf(1),
        ],
        leaves,
    }
}

fn vote_leaf(k: usize) -> JointLeaf {
    std::array::from_fn(|j| {
        if (j + k) % 3 == 0 {
            JointVote::default()
        } else {
            JointVote {
                offset: [j as f32, -(k as f32), 20.0],
                weight: 0.5,
                spread: 30.0,
            }
        }
    })
}

/// Splits an encoded model into its header (up to the tree section's length) and its
/// uncompressed trees, for inputs the run assembles.
fn split_model(bytes: &[u8]) -> Input {
    let desc_len = le_u32(bytes, 16) as usize;
    let at = 20 + desc_len;
    let len = u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes")) as usize;
    let trees = zstd::bulk::decompress(&bytes[at + 8..at + 8 + len], 64 << 20).expect("trees");
    Input {
        parts: vec![
            ("@header".to_owned(), bytes[..at].to_vec()),
            ("@trees".to_owned(), trees),
        ],
    }
}

fn forest_seeds(_scratch: &Path) -> Vec<Input> {
    let info = fixture_info();
    let body = Model::Body(
        ModelInfo {
            kind: ModelKind::Body,
            ..info.clone()
        },
        Forest {
            trees: vec![
                tiny_tree(vec![vote_leaf(0), vote_leaf(1)]),
                tiny_tree(vec![vote_leaf(2), vote_leaf(3)]),
            ],
        },
    );
    let parts = Model::Parts(
        info,
        Forest {
            trees: vec![tiny_tree(vec![
                vec![0.5, 0.1, 0.1, 0.1, 0.1, 0.1],
                vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            ])],
        },
    );
    let mut seeds = Vec::new();
    for m in [&body, &parts] {
        let bytes = model::encode(m).expect("encodes");
        seeds.push(split_model(&bytes));
        seeds.push(Input {
            parts: vec![("model.forest".to_owned(), bytes)],
        });
    }
    seeds
}

/// The model file of an input: assembled from its header and trees (compressed, checksummed)
/// or as it is.
fn model_file(input: &Input) -> Vec<u8> {
    if input.parts.iter().any(|p| p.0 == "model.forest") {
        return input.part("model.forest").to_vec();
    }
    let mut out = input.part("@header").to_vec();
    let trees = zstd::bulk::compress(input.part("@trees"), 1).expect("compresses");
    out.extend_from_slice(&(trees.len() as u64).to_le_bytes());
    out.extend_from_slice(&trees);
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// Whether samples with feature values from the far negative to the far positive all end in a
/// leaf that exists.
fn walkable<L>(t: &Tree<[f32; 2], L>) -> Result<(), String> {
    let values = [-1e9f32, -3.0, 0.0, 0.5, 14.9, 15.0, 1e9];
    for k in 0..values.len() {
        let mut salt = k;
        let leaf = t.leaf_index(|_| {
            salt += 1;
            values[salt % values.len()]
        });
        if leaf >= t.leaves.len() {
            return Err(format!(
                "a sample reached leaf {leaf} of {} ({} nodes)",
                t.leaves.len(),
                t.nodes.len()
            ));
        }
    }
    Ok(())
}

fn forest_run(input: &Input, dir: &Path) -> Outcome {
    std::fs::create_dir_all(dir).expect("work directory");
    let path = dir.join("model.forest");
    std::fs::write(&path, model_file(input)).expect("writes the model");
    let m = match model::load(&path, None) {
        Ok(m) => m,
        Err(e) => return Ok(outcome_of(&e, dir)),
    };
    match m {
        Model::Body(_, forest) => {
            forest.trees.iter().try_for_each(walkable)?;
            let trees = forest.trees.len();
            // The run-time traversal and voting, on a small image.
            let mut estimator = BodyEstimator::new(forest, VoteSettings::default())
                .map_err(|e| format!("a loaded forest refused at run time: {e}"))?;
            let region = Region {
                x0: 0,
                y0: 0,
                width: 16,
                height: 16,
            };
            let depth = (0..256).map(|i| 500.0 + (i % 16) as f32).collect();
            let image = DepthImage { region, depth };
            let pixels: Vec<Pixel> = (0..40)
                .map(|i| Pixel {
                    x: (i % 16) as f32,
                    y: (i / 3) as f32,
                    depth: 500.0 + i as f32,
                })
                .collect();
            let intrinsics = Rig::default_rig().depth.intrinsics;
            let guesses = estimator.estimate(&image, &pixels, &intrinsics);
            if guesses
                .iter()
                .flatten()
                .any(|g| !g.position_mm.iter().all(|c| c.is_finite()))
            {
                return Err("a joint estimate is not finite".to_owned());
            }
            Ok(format!(
                "ok: body trees~{} joints {}",
                bucket(trees as u64),
                guesses.iter().flatten().count().min(BODY_JOINTS)
            ))
        }
        Model::Parts(_, forest) => {
            forest.trees.iter().try_for_each(walkable)?;
            Ok(format!("ok: parts trees~{}", bucket(forest.trees.len() as u64)))
        }
    }
}

// ---- paw cascades -------------------------------------------------------------------------

fn tiny_cascade() -> Cascade {
    let rect = |x, y, width, height, weight| HaarRect {
        x,
        y,
        width,
        height,
        weight,
    };
    Cascade {
        width: 6,
        height: 5,
        min_neighbors: None,
        params: CascadeParams::default(),
        stages: vec![
            BoostStage {
                threshold: -0.5,
                weak: vec![
                    WeakTree::stump(0, 0.015, -1.0, 0.75),
                    WeakTree::stump(1, -0.3, 0.5, -0.25),
                ],
            },
            BoostStage {
                threshold: 0.1,
                weak: vec![WeakTree::stump(1, 1e-7, 0.1, -0.1)],
            },
        ],
        features: vec![
            HaarFeature {
                rects: vec![rect(0, 0, 6, 2, -1.0), rect(0, 1, 6, 1, 2.0)],
            },
            HaarFeature {
                rects: vec![rect(1, 1, 4, 4, -1.0), rect(1, 1, 2, 2, 2.0), rect(3, 3, 2, 2, 2.0)],
            },
        ],
    }
}

/// A stump cascade in OpenCV's older format (`opencv-haar-classifier`).
const OLD_FORMAT: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<paw type_id="opencv-haar-classifier">
  <size>6 5</size>
  <stages>
    <_>
      <trees>
        <_>
          <_>
            <feature>
              <rects>
                <_>0 0 6 2 -1.</_>
                <_>0 1 6 1 2.</_></rects>
              <tilted>0</tilted></feature>
            <threshold>0.015</threshold>
            <left_val>-1.</left_val>
            <right_val>0.75</right_val></_></_></trees>
      <stage_threshold>-0.5</stage_threshold>
      <parent>-1</parent>
      <next>-1</next></_></stages></paw>
</opencv_storage>
"#;

fn cascade_seeds(_scratch: &Path) -> Vec<Input> {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/models/paws.xml");
    [
        std::fs::read(fixture).expect("the fixture cascade"),
        xml::to_xml(&tiny_cascade()).into_bytes(),
        OLD_FORMAT.as_bytes().to_vec(),
    ]
    .into_iter()
    .map(|bytes| Input {
        parts: vec![("paws.xml".to_owned(), bytes)],
    })
    .collect()
}

fn cascade_run(input: &Input, dir: &Path) -> Outcome {
    files(input, dir);
    let c = match xml::load(&dir.join("paws.xml")) {
        Ok(c) => c,
        Err(e) => return Ok(outcome_of(&e, dir)),
    };
    // A loaded cascade runs: over an image a little larger than its window.
    let (width, height) = (c.width as usize + 5, c.height as usize + 4);
    let data = (0..width * height).map(|i| ((i * 37) % 251) as u8).collect();
    let grey = GreyImage { width, height, data };
    let mut found = Vec::new();
    scan_like_opencv(&c, &grey, &mut found);
    Ok(format!(
        "ok: stages~{} features~{} found~{}",
        bucket(c.stages.len() as u64),
        bucket(c.features.len() as u64),
        bucket(found.len() as u64)
    ))
}

// ---- calibration files --------------------------------------------------------------------

fn calibration_seeds(scratch: &Path) -> Vec<Input> {
    let rig = scratch.join("rig.yaml");
    RigCalibration::from_rig(&Rig::default_rig())
        .save(&rig)
        .expect("rig calibration");
    let intrinsics = scratch.join("intrinsics.yaml");
    IntrinsicsCalibration {
        intrinsics: Rig::default_rig().color.intrinsics,
        rms_px: 0.25,
        per_view_errors_px: vec![0.2, 0.3],
        views: vec!["a.png".into(), "b.png".into()],
        skipped: vec!["c.png".into()],
        board: Board::parse("9x6", 40.0).expect("board"),
    }
    .save(&intrinsics)
    .expect("intrinsics");
    vec![Input {
        parts: vec![
            ("rig.yaml".to_owned(), std::fs::read(rig).expect("rig calibration")),
            (
                "intrinsics.yaml".to_owned(),
                std::fs::read(intrinsics).expect("intrinsics"),
            ),
        ],
    }]
}

fn calibration_run(input: &Input, dir: &Path) -> Outcome {
    files(input, dir);
    let mut outcome = Vec::new();
    match RigCalibration::load(&dir.join("rig.yaml")) {
        Ok(cal) => {
            let rig = cal.rig();
            for cam in [&rig.depth, &rig.color] {
                let i = &cam.intrinsics;
                let numbers = [i.fx, i.fy, i.cx, i.cy].into_iter().chain(i.distortion);
                if !(numbers.into_iter().all(f64::is_finite) && i.fx > 0.0 && i.fy > 0.0 && i.width > 0 && i.height > 0)
                {
                    return Err(format!("loaded intrinsics {i:?}"));
                }
            }
            outcome.push("rig ok".to_owned());
        }
        Err(e) => outcome.push(outcome_of(&e, dir)),
    }
    match load_intrinsics(&dir.join("intrinsics.yaml")) {
        Ok(i) => {
            if !(i.fx.is_finite() && i.fx > 0.0 && i.fy.is_finite() && i.fy > 0.0 && i.width > 0 && i.height > 0) {
                return Err(format!("loaded intrinsics {i:?}"));
            }
            outcome.push("intrinsics ok".to_owned());
        }
        Err(e) => outcome.push(outcome_of(&e, dir)),
    }
    Ok(format!("ok: {}", outcome.join("; ")))
}

// ---- the rig config -----------------------------------------------------------------------

fn config_seeds(scratch: &Path) -> Vec<Input> {
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/rig.example.toml");
    let example = std::fs::read(example).expect("the example config");
    // A rig of one depth camera played from a session.
    let played = scratch.join("session");
    write_session(&played, false, true);
    let session = format!(
        "[depth]\nbackend = \"session\"\npath = {:?}\n\n[output]\ndir = {:?}\n",
        played.display().to_string(),
        scratch.join("out").display().to_string()
    )
    .into_bytes();
    [example, session]
        .into_iter()
        .map(|bytes| Input {
            parts: vec![("rig.toml".to_owned(), bytes)],
        })
        .collect()
}

fn config_run(input: &Input, dir: &Path) -> Outcome {
    files(input, dir);
    match Config::load(&dir.join("rig.toml")) {
        Ok(config) => Ok(format!("ok: colour {}", config.color.is_some())),
        Err(e) => Ok(outcome_of(&e, dir)),
    }
}
