//! Paws on real bottom views that a lab labelled: the frames of a label file
//! ([`crate::io::paw_labels`]) read once, cut into training material, and a detector judged on
//! them.
//!
//! Rules of the judging, fixed here and documented with the commands:
//! * Detections are looked for in the bottom view only (the rows from [`RealViews::view_top`]
//!   down), at the scale the user told or the one the detector found
//!   ([`crate::vision::paws::detect::PawDetector::find_scale`]).
//! * A detection matches a labelled paw when its centre lies within [`MATCH_RADIUS_MM`] of the
//!   label (at the view's true scale). Detections are matched greedily, surest first, each to
//!   the nearest paw not matched yet; every other detection is false, a second detection of a
//!   matched paw included. A paw the lab did not label (hidden, or left out) therefore counts
//!   against precision when it is found: the figures are, if anything, low.

use super::paws_data::{CutParams, Cutter, PawDataError, PawWindow};
use crate::core::frame::{ColorFrame, PixelFormat, Stamp};
use crate::core::skeleton::Joint;
use crate::io::paw_labels::{FrameSource, LabelTable, LabelledImage, PawMap, lower_view_top, read_labels};
use crate::vision::paws::grey::{GreyImage, Greyer};
use crate::vision::paws::train::{Background, TrainingSet};
use crate::vision::paws::{CANONICAL_PX_PER_MM, PawDetection, PawModel};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Half the side of the box kept out of the negatives around a labelled paw (a paw's pad seen
/// from below is 5-8 mm long).
const LABELLED_PAW_HALF_MM: f64 = 4.5;

/// How near its label (mm on the glass) a detection's centre must be to find the paw.
pub const MATCH_RADIUS_MM: f64 = 4.5;

/// A label file's frames, read, with where their bottom view is and its scale.
#[derive(Clone, Debug)]
pub struct RealViews {
    pub labels: LabelTable,
    pub paws: PawMap,
    /// The frames in the label file's order, grey.
    pub frames: Vec<ColorFrame>,
    /// The first row of the bottom view: 0 when the frames are bottom views only.
    pub view_top: u32,
    /// How that row was chosen, in words for the user.
    pub view_top_how: String,
    /// Pixels per millimetre of the bottom view in the frames.
    pub px_per_mm: f64,
}

impl RealViews {
    /// Reads the label file, maps its body parts to paws (`map`, or guessed from the names),
    /// reads every labelled frame, and finds the bottom view unless `view_top` says where it
    /// begins.
    ///
    /// # Errors
    /// One sentence naming the file and what is wrong: a label file or mapping refused, a
    /// frame missing or unreadable, frames of different sizes, a bottom view below the frames.
    pub fn open(file: &Path, map: Option<&str>, px_per_mm: f64, view_top: Option<u32>) -> Result<Self, PawDataError> {
        let labels = read_labels(file)?;
        let paws = match map {
            Some(text) => PawMap::parse(text, &labels.parts)?,
            None => PawMap::guess(&labels.parts)?,
        };
        let frames = read_frames(file, &labels)?;
        if let Some(first) = frames.first()
            && let Some((k, other)) = frames
                .iter()
                .enumerate()
                .find(|(_, f)| f.dimensions() != first.dimensions())
        {
            return Err(PawDataError::Image {
                path: labels.images[k].image.clone(),
                why: format!(
                    "it is {}x{} and the first labelled frame {}x{}: the frames of one label file must come from one camera",
                    other.width(),
                    other.height(),
                    first.width(),
                    first.height()
                ),
            });
        }
        let (view_top, view_top_how) = match view_top {
            Some(row) => (row, format!("row {row}, as told")),
            None => stacked_view_top(&labels, &paws, &frames),
        };
        if let Some(first) = frames.first()
            && view_top >= first.height()
        {
            return Err(PawDataError::Image {
                path: labels.images[0].image.clone(),
                why: format!(
                    "it has {} rows, and the bottom view was to begin at row {view_top}",
                    first.height()
                ),
            });
        }
        let frames = frames
            .into_iter()
            .map(|f| ColorFrame {
                stamp: Stamp::default(),
                width: f.width(),
                height: f.height(),
                format: PixelFormat::Mono8,
                data: f.into_raw(),
            })
            .collect();
        Ok(Self {
            labels,
            paws,
            frames,
            view_top,
            view_top_how,
            px_per_mm,
        })
    }

    /// The bottom view's region of frame `k`'s pixels (x0, y0, x1, y1).
    pub fn roi(&self, k: usize) -> (u32, u32, u32, u32) {
        let f = &self.frames[k];
        (0, self.view_top, f.width, f.height)
    }

    /// The paws labelled in frame `k` (paw, x, y in the frame's pixels) inside its bottom view.
    pub fn paws_in(&self, k: usize) -> Vec<(Joint, f64, f64)> {
        self.paws
            .paws_in(&self.labels.images[k])
            .into_iter()
            .filter(|&(_, _, y)| y >= f64::from(self.view_top))
            .collect()
    }

    /// Labelled paws in the frames `which`.
    pub fn paw_count(&self, which: &[usize]) -> usize {
        which.iter().map(|&k| self.paws_in(k).len()).sum()
    }

    /// Frame `k`'s bottom view in grey at the canonical scale, as the detector sees it, and
    /// where it lies in the frame.
    fn canonical(&self, k: usize, greyer: &mut Greyer) -> Option<(GreyImage, crate::vision::paws::grey::Placement)> {
        let mut grey = GreyImage::default();
        let place = greyer.convert(
            &self.frames[k],
            self.roi(k),
            self.px_per_mm,
            CANONICAL_PX_PER_MM,
            &mut grey,
        )?;
        Some((grey, place))
    }

    /// The view above the bottom view in frame `k` (the side view of a mirror rig), as a
    /// background at the bottom view's scale with a box kept out around every point labelled
    /// in it (its paws among them): nothing in it is a paw of the bottom view. `None` when the
    /// frames hold one view.
    fn upper_background(&self, k: usize, greyer: &mut Greyer) -> Option<Background> {
        if self.view_top == 0 {
            return None;
        }
        let frame = &self.frames[k];
        let mut grey = GreyImage::default();
        let region = (0, 0, frame.width, self.view_top);
        let place = greyer.convert(frame, region, self.px_per_mm, CANONICAL_PX_PER_MM, &mut grey)?;
        let half = (LABELLED_PAW_HALF_MM * CANONICAL_PX_PER_MM) as f32 + 1.0;
        let excluded = self.labels.images[k]
            .points
            .values()
            .filter(|&&(_, y)| y < f64::from(self.view_top))
            .map(|&(x, y)| {
                let (cx, cy) = (
                    ((x - place.x0) / place.frame_px_per_px) as f32,
                    ((y - place.y0) / place.frame_px_per_px) as f32,
                );
                [cx - half, cy - half, cx + half, cy + half]
            })
            .collect();
        Some(Background { grey, excluded })
    }

    /// Training material from the frames `which`: a positive at each labelled paw (and its
    /// augmented copies), hard negatives around the other body parts labelled in the bottom
    /// view (the nose, the tail's base...), and each view as a background with the paws' boxes
    /// kept out (the view above it too, in frames that stack two), also turned and mirrored ([`crate::vision::paws::train::Background::dihedral`]).
    ///
    /// # Errors
    /// [`PawDataError::NoPaws`] when the frames hold no labelled paw.
    pub fn material(&self, which: &[usize], params: CutParams) -> Result<TrainingSet, PawDataError> {
        let mut set = TrainingSet {
            width: params.width,
            height: params.height,
            ..TrainingSet::default()
        };
        let mut cutter = Cutter::new(params);
        let mut greyer = Greyer::default();
        for &k in which.iter().filter(|&&k| k < self.frames.len()) {
            let Some((grey, place)) = self.canonical(k, &mut greyer) else {
                continue;
            };
            let canonical = |x: f64, y: f64| {
                (
                    (x - place.x0) / place.frame_px_per_px,
                    (y - place.y0) / place.frame_px_per_px,
                )
            };
            let half = (LABELLED_PAW_HALF_MM * CANONICAL_PX_PER_MM) as f32;
            let paws: Vec<PawWindow> = self
                .paws_in(k)
                .into_iter()
                .map(|(_, x, y)| {
                    let (cx, cy) = canonical(x, y);
                    let (fx, fy) = (cx as f32, cy as f32);
                    PawWindow {
                        bounds: [fx - half, fy - half, fx + half, fy + half],
                        centre: Some((cx, cy)),
                    }
                })
                .collect();
            let image = &self.labels.images[k];
            let hard: Vec<(f64, f64)> = image
                .points
                .iter()
                .filter(|&(part, &(_, y))| {
                    y >= f64::from(self.view_top) && !self.paws.paws.iter().any(|(p, _)| p == part)
                })
                .map(|(_, &(x, y))| canonical(x, y))
                .collect();
            let first = set.backgrounds.len();
            cutter.cut_canonical(&mut set, grey, &paws, &hard);
            if let Some(upper) = self.upper_background(k, &mut greyer) {
                set.backgrounds.push(upper);
            }
            let turned: Vec<_> = set.backgrounds[first..]
                .iter()
                .flat_map(|b| b.dihedral().into_iter().skip(1))
                .collect();
            set.backgrounds.extend(turned);
        }
        if set.paws == 0 {
            return Err(PawDataError::NoPaws {
                path: self.labels.path.clone(),
            });
        }
        Ok(set)
    }
}

/// Where a path a label file gives is: DeepLabCut writes it from the project's folder
/// (`labeled-data/VIDEO/img001.png`, the file itself in `labeled-data/VIDEO/`), other tools
/// from the file's own folder; the first folder, from the file's up, that holds it. A path
/// from another machine (absolute, and not here) is looked for by its name the same way.
fn image_path(file: &Path, image: &Path) -> Option<PathBuf> {
    if image.is_absolute() {
        if image.is_file() {
            return Some(image.to_owned());
        }
        return image_path(file, Path::new(image.file_name()?));
    }
    let dir = file.parent().unwrap_or(Path::new("."));
    dir.ancestors()
        .map(|d| if d.as_os_str().is_empty() { Path::new(".") } else { d })
        .map(|d| d.join(image))
        .find(|p| p.is_file())
}

/// Every labelled frame of `labels` (read from `file`), grey: image files found by
/// [`image_path`], pictures kept in the label file decoded, frames of video files decoded by
/// ffmpeg (one run per video).
fn read_frames(file: &Path, labels: &LabelTable) -> Result<Vec<image::GrayImage>, PawDataError> {
    let missing = |path: &Path| PawDataError::Image {
        path: path.to_owned(),
        why: format!("it is neither beside {file:?} nor under any folder above it"),
    };
    // Each video's frames, decoded at once.
    let mut videos: BTreeMap<PathBuf, Vec<u64>> = BTreeMap::new();
    for image in &labels.images {
        if let FrameSource::Video { path, frame } = &image.source {
            videos.entry(path.clone()).or_default().push(*frame);
        }
    }
    let mut decoded: BTreeMap<(PathBuf, u64), Vec<u8>> = BTreeMap::new();
    for (video, mut wanted) in videos {
        let found = image_path(file, &video).ok_or_else(|| missing(&video))?;
        wanted.sort_unstable();
        wanted.dedup();
        let pictures =
            crate::io::video::decode_frames(Path::new("ffmpeg"), &found, &wanted).map_err(|e| PawDataError::Image {
                path: found.clone(),
                why: e.to_string(),
            })?;
        decoded.extend(wanted.into_iter().map(|f| (video.clone(), f)).zip(pictures));
    }
    let unreadable = |path: &Path, e: image::ImageError| PawDataError::Image {
        path: path.to_owned(),
        why: e.to_string(),
    };
    let mut frames = Vec::with_capacity(labels.images.len());
    for image in &labels.images {
        let picture = match &image.source {
            FrameSource::File(name) => {
                let path = image_path(file, name).ok_or_else(|| missing(name))?;
                image::open(&path).map_err(|e| unreadable(&path, e))?
            }
            FrameSource::Embedded(bytes) => image::load_from_memory(bytes).map_err(|e| unreadable(&image.image, e))?,
            FrameSource::Video { path, frame } => {
                let bytes = &decoded[&(path.clone(), *frame)];
                image::load_from_memory(bytes).map_err(|e| unreadable(&image.image, e))?
            }
        };
        frames.push(picture.to_luma8());
    }
    Ok(frames)
}

/// Where the bottom view begins in frames that may stack two views (a side view above a
/// bottom view through a mirror), and how it was found.
///
/// The upper view's parts are told by their names: when every paw's name ends in one view's
/// tag (`paw2LF_bot`) and the same part is labelled with another tag (`paw2LF_top`), every
/// part with that other tag is of the upper view. Without such names, the parts whose every
/// label lies above every labelled paw are. The bottom view begins at the edge between the
/// lowest of the upper view's labels and the highest paw ([`lower_view_top`]); with no upper
/// view, the frames are bottom views only.
fn stacked_view_top(labels: &LabelTable, paws: &PawMap, frames: &[image::GrayImage]) -> (u32, String) {
    let is_paw = |part: &str| paws.paws.iter().any(|(p, _)| p == part);
    let all = || labels.images.iter().flat_map(|i: &LabelledImage| i.points.iter());
    let highest_paw = all()
        .filter(|(p, _)| is_paw(p))
        .map(|(_, &(_, y))| y)
        .fold(f64::MAX, f64::min);
    let tagged = upper_view_tag(&labels.parts, paws);
    let upper = |part: &str| match &tagged {
        Some(tag) => part.rsplit_once('_').is_some_and(|(_, t)| t == tag),
        None => {
            !is_paw(part)
                && all()
                    .filter(|(p, _)| p.as_str() == part)
                    .all(|(_, &(_, y))| y < highest_paw)
        }
    };
    let uppers: Vec<&String> = labels.parts.iter().filter(|p| upper(p)).collect();
    let above = all()
        .filter(|(p, _)| uppers.contains(p))
        .map(|(_, &(_, y))| y)
        .fold(f64::MIN, f64::max);
    let why = match &tagged {
        Some(tag) => format!("the parts tagged `_{tag}`, twins of the paws' own"),
        None => "the parts always above every paw".to_owned(),
    };
    match (uppers.is_empty(), lower_view_top(frames, above, highest_paw)) {
        (false, Some(row)) => (
            row,
            format!(
                "row {row}: the strongest edge across the frames between the upper view's lowest label (y {above:.0}; {why}) and the highest paw (y {highest_paw:.0})"
            ),
        ),
        _ => (
            0,
            "row 0: no part is labelled in a view above the paws', so the frames are bottom views only".into(),
        ),
    }
}

/// The tag of the other view when the paws' names carry a view's tag after their last `_`
/// (all the same) and some paw's name is also labelled with another tag.
fn upper_view_tag(parts: &[String], paws: &PawMap) -> Option<String> {
    let split: Vec<(&str, &str)> = paws
        .paws
        .iter()
        .map(|(p, _)| p.rsplit_once('_'))
        .collect::<Option<_>>()?;
    let own = split.first()?.1;
    if split.iter().any(|(_, t)| *t != own) {
        return None;
    }
    parts
        .iter()
        .filter_map(|p| p.rsplit_once('_'))
        .find(|(stem, tag)| *tag != own && split.iter().any(|(s, _)| s == stem))
        .map(|(_, tag)| tag.to_owned())
}

/// The scale a judged frame was searched at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// The user told it: the view's true scale.
    Told,
    /// Found by the detector over the frames judged together, within this range of px/mm.
    Found { lowest: f64, highest: f64 },
}

/// Per paw, how many were labelled and found.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct PawTally {
    pub labelled: usize,
    pub found: usize,
    pub recall: f64,
}

/// A detector's figures on labelled real frames.
#[derive(Clone, Debug, Default, Serialize)]
pub struct RealPawReport {
    pub frames: usize,
    pub paws: usize,
    pub found: usize,
    pub detections: usize,
    pub false_detections: usize,
    pub recall: f64,
    pub precision: f64,
    pub f1: f64,
    /// Per paw (our names).
    pub per_paw: BTreeMap<String, PawTally>,
    /// Mean distance of a found paw's detection from its label (mm).
    pub mean_centre_error_mm: f64,
    /// The scale the frames' bottom view was searched at (px/mm), per group of frames judged
    /// together (one when not cross-validated); `None` (JSON null) where no scale was found,
    /// and then no paw either.
    pub px_per_mm: Vec<Option<f64>>,
    /// The view's true scale (px/mm), as the user gave it for the labels.
    pub true_px_per_mm: f64,
    /// Recall and precision had only detections of at least each whole score been kept
    /// (a detection's score counts the raw windows grouped into it).
    pub curve: Vec<super::paws_eval::CurvePoint>,
    /// Every detection's score and whether it found a paw, for the curve.
    #[serde(skip)]
    scored: Vec<(f32, bool)>,
}

/// What one frame gave: paws found and missed, detections that were false.
#[derive(Clone, Debug, Default)]
pub struct FrameOutcome {
    pub frame: usize,
    pub found: Vec<(Joint, PawDetection)>,
    pub missed: Vec<(Joint, f64, f64)>,
    pub false_detections: Vec<PawDetection>,
}

impl RealPawReport {
    /// Adds one frame's outcome.
    fn add(&mut self, views: &RealViews, outcome: &FrameOutcome, error_mm: f64) {
        self.frames += 1;
        let found = outcome.found.len();
        self.paws += found + outcome.missed.len();
        self.found += found;
        self.detections += found + outcome.false_detections.len();
        self.false_detections += outcome.false_detections.len();
        let mean = self.mean_centre_error_mm;
        self.mean_centre_error_mm = if self.found == 0 {
            0.0
        } else {
            mean + (error_mm - mean * found as f64) / self.found as f64
        };
        self.scored.extend(outcome.found.iter().map(|(_, d)| (d.score, true)));
        self.scored
            .extend(outcome.false_detections.iter().map(|d| (d.score, false)));
        for (joint, _) in &outcome.found {
            let t = self.per_paw.entry(joint.name().to_owned()).or_default();
            t.labelled += 1;
            t.found += 1;
        }
        for (joint, _, _) in &outcome.missed {
            self.per_paw.entry(joint.name().to_owned()).or_default().labelled += 1;
        }
        self.true_px_per_mm = views.px_per_mm;
        self.finish();
    }

    /// Merges another group's figures (cross-validation's folds).
    pub fn merge(&mut self, other: &RealPawReport) {
        let errors = self.mean_centre_error_mm * self.found as f64 + other.mean_centre_error_mm * other.found as f64;
        self.frames += other.frames;
        self.paws += other.paws;
        self.found += other.found;
        self.detections += other.detections;
        self.false_detections += other.false_detections;
        self.mean_centre_error_mm = if self.found == 0 {
            0.0
        } else {
            errors / self.found as f64
        };
        for (paw, t) in &other.per_paw {
            let mine = self.per_paw.entry(paw.clone()).or_default();
            mine.labelled += t.labelled;
            mine.found += t.found;
        }
        self.px_per_mm.extend(&other.px_per_mm);
        self.true_px_per_mm = other.true_px_per_mm;
        self.scored.extend(&other.scored);
        self.finish();
    }

    fn finish(&mut self) {
        let ratio = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
        self.recall = ratio(self.found, self.paws);
        self.precision = ratio(self.found, self.detections);
        self.f1 = if self.recall + self.precision > 0.0 {
            2.0 * self.recall * self.precision / (self.recall + self.precision)
        } else {
            0.0
        };
        for t in self.per_paw.values_mut() {
            t.recall = ratio(t.found, t.labelled);
        }
        // A cascade's scores count windows (whole numbers from 1); a network's are
        // probabilities, its curve in tenths.
        let top = self.scored.iter().map(|(s, _)| *s).fold(0.0f32, f32::max);
        let mins: Vec<f32> = if top > 1.0 {
            (1..=top.floor() as u32).map(|m| m as f32).collect()
        } else {
            (1..10).map(|m| m as f32 / 10.0).collect()
        };
        self.curve = mins
            .into_iter()
            .map(|min| {
                let kept = self.scored.iter().filter(|(s, _)| *s >= min);
                let (all, found) = kept.fold((0, 0), |(a, f), (_, t)| (a + 1, f + usize::from(*t)));
                super::paws_eval::CurvePoint {
                    min_score: (f64::from(min) * 10.0).round() / 10.0,
                    precision: ratio(found, all),
                    recall: ratio(found, self.paws),
                }
            })
            .collect();
    }
}

/// Runs `detector` on the bottom views of the frames `which` and matches its detections to the
/// labels ([module rules](self)), keeping the `max_paws` surest detections of a view (all at
/// 0; [`crate::vision::paws::keep_surest`]). At [`Scale::Found`] one scale is found for all
/// of `which` together, as for the frames of one rig.
pub fn judge(
    detector: &mut PawModel,
    views: &RealViews,
    which: &[usize],
    scale: Scale,
    max_paws: usize,
) -> (RealPawReport, Vec<FrameOutcome>) {
    let px_per_mm = match scale {
        Scale::Told => Some(views.px_per_mm),
        Scale::Found { lowest, highest } => {
            let frames: Vec<crate::vision::paws::detect::FrameRegion<'_>> =
                which.iter().map(|&k| (&views.frames[k], views.roi(k))).collect();
            detector.find_scale(&frames, lowest, highest).map(|f| f.px_per_mm)
        }
    };
    let mut report = RealPawReport {
        px_per_mm: vec![px_per_mm],
        true_px_per_mm: views.px_per_mm,
        ..RealPawReport::default()
    };
    let radius = MATCH_RADIUS_MM * views.px_per_mm;
    let mut outcomes = Vec::with_capacity(which.len());
    let mut dets = Vec::new();
    for &k in which {
        // No scale found: nothing is found either.
        dets.clear();
        if let Some(s) = px_per_mm {
            detector.detect(&views.frames[k], views.roi(k), s, &mut dets);
        }
        crate::vision::paws::keep_surest(&mut dets, max_paws);
        let paws = views.paws_in(k);
        let mut taken = vec![false; paws.len()];
        let mut outcome = FrameOutcome {
            frame: k,
            ..FrameOutcome::default()
        };
        let mut error = 0.0;
        for d in &dets {
            let (cx, cy) = d.centre();
            let nearest = paws
                .iter()
                .enumerate()
                .filter(|(i, _)| !taken[*i])
                .map(|(i, &(_, x, y))| (i, (cx - x).hypot(cy - y)))
                .filter(|&(_, dist)| dist <= radius)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match nearest {
                Some((i, dist)) => {
                    taken[i] = true;
                    error += dist / views.px_per_mm;
                    outcome.found.push((paws[i].0, *d));
                }
                None => outcome.false_detections.push(*d),
            }
        }
        outcome.missed = paws.iter().zip(&taken).filter(|(_, t)| !**t).map(|(p, _)| *p).collect();
        report.add(views, &outcome, error);
        outcomes.push(outcome);
    }
    (report, outcomes)
}

/// The frames of fold `fold` of `folds` over `n` frames: contiguous runs, since neighbouring
/// frames of a video look alike and must not be split between training and judging. More
/// folds than frames are as many folds as frames; a fold past the last is empty.
pub fn fold_frames(n: usize, folds: usize, fold: usize) -> Vec<usize> {
    let folds = folds.clamp(1, n.max(1));
    if fold >= folds {
        return Vec::new();
    }
    (n * fold / folds..n * (fold + 1) / folds).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mirror_mouse() -> Option<PathBuf> {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/realdata/mirror-mouse/CollectedData.csv");
        file.is_file().then_some(file)
    }

    const MAP: &str =
        "paw1LH_bot=left_hind_paw,paw2LF_bot=left_fore_paw,paw3RF_bot=right_fore_paw,paw4RH_bot=right_hind_paw";

    /// Lightning Pose's mirror-mouse frames (beside the repository when they are there): the
    /// bottom view found from the labels, a positive cut at every labelled paw, hard negatives
    /// at the nose and the tail labelled in the bottom view, one background per frame.
    #[test]
    fn labelled_real_frames_give_positives_hard_negatives_and_backgrounds() {
        let Some(file) = mirror_mouse() else {
            eprintln!("skipped: the real data is not beside the repository");
            return;
        };
        let views = RealViews::open(&file, Some(MAP), 3.5, None).unwrap();
        assert!((165..=172).contains(&views.view_top), "{}", views.view_top_how);
        let params = CutParams {
            width: 12,
            height: 12,
            augment: 2,
            hard_per_place: 2,
            binnings: &[1],
            seed: 1,
        };
        let all: Vec<usize> = (0..views.frames.len()).collect();
        let set = views.material(&all, params).unwrap();
        assert_eq!(set.paws, views.paw_count(&all));
        assert_eq!(set.positive_count(), set.paws * 3);
        assert_eq!(set.backgrounds.len(), 45 * 2 * 8);
        // 406 x (396 - 168) pixels at 3.5 px/mm: about 116 x 65 mm.
        let b = &set.backgrounds[0].grey;
        assert!(
            (110..120).contains(&b.width) && (60..70).contains(&b.height),
            "{}x{}",
            b.width,
            b.height
        );
        assert!(set.hard_count() > 45, "{} hard negatives", set.hard_count());
        // The first fold alone: fewer paws, never one of the other folds'.
        let first = fold_frames(45, 5, 0);
        let half = views.material(&first, params).unwrap();
        assert!(half.paws < set.paws && half.backgrounds.len() == first.len() * 2 * 8);
    }

    #[test]
    fn folds_are_contiguous_and_cover_every_frame_once() {
        let mut all: Vec<usize> = (0..5).flat_map(|f| fold_frames(45, 5, f)).collect();
        assert_eq!(fold_frames(45, 5, 0), (0..9).collect::<Vec<_>>());
        all.sort_unstable();
        assert_eq!(all, (0..45).collect::<Vec<_>>());
        assert_eq!(fold_frames(3, 5, 2), vec![2]);
        assert!(fold_frames(3, 5, 4).is_empty());
    }

    #[test]
    fn a_label_file_naming_a_missing_frame_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("CollectedData_lab.csv");
        std::fs::write(
            &file,
            "scorer,lab,lab\nbodyparts,LF,LF\ncoords,x,y\nlabeled-data/v/img0.png,1,2\n",
        )
        .unwrap();
        let e = RealViews::open(&file, Some("LF=left_fore_paw"), 3.5, None).unwrap_err();
        assert!(e.to_string().contains("img0.png"), "{e}");
    }
}
