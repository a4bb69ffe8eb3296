//! Synthetic MoSeq recordings: the behaviour sequence of a synthetic session seen by a depth
//! camera of a real rig's kind (512x424 Kinect v2 frames by default) at a height above the
//! floor, written as MoSeq's acquisition writes a recording (`depth.dat`, `depth_ts.txt`,
//! `metadata.json`) with the true camera as `rig.yaml`. It is the input of the comparison with
//! moseq2-extract (`scripts/moseq2-check`), which reads `depth.dat` at 512x424 by default.
//! With [`MoseqSpec::video`] the frames go into `depth.avi` instead (16-bit grey FFV1, as
//! MoSeq compresses its recordings and `export moseq` writes them): an hour of Kinect frames is
//! 47 GB as `depth.dat` and about a fifth of it as `depth.avi`.

use super::body::skin;
use super::mouse::{fit_in_cage, pose_mouse};
use super::render::Cage;
use super::session::session_mouse;
use super::views::render_top_frame;
use super::{ENGINE_VERSION, Mice};
use crate::core::cameras::depth_camera;
use crate::core::geometry::{Camera, Rig, look_at};
use crate::core::image::Region;
use crate::core::noise::DepthNoise;
use crate::core::rng::item_rng;
use crate::io::video::{Encoder, EncoderSpec};
use crate::vision::calibrate::RigCalibration;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// The true camera, beside the recording (`replay DIR --calibration DIR/rig.yaml`).
pub const RIG_FILE: &str = "rig.yaml";
/// MoSeq's file names, as `runtime::recording::moseq` reads them (named here again: the
/// synthesis engine does not import the runtime; the unit test below reads the recording
/// back with the runtime's reader).
const DEPTH_DAT: &str = "depth.dat";
const DEPTH_AVI: &str = "depth.avi";
const DEPTH_TS: &str = "depth_ts.txt";
const METADATA: &str = "metadata.json";

/// What to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MoseqSpec {
    pub frames: u64,
    pub fps: f64,
    pub seed: u64,
    pub noise: DepthNoise,
    /// The frame size; one of the depth camera table's (nominal intrinsics).
    pub width: u32,
    pub height: u32,
    /// The camera's optical centre above the floor (mm), and its axis's tilt from the vertical
    /// (degrees, towards world +x).
    pub camera_height_mm: f64,
    pub tilt_deg: f64,
    /// A mouse of exactly this build instead of a standard one ([`super::Build::exact`]).
    pub build: Option<super::Build>,
    /// Write the frames as `depth.avi` (FFV1) rather than `depth.dat`.
    pub video: bool,
}

impl Default for MoseqSpec {
    fn default() -> Self {
        Self {
            frames: 900,
            fps: 30.0,
            seed: 0,
            noise: DepthNoise {
                model: crate::core::noise::NoiseModel::Tof,
                gaussian_mm: 0.0,
            },
            width: 512,
            height: 424,
            camera_height_mm: 670.0,
            tilt_deg: 0.0,
            build: None,
            video: false,
        }
    }
}

/// Why a recording could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum SynthMoseqError {
    #[error("no depth camera of the table makes {0}x{1} frames")]
    Size(u32, u32),
    #[error("cannot write {path:?}")]
    Write {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {path:?}")]
    Video {
        path: std::path::PathBuf,
        #[source]
        source: crate::io::video::VideoError,
    },
    #[error(transparent)]
    Calibration(#[from] crate::vision::calibrate::CalibrationError),
}

/// The depth camera of `spec`: looking down at the cage's centre from `camera_height_mm`,
/// tilted by `tilt_deg`, image x along world +x.
pub fn moseq_camera(spec: &MoseqSpec) -> Result<Camera, SynthMoseqError> {
    let model =
        depth_camera(None, spec.width, spec.height).map_err(|_| SynthMoseqError::Size(spec.width, spec.height))?;
    let h = spec.camera_height_mm;
    let shift = h * spec.tilt_deg.to_radians().tan() * 0.5;
    Ok(Camera {
        intrinsics: model.intrinsics(),
        world_from_camera: look_at(Point3::new(-shift, 0.0, h), Point3::new(shift, 0.0, 0.0), -Vector3::y()),
    })
}

// The random streams of a recording (the mouse's is the synthetic session's of the same seed).
const STREAM_DEPTH: u64 = 12;

/// Writes the recording into `dir` (which must exist), calling `progress` with the frames done
/// out of the total. Frames are posed and rendered a chunk at a time (rendered in parallel)
/// and written as they come: neither the recording nor its mice are ever held in memory.
///
/// # Errors
/// A frame size not in the camera table, or a file that cannot be written.
pub fn write_moseq(dir: &Path, spec: &MoseqSpec, mut progress: impl FnMut(u64, u64)) -> Result<(), SynthMoseqError> {
    let camera = moseq_camera(spec)?;
    let write_err = |name: &str| {
        let path = dir.join(name);
        move |source| SynthMoseqError::Write { path, source }
    };
    let background = Cage::new(&camera).depth(Region::full(&camera.intrinsics));
    let (mut animator, carriage) = session_mouse(spec.seed, Mice::Standard, spec.build);
    let period = 1.0 / spec.fps;
    let mut depth = DepthWriter::create(dir, spec)?;
    // Posed a chunk at a time (in order: the animation is sequential), then rendered in parallel.
    const CHUNK: u64 = 32;
    let mut mice = Vec::with_capacity(CHUNK as usize);
    let mut done = 0u64;
    while done < spec.frames {
        mice.clear();
        for k in done..(done + CHUNK).min(spec.frames) {
            if k > 0 {
                animator.advance(period);
            }
            let (mut params, placement) = animator.state();
            carriage.apply(&mut params);
            let mut mouse = pose_mouse(&params, &placement);
            fit_in_cage(&mut mouse, 3.0);
            mice.push(mouse);
        }
        let frames: Vec<Vec<u16>> = mice
            .par_iter()
            .enumerate()
            .map(|(i, m)| {
                let mut rng = item_rng(spec.seed, STREAM_DEPTH, done + i as u64);
                render_top_frame(&camera, &background, &skin(m), &spec.noise, &mut rng)
            })
            .collect();
        for f in frames {
            let bytes: Vec<u8> = f.iter().flat_map(|v| v.to_le_bytes()).collect();
            depth.write(&bytes)?;
        }
        done += mice.len() as u64;
        progress(done, spec.frames);
    }
    depth.finish()?;
    // MoSeq's timestamps: device milliseconds, one frame a line.
    let mut ts = String::new();
    for k in 0..spec.frames {
        let _ = writeln!(ts, "{:.3}", 1000.0 + k as f64 * 1000.0 * period);
    }
    std::fs::write(dir.join(DEPTH_TS), ts).map_err(write_err(DEPTH_TS))?;
    let metadata = serde_json::json!({
        "SubjectName": "synthetic",
        "SessionName": format!("synthetic seed {}", spec.seed),
        "StartTime": super::session::SYNTHETIC_CREATED,
        "DepthResolution": [spec.width, spec.height],
        "DepthDataType": "UInt16[]",
        "IsLittleEndian": true,
        "NidaqChannels": 0,
        "NidaqSamplingRate": 0.0,
        "SynthesisEngine": ENGINE_VERSION,
    });
    let json = serde_json::to_vec_pretty(&metadata).map_err(std::io::Error::from);
    json.and_then(|j| std::fs::write(dir.join(METADATA), j))
        .map_err(write_err(METADATA))?;
    let rig = Rig {
        depth: camera,
        ..Rig::default_rig()
    };
    RigCalibration::from_rig(&rig).save(&dir.join(RIG_FILE))?;
    Ok(())
}

/// Where the frames go: `depth.dat` as they are, or `depth.avi` through ffmpeg.
enum DepthWriter {
    Raw(std::path::PathBuf, std::io::BufWriter<std::fs::File>),
    Video(std::path::PathBuf, Encoder),
}

impl DepthWriter {
    fn create(dir: &Path, spec: &MoseqSpec) -> Result<Self, SynthMoseqError> {
        if spec.video {
            let path = dir.join(DEPTH_AVI);
            let video = EncoderSpec::ffv1(spec.width, spec.height, "gray16le", 2, spec.fps);
            let encoder = Encoder::start(video, &path).map_err(|source| SynthMoseqError::Video {
                path: path.clone(),
                source,
            })?;
            Ok(Self::Video(path, encoder))
        } else {
            let path = dir.join(DEPTH_DAT);
            let file = std::fs::File::create(&path).map_err(|source| SynthMoseqError::Write {
                path: path.clone(),
                source,
            })?;
            Ok(Self::Raw(path, std::io::BufWriter::new(file)))
        }
    }

    fn write(&mut self, frame: &[u8]) -> Result<(), SynthMoseqError> {
        match self {
            Self::Raw(path, dat) => dat.write_all(frame).map_err(|source| SynthMoseqError::Write {
                path: path.clone(),
                source,
            }),
            Self::Video(path, encoder) => encoder.write(frame).map_err(|source| SynthMoseqError::Video {
                path: path.clone(),
                source,
            }),
        }
    }

    fn finish(self) -> Result<(), SynthMoseqError> {
        match self {
            Self::Raw(path, mut dat) => dat.flush().map_err(|source| SynthMoseqError::Write { path, source }),
            Self::Video(path, encoder) => encoder
                .finish()
                .map(|_| ())
                .map_err(|source| SynthMoseqError::Video { path, source }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::recording::moseq::{MoseqConfig, MoseqDepth};

    #[test]
    fn a_synthetic_moseq_recording_reads_back_at_its_size_and_count() {
        let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let spec = MoseqSpec {
            frames: 5,
            ..MoseqSpec::default()
        };
        write_moseq(tmp.path(), &spec, |_, _| {}).unwrap_or_else(|e| panic!("{e}"));
        let len = std::fs::metadata(tmp.path().join(DEPTH_DAT))
            .map(|m| m.len())
            .unwrap_or(0);
        assert_eq!(len, 5 * 512 * 424 * 2);
        let rec = MoseqDepth::open(MoseqConfig::new(tmp.path())).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(rec.frame_count(), 5);
        assert_eq!(rec.size(), (512, 424));
        assert!(tmp.path().join(RIG_FILE).is_file());
        let odd = MoseqSpec {
            width: 400,
            height: 300,
            ..spec
        };
        assert!(matches!(
            write_moseq(tmp.path(), &odd, |_, _| {}),
            Err(SynthMoseqError::Size(400, 300))
        ));
    }
}
