//! The depth camera's intrinsics from OpenNI2: the depth stream's fields of view and its
//! current mode give a pinhole camera with the principal point at the image centre and no
//! distortion (`fx = w / (2 tan(hfov / 2))`). Good enough for structured-light cameras whose
//! depth image OpenNI2 already rectifies; a chessboard on the IR image is better.

use super::storage::YamlWriter;
use super::{CalibrationError, INTRINSICS_FORMAT_NAME, INTRINSICS_FORMAT_VERSION};
use crate::core::geometry::Intrinsics;
use openni2 as ni;
use std::path::Path;

/// Errors reading intrinsics from OpenNI2.
#[derive(Debug, thiserror::Error)]
pub enum OpenNiIntrinsicsError {
    #[error("cannot open OpenNI2 device {uri:?}")]
    Open {
        uri: String,
        #[source]
        source: ni::Error,
    },
    #[error("OpenNI2 device {uri:?} does not report its depth stream's field of view")]
    NoFieldOfView {
        uri: String,
        #[source]
        source: ni::Error,
    },
    #[error("OpenNI2 device {uri:?} reports an impossible field of view ({hfov_rad} x {vfov_rad} rad)")]
    BadFieldOfView { uri: String, hfov_rad: f32, vfov_rad: f32 },
}

/// The depth camera's intrinsics as OpenNI2 reports them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OpenNiIntrinsics {
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

/// Opens the device at `uri` and reads its depth stream's mode and fields of view.
///
/// # Errors
/// The device cannot be opened, has no depth stream, or does not report a plausible field of view.
pub fn depth_intrinsics(uri: &str) -> Result<OpenNiIntrinsics, OpenNiIntrinsicsError> {
    let open = |source| OpenNiIntrinsicsError::Open {
        uri: uri.to_owned(),
        source,
    };
    ni::OpenNI::init().map_err(open)?;
    let device = ni::Device::open(uri).map_err(open)?;
    let stream = device.create_depth_stream().map_err(open)?;
    let mode = stream.video_mode().map_err(open)?;
    let (h, v) = stream
        .field_of_view()
        .map_err(|source| OpenNiIntrinsicsError::NoFieldOfView {
            uri: uri.to_owned(),
            source,
        })?;
    let plausible = |a: f32| a.is_finite() && a > 0.01 && a < 3.0;
    if !plausible(h) || !plausible(v) {
        return Err(OpenNiIntrinsicsError::BadFieldOfView {
            uri: uri.to_owned(),
            hfov_rad: h,
            vfov_rad: v,
        });
    }
    Ok(OpenNiIntrinsics {
        intrinsics: from_field_of_view(mode.width, mode.height, f64::from(h), f64::from(v)),
        hfov_deg: f64::from(h).to_degrees(),
        vfov_deg: f64::from(v).to_degrees(),
    })
}

/// Writes the intrinsics file (`rms` 0: not measured).
///
/// # Errors
/// OpenCV cannot compose the YAML or the file cannot be written.
pub fn save(found: &OpenNiIntrinsics, path: &Path) -> Result<(), CalibrationError> {
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
