//! Writing a session: metadata first, then frames, events and truth as they come, each handed
//! to the operating system at once; indexes and the closing event at [`SessionWriter::finish`].

use super::codec::{Codec, CodecError, FrameEncoder};
use super::events::SessionEvent;
use super::meta::{CameraRole, SessionMeta};
use super::text::LineWriter;
use super::{
    EVENTS_FILE, FRAMES_FILE, INDEX_FILE, JOINTS_FILE, META_FILE, PAIRS_FILE, PAIRS_HEADER, Result, SessionError,
    SessionSummary, TIMESTAMPS_FILE, TIMESTAMPS_HEADER, TRUTH_DIR, io_error, joints_header_for,
};
use crate::core::frame::{ColorFrame, DepthFrame, Stamp};
use crate::core::pose::JointPositions;
use crate::io::store::{self, RecordWriter};
use crate::io::table::Exact;
use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

/// How a [`SessionWriter`] stores pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterOptions {
    pub depth_codec: Codec,
    /// zstd level for depth frames (1 fastest, up to 22 smallest).
    pub depth_level: i32,
    pub color_codec: Codec,
    /// zstd level for colour frames.
    pub color_level: i32,
}

impl Default for WriterOptions {
    /// Delta filter and zstd level 1 for both cameras: fast enough for live recording.
    fn default() -> Self {
        Self {
            depth_codec: Codec::DeltaZstd,
            depth_level: 1,
            color_codec: Codec::DeltaZstd,
            color_level: 1,
        }
    }
}

/// One camera's files being written.
#[derive(Debug)]
struct StreamWriter {
    store: RecordWriter,
    encoder: FrameEncoder,
    index_path: PathBuf,
    index: Vec<(u64, u64)>,
    /// The end of the last record in the index: the file's length once closed (a record that
    /// failed to be written whole is cut off).
    indexed_end: u64,
    timestamps: LineWriter,
}

impl StreamWriter {
    fn create(dir: &Path, role: CameraRole, codec: Codec, level: i32) -> Result<Self> {
        let sub = dir.join(role.name());
        fs::create_dir(&sub).map_err(io_error(&sub, "create directory"))?;
        let store = RecordWriter::create(sub.join(FRAMES_FILE), role.store_kind())?;
        let encoder = FrameEncoder::new(codec, level).map_err(|source| SessionError::Compression {
            path: store.path().to_path_buf(),
            level,
            source,
        })?;
        let timestamps = LineWriter::create(sub.join(TIMESTAMPS_FILE), Some(TIMESTAMPS_HEADER))?;
        Ok(Self {
            indexed_end: store.position(),
            store,
            encoder,
            index_path: sub.join(INDEX_FILE),
            index: Vec::new(),
            timestamps,
        })
    }

    /// Appends an encoded frame, flushes it, then records its time.
    fn append(&mut self, stamp: Stamp, payload: &[u8]) -> Result<()> {
        let offset = self.store.append(payload)?;
        self.store.flush()?;
        self.index.push((stamp.seq, offset));
        self.indexed_end = self.store.position();
        self.timestamps.write_row(&(stamp.seq, stamp.device_ns, stamp.host_ns))
    }

    fn write_index(&mut self) -> Result<()> {
        if self.store.position() > self.indexed_end {
            self.store.truncate(self.indexed_end)?;
        }
        self.store.flush()?;
        store::write_index(&self.index_path, self.indexed_end, &self.index)?;
        Ok(())
    }

    fn sync(&mut self) -> Result<()> {
        self.store.sync()?;
        self.timestamps.sync()
    }
}

/// The truth files of a synthetic session, created with the first truth written.
#[derive(Debug)]
struct TruthWriter {
    joints: LineWriter,
    pairs: LineWriter,
    /// Whether `joints.csv` has the `mouse` column (a session of several mice).
    per_mouse: bool,
}

/// The files and directories a session writer creates in `dir`.
fn session_entries(dir: &Path) -> [PathBuf; 5] {
    [
        dir.join(META_FILE),
        dir.join(EVENTS_FILE),
        dir.join(CameraRole::Depth.name()),
        dir.join(CameraRole::Color.name()),
        dir.join(TRUTH_DIR),
    ]
}

/// Removes a session's files and directories from `dir`, leaving anything else.
fn remove_session_entries(dir: &Path) -> Result<()> {
    for path in session_entries(dir) {
        let removed = if path.is_dir() {
            fs::remove_dir_all(&path)
        } else {
            fs::remove_file(&path)
        };
        match removed {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io_error(&path, "remove")(e)),
            _ => {}
        }
    }
    Ok(())
}

/// Writes a session directory. See the [module documentation](super) for the layout.
///
/// Frames, events and truth rows are handed to the operating system as they are written, so
/// a process killed at any point leaves every completed frame readable. Dropping the writer
/// without [`finish`](SessionWriter::finish) leaves a session without indexes and without the
/// `session_ended` event, which readers accept.
#[derive(Debug)]
pub struct SessionWriter {
    dir: PathBuf,
    depth: Option<StreamWriter>,
    color: Option<StreamWriter>,
    events: LineWriter,
    truth: Option<TruthWriter>,
    /// The latest host time seen in frames and events: the end time `finish` logs.
    last_host_ns: u64,
    /// Encoded frame bytes appended so far.
    frame_bytes: u64,
    /// Whether `session_ended` is in the event log (written, or buffered to be).
    ended: bool,
}

impl SessionWriter {
    /// Starts a session in `dir`, which must exist and be empty, with the default
    /// [`WriterOptions`].
    ///
    /// # Errors
    /// See [`SessionWriter::create_with`].
    pub fn create(dir: impl AsRef<Path>, meta: &SessionMeta) -> Result<Self> {
        Self::create_with(dir, meta, WriterOptions::default())
    }

    /// Starts a session in `dir`, which must exist and be empty: writes `session.toml` (and
    /// syncs it), then creates the frame files of the cameras in `meta.cameras` and the event
    /// log.
    ///
    /// # Errors
    /// [`SessionError::NotEmpty`] when `dir` holds anything; [`SessionError::Format`] when
    /// the metadata is not valid for this format version ([`SessionMeta::problem`]);
    /// [`SessionError::Io`] when a file can not be created; [`SessionError::Compression`]
    /// when zstd rejects a compression level.
    pub fn create_with(dir: impl AsRef<Path>, meta: &SessionMeta, options: WriterOptions) -> Result<Self> {
        let dir = dir.as_ref();
        let mut entries = fs::read_dir(dir).map_err(io_error(dir, "read directory"))?;
        if entries.next().is_some() {
            return Err(SessionError::NotEmpty {
                path: dir.to_path_buf(),
            });
        }
        Self::start(dir, meta, options)
    }

    /// Starts a session in `dir`, which may hold files of other kinds (a daemon chunk's
    /// `poses.csv`) but none of a session's, with the default [`WriterOptions`].
    ///
    /// # Errors
    /// [`SessionError::NotEmpty`] when `dir` holds a session's file or directory; otherwise
    /// as [`SessionWriter::create_with`].
    pub fn create_beside(dir: impl AsRef<Path>, meta: &SessionMeta) -> Result<Self> {
        let dir = dir.as_ref();
        if session_entries(dir).iter().any(|p| p.exists()) {
            return Err(SessionError::NotEmpty {
                path: dir.to_path_buf(),
            });
        }
        Self::start(dir, meta, WriterOptions::default())
    }

    /// Removes what a session that never got a frame put in `dir` (a session begun on a full
    /// disk: an empty or cut `session.toml` would be refused by every reader).
    ///
    /// # Errors
    /// A file or directory exists and cannot be removed.
    pub fn abandon(self) -> Result<()> {
        let dir = self.dir.clone();
        drop(self);
        remove_session_entries(&dir)
    }

    /// [`SessionWriter::create_with`] once `dir` is known to be free for a session: on
    /// failure, nothing of the session is left.
    fn start(dir: &Path, meta: &SessionMeta, options: WriterOptions) -> Result<Self> {
        let started = Self::start_files(dir, meta, options);
        if started.is_err() {
            // Best effort: the error to report is the one that stopped the start.
            let _ = remove_session_entries(dir);
        }
        started
    }

    fn start_files(dir: &Path, meta: &SessionMeta, options: WriterOptions) -> Result<Self> {
        let meta_path = dir.join(META_FILE);
        if let Some(reason) = meta.problem() {
            return Err(SessionError::Format {
                path: meta_path,
                reason,
            });
        }
        let text = toml::to_string(meta).map_err(|source| SessionError::MetaEncode {
            path: meta_path.clone(),
            source,
        })?;
        let mut file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&meta_path)
            .map_err(io_error(&meta_path, "create"))?;
        file.write_all(text.as_bytes()).map_err(io_error(&meta_path, "write"))?;
        file.sync_all().map_err(io_error(&meta_path, "sync"))?;

        let mut depth = None;
        let mut color = None;
        for camera in &meta.cameras {
            match camera.role {
                CameraRole::Depth => {
                    depth = Some(StreamWriter::create(
                        dir,
                        camera.role,
                        options.depth_codec,
                        options.depth_level,
                    )?);
                }
                CameraRole::Color => {
                    color = Some(StreamWriter::create(
                        dir,
                        camera.role,
                        options.color_codec,
                        options.color_level,
                    )?);
                }
            }
        }
        let events = LineWriter::create(dir.join(EVENTS_FILE), None)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            depth,
            color,
            events,
            truth: None,
            last_host_ns: 0,
            ended: false,
            frame_bytes: 0,
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Encoded frame bytes written so far (without record headers and indexes).
    pub fn frame_bytes(&self) -> u64 {
        self.frame_bytes
    }

    /// Whether the session's files were removed while it was written (its directory deleted
    /// under the writer): whatever it holds, and whatever is written to it from now on, is
    /// lost.
    pub fn removed(&self) -> bool {
        self.events.unlinked()
            || self
                .depth
                .iter()
                .chain(self.color.iter())
                .any(|s| s.store.unlinked() || s.timestamps.unlinked())
    }

    /// Whether the session's files are gone from where they were written: removed (as
    /// [`SessionWriter::removed`] says), or moved away (its directory, or one above it, renamed:
    /// `events.jsonl` is no longer at its path). What is written from now on does not go into
    /// the directory the session was started in.
    pub fn gone(&self) -> Option<crate::io::Gone> {
        if self.removed() {
            return Some(crate::io::Gone::Removed);
        }
        self.events.gone()
    }

    /// Whether the session has frames of `role` (its metadata declares the camera).
    pub fn has_camera(&self, role: CameraRole) -> bool {
        match role {
            CameraRole::Depth => self.depth.is_some(),
            CameraRole::Color => self.color.is_some(),
        }
    }

    fn stream(&mut self, role: CameraRole) -> Result<&mut StreamWriter> {
        let stream = match role {
            CameraRole::Depth => self.depth.as_mut(),
            CameraRole::Color => self.color.as_mut(),
        };
        stream.ok_or_else(|| SessionError::NoCamera {
            dir: self.dir.clone(),
            role,
        })
    }

    /// Appends a depth frame and its `timestamps.csv` row.
    ///
    /// # Errors
    /// [`SessionError::NoCamera`] without a depth camera in the metadata;
    /// [`SessionError::Encode`] when the frame's data does not match its size;
    /// [`SessionError::Store`] or [`SessionError::Io`] when writing fails.
    pub fn write_depth(&mut self, frame: &DepthFrame) -> Result<()> {
        self.write_frame(CameraRole::Depth, frame.stamp, |e| e.encode_depth(frame))
    }

    /// Appends a colour frame and its `timestamps.csv` row.
    ///
    /// # Errors
    /// As [`SessionWriter::write_depth`], for the colour camera.
    pub fn write_color(&mut self, frame: &ColorFrame) -> Result<()> {
        self.write_frame(CameraRole::Color, frame.stamp, |e| e.encode_color(frame))
    }

    /// Encodes a frame with the camera's encoder and appends it with its stamp.
    fn write_frame(
        &mut self,
        role: CameraRole,
        stamp: Stamp,
        encode: impl FnOnce(&mut FrameEncoder) -> std::result::Result<Vec<u8>, CodecError>,
    ) -> Result<()> {
        let stream = self.stream(role)?;
        let payload = encode(&mut stream.encoder).map_err(|source| SessionError::Encode {
            path: stream.store.path().to_path_buf(),
            seq: stamp.seq,
            source,
        })?;
        stream.append(stamp, &payload)?;
        self.frame_bytes += payload.len() as u64;
        self.last_host_ns = self.last_host_ns.max(stamp.host_ns);
        Ok(())
    }

    /// Events taken so far, including one whose write to the operating system failed but
    /// which waits, whole, in the buffer (the next write or flush writes it).
    pub fn events_logged(&self) -> u64 {
        self.events.lines()
    }

    /// Appends an event to `events.jsonl`.
    ///
    /// # Errors
    /// [`SessionError::Io`] when writing fails; [`SessionError::EventEncode`] should the event
    /// not serialise.
    pub fn log_event(&mut self, event: &SessionEvent) -> Result<()> {
        let line = serde_json::to_string(event).map_err(|source| SessionError::EventEncode {
            path: self.dir.join(EVENTS_FILE),
            source,
        })?;
        self.events.write_line(&line)?;
        if let Some(host_ns) = event.host_ns() {
            self.last_host_ns = self.last_host_ns.max(host_ns);
        }
        Ok(())
    }

    /// The truth's writers, created on first use with the `mouse` column when `per_mouse`
    /// says so (`None`: as they are, or without it); rows of one kind into a file of the other
    /// are refused.
    fn truth(&mut self, per_mouse: Option<bool>) -> Result<&mut TruthWriter> {
        let truth = match self.truth.take() {
            Some(truth) => truth,
            None => {
                let dir = self.dir.join(TRUTH_DIR);
                fs::create_dir(&dir).map_err(io_error(&dir, "create directory"))?;
                let per_mouse = per_mouse.unwrap_or(false);
                TruthWriter {
                    joints: LineWriter::create(dir.join(JOINTS_FILE), Some(&joints_header_for(per_mouse)))?,
                    pairs: LineWriter::create(dir.join(PAIRS_FILE), Some(PAIRS_HEADER))?,
                    per_mouse,
                }
            }
        };
        let truth = self.truth.insert(truth);
        if per_mouse.is_some_and(|p| p != truth.per_mouse) {
            return Err(SessionError::Format {
                path: self.dir.join(TRUTH_DIR).join(JOINTS_FILE),
                reason: "the truth of one mouse and of several mice cannot share a file".to_owned(),
            });
        }
        Ok(truth)
    }

    /// Appends the true joint positions of a depth frame to `truth/joints.csv` (creating the
    /// truth files first if needed). Numbers are written so they read back exactly.
    ///
    /// # Errors
    /// [`SessionError::Io`] when a truth file can not be created or written.
    pub fn write_truth(&mut self, depth_seq: u64, time_ns: u64, joints: &JointPositions) -> Result<()> {
        let coordinates: Vec<Exact> = joints.iter().flat_map(|p| [p.x, p.y, p.z]).map(Exact).collect();
        self.truth(Some(false))?
            .joints
            .write_row(&(depth_seq, time_ns, coordinates))
    }

    /// Appends the true joint positions of mouse `mouse` (1..) in a depth frame of a session
    /// of several mice to `truth/joints.csv`, whose `mouse` column follows `time_ns`.
    ///
    /// # Errors
    /// As [`SessionWriter::write_truth`]; [`SessionError::Format`] after rows of one mouse.
    pub fn write_truth_of(
        &mut self,
        depth_seq: u64,
        time_ns: u64,
        mouse: usize,
        joints: &JointPositions,
    ) -> Result<()> {
        let coordinates: Vec<Exact> = joints.iter().flat_map(|p| [p.x, p.y, p.z]).map(Exact).collect();
        self.truth(Some(true))?
            .joints
            .write_row(&(depth_seq, time_ns, mouse, coordinates))
    }

    /// Appends a depth frame's true colour partner (or none) to `truth/pairs.csv`.
    ///
    /// # Errors
    /// [`SessionError::Io`] when a truth file can not be created or written.
    pub fn write_truth_pair(&mut self, depth_seq: u64, color_seq: Option<u64>) -> Result<()> {
        self.truth(None)?.pairs.write_row(&(depth_seq, color_seq))
    }

    /// Depth frames written so far.
    pub fn depth_frames(&self) -> u64 {
        self.depth.as_ref().map_or(0, |s| s.index.len() as u64)
    }

    /// Colour frames written so far.
    pub fn color_frames(&self) -> u64 {
        self.color.as_ref().map_or(0, |s| s.index.len() as u64)
    }

    /// Ends the session at the latest host time seen in its frames and events; see
    /// [`SessionWriter::finish_at`].
    ///
    /// # Errors
    /// As [`SessionWriter::finish_at`].
    pub fn finish(self) -> Result<SessionSummary> {
        let host_ns = self.last_host_ns;
        self.finish_at(host_ns)
    }

    /// Ends the session: writes the indexes, logs `session_ended` with the frame counts at
    /// `host_ns`, and syncs every file to disk.
    ///
    /// # Errors
    /// [`SessionError::Io`] or [`SessionError::Store`] when writing or syncing fails.
    pub fn finish_at(mut self, host_ns: u64) -> Result<SessionSummary> {
        self.close_at(host_ns)
    }

    /// Ends the session at the latest host time seen, as [`SessionWriter::finish`] does, and
    /// can be tried again after it failed (a full disk): the frames appended before are
    /// written whole, the indexes again, and `session_ended` once.
    ///
    /// # Errors
    /// As [`SessionWriter::finish_at`].
    pub fn close(&mut self) -> Result<SessionSummary> {
        self.close_at(self.last_host_ns)
    }

    fn close_at(&mut self, host_ns: u64) -> Result<SessionSummary> {
        for stream in self.depth.iter_mut().chain(self.color.iter_mut()) {
            stream.write_index()?;
        }
        let (depth_frames, color_frames) = (self.depth_frames(), self.color_frames());
        if !self.ended {
            let logged = self.events.lines();
            let result = self.log_event(&SessionEvent::SessionEnded {
                host_ns,
                depth_frames,
                color_frames,
            });
            // Taken (buffered) even when handing it to the system failed: written by a retry.
            self.ended = self.events.lines() > logged;
            result?;
        }
        for stream in self.depth.iter_mut().chain(self.color.iter_mut()) {
            stream.sync()?;
        }
        self.events.sync()?;
        if let Some(truth) = self.truth.as_mut() {
            truth.joints.sync()?;
            truth.pairs.sync()?;
        }
        Ok(SessionSummary {
            dir: self.dir.clone(),
            depth_frames,
            color_frames,
            depth_bytes: self.depth.as_ref().map_or(0, |s| s.store.position()),
            color_bytes: self.color.as_ref().map_or(0, |s| s.store.position()),
            events: self.events.lines(),
        })
    }
}
