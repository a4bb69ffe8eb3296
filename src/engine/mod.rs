//! The engines: the work behind each command (replay, record, the daemon, batches, exports,
//! reports, benchmarks, calibration, training and evaluation runs), each with an options
//! struct in and a summary out. They know no command line: `app` parses the arguments into
//! the options, calls an engine, prints its summary and maps its [`Failure`] to an exit code.

pub mod adapt;
pub mod batch;
pub mod bench;
pub mod calibrate;
pub mod chart;
pub mod daemon;
pub mod detect;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod listen;
pub mod progress;
pub mod record;
pub mod replay;
pub mod report;
pub mod status;
pub mod synth;
pub mod train;

use anyhow::Context as _;
use std::path::{Path, PathBuf};

/// Where `scripts/nwb-env` puts the project's Python environment (pynwb and ndx-pose for
/// `export nwb`, pyzmq, pylsl).
pub const DEFAULT_PYTHON: &str = "/opt/mousepose/venv/bin/python3";

/// The project's Python: `$MOUSEPOSE_PYTHON`, else [`DEFAULT_PYTHON`] (also where pylsl, which
/// ships liblsl, is installed).
pub fn project_python() -> PathBuf {
    std::env::var_os("MOUSEPOSE_PYTHON").map_or_else(|| PathBuf::from(DEFAULT_PYTHON), PathBuf::from)
}

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
pub struct Exists(pub PathBuf);

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

/// The signals that stop a command cleanly (its output closed, its report written): every
/// signal whose default action ends the process and that a handler may catch, SIGHUP among
/// them when `hangup` (a command in a terminal that hung up; the daemon takes SIGHUP apart).
/// Not among them: SIGPIPE (ignored by Rust's runtime: a broken pipe is an error where it is
/// written), SIGXFSZ (see [`Signals::install`]), and the signals of a fault of the process
/// itself (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGSYS, SIGTRAP), whose handler could not
/// go on.
pub fn stop_signals(hangup: bool) -> Vec<std::ffi::c_int> {
    use rustix::process::Signal;
    use signal_hook::consts::signal::{
        SIGALRM, SIGHUP, SIGINT, SIGIO, SIGPROF, SIGQUIT, SIGTERM, SIGUSR1, SIGUSR2, SIGVTALRM, SIGXCPU,
    };
    let mut signals = vec![
        SIGINT,
        SIGTERM,
        SIGQUIT,
        SIGUSR1,
        SIGUSR2,
        SIGALRM,
        SIGVTALRM,
        SIGPROF,
        SIGXCPU,
        SIGIO,
        Signal::POWER.as_raw(),
        Signal::STKFLT.as_raw(),
    ];
    if hangup {
        signals.push(SIGHUP);
    }
    signals
}

/// The name of signal `signal` (`SIGTERM`), or its number.
pub fn signal_name(signal: std::ffi::c_int) -> String {
    match signal_hook::low_level::signal_name(signal) {
        Some(name) => name.to_owned(),
        None => format!("signal {signal}"),
    }
}

/// The signals caught by a long-running command (`record`, the daemon): each of
/// [`stop_signals`] sets its stop flag and is remembered; SIGHUP is one of them or, for the
/// daemon, a request of its own ([`Signals::take_hangup`]).
#[derive(Debug, Clone)]
pub struct Signals {
    caught: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    hangup: std::sync::Arc<std::sync::atomic::AtomicBool>,
    hangup_stops: bool,
}

impl Signals {
    /// Catches the signals from now on, for the life of the process: each stop signal sets
    /// `stop`; SIGHUP does too when `hangup_stops`, else only [`Signals::take_hangup`]. SIGXFSZ
    /// is caught and left alone, so that a write past the process's file size limit fails
    /// (and is counted as a write error) instead of ending the process.
    ///
    /// # Errors
    /// The handlers cannot be installed.
    pub fn install(stop: &crate::runtime::pipeline::Shutdown, hangup_stops: bool) -> std::io::Result<Self> {
        use std::sync::Arc;
        let signals = Self {
            caught: Arc::default(),
            hangup: Arc::default(),
            hangup_stops,
        };
        for signal in stop_signals(hangup_stops) {
            let number = usize::try_from(signal).unwrap_or(usize::MAX);
            signal_hook::flag::register_usize(signal, Arc::clone(&signals.caught), number)?;
            signal_hook::flag::register(signal, stop.flag())?;
        }
        if !hangup_stops {
            signal_hook::flag::register(signal_hook::consts::SIGHUP, Arc::clone(&signals.hangup))?;
        }
        signal_hook::flag::register(signal_hook::consts::SIGXFSZ, Arc::default())?;
        Ok(signals)
    }

    /// Whether SIGHUP came since the last call (only when it does not stop the command).
    pub fn take_hangup(&self) -> bool {
        self.hangup.swap(false, std::sync::atomic::Ordering::AcqRel)
    }

    /// The last stop signal that came, if any.
    pub fn caught(&self) -> Option<std::ffi::c_int> {
        match self.caught.load(std::sync::atomic::Ordering::Acquire) {
            0 => None,
            n => std::ffi::c_int::try_from(n).ok(),
        }
    }

    /// A command stopped by a signal that is not one of the ordinary requests to stop
    /// (SIGINT, SIGTERM, and SIGHUP where it stops) stopped cleanly, yet was not asked to by
    /// its operator or service manager: it fails (exit 2), so that systemd's
    /// `Restart=on-failure` brings a daemon back. The sentence to say so.
    pub fn unexpected_stop(&self) -> Option<String> {
        use signal_hook::consts::signal::{SIGHUP, SIGINT, SIGTERM};
        let signal = self.caught()?;
        let ordinary = signal == SIGINT || signal == SIGTERM || (self.hangup_stops && signal == SIGHUP);
        (!ordinary).then(|| {
            format!(
                "stopped by {} (its output closed and its report written)",
                signal_name(signal)
            )
        })
    }
}

/// The stop signals ([`stop_signals`], SIGHUP among them) seen by an offline command
/// (`replay`, a batch), so that it stops its work cleanly (removing what it had not finished)
/// instead of dying mid-write.
#[derive(Debug, Clone, Default)]
pub struct Interrupt {
    flag: std::sync::Arc<std::sync::atomic::AtomicBool>,
    /// Whether the signals set `flag` (otherwise it is never set: library use and tests).
    installed: bool,
}

impl Interrupt {
    /// Catches the stop signals from now on, for the life of the process.
    ///
    /// # Errors
    /// The handlers cannot be installed.
    pub fn install() -> std::io::Result<Self> {
        let flag = std::sync::Arc::<std::sync::atomic::AtomicBool>::default();
        for signal in stop_signals(true) {
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
            for signal in stop_signals(true) {
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
