//! A real mouse in the suite: the MoSeq project's test session (a real mouse on a real round
//! arena, seen from above by a Kinect v2 in 2017; moseq2-extract's results file), rebuilt into
//! a whole recording by `scripts/real-moseq-session build` (each of MoSeq's crops pasted back,
//! rotated, into its background at its centroid), replayed with the bundled models, and
//! compared with MoSeq's own tracker by `scripts/real-moseq-session compare`.
//!
//! The data is not ours and is not in the repository: it is read from `../shared/realdata/`
//! beside the repository, or from `$MOUSEPOSE_REALDATA`. Its licence allows research use only,
//! so no bundled model learns from it; it is only judged on. Without it, the test says so and
//! passes without judging.
#![allow(clippy::unwrap_used)] // test code

use crate::util::{mousepose, replay_options, repo_root};
use mousepose::engine::project_python;
use mousepose::engine::replay::replay;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A file of the real data, when it is there.
fn real_file(name: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("MOUSEPOSE_REALDATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join("../shared/realdata"));
    let file = dir.join(name);
    if file.is_file() {
        Some(file)
    } else {
        eprintln!("skipped: no real data at {} (set MOUSEPOSE_REALDATA)", file.display());
        None
    }
}

/// moseq2-extract's results file of the real session, when it is there.
pub(crate) fn moseq_results() -> Option<PathBuf> {
    real_file("moseq2-viz/results_00.h5")
}

/// Runs `scripts/real-moseq-session` with `args`; its stdout.
pub(crate) fn script(args: &[&OsStr]) -> String {
    let out = Command::new(project_python())
        .arg(repo_root().join("scripts/real-moseq-session"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "real-moseq-session {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// The figures of the real session rebuilt with the background's pixels without a reading
/// kept (`keep`, as the Kinect gave them) or filled (`fill`), replayed and reported; and the
/// report's `summary.json`.
fn figures(results: &Path, no_reading: &str, dir: &Path) -> (serde_json::Value, serde_json::Value) {
    let (f, report) = figures_with(results, &["--no-reading", no_reading], dir, true);
    (f, report.unwrap_or_default())
}

/// The figures of the real session rebuilt with the `build` options `options` and replayed,
/// and with `report` reported too (the report's `summary.json`), as [`figures`].
fn figures_with(
    results: &Path,
    options: &[&str],
    dir: &Path,
    report: bool,
) -> (serde_json::Value, Option<serde_json::Value>) {
    let (recording, run, report_dir) = (dir.join("rec"), dir.join("run"), dir.join("report"));
    let mut args: Vec<&OsStr> = vec!["build".as_ref(), results.as_os_str(), recording.as_os_str()];
    args.extend(options.iter().map(OsStr::new));
    script(&args);
    replay(&replay_options(&recording, &run, 2)).unwrap();
    let mut compare: Vec<&OsStr> = vec!["compare".as_ref(), recording.as_os_str(), run.as_os_str()];
    if report {
        let status = mousepose()
            .arg("report")
            .arg(&run)
            .arg("--out")
            .arg(&report_dir)
            .output()
            .unwrap();
        assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
        compare.push(report_dir.as_os_str());
    }
    let line = script(&compare);
    let reported =
        report.then(|| serde_json::from_slice(&std::fs::read(report_dir.join("summary.json")).unwrap()).unwrap());
    (serde_json::from_str(line.trim()).unwrap(), reported)
}

/// Issue 41, item 2, on the recording as the Kinect gave it (no reading outside the arena).
/// Goals met: found in every frame; body axis within 6 degrees of MoSeq's at the median, 20 at
/// the 95th percentile; the head leading in 98 % of the frames where the mouse travels faster
/// than 100 mm/s; the report's turning within 20 % of MoSeq's. The centre (the replay's
/// `mid_back` against MoSeq's centroid; issue 49, item 2) within 1.5 px at the median and 3 at
/// the 95th percentile over all 900 frames (1.15 and 2.64 with `mid_back` placed along the body
/// by the spine and across it on the ridge of the back; on frames 450-899, not looked at when
/// its settings were chosen, 1.04 and 2.31: see docs/FIGURES.md).
#[test]
fn a_real_mouse_is_found_in_every_frame_along_moseqs_axis_and_its_head_leads_its_travel() {
    let Some(results) = moseq_results() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let (f, report) = figures(&results, "keep", tmp.path());
    let get = |key: &str| f[key].as_f64().unwrap_or_else(|| panic!("{key} in {f}"));
    assert_eq!(get("found"), get("frames"), "{f}");
    assert!(get("axis_deg_median") <= 6.0, "{f}");
    assert!(get("axis_deg_p95") <= 20.0, "{f}");
    assert!(get("moving_frames") >= 100.0, "{f}");
    assert!(get("head_leading") >= 0.98 * get("moving_frames"), "{f}");
    // The same by our own centre's travel over 9 frames (over 5, 5 frames of about 180 move
    // backward, the body shortening from the front and the mouse sliding out of view).
    assert!(get("moving_frames_own") >= 100.0, "{f}");
    assert!(get("head_leading_own") >= 0.98 * get("moving_frames_own"), "{f}");
    // Issue 49, item 1: no heading turned 180 degrees and back within one or two frames.
    assert_eq!(get("brief_reversals"), 0.0, "{f}");
    // Issue 49, item 5: MoSeq's tail filter removed this mouse's tail: no tail is seen.
    assert_eq!(get("tails_seen"), 0.0, "{f}");
    assert_eq!(get("tails_frames"), get("found"), "{f}");
    let turned = get("report_turned_deg") / get("moseq_turned_deg");
    assert!((0.8..=1.2).contains(&turned), "turned {turned:.2}x MoSeq's: {f}");
    assert!(get("centre_px_median") <= 1.5, "{f}");
    assert!(get("centre_px_p95") <= 3.0, "{f}");
    // Item 4: the round arena is zoned by its own outline, which is round (a square's corners
    // reach 1.41 times as far as its sides).
    let reach: Vec<f64> = report["arena"]["outline"]["reach_mm"]
        .as_array()
        .unwrap_or_else(|| panic!("no outline: {}", report["arena"]))
        .iter()
        .filter_map(serde_json::Value::as_f64)
        .collect();
    let (low, high) = reach
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), &r| (l.min(r), h.max(r)));
    assert!(high / low < 1.1, "{reach:?}");
}

/// The share of frames in which a tail drawn on as a Kinect reads one must be seen (broken by
/// noise it was seen in 77-78 % of the frames on two seeds; whole, thin or against the wall in
/// 88-94 %).
const TAIL_SEEN_SHARE: f64 = 0.7;

/// Issue 49, items 5 and 1: the same real mouse with a tail drawn back on as a Kinect reads one
/// (`scripts/real-moseq-session build --tail`: faint, 18 mm high at the rump to 7 at the tip),
/// whole, cut by noise into two or three pieces, 2 px wide, and bent to lie against the wall.
/// The tail is seen in most frames, and head and tail are swapped in at most 2 % of them,
/// never in a frame alone (the head: MoSeq's axis followed from frame to frame, its sign from
/// the travel).
#[test]
fn a_real_mouse_with_a_kinects_tail_is_seen_with_it_and_never_flips_for_a_frame() {
    let Some(results) = moseq_results() else { return };
    for kind in ["whole", "broken", "thin", "wall"] {
        let tmp = tempfile::tempdir().unwrap();
        let (f, _) = figures_with(&results, &["--no-reading", "keep", "--tail", kind], tmp.path(), false);
        let get = |key: &str| f[key].as_f64().unwrap_or_else(|| panic!("{kind}: {key} in {f}"));
        eprintln!(
            "{kind}: a tail seen in {} of {} frames, {} swapped ({} alone)",
            get("tails_seen"),
            get("tails_frames"),
            get("swapped"),
            get("swapped_alone")
        );
        assert_eq!(get("found"), get("frames"), "{kind}: {f}");
        assert!(get("tails_seen") >= TAIL_SEEN_SHARE * get("frames"), "{kind}: {f}");
        assert!(get("swapped") <= 0.02 * get("frames"), "{kind}: {f}");
        assert_eq!(get("swapped_alone"), 0.0, "{kind}: {f}");
        assert_eq!(get("brief_reversals"), 0.0, "{kind}: {f}");
    }
}

/// Issue 64, item 1: the same real mouse with strands of bedding laid at the arena's rim where
/// its snout comes near it (`scripts/real-moseq-session build --clutter 8`), from a third of
/// the way in. The snout touches them: a strand joined to it reads as a tail at the head's end
/// in a few frames, and as part of the body in others. Before the tail had to show it was one
/// (seen two frames running, not reaching a wall) and the strands at the wall were left out of
/// the body's shape, 18 frames were swapped in three runs; now none is, and the real mouse is
/// still found where MoSeq found it.
#[test]
fn a_real_mouse_nosing_at_clutter_at_the_rim_keeps_its_head() {
    let Some(results) = moseq_results() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let (f, _) = figures_with(&results, &["--no-reading", "keep", "--clutter", "8"], tmp.path(), false);
    let get = |key: &str| f[key].as_f64().unwrap_or_else(|| panic!("{key} in {f}"));
    eprintln!(
        "clutter: a tail seen in {} of {} frames, {} swapped ({} alone)",
        get("tails_seen"),
        get("tails_frames"),
        get("swapped"),
        get("swapped_alone")
    );
    assert_eq!(get("found"), get("frames"), "{f}");
    // The clutter touched the snout and read as a tail there.
    assert!(get("tails_seen") >= 3.0, "{f}");
    assert!(get("swapped") <= 0.005 * get("frames"), "{f}");
    assert_eq!(get("swapped_alone"), 0.0, "{f}");
    assert_eq!(get("brief_reversals"), 0.0, "{f}");
    assert!(get("centre_px_median") <= 1.5, "{f}");
}

/// Paws learnt from a lab's labelled real frames (Lightning Pose's mirror-mouse bottom views,
/// MIT), judged only on frames each cascade did not learn from: two folds of contiguous
/// frames, a short cascade (the full figures, five folds and 20 stages, are in FIGURES.md).
/// The bottom view is found from the labels, and the scale when not told.
#[test]
fn paws_learnt_from_labelled_real_frames_are_found_on_frames_held_out() {
    let Some(labels) = real_file("mirror-mouse/CollectedData.csv") else {
        return;
    };
    let f = eval_mirror_mouse(&labels, &["--folds", "2", "--stages", "12"]);
    eprintln!("{f:#}");
    assert!(
        f["bottom_view"].as_str().unwrap().starts_with("row 16"),
        "{}",
        f["bottom_view"]
    );
    let (told, found) = (&f["told_scale"], &f["found_scale"]);
    assert_eq!(told["paws"], 180);
    for (what, r) in [("told", told), ("found", found)] {
        let (recall, precision) = (r["recall"].as_f64().unwrap(), r["precision"].as_f64().unwrap());
        assert!(
            recall >= 0.85 && precision >= 0.5,
            "scale {what}: recall {recall}, precision {precision}"
        );
    }
    for s in found["px_per_mm"].as_array().unwrap() {
        let s = s.as_f64().unwrap();
        assert!((3.0..4.1).contains(&s), "scale found {s} px/mm, true 3.5");
    }
}

/// The paw network learns from the labelled real frames (`train paws --net`, a short
/// training: its cross-validated figures, 3,000 iterations, are in FIGURES.md), is written as
/// `safetensors`, and is read and run by `eval paws --labels --model`: judged here on the
/// first 12 frames it learnt from, told their scale (the search for it, 33 scales on every
/// frame, took over 3 minutes on all 45 in the test build: `--find-scale` keeps it to one), so
/// this checks the plumbing, not the figure. A file not named `.safetensors` is refused before
/// any training.
#[test]
fn a_paw_network_learnt_from_labelled_real_frames_is_written_read_and_run() {
    let Some(labels) = real_file("mirror-mouse/CollectedData.csv") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // `train paws --net` on the labels, with `more` arguments.
    let train_with = |out: &Path, more: &[&OsStr]| {
        mousepose()
            .args(["train", "paws", "--labels"])
            .arg(&labels)
            .args([
                "--paws",
                MIRROR_MOUSE_PAWS,
                "--label-px-per-mm",
                "3.5",
                "--net",
                "--out",
            ])
            .arg(out)
            .args(more)
            .output()
            .unwrap()
    };
    // Eight channels instead of the default twelve: two thirds of the training's time, and the
    // width written in the file is read back from it (recall 0.73, precision 0.83 here; six
    // channels learnt nothing in 400 iterations, 200 iterations of twelve reached recall 0.5).
    let train = |out: &Path| {
        let args = ["--net-iterations", "400", "--net-width", "8", "--json"];
        train_with(out, &args.map(OsStr::new))
    };
    let wrong = tmp.path().join("paws.xml");
    let out = train(&wrong);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("safetensors") && !wrong.exists(), "{err}");
    let net = tmp.path().join("paws.safetensors");
    let out = train(&net);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let trained: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (trained["network"].as_bool(), trained["frames"].as_u64()),
        (Some(true), Some(45))
    );
    // The label file's first 12 frames, beside the frames' folder.
    let few = tmp.path().join("few");
    std::fs::create_dir(&few).unwrap();
    let text = std::fs::read_to_string(&labels).unwrap();
    let head: Vec<&str> = text.lines().take(3 + 12).collect();
    std::fs::write(few.join("CollectedData.csv"), head.join("\n") + "\n").unwrap();
    std::os::unix::fs::symlink(labels.with_file_name("labeled-data"), few.join("labeled-data")).unwrap();
    // Only the figures told the scale are judged here: the search for it looks at one scale.
    let f = eval_mirror_mouse(
        &few.join("CollectedData.csv"),
        &[
            "--model".as_ref(),
            net.as_os_str(),
            "--find-scale".as_ref(),
            "3.5:3.5".as_ref(),
        ],
    );
    assert_eq!(f["told_scale"]["frames"], 12, "{f}");
    assert_eq!(f["detector"], "network");
    assert!(
        f["min_neighbors"].is_null(),
        "a network has no grouping: {}",
        f["min_neighbors"]
    );
    let told = &f["told_scale"];
    let (recall, precision) = (told["recall"].as_f64().unwrap(), told["precision"].as_f64().unwrap());
    eprintln!("learnt frames, told the scale: recall {recall}, precision {precision}");
    assert!(
        recall >= 0.6 && precision >= 0.3,
        "recall {recall}, precision {precision}"
    );

    // With rendered views in half of each batch; one seed, one network, byte for byte (ten
    // iterations: each draws its batch and steps the optimiser as the thousands do).
    let data = tmp.path().join("renders");
    let out = mousepose()
        .args([
            "synth",
            "dataset",
            "--images",
            "8",
            "--seed",
            "77",
            "--bottom-clutter",
            "--out",
        ])
        .arg(&data)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mixed = |name: &str, seed: &str| {
        let path = tmp.path().join(name);
        let seed: &OsStr = seed.as_ref();
        let out = train_with(
            &path,
            &[
                "--data".as_ref(),
                data.as_os_str(),
                "--net-iterations".as_ref(),
                "10".as_ref(),
                "--seed".as_ref(),
                seed,
            ],
        );
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        std::fs::read(path).unwrap()
    };
    let first = mixed("a.safetensors", "3");
    assert!(first == mixed("b.safetensors", "3"), "one seed trained two networks");
    assert!(first != mixed("c.safetensors", "4"), "two seeds trained one network");
}

/// `eval paws --labels LABELS` with the mirror-mouse labels' paws at 3.5 px/mm and `more`
/// arguments; what it printed.
fn eval_mirror_mouse<S: AsRef<OsStr>>(labels: &Path, more: &[S]) -> serde_json::Value {
    let out = mousepose()
        .args(["eval", "paws", "--labels"])
        .arg(labels)
        .args(["--paws", MIRROR_MOUSE_PAWS, "--label-px-per-mm", "3.5", "--json"])
        .args(more)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{labels:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The mirror-mouse labels' mapping from its body parts to our paws.
const MIRROR_MOUSE_PAWS: &str =
    "paw1LH_bot=left_hind_paw,paw2LF_bot=left_fore_paw,paw3RF_bot=right_fore_paw,paw4RH_bot=right_hind_paw";

/// The same labels in DeepLabCut's `.h5` and SLEAP's `.slp` (on the image files, with the
/// frames kept in the file, and on a video), each written by its own tool's library
/// (`scripts/label-formats`), are read as the CSV is: the bundled cascade finds the same paws
/// in them, told the scale and not.
#[test]
fn labels_in_deeplabcuts_h5_and_sleaps_slp_are_read_as_the_csv_is() {
    let Some(csv) = real_file("mirror-mouse/CollectedData.csv") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let made = Command::new(project_python())
        .arg(repo_root().join("scripts/label-formats"))
        .arg(&csv)
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    let bundled = repo_root().join("fixtures/models/paws.xml");
    // The scale is looked for between 3 and 4.1 px/mm (4 candidates, where the full search's
    // 33 find 3.36-3.67): enough to compare what each file's frames give.
    let judge = |labels: &Path| {
        eval_mirror_mouse(
            labels,
            &[
                "--model".as_ref(),
                bundled.as_os_str(),
                "--find-scale".as_ref(),
                "3:4.1".as_ref(),
            ],
        )
    };
    let want = judge(&csv);
    assert_eq!(want["told_scale"]["paws"], 180);
    for name in ["CollectedData.h5", "labels.slp", "labels.pkg.slp", "labels-video.slp"] {
        let got = judge(&tmp.path().join(name));
        for key in ["bottom_view", "told_scale", "found_scale"] {
            assert_eq!(got[key], want[key], "{name}: {key}");
        }
    }
}

/// A view of one mouse keeps its four surest detections (`--max-paws`, 4 by default): the
/// bundled cascade grouping no windows finds more than four things in some mirror-mouse
/// views, and keeping the surest four drops false ones.
#[test]
fn a_view_of_one_mouse_keeps_its_four_surest_detections() {
    let Some(labels) = real_file("mirror-mouse/CollectedData.csv") else {
        return;
    };
    let bundled = repo_root().join("fixtures/models/paws.xml");
    let judge = |more: &[&str]| {
        let mut args = vec![
            "--model".as_ref(),
            bundled.as_os_str(),
            "--min-neighbors".as_ref(),
            "0".as_ref(),
            // Only the figures told the scale are judged: the search looks at one scale.
            "--find-scale".as_ref(),
            "3.5:3.5".as_ref(),
        ];
        args.extend(more.iter().map(OsStr::new));
        eval_mirror_mouse(&labels, &args)
    };
    let most = |f: &serde_json::Value| {
        f["per_frame"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v["found"].as_u64().unwrap() + v["false_detections"].as_u64().unwrap())
            .max()
            .unwrap()
    };
    let (kept, all) = (judge(&[]), judge(&["--max-paws", "0"]));
    assert_eq!(
        (kept["max_paws"].as_u64(), all["max_paws"].as_u64()),
        (Some(4), Some(0))
    );
    assert!(most(&kept) <= 4 && most(&all) > 4, "{} and {}", most(&kept), most(&all));
    let (k, a) = (&kept["told_scale"], &all["told_scale"]);
    let f = |r: &serde_json::Value, key: &str| r[key].as_f64().unwrap();
    assert!(f(k, "false_detections") < f(a, "false_detections"), "{k} against {a}");
    assert!(f(k, "precision") > f(a, "precision"), "{k} against {a}");
    eprintln!(
        "four kept: recall {} precision {}; all: recall {} precision {}",
        f(k, "recall"),
        f(k, "precision"),
        f(a, "recall"),
        f(a, "precision")
    );
}

/// An HDF5 file that holds no labels (MoSeq's results) is refused in one sentence naming it.
#[test]
fn an_hdf5_file_without_labels_is_refused_naming_it() {
    let Some(results) = moseq_results() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    for (name, says) in [
        ("results.h5", "no table written by pandas"),
        ("results.slp", "not a SLEAP labels file"),
    ] {
        let file = tmp.path().join(name);
        std::fs::copy(&results, &file).unwrap();
        let out = mousepose()
            .args(["eval", "paws", "--model"])
            .arg(repo_root().join("fixtures/models/paws.xml"))
            .arg("--labels")
            .arg(&file)
            .args(["--label-px-per-mm", "3.5"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(name) && err.contains(says), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}

/// A label file that is wrong is refused in one sentence naming the file and the line.
#[test]
fn a_wrong_label_file_is_one_sentence_naming_the_file_and_the_line() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("CollectedData_lab.csv");
    std::fs::write(
        &file,
        "scorer,lab,lab\nbodyparts,LF,LF\ncoords,x,y\nlabeled-data/v/img0.png,1,two\n",
    )
    .unwrap();
    let out = mousepose()
        .args(["train", "paws", "--labels"])
        .arg(&file)
        .args(["--label-px-per-mm", "3.5", "--out"])
        .arg(tmp.path().join("paws.xml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("CollectedData_lab.csv") && err.contains("line 4"), "{err}");
    assert!(!tmp.path().join("paws.xml").exists());
}
