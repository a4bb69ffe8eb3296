//! The index file that goes with a record file: a caller's keys mapped to record offsets,
//! with the length of the record file it describes so that a stale index is recognised.

use super::format::{le_u32, le_u64};
use super::{Result, StoreError, io_error};
use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;

/// The first eight bytes of every index file.
pub const INDEX_MAGIC: [u8; 8] = *b"MPINDEX\0";
/// The index file format this module writes and reads.
pub const INDEX_VERSION: u32 = 1;
/// Bytes of an index file before its entries: magic, version, count, data length.
const INDEX_HEADER_LEN: u64 = 24;
/// Bytes per index entry: key and offset.
const INDEX_ENTRY_LEN: u64 = 16;

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
    // Asked before opening: opening a FIFO waits for a writer, a device never ends.
    if !std::fs::metadata(path).map_err(io_error(path, "open"))?.is_file() {
        return Err(invalid("not a regular file"));
    }
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
}
