//! What the server admits before a handler runs: connections, HTTP/2 handshakes and the bytes of
//! request messages, each bounded so that no client — however slow, stalled or hostile — makes
//! the server hold unbounded memory or file descriptors.
//!
//! ```text
//! mod.rs       the settings; the accept loop (connection slots, accept-error back-off); the
//!              connection wrapper that closes a connection whose first request is not in by the
//!              handshake timeout
//! messages.rs  the tower layer that buffers each request message until it is complete, within a
//!              per-method size limit, a per-connection and a global memory budget, and a timeout
//! ```
//!
//! Why these four bounds (the failure each one prevents):
//!
//! - **Memory pre-committed by a length prefix.** A gRPC message starts with a 5-byte prefix giving
//!   its length; tonic reserves a buffer of that length as soon as it reads the prefix. A prefix
//!   claiming 1 MB followed by a stall held ~2 MB per stream. Here the message's bytes are
//!   collected as they really arrive and handed to tonic only once complete, so a stalled stream
//!   costs what its client sent, and what all clients sent is charged against the budgets
//!   ([`messages`]).
//! - **Streams and connections without end.** HTTP/2 lets a client open many streams on one
//!   connection and many connections: both are capped ([`AdmissionSettings::max_streams_per_connection`],
//!   [`AdmissionSettings::max_connections`]); a connection over the cap is closed at once, so its
//!   client fails fast (UNAVAILABLE) instead of waiting for its deadline in the listen backlog.
//! - **Half-open handshakes.** A connection that sends part of the HTTP/2 preface (or of a TLS
//!   handshake) and stops used to be held forever. A connection whose first request has not
//!   arrived within [`AdmissionSettings::handshake_timeout`] is closed.
//! - **A busy accept loop.** When the process runs out of file descriptors, `accept` fails at once,
//!   every time; the loop waits [`ACCEPT_BACKOFF`] after an error instead of spinning.
//!
//! HTTP/2 flow-control windows are fixed, not adaptive ([`AdmissionSettings::stream_window_bytes`],
//! [`AdmissionSettings::connection_window_bytes`]): a connection's unread bytes are bounded by its
//! window whatever the client claims.

pub mod messages;

use std::future::Future as _;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, OwnedSemaphorePermit, Semaphore};
use tonic::transport::server::{Connected, TcpIncoming};

/// How long the accept loop waits after a failed `accept` (e.g. EMFILE, out of file descriptors)
/// before it tries again.
pub const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);

/// Bounds on connections and request messages (see the module docs for what each one prevents).
/// Part of [`crate::ServerConfig`]; each field is a `sublevel serve` flag.
///
/// The defaults keep a server under ~1 GB of request buffers whatever its clients do (safe in a
/// 2 GB container): at most [`Self::request_memory_bytes`] (256 MiB) of request bytes held, plus
/// each connection's flow-control window (1 MiB × 256 connections), plus tonic's 8 KiB buffer
/// per open stream (256 × 64 streams × 8 KiB = 128 MiB).
#[derive(Clone, Debug)]
pub struct AdmissionSettings {
    /// Most connections open at once (`--max-connections`); one more is accepted and closed at
    /// once.
    pub max_connections: usize,
    /// Most concurrent HTTP/2 streams (calls) per connection (`--max-streams-per-connection`),
    /// advertised in the HTTP/2 settings: gRPC clients queue calls beyond it.
    pub max_streams_per_connection: u32,
    /// Longest time from accepting a connection to its first request (`--handshake-timeout-ms`):
    /// TLS handshake, HTTP/2 preface and one request's headers. Past it the connection is closed.
    pub handshake_timeout: Duration,
    /// Largest request message of every method but the uploads (`--max-request-bytes`); the
    /// uploads (`UploadBody`, `StartFitJob`, `StartGroupJob`, `ImportScene`, `UploadRobot`, `StartRobotFitJob`,
    /// `UpdatePointCloud`) may send up to
    /// [`crate::ServerConfig::max_message_bytes`]. A larger length prefix is OUT_OF_RANGE before
    /// any byte of the message is buffered.
    pub max_request_bytes: usize,
    /// Most bytes of incomplete request messages held at once by the whole server
    /// (`--request-memory-bytes`). A message whose bytes would pass it is RESOURCE_EXHAUSTED; the
    /// last eighth is kept for messages of at most [`messages::SMALL_MESSAGE_BYTES`] (queries,
    /// pose updates), so large uploads cannot starve them.
    pub request_memory_bytes: usize,
    /// Most bytes of incomplete request messages held at once for one connection
    /// (`--connection-memory-bytes`); at least the largest upload.
    pub connection_memory_bytes: usize,
    /// Longest time one request message may take to arrive once its first byte has
    /// (`--message-timeout-ms`); past it the call is DEADLINE_EXCEEDED and its bytes are freed.
    pub message_timeout: Duration,
    /// HTTP/2 flow-control window of one stream, bytes (`--stream-window-bytes`).
    pub stream_window_bytes: u32,
    /// HTTP/2 flow-control window of one connection, bytes (`--connection-window-bytes`).
    pub connection_window_bytes: u32,
}

impl Default for AdmissionSettings {
    fn default() -> Self {
        Self {
            max_connections: 256,
            max_streams_per_connection: 64,
            handshake_timeout: Duration::from_secs(10),
            max_request_bytes: 16 << 20,
            request_memory_bytes: 256 << 20,
            connection_memory_bytes: 96 << 20,
            message_timeout: Duration::from_secs(30),
            stream_window_bytes: 256 << 10,
            connection_window_bytes: 1 << 20,
        }
    }
}

/// What the server knows about one connection, shared by its I/O wrapper and its requests.
#[derive(Debug)]
pub struct ConnectionState {
    /// Set by the first request; until then the handshake timeout runs.
    requested: AtomicBool,
    /// Bytes of incomplete request messages held for this connection.
    held: AtomicUsize,
}

impl ConnectionState {
    fn new() -> Self {
        Self { requested: AtomicBool::new(false), held: AtomicUsize::new(0) }
    }
}

/// The connection information every request carries in its extensions (tonic's `connect_info`;
/// under TLS wrapped in `TlsConnectInfo`): the peer's address and the connection's state.
#[derive(Clone, Debug)]
pub struct ConnectionInfo {
    /// The server's address of the connection.
    pub local_addr: Option<SocketAddr>,
    /// The client's address.
    pub remote_addr: Option<SocketAddr>,
    /// Shared with the connection's I/O wrapper.
    pub(crate) state: Arc<ConnectionState>,
}

/// An accepted TCP connection holding one of the server's connection slots, closed with an error
/// when its first request has not arrived by its handshake deadline.
pub struct AdmittedConnection {
    stream: TcpStream,
    state: Arc<ConnectionState>,
    /// Armed until the first request; polled on every read so its expiry wakes the connection.
    deadline: Option<Pin<Box<tokio::time::Sleep>>>,
    _slot: OwnedSemaphorePermit,
}

impl std::fmt::Debug for AdmittedConnection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AdmittedConnection").field("state", &self.state).finish_non_exhaustive()
    }
}

impl AdmittedConnection {
    /// Checks the handshake deadline: `Err(TimedOut)` once it passed without a request.
    fn check_deadline(&mut self, cx: &mut Context<'_>) -> io::Result<()> {
        if self.deadline.is_none() {
            return Ok(());
        }
        if self.state.requested.load(Ordering::Relaxed) {
            self.deadline = None;
            return Ok(());
        }
        if let Some(deadline) = self.deadline.as_mut() {
            if deadline.as_mut().poll(cx).is_ready() {
                metrics::counter!(crate::metrics::CONNECTIONS_CLOSED, "reason" => "handshake_timeout").increment(1);
                tracing::debug!("closing a connection whose first request did not arrive in time");
                return Err(io::Error::new(io::ErrorKind::TimedOut, "no request before the handshake timeout"));
            }
        }
        Ok(())
    }
}

impl AsyncRead for AdmittedConnection {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        this.check_deadline(cx)?;
        Pin::new(&mut this.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for AdmittedConnection {
    fn poll_write(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.get_mut().stream).poll_write(cx, buf)
    }
    fn poll_flush(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().stream).poll_flush(cx)
    }
    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.get_mut().stream).poll_shutdown(cx)
    }
    fn poll_write_vectored(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.get_mut().stream).poll_write_vectored(cx, bufs)
    }
    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }
}

impl Connected for AdmittedConnection {
    type ConnectInfo = ConnectionInfo;
    fn connect_info(&self) -> ConnectionInfo {
        ConnectionInfo {
            local_addr: self.stream.local_addr().ok(),
            remote_addr: self.stream.peer_addr().ok(),
            state: self.state.clone(),
        }
    }
}

/// The stream of admitted connections of `listener`, for tonic's `serve_with_incoming_shutdown`.
///
/// A task accepts connections (TCP_NODELAY and TCP keepalive every `keepalive`), gives each one
/// of `settings.max_connections` slots — a connection beyond them is closed at once — and arms
/// its handshake deadline. After a failed accept it waits [`ACCEPT_BACKOFF`]. The task and the
/// listening socket end when the returned stream is dropped (the server stops accepting).
pub fn admit(
    listener: tokio::net::TcpListener,
    settings: &AdmissionSettings,
    keepalive: Duration,
) -> tokio_stream::wrappers::ReceiverStream<io::Result<AdmittedConnection>> {
    use tokio_stream::StreamExt as _;
    let (tx, rx) = mpsc::channel(16);
    let slots = Arc::new(Semaphore::new(settings.max_connections.max(1)));
    let handshake = settings.handshake_timeout;
    let mut incoming = TcpIncoming::from(listener).with_nodelay(Some(true)).with_keepalive(Some(keepalive));
    tokio::spawn(async move {
        loop {
            let accepted = tokio::select! {
                () = tx.closed() => break,
                next = incoming.next() => next,
            };
            let stream = match accepted {
                None => break,
                Some(Ok(stream)) => stream,
                Some(Err(e)) => {
                    tracing::warn!(error = %e, "accept failed; retrying in {ACCEPT_BACKOFF:?}");
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                    continue;
                }
            };
            let Ok(slot) = slots.clone().try_acquire_owned() else {
                metrics::counter!(crate::metrics::CONNECTIONS_CLOSED, "reason" => "max_connections").increment(1);
                tracing::debug!(peer = ?stream.peer_addr().ok(), "closing a connection over --max-connections");
                drop(stream);
                continue;
            };
            let connection = AdmittedConnection {
                stream,
                state: Arc::new(ConnectionState::new()),
                deadline: Some(Box::pin(tokio::time::sleep(handshake))),
                _slot: slot,
            };
            if tx.send(Ok(connection)).await.is_err() {
                break;
            }
        }
    });
    tokio_stream::wrappers::ReceiverStream::new(rx)
}
