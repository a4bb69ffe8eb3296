//! What the commands print: text or one JSON object on stdout.

use crate::app::Outcome;
use crate::engine::batch::BatchRow;
use serde::Serialize;
use std::fmt::Write as _;
use std::io::Write as _;

/// Prints a batch's table (or JSON); sessions that failed fail the command.
///
/// # Errors
/// Stdout is closed, or sessions failed.
pub fn show_batch(summary: &crate::engine::batch::BatchSummary, json: bool) -> Outcome {
    if json {
        print_json(&summary.rows)?;
    } else {
        print(&batch_table(&summary.rows))?;
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

/// A value, or nothing when there is none.
fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map(|v| v.to_string()).unwrap_or_default()
}

/// A batch's rows as the terminal shows them.
pub fn batch_table(rows: &[BatchRow]) -> String {
    let width = rows.iter().map(|r| r.name.len()).max().unwrap_or(7).max(7);
    let mut text = format!(
        "{:<width$}  {:<7}  {:>7}  {:>7}  {:>9}  {:>8}\n",
        "session", "status", "pairs", "ok", "pairs/s", "error mm"
    );
    for r in rows {
        let _ = writeln!(
            text,
            "{:<width$}  {:<7}  {:>7}  {:>7}  {:>9}  {:>8}",
            r.name,
            r.status,
            opt(r.pairs),
            opt(r.ok_poses),
            opt(r.throughput_pairs_per_s.map(|v| format!("{v:.0}"))),
            opt(r.mean_error_mm.map(|v| format!("{v:.2}"))),
        );
        if let Some(e) = &r.error {
            let _ = writeln!(text, "{:<width$}  {e}", "");
        }
    }
    let count = |s: &str| rows.iter().filter(|r| r.status == s).count();
    let _ = writeln!(
        text,
        "{} sessions: {} replayed, {} skipped (finished before), {} failed",
        rows.len(),
        count("done"),
        count("skipped"),
        count("failed")
    );
    text
}
