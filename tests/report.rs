//! `mousepose report`: the page opens in headless Chromium with every image, the tables hold
//! every frame, and the gait measured on a rendered walking mouse matches what its animator
//! knows (a stride of 30 mm when walking, stance 60 % of it).
#![allow(clippy::unwrap_used)] // the helpers below are test code too

use crate::util::{mousepose, repo_root};
use mousepose::core::noise::{DepthNoise, NoiseModel};
use mousepose::core::skeleton::Joint;
use mousepose::engine::replay::replay;
use mousepose::engine::report::{ReportOptions, frame_input, report};
use mousepose::io::session::SessionReader;
use mousepose::synth::mouse::Behaviour as Act;
use mousepose::synth::session::{SessionSpec, session_animator, write_session};
use mousepose::vision::behaviour::{BehaviourConfig, FrameInput, analyse};
use nalgebra::{Point2, Vector2};
use std::path::Path;

fn replay_to(session: &Path, out: &Path) {
    replay(&crate::util::replay_options(session, out, 1)).unwrap();
}

/// Loads `dir/index.html` in headless Chromium and returns what a script found of its
/// images: `images N broken M names...`.
fn images_in_chromium(dir: &Path) -> String {
    let check = dir.parent().unwrap().join("check.html");
    let name = dir.file_name().unwrap().to_string_lossy();
    std::fs::write(
        &check,
        format!(
            "<!DOCTYPE html><html><body><pre id=\"r\">pending</pre><iframe id=\"f\" src=\"{name}/index.html\"></iframe>\n\
             <script>document.getElementById('f').addEventListener('load', () => {{\n\
             const imgs = [...document.getElementById('f').contentDocument.images];\n\
             const bad = imgs.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.getAttribute('src'));\n\
             document.getElementById('r').textContent = 'result: images ' + imgs.length + ' broken ' + bad.length + ' ' + bad.join(' ');\n\
             }});</script></body></html>"
        ),
    )
    .unwrap();
    let out = std::process::Command::new("chromium")
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--allow-file-access-from-files",
        ])
        .args(["--virtual-time-budget=5000", "--dump-dom"])
        .arg(format!("file://{}", check.display()))
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&out.stdout);
    let at = dom.find("result: ").expect("the check script ran");
    dom[at + "result: ".len()..]
        .split('<')
        .next()
        .unwrap()
        .trim()
        .to_owned()
}

#[test]
fn the_report_page_shows_every_chart_and_lists_every_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&repo_root().join("fixtures/sessions/synthetic-small"), &run);
    let out = tmp.path().join("report");
    let done = mousepose()
        .arg("report")
        .arg(&run)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
    assert_eq!(images_in_chromium(&out), "images 7 broken 0");
    // A missing chart is seen as broken: the check can fail.
    std::fs::remove_file(out.join("gait.png")).unwrap();
    assert_eq!(images_in_chromium(&out), "images 7 broken 1 gait.png");

    let rows = std::fs::read_to_string(run.join("poses.csv")).unwrap().lines().count();
    let frames = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(frames.lines().count(), rows);
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let zones = ["centre_s", "wall_s", "between_s", "unknown_s"]
        .iter()
        .map(|k| summary[k].as_f64().unwrap())
        .sum::<f64>();
    assert!((zones - summary["duration_s"].as_f64().unwrap()).abs() < 1e-6);

    // Not a run: one sentence, exit code 1, nothing written.
    let bad = mousepose()
        .arg("report")
        .arg(tmp.path())
        .arg("--out")
        .arg(tmp.path().join("r2"))
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("poses.csv"));
    assert!(!tmp.path().join("r2").exists());
}

/// The seed among the first 200 whose first `seconds` hold the most walking, and that time.
fn walking_seed(seconds: f64) -> (u64, f64) {
    (0..200u64)
        .map(|seed| {
            let mut a = session_animator(seed);
            let steps = (seconds * 30.0) as usize;
            let walking = (0..steps)
                .filter(|_| {
                    a.advance(1.0 / 30.0);
                    a.behaviour() == Act::Walk
                })
                .count();
            (seed, walking as f64 / 30.0)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn gait_of_a_rendered_walk_matches_the_animators_stride() {
    let seconds = 10.0;
    let (seed, walking_s) = walking_seed(seconds);
    assert!(walking_s > 3.0, "seed {seed}: {walking_s} s of walking");
    let tmp = tempfile::tempdir().unwrap();
    let session = tmp.path().join("session");
    std::fs::create_dir_all(&session).unwrap();
    let spec = SessionSpec {
        seconds,
        seed,
        color_binning: 2,
        noise: DepthNoise {
            model: NoiseModel::StructuredLight,
            gaussian_mm: 0.0,
        },
        ..SessionSpec::default()
    };
    write_session(&session, &spec, |_, _| {}).unwrap();
    let config = BehaviourConfig::default();

    // The maths on the true joints (every paw seen, as the bottom camera sees them): the
    // animator's walk has a stride of 30 mm and a duty factor of 0.6.
    let reader = SessionReader::open(&session).unwrap();
    let truth = reader.truth().unwrap().unwrap();
    let t0 = truth.joints[0].1;
    let inputs: Vec<FrameInput> = truth
        .joints
        .iter()
        .map(|(_, t, j)| {
            let xy = |k: Joint| Point2::new(j[k.index()].x, j[k.index()].y);
            FrameInput {
                t_s: (t - t0) as f64 / 1e9,
                centre: Some(xy(Joint::MidBack)),
                axis: Some::<Vector2<f64>>(xy(Joint::Neck) - xy(Joint::TailBase)),
                head_z_mm: Some(j[Joint::Head.index()].z),
                paws: [
                    Joint::LeftForePaw,
                    Joint::RightForePaw,
                    Joint::LeftHindPaw,
                    Joint::RightHindPaw,
                ]
                .map(|k| Some(xy(k))),
            }
        })
        .collect();
    let truth_gait = analyse(&inputs, (500.0, 450.0), &config);
    let lengths =
        |b: &mousepose::vision::behaviour::Behaviour| b.strides.iter().map(|s| s.length_mm).collect::<Vec<_>>();
    let duties =
        |b: &mousepose::vision::behaviour::Behaviour| b.strides.iter().map(|s| s.duty_factor).collect::<Vec<_>>();
    assert!(truth_gait.strides.len() >= 12, "{} strides", truth_gait.strides.len());
    let (tl, td) = (median(lengths(&truth_gait)), median(duties(&truth_gait)));
    println!(
        "seed {seed} ({walking_s:.1} s walking); truth: {} strides, length {tl:.1} mm, duty {td:.2}",
        truth_gait.strides.len()
    );
    assert!((tl - 30.0).abs() < 3.0, "true stride {tl} mm");
    assert!((td - 0.6).abs() < 0.1, "true duty factor {td}");

    // The same measured from the pipeline's poses (paws from the bottom view).
    let run = tmp.path().join("run");
    replay_to(&session, &run);
    let measured = report(&ReportOptions::new(&run, tmp.path().join("report")))
        .unwrap()
        .behaviour;
    let (ml, md) = (median(lengths(&measured)), median(duties(&measured)));
    let cadence = median(measured.strides.iter().map(|s| 1.0 / s.period_s).collect());
    println!(
        "measured: {} strides, length {ml:.1} mm, duty {md:.2}, cadence {cadence:.2} Hz",
        measured.strides.len()
    );
    assert!(measured.strides.len() >= 6, "{} strides", measured.strides.len());
    assert!((ml - 30.0).abs() < 4.5, "measured stride {ml} mm");
    assert!((md - 0.6).abs() < 0.15, "measured duty factor {md}");
    // Cadence times stride length is the walking speed.
    let walking: Vec<f64> = measured
        .frames
        .iter()
        .filter(|f| f.walking)
        .filter_map(|f| f.speed_mm_s)
        .collect();
    let speed = median(walking);
    assert!(
        (cadence * ml / speed - 1.0).abs() < 0.25,
        "cadence {cadence} x stride {ml} vs speed {speed}"
    );
    // The report's frames come from the same rows the analysis read.
    let rows = mousepose::runtime::sink::poses::read_poses(&run.join("poses.csv")).unwrap();
    let first = frame_input(rows[0].depth.device_ns, &rows[0]);
    assert_eq!(first.t_s, 0.0);
}

#[test]
fn a_depth_only_run_says_gait_needs_the_bottom_camera_and_shows_no_empty_gait() {
    use mousepose::engine::export::moseq::{RIG_FILE, export_moseq};
    let tmp = tempfile::tempdir().unwrap();
    // The fixture's depth frames alone: a MoSeq recording has no colour camera.
    let moseq = tmp.path().join("moseq");
    export_moseq(
        &repo_root().join("fixtures/sessions/synthetic-small"),
        &moseq,
        None,
        None,
        false,
        |_, _| {},
    )
    .unwrap();
    let run = tmp.path().join("run");
    replay(&mousepose::engine::replay::ReplayOptions {
        stream: None,
        lsl: None,
        lead_ns: None,
        partner_wait: None,
        mice: 1,
        calibration: Some(moseq.join(RIG_FILE)),
        ..crate::util::replay_options(&moseq, &run, 1)
    })
    .unwrap();
    let out = tmp.path().join("report");
    let done = mousepose()
        .arg("report")
        .arg(&run)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
    let said = String::from_utf8_lossy(&done.stdout);
    assert!(said.contains("needs the bottom camera"), "{said}");
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(page.contains("Gait needs the bottom camera"), "{page}");
    // No empty gait chart, no value-less cell with a unit.
    assert!(
        !page.contains("src=\"gait.png\"") && !page.contains("src=\"stance.png\""),
        "{page}"
    );
    assert!(!out.join("gait.png").exists());
    for empty in [
        "<td> mm",
        "<td> Hz",
        "<td> mm/s",
        "<td> deg",
        " mm.</p>",
        "fore  mm",
        "-0.0",
    ] {
        assert!(!page.contains(empty), "{empty:?} in {page}");
    }
    assert_eq!(images_in_chromium(&out), "images 5 broken 0");
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert!(
        summary["gait_unavailable"].as_str().unwrap().contains("bottom camera"),
        "{summary}"
    );
    // Heading and turning come from the depth image alone.
    assert!(summary["mean_angular_speed_deg_s"].as_f64().unwrap() > 0.0, "{summary}");
    let frames = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let header: Vec<&str> = frames.lines().next().unwrap().split(',').collect();
    let at = header.iter().position(|h| *h == "heading_deg").unwrap();
    let headed = frames
        .lines()
        .skip(1)
        .filter(|l| !l.split(',').nth(at).unwrap().is_empty())
        .count();
    assert!(headed > 10, "{headed} frames with a heading");
}

#[test]
fn the_report_measures_heading_turning_immobility_and_stride_variability() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    replay_to(&repo_root().join("fixtures/sessions/synthetic-small"), &run);
    let out = tmp.path().join("report");
    // Everything slower than 10 m/s is immobile, and every immobile stretch freezing.
    let done = mousepose()
        .arg("report")
        .arg(&run)
        .args(["--immobile", "10000", "--freezing", "0", "--json", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&done.stdout).unwrap();
    assert_eq!(summary["gait_unavailable"], serde_json::Value::Null, "{summary}");
    for key in [
        "mean_angular_speed_deg_s",
        "turned_deg",
        "net_turn_deg",
        "immobile_s",
        "freezing_s",
    ] {
        assert!(summary[key].is_number(), "{key}: {summary}");
    }
    assert_eq!(summary["immobility_bouts"], summary["freezing_bouts"], "{summary}");
    for paw in ["left_fore", "right_fore", "left_hind", "right_hind"] {
        assert!(summary["stride_variability"][paw]["strides"].is_number(), "{summary}");
    }
    let bouts = std::fs::read_to_string(out.join("bouts.csv")).unwrap();
    let immobility = bouts.lines().filter(|l| l.starts_with("immobility,")).count();
    assert_eq!(immobility as u64, summary["immobility_bouts"].as_u64().unwrap());
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(page.contains("stride length CV") && page.contains("freezing"), "{page}");
}
