//! `mousepose export nwb RUN --out FILE.nwb`: a run's poses as NWB 2.x with the ndx-pose
//! extension (a `PoseEstimation` of 24 `PoseEstimationSeries`, one per joint, with the
//! skeleton's edges, the cameras as devices, the software version and models), written by
//! the ecosystem's own library: `pynwb` and `ndx-pose` in the Python environment that
//! `scripts/setup.sh` makes (`/opt/mousepose/venv`, or `--python`/`$MOUSEPOSE_PYTHON`).
//!
//! mousepose writes the metadata as JSON beside a copy of the helper script (`nwb.py`, built
//! into the binary) in a temporary directory and runs it on the run's `poses.csv`; the file
//! is written under a hidden name and renamed into place when the helper succeeds.

use crate::app::export::{Run, check_file_out};
use crate::app::{Failure, print};
use crate::core::skeleton::{BONES, Joint};
use crate::io::session::{CameraMeta, SessionReader};
use crate::runtime::sink::poses::POSES_FILE;
use anyhow::Context as _;
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;
use std::process::Command;

/// The helper, run with the environment's Python.
const HELPER: &str = include_str!("nwb.py");
/// Where `scripts/setup.sh` puts the Python environment with pynwb and ndx-pose.
pub const DEFAULT_PYTHON: &str = "/opt/mousepose/venv/bin/python3";

#[derive(Debug, Args)]
pub struct NwbArgs {
    /// The run: a replay's output directory (or a daemon's chunk).
    #[arg(value_name = "RUN")]
    pub run: PathBuf,
    /// The NWB file to write.
    #[arg(long, value_name = "FILE.nwb")]
    pub out: PathBuf,
    /// The session the run was made from, when its summary does not name it.
    #[arg(long, value_name = "DIR")]
    pub session: Option<PathBuf>,
    /// The subject's identifier.
    #[arg(long, default_value = "unknown")]
    pub subject_id: String,
    /// The subject's species (Latin binomial).
    #[arg(long, default_value = "Mus musculus")]
    pub species: String,
    /// The subject's sex: M, F, U (unknown) or O (other).
    #[arg(long, default_value = "U", value_parser = ["M", "F", "U", "O"])]
    pub sex: String,
    /// The subject's age, ISO 8601 duration (e.g. P90D).
    #[arg(long)]
    pub age: Option<String>,
    /// What the session was.
    #[arg(long, default_value = "open field, top depth camera and bottom colour camera")]
    pub session_description: String,
    #[arg(long)]
    pub experimenter: Option<String>,
    #[arg(long)]
    pub lab: Option<String>,
    #[arg(long)]
    pub institution: Option<String>,
    /// The Python with pynwb and ndx-pose (default: $MOUSEPOSE_PYTHON, else /opt/mousepose/venv).
    #[arg(long, value_name = "PROGRAM")]
    pub python: Option<PathBuf>,
    /// Replace the file if it exists.
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Serialize)]
struct Device {
    name: String,
    description: String,
    manufacturer: String,
}

#[derive(Debug, Serialize)]
struct Subject<'a> {
    subject_id: &'a str,
    species: &'a str,
    sex: &'a str,
    age: Option<&'a str>,
}

/// What the helper reads.
#[derive(Debug, Serialize)]
struct Meta<'a> {
    session_description: &'a str,
    identifier: String,
    session_start_time: String,
    experimenter: Option<&'a str>,
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
}

fn device(c: &CameraMeta) -> Device {
    Device {
        name: format!("{}_camera", c.role.name()),
        description: format!(
            "{} camera {} (serial {:?}, firmware {:?}), {}x{} {} at {} fps",
            c.role.name(),
            c.model,
            c.serial,
            c.firmware,
            c.width,
            c.height,
            c.pixel_format,
            c.fps
        ),
        manufacturer: c.model.split_whitespace().next().unwrap_or("unknown").to_owned(),
    }
}

/// `mousepose export nwb`.
pub fn command(args: &NwbArgs) -> crate::app::Outcome {
    let run = Run::open(&args.run, args.session.as_deref()).map_err(Failure::usage)?;
    let poses = run.dir.join(POSES_FILE);
    if !poses.is_file() {
        return Err(Failure::usage(anyhow::anyhow!(
            "the run {:?} has no {POSES_FILE}",
            run.dir
        )));
    }
    check_file_out(&args.out, args.force)?;
    let reader = SessionReader::open(&run.session)
        .map_err(|e| Failure::usage(e).context(format!("opening the session {:?}", run.session)))?;
    let session_meta = reader.meta();
    let summary: serde_json::Value = std::fs::read(run.dir.join(crate::app::replay::SUMMARY_FILE))
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
    let meta = Meta {
        session_description: &args.session_description,
        identifier: format!("mousepose-{session_name}-{}", session_meta.created),
        session_start_time: session_meta.created.clone(),
        experimenter: args.experimenter.as_deref(),
        lab: args.lab.as_deref(),
        institution: args.institution.as_deref(),
        source_script: format!(
            "mousepose {} replay of {:?} ({})",
            env!("CARGO_PKG_VERSION"),
            run.session,
            run.dir.display()
        ),
        subject: Subject {
            subject_id: &args.subject_id,
            species: &args.species,
            sex: &args.sex,
            age: args.age.as_deref(),
        },
        devices: session_meta.cameras.iter().map(device).collect(),
        joints: Joint::ALL.iter().map(|j| j.name()).collect(),
        edges: BONES.iter().map(|(a, b, _)| [a.index(), b.index()]).collect(),
        description: "24 joints of the mouse in 3D: 1-12 from the top depth image (regression forest), \
                      21-24 from the bottom colour image (paw cascade), 13-20 by inverse kinematics"
            .to_owned(),
        scorer: format!("body model {}; paw model {}", model("body_model"), model("paw_model")),
        software_version: env!("CARGO_PKG_VERSION"),
    };
    let python = args
        .python
        .clone()
        .or_else(|| std::env::var_os("MOUSEPOSE_PYTHON").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from(DEFAULT_PYTHON));
    let work = std::env::temp_dir().join(format!("mousepose-nwb-{}", std::process::id()));
    std::fs::create_dir_all(&work).with_context(|| format!("creating {work:?}"))?;
    let result = (|| -> Result<(), Failure> {
        std::fs::write(work.join("nwb.py"), HELPER).context("writing the NWB helper")?;
        std::fs::write(work.join("meta.json"), serde_json::to_vec_pretty(&meta)?).context("writing the metadata")?;
        let name = args
            .out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out.nwb".to_owned());
        let partial = args
            .out
            .with_file_name(format!(".{name}.partial-{}", std::process::id()));
        let output = Command::new(&python)
            .arg(work.join("nwb.py"))
            .arg(&poses)
            .arg(work.join("meta.json"))
            .arg(&partial)
            .output()
            .map_err(|e| {
                Failure::usage(anyhow::Error::from(e).context(format!(
                    "cannot run {python:?} (run scripts/setup.sh, or give a Python with pynwb and ndx-pose by --python)"
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
        std::fs::rename(&partial, &args.out).with_context(|| format!("writing {:?}", args.out))?;
        Ok(())
    })();
    let _ = std::fs::remove_dir_all(&work);
    result.map_err(|f| f.context(format!("exporting {:?} to NWB", args.run)))?;
    Ok(print(&format!("{:?}: 24 joints, NWB with ndx-pose\n", args.out))?)
}
