//! File formats: the append-only record store, session directories (what `record` and `run`
//! write and `replay` reads), output directories staged and renamed into place, videos
//! encoded by ffmpeg, and masks drawn as PNG images.

pub mod mask;
pub mod output;
pub mod session;
pub mod store;
pub mod video;
