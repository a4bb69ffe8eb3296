//! File formats: the append-only record store, session directories (what `record` and `run`
//! write and `replay` reads), output directories staged and renamed into place, videos
//! encoded by ffmpeg, masks drawn as PNG images, and CSV tables (`table`).

pub mod mask;
pub mod output;
pub mod paw_labels;
pub mod session;
pub mod store;
pub mod table;
pub mod video;

use std::io::{self, Read as _};
use std::path::Path;

/// Little-endian 16-bit samples (depth) from their bytes; an odd last byte is left out. A
/// plain loop over a buffer of the right size, which the compiler turns into vector code (an
/// iterator collected runs a sample at a time: 5 % of a MoSeq replay).
pub fn u16_samples(bytes: &[u8]) -> Vec<u16> {
    let mut samples = vec![0u16; bytes.len() / 2];
    for (v, b) in samples.iter_mut().zip(bytes.chunks_exact(2)) {
        *v = u16::from_le_bytes([b[0], b[1]]);
    }
    samples
}

/// What became of a file being written that is no longer where it was written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gone {
    /// No name is left: what is written to it is lost when it is closed.
    Removed,
    /// It still has a name, but not the one it was created under (its directory, or one
    /// above it, renamed away): what is written to it goes where it was moved.
    Moved,
}

impl Gone {
    /// The reason's label in counters and reports (`removed`, `moved`).
    pub fn reason(self) -> &'static str {
        match self {
            Self::Removed => "removed",
            Self::Moved => "moved",
        }
    }
}

/// Whether `file`, open for writing and created as `path`, is gone from there: removed
/// ([`unlinked`]), or moved away (`path` names another file, or none). A file whose state
/// cannot be read, or a `path` that cannot be looked up for another reason than its absence,
/// counts as still there.
pub fn gone(file: &std::fs::File, path: &Path) -> Option<Gone> {
    use std::os::unix::fs::MetadataExt as _;
    let open = file.metadata().ok()?;
    if open.nlink() == 0 {
        return Some(Gone::Removed);
    }
    match std::fs::metadata(path) {
        Ok(named) if named.dev() == open.dev() && named.ino() == open.ino() => None,
        Ok(_) => Some(Gone::Moved),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Some(Gone::Moved),
        Err(_) => None,
    }
}

/// Whether `file`, open for writing, was removed from the file system (no name is left: what
/// is written to it is lost when it is closed). A file whose state cannot be read counts as
/// still there.
pub fn unlinked(file: &std::fs::File) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    file.metadata().is_ok_and(|m| m.nlink() == 0)
}

/// The bytes of a regular file of at most `max` bytes: a device (`/dev/zero`), a FIFO or a
/// directory is refused before anything is read (opening a FIFO waits for a writer, a device
/// never ends), and a larger file after `max` bytes. Every reader of a file a user names goes
/// through it.
///
/// # Errors
/// The file's own I/O errors (`NotFound` when it is missing), or `InvalidInput` naming why it
/// is refused.
pub fn read_bounded_bytes(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    // Asked before opening: opening a FIFO waits for a writer.
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, "it is not a regular file"));
    }
    // The file's size reserved at once (within the bound), so a large file is read without
    // being copied as the buffer grows; a file that grows meanwhile still stops at the bound.
    let mut bytes = Vec::with_capacity(usize::try_from(meta.len().min(max + 1)).unwrap_or(0));
    std::fs::File::open(path)?.take(max + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("it is larger than {max} bytes"),
        ));
    }
    Ok(bytes)
}

/// The text of a regular file of at most `max` bytes, as [`read_bounded_bytes`].
///
/// # Errors
/// As [`read_bounded_bytes`], and `InvalidData` when the file is not UTF-8.
pub fn read_bounded(path: &Path, max: u64) -> io::Result<String> {
    String::from_utf8(read_bounded_bytes(path, max)?)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "it is not UTF-8 text"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file being written is there, then moved away with its directory (still a name, not
    /// its own), then removed; a directory of the same name made again is not it.
    #[test]
    fn a_file_being_written_is_there_moved_or_removed() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        std::fs::create_dir(&dir).unwrap();
        let path = dir.join("poses.csv");
        let file = std::fs::File::create(&path).unwrap();
        assert_eq!(gone(&file, &path), None);
        std::fs::rename(&dir, tmp.path().join("moved")).unwrap();
        assert_eq!(gone(&file, &path), Some(Gone::Moved));
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(&path, b"another").unwrap();
        assert_eq!(gone(&file, &path), Some(Gone::Moved));
        std::fs::remove_dir_all(tmp.path().join("moved")).unwrap();
        assert_eq!(gone(&file, &path), Some(Gone::Removed));
        assert_eq!(Gone::Removed.reason(), "removed");
    }
}
