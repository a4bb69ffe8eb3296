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
//!
//! The parts, one job a file: `format` (the layout's constants, the kinds of record file and
//! the record header), `writer` ([`RecordWriter`]), `reader` ([`RecordReader`]: sequential
//! reads that step over damage and resynchronise, and reads at an offset) and `index` (the
//! index file).

mod format;
mod index;
mod reader;
mod writer;

pub use format::{
    FILE_HEADER_LEN, FILE_MAGIC, FORMAT_VERSION, HeaderFault, Kind, MAX_PAYLOAD_LEN, RECORD_HEADER_LEN, RECORD_MAGIC,
};
pub use index::{INDEX_MAGIC, INDEX_VERSION, Index, IndexStatus, read_index, write_index};
pub use reader::{Damage, Record, RecordReader, Records, SkipReason, Skipped};
pub use writer::RecordWriter;

use std::io;
use std::path::{Path, PathBuf};

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
