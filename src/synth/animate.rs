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
