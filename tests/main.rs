//! The one integration test binary: each module tests one area through the public API or the
//! built `mousepose` binary.

mod capture_openni;
mod cli;
mod forest;
mod segment;
mod session;
mod synth;
mod util;
