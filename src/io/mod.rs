//! File formats: the append-only record store, session directories (what `record` and `run`
//! write and `replay` reads), output directories staged and renamed into place, and videos
//! encoded by ffmpeg.

pub mod output;
pub mod session;
pub mod store;
pub mod video;
