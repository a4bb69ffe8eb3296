//! `mousepose devices`: the cameras each backend sees (GigE cameras only at configured addresses).

use crate::app::output::{print, print_json};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct DevicesArgs {
    /// A rig configuration: GigE Vision cameras are probed at its addresses.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose devices`.
pub fn command(args: &DevicesArgs) -> crate::app::Outcome {
    let config = args
        .config
        .as_deref()
        .map(crate::runtime::config::Config::load)
        .transpose()
        .map_err(crate::engine::Failure::usage)?;
    let found = crate::runtime::devices::list(config.as_ref());
    if args.json {
        return Ok(print_json(&serde_json::json!({ "backends": found }))?);
    }
    let mut text = String::new();
    for b in &found {
        let _ = writeln!(text, "{} ({}):", b.backend, b.scope);
        if let Some(e) = &b.error {
            let _ = writeln!(text, "  cannot list: {e}");
        }
        if b.devices.is_empty() && b.error.is_none() {
            let _ = writeln!(text, "  none");
        }
        for d in &b.devices {
            let _ = writeln!(text, "  {:<24} {} serial {:?} {}", d.id, d.model, d.serial, d.details);
        }
    }
    Ok(print(&text)?)
}
