//! The LSL outlet (issue 46): a replay offers its poses as an LSL stream that pylsl resolves
//! by name and reads, sample for sample what `poses.csv` holds; the reader of
//! `docs/FORMATS.md` reads it as written there.
//!
//! LSL finds streams by multicast and broadcast: everything here runs in a network namespace
//! of its own with only loopback, with an LSL configuration that keeps discovery on this
//! machine, so nothing leaves it. Without root (no namespace) or without pylsl, it is skipped
//! with a sentence saying why.

use crate::util::repo_root;
use mousepose::engine::project_python;
use mousepose::synth::session::{SessionSpec, write_session};
use std::path::Path;
use std::process::Command;

/// Why the test cannot run here, if it cannot.
fn cannot_run() -> Option<String> {
    let pylsl = Command::new(project_python()).args(["-c", "import pylsl"]).output();
    if !pylsl.is_ok_and(|o| o.status.success()) {
        return Some(format!(
            "{} has no pylsl (run scripts/setup.sh)",
            project_python().display()
        ));
    }
    let netns = Command::new("unshare").args(["-n", "true"]).output();
    if !netns.is_ok_and(|o| o.status.success()) {
        return Some(
            "no network namespace of its own (needs root and unshare): LSL's discovery would reach the network".into(),
        );
    }
    None
}

/// The ```python block of docs/FORMATS.md that reads the LSL stream, as written there.
fn documented_reader() -> String {
    let text = std::fs::read_to_string(repo_root().join("docs/FORMATS.md")).expect("test set-up");
    let start = text
        .find("```python\nimport pylsl\n")
        .expect("the pylsl reader in FORMATS.md")
        + 10;
    let end = start + text[start..].find("```").expect("the block ends");
    text[start..end].to_owned()
}

/// Resolves `mousepose-test`, connects (then says so in a file: the documented reader starts
/// only after it, so that the outlet, which sends from its first reader on, sends this one
/// every sample), writes its type, source id, channel labels and every sample (stamp first,
/// NaN as null) as JSON, until no sample came for 5 s.
const RECEIVER: &str = r#"
import json, math, sys, pylsl
found = pylsl.resolve_byprop("name", "mousepose-test", timeout=30)
if not found:
    sys.exit("no stream called mousepose-test")
inlet = pylsl.StreamInlet(found[0])
inlet.open_stream(timeout=10)
open(sys.argv[2], "w").close()
info = inlet.info(timeout=10)
labels, ch = [], info.desc().child("channels").first_child()
while not ch.empty():
    labels.append([ch.child_value("label"), ch.child_value("unit"), ch.child_value("type")])
    ch = ch.next_sibling()
first_clock = pylsl.local_clock()
samples = []
while True:
    sample, stamp = inlet.pull_sample(timeout=5.0)
    if sample is None:
        break
    samples.append([stamp] + [None if math.isnan(v) else v for v in sample])
json.dump({"type": info.type(), "source_id": info.source_id(), "labels": labels,
           "samples": samples, "first_clock": first_clock, "last_clock": pylsl.local_clock()},
          open(sys.argv[1], "w"))
"#;

#[test]
fn issue46_pylsl_reads_a_replays_poses_from_the_lsl_outlet_as_poses_csv_has_them() {
    if let Some(why) = cannot_run() {
        eprintln!("skipped: {why}");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let session = dir.join("session");
    std::fs::create_dir_all(&session).unwrap();
    let spec = SessionSpec {
        seconds: 8.0,
        seed: 46,
        color: false,
        ..SessionSpec::default()
    };
    write_session(&session, &spec, |_, _| {}).unwrap();
    // Discovery on this machine only, by multicast on loopback and by asking 127.0.0.1.
    let config = dir.join("lsl_api.cfg");
    std::fs::write(
        &config,
        "[ports]\nIPv6 = disable\n[multicast]\nResolveScope = machine\n[lab]\nKnownPeers = {127.0.0.1}\nSessionID = mousepose-test\n",
    )
    .unwrap();
    std::fs::write(dir.join("receiver.py"), RECEIVER).unwrap();
    std::fs::write(
        dir.join("reader.py"),
        documented_reader().replace("\"mousepose\"", "\"mousepose-test\""),
    )
    .unwrap();
    let script = r#"
set -e
ip link set lo up
"$PY" receiver.py received.json connected 2>receiver.err &
receiver=$!
"$BIN" replay session --out out --realtime --lsl mousepose-test --json --models "$MODELS" >summary.json 2>replay.err &
replay=$!
tries=0
until [ -e connected ] || [ $tries -ge 600 ]; do sleep 0.05; tries=$((tries + 1)); done
"$PY" reader.py >reader.txt 2>reader.err &
reader=$!
wait $replay
wait $receiver
kill $reader
"#;
    let status = Command::new("unshare")
        .args(["-n", "sh", "-c", script])
        .current_dir(dir)
        .env("LSLAPICFG", &config)
        .env("PY", project_python())
        .env("BIN", env!("CARGO_BIN_EXE_mousepose"))
        .env("MODELS", repo_root().join("fixtures/models"))
        .status()
        .unwrap();
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap_or_default();
    assert!(
        status.success(),
        "replay: {}\nreceiver: {}\nreader: {}",
        read("replay.err"),
        read("receiver.err"),
        read("reader.err")
    );
    let got: serde_json::Value = serde_json::from_str(&read("received.json")).unwrap();
    assert_eq!(got["type"], "MoCap");
    assert_eq!(got["source_id"], "mousepose");
    let labels: Vec<String> = got["labels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l[0].as_str().unwrap().to_owned())
        .collect();
    assert_eq!(labels.len(), 75);
    assert_eq!(&labels[..3], ["snout_x", "snout_y", "snout_z"]);
    assert_eq!(&labels[72..], ["status", "orientation_confidence", "depth_seq"]);
    assert_eq!(got["labels"][0][1], "millimeters");
    assert_eq!(got["labels"][0][2], "PositionX");

    // Every sample is the row of poses.csv of its depth frame.
    let rows = poses_by_seq(&dir.join("out/poses.csv"));
    let samples = got["samples"].as_array().unwrap();
    // The reader connects a second or two into the 8 s replay; the rest all came.
    assert!(
        samples.len() * 2 > rows.len(),
        "{} samples of {} poses",
        samples.len(),
        rows.len()
    );
    let (first, last) = (
        got["first_clock"].as_f64().unwrap(),
        got["last_clock"].as_f64().unwrap(),
    );
    let mut previous = (f64::MIN, None);
    let mut ok = 0;
    for s in samples {
        let s = s.as_array().unwrap();
        let stamp = s[0].as_f64().unwrap();
        let values = &s[1..];
        let seq = values[74].as_f64().unwrap() as u64;
        let row = rows
            .get(&seq)
            .unwrap_or_else(|| panic!("depth frame {seq} is not in poses.csv"));
        // A replay's samples are stamped when sent: on the reader's clock, in order.
        assert!(
            stamp > previous.0 && stamp > first - 10.0 && stamp < last,
            "{stamp} after {previous:?}"
        );
        assert!(previous.1.is_none_or(|p| seq > p), "frame {seq} after {previous:?}");
        previous = (stamp, Some(seq));
        for (i, label) in labels.iter().take(72).enumerate() {
            let want = row[label.as_str()];
            match (values[i].as_f64(), want) {
                (Some(v), Some(w)) => assert!((v - w).abs() <= 0.006, "frame {seq} {label}: {v} vs {w}"),
                (None, None) => {}
                (v, w) => panic!("frame {seq} {label}: {v:?} vs {w:?}"),
            }
        }
        let status = ["ok", "no_mouse", "no_background"][values[72].as_f64().unwrap() as usize];
        assert_eq!(status, row.status, "frame {seq}");
        ok += usize::from(status == "ok");
        match (values[73].as_f64(), row.confidence) {
            (Some(v), Some(w)) => assert!((v - w).abs() <= 0.001, "frame {seq}: {v} vs {w}"),
            (None, None) => {}
            (v, w) => panic!("frame {seq} orientation confidence: {v:?} vs {w:?}"),
        }
    }
    assert!(ok > 0, "no sample with a mouse");
    eprintln!(
        "{} samples of {} poses read, {ok} with a mouse",
        samples.len(),
        rows.len()
    );
    // The replay's summary counts what it sent, and the documented reader read poses too.
    let summary: serde_json::Value = serde_json::from_str(&read("summary.json")).unwrap();
    let lsl = &summary["lsl"];
    assert_eq!(lsl["sent"].as_u64(), Some(samples.len() as u64), "{lsl}");
    assert_eq!(lsl["dropped"]["queue_full"], 0, "{lsl}");
    let reader = read("reader.txt");
    let line = reader
        .lines()
        .next()
        .unwrap_or_else(|| panic!("the documented reader printed nothing: {}", read("reader.err")));
    let words: Vec<&str> = line.split(' ').collect();
    assert!(
        words[0].parse::<f64>().is_ok() && words[1].parse::<u64>().is_ok(),
        "{line}"
    );
    assert!(["ok", "no_mouse", "no_background"].contains(&words[2]), "{line}");
}

/// A row of poses.csv: joint coordinates by column, status, orientation confidence.
struct Row {
    values: std::collections::HashMap<String, Option<f64>>,
    status: String,
    confidence: Option<f64>,
}

impl std::ops::Index<&str> for Row {
    type Output = Option<f64>;
    fn index(&self, column: &str) -> &Option<f64> {
        &self.values[column]
    }
}

fn poses_by_seq(path: &Path) -> std::collections::HashMap<u64, Row> {
    let mut reader = csv::Reader::from_path(path).expect("poses.csv is there");
    let header: Vec<String> = reader
        .headers()
        .expect("poses.csv has a header")
        .iter()
        .map(str::to_owned)
        .collect();
    let column = |name: &str| header.iter().position(|h| h == name).expect("a column of poses.csv");
    let (seq, status, confidence) = (column("depth_seq"), column("status"), column("orientation_confidence"));
    let number = |f: &str| (!f.is_empty()).then(|| f.parse::<f64>().expect("a number in poses.csv"));
    reader
        .records()
        .map(|r| {
            let r = r.expect("a row of poses.csv");
            let values = header
                .iter()
                .zip(r.iter())
                .filter(|(h, _)| h.ends_with("_x") || h.ends_with("_y") || h.ends_with("_z"))
                .map(|(h, f)| (h.clone(), number(f)))
                .collect();
            let row = Row {
                values,
                status: r[status].to_owned(),
                confidence: number(&r[confidence]),
            };
            (r[seq].parse().expect("a depth frame counter"), row)
        })
        .collect()
}

/// A liblsl that cannot be loaded (or a file that is not liblsl) stops the daemon at start in
/// one sentence, the user's to fix (exit code 1), before any camera is opened.
#[test]
fn issue46_a_missing_or_wrong_liblsl_is_refused_in_one_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    let not_lsl = tmp.path().join("libnotlsl.so");
    // A shared library that is not liblsl: the C library itself.
    let libc = ["/lib/x86_64-linux-gnu/libc.so.6", "/lib/aarch64-linux-gnu/libc.so.6"]
        .into_iter()
        .find(|p| Path::new(p).exists());
    let mut cases = vec![(tmp.path().join("nowhere/liblsl.so"), "cannot load liblsl")];
    if let Some(libc) = libc {
        std::fs::copy(libc, &not_lsl).unwrap();
        cases.push((not_lsl, "is not liblsl"));
    }
    for (library, why) in cases {
        let http = format!(
            "address = \"127.0.0.1:0\"\n[lsl]\nlibrary = \"{}\"\n",
            library.display()
        );
        let rig = crate::run::rig_full(tmp.path(), &crate::run::session_depth(), false, "", &http);
        let out = crate::util::mousepose()
            .args(["run", "--config"])
            .arg(&rig)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains(why) && err.contains("[lsl] library"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}
