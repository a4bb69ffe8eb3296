//! Where in the bottom view to look for paws: the body's footprint on the glass, from the
//! body joints the depth view gave, projected into the bottom camera.

use crate::core::geometry::Camera;
use crate::core::pose::{JointSource, Pose};
use crate::core::skeleton::Joint;
use nalgebra::Point3;

/// How far beyond the body's joints (mm, on the glass) a paw can be: a limb's reach sideways
/// and the snout's and tail base's overhang.
pub const FOOTPRINT_MARGIN_MM: f64 = 18.0;

/// The footprint of the body (joints 1-12 but the tail tip) on the glass in the bottom
/// camera's image: pixel bounds `(x0, y0, x1, y1)` within the image, and how many pixels a
/// millimetre on the glass spans there. `None` without body joints or when the footprint is
/// out of view.
pub fn footprint(pose: &Pose, camera: &Camera, margin_mm: f64) -> Option<((u32, u32, u32, u32), f64)> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for j in Joint::MAIN_BODY.iter().filter(|j| **j != Joint::TailTip) {
        let e = pose.joint(*j);
        if e.source == JointSource::Missing {
            continue;
        }
        let p = e.position_mm;
        lo = [lo[0].min(p.x), lo[1].min(p.y)];
        hi = [hi[0].max(p.x), hi[1].max(p.y)];
    }
    if !lo[0].is_finite() {
        return None;
    }
    let corners = [
        (lo[0] - margin_mm, lo[1] - margin_mm),
        (hi[0] + margin_mm, lo[1] - margin_mm),
        (lo[0] - margin_mm, hi[1] + margin_mm),
        (hi[0] + margin_mm, hi[1] + margin_mm),
    ];
    let (mut a, mut b) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (x, y) in corners {
        let q = camera.project_world(&Point3::new(x, y, 0.0))?;
        a = [a[0].min(q.x), a[1].min(q.y)];
        b = [b[0].max(q.x), b[1].max(q.y)];
    }
    let i = &camera.intrinsics;
    let clamp = |v: f64, max: u32| v.clamp(0.0, f64::from(max)) as u32;
    let roi = (
        clamp(a[0].floor(), i.width),
        clamp(a[1].floor(), i.height),
        clamp(b[0].ceil(), i.width),
        clamp(b[1].ceil(), i.height),
    );
    if roi.2 <= roi.0 || roi.3 <= roi.1 {
        return None;
    }
    // Pixels per millimetre on the glass at the footprint's centre.
    let centre = Point3::new((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, 0.0);
    let depth = (camera.camera_from_world() * centre).z;
    (depth > 0.0).then(|| (roi, i.fx / depth))
}
