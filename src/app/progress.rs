//! Progress for long work: a bar on a terminal, nothing under systemd or in a pipe; the
//! engines' [`crate::engine::progress::Progress`] drawn as such bars ([`Bars`]), their notices
//! and warnings printed on stderr.

use crate::engine::progress::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::{Mutex, PoisonError};

/// A progress bar over `total` items that shows only when stderr is an interactive terminal
/// (not under systemd's journal, not in CI).
pub fn bar(total: u64, what: &str) -> ProgressBar {
    let visible = std::io::stderr().is_terminal() && std::env::var_os("JOURNAL_STREAM").is_none();
    let pb = ProgressBar::with_draw_target(
        Some(total),
        if visible {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    let style = ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} ({per_sec}, eta {eta})")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    pb.set_style(style);
    pb.set_message(what.to_owned());
    pb
}

/// An engine's progress as the command line shows it: each piece of work a [`bar`], cleared
/// when it finishes; notices and warnings as lines on stderr.
#[derive(Debug, Default)]
pub struct Bars {
    current: Mutex<Option<ProgressBar>>,
}

impl Bars {
    fn with(&self, f: impl FnOnce(&ProgressBar)) {
        if let Some(bar) = self.current.lock().unwrap_or_else(PoisonError::into_inner).as_ref() {
            f(bar);
        }
    }

    /// Prints `line` on stderr, out of the way of the bar being drawn.
    fn say(&self, line: &str) {
        let bar = self.current.lock().unwrap_or_else(PoisonError::into_inner).clone();
        match bar {
            Some(bar) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}

impl Progress for Bars {
    fn start(&self, what: &str, total: u64) {
        let old = self
            .current
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .replace(bar(total, what));
        if let Some(old) = old {
            old.finish_and_clear();
        }
    }

    fn set_total(&self, total: u64) {
        self.with(|bar| bar.set_length(total));
    }

    fn set_done(&self, done: u64) {
        self.with(|bar| bar.set_position(done));
    }

    fn advance(&self, steps: u64) {
        self.with(|bar| bar.inc(steps));
    }

    fn label(&self, text: &str) {
        self.with(|bar| bar.set_message(text.to_owned()));
    }

    fn finish(&self) {
        let bar = self.current.lock().unwrap_or_else(PoisonError::into_inner).take();
        if let Some(bar) = bar {
            bar.finish_and_clear();
        }
    }

    fn notice(&self, text: &str) {
        self.say(text);
    }

    fn warning(&self, text: &str) {
        self.say(&format!("warning: {text}"));
    }
}
