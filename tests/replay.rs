//! Replay end to end: sessions through the real pipeline (threads, edges, synchroniser,
//! segmentation, body forest, pose writer), checked against the sessions' ground truth.
#![allow(clippy::unwrap_used)] // the helpers below are test code too

use crate::util::{mousepose, repo_root};
use mousepose::core::noise::{DepthNoise, NoiseModel};
use mousepose::engine::replay::{ReplayOptions, ReplaySummary, replay};
use mousepose::io::session::{SessionReader, SessionWriter};
use mousepose::synth::session::{SessionSpec, write_session};
use std::path::{Path, PathBuf};

fn fixture() -> PathBuf {
    repo_root().join("fixtures/sessions/synthetic-small")
}

fn options(session: &Path, out: &Path, workers: usize) -> ReplayOptions {
    crate::util::replay_options(session, out, workers)
}

/// Every captured frame is paired, unpaired or dropped, per camera.
fn assert_accounted(s: &ReplaySummary) {
    for (name, c) in &s.cameras {
        assert!(c.adds_up(), "{name}: {c:?}");
    }
    let depth = &s.cameras["depth"];
    assert_eq!(s.pairs, depth.paired + depth.unpaired);
}

fn synth(dir: &Path, seconds: f64, seed: u64, color: bool) {
    let spec = SessionSpec {
        seconds,
        seed,
        color_binning: 4,
        color,
        noise: DepthNoise {
            model: NoiseModel::StructuredLight,
            gaussian_mm: 0.0,
        },
        ..SessionSpec::default()
    };
    std::fs::create_dir_all(dir).unwrap();
    write_session(dir, &spec, |_, _| {}).unwrap();
}

#[test]
fn the_fixture_session_replays_with_its_true_pairs_and_joints() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let s = replay(&options(&fixture(), &out, 2)).unwrap();
    let reader = SessionReader::open(fixture()).unwrap();
    assert_eq!(s.pairs as usize, reader.depth_count());
    let pairing = s.pairing.clone().unwrap();
    assert_eq!(pairing.mismatched, 0, "{pairing:?}");
    assert_eq!(pairing.matched as usize, reader.depth_count());
    assert_accounted(&s);
    // The session's forced camera drop shows as a gap in each camera's sequence numbers.
    assert_eq!(s.cameras["depth"].lost_before_capture.get("camera_gap"), Some(&1));
    assert_eq!(s.per_joint_error_mm.len(), 24);
    // The bundled paw cascade finds the paws even in this small (4x binned) colour stream,
    // and the limbs follow them.
    assert!(s.paw_model.is_some());
    let detected = s.group_error_mm["detected_paws"];
    assert!(detected < 5.0, "detected paws {detected} mm off");
    let limbs = s.group_error_mm["limbs"];
    assert!(limbs < 10.0, "limbs {limbs} mm off");
    let mean = s.mean_error_mm.unwrap();
    assert!(mean < 6.0, "mean joint error {mean} mm");
    // poses.csv: the header, then one row per pair.
    let csv = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), mousepose::runtime::sink::poses::header());
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len() as u64, s.pairs);
    let columns = mousepose::runtime::sink::poses::header().split(',').count();
    assert!(rows.iter().all(|r| r.split(',').count() == columns));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    for key in [
        "per_joint_error_mm",
        "mean_error_mm",
        "cameras",
        "stages",
        "throughput_pairs_per_s",
    ] {
        assert!(summary.get(key).is_some(), "summary.json lacks {key}");
    }
    for stage in summary["stages"].as_array().unwrap() {
        assert!(stage["latency"]["p99_ms"].as_f64().is_some());
    }
}

/// The `{joint}_source` values of a poses.csv, per joint name.
fn sources(csv: &str) -> std::collections::HashMap<String, std::collections::BTreeSet<String>> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut out: std::collections::HashMap<String, std::collections::BTreeSet<String>> = Default::default();
    for line in lines {
        for (name, value) in header.iter().zip(line.split(',')) {
            if let Some(joint) = name.strip_suffix("_source") {
                out.entry(joint.to_owned()).or_default().insert(value.to_owned());
            }
        }
    }
    out
}

#[test]
fn every_joint_says_where_it_came_from_and_overlays_are_drawn() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let o = mousepose()
        .arg("replay")
        .arg(fixture())
        .arg("--out")
        .arg(&out)
        .args(["--overlays", "10"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let sources = sources(&std::fs::read_to_string(out.join("poses.csv")).unwrap());
    let allowed = |joint: mousepose::core::skeleton::Joint| -> &[&str] {
        match joint.number() {
            1..=12 => &["depth", "missing"],
            13..=20 => &["ik", "default", "missing"],
            _ => &["paw", "default", "missing"],
        }
    };
    for joint in mousepose::core::skeleton::Joint::ALL {
        let seen = &sources[joint.name()];
        assert!(
            seen.iter().all(|s| allowed(joint).contains(&s.as_str())),
            "{}: {seen:?}",
            joint.name()
        );
    }
    assert!(sources["left_hind_paw"].contains("paw"));
    assert!(sources["left_knee"].contains("ik"));
    // One picture per depth frame whose sequence number is a multiple of 10.
    let reader = SessionReader::open(fixture()).unwrap();
    let expected: Vec<String> = reader
        .seqs(mousepose::io::session::CameraRole::Depth)
        .iter()
        .filter(|s| *s % 10 == 0)
        .map(|s| format!("{s:06}.png"))
        .collect();
    let mut written: Vec<String> = std::fs::read_dir(out.join("overlays"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    assert_eq!(written, expected);
    assert!(out.join("frame.png").is_file());
}

#[test]
fn without_a_paw_cascade_the_limbs_take_their_default_configuration() {
    let tmp = tempfile::tempdir().unwrap();
    let models = tmp.path().join("models");
    std::fs::create_dir(&models).unwrap();
    std::fs::copy(
        repo_root().join("fixtures/models/body.forest"),
        models.join("body.forest"),
    )
    .unwrap();
    let out = tmp.path().join("o");
    let s = replay(&ReplayOptions {
        stream: None,
        models: Some(models),
        ..options(&fixture(), &out, 2)
    })
    .unwrap();
    assert!(s.paw_model.is_none());
    assert!(!s.group_error_mm.contains_key("detected_paws"));
    let sources = sources(&std::fs::read_to_string(out.join("poses.csv")).unwrap());
    for joint in ["left_fore_paw", "right_hind_paw", "left_elbow", "right_ankle"] {
        assert!(
            sources[joint].iter().all(|s| s == "default" || s == "missing"),
            "{joint}: {:?}",
            sources[joint]
        );
    }
}

#[test]
fn a_calibration_file_replaces_the_sessions_and_must_be_of_its_rig() {
    use mousepose::vision::calibrate::RigCalibration;
    let tmp = tempfile::tempdir().unwrap();
    let reader = SessionReader::open(fixture()).unwrap();
    // The session's own rig, from a file: the same poses as without it.
    let same = tmp.path().join("same.yaml");
    RigCalibration::from_rig(&reader.meta().rig.unwrap())
        .save(&same)
        .unwrap();
    let with = replay(&ReplayOptions {
        stream: None,
        calibration: Some(same),
        ..options(&fixture(), &tmp.path().join("a"), 2)
    })
    .unwrap();
    replay(&options(&fixture(), &tmp.path().join("b"), 2)).unwrap();
    assert_eq!(
        std::fs::read(tmp.path().join("a/poses.csv")).unwrap(),
        std::fs::read(tmp.path().join("b/poses.csv")).unwrap()
    );
    assert!(with.mean_error_mm.is_some());
    // A calibration of the full-size colour camera does not fit the session's binned one.
    let other = tmp.path().join("other.yaml");
    RigCalibration::from_rig(&mousepose::core::geometry::Rig::default_rig())
        .save(&other)
        .unwrap();
    let out = tmp.path().join("c");
    let o = mousepose()
        .arg("replay")
        .arg(fixture())
        .arg("--out")
        .arg(&out)
        .arg("--calibration")
        .arg(&other)
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("other.yaml") && err.contains("1280"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(!out.exists());
}

#[test]
fn replay_is_deterministic_whatever_the_worker_count() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    replay(&options(&fixture(), &a, 1)).unwrap();
    replay(&options(&fixture(), &b, 3)).unwrap();
    assert_eq!(
        std::fs::read(a.join("poses.csv")).unwrap(),
        std::fs::read(b.join("poses.csv")).unwrap()
    );
}

/// The stages' and edges' names are read by the daemon's `/status` and `/metrics`, the summaries
/// and whoever scrapes them: the declared chain keeps them, and every pair goes through every
/// stage once.
#[test]
fn the_pipeline_keeps_its_stage_and_edge_names_and_every_pair_passes_every_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let s = replay(&options(&fixture(), &tmp.path().join("o"), 2)).unwrap();
    let edges: Vec<&str> = s.edges.keys().map(String::as_str).collect();
    assert_eq!(
        edges,
        [
            "body->paws",
            "capture",
            "fuse->poses",
            "paws->fuse",
            "segment->body",
            "sync->segment"
        ]
    );
    let stages: Vec<&str> = s.stages.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(stages, ["segment", "body", "paws", "fuse", "poses"]);
    assert!(s.pairs > 0);
    for stage in &s.stages {
        assert_eq!((stage.items_in, stage.items_out), (s.pairs, s.pairs), "{}", stage.name);
    }
    for (name, edge) in &s.edges {
        assert_eq!(edge.dropped_full, 0, "{name}");
    }
    assert_accounted(&s);
}

#[test]
fn drifting_jittery_clocks_with_drops_pair_exactly_as_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    for seed in [21, 22] {
        let session = tmp.path().join(format!("s{seed}"));
        synth(&session, 3.0, seed, true);
        let s = replay(&options(&session, &tmp.path().join(format!("o{seed}")), 2)).unwrap();
        let pairing = s.pairing.clone().unwrap();
        assert_eq!(pairing.mismatched, 0, "seed {seed}: {pairing:?}");
        assert_accounted(&s);
    }
}

#[test]
fn a_depth_only_session_gives_depth_only_pairs() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("s");
    synth(&session, 1.0, 5, false);
    let s = replay(&options(&session, &tmp.path().join("o"), 2)).unwrap();
    assert!(!s.cameras.contains_key("color"));
    assert_eq!(s.cameras["depth"].paired, 0);
    assert_eq!(s.cameras["depth"].unpaired, s.pairs);
    assert_eq!(s.pairing.unwrap().mismatched, 0);
    // The single depth image mode: joints 1-12 only.
    assert_eq!(s.per_joint_error_mm.len(), 12);
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dest = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dest);
        } else {
            std::fs::copy(e.path(), dest).unwrap();
        }
    }
}

#[test]
fn damaged_and_truncated_frames_are_counted_not_fatal() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("s");
    copy_dir(&fixture(), &session);
    let frames = session.join("depth/frames.mpstore");
    let mut bytes = std::fs::read(&frames).unwrap();
    let full = bytes.len();
    // Damage the middle of the file, and cut its last record short.
    for b in &mut bytes[full / 2..full / 2 + 64] {
        *b ^= 0x5a;
    }
    bytes.truncate(full - 1000);
    std::fs::write(&frames, &bytes).unwrap();
    std::fs::remove_file(session.join("depth/index.mpindex")).unwrap();
    let s = replay(&options(&session, &tmp.path().join("o"), 2)).unwrap();
    assert_accounted(&s);
    let reader = SessionReader::open(fixture()).unwrap();
    assert!((s.pairs as usize) < reader.depth_count());
    let lost: u64 = s.cameras["depth"].lost_before_capture.values().sum();
    assert!(lost >= 2, "{:?}", s.cameras["depth"]);
    // The cut last record is reported as such.
    assert_eq!(
        s.cameras["depth"].lost_before_capture.get("truncated"),
        Some(&1),
        "{:?}",
        s.cameras["depth"]
    );
}

#[test]
fn bad_sessions_give_one_clear_error_and_no_output() {
    let tmp = tempfile::tempdir().unwrap();
    // An empty session.
    let empty = tmp.path().join("empty");
    let reader = SessionReader::open(fixture()).unwrap();
    std::fs::create_dir(&empty).unwrap();
    SessionWriter::create(&empty, reader.meta())
        .unwrap()
        .finish_at(1)
        .unwrap();
    // Not a session at all.
    let missing = tmp.path().join("missing");
    for (session, expect) in [(&empty, "no depth frames"), (&missing, "missing")] {
        let out = tmp.path().join("out");
        let o = mousepose()
            .arg("replay")
            .arg(session)
            .arg("--out")
            .arg(&out)
            .arg("--models")
            .arg(repo_root().join("fixtures/models"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.starts_with("error: ") && err.contains(expect), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(!err.contains("panicked"));
        assert!(!out.exists());
    }
    // A models directory without a body forest.
    let o = mousepose()
        .arg("replay")
        .arg(fixture())
        .arg("--out")
        .arg(tmp.path().join("o2"))
        .arg("--models")
        .arg(tmp.path())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("body.forest"));
}

#[test]
fn replay_json_prints_the_summary() {
    let tmp = tempfile::tempdir().unwrap();
    let o = mousepose()
        .arg("replay")
        .arg(fixture())
        .arg("--out")
        .arg(tmp.path().join("o"))
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v["mean_error_mm"].as_f64().is_some());
    assert_eq!(v["per_joint_error_mm"].as_object().unwrap().len(), 24);
}

#[test]
fn a_moseq_layout_recording_replays_depth_only() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("moseq");
    std::fs::create_dir(&dir).unwrap();
    let reader = SessionReader::open(fixture()).unwrap();
    let mut dat = Vec::new();
    let mut ts = String::new();
    let mut size = (0, 0);
    for f in reader.depth_frames() {
        let f = f.unwrap();
        size = (f.width, f.height);
        dat.extend(f.data.iter().flat_map(|v| v.to_le_bytes()));
        ts.push_str(&format!("{}\n", f.stamp.device_ns as f64 / 1e6));
    }
    std::fs::write(dir.join("depth.dat"), dat).unwrap();
    std::fs::write(dir.join("depth_ts.txt"), ts).unwrap();
    std::fs::write(
        dir.join("metadata.json"),
        format!("{{\"DepthResolution\": [{}, {}]}}", size.0, size.1),
    )
    .unwrap();
    let s = replay(&options(&dir, &tmp.path().join("o"), 2)).unwrap();
    assert_eq!(s.pairs as usize, reader.depth_count());
    assert!(!s.cameras.contains_key("color"));
    assert_eq!(s.cameras["depth"].unpaired, s.pairs);
    assert!(s.pairing.is_none() && s.mean_error_mm.is_none());
    assert_accounted(&s);
}

#[test]
fn one_colour_frame_of_another_size_is_skipped_and_counted_not_the_end_of_the_replay() {
    let tmp = tempfile::tempdir().unwrap();
    let reader = SessionReader::open(fixture()).unwrap();
    let session = tmp.path().join("session");
    std::fs::create_dir(&session).unwrap();
    let mut w = SessionWriter::create(&session, reader.meta()).unwrap();
    for f in reader.depth_frames() {
        w.write_depth(&f.unwrap()).unwrap();
    }
    for (k, f) in reader.color_frames().unwrap().enumerate() {
        let mut f = f.unwrap();
        if k == 5 {
            // Half as wide: a camera that changed its region for one frame.
            f.width /= 2;
            f.data.truncate(f.data.len() / 2);
        }
        w.write_color(&f).unwrap();
    }
    w.finish().unwrap();
    let s = replay(&options(&session, &tmp.path().join("o"), 2)).unwrap();
    assert_accounted(&s);
    let color = &s.cameras["color"];
    let skipped: u64 = color.lost_before_capture.values().sum::<u64>() + color.dropped_total;
    assert_eq!(skipped, 1, "{color:?}");
}

/// Halves a depth frame (every other pixel of every other row), as a camera that changed its
/// mode for one frame would deliver it.
fn halve(f: &mut mousepose::core::frame::DepthFrame) {
    let (w, h) = (f.width as usize, f.height as usize);
    f.data = (0..h / 2)
        .flat_map(|y| (0..w / 2).map(move |x| (x, y)))
        .map(|(x, y)| f.data[2 * y * w + 2 * x])
        .collect();
    f.width /= 2;
    f.height /= 2;
}

/// Issue 31 item 3: one depth frame of half the size mid-session (or first) is skipped and
/// counted `wrong_size`, as the daemon does, and the replay goes on.
#[test]
fn issue31_a_half_size_depth_frame_is_skipped_and_counted_not_the_end_of_the_replay() {
    let tmp = tempfile::tempdir().unwrap();
    let reader = SessionReader::open(fixture()).unwrap();
    let baseline = replay(&options(&fixture(), &tmp.path().join("baseline"), 2)).unwrap();
    // The rendered session (its empty cage known), and the same frames as a recording, whose
    // background is modelled from up to 31 frames spread over it (here all of them, the odd
    // one among them).
    assert!(reader.depth_count() <= 31);
    for (name, odd, source) in [
        ("rendered", 5, mousepose::io::session::SessionSource::Synthetic),
        ("recorded", 5, mousepose::io::session::SessionSource::Recorded),
    ] {
        let session = tmp.path().join(name);
        std::fs::create_dir(&session).unwrap();
        let mut meta = reader.meta().clone();
        meta.source = source;
        let mut w = SessionWriter::create(&session, &meta).unwrap();
        for (k, f) in reader.depth_frames().enumerate() {
            let mut f = f.unwrap();
            if k == odd {
                halve(&mut f);
            }
            w.write_depth(&f).unwrap();
        }
        for f in reader.color_frames().unwrap() {
            w.write_color(&f.unwrap()).unwrap();
        }
        w.finish().unwrap();
        let s = replay(&options(&session, &tmp.path().join(format!("{name}-out")), 2))
            .unwrap_or_else(|e| panic!("{name}: {:#}", anyhow::Error::from(e)));
        assert_accounted(&s);
        let depth = &s.cameras["depth"];
        assert_eq!(
            depth.lost_before_capture.get("wrong_size"),
            Some(&1),
            "{name}: {depth:?}"
        );
        // The frame is counted once: not again as a gap in the frame counter (the session's
        // own gaps, rendered drops, are as they were).
        let gaps = &baseline.cameras["depth"].lost_before_capture.get("camera_gap");
        assert_eq!(&depth.lost_before_capture.get("camera_gap"), gaps, "{name}: {depth:?}");
        assert_eq!(depth.captured, baseline.cameras["depth"].captured - 1, "{name}");
        assert_eq!(s.pairs, baseline.pairs - 1, "{name}");
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(tmp.path().join(format!("{name}-out/summary.json"))).unwrap())
                .unwrap();
        assert_eq!(summary["cameras"]["depth"]["lost_before_capture"]["wrong_size"], 1);
    }
}

/// Damages the payload of the depth records of `session` whose index `damage` picks (the
/// index file is kept: the records are known but do not read back).
fn damage_depth_records(session: &Path, damage: impl Fn(usize, usize) -> bool) {
    let path = session.join("depth/frames.mpstore");
    let mut bytes = std::fs::read(&path).unwrap();
    let mut starts = Vec::new();
    let mut at = 16; // the file's header
    while at + 16 <= bytes.len() {
        assert_eq!(&bytes[at..at + 4], b"MPRC", "a record at {at}");
        let len = u32::from_le_bytes(bytes[at + 4..at + 8].try_into().unwrap()) as usize;
        starts.push((at + 16, len));
        at += 16 + len;
    }
    let count = starts.len();
    for (k, &(payload, len)) in starts.iter().enumerate() {
        if damage(k, count) {
            for b in &mut bytes[payload + len / 2..payload + len / 2 + 8.min(len / 2)] {
                *b ^= 0x5a;
            }
        }
    }
    std::fs::write(&path, bytes).unwrap();
}

/// Issue 31 item 4: a session with few intact depth frames keeps its results whatever
/// becomes of the picture: poses.csv and summary.json are written and the exit code is 0;
/// a picture that cannot be drawn is a warning, and the summary says so.
#[test]
fn issue31_a_picture_never_costs_the_results() {
    let tmp = tempfile::tempdir().unwrap();
    let replay_cli = |session: &Path, out: &Path| {
        mousepose()
            .arg("replay")
            .arg(session)
            .arg("--out")
            .arg(out)
            .arg("--models")
            .arg(repo_root().join("fixtures/models"))
            .output()
            .unwrap()
    };
    // The first frame and the whole second half do not read back: no pose in the second half
    // to draw, and the first frame, drawn when no mouse is seen, is damaged.
    let few = tmp.path().join("few");
    copy_dir(&fixture(), &few);
    damage_depth_records(&few, |k, count| k == 0 || k >= count / 2);
    // No depth frame reads back at all: nothing to draw.
    let none = tmp.path().join("none");
    copy_dir(&fixture(), &none);
    damage_depth_records(&none, |_, _| true);
    for (session, drawn) in [(&few, true), (&none, false)] {
        let out = tmp
            .path()
            .join(format!("{}-out", session.file_name().unwrap().to_string_lossy()));
        let o = replay_cli(session, &out);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{session:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
        let rows = std::fs::read_to_string(out.join("poses.csv")).unwrap().lines().count() - 1;
        assert_eq!(summary["pairs"].as_u64(), Some(rows as u64), "{session:?}");
        assert!(
            summary["cameras"]["depth"]["lost_before_capture"]["corrupt"]
                .as_u64()
                .unwrap()
                > 0
        );
        assert_eq!(out.join("frame.png").is_file(), drawn, "{session:?}");
        if drawn {
            assert!(rows > 0, "{session:?}");
            assert_eq!(summary["picture"], "frame.png");
            assert!(summary.get("picture_error").is_none(), "{summary:#}");
        } else {
            assert!(summary["picture"].is_null(), "{summary:#}");
            assert!(summary["picture_error"].as_str().is_some(), "{summary:#}");
            assert!(err.contains("No picture"), "{err}");
        }
    }
}

/// Issue 31 item 11: a replay stopped by SIGTERM (or Ctrl-C) removes its hidden partial
/// directory and writes nothing, with one sentence and exit code 2.
#[test]
fn issue31_a_replay_stopped_by_sigterm_leaves_nothing_behind() {
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("s");
    synth(&session, 8.0, 7, false);
    let out = tmp.path().join("o");
    // At the recorded pace: still running when the signal comes.
    let child = mousepose()
        .arg("replay")
        .arg(&session)
        .arg("--out")
        .arg(&out)
        .arg("--realtime")
        .arg("--models")
        .arg(repo_root().join("fixtures/models"))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let partial = tmp.path().join(format!(".o.partial-{}", child.id()));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while !partial.join("poses.csv").exists() {
        assert!(std::time::Instant::now() < deadline, "no {partial:?}");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    let status = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("stopped by a signal"), "{err}");
    assert!(!partial.exists(), "{partial:?} left behind");
    assert!(!out.exists());
}

#[test]
fn a_single_replay_shows_its_progress_on_a_terminal_only() {
    let tmp = tempfile::tempdir().unwrap();
    let models = repo_root().join("fixtures/models");
    let frames = SessionReader::open(fixture()).unwrap().depth_count();
    // On a terminal (`script` gives the command one): a bar of rows against the session's
    // depth frames, on stderr.
    let out = tmp.path().join("tty");
    let command = format!(
        "{:?} replay {:?} --out {:?} --models {:?} 2>&1 >/dev/null",
        env!("CARGO_BIN_EXE_mousepose"),
        fixture(),
        out,
        models
    );
    let tty = std::process::Command::new("script")
        .args(["-qefc", &command, "/dev/null"])
        .env_remove("JOURNAL_STREAM")
        .output()
        .unwrap();
    assert!(tty.status.success(), "{}", String::from_utf8_lossy(&tty.stderr));
    let shown = String::from_utf8_lossy(&tty.stdout);
    assert!(shown.contains("replay ["), "{shown:?}");
    assert!(shown.contains(&format!("/{frames}")), "{shown:?}");
    assert!(out.join("poses.csv").is_file());
    // In a pipe: no bar.
    let piped = mousepose()
        .arg("replay")
        .arg(fixture())
        .arg("--out")
        .arg(tmp.path().join("pipe"))
        .arg("--models")
        .arg(&models)
        .env_remove("JOURNAL_STREAM")
        .output()
        .unwrap();
    assert!(piped.status.success());
    assert!(!String::from_utf8_lossy(&piped.stderr).contains("replay ["));
}

#[test]
fn issue64_the_pose_predicted_ahead_is_written_beside_and_nearer_where_the_mouse_then_is() {
    use mousepose::core::skeleton::Joint;
    use mousepose::runtime::sink::poses::read_poses;
    let tmp = tempfile::tempdir().unwrap();
    let replay_at = |lead: &str| {
        let out = tmp.path().join(format!("lead-{lead}"));
        let done = mousepose()
            .args([
                "replay",
                fixture().to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--lead",
                lead,
            ])
            .output()
            .unwrap();
        assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
        out
    };
    // At no lead the prediction is the pose itself, byte for byte.
    let out = replay_at("0");
    let read = |name: &str| std::fs::read_to_string(out.join(name)).unwrap();
    assert_eq!(read("poses_predicted.csv"), read("poses.csv"));

    // 100 ms ahead (three frames): joints 1-12 but the tail tip moved on, nearer the truth
    // three frames later than the pose held; the rest as placed.
    let out = replay_at("100");
    let poses = read_poses(&out.join("poses.csv")).unwrap();
    let predicted = read_poses(&out.join("poses_predicted.csv")).unwrap();
    assert_eq!(poses.len(), predicted.len());
    let truth = SessionReader::open(fixture()).unwrap().truth().unwrap().unwrap();
    let later = |seq: u64| truth.joints.iter().find(|(s, _, _)| *s == seq + 3).map(|(_, _, j)| *j);
    let moved = [
        Joint::Snout,
        Joint::Neck,
        Joint::MidBack,
        Joint::Rump,
        Joint::TailBase,
        Joint::LeftHip,
    ];
    let (mut held_mm, mut ahead_mm, mut n) = (0.0, 0.0, 0);
    for (now, ahead) in poses.iter().zip(&predicted) {
        assert_eq!(now.depth.seq, ahead.depth.seq);
        for joint in Joint::ALL.into_iter().filter(|j| !moved.contains(j) && j.index() >= 12) {
            assert_eq!(now.pose.joint(joint), ahead.pose.joint(joint), "{joint:?}");
        }
        assert_eq!(now.pose.joint(Joint::TailTip), ahead.pose.joint(Joint::TailTip));
        let Some(truth) = later(now.depth.seq) else { continue };
        for joint in moved
            .into_iter()
            .filter(|j| now.pose.joint(*j).position_mm.x.is_finite())
        {
            held_mm += (now.pose.joint(joint).position_mm - truth[joint.index()]).norm();
            ahead_mm += (ahead.pose.joint(joint).position_mm - truth[joint.index()]).norm();
            n += 1;
        }
    }
    assert!(n > 50, "{n} joints judged");
    let (held_mm, ahead_mm) = (held_mm / f64::from(n), ahead_mm / f64::from(n));
    eprintln!("100 ms ahead: predicted {ahead_mm:.2} mm from where the mouse then is, held {held_mm:.2} mm");
    assert!(ahead_mm < held_mm, "predicted {ahead_mm:.2} mm, held {held_mm:.2} mm");

    // A lead past a second, or with a batch: one sentence, refused.
    for args in [vec!["--lead", "5000"], vec!["--lead", "40", "a", "b"]] {
        let done = mousepose()
            .args([
                "replay",
                fixture().to_str().unwrap(),
                "--out",
                tmp.path().join("x").to_str().unwrap(),
            ])
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&done.stderr);
        assert!(!done.status.success() && stderr.contains("lead"), "{args:?}: {stderr}");
    }
}

#[test]
fn issue64_a_replay_pairs_as_a_live_partner_wait_and_reach_would_the_same_every_time() {
    let tmp = tempfile::tempdir().unwrap();
    // Colour frames taken a few ms after the depth frames (the renders' phase), arriving
    // about when the depth frames do.
    let session = tmp.path().join("session");
    synth(&session, 4.0, 123, true);
    let replay_with = |name: &str, args: &[&str]| -> serde_json::Value {
        let out = tmp.path().join(name);
        let done = mousepose()
            .args([
                "replay",
                session.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--json",
            ])
            .args(args)
            .output()
            .unwrap();
        assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
        serde_json::from_slice(&done.stdout).unwrap()
    };
    let paired = |s: &serde_json::Value| s["cameras"]["depth"]["paired"].as_u64().unwrap();
    let unproven = |s: &serde_json::Value| s["cameras"]["depth"]["paired_unproven"].as_u64().unwrap_or(0);
    let nearest = replay_with("nearest", &[]);
    let at_once = replay_with("at-once", &["--partner-wait", "0"]);
    let waited = replay_with("wait", &["--partner-wait", "3"]);
    let reached = replay_with("reach", &["--partner-wait", "3", "--partner-reach", "34"]);
    let again = replay_with("again", &["--partner-wait", "3", "--partner-reach", "34"]);
    // Not waiting for the later frame costs pairs, waiting 3 ms (ended by the recorded
    // arrivals, not this machine's clock) fewer; reaching back to the frame before wins
    // more back, decided at the end of the wait; and two replays pair alike.
    let counts = [&nearest, &at_once, &waited, &reached].map(paired);
    eprintln!("paired: nearest, no wait, 3 ms, 3 ms reaching 34 ms: {counts:?}");
    assert!(paired(&at_once) < paired(&waited), "{counts:?}");
    assert!(paired(&waited) < paired(&nearest), "{counts:?}");
    assert!(paired(&reached) > paired(&waited), "{counts:?}");
    assert!(unproven(&reached) > 0, "{reached}");
    assert_eq!(paired(&again), paired(&reached));
    let poses = |name: &str| std::fs::read_to_string(tmp.path().join(name).join("poses.csv")).unwrap();
    assert_eq!(poses("again"), poses("reach"));
    // A reach needs a wait.
    let done = mousepose()
        .args([
            "replay",
            session.to_str().unwrap(),
            "--out",
            tmp.path().join("x").to_str().unwrap(),
        ])
        .args(["--partner-reach", "34"])
        .output()
        .unwrap();
    assert!(!done.status.success());
}
