//! The bounded multi-threaded pipeline: edges with a policy when full, the runner that starts
//! and joins one named thread per component, and their counters.

pub mod edge;
pub mod metrics;
pub mod runner;

pub use edge::{EdgeConfig, EdgeSender, EdgeStats, Sent, WhenFull, edge};
pub use metrics::{Histogram, LatencySummary};
pub use runner::{
    PipelineError, Runner, Shutdown, Sink, Stage, StageError, StageReport, StageStats, Tracked, reports_of,
};
