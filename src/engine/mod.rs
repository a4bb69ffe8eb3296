//! The engines: the work behind each command (replay, record, the daemon, batches, exports,
//! reports, benchmarks, calibration, training and evaluation runs), each with an options
//! struct in and a summary out. They know no command line: `app` parses the arguments into
//! the options, calls an engine, prints its summary and maps its [`Failure`] to an exit code.

pub mod batch;
pub mod bench;
pub mod calibrate;
pub mod chart;
pub mod daemon;
pub mod detect;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod progress;
pub mod record;
pub mod replay;
pub mod report;
pub mod status;
pub mod synth;
pub mod train;

use anyhow::Context as _;
use std::path::Path;

/// Why an engine failed, and whose fault it is: the user's when what they asked for cannot
/// work (an argument, a config, a file in the way), the work's when it failed on the way. Each
/// engine says which of its errors are the user's; everything else is a failure of the work.
/// The command line maps the first to exit code 1 and the second to 2.
#[derive(Debug)]
pub struct Failure {
    usage: bool,
    error: anyhow::Error,
}

impl Failure {
    /// An error in what the user asked for.
    pub fn usage(error: impl Into<anyhow::Error>) -> Self {
        Self {
            usage: true,
            error: error.into(),
        }
    }

    /// `error`, a usage error when `usage` says so.
    pub fn classed(usage: bool, error: impl Into<anyhow::Error>) -> Self {
        Self {
            usage,
            error: error.into(),
        }
    }

    /// The same failure, with what was being done in front of it.
    #[must_use]
    pub fn context(self, what: impl std::fmt::Display + Send + Sync + 'static) -> Self {
        Self {
            usage: self.usage,
            error: self.error.context(what),
        }
    }

    /// Whether the user's request is what cannot work (not the work itself).
    pub fn is_usage(&self) -> bool {
        self.usage
    }

    /// What went wrong, with its causes.
    pub fn error(&self) -> &anyhow::Error {
        &self.error
    }
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    /// A failure of the work.
    fn from(error: E) -> Self {
        Self::classed(false, error)
    }
}

/// Refused to overwrite a file (the user's: see [`Failure`]).
#[derive(Debug, thiserror::Error)]
#[error("{0:?} exists (use --force to replace it)")]
pub struct Exists(pub std::path::PathBuf);

/// A staged output that cannot be made: the user's when the directory is in the way.
pub fn output_failure(e: crate::io::output::OutputError) -> Failure {
    use crate::io::output::OutputError;
    let usage = matches!(e, OutputError::NotEmpty(_) | OutputError::NotADirectory(_));
    Failure::classed(usage, e)
}

/// Writes `bytes` to `dir/name`.
///
/// # Errors
/// The file cannot be written.
pub fn write_report_file(dir: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).with_context(|| format!("writing {path:?}"))
}

/// Creates the report directory `dir` and its parents.
///
/// # Errors
/// It cannot be created.
pub fn report_dir(dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating report directory {dir:?}"))
}

/// SIGINT and SIGTERM seen by an offline command (`replay`, a batch), so that it stops its
/// work cleanly (removing what it had not finished) instead of dying mid-write.
#[derive(Debug, Clone, Default)]
pub struct Interrupt {
    flag: std::sync::Arc<std::sync::atomic::AtomicBool>,
    /// Whether the signals set `flag` (otherwise it is never set: library use and tests).
    installed: bool,
}

impl Interrupt {
    /// Catches SIGINT and SIGTERM from now on, for the life of the process.
    ///
    /// # Errors
    /// The handlers cannot be installed.
    pub fn install() -> std::io::Result<Self> {
        let flag = std::sync::Arc::<std::sync::atomic::AtomicBool>::default();
        for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
            signal_hook::flag::register(signal, std::sync::Arc::clone(&flag))?;
        }
        Ok(Self { flag, installed: true })
    }

    /// Whether a signal came.
    pub fn requested(&self) -> bool {
        self.flag.load(std::sync::atomic::Ordering::Acquire)
    }

    /// Sets `other` too when a signal comes (at once if one came already), until the guard
    /// is dropped: a running pipeline's shutdown flag.
    ///
    /// # Errors
    /// The handlers cannot be installed.
    pub fn forward_to(&self, other: &std::sync::Arc<std::sync::atomic::AtomicBool>) -> std::io::Result<Forwarded> {
        let mut ids = Vec::new();
        if self.installed {
            for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
                ids.push(signal_hook::flag::register(signal, std::sync::Arc::clone(other))?);
            }
            if self.requested() {
                other.store(true, std::sync::atomic::Ordering::Release);
            }
        }
        Ok(Forwarded(ids))
    }
}

/// Signals forwarded by [`Interrupt::forward_to`]; dropped, they no longer are.
#[derive(Debug)]
pub struct Forwarded(Vec<signal_hook::SigId>);

impl Drop for Forwarded {
    fn drop(&mut self) {
        for id in self.0.drain(..) {
            signal_hook::low_level::unregister(id);
        }
    }
}
