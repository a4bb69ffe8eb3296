//! A recording read back as the rig's cameras: a session directory (what `record`, `run` and
//! `synth session` write) or a depth-only recording in MoSeq's layout. It knows its rig, its
//! frame count, how its clocks pair, and can fetch single frames again (for pictures).
//!
//! A recording without a rig calibration gets its depth camera's intrinsics from
//! [`crate::core::cameras`] (the camera its metadata names, else the one of its frame size;
//! an unknown size is refused) or from an intrinsics file, and is marked uncalibrated: the
//! replay then poses the camera on the floor it fits
//! ([`crate::vision::segment::FloorPlane::world_from_camera`]).

pub mod moseq;
pub mod session;

use crate::core::cameras::{CameraModelError, depth_camera};
use crate::core::frame::{ColorFrame, DepthFrame};
use crate::core::geometry::{Intrinsics, Rig};
use crate::io::session::{CameraRole, SessionError, SessionReader, Truth};
use crate::runtime::capture::CaptureError;
use crate::runtime::pairing::SyncConfig;
use crate::runtime::recording::moseq::{MoseqConfig, MoseqDepth};
use crate::vision::calibrate::{CalibrationError, RigCalibration};
use std::path::{Path, PathBuf};

/// Why a recording cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("cannot open the session")]
    Session(#[from] SessionError),
    #[error("cannot read the MoSeq recording")]
    Moseq(#[source] CaptureError),
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
    #[error(transparent)]
    CameraModel(#[from] CameraModelError),
    #[error(
        "the intrinsics {path:?} are for {width}x{height} images but the recording's depth frames are {frame_width}x{frame_height}"
    )]
    IntrinsicsSize {
        path: PathBuf,
        width: u32,
        height: u32,
        frame_width: u32,
        frame_height: u32,
    },
}

impl RecordingError {
    /// Whether the user's input is at fault (a wrong file given, a camera to name), rather
    /// than the recording failing to read.
    pub fn is_input_problem(&self) -> bool {
        match self {
            Self::Calibration(c) => c.is_input_problem(),
            Self::CameraModel(_) | Self::IntrinsicsSize { .. } => true,
            Self::Session(_) | Self::Moseq(_) => false,
        }
    }
}

/// A recording's rig, and what it rests on.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingRig {
    pub rig: Rig,
    /// The rig comes from a calibration, its world frame with it. Otherwise the depth camera's
    /// pose is to be fitted to the floor.
    pub calibrated: bool,
    /// Where the depth camera's intrinsics come from: "rig calibration", an intrinsics file,
    /// or a camera model of the table ("Kinect v2, nominal").
    pub intrinsics_from: String,
}

/// What a replay reads.
#[derive(Debug)]
pub enum Recording {
    Session(Box<SessionReader>),
    /// A depth-only recording in MoSeq's layout, its frame size and number of frames.
    Moseq {
        config: MoseqConfig,
        size: (u32, u32),
        count: usize,
        /// The camera `metadata.json` names.
        camera: Option<String>,
        /// Lines of `depth_ts.txt` repeating the timestamp before them.
        duplicate_timestamps: usize,
    },
}

impl Recording {
    /// Opens the session or MoSeq recording in `dir`. A MoSeq `depth.dat` must look like depth
    /// frames at its size ([`MoseqDepth::check_frame_size`]).
    ///
    /// # Errors
    /// Neither a readable session nor a readable MoSeq recording.
    pub fn open(dir: &Path) -> Result<Self, RecordingError> {
        if is_moseq(dir) {
            let config = MoseqConfig::new(dir);
            let recording = Self::moseq(&config)?;
            recording.check_frame_size().map_err(RecordingError::Moseq)?;
            return Ok(Recording::Moseq {
                size: recording.size(),
                count: recording.frame_count(),
                camera: recording.metadata().camera.clone(),
                duplicate_timestamps: recording.duplicate_timestamps(),
                config,
            });
        }
        Ok(Recording::Session(Box::new(SessionReader::open(dir)?)))
    }

    /// Whether it holds colour frames (a MoSeq recording never does).
    pub fn has_color(&self) -> bool {
        match self {
            Recording::Session(reader) => reader.color_count() > 0,
            Recording::Moseq { .. } => false,
        }
    }

    /// The directory it was read from.
    pub fn dir(&self) -> PathBuf {
        match self {
            Recording::Session(r) => r.dir().to_path_buf(),
            Recording::Moseq { config, .. } => config.dir.clone(),
        }
    }

    /// A fresh reader of the MoSeq recording.
    ///
    /// # Errors
    /// The recording cannot be opened.
    pub fn moseq(config: &MoseqConfig) -> Result<MoseqDepth, RecordingError> {
        MoseqDepth::open(config.clone()).map_err(RecordingError::Moseq)
    }

    /// The rig: the session's calibration; otherwise the default rig with the depth camera's
    /// intrinsics from `intrinsics` (an intrinsics file, as `calibrate intrinsics` writes)
    /// or from the camera table, marked uncalibrated.
    ///
    /// # Errors
    /// The intrinsics file cannot be read or is for another frame size; no camera of the
    /// table fits the recording.
    pub fn rig(&self, intrinsics: Option<&Path>) -> Result<RecordingRig, RecordingError> {
        let session_rig = match self {
            Recording::Session(r) => r.meta().rig,
            Recording::Moseq { .. } => None,
        };
        if let (Some(rig), None) = (session_rig, intrinsics) {
            return Ok(RecordingRig {
                rig,
                calibrated: true,
                intrinsics_from: "rig calibration".to_owned(),
            });
        }
        let (width, height) = self.depth_size();
        let (found, intrinsics_from): (Intrinsics, String) = match intrinsics {
            Some(path) => {
                let i = crate::vision::calibrate::load_intrinsics(path)?;
                if (i.width, i.height) != (width, height) {
                    return Err(RecordingError::IntrinsicsSize {
                        path: path.to_owned(),
                        width: i.width,
                        height: i.height,
                        frame_width: width,
                        frame_height: height,
                    });
                }
                (i, path.display().to_string())
            }
            None => {
                let named = match self {
                    Recording::Moseq { camera, .. } => camera.as_deref(),
                    Recording::Session(_) => None,
                };
                let model = depth_camera(named, width, height)?;
                (model.intrinsics(), format!("{}, nominal", model.label()))
            }
        };
        let mut rig = session_rig.unwrap_or_else(Rig::default_rig);
        rig.depth.intrinsics = found;
        Ok(RecordingRig {
            rig,
            calibrated: false,
            intrinsics_from,
        })
    }

    /// The depth frames' size.
    pub fn depth_size(&self) -> (u32, u32) {
        match self {
            Recording::Session(r) => r
                .meta()
                .camera(CameraRole::Depth)
                .map_or((0, 0), |c| (c.width, c.height)),
            Recording::Moseq { size, .. } => *size,
        }
    }

    /// Lines of a MoSeq `depth_ts.txt` that repeat the timestamp before them (`None` for
    /// sessions, whose frames carry their own stamps).
    pub fn duplicate_timestamps(&self) -> Option<usize> {
        match self {
            Recording::Session(_) => None,
            Recording::Moseq {
                duplicate_timestamps, ..
            } => Some(*duplicate_timestamps),
        }
    }

    /// The rig of a calibration file, refused when it was made for other cameras than the
    /// recording's (their image sizes, and serials when both are known).
    ///
    /// # Errors
    /// The file cannot be read, or was made for other cameras.
    pub fn calibrated_rig(&self, path: &Path) -> Result<Rig, RecordingError> {
        let calibration = RigCalibration::load(path)?;
        match self {
            Recording::Session(r) => calibration.check_matches(r.meta())?,
            &Recording::Moseq { size: (w, h), .. } => {
                calibration.check_camera(CameraRole::Depth, w, h, None, "the MoSeq recording")?;
            }
        }
        Ok(calibration.rig())
    }

    /// How the synchroniser pairs its cameras.
    pub fn sync_config(&self) -> SyncConfig {
        match self {
            Recording::Session(r) => SyncConfig {
                color: r.meta().camera(CameraRole::Color).is_some(),
                color_latency_ns: r.meta().color_latency_ns.unwrap_or(0),
                ..SyncConfig::default()
            },
            Recording::Moseq { .. } => SyncConfig {
                color: false,
                ..SyncConfig::default()
            },
        }
    }

    /// A synthetic session's ground truth.
    ///
    /// # Errors
    /// The truth files are there but damaged.
    pub fn truth(&self) -> Result<Option<Truth>, RecordingError> {
        match self {
            Recording::Session(reader) => Ok(reader.truth()?),
            Recording::Moseq { .. } => Ok(None),
        }
    }

    pub fn depth_count(&self) -> usize {
        match self {
            Recording::Session(r) => r.depth_count(),
            Recording::Moseq { count, .. } => *count,
        }
    }

    /// Up to `n` depth frames spread evenly over the whole recording.
    ///
    /// # Errors
    /// The MoSeq recording cannot be read.
    pub fn sample_depth(&self, n: usize) -> Result<Vec<DepthFrame>, RecordingError> {
        let count = self.depth_count();
        let picks = n.min(count);
        let indices: Vec<usize> = (0..picks).map(|k| k * count / picks).collect();
        self.depth_frames_at(&indices)
    }

    /// The depth frames at `indices` (positions in the recording, in increasing order); a
    /// session's frames that do not decode are left out.
    ///
    /// # Errors
    /// The MoSeq recording cannot be read.
    pub fn depth_frames_at(&self, indices: &[usize]) -> Result<Vec<DepthFrame>, RecordingError> {
        match self {
            Recording::Session(r) => Ok(indices.iter().filter_map(|&k| r.depth_frame(k).ok()).collect()),
            Recording::Moseq { config: c, .. } => {
                // Seeking: `depth.dat` directly, `depth.avi` by an ffmpeg per frame or, short, in one pass.
                let source = Self::moseq(c)?;
                source.frames_at(indices).map_err(RecordingError::Moseq)
            }
        }
    }

    /// The depth frames at positions `range`, in order, each handed to `each` as it is read
    /// (a MoSeq `depth.avi` by one ffmpeg from the first; never all of them in memory); a
    /// session's frames that do not decode are left out.
    ///
    /// # Errors
    /// The MoSeq recording cannot be read.
    pub fn for_each_depth_frame(
        &self,
        range: std::ops::Range<usize>,
        mut each: impl FnMut(DepthFrame),
    ) -> Result<(), RecordingError> {
        match self {
            Recording::Session(r) => {
                range.filter_map(|k| r.depth_frame(k).ok()).for_each(each);
                Ok(())
            }
            Recording::Moseq { config: c, .. } => {
                let source = Self::moseq(c)?;
                source.for_each_in(range, &mut each).map_err(RecordingError::Moseq)
            }
        }
    }

    /// The colour frame with sequence number `seq` (sessions only).
    pub fn color_frame(&self, seq: u64) -> Option<ColorFrame> {
        match self {
            Recording::Session(r) => {
                let index = r.seqs(CameraRole::Color).iter().position(|&s| s == seq)?;
                r.color_frame(index).ok()
            }
            Recording::Moseq { .. } => None,
        }
    }

    /// The depth frame with sequence number `seq`.
    pub fn depth_frame(&self, seq: u64) -> Option<DepthFrame> {
        match self {
            Recording::Session(r) => {
                let index = r.seqs(CameraRole::Depth).iter().position(|&s| s == seq)?;
                r.depth_frame(index).ok()
            }
            Recording::Moseq { config: c, count, .. } => {
                let index = usize::try_from(seq).ok().filter(|&i| i < *count)?;
                Self::moseq(c).ok()?.frame_at(index).ok()
            }
        }
    }
}

/// Whether `dir` holds a MoSeq-layout recording rather than a session.
fn is_moseq(dir: &Path) -> bool {
    !dir.join(crate::io::session::META_FILE).exists()
        && (dir.join("depth.dat").is_file() || dir.join("depth.avi").is_file())
}
