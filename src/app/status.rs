//! `mousepose status`: the running daemon's status in a terminal (for an operator on ssh), read
//! from its HTTP server's `/status`.

use crate::app::print;
use crate::engine::Failure;
use crate::runtime::config::{Config, DEFAULT_HTTP_PORT};
use crate::runtime::http::client::get;
use anyhow::Context as _;
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

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
pub fn command(args: &StatusArgs) -> crate::app::Outcome {
    let config = args
        .config
        .as_deref()
        .map(Config::load)
        .transpose()
        .map_err(Failure::usage)?;
    let http = config.map(|c| c.http);
    let address = match (args.address, &http) {
        (Some(a), _) => a,
        (None, Some(h)) => h
            .address
            .context("the config says `[http] address = \"off\"`: the daemon serves no status")
            .map_err(Failure::usage)?,
        (None, None) => SocketAddr::from(([127, 0, 0, 1], DEFAULT_HTTP_PORT)),
    };
    let token = match &args.token_file {
        Some(path) => Some(
            crate::io::read_bounded(path, crate::runtime::config::MAX_TOKEN_BYTES)
                .with_context(|| format!("cannot read the token file {path:?}"))
                .map_err(Failure::usage)?
                .trim()
                .to_owned(),
        ),
        None => http.and_then(|h| h.token),
    };
    let path = if args.json { "/status" } else { "/status?format=text" };
    let answer = get(address, path, token.as_deref(), Duration::from_secs(5))?;
    match answer.status {
        200 => Ok(print(&String::from_utf8_lossy(&answer.body))?),
        401 => Err(Failure::usage(anyhow::anyhow!(
            "the daemon at {address} asks for its bearer token: give --token-file (or --config)"
        ))),
        code => Err(Failure::from(anyhow::anyhow!(
            "the daemon at {address} answered {code}: {}",
            String::from_utf8_lossy(&answer.body).trim()
        ))),
    }
}
