//! The timestamp file, `depth_ts.txt`: one or two columns of milliseconds a line, read into
//! nanoseconds exactly ([`ns_from_ms`]), and refused at the first line that goes back in time
//! ([`parse_timestamps`]).

use super::MoseqError;
use std::path::Path;

/// One line of `depth_ts.txt`, in nanoseconds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MoseqTimestamp {
    /// The first column.
    pub device_ns: u64,
    /// The second column, when the file has two.
    pub system_ns: Option<u64>,
}

/// Parses `depth_ts.txt` (see the module documentation); `path` only names the file in errors.
///
/// # Errors
/// A line that is not one or two non-negative numbers, a column count that changes, or a
/// timestamp smaller than the one on the line before.
pub fn parse_timestamps(text: &str, path: &Path) -> Result<Vec<MoseqTimestamp>, MoseqError> {
    let mut out: Vec<MoseqTimestamp> = Vec::new();
    let mut columns = None;
    let mut previous: Option<(&str, &str)> = None;
    for (index, line) in text.lines().enumerate() {
        let line_no = index + 1;
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        let n = fields.len();
        if !(1..=2).contains(&n) || columns.is_some_and(|c| c != n) {
            return Err(MoseqError::Columns {
                path: path.to_owned(),
                line: line_no,
                columns: n,
            });
        }
        columns = Some(n);
        let parse = |text: &str| {
            ns_from_ms(text).ok_or_else(|| MoseqError::BadTimestamp {
                path: path.to_owned(),
                line: line_no,
                text: text.to_owned(),
            })
        };
        let device_text = fields.first().copied().unwrap_or_default();
        let system_text = fields.get(1).copied();
        let stamp = MoseqTimestamp {
            device_ns: parse(device_text)?,
            system_ns: system_text.map(parse).transpose()?,
        };
        if let (Some(last), Some((last_device, last_system))) = (out.last(), previous) {
            let disorder = if stamp.device_ns < last.device_ns {
                Some((last_device, device_text))
            } else if stamp.system_ns < last.system_ns {
                Some((last_system, system_text.unwrap_or_default()))
            } else {
                None
            };
            if let Some((previous_ms, this_ms)) = disorder {
                return Err(MoseqError::OutOfOrder {
                    path: path.to_owned(),
                    line: line_no,
                    previous_ms: previous_ms.to_owned(),
                    this_ms: this_ms.to_owned(),
                });
            }
        }
        previous = Some((device_text, system_text.unwrap_or_default()));
        out.push(stamp);
    }
    Ok(out)
}

/// A non-negative decimal number of milliseconds (`1234`, `1234.5678`, `1.5e3`) in nanoseconds.
/// Plain decimals are converted exactly (digits past the nanosecond are truncated); numbers in
/// exponent notation go through `f64`.
pub fn ns_from_ms(text: &str) -> Option<u64> {
    if text.contains(['e', 'E']) {
        let ms: f64 = text.parse().ok()?;
        let ns = (ms * 1e6).round();
        return (ns.is_finite() && ns >= 0.0 && ns < u64::MAX as f64).then_some(ns as u64);
    }
    let text = text.strip_prefix('+').unwrap_or(text);
    let (int, frac) = text.split_once('.').unwrap_or((text, ""));
    if int.is_empty() && frac.is_empty() {
        return None;
    }
    if !int.bytes().chain(frac.bytes()).all(|b| b.is_ascii_digit()) {
        return None;
    }
    let int_ms: u64 = if int.is_empty() { 0 } else { int.parse().ok()? };
    let mut frac_ns = 0u64;
    for (i, digit) in frac.bytes().take(6).enumerate() {
        frac_ns += u64::from(digit - b'0') * 10u64.pow(5 - i as u32);
    }
    int_ms.checked_mul(1_000_000)?.checked_add(frac_ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn milliseconds_convert_exactly() {
        assert_eq!(ns_from_ms("0"), Some(0));
        assert_eq!(ns_from_ms("1234"), Some(1_234_000_000));
        assert_eq!(ns_from_ms("1234.5678"), Some(1_234_567_800));
        assert_eq!(ns_from_ms("1.0000019"), Some(1_000_001));
        assert_eq!(ns_from_ms(".5"), Some(500_000));
        assert_eq!(ns_from_ms("1.5e3"), Some(1_500_000_000));
        for bad in ["", ".", "-1", "1,5", "abc", "1.2.3", "NaN"] {
            assert_eq!(ns_from_ms(bad), None, "{bad}");
        }
    }

    #[test]
    fn one_and_two_columns_parse() {
        let path = Path::new("depth_ts.txt");
        let one = parse_timestamps("10\n43.5\n\n77\n", path).unwrap();
        assert_eq!(one.len(), 3);
        assert_eq!(
            one[1],
            MoseqTimestamp {
                device_ns: 43_500_000,
                system_ns: None
            }
        );
        let two = parse_timestamps("10 1000.25\n43 1033\n", path).unwrap();
        assert_eq!(two[0].system_ns, Some(1_000_250_000));
        let err = parse_timestamps("10 1\n20\n", path).unwrap_err();
        assert!(matches!(err, MoseqError::Columns { line: 2, .. }), "{err}");
        let err = parse_timestamps("10 100\n20 90\n", path).unwrap_err();
        assert!(matches!(err, MoseqError::OutOfOrder { line: 2, .. }), "{err}");
    }
}
