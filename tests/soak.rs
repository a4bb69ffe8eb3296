//! The daemon through the faults of a rig's life, in about a minute and a half: the short
//! version of `scripts/soak` (which runs them for an hour), one round of its faults three at
//! once, every pair meeting once; `/metrics` scraped throughout. Then: no counter ever fell,
//! every frame is accounted for, every chunk is closed and replays whole, the daemon's
//! descriptors and threads are back where they were.

use crate::capture_aravis::take_port;
use crate::http::{Scraper, free_port, value, wait_status};
use crate::run::{
    Tmpfs, assert_accounted, assert_replays_whole, chunks, daemon, fake_camera, is_root, report, rig_full,
    session_depth, terminate,
};
use crate::util::repo_root;
use std::net::SocketAddr;
use std::process::Command;
use std::time::Duration;

/// Open descriptors and threads of a process.
fn descriptors_and_threads(pid: u32) -> (usize, usize) {
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, Iterator::count);
    let threads = std::fs::read_dir(format!("/proc/{pid}/task")).map_or(0, Iterator::count);
    (fds, threads)
}

/// Issues 48 and 63: the daemon through one round of the soak's faults, three at once, every
/// pair of the seven meeting once (`scripts/lib/soak-schedule.py --short`, run by
/// `scripts/lib/soak-faults.py` as `scripts/soak` runs its hour): a full disk, the colour
/// camera killed, the depth camera stalled past the stall time and for less (a gap), chunk
/// boundaries (a chunk every 3 s), SIGHUP, the run directory moved away and removed. The
/// daemon lives through all, loses nothing unaccounted, and every chunk closes and replays.
#[test]
fn issue48_a_short_soak_through_every_fault_loses_nothing_unaccounted() {
    if !is_root() {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let _port = take_port();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let _disk = Tmpfs::mount(&out, "160m");
    let stall = tmp.path().join("stall");
    let depth = format!("{}stall_while = {stall:?}\n", session_depth());
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = rig_full(
        tmp.path(),
        &depth,
        true,
        "min_free_percent = 0\n",
        &format!("address = \"{address}\"\n"),
    );
    // The schedule, from a seed: one round of every pair.
    let script = |name: &str| repo_root().join("scripts/lib").join(name);
    let schedule = tmp.path().join("faults.jsonl");
    let drawn = Command::new("python3")
        .arg(script("soak-schedule.py"))
        .args(["48", "300", "--short"])
        .output()
        .unwrap();
    assert!(drawn.status.success(), "{}", String::from_utf8_lossy(&drawn.stderr));
    std::fs::write(&schedule, &drawn.stdout).unwrap();
    let camera = fake_camera();
    let camera_pid = tmp.path().join("camera.pid");
    std::fs::write(&camera_pid, camera.0.id().to_string()).unwrap();
    let child = daemon(&rig, None);
    let pid = child.0.id();
    wait_status(address, Duration::from_secs(60), |s| {
        s["cameras"]["color"]["recorded"].as_u64() > Some(30) && s["cameras"]["depth"]["recorded"].as_u64() > Some(30)
    });
    let mut metrics = Scraper::new(address);
    metrics.scrape_for(3.0);
    let before = descriptors_and_threads(pid);
    let mut faults = Command::new("python3")
        .arg(script("soak-faults.py"))
        .arg(&schedule)
        .arg(tmp.path().join("faults-done.txt"))
        .args(["--daemon", &pid.to_string(), "--out"])
        .arg(&out)
        .arg("--stall")
        .arg(&stall)
        .args([
            "--status",
            &format!("http://{address}/status"),
            "--period",
            "3",
            "--camera-pid",
        ])
        .arg(&camera_pid)
        .args(["--camera-serial", "MP-RUN", "--until", "240"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let ran = loop {
        if let Some(status) = faults.try_wait().unwrap() {
            break status;
        }
        metrics.scrape_for(1.0);
    };
    let mut met = String::new();
    std::io::Read::read_to_string(&mut faults.stdout.take().unwrap(), &mut met).unwrap();
    let done = std::fs::read_to_string(tmp.path().join("faults-done.txt")).unwrap();
    assert!(ran.success(), "{met}\n{done}");
    eprintln!("{met}");
    metrics.scrape_for(4.0);
    let after = descriptors_and_threads(pid);
    let (status, stdout, err) = terminate(child, Duration::from_secs(30));
    drop(camera);
    let last_camera = std::fs::read_to_string(&camera_pid).unwrap();
    Command::new("kill").arg(last_camera.trim()).status().unwrap();
    assert!(status.success(), "{status}: {err}");
    assert!(!err.contains("panicked"), "{err}");
    metrics.assert_none_fell();

    // Every fault was seen, and came back.
    let report = report(&stdout);
    let (depth, color) = (&report["cameras"]["depth"], &report["cameras"]["color"]);
    let ended = |camera: &serde_json::Value| {
        let outages = camera["outages"].as_array().unwrap();
        assert!(outages.iter().all(|o| o["end_ns"].is_u64()), "{camera:#}");
        outages.len()
    };
    // Each fault in three episodes: the colour camera killed three times, the depth camera
    // stalled past the stall time three times.
    assert!(ended(color) >= 3, "{report:#}");
    assert!(ended(depth) >= 3, "{report:#}");
    assert!(
        err.contains("recording paused") && err.contains("recording resumed"),
        "{err}"
    );
    // Every frame accounted for, in the report and on `/metrics`, and what the report calls
    // recorded is on the disk.
    assert_accounted(depth);
    assert_accounted(color);
    let last = metrics.last();
    for (camera, name) in [(depth, "depth"), (color, "color")] {
        assert!(
            camera["not_recorded_total"].as_u64() > Some(0),
            "the full disk lost nothing: {report:#}"
        );
        // Only what the moves took away is lost after recording: moved, or removed when the
        // moved copy went before the daemon saw it move.
        let lost = camera["lost_after_recording"].as_object();
        assert!(
            lost.is_none_or(|l| l.keys().all(|k| k == "moved" || k == "removed")),
            "{report:#}"
        );
        let full = value(
            last,
            "mousepose_frames_not_recorded_total",
            &[("camera", name), ("reason", "write_error")],
        );
        assert!(full > 0.0, "{name}: no write error counted on /metrics");
    }
    let chunks = chunks(&out);
    let on_disk: u64 = chunks
        .iter()
        .map(|c| mousepose::io::session::SessionReader::open(c).map_or(0, |s| s.depth_count() as u64))
        .sum();
    let lost = &depth["lost_after_recording"];
    let moved = lost["moved"].as_u64().unwrap_or(0) + lost["removed"].as_u64().unwrap_or(0);
    assert!(moved > 0, "the run directory was moved three times: {report:#}");
    assert_eq!(
        Some(on_disk + moved),
        depth["recorded"].as_u64(),
        "{chunks:?}: {report:#}"
    );
    for chunk in &chunks {
        assert!(chunk.join("summary.json").is_file(), "{chunk:?} has no summary");
        if chunk.join("session.toml").exists() {
            assert_replays_whole(chunk, &tmp.path().join("replayed"));
        } else {
            // A chunk whose whole time the disk was full: its poses, and no half a session.
            let mut entries: Vec<_> = std::fs::read_dir(chunk)
                .unwrap()
                .map(|e| e.unwrap().file_name().into_string().unwrap())
                .collect();
            entries.sort();
            assert_eq!(entries, ["poses.csv", "poses_raw.csv", "summary.json"], "{chunk:?}");
        }
    }
    // Back where they were: the cameras' reconnections, the disk's pauses and the reload left
    // nothing open behind them.
    assert!(after.0 <= before.0 + 4, "descriptors {before:?} -> {after:?}");
    assert!(after.1 <= before.1 + 2, "threads {before:?} -> {after:?}");
}
