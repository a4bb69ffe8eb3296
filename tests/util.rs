//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// The built `mousepose` binary.
pub fn mousepose() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mousepose"))
}

/// The repository's root.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Options to replay `session` into `out` with the fixture models on `workers` threads, and
/// everything else as `replay` does by default.
pub fn replay_options(
    session: &std::path::Path,
    out: &std::path::Path,
    workers: usize,
) -> mousepose::engine::replay::ReplayOptions {
    mousepose::engine::replay::ReplayOptions {
        stream: None,
        lsl: None,
        lead_ns: None,
        partner_wait: None,
        mice: 1,
        session: session.to_owned(),
        out: out.to_owned(),
        models: Some(repo_root().join("fixtures/models")),
        realtime: false,
        workers,
        overlays: None,
        calibration: None,
        intrinsics: None,
        roi: None,
        force: false,
    }
}

/// Every file under `dir`, its subdirectories' included.
pub fn walk(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).expect("directory") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            out.extend(walk(&path));
        } else {
            out.push(path);
        }
    }
    out
}
