//! `poses.csv`: one row per frame pair, written as the poses arrive, and a tally of what was
//! written (statuses, pairs, and the error against ground truth when there is one).
//!
//! Columns: `frame, depth_seq, color_seq, host_ns, depth_device_ns, color_device_ns, skew_ns,
//! status`, then per joint in joint order `{name}_x, {name}_y, {name}_z` (mm, world frame),
//! `{name}_score` and `{name}_source` (Anipose's per-joint convention). A joint without an
//! estimate has empty coordinates and score, and source `missing`; a depth-only pair has an
//! empty `color_seq` and `color_device_ns`. The last column, `orientation_confidence`, is how
//! sure the orientation tracker is of which end is the head (0.5 to 1; empty without a mouse).
//! Files written before it was added (without that column) read back too.

use crate::core::pose::{JointPositions, JointSource};
use crate::core::skeleton::{JOINT_COUNT, Joint};
use crate::io::table::Fixed;
use crate::runtime::pipeline::{Sink, StageError};
use crate::runtime::pose_record::{Identity, PoseRecord, PoseStatus};
use crate::runtime::stages::Fused;
use crate::vision::identity::{CONTACT_MM, nearest_mm, nearest_truth};
use crate::vision::orientation::{self, BodyJoints, Orientation};
use nalgebra::Vector2;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;

use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

/// The name of the file.
pub const POSES_FILE: &str = "poses.csv";
/// The main-body joints as each frame alone placed them, before smoothing over time: the same
/// columns as `poses.csv`.
pub const RAW_POSES_FILE: &str = "poses_raw.csv";

/// The file of the poses predicted ahead ([`PoseWriter::with_predicted_file`]).
pub const PREDICTED_POSES_FILE: &str = "poses_predicted.csv";

/// The directory the pictures of `--overlays` go to, one PNG per pictured frame named by its
/// depth sequence number.
pub const OVERLAYS_DIR: &str = "overlays";

/// The header line of `poses.csv`.
pub fn header() -> String {
    columns(true, false).join(",")
}

/// The header line of `poses.csv` of `mice` mice (that of [`header`] for one).
pub fn header_for(mice: usize) -> String {
    columns(true, mice > 1).join(",")
}

/// The last column's name.
const ORIENTATION_COLUMN: &str = "orientation_confidence";
/// With several mice: the column of the mouse's number, and of how sure it is.
const MOUSE_COLUMN: &str = "mouse";
const IDENTITY_COLUMN: &str = "identity_confidence";

/// The columns of `poses.csv`; without `orientation`, those of files written before the
/// orientation column was added; with `several` (mice), the mouse's number after the pair's
/// columns and how sure it is after the status.
fn columns(orientation: bool, several: bool) -> Vec<String> {
    let mut columns: Vec<String> = [
        "frame",
        "depth_seq",
        "color_seq",
        "host_ns",
        "depth_device_ns",
        "color_device_ns",
        "skew_ns",
    ]
    .map(str::to_owned)
    .into();
    if several {
        columns.push(MOUSE_COLUMN.to_owned());
    }
    columns.push("status".to_owned());
    if several {
        columns.push(IDENTITY_COLUMN.to_owned());
    }
    for joint in Joint::ALL {
        for col in ["x", "y", "z", "score", "source"] {
            columns.push(format!("{}_{col}", joint.name()));
        }
    }
    if orientation {
        columns.push(ORIENTATION_COLUMN.to_owned());
    }
    columns
}

/// How often the head's end was wrong, against the truth: of the tracker's output, of each
/// frame's own evidence, and of the body forest alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct OrientationCheck {
    /// Frames with a mouse, the truth and a heading.
    pub frames: u64,
    /// Frames whose heading (tail base to neck, seen from above) points more than 90 degrees
    /// away from the truth's.
    pub flipped_tracked: u64,
    pub flipped_frame_alone: u64,
    pub flipped_forest: u64,
    /// Of the frames where the body-shape model said anything (`shape_frames`), how many its
    /// choice alone would have swapped.
    pub shape_frames: u64,
    pub flipped_shape: u64,
    /// Of the frames where a visible tail was seen (`tail_frames`), how many its end alone
    /// would have swapped.
    pub tail_frames: u64,
    pub flipped_tail: u64,
    /// Mean angle (degrees) between the tracked heading and the truth's, over frames not flipped.
    pub heading_error_deg: f64,
}

impl OrientationCheck {
    /// Counts one frame: the true heading and the three estimated ones.
    fn count(&mut self, truth: Vector2<f64>, tracked: Option<Vector2<f64>>, orientation: &Orientation) {
        let Some(tracked) = tracked else { return };
        let flipped = |v: Option<Vector2<f64>>| v.is_none_or(|v| v.dot(&truth) < 0.0);
        let not_flipped = self.frames - self.flipped_tracked;
        self.frames += 1;
        if flipped(Some(tracked)) {
            self.flipped_tracked += 1;
        } else {
            let angle = tracked.angle(&truth).to_degrees();
            self.heading_error_deg += (angle - self.heading_error_deg) / (not_flipped + 1) as f64;
        }
        self.flipped_frame_alone += u64::from(flipped(orientation.frame_alone));
        self.flipped_forest += u64::from(flipped(orientation.forest));
        if orientation.shape.is_some() {
            self.shape_frames += 1;
            self.flipped_shape += u64::from(flipped(orientation.shape));
        }
        if orientation.tail.is_some() {
            self.tail_frames += 1;
            self.flipped_tail += u64::from(flipped(orientation.tail));
        }
    }
}

/// What the sink has written.
#[derive(Clone, Debug, Default)]
pub struct PoseTally {
    pub rows: u64,
    pub statuses: BTreeMap<&'static str, u64>,
    /// `(depth_seq, color_seq)` of every row, in order, when there is ground truth to check
    /// the pairing against (otherwise nothing grows with the session's length).
    pub pairs: Vec<(u64, Option<u64>)>,
    /// Per joint: summed error (mm) and count, over rows with truth and an estimate.
    pub error_sum_mm: [f64; JOINT_COUNT],
    pub error_count: [u64; JOINT_COUNT],
    /// Summed error (mm) and count of the paws placed from a detection.
    pub detected_paw_error: (f64, u64),
    /// Summed error (mm) and count of joints 1-12 before smoothing over time.
    pub raw_body_error: (f64, u64),
    /// The first pose with a mouse at or after the snapshot row (for a picture).
    pub snapshot: Option<PoseRecord>,
    /// Flipped headings against the truth (frames without truth are not counted).
    pub orientation: OrientationCheck,
    /// In how many frames a tail was seen, truth or not.
    pub tails: TailsSeen,
    /// With several mice, each one's own tally, mouse 1's first (`rows` there counts its
    /// rows); empty with one. The fields above count every mouse's rows but `rows` and
    /// `pairs`, which count pairs.
    pub mice: Vec<MouseTally>,
    /// With several mice, the frames that could have swapped two of them: `(depth_seq, a, b)`.
    pub possible_swaps: Vec<(u64, usize, usize)>,
    /// With several mice, the pairs whose depth frame showed more mouse-sized things than mice.
    pub more_mice_seen: u64,
}

/// What was written of one of several mice.
#[derive(Clone, Debug, Default)]
pub struct MouseTally {
    /// Its rows' statuses and errors, each row's against the true mouse nearest it.
    pub rows: PoseTally,
    /// How often the true mouse its number follows changed (in frames where each mouse found
    /// was nearest a true mouse of its own): identity swaps, where there is truth.
    pub identity_swaps: u64,
    /// Times it came into contact with another mouse ([`CONTACT_MM`]).
    pub contacts: u64,
    following: Option<usize>,
    touching: bool,
}

/// In how many of the frames whose head's end the tracker chose a visible tail was found
/// (`vision::tail`), on any recording, with ground truth or not.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct TailsSeen {
    /// Frames with a mouse and a heading chosen.
    pub frames: u64,
    /// Of those, the frames where a tail was seen.
    pub seen: u64,
}

impl PoseTally {
    /// Counts one row of a mouse, `truth` its true joints when known (the rows themselves,
    /// pairs and the snapshot are the writer's).
    fn count(&mut self, r: &PoseRecord, truth: Option<&JointPositions>) {
        if let (Some(t), Some(raw)) = (truth, &r.raw_body) {
            for (j, t) in raw
                .iter()
                .zip(t.iter())
                .filter(|(j, _)| j.source != JointSource::Missing)
            {
                self.raw_body_error.0 += (j.position_mm - t).norm();
                self.raw_body_error.1 += 1;
            }
        }
        for (k, j) in r.pose.joints.iter().enumerate() {
            let Some(t) = truth
                .and_then(|t| t.get(k))
                .filter(|_| j.source != JointSource::Missing)
            else {
                continue;
            };
            let e = (j.position_mm - t).norm();
            self.error_sum_mm[k] += e;
            self.error_count[k] += 1;
            if j.source == JointSource::Paw {
                self.detected_paw_error.0 += e;
                self.detected_paw_error.1 += 1;
            }
        }
        if let Some(o) = &r.orientation {
            self.tails.frames += 1;
            self.tails.seen += u64::from(o.tail.is_some());
        }
        if let (Some(o), Some(t)) = (&r.orientation, truth) {
            let body: BodyJoints = std::array::from_fn(|k| r.pose.joints[k]);
            if let Some(true_heading) =
                orientation::heading_between(&t[Joint::Neck.index()], &t[Joint::TailBase.index()])
            {
                self.orientation.count(true_heading, orientation::heading(&body), o);
            }
        }
        *self.statuses.entry(r.status.name()).or_default() += 1;
    }

    /// Counts one pair's rows of several mice (`records`, in the order of their numbers),
    /// `truth` the true joints of each mouse in the cage (empty without truth): each row
    /// against the true mouse nearest it, identity swaps, contacts and possible swaps.
    fn mice_frame<'a>(&mut self, records: impl Iterator<Item = &'a PoseRecord>, truth: &[JointPositions]) {
        let records: Vec<&PoseRecord> = records.collect();
        if self.mice.len() < records.len() {
            self.mice.resize_with(records.len(), MouseTally::default);
        }
        let nearest: Vec<Option<usize>> = records.iter().map(|r| nearest_truth(&r.pose, truth)).collect();
        self.more_mice_seen += u64::from(records.first().and_then(|r| r.identity).is_some_and(|i| i.beyond > 0));
        for ((r, t), mouse) in records.iter().zip(&nearest).zip(&mut self.mice) {
            let t = t.map(|t| &truth[t]);
            mouse.rows.count(r, t);
            mouse.rows.rows += 1;
        }
        for (r, t) in records.iter().zip(&nearest) {
            self.count(r, t.map(|t| &truth[t]));
        }
        // A swap shows where every mouse found follows a true mouse of its own.
        let followed: Vec<usize> = nearest.iter().flatten().copied().collect();
        let distinct = followed.iter().enumerate().all(|(i, t)| !followed[..i].contains(t));
        if followed.len() >= 2 && distinct {
            for (mouse, t) in self.mice.iter_mut().zip(&nearest) {
                if let Some(t) = *t {
                    mouse.identity_swaps += u64::from(mouse.following.is_some_and(|f| f != t));
                    mouse.following = Some(t);
                }
            }
        }
        for (k, r) in records.iter().enumerate() {
            let touching = records
                .iter()
                .enumerate()
                .any(|(j, other)| j != k && nearest_mm(&r.pose, &other.pose).is_some_and(|d| d < CONTACT_MM));
            let mouse = &mut self.mice[k];
            mouse.contacts += u64::from(touching && !mouse.touching);
            mouse.touching = touching;
            if let Some(Identity {
                mouse: a,
                swap_with: Some(b),
                ..
            }) = r.identity
            {
                if a < b {
                    self.possible_swaps.push((r.depth.seq, a, b));
                }
            }
        }
    }

    /// Mean error per joint (mm), for joints that were ever compared.
    pub fn per_joint_error_mm(&self) -> BTreeMap<&'static str, f64> {
        Joint::ALL
            .iter()
            .filter(|j| self.error_count[j.index()] > 0)
            .map(|j| {
                (
                    j.name(),
                    self.error_sum_mm[j.index()] / self.error_count[j.index()] as f64,
                )
            })
            .collect()
    }

    /// Mean error per group of joints: `body` (1-12), `limbs` (13-20), `paws` (21-24),
    /// `detected_paws` (paws placed from a detection in the bottom view), and `body_raw` (1-12
    /// before smoothing over time).
    pub fn group_error_mm(&self) -> BTreeMap<&'static str, f64> {
        let mean = |sum: f64, count: u64| (count > 0).then(|| sum / count as f64);
        let group = |joints: std::ops::Range<usize>| {
            let (sum, count) = joints.fold((0.0, 0), |(s, c), k| {
                (s + self.error_sum_mm[k], c + self.error_count[k])
            });
            mean(sum, count)
        };
        [
            ("body", group(0..12)),
            ("body_raw", mean(self.raw_body_error.0, self.raw_body_error.1)),
            ("limbs", group(12..20)),
            ("paws", group(20..24)),
            (
                "detected_paws",
                mean(self.detected_paw_error.0, self.detected_paw_error.1),
            ),
        ]
        .into_iter()
        .filter_map(|(name, v)| v.map(|v| (name, v)))
        .collect()
    }

    /// Mean of the per-joint errors, `None` without any.
    pub fn mean_error_mm(&self) -> Option<f64> {
        let per = self.per_joint_error_mm();
        (!per.is_empty()).then(|| per.values().sum::<f64>() / per.len() as f64)
    }
}

/// One row of `poses.csv` as the csv crate writes it: numbers with the decimals they have
/// always had, empty cells for what is unknown.
struct PoseRow<'a> {
    frame: u64,
    record: &'a PoseRecord,
    /// Whether the file has the columns of several mice.
    several: bool,
}

impl serde::Serialize for PoseRow<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple as _;
        let r = self.record;
        let mut row = serializer.serialize_tuple(8 + 5 * JOINT_COUNT + 1 + 2 * usize::from(self.several))?;
        row.serialize_element(&self.frame)?;
        row.serialize_element(&r.depth.seq)?;
        row.serialize_element(&r.color.map(|c| c.seq))?;
        row.serialize_element(&r.depth.host_ns)?;
        row.serialize_element(&r.depth.device_ns)?;
        row.serialize_element(&r.color.map(|c| c.device_ns))?;
        row.serialize_element(&r.skew_ns)?;
        if self.several {
            row.serialize_element(&r.identity.map(|i| i.mouse))?;
        }
        row.serialize_element(r.status.name())?;
        if self.several {
            row.serialize_element(&r.identity.map(|i| Fixed::<3>(i.confidence)))?;
        }
        for j in &r.pose.joints {
            let known = (j.source != JointSource::Missing).then_some(j);
            let p = known.map(|j| j.position_mm);
            row.serialize_element(&p.map(|p| Fixed::<2>(p.x)))?;
            row.serialize_element(&p.map(|p| Fixed::<2>(p.y)))?;
            row.serialize_element(&p.map(|p| Fixed::<2>(p.z)))?;
            row.serialize_element(&known.map(|j| Fixed::<3>(j.score)))?;
            row.serialize_element(j.source.name())?;
        }
        row.serialize_element(&r.orientation.as_ref().map(|o| Fixed::<3>(o.confidence)))?;
        row.end()
    }
}

/// Which pose a file beside `poses.csv` holds, in the same rows and columns.
#[derive(Clone, Copy, Debug)]
enum Beside {
    /// The main-body joints before smoothing (`poses_raw.csv`).
    Raw,
    /// The pose predicted this long after the depth frame (`poses_predicted.csv`).
    Predicted { lead_s: f64 },
}

impl Beside {
    /// `record` with this file's pose in it.
    fn of(self, record: &PoseRecord) -> PoseRecord {
        let mut out = record.clone();
        match self {
            Beside::Raw => {
                for (j, estimate) in out
                    .pose
                    .joints
                    .iter_mut()
                    .zip(record.raw_body.iter().flat_map(|b| b.iter()))
                {
                    *j = *estimate;
                }
            }
            Beside::Predicted { lead_s } => out.pose = record.predicted(lead_s),
        }
        out
    }
}

/// Writes `poses.csv` and keeps the tally.
#[derive(Debug)]
pub struct PoseWriter {
    out: csv::Writer<RowFile>,
    /// `poses_raw.csv` and `poses_predicted.csv`, when asked for
    /// ([`PoseWriter::with_raw_file`], [`PoseWriter::with_predicted_file`]).
    beside: Vec<(Beside, csv::Writer<File>)>,
    dir: std::path::PathBuf,
    /// Per depth sequence number, the true joints of each mouse in the cage (mouse 1's first).
    truth: HashMap<u64, Vec<JointPositions>>,
    snapshot_row: u64,
    /// Whether the file has the columns of several mice.
    several: bool,
    tally: Arc<Mutex<PoseTally>>,
    /// When each row is handed to the operating system as it is written
    /// ([`PoseWriter::handing_over_each_row`]): the file's length after its last whole row.
    whole_len: Option<u64>,
}

/// `poses.csv` under its CSV writer: the file, until a row cut by a write error has been cut
/// off it again; from then on nowhere, so that what the writer still holds of that row never
/// reaches the file (dropping a CSV writer flushes it) and the file keeps whole rows only.
#[derive(Debug)]
struct RowFile {
    file: File,
    cut: std::sync::atomic::AtomicBool,
}

impl std::io::Write for RowFile {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        if self.cut.load(std::sync::atomic::Ordering::Relaxed) {
            Ok(bytes.len())
        } else {
            self.file.write(bytes)
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if self.cut.load(std::sync::atomic::Ordering::Relaxed) {
            Ok(())
        } else {
            self.file.flush()
        }
    }
}

impl PoseWriter {
    /// Creates `dir/poses.csv` for `mice` mice and writes the header. `truth` maps depth
    /// sequence numbers to the true joints of each mouse (empty for recorded sessions).
    ///
    /// # Errors
    /// The file cannot be created or written.
    /// The tally keeps the first pose with a mouse from row `snapshot_row` on.
    pub fn create(
        dir: &Path,
        truth: HashMap<u64, Vec<JointPositions>>,
        snapshot_row: u64,
        mice: usize,
    ) -> std::io::Result<Self> {
        let several = mice > 1;
        let mut out = csv::Writer::from_writer(RowFile {
            file: File::create(dir.join(POSES_FILE))?,
            cut: std::sync::atomic::AtomicBool::new(false),
        });
        out.write_record(columns(true, several))?;
        Ok(Self {
            out,
            beside: Vec::new(),
            dir: dir.to_owned(),
            truth,
            snapshot_row,
            several,
            tally: Arc::default(),
            whole_len: None,
        })
    }

    /// Also writes `dir/poses_raw.csv`: the same rows with the main-body joints before
    /// smoothing over time.
    ///
    /// # Errors
    /// The file cannot be created or its header written.
    pub fn with_raw_file(self) -> std::io::Result<Self> {
        self.with_beside(Beside::Raw, RAW_POSES_FILE)
    }

    /// Also writes `dir/poses_predicted.csv`: the same rows with the pose predicted `lead_s`
    /// seconds after each depth frame ([`PoseRecord::predicted`]).
    ///
    /// # Errors
    /// The file cannot be created or its header written.
    pub fn with_predicted_file(self, lead_s: f64) -> std::io::Result<Self> {
        self.with_beside(Beside::Predicted { lead_s }, PREDICTED_POSES_FILE)
    }

    fn with_beside(mut self, which: Beside, name: &str) -> std::io::Result<Self> {
        let mut out = csv::Writer::from_writer(File::create(self.dir.join(name))?);
        out.write_record(columns(true, self.several))?;
        self.beside.push((which, out));
        Ok(self)
    }

    /// Hands each row to the operating system as it is written (a live run's rows, which a
    /// process killed next must not lose), and counts it only then: a row cut by a write error
    /// (a full disk) is cut off the file again, so that the file holds whole rows only and the
    /// tally counts exactly those. `poses_raw.csv`'s rows are handed over too, each before
    /// its row of `poses.csv` (after a write error it may hold a row, or part of one,
    /// that `poses.csv` does not).
    ///
    /// # Errors
    /// The header cannot be written.
    pub fn handing_over_each_row(mut self) -> std::io::Result<Self> {
        use std::io::Seek as _;
        self.out.flush()?;
        self.whole_len = Some((&self.out.get_ref().file).stream_position()?);
        Ok(self)
    }

    /// Whether `poses.csv` was removed while being written ([`crate::io::unlinked`]): its rows
    /// are lost.
    pub fn removed(&self) -> bool {
        crate::io::unlinked(&self.out.get_ref().file)
    }

    /// Whether `poses.csv` was removed or moved away while being written
    /// ([`crate::io::gone`]).
    pub fn gone(&self) -> Option<crate::io::Gone> {
        crate::io::gone(&self.out.get_ref().file, &self.dir.join(POSES_FILE))
    }

    /// Writes one row of pair `frame`: to the files beside first, so that a row one cannot
    /// take is not written to `poses.csv` either, whose rows the tally counts.
    fn write_row(&mut self, frame: u64, record: &PoseRecord) -> Result<(), StageError> {
        let several = self.several;
        for (which, out) in &mut self.beside {
            out.serialize(PoseRow {
                frame,
                record: &which.of(record),
                several,
            })?;
            if self.whole_len.is_some() {
                out.flush()?;
            }
        }
        self.out.serialize(PoseRow { frame, record, several })?;
        if self.whole_len.is_some() {
            self.out.flush().map_err(|e| self.cut_back(e))?;
        }
        Ok(())
    }

    /// After a write error, while each row is handed over: cuts `poses.csv` back to its last
    /// whole pair's rows, and returns the error to report.
    fn cut_back(&self, error: std::io::Error) -> StageError {
        if let Some(len) = self.whole_len {
            // Best effort: the error to report is the write's. What the writer still holds
            // of the row goes nowhere (dropping it would flush it).
            let _ = self.out.get_ref().file.set_len(len);
            self.out.get_ref().cut.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        error.into()
    }

    /// The tally, readable while and after the writer runs.
    pub fn tally(&self) -> Arc<Mutex<PoseTally>> {
        Arc::clone(&self.tally)
    }
}

impl Sink for PoseWriter {
    type In = Fused;

    fn write(&mut self, item: Fused) -> Result<(), StageError> {
        let Fused {
            record: r,
            others,
            overlay,
            ..
        } = item;
        if let Some(picture) = overlay {
            let dir = self.dir.join(OVERLAYS_DIR);
            std::fs::create_dir_all(&dir)?;
            picture.write_png(&dir.join(format!("{:06}.png", r.depth.seq)))?;
        }
        // Only this writer changes the tally: it is locked once the rows are written.
        let frame = self.tally.lock().unwrap_or_else(PoisonError::into_inner).rows;
        for record in std::iter::once(&r).chain(&others) {
            self.write_row(frame, record)?;
        }
        if self.whole_len.is_some() {
            use std::io::Seek as _;
            let end = (&self.out.get_ref().file)
                .stream_position()
                .map_err(|e| self.cut_back(e))?;
            self.whole_len = Some(end);
        }
        let mut tally = self.tally.lock().unwrap_or_else(PoisonError::into_inner);
        let truth = self.truth.get(&r.depth.seq).map(Vec::as_slice).unwrap_or_default();
        if self.several {
            tally.mice_frame(std::iter::once(&r).chain(&others), truth);
        } else {
            tally.count(&r, truth.first());
        }
        tally.rows += 1;
        if !self.truth.is_empty() {
            tally.pairs.push((r.depth.seq, r.color.map(|c| c.seq)));
        }
        if tally.snapshot.is_none() && tally.rows > self.snapshot_row && r.status == PoseStatus::Ok {
            tally.snapshot = Some(r);
        }
        drop(tally);
        Ok(())
    }

    fn flush(&mut self) -> Result<(), StageError> {
        for (_, out) in &mut self.beside {
            out.flush()?;
        }
        self.out.flush()?;
        self.out.get_ref().file.sync_all()?;
        Ok(())
    }
}

/// What is wrong with a `poses.csv` being read back.
#[derive(Debug, thiserror::Error)]
pub enum PosesReadError {
    #[error("cannot read {path:?}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path:?} does not start with the header of poses.csv")]
    Header { path: std::path::PathBuf },
    #[error("{path:?} holds several mice (replay --mice): this reads one mouse's poses.csv so far")]
    SeveralMice { path: std::path::PathBuf },
    #[error("{path:?} line {line}: {what}")]
    Row {
        path: std::path::PathBuf,
        line: usize,
        what: String,
    },
}

/// A `poses.csv`'s header (`None` when its first line does not read) and its rows after it.
fn rows_of(path: &Path) -> Result<(Option<csv::StringRecord>, PoseRecords), PosesReadError> {
    let file = File::open(path).map_err(|source| PosesReadError::Io {
        path: path.to_owned(),
        source,
    })?;
    let mut records = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_reader(std::io::BufReader::new(file))
        .into_records();
    let header = records.next().and_then(Result::ok);
    Ok((header, records))
}

/// The rows of a `poses.csv` as the csv crate reads them.
type PoseRecords = csv::StringRecordsIntoIter<std::io::BufReader<File>>;

/// How many mice a `poses.csv` is of: 1 without the `mouse` column, else the rows of its
/// first pair.
///
/// # Errors
/// The file cannot be read, or its header is not that of `poses.csv`.
pub fn mice_in(path: &Path) -> Result<usize, PosesReadError> {
    let io = |source| PosesReadError::Io {
        path: path.to_owned(),
        source,
    };
    let (header, rows) = rows_of(path)?;
    let Some(header) = header.filter(|h| h.get(0) == Some("frame")) else {
        return Err(PosesReadError::Header { path: path.to_owned() });
    };
    if !header.iter().any(|c| c == MOUSE_COLUMN) {
        return Ok(1);
    }
    let mut first = None;
    let mut mice = 0;
    for row in rows {
        let row = row.map_err(|e| io(e.into()))?;
        let frame = row.get(0).unwrap_or_default().to_owned();
        if first.get_or_insert_with(|| frame.clone()) != &frame {
            break;
        }
        mice += 1;
    }
    Ok(mice.max(1))
}

/// Reads a `poses.csv` back into pose records, in row order (the colour stamp's host time,
/// which the file does not hold, reads as 0; `paws` is empty).
///
/// # Errors
/// The file cannot be read, its header is not this version's, or a row does not parse.
pub fn read_poses(path: &Path) -> Result<Vec<PoseRecord>, PosesReadError> {
    PosesRows::open(path)?.collect()
}

/// The rows of a `poses.csv` read one at a time, as [`read_poses`] reads them all (a long
/// run's file is never held in memory).
pub struct PosesRows {
    records: PoseRecords,
    orientation: bool,
    path: std::path::PathBuf,
}

impl PosesRows {
    /// Opens `path` and reads its header.
    ///
    /// # Errors
    /// The file cannot be read, or its header is not this version's.
    pub fn open(path: &Path) -> Result<Self, PosesReadError> {
        let (header, records) = rows_of(path)?;
        let is = |orientation: bool| {
            header
                .as_ref()
                .is_some_and(|h| h.iter().eq(columns(orientation, false).iter()))
        };
        let orientation = if is(true) {
            true
        } else if is(false) {
            false
        } else if header.as_ref().is_some_and(|h| h.iter().eq(columns(true, true).iter())) {
            return Err(PosesReadError::SeveralMice { path: path.to_owned() });
        } else {
            return Err(PosesReadError::Header { path: path.to_owned() });
        };
        Ok(Self {
            records,
            orientation,
            path: path.to_owned(),
        })
    }
}

impl std::fmt::Debug for PosesRows {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PosesRows")
            .field("path", &self.path)
            .field("orientation", &self.orientation)
            .finish_non_exhaustive()
    }
}

impl Iterator for PosesRows {
    type Item = Result<PoseRecord, PosesReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        let record = self.records.next()?;
        let path = &self.path;
        let line = |e: &csv::Error| e.position().map_or(0, csv::Position::line);
        Some(
            record
                .map_err(|e| PosesReadError::Row {
                    path: path.clone(),
                    line: line(&e) as usize,
                    what: e.to_string(),
                })
                .and_then(|record| {
                    parse_row(&record, self.orientation).map_err(|what| PosesReadError::Row {
                        path: path.clone(),
                        line: record.position().map_or(0, csv::Position::line) as usize,
                        what,
                    })
                }),
        )
    }
}

/// One row of `poses.csv`; `orientation`: whether the file has the orientation column.
fn parse_row(record: &csv::StringRecord, orientation: bool) -> Result<PoseRecord, String> {
    use crate::core::frame::Stamp;
    use crate::core::pose::{JointEstimate, Pose};
    let expected = 8 + 5 * JOINT_COUNT + usize::from(orientation);
    if record.len() != expected {
        return Err(format!("{} columns, expected {expected}", record.len()));
    }
    let field = |i: usize| record.get(i).unwrap_or_default();
    let int = |i: usize| -> Result<Option<i64>, String> {
        let f = field(i);
        if f.is_empty() {
            return Ok(None);
        }
        f.parse().map(Some).map_err(|_| format!("{f:?} is not a whole number"))
    };
    let unsigned = |i: usize| -> Result<Option<u64>, String> {
        int(i)?
            .map(|v| u64::try_from(v).map_err(|_| format!("{v} is negative")))
            .transpose()
    };
    let need = |v: Option<u64>, what: &str| v.ok_or_else(|| format!("no {what}"));
    let depth = Stamp {
        seq: need(unsigned(1)?, "depth_seq")?,
        host_ns: need(unsigned(3)?, "host_ns")?,
        device_ns: need(unsigned(4)?, "depth_device_ns")?,
    };
    let color = match (unsigned(2)?, unsigned(5)?) {
        (Some(seq), Some(device_ns)) => Some(Stamp {
            seq,
            device_ns,
            host_ns: 0,
        }),
        (None, None) => None,
        _ => return Err("color_seq and color_device_ns must both be there or both be empty".to_owned()),
    };
    let status = PoseStatus::from_name(field(7)).ok_or_else(|| format!("unknown status {:?}", field(7)))?;
    let mut pose = Pose::default();
    for (k, joint) in pose.joints.iter_mut().enumerate() {
        let base = 8 + 5 * k;
        let source_text = field(base + 4);
        let source =
            JointSource::from_name(source_text).ok_or_else(|| format!("unknown joint source {source_text:?}"))?;
        if source == JointSource::Missing {
            continue;
        }
        let num = |i: usize| -> Result<f64, String> {
            let f = field(i);
            f.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{f:?} is not a number"))
        };
        *joint = JointEstimate {
            position_mm: nalgebra::Point3::new(num(base)?, num(base + 1)?, num(base + 2)?),
            score: num(base + 3)?,
            source,
        };
    }
    let confidence = match field(8 + 5 * JOINT_COUNT) {
        "" => None,
        f => Some(
            f.parse::<f64>()
                .ok()
                .filter(|v| (0.0..=1.0).contains(v))
                .ok_or_else(|| format!("{f:?} is not an orientation confidence (0 to 1)"))?,
        ),
    };
    Ok(PoseRecord {
        depth,
        color,
        skew_ns: int(6)?.unwrap_or(0),
        status,
        pose,
        paws: Vec::new(),
        headings: None,
        orientation: confidence.map(|confidence| Orientation {
            confidence,
            frame_alone: None,
            forest: None,
            shape: None,
            tail: None,
        }),
        raw_body: None,
        velocities: None,
        identity: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of a frame without a mouse: every joint missing.
    fn empty_row(seq: u64) -> String {
        let mut row = format!("{seq},{seq},,{},{},,0,no_mouse", 1000 + seq, 2000 + seq);
        for _ in 0..JOINT_COUNT {
            row.push_str(",,,,,missing");
        }
        row
    }

    #[test]
    fn files_with_and_without_the_orientation_column_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let old = dir.path().join("old.csv");
        std::fs::write(&old, format!("{}\n{}\n", columns(false, false).join(","), empty_row(3))).unwrap();
        let rows = read_poses(&old).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].depth.seq, 3);
        assert_eq!(rows[0].orientation, None);

        let new = dir.path().join("new.csv");
        let text = format!("{}\n{},\n{},0.875\n", header(), empty_row(4), empty_row(5));
        std::fs::write(&new, text).unwrap();
        let rows = read_poses(&new).unwrap();
        assert_eq!(rows[0].orientation, None);
        assert_eq!(rows[1].orientation.map(|o| o.confidence), Some(0.875));

        // A confidence out of its range, or an old row under the new header, is refused.
        std::fs::write(&new, format!("{}\n{},1.5\n", header(), empty_row(6))).unwrap();
        assert!(read_poses(&new).is_err());
        std::fs::write(&new, format!("{}\n{}\n", header(), empty_row(6))).unwrap();
        assert!(read_poses(&new).is_err());
    }
}
