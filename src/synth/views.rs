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
    /// What was drawn into the view besides the mouse when it was rendered with
    /// [`BottomClutter`] (empty otherwise): things a paw detector must not take for paws.
    pub marks: Vec<Mark>,
}

impl BottomView {
    /// The view as a colour camera binned by `factor` sees it (each pixel the mean of a
    /// `factor x factor` block of the full sensor's, as sensor binning averages), with the
    /// region, the paws' boxes and the marks in the binned image's pixels. Blocks the region
    /// cuts are left out; `factor` 1 gives the view itself.
    pub fn binned(&self, factor: u32) -> BottomView {
        let f = factor.max(1);
        let r = self.region;
        let (bx0, by0) = (r.x0.div_ceil(f), r.y0.div_ceil(f));
        let (bx1, by1) = ((r.x0 + r.width) / f, (r.y0 + r.height) / f);
        let region = Region {
            x0: bx0,
            y0: by0,
            width: bx1.saturating_sub(bx0),
            height: by1.saturating_sub(by0),
        };
        let (w, fu) = (r.width as usize, f as usize);
        let mut rgb = Vec::with_capacity(region.len() * 3);
        for by in by0..by0 + region.height {
            for bx in bx0..bx0 + region.width {
                let mut sum = [0u32; 3];
                for y in (by * f - r.y0) as usize..(by * f - r.y0) as usize + fu {
                    for x in (bx * f - r.x0) as usize..(bx * f - r.x0) as usize + fu {
                        for (c, s) in sum.iter_mut().enumerate() {
                            *s += u32::from(self.rgb[(y * w + x) * 3 + c]);
                        }
                    }
                }
                let n = (fu * fu) as u32;
                rgb.extend(sum.map(|s| ((s + n / 2) / n) as u8));
            }
        }
        let k = f as f32;
        let paws = self.paws.map(|p| PawBox {
            x0: p.x0 / k,
            y0: p.y0 / k,
            x1: p.x1 / k,
            y1: p.y1 / k,
            ..p
        });
        let marks = self
            .marks
            .iter()
            .map(|m| Mark {
                x0: m.x0 / k,
                y0: m.y0 / k,
                x1: m.x1 / k,
                y1: m.y1 / k,
                ..*m
            })
            .collect();
        BottomView {
            region,
            rgb,
            paws,
            marks,
        }
    }
}

/// Something in a bottom view that is not a paw but can look like one to a detector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MarkKind {
    /// The LED ring's reflection at the glass's edge: a bright, soft band.
    Glare,
    /// A pale spot on the glass (a dried drop, dust, a smear).
    Spot,
    /// A thin bright scratch on the glass.
    Scratch,
    /// A pale patch of the mouse's belly fur.
    BellySpot,
}

impl MarkKind {
    /// The code stored in datasets (`docs/FORMATS.md`).
    pub fn code(self) -> u8 {
        match self {
            Self::Glare => 0,
            Self::Spot => 1,
            Self::Scratch => 2,
            Self::BellySpot => 3,
        }
    }

    /// The kind stored as `code`.
    pub fn from_code(code: u8) -> Option<Self> {
        [Self::Glare, Self::Spot, Self::Scratch, Self::BellySpot]
            .into_iter()
            .find(|k| k.code() == code)
    }
}

/// A [`MarkKind`] drawn into a bottom view, with its box in the full colour image's pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mark {
    pub kind: MarkKind,
    pub x0: f32,
    pub y0: f32,
    pub x1: f32,
    pub y1: f32,
}

impl Mark {
    /// The box's centre.
    pub fn centre(&self) -> (f64, f64) {
        (f64::from(self.x0 + self.x1) / 2.0, f64::from(self.y0 + self.y1) / 2.0)
    }
}

/// Whether a bottom view is rendered with the things real bottom views show besides the
/// mouse's paws: glare at the glass's edge, pale spots and scratches on the glass, a pale
/// patch of belly fur. The paw detector's training and test sets use them as hard negatives.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BottomClutter {
    #[default]
    None,
    GlassAndBelly,
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
    render_bottom_with(camera, m, skin, margin, BottomClutter::None, rng)
}

/// [`render_bottom`], with `clutter` drawn in (no random draw is spent on it when `None`, so
/// views without clutter are the same as before it existed).
pub fn render_bottom_with(
    camera: &Camera,
    m: &MouseInstance,
    skin: &[Primitive],
    margin: u32,
    clutter: BottomClutter,
    rng: &mut impl Rng,
) -> BottomView {
    let scene = Scene::new(camera, skin);
    let i = &camera.intrinsics;
    let region = scene.bounds.grown(margin, i.width, i.height);
    let hits = scene.cast(region);
    let mut shaded = shade(camera, &scene, &hits);
    let paws = paw_boxes(m, &scene, &hits);
    let marks = match clutter {
        BottomClutter::None => Vec::new(),
        BottomClutter::GlassAndBelly => draw_clutter(camera, m, region, &paws, &mut shaded, rng),
    };
    let mut rgb = Vec::with_capacity(region.len() * 3);
    for px in &shaded {
        for &v in px {
            rgb.push(sensor_noise(v, rng));
        }
    }
    BottomView {
        region,
        rgb,
        paws,
        marks,
    }
}

/// Margin (pixels) kept between a mark's box and any paw's, so no positive window of a paw
/// is spoilt by a mark.
const MARK_CLEARANCE_PX: f32 = 4.0;

/// Draws glare, glass marks and a belly patch into `img` (the shaded view over `region`),
/// none of them within [`MARK_CLEARANCE_PX`] of a paw's box, and returns their boxes.
fn draw_clutter(
    camera: &Camera,
    m: &MouseInstance,
    region: Region,
    paws: &[PawBox; 4],
    img: &mut [[f32; 3]],
    rng: &mut impl Rng,
) -> Vec<Mark> {
    let (rx, ry) = (region.x0 as f32, region.y0 as f32);
    let (rw, rh) = (region.width as f32, region.height as f32);
    let clear = |b: [f32; 4]| {
        paws.iter().filter(|p| p.x1 > p.x0).all(|p| {
            b[0] > p.x1 + MARK_CLEARANCE_PX
                || b[2] < p.x0 - MARK_CLEARANCE_PX
                || b[1] > p.y1 + MARK_CLEARANCE_PX
                || b[3] < p.y0 - MARK_CLEARANCE_PX
        })
    };
    let mut marks = Vec::new();
    let mut place = |kind: MarkKind, blob: Blob, img: &mut [[f32; 3]]| {
        let b = blob.bounds();
        if !clear(b) || b[2] < rx || b[3] < ry || b[0] > rx + rw || b[1] > ry + rh {
            return;
        }
        blob.draw(region, img);
        marks.push(Mark {
            kind,
            x0: b[0].max(rx),
            y0: b[1].max(ry),
            x1: b[2].min(rx + rw),
            y1: b[3].min(ry + rh),
        });
    };
    if rng.gen_bool(0.7) {
        place(MarkKind::Glare, glare(region, rng), img);
    }
    // Spots and scratches anywhere in the view: on the glass, so over the mouse too.
    for _ in 0..rng.gen_range(0..=3) {
        let blob = glass_mark(region, rng);
        let kind = if blob.sigma < 1.5 {
            MarkKind::Scratch
        } else {
            MarkKind::Spot
        };
        place(kind, blob, img);
    }
    if rng.gen_bool(0.5)
        && let Some(blob) = belly_patch(camera, m, rng)
    {
        place(MarkKind::BellySpot, blob, img);
    }
    marks
}

/// Glare: a soft bright band along one edge of the view (`region`), the glass's edge
/// catching the LEDs.
fn glare(region: Region, rng: &mut impl Rng) -> Blob {
    let (rx, ry) = (region.x0 as f32, region.y0 as f32);
    let (rw, rh) = (region.width as f32, region.height as f32);
    let along = rng.gen_range(20.0f32..70.0);
    let across = rng.gen_range(2.5f32..7.0);
    let side = rng.gen_range(0..4);
    let inset = rng.gen_range(0.0f32..10.0);
    let (cx, cy, angle) = match side {
        0 => (rx + rng.gen_range(0.0..rw), ry + inset, 0.0),
        1 => (rx + rng.gen_range(0.0..rw), ry + rh - inset, 0.0),
        2 => (rx + inset, ry + rng.gen_range(0.0..rh), std::f32::consts::FRAC_PI_2),
        _ => (
            rx + rw - inset,
            ry + rng.gen_range(0.0..rh),
            std::f32::consts::FRAC_PI_2,
        ),
    };
    let level = rng.gen_range(90.0f32..230.0);
    Blob {
        cx,
        cy,
        half_length: along / 2.0,
        sigma: across / 2.0,
        angle: angle + rng.gen_range(-0.2..0.2),
        colour: [level * 0.95, level, level * 1.05],
        cover: 1.0,
    }
}

/// A spot (round, partly covering) or a scratch (long and thin, adding light) anywhere in
/// the view (`region`).
fn glass_mark(region: Region, rng: &mut impl Rng) -> Blob {
    let (rx, ry) = (region.x0 as f32, region.y0 as f32);
    let (rw, rh) = (region.width as f32, region.height as f32);
    let (cx, cy) = (rx + rng.gen_range(0.0..rw), ry + rng.gen_range(0.0..rh));
    let level = rng.gen_range(70.0f32..190.0);
    if rng.gen_bool(0.7) {
        Blob {
            cx,
            cy,
            half_length: rng.gen_range(0.0f32..4.0),
            sigma: rng.gen_range(2.0f32..6.0),
            angle: rng.gen_range(0.0..std::f32::consts::PI),
            colour: [level, level * 0.97, level * 0.92],
            cover: rng.gen_range(0.3f32..0.8),
        }
    } else {
        Blob {
            cx,
            cy,
            half_length: rng.gen_range(6.0f32..20.0),
            sigma: rng.gen_range(0.6f32..1.2),
            angle: rng.gen_range(0.0..std::f32::consts::PI),
            colour: [level; 3],
            cover: 0.0,
        }
    }
}

/// A pale patch of belly fur, under the back between the mid back and the rump; `None` when
/// that point does not project into the camera.
fn belly_patch(camera: &Camera, m: &MouseInstance, rng: &mut impl Rng) -> Option<Blob> {
    let t = rng.gen_range(0.0..1.0);
    let a = m.joint(Joint::MidBack);
    let b = m.joint(Joint::Rump);
    let on_belly = nalgebra::Point3::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, 0.0);
    let p = camera.project_world(&on_belly)?;
    Some(Blob {
        cx: p.x as f32,
        cy: p.y as f32,
        half_length: rng.gen_range(0.0f32..6.0),
        sigma: rng.gen_range(3.0f32..7.0),
        angle: rng.gen_range(0.0..std::f32::consts::PI),
        colour: [150.0, 122.0, 116.0].map(|c| c * rng.gen_range(0.6f32..1.0)),
        cover: 0.8,
    })
}

/// A soft elongated blob: a segment of `2 * half_length` pixels at `angle` with a Gaussian
/// profile of `sigma` across it. It covers what is under it by `cover` (0: adds light, as
/// glare and scratches do) and adds `colour` by its profile.
struct Blob {
    cx: f32,
    cy: f32,
    half_length: f32,
    sigma: f32,
    angle: f32,
    colour: [f32; 3],
    cover: f32,
}

impl Blob {
    fn bounds(&self) -> [f32; 4] {
        let (s, c) = self.angle.sin_cos();
        let r = 2.0 * self.sigma;
        let (dx, dy) = ((c * self.half_length).abs() + r, (s * self.half_length).abs() + r);
        [self.cx - dx, self.cy - dy, self.cx + dx, self.cy + dy]
    }

    fn draw(&self, region: Region, img: &mut [[f32; 3]]) {
        let b = self.bounds();
        let (s, c) = self.angle.sin_cos();
        let (w, h) = (region.width as i64, region.height as i64);
        let x0 = ((b[0] - region.x0 as f32).floor() as i64).max(0);
        let y0 = ((b[1] - region.y0 as f32).floor() as i64).max(0);
        let x1 = ((b[2] - region.x0 as f32).ceil() as i64).min(w - 1);
        let y1 = ((b[3] - region.y0 as f32).ceil() as i64).min(h - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f32 + region.x0 as f32 + 0.5, y as f32 + region.y0 as f32 + 0.5);
                let (u, v) = (px - self.cx, py - self.cy);
                let along = (u * c + v * s).abs();
                let across = (-u * s + v * c).abs();
                let d = (along - self.half_length).max(0.0).hypot(across);
                let k = (-(d * d) / (2.0 * self.sigma * self.sigma)).exp();
                if k < 0.01 {
                    continue;
                }
                let px = &mut img[(y * w + x) as usize];
                for (v, c) in px.iter_mut().zip(self.colour) {
                    *v = *v * (1.0 - self.cover * k) + c * k;
                }
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::geometry::Rig;
    use crate::synth::body::skin;
    use crate::synth::mouse::{pose_library, pose_mouse};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn a_binned_view_averages_whole_blocks_and_scales_its_boxes() {
        let paw = PawBox {
            joint: Joint::LeftForePaw,
            x0: 4.0,
            y0: 6.0,
            x1: 10.0,
            y1: 12.0,
            contact: true,
            visible: true,
        };
        // A 5x4 region at (3, 2): blocks of 2 start at (4, 2); column 3 and the last column
        // are cut, leaving 2x2 blocks.
        let region = Region {
            x0: 3,
            y0: 2,
            width: 5,
            height: 4,
        };
        let rgb: Vec<u8> = (0..region.len()).flat_map(|i| [i as u8 * 10, 7, 200]).collect();
        let view = BottomView {
            region,
            rgb,
            paws: [paw; 4],
            marks: vec![Mark {
                kind: MarkKind::Spot,
                x0: 2.0,
                y0: 2.0,
                x1: 4.0,
                y1: 4.0,
            }],
        };
        let b = view.binned(2);
        assert_eq!(
            b.region,
            Region {
                x0: 2,
                y0: 1,
                width: 2,
                height: 2
            }
        );
        // The first block: the view's pixels (1, 0), (2, 0), (1, 1), (2, 1), i.e. 1, 2, 6, 7.
        assert_eq!(&b.rgb[..3], &[(10 + 20 + 60 + 70 + 2) / 4, 7, 200]);
        assert_eq!(b.rgb.len(), 2 * 2 * 3);
        assert_eq!((b.paws[0].x0, b.paws[0].y1), (2.0, 6.0));
        assert_eq!((b.marks[0].x0, b.marks[0].y1), (1.0, 2.0));
        assert_eq!(view.binned(1), view);
    }

    #[test]
    fn clutter_marks_the_glass_and_the_belly_but_never_a_paw() {
        let rig = Rig::default_rig();
        let library = pose_library();
        let (mut marks, mut kinds) = (0, std::collections::HashSet::new());
        for k in 0..24 {
            let mut rng = ChaCha8Rng::seed_from_u64(k);
            let m = pose_mouse(
                &library[(k as usize * 31) % library.len()],
                &crate::synth::random_placement(&mut rng),
            );
            let s = skin(&m);
            let plain = render_bottom(&rig.color, &m, &s, 12, &mut ChaCha8Rng::seed_from_u64(k));
            let none = render_bottom_with(
                &rig.color,
                &m,
                &s,
                12,
                BottomClutter::None,
                &mut ChaCha8Rng::seed_from_u64(k),
            );
            assert_eq!(plain, none, "no clutter renders as before");
            let view = render_bottom_with(
                &rig.color,
                &m,
                &s,
                12,
                BottomClutter::GlassAndBelly,
                &mut ChaCha8Rng::seed_from_u64(k),
            );
            assert_eq!(view.paws, plain.paws);
            let r = view.region;
            for mark in &view.marks {
                marks += 1;
                kinds.insert(mark.kind);
                for p in view.paws.iter().filter(|p| p.x1 > p.x0) {
                    let apart = mark.x0 > p.x1 || mark.x1 < p.x0 || mark.y0 > p.y1 || mark.y1 < p.y0;
                    assert!(apart, "{mark:?} on the paw {p:?}");
                }
                // The mark is paler than what it lies on (3x3 pixels at its centre).
                let (cx, cy) = mark.centre();
                let at = |v: &BottomView| {
                    let mut sum = 0;
                    for dy in -1..=1 {
                        for dx in -1..=1 {
                            let x = (cx as i64 + dx).clamp(i64::from(r.x0), i64::from(r.x0 + r.width - 1)) as u32;
                            let y = (cy as i64 + dy).clamp(i64::from(r.y0), i64::from(r.y0 + r.height - 1)) as u32;
                            let i = ((y - r.y0) * r.width + (x - r.x0)) as usize * 3;
                            sum += v.rgb[i..i + 3].iter().map(|&c| i32::from(c)).sum::<i32>();
                        }
                    }
                    sum / 9
                };
                assert!(
                    at(&view) >= at(&plain) + 20,
                    "{mark:?}: {} against {}",
                    at(&view),
                    at(&plain)
                );
            }
        }
        assert!(marks >= 24, "{marks} marks in 24 views");
        assert_eq!(kinds.len(), 4, "{kinds:?}");
    }
}
