//! Paw labels as labs already keep them: DeepLabCut's `CollectedData_*.csv` (its header rows
//! `scorer`, optionally `individuals`, `bodyparts` and `coords`, then one row per labelled
//! image: the image's path in one to three index columns, then x and y of every body part,
//! empty where it is not visible) and the same table in its `.h5` ([`hdf5`]), SLEAP's `.slp`
//! ([`hdf5`]), and the mapping from a lab's body-part names to our four paws.
//!
//! A file that is wrong is refused in one sentence naming the file, the line, row or frame,
//! and what is wrong. Frames that hold two views stacked (a side view above a bottom view through a
//! mirror) give the row where the bottom view begins ([`lower_view_top`]).

mod hdf5;

pub use hdf5::{read_dlc_h5, read_slp};

use crate::core::skeleton::Joint;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One labelled image: its name (the path the file gives, relative to the project the file
/// belongs to, or a video's path and the frame), where its pixels are, and the points
/// labelled in it, by body-part name (pixels).
#[derive(Clone, Debug, PartialEq)]
pub struct LabelledImage {
    pub image: PathBuf,
    pub source: FrameSource,
    pub points: BTreeMap<String, (f64, f64)>,
}

/// Where a labelled image's pixels are.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameSource {
    /// An image file, its path as the label file gives it.
    File(PathBuf),
    /// An encoded picture (PNG, JPEG) kept in the label file itself (SLEAP's `.pkg.slp`).
    Embedded(Vec<u8>),
    /// A frame of a video file (counted from 0), as SLEAP labels videos.
    Video { path: PathBuf, frame: u64 },
}

/// A label file read: its body parts (in the file's order) and its images.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelTable {
    pub path: PathBuf,
    pub scorer: String,
    pub parts: Vec<String>,
    pub images: Vec<LabelledImage>,
}

/// Why a label file or a mapping is refused.
#[derive(Debug, thiserror::Error)]
pub enum LabelError {
    #[error("cannot read the label file {path:?}: {error}")]
    Io { path: PathBuf, error: std::io::Error },
    #[error("label file {path:?}, line {line}: {what}")]
    Malformed { path: PathBuf, line: usize, what: String },
    /// A file of tables (HDF5): `place` names the row, frame or table.
    #[error("label file {path:?}, {place}: {what}")]
    Table { path: PathBuf, place: String, what: String },
    #[error("paw mapping: {0}")]
    Mapping(String),
}

/// Reads a label file by its kind: SLEAP's `.slp` ([`read_slp`]), DeepLabCut's `.h5`
/// ([`read_dlc_h5`]), else DeepLabCut's CSV ([`read_dlc_csv`]).
///
/// # Errors
/// As the reader of its kind.
pub fn read_labels(path: &Path) -> Result<LabelTable, LabelError> {
    let extension = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("slp") => read_slp(path),
        Some("h5" | "hdf5") => read_dlc_h5(path),
        _ => read_dlc_csv(path),
    }
}

/// Reads a DeepLabCut `CollectedData_*.csv`.
///
/// # Errors
/// [`LabelError::Io`] when it cannot be read; [`LabelError::Malformed`] naming the line when
/// its header rows are not DeepLabCut's, a row has another number of cells, or a coordinate
/// is not a finite number.
pub fn read_dlc_csv(path: &Path) -> Result<LabelTable, LabelError> {
    let bad = |line: usize, what: String| LabelError::Malformed {
        path: path.to_owned(),
        line,
        what,
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .from_path(path)
        .map_err(|e| LabelError::Io {
            path: path.to_owned(),
            error: std::io::Error::other(e.to_string()),
        })?;
    let mut rows = Vec::new();
    for (k, record) in reader.records().enumerate() {
        let record = record.map_err(|e| bad(k + 1, format!("not CSV ({e})")))?;
        rows.push(record.iter().map(str::to_owned).collect::<Vec<_>>());
    }
    let first = |k: usize| rows.get(k).and_then(|r| r.first()).map_or("", String::as_str);
    if first(0) != "scorer" {
        return Err(bad(
            1,
            format!("starts with `{}`, not DeepLabCut's `scorer` header row", first(0)),
        ));
    }
    let individuals = first(1) == "individuals";
    let (parts_row, coords_row) = if individuals { (2, 3) } else { (1, 2) };
    if first(parts_row) != "bodyparts" || first(coords_row) != "coords" {
        return Err(bad(
            parts_row + 1,
            "DeepLabCut's header rows `bodyparts` and `coords` are not where they belong".into(),
        ));
    }
    let coords = &rows[coords_row];
    let index_columns = coords
        .iter()
        .position(|c| c == "x")
        .ok_or_else(|| bad(coords_row + 1, "the `coords` row names no `x` column".into()))?;
    let columns = csv_columns(path, &rows, (parts_row, coords_row), individuals, index_columns)?;
    let scorer = rows[0].get(index_columns).cloned().unwrap_or_default();
    let mut images = Vec::new();
    for (k, row) in rows.iter().enumerate().skip(coords_row + 1) {
        let line = k + 1;
        if row.iter().all(String::is_empty) {
            continue;
        }
        if row.len() != coords.len() {
            return Err(bad(
                line,
                format!("{} cells where the header has {}", row.len(), coords.len()),
            ));
        }
        let image: PathBuf = row[..index_columns].iter().filter(|c| !c.is_empty()).collect();
        let mut points = BTreeMap::new();
        for (part, cx, cy) in &columns {
            let value = |c: usize| -> Result<Option<f64>, LabelError> {
                let text = row[c].trim();
                if text.is_empty() || text.eq_ignore_ascii_case("nan") {
                    return Ok(None);
                }
                match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(Some(v)),
                    _ => Err(bad(line, format!("`{text}` for `{part}` is not a number"))),
                }
            };
            match (value(*cx)?, value(*cy)?) {
                (Some(x), Some(y)) => {
                    points.insert(part.clone(), (x, y));
                }
                (None, None) => {}
                _ => return Err(bad(line, format!("`{part}` has one coordinate without the other"))),
            }
        }
        images.push(LabelledImage {
            source: FrameSource::File(image.clone()),
            image,
            points,
        });
    }
    if images.is_empty() {
        return Err(bad(rows.len(), "no labelled image after the header rows".into()));
    }
    Ok(LabelTable {
        path: path.to_owned(),
        scorer,
        parts: columns.into_iter().map(|(p, _, _)| p).collect(),
        images,
    })
}

/// The body parts of a DeepLabCut CSV's columns (of the file at `path`) from its header rows
/// (`rows`, the `bodyparts` and `coords` rows at `parts_row` and `coords_row`, an
/// `individuals` row at 1 when `individuals`), each with its columns of x and y, from `first`
/// on.
fn csv_columns(
    path: &Path,
    rows: &[Vec<String>],
    (parts_row, coords_row): (usize, usize),
    individuals: bool,
    first: usize,
) -> Result<Vec<(String, usize, usize)>, LabelError> {
    let coords = &rows[coords_row];
    let mut columns: Vec<(String, usize, usize)> = Vec::new();
    let mut c = first;
    while c < coords.len() {
        let name = |row: usize| rows[row].get(c).cloned().unwrap_or_default();
        let part = if individuals {
            format!("{}/{}", name(1), name(parts_row))
        } else {
            name(parts_row)
        };
        match (coords.get(c).map(String::as_str), coords.get(c + 1).map(String::as_str)) {
            (Some("x"), Some("y")) => {}
            (x, y) => {
                let said = |v: Option<&str>| v.map_or("missing".to_owned(), |v| format!("`{v}`"));
                return Err(LabelError::Malformed {
                    path: path.to_owned(),
                    line: coords_row + 1,
                    what: format!(
                        "the `coords` row's columns {} and {} (of `{part}`) are {} and {}, not x and y",
                        c + 1,
                        c + 2,
                        said(x),
                        said(y)
                    ),
                });
            }
        }
        columns.push((part, c, c + 1));
        // DeepLabCut's machine labels add a likelihood after x and y.
        c += if coords.get(c + 2).is_some_and(|l| l == "likelihood") {
            3
        } else {
            2
        };
    }
    Ok(columns)
}

/// Which of a lab's body parts are which of our paws.
#[derive(Clone, Debug, PartialEq)]
pub struct PawMap {
    pub paws: Vec<(String, Joint)>,
}

impl PawMap {
    /// Reads `NAME=PAW,...` (`PAW` one of `left_fore_paw`, `right_fore_paw`, `left_hind_paw`,
    /// `right_hind_paw`), each name one of `parts`, each paw at most once.
    ///
    /// # Errors
    /// [`LabelError::Mapping`] naming what is wrong.
    pub fn parse(text: &str, parts: &[String]) -> Result<Self, LabelError> {
        let mut paws = Vec::new();
        for item in text.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let Some((name, paw)) = item.split_once('=') else {
                return Err(LabelError::Mapping(format!("`{item}` is not NAME=PAW")));
            };
            let (name, paw) = (name.trim(), paw.trim());
            let joint: Joint = paw
                .parse()
                .ok()
                .filter(|j| Joint::PAWS.contains(j))
                .ok_or_else(|| LabelError::Mapping(format!("`{paw}` is not one of {}", paw_names())))?;
            if !parts.iter().any(|p| p == name) {
                return Err(LabelError::Mapping(format!(
                    "the labels have no body part `{name}` (they have {})",
                    parts.join(", ")
                )));
            }
            paws.push((name.to_owned(), joint));
        }
        Self::checked(paws)
    }

    /// Guesses the mapping from the names (`LF`, `left_front`, `fore_left`, `RH`, `hindpaw_r`,
    /// ...): each paw must be named by exactly one part.
    ///
    /// # Errors
    /// [`LabelError::Mapping`] when a paw is named by none or by several parts: then the lab
    /// says which with `NAME=PAW`.
    pub fn guess(parts: &[String]) -> Result<Self, LabelError> {
        let mut paws = Vec::new();
        for joint in Joint::PAWS {
            let named: Vec<&String> = parts.iter().filter(|p| names_paw(p) == Some(joint)).collect();
            match named.as_slice() {
                [one] => paws.push(((*one).clone(), joint)),
                [] => {
                    return Err(LabelError::Mapping(format!(
                        "no body part is named as the {} (of {}): say which with NAME={}",
                        joint.name(),
                        parts.join(", "),
                        joint.name()
                    )));
                }
                several => {
                    let names: Vec<&str> = several.iter().map(|s| s.as_str()).collect();
                    return Err(LabelError::Mapping(format!(
                        "{} all look like the {}: say which with NAME={}",
                        names.join(", "),
                        joint.name(),
                        joint.name()
                    )));
                }
            }
        }
        Self::checked(paws)
    }

    fn checked(paws: Vec<(String, Joint)>) -> Result<Self, LabelError> {
        for (k, (name, joint)) in paws.iter().enumerate() {
            if let Some((other, _)) = paws[..k].iter().find(|(_, j)| j == joint) {
                return Err(LabelError::Mapping(format!(
                    "`{other}` and `{name}` are both the {}",
                    joint.name()
                )));
            }
        }
        if paws.is_empty() {
            return Err(LabelError::Mapping(format!(
                "names no paw (NAME=PAW, PAW one of {})",
                paw_names()
            )));
        }
        Ok(Self { paws })
    }

    /// The paws labelled in `image`: (paw, x, y).
    pub fn paws_in(&self, image: &LabelledImage) -> Vec<(Joint, f64, f64)> {
        self.paws
            .iter()
            .filter_map(|(name, joint)| image.points.get(name).map(|&(x, y)| (*joint, x, y)))
            .collect()
    }
}

/// Where the lower of two views stacked in the frames of one rig begins (a side view above a
/// bottom view seen through a mirror, as mirror rigs film them): the row, between the lowest
/// label of the upper view in any frame (`above`) and the highest label of the lower view in
/// any frame (`below`), where the rows' mean brightness changes most from one row to the next,
/// over all the frames (the mirror's edge, which stays where the rig put it while the mouse
/// moves). `None` when the labels leave no row between them or no frame is given.
pub fn lower_view_top(frames: &[image::GrayImage], above: f64, below: f64) -> Option<u32> {
    let (width, height) = frames.first()?.dimensions();
    let first = (above.max(0.0).ceil() as u32 + 1).min(height);
    let last = (below.floor().max(0.0) as u32).min(height.saturating_sub(1));
    if first >= last || width == 0 {
        return None;
    }
    let same: Vec<&image::GrayImage> = frames.iter().filter(|f| f.dimensions() == (width, height)).collect();
    let mean = |f: &image::GrayImage, y: u32| {
        (0..width).map(|x| f64::from(f.get_pixel(x, y)[0])).sum::<f64>() / f64::from(width)
    };
    (first..=last)
        .map(|y| (y, same.iter().map(|f| (mean(f, y) - mean(f, y - 1)).abs()).sum::<f64>()))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(y, _)| y)
}

fn paw_names() -> String {
    Joint::PAWS.map(Joint::name).join(", ")
}

/// The paw a body-part name says, if it says one: a side (`L`/`left`, `R`/`right`) and an
/// end (`F`/`fore`/`front`, `H`/`hind`/`back`), as letters side by side (`LF`, `RH`) or as
/// words in any order.
fn names_paw(name: &str) -> Option<Joint> {
    let lower = name.to_ascii_lowercase();
    let words: Vec<&str> = lower
        .split(|c: char| !c.is_ascii_alphabetic())
        .filter(|w| !w.is_empty())
        .collect();
    let has = |options: &[&str]| words.iter().any(|w| options.iter().any(|o| w.contains(o)));
    // Letters side by side, as in `paw2LF`: upper case in the name, after a letter or digit.
    let letters = name.as_bytes().windows(2).find_map(|w| match (w[0], w[1]) {
        (b'L' | b'R', b'F' | b'H') => Some((w[0] == b'L', w[1] == b'F')),
        _ => None,
    });
    let (left, fore) = match letters {
        Some(found) => found,
        None => {
            let left = has(&["left"]);
            let right = has(&["right"]);
            let fore = has(&["fore", "front"]);
            let hind = has(&["hind", "back", "rear"]);
            if left == right || fore == hind || !has(&["paw", "foot", "feet", "hand", "limb", "leg"]) {
                return None;
            }
            (left, fore)
        }
    };
    Some(match (left, fore) {
        (true, true) => Joint::LeftForePaw,
        (false, true) => Joint::RightForePaw,
        (true, false) => Joint::LeftHindPaw,
        (false, false) => Joint::RightHindPaw,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("CollectedData_lab.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    const GOOD: &str = "scorer,,,lab,lab,lab,lab\n\
        bodyparts,,,LF,LF,nose,nose\n\
        coords,,,x,y,x,y\n\
        labeled-data,vid1,img001.png,10.5,20,,\n\
        labeled-data,vid1,img002.png,,,3,4\n";

    #[test]
    fn a_collected_data_file_with_three_index_columns_is_read() {
        let (_dir, path) = write(GOOD);
        let table = read_dlc_csv(&path).unwrap();
        assert_eq!(table.scorer, "lab");
        assert_eq!(table.parts, ["LF", "nose"]);
        assert_eq!(table.images.len(), 2);
        assert_eq!(table.images[0].image, Path::new("labeled-data/vid1/img001.png"));
        assert_eq!(table.images[0].points["LF"], (10.5, 20.0));
        assert!(!table.images[0].points.contains_key("nose"));
        assert_eq!(table.images[1].points["nose"], (3.0, 4.0));
    }

    #[test]
    fn a_wrong_file_is_refused_naming_the_line_and_what_is_wrong() {
        for (text, says) in [
            (
                "bodyparts,LF,LF\ncoords,x,y\nimg.png,1,2\n",
                "line 1: starts with `bodyparts`",
            ),
            (
                "scorer,a,a\nbodyparts,LF,LF\ncoords,x,y\nimg.png,1,two\n",
                "line 4: `two` for `LF`",
            ),
            (
                "scorer,a,a\nbodyparts,LF,LF\ncoords,x,y\nimg.png,1\n",
                "line 4: 2 cells where the header has 3",
            ),
            (
                "scorer,a,a\nbodyparts,LF,LF\ncoords,x,y\nimg.png,1,\n",
                "line 4: `LF` has one coordinate",
            ),
            (
                "scorer,a,a\nbodyparts,LF,LF\ncoords,y,x\nimg.png,1,2\n",
                "line 3: the `coords` row",
            ),
            ("scorer,a,a\nbodyparts,LF,LF\ncoords,x,y\n", "no labelled image"),
        ] {
            let (_dir, path) = write(text);
            let e = read_dlc_csv(&path).unwrap_err().to_string();
            assert!(
                e.contains("CollectedData_lab.csv") && e.contains(says),
                "{e} (wanted {says})"
            );
        }
    }

    #[test]
    fn paws_are_guessed_from_the_names_labs_give_them_or_said() {
        let parts = |names: &[&str]| names.iter().map(|n| (*n).to_owned()).collect::<Vec<_>>();
        let lp = parts(&[
            "nose",
            "forepaw_left",
            "right_front_paw",
            "hindpaw_L",
            "right hind foot",
        ]);
        // `hindpaw_L` says no side in words: not guessed.
        assert!(PawMap::guess(&lp).is_err());
        let lp = parts(&[
            "nose",
            "forepaw_left",
            "right_front_paw",
            "left_hindpaw",
            "right hind foot",
        ]);
        let map = PawMap::guess(&lp).unwrap();
        assert_eq!(map.paws[0], ("forepaw_left".to_owned(), Joint::LeftForePaw));
        assert_eq!(map.paws[3], ("right hind foot".to_owned(), Joint::RightHindPaw));
        // Two views of the same paw: the lab says which.
        let two = parts(&[
            "paw1LH_top",
            "paw2LF_top",
            "paw1LH_bot",
            "paw2LF_bot",
            "paw3RF_bot",
            "paw4RH_bot",
        ]);
        let e = PawMap::guess(&two).unwrap_err().to_string();
        assert!(
            e.contains("paw2LF_top, paw2LF_bot all look like the left_fore_paw"),
            "{e}"
        );
        let said =
            "paw1LH_bot=left_hind_paw, paw2LF_bot=left_fore_paw,paw3RF_bot=right_fore_paw,paw4RH_bot=right_hind_paw";
        let map = PawMap::parse(said, &two).unwrap();
        assert_eq!(map.paws.len(), 4);
        for (text, says) in [
            ("paw9=left_fore_paw", "no body part `paw9`"),
            ("paw1LH_bot=snout", "`snout` is not one of"),
            (
                "paw1LH_bot=left_hind_paw,paw1LH_top=left_hind_paw",
                "are both the left_hind_paw",
            ),
            ("paw1LH_bot", "is not NAME=PAW"),
        ] {
            let e = PawMap::parse(text, &two).unwrap_err().to_string();
            assert!(e.contains(says), "{e} (wanted {says})");
        }
    }

    /// The labels of a real lab's frames (Lightning Pose's mirror-mouse example, beside the
    /// repository when it is there): read whole, the bottom view's paws mapped.
    #[test]
    fn the_real_mirror_mouse_labels_are_read() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/realdata/mirror-mouse/CollectedData.csv");
        if !path.is_file() {
            eprintln!("skipped: the real data is not beside the repository");
            return;
        }
        let table = read_dlc_csv(&path).unwrap();
        assert_eq!(table.images.len(), 45);
        let said =
            "paw1LH_bot=left_hind_paw,paw2LF_bot=left_fore_paw,paw3RF_bot=right_fore_paw,paw4RH_bot=right_hind_paw";
        let map = PawMap::parse(said, &table.parts).unwrap();
        let paws: usize = table.images.iter().map(|i| map.paws_in(i).len()).sum();
        assert!(paws > 150, "{paws} paws labelled");
        // Every bottom-view paw lies below every top-view label of its frame, and the mirror's
        // edge between them is found on the same row in every frame (about y = 170: the
        // README of the data says "to about y = 170").
        let (mut above, mut below, mut frames) = (f64::MIN, f64::MAX, Vec::new());
        for image in &table.images {
            let top = image
                .points
                .iter()
                .filter(|(p, _)| p.ends_with("_top"))
                .map(|(_, &(_, y))| y);
            let lowest_top = top.fold(f64::MIN, f64::max);
            let highest_paw = map.paws_in(image).iter().map(|&(_, _, y)| y).fold(f64::MAX, f64::min);
            assert!(highest_paw > lowest_top, "{:?}", image.image);
            (above, below) = (above.max(lowest_top), below.min(highest_paw));
            let file = path.parent().unwrap().join(&image.image);
            frames.push(image::open(&file).unwrap().to_luma8());
        }
        let top = lower_view_top(&frames, above, below).unwrap();
        assert!(
            (165..=172).contains(&top),
            "the bottom view begins at row {top} ({above}..{below})"
        );
        // Each frame alone finds it there too, but for a few whose side-view labels lie high
        // (the wheel's edge, higher up, then changes more).
        let alone = frames
            .iter()
            .zip(&table.images)
            .filter(|(f, image)| {
                let lowest_top = image
                    .points
                    .iter()
                    .filter(|(p, _)| p.ends_with("_top"))
                    .map(|(_, &(_, y))| y);
                let below = map.paws_in(image).iter().map(|&(_, _, y)| y).fold(f64::MAX, f64::min);
                lower_view_top(std::slice::from_ref(*f), lowest_top.fold(f64::MIN, f64::max), below)
                    .is_some_and(|t| t.abs_diff(top) <= 2)
            })
            .count();
        assert!(alone >= 40, "{alone} of 45 frames alone");
    }
}
