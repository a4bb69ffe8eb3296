//! Pictures of one frame pair and its pose: the depth image around the mouse with the
//! skeleton in the paper's colours (spine red, ears green, limbs blue), the bottom view around
//! the mouse with the paws found there, and a side view of the skeleton in 3D.

use crate::core::draw::draw_bones;
use crate::core::frame::{ColorFrame, DepthFrame, PixelFormat};
use crate::core::geometry::Rig;
use crate::core::image::{Region, RgbImage};
use crate::core::pose::JointSource;
use crate::core::skeleton::{JOINT_COUNT, Joint};
use crate::runtime::pose_record::PoseRecord;
use crate::vision::fusion::BodyAxes;
use crate::vision::paws::{FOOTPRINT_MARGIN_MM, footprint};
use crate::vision::segment::{FloorPlane, caption, frame_picture, height_picture};
use nalgebra::{Point3, Vector3};

/// Height of every panel, pixels.
const PANEL: u32 = 480;

/// The colour of the arena's outline in pictures.
pub const ARENA_OUTLINE: [u8; 3] = [255, 0, 255];

/// The three panels side by side (the bottom view only with a colour frame).
pub fn draw(rig: &Rig, depth: &DepthFrame, color: Option<&ColorFrame>, record: &PoseRecord) -> RgbImage {
    draw_panels(rig, depth, color, record, false, None)
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
    draw_panels(rig, depth, color, record, false, arena)
}

/// The three panels side by side; with `bottom_slot`, a pair without a colour frame gets an
/// empty bottom view saying so, so that every picture of a recording with a colour camera has
/// the same size and its panels the same places (the frames of a video); with `arena`, its
/// outline on the depth panel.
pub fn draw_panels(
    rig: &Rig,
    depth: &DepthFrame,
    color: Option<&ColorFrame>,
    record: &PoseRecord,
    bottom_slot: bool,
    arena: Option<&[u8]>,
) -> RgbImage {
    let joints = record
        .pose
        .joints
        .map(|j| (j.source != JointSource::Missing).then_some(j.position_mm));
    let mut panels = vec![top_panel(rig, depth, &joints, arena)];
    match color {
        Some(color) => panels.push(bottom_panel(rig, color, record)),
        None if bottom_slot => {
            let mut empty = RgbImage::new(PANEL, PANEL, [60, 60, 60]);
            caption(&mut empty, "no colour frame");
            panels.push(empty);
        }
        None => {}
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
    crate::core::draw::draw_joints(&mut img, &rig.depth, &joints, (0.0, 0.0), f64::from(zoom));
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
    crate::core::draw::draw_joints(
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

/// The square of the colour frame around `(x0, y0)-(x1, y1)` (at least as large, at most the
/// frame's shorter side, moved inside the frame): its corner and side.
fn square_around(frame: &ColorFrame, (x0, y0, x1, y1): (u32, u32, u32, u32)) -> (u32, u32, u32) {
    let (x0, y0) = (
        x0.min(frame.width.saturating_sub(1)),
        y0.min(frame.height.saturating_sub(1)),
    );
    let (x1, y1) = (x1.min(frame.width), y1.min(frame.height));
    let (w, h) = (x1.saturating_sub(x0).max(1), y1.saturating_sub(y0).max(1));
    let side = w.max(h).min(frame.width).min(frame.height).max(1);
    let (cx, cy) = (x0 + w / 2, y0 + h / 2);
    let sx = cx.saturating_sub(side / 2).min(frame.width.saturating_sub(side));
    let sy = cy.saturating_sub(side / 2).min(frame.height.saturating_sub(side));
    (sx, sy, side)
}

/// The bottom view, always a square panel (so every bottom view has the same size): a square
/// of the colour frame around the mouse's footprint, or, for a camera without a calibration
/// for this frame's mode (where the footprint would land anywhere), its whole frame in its own
/// aspect, centred; with the paw detections (yellow) and the fused paws (blue discs).
pub fn bottom_panel(rig: &Rig, frame: &ColorFrame, record: &PoseRecord) -> RgbImage {
    let calibrated = (frame.width, frame.height) == (rig.color.intrinsics.width, rig.color.intrinsics.height);
    let (x0, y0, w, h) = match footprint(&record.pose, &rig.color, FOOTPRINT_MARGIN_MM).filter(|_| calibrated) {
        Some((roi, _)) => {
            let (x0, y0, side) = square_around(frame, roi);
            (x0, y0, side, side)
        }
        None => (0, 0, frame.width.max(1), frame.height.max(1)),
    };
    let k = (f64::from(PANEL) / f64::from(w)).min(f64::from(PANEL) / f64::from(h));
    let (out_w, out_h) = (
        ((f64::from(w) * k).round() as u32).clamp(1, PANEL),
        ((f64::from(h) * k).round() as u32).clamp(1, PANEL),
    );
    // Where the picture sits in the square panel.
    let (ox0, oy0) = ((PANEL - out_w) / 2, (PANEL - out_h) / 2);
    let mut native = Vec::with_capacity(w as usize * h as usize * 3);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            native.extend_from_slice(&rgb_at(frame, x, y));
        }
    }
    let mut img = RgbImage::new(PANEL, PANEL, [0; 3]);
    for oy in 0..out_h {
        let sy = ((f64::from(oy) / k) as u32).min(h - 1);
        for ox in 0..out_w {
            let sx = ((f64::from(ox) / k) as u32).min(w - 1);
            let i = (sy * w + sx) as usize * 3;
            let o = ((oy0 + oy) * PANEL + ox0 + ox) as usize * 3;
            img.data[o..o + 3].copy_from_slice(&native[i..i + 3]);
        }
    }
    let to_panel = |x: f64, y: f64| {
        (
            f64::from(ox0) + (x - f64::from(x0)) * k,
            f64::from(oy0) + (y - f64::from(y0)) * k,
        )
    };
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

/// Pixels per millimetre of the side view, when the whole skeleton fits at it.
const SIDE_SCALE: f64 = 4.0;
/// Space kept free around the skeleton in the side view, pixels.
const SIDE_MARGIN: f64 = 12.0;

/// How the side view maps a point: the offset along the body that sits at the panel's
/// centre, and the pixels per mm. The skeleton is centred between its ends (snout and tail),
/// at [`SIDE_SCALE`] unless it would not fit (a stretched or rearing mouse), then smaller.
fn side_fit(joints: &[Option<Point3<f64>>; JOINT_COUNT], forward: &Vector3<f64>, floor_y: f64) -> (f64, f64) {
    let seen: Vec<&Point3<f64>> = joints.iter().flatten().collect();
    if seen.is_empty() {
        return (0.0, SIDE_SCALE);
    }
    let along: Vec<f64> = seen.iter().map(|p| p.coords.dot(forward)).collect();
    let lo = along.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = along.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let top = seen.iter().map(|p| p.z).fold(0.0, f64::max);
    let width = f64::from(PANEL) - 2.0 * SIDE_MARGIN;
    let mut scale = SIDE_SCALE;
    if hi - lo > 1e-9 {
        scale = scale.min(width / (hi - lo));
    }
    if top > 1e-9 {
        scale = scale.min((floor_y - SIDE_MARGIN) / top);
    }
    ((lo + hi) / 2.0, scale)
}

/// The skeleton seen from the mouse's left side (orthographic, 4 pixels per mm, less when it
/// would not fit), the glass as a grey line.
fn side_panel(record: &PoseRecord, joints: &[Option<Point3<f64>>; JOINT_COUNT]) -> RgbImage {
    let mut img = RgbImage::new(PANEL, PANEL, [250, 250, 250]);
    let floor_y = f64::from(PANEL) - 40.0;
    img.line((0.0, floor_y), (f64::from(PANEL), floor_y), [150, 150, 150], 2.0);
    let forward = BodyAxes::of(&record.pose).map_or(Vector3::x(), |a| a.fore_forward);
    let (middle, scale) = side_fit(joints, &forward, floor_y);
    draw_bones(
        &mut img,
        joints,
        |p| {
            let along = p.coords.dot(&forward) - middle;
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
    use crate::runtime::pose_record::PoseStatus;

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
            raw_body: None,
            velocities: None,
            identity: None,
        };
        let frame = ColorFrame {
            stamp: Stamp::default(),
            width: 256,
            height: 64,
            format: PixelFormat::Mono8,
            data: vec![128; 256 * 64],
        };
        let img = bottom_panel(&rig, &frame, &record);
        assert_eq!((img.width, img.height), (PANEL, PANEL), "a square panel, as always");
        // The whole 4:1 frame (grey) across the panel's middle quarter, black above and below.
        let grey_rows = (0..PANEL).filter(|&y| img.get(PANEL / 2, y) == Some([128; 3])).count() as u32;
        assert_eq!(grey_rows, PANEL / 4);
        assert_eq!(img.get(0, PANEL / 2), Some([128; 3]), "from the frame's left edge");
        assert_eq!(img.get(PANEL - 1, PANEL / 2), Some([128; 3]), "to its right edge");
    }

    #[test]
    fn the_side_view_holds_the_whole_skeleton_even_stretched_or_rearing() {
        let forward = Vector3::x();
        let floor_y = f64::from(PANEL) - 40.0;
        // A mouse stretched from its tail tip (110 mm behind the middle of its back) to its
        // snout (70 mm ahead), and one rearing with its snout 150 mm up.
        for (snout, tail) in [
            (Point3::new(70.0, 0.0, 20.0), Point3::new(-110.0, 0.0, 5.0)),
            (Point3::new(30.0, 0.0, 150.0), Point3::new(-60.0, 0.0, 5.0)),
            (Point3::new(250.0, 40.0, 20.0), Point3::new(190.0, 40.0, 5.0)),
        ] {
            let mut joints = [None; JOINT_COUNT];
            joints[Joint::Snout.index()] = Some(snout);
            joints[Joint::MidBack.index()] = Some(Point3::new((snout.x + tail.x) / 2.0, snout.y, 30.0));
            joints[Joint::TailBase.index()] = Some(tail);
            let (middle, scale) = side_fit(&joints, &forward, floor_y);
            assert!(scale > 0.0 && scale <= SIDE_SCALE);
            for p in joints.iter().flatten() {
                let x = f64::from(PANEL) / 2.0 + (p.coords.dot(&forward) - middle) * scale;
                let y = floor_y - p.z * scale;
                assert!((0.0..=f64::from(PANEL)).contains(&x), "{p:?} at x {x}");
                assert!((0.0..=floor_y).contains(&y), "{p:?} at y {y}");
            }
        }
        // A mouse that fits keeps 4 pixels per mm.
        let mut joints = [None; JOINT_COUNT];
        joints[Joint::Snout.index()] = Some(Point3::new(40.0, 0.0, 20.0));
        joints[Joint::TailBase.index()] = Some(Point3::new(-40.0, 0.0, 10.0));
        assert_eq!(side_fit(&joints, &forward, floor_y).1, SIDE_SCALE);
    }

    #[test]
    fn the_bottom_view_is_a_square_inside_the_frame() {
        let frame = ColorFrame {
            stamp: Stamp::default(),
            width: 320,
            height: 256,
            format: PixelFormat::Mono8,
            data: vec![0; 320 * 256],
        };
        for (around, side) in [
            ((10, 10, 110, 50), 100),
            ((300, 200, 340, 300), 56),
            ((0, 0, 320, 256), 256),
            ((5, 100, 6, 101), 1),
        ] {
            let (x, y, s) = square_around(&frame, around);
            assert_eq!(s, side, "{around:?}");
            assert!(x + s <= frame.width && y + s <= frame.height, "{around:?}");
        }
    }
}
