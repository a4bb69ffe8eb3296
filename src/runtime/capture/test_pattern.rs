//! A colour backend for the tests only, and the example of what a camera backend is: this
//! module (its [`FrameSource`], its table, its `REGISTERED` entry) and one line in
//! `capture::COLOR_BACKENDS`. It delivers `frames` flat grey frames, numbered from 0,
//! one every `interval_ms`, stamped with the clock it was started with.

use super::backend::{self, Backend, CameraConfig, ColorBackend, TableError};
use super::{CaptureError, Clock, FrameSource};
use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::io::session::codec::FrameFormat;
use crate::io::session::meta::{BackendName, CameraMeta, CameraRole};
use std::sync::Arc;
use std::time::Duration;

const BACKEND: &str = "test_pattern";

/// The backend, registered in `capture::backend` (for the tests only).
pub const REGISTERED: ColorBackend = Backend {
    name: BACKEND,
    table: read_table,
    list: None,
};

/// `[color] backend = "test_pattern"`.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestPatternConfig {
    pub width: u32,
    pub height: u32,
    pub frames: u64,
    #[serde(default)]
    pub interval_ms: u64,
}

fn read_table(table: toml::Table) -> Result<Arc<dyn CameraConfig<Frame = ColorFrame>>, TableError> {
    let c: TestPatternConfig = backend::deserialize(BACKEND, table)?;
    if c.width == 0 || c.height == 0 {
        return Err(TableError::new("width", "width and height must be above 0"));
    }
    Ok(Arc::new(c))
}

impl CameraConfig for TestPatternConfig {
    type Frame = ColorFrame;

    fn backend(&self) -> &'static str {
        BACKEND
    }

    fn open(&self) -> Result<Box<dyn FrameSource<Frame = ColorFrame>>, CaptureError> {
        Ok(Box::new(TestPattern {
            config: self.clone(),
            clock: None,
            next: 0,
        }))
    }

    fn frame_size(&self) -> Option<(u32, u32)> {
        Some((self.width, self.height))
    }
}

#[derive(Debug)]
struct TestPattern {
    config: TestPatternConfig,
    clock: Option<Clock>,
    next: u64,
}

impl FrameSource for TestPattern {
    type Frame = ColorFrame;

    fn meta(&self) -> CameraMeta {
        CameraMeta {
            role: CameraRole::Color,
            backend: BackendName::new(BACKEND),
            model: "test pattern".to_owned(),
            serial: String::new(),
            firmware: String::new(),
            width: self.config.width,
            height: self.config.height,
            pixel_format: FrameFormat::Color(PixelFormat::Mono8),
            fps: 30.0,
        }
    }

    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        self.clock = Some(clock.clone());
        Ok(())
    }

    fn next_frame(&mut self, _timeout: Duration) -> Result<Option<ColorFrame>, CaptureError> {
        let Some(clock) = &self.clock else {
            return Ok(None);
        };
        if self.finished() {
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(self.config.interval_ms));
        let seq = self.next;
        self.next += 1;
        let (width, height) = (self.config.width, self.config.height);
        Ok(Some(ColorFrame {
            stamp: Stamp {
                seq,
                device_ns: seq * 33_333_333,
                host_ns: clock.now_ns(),
            },
            width,
            height,
            format: PixelFormat::Mono8,
            data: vec![128; ColorFrame::expected_len(width, height, PixelFormat::Mono8)],
        }))
    }

    fn finished(&self) -> bool {
        self.next == self.config.frames
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        Ok(())
    }
}
