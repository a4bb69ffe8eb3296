//! Reading a record file ([`RecordReader`]): sequentially, stepping over damaged records by
//! scanning for the next intact header and stopping at a truncated tail, with a report of what
//! was skipped ([`Damage`]); or one record at an offset, such as an index gives.

use super::format::{
    FILE_HEADER_LEN, FILE_MAGIC, FORMAT_VERSION, HeaderFault, Kind, RECORD_HEADER_LEN, RECORD_MAGIC, le_u32,
    parse_record_header,
};
use super::index::{IndexStatus, read_index};
use super::{Result, StoreError, io_error};
use std::fmt;
use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// How much of the file a resynchronising scan reads at a time.
const SCAN_CHUNK: usize = 64 << 10;

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
        // Asked before opening: opening a FIFO waits for a writer, a device never ends.
        if !std::fs::metadata(path).map_err(io_error(path, "open"))?.is_file() {
            return Err(StoreError::NotRecordFile {
                path: path.to_path_buf(),
            });
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::store::{RecordWriter, write_index};
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
}
