//! The synchroniser: pairs depth and colour frames by when they were taken.
//!
//! Pure code: no threads, no clock reads. Frames go in per camera, in the order the camera
//! delivered them; pairs, unpaired colour frames and rejected frames come out, each input
//! exactly once.
//!
//! The two cameras have their own clocks with unknown epochs that drift apart by tens of ppm.
//! Each camera's clock is tied to the host's monotonic clock by a [`ClockModel`]: the lower
//! envelope of `host_ns - device_ns` (arrival is capture plus a latency that is never below
//! its minimum), fitted as a line over the per-second minima of the recent past, which follows
//! both the offset and the drift. A frame's capture time on the common (host) time line is then
//! `device_ns + offset(device_ns)`; a depth frame pairs with the colour frame nearest to it on
//! that line, within the tolerance (half a depth frame interval by default). A constant
//! difference between the two cameras' minimal latencies shifts every colour frame alike; the
//! config's `color_latency_ns` corrects it when known.
//!
//! A depth frame goes out as soon as no colour frame still to come can be a nearer partner.
//! Live, a partner wait ([`SyncConfig::partner_wait_ns`]) bounds that: at its end (told by
//! [`Synchronizer::tick`], or at once when the next colour frame cannot arrive before it) the
//! depth frame pairs with the nearest colour frame in within the tolerance, or goes out
//! depth-only, and the decision is counted as unproven; a partner reach
//! ([`SyncConfig::partner_reach_ns`]) widens what it may pair with then. Replay pairs exactly,
//! unless told to pair as a live run with a partner wait did (the frames' own arrivals then
//! end the wait: [`Synchronizer::push_color`] first decides what ended before it).
//!
//! Faults a rig meets: frames held up and delivered in a burst (a USB or network stall) are
//! paired by the model but do not fit it (a frame 20 ms later than the model expects, and its
//! block of the envelope, are left out; a Theil-Sen line shrugs off the rest), so they go out
//! unpaired rather than wrongly paired; a latency that stays late for 5 s is learnt again. A
//! frame counter or device clock that starts again (three backward frames in a row) or jumps
//! ahead is logged and that camera's clock learnt again. Not covered: a counter or clock that
//! starts again in the middle of a stall, when nothing in the stamps tells late from on time.

use crate::core::frame::{ColorFrame, DepthFrame, FramePair, Stamp};
use std::collections::VecDeque;
use std::sync::Arc;

/// How the synchroniser pairs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SyncConfig {
    /// Largest capture-time difference of a pair; `None`: half the depth frame interval seen
    /// so far (1/60 s until two depth frames have arrived).
    pub tolerance_ns: Option<u64>,
    /// Whether a colour camera is expected at all. Without one every depth frame goes out at
    /// once as a depth-only pair.
    pub color: bool,
    /// How long (capture time) a depth frame waits for a colour partner before it goes out
    /// depth-only; a colour camera that delivered nothing for twice as long (host time) is
    /// not waited for at all. A colour camera that stalls must not stall the pipeline, and
    /// one whose frames come late in a burst must still pair: as long as the daemon's stall
    /// time by default, since until then the camera is not taken for gone.
    pub max_wait_ns: u64,
    /// The colour camera's minimal latency minus the depth camera's, when known (ns).
    pub color_latency_ns: i64,
    /// How long (host time from its arrival) a depth frame waits for a colour frame still to
    /// come that could be a nearer partner than those in; then it pairs with the nearest
    /// colour frame in within the tolerance, or goes out depth-only. `None`: it waits until
    /// the nearest partner is known (exact pairing, what replay does). A live pipeline decides
    /// at the latest at the end of the wait only if something calls [`Synchronizer::tick`]
    /// then ([`Synchronizer::due_ns`] says when); without ticks, at the next frame's arrival.
    pub partner_wait_ns: Option<u64>,
    /// How far (capture time) from a depth frame the colour frame it pairs with at the end of
    /// its partner wait may have been taken; `None`: the tolerance. One colour frame interval
    /// pairs a depth frame whose nearer partner is still to come with the one taken before
    /// it: its paws are then seen up to an interval earlier. When that one went to the depth
    /// frame before, it pairs again if in reach ([`FramePair::color_again`]).
    pub partner_reach_ns: Option<u64>,
}

impl Default for SyncConfig {
    fn default() -> Self {
        Self {
            tolerance_ns: None,
            color: true,
            max_wait_ns: DEFAULT_MAX_WAIT_NS,
            color_latency_ns: 0,
            partner_wait_ns: None,
            partner_reach_ns: None,
        }
    }
}

/// The default of [`SyncConfig::max_wait_ns`]: the default stall time of a camera.
pub const DEFAULT_MAX_WAIT_NS: u64 = 2_000_000_000;

/// What the synchroniser emits. Every frame pushed in comes out in exactly one of these.
#[derive(Debug)]
pub enum SyncOutput {
    /// A depth frame, with its colour partner if it has one.
    Pair(FramePair),
    /// A colour frame no depth frame claimed.
    UnpairedColor(Arc<ColorFrame>),
    /// A frame refused because it is out of order (its device time or sequence number does
    /// not follow the previous frame of its camera).
    Rejected {
        role: Role,
        stamp: Stamp,
        reason: RejectReason,
    },
}

/// Which camera a rejected frame came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Depth,
    Color,
}

/// Why a frame was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RejectReason {
    /// Its sequence number is not above the previous frame's.
    SequenceNotIncreasing,
    /// Its device time is not after the previous frame's.
    TimeNotIncreasing,
}

impl RejectReason {
    /// The reason's name in counters and summaries.
    pub fn name(self) -> &'static str {
        match self {
            RejectReason::SequenceNotIncreasing => "seq_out_of_order",
            RejectReason::TimeNotIncreasing => "time_out_of_order",
        }
    }
}

/// One camera's device clock tied to the host clock.
#[derive(Clone, Debug, Default)]
pub struct ClockModel {
    /// Per block of [`BLOCK_NS`] device time: the device time and `host - device` of the frame
    /// with the smallest `host - device` (the least delayed arrival), oldest first.
    minima: VecDeque<(u64, i64)>,
    /// The line through the completed blocks' minima: `host - device` at device time `t` is
    /// `.0 + .1 * (t - .2)`.
    line: Option<(f64, f64, u64)>,
    /// The smallest `host - device` seen, used until the line exists.
    lowest: Option<i64>,
    first_ns: Option<u64>,
    /// Device time of the first frame of the current run of late frames.
    late_since: Option<u64>,
    /// Blocks that had late frames: left out of the fit (their minimum may be a late frame).
    tainted: std::collections::BTreeSet<u64>,
}

/// A frame reaching the host this much later than the model expects is late (a stall, then a
/// burst): it is paired by the model but not used to fit it.
const LATE_NS: i64 = 20_000_000;
/// Frames late for this long (device time) mean the camera's latency really changed: the
/// model is learnt again.
const LATE_RELEARN_NS: u64 = 5_000_000_000;

/// Length of a block of the lower envelope.
const BLOCK_NS: u64 = 1_000_000_000;
/// Blocks the line is fitted over (the recent past only, so that the fit follows changes).
const BLOCKS: usize = 30;
/// The least device time between two blocks' minima for their slope to count: each minimum
/// lies anywhere in its block, and two of them a tenth of a second apart, one of them a few
/// hundred microseconds above the envelope (its block had no frame as little delayed), made a
/// slope of thousands of ppm that moved frames seconds later by a third of a frame interval.
const MIN_SLOPE_SPAN_NS: f64 = 2e9;
/// The largest drift a camera clock has (crystals are within about 100 ppm): a steeper slope
/// is the fit's error, not the clock's.
const MAX_DRIFT: f64 = 1e-3;

impl ClockModel {
    /// Adds a frame's stamp.
    pub fn observe(&mut self, stamp: Stamp) {
        let residual = stamp.host_ns as i64 - stamp.device_ns as i64;
        if let Some(expected) = self.offset_ns(stamp.device_ns) {
            if residual - expected > LATE_NS {
                let since = *self.late_since.get_or_insert(stamp.device_ns);
                if stamp.device_ns.saturating_sub(since) < LATE_RELEARN_NS {
                    if let Some(first) = self.first_ns {
                        self.tainted.insert(stamp.device_ns.saturating_sub(first) / BLOCK_NS);
                    }
                    return;
                }
                *self = ClockModel::default();
            } else {
                self.late_since = None;
            }
        }
        let first = *self.first_ns.get_or_insert(stamp.device_ns);
        self.lowest = Some(self.lowest.map_or(residual, |l| l.min(residual)));
        let block_of = |t: u64| t.saturating_sub(first) / BLOCK_NS;
        match self.minima.back_mut() {
            Some(last) if block_of(last.0) == block_of(stamp.device_ns) => {
                if residual < last.1 {
                    *last = (stamp.device_ns, residual);
                }
            }
            _ => {
                self.minima.push_back((stamp.device_ns, residual));
                if self.minima.len() > BLOCKS {
                    self.minima.pop_front();
                }
                if let Some(&(oldest, _)) = self.minima.front() {
                    let oldest = block_of(oldest);
                    self.tainted.retain(|&b| b >= oldest);
                }
                self.refit();
            }
        }
    }

    /// Fits the line through the minima of the completed blocks (all but the newest, which is
    /// still filling); none before two blocks are complete. Theil-Sen (the median of the
    /// pairwise slopes, then the median intercept): a block whose every frame arrived late (a
    /// stall, then a burst) is an outlier that moves a least-squares line by a good part of
    /// its delay, and the median not at all while such blocks are under a third.
    fn refit(&mut self) {
        let done = self.minima.len().saturating_sub(1);
        let (Some(&(t0, _)), Some(first)) = (self.minima.front(), self.first_ns) else {
            return;
        };
        let pts: Vec<(f64, f64)> = self
            .minima
            .iter()
            .take(done)
            .filter(|&&(t, _)| !self.tainted.contains(&(t.saturating_sub(first) / BLOCK_NS)))
            .map(|&(t, r)| ((t - t0) as f64, r as f64))
            .collect();
        if pts.len() < 2 {
            // Too few clean blocks: keep the line there is (none at the start).
            if done < 2 {
                self.line = None;
            }
            return;
        }
        let mut slopes: Vec<f64> = Vec::with_capacity(pts.len() * pts.len() / 2);
        for (i, a) in pts.iter().enumerate() {
            for b in &pts[i + 1..] {
                if b.0 - a.0 >= MIN_SLOPE_SPAN_NS {
                    slopes.push((b.1 - a.1) / (b.0 - a.0));
                }
            }
        }
        // Until the blocks span enough time to tell a drift, the clocks are taken not to drift
        // (tens of ppm are microseconds over a few seconds) and the line is the lower envelope.
        let Some(slope) = crate::core::median(&mut slopes) else {
            let lowest = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
            self.line = Some((lowest, 0.0, t0));
            return;
        };
        let slope = slope.clamp(-MAX_DRIFT, MAX_DRIFT);
        let mut intercepts: Vec<f64> = pts.iter().map(|p| p.1 - slope * p.0).collect();
        self.line = crate::core::median(&mut intercepts).map(|a| (a, slope, t0));
    }

    /// `host - device` at device time `device_ns`: the clocks' offset plus the camera's
    /// minimal latency. `None` before the first frame.
    pub fn offset_ns(&self, device_ns: u64) -> Option<i64> {
        match self.line {
            Some((a, b, t0)) => Some((a + b * (device_ns as f64 - t0 as f64)).round() as i64),
            None => self.lowest,
        }
    }

    /// Whether the line through the minima exists (two whole blocks in since the clock was
    /// learnt last), so that the envelope is more than the lowest of the first frames.
    pub fn fitted(&self) -> bool {
        self.line.is_some()
    }

    /// The device clock's rate relative to the host's, in ppm (positive: the device runs
    /// slow), once the line exists.
    pub fn drift_ppm(&self) -> Option<f64> {
        self.line.map(|l| l.1 * 1e6)
    }

    /// A capture time on the host's time line.
    fn host_time(&self, stamp: Stamp) -> i64 {
        stamp.device_ns as i64 + self.offset_ns(stamp.device_ns).unwrap_or(0)
    }
}

/// A frame waiting for its partner.
#[derive(Debug)]
struct Pending<F> {
    frame: F,
    stamp: Stamp,
}

/// Pairs depth and colour frames; see the module documentation.
#[derive(Debug)]
pub struct Synchronizer {
    config: SyncConfig,
    depth_clock: ClockModel,
    color_clock: ClockModel,
    depth: VecDeque<Pending<Arc<DepthFrame>>>,
    color: VecDeque<Pending<Arc<ColorFrame>>>,
    last_depth: Option<Stamp>,
    last_color: Option<Stamp>,
    /// Frames in a row refused for going backwards, per camera (depth, colour).
    backwards: [u32; 2],
    /// Smallest interval between depth frames per step of their frame counter (device time).
    depth_interval_ns: Option<u64>,
    /// The colour frames' last intervals per step of their frame counter (device time), and
    /// their median: about when the next colour frame is taken after the newest, which tells
    /// when the nearest partner of a depth frame is already in.
    color_intervals: VecDeque<u64>,
    color_interval_ns: Option<u64>,
    /// The newest capture time seen from each camera (host time line).
    newest_depth: Option<i64>,
    newest_color: Option<i64>,
    /// Arrival (host clock) of the first depth frame, the newest depth frame and the last
    /// colour frame: a colour camera silent for the longest wait is not waited for.
    first_depth_arrival: Option<u64>,
    newest_depth_arrival: u64,
    last_color_arrival: Option<u64>,
    /// Depth frames in the current run that went out depth-only because waiting for their
    /// partner was given up, and in all runs.
    given_up_run: u64,
    given_up: u64,
    /// The newest host time known: the latest arrival pushed or tick.
    now_ns: u64,
    /// Depth frames decided at the end of [`SyncConfig::partner_wait_ns`] before their
    /// nearest partner was known: paired with the nearest colour frame in, or depth-only.
    unproven_paired: u64,
    unproven_unpaired: u64,
    /// The colour frame the last depth frame with a partner paired with, and its capture time
    /// (host time line): with a partner reach, a depth frame left without one at the end of
    /// its wait pairs with it again when it is in reach.
    last_partner: Option<(Arc<ColorFrame>, i64)>,
}

impl Synchronizer {
    pub fn new(config: SyncConfig) -> Self {
        Self {
            config,
            depth_clock: ClockModel::default(),
            color_clock: ClockModel::default(),
            depth: VecDeque::new(),
            color: VecDeque::new(),
            last_depth: None,
            last_color: None,
            backwards: [0; 2],
            depth_interval_ns: None,
            color_intervals: VecDeque::new(),
            color_interval_ns: None,
            newest_depth: None,
            newest_color: None,
            first_depth_arrival: None,
            newest_depth_arrival: 0,
            last_color_arrival: None,
            given_up_run: 0,
            given_up: 0,
            now_ns: 0,
            unproven_paired: 0,
            unproven_unpaired: 0,
            last_partner: None,
        }
    }

    /// Depth frames decided at the end of the partner wait before their nearest partner was
    /// known, over the whole run: (paired with the nearest colour frame in, depth-only).
    pub fn unproven(&self) -> (u64, u64) {
        (self.unproven_paired, self.unproven_unpaired)
    }

    /// When (host clock, ns) the oldest pending depth frame's partner wait ends, if there is
    /// a partner wait and a depth frame waiting: [`Synchronizer::tick`] then decides it.
    pub fn due_ns(&self) -> Option<u64> {
        let wait = self.config.partner_wait_ns?;
        self.depth.front().map(|d| d.stamp.host_ns.saturating_add(wait))
    }

    /// Tells the time (host clock, ns) without a frame: depth frames whose partner wait ended
    /// are decided into `out`.
    pub fn tick(&mut self, now_ns: u64, out: &mut Vec<SyncOutput>) {
        self.now_ns = self.now_ns.max(now_ns);
        self.decide(out, false);
    }

    /// Depth frames that went out without waiting longer for a colour partner (the colour
    /// camera late or silent for longer than the wait), over the whole run.
    pub fn given_up(&self) -> u64 {
        self.given_up
    }

    /// Whether the colour camera delivered nothing for twice the wait, by the host clock of
    /// the frames (a camera that never delivered counts from the first depth frame). Twice:
    /// frames held up for about the wait and then delivered in a burst must find their depth
    /// partners still waiting.
    fn color_silent(&self) -> bool {
        let since = self.last_color_arrival.or(self.first_depth_arrival);
        since.is_some_and(|t| self.newest_depth_arrival.saturating_sub(t) > self.config.max_wait_ns.saturating_mul(2))
    }

    /// Ends a run of depth frames given up on, with one warning saying how many.
    fn end_given_up_run(&mut self) {
        if self.given_up_run > 0 {
            tracing::warn!(
                frames = self.given_up_run,
                wait_ms = self.config.max_wait_ns as f64 * 1e-6,
                "pairing gave up on {} depth frames in a row: their colour frames were later than the wait or missing, so they went out depth-only",
                self.given_up_run
            );
            self.given_up_run = 0;
        }
    }

    /// The pairing tolerance in use.
    pub fn tolerance_ns(&self) -> u64 {
        self.config
            .tolerance_ns
            .unwrap_or_else(|| self.depth_interval_ns.unwrap_or(1_000_000_000 / 30) / 2)
    }

    /// The two cameras' clock models (depth, colour).
    pub fn clocks(&self) -> (&ClockModel, &ClockModel) {
        (&self.depth_clock, &self.color_clock)
    }

    /// Takes a depth frame; whatever can be decided goes to `out`.
    pub fn push_depth(&mut self, frame: Arc<DepthFrame>, out: &mut Vec<SyncOutput>) {
        let stamp = frame.stamp;
        if !self.admit(Role::Depth, stamp, out) {
            return;
        }
        if let Some(last) = self.last_depth {
            let dt = per_step(last, stamp);
            self.depth_interval_ns = Some(self.depth_interval_ns.map_or(dt, |i| i.min(dt)));
        }
        self.last_depth = Some(stamp);
        self.now_ns = self.now_ns.max(stamp.host_ns);
        self.first_depth_arrival.get_or_insert(stamp.host_ns);
        self.newest_depth_arrival = self.newest_depth_arrival.max(stamp.host_ns);
        self.depth_clock.observe(stamp);
        let t = self.depth_clock.host_time(stamp);
        self.newest_depth = Some(self.newest_depth.map_or(t, |n| n.max(t)));
        self.depth.push_back(Pending { frame, stamp });
        self.decide(out, false);
    }

    /// Takes a colour frame; whatever can be decided goes to `out`.
    pub fn push_color(&mut self, frame: Arc<ColorFrame>, out: &mut Vec<SyncOutput>) {
        let stamp = frame.stamp;
        if !self.admit(Role::Color, stamp, out) {
            return;
        }
        // Depth frames whose partner wait ended before this frame arrived are decided without
        // it, as ticks would have decided them live: a replay of the recorded stamps pairs as
        // the live run did.
        if self.config.partner_wait_ns.is_some() {
            self.tick(stamp.host_ns, out);
        }
        if let Some(last) = self.last_color {
            self.color_intervals.push_back(per_step(last, stamp));
            if self.color_intervals.len() > COLOR_INTERVALS {
                self.color_intervals.pop_front();
            }
            let mut v: Vec<f64> = self.color_intervals.iter().map(|&i| i as f64).collect();
            self.color_interval_ns = crate::core::median(&mut v).map(|m| m as u64);
        }
        self.last_color = Some(stamp);
        self.now_ns = self.now_ns.max(stamp.host_ns);
        self.last_color_arrival = Some(self.last_color_arrival.map_or(stamp.host_ns, |t| t.max(stamp.host_ns)));
        self.color_clock.observe(stamp);
        let t = self.color_time(stamp);
        self.newest_color = Some(self.newest_color.map_or(t, |n| n.max(t)));
        self.color.push_back(Pending { frame, stamp });
        self.decide(out, false);
    }

    /// Whether a camera's frame goes on to pairing. A frame whose counter or device time goes
    /// backwards is refused (`out`); [`RESET_AFTER`] of them in a row mean the camera started
    /// counting again (reopened, or a 32-bit counter wrapped): its clock is learnt again and
    /// the frame taken. A device clock that jumps ahead of the host clock by more than
    /// [`CLOCK_STEP_NS`] is learnt again too. Both are logged.
    fn admit(&mut self, role: Role, stamp: Stamp, out: &mut Vec<SyncOutput>) -> bool {
        let (last, k) = match role {
            Role::Depth => (self.last_depth, 0),
            Role::Color => (self.last_color, 1),
        };
        if let Some(reason) = out_of_order(last, stamp) {
            self.backwards[k] += 1;
            if self.backwards[k] < RESET_AFTER {
                out.push(SyncOutput::Rejected { role, stamp, reason });
                return false;
            }
            tracing::warn!(camera = ?role, "the camera's frame counter or clock started again: its clock is learnt again");
            self.restart(role);
        } else if let Some(last) = last {
            let device = stamp.device_ns.saturating_sub(last.device_ns);
            let host = stamp.host_ns.saturating_sub(last.host_ns);
            if device.saturating_sub(host) > CLOCK_STEP_NS {
                tracing::warn!(
                    camera = ?role,
                    step_s = (device - host) as f64 * 1e-9,
                    "the camera's clock jumped ahead: its clock is learnt again"
                );
                self.restart(role);
            }
        }
        self.backwards[k] = 0;
        true
    }

    /// Forgets what was learnt of a camera's clock, after it was reopened: its device clock
    /// and frame counter may start again from anywhere. Frames of it still pending stay.
    pub fn restart(&mut self, role: Role) {
        match role {
            Role::Depth => {
                self.depth_clock = ClockModel::default();
                self.last_depth = None;
            }
            Role::Color => {
                self.color_clock = ClockModel::default();
                self.last_color = None;
                // A reopened camera may run at another rate.
                self.color_intervals.clear();
                self.color_interval_ns = None;
                self.last_partner = None;
            }
        }
    }

    /// Emits everything still pending (end of input): depth frames with the best partner they
    /// have, then the colour frames left over.
    pub fn flush(&mut self, out: &mut Vec<SyncOutput>) {
        self.decide(out, true);
        self.end_given_up_run();
        while let Some(c) = self.color.pop_front() {
            out.push(SyncOutput::UnpairedColor(c.frame));
        }
    }

    fn color_time(&self, stamp: Stamp) -> i64 {
        self.color_clock.host_time(stamp) - self.config.color_latency_ns
    }

    /// The widest capture-time difference of a pair decided at the end of the partner wait
    /// ([`SyncConfig::partner_reach_ns`], at least the tolerance `tol`).
    fn reach_ns(&self, tol: i64) -> i64 {
        match (self.config.partner_wait_ns, self.config.partner_reach_ns) {
            (Some(_), Some(reach)) => tol.max(reach as i64),
            _ => tol,
        }
    }

    /// Decides the oldest pending depth frames whose partner cannot change any more, and
    /// releases the colour frames no pending or future depth frame can claim.
    fn decide(&mut self, out: &mut Vec<SyncOutput>, end: bool) {
        let tol = self.tolerance_ns() as i64;
        // Colour frames this old may still pair at the end of a partner wait.
        let keep = self.reach_ns(tol);
        while let Some(d) = self.depth.front() {
            let td = self.depth_clock.host_time(d.stamp);
            // Colour frames come in capture order: once one taken at or after this depth frame
            // is in, every later one is farther from it than that one, so the nearest partner
            // is among those in (waiting until one is past the tolerance adds up to a frame
            // interval of latency for nothing). So it is too once the next colour frame, taken
            // about a colour frame interval after the newest, cannot be nearer than the newest
            // nor within the tolerance: waiting for it cost up to a whole interval.
            let decided = end || !self.config.color || self.nearest_color_in(td, tol);
            // Or its partner wait is over, or no colour frame can arrive before it is: the
            // nearest colour frame in is taken without knowing that it is the nearest.
            let unproven = !decided && self.partner_wait_over(d.stamp.host_ns);
            // Waiting given up: the frame waited the longest wait, or the colour camera has
            // been silent that long.
            let given_up = !decided
                && !unproven
                && (self
                    .newest_depth
                    .is_some_and(|n| n - td > self.config.max_wait_ns as i64)
                    || self.color_silent());
            if !decided && !unproven && !given_up {
                break;
            }
            let Some(d) = self.depth.pop_front() else {
                break;
            };
            // Colour frames too old for this depth frame are too old for every later one.
            let reach = if unproven { keep } else { tol };
            while let Some(c) = self.color.front() {
                if self.color_time(c.stamp) < td - keep {
                    if let Some(c) = self.color.pop_front() {
                        out.push(SyncOutput::UnpairedColor(c.frame));
                    }
                } else {
                    break;
                }
            }
            let best = self
                .color
                .iter()
                .enumerate()
                .map(|(i, c)| (i, self.color_time(c.stamp) - td))
                .filter(|(_, dt)| dt.abs() <= reach)
                .min_by_key(|(_, dt)| dt.abs());
            let (mut color, mut skew_ns) = match best {
                Some((i, dt)) => {
                    // Frames before the chosen one can no longer pair with anything.
                    for _ in 0..i {
                        if let Some(c) = self.color.pop_front() {
                            out.push(SyncOutput::UnpairedColor(c.frame));
                        }
                    }
                    (self.color.pop_front().map(|c| c.frame), dt)
                }
                None => (None, 0),
            };
            let mut color_again = false;
            match &color {
                Some(c) => self.last_partner = Some((Arc::clone(c), td + skew_ns)),
                // With a partner wait and reach, a depth frame left without a partner (at the
                // end of its wait, or none within the tolerance to come): the last partner,
                // again, if in reach (a colour frame that paired once is no longer pending).
                None if self.config.partner_wait_ns.is_some() && self.config.partner_reach_ns.is_some() => {
                    if let Some((c, tc)) = self.last_partner.as_ref().filter(|(_, tc)| (tc - td).abs() <= keep) {
                        color = Some(Arc::clone(c));
                        skew_ns = tc - td;
                        color_again = true;
                    }
                }
                None => {}
            }
            if unproven {
                if color.is_some() {
                    self.unproven_paired += 1;
                } else {
                    self.unproven_unpaired += 1;
                }
            }
            if given_up && color.is_none() {
                self.given_up_run += 1;
                self.given_up += 1;
            } else {
                self.end_given_up_run();
            }
            out.push(SyncOutput::Pair(FramePair {
                depth: d.frame,
                color,
                skew_ns,
                color_again,
            }));
        }
        // Without pending depth frames, colour frames older than the newest depth frame by
        // more than the tolerance (or the partner reach) can never pair.
        if self.depth.is_empty() {
            if let Some(nd) = self.newest_depth {
                while let Some(c) = self.color.front() {
                    if self.color_time(c.stamp) < nd - keep {
                        if let Some(c) = self.color.pop_front() {
                            out.push(SyncOutput::UnpairedColor(c.frame));
                        }
                    } else {
                        break;
                    }
                }
            }
        }
        // A colour camera far ahead of a stalled depth camera must not pile up frames.
        while self.color.len() > MAX_PENDING {
            if let Some(c) = self.color.pop_front() {
                out.push(SyncOutput::UnpairedColor(c.frame));
            }
        }
    }

    /// Whether no colour frame still to come can be a nearer partner of a depth frame taken
    /// at `td` (host time line) than those in: one taken at or after it is in, or the next
    /// one, at least [`NEXT_COLOR_SHARE`] of the usual colour interval after the newest, would
    /// be farther than the newest or out of the tolerance `tol`. A tie goes to the earlier
    /// frame, as the choice among pending frames does.
    fn nearest_color_in(&self, td: i64, tol: i64) -> bool {
        let Some(newest) = self.newest_color else {
            return false;
        };
        if newest >= td {
            return true;
        }
        let Some(interval) = self.color_interval_ns else {
            return false;
        };
        let next = newest + (interval as f64 * NEXT_COLOR_SHARE) as i64;
        next - td >= td - newest || next - td > tol
    }

    /// Whether a depth frame that arrived at `arrival_ns` (host clock) waited its partner wait,
    /// or the next colour frame cannot arrive before the wait is over: it arrives no earlier
    /// than the colour clock's lower envelope says, [`NEXT_COLOR_SHARE`] of the usual colour
    /// interval after the newest (once the envelope is a fitted line: the lowest of a camera's
    /// first frames may be well above it). Never without a partner wait.
    fn partner_wait_over(&self, arrival_ns: u64) -> bool {
        let Some(wait) = self.config.partner_wait_ns else {
            return false;
        };
        let end = arrival_ns.saturating_add(wait);
        if self.now_ns >= end {
            return true;
        }
        let (Some(newest), Some(interval), true) =
            (self.newest_color, self.color_interval_ns, self.color_clock.fitted())
        else {
            return false;
        };
        let next_arrival = newest + self.config.color_latency_ns + (interval as f64 * NEXT_COLOR_SHARE) as i64;
        next_arrival > end as i64
    }

    /// Frames waiting for a decision (depth, colour).
    pub fn pending(&self) -> (usize, usize) {
        (self.depth.len(), self.color.len())
    }
}

/// The share of the usual colour frame interval (the median of the last [`COLOR_INTERVALS`])
/// that the next colour frame is taken after the newest at the least: below 1 for the jitter
/// of the device's stamps and its drift against the host's clock. A camera stamping at the
/// sensor is microseconds off; one stamping in software (Aravis's fake camera) was 10 ms off
/// now and then, so the smallest interval seen would soon stop the early decision. Only a
/// next interval more than 10 % shorter than usual can then pair a depth frame (one within 5 %
/// of an interval of the midpoint between two colour frames) with the farther of the two.
const NEXT_COLOR_SHARE: f64 = 0.9;

/// Colour frame intervals the usual one is the median of.
const COLOR_INTERVALS: usize = 31;

/// The interval between two frames of a camera, `last` then `stamp`, per step of the frame
/// counter (device time), so that dropped frames do not widen it.
fn per_step(last: Stamp, stamp: Stamp) -> u64 {
    let steps = stamp.seq.saturating_sub(last.seq).max(1);
    stamp.device_ns.saturating_sub(last.device_ns) / steps
}

/// Most colour frames held while waiting for depth frames.
const MAX_PENDING: usize = 64;

/// Frames in a row going backwards that mean a camera started counting again.
const RESET_AFTER: u32 = 3;
/// How far a device clock may run ahead of the host clock between two frames before it counts
/// as a step (a late burst makes the host clock run ahead instead, which is no step).
const CLOCK_STEP_NS: u64 = 1_000_000_000;

fn out_of_order(last: Option<Stamp>, stamp: Stamp) -> Option<RejectReason> {
    let last = last?;
    if stamp.seq <= last.seq {
        Some(RejectReason::SequenceNotIncreasing)
    } else if stamp.device_ns <= last.device_ns {
        Some(RejectReason::TimeNotIncreasing)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A camera stream: `(true capture time s, stamp)` with its own clock and latency.
    #[allow(clippy::too_many_arguments)]
    fn stream(
        n: usize,
        period_s: f64,
        phase_s: f64,
        offset_ns: u64,
        drift_ppm: f64,
        latency_ms: f64,
        jitter: &[f64],
        drops: &[bool],
    ) -> Vec<(f64, Stamp)> {
        (0..n)
            .filter(|&k| !drops[k % drops.len()])
            .map(|k| {
                let t = phase_s + k as f64 * period_s;
                let device_ns = offset_ns + (t * 1e9 * (1.0 + drift_ppm * 1e-6)) as u64;
                let host_ns = 5_000_000_000 + ((t + latency_ms * 1e-3 * (1.0 + jitter[k % jitter.len()])) * 1e9) as u64;
                (
                    t,
                    Stamp {
                        seq: k as u64,
                        device_ns,
                        host_ns,
                    },
                )
            })
            .collect()
    }

    fn depth(stamp: Stamp) -> Arc<DepthFrame> {
        Arc::new(DepthFrame::empty(stamp, 1, 1))
    }

    fn color(stamp: Stamp) -> Arc<ColorFrame> {
        Arc::new(ColorFrame {
            stamp,
            width: 1,
            height: 1,
            format: crate::core::frame::PixelFormat::Mono8,
            data: vec![0],
        })
    }

    /// Feeds both streams in host arrival order and returns everything emitted.
    fn run(config: SyncConfig, d: &[(f64, Stamp)], c: &[(f64, Stamp)]) -> Vec<SyncOutput> {
        run_on(&mut Synchronizer::new(config), d, c)
    }

    /// Both streams' frames in the order they reach the host (depth first at equal times):
    /// (host time, depth?, stamp).
    fn arrivals(d: &[(f64, Stamp)], c: &[(f64, Stamp)]) -> Vec<(u64, bool, Stamp)> {
        let mut arrivals: Vec<(u64, bool, Stamp)> = d
            .iter()
            .map(|x| (x.1.host_ns, true, x.1))
            .chain(c.iter().map(|x| (x.1.host_ns, false, x.1)))
            .collect();
        arrivals.sort_by_key(|a| (a.0, !a.1));
        arrivals
    }

    /// Pushes both streams into `sync` in the order their frames reach the host, then flushes.
    fn run_on(sync: &mut Synchronizer, d: &[(f64, Stamp)], c: &[(f64, Stamp)]) -> Vec<SyncOutput> {
        let arrivals = arrivals(d, c);
        let mut out = Vec::new();
        for (_, is_depth, s) in arrivals {
            if is_depth {
                sync.push_depth(depth(s), &mut out);
            } else {
                sync.push_color(color(s), &mut out);
            }
        }
        sync.flush(&mut out);
        out
    }

    fn true_partner(c: &[(f64, Stamp)], t: f64, period: f64) -> Option<u64> {
        c.iter()
            .filter(|x| (x.0 - t).abs() < period / 2.0)
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .map(|x| x.1.seq)
    }

    proptest! {
        // PROPTEST_CASES runs more (a long search for rare cases); 1024 by default.
        #![proptest_config(ProptestConfig::with_cases(
            std::env::var("PROPTEST_CASES").ok().and_then(|n| n.parse().ok()).unwrap_or(1024)
        ))]

        #[test]
        fn pairs_follow_the_truth_and_account_for_every_frame(
            n in 10usize..400,
            phase in 0.15f64..0.35,
            offsets in (1_000_000_000u64..1_000_000_000_000, 1_000_000_000u64..1_000_000_000_000),
            drifts in (-40.0f64..40.0, -40.0f64..40.0),
            jitter in prop::collection::vec(0.0f64..0.5, 1..20),
            depth_drops in prop::collection::vec(prop::bool::weighted(0.03), 1..50),
            color_drops in prop::collection::vec(prop::bool::weighted(0.03), 1..50),
        ) {
            let period = 1.0 / 30.0;
            let d = stream(n, period, 0.0, offsets.0, drifts.0, 6.0, &jitter, &depth_drops);
            let c = stream(n, period, phase * period, offsets.1, drifts.1, 3.0, &jitter, &color_drops);
            let out = run(SyncConfig::default(), &d, &c);
            let mut depth_seen = Vec::new();
            let mut color_seen = Vec::new();
            for o in &out {
                match o {
                    SyncOutput::Pair(p) => {
                        depth_seen.push(p.depth.stamp.seq);
                        let truth = d.iter().find(|x| x.1.seq == p.depth.stamp.seq).map(|x| x.0);
                        let want = truth.and_then(|t| true_partner(&c, t, period));
                        prop_assert_eq!(p.color.as_ref().map(|f| f.stamp.seq), want);
                        if let Some(f) = &p.color {
                            color_seen.push(f.stamp.seq);
                        }
                    }
                    SyncOutput::UnpairedColor(f) => color_seen.push(f.stamp.seq),
                    SyncOutput::Rejected { .. } => prop_assert!(false, "nothing is out of order here"),
                }
            }
            // Output monotone in depth order, each depth frame once.
            prop_assert!(depth_seen.windows(2).all(|w| w[0] < w[1]));
            prop_assert_eq!(depth_seen.len(), d.len());
            // Every colour frame exactly once.
            color_seen.sort_unstable();
            let before = color_seen.len();
            color_seen.dedup();
            prop_assert_eq!(before, color_seen.len());
            prop_assert_eq!(color_seen.len(), c.len());
        }

        #[test]
        fn scrambled_input_is_rejected_or_paired_never_lost(
            seqs in prop::collection::vec((0u64..50, 0u64..2_000_000_000, any::<bool>()), 0..200),
        ) {
            let mut sync = Synchronizer::new(SyncConfig::default());
            let mut out = Vec::new();
            for &(seq, t, is_depth) in &seqs {
                let s = Stamp { seq, device_ns: t, host_ns: t };
                if is_depth { sync.push_depth(depth(s), &mut out) } else { sync.push_color(color(s), &mut out) }
            }
            sync.flush(&mut out);
            let count: usize = out
                .iter()
                .map(|o| match o {
                    SyncOutput::Pair(p) => 1 + usize::from(p.color.is_some()),
                    _ => 1,
                })
                .sum();
            prop_assert_eq!(count, seqs.len());
            prop_assert_eq!(sync.pending(), (0, 0));
        }
    }

    /// Issue 48: a case the property test above once failed on (depth frame 83 paired with
    /// colour frame 82, where its true partner is 83), kept.
    #[test]
    fn regression_a_depth_frame_near_the_end_pairs_with_its_true_partner() {
        let period = 1.0 / 30.0;
        let jitter = [
            0.46740479232607735,
            0.18436038780135208,
            0.2712741735085043,
            0.3718709961186295,
            0.11832275962176089,
            0.486469745144515,
            0.4006914570965276,
            0.12636602710925002,
            0.24463809696867694,
            0.3568617876862545,
            0.0912866105220433,
            0.39509950030310587,
            0.19231297501986797,
            0.0,
            0.24894670788143167,
            0.0,
            0.4432292628056722,
        ];
        let depth_drops = [false, false, true, false, false, true, false, true];
        let d = stream(87, period, 0.0, 1_000_000_000, 0.0, 6.0, &jitter, &depth_drops);
        let c = stream(
            87,
            period,
            0.3048763248237374 * period,
            1_000_000_000,
            0.0,
            3.0,
            &jitter,
            &[false],
        );
        for o in &run(SyncConfig::default(), &d, &c) {
            if let SyncOutput::Pair(p) = o {
                let t = d.iter().find(|x| x.1.seq == p.depth.stamp.seq).unwrap().0;
                assert_eq!(
                    p.color.as_ref().map(|f| f.stamp.seq),
                    true_partner(&c, t, period),
                    "depth frame {}",
                    p.depth.stamp.seq
                );
            }
        }
    }

    #[test]
    fn dropped_depth_frames_do_not_widen_the_tolerance() {
        // Every other depth frame lost: the frames still come 1/30 s apart per counter step,
        // so a colour frame 0.85 of an interval away is no partner.
        let period = 1.0 / 30.0;
        let d = stream(19, period, 0.0, 1_000_000_000, 0.0, 6.0, &[0.0], &[false, true]);
        let mut color_drops = vec![false; 19];
        color_drops[18] = true;
        let c = stream(19, period, 0.15 * period, 1_000_000_000, 0.0, 3.0, &[0.0], &color_drops);
        let out = run(SyncConfig::default(), &d, &c);
        let last = out.iter().rev().find_map(|o| match o {
            SyncOutput::Pair(p) if p.depth.stamp.seq == 18 => Some(p.color.as_ref().map(|f| f.stamp.seq)),
            _ => None,
        });
        assert_eq!(last, Some(None));
    }

    #[test]
    fn a_known_latency_difference_decides_pairs_near_half_an_interval() {
        // Colour frames half an interval plus 1 ms after the depth frames: each depth frame's
        // partner is the colour frame before it. The depth camera's transport is 3 ms slower,
        // which the clock models cannot see; uncorrected, that shifts the colour frames 3 ms
        // earlier and the frame after wins.
        let period = 1.0 / 30.0;
        let d = stream(60, period, 0.0, 1_000_000_000, 10.0, 6.0, &[0.0], &[false]);
        let c = stream(
            60,
            period,
            0.5 * period + 0.001,
            5_000_000_000,
            -10.0,
            3.0,
            &[0.0],
            &[false],
        );
        let want: Vec<_> = d.iter().map(|x| (x.1.seq, true_partner(&c, x.0, period))).collect();
        let pairs = |color_latency_ns| -> Vec<_> {
            let config = SyncConfig {
                color_latency_ns,
                ..SyncConfig::default()
            };
            run(config, &d, &c)
                .iter()
                .filter_map(|o| match o {
                    SyncOutput::Pair(p) => Some((p.depth.stamp.seq, p.color.as_ref().map(|f| f.stamp.seq))),
                    _ => None,
                })
                .collect()
        };
        assert_ne!(pairs(0), want);
        assert_eq!(pairs(-3_000_000), want);
    }

    #[test]
    fn depth_only_pairs_go_out_at_once() {
        let mut sync = Synchronizer::new(SyncConfig {
            color: false,
            ..SyncConfig::default()
        });
        let mut out = Vec::new();
        sync.push_depth(
            depth(Stamp {
                seq: 1,
                device_ns: 10,
                host_ns: 20,
            }),
            &mut out,
        );
        assert!(matches!(&out[..], [SyncOutput::Pair(p)] if p.color.is_none()));
    }

    /// Both cameras at 30 frames/s, each colour frame taken `lead_ms` before its depth frame
    /// and in first: for each depth frame, the colour frames out of the synchroniser when it
    /// arrives (`None`: not decided yet).
    fn decided_on_arrival(lead_ms: u64) -> Vec<Option<Option<u64>>> {
        decided_with_wait(lead_ms, None, 20)
            .0
            .into_iter()
            .map(|(d, _)| d)
            .collect()
    }

    #[test]
    fn a_depth_frame_whose_nearest_colour_frame_is_in_goes_out_at_once() {
        // 9 ms: the next colour frame (24 ms after) cannot be nearer; once the colour interval
        // is known (two colour frames) each depth frame goes out on arrival with its partner.
        let early = decided_on_arrival(9);
        assert_eq!(early[0], None);
        assert!(
            early[1..]
                .iter()
                .enumerate()
                .all(|(k, d)| *d == Some(Some(k as u64 + 1))),
            "{early:?}"
        );
        // 20 ms: the next colour frame, 13 ms after, is nearer: it is waited for.
        assert!(decided_on_arrival(20).iter().all(Option::is_none));
    }

    /// A depth frame's partner (`Some(None)`: depth-only) if decided on arrival, and if not,
    /// after a tick at the end of its wait.
    type Decided = (Option<Option<u64>>, Option<Option<u64>>);

    /// As [`decided_on_arrival`], `frames` frames, with a partner wait of `wait_ms` (`None`:
    /// the nearest): per depth frame, its partner if decided on arrival, and if not, after a
    /// tick at the end of its wait (`None`: still not decided); and the unproven decisions at
    /// the end.
    fn decided_with_wait(lead_ms: u64, wait_ms: Option<u64>, frames: u64) -> (Vec<Decided>, (u64, u64)) {
        decided_with_reach(lead_ms, wait_ms, None, frames)
    }

    /// As [`decided_with_wait`], with a partner reach of `reach_ms` (`None`: the tolerance).
    fn decided_with_reach(
        lead_ms: u64,
        wait_ms: Option<u64>,
        reach_ms: Option<u64>,
        frames: u64,
    ) -> (Vec<Decided>, (u64, u64)) {
        let mut sync = Synchronizer::new(SyncConfig {
            partner_wait_ns: wait_ms.map(|w| w * 1_000_000),
            partner_reach_ns: reach_ms.map(|r| r * 1_000_000),
            ..SyncConfig::default()
        });
        let ms = 1_000_000;
        let partner = |out: &[SyncOutput], k: u64| {
            out.iter().find_map(|o| match o {
                SyncOutput::Pair(p) if p.depth.stamp.seq == k => Some(p.color.as_ref().map(|c| c.stamp.seq)),
                _ => None,
            })
        };
        let decided = (0..frames)
            .map(|k| {
                let t = 1_000 * ms + k * 33 * ms;
                let mut out = Vec::new();
                let c = Stamp {
                    seq: k,
                    device_ns: t - lead_ms * ms,
                    host_ns: t - lead_ms * ms + 2 * ms,
                };
                sync.push_color(color(c), &mut out);
                let arrival = t + 2 * ms;
                let d = Stamp {
                    seq: k,
                    device_ns: t,
                    host_ns: arrival,
                };
                sync.push_depth(depth(d), &mut out);
                let on_arrival = partner(&out, k);
                let Some(wait_ms) = wait_ms.filter(|_| on_arrival.is_none()) else {
                    return (on_arrival, None);
                };
                assert_eq!(sync.due_ns(), Some(arrival + wait_ms * ms));
                // Just before the end of the wait nothing is decided; at its end it is.
                sync.tick(arrival + wait_ms * ms - 1, &mut out);
                assert!(partner(&out, k).is_none());
                sync.tick(arrival + wait_ms * ms, &mut out);
                (None, partner(&out, k))
            })
            .collect();
        (decided, sync.unproven())
    }

    /// Whether each depth frame from `from` on went out on arrival with its colour frame.
    fn each_on_arrival(decided: &[Decided], from: usize) -> bool {
        decided[from..]
            .iter()
            .zip(from as u64..)
            .all(|(d, k)| *d == (Some(Some(k)), None))
    }

    #[test]
    fn a_depth_frame_waits_for_a_nearer_partner_no_longer_than_the_partner_wait() {
        // 16 ms: near the midpoint, the next colour frame (17 ms after) cannot be ruled out as
        // nearer; waited for without a partner wait, here each depth frame goes out at the end
        // of the wait with the colour frame 16 ms before it, counted as unproven.
        let (mid, unproven) = decided_with_wait(16, Some(3), 20);
        assert!(
            mid.iter().enumerate().all(|(k, d)| *d == (None, Some(Some(k as u64)))),
            "{mid:?}"
        );
        assert_eq!(unproven, (20, 0));
        // 20 ms: the frame before is out of the tolerance and the next one still to come:
        // depth-only at the end of the wait, counted.
        let (late, unproven) = decided_with_wait(20, Some(3), 20);
        assert!(late.iter().all(|d| *d == (None, Some(None))), "{late:?}");
        assert_eq!(unproven, (0, 20));
        // 9 ms: the nearest partner is known on arrival, as without a partner wait, once the
        // colour interval is (the first frame waits its wait).
        let (early, unproven) = decided_with_wait(9, Some(3), 20);
        assert!(each_on_arrival(&early, 1), "{early:?}");
        assert_eq!(unproven, (1, 0));
        // A wait of 0: never waits for a later colour frame.
        let (now, _) = decided_with_wait(16, Some(0), 20);
        assert!(each_on_arrival(&now, 1), "{now:?}");
    }

    #[test]
    fn with_a_partner_reach_the_colour_frame_taken_before_pairs_at_the_end_of_the_wait() {
        // 20 ms: the frame before is out of the tolerance and the nearer one still to come.
        // Reaching a colour frame interval, the frame before pairs at the end of the wait
        // (unproven, counted) instead of none.
        let (late, unproven) = decided_with_reach(20, Some(3), Some(34), 20);
        assert!(
            late.iter().enumerate().all(|(k, d)| *d == (None, Some(Some(k as u64)))),
            "{late:?}"
        );
        assert_eq!(unproven, (20, 0));
        // Farther than the reach: depth-only still.
        let (far, unproven) = decided_with_reach(20, Some(3), Some(18), 20);
        assert!(far.iter().all(|d| *d == (None, Some(None))), "{far:?}");
        assert_eq!(unproven, (0, 20));
        // Without a partner wait the reach changes nothing: the nearest partner is waited for.
        let (exact, _) = decided_with_reach(20, None, Some(34), 20);
        assert_eq!(exact, decided_with_wait(20, None, 20).0);
    }

    #[test]
    fn with_a_partner_reach_a_depth_frame_left_without_one_pairs_again_with_the_last_partner() {
        let ms = 1_000_000;
        // Colour at half the depth rate, each frame taken 5 ms before an even depth frame: at
        // the end of an odd one's wait no colour frame is pending (the one before paired with
        // the even frame, the next is still to come). (depth seq, colour seq, again, skew ms).
        let run = |reach_ms: u64| {
            let mut sync = Synchronizer::new(SyncConfig {
                partner_wait_ns: Some(3 * ms),
                partner_reach_ns: Some(reach_ms * ms),
                ..SyncConfig::default()
            });
            let mut pairs = Vec::new();
            for k in 0..20u64 {
                let t = 1_000 * ms + k * 33 * ms;
                let mut out = Vec::new();
                if k % 2 == 0 {
                    let c = Stamp {
                        seq: k / 2,
                        device_ns: t - 5 * ms,
                        host_ns: t - 3 * ms,
                    };
                    sync.push_color(color(c), &mut out);
                }
                let d = Stamp {
                    seq: k,
                    device_ns: t,
                    host_ns: t + 2 * ms,
                };
                sync.push_depth(depth(d), &mut out);
                sync.tick(t + 5 * ms, &mut out);
                pairs.extend(out.into_iter().filter_map(|o| match o {
                    SyncOutput::Pair(p) => Some((
                        p.depth.stamp.seq,
                        p.color.map(|c| c.stamp.seq),
                        p.color_again,
                        (p.skew_ns as f64 / ms as f64).round() as i64,
                    )),
                    _ => None,
                }));
            }
            pairs
        };
        // Reaching 50 ms: each odd depth frame pairs with the colour frame 38 ms before it,
        // again, and says so.
        let again = run(50);
        assert_eq!(again.len(), 20);
        for &(k, c, is_again, skew) in &again {
            if k % 2 == 0 {
                assert_eq!((c, is_again, skew), (Some(k / 2), false, -5), "{again:?}");
            } else {
                assert_eq!((c, is_again, skew), (Some(k / 2), true, -38), "{again:?}");
            }
        }
        // Reaching 34 ms, that frame is out of reach: depth-only.
        let short = run(34);
        assert!(
            short
                .iter()
                .all(|&(k, c, is_again, _)| !is_again && c.is_some() == (k % 2 == 0)),
            "{short:?}"
        );
    }

    #[test]
    fn a_depth_frame_goes_out_at_once_when_no_colour_frame_can_arrive_within_the_wait() {
        // Once the colour camera's clock is learnt (a line over two whole seconds), the next
        // colour frame's earliest arrival, 15.7 ms after the depth frame's, is past the 3 ms
        // wait: the depth frame goes out on arrival, unproven, with the frame 16 ms before.
        let (mid, unproven) = decided_with_wait(16, Some(3), 150);
        assert!(each_on_arrival(&mid, 120), "{:?}", &mid[120..]);
        assert_eq!(unproven, (150, 0));
        // With a wait of 20 ms the next colour frame can arrive within it: it is waited for
        // (until the tick at the end of the wait here, the frame never delivered in time).
        let (long, _) = decided_with_wait(16, Some(20), 150);
        assert!(long[120..].iter().all(|d| d.0.is_none()), "{:?}", &long[120..]);
    }

    #[test]
    fn a_stalled_color_camera_does_not_hold_depth_frames() {
        let mut sync = Synchronizer::new(SyncConfig {
            max_wait_ns: 200_000_000,
            ..SyncConfig::default()
        });
        let mut out = Vec::new();
        for k in 0..30u64 {
            let t = k * 33_333_333;
            sync.push_depth(
                depth(Stamp {
                    seq: k,
                    device_ns: t,
                    host_ns: t,
                }),
                &mut out,
            );
        }
        // 200 ms of waiting at most: all but the last six frames are out.
        assert!(out.len() >= 23, "{} pairs out", out.len());
    }

    /// Depth frames paired with their true colour partner, of all depth frames.
    fn right_share(out: &[SyncOutput], d: &[(f64, Stamp)], c: &[(f64, Stamp)], period: f64) -> f64 {
        let right = out
            .iter()
            .filter(|o| match o {
                SyncOutput::Pair(p) => {
                    let t = d.iter().find(|x| x.1.seq == p.depth.stamp.seq).map(|x| x.0);
                    let want = t.and_then(|t| true_partner(c, t, period));
                    want.is_some() && p.color.as_ref().map(|f| f.stamp.seq) == want
                }
                _ => false,
            })
            .count();
        right as f64 / d.len() as f64
    }

    /// 30 s at 30 fps with the colour frames taken in [10 s, 10 s + `held_s`) reaching the host
    /// together at its end, 0.1 ms apart and before the next frame (a network stall, then a
    /// burst): the share of depth frames paired with their true partner, and the depth frames
    /// given up on.
    fn burst(held_s: f64) -> (f64, u64) {
        burst_with(held_s, SyncConfig::default())
    }

    fn burst_with(held_s: f64, config: SyncConfig) -> (f64, u64) {
        let period = 1.0 / 30.0;
        let d = stream(900, period, 0.0, 1_000_000_000, 0.0, 6.0, &[0.0], &[false]);
        let mut c = stream(900, period, 0.25 * period, 3_000_000_000, 0.0, 3.0, &[0.0], &[false]);
        let mut burst = 0;
        for (t, stamp) in &mut c {
            if (10.0..10.0 + held_s).contains(t) {
                stamp.host_ns = 5_000_000_000 + ((10.0 + held_s) * 1e9) as u64 + burst * 100_000;
                burst += 1;
            }
        }
        let mut sync = Synchronizer::new(config);
        let out = run_on(&mut sync, &d, &c);
        (right_share(&out, &d, &c, period), sync.given_up())
    }

    #[test]
    fn colour_frames_held_up_for_two_seconds_and_delivered_in_a_burst_still_pair() {
        let (share, given_up) = burst(2.0);
        assert!(
            share >= 0.97,
            "{:.1} % of depth frames with their true partner",
            share * 100.0
        );
        assert!(given_up <= 27, "{given_up} given up");
    }

    /// The pairing figures under bursts of 1-4 s:
    /// `cargo test --lib burst_pairing_figures -- --ignored --nocapture`.
    #[test]
    #[ignore = "a measurement: prints the pairing figures under bursts"]
    fn burst_pairing_figures() {
        let before = SyncConfig {
            max_wait_ns: 200_000_000,
            ..SyncConfig::default()
        };
        for held_s in [1.0, 2.0, 3.0, 4.0] {
            let (share, given_up) = burst(held_s);
            let (share_200, given_up_200) = burst_with(held_s, before);
            eprintln!(
                "colour held {held_s} s then a burst: {:.1} % of 900 depth frames with their true partner, {given_up} given up \
                 (with the earlier 200 ms wait: {:.1} %, {given_up_200})",
                share * 100.0,
                share_200 * 100.0
            );
        }
    }

    #[test]
    fn a_colour_camera_silent_for_longer_than_the_wait_is_not_waited_for() {
        let mut sync = Synchronizer::new(SyncConfig::default());
        let mut out = Vec::new();
        let stamp = |seq: u64| Stamp {
            seq,
            device_ns: seq * 33_333_333,
            host_ns: 1_000_000_000 + seq * 33_333_333,
        };
        for k in 0..30 {
            sync.push_depth(depth(stamp(k)), &mut out);
            sync.push_color(color(stamp(k)), &mut out);
        }
        // The colour camera dies; for its first two seconds of silence depth frames wait
        // (its frames may yet come in a burst), then none waits any more.
        for k in 30..300 {
            sync.push_depth(depth(stamp(k)), &mut out);
        }
        assert!(sync.pending().0 <= 1, "{:?} pending", sync.pending());
        assert!(sync.given_up() > 200, "{} given up", sync.given_up());
    }

    #[test]
    fn clock_model_follows_offset_and_drift() {
        let mut m = ClockModel::default();
        for k in 0..3000u64 {
            let device_ns = 7_000_000_000 + k * 10_000_000;
            // host runs 50 ppm faster; latency 2 ms plus up to 1 ms of jitter.
            let host_ns = (device_ns as f64 * (1.0 + 50e-6)) as u64 + 2_000_000 + (k * 7919 % 1_000_000);
            m.observe(Stamp {
                seq: k,
                device_ns,
                host_ns,
            });
        }
        let drift = m.drift_ppm().unwrap();
        assert!((drift - 50.0).abs() < 2.0, "drift {drift} ppm");
        let t = 7_000_000_000 + 2999 * 10_000_000u64;
        let want = (t as f64 * 50e-6) as i64 + 2_000_000;
        let got = m.offset_ns(t).unwrap();
        assert!((got - want).abs() < 200_000, "offset {got} vs {want}");
    }

    #[test]
    fn a_reopened_camera_whose_clock_starts_again_pairs_after_a_restart() {
        let config = SyncConfig::default();
        let mut sync = Synchronizer::new(config);
        let mut out = Vec::new();
        let stamp = |seq: u64, device_ms: u64, host_ms: u64| Stamp {
            seq,
            device_ns: device_ms * 1_000_000,
            host_ns: host_ms * 1_000_000,
        };
        for k in 0..30u64 {
            sync.push_depth(depth(stamp(k, 10_000 + 33 * k, 1_000 + 33 * k)), &mut out);
            sync.push_color(color(stamp(k, 50_000 + 33 * k, 1_001 + 33 * k)), &mut out);
        }
        // The colour camera comes back counting from 0 with its clock at 0.
        sync.restart(Role::Color);
        out.clear();
        for k in 30..60u64 {
            sync.push_depth(depth(stamp(k, 10_000 + 33 * k, 1_000 + 33 * k)), &mut out);
            sync.push_color(color(stamp(k - 30, 33 * (k - 30), 1_001 + 33 * k)), &mut out);
        }
        assert!(!out.iter().any(|o| matches!(o, SyncOutput::Rejected { .. })));
        let paired = out
            .iter()
            .filter(|o| matches!(o, SyncOutput::Pair(p) if p.color.is_some()))
            .count();
        assert!(paired >= 25, "{paired} pairs after the restart");
    }

    /// Both cameras at 30 fps, colour 1 ms after depth; `color_stamp(k)` gives colour frame
    /// k's counter and device time (ms). Returns the outputs of frames 30-89.
    fn with_colour(color_stamp: impl Fn(u64) -> (u64, u64)) -> Vec<SyncOutput> {
        let mut sync = Synchronizer::new(SyncConfig::default());
        let mut out = Vec::new();
        let stamp = |seq: u64, device_ms: u64, host_ms: u64| Stamp {
            seq,
            device_ns: device_ms * 1_000_000,
            host_ns: host_ms * 1_000_000,
        };
        for k in 0..90u64 {
            if k == 30 {
                out.clear();
            }
            sync.push_depth(depth(stamp(k, 10_000 + 33 * k, 1_000 + 33 * k)), &mut out);
            let (seq, device_ms) = color_stamp(k);
            sync.push_color(color(stamp(seq, device_ms, 1_001 + 33 * k)), &mut out);
        }
        out
    }

    fn colour_pairs(out: &[SyncOutput]) -> usize {
        out.iter()
            .filter(|o| matches!(o, SyncOutput::Pair(p) if p.color.is_some()))
            .count()
    }

    #[test]
    fn a_frame_counter_that_starts_again_is_followed_after_a_few_frames() {
        // From frame 40 on, the colour camera counts (and keeps time) from 0 again.
        let out = with_colour(|k| {
            if k < 40 {
                (k, 50_000 + 33 * k)
            } else {
                (k - 40, 33 * (k - 40))
            }
        });
        let rejected = out.iter().filter(|o| matches!(o, SyncOutput::Rejected { .. })).count();
        assert_eq!(rejected, usize::try_from(RESET_AFTER).unwrap() - 1);
        assert!(colour_pairs(&out) >= 50, "{} pairs of 60", colour_pairs(&out));
    }

    #[test]
    fn a_device_clock_that_jumps_ahead_is_learnt_again() {
        // From frame 40 on, the colour camera's clock is 10 s ahead.
        let out = with_colour(|k| (k, 50_000 + 33 * k + if k < 40 { 0 } else { 10_000 }));
        assert!(!out.iter().any(|o| matches!(o, SyncOutput::Rejected { .. })));
        assert!(colour_pairs(&out) >= 50, "{} pairs of 60", colour_pairs(&out));
    }

    /// A stall from `from` to `to` s (true time): every frame captured since `from` that would
    /// have reached the host before `to` + 10 ms reaches it then, in one burst, in order.
    fn stall(c: &mut [(f64, Stamp)], from: f64, to: f64) {
        let burst_ns = 5_000_000_000 + ((to + 0.01) * 1e9) as u64;
        // Just before the burst time, a nanosecond apart: before every frame not held up.
        for (i, x) in c
            .iter_mut()
            .filter(|x| x.0 >= from && x.1.host_ns < burst_ns)
            .enumerate()
        {
            x.1.host_ns = burst_ns - 1_000 + i as u64;
        }
    }

    #[test]
    fn colour_frames_arriving_late_in_one_burst_are_never_mispaired() {
        let period = 1.0 / 30.0;
        let n = 1200;
        let d = stream(n, period, 0.0, 3_000_000_000, 12.0, 6.0, &[0.0, 0.3, 0.1], &[false]);
        let mut c = stream(n, period, 0.3 * period, 9_000_000_000, -7.0, 3.0, &[0.2, 0.0], &[false]);
        // Colour frames captured from 20 s to 22 s reach the host together at 22.01 s (a USB
        // or network stall); the same again from 30 s to 31.5 s.
        stall(&mut c, 20.0, 22.0);
        stall(&mut c, 30.0, 31.5);
        let out = run(SyncConfig::default(), &d, &c);
        let (mut right, mut wrong) = (0, Vec::new());
        for o in &out {
            if let SyncOutput::Pair(p) = o {
                if let Some(f) = &p.color {
                    let t = d.iter().find(|x| x.1.seq == p.depth.stamp.seq).map(|x| x.0);
                    if t.and_then(|t| true_partner(&c, t, period)) == Some(f.stamp.seq) {
                        right += 1;
                    } else {
                        wrong.push((p.depth.stamp.seq, f.stamp.seq));
                    }
                }
            }
        }
        assert!(
            wrong.is_empty(),
            "{} wrong pairs: {:?}",
            wrong.len(),
            &wrong[..wrong.len().min(10)]
        );
        // Everything outside the stalls still pairs.
        assert!(right > n - 150, "{right} right pairs of {n}");
    }

    /// One case of the fault mix: drops, a stall with a burst of late colour frames, a colour
    /// clock that jumps ahead, a colour counter that starts again.
    #[derive(Clone, Debug)]
    struct FaultMix {
        n: usize,
        phase: f64,
        jitter: Vec<f64>,
        depth_drops: Vec<bool>,
        color_drops: Vec<bool>,
        /// Start (share of the span) and length (s) of the stall.
        burst: Option<(f64, f64)>,
        /// When (share of the span) and by how much (s) the colour clock jumps ahead.
        step: Option<(f64, f64)>,
        /// When (share of the span) the colour counter and clock start again.
        reset: Option<f64>,
    }

    const PERIOD_S: f64 = 1.0 / 30.0;

    /// A camera's frames: `(true capture time s, stamp)`.
    type Stream = Vec<(f64, Stamp)>;

    fn fault_mix() -> impl Strategy<Value = FaultMix> {
        (
            200usize..600,
            0.15f64..0.35,
            prop::collection::vec(0.0f64..0.5, 1..20),
            prop::collection::vec(prop::bool::weighted(0.05), 1..50),
            prop::collection::vec(prop::bool::weighted(0.05), 1..50),
            prop::option::of((0.1f64..0.9, 0.2f64..2.5)),
            prop::option::of((0.1f64..0.9, 1.5f64..100.0)),
            prop::option::of(0.1f64..0.9),
        )
            .prop_map(
                |(n, phase, jitter, depth_drops, color_drops, burst, step, reset)| FaultMix {
                    n,
                    phase,
                    jitter,
                    depth_drops,
                    color_drops,
                    burst,
                    step,
                    reset,
                },
            )
    }

    impl FaultMix {
        /// The depth and colour streams of the case.
        fn streams(&self) -> (Stream, Stream) {
            let span = self.n as f64 * PERIOD_S;
            // A counter or clock that starts again in the middle of a stall is not covered: the
            // clock is then learnt again from late frames only, and nothing in the stamps says
            // they are late.
            let apart = |t: f64| {
                self.burst
                    .is_none_or(|(at, len)| t * span < at * span - 0.5 || t * span > at * span + len + 3.0)
            };
            let reset = self.reset.filter(|&t| apart(t));
            let step = self.step.filter(|&(t, _)| apart(t));
            let d = stream(
                self.n,
                PERIOD_S,
                0.0,
                4_000_000_000,
                20.0,
                6.0,
                &self.jitter,
                &self.depth_drops,
            );
            let mut c = stream(
                self.n,
                PERIOD_S,
                self.phase * PERIOD_S,
                8_000_000_000,
                -15.0,
                3.0,
                &self.jitter,
                &self.color_drops,
            );
            if let Some((at, len)) = self.burst {
                stall(&mut c, at * span, at * span + len);
            }
            if let Some((at, by)) = step {
                for x in c.iter_mut().filter(|x| x.0 >= at * span) {
                    x.1.device_ns += (by * 1e9) as u64;
                }
            }
            if let Some(at) = reset {
                let first = c.iter().position(|x| x.0 >= at * span);
                if let Some((k0, t0)) = first.map(|k| (c[k].1.seq, c[k].1.device_ns)) {
                    for x in c.iter_mut().filter(|x| x.0 >= at * span) {
                        x.1.seq -= k0;
                        x.1.device_ns = x.1.device_ns - t0 + 1_000;
                    }
                }
            }
            (d, c)
        }
    }

    /// What the synchroniser made of a case, against the truth.
    #[derive(Clone, Debug, Default)]
    struct Tally {
        depth_seen: usize,
        color_seen: usize,
        /// Pairs with a colour frame, right and wrong (`(depth seq, colour seq)`).
        right: usize,
        wrong: Vec<(u64, u64)>,
        /// Depth frames that went out without a colour frame although one was taken within
        /// half a frame interval of them, and those that truly had none.
        unpaired_with_partner: usize,
        unpaired_without_partner: usize,
        rejected_color: usize,
        rejected_depth: usize,
    }

    impl Tally {
        fn of(out: &[SyncOutput], d: &[(f64, Stamp)], c: &[(f64, Stamp)]) -> Self {
            let mut t = Tally::default();
            for o in out {
                match o {
                    SyncOutput::Pair(p) => {
                        t.depth_seen += 1;
                        let time = d.iter().find(|x| x.1.seq == p.depth.stamp.seq).map(|x| x.0);
                        let want = time.and_then(|time| true_partner(c, time, PERIOD_S));
                        match &p.color {
                            Some(f) => {
                                t.color_seen += 1;
                                let truth = c
                                    .iter()
                                    .find(|x| x.1.seq == f.stamp.seq && x.1.device_ns == f.stamp.device_ns);
                                if truth.is_some() && truth.map(|x| x.1.seq) == want {
                                    t.right += 1;
                                } else {
                                    t.wrong.push((p.depth.stamp.seq, f.stamp.seq));
                                }
                            }
                            None if want.is_some() => t.unpaired_with_partner += 1,
                            None => t.unpaired_without_partner += 1,
                        }
                    }
                    SyncOutput::UnpairedColor(_) => t.color_seen += 1,
                    SyncOutput::Rejected { role: Role::Color, .. } => t.rejected_color += 1,
                    SyncOutput::Rejected { role: Role::Depth, .. } => t.rejected_depth += 1,
                }
            }
            t
        }

        fn add(&mut self, o: &Tally) {
            self.depth_seen += o.depth_seen;
            self.color_seen += o.color_seen;
            self.right += o.right;
            self.wrong.extend_from_slice(&o.wrong);
            self.unpaired_with_partner += o.unpaired_with_partner;
            self.unpaired_without_partner += o.unpaired_without_partner;
            self.rejected_color += o.rejected_color;
            self.rejected_depth += o.rejected_depth;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Under the fault mix, every frame is accounted for once, and every pair made is the
        /// true one.
        #[test]
        fn under_bursts_steps_resets_and_drops_no_pair_is_wrong(case in fault_mix()) {
            let (d, c) = case.streams();
            let t = Tally::of(&run(SyncConfig::default(), &d, &c), &d, &c);
            prop_assert!(t.wrong.is_empty(), "{} wrong pairs (depth, colour): {:?}", t.wrong.len(), &t.wrong[..t.wrong.len().min(10)]);
            prop_assert_eq!(t.rejected_depth, 0);
            prop_assert_eq!(t.depth_seen, d.len());
            prop_assert_eq!(t.color_seen + t.rejected_color, c.len());
            prop_assert!(t.rejected_color < RESET_AFTER as usize);
        }
    }

    /// Pushes both streams into a synchroniser in the order their frames reach the host, with a
    /// timer that ticks at every end of a partner wait before the next arrival, then flushes:
    /// each output with the host time it was decided at (`u64::MAX`: at the flush), and the
    /// unproven decisions.
    fn run_timed(config: SyncConfig, d: &[(f64, Stamp)], c: &[(f64, Stamp)]) -> (Vec<(u64, SyncOutput)>, (u64, u64)) {
        let mut sync = Synchronizer::new(config);
        let arrivals = arrivals(d, c);
        let (mut timed, mut out) = (Vec::new(), Vec::new());
        for (t, is_depth, s) in arrivals {
            while let Some(due) = sync.due_ns().filter(|&due| due <= t) {
                sync.tick(due, &mut out);
                if out.is_empty() {
                    break;
                }
                timed.extend(out.drain(..).map(|o| (due, o)));
            }
            if is_depth {
                sync.push_depth(depth(s), &mut out);
            } else {
                sync.push_color(color(s), &mut out);
            }
            timed.extend(out.drain(..).map(|o| (t, o)));
        }
        sync.flush(&mut out);
        timed.extend(out.drain(..).map(|o| (u64::MAX, o)));
        (timed, sync.unproven())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Under the fault mix with a partner wait: every frame is accounted for once, every
        /// depth frame is decided by the end of its wait (or at the end of the input), and
        /// every pair made is with the true nearest colour frame of those that reached the host
        /// by the end of the wait, within half an interval.
        #[test]
        fn with_a_partner_wait_each_pair_is_the_nearest_arrived_within_the_wait(case in fault_mix(), wait_ms in 0u64..12) {
            let (d, c) = case.streams();
            let wait = wait_ms * 1_000_000;
            let config = SyncConfig { partner_wait_ns: Some(wait), ..SyncConfig::default() };
            let (timed, (unproven_paired, unproven_unpaired)) = run_timed(config, &d, &c);
            let (times, out): (Vec<u64>, Vec<SyncOutput>) = timed.into_iter().unzip();
            let t = Tally::of(&out, &d, &c);
            prop_assert_eq!(t.rejected_depth, 0);
            prop_assert_eq!(t.depth_seen, d.len());
            prop_assert_eq!(t.color_seen + t.rejected_color, c.len());
            prop_assert!(unproven_paired + unproven_unpaired <= d.len() as u64);
            let mut wrong = Vec::new();
            for (at, o) in times.iter().zip(&out) {
                let SyncOutput::Pair(p) = o else { continue };
                let end = p.depth.stamp.host_ns + wait;
                prop_assert!(*at <= end || *at == u64::MAX, "depth frame {} decided {} ns after its wait", p.depth.stamp.seq, at - end);
                let Some(f) = &p.color else { continue };
                let time = d.iter().find(|x| x.1.seq == p.depth.stamp.seq).map(|x| x.0);
                let arrived: Vec<(f64, Stamp)> = c.iter().filter(|x| x.1.host_ns <= end).copied().collect();
                let want = time.and_then(|time| true_partner(&arrived, time, PERIOD_S));
                let truth = c.iter().find(|x| x.1.seq == f.stamp.seq && x.1.device_ns == f.stamp.device_ns);
                if truth.is_none() || truth.map(|x| x.1.seq) != want {
                    wrong.push((p.depth.stamp.seq, f.stamp.seq));
                }
            }
            prop_assert!(wrong.is_empty(), "{} pairs not with the nearest arrived (depth, colour): {:?}", wrong.len(), &wrong[..wrong.len().min(10)]);
        }
    }

    /// The pairing figures under the fault mix, over 1,000 cases of the property test's
    /// generator from a fixed seed: `cargo test --lib under_bursts -- --ignored --nocapture`.
    #[test]
    #[ignore = "a measurement: prints the pairing figures under the fault mix"]
    fn under_bursts_pairing_figures() {
        use proptest::strategy::ValueTree;
        use proptest::test_runner::{RngAlgorithm, TestRng, TestRunner};
        let mut runner = TestRunner::new_with_rng(
            ProptestConfig::default(),
            TestRng::deterministic_rng(RngAlgorithm::ChaCha),
        );
        let strategy = fault_mix();
        let cases = 1000;
        let mut total = Tally::default();
        for _ in 0..cases {
            let case = strategy.new_tree(&mut runner).expect("a case").current();
            let (d, c) = case.streams();
            total.add(&Tally::of(&run(SyncConfig::default(), &d, &c), &d, &c));
        }
        let with_partner = total.right + total.wrong.len() + total.unpaired_with_partner;
        let share = |n: usize, of: usize| 100.0 * n as f64 / of.max(1) as f64;
        eprintln!(
            "fault mix, {cases} cases: {} depth frames; {} paired with colour ({} right, {} wrong); {} unpaired ({:.2} %), \
             of which {} had a true partner: {:.2} % of the {with_partner} depth frames with one left unpaired; \
             {} colour frames rejected (counter restarts)",
            total.depth_seen,
            total.right + total.wrong.len(),
            total.right,
            total.wrong.len(),
            total.unpaired_with_partner + total.unpaired_without_partner,
            share(
                total.unpaired_with_partner + total.unpaired_without_partner,
                total.depth_seen
            ),
            total.unpaired_with_partner,
            share(total.unpaired_with_partner, with_partner),
            total.rejected_color,
        );
        assert!(total.wrong.is_empty(), "{} wrong pairs", total.wrong.len());
    }
}
