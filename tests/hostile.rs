//! Files that are not files: a FIFO (opening one waits for a writer) or a device such as
//! `/dev/zero` (reading one never ends) where a reader expects a file is refused at once.

use crate::util::walk;
use mousepose::io::session::{CameraRole, SessionReader};
use mousepose::runtime::recording::moseq::{MoseqConfig, MoseqDepth};
use mousepose::vision::calibrate::{RigCalibration, load_intrinsics};
use mousepose::vision::forest::model;
use mousepose::vision::paws::xml;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

fn mkfifo(path: &Path) {
    let made = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("runs mkfifo");
    assert!(made.success(), "mkfifo {path:?}");
}

/// Runs `read` on another thread and gives its error text, failing when it takes over 10 s
/// (a reader waiting on a FIFO would wait forever).
fn refused_at_once(what: &str, read: impl FnOnce() -> Result<(), String> + Send + 'static) -> String {
    let (send, recv) = mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("hostile-read".to_owned())
        .spawn(move || send.send(read()));
    assert!(spawned.is_ok());
    match recv.recv_timeout(Duration::from_secs(10)) {
        Ok(Err(e)) => e,
        Ok(Ok(())) => panic!("{what} was read as if it were a file"),
        Err(_) => panic!("reading {what} hangs"),
    }
}

/// A small session written by `synth session`, copied so that its files can be replaced.
fn session_copy(dir: &Path) -> PathBuf {
    let from = crate::util::repo_root().join("fixtures/sessions/synthetic-small");
    let to = dir.join("session");
    for entry in walk(&from) {
        let rel = entry.strip_prefix(&from).expect("inside");
        let dest = to.join(rel);
        std::fs::create_dir_all(dest.parent().expect("a parent")).expect("directory");
        std::fs::copy(&entry, &dest).expect("copies");
    }
    to
}

#[test]
fn a_fifo_in_place_of_a_session_file_is_refused_at_once() {
    for file in [
        "session.toml",
        "depth/frames.mpstore",
        "events.jsonl",
        "truth/pairs.csv",
    ] {
        let dir = tempfile::tempdir().expect("temporary directory");
        let session = session_copy(dir.path());
        std::fs::remove_file(session.join(file)).expect("removes");
        mkfifo(&session.join(file));
        let e = refused_at_once(file, move || {
            let r = SessionReader::open(&session).map_err(|e| mousepose::core::error_chain(&e))?;
            // An index that cannot be used is rebuilt by scanning, which is no error.
            r.events().map_err(|e| mousepose::core::error_chain(&e))?;
            r.truth().map_err(|e| mousepose::core::error_chain(&e))?;
            Ok(())
        });
        assert!(e.contains(file.rsplit('/').next().unwrap_or(file)), "{file}: {e}");
    }
}

#[test]
fn a_fifo_in_place_of_an_index_is_not_used_and_the_frames_are_scanned() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let session = session_copy(dir.path());
    let index = session.join("depth/index.mpindex");
    std::fs::remove_file(&index).expect("removes");
    mkfifo(&index);
    let status = refused_at_once("an index", move || {
        let r = SessionReader::open(&session).map_err(|e| mousepose::core::error_chain(&e))?;
        let status = format!("{:?}", r.index_status(CameraRole::Depth));
        assert!(r.depth_count() > 0, "no depth frame found by the scan");
        Err(status)
    });
    assert!(
        status.contains("Invalid") && status.contains("not a regular file"),
        "{status}"
    );
}

#[test]
fn a_fifo_or_device_in_place_of_a_model_cascade_calibration_or_recording_is_refused_at_once() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let fifo = dir.path().join("fifo");
    mkfifo(&fifo);
    for path in [fifo.clone(), PathBuf::from("/dev/zero")] {
        let p = path.clone();
        let e = refused_at_once("a model", move || {
            model::load(&p, None).map(drop).map_err(|e| e.to_string())
        });
        assert!(e.contains("cannot read"), "{e}");
        let p = path.clone();
        let e = refused_at_once("a cascade", move || xml::load(&p).map(drop).map_err(|e| e.to_string()));
        assert!(e.contains("cannot read"), "{e}");
        let p = path.clone();
        let e = refused_at_once("a rig calibration", move || {
            RigCalibration::load(&p)
                .map(drop)
                .map_err(|e| mousepose::core::error_chain(&e))
        });
        assert!(e.contains("not a regular file"), "{e}");
        let p = path.clone();
        let e = refused_at_once("intrinsics", move || {
            load_intrinsics(&p)
                .map(drop)
                .map_err(|e| mousepose::core::error_chain(&e))
        });
        assert!(e.contains("not a regular file"), "{e}");
    }
    let moseq = dir.path().join("moseq");
    std::fs::create_dir_all(&moseq).expect("directory");
    std::fs::write(moseq.join("depth.dat"), b"").expect("depth.dat");
    mkfifo(&moseq.join("depth_ts.txt"));
    let e = refused_at_once("depth_ts.txt", move || {
        MoseqDepth::open(MoseqConfig::new(&moseq))
            .map(drop)
            .map_err(|e| mousepose::core::error_chain(&e))
    });
    assert!(e.contains("not a regular file"), "{e}");
}

#[test]
fn a_calibration_file_that_sends_opencvs_yaml_parser_into_a_loop_is_refused_at_once() {
    // Found by fuzzing: OpenCV 4.6's FileStorage parser never returns on these 19 bytes.
    let dir = tempfile::tempdir().expect("temporary directory");
    let path = dir.path().join("intrinsics.yaml");
    std::fs::write(&path, "%YAML:1.\n---%:1\n-\n-").expect("writes");
    let p = path.clone();
    let e = refused_at_once("the looping YAML", move || {
        load_intrinsics(&p)
            .map(drop)
            .map_err(|e| mousepose::core::error_chain(&e))
    });
    assert!(e.contains("line 2 holds a YAML directive"), "{e}");
    // What OpenCV writes still reads: a directive on the first line, markers alone on theirs.
    std::fs::write(
        &path,
        "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\ndistortion_coefficients: [ 0., 0., 0., 0., 0. ]\n",
    )
    .expect("writes");
    let intrinsics = load_intrinsics(&path).expect("an OpenCV intrinsics file");
    assert_eq!((intrinsics.width, intrinsics.fx), (640, 500.0));
}
