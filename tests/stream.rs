//! The live pose stream (issue 46): a stuck subscriber holds at most its queues, the daemon
//! publishes poses and events that `mousepose listen` and the Python subscriber of
//! `docs/FORMATS.md` (run as written there) read.

use crate::run::{daemon, rig_full, session_depth, terminate};
use crate::util::{mousepose, repo_root};
use mousepose::engine::project_python;
use mousepose::runtime::stream::{Endpoint, Publisher, StreamConfig, Subscriber, Topic};
use std::io::BufRead as _;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Waits (at most 30 s) until `publisher` counts `n` subscribers.
fn wait_for_subscribers(publisher: &Publisher, n: u64) {
    let start = Instant::now();
    while publisher.handle().stats().subscribers() != n {
        assert!(start.elapsed() < Duration::from_secs(30), "no subscriber counted");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A subscriber that never reads: everything published is sent or counted as dropped, and
/// what waits for it is bounded by the high-water marks (counted, not timed).
#[test]
fn issue46_a_stuck_subscriber_holds_at_most_the_high_water_marks_and_every_message_is_counted() {
    let tmp = tempfile::tempdir().unwrap();
    let endpoint = Endpoint::Ipc(tmp.path().join("stream.sock"));
    let config = StreamConfig {
        queue: 8,
        high_water_mark: 10,
        ..StreamConfig::at(endpoint.clone())
    };
    let publisher = Publisher::start(&config).unwrap();
    let handle = publisher.handle();
    // No subscriber: nothing is even made.
    handle.publish(Topic::Poses, |_| unreachable!("a message made with no subscriber"));
    let stuck = Subscriber::connect(&endpoint, &[Topic::Poses]).unwrap();
    wait_for_subscribers(&publisher, 1);
    const N: u64 = 5000;
    for _ in 0..N {
        handle.publish(Topic::Poses, |seq| format!("{seq:016}").repeat(1024).into_bytes());
    }
    publisher.stop();
    let s = handle.summary();
    assert_eq!(s.published["poses"], N, "{s:?}");
    assert_eq!(
        s.sent["poses"] + s.dropped["queue_full"] + s.dropped["send_failed"],
        N,
        "{s:?}"
    );
    // Only now does it read: it finds at most what libzmq held for it (the publisher's
    // high-water mark, its own receive mark of 1000, what the socket buffers carry).
    let mut got = 0u64;
    while stuck.next(Duration::from_millis(500)).unwrap().is_some() {
        got += 1;
    }
    assert!(got > 0, "the subscriber got nothing");
    assert!(
        got <= 10 + 1000 + 64,
        "{got} of {N} messages waited for a subscriber that never read"
    );
}

/// A reader that fell behind reads every message waiting at once: of the poses, only the
/// newest (the others skipped, as their `seq` shows), and every event in the order sent; the
/// next read waits for the next message. Read one at a time instead, the same messages come
/// oldest first (issue 64).
#[test]
fn issue64_a_reader_that_fell_behind_gets_the_newest_pose_and_every_event() {
    let tmp = tempfile::tempdir().unwrap();
    let endpoint = Endpoint::Ipc(tmp.path().join("stream.sock"));
    let config = StreamConfig {
        queue: 1000,
        high_water_mark: 1000,
        ..StreamConfig::at(endpoint.clone())
    };
    let publisher = Publisher::start(&config).unwrap();
    let handle = publisher.handle();
    let newest = Subscriber::connect(&endpoint, &Topic::ALL).unwrap();
    let oldest = Subscriber::connect(&endpoint, &Topic::ALL).unwrap();
    wait_for_subscribers(&publisher, 2);
    let message = |topic: &str, seq: u64| format!(r#"{{"topic":"{topic}","seq":{seq}}}"#).into_bytes();
    let seq = |body: &str| {
        serde_json::from_str::<serde_json::Value>(body).unwrap()["seq"]
            .as_u64()
            .unwrap()
    };
    // A subscription reaches the publisher after the connection: poses until both hear one.
    let start = Instant::now();
    let (mut heard_newest, mut heard_oldest) = (false, false);
    while !(heard_newest && heard_oldest) {
        assert!(start.elapsed() < Duration::from_secs(30), "no subscription took");
        handle.publish(Topic::Poses, |seq| message("poses", seq));
        heard_newest |= !newest.newest(Duration::from_millis(20)).unwrap().is_empty();
        heard_oldest |= !oldest.newest(Duration::from_millis(20)).unwrap().is_empty();
    }
    while !newest.newest(Duration::from_millis(200)).unwrap().is_empty() {}
    while !oldest.newest(Duration::from_millis(200)).unwrap().is_empty() {}
    let base = handle.summary().published["poses"];
    for k in 0..300 {
        handle.publish(Topic::Poses, |seq| message("poses", seq));
        if k % 100 == 50 {
            handle.publish(Topic::Events, |seq| message("events", seq));
        }
    }
    // All sent (the thread sends what it was given before it ends).
    publisher.stop();
    assert_eq!(handle.summary().sent["poses"], base + 300, "{:?}", handle.summary());
    let last = base + 299;
    // One at a time: the oldest first.
    let first = oldest.next(Duration::from_secs(10)).unwrap().expect("a message");
    assert_eq!((first.0, seq(&first.1)), (Topic::Poses, base));
    // All at once: by the time the other reader has heard the last pose, it has come here
    // too (the same messages, from one publisher, on the same machine).
    while oldest
        .next(Duration::from_secs(10))
        .unwrap()
        .is_some_and(|(t, b)| !(t == Topic::Poses && seq(&b) == last))
    {
        assert!(start.elapsed() < Duration::from_secs(60), "the poses never all came");
    }
    let mut heard = Vec::new();
    while heard
        .last()
        .is_none_or(|(t, b): &(Topic, String)| *t != Topic::Poses || seq(b) != last)
    {
        heard.extend(newest.newest(Duration::from_secs(10)).unwrap());
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the newest pose never came: {heard:?}"
        );
    }
    let poses: Vec<u64> = heard
        .iter()
        .filter(|(t, _)| *t == Topic::Poses)
        .map(|(_, b)| seq(b))
        .collect();
    let events: Vec<u64> = heard
        .iter()
        .filter(|(t, _)| *t == Topic::Events)
        .map(|(_, b)| seq(b))
        .collect();
    assert_eq!(events, [0, 1, 2], "every event, in order: {heard:?}");
    assert!(
        poses.len() <= 3 && poses.ends_with(&[last]),
        "a backlog of poses: {poses:?}"
    );
    assert!(newest.newest(Duration::from_millis(200)).unwrap().is_empty());
}

/// The ```python block of docs/FORMATS.md, as written there.
fn documented_subscriber() -> String {
    let text = std::fs::read_to_string(repo_root().join("docs/FORMATS.md")).expect("test set-up");
    let start = text
        .find("```python\nimport json, time, zmq")
        .expect("the subscriber in FORMATS.md")
        + 10;
    let end = start + text[start..].find("```").expect("the block ends");
    text[start..end].to_owned()
}

/// A daemon on the fixture session with its stream on a socket file of `dir`, each pose
/// predicted 30 ms ahead beside it.
fn streaming_daemon(dir: &Path) -> (crate::capture_aravis::ChildGuard, String) {
    let endpoint = format!("ipc://{}", dir.join("stream.sock").display());
    let http = format!("address = \"127.0.0.1:0\"\n[stream]\nendpoint = \"{endpoint}\"\nlead_ms = 30\n");
    let rig = rig_full(dir, &session_depth(), false, "min_free_percent = 0\n", &http);
    (daemon(&rig, None), endpoint)
}

#[test]
fn issue46_the_documented_python_subscriber_and_listen_read_a_running_daemon() {
    let tmp = tempfile::tempdir().unwrap();
    let (daemon, endpoint) = streaming_daemon(tmp.path());
    // The subscriber of the docs, word for word but for the endpoint.
    let script = documented_subscriber().replace("tcp://127.0.0.1:8471", &endpoint);
    assert!(script.contains(&endpoint), "{script}");
    let mut child = crate::capture_aravis::ChildGuard(
        Command::new(project_python())
            .args(["-c", &script])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut lines = std::io::BufReader::new(child.0.stdout.take().unwrap()).lines();
    let mut poses = Vec::new();
    // Until the mouse is found (the background is learnt live first): at most a minute of poses.
    while poses.len() < 1800 && (poses.len() < 5 || !poses.iter().any(|l: &String| l.contains(" ok ("))) {
        let line = lines.next().expect("the subscriber ended").unwrap();
        if !line.starts_with("entered") {
            poses.push(line);
        }
    }
    drop(child);
    for line in &poses {
        let mut words = line.split(' ');
        assert!(words.next().unwrap().parse::<u64>().is_ok(), "{line}");
        assert!(
            ["ok", "no_mouse", "no_background"].contains(&words.next().unwrap()),
            "{line}"
        );
    }
    assert!(
        poses.iter().any(|l| l.contains(" ok (")),
        "no pose of the mouse: {poses:?}"
    );

    // `listen --json`: poses with their stamps and 24 joints, then a chunk begun (every 3 s).
    let out = mousepose()
        .args(["listen", &endpoint, "--json", "--count", "3", "--seconds", "60"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let messages: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let poses: Vec<_> = messages.iter().filter(|m| m["topic"] == "poses").collect();
    assert!(!poses.is_empty(), "{messages:?}");
    for m in poses {
        assert_eq!(m["version"], 1);
        assert_eq!(m["host_clock"], "monotonic");
        assert_eq!(m["joints"].as_object().unwrap().len(), 24, "{m}");
        let (arrived, published) = (
            m["depth"]["host_ns"].as_u64().unwrap(),
            m["published_ns"].as_u64().unwrap(),
        );
        assert!(published >= arrived, "{m}");
        // The pose predicted for the config's lead, for the frame's arrival plus the lead.
        let predicted = &m["predicted"];
        assert_eq!(predicted["lead_ms"], 30.0, "{m}");
        assert_eq!(predicted["for_ns"].as_u64(), Some(arrived + 30_000_000), "{m}");
        assert_eq!(predicted["joints"].as_object().unwrap().len(), 24, "{m}");
        for (name, joint) in m["joints"].as_object().unwrap() {
            assert_eq!(joint.is_null(), predicted["joints"][name].is_null(), "{name}: {m}");
        }
    }
    let out = mousepose()
        .args([
            "listen",
            &endpoint,
            "--topic",
            "events",
            "--count",
            "1",
            "--seconds",
            "60",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.starts_with("events #") && text.contains("chunk_begun chunk="),
        "{text}"
    );
    // `listen --newest`: the newest pose each time, in order.
    let out = mousepose()
        .args([
            "listen",
            &endpoint,
            "--newest",
            "--topic",
            "poses",
            "--json",
            "--count",
            "2",
            "--seconds",
            "60",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let seqs: Vec<u64> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["seq"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert!(seqs.len() == 2 && seqs[0] < seqs[1], "{seqs:?}");

    let (status, stdout, err) = terminate(daemon, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    let report: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let stream = &report["stream"];
    assert_eq!(stream["endpoint"], endpoint.as_str(), "{report:#}");
    assert!(stream["sent"]["poses"].as_u64().unwrap() >= 8, "{stream}");
    assert!(stream["sent"]["events"].as_u64().unwrap() >= 1, "{stream}");
}

#[test]
fn issue46_a_bad_or_taken_endpoint_is_refused_in_one_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    for (endpoint, why) in [
        ("tcp://localhost:8471", "IP:PORT"),
        ("udp://127.0.0.1:8471", "tcp://IP:PORT or ipc://PATH"),
        ("tcp://0.0.0.0:8471", "allow_remote"),
    ] {
        let http = format!("address = \"127.0.0.1:0\"\n[stream]\nendpoint = \"{endpoint}\"\n");
        let rig = rig_full(tmp.path(), &session_depth(), false, "", &http);
        let out = mousepose().args(["run", "--config"]).arg(&rig).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{endpoint}: {err}");
        assert!(
            err.contains("stream.endpoint") && err.contains(why),
            "{endpoint}: {err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    // An address in use: refused, naming it.
    let holder = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let taken = Endpoint::Tcp(holder.local_addr().unwrap());
    let e = Publisher::start(&StreamConfig::at(taken.clone()))
        .unwrap_err()
        .to_string();
    assert!(e.contains(&taken.to_string()), "{e}");
    // The daemon refuses it at start, before it opens a camera: the user's to fix.
    let http = format!("address = \"127.0.0.1:0\"\n[stream]\nendpoint = \"{taken}\"\n");
    let rig = rig_full(tmp.path(), &session_depth(), false, "", &http);
    let out = mousepose().args(["run", "--config"]).arg(&rig).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("cannot bind the pose stream") && err.contains(&taken.to_string()),
        "{err}"
    );
    drop(holder);
}
