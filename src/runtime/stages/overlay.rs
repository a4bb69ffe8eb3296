//! Pictures of one frame pair and its pose: the depth image around the mouse with the
//! skeleton in the paper's colours (spine red, ears green, limbs blue), the bottom view around
//! the mouse with the paws found there, and a side view of the skeleton in 3D.

use crate::core::frame::{ColorFrame, DepthFrame, PixelFormat};
use crate::core::geometry::Rig;
use crate::core::image::draw_bones;
use crate::core::image::{Region, RgbImage};
use crate::core::pose::JointSource;
use crate::core::skeleton::{JOINT_COUNT, Joint};
use crate::runtime::stages::PoseRecord;
use crate::runtime::stages::paws::{FOOTPRINT_MARGIN_MM, footprint};
use crate::vision::fusion::BodyAxes;
use crate::vision::segment::{FloorPlane, caption, frame_picture, height_picture};
use nalgebra::{Point3, Vector3};

/// Height of every panel, pixels.
const PANEL: u32 = 480;

/// The colour of the arena's outline in pictures.
pub const ARENA_OUTLINE: [u8; 3] = [255, 0, 255];

/// The three panels side by side.
pub fn draw(rig: &Rig, depth: &DepthFrame, color: Option<&ColorFrame>, record: &PoseRecord) -> RgbImage {
    draw_in_arena(rig, depth, color, record, None)
}

/// [`draw`], with the outline of `arena` (1 = inside, row-major over the depth image) in
/// [`ARENA_OUTLINE`] on the depth panel when it is given.
pub fn draw_in_arena(
    rig: &Rig,
    depth: &DepthFrame,
    color: Option<&ColorFrame>,
    record: &PoseRecord,
    arena: Option<&[u8]>,
) -> RgbImage {
    let joints = record
        .pose
        .joints
        .map(|j| (j.source != JointSource::Missing).then_some(j.position_mm));
    let mut panels = vec![top_panel(rig, depth, &joints, arena)];
    if let Some(color) = color {
        panels.push(bottom_panel(rig, color, record));
    }
    panels.push(side_panel(record, &joints));
    RgbImage::hstack(&panels, 4, [255, 255, 255])
}

/// The depth image around the mouse, magnified, with the skeleton: the live page's close-up
/// beside the whole cage (where the mouse is a few per cent of the picture).
pub fn mouse_view(rig: &Rig, frame: &DepthFrame, record: &PoseRecord) -> RgbImage {
    let joints = record
        .pose
        .joints
        .map(|j| (j.source != JointSource::Missing).then_some(j.position_mm));
    top_panel(rig, frame, &joints, None)
}

/// The whole depth frame coloured by height above `floor` (the segmenter's, fitted to the
/// camera's view), with the skeleton: the daemon's live view.
pub fn depth_view(rig: &Rig, frame: &DepthFrame, record: &PoseRecord, floor: &FloorPlane) -> RgbImage {
    // Small frames are magnified so that the skeleton stays legible.
    let zoom = if frame.width < 400 { 2 } else { 1 };
    let mut img = frame_picture(frame, &rig.depth.intrinsics, floor).upscale(zoom);
    let joints = record
        .pose
        .joints
        .map(|j| (j.source != JointSource::Missing).then_some(j.position_mm));
    crate::core::image::draw_joints(&mut img, &rig.depth, &joints, (0.0, 0.0), f64::from(zoom));
    img
}

/// A whole depth frame coloured by height above the floor, magnified to about the panels'
/// height, with `note` written across its top: the picture of a recording in which no frame
/// had a mouse; with the outline of `arena` (as in [`draw_in_arena`]) when it is given.
pub fn draw_note(rig: &Rig, depth: &DepthFrame, note: &str, arena: Option<&[u8]>) -> RgbImage {
    let floor = FloorPlane::of_camera(&rig.depth);
    let zoom = (PANEL / depth.height.max(1)).max(1);
    let mut img = frame_picture(depth, &rig.depth.intrinsics, &floor);
    if let Some(arena) = arena {
        outline(&mut img, arena, depth.width, (0, 0));
    }
    let mut img = img.upscale(zoom);
    caption(&mut img, note);
    img
}

/// Paints, in `img` (showing the depth image from pixel `origin` on), the pixels of `arena`
/// (1 = inside, `width` pixels a row) that have a neighbour outside it.
fn outline(img: &mut RgbImage, arena: &[u8], width: u32, origin: (u32, u32)) {
    let width = width as usize;
    if width == 0 {
        return;
    }
    let height = arena.len() / width;
    let inside = |x: usize, y: usize| arena.get(y * width + x).is_some_and(|&m| m != 0);
    for y in 0..img.height {
        for x in 0..img.width {
            let (ax, ay) = ((origin.0 + x) as usize, (origin.1 + y) as usize);
            if ax >= width || ay >= height || !inside(ax, ay) {
                continue;
            }
            let edge = ax == 0
                || ay == 0
                || ax + 1 == width
                || ay + 1 == height
                || !inside(ax - 1, ay)
                || !inside(ax + 1, ay)
                || !inside(ax, ay - 1)
                || !inside(ax, ay + 1);
            if edge {
                img.put(i64::from(x), i64::from(y), ARENA_OUTLINE);
            }
        }
    }
}

/// The depth frame around the mouse, magnified 4 times, coloured by height above the floor
/// (the world's `z = 0`: the rig's, or the one fitted to a recording without a calibration),
/// with the skeleton.
fn top_panel(
    rig: &Rig,
    frame: &DepthFrame,
    joints: &[Option<Point3<f64>>; JOINT_COUNT],
    arena: Option<&[u8]>,
) -> RgbImage {
    let projected: Vec<_> = joints
        .iter()
        .flatten()
        .filter_map(|p| rig.depth.project_world(p))
        .collect();
    let n = projected.len().max(1) as f64;
    let (cx, cy) = if projected.is_empty() {
        (f64::from(frame.width) / 2.0, f64::from(frame.height) / 2.0)
    } else {
        (
            projected.iter().map(|p| p.x).sum::<f64>() / n,
            projected.iter().map(|p| p.y).sum::<f64>() / n,
        )
    };
    let zoom = 4u32;
    let (w, h) = (160u32.min(frame.width), (PANEL / zoom).min(frame.height));
    let x0 = (cx - f64::from(w) / 2.0).clamp(0.0, f64::from(frame.width - w)) as u32;
    let y0 = (cy - f64::from(h) / 2.0).clamp(0.0, f64::from(frame.height - h)) as u32;
    let crop: Vec<u16> = (y0..y0 + h)
        .flat_map(|y| {
            let row = (y * frame.width + x0) as usize;
            frame.data.get(row..row + w as usize).unwrap_or_default()
        })
        .copied()
        .collect();
    let region = Region {
        x0,
        y0,
        width: w,
        height: h,
    };
    let floor = FloorPlane::of_camera(&rig.depth);
    let mut img = height_picture(&crop, region, &rig.depth.intrinsics, &floor);
    if let Some(arena) = arena {
        outline(&mut img, arena, frame.width, (x0, y0));
    }
    let mut img = img.upscale(zoom);
    crate::core::image::draw_joints(
        &mut img,
        &rig.depth,
        joints,
        (f64::from(x0), f64::from(y0)),
        f64::from(zoom),
    );
    img
}

/// The colour frame's pixel at `(x, y)` as RGB (a Bayer mosaic shows its 2x2 cell's colour).
fn rgb_at(frame: &ColorFrame, x: u32, y: u32) -> [u8; 3] {
    let w = frame.width as usize;
    let (x, y) = (x as usize, y as usize);
    match frame.format {
        PixelFormat::Mono8 => [frame.data[y * w + x]; 3],
        PixelFormat::Rgb8 => {
            let i = (y * w + x) * 3;
            [frame.data[i], frame.data[i + 1], frame.data[i + 2]]
        }
        bayer => {
            let (bx, by) = (x & !1, y & !1);
            let mut rgb = [0u16; 3];
            let mut count = [0u16; 3];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (px, py) = ((bx + dx).min(w - 1), (by + dy).min(frame.height as usize - 1));
                let c = bayer.bayer_channel(px, py).unwrap_or(1);
                rgb[c] += u16::from(frame.data[py * w + px]);
                count[c] += 1;
            }
            [0, 1, 2].map(|c| (rgb[c] / count[c].max(1)) as u8)
        }
    }
}

/// The bottom view around the mouse's footprint, scaled to the panel's height, with the paw
/// detections (yellow) and the fused paws (blue discs).
pub fn bottom_panel(rig: &Rig, frame: &ColorFrame, record: &PoseRecord) -> RgbImage {
    let whole = (0, 0, frame.width, frame.height);
    // The footprint only where the rig's colour camera is this frame's (a camera without a
    // calibration for its mode shows its whole frame), and only when it is more than a sliver.
    let calibrated = (frame.width, frame.height) == (rig.color.intrinsics.width, rig.color.intrinsics.height);
    let (x0, y0, x1, y1) = footprint(&record.pose, &rig.color, FOOTPRINT_MARGIN_MM)
        .filter(|_| calibrated)
        .map(|(roi, _)| roi)
        .filter(|&(x0, y0, x1, y1)| x1.min(frame.width) >= x0 + 8 && y1.min(frame.height) >= y0 + 8)
        .unwrap_or(whole);
    let (x1, y1) = (x1.min(frame.width), y1.min(frame.height));
    let (w, h) = (x1.saturating_sub(x0).max(1), y1.saturating_sub(y0).max(1));
    // As tall as the other panels, but never wider than two of them: the frame's aspect kept.
    let k = (f64::from(PANEL) / f64::from(h)).min(f64::from(2 * PANEL) / f64::from(w));
    let out_w = ((f64::from(w) * k).round() as u32).max(1);
    let out_h = ((f64::from(h) * k).round() as u32).max(1);
    let mut native = Vec::with_capacity(w as usize * h as usize * 3);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            native.extend_from_slice(&rgb_at(frame, x, y));
        }
    }
    let mut img = RgbImage::new(out_w, out_h, [0; 3]);
    for oy in 0..out_h {
        let sy = ((f64::from(oy) / k) as u32).min(h - 1);
        for ox in 0..out_w {
            let sx = ((f64::from(ox) / k) as u32).min(w - 1);
            let i = (sy * w + sx) as usize * 3;
            let o = (oy * out_w + ox) as usize * 3;
            img.data[o..o + 3].copy_from_slice(&native[i..i + 3]);
        }
    }
    let to_panel = |x: f64, y: f64| ((x - f64::from(x0)) * k, (y - f64::from(y0)) * k);
    for d in &record.paws {
        let a = to_panel(f64::from(d.x0), f64::from(d.y0));
        let b = to_panel(f64::from(d.x1), f64::from(d.y1));
        img.rect(a, b, [255, 220, 40], 2.0);
    }
    for j in Joint::PAWS {
        let e = record.pose.joint(j);
        if e.source == JointSource::Paw
            && let Some(q) = rig.color.project_world(&e.position_mm)
        {
            img.disc(to_panel(q.x, q.y), 4.0, [40, 90, 255]);
        }
    }
    img
}

/// The skeleton seen from the mouse's left side (orthographic, 4 pixels per mm), the glass as
/// a grey line.
fn side_panel(record: &PoseRecord, joints: &[Option<Point3<f64>>; JOINT_COUNT]) -> RgbImage {
    let mut img = RgbImage::new(PANEL, PANEL, [250, 250, 250]);
    let scale = 4.0;
    let floor_y = f64::from(PANEL) - 40.0;
    img.line((0.0, floor_y), (f64::from(PANEL), floor_y), [150, 150, 150], 2.0);
    let forward = BodyAxes::of(&record.pose).map_or(Vector3::x(), |a| a.fore_forward);
    let centre = joints[Joint::MidBack.index()].unwrap_or_else(Point3::origin);
    draw_bones(
        &mut img,
        joints,
        |p| {
            let along = (p - centre).dot(&forward);
            Some((f64::from(PANEL) / 2.0 + along * scale, floor_y - p.z * scale))
        },
        3.0,
    );
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::frame::Stamp;
    use crate::core::pose::Pose;
    use crate::runtime::stages::PoseStatus;

    #[test]
    fn the_bottom_view_of_an_uncalibrated_camera_is_its_whole_frame_in_its_own_aspect() {
        let rig = Rig::default_rig();
        // A mouse in the middle of the cage, and a colour camera of another mode than the
        // rig's (a 256x64 region), whose footprint would be a sliver at its edge.
        let mut pose = Pose::default();
        for (k, j) in Joint::MAIN_BODY.into_iter().enumerate() {
            let e = pose.joint_mut(j);
            e.position_mm = Point3::new(k as f64 * 5.0 - 30.0, 0.0, 20.0);
            e.source = JointSource::Depth;
        }
        let record = PoseRecord {
            depth: Stamp::default(),
            color: Some(Stamp::default()),
            skew_ns: 0,
            status: PoseStatus::Ok,
            pose,
            paws: Vec::new(),
            headings: None,
            orientation: None,
        };
        let frame = ColorFrame {
            stamp: Stamp::default(),
            width: 256,
            height: 64,
            format: PixelFormat::Mono8,
            data: vec![128; 256 * 64],
        };
        let img = bottom_panel(&rig, &frame, &record);
        assert_eq!((img.width, img.height), (2 * PANEL, PANEL / 2), "the whole 4:1 frame");
    }
}
