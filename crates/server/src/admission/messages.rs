//! The request-message layer: every request body is read through [`AdmittedBody`], which collects
//! each gRPC message (5-byte prefix: a compression flag and the big-endian length, then the
//! bytes) until it is complete and only then hands it to tonic.
//!
//! - A length over the method's limit is OUT_OF_RANGE before any byte is buffered: uploads
//!   (`UploadBody`, `StartFitJob`, `StartGroupJob`, `ImportScene`, `UploadRobot`,
//!   `StartRobotFitJob`, and `UpdatePointCloud`'s sensor frames) may send
//!   [`crate::ServerConfig::max_message_bytes`],
//!   every other method [`super::AdmissionSettings::max_request_bytes`].
//! - Bytes held (received, message not yet complete) are charged as they arrive to the
//!   connection's budget and to the server's, and released when the message is handed on or the
//!   call ends; a chunk that would pass either budget makes the call RESOURCE_EXHAUSTED naming the
//!   flag. A stalled message therefore costs the bytes its client really sent, never its claimed
//!   length (tonic reserves the claimed length when it reads the prefix; here it only ever sees
//!   complete messages).
//! - A message must arrive within [`super::AdmissionSettings::message_timeout`] of its first byte,
//!   else the call is DEADLINE_EXCEEDED and its bytes are freed.
//!
//! The layer also marks the connection as past its handshake (its first request arrived), which
//! stops the handshake timeout of [`super::AdmittedConnection`].

use super::{AdmissionSettings, ConnectionInfo, ConnectionState};
use bytes::{Bytes, BytesMut};
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tonic::codegen::http::{HeaderMap, Request};
use tonic::codegen::Service;
use tonic::transport::server::TlsConnectInfo;
use tonic::Status;

/// Messages of at most this many bytes are "small" (queries, pose updates, listings): they may
/// use the whole server budget, while larger ones leave its last eighth free for them.
pub const SMALL_MESSAGE_BYTES: usize = 64 << 10;

/// Length of the gRPC message prefix (compression flag + u32 length).
const PREFIX: usize = 5;

/// The methods whose requests may be as large as [`crate::ServerConfig::max_message_bytes`].
const UPLOADS: [&str; 7] = [
    "/sublevel.v1.Sublevel/UploadBody",
    "/sublevel.v1.Sublevel/StartFitJob",
    "/sublevel.v1.Sublevel/StartGroupJob",
    "/sublevel.v1.Sublevel/ImportScene",
    "/sublevel.v1.Sublevel/UploadRobot",
    "/sublevel.v1.Sublevel/StartRobotFitJob",
    // A sensor frame: a million-point PointCloud2 at 16 bytes per point is 16 MB.
    "/sublevel.v1.Sublevel/UpdatePointCloud",
];

type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// The limits and the server-wide budget shared by every call.
#[derive(Debug)]
struct Shared {
    /// Bytes held by incomplete messages, all connections together.
    held: AtomicUsize,
    request_memory: usize,
    connection_memory: usize,
    max_request: usize,
    max_upload: usize,
    timeout: Duration,
}

/// The [`tower::Layer`] of request-message admission (see the module docs).
#[derive(Clone, Debug)]
pub struct MessageLayer {
    shared: Arc<Shared>,
}

impl MessageLayer {
    /// The layer for `settings`, with uploads limited to `max_upload_bytes`.
    pub fn new(settings: &AdmissionSettings, max_upload_bytes: usize) -> Self {
        Self {
            shared: Arc::new(Shared {
                held: AtomicUsize::new(0),
                request_memory: settings.request_memory_bytes,
                connection_memory: settings.connection_memory_bytes,
                max_request: settings.max_request_bytes,
                max_upload: max_upload_bytes,
                timeout: settings.message_timeout,
            }),
        }
    }

    /// Bytes held by incomplete request messages right now, all connections together.
    pub fn held_bytes(&self) -> usize {
        self.shared.held.load(Ordering::Relaxed)
    }
}

impl<S> tower::Layer<S> for MessageLayer {
    type Service = MessageService<S>;
    fn layer(&self, inner: S) -> Self::Service {
        MessageService { inner, shared: self.shared.clone() }
    }
}

/// The service [`MessageLayer`] wraps around the router.
#[derive(Clone, Debug)]
pub struct MessageService<S> {
    inner: S,
    shared: Arc<Shared>,
}

impl<S, B> Service<Request<B>> for MessageService<S>
where
    S: Service<Request<tonic::body::Body>>,
    B: http_body::Body<Data = Bytes> + Send + 'static,
    B::Error: Into<BoxError>,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = S::Future;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request<B>) -> Self::Future {
        let extensions = req.extensions();
        let info = extensions
            .get::<ConnectionInfo>()
            .or_else(|| extensions.get::<TlsConnectInfo<ConnectionInfo>>().map(TlsConnectInfo::get_ref));
        let connection = info.map(|i| i.state.clone());
        if let Some(c) = &connection {
            c.requested.store(true, Ordering::Relaxed);
        }
        let (limit, flag) = if UPLOADS.contains(&req.uri().path()) {
            (self.shared.max_upload, "--max-message-bytes / SUBLEVEL_MAX_MESSAGE_BYTES")
        } else {
            (self.shared.max_request, "--max-request-bytes / SUBLEVEL_MAX_REQUEST_BYTES")
        };
        let uri = req.uri().clone();
        let shared = self.shared.clone();
        let req = req.map(move |body| {
            tonic::body::Body::new(AdmittedBody::new(body, Limit { bytes: limit, flag }, uri, shared, connection))
        });
        self.inner.call(req)
    }
}

/// A request body read message by message (see the module docs).
pub struct AdmittedBody<B> {
    inner: Pin<Box<B>>,
    /// Received bytes not yet handed on: `ready` bytes of complete messages, then the start of the
    /// message being collected.
    pending: BytesMut,
    ready: usize,
    /// Total length (prefix included) of the message being collected, once its prefix is in.
    need: Option<usize>,
    /// Whether the message being collected is small ([`SMALL_MESSAGE_BYTES`]; true until its
    /// prefix is in).
    small: bool,
    /// Bytes charged to the budgets (= `pending.len()`).
    held: usize,
    /// The message timeout, armed from the first byte of a message to its last.
    timer: Option<Pin<Box<tokio::time::Sleep>>>,
    finished: bool,
    failed: bool,
    trailers: Option<HeaderMap>,
    limit: Limit,
    /// The call's URI (its path names the method in error messages; kept as is, so a call that
    /// never fails allocates no name).
    uri: tonic::codegen::http::Uri,
    shared: Arc<Shared>,
    connection: Option<Arc<ConnectionState>>,
}

/// A method's message-size limit and the flag that sets it.
#[derive(Clone, Copy, Debug)]
struct Limit {
    bytes: usize,
    flag: &'static str,
}

impl<B> std::fmt::Debug for AdmittedBody<B> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AdmittedBody").field("uri", &self.uri).field("held", &self.held).finish_non_exhaustive()
    }
}

impl<B> AdmittedBody<B> {
    /// A body read message by message under `limit`, charging `shared`'s budget and
    /// `connection`'s.
    fn new(
        body: B,
        limit: Limit,
        uri: tonic::codegen::http::Uri,
        shared: Arc<Shared>,
        connection: Option<Arc<ConnectionState>>,
    ) -> Self {
        Self {
            inner: Box::pin(body),
            pending: BytesMut::new(),
            ready: 0,
            need: None,
            small: true,
            held: 0,
            timer: None,
            finished: false,
            failed: false,
            trailers: None,
            limit,
            uri,
            shared,
            connection,
        }
    }

    /// The method's name, for messages (clipped).
    fn method(&self) -> String {
        let path = self.uri.path();
        sublevel_core::error::clip(path.rsplit('/').next().unwrap_or(path))
    }

    /// Charges `n` more bytes to both budgets, or says which one is full.
    fn charge(&mut self, n: usize) -> Result<(), Status> {
        let s = &self.shared;
        let cap = if self.small { s.request_memory } else { s.request_memory - s.request_memory / 8 };
        let before = s.held.fetch_add(n, Ordering::Relaxed);
        if before + n > cap {
            s.held.fetch_sub(n, Ordering::Relaxed);
            metrics::counter!(crate::metrics::REQUESTS_REFUSED, "reason" => "request_memory").increment(1);
            return Err(Status::resource_exhausted(format!(
                "request memory full: `{}` needs {n} more bytes while {before} of {} are held by incomplete request \
                 messages (set by --request-memory-bytes / SUBLEVEL_REQUEST_MEMORY_BYTES); retry later",
                self.method(),
                s.request_memory
            )));
        }
        if let Some(c) = &self.connection {
            let before = c.held.fetch_add(n, Ordering::Relaxed);
            if before + n > s.connection_memory {
                c.held.fetch_sub(n, Ordering::Relaxed);
                s.held.fetch_sub(n, Ordering::Relaxed);
                metrics::counter!(crate::metrics::REQUESTS_REFUSED, "reason" => "connection_memory").increment(1);
                return Err(Status::resource_exhausted(format!(
                    "connection request memory full: `{}` needs {n} more bytes while {before} of {} are held by this \
                     connection's incomplete request messages (set by --connection-memory-bytes / \
                     SUBLEVEL_CONNECTION_MEMORY_BYTES)",
                    self.method(),
                    s.connection_memory
                )));
            }
        }
        self.held += n;
        Ok(())
    }

    /// Releases `n` charged bytes.
    fn release(&mut self, n: usize) {
        let n = n.min(self.held);
        self.held -= n;
        self.shared.held.fetch_sub(n, Ordering::Relaxed);
        if let Some(c) = &self.connection {
            c.held.fetch_sub(n, Ordering::Relaxed);
        }
    }

    /// Takes in one received chunk: charges it, appends it, and advances over every message it
    /// completes.
    fn absorb(&mut self, data: &[u8]) -> Result<(), Status> {
        if data.is_empty() {
            return Ok(());
        }
        self.charge(data.len())?;
        self.pending.extend_from_slice(data);
        loop {
            let available = self.pending.len() - self.ready;
            if available == 0 {
                return Ok(());
            }
            if self.timer.is_none() {
                self.timer = Some(Box::pin(tokio::time::sleep(self.shared.timeout)));
            }
            let need = match self.need {
                Some(n) => n,
                None if available < PREFIX => return Ok(()),
                None => {
                    let at = self.ready;
                    let len = u32::from_be_bytes([
                        self.pending[at + 1],
                        self.pending[at + 2],
                        self.pending[at + 3],
                        self.pending[at + 4],
                    ]) as usize;
                    if len > self.limit.bytes {
                        metrics::counter!(crate::metrics::REQUESTS_REFUSED, "reason" => "message_size").increment(1);
                        return Err(Status::out_of_range(format!(
                            "request message of `{}` is {len} bytes, over the limit of {} bytes (set by {})",
                            self.method(),
                            self.limit.bytes,
                            self.limit.flag
                        )));
                    }
                    self.small = len <= SMALL_MESSAGE_BYTES;
                    self.need = Some(PREFIX + len);
                    PREFIX + len
                }
            };
            if available < need {
                return Ok(());
            }
            self.ready += need;
            self.need = None;
            self.small = true;
            self.timer = None;
        }
    }

    /// Ends the body with `status` (later polls end the stream).
    fn fail(&mut self, status: Status) -> Poll<Option<Result<http_body::Frame<Bytes>, BoxError>>> {
        self.failed = true;
        let held = self.held;
        self.release(held);
        self.pending = BytesMut::new();
        Poll::Ready(Some(Err(Box::new(status))))
    }
}

impl<B> http_body::Body for AdmittedBody<B>
where
    B: http_body::Body<Data = Bytes>,
    B::Error: Into<BoxError>,
{
    type Data = Bytes;
    type Error = BoxError;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Bytes>, Self::Error>>> {
        let this = self.get_mut();
        if this.failed {
            return Poll::Ready(None);
        }
        loop {
            if this.ready > 0 {
                let out = this.pending.split_to(this.ready).freeze();
                this.ready = 0;
                this.release(out.len());
                return Poll::Ready(Some(Ok(http_body::Frame::data(out))));
            }
            if this.finished {
                // A truncated last message goes on as it is: tonic reports it.
                if !this.pending.is_empty() {
                    let out = std::mem::take(&mut this.pending).freeze();
                    this.release(out.len());
                    this.timer = None;
                    return Poll::Ready(Some(Ok(http_body::Frame::data(out))));
                }
                return Poll::Ready(this.trailers.take().map(|t| Ok(http_body::Frame::trailers(t))));
            }
            if let Some(timer) = this.timer.as_mut() {
                if timer.as_mut().poll(cx).is_ready() {
                    metrics::counter!(crate::metrics::REQUESTS_REFUSED, "reason" => "message_timeout").increment(1);
                    let status = Status::deadline_exceeded(format!(
                        "request message of `{}` did not arrive within {:?} of its first byte ({} bytes received; set \
                         by --message-timeout-ms / SUBLEVEL_MESSAGE_TIMEOUT_MS)",
                        this.method(),
                        this.shared.timeout,
                        this.pending.len()
                    ));
                    return this.fail(status);
                }
            }
            match this.inner.as_mut().poll_frame(cx) {
                Poll::Pending => return Poll::Pending,
                Poll::Ready(None) => this.finished = true,
                Poll::Ready(Some(Err(e))) => {
                    this.failed = true;
                    return Poll::Ready(Some(Err(e.into())));
                }
                Poll::Ready(Some(Ok(frame))) => match frame.into_data() {
                    Ok(data) => {
                        if let Err(status) = this.absorb(&data) {
                            return this.fail(status);
                        }
                    }
                    Err(frame) => {
                        if let Ok(trailers) = frame.into_trailers() {
                            this.trailers = Some(trailers);
                        }
                        this.finished = true;
                    }
                },
            }
        }
    }

    fn is_end_stream(&self) -> bool {
        self.failed || (self.finished && self.pending.is_empty() && self.trailers.is_none())
    }
}

impl<B> Drop for AdmittedBody<B> {
    fn drop(&mut self) {
        let held = self.held;
        self.release(held);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use http_body_util::BodyExt as _;

    fn settings(memory: usize, connection: usize) -> AdmissionSettings {
        AdmissionSettings {
            request_memory_bytes: memory,
            connection_memory_bytes: connection,
            max_request_bytes: 1000,
            message_timeout: Duration::from_millis(200),
            ..AdmissionSettings::default()
        }
    }

    /// A body of the given chunks, then an open end when `stall` (a client that stops sending).
    fn body_of(
        chunks: Vec<Vec<u8>>,
        stall: bool,
    ) -> impl http_body::Body<Data = Bytes, Error = BoxError> + Send + 'static {
        let frames = chunks.into_iter().map(|c| Ok::<_, BoxError>(http_body::Frame::data(Bytes::from(c))));
        let tail: Box<dyn futures_util::Stream<Item = Result<http_body::Frame<Bytes>, BoxError>> + Send + Unpin> =
            if stall { Box::new(futures_util::stream::pending()) } else { Box::new(futures_util::stream::empty()) };
        http_body_util::StreamBody::new(futures_util::StreamExt::chain(futures_util::stream::iter(frames), tail))
    }

    fn message(len: usize) -> Vec<u8> {
        let mut m = vec![0u8];
        m.extend_from_slice(&u32::try_from(len).unwrap().to_be_bytes());
        m.extend(std::iter::repeat_n(7u8, len));
        m
    }

    fn admitted<B>(layer: &MessageLayer, body: B, connection: Option<Arc<ConnectionState>>) -> AdmittedBody<B> {
        let limit = Limit { bytes: layer.shared.max_request, flag: "--max-request-bytes" };
        let uri = tonic::codegen::http::Uri::from_static("/sublevel.v1.Sublevel/Distance");
        AdmittedBody::new(body, limit, uri, layer.shared.clone(), connection)
    }

    /// Two messages split across chunks at every awkward place (inside the prefix, inside the
    /// bytes) come out whole and in order, byte for byte; nothing stays charged.
    #[tokio::test]
    async fn messages_are_reassembled_whole() {
        let layer = MessageLayer::new(&settings(1 << 20, 1 << 20), 1000);
        let (a, b) = (message(300), message(17));
        let all: Vec<u8> = a.iter().chain(b.iter()).copied().collect();
        let chunks = vec![all[..2].to_vec(), all[2..150].to_vec(), all[150..306].to_vec(), all[306..].to_vec()];
        let out = admitted(&layer, body_of(chunks, false), None).collect().await.unwrap().to_bytes();
        assert_eq!(out.as_ref(), all.as_slice());
        assert_eq!(layer.held_bytes(), 0);
    }

    /// A prefix claiming more than the method's limit is OUT_OF_RANGE at once, naming the flag.
    #[tokio::test]
    async fn an_oversized_length_prefix_is_out_of_range() {
        let layer = MessageLayer::new(&settings(1 << 20, 1 << 20), 1000);
        let e = admitted(&layer, body_of(vec![message(1001)[..5].to_vec()], true), None).collect().await.unwrap_err();
        let status = e.downcast::<Status>().unwrap();
        assert_eq!(status.code(), tonic::Code::OutOfRange);
        assert!(status.message().contains("1001 bytes") && status.message().contains("--max-request-bytes"));
        assert_eq!(layer.held_bytes(), 0);
    }

    /// A stalled message holds the bytes really sent (not its claimed length) while it waits,
    /// and frees them with DEADLINE_EXCEEDED at the message timeout.
    #[tokio::test]
    async fn a_stalled_message_holds_what_was_sent_until_its_timeout() {
        let layer = MessageLayer::new(&settings(1 << 20, 1 << 20), 1000);
        let chunk = message(900)[..105].to_vec();
        let mut body = admitted(&layer, body_of(vec![chunk], true), None);
        let mut body = std::pin::Pin::new(&mut body);
        let first = tokio::time::timeout(Duration::from_millis(50), body.frame()).await;
        assert!(first.is_err(), "a stalled message is not handed on");
        assert_eq!(layer.held_bytes(), 105);
        let e = body.frame().await.unwrap().unwrap_err().downcast::<Status>().unwrap();
        assert_eq!(e.code(), tonic::Code::DeadlineExceeded);
        assert!(e.message().contains("--message-timeout-ms"), "{}", e.message());
        assert_eq!(layer.held_bytes(), 0);
    }

    /// Budgets: the server budget refuses the chunk that would pass it (RESOURCE_EXHAUSTED naming
    /// the flag); a connection budget refuses a second message on the same connection while
    /// another connection still gets in; dropping a body releases its bytes.
    #[tokio::test]
    async fn budgets_refuse_what_would_pass_them_and_free_on_drop() {
        // Server budget 800, connection budget 600 (unused by bodies without a connection).
        let layer = MessageLayer::new(&settings(800, 600), 1000);
        let stalled = message(900)[..600].to_vec();
        let mut one = admitted(&layer, body_of(vec![stalled.clone()], true), None);
        let polled = tokio::time::timeout(Duration::from_millis(20), std::pin::Pin::new(&mut one).frame()).await;
        assert!(polled.is_err());
        assert_eq!(layer.held_bytes(), 600);
        let e = admitted(&layer, body_of(vec![stalled.clone()], true), None).collect().await.unwrap_err();
        let status = e.downcast::<Status>().unwrap();
        assert_eq!(status.code(), tonic::Code::ResourceExhausted);
        assert!(status.message().contains("--request-memory-bytes"), "{}", status.message());
        drop(one);
        assert_eq!(layer.held_bytes(), 0);

        let connection = Arc::new(ConnectionState::new());
        let small = message(400)[..350].to_vec();
        let mut first = admitted(&layer, body_of(vec![small.clone()], true), Some(connection.clone()));
        let polled = tokio::time::timeout(Duration::from_millis(20), std::pin::Pin::new(&mut first).frame()).await;
        assert!(polled.is_err());
        let e = admitted(&layer, body_of(vec![small.clone()], true), Some(connection.clone()))
            .collect()
            .await
            .unwrap_err()
            .downcast::<Status>()
            .unwrap();
        assert!(e.message().contains("--connection-memory-bytes"), "{}", e.message());
        let other = Arc::new(ConnectionState::new());
        let mut second = admitted(&layer, body_of(vec![small], true), Some(other.clone()));
        let polled = tokio::time::timeout(Duration::from_millis(20), std::pin::Pin::new(&mut second).frame()).await;
        assert!(polled.is_err(), "another connection's message is admitted");
        assert_eq!(layer.held_bytes(), 700);
        drop((first, second));
        assert_eq!((layer.held_bytes(), connection.held.load(Ordering::Relaxed)), (0, 0));
    }
}
