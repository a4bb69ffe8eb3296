//! The OpenCV calls of mousepose's calibration, safe, over Debian's OpenCV 4 through a small
//! C++ shim (`crates/opencv-calib/src/shim.cpp`, built by its `build.rs`): chessboard corners and their sub-pixel
//! refinement, camera calibration, PnP and its Levenberg-Marquardt refinement, the drawing of a
//! pose's axes, FileStorage YAML composed and parsed in memory, and OpenCV's thread count.
//!
//! Each function calls exactly one OpenCV function (or the few a drawing takes), with the
//! arguments it is given, so results are OpenCV's own. Images cross as row-major 8-bit grey
//! pixels ([`Grey`]), points as `f32` arrays, matrices as row-major `f64`. Every length is
//! checked here before the shim is called, and every C++ exception comes back as an [`Error`].

use std::ffi::{CString, c_char, c_int};
use std::fmt;
use std::marker::PhantomData;
use std::ptr::NonNull;

/// `CALIB_CB_ADAPTIVE_THRESH`: [`find_chessboard_corners`] thresholds adaptively.
pub const CALIB_CB_ADAPTIVE_THRESH: i32 = 1;
/// `CALIB_CB_NORMALIZE_IMAGE`: [`find_chessboard_corners`] equalises the image first.
pub const CALIB_CB_NORMALIZE_IMAGE: i32 = 2;
/// `CALIB_CB_FILTER_QUADS`: [`find_chessboard_corners`] rejects unlikely quads.
pub const CALIB_CB_FILTER_QUADS: i32 = 4;
/// `CALIB_CB_FAST_CHECK`: [`find_chessboard_corners`] gives up early on images without a board.
pub const CALIB_CB_FAST_CHECK: i32 = 8;
/// `CALIB_FIX_K3`: [`calibrate_camera`] holds the distortion coefficient k3 at its start (0).
pub const CALIB_FIX_K3: i32 = 128;
/// `SOLVEPNP_ITERATIVE`: [`solve_pnp`]'s Levenberg-Marquardt method.
pub const SOLVEPNP_ITERATIVE: i32 = 0;
/// `TermCriteria::COUNT`: stop after `max_count` iterations.
pub const TERM_COUNT: i32 = 1;
/// `TermCriteria::EPS`: stop when a step changes less than `epsilon`.
pub const TERM_EPS: i32 = 2;

/// The bytes of the buffer an error message is copied into.
const MESSAGE_BYTES: usize = 4096;

/// An OpenCV call that failed: which one, and OpenCV's message (or this crate's, for arguments
/// refused before the call).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    /// The OpenCV function or method, e.g. `calibrateCamera`.
    pub operation: &'static str,
    /// What OpenCV said (`cv::Exception::what`), which may span lines.
    pub message: String,
}

impl Error {
    fn new(operation: &'static str, message: impl Into<String>) -> Self {
        Self {
            operation,
            message: message.into(),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "OpenCV's {} failed: {}", self.operation, self.message)
    }
}

impl std::error::Error for Error {}

/// The shim's functions (`crates/opencv-calib/src/shim.cpp`). Each returns 0, or 1 with its message in `err`.
mod ffi {
    use std::ffi::{c_char, c_int};

    #[repr(C)]
    pub struct OcbDoubles {
        pub data: *mut f64,
        pub capacity: usize,
        pub len: usize,
    }

    #[repr(C)]
    pub struct OcbCircle {
        pub x: c_int,
        pub y: c_int,
        pub radius: c_int,
        pub blue: f64,
        pub green: f64,
        pub red: f64,
        pub thickness: c_int,
    }

    #[repr(C)]
    #[derive(Default)]
    pub struct OcbNodeInfo {
        pub is_none: c_int,
        pub empty: c_int,
        pub is_map: c_int,
        pub is_seq: c_int,
        pub is_int: c_int,
        pub is_real: c_int,
        pub is_string: c_int,
        pub size: usize,
    }

    /// Opaque: a `cv::FileStorage` being written.
    #[repr(C)]
    pub struct OcbWriter {
        _private: [u8; 0],
    }

    /// Opaque: a parsed `cv::FileStorage`.
    #[repr(C)]
    pub struct OcbReader {
        _private: [u8; 0],
    }

    /// Opaque: a `cv::FileNode` of a reader.
    #[repr(C)]
    pub struct OcbNode {
        _private: [u8; 0],
    }

    unsafe extern "C" {
        pub fn ocb_find_chessboard_corners(
            pixels: *const u8,
            width: c_int,
            height: c_int,
            cols: c_int,
            rows: c_int,
            flags: c_int,
            corners: *mut f32,
            capacity: usize,
            count: *mut usize,
            found: *mut c_int,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_corner_sub_pix(
            pixels: *const u8,
            width: c_int,
            height: c_int,
            corners: *mut f32,
            count: usize,
            win_width: c_int,
            win_height: c_int,
            zero_width: c_int,
            zero_height: c_int,
            term_type: c_int,
            max_count: c_int,
            epsilon: f64,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_calibrate_camera(
            object: *const f32,
            image: *const f32,
            counts: *const usize,
            views: usize,
            width: c_int,
            height: c_int,
            flags: c_int,
            term_type: c_int,
            max_count: c_int,
            epsilon: f64,
            camera_matrix: *mut OcbDoubles,
            distortion: *mut OcbDoubles,
            rvecs: *mut OcbDoubles,
            tvecs: *mut OcbDoubles,
            std_intrinsics: *mut OcbDoubles,
            std_extrinsics: *mut OcbDoubles,
            per_view_errors: *mut OcbDoubles,
            rms: *mut f64,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_solve_pnp(
            object: *const f32,
            image: *const f32,
            count: usize,
            camera_matrix: *const f64,
            distortion: *const f64,
            distortion_len: usize,
            use_guess: c_int,
            flags: c_int,
            rvec: *mut f64,
            tvec: *mut f64,
            solved: *mut c_int,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_solve_pnp_refine_lm(
            object: *const f32,
            image: *const f32,
            count: usize,
            camera_matrix: *const f64,
            distortion: *const f64,
            distortion_len: usize,
            rvec: *mut f64,
            tvec: *mut f64,
            term_type: c_int,
            max_count: c_int,
            epsilon: f64,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_draw_frame_axes(
            pixels: *const u8,
            width: c_int,
            height: c_int,
            camera_matrix: *const f64,
            distortion: *const f64,
            distortion_len: usize,
            rvec: *const f64,
            tvec: *const f64,
            length: f32,
            thickness: c_int,
            circle: *const OcbCircle,
            bgr: *mut u8,
            bgr_len: usize,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;

        pub fn ocb_writer_new(out: *mut *mut OcbWriter, err: *mut c_char, err_len: usize) -> c_int;
        pub fn ocb_writer_free(writer: *mut OcbWriter);
        pub fn ocb_writer_int(
            writer: *mut OcbWriter,
            name: *const c_char,
            value: c_int,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_writer_real(
            writer: *mut OcbWriter,
            name: *const c_char,
            value: f64,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_writer_text(
            writer: *mut OcbWriter,
            name: *const c_char,
            value: *const c_char,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_writer_texts(
            writer: *mut OcbWriter,
            name: *const c_char,
            values: *const *const c_char,
            count: usize,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_writer_matrix(
            writer: *mut OcbWriter,
            name: *const c_char,
            rows: c_int,
            cols: c_int,
            data: *const f64,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_writer_begin_map(
            writer: *mut OcbWriter,
            name: *const c_char,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_writer_end_map(writer: *mut OcbWriter, err: *mut c_char, err_len: usize) -> c_int;
        pub fn ocb_writer_finish(
            writer: *mut OcbWriter,
            text: *mut *const c_char,
            len: *mut usize,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;

        pub fn ocb_reader_open(
            text: *const c_char,
            out: *mut *mut OcbReader,
            opened: *mut c_int,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_reader_free(reader: *mut OcbReader);
        pub fn ocb_reader_get(
            reader: *const OcbReader,
            name: *const c_char,
            out: *mut *mut OcbNode,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_node_get(
            node: *const OcbNode,
            name: *const c_char,
            out: *mut *mut OcbNode,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_node_at(
            node: *const OcbNode,
            index: c_int,
            out: *mut *mut OcbNode,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_node_free(node: *mut OcbNode);
        pub fn ocb_node_info(node: *const OcbNode, info: *mut OcbNodeInfo, err: *mut c_char, err_len: usize) -> c_int;
        pub fn ocb_node_int(node: *const OcbNode, out: *mut c_int, err: *mut c_char, err_len: usize) -> c_int;
        pub fn ocb_node_real(node: *const OcbNode, out: *mut f64, err: *mut c_char, err_len: usize) -> c_int;
        pub fn ocb_node_string(
            node: *const OcbNode,
            buf: *mut c_char,
            capacity: usize,
            len: *mut usize,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
        pub fn ocb_node_matrix(
            node: *const OcbNode,
            matrix: *mut c_int,
            rows: *mut c_int,
            cols: *mut c_int,
            data: *mut f64,
            capacity: usize,
            len: *mut usize,
            err: *mut c_char,
            err_len: usize,
        ) -> c_int;
    }
}

/// Runs one shim call, giving it a message buffer: its status 0 is `Ok`, any other an
/// [`Error`] with the message the shim copied.
fn check(operation: &'static str, call: impl FnOnce(*mut c_char, usize) -> c_int) -> Result<(), Error> {
    let mut message = vec![0u8; MESSAGE_BYTES];
    let status = call(message.as_mut_ptr().cast::<c_char>(), message.len());
    if status == 0 {
        return Ok(());
    }
    let end = message.iter().position(|&b| b == 0).unwrap_or(message.len());
    let text = String::from_utf8_lossy(&message[..end]).into_owned();
    Err(Error::new(
        operation,
        if text.is_empty() {
            "(no message)".to_owned()
        } else {
            text
        },
    ))
}

/// A count as OpenCV's `int`.
fn c_count(operation: &'static str, what: &str, n: usize) -> Result<c_int, Error> {
    c_int::try_from(n).map_err(|_| Error::new(operation, format!("{what} {n} is more than OpenCV's int holds")))
}

/// `text` NUL-terminated for C.
fn c_text(operation: &'static str, text: &str) -> Result<CString, Error> {
    CString::new(text).map_err(|_| Error::new(operation, format!("{text:?} holds a NUL byte")))
}

/// Points as the flat `f32`s the shim reads.
fn flat<const N: usize>(points: &[[f32; N]]) -> *const f32 {
    points.as_ptr().cast::<f32>()
}

/// An 8-bit grey image: `width * height` pixels, row-major, each row `width` bytes.
#[derive(Clone, Copy, Debug)]
pub struct Grey<'a> {
    pub pixels: &'a [u8],
    pub width: u32,
    pub height: u32,
}

impl Grey<'_> {
    /// The image's width and height as OpenCV's `int`s, after checking that the pixels are
    /// exactly `width * height` and the image not empty.
    fn checked(&self, operation: &'static str) -> Result<(c_int, c_int), Error> {
        let w = c_int::try_from(self.width).ok().filter(|&w| w > 0);
        let h = c_int::try_from(self.height).ok().filter(|&h| h > 0);
        let expected = (self.width as usize).checked_mul(self.height as usize);
        match (w, h, expected) {
            (Some(w), Some(h), Some(n)) if n == self.pixels.len() => Ok((w, h)),
            _ => Err(Error::new(
                operation,
                format!(
                    "a {}x{} grey image needs {} pixels, not {}",
                    self.width,
                    self.height,
                    expected.map_or_else(|| "more".to_owned(), |n| n.to_string()),
                    self.pixels.len()
                ),
            )),
        }
    }
}

/// When an iterative OpenCV algorithm stops (`cv::TermCriteria`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TermCriteria {
    /// [`TERM_COUNT`], [`TERM_EPS`] or both (`TERM_COUNT | TERM_EPS`).
    pub kind: i32,
    pub max_count: i32,
    pub epsilon: f64,
}

/// A pose as OpenCV gives it: a rotation vector (axis times angle, radians) and a translation,
/// `p_camera = R(rvec) p_object + tvec`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub rvec: [f64; 3],
    pub tvec: [f64; 3],
}

/// `cv::findChessboardCorners`: the `cols` x `rows` inner corners of a chessboard, in OpenCV's
/// detection order (rows of `cols` corners), `(x, y)` in pixels; `None` unless OpenCV found the
/// board with all its corners. `flags` are the `CALIB_CB_*` constants.
///
/// # Errors
/// Pixels that are not `width * height`, a pattern size beyond `int`, or OpenCV failing (not:
/// no board found).
pub fn find_chessboard_corners(
    image: Grey<'_>,
    cols: u32,
    rows: u32,
    flags: i32,
) -> Result<Option<Vec<[f32; 2]>>, Error> {
    const OP: &str = "findChessboardCorners";
    let (width, height) = image.checked(OP)?;
    let c = c_count(OP, "a pattern of columns", cols as usize)?;
    let r = c_count(OP, "a pattern of rows", rows as usize)?;
    let capacity = (cols as usize)
        .checked_mul(rows as usize)
        .ok_or_else(|| Error::new(OP, "the pattern has too many corners"))?;
    let mut corners = vec![[0.0f32; 2]; capacity];
    let mut count = 0usize;
    let mut found: c_int = 0;
    check(OP, |err, err_len| {
        // SAFETY: `image.pixels` holds `width * height` bytes (checked above) and is only read;
        // `corners` has room for `capacity` points of two floats, and the shim writes at most
        // that many; `count`, `found` and `err` (`err_len` bytes) are live for the call.
        unsafe {
            ffi::ocb_find_chessboard_corners(
                image.pixels.as_ptr(),
                width,
                height,
                c,
                r,
                flags,
                corners.as_mut_ptr().cast::<f32>(),
                capacity,
                &mut count,
                &mut found,
                err,
                err_len,
            )
        }
    })?;
    Ok((found != 0 && count == capacity).then_some(corners))
}

/// `cv::cornerSubPix`: refines `corners` in place, searching a window of
/// `(2 * window.0 + 1) x (2 * window.1 + 1)` pixels, with `zero_zone` (`(-1, -1)` for none)
/// left out of it.
///
/// # Errors
/// Pixels that are not `width * height`, or OpenCV failing.
pub fn corner_sub_pix(
    image: Grey<'_>,
    corners: &mut [[f32; 2]],
    window: (i32, i32),
    zero_zone: (i32, i32),
    criteria: TermCriteria,
) -> Result<(), Error> {
    const OP: &str = "cornerSubPix";
    let (width, height) = image.checked(OP)?;
    let count = corners.len();
    check(OP, |err, err_len| {
        // SAFETY: `image.pixels` holds `width * height` bytes (checked above) and is only read;
        // `corners` holds `count` points of two floats, read and rewritten in place; `err` is a
        // live buffer of `err_len` bytes.
        unsafe {
            ffi::ocb_corner_sub_pix(
                image.pixels.as_ptr(),
                width,
                height,
                corners.as_mut_ptr().cast::<f32>(),
                count,
                window.0,
                window.1,
                zero_zone.0,
                zero_zone.1,
                criteria.kind,
                criteria.max_count,
                criteria.epsilon,
                err,
                err_len,
            )
        }
    })
}

/// What [`calibrate_camera`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraCalibration {
    /// `[fx 0 cx; 0 fy cy; 0 0 1]`, row-major.
    pub camera_matrix: [f64; 9],
    /// The distortion coefficients, `[k1, k2, p1, p2, k3, ...]` (5 without the rational, thin
    /// prism or tilted models).
    pub distortion: Vec<f64>,
    /// Each view's board pose.
    pub rvecs: Vec<[f64; 3]>,
    pub tvecs: Vec<[f64; 3]>,
    /// Standard deviations of the intrinsics (`fx, fy, cx, cy, k1, k2, p1, p2, k3, ...`).
    pub std_deviations_intrinsics: Vec<f64>,
    /// Standard deviations of each view's pose (`rvec` then `tvec`, view after view).
    pub std_deviations_extrinsics: Vec<f64>,
    /// RMS reprojection error of each view, pixels.
    pub per_view_errors: Vec<f64>,
    /// RMS reprojection error over every point of every view, pixels.
    pub rms: f64,
}

/// A buffer of doubles for the shim to fill: `raw` points into `values`' heap buffer.
struct Out {
    values: Vec<f64>,
    raw: ffi::OcbDoubles,
}

impl Out {
    fn new(capacity: usize) -> Self {
        let mut values = vec![0.0; capacity];
        let raw = ffi::OcbDoubles {
            data: values.as_mut_ptr(),
            capacity,
            len: 0,
        };
        Self { values, raw }
    }

    /// The values the shim wrote (it never reports more than the capacity).
    fn take(self) -> Vec<f64> {
        let mut values = self.values;
        values.truncate(self.raw.len);
        values
    }
}

fn triples(values: &[f64]) -> Vec<[f64; 3]> {
    values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// `cv::calibrateCamera` with standard deviations and per-view errors (the Python binding's
/// `calibrateCameraExtended`): one camera's intrinsics from views of a planar pattern, each
/// view's object points (board frame) beside its image points (pixels). `flags` are the
/// `CALIB_*` constants; the camera matrix and distortion start from nothing (no
/// `CALIB_USE_INTRINSIC_GUESS`).
///
/// # Errors
/// As many object views as image views, and as many points in each, or the error says so;
/// OpenCV failing (too few points, a degenerate configuration).
pub fn calibrate_camera(
    object_points: &[Vec<[f32; 3]>],
    image_points: &[Vec<[f32; 2]>],
    image_size: (u32, u32),
    flags: i32,
    criteria: TermCriteria,
) -> Result<CameraCalibration, Error> {
    const OP: &str = "calibrateCamera";
    if object_points.len() != image_points.len() {
        return Err(Error::new(
            OP,
            format!(
                "{} views of object points but {} of image points",
                object_points.len(),
                image_points.len()
            ),
        ));
    }
    let counts: Vec<usize> = object_points.iter().map(Vec::len).collect();
    if let Some(k) = (0..counts.len()).find(|&k| image_points[k].len() != counts[k]) {
        return Err(Error::new(
            OP,
            format!(
                "view {k} has {} object points but {} image points",
                counts[k],
                image_points[k].len()
            ),
        ));
    }
    let width = c_count(OP, "an image width", image_size.0 as usize)?;
    let height = c_count(OP, "an image height", image_size.1 as usize)?;
    let object: Vec<[f32; 3]> = object_points.iter().flatten().copied().collect();
    let image: Vec<[f32; 2]> = image_points.iter().flatten().copied().collect();
    let views = counts.len();
    let mut k = Out::new(9);
    let mut d = Out::new(14);
    let mut r = Out::new(3 * views);
    let mut t = Out::new(3 * views);
    let mut std_in = Out::new(32);
    let mut std_ex = Out::new(6 * views);
    let mut per_view = Out::new(views);
    let mut rms = 0.0;
    check(OP, |err, err_len| {
        // SAFETY: `object` and `image` hold `sum(counts)` points each (3 and 2 floats), and
        // `counts` `views` sizes, all only read; each `Out` points at its own live buffer of
        // `capacity` doubles, which the shim fills no further than that; `rms` and `err`
        // (`err_len` bytes) are live for the call.
        unsafe {
            ffi::ocb_calibrate_camera(
                flat(&object),
                flat(&image),
                counts.as_ptr(),
                views,
                width,
                height,
                flags,
                criteria.kind,
                criteria.max_count,
                criteria.epsilon,
                &mut k.raw,
                &mut d.raw,
                &mut r.raw,
                &mut t.raw,
                &mut std_in.raw,
                &mut std_ex.raw,
                &mut per_view.raw,
                &mut rms,
                err,
                err_len,
            )
        }
    })?;
    let k = k.take();
    let camera_matrix: [f64; 9] = k
        .as_slice()
        .try_into()
        .map_err(|_| Error::new(OP, format!("the camera matrix has {} values, not 9", k.len())))?;
    Ok(CameraCalibration {
        camera_matrix,
        distortion: d.take(),
        rvecs: triples(&r.take()),
        tvecs: triples(&t.take()),
        std_deviations_intrinsics: std_in.take(),
        std_deviations_extrinsics: std_ex.take(),
        per_view_errors: per_view.take(),
        rms,
    })
}

/// Checks that PnP's object and image points pair up.
fn check_pairs(operation: &'static str, object: &[[f32; 3]], image: &[[f32; 2]]) -> Result<(), Error> {
    if object.len() != image.len() {
        return Err(Error::new(
            operation,
            format!("{} object points but {} image points", object.len(), image.len()),
        ));
    }
    Ok(())
}

/// `cv::solvePnP`: the pose of an object from its points (object frame) and their images
/// (pixels), through the row-major camera matrix and the distortion coefficients; from `guess`
/// when given (`useExtrinsicGuess`). `flags` is a `SOLVEPNP_*` method. `None` when OpenCV
/// finds no pose.
///
/// # Errors
/// Object and image points that do not pair up, or OpenCV failing (too few points).
pub fn solve_pnp(
    object: &[[f32; 3]],
    image: &[[f32; 2]],
    camera_matrix: &[f64; 9],
    distortion: &[f64],
    guess: Option<Pose>,
    flags: i32,
) -> Result<Option<Pose>, Error> {
    const OP: &str = "solvePnP";
    check_pairs(OP, object, image)?;
    let mut pose = guess.unwrap_or(Pose {
        rvec: [0.0; 3],
        tvec: [0.0; 3],
    });
    let mut solved: c_int = 0;
    check(OP, |err, err_len| {
        // SAFETY: `object` and `image` hold `object.len()` points each, the camera matrix 9
        // doubles and `distortion` its length, all only read; `pose`'s two 3-vectors are read
        // (with a guess) and written; `solved` and `err` (`err_len` bytes) are live.
        unsafe {
            ffi::ocb_solve_pnp(
                flat(object),
                flat(image),
                object.len(),
                camera_matrix.as_ptr(),
                distortion.as_ptr(),
                distortion.len(),
                c_int::from(guess.is_some()),
                flags,
                pose.rvec.as_mut_ptr(),
                pose.tvec.as_mut_ptr(),
                &mut solved,
                err,
                err_len,
            )
        }
    })?;
    Ok((solved != 0).then_some(pose))
}

/// `cv::solvePnPRefineLM`: `pose` refined by Levenberg-Marquardt on the reprojection error.
///
/// # Errors
/// Object and image points that do not pair up, or OpenCV failing.
pub fn solve_pnp_refine_lm(
    object: &[[f32; 3]],
    image: &[[f32; 2]],
    camera_matrix: &[f64; 9],
    distortion: &[f64],
    pose: Pose,
    criteria: TermCriteria,
) -> Result<Pose, Error> {
    const OP: &str = "solvePnPRefineLM";
    check_pairs(OP, object, image)?;
    let mut pose = pose;
    check(OP, |err, err_len| {
        // SAFETY: `object` and `image` hold `object.len()` points each, the camera matrix 9
        // doubles and `distortion` its length, all only read; `pose`'s two 3-vectors are read
        // and rewritten; `err` is a live buffer of `err_len` bytes.
        unsafe {
            ffi::ocb_solve_pnp_refine_lm(
                flat(object),
                flat(image),
                object.len(),
                camera_matrix.as_ptr(),
                distortion.as_ptr(),
                distortion.len(),
                pose.rvec.as_mut_ptr(),
                pose.tvec.as_mut_ptr(),
                criteria.kind,
                criteria.max_count,
                criteria.epsilon,
                err,
                err_len,
            )
        }
    })?;
    Ok(pose)
}

/// A circle for [`draw_frame_axes`] to draw as well (`cv::circle`, anti-aliased).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Circle {
    /// Its centre, whole pixels.
    pub centre: [i32; 2],
    pub radius: i32,
    /// Blue, green, red, 0-255.
    pub colour_bgr: [f64; 3],
    pub thickness: i32,
}

/// The grey image in colour (`cv::cvtColor`, `COLOR_GRAY2BGR`) with `cv::drawFrameAxes` of
/// `pose` (axes `length` long in the object's units, x red, y green, z blue, `thickness` pixels)
/// and then `circle`, if any: the BGR pixels, row-major, 3 bytes a pixel.
///
/// # Errors
/// Pixels that are not `width * height`, or OpenCV failing.
pub fn draw_frame_axes(
    image: Grey<'_>,
    camera_matrix: &[f64; 9],
    distortion: &[f64],
    pose: &Pose,
    length: f32,
    thickness: i32,
    circle: Option<&Circle>,
) -> Result<Vec<u8>, Error> {
    const OP: &str = "drawFrameAxes";
    let (width, height) = image.checked(OP)?;
    let mut bgr = vec![0u8; image.pixels.len() * 3];
    let circle = circle.map(|c| ffi::OcbCircle {
        x: c.centre[0],
        y: c.centre[1],
        radius: c.radius,
        blue: c.colour_bgr[0],
        green: c.colour_bgr[1],
        red: c.colour_bgr[2],
        thickness: c.thickness,
    });
    let circle_ptr = circle.as_ref().map_or(std::ptr::null(), std::ptr::from_ref);
    check(OP, |err, err_len| {
        // SAFETY: `image.pixels` holds `width * height` bytes (checked above), the camera
        // matrix 9 doubles, `distortion` its length, the pose two 3-vectors and `circle_ptr`
        // null or a live circle, all only read; `bgr` holds `width * height * 3` bytes, which
        // the shim fills exactly; `err` is a live buffer of `err_len` bytes.
        unsafe {
            ffi::ocb_draw_frame_axes(
                image.pixels.as_ptr(),
                width,
                height,
                camera_matrix.as_ptr(),
                distortion.as_ptr(),
                distortion.len(),
                pose.rvec.as_ptr(),
                pose.tvec.as_ptr(),
                length,
                thickness,
                circle_ptr,
                bgr.as_mut_ptr(),
                bgr.len(),
                err,
                err_len,
            )
        }
    })?;
    Ok(bgr)
}

/// A FileStorage YAML document composed in memory (`WRITE | MEMORY | FORMAT_YAML`): values
/// written in order at the top level or in the map last begun, then [`StorageWriter::finish`]
/// for its text.
pub struct StorageWriter {
    raw: NonNull<ffi::OcbWriter>,
    /// Maps begun and not ended: OpenCV 4.6 corrupts its memory when told to end one more
    /// (`endWriteStruct` checks nothing), so that is refused here.
    open_maps: usize,
}

impl fmt::Debug for StorageWriter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StorageWriter")
            .field("open_maps", &self.open_maps)
            .finish_non_exhaustive()
    }
}

impl Drop for StorageWriter {
    fn drop(&mut self) {
        // SAFETY: `raw` came from `ocb_writer_new`, is freed only here, and nothing uses it after.
        unsafe { ffi::ocb_writer_free(self.raw.as_ptr()) }
    }
}

impl StorageWriter {
    /// An empty YAML document.
    ///
    /// # Errors
    /// OpenCV's, if it cannot open one.
    pub fn new() -> Result<Self, Error> {
        const OP: &str = "FileStorage::open";
        let mut raw: *mut ffi::OcbWriter = std::ptr::null_mut();
        check(OP, |err, err_len| {
            // SAFETY: `raw` and `err` (`err_len` bytes) are live; the shim writes a new writer's
            // address into `raw` on success.
            unsafe { ffi::ocb_writer_new(&mut raw, err, err_len) }
        })?;
        let raw = NonNull::new(raw).ok_or_else(|| Error::new(OP, "no writer was made"))?;
        Ok(Self { raw, open_maps: 0 })
    }

    /// One write of the shim, with the value's name as C text.
    fn write(
        &mut self,
        operation: &'static str,
        name: &str,
        call: impl FnOnce(*mut ffi::OcbWriter, *const c_char, *mut c_char, usize) -> c_int,
    ) -> Result<(), Error> {
        let name = c_text(operation, name)?;
        let raw = self.raw.as_ptr();
        check(operation, |err, err_len| call(raw, name.as_ptr(), err, err_len))
    }

    /// `name: value`, an integer.
    ///
    /// # Errors
    /// A name OpenCV refuses (or holding NUL).
    pub fn int(&mut self, name: &str, value: i32) -> Result<(), Error> {
        self.write("FileStorage::write", name, |w, name, err, err_len| {
            // SAFETY: `w` is this live writer, `name` a NUL-terminated string and `err` a live
            // buffer of `err_len` bytes, all for the duration of the call.
            unsafe { ffi::ocb_writer_int(w, name, value, err, err_len) }
        })
    }

    /// `name: value`, a real.
    ///
    /// # Errors
    /// A name OpenCV refuses (or holding NUL).
    pub fn real(&mut self, name: &str, value: f64) -> Result<(), Error> {
        self.write("FileStorage::write", name, |w, name, err, err_len| {
            // SAFETY: as in `int`: a live writer, a NUL-terminated name, a live message buffer.
            unsafe { ffi::ocb_writer_real(w, name, value, err, err_len) }
        })
    }

    /// `name: "value"`, a string.
    ///
    /// # Errors
    /// A name OpenCV refuses, or a name or value holding NUL.
    pub fn text(&mut self, name: &str, value: &str) -> Result<(), Error> {
        const OP: &str = "FileStorage::write";
        let value = c_text(OP, value)?;
        self.write(OP, name, |w, name, err, err_len| {
            // SAFETY: a live writer, NUL-terminated name and value that outlive the call, and
            // a live message buffer of `err_len` bytes.
            unsafe { ffi::ocb_writer_text(w, name, value.as_ptr(), err, err_len) }
        })
    }

    /// `name:` then a sequence of strings.
    ///
    /// # Errors
    /// A name OpenCV refuses, or a name or value holding NUL.
    pub fn texts<S: AsRef<str>>(&mut self, name: &str, values: &[S]) -> Result<(), Error> {
        const OP: &str = "FileStorage::write";
        let owned = values
            .iter()
            .map(|v| c_text(OP, v.as_ref()))
            .collect::<Result<Vec<_>, _>>()?;
        let pointers: Vec<*const c_char> = owned.iter().map(|v| v.as_ptr()).collect();
        self.write(OP, name, |w, name, err, err_len| {
            // SAFETY: a live writer and name; `pointers` holds `pointers.len()` pointers to
            // NUL-terminated strings kept alive by `owned`, all only read; a live message buffer.
            unsafe { ffi::ocb_writer_texts(w, name, pointers.as_ptr(), pointers.len(), err, err_len) }
        })
    }

    /// `name:` a `rows` x `cols` matrix of doubles (`!!opencv-matrix`) from row-major `data`.
    ///
    /// # Errors
    /// `data` not `rows * cols` values (or none), or a name OpenCV refuses.
    pub fn matrix(&mut self, name: &str, rows: usize, cols: usize, data: &[f64]) -> Result<(), Error> {
        const OP: &str = "FileStorage::write";
        if rows == 0 || cols == 0 || rows.checked_mul(cols) != Some(data.len()) {
            return Err(Error::new(
                OP,
                format!("a {rows}x{cols} matrix cannot hold {} values", data.len()),
            ));
        }
        let r = c_count(OP, "a matrix of rows", rows)?;
        let c = c_count(OP, "a matrix of columns", cols)?;
        self.write(OP, name, |w, name, err, err_len| {
            // SAFETY: a live writer and name; `data` holds `rows * cols` doubles (checked
            // above), only read; a live message buffer.
            unsafe { ffi::ocb_writer_matrix(w, name, r, c, data.as_ptr(), err, err_len) }
        })
    }

    /// `name:` then a map, which takes the values written until [`StorageWriter::end_map`].
    ///
    /// # Errors
    /// A name OpenCV refuses (or holding NUL).
    pub fn begin_map(&mut self, name: &str) -> Result<(), Error> {
        self.write("FileStorage::startWriteStruct", name, |w, name, err, err_len| {
            // SAFETY: a live writer, a NUL-terminated name, a live message buffer.
            unsafe { ffi::ocb_writer_begin_map(w, name, err, err_len) }
        })?;
        // OpenCV pushes the map only once it is begun: a failure leaves none open.
        self.open_maps += 1;
        Ok(())
    }

    /// Ends the map last begun.
    ///
    /// # Errors
    /// No map is open (refused before OpenCV, which would corrupt its memory), or OpenCV's.
    pub fn end_map(&mut self) -> Result<(), Error> {
        const OP: &str = "FileStorage::endWriteStruct";
        if self.open_maps == 0 {
            return Err(Error::new(OP, "no map is open"));
        }
        let raw = self.raw.as_ptr();
        check(OP, |err, err_len| {
            // SAFETY: a live writer with a map open (counted above), and a live message
            // buffer of `err_len` bytes.
            unsafe { ffi::ocb_writer_end_map(raw, err, err_len) }
        })?;
        self.open_maps -= 1;
        Ok(())
    }

    /// Ends the document and gives its text (`%YAML:1.0` first).
    ///
    /// # Errors
    /// OpenCV's, when the document cannot be closed (a map left open).
    pub fn finish(self) -> Result<String, Error> {
        const OP: &str = "FileStorage::releaseAndGetString";
        let mut text: *const c_char = std::ptr::null();
        let mut len = 0usize;
        let raw = self.raw.as_ptr();
        check(OP, |err, err_len| {
            // SAFETY: a live writer; `text`, `len` and `err` (`err_len` bytes) are live. The
            // shim points `text` at `len` bytes the writer owns until it is freed (on drop,
            // after the copy below).
            unsafe { ffi::ocb_writer_finish(raw, &mut text, &mut len, err, err_len) }
        })?;
        if text.is_null() {
            return Ok(String::new());
        }
        // SAFETY: `text` points at `len` initialised bytes owned by the writer, which `self`
        // keeps alive (it is dropped at the end of this function, after the copy).
        let bytes = unsafe { std::slice::from_raw_parts(text.cast::<u8>(), len) };
        Ok(String::from_utf8_lossy(bytes).into_owned())
    }
}

/// A FileStorage YAML document parsed from text (`READ | MEMORY | FORMAT_YAML`).
pub struct StorageReader {
    raw: NonNull<ffi::OcbReader>,
    opened: bool,
}

impl fmt::Debug for StorageReader {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StorageReader")
            .field("opened", &self.opened)
            .finish_non_exhaustive()
    }
}

impl Drop for StorageReader {
    fn drop(&mut self) {
        // SAFETY: `raw` came from `ocb_reader_open`, is freed only here, and no node of it
        // outlives it (each borrows the reader).
        unsafe { ffi::ocb_reader_free(self.raw.as_ptr()) }
    }
}

impl StorageReader {
    /// Parses `text`.
    ///
    /// # Errors
    /// Text holding NUL, or OpenCV's parser refusing it.
    pub fn from_yaml(text: &str) -> Result<Self, Error> {
        const OP: &str = "FileStorage::open";
        let text = c_text(OP, text)?;
        let mut raw: *mut ffi::OcbReader = std::ptr::null_mut();
        let mut opened: c_int = 0;
        check(OP, |err, err_len| {
            // SAFETY: `text` is NUL-terminated and only read (the shim keeps its own copy);
            // `raw`, `opened` and `err` (`err_len` bytes) are live; the shim writes a new
            // reader's address into `raw` on success.
            unsafe { ffi::ocb_reader_open(text.as_ptr(), &mut raw, &mut opened, err, err_len) }
        })?;
        let raw = NonNull::new(raw).ok_or_else(|| Error::new(OP, "no reader was made"))?;
        Ok(Self {
            raw,
            opened: opened != 0,
        })
    }

    /// Whether OpenCV holds a document (`FileStorage::isOpened`).
    pub fn is_opened(&self) -> bool {
        self.opened
    }

    /// The top-level node `name` (`FileStorage::operator[]`): a none node when there is none.
    ///
    /// # Errors
    /// A name holding NUL, or OpenCV failing.
    pub fn get(&self, name: &str) -> Result<StorageNode<'_>, Error> {
        const OP: &str = "FileStorage::operator[]";
        let name = c_text(OP, name)?;
        let reader = self.raw.as_ptr().cast_const();
        StorageNode::make(OP, |out, err, err_len| {
            // SAFETY: a live reader, a NUL-terminated name, `out` and `err` (`err_len` bytes)
            // live; the shim writes a new node's address into `out` on success.
            unsafe { ffi::ocb_reader_get(reader, name.as_ptr(), out, err, err_len) }
        })
    }
}

/// What a node is (`FileNode`'s checks).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NodeKind {
    pub is_none: bool,
    pub empty: bool,
    pub is_map: bool,
    pub is_seq: bool,
    pub is_int: bool,
    pub is_real: bool,
    pub is_string: bool,
    /// Items of a sequence or map (`FileNode::size`).
    pub size: usize,
}

/// A matrix node read as doubles (`FileNode::mat`, converted to `CV_64F`).
#[derive(Clone, Debug, PartialEq)]
pub struct Matrix {
    pub rows: i32,
    pub cols: i32,
    /// Row-major, `rows * cols` values.
    pub data: Vec<f64>,
}

/// A node of a [`StorageReader`]'s document, which it borrows.
pub struct StorageNode<'r> {
    raw: NonNull<ffi::OcbNode>,
    reader: PhantomData<&'r StorageReader>,
}

impl fmt::Debug for StorageNode<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StorageNode").finish_non_exhaustive()
    }
}

impl Drop for StorageNode<'_> {
    fn drop(&mut self) {
        // SAFETY: `raw` came from the shim's node functions, is freed only here, and its
        // reader is still alive (the node borrows it).
        unsafe { ffi::ocb_node_free(self.raw.as_ptr()) }
    }
}

impl<'r> StorageNode<'r> {
    /// A node from one of the shim's node-making calls.
    fn make(
        operation: &'static str,
        call: impl FnOnce(*mut *mut ffi::OcbNode, *mut c_char, usize) -> c_int,
    ) -> Result<Self, Error> {
        let mut raw: *mut ffi::OcbNode = std::ptr::null_mut();
        check(operation, |err, err_len| call(&mut raw, err, err_len))?;
        let raw = NonNull::new(raw).ok_or_else(|| Error::new(operation, "no node was made"))?;
        Ok(Self {
            raw,
            reader: PhantomData,
        })
    }

    fn ptr(&self) -> *const ffi::OcbNode {
        self.raw.as_ptr().cast_const()
    }

    /// What the node is.
    ///
    /// # Errors
    /// OpenCV failing.
    pub fn kind(&self) -> Result<NodeKind, Error> {
        let mut info = ffi::OcbNodeInfo::default();
        let node = self.ptr();
        check("FileNode::type", |err, err_len| {
            // SAFETY: a live node (its reader alive), `info` and `err` (`err_len` bytes) live.
            unsafe { ffi::ocb_node_info(node, &mut info, err, err_len) }
        })?;
        Ok(NodeKind {
            is_none: info.is_none != 0,
            empty: info.empty != 0,
            is_map: info.is_map != 0,
            is_seq: info.is_seq != 0,
            is_int: info.is_int != 0,
            is_real: info.is_real != 0,
            is_string: info.is_string != 0,
            size: info.size,
        })
    }

    /// The child `name` of this map (`FileNode::operator[]`): a none node when there is none.
    ///
    /// # Errors
    /// A name holding NUL, or OpenCV failing.
    pub fn get(&self, name: &str) -> Result<StorageNode<'r>, Error> {
        const OP: &str = "FileNode::operator[]";
        let name = c_text(OP, name)?;
        let node = self.ptr();
        Self::make(OP, |out, err, err_len| {
            // SAFETY: a live node, a NUL-terminated name, `out` and `err` (`err_len` bytes)
            // live; the shim writes a new node's address into `out` on success.
            unsafe { ffi::ocb_node_get(node, name.as_ptr(), out, err, err_len) }
        })
    }

    /// Item `index` of this sequence (`FileNode::operator[]`).
    ///
    /// # Errors
    /// OpenCV failing.
    pub fn at(&self, index: i32) -> Result<StorageNode<'r>, Error> {
        let node = self.ptr();
        Self::make("FileNode::operator[]", |out, err, err_len| {
            // SAFETY: a live node, `out` and `err` (`err_len` bytes) live; the shim writes a
            // new node's address into `out` on success.
            unsafe { ffi::ocb_node_at(node, index, out, err, err_len) }
        })
    }

    /// The node as an integer (`(int)node`).
    ///
    /// # Errors
    /// OpenCV failing.
    pub fn int(&self) -> Result<i32, Error> {
        let mut value: c_int = 0;
        let node = self.ptr();
        check("FileNode::operator int", |err, err_len| {
            // SAFETY: a live node, `value` and `err` (`err_len` bytes) live.
            unsafe { ffi::ocb_node_int(node, &mut value, err, err_len) }
        })?;
        Ok(value)
    }

    /// The node as a real (`(double)node`).
    ///
    /// # Errors
    /// OpenCV failing.
    pub fn real(&self) -> Result<f64, Error> {
        let mut value = 0.0;
        let node = self.ptr();
        check("FileNode::operator double", |err, err_len| {
            // SAFETY: a live node, `value` and `err` (`err_len` bytes) live.
            unsafe { ffi::ocb_node_real(node, &mut value, err, err_len) }
        })?;
        Ok(value)
    }

    /// The node as text (`(std::string)node`; not UTF-8 is replaced).
    ///
    /// # Errors
    /// OpenCV failing.
    pub fn string(&self) -> Result<String, Error> {
        const OP: &str = "FileNode::string";
        let node = self.ptr();
        let mut buf: Vec<u8> = vec![0; 256];
        loop {
            let mut len = 0usize;
            check(OP, |err, err_len| {
                // SAFETY: a live node; `buf` holds `buf.len()` bytes, which the shim writes
                // only when the text fits; `len` and `err` (`err_len` bytes) are live.
                unsafe {
                    ffi::ocb_node_string(
                        node,
                        buf.as_mut_ptr().cast::<c_char>(),
                        buf.len(),
                        &mut len,
                        err,
                        err_len,
                    )
                }
            })?;
            if len <= buf.len() {
                buf.truncate(len);
                return Ok(String::from_utf8_lossy(&buf).into_owned());
            }
            buf = vec![0; len];
        }
    }

    /// The node read as a matrix (`FileNode::mat`) of doubles; `None` when that is empty or has
    /// more than one channel.
    ///
    /// # Errors
    /// OpenCV failing (a malformed `!!opencv-matrix`).
    pub fn matrix(&self) -> Result<Option<Matrix>, Error> {
        const OP: &str = "FileNode::mat";
        let node = self.ptr();
        let mut data: Vec<f64> = vec![0.0; 16];
        loop {
            let (mut is_matrix, mut rows, mut cols, mut len): (c_int, c_int, c_int, usize) = (0, 0, 0, 0);
            check(OP, |err, err_len| {
                // SAFETY: a live node; `data` holds `data.len()` doubles, which the shim writes
                // only when the values fit; the other outputs and `err` (`err_len` bytes) are live.
                unsafe {
                    ffi::ocb_node_matrix(
                        node,
                        &mut is_matrix,
                        &mut rows,
                        &mut cols,
                        data.as_mut_ptr(),
                        data.len(),
                        &mut len,
                        err,
                        err_len,
                    )
                }
            })?;
            if is_matrix == 0 {
                return Ok(None);
            }
            if len <= data.len() {
                data.truncate(len);
                return Ok(Some(Matrix { rows, cols, data }));
            }
            data = vec![0.0; len];
        }
    }
}

#[cfg(test)]
mod tests;
