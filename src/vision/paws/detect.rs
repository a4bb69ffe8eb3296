//! The run-time paw detector: a cascade evaluated over a grey image at the canonical scale
//! (and a few scales around it), its raw windows grouped like OpenCV's `groupRectangles`.
//!
//! The window arithmetic is OpenCV's, operation for operation: 32-bit integral sums, features
//! in single precision times the window's normalisation factor, stage sums in double
//! precision against the stored threshold less 1e-5, flat windows rejected before the first
//! stage. [`scan_like_opencv`] also walks
//! the positions the way OpenCV 4's `CascadeClassifier` does at scale 1 (a step of 2 pixels in
//! x and y, and one more step in x after a window the first stage rejects), so the two give
//! identical raw windows on the same image.

use super::cascade::{Cascade, Verdict};
use super::grey::{GreyImage, Greyer, Placement, ResampleScratch, resample};
use super::integral::Integral;
use super::{CANONICAL_PX_PER_MM, PawDetection, PawError};
use crate::core::frame::ColorFrame;
use std::path::Path;

/// A feature rectangle as four offsets into the integral image and a weight.
#[derive(Clone, Copy, Debug, Default)]
struct RectOfs {
    a: usize,
    b: usize,
    c: usize,
    d: usize,
    weight: f32,
}

/// A stump ready to run: its feature's rectangles, threshold and leaves.
#[derive(Clone, Copy, Debug, Default)]
struct FastStump {
    rects: [RectOfs; 3],
    count: usize,
    threshold: f32,
    left: f32,
    right: f32,
}

/// A cascade compiled against one integral-image row stride.
#[derive(Clone, Debug, Default)]
struct Compiled {
    stride: usize,
    stumps: Vec<FastStump>,
    /// Per stage: index of its first stump, its stump count, its applied threshold.
    stages: Vec<(usize, usize, f64)>,
    norm: RectOfs,
    area: f64,
}

impl Compiled {
    fn ofs(stride: usize, x: u32, y: u32, w: u32, h: u32, weight: f32) -> RectOfs {
        let (x, y, w, h) = (x as usize, y as usize, w as usize, h as usize);
        RectOfs {
            a: y * stride + x,
            b: y * stride + x + w,
            c: (y + h) * stride + x,
            d: (y + h) * stride + x + w,
            weight,
        }
    }

    /// Rebuilds the offsets for `stride` (no allocation once the vectors have grown).
    fn compile(&mut self, cascade: &Cascade, stride: usize) {
        if self.stride == stride && !self.stumps.is_empty() {
            return;
        }
        self.stride = stride;
        self.stumps.clear();
        self.stages.clear();
        for stage in &cascade.stages {
            let first = self.stumps.len();
            for tree in &stage.weak {
                let node = tree.nodes[0];
                let f = &cascade.features[node.feature];
                let mut s = FastStump {
                    count: f.rects.len(),
                    threshold: node.threshold,
                    left: tree.leaves[(-node.left).max(0) as usize],
                    right: tree.leaves[(-node.right).max(0) as usize],
                    ..FastStump::default()
                };
                for (k, r) in f.rects.iter().enumerate().take(3) {
                    s.rects[k] = Self::ofs(stride, r.x, r.y, r.width, r.height, r.weight);
                }
                self.stumps.push(s);
            }
            self.stages.push((first, stage.weak.len(), stage.applied_threshold()));
        }
        let (w, h) = (cascade.width, cascade.height);
        self.norm = Self::ofs(stride, 1, 1, w - 2, h - 2, 1.0);
        self.area = f64::from((w - 2) * (h - 2));
    }

    #[inline]
    fn rect(sum: &[i32], base: usize, r: &RectOfs) -> i32 {
        sum[base + r.a]
            .wrapping_sub(sum[base + r.b])
            .wrapping_sub(sum[base + r.c])
            .wrapping_add(sum[base + r.d])
    }

    /// OpenCV's verdict for the window at corner index `base` of `ii`.
    #[inline]
    fn classify(&self, ii: &Integral, base: usize) -> Verdict {
        let n = &self.norm;
        let s = Self::rect(&ii.sum, base, n);
        let sq = ii.sqsum[base + n.a]
            .wrapping_sub(ii.sqsum[base + n.b])
            .wrapping_sub(ii.sqsum[base + n.c])
            .wrapping_add(ii.sqsum[base + n.d]);
        let nf = self.area * f64::from(sq) - f64::from(s) * f64::from(s);
        if nf <= 0.0 {
            return Verdict::Flat;
        }
        let factor = (1.0 / nf.sqrt()) as f32;
        if self.area * f64::from(factor) >= 0.1 {
            return Verdict::Flat;
        }
        let mut margin = 0.0;
        for (k, &(first, count, threshold)) in self.stages.iter().enumerate() {
            let mut sum = 0.0f64;
            for st in &self.stumps[first..first + count] {
                let mut v = st.rects[0].weight * Self::rect(&ii.sum, base, &st.rects[0]) as f32;
                v += st.rects[1].weight * Self::rect(&ii.sum, base, &st.rects[1]) as f32;
                if st.count > 2 && st.rects[2].weight != 0.0 {
                    v += st.rects[2].weight * Self::rect(&ii.sum, base, &st.rects[2]) as f32;
                }
                let value = v * factor;
                sum += f64::from(if value < st.threshold { st.left } else { st.right });
            }
            if sum < threshold {
                return Verdict::Rejected { stage: k };
            }
            margin = sum - threshold;
        }
        Verdict::Accepted { margin }
    }
}

/// Classifies windows of one cascade, with the stump fast path when every tree is a stump.
#[derive(Clone, Debug)]
struct CascadeScan {
    /// The cascade compiled for the strides met last ([`LAYOUTS`] at most), the one in use
    /// first: the images a detector scans change width from frame to frame and scale to
    /// scale, and a large cascade takes about as long to compile as to scan a frame.
    layouts: Vec<Compiled>,
    stumps_only: bool,
}

/// How many compiled layouts a detector keeps.
const LAYOUTS: usize = 8;

impl CascadeScan {
    fn new(cascade: &Cascade) -> Self {
        Self {
            layouts: Vec::new(),
            stumps_only: cascade.max_nodes() == 1,
        }
    }

    /// Makes the layout for `stride` the one in use, compiling it when it is not kept.
    fn prepare(&mut self, cascade: &Cascade, stride: usize) {
        if let Some(k) = self.layouts.iter().position(|c| c.stride == stride) {
            self.layouts[..=k].rotate_right(1);
            return;
        }
        let mut layout = if self.layouts.len() >= LAYOUTS {
            self.layouts.pop().unwrap_or_default()
        } else {
            Compiled::default()
        };
        layout.compile(cascade, stride);
        self.layouts.insert(0, layout);
    }

    #[inline]
    fn classify(&self, cascade: &Cascade, ii: &Integral, x: usize, y: usize) -> Verdict {
        match self.layouts.first() {
            Some(layout) if self.stumps_only && layout.stride == ii.stride => layout.classify(ii, y * ii.stride + x),
            _ => cascade.classify(ii, x, y),
        }
    }
}

/// The raw windows OpenCV 4's `CascadeClassifier::detectMultiScale` finds in `grey` at scale 1
/// (`minSize = maxSize =` the window, `minNeighbors = 0`): top-left corners, in scan order.
pub fn scan_like_opencv(cascade: &Cascade, grey: &GreyImage, out: &mut Vec<(u32, u32)>) {
    out.clear();
    let (w, h) = (cascade.width as usize, cascade.height as usize);
    if grey.width < w || grey.height < h {
        return;
    }
    let mut ii = Integral::default();
    ii.compute(&grey.data, grey.width, grey.height);
    let mut runner = CascadeScan::new(cascade);
    runner.prepare(cascade, ii.stride);
    let step = 2;
    // Corners x with x + w < width + 1.
    let (nx, ny) = (grey.width + 1 - w, grey.height + 1 - h);
    for y in (0..ny).step_by(step) {
        let mut x = 0;
        while x < nx {
            match runner.classify(cascade, &ii, x, y) {
                Verdict::Accepted { .. } => out.push((x as u32, y as u32)),
                Verdict::Rejected { stage: 0 } => x += step,
                _ => {}
            }
            x += step;
        }
    }
}

/// One raw window, in canonical-image pixels.
#[derive(Clone, Copy, Debug, Default)]
struct Raw {
    x: f32,
    y: f32,
    size: f32,
    margin: f32,
}

/// A group of similar raw windows being accumulated.
#[derive(Clone, Copy, Debug, Default)]
struct Group {
    x: f32,
    y: f32,
    size: f32,
    margin: f32,
    count: usize,
}

/// Finds paws in bottom colour frames. Cheap to clone: one per worker thread.
///
/// It converts the region to grey at 1 px/mm, runs the 12x12 window at every pixel (step 1)
/// of that image and of its resamplings for objects 0.8x and 1.25x the window, and groups the
/// raw windows. Single-threaded; after the first frames of a size it does not allocate.
#[derive(Clone, Debug)]
pub struct PawDetector {
    cascade: Cascade,
    runner: CascadeScan,
    scales: Vec<f64>,
    step: usize,
    min_neighbors: usize,
    greyer: Greyer,
    canonical: GreyImage,
    scaled: GreyImage,
    rows: ResampleScratch,
    ii: Integral,
    raw: Vec<Raw>,
    labels: Vec<usize>,
    groups: Vec<Group>,
}

/// The integral images' strides are multiples of this, so that images a few pixels apart in
/// width share a compiled layout ([`CascadeScan::prepare`]).
const STRIDE_STEP: usize = 16;

/// The object scales run by default: paws up to 30 % smaller or larger than the window's.
pub const DEFAULT_SCALES: [f64; 3] = [0.8, 1.0, 1.25];

/// Drops each detection whose centre lies in the box of a surer one: one paw found twice by
/// groups the grouping kept apart (a paw's toes and its heel). Surest first.
pub(super) fn suppress_repeats(found: &mut Vec<PawDetection>) {
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept = 0;
    for i in 0..found.len() {
        let (cx, cy) = found[i].centre();
        let repeat = found[..kept].iter().any(|k| {
            (f64::from(k.x0)..=f64::from(k.x1)).contains(&cx) && (f64::from(k.y0)..=f64::from(k.y1)).contains(&cy)
        });
        if !repeat {
            found.swap(kept, i);
            kept += 1;
        }
    }
    found.truncate(kept);
}

/// The scales (px/mm on the glass) [`PawDetector::find_scale`] searches by default when a view's
/// scale is not told: from a binned camera far away to a close macro view.
pub const FIND_SCALE_RANGE: (f64, f64) = (0.5, 8.0);

/// A frame and the region of it to look in, `(x0, y0, x1, y1)` pixel bounds.
pub type FrameRegion<'a> = (&'a ColorFrame, (u32, u32, u32, u32));

/// Candidate scales per octave that [`PawDetector::find_scale`] tries.
pub const SCALE_STEPS_PER_OCTAVE: u32 = 8;

/// A scale [`PawDetector::find_scale`] found and how sure: the summed scores it chose by.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FoundScale {
    pub px_per_mm: f64,
    pub evidence: f64,
}

/// [`PawDetector::find_scale`] with any detector: `detect` finds paws in a frame's region at
/// a scale. The scale whose detections are surest, their four best scores in each frame (a
/// mouse has four paws) summed over the frames; candidates [`SCALE_STEPS_PER_OCTAVE`] to an
/// octave apart from `lowest` to `highest`. `None` when the range is empty or nothing is
/// detected at any scale.
pub fn find_scale_with(
    frames: &[FrameRegion<'_>],
    lowest: f64,
    highest: f64,
    mut detect: impl FnMut(&ColorFrame, (u32, u32, u32, u32), f64, &mut Vec<PawDetection>),
) -> Option<FoundScale> {
    if !(lowest > 0.0 && highest >= lowest && highest.is_finite()) {
        return None;
    }
    let step = 2f64.powf(1.0 / f64::from(SCALE_STEPS_PER_OCTAVE));
    let mut best: Option<FoundScale> = None;
    let mut found = Vec::new();
    let mut px_per_mm = lowest;
    while px_per_mm <= highest * 1.000_001 {
        let mut evidence = 0.0;
        for &(frame, roi) in frames {
            detect(frame, roi, px_per_mm, &mut found);
            super::keep_surest(&mut found, super::PAWS_PER_VIEW);
            evidence += found.iter().map(|d| f64::from(d.score)).sum::<f64>();
        }
        if evidence > 0.0 && best.is_none_or(|b| evidence > b.evidence) {
            best = Some(FoundScale { px_per_mm, evidence });
        }
        px_per_mm *= step;
    }
    best
}

/// The view's scale (px/mm on the glass) from which a cascade's grouping holds as chosen
/// ([`PawDetector::min_neighbors_at`]): the scale our rendered training views are cut at
/// (`DATASET_PX_PER_MM` of the training data).
pub const GROUPING_FULL_PX_PER_MM: f64 = 2.0;

/// Raw windows a group needs beyond the first to be reported, by default.
pub const DEFAULT_MIN_NEIGHBORS: usize = 1;

impl PawDetector {
    /// Reads an OpenCV cascade XML file.
    ///
    /// # Errors
    /// As [`super::xml::load`].
    pub fn load(path: &Path) -> Result<Self, PawError> {
        Ok(Self::from_cascade(super::xml::load(path)?))
    }

    /// A detector running `cascade` at [`DEFAULT_SCALES`], grouping as the cascade says
    /// ([`Cascade::min_neighbors`]) or else with [`DEFAULT_MIN_NEIGHBORS`].
    pub fn from_cascade(cascade: Cascade) -> Self {
        Self {
            min_neighbors: cascade.min_neighbors.map_or(DEFAULT_MIN_NEIGHBORS, |n| n as usize),
            runner: CascadeScan::new(&cascade),
            cascade,
            scales: DEFAULT_SCALES.to_vec(),
            step: 1,
            greyer: Greyer::default(),
            canonical: GreyImage::default(),
            scaled: GreyImage::default(),
            rows: ResampleScratch::default(),
            ii: Integral::default(),
            raw: Vec::new(),
            labels: Vec::new(),
            groups: Vec::new(),
        }
    }

    /// The cascade it runs.
    pub fn cascade(&self) -> &Cascade {
        &self.cascade
    }

    /// Reports groups of more than `n` raw windows only (OpenCV's `minNeighbors`); 0 keeps
    /// every group.
    pub fn set_min_neighbors(&mut self, n: usize) {
        self.min_neighbors = n;
    }

    /// Groups need more than this many raw windows to be reported.
    pub fn min_neighbors(&self) -> usize {
        self.min_neighbors
    }

    /// The object scales it runs.
    pub fn scales(&self) -> &[f64] {
        &self.scales
    }

    /// The object scales to run, relative to the window at the canonical scale.
    pub fn set_scales(&mut self, scales: &[f64]) {
        self.scales.clear();
        self.scales
            .extend(scales.iter().copied().filter(|s| *s > 0.0 && s.is_finite()));
    }

    /// Detects paws in `frame` within `roi` = (x0, y0, x1, y1) pixel bounds in the frame, the
    /// glass seen at `px_per_mm` pixels per mm. Clears `out`, then pushes the detections, boxes
    /// in the frame's own pixel coordinates, overlapping raw windows grouped (like OpenCV's
    /// groupRectangles), one paw found twice kept once (the surer), `score` higher for surer
    /// detections, surest first.
    ///
    /// The score of a detection is the number of raw windows grouped into it plus
    /// `m / (1 + m)`, `m` their mean margin over the last stage's threshold: whole numbers
    /// count windows, the fraction breaks ties.
    pub fn detect(
        &mut self,
        frame: &ColorFrame,
        roi: (u32, u32, u32, u32),
        px_per_mm: f64,
        out: &mut Vec<PawDetection>,
    ) {
        let min = self.min_neighbors_at(px_per_mm);
        self.detect_grouped(frame, roi, px_per_mm, min, out);
    }

    /// The grouping a view of `px_per_mm` on the glass is searched with: the cascade's own
    /// from [`GROUPING_FULL_PX_PER_MM`] up, and in proportion below it (rounded, never below
    /// the smaller of 1 and the cascade's own): a coarser view's paws are blurred, and fewer
    /// windows take a blurred paw for one (a cascade grouping 7 found 45 % of the paws of
    /// rendered views binned 4x4, 0.5 px/mm, and 93 % grouping 1).
    pub fn min_neighbors_at(&self, px_per_mm: f64) -> usize {
        let share = (px_per_mm / GROUPING_FULL_PX_PER_MM).clamp(0.0, 1.0);
        let scaled = (self.min_neighbors as f64 * share).round() as usize;
        scaled.max(self.min_neighbors.min(1))
    }

    /// [`Self::detect`] with the grouping `min` (raw windows a detection needs beyond the
    /// first).
    fn detect_grouped(
        &mut self,
        frame: &ColorFrame,
        roi: (u32, u32, u32, u32),
        px_per_mm: f64,
        min: usize,
        out: &mut Vec<PawDetection>,
    ) {
        out.clear();
        self.raw.clear();
        let Some(place) = self
            .greyer
            .convert(frame, roi, px_per_mm, CANONICAL_PX_PER_MM, &mut self.canonical)
        else {
            return;
        };
        for k in 0..self.scales.len() {
            let scale = self.scales[k];
            if (scale - 1.0).abs() < 1e-9 {
                self.scan(1.0, false);
            } else {
                resample(&self.canonical, scale, &mut self.scaled, &mut self.rows);
                self.scan(scale, true);
            }
        }
        self.group(place, min, out);
    }

    /// Finds the scale (pixels per millimetre on the glass, between `lowest` and `highest`) at
    /// which the regions of `frames`, taken with one camera, show paws: the scale whose
    /// detections are surest, their four best scores in each frame (a mouse has four paws)
    /// summed over the frames, each scale searched with the cascade's own grouping.
    /// Candidates are [`SCALE_STEPS_PER_OCTAVE`] to an octave apart.
    /// `None` when the range is empty or nothing is detected at any scale.
    pub fn find_scale(&mut self, frames: &[FrameRegion<'_>], lowest: f64, highest: f64) -> Option<FoundScale> {
        let min = self.min_neighbors;
        find_scale_with(frames, lowest, highest, |frame, roi, px_per_mm, out| {
            self.detect_grouped(frame, roi, px_per_mm, min, out);
        })
    }

    /// Scans one image (`scaled` or `canonical`) and appends its accepted windows to `raw`.
    fn scan(&mut self, scale: f64, use_scaled: bool) {
        let img = if use_scaled { &self.scaled } else { &self.canonical };
        let (w, h) = (self.cascade.width as usize, self.cascade.height as usize);
        if img.width < w || img.height < h {
            return;
        }
        let stride = (img.width + 1).next_multiple_of(STRIDE_STEP);
        self.ii.compute_strided(&img.data, img.width, img.height, stride);
        self.runner.prepare(&self.cascade, stride);
        let (nx, ny) = (img.width + 1 - w, img.height + 1 - h);
        let s = scale as f32;
        for y in (0..ny).step_by(self.step) {
            for x in (0..nx).step_by(self.step) {
                if let Verdict::Accepted { margin } = self.runner.classify(&self.cascade, &self.ii, x, y) {
                    self.raw.push(Raw {
                        x: x as f32 * s,
                        y: y as f32 * s,
                        size: w as f32 * s,
                        margin: margin as f32,
                    });
                }
            }
        }
    }

    /// Groups `raw` like OpenCV's `groupRectangles` (eps 0.2) and writes the groups to `out`.
    fn group(&mut self, place: Placement, min: usize, out: &mut Vec<PawDetection>) {
        const EPS: f32 = 0.2;
        let n = self.raw.len();
        self.labels.clear();
        self.labels.extend(0..n);
        fn find(labels: &mut [usize], mut i: usize) -> usize {
            while labels[i] != i {
                labels[i] = labels[labels[i]];
                i = labels[i];
            }
            i
        }
        for i in 0..n {
            for j in i + 1..n {
                let (a, b) = (self.raw[i], self.raw[j]);
                let delta = EPS * (a.size.min(b.size) + a.size.min(b.size)) * 0.5;
                if (a.x - b.x).abs() <= delta
                    && (a.y - b.y).abs() <= delta
                    && (a.x + a.size - b.x - b.size).abs() <= delta
                    && (a.y + a.size - b.y - b.size).abs() <= delta
                {
                    let (ri, rj) = (find(&mut self.labels, i), find(&mut self.labels, j));
                    if ri != rj {
                        self.labels[ri.max(rj)] = ri.min(rj);
                    }
                }
            }
        }
        self.groups.clear();
        self.groups.resize(n, Group::default());
        for i in 0..n {
            let root = find(&mut self.labels, i);
            let r = self.raw[i];
            let g = &mut self.groups[root];
            g.x += r.x;
            g.y += r.y;
            g.size += r.size;
            g.margin += r.margin;
            g.count += 1;
        }
        for g in &mut self.groups {
            if g.count > 0 {
                let c = g.count as f32;
                g.x /= c;
                g.y /= c;
                g.size /= c;
                g.margin /= c;
            }
        }
        // Drop groups inside a much stronger one, as OpenCV does.
        for i in 0..n {
            let a = self.groups[i];
            if a.count == 0 || a.count <= min {
                continue;
            }
            let inside = self.groups.iter().enumerate().any(|(j, b)| {
                let d = (b.size * EPS).round();
                j != i
                    && b.count > min
                    && a.x >= b.x - d
                    && a.y >= b.y - d
                    && a.x + a.size <= b.x + b.size + d
                    && a.y + a.size <= b.y + b.size + d
                    && (b.count > a.count.max(3) || a.count < 3)
            });
            if inside {
                continue;
            }
            let (x0, y0) = place.to_frame(f64::from(a.x), f64::from(a.y));
            let (x1, y1) = place.to_frame(f64::from(a.x + a.size), f64::from(a.y + a.size));
            let m = a.margin.max(0.0);
            out.push(PawDetection {
                x0: x0 as f32,
                y0: y0 as f32,
                x1: x1 as f32,
                y1: y1 as f32,
                score: a.count as f32 + m / (1.0 + m),
            });
        }
        suppress_repeats(out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(x0: f32, y0: f32, size: f32, score: f32) -> PawDetection {
        PawDetection {
            x0,
            y0,
            x1: x0 + size,
            y1: y0 + size,
            score,
        }
    }

    /// A view keeps its surest detections, surest first; 0 keeps every one.
    #[test]
    fn a_view_keeps_its_surest_detections() {
        let mut found = vec![
            det(0.0, 0.0, 12.0, 1.5),
            det(20.0, 0.0, 12.0, 3.5),
            det(40.0, 0.0, 12.0, 2.5),
        ];
        crate::vision::paws::keep_surest(&mut found, 2);
        let scores: Vec<f32> = found.iter().map(|d| d.score).collect();
        assert_eq!(scores, vec![3.5, 2.5]);
        let mut all = vec![det(0.0, 0.0, 12.0, 1.5), det(20.0, 0.0, 12.0, 3.5)];
        crate::vision::paws::keep_surest(&mut all, 0);
        assert_eq!(all.len(), 2, "0 keeps every detection");
    }

    /// A paw found twice (its toes and its heel) is kept once, the surer; paws apart stay.
    #[test]
    fn one_paw_found_twice_is_kept_once() {
        let mut found = vec![
            det(0.0, 0.0, 10.0, 2.5),
            det(4.0, 3.0, 10.0, 5.2),
            det(30.0, 0.0, 10.0, 3.1),
            det(31.0, 9.0, 10.0, 1.2),
        ];
        suppress_repeats(&mut found);
        let scores: Vec<f32> = found.iter().map(|d| d.score).collect();
        assert_eq!(scores, vec![5.2, 3.1, 1.2]);
    }

    /// The grouping is the cascade's own from 2 px/mm up and in proportion below, never below
    /// 1 unless the cascade's own is 0.
    #[test]
    fn a_coarser_view_is_grouped_in_proportion() {
        let mut detector = PawDetector::load(Path::new("fixtures/models/paws.xml")).unwrap();
        detector.set_min_neighbors(7);
        let at: Vec<usize> = [3.5, 2.0, 1.0, 0.5, 0.1]
            .iter()
            .map(|&s| detector.min_neighbors_at(s))
            .collect();
        assert_eq!(at, [7, 7, 4, 2, 1]);
        detector.set_min_neighbors(1);
        assert_eq!(detector.min_neighbors_at(0.5), 1);
        detector.set_min_neighbors(0);
        assert_eq!(detector.min_neighbors_at(3.5), 0);
    }
}
