//! Sinks: where the pipeline's results go: poses (`poses.csv`) and raw frames (the recorder).

pub mod chunks;
pub mod poses;
pub mod recorder;
