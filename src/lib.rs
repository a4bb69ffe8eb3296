//! mousepose: live 3D pose of a lab mouse from a depth camera above its cage and a colour
//! camera under its glass floor. See `docs/ARCHITECTURE.md` for how the parts fit.

pub mod bench;
pub mod calibrate;
pub mod capture;
pub mod chart;
pub mod cli;
pub mod commands;
pub mod config;
pub mod devices;
pub mod experiment;
pub mod forest;
pub mod frame;
pub mod fusion;
pub mod geometry;
pub mod image;
pub mod kinematics;
pub mod learn;
pub mod output;
pub mod overlay;
pub mod paws;
pub mod pipeline;
pub mod pose;
pub mod progress;
pub mod record;
pub mod replay;
pub mod segment;
pub mod session;
pub mod sink;
pub mod skeleton;
pub mod stages;
pub mod store;
pub mod sync;
pub mod synth;
