//! The one integration test binary: each module tests one area through the public API or the
//! built `mousepose` binary.

mod adapt;
mod batch;
mod calibrate;
mod capture_aravis;
mod capture_openni;
mod capture_v4l2;
mod cli;
mod docs;
mod export;
mod faults;
mod forest;
mod fuzz;
mod hostile;
mod http;
mod layers;
mod lsl;
mod mice;
mod packaging;
mod paws;
mod realdata;
mod realrig;
mod record;
mod replay;
mod report;
mod run;
mod segment;
mod session;
mod soak;
mod stream;
mod synth;
mod util;
