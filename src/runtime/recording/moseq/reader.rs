//! Reading the depth file: the frame size of `depth.dat` from `metadata.json`, and that of
//! `depth.avi` from `ffprobe`; frames read from `depth.dat` as they are, or from an `ffmpeg`
//! child decoding `depth.avi`, whose output a named thread cuts into whole frames.

use super::{MoseqDepth, MoseqError};
use std::fs::File;
use std::io::{self, Read};
use std::path::Path;
use std::process::{Child, ChildStderr, Command, Stdio};
use std::sync::mpsc;

/// The longest side of a depth frame accepted (far beyond any depth camera's).
pub const MAX_SIDE_PX: u32 = 65_535;

/// What `metadata.json` says about the depth camera.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MoseqMetadata {
    /// `DepthResolution`: `[width, height]`.
    pub resolution: Option<(u32, u32)>,
    /// The camera, when a key names it (`CameraType`, `Camera`, `CameraName`, `DeviceName`,
    /// `DepthCamera`, `Device`, in any letter case): free text such as "Azure Kinect".
    pub camera: Option<String>,
}

/// Keys of `metadata.json` (compared without letter case) whose text names the depth camera.
const CAMERA_KEYS: &[&str] = &[
    "cameratype",
    "camera_type",
    "camera",
    "cameraname",
    "camera_name",
    "devicename",
    "device_name",
    "depthcamera",
    "depth_camera",
    "device",
];

/// Reads `metadata.json`; everything `None` when the file is absent.
///
/// # Errors
/// The file exists but cannot be read, is not JSON, or its `DepthResolution` is not two
/// positive integers.
pub fn read_metadata(path: &Path) -> Result<MoseqMetadata, MoseqError> {
    let text = match crate::io::read_bounded(path, 1 << 20) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(MoseqMetadata::default()),
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
    let camera = value.as_object().and_then(|o| {
        o.iter()
            .find(|(k, v)| CAMERA_KEYS.contains(&k.to_lowercase().as_str()) && v.is_string())
            .and_then(|(_, v)| v.as_str())
            .map(str::to_owned)
    });
    let Some(resolution) = value.get("DepthResolution") else {
        return Ok(MoseqMetadata {
            resolution: None,
            camera,
        });
    };
    let size = |i: usize| {
        resolution
            .get(i)
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .filter(|v| (1..=MAX_SIDE_PX).contains(v))
    };
    match (resolution.as_array().map(Vec::len), size(0), size(1)) {
        (Some(2), Some(w), Some(h)) => Ok(MoseqMetadata {
            resolution: Some((w, h)),
            camera,
        }),
        _ => Err(MoseqError::Resolution {
            path: path.to_owned(),
            value: resolution.to_string(),
        }),
    }
}

/// The frame size `metadata.json` gives (`DepthResolution`), `None` when the file or the key
/// is absent.
///
/// # Errors
/// As [`read_metadata`].
pub fn metadata_resolution(path: &Path) -> Result<Option<(u32, u32)>, MoseqError> {
    Ok(read_metadata(path)?.resolution)
}

/// Reads frame `index` of a raw depth file of `samples`-pixel frames, by seeking to it.
///
/// # Errors
/// The file cannot be read there (it is shorter).
pub(super) fn read_raw_frame(path: &Path, samples: usize, index: u64) -> Result<Vec<u16>, MoseqError> {
    use std::io::{Seek, SeekFrom};
    let io_error = |source| MoseqError::Io {
        path: path.to_owned(),
        source,
    };
    let mut file = File::open(path).map_err(io_error)?;
    file.seek(SeekFrom::Start(index * samples as u64 * 2))
        .map_err(io_error)?;
    match read_samples(&mut file, samples) {
        Ok((frame, n)) if n == samples * 2 => Ok(frame),
        Ok(_) => Err(io_error(io::ErrorKind::UnexpectedEof.into())),
        Err(e) => Err(io_error(e)),
    }
}

/// A frame of `samples` little-endian depth readings read from `reader` straight into the
/// frame's memory (no byte buffer between, no second copy), and the number of bytes read:
/// fewer than `2 * samples` when the reader ended first.
pub(super) fn read_samples(reader: &mut impl Read, samples: usize) -> io::Result<(Vec<u16>, usize)> {
    let mut frame = vec![0u16; samples];
    let n = read_full(reader, bytemuck::cast_slice_mut(&mut frame))?;
    // Nothing to do on a little-endian machine.
    for v in &mut frame {
        *v = u16::from_le(*v);
    }
    Ok((frame, n))
}

/// Decodes one frame of `depth.avi` at `seconds` from its start (ffmpeg seeks to it).
///
/// # Errors
/// ffmpeg cannot be run, fails, or gives no whole frame.
pub(super) fn read_video_frame(
    ffmpeg: &Path,
    path: &Path,
    samples: usize,
    seconds: f64,
) -> Result<Vec<u16>, MoseqError> {
    let output = Command::new(ffmpeg)
        .args(["-nostdin", "-v", "error", "-ss", &format!("{seconds:.6}"), "-i"])
        .arg(path)
        .args([
            "-map",
            "0:v:0",
            "-frames:v",
            "1",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "gray16le",
            "-",
        ])
        .stdin(Stdio::null())
        .output()
        .map_err(|source| MoseqError::Spawn {
            program: ffmpeg.to_owned(),
            source,
        })?;
    if !output.status.success() || output.stdout.len() != samples * 2 {
        return Err(MoseqError::Tool {
            program: ffmpeg.to_owned(),
            path: path.to_owned(),
            stderr: format!(
                "no whole frame at {seconds:.3} s ({} bytes): {}",
                output.stdout.len(),
                String::from_utf8_lossy(&output.stderr).trim()
            ),
        });
    }
    Ok(crate::io::u16_samples(&output.stdout))
}

/// What frames are read from while the source runs.
#[derive(Debug)]
pub(super) enum Reader {
    /// `depth.dat`, read a frame at a time straight into the frame's samples (no buffered
    /// reader: whole frames are larger than its buffer would be, and it would copy them once
    /// more).
    Raw(File),
    Video(VideoDecoder),
}

/// The ffmpeg child and the named thread that reads its output into whole frames.
#[derive(Debug)]
pub(super) struct VideoDecoder {
    child: Child,
    pub(super) frames: Option<mpsc::Receiver<Result<Vec<u16>, MoseqError>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl MoseqDepth {
    /// An ffmpeg decoding `depth.avi` from frame `from` on (seeking to its time, as
    /// [`MoseqDepth::frame_at`] does) to its end.
    pub(super) fn spawn_decoder(&self, from: usize) -> Result<VideoDecoder, MoseqError> {
        let mut command = Command::new(&self.config.ffmpeg);
        command.args(["-nostdin", "-v", "error"]);
        if from > 0 {
            command.args(["-ss", &format!("{:.6}", self.video_seconds(from))]);
        }
        let mut child = command
            .arg("-i")
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
    loop {
        match read_samples(&mut stdout, samples) {
            Ok((frame, n)) if n == samples * 2 => {
                if sender.send(Ok(frame)).is_err() {
                    return;
                }
            }
            Ok((_, n)) => {
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
pub(super) fn probe(ffprobe: &Path, path: &Path) -> Result<Probed, MoseqError> {
    let output = Command::new(ffprobe)
        .args(["-v", "error", "-select_streams", "v:0"])
        .args([
            "-show_entries",
            "stream=width,height,nb_frames,r_frame_rate",
            "-of",
            "json",
        ])
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
    // "30/1", "30000/1001".
    let rate = stream
        .get("r_frame_rate")
        .and_then(serde_json::Value::as_str)
        .and_then(|s| s.split_once('/'))
        .and_then(|(n, d)| Some(n.parse::<f64>().ok()? / d.parse::<f64>().ok()?))
        .filter(|r| r.is_finite() && *r > 0.0);
    Ok(Probed {
        width,
        height,
        frames,
        rate,
    })
}

/// What ffprobe says of a video: its frame size, frame count when the container records it,
/// and frame rate.
pub(super) struct Probed {
    pub width: u32,
    pub height: u32,
    pub frames: Option<u64>,
    pub rate: Option<f64>,
}
