//! The live pose stream: every pose as it leaves the pipeline, and the daemon's events, on a
//! ZeroMQ PUB socket (Debian's libzmq; pyzmq, Bonsai.ZeroMQ and Open Ephys speak it), for
//! closed-loop experiments and for recording the poses beside other data.
//!
//! Never slower for a listener: the pose sink hands each message to the `stream` thread through
//! a bounded queue (`try_send`: a full queue drops the message and counts it `queue_full`); the
//! thread sends without waiting (`DONTWAIT`) on a socket whose per-subscriber queue is bounded
//! by its high-water mark (past it libzmq drops for that subscriber alone, which each message's
//! `seq` lets a subscriber see). With no subscriber connected (the socket's monitor counts
//! them) no message is even made. The message format is in `docs/FORMATS.md`; [`message`].

pub mod lsl;
pub mod message;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use std::fmt;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// The port the stream binds by default (beside the HTTP server's).
pub const DEFAULT_STREAM_PORT: u16 = 8471;

/// Messages waiting for the `stream` thread; more are dropped (`queue_full`).
pub const DEFAULT_QUEUE: usize = 64;

/// Messages libzmq keeps per subscriber before dropping for it (`ZMQ_SNDHWM`).
pub const DEFAULT_HIGH_WATER_MARK: i32 = 100;

/// The two topics, each message's first frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Topic {
    Poses,
    Events,
}

impl Topic {
    pub const ALL: [Topic; 2] = [Topic::Poses, Topic::Events];

    pub fn name(self) -> &'static str {
        match self {
            Topic::Poses => "poses",
            Topic::Events => "events",
        }
    }

    /// The topic a name stands for.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// Where the stream is bound (or a listener connects): `tcp://IP:PORT` or `ipc://PATH`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Endpoint {
    Tcp(SocketAddr),
    Ipc(PathBuf),
}

/// Why an endpoint was refused.
#[derive(Debug, thiserror::Error)]
#[error("{text:?} is not a stream endpoint: {why}")]
pub struct EndpointError {
    text: String,
    why: &'static str,
}

impl std::str::FromStr for Endpoint {
    type Err = EndpointError;

    fn from_str(text: &str) -> Result<Self, EndpointError> {
        let bad = |why| EndpointError {
            text: text.to_owned(),
            why,
        };
        if let Some(address) = text.strip_prefix("tcp://") {
            let address: SocketAddr = address
                .parse()
                .map_err(|_| bad("expected tcp://IP:PORT (e.g. tcp://127.0.0.1:8471), an IP address and a port"))?;
            if address.port() == 0 {
                return Err(bad("the port must be from 1 to 65535"));
            }
            Ok(Endpoint::Tcp(address))
        } else if let Some(path) = text.strip_prefix("ipc://") {
            if path.is_empty() || path.contains('\0') {
                return Err(bad("expected ipc://PATH with a file path"));
            }
            Ok(Endpoint::Ipc(PathBuf::from(path)))
        } else {
            Err(bad("expected tcp://IP:PORT or ipc://PATH"))
        }
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::Tcp(address) => write!(f, "tcp://{address}"),
            Endpoint::Ipc(path) => write!(f, "ipc://{}", path.display()),
        }
    }
}

impl Endpoint {
    /// The default: loopback, [`DEFAULT_STREAM_PORT`].
    pub fn default_tcp() -> Self {
        Endpoint::Tcp(([127, 0, 0, 1], DEFAULT_STREAM_PORT).into())
    }

    /// Whether only this machine can reach it (a loopback address, or a socket file).
    pub fn is_local(&self) -> bool {
        match self {
            Endpoint::Tcp(address) => address.ip().is_loopback(),
            Endpoint::Ipc(_) => true,
        }
    }
}

/// The stream's settings (the rig config's `[stream]`, or `replay --stream`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StreamConfig {
    pub endpoint: Endpoint,
    /// Messages waiting for the `stream` thread.
    pub queue: usize,
    /// Messages libzmq keeps per subscriber.
    pub high_water_mark: i32,
    /// What the frames' host stamps are: `monotonic` live (this machine's `CLOCK_MONOTONIC`,
    /// as `published_ns`), `recording` in a replay (the recorded stamps).
    pub host_clock: &'static str,
    /// With each pose, the pose predicted this long after its depth frame was taken (the
    /// rig's latency to what the pose drives); `None`: no prediction.
    pub lead_ns: Option<u64>,
}

impl StreamConfig {
    /// Defaults but for the endpoint.
    pub fn at(endpoint: Endpoint) -> Self {
        Self {
            endpoint,
            queue: DEFAULT_QUEUE,
            high_water_mark: DEFAULT_HIGH_WATER_MARK,
            host_clock: "monotonic",
            lead_ns: None,
        }
    }
}

/// Why the stream could not start.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    #[error("cannot bind the pose stream to {endpoint}: {source}")]
    Bind {
        endpoint: Endpoint,
        #[source]
        source: zmq::Error,
    },
    #[error("cannot set up the pose stream's socket")]
    Socket(#[source] zmq::Error),
    #[error("cannot start the pose stream's thread")]
    Thread(#[source] std::io::Error),
}

/// Why a message did not go out (the label of `mousepose_stream_dropped_total`).
pub const DROP_REASONS: [&str; 2] = ["queue_full", "send_failed"];

/// The stream's counters, read by the status and `/metrics`.
#[derive(Debug, Default)]
pub struct StreamStats {
    /// Per topic ([`Topic::ALL`]'s order): messages handed to libzmq.
    sent: [AtomicU64; 2],
    /// Per [`DROP_REASONS`].
    dropped: [AtomicU64; 2],
    /// Subscribers connected now (connections accepted less those closed).
    subscribers: AtomicU64,
}

/// What the status shows of the stream.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct StreamSummary {
    pub endpoint: String,
    pub subscribers: u64,
    /// Per topic: messages made for the subscribers connected (none while there is none).
    pub published: std::collections::BTreeMap<&'static str, u64>,
    /// Per topic: of those, handed to ZeroMQ.
    pub sent: std::collections::BTreeMap<&'static str, u64>,
    /// Per reason.
    pub dropped: std::collections::BTreeMap<&'static str, u64>,
}

impl StreamStats {
    pub fn subscribers(&self) -> u64 {
        self.subscribers.load(Ordering::Relaxed)
    }

    pub fn sent(&self, topic: Topic) -> u64 {
        self.sent[topic.index()].load(Ordering::Relaxed)
    }

    /// Messages dropped for `reason` (one of [`DROP_REASONS`]).
    pub fn dropped(&self, reason: &str) -> u64 {
        DROP_REASONS
            .iter()
            .position(|r| *r == reason)
            .map_or(0, |i| self.dropped[i].load(Ordering::Relaxed))
    }

    fn drop_one(&self, reason: usize) {
        self.dropped[reason].fetch_add(1, Ordering::Relaxed);
    }
}

/// One message for the `stream` thread: its topic and its JSON body.
type Outgoing = (Topic, Vec<u8>);

/// Where the pipeline and the daemon publish: cheap to clone, never waits.
#[derive(Clone, Debug)]
pub struct StreamHandle {
    tx: Sender<Outgoing>,
    stats: Arc<StreamStats>,
    /// Per topic: the number the next message gets.
    seq: Arc<[AtomicU64; 2]>,
    endpoint: Arc<str>,
    host_clock: &'static str,
    lead_ns: Option<u64>,
}

impl StreamHandle {
    /// Publishes the message `body` makes of its sequence number, when a subscriber is
    /// connected; a full queue drops it (counted `queue_full`). Never waits.
    pub fn publish(&self, topic: Topic, body: impl FnOnce(u64) -> Vec<u8>) {
        if self.stats.subscribers() == 0 {
            return;
        }
        let seq = self.seq[topic.index()].fetch_add(1, Ordering::Relaxed);
        match self.tx.try_send((topic, body(seq))) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => self.stats.drop_one(0),
            // The thread has ended (the run is stopping): nothing to count.
            Err(TrySendError::Disconnected(_)) => {}
        }
    }

    pub fn stats(&self) -> &Arc<StreamStats> {
        &self.stats
    }

    /// The counters, for the status.
    pub fn summary(&self) -> StreamSummary {
        StreamSummary {
            endpoint: self.endpoint.to_string(),
            subscribers: self.stats.subscribers(),
            published: Topic::ALL
                .iter()
                .map(|t| (t.name(), self.seq[t.index()].load(Ordering::Relaxed)))
                .collect(),
            sent: Topic::ALL.iter().map(|t| (t.name(), self.stats.sent(*t))).collect(),
            dropped: DROP_REASONS.iter().map(|r| (*r, self.stats.dropped(r))).collect(),
        }
    }
}

/// The running stream: its socket on the `stream` thread. Dropping it ends the thread once the
/// handles are gone; [`Publisher::stop`] ends it now.
#[derive(Debug)]
pub struct Publisher {
    handle: StreamHandle,
    thread: SendThread,
}

/// The thread that sends what a bounded queue brings (the ZeroMQ stream's and the LSL
/// outlet's) until told to stop; stopped and joined when this is stopped or dropped.
#[derive(Debug)]
struct SendThread {
    name: &'static str,
    stop: Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl SendThread {
    /// Starts the thread `name` running `body`, which returns once the flag it is given is
    /// set and its queue is empty.
    fn spawn(
        name: &'static str,
        body: impl FnOnce(&std::sync::atomic::AtomicBool) + Send + 'static,
    ) -> std::io::Result<Self> {
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || body(&flag))?;
        Ok(Self {
            name,
            stop,
            thread: Some(thread),
        })
    }

    fn end(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::error!(thread = self.name, "the {} thread panicked", self.name);
        }
    }
}

impl Drop for SendThread {
    fn drop(&mut self) {
        self.end();
    }
}

/// How often the `stream` thread looks at its monitor when no message comes.
const MONITOR_PERIOD: Duration = Duration::from_millis(50);

impl Publisher {
    /// Binds the PUB socket to the endpoint and starts the `stream` thread. A non-local
    /// endpoint is said in the log: anyone who can reach it can read the poses.
    ///
    /// # Errors
    /// The endpoint cannot be bound (in use, no such address) or the thread cannot start.
    pub fn start(config: &StreamConfig) -> Result<Self, StreamError> {
        let context = zmq::Context::new();
        let socket = context.socket(zmq::PUB).map_err(StreamError::Socket)?;
        socket.set_sndhwm(config.high_water_mark).map_err(StreamError::Socket)?;
        socket.set_linger(0).map_err(StreamError::Socket)?;
        let endpoint = config.endpoint.to_string();
        socket.bind(&endpoint).map_err(|source| StreamError::Bind {
            endpoint: config.endpoint.clone(),
            source,
        })?;
        static MONITORS: AtomicU64 = AtomicU64::new(0);
        let monitor_at = format!(
            "inproc://mousepose-stream-monitor-{}",
            MONITORS.fetch_add(1, Ordering::Relaxed)
        );
        let events = zmq::SocketEvent::ACCEPTED as i32 | zmq::SocketEvent::DISCONNECTED as i32;
        socket.monitor(&monitor_at, events).map_err(StreamError::Socket)?;
        let monitor = context.socket(zmq::PAIR).map_err(StreamError::Socket)?;
        monitor.connect(&monitor_at).map_err(StreamError::Socket)?;
        if config.endpoint.is_local() {
            tracing::info!(endpoint = %config.endpoint, "pose stream bound (this machine only)");
        } else {
            tracing::warn!(
                endpoint = %config.endpoint,
                "pose stream bound to an address other machines can reach: anyone who reaches it reads the poses (restrict it with the host's firewall, see docs/FORMATS.md)"
            );
        }
        let (tx, rx) = crossbeam_channel::bounded(config.queue);
        let stats = Arc::new(StreamStats::default());
        let thread = {
            let stats = Arc::clone(&stats);
            SendThread::spawn("stream", move |stop| {
                send_loop(&socket, &monitor, &rx, &stats, stop);
                // The sockets close before their context ends.
                drop((monitor, socket));
                drop(context);
            })
            .map_err(StreamError::Thread)?
        };
        Ok(Self {
            handle: StreamHandle {
                tx,
                stats,
                seq: Arc::default(),
                endpoint: endpoint.into(),
                host_clock: config.host_clock,
                lead_ns: config.lead_ns,
            },
            thread,
        })
    }

    pub fn handle(&self) -> StreamHandle {
        self.handle.clone()
    }

    /// Ends the `stream` thread (messages still queued are sent first) and closes the socket.
    pub fn stop(mut self) {
        self.thread.end();
    }
}

/// The `stream` thread: sends what comes, counts the subscribers, until stopped.
fn send_loop(
    socket: &zmq::Socket,
    monitor: &zmq::Socket,
    rx: &Receiver<Outgoing>,
    stats: &StreamStats,
    stop: &std::sync::atomic::AtomicBool,
) {
    let mut failed_once = false;
    loop {
        let item = rx.recv_timeout(MONITOR_PERIOD);
        count_subscribers(monitor, stats);
        match item {
            Ok((topic, body)) => match socket.send_multipart([topic.name().as_bytes(), &body[..]], zmq::DONTWAIT) {
                Ok(()) => {
                    stats.sent[topic.index()].fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => {
                    stats.drop_one(1);
                    if !failed_once {
                        tracing::warn!(error = %e, "a pose stream message could not be sent (counted, further ones not logged)");
                        failed_once = true;
                    }
                }
            },
            Err(_) if stop.load(Ordering::Relaxed) && rx.is_empty() => return,
            Err(_) => {}
        }
    }
}

/// Reads the monitor's events without waiting: accepted connections less closed ones.
fn count_subscribers(monitor: &zmq::Socket, stats: &StreamStats) {
    while let Ok(frames) = monitor.recv_multipart(zmq::DONTWAIT) {
        let Some(event) = frames.first().and_then(|f| f.get(..2)) else {
            continue;
        };
        let event = u16::from_le_bytes([event[0], event[1]]);
        if event == zmq::SocketEvent::ACCEPTED as u16 {
            stats.subscribers.fetch_add(1, Ordering::Relaxed);
        } else if event == zmq::SocketEvent::DISCONNECTED as u16 {
            let _ = stats
                .subscribers
                .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| Some(n.saturating_sub(1)));
        }
    }
}

/// A subscriber: what `mousepose listen` reads, and what the tests read with.
pub struct Subscriber {
    /// Holds its context (libzmq's) alive.
    socket: zmq::Socket,
}

impl fmt::Debug for Subscriber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Subscriber")
    }
}

impl Subscriber {
    /// Connects to `endpoint` for `topics` (ZeroMQ connects in the background: a publisher
    /// that is not there yet is waited for).
    ///
    /// # Errors
    /// The socket cannot be made or the endpoint not connected to.
    pub fn connect(endpoint: &Endpoint, topics: &[Topic]) -> Result<Self, zmq::Error> {
        let context = zmq::Context::new();
        let socket = context.socket(zmq::SUB)?;
        socket.set_linger(0)?;
        socket.connect(&endpoint.to_string())?;
        for topic in topics {
            socket.set_subscribe(topic.name().as_bytes())?;
        }
        Ok(Self { socket })
    }

    /// The next message (topic and JSON body), waiting at most `timeout`; `None` when none
    /// came. A message of another shape is skipped.
    ///
    /// # Errors
    /// The socket failed.
    pub fn next(&self, timeout: Duration) -> Result<Option<(Topic, String)>, zmq::Error> {
        if !self.wait(timeout)? {
            return Ok(None);
        }
        Ok(split(self.socket.recv_multipart(0)?))
    }

    /// What a reader that fell behind should act on: every message waiting (waiting at most
    /// `timeout` for the first) read at once, of which every event in the order sent, then the
    /// newest pose. The poses read past are only skipped (their `seq` says how many); libzmq
    /// keeps reading the socket into this subscriber's queue while the reader is busy, so
    /// reading it empty each time leaves no backlog anywhere. Empty when none came.
    ///
    /// # Errors
    /// The socket failed.
    pub fn newest(&self, timeout: Duration) -> Result<Vec<(Topic, String)>, zmq::Error> {
        let mut heard = Vec::new();
        let mut pose = None;
        if !self.wait(timeout)? {
            return Ok(heard);
        }
        loop {
            let frames = match self.socket.recv_multipart(zmq::DONTWAIT) {
                Ok(frames) => frames,
                Err(zmq::Error::EAGAIN) => break,
                Err(e) => return Err(e),
            };
            match split(frames) {
                Some((Topic::Poses, body)) => pose = Some(body),
                Some(event) => heard.push(event),
                None => {}
            }
        }
        heard.extend(pose.map(|body| (Topic::Poses, body)));
        Ok(heard)
    }

    /// Whether a message came within `timeout`.
    fn wait(&self, timeout: Duration) -> Result<bool, zmq::Error> {
        let ms = i64::try_from(timeout.as_millis()).unwrap_or(i64::MAX);
        Ok(self.socket.poll(zmq::POLLIN, ms)? > 0)
    }
}

/// A message's topic and JSON body; `None` for a message of another shape.
fn split(mut frames: Vec<Vec<u8>>) -> Option<(Topic, String)> {
    let (Some(body), Some(topic), None) = (frames.pop(), frames.pop(), frames.pop()) else {
        return None;
    };
    std::str::from_utf8(&topic)
        .ok()
        .and_then(Topic::from_name)
        .zip(String::from_utf8(body).ok())
}

/// Wraps a pose sink: each pose is published (on the ZeroMQ stream, the LSL outlet, or both)
/// before it is written.
#[derive(Debug)]
pub struct Published<S> {
    pub inner: S,
    pub stream: Option<StreamHandle>,
    pub lsl: Option<lsl::LslHandle>,
}

impl<S: crate::runtime::pipeline::Sink<In = crate::runtime::stages::Fused>> crate::runtime::pipeline::Sink
    for Published<S>
{
    type In = crate::runtime::stages::Fused;

    fn write(&mut self, item: Self::In) -> Result<(), crate::runtime::pipeline::StageError> {
        if let Some(stream) = &self.stream {
            let (host_clock, lead_ns) = (stream.host_clock, stream.lead_ns);
            for record in item.records() {
                stream.publish(Topic::Poses, |seq| message::pose(seq, record, host_clock, lead_ns));
            }
        }
        if let Some(lsl) = &self.lsl {
            lsl.publish(&item.record);
        }
        self.inner.write(item)
    }

    fn flush(&mut self) -> Result<(), crate::runtime::pipeline::StageError> {
        self.inner.flush()
    }
}
