//! Calibration end to end through the built binary: rendered chessboards of a known rig,
//! intrinsics of both cameras, extrinsics against the board on the glass, compared with the
//! truth; and every bad input refused with one clear sentence and a non-zero exit.

use crate::util::mousepose;
use mousepose::core::frame::PixelFormat;
use mousepose::core::geometry::Rig;
use mousepose::io::session::{BackendName, CameraMeta, CameraRole, FrameFormat, SessionMeta, SessionSource};
use mousepose::vision::calibrate::extrinsics::pose_difference;
use mousepose::vision::calibrate::{CalibrationError, RigCalibration, load_intrinsics};
use std::path::{Path, PathBuf};
use std::process::Output;

fn run(args: &[&str]) -> Output {
    mousepose().args(args).output().expect("runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Runs `calibrate extrinsics` with a 9x6 board of 40 mm squares: the depth and colour
/// intrinsics files, the depth and colour images, the output, then `extra` arguments.
fn extrinsics(intrinsics: [&str; 2], images: [&str; 2], out: &str, extra: &[&str]) -> Output {
    let mut args = vec![
        "calibrate",
        "extrinsics",
        "--depth-intrinsics",
        intrinsics[0],
        "--color-intrinsics",
        intrinsics[1],
        "--depth-image",
        images[0],
        "--color-image",
        images[1],
        "--board",
        "9x6",
        "--square-mm",
        "40",
        "--out",
        out,
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// Renders a chessboard set (colour binned by 2, a 9x6 board of 40 mm squares) with `views`
/// views per camera. A board this size (440 x 320 mm with its margin) fills much of both
/// views when it lies on the glass, which PnP needs to reach 1 mm and 0.2 degrees at 600 mm.
fn render(dir: &Path, views: u32, seed: u64) -> PathBuf {
    let out = dir.join("boards");
    let o = run(&[
        "synth",
        "chessboard",
        "--square-mm",
        "40",
        "--out",
        s(&out),
        "--views",
        &views.to_string(),
        "--seed",
        &seed.to_string(),
        "--color-binning",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    out
}

/// Asserts a failure with exit code 1 and one line on stderr containing every needle.
fn assert_refused(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one sentence: {err}");
    for n in needles {
        assert!(err.contains(n), "{n:?} not in {err}");
    }
}

#[test]
fn calibration_round_trip_recovers_the_rendered_rig() {
    let tmp = tempfile::tempdir().expect("tmp");
    let boards = render(tmp.path(), 10, 3);
    let mut files = Vec::new();
    for (cam, dir) in [("color", "color"), ("depth", "depth-ir")] {
        let out = tmp.path().join(format!("{cam}.yaml"));
        let o = run(&[
            "calibrate",
            "intrinsics",
            "--images",
            &format!("{}/{dir}/*.png", s(&boards)),
            "--board",
            "9x6",
            "--square-mm",
            "40",
            "--out",
            s(&out),
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
        for key in [
            "rms",
            "fx",
            "fy",
            "cx",
            "cy",
            "width",
            "height",
            "distortion",
            "per_view_errors",
            "skipped",
        ] {
            assert!(json.get(key).is_some(), "{key} missing from {json}");
        }
        assert!(json["rms"].as_f64().expect("rms") < 0.3, "{json}");
        assert_eq!(json["per_view_errors"].as_array().expect("array").len(), 10);
        // OpenCV reads what was written through OpenCV; the keys are OpenCV's own.
        let text = std::fs::read_to_string(&out).expect("read");
        for key in [
            "image_width",
            "camera_matrix",
            "distortion_coefficients",
            "per_view_errors",
            "views",
        ] {
            assert!(text.contains(key), "{key} missing from {text}");
        }
        files.push(out);
    }
    let truth = RigCalibration::load(&boards.join("truth.yaml")).expect("truth loads");
    for (file, role) in files.iter().zip([CameraRole::Color, CameraRole::Depth]) {
        let found = load_intrinsics(file).expect("intrinsics load");
        let t = truth.camera(role).intrinsics;
        assert_eq!((found.width, found.height), (t.width, t.height));
        assert!(
            (found.fx - t.fx).abs() / t.fx < 0.005,
            "{role}: fx {} vs {}",
            found.fx,
            t.fx
        );
    }
    let rig = tmp.path().join("rig.yaml");
    let report = tmp.path().join("report");
    let o = extrinsics(
        [s(&files[1]), s(&files[0])],
        [
            s(&boards.join("extrinsics/depth-ir.png")),
            s(&boards.join("extrinsics/color.png")),
        ],
        s(&rig),
        &["--report", s(&report), "--json"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    for cam in ["depth", "color"] {
        for key in [
            "translation_mm",
            "rotation_quaternion_wxyz",
            "rotation_vector",
            "reprojection_rms_px",
        ] {
            assert!(json[cam].get(key).is_some(), "{cam}.{key} missing from {json}");
        }
    }
    for name in ["report.json", "report.txt", "depth-axes.png", "color-axes.png"] {
        assert!(report.join(name).is_file(), "{name} missing");
    }
    let found = RigCalibration::load(&rig).expect("rig loads");
    for role in [CameraRole::Depth, CameraRole::Color] {
        let (mm, deg) = pose_difference(
            &found.camera(role).world_from_camera,
            &truth.camera(role).world_from_camera,
        );
        assert!(mm < 1.0 && deg < 0.2, "{role}: {mm:.3} mm, {deg:.4} deg off");
    }
    // An existing output is refused without --force.
    let o = extrinsics(
        [s(&files[1]), s(&files[0])],
        [
            s(&boards.join("extrinsics/depth-ir.png")),
            s(&boards.join("extrinsics/color.png")),
        ],
        s(&rig),
        &[],
    );
    assert_refused(&o, &["exists", "--force"]);

    // Swapped images: each camera's image has the other's size.
    let o = extrinsics(
        [s(&files[1]), s(&files[0])],
        [
            s(&boards.join("extrinsics/color.png")),
            s(&boards.join("extrinsics/depth-ir.png")),
        ],
        s(&tmp.path().join("swapped.yaml")),
        &[],
    );
    assert_refused(&o, &["depth image", "640x512", "640x480"]);

    // A board size that does not match the printed board.
    let o = run(&[
        "calibrate",
        "intrinsics",
        "--images",
        &format!("{}/depth-ir/*.png", s(&boards)),
        "--board",
        "8x6",
        "--out",
        s(&tmp.path().join("wrong.yaml")),
    ]);
    assert_refused(&o, &["8x6 board was found in only 0 of 10 images", "view-00.png"]);
    assert!(!tmp.path().join("wrong.yaml").exists());
}

#[test]
fn too_few_views_and_views_without_a_board_are_named() {
    let tmp = tempfile::tempdir().expect("tmp");
    let boards = render(tmp.path(), 3, 1);
    // Three views with a board and two blank ones.
    let dir = boards.join("depth-ir");
    for k in 0..2 {
        let blank = vec![128u8; 640 * 480];
        let path = dir.join(format!("blank-{k}.png"));
        let file = std::fs::File::create(&path).expect("create");
        let mut enc = png::Encoder::new(file, 640, 480);
        enc.set_color(png::ColorType::Grayscale);
        enc.write_header()
            .expect("header")
            .write_image_data(&blank)
            .expect("data");
    }
    let o = run(&[
        "calibrate",
        "intrinsics",
        "--images",
        &format!("{}/*.png", s(&dir)),
        "--out",
        s(&tmp.path().join("x.yaml")),
    ]);
    assert_refused(
        &o,
        &[
            "found in only 3 of 5 images, at least 5 needed",
            "blank-0.png",
            "blank-1.png",
        ],
    );
    // Nothing matches.
    let o = run(&[
        "calibrate",
        "intrinsics",
        "--images",
        &format!("{}/*.jpg", s(&dir)),
        "--out",
        s(&tmp.path().join("x.yaml")),
    ]);
    assert_refused(&o, &["matches no files"]);
    // Views of two sizes.
    let o = run(&[
        "calibrate",
        "intrinsics",
        "--images",
        &format!("{}/*/view-0*.png", s(&boards)),
        "--out",
        s(&tmp.path().join("x.yaml")),
    ]);
    assert_refused(&o, &["must share a size", "640x480", "640x512"]);
}

fn camera(role: CameraRole, width: u32, height: u32, serial: &str) -> CameraMeta {
    CameraMeta {
        role,
        backend: BackendName::SYNTHETIC,
        model: format!("synthetic {role}"),
        serial: serial.to_owned(),
        firmware: String::new(),
        width,
        height,
        pixel_format: match role {
            CameraRole::Depth => FrameFormat::Depth16,
            CameraRole::Color => FrameFormat::Color(PixelFormat::BayerRg8),
        },
        fps: 30.0,
    }
}

#[test]
fn a_calibration_from_another_rig_is_refused() {
    let tmp = tempfile::tempdir().expect("tmp");
    let path = tmp.path().join("rig.yaml");
    let mut cal = RigCalibration::from_rig(&Rig::default_rig());
    cal.depth.serial = Some("A123".to_owned());
    cal.save(&path).expect("saves");
    let cal = RigCalibration::load(&path).expect("loads");

    let ok = SessionMeta::new(
        "2026-11-22T00:00:00Z",
        SessionSource::Recorded,
        vec![
            camera(CameraRole::Depth, 640, 480, "A123"),
            camera(CameraRole::Color, 1280, 1024, ""),
        ],
    );
    cal.check_matches(&ok).expect("the same rig");
    assert_eq!(cal.rig(), Rig::default_rig());

    let binned = SessionMeta::new(
        "2026-11-22T00:00:00Z",
        SessionSource::Recorded,
        vec![
            camera(CameraRole::Depth, 640, 480, ""),
            camera(CameraRole::Color, 640, 512, ""),
        ],
    );
    let e = cal.check_matches(&binned).expect_err("other colour size");
    assert!(matches!(e, CalibrationError::SizeMismatch { .. }));
    let msg = e.to_string();
    assert!(
        msg.contains("rig.yaml") && msg.contains("1280x1024 color") && msg.contains("640x512"),
        "{msg}"
    );

    let other_serial = SessionMeta::new(
        "2026-11-22T00:00:00Z",
        SessionSource::Recorded,
        vec![camera(CameraRole::Depth, 640, 480, "B999")],
    );
    let msg = cal.check_matches(&other_serial).expect_err("other serial").to_string();
    assert!(msg.contains("A123") && msg.contains("B999"), "{msg}");
}

#[test]
fn corrupt_or_foreign_calibration_files_are_named() {
    let tmp = tempfile::tempdir().expect("tmp");
    let path = tmp.path().join("rig.yaml");
    let cases: [(&str, &[&str]); 5] = [
        ("", &["is empty"]),
        ("%YAML:1.0\n---\nformat: [unclosed\n", &["rig.yaml"]),
        (
            "%YAML:1.0\n---\nformat: \"something-else\"\nformat_version: 1\n",
            &["not a rig calibration", "something-else"],
        ),
        (
            "%YAML:1.0\n---\nformat: \"mousepose-rig-calibration\"\nformat_version: 2\n",
            &["format_version 2"],
        ),
        (
            "%YAML:1.0\n---\nformat: \"mousepose-rig-calibration\"\nformat_version: 1\n",
            &["\"depth\""],
        ),
    ];
    for (text, needles) in cases {
        std::fs::write(&path, text).expect("write");
        let e = RigCalibration::load(&path).expect_err(text).to_string();
        for n in needles {
            assert!(e.contains(n), "{n:?} not in {e:?} for {text:?}");
        }
    }
    // A camera matrix of the wrong shape.
    RigCalibration::from_rig(&Rig::default_rig())
        .save(&path)
        .expect("saves");
    let good = std::fs::read_to_string(&path).expect("read");
    let bad = good.replacen("rows: 3\n      cols: 3", "rows: 1\n      cols: 9", 1);
    assert_ne!(bad, good, "the test's edit applies");
    std::fs::write(&path, bad).expect("write");
    let e = RigCalibration::load(&path).expect_err("shape").to_string();
    assert!(
        e.contains("depth.camera_matrix") && e.contains("1x9") && e.contains("3x3"),
        "{e}"
    );
    // The CLI names the intrinsics file it cannot use.
    std::fs::write(&path, "%YAML:1.0\n---\nimage_width: 640\n").expect("write");
    let o = extrinsics(
        [s(&path), s(&path)],
        ["a.png", "b.png"],
        s(&tmp.path().join("out.yaml")),
        &[],
    );
    let err = stderr(&o);
    assert_ne!(o.status.code(), Some(0));
    assert!(err.contains("image_height") && err.contains("rig.yaml"), "{err}");
}

#[test]
fn openni_dummy_intrinsics() {
    let _guard = crate::capture_openni::serial();
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("depth.yaml");
    let result = mousepose::runtime::capture::openni::depth_intrinsics("Dummy");
    match result {
        Ok(found) => {
            assert_eq!((found.intrinsics.width, found.intrinsics.height), (320, 240));
            assert!(found.intrinsics.fx > 0.0);
            mousepose::vision::calibrate::field_of_view::save(&found, &out).expect("saves");
            let back = load_intrinsics(&out).expect("loads");
            assert_eq!(back, found.intrinsics);
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains("Dummy") && msg.contains("field of view"), "{msg}");
        }
    }
}
