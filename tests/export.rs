//! `mousepose export`: the MoSeq layout read back frame for frame and replayed to the same
//! poses, and the video's frame count and size as ffprobe sees them.
#![allow(clippy::unwrap_used)] // the helpers below are test code too

use crate::util::{mousepose, repo_root};
use mousepose::engine::export::moseq::{COLOR_AVI, PROVENANCE_FILE, RIG_FILE, export_moseq};
use mousepose::engine::replay::{ReplayOptions, replay};
use mousepose::io::session::SessionReader;
use mousepose::runtime::capture::{Clock, FrameSource};
use mousepose::runtime::recording::moseq::{
    DEPTH_DAT, DEPTH_TS, METADATA, MoseqConfig, MoseqDepth, metadata_resolution, parse_timestamps,
};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn fixture() -> PathBuf {
    repo_root().join("fixtures/sessions/synthetic-small")
}

fn replay_to(session: &Path, out: &Path, calibration: Option<PathBuf>) {
    replay(&ReplayOptions {
        stream: None,
        lsl: None,
        lead_ns: None,
        partner_wait: None,
        mice: 1,
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
    // Depth-only: joints 1-12 from the depth image (the tail tip only where the forest put
    // it on the mouse, otherwise unknown), the rest missing.
    let row = a.lines().nth(15).unwrap();
    assert!(row.contains(",ok,"), "{row}");
    let (depth, missing) = (row.matches(",depth").count(), row.matches(",missing").count());
    assert!((depth, missing) == (12, 12) || (depth, missing) == (11, 13), "{row}");
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
        .args(["--from", "0.2", "--to", "0.6", "--json", "--out"])
        .arg(&part)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let said: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(said["out"], part.to_str().unwrap());
    assert_eq!(said["frames"], expected);
    assert_eq!(
        (said["width"].as_u64(), said["height"].as_u64()),
        (Some(width.into()), Some(height.into()))
    );
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
    let python = Path::new(mousepose::engine::export::nwb::DEFAULT_PYTHON);
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
            "--sex",
            "F",
            "--strain",
            "C57BL/6J",
            "--subject-description",
            "group-housed, 12 h light cycle",
            "--experimenter",
            "Doe, Jane",
            "--institution",
            "Lab",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("warning"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Read back by pynwb; checked by nwbinspector.
    let check = r#"
import json, sys
import numpy as np
from pynwb import NWBHDF5IO
import ndx_pose
from nwbinspector import inspect_nwbfile, Importance, load_config
import warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught, NWBHDF5IO(sys.argv[1], "r") as io:
    f = io.read()
    read_warnings = [str(w.message) for w in caught]
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
        "age": f.subject.age,
        "strain": f.subject.strain,
        "sex": f.subject.sex,
        "subject_description": f.subject.description,
        "serials": {n: d.serial_number for n, d in f.devices.items()},
        "models": {n: d.model.name if d.model else None for n, d in f.devices.items()},
        "read_warnings": read_warnings,
        "snout_x0": float(series["snout"].data[0][0]),
    }
# At nwbinspector's default threshold, and with DANDI's configuration (what `dandi validate`
# runs): nothing critical, no best-practice violation, no error.
serious = lambda ms: [f"{m.importance.name} {m.check_function_name}: {m.message}" for m in ms
                      if m.importance.value >= Importance.BEST_PRACTICE_VIOLATION.value]
out["critical"] = serious(inspect_nwbfile(nwbfile_path=sys.argv[1]))
out["dandi"] = serious(inspect_nwbfile(nwbfile_path=sys.argv[1], config=load_config("dandi")))
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
    assert_eq!(v["dandi"], serde_json::json!([]), "{v}");
    assert_eq!(v["age"], "P84D");
    assert_eq!(v["strain"], "C57BL/6J");
    assert_eq!(v["sex"], "F");
    assert_eq!(v["subject_description"], "group-housed, 12 h light cycle");
    // The cameras' serial numbers and models in their own fields (no deprecated field that
    // warns on read).
    let meta = SessionReader::open(fixture()).unwrap().meta().clone();
    for c in &meta.cameras {
        let name = format!("{}_camera", c.role.name());
        assert_eq!(v["serials"][&name], c.serial.as_str(), "{v}");
        assert_eq!(v["models"][&name], c.model.as_str(), "{v}");
    }
    assert_eq!(v["read_warnings"], serde_json::json!([]), "{v}");
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

/// Runs the daemon for a few seconds on the fixture session's depth frames (no colour camera,
/// chunks of 3 s, recording) and returns its first chunk, closed, with its `summary.json`.
fn daemon_chunk(dir: &Path) -> PathBuf {
    let rig = crate::run::rig_full(
        dir,
        &crate::run::session_depth(),
        false,
        "",
        "address = \"127.0.0.1:0\"\n",
    );
    let run = mousepose()
        .args(["run", "--seconds", "4", "--json", "--config"])
        .arg(&rig)
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let runs: Vec<PathBuf> = std::fs::read_dir(dir.join("out"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    let chunk = runs[0].join("chunk-0000");
    assert!(chunk.join("summary.json").is_file(), "{chunk:?} was not closed");
    chunk
}

#[test]
fn a_daemon_chunk_exports_to_nwb_moseq_and_video() {
    let tmp = tempfile::tempdir().unwrap();
    let chunk = daemon_chunk(tmp.path());
    let csv = std::fs::read_to_string(chunk.join("poses.csv")).unwrap();
    let rows = csv.lines().count() - 1;
    assert!(rows > 10, "{rows} rows");
    let reader = SessionReader::open(&chunk).unwrap();
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(chunk.join("summary.json")).unwrap()).unwrap();
    // The chunk's summary names the models its poses come from.
    let body_model = summary["body_model"].as_str().unwrap().to_owned();
    assert!(body_model.ends_with("body.forest"), "{summary}");

    // MoSeq: the chunk is a session.
    let moseq = tmp.path().join("moseq");
    let out = mousepose()
        .args(["export", "moseq", "--json"])
        .arg(&chunk)
        .arg("--out")
        .arg(&moseq)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let said: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(said["depth_frames"], reader.depth_count());
    let ts = std::fs::read_to_string(moseq.join(DEPTH_TS)).unwrap();
    assert_eq!(ts.lines().count(), reader.depth_count());

    // Video: a frame per row of poses.csv, its frames from the chunk's own session.
    let video = tmp.path().join("chunk.mp4");
    let out = mousepose()
        .args(["export", "video"])
        .arg(&chunk)
        .arg("--out")
        .arg(&video)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(probe(&video).0 as usize, rows);

    // NWB: one sample per row, the models as scorer.
    let python = Path::new(mousepose::engine::export::nwb::DEFAULT_PYTHON);
    assert!(python.is_file(), "{python:?} is missing: run scripts/setup.sh");
    let nwb = tmp.path().join("chunk.nwb");
    let out = mousepose()
        .args(["export", "nwb"])
        .arg(&chunk)
        .arg("--out")
        .arg(&nwb)
        .args(["--subject-id", "m1", "--age", "P84D", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let said: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (said["rows"].as_u64(), said["series"].as_u64()),
        (Some(rows as u64), Some(24))
    );
    assert_eq!(said["warnings"], serde_json::json!([]));
    let check = r#"
import json, sys
from pynwb import NWBHDF5IO
import ndx_pose
with NWBHDF5IO(sys.argv[1], "r") as io:
    pe = io.read().processing["behavior"]["PoseEstimation"]
    first = next(iter(pe.pose_estimation_series.values()))
    print(json.dumps({"series": len(pe.pose_estimation_series), "timestamps": len(first.timestamps), "scorer": pe.scorer}))
"#;
    let read = Command::new(python).args(["-c", check]).arg(&nwb).output().unwrap();
    assert!(read.status.success(), "{}", String::from_utf8_lossy(&read.stderr));
    let v: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(v["series"], 24);
    assert_eq!(v["timestamps"], rows);
    assert!(v["scorer"].as_str().unwrap().contains(&body_model), "{v}");
}

#[test]
fn nwb_export_without_an_age_warns_of_dandi_and_invents_none() {
    let python = Path::new(mousepose::engine::export::nwb::DEFAULT_PYTHON);
    assert!(python.is_file(), "{python:?} is missing: run scripts/setup.sh");
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&fixture(), &run, None);
    let export = |name: &str, flags: &[&str]| {
        let nwb = tmp.path().join(name);
        let out = mousepose()
            .args(["export", "nwb"])
            .arg(&run)
            .arg("--out")
            .arg(&nwb)
            .args(flags)
            .output()
            .unwrap();
        (nwb, out)
    };
    let subject = |nwb: &Path| -> serde_json::Value {
        let script = r#"
import json, sys
from pynwb import NWBHDF5IO
import ndx_pose
from nwbinspector import inspect_nwbfile, load_config
with NWBHDF5IO(sys.argv[1], "r") as io:
    s = io.read().subject
    out = {"age": s.age, "date_of_birth": s.date_of_birth.isoformat() if s.date_of_birth else None}
out["dandi"] = sorted({m.check_function_name for m in inspect_nwbfile(nwbfile_path=sys.argv[1], config=load_config("dandi")) if m.importance.name == "CRITICAL"})
print(json.dumps(out))
"#;
        let read = Command::new(python).args(["-c", script]).arg(nwb).output().unwrap();
        assert!(read.status.success(), "{}", String::from_utf8_lossy(&read.stderr));
        serde_json::from_slice(&read.stdout).unwrap()
    };

    // No age, no date of birth: written, with a warning naming what DANDI refuses.
    let (nwb, out) = export("bare.nwb", &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("warning") && err.contains("DANDI") && err.contains("check_subject_age"),
        "{err}"
    );
    let v = subject(&nwb);
    assert_eq!(v["age"], serde_json::Value::Null);
    assert_eq!(v["date_of_birth"], serde_json::Value::Null);
    assert_eq!(v["dandi"], serde_json::json!(["check_subject_age"]), "{v}");

    // A date of birth instead: no warning, DANDI content.
    let (nwb, out) = export("born.nwb", &["--date-of-birth", "1999-10-02"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    let v = subject(&nwb);
    assert_eq!(v["date_of_birth"], "1999-10-02T00:00:00+00:00");
    assert_eq!(v["dandi"], serde_json::json!([]), "{v}");

    // What DANDI would refuse is refused here, in one sentence, before anything is written.
    for (flag, value, says) in [
        ("--age", "90 days", "ISO 8601 duration"),
        ("--age", "P100D/P80D", "does not increase"),
        ("--date-of-birth", "2000-02-30", "YYYY-MM-DD"),
        ("--date-of-birth", "2001-01-01", "after the session's start"),
        ("--species", "mouse", "Latin binomial"),
        ("--weight", "25", "unit"),
    ] {
        let name = format!("bad-{}.nwb", flag.trim_start_matches('-'));
        let (nwb, out) = export(&name, &[flag, value]);
        assert_eq!(out.status.code(), Some(1), "{flag} {value}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{flag} {value}: {err}");
        assert!(!nwb.exists(), "{flag} {value}");
    }
}

#[test]
fn video_frames_keep_the_cameras_times_and_their_panels_stay_in_place() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&fixture(), &run, None);
    let rows = mousepose::runtime::sink::poses::read_poses(&run.join("poses.csv")).unwrap();

    // Every picture of the run has the same size: the bottom view's width does not follow the
    // mouse's footprint, so the side view never moves.
    let reader = SessionReader::open(fixture()).unwrap();
    let rig = reader.meta().rig.unwrap();
    let depth: Vec<_> = reader.depth_frames().map(Result::unwrap).collect();
    let color: Vec<_> = reader.color_frames().unwrap().map(Result::unwrap).collect();
    let (mut with_colour, mut slotted) = (std::collections::BTreeSet::new(), std::collections::BTreeSet::new());
    for row in &rows {
        let d = depth.iter().find(|f| f.stamp.seq == row.depth.seq).unwrap();
        let c = row.color.and_then(|s| color.iter().find(|f| f.stamp.seq == s.seq));
        if c.is_some() {
            let picture = mousepose::runtime::overlay::draw(&rig, d, c, row);
            with_colour.insert((picture.width, picture.height));
        }
        // A pair without its colour frame keeps an empty bottom view in its place.
        let picture = mousepose::runtime::overlay::draw_panels(&rig, d, c, row, true, None);
        slotted.insert((picture.width, picture.height));
    }
    assert_eq!(with_colour.len(), 1, "{with_colour:?}");
    assert_eq!(slotted, with_colour);

    // Each frame is shown at its depth frame's device time from the first (the fixture drops
    // a frame: a constant 30 fps would show every later frame 33 ms early).
    let video = tmp.path().join("v.mp4");
    let out = mousepose()
        .args(["export", "video"])
        .arg(&run)
        .arg("--out")
        .arg(&video)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let probe = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "frame=pts_time",
            "-of",
            "csv=p=0",
        ])
        .arg(&video)
        .output()
        .unwrap();
    assert!(probe.status.success());
    let shown: Vec<f64> = String::from_utf8_lossy(&probe.stdout)
        .lines()
        .map(|l| l.trim().trim_end_matches(','))
        .filter(|l| !l.is_empty())
        .map(|l| l.parse().unwrap())
        .collect();
    let t0 = rows[0].depth.device_ns;
    let times: Vec<f64> = rows.iter().map(|r| (r.depth.device_ns - t0) as f64 / 1e9).collect();
    let gaps = times.windows(2).filter(|w| w[1] - w[0] > 0.05).count();
    assert!(gaps > 0, "the fixture no longer drops a frame: {times:?}");
    assert_eq!(shown.len(), times.len());
    for (k, (s, t)) in shown.iter().zip(&times).enumerate() {
        assert!((s - t).abs() < 0.001, "frame {k} shown at {s} s, taken at {t} s");
    }
}

#[test]
fn nwb_export_keeps_the_calibration_the_videos_and_how_each_pose_was_made() {
    let python = Path::new(mousepose::engine::export::nwb::DEFAULT_PYTHON);
    assert!(python.is_file(), "{python:?} is missing: run scripts/setup.sh");
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&fixture(), &run, None);
    // The videos: the session's depth as MoSeq's depth.avi, and the run drawn.
    let moseq = tmp.path().join("moseq");
    export_moseq(&fixture(), &moseq, None, None, false, |_, _| {}).unwrap();
    let labeled = tmp.path().join("labeled.mp4");
    let drawn = mousepose()
        .args(["export", "video"])
        .arg(&run)
        .arg("--out")
        .arg(&labeled)
        .output()
        .unwrap();
    assert!(drawn.status.success(), "{}", String::from_utf8_lossy(&drawn.stderr));
    let nwb = tmp.path().join("out/run.nwb");
    std::fs::create_dir(tmp.path().join("out")).unwrap();
    let out = mousepose()
        .args(["export", "nwb"])
        .arg(&run)
        .arg("--out")
        .arg(&nwb)
        .args(["--subject-id", "m1", "--age", "P84D", "--source-video"])
        .arg(moseq.join("depth.avi"))
        .arg("--labeled-video")
        .arg(&labeled)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let check = r#"
import json, sys
import numpy as np
from pynwb import NWBHDF5IO
import ndx_pose
from nwbinspector import inspect_nwbfile, Importance, load_config
import warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught, NWBHDF5IO(sys.argv[1], "r") as io:
    f = io.read()
    read_warnings = [str(w.message) for w in caught]
    pe = f.processing["behavior"]["PoseEstimation"]
    frames = f.processing["behavior"]["PoseFrames"].to_dataframe()
    cameras = {n: {"type": type(d).__name__,
                   "K": np.asarray(d.intrinsic_matrix).tolist(),
                   "R": np.asarray(d.rotation_matrix).tolist(),
                   "t": np.asarray(d.translation_vector).tolist(),
                   "dist": np.asarray(d.distortion_coefficients).tolist(),
                   "serial": d.serial_number} for n, d in f.devices.items()}
    def video(v):
        if v is None:
            return None
        out = {"file": [str(x) for x in v.external_file[:]], "dimension": [int(x) for x in v.dimension[:]]}
        if v.timestamps is not None:
            out["frames"] = len(v.timestamps)
            out["first_s"] = float(v.timestamps[0])
            out["last_s"] = float(v.timestamps[-1])
        else:
            out["rate"] = v.rate
        return out
    out = {
        "cameras": cameras,
        "device": pe.device.name,
        "source_video": video(pe.source_video),
        "labeled_video": video(pe.labeled_video),
        "status": frames["status"].tolist(),
        "orientation_confidence": [None if np.isnan(x) else float(x) for x in frames["orientation_confidence"]],
        "joint_source": [list(map(str, s)) for s in frames["joint_source"]],
        "color_seq": [int(x) for x in frames["color_seq"]],
        "read_warnings": read_warnings,
    }
serious = lambda ms: [f"{m.importance.name} {m.check_function_name}: {m.message}" for m in ms
                      if m.importance.value >= Importance.BEST_PRACTICE_VIOLATION.value]
out["critical"] = serious(inspect_nwbfile(nwbfile_path=sys.argv[1]))
out["dandi"] = serious(inspect_nwbfile(nwbfile_path=sys.argv[1], config=load_config("dandi")))
print(json.dumps(out))
"#;
    let read = Command::new(python).args(["-c", check]).arg(&nwb).output().unwrap();
    assert!(read.status.success(), "{}", String::from_utf8_lossy(&read.stderr));
    let v: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(v["critical"], serde_json::json!([]), "{v}");
    assert_eq!(v["dandi"], serde_json::json!([]), "{v}");
    assert_eq!(v["read_warnings"], serde_json::json!([]), "{v}");

    // The rig calibration, as OpenCV has a camera: p_camera = R p_world + t, mm.
    let meta = SessionReader::open(fixture()).unwrap().meta().clone();
    let rig = meta.rig.unwrap();
    for (name, cam) in [("depth_camera", rig.depth), ("color_camera", rig.color)] {
        let c = &v["cameras"][name];
        assert_eq!(c["type"], "CalibratedCamera", "{v}");
        let i = cam.intrinsics;
        let k = [[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]];
        let inv = cam.world_from_camera.inverse();
        let r = inv.rotation.to_rotation_matrix();
        for row in 0..3 {
            for col in 0..3 {
                assert!(
                    (c["K"][row][col].as_f64().unwrap() - k[row][col]).abs() < 1e-9,
                    "{name}: {c}"
                );
                assert!(
                    (c["R"][row][col].as_f64().unwrap() - r[(row, col)]).abs() < 1e-9,
                    "{name}: {c}"
                );
            }
            assert!(
                (c["t"][row].as_f64().unwrap() - inv.translation.vector[row]).abs() < 1e-9,
                "{name}: {c}"
            );
        }
        let dist: Vec<f64> = c["dist"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(dist, i.distortion.to_vec());
        // A world point projects where the rig projects it.
        let p = nalgebra::Point3::new(30.0, -20.0, 10.0);
        let q = inv * p;
        let rp = |m: &serde_json::Value, v: [f64; 3], row: usize| {
            (0..3).map(|j| m[row][j].as_f64().unwrap() * v[j]).sum::<f64>()
        };
        let pc: [f64; 3] = std::array::from_fn(|row| rp(&c["R"], [p.x, p.y, p.z], row) + c["t"][row].as_f64().unwrap());
        assert!((pc[0] - q.x).abs() < 1e-6 && (pc[2] - q.z).abs() < 1e-6, "{name}");
    }
    assert_eq!(v["device"], "depth_camera");

    // The videos, by paths relative to the NWB file, with their sizes and frames.
    let depth_frames = SessionReader::open(fixture()).unwrap().depth_count();
    let rows = mousepose::runtime::sink::poses::read_poses(&run.join("poses.csv")).unwrap();
    let t0 = rows[0].depth.device_ns;
    let last_s = |ns: u64| (ns - t0) as f64 / 1e9;
    // The source's times from depth_ts.txt beside it: the depth frames' own, exactly.
    let session_depth: Vec<_> = SessionReader::open(fixture())
        .unwrap()
        .depth_frames()
        .map(|f| f.unwrap().stamp.device_ns)
        .collect();
    let source = &v["source_video"];
    assert_eq!(source["file"], serde_json::json!(["../moseq/depth.avi"]), "{v}");
    assert_eq!(source["dimension"], serde_json::json!([640, 480]), "{v}");
    assert_eq!(source["frames"], depth_frames, "{v}");
    assert!(
        (source["first_s"].as_f64().unwrap() - last_s(session_depth[0])).abs() < 1e-9,
        "{v}"
    );
    assert!(
        (source["last_s"].as_f64().unwrap() - last_s(*session_depth.last().unwrap())).abs() < 1e-9,
        "{v}"
    );
    // The labelled video's: its own (variable frame rate, a frame per pose row).
    let labeled = &v["labeled_video"];
    assert_eq!(labeled["file"], serde_json::json!(["../labeled.mp4"]), "{v}");
    assert_eq!(labeled["frames"], rows.len(), "{v}");
    let end = last_s(rows.last().unwrap().depth.device_ns);
    assert!((labeled["last_s"].as_f64().unwrap() - end).abs() < 0.001, "{v}");

    // Each frame's status, orientation confidence and each joint's source, as poses.csv has them.
    let csv = std::fs::read_to_string(run.join("poses.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let body: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(v["status"].as_array().unwrap().len(), body.len());
    let mut sources = std::collections::BTreeSet::new();
    for (k, cells) in body.iter().enumerate() {
        assert_eq!(v["status"][k], cells[col("status")], "row {k}");
        let oc = cells[col("orientation_confidence")];
        match v["orientation_confidence"][k].as_f64() {
            Some(x) => assert!((x - oc.parse::<f64>().unwrap()).abs() < 1e-9, "row {k}"),
            None => assert_eq!(oc, "", "row {k}"),
        }
        let cs = cells[col("color_seq")];
        assert_eq!(
            v["color_seq"][k],
            if cs.is_empty() { -1 } else { cs.parse::<i64>().unwrap() },
            "row {k}"
        );
        for (j, joint) in mousepose::core::skeleton::Joint::ALL.iter().enumerate() {
            let s = cells[col(&format!("{}_source", joint.name()))];
            assert_eq!(v["joint_source"][k][j], s, "row {k} {}", joint.name());
            sources.insert(s.to_owned());
        }
    }
    assert!(
        sources.contains("depth") && sources.contains("paw") && sources.contains("ik"),
        "{sources:?}"
    );

    // A video that is not there is refused before anything is written.
    let missing = mousepose()
        .args(["export", "nwb"])
        .arg(&run)
        .arg("--out")
        .arg(tmp.path().join("b.nwb"))
        .args(["--source-video", "/nonexistent.avi"])
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("not a file"));
    assert!(!tmp.path().join("b.nwb").exists());
}

#[test]
fn moseq_export_says_how_far_moseqs_millimetres_are_from_the_cameras() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("m");
    let out = mousepose()
        .args(["export", "moseq", "--json"])
        .arg(fixture())
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // moseq2-extract's convert_pxs_to_mm: a 512 x 424 frame over a 70.6 x 60 degree field of
    // view, the angles taken in radians as they are.
    let moseq_fx = 512.0 / (2.0 * 35.3f64.to_radians());
    let moseq_fy = 424.0 / (2.0 * 30.0f64.to_radians());
    let rig = SessionReader::open(fixture()).unwrap().meta().rig.unwrap();
    let (fx, fy) = (rig.depth.intrinsics.fx, rig.depth.intrinsics.fy);
    let said: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let provenance: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join(PROVENANCE_FILE)).unwrap()).unwrap();
    for mm in [&said["millimetres"], &provenance["millimetres"]] {
        assert!((mm["scale_x"].as_f64().unwrap() - moseq_fx / fx).abs() < 1e-9, "{mm}");
        assert!((mm["scale_y"].as_f64().unwrap() - moseq_fy / fy).abs() < 1e-9, "{mm}");
        assert_eq!(mm["fx"], fx);
        assert_eq!(mm["intrinsics_from"], "rig calibration");
    }
    // The fixture's camera (570 px) is far from moseq2's assumption: the operator is told.
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("warning") && err.contains("Kinect v2"), "{err}");
    assert!(err.contains(&format!("{:.4}", moseq_fx / fx)), "{err}");
}

#[test]
fn a_replay_of_a_short_moseq_export_starts_no_ffmpeg_per_background_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let moseq = tmp.path().join("moseq");
    export_moseq(&fixture(), &moseq, None, None, false, |_, _| {}).unwrap();
    // An ffmpeg first on the search path that notes each run, then runs the real one.
    let path = std::env::var_os("PATH").unwrap();
    let real = std::env::split_paths(&path)
        .map(|d| d.join("ffmpeg"))
        .find(|p| p.is_file())
        .unwrap();
    let bin = tmp.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let log = tmp.path().join("ffmpeg.log");
    let wrapper = bin.join("ffmpeg");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\necho \"$*\" >> '{}'\nexec '{}' \"$@\"\n",
            log.display(),
            real.display()
        ),
    )
    .unwrap();
    let mut perms = std::fs::metadata(&wrapper).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&wrapper, perms).unwrap();
    let mut dirs = vec![bin.clone()];
    dirs.extend(std::env::split_paths(&path));
    let out = mousepose()
        .env("PATH", std::env::join_paths(dirs).unwrap())
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .arg("replay")
        .arg(&moseq)
        .arg("--calibration")
        .arg(moseq.join(RIG_FILE))
        .arg("--out")
        .arg(tmp.path().join("run"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let runs = std::fs::read_to_string(&log).unwrap();
    // The 29 frames: one ffmpeg samples the background, one decodes the frames for the
    // replay, one draws frame.png (it was one per background frame, 31 in all).
    assert!(
        runs.lines().count() <= 3,
        "{} ffmpeg runs:\n{runs}",
        runs.lines().count()
    );
    let rows = std::fs::read_to_string(tmp.path().join("run/poses.csv"))
        .unwrap()
        .lines()
        .count()
        - 1;
    assert_eq!(rows, SessionReader::open(fixture()).unwrap().depth_count());
}
