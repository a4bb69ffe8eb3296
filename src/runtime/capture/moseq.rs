//! A MoSeq-layout depth recording read as a depth camera, so that `replay` can run depth-only
//! pose on recordings made for MoSeq.
//!
//! # The layout
//! A session directory holds:
//! - `depth.dat`: raw frames one after the other, each `width * height` little-endian `u16`
//!   depths in millimetres, row-major, no header. The size comes from `metadata.json`
//!   (`"DepthResolution": [width, height]`) when that file has it, else from the configured
//!   default (512x424, the Kinect v2 depth size). The file length must be a whole number of
//!   frames; or
//! - `depth.avi`: the same frames compressed losslessly (FFV1, 16-bit grey). It is decoded by an
//!   `ffmpeg` child process writing raw `gray16le` frames to a pipe, and its size comes from
//!   `ffprobe`. When both files exist, `depth.dat` is read.
//! - `depth_ts.txt`: one line per frame, in frame order, of whitespace-separated numbers in
//!   milliseconds. moseq2-extract reads the first column as the frame time; recordings made by
//!   some acquisition versions carry a second column. This reader takes the first column as the
//!   device timestamp and, when present, the second as the host (system) timestamp. Decimals are
//!   kept exactly down to the nanosecond. Blank lines are ignored. A line whose timestamp is
//!   smaller than the one before (in either column) is an error naming the line: skipping it
//!   would shift every later frame against its time.
//!
//! Each frame gets `Stamp { seq: frame index, device_ns: column 1 in ns, host_ns: column 2 in ns
//! or column 1 when there is no second column }`. The host clock handed to `start` is not
//! read: a recording's times are its own.
//!
//! Every check that can be made before reading a frame (sizes, the timestamp file, the frame
//! count against the timestamp count) is made by [`MoseqDepth::open`], so a bad directory fails
//! at once with an error naming the file.

use super::{CaptureError, Clock, FrameSource};
use crate::core::frame::{DepthFrame, Stamp};
use crate::io::session::codec::FrameFormat;
use crate::io::session::meta::{Backend, CameraMeta, CameraRole};
use std::fs::File;
use std::io::{self, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStderr, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// The depth file name of a raw recording.
pub const DEPTH_DAT: &str = "depth.dat";
/// The depth file name of a compressed recording.
pub const DEPTH_AVI: &str = "depth.avi";
/// The timestamp file name.
pub const DEPTH_TS: &str = "depth_ts.txt";
/// The metadata file name.
pub const METADATA: &str = "metadata.json";

/// Where a MoSeq recording is and how to read it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MoseqConfig {
    /// The session directory.
    pub dir: PathBuf,
    /// The frame size of `depth.dat` when `metadata.json` does not give one.
    pub default_width: u32,
    pub default_height: u32,
    /// The `ffmpeg` program (for `depth.avi`).
    pub ffmpeg: PathBuf,
    /// The `ffprobe` program (for `depth.avi`).
    pub ffprobe: PathBuf,
}

impl MoseqConfig {
    /// A recording in `dir` with the defaults: 512x424 frames, `ffmpeg` and `ffprobe` found on
    /// the search path.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            default_width: 512,
            default_height: 424,
            ffmpeg: PathBuf::from("ffmpeg"),
            ffprobe: PathBuf::from("ffprobe"),
        }
    }
}

/// What is wrong with a MoSeq recording. Carried as the source of
/// [`CaptureError::Recording`].
#[derive(Debug, thiserror::Error)]
pub enum MoseqError {
    #[error("{dir:?} holds neither {DEPTH_DAT} nor {DEPTH_AVI}")]
    NoDepthFile { dir: PathBuf },
    #[error("no timestamp file {path:?}")]
    NoTimestamps { path: PathBuf },
    #[error("cannot read {path:?}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{path:?} is not valid JSON")]
    Metadata {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{path:?}: DepthResolution {value} is not [width, height] of positive integers")]
    Resolution { path: PathBuf, value: String },
    #[error("{path:?} is {len} bytes, not a multiple of the {frame_bytes}-byte frame of {width}x{height} u16 depths")]
    Truncated {
        path: PathBuf,
        len: u64,
        frame_bytes: u64,
        width: u32,
        height: u32,
    },
    #[error("{path:?} line {line}: {text:?} is not a timestamp in milliseconds")]
    BadTimestamp { path: PathBuf, line: usize, text: String },
    #[error("{path:?} line {line}: {columns} columns, expected 1 or 2 like the lines before")]
    Columns { path: PathBuf, line: usize, columns: usize },
    #[error("{path:?} line {line}: timestamp {this_ms} ms is earlier than {previous_ms} ms on the line before")]
    OutOfOrder {
        path: PathBuf,
        line: usize,
        previous_ms: String,
        this_ms: String,
    },
    #[error("{depth:?} holds {frames} frames but {timestamps:?} holds {stamps} timestamps")]
    CountMismatch {
        depth: PathBuf,
        frames: u64,
        timestamps: PathBuf,
        stamps: usize,
    },
    #[error("cannot run {program:?}")]
    Spawn {
        program: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{program:?} failed on {path:?}: {stderr}")]
    Tool {
        program: PathBuf,
        path: PathBuf,
        stderr: String,
    },
    #[error("{path:?}: unexpected ffprobe output {output:?}")]
    Probe { path: PathBuf, output: String },
}

/// One line of `depth_ts.txt`, in nanoseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MoseqTimestamp {
    /// The first column.
    pub device_ns: u64,
    /// The second column, when the file has two.
    pub system_ns: Option<u64>,
}

/// Parses `depth_ts.txt` (see the module documentation); `path` only names the file in errors.
///
/// # Errors
/// A line that is not one or two non-negative numbers, a column count that changes, or a
/// timestamp smaller than the one on the line before.
pub fn parse_timestamps(text: &str, path: &Path) -> Result<Vec<MoseqTimestamp>, MoseqError> {
    let mut out: Vec<MoseqTimestamp> = Vec::new();
    let mut columns = None;
    let mut previous: Option<(&str, &str)> = None;
    for (index, line) in text.lines().enumerate() {
        let line_no = index + 1;
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        let n = fields.len();
        if !(1..=2).contains(&n) || columns.is_some_and(|c| c != n) {
            return Err(MoseqError::Columns {
                path: path.to_owned(),
                line: line_no,
                columns: n,
            });
        }
        columns = Some(n);
        let parse = |text: &str| {
            ns_from_ms(text).ok_or_else(|| MoseqError::BadTimestamp {
                path: path.to_owned(),
                line: line_no,
                text: text.to_owned(),
            })
        };
        let device_text = fields.first().copied().unwrap_or_default();
        let system_text = fields.get(1).copied();
        let stamp = MoseqTimestamp {
            device_ns: parse(device_text)?,
            system_ns: system_text.map(parse).transpose()?,
        };
        if let (Some(last), Some((last_device, last_system))) = (out.last(), previous) {
            let disorder = if stamp.device_ns < last.device_ns {
                Some((last_device, device_text))
            } else if stamp.system_ns < last.system_ns {
                Some((last_system, system_text.unwrap_or_default()))
            } else {
                None
            };
            if let Some((previous_ms, this_ms)) = disorder {
                return Err(MoseqError::OutOfOrder {
                    path: path.to_owned(),
                    line: line_no,
                    previous_ms: previous_ms.to_owned(),
                    this_ms: this_ms.to_owned(),
                });
            }
        }
        previous = Some((device_text, system_text.unwrap_or_default()));
        out.push(stamp);
    }
    Ok(out)
}

/// A non-negative decimal number of milliseconds (`1234`, `1234.5678`, `1.5e3`) in nanoseconds.
/// Plain decimals are converted exactly (digits past the nanosecond are truncated); numbers in
/// exponent notation go through `f64`.
pub fn ns_from_ms(text: &str) -> Option<u64> {
    if text.contains(['e', 'E']) {
        let ms: f64 = text.parse().ok()?;
        let ns = (ms * 1e6).round();
        return (ns.is_finite() && ns >= 0.0 && ns < u64::MAX as f64).then_some(ns as u64);
    }
    let text = text.strip_prefix('+').unwrap_or(text);
    let (int, frac) = text.split_once('.').unwrap_or((text, ""));
    if int.is_empty() && frac.is_empty() {
        return None;
    }
    if !int.bytes().chain(frac.bytes()).all(|b| b.is_ascii_digit()) {
        return None;
    }
    let int_ms: u64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut frac_ns = 0u64;
    for (i, digit) in frac.bytes().take(6).enumerate() {
        frac_ns += u64::from(digit - b'0') * 10u64.pow(5 - i as u32);
    }
    int_ms.checked_mul(1_000_000)?.checked_add(frac_ns)
}

/// The frame size `metadata.json` gives (`DepthResolution`), `None` when the file or the key
/// is absent.
///
/// # Errors
/// The file exists but cannot be read, is not JSON, or its `DepthResolution` is not two
/// positive integers.
pub fn metadata_resolution(path: &Path) -> Result<Option<(u32, u32)>, MoseqError> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(MoseqError::Io {
                path: path.to_owned(),
                source,
            });
        }
    };
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|source| MoseqError::Metadata {
        path: path.to_owned(),
        source,
    })?;
    let Some(resolution) = value.get("DepthResolution") else {
        return Ok(None);
    };
    let size = |i: usize| {
        resolution
            .get(i)
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .filter(|&v| v > 0)
    };
    match (resolution.as_array().map(Vec::len), size(0), size(1)) {
        (Some(2), Some(w), Some(h)) => Ok(Some((w, h))),
        _ => Err(MoseqError::Resolution {
            path: path.to_owned(),
            value: resolution.to_string(),
        }),
    }
}

/// Which depth file a recording has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MoseqKind {
    /// `depth.dat`, raw frames.
    Raw,
    /// `depth.avi`, decoded by ffmpeg.
    Video,
}

/// A MoSeq-layout recording read frame by frame as a depth camera.
#[derive(Debug)]
pub struct MoseqDepth {
    config: MoseqConfig,
    kind: MoseqKind,
    depth_path: PathBuf,
    width: u32,
    height: u32,
    timestamps: Vec<MoseqTimestamp>,
    fps: f64,
    next_index: usize,
    reader: Option<Reader>,
}

/// What frames are read from while the source runs.
#[derive(Debug)]
enum Reader {
    Raw(BufReader<File>),
    Video(VideoDecoder),
}

/// The ffmpeg child and the named thread that reads its output into whole frames.
#[derive(Debug)]
struct VideoDecoder {
    child: Child,
    frames: Option<mpsc::Receiver<Result<Vec<u16>, MoseqError>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl MoseqDepth {
    /// Checks the recording in `config.dir`: finds the depth file and its frame size, reads
    /// and checks the timestamps, and compares the frame count with the timestamp count.
    ///
    /// # Errors
    /// [`CaptureError::Recording`] with a [`MoseqError`] source naming the file at fault.
    pub fn open(config: MoseqConfig) -> Result<Self, CaptureError> {
        let dir = config.dir.clone();
        let recording = |source: MoseqError| CaptureError::Recording {
            path: dir.clone(),
            source: Box::new(source),
        };
        let dat = config.dir.join(DEPTH_DAT);
        let avi = config.dir.join(DEPTH_AVI);
        let (kind, depth_path) = if dat.is_file() {
            (MoseqKind::Raw, dat)
        } else if avi.is_file() {
            (MoseqKind::Video, avi)
        } else {
            return Err(recording(MoseqError::NoDepthFile {
                dir: config.dir.clone(),
            }));
        };

        let ts_path = config.dir.join(DEPTH_TS);
        let text = match std::fs::read_to_string(&ts_path) {
            Ok(text) => text,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(recording(MoseqError::NoTimestamps { path: ts_path }));
            }
            Err(source) => return Err(recording(MoseqError::Io { path: ts_path, source })),
        };
        let timestamps = parse_timestamps(&text, &ts_path).map_err(recording)?;

        let (width, height, frames) = match kind {
            MoseqKind::Raw => {
                let (width, height) = metadata_resolution(&config.dir.join(METADATA))
                    .map_err(recording)?
                    .unwrap_or((config.default_width, config.default_height));
                let len = std::fs::metadata(&depth_path)
                    .map_err(|source| {
                        recording(MoseqError::Io {
                            path: depth_path.clone(),
                            source,
                        })
                    })?
                    .len();
                let frame_bytes = u64::from(width) * u64::from(height) * 2;
                if frame_bytes == 0 || len % frame_bytes != 0 {
                    return Err(recording(MoseqError::Truncated {
                        path: depth_path,
                        len,
                        frame_bytes,
                        width,
                        height,
                    }));
                }
                (width, height, Some(len / frame_bytes))
            }
            MoseqKind::Video => probe(&config.ffprobe, &depth_path).map_err(recording)?,
        };
        if let Some(frames) = frames
            && frames != timestamps.len() as u64
        {
            return Err(recording(MoseqError::CountMismatch {
                depth: depth_path,
                frames,
                timestamps: ts_path,
                stamps: timestamps.len(),
            }));
        }
        let fps = match (timestamps.first(), timestamps.last()) {
            (Some(first), Some(last)) if last.device_ns > first.device_ns => {
                (timestamps.len() - 1) as f64 * 1e9 / (last.device_ns - first.device_ns) as f64
            }
            _ => 0.0,
        };
        tracing::debug!(
            message = "MoSeq recording opened.",
            dir = %config.dir.display(),
            kind = ?kind,
            width,
            height,
            frames = timestamps.len(),
        );
        Ok(Self {
            config,
            kind,
            depth_path,
            width,
            height,
            timestamps,
            fps,
            next_index: 0,
            reader: None,
        })
    }

    /// Which depth file the recording has.
    pub fn kind(&self) -> MoseqKind {
        self.kind
    }

    /// The number of frames (the number of timestamps).
    pub fn frame_count(&self) -> usize {
        self.timestamps.len()
    }

    /// The frame size in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn error(&self, source: MoseqError) -> CaptureError {
        CaptureError::Recording {
            path: self.config.dir.clone(),
            source: Box::new(source),
        }
    }

    fn frame_samples(&self) -> usize {
        self.width as usize * self.height as usize
    }

    fn count_mismatch(&self, frames: u64) -> MoseqError {
        MoseqError::CountMismatch {
            depth: self.depth_path.clone(),
            frames,
            timestamps: self.config.dir.join(DEPTH_TS),
            stamps: self.timestamps.len(),
        }
    }

    fn spawn_decoder(&self) -> Result<VideoDecoder, MoseqError> {
        let mut child = Command::new(&self.config.ffmpeg)
            .args(["-nostdin", "-v", "error", "-i"])
            .arg(&self.depth_path)
            .args(["-map", "0:v:0", "-f", "rawvideo", "-pix_fmt", "gray16le", "-"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| MoseqError::Spawn {
                program: self.config.ffmpeg.clone(),
                source,
            })?;
        let (Some(stdout), Some(stderr)) = (child.stdout.take(), child.stderr.take()) else {
            kill_and_reap(&mut child);
            return Err(MoseqError::Spawn {
                program: self.config.ffmpeg.clone(),
                source: io::Error::other("no pipe to the child"),
            });
        };
        let (sender, receiver) = mpsc::sync_channel(2);
        let samples = self.frame_samples();
        let program = self.config.ffmpeg.clone();
        let path = self.depth_path.clone();
        let thread = std::thread::Builder::new()
            .name("moseq-ffmpeg".to_owned())
            .spawn(move || decode_frames(stdout, stderr, samples, &program, &path, &sender))
            .map_err(|source| MoseqError::Spawn {
                program: self.config.ffmpeg.clone(),
                source,
            });
        match thread {
            Ok(thread) => Ok(VideoDecoder {
                child,
                frames: Some(receiver),
                thread: Some(thread),
            }),
            Err(e) => {
                kill_and_reap(&mut child);
                Err(e)
            }
        }
    }
}

/// Runs on the decoder thread: reads whole frames from ffmpeg's output and sends them until
/// the output ends, the receiver is gone or an error occurs (sent as the last item).
fn decode_frames(
    mut stdout: impl Read,
    mut stderr: ChildStderr,
    samples: usize,
    program: &Path,
    path: &Path,
    sender: &mpsc::SyncSender<Result<Vec<u16>, MoseqError>>,
) {
    let mut bytes = vec![0u8; samples * 2];
    loop {
        match read_full(&mut stdout, &mut bytes) {
            Ok(n) if n == bytes.len() => {
                let frame = bytes
                    .chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect();
                if sender.send(Ok(frame)).is_err() {
                    return;
                }
            }
            Ok(n) => {
                // End of output: clean after whole frames, otherwise ffmpeg failed.
                let mut text = String::new();
                let _ = stderr.read_to_string(&mut text);
                let text = text.trim();
                if n != 0 || !text.is_empty() {
                    let stderr = if text.is_empty() {
                        format!("output ended {n} bytes into a frame")
                    } else {
                        text.chars().take(1000).collect()
                    };
                    let _ = sender.send(Err(MoseqError::Tool {
                        program: program.to_owned(),
                        path: path.to_owned(),
                        stderr,
                    }));
                }
                return;
            }
            Err(source) => {
                let _ = sender.send(Err(MoseqError::Io {
                    path: path.to_owned(),
                    source,
                }));
                return;
            }
        }
    }
}

/// Reads until `buf` is full or the input ends; returns the number of bytes read.
fn read_full(reader: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        let Some(rest) = buf.get_mut(filled..) else { break };
        match reader.read(rest) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

/// Kills a child process (it may have ended already) and waits for it, so that no zombie stays.
fn kill_and_reap(child: &mut Child) {
    if let Err(error) = child.kill() {
        tracing::debug!(message = "Child already ended.", %error);
    }
    if let Err(error) = child.wait() {
        tracing::warn!(message = "Could not reap a child process.", %error);
    }
}

impl VideoDecoder {
    fn shut(&mut self) {
        // Dropping the receiver first unblocks a thread waiting to send; killing ffmpeg closes
        // the pipe the thread reads.
        self.frames = None;
        kill_and_reap(&mut self.child);
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!(message = "The ffmpeg reader thread panicked.");
        }
    }
}

impl Drop for VideoDecoder {
    fn drop(&mut self) {
        self.shut();
    }
}

/// Width, height and (when the container knows it) frame count of the first video stream.
fn probe(ffprobe: &Path, path: &Path) -> Result<(u32, u32, Option<u64>), MoseqError> {
    let output = Command::new(ffprobe)
        .args(["-v", "error", "-select_streams", "v:0"])
        .args(["-show_entries", "stream=width,height,nb_frames", "-of", "json"])
        .arg(path)
        .stdin(Stdio::null())
        .output()
        .map_err(|source| MoseqError::Spawn {
            program: ffprobe.to_owned(),
            source,
        })?;
    if !output.status.success() {
        return Err(MoseqError::Tool {
            program: ffprobe.to_owned(),
            path: path.to_owned(),
            stderr: String::from_utf8_lossy(&output.stderr)
                .trim()
                .chars()
                .take(1000)
                .collect(),
        });
    }
    let text = String::from_utf8_lossy(&output.stdout).into_owned();
    let bad = || MoseqError::Probe {
        path: path.to_owned(),
        output: text.chars().take(1000).collect(),
    };
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|_| bad())?;
    let stream = value.get("streams").and_then(|s| s.get(0)).ok_or_else(bad)?;
    let dim = |key: &str| {
        stream
            .get(key)
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .filter(|&v| v > 0)
    };
    let (Some(width), Some(height)) = (dim("width"), dim("height")) else {
        return Err(bad());
    };
    let frames = stream
        .get("nb_frames")
        .and_then(serde_json::Value::as_str)
        .and_then(|s| s.parse().ok());
    Ok((width, height, frames))
}

impl FrameSource for MoseqDepth {
    type Frame = DepthFrame;

    fn meta(&self) -> CameraMeta {
        CameraMeta {
            role: CameraRole::Depth,
            backend: Backend::Moseq,
            model: match self.kind {
                MoseqKind::Raw => format!("MoSeq recording ({DEPTH_DAT})"),
                MoseqKind::Video => format!("MoSeq recording ({DEPTH_AVI})"),
            },
            serial: self
                .config
                .dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            firmware: String::new(),
            width: self.width,
            height: self.height,
            pixel_format: FrameFormat::Depth16,
            fps: self.fps,
        }
    }

    fn start(&mut self, _clock: &Clock) -> Result<(), CaptureError> {
        self.stop()?;
        self.next_index = 0;
        let reader = match self.kind {
            MoseqKind::Raw => File::open(&self.depth_path)
                .map(|f| Reader::Raw(BufReader::with_capacity(1 << 20, f)))
                .map_err(|source| {
                    self.error(MoseqError::Io {
                        path: self.depth_path.clone(),
                        source,
                    })
                })?,
            MoseqKind::Video => Reader::Video(self.spawn_decoder().map_err(|e| self.error(e))?),
        };
        self.reader = Some(reader);
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<DepthFrame>, CaptureError> {
        let index = self.next_index;
        let samples = self.frame_samples();
        let data = match self.reader.as_mut() {
            None => return Ok(None),
            Some(Reader::Raw(file)) => {
                if index >= self.timestamps.len() {
                    return Ok(None);
                }
                let mut bytes = vec![0u8; samples * 2];
                let read = read_full(file, &mut bytes);
                match read {
                    Ok(n) if n == bytes.len() => bytes
                        .chunks_exact(2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]]))
                        .collect(),
                    Ok(_) => return Err(self.error(self.count_mismatch(index as u64))),
                    Err(source) => {
                        return Err(self.error(MoseqError::Io {
                            path: self.depth_path.clone(),
                            source,
                        }));
                    }
                }
            }
            Some(Reader::Video(decoder)) => {
                let Some(frames) = decoder.frames.as_ref() else {
                    return Ok(None);
                };
                match frames.recv_timeout(timeout) {
                    Ok(Ok(data)) if index < self.timestamps.len() => data,
                    Ok(Ok(_)) => {
                        // One frame more than timestamps: count what the decoder still has.
                        let mut frames_seen = index as u64 + 1;
                        while let Ok(Ok(_)) = frames.recv_timeout(timeout) {
                            frames_seen += 1;
                        }
                        return Err(self.error(self.count_mismatch(frames_seen)));
                    }
                    Ok(Err(e)) => return Err(self.error(e)),
                    Err(mpsc::RecvTimeoutError::Timeout) => return Ok(None),
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        decoder.frames = None;
                        if index < self.timestamps.len() {
                            return Err(self.error(self.count_mismatch(index as u64)));
                        }
                        return Ok(None);
                    }
                }
            }
        };
        let Some(ts) = self.timestamps.get(index) else {
            return Ok(None);
        };
        self.next_index += 1;
        let stamp = Stamp {
            seq: index as u64,
            device_ns: ts.device_ns,
            host_ns: ts.system_ns.unwrap_or(ts.device_ns),
        };
        tracing::trace!(message = "MoSeq frame read.", seq = stamp.seq);
        Ok(Some(DepthFrame {
            stamp,
            width: self.width,
            height: self.height,
            data,
        }))
    }

    fn finished(&self) -> bool {
        self.next_index >= self.timestamps.len()
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        // Dropping the decoder kills and reaps ffmpeg and joins its reader thread.
        self.reader = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn milliseconds_convert_exactly() {
        assert_eq!(ns_from_ms("0"), Some(0));
        assert_eq!(ns_from_ms("1234"), Some(1_234_000_000));
        assert_eq!(ns_from_ms("1234.5678"), Some(1_234_567_800));
        assert_eq!(ns_from_ms("1.0000019"), Some(1_000_001));
        assert_eq!(ns_from_ms(".5"), Some(500_000));
        assert_eq!(ns_from_ms("1.5e3"), Some(1_500_000_000));
        for bad in ["", ".", "-1", "1,5", "abc", "1.2.3", "NaN"] {
            assert_eq!(ns_from_ms(bad), None, "{bad}");
        }
    }

    #[test]
    fn one_and_two_columns_parse() {
        let path = Path::new("depth_ts.txt");
        let one = parse_timestamps("10\n43.5\n\n77\n", path).unwrap();
        assert_eq!(one.len(), 3);
        assert_eq!(
            one[1],
            MoseqTimestamp {
                device_ns: 43_500_000,
                system_ns: None
            }
        );
        let two = parse_timestamps("10 1000.25\n43 1033\n", path).unwrap();
        assert_eq!(two[0].system_ns, Some(1_000_250_000));
        let err = parse_timestamps("10 1\n20\n", path).unwrap_err();
        assert!(matches!(err, MoseqError::Columns { line: 2, .. }), "{err}");
        let err = parse_timestamps("10 100\n20 90\n", path).unwrap_err();
        assert!(matches!(err, MoseqError::OutOfOrder { line: 2, .. }), "{err}");
    }
}
