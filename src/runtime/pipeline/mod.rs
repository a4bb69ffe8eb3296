//! The bounded multi-threaded pipeline: what a stage is (its input and output types, its
//! name), edges with a policy when full, the builder that joins stages with named edges, the
//! runner that starts and joins one named thread per component, and their counters.

pub mod chain;
pub mod edge;
pub mod metrics;
pub mod runner;
pub mod stage;

pub use chain::{Chain, NamedEdge};
pub use edge::{EdgeConfig, EdgeSender, EdgeStats, Sent, WhenFull, edge};
pub use metrics::{Histogram, LatencySummary};
pub use runner::{PipelineError, Runner, Shutdown, StageReport, StageStats, reports_of};
pub use stage::{FlatMap, Map, Sink, StageError, Tracked};
