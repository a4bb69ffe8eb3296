//! `mousepose status`: the running daemon's status in a terminal; the work is
//! [`crate::engine::status`].

use crate::app::Outcome;
use crate::app::output::print;
use crate::engine::status::{StatusOptions, status};
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct StatusArgs {
    /// The daemon's HTTP address [default: the config's `[http] address`, else 127.0.0.1:8470].
    #[arg(long, value_name = "IP:PORT")]
    pub address: Option<SocketAddr>,
    /// The rig config the daemon runs with: its address and token are used.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// A file holding the bearer token (a daemon serving beyond loopback asks for one).
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// Print the run report as one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose status`.
pub fn command(args: &StatusArgs) -> Outcome {
    Ok(print(&status(&StatusOptions {
        address: args.address,
        config: args.config.clone(),
        token_file: args.token_file.clone(),
        json: args.json,
    })?)?)
}
