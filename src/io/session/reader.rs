//! Reading a session: metadata checked first, frames sequentially (stepping over damage) or
//! by position through the index, events and truth tolerant of a writer killed mid-line.

use super::codec::{self, CodecError, peek_seq};
use super::events::SessionEvent;
use super::meta::{CameraRole, FORMAT_NAME, FORMAT_VERSION, SessionMeta};
use super::text::{Csv, read_lines};
use super::{
    EVENTS_FILE, FRAMES_FILE, FrameLocation, INDEX_FILE, JOINTS_FILE, META_FILE, MOST_TRUE_MICE, PAIRS_FILE,
    PAIRS_HEADER, Result, SessionDamage, SessionError, TIMESTAMPS_FILE, TIMESTAMPS_HEADER, TRUTH_DIR, Truth, io_error,
    joints_header, joints_header_for,
};
use crate::core::frame::{ColorFrame, DepthFrame, Stamp};
use crate::core::pose::JointPositions;
use crate::core::skeleton::JOINT_COUNT;
use crate::io::store::{Damage, IndexStatus, Kind, RecordReader};
use nalgebra::Point3;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

/// One camera's frame file opened for random access, with its index.
#[derive(Debug)]
struct Stream {
    path: PathBuf,
    reader: Mutex<RecordReader>,
    /// `(seq, offset)` in file order.
    entries: Vec<(u64, u64)>,
    index_status: IndexStatus,
    /// What rebuilding the index stepped over (nothing when the index file was used).
    damage: Damage,
}

impl Stream {
    fn open(dir: &Path, role: CameraRole) -> Result<Self> {
        let sub = dir.join(role.name());
        let path = sub.join(FRAMES_FILE);
        let mut reader = RecordReader::open(&path, role.store_kind())?;
        let (entries, index_status) = reader.load_index(sub.join(INDEX_FILE), peek_seq)?;
        let damage = if index_status.rebuilt() {
            reader.damage().clone()
        } else {
            Damage::default()
        };
        Ok(Self {
            path,
            reader: Mutex::new(reader),
            entries,
            index_status,
            damage,
        })
    }

    fn payload(&self, dir: &Path, role: CameraRole, index: usize) -> Result<(u64, Vec<u8>)> {
        let &(_, offset) = self.entries.get(index).ok_or_else(|| SessionError::OutOfRange {
            dir: dir.to_path_buf(),
            role,
            index,
            count: self.entries.len(),
        })?;
        // Reads leave nothing half-done that a panic elsewhere could have broken.
        let mut reader = self.reader.lock().unwrap_or_else(PoisonError::into_inner);
        Ok((offset, reader.read_at(offset)?))
    }

    fn decode<T>(&self, offset: u64, payload: &[u8], decode: fn(&[u8]) -> Result<T, CodecError>) -> Result<T> {
        decode(payload).map_err(|source| SessionError::Frame {
            path: self.path.clone(),
            frame: FrameLocation {
                offset,
                seq: peek_seq(payload),
            },
            source,
        })
    }
}

/// A session opened for reading. See the [module documentation](super) for the layout.
///
/// Frame counts and random access come from each camera's index, or, when the index is
/// missing, invalid or stale (a session whose writer was killed has none), from a scan of the
/// frame file made when the session is opened.
#[derive(Debug)]
pub struct SessionReader {
    dir: PathBuf,
    meta: SessionMeta,
    depth: Stream,
    color: Option<Stream>,
}

impl SessionReader {
    /// Opens a session: reads and checks `session.toml`, then opens each camera's frames and
    /// loads (or rebuilds) its index.
    ///
    /// # Errors
    /// [`SessionError::Io`] when `session.toml` or a camera's frame file is missing or can not
    /// be read; [`SessionError::Format`] when the metadata is not of a known format and
    /// version, or describes no valid camera set; [`SessionError::Meta`] when it does not
    /// parse (an unknown key is named in the cause); [`SessionError::Store`] when a frame file
    /// is not a record file of the right kind.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref();
        let meta = read_meta(&dir.join(META_FILE))?;
        let depth = Stream::open(dir, CameraRole::Depth)?;
        let color = match meta.camera(CameraRole::Color) {
            Some(_) => Some(Stream::open(dir, CameraRole::Color)?),
            None => None,
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            meta,
            depth,
            color,
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn meta(&self) -> &SessionMeta {
        &self.meta
    }

    fn stream(&self, role: CameraRole) -> Result<&Stream> {
        match role {
            CameraRole::Depth => Ok(&self.depth),
            CameraRole::Color => self.color.as_ref().ok_or_else(|| SessionError::NoCamera {
                dir: self.dir.clone(),
                role,
            }),
        }
    }

    /// The depth frames in file order, read from the start. Damaged records are stepped over
    /// (see [`Frames::damage`]); a frame whose record is intact but whose contents do not
    /// decode is an `Err` item, and the frames after it still follow.
    pub fn depth_frames(&self) -> DepthFrames {
        Frames::new(self.depth.path.clone(), Kind::DepthFrames, codec::decode_depth)
    }

    /// The colour frames in file order; `None` in depth-only sessions.
    pub fn color_frames(&self) -> Option<ColorFrames> {
        self.color
            .as_ref()
            .map(|s| Frames::new(s.path.clone(), Kind::ColorFrames, codec::decode_color))
    }

    /// Number of depth frames.
    pub fn depth_count(&self) -> usize {
        self.depth.entries.len()
    }

    /// Number of colour frames (0 in depth-only sessions).
    pub fn color_count(&self) -> usize {
        self.color.as_ref().map_or(0, |s| s.entries.len())
    }

    /// The sequence numbers of a camera's frames in file order (empty without that camera).
    pub fn seqs(&self, role: CameraRole) -> Vec<u64> {
        self.stream(role)
            .map(|s| s.entries.iter().map(|e| e.0).collect())
            .unwrap_or_default()
    }

    /// A camera's index (`(seq, offset)` in file order) and the bytes of the cut record that
    /// end its frame file (0 when it ends on a whole record); `None` without that camera.
    pub(super) fn frame_index(&self, role: CameraRole) -> Option<(Vec<(u64, u64)>, u64)> {
        self.stream(role)
            .ok()
            .map(|s| (s.entries.clone(), s.damage.truncated_tail_bytes))
    }

    /// The host time of a camera's last frame; `None` without that camera, a frame, or a
    /// last frame that decodes.
    pub(super) fn last_host_ns(&self, role: CameraRole) -> Option<u64> {
        let last = self.stream(role).ok()?.entries.len().checked_sub(1)?;
        match role {
            CameraRole::Depth => self.depth_frame(last).ok().map(|f| f.stamp.host_ns),
            CameraRole::Color => self.color_frame(last).ok().map(|f| f.stamp.host_ns),
        }
    }

    /// The depth frame at `index` (0-based position in the file).
    ///
    /// # Errors
    /// [`SessionError::OutOfRange`] past the last frame; [`SessionError::Store`] when its
    /// record is damaged; [`SessionError::Frame`] when it does not decode.
    pub fn depth_frame(&self, index: usize) -> Result<DepthFrame> {
        let (offset, payload) = self.depth.payload(&self.dir, CameraRole::Depth, index)?;
        self.depth.decode(offset, &payload, codec::decode_depth)
    }

    /// The colour frame at `index` (0-based position in the file).
    ///
    /// # Errors
    /// [`SessionError::NoCamera`] in depth-only sessions, otherwise as
    /// [`SessionReader::depth_frame`].
    pub fn color_frame(&self, index: usize) -> Result<ColorFrame> {
        let stream = self.stream(CameraRole::Color)?;
        let (offset, payload) = stream.payload(&self.dir, CameraRole::Color, index)?;
        stream.decode(offset, &payload, codec::decode_color)
    }

    /// How each camera's index was obtained; `None` without that camera.
    pub fn index_status(&self, role: CameraRole) -> Option<&IndexStatus> {
        self.stream(role).ok().map(|s| &s.index_status)
    }

    /// What opening the session stepped over in each camera's frames: known for cameras
    /// whose index had to be rebuilt by scanning (which is the case after a killed writer);
    /// clean otherwise. [`SessionReader::verify`] checks every record.
    pub fn damage(&self) -> SessionDamage {
        SessionDamage {
            depth: self.depth.damage.clone(),
            color: self.color.as_ref().map(|s| s.damage.clone()),
        }
    }

    /// Reads every record of every camera and reports what was damaged or truncated.
    ///
    /// # Errors
    /// [`SessionError::Store`] when a frame file can not be read.
    pub fn verify(&self) -> Result<SessionDamage> {
        let scan = |stream: &Stream, kind: Kind| -> Result<Damage> {
            let mut reader = RecordReader::open(&stream.path, kind)?;
            for record in reader.records() {
                record?;
            }
            Ok(reader.damage().clone())
        };
        Ok(SessionDamage {
            depth: scan(&self.depth, Kind::DepthFrames)?,
            color: self.color.as_ref().map(|s| scan(s, Kind::ColorFrames)).transpose()?,
        })
    }

    /// The rows of a camera's `timestamps.csv` (an unfinished last row left out).
    ///
    /// # Errors
    /// [`SessionError::NoCamera`] without that camera; [`SessionError::Io`],
    /// [`SessionError::Text`] or [`SessionError::CsvValue`] when the file is missing or
    /// malformed.
    pub fn timestamps(&self, role: CameraRole) -> Result<Vec<Stamp>> {
        self.stream(role)?;
        let csv = Csv::read(&self.dir.join(role.name()).join(TIMESTAMPS_FILE), TIMESTAMPS_HEADER)?;
        csv.rows(|r| {
            Ok(Stamp {
                seq: r.u64(0)?,
                device_ns: r.u64(1)?,
                host_ns: r.u64(2)?,
            })
        })
    }

    /// The events in `events.jsonl`, in the order they were logged. A last line the writer
    /// did not finish is left out.
    ///
    /// # Errors
    /// [`SessionError::Io`] when the file is missing or can not be read;
    /// [`SessionError::Event`] for a finished line that is not a valid event.
    pub fn events(&self) -> Result<Vec<SessionEvent>> {
        let path = self.dir.join(EVENTS_FILE);
        let mut events = Vec::new();
        for (line, text) in read_lines(&path)? {
            if text.trim().is_empty() {
                continue;
            }
            let event = serde_json::from_str(&text).map_err(|source| SessionError::Event {
                path: path.clone(),
                line,
                source,
            })?;
            events.push(event);
        }
        Ok(events)
    }

    /// True when the writer finished the session (its `session_ended` event is there).
    pub fn complete(&self) -> bool {
        self.events()
            .is_ok_and(|events| events.iter().any(|e| matches!(e, SessionEvent::SessionEnded { .. })))
    }

    /// The ground truth of a synthetic session; `None` when the session has no `truth`
    /// directory.
    ///
    /// # Errors
    /// [`SessionError::Io`] when a truth file is missing or can not be read;
    /// [`SessionError::Text`] or [`SessionError::CsvValue`] when one is malformed.
    pub fn truth(&self) -> Result<Option<Truth>> {
        let dir = self.dir.join(TRUTH_DIR);
        if !dir.is_dir() {
            return Ok(None);
        }
        let path = dir.join(JOINTS_FILE);
        // One mouse's header, or several mice's with the `mouse` column after `time_ns`.
        let (csv, per_mouse) = match Csv::read(&path, &joints_header()) {
            Ok(csv) => (csv, false),
            Err(one) => match Csv::read(&path, &joints_header_for(true)) {
                Ok(csv) => (csv, true),
                Err(_) => return Err(one),
            },
        };
        let first = if per_mouse { 3 } else { 2 };
        let rows = csv.rows(|r| {
            let mut positions: JointPositions = [Point3::origin(); JOINT_COUNT];
            for (j, p) in positions.iter_mut().enumerate() {
                let at = first + 3 * j;
                *p = Point3::new(r.f64(at)?, r.f64(at + 1)?, r.f64(at + 2)?);
            }
            let mouse = if per_mouse { r.u64(2)? } else { 1 };
            Ok((mouse, (r.u64(0)?, r.u64(1)?, positions)))
        })?;
        let mut joints = Vec::new();
        let mut others: Vec<Vec<(u64, u64, JointPositions)>> = Vec::new();
        for (mouse, row) in rows {
            match mouse {
                1 => joints.push(row),
                m @ 2..=MOST_TRUE_MICE => {
                    let k = m as usize - 2;
                    if others.len() <= k {
                        others.resize_with(k + 1, Vec::new);
                    }
                    others[k].push(row);
                }
                m => {
                    return Err(SessionError::Format {
                        path,
                        reason: format!("its truth names mouse {m}: mice are numbered 1 to {MOST_TRUE_MICE}"),
                    });
                }
            }
        }
        let pairs = Csv::read(&dir.join(PAIRS_FILE), PAIRS_HEADER)?.rows(|r| Ok((r.u64(0)?, r.opt_u64(1)?)))?;
        Ok(Some(Truth { joints, pairs, others }))
    }
}

/// `session.toml` is a few kilobytes; more is not session metadata.
const MAX_META_BYTES: u64 = 1 << 20;

/// Reads and checks `session.toml`: format name and version before the rest, so a newer
/// version's file is reported as such rather than by its first unknown key.
fn read_meta(path: &Path) -> Result<SessionMeta> {
    let text = crate::io::read_bounded(path, MAX_META_BYTES).map_err(io_error(path, "read"))?;
    let table: toml::Table = toml::from_str(&text).map_err(|source| SessionError::Meta {
        path: path.to_path_buf(),
        source,
    })?;
    let format = |reason: String| SessionError::Format {
        path: path.to_path_buf(),
        reason,
    };
    match table.get("format").and_then(toml::Value::as_str) {
        Some(FORMAT_NAME) => {}
        Some(other) => {
            return Err(format(format!("not a mousepose session (format = {other:?})")));
        }
        None => return Err(format("not a mousepose session (no format key)".to_owned())),
    }
    match table.get("format_version").and_then(toml::Value::as_integer) {
        Some(v) if v == i64::from(FORMAT_VERSION) => {}
        Some(v) => return Err(format(format!("unsupported session format version {v}"))),
        None => return Err(format("no integer format_version key".to_owned())),
    }
    let meta: SessionMeta = toml::from_str(&text).map_err(|source| SessionError::Meta {
        path: path.to_path_buf(),
        source,
    })?;
    if let Some(reason) = meta.problem() {
        return Err(format(reason));
    }
    Ok(meta)
}

/// The frames of one camera read sequentially, from [`SessionReader::depth_frames`] or
/// [`SessionReader::color_frames`]. The file is opened by the first call to `next` (an error
/// opening it is the first and last item), with its own handle, so several iterations can
/// run at once.
#[derive(Debug)]
pub struct Frames<T> {
    path: PathBuf,
    kind: Kind,
    reader: Option<RecordReader>,
    failed: bool,
    decode: fn(&[u8]) -> Result<T, CodecError>,
}

/// Depth frames read sequentially.
pub type DepthFrames = Frames<DepthFrame>;
/// Colour frames read sequentially.
pub type ColorFrames = Frames<ColorFrame>;

impl<T> Frames<T> {
    fn new(path: PathBuf, kind: Kind, decode: fn(&[u8]) -> Result<T, CodecError>) -> Self {
        Self {
            path,
            kind,
            reader: None,
            failed: false,
            decode,
        }
    }

    /// What the iteration has stepped over so far: damaged records skipped and, once it has
    /// ended, the bytes of a truncated last record.
    pub fn damage(&self) -> Damage {
        self.reader.as_ref().map(|r| r.damage().clone()).unwrap_or_default()
    }
}

impl<T> Iterator for Frames<T> {
    type Item = Result<T>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let reader = match &mut self.reader {
            Some(reader) => reader,
            None => match RecordReader::open(&self.path, self.kind) {
                Ok(reader) => self.reader.insert(reader),
                Err(e) => {
                    self.failed = true;
                    return Some(Err(e.into()));
                }
            },
        };
        let record = match reader.next_record()? {
            Ok(record) => record,
            Err(e) => return Some(Err(e.into())),
        };
        Some((self.decode)(&record.payload).map_err(|source| SessionError::Frame {
            path: self.path.clone(),
            frame: FrameLocation {
                offset: record.offset,
                seq: peek_seq(&record.payload),
            },
            source,
        }))
    }
}
