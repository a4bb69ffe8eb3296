//! The engine of `mousepose export nwb RUN --out FILE.nwb`: a run's poses as NWB 2.x with the ndx-pose
//! extension (a `PoseEstimation` of 24 `PoseEstimationSeries`, one per joint, with the
//! skeleton's edges, the cameras as devices, the software version and models), written by
//! the ecosystem's own library: `pynwb` and `ndx-pose` in the Python environment that
//! `scripts/nwb-env` makes (`/opt/mousepose/venv`, or `--python`/`$MOUSEPOSE_PYTHON`; the
//! package installs the script as `/usr/share/mousepose/nwb-env`, `scripts/setup.sh` runs it).
//!
//! mousepose writes the metadata as JSON beside a copy of the helper script (`nwb.py`, built
//! into the binary) in a temporary directory and runs it on the run's `poses.csv`; the file
//! is written under a hidden name and renamed into place when the helper succeeds.

use crate::core::skeleton::{BONES, Joint};
use crate::engine::Failure;
use crate::engine::export::{Run, check_file_out};
use crate::engine::progress::Progress;
use crate::io::session::{CameraMeta, SessionReader};
use crate::runtime::sink::poses::{POSES_FILE, mice_in};
use crate::vision::calibrate::{CameraCalibration, RigCalibration};
use anyhow::Context as _;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The helper, run with the environment's Python.
const HELPER: &str = include_str!("../../../python/nwb.py");
pub use crate::engine::DEFAULT_PYTHON;
use crate::engine::project_python;

/// What `export nwb` writes, from what (see its `--help`; the subject's fields are checked
/// by [`check_subject`]).
#[derive(Clone, Debug)]
pub struct NwbOptions {
    /// The run: a replay's output directory (or a daemon's chunk).
    pub run: PathBuf,
    /// The NWB file to write.
    pub out: PathBuf,
    /// The session the run was made from, when its summary does not name it.
    pub session: Option<PathBuf>,
    pub subject_id: String,
    pub species: String,
    pub sex: String,
    pub age: Option<String>,
    pub date_of_birth: Option<String>,
    pub strain: Option<String>,
    pub genotype: Option<String>,
    pub weight: Option<String>,
    pub subject_description: Option<String>,
    pub session_description: String,
    pub experimenter: Vec<String>,
    pub lab: Option<String>,
    pub institution: Option<String>,
    /// The video the poses were estimated from, linked from the PoseEstimation.
    pub source_video: Option<PathBuf>,
    /// The video with the poses drawn, linked as the labelled video.
    pub labeled_video: Option<PathBuf>,
    /// The Python with pynwb and ndx-pose (default: $MOUSEPOSE_PYTHON, else [`DEFAULT_PYTHON`]).
    pub python: Option<PathBuf>,
    /// Replace the file if it exists.
    pub force: bool,
    /// A run of several mice: a file per mouse (`OUT`'s name with `_mouse1`, ... before its
    /// extension) instead of one holding them all.
    pub per_mouse: bool,
}

/// What `export nwb` wrote.
#[derive(Clone, Debug)]
pub struct NwbSummary {
    /// The files written: one, or one per mouse (`--per-mouse`).
    pub out: Vec<PathBuf>,
    /// Rows of `poses.csv`.
    pub rows: usize,
    /// Pose series (one per joint).
    pub series: usize,
    pub subject_id: String,
    /// What DANDI will refuse in the file (also said on stderr).
    pub warnings: Vec<String>,
}

#[derive(Debug, Serialize)]
struct Device {
    name: String,
    description: String,
    /// The camera's serial number (`None` when the driver gave none).
    serial_number: Option<String>,
    /// The camera's model (an NWB `DeviceModel`, shared by cameras of one model).
    model: String,
    manufacturer: String,
    firmware: String,
    /// The camera's calibration, when the run has one.
    calibration: Option<Calibration>,
}

/// One camera's calibration as ndx-pose's `CalibratedCamera` holds it: OpenCV's convention,
/// `p_camera = R · p_world + t` (world millimetres), pixels with centres at integers.
#[derive(Debug, Serialize)]
struct Calibration {
    intrinsic_matrix: [[f64; 3]; 3],
    rotation_matrix: [[f64; 3]; 3],
    translation_vector: [f64; 3],
    distortion_coefficients: [f64; 5],
}

impl Calibration {
    fn of(c: &CameraCalibration) -> Self {
        let i = &c.intrinsics;
        let camera_from_world = c.world_from_camera.inverse();
        let r = camera_from_world.rotation.to_rotation_matrix();
        let t = camera_from_world.translation.vector;
        Self {
            intrinsic_matrix: [[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]],
            rotation_matrix: std::array::from_fn(|row| std::array::from_fn(|col| r[(row, col)])),
            translation_vector: [t.x, t.y, t.z],
            distortion_coefficients: i.distortion,
        }
    }
}

/// A video to link: its path and where its first frame falls on the poses' time axis, s.
#[derive(Debug, Serialize)]
struct Video {
    path: PathBuf,
    start_s: f64,
}

#[derive(Debug, Default, Serialize)]
struct Videos {
    source: Option<Video>,
    labeled: Option<Video>,
}

#[derive(Debug, Serialize)]
struct Subject<'a> {
    subject_id: &'a str,
    species: &'a str,
    sex: &'a str,
    age: Option<&'a str>,
    /// RFC 3339, midnight UTC of the date given.
    date_of_birth: Option<String>,
    strain: Option<&'a str>,
    genotype: Option<&'a str>,
    weight: Option<&'a str>,
    description: Option<&'a str>,
}

/// What the helper reads.
#[derive(Debug, Serialize)]
struct Meta<'a> {
    session_description: &'a str,
    identifier: String,
    session_start_time: String,
    experimenter: &'a [String],
    lab: Option<&'a str>,
    institution: Option<&'a str>,
    source_script: String,
    subject: Subject<'a>,
    devices: Vec<Device>,
    joints: Vec<&'static str>,
    edges: Vec<[usize; 2]>,
    description: String,
    scorer: String,
    software_version: &'static str,
    videos: Videos,
    /// In a file of one of several mice, its number.
    #[serde(skip_serializing_if = "Option::is_none")]
    mouse: Option<usize>,
}

fn device(c: &CameraMeta, rig: Option<&RigCalibration>) -> Device {
    let known = |v: &str| Some(v.trim().to_owned()).filter(|v| !v.is_empty() && v != "unknown");
    Device {
        name: format!("{}_camera", c.role.name()),
        description: format!(
            "{} camera, {}x{} {} at {} fps, firmware {:?}",
            c.role.name(),
            c.width,
            c.height,
            c.pixel_format,
            c.fps,
            c.firmware
        ),
        serial_number: known(&c.serial),
        model: known(&c.model).unwrap_or_else(|| format!("unknown {} camera", c.role.name())),
        manufacturer: c.model.split_whitespace().next().unwrap_or("unknown").to_owned(),
        firmware: c.firmware.clone(),
        calibration: rig.map(|r| Calibration::of(r.camera(c.role))),
    }
}

/// The rig calibration the run's poses were made with: the file its replay was given, else
/// the session's own; `None` for a recording without one (its world is the fitted floor's).
fn run_calibration(run: &Run, session: Option<&crate::core::geometry::Rig>) -> Result<Option<RigCalibration>, Failure> {
    if let Some(path) = &run.calibration {
        return RigCalibration::load(path).map(Some).map_err(|e| {
            Failure::usage(anyhow::Error::from(e).context(format!("reading the run's calibration {path:?}")))
        });
    }
    Ok(session.map(RigCalibration::from_rig))
}

/// `mousepose export nwb`: writes `options.out` through the helper; what DANDI will refuse
/// in the file goes to `progress` as warnings (and into the summary).
///
/// # Errors
/// A directory that is not a run, a run without poses, a file in the way, a subject's field
/// that is not what nwbinspector takes, a date of birth after the session, a Python that
/// cannot run (the user's); the helper failing.
pub fn nwb(options: &NwbOptions, progress: &dyn Progress) -> Result<NwbSummary, Failure> {
    check_subject(options).map_err(|e| Failure::usage(anyhow::anyhow!(e)))?;
    let run = Run::open(&options.run, options.session.as_deref()).map_err(Failure::usage)?;
    let poses = run.dir.join(POSES_FILE);
    if !poses.is_file() {
        return Err(Failure::usage(anyhow::anyhow!(
            "the run {:?} has no {POSES_FILE}",
            run.dir
        )));
    }
    let mice = mice_in(&poses).map_err(Failure::usage)?;
    let files = match (options.per_mouse, mice) {
        (true, 1) => {
            return Err(Failure::usage(anyhow::anyhow!(
                "the run {:?} is of one mouse: --per-mouse is for runs of several (replay --mice N)",
                run.dir
            )));
        }
        (true, _) => (1..=mice).map(|k| (Some(k), per_mouse_file(&options.out, k))).collect(),
        (false, _) => vec![(None, options.out.clone())],
    };
    for (_, out) in &files {
        check_file_out(out, options.force)?;
    }
    let reader = SessionReader::open(&run.session)
        .map_err(|e| Failure::usage(e).context(format!("opening the session {:?}", run.session)))?;
    let session_meta = reader.meta();
    if let Some(born) = &options.date_of_birth {
        // Both are written as ISO 8601, so their dates compare as text.
        if session_meta.created.get(..10).is_some_and(|day| day < born.as_str()) {
            return Err(Failure::usage(anyhow::anyhow!(
                "the date of birth {born} is after the session's start ({})",
                session_meta.created
            )));
        }
    }
    let mut warnings = Vec::new();
    if options.age.is_none() && options.date_of_birth.is_none() {
        warnings.push(
            "no --age or --date-of-birth: the file is written, but DANDI refuses it (nwbinspector's check_subject_age is critical) until the subject has one"
                .to_owned(),
        );
    }
    for w in &warnings {
        progress.warning(w);
    }
    let calibration = run_calibration(&run, session_meta.rig.as_ref())?;
    let videos = Videos {
        source: linked_video(options.source_video.as_ref(), "--source-video")?,
        labeled: linked_video(options.labeled_video.as_ref(), "--labeled-video")?,
    };
    let mut meta = metadata(options, &run, session_meta, calibration.as_ref(), videos);
    for (k, (mouse, out)) in files.iter().enumerate() {
        meta.mouse = *mouse;
        if let Err(f) = write_with_helper(options, &poses, &meta, out) {
            // A file per mouse, all or none: those written before go again.
            for (_, written) in &files[..k] {
                let _ = std::fs::remove_file(written);
            }
            return Err(f.context(format!("exporting {:?} to NWB", options.run)));
        }
    }
    let rows = std::fs::read_to_string(&poses).map_or(0, |t| t.lines().count().saturating_sub(1));
    Ok(NwbSummary {
        out: files.into_iter().map(|(_, out)| out).collect(),
        rows,
        series: Joint::ALL.len(),
        subject_id: options.subject_id.clone(),
        warnings,
    })
}

/// A video to link (`what` names its flag): it must be a file.
fn linked_video(path: Option<&PathBuf>, what: &str) -> Result<Option<Video>, Failure> {
    match path {
        Some(p) if !p.is_file() => Err(Failure::usage(anyhow::anyhow!("the {what} {p:?} is not a file"))),
        Some(p) => Ok(Some(Video {
            path: std::path::absolute(p).with_context(|| format!("finding {p:?}"))?,
            start_s: 0.0,
        })),
        None => Ok(None),
    }
}

/// What the helper reads: the session, the subject, the cameras, the skeleton, the models.
fn metadata<'a>(
    options: &'a NwbOptions,
    run: &Run,
    session_meta: &crate::io::session::SessionMeta,
    calibration: Option<&RigCalibration>,
    videos: Videos,
) -> Meta<'a> {
    let summary: serde_json::Value = std::fs::read(run.dir.join(crate::engine::replay::SUMMARY_FILE))
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    let model = |key: &str| {
        summary
            .get(key)
            .and_then(|v| v.as_str())
            .unwrap_or("unknown")
            .to_owned()
    };
    let session_name = run
        .session
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Meta {
        session_description: &options.session_description,
        identifier: format!("mousepose-{session_name}-{}", session_meta.created),
        session_start_time: session_meta.created.clone(),
        experimenter: &options.experimenter,
        lab: options.lab.as_deref(),
        institution: options.institution.as_deref(),
        source_script: format!(
            "mousepose {} replay of {:?} ({})",
            env!("CARGO_PKG_VERSION"),
            run.session,
            run.dir.display()
        ),
        subject: Subject {
            subject_id: &options.subject_id,
            species: &options.species,
            sex: &options.sex,
            age: options.age.as_deref(),
            date_of_birth: options.date_of_birth.as_ref().map(|d| format!("{d}T00:00:00+00:00")),
            strain: options.strain.as_deref(),
            genotype: options.genotype.as_deref(),
            weight: options.weight.as_deref(),
            description: options.subject_description.as_deref(),
        },
        devices: session_meta.cameras.iter().map(|c| device(c, calibration)).collect(),
        joints: Joint::ALL.iter().map(|j| j.name()).collect(),
        edges: BONES.iter().map(|(a, b, _)| [a.index(), b.index()]).collect(),
        description: "24 joints of the mouse in 3D: 1-12 from the top depth image (regression forest), \
                      21-24 from the bottom colour image (paw cascade), 13-20 by inverse kinematics"
            .to_owned(),
        scorer: format!("body model {}; paw model {}", model("body_model"), model("paw_model")),
        software_version: env!("CARGO_PKG_VERSION"),
        videos,
        mouse: None,
    }
}

/// The file of mouse `k` of `--per-mouse`: `out`'s name with `_mouse{k}` before its extension.
fn per_mouse_file(out: &Path, k: usize) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match out.extension() {
        Some(ext) => format!("{stem}_mouse{k}.{}", ext.to_string_lossy()),
        None => format!("{stem}_mouse{k}"),
    };
    out.with_file_name(name)
}

/// Runs the helper with `options`'s Python on `poses` and `meta` (both written with a copy of
/// the helper into a temporary directory, removed after), into a hidden file renamed to
/// `out` when it succeeds.
fn write_with_helper(options: &NwbOptions, poses: &Path, meta: &Meta<'_>, out: &Path) -> Result<(), Failure> {
    let python = options.python.clone().unwrap_or_else(project_python);
    let work = std::env::temp_dir().join(format!("mousepose-nwb-{}", std::process::id()));
    std::fs::create_dir_all(&work).with_context(|| format!("creating {work:?}"))?;
    let result = (|| -> Result<(), Failure> {
        std::fs::write(work.join("nwb.py"), HELPER).context("writing the NWB helper")?;
        std::fs::write(work.join("meta.json"), serde_json::to_vec_pretty(meta)?).context("writing the metadata")?;
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out.nwb".to_owned());
        let partial = out.with_file_name(format!(".{name}.partial-{}", std::process::id()));
        let output = Command::new(&python)
            .arg(work.join("nwb.py"))
            .arg(poses)
            .arg(work.join("meta.json"))
            .arg(&partial)
            .output()
            .map_err(|e| {
                Failure::usage(anyhow::Error::from(e).context(format!(
                    "cannot run {python:?} (make it with 'sudo /usr/share/mousepose/nwb-env' where the package is installed, scripts/setup.sh in a checkout, or give a Python with pynwb and ndx-pose by --python)"
                )))
            })?;
        if !output.status.success() {
            let _ = std::fs::remove_file(&partial);
            let stderr = String::from_utf8_lossy(&output.stderr);
            let last = stderr
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("no message");
            return Err(Failure::from(anyhow::anyhow!("the NWB helper failed: {last}")));
        }
        std::fs::rename(&partial, out).with_context(|| format!("writing {:?}", out))?;
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&work);
    result
}

/// The subject's fields, checked as nwbinspector checks them: each one's sentence says what
/// was expected (the command line's flags give the same sentences).
///
/// # Errors
/// The first field that is not what nwbinspector takes.
pub fn check_subject(options: &NwbOptions) -> Result<(), String> {
    check_species(&options.species)?;
    if !SEXES.contains(&options.sex.as_str()) {
        return Err(format!(
            "expected the sex as one of {}, got {:?}",
            SEXES.join(", "),
            options.sex
        ));
    }
    if let Some(age) = &options.age {
        check_age(age)?;
    }
    if let Some(date) = &options.date_of_birth {
        check_date(date)?;
    }
    if let Some(weight) = &options.weight {
        check_weight(weight)?;
    }
    Ok(())
}

/// The subject's sexes NWB knows: male, female, unknown, other.
pub const SEXES: [&str; 4] = ["M", "F", "U", "O"];

/// A number of the ISO 8601 duration: digits, then optionally a point and digits; returns
/// its value and the rest.
fn duration_number(s: &str) -> Option<(f64, &str)> {
    let int = s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
    if int == 0 {
        return None;
    }
    let mut end = int;
    if let Some(frac) = s[int..].strip_prefix('.') {
        let digits = frac.find(|c: char| !c.is_ascii_digit()).unwrap_or(frac.len());
        if digits == 0 {
            return None;
        }
        end = int + 1 + digits;
    }
    Some((s[..end].parse().ok()?, &s[end..]))
}

/// The days an ISO 8601 duration (`P[nY][nM][nW][nD][T[nH][nM][nS]]`, as nwbinspector's
/// `check_subject_age` reads it) stands for, roughly (a year 365.25 days, a month 30.44);
/// `None` when it is not one.
fn duration_days(s: &str) -> Option<f64> {
    let mut rest = s.strip_prefix('P')?;
    if rest.is_empty() {
        return None;
    }
    let mut days = 0.0;
    let mut parts = 0;
    for (unit, scale) in [('Y', 365.25), ('M', 30.44), ('W', 7.0), ('D', 1.0)] {
        if let Some((v, after)) = duration_number(rest).filter(|(_, after)| after.starts_with(unit)) {
            days += v * scale;
            rest = &after[1..];
            parts += 1;
        }
    }
    if let Some(time) = rest.strip_prefix('T') {
        rest = time;
        let mut time_parts = 0;
        for (unit, scale) in [('H', 1.0 / 24.0), ('M', 1.0 / 1440.0), ('S', 1.0 / 86_400.0)] {
            if let Some((v, after)) = duration_number(rest).filter(|(_, after)| after.starts_with(unit)) {
                days += v * scale;
                rest = &after[1..];
                time_parts += 1;
            }
        }
        if time_parts == 0 {
            return None;
        }
        parts += time_parts;
    }
    (rest.is_empty() && parts > 0).then_some(days)
}

/// An age: an ISO 8601 duration, or a range of two (either side may be left open), the
/// lower bound below the upper.
///
/// # Errors
/// A sentence saying what was expected.
pub fn check_age(s: &str) -> Result<(), String> {
    let wrong = || {
        format!(
            "expected an ISO 8601 duration such as P90D (90 days), P12W or P1Y2M, or a range such as P80D/P100D or P90D/, got {s:?}"
        )
    };
    match s.split_once('/') {
        None => duration_days(s).map(|_| ()).ok_or_else(wrong),
        Some((lo, hi)) => {
            let bound = |b: &str| {
                if b.is_empty() {
                    Some(None)
                } else {
                    duration_days(b).map(Some)
                }
            };
            match (bound(lo), bound(hi)) {
                (Some(None), Some(None)) | (None, _) | (_, None) => Err(wrong()),
                (Some(Some(a)), Some(Some(b))) if a >= b => Err(format!(
                    "the age range {s:?} does not increase: its upper bound must be the longer duration"
                )),
                _ => Ok(()),
            }
        }
    }
}

/// A date of birth: a calendar date, YYYY-MM-DD.
///
/// # Errors
/// A sentence saying what was expected.
pub fn check_date(s: &str) -> Result<(), String> {
    let wrong = || format!("expected a date as YYYY-MM-DD, got {s:?}");
    let parts: Vec<&str> = s.split('-').collect();
    let [y, m, d] = parts[..] else {
        return Err(wrong());
    };
    if y.len() != 4 || m.len() != 2 || d.len() != 2 || !s.chars().all(|c| c.is_ascii_digit() || c == '-') {
        return Err(wrong());
    }
    let (y, m, d): (u32, u32, u32) = (
        y.parse().map_err(|_| wrong())?,
        m.parse().map_err(|_| wrong())?,
        d.parse().map_err(|_| wrong())?,
    );
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let days = match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return Err(wrong()),
    };
    if d == 0 || d > days || y < 1900 {
        return Err(wrong());
    }
    Ok(())
}

/// A species: a Latin binomial or an NCBI taxonomy link, as nwbinspector wants.
///
/// # Errors
/// A sentence saying what was expected.
pub fn check_species(s: &str) -> Result<(), String> {
    const TAXON: &str = "http://purl.obolibrary.org/obo/NCBITaxon_";
    let binomial = s.split_once(' ').is_some_and(|(genus, species)| {
        let mut g = genus.chars();
        g.next().is_some_and(|c| c.is_ascii_uppercase())
            && g.all(|c| c.is_ascii_lowercase())
            && !species.is_empty()
            && species.chars().all(|c| c.is_ascii_lowercase())
    });
    let taxon = s
        .strip_prefix(TAXON)
        .is_some_and(|id| !id.is_empty() && id.chars().all(|c| c.is_ascii_digit()));
    if binomial || taxon {
        Ok(())
    } else {
        Err(format!(
            "expected a Latin binomial such as \"Mus musculus\" or an NCBI taxonomy link ({TAXON}10090), got {s:?}"
        ))
    }
}

/// A weight: a number, a space and a unit of mass.
///
/// # Errors
/// A sentence saying what was expected.
pub fn check_weight(s: &str) -> Result<(), String> {
    let ok = s.split_once(' ').is_some_and(|(number, unit)| {
        duration_number(number).is_some_and(|(_, rest)| rest.is_empty())
            && ["kg", "g", "mg", "ug", "μg", "ng", "pg"].contains(&unit.to_lowercase().as_str())
    });
    if ok {
        Ok(())
    } else {
        Err(format!(
            "expected a number, a space and a unit (kg, g, mg, ug, ng, pg), such as \"25 g\", got {s:?}"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::{check_age, check_date, check_species, check_weight};

    #[test]
    fn ages_are_iso_8601_durations_or_increasing_ranges() {
        for good in [
            "P90D",
            "P12W",
            "P1Y2M",
            "P0.5Y",
            "PT36H",
            "P2DT3H",
            "P90D/",
            "/P90D",
            "P80D/P100D",
        ] {
            assert_eq!(check_age(good), Ok(()));
        }
        for bad in [
            "90",
            "P",
            "PT",
            "P90",
            "P1D2Y",
            "90D",
            "P1.D",
            "P80D/P80D",
            "P100D/P12W",
            "/",
            "p90d",
        ] {
            assert!(check_age(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn dates_species_and_weights_take_what_nwbinspector_takes() {
        assert!(check_date("2024-02-29").is_ok());
        for bad in ["2023-02-29", "2024-13-01", "2024-1-01", "20240101", "2024-01-01T00:00"] {
            assert!(check_date(bad).is_err(), "{bad}");
        }
        for good in [
            "Mus musculus",
            "Rattus norvegicus",
            "http://purl.obolibrary.org/obo/NCBITaxon_10090",
        ] {
            assert!(check_species(good).is_ok(), "{good}");
        }
        for bad in [
            "mouse",
            "Mus",
            "mus musculus",
            "Mus Musculus",
            "Mus musculus domesticus",
        ] {
            assert!(check_species(bad).is_err(), "{bad}");
        }
        for good in ["25 g", "0.025 kg", "25 G"] {
            assert!(check_weight(good).is_ok(), "{good}");
        }
        for bad in ["25", "25g", "25 lb", "g 25"] {
            assert!(check_weight(bad).is_err(), "{bad}");
        }
    }
}
