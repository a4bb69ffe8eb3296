//! Plain types every layer shares: frames and their stamps, the skeleton and poses, cameras and
//! the rig, the limbs' kinematics, RGB pictures, errors on one line. Nothing here reads a file,
//! a clock or a thread.

pub mod cameras;
pub mod draw;
pub mod frame;
pub mod geometry;
pub mod image;
pub mod kinematics;
pub mod noise;
pub mod pose;
pub mod rng;
pub mod skeleton;

/// The median (the mean of the middle two for an even count); `None` for no values. Sorts
/// `values`.
pub fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    })
}

/// An error and its causes on one line.
pub fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}
