//! The two rendered views of one instant: the top depth image with its part labels, and the
//! bottom colour image through the glass with the paws' boxes.

use super::body::{Material, PAW_PRIMITIVES, Primitive};
use super::mouse::MouseInstance;
use super::noise::quantise;
use super::render::{Cage, Hits, Scene};
use crate::core::frame::PixelFormat;
use crate::core::geometry::Camera;
use crate::core::image::Region;
use crate::core::kinematics::PAW_SOLE_MM;
use crate::core::noise::DepthNoise;
use crate::core::skeleton::Joint;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// The top camera's view of a region: depth (mm, 0 = no reading) and part labels.
#[derive(Clone, Debug, PartialEq)]
pub struct TopView {
    pub region: Region,
    pub depth: Vec<u16>,
    /// Part label per pixel ([`crate::core::skeleton::Part::label`]), 255 where there is no mouse.
    pub label: Vec<u8>,
}

/// Renders the top view over `region` (or, when `None`, over the mouse's own pixels grown by
/// `margin`), the cage behind the mouse, with `noise`.
pub fn render_top(
    camera: &Camera,
    cage: &Cage,
    skin: &[Primitive],
    region: Option<Region>,
    margin: u32,
    noise: &DepthNoise,
    rng: &mut impl Rng,
) -> TopView {
    let scene = Scene::new(camera, skin);
    let i = &camera.intrinsics;
    let region = region.unwrap_or_else(|| scene.bounds.grown(margin, i.width, i.height));
    let hits = scene.cast(region);
    let mut depth = cage.depth(region);
    for (z, &hit) in depth.iter_mut().zip(&hits.z) {
        if hit.is_finite() {
            *z = hit;
        }
    }
    noise.apply(&mut depth, region, i, rng);
    TopView {
        region,
        depth: quantise(&depth),
        label: hits.label,
    }
}

/// A full top frame: `background` (the cage's depth over the whole image, mm) with the mouse
/// drawn in, then the sensor's noise, as the camera's u16 millimetres.
pub fn render_top_frame(
    camera: &Camera,
    background: &[f32],
    skin: &[Primitive],
    noise: &DepthNoise,
    rng: &mut impl Rng,
) -> Vec<u16> {
    let i = &camera.intrinsics;
    let scene = Scene::new(camera, skin);
    let region = scene.bounds.grown(2, i.width, i.height);
    let hits = scene.cast(region);
    let mut depth = background.to_vec();
    let w = i.width as usize;
    for y in 0..region.height as usize {
        for x in 0..region.width as usize {
            let z = hits.z[y * region.width as usize + x];
            if z.is_finite() {
                depth[(region.y0 as usize + y) * w + region.x0 as usize + x] = z;
            }
        }
    }
    noise.apply(&mut depth, Region::full(i), i, rng);
    quantise(&depth)
}

/// A paw's box in the bottom colour image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PawBox {
    pub joint: Joint,
    /// Pixel bounds in the full colour image.
    pub x0: f32,
    pub y0: f32,
    pub x1: f32,
    pub y1: f32,
    /// The paw rests on the glass.
    pub contact: bool,
    /// Some of the paw is seen by the bottom camera.
    pub visible: bool,
}

/// The bottom camera's view of a region, as 8-bit RGB, and the four paws' boxes.
#[derive(Clone, Debug, PartialEq)]
pub struct BottomView {
    pub region: Region,
    pub rgb: Vec<u8>,
    pub paws: [PawBox; 4],
}

/// A paw closer to the glass than this touches it.
pub const CONTACT_MM: f64 = 1.0;

/// The dim background through the glass: black cloth lit by the LED ring, brighter at the
/// centre of the image.
fn background(camera: &Camera, x: u32, y: u32) -> [f32; 3] {
    let i = &camera.intrinsics;
    let dx = (f64::from(x) - i.cx) / f64::from(i.width);
    let dy = (f64::from(y) - i.cy) / f64::from(i.height);
    let v = (1.0 - 1.4 * (dx * dx + dy * dy)).max(0.3) as f32;
    [16.0 * v, 15.0 * v, 19.0 * v]
}

fn albedo(material: Material) -> [f32; 3] {
    match material {
        // A dark-furred (C57BL/6-like) mouse's belly.
        Material::Fur => [62.0, 56.0, 54.0],
        Material::Skin => [150.0, 112.0, 108.0],
        Material::Paw => [232.0, 168.0, 164.0],
    }
}

/// Shades the mouse over `hits.region`: LED light from around the camera, dimmer the further
/// a surface is above the glass, paws pressed on the glass brightest.
fn shade(camera: &Camera, scene: &Scene, hits: &Hits) -> Vec<[f32; 3]> {
    let r = hits.region;
    let mut out = Vec::with_capacity(r.len());
    let world = camera.world_from_camera;
    for y in r.y0..r.y0 + r.height {
        for x in r.x0..r.x0 + r.width {
            let Some((p, n, material)) = scene.surface(hits, x, y) else {
                out.push(background(camera, x, y));
                continue;
            };
            let light = (-p).normalize();
            let diffuse = n.dot(&light).max(0.0) as f32;
            let height = (world * nalgebra::Point3::from(p)).z.max(0.0) as f32;
            // The LEDs light what is close to the glass; fur a finger's width up is dim.
            let mut gain = (0.3 + 0.7 * diffuse) / (1.0 + height / 12.0);
            if material == Material::Paw && f64::from(height) < PAW_SOLE_MM * 2.0 + CONTACT_MM {
                gain *= 1.4;
            }
            let a = albedo(material);
            out.push([a[0] * gain, a[1] * gain, a[2] * gain]);
        }
    }
    blur3(&mut out, r.width as usize, r.height as usize);
    out
}

/// A 3x3 binomial blur (the lens and the glass), in place.
fn blur3(img: &mut [[f32; 3]], w: usize, h: usize) {
    if w < 3 || h < 3 {
        return;
    }
    let src = img.to_vec();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mut acc = [0.0f32; 3];
            for (dy, wy) in [(-1i64, 1.0f32), (0, 2.0), (1, 1.0)] {
                for (dx, wx) in [(-1i64, 1.0f32), (0, 2.0), (1, 1.0)] {
                    let s = src[(y as i64 + dy) as usize * w + (x as i64 + dx) as usize];
                    for c in 0..3 {
                        acc[c] += s[c] * wx * wy;
                    }
                }
            }
            img[y * w + x] = acc.map(|v| v / 16.0);
        }
    }
}

/// Sensor noise: read noise plus shot noise growing with the signal.
fn sensor_noise(value: f32, rng: &mut impl Rng) -> u8 {
    let n: f32 = StandardNormal.sample(rng);
    (value + n * (1.2 + 0.1 * value.sqrt())).round().clamp(0.0, 255.0) as u8
}

/// The paws' boxes as the bottom camera sees them.
fn paw_boxes(m: &MouseInstance, scene: &Scene, hits: &Hits) -> [PawBox; 4] {
    std::array::from_fn(|k| {
        let joint = Joint::PAWS[k];
        let contact = m.joint(joint).z - PAW_SOLE_MM * m.scale <= CONTACT_MM;
        let extent = scene.primitive_extent(k);
        let [x0, y0, x1, y1] = extent.unwrap_or([0.0; 4]).map(|v| v as f32);
        // Seen when at least a third of the ellipse inscribed in its box shows.
        let area = std::f32::consts::FRAC_PI_4 * (x1 - x0) * (y1 - y0);
        let shown = if k < PAW_PRIMITIVES {
            scene.pixels_of(hits, k)
        } else {
            0
        };
        PawBox {
            joint,
            x0,
            y0,
            x1,
            y1,
            contact,
            visible: shown > 0 && shown as f32 >= area / 3.0,
        }
    })
}

/// Renders the bottom view of the mouse's own pixels grown by `margin`, as 8-bit RGB.
pub fn render_bottom(
    camera: &Camera,
    m: &MouseInstance,
    skin: &[Primitive],
    margin: u32,
    rng: &mut impl Rng,
) -> BottomView {
    let scene = Scene::new(camera, skin);
    let i = &camera.intrinsics;
    let region = scene.bounds.grown(margin, i.width, i.height);
    let hits = scene.cast(region);
    let shaded = shade(camera, &scene, &hits);
    let mut rgb = Vec::with_capacity(region.len() * 3);
    for px in &shaded {
        for &v in px {
            rgb.push(sensor_noise(v, rng));
        }
    }
    BottomView {
        region,
        rgb,
        paws: paw_boxes(m, &scene, &hits),
    }
}

/// A full bottom frame: the static background with the mouse drawn in, mosaicked to `format`
/// (or kept as RGB8 / converted to Mono8), with sensor noise. Also returns the paw boxes.
pub fn render_bottom_frame(
    camera: &Camera,
    m: &MouseInstance,
    skin: &[Primitive],
    format: PixelFormat,
    rng: &mut impl Rng,
) -> (Vec<u8>, [PawBox; 4]) {
    let scene = Scene::new(camera, skin);
    let i = &camera.intrinsics;
    let region = scene.bounds.grown(2, i.width, i.height);
    let hits = scene.cast(region);
    let shaded = shade(camera, &scene, &hits);
    let (w, h) = (i.width as usize, i.height as usize);
    let bpp = format.bytes_per_pixel();
    let mut out = Vec::with_capacity(w * h * bpp);
    for y in 0..h {
        for x in 0..w {
            let rgb = if region.contains(x as u32, y as u32) {
                shaded[(y - region.y0 as usize) * region.width as usize + (x - region.x0 as usize)]
            } else {
                background(camera, x as u32, y as u32)
            };
            match format {
                PixelFormat::Rgb8 => out.extend(rgb.map(|v| sensor_noise(v, rng))),
                PixelFormat::Mono8 => out.push(sensor_noise(0.3 * rgb[0] + 0.59 * rgb[1] + 0.11 * rgb[2], rng)),
                bayer => {
                    let c = bayer.bayer_channel(x, y).unwrap_or(1);
                    out.push(sensor_noise(rgb[c], rng));
                }
            }
        }
    }
    (out, paw_boxes(m, &scene, &hits))
}
