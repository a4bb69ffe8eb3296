//! A camera kept open for a daemon: [`Supervised`] wraps a camera's opener and, when the camera
//! errors, disappears or goes silent, closes it and opens it again with exponential backoff,
//! while its capture thread (and the other camera's) keeps running.
//!
//! What the outside sees of a supervised camera is its [`CameraHealth`]: its state, its outages
//! with their start, end and frame counts, and the session events to log. Frames keep sequence
//! numbers that only grow across reconnections (a camera that comes back counts from 0 again),
//! and the camera's `epoch` goes up at each reconnection so that the synchroniser starts its
//! clock model for that camera again.

use crate::core::frame::{ColorFrame, DepthFrame, Stamp};
use crate::io::session::{CameraMeta, CameraRole, SessionEvent};
use crate::runtime::capture::{CaptureError, Clock, FrameSource, Stamped, error_chain};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// When a camera counts as gone, and how often to try it again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reconnect {
    /// No frame for this long: the camera is closed and opened again.
    pub stall: Duration,
    /// The first wait before opening again; doubled after each failure...
    pub first_wait: Duration,
    /// ...up to this.
    pub max_wait: Duration,
}

impl Default for Reconnect {
    fn default() -> Self {
        Self {
            stall: Duration::from_secs(2),
            first_wait: Duration::from_millis(250),
            max_wait: Duration::from_secs(10),
        }
    }
}

/// Reopen counters of the two cameras (depth, colour): each goes up when its camera is
/// reopened, so that the synchroniser learns its clock again.
pub type Epochs = [Arc<AtomicU64>; 2];

/// A camera's state, as the status shows it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "state", content = "reason")]
pub enum CameraState {
    /// Not opened yet.
    Opening,
    /// Delivering frames.
    Streaming,
    /// Closed after a fault, being tried again; the reason is the last fault.
    Away(String),
}

/// One time a camera was away.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Outage {
    /// Host clock (ns) when the camera was taken for gone, and when its first frame came back
    /// (`None` while it is still away).
    pub start_ns: u64,
    pub end_ns: Option<u64>,
    /// What went wrong first.
    pub reason: String,
    /// Frames the camera had delivered before it went away, and attempts to open it again
    /// (the successful one included).
    pub frames_before: u64,
    pub attempts: u64,
}

/// What a supervised camera tells the rest of the daemon.
#[derive(Debug, Default, Serialize)]
pub struct CameraHealth {
    pub state: Option<CameraState>,
    /// Frames delivered since the daemon started.
    pub frames: u64,
    /// When the capture thread last came by (it does at least every read timeout): a thread
    /// stuck in a driver call stops updating it.
    #[serde(skip)]
    pub alive: Option<Instant>,
    /// The last sign of life from the camera itself: its last frame, or its opening when no
    /// frame came since; when it was, and the host clock (ns) then. [`StallWatch`] reads it.
    #[serde(skip)]
    pub last_sign: Option<(Instant, u64)>,
    pub outages: Vec<Outage>,
    /// The camera's metadata from its latest opening.
    #[serde(skip)]
    pub meta: Option<CameraMeta>,
    /// Events for the recorder to log in the session, oldest first.
    #[serde(skip)]
    pub events: Vec<SessionEvent>,
}

impl CameraHealth {
    /// Starts an outage at `start_ns` after the frames delivered so far, with the tries to open
    /// the camera made in it already.
    fn begin_outage(&mut self, start_ns: u64, reason: String, attempts: u64) {
        let frames_before = self.frames;
        self.outages.push(Outage {
            start_ns,
            end_ns: None,
            reason,
            frames_before,
            attempts,
        });
    }
}

/// A [`CameraHealth`] shared between a capture thread and its readers.
pub type SharedHealth = Arc<Mutex<CameraHealth>>;

/// Locks a health record (a reader that panicked cannot leave it half-written: every update is
/// a few field stores).
pub fn lock(health: &SharedHealth) -> std::sync::MutexGuard<'_, CameraHealth> {
    health.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A camera (re)opened at `host_ns`: its event and metadata, and its opening as its last sign
/// of life. Its state stays as it was (opening, or away) until its first frame
/// ([`Supervised::accept`]): a camera that opens is not yet one that delivers.
fn mark_open(h: &mut CameraHealth, role: CameraRole, meta: CameraMeta, host_ns: u64) {
    h.events.push(SessionEvent::CameraOpened {
        host_ns,
        role,
        model: meta.model.clone(),
        serial: meta.serial.clone(),
    });
    h.meta = Some(meta);
    h.last_sign = Some((Instant::now(), host_ns));
}

/// Takes a camera for gone: state away, an outage from `since_ns` (its last sign of life), and
/// the event for the session. A camera already away with its outage still open stays in that
/// outage: a watchdog and the capture thread may both notice the same silence.
fn mark_away(h: &mut CameraHealth, role: CameraRole, reason: String, since_ns: u64) {
    let open = h.outages.last().is_some_and(|o| o.end_ns.is_none());
    if !open {
        tracing::warn!(camera = %role, frames = h.frames, "camera lost: {reason}");
        h.events.push(SessionEvent::CameraDisconnected {
            host_ns: since_ns,
            role,
            reason: reason.clone(),
        });
        h.begin_outage(since_ns, reason.clone(), 0);
    }
    if !matches!(h.state, Some(CameraState::Away(_))) {
        h.state = Some(CameraState::Away(reason));
    }
}

/// Marks a streaming camera away once its last sign of life is `stall` old, from outside its
/// capture thread: that thread may be stuck in a driver call (a GigE read or close waits on
/// timeouts of seconds), and the state the status shows must not wait for it. The daemon
/// calls [`StallWatch::check`] a few times a second; the capture thread closes and reopens the
/// camera on its own time.
#[derive(Clone, Debug)]
pub struct StallWatch {
    role: CameraRole,
    stall: Duration,
    health: SharedHealth,
}

impl StallWatch {
    /// Checks the camera now; true when this check took it for gone. A camera opened that
    /// has not delivered its first frame yet is checked too (from its opening).
    pub fn check(&self) -> bool {
        let mut h = lock(&self.health);
        if !matches!(h.state, Some(CameraState::Streaming | CameraState::Opening)) {
            return false;
        }
        let Some((at, host_ns)) = h.last_sign else {
            return false;
        };
        let silent = at.elapsed();
        if silent < self.stall {
            return false;
        }
        let reason = format!("no frame for {:.1} s", silent.as_secs_f64());
        mark_away(&mut h, self.role, reason, host_ns);
        true
    }
}

/// Hands the events the cameras gathered since the last call (outages, reopenings) to `log`,
/// oldest first per camera, and forgets them.
///
/// # Errors
/// The first error of `log`; the events not yet logged are lost with it.
pub fn log_camera_events<E>(
    cameras: &[SharedHealth],
    mut log: impl FnMut(&SessionEvent) -> Result<(), E>,
) -> Result<(), E> {
    for h in cameras {
        let events = std::mem::take(&mut lock(h).events);
        for e in &events {
            log(e)?;
        }
    }
    Ok(())
}

/// Opens one camera (not started).
pub type Opener<S> = Box<dyn FnMut() -> Result<S, CaptureError> + Send>;

/// A camera that is reopened whenever it fails; see the module documentation.
pub struct Supervised<S: FrameSource> {
    role: CameraRole,
    open: Opener<S>,
    policy: Reconnect,
    current: Option<S>,
    clock: Option<Clock>,
    wait: Duration,
    next_try: Instant,
    last_frame: Instant,
    /// Added to the camera's own sequence numbers so that they keep growing.
    seq_offset: u64,
    next_seq: u64,
    /// The frame size of the first frame: frames of another size are skipped and counted.
    size: Option<(u32, u32)>,
    /// Losses of the camera's earlier openings, and the wrong-sized frames.
    losses: BTreeMap<&'static str, u64>,
    health: SharedHealth,
    epoch: Arc<AtomicU64>,
    ended: bool,
}

impl<S: FrameSource> std::fmt::Debug for Supervised<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Supervised")
            .field("role", &self.role)
            .field("open", &self.current.is_some())
            .field("wait", &self.wait)
            .finish_non_exhaustive()
    }
}

/// A camera's frame as a supervisor handles it: its size, and its stamp to renumber.
pub trait CameraFrame: Stamped {
    fn size(&self) -> (u32, u32);
    fn stamp_mut(&mut self) -> &mut Stamp;
}

impl CameraFrame for DepthFrame {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    fn stamp_mut(&mut self) -> &mut Stamp {
        &mut self.stamp
    }
}

impl CameraFrame for ColorFrame {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    fn stamp_mut(&mut self) -> &mut Stamp {
        &mut self.stamp
    }
}

impl<S> Supervised<S>
where
    S: FrameSource,
    S::Frame: CameraFrame,
{
    /// A camera opened by `open`; `epoch` goes up at each reconnection.
    pub fn new(role: CameraRole, open: Opener<S>, policy: Reconnect, epoch: Arc<AtomicU64>) -> Self {
        let now = Instant::now();
        Self {
            role,
            open,
            policy,
            current: None,
            clock: None,
            wait: policy.first_wait,
            next_try: now,
            last_frame: now,
            seq_offset: 0,
            next_seq: 0,
            size: None,
            losses: BTreeMap::new(),
            health: Arc::new(Mutex::new(CameraHealth {
                state: Some(CameraState::Opening),
                ..CameraHealth::default()
            })),
            epoch,
            ended: false,
        }
    }

    /// The camera's health, shared.
    pub fn health(&self) -> SharedHealth {
        Arc::clone(&self.health)
    }

    /// The supervisor of a camera already opened and started by the caller (who needed its
    /// metadata first); `open` serves only the reopenings.
    pub fn opened(mut self, source: S, clock: &Clock) -> Self {
        mark_open(&mut lock(&self.health), self.role, source.meta(), clock.now_ns());
        self.current = Some(source);
        self.last_frame = Instant::now();
        self
    }

    /// The watch that marks this camera away from outside its capture thread.
    pub fn stall_watch(&self) -> StallWatch {
        StallWatch {
            role: self.role,
            stall: self.policy.stall,
            health: self.health(),
        }
    }

    /// Tries to open and start the camera now; on failure it is away until the next try, and
    /// the error is returned.
    fn try_open(&mut self, clock: &Clock) -> Option<CaptureError> {
        let opened = (self.open)().and_then(|mut s| s.start(clock).map(|()| s));
        let now = Instant::now();
        let host_ns = clock.now_ns();
        let mut h = lock(&self.health);
        match opened {
            Ok(source) => {
                let meta = source.meta();
                // The outage ends with the first frame back (`accept`), not with the opening,
                // and so do the camera's state and its `camera_reconnected` event: a reopened
                // camera may yet deliver nothing.
                if let Some(outage) = h.outages.last_mut().filter(|o| o.end_ns.is_none()) {
                    outage.attempts += 1;
                }
                if h.meta.is_some() {
                    tracing::debug!(camera = %self.role, "camera reopened after an outage: waiting for its first frame");
                } else {
                    tracing::info!(camera = %self.role, model = %meta.model, serial = %meta.serial, "camera open");
                }
                mark_open(&mut h, self.role, meta, host_ns);
                // The camera may count from 0 again: carry on from the last number given out.
                self.seq_offset = u64::MAX;
                self.current = Some(source);
                self.last_frame = now;
                self.wait = self.policy.first_wait;
                None
            }
            Err(e) => {
                let reason = error_chain(&e);
                if let Some(outage) = h.outages.last_mut().filter(|o| o.end_ns.is_none()) {
                    outage.attempts += 1;
                }
                if h.state != Some(CameraState::Away(reason.clone())) {
                    tracing::warn!(camera = %self.role, retry_s = self.wait.as_secs_f64(), "cannot open the camera: {reason}");
                    if h.state == Some(CameraState::Opening) {
                        h.begin_outage(host_ns, reason.clone(), 1);
                    }
                    h.state = Some(CameraState::Away(reason));
                }
                self.next_try = now + self.wait;
                self.wait = (self.wait * 2).min(self.policy.max_wait);
                Some(e)
            }
        }
    }

    /// Takes the camera for gone (the state first, so that the status never waits on the
    /// driver), then closes it; the next try comes after the first wait.
    fn lose(&mut self, reason: String, clock: &Clock) {
        {
            let mut h = lock(&self.health);
            let since_ns = h.last_sign.map_or_else(|| clock.now_ns(), |(_, ns)| ns);
            mark_away(&mut h, self.role, reason, since_ns);
        }
        if let Some(mut source) = self.current.take() {
            for (why, n) in source.losses() {
                *self.losses.entry(why).or_default() += n;
            }
            if let Err(e) = source.stop() {
                tracing::debug!(camera = %self.role, "closing the lost camera: {}", error_chain(&e));
            }
        }
        self.wait = self.policy.first_wait;
        self.next_try = Instant::now() + self.wait;
    }

    /// Renumbers and checks a frame; `None` for a frame of another size than the first.
    fn accept(&mut self, mut frame: S::Frame) -> Option<S::Frame> {
        let size = frame.size();
        if *self.size.get_or_insert(size) != size {
            let n = self.losses.entry("wrong_size").or_default();
            if *n == 0 {
                tracing::warn!(camera = %self.role, ?size, expected = ?self.size, "frames of another size are skipped and counted");
            }
            *n += 1;
            return None;
        }
        let stamp = frame.stamp_mut();
        if self.seq_offset == u64::MAX {
            self.seq_offset = self.next_seq.saturating_sub(stamp.seq);
        }
        let seq = stamp.seq.saturating_add(self.seq_offset);
        if seq < self.next_seq {
            // A camera that numbers its frames backwards: keep the numbers growing.
            self.seq_offset += self.next_seq - seq;
        }
        stamp.seq = seq.max(self.next_seq);
        self.next_seq = stamp.seq + 1;
        let host_ns = stamp.host_ns;
        let mut h = lock(&self.health);
        // Back: it had delivered frames before an outage (not merely failing to open at first).
        let back = h.frames > 0 && matches!(h.state, Some(CameraState::Away(_)));
        h.frames += 1;
        h.last_sign = Some((Instant::now(), host_ns));
        if let Some(outage) = h.outages.last_mut().filter(|o| o.end_ns.is_none()) {
            outage.end_ns = Some(host_ns);
        }
        if back {
            // Its first frame after an outage (reopened, or on the same stream after a silence
            // the stall watch took for gone): only now is it back.
            tracing::info!(camera = %self.role, "camera back: frames again after an outage");
            h.events.push(SessionEvent::CameraReconnected {
                host_ns,
                role: self.role,
            });
            self.epoch.fetch_add(1, Ordering::Release);
        }
        h.state = Some(CameraState::Streaming);
        drop(h);
        Some(frame)
    }
}

impl<S> FrameSource for Supervised<S>
where
    S: FrameSource,
    S::Frame: CameraFrame,
{
    type Frame = S::Frame;

    /// The metadata of the latest opening; before any, what the opener would give is unknown,
    /// so the role alone (with an empty model) stands in.
    fn meta(&self) -> CameraMeta {
        match (&self.current, &lock(&self.health).meta) {
            (Some(s), _) => s.meta(),
            (None, Some(m)) => m.clone(),
            (None, None) => CameraMeta {
                role: self.role,
                backend: crate::io::session::BackendName::SYNTHETIC,
                model: String::new(),
                serial: String::new(),
                firmware: String::new(),
                width: 0,
                height: 0,
                pixel_format: match self.role {
                    CameraRole::Depth => crate::io::session::codec::FrameFormat::Depth16,
                    CameraRole::Color => {
                        crate::io::session::codec::FrameFormat::Color(crate::core::frame::PixelFormat::Mono8)
                    }
                },
                fps: 0.0,
            },
        }
    }

    /// Tries the camera once (unless it came [`Supervised::opened`]); a camera that cannot be
    /// opened is not an error here, it is away (it may come later), unless the configuration
    /// itself is at fault ([`CaptureError::never_works`]: a setting the camera does not have,
    /// an unreadable recording), which is returned.
    /// A second call (the daemon tries its cameras before its pipeline starts them) does
    /// nothing.
    fn start(&mut self, clock: &Clock) -> Result<(), CaptureError> {
        if self.clock.is_some() {
            return Ok(());
        }
        self.clock = Some(clock.clone());
        if self.current.is_none()
            && let Some(e) = self.try_open(clock)
            && e.never_works()
        {
            return Err(e);
        }
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Option<S::Frame>, CaptureError> {
        let Some(clock) = self.clock.clone() else {
            return Ok(None);
        };
        lock(&self.health).alive = Some(Instant::now());
        let Some(source) = self.current.as_mut() else {
            let now = Instant::now();
            if now < self.next_try {
                std::thread::sleep(timeout.min(self.next_try - now));
                return Ok(None);
            }
            // A failure leaves the camera away until the next try; its reason is in its state.
            drop(self.try_open(&clock));
            return Ok(None);
        };
        match source.next_frame(timeout) {
            Ok(Some(frame)) => {
                self.last_frame = Instant::now();
                Ok(self.accept(frame))
            }
            Ok(None) if source.finished() => {
                self.ended = true;
                Ok(None)
            }
            Ok(None) => {
                if self.last_frame.elapsed() >= self.policy.stall {
                    let silent = self.last_frame.elapsed().as_secs_f64();
                    self.lose(format!("no frame for {silent:.1} s"), &clock);
                }
                Ok(None)
            }
            Err(e) => {
                self.lose(error_chain(&e), &clock);
                Ok(None)
            }
        }
    }

    /// Only a recording used as a camera (a `.oni` file) ends.
    fn finished(&self) -> bool {
        self.ended
    }

    fn losses(&self) -> Vec<(&'static str, u64)> {
        let mut all = self.losses.clone();
        if let Some(s) = &self.current {
            for (why, n) in s.losses() {
                *all.entry(why).or_default() += n;
            }
        }
        all.into_iter().collect()
    }

    fn stop(&mut self) -> Result<(), CaptureError> {
        match self.current.take() {
            Some(mut s) => {
                for (why, n) in s.losses() {
                    *self.losses.entry(why).or_default() += n;
                }
                s.stop()
            }
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;

    /// What a scripted camera does at each read.
    #[derive(Clone, Copy, Debug)]
    enum Step {
        /// A frame of this width with this camera frame number.
        Frame(u32, u64),
        Fail,
        /// A driver call that does not return for this many milliseconds.
        Hang(u64),
        /// A driver call that returns a frame (width 4, this number) after this many
        /// milliseconds.
        Late(u64, u64),
    }

    #[derive(Debug)]
    struct Scripted(VecDeque<Step>);

    impl FrameSource for Scripted {
        type Frame = DepthFrame;
        fn meta(&self) -> CameraMeta {
            CameraMeta {
                role: CameraRole::Depth,
                backend: crate::io::session::BackendName::SYNTHETIC,
                model: "scripted".into(),
                serial: String::new(),
                firmware: String::new(),
                width: 4,
                height: 1,
                pixel_format: crate::io::session::codec::FrameFormat::Depth16,
                fps: 30.0,
            }
        }
        fn start(&mut self, _clock: &Clock) -> Result<(), CaptureError> {
            Ok(())
        }
        fn next_frame(&mut self, _timeout: Duration) -> Result<Option<DepthFrame>, CaptureError> {
            let mut step = self.0.pop_front();
            if let Some(Step::Late(ms, seq)) = step {
                std::thread::sleep(Duration::from_millis(ms));
                step = Some(Step::Frame(4, seq));
            }
            match step {
                Some(Step::Frame(width, seq)) => {
                    let stamp = Stamp {
                        seq,
                        device_ns: seq,
                        host_ns: seq,
                    };
                    Ok(Some(DepthFrame::empty(stamp, width, 1)))
                }
                Some(Step::Hang(ms)) => {
                    std::thread::sleep(Duration::from_millis(ms));
                    Ok(None)
                }
                Some(Step::Late(..)) => unreachable!("made a frame above"),
                Some(Step::Fail) => Err(CaptureError::Disconnected {
                    backend: "scripted",
                    id: "0".into(),
                    reason: "unplugged".into(),
                }),
                None => Ok(None),
            }
        }
        fn stop(&mut self) -> Result<(), CaptureError> {
            Ok(())
        }
    }

    /// A supervised camera whose openings are `openings` in turn (`None`: the opening fails).
    fn supervised(openings: Vec<Option<Vec<Step>>>) -> (Supervised<Scripted>, Arc<AtomicU64>) {
        let mut openings = VecDeque::from(openings);
        let open = move || match openings.pop_front().flatten() {
            Some(steps) => Ok(Scripted(steps.into())),
            None => Err(CaptureError::NotFound {
                backend: "scripted",
                id: "0".into(),
            }),
        };
        let policy = Reconnect {
            stall: Duration::from_millis(30),
            first_wait: Duration::from_millis(1),
            max_wait: Duration::from_millis(4),
        };
        let epoch = Arc::new(AtomicU64::new(0));
        let s = Supervised::new(CameraRole::Depth, Box::new(open), policy, Arc::clone(&epoch));
        (s, epoch)
    }

    /// Reads until `n` frames came out (or a second passed); their frame numbers.
    fn read(s: &mut Supervised<Scripted>, n: usize) -> Vec<u64> {
        let deadline = Instant::now() + Duration::from_secs(1);
        let mut seqs = Vec::new();
        while seqs.len() < n && Instant::now() < deadline {
            if let Some(f) = s.next_frame(Duration::from_millis(1)).unwrap() {
                seqs.push(f.stamp.seq);
            }
        }
        seqs
    }

    #[test]
    fn frames_of_another_size_are_skipped_and_counted() {
        use Step::Frame;
        let (mut s, _) = supervised(vec![Some(vec![Frame(4, 0), Frame(8, 1), Frame(8, 2), Frame(4, 3)])]);
        s.start(&Clock::replay(0)).unwrap();
        assert_eq!(read(&mut s, 2), vec![0, 3]);
        assert_eq!(s.losses(), vec![("wrong_size", 2)]);
        assert_eq!(lock(&s.health()).frames, 2);
    }

    #[test]
    fn a_failing_camera_is_reopened_and_its_frame_numbers_keep_growing() {
        use Step::{Fail, Frame};
        let (mut s, epoch) = supervised(vec![
            Some(vec![Frame(4, 10), Frame(4, 11), Fail]),
            None,
            None,
            Some(vec![Frame(4, 0), Frame(4, 1)]),
        ]);
        s.start(&Clock::replay(0)).unwrap();
        assert_eq!(read(&mut s, 4), vec![10, 11, 12, 13]);
        assert_eq!(epoch.load(Ordering::Acquire), 1, "one reconnection");
        let h = s.health();
        let h = lock(&h);
        assert_eq!(h.state, Some(CameraState::Streaming));
        assert_eq!(h.outages.len(), 1, "{:?}", h.outages);
        let outage = &h.outages[0];
        assert_eq!((outage.frames_before, outage.attempts), (2, 3));
        assert!(
            outage.end_ns.is_some() && outage.reason.contains("unplugged"),
            "{outage:?}"
        );
        let kinds: Vec<String> = h
            .events
            .iter()
            .map(|e| serde_json::to_value(e).unwrap()["kind"].as_str().unwrap().to_owned())
            .collect();
        assert_eq!(
            kinds,
            [
                "camera_opened",
                "camera_disconnected",
                "camera_opened",
                "camera_reconnected"
            ]
        );
    }

    /// The kinds of the events a camera gathered so far.
    fn event_kinds(health: &SharedHealth) -> Vec<String> {
        lock(health)
            .events
            .iter()
            .map(|e| serde_json::to_value(e).unwrap()["kind"].as_str().unwrap().to_owned())
            .collect()
    }

    /// Issue 37 item 3: a camera reopened after an outage is back (`streaming`,
    /// `camera_reconnected`, the synchroniser told) only with its first frame: a reopening that
    /// delivers nothing leaves it away, in the same outage, until one that does.
    #[test]
    fn issue37_a_reopened_camera_is_back_only_once_a_frame_arrives() {
        use Step::{Fail, Frame};
        let (mut s, epoch) = supervised(vec![
            Some(vec![Frame(4, 5), Fail]),
            Some(Vec::new()),
            Some(vec![Frame(4, 0)]),
        ]);
        s.start(&Clock::replay(0)).unwrap();
        assert_eq!(read(&mut s, 1), vec![5]);
        let health = s.health();
        let opened = |h: &SharedHealth| event_kinds(h).iter().filter(|k| *k == "camera_opened").count();
        let deadline = Instant::now() + Duration::from_secs(1);
        while opened(&health) < 2 {
            assert!(Instant::now() < deadline, "never reopened: {:?}", event_kinds(&health));
            assert!(s.next_frame(Duration::from_millis(1)).unwrap().is_none());
        }
        // Reopened, no frame yet.
        assert!(
            matches!(lock(&health).state, Some(CameraState::Away(_))),
            "{:?}",
            lock(&health).state
        );
        assert_eq!(
            event_kinds(&health),
            ["camera_opened", "camera_disconnected", "camera_opened"]
        );
        assert_eq!(epoch.load(Ordering::Acquire), 0);
        assert_eq!(lock(&health).outages[0].end_ns, None);
        // That opening goes silent and is closed; the next one delivers.
        assert_eq!(read(&mut s, 1), vec![6]);
        let h = lock(&health);
        assert_eq!(h.state, Some(CameraState::Streaming));
        assert_eq!(h.outages.len(), 1, "{:?}", h.outages);
        assert_eq!((h.outages[0].attempts, h.outages[0].end_ns), (2, Some(0)));
        drop(h);
        assert_eq!(
            event_kinds(&health),
            [
                "camera_opened",
                "camera_disconnected",
                "camera_opened",
                "camera_opened",
                "camera_reconnected"
            ]
        );
        assert_eq!(epoch.load(Ordering::Acquire), 1);
    }

    #[test]
    fn a_silent_camera_is_an_outage_after_the_stall_time() {
        let (mut s, _) = supervised(vec![Some(vec![Step::Frame(4, 0)]), None]);
        s.start(&Clock::replay(0)).unwrap();
        assert_eq!(read(&mut s, 1), vec![0]);
        let deadline = Instant::now() + Duration::from_secs(1);
        while !matches!(lock(&s.health()).state, Some(CameraState::Away(_))) {
            assert!(Instant::now() < deadline, "the silence was never noticed");
            s.next_frame(Duration::from_millis(1)).unwrap();
        }
        let h = s.health();
        let h = lock(&h);
        assert!(h.outages[0].reason.starts_with("no frame for"), "{:?}", h.outages);
    }

    #[test]
    fn a_camera_stuck_in_its_driver_is_away_within_the_stall_time_and_its_outage_starts_at_its_last_frame() {
        use std::sync::atomic::AtomicBool;
        let (mut s, _) = supervised(vec![Some(vec![Step::Frame(4, 7), Step::Hang(3000)]), None]);
        s.start(&Clock::replay(0)).unwrap();
        assert_eq!(read(&mut s, 1), vec![7]);
        let watch = s.stall_watch();
        let health = s.health();
        let returned = Arc::new(AtomicBool::new(false));
        let capture = {
            let returned = Arc::clone(&returned);
            std::thread::Builder::new()
                .name("cap-test".into())
                .spawn(move || {
                    // The read that hangs for 3 s in the driver.
                    let _ = s.next_frame(Duration::from_millis(1));
                    returned.store(true, Ordering::Release);
                })
                .unwrap()
        };
        let deadline = Instant::now() + Duration::from_secs(2);
        while !watch.check() {
            assert!(
                Instant::now() < deadline,
                "never taken for gone: {:?}",
                lock(&health).state
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(
            !returned.load(Ordering::Acquire),
            "taken for gone only once the driver call returned"
        );
        {
            let h = lock(&health);
            assert!(matches!(h.state, Some(CameraState::Away(_))), "{:?}", h.state);
            assert_eq!(h.outages.len(), 1);
            assert_eq!(h.outages[0].start_ns, 7, "the outage starts at the last frame");
        }
        assert!(!watch.check(), "one silence, one outage");
        capture.join().unwrap();
        assert_eq!(
            lock(&health).outages.len(),
            1,
            "the capture thread's own notice adds none"
        );
    }

    #[test]
    fn a_camera_back_on_its_stream_after_a_silence_ends_the_outage_at_its_first_frame() {
        use Step::{Frame, Late};
        let (mut s, epoch) = supervised(vec![Some(vec![Frame(4, 1), Late(200, 2)])]);
        s.start(&Clock::replay(0)).unwrap();
        assert_eq!(read(&mut s, 1), vec![1]);
        let watch = s.stall_watch();
        let health = s.health();
        // The driver call hangs for 200 ms, then returns a frame on the same stream.
        let capture = std::thread::Builder::new()
            .name("cap-test".into())
            .spawn(move || read(&mut s, 1))
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(1);
        while !watch.check() {
            assert!(Instant::now() < deadline, "never taken for gone");
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(capture.join().unwrap(), vec![2]);
        let h = lock(&health);
        assert_eq!(h.state, Some(CameraState::Streaming));
        assert_eq!(h.outages.len(), 1, "{:?}", h.outages);
        assert_eq!((h.outages[0].start_ns, h.outages[0].end_ns), (1, Some(2)));
        assert_eq!(
            epoch.load(Ordering::Acquire),
            1,
            "the synchroniser starts the clock again"
        );
    }
}
