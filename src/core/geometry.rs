//! Cameras and rigid transforms: pinhole intrinsics with Brown-Conrady distortion, camera
//! poses in the world frame, and the default rig (`Rig::default_rig`).
//!
//! Conventions: the world frame has its origin on the glass floor's top surface at the cage's
//! centre, x along the 500 mm side, y along the 450 mm side, z up, millimetres. Camera frames
//! follow OpenCV: x right, y down, z along the optical axis. Transforms are named
//! `<to>_from_<from>`, so `p_world = world_from_camera * p_camera` reads correctly.

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics with OpenCV's five-parameter distortion `[k1, k2, p1, p2, k3]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    #[serde(default)]
    pub distortion: [f64; 5],
}

impl Intrinsics {
    /// True when the distortion coefficients are all zero.
    pub fn is_rectified(&self) -> bool {
        self.distortion.iter().all(|&k| k == 0.0)
    }

    /// Applies the distortion model to normalised image coordinates.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        (xd, yd)
    }

    /// Inverts [`Intrinsics::distort`] by fixed-point iteration (converges for the mild
    /// distortion of real lenses).
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if self.is_rectified() {
            return (xd, yd);
        }
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let (dx, dy) = self.distort(x, y);
            x -= dx - xd;
            y -= dy - yd;
        }
        (x, y)
    }

    /// Projects a point in the camera frame to pixel coordinates; `None` behind the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<Point2<f64>> {
        if p.z <= 1e-9 {
            return None;
        }
        let (x, y) = self.distort(p.x / p.z, p.y / p.z);
        Some(Point2::new(self.fx * x + self.cx, self.fy * y + self.cy))
    }

    /// The direction of the ray through a pixel, scaled so that its z component is 1
    /// (so `ray * depth` is the 3D point at that depth).
    pub fn ray(&self, pixel: &Point2<f64>) -> Vector3<f64> {
        let (x, y) = self.undistort((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy);
        Vector3::new(x, y, 1.0)
    }

    /// The point in the camera frame seen at `pixel` with depth `z_mm` along the optical axis.
    pub fn unproject(&self, pixel: &Point2<f64>, z_mm: f64) -> Point3<f64> {
        Point3::from(self.ray(pixel) * z_mm)
    }

    /// True when the pixel coordinate lies inside the image.
    pub fn contains(&self, pixel: &Point2<f64>) -> bool {
        pixel.x >= 0.0 && pixel.y >= 0.0 && pixel.x < f64::from(self.width) && pixel.y < f64::from(self.height)
    }
}

/// A camera: its intrinsics and where it stands in the world.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    pub world_from_camera: Isometry3<f64>,
}

impl Camera {
    /// The transform from world coordinates to this camera's frame.
    pub fn camera_from_world(&self) -> Isometry3<f64> {
        self.world_from_camera.inverse()
    }

    /// Projects a world point into the image; `None` behind the camera.
    pub fn project_world(&self, p_world: &Point3<f64>) -> Option<Point2<f64>> {
        self.intrinsics.project(&(self.camera_from_world() * p_world))
    }

    /// The camera's centre in the world frame.
    pub fn centre(&self) -> Point3<f64> {
        Point3::from(self.world_from_camera.translation.vector)
    }

    /// How many image pixels a millimetre on the glass (the world's z = 0 plane) spans right
    /// below the camera; `None` when that point is not in front of it.
    pub fn glass_px_per_mm(&self) -> Option<f64> {
        let c = self.centre();
        let depth = (self.camera_from_world() * Point3::new(c.x, c.y, 0.0)).z;
        (depth > 0.0).then(|| self.intrinsics.fx / depth)
    }
}

/// A camera at `centre` whose optical axis points at `target`, with the image's "down"
/// direction as close to `down_hint` as the axis allows.
pub fn look_at(centre: Point3<f64>, target: Point3<f64>, down_hint: Vector3<f64>) -> Isometry3<f64> {
    let z = (target - centre).normalize();
    let x = down_hint.cross(&z).normalize();
    let y = z.cross(&x);
    let rotation = nalgebra::Rotation3::from_basis_unchecked(&[x, y, z]);
    Isometry3::from_parts(
        Translation3::from(centre.coords),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// The two cameras of a rig, both posed in the world frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rig {
    /// The depth camera above the cage.
    pub depth: Camera,
    /// The colour camera under the glass floor.
    pub color: Camera,
}

/// Inside dimensions of the default cage (open field), millimetres.
pub const CAGE_X_MM: f64 = 500.0;
pub const CAGE_Y_MM: f64 = 450.0;
pub const CAGE_WALL_MM: f64 = 300.0;

impl Rig {
    /// Height of the depth camera's centre above the glass, and depth of the colour camera's
    /// centre below it.
    pub const CAMERA_DISTANCE_MM: f64 = 600.0;
    /// How far the colour camera's axis leans from the vertical.
    pub const COLOR_TILT_DEG: f64 = 10.0;

    /// The default rig: a Primesense-like depth camera (640x480, fx 570 px) 600 mm above
    /// the floor looking straight down, and a 1280x1024 colour camera 600 mm below the glass,
    /// tilted 10 degrees and aimed at the cage's centre.
    pub fn default_rig() -> Self {
        let depth = Camera {
            intrinsics: Intrinsics {
                width: 640,
                height: 480,
                fx: 570.3,
                fy: 570.3,
                cx: 319.5,
                cy: 239.5,
                distortion: [0.0; 5],
            },
            // Image x along world +x, image y along world -y, optical axis down.
            world_from_camera: look_at(
                Point3::new(0.0, 0.0, Self::CAMERA_DISTANCE_MM),
                Point3::origin(),
                -Vector3::y(),
            ),
        };
        let tilt = Self::COLOR_TILT_DEG.to_radians();
        let centre = Point3::new(0.0, -Self::CAMERA_DISTANCE_MM * tilt.tan(), -Self::CAMERA_DISTANCE_MM);
        let color = Camera {
            intrinsics: Intrinsics {
                width: 1280,
                height: 1024,
                fx: 1200.0,
                fy: 1200.0,
                cx: 639.5,
                cy: 511.5,
                distortion: [0.0; 5],
            },
            // Seen from below, image x runs along world +x and image y along world +y.
            world_from_camera: look_at(centre, Point3::origin(), Vector3::y()),
        };
        Self { depth, color }
    }

    /// The same rig with the colour camera binned by `factor` (a smaller sensor mode with the
    /// same field of view), as small sessions and fixtures use.
    pub fn with_color_binning(mut self, factor: u32) -> Self {
        let k = f64::from(factor.max(1));
        let i = &mut self.color.intrinsics;
        i.width /= factor.max(1);
        i.height /= factor.max(1);
        i.fx /= k;
        i.fy /= k;
        i.cx = (i.cx + 0.5) / k - 0.5;
        i.cy = (i.cy + 0.5) / k - 0.5;
        self
    }
}
