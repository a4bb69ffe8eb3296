//! `session.toml`: what a session is (format and version, software, when, synthetic or
//! recorded), the rig's calibration and the cameras that recorded it.
//!
//! The rig is stored in an explicit, human-readable form (intrinsics, `translation_mm`,
//! `rotation_quaternion_wxyz` per camera) rather than nalgebra's own serialisation, whose
//! quaternion order (`[i, j, k, w]`) is easy to misread when editing a file by hand.

use super::codec::FrameFormat;
use crate::core::geometry::{Camera, Intrinsics, Rig};
use crate::io::store::Kind;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// The `format` value of every session.
pub const FORMAT_NAME: &str = "mousepose-session";
/// The session format version this module writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// Which camera of the rig.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraRole {
    /// The depth camera above the cage.
    Depth,
    /// The colour camera under the glass floor.
    Color,
}

impl CameraRole {
    /// `depth` or `color`: the name in metadata and events, and the camera's subdirectory.
    pub fn name(self) -> &'static str {
        match self {
            CameraRole::Depth => "depth",
            CameraRole::Color => "color",
        }
    }
}

impl CameraRole {
    /// The kind of record file that holds this camera's frames.
    pub fn store_kind(self) -> Kind {
        match self {
            CameraRole::Depth => Kind::DepthFrames,
            CameraRole::Color => Kind::ColorFrames,
        }
    }
}

impl fmt::Display for CameraRole {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The driver a camera was read through, by the name its backend gives itself (`openni2`,
/// `aravis`, `v4l2`, `moseq`, ...; `synthetic` for rendered frames). Sessions name it; the
/// backends themselves are registered in the runtime (`runtime::capture::backend`), so a
/// session written through a backend this build lacks still reads.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct BackendName(std::borrow::Cow<'static, str>);

impl BackendName {
    /// Rendered frames (`synth`).
    pub const SYNTHETIC: Self = Self::new("synthetic");

    pub const fn new(name: &'static str) -> Self {
        Self(std::borrow::Cow::Borrowed(name))
    }

    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl PartialEq<&str> for BackendName {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

impl fmt::Display for BackendName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Whether a session was generated or recorded from cameras.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionSource {
    Synthetic,
    Recorded,
}

/// One camera of the session as it was configured when recording started.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraMeta {
    pub role: CameraRole,
    pub backend: BackendName,
    pub model: String,
    pub serial: String,
    #[serde(default)]
    pub firmware: String,
    pub width: u32,
    pub height: u32,
    /// `depth16` for the depth camera, a colour format for the colour camera.
    pub pixel_format: FrameFormat,
    pub fps: f64,
}

/// The contents of `session.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionMeta {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// Always [`FORMAT_VERSION`] for sessions this version writes.
    pub format_version: u32,
    /// The mousepose version that wrote the session.
    pub software_version: String,
    /// When the session started, as the caller wrote it (RFC 3339 UTC by convention).
    pub created: String,
    pub source: SessionSource,
    #[serde(default)]
    pub notes: String,
    /// The calibration in use when the session was written, if there was one.
    #[serde(default, skip_serializing_if = "Option::is_none", with = "rig_repr")]
    pub rig: Option<Rig>,
    /// The colour camera's minimal transport latency minus the depth camera's (ns), when
    /// known: the rig config's `sync.color_latency_ms` for recorded sessions, the simulated
    /// cameras' own for synthetic ones. Replay pairs frames with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color_latency_ns: Option<i64>,
    /// One entry per camera: exactly one depth camera, at most one colour camera.
    pub cameras: Vec<CameraMeta>,
    /// The synthetic generator's parameters, free-form.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synthetic: Option<toml::Table>,
}

impl SessionMeta {
    /// Metadata for the current format and software version, without rig, notes or
    /// generator parameters.
    pub fn new(created: impl Into<String>, source: SessionSource, cameras: Vec<CameraMeta>) -> Self {
        Self {
            format: FORMAT_NAME.to_owned(),
            format_version: FORMAT_VERSION,
            software_version: env!("CARGO_PKG_VERSION").to_owned(),
            created: created.into(),
            source,
            notes: String::new(),
            rig: None,
            color_latency_ns: None,
            cameras,
            synthetic: None,
        }
    }

    /// The camera with a role, if the session has one.
    pub fn camera(&self, role: CameraRole) -> Option<&CameraMeta> {
        self.cameras.iter().find(|c| c.role == role)
    }

    /// What is wrong with the metadata, if anything: format, version, one depth camera, at
    /// most one colour camera, pixel formats that fit the roles.
    pub fn problem(&self) -> Option<String> {
        if self.format != FORMAT_NAME {
            return Some(format!("not a mousepose session (format = {:?})", self.format));
        }
        if self.format_version != FORMAT_VERSION {
            return Some(format!("unsupported session format version {}", self.format_version));
        }
        for role in [CameraRole::Depth, CameraRole::Color] {
            let count = self.cameras.iter().filter(|c| c.role == role).count();
            if count > 1 {
                return Some(format!("{count} cameras with role {role}, at most one allowed"));
            }
        }
        if self.camera(CameraRole::Depth).is_none() {
            return Some("no camera with role depth".to_owned());
        }
        for camera in &self.cameras {
            let fits = match camera.role {
                CameraRole::Depth => camera.pixel_format == FrameFormat::Depth16,
                CameraRole::Color => camera.pixel_format != FrameFormat::Depth16,
            };
            if !fits {
                return Some(format!(
                    "the {} camera can not have pixel format {}",
                    camera.role, camera.pixel_format
                ));
            }
        }
        None
    }
}

/// `Option<Rig>` as `[rig.depth]` and `[rig.color]` tables of explicit fields.
pub mod rig_repr {
    use super::*;

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct RigRepr {
        depth: CameraRepr,
        color: CameraRepr,
    }

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct CameraRepr {
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        /// `[k1, k2, p1, p2, k3]`.
        #[serde(default)]
        distortion: [f64; 5],
        /// The camera's centre in the world frame.
        translation_mm: [f64; 3],
        /// The rotation of `world_from_camera`, scalar first.
        rotation_quaternion_wxyz: [f64; 4],
    }

    impl CameraRepr {
        fn from_camera(camera: &Camera) -> Self {
            let i = &camera.intrinsics;
            let t = camera.world_from_camera.translation.vector;
            let q = camera.world_from_camera.rotation.quaternion();
            Self {
                width: i.width,
                height: i.height,
                fx: i.fx,
                fy: i.fy,
                cx: i.cx,
                cy: i.cy,
                distortion: i.distortion,
                translation_mm: [t.x, t.y, t.z],
                rotation_quaternion_wxyz: [q.w, q.i, q.j, q.k],
            }
        }

        fn to_camera(&self, role: &str) -> Result<Camera, String> {
            let [w, x, y, z] = self.rotation_quaternion_wxyz;
            let q = Quaternion::new(w, x, y, z);
            let norm = q.norm();
            if !norm.is_finite() || (norm - 1.0).abs() > 1e-6 {
                return Err(format!(
                    "rig.{role}.rotation_quaternion_wxyz is not a unit quaternion (norm {norm})"
                ));
            }
            // Keep the stored numbers exactly when they are unit already, so files round-trip.
            let rotation = if (norm - 1.0).abs() <= 1e-12 {
                UnitQuaternion::new_unchecked(q)
            } else {
                UnitQuaternion::new_normalize(q)
            };
            let [tx, ty, tz] = self.translation_mm;
            Ok(Camera {
                intrinsics: Intrinsics {
                    width: self.width,
                    height: self.height,
                    fx: self.fx,
                    fy: self.fy,
                    cx: self.cx,
                    cy: self.cy,
                    distortion: self.distortion,
                },
                world_from_camera: Isometry3::from_parts(Translation3::new(tx, ty, tz), rotation),
            })
        }
    }

    pub fn serialize<S: Serializer>(rig: &Option<Rig>, serializer: S) -> Result<S::Ok, S::Error> {
        rig.as_ref()
            .map(|rig| RigRepr {
                depth: CameraRepr::from_camera(&rig.depth),
                color: CameraRepr::from_camera(&rig.color),
            })
            .serialize(serializer)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Option<Rig>, D::Error> {
        let Some(repr) = Option::<RigRepr>::deserialize(deserializer)? else {
            return Ok(None);
        };
        let depth = repr.depth.to_camera("depth").map_err(serde::de::Error::custom)?;
        let color = repr.color.to_camera("color").map_err(serde::de::Error::custom)?;
        Ok(Some(Rig { depth, color }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta() -> SessionMeta {
        let depth = CameraMeta {
            role: CameraRole::Depth,
            backend: BackendName::SYNTHETIC,
            model: "synthetic depth".into(),
            serial: "0".into(),
            firmware: String::new(),
            width: 640,
            height: 480,
            pixel_format: FrameFormat::Depth16,
            fps: 30.0,
        };
        let color = CameraMeta {
            role: CameraRole::Color,
            pixel_format: FrameFormat::Color(crate::core::frame::PixelFormat::BayerRg8),
            width: 640,
            height: 512,
            model: "synthetic colour".into(),
            ..depth.clone()
        };
        let mut meta = SessionMeta::new("2026-11-21T20:00:00Z", SessionSource::Synthetic, vec![depth, color]);
        meta.rig = Some(Rig::default_rig().with_color_binning(2));
        let mut synthetic = toml::Table::new();
        synthetic.insert("seed".into(), toml::Value::Integer(42));
        synthetic.insert("speed_mm_s".into(), toml::Value::Float(80.5));
        meta.synthetic = Some(synthetic);
        meta
    }

    #[test]
    fn round_trips_through_toml_exactly() {
        let meta = meta();
        let text = toml::to_string(&meta).unwrap();
        assert!(text.contains("rotation_quaternion_wxyz = ["), "{text}");
        assert!(text.contains("pixel_format = \"bayer_rg8\""), "{text}");
        let back: SessionMeta = toml::from_str(&text).unwrap();
        assert_eq!(back, meta);
        assert_eq!(toml::to_string(&back).unwrap(), text);
        assert!(back.problem().is_none());
    }

    #[test]
    fn rig_is_optional_and_checked() {
        let mut meta = meta();
        meta.rig = None;
        let text = toml::to_string(&meta).unwrap();
        assert!(!text.contains("[rig"));
        assert_eq!(toml::from_str::<SessionMeta>(&text).unwrap(), meta);
        let text = toml::to_string(&self::meta()).unwrap();
        let i = text.find("rotation_quaternion_wxyz = [").unwrap() + "rotation_quaternion_wxyz = [".len();
        let broken = format!(
            "{}2.0, 0.0, 0.0, 0.0]{}",
            &text[..i],
            &text[i..].split_once(']').unwrap().1
        );
        let err = toml::from_str::<SessionMeta>(&broken).unwrap_err().to_string();
        assert!(err.contains("not a unit quaternion"), "{err}");
    }

    #[test]
    fn problems_are_named() {
        let mut m = meta();
        m.cameras[1].pixel_format = FrameFormat::Depth16;
        assert_eq!(
            m.problem().unwrap(),
            "the color camera can not have pixel format depth16"
        );
        let mut m = meta();
        m.cameras.remove(0);
        assert_eq!(m.problem().unwrap(), "no camera with role depth");
        let mut m = meta();
        m.format_version = 2;
        assert_eq!(m.problem().unwrap(), "unsupported session format version 2");
    }
}
