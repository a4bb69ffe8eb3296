//! An append-only file of checksummed records, and the small index file that goes with it.
//!
//! Sessions keep their depth and colour frames in these files, and datasets their samples.
//! The layout is meant to survive the ways a recorder dies: every record carries its length
//! and two CRC-32s (one over its header, one over its payload), so a reader can
//!
//! - stop cleanly at a record cut short by a killed process (reported as a truncated tail),
//! - skip a record whose bytes were damaged and find the next intact one by scanning for a
//!   record header whose own checksum verifies,
//! - never trust a length before its header checksum has verified, so a damaged length can
//!   not make it allocate gigabytes.
//!
//! File layout (all integers little-endian; `docs/FORMATS.md` has the full description):
//!
//! ```text
//! file header  16 bytes  b"MPSTORE\0", u32 version (1), u32 kind (1 depth, 2 colour, 3 samples)
//! record       16 bytes  b"MPRC", u32 payload_len, u32 crc32(payload), u32 crc32(header[0..12])
//!              payload_len bytes of payload
//! ```
//!
//! The index file (`b"MPINDEX\0"`) maps a caller's key (a frame's sequence number) to a
//! record's offset. It records the length of the record file it describes, so a reader can
//! tell a stale index from a current one and fall back to scanning.

use std::fmt;
use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The first eight bytes of every record file.
pub const FILE_MAGIC: [u8; 8] = *b"MPSTORE\0";
/// The record file format this module writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// Length of the file header.
pub const FILE_HEADER_LEN: u64 = 16;
/// The first four bytes of every record header.
pub const RECORD_MAGIC: [u8; 4] = *b"MPRC";
/// Length of a record header.
pub const RECORD_HEADER_LEN: u64 = 16;
/// The largest payload a record may hold (256 MiB). Writers refuse larger payloads and
/// readers treat a header announcing one as damaged.
pub const MAX_PAYLOAD_LEN: u32 = 256 << 20;

/// The first eight bytes of every index file.
pub const INDEX_MAGIC: [u8; 8] = *b"MPINDEX\0";
/// The index file format this module writes and reads.
pub const INDEX_VERSION: u32 = 1;
/// Bytes of an index file before its entries: magic, version, count, data length.
const INDEX_HEADER_LEN: u64 = 24;
/// Bytes per index entry: key and offset.
const INDEX_ENTRY_LEN: u64 = 16;

/// How much of the file a resynchronising scan reads at a time.
const SCAN_CHUNK: usize = 64 << 10;

/// Errors of record and index files. Every variant names the file at fault.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("cannot {action} {}", path.display())]
    Io {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: io::Error,
    },
    #[error("{}: not a mousepose record file", path.display())]
    NotRecordFile { path: PathBuf },
    #[error("{}: unsupported version {version}", path.display())]
    UnsupportedVersion { path: PathBuf, version: u32 },
    #[error("{}: unknown record file kind {code}", path.display())]
    UnknownKind { path: PathBuf, code: u32 },
    #[error("{}: holds {found}, expected {expected}", path.display())]
    WrongKind { path: PathBuf, found: Kind, expected: Kind },
    #[error("{}: record at offset {offset}: {reason}", path.display())]
    Corrupt { path: PathBuf, offset: u64, reason: String },
    #[error("{}: payload of {len} bytes exceeds the {MAX_PAYLOAD_LEN} byte limit", path.display())]
    PayloadTooLarge { path: PathBuf, len: usize },
    #[error("{}: an earlier write failed, the writer accepts no more records", path.display())]
    WriterFailed { path: PathBuf },
    #[error("{}: invalid index: {reason}", path.display())]
    InvalidIndex { path: PathBuf, reason: String },
}

type Result<T, E = StoreError> = std::result::Result<T, E>;

fn io_error<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(io::Error) -> StoreError + 'a {
    move |source| StoreError::Io {
        path: path.to_path_buf(),
        action,
        source,
    }
}

/// What a record file holds; stored in its header so a file can not be read as the wrong kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    DepthFrames,
    ColorFrames,
    DatasetSamples,
}

impl Kind {
    /// The code stored in the file header.
    pub fn code(self) -> u32 {
        match self {
            Kind::DepthFrames => 1,
            Kind::ColorFrames => 2,
            Kind::DatasetSamples => 3,
        }
    }

    /// The kind with a header code, if there is one.
    pub fn from_code(code: u32) -> Option<Kind> {
        match code {
            1 => Some(Kind::DepthFrames),
            2 => Some(Kind::ColorFrames),
            3 => Some(Kind::DatasetSamples),
            _ => None,
        }
    }

    /// What the records are, in words: `depth frames`, `colour frames`, `dataset samples`.
    pub fn describe(self) -> &'static str {
        match self {
            Kind::DepthFrames => "depth frames",
            Kind::ColorFrames => "colour frames",
            Kind::DatasetSamples => "dataset samples",
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.describe())
    }
}

/// The 16-byte header of a record with this payload.
fn record_header(payload: &[u8], payload_len: u32) -> [u8; 16] {
    let mut header = [0u8; 16];
    header[0..4].copy_from_slice(&RECORD_MAGIC);
    header[4..8].copy_from_slice(&payload_len.to_le_bytes());
    header[8..12].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
    let header_crc = crc32fast::hash(&header[0..12]);
    header[12..16].copy_from_slice(&header_crc.to_le_bytes());
    header
}

fn le_u32(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    if let Some(s) = bytes.get(at..at + 4) {
        b.copy_from_slice(s);
    }
    u32::from_le_bytes(b)
}

fn le_u64(bytes: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    if let Some(s) = bytes.get(at..at + 8) {
        b.copy_from_slice(s);
    }
    u64::from_le_bytes(b)
}

/// What is wrong with a record header.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HeaderFault {
    /// The bytes do not start with `MPRC`.
    BadMagic,
    /// The header's own CRC does not match.
    BadHeaderCrc,
    /// The checksummed length is above [`MAX_PAYLOAD_LEN`].
    LengthOverLimit,
}

impl fmt::Display for HeaderFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            HeaderFault::BadMagic => "no record header magic",
            HeaderFault::BadHeaderCrc => "record header checksum mismatch",
            HeaderFault::LengthOverLimit => "payload length above the limit",
        })
    }
}

/// The payload length and payload CRC of a record header, once its own checksum verifies.
fn parse_record_header(header: &[u8]) -> std::result::Result<(u32, u32), HeaderFault> {
    if header.get(0..4) != Some(&RECORD_MAGIC[..]) {
        return Err(HeaderFault::BadMagic);
    }
    let stored = le_u32(header, 12);
    let computed = header.get(0..12).map(crc32fast::hash);
    if computed != Some(stored) {
        return Err(HeaderFault::BadHeaderCrc);
    }
    let len = le_u32(header, 4);
    if len > MAX_PAYLOAD_LEN {
        return Err(HeaderFault::LengthOverLimit);
    }
    Ok((len, le_u32(header, 8)))
}

/// Writes a record file: the file header at creation, then one record per [`append`].
///
/// Each record goes out as a single `write_all` of header and payload; [`flush`] hands the
/// buffered bytes to the operating system (cheap enough to call after every frame) so a
/// killed process leaves every flushed record readable, and [`sync`] also waits for the disk.
///
/// [`append`]: RecordWriter::append
/// [`flush`]: RecordWriter::flush
/// [`sync`]: RecordWriter::sync
#[derive(Debug)]
pub struct RecordWriter {
    path: PathBuf,
    kind: Kind,
    out: BufWriter<File>,
    /// Bytes written so far, headers included: the offset of the next record.
    position: u64,
    /// Header and payload of the record being written, reused between records.
    scratch: Vec<u8>,
    failed: bool,
}

impl RecordWriter {
    /// Creates a new record file (it must not exist yet) and writes its header.
    ///
    /// # Errors
    /// [`StoreError::Io`] when the file exists already or can not be created or written.
    pub fn create(path: impl AsRef<Path>, kind: Kind) -> Result<Self> {
        let path = path.as_ref();
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)
            .map_err(io_error(path, "create"))?;
        let mut out = BufWriter::with_capacity(256 << 10, file);
        let mut header = [0u8; 16];
        header[0..8].copy_from_slice(&FILE_MAGIC);
        header[8..12].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
        header[12..16].copy_from_slice(&kind.code().to_le_bytes());
        out.write_all(&header).map_err(io_error(path, "write"))?;
        out.flush().map_err(io_error(path, "write"))?;
        Ok(Self {
            path: path.to_path_buf(),
            kind,
            out,
            position: FILE_HEADER_LEN,
            scratch: Vec::new(),
            failed: false,
        })
    }

    /// Appends one record and returns its offset (where its header starts).
    ///
    /// # Errors
    /// [`StoreError::PayloadTooLarge`] above [`MAX_PAYLOAD_LEN`]; [`StoreError::Io`] when
    /// writing fails, after which the writer refuses further records
    /// ([`StoreError::WriterFailed`]) since the file's end is no longer known.
    pub fn append(&mut self, payload: &[u8]) -> Result<u64> {
        if self.failed {
            return Err(StoreError::WriterFailed {
                path: self.path.clone(),
            });
        }
        let len = u32::try_from(payload.len())
            .ok()
            .filter(|&len| len <= MAX_PAYLOAD_LEN)
            .ok_or_else(|| StoreError::PayloadTooLarge {
                path: self.path.clone(),
                len: payload.len(),
            })?;
        self.scratch.clear();
        self.scratch.extend_from_slice(&record_header(payload, len));
        self.scratch.extend_from_slice(payload);
        if let Err(source) = self.out.write_all(&self.scratch) {
            self.failed = true;
            return Err(StoreError::Io {
                path: self.path.clone(),
                action: "write",
                source,
            });
        }
        let offset = self.position;
        self.position += RECORD_HEADER_LEN + u64::from(len);
        Ok(offset)
    }

    /// Hands buffered records to the operating system (no disk sync).
    ///
    /// # Errors
    /// [`StoreError::Io`] when writing fails.
    pub fn flush(&mut self) -> Result<()> {
        if let Err(source) = self.out.flush() {
            self.failed = true;
            return Err(StoreError::Io {
                path: self.path.clone(),
                action: "write",
                source,
            });
        }
        Ok(())
    }

    /// Flushes and waits until the file's data is on disk.
    ///
    /// # Errors
    /// [`StoreError::Io`] when writing or syncing fails.
    pub fn sync(&mut self) -> Result<()> {
        self.flush()?;
        self.out.get_ref().sync_all().map_err(io_error(&self.path, "sync"))
    }

    /// The file's length once everything appended is flushed: the offset of the next record.
    pub fn position(&self) -> u64 {
        self.position
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn kind(&self) -> Kind {
        self.kind
    }
}

/// One intact record: where its header starts and its payload.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Record {
    pub offset: u64,
    pub payload: Vec<u8>,
}

/// Why a reader skipped bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SkipReason {
    /// The bytes at this offset are not an intact record header.
    Header(HeaderFault),
    /// The header verified but the payload's CRC does not match.
    PayloadCrc,
}

impl fmt::Display for SkipReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SkipReason::Header(fault) => fault.fmt(f),
            SkipReason::PayloadCrc => f.write_str("payload checksum mismatch"),
        }
    }
}

/// A damaged stretch of a record file that a reader stepped over.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Skipped {
    /// Where the damaged stretch starts.
    pub offset: u64,
    /// How many bytes were skipped (up to the next intact record header or the file's end).
    pub len: u64,
    pub reason: SkipReason,
}

/// What a sequential read found wrong with a record file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Damage {
    /// Damaged records stepped over, in file order.
    pub skipped: Vec<Skipped>,
    /// Bytes at the end of the file that hold an incomplete record (what a writer killed
    /// mid-record leaves); 0 when the file ends on a record boundary.
    pub truncated_tail_bytes: u64,
}

impl Damage {
    /// True when nothing was skipped and nothing was truncated.
    pub fn is_clean(&self) -> bool {
        self.skipped.is_empty() && self.truncated_tail_bytes == 0
    }

    /// Number of damaged records stepped over.
    pub fn skipped_records(&self) -> u64 {
        self.skipped.len() as u64
    }

    /// Number of bytes stepped over in damaged records (the truncated tail not included).
    pub fn skipped_bytes(&self) -> u64 {
        self.skipped.iter().map(|s| s.len).sum()
    }
}

/// Reads a record file: sequentially with [`next_record`] (or [`records`]), which steps over
/// damage and stops at a truncated tail, or one record at a time with [`read_at`].
///
/// The file's length is taken when it is opened; bytes appended later are not seen.
///
/// [`next_record`]: RecordReader::next_record
/// [`records`]: RecordReader::records
/// [`read_at`]: RecordReader::read_at
#[derive(Debug)]
pub struct RecordReader {
    path: PathBuf,
    file: File,
    kind: Kind,
    len: u64,
    /// Offset of the next record a sequential read looks at.
    pos: u64,
    done: bool,
    damage: Damage,
    /// Reused by resynchronising scans.
    scan_buf: Vec<u8>,
}

impl RecordReader {
    /// Opens a record file and checks that it holds records of the `expected` kind.
    ///
    /// # Errors
    /// [`StoreError::Io`] when the file can not be opened or read;
    /// [`StoreError::NotRecordFile`], [`StoreError::UnsupportedVersion`],
    /// [`StoreError::UnknownKind`] or [`StoreError::WrongKind`] when its header is not that of a
    /// version 1 record file of the expected kind.
    pub fn open(path: impl AsRef<Path>, expected: Kind) -> Result<Self> {
        let path = path.as_ref();
        let mut file = File::open(path).map_err(io_error(path, "open"))?;
        let len = file.metadata().map_err(io_error(path, "read"))?.len();
        let mut header = [0u8; 16];
        if len < FILE_HEADER_LEN {
            return Err(StoreError::NotRecordFile {
                path: path.to_path_buf(),
            });
        }
        file.read_exact(&mut header).map_err(io_error(path, "read"))?;
        if header[0..8] != FILE_MAGIC {
            return Err(StoreError::NotRecordFile {
                path: path.to_path_buf(),
            });
        }
        let version = le_u32(&header, 8);
        if version != FORMAT_VERSION {
            return Err(StoreError::UnsupportedVersion {
                path: path.to_path_buf(),
                version,
            });
        }
        let code = le_u32(&header, 12);
        let kind = Kind::from_code(code).ok_or_else(|| StoreError::UnknownKind {
            path: path.to_path_buf(),
            code,
        })?;
        if kind != expected {
            return Err(StoreError::WrongKind {
                path: path.to_path_buf(),
                found: kind,
                expected,
            });
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            kind,
            len,
            pos: FILE_HEADER_LEN,
            done: false,
            damage: Damage::default(),
            scan_buf: Vec::new(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// The file's length when it was opened.
    pub fn file_len(&self) -> u64 {
        self.len
    }

    /// What the sequential read so far has stepped over; complete once it has ended.
    pub fn damage(&self) -> &Damage {
        &self.damage
    }

    /// Damaged records the sequential read so far has stepped over.
    pub fn skipped_records(&self) -> u64 {
        self.damage.skipped_records()
    }

    /// Bytes of an incomplete last record, known once the sequential read has ended.
    pub fn tail(&self) -> u64 {
        self.damage.truncated_tail_bytes
    }

    /// Starts the sequential read over from the first record and forgets its damage report.
    pub fn rewind(&mut self) {
        self.pos = FILE_HEADER_LEN;
        self.done = false;
        self.damage = Damage::default();
    }

    /// The records from the first one on (the sequential read starts over).
    pub fn records(&mut self) -> Records<'_> {
        self.rewind();
        Records { reader: self }
    }

    fn read_exact_at(&mut self, offset: u64, buf: &mut [u8]) -> io::Result<()> {
        self.file.seek(SeekFrom::Start(offset))?;
        self.file.read_exact(buf)
    }

    /// The next intact record of the sequential read; `None` at the end of the file or at a
    /// truncated tail. Damaged records are stepped over and counted in [`damage`].
    ///
    /// # Errors
    /// [`StoreError::Io`] when reading fails; the sequential read ends after it.
    ///
    /// [`damage`]: RecordReader::damage
    pub fn next_record(&mut self) -> Option<Result<Record>> {
        match self.advance() {
            Ok(record) => record.map(Ok),
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }

    fn advance(&mut self) -> Result<Option<Record>> {
        while !self.done {
            let pos = self.pos;
            let remaining = self.len.saturating_sub(pos);
            if remaining == 0 {
                self.done = true;
                break;
            }
            if remaining < RECORD_HEADER_LEN {
                self.damage.truncated_tail_bytes = remaining;
                self.done = true;
                break;
            }
            let mut header = [0u8; 16];
            self.read_exact_at(pos, &mut header)
                .map_err(io_error(&self.path, "read"))?;
            match parse_record_header(&header) {
                Ok((payload_len, payload_crc)) => {
                    let record_len = RECORD_HEADER_LEN + u64::from(payload_len);
                    if record_len > remaining {
                        self.damage.truncated_tail_bytes = remaining;
                        self.done = true;
                        break;
                    }
                    // The length is checksummed, capped and within the file: safe to allocate.
                    let mut payload = vec![0u8; payload_len as usize];
                    self.read_exact_at(pos + RECORD_HEADER_LEN, &mut payload)
                        .map_err(io_error(&self.path, "read"))?;
                    self.pos = pos + record_len;
                    if crc32fast::hash(&payload) == payload_crc {
                        return Ok(Some(Record { offset: pos, payload }));
                    }
                    self.damage.skipped.push(Skipped {
                        offset: pos,
                        len: record_len,
                        reason: SkipReason::PayloadCrc,
                    });
                }
                Err(fault) => {
                    let next = self.find_header(pos + 1)?;
                    let end = next.unwrap_or(self.len);
                    self.damage.skipped.push(Skipped {
                        offset: pos,
                        len: end - pos,
                        reason: SkipReason::Header(fault),
                    });
                    self.pos = end;
                }
            }
        }
        Ok(None)
    }

    /// The offset of the first intact record header at or after `from`, if any.
    fn find_header(&mut self, from: u64) -> Result<Option<u64>> {
        let header_len = RECORD_HEADER_LEN as usize;
        let mut start = from;
        let mut buf = std::mem::take(&mut self.scan_buf);
        let found = loop {
            if start.saturating_add(RECORD_HEADER_LEN) > self.len {
                break None;
            }
            let n = usize::try_from(self.len - start).map_or(SCAN_CHUNK, |left| left.min(SCAN_CHUNK));
            buf.resize(n, 0);
            if let Err(e) = self.read_exact_at(start, &mut buf) {
                self.scan_buf = buf;
                return Err(StoreError::Io {
                    path: self.path.clone(),
                    action: "read",
                    source: e,
                });
            }
            let hit = buf
                .windows(header_len)
                .position(|w| w.starts_with(&RECORD_MAGIC) && parse_record_header(w).is_ok());
            if let Some(i) = hit {
                break Some(start + i as u64);
            }
            if start + n as u64 >= self.len {
                break None;
            }
            // Overlap by a header's length less one so a header across the boundary is seen.
            start += (n - (header_len - 1)) as u64;
        };
        self.scan_buf = buf;
        Ok(found)
    }

    /// The payload of the record whose header starts at `offset`, checked like a sequential
    /// read checks it.
    ///
    /// # Errors
    /// [`StoreError::Corrupt`] when there is no intact record at `offset` (outside the file,
    /// bad header, cut short, payload checksum mismatch); [`StoreError::Io`] when reading fails.
    pub fn read_at(&mut self, offset: u64) -> Result<Vec<u8>> {
        let path = self.path.clone();
        let corrupt = move |reason: String| StoreError::Corrupt {
            path: path.clone(),
            offset,
            reason,
        };
        if offset < FILE_HEADER_LEN || offset.saturating_add(RECORD_HEADER_LEN) > self.len {
            return Err(corrupt(format!("no record header there (file is {} bytes)", self.len)));
        }
        let mut header = [0u8; 16];
        self.read_exact_at(offset, &mut header)
            .map_err(io_error(&self.path, "read"))?;
        let (payload_len, payload_crc) = parse_record_header(&header).map_err(|fault| corrupt(fault.to_string()))?;
        let end = offset + RECORD_HEADER_LEN + u64::from(payload_len);
        if end > self.len {
            return Err(corrupt(format!(
                "record of {payload_len} payload bytes runs past the end of the file"
            )));
        }
        let mut payload = vec![0u8; payload_len as usize];
        self.read_exact_at(offset + RECORD_HEADER_LEN, &mut payload)
            .map_err(io_error(&self.path, "read"))?;
        if crc32fast::hash(&payload) != payload_crc {
            return Err(corrupt(SkipReason::PayloadCrc.to_string()));
        }
        Ok(payload)
    }

    /// Loads the index at `index_path` if it is valid and describes this file as it is now;
    /// otherwise builds it by reading every record, with `key` giving each payload's key
    /// (records for which it returns `None` are left out).
    ///
    /// After a rebuild, [`damage`] reports what the scan stepped over.
    ///
    /// # Errors
    /// [`StoreError::Io`] when the record file can not be read. A missing, invalid or stale
    /// index is not an error: it is reported in the returned [`IndexStatus`].
    ///
    /// [`damage`]: RecordReader::damage
    pub fn load_index(
        &mut self,
        index_path: impl AsRef<Path>,
        mut key: impl FnMut(&[u8]) -> Option<u64>,
    ) -> Result<(Vec<(u64, u64)>, IndexStatus)> {
        let index_path = index_path.as_ref();
        let status = match read_index(index_path) {
            Ok(index) if index.data_len == self.len => {
                return Ok((index.entries, IndexStatus::Loaded));
            }
            Ok(index) => IndexStatus::Stale {
                index_data_len: index.data_len,
                file_len: self.len,
            },
            Err(StoreError::Io { source, .. }) if source.kind() == io::ErrorKind::NotFound => IndexStatus::Missing,
            Err(e) => IndexStatus::Invalid(e),
        };
        let mut entries = Vec::new();
        for record in self.records() {
            let record = record?;
            if let Some(k) = key(&record.payload) {
                entries.push((k, record.offset));
            }
        }
        Ok((entries, status))
    }
}

/// The records of a [`RecordReader`], from [`RecordReader::records`].
#[derive(Debug)]
pub struct Records<'a> {
    reader: &'a mut RecordReader,
}

impl Records<'_> {
    /// What the read has stepped over so far.
    pub fn damage(&self) -> &Damage {
        self.reader.damage()
    }
}

impl Iterator for Records<'_> {
    type Item = Result<Record>;

    fn next(&mut self) -> Option<Self::Item> {
        self.reader.next_record()
    }
}

/// How a reader came by its index.
#[derive(Debug)]
pub enum IndexStatus {
    /// Read from the index file.
    Loaded,
    /// There was no index file; rebuilt by scanning.
    Missing,
    /// The index file described a record file of another length; rebuilt by scanning.
    Stale { index_data_len: u64, file_len: u64 },
    /// The index file could not be used; rebuilt by scanning.
    Invalid(StoreError),
}

impl IndexStatus {
    /// True when the index was rebuilt by scanning the record file.
    pub fn rebuilt(&self) -> bool {
        !matches!(self, IndexStatus::Loaded)
    }
}

/// The contents of an index file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Index {
    /// Length of the record file when the index was written.
    pub data_len: u64,
    /// `(key, record offset)` pairs in the order they were written.
    pub entries: Vec<(u64, u64)>,
}

/// Writes an index file for a record file of `data_len` bytes, replacing any older one, and
/// syncs it to disk.
///
/// # Errors
/// [`StoreError::Io`] when the file can not be written; [`StoreError::InvalidIndex`] when there
/// are more than `u32::MAX` entries.
pub fn write_index(path: impl AsRef<Path>, data_len: u64, entries: &[(u64, u64)]) -> Result<()> {
    let path = path.as_ref();
    let count = u32::try_from(entries.len()).map_err(|_| StoreError::InvalidIndex {
        path: path.to_path_buf(),
        reason: format!("{} entries do not fit the format", entries.len()),
    })?;
    let mut bytes = Vec::with_capacity(INDEX_HEADER_LEN as usize + entries.len() * INDEX_ENTRY_LEN as usize + 4);
    bytes.extend_from_slice(&INDEX_MAGIC);
    bytes.extend_from_slice(&INDEX_VERSION.to_le_bytes());
    bytes.extend_from_slice(&count.to_le_bytes());
    bytes.extend_from_slice(&data_len.to_le_bytes());
    for &(key, offset) in entries {
        bytes.extend_from_slice(&key.to_le_bytes());
        bytes.extend_from_slice(&offset.to_le_bytes());
    }
    let crc = crc32fast::hash(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());
    let mut file = File::create(path).map_err(io_error(path, "create"))?;
    file.write_all(&bytes).map_err(io_error(path, "write"))?;
    file.sync_all().map_err(io_error(path, "sync"))
}

/// Reads and checks an index file.
///
/// # Errors
/// [`StoreError::Io`] when it can not be read (`NotFound` when it is missing);
/// [`StoreError::InvalidIndex`] when its magic, version, length or checksum is wrong.
pub fn read_index(path: impl AsRef<Path>) -> Result<Index> {
    let path = path.as_ref();
    let invalid = |reason: &str| StoreError::InvalidIndex {
        path: path.to_path_buf(),
        reason: reason.to_owned(),
    };
    let mut file = File::open(path).map_err(io_error(path, "open"))?;
    let file_len = file.metadata().map_err(io_error(path, "read"))?.len();
    let mut header = [0u8; INDEX_HEADER_LEN as usize];
    if file_len < INDEX_HEADER_LEN + 4 {
        return Err(invalid("too short"));
    }
    file.read_exact(&mut header).map_err(io_error(path, "read"))?;
    if header[0..8] != INDEX_MAGIC {
        return Err(invalid("not a mousepose index file"));
    }
    let version = le_u32(&header, 8);
    if version != INDEX_VERSION {
        return Err(invalid(&format!("unsupported version {version}")));
    }
    let count = u64::from(le_u32(&header, 12));
    let data_len = le_u64(&header, 16);
    // Check the length before allocating: the count is not trusted until the CRC verifies.
    if file_len != INDEX_HEADER_LEN + count * INDEX_ENTRY_LEN + 4 {
        return Err(invalid(&format!(
            "{count} entries do not match the file length {file_len}"
        )));
    }
    let mut rest = vec![0u8; (file_len - INDEX_HEADER_LEN) as usize];
    file.read_exact(&mut rest).map_err(io_error(path, "read"))?;
    let (body, crc) = rest.split_at(rest.len() - 4);
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(&header);
    hasher.update(body);
    if hasher.finalize() != le_u32(crc, 0) {
        return Err(invalid("checksum mismatch"));
    }
    let entries = body
        .chunks_exact(INDEX_ENTRY_LEN as usize)
        .map(|pair| (le_u64(pair, 0), le_u64(pair, 8)))
        .collect();
    Ok(Index { data_len, entries })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    fn payload(i: usize, len: usize) -> Vec<u8> {
        (0..len).map(|j| (i * 31 + j * 7) as u8).collect()
    }

    fn write_file(dir: &Path, lens: &[usize]) -> (PathBuf, Vec<u64>) {
        let path = dir.join("r.mpstore");
        let mut w = RecordWriter::create(&path, Kind::DepthFrames).unwrap();
        let offsets = lens
            .iter()
            .enumerate()
            .map(|(i, &len)| w.append(&payload(i, len)).unwrap())
            .collect();
        w.sync().unwrap();
        (path, offsets)
    }

    fn read_all(path: &Path) -> (Vec<Record>, Damage) {
        let mut r = RecordReader::open(path, Kind::DepthFrames).unwrap();
        let records = r.records().collect::<Result<Vec<_>>>().unwrap();
        (records, r.damage().clone())
    }

    #[test]
    fn round_trip_and_random_access() {
        let dir = tempfile::tempdir().unwrap();
        let lens = [0, 1, 100, 70_000, 5];
        let (path, offsets) = write_file(dir.path(), &lens);
        let (records, damage) = read_all(&path);
        assert!(damage.is_clean());
        assert_eq!(records.len(), lens.len());
        for (i, r) in records.iter().enumerate() {
            assert_eq!(r.payload, payload(i, lens[i]));
            assert_eq!(r.offset, offsets[i]);
        }
        let mut r = RecordReader::open(&path, Kind::DepthFrames).unwrap();
        assert_eq!(r.read_at(offsets[3]).unwrap(), payload(3, lens[3]));
        assert!(matches!(r.read_at(offsets[3] + 1), Err(StoreError::Corrupt { .. })));
        assert!(matches!(r.read_at(1 << 40), Err(StoreError::Corrupt { .. })));
    }

    #[test]
    fn header_checks() {
        let dir = tempfile::tempdir().unwrap();
        let (path, _) = write_file(dir.path(), &[3]);
        let err = RecordReader::open(&path, Kind::DatasetSamples).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("{}: holds depth frames, expected dataset samples", path.display())
        );
        let mut bytes = fs::read(&path).unwrap();
        bytes[8] = 7;
        fs::write(&path, &bytes).unwrap();
        let err = RecordReader::open(&path, Kind::DepthFrames).unwrap_err();
        assert!(err.to_string().ends_with("unsupported version 7"), "{err}");
        fs::write(&path, b"hello").unwrap();
        let err = RecordReader::open(&path, Kind::DepthFrames).unwrap_err();
        assert!(err.to_string().ends_with("not a mousepose record file"), "{err}");
    }

    #[test]
    fn truncation_at_every_length_never_fails() {
        let dir = tempfile::tempdir().unwrap();
        let lens = [10, 20, 30];
        let (path, offsets) = write_file(dir.path(), &lens);
        let full = fs::read(&path).unwrap();
        let cut = dir.path().join("cut.mpstore");
        for n in FILE_HEADER_LEN as usize..=full.len() {
            fs::write(&cut, &full[..n]).unwrap();
            let (records, damage) = read_all(&cut);
            let complete = offsets
                .iter()
                .zip(lens)
                .filter(|&(&o, l)| o as usize + 16 + l <= n)
                .count();
            assert_eq!(records.len(), complete, "cut at {n}");
            assert!(damage.skipped.is_empty(), "cut at {n}");
            let boundary = offsets.get(complete).map_or(full.len(), |&o| o as usize);
            assert_eq!(damage.truncated_tail_bytes as usize, n - boundary.min(n), "cut at {n}");
        }
    }

    #[test]
    fn every_single_byte_flip_is_survived() {
        let dir = tempfile::tempdir().unwrap();
        let lens = [10, 20, 30, 40];
        let (path, _) = write_file(dir.path(), &lens);
        let full = fs::read(&path).unwrap();
        let bad = dir.path().join("bad.mpstore");
        for i in FILE_HEADER_LEN as usize..full.len() {
            let mut bytes = full.clone();
            bytes[i] ^= 0x5a;
            fs::write(&bad, &bytes).unwrap();
            let (records, damage) = read_all(&bad);
            assert_eq!(records.len(), lens.len() - 1, "flip at {i}");
            assert_eq!(damage.skipped_records(), 1, "flip at {i}");
            for r in &records {
                assert!(lens.iter().enumerate().any(|(k, &l)| r.payload == payload(k, l)));
            }
        }
    }

    #[test]
    fn huge_length_in_a_damaged_header_is_not_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let (path, offsets) = write_file(dir.path(), &[10, 20, 30]);
        let mut bytes = fs::read(&path).unwrap();
        let at = offsets[1] as usize + 4;
        bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        fs::write(&path, &bytes).unwrap();
        let (records, damage) = read_all(&path);
        assert_eq!(records.len(), 2);
        assert_eq!(damage.skipped[0].reason, SkipReason::Header(HeaderFault::BadHeaderCrc));
        assert_eq!(damage.skipped[0].len, 16 + 20);
    }

    #[test]
    fn garbage_between_records_is_skipped_once() {
        let dir = tempfile::tempdir().unwrap();
        let (path, offsets) = write_file(dir.path(), &[10, 20]);
        let mut bytes = fs::read(&path).unwrap();
        let garbage: Vec<u8> = (0..100_000u32)
            .flat_map(|i| if i % 3 == 0 { *b"MPRC" } else { i.to_le_bytes() })
            .collect();
        let at = offsets[1] as usize;
        bytes.splice(at..at, garbage.iter().copied());
        fs::write(&path, &bytes).unwrap();
        let (records, damage) = read_all(&path);
        assert_eq!(records.len(), 2);
        assert_eq!(damage.skipped_records(), 1);
        assert_eq!(damage.skipped_bytes(), garbage.len() as u64);
    }

    #[test]
    fn index_round_trip_and_rejection() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("i.mpindex");
        let entries = vec![(5, 16), (6, 100), (9, 1000)];
        write_index(&path, 1234, &entries).unwrap();
        assert_eq!(
            read_index(&path).unwrap(),
            Index {
                data_len: 1234,
                entries: entries.clone()
            }
        );
        let mut bytes = fs::read(&path).unwrap();
        bytes[30] ^= 1;
        fs::write(&path, &bytes).unwrap();
        assert!(matches!(read_index(&path), Err(StoreError::InvalidIndex { .. })));
        bytes[12] = 200;
        fs::write(&path, &bytes).unwrap();
        assert!(matches!(read_index(&path), Err(StoreError::InvalidIndex { .. })));
        write_index(&path, 0, &[]).unwrap();
        assert!(read_index(&path).unwrap().entries.is_empty());
    }

    #[test]
    fn load_index_uses_or_rebuilds() {
        let dir = tempfile::tempdir().unwrap();
        let (path, offsets) = write_file(dir.path(), &[10, 20, 30]);
        let index_path = dir.path().join("r.mpindex");
        let key = |p: &[u8]| p.first().map(|&b| u64::from(b));
        let mut r = RecordReader::open(&path, Kind::DepthFrames).unwrap();
        let (rebuilt, status) = r.load_index(&index_path, key).unwrap();
        assert!(matches!(status, IndexStatus::Missing));
        assert_eq!(rebuilt.iter().map(|e| e.1).collect::<Vec<_>>(), offsets);
        write_index(&index_path, r.file_len(), &rebuilt).unwrap();
        let (loaded, status) = r.load_index(&index_path, key).unwrap();
        assert!(matches!(status, IndexStatus::Loaded));
        assert_eq!(loaded, rebuilt);
        write_index(&index_path, r.file_len() - 1, &rebuilt[..1]).unwrap();
        let (again, status) = r.load_index(&index_path, key).unwrap();
        assert!(matches!(status, IndexStatus::Stale { .. }));
        assert_eq!(again, rebuilt);
    }

    #[test]
    fn oversized_payload_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = RecordWriter::create(dir.path().join("x"), Kind::ColorFrames).unwrap();
        let big = vec![0u8; MAX_PAYLOAD_LEN as usize + 1];
        assert!(matches!(w.append(&big), Err(StoreError::PayloadTooLarge { .. })));
        assert!(RecordWriter::create(dir.path().join("x"), Kind::ColorFrames).is_err());
    }
}
