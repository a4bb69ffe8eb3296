//! The depth image as a person looks at it: each reading coloured by its height above the
//! fitted floor, so the mouse shows whatever the camera's height and tilt (a fixed depth range
//! hides a mouse on a floor farther away than the range). One pure function, shared by every
//! picture the program draws (`frame.png`, overlays, the daemon's live view).

use super::FloorPlane;
use crate::core::draw::{draw_text, text_width};
use crate::core::frame::DepthFrame;
use crate::core::geometry::Intrinsics;
use crate::core::image::{Region, RgbImage, colour_map};
use nalgebra::Point2;

/// Heights above the floor from 0 to this (mm) span the colour map: a mouse, standing or
/// rearing. Higher readings (walls, a hand) take the top colour, the floor and anything
/// below it the bottom one; pixels without a reading are black.
pub const PICTURE_HEIGHT_MM: f64 = 120.0;

/// Colours `depth` (mm, 0 = no reading, row-major over `region` of the image of a camera with
/// `intrinsics`) by height above `floor` (in that camera's frame).
pub fn height_picture(depth: &[u16], region: Region, intrinsics: &Intrinsics, floor: &FloorPlane) -> RgbImage {
    let mut out = RgbImage::new(region.width, region.height, [0; 3]);
    let rows =
        (region.y0..region.y0 + region.height).flat_map(|y| (region.x0..region.x0 + region.width).map(move |x| (x, y)));
    for ((x, y), (&z, rgb)) in rows.zip(depth.iter().zip(out.data.chunks_exact_mut(3))) {
        if z == 0 {
            continue;
        }
        let ray = intrinsics.ray(&Point2::new(f64::from(x), f64::from(y)));
        let height = floor.normal.dot(&ray) * f64::from(z) + floor.offset_mm;
        rgb.copy_from_slice(&colour_map(height / PICTURE_HEIGHT_MM));
    }
    out
}

/// A whole depth frame coloured by height above `floor` (see [`height_picture`]).
pub fn frame_picture(frame: &DepthFrame, intrinsics: &Intrinsics, floor: &FloorPlane) -> RgbImage {
    let region = Region {
        x0: 0,
        y0: 0,
        width: frame.width,
        height: frame.height,
    };
    height_picture(&frame.data, region, intrinsics, floor)
}

/// Writes `text` on a dark band across the top of `img`, in as large letters as fit.
pub fn caption(img: &mut RgbImage, text: &str) {
    let scale = (img.width.saturating_sub(8) / text_width(text, 1).max(1)).clamp(1, 3);
    let band = 7 * scale + 8;
    for y in 0..band.min(img.height) {
        for x in 0..img.width {
            img.put(i64::from(x), i64::from(y), [20, 20, 20]);
        }
    }
    draw_text(img, 4, 4, text, [255, 255, 255], scale);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::geometry::{Rig, look_at};
    use nalgebra::{Point3, Vector3};

    #[test]
    fn a_mouse_on_a_far_tilted_floor_shows_in_the_colours_of_its_height() {
        // A camera 670 mm above the floor, tilted 10 degrees: a fixed 480-620 mm range would
        // show the floor and a 30 mm high mouse alike.
        let mut camera = Rig::default_rig().depth;
        let t = 10f64.to_radians();
        camera.world_from_camera = look_at(
            Point3::new(0.0, 0.0, 670.0),
            Point3::new(670.0 * t.tan(), 0.0, 0.0),
            -Vector3::y(),
        );
        let i = camera.intrinsics;
        let floor = FloorPlane::of_camera(&camera);
        let mut data = vec![0u16; (i.width * i.height) as usize];
        for y in 0..i.height {
            for x in 0..i.width {
                let ray = i.ray(&Point2::new(f64::from(x), f64::from(y)));
                let mut z = floor.depth_along(&ray).unwrap_or(0.0);
                if (300..340).contains(&x) && (220..260).contains(&y) {
                    // 30 mm above the floor, along the ray.
                    z -= 30.0 / -floor.normal.dot(&ray);
                }
                data[(y * i.width + x) as usize] = z.round() as u16;
            }
        }
        data[0] = 0;
        let frame = DepthFrame {
            stamp: crate::core::frame::Stamp::default(),
            width: i.width,
            height: i.height,
            data,
        };
        let img = frame_picture(&frame, &i, &floor);
        let floor_colour = colour_map(0.0);
        let mouse_colour = colour_map(30.0 / PICTURE_HEIGHT_MM);
        let near = |a: [u8; 3], b: [u8; 3]| a.iter().zip(&b).all(|(p, q)| p.abs_diff(*q) <= 12);
        // The floor is the floor's colour at both ends of the tilted image, the mouse its own.
        for (x, y) in [(5, 240), (630, 240), (320, 20)] {
            assert!(near(img.get(x, y).unwrap(), floor_colour), "floor at ({x}, {y})");
        }
        assert!(near(img.get(320, 240).unwrap(), mouse_colour));
        assert!(!near(mouse_colour, floor_colour));
        assert_eq!(img.get(0, 0), Some([0, 0, 0]));
        let mut captioned = img.clone();
        caption(&mut captioned, "no mouse found");
        assert_ne!(captioned.data, img.data);
    }
}
