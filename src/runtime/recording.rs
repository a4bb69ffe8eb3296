//! A recording read back as the rig's cameras: a session directory (what `record`, `run` and
//! `synth session` write) or a depth-only recording in MoSeq's layout. It knows its rig, its
//! frame count, how its clocks pair, and can fetch single frames again (for pictures).

use crate::core::frame::{ColorFrame, DepthFrame};
use crate::core::geometry::Rig;
use crate::io::session::{CameraRole, SessionError, SessionReader, Truth};
use crate::runtime::capture::moseq::{MoseqConfig, MoseqDepth};
use crate::runtime::capture::{CaptureError, Clock, FrameSource};
use crate::runtime::sync::SyncConfig;
use crate::vision::calibrate::{CalibrationError, RigCalibration};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Why a recording cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("cannot open the session")]
    Session(#[from] SessionError),
    #[error("cannot read the MoSeq recording")]
    Moseq(#[source] CaptureError),
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
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
    },
}

impl Recording {
    /// Opens the session or MoSeq recording in `dir`.
    ///
    /// # Errors
    /// Neither a readable session nor a readable MoSeq recording.
    pub fn open(dir: &Path) -> Result<Self, RecordingError> {
        if is_moseq(dir) {
            let config = MoseqConfig::new(dir);
            let recording = Self::moseq(&config)?;
            let (size, count) = (recording.size(), recording.frame_count());
            return Ok(Recording::Moseq { config, size, count });
        }
        Ok(Recording::Session(Box::new(SessionReader::open(dir)?)))
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

    /// The rig: the session's calibration, or the default rig (for MoSeq recordings with the
    /// intrinsics of their frame size: Kinect v2's for 512x424, the default's scaled otherwise).
    pub fn rig(&self) -> Rig {
        let mut rig = Rig::default_rig();
        match self {
            Recording::Session(r) => r.meta().rig.unwrap_or(rig),
            &Recording::Moseq { size: (w, h), .. } => {
                let i = &mut rig.depth.intrinsics;
                let f = if (w, h) == (512, 424) {
                    365.0
                } else {
                    i.fx * f64::from(w) / f64::from(i.width)
                };
                (i.width, i.height, i.fx, i.fy) = (w, h, f, f);
                (i.cx, i.cy) = (f64::from(w) / 2.0, f64::from(h) / 2.0);
                rig
            }
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

    /// Up to `n` depth frames spread over the session (MoSeq: over its first frames).
    ///
    /// # Errors
    /// The MoSeq recording cannot be read.
    pub fn sample_depth(&self, n: usize) -> Result<Vec<DepthFrame>, RecordingError> {
        let count = self.depth_count();
        let picks = n.min(count);
        match self {
            Recording::Session(r) => Ok((0..picks)
                .filter_map(|k| r.depth_frame(k * count / picks).ok())
                .collect()),
            Recording::Moseq { config: c, .. } => {
                // One frame in ten of the first ones: a pass over the whole file would cost a
                // full decode of a long video.
                let mut source = Self::moseq(c)?;
                source.start(&Clock::replay(0)).map_err(RecordingError::Moseq)?;
                let mut frames = Vec::new();
                let mut k = 0usize;
                while frames.len() < picks && k < count && !source.finished() {
                    if let Some(f) = source
                        .next_frame(Duration::from_secs(5))
                        .map_err(RecordingError::Moseq)?
                    {
                        if k % 10 == 0 {
                            frames.push(f);
                        }
                        k += 1;
                    }
                }
                source.stop().map_err(RecordingError::Moseq)?;
                Ok(frames)
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
            Recording::Moseq { config: c, .. } => {
                let mut source = Self::moseq(c).ok()?;
                source.start(&Clock::replay(0)).ok()?;
                while !source.finished() {
                    if let Some(f) = source.next_frame(Duration::from_secs(5)).ok()? {
                        if f.stamp.seq >= seq {
                            let _ = source.stop();
                            return (f.stamp.seq == seq).then_some(f);
                        }
                    }
                }
                None
            }
        }
    }
}

/// Whether `dir` holds a MoSeq-layout recording rather than a session.
fn is_moseq(dir: &Path) -> bool {
    !dir.join(crate::io::session::META_FILE).exists()
        && (dir.join("depth.dat").is_file() || dir.join("depth.avi").is_file())
}
