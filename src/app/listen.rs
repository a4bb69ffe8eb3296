//! `mousepose listen`: prints the live stream of a running daemon (or of `replay --realtime
//! --stream`), as `mosquitto_sub` does for MQTT; the work is [`crate::engine::listen`].

use crate::app::Outcome;
use crate::app::output::print;
use crate::engine::listen::{Heard, ListenOptions, listen};
use crate::runtime::capture::clock::monotonic_ns;
use crate::runtime::stream::{Endpoint, Topic};
use clap::{Args, ValueEnum};
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct ListenArgs {
    /// The stream's endpoint [default: the config's `[stream] endpoint`, else tcp://127.0.0.1:8471].
    #[arg(value_name = "ENDPOINT", value_parser = crate::app::parse::endpoint)]
    pub endpoint: Option<Endpoint>,
    /// The rig config the daemon runs with: its `[stream] endpoint` is used.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Only this topic [default: both].
    #[arg(long, value_enum)]
    pub topic: Option<TopicArg>,
    /// Print each message as the JSON object sent, one a line.
    #[arg(long)]
    pub json: bool,
    /// Stop after this many messages.
    #[arg(long, value_name = "N")]
    pub count: Option<u64>,
    /// Stop after this many seconds.
    #[arg(long, value_name = "S", value_parser = crate::app::parse::seconds)]
    pub seconds: Option<f64>,
    /// Each time, only the newest pose waiting (and every event), the poses skipped counted as
    /// missed: a reader slower than the poses then acts on the mouse as it is now.
    #[arg(long)]
    pub newest: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TopicArg {
    /// Each pose as it leaves the pipeline.
    Poses,
    /// The daemon's events (camera away and back, chunk begun, recording paused).
    Events,
}

/// `mousepose listen`.
pub fn command(args: &ListenArgs) -> Outcome {
    let topics = match args.topic {
        Some(TopicArg::Poses) => vec![Topic::Poses],
        Some(TopicArg::Events) => vec![Topic::Events],
        None => Topic::ALL.to_vec(),
    };
    let options = ListenOptions {
        endpoint: args.endpoint.clone(),
        config: args.config.clone(),
        topics,
        count: args.count,
        seconds: args.seconds,
        newest: args.newest,
    };
    listen(&options, |heard| {
        if heard.missed > 0 {
            eprintln!("{} {} messages missed", heard.topic.name(), heard.missed);
        }
        let line = if args.json { heard.body.clone() } else { text(heard) };
        print(&format!("{line}\n"))
    })
}

/// A message as one line of text.
fn text(heard: &Heard) -> String {
    let v = &heard.value;
    let seq = v["seq"].as_u64().unwrap_or(0);
    match heard.topic {
        Topic::Poses => {
            // Live stamps are this machine's monotonic clock; a replay's are the recording's.
            let live = v["host_clock"] == "monotonic";
            let age_ms = v["depth"]["host_ns"]
                .as_u64()
                .filter(|_| live)
                .map(|ns| monotonic_ns().saturating_sub(ns) as f64 / 1e6);
            let snout = &v["joints"]["snout"];
            let at = match (snout["x"].as_f64(), snout["y"].as_f64(), snout["z"].as_f64()) {
                (Some(x), Some(y), Some(z)) => format!("snout ({x:.1}, {y:.1}, {z:.1}) mm"),
                _ => "snout -".to_owned(),
            };
            format!(
                "poses #{seq} frame {} {} {at}, orientation {}{}",
                v["depth"]["seq"],
                v["status"].as_str().unwrap_or("?"),
                v["orientation_confidence"],
                age_ms.map_or(String::new(), |ms| format!(", {ms:.1} ms since the depth frame"))
            )
        }
        Topic::Events => {
            let mut rest = v.as_object().cloned().unwrap_or_default();
            for key in ["topic", "version", "seq", "published_ns", "event"] {
                rest.remove(key);
            }
            let detail = rest.iter().map(|(k, v)| format!(" {k}={v}")).collect::<String>();
            format!("events #{seq} {}{detail}", v["event"].as_str().unwrap_or("?"))
        }
    }
}
