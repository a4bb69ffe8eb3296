//! OpenNI2, the driver layer of PrimeSense-family depth cameras (Asus Xtion, Kinect via
//! freenect, Orbbec) and of `.oni` recordings.
//!
//! [`ffi`] holds the raw C API, generated at build time by bindgen from the installed
//! `OniCAPI.h`. [`safe`] (re-exported at the crate root) is the small safe layer the rest of
//! mousepose uses: initialisation, the device list, devices, depth streams, frames, properties,
//! recording and playback.

pub mod safe;

pub use safe::*;

/// The raw OpenNI2 C API (`oni*` functions, `Oni*` types, `ONI_*` constants).
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
pub mod ffi {
    include!(concat!(env!("OUT_DIR"), "/bindings.rs"));

    /// `ONI_API_VERSION` for OpenNI 2.2 (`ONI_CREATE_API_VERSION(2, 2)`): a function-like macro
    /// bindgen does not evaluate, so it is written out here.
    pub const ONI_API_VERSION: i32 = 2 * 1000 + 2;
}
