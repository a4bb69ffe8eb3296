//! `mousepose export nwb RUN --out FILE.nwb`: the arguments (the subject's fields checked as
//! nwbinspector checks them), handed to [`crate::engine::export::nwb`], and what was written
//! printed.

use crate::app::output::print;
use crate::engine::export::nwb::NwbOptions;
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
    #[arg(long, default_value = "U", value_parser = ["M", "F", "U", "O"])]
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
    /// Print what was written as one JSON object (`out`, `rows`, `series`, `subject_id`,
    /// `warnings`).
    #[arg(long)]
    pub json: bool,
}

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

/// `--age`: an ISO 8601 duration, or a range of two (either side may be left open), the
/// lower bound below the upper.
fn parse_age(s: &str) -> Result<String, String> {
    let wrong = || {
        format!(
            "expected an ISO 8601 duration such as P90D (90 days), P12W or P1Y2M, or a range such as P80D/P100D or P90D/, got {s:?}"
        )
    };
    match s.split_once('/') {
        None => duration_days(s).map(|_| s.to_owned()).ok_or_else(wrong),
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
                _ => Ok(s.to_owned()),
            }
        }
    }
}

/// `--date-of-birth`: a calendar date, YYYY-MM-DD.
fn parse_date(s: &str) -> Result<String, String> {
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
    Ok(s.to_owned())
}

/// `--species`: a Latin binomial or an NCBI taxonomy link, as nwbinspector wants.
fn parse_species(s: &str) -> Result<String, String> {
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
        Ok(s.to_owned())
    } else {
        Err(format!(
            "expected a Latin binomial such as \"Mus musculus\" or an NCBI taxonomy link ({TAXON}10090), got {s:?}"
        ))
    }
}

/// `--weight`: a number, a space and a unit of mass.
fn parse_weight(s: &str) -> Result<String, String> {
    let ok = s.split_once(' ').is_some_and(|(number, unit)| {
        duration_number(number).is_some_and(|(_, rest)| rest.is_empty())
            && ["kg", "g", "mg", "ug", "μg", "ng", "pg"].contains(&unit.to_lowercase().as_str())
    });
    if ok {
        Ok(s.to_owned())
    } else {
        Err(format!(
            "expected a number, a space and a unit (kg, g, mg, ug, ng, pg), such as \"25 g\", got {s:?}"
        ))
    }
}

/// `mousepose export nwb`.
pub fn command(args: &NwbArgs) -> crate::app::Outcome {
    let written = crate::engine::export::nwb::nwb(&NwbOptions {
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
    })?;
    if args.json {
        return Ok(crate::app::output::print_json(&serde_json::json!({
            "out": written.out,
            "rows": written.rows,
            "series": written.series,
            "subject_id": written.subject_id,
            "warnings": written.warnings,
        }))?);
    }
    Ok(print(&format!("{:?}: 24 joints, NWB with ndx-pose\n", args.out))?)
}

#[cfg(test)]
mod tests {
    use super::{parse_age, parse_date, parse_species, parse_weight};

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
            assert_eq!(parse_age(good).as_deref(), Ok(good));
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
            assert!(parse_age(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn dates_species_and_weights_take_what_nwbinspector_takes() {
        assert!(parse_date("2024-02-29").is_ok());
        for bad in ["2023-02-29", "2024-13-01", "2024-1-01", "20240101", "2024-01-01T00:00"] {
            assert!(parse_date(bad).is_err(), "{bad}");
        }
        for good in [
            "Mus musculus",
            "Rattus norvegicus",
            "http://purl.obolibrary.org/obo/NCBITaxon_10090",
        ] {
            assert!(parse_species(good).is_ok(), "{good}");
        }
        for bad in [
            "mouse",
            "Mus",
            "mus musculus",
            "Mus Musculus",
            "Mus musculus domesticus",
        ] {
            assert!(parse_species(bad).is_err(), "{bad}");
        }
        for good in ["25 g", "0.025 kg", "25 G"] {
            assert!(parse_weight(good).is_ok(), "{good}");
        }
        for bad in ["25", "25g", "25 lb", "g 25"] {
            assert!(parse_weight(bad).is_err(), "{bad}");
        }
    }
}
