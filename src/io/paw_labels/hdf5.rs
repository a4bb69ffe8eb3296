//! Label files kept as HDF5 (read through the HDF5 library, Debian's `libhdf5`):
//!
//! - DeepLabCut's `CollectedData_*.h5`: the labels' table as pandas writes a DataFrame in its
//!   fixed format. A group (DeepLabCut's key `df_with_missing`, napari's `keypoints`) holds
//!   the column index (`axis0`: the levels `scorer`, optionally `individuals`, `bodyparts`
//!   and `coords`, each as the level's values and a code per column), the row index
//!   (`axis1`: the image paths, as one level or as the path's parts), and the values in
//!   blocks (`block0_values`, its columns named by `block0_items`).
//! - SLEAP's `.slp`: the skeleton's node names in the JSON of `metadata`, then tables of
//!   labelled frames (`frames`), instances (`instances`) and points (`points`), and the
//!   videos (`videos_json`): a list of images, a video file, or pictures kept in the file
//!   itself (a `.pkg.slp`: `video0/video` and its `frame_numbers`). Only instances a person
//!   placed are labels; predicted ones are left out.

use super::{FrameSource, LabelError, LabelTable, LabelledImage};
use hdf5_metno as h5;
use hdf5_metno::types::{FixedAscii, FixedUnicode, TypeDescriptor, VarLenArray, VarLenAscii, VarLenUnicode};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The longest string of a table index read (image paths, body-part names).
const LONGEST_NAME: usize = 1024;
/// The longest JSON document read from an attribute (SLEAP's metadata: the skeletons).
const LONGEST_JSON: usize = 1 << 22;

fn opened(path: &Path) -> Result<h5::File, LabelError> {
    std::fs::File::open(path).map_err(|error| LabelError::Io {
        path: path.to_owned(),
        error,
    })?;
    h5::File::open(path).map_err(|_| wrong(path, "its first bytes", "not an HDF5 file"))
}

/// The error of a table of `path`.
fn wrong(path: &Path, place: impl Into<String>, what: impl Into<String>) -> LabelError {
    LabelError::Table {
        path: path.to_owned(),
        place: place.into(),
        what: what.into(),
    }
}

/// The strings of a dataset or attribute of strings, whatever HDF5 string type it has.
fn strings(container: &h5::Container, longest: usize) -> Result<Vec<String>, String> {
    fn fixed<const N: usize>(c: &h5::Container, unicode: bool) -> h5::Result<Vec<String>> {
        Ok(if unicode {
            c.read_raw::<FixedUnicode<N>>()?
                .iter()
                .map(|s| s.as_str().to_owned())
                .collect()
        } else {
            c.read_raw::<FixedAscii<N>>()?
                .iter()
                .map(|s| s.as_str().to_owned())
                .collect()
        })
    }
    let descriptor = container
        .dtype()
        .and_then(|t| t.to_descriptor())
        .map_err(|e| e.to_string())?;
    let read = match descriptor {
        TypeDescriptor::FixedAscii(n) | TypeDescriptor::FixedUnicode(n) if n > longest => {
            return Err(format!("strings of {n} bytes, more than the {longest} read"));
        }
        TypeDescriptor::FixedAscii(n) | TypeDescriptor::FixedUnicode(n) => {
            let unicode = matches!(descriptor, TypeDescriptor::FixedUnicode(_));
            if n <= LONGEST_NAME {
                fixed::<LONGEST_NAME>(container, unicode)
            } else {
                fixed::<LONGEST_JSON>(container, unicode)
            }
        }
        TypeDescriptor::VarLenAscii => container
            .read_raw::<VarLenAscii>()
            .map(|v| v.iter().map(|s| s.as_str().to_owned()).collect()),
        TypeDescriptor::VarLenUnicode => container
            .read_raw::<VarLenUnicode>()
            .map(|v| v.iter().map(|s| s.as_str().to_owned()).collect()),
        other => return Err(format!("{other} where strings belong")),
    };
    read.map_err(|e| e.to_string())
}

/// The one string of an attribute.
fn string_attr(location: &h5::Location, name: &str, longest: usize) -> Option<String> {
    let attr = location.attr(name).ok()?;
    strings(&attr, longest).ok()?.into_iter().next()
}

/// Reads DeepLabCut's `CollectedData_*.h5`.
///
/// # Errors
/// [`LabelError::Io`] when it cannot be read; [`LabelError::Table`] naming the table or
/// row when it is not HDF5, holds no DataFrame of DeepLabCut's labels, or a coordinate is wrong.
pub fn read_dlc_h5(path: &Path) -> Result<LabelTable, LabelError> {
    let file = opened(path)?;
    let (frame, key) = dataframe(path, &file)?;
    let frame = &frame;
    let table = |what: &str| format!("table `{key}/{what}`");
    let columns = index(path, frame, &key, "axis0")?;
    let Some(column_names) = part_and_coordinate(&columns) else {
        return Err(wrong(
            path,
            table("axis0"),
            format!(
                "its columns' levels are {}, not DeepLabCut's `scorer`, `bodyparts` and `coords`",
                columns
                    .iter()
                    .map(|(n, _)| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    };
    let scorer = columns
        .iter()
        .find(|(n, _)| n == "scorer")
        .and_then(|(_, v)| v.first().cloned())
        .unwrap_or_default();
    let rows = index(path, frame, &key, "axis1")?;
    let n_rows = rows.first().map_or(0, |(_, v)| v.len());
    let images: Vec<PathBuf> = (0..n_rows)
        .map(|r| {
            rows.iter()
                .map(|(_, v)| v[r].as_str())
                .filter(|s| !s.is_empty())
                .collect()
        })
        .collect();
    let mut parts: Vec<String> = Vec::new();
    for (part, _) in column_names {
        if !parts.contains(&part) {
            parts.push(part);
        }
    }
    let values = block_columns(path, frame, &key, n_rows)?;
    let mut labelled = Vec::with_capacity(n_rows);
    for (r, image) in images.into_iter().enumerate() {
        let place = || format!("row {} (`{}`)", r + 1, image.display());
        let mut points = BTreeMap::new();
        for part in &parts {
            let coordinate = |c: &str| values.get(&(part.clone(), c.to_owned())).map(|v| v[r]);
            let (Some(x), Some(y)) = (coordinate("x"), coordinate("y")) else {
                return Err(wrong(path, table("axis0"), format!("`{part}` has no x and y columns")));
            };
            match (x.is_nan(), y.is_nan()) {
                (true, true) => {}
                (false, false) if x.is_finite() && y.is_finite() => {
                    points.insert(part.clone(), (x, y));
                }
                (false, false) => return Err(wrong(path, place(), format!("`{part}` is at ({x}, {y})"))),
                _ => {
                    return Err(wrong(
                        path,
                        place(),
                        format!("`{part}` has one coordinate without the other"),
                    ));
                }
            }
        }
        labelled.push(LabelledImage {
            source: FrameSource::File(image.clone()),
            image,
            points,
        });
    }
    if labelled.is_empty() {
        return Err(wrong(path, format!("table `{key}`"), "it has no row"));
    }
    Ok(LabelTable {
        path: path.to_owned(),
        scorer,
        parts,
        images: labelled,
    })
}

/// The group of `file` that holds the DataFrame pandas wrote in its fixed format, and its key.
fn dataframe(path: &Path, file: &h5::File) -> Result<(h5::Group, String), LabelError> {
    let groups = file.groups().map_err(|e| wrong(path, "its top level", e.to_string()))?;
    let (frame, pandas_type) = groups
        .into_iter()
        .find_map(|g| string_attr(&g, "pandas_type", 64).map(|t| (g, t)))
        .ok_or_else(|| {
            wrong(
                path,
                "its top level",
                "no table written by pandas (DeepLabCut's `df_with_missing`) is in it",
            )
        })?;
    let key = frame.name().trim_start_matches('/').to_owned();
    match pandas_type.as_str() {
        "frame" => Ok((frame, key)),
        "frame_table" => Err(wrong(
            path,
            format!("table `{key}`"),
            "it is in pandas' `table` format; save it in the fixed format DeepLabCut writes (`to_hdf(..., format=\"fixed\")`) or as CSV",
        )),
        other => Err(wrong(
            path,
            format!("table `{key}`"),
            format!("pandas wrote a `{other}`, not a DataFrame"),
        )),
    }
}

/// The columns of a DataFrame's value blocks: (part, coordinate) -> the column's values, one
/// per row of its `n_rows`.
fn block_columns(
    path: &Path,
    frame: &h5::Group,
    key: &str,
    n_rows: usize,
) -> Result<BTreeMap<(String, String), Vec<f64>>, LabelError> {
    let blocks = frame
        .attr("nblocks")
        .and_then(|a| a.read_scalar::<i64>())
        .map_err(|e| wrong(path, format!("table `{key}`"), format!("no block count ({e})")))?;
    let mut values = BTreeMap::new();
    for b in 0..blocks {
        let items = index(path, frame, key, &format!("block{b}_items"))?;
        let dataset_name = format!("block{b}_values");
        let place = format!("table `{key}/{dataset_name}`");
        let dataset = frame
            .dataset(&dataset_name)
            .map_err(|e| wrong(path, place.clone(), e.to_string()))?;
        let numbers: Vec<f64> = dataset
            .read_raw()
            .map_err(|e| wrong(path, place.clone(), format!("its values are not numbers ({e})")))?;
        let n_items = items.first().map_or(0, |(_, v)| v.len());
        // pandas keeps a block's values one row of the table after another (`transposed`);
        // by the shape when it tells.
        let transposed = match dataset.shape()[..] {
            [r, i] if r == n_rows && i == n_items && r != i => true,
            [i, r] if r == n_rows && i == n_items && r != i => false,
            [r, i] if r == n_rows && i == n_items => dataset
                .attr("transposed")
                .and_then(|a| a.read_scalar::<u8>())
                .map_or(true, |t| t != 0),
            _ => {
                return Err(wrong(
                    path,
                    place,
                    format!(
                        "its shape is {:?}, and the table has {n_rows} rows and {n_items} of these columns",
                        dataset.shape()
                    ),
                ));
            }
        };
        let Some(item_names) = part_and_coordinate(&items) else {
            return Err(wrong(
                path,
                place,
                "its columns are not named by body part and coordinate",
            ));
        };
        for (i, name) in item_names.into_iter().enumerate() {
            let column = (0..n_rows)
                .map(|r| {
                    if transposed {
                        numbers[r * n_items + i]
                    } else {
                        numbers[i * n_rows + r]
                    }
                })
                .collect();
            values.insert(name, column);
        }
    }
    Ok(values)
}

/// The (body part, coordinate) of each column of a DeepLabCut column index: its levels
/// `bodyparts` and `coords`, the part named `individual/part` where an `individuals` level
/// names one. `None` without those levels.
fn part_and_coordinate(index: &[(String, Vec<String>)]) -> Option<Vec<(String, String)>> {
    let level = |name: &str| index.iter().find(|(n, _)| n == name).map(|(_, v)| v);
    let (parts, coords) = (level("bodyparts")?, level("coords")?);
    let individuals = level("individuals");
    Some(
        parts
            .iter()
            .zip(coords)
            .enumerate()
            .map(|(c, (part, coord))| {
                let part = match individuals.map(|i| &i[c]) {
                    Some(individual) if !individual.is_empty() => format!("{individual}/{part}"),
                    _ => part.clone(),
                };
                (part, coord.clone())
            })
            .collect(),
    )
}

/// A pandas index kept in the fixed format: its levels, each with its name and the value of
/// every entry (empty where pandas kept no value).
fn index(path: &Path, frame: &h5::Group, key: &str, axis: &str) -> Result<Vec<(String, Vec<String>)>, LabelError> {
    let place = |what: &str| format!("table `{key}/{what}`");
    let level = |name: &str| -> Result<(String, Vec<String>), LabelError> {
        let dataset = frame
            .dataset(name)
            .map_err(|e| wrong(path, place(name), e.to_string()))?;
        let values = strings(&dataset, LONGEST_NAME).map_err(|e| wrong(path, place(name), e))?;
        let named = string_attr(&dataset, "name", LONGEST_NAME).unwrap_or_default();
        Ok((named, values))
    };
    match string_attr(frame, &format!("{axis}_variety"), 64).as_deref() {
        Some("regular") => Ok(vec![level(axis)?]),
        Some("multi") => {
            let levels = frame
                .attr(&format!("{axis}_nlevels"))
                .and_then(|a| a.read_scalar::<i64>())
                .map_err(|e| wrong(path, place(axis), format!("no level count ({e})")))?;
            let mut out = Vec::new();
            for l in 0..levels {
                let (named, values) = level(&format!("{axis}_level{l}"))?;
                let label = format!("{axis}_label{l}");
                let codes: Vec<i64> = frame
                    .dataset(&label)
                    .and_then(|d| d.read_raw())
                    .map_err(|e| wrong(path, place(&label), e.to_string()))?;
                let entries = codes
                    .iter()
                    .map(|&c| {
                        usize::try_from(c)
                            .ok()
                            .map_or(Some(String::new()), |c| values.get(c).cloned())
                    })
                    .collect::<Option<Vec<_>>>()
                    .ok_or_else(|| wrong(path, place(&label), "a code names no value of its level"))?;
                out.push((named, entries));
            }
            if out.iter().any(|(_, v)| v.len() != out[0].1.len()) || out.is_empty() {
                return Err(wrong(path, place(axis), "its levels have different lengths"));
            }
            Ok(out)
        }
        other => Err(wrong(
            path,
            place(axis),
            format!("an index kept as {other:?}, not as pandas' fixed format keeps one"),
        )),
    }
}

#[derive(h5::H5Type, Clone, Copy, Debug)]
#[repr(C)]
struct SlpFrame {
    frame_id: u64,
    video: u32,
    frame_idx: u64,
    instance_id_start: u64,
    instance_id_end: u64,
}

#[derive(h5::H5Type, Clone, Copy, Debug)]
#[repr(C)]
struct SlpInstance {
    instance_type: u8,
    skeleton: u32,
    point_id_start: u64,
    point_id_end: u64,
}

#[derive(h5::H5Type, Clone, Copy, Debug)]
#[repr(C)]
struct SlpPoint {
    x: f64,
    y: f64,
    visible: bool,
}

/// Where a SLEAP video's frames are.
enum SlpVideo {
    Images(Vec<PathBuf>),
    /// In the file: the dataset of encoded pictures, and the frame number of each.
    Embedded {
        dataset: String,
        frames: Vec<i64>,
    },
    File(PathBuf),
}

/// Reads SLEAP's `.slp` (or `.pkg.slp`): the instances a person placed, one per frame.
///
/// # Errors
/// [`LabelError::Io`] when it cannot be read; [`LabelError::Table`] naming the table or
/// frame when it is not HDF5, its layout is not SLEAP's, a frame holds more than one animal, or a point is
/// not a finite number.
pub fn read_slp(path: &Path) -> Result<LabelTable, LabelError> {
    let file = opened(path)?;
    let (format_id, skeletons) = slp_skeletons(path, &file)?;
    // SLEAP before format 1.1 put a pixel's top-left corner at (0, 0); now its centre.
    let offset = if format_id < 1.1 { 0.5 } else { 0.0 };
    let table = |name: &str| format!("table `{name}`");
    let read = |name: &str| -> Result<h5::Dataset, LabelError> {
        file.dataset(name).map_err(|e| wrong(path, table(name), e.to_string()))
    };
    let frames: Vec<SlpFrame> = read("frames")?
        .read_raw()
        .map_err(|e| wrong(path, table("frames"), e.to_string()))?;
    let instances: Vec<SlpInstance> = read("instances")?
        .read_raw()
        .map_err(|e| wrong(path, table("instances"), e.to_string()))?;
    let points: Vec<SlpPoint> = read("points")?
        .read_raw()
        .map_err(|e| wrong(path, table("points"), e.to_string()))?;
    let videos = strings(&*read("videos_json")?, LONGEST_JSON)
        .map_err(|e| wrong(path, table("videos_json"), e))?
        .iter()
        .enumerate()
        .map(|(v, text)| slp_video(path, &file, v, text))
        .collect::<Result<Vec<_>, _>>()?;
    let mut parts: Vec<String> = Vec::new();
    for names in &skeletons {
        for name in names {
            if !parts.contains(name) {
                parts.push(name.clone());
            }
        }
    }
    let mut images = Vec::new();
    for (f, frame) in frames.iter().enumerate() {
        let place = || format!("frame {f} (frame {} of video {})", frame.frame_idx, frame.video);
        let user: Vec<&SlpInstance> = usize::try_from(frame.instance_id_start)
            .ok()
            .zip(usize::try_from(frame.instance_id_end).ok())
            .and_then(|(a, b)| instances.get(a..b))
            .ok_or_else(|| wrong(path, place(), "its instances are not in the table `instances`"))?
            .iter()
            .filter(|i| i.instance_type == 0)
            .collect();
        let instance = match user.as_slice() {
            [] => continue,
            [one] => *one,
            several => {
                return Err(wrong(
                    path,
                    place(),
                    format!(
                        "{} animals are labelled; paws are learnt from one mouse a frame",
                        several.len()
                    ),
                ));
            }
        };
        let labelled = slp_points(instance, &skeletons, &points, offset).map_err(|e| wrong(path, place(), e))?;
        let video = usize::try_from(frame.video)
            .ok()
            .and_then(|v| videos.get(v))
            .ok_or_else(|| wrong(path, place(), "its video is not in `videos_json`"))?;
        let (image, source) = slp_frame(path, &file, video, frame.frame_idx).map_err(|e| wrong(path, place(), e))?;
        images.push(LabelledImage {
            image,
            source,
            points: labelled,
        });
    }
    if images.is_empty() {
        return Err(wrong(
            path,
            table("instances"),
            "no frame holds an instance a person placed",
        ));
    }
    Ok(LabelTable {
        path: path.to_owned(),
        scorer: String::from("SLEAP"),
        parts,
        images,
    })
}

/// The format of a SLEAP file and its skeletons (each its nodes' names, in order), from the
/// attributes of its `metadata`.
fn slp_skeletons(path: &Path, file: &h5::File) -> Result<(f64, Vec<Vec<String>>), LabelError> {
    let format_id = file
        .group("metadata")
        .and_then(|m| m.attr("format_id"))
        .and_then(|a| a.read_scalar::<f64>())
        .map_err(|_| {
            wrong(
                path,
                "its top level",
                "no `format_id` in `metadata`: not a SLEAP labels file",
            )
        })?;
    let metadata = file
        .group("metadata")
        .map_err(|e| wrong(path, "`metadata`", e.to_string()))?;
    let json = string_attr(&metadata, "json", LONGEST_JSON)
        .ok_or_else(|| wrong(path, "`metadata`", "no `json` with the skeleton"))?;
    let meta: serde_json::Value =
        serde_json::from_str(&json).map_err(|e| wrong(path, "`metadata`", format!("its JSON does not parse ({e})")))?;
    let node_names: Vec<String> = meta["nodes"]
        .as_array()
        .map(|n| {
            n.iter()
                .map(|n| n["name"].as_str().unwrap_or_default().to_owned())
                .collect()
        })
        .unwrap_or_default();
    let skeletons: Vec<Vec<String>> = meta["skeletons"]
        .as_array()
        .map(Vec::as_slice)
        .unwrap_or_default()
        .iter()
        .enumerate()
        .map(|(s, skeleton)| {
            skeleton["nodes"]
                .as_array()
                .map(Vec::as_slice)
                .unwrap_or_default()
                .iter()
                .map(|n| {
                    n["id"]
                        .as_u64()
                        .and_then(|i| node_names.get(usize::try_from(i).ok()?).cloned())
                        .ok_or_else(|| {
                            wrong(
                                path,
                                "`metadata`",
                                format!("skeleton {s} names a node not in its list: {n}"),
                            )
                        })
                })
                .collect()
        })
        .collect::<Result<_, _>>()?;
    if skeletons.is_empty() {
        return Err(wrong(path, "`metadata`", "it holds no skeleton"));
    }
    Ok((format_id, skeletons))
}

/// The points of an instance a person placed, by its skeleton's node names, moved by `offset`
/// to pixel centres; a point not placed (hidden, or at NaN) is left out. The error says what
/// is wrong with the instance.
fn slp_points(
    instance: &SlpInstance,
    skeletons: &[Vec<String>],
    points: &[SlpPoint],
    offset: f64,
) -> Result<BTreeMap<String, (f64, f64)>, String> {
    let names = usize::try_from(instance.skeleton)
        .ok()
        .and_then(|s| skeletons.get(s))
        .ok_or_else(|| format!("skeleton {} is not in `metadata`", instance.skeleton))?;
    let placed = usize::try_from(instance.point_id_start)
        .ok()
        .zip(usize::try_from(instance.point_id_end).ok())
        .and_then(|(a, b)| points.get(a..b))
        .filter(|p| p.len() == names.len())
        .ok_or("its points are not in the table `points`, one per node")?;
    let mut labelled = BTreeMap::new();
    for (name, point) in names.iter().zip(placed) {
        if !point.visible || (point.x.is_nan() && point.y.is_nan()) {
            continue;
        }
        if !(point.x.is_finite() && point.y.is_finite()) {
            return Err(format!("`{name}` is at ({}, {})", point.x, point.y));
        }
        labelled.insert(name.clone(), (point.x - offset, point.y - offset));
    }
    Ok(labelled)
}

/// A video of `videos_json`: its backend's `filenames` (a list of images), `dataset` (the
/// pictures kept in the file) or `filename` (a video file).
fn slp_video(path: &Path, file: &h5::File, v: usize, text: &str) -> Result<SlpVideo, LabelError> {
    let place = || format!("video {v} of `videos_json`");
    let json: serde_json::Value =
        serde_json::from_str(text).map_err(|e| wrong(path, place(), format!("its JSON does not parse ({e})")))?;
    let backend = &json["backend"];
    if let Some(list) = backend["filenames"].as_array().or_else(|| json["filename"].as_array()) {
        return Ok(SlpVideo::Images(
            list.iter()
                .map(|f| PathBuf::from(f.as_str().unwrap_or_default()))
                .collect(),
        ));
    }
    if let Some(dataset) = backend["dataset"].as_str().filter(|d| !d.is_empty())
        && file.link_exists(dataset)
    {
        let group = dataset.rsplit_once('/').map_or("", |(g, _)| g);
        let numbers = format!("{group}/frame_numbers");
        let frames = file
            .dataset(&numbers)
            .and_then(|d| d.read_raw::<i64>())
            .map_err(|e| wrong(path, place(), format!("`{numbers}`: {e}")))?;
        return Ok(SlpVideo::Embedded {
            dataset: dataset.to_owned(),
            frames,
        });
    }
    backend["filename"]
        .as_str()
        .or_else(|| json["filename"].as_str())
        .filter(|f| !f.is_empty() && *f != ".")
        .map(|f| SlpVideo::File(PathBuf::from(f)))
        .ok_or_else(|| {
            wrong(
                path,
                place(),
                "it names no images, no video file and no pictures kept in the file",
            )
        })
}

/// The name and the pixels' place of frame `index` of `video`.
fn slp_frame(path: &Path, file: &h5::File, video: &SlpVideo, index: u64) -> Result<(PathBuf, FrameSource), String> {
    let at = usize::try_from(index).map_err(|e| e.to_string())?;
    match video {
        SlpVideo::Images(list) => list
            .get(at)
            .map(|p| (p.clone(), FrameSource::File(p.clone())))
            .ok_or_else(|| format!("the video lists {} images, not {}", list.len(), at + 1)),
        SlpVideo::File(video) => Ok((
            PathBuf::from(format!("{} frame {index}", video.display())),
            FrameSource::Video {
                path: video.clone(),
                frame: index,
            },
        )),
        SlpVideo::Embedded { dataset, frames } => {
            let row = frames
                .iter()
                .position(|&f| u64::try_from(f) == Ok(index))
                .ok_or_else(|| format!("its picture is not kept in `{dataset}`"))?;
            let pictures = file.dataset(dataset).map_err(|e| e.to_string())?;
            let bytes: Vec<u8> = match pictures.ndim() {
                // One picture a row, as long as the longest, zeros after its end.
                2 => pictures
                    .read_slice_1d::<i8, _>((row, ..))
                    .map_err(|e| e.to_string())?
                    .iter()
                    .map(|&b| u8::from_ne_bytes(b.to_ne_bytes()))
                    .collect(),
                _ => pictures
                    .read_slice_1d::<VarLenArray<i8>, _>(row..=row)
                    .map_err(|e| e.to_string())?
                    .first()
                    .map(|p| p.iter().map(|&b| u8::from_ne_bytes(b.to_ne_bytes())).collect())
                    .unwrap_or_default(),
            };
            Ok((
                PathBuf::from(format!("{} {dataset} frame {index}", path.display())),
                FrameSource::Embedded(bytes),
            ))
        }
    }
}
