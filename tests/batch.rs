//! Batches: `replay` over several sessions or a glob (resumable, one table for all), and
//! `batch --slurm` on a real one-node Slurm cluster started for the test.
#![allow(clippy::unwrap_used)] // the helpers below are test code too

use crate::util::{mousepose, repo_root};
use std::path::Path;

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let dest = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &dest);
        } else {
            std::fs::copy(entry.path(), dest).unwrap();
        }
    }
}

/// `(name, status)` of each line of `batch.csv`.
fn table(out: &Path) -> Vec<(String, String)> {
    csv::Reader::from_path(out.join("batch.csv"))
        .unwrap()
        .records()
        .map(|r| {
            let r = r.unwrap();
            (r[0].to_owned(), r[2].to_owned())
        })
        .collect()
}

#[test]
fn a_batch_replays_each_session_once_and_redoes_a_crashed_one() {
    let tmp = tempfile::tempdir().unwrap();
    let sessions = tmp.path().join("sessions");
    for name in ["mouse-a", "mouse-b"] {
        copy_dir(
            &repo_root().join("fixtures/sessions/synthetic-small"),
            &sessions.join(name),
        );
    }
    let out = tmp.path().join("out");
    let models = repo_root().join("fixtures/models");
    let run = |args: &[&str]| {
        mousepose()
            .arg("replay")
            .args(args)
            .arg("--out")
            .arg(&out)
            .arg("--models")
            .arg(&models)
            .args(["--workers", "1"])
            .output()
            .unwrap()
    };
    let pattern = format!("{}/mouse-*", sessions.display());
    let first = run(&[&pattern]);
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let done = vec![
        ("mouse-a".to_owned(), "done".to_owned()),
        ("mouse-b".to_owned(), "done".to_owned()),
    ];
    assert_eq!(table(&out), done);
    let printed = String::from_utf8_lossy(&first.stdout);
    assert!(printed.contains("2 sessions: 2 replayed, 0 skipped"), "{printed}");
    for name in ["mouse-a", "mouse-b"] {
        assert!(out.join(name).join("summary.json").is_file());
        assert!(out.join(name).join("poses.csv").is_file());
    }
    let a_poses = std::fs::read(out.join("mouse-a/poses.csv")).unwrap();

    // mouse-b "crashed": its directory has no summary, and a staging directory is left.
    std::fs::remove_file(out.join("mouse-b/summary.json")).unwrap();
    std::fs::create_dir(out.join(".mouse-b.partial-999999")).unwrap();
    let a = sessions.join("mouse-a");
    let b = sessions.join("mouse-b");
    let second = run(&[a.to_str().unwrap(), b.to_str().unwrap()]);
    assert!(second.status.success(), "{}", String::from_utf8_lossy(&second.stderr));
    assert_eq!(
        table(&out),
        vec![
            ("mouse-a".to_owned(), "skipped".to_owned()),
            ("mouse-b".to_owned(), "done".to_owned()),
        ]
    );
    assert!(out.join("mouse-b/summary.json").is_file());
    assert!(!out.join(".mouse-b.partial-999999").exists());
    // The finished session was not touched.
    assert_eq!(std::fs::read(out.join("mouse-a/poses.csv")).unwrap(), a_poses);

    // A directory that is no session fails alone: the others are listed, exit code 2.
    let junk = sessions.join("junk");
    std::fs::create_dir(&junk).unwrap();
    let third = run(&[a.to_str().unwrap(), junk.to_str().unwrap()]);
    assert_eq!(third.status.code(), Some(2));
    let rows = table(&out);
    assert_eq!(rows[0], ("mouse-a".to_owned(), "skipped".to_owned()));
    assert_eq!(rows[1], ("junk".to_owned(), "failed".to_owned()));
    assert!(String::from_utf8_lossy(&third.stderr).contains("1 of 2 sessions failed"));

    // Two sessions of one name would write to one place: refused before any work.
    let other = tmp.path().join("elsewhere/mouse-a");
    std::fs::create_dir_all(&other).unwrap();
    let clash = run(&[a.to_str().unwrap(), other.to_str().unwrap()]);
    assert_eq!(clash.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&clash.stderr).contains("the same name"));
    // A pattern that matches nothing is refused too.
    let none = run(&[&format!("{}/nothing-*", sessions.display())]);
    assert_eq!(none.status.code(), Some(1));
}

#[test]
fn batch_on_slurm_runs_a_job_array_and_gathers_every_summary() {
    // scripts/slurm-test starts munge, slurmctld and slurmd on localhost in a temporary
    // directory, runs `batch --slurm` on three rendered sessions (and again, to check that
    // finished ones are skipped), and stops them.
    let out = std::process::Command::new(repo_root().join("scripts/slurm-test"))
        .arg(env!("CARGO_BIN_EXE_mousepose"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{said}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(said.contains("slurm-test: passed"), "{said}");
}

fn signal(pid: u32, name: &str) {
    let status = std::process::Command::new("kill")
        .arg(format!("-{name}"))
        .arg(pid.to_string())
        .status()
        .unwrap();
    assert!(status.success());
}

/// Issue 31 item 11: a second batch into the output directory of a running one is refused at
/// once, naming the holder's process id, and takes nothing from it; the chunks of a daemon's
/// runs (every run has a `chunk-0000`) make a batch, each output named by run and chunk.
#[test]
fn issue31_batches_lock_their_output_and_accept_the_chunks_of_many_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let fixture = repo_root().join("fixtures/sessions/synthetic-small");
    let runs = tmp.path().join("runs");
    for chunk in [
        "20260101T000000Z/chunk-0000",
        "20260101T000000Z/chunk-0001",
        "20260102T000000Z/chunk-0000",
    ] {
        copy_dir(&fixture, &runs.join(chunk));
    }
    let out = tmp.path().join("out");
    let models = repo_root().join("fixtures/models");
    let batch = |pattern: &str| {
        let mut c = mousepose();
        c.arg("replay")
            .arg(pattern)
            .arg("--out")
            .arg(&out)
            .arg("--models")
            .arg(&models)
            .args(["--workers", "1"]);
        c
    };
    let pattern = format!("{}/*/chunk-*", runs.display());

    // The first batch, held still once it has taken the directory.
    let mut first = batch(&pattern)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lock = out.join(".mousepose-batch.lock");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while std::fs::read_to_string(&lock).map_or(true, |t| t.trim() != first.id().to_string()) {
        assert!(
            std::time::Instant::now() < deadline,
            "the first batch never took its lock"
        );
        assert!(
            first.try_wait().unwrap().is_none(),
            "the first batch ended before the test could hold it"
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    signal(first.id(), "STOP");
    let second = batch(&pattern).output().unwrap();
    signal(first.id(), "CONT");
    let err = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(1), "{err}");
    assert!(
        err.contains("in use by another batch") && err.contains(&first.id().to_string()),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");

    let first = first.wait_with_output().unwrap();
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let names: Vec<(String, String)> = table(&out);
    assert_eq!(
        names,
        vec![
            ("20260101T000000Z-chunk-0000".to_owned(), "done".to_owned()),
            ("20260101T000000Z-chunk-0001".to_owned(), "done".to_owned()),
            ("20260102T000000Z-chunk-0000".to_owned(), "done".to_owned()),
        ]
    );
    for (name, _) in &names {
        assert!(out.join(name).join("summary.json").is_file(), "{name}");
    }
    // Once the first is over, the directory is free again: everything is finished, skipped.
    let again = batch(&pattern).output().unwrap();
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert!(
        table(&out).iter().all(|(_, status)| status == "skipped"),
        "{:?}",
        table(&out)
    );
}
