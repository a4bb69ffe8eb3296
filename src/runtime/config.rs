//! The rig configuration (`rig.toml`): read in two steps, raw then checked. Only this module
//! sees the raw form; the rest of mousepose gets a [`Config`] whose values are known to make
//! sense. An unknown key or an impossible value is refused with the file, the key and why.
//!
//! `docs/rig.example.toml` is a commented example of every key.

use crate::core::frame::PixelFormat;
use crate::io::read_bounded;
use crate::runtime::pipeline::{EdgeConfig, WhenFull};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// What is wrong with a configuration file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {path:?}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not TOML, an unknown key or a value of the wrong type (the parser's message names it).
    #[error("{path:?} is not a valid rig config: {message}")]
    Parse { path: PathBuf, message: String },
    /// A value of the right type that cannot work.
    #[error("{path:?}: {key} {reason}")]
    Value { path: PathBuf, key: String, reason: String },
}

/// A rig config is a few kilobytes; more is not a config.
const MAX_CONFIG_BYTES: u64 = 1 << 20;

// ---- the raw form, as written -------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    depth: RawDepth,
    color: Option<RawColor>,
    /// Read by earlier versions and never used: an empty table is taken (with a warning), a
    /// list of interfaces refused.
    aravis: Option<RawAravis>,
    #[serde(default)]
    sync: RawSync,
    #[serde(default)]
    pipeline: RawPipeline,
    #[serde(default)]
    models: RawModels,
    #[serde(default)]
    calibration: RawCalibration,
    #[serde(default)]
    segment: RawSegment,
    #[serde(default)]
    output: RawOutput,
    #[serde(default)]
    reconnect: RawReconnect,
    #[serde(default)]
    http: RawHttp,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDepth {
    backend: String,
    uri: Option<String>,
    serial: Option<String>,
    /// The session directory of the `session` backend.
    path: Option<PathBuf>,
    #[serde(default = "default_depth_width")]
    width: u32,
    #[serde(default = "default_depth_height")]
    height: u32,
    #[serde(default = "default_fps")]
    fps: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawColor {
    backend: String,
    address: Option<String>,
    serial: Option<String>,
    device: Option<PathBuf>,
    pixel_format: Option<String>,
    width: Option<u32>,
    height: Option<u32>,
    region: Option<[u32; 4]>,
    exposure_us: Option<f64>,
    gain_db: Option<f64>,
    fps: Option<f64>,
    trigger: Option<String>,
    buffers: Option<usize>,
}

impl RawColor {
    /// The keys given that belong to the other backend than `backend`.
    fn foreign_keys(&self, backend: &str) -> Vec<&'static str> {
        let aravis_only = [
            ("address", self.address.is_some()),
            ("serial", self.serial.is_some()),
            ("pixel_format", self.pixel_format.is_some()),
            ("region", self.region.is_some()),
            ("exposure_us", self.exposure_us.is_some()),
            ("gain_db", self.gain_db.is_some()),
            ("trigger", self.trigger.is_some()),
            ("buffers", self.buffers.is_some()),
        ];
        let v4l2_only = [
            ("device", self.device.is_some()),
            ("width", self.width.is_some()),
            ("height", self.height.is_some()),
        ];
        let foreign: &[(&'static str, bool)] = match backend {
            "aravis" => &v4l2_only,
            "v4l2" => &aravis_only,
            _ => &[],
        };
        foreign
            .iter()
            .filter(|(_, given)| *given)
            .map(|(key, _)| *key)
            .collect()
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAravis {
    #[serde(default)]
    interfaces: Vec<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSync {
    tolerance_ms: Option<f64>,
    color_latency_ms: Option<f64>,
    max_wait_ms: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPipeline {
    capture_capacity: Option<usize>,
    capture_when_full: Option<WhenFull>,
    stage_capacity: Option<usize>,
    body_workers: Option<usize>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModels {
    dir: Option<PathBuf>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCalibration {
    file: Option<PathBuf>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSegment {
    background: Option<PathBuf>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    dir: Option<PathBuf>,
    record: Option<RawRecord>,
    chunk_minutes: Option<f64>,
    min_free_gb: Option<f64>,
    min_free_percent: Option<f64>,
}

/// `record = true` / `false`, or `"always"` / `"never"`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RawRecord {
    Flag(bool),
    Mode(String),
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHttp {
    address: Option<String>,
    allow_remote: Option<bool>,
    token_file: Option<PathBuf>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReconnect {
    stall_ms: Option<f64>,
    max_wait_ms: Option<f64>,
}

fn default_depth_width() -> u32 {
    640
}
fn default_depth_height() -> u32 {
    480
}
fn default_fps() -> f64 {
    30.0
}
fn default_pixel_format() -> String {
    "bayer_rg8".to_owned()
}
/// The largest sensor side a colour region may reach, pixels.
const MAX_SENSOR_PX: u64 = 16_384;
/// The longest exposure, µs.
const MAX_EXPOSURE_US: f64 = 10_000_000.0;
/// The highest analogue gain a GenICam camera offers, dB (Basler's and FLIR's reach 24-48).
const MAX_GAIN_DB: f64 = 48.0;

fn default_trigger() -> String {
    "free_run".to_owned()
}
fn default_buffers() -> usize {
    16
}

// ---- the checked form -----------------------------------------------------------------------

/// When a camera counts as gone, and how often to try it again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reconnect {
    /// No frame for this long: the camera is closed and opened again.
    pub stall: std::time::Duration,
    /// The first wait before opening again; doubled after each failure...
    pub first_wait: std::time::Duration,
    /// ...up to this.
    pub max_wait: std::time::Duration,
}

impl Default for Reconnect {
    fn default() -> Self {
        Self {
            stall: std::time::Duration::from_secs(2),
            first_wait: std::time::Duration::from_millis(250),
            max_wait: std::time::Duration::from_secs(10),
        }
    }
}

/// The depth camera.
#[derive(Clone, Debug, PartialEq)]
pub enum DepthCamera {
    /// An OpenNI2 device by URI (a `.oni` file is a URI too) or serial, in a depth mode.
    Openni2 {
        uri: Option<String>,
        serial: Option<String>,
        width: u32,
        height: u32,
        fps: f64,
    },
    /// The depth frames of a recorded session, played at their recorded pace and looped: a rig
    /// without a depth camera, for trying the daemon and for benchmarks. The mode is the
    /// session's.
    Session {
        path: PathBuf,
        width: u32,
        height: u32,
        fps: f64,
        /// The rig the session was recorded or rendered with, if it says.
        rig: Option<Box<crate::core::geometry::Rig>>,
    },
}

impl DepthCamera {
    /// The depth mode: width, height, frames per second.
    pub fn mode(&self) -> (u32, u32, f64) {
        match self {
            DepthCamera::Openni2 { width, height, fps, .. } | DepthCamera::Session { width, height, fps, .. } => {
                (*width, *height, *fps)
            }
        }
    }
}

/// How the colour camera is triggered.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TriggerMode {
    FreeRun,
    /// A hardware trigger on the named input line (e.g. `Line1`).
    Line(String),
}

/// The colour camera.
#[derive(Clone, Debug, PartialEq)]
pub enum ColorCamera {
    /// A GenICam camera through Aravis, opened by address (unicast) or serial.
    Aravis {
        address: Option<String>,
        serial: Option<String>,
        pixel_format: PixelFormat,
        region: Option<(u32, u32, u32, u32)>,
        exposure_us: Option<f64>,
        gain_db: Option<f64>,
        fps: Option<f64>,
        trigger: TriggerMode,
        buffers: usize,
    },
    /// A UVC camera through V4L2.
    V4l2 {
        device: PathBuf,
        width: u32,
        height: u32,
        fps: f64,
    },
}

/// The checked configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The file it was read from.
    pub path: PathBuf,
    pub depth: DepthCamera,
    pub color: Option<ColorCamera>,
    pub sync: crate::runtime::sync::SyncConfig,
    /// Edges out of the capture threads.
    pub capture_edge: EdgeConfig,
    /// Edges between stages.
    pub stage_edge: EdgeConfig,
    /// Body-forest workers (0: one per core).
    pub body_workers: usize,
    pub models_dir: Option<PathBuf>,
    pub calibration: Option<PathBuf>,
    /// A session recorded with the cage empty: `run`'s background reference. Without it the
    /// background is learnt from the live frames.
    pub background: Option<PathBuf>,
    /// Where `run` writes its runs (`DIR/<start>/chunk-NNNN`).
    pub output_dir: PathBuf,
    /// Whether `run` records raw frames.
    pub record: bool,
    /// Length of a chunk of a live run.
    pub chunk: std::time::Duration,
    /// Raw recording pauses below the larger of these free on the output's file system.
    pub min_free_bytes: u64,
    pub min_free_share: f64,
    /// When a camera counts as gone, and the longest wait between tries to reopen it.
    pub reconnect: Reconnect,
    /// The daemon's HTTP server (live page, metrics, status).
    pub http: Http,
}

/// The `[http]` table: where the daemon serves its live page, metrics and status.
#[derive(Clone, Debug, PartialEq)]
pub struct Http {
    /// `None`: no server (`address = "off"`).
    pub address: Option<std::net::SocketAddr>,
    /// The bearer token every request must carry, read from `token_file` (required when the
    /// address is not loopback, which needs `allow_remote = true`).
    pub token: Option<String>,
}

/// The port the daemon serves on by default (loopback only).
pub const DEFAULT_HTTP_PORT: u16 = 8470;

/// A token file is one line; more is not a token.
pub const MAX_TOKEN_BYTES: u64 = 4096;

impl Config {
    /// Reads and checks a config file.
    ///
    /// # Errors
    /// The file cannot be read, does not parse (unknown keys included), or holds a value
    /// that cannot work.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = read_bounded(path, MAX_CONFIG_BYTES).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Checks config text; `path` is named in errors.
    ///
    /// # Errors
    /// As [`Config::load`].
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_owned(),
            message: one_line(e.message()) + &span_note(text, e.span()),
        })?;
        Checker { path }.check(raw)
    }
}

/// A parser's message on one line: some of TOML's span lines (a duplicated table: "invalid
/// table header" then "duplicate key ..."), and an error is one sentence.
fn one_line(message: &str) -> String {
    let lines: Vec<&str> = message.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    lines.join(": ")
}

/// ` (line N)` for a parse error's position.
fn span_note(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    span.map(|s| {
        format!(
            " (line {})",
            text.get(..s.start).unwrap_or("").matches('\n').count() + 1
        )
    })
    .unwrap_or_default()
}

struct Checker<'a> {
    path: &'a Path,
}

impl Checker<'_> {
    fn bad(&self, key: &str, reason: impl Into<String>) -> ConfigError {
        ConfigError::Value {
            path: self.path.to_owned(),
            key: key.to_owned(),
            reason: reason.into(),
        }
    }

    fn positive(&self, key: &str, v: f64, max: f64) -> Result<f64, ConfigError> {
        if v.is_finite() && v > 0.0 && v <= max {
            Ok(v)
        } else {
            Err(self.bad(key, format!("must be above 0 and at most {max}, not {v}")))
        }
    }

    /// A camera frame rate: whole frames per second, at least 1 (a camera mode has one).
    fn frame_rate(&self, key: &str, v: f64) -> Result<f64, ConfigError> {
        if v.is_finite() && (1.0..=1000.0).contains(&v) {
            Ok(v)
        } else {
            Err(self.bad(key, format!("must be from 1 to 1000 frames per second, not {v}")))
        }
    }

    fn capacity(&self, key: &str, v: usize) -> Result<usize, ConfigError> {
        if (1..=4096).contains(&v) {
            Ok(v)
        } else {
            Err(self.bad(key, format!("must be from 1 to 4096, not {v}")))
        }
    }

    fn check(&self, raw: RawConfig) -> Result<Config, ConfigError> {
        let d = raw.depth;
        let depth = match d.backend.as_str() {
            "openni2" => {
                if d.uri.is_none() && d.serial.is_none() {
                    return Err(self.bad("depth", "needs `uri` or `serial` to say which camera"));
                }
                // A recording played as the camera cannot come later, as a camera can.
                if let Some(uri) = &d.uri {
                    let path = Path::new(uri);
                    let recording = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("oni"));
                    if recording && !path.is_file() {
                        return Err(self.bad("depth.uri", format!("names the recording {uri:?}, which is not a file")));
                    }
                }
                if !(1..=4096).contains(&d.width) || !(1..=4096).contains(&d.height) {
                    return Err(self.bad(
                        "depth.width/height",
                        format!("must be from 1 to 4096, not {}x{}", d.width, d.height),
                    ));
                }
                DepthCamera::Openni2 {
                    uri: d.uri,
                    serial: d.serial,
                    width: d.width,
                    height: d.height,
                    fps: self.frame_rate("depth.fps", d.fps)?,
                }
            }
            "session" => {
                let Some(path) = d.path else {
                    return Err(self.bad("depth", "needs `path`: the recorded session to play"));
                };
                let reader = crate::io::session::SessionReader::open(&path).map_err(|e| {
                    self.bad(
                        "depth.path",
                        format!("is not a readable session: {}", crate::core::error_chain(&e)),
                    )
                })?;
                let Some(camera) = reader.meta().camera(crate::io::session::CameraRole::Depth) else {
                    return Err(self.bad("depth.path", format!("{path:?} has no depth camera")));
                };
                DepthCamera::Session {
                    width: camera.width,
                    height: camera.height,
                    fps: camera.fps,
                    rig: reader.meta().rig.map(Box::new),
                    path,
                }
            }
            other => {
                return Err(self.bad(
                    "depth.backend",
                    format!("must be \"openni2\" or \"session\", not {other:?}"),
                ));
            }
        };
        let color = raw.color.map(|c| self.color(c)).transpose()?;
        let (_, _, fps) = depth.mode();
        let ms = |key: &str, v: Option<f64>| -> Result<Option<f64>, ConfigError> {
            v.map(|v| self.positive(key, v, 10_000.0)).transpose()
        };
        let tolerance = ms("sync.tolerance_ms", raw.sync.tolerance_ms)?;
        if let Some(t) = tolerance {
            if t * 1e-3 * fps > 0.5 + 1e-9 {
                return Err(self.bad(
                    "sync.tolerance_ms",
                    format!(
                        "must be at most half a depth frame interval ({:.1} ms), not {t}",
                        500.0 / fps
                    ),
                ));
            }
        }
        let latency = raw.sync.color_latency_ms.unwrap_or(0.0);
        if !latency.is_finite() || latency.abs() > 1000.0 {
            return Err(self.bad("sync.color_latency_ms", format!("must be within ±1000, not {latency}")));
        }
        let r = raw.reconnect;
        let stall_ms = self.positive("reconnect.stall_ms", r.stall_ms.unwrap_or(2000.0), 600_000.0)?;
        let sync = crate::runtime::sync::SyncConfig {
            tolerance_ns: tolerance.map(|t| (t * 1e6) as u64),
            color: color.is_some(),
            max_wait_ns: (ms("sync.max_wait_ms", raw.sync.max_wait_ms)?.unwrap_or(stall_ms) * 1e6) as u64,
            color_latency_ns: (latency * 1e6) as i64,
        };
        let p = raw.pipeline;
        let capture_edge = EdgeConfig {
            when_full: p.capture_when_full.unwrap_or(WhenFull::DropNewest),
            ..EdgeConfig::block(self.capacity("pipeline.capture_capacity", p.capture_capacity.unwrap_or(16))?)
        };
        let stage_edge = EdgeConfig::block(self.capacity("pipeline.stage_capacity", p.stage_capacity.unwrap_or(8))?);
        let body_workers = p.body_workers.unwrap_or(0);
        if body_workers > 64 {
            return Err(self.bad(
                "pipeline.body_workers",
                format!("must be at most 64, not {body_workers}"),
            ));
        }
        let o = raw.output;
        let record = match o.record {
            None | Some(RawRecord::Flag(true)) => true,
            Some(RawRecord::Flag(false)) => false,
            Some(RawRecord::Mode(m)) => match m.as_str() {
                "always" => true,
                "never" => false,
                _ => return Err(self.bad("output.record", format!("must be \"always\" or \"never\", not {m:?}"))),
            },
        };
        let chunk_minutes = self.positive("output.chunk_minutes", o.chunk_minutes.unwrap_or(60.0), 1440.0)?;
        let min_free_gb = o.min_free_gb.unwrap_or(5.0);
        if !(min_free_gb.is_finite() && (0.0..=1e6).contains(&min_free_gb)) {
            return Err(self.bad(
                "output.min_free_gb",
                format!("must be from 0 to 1000000, not {min_free_gb}"),
            ));
        }
        let min_free_percent = o.min_free_percent.unwrap_or(5.0);
        if !(min_free_percent.is_finite() && (0.0..=90.0).contains(&min_free_percent)) {
            return Err(self.bad(
                "output.min_free_percent",
                format!("must be from 0 to 90, not {min_free_percent}"),
            ));
        }
        let max_wait_ms = self.positive("reconnect.max_wait_ms", r.max_wait_ms.unwrap_or(10_000.0), 600_000.0)?;
        let secs = |ms: f64| std::time::Duration::from_secs_f64(ms / 1000.0);
        let reconnect = Reconnect {
            stall: secs(stall_ms),
            first_wait: secs(250.0_f64.min(max_wait_ms)),
            max_wait: secs(max_wait_ms),
        };
        if let Some(aravis) = raw.aravis {
            if !aravis.interfaces.is_empty() {
                return Err(self.bad(
                    "aravis.interfaces",
                    "is not used: mousepose never looks for GigE Vision cameras by broadcast; it opens the [color] address (remove the [aravis] table)",
                ));
            }
            tracing::warn!(config = ?self.path, "the [aravis] table is not used (cameras are opened by their address): remove it");
        }
        let http = self.http(raw.http)?;
        Ok(Config {
            path: self.path.to_owned(),
            depth,
            color,
            sync,
            capture_edge,
            stage_edge,
            body_workers,
            models_dir: raw.models.dir,
            calibration: raw.calibration.file,
            background: raw.segment.background,
            output_dir: o.dir.unwrap_or_else(|| PathBuf::from("/var/lib/mousepose/sessions")),
            record,
            chunk: std::time::Duration::from_secs_f64(chunk_minutes * 60.0),
            min_free_bytes: (min_free_gb * 1e9) as u64,
            min_free_share: min_free_percent / 100.0,
            reconnect,
            http,
        })
    }

    /// `[http]`: a loopback address unless `allow_remote`, and then a token.
    fn http(&self, h: RawHttp) -> Result<Http, ConfigError> {
        let text = h.address.unwrap_or_else(|| format!("127.0.0.1:{DEFAULT_HTTP_PORT}"));
        if text == "off" {
            return Ok(Http {
                address: None,
                token: None,
            });
        }
        let address: std::net::SocketAddr = text.parse().map_err(|_| {
            self.bad(
                "http.address",
                format!("must be IP:PORT (e.g. \"127.0.0.1:{DEFAULT_HTTP_PORT}\") or \"off\", not {text:?}"),
            )
        })?;
        let remote = !address.ip().is_loopback();
        if remote && h.allow_remote != Some(true) {
            return Err(self.bad(
                "http.address",
                format!(
                    "{address} is reachable from other machines: set `allow_remote = true` (and a \
                     `token_file`) to serve the rig's status beyond this machine"
                ),
            ));
        }
        let token = match &h.token_file {
            Some(path) => Some(self.token(path)?),
            None if remote => {
                return Err(self.bad(
                    "http.token_file",
                    "is needed with `allow_remote = true`: a file holding the bearer token clients must send",
                ));
            }
            None => None,
        };
        Ok(Http {
            address: Some(address),
            token,
        })
    }

    /// The bearer token in `path`: one line of at least 16 visible characters.
    fn token(&self, path: &Path) -> Result<String, ConfigError> {
        let bad = |reason: String| self.bad("http.token_file", reason);
        let text = read_bounded(path, MAX_TOKEN_BYTES).map_err(|e| bad(format!("{path:?} cannot be read: {e}")))?;
        let token = text.trim();
        if token.len() < 16 || !token.chars().all(|c| c.is_ascii_graphic()) {
            return Err(bad(format!(
                "{path:?} must hold one token of at least 16 visible ASCII characters"
            )));
        }
        Ok(token.to_owned())
    }

    fn color(&self, c: RawColor) -> Result<ColorCamera, ConfigError> {
        let fps = c.fps.map(|f| self.positive("color.fps", f, 1000.0)).transpose()?;
        if let Some(key) = c.foreign_keys(&c.backend).first() {
            let other = if c.backend == "aravis" { "v4l2" } else { "aravis" };
            return Err(self.bad(
                &format!("color.{key}"),
                format!("is a setting of the {other} backend, not of {:?}", c.backend),
            ));
        }
        match c.backend.as_str() {
            "aravis" => {
                if c.address.is_none() && c.serial.is_none() {
                    return Err(self.bad("color", "needs `address` or `serial` to say which camera"));
                }
                if let Some(a) = &c.address {
                    if a.parse::<std::net::Ipv4Addr>().is_err() {
                        return Err(self.bad("color.address", format!("must be an IPv4 address, not {a:?}")));
                    }
                }
                let pixel_format_name = c.pixel_format.unwrap_or_else(default_pixel_format);
                let pixel_format = PixelFormat::ALL
                    .into_iter()
                    .find(|f| f.name() == pixel_format_name)
                    .ok_or_else(|| {
                        let names: Vec<&str> = PixelFormat::ALL.iter().map(|f| f.name()).collect();
                        self.bad(
                            "color.pixel_format",
                            format!("must be one of {}, not {pixel_format_name:?}", names.join(", ")),
                        )
                    })?;
                if let Some([x, y, w, h]) = c.region {
                    if w == 0 || h == 0 {
                        return Err(self.bad("color.region", "must have a width and height above 0"));
                    }
                    if u64::from(x) + u64::from(w) > MAX_SENSOR_PX || u64::from(y) + u64::from(h) > MAX_SENSOR_PX {
                        return Err(self.bad(
                            "color.region",
                            format!("must lie within {MAX_SENSOR_PX}x{MAX_SENSOR_PX} pixels, not [{x}, {y}, {w}, {h}]"),
                        ));
                    }
                }
                let trigger = c.trigger.unwrap_or_else(default_trigger);
                let trigger = match trigger.as_str() {
                    "free_run" => TriggerMode::FreeRun,
                    t => match t.strip_prefix("line:") {
                        Some(line)
                            if !line.is_empty()
                                && line.len() <= 32
                                && line.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_') =>
                        {
                            TriggerMode::Line(line.to_owned())
                        }
                        _ => {
                            return Err(self.bad(
                                "color.trigger",
                                format!(
                                    "must be \"free_run\" or \"line:<LINE>\" with a GenICam line name of letters, digits and _ (e.g. \"line:Line1\"), not {t:?}"
                                ),
                            ));
                        }
                    },
                };
                if let Some(e) = c.exposure_us {
                    if !(e.is_finite() && e > 0.0 && e <= MAX_EXPOSURE_US) {
                        return Err(self.bad(
                            "color.exposure_us",
                            format!("must be above 0 and at most {MAX_EXPOSURE_US} (10 s), not {e}"),
                        ));
                    }
                }
                if let Some(g) = c.gain_db {
                    if !(g.is_finite() && (0.0..=MAX_GAIN_DB).contains(&g)) {
                        return Err(self.bad("color.gain_db", format!("must be from 0 to {MAX_GAIN_DB} dB, not {g}")));
                    }
                }
                let buffers = c.buffers.unwrap_or_else(default_buffers);
                if !(1..=256).contains(&buffers) {
                    return Err(self.bad("color.buffers", format!("must be from 1 to 256, not {buffers}")));
                }
                Ok(ColorCamera::Aravis {
                    address: c.address,
                    serial: c.serial,
                    pixel_format,
                    region: c.region.map(|[x, y, w, h]| (x, y, w, h)),
                    exposure_us: c.exposure_us,
                    gain_db: c.gain_db,
                    fps,
                    trigger,
                    buffers,
                })
            }
            "v4l2" => {
                let device = c
                    .device
                    .ok_or_else(|| self.bad("color.device", "is needed for a v4l2 camera (e.g. /dev/video0)"))?;
                let (width, height) = (c.width.unwrap_or(640), c.height.unwrap_or(480));
                if !(1..=MAX_SENSOR_PX).contains(&u64::from(width)) || !(1..=MAX_SENSOR_PX).contains(&u64::from(height))
                {
                    return Err(self.bad(
                        "color.width",
                        format!("width and height must be from 1 to {MAX_SENSOR_PX}, not {width}x{height}"),
                    ));
                }
                Ok(ColorCamera::V4l2 {
                    device,
                    width,
                    height,
                    fps: fps.unwrap_or(30.0),
                })
            }
            other => Err(self.bad(
                "color.backend",
                format!("must be \"aravis\" or \"v4l2\", not {other:?}"),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Config, ConfigError> {
        Config::parse(text, Path::new("rig.toml"))
    }

    /// Issue 37 item 5: a missing `.oni` recording named as the depth camera is refused (it
    /// cannot come later, as a camera can).
    #[test]
    fn issue37_a_missing_oni_recording_is_refused() {
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"/nonexistent/issue37.oni\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("depth.uri") && e.contains("issue37.oni"), "{e}");
    }

    /// Issue 37 item 5: a duplicated table is refused in one line, naming the table and where.
    #[test]
    fn issue37_a_duplicated_table_is_refused_in_one_line() {
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n[depth]\nfps = 30\n")
            .unwrap_err()
            .to_string();
        assert!(!e.contains('\n'), "{e}");
        assert!(e.contains("depth") && e.contains("line 4"), "{e}");
    }

    #[test]
    fn the_example_config_is_valid() {
        let text = include_str!("../../docs/rig.example.toml");
        let c = parse(text).unwrap();
        assert!(matches!(c.color, Some(ColorCamera::Aravis { .. })));
        assert_eq!(c.capture_edge.when_full, WhenFull::DropNewest);
        assert_eq!(c.chunk, std::time::Duration::from_secs(3600));
        assert_eq!(c.reconnect.stall, std::time::Duration::from_secs(2));
    }

    #[test]
    fn colour_settings_out_of_range_or_of_the_other_backend_are_refused_by_name() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        let aravis = "[color]\nbackend = \"aravis\"\naddress = \"127.0.0.1\"\n";
        let v4l2 = "[color]\nbackend = \"v4l2\"\ndevice = \"/dev/video0\"\n";
        for (table, text, key) in [
            (aravis, "gain_db = 100.0\n", "color.gain_db"),
            (aravis, "gain_db = -3.0\n", "color.gain_db"),
            (aravis, "gain_db = nan\n", "color.gain_db"),
            (aravis, "exposure_us = 1e9\n", "color.exposure_us"),
            (aravis, "region = [4294967295, 0, 2, 2]\n", "color.region"),
            (aravis, "region = [0, 0, 20000, 10]\n", "color.region"),
            (aravis, "trigger = \"line:Line 1; x\"\n", "color.trigger"),
            (aravis, "device = \"/dev/video0\"\n", "color.device"),
            (aravis, "width = 640\n", "color.width"),
            (v4l2, "address = \"127.0.0.1\"\n", "color.address"),
            (v4l2, "gain_db = 0.0\n", "color.gain_db"),
            (v4l2, "width = 0\n", "color.width"),
            ("[aravis]\ninterfaces = [\"eth0\"]\n", "", "aravis.interfaces"),
        ] {
            let e = parse(&format!("{base}{table}{text}")).unwrap_err().to_string();
            assert!(e.contains(key), "{table}{text}: {e}");
        }
        let c = parse(&format!(
            "{base}{aravis}gain_db = 12.0\ntrigger = \"line:Line1\"\n[aravis]\n"
        ))
        .unwrap();
        assert!(matches!(
            c.color,
            Some(ColorCamera::Aravis {
                gain_db: Some(12.0),
                trigger: TriggerMode::Line(_),
                buffers: 16,
                ..
            })
        ));
    }

    #[test]
    fn output_and_reconnect_settings_are_checked() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        let c = parse(&format!("{base}[output]\nrecord = \"never\"\nchunk_minutes = 0.5\n")).unwrap();
        assert!(!c.record);
        assert_eq!(c.chunk, std::time::Duration::from_secs(30));
        for (text, key) in [
            ("[output]\nrecord = \"sometimes\"\n", "output.record"),
            ("[output]\nchunk_minutes = 0\n", "output.chunk_minutes"),
            ("[output]\nmin_free_percent = 99\n", "output.min_free_percent"),
            ("[reconnect]\nstall_ms = -1\n", "reconnect.stall_ms"),
        ] {
            let e = parse(&format!("{base}{text}")).unwrap_err().to_string();
            assert!(e.contains(key), "{e}");
        }
    }

    #[test]
    fn the_http_server_stays_on_loopback_unless_allowed_and_then_needs_a_token() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        let c = parse(base).unwrap();
        assert_eq!(c.http.address, Some(([127, 0, 0, 1], DEFAULT_HTTP_PORT).into()));
        assert_eq!(c.http.token, None);
        assert_eq!(
            parse(&format!("{base}[http]\naddress = \"off\"\n"))
                .unwrap()
                .http
                .address,
            None
        );
        let dir = tempfile::tempdir().unwrap();
        let token = dir.path().join("token");
        std::fs::write(&token, "  0123456789abcdefXYZ\n").unwrap();
        let short = dir.path().join("short");
        std::fs::write(&short, "secret\n").unwrap();
        let c = parse(&format!(
            "{base}[http]\naddress = \"0.0.0.0:9000\"\nallow_remote = true\ntoken_file = {token:?}\n"
        ))
        .unwrap();
        assert_eq!(c.http.token.as_deref(), Some("0123456789abcdefXYZ"));
        for (http, key, why) in [
            ("address = \"0.0.0.0:9000\"\n", "http.address", "allow_remote"),
            ("address = \"[::]:9000\"\n", "http.address", "allow_remote"),
            ("address = \"localhost\"\n", "http.address", "IP:PORT"),
            (
                "address = \"0.0.0.0:9000\"\nallow_remote = true\n",
                "http.token_file",
                "bearer token",
            ),
            (&format!("token_file = {short:?}\n"), "http.token_file", "at least 16"),
            ("token_file = \"/dev/zero\"\n", "http.token_file", "regular file"),
        ] {
            let e = parse(&format!("{base}[http]\n{http}")).unwrap_err().to_string();
            assert!(e.contains(key) && e.contains(why), "{http}: {e}");
        }
    }

    #[test]
    fn a_minimal_depth_only_config() {
        let c = parse("[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n").unwrap();
        assert!(c.color.is_none() && !c.sync.color);
        assert_eq!(c.stage_edge.when_full, WhenFull::Block);
    }

    #[test]
    fn unknown_keys_and_bad_values_name_the_key_and_file() {
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\nwidht = 640\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("rig.toml") && e.contains("widht") && e.contains("line 4"),
            "{e}"
        );
        let e = parse("[depth]\nbackend = \"kinect\"\nuri = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("depth.backend") && e.contains("kinect"), "{e}");
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"x\"\nfps = -3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("depth.fps"), "{e}");
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"x\"\n[sync]\ntolerance_ms = 40\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sync.tolerance_ms") && e.contains("16.7"), "{e}");
        let e =
            parse("[depth]\nbackend = \"openni2\"\nuri = \"x\"\n[color]\nbackend = \"aravis\"\naddress = \"cam\"\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("color.address"), "{e}");
        let e = parse("[depth]\nbackend = \"openni2\"\n").unwrap_err().to_string();
        assert!(e.contains("uri"), "{e}");
        // Below one frame a second is no camera mode (it used to mean "any mode").
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"x\"\nfps = 0.4\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("depth.fps") && e.contains("0.4"), "{e}");
    }

    #[test]
    fn a_config_path_that_is_not_a_small_regular_file_is_refused_without_reading_it() {
        for path in ["/dev/zero", "/"] {
            let e = Config::load(Path::new(path)).unwrap_err();
            assert!(crate::core::error_chain(&e).contains("not a regular file"), "{e}");
        }
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        assert!(
            std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .unwrap()
                .success()
        );
        let e = Config::load(&fifo).unwrap_err();
        assert!(crate::core::error_chain(&e).contains("not a regular file"), "{e}");
        let big = dir.path().join("big.toml");
        std::fs::write(&big, vec![b'#'; 2 << 20]).unwrap();
        let e = Config::load(&big).unwrap_err();
        assert!(crate::core::error_chain(&e).contains("larger than"), "{e}");
    }
}
