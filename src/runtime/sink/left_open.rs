//! At a daemon's start, the chunks an earlier run left open: stopped by SIGKILL, a crash or a
//! power cut, a chunk has no `summary.json`, and its session (or one the disk was too full to
//! close) no `session_ended`. Each reads back as it is, up to its last whole frame and row;
//! closing it makes it what a closed chunk is, and the log says so.

use crate::io::session::{ClosedLeftOpen, close_left_open, cut_last_line};
use crate::runtime::sink::chunks::{CHUNK_SUMMARY_FILE, write_whole};
use crate::runtime::sink::poses::{POSES_FILE, RAW_POSES_FILE};
use std::collections::BTreeMap;
use std::io::BufRead as _;
use std::path::{Path, PathBuf};

/// What closing one chunk did: its session closed (if it had one left open) and its rows
/// counted (if it had no summary).
#[derive(Debug, Default)]
struct Closed {
    session: Option<ClosedLeftOpen>,
    rows: Option<u64>,
}

/// Closes every chunk of every run in `output` that an earlier run left open, logging each;
/// one that cannot be closed is logged and left as it is. Returns the chunks closed.
pub fn close_chunks_left_open(output: &Path) -> Vec<PathBuf> {
    let mut closed = Vec::new();
    for chunk in chunks_in(output) {
        match close_chunk(&chunk) {
            Ok(Closed {
                session: None,
                rows: None,
            }) => {}
            Ok(Closed { session, rows }) => {
                tracing::warn!(
                    chunk = ?chunk,
                    depth_frames = session.as_ref().map(|s| s.depth_frames),
                    color_frames = session.as_ref().map(|s| s.color_frames),
                    cut_bytes = session.as_ref().map(|s| s.cut_bytes),
                    rows,
                    "closed a chunk that an earlier run left open (stopped without closing it: \
                     SIGKILL, a crash or a power cut)"
                );
                closed.push(chunk);
            }
            Err(e) => tracing::error!(
                chunk = ?chunk,
                "cannot close a chunk that an earlier run left open (it reads back up to its last \
                 whole frame and row): {e}"
            ),
        }
    }
    closed
}

/// The chunk directories of the runs in `output`, in order.
fn chunks_in(output: &Path) -> Vec<PathBuf> {
    let dirs = |dir: &Path| -> Vec<PathBuf> {
        std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.is_dir())
            .collect()
    };
    let mut chunks: Vec<PathBuf> = dirs(output)
        .iter()
        .flat_map(|run| dirs(run))
        .filter(|c| {
            c.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("chunk-"))
        })
        .collect();
    chunks.sort();
    chunks
}

/// Closes one chunk if it was left open: its session, and, without a summary, its rows.
fn close_chunk(chunk: &Path) -> Result<Closed, String> {
    let mut closed = Closed::default();
    if chunk.join(crate::io::session::META_FILE).is_file() {
        closed.session = close_left_open(chunk).map_err(|e| crate::core::error_chain(&e))?;
    }
    if !chunk.join(CHUNK_SUMMARY_FILE).exists() {
        closed.rows = Some(close_rows(chunk)?);
    }
    Ok(closed)
}

/// Cuts the cut last row of `poses.csv` and `poses_raw.csv` off and writes `summary.json` from
/// the rows `poses.csv` holds; returns how many.
fn close_rows(chunk: &Path) -> Result<u64, String> {
    for file in [POSES_FILE, RAW_POSES_FILE] {
        cut_last_line(&chunk.join(file)).map_err(|e| crate::core::error_chain(&e))?;
    }
    let tally = RowTally::of(&chunk.join(POSES_FILE))?;
    let index = chunk
        .file_name()
        .and_then(|n| n.to_str())
        .and_then(|n| n.strip_prefix("chunk-"))
        .and_then(|n| n.parse::<usize>().ok());
    let summary = serde_json::json!({
        "chunk": index,
        "rows": tally.rows,
        "statuses": tally.statuses,
        "first_host_ns": tally.first_host_ns,
        "last_host_ns": tally.last_host_ns,
        // Rows the stopped run could not write are not known.
        "rows_lost": null,
        "software_version": env!("CARGO_PKG_VERSION"),
        "closed_at_next_start": true,
    });
    let path = chunk.join(CHUNK_SUMMARY_FILE);
    let text = serde_json::to_vec_pretty(&summary).map_err(|e| e.to_string())?;
    write_whole(&path, &text).map_err(|e| format!("cannot write {path:?}: {e}"))?;
    Ok(tally.rows)
}

/// The rows of a `poses.csv`: how many, by status, and the host times of the first and last.
#[derive(Debug, Default)]
struct RowTally {
    rows: u64,
    statuses: BTreeMap<String, u64>,
    first_host_ns: Option<u64>,
    last_host_ns: Option<u64>,
}

impl RowTally {
    /// Reads the rows of `path` one line at a time (an hour's file is large); a missing file
    /// has none.
    fn of(path: &Path) -> Result<Self, String> {
        let mut tally = Self::default();
        let file = match std::fs::File::open(path) {
            Ok(file) => file,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(tally),
            Err(e) => return Err(format!("cannot read {path:?}: {e}")),
        };
        let mut lines = std::io::BufReader::new(file).lines();
        let header = match lines.next() {
            Some(line) => line.map_err(|e| format!("cannot read {path:?}: {e}"))?,
            None => return Ok(tally),
        };
        let column = |name: &str| header.split(',').position(|c| c == name);
        let (Some(host), Some(status)) = (column("host_ns"), column("status")) else {
            return Err(format!("{path:?} has no host_ns and status columns"));
        };
        for line in lines {
            let line = line.map_err(|e| format!("cannot read {path:?}: {e}"))?;
            let cells: Vec<&str> = line.split(',').collect();
            let host_ns = cells.get(host).and_then(|c| c.parse::<u64>().ok());
            tally.first_host_ns = tally.first_host_ns.or(host_ns);
            tally.last_host_ns = host_ns.or(tally.last_host_ns);
            *tally
                .statuses
                .entry(cells.get(status).map_or_else(String::new, |s| (*s).to_owned()))
                .or_default() += 1;
            tally.rows += 1;
        }
        Ok(tally)
    }
}
