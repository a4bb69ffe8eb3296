//! CSV files, written and read with the `csv` crate and serde: every table mousepose writes
//! (`poses.csv`, a session's `timestamps.csv` and truth, `batch.csv`, the tables of reports and
//! evaluations) and every one it reads back. Fields holding a comma, a quote or a line break
//! are quoted, and read back whole.
//!
//! Numbers keep the text they have always had, so files stay byte for byte what earlier
//! versions wrote: [`Exact`] writes a float the way Rust prints it (shortest text that reads
//! back to the same value), [`Fixed`] with a set number of decimals. An `Option` that is
//! `None` is an empty field.

use serde::Serialize;

/// A float written as Rust prints it (`{}`): the shortest text that reads back exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exact(pub f64);

impl Serialize for Exact {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(&self.0)
    }
}

/// A float written with `DECIMALS` decimals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fixed<const DECIMALS: usize>(pub f64);

impl<const DECIMALS: usize> Serialize for Fixed<DECIMALS> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(&format_args!("{:.*}", DECIMALS, self.0))
    }
}

/// The bytes a row is first written into: a session's `timestamps.csv` row fits.
const LINE_BUFFER: usize = 128;

/// The CSV line of one row (a struct, tuple or sequence of fields), with its `\n`. Called
/// for every frame a session records, so the writer's own buffer is kept small (a longer row
/// goes through it in pieces) instead of the crate's 8 KiB.
///
/// # Errors
/// A field is not a scalar (a nested struct or sequence).
pub fn line(row: &impl Serialize) -> Result<Vec<u8>, csv::Error> {
    let mut writer = csv::WriterBuilder::new()
        .has_headers(false)
        .buffer_capacity(LINE_BUFFER)
        .from_writer(Vec::with_capacity(LINE_BUFFER));
    writer.serialize(row)?;
    writer.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// A whole table: the header `columns`, then one line per row (a struct, tuple or sequence
/// of as many fields).
///
/// # Errors
/// A field is not a scalar.
pub fn table<T: Serialize>(columns: &[&str], rows: &[T]) -> Result<Vec<u8>, csv::Error> {
    let mut writer = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
    writer.write_record(columns)?;
    for row in rows {
        writer.serialize(row)?;
    }
    writer.into_inner().map_err(|e| csv::Error::from(e.into_error()))
}

/// A reader of CSV `text` whose first record is its header; every record must have the
/// header's number of fields.
pub fn reader(text: &[u8]) -> csv::Reader<&[u8]> {
    csv::ReaderBuilder::new().has_headers(true).from_reader(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Serialize, serde::Deserialize, Debug, PartialEq)]
    struct Row {
        name: String,
        n: Option<u64>,
        mm: f64,
    }

    #[test]
    fn numbers_keep_their_text_and_none_is_empty() {
        let row = (
            1u64,
            None::<u64>,
            Exact(0.1 + 0.2),
            Exact(1.0),
            Fixed::<2>(2.0 / 3.0),
            "ok",
        );
        assert_eq!(line(&row).unwrap(), b"1,,0.30000000000000004,1,0.67,ok\n");
        // A sequence inside a row continues the row.
        assert_eq!(line(&(7u64, vec![Exact(1.5), Exact(-2.0)])).unwrap(), b"7,1.5,-2\n");
    }

    #[test]
    fn fields_with_commas_quotes_and_line_breaks_read_back_whole() {
        let rows = vec![
            Row {
                name: "a, \"b\"\nc".to_owned(),
                n: Some(3),
                mm: 1.5,
            },
            Row {
                name: "plain".to_owned(),
                n: None,
                mm: -2.0,
            },
        ];
        let bytes = table(&["name", "n", "mm"], &rows).unwrap();
        assert!(bytes.starts_with(b"name,n,mm\n\"a, \"\"b\"\"\nc\",3,1.5\n"));
        let back: Vec<Row> = reader(&bytes).deserialize().collect::<Result<_, _>>().unwrap();
        assert_eq!(back, rows);
    }

    #[test]
    fn an_empty_table_still_has_its_header() {
        assert_eq!(table::<Row>(&["name", "n", "mm"], &[]).unwrap(), b"name,n,mm\n");
    }
}
