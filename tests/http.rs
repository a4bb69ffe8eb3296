//! The daemon's HTTP server: the live page, `/metrics`, `/status` and the pictures, while
//! `mousepose run` works on the fixture session's depth and Aravis's fake camera on 127.0.0.1;
//! the page rendered by headless Chromium; a remote address refused without `allow_remote`, and
//! requests without the bearer token refused with it.

use crate::capture_aravis::ChildGuard;
use crate::run::{daemon, fake_camera, rig_full, session_depth, terminate};
use crate::util::mousepose;
use mousepose::runtime::http::client::{Answer, get};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant};

/// A port free on loopback now.
pub(crate) fn free_port() -> u16 {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").expect("test set-up");
    listener.local_addr().expect("test set-up").port()
}

fn fetch(address: SocketAddr, path: &str, token: Option<&str>) -> Answer {
    get(address, path, token, Duration::from_secs(10)).unwrap_or_else(|e| panic!("GET {path}: {e}"))
}

/// Polls `/status` until `ready` holds for it (at most `limit`); returns it.
pub(crate) fn wait_status(
    address: SocketAddr,
    limit: Duration,
    ready: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = Instant::now() + limit;
    let mut last = serde_json::Value::Null;
    while Instant::now() < deadline {
        if let Ok(a) = get(address, "/status", None, Duration::from_secs(2)) {
            if a.status == 200 {
                last = serde_json::from_slice(&a.body).expect("/status is JSON");
                if ready(&last) {
                    return last;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    panic!("the status did not get there within {limit:?}: {last:#}");
}

/// A series of an exposition: its name and labels.
pub(crate) type SeriesKey = (String, Vec<(String, String)>);
/// The samples of an exposition.
pub(crate) type Series = BTreeMap<SeriesKey, f64>;

/// Checks `text` strictly against the OpenMetrics text format as Prometheus reads it: every
/// family declared (`# HELP`, `# TYPE`) before its samples, sample names the family's name with
/// the suffixes its type allows, well-formed labels and values, histogram buckets cumulative up
/// to `+Inf` equal to `_count`, no series twice, `# EOF` last. Returns the samples.
fn parse_exposition(text: &str) -> Result<Series, String> {
    let name_ok = |n: &str| {
        !n.is_empty()
            && n.chars()
                .enumerate()
                .all(|(i, c)| c.is_ascii_alphabetic() || c == '_' || c == ':' || (i > 0 && c.is_ascii_digit()))
    };
    let mut lines: Vec<&str> = text.split('\n').collect();
    if lines.pop() != Some("") || lines.pop() != Some("# EOF") {
        return Err("the exposition does not end with `# EOF` and a newline".into());
    }
    let mut types: BTreeMap<String, String> = BTreeMap::new();
    let mut helped = std::collections::BTreeSet::new();
    let mut series = Series::new();
    let mut buckets: BTreeMap<SeriesKey, Vec<(f64, f64)>> = BTreeMap::new();
    for (i, line) in lines.iter().enumerate() {
        let at = |what: &str| format!("line {}: {what}: {line:?}", i + 1);
        if let Some(rest) = line.strip_prefix("# ") {
            let mut parts = rest.splitn(3, ' ');
            let (kind, name) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
            if !name_ok(name) || !name.starts_with("mousepose_") {
                return Err(at("a family name not of mousepose"));
            }
            match kind {
                "HELP" => {
                    helped.insert(name.to_owned());
                }
                "TYPE" => {
                    let t = parts.next().unwrap_or("");
                    if !["counter", "gauge", "histogram", "info", "stateset", "unknown"].contains(&t) {
                        return Err(at("an unknown type"));
                    }
                    if types.insert(name.to_owned(), t.to_owned()).is_some() {
                        return Err(at("a family declared twice"));
                    }
                }
                "UNIT" => {
                    if !name.ends_with(parts.next().unwrap_or("?")) {
                        return Err(at("a unit that is not the name's suffix"));
                    }
                }
                _ => return Err(at("an unknown comment")),
            }
            continue;
        }
        let (head, value) = line.rsplit_once(' ').ok_or_else(|| at("no value"))?;
        let value: f64 = match value {
            "+Inf" => f64::INFINITY,
            "-Inf" => f64::NEG_INFINITY,
            v => v.parse().map_err(|_| at("a value that is not a number"))?,
        };
        let (name, labels) = match head.split_once('{') {
            Some((n, rest)) => (n, rest.strip_suffix('}').ok_or_else(|| at("labels not closed"))?),
            None => (head, ""),
        };
        let mut parsed = Vec::new();
        let mut rest = labels;
        while !rest.is_empty() {
            let (key, after) = rest.split_once("=\"").ok_or_else(|| at("a label without =\""))?;
            if !name_ok(key) {
                return Err(at("a bad label name"));
            }
            let mut end = None;
            let mut escaped = false;
            for (k, c) in after.char_indices() {
                match (escaped, c) {
                    (true, _) => escaped = false,
                    (false, '\\') => escaped = true,
                    (false, '"') => {
                        end = Some(k);
                        break;
                    }
                    _ => {}
                }
            }
            let end = end.ok_or_else(|| at("a label value not closed"))?;
            parsed.push((key.to_owned(), after[..end].to_owned()));
            rest = after[end + 1..].strip_prefix(',').unwrap_or(&after[end + 1..]);
        }
        let family = types
            .iter()
            .filter(|(f, t)| {
                let suffixes: &[&str] = match t.as_str() {
                    "counter" => &["_total", "_created"],
                    "histogram" => &["_bucket", "_sum", "_count", "_created"],
                    "info" => &["_info"],
                    _ => &[""],
                };
                suffixes.iter().any(|s| name.strip_suffix(s) == Some(f.as_str()))
            })
            .map(|(f, t)| (f.clone(), t.clone()))
            .next()
            .ok_or_else(|| at("a sample of no declared family"))?;
        if !helped.contains(&family.0) {
            return Err(at("a family without # HELP"));
        }
        if family.1 == "histogram" && name.ends_with("_bucket") {
            let le = parsed
                .iter()
                .position(|(k, _)| k == "le")
                .ok_or_else(|| at("a bucket without le"))?;
            let (_, bound) = parsed.remove(le);
            let bound: f64 = if bound == "+Inf" {
                f64::INFINITY
            } else {
                bound.parse().map_err(|_| at("a bad le"))?
            };
            buckets
                .entry((family.0.clone(), parsed.clone()))
                .or_default()
                .push((bound, value));
            parsed.push(("le".into(), format!("{bound}")));
        }
        if series.insert((name.to_owned(), parsed), value).is_some() {
            return Err(at("a series twice"));
        }
    }
    for ((family, labels), b) in &buckets {
        let count = series
            .get(&(format!("{family}_count"), labels.clone()))
            .ok_or_else(|| format!("{family}{labels:?} has buckets but no _count"))?;
        if !b.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 <= w[1].1) {
            return Err(format!(
                "{family}{labels:?}: buckets not cumulative in ascending le: {b:?}"
            ));
        }
        if b.last().map(|l| (l.0, l.1)) != Some((f64::INFINITY, *count)) {
            return Err(format!("{family}{labels:?}: the +Inf bucket is not the count"));
        }
    }
    Ok(series)
}

pub(crate) fn value(series: &Series, name: &str, labels: &[(&str, &str)]) -> f64 {
    let key = (
        name.to_owned(),
        labels.iter().map(|(k, v)| ((*k).to_owned(), (*v).to_owned())).collect(),
    );
    *series
        .get(&key)
        .unwrap_or_else(|| panic!("no {name}{labels:?} in the metrics"))
}

#[test]
fn the_exposition_check_refuses_what_prometheus_would() {
    let good = "# HELP mousepose_x X.\n# TYPE mousepose_x counter\nmousepose_x_total{camera=\"depth\"} 3\n# EOF\n";
    assert!(parse_exposition(good).is_ok());
    for bad in [
        // No EOF; a sample before its type; a counter without _total; a bad value; a
        // histogram whose +Inf bucket is not its count.
        "# HELP mousepose_x X.\n# TYPE mousepose_x counter\nmousepose_x_total 3\n",
        "mousepose_x_total 3\n# HELP mousepose_x X.\n# TYPE mousepose_x counter\n# EOF\n",
        "# HELP mousepose_x X.\n# TYPE mousepose_x counter\nmousepose_x 3\n# EOF\n",
        "# HELP mousepose_x X.\n# TYPE mousepose_x gauge\nmousepose_x three\n# EOF\n",
        "# HELP mousepose_h H.\n# TYPE mousepose_h histogram\nmousepose_h_sum 1\nmousepose_h_count 2\n\
         mousepose_h_bucket{le=\"1\"} 1\nmousepose_h_bucket{le=\"+Inf\"} 1\n# EOF\n",
    ] {
        assert!(parse_exposition(bad).is_err(), "{bad}");
    }
}

fn http_rig(dir: &Path, color: bool, http: &str) -> std::path::PathBuf {
    rig_full(dir, &session_depth(), color, "min_free_percent = 0\n", http)
}

#[test]
fn the_endpoints_answer_while_the_daemon_runs_and_the_page_renders_in_chromium() {
    let tmp = tempfile::tempdir().unwrap();
    let _camera = fake_camera();
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = http_rig(tmp.path(), true, &format!("address = \"{address}\"\n"));
    let child = daemon(&rig, None);
    let first = wait_status(address, Duration::from_secs(60), |s| {
        s["poses"].as_u64() > Some(5) && s["cameras"]["color"]["captured"].as_u64() > Some(5)
    });
    for key in [
        "dir",
        "info",
        "cameras",
        "stages",
        "edges",
        "end_to_end_latency",
        "statuses",
        "recording",
    ] {
        assert!(first.get(key).is_some(), "no {key} in {first:#}");
    }

    let metrics = fetch(address, "/metrics", None);
    assert_eq!(metrics.status, 200);
    assert!(
        metrics
            .content_type
            .as_deref()
            .is_some_and(|t| t.starts_with("application/openmetrics-text"))
    );
    let text = String::from_utf8(metrics.body).unwrap();
    let before = parse_exposition(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    for family in [
        "mousepose_frames_paired_total",
        "mousepose_camera_up",
        "mousepose_stage_latency_seconds_count",
        "mousepose_end_to_end_latency_seconds_count",
        "mousepose_queue_depth",
        "mousepose_poses_total",
        "mousepose_chunk",
        "mousepose_recorded_bytes_total",
        "mousepose_disk_free_bytes",
        "mousepose_recording_paused",
        "mousepose_process_resident_memory_bytes",
    ] {
        assert!(before.keys().any(|(n, _)| n == family), "no {family} in\n{text}");
    }
    assert_eq!(value(&before, "mousepose_camera_up", &[("camera", "color")]), 1.0);
    // Counters an alert takes the increase of are there from the start, at 0 until the
    // first event (a series that appears with its first increment hides that increment).
    for camera in ["depth", "color"] {
        for (name, reason) in [
            ("mousepose_frames_dropped_total", "queue_full"),
            ("mousepose_frames_lost_before_capture_total", "camera_gap"),
            ("mousepose_frames_not_recorded_total", "disk_low"),
        ] {
            value(&before, name, &[("camera", camera), ("reason", reason)]);
        }
    }
    value(&before, "mousepose_poses_total", &[("status", "no_background")]);
    std::thread::sleep(Duration::from_secs(2));
    let after = parse_exposition(&String::from_utf8(fetch(address, "/metrics", None).body).unwrap()).unwrap();
    for camera in ["depth", "color"] {
        let captured = |s: &Series| value(s, "mousepose_frames_captured_total", &[("camera", camera)]);
        assert!(captured(&after) > captured(&before), "{camera} frames did not move");
    }
    let e2e = |s: &Series| value(s, "mousepose_end_to_end_latency_seconds_count", &[]);
    assert!(e2e(&after) > e2e(&before));

    // The bottom view stays while the colour camera streams, even when one depth frame was
    // paired with no colour frame.
    for picture in ["/live/depth.png", "/live/mouse.png", "/live/bottom.png"] {
        let png = fetch(address, picture, None);
        assert_eq!(
            (png.status, png.content_type.as_deref()),
            (200, Some("image/png")),
            "{picture}"
        );
        assert!(png.body.starts_with(b"\x89PNG"), "{picture}");
    }
    let events = fetch(address, "/events", None);
    let events: serde_json::Value = serde_json::from_slice(&events.body).unwrap();
    assert!(
        events
            .as_array()
            .unwrap()
            .iter()
            .any(|e| e["text"].as_str().unwrap_or("").contains("serving the live page")),
        "{events:#}"
    );
    let history: serde_json::Value = serde_json::from_slice(&fetch(address, "/history", None).body).unwrap();
    assert!(!history.as_array().unwrap().is_empty());
    let text = fetch(address, "/status?format=text", None);
    assert!(String::from_utf8_lossy(&text.body).contains("color: streaming"));
    // Only reading: anything but GET is refused.
    assert_eq!(fetch(address, "/nothing", None).status, 404);

    // `mousepose status` reads the same status.
    let status = mousepose()
        .args(["status", "--address", &address.to_string()])
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    assert!(String::from_utf8_lossy(&status.stdout).contains("depth: streaming"));

    screenshot_of_the_page(address, tmp.path());
    let (exit, out, err) = terminate(child, Duration::from_secs(30));
    assert!(exit.success(), "{err}");
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(report["poses"].as_u64() >= first["poses"].as_u64(), "{report:#}");
}

/// Headless Chromium opens the page: the pictures load, the status fills in, and the screenshot
/// is not blank.
fn screenshot_of_the_page(address: SocketAddr, dir: &Path) {
    let chromium = |extra: &[&str]| {
        let profile = tempfile::tempdir_in(dir).expect("test set-up");
        let out = std::process::Command::new("chromium")
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--hide-scrollbars",
                "--window-size=900,1300",
                "--virtual-time-budget=4000",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .args(extra)
            .arg(format!("http://{address}/"))
            .output()
            .expect("chromium (installed by scripts/setup.sh)");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let dom = chromium(&["--dump-dom"]);
    // Each picture's placeholder is hidden once its image has loaded.
    for placeholder in ["depth-none", "bottom-none"] {
        let tag = dom
            .split('<')
            .find(|t| t.contains(&format!("id=\"{placeholder}\"")))
            .unwrap_or_else(|| panic!("no {placeholder} in\n{dom}"));
        assert!(tag.contains("hidden"), "the image of {placeholder} did not load: {tag}");
    }
    assert!(dom.contains("streaming"), "the status did not fill in:\n{dom}");
    let shot = dir.join("page.png");
    chromium(&[&format!("--screenshot={}", shot.display())]);
    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&shot).expect("a screenshot"),
    ));
    let mut reader = decoder.read_info().expect("a PNG screenshot");
    let mut pixels = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut pixels).expect("a PNG screenshot");
    let channels = info.color_type.samples();
    let colours: std::collections::HashSet<&[u8]> = pixels[..info.buffer_size()].chunks(channels).collect();
    assert!(
        colours.len() > 200,
        "the screenshot is nearly blank ({} colours)",
        colours.len()
    );
    if let Ok(keep) = std::env::var("MOUSEPOSE_KEEP_SCREENSHOT") {
        std::fs::copy(&shot, keep).expect("the screenshot kept");
    }
}

/// Runs the daemon with `rig`, which it must refuse as a usage error (exit 1); its stderr.
fn refused_at_start(rig: &Path) -> String {
    let run = mousepose()
        .args(["run", "--seconds", "1", "--config"])
        .arg(rig)
        .output()
        .expect("test set-up");
    assert_eq!(run.status.code(), Some(1));
    String::from_utf8_lossy(&run.stderr).into_owned()
}

#[test]
fn a_remote_address_needs_allow_remote_and_then_a_token() {
    let tmp = tempfile::tempdir().unwrap();
    let err = refused_at_start(&http_rig(tmp.path(), false, "address = \"0.0.0.0:8470\"\n"));
    assert!(err.contains("http.address") && err.contains("allow_remote"), "{err}");
    let err = refused_at_start(&http_rig(
        tmp.path(),
        false,
        "address = \"0.0.0.0:8470\"\nallow_remote = true\n",
    ));
    assert!(err.contains("http.token_file"), "{err}");

    // With a token (served on loopback here: no test listens beyond this machine).
    let token = "f3a9c2d81b7e4a60b5c3";
    let token_file = tmp.path().join("token");
    std::fs::write(&token_file, format!("{token}\n")).unwrap();
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = http_rig(
        tmp.path(),
        false,
        &format!("address = \"{address}\"\nallow_remote = true\ntoken_file = {token_file:?}\n"),
    );
    let child: ChildGuard = daemon(&rig, None);
    let deadline = Instant::now() + Duration::from_secs(30);
    while get(address, "/", None, Duration::from_secs(1)).is_err() {
        assert!(Instant::now() < deadline, "the server did not start");
        std::thread::sleep(Duration::from_millis(100));
    }
    for path in ["/", "/metrics", "/status", "/live/depth.png"] {
        assert_eq!(fetch(address, path, None).status, 401, "{path}");
        assert_eq!(fetch(address, path, Some("wrong-token-0000000")).status, 401, "{path}");
    }
    assert_eq!(fetch(address, "/status", Some(token)).status, 200);
    assert_eq!(fetch(address, &format!("/metrics?token={token}"), None).status, 200);
    let status = mousepose().args(["status", "--config"]).arg(&rig).output().unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let status = mousepose()
        .args(["status", "--address", &address.to_string()])
        .output()
        .unwrap();
    assert_eq!(status.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&status.stderr).contains("--token-file"));
    let (exit, _, err) = terminate(child, Duration::from_secs(30));
    assert!(exit.success(), "{err}");
}

#[test]
fn status_without_a_daemon_says_so() {
    let port = free_port();
    let out = mousepose()
        .args(["status", "--address", &format!("127.0.0.1:{port}")])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot reach") && err.contains("mousepose run"), "{err}");
}

#[test]
fn an_address_in_use_stops_the_daemon_before_it_starts_a_run() {
    let tmp = tempfile::tempdir().unwrap();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = taken.local_addr().unwrap();
    let rig = http_rig(tmp.path(), false, &format!("address = \"{address}\"\n"));
    let run = mousepose()
        .args(["run", "--seconds", "5", "--config"])
        .arg(&rig)
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("cannot listen on") && err.contains(&address.to_string()),
        "{err}"
    );
    assert!(!tmp.path().join("out").exists(), "a run directory was made");
}

#[test]
fn a_client_that_never_finishes_its_request_does_not_hold_up_sigterm() {
    let tmp = tempfile::tempdir().unwrap();
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = http_rig(tmp.path(), false, &format!("address = \"{address}\"\n"));
    let child = daemon(&rig, None);
    wait_status(address, Duration::from_secs(30), |s| s["poses"].as_u64() > Some(0));
    // Half a request, never finished, and a finished one kept alive.
    let mut slow = std::net::TcpStream::connect(address).unwrap();
    std::io::Write::write_all(&mut slow, b"GET /status HTTP/1.1\r\nHost: x\r\n").unwrap();
    let mut idle = std::net::TcpStream::connect(address).unwrap();
    std::io::Write::write_all(&mut idle, b"GET /status HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    let started = Instant::now();
    let (exit, _, err) = terminate(child, Duration::from_secs(15));
    assert!(exit.success(), "{err}");
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "{:?} to stop",
        started.elapsed()
    );
    drop((slow, idle));
}

/// The colour camera's state in a `/status`, and its reason when away.
fn color_state(status: &serde_json::Value) -> (String, String) {
    let state = &status["cameras"]["color"]["state"];
    (
        state["state"].as_str().unwrap_or("").to_owned(),
        state["reason"].as_str().unwrap_or("").to_owned(),
    )
}

/// A colour camera killed for good is `away` in `/status` within the configured stall time
/// of its last frame (not once the driver's GigE timeouts let go of it), and the stall time
/// is the rig config's: 400 ms here, against the default 2 s.
#[test]
fn a_killed_colour_camera_is_away_in_the_status_within_the_configured_stall_time() {
    let _port = crate::capture_aravis::take_port();
    let tmp = tempfile::tempdir().unwrap();
    let camera = fake_camera();
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = http_rig(tmp.path(), true, &format!("address = \"{address}\"\n"));
    let text = std::fs::read_to_string(&rig)
        .unwrap()
        .replace("stall_ms = 1000", "stall_ms = 400");
    std::fs::write(&rig, text).unwrap();
    let child = daemon(&rig, None);
    wait_status(address, Duration::from_secs(60), |s| {
        color_state(s).0 == "streaming" && s["cameras"]["color"]["captured"].as_u64() > Some(30)
    });
    drop(camera);
    let killed = Instant::now();
    let away = wait_status(address, Duration::from_secs(30), |s| color_state(s).0 == "away");
    let noticed = killed.elapsed();
    let (_, reason) = color_state(&away);
    let (status, _, err) = terminate(child, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
    // The goal is the stall time plus half a second; the test allows for a loaded machine.
    assert!(
        noticed < Duration::from_millis(400 + 2500),
        "away {noticed:?} after the kill: {away:#}"
    );
    let silent: f64 = reason
        .strip_prefix("no frame for ")
        .and_then(|r| r.strip_suffix(" s"))
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("reason {reason:?}"));
    assert!(
        (0.4..1.5).contains(&silent),
        "taken for gone after {silent} s of silence, with a 0.4 s stall time"
    );
}

/// Idle connections cannot use up the daemon's descriptors: 300 clients that connect and
/// never ask are closed after the idle time-out, `/status` still answers while they are open,
/// and the daemon's open descriptors come back to what they were.
#[test]
fn idle_connections_are_closed_and_do_not_use_up_the_descriptors() {
    let tmp = tempfile::tempdir().unwrap();
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = http_rig(tmp.path(), false, &format!("address = \"{address}\"\n"));
    let child = daemon(&rig, None);
    wait_status(address, Duration::from_secs(60), |s| s["poses"].as_u64() > Some(5));
    let descriptors = || std::fs::read_dir(format!("/proc/{}/fd", child.0.id())).unwrap().count();
    let before = descriptors();
    let idle: Vec<std::net::TcpStream> = (0..300)
        .map(|_| std::net::TcpStream::connect(address).unwrap())
        .collect();
    // Answered while the idle clients hold their connections (after them in the queue at
    // worst: within the idle time-out).
    let answered = get(address, "/status", None, Duration::from_secs(15)).expect("/status answers");
    assert_eq!(answered.status, 200);
    let deadline = Instant::now() + Duration::from_secs(30);
    while descriptors() > before + 20 {
        assert!(
            Instant::now() < deadline,
            "{} descriptors open with 300 idle clients, {before} before them",
            descriptors()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    drop(idle);
    let (status, _, err) = terminate(child, Duration::from_secs(30));
    assert!(status.success(), "{status}: {err}");
}

/// Whether a sample of `name` is one that only counts up: a counter's `_total`, a histogram's
/// `_count`, `_sum` and `_bucket`.
fn counts_up(name: &str) -> bool {
    ["_total", "_count", "_sum", "_bucket"]
        .iter()
        .any(|s| name.ends_with(s))
}

/// `/metrics` of a live daemon, scraped again and again: every fall or disappearance of a
/// series that only counts up is kept (Prometheus would read either as a reset).
pub(crate) struct Scraper {
    address: SocketAddr,
    last: Option<Series>,
    falls: Vec<String>,
    pub(crate) scrapes: usize,
}

impl Scraper {
    pub(crate) fn new(address: SocketAddr) -> Self {
        Self {
            address,
            last: None,
            falls: Vec::new(),
            scrapes: 0,
        }
    }

    /// Scrapes every 50 ms for `seconds`, each exposition checked as Prometheus reads it.
    pub(crate) fn scrape_for(&mut self, seconds: f64) {
        let until = Instant::now() + Duration::from_secs_f64(seconds);
        while Instant::now() < until {
            let text = String::from_utf8(fetch(self.address, "/metrics", None).body).expect("UTF-8 metrics");
            let now = parse_exposition(&text).unwrap_or_else(|e| panic!("{e}\n{text}"));
            self.scrapes += 1;
            if let Some(before) = &self.last {
                for (key, &was) in before.iter().filter(|((name, _), _)| counts_up(name)) {
                    match now.get(key) {
                        Some(&is) if is >= was => {}
                        is => self
                            .falls
                            .push(format!("scrape {}: {key:?} {was} -> {is:?}", self.scrapes)),
                    }
                }
            }
            self.last = Some(now);
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The last exposition.
    pub(crate) fn last(&self) -> &Series {
        self.last.as_ref().expect("scraped at least once")
    }

    pub(crate) fn assert_none_fell(&self) {
        assert!(self.falls.is_empty(), "counters fell:\n{}", self.falls.join("\n"));
    }
}

/// Issue 48 item 1: `/metrics` scraped again and again while faults hit a live run (the
/// current chunk's directory removed, the run directory moved away and removed, SIGHUP):
/// no counter ever falls or vanishes (Prometheus would read either as a reset and count the
/// whole value again), and what left the run's directory is counted on a counter of its own.
#[test]
fn issue48_no_counter_ever_falls_through_faults() {
    let tmp = tempfile::tempdir().unwrap();
    let _camera = fake_camera();
    let port = free_port();
    let address: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let rig = http_rig(tmp.path(), true, &format!("address = \"{address}\"\n"));
    let out = tmp.path().join("out");
    let child = daemon(&rig, None);
    wait_status(address, Duration::from_secs(60), |s| {
        s["cameras"]["depth"]["recorded"].as_u64() > Some(30) && s["cameras"]["color"]["recorded"].as_u64() > Some(30)
    });
    let mut metrics = Scraper::new(address);
    let run = || std::fs::read_dir(&out).unwrap().next().unwrap().unwrap().path();
    metrics.scrape_for(2.0);
    // The chunk being written, removed in place.
    let mut chunks: Vec<_> = std::fs::read_dir(run()).unwrap().map(|e| e.unwrap().path()).collect();
    chunks.sort();
    // (A summary written into it at that very moment may keep it: the files are gone anyway.)
    let _ = std::fs::remove_dir_all(chunks.last().unwrap());
    metrics.scrape_for(3.0);
    // The run directory moved away, and the moved copy removed.
    let run = run();
    let moved = tmp.path().join("moved");
    std::fs::rename(&run, &moved).unwrap();
    std::fs::remove_dir_all(&moved).unwrap();
    metrics.scrape_for(3.0);
    crate::run::signal(&child, "HUP");
    metrics.scrape_for(2.0);
    let (exit, _, err) = terminate(child, Duration::from_secs(30));
    assert!(exit.success(), "{err}");
    metrics.assert_none_fell();
    assert!(!err.contains("panicked"), "{err}");
    let last = metrics.last();
    let lost = |camera: &str| {
        ["removed", "moved"]
            .iter()
            .map(|r| {
                value(
                    last,
                    "mousepose_frames_lost_after_recording_total",
                    &[("camera", camera), ("reason", r)],
                )
            })
            .sum::<f64>()
    };
    assert!(lost("depth") > 0.0 && lost("color") > 0.0, "the faults were not seen");
    let lost_bytes: f64 = ["removed", "moved"]
        .iter()
        .map(|r| value(last, "mousepose_lost_after_recording_bytes_total", &[("reason", r)]))
        .sum();
    assert!(lost_bytes > 0.0);
    assert!(value(last, "mousepose_recorded_bytes_total", &[]) > lost_bytes);
    assert!(metrics.scrapes > 50, "{} scrapes", metrics.scrapes);
}
