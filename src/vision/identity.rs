//! Which mouse is which, frame after frame, when several share the cage: each mouse found in a
//! frame is given the number (1..N) of the track it continues, so that a mouse keeps its number
//! from the first frame to the last through contacts and crossings.
//!
//! Each track remembers where its mouse was, how fast it moved, and its build as `adapt`
//! measures one (body length, width and mean height, each followed slowly). A frame's mice are
//! matched to the tracks by trying every assignment (N is at most a handful) and keeping the
//! cheapest: the distance from where each track's mouse should be by now, in units of how far
//! a mouse can move in that time, plus how unlike its build the mouse found is. How much
//! cheaper that assignment is than the next best gives the frame's `identity_confidence`, and a
//! frame where the next best would have swapped two mice and is nearly as cheap is a possible
//! swap, listed for the user to check.
//!
//! In the first frame the mice are numbered from left to right in the image (by their centres'
//! x), since nothing else tells them apart yet.

use nalgebra::{Point2, Vector2};

/// How far a mouse may move in a frame's time at most, on top of what its speed predicts
/// (mm): the scale of a position's cost.
pub const POSITION_SCALE_MM: f64 = 15.0;
/// The scale of a build's cost: a mouse's length, width or height this far (mm) from its
/// track's costs as much as being one position scale away.
pub const BUILD_SCALE_MM: f64 = 6.0;
/// How much a track's build follows each frame's measurement (the rest is its past).
const BUILD_FOLLOW: f64 = 0.05;
/// How much a track's velocity follows each frame's.
const VELOCITY_FOLLOW: f64 = 0.3;
/// Below this confidence, a frame whose runner-up assignment swaps two mice is a possible swap.
pub const SWAP_CONFIDENCE: f64 = 0.5;
/// The cost margin (in scales) at which confidence reaches 1 - 1/e.
const CONFIDENCE_MARGIN: f64 = 2.0;

/// What identity needs of a mouse found in a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seen {
    /// Its centre on the floor (mm, world x and y).
    pub centre: Point2<f64>,
    /// Its build: body length, width and mean height (mm).
    pub build: [f64; 3],
}

/// A mouse's number in a frame and how sure it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Numbered {
    /// Which of the frame's mice (an index into what [`Identities::assign`] was given).
    pub found: usize,
    /// Its number, 1..=N.
    pub mouse: usize,
    /// 0-1: how much better this assignment is than the next best.
    pub confidence: f64,
}

/// One frame's numbering.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub numbered: Vec<Numbered>,
    /// The numbers of two mice that the next best assignment would have swapped, when it was
    /// nearly as good ([`SWAP_CONFIDENCE`]).
    pub possible_swap: Option<(usize, usize)>,
}

#[derive(Clone, Debug)]
struct Track {
    centre: Point2<f64>,
    velocity: Vector2<f64>,
    build: [f64; 3],
    /// Seconds of the frame it was last seen in.
    seen_s: f64,
}

/// The tracks of `count` mice.
#[derive(Clone, Debug)]
pub struct Identities {
    count: usize,
    tracks: Vec<Option<Track>>,
}

impl Identities {
    /// Tracks for `count` mice (at least 1), none seen yet.
    pub fn new(count: usize) -> Self {
        let count = count.max(1);
        Self {
            count,
            tracks: vec![None; count],
        }
    }

    /// Numbers the mice `seen` in a frame taken at `time_s` (at most as many as there are
    /// tracks; more are left unnumbered, the last ones), and moves the tracks on.
    pub fn assign(&mut self, seen: &[Seen], time_s: f64) -> Frame {
        let seen = &seen[..seen.len().min(self.count)];
        if self.tracks.iter().all(Option::is_none) {
            return self.first(seen, time_s);
        }
        // Every injective map of the seen mice to tracks, cheapest first.
        let mut best: Option<(f64, Vec<usize>)> = None;
        let mut second: Option<(f64, Vec<usize>)> = None;
        let mut chosen = Vec::with_capacity(seen.len());
        let mut used = vec![false; self.count];
        self.search(seen, time_s, &mut chosen, &mut used, 0.0, &mut best, &mut second);
        let Some((cost, map)) = best else {
            return Frame {
                numbered: Vec::new(),
                possible_swap: None,
            };
        };
        let margin = second.as_ref().map_or(f64::INFINITY, |(c, _)| c - cost);
        let confidence = 1.0 - (-margin / CONFIDENCE_MARGIN).exp();
        let possible_swap = second.filter(|_| confidence < SWAP_CONFIDENCE).and_then(|(_, other)| {
            let differ: Vec<usize> = (0..map.len()).filter(|&i| map[i] != other[i]).collect();
            match differ.as_slice() {
                [a, b] => Some((map[*a].min(map[*b]) + 1, map[*a].max(map[*b]) + 1)),
                _ => None,
            }
        });
        for (i, &t) in map.iter().enumerate() {
            self.follow(t, &seen[i], time_s);
        }
        Frame {
            numbered: map
                .iter()
                .enumerate()
                .map(|(found, &t)| Numbered {
                    found,
                    mouse: t + 1,
                    confidence,
                })
                .collect(),
            possible_swap,
        }
    }

    /// The first frame: numbers from left to right.
    fn first(&mut self, seen: &[Seen], time_s: f64) -> Frame {
        let mut order: Vec<usize> = (0..seen.len()).collect();
        order.sort_by(|&a, &b| seen[a].centre.x.total_cmp(&seen[b].centre.x));
        let mut numbered = Vec::new();
        for (t, &found) in order.iter().enumerate() {
            self.tracks[t] = Some(Track {
                centre: seen[found].centre,
                velocity: Vector2::zeros(),
                build: seen[found].build,
                seen_s: time_s,
            });
            numbered.push(Numbered {
                found,
                mouse: t + 1,
                confidence: if seen.len() == 1 { 1.0 } else { 0.0 },
            });
        }
        numbered.sort_by_key(|n| n.found);
        Frame {
            numbered,
            possible_swap: None,
        }
    }

    /// The cost of mouse `s` continuing track `t` (in position scales).
    fn cost(&self, t: usize, s: &Seen, time_s: f64) -> f64 {
        let Some(track) = &self.tracks[t] else {
            // A track never seen takes any mouse, at a cost above a plausible continuation.
            return 3.0;
        };
        let dt = (time_s - track.seen_s).clamp(0.0, 2.0);
        let expected = track.centre + track.velocity * dt;
        // A mouse unseen for longer may be further: the scale grows with the time.
        let scale = POSITION_SCALE_MM * (1.0 + 10.0 * dt);
        let position = (s.centre - expected).norm() / scale;
        let build: f64 = track
            .build
            .iter()
            .zip(&s.build)
            .map(|(a, b)| ((a - b) / BUILD_SCALE_MM).powi(2))
            .sum::<f64>()
            .sqrt();
        position + build
    }

    /// Tries every assignment of `seen[chosen.len()..]` to unused tracks, keeping the best two.
    #[allow(clippy::too_many_arguments)]
    fn search(
        &self,
        seen: &[Seen],
        time_s: f64,
        chosen: &mut Vec<usize>,
        used: &mut [bool],
        cost: f64,
        best: &mut Option<(f64, Vec<usize>)>,
        second: &mut Option<(f64, Vec<usize>)>,
    ) {
        let i = chosen.len();
        if i == seen.len() {
            let map = chosen.clone();
            if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                *second = best.take();
                *best = Some((cost, map));
            } else if second.as_ref().is_none_or(|(c, _)| cost < *c) {
                *second = Some((cost, map));
            }
            return;
        }
        for t in 0..self.count {
            if used[t] {
                continue;
            }
            used[t] = true;
            chosen.push(t);
            let c = cost + self.cost(t, &seen[i], time_s);
            self.search(seen, time_s, chosen, used, c, best, second);
            chosen.pop();
            used[t] = false;
        }
    }

    /// Track `t` continues with mouse `s`, seen at `time_s`.
    fn follow(&mut self, t: usize, s: &Seen, time_s: f64) {
        let track = self.tracks[t].get_or_insert(Track {
            centre: s.centre,
            velocity: Vector2::zeros(),
            build: s.build,
            seen_s: time_s,
        });
        let dt = time_s - track.seen_s;
        if dt > 1e-6 && dt < 1.0 {
            let v = (s.centre - track.centre) / dt;
            track.velocity += (v - track.velocity) * VELOCITY_FOLLOW;
        } else if dt >= 1.0 {
            track.velocity = Vector2::zeros();
        }
        for (b, &m) in track.build.iter_mut().zip(&s.build) {
            *b += (m - *b) * BUILD_FOLLOW;
        }
        track.centre = s.centre;
        track.seen_s = time_s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64, build: [f64; 3]) -> Seen {
        Seen {
            centre: Point2::new(x, y),
            build,
        }
    }

    #[test]
    fn mice_are_numbered_left_to_right_and_keep_their_numbers_as_they_move() {
        let mut ids = Identities::new(2);
        let (a, b) = ([80.0, 30.0, 28.0], [95.0, 34.0, 31.0]);
        let f = ids.assign(&[at(100.0, 0.0, b), at(-100.0, 0.0, a)], 0.0);
        assert_eq!(
            f.numbered.iter().map(|n| (n.found, n.mouse)).collect::<Vec<_>>(),
            [(0, 2), (1, 1)]
        );
        // They walk towards each other and past, given in either order.
        for k in 1..60 {
            let t = f64::from(k) / 30.0;
            let x = -100.0 + 120.0 * t;
            let seen = if k % 2 == 0 {
                [at(x, 5.0, a), at(-x, -5.0, b)]
            } else {
                [at(-x, -5.0, b), at(x, 5.0, a)]
            };
            let f = ids.assign(&seen, t);
            let of = |found: usize| f.numbered.iter().find(|n| n.found == found).unwrap().mouse;
            if k % 2 == 0 {
                assert_eq!((of(0), of(1)), (1, 2), "frame {k}");
            } else {
                assert_eq!((of(0), of(1)), (2, 1), "frame {k}");
            }
        }
    }

    #[test]
    fn two_alike_mice_on_the_same_spot_are_a_possible_swap() {
        let mut ids = Identities::new(2);
        let build = [85.0, 30.0, 29.0];
        ids.assign(&[at(-20.0, 0.0, build), at(20.0, 0.0, build)], 0.0);
        let f = ids.assign(&[at(0.5, 0.0, build), at(-0.5, 0.0, build)], 1.0 / 30.0);
        assert!(f.numbered[0].confidence < SWAP_CONFIDENCE, "{f:?}");
        assert_eq!(f.possible_swap, Some((1, 2)));
        // Apart and unlike: sure.
        let mut ids = Identities::new(2);
        ids.assign(
            &[at(-60.0, 0.0, [80.0, 28.0, 27.0]), at(60.0, 0.0, [100.0, 35.0, 32.0])],
            0.0,
        );
        let f = ids.assign(
            &[at(-58.0, 0.0, [80.0, 28.0, 27.0]), at(61.0, 0.0, [100.0, 35.0, 32.0])],
            1.0 / 30.0,
        );
        assert!(f.numbered[0].confidence > 0.99, "{f:?}");
        assert_eq!(f.possible_swap, None);
    }

    #[test]
    fn a_mouse_not_seen_for_a_while_is_found_again_by_its_build() {
        let mut ids = Identities::new(2);
        let (small, large) = ([75.0, 27.0, 26.0], [100.0, 36.0, 33.0]);
        ids.assign(&[at(-50.0, 0.0, small), at(50.0, 0.0, large)], 0.0);
        // The small one hides for a second; the large one goes on.
        for k in 1..30 {
            ids.assign(&[at(50.0, f64::from(k), large)], f64::from(k) / 30.0);
        }
        let f = ids.assign(&[at(48.0, 30.0, large), at(0.0, 0.0, small)], 1.0);
        let of = |found: usize| f.numbered.iter().find(|n| n.found == found).unwrap().mouse;
        assert_eq!((of(0), of(1)), (2, 1));
    }
}
