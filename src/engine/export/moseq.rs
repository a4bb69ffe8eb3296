//! The engine of `mousepose export moseq SESSION --out DIR`: a session in the layout MoSeq's acquisition
//! writes and moseq2-extract reads, which `replay` reads back too:
//!
//! ```text
//! DIR/
//!   depth.avi       depth frames, FFV1 16-bit grey (gray16le), millimetres, lossless
//!   depth_ts.txt    per depth frame: device time (ms), host time (ms)
//!   metadata.json   SubjectName, SessionName, StartTime, DepthResolution, ... (MoSeq's keys)
//!   mousepose.json  where the export came from: software version, session, cameras, counts
//!   color.avi       the colour camera's frames, FFV1, lossless (Bayer mosaics as recorded)
//!   color_ts.txt    per colour frame: device time (ms), host time (ms)
//!   rig.yaml        the session's calibration (for `replay DIR --calibration DIR/rig.yaml`)
//! ```

use crate::core::frame::PixelFormat;
use crate::engine::export::Run;
use crate::engine::progress::Progress;
use crate::engine::{Failure, output_failure};
use crate::io::output::Staging;
use crate::io::session::{CameraMeta, CameraRole, SessionReader};
use crate::io::video::{Encoder, EncoderSpec};
use crate::runtime::recording::moseq::{DEPTH_AVI, DEPTH_TS, METADATA};
use crate::vision::calibrate::RigCalibration;
use anyhow::Context as _;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The colour camera's video.
pub const COLOR_AVI: &str = "color.avi";
/// The colour camera's timestamps.
pub const COLOR_TS: &str = "color_ts.txt";
/// The session's calibration.
pub const RIG_FILE: &str = "rig.yaml";
/// Where the export came from. Not in `metadata.json`: moseq2-extract stores each of that
/// file's values as an HDF5 dataset and fails on a nested object.
pub const PROVENANCE_FILE: &str = "mousepose.json";

/// What `export moseq` exports, and where (see its `--help`).
#[derive(Clone, Debug)]
pub struct MoseqOptions {
    /// The session (or a run whose summary names it).
    pub session: PathBuf,
    /// The directory to write.
    pub out: PathBuf,
    /// `SubjectName` in metadata.json (default: "unknown").
    pub subject: Option<String>,
    /// `SessionName` in metadata.json (default: the session directory's name).
    pub session_name: Option<String>,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

/// `metadata.json`: the keys MoSeq's acquisition writes (moseq2-extract reads the resolution,
/// byte order and data type, names its results after the subject and session, and copies
/// every value into its results, so each must be a string, a number or a flat list).
#[derive(Debug, Serialize)]
#[serde(rename_all = "PascalCase")]
struct Metadata {
    subject_name: String,
    session_name: String,
    start_time: String,
    depth_resolution: [u32; 2],
    depth_data_type: &'static str,
    is_little_endian: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    color_resolution: Option<[u32; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    color_data_type: Option<&'static str>,
    nidaq_channels: u32,
    nidaq_sampling_rate: f64,
}

/// Where the export came from.
#[derive(Debug, Serialize)]
struct Provenance {
    software_version: &'static str,
    session: PathBuf,
    depth_camera: CameraMeta,
    #[serde(skip_serializing_if = "Option::is_none")]
    color_camera: Option<CameraMeta>,
    /// The pixel layout stored in `color.avi` (a Bayer mosaic is stored as recorded, as grey).
    #[serde(skip_serializing_if = "Option::is_none")]
    color_pixel_format: Option<&'static str>,
    depth_frames: u64,
    color_frames: u64,
    /// The depth camera's intrinsics and how moseq2-extract's millimetres differ from them.
    #[serde(skip_serializing_if = "Option::is_none")]
    millimetres: Option<MoseqMillimetres>,
}

/// moseq2-extract turns pixels into millimetres as if every depth camera were a Kinect v2 at
/// 512 x 424 (`convert_pxs_to_mm` with its defaults: a focal length of
/// `512 / (2 · 35.3°)` by `424 / (2 · 30°)` pixels, angles in radians, and the principal point
/// at (256, 212)); its `*_mm` scalars of another camera are off by the ratio of the two focal
/// lengths, and nothing in its config or `metadata.json` changes that.
pub const MOSEQ_FOCAL_PX: (f64, f64) = (
    512.0 / (2.0 * 35.3 * std::f64::consts::PI / 180.0),
    424.0 / (2.0 * std::f64::consts::FRAC_PI_6),
);

/// What a MoSeq export knows of the depth camera's millimetres.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MoseqMillimetres {
    /// Where the intrinsics come from: `rig calibration` or a camera of the table, nominal.
    pub intrinsics_from: String,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Multiply moseq2-extract's millimetres along the image's x (y) by this to get true
    /// millimetres: its focal length over the camera's.
    pub scale_x: f64,
    pub scale_y: f64,
}

impl MoseqMillimetres {
    pub fn new(intrinsics: &crate::core::geometry::Intrinsics, from: String) -> Self {
        Self {
            intrinsics_from: from,
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            scale_x: MOSEQ_FOCAL_PX.0 / intrinsics.fx,
            scale_y: MOSEQ_FOCAL_PX.1 / intrinsics.fy,
        }
    }

    /// The warning to print when moseq2-extract's millimetres are more than 2 % off.
    pub fn warning(&self) -> Option<String> {
        let off = |s: f64| (s - 1.0).abs() > 0.02;
        (off(self.scale_x) || off(self.scale_y)).then(|| {
            format!(
                "moseq2-extract's millimetre scalars (centroid_*_mm, velocity_*_mm, length_mm, width_mm, area_mm) assume a Kinect v2's field of view: for this camera (fx {:.1}, fy {:.1} px, {}) they come out {:.2} x (along x) and {:.2} x (along y) the true values; multiply them by {:.4} and {:.4} (both are in {PROVENANCE_FILE}), or use the *_px scalars with these intrinsics",
                self.fx,
                self.fy,
                self.intrinsics_from,
                1.0 / self.scale_x,
                1.0 / self.scale_y,
                self.scale_x,
                self.scale_y
            )
        })
    }
}

/// What an export wrote.
#[derive(Clone, Debug, Serialize)]
pub struct MoseqExport {
    pub out: PathBuf,
    pub depth_frames: u64,
    pub color_frames: u64,
    /// Frames of the session that could not be read (damaged records), left out.
    pub skipped_frames: u64,
    /// How moseq2-extract's millimetres differ from this camera's (`None` when the depth
    /// camera's intrinsics are unknown).
    pub millimetres: Option<MoseqMillimetres>,
}

/// A stamp in milliseconds, exact to the nanosecond.
fn ms(ns: u64) -> String {
    format!("{}.{:06}", ns / 1_000_000, ns % 1_000_000)
}

/// ffmpeg's name and the bytes per pixel of a colour format as stored (Bayer mosaics as grey).
fn color_pix_fmt(format: PixelFormat) -> (&'static str, usize) {
    match format {
        PixelFormat::Rgb8 => ("rgb24", 3),
        _ => ("gray", 1),
    }
}

/// Writes the session at `session` into `out` in MoSeq's layout (see the module
/// documentation); `progress` is called with the frames done and the total.
///
/// # Errors
/// The session cannot be read, ffmpeg fails, or `out` cannot be written (nothing is left at
/// `out` then).
pub fn export_moseq(
    session: &Path,
    out: &Path,
    subject: Option<&str>,
    session_name: Option<&str>,
    force: bool,
    mut progress: impl FnMut(u64, u64),
) -> Result<MoseqExport, Failure> {
    let reader = SessionReader::open(session)
        .map_err(|e| Failure::usage(e).context(format!("opening the session {session:?}")))?;
    let meta = reader.meta().clone();
    let depth_meta = meta
        .camera(CameraRole::Depth)
        .cloned()
        .ok_or_else(|| Failure::usage(anyhow::anyhow!("the session {session:?} has no depth camera")))?;
    let color_meta = meta.camera(CameraRole::Color).cloned();
    let staging = Staging::new(out, force).map_err(output_failure)?;
    let dir = staging.path().to_owned();
    let mut count = Count {
        done: 0,
        total: (reader.depth_count() + reader.color_count()) as u64,
        skipped: 0,
        progress: &mut progress,
    };
    let fps = if depth_meta.fps > 0.0 { depth_meta.fps } else { 30.0 };
    let depth_frames = write_depth(&reader, &depth_meta, fps, &dir, &mut count)?;
    if depth_frames == 0 {
        return Err(Failure::usage(anyhow::anyhow!(
            "the session {session:?} has no readable depth frame"
        )));
    }
    let (color_frames, color_pixel_format) = match &color_meta {
        Some(color_meta) => write_color(&reader, color_meta, fps, &dir, &mut count)?,
        None => (0, None),
    };
    let skipped = count.skipped;

    let session_name = session_name.map(str::to_owned).unwrap_or_else(|| {
        session
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "session".to_owned())
    });
    let metadata = Metadata {
        subject_name: subject.unwrap_or("unknown").to_owned(),
        session_name,
        start_time: meta.created.clone(),
        depth_resolution: [depth_meta.width, depth_meta.height],
        depth_data_type: "UInt16[]",
        is_little_endian: true,
        color_resolution: color_meta
            .as_ref()
            .filter(|_| color_frames > 0)
            .map(|c| [c.width, c.height]),
        color_data_type: (color_frames > 0).then_some("Byte[]"),
        nidaq_channels: 0,
        nidaq_sampling_rate: 0.0,
    };
    let millimetres = millimetres_of(meta.rig.as_ref(), &depth_meta);
    let provenance = Provenance {
        software_version: env!("CARGO_PKG_VERSION"),
        session: std::fs::canonicalize(session).unwrap_or_else(|_| session.to_owned()),
        depth_camera: depth_meta,
        color_camera: color_meta,
        color_pixel_format,
        depth_frames,
        color_frames,
        millimetres: millimetres.clone(),
    };
    crate::engine::write_report_file(&dir, METADATA, &serde_json::to_vec_pretty(&metadata)?)?;
    crate::engine::write_report_file(&dir, PROVENANCE_FILE, &serde_json::to_vec_pretty(&provenance)?)?;
    if let Some(rig) = &meta.rig {
        RigCalibration::from_rig(rig)
            .save(&dir.join(RIG_FILE))
            .context("writing the session's calibration")?;
    }
    staging.commit().map_err(output_failure)?;
    Ok(MoseqExport {
        out: out.to_owned(),
        depth_frames,
        color_frames,
        skipped_frames: skipped,
        millimetres,
    })
}

/// The frames an export has gone through of all the session's, and those it left out;
/// `progress` is told of each frame.
struct Count<'a> {
    done: u64,
    total: u64,
    skipped: u64,
    progress: &'a mut dyn FnMut(u64, u64),
}

impl Count<'_> {
    /// One more frame gone through.
    fn next(&mut self) {
        self.done += 1;
        (self.progress)(self.done, self.total);
    }
}

/// Writes the depth frames into `dir` as MoSeq's acquisition does (16-bit grey FFV1, and their
/// timestamps) and returns how many; damaged frames and frames of another size are left out.
/// With no frame written, nothing is finished.
fn write_depth(
    reader: &SessionReader,
    depth_meta: &CameraMeta,
    fps: f64,
    dir: &Path,
    count: &mut Count<'_>,
) -> Result<u64, Failure> {
    let mut depth = Encoder::start(
        EncoderSpec::ffv1(depth_meta.width, depth_meta.height, "gray16le", 2, fps),
        &dir.join(DEPTH_AVI),
    )?;
    let mut depth_ts = String::new();
    let mut bytes = Vec::new();
    for frame in reader.depth_frames() {
        count.next();
        let frame = match frame {
            Ok(f) => f,
            Err(e) => {
                tracing::warn!(message = "Damaged depth frame left out.", error = %e);
                count.skipped += 1;
                continue;
            }
        };
        if (frame.width, frame.height) != (depth_meta.width, depth_meta.height) {
            tracing::warn!(
                message = "Depth frame of another size than the camera's left out.",
                seq = frame.stamp.seq
            );
            count.skipped += 1;
            continue;
        }
        bytes.clear();
        bytes.extend(frame.data.iter().flat_map(|d| d.to_le_bytes()));
        depth.write(&bytes)?;
        let _ = writeln!(depth_ts, "{} {}", ms(frame.stamp.device_ns), ms(frame.stamp.host_ns));
    }
    let depth_frames = depth.frames();
    if depth_frames == 0 {
        return Ok(0);
    }
    depth.finish()?;
    crate::engine::write_report_file(dir, DEPTH_TS, depth_ts.as_bytes())?;
    Ok(depth_frames)
}

/// Writes the colour frames into `dir` as a lossless video of their own, in the camera's
/// layout (the first frame's), with their timestamps; returns how many, and the layout.
fn write_color(
    reader: &SessionReader,
    color_meta: &CameraMeta,
    fps: f64,
    dir: &Path,
    count: &mut Count<'_>,
) -> Result<(u64, Option<&'static str>), Failure> {
    let Some(frames) = reader.color_frames() else {
        return Ok((0, None));
    };
    let mut color_pixel_format = None;
    let mut encoder: Option<(Encoder, PixelFormat, u32, u32)> = None;
    let mut color_ts = String::new();
    for frame in frames {
        count.next();
        let frame = match frame {
            Ok(f) => f,
            Err(e) => {
                tracing::warn!(message = "Damaged colour frame left out.", error = %e);
                count.skipped += 1;
                continue;
            }
        };
        let (enc, format, width, height) = match &mut encoder {
            Some(e) => e,
            None => {
                let (pix_fmt, bpp) = color_pix_fmt(frame.format);
                let spec = EncoderSpec::ffv1(
                    frame.width,
                    frame.height,
                    pix_fmt,
                    bpp,
                    if color_meta.fps > 0.0 { color_meta.fps } else { fps },
                );
                color_pixel_format = Some(frame.format.name());
                let enc = Encoder::start(spec, &dir.join(COLOR_AVI))?;
                encoder.insert((enc, frame.format, frame.width, frame.height))
            }
        };
        if frame.format != *format || (frame.width, frame.height) != (*width, *height) {
            tracing::warn!(
                message = "Colour frame of another size or format left out.",
                seq = frame.stamp.seq
            );
            count.skipped += 1;
            continue;
        }
        enc.write(&frame.data)?;
        let _ = writeln!(color_ts, "{} {}", ms(frame.stamp.device_ns), ms(frame.stamp.host_ns));
    }
    let mut color_frames = 0;
    if let Some((enc, ..)) = encoder {
        color_frames = enc.frames();
        enc.finish()?;
        crate::engine::write_report_file(dir, COLOR_TS, color_ts.as_bytes())?;
    }
    Ok((color_frames, color_pixel_format))
}

/// The depth camera's intrinsics (the session's calibration, else the camera table's) and
/// how moseq2-extract's millimetres differ from them; `None` when they are unknown.
fn millimetres_of(rig: Option<&crate::core::geometry::Rig>, depth_meta: &CameraMeta) -> Option<MoseqMillimetres> {
    match rig {
        Some(rig) => Some(MoseqMillimetres::new(
            &rig.depth.intrinsics,
            "rig calibration".to_owned(),
        )),
        None => {
            crate::core::cameras::depth_camera(Some(depth_meta.model.as_str()), depth_meta.width, depth_meta.height)
                .ok()
                .map(|m| MoseqMillimetres::new(&m.intrinsics(), format!("{}, nominal", m.label())))
        }
    }
}

/// `mousepose export moseq`: finds the session of `options.session` and exports it, telling
/// `progress` the frames done, then warns there when moseq2-extract's millimetres will be off
/// (or may be: a camera of unknown intrinsics).
///
/// # Errors
/// See [`export_moseq`]; a directory that is neither a session nor a run (the user's).
pub fn moseq(options: &MoseqOptions, progress: &dyn Progress) -> Result<MoseqExport, Failure> {
    let run = Run::open(&options.session, None).map_err(Failure::usage)?;
    progress.start("moseq", 0);
    let result = export_moseq(
        &run.session,
        &options.out,
        options.subject.as_deref(),
        options.session_name.as_deref(),
        options.force,
        |done, total| {
            progress.set_total(total);
            progress.set_done(done);
        },
    );
    progress.finish();
    let export = result.map_err(|f| f.context(format!("exporting {:?} for MoSeq", run.session)))?;
    match export.millimetres.as_ref() {
        Some(mm) => {
            if let Some(w) = mm.warning() {
                progress.warning(&w);
            }
        }
        None => progress.warning(
            "the depth camera's intrinsics are unknown (no rig calibration, a camera the table does not know): moseq2-extract's millimetre scalars assume a Kinect v2's field of view and may be off",
        ),
    }
    Ok(export)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn milliseconds_keep_every_nanosecond() {
        assert_eq!(ms(0), "0.000000");
        assert_eq!(ms(1_234_567_891), "1234.567891");
        let back = crate::runtime::recording::moseq::ns_from_ms(&ms(987_654_321_012));
        assert_eq!(back, Some(987_654_321_012));
    }
}
