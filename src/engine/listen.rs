//! `mousepose listen`: a running daemon's (or a realtime replay's) live stream, message by
//! message, as `mosquitto_sub` prints an MQTT topic. The messages are made in
//! `runtime::stream::message`; the command line prints them.

use crate::engine::Failure;
use crate::runtime::config::Config;
use crate::runtime::stream::{Endpoint, Subscriber, Topic};
use anyhow::Context as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What to listen to.
#[derive(Clone, Debug)]
pub struct ListenOptions {
    /// The stream's endpoint (default: the config's `[stream] endpoint`, else the default one).
    pub endpoint: Option<Endpoint>,
    /// The rig config the daemon runs with: its `[stream]` endpoint is used.
    pub config: Option<PathBuf>,
    pub topics: Vec<Topic>,
    /// Stop after this many messages.
    pub count: Option<u64>,
    /// Stop after this long.
    pub seconds: Option<f64>,
    /// Each time, only the newest pose waiting (and every event): what a reader slower than
    /// the poses acts on ([`Subscriber::newest`]); the poses skipped are counted as missed.
    pub newest: bool,
}

/// One message heard.
#[derive(Clone, Debug)]
pub struct Heard {
    pub topic: Topic,
    /// The JSON text as sent.
    pub body: String,
    pub value: serde_json::Value,
    /// Messages of this topic lost before this one (by their `seq`), since the first heard.
    pub missed: u64,
}

/// How long a listener waits for one message before looking at the clock again.
const POLL: Duration = Duration::from_millis(200);

/// Listens until `count` messages or `seconds` (forever without either: Ctrl-C ends it),
/// handing each message to `heard` (which stops the listening by returning an error).
///
/// # Errors
/// The config cannot be read or names no stream, the endpoint cannot be connected to (the
/// user's), or `heard` failed.
pub fn listen(options: &ListenOptions, mut heard: impl FnMut(&Heard) -> anyhow::Result<()>) -> Result<(), Failure> {
    let endpoint = match (&options.endpoint, &options.config) {
        (Some(e), _) => e.clone(),
        (None, Some(path)) => Config::load(path)
            .map_err(Failure::usage)?
            .stream
            .map(|s| s.endpoint)
            .with_context(|| format!("the config {path:?} has no [stream] table: its daemon publishes no stream"))
            .map_err(Failure::usage)?,
        (None, None) => Endpoint::default_tcp(),
    };
    let subscriber = Subscriber::connect(&endpoint, &options.topics)
        .with_context(|| format!("cannot listen to {endpoint}"))
        .map_err(Failure::usage)?;
    let until = options
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut next_seq: [Option<u64>; 2] = [None, None];
    let mut count = 0u64;
    while options.count.is_none_or(|n| count < n) && until.is_none_or(|u| Instant::now() < u) {
        let wait = until.map_or(POLL, |u| u.saturating_duration_since(Instant::now()).min(POLL));
        let round = if options.newest {
            subscriber.newest(wait)
        } else {
            subscriber.next(wait).map(Vec::from_iter)
        };
        for (topic, body) in round.with_context(|| format!("cannot read from {endpoint}"))? {
            let Ok(value) = serde_json::from_str::<serde_json::Value>(&body) else {
                continue;
            };
            let seq = value["seq"].as_u64();
            let expected = &mut next_seq[Topic::ALL.iter().position(|t| *t == topic).unwrap_or(0)];
            let missed = match (seq, *expected) {
                (Some(seq), Some(e)) => seq.saturating_sub(e),
                _ => 0,
            };
            *expected = seq.map(|s| s + 1);
            heard(&Heard {
                topic,
                body,
                value,
                missed,
            })?;
            count += 1;
            if options.count.is_some_and(|n| count >= n) {
                break;
            }
        }
    }
    Ok(())
}
