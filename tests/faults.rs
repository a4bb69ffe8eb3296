//! Issue 63: the daemon's writes failing one at a time. A file system that fails the N-th
//! write (`tests/fault/fail_write.c`, loaded with `LD_PRELOAD`) makes each write of a short
//! recording fail once, in turn; after each run, the daemon must have gone on, every frame be
//! accounted for, and every chunk read back.

use crate::run::{assert_accounted, chunks, pose_rows, report, session_rig};
use crate::util::{mousepose, repo_root};
use mousepose::io::session::SessionReader;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Builds the failing file system's library into `dir`.
fn fail_write_library(dir: &Path) -> PathBuf {
    let library = dir.join("fail_write.so");
    let out = Command::new("cc")
        .args(["-shared", "-fPIC", "-O1", "-o"])
        .arg(&library)
        .arg(repo_root().join("tests/fault/fail_write.c"))
        .arg("-ldl")
        .output()
        .expect("a C compiler (cc)");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    library
}

/// What one run with its `at`-th write failing gave: its report, log and chunks, and how many
/// writes it made.
struct FailedRun {
    report: serde_json::Value,
    log: String,
    chunks: Vec<PathBuf>,
    writes: u64,
}

/// The daemon (the fixture session as its depth camera, recording) for half a second (15
/// frames) with its `at`-th write under the output directory failing with `errno` (0: none
/// fails).
fn run_failing(library: &Path, dir: &Path, at: u64, errno: i32) -> FailedRun {
    let out = dir.join("out");
    std::fs::create_dir_all(&out).expect("test set-up");
    let rig = session_rig(dir);
    let count = dir.join("writes");
    let run = mousepose()
        .args(["run", "--json", "--seconds", "0.5", "--config"])
        .arg(&rig)
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .env("RUST_LOG", "info")
        .env("LD_PRELOAD", library)
        .env("FAIL_WRITE_UNDER", &out)
        .env("FAIL_WRITE_AT", at.to_string())
        .env("FAIL_WRITE_ERRNO", errno.to_string())
        .env("FAIL_WRITE_COUNT", &count)
        .output()
        .expect("test set-up");
    let log = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "write {at} failing: {}\n{log}", run.status);
    let writes = std::fs::read_to_string(&count)
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or_else(|| panic!("write {at} failing: the library counted nothing\n{log}"));
    FailedRun {
        report: report(&String::from_utf8_lossy(&run.stdout)),
        log,
        chunks: chunks(&out),
        writes,
    }
}

/// After a run with one write failing: every frame accounted for, and every chunk whole: its
/// session read back frame by frame, `poses.csv` whole rows that its `summary.json` counts.
fn assert_whole(run: &FailedRun, at: u64) {
    let depth = &run.report["cameras"]["depth"];
    assert_accounted(depth);
    assert!(
        run.report["poses"].as_u64().unwrap_or(0) > 0,
        "write {at} failing: no pose\n{}",
        run.log
    );
    for chunk in &run.chunks {
        if chunk.join("session.toml").exists() {
            let session = SessionReader::open(chunk).unwrap_or_else(|e| panic!("write {at} failing: {chunk:?}: {e}"));
            let read = session.depth_frames().filter(Result::is_ok).count();
            assert_eq!(read, session.depth_count(), "write {at} failing: {chunk:?}");
        }
        let text = std::fs::read_to_string(chunk.join("poses.csv")).unwrap_or_default();
        assert!(
            text.is_empty() || text.ends_with('\n'),
            "write {at} failing: {chunk:?} ends with a cut row"
        );
        let summary: serde_json::Value = serde_json::from_slice(
            &std::fs::read(chunk.join("summary.json"))
                .unwrap_or_else(|e| panic!("write {at} failing: {chunk:?}: no summary.json ({e})\n{}", run.log)),
        )
        .unwrap_or_else(|e| panic!("write {at} failing: {chunk:?}: summary.json cut ({e})"));
        assert_eq!(
            summary["rows"].as_u64(),
            Some(pose_rows(chunk) as u64),
            "write {at} failing: {chunk:?}: {summary:#}"
        );
    }
}

/// Issue 63 item 2: each write of a short recording (the session's files, frames, events,
/// poses, the summary) fails once, in turn, as a failing disk (EIO), a full one (ENOSPC) or
/// one remounted read-only (EROFS) fails it, taking turns: the daemon goes on every time,
/// every frame is accounted for, and every chunk reads back whole.
#[test]
fn issue63_every_write_of_a_short_recording_fails_in_turn_and_the_daemon_goes_on() {
    let tmp = tempfile::tempdir().expect("test set-up");
    let library = fail_write_library(tmp.path());
    let clean = run_failing(&library, &tmp.path().join("clean"), 0, 0);
    assert_whole(&clean, 0);
    assert!(clean.writes > 10, "only {} writes counted", clean.writes);
    // A run is half a second long, so runs make a few writes more or fewer than the clean one:
    // the last writes of the clean run may lie beyond a shorter run's end.
    let mut reached = 0;
    for at in 1..=clean.writes {
        let dir = tmp.path().join(format!("at{at}"));
        let errno = [EIO, ENOSPC, EROFS][(at % 3) as usize];
        let run = run_failing(&library, &dir, at, errno);
        reached += u64::from(run.writes >= at);
        assert_whole(&run, at);
        std::fs::remove_dir_all(&dir).expect("test set-up");
    }
    assert!(
        reached * 10 >= clean.writes * 9,
        "only {reached} of {} failing writes were reached",
        clean.writes
    );
}

/// The errors of a failing disk, a full one and one remounted read-only (Linux's numbers).
const EIO: i32 = 5;
const ENOSPC: i32 = 28;
const EROFS: i32 = 30;

/// Starts the daemon recording into `dir/out` (a 32 MB disk of its own when `fill`), waits
/// for 20 frames, fills the disk when `fill` and lets the writes fail for two seconds, and
/// kills it (SIGKILL). Returns the chunk it left.
fn killed_while_recording(dir: &Path, fill: bool) -> (PathBuf, Option<crate::run::Tmpfs>) {
    let out = dir.join("out");
    let disk = fill.then(|| crate::run::Tmpfs::mount(&out, "32m"));
    std::fs::create_dir_all(&out).expect("test set-up");
    let rig = session_rig(dir);
    let mut daemon = crate::run::daemon(&rig, None);
    let start = std::time::Instant::now();
    let lines = |c: &Path, file: &str| std::fs::read_to_string(c.join(file)).map_or(0, |t| t.lines().count());
    let recorded = || {
        let runs = std::fs::read_dir(&out).map_or(0, Iterator::count);
        runs > 0
            && chunks(&out)
                .first()
                .is_some_and(|c| lines(c, "depth/timestamps.csv") >= 21 && lines(c, "poses.csv") >= 2)
    };
    while !recorded() {
        assert!(start.elapsed().as_secs() < 60, "the daemon wrote no poses");
        assert!(
            daemon.0.try_wait().expect("test set-up").is_none(),
            "the daemon exited early"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    if fill {
        // Written until the disk is full.
        drop(std::fs::write(out.join("filler"), vec![1u8; 40 << 20]));
        std::thread::sleep(std::time::Duration::from_secs(2));
    }
    daemon.0.kill().expect("test set-up");
    daemon.0.wait().expect("test set-up");
    if fill {
        std::fs::remove_file(out.join("filler")).expect("test set-up");
    }
    (chunks(&out).remove(0), disk)
}

/// The next start after a daemon was killed in the middle of recording: it closes the chunk
/// the killed one left open and says so; the chunk then is what a closed one is (its session
/// ended, its index whole, `summary.json` counting the rows `poses.csv` holds) and replays.
fn next_start_closes(dir: &Path, chunk: &Path) {
    assert!(!chunk.join("summary.json").exists(), "{chunk:?}");
    let before = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
    assert!(!before.complete());
    let frames = before.depth_count();
    let run = mousepose()
        .args(["run", "--json", "--seconds", "0.5", "--config"])
        .arg(dir.join("rig.toml"))
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .env("RUST_LOG", "info")
        .output()
        .expect("test set-up");
    let log = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{log}");
    assert!(
        log.contains("closed a chunk that an earlier run left open") && log.contains(&chunk.display().to_string()),
        "{log}"
    );
    let after = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
    assert!(after.complete(), "{chunk:?}");
    assert_eq!(after.depth_count(), frames);
    assert!(
        matches!(
            after.index_status(mousepose::io::session::CameraRole::Depth),
            Some(mousepose::io::store::IndexStatus::Loaded)
        ),
        "{chunk:?}: the index was not written"
    );
    assert!(after.damage().depth.is_clean(), "{chunk:?}");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(chunk.join("summary.json")).expect("summary.json")).expect("whole");
    assert_eq!(summary["rows"].as_u64(), Some(pose_rows(chunk) as u64), "{summary:#}");
    assert_eq!(summary["closed_at_next_start"], true, "{summary:#}");
    let replayed = dir.join("replayed");
    let replay = mousepose()
        .arg("replay")
        .arg(chunk)
        .arg("--out")
        .arg(&replayed)
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .output()
        .expect("test set-up");
    assert!(replay.status.success(), "{}", String::from_utf8_lossy(&replay.stderr));
    assert_eq!(pose_rows(&replayed), frames, "{chunk:?}");
}

/// Issue 63 item 4: a daemon killed (SIGKILL) while it records leaves its chunk readable, and
/// the next start closes it.
#[test]
fn issue63_the_next_start_closes_the_chunk_a_killed_daemon_left_open() {
    let tmp = tempfile::tempdir().expect("test set-up");
    let (chunk, _) = killed_while_recording(tmp.path(), false);
    next_start_closes(tmp.path(), &chunk);
}

/// Issue 63 item 4: the same for a daemon killed while the disk is full (its session could
/// not be closed and `poses.csv` was failing).
#[test]
fn issue63_the_next_start_closes_the_chunk_a_daemon_killed_on_a_full_disk_left_open() {
    if !crate::run::is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let tmp = tempfile::tempdir().expect("test set-up");
    let (chunk, _disk) = killed_while_recording(tmp.path(), true);
    next_start_closes(tmp.path(), &chunk);
}
