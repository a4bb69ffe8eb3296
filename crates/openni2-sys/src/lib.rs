//! The raw OpenNI2 C API (`oni*` functions, `Oni*` types, `ONI_*` constants), generated at build
//! time by bindgen from the installed `OniCAPI.h`. Nothing else: the safe layer the rest of
//! mousepose uses is the `openni2` crate.
//!
//! OpenNI2 is the driver layer of PrimeSense-family depth cameras (Asus Xtion, Kinect via
//! freenect, Orbbec) and of `.oni` recordings.

pub use bindings::*;

/// The generated declarations, with the lints their generated style trips turned off here only.
#[allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    unused_qualifications,
    missing_debug_implementations,
    clippy::all,
    clippy::undocumented_unsafe_blocks
)]
mod bindings {
    include!(concat!(env!("OUT_DIR"), "/bindings.rs"));
}

/// `ONI_API_VERSION` for OpenNI 2.2 (`ONI_CREATE_API_VERSION(2, 2)`): a function-like macro
/// bindgen does not evaluate, so it is written out here.
pub const ONI_API_VERSION: i32 = 2 * 1000 + 2;
