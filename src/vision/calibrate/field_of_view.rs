//! The depth camera's intrinsics from its fields of view: the depth stream's fields of view
//! and its current mode, as OpenNI2 reports them, give a pinhole camera with the principal
//! point at the image centre and no distortion (`fx = w / (2 tan(hfov / 2))`). Good enough for
//! structured-light cameras whose depth image OpenNI2 already rectifies; a chessboard on the IR
//! image is better. The device is read in the runtime layer
//! (`runtime::capture::openni::depth_intrinsics`); here are the maths and the file.

use super::storage::YamlWriter;
use super::{CalibrationError, INTRINSICS_FORMAT_NAME, INTRINSICS_FORMAT_VERSION};
use crate::core::geometry::Intrinsics;
use std::path::Path;

/// The depth camera's intrinsics from its fields of view, with those fields of view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldOfViewIntrinsics {
    pub intrinsics: Intrinsics,
    pub hfov_deg: f64,
    pub vfov_deg: f64,
}

/// Pinhole intrinsics from an image size and fields of view (radians).
pub fn from_field_of_view(width: u32, height: u32, hfov_rad: f64, vfov_rad: f64) -> Intrinsics {
    Intrinsics {
        width,
        height,
        fx: f64::from(width) / (2.0 * (hfov_rad / 2.0).tan()),
        fy: f64::from(height) / (2.0 * (vfov_rad / 2.0).tan()),
        cx: (f64::from(width) - 1.0) / 2.0,
        cy: (f64::from(height) - 1.0) / 2.0,
        distortion: [0.0; 5],
    }
}

/// Writes the intrinsics file (`rms` 0: not measured).
///
/// # Errors
/// OpenCV cannot compose the YAML or the file cannot be written.
pub fn save(found: &FieldOfViewIntrinsics, path: &Path) -> Result<(), CalibrationError> {
    let mut w = YamlWriter::new(path)?;
    w.text("format", INTRINSICS_FORMAT_NAME)?;
    w.int("format_version", INTRINSICS_FORMAT_VERSION)?;
    super::write_intrinsics(&mut w, &found.intrinsics)?;
    w.real("rms", 0.0)?;
    w.text("source", "openni2")?;
    w.real("hfov_deg", found.hfov_deg)?;
    w.real("vfov_deg", found.vfov_deg)?;
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_of_view_gives_the_focal_length() {
        // A Primesense: 58 x 45 degrees at 640x480 is about fx 570.
        let i = from_field_of_view(640, 480, 58f64.to_radians(), 45f64.to_radians());
        assert!((i.fx - 577.3).abs() < 1.0, "{}", i.fx);
        assert!((i.cx - 319.5).abs() < 1e-9);
    }
}
