//! A MoSeq-layout depth recording read as a depth camera, so that `replay` can run depth-only
//! pose on recordings made for MoSeq.
//!
//! # The layout
//! A session directory holds:
//! - `depth.dat`: raw frames one after the other, each `width * height` little-endian `u16`
//!   depths in millimetres, row-major, no header. The size comes from `metadata.json`
//!   (`"DepthResolution": [width, height]`, each side up to 65535) when that file has it, else from the configured
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
//!   would shift every later frame against its time. A line that repeats the timestamp before
//!   it is kept and counted ([`MoseqDepth::duplicate_timestamps`]): the synchroniser drops its
//!   frame (`time_out_of_order`), and `replay` reports how many there were.
//!
//! Each frame gets `Stamp { seq: frame index, device_ns: column 1 in ns, host_ns: column 2 in ns
//! or column 1 when there is no second column }`. The host clock handed to `start` is not
//! read: a recording's times are its own.
//!
//! Every check that can be made before reading a frame (sizes, the timestamp file, the frame
//! count against the timestamp count) is made by [`MoseqDepth::open`], so a bad directory fails
//! at once with an error naming the file. [`MoseqDepth::check_frame_size`] then reads a few
//! frames and refuses a `depth.dat` whose frames do not look like depth images at the size
//! used (a wrong `DepthResolution` of the same pixel count divides the file just as well).
//!
//! This file holds the source, [`MoseqDepth`], with its config and errors; `timestamps` reads
//! `depth_ts.txt`, and `reader` reads the depth file (its frame size, and its frames from
//! `depth.dat` or from an `ffmpeg` child decoding `depth.avi`).

mod reader;
mod size_check;
mod timestamps;

pub use reader::{MoseqMetadata, metadata_resolution, read_metadata};
pub use size_check::{SizeTried, smooth_share};
pub use timestamps::{MoseqTimestamp, ns_from_ms, parse_timestamps};

use reader::{Reader, probe, read_raw_frame, read_samples, read_video_frame};

use crate::core::frame::{DepthFrame, Stamp};
use crate::io::session::codec::FrameFormat;
use crate::io::session::meta::{BackendName, CameraMeta, CameraRole};
use crate::runtime::capture::{CaptureError, Clock, FrameSource};
use std::fs::File;
use std::io;
use std::ops::Range;
use std::path::PathBuf;
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

/// [`MoseqDepth::frames_at`] decodes a `depth.avi` in one pass rather than seeking to each
/// frame when it has at most this many frames per frame asked for (measured: an ffmpeg started
/// to seek to one 640x480 frame costs as much as decoding 10-70 of them on 2 cores).
pub const ONE_PASS_FRAMES_PER_SEEK: usize = 20;

/// The longest `depth_ts.txt` read (a day at 30 fps takes about 60 MB).
const MAX_TIMESTAMPS_BYTES: u64 = 1 << 30;

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
    #[error(
        "{path:?}: DepthResolution {value} is not [width, height] of positive integers up to {}",
        reader::MAX_SIDE_PX
    )]
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
    #[error(
        "{path:?} does not look like {width}x{height} depth frames ({given}): only {share_pct:.0} % of vertically neighbouring readings agree, as in noise, where a smooth floor gives most; sizes tried: {tried}; {advice}"
    )]
    FrameSize {
        path: PathBuf,
        width: u32,
        height: u32,
        /// Where the size came from.
        given: &'static str,
        share_pct: f64,
        tried: String,
        advice: String,
    },
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
    duplicates: usize,
    metadata: MoseqMetadata,
    fps: f64,
    /// The video's own frame rate (`depth.avi`), which its frames are seeked by.
    video_rate: Option<f64>,
    next_index: usize,
    reader: Option<Reader>,
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
        let text = match crate::io::read_bounded(&ts_path, MAX_TIMESTAMPS_BYTES) {
            Ok(text) => text,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Err(recording(MoseqError::NoTimestamps { path: ts_path }));
            }
            Err(source) => return Err(recording(MoseqError::Io { path: ts_path, source })),
        };
        let timestamps = parse_timestamps(&text, &ts_path).map_err(recording)?;

        let duplicates = timestamps
            .windows(2)
            .filter(|w| w.first().map(|a| a.device_ns) == w.get(1).map(|b| b.device_ns))
            .count();
        if duplicates > 0 {
            tracing::warn!(
                message = "Timestamps repeat: the frames after them are dropped as out of order.",
                path = %ts_path.display(),
                duplicates,
            );
        }
        let metadata = read_metadata(&config.dir.join(METADATA)).map_err(recording)?;
        let mut video_rate = None;
        let (width, height, frames) = match kind {
            MoseqKind::Raw => {
                let (width, height) = metadata
                    .resolution
                    .unwrap_or((config.default_width, config.default_height));
                let len = std::fs::metadata(&depth_path)
                    .map_err(|source| {
                        recording(MoseqError::Io {
                            path: depth_path.clone(),
                            source,
                        })
                    })?
                    .len();
                // Saturating: a configured default size is not bounded like metadata's.
                let frame_bytes = (u64::from(width) * u64::from(height)).saturating_mul(2);
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
            MoseqKind::Video => {
                let p = probe(&config.ffprobe, &depth_path).map_err(recording)?;
                video_rate = p.rate;
                (p.width, p.height, p.frames)
            }
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
            duplicates,
            metadata,
            fps,
            video_rate,
            next_index: 0,
            reader: None,
        })
    }

    /// How many lines of `depth_ts.txt` repeat the timestamp of the line before.
    pub fn duplicate_timestamps(&self) -> usize {
        self.duplicates
    }

    /// What `metadata.json` says (its camera, its frame size).
    pub fn metadata(&self) -> &MoseqMetadata {
        &self.metadata
    }

    /// Frame `index` (0-based), read on its own: `depth.dat` is seeked, `depth.avi` decoded by
    /// an ffmpeg seeking to the frame's time. Independent of the frames `next_frame` reads.
    ///
    /// # Errors
    /// An index past the end, or the file cannot be read there.
    pub fn frame_at(&self, index: usize) -> Result<DepthFrame, CaptureError> {
        if index >= self.timestamps.len() {
            return Err(self.error(self.count_mismatch(index as u64)));
        }
        let samples = self.frame_samples();
        let data = match self.kind {
            MoseqKind::Raw => read_raw_frame(&self.depth_path, samples, index as u64),
            MoseqKind::Video => read_video_frame(
                &self.config.ffmpeg,
                &self.depth_path,
                samples,
                self.video_seconds(index),
            ),
        }
        .map_err(|e| self.error(e))?;
        Ok(self.frame(index, data))
    }

    /// The time `depth.avi` is seeked to for frame `index`: the frame's own time by the
    /// video's rate (ffmpeg seeking an AVI half a frame early or late can give the frame
    /// before or after).
    fn video_seconds(&self, index: usize) -> f64 {
        let fps = self.video_rate.unwrap_or(if self.fps > 0.0 { self.fps } else { 30.0 });
        index as f64 / fps
    }

    /// Frames `range` in order, each handed to `each` as it is read, one at a time:
    /// `depth.dat` read on from the first, `depth.avi` decoded by a single ffmpeg from the
    /// first (a long range costs one seek, not one a frame, and never all its frames in memory).
    ///
    /// # Errors
    /// A range past the end, or the file cannot be read there.
    pub fn for_each_in(&self, range: Range<usize>, mut each: impl FnMut(DepthFrame)) -> Result<(), CaptureError> {
        if range.end > self.timestamps.len() {
            return Err(self.error(self.count_mismatch(range.end as u64)));
        }
        if range.is_empty() {
            return Ok(());
        }
        let samples = self.frame_samples();
        match self.kind {
            MoseqKind::Raw => {
                use std::io::{Seek, SeekFrom};
                let io_error = |source| {
                    self.error(MoseqError::Io {
                        path: self.depth_path.clone(),
                        source,
                    })
                };
                let mut file = File::open(&self.depth_path).map_err(io_error)?;
                file.seek(SeekFrom::Start(range.start as u64 * samples as u64 * 2))
                    .map_err(io_error)?;
                for index in range {
                    match read_samples(&mut file, samples) {
                        Ok((data, n)) if n == samples * 2 => each(self.frame(index, data)),
                        Ok(_) => return Err(self.error(self.count_mismatch(index as u64))),
                        Err(e) => return Err(io_error(e)),
                    }
                }
            }
            MoseqKind::Video => self.decode_video(range, |index, data| each(self.frame(index, data)))?,
        }
        Ok(())
    }

    /// Decodes `depth.avi`'s frames `range` by one ffmpeg seeking to the first, handing each
    /// frame's index and samples to `each` as it comes.
    ///
    /// # Errors
    /// The decoder fails or ends before the range does.
    fn decode_video(&self, range: Range<usize>, mut each: impl FnMut(usize, Vec<u16>)) -> Result<(), CaptureError> {
        let decoder = self.spawn_decoder(range.start).map_err(|e| self.error(e))?;
        let Some(frames) = decoder.frames.as_ref() else {
            return Err(self.error(self.count_mismatch(range.start as u64)));
        };
        for index in range {
            match frames.recv() {
                Ok(Ok(data)) => each(index, data),
                Ok(Err(e)) => return Err(self.error(e)),
                Err(_) => return Err(self.error(self.count_mismatch(index as u64))),
            }
        }
        Ok(())
    }

    /// Frame `index` with its stamp from the time file, holding `data`.
    fn frame(&self, index: usize, data: Vec<u16>) -> DepthFrame {
        let ts = &self.timestamps[index];
        DepthFrame {
            stamp: Stamp {
                seq: index as u64,
                device_ns: ts.device_ns,
                host_ns: ts.system_ns.unwrap_or(ts.device_ns),
            },
            width: self.width,
            height: self.height,
            data,
        }
    }

    /// Frames `indices` (in increasing order), each as [`Self::frame_at`] reads it. Of a
    /// `depth.avi`, when the frames up to the last one asked for are at most
    /// [`ONE_PASS_FRAMES_PER_SEEK`] times as many as the frames asked for, one ffmpeg decodes
    /// them all in a single pass and the ones asked for are kept: starting an ffmpeg to seek to
    /// one frame costs about as much as decoding that many frames (a replay of a short
    /// recording sampled its background by one ffmpeg per frame, most of its time).
    ///
    /// # Errors
    /// As [`Self::frame_at`]; or the decoder ends before the last frame asked for.
    pub fn frames_at(&self, indices: &[usize]) -> Result<Vec<DepthFrame>, CaptureError> {
        let Some(&last) = indices.last() else {
            return Ok(Vec::new());
        };
        let one_pass = self.kind == MoseqKind::Video
            && indices.windows(2).all(|w| w[0] < w[1])
            && last < self.timestamps.len()
            && last < ONE_PASS_FRAMES_PER_SEEK.saturating_mul(indices.len());
        if !one_pass {
            return indices.iter().map(|&i| self.frame_at(i)).collect();
        }
        let mut out = Vec::with_capacity(indices.len());
        let mut wanted = indices.iter().peekable();
        self.decode_video(0..last + 1, |index, data| {
            if wanted.next_if_eq(&&index).is_some() {
                out.push(self.frame(index, data));
            }
        })?;
        Ok(out)
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
}

impl FrameSource for MoseqDepth {
    type Frame = DepthFrame;

    fn meta(&self) -> CameraMeta {
        CameraMeta {
            role: CameraRole::Depth,
            backend: BackendName::new("moseq"),
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
            MoseqKind::Raw => File::open(&self.depth_path).map(Reader::Raw).map_err(|source| {
                self.error(MoseqError::Io {
                    path: self.depth_path.clone(),
                    source,
                })
            })?,
            MoseqKind::Video => Reader::Video(self.spawn_decoder(0).map_err(|e| self.error(e))?),
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
                match read_samples(file, samples) {
                    Ok((frame, n)) if n == samples * 2 => frame,
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
