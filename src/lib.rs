//! mousepose: live 3D pose of a lab mouse from a depth camera above its cage and a colour
//! camera under its glass floor. See `docs/ARCHITECTURE.md` for how the parts fit.
//!
//! The folders are the layers, and imports only point down (`tests/layers.rs` checks it):
//!
//! * [`core`]: plain types: frames, poses, the skeleton, cameras and the rig, kinematics, images.
//! * [`io`]: file formats: the record store, sessions, staged output directories.
//! * [`vision`]: the algorithms: segmentation, forests, the paw cascade, fusion, calibration
//!   maths. No threads, no command line, no files but those they are asked to open.
//! * [`runtime`]: the frame path: camera sources, the synchroniser, the pipeline runner, stages,
//!   sinks, the rig config, and the one topology builder every command uses.
//! * Tooling beside them: [`synth`] (the synthesis engine), [`training`] (datasets to models
//!   and their figures), [`experiment`] (the paper's running example).
//! * [`engine`]: the work behind each command (replay, record, the daemon, batches, exports,
//!   reports, benchmarks, calibration, training runs), an options struct in and a summary out.
//! * [`app`]: the command line, one file per command: parses, dispatches to an engine, prints,
//!   and maps failures to exit codes; the only place clap and exit codes live.

pub mod app;
pub mod core;
pub mod engine;
pub mod experiment;
pub mod io;
pub mod runtime;
pub mod synth;
pub mod training;
pub mod vision;
