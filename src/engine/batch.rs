//! Many sessions at once: `mousepose replay S1 S2 ... --out DIR` (or a glob) and
//! `mousepose batch SESSIONS... --out DIR [--slurm]`.
//!
//! Each session goes to `DIR/<session name>/` (a daemon's chunk to `DIR/<run>-<chunk>/`:
//! every run has a `chunk-0000`). One batch at a time writes into a `DIR`: it holds the lock
//! file [`LOCK_FILE`] while it runs. A signal stops the batch, and the session under way
//! leaves nothing behind. A session whose `summary.json` is there is
//! finished and skipped; anything else there (a directory a crash left without its summary,
//! a hidden `.NAME.partial-PID` staging directory) is removed and the session replayed
//! again. One table for all (`DIR/batch.csv`, and printed) says, per session, whether it was
//! replayed now, skipped or failed, with its pairs, throughput and error against the truth.
//!
//! With `--slurm` the sessions left to do become one Slurm job array (`sbatch --array`, one
//! task per session, each task a `mousepose replay`); the command waits for the array to end
//! and gathers the summaries the same way.

use crate::engine::progress::Progress;
use crate::engine::replay::{ReplayOptions, SUMMARY_FILE, replay_until};
use crate::engine::{Failure, Interrupt};
use crate::io::table::Fixed;
use anyhow::Context as _;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// The table of a batch.
pub const BATCH_FILE: &str = "batch.csv";
/// The Slurm job's files, in the batch's directory.
pub const SLURM_DIR: &str = "slurm";

/// One session of a batch and where its output goes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BatchItem {
    pub session: PathBuf,
    pub name: String,
    pub out: PathBuf,
}

impl BatchItem {
    /// Whether the session's replay finished (its summary is written last, on commit).
    pub fn finished(&self) -> bool {
        self.out.join(SUMMARY_FILE).is_file()
    }
}

/// What became of one session.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BatchRow {
    pub name: String,
    pub session: PathBuf,
    /// `done` (replayed now), `skipped` (finished before) or `failed`.
    pub status: &'static str,
    pub pairs: Option<u64>,
    pub ok_poses: Option<u64>,
    pub throughput_pairs_per_s: Option<f64>,
    pub mean_error_mm: Option<f64>,
    pub error: Option<String>,
}

/// Whether `arg` is a glob pattern rather than a path.
fn is_pattern(arg: &Path) -> bool {
    !arg.exists() && arg.to_string_lossy().contains(['*', '?', '['])
}

/// Whether these arguments ask for a batch: more than one, or a pattern.
pub fn is_batch(args: &[PathBuf]) -> bool {
    args.len() > 1 || args.iter().any(|a| is_pattern(a))
}

/// The sessions named by `args` (paths, or glob patterns matching directories), in order,
/// each once.
///
/// # Errors
/// A pattern that is not valid or matches no directory, or a path that is not a directory.
pub fn expand_sessions(args: &[PathBuf]) -> Result<Vec<PathBuf>, Failure> {
    let mut sessions: Vec<PathBuf> = Vec::new();
    for arg in args {
        let found: Vec<PathBuf> = if is_pattern(arg) {
            let text = arg.to_string_lossy();
            let paths = glob::glob(&text)
                .map_err(|e| Failure::usage(anyhow::anyhow!("{text:?} is not a valid pattern: {e}")))?;
            let mut dirs: Vec<PathBuf> = paths.filter_map(Result::ok).filter(|p| p.is_dir()).collect();
            dirs.sort();
            if dirs.is_empty() {
                return Err(Failure::usage(anyhow::anyhow!("{text:?} matches no session directory")));
            }
            dirs
        } else if arg.is_dir() {
            vec![arg.clone()]
        } else {
            return Err(Failure::usage(anyhow::anyhow!(
                "the session {arg:?} is not a directory"
            )));
        };
        for p in found {
            if !sessions.contains(&p) {
                sessions.push(p);
            }
        }
    }
    Ok(sessions)
}

/// The name of a session's output: its directory's name, and for a chunk of a daemon's run
/// (`RUN/chunk-0003`, every run has a `chunk-0000`) the run's name before it
/// (`RUN-chunk-0003`).
fn output_name(session: &Path) -> Option<String> {
    let name = session.file_name()?.to_string_lossy().into_owned();
    let run = session
        .parent()
        .and_then(Path::file_name)
        .map(|n| n.to_string_lossy().into_owned());
    match run {
        Some(run) if is_chunk_name(&name) => Some(format!("{run}-{name}")),
        _ => Some(name),
    }
}

/// Whether `name` is a chunk's directory name as the daemon writes it: `chunk-` and digits.
fn is_chunk_name(name: &str) -> bool {
    name.strip_prefix("chunk-")
        .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
}

/// Each session's output directory under `out`, named after the session's directory (a
/// daemon's chunk after its run and itself, see [`output_name`]).
///
/// # Errors
/// Two sessions with the same name (their outputs would collide), or a session without a
/// name.
pub fn plan(sessions: &[PathBuf], out: &Path) -> Result<Vec<BatchItem>, Failure> {
    let mut items: Vec<BatchItem> = Vec::new();
    for session in sessions {
        let absolute = std::fs::canonicalize(session).unwrap_or_else(|_| session.clone());
        let name = output_name(&absolute)
            .ok_or_else(|| Failure::usage(anyhow::anyhow!("the session {session:?} has no name")))?;
        if let Some(other) = items.iter().find(|i| i.name == name) {
            return Err(Failure::usage(anyhow::anyhow!(
                "the sessions {:?} and {session:?} have the same name {name:?}: their outputs would collide in {out:?}",
                other.session
            )));
        }
        if absolute.starts_with(out) && absolute.parent() == Some(out) {
            return Err(Failure::usage(anyhow::anyhow!(
                "the session {session:?} is inside the output directory {out:?}"
            )));
        }
        items.push(BatchItem {
            session: absolute,
            out: out.join(&name),
            name,
        });
    }
    Ok(items)
}

/// Removes what an unfinished replay of `item` left: its directory without a summary and
/// its hidden staging directories.
///
/// # Errors
/// They cannot be removed.
pub fn clear_unfinished(item: &BatchItem) -> anyhow::Result<()> {
    if item.out.exists() && !item.finished() {
        std::fs::remove_dir_all(&item.out).with_context(|| format!("removing the unfinished {:?}", item.out))?;
    }
    let Some(parent) = item.out.parent() else {
        return Ok(());
    };
    let prefix = format!(".{}.partial-", item.name);
    if let Ok(entries) = std::fs::read_dir(parent) {
        for entry in entries.flatten() {
            if entry.file_name().to_string_lossy().starts_with(&prefix) {
                let path = entry.path();
                std::fs::remove_dir_all(&path).with_context(|| format!("removing the unfinished {path:?}"))?;
            }
        }
    }
    Ok(())
}

/// The row of a session from its `summary.json`; `status` as given.
fn row_from_summary(item: &BatchItem, status: &'static str) -> BatchRow {
    let summary: Option<serde_json::Value> = std::fs::read(item.out.join(SUMMARY_FILE))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok());
    let get = |key: &str| summary.as_ref().and_then(|s| s.get(key).cloned());
    match summary {
        Some(_) => BatchRow {
            name: item.name.clone(),
            session: item.session.clone(),
            status,
            pairs: get("pairs").and_then(|v| v.as_u64()),
            ok_poses: get("statuses").and_then(|v| v.get("ok").and_then(serde_json::Value::as_u64)),
            throughput_pairs_per_s: get("throughput_pairs_per_s").and_then(|v| v.as_f64()),
            mean_error_mm: get("mean_error_mm").and_then(|v| v.as_f64()),
            error: None,
        },
        None => failed_row(
            item,
            format!("{:?} is missing or not JSON", item.out.join(SUMMARY_FILE)),
        ),
    }
}

fn failed_row(item: &BatchItem, error: String) -> BatchRow {
    BatchRow {
        name: item.name.clone(),
        session: item.session.clone(),
        status: "failed",
        pairs: None,
        ok_poses: None,
        throughput_pairs_per_s: None,
        mean_error_mm: None,
        error: Some(error),
    }
}

/// How each session is replayed.
#[derive(Clone, Debug, Default)]
pub struct BatchOptions {
    pub models: Option<PathBuf>,
    pub workers: usize,
    pub calibration: Option<PathBuf>,
    /// Replay finished sessions again too.
    pub force: bool,
}

/// Replays every session of `items` here, one after the other, skipping finished ones;
/// `progress` is told each session's name as it starts. A signal (`interrupt`) stops the
/// batch: the session being replayed leaves nothing behind, and the rows end there.
pub fn run_local(
    items: &[BatchItem],
    options: &BatchOptions,
    interrupt: &Interrupt,
    mut progress: impl FnMut(&str),
) -> Vec<BatchRow> {
    items
        .iter()
        .map_while(|item| {
            if interrupt.requested() {
                return None;
            }
            progress(&item.name);
            Some(item)
        })
        .map(|item| {
            if item.finished() && !options.force {
                return row_from_summary(item, "skipped");
            }
            if let Err(e) = clear_unfinished(item) {
                return failed_row(item, format!("{e:#}"));
            }
            let result = replay_until(
                &ReplayOptions {
                    stream: None,
                    lsl: None,
                    lead_ns: None,
                    partner_wait: None,
                    mice: 1,
                    session: item.session.clone(),
                    out: item.out.clone(),
                    models: options.models.clone(),
                    realtime: false,
                    workers: options.workers,
                    overlays: None,
                    calibration: options.calibration.clone(),
                    // A batch's sessions each carry their rig, or are placed on their own floor
                    // with the camera table's intrinsics; one mask or lens for all is not offered.
                    intrinsics: None,
                    roi: None,
                    force: true,
                },
                interrupt,
            );
            match result {
                Ok(_) => row_from_summary(item, "done"),
                Err(e) => {
                    let error = format!("{:#}", anyhow::Error::from(e));
                    tracing::error!(message = "Session failed.", session = %item.session.display(), error = %error);
                    failed_row(item, error)
                }
            }
        })
        .collect()
}

/// The columns of `batch.csv`.
const BATCH_COLUMNS: [&str; 8] = [
    "name",
    "session",
    "status",
    "pairs",
    "ok_poses",
    "throughput_pairs_per_s",
    "mean_error_mm",
    "error",
];

/// One line of `batch.csv`: the row with its numbers rounded as the table has always shown them.
#[derive(Serialize)]
struct BatchLine<'a> {
    name: &'a str,
    session: std::borrow::Cow<'a, str>,
    status: &'a str,
    pairs: Option<u64>,
    ok_poses: Option<u64>,
    throughput_pairs_per_s: Option<Fixed<1>>,
    mean_error_mm: Option<Fixed<3>>,
    error: &'a str,
}

/// `batch.csv`: one line per session.
///
/// # Errors
/// Never in practice: every field is a scalar.
pub fn table_csv(rows: &[BatchRow]) -> Result<Vec<u8>, csv::Error> {
    let lines: Vec<BatchLine<'_>> = rows
        .iter()
        .map(|r| BatchLine {
            name: &r.name,
            session: r.session.to_string_lossy(),
            status: r.status,
            pairs: r.pairs,
            ok_poses: r.ok_poses,
            throughput_pairs_per_s: r.throughput_pairs_per_s.map(Fixed),
            mean_error_mm: r.mean_error_mm.map(Fixed),
            error: r.error.as_deref().unwrap_or_default(),
        })
        .collect();
    crate::io::table::table(&BATCH_COLUMNS, &lines)
}

/// Writes `batch.csv` into `out` (through a temporary file and a rename).
///
/// # Errors
/// It cannot be written.
pub fn write_table(out: &Path, rows: &[BatchRow]) -> anyhow::Result<PathBuf> {
    let path = out.join(BATCH_FILE);
    let tmp = out.join(format!(".{BATCH_FILE}.partial-{}", std::process::id()));
    std::fs::write(&tmp, table_csv(rows)?).with_context(|| format!("writing {tmp:?}"))?;
    std::fs::rename(&tmp, &path).with_context(|| format!("writing {path:?}"))?;
    Ok(path)
}

/// What a batch did: a row per session, and the table written from them.
#[derive(Clone, Debug)]
pub struct BatchSummary {
    pub rows: Vec<BatchRow>,
    /// `batch.csv`, written from `rows`.
    pub table: PathBuf,
}

impl BatchSummary {
    /// Sessions that failed make the batch a failure of the work, naming the table to read.
    pub fn failure(&self) -> Option<Failure> {
        let failed = self.rows.iter().filter(|r| r.status == "failed").count();
        (failed > 0).then(|| {
            Failure::from(anyhow::anyhow!(
                "{failed} of {} sessions failed (see {:?})",
                self.rows.len(),
                self.table
            ))
        })
    }
}

/// Replays `sessions` (directories or glob patterns) into `out`, here, in turn, or as a
/// Slurm job array when `slurm` is given; writes `batch.csv`.
///
/// # Errors
/// The sessions or the output directory cannot be used (the user's), another batch holds
/// `out`, Slurm cannot be run, or a signal stopped the batch (what was under way is removed).
pub fn batch(
    sessions: &[PathBuf],
    out: &Path,
    options: &BatchOptions,
    slurm: Option<&SlurmResources>,
    progress: &dyn Progress,
) -> Result<BatchSummary, Failure> {
    let sessions = expand_sessions(sessions)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {out:?}"))?;
    let out = std::fs::canonicalize(out).with_context(|| format!("reading {out:?}"))?;
    let items = plan(&sessions, &out)?;
    let _lock = BatchLock::take(&out)?;
    let rows = match slurm {
        Some(slurm) => run_slurm(&items, &out, options, slurm, progress)?,
        None => {
            let interrupt = Interrupt::install().context("installing the signal handlers")?;
            progress.start("sessions", items.len() as u64);
            let rows = run_local(&items, options, &interrupt, |name| {
                progress.label(name);
                progress.advance(1);
            });
            progress.finish();
            if interrupt.requested() {
                let done = rows.iter().filter(|r| r.status != "failed").count();
                return Err(Failure::from(anyhow::anyhow!(
                    "stopped by a signal after {done} of {} sessions; the one under way left nothing behind (run the batch again to go on)",
                    items.len()
                )));
            }
            rows
        }
    };
    let table = write_table(&out, &rows)?;
    Ok(BatchSummary { rows, table })
}

/// The lock file a batch holds in its output directory while it runs.
pub const LOCK_FILE: &str = ".mousepose-batch.lock";

/// A batch's hold on its output directory: two batches into one directory would each
/// remove what the other has not finished. Released when dropped (or when the process
/// ends, however it ends: an advisory `flock`).
#[derive(Debug)]
pub struct BatchLock {
    _file: std::fs::File,
}

impl BatchLock {
    /// Takes the lock of `out`, writing this process's id into it.
    ///
    /// # Errors
    /// Another batch holds it (a usage error naming its process id), or the file cannot be
    /// created.
    pub fn take(out: &Path) -> Result<Self, Failure> {
        use std::io::{Read as _, Seek as _, Write as _};
        let path = out.join(LOCK_FILE);
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .with_context(|| format!("creating the lock file {path:?}"))?;
        if let Err(e) = rustix::fs::flock(&file, rustix::fs::FlockOperation::NonBlockingLockExclusive) {
            if e != rustix::io::Errno::WOULDBLOCK {
                return Err(Failure::from(
                    anyhow::Error::from(std::io::Error::from(e)).context(format!("locking {path:?}")),
                ));
            }
            let mut text = String::new();
            let _ = file.read_to_string(&mut text);
            let holder = match text.trim() {
                "" => "another process".to_owned(),
                pid => format!("process {pid}"),
            };
            return Err(Failure::usage(anyhow::anyhow!(
                "the output directory {out:?} is in use by another batch ({holder}, see {LOCK_FILE}): wait for it to end or choose another --out"
            )));
        }
        let written = file
            .set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| writeln!(file, "{}", std::process::id()));
        written.with_context(|| format!("writing {path:?}"))?;
        Ok(Self { _file: file })
    }
}

/// Resources and placement of the Slurm job.
#[derive(Clone, Debug)]
pub struct SlurmResources {
    /// CPUs per task (each task is one replay; its body-forest workers use them all).
    pub cpus: u32,
    /// Memory per task, in Slurm's notation (e.g. 4G, 2000M).
    pub mem: String,
    /// Time limit per task, in Slurm's notation (e.g. 01:00:00, 90, 1-00:00:00).
    pub time: String,
    /// The partition to run in (the cluster's default when not given).
    pub partition: Option<String>,
    /// At most this many tasks at once (`--array=...%N`).
    pub max_parallel: Option<u32>,
    /// The job's name in the queue.
    pub job_name: String,
}

/// `text` quoted for a POSIX shell.
fn shell_quote(text: &str) -> String {
    format!("'{}'", text.replace('\'', "'\\''"))
}

/// The job script of a Slurm array of `tasks` tasks (task `i` replays line `i + 1` of
/// `tasks.tsv`).
pub fn job_script(
    program: &Path,
    slurm_dir: &Path,
    tasks: usize,
    options: &BatchOptions,
    slurm: &SlurmResources,
) -> String {
    let last = tasks.saturating_sub(1);
    let throttle = slurm.max_parallel.map(|n| format!("%{n}")).unwrap_or_default();
    let mut s = String::from("#!/bin/bash\n");
    let _ = writeln!(s, "#SBATCH --job-name={}", slurm.job_name);
    let _ = writeln!(s, "#SBATCH --array=0-{last}{throttle}");
    let _ = writeln!(s, "#SBATCH --cpus-per-task={}", slurm.cpus);
    let _ = writeln!(s, "#SBATCH --mem={}", slurm.mem);
    let _ = writeln!(s, "#SBATCH --time={}", slurm.time);
    if let Some(p) = &slurm.partition {
        let _ = writeln!(s, "#SBATCH --partition={p}");
    }
    let _ = writeln!(s, "#SBATCH --output={}/task-%A_%a.log", slurm_dir.display());
    s.push_str("# Written by mousepose batch --slurm: one task per session of tasks.tsv.\nset -euo pipefail\n");
    let _ = writeln!(
        s,
        "tasks={}",
        shell_quote(&slurm_dir.join("tasks.tsv").to_string_lossy())
    );
    s.push_str("line=$(sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" \"$tasks\")\n");
    s.push_str("session=${line%%$'\\t'*}\nout=${line#*$'\\t'}\n");
    let mut command = format!(
        "exec {} replay \"$session\" --out \"$out\" --force --workers \"${{SLURM_CPUS_PER_TASK:-1}}\"",
        shell_quote(&program.to_string_lossy())
    );
    if let Some(m) = &options.models {
        let _ = write!(command, " --models {}", shell_quote(&m.to_string_lossy()));
    }
    if let Some(c) = &options.calibration {
        let _ = write!(command, " --calibration {}", shell_quote(&c.to_string_lossy()));
    }
    s.push_str(&command);
    s.push('\n');
    s
}

/// Runs a Slurm command and returns its standard output.
fn slurm_command(program: &str, args: &[&str]) -> Result<String, Failure> {
    let out = Command::new(program).args(args).output().map_err(|e| {
        Failure::usage(anyhow::Error::from(e).context(format!("cannot run {program} (is Slurm installed here?)")))
    })?;
    if !out.status.success() {
        return Err(Failure::from(anyhow::anyhow!(
            "{program} failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Whether the job still has tasks in the queue.
fn job_queued(job: &str) -> Result<bool, Failure> {
    let out = Command::new("squeue")
        .args(["-h", "-j", job, "-o", "%i"])
        .output()
        .map_err(|e| Failure::from(anyhow::Error::from(e).context("cannot run squeue")))?;
    if !out.status.success() {
        // A job that ended long enough ago is unknown to squeue.
        let err = String::from_utf8_lossy(&out.stderr);
        if err.contains("Invalid job id") {
            return Ok(false);
        }
        return Err(Failure::from(anyhow::anyhow!("squeue failed: {}", err.trim())));
    }
    Ok(!out.stdout.iter().all(u8::is_ascii_whitespace))
}

/// The last line a failed task wrote to its log.
fn task_error(slurm_dir: &Path, job: &str, index: usize) -> String {
    let log = slurm_dir.join(format!("task-{job}_{index}.log"));
    std::fs::read_to_string(&log)
        .ok()
        .and_then(|t| t.lines().rev().find(|l| !l.trim().is_empty()).map(str::to_owned))
        .map_or_else(
            || format!("no summary, and no task log {log:?}"),
            |l| format!("{l} (see {log:?})"),
        )
}

/// `mousepose batch --slurm`: submits the unfinished sessions as a job array, waits for it,
/// and gathers every session's summary.
fn run_slurm(
    items: &[BatchItem],
    out: &Path,
    options: &BatchOptions,
    slurm: &SlurmResources,
    progress: &dyn Progress,
) -> Result<Vec<BatchRow>, Failure> {
    let finished_before: Vec<bool> = items.iter().map(|i| i.finished() && !options.force).collect();
    let todo: Vec<&BatchItem> = items
        .iter()
        .zip(&finished_before)
        .filter(|(_, f)| !**f)
        .map(|(i, _)| i)
        .collect();
    let mut job = None;
    let slurm_dir = out.join(SLURM_DIR);
    if !todo.is_empty() {
        for item in &todo {
            clear_unfinished(item)?;
        }
        std::fs::create_dir_all(&slurm_dir).with_context(|| format!("creating {slurm_dir:?}"))?;
        let tasks: String = todo
            .iter()
            .map(|i| format!("{}\t{}\n", i.session.display(), i.out.display()))
            .collect();
        if tasks.lines().any(|l| l.matches('\t').count() != 1) {
            return Err(Failure::usage(anyhow::anyhow!(
                "a session path holds a tab or a line break"
            )));
        }
        crate::engine::write_report_file(&slurm_dir, "tasks.tsv", tasks.as_bytes())?;
        let program = std::env::current_exe().context("finding the mousepose program")?;
        let script = job_script(&program, &slurm_dir, todo.len(), options, slurm);
        let script_path = slurm_dir.join("job.sh");
        crate::engine::write_report_file(&slurm_dir, "job.sh", script.as_bytes())?;
        let submitted = slurm_command("sbatch", &["--parsable", &script_path.to_string_lossy()])?;
        let id = submitted.trim().split(';').next().unwrap_or_default().to_owned();
        if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
            return Err(Failure::from(anyhow::anyhow!(
                "sbatch answered {submitted:?}, not a job id"
            )));
        }
        progress.notice(&format!(
            "submitted job array {id} ({} tasks); waiting for it",
            todo.len()
        ));
        progress.start("tasks", todo.len() as u64);
        let started = Instant::now();
        while job_queued(&id)? {
            progress.set_done(todo.iter().filter(|i| i.finished()).count() as u64);
            std::thread::sleep(Duration::from_secs(if started.elapsed() < Duration::from_secs(30) {
                1
            } else {
                5
            }));
        }
        progress.finish();
        job = Some(id);
    }
    let mut todo_index = 0usize;
    Ok(items
        .iter()
        .zip(&finished_before)
        .map(|(item, &before)| {
            if before {
                return row_from_summary(item, "skipped");
            }
            let index = todo_index;
            todo_index += 1;
            if item.finished() {
                row_from_summary(item, "done")
            } else {
                failed_row(item, task_error(&slurm_dir, job.as_deref().unwrap_or_default(), index))
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shell_quoting_survives_quotes() {
        assert_eq!(shell_quote("a'b"), "'a'\\''b'");
    }

    #[test]
    fn a_daemons_chunks_are_named_by_run_and_chunk() {
        let name = |p: &str| output_name(Path::new(p));
        assert_eq!(
            name("/d/20261123T221726Z/chunk-0003").as_deref(),
            Some("20261123T221726Z-chunk-0003")
        );
        assert_eq!(name("/d/mouse-a").as_deref(), Some("mouse-a"));
        assert_eq!(name("/d/run/chunk-notes").as_deref(), Some("chunk-notes"));
        assert_eq!(name("/chunk-0000").as_deref(), Some("chunk-0000"));
    }
}
