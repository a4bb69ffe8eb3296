//! What mousepose needs from Aravis 0.8 that the `aravis` crate does not wrap, behind a safe API:
//!
//! - choosing which Aravis interfaces (`GigEVision`, `USB3Vision`, `Fake`) discovery and
//!   `arv_open_device` may use, so that nothing broadcasts on a network it should not;
//! - opening a GigE Vision camera by address alone (unicast, no discovery);
//! - [`FakeCamera`], Aravis's own GigE Vision camera simulator run inside the process on the
//!   loopback interface, streaming frames a Rust closure draws.
//!
//! All the `unsafe` code of mousepose's Aravis support lives here; the main crate denies it.

use aravis::glib;
use aravis::glib::translate::ToGlibPtr;
use std::ffi::{CStr, c_void};
use std::net::{IpAddr, Ipv4Addr, UdpSocket};
use std::panic::AssertUnwindSafe;

pub use aravis;

/// The UDP port of the GigE Vision control protocol (GVCP). Aravis 0.8 has its fake camera
/// listen on this port only, so one fake camera at a time can run on an address.
pub const GVCP_PORT: u16 = 3956;

/// One of Aravis's device interfaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Interface {
    /// GigE Vision: discovery broadcasts on every network interface of the host.
    GigEVision,
    /// USB3 Vision: discovery enumerates the USB bus (no network traffic).
    Usb3Vision,
    /// Aravis's built-in fake camera interface (disabled by Aravis by default).
    Fake,
}

impl Interface {
    pub const ALL: [Interface; 3] = [Interface::GigEVision, Interface::Usb3Vision, Interface::Fake];

    /// The interface id Aravis uses.
    pub fn id(self) -> &'static CStr {
        match self {
            Interface::GigEVision => c"GigEVision",
            Interface::Usb3Vision => c"USB3Vision",
            Interface::Fake => c"Fake",
        }
    }
}

/// Lets Aravis's discovery and `arv_open_device` use `interface`. Process-wide.
pub fn enable_interface(interface: Interface) {
    // SAFETY: the argument is a valid NUL-terminated string that outlives the call; Aravis
    // only compares it with its interface ids under its own system mutex and keeps no pointer.
    unsafe { aravis_sys::arv_enable_interface(interface.id().as_ptr()) }
}

/// Keeps Aravis's discovery and `arv_open_device` away from `interface`. Process-wide.
pub fn disable_interface(interface: Interface) {
    // SAFETY: as in `enable_interface`.
    unsafe { aravis_sys::arv_disable_interface(interface.id().as_ptr()) }
}

/// Enables exactly the listed interfaces and disables the others. Process-wide.
pub fn use_only_interfaces(interfaces: &[Interface]) {
    for interface in Interface::ALL {
        if interfaces.contains(&interface) {
            enable_interface(interface);
        } else {
            disable_interface(interface);
        }
    }
}

/// The address of the host's network interface that the kernel would use to reach `device`.
///
/// Works out the route with an unconnected-then-connected UDP socket: connecting a UDP
/// socket sends nothing.
///
/// # Errors
/// There is no route to `device`.
pub fn local_address_for(device: Ipv4Addr) -> std::io::Result<Ipv4Addr> {
    let socket = UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))?;
    socket.connect((device, GVCP_PORT))?;
    match socket.local_addr()?.ip() {
        IpAddr::V4(ip) => Ok(ip),
        IpAddr::V6(ip) => Err(std::io::Error::other(format!(
            "route to {device} goes through IPv6 address {ip}"
        ))),
    }
}

/// Opens the GigE Vision camera at `device` by unicast, without any discovery: the control
/// channel is opened from the local address that routes to `device`.
///
/// # Errors
/// No route to the address, no GigE Vision camera answering there, or a camera that cannot
/// be controlled (its GenICam description is unreadable, another application controls it).
pub fn open_gv_camera(device: Ipv4Addr) -> Result<aravis::Camera, OpenError> {
    let local = local_address_for(device).map_err(|source| OpenError::NoRoute { device, source })?;
    let local = gio::InetAddress::from(IpAddr::V4(local));
    let remote = gio::InetAddress::from(IpAddr::V4(device));
    let gv_device = aravis::GvDevice::new(&local, &remote).map_err(|source| OpenError::Device { device, source })?;
    // Aravis opens a camera it cannot take control of read-only, without an error: a stream
    // from it would never start.
    if !gv_device.is_controller() {
        return Err(OpenError::Held { device });
    }
    aravis::Camera::with_device(&gv_device).map_err(|source| OpenError::Device { device, source })
}

/// Why [`open_gv_camera`] failed.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error("no route to {device}")]
    NoRoute {
        device: Ipv4Addr,
        #[source]
        source: std::io::Error,
    },
    /// Another application controls the camera, or a process that controlled it ended less
    /// than the camera's heartbeat timeout ago (typically a few seconds).
    #[error(
        "the camera at {device} is controlled by another application (or by one that ended less than the camera's heartbeat timeout ago)"
    )]
    Held { device: Ipv4Addr },
    #[error("no GigE Vision camera answers at {device}")]
    Device {
        device: Ipv4Addr,
        #[source]
        source: glib::Error,
    },
}

/// What draws the fake camera's frames: called on Aravis's fake camera thread with the
/// frame's bytes (the whole payload, `width * height * bytes per pixel` for the pixel format
/// the client chose), its width and height in pixels and its frame id (1 to 65535, wrapping).
pub type FillFn = Box<dyn FnMut(&mut [u8], u32, u32, u64) + Send>;

/// Why a [`FakeCamera`] could not start.
#[derive(Debug, thiserror::Error)]
pub enum FakeCameraError {
    #[error("the GVCP port {address}:{GVCP_PORT} is taken (another camera is running there)")]
    PortInUse {
        address: Ipv4Addr,
        #[source]
        source: std::io::Error,
    },
    #[error("the fake camera could not listen on {address}")]
    NotRunning { address: Ipv4Addr },
    #[error("the fake camera has no underlying device model")]
    NoModel,
    #[error("the GenICam file path {0:?} is not valid UTF-8")]
    GenicamPath(std::path::PathBuf),
}

/// How to build a [`FakeCamera`].
#[derive(Clone, Debug)]
pub struct FakeCameraConfig {
    /// The serial number the camera reports.
    pub serial: String,
    /// A GenICam description to use instead of Aravis's own (it must describe the fake
    /// camera's registers, e.g. a copy of [`default_genicam_xml`] with features removed).
    pub genicam_file: Option<std::path::PathBuf>,
    /// The share of GVSP packets (0 to 1) the camera drops instead of sending.
    pub lost_packet_ratio: f64,
    /// How often, per second, the camera looks for a software trigger when it is in trigger
    /// mode: a triggered frame is sent at the next such instant. `None`: Aravis's own rate
    /// (25 Hz, far coarser than a real camera's response to a trigger).
    pub trigger_frequency: Option<f64>,
}

impl Default for FakeCameraConfig {
    fn default() -> Self {
        Self {
            serial: "GV01".into(),
            genicam_file: None,
            lost_packet_ratio: 0.0,
            trigger_frequency: None,
        }
    }
}

/// The GenICam description Aravis's fake camera uses by default.
pub fn default_genicam_xml() -> String {
    aravis::FakeCamera::new("probe").genicam_xml().0.to_string()
}

/// The state the fill trampoline reads: owned by the [`FakeCamera`], freed after Aravis has
/// been told to stop calling it.
struct FillState {
    /// The fake camera model the frames are drawn for (kept alive by `FakeCamera::model`).
    model: *mut aravis_sys::ArvFakeCamera,
    fill: FillFn,
    panicked: bool,
}

/// Aravis's GigE Vision fake camera, running in this process on 127.0.0.1 (GVCP port
/// [`GVCP_PORT`], fixed by Aravis 0.8), streaming frames drawn by a [`FillFn`]. Dropping it
/// stops the camera's thread and closes its sockets.
pub struct FakeCamera {
    /// Dropped first in `Drop`, which joins Aravis's camera thread.
    camera: Option<aravis::GvFakeCamera>,
    /// A reference to the camera's register model, keeping `FillState::model` valid.
    model: aravis::FakeCamera,
    /// From `Box::into_raw`; freed in `Drop`.
    state: *mut FillState,
    serial: String,
}

impl std::fmt::Debug for FakeCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FakeCamera")
            .field("address", &self.address())
            .field("serial", &self.serial)
            .finish_non_exhaustive()
    }
}

impl FakeCamera {
    /// Starts a fake camera on 127.0.0.1 whose frames `fill` draws.
    ///
    /// # Errors
    /// The GVCP port is taken on 127.0.0.1, or Aravis could not start the camera.
    pub fn start(config: &FakeCameraConfig, fill: FillFn) -> Result<Self, FakeCameraError> {
        let address = Ipv4Addr::LOCALHOST;
        // Aravis does not report a failed bind, so find out first whether the port is free.
        drop(UdpSocket::bind((address, GVCP_PORT)).map_err(|source| FakeCameraError::PortInUse { address, source })?);
        let genicam = match &config.genicam_file {
            Some(path) => Some(
                path.to_str()
                    .ok_or_else(|| FakeCameraError::GenicamPath(path.clone()))?
                    .to_owned(),
            ),
            None => None,
        };
        let address_text = address.to_string();
        let camera = aravis::GvFakeCamera::new_full(Some(&address_text), Some(&config.serial), genicam.as_deref());
        if !camera.is_running() {
            return Err(FakeCameraError::NotRunning { address });
        }
        camera.set_gvsp_lost_ratio(config.lost_packet_ratio.clamp(0.0, 1.0));
        let model = camera.fake_camera().ok_or(FakeCameraError::NoModel)?;
        if let Some(hz) = config.trigger_frequency.filter(|hz| hz.is_finite() && *hz > 0.0) {
            model.set_trigger_frequency(hz);
        }
        let model_ptr: *mut aravis_sys::ArvFakeCamera = model.to_glib_none().0;
        let state = Box::into_raw(Box::new(FillState {
            model: model_ptr,
            fill,
            panicked: false,
        }));
        // SAFETY: `model_ptr` is a live ArvFakeCamera (we hold a reference in `model`);
        // `state` stays valid until `Drop` has replaced the callback (which waits, under the
        // camera's fill mutex, for a running call to end) and only then frees it. The
        // trampoline matches `ArvFakeCameraFillPattern`.
        unsafe {
            aravis_sys::arv_fake_camera_set_fill_pattern(model_ptr, Some(fill_trampoline), state.cast::<c_void>());
        }
        Ok(Self {
            camera: Some(camera),
            model,
            state,
            serial: config.serial.clone(),
        })
    }

    /// The address the camera answers on.
    pub fn address(&self) -> Ipv4Addr {
        Ipv4Addr::LOCALHOST
    }

    /// The serial number the camera reports.
    pub fn serial(&self) -> &str {
        &self.serial
    }
}

impl Drop for FakeCamera {
    fn drop(&mut self) {
        let model_ptr: *mut aravis_sys::ArvFakeCamera = self.model.to_glib_none().0;
        // SAFETY: `model_ptr` is live (held by `self.model`). Setting the default pattern
        // takes the fill mutex, so once this returns no call of the trampoline is running
        // and none will start with `self.state`.
        unsafe {
            aravis_sys::arv_fake_camera_set_fill_pattern(model_ptr, None, std::ptr::null_mut());
        }
        // Joins the camera's thread and closes its sockets (we hold the only reference).
        drop(self.camera.take());
        // SAFETY: `state` came from `Box::into_raw` in `start` and Aravis no longer uses it.
        drop(unsafe { Box::from_raw(self.state) });
    }
}

/// Called by Aravis on the fake camera's thread, under its fill mutex, for each frame.
///
/// # Safety
/// `data` is the `FillState` registered in `FakeCamera::start`, valid and used by no one
/// else while the fill mutex is held; `buffer` is the camera's frame buffer, whose
/// allocation Aravis has checked to hold at least the camera's current payload.
unsafe extern "C" fn fill_trampoline(
    buffer: *mut aravis_sys::ArvBuffer,
    data: *mut c_void,
    _exposure_time_us: u32,
    _gain: u32,
    _pixel_format: aravis_sys::ArvPixelFormat,
) {
    if buffer.is_null() || data.is_null() {
        return;
    }
    // SAFETY: per the contract above, `data` points to a live `FillState` that only this
    // call touches.
    let state = unsafe { &mut *data.cast::<FillState>() };
    if state.panicked {
        return;
    }
    // SAFETY: `state.model` is the live camera that is calling us; reading its registers
    // does not need the fill mutex.
    let payload = unsafe { aravis_sys::arv_fake_camera_get_payload(state.model) };
    let mut received = 0usize;
    // SAFETY: `buffer` is a live ArvBuffer; the call only reads its fields.
    let bytes = unsafe { aravis_sys::arv_buffer_get_data(buffer, &mut received) };
    if bytes.is_null() || payload == 0 {
        return;
    }
    // SAFETY: `buffer` is a live ArvBuffer whose first part Aravis set up just before.
    let (width, height, frame_id) = unsafe {
        (
            aravis_sys::arv_buffer_get_image_width(buffer),
            aravis_sys::arv_buffer_get_image_height(buffer),
            aravis_sys::arv_buffer_get_frame_id(buffer),
        )
    };
    // SAFETY: Aravis's fake camera checked that this buffer's allocation holds at least
    // `payload` bytes before calling us (it reports a size mismatch and skips the fill
    // otherwise), the register model is only changed on this same thread, and the buffer is
    // the camera's own, touched by nothing else during the fill. Writing is what the fill
    // callback is for: the getter returns a const pointer to memory the buffer owns.
    let frame = unsafe { std::slice::from_raw_parts_mut(bytes.cast::<u8>(), payload) };
    let width = u32::try_from(width).unwrap_or(0);
    let height = u32::try_from(height).unwrap_or(0);
    let fill = &mut state.fill;
    if std::panic::catch_unwind(AssertUnwindSafe(|| fill(frame, width, height, frame_id))).is_err() {
        // A panic must not unwind into C; draw nothing more.
        state.panicked = true;
    }
}
