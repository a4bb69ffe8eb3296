//! Writing videos through the `ffmpeg` command line: raw frames are piped into a child
//! process, which encodes them into a file (FFV1 for lossless exports, H.264 for viewing).
//! Reading chosen frames of a video the same way ([`decode_frames`]).
//!
//! Frames go in as raw video at a constant rate, or, for a video whose frames keep their own
//! times ([`EncoderSpec::timed`]), each in a minimal Matroska stream (uncompressed RGB blocks
//! with microsecond timestamps) that ffmpeg passes through as variable frame rate.
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
    #[error("{program:?} could not decode the frames wanted of {path:?}: {why}")]
    Decode {
        program: PathBuf,
        path: PathBuf,
        why: String,
    },
    #[error("frame of {got} bytes, the video's frames are {expected} bytes")]
    FrameSize { got: usize, expected: usize },
    #[error("frame time {got_us} us is not after the previous frame's ({previous_us} us)")]
    TimeOrder { got_us: u64, previous_us: u64 },
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
    /// Frames carry their own times ([`Encoder::write_at`]), kept in the file (variable frame
    /// rate); `fps` is then only the time of frames written without one.
    pub timed: bool,
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
            timed: false,
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
            timed: false,
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

    /// The same video with each frame's own time kept (variable frame rate; RGB frames only):
    /// frames are written by [`Encoder::write_at`].
    #[must_use]
    pub fn timed(mut self) -> Self {
        self.timed = true;
        // The frames' own times, kept to 1/90000 s (the encoder's time base would otherwise be
        // one over the frame rate ffmpeg guesses, rounding each time to a whole frame).
        let keep = [
            "-fps_mode",
            "passthrough",
            "-enc_time_base:v",
            "1:90000",
            "-video_track_timescale",
            "90000",
        ];
        self.output_args.splice(0..0, keep.map(str::to_owned));
        self
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
    /// The time of the last frame written, microseconds.
    last_us: Option<u64>,
}

/// Minimal Matroska (EBML) for piping timed raw frames to ffmpeg: one video track of
/// uncompressed 24-bit RGB, each frame a cluster with its own timestamp (1 us units).
mod mkv {
    /// An element: its ID, its size as an 8-byte EBML number, its payload.
    fn element(out: &mut Vec<u8>, id: &[u8], payload: &[u8]) {
        out.extend_from_slice(id);
        let size = payload.len() as u64 | (1 << 56);
        out.extend_from_slice(&size.to_be_bytes());
        out.extend_from_slice(payload);
    }

    fn uint(out: &mut Vec<u8>, id: &[u8], value: u64) {
        element(out, id, &value.to_be_bytes());
    }

    /// The EBML header, the start of a segment of unknown size, its info (timestamps in
    /// microseconds) and the one track.
    pub fn header(width: u32, height: u32) -> Vec<u8> {
        let mut out = Vec::new();
        let mut ebml = Vec::new();
        uint(&mut ebml, &[0x42, 0x86], 1); // EBMLVersion
        uint(&mut ebml, &[0x42, 0xF7], 1); // EBMLReadVersion
        uint(&mut ebml, &[0x42, 0xF2], 4); // EBMLMaxIDLength
        uint(&mut ebml, &[0x42, 0xF3], 8); // EBMLMaxSizeLength
        element(&mut ebml, &[0x42, 0x82], b"matroska"); // DocType
        uint(&mut ebml, &[0x42, 0x87], 4); // DocTypeVersion
        uint(&mut ebml, &[0x42, 0x85], 2); // DocTypeReadVersion
        element(&mut out, &[0x1A, 0x45, 0xDF, 0xA3], &ebml);
        // Segment, size unknown (all ones).
        out.extend_from_slice(&[0x18, 0x53, 0x80, 0x67, 0x01, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]);
        let mut info = Vec::new();
        uint(&mut info, &[0x2A, 0xD7, 0xB1], 1000); // TimestampScale: 1 us
        element(&mut info, &[0x4D, 0x80], b"mousepose"); // MuxingApp
        element(&mut info, &[0x57, 0x41], b"mousepose"); // WritingApp
        element(&mut out, &[0x15, 0x49, 0xA9, 0x66], &info);
        let mut video = Vec::new();
        uint(&mut video, &[0xB0], u64::from(width)); // PixelWidth
        uint(&mut video, &[0xBA], u64::from(height)); // PixelHeight
        element(&mut video, &[0x2E, 0xB5, 0x24], b"RGB\x18"); // ColourSpace: 24-bit RGB
        let mut track = Vec::new();
        uint(&mut track, &[0xD7], 1); // TrackNumber
        uint(&mut track, &[0x73, 0xC5], 1); // TrackUID
        uint(&mut track, &[0x83], 1); // TrackType: video
        element(&mut track, &[0x86], b"V_UNCOMPRESSED"); // CodecID
        element(&mut track, &[0xE0], &video);
        let mut entry = Vec::new();
        element(&mut entry, &[0xAE], &track);
        element(&mut out, &[0x16, 0x54, 0xAE, 0x6B], &entry); // Tracks
        out
    }

    /// The cluster head of a frame of `frame_len` bytes at `t_us`: the frame's bytes follow.
    pub fn cluster_head(t_us: u64, frame_len: usize) -> Vec<u8> {
        // SimpleBlock: track 1, relative time 0, keyframe.
        let block_head = [0x81, 0, 0, 0x80];
        let block_len = block_head.len() + frame_len;
        let mut out = Vec::with_capacity(64);
        let mut time = Vec::new();
        uint(&mut time, &[0xE7], t_us); // Timestamp
        let cluster_len = time.len() + 1 + 8 + block_len;
        out.extend_from_slice(&[0x1F, 0x43, 0xB6, 0x75]);
        out.extend_from_slice(&(cluster_len as u64 | (1 << 56)).to_be_bytes());
        out.extend_from_slice(&time);
        out.push(0xA3);
        out.extend_from_slice(&(block_len as u64 | (1 << 56)).to_be_bytes());
        out.extend_from_slice(&block_head);
        out
    }
}

/// Decodes the frames `frames` (counted from 0, ascending, each once) of the video at `path`,
/// each as a PNG picture, in one run of ffmpeg.
///
/// # Errors
/// [`VideoError::Spawn`] when ffmpeg cannot be run; [`VideoError::Decode`] when it fails or
/// gives fewer frames (a video shorter than the frames wanted).
pub fn decode_frames(program: &Path, path: &Path, frames: &[u64]) -> Result<Vec<Vec<u8>>, VideoError> {
    let Some(last) = frames.last() else {
        return Ok(Vec::new());
    };
    let select: Vec<String> = frames.iter().map(|f| format!("eq(n\\,{f})")).collect();
    let output = Command::new(program)
        .args(["-nostdin", "-v", "error", "-i"])
        .arg(path)
        .args(["-map", "0:v:0", "-vf"])
        .arg(format!("select={}", select.join("+")))
        .args(["-fps_mode", "passthrough", "-f", "image2pipe", "-c:v", "png", "-"])
        .stdin(Stdio::null())
        .output()
        .map_err(|source| VideoError::Spawn {
            program: program.to_owned(),
            source,
        })?;
    let pictures = split_pngs(&output.stdout);
    if !output.status.success() || pictures.len() != frames.len() {
        return Err(VideoError::Decode {
            program: program.to_owned(),
            path: path.to_owned(),
            why: format!(
                "{} of {} frames decoded, the last wanted frame {last}: {}",
                pictures.len(),
                frames.len(),
                tail(&String::from_utf8_lossy(&output.stderr))
            ),
        });
    }
    Ok(pictures.into_iter().map(<[u8]>::to_vec).collect())
}

/// Splits PNG files written end to end, each at its end (its `IEND` chunk); a last file cut
/// short is left out.
fn split_pngs(mut bytes: &[u8]) -> Vec<&[u8]> {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    let mut out = Vec::new();
    while bytes.starts_with(&SIGNATURE) {
        let mut at = SIGNATURE.len();
        loop {
            // A chunk: its data's length, its type, the data, a checksum.
            let Some(head) = bytes.get(at..at + 8) else {
                return out;
            };
            let length = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
            at = at.saturating_add(12).saturating_add(length);
            if at > bytes.len() {
                return out;
            }
            if &head[4..8] == b"IEND" {
                break;
            }
        }
        out.push(&bytes[..at]);
        bytes = &bytes[at..];
    }
    out
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
        let mut command = Command::new(&spec.program);
        command.args(["-nostdin", "-hide_banner", "-v", "error", "-y"]);
        if spec.timed {
            command.args(["-f", "matroska", "-i", "-", "-an"]);
        } else {
            command
                .args(["-f", "rawvideo", "-pix_fmt", spec.input_pix_fmt])
                .args(["-s", &format!("{}x{}", spec.width, spec.height)])
                .args(["-framerate", &format!("{}", spec.fps), "-i", "-", "-an"]);
        }
        let mut child = command
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
        let mut encoder = Self {
            child,
            stdin,
            stderr,
            partial,
            dest: dest.to_owned(),
            frames: 0,
            last_us: None,
            spec,
        };
        if encoder.spec.timed {
            let header = mkv::header(encoder.spec.width, encoder.spec.height);
            encoder.pipe(&header)?;
        }
        Ok(encoder)
    }

    /// Writes `bytes` to ffmpeg.
    fn pipe(&mut self, bytes: &[u8]) -> Result<(), VideoError> {
        let written = match self.stdin.as_mut() {
            Some(stdin) => stdin.write_all(bytes),
            None => Err(io::Error::from(io::ErrorKind::BrokenPipe)),
        };
        written.map_err(|_| self.failure())
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Pipes one frame (`width * height * bytes_per_pixel` bytes, row-major) to ffmpeg; a
    /// timed video gives it the time of the frame after the last at `fps`.
    ///
    /// # Errors
    /// A frame of the wrong size, or ffmpeg stopped (its error output says why).
    pub fn write(&mut self, frame: &[u8]) -> Result<(), VideoError> {
        if self.spec.timed {
            let step = (1e6 / self.spec.fps.max(1e-3)).round() as u64;
            let t_us = self.last_us.map_or(0, |t| t + step.max(1));
            return self.write_at(frame, t_us);
        }
        self.check_size(frame)?;
        self.pipe(frame)?;
        self.frames += 1;
        Ok(())
    }

    /// Pipes one frame shown at `t_us` microseconds (a timed video; see
    /// [`EncoderSpec::timed`]; an untimed one takes the frame at its constant rate).
    ///
    /// # Errors
    /// A frame of the wrong size, a time not after the previous frame's, or ffmpeg stopped.
    pub fn write_at(&mut self, frame: &[u8], t_us: u64) -> Result<(), VideoError> {
        if !self.spec.timed {
            return self.write(frame);
        }
        self.check_size(frame)?;
        if let Some(previous_us) = self.last_us.filter(|&p| t_us <= p) {
            return Err(VideoError::TimeOrder {
                got_us: t_us,
                previous_us,
            });
        }
        let head = mkv::cluster_head(t_us, frame.len());
        self.pipe(&head)?;
        self.pipe(frame)?;
        self.last_us = Some(t_us);
        self.frames += 1;
        Ok(())
    }

    fn check_size(&self, frame: &[u8]) -> Result<(), VideoError> {
        if frame.len() == self.spec.frame_bytes() {
            Ok(())
        } else {
            Err(VideoError::FrameSize {
                got: frame.len(),
                expected: self.spec.frame_bytes(),
            })
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn png(value: u8) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, 2, 1);
        encoder.set_color(png::ColorType::Grayscale);
        encoder
            .write_header()
            .unwrap()
            .write_image_data(&[value, value])
            .unwrap();
        out
    }

    #[test]
    fn pngs_end_to_end_are_split_each_whole_and_a_cut_one_left_out() {
        let (a, b) = (png(7), png(200));
        let mut stream = [a.clone(), b.clone()].concat();
        assert_eq!(split_pngs(&stream), [a.as_slice(), b.as_slice()]);
        stream.extend_from_slice(&a[..a.len() - 3]);
        assert_eq!(split_pngs(&stream).len(), 2);
        assert!(split_pngs(b"not a picture").is_empty());
    }
}
