//! `mousepose run`, the daemon, against real camera software: OpenNI2's Dummy depth device and
//! the `arv-fake-gv-camera-0.8` program on 127.0.0.1 (opened by address, no discovery), killed
//! and started again mid-run. systemd's notifications are read from a socket of the test's.

use crate::capture_aravis::{ChildGuard, start_fake_program, take_port};
use crate::util::{mousepose, repo_root};
use mousepose::io::session::SessionReader;
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn fake_camera() -> ChildGuard {
    start_fake_program(&["-s", "MP-RUN"])
}

fn rig(dir: &Path, color: bool) -> PathBuf {
    let mut text = format!(
        "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\nwidth = 320\nheight = 240\nfps = 30\n\
         [output]\ndir = {:?}\nchunk_minutes = 0.05\nmin_free_gb = 0\nmin_free_percent = 0\n\
         [reconnect]\nstall_ms = 1000\nmax_wait_ms = 1000\n",
        dir.join("out")
    );
    if color {
        text.push_str(
            "[color]\nbackend = \"aravis\"\naddress = \"127.0.0.1\"\npixel_format = \"mono8\"\n\
             region = [0, 0, 256, 64]\nfps = 30\nbuffers = 8\n",
        );
    }
    let path = dir.join("rig.toml");
    std::fs::write(&path, text).expect("test set-up");
    path
}

fn daemon(rig: &Path, notify: Option<&Path>) -> ChildGuard {
    let mut cmd = mousepose();
    cmd.args(["run", "--json", "--config"])
        .arg(rig)
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .env("RUST_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(socket) = notify {
        cmd.env("NOTIFY_SOCKET", socket);
    }
    ChildGuard(cmd.spawn().expect("test set-up"))
}

/// The run's chunk directories, in order.
fn chunks(out: &Path) -> Vec<PathBuf> {
    let mut runs: Vec<PathBuf> = std::fs::read_dir(out)
        .expect("test set-up")
        .map(|e| e.expect("test set-up").path())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    let mut chunks: Vec<PathBuf> = std::fs::read_dir(runs.remove(0))
        .expect("test set-up")
        .map(|e| e.expect("test set-up").path())
        .collect();
    chunks.sort();
    chunks
}

/// Sends SIGTERM and waits (at most `limit`) for the exit; returns its status and stdout.
fn terminate(mut child: ChildGuard, limit: Duration) -> (std::process::ExitStatus, String, String) {
    let pid = child.0.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("test set-up")
            .success()
    );
    let deadline = Instant::now() + limit;
    loop {
        if let Some(status) = child.0.try_wait().expect("test set-up") {
            let mut out = String::new();
            let mut err = String::new();
            use std::io::Read as _;
            child
                .0
                .stdout
                .take()
                .expect("test set-up")
                .read_to_string(&mut out)
                .expect("test set-up");
            child
                .0
                .stderr
                .take()
                .expect("test set-up")
                .read_to_string(&mut err)
                .expect("test set-up");
            return (status, out, err);
        }
        assert!(
            Instant::now() < deadline,
            "the daemon did not stop within {limit:?} of SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn the_daemon_rides_out_a_colour_camera_restart_and_stops_cleanly_on_sigterm() {
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig(tmp.path(), true);
    let socket_path = tmp.path().join("notify");
    let socket = UnixDatagram::bind(&socket_path).unwrap();
    socket.set_read_timeout(Some(Duration::from_millis(200))).unwrap();

    let camera = fake_camera();
    let daemon = daemon(&rig, Some(&socket_path));
    let mut said = String::new();
    let mut read_notes = |until: Instant| {
        let mut buf = [0u8; 4096];
        while Instant::now() < until {
            if let Ok(n) = socket.recv(&mut buf) {
                said.push_str(&String::from_utf8_lossy(&buf[..n]));
                said.push('\n');
            }
        }
    };
    read_notes(Instant::now() + Duration::from_secs(5));
    // The colour camera goes away for about three seconds, and comes back.
    drop(camera);
    read_notes(Instant::now() + Duration::from_secs(3));
    let camera = fake_camera();
    read_notes(Instant::now() + Duration::from_secs(7));
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    drop(camera);
    assert!(status.success(), "{status}: {err}");
    assert!(said.contains("READY=1"), "{said}");
    assert!(said.contains("WATCHDOG=1"), "{said}");
    assert!(said.contains("STATUS="), "{said}");

    let report: serde_json::Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    let color = &report["cameras"]["color"];
    let outages = color["outages"].as_array().unwrap();
    assert!(!outages.is_empty(), "{report:#}");
    let outage = &outages[0];
    assert!(outage["end_ns"].is_u64(), "the camera never came back: {report:#}");
    let before = outage["frames_before"].as_u64().unwrap();
    let captured = color["captured"].as_u64().unwrap();
    assert!(before > 10 && captured > before + 10, "{report:#}");
    let depth = &report["cameras"]["depth"];
    assert!(depth["captured"].as_u64().unwrap() > 300, "{report:#}");
    for cam in [depth, color] {
        let c = cam["captured"].as_u64().unwrap();
        let accounted = cam["paired"].as_u64().unwrap()
            + cam["unpaired"].as_u64().unwrap()
            + cam["dropped_total"].as_u64().unwrap();
        assert_eq!(c, accounted, "{cam:#}");
        assert_eq!(
            c,
            cam["recorded"].as_u64().unwrap() + cam["not_recorded_total"].as_u64().unwrap()
        );
    }

    let chunks = chunks(&tmp.path().join("out"));
    assert!(chunks.len() >= 3, "{chunks:?}");
    let mut events = String::new();
    for chunk in &chunks {
        let session = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
        assert!(session.complete(), "{chunk:?} was not closed");
        assert!(chunk.join("summary.json").is_file(), "{chunk:?}");
        let poses = std::fs::read_to_string(chunk.join("poses.csv")).unwrap();
        assert!(poses.lines().count() > 1, "{chunk:?}");
        events.push_str(&std::fs::read_to_string(chunk.join("events.jsonl")).unwrap());
    }
    assert!(events.contains("camera_disconnected"), "{events}");
    assert!(events.contains("camera_reconnected"), "{events}");
}

#[test]
fn a_daemon_killed_with_sigkill_leaves_its_chunk_readable() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig(tmp.path(), false);
    let mut daemon = daemon(&rig, None);
    let start = Instant::now();
    let first = || tmp.path().join("out");
    while !first().is_dir() || chunks(&first()).is_empty() || {
        let c = &chunks(&first())[0];
        std::fs::read_to_string(c.join("poses.csv")).map_or(0, |t| t.lines().count()) < 20
    } {
        assert!(start.elapsed() < Duration::from_secs(60), "the daemon wrote no poses");
        assert!(daemon.0.try_wait().unwrap().is_none(), "the daemon exited early");
        std::thread::sleep(Duration::from_millis(100));
    }
    daemon.0.kill().unwrap();
    daemon.0.wait().unwrap();
    let chunk = &chunks(&first())[0];
    let session = SessionReader::open(chunk).unwrap();
    assert!(!session.complete());
    assert!(session.depth_count() >= 20);
    assert_eq!(
        session.depth_frames().filter(|f| f.is_ok()).count(),
        session.depth_count()
    );
}

#[test]
fn a_bad_config_is_exit_code_1_naming_the_key() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = tmp.path().join("rig.toml");
    std::fs::write(
        &rig,
        "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\n[output]\nchunk_minutes = -1\n",
    )
    .unwrap();
    let out = mousepose().args(["run", "--config"]).arg(&rig).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("output.chunk_minutes"), "{err}");
}
