//! The session directory: what `record` and `synth session` write and `replay` reads.
//!
//! ```text
//! SESSION/
//!   session.toml           metadata (meta.rs), written first
//!   depth/frames.mpstore   depth frames, one record each (io::store, codec/)
//!   depth/index.mpindex    seq -> record offset, written at the end
//!   depth/timestamps.csv   seq,device_ns,host_ns per frame written
//!   color/...              the same for the colour camera, absent in depth-only sessions
//!   events.jsonl           camera and session events (events.rs)
//!   truth/joints.csv       synthetic sessions: the true joint positions per depth frame
//!   truth/pairs.csv        synthetic sessions: the colour frame truly paired with each depth frame
//! ```
//!
//! Everything a writer puts out is handed to the operating system frame by frame, so a
//! recorder killed at any moment leaves a session whose complete frames are all readable: the
//! reader stops at a cut-short last record, steps over damaged ones, and rebuilds a missing
//! or stale index by scanning. `docs/FORMATS.md` describes the layout byte by byte.

pub mod codec;
pub mod events;
pub mod meta;
mod reader;
mod recover;
mod text;
mod writer;

pub use codec::{Codec, CodecError, FrameEncoder, FrameFormat, FrameHeader};
pub use events::SessionEvent;
pub use meta::{BackendName, CameraMeta, CameraRole, FORMAT_NAME, FORMAT_VERSION, SessionMeta, SessionSource};
pub use reader::{ColorFrames, DepthFrames, Frames, SessionReader};
pub use recover::{ClosedLeftOpen, close_left_open, cut_last_line};
pub use writer::{SessionWriter, WriterOptions};

use crate::core::pose::JointPositions;
use crate::io::store::{Damage, StoreError};
use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

/// The metadata file.
pub const META_FILE: &str = "session.toml";
/// A camera's frames, in its role's subdirectory.
pub const FRAMES_FILE: &str = "frames.mpstore";
/// A camera's index, in its role's subdirectory.
pub const INDEX_FILE: &str = "index.mpindex";
/// A camera's frame times, in its role's subdirectory.
pub const TIMESTAMPS_FILE: &str = "timestamps.csv";
/// The event log.
pub const EVENTS_FILE: &str = "events.jsonl";
/// The ground truth of synthetic sessions.
pub const TRUTH_DIR: &str = "truth";
/// True joint positions, in [`TRUTH_DIR`].
pub const JOINTS_FILE: &str = "joints.csv";
/// True depth-colour pairs, in [`TRUTH_DIR`].
pub const PAIRS_FILE: &str = "pairs.csv";

/// The header line of `timestamps.csv`.
pub const TIMESTAMPS_HEADER: &str = "seq,device_ns,host_ns";
/// The header line of `truth/pairs.csv`.
pub const PAIRS_HEADER: &str = "depth_seq,color_seq";

/// The header line of `truth/joints.csv`: `depth_seq,time_ns,` then `{joint}_x,{joint}_y,
/// {joint}_z` for the 24 joints in joint order.
pub fn joints_header() -> String {
    joints_header_for(false)
}

/// The header of `truth/joints.csv`, with the `mouse` column after `time_ns` for a session
/// of several mice (`per_mouse`).
pub fn joints_header_for(per_mouse: bool) -> String {
    let mut header = String::from(if per_mouse {
        "depth_seq,time_ns,mouse"
    } else {
        "depth_seq,time_ns"
    });
    for joint in crate::core::skeleton::Joint::ALL {
        for axis in ["x", "y", "z"] {
            header.push(',');
            header.push_str(joint.name());
            header.push('_');
            header.push_str(axis);
        }
    }
    header
}

/// Errors of writing and reading sessions. Every variant names the file or directory at fault.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    #[error("cannot {action} {}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: io::Error,
    },
    #[error("{}: {reason}", path.display())]
    Format { path: PathBuf, reason: String },
    #[error("{}: invalid session metadata", path.display())]
    Meta {
        path: PathBuf,
        #[source]
        source: toml::de::Error,
    },
    #[error("{}: cannot serialise the session metadata", path.display())]
    MetaEncode {
        path: PathBuf,
        #[source]
        source: toml::ser::Error,
    },
    #[error("{}: not empty, a new session needs an empty directory", path.display())]
    NotEmpty { path: PathBuf },
    #[error("{}: the session has no {role} camera", dir.display())]
    NoCamera { dir: PathBuf, role: CameraRole },
    #[error("{}: no {role} frame at position {index}, there are {count}", dir.display())]
    OutOfRange {
        dir: PathBuf,
        role: CameraRole,
        index: usize,
        count: usize,
    },
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("{}: cannot encode frame seq {seq}", path.display())]
    Encode {
        path: PathBuf,
        seq: u64,
        #[source]
        source: CodecError,
    },
    #[error("{}: cannot compress at zstd level {level}", path.display())]
    Compression {
        path: PathBuf,
        level: i32,
        #[source]
        source: CodecError,
    },
    #[error("{}: frame {frame}", path.display())]
    Frame {
        path: PathBuf,
        frame: FrameLocation,
        #[source]
        source: CodecError,
    },
    #[error("{}: line {line}: invalid event", path.display())]
    Event {
        path: PathBuf,
        line: u64,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: cannot encode event", path.display())]
    EventEncode {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: cannot encode a row", path.display())]
    RowEncode {
        path: PathBuf,
        #[source]
        source: csv::Error,
    },
    #[error("{}: line {line}: {reason}", path.display())]
    Text { path: PathBuf, line: u64, reason: String },
    #[error("{}: line {line}: not UTF-8 text", path.display())]
    NotText {
        path: PathBuf,
        line: u64,
        #[source]
        source: std::str::Utf8Error,
    },
    #[error("{}: line {line}: invalid {column}", path.display())]
    CsvValue {
        path: PathBuf,
        line: u64,
        column: String,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

type Result<T, E = SessionError> = std::result::Result<T, E>;

fn io_error<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(io::Error) -> SessionError + 'a {
    move |source| SessionError::Io {
        path: path.to_path_buf(),
        action,
        source,
    }
}

/// Where a frame that failed to decode sits in its file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameLocation {
    /// Offset of its record.
    pub offset: u64,
    /// Its sequence number, when the payload is long enough to hold one.
    pub seq: Option<u64>,
}

impl fmt::Display for FrameLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.seq {
            Some(seq) => write!(f, "seq {seq} at offset {}", self.offset),
            None => write!(f, "at offset {}", self.offset),
        }
    }
}

/// The ground truth of a synthetic session.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Truth {
    /// `(depth_seq, time_ns, joints)` per depth frame, millimetres in the world frame.
    pub joints: Vec<(u64, u64, JointPositions)>,
    /// `(depth_seq, color_seq)`: the colour frame truly taken with each depth frame, `None`
    /// when it has no partner.
    pub pairs: Vec<(u64, Option<u64>)>,
    /// In a session of several mice, the rows of mice 2, 3, ... (`joints` holds mouse 1's);
    /// empty for one mouse.
    pub others: Vec<Vec<(u64, u64, JointPositions)>>,
}

/// The highest mouse number a session's truth may name.
pub const MOST_TRUE_MICE: u64 = 64;

/// What readers stepped over in each camera's frames.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SessionDamage {
    pub depth: Damage,
    /// `None` in depth-only sessions.
    pub color: Option<Damage>,
}

impl SessionDamage {
    /// True when no camera's frames had damage or a truncated tail.
    pub fn is_clean(&self) -> bool {
        self.depth.is_clean() && self.color.as_ref().is_none_or(Damage::is_clean)
    }
}

/// What [`SessionWriter::finish`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionSummary {
    pub dir: PathBuf,
    pub depth_frames: u64,
    pub color_frames: u64,
    /// Sizes of the frame files.
    pub depth_bytes: u64,
    pub color_bytes: u64,
    /// Events logged, `session_ended` included.
    pub events: u64,
}
