//! The server's connections, bounded: at most [`MAX_CONNECTIONS`] open at once (more wait in
//! the kernel's queue, taking no descriptor of the daemon's), and each closed after
//! [`IDLE_TIMEOUT`] without a byte either way. Clients that connect and never ask (or keep a
//! connection open between requests for ever) cannot use up the daemon's descriptors, which
//! the recorder needs for its chunks.

use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::{Instant, Sleep};

/// Connections open at once.
pub const MAX_CONNECTIONS: usize = 256;
/// A connection with nothing read or written for this long is closed: longer than a request
/// may take ([`super::REQUEST_TIMEOUT`]), so that no answer is cut short.
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(6);

/// A listener that hands out at most [`MAX_CONNECTIONS`] connections at once, each an
/// [`Idle`]-bounded stream.
#[derive(Debug)]
pub struct Bounded {
    listener: TcpListener,
    slots: Arc<Semaphore>,
    idle: Duration,
}

impl Bounded {
    pub fn new(listener: TcpListener) -> Self {
        Self::with_limits(listener, MAX_CONNECTIONS, IDLE_TIMEOUT)
    }

    fn with_limits(listener: TcpListener, connections: usize, idle: Duration) -> Self {
        Self {
            listener,
            slots: Arc::new(Semaphore::new(connections)),
            idle,
        }
    }
}

impl axum::serve::Listener for Bounded {
    type Io = Idle;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Idle, SocketAddr) {
        loop {
            // The semaphore is never closed.
            let Ok(slot) = Arc::clone(&self.slots).acquire_owned().await else {
                std::future::pending::<()>().await;
                continue;
            };
            match self.listener.accept().await {
                Ok((stream, address)) => return (Idle::new(stream, slot, self.idle), address),
                Err(e) => {
                    // Out of descriptors, or a connection reset before it was taken: wait a
                    // moment (the error would come back at once) and go on.
                    tracing::debug!("cannot accept an HTTP connection: {e}");
                    drop(slot);
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        self.listener.local_addr()
    }
}

/// A connection that fails with [`io::ErrorKind::TimedOut`] once it has been idle (nothing
/// read, nothing written) for its timeout; it holds its place among the open connections.
#[derive(Debug)]
pub struct Idle {
    stream: TcpStream,
    idle: Duration,
    deadline: Pin<Box<Sleep>>,
    _slot: OwnedSemaphorePermit,
}

impl Idle {
    fn new(stream: TcpStream, slot: OwnedSemaphorePermit, idle: Duration) -> Self {
        Self {
            stream,
            idle,
            deadline: Box::pin(tokio::time::sleep(idle)),
            _slot: slot,
        }
    }

    /// Moves the deadline on after some bytes went through.
    fn active(&mut self) {
        self.deadline.as_mut().reset(Instant::now() + self.idle);
    }

    /// For an operation that is still pending: the time-out error once the deadline passed
    /// (polling the deadline also wakes the connection then).
    fn expired(&mut self, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match self.deadline.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the HTTP connection was idle too long",
            ))),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl AsyncRead for Idle {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.stream).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                if buf.filled().len() > before {
                    self.active();
                }
                Poll::Ready(Ok(()))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => self.expired(cx),
        }
    }
}

impl AsyncWrite for Idle {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.stream).poll_write(cx, buf) {
            Poll::Ready(Ok(n)) => {
                if n > 0 {
                    self.active();
                }
                Poll::Ready(Ok(n))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => self.expired(cx).map(|r| r.map(|()| 0)),
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::serve::Listener as _;
    use tokio::io::AsyncReadExt as _;

    fn runtime() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .unwrap()
    }

    #[test]
    fn an_idle_connection_is_closed_after_the_timeout_and_frees_its_place() {
        runtime().block_on(async {
            let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
            let address = listener.local_addr().unwrap();
            let mut bounded = Bounded::with_limits(listener, 1, Duration::from_millis(100));
            let _client = TcpStream::connect(address).await.unwrap();
            let (mut io, _) = bounded.accept().await;
            let started = Instant::now();
            let mut byte = [0u8; 1];
            let err = io.read(&mut byte).await.unwrap_err();
            assert_eq!(err.kind(), io::ErrorKind::TimedOut);
            assert!(started.elapsed() >= Duration::from_millis(100));
            // The one place is taken until the idle connection goes.
            let _second = TcpStream::connect(address).await.unwrap();
            let waiting = tokio::time::timeout(Duration::from_millis(100), bounded.accept()).await;
            assert!(waiting.is_err(), "a second connection while the first is open");
            drop(io);
            tokio::time::timeout(Duration::from_secs(5), bounded.accept())
                .await
                .expect("the place is free again");
        });
    }

    #[test]
    fn bytes_keep_a_connection_open() {
        runtime().block_on(async {
            let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
            let address = listener.local_addr().unwrap();
            let mut bounded = Bounded::with_limits(listener, 1, Duration::from_millis(200));
            let mut client = TcpStream::connect(address).await.unwrap();
            let (mut io, _) = bounded.accept().await;
            let writer = tokio::spawn(async move {
                use tokio::io::AsyncWriteExt as _;
                for _ in 0..6 {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    client.write_all(b"x").await.unwrap();
                }
                client
            });
            let mut got = [0u8; 6];
            io.read_exact(&mut got)
                .await
                .expect("600 ms of bytes 100 ms apart, idle 200 ms");
            drop(writer.await.unwrap());
        });
    }
}
