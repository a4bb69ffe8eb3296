//! Recordings as real rigs make them, written by the tests in MoSeq's layout (`depth.dat`,
//! `depth_ts.txt`, `metadata.json`): cameras 550-800 mm above the floor and tilted, Kinect v2
//! and Azure Kinect frame sizes, an arena that is a small part of the view, a mouse that sits
//! still for the first 30 s, wrong metadata. The mouse is the synthesis engine's, so its true
//! joints are known.
#![allow(clippy::unwrap_used)] // the helpers below are test code too

use crate::util::mousepose;
use mousepose::core::cameras::depth_camera;
use mousepose::core::geometry::{Camera, Intrinsics, look_at};
use mousepose::core::image::{Region, RgbImage};
use mousepose::core::noise::{DepthNoise, NoiseModel};
use mousepose::core::skeleton::Joint;
use mousepose::engine::replay::{ReplayOptions, ReplaySummary, replay};
use mousepose::synth::body::skin;
use mousepose::synth::mouse::{MouseInstance, Placement, pose_library, pose_mouse};
use mousepose::synth::render::Cage;
use mousepose::synth::views::render_top_frame;
use nalgebra::{Point2, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

/// A depth camera `height_mm` above the floor, its axis tilted `tilt_deg` from the vertical
/// (towards world +x), looking at the cage's centre region.
fn camera(intrinsics: Intrinsics, height_mm: f64, tilt_deg: f64) -> Camera {
    let t = tilt_deg.to_radians();
    Camera {
        intrinsics,
        world_from_camera: look_at(
            Point3::new(-height_mm * t.tan() * 0.5, 10.0, height_mm),
            Point3::new(height_mm * t.tan() * 0.5, 10.0, 0.0),
            -Vector3::y(),
        ),
    }
}

fn nominal(width: u32, height: u32) -> Intrinsics {
    depth_camera(None, width, height).unwrap().intrinsics()
}

fn noise() -> DepthNoise {
    DepthNoise {
        model: NoiseModel::None,
        gaussian_mm: 1.5,
    }
}

/// A mouse of the pose library at a place in the cage.
fn mouse(k: usize, x_mm: f64, y_mm: f64, heading: f64) -> MouseInstance {
    let library = pose_library();
    let placement = Placement {
        x_mm,
        y_mm,
        heading,
        ..Placement::default()
    };
    pose_mouse(&library[(k * 37) % library.len()], &placement)
}

/// A mouse walking around the cage's centre, frame `k`.
fn walking(k: usize) -> MouseInstance {
    let a = k as f64 * 0.7;
    mouse(k, 110.0 * a.cos(), 90.0 * a.sin(), a + std::f64::consts::FRAC_PI_2)
}

/// Renders `mice` over `background` and writes them as a MoSeq recording at `fps`.
fn write_recording(dir: &Path, camera: &Camera, background: &[f32], mice: &[MouseInstance], fps: f64, metadata: &str) {
    std::fs::create_dir_all(dir).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut dat = Vec::new();
    let mut ts = String::new();
    for (k, m) in mice.iter().enumerate() {
        let frame = render_top_frame(camera, background, &skin(m), &noise(), &mut rng);
        dat.extend(frame.iter().flat_map(|v| v.to_le_bytes()));
        ts.push_str(&format!("{:.3}\n", 1000.0 + k as f64 * 1000.0 / fps));
    }
    std::fs::write(dir.join("depth.dat"), dat).unwrap();
    std::fs::write(dir.join("depth_ts.txt"), ts).unwrap();
    std::fs::write(dir.join("metadata.json"), metadata).unwrap();
}

fn resolution(i: &Intrinsics) -> String {
    format!(
        "{{\"SubjectName\": \"m1\", \"DepthResolution\": [{}, {}]}}",
        i.width, i.height
    )
}

fn options(session: &Path, out: &Path) -> ReplayOptions {
    crate::util::replay_options(session, out, 2)
}

/// Per row of `poses.csv`: its status and the mean z of joints 1-12 (the tail tip left out)
/// when it has them.
fn rows(out: &Path) -> Vec<(String, Option<f64>)> {
    let text = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let status = col("status");
    let z_cols: Vec<usize> = body_but_tail_tip().map(|j| col(&format!("{}_z", j.name()))).collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let zs: Vec<f64> = z_cols.iter().filter_map(|&c| f[c].parse().ok()).collect();
            let mean = (zs.len() == z_cols.len()).then(|| zs.iter().sum::<f64>() / zs.len() as f64);
            (f[status].to_owned(), mean)
        })
        .collect()
}

fn true_mean_z(m: &MouseInstance) -> f64 {
    body_but_tail_tip().map(|j| m.joint(j).z).sum::<f64>() / body_but_tail_tip().count() as f64
}

/// Joints 1-12 but the tail tip, which is unknown where no tail is seen.
fn body_but_tail_tip() -> impl Iterator<Item = Joint> {
    Joint::MAIN_BODY.into_iter().filter(|&j| j != Joint::TailTip)
}

/// Checks the replay's camera height and the mouse's heights against the truth; returns the
/// mean absolute error of the joints' mean height (mm).
fn check_heights(s: &ReplaySummary, out: &Path, mice: &[MouseInstance], height_mm: f64, tilt_deg: f64) -> f64 {
    assert_eq!(s.world.frame, "floor");
    assert!(
        (s.world.camera_height_mm - height_mm).abs() < 3.0,
        "fitted camera height {} mm, true {height_mm} mm",
        s.world.camera_height_mm
    );
    assert!(
        (s.world.camera_tilt_deg - tilt_deg).abs() < 0.5,
        "fitted tilt {} deg, true {tilt_deg}",
        s.world.camera_tilt_deg
    );
    let rows = rows(out);
    let errors: Vec<f64> = rows
        .iter()
        .zip(mice)
        .filter_map(|((_, z), m)| z.map(|z| (z - true_mean_z(m)).abs()))
        .collect();
    assert!(
        errors.len() * 10 >= mice.len() * 9,
        "{} of {} frames posed",
        errors.len(),
        mice.len()
    );
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    eprintln!(
        "camera {height_mm} mm, {tilt_deg} deg: fitted {:.1} mm, {:.2} deg; joints' mean height off by {mean:.2} mm",
        s.world.camera_height_mm, s.world.camera_tilt_deg
    );
    mean
}

#[test]
fn heights_are_above_the_fitted_floor_whatever_the_cameras_height_and_tilt() {
    let tmp = tempfile::tempdir().unwrap();
    let mice: Vec<MouseInstance> = (0..16).map(walking).collect();
    for (k, (size, height_mm, tilt_deg)) in [
        ((512, 424), 550.0, 4.0),
        ((512, 424), 670.0, 10.0),
        ((640, 576), 800.0, 15.0),
    ]
    .into_iter()
    .enumerate()
    {
        let cam = camera(nominal(size.0, size.1), height_mm, tilt_deg);
        let dir = tmp.path().join(format!("rec{k}"));
        let cage = Cage::new(&cam).depth(Region::full(&cam.intrinsics));
        write_recording(&dir, &cam, &cage, &mice, 30.0, &resolution(&cam.intrinsics));
        let out = tmp.path().join(format!("out{k}"));
        let s = replay(&options(&dir, &out)).unwrap();
        let error = check_heights(&s, &out, &mice, height_mm, tilt_deg);
        assert!(
            error < 5.0,
            "{height_mm} mm, {tilt_deg} deg: mean height off by {error:.1} mm"
        );
        assert!(
            s.world.intrinsics_from.contains("nominal"),
            "{}",
            s.world.intrinsics_from
        );
        assert!(out.join("frame.png").is_file());
    }
}

#[test]
fn the_camera_comes_from_the_metadata_or_an_intrinsics_file_and_unknown_sizes_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let mice: Vec<MouseInstance> = (0..8).map(walking).collect();
    // An Azure Kinect recording that says so: its NFOV unbinned intrinsics.
    let cam = camera(nominal(640, 576), 700.0, 6.0);
    let dir = tmp.path().join("azure");
    let cage = Cage::new(&cam).depth(Region::full(&cam.intrinsics));
    write_recording(
        &dir,
        &cam,
        &cage,
        &mice,
        30.0,
        r#"{"DepthResolution": [640, 576], "CameraType": "Azure Kinect DK"}"#,
    );
    let s = replay(&options(&dir, &tmp.path().join("a"))).unwrap();
    assert_eq!(s.world.intrinsics_from, "Azure Kinect (NFOV unbinned), nominal");
    assert_eq!(s.world.fx, 504.5);

    // A camera of a size nobody makes: refused, saying how to give the intrinsics.
    let odd = Intrinsics {
        width: 400,
        height: 300,
        fx: 300.0,
        fy: 300.0,
        cx: 199.5,
        cy: 149.5,
        distortion: [0.0; 5],
    };
    let cam = camera(odd, 650.0, 8.0);
    let dir = tmp.path().join("odd");
    let cage = Cage::new(&cam).depth(Region::full(&cam.intrinsics));
    write_recording(&dir, &cam, &cage, &mice, 30.0, &resolution(&odd));
    let o = mousepose()
        .arg("replay")
        .arg(&dir)
        .arg("--out")
        .arg(tmp.path().join("o"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("400x300") && err.contains("--intrinsics FILE"), "{err}");
    assert!(!tmp.path().join("o").exists());

    // Its intrinsics given in the calibration YAML `calibrate intrinsics` writes.
    let yaml = tmp.path().join("depth.yaml");
    std::fs::write(
        &yaml,
        "%YAML:1.0\n---\nimage_width: 400\nimage_height: 300\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 300., 0., 199.5, 0., 300., 149.5, 0., 0., 1. ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ 0., 0., 0., 0., 0. ]\n",
    )
    .unwrap();
    let out = tmp.path().join("b");
    let s = replay(&ReplayOptions {
        stream: None,
        intrinsics: Some(yaml),
        ..options(&dir, &out)
    })
    .unwrap();
    assert_eq!(s.world.fx, 300.0);
    let error = check_heights(&s, &out, &mice, 650.0, 8.0);
    assert!(error < 5.0, "mean height off by {error:.1} mm");
}

#[test]
fn a_wrong_depth_resolution_and_noise_are_refused_and_repeated_timestamps_counted() {
    let tmp = tempfile::tempdir().unwrap();
    let mice: Vec<MouseInstance> = (0..6).map(walking).collect();
    let cam = camera(nominal(512, 424), 670.0, 10.0);
    let cage = Cage::new(&cam).depth(Region::full(&cam.intrinsics));
    let dir = tmp.path().join("swapped");
    write_recording(&dir, &cam, &cage, &mice, 30.0, r#"{"DepthResolution": [424, 512]}"#);
    let err = replay(&options(&dir, &tmp.path().join("a"))).unwrap_err();
    let text = mousepose::core::error_chain(&err);
    assert!(text.contains("does not look like 424x512 depth frames"), "{text}");
    assert!(text.contains("512x424 looks right"), "{text}");

    // Noise at every size tried.
    let noise_dir = tmp.path().join("noise");
    write_recording(&noise_dir, &cam, &cage, &mice, 30.0, &resolution(&cam.intrinsics));
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let junk: Vec<u8> = (0..std::fs::metadata(noise_dir.join("depth.dat")).unwrap().len())
        .map(|_| rng.r#gen::<u8>())
        .collect();
    std::fs::write(noise_dir.join("depth.dat"), junk).unwrap();
    let err = replay(&options(&noise_dir, &tmp.path().join("b"))).unwrap_err();
    let text = mousepose::core::error_chain(&err);
    assert!(
        text.contains("sizes tried: 512x424") && text.contains("none looks like depth frames"),
        "{text}"
    );

    // A repeated timestamp: counted and reported, its frame dropped as out of order.
    let dup = tmp.path().join("dup");
    write_recording(&dup, &cam, &cage, &mice, 30.0, &resolution(&cam.intrinsics));
    let ts = std::fs::read_to_string(dup.join("depth_ts.txt")).unwrap();
    let mut lines: Vec<&str> = ts.lines().collect();
    lines[3] = lines[2];
    std::fs::write(dup.join("depth_ts.txt"), lines.join("\n")).unwrap();
    let s = replay(&options(&dup, &tmp.path().join("c"))).unwrap();
    assert_eq!(s.duplicate_timestamps, Some(1));
    assert_eq!(s.cameras["depth"].dropped.get("time_out_of_order"), Some(&1));
    let text = mousepose::app::replay::summary_text(&s, &tmp.path().join("c"));
    assert!(text.contains("depth_ts.txt: 1 timestamps repeat"), "{text}");
}

/// A round arena (a disc of floor `radius_mm` in radius, walls 200 mm high around it) in a
/// cluttered view: around it, tiles at random depths; a few pixels without a reading.
fn arena_background(cam: &Camera, radius_mm: f64) -> Vec<f32> {
    let i = &cam.intrinsics;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let tiles: Vec<f32> = (0..1024).map(|_| rng.gen_range(350.0..1100.0)).collect();
    let o = cam.centre();
    let mut out = Vec::with_capacity((i.width * i.height) as usize);
    for y in 0..i.height {
        for x in 0..i.width {
            let d_cam = i.ray(&Point2::new(f64::from(x), f64::from(y)));
            let d = cam.world_from_camera.rotation * d_cam;
            // Where the ray meets the floor, and the wall's top.
            let floor = o + d * (-o.z / d.z);
            let top = o + d * ((200.0 - o.z) / d.z);
            let r = |p: Point3<f64>| (p.x * p.x + p.y * p.y).sqrt();
            let z = if r(floor) <= radius_mm && r(top) <= radius_mm {
                -o.z / d.z
            } else if r(top) <= radius_mm {
                // The wall's inner face, where the ray crosses the circle of the arena.
                let (mut near, mut far) = ((200.0 - o.z) / d.z, -o.z / d.z);
                for _ in 0..40 {
                    let mid = (near + far) / 2.0;
                    if r(o + d * mid) <= radius_mm {
                        near = mid;
                    } else {
                        far = mid;
                    }
                }
                near
            } else if r(top) <= radius_mm + 10.0 {
                (200.0 - o.z) / d.z
            } else {
                let tile = (y / 24) * 32 + x / 24;
                f64::from(tiles[tile as usize % tiles.len()])
            };
            out.push(if (x * 7 + y * 13) % 97 == 0 { 0.0 } else { z as f32 });
        }
    }
    out
}

#[test]
fn an_arena_a_quarter_of_the_view_is_found_or_given_and_its_floor_fitted() {
    let tmp = tempfile::tempdir().unwrap();
    let cam = camera(nominal(512, 424), 700.0, 6.0);
    let background = arena_background(&cam, 220.0);
    // The arena's floor holds fewer than a fifth of the readings: a floor fitted to the whole
    // view was refused.
    let floor = mousepose::vision::segment::FloorPlane::of_camera(&cam);
    let i = &cam.intrinsics;
    let on_floor = background
        .iter()
        .enumerate()
        .filter(|&(k, &z)| {
            let ray = i.ray(&Point2::new((k as u32 % i.width).into(), (k as u32 / i.width).into()));
            z > 0.0 && floor.depth_along(&ray).is_some_and(|f| (f - f64::from(z)).abs() < 1.0)
        })
        .count();
    let valid = background.iter().filter(|&&z| z > 0.0).count();
    assert!(on_floor * 5 < valid, "{on_floor} of {valid}");
    let mice: Vec<MouseInstance> = (0..12)
        .map(|k| {
            let a = k as f64 * 0.9;
            mouse(k, 70.0 * a.cos(), 70.0 * a.sin(), a + 1.6)
        })
        .collect();
    let dir = tmp.path().join("arena");
    write_recording(&dir, &cam, &background, &mice, 30.0, &resolution(&cam.intrinsics));
    let out = tmp.path().join("found");
    let s = replay(&options(&dir, &out)).unwrap();
    assert_eq!(s.world.arena_from, "found");
    assert!((0.15..0.45).contains(&s.world.arena_share), "{}", s.world.arena_share);
    let error = check_heights(&s, &out, &mice, 700.0, 6.0);
    assert!(error < 5.0, "mean height off by {error:.1} mm");
    // The arena's floor in the fitted world frame: within the 440 mm disc's bounding square
    // (the floor frame turns the view about z only), most of it (the segmenter's arena
    // leaves out the floor by the walls).
    let size = |a: &mousepose::vision::behaviour::Arena| a.size_mm();
    let found = s.world.arena_mm.expect("the arena on the floor");
    let (l, w) = size(&found);
    assert!((350.0..460.0).contains(&l) && (350.0..460.0).contains(&w), "{found:?}");
    // The report takes it as its cage, and its thresholds from the flags.
    let report = |run: &Path, name: &str, flags: &[&str]| -> serde_json::Value {
        let o = mousepose()
            .arg("report")
            .arg(run)
            .arg("--out")
            .arg(tmp.path().join(name))
            .arg("--json")
            .args(flags)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let v = report(&out, "report-found", &[]);
    assert_eq!(v["arena"]["from"], "recording", "{v}");
    assert!(
        (v["arena"]["x_max_mm"].as_f64().unwrap() - found.x_max_mm).abs() < 1e-6,
        "{v}"
    );
    // Every mouse circles 70 mm from the arena's centre: in the central rectangle.
    assert!(
        v["centre_s"].as_f64().unwrap() > 0.0 && v["wall_s"].as_f64().unwrap() == 0.0,
        "{v}"
    );
    let v = report(
        &out,
        "report-given",
        &[
            "--arena",
            "-1000,-1000,-900,-900",
            "--rearing",
            "25",
            "--walk-min",
            "20",
            "--walk-max",
            "300",
            "--wall",
            "30",
        ],
    );
    assert_eq!(v["arena"]["from"], "flag", "{v}");
    assert_eq!(v["arena"]["x_min_mm"], -1000.0);
    assert_eq!(
        (
            &v["config"]["rear_head_mm"],
            &v["config"]["walk_min_mm_s"],
            &v["config"]["walk_max_mm_s"],
            &v["config"]["wall_band_mm"]
        ),
        (
            &serde_json::json!(25.0),
            &serde_json::json!(20.0),
            &serde_json::json!(300.0),
            &serde_json::json!(30.0)
        )
    );
    // Far outside that arena, the mouse is never in its centre.
    assert_eq!(v["centre_s"].as_f64(), Some(0.0), "{v}");

    // The same arena drawn by hand as a PNG mask.
    let mut mask = RgbImage::new(i.width, i.height, [0; 3]);
    let c = cam.project_world(&Point3::origin()).unwrap();
    let r_px = 200.0 * i.fx / 700.0;
    mask.disc((c.x, c.y), r_px, [255, 255, 255]);
    let roi = tmp.path().join("roi.png");
    mask.write_png(&roi).unwrap();
    let out = tmp.path().join("given");
    let s = replay(&ReplayOptions {
        stream: None,
        roi: Some(roi.clone()),
        ..options(&dir, &out)
    })
    .unwrap();
    assert_eq!(s.world.arena_from, "roi");
    check_heights(&s, &out, &mice, 700.0, 6.0);
    let (l, w) = size(&s.world.arena_mm.expect("the given arena on the floor"));
    assert!((300.0..420.0).contains(&l) && (300.0..420.0).contains(&w), "{l} x {w}");
    // A mask of another size is refused with exit code 1.
    RgbImage::new(10, 10, [255; 3]).write_png(&roi).unwrap();
    let o = mousepose()
        .arg("replay")
        .arg(&dir)
        .arg("--roi")
        .arg(&roi)
        .arg("--out")
        .arg(tmp.path().join("bad"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("10x10") && err.contains("512x424"), "{err}");
}

#[test]
fn a_mouse_still_for_the_first_30_s_is_found_and_an_empty_recording_still_gets_a_picture() {
    let tmp = tempfile::tempdir().unwrap();
    let cam = camera(nominal(320, 288), 670.0, 8.0);
    let cage = Cage::new(&cam).depth(Region::full(&cam.intrinsics));
    // 2 frames a second: 30 s still, then 15 s walking.
    let still = mouse(3, -40.0, 20.0, 0.4);
    let mice: Vec<MouseInstance> = (0..90)
        .map(|k| if k < 60 { still.clone() } else { walking(k) })
        .collect();
    let dir = tmp.path().join("still");
    write_recording(&dir, &cam, &cage, &mice, 2.0, &resolution(&cam.intrinsics));
    let out = tmp.path().join("o");
    let s = replay(&options(&dir, &out)).unwrap();
    let rows = rows(&out);
    let found_still = rows[..60].iter().filter(|(status, _)| status == "ok").count();
    assert!(
        found_still >= 57,
        "{found_still} of 60 still frames with a mouse: {:?}",
        s.statuses
    );

    // No mouse at all: the picture says so.
    let empty = tmp.path().join("empty");
    write_recording(&empty, &cam, &cage, &[], 2.0, &resolution(&cam.intrinsics));
    let dat: Vec<u8> = (0..10)
        .flat_map(|_| cage.iter().flat_map(|&z| (z.round() as u16).to_le_bytes()))
        .collect();
    std::fs::write(empty.join("depth.dat"), dat).unwrap();
    let ts: String = (0..10).map(|k| format!("{}\n", 1000 + k * 33)).collect();
    std::fs::write(empty.join("depth_ts.txt"), ts).unwrap();
    let out = tmp.path().join("e");
    let s = replay(&options(&empty, &out)).unwrap();
    assert_eq!(s.statuses.get("no_mouse"), Some(&10), "{:?}", s.statuses);
    let picture = read_png(&out.join("frame.png"));
    // The caption's white letters on its dark band.
    let white = picture
        .iter()
        .take(picture.len() / 20)
        .filter(|p| **p == [255, 255, 255])
        .count();
    assert!(white > 50, "{white} white pixels at the top");
}

/// A PNG written by the program, as RGB pixels.
fn read_png(path: &PathBuf) -> Vec<[u8; 3]> {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

#[test]
fn detect_paws_finds_the_paws_in_single_bottom_views() {
    use mousepose::core::geometry::Rig;
    use mousepose::synth::views::render_bottom;
    let tmp = tempfile::tempdir().unwrap();
    let rig = Rig::default_rig();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut images = Vec::new();
    let mut truth = Vec::new();
    for k in 0..3 {
        let m = walking(k * 3);
        let view = render_bottom(&rig.color, &m, &skin(&m), 40, &mut rng);
        let r = view.region;
        let path = tmp.path().join(format!("bottom{k}.png"));
        RgbImage {
            width: r.width,
            height: r.height,
            data: view.rgb,
        }
        .write_png(&path)
        .unwrap();
        images.push(path);
        truth.push(
            view.paws
                .iter()
                .filter(|p| p.contact && p.visible)
                .map(|p| {
                    let (x0, y0) = (r.x0 as f32, r.y0 as f32);
                    (p.x0 - x0, p.y0 - y0, p.x1 - x0, p.y1 - y0)
                })
                .collect::<Vec<_>>(),
        );
    }
    let out = tmp.path().join("out");
    let o = mousepose()
        .args(["detect", "paws"])
        .args(&images)
        .arg("--out")
        .arg(&out)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let printed: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("detections.json")).unwrap()).unwrap();
    assert_eq!(printed, written);
    let (mut paws, mut matched) = (0, 0);
    for (image, boxes) in written["images"].as_array().unwrap().iter().zip(&truth) {
        assert!(out.join(image["picture"].as_str().unwrap()).is_file());
        let centres: Vec<(f64, f64)> = image["paws"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| {
                let f = |k: &str| d[k].as_f64().unwrap();
                // Each box has its detector score.
                assert!(f("score").is_finite(), "{d}");
                ((f("x0") + f("x1")) / 2.0, (f("y0") + f("y1")) / 2.0)
            })
            .collect();
        for &(x0, y0, x1, y1) in boxes {
            paws += 1;
            let inside = |&(x, y): &(f64, f64)| {
                (f64::from(x0)..=f64::from(x1)).contains(&x) && (f64::from(y0)..=f64::from(y1)).contains(&y)
            };
            if centres.iter().any(inside) {
                matched += 1;
            }
        }
    }
    assert!(
        paws > 0 && matched * 4 >= paws * 3,
        "{matched} of {paws} paws on the glass found"
    );

    // A missing image: exit code 1 naming it, nothing written.
    let o = mousepose()
        .args(["detect", "paws"])
        .arg(tmp.path().join("nope.png"))
        .arg("--out")
        .arg(tmp.path().join("out2"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("nope.png"), "{err}");
    assert!(!tmp.path().join("out2").exists());
}

/// Mice well outside the standard range (`--mice varied`): on this one (seed 505, a
/// time-of-flight camera) the body forest alone swaps head and tail in some frames (9 of 299
/// for the forest trained on 24,000 images of mixed mice, 11 for the one of 12,000, 5 % and
/// more for the one of standard mice); the orientation tracker's output does not, and
/// `poses.csv` says how sure it is.
/// A mouse whose tail the camera does not see, staying in place from the first frame (issue
/// 27: real mice like that came out swapped in every frame): the body's shape, learnt from
/// rendered mice with their tails hidden, starts the tracker on the right end and holds it.
#[test]
fn a_still_mouse_without_a_visible_tail_keeps_its_head_in_front() {
    use mousepose::synth::Mice;
    use mousepose::synth::animate::Activity;
    use mousepose::synth::session::{SessionSpec, TailLook, write_session};
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("still");
    std::fs::create_dir_all(&dir).unwrap();
    let spec = SessionSpec {
        seconds: 6.0,
        seed: 611,
        color: false,
        mice: Mice::Varied,
        activity: Activity::Still,
        tail: TailLook::Hidden,
        noise: DepthNoise {
            model: NoiseModel::Tof,
            gaussian_mm: 0.0,
        },
        ..SessionSpec::default()
    };
    write_session(&dir, &spec, |_, _| {}).unwrap();
    let out = tmp.path().join("o");
    let s = replay(&options(&dir, &out)).unwrap();
    assert!(s.orientation_model.is_some());
    let o = s.orientation.unwrap();
    assert!(o.frames > 150, "{o:?}");
    assert!(o.flipped_tracked * 50 <= o.frames, "more than 2 % flipped: {o:?}");
    assert!(
        o.flipped_frame_alone * 50 <= o.frames,
        "more than 2 % flipped frame by frame: {o:?}"
    );
    // The learnt shape alone, frame by frame, whatever the forest's votes say.
    assert!(o.shape_frames * 10 >= o.frames * 9, "{o:?}");
    assert!(
        o.flipped_shape * 50 <= o.shape_frames,
        "the body shape alone swapped more than 2 %: {o:?}"
    );
    // Depth only: no paw cascade is read.
    assert!(s.paw_model.is_none());
    // No tail is seen, so no tail tip is given (issue 27, item 4), in all but a few frames.
    let text = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (status, tip) = (column("status"), column("tail_tip_x"));
    let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let found = rows.iter().filter(|r| r[status] == "ok").count();
    let given = rows.iter().filter(|r| r[status] == "ok" && !r[tip].is_empty()).count();
    assert!(
        given * 20 <= found,
        "a tail tip in {given} of {found} frames without a tail"
    );
}

#[test]
fn varied_mice_keep_their_heads_in_front() {
    use mousepose::synth::Mice;
    use mousepose::synth::session::{SessionSpec, write_session};
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("varied");
    std::fs::create_dir_all(&dir).unwrap();
    let spec = SessionSpec {
        seconds: 10.0,
        seed: 505,
        color: false,
        mice: Mice::Varied,
        noise: DepthNoise {
            model: NoiseModel::Tof,
            gaussian_mm: 0.0,
        },
        ..SessionSpec::default()
    };
    write_session(&dir, &spec, |_, _| {}).unwrap();
    let out = tmp.path().join("o");
    let s = replay(&options(&dir, &out)).unwrap();
    let o = s.orientation.unwrap();
    assert!(o.frames > 250, "{o:?}");
    assert!(o.flipped_forest >= 5, "the forest alone should flip here: {o:?}");
    assert!(o.flipped_tracked * 50 <= o.frames, "more than 2 % flipped: {o:?}");
    assert!(
        o.flipped_tracked * 5 <= o.flipped_forest,
        "the tracker should undo most of the forest's flips: {o:?}"
    );
    assert!(o.heading_error_deg < 10.0, "{o:?}");
    let text = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let confidences: Vec<f64> = text
        .lines()
        .skip(1)
        .filter_map(|l| l.rsplit(',').next()?.parse().ok())
        .collect();
    assert_eq!(confidences.len() as u64, s.statuses["ok"]);
    assert!(confidences.iter().all(|c| (0.5..=1.0).contains(c)));
}

/// A round arena (floor `radius_mm` in radius at the world's `z = 0`, strewn with bedding up
/// to `bedding_mm` high, walls 150 mm high) standing in a room whose floor, all around it, is
/// the plane `z = room_mm + room_slope * x`: the largest flat region of the view is the
/// room's floor, not the arena's, and the arena's floor is tilted against it.
/// A round arena of `radius_mm` centred at world x = `centre_x_mm`, y = 0, its wall 150 mm
/// high, on a room floor `room_mm` below (or above) its own, sloping by `room_slope`.
fn raised_arena(
    cam: &Camera,
    (radius_mm, centre_x_mm): (f64, f64),
    bedding_mm: f64,
    room_mm: f64,
    room_slope: f64,
) -> Vec<f32> {
    const WALL_MM: f64 = 150.0;
    let i = &cam.intrinsics;
    let o = cam.centre();
    let mut out = Vec::with_capacity((i.width * i.height) as usize);
    for y in 0..i.height {
        for x in 0..i.width {
            let d = cam.world_from_camera.rotation * i.ray(&Point2::new(f64::from(x), f64::from(y)));
            let at = |t: f64| o + d * t;
            let r = |p: Point3<f64>| ((p.x - centre_x_mm).powi(2) + p.y * p.y).sqrt();
            let (t_floor, t_top) = (-o.z / d.z, (WALL_MM - o.z) / d.z);
            let z = if r(at(t_floor)) <= radius_mm && r(at(t_top)) <= radius_mm {
                // Bedding: bumps a few pixels across, fixed in time.
                let p = at(t_floor);
                let bump = (((p.x * 0.31).sin() * (p.y * 0.27).cos() + 1.0) / 2.0).powi(2) * bedding_mm;
                t_floor - bump / -d.z
            } else if r(at(t_top)) <= radius_mm {
                let (mut near, mut far) = (t_top, t_floor);
                for _ in 0..40 {
                    let mid = (near + far) / 2.0;
                    if r(at(mid)) <= radius_mm {
                        near = mid;
                    } else {
                        far = mid;
                    }
                }
                near
            } else if r(at(t_top)) <= radius_mm + 10.0 {
                t_top
            } else {
                // o.z + t d.z = room + slope (o.x + t d.x)
                (room_mm + room_slope * o.x - o.z) / (d.z - room_slope * d.x)
            };
            out.push(z as f32);
        }
    }
    out
}

/// Issue 27, item 3: the automatic arena finds the mouse where the largest flat region of the
/// view is not its floor: a bedded arena whose floor, about 770 mm away, is tilted against the
/// room's floor around it, and an arena a tenth of the view. (Both gave `no_mouse` in every
/// frame: the floor was the room's, 250-300 mm below the mouse.)
#[test]
fn arenas_on_tilted_bedded_floors_and_small_arenas_are_found() {
    let tmp = tempfile::tempdir().unwrap();
    let mice: Vec<MouseInstance> = (0..12)
        .map(|k| {
            let a = k as f64 * 0.9;
            mouse(k, 60.0 * a.cos(), 60.0 * a.sin(), a + 1.6)
        })
        .collect();
    for (name, tilt_deg, radius_mm, room_mm, slope, share) in [
        ("tilted", 5.0, 220.0, -250.0, 0.08, 0.15..0.5),
        ("small", 2.0, 175.0, -300.0, 0.0, 0.05..0.2),
    ] {
        let cam = camera(nominal(512, 424), 770.0, tilt_deg);
        let background = raised_arena(&cam, (radius_mm, 0.0), 3.0, room_mm, slope);
        let dir = tmp.path().join(name);
        write_recording(&dir, &cam, &background, &mice, 30.0, &resolution(&cam.intrinsics));
        let out = tmp.path().join(format!("{name}-out"));
        let s = replay(&options(&dir, &out)).unwrap();
        assert!(
            share.contains(&s.world.arena_share),
            "{name}: arena share {}",
            s.world.arena_share
        );
        assert!((s.world.camera_height_mm - 768.5).abs() < 3.0, "{name}: {:?}", s.world);
        assert!(
            (s.world.camera_tilt_deg - tilt_deg).abs() < 0.5,
            "{name}: {:?}",
            s.world
        );
        let errors: Vec<f64> = rows(&out)
            .iter()
            .zip(&mice)
            .filter_map(|((_, z), m)| z.map(|z| (z - true_mean_z(m)).abs()))
            .collect();
        // Before: no frame posed. Now 10 of 12 in the bedded, tilted arena (the two others
        // are not yet understood).
        assert!(
            errors.len() * 4 >= mice.len() * 3,
            "{name}: {} of {} frames posed",
            errors.len(),
            mice.len()
        );
        let error = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!(error < 5.0, "{name}: mean height off by {error:.1} mm");
        assert!(s.warnings.is_empty(), "{name}: {:?}", s.warnings);
        let check = s.world.arena_check.unwrap();
        assert_eq!(check.mouse_sized_outside, 0, "{name}: {check:?}");
    }
}

/// Issue 49, item 4: an arena a tenth of the view standing on the room's floor, off to one
/// side: its floor and the room's are one plane, and the room's is the largest solid region
/// of it, the first choice. The mice move inside the small arena; seen outside the first
/// choice, they make the replay choose the region of the plane that holds them. An empty
/// recording of the same rig finds no mouse.
#[test]
fn a_small_arena_on_the_rooms_floor_is_chosen_by_the_mouse_seen_in_it() {
    let tmp = tempfile::tempdir().unwrap();
    let cam = camera(nominal(512, 424), 770.0, 2.0);
    let centre_x_mm = -300.0;
    let background = raised_arena(&cam, (175.0, centre_x_mm), 0.0, 0.0, 0.0);
    let mice: Vec<MouseInstance> = (0..40)
        .map(|k| {
            let a = k as f64 * 0.45;
            mouse(k, centre_x_mm + 70.0 * a.cos(), 70.0 * a.sin(), a + 1.6)
        })
        .collect();
    let dir = tmp.path().join("small");
    write_recording(&dir, &cam, &background, &mice, 30.0, &resolution(&cam.intrinsics));
    let out = tmp.path().join("small-out");
    let s = replay(&options(&dir, &out)).unwrap();
    assert!(
        (0.05..0.2).contains(&s.world.arena_share),
        "arena share {}",
        s.world.arena_share
    );
    let posed = rows(&out).iter().filter(|(status, _)| status == "ok").count();
    assert!(posed * 100 >= mice.len() * 95, "{posed} of {} frames posed", mice.len());
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    // The same rig without a mouse: no mouse found.
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let frame: Vec<u8> = background
        .iter()
        .flat_map(|&z| (z.round() as u16).to_le_bytes())
        .collect();
    std::fs::write(empty.join("depth.dat"), frame.repeat(mice.len())).unwrap();
    let ts: String = (0..mice.len())
        .map(|k| format!("{:.3}\n", 1000.0 + k as f64 * 1000.0 / 30.0))
        .collect();
    std::fs::write(empty.join("depth_ts.txt"), ts).unwrap();
    std::fs::write(empty.join("metadata.json"), resolution(&cam.intrinsics)).unwrap();
    let out = tmp.path().join("empty-out");
    replay(&options(&empty, &out)).unwrap();
    assert!(
        rows(&out).iter().all(|(status, _)| status != "ok"),
        "a mouse in an empty arena"
    );
}

/// Issue 27, item 3: when something of a mouse's size moves outside the arena used and no
/// frame has a mouse, replay says so: a warning on stderr, `warnings` and `world.arena_check`
/// in `summary.json`, and `frame.png` with the arena's outline.
#[test]
fn a_mouse_outside_the_arena_is_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let cam = camera(nominal(512, 424), 700.0, 4.0);
    let background = raised_arena(&cam, (230.0, 0.0), 0.0, -250.0, 0.0);
    let mice: Vec<MouseInstance> = (0..10)
        .map(|k| {
            let a = k as f64 * 0.9;
            mouse(k, -60.0 + 25.0 * a.cos(), 25.0 * a.sin(), a + 1.6)
        })
        .collect();
    let dir = tmp.path().join("rec");
    write_recording(&dir, &cam, &background, &mice, 30.0, &resolution(&cam.intrinsics));
    // The arena given: a disc of floor the mouse never enters.
    let i = &cam.intrinsics;
    let mut mask = RgbImage::new(i.width, i.height, [0; 3]);
    let c = cam.project_world(&Point3::new(150.0, 0.0, 0.0)).unwrap();
    mask.disc((c.x, c.y), 50.0 * i.fx / 700.0, [255, 255, 255]);
    let roi = tmp.path().join("roi.png");
    mask.write_png(&roi).unwrap();
    let out = tmp.path().join("o");
    let o = mousepose()
        .arg("replay")
        .arg(&dir)
        .arg("--roi")
        .arg(&roi)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("--roi") && err.contains("outside the arena"), "{err}");
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["statuses"]["no_mouse"], 10, "{summary}");
    let check = &summary["world"]["arena_check"];
    assert!(check["mouse_sized_outside"].as_u64().unwrap() >= 5, "{check}");
    assert_eq!(check["mouse_sized_inside"], 0, "{check}");
    assert!(summary["warnings"].as_array().unwrap().len() == 2, "{summary}");
    let picture = read_png(&out.join("frame.png"));
    let outline = picture
        .iter()
        .filter(|p| **p == mousepose::runtime::overlay::ARENA_OUTLINE)
        .count();
    assert!(outline > 100, "{outline} pixels of the arena's outline");
}

/// Issue 41, item 3: a mouse against a wall 200 mm high (the wall's face seen by a camera
/// tilted toward it, time-of-flight noise with its flying pixels across the wall's edge): no
/// joint takes the wall's height; each lies within the mouse's own height. A guard: on these
/// renders the build before this round kept its joints on the mouse too (highest 63 mm for
/// mice up to about 60 mm high); the real cross-shaped arena where joints took the wall's
/// depth is not among the recordings we have.
#[test]
fn a_mouse_against_a_wall_keeps_its_joints_on_itself() {
    use std::f64::consts::FRAC_PI_2;
    const WALL_X_MM: f64 = 120.0;
    const WALL_MM: f64 = 200.0;
    let tmp = tempfile::tempdir().unwrap();
    let cam = camera(nominal(512, 424), 680.0, 6.0);
    let i = &cam.intrinsics;
    let o = cam.centre();
    // The floor at z = 0, and from x = WALL_X_MM on a wall 200 mm high (its face toward the
    // camera's side).
    let background: Vec<f32> = (0..i.height)
        .flat_map(|y| (0..i.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let d = cam.world_from_camera.rotation * i.ray(&Point2::new(f64::from(x), f64::from(y)));
            let t_floor = -o.z / d.z;
            let t_top = (WALL_MM - o.z) / d.z;
            let t_face = (WALL_X_MM - o.x) / d.x;
            let t = if (o + d * t_top).x >= WALL_X_MM {
                t_top
            } else if (o + d * t_floor).x >= WALL_X_MM && d.x > 0.0 {
                t_face
            } else {
                t_floor
            };
            t as f32
        })
        .collect();
    // Mice walking along the wall, their flanks 0-8 mm from it, both ways; time-of-flight
    // noise (flying pixels across the wall's edge, as real Kinects have them).
    let mice: Vec<MouseInstance> = (0..30)
        .map(|k| {
            let heading = if k % 2 == 0 { FRAC_PI_2 } else { -FRAC_PI_2 };
            let gap = (k % 5) as f64 * 2.0;
            mouse(k, WALL_X_MM - 14.0 - gap, -60.0 + 4.0 * k as f64, heading)
        })
        .collect();
    let dir = tmp.path().join("wall");
    std::fs::create_dir_all(&dir).unwrap();
    let tof = DepthNoise {
        model: NoiseModel::Tof,
        gaussian_mm: 0.0,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let mut dat = Vec::new();
    let mut ts = String::new();
    for (k, m) in mice.iter().enumerate() {
        let frame = render_top_frame(&cam, &background, &skin(m), &tof, &mut rng);
        dat.extend(frame.iter().flat_map(|v| v.to_le_bytes()));
        ts.push_str(&format!("{:.3}\n", 1000.0 + k as f64 * 1000.0 / 30.0));
    }
    std::fs::write(dir.join("depth.dat"), dat).unwrap();
    std::fs::write(dir.join("depth_ts.txt"), ts).unwrap();
    std::fs::write(dir.join("metadata.json"), resolution(i)).unwrap();
    let out = tmp.path().join("o");
    let mut opts = options(&dir, &out);
    opts.force = true;
    replay(&opts).unwrap();
    let text = std::fs::read_to_string(out.join("poses.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let mut posed = 0;
    for (line, m) in lines.zip(&mice) {
        let f: Vec<&str> = line.split(',').collect();
        if f[col("status")] != "ok" {
            continue;
        }
        posed += 1;
        let top = Joint::MAIN_BODY.iter().map(|&j| m.joint(j).z).fold(0.0, f64::max);
        for joint in Joint::MAIN_BODY {
            // The replay's world is the fitted floor's: heights compare, places do not.
            let Ok(z) = f[col(&format!("{}_z", joint.name()))].parse::<f64>() else {
                continue;
            };
            assert!(
                z <= top + 15.0,
                "{}: {} at {z:.0} mm, the mouse's top {top:.0} mm",
                f[0],
                joint.name()
            );
        }
    }
    assert!(posed * 4 >= mice.len() * 3, "{posed} of {} frames posed", mice.len());
}

/// Issue 41, item 1: a tail that a real depth camera shows blurred and raised (about 6 mm wide,
/// reading 24 mm above the floor at its base and 10 mm at its tip, where the back reads about
/// 30 mm) is found as a tail and not taken for the head, whether the mouse moves or stays still
/// from its first frame. (Before: the head on the tail's end in 296 of 296 frames of the first
/// session.)
#[test]
fn a_raised_visible_tail_is_taken_for_a_tail_not_a_head() {
    use mousepose::synth::Mice;
    use mousepose::synth::animate::Activity;
    use mousepose::synth::session::{SessionSpec, TailLook, write_session};
    let tmp = tempfile::tempdir().unwrap();
    for (seed, activity) in [(7401, Activity::Mixed), (7501, Activity::Still)] {
        let dir = tmp.path().join(format!("s{seed}"));
        std::fs::create_dir_all(&dir).unwrap();
        let spec = SessionSpec {
            seconds: 10.0,
            seed,
            color: false,
            mice: Mice::Varied,
            activity,
            tail: TailLook::Raised,
            noise: DepthNoise {
                model: NoiseModel::Tof,
                gaussian_mm: 0.0,
            },
            ..SessionSpec::default()
        };
        write_session(&dir, &spec, |_, _| {}).unwrap();
        let out = tmp.path().join(format!("o{seed}"));
        let s = replay(&options(&dir, &out)).unwrap();
        let o = s.orientation.unwrap();
        assert!(o.frames > 250, "{seed}: {o:?}");
        assert!(
            o.tail_frames * 2 >= o.frames,
            "{seed}: the tail seen in too few frames: {o:?}"
        );
        assert!(
            o.flipped_tail * 50 <= o.tail_frames,
            "{seed}: the tail's end wrong: {o:?}"
        );
        assert!(
            o.flipped_tracked * 50 <= o.frames,
            "{seed}: more than 2 % flipped: {o:?}"
        );
    }
}
