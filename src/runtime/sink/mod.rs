//! Sinks: where the pipeline's results go: poses (`poses.csv`), raw frames written to a
//! session (`session`), and the daemon's chunks of both (`chunks`).

pub mod chunks;
pub mod poses;
pub mod session;
