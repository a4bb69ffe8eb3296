//! File formats: the append-only record store, session directories (what `record` and `run`
//! write and `replay` reads), and output directories staged and renamed into place.

pub mod output;
pub mod session;
pub mod store;
