//! A picture of one rendered instant: the top depth image colour-mapped with the skeleton, its
//! part labels, and the bottom view with the paws' boxes.

use super::body::skin;
use super::mouse::MouseInstance;
use super::render::Cage;
use super::views::{render_bottom, render_top};
use crate::core::draw::draw_skeleton;
use crate::core::geometry::Rig;
use crate::core::image::Region;
use crate::core::image::{RgbImage, depth_to_rgb};
use crate::core::noise::DepthNoise;
use crate::core::skeleton::{BACKGROUND_LABEL, Part};
use rand::Rng;

/// The three-panel picture of one instant (each panel the mouse's surroundings, magnified).
pub fn preview(rig: &Rig, m: &MouseInstance, noise: &DepthNoise, rng: &mut impl Rng) -> RgbImage {
    let skin = skin(m);
    let cage = Cage::new(&rig.depth);
    // A fixed-size window of the top image centred on the mouse's back.
    let (w, h) = (190u32, 150u32);
    let i = &rig.depth.intrinsics;
    let centre = rig
        .depth
        .project_world(&m.joint(crate::core::skeleton::Joint::MidBack))
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
