//! Common depth cameras' intrinsics by frame size and mode, for recordings made without a
//! calibration (MoSeq-layout recordings above all): which camera made a recording is read from
//! its metadata when it says so, else from its frame size.
//!
//! The values are **nominal**: the makers' published fields of view or the typical factory
//! calibration of the model, with the principal point at the image centre. A real unit differs
//! by a few per cent in focal length and a few pixels in centre; a lab that needs better
//! gives its own intrinsics (`calibrate intrinsics`, then `replay --intrinsics FILE`).

use crate::core::geometry::Intrinsics;

/// One camera model in one depth mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthCameraModel {
    /// The camera, as people name it.
    pub camera: &'static str,
    /// The depth mode (empty when the camera has one).
    pub mode: &'static str,
    pub width: u32,
    pub height: u32,
    /// Focal length (px), the same along both axes.
    pub focal_px: f64,
    /// Lower-case words that, found in a recording's metadata, name this camera.
    pub names: &'static [&'static str],
}

impl DepthCameraModel {
    /// The nominal intrinsics: the focal length, the centre of the image, no distortion.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics {
            width: self.width,
            height: self.height,
            fx: self.focal_px,
            fy: self.focal_px,
            cx: (f64::from(self.width) - 1.0) / 2.0,
            cy: (f64::from(self.height) - 1.0) / 2.0,
            distortion: [0.0; 5],
        }
    }

    /// "Azure Kinect (NFOV unbinned)", "Kinect v2".
    pub fn label(&self) -> String {
        if self.mode.is_empty() {
            self.camera.to_owned()
        } else {
            format!("{} ({})", self.camera, self.mode)
        }
    }
}

const KINECT_V2: &[&str] = &[
    "kinect v2",
    "kinect2",
    "kinect for windows v2",
    "kinect one",
    "kinectv2",
];
const AZURE: &[&str] = &["azure", "k4a"];
const FEMTO: &[&str] = &["femto"];
const PRIMESENSE: &[&str] = &["primesense", "carmine", "xtion", "openni"];
const ASTRA: &[&str] = &["astra"];

/// The table, in the order a frame size is looked up: the first model of a size is the one a
/// recording that does not name its camera gets.
///
/// - Kinect v2: 512x424, 70.6 x 60 degrees; the focal length of typical factory calibrations
///   (365 px).
/// - Azure Kinect: one 1024x1024 sensor read in four modes with one focal length (about
///   504 px unbinned, 252 px binned 2x2): NFOV unbinned 640x576, NFOV binned 320x288, WFOV
///   unbinned 1024x1024, WFOV binned 512x512.
/// - Orbbec Femto Bolt and Femto Mega: the Azure Kinect's sensor and modes.
/// - Primesense Carmine, Asus Xtion: 640x480 (QVGA 320x240), 58 x 45 degrees (570 px).
/// - Orbbec Astra: 640x480 (QVGA 320x240), 60 x 49.5 degrees (554 px).
pub const DEPTH_CAMERAS: &[DepthCameraModel] = &[
    model("Kinect v2", "", 512, 424, 365.0, KINECT_V2),
    model("Azure Kinect", "NFOV unbinned", 640, 576, 504.5, AZURE),
    model("Azure Kinect", "NFOV binned", 320, 288, 252.25, AZURE),
    model("Azure Kinect", "WFOV unbinned", 1024, 1024, 504.5, AZURE),
    model("Azure Kinect", "WFOV binned", 512, 512, 252.25, AZURE),
    model("Primesense Carmine / Asus Xtion", "VGA", 640, 480, 570.3, PRIMESENSE),
    model("Primesense Carmine / Asus Xtion", "QVGA", 320, 240, 285.15, PRIMESENSE),
    model("Orbbec Femto Bolt / Mega", "NFOV unbinned", 640, 576, 504.5, FEMTO),
    model("Orbbec Femto Bolt / Mega", "NFOV binned", 320, 288, 252.25, FEMTO),
    model("Orbbec Femto Bolt / Mega", "WFOV unbinned", 1024, 1024, 504.5, FEMTO),
    model("Orbbec Femto Bolt / Mega", "WFOV binned", 512, 512, 252.25, FEMTO),
    model("Orbbec Astra", "VGA", 640, 480, 554.3, ASTRA),
    model("Orbbec Astra", "QVGA", 320, 240, 277.15, ASTRA),
];

const fn model(
    camera: &'static str,
    mode: &'static str,
    width: u32,
    height: u32,
    focal_px: f64,
    names: &'static [&'static str],
) -> DepthCameraModel {
    DepthCameraModel {
        camera,
        mode,
        width,
        height,
        focal_px,
        names,
    }
}

/// Why no model fits a recording.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CameraModelError {
    #[error(
        "no known depth camera has {width}x{height} frames (known: {known}): give the camera's intrinsics with --intrinsics FILE (as `calibrate intrinsics` writes) or a rig calibration with --calibration FILE"
    )]
    UnknownSize { width: u32, height: u32, known: String },
    #[error(
        "the recording names its camera {named:?} (a {camera}), which has no {width}x{height} depth mode: give the camera's intrinsics with --intrinsics FILE (as `calibrate intrinsics` writes) or a rig calibration with --calibration FILE"
    )]
    NoSuchMode {
        named: String,
        camera: &'static str,
        width: u32,
        height: u32,
    },
}

/// The model of a `width` x `height` depth recording: of the camera `named` (free text from the
/// recording's metadata) when it names one the table knows, else the first of that size.
///
/// # Errors
/// A size no model has, or a named camera without a mode of that size.
pub fn depth_camera(
    named: Option<&str>,
    width: u32,
    height: u32,
) -> Result<&'static DepthCameraModel, CameraModelError> {
    let of_size = |m: &&DepthCameraModel| (m.width, m.height) == (width, height);
    if let Some(named) = named {
        let lower = named.to_lowercase();
        let family: Vec<&DepthCameraModel> = DEPTH_CAMERAS
            .iter()
            .filter(|m| m.names.iter().any(|n| lower.contains(n)))
            .collect();
        if let Some(first) = family.first() {
            return family
                .iter()
                .copied()
                .find(|m| of_size(m))
                .ok_or_else(|| CameraModelError::NoSuchMode {
                    named: named.to_owned(),
                    camera: first.camera,
                    width,
                    height,
                });
        }
    }
    DEPTH_CAMERAS
        .iter()
        .find(of_size)
        .ok_or_else(|| CameraModelError::UnknownSize {
            width,
            height,
            known: known_sizes(),
        })
}

/// The frame sizes of the table, e.g. "512x424, 640x576, ...".
pub fn known_sizes() -> String {
    let mut sizes: Vec<(u32, u32)> = DEPTH_CAMERAS.iter().map(|m| (m.width, m.height)).collect();
    sizes.sort_unstable();
    sizes.dedup();
    sizes
        .iter()
        .map(|(w, h)| format!("{w}x{h}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_pick_their_camera_and_names_pick_among_cameras_of_a_size() {
        assert_eq!(depth_camera(None, 512, 424).unwrap().camera, "Kinect v2");
        let nfov = depth_camera(None, 640, 576).unwrap();
        assert_eq!(nfov.label(), "Azure Kinect (NFOV unbinned)");
        assert!((nfov.intrinsics().fx - 504.5).abs() < 1e-9);
        assert_eq!(depth_camera(None, 640, 480).unwrap().focal_px, 570.3);
        assert_eq!(
            depth_camera(Some("Orbbec Astra Pro"), 640, 480).unwrap().focal_px,
            554.3
        );
        assert_eq!(
            depth_camera(Some("Femto Bolt"), 512, 512).unwrap().camera,
            "Orbbec Femto Bolt / Mega"
        );
        // A name the table does not know falls back on the size.
        assert_eq!(depth_camera(Some("my camera"), 320, 288).unwrap().mode, "NFOV binned");
        let err = depth_camera(Some("Kinect v2"), 640, 576).unwrap_err();
        assert!(matches!(err, CameraModelError::NoSuchMode { .. }), "{err}");
        let err = depth_camera(None, 800, 600).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("800x600") && text.contains("--intrinsics FILE"), "{text}");
        assert!(text.contains("512x424"), "{text}");
    }

    #[test]
    fn every_model_is_sane() {
        for m in DEPTH_CAMERAS {
            let i = m.intrinsics();
            // Horizontal fields of view of depth cameras lie between 50 and 130 degrees.
            let hfov = 2.0 * (f64::from(m.width) / 2.0 / i.fx).atan().to_degrees();
            assert!((50.0..130.0).contains(&hfov), "{}: {hfov}", m.label());
            assert!(!m.names.is_empty());
        }
    }
}
