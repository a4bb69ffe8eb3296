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

use crate::core::frame::DepthFrame;
use crate::core::pose::{JointPositions, JointSource, Pose};
use crate::core::skeleton::Joint;
use crate::vision::segment::{Mouse, SegmentError, Segmenter, SeveralMice};
use nalgebra::{Point2, Point3, Vector2};

/// The most mice followed in one cage: every assignment of a frame's mice to the tracks is
/// tried, 120 of them for five.
pub const MOST_MICE: usize = 5;

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

impl Seen {
    /// What identity is told of a segmented mouse: its centre on the floor and its build.
    pub fn of(mouse: &Mouse) -> Self {
        Self {
            centre: mouse.centroid_mm.xy(),
            build: [mouse.length_mm, mouse.width_mm, mouse.mean_height_mm],
        }
    }
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

/// A number of mice to follow, checked: 1 to [`MOST_MICE`].
///
/// # Errors
/// Another number, in one sentence.
pub fn mice_count(n: i64) -> Result<usize, String> {
    match usize::try_from(n) {
        Ok(n @ 1..=MOST_MICE) => Ok(n),
        _ => Err(format!("mousepose follows 1 to {MOST_MICE} mice in one cage, not {n}")),
    }
}

/// Two mice whose nearest main-body joints (1-12) are closer than this (mm) touch: their
/// spines are about a body's width apart when their sides meet.
pub const CONTACT_MM: f64 = 25.0;

/// The main-body joints of `pose` that were estimated.
fn body_joints(pose: &Pose) -> impl Iterator<Item = (usize, Point3<f64>)> + '_ {
    Joint::MAIN_BODY.iter().filter_map(|j| {
        let e = pose.joint(*j);
        (e.source != JointSource::Missing).then_some((j.index(), e.position_mm))
    })
}

/// The distance between the nearest main-body joints of two poses (mm); `None` when either
/// has none.
pub fn nearest_mm(a: &Pose, b: &Pose) -> Option<f64> {
    body_joints(a)
        .flat_map(|(_, p)| body_joints(b).map(move |(_, q)| (p - q).norm()))
        .min_by(f64::total_cmp)
}

/// Which of the true mice `truth` the pose is of: the one whose main-body joints are nearest
/// its own on average; `None` without truth or estimated joints.
pub fn nearest_truth(pose: &Pose, truth: &[JointPositions]) -> Option<usize> {
    let joints: Vec<(usize, Point3<f64>)> = body_joints(pose).collect();
    if joints.is_empty() {
        return None;
    }
    let apart = |t: &JointPositions| joints.iter().map(|(k, p)| (p - t[*k]).norm()).sum::<f64>();
    (0..truth.len()).min_by(|&a, &b| apart(&truth[a]).total_cmp(&apart(&truth[b])))
}

/// Several mice followed from frame to frame: each frame's mice segmented alone
/// ([`Segmenter::segment_mice`], touching mice split from where they were in the frame before)
/// and numbered ([`Identities::assign`]).
#[derive(Clone, Debug)]
pub struct MiceTracker {
    identities: Identities,
    /// Where each mouse found in the frame before lay in the image (pixels).
    last: Vec<(f64, f64)>,
    /// The areas (mm^2) of the last [`AREAS_KEPT`] components that claimed one mouse alone:
    /// their median is one mouse's (touching mice, split, are not among them).
    areas: std::collections::VecDeque<f64>,
}

/// Components whose areas [`MiceTracker`] keeps.
const AREAS_KEPT: usize = 301;

/// One frame's mice by number.
#[derive(Debug)]
pub struct NumberedMice {
    /// Mouse k + 1 at index k with its number's confidence (0-1); `None` where it was not found.
    pub mice: Vec<Option<(Mouse, f64)>>,
    /// Two numbers the frame could have swapped ([`Frame::possible_swap`]).
    pub possible_swap: Option<(usize, usize)>,
    /// Mouse-sized things seen beyond the mice counted ([`crate::vision::segment::Claims::beyond`]).
    pub beyond: usize,
}

impl MiceTracker {
    /// Follows `count` mice (1 to [`MOST_MICE`]).
    pub fn new(count: usize) -> Self {
        Self {
            identities: Identities::new(count.clamp(1, MOST_MICE)),
            last: Vec::new(),
            areas: std::collections::VecDeque::with_capacity(AREAS_KEPT),
        }
    }

    /// How many mice it follows.
    pub fn count(&self) -> usize {
        self.identities.count
    }

    /// The area one mouse covers, by the components seen so far (none before a few).
    fn mouse_area(&self) -> Option<f64> {
        if self.areas.len() < 5 {
            return None;
        }
        let mut sorted: Vec<f64> = self.areas.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        Some(sorted[sorted.len() / 2])
    }

    /// The mice of `frame`, segmented by `segmenter` and numbered.
    ///
    /// # Errors
    /// As [`Segmenter::segment_mice`].
    pub fn next(&mut self, segmenter: &mut Segmenter, frame: &DepthFrame) -> Result<NumberedMice, SegmentError> {
        let count = self.count();
        let mouse_area = self.mouse_area();
        let SeveralMice {
            mice: found,
            beyond,
            areas,
        } = segmenter.segment_mice(frame, count, &self.last, mouse_area)?;
        for a in areas {
            if self.areas.len() == AREAS_KEPT {
                self.areas.pop_front();
            }
            self.areas.push_back(a);
        }
        self.last = found.iter().map(Mouse::image_centre).collect();
        let seen: Vec<Seen> = found.iter().map(Seen::of).collect();
        let numbering = self.identities.assign(&seen, frame.stamp.device_ns as f64 * 1e-9);
        let mut found: Vec<Option<Mouse>> = found.into_iter().map(Some).collect();
        let mut mice: Vec<Option<(Mouse, f64)>> = (0..count).map(|_| None).collect();
        for n in &numbering.numbered {
            if let Some(mouse) = found.get_mut(n.found).and_then(Option::take) {
                mice[n.mouse - 1] = Some((mouse, n.confidence));
            }
        }
        Ok(NumberedMice {
            mice,
            possible_swap: numbering.possible_swap,
            beyond,
        })
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
