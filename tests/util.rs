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
