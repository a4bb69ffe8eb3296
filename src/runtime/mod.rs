//! The frame path: camera sources, the synchroniser, the pipeline runner with its edges,
//! stages and sinks, the rig config, and [`topology`], the one builder that wires them for
//! `record`, `replay`, `bench` and `run`.

pub mod accounting;
pub mod capture;
pub mod config;
pub mod devices;
pub mod http;
pub mod models;
pub mod overlay;
pub mod pairing;
pub mod pipeline;
pub mod pose_record;
pub mod recording;
pub mod sink;
pub mod stages;
pub mod status;
pub mod stream;
pub mod topology;
pub mod usage;
