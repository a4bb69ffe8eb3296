//! The rig configuration (`rig.toml`): read in two steps, raw then checked. Only this module
//! sees the raw form; the rest of mousepose gets a [`Config`] whose values are known to make
//! sense. An unknown key or an impossible value is refused with the file, the key and why.
//!
//! `docs/rig.example.toml` is a commented example of every key.

use crate::io::read_bounded;
use crate::runtime::capture::backend::{self, Backend, read_table};
pub use crate::runtime::capture::backend::{ColorCamera, DepthCamera};
pub use crate::runtime::capture::supervise::Reconnect;
use crate::runtime::capture::{COLOR_BACKENDS, DEPTH_BACKENDS};
use crate::runtime::pipeline::{EdgeConfig, WhenFull};
use crate::runtime::stream::lsl::LslConfig;
use crate::runtime::stream::{Endpoint, StreamConfig};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

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
    /// Each camera's table, read by the backend its `backend` key names
    /// (`capture::backend`).
    depth: toml::Spanned<toml::Table>,
    color: Option<toml::Spanned<toml::Table>>,
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
    /// The live pose stream: none without the table.
    stream: Option<RawStream>,
    /// The LSL outlet: none without the table.
    lsl: Option<RawLsl>,
    #[serde(default)]
    mice: RawMice,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMice {
    count: Option<i64>,
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
    partner_wait_ms: Option<RawPartnerWait>,
    partner_reach_ms: Option<f64>,
}

/// `[sync] partner_wait_ms`: milliseconds, or `"nearest"`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RawPartnerWait {
    Ms(f64),
    Word(String),
}

/// The `[sync] partner_wait_ms` a closed-loop rig sets (not the default, which waits for the
/// nearest partner: poses keep their paws at every camera phase): small beside the pipeline's
/// own p99 of 10-18 ms from a depth frame's arrival to its pose published.
pub const CLOSED_LOOP_PARTNER_WAIT_MS: f64 = 3.0;

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
struct RawStream {
    endpoint: Option<String>,
    allow_remote: Option<bool>,
    queue: Option<usize>,
    high_water_mark: Option<usize>,
    lead_ms: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLsl {
    enabled: Option<bool>,
    name: Option<String>,
    #[serde(rename = "type")]
    kind: Option<String>,
    source_id: Option<String>,
    library: Option<PathBuf>,
    queue: Option<usize>,
    lead_ms: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReconnect {
    stall_ms: Option<f64>,
    max_wait_ms: Option<f64>,
}

// ---- the checked form -----------------------------------------------------------------------

/// The checked configuration.
#[derive(Clone, Debug)]
pub struct Config {
    /// The file it was read from.
    pub path: PathBuf,
    pub depth: DepthCamera,
    pub color: Option<ColorCamera>,
    pub sync: crate::runtime::pairing::SyncConfig,
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
    /// The live pose stream (`[stream]`), when the config has one.
    pub stream: Option<StreamConfig>,
    /// The LSL outlet (`[lsl]`), when the config has one and it is enabled.
    pub lsl: Option<LslConfig>,
    /// How many mice share the cage (`[mice] count`, 1 to
    /// [`crate::vision::identity::MOST_MICE`]; 1 without the table).
    pub mice: usize,
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
        Checker { path, text }.check(raw)
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
    /// The file's text, to say on which line a key is.
    text: &'a str,
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
        backend::positive(key, v, max).map_err(|e| self.bad(&e.key, e.reason))
    }

    /// A camera's table (`[depth]`, `[color]`), read by the backend it names.
    fn camera<C: ?Sized>(
        &self,
        name: &str,
        backends: &[Backend<C>],
        table: toml::Spanned<toml::Table>,
    ) -> Result<Arc<C>, ConfigError> {
        let span = table.span();
        read_table(backends, table.into_inner()).map_err(|e| match e.key.as_str() {
            "" => self.bad(name, e.reason),
            key => self.bad(&format!("{name}.{key}"), e.reason + &self.line_of(key, span)),
        })
    }

    /// ` (line N)` for the line where `key` is set in the table spanning `span`, if found.
    fn line_of(&self, key: &str, span: std::ops::Range<usize>) -> String {
        let table = self.text.get(span.clone()).unwrap_or("");
        let mut at = 0;
        for line in table.split_inclusive('\n') {
            let rest = line.trim_start().strip_prefix(key).unwrap_or("");
            if rest.trim_start().starts_with('=') {
                return span_note(self.text, Some(span.start + at..span.start + at));
            }
            at += line.len();
        }
        String::new()
    }

    /// `[sync] partner_reach_ms`: with a partner wait only, at most two depth frame intervals.
    fn partner_reach(&self, reach_ms: Option<f64>, fps: f64, wait: bool) -> Result<Option<u64>, ConfigError> {
        let Some(ms) = reach_ms else {
            return Ok(None);
        };
        let key = "sync.partner_reach_ms";
        let most = 2000.0 / fps;
        if !wait {
            return Err(self.bad(
                key,
                "needs a `partner_wait_ms`: without one each depth frame waits for its nearest partner",
            ));
        }
        if !ms.is_finite() || !(0.0..=most).contains(&ms) {
            return Err(self.bad(
                key,
                format!("must be from 0 to two depth frame intervals ({most:.1} ms), not {ms}"),
            ));
        }
        Ok(Some((ms * 1e6) as u64))
    }

    fn capacity(&self, key: &str, v: usize) -> Result<usize, ConfigError> {
        if (1..=4096).contains(&v) {
            Ok(v)
        } else {
            Err(self.bad(key, format!("must be from 1 to 4096, not {v}")))
        }
    }

    fn check(&self, raw: RawConfig) -> Result<Config, ConfigError> {
        let depth = self.camera("depth", DEPTH_BACKENDS, raw.depth)?;
        let color = raw.color.map(|c| self.camera("color", COLOR_BACKENDS, c)).transpose()?;
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
        let partner_wait_ms = match raw.sync.partner_wait_ms {
            None => None,
            Some(RawPartnerWait::Word(w)) if w == "nearest" => None,
            Some(RawPartnerWait::Ms(v)) if v.is_finite() && (0.0..=10_000.0).contains(&v) => Some(v),
            Some(RawPartnerWait::Ms(v)) => {
                return Err(self.bad("sync.partner_wait_ms", format!("must be from 0 to 10000 ms, not {v}")));
            }
            Some(RawPartnerWait::Word(w)) => {
                return Err(self.bad(
                    "sync.partner_wait_ms",
                    format!("must be a number of ms or \"nearest\", not \"{w}\""),
                ));
            }
        };
        let sync = crate::runtime::pairing::SyncConfig {
            tolerance_ns: tolerance.map(|t| (t * 1e6) as u64),
            color: color.is_some(),
            max_wait_ns: (ms("sync.max_wait_ms", raw.sync.max_wait_ms)?.unwrap_or(stall_ms) * 1e6) as u64,
            color_latency_ns: (latency * 1e6) as i64,
            partner_wait_ns: partner_wait_ms.map(|ms| (ms * 1e6) as u64),
            partner_reach_ns: self.partner_reach(raw.sync.partner_reach_ms, fps, partner_wait_ms.is_some())?,
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
        let record = self.record(o.record)?;
        let chunk_minutes = self.positive("output.chunk_minutes", o.chunk_minutes.unwrap_or(60.0), 1440.0)?;
        let (min_free_gb, min_free_percent) = self.free_space(o.min_free_gb, o.min_free_percent)?;
        let max_wait_ms = self.positive("reconnect.max_wait_ms", r.max_wait_ms.unwrap_or(10_000.0), 600_000.0)?;
        let secs = |ms: f64| std::time::Duration::from_secs_f64(ms / 1000.0);
        let reconnect = Reconnect {
            stall: secs(stall_ms),
            first_wait: secs(250.0_f64.min(max_wait_ms)),
            max_wait: secs(max_wait_ms),
        };
        if let Some(aravis) = raw.aravis {
            self.aravis(&aravis)?;
        }
        let http = self.http(raw.http)?;
        let stream = raw.stream.as_ref().map(|s| self.stream(s)).transpose()?.flatten();
        let lsl = raw.lsl.map(|l| self.lsl(l)).transpose()?.flatten();
        let mice = raw.mice.count.unwrap_or(1);
        let mice = crate::vision::identity::mice_count(mice).map_err(|_| {
            let most = crate::vision::identity::MOST_MICE;
            self.bad(
                "mice.count",
                format!("must be from 1 to {most} (the most mice followed in one cage), not {mice}"),
            )
        })?;
        if mice > 1 && lsl.is_some() {
            return Err(self.bad(
                "mice.count",
                format!("is {mice}, but the LSL outlet offers one mouse's stream: take several mice's poses from [stream] or poses.csv"),
            ));
        }
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
            stream,
            lsl,
            mice,
        })
    }

    /// `output.record`: `true`, `false`, `"always"` or `"never"` (recording unless told not to).
    fn record(&self, record: Option<RawRecord>) -> Result<bool, ConfigError> {
        match record {
            None | Some(RawRecord::Flag(true)) => Ok(true),
            Some(RawRecord::Flag(false)) => Ok(false),
            Some(RawRecord::Mode(m)) => match m.as_str() {
                "always" => Ok(true),
                "never" => Ok(false),
                _ => Err(self.bad("output.record", format!("must be \"always\" or \"never\", not {m:?}"))),
            },
        }
    }

    /// `output.min_free_gb` and `output.min_free_percent`, 5 and 5 unless given.
    fn free_space(&self, gb: Option<f64>, percent: Option<f64>) -> Result<(f64, f64), ConfigError> {
        let min_free_gb = gb.unwrap_or(5.0);
        if !(min_free_gb.is_finite() && (0.0..=1e6).contains(&min_free_gb)) {
            return Err(self.bad(
                "output.min_free_gb",
                format!("must be from 0 to 1000000, not {min_free_gb}"),
            ));
        }
        let min_free_percent = percent.unwrap_or(5.0);
        if !(min_free_percent.is_finite() && (0.0..=90.0).contains(&min_free_percent)) {
            return Err(self.bad(
                "output.min_free_percent",
                format!("must be from 0 to 90, not {min_free_percent}"),
            ));
        }
        Ok((min_free_gb, min_free_percent))
    }

    /// `[aravis]`: no longer used (cameras are opened by their address); its `interfaces`,
    /// which asked for discovery by broadcast, refused.
    fn aravis(&self, aravis: &RawAravis) -> Result<(), ConfigError> {
        if !aravis.interfaces.is_empty() {
            return Err(self.bad(
                "aravis.interfaces",
                "is not used: mousepose never looks for GigE Vision cameras by broadcast; it opens the [color] address (remove the [aravis] table)",
            ));
        }
        tracing::warn!(config = ?self.path, "the [aravis] table is not used (cameras are opened by their address): remove it");
        Ok(())
    }

    /// `[lsl]`: the outlet, unless `enabled = false`; names must be non-empty.
    fn lsl(&self, l: RawLsl) -> Result<Option<LslConfig>, ConfigError> {
        if l.enabled == Some(false) {
            return Ok(None);
        }
        let mut config = LslConfig::named("mousepose");
        for (key, value, slot) in [
            ("lsl.name", l.name, &mut config.name),
            ("lsl.type", l.kind, &mut config.kind),
            ("lsl.source_id", l.source_id, &mut config.source_id),
        ] {
            match value {
                Some(v) if v.trim().is_empty() || v.contains('\0') => {
                    return Err(self.bad(key, "must be a name of at least one character"));
                }
                Some(v) => *slot = v,
                None => {}
            }
        }
        config.library = l.library;
        if let Some(queue) = l.queue {
            config.queue = self.capacity("lsl.queue", queue)?;
        }
        config.lead_ns = self.lead("lsl.lead_ms", l.lead_ms)?;
        Ok(Some(config))
    }

    /// `[stream]`: an endpoint this machine alone reaches unless `allow_remote`; `"off"`: none.
    fn stream(&self, s: &RawStream) -> Result<Option<StreamConfig>, ConfigError> {
        let endpoint = match s.endpoint.as_deref() {
            Some("off") => return Ok(None),
            Some(text) => text
                .parse::<Endpoint>()
                .map_err(|e| self.bad("stream.endpoint", format!("is wrong: {e} (or \"off\")")))?,
            None => Endpoint::default_tcp(),
        };
        if !endpoint.is_local() && s.allow_remote != Some(true) {
            return Err(self.bad(
                "stream.endpoint",
                format!(
                    "{endpoint} is reachable from other machines: set `allow_remote = true` to publish the \
                     poses beyond this machine (and secure it: see docs/FORMATS.md)"
                ),
            ));
        }
        let mut config = StreamConfig::at(endpoint);
        if let Some(queue) = s.queue {
            config.queue = self.capacity("stream.queue", queue)?;
        }
        if let Some(hwm) = s.high_water_mark {
            config.high_water_mark = i32::try_from(self.capacity("stream.high_water_mark", hwm)?).unwrap_or(4096);
        }
        config.lead_ns = self.lead("stream.lead_ms", s.lead_ms)?;
        Ok(Some(config))
    }

    /// A prediction's lead (`lead_ms`), as nanoseconds.
    fn lead(&self, key: &str, ms: Option<f64>) -> Result<Option<u64>, ConfigError> {
        ms.map(|ms| crate::runtime::pose_record::lead_ns(ms).map_err(|reason| self.bad(key, reason)))
            .transpose()
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Config, ConfigError> {
        Config::parse(text, Path::new("rig.toml"))
    }

    /// Issue 48 item 4: a URI no OpenNI2 driver can take is refused at start (OpenNI2 says
    /// "no device" for it as for a camera merely absent); well-formed ones are taken.
    #[test]
    fn openni2_uris_that_can_never_open_are_refused() {
        for bad in [
            "no-such-camera",
            "/dev/video0",
            "1d27/0601",
            "1d27/0601@x/1",
            "://x",
            "",
        ] {
            let e = parse(&format!("[depth]\nbackend = \"openni2\"\nuri = {bad:?}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("depth.uri") && e.contains("no OpenNI2 device URI"),
                "{bad}: {e}"
            );
        }
        for good in ["Dummy", "1d27/0601@3/7", "2bc5/0401@1/12", "freenect://0"] {
            parse(&format!("[depth]\nbackend = \"openni2\"\nuri = {good:?}\n")).unwrap();
        }
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
        assert_eq!(c.color.as_ref().map(|c| c.backend()), Some("aravis"));
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
        assert_eq!(c.color.as_ref().map(|c| c.backend()), Some("aravis"));
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
    fn issue46_the_lsl_outlet_is_off_without_its_table_and_its_names_are_checked() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        assert_eq!(parse(base).unwrap().lsl, None);
        assert_eq!(
            parse(&format!("{base}[lsl]\n")).unwrap().lsl,
            Some(LslConfig::named("mousepose"))
        );
        assert_eq!(parse(&format!("{base}[lsl]\nenabled = false\n")).unwrap().lsl, None);
        let c = parse(&format!(
            "{base}[lsl]\nname = \"rig2\"\ntype = \"Pose\"\nsource_id = \"rig2-top\"\nlibrary = \"/usr/lib/liblsl.so\"\n"
        ))
        .unwrap()
        .lsl
        .unwrap();
        assert_eq!(
            (c.name.as_str(), c.kind.as_str(), c.source_id.as_str()),
            ("rig2", "Pose", "rig2-top")
        );
        assert_eq!(c.library.as_deref(), Some(Path::new("/usr/lib/liblsl.so")));
        for (lsl, key) in [
            ("name = \" \"\n", "lsl.name"),
            ("queue = 0\n", "lsl.queue"),
            ("port = 1\n", "port"),
        ] {
            let e = parse(&format!("{base}[lsl]\n{lsl}")).unwrap_err().to_string();
            assert!(e.contains(key), "{lsl}: {e}");
        }
    }

    #[test]
    fn issue60_one_mouse_without_the_mice_table_and_a_count_checked() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        assert_eq!(parse(base).unwrap().mice, 1);
        assert_eq!(parse(&format!("{base}[mice]\ncount = 3\n")).unwrap().mice, 3);
        for count in ["0", "50", "-2"] {
            let e = parse(&format!("{base}[mice]\ncount = {count}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(&format!(
                    "mice.count must be from 1 to 5 (the most mice followed in one cage), not {count}"
                )),
                "{e}"
            );
        }
        let e = parse(&format!("{base}[mice]\ncount = \"two\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"two\"") && e.contains("line 5"), "{e}");
    }

    #[test]
    fn issue46_the_stream_is_off_without_its_table_on_loopback_by_default_and_checked() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        assert_eq!(parse(base).unwrap().stream, None);
        let c = parse(&format!("{base}[stream]\n")).unwrap();
        assert_eq!(c.stream, Some(StreamConfig::at(Endpoint::default_tcp())));
        let c = parse(&format!("{base}[stream]\nendpoint = \"off\"\n")).unwrap();
        assert_eq!(c.stream, None);
        let c = parse(&format!(
            "{base}[stream]\nendpoint = \"tcp://0.0.0.0:9000\"\nallow_remote = true\nqueue = 8\nhigh_water_mark = 5\nlead_ms = 40\n"
        ))
        .unwrap()
        .stream
        .unwrap();
        assert_eq!(
            (c.endpoint.to_string(), c.queue, c.high_water_mark, c.lead_ns),
            ("tcp://0.0.0.0:9000".to_owned(), 8, 5, Some(40_000_000))
        );
        for (stream, why) in [
            ("endpoint = \"tcp://0.0.0.0:9000\"\n", "allow_remote"),
            ("endpoint = \"tcp://localhost:9000\"\n", "IP:PORT"),
            ("endpoint = \"tcp://127.0.0.1:0\"\n", "port"),
            ("endpoint = \"ipc://\"\n", "ipc://PATH"),
            ("queue = 0\n", "from 1 to 4096"),
            ("high_water_mark = 5000\n", "from 1 to 4096"),
            ("lead_ms = 5000\n", "from 0 to 1000 ms"),
            ("lead_ms = -1\n", "from 0 to 1000 ms"),
            ("topic = \"poses\"\n", "unknown field"),
        ] {
            let e = parse(&format!("{base}[stream]\n{stream}")).unwrap_err().to_string();
            assert!(e.contains(why) && !e.contains('\n'), "{stream}: {e}");
        }
    }

    #[test]
    fn the_partner_wait_is_the_nearest_by_default_and_bounded_on_request() {
        let base = "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n";
        let ms = |sync: &str| parse(&format!("{base}{sync}")).map(|c| c.sync.partner_wait_ns);
        assert_eq!(ms("").unwrap(), None);
        let closed_loop = format!("[sync]\npartner_wait_ms = {CLOSED_LOOP_PARTNER_WAIT_MS}\n");
        assert_eq!(ms(&closed_loop).unwrap(), Some(3_000_000));
        assert_eq!(ms("[sync]\npartner_wait_ms = 0\n").unwrap(), Some(0));
        assert_eq!(ms("[sync]\npartner_wait_ms = 7.5\n").unwrap(), Some(7_500_000));
        assert_eq!(ms("[sync]\npartner_wait_ms = \"nearest\"\n").unwrap(), None);
        for (bad, why) in [("-1", "from 0 to 10000"), ("\"soon\"", "\"nearest\"")] {
            let e = ms(&format!("[sync]\npartner_wait_ms = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("sync.partner_wait_ms") && e.contains(why) && !e.contains('\n'),
                "{e}"
            );
        }

        // The partner reach: with a partner wait, up to two depth frame intervals.
        let reach = |sync: &str| parse(&format!("{base}[sync]\n{sync}")).map(|c| c.sync.partner_reach_ns);
        assert_eq!(reach("partner_wait_ms = 3\n").unwrap(), None);
        assert_eq!(
            reach("partner_wait_ms = 3\npartner_reach_ms = 34\n").unwrap(),
            Some(34_000_000)
        );
        for (bad, why) in [
            ("partner_reach_ms = 34\n", "needs a `partner_wait_ms`"),
            (
                "partner_wait_ms = 3\npartner_reach_ms = 90\n",
                "two depth frame intervals",
            ),
        ] {
            let e = reach(bad).unwrap_err().to_string();
            assert!(
                e.contains("sync.partner_reach_ms") && e.contains(why) && !e.contains('\n'),
                "{e}"
            );
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
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\nfps = -3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("depth.fps"), "{e}");
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n[sync]\ntolerance_ms = 40\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sync.tolerance_ms") && e.contains("16.7"), "{e}");
        let e = parse(
            "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n[color]\nbackend = \"aravis\"\naddress = \"cam\"\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("color.address"), "{e}");
        let e = parse("[depth]\nbackend = \"openni2\"\n").unwrap_err().to_string();
        assert!(e.contains("uri"), "{e}");
        // Below one frame a second is no camera mode (it used to mean "any mode").
        let e = parse("[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\nfps = 0.4\n")
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
