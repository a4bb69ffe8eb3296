//! Whether `depth.dat`'s frames look like depth images at the size they are read at. The file
//! has no header: a wrong `DepthResolution` with the same number of pixels (424x512 for
//! 512x424) divides it just as well and gives as many frames as timestamps, but each row then
//! starts part-way through a real one. A depth image is smooth (the floor, the mouse's back):
//! most readings agree with the one below them. At a wrong width the one below is another part
//! of the scene, and the frame looks like noise.

use super::{MoseqDepth, MoseqError, MoseqKind};
use crate::core::cameras::DEPTH_CAMERAS;
use crate::runtime::capture::CaptureError;

/// Two readings agree when they differ by at most this (mm).
const AGREE_MM: u16 = 20;
/// A depth image has at least this share of agreeing vertical neighbours.
const MIN_SMOOTH_SHARE: f64 = 0.8;
/// A size whose share is better than the given one's by more than this is the right one.
const BETTER_BY: f64 = 0.1;
/// Sizes tried, at most (the given one, its transpose, the camera table's, then others with
/// the same pixel count and an aspect ratio between 1:2 and 2:1).
const MAX_SIZES: usize = 12;

/// One frame size tried, and how smooth the frames looked at it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SizeTried {
    pub width: u32,
    pub height: u32,
    /// [`smooth_share`] averaged over the frames read.
    pub smooth_share: f64,
}

/// The share of vertically neighbouring pixel pairs (of those where either has a reading)
/// whose readings agree (both present, within 20 mm), in `data` read as `width` x `height`.
/// About 1 for a depth image, far less for noise or for a depth image read at a wrong width.
pub fn smooth_share(data: &[u16], width: u32, height: u32) -> f64 {
    let w = width as usize;
    let n = (w * height as usize).min(data.len());
    let (mut pairs, mut agree) = (0u64, 0u64);
    if let (Some(upper), Some(lower)) = (data.get(..n.saturating_sub(w)), data.get(w..n)) {
        for (&a, &b) in upper.iter().zip(lower) {
            if a == 0 && b == 0 {
                continue;
            }
            pairs += 1;
            if a != 0 && b != 0 && a.abs_diff(b) <= AGREE_MM {
                agree += 1;
            }
        }
    }
    if pairs == 0 { 0.0 } else { agree as f64 / pairs as f64 }
}

/// The sizes with `width * height` pixels to try, the given one first.
fn candidate_sizes(width: u32, height: u32) -> Vec<(u32, u32)> {
    let pixels = u64::from(width) * u64::from(height);
    let mut sizes = vec![(width, height), (height, width)];
    sizes.extend(
        DEPTH_CAMERAS
            .iter()
            .filter(|m| u64::from(m.width) * u64::from(m.height) == pixels)
            .map(|m| (m.width, m.height)),
    );
    let mut w = 1u64;
    while w * w <= 4 * pixels {
        if pixels % w == 0 {
            let h = pixels / w;
            if 2 * w >= h && w <= 2 * h {
                if let (Ok(w), Ok(h)) = (u32::try_from(w), u32::try_from(h)) {
                    sizes.push((w, h));
                }
            }
        }
        w += 1;
    }
    let mut unique = Vec::new();
    for s in sizes {
        if !unique.contains(&s) && unique.len() < MAX_SIZES {
            unique.push(s);
        }
    }
    unique
}

impl MoseqDepth {
    /// Reads the first, middle and last frames of a `depth.dat` and refuses a frame size at
    /// which they do not look like depth images (see the module documentation), naming the
    /// sizes tried and, when one of them looks right, that one. `depth.avi` carries its own
    /// size and is not checked. Returns the sizes tried.
    ///
    /// # Errors
    /// [`MoseqError::FrameSize`], or the file cannot be read.
    pub fn check_frame_size(&self) -> Result<Vec<SizeTried>, CaptureError> {
        let count = self.frame_count();
        if self.kind != MoseqKind::Raw || count == 0 {
            return Ok(Vec::new());
        }
        let mut picks = vec![0, count / 2, count - 1];
        picks.dedup();
        let frames = picks
            .iter()
            .map(|&k| self.frame_at(k).map(|f| f.data))
            .collect::<Result<Vec<_>, _>>()?;
        let tried: Vec<SizeTried> = candidate_sizes(self.width, self.height)
            .into_iter()
            .map(|(width, height)| SizeTried {
                width,
                height,
                smooth_share: frames.iter().map(|f| smooth_share(f, width, height)).sum::<f64>() / frames.len() as f64,
            })
            .collect();
        let Some(given) = tried.first().copied() else {
            return Ok(tried);
        };
        let best = tried
            .iter()
            .copied()
            .max_by(|a, b| a.smooth_share.total_cmp(&b.smooth_share))
            .unwrap_or(given);
        if given.smooth_share >= MIN_SMOOTH_SHARE && given.smooth_share + BETTER_BY >= best.smooth_share {
            return Ok(tried);
        }
        let advice = if best.smooth_share >= MIN_SMOOTH_SHARE && best != given {
            format!(
                "{}x{} looks right: set \"DepthResolution\": [{}, {}] in metadata.json",
                best.width, best.height, best.width, best.height
            )
        } else {
            "none looks like depth frames: depth.dat should hold little-endian 16-bit depths in millimetres, and metadata.json its \"DepthResolution\": [width, height]".to_owned()
        };
        Err(self.error(MoseqError::FrameSize {
            path: self.depth_path.clone(),
            width: self.width,
            height: self.height,
            given: if self.metadata.resolution.is_some() {
                "DepthResolution in metadata.json"
            } else {
                "the default size: metadata.json gives no DepthResolution"
            },
            share_pct: given.smooth_share * 100.0,
            tried: tried
                .iter()
                .map(|t| format!("{}x{} ({:.0} % agree)", t.width, t.height, t.smooth_share * 100.0))
                .collect::<Vec<_>>()
                .join(", "),
            advice,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_tried_share_the_pixel_count_and_start_with_the_given_one() {
        let sizes = candidate_sizes(512, 424);
        assert_eq!(sizes.first(), Some(&(512, 424)));
        assert!(sizes.contains(&(424, 512)));
        assert!(sizes.iter().all(|(w, h)| w * h == 512 * 424));
        assert!(candidate_sizes(640, 576).len() <= MAX_SIZES);
    }

    #[test]
    fn a_smooth_image_agrees_and_noise_does_not() {
        let (w, h) = (64u32, 48u32);
        // A tilted floor: depth grows 1 mm a column, 0.5 mm a row.
        let ramp: Vec<u16> = (0..w * h).map(|i| (600 + i % w + (i / w) / 2) as u16).collect();
        assert!(smooth_share(&ramp, w, h) > 0.99);
        // Read 40 pixels wide, a reading's neighbour below lies 40 columns on (40 mm deeper)
        // or, past the row's end, 24 columns back and a row down: neither agrees.
        assert!(smooth_share(&ramp, 40, w * h / 40) < 0.1);
        let noise: Vec<u16> = (0..w * h)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 16) as u16)
            .collect();
        assert!(smooth_share(&noise, w, h) < 0.05);
    }
}
