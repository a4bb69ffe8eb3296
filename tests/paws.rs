//! The paw detector: our cascade evaluator against OpenCV's `CascadeClassifier` (Debian's own
//! face cascades and our trained paw cascade, both ways through our XML), `eval paws` end to
//! end, and damaged cascades refused with one clear sentence.

use crate::util::{mousepose, repo_root};
use mousepose::vision::paws::cascade::Cascade;
use mousepose::vision::paws::detect::scan_like_opencv;
use mousepose::vision::paws::grey::GreyImage;
use mousepose::vision::paws::{PawDetector, xml};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

const FACE: &str = "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml";

fn paw_model() -> PathBuf {
    repo_root().join("fixtures/models/paws.xml")
}

/// Test images: smooth blobs and edges with noise, so early stages accept many windows.
fn images(seed: u64, n: usize, width: usize, height: usize) -> Vec<GreyImage> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let blobs: Vec<(f64, f64, f64, f64)> = (0..12)
                .map(|_| {
                    (
                        rng.gen_range(0.0..width as f64),
                        rng.gen_range(0.0..height as f64),
                        rng.gen_range(2.0..14.0),
                        rng.gen_range(-120.0..160.0),
                    )
                })
                .collect();
            let mut data = Vec::with_capacity(width * height);
            for y in 0..height {
                for x in 0..width {
                    let mut v = 60.0 + 0.4 * x as f64;
                    for &(bx, by, r, a) in &blobs {
                        let d2 = (x as f64 - bx).powi(2) + (y as f64 - by).powi(2);
                        v += a * (-d2 / (2.0 * r * r)).exp();
                    }
                    v += rng.gen_range(-6.0..6.0);
                    data.push(v.clamp(0.0, 255.0) as u8);
                }
            }
            GreyImage { width, height, data }
        })
        .collect()
}

/// OpenCV's own `CascadeClassifier`, through a small program built against the system's
/// OpenCV (`tests/paws/opencv_windows.cpp`): the crate's build then needs no bindings of
/// objdetect, nor of dnn, which objdetect pulls in (a minute of the suite's build).
struct OpenCv {
    dir: tempfile::TempDir,
    program: PathBuf,
}

impl OpenCv {
    fn build() -> Self {
        let dir = tempfile::tempdir().expect("tmp");
        let program = dir.path().join("opencv_windows");
        let flags = Command::new("pkg-config")
            .args(["--cflags", "opencv4"])
            .output()
            .expect("pkg-config");
        assert!(flags.status.success(), "pkg-config knows no opencv4");
        let out = Command::new("c++")
            .args(["-O1", "-o"])
            .arg(&program)
            .arg(repo_root().join("tests/paws/opencv_windows.cpp"))
            .args(String::from_utf8_lossy(&flags.stdout).split_whitespace())
            .args(["-lopencv_objdetect", "-lopencv_imgcodecs", "-lopencv_core"])
            .output()
            .expect("a C++ compiler (c++)");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        Self { dir, program }
    }

    /// Its raw windows at scale 1 (`minNeighbors = 0`, min = max size = the window), per image.
    fn windows(&self, path: &Path, c: &Cascade, images: &[GreyImage]) -> Vec<BTreeSet<(u32, u32)>> {
        let mut run = Command::new(&self.program);
        run.arg(path).arg(c.width.to_string()).arg(c.height.to_string());
        for (k, img) in images.iter().enumerate() {
            let pgm = self.dir.path().join(format!("{k}.pgm"));
            let mut bytes = format!("P5\n{} {}\n255\n", img.width, img.height).into_bytes();
            bytes.extend_from_slice(&img.data);
            std::fs::write(&pgm, bytes).expect("writes");
            run.arg(pgm);
        }
        let out = run.output().expect("runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let mut found = vec![BTreeSet::new(); images.len()];
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let v: Vec<u32> = line.split(' ').map(|n| n.parse().expect("a number")).collect();
            found[v[0] as usize].insert((v[1], v[2]));
        }
        found
    }
}

fn ours(c: &Cascade, img: &GreyImage) -> BTreeSet<(u32, u32)> {
    let mut v = Vec::new();
    scan_like_opencv(c, img, &mut v);
    v.into_iter().collect()
}

/// Compares both on `images`, returning the total number of windows found.
fn agree(opencv: &OpenCv, path: &Path, c: &Cascade, images: &[GreyImage]) -> usize {
    let mut total = 0;
    for (k, (img, a)) in images.iter().zip(opencv.windows(path, c, images)).enumerate() {
        let b = ours(c, img);
        assert_eq!(
            a,
            b,
            "image {k}: OpenCV and ours differ ({} vs {} windows)",
            a.len(),
            b.len()
        );
        total += a.len();
    }
    total
}

#[test]
fn debian_face_cascade_agrees_with_opencv_through_our_writer() {
    let full = xml::load(Path::new(FACE)).expect("Debian's face cascade reads");
    assert_eq!((full.width, full.height, full.stages.len()), (24, 24, 25));
    let imgs = images(7, 4, 160, 120);
    let opencv = OpenCv::build();
    // The full cascade as Debian ships it.
    agree(&opencv, Path::new(FACE), &full, &imgs);
    // Its first stages, written by our writer and read by OpenCV: many raw windows.
    let tmp = tempfile::tempdir().expect("tmp");
    for n in [1, 3] {
        let cut = full.truncated(n);
        let path = tmp.path().join(format!("face{n}.xml"));
        xml::save(&cut, &path).expect("writes");
        assert_eq!(xml::load(&path).expect("reads back"), cut);
        let found = agree(&opencv, &path, &cut, &imgs);
        assert!(found > 50, "only {found} windows with {n} stages");
    }
}

#[test]
fn debian_cascades_read_or_are_refused_clearly() {
    for entry in std::fs::read_dir("/usr/share/opencv4/haarcascades").expect("cascades") {
        let path = entry.expect("entry").path();
        match xml::load(&path) {
            Ok(c) => assert!(!c.stages.is_empty()),
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.contains("does not support"), "{path:?}: {msg}");
            }
        }
    }
}

#[test]
fn paw_cascade_agrees_with_opencv() {
    let c = xml::load(&paw_model()).expect("the committed paw model reads");
    let imgs = images(11, 3, 200, 140);
    let opencv = OpenCv::build();
    // Its first stage accepts many windows; the whole cascade few.
    let tmp = tempfile::tempdir().expect("tmp");
    let path = tmp.path().join("paws1.xml");
    let cut = c.truncated(1);
    xml::save(&cut, &path).expect("writes");
    let found = agree(&opencv, &path, &cut, &imgs);
    assert!(found > 10, "only {found} windows");
    agree(&opencv, &paw_model(), &c, &imgs);
    // And on a grey bottom view at the canonical scale.
    let ds = mousepose::synth::dataset::DatasetSpec {
        count: 1,
        seed: 3,
        noise: mousepose::core::noise::DepthNoise::default(),
        bottom_views: true,
        bottom_clutter: false,
        mice: mousepose::synth::Mice::Standard,
        build: None,
    };
    let rig = mousepose::core::geometry::Rig::default_rig();
    let library = mousepose::synth::mouse::pose_library();
    let sample = mousepose::synth::dataset::render_sample(&rig, &ds, &library, 0);
    let view = sample.bottom.expect("bottom view");
    let mut greyer = mousepose::vision::paws::grey::Greyer::default();
    let (grey, _) = mousepose::training::paws_data::canonical_view(
        &view,
        mousepose::training::paws_data::DATASET_PX_PER_MM,
        &mut greyer,
    )
    .expect("grey");
    agree(&opencv, &path, &cut, std::slice::from_ref(&grey));
    agree(&opencv, &paw_model(), &c, std::slice::from_ref(&grey));
}

#[test]
fn detector_is_clone_send_debug_and_finds_paws_in_a_full_frame() {
    fn bounds<T: Clone + Send + std::fmt::Debug>() {}
    bounds::<PawDetector>();
    let mut det = PawDetector::load(&paw_model()).expect("loads");
    let frame = mousepose::core::frame::ColorFrame {
        stamp: mousepose::core::frame::Stamp::default(),
        width: 64,
        height: 48,
        format: mousepose::core::frame::PixelFormat::BayerRg8,
        data: vec![16; 64 * 48],
    };
    let mut out = vec![mousepose::vision::paws::PawDetection {
        x0: 0.0,
        y0: 0.0,
        x1: 1.0,
        y1: 1.0,
        score: 1.0,
    }];
    det.detect(&frame, (0, 0, 64, 48), 2.0, &mut out);
    assert!(out.is_empty(), "a flat frame has no paws: {out:?}");
    // Regions outside the frame, and nonsense scales, give nothing rather than a panic.
    det.detect(&frame, (100, 100, 200, 200), 2.0, &mut out);
    det.detect(&frame, (0, 0, 64, 48), 0.0, &mut out);
    assert!(out.is_empty());
}

#[test]
fn eval_paws_end_to_end_with_the_committed_model() {
    let tmp = tempfile::tempdir().expect("tmp");
    let data = tmp.path().join("data");
    let o = mousepose()
        .args([
            "synth",
            "dataset",
            "--out",
            data.to_str().unwrap(),
            "--images",
            "12",
            "--seed",
            "77",
            "--bottom-clutter",
        ])
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta = std::fs::read_to_string(data.join("dataset.toml")).expect("dataset.toml");
    assert!(meta.contains("bottom_clutter = true"), "{meta}");
    let report = tmp.path().join("report");
    let o = mousepose()
        .args([
            "eval",
            "paws",
            "--model",
            paw_model().to_str().unwrap(),
            "--data",
            data.to_str().unwrap(),
        ])
        .args(["--report", report.to_str().unwrap(), "--json"])
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for key in ["precision", "recall", "f1", "mean_centre_error_px"] {
        let x = v[key].as_f64().unwrap_or(-1.0);
        assert!((0.0..=1000.0).contains(&x), "{key} = {x}");
    }
    assert!(v["contact_paws"].as_u64().unwrap_or(0) > 0);
    // False detections are told apart by where they lie: on the view's marks, on the body.
    let fp = v["false_positives"].as_u64().expect("false_positives");
    let on_marks = v["false_on_marks"].as_u64().expect("false_on_marks");
    let on_body = v["false_on_body"].as_u64().expect("false_on_body");
    assert!(on_marks + on_body <= fp, "{v}");
    for f in ["precision_recall.png", "precision_recall.csv", "summary.json"] {
        assert!(report.join(f).is_file(), "{f} missing");
    }
}

#[test]
fn a_damaged_cascade_is_one_clear_sentence_and_a_non_zero_exit() {
    let tmp = tempfile::tempdir().expect("tmp");
    let text = std::fs::read_to_string(paw_model()).expect("model");
    let bad = tmp.path().join("cut.xml");
    std::fs::write(&bad, &text[..text.len() / 3]).expect("write");
    let o = mousepose()
        .args([
            "eval",
            "paws",
            "--model",
            bad.to_str().unwrap(),
            "--data",
            tmp.path().to_str().unwrap(),
        ])
        .output()
        .expect("runs");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("cut.xml") && err.contains("not well-formed XML"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    // A cascade of LBP features is refused by name.
    let lbp = tmp.path().join("lbp.xml");
    std::fs::write(&lbp, text.replace("<featureType>HAAR", "<featureType>LBP")).expect("write");
    let e = PawDetector::load(&lbp).unwrap_err();
    assert!(e.to_string().contains("LBP features"), "{e}");
}

#[test]
fn train_paws_refuses_an_existing_output() {
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("paws.xml");
    std::fs::write(&out, "keep").expect("write");
    let o = mousepose()
        .args([
            "train",
            "paws",
            "--data",
            tmp.path().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(std::fs::read_to_string(&out).expect("kept"), "keep");
}

/// The pipeline's use: a full 1280x1024 BayerRG8 frame, a region around the mouse, boxes
/// back in the frame's pixels, on the paws that touch the glass.
#[test]
fn detections_land_on_paws_in_full_frames() {
    use mousepose::core::frame::{ColorFrame, PixelFormat, Stamp};
    use mousepose::core::rng::item_rng;
    use mousepose::synth::{body::skin, mouse, random_placement, views::render_bottom_frame};
    let rig = mousepose::core::geometry::Rig::default_rig();
    let camera = &rig.color;
    let library = mouse::pose_library();
    let mut det = PawDetector::load(&paw_model()).expect("loads");
    let mut out = Vec::new();
    let (mut paws, mut found, mut false_hits) = (0, 0, 0);
    for k in 0..6u64 {
        let mut rng = item_rng(41, 3, k);
        let pose = library[(k as usize * 97) % library.len()];
        let mut m = mouse::pose_mouse(&pose, &random_placement(&mut rng));
        mouse::fit_in_cage(&mut m, 3.0);
        let (data, boxes) = render_bottom_frame(camera, &m, &skin(&m), PixelFormat::BayerRg8, &mut rng);
        let (w, h) = (camera.intrinsics.width, camera.intrinsics.height);
        let frame = ColorFrame {
            stamp: Stamp::default(),
            width: w,
            height: h,
            format: PixelFormat::BayerRg8,
            data,
        };
        // A generous region around the paws (the pipeline uses the mouse's footprint).
        let x0 = boxes.iter().map(|b| b.x0).fold(f32::INFINITY, f32::min) - 60.0;
        let y0 = boxes.iter().map(|b| b.y0).fold(f32::INFINITY, f32::min) - 60.0;
        let x1 = boxes.iter().map(|b| b.x1).fold(0.0, f32::max) + 60.0;
        let y1 = boxes.iter().map(|b| b.y1).fold(0.0, f32::max) + 60.0;
        let roi = (
            x0.max(0.0) as u32,
            y0.max(0.0) as u32,
            (x1 as u32).min(w),
            (y1 as u32).min(h),
        );
        det.detect(&frame, roi, 2.0, &mut out);
        let near = |d: &mousepose::vision::paws::PawDetection, b: &mousepose::synth::views::PawBox| {
            let (cx, cy) = d.centre();
            let (px, py) = (f64::from(b.x0 + b.x1) / 2.0, f64::from(b.y0 + b.y1) / 2.0);
            (cx - px).hypot(cy - py) <= f64::from((b.x1 - b.x0).max(b.y1 - b.y0)) / 2.0
        };
        for b in boxes.iter().filter(|b| b.contact && b.visible) {
            paws += 1;
            found += usize::from(out.iter().any(|d| near(d, b)));
        }
        false_hits += out.iter().filter(|d| !boxes.iter().any(|b| near(d, b))).count();
        assert!(out.iter().all(|d| d.score >= 2.0 && d.x1 > d.x0 && d.y1 > d.y0));
    }
    assert!(paws > 5, "only {paws} paws on the glass");
    assert!(found * 10 >= paws * 8, "found {found} of {paws} paws on the glass");
    assert!(false_hits <= 3, "{false_hits} detections away from every paw");
}
