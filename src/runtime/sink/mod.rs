//! Sinks: where the pipeline's results go: poses (`poses.csv`), raw frames written to a
//! session (`session`), and the daemon's chunks of both (`chunks`; those an earlier run left
//! open are closed at the next start, `left_open`).

pub mod chunks;
pub mod left_open;
pub mod poses;
pub mod session;
