//! The layout of a record file: its constants, the kinds of file ([`Kind`]), and the 16-byte
//! record header, made for a payload and checked when read back ([`HeaderFault`]).

use std::fmt;

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
pub(super) fn record_header(payload: &[u8], payload_len: u32) -> [u8; 16] {
    let mut header = [0u8; 16];
    header[0..4].copy_from_slice(&RECORD_MAGIC);
    header[4..8].copy_from_slice(&payload_len.to_le_bytes());
    header[8..12].copy_from_slice(&crc32fast::hash(payload).to_le_bytes());
    let header_crc = crc32fast::hash(&header[0..12]);
    header[12..16].copy_from_slice(&header_crc.to_le_bytes());
    header
}

pub(super) fn le_u32(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    if let Some(s) = bytes.get(at..at + 4) {
        b.copy_from_slice(s);
    }
    u32::from_le_bytes(b)
}

pub(super) fn le_u64(bytes: &[u8], at: usize) -> u64 {
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
pub(super) fn parse_record_header(header: &[u8]) -> Result<(u32, u32), HeaderFault> {
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
