//! A small safe layer over the OpenNI2 C API (the `openni2-sys` bindings): what a depth source
//! needs and no more. OpenNI2 is the driver layer of PrimeSense-family depth cameras (Asus
//! Xtion, Kinect via freenect, Orbbec) and of `.oni` recordings.
//!
//! - [`OpenNI`]: the library, initialised once per process on first use and never shut down
//!   (see [`OpenNI::init`] for why).
//! - [`OpenNI::devices`]: the cameras the drivers see ([`DeviceInfo`]: URI, vendor, name, USB ids).
//! - [`Device`]: one open device (a camera, the `"Dummy"` test device or a `.oni` file played
//!   back): its sensors and their [`VideoMode`]s, its serial number and firmware, and for files
//!   the playback speed, repeat and end of file.
//! - [`DepthStream`]: a depth stream (create, set the mode, start, stop) and
//!   [`DepthStream::read_frame`], which waits with a timeout and copies the frame into a buffer
//!   the caller reuses ([`DepthFrame`], millimetres as `u16`).
//! - [`Recorder`]: records streams to a `.oni` file, and [`oni_file`] fixes such a file for
//!   playback when the driver did not report cropping (Dummy).
//!
//! Ownership: a stream keeps its device open and a recorder keeps its streams alive, so handles
//! are always released in the order OpenNI2 needs (recorder, then streams, then the device),
//! whatever order the Rust values are dropped in.
//!
//! Threads: every type here is `Send`; a handle shared between values (a device by its streams,
//! a stream by a recorder) sits behind a mutex, so no two threads call into OpenNI2 with the
//! same handle at once.

use openni2_sys as ffi;
use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant};

/// How long a stream is left alone between `oniStreamStop` and `oniStreamDestroy`.
///
/// Some drivers stop their producer thread lazily: Debian's Dummy driver only clears a flag and
/// its thread sleeps up to 33 ms before it looks again, then writes into the stream it was
/// given. Destroying the stream before that thread has noticed crashes the process, typically
/// at exit. Waiting this long after a stop (only when the stream was started) is enough for every
/// driver we use and costs nothing in a pipeline that stops once.
pub const STOP_SETTLE: Duration = Duration::from_millis(100);

/// An OpenNI2 status code other than success.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Error,
    NotImplemented,
    NotSupported,
    BadParameter,
    OutOfFlow,
    NoDevice,
    TimeOut,
    /// A code the headers do not name.
    Other(u32),
}

impl Status {
    fn from_raw(raw: ffi::OniStatus) -> Option<Self> {
        Some(match raw {
            ffi::ONI_STATUS_OK => return None,
            ffi::ONI_STATUS_ERROR => Status::Error,
            ffi::ONI_STATUS_NOT_IMPLEMENTED => Status::NotImplemented,
            ffi::ONI_STATUS_NOT_SUPPORTED => Status::NotSupported,
            ffi::ONI_STATUS_BAD_PARAMETER => Status::BadParameter,
            ffi::ONI_STATUS_OUT_OF_FLOW => Status::OutOfFlow,
            ffi::ONI_STATUS_NO_DEVICE => Status::NoDevice,
            ffi::ONI_STATUS_TIME_OUT => Status::TimeOut,
            other => Status::Other(other),
        })
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Status::Error => f.write_str("error"),
            Status::NotImplemented => f.write_str("not implemented"),
            Status::NotSupported => f.write_str("not supported"),
            Status::BadParameter => f.write_str("bad parameter"),
            Status::OutOfFlow => f.write_str("out of flow"),
            Status::NoDevice => f.write_str("no device"),
            Status::TimeOut => f.write_str("time out"),
            Status::Other(code) => write!(f, "status {code}"),
        }
    }
}

/// What went wrong in a call to OpenNI2.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An OpenNI2 function returned a failure. `detail` is `oniGetExtendedError()` right after
    /// the call (OpenNI2 clears it at the start of every call), empty when it said nothing.
    #[error("{call} failed ({status}){}", detail_suffix(.detail))]
    Call {
        call: &'static str,
        status: Status,
        detail: String,
    },
    /// A string handed to OpenNI2 (a URI, a file name) contains a NUL byte.
    #[error("{what} contains a NUL byte: {value:?}")]
    Nul { what: &'static str, value: String },
    /// The device has no sensor of this type.
    #[error("the device has no {0} sensor")]
    NoSensor(SensorType),
    /// A frame is not what the stream promised (format, size).
    #[error("bad frame: {0}")]
    BadFrame(String),
    /// A recording could not be read or written.
    #[error("{path:?}")]
    File {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A recording is not laid out as OpenNI2 writes them.
    #[error("{path:?} is not a usable .oni recording: {reason}")]
    BadRecording { path: PathBuf, reason: String },
}

fn detail_suffix(detail: &str) -> String {
    if detail.is_empty() {
        String::new()
    } else {
        format!(": {detail}")
    }
}

/// Turns a status into `Ok` or an [`Error::Call`] carrying OpenNI2's own explanation.
fn check(call: &'static str, raw: ffi::OniStatus) -> Result<(), Error> {
    match Status::from_raw(raw) {
        None => Ok(()),
        Some(status) => Err(Error::Call {
            call,
            status,
            detail: extended_error(),
        }),
    }
}

/// `oniGetExtendedError()`, trimmed.
fn extended_error() -> String {
    // SAFETY: oniGetExtendedError takes no argument and returns either NULL or a pointer to a
    // NUL-terminated buffer owned by OpenNI2 that stays valid until the next OpenNI2 call on this
    // thread; it is copied before anything else is called.
    let ptr = unsafe { ffi::oniGetExtendedError() };
    if ptr.is_null() {
        return String::new();
    }
    // SAFETY: non-null and NUL-terminated, see above.
    let text = unsafe { CStr::from_ptr(ptr) };
    text.to_string_lossy().trim().to_owned()
}

/// A C string from a Rust one, or [`Error::Nul`].
fn c_string(what: &'static str, value: &str) -> Result<CString, Error> {
    CString::new(value).map_err(|_| Error::Nul {
        what,
        value: value.to_owned(),
    })
}

/// The text of a fixed-size C char array: up to the first NUL, lossy UTF-8, trimmed.
fn fixed_str(chars: &[c_char]) -> String {
    let bytes: Vec<u8> = chars.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).trim().to_owned()
}

/// Locks a mutex whose data cannot be left inconsistent by a panic (a raw handle).
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

// ---------------------------------------------------------------------------------------------
// The library

/// The OpenNI2 library, initialised. A zero-sized proof that [`OpenNI::init`] succeeded; every
/// other entry point (e.g. [`Device::open`]) gets one itself, so holding it is optional.
#[derive(Clone, Copy, Debug)]
pub struct OpenNI {
    _private: (),
}

/// The outcome of the one `oniInitialize` call of the process.
static INIT: OnceLock<Result<(), (Status, String)>> = OnceLock::new();

/// URIs of played-back files that reached their end, as OpenNI2's device-state callback
/// reports them. A device clears its URI when it opens.
static ENDED: Mutex<Vec<String>> = Mutex::new(Vec::new());

impl OpenNI {
    /// Initialises OpenNI2 (API 2.2) on the first call; later calls return the first outcome.
    ///
    /// Drivers are loaded from `<libdir>/OpenNI2/Drivers` as OpenNI2 is configured; no
    /// environment variable is needed with Debian's packages.
    ///
    /// The library is never shut down: OpenNI2 keeps one context per process whose
    /// initialisation counter is not thread-safe and which does not come back reliably after
    /// `oniShutdown` (drivers are unloaded and reloaded). Devices, streams and recorders are
    /// closed when their Rust values drop; what is left (loaded drivers, the context) is freed
    /// when the process exits.
    ///
    /// # Errors
    /// `oniInitialize` failed (no driver could be loaded, wrong library version); every later
    /// call returns the same error.
    pub fn init() -> Result<OpenNI, Error> {
        let outcome = INIT.get_or_init(|| {
            // SAFETY: oniInitialize is called once per process (OnceLock) with the API version
            // the bindings were generated for.
            let raw = unsafe { ffi::oniInitialize(ffi::ONI_API_VERSION) };
            if let Some(status) = Status::from_raw(raw) {
                return Err((status, extended_error()));
            }
            let mut callbacks = ffi::OniDeviceCallbacks {
                deviceConnected: None,
                deviceDisconnected: None,
                deviceStateChanged: Some(device_state_changed),
            };
            let mut handle: ffi::OniCallbackHandle = std::ptr::null_mut();
            // SAFETY: the callbacks struct is read during the call only (OpenNI2 copies the
            // function pointers); the callback is a plain function that lives for the whole
            // process, it needs no cookie, and the registration is never undone, like the
            // library itself.
            let raw = unsafe { ffi::oniRegisterDeviceCallbacks(&mut callbacks, std::ptr::null_mut(), &mut handle) };
            if let Some(status) = Status::from_raw(raw) {
                return Err((status, extended_error()));
            }
            Ok(())
        });
        match outcome {
            Ok(()) => Ok(OpenNI { _private: () }),
            Err((status, detail)) => Err(Error::Call {
                call: "oniInitialize",
                status: *status,
                detail: detail.clone(),
            }),
        }
    }

    /// The library's version (major, minor, maintenance, build).
    pub fn version(&self) -> (i32, i32, i32, i32) {
        // SAFETY: oniGetVersion has no argument and returns a plain struct by value.
        let v = unsafe { ffi::oniGetVersion() };
        (v.major, v.minor, v.maintenance, v.build)
    }

    /// The devices the drivers see now.
    ///
    /// Debian's Dummy driver lists no device until `"Dummy"` has been opened once, and files are
    /// never listed: both open by URI all the same.
    ///
    /// # Errors
    /// `oniGetDeviceList` failed.
    pub fn devices(&self) -> Result<Vec<DeviceInfo>, Error> {
        let mut list: *mut ffi::OniDeviceInfo = std::ptr::null_mut();
        let mut count: c_int = 0;
        // SAFETY: both out-pointers point to live locals; on success OpenNI2 allocates `count`
        // entries at `list`, released below.
        check("oniGetDeviceList", unsafe {
            ffi::oniGetDeviceList(&mut list, &mut count)
        })?;
        if list.is_null() {
            return Ok(Vec::new());
        }
        let count = usize::try_from(count).unwrap_or(0);
        // SAFETY: OpenNI2 returned `count` initialised, properly aligned entries at `list`,
        // valid until oniReleaseDeviceList; they are copied into owned values before that.
        let infos = unsafe { std::slice::from_raw_parts(list, count) }
            .iter()
            .map(DeviceInfo::from_raw)
            .collect();
        // SAFETY: `list` came from oniGetDeviceList and is released once; the slice above is no
        // longer used.
        check("oniReleaseDeviceList", unsafe { ffi::oniReleaseDeviceList(list) })?;
        Ok(infos)
    }
}

/// OpenNI2's device-state callback: records the URIs of files that reached their end.
extern "C" fn device_state_changed(info: *const ffi::OniDeviceInfo, state: ffi::OniDeviceState, _cookie: *mut c_void) {
    if state != ffi::ONI_DEVICE_STATE_EOF || info.is_null() {
        return;
    }
    // SAFETY: OpenNI2 passes a pointer to a device info that is valid for the duration of the
    // callback; it was checked for NULL and is only read here.
    let uri = fixed_str(unsafe { &(*info).uri });
    let mut ended = lock(&ENDED);
    if !ended.contains(&uri) {
        ended.push(uri);
    }
}

// ---------------------------------------------------------------------------------------------
// Plain data

/// A device as the drivers describe it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct DeviceInfo {
    /// What [`Device::open`] takes.
    pub uri: String,
    pub vendor: String,
    pub name: String,
    pub usb_vendor_id: u16,
    pub usb_product_id: u16,
}

impl DeviceInfo {
    fn from_raw(raw: &ffi::OniDeviceInfo) -> Self {
        Self {
            uri: fixed_str(&raw.uri),
            vendor: fixed_str(&raw.vendor),
            name: fixed_str(&raw.name),
            usb_vendor_id: raw.usbVendorId,
            usb_product_id: raw.usbProductId,
        }
    }
}

/// The kinds of sensor a device can have.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SensorType {
    Ir,
    Color,
    Depth,
}

impl SensorType {
    fn raw(self) -> ffi::OniSensorType {
        match self {
            SensorType::Ir => ffi::ONI_SENSOR_IR,
            SensorType::Color => ffi::ONI_SENSOR_COLOR,
            SensorType::Depth => ffi::ONI_SENSOR_DEPTH,
        }
    }
}

impl fmt::Display for SensorType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SensorType::Ir => "ir",
            SensorType::Color => "color",
            SensorType::Depth => "depth",
        })
    }
}

/// Pixel formats of OpenNI2 streams.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    /// Depth in millimetres, `u16`.
    #[default]
    Depth1Mm,
    /// Depth in 100 µm units, `u16`.
    Depth100Um,
    Shift9_2,
    Shift9_3,
    Rgb888,
    Yuv422,
    Gray8,
    Gray16,
    Jpeg,
    Yuyv,
    /// A code the headers do not name.
    Other(u32),
}

impl PixelFormat {
    fn from_raw(raw: ffi::OniPixelFormat) -> Self {
        match raw {
            ffi::ONI_PIXEL_FORMAT_DEPTH_1_MM => PixelFormat::Depth1Mm,
            ffi::ONI_PIXEL_FORMAT_DEPTH_100_UM => PixelFormat::Depth100Um,
            ffi::ONI_PIXEL_FORMAT_SHIFT_9_2 => PixelFormat::Shift9_2,
            ffi::ONI_PIXEL_FORMAT_SHIFT_9_3 => PixelFormat::Shift9_3,
            ffi::ONI_PIXEL_FORMAT_RGB888 => PixelFormat::Rgb888,
            ffi::ONI_PIXEL_FORMAT_YUV422 => PixelFormat::Yuv422,
            ffi::ONI_PIXEL_FORMAT_GRAY8 => PixelFormat::Gray8,
            ffi::ONI_PIXEL_FORMAT_GRAY16 => PixelFormat::Gray16,
            ffi::ONI_PIXEL_FORMAT_JPEG => PixelFormat::Jpeg,
            ffi::ONI_PIXEL_FORMAT_YUYV => PixelFormat::Yuyv,
            other => PixelFormat::Other(other),
        }
    }

    fn raw(self) -> ffi::OniPixelFormat {
        match self {
            PixelFormat::Depth1Mm => ffi::ONI_PIXEL_FORMAT_DEPTH_1_MM,
            PixelFormat::Depth100Um => ffi::ONI_PIXEL_FORMAT_DEPTH_100_UM,
            PixelFormat::Shift9_2 => ffi::ONI_PIXEL_FORMAT_SHIFT_9_2,
            PixelFormat::Shift9_3 => ffi::ONI_PIXEL_FORMAT_SHIFT_9_3,
            PixelFormat::Rgb888 => ffi::ONI_PIXEL_FORMAT_RGB888,
            PixelFormat::Yuv422 => ffi::ONI_PIXEL_FORMAT_YUV422,
            PixelFormat::Gray8 => ffi::ONI_PIXEL_FORMAT_GRAY8,
            PixelFormat::Gray16 => ffi::ONI_PIXEL_FORMAT_GRAY16,
            PixelFormat::Jpeg => ffi::ONI_PIXEL_FORMAT_JPEG,
            PixelFormat::Yuyv => ffi::ONI_PIXEL_FORMAT_YUYV,
            PixelFormat::Other(raw) => raw,
        }
    }
}

impl fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PixelFormat::Depth1Mm => f.write_str("depth_1_mm"),
            PixelFormat::Depth100Um => f.write_str("depth_100_um"),
            PixelFormat::Shift9_2 => f.write_str("shift_9_2"),
            PixelFormat::Shift9_3 => f.write_str("shift_9_3"),
            PixelFormat::Rgb888 => f.write_str("rgb888"),
            PixelFormat::Yuv422 => f.write_str("yuv422"),
            PixelFormat::Gray8 => f.write_str("gray8"),
            PixelFormat::Gray16 => f.write_str("gray16"),
            PixelFormat::Jpeg => f.write_str("jpeg"),
            PixelFormat::Yuyv => f.write_str("yuyv"),
            PixelFormat::Other(raw) => write!(f, "format {raw}"),
        }
    }
}

/// A stream configuration: pixel format, resolution and frame rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct VideoMode {
    pub pixel_format: PixelFormat,
    pub width: u32,
    pub height: u32,
    pub fps: u32,
}

impl VideoMode {
    fn from_raw(raw: &ffi::OniVideoMode) -> Self {
        Self {
            pixel_format: PixelFormat::from_raw(raw.pixelFormat),
            width: u32::try_from(raw.resolutionX).unwrap_or(0),
            height: u32::try_from(raw.resolutionY).unwrap_or(0),
            fps: u32::try_from(raw.fps).unwrap_or(0),
        }
    }

    fn raw(&self) -> ffi::OniVideoMode {
        ffi::OniVideoMode {
            pixelFormat: self.pixel_format.raw(),
            resolutionX: c_int::try_from(self.width).unwrap_or(c_int::MAX),
            resolutionY: c_int::try_from(self.height).unwrap_or(c_int::MAX),
            fps: c_int::try_from(self.fps).unwrap_or(c_int::MAX),
        }
    }
}

impl fmt::Display for VideoMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}@{} {}", self.width, self.height, self.fps, self.pixel_format)
    }
}

/// A sensor of a device and the modes it supports.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SensorInfo {
    pub sensor: SensorType,
    pub modes: Vec<VideoMode>,
}

impl SensorInfo {
    /// Copies a sensor info OpenNI2 returned.
    ///
    /// # Safety
    /// `raw` is NULL or points to a sensor info whose mode array holds `numSupportedVideoModes`
    /// entries, both valid for the duration of the call.
    unsafe fn from_raw(sensor: SensorType, raw: *const ffi::OniSensorInfo) -> Option<Self> {
        if raw.is_null() {
            return None;
        }
        // SAFETY: non-null and valid per the function's contract.
        let raw = unsafe { &*raw };
        let count = usize::try_from(raw.numSupportedVideoModes).unwrap_or(0);
        let modes = if raw.pSupportedVideoModes.is_null() || count == 0 {
            Vec::new()
        } else {
            // SAFETY: the array holds `count` initialised modes per the function's contract.
            unsafe { std::slice::from_raw_parts(raw.pSupportedVideoModes, count) }
                .iter()
                .map(VideoMode::from_raw)
                .collect()
        };
        Some(Self { sensor, modes })
    }
}

/// How fast a played-back `.oni` file delivers its frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlaybackSpeed {
    /// One frame each time the reader waits for one (OpenNI2's `-1`, "manual"): as fast as the
    /// reader reads, and no frame is ever overwritten before it was read.
    Manual,
    /// As fast as the file can be decoded (`0`); frames the reader does not take in time are
    /// replaced by newer ones, as with a camera.
    Fastest,
    /// A multiple of the recorded rate (`1.0` is real time).
    Ratio(f32),
}

impl PlaybackSpeed {
    fn raw(self) -> f32 {
        match self {
            PlaybackSpeed::Manual => -1.0,
            PlaybackSpeed::Fastest => 0.0,
            PlaybackSpeed::Ratio(r) => r,
        }
    }

    fn from_raw(raw: f32) -> Self {
        if raw < 0.0 {
            PlaybackSpeed::Manual
        } else if raw == 0.0 {
            PlaybackSpeed::Fastest
        } else {
            PlaybackSpeed::Ratio(raw)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Devices

/// An open device handle, closed on drop.
#[derive(Debug)]
struct RawDevice(ffi::OniDeviceHandle);

// SAFETY: an OpenNI2 device handle is an opaque pointer into the process-wide context and is not
// tied to the thread that opened it; it is only used through the mutex in `DeviceShared`, so at
// most one thread calls into OpenNI2 with it at a time.
unsafe impl Send for RawDevice {}

#[derive(Debug)]
struct DeviceShared {
    raw: Mutex<RawDevice>,
    uri: String,
}

impl Drop for DeviceShared {
    fn drop(&mut self) {
        let raw = lock(&self.raw).0;
        // SAFETY: the handle came from oniDeviceOpen and is closed once, here; every stream and
        // recorder that used it holds an Arc to this value, so they are all gone.
        unsafe { ffi::oniDeviceClose(raw) };
    }
}

/// An open device: a camera, the Dummy test device or a `.oni` file. Closed when the value and
/// every stream created from it are dropped.
///
/// Closing a played-back file on which no stream was ever started takes OpenNI2 3 s (its player
/// thread only notices the close at a time-out); once a stream has started, closing is quick.
#[derive(Debug)]
pub struct Device {
    shared: Arc<DeviceShared>,
}

impl Device {
    /// Opens a device by URI: one from [`OpenNI::devices`], `"Dummy"` for Debian's test device,
    /// or the path of a `.oni` file to play back. Initialises OpenNI2 if needed.
    ///
    /// # Errors
    /// OpenNI2 cannot be initialised, no driver accepts the URI, or the device fails to open.
    pub fn open(uri: &str) -> Result<Device, Error> {
        OpenNI::init()?;
        let c_uri = c_string("device URI", uri)?;
        lock(&ENDED).retain(|u| u != uri);
        let mut raw: ffi::OniDeviceHandle = std::ptr::null_mut();
        // SAFETY: `c_uri` is a NUL-terminated string alive for the call; `raw` is a live
        // out-pointer, set only on success.
        check("oniDeviceOpen", unsafe { ffi::oniDeviceOpen(c_uri.as_ptr(), &mut raw) })?;
        if raw.is_null() {
            return Err(Error::Call {
                call: "oniDeviceOpen",
                status: Status::Error,
                detail: "returned no handle".to_owned(),
            });
        }
        Ok(Device {
            shared: Arc::new(DeviceShared {
                raw: Mutex::new(RawDevice(raw)),
                uri: uri.to_owned(),
            }),
        })
    }

    /// The URI the device was opened with.
    pub fn uri(&self) -> &str {
        &self.shared.uri
    }

    /// What the driver says of the device now.
    ///
    /// # Errors
    /// `oniDeviceGetInfo` failed.
    pub fn info(&self) -> Result<DeviceInfo, Error> {
        let raw = lock(&self.shared.raw);
        let mut info = ffi::OniDeviceInfo::default();
        // SAFETY: the handle is open (we hold it); `info` is a live out-parameter.
        check("oniDeviceGetInfo", unsafe { ffi::oniDeviceGetInfo(raw.0, &mut info) })?;
        Ok(DeviceInfo::from_raw(&info))
    }

    /// The sensor of a type and its modes, or `None` when the device has none.
    pub fn sensor_info(&self, sensor: SensorType) -> Option<SensorInfo> {
        let raw = lock(&self.shared.raw);
        // SAFETY: the handle is open; OpenNI2 returns NULL or a pointer into the device's own
        // sensor table, valid while the device is open (it is, and locked) and copied at once.
        unsafe {
            let info = ffi::oniDeviceGetSensorInfo(raw.0, sensor.raw());
            SensorInfo::from_raw(sensor, info)
        }
    }

    /// Whether the driver supports a device property (`ffi::ONI_DEVICE_PROPERTY_*`).
    pub fn is_property_supported(&self, property: u32) -> bool {
        let Ok(id) = c_int::try_from(property) else {
            return false;
        };
        let raw = lock(&self.shared.raw);
        // SAFETY: the handle is open; the call only reads its arguments.
        unsafe { ffi::oniDeviceIsPropertySupported(raw.0, id) != 0 }
    }

    /// Reads a device property into `buf`; returns how many bytes the driver wrote.
    ///
    /// # Errors
    /// The driver does not have the property or it does not fit `buf`.
    pub fn property_bytes(&self, property: u32, buf: &mut [u8]) -> Result<usize, Error> {
        let id = c_int::try_from(property).map_err(|_| bad_property(property))?;
        let mut size = c_int::try_from(buf.len()).unwrap_or(c_int::MAX);
        let raw = lock(&self.shared.raw);
        // SAFETY: the handle is open; `buf` is writable for `size` bytes and OpenNI2 writes at
        // most `size` bytes, then sets `size` to the bytes written.
        check("oniDeviceGetProperty", unsafe {
            ffi::oniDeviceGetProperty(raw.0, id, buf.as_mut_ptr().cast(), &mut size)
        })?;
        Ok(usize::try_from(size).unwrap_or(0).min(buf.len()))
    }

    /// Writes a device property from raw bytes.
    ///
    /// # Errors
    /// The driver refused the property or its value.
    pub fn set_property_bytes(&self, property: u32, value: &[u8]) -> Result<(), Error> {
        let id = c_int::try_from(property).map_err(|_| bad_property(property))?;
        let size = c_int::try_from(value.len()).map_err(|_| bad_property(property))?;
        let raw = lock(&self.shared.raw);
        // SAFETY: the handle is open; `value` is readable for `size` bytes, which OpenNI2 only
        // reads during the call.
        check("oniDeviceSetProperty", unsafe {
            ffi::oniDeviceSetProperty(raw.0, id, value.as_ptr().cast(), size)
        })
    }

    /// A string property (serial number, firmware version), trimmed at its first NUL.
    fn string_property(&self, property: u32) -> Result<String, Error> {
        let mut buf = [0u8; ffi::ONI_MAX_STR as usize];
        let len = self.property_bytes(property, &mut buf)?;
        let text = &buf[..len];
        let end = text.iter().position(|&b| b == 0).unwrap_or(text.len());
        Ok(String::from_utf8_lossy(&text[..end]).trim().to_owned())
    }

    /// The serial number (`ONI_DEVICE_PROPERTY_SERIAL_NUMBER`).
    ///
    /// # Errors
    /// The driver has no serial number (Dummy, files).
    pub fn serial(&self) -> Result<String, Error> {
        self.string_property(ffi::ONI_DEVICE_PROPERTY_SERIAL_NUMBER)
    }

    /// The firmware version as the driver writes it (`ONI_DEVICE_PROPERTY_FIRMWARE_VERSION`).
    ///
    /// # Errors
    /// The driver does not report a firmware version.
    pub fn firmware(&self) -> Result<String, Error> {
        self.string_property(ffi::ONI_DEVICE_PROPERTY_FIRMWARE_VERSION)
    }

    /// Whether the device is a played-back file (it has a playback speed).
    pub fn is_file(&self) -> bool {
        self.is_property_supported(ffi::ONI_DEVICE_PROPERTY_PLAYBACK_SPEED)
    }

    /// Sets how fast a played-back file delivers frames.
    ///
    /// # Errors
    /// The device is not a file.
    pub fn set_playback_speed(&self, speed: PlaybackSpeed) -> Result<(), Error> {
        self.set_property_bytes(ffi::ONI_DEVICE_PROPERTY_PLAYBACK_SPEED, &speed.raw().to_ne_bytes())
    }

    /// How fast a played-back file delivers frames.
    ///
    /// # Errors
    /// The device is not a file.
    pub fn playback_speed(&self) -> Result<PlaybackSpeed, Error> {
        let mut buf = [0u8; 4];
        self.property_bytes(ffi::ONI_DEVICE_PROPERTY_PLAYBACK_SPEED, &mut buf)?;
        Ok(PlaybackSpeed::from_raw(f32::from_ne_bytes(buf)))
    }

    /// Whether a played-back file starts over at its end (OpenNI2's default) or stops.
    ///
    /// # Errors
    /// The device is not a file.
    pub fn set_playback_repeat(&self, repeat: bool) -> Result<(), Error> {
        let value: ffi::OniBool = repeat.into();
        self.set_property_bytes(ffi::ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED, &value.to_ne_bytes())
    }

    /// True once a played-back file with repeat off has delivered its last frame to its streams
    /// (OpenNI2's end-of-file device state). A frame may still be waiting to be read: see
    /// [`DepthStream::read_frame`], which only reports the end once none is.
    pub fn playback_ended(&self) -> bool {
        lock(&ENDED).iter().any(|u| u == &self.shared.uri)
    }

    /// Creates a depth stream (not started) in the driver's default mode.
    ///
    /// # Errors
    /// The device has no depth sensor or the driver failed to create the stream.
    pub fn create_depth_stream(&self) -> Result<DepthStream, Error> {
        if self.sensor_info(SensorType::Depth).is_none() {
            return Err(Error::NoSensor(SensorType::Depth));
        }
        let mut stream: ffi::OniStreamHandle = std::ptr::null_mut();
        {
            let raw = lock(&self.shared.raw);
            // SAFETY: the handle is open; `stream` is a live out-pointer set only on success.
            check("oniDeviceCreateStream", unsafe {
                ffi::oniDeviceCreateStream(raw.0, ffi::ONI_SENSOR_DEPTH, &mut stream)
            })?;
        }
        if stream.is_null() {
            return Err(Error::Call {
                call: "oniDeviceCreateStream",
                status: Status::Error,
                detail: "returned no handle".to_owned(),
            });
        }
        Ok(DepthStream {
            shared: Arc::new(StreamShared {
                raw: Mutex::new(RawStream {
                    handle: stream,
                    started: false,
                    stopped_at: None,
                }),
                _device: Arc::clone(&self.shared),
            }),
            eof_uri: self.is_file().then(|| self.shared.uri.clone()),
        })
    }
}

fn bad_property(property: u32) -> Error {
    Error::Call {
        call: "property",
        status: Status::BadParameter,
        detail: format!("property id {property} out of range"),
    }
}

// ---------------------------------------------------------------------------------------------
// Streams and frames

/// A stream handle and what its teardown needs to know.
#[derive(Debug)]
struct RawStream {
    handle: ffi::OniStreamHandle,
    started: bool,
    /// When the stream was last stopped, if it was ever started.
    stopped_at: Option<Instant>,
}

// SAFETY: a stream handle is an opaque pointer into the process-wide context, not tied to the
// thread that created it; it is only used through the mutex in `StreamShared`.
unsafe impl Send for RawStream {}

impl RawStream {
    fn stop(&mut self) {
        if self.started {
            // SAFETY: the handle is alive (destroyed only in Drop) and started.
            unsafe { ffi::oniStreamStop(self.handle) };
            self.started = false;
            self.stopped_at = Some(Instant::now());
        }
    }
}

#[derive(Debug)]
struct StreamShared {
    raw: Mutex<RawStream>,
    /// Keeps the device open until the stream is destroyed.
    _device: Arc<DeviceShared>,
}

impl Drop for StreamShared {
    fn drop(&mut self) {
        let raw = self.raw.get_mut().unwrap_or_else(PoisonError::into_inner);
        raw.stop();
        if let Some(stopped_at) = raw.stopped_at {
            let settled = stopped_at.elapsed();
            if settled < STOP_SETTLE {
                std::thread::sleep(STOP_SETTLE - settled);
            }
        }
        // SAFETY: the handle came from oniDeviceCreateStream and is destroyed once, here, while
        // its device is still open (`_device` drops after this body); recorders that used it
        // hold an Arc to this value, so they are gone.
        unsafe { ffi::oniStreamDestroy(raw.handle) };
    }
}

/// A depth stream of a [`Device`]. Keeps the device open; stopped (with [`STOP_SETTLE`]) and
/// destroyed on drop.
#[derive(Debug)]
pub struct DepthStream {
    shared: Arc<StreamShared>,
    /// The file's URI when the device is a played-back file.
    eof_uri: Option<String>,
}

/// One depth frame as OpenNI2 delivered it. `data` is row-major, `width * height` values, in
/// the units of the stream's pixel format (millimetres for [`PixelFormat::Depth1Mm`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DepthFrame {
    /// The driver's frame counter (`frameIndex`).
    pub index: u64,
    /// The device clock in microseconds (`timestamp`).
    pub timestamp_us: u64,
    /// The unit of `data` (a depth format).
    pub pixel_format: PixelFormat,
    pub width: u32,
    pub height: u32,
    pub data: Vec<u16>,
}

/// What [`DepthStream::read_frame`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadOutcome {
    /// A frame was copied into the caller's [`DepthFrame`].
    Frame,
    /// No frame within the timeout.
    Timeout,
    /// A played-back file (repeat off) has no more frames.
    EndOfFile,
}

impl DepthStream {
    /// The sensor's modes (the same as the device's depth sensor).
    pub fn sensor_info(&self) -> Option<SensorInfo> {
        let raw = lock(&self.shared.raw);
        // SAFETY: the stream is alive; OpenNI2 returns NULL or a pointer into the stream's
        // sensor table, valid while the stream exists, copied at once.
        unsafe {
            let info = ffi::oniStreamGetSensorInfo(raw.handle);
            SensorInfo::from_raw(SensorType::Depth, info)
        }
    }

    /// The stream's current mode.
    ///
    /// # Errors
    /// The driver does not report it.
    pub fn video_mode(&self) -> Result<VideoMode, Error> {
        let mut mode = ffi::OniVideoMode::default();
        let mut size = size_of::<ffi::OniVideoMode>() as c_int;
        let raw = lock(&self.shared.raw);
        // SAFETY: the stream is alive; `mode` is writable for `size` bytes, the exact size of
        // the struct OpenNI2 writes for this property.
        check("oniStreamGetProperty(VIDEO_MODE)", unsafe {
            ffi::oniStreamGetProperty(
                raw.handle,
                ffi::ONI_STREAM_PROPERTY_VIDEO_MODE as c_int,
                (&raw mut mode).cast(),
                &mut size,
            )
        })?;
        Ok(VideoMode::from_raw(&mode))
    }

    /// Sets the stream's mode (before it starts). Drivers with a single mode (Dummy) refuse
    /// even that one: compare with [`DepthStream::video_mode`] first.
    ///
    /// # Errors
    /// The driver refused the mode.
    pub fn set_video_mode(&mut self, mode: VideoMode) -> Result<(), Error> {
        let raw_mode = mode.raw();
        let raw = lock(&self.shared.raw);
        // SAFETY: the stream is alive; `raw_mode` is a complete OniVideoMode read during the
        // call only.
        check("oniStreamSetProperty(VIDEO_MODE)", unsafe {
            ffi::oniStreamSetProperty(
                raw.handle,
                ffi::ONI_STREAM_PROPERTY_VIDEO_MODE as c_int,
                (&raw const raw_mode).cast(),
                size_of::<ffi::OniVideoMode>() as c_int,
            )
        })
    }

    /// The stream's cropping (`ONI_STREAM_PROPERTY_CROPPING`), `None` when the driver does not
    /// implement it (Dummy). A `.oni` recording of such a stream needs the fix-up
    /// [`Recorder::finish`] does.
    pub fn cropping(&self) -> Option<ffi::OniCropping> {
        let mut cropping = ffi::OniCropping::default();
        let mut size = size_of::<ffi::OniCropping>() as c_int;
        let raw = lock(&self.shared.raw);
        // SAFETY: the stream is alive; `cropping` is writable for `size` bytes, the size of the
        // struct OpenNI2 writes for this property.
        let status = unsafe {
            ffi::oniStreamGetProperty(
                raw.handle,
                ffi::ONI_STREAM_PROPERTY_CROPPING as c_int,
                (&raw mut cropping).cast(),
                &mut size,
            )
        };
        (status == ffi::ONI_STATUS_OK).then_some(cropping)
    }

    /// The stream's horizontal and vertical fields of view, radians
    /// (`ONI_STREAM_PROPERTY_HORIZONTAL_FOV`, `ONI_STREAM_PROPERTY_VERTICAL_FOV`).
    ///
    /// # Errors
    /// The driver does not report them.
    pub fn field_of_view(&self) -> Result<(f32, f32), Error> {
        let raw = lock(&self.shared.raw);
        let get = |property: u32, what: &'static str| -> Result<f32, Error> {
            let mut value: f32 = 0.0;
            let mut size = size_of::<f32>() as c_int;
            // SAFETY: the stream is alive; `value` is writable for `size` bytes, the float
            // OpenNI2 writes for these properties.
            check(what, unsafe {
                ffi::oniStreamGetProperty(raw.handle, property as c_int, (&raw mut value).cast(), &mut size)
            })?;
            Ok(value)
        };
        let h = get(
            ffi::ONI_STREAM_PROPERTY_HORIZONTAL_FOV,
            "oniStreamGetProperty(HORIZONTAL_FOV)",
        )?;
        let v = get(
            ffi::ONI_STREAM_PROPERTY_VERTICAL_FOV,
            "oniStreamGetProperty(VERTICAL_FOV)",
        )?;
        Ok((h, v))
    }

    /// The number of frames of a played-back stream (`ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES`).
    ///
    /// # Errors
    /// The stream is not from a file.
    pub fn number_of_frames(&self) -> Result<u64, Error> {
        let mut count: c_int = 0;
        let mut size = size_of::<c_int>() as c_int;
        let raw = lock(&self.shared.raw);
        // SAFETY: the stream is alive; `count` is writable for `size` bytes, the size OpenNI2
        // writes for this property.
        check("oniStreamGetProperty(NUMBER_OF_FRAMES)", unsafe {
            ffi::oniStreamGetProperty(
                raw.handle,
                ffi::ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES as c_int,
                (&raw mut count).cast(),
                &mut size,
            )
        })?;
        Ok(u64::try_from(count).unwrap_or(0))
    }

    /// Starts streaming.
    ///
    /// # Errors
    /// The driver failed to start.
    pub fn start(&mut self) -> Result<(), Error> {
        let mut raw = lock(&self.shared.raw);
        if raw.started {
            return Ok(());
        }
        // SAFETY: the stream is alive and not started.
        check("oniStreamStart", unsafe { ffi::oniStreamStart(raw.handle) })?;
        raw.started = true;
        Ok(())
    }

    /// Stops streaming (does nothing when not started). The stream can be started again.
    pub fn stop(&mut self) {
        lock(&self.shared.raw).stop();
    }

    /// Whether the stream is started.
    pub fn is_started(&self) -> bool {
        lock(&self.shared.raw).started
    }

    /// Waits at most `timeout` for a frame and copies it into `frame`, reusing its buffer (no
    /// allocation once the buffer has the frame's size).
    ///
    /// For a played-back file with repeat off, returns [`ReadOutcome::EndOfFile`] once the file
    /// has signalled its end and no frame is left to read.
    ///
    /// # Errors
    /// The stream is not started, the wait or the read failed, or the frame is not 16-bit depth
    /// of the size it claims.
    pub fn read_frame(&mut self, timeout: Duration, frame: &mut DepthFrame) -> Result<ReadOutcome, Error> {
        let raw = lock(&self.shared.raw);
        if !raw.started {
            return Err(Error::Call {
                call: "oniWaitForAnyStream",
                status: Status::OutOfFlow,
                detail: "the stream is not started".to_owned(),
            });
        }
        // The end flag is read before waiting: the player delivers its last frame before it
        // reports the end, so a wait that then finds nothing means the last frame was read.
        let ended = self
            .eof_uri
            .as_deref()
            .is_some_and(|uri| lock(&ENDED).iter().any(|u| u == uri));
        let wait_ms = if ended {
            0
        } else {
            c_int::try_from(timeout.as_millis()).unwrap_or(c_int::MAX)
        };
        let mut handle = raw.handle;
        let mut index: c_int = -1;
        // SAFETY: `handle` is a live, started stream; the array of one handle and `index` are
        // live locals for the duration of the call.
        let status = unsafe { ffi::oniWaitForAnyStream(&mut handle, 1, &mut index, wait_ms) };
        if status == ffi::ONI_STATUS_TIME_OUT {
            return Ok(if ended {
                ReadOutcome::EndOfFile
            } else {
                ReadOutcome::Timeout
            });
        }
        check("oniWaitForAnyStream", status)?;

        let mut raw_frame: *mut ffi::OniFrame = std::ptr::null_mut();
        // SAFETY: the stream is alive and has a frame ready (the wait said so); `raw_frame` is a
        // live out-pointer, set on success to a frame we hold one reference to.
        check("oniStreamReadFrame", unsafe {
            ffi::oniStreamReadFrame(raw.handle, &mut raw_frame)
        })?;
        if raw_frame.is_null() {
            return Err(Error::BadFrame("oniStreamReadFrame returned no frame".to_owned()));
        }
        // SAFETY: non-null frame we hold a reference to; released right after the copy.
        let copied = unsafe { copy_frame(&*raw_frame, frame) };
        // SAFETY: releases the one reference oniStreamReadFrame gave us; `raw_frame` is not used
        // after this.
        unsafe { ffi::oniFrameRelease(raw_frame) };
        copied.map(|()| ReadOutcome::Frame)
    }
}

/// Copies an OpenNI2 frame into a [`DepthFrame`], reusing its buffer: one pass over the pixels,
/// no allocation once the buffer has grown to the frame's size.
///
/// # Safety
/// `src.data` points to at least `src.dataSize` readable bytes (OpenNI2's frame contract).
unsafe fn copy_frame(src: &ffi::OniFrame, dst: &mut DepthFrame) -> Result<(), Error> {
    let format = PixelFormat::from_raw(src.videoMode.pixelFormat);
    if !matches!(
        format,
        PixelFormat::Depth1Mm | PixelFormat::Depth100Um | PixelFormat::Shift9_2 | PixelFormat::Shift9_3
    ) {
        return Err(Error::BadFrame(format!("pixel format {format} is not 16-bit depth")));
    }
    let (Ok(width), Ok(height), Ok(stride), Ok(size)) = (
        usize::try_from(src.width),
        usize::try_from(src.height),
        usize::try_from(src.stride),
        usize::try_from(src.dataSize),
    ) else {
        return Err(Error::BadFrame(format!(
            "negative geometry: {}x{}, stride {}, {} bytes",
            src.width, src.height, src.stride, src.dataSize
        )));
    };
    let row_bytes = width * 2;
    let stride = if stride == 0 { row_bytes } else { stride };
    let needed = if height == 0 {
        0
    } else {
        stride * (height - 1) + row_bytes
    };
    if stride < row_bytes || stride % 2 != 0 || size < needed || (needed > 0 && src.data.is_null()) {
        return Err(Error::BadFrame(format!(
            "{width}x{height} with stride {stride} does not fit {size} bytes"
        )));
    }
    dst.index = u64::try_from(src.frameIndex).unwrap_or(0);
    dst.timestamp_us = src.timestamp;
    dst.pixel_format = format;
    dst.width = width as u32;
    dst.height = height as u32;
    dst.data.clear();
    if needed == 0 {
        return Ok(());
    }
    dst.data.reserve(width * height);
    // SAFETY: `data` is non-null and readable for `size >= needed` bytes (checked above and per
    // the function's contract); it is read as bytes, so its alignment does not matter.
    let bytes = unsafe { std::slice::from_raw_parts(src.data.cast::<u8>(), needed) };
    for row in bytes.chunks(stride).take(height) {
        let line = row.get(..row_bytes).unwrap_or_default();
        dst.data
            .extend(line.chunks_exact(2).map(|pair| u16::from_ne_bytes([pair[0], pair[1]])));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Recording

/// Records streams into a `.oni` file.
///
/// Keeps the attached streams alive (and so streaming) until it is finished or dropped.
/// [`Recorder::finish`] closes the file and reports errors; dropping an unfinished recorder does
/// the same and ignores them.
///
/// OpenNI2's player drops every frame of a stream whose file has no cropping record, and its
/// recorder only writes one when the driver answers the cropping property, which the Dummy
/// driver does not (setting the property first does not help: the driver refuses it). For such
/// streams `finish` writes a "cropping disabled" record into the closed file (see
/// [`oni_file::add_disabled_cropping`]).
#[derive(Debug)]
pub struct Recorder {
    handle: ffi::OniRecorderHandle,
    path: PathBuf,
    streams: Vec<Arc<StreamShared>>,
    /// Whether some attached stream has no cropping property, so the file needs the fix-up.
    needs_cropping: bool,
    started: bool,
    finished: bool,
}

// SAFETY: a recorder handle is an opaque pointer into the process-wide context, not tied to a
// thread; `Recorder` is not `Sync` and every call takes `&mut self` or `self`, so one thread at a
// time uses it.
unsafe impl Send for Recorder {}

impl Recorder {
    /// Creates a recorder writing to `path` (created or truncated).
    ///
    /// # Errors
    /// OpenNI2 cannot be initialised or refuses the file name.
    pub fn create(path: &Path) -> Result<Recorder, Error> {
        OpenNI::init()?;
        let name = path.to_string_lossy();
        let c_name = c_string("recording path", &name)?;
        let mut handle: ffi::OniRecorderHandle = std::ptr::null_mut();
        // SAFETY: `c_name` is NUL-terminated and alive for the call; `handle` is a live
        // out-pointer set only on success.
        check("oniCreateRecorder", unsafe {
            ffi::oniCreateRecorder(c_name.as_ptr(), &mut handle)
        })?;
        if handle.is_null() {
            return Err(Error::Call {
                call: "oniCreateRecorder",
                status: Status::Error,
                detail: "returned no handle".to_owned(),
            });
        }
        Ok(Recorder {
            handle,
            path: path.to_owned(),
            streams: Vec::new(),
            needs_cropping: false,
            started: false,
            finished: false,
        })
    }

    /// Attaches a stream (before [`Recorder::start`]). Depth is stored losslessly unless
    /// `lossy` allows OpenNI2's lossy codecs.
    ///
    /// # Errors
    /// The recorder already started, or OpenNI2 refused the stream.
    pub fn attach(&mut self, stream: &DepthStream, lossy: bool) -> Result<(), Error> {
        let has_cropping = stream.cropping().is_some();
        let raw = lock(&stream.shared.raw);
        // SAFETY: both handles are alive; the recorder keeps an Arc to the stream from here on,
        // so the stream outlives its attachment.
        check("oniRecorderAttachStream", unsafe {
            ffi::oniRecorderAttachStream(self.handle, raw.handle, lossy.into())
        })?;
        drop(raw);
        self.streams.push(Arc::clone(&stream.shared));
        self.needs_cropping |= !has_cropping;
        Ok(())
    }

    /// Starts (or resumes) recording the attached streams' frames. OpenNI2 starts
    /// asynchronously: frames that arrive in the next few milliseconds may not be recorded.
    ///
    /// # Errors
    /// No stream is attached, or OpenNI2 failed to start.
    pub fn start(&mut self) -> Result<(), Error> {
        // SAFETY: the handle is alive (destroyed only in `close`).
        check("oniRecorderStart", unsafe { ffi::oniRecorderStart(self.handle) })?;
        self.started = true;
        Ok(())
    }

    /// Stops recording; frames produced from now on are not written. Recording can resume with
    /// [`Recorder::start`].
    pub fn stop(&mut self) {
        if self.started {
            // SAFETY: the handle is alive.
            unsafe { ffi::oniRecorderStop(self.handle) };
            self.started = false;
        }
    }

    /// Stops recording, closes the file (OpenNI2 writes its seek tables) and adds the cropping
    /// record the player needs when a stream had none. The attached streams are released.
    ///
    /// # Errors
    /// OpenNI2 failed to close the recorder, or the closed file cannot be read or fixed.
    pub fn finish(mut self) -> Result<(), Error> {
        self.close()
    }

    fn close(&mut self) -> Result<(), Error> {
        if self.finished {
            return Ok(());
        }
        self.finished = true;
        self.stop();
        // SAFETY: the handle came from oniCreateRecorder and is destroyed once (`finished`
        // guards), before the streams it records are released. OpenNI2 drains the recorder's
        // queue and writes the file's tables before returning.
        let status = unsafe { ffi::oniRecorderDestroy(&mut self.handle) };
        self.streams.clear();
        check("oniRecorderDestroy", status)?;
        if self.needs_cropping {
            oni_file::add_disabled_cropping(&self.path)?;
        }
        Ok(())
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        // Errors cannot be reported from Drop; `finish` is the way to see them.
        let _ = self.close();
    }
}

/// The minimum of the `.oni` format (OpenNI's "NI10" record file) needed to fix a recording.
pub mod oni_file {
    use super::Error;
    use std::path::Path;

    /// The file header: magic, version, max timestamp, max node id (padded).
    const FILE_HEADER_BYTES: usize = 24;
    /// A record header: magic `NIR\0`, type, node id, fields size (header included), payload
    /// size, undo position (`u64`), little-endian.
    const RECORD_HEADER_BYTES: usize = 28;
    const RECORD_MAGIC: &[u8; 4] = b"NIR\0";
    const RECORD_INT_PROPERTY: u32 = 0x03;
    const RECORD_GENERAL_PROPERTY: u32 = 0x06;
    const RECORD_END: u32 = 0x0B;

    /// The record written in place of `xnIsGenerating`: a general property `xnCropping` holding
    /// OpenNI's `XnCropping { XnBool enabled; u16 x, y, width, height }` all zero (disabled).
    fn cropping_record(node: u32) -> Vec<u8> {
        let name = b"xnCropping\0";
        let data = [0u8; 12];
        let fields = RECORD_HEADER_BYTES + 4 + name.len() + 4 + data.len();
        let mut out = Vec::with_capacity(fields);
        out.extend_from_slice(RECORD_MAGIC);
        out.extend_from_slice(&RECORD_GENERAL_PROPERTY.to_le_bytes());
        out.extend_from_slice(&node.to_le_bytes());
        out.extend_from_slice(&(fields as u32).to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&0u64.to_le_bytes());
        out.extend_from_slice(&(name.len() as u32).to_le_bytes());
        out.extend_from_slice(name);
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(&data);
        out
    }

    fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
        let b = bytes.get(at..at + 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// One property record: where it is, its node, type, size and name.
    struct Property {
        offset: usize,
        node: u32,
        kind: u32,
        size: usize,
        payload: usize,
        name: Vec<u8>,
    }

    /// The property records of a recording, in file order, up to its end record.
    fn properties(bytes: &[u8]) -> Result<Vec<Property>, String> {
        if bytes.get(..4) != Some(b"NI10") {
            return Err("not an OpenNI recording (no NI10 header)".to_owned());
        }
        let mut out = Vec::new();
        let mut at = FILE_HEADER_BYTES;
        while at + RECORD_HEADER_BYTES <= bytes.len() {
            if bytes.get(at..at + 4) != Some(RECORD_MAGIC) {
                return Err(format!("no record at byte {at}"));
            }
            let header = |i: usize| u32_at(bytes, at + 4 * i).ok_or_else(|| format!("truncated record at byte {at}"));
            let (kind, node, fields, payload) = (header(1)?, header(2)?, header(3)?, header(4)?);
            let (fields, payload) = (fields as usize, payload as usize);
            if fields < RECORD_HEADER_BYTES || at + fields + payload > bytes.len() {
                return Err(format!("record at byte {at} overruns the file"));
            }
            if kind == RECORD_END {
                break;
            }
            if (RECORD_INT_PROPERTY..=RECORD_GENERAL_PROPERTY).contains(&kind) {
                let name_len = u32_at(bytes, at + RECORD_HEADER_BYTES).unwrap_or(0) as usize;
                let name_at = at + RECORD_HEADER_BYTES + 4;
                let name = bytes
                    .get(name_at..(name_at + name_len).min(at + fields))
                    .unwrap_or_default()
                    .iter()
                    .copied()
                    .take_while(|&b| b != 0)
                    .collect();
                out.push(Property {
                    offset: at,
                    node,
                    kind,
                    size: fields,
                    payload,
                    name,
                });
            }
            at += fields + payload;
        }
        Ok(out)
    }

    /// Gives every node of a closed `.oni` recording that has no `xnCropping` record a
    /// "cropping disabled" one, so that OpenNI2's player delivers its frames. Does nothing to a
    /// file whose nodes all have one.
    ///
    /// The record takes the place of the node's `xnIsGenerating` integer property, which only
    /// OpenNI 1.x reads and which has exactly the same size, so no position recorded elsewhere
    /// in the file (seek tables, undo links) moves.
    ///
    /// # Errors
    /// The file cannot be read or written, is not a recording, or a node lacking cropping has
    /// no record of the right size to replace.
    pub fn add_disabled_cropping(path: &Path) -> Result<(), Error> {
        let io_error = |source| Error::File {
            path: path.to_owned(),
            source,
        };
        let bad = |reason: String| Error::BadRecording {
            path: path.to_owned(),
            reason,
        };
        let mut bytes = std::fs::read(path).map_err(io_error)?;
        let props = properties(&bytes).map_err(bad)?;
        let mut nodes: Vec<u32> = props.iter().map(|p| p.node).collect();
        nodes.sort_unstable();
        nodes.dedup();
        let mut changed = false;
        for node in nodes {
            let of_node = || props.iter().filter(move |p| p.node == node);
            if of_node().any(|p| p.name == b"xnCropping") {
                continue;
            }
            let record = cropping_record(node);
            let slot = of_node()
                .find(|p| {
                    p.name == b"xnIsGenerating"
                        && p.kind == RECORD_INT_PROPERTY
                        && p.size == record.len()
                        && p.payload == 0
                })
                .ok_or_else(|| bad(format!("node {node} has no xnIsGenerating record to replace")))?;
            bytes[slot.offset..slot.offset + record.len()].copy_from_slice(&record);
            changed = true;
        }
        if changed {
            std::fs::write(path, &bytes).map_err(io_error)?;
        }
        Ok(())
    }
}

// Every handle type can move to a capture thread.
const _: () = {
    const fn is_send<T: Send>() {}
    is_send::<Device>();
    is_send::<DepthStream>();
    is_send::<Recorder>();
};
