//! A picture of one rendered instant: the top depth image colour-mapped with the skeleton, its
//! part labels, and the bottom view with the paws' boxes.

use super::body::skin;
use super::mouse::MouseInstance;
use super::noise::DepthNoise;
use super::render::{Cage, Region};
use super::views::{render_bottom, render_top};
use crate::geometry::{Camera, Rig};
use crate::image::{RgbImage, depth_to_rgb};
use crate::skeleton::{BACKGROUND_LABEL, BONES, BoneKind, Part};
use rand::Rng;

/// Colours of bones in drawings: the paper's spine red, ears green, limbs blue.
pub fn bone_colour(kind: BoneKind) -> [u8; 3] {
    match kind {
        BoneKind::Spine => [230, 30, 30],
        BoneKind::Ear => [30, 200, 30],
        BoneKind::Limb => [40, 90, 255],
    }
}

/// Draws the skeleton of `m` as seen by `camera` onto `img`, whose pixel (0, 0) is the
/// camera's pixel `origin`, magnified `zoom` times.
pub fn draw_skeleton(
    img: &mut RgbImage,
    camera: &Camera,
    joints: &crate::pose::JointPositions,
    origin: (f64, f64),
    zoom: f64,
) {
    draw_joints(img, camera, &joints.map(Some), origin, zoom);
}

/// As [`draw_skeleton`], for joints that may be unknown (`None`): only bones with both ends
/// known are drawn.
pub fn draw_joints(
    img: &mut RgbImage,
    camera: &Camera,
    joints: &[Option<nalgebra::Point3<f64>>; crate::skeleton::JOINT_COUNT],
    origin: (f64, f64),
    zoom: f64,
) {
    draw_bones(
        img,
        joints,
        |p| {
            camera
                .project_world(p)
                .map(|q| ((q.x - origin.0 + 0.5) * zoom, (q.y - origin.1 + 0.5) * zoom))
        },
        zoom.max(1.0),
    );
}

/// Draws the bones whose ends are both known, through any projection `to_img` from the world
/// to the picture's pixels (`None`: not drawable), lines `thickness` wide, joints as discs.
pub fn draw_bones(
    img: &mut RgbImage,
    joints: &[Option<nalgebra::Point3<f64>>; crate::skeleton::JOINT_COUNT],
    to_img: impl Fn(&nalgebra::Point3<f64>) -> Option<(f64, f64)>,
    thickness: f64,
) {
    let at = |p: &Option<nalgebra::Point3<f64>>| p.as_ref().and_then(&to_img);
    for (a, b, kind) in BONES {
        if let (Some(pa), Some(pb)) = (at(&joints[a.index()]), at(&joints[b.index()])) {
            img.line(pa, pb, bone_colour(kind), thickness);
        }
    }
    for p in joints.iter().filter_map(at) {
        img.disc(p, thickness * 0.9, [255, 255, 255]);
    }
}

/// The three-panel picture of one instant (each panel the mouse's surroundings, magnified).
pub fn preview(rig: &Rig, m: &MouseInstance, noise: &DepthNoise, rng: &mut impl Rng) -> RgbImage {
    let skin = skin(m);
    let cage = Cage::new(&rig.depth);
    // A fixed-size window of the top image centred on the mouse's back.
    let (w, h) = (190u32, 150u32);
    let i = &rig.depth.intrinsics;
    let centre = rig
        .depth
        .project_world(&m.joint(crate::skeleton::Joint::MidBack))
        .unwrap_or(nalgebra::Point2::new(i.cx, i.cy));
    let (cx, cy) = (centre.x.max(0.0) as u32, centre.y.max(0.0) as u32);
    let window = Region {
        x0: cx.saturating_sub(w / 2).min(i.width - w),
        y0: cy.saturating_sub(h / 2).min(i.height - h),
        width: w,
        height: h,
    };
    let top = render_top(&rig.depth, &cage, &skin, Some(window), 0, noise, rng);
    let zoom = 3;
    let floor = f64::from(top.depth.iter().copied().max().unwrap_or(600));
    let mut depth_img = depth_to_rgb(&top.depth, w, h, floor - 60.0, floor + 5.0).upscale(zoom);
    draw_skeleton(
        &mut depth_img,
        &rig.depth,
        &m.joints,
        (f64::from(window.x0), f64::from(window.y0)),
        f64::from(zoom),
    );

    let mut labels = RgbImage::new(w, h, [20, 20, 20]);
    for (k, &l) in top.label.iter().enumerate() {
        if l != BACKGROUND_LABEL {
            let c = Part::from_label(l).map_or([255; 3], Part::colour);
            labels.data[k * 3..k * 3 + 3].copy_from_slice(&c);
        }
    }
    let labels = labels.upscale(zoom);

    // The bottom view around the mouse (20 mm of margin), magnified to the same height, with
    // the paws' boxes: green on the glass, amber lifted.
    let margin = (20.0 * rig.color.intrinsics.fx / Rig::CAMERA_DISTANCE_MM).round() as u32;
    let bottom = render_bottom(&rig.color, m, &skin, margin, rng);
    let bottom_img = RgbImage {
        width: bottom.region.width,
        height: bottom.region.height,
        data: bottom.rgb.clone(),
    };
    let k = ((h * zoom) / bottom_img.height.max(1)).max(1);
    let mut bottom_img = bottom_img.upscale(k);
    let kf = f64::from(k);
    for paw in &bottom.paws {
        let c = if paw.contact { [80, 255, 80] } else { [255, 200, 40] };
        let x = |v: f32| (f64::from(v) - f64::from(bottom.region.x0)) * kf;
        let y = |v: f32| (f64::from(v) - f64::from(bottom.region.y0)) * kf;
        bottom_img.rect(
            (x(paw.x0) - 1.0, y(paw.y0) - 1.0),
            (x(paw.x1) + 1.0, y(paw.y1) + 1.0),
            c,
            1.0,
        );
    }
    RgbImage::hstack(&[depth_img, labels, bottom_img], 6, [255, 255, 255])
}
