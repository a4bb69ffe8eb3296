//! How an engine tells how its work goes, without drawing or printing anything itself: it
//! calls a [`Progress`] it is handed. The command line's one draws a bar on a terminal and
//! prints the notices on stderr (`app::progress`); [`Silent`] is for callers that want none
//! (tests, library use).

/// What an engine reports while it works: one piece of work at a time, started, moved on
/// and finished, and the odd line for the user. Every method has a default that does nothing.
pub trait Progress: Sync {
    /// Work called `what` begins, of `total` steps (0 while not known yet).
    fn start(&self, what: &str, total: u64) {
        let _ = (what, total);
    }

    /// The work now has `total` steps.
    fn set_total(&self, total: u64) {
        let _ = total;
    }

    /// `done` steps of the work are done.
    fn set_done(&self, done: u64) {
        let _ = done;
    }

    /// `steps` more steps are done.
    fn advance(&self, steps: u64) {
        let _ = steps;
    }

    /// What is being worked on now, in a word or two (a session's name, a figure).
    fn label(&self, text: &str) {
        let _ = text;
    }

    /// The work is over (finished or abandoned).
    fn finish(&self) {}

    /// A line for the user about the work (what was submitted, what is waited for).
    fn notice(&self, text: &str) {
        let _ = text;
    }

    /// Something the user should fix, though the work goes on.
    fn warning(&self, text: &str) {
        let _ = text;
    }
}

/// Progress nobody sees.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Progress for Silent {}
