//! The built binary: `synth` commands end to end, determinism, and every bad input refused
//! with one clear sentence and a non-zero exit.

use crate::util::mousepose;
use mousepose::io::session::{CameraRole, SessionEvent, SessionReader};
use std::fs;
use std::path::Path;
use std::process::Output;
use std::time::{Duration, Instant};

fn run(args: &[&str]) -> Output {
    mousepose().args(args).output().expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).expect("dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let name = p.strip_prefix(dir).expect("inside").to_string_lossy().into_owned();
                out.push((name, fs::read(&p).expect("read")));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn synth_dataset_is_deterministic_and_readable() {
    let tmp = tempfile::tempdir().expect("tmp");
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    for out in [&a, &b] {
        let o = run(&[
            "synth",
            "dataset",
            "--out",
            out.to_str().unwrap(),
            "--images",
            "24",
            "--seed",
            "5",
            "--noise-mm",
            "1.5",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    assert_eq!(files(&a), files(&b), "same seed, different bytes");
    let ds = mousepose::synth::dataset::Dataset::open(&a).expect("opens");
    let samples = ds.load().expect("loads");
    assert_eq!(samples.len(), 24);
    assert!(samples.iter().all(|s| s.bottom.is_some()));
    assert_eq!(ds.meta.seed, 5);
}

#[test]
fn synth_session_is_deterministic_and_round_trips() {
    let tmp = tempfile::tempdir().expect("tmp");
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    for out in [&a, &b] {
        let o = run(&[
            "synth",
            "session",
            "--out",
            out.to_str().unwrap(),
            "--seconds",
            "2",
            "--seed",
            "9",
            "--color-binning",
            "4",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    assert_eq!(files(&a), files(&b), "same seed, different bytes");
    assert!(a.join("preview.png").exists());

    let s = SessionReader::open(&a).expect("opens");
    assert!(s.complete());
    assert!(s.damage().is_clean());
    let depth: Vec<_> = s.depth_frames().collect::<Result<_, _>>().expect("depth frames");
    let color: Vec<_> = s
        .color_frames()
        .expect("colour")
        .collect::<Result<_, _>>()
        .expect("colour frames");
    let events = s.events().expect("events");
    let drops = |role| {
        events
            .iter()
            .filter_map(|e| match e {
                SessionEvent::FramesDropped { role: r, count, .. } if *r == role => Some(*count),
                _ => None,
            })
            .sum::<u64>()
    };
    // 60 depth frames planned; every one is either in the file or logged as dropped.
    assert_eq!(depth.len() as u64 + drops(CameraRole::Depth), 60);
    assert!(
        drops(CameraRole::Depth) >= 1 && drops(CameraRole::Color) >= 1,
        "an occasional drop"
    );
    let first_color = color.first().expect("frames").stamp.seq;
    assert_eq!(
        color.last().expect("frames").stamp.seq - first_color + 1,
        color.len() as u64 + drops(CameraRole::Color)
    );
    for w in depth.windows(2) {
        assert!(w[1].stamp.seq > w[0].stamp.seq);
        assert!(w[1].stamp.device_ns > w[0].stamp.device_ns);
        assert!(w[1].stamp.host_ns > w[0].stamp.host_ns);
    }
    // The two device clocks are far apart; the host clock is shared.
    let dd = depth[0].stamp.device_ns as i128 - color[0].stamp.device_ns as i128;
    assert!(dd.abs() > 1_000_000_000, "device clocks should be offset");
    let hd = depth[0].stamp.host_ns as i128 - color[0].stamp.host_ns as i128;
    assert!(hd.abs() < 50_000_000);
    // Frames carry real content: a floor at about 600 mm and a mouse above it.
    let d = &depth[10];
    assert_eq!((d.width, d.height), (640, 480));
    let centre = d.data[240 * 640 + 320];
    assert!(centre == 0 || (585..=615).contains(&centre), "floor at {centre}");
    assert!(d.data.iter().any(|&z| z > 0 && z < 590));
    assert_eq!((color[0].width, color[0].height), (320, 256));
    // Ground truth for every depth frame written, and the true pairing.
    let truth = s.truth().expect("truth").expect("synthetic");
    assert_eq!(truth.joints.len(), depth.len());
    assert_eq!(truth.pairs.len(), depth.len());
    assert!(truth.pairs.iter().filter(|(_, c)| c.is_some()).count() >= depth.len() - 3);
}

#[test]
fn non_empty_output_is_refused_unless_forced() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    fs::create_dir(&out).expect("mkdir");
    fs::write(out.join("keep.txt"), "precious").expect("write");
    let args = ["synth", "dataset", "--out", out.to_str().unwrap(), "--images", "2"];
    let o = run(&args);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("not empty"), "{}", stderr(&o));
    assert!(
        out.join("keep.txt").exists(),
        "refused run must not touch the directory"
    );
    let o = run(&[&args[..], &["--force"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!out.join("keep.txt").exists());
    assert!(out.join("dataset.toml").exists());
    // An empty directory is fine without --force; a file in the way is not.
    let empty = tmp.path().join("empty");
    fs::create_dir(&empty).expect("mkdir");
    assert!(
        run(&["synth", "dataset", "--out", empty.to_str().unwrap(), "--images", "1"])
            .status
            .success()
    );
    let file = tmp.path().join("file");
    fs::write(&file, "x").expect("write");
    let o = run(&["synth", "session", "--out", file.to_str().unwrap(), "--seconds", "1"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("not a directory"), "{}", stderr(&o));
}

#[test]
fn bad_numbers_are_refused_with_one_sentence() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let out = out.to_str().unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["synth", "dataset", "--out", out, "--images", "-5"], "-5"),
        (&["synth", "dataset", "--out", out, "--images", "0"], "from 1"),
        (
            &["synth", "dataset", "--out", out, "--images", "99999999999"],
            "99999999999",
        ),
        (&["synth", "dataset", "--out", out, "--images", "lots"], "lots"),
        (
            &["synth", "dataset", "--out", out, "--images", "3", "--noise-mm", "-1"],
            "noise",
        ),
        (
            &[
                "synth",
                "dataset",
                "--out",
                out,
                "--images",
                "3",
                "--noise-model",
                "fog",
            ],
            "fog",
        ),
        (&["synth", "session", "--out", out, "--seconds", "0"], "seconds"),
        (&["synth", "session", "--out", out, "--seconds", "-3"], "seconds"),
        (&["synth", "session", "--out", out, "--seconds", "1e9"], "seconds"),
        (
            &["synth", "session", "--out", out, "--seconds", "1", "--fps", "0"],
            "frame rate",
        ),
        (
            &[
                "synth",
                "session",
                "--out",
                out,
                "--seconds",
                "1",
                "--color-binning",
                "3",
            ],
            "binning",
        ),
    ];
    for (args, needle) in cases {
        let o = run(args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        let first = stderr(&o).lines().next().unwrap_or_default().to_owned();
        assert!(
            first.starts_with("error:") && first.contains(needle),
            "{args:?}: {first}"
        );
    }
    assert!(!Path::new(out).exists(), "nothing written on bad input");
}

/// Issue 31 item 6: every floating-point flag of every command refuses `nan`, infinities
/// and values below its range in one sentence (exit code 1), never a panic.
#[test]
fn issue31_every_float_flag_refuses_nan_infinity_and_negatives() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let out = out.to_str().unwrap();
    let rig = tmp.path().join("rig.toml");
    let rig = rig.to_str().unwrap();
    // Each command with its float flag last; the value is joined to it.
    let commands: &[&[&str]] = &[
        &["run", "--config", rig, "--seconds"],
        &["record", "--config", rig, "--out", out, "--seconds"],
        &["synth", "session", "--out", out, "--seconds"],
        &["synth", "session", "--out", out, "--seconds", "1", "--fps"],
        &["synth", "dataset", "--out", out, "--images", "3", "--noise-mm"],
        &["synth", "chessboard", "--out", out, "--square-mm"],
        &[
            "calibrate",
            "intrinsics",
            "--images",
            "*.png",
            "--out",
            out,
            "--square-mm",
        ],
        &[
            "calibrate",
            "extrinsics",
            "--depth-intrinsics",
            "d.yml",
            "--color-intrinsics",
            "c.yml",
            "--depth-image",
            "d.png",
            "--color-image",
            "c.png",
            "--out",
            out,
            "--square-mm",
        ],
        &["train", "body", "--data", out, "--out", out, "--subset"],
        &["export", "video", out, "--out", "v.mp4", "--from"],
        &["export", "video", out, "--out", "v.mp4", "--to"],
        &["detect", "paws", "a.png", "--out", out, "--px-per-mm"],
        &["detect", "paws", "a.png", "--out", out, "--find-scale"],
        &[
            "eval",
            "paws",
            "--labels",
            "l.csv",
            "--label-px-per-mm",
            "3",
            "--find-scale",
        ],
    ];
    for command in commands {
        for value in ["nan", "NaN", "inf", "-inf", "-1"] {
            // `--flag=value`: clap takes `-inf` after a space for a flag of its own.
            let (flag, rest) = command.split_last().unwrap();
            let joined = format!("{flag}={value}");
            let mut args = rest.to_vec();
            args.push(&joined);
            let o = run(&args);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
            assert!(!err.contains("panicked"), "{args:?}: {err}");
            let first = err.lines().next().unwrap_or_default();
            assert!(first.starts_with("error:") && first.contains(value), "{args:?}: {err}");
        }
    }
    // A range of scales upside down.
    let o = run(&["detect", "paws", "a.png", "--out", out, "--find-scale", "4:3"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error:") && err.contains("above the highest"), "{err}");
    // A scale told and searched for at once.
    let o = run(&[
        "detect",
        "paws",
        "a.png",
        "--out",
        out,
        "--find-scale",
        "3:4",
        "--px-per-mm",
        "3",
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.starts_with("error:") && err.contains("--find-scale"), "{err}");
    assert!(!Path::new(out).exists(), "nothing written on bad input");
}

#[test]
fn unwritable_output_is_a_clear_error() {
    let o = run(&[
        "synth",
        "dataset",
        "--out",
        "/proc/mousepose-cannot-write/here",
        "--images",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.starts_with("error:") && e.contains("/proc/mousepose-cannot-write"),
        "{e}"
    );
    assert!(!e.contains("panicked"));
}

#[test]
fn an_interrupted_run_leaves_nothing_that_looks_complete() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("session");
    let mut child = mousepose()
        .args([
            "synth",
            "session",
            "--out",
            out.to_str().unwrap(),
            "--seconds",
            "600",
            "--color-binning",
            "4",
        ])
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("starts");
    // Wait until it is writing frames, then kill it hard.
    let deadline = Instant::now() + Duration::from_secs(60);
    let staging_has_frames = || {
        fs::read_dir(tmp.path()).expect("dir").flatten().any(|e| {
            let p = e.path().join("depth").join("frames.mpstore");
            fs::metadata(p).map(|m| m.len() > 100_000).unwrap_or(false)
        })
    };
    while !staging_has_frames() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    child.kill().expect("kill");
    child.wait().expect("wait");
    assert!(!out.exists(), "a killed run left {out:?} looking complete");
    let leftovers: Vec<_> = fs::read_dir(tmp.path())
        .expect("dir")
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert!(
        leftovers.iter().all(|n| n.to_string_lossy().contains(".partial-")),
        "{leftovers:?}"
    );
}

/// `train orientation` fits the body-shape model to a dataset's mice (tails hidden and shown)
/// and `eval orientation` measures it; a damaged model file is refused with one sentence.
#[test]
fn train_and_eval_orientation_on_the_fixture_dataset() {
    let tmp = tempfile::tempdir().expect("tmp");
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/datasets/small");
    let model = tmp.path().join("orientation.json");
    let o = run(&["train", "orientation", "--data", data, "--out", model.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = fs::read_to_string(&model).expect("written");
    assert!(text.len() < 8_000, "{} bytes", text.len());
    let o = run(&[
        "eval",
        "orientation",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data,
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    // 24 images, four views each (tail hidden and shown, full and half resolution).
    assert!(v["views"].as_u64().is_some_and(|n| n > 80), "{v}");
    assert!(v["tail_hidden"].as_f64().is_some_and(|a| a > 0.9), "{v}");
    // The bundled model on the same images (engine 2's mice).
    let bundled = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/models/orientation.json");
    let o = run(&["eval", "orientation", "--model", bundled, "--data", data, "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert!(v["accuracy"].as_f64().is_some_and(|a| a > 0.95), "{v}");
    fs::write(&model, "{\"format\": 3}").expect("write");
    let o = run(&[
        "eval",
        "orientation",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data,
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("is not an orientation model"), "{}", stderr(&o));
}

#[test]
fn train_and_eval_body_and_parts_on_the_fixture_dataset() {
    let tmp = tempfile::tempdir().expect("tmp");
    let data = crate::util::repo_root().join("fixtures/datasets/small");
    let data = data.to_str().expect("utf-8");
    let body = tmp.path().join("body.forest");
    let small = ["--trees", "2", "--depth", "6", "--tests", "10", "--pixels", "30"];
    let o = run(&[
        &["train", "body", "--data", data, "--out", body.to_str().unwrap()][..],
        &small,
    ]
    .concat());
    assert!(o.status.success(), "{}", stderr(&o));
    // A model is never overwritten silently.
    let o = run(&[
        &["train", "body", "--data", data, "--out", body.to_str().unwrap()][..],
        &small,
    ]
    .concat());
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--force"));

    let report = tmp.path().join("report");
    let o = run(&[
        "eval",
        "body",
        "--model",
        body.to_str().unwrap(),
        "--data",
        data,
        "--json",
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert!(v["mean_error_mm"].as_f64().is_some_and(|e| e > 0.0 && e < 100.0), "{v}");
    let per_joint = v["per_joint_mm"].as_object().expect("per_joint_mm");
    assert_eq!(per_joint.len(), 12);
    assert!(per_joint.contains_key("snout") && per_joint.contains_key("right_hip"));
    assert!(report.join("joint_error.png").exists() && report.join("error_vs_noise.png").exists());

    let parts = tmp.path().join("parts.forest");
    let o = run(&[
        &[
            "train",
            "parts",
            "--data",
            data,
            "--out",
            parts.to_str().unwrap(),
            "--discriminative",
            data,
            "--json",
        ][..],
        &small,
    ]
    .concat());
    assert!(o.status.success(), "{}", stderr(&o));
    // --json: what was written, as one JSON object.
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["out"], parts.to_str().unwrap());
    assert_eq!(
        (v["kind"].as_str(), v["trees"].as_u64()),
        (Some("parts"), Some(2)),
        "{v}"
    );
    assert!(v["nodes"].as_u64().is_some_and(|n| n > 1), "{v}");
    let o = run(&[
        "eval",
        "parts",
        "--model",
        parts.to_str().unwrap(),
        "--data",
        data,
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(
        v["per_class_accuracy"].as_object().expect("per_class_accuracy").len(),
        6
    );

    // The wrong kind of model, a damaged one and a foreign file: one clear sentence each.
    let o = run(&["eval", "parts", "--model", body.to_str().unwrap(), "--data", data]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("holds a body forest, expected a part forest"),
        "{}",
        stderr(&o)
    );
    let damaged = tmp.path().join("damaged.forest");
    let mut bytes = fs::read(&body).expect("read");
    bytes.truncate(bytes.len() / 2);
    fs::write(&damaged, bytes).expect("write");
    let o = run(&["eval", "body", "--model", damaged.to_str().unwrap(), "--data", data]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("damaged.forest") && stderr(&o).contains("damaged"),
        "{}",
        stderr(&o)
    );
    let o = run(&["eval", "body", "--model", data, "--data", data]);
    assert_ne!(o.status.code(), Some(0));
    assert!(!stderr(&o).contains("panicked"));
}

/// Every flag and argument of `cmd` and its subcommands, as "path --flag", that `--help`
/// shows without a description; and every subcommand without one.
fn undescribed(cmd: &clap::Command, path: &str, found: &mut Vec<String>) {
    for arg in cmd.get_arguments() {
        if arg.is_hide_set() || ["help", "version"].contains(&arg.get_id().as_str()) {
            continue;
        }
        let described = arg
            .get_help()
            .or(arg.get_long_help())
            .is_some_and(|h| !h.to_string().trim().is_empty());
        if !described {
            let name = arg
                .get_long()
                .map_or_else(|| arg.get_id().to_string(), |l| format!("--{l}"));
            found.push(format!("{path} {name}"));
        }
    }
    for sub in cmd.get_subcommands() {
        let sub_path = format!("{path} {}", sub.get_name());
        if sub.get_about().is_none_or(|a| a.to_string().trim().is_empty()) {
            found.push(sub_path.clone());
        }
        undescribed(sub, &sub_path, found);
    }
}

#[test]
fn every_command_and_flag_has_a_description_in_its_help() {
    let mut found = Vec::new();
    undescribed(&mousepose::app::cli(), "mousepose", &mut found);
    assert!(found.is_empty(), "without a description in --help: {found:#?}");
    // What the walk reads is what --help prints.
    let help = run(&["export", "nwb", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(
        text.contains("--experimenter <NAME>") && text.contains("Who ran the experiment"),
        "{text}"
    );
}

#[test]
fn an_invalid_rust_log_is_refused_with_one_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = mousepose()
        .args(["synth", "session", "--seconds", "0.1", "--out"])
        .arg(&out)
        .env("RUST_LOG", "verbose")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = stderr(&o);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("RUST_LOG=\"verbose\" is not a log filter"), "{err}");
    assert!(!out.exists());
}

#[test]
fn synth_commands_print_what_they_wrote_as_json() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dataset = tmp.path().join("d");
    let o = run(&[
        "synth",
        "dataset",
        "--images",
        "2",
        "--json",
        "--out",
        dataset.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(v["out"], dataset.to_str().unwrap());
    assert_eq!(v["images"], 2);

    let session = tmp.path().join("s");
    let o = run(&[
        "synth",
        "session",
        "--seconds",
        "0.2",
        "--json",
        "--out",
        session.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let reader = SessionReader::open(&session).expect("a session");
    assert_eq!(v["depth_frames"], reader.depth_count());
    assert_eq!(v["color_frames"], reader.color_count());
    assert!(Path::new(v["preview"].as_str().expect("preview")).is_file(), "{v}");

    let boards = tmp.path().join("c");
    let o = run(&[
        "synth",
        "chessboard",
        "--views",
        "1",
        "--json",
        "--out",
        boards.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(
        (v["out"].as_str(), v["views"].as_u64()),
        (boards.to_str(), Some(1)),
        "{v}"
    );
}
