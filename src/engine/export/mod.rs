//! The engines of `mousepose export`: what researchers take away from a session or a run. `nwb` writes the
//! poses as NWB with ndx-pose (through pynwb); `moseq` writes a
//! session in MoSeq's acquisition layout (lossless FFV1 depth, timestamps, metadata) and the
//! colour camera as its own lossless video; `video` draws a run's poses over its frames into
//! an H.264 MP4.

pub mod moseq;
pub mod nwb;
pub mod video;

use crate::engine::replay::SUMMARY_FILE;
use crate::io::session::META_FILE;
use std::path::{Path, PathBuf};

/// What a run's `summary.json` says about how it was made: a replay's names its session; a
/// daemon's chunk's does not (the chunk is its session, when the daemon recorded).
#[derive(Debug, serde::Deserialize)]
struct RunSummary {
    #[serde(default)]
    session: Option<PathBuf>,
    #[serde(default)]
    calibration: Option<PathBuf>,
}

/// Why the session of a run cannot be found.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0:?} is neither a session (no {META_FILE}) nor a run (no {SUMMARY_FILE})")]
    NotARun(PathBuf),
    #[error("cannot read {path:?}")]
    Summary {
        path: PathBuf,
        #[source]
        source: anyhow::Error,
    },
    #[error("the session {session:?} that {summary:?} names is not there (give it with --session)")]
    SessionGone { session: PathBuf, summary: PathBuf },
    #[error(
        "{0:?} holds poses but no recorded frames, and its summary names no session (a daemon's chunk recorded with `record = false`?); give the session with --session"
    )]
    NoSession(PathBuf),
}

/// A run (a replay's output directory, or a daemon's chunk) and the session it was made from.
#[derive(Clone, Debug)]
pub struct Run {
    pub dir: PathBuf,
    pub session: PathBuf,
    /// The calibration file the replay used instead of the session's own, if any.
    pub calibration: Option<PathBuf>,
}

impl Run {
    /// Finds the session of `dir`: `session` when given, `dir` itself when it is a session
    /// (a daemon's chunk, whose `summary.json` names no session), else the one its
    /// `summary.json` names.
    ///
    /// # Errors
    /// See [`RunError`].
    pub fn open(dir: &Path, session: Option<&Path>) -> Result<Self, RunError> {
        let summary_path = dir.join(SUMMARY_FILE);
        let summary = if summary_path.is_file() {
            let text = std::fs::read_to_string(&summary_path).map_err(|e| RunError::Summary {
                path: summary_path.clone(),
                source: e.into(),
            })?;
            let summary: RunSummary = serde_json::from_str(&text).map_err(|e| RunError::Summary {
                path: summary_path.clone(),
                source: e.into(),
            })?;
            Some(summary)
        } else {
            None
        };
        let calibration = summary.as_ref().and_then(|s| s.calibration.clone());
        let session = match (session, &summary) {
            (Some(s), _) => s.to_owned(),
            (None, _) if dir.join(META_FILE).is_file() => dir.to_owned(),
            (None, Some(summary)) => match &summary.session {
                Some(named) if named.is_dir() => named.clone(),
                Some(named) => {
                    return Err(RunError::SessionGone {
                        session: named.clone(),
                        summary: summary_path,
                    });
                }
                None => return Err(RunError::NoSession(dir.to_owned())),
            },
            (None, None) => return Err(RunError::NotARun(dir.to_owned())),
        };
        Ok(Self {
            dir: dir.to_owned(),
            session,
            calibration,
        })
    }
}

/// Refuses to replace an existing file unless `force`.
fn check_file_out(path: &Path, force: bool) -> Result<(), crate::engine::Failure> {
    if path.is_dir() {
        return Err(crate::engine::Failure::usage(anyhow::anyhow!(
            "{path:?} is a directory"
        )));
    }
    if path.exists() && !force {
        return Err(crate::engine::Failure::usage(crate::engine::Exists(path.to_owned())));
    }
    Ok(())
}
