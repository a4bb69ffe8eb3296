//! Closing a session that its writer left open (the process killed by SIGKILL, a crash, the
//! power lost): it already reads back up to its last whole frame ([`SessionReader`] rebuilds a
//! missing index and steps over a cut last record); closing it makes it what a closed session
//! is, so that nothing reading it later has to know.

use super::events::SessionEvent;
use super::meta::CameraRole;
use super::{EVENTS_FILE, FRAMES_FILE, INDEX_FILE, Result, SessionReader, TIMESTAMPS_FILE, io_error};
use std::fs::OpenOptions;
use std::io::Write as _;
use std::path::Path;

/// What closing a session left open did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClosedLeftOpen {
    pub depth_frames: usize,
    pub color_frames: usize,
    /// Bytes cut off the end of the frame files: a record the killed writer had begun.
    pub cut_bytes: u64,
}

/// Closes the session in `dir` if its writer left it open: each camera's frame file cut after
/// its last whole record and its index written, the cut last line of each text file cut off,
/// and `session_ended` appended to `events.jsonl` at the latest host time its frames and
/// events hold. A closed session is left as it is (`None`).
///
/// # Errors
/// The session cannot be read ([`SessionReader::open`]), or a file cannot be cut or written.
pub fn close_left_open(dir: &Path) -> Result<Option<ClosedLeftOpen>> {
    let session = SessionReader::open(dir)?;
    if session.complete() {
        return Ok(None);
    }
    let mut cut_bytes = 0;
    let mut last_host_ns = 0;
    for role in [CameraRole::Depth, CameraRole::Color] {
        let Some((entries, tail)) = session.frame_index(role) else {
            continue;
        };
        let sub = dir.join(role.name());
        let frames = sub.join(FRAMES_FILE);
        let len = std::fs::metadata(&frames).map_err(io_error(&frames, "read"))?.len();
        let whole = len - tail;
        if tail > 0 {
            let file = OpenOptions::new()
                .write(true)
                .open(&frames)
                .map_err(io_error(&frames, "open"))?;
            file.set_len(whole).map_err(io_error(&frames, "truncate"))?;
            file.sync_all().map_err(io_error(&frames, "sync"))?;
            cut_bytes += tail;
        }
        crate::io::store::write_index(sub.join(INDEX_FILE), whole, &entries)?;
        cut_last_line(&sub.join(TIMESTAMPS_FILE))?;
        last_host_ns = last_host_ns.max(session.last_host_ns(role).unwrap_or(0));
    }
    let events = dir.join(EVENTS_FILE);
    cut_last_line(&events)?;
    for event in session.events()? {
        last_host_ns = last_host_ns.max(event.host_ns().unwrap_or(0));
    }
    let closed = ClosedLeftOpen {
        depth_frames: session.depth_count(),
        color_frames: session.color_count(),
        cut_bytes,
    };
    let ended = SessionEvent::SessionEnded {
        host_ns: last_host_ns,
        depth_frames: closed.depth_frames as u64,
        color_frames: closed.color_frames as u64,
    };
    let mut line = serde_json::to_string(&ended).map_err(|source| super::SessionError::EventEncode {
        path: events.clone(),
        source,
    })?;
    line.push('\n');
    let mut file = OpenOptions::new()
        .append(true)
        .create(true)
        .open(&events)
        .map_err(io_error(&events, "open"))?;
    file.write_all(line.as_bytes()).map_err(io_error(&events, "write"))?;
    file.sync_all().map_err(io_error(&events, "sync"))?;
    Ok(Some(closed))
}

/// Cuts off a text file's last line when it has no end (a writer killed in the middle of
/// it); a missing file is left missing.
pub fn cut_last_line(path: &Path) -> Result<()> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(io_error(path, "read")(e)),
    };
    if bytes.is_empty() || bytes.ends_with(b"\n") {
        return Ok(());
    }
    let whole = bytes.iter().rposition(|&b| b == b'\n').map_or(0, |at| at + 1);
    let file = OpenOptions::new()
        .write(true)
        .open(path)
        .map_err(io_error(path, "open"))?;
    file.set_len(whole as u64).map_err(io_error(path, "truncate"))?;
    file.sync_all().map_err(io_error(path, "sync"))
}

#[cfg(test)]
mod tests {
    use super::cut_last_line;

    #[test]
    fn a_cut_last_line_is_cut_off_and_a_whole_file_left_as_it_is() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("events.jsonl");
        for (text, left) in [("a\nb\nhalf", "a\nb\n"), ("a\nb\n", "a\nb\n"), ("half", ""), ("", "")] {
            std::fs::write(&path, text).unwrap();
            cut_last_line(&path).unwrap();
            assert_eq!(std::fs::read_to_string(&path).unwrap(), left, "{text:?}");
        }
        cut_last_line(&dir.path().join("missing")).unwrap();
        assert!(!dir.path().join("missing").exists());
    }
}
