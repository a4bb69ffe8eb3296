//! `mousepose export`: the MoSeq layout read back frame for frame and replayed to the same
//! poses, and the video's frame count and size as ffprobe sees them.
#![allow(clippy::unwrap_used)] // the helpers below are test code too

use crate::util::{mousepose, repo_root};
use mousepose::app::export::moseq::{COLOR_AVI, PROVENANCE_FILE, RIG_FILE, export_moseq};
use mousepose::app::replay::{ReplayOptions, replay};
use mousepose::io::session::SessionReader;
use mousepose::runtime::capture::moseq::{
    DEPTH_DAT, DEPTH_TS, METADATA, MoseqConfig, MoseqDepth, metadata_resolution, parse_timestamps,
};
use mousepose::runtime::capture::{Clock, FrameSource};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn fixture() -> PathBuf {
    repo_root().join("fixtures/sessions/synthetic-small")
}

fn replay_to(session: &Path, out: &Path, calibration: Option<PathBuf>) {
    replay(&ReplayOptions {
        calibration,
        ..crate::util::replay_options(session, out, 1)
    })
    .unwrap();
}

/// Every frame of a MoSeq recording, read by the reader `replay` uses.
fn moseq_frames(dir: &Path) -> Vec<mousepose::core::frame::DepthFrame> {
    let mut source = MoseqDepth::open(MoseqConfig::new(dir)).unwrap();
    source.start(&Clock::replay(0)).unwrap();
    let mut frames = Vec::new();
    while !source.finished() {
        if let Some(f) = source.next_frame(Duration::from_secs(10)).unwrap() {
            frames.push(f);
        }
    }
    source.stop().unwrap();
    frames
}

/// Nanoseconds as exact milliseconds.
fn ms(ns: u64) -> String {
    format!("{}.{:06}", ns / 1_000_000, ns % 1_000_000)
}

#[test]
fn moseq_export_is_lossless_and_replays_to_the_same_poses() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("moseq");
    let e = export_moseq(&fixture(), &out, Some("m1"), None, false, |_, _| {}).unwrap();
    let reader = SessionReader::open(fixture()).unwrap();
    assert_eq!(e.depth_frames as usize, reader.depth_count());
    assert_eq!(e.color_frames as usize, reader.color_count());
    assert_eq!(e.skipped_frames, 0);

    // Depth: the same millimetres and the same device and host times, frame for frame.
    let session_depth: Vec<_> = reader.depth_frames().map(Result::unwrap).collect();
    let exported = moseq_frames(&out);
    assert_eq!(exported.len(), session_depth.len());
    for (k, (a, b)) in exported.iter().zip(&session_depth).enumerate() {
        assert_eq!(a.stamp.seq, k as u64);
        assert_eq!(
            (a.stamp.device_ns, a.stamp.host_ns),
            (b.stamp.device_ns, b.stamp.host_ns)
        );
        assert_eq!((a.width, a.height), (b.width, b.height));
        assert!(a.data == b.data, "depth frame {k} differs");
    }
    // Colour: the recorded bytes (a Bayer mosaic) exactly, decoded by ffmpeg.
    let decoded = Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(out.join(COLOR_AVI))
        .args(["-f", "rawvideo", "-pix_fmt", "gray", "-"])
        .output()
        .unwrap();
    assert!(decoded.status.success());
    let recorded: Vec<u8> = reader.color_frames().unwrap().flat_map(|f| f.unwrap().data).collect();
    assert!(decoded.stdout == recorded, "colour frames differ");
    let color_ts = std::fs::read_to_string(out.join("color_ts.txt")).unwrap();
    assert_eq!(color_ts.lines().count(), reader.color_count());

    // metadata.json: MoSeq's keys, read by the project's own MoSeq reader too.
    assert_eq!(metadata_resolution(&out.join(METADATA)).unwrap(), Some((640, 480)));
    let meta: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join(METADATA)).unwrap()).unwrap();
    assert_eq!(meta["SubjectName"], "m1");
    assert_eq!(meta["SessionName"], "synthetic-small");
    assert_eq!(meta["IsLittleEndian"], true);
    assert_eq!(meta["DepthDataType"], "UInt16[]");
    assert_eq!(meta["ColorResolution"], serde_json::json!([320, 256]));
    // moseq2-extract stores each value as an HDF5 dataset: no objects, no nested lists.
    for (key, value) in meta.as_object().unwrap() {
        let flat = match value {
            serde_json::Value::Object(_) => false,
            serde_json::Value::Array(items) => items.iter().all(|v| !v.is_array() && !v.is_object()),
            _ => true,
        };
        assert!(flat, "metadata.json's {key} is not a string, a number or a flat list");
    }
    let provenance: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join(PROVENANCE_FILE)).unwrap()).unwrap();
    assert_eq!(provenance["software_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(provenance["depth_frames"], reader.depth_count());

    // The same frames written raw (depth.dat, the layout's uncompressed form) straight from
    // the session, with the session's own times: replayed with the session's calibration,
    // both give the very same poses.csv. (A replay of the session itself differs, and not
    // because of the export: a MoSeq recording's empty cage is the median of its frames, a
    // synthetic session's the rendered cage, so the mouse is segmented differently.)
    let raw = tmp.path().join("raw");
    std::fs::create_dir(&raw).unwrap();
    let bytes: Vec<u8> = session_depth
        .iter()
        .flat_map(|f| f.data.iter().flat_map(|d| d.to_le_bytes()))
        .collect();
    std::fs::write(raw.join(DEPTH_DAT), bytes).unwrap();
    let ts: String = session_depth
        .iter()
        .map(|f| format!("{} {}\n", ms(f.stamp.device_ns), ms(f.stamp.host_ns)))
        .collect();
    std::fs::write(raw.join(DEPTH_TS), &ts).unwrap();
    std::fs::copy(out.join(METADATA), raw.join(METADATA)).unwrap();
    let exported_ts = parse_timestamps(&std::fs::read_to_string(out.join(DEPTH_TS)).unwrap(), Path::new("x")).unwrap();
    for (a, f) in exported_ts.iter().zip(&session_depth) {
        assert_eq!((a.device_ns, a.system_ns), (f.stamp.device_ns, Some(f.stamp.host_ns)));
    }
    let (from_export, from_raw) = (tmp.path().join("r-export"), tmp.path().join("r-raw"));
    replay_to(&out, &from_export, Some(out.join(RIG_FILE)));
    replay_to(&raw, &from_raw, Some(out.join(RIG_FILE)));
    let a = std::fs::read_to_string(from_export.join("poses.csv")).unwrap();
    let b = std::fs::read_to_string(from_raw.join("poses.csv")).unwrap();
    assert_eq!(a.lines().count(), session_depth.len() + 1);
    assert!(a == b, "the exported depth replays to other poses");
    // Depth-only: joints 1-12 from the depth image, the rest missing.
    let row = a.lines().nth(15).unwrap();
    assert!(row.contains(",ok,"), "{row}");
    assert_eq!(row.matches(",depth").count(), 12, "{row}");
    assert_eq!(row.matches(",missing").count(), 12, "{row}");
}

#[test]
fn moseq_export_refuses_what_is_not_a_session() {
    let tmp = tempfile::tempdir().unwrap();
    let out = mousepose()
        .args(["export", "moseq"])
        .arg(tmp.path())
        .arg("--out")
        .arg(tmp.path().join("m"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("neither a session"), "{err}");
    assert!(!tmp.path().join("m").exists());
}

/// `nb_read_frames`, width and height of the video's first stream.
fn probe(path: &Path) -> (u64, u32, u32, String) {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
        .args([
            "-show_entries",
            "stream=nb_read_frames,width,height,codec_name",
            "-of",
            "json",
        ])
        .arg(path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let s = &v["streams"][0];
    (
        s["nb_read_frames"].as_str().unwrap().parse().unwrap(),
        s["width"].as_u64().unwrap() as u32,
        s["height"].as_u64().unwrap() as u32,
        s["codec_name"].as_str().unwrap().to_owned(),
    )
}

#[test]
fn video_export_has_a_frame_per_pose_row_and_the_window_asked_for() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&fixture(), &run, None);
    let rows = std::fs::read_to_string(run.join("poses.csv")).unwrap().lines().count() - 1;

    // The run's summary names its session: the video needs nothing else, from any directory.
    let video = tmp.path().join("all.mp4");
    let out = mousepose()
        .current_dir(tmp.path())
        .args(["export", "video", "run", "--out", "all.mp4"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (frames, width, height, codec) = probe(&video);
    assert_eq!(frames as usize, rows);
    assert_eq!(codec, "h264");
    // Depth panel, the widest bottom view and the side view; a line of counters on top.
    assert!(width >= 640 + 480 && width % 2 == 0, "{width}");
    assert!(height > 480 && height % 2 == 0, "{height}");
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains(&format!("{rows} frames of {width}x{height}")), "{said}");

    // --from/--to: the rows whose depth time (from the first frame) falls in [0.2, 0.6) s.
    let csv = std::fs::read_to_string(run.join("poses.csv")).unwrap();
    let times: Vec<u64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(4).unwrap().parse().unwrap())
        .collect();
    let expected = times
        .iter()
        .filter(|&&t| (0.2..0.6).contains(&((t - times[0]) as f64 / 1e9)))
        .count();
    assert!(expected > 5 && expected < rows, "{expected}");
    let part = tmp.path().join("part.mp4");
    let out = mousepose()
        .args(["export", "video"])
        .arg(&run)
        .args(["--from", "0.2", "--to", "0.6", "--out"])
        .arg(&part)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(probe(&part), (expected as u64, width, height, "h264".to_owned()));

    // An existing file is kept without --force; a window past the end is refused.
    let again = mousepose()
        .args(["export", "video"])
        .arg(&run)
        .arg("--out")
        .arg(&part)
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(1));
    let late = mousepose()
        .args(["export", "video"])
        .arg(&run)
        .args(["--from", "100", "--out"])
        .arg(tmp.path().join("late.mp4"))
        .output()
        .unwrap();
    assert_eq!(late.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&late.stderr).contains("no frame of the run"));
    assert!(!tmp.path().join("late.mp4").exists());
}

#[test]
fn nwb_export_reads_back_with_24_series_and_passes_nwbinspector() {
    let python = Path::new(mousepose::app::export::nwb::DEFAULT_PYTHON);
    assert!(python.is_file(), "{python:?} is missing: run scripts/setup.sh");
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&fixture(), &run, None);
    let rows = std::fs::read_to_string(run.join("poses.csv")).unwrap().lines().count() - 1;
    let nwb = tmp.path().join("run.nwb");
    let out = mousepose()
        .args(["export", "nwb"])
        .arg(&run)
        .arg("--out")
        .arg(&nwb)
        .args([
            "--subject-id",
            "m1",
            "--age",
            "P84D",
            "--experimenter",
            "Doe, Jane",
            "--institution",
            "Lab",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // Read back by pynwb; checked by nwbinspector.
    let check = r#"
import json, sys
import numpy as np
from pynwb import NWBHDF5IO
import ndx_pose
from nwbinspector import inspect_nwbfile, Importance
with NWBHDF5IO(sys.argv[1], "r") as io:
    f = io.read()
    pe = f.processing["behavior"]["PoseEstimation"]
    series = pe.pose_estimation_series
    first = next(iter(series.values()))
    out = {
        "series": len(series),
        "names": list(series.keys()),
        "shapes": sorted({tuple(s.data.shape) for s in series.values()}),
        "timestamps": len(first.timestamps),
        "increasing": bool(np.all(np.diff(first.timestamps[:]) > 0)),
        "conversion": first.conversion,
        "confidence": len(first.confidence),
        "edges": len(pe.skeleton.edges),
        "nodes": len(pe.skeleton.nodes),
        "software": pe.source_software,
        "devices": sorted(f.devices.keys()),
        "subject": f.subject.subject_id,
        "snout_x0": float(series["snout"].data[0][0]),
    }
critical = [m for m in inspect_nwbfile(nwbfile_path=sys.argv[1]) if m.importance == Importance.CRITICAL]
out["critical"] = [m.message for m in critical]
print(json.dumps(out))
"#;
    let read = Command::new(python).args(["-c", check]).arg(&nwb).output().unwrap();
    assert!(read.status.success(), "{}", String::from_utf8_lossy(&read.stderr));
    let v: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(v["series"], 24);
    let names: Vec<&str> = v["names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    let mut expected: Vec<&str> = mousepose::core::skeleton::Joint::ALL.iter().map(|j| j.name()).collect();
    let mut got = names.clone();
    got.sort_unstable();
    expected.sort_unstable();
    assert_eq!(got, expected);
    assert_eq!(v["shapes"], serde_json::json!([[rows, 3]]));
    assert_eq!(v["timestamps"], rows);
    assert_eq!(v["increasing"], true);
    assert_eq!(v["conversion"], 0.001);
    assert_eq!(v["confidence"], rows);
    assert_eq!(v["edges"], 23);
    assert_eq!(v["nodes"], 24);
    assert_eq!(v["software"], "mousepose");
    assert_eq!(v["devices"], serde_json::json!(["color_camera", "depth_camera"]));
    assert_eq!(v["subject"], "m1");
    assert_eq!(v["critical"], serde_json::json!([]), "{v}");
    // The first row's snout, as poses.csv has it.
    let csv = std::fs::read_to_string(run.join("poses.csv")).unwrap();
    let snout_x: f64 = csv.lines().nth(1).unwrap().split(',').nth(8).unwrap().parse().unwrap();
    assert!((v["snout_x0"].as_f64().unwrap() - snout_x).abs() < 1e-9);

    // Without the Python environment: one sentence, exit code 1, no file.
    let missing = mousepose()
        .args(["export", "nwb"])
        .arg(&run)
        .arg("--out")
        .arg(tmp.path().join("b.nwb"))
        .args(["--python", "/nonexistent/python3"])
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("cannot run"));
    assert!(!tmp.path().join("b.nwb").exists());
}
