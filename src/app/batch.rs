//! `mousepose batch`: many sessions here or as a Slurm job array; the work is
//! [`crate::engine::batch`].

use crate::app::Outcome;
use crate::app::output::show_batch;
use crate::app::progress::Bars;
use crate::engine::batch::{BatchOptions, SlurmResources, batch};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct BatchArgs {
    /// Session directories, or glob patterns matching them (quote them).
    #[arg(value_name = "SESSIONS", required = true)]
    pub sessions: Vec<PathBuf>,
    /// The directory each session's output goes into (DIR/<session name>/, a daemon's chunk
    /// DIR/<run>-<chunk>/), with batch.csv; one batch at a time per DIR.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The models directory; the bundled models by default.
    #[arg(long, value_name = "DIR")]
    pub models: Option<PathBuf>,
    /// Body-forest worker threads per session when run here (0: one per core).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=64))]
    pub workers: u32,
    /// A rig calibration to use instead of each session's own.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Submit the sessions as a Slurm job array and wait for it.
    #[arg(long)]
    pub slurm: bool,
    #[command(flatten)]
    pub resources: SlurmArgs,
    /// Print the table as JSON.
    #[arg(long)]
    pub json: bool,
    /// Replay finished sessions again.
    #[arg(long)]
    pub force: bool,
}

/// `mousepose batch`.
pub fn command(args: &BatchArgs) -> Outcome {
    let absolute = |p: &PathBuf| std::fs::canonicalize(p).unwrap_or_else(|_| p.clone());
    let options = BatchOptions {
        models: args.models.as_ref().map(absolute),
        workers: args.workers as usize,
        calibration: args.calibration.as_ref().map(absolute),
        force: args.force,
    };
    let slurm = args.slurm.then(|| args.resources.resources());
    let summary = batch(&args.sessions, &args.out, &options, slurm.as_ref(), &Bars::default())?;
    show_batch(&summary, args.json)
}

/// Resources and placement of the Slurm job.
#[derive(Clone, Debug, Args)]
pub struct SlurmArgs {
    /// CPUs per task (each task is one replay; its body-forest workers use them all).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub cpus: u32,
    /// Memory per task, in Slurm's notation (e.g. 4G, 2000M).
    #[arg(long, default_value = "4G", value_parser = parse_memory)]
    pub mem: String,
    /// Time limit per task, in Slurm's notation (e.g. 01:00:00, 90, 1-00:00:00).
    #[arg(long, default_value = "01:00:00", value_parser = parse_time)]
    pub time: String,
    /// The partition to run in (the cluster's default when not given).
    #[arg(long)]
    pub partition: Option<String>,
    /// At most this many tasks at once (`--array=...%N`).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub max_parallel: Option<u32>,
    /// The job's name in the queue.
    #[arg(long, default_value = "mousepose")]
    pub job_name: String,
}

fn parse_memory(s: &str) -> Result<String, String> {
    let digits = s.trim_end_matches(['K', 'M', 'G', 'T', 'k', 'm', 'g', 't']);
    if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) && s.len() <= digits.len() + 1 {
        Ok(s.to_owned())
    } else {
        Err(format!("expected memory like 4G or 2000M, got {s:?}"))
    }
}

fn parse_time(s: &str) -> Result<String, String> {
    if !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit() || b == b':' || b == b'-') {
        Ok(s.to_owned())
    } else {
        Err(format!(
            "expected a time limit like 01:00:00, 90 or 1-00:00:00, got {s:?}"
        ))
    }
}

impl SlurmArgs {
    fn resources(&self) -> SlurmResources {
        SlurmResources {
            cpus: self.cpus,
            mem: self.mem.clone(),
            time: self.time.clone(),
            partition: self.partition.clone(),
            max_parallel: self.max_parallel,
            job_name: self.job_name.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slurm_values_are_checked() {
        assert!(parse_memory("4G").is_ok());
        assert!(parse_memory("2000").is_ok());
        assert!(parse_memory("G").is_err());
        assert!(parse_memory("4GG").is_err());
        assert!(parse_time("1-00:00:00").is_ok());
        assert!(parse_time("1 hour").is_err());
    }
}
