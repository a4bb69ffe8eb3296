//! Where the cage stands up from the floor: the pixels within [`WALL_REACH_MM`] of a wall, of
//! anything fixed standing on the floor, or of the arena's rim. Bedding and clutter gather
//! there, and a mouse nosing at the wall touches them: a thin strand of it joined to the mouse's
//! head reads as a tail, so a tail that reaches this near a wall is not trusted as one
//! ([`Mouse::wall`](super::Mouse::wall), `vision::orientation`).

use super::floor::FloorPlane;

/// A reading of the empty cage this high above the floor (mm) is a wall or something fixed on
/// the floor, not floor.
pub const WALL_HEIGHT_MM: f64 = 10.0;
/// How near (mm on the floor) a pixel lies to a wall, a fixed object or the arena's rim to be
/// "at the wall".
pub const WALL_REACH_MM: f64 = 10.0;

/// 1 where a pixel of the background lies within `reach_px` pixels (chessboard distance) of a
/// pixel that stands: outside the arena (`arena` 0), or whose background reading (`depth`, mm,
/// 0 = none) lies at least [`WALL_HEIGHT_MM`] above `floor` along its ray (`rays`, `(x, y, 1)`).
/// Row-major over a background `width` pixels wide.
pub(super) fn near_walls(
    depth: &[f32],
    rays: &[[f32; 2]],
    arena: &[u8],
    floor: &FloorPlane,
    width: usize,
    reach_px: usize,
) -> Vec<u8> {
    let n = depth.len();
    let mut distance = vec![usize::MAX; n];
    let mut queue = std::collections::VecDeque::new();
    for (k, ((&bg, r), &inside)) in depth.iter().zip(rays).zip(arena).enumerate() {
        let a = floor
            .normal
            .dot(&nalgebra::Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0));
        let standing = inside == 0 || (bg > 0.0 && a * f64::from(bg) + floor.offset_mm >= WALL_HEIGHT_MM);
        if standing {
            distance[k] = 0;
            queue.push_back(k);
        }
    }
    if width == 0 {
        return vec![0; n];
    }
    let height = n / width;
    while let Some(k) = queue.pop_front() {
        let d = distance[k];
        if d >= reach_px {
            continue;
        }
        let (x, y) = (k % width, k / width);
        for ny in y.saturating_sub(1)..=(y + 1).min(height - 1) {
            for nx in x.saturating_sub(1)..=(x + 1).min(width - 1) {
                let m = ny * width + nx;
                if distance[m] > d + 1 {
                    distance[m] = d + 1;
                    queue.push_back(m);
                }
            }
        }
    }
    distance.iter().map(|&d| u8::from(d <= reach_px)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn pixels_near_a_wall_or_the_rim_are_marked_and_the_open_floor_is_not() {
        // A camera 500 mm straight above a floor; a wall 30 mm high along the left edge, the
        // arena ending at the right edge.
        let (width, height) = (20, 5);
        let floor = FloorPlane {
            normal: Vector3::new(0.0, 0.0, -1.0),
            offset_mm: 500.0,
        };
        let rays = vec![[0.0, 0.0]; width * height];
        let mut depth = vec![500.0_f32; width * height];
        let mut arena = vec![1u8; width * height];
        for y in 0..height {
            depth[y * width] = 470.0;
            arena[y * width + width - 1] = 0;
        }
        let near = near_walls(&depth, &rays, &arena, &floor, width, 2);
        let row: Vec<u8> = near[2 * width..3 * width].to_vec();
        assert_eq!(row, [1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1]);
        // A floor reading a few millimetres high is floor.
        depth[2 * width + 10] = 495.0;
        assert_eq!(near_walls(&depth, &rays, &arena, &floor, width, 2), near);
    }
}
