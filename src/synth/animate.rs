//! A continuous behaviour sequence for synthetic sessions: the mouse follows a smooth path
//! through the cage, walking, running, turning, pausing, rearing, grooming and sniffing, with
//! every pose parameter eased so nothing jumps between frames.

use super::mouse::{Behaviour, Placement, PoseParams, behaviour_params};
use crate::core::geometry::{CAGE_X_MM, CAGE_Y_MM};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{PI, TAU};

/// What the animated mouse does: anything (`Mixed`, the default), stay in place (`Still`:
/// standing, sniffing, grooming, rearing and bending where it is), or walk (`Walking`: walking
/// and the turns the walls ask for).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Activity {
    #[default]
    Mixed,
    Still,
    Walking,
}

/// Time constant of the easing between behaviours, seconds.
const EASE_S: f64 = 0.18;
/// Keep the rump this far from the walls.
const WALL_MARGIN_MM: f64 = 70.0;

/// The state of the animated mouse.
#[derive(Clone, Debug)]
pub struct Animator {
    rng: ChaCha8Rng,
    placement: Placement,
    params: PoseParams,
    behaviour: Behaviour,
    remaining_s: f64,
    speed_mm_s: f64,
    phase: f64,
    bend: f64,
    bend_target: f64,
    head: f64,
    head_target: f64,
    look: f64,
    amount: f64,
    clock_s: f64,
    activity: Activity,
}

impl Animator {
    /// A mouse of the given build, standing at a random place in the cage.
    pub fn new(mut rng: ChaCha8Rng, mut placement: Placement) -> Self {
        placement.x_mm = rng.gen_range(-100.0..=100.0);
        placement.y_mm = rng.gen_range(-80.0..=80.0);
        placement.heading = rng.gen_range(-PI..PI);
        placement.pitch = 0.0;
        placement.roll = 0.0;
        let params = behaviour_params(Behaviour::Stand, 0.0, 0.0, 0.0, 0.0, 0.5);
        Self {
            rng,
            placement,
            params,
            behaviour: Behaviour::Walk,
            remaining_s: 1.5,
            speed_mm_s: 0.0,
            phase: 0.0,
            bend: 0.0,
            bend_target: 0.0,
            head: 0.0,
            head_target: 0.0,
            look: 0.0,
            amount: 0.5,
            clock_s: 0.0,
            activity: Activity::Mixed,
        }
    }

    /// The same mouse doing only `activity` from now on.
    pub fn with_activity(mut self, activity: Activity) -> Self {
        self.activity = activity;
        match activity {
            Activity::Mixed => {}
            Activity::Still => self.behaviour = Behaviour::Stand,
            Activity::Walking => self.behaviour = Behaviour::Walk,
        }
        self
    }

    /// The current behaviour.
    pub fn behaviour(&self) -> Behaviour {
        self.behaviour
    }

    /// The pose and placement now.
    pub fn state(&self) -> (PoseParams, Placement) {
        (self.params, self.placement)
    }

    /// Advances the animation by `dt_s` seconds (internally in steps of at most 5 ms).
    pub fn advance(&mut self, dt_s: f64) {
        let mut left = dt_s.max(0.0);
        while left > 1e-12 {
            let dt = left.min(0.005);
            self.step(dt);
            left -= dt;
        }
    }

    fn choose_next(&mut self) {
        let r: f64 = self.rng.r#gen();
        let (behaviour, duration) = match r {
            r if r < 0.30 => (Behaviour::Walk, self.rng.gen_range(1.0..3.5)),
            r if r < 0.40 => (Behaviour::Run, self.rng.gen_range(0.4..1.2)),
            r if r < 0.52 => (Behaviour::Turn, self.rng.gen_range(0.5..1.4)),
            r if r < 0.62 => (Behaviour::Stand, self.rng.gen_range(0.4..1.5)),
            r if r < 0.72 => (Behaviour::Rear, self.rng.gen_range(0.8..2.5)),
            r if r < 0.82 => (Behaviour::Groom, self.rng.gen_range(1.5..4.0)),
            r if r < 0.92 => (Behaviour::Sniff, self.rng.gen_range(0.6..1.8)),
            _ => (Behaviour::Bend, self.rng.gen_range(0.5..1.2)),
        };
        let (behaviour, duration) = match (self.activity, behaviour) {
            (Activity::Still, Behaviour::Walk | Behaviour::Run | Behaviour::Turn) => (Behaviour::Stand, duration),
            (Activity::Walking, _) => (Behaviour::Walk, duration),
            (_, chosen) => (chosen, duration),
        };
        self.behaviour = behaviour;
        self.remaining_s = duration;
        self.amount = self.rng.gen_range(0.2..=1.0);
        self.bend_target = match behaviour {
            Behaviour::Turn => self.rng.gen_range(0.5..=1.0) * if self.rng.gen_bool(0.5) { 1.0 } else { -1.0 },
            Behaviour::Bend => self.rng.gen_range(-1.0..=1.0),
            _ => self.rng.gen_range(-0.3..=0.3),
        };
        self.head_target = self.rng.gen_range(-0.8..=0.8);
    }

    /// Heading change needed to stay inside the cage, positive to the left.
    fn wall_steer(&self) -> f64 {
        let (x, y, h) = (self.placement.x_mm, self.placement.y_mm, self.placement.heading);
        let hx = CAGE_X_MM / 2.0 - WALL_MARGIN_MM;
        let hy = CAGE_Y_MM / 2.0 - WALL_MARGIN_MM;
        // Look ahead; if that point is outside, turn towards the cage's centre.
        let ahead = (x + 60.0 * h.cos(), y + 60.0 * h.sin());
        if ahead.0.abs() < hx && ahead.1.abs() < hy {
            return 0.0;
        }
        let to_centre = (-y).atan2(-x);
        let mut diff = (to_centre - h).rem_euclid(TAU);
        if diff > PI {
            diff -= TAU;
        }
        diff.signum()
    }

    fn step(&mut self, dt: f64) {
        self.clock_s += dt;
        self.remaining_s -= dt;
        if self.remaining_s <= 0.0 {
            self.choose_next();
        }
        let steer = self.wall_steer();
        if steer != 0.0
            && self.activity != Activity::Still
            && matches!(self.behaviour, Behaviour::Walk | Behaviour::Run | Behaviour::Stand)
        {
            self.behaviour = Behaviour::Turn;
            self.remaining_s = 0.6;
            self.bend_target = steer * 0.9;
        }
        let speed_target = match self.behaviour {
            Behaviour::Walk => 60.0 + 70.0 * self.amount,
            Behaviour::Run => 250.0 + 150.0 * self.amount,
            Behaviour::Turn => 35.0,
            _ => 0.0,
        };
        let ease = 1.0 - (-dt / EASE_S).exp();
        self.speed_mm_s += (speed_target - self.speed_mm_s) * ease;
        self.bend += (self.bend_target - self.bend) * ease;
        self.head += (self.head_target - self.head) * ease * 0.5;
        self.look = 0.5 * (TAU * 0.3 * self.clock_s).sin();
        if self.rng.gen_bool((dt * 0.8).min(1.0)) {
            self.head_target = self.rng.gen_range(-0.8..=0.8);
        }

        // Gait cycle: a stride of about 30 mm walking and 45 mm running; activity cycles (head
        // bobbing, grooming strokes) at a few hertz when standing still.
        let stride = if self.behaviour == Behaviour::Run { 45.0 } else { 30.0 };
        let cycle_hz = if self.speed_mm_s > 5.0 {
            self.speed_mm_s / stride
        } else {
            2.5
        };
        self.phase = (self.phase + cycle_hz * dt).rem_euclid(1.0);

        // Move along the heading; the body's bend turns it.
        let turn_rate = self.bend * 1.6;
        self.placement.heading =
            (self.placement.heading + turn_rate * dt * (0.3 + self.speed_mm_s / 120.0).min(2.0)).rem_euclid(TAU);
        self.placement.x_mm += self.speed_mm_s * dt * self.placement.heading.cos();
        self.placement.y_mm += self.speed_mm_s * dt * self.placement.heading.sin();
        let hx = CAGE_X_MM / 2.0 - WALL_MARGIN_MM * 0.6;
        let hy = CAGE_Y_MM / 2.0 - WALL_MARGIN_MM * 0.6;
        self.placement.x_mm = self.placement.x_mm.clamp(-hx, hx);
        self.placement.y_mm = self.placement.y_mm.clamp(-hy, hy);

        let target = behaviour_params(self.behaviour, self.phase, self.bend, self.head, self.look, self.amount);
        // Paw offsets follow the gait directly (they are already smooth in phase); the rest eases.
        let mut next = self.params.lerp(&target, ease);
        if matches!(self.behaviour, Behaviour::Walk | Behaviour::Run | Behaviour::Turn) {
            next.paw_offsets = self.params.lerp(&target, (ease * 4.0).min(1.0)).paw_offsets;
        }
        next.behaviour = self.behaviour;
        self.params = next;
    }
}

/// How close a mouse walks to the point it approaches before it stops there (mm).
const APPROACH_REACH_MM: f64 = 30.0;
/// The longest an approach lasts (s): a mouse that has not got there by then gives up.
const APPROACH_LONGEST_S: f64 = 5.0;
/// Seconds between two approaches in a group, at random in this range.
const APPROACH_EVERY_S: (f64, f64) = (1.0, 4.0);
/// The trunk's length from the rump forward and its half width, at scale 1 (mm): the capsule
/// two mice may touch but not pass into.
const TRUNK_LENGTH_MM: f64 = 54.0;
const TRUNK_HALF_WIDTH_MM: f64 = 13.0;
/// The nose ahead of the rump and the tail's base behind it, at scale 1 (mm; the default bones').
const NOSE_MM: f64 = 81.0;
const TAIL_BASE_MM: f64 = 18.0;

/// Where a mouse goes when it approaches another: its nose (nose to nose), its tail's base
/// (nose to tail) or its flank (side by side).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Goal {
    Nose,
    TailBase,
    Flank,
}

/// One mouse approaching another.
#[derive(Clone, Copy, Debug)]
struct Approach {
    by: usize,
    to: usize,
    goal: Goal,
    left_s: f64,
}

/// Several mice animated together in one cage: each its own [`Animator`] (its own build and
/// behaviour), and between them every few seconds one walks up to another (to its nose, its
/// tail's base or its flank), while no two trunks pass into each other: mice touching, side by
/// side, nose to nose and nose to tail, as group-housed mice do. One mouse alone moves exactly
/// as its [`Animator`] does.
#[derive(Clone, Debug)]
pub struct Group {
    mice: Vec<Animator>,
    rng: ChaCha8Rng,
    approach: Option<Approach>,
    next_approach_s: f64,
}

impl Group {
    /// The mice of `mice`, moved apart where they start inside each other; `rng` draws who
    /// approaches whom, and when.
    pub fn new(mice: Vec<Animator>, mut rng: ChaCha8Rng) -> Self {
        let next_approach_s = rng.gen_range(APPROACH_EVERY_S.0..APPROACH_EVERY_S.1);
        let mut group = Self {
            mice,
            rng,
            approach: None,
            next_approach_s,
        };
        for _ in 0..200 {
            if !group.separate() {
                break;
            }
        }
        group
    }

    /// The mice, in their order.
    pub fn mice(&self) -> &[Animator] {
        &self.mice
    }

    /// Advances every mouse by `dt_s` seconds, in steps of at most 5 ms as [`Animator::advance`].
    pub fn advance(&mut self, dt_s: f64) {
        if self.mice.len() == 1 {
            self.mice[0].advance(dt_s);
            return;
        }
        let mut left = dt_s.max(0.0);
        while left > 1e-12 {
            let dt = left.min(0.005);
            self.social(dt);
            for mouse in &mut self.mice {
                mouse.step(dt);
            }
            self.separate();
            left -= dt;
        }
    }

    /// Starts, steers and ends approaches.
    fn social(&mut self, dt: f64) {
        self.next_approach_s -= dt;
        if self.approach.is_none() && self.next_approach_s <= 0.0 {
            let n = self.mice.len();
            let by = self.rng.gen_range(0..n);
            let to = (by + self.rng.gen_range(1..n)) % n;
            let goal = match self.rng.gen_range(0..3) {
                0 => Goal::Nose,
                1 => Goal::TailBase,
                _ => Goal::Flank,
            };
            self.approach = Some(Approach {
                by,
                to,
                goal,
                left_s: APPROACH_LONGEST_S,
            });
        }
        let Some(a) = &mut self.approach else {
            return;
        };
        a.left_s -= dt;
        let target = self.mice[a.to].point(a.goal);
        let nose = self.mice[a.by].point(Goal::Nose);
        let reached = (target.0 - nose.0).hypot(target.1 - nose.1) < APPROACH_REACH_MM;
        if reached || a.left_s <= 0.0 {
            // There: it stops and sniffs a moment.
            if reached {
                let by = &mut self.mice[a.by];
                by.behaviour = Behaviour::Sniff;
                by.remaining_s = self.rng.gen_range(0.5..1.5);
            }
            self.approach = None;
            self.next_approach_s = self.rng.gen_range(APPROACH_EVERY_S.0..APPROACH_EVERY_S.1);
            return;
        }
        self.mice[a.by].steer_to(target);
    }

    /// Pushes apart every two trunks that pass into each other, half each; whether any did.
    fn separate(&mut self) -> bool {
        let mut moved = false;
        for i in 0..self.mice.len() {
            for j in i + 1..self.mice.len() {
                let (a, b) = (self.mice[i].trunk(), self.mice[j].trunk());
                let (pa, pb) = closest_points(a.0, a.1, b.0, b.1);
                let (dx, dy) = (pb.0 - pa.0, pb.1 - pa.1);
                let d = dx.hypot(dy);
                let touch = a.2 + b.2;
                if d >= touch {
                    continue;
                }
                let (ux, uy) = if d > 1e-6 { (dx / d, dy / d) } else { (1.0, 0.0) };
                let push = (touch - d) / 2.0;
                self.mice[i].shift(-ux * push, -uy * push);
                self.mice[j].shift(ux * push, uy * push);
                moved = true;
            }
        }
        moved
    }
}

impl Animator {
    /// A point of the mouse on the floor: its nose, its tail's base or beside its flank's
    /// middle (on its left).
    fn point(&self, goal: Goal) -> (f64, f64) {
        let p = &self.placement;
        let (c, s) = (p.heading.cos(), p.heading.sin());
        let along = |mm: f64, side: f64| (p.x_mm + mm * c - side * s, p.y_mm + mm * s + side * c);
        match goal {
            Goal::TailBase => along(-TAIL_BASE_MM * p.scale, 0.0),
            Goal::Nose => along(NOSE_MM * p.scale, 0.0),
            Goal::Flank => along(
                0.5 * TRUNK_LENGTH_MM * p.scale,
                2.2 * TRUNK_HALF_WIDTH_MM * p.scale * p.girth,
            ),
        }
    }

    /// The trunk as a capsule on the floor: from the rump forward, and its half width (mm).
    fn trunk(&self) -> ((f64, f64), (f64, f64), f64) {
        let p = &self.placement;
        let length = TRUNK_LENGTH_MM * p.scale;
        let end = (p.x_mm + length * p.heading.cos(), p.y_mm + length * p.heading.sin());
        ((p.x_mm, p.y_mm), end, TRUNK_HALF_WIDTH_MM * p.scale * p.girth)
    }

    /// Walks towards `target` (world x, y): the body bends the way it has to turn.
    fn steer_to(&mut self, target: (f64, f64)) {
        let nose = self.point(Goal::Nose);
        let want = (target.1 - nose.1).atan2(target.0 - nose.0);
        let mut diff = (want - self.placement.heading).rem_euclid(TAU);
        if diff > PI {
            diff -= TAU;
        }
        if self.activity != Activity::Still {
            self.behaviour = Behaviour::Walk;
            self.remaining_s = self.remaining_s.max(0.3);
            self.bend_target = (1.5 * diff).clamp(-1.0, 1.0);
        }
    }

    /// Moves the mouse by `(dx, dy)` mm on the floor, kept inside the cage as [`Self::step`]
    /// keeps it.
    fn shift(&mut self, dx: f64, dy: f64) {
        let hx = CAGE_X_MM / 2.0 - WALL_MARGIN_MM * 0.6;
        let hy = CAGE_Y_MM / 2.0 - WALL_MARGIN_MM * 0.6;
        self.placement.x_mm = (self.placement.x_mm + dx).clamp(-hx, hx);
        self.placement.y_mm = (self.placement.y_mm + dy).clamp(-hy, hy);
    }
}

/// The closest points of the segments `a0 a1` and `b0 b1` (in the plane).
fn closest_points(a0: (f64, f64), a1: (f64, f64), b0: (f64, f64), b1: (f64, f64)) -> ((f64, f64), (f64, f64)) {
    let on = |p: (f64, f64), q0: (f64, f64), q1: (f64, f64)| {
        let (dx, dy) = (q1.0 - q0.0, q1.1 - q0.1);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((p.0 - q0.0) * dx + (p.1 - q0.1) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (q0.0 + t * dx, q0.1 + t * dy)
    };
    let dist = |p: (f64, f64), q: (f64, f64)| (p.0 - q.0).hypot(p.1 - q.1);
    // Segments that cross: their crossing, both.
    let (da, db) = ((a1.0 - a0.0, a1.1 - a0.1), (b1.0 - b0.0, b1.1 - b0.1));
    let denom = da.0 * db.1 - da.1 * db.0;
    if denom.abs() > 1e-12 {
        let t = ((b0.0 - a0.0) * db.1 - (b0.1 - a0.1) * db.0) / denom;
        let u = ((b0.0 - a0.0) * da.1 - (b0.1 - a0.1) * da.0) / denom;
        if (0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u) {
            let p = (a0.0 + t * da.0, a0.1 + t * da.1);
            return (p, p);
        }
    }
    // Otherwise an end of one against the other.
    [
        (a0, on(a0, b0, b1)),
        (a1, on(a1, b0, b1)),
        (on(b0, a0, a1), b0),
        (on(b1, a0, a1), b1),
    ]
    .into_iter()
    .min_by(|x, y| dist(x.0, x.1).total_cmp(&dist(y.0, y.1)))
    .unwrap_or((a0, b0))
}
