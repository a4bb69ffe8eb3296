//! The daemon's window: a small HTTP server (tokio + axum on one thread of its own) with the
//! live page (`/`), Prometheus metrics (`/metrics`), the run report so far (`/status`), the
//! last minutes' rates (`/history`), the last events (`/events`) and the latest pictures
//! (`/live/depth.png`, `/live/mouse.png`, `/live/bottom.png`).
//!
//! It only reads: every handler reads the [`Watch`] (counters and the latest snapshot), never
//! waits on a stage, and frames never cross it. Connections are bounded ([`conn`]: at most
//! 256 open, each closed after 6 s idle) and so are requests: at most
//! [`MAX_IN_FLIGHT`] at once (more get 503), each done within [`REQUEST_TIMEOUT`], pictures
//! drawn at most twice a second whatever the number of clients, and the server's threads
//! run at a lower priority than the pipeline's. A non-loopback address needs `allow_remote` in
//! the config and then a bearer token on every request.

pub mod client;
pub mod conn;
pub mod metrics;

use crate::core::geometry::Rig;
use crate::runtime::overlay;
use crate::runtime::status::Watch;
use crate::runtime::status::events::EventLog;
use crate::vision::segment::FloorPlane;
use axum::Router;
use axum::body::Body;
use axum::extract::{RawQuery, Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

/// Requests handled at once; more are answered 503 at once.
pub const MAX_IN_FLIGHT: usize = 64;
/// The longest a request may take.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

/// How long stopping waits for open connections.
const STOP_WAIT: Duration = Duration::from_secs(2);

/// The live page, served from the binary.
const PAGE: &str = include_str!("page.html");

/// Why the server could not start.
#[derive(Debug, thiserror::Error)]
pub enum HttpError {
    #[error("cannot listen on {address} (is another mousepose or program using it? set [http] address)")]
    Bind {
        address: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start the HTTP server's thread")]
    Thread(#[source] std::io::Error),
}

/// An address taken for the server, not served yet.
#[derive(Debug)]
pub struct Listener {
    listener: std::net::TcpListener,
    bound: SocketAddr,
}

/// A running server; dropping it (or [`HttpServer::stop`]) stops it.
#[derive(Debug)]
pub struct HttpServer {
    address: SocketAddr,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl HttpServer {
    /// Takes `address` (port 0: any free port), before anything else of a run starts, so that
    /// an address in use stops the daemon before it opens a camera.
    ///
    /// # Errors
    /// The address cannot be bound.
    pub fn bind(address: SocketAddr) -> Result<Listener, HttpError> {
        let listener = std::net::TcpListener::bind(address).map_err(|source| HttpError::Bind { address, source })?;
        let bound = listener
            .local_addr()
            .and_then(|a| listener.set_nonblocking(true).map(|()| a))
            .map_err(|source| HttpError::Bind { address, source })?;
        Ok(Listener { listener, bound })
    }

    /// Serves `watch` on `listener` from a thread of its own. `token`: the bearer token every
    /// request must carry.
    ///
    /// # Errors
    /// The thread cannot start.
    pub fn start(listener: Listener, token: Option<String>, watch: Arc<Watch>, rig: Rig) -> Result<Self, HttpError> {
        let Listener { listener, bound } = listener;
        let state = Arc::new(Served {
            watch,
            rig,
            token,
            events: EventLog::global(),
            permits: tokio::sync::Semaphore::new(MAX_IN_FLIGHT),
            pictures: tokio::sync::Mutex::new(None),
        });
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("http".into())
            .spawn(move || serve(listener, state, stop_rx))
            .map_err(HttpError::Thread)?;
        tracing::info!(address = %bound, "serving the live page, /metrics and /status on http://{bound}/");
        Ok(Self {
            address: bound,
            stop: Some(stop_tx),
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Stops serving and waits for the thread.
    pub fn stop(mut self) {
        self.shut();
    }

    fn shut(&mut self) {
        // An error means the server has stopped already.
        if let Some(stop) = self.stop.take()
            && stop.send(()).is_err()
        {
            tracing::debug!("the HTTP server had stopped already");
        }
        if let Some(thread) = self.thread.take() {
            // Open connections get a moment to finish; a client that holds one longer does not
            // hold up the daemon's exit.
            let deadline = std::time::Instant::now() + STOP_WAIT;
            while !thread.is_finished() && std::time::Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            if !thread.is_finished() {
                tracing::warn!("the HTTP server still had clients after {STOP_WAIT:?}: left to end with the process");
            } else if thread.join().is_err() {
                tracing::error!("the HTTP server's thread panicked");
            }
        }
    }
}

impl Drop for HttpServer {
    fn drop(&mut self) {
        self.shut();
    }
}

/// Nice value of the server's threads: the pipeline's threads come first on a busy machine.
const NICE: i32 = 10;

/// Lowers the calling thread's priority (Linux sets nice per thread).
fn lower_priority() {
    if let Err(e) = rustix::process::setpriority_process(Some(rustix::thread::gettid()), NICE) {
        tracing::debug!("cannot lower the HTTP server's priority: {e}");
    }
}

/// The body of the server's thread.
fn serve(listener: std::net::TcpListener, state: Arc<Served>, stop: tokio::sync::oneshot::Receiver<()>) {
    lower_priority();
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .max_blocking_threads(2)
        .thread_name("http-draw")
        .on_thread_start(lower_priority)
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            tracing::error!("cannot start the HTTP server: {e}");
            return;
        }
    };
    let app = router(state);
    let result = runtime.block_on(async move {
        let listener = conn::Bounded::new(tokio::net::TcpListener::from_std(listener)?);
        axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                drop(stop.await);
            })
            .await
    });
    if let Err(e) = result {
        tracing::error!("the HTTP server stopped: {e}");
    }
}

/// What the handlers share.
#[derive(Debug)]
struct Served {
    watch: Arc<Watch>,
    rig: Rig,
    token: Option<String>,
    events: Arc<EventLog>,
    permits: tokio::sync::Semaphore,
    /// The pictures of the latest frame drawn, shared by every client.
    pictures: tokio::sync::Mutex<Option<Pictures>>,
}

/// Pictures are drawn at most this often, however fast poses come and however many pages are
/// open: drawing and encoding them is the page's main cost to the machine.
const PICTURE_INTERVAL: Duration = Duration::from_millis(500);

/// How much older than the latest pose the bottom view may be: a colour frame missing from one
/// pair keeps the last one on the page; a colour camera away for longer blanks it.
const BOTTOM_STALE: Duration = Duration::from_secs(2);

/// The live pictures of one frame pair, as PNG.
#[derive(Debug, Clone)]
struct Pictures {
    /// The depth frame's number, and that of the colour frame the bottom view shows.
    key: (u64, Option<u64>),
    drawn: std::time::Instant,
    depth: axum::body::Bytes,
    /// The depth image around the mouse, magnified.
    mouse: axum::body::Bytes,
    bottom: Option<axum::body::Bytes>,
}

fn router(state: Arc<Served>) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/metrics", get(metrics_text))
        .route("/status", get(status))
        .route("/history", get(history))
        .route("/events", get(events))
        .route("/live/depth.png", get(depth_png))
        .route("/live/mouse.png", get(mouse_png))
        .route("/live/bottom.png", get(bottom_png))
        .layer(axum::middleware::from_fn_with_state(Arc::clone(&state), guard))
        .with_state(state)
}

/// Bearer token, then a place among the requests in flight, then the time limit.
async fn guard(State(s): State<Arc<Served>>, request: Request, next: Next) -> Response {
    if let Some(token) = &s.token {
        if !authorised(&request, token) {
            let mut response = (StatusCode::UNAUTHORIZED, "a bearer token is needed\n").into_response();
            response
                .headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            return response;
        }
    }
    let Ok(_permit) = s.permits.try_acquire() else {
        return (StatusCode::SERVICE_UNAVAILABLE, "too many requests at once\n").into_response();
    };
    match tokio::time::timeout(REQUEST_TIMEOUT, next.run(request)).await {
        Ok(response) => response,
        Err(_) => (StatusCode::SERVICE_UNAVAILABLE, "the request took too long\n").into_response(),
    }
}

/// Whether the request carries `token`: `Authorization: Bearer TOKEN`, or `?token=TOKEN` (for a
/// browser opening the page, which then sends it with every request of its own).
fn authorised(request: &Request, token: &str) -> bool {
    let header = request
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    let query = request
        .uri()
        .query()
        .into_iter()
        .flat_map(|q| q.split('&'))
        .find_map(|kv| kv.strip_prefix("token="));
    [header, query]
        .into_iter()
        .flatten()
        .any(|given| same(given.trim(), token))
}

/// Compares in time independent of where the strings differ.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn with_type(content_type: &'static str, body: impl Into<Body>) -> Response {
    let mut response = Response::new(body.into());
    let headers = response.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    response
}

fn json(value: &impl serde::Serialize) -> Response {
    match serde_json::to_vec(value) {
        Ok(bytes) => with_type("application/json", bytes),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot encode: {e}\n")).into_response(),
    }
}

async fn page() -> Response {
    with_type("text/html; charset=utf-8", PAGE)
}

async fn metrics_text(State(s): State<Arc<Served>>) -> Response {
    match metrics::encode(&s.watch) {
        Ok(text) => with_type("application/openmetrics-text; version=1.0.0; charset=utf-8", text),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "cannot encode the metrics\n").into_response(),
    }
}

/// The run report so far: JSON, or a few lines of text with `?format=text`.
async fn status(State(s): State<Arc<Served>>, RawQuery(query): RawQuery) -> Response {
    let report = s.watch.report();
    if query.is_some_and(|q| q.split('&').any(|kv| kv == "format=text")) {
        return with_type("text/plain; charset=utf-8", report.text());
    }
    json(&report)
}

async fn history(State(s): State<Arc<Served>>) -> Response {
    json(&s.watch.history())
}

async fn events(State(s): State<Arc<Served>>) -> Response {
    json(&s.events.recent())
}

async fn depth_png(State(s): State<Arc<Served>>) -> Response {
    match pictures(&s).await {
        Some(p) => with_type("image/png", p.depth),
        None => (StatusCode::NOT_FOUND, "no pose yet\n").into_response(),
    }
}

async fn mouse_png(State(s): State<Arc<Served>>) -> Response {
    match pictures(&s).await {
        Some(p) => with_type("image/png", p.mouse),
        None => (StatusCode::NOT_FOUND, "no pose yet\n").into_response(),
    }
}

async fn bottom_png(State(s): State<Arc<Served>>) -> Response {
    match pictures(&s).await.and_then(|p| p.bottom) {
        Some(png) => with_type("image/png", png),
        None => (StatusCode::NOT_FOUND, "no colour frame in the last two seconds\n").into_response(),
    }
}

/// The pictures of the latest pose, drawn off the server's thread at most once per frame pair
/// and once per [`PICTURE_INTERVAL`], and shared by every client.
async fn pictures(s: &Arc<Served>) -> Option<Pictures> {
    let mut cached = s.pictures.lock().await;
    if let Some(p) = cached.as_ref().filter(|p| p.drawn.elapsed() < PICTURE_INTERVAL) {
        return Some(p.clone());
    }
    let (record, frames) = s.watch.latest()?;
    let bottom_source = s
        .watch
        .latest_with_color()
        .filter(|(with, _)| record.depth.host_ns.saturating_sub(with.depth.host_ns) <= BOTTOM_STALE.as_nanos() as u64);
    let key = (
        record.depth.seq,
        bottom_source.as_ref().and_then(|(with, _)| with.color.map(|c| c.seq)),
    );
    if let Some(p) = cached.as_ref().filter(|p| p.key == key) {
        return Some(p.clone());
    }
    let rig = s.rig;
    // The floor the segmenter fitted; the rig's own until there is one.
    let floor = s.watch.floor().unwrap_or_else(|| FloorPlane::of_camera(&rig.depth));
    let drawn = tokio::task::spawn_blocking(move || {
        let depth = overlay::depth_view(&rig, &frames.depth, &record, &floor)
            .to_png()
            .ok()?;
        let mouse = overlay::mouse_view(&rig, &frames.depth, &record).to_png().ok()?;
        let bottom = bottom_source.and_then(|(with, pair)| {
            let color = pair.color?;
            overlay::bottom_panel(&rig, &color, &with).to_png().ok()
        });
        Some(Pictures {
            key,
            drawn: std::time::Instant::now(),
            depth: depth.into(),
            mouse: mouse.into(),
            bottom: bottom.map(Into::into),
        })
    })
    .await
    .ok()
    .flatten()?;
    *cached = Some(drawn.clone());
    Some(drawn)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_is_taken_from_the_header_or_the_query_and_compared_whole() {
        let token = "0123456789abcdef";
        let request = |uri: &str, auth: Option<&str>| {
            let mut b = Request::builder().uri(uri);
            if let Some(a) = auth {
                b = b.header(header::AUTHORIZATION, a);
            }
            b.body(Body::empty()).expect("a request")
        };
        assert!(authorised(&request("/status", Some("Bearer 0123456789abcdef")), token));
        assert!(authorised(&request("/?x=1&token=0123456789abcdef", None), token));
        assert!(!authorised(&request("/status", None), token));
        assert!(!authorised(&request("/status", Some("Bearer 0123456789abcde")), token));
        assert!(!authorised(&request("/status", Some("0123456789abcdef")), token));
        assert!(!authorised(&request("/?token=0123456789abcdeF", None), token));
    }
}
