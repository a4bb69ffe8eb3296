//! `mousepose export nwb RUN --out FILE.nwb`: the arguments (the subject's fields checked by
//! the engine's checks, as nwbinspector checks them), handed to [`crate::engine::export::nwb`],
//! and what was written printed.

use crate::app::output::print;
use crate::app::progress::Bars;
use crate::engine::export::nwb::{self, NwbOptions};
use clap::Args;
use std::path::PathBuf;

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
    /// The subject's identifier (DANDI names files by it).
    #[arg(long, value_name = "ID", default_value = "unknown")]
    pub subject_id: String,
    /// The subject's species: a Latin binomial ("Mus musculus") or an NCBI taxonomy link.
    #[arg(long, value_name = "SPECIES", default_value = "Mus musculus", value_parser = parse_species)]
    pub species: String,
    /// The subject's sex: M, F, U (unknown) or O (other).
    #[arg(long, default_value = "U", value_parser = nwb::SEXES)]
    pub sex: String,
    /// The subject's age at the session's start, an ISO 8601 duration (P90D, P12W, P3M2D) or a
    /// range (P80D/P100D, or P90D/ for 90 days or older). DANDI needs this or --date-of-birth.
    #[arg(long, value_name = "DURATION", value_parser = parse_age)]
    pub age: Option<String>,
    /// The subject's date of birth, YYYY-MM-DD (UTC). DANDI needs this or --age.
    #[arg(long, value_name = "DATE", value_parser = parse_date)]
    pub date_of_birth: Option<String>,
    /// The subject's strain, e.g. "C57BL/6J".
    #[arg(long, value_name = "STRAIN")]
    pub strain: Option<String>,
    /// The subject's genotype, e.g. "wild type".
    #[arg(long, value_name = "GENOTYPE")]
    pub genotype: Option<String>,
    /// The subject's weight at the session, a number and a unit ("25 g", "0.025 kg").
    #[arg(long, value_name = "WEIGHT", value_parser = parse_weight)]
    pub weight: Option<String>,
    /// A description of the subject (e.g. housing, treatment, where it came from).
    #[arg(long, value_name = "TEXT")]
    pub subject_description: Option<String>,
    /// What the session was.
    #[arg(
        long,
        value_name = "TEXT",
        default_value = "open field, top depth camera and bottom colour camera"
    )]
    pub session_description: String,
    /// Who ran the experiment, as "Last, First" (repeat the flag for several people).
    #[arg(long, value_name = "NAME")]
    pub experimenter: Vec<String>,
    /// The lab the data come from.
    #[arg(long, value_name = "NAME")]
    pub lab: Option<String>,
    /// The institution the lab belongs to.
    #[arg(long, value_name = "NAME")]
    pub institution: Option<String>,
    /// The video the poses were estimated from (e.g. `export moseq`'s depth.avi), linked from
    /// the PoseEstimation by its path relative to the NWB file; its frames' times come from the
    /// MoSeq time file beside it (depth_ts.txt), else are the video's own, its first frame at
    /// the run's first pose.
    #[arg(long, value_name = "VIDEO")]
    pub source_video: Option<PathBuf>,
    /// The video with the poses drawn (`export video` of the run), linked as the source video.
    #[arg(long, value_name = "VIDEO")]
    pub labeled_video: Option<PathBuf>,
    /// The Python with pynwb and ndx-pose (default: $MOUSEPOSE_PYTHON, else /opt/mousepose/venv).
    #[arg(long, value_name = "PROGRAM")]
    pub python: Option<PathBuf>,
    /// Replace the file if it exists.
    #[arg(long)]
    pub force: bool,
    /// A run of several mice (`replay --mice N`): a file per mouse, FILE's name with
    /// `_mouse1`, `_mouse2`, ... before `.nwb` (each as a run of one mouse is written: what
    /// keypoint-MoSeq and movement read), instead of one file holding every mouse.
    #[arg(long)]
    pub per_mouse: bool,
    /// Print what was written as one JSON object (`out`, `rows`, `series`, `subject_id`,
    /// `warnings`).
    #[arg(long)]
    pub json: bool,
}

/// `--age`: see [`nwb::check_age`].
fn parse_age(s: &str) -> Result<String, String> {
    nwb::check_age(s).map(|()| s.to_owned())
}

/// `--date-of-birth`: see [`nwb::check_date`].
fn parse_date(s: &str) -> Result<String, String> {
    nwb::check_date(s).map(|()| s.to_owned())
}

/// `--species`: see [`nwb::check_species`].
fn parse_species(s: &str) -> Result<String, String> {
    nwb::check_species(s).map(|()| s.to_owned())
}

/// `--weight`: see [`nwb::check_weight`].
fn parse_weight(s: &str) -> Result<String, String> {
    nwb::check_weight(s).map(|()| s.to_owned())
}

/// `mousepose export nwb`.
pub fn command(args: &NwbArgs) -> crate::app::Outcome {
    let written = nwb::nwb(
        &NwbOptions {
            run: args.run.clone(),
            out: args.out.clone(),
            session: args.session.clone(),
            subject_id: args.subject_id.clone(),
            species: args.species.clone(),
            sex: args.sex.clone(),
            age: args.age.clone(),
            date_of_birth: args.date_of_birth.clone(),
            strain: args.strain.clone(),
            genotype: args.genotype.clone(),
            weight: args.weight.clone(),
            subject_description: args.subject_description.clone(),
            session_description: args.session_description.clone(),
            experimenter: args.experimenter.clone(),
            lab: args.lab.clone(),
            institution: args.institution.clone(),
            source_video: args.source_video.clone(),
            labeled_video: args.labeled_video.clone(),
            python: args.python.clone(),
            force: args.force,
            per_mouse: args.per_mouse,
        },
        &Bars::default(),
    )?;
    if args.json {
        let mut json = serde_json::json!({
            "out": args.out,
            "rows": written.rows,
            "series": written.series,
            "subject_id": written.subject_id,
            "warnings": written.warnings,
        });
        if args.per_mouse {
            json["files"] = serde_json::json!(written.out);
        }
        return Ok(crate::app::output::print_json(&json)?);
    }
    for out in &written.out {
        print(&format!("{out:?}: 24 joints, NWB with ndx-pose\n"))?;
    }
    Ok(())
}
