//! Line files of a session (CSV and JSON lines): writing a line at a time, each handed to the
//! operating system at once, and reading back only the lines a writer finished.
//!
//! A line counts only once its `\n` is in the file: a writer killed mid-line leaves a last
//! line without one, which readers drop.

use super::{Result, SessionError, io_error};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// A line file being written.
#[derive(Debug)]
pub(crate) struct LineWriter {
    path: PathBuf,
    out: BufWriter<File>,
    lines: u64,
}

impl LineWriter {
    /// Creates the file (it must not exist) and writes `header` as its first line, if given.
    pub fn create(path: PathBuf, header: Option<&str>) -> Result<Self> {
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(io_error(&path, "create"))?;
        let mut writer = Self {
            path,
            out: BufWriter::new(file),
            lines: 0,
        };
        if let Some(header) = header {
            writer.write_line(header)?;
            writer.lines = 0;
        }
        Ok(writer)
    }

    /// Writes one line (the `\n` is added) and flushes it to the operating system.
    pub fn write_line(&mut self, line: &str) -> Result<()> {
        let mut bytes = Vec::with_capacity(line.len() + 1);
        bytes.extend_from_slice(line.as_bytes());
        bytes.push(b'\n');
        self.write_bytes(&bytes)
    }

    /// Writes one CSV row (see [`crate::io::table`]) and flushes it to the operating system.
    pub fn write_row(&mut self, row: &impl serde::Serialize) -> Result<()> {
        let bytes = crate::io::table::line(row).map_err(|source| SessionError::RowEncode {
            path: self.path.clone(),
            source,
        })?;
        self.write_bytes(&bytes)
    }

    /// A line that the buffer took is counted even when handing it to the operating system
    /// fails: it stays buffered, whole, and the next flush (a retry, [`LineWriter::sync`])
    /// writes it. (Lines are far shorter than the buffer, so one that it did not take was not
    /// written at all.)
    fn write_bytes(&mut self, bytes: &[u8]) -> Result<()> {
        self.out.write_all(bytes).map_err(io_error(&self.path, "write"))?;
        self.lines += 1;
        self.out.flush().map_err(io_error(&self.path, "write"))
    }

    /// Whether the file was removed while being written ([`crate::io::unlinked`]).
    pub fn unlinked(&self) -> bool {
        crate::io::unlinked(self.out.get_ref())
    }

    /// Whether the file was removed or moved away while being written ([`crate::io::gone`]).
    pub fn gone(&self) -> Option<crate::io::Gone> {
        crate::io::gone(self.out.get_ref(), &self.path)
    }

    /// Lines written, the header not counted.
    pub fn lines(&self) -> u64 {
        self.lines
    }

    /// Flushes and waits until the file is on disk.
    pub fn sync(&mut self) -> Result<()> {
        self.out.flush().map_err(io_error(&self.path, "write"))?;
        self.out.get_ref().sync_all().map_err(io_error(&self.path, "sync"))
    }
}

/// The longest line file read (4 GiB: ten hours of ground truth at 30 fps take under 1 GiB).
const MAX_LINE_FILE_BYTES: u64 = 4 << 30;

/// The finished lines of a file with their one-based line numbers; a last line without its
/// `\n` is left out.
pub(crate) fn read_lines(path: &Path) -> Result<Vec<(u64, String)>> {
    let bytes = crate::io::read_bounded_bytes(path, MAX_LINE_FILE_BYTES).map_err(io_error(path, "read"))?;
    let text = std::str::from_utf8(&bytes).map_err(|source| {
        let valid = bytes.get(..source.valid_up_to()).unwrap_or_default();
        SessionError::NotText {
            path: path.to_path_buf(),
            line: 1 + valid.iter().filter(|&&c| c == b'\n').count() as u64,
            source,
        }
    })?;
    let Some(end) = text.rfind('\n') else {
        return Ok(Vec::new());
    };
    let finished = text.get(..end).unwrap_or_default();
    Ok(finished
        .split('\n')
        .zip(1..)
        .map(|(line, n)| (n, line.strip_suffix('\r').unwrap_or(line).to_owned()))
        .collect())
}

/// A CSV file read back (with the `csv` crate: quoted fields read whole): its header
/// checked, its finished rows kept.
pub(crate) struct Csv {
    path: PathBuf,
    columns: Vec<String>,
    rows: Vec<(u64, csv::StringRecord)>,
}

impl Csv {
    /// Reads a CSV file whose first line must be `header`; a last row without its `\n` is
    /// left out.
    pub fn read(path: &Path, header: &str) -> Result<Self> {
        let bytes = crate::io::read_bounded_bytes(path, MAX_LINE_FILE_BYTES).map_err(io_error(path, "read"))?;
        let finished = bytes.get(..bytes.iter().rposition(|&c| c == b'\n').map_or(0, |end| end + 1));
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .from_reader(finished.unwrap_or_default());
        let text_error = |line: u64, reason: String| SessionError::Text {
            path: path.to_path_buf(),
            line,
            reason,
        };
        let mut records = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(0, csv::Position::line);
                match e.into_kind() {
                    csv::ErrorKind::Utf8 { err, .. } => text_error(line, format!("not UTF-8 text ({err})")),
                    kind => text_error(line, format!("{kind:?}")),
                }
            })?;
            let line = record.position().map_or(0, csv::Position::line);
            records.push((line, record));
        }
        let columns: Vec<String> = header.split(',').map(str::to_owned).collect();
        let found = (!records.is_empty()).then(|| records.remove(0).1);
        if found.is_none_or(|f| f.iter().ne(columns.iter().map(String::as_str))) {
            return Err(text_error(1, format!("expected the header {header:?}")));
        }
        Ok(Self {
            path: path.to_path_buf(),
            columns,
            rows: records,
        })
    }

    /// Parses each row (blank lines skipped) with `parse`, which gets the row's fields.
    pub fn rows<T>(&self, mut parse: impl FnMut(&Row<'_>) -> Result<T>) -> Result<Vec<T>> {
        let mut out = Vec::with_capacity(self.rows.len());
        for (line, record) in &self.rows {
            if record.len() == 1 && record.get(0) == Some("") {
                continue;
            }
            if record.len() != self.columns.len() {
                return Err(SessionError::Text {
                    path: self.path.clone(),
                    line: *line,
                    reason: format!("{} fields, expected {}", record.len(), self.columns.len()),
                });
            }
            out.push(parse(&Row {
                csv: self,
                line: *line,
                record,
            })?);
        }
        Ok(out)
    }
}

/// One CSV row with as many fields as the header has columns.
pub(crate) struct Row<'a> {
    csv: &'a Csv,
    line: u64,
    record: &'a csv::StringRecord,
}

impl Row<'_> {
    fn field(&self, i: usize) -> &str {
        self.record.get(i).unwrap_or_default()
    }

    fn invalid(&self, i: usize, source: Box<dyn std::error::Error + Send + Sync>) -> SessionError {
        SessionError::CsvValue {
            path: self.csv.path.clone(),
            line: self.line,
            column: self.csv.columns.get(i).cloned().unwrap_or_default(),
            source,
        }
    }

    pub fn u64(&self, i: usize) -> Result<u64> {
        self.field(i).parse().map_err(|e| self.invalid(i, Box::new(e)))
    }

    /// An integer, or `None` for an empty field.
    pub fn opt_u64(&self, i: usize) -> Result<Option<u64>> {
        if self.field(i).is_empty() {
            Ok(None)
        } else {
            self.u64(i).map(Some)
        }
    }

    pub fn f64(&self, i: usize) -> Result<f64> {
        self.field(i).parse().map_err(|e| self.invalid(i, Box::new(e)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unfinished_last_line_is_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.csv");
        for (text, lines) in [
            ("", vec![]),
            ("a", vec![]),
            ("a\n", vec!["a"]),
            ("a\nb", vec!["a"]),
            ("a\nb\n", vec!["a", "b"]),
            ("\n", vec![""]),
            ("a\r\nb\r\n", vec!["a", "b"]),
        ] {
            std::fs::write(&path, text).unwrap();
            let got: Vec<String> = read_lines(&path).unwrap().into_iter().map(|l| l.1).collect();
            assert_eq!(got, lines, "{text:?}");
        }
    }

    #[test]
    fn bad_values_name_line_and_column() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.csv");
        std::fs::write(&path, "a,b\n1,2\n3,x\n").unwrap();
        let csv = Csv::read(&path, "a,b").unwrap();
        let err = csv.rows(|r| Ok((r.u64(0)?, r.u64(1)?))).unwrap_err();
        assert_eq!(err.to_string(), format!("{}: line 3: invalid b", path.display()));
        assert!(Csv::read(&path, "a,c").is_err());
    }
}
