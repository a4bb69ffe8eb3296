//! Writing videos through the `ffmpeg` command line: raw frames are piped into a child
//! process, which encodes them into a file (FFV1 for lossless exports, H.264 for viewing).
//!
//! The child's error output is read on a named thread (so that a chatty ffmpeg never blocks on
//! a full pipe) and its last lines name the cause when encoding fails. The video is written to
//! a hidden file beside the destination and renamed into place by [`Encoder::finish`], so an
//! interrupted export never leaves a file that looks complete.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

/// Why a video could not be written.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("cannot run {program:?} (is ffmpeg installed?)")]
    Spawn {
        program: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{program:?} failed writing {path:?}: {stderr}")]
    Encode {
        program: PathBuf,
        path: PathBuf,
        stderr: String,
    },
    #[error("frame of {got} bytes, the video's frames are {expected} bytes")]
    FrameSize { got: usize, expected: usize },
    #[error("cannot move the finished video to {path:?}")]
    Rename {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// What to encode: raw frames of one size and pixel format at a frame rate, and the output
/// options that pick the codec.
#[derive(Clone, Debug)]
pub struct EncoderSpec {
    /// The `ffmpeg` program.
    pub program: PathBuf,
    pub width: u32,
    pub height: u32,
    /// ffmpeg's name of the piped frames' pixel format (`gray16le`, `gray`, `rgb24`).
    pub input_pix_fmt: &'static str,
    /// Bytes per pixel of the piped frames.
    pub bytes_per_pixel: usize,
    pub fps: f64,
    /// Options before the output file (codec, its pixel format, its settings).
    pub output_args: Vec<String>,
}

impl EncoderSpec {
    /// Lossless FFV1 with per-slice checksums, the way MoSeq's acquisition writes depth:
    /// `input_pix_fmt` kept as the stored pixel format (`gray16le` depth, `gray` mono or
    /// Bayer mosaics, `rgb24` turned into FFV1's `bgr0`).
    pub fn ffv1(width: u32, height: u32, input_pix_fmt: &'static str, bytes_per_pixel: usize, fps: f64) -> Self {
        let stored = if input_pix_fmt == "rgb24" {
            "bgr0"
        } else {
            input_pix_fmt
        };
        Self {
            program: PathBuf::from("ffmpeg"),
            width,
            height,
            input_pix_fmt,
            bytes_per_pixel,
            fps,
            output_args: [
                "-c:v",
                "ffv1",
                "-level",
                "3",
                "-g",
                "1",
                "-slices",
                "4",
                "-slicecrc",
                "1",
                "-pix_fmt",
                stored,
            ]
            .map(str::to_owned)
            .to_vec(),
        }
    }

    /// H.264 (libx264) of RGB frames for viewing: yuv420p (what every player reads), the size
    /// rounded down to even numbers by the caller, `crf` the quality (lower is better).
    pub fn h264(width: u32, height: u32, fps: f64, crf: u32) -> Self {
        Self {
            program: PathBuf::from("ffmpeg"),
            width,
            height,
            input_pix_fmt: "rgb24",
            bytes_per_pixel: 3,
            fps,
            output_args: vec![
                "-c:v".into(),
                "libx264".into(),
                "-preset".into(),
                "veryfast".into(),
                "-crf".into(),
                crf.to_string(),
                "-pix_fmt".into(),
                "yuv420p".into(),
                "-movflags".into(),
                "+faststart".into(),
            ],
        }
    }

    fn frame_bytes(&self) -> usize {
        self.width as usize * self.height as usize * self.bytes_per_pixel
    }
}

/// An ffmpeg child encoding piped frames into a file.
#[derive(Debug)]
pub struct Encoder {
    spec: EncoderSpec,
    child: Child,
    stdin: Option<ChildStdin>,
    stderr: Option<std::thread::JoinHandle<String>>,
    partial: PathBuf,
    dest: PathBuf,
    frames: u64,
}

/// The last part of ffmpeg's error output, on one line.
fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    let start = lines.len().saturating_sub(4);
    lines.get(start..).unwrap_or_default().join(" / ")
}

impl Encoder {
    /// Starts ffmpeg writing to a hidden file beside `dest` (the container from `dest`'s
    /// extension).
    ///
    /// # Errors
    /// ffmpeg cannot be started.
    pub fn start(spec: EncoderSpec, dest: &Path) -> Result<Self, VideoError> {
        let name = dest
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "video".to_owned());
        let ext = dest.extension().map(|e| e.to_string_lossy().into_owned());
        let partial_name = match ext {
            Some(ext) => format!(".{name}.partial-{}.{ext}", std::process::id()),
            None => format!(".{name}.partial-{}", std::process::id()),
        };
        let partial = dest.with_file_name(partial_name);
        let mut child = Command::new(&spec.program)
            .args(["-nostdin", "-hide_banner", "-v", "error", "-y"])
            .args(["-f", "rawvideo", "-pix_fmt", spec.input_pix_fmt])
            .args(["-s", &format!("{}x{}", spec.width, spec.height)])
            .args(["-framerate", &format!("{}", spec.fps), "-i", "-", "-an"])
            .args(&spec.output_args)
            .arg(&partial)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| VideoError::Spawn {
                program: spec.program.clone(),
                source,
            })?;
        let stdin = child.stdin.take();
        let stderr = child.stderr.take().map(|mut pipe| {
            std::thread::Builder::new()
                .name("ffmpeg-stderr".to_owned())
                .spawn(move || {
                    let mut text = String::new();
                    // A read error ends the collection; the exit status still reports the failure.
                    let _ = pipe.read_to_string(&mut text);
                    text
                })
        });
        let stderr = match stderr.transpose() {
            Ok(handle) => handle,
            Err(source) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(VideoError::Spawn {
                    program: spec.program.clone(),
                    source,
                });
            }
        };
        Ok(Self {
            spec,
            child,
            stdin,
            stderr,
            partial,
            dest: dest.to_owned(),
            frames: 0,
        })
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Pipes one frame (`width * height * bytes_per_pixel` bytes, row-major) to ffmpeg.
    ///
    /// # Errors
    /// A frame of the wrong size, or ffmpeg stopped (its error output says why).
    pub fn write(&mut self, frame: &[u8]) -> Result<(), VideoError> {
        if frame.len() != self.spec.frame_bytes() {
            return Err(VideoError::FrameSize {
                got: frame.len(),
                expected: self.spec.frame_bytes(),
            });
        }
        let written = match self.stdin.as_mut() {
            Some(stdin) => stdin.write_all(frame),
            None => Err(io::Error::from(io::ErrorKind::BrokenPipe)),
        };
        if written.is_err() {
            return Err(self.failure());
        }
        self.frames += 1;
        Ok(())
    }

    /// Closes the pipe, waits for ffmpeg and moves the video into place.
    ///
    /// # Errors
    /// ffmpeg failed, or the rename failed.
    pub fn finish(mut self) -> Result<PathBuf, VideoError> {
        self.stdin = None;
        let status = self.child.wait();
        let stderr = self.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
        match status {
            Ok(s) if s.success() => {}
            _ => {
                let _ = std::fs::remove_file(&self.partial);
                return Err(VideoError::Encode {
                    program: self.spec.program.clone(),
                    path: self.dest.clone(),
                    stderr: tail(&stderr),
                });
            }
        }
        std::fs::rename(&self.partial, &self.dest).map_err(|source| VideoError::Rename {
            path: self.dest.clone(),
            source,
        })?;
        Ok(self.dest.clone())
    }

    /// ffmpeg stopped taking frames: waits for it and reports its error output.
    fn failure(&mut self) -> VideoError {
        self.stdin = None;
        let _ = self.child.kill();
        let _ = self.child.wait();
        let stderr = self.stderr.take().and_then(|h| h.join().ok()).unwrap_or_default();
        let _ = std::fs::remove_file(&self.partial);
        VideoError::Encode {
            program: self.spec.program.clone(),
            path: self.dest.clone(),
            stderr: tail(&stderr),
        }
    }
}

impl Drop for Encoder {
    fn drop(&mut self) {
        // Unfinished (an error or a panic elsewhere): stop ffmpeg and leave no partial file.
        if self.stdin.is_some() || self.stderr.is_some() {
            self.stdin = None;
            let _ = self.child.kill();
            let _ = self.child.wait();
            if let Some(h) = self.stderr.take() {
                let _ = h.join();
            }
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}
