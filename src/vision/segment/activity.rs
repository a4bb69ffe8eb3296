//! Where something of a mouse's size stood in the frames a background model is made of: in
//! each frame, the connected groups of readings nearer than the model (by more than a mouse's
//! lowest part, less than a rearing mouse's height) whose area seen from above is a mouse's.
//! The arena finder uses them to choose, among the flat regions of the view, the one the
//! mouse walks on ([`super::arena`]); replay uses them to say when a mouse-sized thing moved
//! outside the arena used ([`ArenaCheck`]), so that a user knows to give the arena (`--roi`).

use serde::Serialize;

/// A reading this much nearer than the model (mm along the ray) may be the mouse.
const MIN_RISE_MM: f32 = 8.0;
/// ... and at most this much (a hand, a person leaning over are nearer still).
const MAX_RISE_MM: f32 = 200.0;
/// The largest area seen from above (mm^2) taken for a mouse: an adult mouse shows about
/// 2,000-3,500 mm^2, a hand three times as much.
pub const MOUSE_MAX_AREA_MM2: f64 = 8_000.0;

/// A mouse-sized group of readings in one frame: pixel indices (row-major over the model's
/// region) and their depths (mm).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Blob {
    pub frame: usize,
    pub pixels: Vec<(u32, f32)>,
}

impl Blob {
    /// Whether at least half of the blob's pixels are 1 in `mask`.
    pub fn mostly_in(&self, mask: &[u8]) -> bool {
        let inside = self
            .pixels
            .iter()
            .filter(|(i, _)| mask.get(*i as usize).is_some_and(|&m| m != 0))
            .count();
        2 * inside >= self.pixels.len()
    }
}

/// The mouse-sized groups of readings of `frame` (mm, 0 = none) against `model` (mm, 0 =
/// none), both `width` pixels wide, seen by a camera of focal lengths `fx`, `fy` (px); groups
/// smaller than `min_area_mm2` are noise. Groups are 8-connected.
pub fn mouse_blobs(
    frame_index: usize,
    frame: &[u16],
    model: &[f32],
    width: usize,
    (fx, fy): (f64, f64),
    min_area_mm2: f64,
) -> Vec<Blob> {
    let n = frame.len().min(model.len());
    let raised = |i: usize| {
        let (z, m) = (f32::from(frame[i]), model[i]);
        z > 0.0 && m > 0.0 && (MIN_RISE_MM..=MAX_RISE_MM).contains(&(m - z))
    };
    let height = n / width.max(1);
    let mut seen = vec![false; n];
    let mut stack = Vec::new();
    let mut blobs = Vec::new();
    for start in 0..n {
        if seen[start] || !raised(start) {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut pixels = Vec::new();
        let mut area = 0.0;
        while let Some(i) = stack.pop() {
            let z = f64::from(frame[i]);
            pixels.push((i as u32, z as f32));
            area += (z / fx) * (z / fy);
            let (x, y) = (i % width, i / width);
            for ny in y.saturating_sub(1)..(y + 2).min(height) {
                for nx in x.saturating_sub(1)..(x + 2).min(width) {
                    let j = ny * width + nx;
                    if !seen[j] && raised(j) {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if (min_area_mm2..=MOUSE_MAX_AREA_MM2).contains(&area) {
            blobs.push(Blob {
                frame: frame_index,
                pixels,
            });
        }
    }
    blobs
}

/// What the frames sampled for the background say about the arena used: in how many of them
/// something of a mouse's size stood inside it, and outside it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ArenaCheck {
    /// Frames sampled (spread over the recording).
    pub sampled_frames: usize,
    /// Of those, frames with a mouse-sized thing mostly inside the arena, and mostly outside.
    pub mouse_sized_inside: usize,
    pub mouse_sized_outside: usize,
}

impl ArenaCheck {
    /// The check of `blobs` (from `sampled_frames` frames) against `arena`.
    pub fn of(blobs: &[Blob], sampled_frames: usize, arena: &[u8]) -> Self {
        let mut inside = vec![false; sampled_frames];
        let mut outside = vec![false; sampled_frames];
        for b in blobs {
            let flags = if b.mostly_in(arena) { &mut inside } else { &mut outside };
            if let Some(f) = flags.get_mut(b.frame) {
                *f = true;
            }
        }
        Self {
            sampled_frames,
            mouse_sized_inside: inside.iter().filter(|&&f| f).count(),
            mouse_sized_outside: outside.iter().filter(|&&f| f).count(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mouse_sized_group_is_found_and_noise_and_a_hand_are_not() {
        // 100 x 100 pixels at 1 mm a pixel (f = depth): a floor 700 mm away.
        let (w, h) = (100usize, 100usize);
        let model = vec![700.0f32; w * h];
        let mut frame = vec![700u16; w * h];
        // A 20 x 60 mm mouse 25 mm high, one noisy pixel; a hand 50 mm up over the view.
        for y in 10..30 {
            for x in 5..65 {
                frame[y * w + x] = 675;
            }
        }
        frame[50 * w + 90] = 680;
        let blobs = mouse_blobs(3, &frame, &model, w, (700.0, 700.0), 400.0);
        assert_eq!(blobs.len(), 1);
        assert_eq!(blobs[0].pixels.len(), 20 * 60);
        assert_eq!(blobs[0].frame, 3);
        let hand = vec![650u16; w * h];
        assert!(mouse_blobs(0, &hand, &model, w, (700.0, 700.0), 400.0).is_empty());
        let mut arena = vec![0u8; w * h];
        arena[..50 * w].fill(1);
        let check = ArenaCheck::of(&blobs, 5, &arena);
        assert_eq!((check.mouse_sized_inside, check.mouse_sized_outside), (1, 0));
        let check = ArenaCheck::of(&blobs, 5, &vec![0; w * h]);
        assert_eq!((check.mouse_sized_inside, check.mouse_sized_outside), (0, 1));
    }
}
