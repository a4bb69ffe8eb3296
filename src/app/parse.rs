//! The command line's value parsers: a flag's value checked where clap reads it, refused in
//! one sentence that names what was expected.

/// `s` as a `T` within `lo..=hi` (what a flag takes, named by `what`).
pub fn ranged<T>(s: &str, what: &str, lo: T, hi: T) -> Result<T, String>
where
    T: std::str::FromStr + PartialOrd + std::fmt::Display + Copy,
{
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| format!("expected {what} from {lo} to {hi}, got {s:?}"))?;
    // A value that compares with nothing (a float's `nan`) is outside the range too.
    use std::cmp::Ordering::{Equal, Greater, Less};
    let inside =
        matches!(v.partial_cmp(&lo), Some(Greater | Equal)) && matches!(v.partial_cmp(&hi), Some(Less | Equal));
    if !inside {
        return Err(format!("expected {what} from {lo} to {hi}, got {s}"));
    }
    Ok(v)
}

/// A number of images.
pub fn images(s: &str) -> Result<u64, String> {
    ranged(s, "a whole number of images", 1, 10_000_000)
}

/// A duration in seconds, above 0 and at most a day.
pub fn seconds(s: &str) -> Result<f64, String> {
    let v = ranged(s, "a number of seconds", 0.0, 86_400.0)?;
    if v <= 0.0 {
        return Err(format!("expected a number of seconds above 0, got {s}"));
    }
    Ok(v)
}

/// A fraction of a data set, above 0 and at most 1.
pub fn subset(s: &str) -> Result<f64, String> {
    let v = ranged(s, "a fraction of the data set", 0.0, 1.0)?;
    if v <= 0.0 {
        return Err(format!("expected a fraction of the data set above 0, got {s}"));
    }
    Ok(v)
}

/// A frame rate.
pub fn fps(s: &str) -> Result<f64, String> {
    ranged(s, "a frame rate", 1.0, 1000.0)
}

/// A depth noise level in millimetres.
pub fn noise_mm(s: &str) -> Result<f64, String> {
    ranged(s, "a noise level in millimetres", 0.0, 100.0)
}

/// The side of a chessboard square in millimetres.
pub fn square_mm(s: &str) -> Result<f64, String> {
    ranged(s, "a square side in millimetres", 0.5, 1000.0)
}

/// A binning factor: 1, 2 or 4.
/// Pixels per millimetre on the glass or floor.
pub fn px_per_mm(s: &str) -> Result<f64, String> {
    ranged(s, "pixels per millimetre", 0.05, 50.0)
}

pub fn binning(s: &str) -> Result<u32, String> {
    match s.trim() {
        "1" => Ok(1),
        "2" => Ok(2),
        "4" => Ok(4),
        other => Err(format!("expected a binning factor of 1, 2 or 4, got {other:?}")),
    }
}

/// A live stream's endpoint: `tcp://IP:PORT` or `ipc://PATH`.
pub fn endpoint(s: &str) -> Result<crate::runtime::stream::Endpoint, String> {
    s.parse()
        .map_err(|e: crate::runtime::stream::EndpointError| e.to_string())
}
