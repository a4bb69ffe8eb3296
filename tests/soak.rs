//! The daemon through the faults of a rig's life, in a minute and a half: the short version of
//! `scripts/soak` (which runs them for an hour). The colour camera (Aravis's fake GigE camera on
//! 127.0.0.1) killed and started again twice, the depth camera (the fixture session, played)
//! stalled once, the disk (a small tmpfs) filled and freed twice, a SIGHUP; `/metrics` scraped
//! throughout. Then: no counter ever fell, every frame is accounted for, every chunk is closed
//! and replays whole, the daemon's descriptors and threads are back where they were.

use crate::capture_aravis::take_port;
use crate::http::{Scraper, free_port, value, wait_status};
use crate::run::{
    Tmpfs, assert_accounted, assert_replays_whole, chunks, daemon, fake_camera, is_root, report, rig_full,
    session_depth, signal, terminate,
};
use std::io::Write as _;
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

/// Fills the file system of `dir` with a file of its own until a write fails (ENOSPC); returns
/// the file.
fn fill(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("filler");
    let mut file = std::fs::File::create(&path).expect("test set-up");
    let block = vec![7u8; 1 << 20];
    while file.write_all(&block).is_ok() {}
    drop(file);
    path
}

/// Open descriptors and threads of a process.
fn descriptors_and_threads(pid: u32) -> (usize, usize) {
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, Iterator::count);
    let threads = std::fs::read_dir(format!("/proc/{pid}/task")).map_or(0, Iterator::count);
    (fds, threads)
}

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
    let mut camera = Some(fake_camera());
    let child = daemon(&rig, None);
    let pid = child.0.id();
    wait_status(address, Duration::from_secs(60), |s| {
        s["cameras"]["color"]["recorded"].as_u64() > Some(30) && s["cameras"]["depth"]["recorded"].as_u64() > Some(30)
    });
    let mut metrics = Scraper::new(address);
    metrics.scrape_for(3.0);
    let before = descriptors_and_threads(pid);
    let mut restart_colour = |metrics: &mut Scraper| {
        drop(camera.take());
        metrics.scrape_for(3.0);
        camera = Some(fake_camera());
        metrics.scrape_for(6.0);
    };
    let fill_and_free = |metrics: &mut Scraper| {
        let filler = fill(&out);
        metrics.scrape_for(4.0);
        std::fs::remove_file(filler).unwrap();
        metrics.scrape_for(6.0);
    };
    restart_colour(&mut metrics);
    std::fs::write(&stall, b"").unwrap();
    metrics.scrape_for(4.0);
    std::fs::remove_file(&stall).unwrap();
    metrics.scrape_for(6.0);
    fill_and_free(&mut metrics);
    signal(&child, "HUP");
    metrics.scrape_for(2.0);
    restart_colour(&mut metrics);
    fill_and_free(&mut metrics);
    let after = descriptors_and_threads(pid);
    let (status, stdout, err) = terminate(child, Duration::from_secs(30));
    drop(camera);
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
    assert!(ended(color) >= 2, "{report:#}");
    assert!(ended(depth) >= 1, "{report:#}");
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
        assert!(
            camera
                .get("lost_after_recording")
                .is_none_or(|l| l.as_object().is_some_and(|m| m.is_empty()))
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
    assert_eq!(Some(on_disk), depth["recorded"].as_u64(), "{chunks:?}");
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
