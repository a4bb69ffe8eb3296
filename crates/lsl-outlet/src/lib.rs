//! A Lab Streaming Layer (LSL) outlet: liblsl loaded at run time (`dlopen`), so that nothing
//! needs liblsl to build and a machine without it only loses the outlet. liblsl is not in
//! Debian; the Python package pylsl ships it (`pylsl/lib/liblsl.so`), and a lab's own build
//! of it serves as well.
//!
//! - [`Lsl`]: the library, loaded from a path, with the few functions an outlet needs;
//!   [`Lsl::local_clock`] is LSL's clock (seconds; `CLOCK_MONOTONIC` on Linux).
//! - [`StreamSpec`]: what a stream is called and carries (its channels, each with a label,
//!   a unit and a type, written into the stream's description the way XDF files expect).
//! - [`Outlet`]: one stream on the network, [`Outlet::push`] sends a sample of `f64` with its
//!   time stamp. liblsl's outlets are safe to use from any thread.
//!
//! Only `double64` channels: poses are millimetres and scores, and one format keeps the
//! surface small.

use std::ffi::{CStr, CString, OsStr, c_char, c_double, c_int, c_void};
use std::fmt;
use std::sync::Arc;

/// liblsl's `cft_double64` (`lsl_channel_format_t`).
const CFT_DOUBLE64: c_int = 2;

type CreateStreaminfo =
    unsafe extern "C" fn(*const c_char, *const c_char, i32, c_double, c_int, *const c_char) -> *mut c_void;
type DestroyStreaminfo = unsafe extern "C" fn(*mut c_void);
type GetDesc = unsafe extern "C" fn(*mut c_void) -> *mut c_void;
type AppendChild = unsafe extern "C" fn(*mut c_void, *const c_char) -> *mut c_void;
type AppendChildValue = unsafe extern "C" fn(*mut c_void, *const c_char, *const c_char) -> *mut c_void;
type CreateOutlet = unsafe extern "C" fn(*mut c_void, i32, i32) -> *mut c_void;
type DestroyOutlet = unsafe extern "C" fn(*mut c_void);
type PushSampleDtp = unsafe extern "C" fn(*mut c_void, *const c_double, c_double, i32) -> i32;
type HaveConsumers = unsafe extern "C" fn(*mut c_void) -> i32;
type LocalClock = unsafe extern "C" fn() -> c_double;
type LibraryVersion = unsafe extern "C" fn() -> i32;

/// The functions used, copied out of the library (valid while it stays loaded).
#[derive(Clone, Copy)]
struct Fns {
    create_streaminfo: CreateStreaminfo,
    destroy_streaminfo: DestroyStreaminfo,
    get_desc: GetDesc,
    append_child: AppendChild,
    append_child_value: AppendChildValue,
    create_outlet: CreateOutlet,
    destroy_outlet: DestroyOutlet,
    push_sample_dtp: PushSampleDtp,
    have_consumers: HaveConsumers,
    local_clock: LocalClock,
    library_version: LibraryVersion,
}

/// Why liblsl could not be used.
#[derive(Debug, thiserror::Error)]
pub enum LslError {
    #[error("cannot load liblsl from {path}")]
    Load {
        path: String,
        #[source]
        source: libloading::Error,
    },
    #[error("{path} is not liblsl (it has no {symbol})")]
    Symbol { path: String, symbol: &'static str },
    #[error("the stream's {what} has a NUL character")]
    Nul { what: &'static str },
    #[error("a sample has {got} values, the stream {want} channels")]
    Channels { got: usize, want: usize },
    #[error("liblsl refused to make the stream ({what})")]
    Refused { what: &'static str },
    #[error("liblsl failed to send a sample (error {0})")]
    Push(i32),
}

/// liblsl, loaded.
pub struct Lsl {
    fns: Fns,
    path: String,
    /// Keeps the functions in `fns` mapped; never used otherwise.
    _library: libloading::Library,
}

impl fmt::Debug for Lsl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Lsl").field("path", &self.path).finish_non_exhaustive()
    }
}

impl Lsl {
    /// Loads liblsl from `path` (a file, or a bare name the dynamic loader searches for).
    ///
    /// # Errors
    /// The file cannot be loaded or lacks one of the functions.
    pub fn open(path: &OsStr) -> Result<Arc<Self>, LslError> {
        let shown = path.to_string_lossy().into_owned();
        // SAFETY: loading runs the library's initialisers; liblsl's only set up its own
        // statics. A file that is not liblsl is caught by the symbol checks below before any
        // of its code is called through them.
        let library = unsafe { libloading::Library::new(path) }.map_err(|source| LslError::Load {
            path: shown.clone(),
            source,
        })?;
        macro_rules! get {
            ($name:literal) => {{
                // SAFETY: the type given is the function's signature in liblsl's C headers
                // (lsl_c.h, stable since 1.0); the pointer is only used while `library` lives.
                let symbol = unsafe { library.get(concat!($name, "\0").as_bytes()) };
                *symbol.map_err(|_| LslError::Symbol {
                    path: shown.clone(),
                    symbol: $name,
                })?
            }};
        }
        let fns = Fns {
            create_streaminfo: get!("lsl_create_streaminfo"),
            destroy_streaminfo: get!("lsl_destroy_streaminfo"),
            get_desc: get!("lsl_get_desc"),
            append_child: get!("lsl_append_child"),
            append_child_value: get!("lsl_append_child_value"),
            create_outlet: get!("lsl_create_outlet"),
            destroy_outlet: get!("lsl_destroy_outlet"),
            push_sample_dtp: get!("lsl_push_sample_dtp"),
            have_consumers: get!("lsl_have_consumers"),
            local_clock: get!("lsl_local_clock"),
            library_version: get!("lsl_library_version"),
        };
        Ok(Arc::new(Self {
            fns,
            path: shown,
            _library: library,
        }))
    }

    /// Where it was loaded from.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// LSL's clock in seconds (what stamps mean to every LSL reader).
    pub fn local_clock(&self) -> f64 {
        // SAFETY: no arguments; liblsl reads its steady clock.
        unsafe { (self.fns.local_clock)() }
    }

    /// The library's version, major * 100 + minor (118: 1.18).
    pub fn version(&self) -> i32 {
        // SAFETY: no arguments.
        unsafe { (self.fns.library_version)() }
    }
}

/// One channel: its label (`nose_x`), unit (`millimeters`) and type (`PositionX`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Channel {
    pub label: String,
    pub unit: String,
    pub kind: String,
}

/// What an outlet's stream is.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamSpec {
    /// What readers resolve it by (`name='mousepose'`).
    pub name: String,
    /// Its content type (`MoCap`).
    pub kind: String,
    /// Samples per second, 0 for an irregular rate.
    pub nominal_rate: f64,
    /// Identifies the source across restarts (readers reconnect to the same source id).
    pub source_id: String,
    pub channels: Vec<Channel>,
    /// Extra `(name, value)` children of the description (`manufacturer`, ...).
    pub desc: Vec<(String, String)>,
    /// Samples kept for a slow reader: liblsl counts this in seconds when the rate is
    /// nominal, in hundreds of samples when it is irregular.
    pub max_buffered: i32,
}

/// A stream on the network; dropping it withdraws the stream.
pub struct Outlet {
    lsl: Arc<Lsl>,
    handle: *mut c_void,
    channels: usize,
}

// SAFETY: liblsl's outlets may be used from any thread (its documentation: "all functions are
// thread-safe"); the handle is owned here alone and freed once, in `drop`.
unsafe impl Send for Outlet {}

impl fmt::Debug for Outlet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Outlet")
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

fn c_string(text: &str, what: &'static str) -> Result<CString, LslError> {
    CString::new(text).map_err(|_| LslError::Nul { what })
}

impl Outlet {
    /// Makes the stream `spec` describes and offers it on the network.
    ///
    /// # Errors
    /// A name has a NUL character, or liblsl refused the stream (it logs why).
    pub fn new(lsl: &Arc<Lsl>, spec: &StreamSpec) -> Result<Self, LslError> {
        let f = lsl.fns;
        let name = c_string(&spec.name, "name")?;
        let kind = c_string(&spec.kind, "type")?;
        let source_id = c_string(&spec.source_id, "source id")?;
        let count = i32::try_from(spec.channels.len()).map_err(|_| LslError::Refused { what: "channel count" })?;
        // Every string of the description, made before any call so that a NUL fails first.
        let tag = |t: &str| c_string(t, "description");
        let channels: Vec<[CString; 3]> = spec
            .channels
            .iter()
            .map(|c| Ok([tag(&c.label)?, tag(&c.unit)?, tag(&c.kind)?]))
            .collect::<Result<_, LslError>>()?;
        let desc: Vec<(CString, CString)> = spec
            .desc
            .iter()
            .map(|(n, v)| Ok((tag(n)?, tag(v)?)))
            .collect::<Result<_, LslError>>()?;
        let [k_channels, k_channel, k_label, k_unit, k_type] =
            [c"channels", c"channel", c"label", c"unit", c"type"].map(CStr::as_ptr);
        // SAFETY: every pointer is a NUL-terminated string alive for the call; liblsl copies
        // what it keeps. A null info is checked before use.
        let info = unsafe {
            (f.create_streaminfo)(
                name.as_ptr(),
                kind.as_ptr(),
                count,
                spec.nominal_rate,
                CFT_DOUBLE64,
                source_id.as_ptr(),
            )
        };
        if info.is_null() {
            return Err(LslError::Refused { what: "stream info" });
        }
        // SAFETY: `info` is a live stream info; the description's element handles it returns
        // point into it, and each string is alive for its call (liblsl copies it). Appending
        // to an empty handle is a no-op in liblsl, so a failure cannot write elsewhere.
        let outlet = unsafe {
            let root = (f.get_desc)(info);
            for (n, v) in &desc {
                (f.append_child_value)(root, n.as_ptr(), v.as_ptr());
            }
            let list = (f.append_child)(root, k_channels);
            for [label, unit, kind] in &channels {
                let ch = (f.append_child)(list, k_channel);
                (f.append_child_value)(ch, k_label, label.as_ptr());
                (f.append_child_value)(ch, k_unit, unit.as_ptr());
                (f.append_child_value)(ch, k_type, kind.as_ptr());
            }
            // Chunk size 0: each sample goes out as it is pushed. The outlet copies the info.
            let outlet = (f.create_outlet)(info, 0, spec.max_buffered);
            (f.destroy_streaminfo)(info);
            outlet
        };
        if outlet.is_null() {
            return Err(LslError::Refused { what: "outlet" });
        }
        Ok(Self {
            lsl: Arc::clone(lsl),
            handle: outlet,
            channels: spec.channels.len(),
        })
    }

    /// Sends one sample stamped `timestamp` (LSL's clock, seconds; 0: now).
    ///
    /// # Errors
    /// The sample's length is not the channel count, or liblsl failed.
    pub fn push(&self, sample: &[f64], timestamp: f64) -> Result<(), LslError> {
        if sample.len() != self.channels {
            return Err(LslError::Channels {
                got: sample.len(),
                want: self.channels,
            });
        }
        // SAFETY: the outlet is live; `sample` holds exactly its channel count of doubles,
        // which liblsl copies before returning. Pushthrough 1: sent now, not batched.
        let code = unsafe { (self.lsl.fns.push_sample_dtp)(self.handle, sample.as_ptr(), timestamp, 1) };
        if code < 0 { Err(LslError::Push(code)) } else { Ok(()) }
    }

    /// Whether a reader is connected.
    pub fn has_consumers(&self) -> bool {
        // SAFETY: the outlet is live.
        unsafe { (self.lsl.fns.have_consumers)(self.handle) != 0 }
    }

    pub fn channels(&self) -> usize {
        self.channels
    }
}

impl Drop for Outlet {
    fn drop(&mut self) {
        // SAFETY: the handle is live and freed here only, once; the library outlives it (the
        // `Arc` held).
        unsafe { (self.lsl.fns.destroy_outlet)(self.handle) };
    }
}
