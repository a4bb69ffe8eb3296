//! Sinks: where the pipeline's results go.

pub mod poses;
