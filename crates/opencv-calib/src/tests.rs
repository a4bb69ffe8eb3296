use super::*;

/// A chessboard of `cols` x `rows` inner corners, squares of `square` pixels, on a white margin
/// of `margin` pixels: its pixels, width and height.
fn chessboard(cols: u32, rows: u32, square: u32, margin: u32) -> (Vec<u8>, u32, u32) {
    let (w, h) = ((cols + 1) * square + 2 * margin, (rows + 1) * square + 2 * margin);
    let mut pixels = vec![255u8; (w * h) as usize];
    for y in margin..h - margin {
        for x in margin..w - margin {
            if ((x - margin) / square + (y - margin) / square) % 2 == 0 {
                pixels[(y * w + x) as usize] = 0;
            }
        }
    }
    (pixels, w, h)
}

const FLAGS: i32 = CALIB_CB_ADAPTIVE_THRESH | CALIB_CB_NORMALIZE_IMAGE | CALIB_CB_FAST_CHECK;

#[test]
fn a_rendered_chessboard_is_found_and_refined_onto_its_corners() {
    let (pixels, width, height) = chessboard(9, 6, 20, 30);
    let grey = Grey {
        pixels: &pixels,
        width,
        height,
    };
    let mut corners = find_chessboard_corners(grey, 9, 6, FLAGS)
        .expect("runs")
        .expect("found");
    assert_eq!(corners.len(), 54);
    let criteria = TermCriteria {
        kind: TERM_COUNT | TERM_EPS,
        max_count: 60,
        epsilon: 1e-4,
    };
    corner_sub_pix(grey, &mut corners, (5, 5), (-1, -1), criteria).expect("refines");
    // Square edges fall between pixels: OpenCV puts pixel centres at whole coordinates.
    let mut expected: Vec<(f32, f32)> = (1..=6)
        .flat_map(|j| (1..=9).map(move |i| (30.0 + 20.0 * i as f32 - 0.5, 30.0 + 20.0 * j as f32 - 0.5)))
        .collect();
    let mut found: Vec<(f32, f32)> = corners.iter().map(|c| (c[0], c[1])).collect();
    let key = |p: &(f32, f32)| ((p.1 / 10.0).round() as i32, (p.0 / 10.0).round() as i32);
    expected.sort_by_key(key);
    found.sort_by_key(key);
    for (f, e) in found.iter().zip(&expected) {
        assert!((f.0 - e.0).abs() < 0.2 && (f.1 - e.1).abs() < 0.2, "{f:?} vs {e:?}");
    }
    // A blank image has no board; a board of another size is not this one.
    let blank = vec![128u8; pixels.len()];
    let blank = Grey {
        pixels: &blank,
        width,
        height,
    };
    assert_eq!(find_chessboard_corners(blank, 9, 6, FLAGS).expect("runs"), None);
    assert_eq!(find_chessboard_corners(grey, 8, 6, FLAGS).expect("runs"), None);
}

#[test]
fn a_known_pose_is_solved_and_drawn() {
    let k = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0];
    let d = [0.0; 5];
    let t = [10.0, -5.0, 600.0];
    let object: Vec<[f32; 3]> = (0..6)
        .flat_map(|j| (0..9).map(move |i| [(i as f32 - 4.0) * 20.0, (j as f32 - 2.5) * 20.0, 0.0]))
        .collect();
    let image: Vec<[f32; 2]> = object
        .iter()
        .map(|p| {
            let z = f64::from(p[2]) + t[2];
            [
                (500.0 * (f64::from(p[0]) + t[0]) / z + 320.0) as f32,
                (500.0 * (f64::from(p[1]) + t[1]) / z + 240.0) as f32,
            ]
        })
        .collect();
    let pose = solve_pnp(&object, &image, &k, &d, None, SOLVEPNP_ITERATIVE)
        .expect("runs")
        .expect("solved");
    let criteria = TermCriteria {
        kind: TERM_COUNT | TERM_EPS,
        max_count: 100,
        epsilon: 1e-12,
    };
    let pose = solve_pnp_refine_lm(&object, &image, &k, &d, pose, criteria).expect("refines");
    for ((r, found), truth) in pose.rvec.iter().zip(pose.tvec).zip(t) {
        assert!(r.abs() < 1e-4 && (found - truth).abs() < 1e-2, "{pose:?}");
    }
    let grey = vec![100u8; 640 * 480];
    let grey = Grey {
        pixels: &grey,
        width: 640,
        height: 480,
    };
    let circle = Circle {
        centre: [320, 240],
        radius: 6,
        colour_bgr: [0.0, 200.0, 255.0],
        thickness: 2,
    };
    let bgr = draw_frame_axes(grey, &k, &d, &pose, 60.0, 2, Some(&circle)).expect("draws");
    assert_eq!(bgr.len(), 640 * 480 * 3);
    // Grey stays grey away from the drawing; the x axis (red) runs right of the origin.
    assert_eq!(&bgr[..3], &[100, 100, 100]);
    let at = |x: usize, y: usize| &bgr[(y * 640 + x) * 3..(y * 640 + x) * 3 + 3];
    let origin = (328, 236);
    let on_x = at(origin.0 + 30, origin.1);
    assert!(on_x[2] > 200 && on_x[0] < 50, "{on_x:?}");
}

#[test]
fn calibration_of_rendered_views_is_near_the_camera() {
    // Views of a planar grid through a pinhole camera, tilted a little each.
    let k = [600.0, 0.0, 320.0, 0.0, 600.0, 240.0];
    let grid: Vec<[f32; 3]> = (0..6)
        .flat_map(|j| (0..9).map(move |i| [i as f32 * 20.0, j as f32 * 20.0, 0.0]))
        .collect();
    let mut object = Vec::new();
    let mut image = Vec::new();
    for v in 0..6 {
        let (a, b) = (0.15 * f64::from(v % 3) - 0.15, 0.1 * f64::from(v / 3) - 0.05);
        let view: Vec<[f32; 2]> = grid
            .iter()
            .map(|p| {
                let (x, y) = (f64::from(p[0]) - 80.0, f64::from(p[1]) - 50.0);
                // Rotation about y by `a`, then about x by `b`, 500 away.
                let (x1, z1) = (x * a.cos(), -x * a.sin());
                let (y2, z2) = (y * b.cos() - z1 * b.sin(), y * b.sin() + z1 * b.cos());
                let z = z2 + 500.0;
                [(k[0] * x1 / z + k[2]) as f32, (k[4] * y2 / z + k[5]) as f32]
            })
            .collect();
        object.push(grid.clone());
        image.push(view);
    }
    let criteria = TermCriteria {
        kind: TERM_COUNT | TERM_EPS,
        max_count: 100,
        epsilon: f64::EPSILON,
    };
    let c = calibrate_camera(&object, &image, (640, 480), CALIB_FIX_K3, criteria).expect("calibrates");
    assert!((c.camera_matrix[0] - 600.0).abs() < 1.0, "{c:?}");
    assert!((c.camera_matrix[4] - 600.0).abs() < 1.0, "{c:?}");
    assert_eq!(c.distortion.len(), 5);
    assert_eq!(c.distortion[4], 0.0);
    assert_eq!((c.rvecs.len(), c.tvecs.len(), c.per_view_errors.len()), (6, 6, 6));
    assert_eq!(c.std_deviations_extrinsics.len(), 36);
    assert!(c.rms < 0.01, "{c:?}");
    // Views that do not pair up are refused before OpenCV.
    let e = calibrate_camera(&object, &image[..5], (640, 480), CALIB_FIX_K3, criteria).expect_err("pairs");
    assert_eq!(e.operation, "calibrateCamera");
}

#[test]
fn file_storage_round_trips_every_kind_of_value() {
    let mut w = StorageWriter::new().expect("writer");
    w.text("format", "a test").expect("text");
    w.int("version", 3).expect("int");
    w.begin_map("camera").expect("map");
    w.real("rms", 0.125).expect("real");
    w.matrix("k", 2, 3, &[1.0, 2.0, 3.0, 4.0, 5.5, -6.0]).expect("matrix");
    w.end_map().expect("end");
    w.texts("views", &["a.png", "b.png"]).expect("texts");
    let text = w.finish().expect("finish");
    assert!(text.starts_with("%YAML:1.0"), "{text}");
    assert!(text.contains("!!opencv-matrix"), "{text}");

    let r = StorageReader::from_yaml(&text).expect("parses");
    assert!(r.is_opened());
    let format = r.get("format").expect("node");
    assert!(format.kind().expect("kind").is_string);
    assert_eq!(format.string().expect("string"), "a test");
    let version = r.get("version").expect("node");
    assert!(version.kind().expect("kind").is_int);
    assert_eq!(version.int().expect("int"), 3);
    let camera = r.get("camera").expect("node");
    assert!(camera.kind().expect("kind").is_map);
    let rms = camera.get("rms").expect("node");
    assert!(rms.kind().expect("kind").is_real);
    assert_eq!(rms.real().expect("real"), 0.125);
    let k = camera
        .get("k")
        .expect("node")
        .matrix()
        .expect("reads")
        .expect("a matrix");
    assert_eq!((k.rows, k.cols), (2, 3));
    assert_eq!(k.data, [1.0, 2.0, 3.0, 4.0, 5.5, -6.0]);
    let views = r.get("views").expect("node");
    let kind = views.kind().expect("kind");
    assert!(kind.is_seq && kind.size == 2, "{kind:?}");
    assert_eq!(views.at(1).expect("item").string().expect("string"), "b.png");
    let missing = r.get("nothing").expect("node").kind().expect("kind");
    assert!(missing.is_none && missing.empty, "{missing:?}");
    assert!(camera.get("nothing").expect("node").kind().expect("kind").is_none);
    // Only a map is read as a matrix: OpenCV asserts on anything else.
    let e = r.get("version").expect("node").matrix().expect_err("not a map");
    assert_eq!(e.operation, "FileNode::mat");
}

#[test]
fn failures_come_back_as_errors() {
    let e = StorageReader::from_yaml("%YAML:1.0\n---\nk: [ 1, 2\nj: {\n").expect_err("malformed");
    assert_eq!(e.operation, "FileStorage::open");
    assert!(!e.message.is_empty());
    assert!(e.to_string().starts_with("OpenCV's FileStorage::open failed: "), "{e}");

    let mut w = StorageWriter::new().expect("writer");
    let e = w.int("9lives", 1).expect_err("a key that starts with a digit");
    assert_eq!(e.operation, "FileStorage::write");
    assert!(w.matrix("m", 2, 2, &[1.0]).is_err());
    assert!(w.text("nul", "a\0b").is_err());
    let mut w = StorageWriter::new().expect("writer");
    assert!(w.end_map().is_err(), "no map open");

    let pixels = [0u8; 10];
    let grey = Grey {
        pixels: &pixels,
        width: 4,
        height: 4,
    };
    let e = find_chessboard_corners(grey, 9, 6, FLAGS).expect_err("too few pixels");
    assert!(e.message.contains("16 pixels"), "{e}");
    let e = solve_pnp(&[[0.0; 3]], &[[0.0; 2]], &[1.0; 9], &[0.0; 5], None, SOLVEPNP_ITERATIVE).expect_err("one point");
    assert_eq!(e.operation, "solvePnP");
    assert!(!e.message.is_empty());
}
