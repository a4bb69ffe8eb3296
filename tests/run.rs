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

pub(crate) fn fake_camera() -> ChildGuard {
    start_fake_program(&["-s", "MP-RUN"])
}

fn rig(dir: &Path, color: bool) -> PathBuf {
    rig_with(dir, DUMMY_DEPTH, color, "min_free_percent = 0\n")
}

/// OpenNI2's Dummy device: frames without a floor or a mouse.
const DUMMY_DEPTH: &str = "backend = \"openni2\"\nuri = \"Dummy\"\nwidth = 320\nheight = 240\nfps = 30\n";

/// The fixture session's depth frames (a mouse from the first frame), played at camera pace.
pub(crate) fn session_depth() -> String {
    format!(
        "backend = \"session\"\npath = {:?}\n",
        repo_root().join("fixtures/sessions/synthetic-small")
    )
}

/// A rig config in `dir`: the fixture session as the depth camera, no colour camera, chunks of
/// an hour in `dir/out`, never paused for disk space; its HTTP server on any free port.
pub(crate) fn session_rig(dir: &Path) -> PathBuf {
    let path = dir.join("rig.toml");
    let text = format!(
        "[depth]\n{}[output]\ndir = {:?}\nchunk_minutes = 60\nmin_free_gb = 0\nmin_free_percent = 0\n\
         [http]\naddress = \"127.0.0.1:0\"\n",
        session_depth(),
        dir.join("out")
    );
    std::fs::write(&path, text).expect("test set-up");
    path
}

/// A rig config in `dir` with the depth table `depth`, the fake camera as colour camera if
/// `color`, and `output` added to the `[output]` table; its HTTP server on any free port.
fn rig_with(dir: &Path, depth: &str, color: bool, output: &str) -> PathBuf {
    rig_full(dir, depth, color, output, "address = \"127.0.0.1:0\"\n")
}

/// As [`rig_with`], with `http` as the `[http]` table.
pub(crate) fn rig_full(dir: &Path, depth: &str, color: bool, output: &str, http: &str) -> PathBuf {
    let mut text = format!(
        "[depth]\n{depth}\
         [output]\ndir = {:?}\nchunk_minutes = 0.05\nmin_free_gb = 0\n{output}\
         [reconnect]\nstall_ms = 1000\nmax_wait_ms = 1000\n[http]\n{http}",
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

pub(crate) fn daemon(rig: &Path, notify: Option<&Path>) -> ChildGuard {
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
pub(crate) fn chunks(out: &Path) -> Vec<PathBuf> {
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

/// Sends SIGTERM and waits (at most `limit`) for the exit; returns its status, stdout and
/// stderr.
pub(crate) fn terminate(child: ChildGuard, limit: Duration) -> (std::process::ExitStatus, String, String) {
    stop_with(child, "TERM", limit)
}

/// Sends `signal` (`TERM`, `HUP`...) and waits (at most `limit`) for the exit; returns its
/// status, stdout and stderr.
pub(crate) fn stop_with(
    mut child: ChildGuard,
    signal: &str,
    limit: Duration,
) -> (std::process::ExitStatus, String, String) {
    self::signal(&child, signal);
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
            "the process did not stop within {limit:?} of SIG{signal}"
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
    let went = Instant::now();
    drop(camera);
    read_notes(Instant::now() + Duration::from_secs(3));
    let gone_s = went.elapsed().as_secs_f64();
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
    // The outage is the real gap: from the last frame before the camera went to the first
    // after it came back, so at least as long as it was gone (then its start-up, 0.4-1 s
    // here), not from when the stall was seen (1 s after its last frame) to the reopening.
    let length_s = (outage["end_ns"].as_u64().unwrap() - outage["start_ns"].as_u64().unwrap()) as f64 * 1e-9;
    assert!(
        (gone_s - 0.05..gone_s + 3.0).contains(&length_s),
        "an outage of {length_s:.2} s for a camera gone {gone_s:.2} s: {report:#}"
    );
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
    for (k, chunk) in chunks.iter().enumerate() {
        let session = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
        assert!(session.complete(), "{chunk:?} was not closed");
        // Every chunk is complete with its summary, one that no pose reached too (issue 48: a
        // chunk begun by the colour camera's frames may end before a pose of its time came).
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(chunk.join("summary.json")).unwrap()).unwrap();
        let rows = std::fs::read_to_string(chunk.join("poses.csv"))
            .unwrap()
            .lines()
            .count()
            - 1;
        assert_eq!(summary["rows"].as_u64(), Some(rows as u64), "{chunk:?}");
        assert!(rows > 0 || k > 0, "the first chunk holds no pose");
        events.push_str(&std::fs::read_to_string(chunk.join("events.jsonl")).unwrap());
    }
    assert!(events.contains("camera_disconnected"), "{events}");
    assert!(events.contains("camera_reconnected"), "{events}");
}

/// Reads systemd's notifications from `socket` into `said` until `done` holds of them (at most
/// `limit`).
fn read_notes_until(socket: &UnixDatagram, said: &mut String, limit: Duration, done: impl Fn(&str) -> bool) {
    let deadline = Instant::now() + limit;
    let mut buf = [0u8; 4096];
    while !done(said) {
        assert!(Instant::now() < deadline, "systemd was not told: {said}");
        if let Ok(n) = socket.recv(&mut buf) {
            said.push_str(&String::from_utf8_lossy(&buf[..n]));
            said.push('\n');
        }
    }
}

/// Issue 37 item 1: SIGHUP does not stop the daemon (there is nothing to reload: it says so,
/// tells systemd of the reload, and goes on); another signal that would end it stops it as
/// SIGTERM does (every chunk closed with its summary, the report printed), then fails, so that
/// systemd restarts it.
#[test]
fn issue37_sighup_leaves_the_daemon_running_and_other_signals_leave_a_report() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig(tmp.path(), false);
    let socket_path = tmp.path().join("notify");
    let socket = UnixDatagram::bind(&socket_path).unwrap();
    socket.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    let daemon = daemon(&rig, Some(&socket_path));
    let mut said = String::new();
    read_notes_until(&socket, &mut said, Duration::from_secs(60), |s| s.contains("READY=1"));
    signal(&daemon, "HUP");
    // The reload, then ready again; the reload says when it began (MONOTONIC_USEC=, in the
    // same message: systemd 253 and later require it of `Type=notify-reload`).
    read_notes_until(&socket, &mut said, Duration::from_secs(30), |s| {
        s.split_once("RELOADING=1")
            .is_some_and(|(_, after)| after.contains("READY=1"))
    });
    let (_, after) = said.split_once("RELOADING=1").unwrap();
    let usec = after.trim_start().strip_prefix("MONOTONIC_USEC=").map(|rest| {
        rest.split(|c: char| !c.is_ascii_digit())
            .next()
            .unwrap_or("")
            .parse::<u64>()
    });
    assert!(
        matches!(usec, Some(Ok(n)) if n > 0),
        "no MONOTONIC_USEC= with RELOADING=1: {said:?}"
    );
    // Still at work: a watchdog ping after the reload.
    let reloaded = said.len();
    read_notes_until(&socket, &mut said, Duration::from_secs(30), |s| {
        s[reloaded..].contains("WATCHDOG=1")
    });
    let (status, out, err) = stop_with(daemon, "USR1", Duration::from_secs(30));
    assert_eq!(status.code(), Some(2), "{status}: {err}");
    assert!(err.contains("SIGHUP"), "{err}");
    assert!(err.contains("stopped by SIGUSR1"), "{err}");
    let report = report(&out);
    assert!(report["poses"].as_u64().unwrap() > 0, "{report:#}");
    assert_accounted(&report["cameras"]["depth"]);
    for chunk in chunks(&tmp.path().join("out")) {
        let session = SessionReader::open(&chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
        assert!(session.complete(), "{chunk:?} was not closed");
        assert!(chunk.join("summary.json").is_file(), "{chunk:?}");
    }
}

#[test]
fn a_daemon_killed_with_sigkill_leaves_its_chunk_readable() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig(tmp.path(), false);
    let mut daemon = daemon(&rig, None);
    let start = Instant::now();
    let first = || tmp.path().join("out");
    // Twenty frames recorded (the recorder is its own thread: poses may run ahead of it).
    let lines = |c: &Path, file: &str| std::fs::read_to_string(c.join(file)).map_or(0, |t| t.lines().count());
    while !first().is_dir() || chunks(&first()).is_empty() || {
        let c = &chunks(&first())[0];
        lines(c, "depth/timestamps.csv") < 21 || lines(c, "poses.csv") < 2
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
    // As `record`'s: the frames whose timestamps were written, give or take the last two.
    assert!(session.depth_count() >= 18, "{} frames", session.depth_count());
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

/// Sends `signal` (`STOP`, `CONT`, `KILL`...) to a child.
pub(crate) fn signal(child: &ChildGuard, signal: &str) {
    let status = Command::new("kill")
        .arg(format!("-{signal}"))
        .arg(child.0.id().to_string())
        .status()
        .expect("test set-up");
    assert!(status.success());
}

pub(crate) fn report(out: &str) -> serde_json::Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

/// Every frame of `camera` in the report is accounted for by both branches.
pub(crate) fn assert_accounted(camera: &serde_json::Value) {
    let n = |key: &str| camera[key].as_u64().unwrap_or_else(|| panic!("no {key}: {camera:#}"));
    assert_eq!(
        n("captured"),
        n("paired") + n("unpaired") + n("dropped_total"),
        "{camera:#}"
    );
    assert_eq!(n("captured"), n("recorded") + n("not_recorded_total"), "{camera:#}");
}

#[test]
fn a_frozen_colour_camera_is_an_outage_while_depth_keeps_flowing() {
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), true, "");
    let camera = fake_camera();
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(5));
    signal(&camera, "STOP");
    std::thread::sleep(Duration::from_secs(4));
    signal(&camera, "CONT");
    std::thread::sleep(Duration::from_secs(8));
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    drop(camera);
    assert!(status.success(), "{status}: {err}");
    let report = report(&out);
    let color = &report["cameras"]["color"];
    let outage = &color["outages"][0];
    assert!(
        outage["reason"].as_str().is_some_and(|r| r.contains("no frame")),
        "{report:#}"
    );
    assert!(outage["end_ns"].is_u64(), "the camera never came back: {report:#}");
    // The outage is the real gap: from the last frame before the freeze to the first after
    // it (4 s frozen), not from when the driver let go to the reopening.
    let length_s = (outage["end_ns"].as_u64().unwrap() - outage["start_ns"].as_u64().unwrap()) as f64 * 1e-9;
    assert!(
        (3.5..6.0).contains(&length_s),
        "an outage of {length_s:.2} s: {report:#}"
    );
    let before = outage["frames_before"].as_u64().unwrap();
    assert!(before > 30, "{report:#}");
    assert!(color["captured"].as_u64().unwrap() > before + 30, "{report:#}");
    // The first chunk holds both cameras and whole seconds of poses (the colour camera is
    // tried before the pipeline starts, so its opening does not end the chunk at once).
    let first = chunks(&tmp.path().join("out")).remove(0);
    let first_session = SessionReader::open(&first).unwrap();
    assert!(
        first_session
            .meta()
            .camera(mousepose::io::session::CameraRole::Color)
            .is_some(),
        "chunk {first:?} has no colour camera"
    );
    let rows = std::fs::read_to_string(first.join("poses.csv"))
        .unwrap()
        .lines()
        .count();
    assert!(rows > 30, "{rows} lines in the first chunk's poses");
    // Depth went on through the outage: about 30 frames a second for the whole run.
    let depth = &report["cameras"]["depth"];
    assert!(depth["captured"].as_u64().unwrap() > 350, "{report:#}");
    assert!(report["statuses"]["ok"].as_u64().unwrap_or(0) > 300, "{report:#}");
    assert_accounted(depth);
    assert_accounted(color);
}

/// A GigE camera controlled by another application (here the test itself, in-process; a
/// daemon restarted right after a SIGKILL meets the same until the camera's heartbeat timeout
/// runs out) is reported as held, tried again, and taken once it is free.
#[test]
fn a_camera_held_by_another_application_is_reported_and_taken_once_free() {
    use mousepose::core::frame::PixelFormat;
    use mousepose::runtime::capture::aravis::{AravisColor, AravisConfig};
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), true, "");
    let camera = fake_camera();
    let config = AravisConfig {
        address: Some("127.0.0.1".into()),
        pixel_format: PixelFormat::Mono8,
        ..AravisConfig::default()
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    let holder = loop {
        match AravisColor::open(&config) {
            Ok(holder) => break holder,
            Err(e) => {
                assert!(Instant::now() < deadline, "the fake camera does not open: {e}");
                std::thread::sleep(Duration::from_millis(200));
            }
        }
    };
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(5));
    drop(holder);
    std::thread::sleep(Duration::from_secs(12));
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    drop(camera);
    assert!(status.success(), "{status}: {err}");
    assert!(err.contains("is held"), "the held camera was not reported: {err}");
    let report = report(&out);
    let color = &report["cameras"]["color"];
    assert!(color["captured"].as_u64().unwrap() > 100, "{report:#}");
    assert_eq!(color["state"]["state"], "streaming", "{report:#}");
}

#[test]
fn lossy_packets_are_counted_and_every_chunk_replays() {
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), true, "");
    let camera = start_fake_program(&["-s", "MP-LOSSY", "-r", "50"]);
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(10));
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    drop(camera);
    assert!(status.success(), "{status}: {err}");
    let report = report(&out);
    let color = &report["cameras"]["color"];
    let lost: u64 = color["lost_before_capture"]
        .as_object()
        .unwrap()
        .values()
        .filter_map(serde_json::Value::as_u64)
        .sum();
    assert!(lost > 0, "no incomplete frame was counted: {report:#}");
    assert_accounted(color);
    assert_accounted(&report["cameras"]["depth"]);

    let chunks = chunks(&tmp.path().join("out"));
    assert!(chunks.len() >= 3, "{chunks:?}");
    // The mouse is there from the first frame, in a background learnt live: found within a
    // second.
    let rows: Vec<String> = chunks
        .iter()
        .flat_map(|c| {
            let text = std::fs::read_to_string(c.join("poses.csv")).unwrap();
            text.lines().skip(1).map(str::to_owned).collect::<Vec<_>>()
        })
        .collect();
    assert!(rows.iter().take(30).any(|l| l.contains(",ok,")), "{rows:#?}");
    for chunk in &chunks {
        assert_replays_whole(chunk, &tmp.path().join("replayed"));
    }
}

/// `chunk` is a closed session that `mousepose replay` reads whole (into `out`): a pose row for
/// each of its depth frames.
pub(crate) fn assert_replays_whole(chunk: &Path, out: &Path) {
    let session = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
    assert!(session.complete(), "{chunk:?} was not closed");
    let run = mousepose()
        .arg("replay")
        .arg(chunk)
        .arg("--out")
        .arg(out)
        .args(["--force", "--json"])
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .output()
        .expect("test set-up");
    assert!(
        run.status.success(),
        "{chunk:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert_eq!(pose_rows(out), session.depth_count(), "{chunk:?}");
}

/// A small tmpfs mounted at a directory for the life of the guard (needs root).
pub(crate) struct Tmpfs(PathBuf);

impl Tmpfs {
    pub(crate) fn mount(dir: &Path, size: &str) -> Self {
        std::fs::create_dir_all(dir).expect("test set-up");
        let status = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "mousepose-test"])
            .arg(dir)
            .status()
            .expect("test set-up");
        assert!(status.success(), "cannot mount a tmpfs at {dir:?}");
        Tmpfs(dir.to_owned())
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

pub(crate) fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// Runs the daemon (depth only, from the fixture session) on a 24 MB tmpfs for `seconds`;
/// returns its report and log, and the chunks left on the disk.
fn run_on_small_disk(output: &str, seconds: u64) -> (serde_json::Value, String, Vec<PathBuf>) {
    let tmp = tempfile::tempdir().expect("test set-up");
    let _disk = Tmpfs::mount(&tmp.path().join("out"), "24m");
    let rig = rig_with(tmp.path(), &session_depth(), false, output);
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(seconds));
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    let report = report(&out);
    let chunks = chunks(&tmp.path().join("out"));
    for chunk in &chunks[..1] {
        // Closed before the disk filled: whole, every frame readable.
        let session = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
        assert_eq!(
            session.depth_frames().filter(|f| f.is_ok()).count(),
            session.depth_count()
        );
        assert!(session.depth_count() > 0, "{chunk:?}");
    }
    (report, err, chunks)
}

#[test]
fn a_full_disk_pauses_recording_and_the_daemon_lives_on() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    // No threshold: the disk fills up and the writes fail (ENOSPC).
    let (report, err, _) = run_on_small_disk("min_free_percent = 0\n", 14);
    let depth = &report["cameras"]["depth"];
    assert!(
        depth["not_recorded"]["write_error"].as_u64().unwrap_or(0) > 0,
        "{report:#}"
    );
    assert!(err.contains("recording paused"), "{err}");
    assert!(report["poses"].as_u64().unwrap() > 300, "{report:#}");
    assert_accounted(depth);

    // Half of the disk as the threshold: recording pauses before the disk is full.
    let (report, err, _) = run_on_small_disk("min_free_percent = 50\n", 10);
    let depth = &report["cameras"]["depth"];
    assert!(
        depth["not_recorded"]["disk_low"].as_u64().unwrap_or(0) > 0,
        "{report:#}"
    );
    assert!(depth["not_recorded"].get("write_error").is_none(), "{report:#}");
    assert!(err.contains("disk space low"), "{err}");
    assert_eq!(report["poses_not_written"], 0, "{report:#}");
}

#[test]
fn with_a_background_reference_a_mouse_present_from_the_first_frame_is_found_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), false, "");
    // The fixture session is a rendering: its reference is the rendered empty cage.
    let run = mousepose()
        .args(["run", "--seconds", "3", "--json", "--config"])
        .arg(&rig)
        .arg("--background")
        .arg(repo_root().join("fixtures/sessions/synthetic-small"))
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let poses = std::fs::read_to_string(chunks(&tmp.path().join("out"))[0].join("poses.csv")).unwrap();
    let first = poses.lines().nth(1).expect("a pose");
    assert!(first.contains(",ok,"), "{first}");

    // A recorded reference of another size than the camera is refused before anything opens.
    let recorded = chunks(&tmp.path().join("out")).remove(0);
    let other = tmp.path().join("rig-small.toml");
    std::fs::write(
        &other,
        "[depth]\nbackend = \"openni2\"\nuri = \"Dummy\"\nwidth = 320\nheight = 240\n",
    )
    .unwrap();
    let run = mousepose()
        .args(["run", "--seconds", "3", "--config"])
        .arg(&other)
        .arg("--background")
        .arg(&recorded)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(1));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("640x480") && err.contains("320x240"), "{err}");
}

#[test]
fn a_write_error_pauses_recording_and_keeps_what_was_written() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), false, "");
    // Writes past 3 MB fail (EFBIG): the frame file of the first chunk breaks after about a
    // second of frames. SIGXFSZ is ignored, as a daemon's would be.
    let run = Command::new("bash")
        .arg("-c")
        .arg("trap '' XFSZ; ulimit -f 3072; exec \"$0\" run --seconds 5 --json --config \"$1\"")
        .arg(env!("CARGO_BIN_EXE_mousepose"))
        .arg(&rig)
        .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("recording paused"), "{err}");
    let report = report(&String::from_utf8_lossy(&run.stdout));
    let depth = &report["cameras"]["depth"];
    assert!(
        depth["not_recorded"]["write_error"].as_u64().unwrap_or(0) > 0,
        "{report:#}"
    );
    assert!(depth["recorded"].as_u64().unwrap() > 0, "{report:#}");
    assert_accounted(depth);
    assert!(report["poses"].as_u64().unwrap() > 100, "{report:#}");
    // What was written before the error reads back, every frame whole.
    let chunk = &chunks(&tmp.path().join("out"))[0];
    let session = SessionReader::open(chunk).unwrap();
    assert!(session.depth_count() > 0);
    assert_eq!(
        session.depth_frames().filter(|f| f.is_ok()).count(),
        session.depth_count()
    );
}

#[test]
fn a_camera_that_cannot_be_stopped_at_the_end_does_not_fail_the_run() {
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), true, "");
    let camera = fake_camera();
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(5));
    // Frozen just before the stop: stopping its acquisition times out.
    signal(&camera, "STOP");
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    signal(&camera, "CONT");
    drop(camera);
    assert!(status.success(), "{status}: {err}");
    let report = report(&out);
    assert!(
        report["cameras"]["color"]["captured"].as_u64().unwrap() > 30,
        "{report:#}"
    );
}

/// Issue 31 item 7: on a disk that fills up (no threshold: the writes fail with ENOSPC),
/// recording resumes within seconds of space coming back, not at the next chunk (an hour
/// away here); no chunk is left with an empty `session.toml` or an empty `summary.json`.
#[test]
fn issue31_recording_resumes_soon_after_a_full_disk_and_every_chunk_reads_back() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    // About 6 MB left: full within two seconds of frames; full for long enough that recording
    // tries again (and fails) while it is.
    let (report, err, chunks, _disk) = run_on_a_disk_freed_later(26, 16, 10);
    assert!(err.contains("recording paused"), "{err}");
    assert_accounted(&report["cameras"]["depth"]);
    // Recording went on after the space came back, in a chunk of its own.
    let later: usize = chunks[1..]
        .iter()
        .filter_map(|c| SessionReader::open(c).ok())
        .map(|s| s.depth_count())
        .sum();
    assert!(
        later > 0,
        "nothing recorded after the disk had room again: {chunks:?}\n{err}"
    );
    for chunk in &chunks {
        // Every session begun reads back (no empty or cut session.toml) ...
        if chunk.join("session.toml").exists() {
            let session = SessionReader::open(chunk).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
            assert!(session.depth_count() > 0, "{chunk:?}");
        }
        // ... and a summary is whole or absent, never empty; no hidden partial file is left.
        for entry in std::fs::read_dir(chunk).expect("test set-up") {
            let name = entry.expect("test set-up").file_name().to_string_lossy().into_owned();
            assert!(!name.contains(".partial-"), "{chunk:?}: {name}");
        }
        if let Ok(text) = std::fs::read(chunk.join("summary.json")) {
            serde_json::from_slice::<serde_json::Value>(&text).unwrap_or_else(|e| panic!("{chunk:?}: {e}"));
        }
    }
    // The first chunk, closed while the disk was full, got its summary once there was room.
    assert!(chunks[0].join("summary.json").is_file(), "{chunks:?}");
}

/// Issue 31 item 7, poses: a `poses.csv` that cannot be written on a full disk is written
/// again within seconds of space coming back, in the same chunk when it held no row (a run
/// that only makes poses: nothing else would begin a new chunk for an hour).
#[test]
fn issue31_poses_are_written_again_soon_after_a_full_disk() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let tmp = tempfile::tempdir().expect("test set-up");
    let out = tmp.path().join("out");
    let _disk = Tmpfs::mount(&out, "16m");
    // Not a byte left.
    let filler = out.join("filler");
    assert!(
        std::fs::write(&filler, vec![1u8; 20 << 20]).is_err(),
        "the disk did not fill"
    );
    let rig = tmp.path().join("rig.toml");
    std::fs::write(
        &rig,
        format!(
            "[depth]\n{}[output]\ndir = {out:?}\nrecord = \"never\"\nchunk_minutes = 60\nmin_free_gb = 0\n\
             min_free_percent = 0\n[http]\naddress = \"127.0.0.1:0\"\n",
            session_depth()
        ),
    )
    .expect("test set-up");
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(4));
    std::fs::remove_file(&filler).expect("test set-up");
    std::thread::sleep(Duration::from_secs(9));
    let (status, stdout, err) = terminate(daemon, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    let report = report(&stdout);
    assert!(report["poses_not_written"].as_u64().unwrap_or(0) > 0, "{report:#}");
    let chunks = chunks(&out);
    assert_eq!(chunks.len(), 1, "{chunks:?}");
    let poses = std::fs::read_to_string(chunks[0].join("poses.csv")).expect("poses.csv");
    assert!(poses.lines().count() > 30, "{} lines\n{err}", poses.lines().count());
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(chunks[0].join("summary.json")).expect("summary.json"))
            .expect("a whole summary");
    assert!(summary["rows_lost"].as_u64().unwrap_or(0) > 0, "{summary:#}");
}

/// The rows of a `poses.csv` (its header not counted), 0 when it is missing.
pub(crate) fn pose_rows(chunk: &Path) -> usize {
    std::fs::read_to_string(chunk.join("poses.csv")).map_or(0, |t| t.lines().count().saturating_sub(1))
}

/// Issue 37 item 2, issue 48 item 1: a chunk's directory deleted under the daemon is not
/// reported as on the disk: its frames stay counted as recorded (a count never goes down) and
/// are counted as lost after recording (`removed`), its poses as not written, and recording
/// goes on at once in a new chunk. Recorded less lost after recording is what is on the disk.
#[test]
fn issue37_a_chunk_directory_removed_under_the_daemon_is_counted_as_lost_and_recording_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let rig = session_rig(tmp.path());
    let daemon = daemon(&rig, None);
    let start = Instant::now();
    while !out.is_dir() || chunks(&out).is_empty() || pose_rows(&chunks(&out)[0]) < 30 {
        assert!(start.elapsed() < Duration::from_secs(60), "the daemon wrote no poses");
        std::thread::sleep(Duration::from_millis(100));
    }
    // The chunk the daemon writes, removed in place: the daemon goes on in a new chunk beside
    // it and never writes into it again, so that the removal always succeeds.
    let gone = chunks(&out).remove(0);
    std::fs::remove_dir_all(&gone).unwrap();
    let start = Instant::now();
    while chunks(&out).is_empty() || pose_rows(&chunks(&out)[0]) < 30 || {
        SessionReader::open(&chunks(&out)[0]).map_or(0, |s| s.depth_count()) < 30
    } {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "nothing written after the removal"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(!gone.exists(), "the daemon wrote into the removed chunk again");
    let (status, stdout, err) = terminate(daemon, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    assert!(err.contains("removed from the disk"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let report = report(&stdout);
    let depth = &report["cameras"]["depth"];
    assert_accounted(depth);
    let lost = depth["lost_after_recording"]["removed"].as_u64().unwrap_or(0);
    assert!(lost >= 30, "{report:#}");
    assert_eq!(depth["not_recorded_total"].as_u64(), Some(0), "{report:#}");
    // Recorded less lost is what is on the disk, frame for frame and row for row.
    let chunks = chunks(&out);
    let on_disk: usize = chunks
        .iter()
        .map(|c| {
            SessionReader::open(c)
                .unwrap_or_else(|e| panic!("{c:?}: {e}"))
                .depth_count()
        })
        .sum();
    assert_eq!(
        depth["recorded"].as_u64().map(|r| r - lost),
        Some(on_disk as u64),
        "{report:#}"
    );
    let rows: usize = chunks.iter().map(|c| pose_rows(c)).sum();
    let written = report["poses"].as_u64().unwrap() - report["poses_not_written"].as_u64().unwrap();
    assert_eq!(written, rows as u64, "{report:#}");
    assert!(report["poses_not_written"].as_u64().unwrap() >= 30, "{report:#}");
    for chunk in &chunks {
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(chunk.join("summary.json")).unwrap()).unwrap();
        assert_eq!(summary["rows"].as_u64(), Some(pose_rows(chunk) as u64), "{chunk:?}");
    }
}

/// Depth frames of the sessions in the chunks of `run` (a chunk without a readable session
/// counts 0).
fn depth_frames(run: &Path) -> u64 {
    std::fs::read_dir(run).map_or(0, |entries| {
        entries
            .map(|e| SessionReader::open(e.expect("test set-up").path()).map_or(0, |s| s.depth_count() as u64))
            .sum()
    })
}

/// Rows of the `poses.csv` files in the chunks of `run`.
fn rows_in(run: &Path) -> usize {
    std::fs::read_dir(run).map_or(0, |entries| {
        entries.map(|e| pose_rows(&e.expect("test set-up").path())).sum()
    })
}

/// Issue 48 item 6: the documented way to take a live run away: move (rename) its directory,
/// then remove the moved copy at leisure. The daemon notices the move, never writes into the
/// moved copy again and goes on in the run directory made again; the removal succeeds every
/// time, and the frames moved away are counted (`lost_after_recording`: `moved`), frame for
/// frame.
#[test]
fn issue48_a_live_run_moved_away_is_left_alone_and_its_removal_succeeds_every_time() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let rig = session_rig(tmp.path());
    let daemon = daemon(&rig, None);
    let wait_for_frames = |run: &Path| {
        let start = Instant::now();
        while depth_frames(run) < 10 || rows_in(run) < 5 {
            assert!(start.elapsed() < Duration::from_secs(60), "nothing written in {run:?}");
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    let start = Instant::now();
    while !out.is_dir() || std::fs::read_dir(&out).unwrap().next().is_none() {
        assert!(start.elapsed() < Duration::from_secs(60), "no run directory");
        std::thread::sleep(Duration::from_millis(50));
    }
    let run = std::fs::read_dir(&out).unwrap().next().unwrap().unwrap().path();
    let (mut moved_frames, mut moved_rows) = (0, 0);
    for attempt in 0..8 {
        wait_for_frames(&run);
        let moved = tmp.path().join(format!("moved-{attempt}"));
        std::fs::rename(&run, &moved).unwrap();
        // Once the daemon has noticed (its recorder and its pose sink write in the run
        // directory made again), the moved copy no longer changes.
        let start = Instant::now();
        while depth_frames(&run) == 0 || rows_in(&run) == 0 {
            assert!(start.elapsed() < Duration::from_secs(30), "the daemon did not go on");
            std::thread::sleep(Duration::from_millis(20));
        }
        let (frames, rows) = (depth_frames(&moved), rows_in(&moved));
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(
            (depth_frames(&moved), rows_in(&moved)),
            (frames, rows),
            "attempt {attempt}: written into the moved copy"
        );
        moved_frames += frames;
        moved_rows += rows;
        std::fs::remove_dir_all(&moved).unwrap_or_else(|e| panic!("attempt {attempt}: {e}"));
    }
    wait_for_frames(&run);
    let (status, stdout, err) = terminate(daemon, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("moved away"), "{err}");
    let report = report(&stdout);
    let depth = &report["cameras"]["depth"];
    assert_accounted(depth);
    assert_eq!(
        depth["lost_after_recording"],
        serde_json::json!({ "moved": moved_frames }),
        "{report:#}"
    );
    let recorded = depth["recorded"].as_u64().unwrap();
    assert_eq!(recorded - moved_frames, depth_frames(&run), "{report:#}");
    // Rows moved away were written: none is counted as not written.
    let rows: usize = chunks(&out).iter().map(|c| pose_rows(c)).sum();
    assert_eq!(report["poses_not_written"].as_u64(), Some(0), "{report:#}");
    assert_eq!(report["poses"].as_u64(), Some((rows + moved_rows) as u64), "{report:#}");
}

/// Issue 37 item 5: a configuration that can never work is refused at start in one sentence
/// (exit 1): a depth mode the camera does not have, a trigger line the colour camera does not
/// have. A camera absent now is not refused: the daemon runs without it (exit 0).
#[test]
fn issue37_a_camera_configured_as_it_can_never_work_is_refused_at_start_but_an_absent_one_is_not() {
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let run = |rig: &Path| {
        mousepose()
            .args(["run", "--seconds", "2", "--config"])
            .arg(rig)
            .env("MOUSEPOSE_MODELS", repo_root().join("fixtures/models"))
            .output()
            .unwrap()
    };
    let no_mode = "backend = \"openni2\"\nuri = \"Dummy\"\nwidth = 1234\nheight = 1000\nfps = 30\n";
    let out = run(&rig_with(tmp.path(), no_mode, false, ""));
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last().unwrap_or("");
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        last.starts_with("error: the depth camera cannot work as") && last.contains("1234x1000"),
        "{err}"
    );
    // The colour camera absent (no fake camera runs): the daemon runs without it.
    let out = run(&rig(tmp.path(), true));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("cannot open the camera"), "{err}");
    // There, with a trigger line it does not have.
    let camera = fake_camera();
    let rig = rig(tmp.path(), true);
    let text = std::fs::read_to_string(&rig).unwrap() + "trigger = \"line:Line9\"\n";
    std::fs::write(&rig, text).unwrap();
    let out = run(&rig);
    drop(camera);
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.lines().last().unwrap_or("");
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        last.starts_with("error: the color camera cannot work as") && last.contains("Line9"),
        "{err}"
    );
}

/// The `events.jsonl` lines of every chunk, and their kinds.
fn event_kinds(chunks: &[PathBuf]) -> Vec<String> {
    chunks
        .iter()
        .flat_map(|c| {
            let text = std::fs::read_to_string(c.join("events.jsonl")).unwrap_or_default();
            text.lines()
                .map(|l| {
                    let e: serde_json::Value = serde_json::from_str(l).unwrap_or_else(|e| panic!("{c:?}: {e}: {l}"));
                    e["kind"].as_str().unwrap_or("").to_owned()
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Runs the daemon (depth from the fixture session, recording) on a 32 MB tmpfs holding a
/// file of `filler_mb`, removed after `full_s` seconds; stops it `after_s` seconds later.
/// Returns its report, its log, the chunks, and the disk and directory that hold them (kept
/// while the guard lives).
fn run_on_a_disk_freed_later(
    filler_mb: usize,
    full_s: u64,
    after_s: u64,
) -> (serde_json::Value, String, Vec<PathBuf>, (Tmpfs, tempfile::TempDir)) {
    let tmp = tempfile::tempdir().expect("test set-up");
    let out = tmp.path().join("out");
    let disk = Tmpfs::mount(&out, "32m");
    let filler = out.join("filler");
    // Written until the disk is full when it is larger than the disk.
    drop(std::fs::write(&filler, vec![1u8; filler_mb << 20]));
    let rig = session_rig(tmp.path());
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(full_s));
    std::fs::remove_file(&filler).expect("test set-up");
    std::thread::sleep(Duration::from_secs(after_s));
    let (status, stdout, err) = terminate(daemon, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    let chunks = chunks(&out);
    (report(&stdout), err, chunks, (disk, tmp))
}

/// Issue 37 item 4: on a disk that fills up while poses and frames are written, every
/// `poses.csv` holds whole rows only and its `summary.json` counts exactly those; every pause
/// of recording has its resume, in the log and in `events.jsonl`.
#[test]
fn issue37_on_a_full_disk_rows_counted_are_whole_rows_and_every_pause_has_its_resume() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let (report, err, chunks, _disk) = run_on_a_disk_freed_later(26, 16, 10);
    assert_accounted(&report["cameras"]["depth"]);
    assert!(err.contains("recording paused"), "{err}");
    for chunk in &chunks {
        let Ok(text) = std::fs::read_to_string(chunk.join("poses.csv")) else {
            continue;
        };
        assert!(text.is_empty() || text.ends_with('\n'), "{chunk:?} ends with a cut row");
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(chunk.join("summary.json")).expect("summary.json")).expect("whole");
        assert_eq!(
            summary["rows"].as_u64(),
            Some(pose_rows(chunk) as u64),
            "{chunk:?}: {summary:#}"
        );
    }
    let kinds = event_kinds(&chunks);
    let paused = kinds.iter().filter(|k| *k == "recording_paused").count();
    let resumed = kinds.iter().filter(|k| *k == "recording_resumed").count();
    assert!(paused >= 1 && paused == resumed, "{kinds:?}");
    assert_eq!(
        err.matches("recording paused").count(),
        err.matches("recording resumed").count(),
        "{err}"
    );
}

/// Issue 63 item 1: a camera's gaps while the disk is full (the fixture's depth camera misses
/// a frame each loop, so about once a second) never end the run: each gap's `frames_dropped`
/// waits for room and is written once the disk has some, in order, none lost.
#[test]
fn issue63_camera_gaps_on_a_full_disk_wait_for_room_and_end_nothing() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let (report, err, chunks, _disk) = run_on_a_disk_freed_later(26, 16, 10);
    let depth = &report["cameras"]["depth"];
    assert_accounted(depth);
    assert!(
        depth["not_recorded"]["write_error"].as_u64().unwrap_or(0) > 0,
        "the disk never filled: {report:#}"
    );
    // Every gap the recorder saw is in a chunk's events: one a loop of 29 frames, less the
    // gaps of the loop the run ended in and of the first.
    let mut gaps = Vec::new();
    for chunk in &chunks {
        let text = std::fs::read_to_string(chunk.join("events.jsonl")).unwrap_or_default();
        for line in text.lines() {
            let event: serde_json::Value = serde_json::from_str(line).expect("whole lines");
            if event["kind"] == "frames_dropped" && event["role"] == "depth" {
                gaps.push(event["seq_from"].as_u64().expect("seq_from"));
            }
        }
    }
    let loops = depth["captured"].as_u64().expect("captured") / 29;
    assert!(
        gaps.len() as u64 + 2 >= loops,
        "{} gaps logged in {loops} loops: {gaps:?}\n{err}",
        gaps.len()
    );
    assert!(gaps.windows(2).all(|w| w[0] < w[1]), "gaps out of order: {gaps:?}");
    let recording = &report["recording"];
    assert_eq!(recording["events_lost"].as_u64(), Some(0), "{report:#}\n{err}");
    assert_eq!(recording["events_waiting"].as_u64(), Some(0), "{report:#}\n{err}");
}

/// Issue 37 item 4: a chunk whose session begins only once a disk full from the start has
/// room gets the cameras' `camera_opened` events (they wait for a session to go into).
#[test]
fn issue37_a_chunk_begun_on_a_full_disk_gets_its_camera_events() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let (report, err, chunks, _disk) = run_on_a_disk_freed_later(40, 4, 9);
    assert_accounted(&report["cameras"]["depth"]);
    let recorded = report["cameras"]["depth"]["recorded"].as_u64().unwrap_or(0);
    assert!(
        recorded > 0,
        "nothing recorded once the disk had room: {report:#}\n{err}"
    );
    let kinds = event_kinds(&chunks);
    assert!(kinds.iter().any(|k| k == "camera_opened"), "{kinds:?}");
    assert!(kinds.iter().any(|k| k == "recording_resumed"), "{kinds:?}");
}

/// Issue 46: a colour camera triggered in step with the depth camera (`trigger = "depth"`)
/// makes a frame for each depth frame, whatever its own frame rate (here 5 frames/s against
/// the depth camera's 30), and each depth frame gets a colour partner.
#[test]
fn issue46_a_colour_camera_triggered_by_the_depth_camera_gives_every_depth_frame_a_partner() {
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let rig = rig_with(tmp.path(), &session_depth(), true, "");
    let text = std::fs::read_to_string(&rig).unwrap();
    std::fs::write(
        &rig,
        text.replace("fps = 30\nbuffers = 8\n", "fps = 5\nbuffers = 8\ntrigger = \"depth\"\n"),
    )
    .unwrap();
    let camera = crate::capture_aravis::start_fake(&aravis_ext::FakeCameraConfig {
        serial: "MP-STEP".into(),
        trigger_frequency: Some(2_000.0),
        ..aravis_ext::FakeCameraConfig::default()
    });
    let daemon = daemon(&rig, None);
    std::thread::sleep(Duration::from_secs(8));
    let (status, out, err) = terminate(daemon, Duration::from_secs(30));
    drop(camera);
    assert!(status.success(), "{status}: {err}");
    let report = report(&out);
    let count = |camera: &str, what: &str| report["cameras"][camera][what].as_u64().unwrap_or(0);
    let depth = count("depth", "captured");
    assert!(depth > 100, "{report:#}");
    // At its own 5 frames/s the colour camera would give a sixth of this.
    assert!(count("color", "captured") * 10 >= depth * 8, "{report:#}");
    assert!(count("depth", "paired") * 10 >= depth * 8, "{report:#}");
    assert!(
        !report["cameras"]["color"].to_string().contains("trigger_failed"),
        "{report:#}"
    );
}
