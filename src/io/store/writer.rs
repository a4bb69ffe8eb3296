//! Writing a record file ([`RecordWriter`]): the file header at creation, then each record as
//! one write of its header and payload.

use super::format::{
    FILE_HEADER_LEN, FILE_MAGIC, FORMAT_VERSION, Kind, MAX_PAYLOAD_LEN, RECORD_HEADER_LEN, record_header,
};
use super::{Result, StoreError, io_error};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

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

    /// Cuts the file back to `len` bytes (the end of a record: the records after it, and what
    /// of them is still buffered, are dropped), so that a writer that failed mid-record can
    /// close the file on its whole records.
    ///
    /// # Errors
    /// [`StoreError::Io`] when the file can not be cut.
    pub fn truncate(&mut self, len: u64) -> Result<()> {
        let file = self
            .out
            .get_ref()
            .try_clone()
            .map_err(io_error(&self.path, "truncate"))?;
        let fresh = BufWriter::with_capacity(self.out.capacity(), file);
        // Unflushed bytes are after `len`: dropped with the old buffer, never written.
        drop(std::mem::replace(&mut self.out, fresh).into_parts());
        let file = self.out.get_mut();
        file.set_len(len).map_err(io_error(&self.path, "truncate"))?;
        file.seek(std::io::SeekFrom::Start(len))
            .map_err(io_error(&self.path, "truncate"))?;
        self.position = len;
        Ok(())
    }

    /// The file's length once everything appended is flushed: the offset of the next record.
    pub fn position(&self) -> u64 {
        self.position
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether the file was removed while being written ([`crate::io::unlinked`]).
    pub fn unlinked(&self) -> bool {
        crate::io::unlinked(self.out.get_ref())
    }

    pub fn kind(&self) -> Kind {
        self.kind
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn oversized_payload_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = RecordWriter::create(dir.path().join("x"), Kind::ColorFrames).unwrap();
        let big = vec![0u8; MAX_PAYLOAD_LEN as usize + 1];
        assert!(matches!(w.append(&big), Err(StoreError::PayloadTooLarge { .. })));
        assert!(RecordWriter::create(dir.path().join("x"), Kind::ColorFrames).is_err());
    }

    #[test]
    fn truncate_cuts_back_to_a_record_end_and_drops_what_was_buffered_after_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x");
        let mut w = RecordWriter::create(&path, Kind::ColorFrames).unwrap();
        w.append(&[1; 100]).unwrap();
        w.flush().unwrap();
        let end = w.position();
        // Buffered, not flushed: gone with the cut, never written after it.
        w.append(&[2; 100]).unwrap();
        w.truncate(end).unwrap();
        w.sync().unwrap();
        drop(w);
        assert_eq!(std::fs::metadata(&path).unwrap().len(), end);
        let mut reader = crate::io::store::RecordReader::open(&path, Kind::ColorFrames).unwrap();
        let records: Vec<_> = reader.records().collect::<Result<_>>().unwrap();
        assert_eq!(records.len(), 1);
        assert_eq!(records[0].payload, vec![1; 100]);
    }
}
