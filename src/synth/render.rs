//! Ray casting of the mouse's skin and the cage into a camera: the depth and part-label images
//! of the top camera and the shaded view of the bottom camera.
//!
//! Each primitive is cast only over the pixels of its own projected bounding box, so a frame
//! costs about as many ray tests as the mouse covers pixels, whatever the image size.

use super::body::{Labeller, Material, Primitive, Shape};
use crate::core::geometry::{CAGE_WALL_MM, CAGE_X_MM, CAGE_Y_MM, Camera, Intrinsics};
use crate::core::image::Region;
use crate::core::skeleton::BACKGROUND_LABEL;
use nalgebra::{Isometry3, Matrix3, Point2, Point3, Vector3};

/// A primitive moved into a camera's frame, with what the ray tests need precomputed.
#[derive(Clone, Copy, Debug)]
enum CamShape {
    Ellipsoid {
        /// Maps camera coordinates relative to the centre into the unit sphere.
        to_unit: Matrix3<f64>,
        /// The camera centre in unit-sphere coordinates and its squared norm minus one.
        origin: Vector3<f64>,
        c: f64,
    },
    Capsule {
        a: Vector3<f64>,
        ba: Vector3<f64>,
        baba: f64,
        radius: f64,
    },
}

#[derive(Clone, Copy, Debug)]
struct CamPrimitive {
    shape: CamShape,
    labeller: Labeller,
    material: Material,
    bbox: Region,
    /// The projection's exact bounds `[u0, v0, u1, v1]` in pixels.
    extent: [f64; 4],
}

/// What a ray hit: its depth along the optical axis, the primitive and the part label.
#[derive(Clone, Debug)]
pub struct Hits {
    pub region: Region,
    /// Camera z in millimetres, `f32::INFINITY` where no primitive was hit.
    pub z: Vec<f32>,
    /// Index of the primitive hit, `u16::MAX` for none.
    pub primitive: Vec<u16>,
    pub label: Vec<u8>,
}

impl Hits {
    fn new(region: Region) -> Self {
        let n = region.len();
        Self {
            region,
            z: vec![f32::INFINITY; n],
            primitive: vec![u16::MAX; n],
            label: vec![BACKGROUND_LABEL; n],
        }
    }
}

fn to_camera(prim: &Primitive, iso: &Isometry3<f64>, intrinsics: &Intrinsics) -> Option<CamPrimitive> {
    let (shape, lo, hi) = match prim.shape {
        Shape::Ellipsoid { centre, axes, radii } => {
            let c = iso * centre;
            let r = iso.rotation.to_rotation_matrix() * axes;
            let m = r.matrix();
            let inv_r = Matrix3::from_diagonal(&radii.map(|v| 1.0 / v));
            let to_unit = inv_r * m.transpose();
            let origin = to_unit * -c.coords;
            // Axis-aligned half extents of the rotated ellipsoid.
            let half = Vector3::from_fn(|i, _| (0..3).map(|k| (m[(i, k)] * radii[k]).powi(2)).sum::<f64>().sqrt());
            (
                CamShape::Ellipsoid {
                    to_unit,
                    origin,
                    c: origin.norm_squared() - 1.0,
                },
                c.coords - half,
                c.coords + half,
            )
        }
        Shape::Capsule { a, b, radius } => {
            let a = iso * a;
            let b = iso * b;
            let ba = b - a;
            let r = Vector3::repeat(radius);
            (
                CamShape::Capsule {
                    a: a.coords,
                    ba,
                    baba: ba.norm_squared().max(1e-12),
                    radius,
                },
                a.coords.inf(&b.coords) - r,
                a.coords.sup(&b.coords) + r,
            )
        }
    };
    let (bbox, extent) = project_box(&lo, &hi, intrinsics)?;
    Some(CamPrimitive {
        shape,
        labeller: prim.labeller.transformed(iso),
        material: prim.material,
        bbox,
        extent,
    })
}

/// The pixels covered by the projection of an axis-aligned box in camera coordinates, and the
/// projection's exact bounds; `None` when the box reaches behind the camera or misses the image.
fn project_box(lo: &Vector3<f64>, hi: &Vector3<f64>, intrinsics: &Intrinsics) -> Option<(Region, [f64; 4])> {
    if lo.z <= 1.0 {
        return None;
    }
    let (mut u0, mut v0, mut u1, mut v1) = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for k in 0..8 {
        let p = Point3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        let q = intrinsics.project(&p)?;
        u0 = u0.min(q.x);
        v0 = v0.min(q.y);
        u1 = u1.max(q.x);
        v1 = v1.max(q.y);
    }
    let w = f64::from(intrinsics.width);
    let h = f64::from(intrinsics.height);
    // One pixel of slack for distortion and rounding.
    let x0 = (u0 - 1.0).floor().clamp(0.0, w);
    let y0 = (v0 - 1.0).floor().clamp(0.0, h);
    let x1 = (u1 + 2.0).ceil().clamp(0.0, w);
    let y1 = (v1 + 2.0).ceil().clamp(0.0, h);
    let region = Region {
        x0: x0 as u32,
        y0: y0 as u32,
        width: (x1 - x0) as u32,
        height: (y1 - y0) as u32,
    };
    (!region.is_empty()).then_some((region, [u0, v0, u1, v1]))
}

impl CamShape {
    /// Distance along `d` (a ray from the camera centre) to the first hit, in units of `d`.
    #[inline]
    fn intersect(&self, d: &Vector3<f64>) -> Option<f64> {
        match *self {
            CamShape::Ellipsoid { to_unit, origin, c } => {
                let du = to_unit * d;
                let a = du.norm_squared();
                let b = origin.dot(&du);
                let disc = b * b - a * c;
                if disc < 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                (t > 0.0).then_some(t)
            }
            CamShape::Capsule { a, ba, baba, radius } => {
                // Ray from the origin: oa = -a.
                let oa = -a;
                let dd = d.norm_squared();
                let bard = ba.dot(d);
                let baoa = ba.dot(&oa);
                let rdoa = d.dot(&oa);
                let oaoa = oa.norm_squared();
                let k2 = baba * dd - bard * bard;
                let k1 = baba * rdoa - baoa * bard;
                let k0 = baba * oaoa - baoa * baoa - radius * radius * baba;
                let h = k1 * k1 - k2 * k0;
                if h < 0.0 {
                    return None;
                }
                // The cylinder's side, when the ray is not parallel to the axis.
                let cap_a = if k2 > 1e-12 {
                    let t = (-k1 - h.sqrt()) / k2;
                    let y = baoa + t * bard;
                    if y > 0.0 && y < baba {
                        return (t > 0.0).then_some(t);
                    }
                    y <= 0.0
                } else {
                    bard > 0.0
                };
                // Otherwise one of the caps.
                let oc = if cap_a { oa } else { oa - ba };
                let b = d.dot(&oc);
                let c = oc.norm_squared() - radius * radius;
                let h = b * b - dd * c;
                if h < 0.0 {
                    return None;
                }
                let t = (-b - h.sqrt()) / dd;
                (t > 0.0).then_some(t)
            }
        }
    }

    /// Whether the point `p` (camera frame) lies inside the solid.
    fn contains(&self, p: &Vector3<f64>) -> bool {
        match *self {
            CamShape::Ellipsoid { to_unit, origin, .. } => (to_unit * p + origin).norm_squared() <= 1.0,
            CamShape::Capsule { a, ba, baba, radius } => {
                let t = ((p - a).dot(&ba) / baba).clamp(0.0, 1.0);
                (p - (a + ba * t)).norm_squared() <= radius * radius
            }
        }
    }

    /// Outward surface normal at a surface point `p` (camera frame).
    fn normal(&self, p: &Vector3<f64>) -> Vector3<f64> {
        match *self {
            CamShape::Ellipsoid { to_unit, origin, .. } => {
                // In unit-sphere space the normal is the point; map the gradient back.
                let q = to_unit * p + origin;
                (to_unit.transpose() * q).normalize()
            }
            CamShape::Capsule { a, ba, baba, .. } => {
                let t = ((p - a).dot(&ba) / baba).clamp(0.0, 1.0);
                (p - (a + ba * t)).normalize()
            }
        }
    }
}

/// The skin of one mouse prepared for one camera.
///
/// The glass floor clips the skin: nothing lies below it, and a solid that reaches through it
/// shows its flat contact patch to the camera underneath.
#[derive(Clone, Debug)]
pub struct Scene {
    primitives: Vec<CamPrimitive>,
    intrinsics: Intrinsics,
    /// World up in the camera frame and the camera centre's height: a camera-frame point
    /// `p` lies `up . p + height` above the floor.
    up: Vector3<f64>,
    height: f64,
    /// Index of each input primitive in `primitives` (`None` when it is out of view).
    pub visible: Vec<Option<usize>>,
    /// The pixels any primitive can cover.
    pub bounds: Region,
}

impl Scene {
    /// Moves the primitives into the camera's frame and works out what each can cover.
    pub fn new(camera: &Camera, skin: &[Primitive]) -> Self {
        let iso = camera.camera_from_world();
        let mut primitives = Vec::with_capacity(skin.len());
        let mut visible = Vec::with_capacity(skin.len());
        let mut bounds = Region::default();
        for prim in skin {
            match to_camera(prim, &iso, &camera.intrinsics) {
                Some(p) => {
                    bounds = bounds.union(&p.bbox);
                    visible.push(Some(primitives.len()));
                    primitives.push(p);
                }
                None => visible.push(None),
            }
        }
        Self {
            primitives,
            intrinsics: camera.intrinsics,
            up: iso.rotation * Vector3::z(),
            height: camera.centre().z,
            visible,
            bounds,
        }
    }

    #[inline]
    fn height_of(&self, p: &Vector3<f64>) -> f64 {
        self.up.dot(p) + self.height
    }

    /// The first hit of ray `d` on a primitive, clipped by the floor.
    #[inline]
    fn hit(&self, prim: &CamPrimitive, d: &Vector3<f64>) -> Option<f64> {
        let t = prim.shape.intersect(d)?;
        if self.height_of(&(d * t)) >= 0.0 {
            return Some(t);
        }
        // The entry is under the glass: seen from below, the solid's cut by the floor plane.
        let rate = self.up.dot(d);
        if rate <= 1e-12 {
            return None;
        }
        let t_floor = -self.height / rate;
        (t_floor > t && prim.shape.contains(&(d * t_floor))).then_some(t_floor)
    }

    /// Casts every primitive over its pixels inside `region`, nearest hit wins.
    pub fn cast(&self, region: Region) -> Hits {
        let mut hits = Hits::new(region);
        let stride = region.width as usize;
        for (index, prim) in self.primitives.iter().enumerate() {
            let r = prim.bbox.intersect(&region);
            for y in r.y0..r.y0 + r.height {
                let row = (y - region.y0) as usize * stride;
                for x in r.x0..r.x0 + r.width {
                    let d = self.intrinsics.ray(&Point2::new(f64::from(x), f64::from(y)));
                    let Some(t) = self.hit(prim, &d) else {
                        continue;
                    };
                    // With d.z == 1, t is the depth along the optical axis.
                    let z = t as f32;
                    let i = row + (x - region.x0) as usize;
                    if z < hits.z[i] {
                        hits.z[i] = z;
                        hits.primitive[i] = index as u16;
                        hits.label[i] = prim.labeller.label(&Point3::from(d * t)).label();
                    }
                }
            }
        }
        hits
    }

    /// Surface normal (camera frame) and material at a hit pixel.
    pub fn surface(&self, hits: &Hits, x: u32, y: u32) -> Option<(Vector3<f64>, Vector3<f64>, Material)> {
        let i = (y - hits.region.y0) as usize * hits.region.width as usize + (x - hits.region.x0) as usize;
        let prim = self.primitives.get(usize::from(*hits.primitive.get(i)?))?;
        let d = self.intrinsics.ray(&Point2::new(f64::from(x), f64::from(y)));
        let p = d * f64::from(hits.z[i]);
        // On the floor's cut the surface faces straight down.
        let normal = if self.height_of(&p) < 1e-3 {
            -self.up
        } else {
            prim.shape.normal(&p)
        };
        Some((p, normal, prim.material))
    }

    /// The bounds `[u0, v0, u1, v1]` (pixels) of input primitive `index`'s projected bounding
    /// box, if it is in view.
    pub fn primitive_extent(&self, index: usize) -> Option<[f64; 4]> {
        let k = (*self.visible.get(index)?)?;
        Some(self.primitives[k].extent)
    }

    /// How many pixels of `hits` show input primitive `index`.
    pub fn pixels_of(&self, hits: &Hits, index: usize) -> usize {
        match self.visible.get(index).copied().flatten() {
            Some(k) => hits.primitive.iter().filter(|&&p| usize::from(p) == k).count(),
            None => 0,
        }
    }
}

/// The cage: the glass floor and the four inner wall faces, as seen by a camera above it.
#[derive(Clone, Debug)]
pub struct Cage {
    camera: Camera,
}

impl Cage {
    pub fn new(camera: &Camera) -> Self {
        Self { camera: *camera }
    }

    /// The depth (camera z, mm) of the cage surface seen at a pixel, or `None` when the ray
    /// leaves the cage without hitting it.
    pub fn depth_at(&self, x: u32, y: u32) -> Option<f32> {
        let d_cam = self.camera.intrinsics.ray(&Point2::new(f64::from(x), f64::from(y)));
        let o = self.camera.centre();
        let d = self.camera.world_from_camera.rotation * d_cam;
        let hx = CAGE_X_MM / 2.0;
        let hy = CAGE_Y_MM / 2.0;
        let mut best = f64::INFINITY;
        let mut try_plane = |t: f64, inside: &dyn Fn(&Point3<f64>) -> bool| {
            if t > 0.0 && t < best && inside(&(o + d * t)) {
                best = t;
            }
        };
        if d.z.abs() > 1e-12 {
            try_plane(-o.z / d.z, &|p| p.x.abs() <= hx && p.y.abs() <= hy);
        }
        for (axis, half, other_half) in [(0usize, hx, hy), (1, hy, hx)] {
            if d[axis].abs() < 1e-12 {
                continue;
            }
            for sign in [-1.0, 1.0] {
                let t = (sign * half - o[axis]) / d[axis];
                try_plane(t, &|p| {
                    p[1 - axis].abs() <= other_half && p.z >= 0.0 && p.z <= CAGE_WALL_MM
                });
            }
        }
        // t is in units of d, whose camera-frame z is 1.
        best.is_finite().then_some(best as f32)
    }

    /// The cage's depth over a region, 0 where there is none.
    pub fn depth(&self, region: Region) -> Vec<f32> {
        let mut out = Vec::with_capacity(region.len());
        for y in region.y0..region.y0 + region.height {
            for x in region.x0..region.x0 + region.width {
                out.push(self.depth_at(x, y).unwrap_or(0.0));
            }
        }
        out
    }
}
