//! `mousepose export video RUN --out FILE.mp4`: every frame pair of a run drawn as `replay`
//! draws its pictures (the depth view with the skeleton, the bottom view with the paws, a side
//! view; [`crate::runtime::stages::overlay`]) under a line of frame counters, encoded by
//! ffmpeg with libx264.
//!
//! The frames are read again from the run's session, in order, and matched to the rows of
//! `poses.csv` by their sequence numbers. `--from`/`--to` select seconds from the first
//! depth frame (its device clock).

use crate::app::chart::{draw_text, text_width};
use crate::app::export::{Run, check_file_out};
use crate::app::{Failure, print};
use crate::core::frame::{ColorFrame, DepthFrame};
use crate::core::image::RgbImage;
use crate::io::session::SessionReader;
use crate::io::video::{Encoder, EncoderSpec};
use crate::runtime::sink::poses::{POSES_FILE, read_poses};
use crate::runtime::stages::PoseRecord;
use crate::runtime::stages::overlay;
use crate::vision::calibrate::RigCalibration;
use clap::Args;
use std::path::PathBuf;

/// Height of the line of counters above the pictures, pixels.
const COUNTER_BAR_PX: u32 = 24;
/// Space between the overlay's panels (as `overlay::draw` leaves it).
const GAP_PX: u32 = 4;

#[derive(Debug, Args)]
pub struct VideoArgs {
    /// The run: a replay's output directory (or a daemon's chunk).
    #[arg(value_name = "RUN")]
    pub run: PathBuf,
    /// The MP4 file to write.
    #[arg(long, value_name = "FILE.mp4")]
    pub out: PathBuf,
    /// The session the run was made from, when its summary does not name it (or it moved).
    #[arg(long, value_name = "DIR")]
    pub session: Option<PathBuf>,
    /// Start this many seconds after the first frame.
    #[arg(long, value_name = "S", value_parser = parse_offset, allow_negative_numbers = true)]
    pub from: Option<f64>,
    /// End this many seconds after the first frame.
    #[arg(long, value_name = "S", value_parser = parse_offset, allow_negative_numbers = true)]
    pub to: Option<f64>,
    /// H.264 quality, 0 (lossless) to 51 (worst); 23 is x264's default.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(0..=51))]
    pub crf: u32,
    /// Replace the file if it exists.
    #[arg(long)]
    pub force: bool,
    /// Print what was written as one JSON object (`out`, `frames`, `width`, `height`).
    #[arg(long)]
    pub json: bool,
}

fn parse_offset(s: &str) -> Result<f64, String> {
    crate::app::parse_ranged(s, "a number of seconds", 0.0, 1e7)
}

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
    let has_color = chosen.iter().any(|r| r.color.is_some());
    check_file_out(&options.out, options.force)?;

    let mut depth_frames = reader.depth_frames().filter_map(Result::ok);
    let mut color_frames = reader.color_frames().into_iter().flatten().filter_map(Result::ok);
    let mut color: Option<ColorFrame> = None;
    let mut encoder: Option<Encoder> = None;
    let (mut width, mut height) = (0, 0);
    let fps = reader
        .meta()
        .camera(crate::io::session::CameraRole::Depth)
        .map_or(30.0, |c| c.fps)
        .max(1.0);
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
        let picture = overlay::draw(&rig, &depth, this_color, row);
        let encoder = match &mut encoder {
            Some(e) => e,
            None => {
                // Wide enough for the widest bottom view the overlay draws (twice its height).
                let plain = overlay::draw(&rig, &depth, None, row);
                let bottom = if has_color { GAP_PX + 2 * plain.height } else { 0 };
                width = (plain.width + bottom).max(picture.width).next_multiple_of(2);
                height = (plain.height + COUNTER_BAR_PX).next_multiple_of(2);
                encoder.insert(Encoder::start(
                    EncoderSpec::h264(width, height, fps, options.crf),
                    &options.out,
                )?)
            }
        };
        let mut canvas = RgbImage::new(width, height, [255, 255, 255]);
        place(&mut canvas, &picture, COUNTER_BAR_PX);
        let colour_text = row.color.map_or_else(|| "-".to_owned(), |c| c.seq.to_string());
        let text = format!(
            "frame {}  depth {}  colour {}  t {:.3} s  {}",
            k + 1,
            row.depth.seq,
            colour_text,
            seconds(row),
            row.status.name()
        );
        draw_text(&mut canvas, 6, 6, &text, [20, 20, 20], 2);
        let label = format!("{}/{}", k + 1, total);
        draw_text(
            &mut canvas,
            i64::from(width) - i64::from(text_width(&label, 2)) - 6,
            6,
            &label,
            [90, 90, 90],
            2,
        );
        encoder.write(&canvas.data)?;
        progress(k as u64 + 1, total);
    }
    let frames = encoder.as_ref().map_or(0, Encoder::frames);
    if let Some(e) = encoder {
        e.finish()?;
    }
    Ok(VideoExport { frames, width, height })
}

/// `mousepose export video`.
pub fn command(args: &VideoArgs) -> crate::app::Outcome {
    let run = Run::open(&args.run, args.session.as_deref()).map_err(Failure::usage)?;
    let options = VideoOptions {
        run,
        out: args.out.clone(),
        from_s: args.from,
        to_s: args.to,
        crf: args.crf,
        force: args.force,
    };
    let bar = crate::app::progress::bar(0, "video");
    let result = export_video(&options, |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    let v = result.map_err(|f| f.context(format!("drawing the video of {:?}", args.run)))?;
    if args.json {
        #[derive(serde::Serialize)]
        struct Written<'a> {
            out: &'a std::path::Path,
            #[serde(flatten)]
            video: VideoExport,
        }
        return Ok(crate::app::print_json(&Written {
            out: &args.out,
            video: v,
        })?);
    }
    Ok(print(&format!(
        "{} frames of {}x{} to {:?}\n",
        v.frames, v.width, v.height, args.out
    ))?)
}
