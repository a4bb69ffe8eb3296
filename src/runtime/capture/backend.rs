//! The camera backends, registered: each backend names itself, reads its own table of the rig
//! config (`[depth]` or `[color]`, picked by its `backend` key) and opens its camera.
//!
//! A new camera backend is one module under `capture/` holding its [`FrameSource`], its
//! table (a serde struct with `deny_unknown_fields`, checked into a [`CameraConfig`]) and a
//! [`Backend`] constant (`REGISTERED`), plus one line in `capture::DEPTH_BACKENDS` or
//! `capture::COLOR_BACKENDS` (docs/ARCHITECTURE.md, "Adding a camera backend").

use crate::core::frame::{ColorFrame, DepthFrame};
use crate::core::geometry::Rig;
use crate::runtime::capture::beat::DepthBeat;
use crate::runtime::capture::{CaptureError, DeviceInfo, FrameSource};
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::fmt;
use std::sync::Arc;

/// A camera as its table configures it, checked: what opens it.
pub trait CameraConfig: fmt::Debug + Send + Sync {
    type Frame;

    /// The backend's name, as the table's `backend` key gives it.
    fn backend(&self) -> &'static str;

    /// The camera's source, ready to start (a driver may open the camera here or in `start`).
    ///
    /// # Errors
    /// The camera cannot be found, opened or configured.
    fn open(&self) -> Result<Box<dyn FrameSource<Frame = Self::Frame>>, CaptureError>;

    /// The camera's source as [`CameraConfig::open`] gives it, told when the depth camera's
    /// frames arrive: a colour camera its table triggers in step with the depth camera keeps
    /// `beat` (`[color] trigger = "depth"`); every other camera ignores it.
    ///
    /// # Errors
    /// As [`CameraConfig::open`].
    fn open_in_step(&self, beat: &Arc<DepthBeat>) -> Result<Box<dyn FrameSource<Frame = Self::Frame>>, CaptureError> {
        let _ = beat;
        self.open()
    }

    /// The size of its frames when the configuration fixes it, known before the camera opens
    /// (a calibration is checked against it).
    fn frame_size(&self) -> Option<(u32, u32)> {
        None
    }

    /// What `mousepose devices` lists for this backend when this camera is configured;
    /// `None`: the backend's own listing ([`Backend::list`]).
    fn devices(&self) -> Option<BackendDevices> {
        None
    }
}

/// A depth camera: its mode is known from its table, before it opens.
pub trait DepthConfig: CameraConfig<Frame = DepthFrame> {
    /// Width, height, frames per second.
    fn mode(&self) -> (u32, u32, f64);

    /// The rig a recording played as the camera was made with, if it says.
    fn rig(&self) -> Option<Rig> {
        None
    }
}

/// The depth camera of a rig config, checked.
pub type DepthCamera = Arc<dyn DepthConfig>;
/// The colour camera of a rig config, checked.
pub type ColorCamera = Arc<dyn CameraConfig<Frame = ColorFrame>>;

/// What is wrong in a camera's table: the key (within the table; empty for the table as a
/// whole) and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TableError {
    pub key: String,
    pub reason: String,
}

impl TableError {
    pub fn new(key: &str, reason: impl Into<String>) -> Self {
        Self {
            key: key.to_owned(),
            reason: reason.into(),
        }
    }
}

/// One registered backend: its name, how its table is read, what it lists.
pub struct Backend<C: ?Sized> {
    /// The value of the table's `backend` key.
    pub name: &'static str,
    /// Reads and checks the table (every key but `backend`).
    pub table: fn(toml::Table) -> Result<Arc<C>, TableError>,
    /// The cameras `mousepose devices` shows for it; `None` for a backend with nothing to list
    /// (a recording).
    pub list: Option<fn() -> BackendDevices>,
}

impl<C: ?Sized> fmt::Debug for Backend<C> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Backend")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

pub type DepthBackend = Backend<dyn DepthConfig>;
pub type ColorBackend = Backend<dyn CameraConfig<Frame = ColorFrame>>;

/// The backend of `backends` that `table`'s `backend` key names, and its checked camera.
///
/// # Errors
/// No `backend` key, a name no backend has, or what the backend finds wrong in the table.
pub fn read_table<C: ?Sized>(backends: &[Backend<C>], mut table: toml::Table) -> Result<Arc<C>, TableError> {
    let names = || {
        let names: Vec<String> = backends.iter().map(|b| format!("{:?}", b.name)).collect();
        names.join(" or ")
    };
    let name = match table.remove("backend") {
        Some(toml::Value::String(name)) => name,
        Some(other) => return Err(TableError::new("backend", format!("must be {}, not {other}", names()))),
        None => return Err(TableError::new("backend", format!("is needed: {}", names()))),
    };
    let backend = backends
        .iter()
        .find(|b| b.name == name)
        .ok_or_else(|| TableError::new("backend", format!("must be {}, not {name:?}", names())))?;
    (backend.table)(table)
}

/// A backend's table read into its serde form: an unknown key is named (a setting of another
/// backend is one), a value of the wrong type described.
///
/// # Errors
/// The parser's complaint, with the key it is about when it names one.
pub fn deserialize<T: DeserializeOwned>(backend: &str, table: toml::Table) -> Result<T, TableError> {
    T::deserialize(toml::Value::Table(table)).map_err(|e| {
        let message = e.message().trim().to_owned();
        let unknown = message
            .strip_prefix("unknown field `")
            .and_then(|rest| rest.split_once('`'))
            .map(|(key, _)| key.to_owned());
        match unknown {
            Some(key) => TableError::new(&key, format!("is not a setting of the {backend} backend ({message})")),
            None => TableError::new("", message),
        }
    })
}

/// The largest sensor side a colour region or mode may reach, pixels.
pub const MAX_SENSOR_PX: u64 = 16_384;

/// A value above 0 and at most `max`.
///
/// # Errors
/// Not in that range, or not a number.
pub fn positive(key: &str, v: f64, max: f64) -> Result<f64, TableError> {
    if v.is_finite() && v > 0.0 && v <= max {
        Ok(v)
    } else {
        Err(TableError::new(
            key,
            format!("must be above 0 and at most {max}, not {v}"),
        ))
    }
}

/// A frame rate a camera may be asked for: 1 to 1000 frames per second.
///
/// # Errors
/// Out of that range, or not a number.
pub fn frame_rate(key: &str, v: f64) -> Result<f64, TableError> {
    if v.is_finite() && (1.0..=1000.0).contains(&v) {
        Ok(v)
    } else {
        Err(TableError::new(
            key,
            format!("must be from 1 to 1000 frames per second, not {v}"),
        ))
    }
}

/// What one backend reported to `mousepose devices`.
#[derive(Debug, Serialize)]
pub struct BackendDevices {
    pub backend: &'static str,
    pub devices: Vec<DeviceInfo>,
    /// Why the backend could not list its devices, if it could not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// What the listing covers (e.g. which addresses were probed).
    pub scope: String,
}
