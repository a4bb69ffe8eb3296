//! The engine of `mousepose export video RUN --out FILE.mp4`: every frame pair of a run drawn as `replay`
//! draws its pictures (the depth view with the skeleton, the bottom view with the paws, a side
//! view; [`crate::runtime::overlay`]) under a line of frame counters, encoded by
//! ffmpeg with libx264.
//!
//! The frames are read again from the run's session, in order, and matched to the rows of
//! `poses.csv` by their sequence numbers (rows whose depth frame the session does not hold,
//! e.g. a daemon's chunk while recording was paused, are left out and counted). `--from`/`--to`
//! select seconds from the first depth frame (its device clock). Every frame of the video has
//! the same size (a recording with a colour camera shows an empty bottom view where a pair
//! has no colour frame) and is shown at its depth frame's device time from the first frame
//! drawn: the file has variable frame rate timestamps, not a constant rate.

use crate::core::frame::{ColorFrame, DepthFrame};
use crate::core::image::RgbImage;
use crate::engine::Failure;
use crate::engine::chart::{draw_text, text_width};
use crate::engine::export::{Run, check_file_out};
use crate::engine::progress::Progress;
use crate::io::session::{CameraRole, SessionReader};
use crate::io::video::{Encoder, EncoderSpec};
use crate::runtime::overlay;
use crate::runtime::pose_record::PoseRecord;
use crate::runtime::sink::poses::{POSES_FILE, read_poses};
use crate::vision::calibrate::RigCalibration;
use std::path::PathBuf;

/// Height of the line of counters above the pictures, pixels.
const COUNTER_BAR_PX: u32 = 24;

/// What to draw.
#[derive(Clone, Debug)]
pub struct VideoOptions {
    pub run: Run,
    pub out: PathBuf,
    pub from_s: Option<f64>,
    pub to_s: Option<f64>,
    pub crf: u32,
    pub force: bool,
}

/// What was written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct VideoExport {
    pub frames: u64,
    pub width: u32,
    pub height: u32,
    /// Rows of the window whose depth frame is not in the session, left out.
    pub rows_without_frames: u64,
    /// The last frame's time from the first, microseconds.
    pub duration_us: u64,
}

/// `img` placed at the top left of a `width` x `height` canvas (cut off where larger).
fn place(canvas: &mut RgbImage, img: &RgbImage, y0: u32) {
    let w = img.width.min(canvas.width) as usize;
    for y in 0..img.height.min(canvas.height.saturating_sub(y0)) {
        let src = (y * img.width) as usize * 3;
        let dst = ((y + y0) * canvas.width) as usize * 3;
        if let (Some(s), Some(d)) = (img.data.get(src..src + w * 3), canvas.data.get_mut(dst..dst + w * 3)) {
            d.copy_from_slice(s);
        }
    }
}

/// `picture` on a white canvas of `size` under a line of counters: `text` on the left,
/// `label` on the right.
fn with_counters(picture: &RgbImage, (width, height): (u32, u32), text: &str, label: &str) -> RgbImage {
    let mut canvas = RgbImage::new(width, height, [255, 255, 255]);
    place(&mut canvas, picture, COUNTER_BAR_PX);
    draw_text(&mut canvas, 6, 6, text, [20, 20, 20], 2);
    draw_text(
        &mut canvas,
        i64::from(width) - i64::from(text_width(label, 2)) - 6,
        6,
        label,
        [90, 90, 90],
        2,
    );
    canvas
}

/// The rows of `poses.csv` to draw: those of the time window whose depth frame the session
/// holds (at least one).
struct Window<'r> {
    /// The run's first row's depth device time, ns: the window's times count from it.
    t0_ns: u64,
    rows: Vec<&'r PoseRecord>,
    /// Rows of the window whose depth frame is not in the session.
    rows_without_frames: u64,
}

impl<'r> Window<'r> {
    fn choose(options: &VideoOptions, rows: &'r [PoseRecord], reader: &SessionReader) -> Result<Self, Failure> {
        let run = &options.run;
        let Some(first) = rows.first() else {
            return Err(Failure::usage(anyhow::anyhow!(
                "{:?} has no rows",
                run.dir.join(POSES_FILE)
            )));
        };
        let t0 = first.depth.device_ns;
        let seconds = |r: &PoseRecord| r.depth.device_ns.saturating_sub(t0) as f64 / 1e9;
        let (from, to) = (options.from_s.unwrap_or(0.0), options.to_s.unwrap_or(f64::INFINITY));
        if to <= from {
            return Err(Failure::usage(anyhow::anyhow!(
                "--to {to} s is not after --from {from} s"
            )));
        }
        let chosen: Vec<&PoseRecord> = rows.iter().filter(|r| (from..to).contains(&seconds(r))).collect();
        if chosen.is_empty() {
            return Err(Failure::usage(anyhow::anyhow!(
                "no frame of the run lies between {from} s and {to} s (it lasts {:.2} s)",
                rows.last().map_or(0.0, seconds)
            )));
        }
        let recorded: std::collections::HashSet<u64> = reader.seqs(CameraRole::Depth).into_iter().collect();
        let in_window = chosen.len() as u64;
        let chosen: Vec<&PoseRecord> = chosen.into_iter().filter(|r| recorded.contains(&r.depth.seq)).collect();
        if chosen.is_empty() {
            return Err(Failure::usage(anyhow::anyhow!(
                "none of the run's depth frames between {from} s and {to} s is in the session {:?} (is it the run's session?)",
                run.session
            )));
        }
        Ok(Self {
            t0_ns: t0,
            rows_without_frames: in_window - chosen.len() as u64,
            rows: chosen,
        })
    }
}

/// Writes the video (see the module documentation); `progress` is called with the frames done
/// and the total.
///
/// # Errors
/// The run or its session cannot be read, no row falls in the time window, or ffmpeg fails.
pub fn export_video(options: &VideoOptions, mut progress: impl FnMut(u64, u64)) -> Result<VideoExport, Failure> {
    let run = &options.run;
    let rows = read_poses(&run.dir.join(POSES_FILE)).map_err(Failure::usage)?;
    let reader = SessionReader::open(&run.session)
        .map_err(|e| Failure::usage(e).context(format!("opening the session {:?}", run.session)))?;
    let rig = match &run.calibration {
        Some(path) => RigCalibration::load(path)
            .map_err(|e| Failure::usage(e).context("loading the run's calibration"))?
            .rig(),
        None => reader
            .meta()
            .rig
            .unwrap_or_else(crate::core::geometry::Rig::default_rig),
    };
    let Window {
        t0_ns: t0,
        rows: chosen,
        rows_without_frames,
    } = Window::choose(options, &rows, &reader)?;
    let seconds = |r: &PoseRecord| r.depth.device_ns.saturating_sub(t0) as f64 / 1e9;
    // The window holds a row at least.
    let t_first = chosen.first().map_or(t0, |r| r.depth.device_ns);
    let has_color = reader.meta().camera(CameraRole::Color).is_some();
    check_file_out(&options.out, options.force)?;

    let mut depth_frames = reader.depth_frames().filter_map(Result::ok);
    let mut color_frames = reader.color_frames().into_iter().flatten().filter_map(Result::ok);
    let mut color: Option<ColorFrame> = None;
    let mut encoder: Option<Encoder> = None;
    let (mut width, mut height) = (0, 0);
    let mut last_us: Option<u64> = None;
    let fps = reader.meta().camera(CameraRole::Depth).map_or(30.0, |c| c.fps).max(1.0);
    let total = chosen.len() as u64;
    for (k, row) in chosen.iter().enumerate() {
        let depth: DepthFrame = loop {
            match depth_frames.next() {
                Some(f) if f.stamp.seq == row.depth.seq => break f,
                Some(f) if f.stamp.seq < row.depth.seq => {}
                _ => {
                    return Err(Failure::from(anyhow::anyhow!(
                        "the depth frame {} of poses.csv is not in the session {:?} (is it the run's session?)",
                        row.depth.seq,
                        run.session
                    )));
                }
            }
        };
        if let Some(c) = row.color {
            while color.as_ref().is_none_or(|f| f.stamp.seq < c.seq) {
                match color_frames.next() {
                    Some(f) => color = Some(f),
                    None => break,
                }
            }
        }
        let this_color = row.color.and_then(|c| color.as_ref().filter(|f| f.stamp.seq == c.seq));
        // Every picture has the same size: panels of fixed sizes, an empty bottom view where
        // a pair of a recording with a colour camera has no colour frame.
        let picture = overlay::draw_panels(&rig, &depth, this_color, row, has_color, None);
        let encoder = match &mut encoder {
            Some(e) => e,
            None => {
                width = picture.width.next_multiple_of(2);
                height = (picture.height + COUNTER_BAR_PX).next_multiple_of(2);
                encoder.insert(Encoder::start(
                    EncoderSpec::h264(width, height, fps, options.crf).timed(),
                    &options.out,
                )?)
            }
        };
        let text = format!(
            "frame {}  depth {}  colour {}  t {:.3} s  {}",
            k + 1,
            row.depth.seq,
            row.color.map_or_else(|| "-".to_owned(), |c| c.seq.to_string()),
            seconds(row),
            row.status.name()
        );
        let canvas = with_counters(&picture, (width, height), &text, &format!("{}/{}", k + 1, total));
        // The depth frame's device time from the first frame drawn (times that do not
        // increase are nudged by a microsecond, as a container needs).
        let t_us = row.depth.device_ns.saturating_sub(t_first) / 1000;
        let t_us = last_us.map_or(t_us, |last| t_us.max(last + 1));
        encoder.write_at(&canvas.data, t_us)?;
        last_us = Some(t_us);
        progress(k as u64 + 1, total);
    }
    let frames = encoder.as_ref().map_or(0, Encoder::frames);
    if let Some(e) = encoder {
        e.finish()?;
    }
    Ok(VideoExport {
        frames,
        width,
        height,
        rows_without_frames,
        duration_us: last_us.unwrap_or(0),
    })
}

/// `mousepose export video`: [`export_video`], telling `progress` the frames done.
///
/// # Errors
/// See [`export_video`].
pub fn video(options: &VideoOptions, progress: &dyn Progress) -> Result<VideoExport, Failure> {
    progress.start("video", 0);
    let result = export_video(options, |done, total| {
        progress.set_total(total);
        progress.set_done(done);
    });
    progress.finish();
    result.map_err(|f| f.context(format!("drawing the video of {:?}", options.run.dir)))
}
