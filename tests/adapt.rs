//! `mousepose adapt` on recordings whose mouse is known: a MoSeq-layout recording of a mouse
//! rendered 1.2 times the standard size and 1.15 times its girth must be measured as such,
//! the models written beside (never over) the bundled ones, and the judging replays must name
//! the models that made them, with their hashes. Bad recordings get one sentence.
#![allow(clippy::unwrap_used)] // test code

use crate::util::mousepose;
use std::path::Path;

/// A synthetic MoSeq recording of `frames` frames into `dir`, of a mouse of the given build.
fn recording(dir: &Path, frames: u32, scale: f64, girth: f64) {
    recording_as(dir, frames, scale, girth, &[]);
}

/// [`recording`] with more arguments of `synth moseq`.
fn recording_as(dir: &Path, frames: u32, scale: f64, girth: f64, more: &[&str]) {
    let out = mousepose()
        .args(["synth", "moseq", "--frames", &frames.to_string(), "--seed", "5"])
        .args(["--scale", &scale.to_string(), "--girth", &girth.to_string()])
        .args(more)
        .arg("--out")
        .arg(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Runs `adapt` with small sizes; its exit status, stdout and stderr.
fn adapt(args: &[&std::ffi::OsStr]) -> (std::process::ExitStatus, String, String) {
    let out = mousepose()
        .arg("adapt")
        .args(args)
        .args([
            "--images", "80", "--trees", "1", "--depth", "10", "--frames", "60", "--json",
        ])
        .output()
        .unwrap();
    (
        out.status,
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `adapt` of `rec` into `models`, judged on frames 30..; what it printed (`adapt.json`).
fn adapt_judging_from_30(rec: &Path, models: &Path) -> serde_json::Value {
    let (status, stdout, stderr) = adapt(&[
        rec.as_os_str(),
        "--out".as_ref(),
        models.as_os_str(),
        "--judge-frames".as_ref(),
        "30:".as_ref(),
    ]);
    // The status too: a process ended by a signal writes nothing of its own.
    assert!(status.success(), "{status}: {stderr}");
    serde_json::from_str(stdout.trim()).unwrap()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn adapt_measures_a_larger_rendered_mouse_and_writes_models_that_the_replays_name() {
    let tmp = tempfile::tempdir().unwrap();
    let (rec, models) = (tmp.path().join("rec"), tmp.path().join("models"));
    recording(&rec, 90, 1.2, 1.15);
    let s = adapt_judging_from_30(&rec, &models);
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("{v} in {s}"));
    // The build is fitted so that the rendered mouse measures as the recording's: its size
    // and girth are the recording's mouse's (within 5 %).
    assert!((f(&s["build"]["scale"]) - 1.2).abs() <= 0.06, "{}", s["build"]);
    assert!((f(&s["build"]["girth"]) - 1.15).abs() <= 0.06, "{}", s["build"]);
    let measured = f(&s["measured"]["length_mm"]["p50"]);
    let standard = f(&s["standard"]["length_mm"]["p50"]);
    assert!(
        (measured / standard - 1.2).abs() <= 0.08,
        "{measured} against {standard}"
    );
    assert!(
        (f(&s["fitted"]["length_mm"]["p50"]) / measured - 1.0).abs() <= 0.05,
        "{s}"
    );
    // The camera the recording was rendered with: 670 mm above the floor, fx 365 px.
    let r = &s["recordings"][0];
    assert!((f(&r["camera_height_mm"]) - 670.0).abs() <= 10.0, "{r}");
    assert!((f(&r["mm_per_px"]) - 670.0 / 365.0).abs() <= 0.05, "{r}");
    for file in ["body.forest", "orientation.json", "adapt.json"] {
        assert!(models.join(file).is_file(), "{file}");
    }
    // Judged before and after on frames 30.., each replay naming its models.
    let judged = &s["judged"][0];
    assert_eq!(judged["frames"]["start"], 30, "{judged}");
    assert!(f(&judged["adapted"]["frames"]) >= 50.0, "{judged}");
    let adapted = json(&Path::new(judged["adapted_run"].as_str().unwrap()).join("summary.json"));
    let bundled = json(&Path::new(judged["bundled_run"].as_str().unwrap()).join("summary.json"));
    assert_eq!(adapted["models"]["bundled"], false, "{}", adapted["models"]);
    assert_eq!(bundled["models"]["bundled"], true, "{}", bundled["models"]);
    let hash = |v: &serde_json::Value| {
        v["models"]["files"]["body.forest"]["sha256"]
            .as_str()
            .unwrap()
            .to_owned()
    };
    let bytes = std::fs::read(models.join("body.forest")).unwrap().len() as u64;
    assert_eq!(adapted["models"]["files"]["body.forest"]["bytes"], bytes);
    assert_eq!(hash(&adapted).len(), 64);
    assert_ne!(hash(&adapted), hash(&bundled));
}

/// The same recording as `depth.avi` (`synth moseq --video`) adapts and judges exactly as
/// its `depth.dat`: the judged frames (from frame 30: one ffmpeg seeking there) are the same.
#[test]
fn a_depth_avi_adapts_and_judges_as_its_depth_dat() {
    let tmp = tempfile::tempdir().unwrap();
    let mut figures = Vec::new();
    for (name, more) in [("dat", &[][..]), ("avi", &["--video"][..])] {
        let rec = tmp.path().join(name);
        recording_as(&rec, 60, 1.0, 1.0, more);
        let file = if more.is_empty() { "depth.dat" } else { "depth.avi" };
        assert!(rec.join(file).is_file(), "{name}");
        let models = tmp.path().join(format!("models-{name}"));
        let s = adapt_judging_from_30(&rec, &models);
        let judged = &s["judged"][0];
        assert!(judged["adapted"]["frames"].as_u64().unwrap() >= 25, "{judged}");
        figures.push((s["build"].clone(), judged["bundled"].clone(), judged["adapted"].clone()));
    }
    assert_eq!(figures[0], figures[1]);
}

#[test]
fn adapt_refuses_a_recording_too_short_or_without_a_mouse_in_one_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = tmp.path().join("rec");
    recording(&rec, 40, 1.0, 1.0);
    let (status, _, stderr) = adapt(&[
        rec.as_os_str(),
        "--out".as_ref(),
        tmp.path().join("m1").as_os_str(),
        "--learn-frames".as_ref(),
        "0:20".as_ref(),
    ]);
    assert!(!status.success());
    assert!(stderr.contains("has 20 frames to learn from"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");

    // An empty arena: a flat floor 670 mm away in every frame.
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let frame: Vec<u8> = (0..512 * 424)
        .flat_map(|k: u32| (670 + (k % 3) as u16).to_le_bytes())
        .collect();
    std::fs::write(empty.join("depth.dat"), frame.repeat(40)).unwrap();
    let ts: String = (0..40).map(|k| format!("{}\n", 1000 + k * 33)).collect();
    std::fs::write(empty.join("depth_ts.txt"), ts).unwrap();
    let (status, _, stderr) = adapt(&[empty.as_os_str(), "--out".as_ref(), tmp.path().join("m2").as_os_str()]);
    assert!(!status.success());
    assert!(stderr.contains("no mouse found"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(!tmp.path().join("m2").exists());

    // Not a recording at all.
    let (status, _, stderr) = adapt(&[
        tmp.path().join("m1").as_os_str(),
        "--out".as_ref(),
        tmp.path().join("m3").as_os_str(),
    ]);
    assert!(!status.success());
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
}
