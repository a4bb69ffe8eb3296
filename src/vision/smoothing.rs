//! The main-body joints smoothed over time: a One Euro filter (Casiez, Roussel and Vogel,
//! CHI 2012) on each joint's position, after the orientation tracker has chosen the head's
//! end. Each frame's forest estimate wobbles by a few millimetres about the mouse's true pose;
//! a low-pass filter takes most of that out, and the One Euro filter's cut-off rises with the
//! joint's speed, so that a still mouse is held steady and a running one is followed closely.
//! Causal: a frame's smoothed joints depend on that frame and the ones before it only, so the
//! daemon's latency does not grow by a frame. A low-pass filter alone trails a moving joint by
//! its time constant, `1 / (2 pi f)` seconds at the cut-off `f` its speed gives: 1-2.3 mm at a
//! walk or a run, behind the body. So each joint's velocity is followed too (the filtered
//! position's own, low-passed), and the joint is moved ahead by that velocity times the lag of
//! the step just taken, in full when the joint moves clearly faster than the filter's own
//! wobble and hardly at all when it is still (see [`SmootherConfig::lead_speed_mm_s`]): a still
//! mouse is held nearly as steady as the filter alone holds it (a real one's joints, wobbling
//! faster, a little less: `docs/FIGURES.md`), a moving one is not placed behind itself. The
//! same velocity gives the pose predicted a little ahead ([`Smoother::velocities`]).
//!
//! `mid_back` is then placed along the body by the spine rather than by its own filter: the
//! filtered centre of `neck`, `withers`, `mid_back` and `rump` plus `mid_back`'s place along
//! the body from that centre averaged over seconds (see [`SmootherConfig::back_along_s`]). On
//! a real mouse each spine joint's place along the back wanders slowly and independently of
//! the others, which no filter of a few frames takes out but their centre averages away.
//! Across the body, each frame's `mid_back` is first moved to the ridge of the back through
//! it, seen in the frame's own surface points (see [`ridge_across`]), and then filtered: the
//! forest places it sideways with a wobble of its own, while the spine runs along the top of
//! the back. The raw joints the frame placed are kept by the caller.
//!
//! The filter starts afresh on the first frame of a mouse, after a gap, for a joint that was
//! not placed in the frame before or that jumped farther than a mouse moves in a frame, and for every joint when the heading turns more than 90
//! degrees from the smoothed one between two frames (the tracker took the other end for the
//! head: the joints swap ends, which no smoothing should blur).

use nalgebra::{Point2, Point3, Vector2, Vector3};

use crate::core::pose::{JointEstimate, JointSource};
use crate::core::skeleton::Joint;
use crate::vision::orientation::{self, BodyJoints};

/// The filter's settings. The defaults were chosen on the first half of a real MoSeq session's
/// frames (its tracker's centroid against `mid_back`; see `docs/FIGURES.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmootherConfig {
    /// The cut-off of a still joint (Hz): the lower, the steadier and the more lag.
    pub min_cutoff_hz: f64,
    /// How much the cut-off rises per mm/s of the joint's speed (Hz per mm/s).
    pub beta_hz_per_mm_s: f64,
    /// The cut-off of the speed's own low-pass filter (Hz).
    pub derivative_cutoff_hz: f64,
    /// A gap between frames longer than this starts the filter afresh (s).
    pub max_gap_s: f64,
    /// A joint placed this far (mm) from where the filter holds it starts afresh: no mouse
    /// moves so far in a frame (1,200 mm/s at 30 fps), so the estimate jumped (or the frames
    /// are not of one continuous scene).
    pub max_jump_mm: f64,
    /// The time constant (s) over which `mid_back`'s place along the body, measured from the
    /// centre of the spine's four joints (`neck`, `withers`, `mid_back`, `rump`), is averaged.
    /// `0` leaves `mid_back` to its own filter like every other joint.
    pub back_along_s: f64,
    /// The cut-off (Hz) of the low-pass filter on each joint's velocity (the filtered
    /// position's change per second), which moves the joint ahead by its lag and predicts it.
    pub velocity_cutoff_hz: f64,
    /// The speed (mm/s) at which the joint is moved half its lag ahead: by a share
    /// `s^2 / (s^2 + lead_speed^2)` of it at speed `s`, so that the velocity's own wobble on a
    /// still joint (2-5 mm/s) moves it by a few hundredths of a millimetre. `0` moves it the
    /// whole lag at any speed; infinity not at all (the plain One Euro filter).
    pub lead_speed_mm_s: f64,
    /// The speed (mm/s) of the body as a whole (the mean of its joints' velocities) at which
    /// the pose predicted ahead takes half of each joint's velocity: a share
    /// `s^2 / (s^2 + predict_speed^2)` of it at the body's speed `s`. A real mouse sitting
    /// still wobbles its joints by millimetres a frame, velocities of 20-40 mm/s that point
    /// nowhere; moved on by them, its pose predicted 100 ms ahead lands farther from where it
    /// then is than the pose held (`scripts/prediction-error`). `0` takes the whole velocity.
    pub predict_speed_mm_s: f64,
    /// Half the thickness (mm) of the slab across the body, through `mid_back`, in which its
    /// place across the body is taken from the body's surface (see [`ridge_across`]). `0`
    /// leaves it where the frame placed it.
    pub across_slab_mm: f64,
    /// The surface points of that slab at least this share of its highest point's height
    /// above the floor make the back's ridge, whose middle `mid_back` is moved to.
    pub ridge_height_share: f64,
}

impl Default for SmootherConfig {
    fn default() -> Self {
        Self {
            min_cutoff_hz: 3.0,
            beta_hz_per_mm_s: 0.07,
            derivative_cutoff_hz: 1.0,
            max_gap_s: 0.5,
            max_jump_mm: 40.0,
            back_along_s: 10.0,
            velocity_cutoff_hz: 2.0,
            lead_speed_mm_s: 15.0,
            predict_speed_mm_s: 30.0,
            across_slab_mm: 2.0,
            ridge_height_share: 0.8,
        }
    }
}

impl SmootherConfig {
    /// The lag (s) the low-pass filter alone leaves behind a joint moving steadily at
    /// `speed_mm_s`: its time constant at the cut-off that speed gives.
    pub fn filter_lag_s(&self, speed_mm_s: f64) -> f64 {
        1.0 / (2.0 * std::f64::consts::PI * self.cutoff_hz(speed_mm_s))
    }

    /// The share of the filter's lag a joint moving at `speed_mm_s` is moved ahead by.
    fn lead_share(&self, speed_mm_s: f64) -> f64 {
        share(speed_mm_s, self.lead_speed_mm_s)
    }

    fn cutoff_hz(&self, speed_mm_s: f64) -> f64 {
        self.min_cutoff_hz + self.beta_hz_per_mm_s * speed_mm_s
    }
}

/// `s^2 / (s^2 + half^2)` at the speed `s`: 0 when still, a half at `half`, nearly 1 well
/// above it (none with an infinite `half`: a finite number over infinity is 0; all with `0`).
fn share(speed_mm_s: f64, half_mm_s: f64) -> f64 {
    let s2 = speed_mm_s * speed_mm_s;
    let h2 = half_mm_s * half_mm_s;
    if s2 + h2 > 0.0 { s2 / (s2 + h2) } else { 1.0 }
}

/// The share of a new sample an exponential filter with this cut-off takes after `dt_s`.
fn alpha(cutoff_hz: f64, dt_s: f64) -> f64 {
    let tau = 1.0 / (2.0 * std::f64::consts::PI * cutoff_hz);
    1.0 / (1.0 + tau / dt_s)
}

/// One joint's filter state: its low-passed position and speed (the One Euro filter's own,
/// which sets its cut-off), the low-passed position's velocity, and how far ahead of the
/// low-passed position the joint is placed.
#[derive(Clone, Copy, Debug)]
struct OneEuro {
    position_mm: Point3<f64>,
    velocity_mm_s: Vector3<f64>,
    trend_mm_s: Vector3<f64>,
    lead_mm: Vector3<f64>,
}

impl OneEuro {
    /// A filter started at `position_mm`, still.
    fn at(position_mm: Point3<f64>) -> Self {
        Self {
            position_mm,
            velocity_mm_s: Vector3::zeros(),
            trend_mm_s: Vector3::zeros(),
            lead_mm: Vector3::zeros(),
        }
    }

    /// Where the joint is placed: the low-passed position moved ahead by its lag.
    fn placed(&self) -> Point3<f64> {
        self.position_mm + self.lead_mm
    }

    /// The same filter moved by `by` (its velocities kept).
    fn moved(self, by: Vector3<f64>) -> Self {
        Self {
            position_mm: self.position_mm + by,
            ..self
        }
    }
}

/// Smooths the main-body joints of successive frames of one mouse.
#[derive(Clone, Debug)]
pub struct Smoother {
    config: SmootherConfig,
    joints: [Option<OneEuro>; 12],
    /// The centre of the spine's joints, filtered as a joint is.
    spine: Option<OneEuro>,
    /// `mid_back`'s place along the body from the spine's centre (mm, toward the head),
    /// averaged over `back_along_s`.
    back_along_mm: Option<f64>,
    last_ns: Option<u64>,
    /// Scratch for [`ridge_across`]: the slab's points, across the axis and in height (mm).
    slab: Vec<(f64, f64)>,
}

impl Smoother {
    pub fn new(config: SmootherConfig) -> Self {
        Self {
            config,
            joints: [None; 12],
            spine: None,
            back_along_mm: None,
            last_ns: None,
            slab: Vec::new(),
        }
    }

    /// Each main-body joint's velocity (mm/s, world frame) as the last frame left it, for the
    /// pose predicted ahead: its smoothed position's own, low-passed (zero just after the
    /// filter started afresh), taken by a share that the body's speed as a whole gives (see
    /// [`SmootherConfig::predict_speed_mm_s`]); `None` for a joint it does not follow (not
    /// placed in the last frame, or the tail tip). A joint `t` seconds after that frame is
    /// predicted at its smoothed place plus `t` times this.
    pub fn velocities(&self) -> [Option<Vector3<f64>>; 12] {
        let (sum, n) = self
            .joints
            .iter()
            .flatten()
            .fold((Vector3::zeros(), 0.0), |(sum, n), s| (sum + s.trend_mm_s, n + 1.0));
        let body_mm_s = if n > 0.0 { (sum / n).norm() } else { 0.0 };
        let taken = share(body_mm_s, self.config.predict_speed_mm_s);
        self.joints.map(|state| state.map(|s| s.trend_mm_s * taken))
    }

    /// Forgets every joint: the next frame starts afresh (a frame without a mouse).
    pub fn reset(&mut self) {
        *self = Self::new(self.config);
    }

    /// Smooths `joints`, the frame at `device_ns`'s estimates, in place. Joints that were not
    /// placed (source `missing`) are left alone and their filter forgotten; so is `tail_tip`,
    /// which the tail search places where it sees the tail end, and which whips faster than
    /// the filter follows (on renders 141 mm/s at the median against 15-26 mm/s for the
    /// body's joints).
    ///
    /// `body` is the mouse's surface in the frame (world points, mm; its tail left out):
    /// `mid_back` is first moved across the body to the ridge of the back there (see
    /// [`ridge_across`]); empty, it stays where the frame placed it.
    pub fn smooth(&mut self, device_ns: u64, joints: &mut BodyJoints, body: &[Point3<f64>]) {
        self.move_to_ridge(joints, body);
        let dt_s = self
            .last_ns
            .map(|last| device_ns.saturating_sub(last) as f64 * 1e-9)
            .filter(|&dt| dt > 0.0 && dt <= self.config.max_gap_s);
        let smoothed: BodyJoints = std::array::from_fn(|k| {
            let mut j = joints[k];
            if let Some(state) = self.joints[k] {
                j.position_mm = state.placed();
            }
            j
        });
        let turned = match (orientation::heading(&smoothed), orientation::heading(joints)) {
            (Some(before), Some(now)) => before.dot(&now) < 0.0,
            _ => false,
        };
        if dt_s.is_none() || turned {
            self.joints = [None; 12];
            self.spine = None;
            self.back_along_mm = None;
        }
        self.last_ns = Some(device_ns);
        let raw = *joints;
        let config = self.config;
        for ((state, joint), which) in self.joints.iter_mut().zip(joints.iter_mut()).zip(Joint::MAIN_BODY) {
            *state = (which != Joint::TailTip)
                .then(|| step(&config, *state, joint, dt_s))
                .flatten();
        }
        self.place_mid_back(&raw, joints, dt_s);
    }

    /// Moves `mid_back` across the body's axis to the middle of the back's ridge there.
    fn move_to_ridge(&mut self, joints: &mut BodyJoints, body: &[Point3<f64>]) {
        if self.config.across_slab_mm <= 0.0 {
            return;
        }
        let Some(axis) = body_axis(joints).map(|a| a.normalize()) else {
            return;
        };
        let mid_back = &mut joints[Joint::MidBack.index()];
        if mid_back.source == JointSource::Missing {
            return;
        }
        if let Some(shift) = ridge_across(&self.config, &mid_back.position_mm, &axis, body, &mut self.slab) {
            mid_back.position_mm += shift;
        }
    }

    /// Moves the smoothed `mid_back` along the body to the spine's filtered centre plus its
    /// averaged place from that centre, keeping its own place across the body and in height.
    /// Each spine joint's place along the body wanders by a few millimetres, slowly (a filter
    /// over a few frames does not take it out) and independently of the others (the middle of
    /// the back has no feature along its length for the forest to place it by), so their
    /// centre wanders less than any of them. Needs the four spine joints and the heading;
    /// without them `mid_back` keeps its own filter's place and the averages start afresh.
    fn place_mid_back(&mut self, raw: &BodyJoints, joints: &mut BodyJoints, dt_s: Option<f64>) {
        let config = self.config;
        let placed = |joint: Joint| {
            let j = &raw[joint.index()];
            (j.source != JointSource::Missing).then_some(j.position_mm.coords)
        };
        let centre = SPINE
            .map(placed)
            .iter()
            .try_fold(Vector3::zeros(), |sum, p| p.map(|p| sum + p))
            .map(|sum| Point3::from(sum / SPINE.len() as f64));
        let axis = body_axis(raw).map(|h| h.normalize());
        let (Some(centre), Some(axis), true) = (centre, axis, config.back_along_s > 0.0) else {
            self.spine = None;
            self.back_along_mm = None;
            return;
        };
        let along_axis = Vector3::new(axis.x, axis.y, 0.0);
        let offset = raw[Joint::MidBack.index()].position_mm - centre;
        let along_now = offset.dot(&along_axis);
        let mid_back = &mut joints[Joint::MidBack.index()];
        // Starting afresh, the centre is taken where it puts `mid_back` at its own filter's
        // place, so that `mid_back` does not jump when a spine joint comes back.
        let filtered_centre = match (self.spine, self.joints[Joint::MidBack.index()]) {
            (None, Some(own)) => own.moved(-offset),
            (state, _) => filtered(&config, state, centre, dt_s),
        };
        let along = match (self.back_along_mm, dt_s) {
            (Some(before), Some(dt)) if self.spine.is_some() => {
                before + dt / (config.back_along_s + dt) * (along_now - before)
            }
            _ => along_now,
        };
        self.spine = Some(filtered_centre);
        self.back_along_mm = Some(along);
        // Along the body from the spine; across it and in height its own filter's place.
        let own = mid_back.position_mm;
        mid_back.position_mm =
            own + (filtered_centre.placed() + along * along_axis - own).dot(&along_axis) * along_axis;
    }
}

/// The spine's joints, whose centre places `mid_back` along the body.
const SPINE: [Joint; 4] = [Joint::Neck, Joint::Withers, Joint::MidBack, Joint::Rump];

/// The body's axis seen from above (world x, y; toward the head, not of unit length): from
/// the tail base to the snout when both are placed (the longer base wobbles less than the
/// neck's: chosen on the first half of the real MoSeq session), else to the neck.
fn body_axis(joints: &BodyJoints) -> Option<Vector2<f64>> {
    let placed = |joint: Joint| {
        let j = &joints[joint.index()];
        (j.source != JointSource::Missing).then_some(j.position_mm)
    };
    match (placed(Joint::Snout), placed(Joint::TailBase)) {
        (Some(snout), Some(tail_base)) => orientation::heading_between(&snout, &tail_base),
        _ => orientation::heading(joints),
    }
}

/// Fewer of the body's points than this in the slab say nothing of its cross-section.
const MIN_SLAB_POINTS: usize = 3;

/// A gap across the body wider than this (mm, about three depth pixels at a mouse) between
/// the slab's points parts two pieces of body: on a curled mouse the slab may cross the other
/// side of the curl too.
const SLAB_GAP_MM: f64 = 6.0;

/// The shift across `axis` (world x, y, unit length) that puts `at` on the middle of the
/// back's ridge: of the `body` points within `config.across_slab_mm` of `at` along the axis,
/// the piece across the axis that holds `at` (or the nearest piece), and of it the points at
/// least `config.ridge_height_share` of its highest point's height above the floor; their
/// mean place across the axis. The top of the back, not the whole cross-section: a camera
/// off to one side sees more of the mouse's flank facing it, which would pull the middle of
/// all the points seen toward it, while the ridge is seen from either side. `slab` is
/// scratch space.
fn ridge_across(
    config: &SmootherConfig,
    at: &Point3<f64>,
    axis: &Vector2<f64>,
    body: &[Point3<f64>],
    slab: &mut Vec<(f64, f64)>,
) -> Option<Vector3<f64>> {
    let normal = Vector2::new(-axis.y, axis.x);
    let at = Point2::new(at.x, at.y);
    slab.clear();
    slab.extend(body.iter().filter_map(|p| {
        let d = Point2::new(p.x, p.y) - at;
        (d.dot(axis).abs() <= config.across_slab_mm).then(|| (d.dot(&normal), p.z))
    }));
    if slab.len() < MIN_SLAB_POINTS {
        return None;
    }
    slab.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    // The piece nearest `at` (0 across): its distance from it, first and last index.
    let mut nearest: Option<(f64, usize, usize)> = None;
    let mut start = 0;
    for k in 1..=slab.len() {
        if k < slab.len() && slab[k].0 - slab[k - 1].0 <= SLAB_GAP_MM {
            continue;
        }
        let distance = slab[start].0.max(0.0) + (-slab[k - 1].0).max(0.0);
        if nearest.is_none_or(|(d, _, _)| distance < d) {
            nearest = Some((distance, start, k - 1));
        }
        start = k;
    }
    let (_, first, last) = nearest?;
    let piece = &slab[first..=last];
    let top = piece.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    let (sum, count) = piece
        .iter()
        .filter(|p| p.1 >= config.ridge_height_share * top)
        .fold((0.0, 0usize), |(sum, count), p| (sum + p.0, count + 1));
    (count > 0).then(|| Vector3::new(normal.x, normal.y, 0.0) * (sum / count as f64))
}

/// One joint's step: its new state, with `joint` moved to its smoothed position.
fn step(
    config: &SmootherConfig,
    state: Option<OneEuro>,
    joint: &mut JointEstimate,
    dt_s: Option<f64>,
) -> Option<OneEuro> {
    if joint.source == JointSource::Missing {
        return None;
    }
    let next = filtered(config, state, joint.position_mm, dt_s);
    joint.position_mm = next.placed();
    Some(next)
}

/// The One Euro filter's step from `state` to the new sample `position_mm`, `dt_s` after it
/// (`None`: start afresh, as it also does after a jump farther than `max_jump_mm`), and the
/// lead that undoes its lag. A step that takes the share `a` of the new sample leaves a joint
/// moving steadily at `v` behind by `v dt (1 - a) / a` (the continuous filter's `v tau`);
/// `v` is the low-passed position's own velocity, which at a steady speed is the joint's.
fn filtered(config: &SmootherConfig, state: Option<OneEuro>, position_mm: Point3<f64>, dt_s: Option<f64>) -> OneEuro {
    match (state, dt_s) {
        (Some(s), Some(dt)) if (position_mm - s.position_mm).norm() <= config.max_jump_mm => {
            let raw_velocity = (position_mm - s.position_mm) / dt;
            let velocity_mm_s =
                s.velocity_mm_s + alpha(config.derivative_cutoff_hz, dt) * (raw_velocity - s.velocity_mm_s);
            let a = alpha(config.cutoff_hz(velocity_mm_s.norm()), dt);
            let moved = a * (position_mm - s.position_mm);
            let trend_mm_s = s.trend_mm_s + alpha(config.velocity_cutoff_hz, dt) * (moved / dt - s.trend_mm_s);
            let lag_s = dt * (1.0 - a) / a;
            OneEuro {
                position_mm: s.position_mm + moved,
                velocity_mm_s,
                trend_mm_s,
                lead_mm: trend_mm_s * (lag_s * config.lead_share(trend_mm_s.norm())),
            }
        }
        _ => OneEuro::at(position_mm),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRAME_NS: u64 = 33_333_333;

    /// A straight mouse along +x (head toward +x), its joints `dx` mm along x.
    fn body(dx: f64) -> BodyJoints {
        std::array::from_fn(|k| {
            let along = f64::from(orientation::end_of(Joint::MAIN_BODY[k])) * 30.0;
            JointEstimate {
                position_mm: Point3::new(dx + along, 0.0, 20.0),
                score: 1.0,
                source: JointSource::Depth,
            }
        })
    }

    fn x_of(joints: &BodyJoints, joint: Joint) -> f64 {
        joints[joint.index()].position_mm.x
    }

    #[test]
    fn jitter_is_damped_and_a_still_mouse_is_not_moved() {
        let mut smoother = Smoother::new(SmootherConfig::default());
        let (mut raw_sq, mut smooth_sq) = (0.0, 0.0);
        for k in 0..300u64 {
            // Jitter of +-2 mm, alternating with a period that is not a multiple of two frames.
            let noise = 2.0 * ((k as f64) * 2.3).sin();
            let mut joints = body(noise);
            smoother.smooth(k * FRAME_NS, &mut joints, &[]);
            if k >= 30 {
                raw_sq += noise * noise;
                smooth_sq += x_of(&joints, Joint::MidBack).powi(2);
            }
        }
        assert!(smooth_sq < 0.3 * raw_sq, "smoothed {smooth_sq} against raw {raw_sq}");
    }

    /// The mouse moving steadily along +x at `speed_mm_s` for two seconds: how far (mm) its
    /// smoothed `mid_back` and `snout` end behind the true ones.
    fn behind_after_two_seconds(config: SmootherConfig, speed_mm_s: f64) -> [f64; 2] {
        let mut smoother = Smoother::new(config);
        let mut behind = [0.0; 2];
        for k in 0..60u64 {
            let x = speed_mm_s * k as f64 * FRAME_NS as f64 * 1e-9;
            let mut joints = body(x);
            smoother.smooth(k * FRAME_NS, &mut joints, &[]);
            behind = [Joint::MidBack, Joint::Snout].map(|j| x_of(&body(x), j) - x_of(&joints, j));
        }
        behind
    }

    #[test]
    fn a_moving_mouse_is_not_placed_behind_itself() {
        let config = SmootherConfig::default();
        for speed_mm_s in [20.0, 50.0, 100.0, 200.0, 400.0] {
            // Half a frame's travel at this speed, and 1 mm: the goals.
            let bound = (0.5 * speed_mm_s * FRAME_NS as f64 * 1e-9).min(1.0);
            for behind in behind_after_two_seconds(config, speed_mm_s) {
                assert!(behind.abs() < bound, "{speed_mm_s} mm/s: {behind} mm behind");
            }
            // The low-pass filter alone trails by about its time constant (a little more:
            // the discrete filter), which is what the lead undoes.
            let plain = SmootherConfig {
                lead_speed_mm_s: f64::INFINITY,
                ..config
            };
            let expected_mm = speed_mm_s * config.filter_lag_s(speed_mm_s);
            for behind in behind_after_two_seconds(plain, speed_mm_s) {
                assert!(
                    behind > 0.5 * expected_mm && behind < 1.5 * expected_mm + 0.5,
                    "{speed_mm_s} mm/s, the filter alone: {behind} mm behind, expected {expected_mm} mm"
                );
            }
        }
    }

    #[test]
    fn the_velocities_are_the_mouses() {
        use rand::Rng as _;
        use rand_distr::StandardNormal;
        let mut smoother = Smoother::new(SmootherConfig::default());
        for k in 0..60u64 {
            let x = 150.0 * k as f64 * FRAME_NS as f64 * 1e-9;
            smoother.smooth(k * FRAME_NS, &mut body(x), &[]);
        }
        // Running: nearly the whole velocity (150^2 / (150^2 + 30^2) of it).
        let taken = 150.0 * 150.0 / (150.0 * 150.0 + 30.0 * 30.0);
        for (joint, v) in Joint::MAIN_BODY.iter().zip(smoother.velocities()) {
            match (joint, v) {
                (Joint::TailTip, v) => assert_eq!(v, None),
                (_, Some(v)) => assert!(
                    (v - Vector3::new(150.0 * taken, 0.0, 0.0)).norm() < 1.0,
                    "{joint:?}: {v}"
                ),
                (_, None) => panic!("{joint:?} has no velocity"),
            }
        }
        // Still, each joint wobbling by its own millimetre or two a frame: next to nothing.
        let mut smoother = Smoother::new(SmootherConfig::default());
        let mut rng = crate::core::rng::item_rng(7, 0, 0);
        for k in 0..90u64 {
            let mut joints = body(0.0);
            for j in &mut joints {
                let (dx, dy): (f64, f64) = (rng.sample(StandardNormal), rng.sample(StandardNormal));
                j.position_mm += Vector3::new(dx, dy, 0.0) * 1.5;
            }
            smoother.smooth(k * FRAME_NS, &mut joints, &[]);
        }
        let fastest = smoother
            .velocities()
            .iter()
            .flatten()
            .map(|v| v.norm())
            .fold(0.0, f64::max);
        assert!(
            fastest < 5.0,
            "a still mouse's joints predicted to move at {fastest:.1} mm/s"
        );
    }

    #[test]
    fn mid_back_wandering_alone_along_the_body_is_held_by_the_spine() {
        let mut smoother = Smoother::new(SmootherConfig::default());
        let (mut raw_sq, mut smooth_sq, mut across_sq) = (0.0, 0.0, 0.0);
        for k in 0..600u64 {
            // `mid_back` alone wanders 3 mm along the body with a period of a second, too
            // slowly for a filter of a few frames; across the body it stands 1 mm aside.
            let wander = 3.0 * (k as f64 * 2.0 * std::f64::consts::PI / 30.0).sin();
            let mut joints = body(0.0);
            joints[Joint::MidBack.index()].position_mm.x = wander;
            joints[Joint::MidBack.index()].position_mm.y = 1.0;
            smoother.smooth(k * FRAME_NS, &mut joints, &[]);
            if k >= 300 {
                raw_sq += wander * wander;
                smooth_sq += x_of(&joints, Joint::MidBack).powi(2);
                across_sq += (joints[Joint::MidBack.index()].position_mm.y - 1.0).powi(2);
            }
        }
        assert!(smooth_sq < 0.1 * raw_sq, "smoothed {smooth_sq} against raw {raw_sq}");
        assert!(across_sq < 1e-6 * raw_sq, "moved across the body: {across_sq}");
    }

    /// A back along x seen from above: a rounded ridge 12 mm to either side of y = 0, 30 mm
    /// high at its middle; beside it toward +y more of its flank in view, low and densely
    /// seen (as a camera off to that side sees it); and, across a gap, the other side of a
    /// curl at y = 30-43.5 mm, higher still.
    fn back_surface() -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        for i in -40..=40 {
            let x = f64::from(i) * 1.5;
            for j in -8..=8 {
                let y = f64::from(j) * 1.5;
                points.push(Point3::new(x, y, 30.0 * (1.0 - (y / 14.0).powi(2)).sqrt()));
            }
            for j in 0..20 {
                points.push(Point3::new(x, 12.5 + f64::from(j) * 0.3, 8.0));
            }
            for j in 0..10 {
                points.push(Point3::new(x, 30.0 + f64::from(j) * 1.5, 35.0));
            }
        }
        points
    }

    #[test]
    fn mid_back_wobbling_sideways_is_held_on_the_ridge_of_the_back() {
        let surface = back_surface();
        for (body_seen, held) in [(&surface[..], true), (&[][..], false)] {
            let mut smoother = Smoother::new(SmootherConfig::default());
            let mut worst_mm: f64 = 0.0;
            for k in 0..120u64 {
                // 3 mm to either side, once a second: slowly enough for the filter to follow.
                let wobble = 3.0 * (k as f64 * 2.0 * std::f64::consts::PI / 30.0).sin();
                let mut joints = body(0.0);
                joints[Joint::MidBack.index()].position_mm.y = wobble;
                smoother.smooth(k * FRAME_NS, &mut joints, body_seen);
                if k >= 30 {
                    worst_mm = worst_mm.max(joints[Joint::MidBack.index()].position_mm.y.abs());
                }
            }
            if held {
                assert!(worst_mm < 1e-6, "{worst_mm} mm off the ridge");
            } else {
                assert!(
                    worst_mm > 1.5,
                    "without the body's surface the filter alone: {worst_mm} mm"
                );
            }
        }
    }

    #[test]
    fn a_swap_of_ends_a_gap_and_a_missing_joint_start_afresh() {
        let mut smoother = Smoother::new(SmootherConfig::default());
        for k in 0..10u64 {
            smoother.smooth(k * FRAME_NS, &mut body(0.0), &[]);
        }
        // The tracker takes the other end for the head: the joints are taken as they are.
        let mut swapped: BodyJoints = body(0.0);
        for j in &mut swapped {
            j.position_mm.x = -j.position_mm.x;
        }
        let expected = swapped;
        smoother.smooth(10 * FRAME_NS, &mut swapped, &[]);
        assert_eq!(swapped, expected);
        // A second later, the mouse has moved 50 mm: taken as it is.
        let mut later = body(50.0);
        smoother.smooth(40 * FRAME_NS, &mut later, &[]);
        assert_eq!(later, body(50.0));
        // The rump missing for one frame is taken as it is when it returns; the tail tip is
        // never smoothed.
        let mut rump_gone = body(50.0);
        rump_gone[Joint::Rump.index()].source = JointSource::Missing;
        smoother.smooth(41 * FRAME_NS, &mut rump_gone, &[]);
        let mut back = body(52.0);
        smoother.smooth(42 * FRAME_NS, &mut back, &[]);
        for joint in [Joint::Rump, Joint::TailTip] {
            assert_eq!(back[joint.index()], body(52.0)[joint.index()], "{joint:?}");
        }
        assert!(x_of(&back, Joint::MidBack) < 52.0);
    }
}
