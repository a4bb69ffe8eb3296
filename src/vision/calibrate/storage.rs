//! OpenCV FileStorage YAML, written and read through OpenCV itself so that OpenCV users read
//! mousepose's calibration files (and mousepose reads theirs) with no conversion.
//!
//! Files are composed in memory, then written to a temporary file beside the destination and
//! renamed into place, so a crash never leaves a half-written file that looks complete.

use super::CalibrationError;
use opencv_calib::{NodeKind, StorageNode, StorageReader, StorageWriter};
use std::path::{Path, PathBuf};

/// A YAML document being composed in memory.
pub(crate) struct YamlWriter {
    fs: StorageWriter,
    path: PathBuf,
}

impl YamlWriter {
    /// A new document destined for `path` (named in errors).
    pub(crate) fn new(path: &Path) -> Result<Self, CalibrationError> {
        let fs = StorageWriter::new().map_err(|e| cv(path, "compose", e))?;
        Ok(Self {
            fs,
            path: path.to_owned(),
        })
    }

    fn err(&self, e: opencv_calib::Error) -> CalibrationError {
        cv(&self.path, "compose", e)
    }

    pub(crate) fn int(&mut self, name: &str, value: i32) -> Result<(), CalibrationError> {
        self.fs.int(name, value).map_err(|e| self.err(e))
    }

    pub(crate) fn real(&mut self, name: &str, value: f64) -> Result<(), CalibrationError> {
        self.fs.real(name, value).map_err(|e| self.err(e))
    }

    pub(crate) fn text(&mut self, name: &str, value: &str) -> Result<(), CalibrationError> {
        self.fs.text(name, value).map_err(|e| self.err(e))
    }

    pub(crate) fn texts(&mut self, name: &str, values: &[String]) -> Result<(), CalibrationError> {
        self.fs.texts(name, values).map_err(|e| self.err(e))
    }

    /// A `rows` x `cols` matrix of doubles (`!!opencv-matrix`, row-major `data`).
    pub(crate) fn matrix(
        &mut self,
        name: &str,
        rows: usize,
        cols: usize,
        data: &[f64],
    ) -> Result<(), CalibrationError> {
        self.fs.matrix(name, rows, cols, data).map_err(|e| self.err(e))
    }

    pub(crate) fn begin_map(&mut self, name: &str) -> Result<(), CalibrationError> {
        self.fs.begin_map(name).map_err(|e| self.err(e))
    }

    pub(crate) fn end_map(&mut self) -> Result<(), CalibrationError> {
        self.fs.end_map().map_err(|e| self.err(e))
    }

    /// Writes the document to its path atomically.
    pub(crate) fn finish(self) -> Result<(), CalibrationError> {
        let Self { fs, path } = self;
        let text = fs.finish().map_err(|e| cv(&path, "compose", e))?;
        write_atomically(&path, text.as_bytes())
    }
}

/// Writes `bytes` to a temporary file beside `path`, then renames it into place.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), CalibrationError> {
    let io = |source| CalibrationError::Io {
        path: path.to_owned(),
        source,
    };
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "calibration".to_owned());
    let tmp = path.with_file_name(format!(".{name}.partial-{}", std::process::id()));
    let result = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if result.is_err() {
        // Best effort: the temporary file is hidden and named as partial.
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}

fn cv(path: &Path, action: &'static str, source: opencv_calib::Error) -> CalibrationError {
    CalibrationError::OpenCv {
        path: path.to_owned(),
        action,
        source: source.into(),
    }
}

/// Calibration files are a few kilobytes; more is not a calibration.
const MAX_YAML_BYTES: u64 = 1 << 20;

/// A parsed YAML document.
pub(crate) struct YamlReader {
    fs: StorageReader,
    path: PathBuf,
}

/// A node of a document with its dotted name, for error messages.
pub(crate) struct Node<'a> {
    node: StorageNode<'a>,
    name: String,
    path: &'a Path,
}

/// The first line (1-based) holding a directive (`%...`) other than the first line's, or a
/// document marker (`---`, `...`) with more after it: OpenCV writes neither, and its YAML
/// parser (4.6) loops forever on some such files (`%YAML:1.0`, `---%:1`, `-`, `-`; found by
/// fuzzing), so they never reach it.
fn directive_out_of_place(text: &str) -> Option<usize> {
    text.lines().enumerate().skip(1).find_map(|(i, line)| {
        let marker = ["---", "..."]
            .iter()
            .any(|m| line.strip_prefix(m).is_some_and(|rest| !rest.trim().is_empty()));
        (line.starts_with('%') || marker).then_some(i + 1)
    })
}

impl YamlReader {
    /// Reads and parses the file at `path`.
    pub(crate) fn open(path: &Path) -> Result<Self, CalibrationError> {
        let text = crate::io::read_bounded(path, MAX_YAML_BYTES).map_err(|source| CalibrationError::Io {
            path: path.to_owned(),
            source,
        })?;
        if text.trim().is_empty() {
            return Err(CalibrationError::Empty(path.to_owned()));
        }
        if let Some(line) = directive_out_of_place(&text) {
            return Err(CalibrationError::Invalid {
                path: path.to_owned(),
                what: format!(
                    "line {line} holds a YAML directive or document marker where OpenCV writes none (OpenCV's parser can loop forever on one)"
                ),
            });
        }
        let fs = StorageReader::from_yaml(&text).map_err(|e| cv(path, "parse", e))?;
        if !fs.is_opened() {
            return Err(CalibrationError::Empty(path.to_owned()));
        }
        Ok(Self {
            fs,
            path: path.to_owned(),
        })
    }

    /// The top-level node `name`, if present.
    pub(crate) fn get(&self, name: &str) -> Result<Option<Node<'_>>, CalibrationError> {
        let node = self.fs.get(name).map_err(|e| cv(&self.path, "parse", e))?;
        wrap(node, name.to_owned(), &self.path)
    }

    /// The top-level node `name`.
    pub(crate) fn require(&self, name: &str) -> Result<Node<'_>, CalibrationError> {
        self.get(name)?.ok_or_else(|| CalibrationError::MissingNode {
            path: self.path.clone(),
            node: name.to_owned(),
        })
    }
}

fn wrap<'a>(node: StorageNode<'a>, name: String, path: &'a Path) -> Result<Option<Node<'a>>, CalibrationError> {
    let kind = node.kind().map_err(|e| cv(path, "parse", e))?;
    let missing = kind.is_none || kind.empty;
    Ok((!missing).then_some(Node { node, name, path }))
}

impl<'a> Node<'a> {
    fn err(&self, e: opencv_calib::Error) -> CalibrationError {
        cv(self.path, "parse", e)
    }

    fn kind(&self) -> Result<NodeKind, CalibrationError> {
        self.node.kind().map_err(|e| self.err(e))
    }

    fn wrong(&self, expected: &str) -> CalibrationError {
        CalibrationError::WrongType {
            path: self.path.to_owned(),
            node: self.name.clone(),
            expected: expected.to_owned(),
        }
    }

    /// The child `name` of this map, if present.
    pub(crate) fn get(&self, name: &str) -> Result<Option<Node<'a>>, CalibrationError> {
        if !self.kind()?.is_map {
            return Err(self.wrong("a map"));
        }
        let child = self.node.get(name).map_err(|e| self.err(e))?;
        wrap(child, format!("{}.{name}", self.name), self.path)
    }

    /// The child `name` of this map.
    pub(crate) fn require(&self, name: &str) -> Result<Node<'a>, CalibrationError> {
        self.get(name)?.ok_or_else(|| CalibrationError::MissingNode {
            path: self.path.to_owned(),
            node: format!("{}.{name}", self.name),
        })
    }

    pub(crate) fn int(&self) -> Result<i32, CalibrationError> {
        if !self.kind()?.is_int {
            return Err(self.wrong("an integer"));
        }
        self.node.int().map_err(|e| self.err(e))
    }

    pub(crate) fn real(&self) -> Result<f64, CalibrationError> {
        let kind = self.kind()?;
        if !(kind.is_real || kind.is_int) {
            return Err(self.wrong("a number"));
        }
        let v = self.node.real().map_err(|e| self.err(e))?;
        if !v.is_finite() {
            return Err(self.wrong("a finite number"));
        }
        Ok(v)
    }

    pub(crate) fn text(&self) -> Result<String, CalibrationError> {
        if !self.kind()?.is_string {
            return Err(self.wrong("a string"));
        }
        self.node.string().map_err(|e| self.err(e))
    }

    /// A sequence of numbers (or an `!!opencv-matrix` with one row or column).
    pub(crate) fn reals(&self) -> Result<Vec<f64>, CalibrationError> {
        let kind = self.kind()?;
        if kind.is_seq {
            let n = kind.size;
            let mut out = Vec::with_capacity(n);
            for i in 0..n {
                let idx = i32::try_from(i).map_err(|_| self.wrong("a shorter sequence"))?;
                let item = self.node.at(idx).map_err(|e| self.err(e))?;
                let node = Node {
                    node: item,
                    name: format!("{}[{i}]", self.name),
                    path: self.path,
                };
                out.push(node.real()?);
            }
            return Ok(out);
        }
        let (rows, cols, data) = self.any_matrix()?;
        if rows != 1 && cols != 1 {
            return Err(self.wrong("a sequence of numbers"));
        }
        Ok(data)
    }

    fn any_matrix(&self) -> Result<(i32, i32, Vec<f64>), CalibrationError> {
        if !self.kind()?.is_map {
            return Err(self.wrong("an !!opencv-matrix"));
        }
        // OpenCV's matrix as doubles; none when it is empty or has more than one channel.
        let Some(m) = self.node.matrix().map_err(|e| self.err(e))? else {
            return Err(self.wrong("an !!opencv-matrix"));
        };
        let opencv_calib::Matrix { rows, cols, data } = m;
        if data.iter().any(|v| !v.is_finite()) {
            return Err(self.wrong("a matrix of finite numbers"));
        }
        Ok((rows, cols, data))
    }

    /// An `!!opencv-matrix` of exactly `rows` x `cols`, row-major.
    pub(crate) fn matrix(&self, rows: i32, cols: i32) -> Result<Vec<f64>, CalibrationError> {
        let (r, c, data) = self.any_matrix()?;
        if (r, c) != (rows, cols) {
            return Err(CalibrationError::MatrixShape {
                path: self.path.to_owned(),
                node: self.name.clone(),
                expected: format!("{rows}x{cols}"),
                found: format!("{r}x{c}"),
            });
        }
        Ok(data)
    }
}
