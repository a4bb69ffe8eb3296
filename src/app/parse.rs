//! The command line's value parsers: a flag's value checked where clap reads it, refused in
//! one sentence that names what was expected; and the flags more than one command takes.

use clap::Args;
use std::path::PathBuf;

/// `s` as a `T` within `lo..=hi` (what a flag takes, named by `what`).
pub fn ranged<T>(s: &str, what: &str, lo: T, hi: T) -> Result<T, String>
where
    T: std::str::FromStr + PartialOrd + std::fmt::Display + Copy,
{
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| format!("expected {what} from {lo} to {hi}, got {s:?}"))?;
    // A value that compares with nothing (a float's `nan`) is outside the range too.
    use std::cmp::Ordering::{Equal, Greater, Less};
    let inside =
        matches!(v.partial_cmp(&lo), Some(Greater | Equal)) && matches!(v.partial_cmp(&hi), Some(Less | Equal));
    if !inside {
        return Err(format!("expected {what} from {lo} to {hi}, got {s}"));
    }
    Ok(v)
}

/// A number of images.
pub fn images(s: &str) -> Result<u64, String> {
    ranged(s, "a whole number of images", 1, 10_000_000)
}

/// A duration in seconds, above 0 and at most a day.
pub fn seconds(s: &str) -> Result<f64, String> {
    let v = ranged(s, "a number of seconds", 0.0, 86_400.0)?;
    if v <= 0.0 {
        return Err(format!("expected a number of seconds above 0, got {s}"));
    }
    Ok(v)
}

/// A fraction of a data set, above 0 and at most 1.
pub fn subset(s: &str) -> Result<f64, String> {
    let v = ranged(s, "a fraction of the data set", 0.0, 1.0)?;
    if v <= 0.0 {
        return Err(format!("expected a fraction of the data set above 0, got {s}"));
    }
    Ok(v)
}

/// A prediction's lead in milliseconds, as nanoseconds
/// ([`crate::runtime::pose_record::lead_ns`]).
pub fn lead_ms(s: &str) -> Result<u64, String> {
    let ms: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("expected a lead in milliseconds, got {s:?}"))?;
    crate::runtime::pose_record::lead_ns(ms)
}

/// `--mice N`: how many mice share the cage ([`crate::vision::identity::mice_count`]).
pub fn mice(s: &str) -> Result<usize, String> {
    let n = s
        .trim()
        .parse::<i64>()
        .map_err(|_| format!("expected a number of mice, got {s:?}"))?;
    crate::vision::identity::mice_count(n)
}

/// A pairing time in milliseconds (`--partner-wait`, `--partner-reach`), as nanoseconds.
pub fn partner_ms(s: &str) -> Result<u64, String> {
    ranged(s, "a number of milliseconds", 0.0_f64, 1000.0).map(|ms| (ms * 1e6).round() as u64)
}

/// A frame rate.
pub fn fps(s: &str) -> Result<f64, String> {
    ranged(s, "a frame rate", 1.0, 1000.0)
}

/// A depth noise level in millimetres.
pub fn noise_mm(s: &str) -> Result<f64, String> {
    ranged(s, "a noise level in millimetres", 0.0, 100.0)
}

/// The side of a chessboard square in millimetres.
pub fn square_mm(s: &str) -> Result<f64, String> {
    ranged(s, "a square side in millimetres", 0.5, 1000.0)
}

/// A binning factor: 1, 2 or 4.
/// Pixels per millimetre on the glass or floor.
pub fn px_per_mm(s: &str) -> Result<f64, String> {
    ranged(s, "pixels per millimetre", 0.05, 50.0)
}

pub fn binning(s: &str) -> Result<u32, String> {
    match s.trim() {
        "1" => Ok(1),
        "2" => Ok(2),
        "4" => Ok(4),
        other => Err(format!("expected a binning factor of 1, 2 or 4, got {other:?}")),
    }
}

/// A live stream's endpoint: `tcp://IP:PORT` or `ipc://PATH`.
pub fn endpoint(s: &str) -> Result<crate::runtime::stream::Endpoint, String> {
    s.parse()
        .map_err(|e: crate::runtime::stream::EndpointError| e.to_string())
}

/// How many paws a bottom view keeps, as `detect paws` and `eval paws` take it.
#[derive(Clone, Copy, Debug, Args)]
pub struct MaxPawsArg {
    /// Keep at most this many detections a view, the surest: a view of one mouse shows four
    /// paws. 0 keeps every detection (a view of several mice).
    #[arg(long, value_name = "N", default_value_t = crate::vision::paws::PAWS_PER_VIEW)]
    pub max_paws: usize,
}

/// Where `detect paws` and `eval paws` look for a bottom view's scale they are not told.
#[derive(Clone, Copy, Debug, Args)]
pub struct FindScaleArg {
    /// Where to look for the bottom view's scale when it is not told: LOWEST:HIGHEST pixels per
    /// millimetre, candidates an eighth of an octave apart (default 0.5:8, from a binned camera
    /// far away to a close macro view). A lab that knows its rig roughly narrows it: faster,
    /// and no scale the rig cannot have.
    #[arg(long, value_name = "LO:HI", value_parser = scale_range)]
    pub find_scale: Option<(f64, f64)>,
}

impl FindScaleArg {
    /// The range asked for, or the default.
    pub fn range(&self) -> (f64, f64) {
        self.find_scale.unwrap_or(crate::vision::paws::detect::FIND_SCALE_RANGE)
    }
}

/// A range of scales, `LOWEST:HIGHEST` pixels per millimetre.
pub fn scale_range(s: &str) -> Result<(f64, f64), String> {
    let Some((lowest, highest)) = s.split_once(':') else {
        return Err(format!("expected LOWEST:HIGHEST pixels per millimetre, got {s:?}"));
    };
    let (lowest, highest) = (px_per_mm(lowest)?, px_per_mm(highest)?);
    if lowest > highest {
        return Err(format!("the lowest scale {lowest} is above the highest, {highest}"));
    }
    Ok((lowest, highest))
}

/// Real frames a lab labelled (paws), as `train paws` and `eval paws` take them.
#[derive(Debug, Args)]
pub struct LabelArgs {
    /// Paws: real frames a lab labelled, in DeepLabCut's `CollectedData_*.csv` (the frames'
    /// paths in it are found from the file's folder or a folder above it).
    #[arg(long, value_name = "FILE")]
    pub labels: Option<PathBuf>,
    /// Which labelled body parts are our paws: `NAME=PAW,...`, PAW one of left_fore_paw,
    /// right_fore_paw, left_hind_paw, right_hind_paw; guessed from the names (`LF`,
    /// `right_hind`...) when not given.
    #[arg(long, value_name = "MAP", requires = "labels")]
    pub paws: Option<String>,
    /// How many pixels a millimetre on the floor spans in the labelled frames' bottom view.
    #[arg(long = "label-px-per-mm", value_name = "S", requires = "labels", value_parser = px_per_mm)]
    pub px_per_mm: Option<f64>,
    /// The first row of the bottom view in frames that stack a side view above it; found from
    /// the labels when not given (0 when no part is labelled above every paw).
    #[arg(long, value_name = "ROW", requires = "labels")]
    pub view_top: Option<u32>,
}

impl LabelArgs {
    /// The labels to read, if any.
    ///
    /// # Errors
    /// `--labels` without `--label-px-per-mm`.
    pub fn options(&self) -> anyhow::Result<Option<crate::engine::train::LabelOptions>> {
        let Some(file) = &self.labels else {
            return Ok(None);
        };
        let Some(px_per_mm) = self.px_per_mm else {
            anyhow::bail!(
                "--labels needs --label-px-per-mm S, the labelled frames' pixels per millimetre on the floor (measure a known length in one frame)"
            );
        };
        Ok(Some(crate::engine::train::LabelOptions {
            file: file.clone(),
            map: self.paws.clone(),
            px_per_mm,
            view_top: self.view_top,
        }))
    }
}

/// How the paw network is trained (`--net`).
#[derive(clap::Args, Clone, Debug)]
pub struct NetArgs {
    /// With `--net`: training iterations, each a batch of 16 crops of the labelled views.
    #[arg(long, value_name = "N", default_value_t = crate::training::paws_net::NetParams::default().iterations)]
    pub net_iterations: usize,
    /// With `--net`: channels of the network's inner layers.
    #[arg(long, value_name = "C", default_value_t = 12, value_parser = clap::value_parser!(u16).range(2..=128))]
    pub net_width: u16,
    /// With `--net`: the heatmap's probability a paw needs to be reported.
    #[arg(long, value_name = "P", default_value_t = crate::training::paws_net::NetParams::default().threshold)]
    pub net_threshold: f32,
}

impl NetArgs {
    /// The training's settings, drawn from `seed`.
    pub fn params(&self, seed: u64) -> crate::training::paws_net::NetParams {
        crate::training::paws_net::NetParams {
            iterations: self.net_iterations,
            width: usize::from(self.net_width),
            threshold: self.net_threshold,
            seed,
            ..crate::training::paws_net::NetParams::default()
        }
    }
}
