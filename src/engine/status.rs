//! The running daemon's status (`mousepose status`, for an operator on ssh), read from its
//! HTTP server's `/status`.

use crate::engine::Failure;
use crate::runtime::config::{Config, DEFAULT_HTTP_PORT};
use crate::runtime::http::client::get;
use anyhow::Context as _;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Where the daemon is and how to ask it.
#[derive(Clone, Debug, Default)]
pub struct StatusOptions {
    /// The daemon's HTTP address (default: the config's, else 127.0.0.1 on the default port).
    pub address: Option<SocketAddr>,
    /// The rig config the daemon runs with: its address and token are used.
    pub config: Option<PathBuf>,
    /// A file holding the bearer token.
    pub token_file: Option<PathBuf>,
    /// The run report as JSON rather than text.
    pub json: bool,
}

/// The running daemon's status, as its HTTP server's `/status` gives it (text or JSON).
///
/// # Errors
/// The config or token file cannot be read, the config turns the server off, the daemon
/// asks for a token (the user's), or it cannot be reached or answers with an error.
pub fn status(options: &StatusOptions) -> Result<String, Failure> {
    let config = options
        .config
        .as_deref()
        .map(Config::load)
        .transpose()
        .map_err(Failure::usage)?;
    let http = config.map(|c| c.http);
    let address = match (options.address, &http) {
        (Some(a), _) => a,
        (None, Some(h)) => h
            .address
            .context("the config says `[http] address = \"off\"`: the daemon serves no status")
            .map_err(Failure::usage)?,
        (None, None) => SocketAddr::from(([127, 0, 0, 1], DEFAULT_HTTP_PORT)),
    };
    let token = match &options.token_file {
        Some(path) => Some(
            crate::io::read_bounded(path, crate::runtime::config::MAX_TOKEN_BYTES)
                .with_context(|| format!("cannot read the token file {path:?}"))
                .map_err(Failure::usage)?
                .trim()
                .to_owned(),
        ),
        None => http.and_then(|h| h.token),
    };
    let path = if options.json { "/status" } else { "/status?format=text" };
    let answer = get(address, path, token.as_deref(), Duration::from_secs(5))?;
    match answer.status {
        200 => Ok(String::from_utf8_lossy(&answer.body).into_owned()),
        401 => Err(Failure::usage(anyhow::anyhow!(
            "the daemon at {address} asks for its bearer token: give --token-file (or --config)"
        ))),
        code => Err(Failure::from(anyhow::anyhow!(
            "the daemon at {address} answered {code}: {}",
            String::from_utf8_lossy(&answer.body).trim()
        ))),
    }
}
