//! The synthesis engine through its public API: geometry, renderer properties, determinism
//! and the dataset format.

use mousepose::core::geometry::{Intrinsics, Rig};
use mousepose::core::image::Region;
use mousepose::core::noise::DepthNoise;
use mousepose::core::rng::item_rng;
use mousepose::core::skeleton::{BACKGROUND_LABEL, Joint, Part};
use mousepose::synth::body::skin;
use mousepose::synth::dataset::{DatasetSpec, decode_sample, encode_sample, render_sample};
use mousepose::synth::mouse::{Placement, pose_library, pose_mouse};
use mousepose::synth::random_placement;
use mousepose::synth::render::Cage;
use nalgebra::{Point2, Point3};

fn clean_spec(count: u64) -> DatasetSpec {
    DatasetSpec {
        count,
        seed: 42,
        noise: DepthNoise::default(),
        bottom_views: true,
        bottom_clutter: false,
        mice: mousepose::synth::Mice::Standard,
        build: None,
    }
}

#[test]
fn project_unproject_round_trip_with_distortion() {
    let i = Intrinsics {
        width: 640,
        height: 480,
        fx: 570.0,
        fy: 572.0,
        cx: 320.0,
        cy: 241.0,
        distortion: [-0.12, 0.05, 0.001, -0.0015, 0.0],
    };
    for &(x, y, z) in &[(0.0, 0.0, 600.0), (120.0, -80.0, 550.0), (-200.0, 150.0, 700.0)] {
        let p = Point3::new(x, y, z);
        let px = i.project(&p).expect("in front");
        let q = i.unproject(&px, z);
        assert!((q - p).norm() < 1e-6, "{p} -> {px} -> {q}");
    }
}

#[test]
fn rig_transforms_compose_and_cameras_face_the_cage() {
    let rig = Rig::default_rig();
    for cam in [rig.depth, rig.color] {
        let id = cam.world_from_camera * cam.camera_from_world();
        assert!(id.translation.vector.norm() < 1e-9);
        assert!(id.rotation.angle() < 1e-9);
        // The cage's centre is in view, near the image centre.
        let c = cam.project_world(&Point3::origin()).expect("in front");
        assert!(cam.intrinsics.contains(&c));
    }
    assert!((rig.depth.centre().z - 600.0).abs() < 1e-9);
    assert!((rig.color.centre().z + 600.0).abs() < 1e-9);
    // The colour camera leans about 10 degrees from the vertical.
    let axis = rig.color.world_from_camera.rotation * nalgebra::Vector3::z();
    let tilt = axis.z.clamp(-1.0, 1.0).acos().to_degrees();
    assert!((tilt - 10.0).abs() < 0.5, "tilt {tilt}");
    // Straight down from the depth camera the empty cage's floor reads 600 mm.
    let cage = Cage::new(&rig.depth);
    let centre = rig.depth.intrinsics;
    let z = cage.depth_at((centre.cx) as u32, (centre.cy) as u32).expect("floor");
    assert!((z - 600.0).abs() < 0.01, "floor at {z}");
}

#[test]
fn pose_library_has_800_distinct_poses() {
    let lib = pose_library();
    assert!(lib.len() >= 800, "{} poses", lib.len());
    let joints: Vec<_> = lib
        .iter()
        .map(|p| pose_mouse(p, &Placement::default()).joints)
        .collect();
    for (a, ja) in joints.iter().enumerate() {
        for jb in &joints[a + 1..] {
            let max_diff = ja.iter().zip(jb).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
            assert!(max_diff > 0.5, "two poses of the library are the same");
        }
    }
}

#[test]
fn rendered_top_view_is_consistent() {
    let rig = Rig::default_rig();
    let lib = pose_library();
    let spec = DatasetSpec {
        bottom_views: false,
        bottom_clutter: false,
        ..clean_spec(300)
    };
    for index in 0..300 {
        let s = render_sample(&rig, &spec, &lib, index);
        let r = s.top.region;
        let floor = Cage::new(&rig.depth).depth(r);
        let at = |x: u32, y: u32| ((y - r.y0) * r.width + (x - r.x0)) as usize;
        // Labels cover the silhouette exactly: every pixel above the floor is labelled, and
        // no labelled pixel lies below it (grazing rays on the tail may read floor depth).
        for (k, &floor_z) in floor.iter().enumerate() {
            let labelled = s.top.label[k] != BACKGROUND_LABEL;
            let z = f32::from(s.top.depth[k]);
            if z < floor_z - 1.0 {
                assert!(labelled, "sample {index} pixel {k}: mouse depth without a label");
            }
            if labelled {
                assert!(z <= floor_z + 0.5, "sample {index} pixel {k}: label on the floor");
            }
        }
        // Every main-body joint projects inside the silhouette.
        for j in Joint::MAIN_BODY {
            let p = rig.depth.project_world(&s.joints[j.index()]).expect("in front");
            let (x, y) = (p.x.round() as u32, p.y.round() as u32);
            assert!(r.contains(x, y), "sample {index}: {j} outside the rendered region");
            let near = (-1i64..=1)
                .flat_map(|dy| (-1i64..=1).map(move |dx| (dx, dy)))
                .any(|(dx, dy)| {
                    let (xx, yy) = ((x as i64 + dx) as u32, (y as i64 + dy) as u32);
                    r.contains(xx, yy) && s.top.label[at(xx, yy)] != BACKGROUND_LABEL
                });
            assert!(near, "sample {index}: {j} projects outside the silhouette");
        }
        // Mouse pixels lie 0-120 mm above the floor.
        for (k, &floor_z) in floor.iter().enumerate() {
            if s.top.label[k] != BACKGROUND_LABEL {
                let h = floor_z - f32::from(s.top.depth[k]);
                assert!((0.0..=120.0).contains(&h), "height {h}");
            }
        }
    }
}

#[test]
fn tail_is_a_thin_strip_and_every_part_appears() {
    let rig = Rig::default_rig();
    let lib = pose_library();
    let spec = clean_spec(200);
    let mut seen = [0usize; 6];
    for index in 0..200 {
        let s = render_sample(&rig, &spec, &lib, index);
        for &l in &s.top.label {
            if let Some(p) = Part::from_label(l) {
                seen[p.label() as usize] += 1;
            }
        }
        // Tail pixels per pixel of tail length: a strip a few pixels wide.
        let tail_px = s.top.label.iter().filter(|&&l| l == Part::Tail.label()).count() as f64;
        let base = rig
            .depth
            .project_world(&s.joints[Joint::TailBase.index()])
            .expect("front");
        let tip = rig
            .depth
            .project_world(&s.joints[Joint::TailTip.index()])
            .expect("front");
        let length_px = (tip - base).norm();
        if length_px > 40.0 {
            let width = tail_px / length_px;
            assert!((0.8..=6.0).contains(&width), "sample {index}: tail {width:.1} px wide");
        }
    }
    for part in Part::ALL {
        assert!(seen[part.label() as usize] > 1000, "{part} barely appears: {seen:?}");
    }
}

#[test]
fn rendering_is_deterministic_for_a_seed() {
    let rig = Rig::default_rig();
    let lib = pose_library();
    let spec = DatasetSpec {
        noise: DepthNoise {
            model: mousepose::core::noise::NoiseModel::StructuredLight,
            gaussian_mm: 2.0,
        },
        ..clean_spec(20)
    };
    for i in 0..20 {
        assert_eq!(
            encode_sample(&render_sample(&rig, &spec, &lib, i)),
            encode_sample(&render_sample(&rig, &spec, &lib, i))
        );
    }
    let other = DatasetSpec { seed: 43, ..spec };
    assert_ne!(
        render_sample(&rig, &spec, &lib, 3).joints,
        render_sample(&rig, &other, &lib, 3).joints
    );
}

#[test]
fn samples_round_trip_and_corruption_is_refused() {
    let rig = Rig::default_rig();
    let lib = pose_library();
    let s = render_sample(&rig, &clean_spec(1), &lib, 0);
    let bytes = encode_sample(&s);
    let back = decode_sample(&bytes).expect("decodes");
    assert_eq!(back.top, s.top);
    assert_eq!(back.bottom, s.bottom);
    for (a, b) in back.joints.iter().zip(&s.joints) {
        assert!((a - b).norm() < 1e-3);
    }
    // Truncated, bit-flipped and foreign payloads give an error, never a panic.
    for cut in [0, 4, 8, 20, bytes.len() / 2, bytes.len() - 1] {
        assert!(decode_sample(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    let mut flipped = bytes.clone();
    let n = flipped.len();
    flipped[n / 2] ^= 0x5a;
    let _ = decode_sample(&flipped);
    let mut huge = bytes.clone();
    huge[0..4].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(decode_sample(&huge).is_err());
    assert!(decode_sample(b"PNG\r\n\x1a\n not a sample at all").is_err());
}

#[test]
fn cluttered_bottom_views_keep_their_marks_and_plain_ones_are_unchanged() {
    let rig = Rig::default_rig();
    let lib = pose_library();
    let plain = clean_spec(8);
    let cluttered = DatasetSpec {
        bottom_clutter: true,
        ..plain
    };
    let mut marks = 0;
    for i in 0..8 {
        let a = render_sample(&rig, &plain, &lib, i);
        let b = render_sample(&rig, &cluttered, &lib, i);
        // The same mouse and paws; only the view's picture and marks differ.
        assert_eq!(a.top, b.top);
        let bytes = encode_sample(&b);
        let (va, vb) = (a.bottom.expect("bottom"), b.bottom.expect("bottom"));
        assert_eq!(va.paws, vb.paws);
        assert!(va.marks.is_empty());
        marks += vb.marks.len();
        let back = decode_sample(&bytes).expect("decodes");
        assert_eq!(back.bottom.expect("bottom").marks, vb.marks);
    }
    assert!(marks > 0, "no marks in 8 cluttered views");
}

#[test]
fn bottom_view_sees_paws_in_contact() {
    let rig = Rig::default_rig();
    let lib = pose_library();
    let spec = clean_spec(100);
    let (mut contact, mut visible_contact) = (0, 0);
    for index in 0..100 {
        let s = render_sample(&rig, &spec, &lib, index);
        let b = s.bottom.expect("bottom view");
        for paw in &b.paws {
            assert!(paw.x1 >= paw.x0 && paw.y1 >= paw.y0);
            if paw.contact {
                contact += 1;
                visible_contact += usize::from(paw.visible);
                // A paw on the glass is bright in the bottom view.
                let cx = ((paw.x0 + paw.x1) / 2.0) as u32;
                let cy = ((paw.y0 + paw.y1) / 2.0) as u32;
                if paw.visible && b.region.contains(cx, cy) {
                    let k = (((cy - b.region.y0) * b.region.width + (cx - b.region.x0)) * 3) as usize;
                    let red = b.rgb[k];
                    assert!(red > 120, "sample {index}: contact paw red {red}");
                }
            }
        }
    }
    assert!(contact > 150, "{contact} paws in contact");
    assert!(visible_contact as f64 > 0.9 * contact as f64);
}

#[test]
fn random_placements_keep_the_mouse_in_the_cage() {
    let lib = pose_library();
    for i in 0..500 {
        let mut rng = item_rng(7, 99, i);
        let placement = random_placement(&mut rng);
        assert!((0.85..=1.15).contains(&placement.scale));
        let mut m = pose_mouse(&lib[i as usize % lib.len()], &placement);
        mousepose::synth::mouse::fit_in_cage(&mut m, 3.0);
        for p in m.joints.iter().chain(&m.tail) {
            assert!(p.x.abs() <= 250.0 && p.y.abs() <= 225.0, "{p}");
            assert!(p.z > 0.0 && p.z < 120.0, "{p}");
        }
        assert!(!skin(&m).is_empty());
    }
}

#[test]
fn region_helpers() {
    let a = Region {
        x0: 10,
        y0: 10,
        width: 5,
        height: 5,
    };
    let b = Region {
        x0: 12,
        y0: 0,
        width: 10,
        height: 12,
    };
    assert_eq!(
        a.union(&b),
        Region {
            x0: 10,
            y0: 0,
            width: 12,
            height: 15
        }
    );
    assert_eq!(
        a.intersect(&b),
        Region {
            x0: 12,
            y0: 10,
            width: 3,
            height: 2
        }
    );
    assert_eq!(
        a.grown(20, 100, 100),
        Region {
            x0: 0,
            y0: 0,
            width: 35,
            height: 35
        }
    );
    let _ = Point2::new(0.0, 0.0);
}
