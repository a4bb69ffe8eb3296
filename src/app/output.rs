//! What the commands print: text or one JSON object on stdout.

use crate::app::Outcome;
use serde::Serialize;
use std::io::Write;

/// Prints a batch's table (or JSON); sessions that failed fail the command.
///
/// # Errors
/// Stdout is closed, or sessions failed.
pub fn show_batch(summary: &crate::engine::batch::BatchSummary, json: bool) -> Outcome {
    if json {
        print_json(&summary.rows)?;
    } else {
        print(&summary.text())?;
    }
    summary.failure().map_or(Ok(()), Err)
}

/// Writes `text` to stdout.
///
/// # Errors
/// Stdout is closed.
pub fn print(text: &str) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())?;
    out.flush()?;
    Ok(())
}

/// Writes `value` to stdout as one pretty JSON object.
///
/// # Errors
/// Stdout is closed.
pub fn print_json(value: &impl Serialize) -> anyhow::Result<()> {
    print(&format!("{}\n", serde_json::to_string_pretty(value)?))
}
