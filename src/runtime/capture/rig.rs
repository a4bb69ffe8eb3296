//! The cameras a rig config names, opened through their drivers: the depth camera (OpenNI2)
//! and the colour camera (Aravis or V4L2), as [`FrameSource`]s.

use crate::core::frame::{ColorFrame, DepthFrame};
use crate::io::session::CameraMeta;
use crate::runtime::capture::aravis::{AravisColor, AravisConfig, Trigger};
use crate::runtime::capture::openni::{OpenNiConfig, OpenNiDepth};
use crate::runtime::capture::session::LoopedDepth;
use crate::runtime::capture::v4l2::{V4l2Color, V4l2Config};
use crate::runtime::capture::{CaptureError, Clock, FrameSource};
use crate::runtime::config::{ColorCamera, DepthCamera, TriggerMode};
use std::time::Duration;

/// The colour camera of a rig, whichever its driver.
#[derive(Debug)]
pub enum ColorSource {
    Aravis(AravisColor),
    V4l2(V4l2Color),
}

impl FrameSource for ColorSource {
    type Frame = ColorFrame;

    fn meta(&self) -> CameraMeta {
        match self {
            ColorSource::Aravis(s) => s.meta(),
            ColorSource::V4l2(s) => s.meta(),
        }
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        match self {
            ColorSource::Aravis(s) => s.start(clock),
            ColorSource::V4l2(s) => s.start(clock),
        }
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<ColorFrame>, CaptureError> {
        match self {
            ColorSource::Aravis(s) => s.next_frame(timeout),
            ColorSource::V4l2(s) => s.next_frame(timeout),
        }
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        match self {
            ColorSource::Aravis(s) => s.losses(),
            ColorSource::V4l2(s) => s.losses(),
        }
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        match self {
            ColorSource::Aravis(s) => s.stop(),
            ColorSource::V4l2(s) => s.stop(),
        }
    }
}

/// The depth camera a config names, ready to start (an OpenNI2 camera is opened by `start`).
///
/// # Errors
/// A recorded session named as the depth camera cannot be read.
pub fn open_depth(camera: &DepthCamera) -> Result<Box<dyn FrameSource<Frame = DepthFrame>>, CaptureError> {
    Ok(match camera {
        DepthCamera::Openni2 {
            uri,
            serial,
            width,
            height,
            fps,
        } => Box::new(OpenNiDepth::new(OpenNiConfig {
            uri: uri.clone(),
            serial: serial.clone(),
            width: *width,
            height: *height,
            fps: fps.round() as u32,
        })),
        DepthCamera::Session { path, .. } => Box::new(LoopedDepth::open(path)?),
    })
}

/// Opens the colour camera a config names (settings are checked against the camera here).
///
/// # Errors
/// The camera cannot be found, opened or configured.
pub fn open_color(camera: &ColorCamera) -> Result<ColorSource, CaptureError> {
    match camera {
        ColorCamera::Aravis {
            address,
            serial,
            pixel_format,
            region,
            exposure_us,
            gain_db,
            fps,
            trigger,
            buffers,
        } => AravisColor::open(&AravisConfig {
            address: address.clone(),
            serial: serial.clone(),
            pixel_format: *pixel_format,
            region: *region,
            exposure_us: *exposure_us,
            gain_db: *gain_db,
            fps: *fps,
            trigger: match trigger {
                TriggerMode::FreeRun => Trigger::FreeRun,
                TriggerMode::Line(l) => Trigger::Line(l.clone()),
            },
            buffers: *buffers,
        })
        .map(ColorSource::Aravis),
        ColorCamera::V4l2 {
            device,
            width,
            height,
            fps,
        } => V4l2Color::open(V4l2Config {
            device: device.clone(),
            width: *width,
            height: *height,
            fps: *fps,
            format: None,
        })
        .map(ColorSource::V4l2),
    }
}
