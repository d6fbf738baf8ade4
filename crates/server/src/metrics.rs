//! Observability of the service: Prometheus metrics, a `tracing` span and a request id per RPC.
//!
//! Metrics go through the [`metrics`] facade; they cost nothing until a recorder is installed,
//! which `sublevel serve --metrics-addr ADDR` does with [`install_prometheus`] (Prometheus text
//! format at `http://ADDR/metrics`). The names (all in seconds or plain counts):
//!
//! | metric | type | labels | what |
//! |---|---|---|---|
//! | `sublevel_rpc_requests_total` | counter | `method`, `code` | finished RPCs by gRPC status code (`OK`, `INVALID_ARGUMENT`, …) |
//! | `sublevel_rpc_duration_seconds` | histogram | `method` | request received → final status (for streams: the stream's life) |
//! | `sublevel_query_answers_total` | counter | `query` | distance / growth answers computed (Distance, Growth, BatchQuery pairs) |
//! | `sublevel_newton_iterations` | histogram | `query` | Newton iterations of each answer |
//! | `sublevel_query_non_converged_total` | counter | `query` | answers whose solve did not converge |
//! | `sublevel_query_sdp_fallbacks_total` | counter | `query` | answers that came from the level-0 SDP (fallback or lower bound) |
//! | `sublevel_warm_start_total` | counter | `query`, `outcome` | `hit` (warm-started from the cache) or `miss`; hit rate = hit / (hit + miss) |
//! | `sublevel_fit_queue_depth` | gauge | | fit and group jobs queued or running |
//! | `sublevel_fit_duration_seconds` | histogram | `kind`, `outcome` | fit / group job time in its slot, by `succeeded`, `failed`, `interrupted` |
//! | `sublevel_store_commit_seconds` | histogram | `operation` | one store transaction (`put_body`, `put_poses`, …) |
//! | `sublevel_connections_closed_total` | counter | `reason` | connections closed by admission: `max_connections`, `handshake_timeout` |
//! | `sublevel_requests_refused_total` | counter | `reason` | calls refused by admission: `message_size`, `request_memory`, `connection_memory`, `message_timeout` |
//!
//! [`RpcLayer`] wraps the whole router: every RPC runs in a `rpc` span with fields `method` and
//! `request_id`; the id is the request's `x-request-id` metadata when it is a short printable
//! string, else a new random one, and it comes back in the response's `x-request-id` header.
//! The status code of a normal response is read from its trailers, of a trailers-only response
//! (an error before any message) from its headers.

use crate::{Error, Result};
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use sublevel_scene::store::{QuarantinedRecord, Store};
use sublevel_scene::{BodyRecord, InstanceRecord, JobRecord, JobRecordState, RobotRecord, SceneMeta, SceneRecord};
use tonic::codegen::http::{HeaderMap, HeaderValue, Request, Response};
use tonic::codegen::{Bytes, Service};
use tracing::Instrument;

/// Counter of finished RPCs (`method`, `code`).
pub const RPC_REQUESTS: &str = "sublevel_rpc_requests_total";
/// Histogram of RPC latency in seconds (`method`).
pub const RPC_DURATION: &str = "sublevel_rpc_duration_seconds";
/// Counter of query answers (`query`).
pub const QUERY_ANSWERS: &str = "sublevel_query_answers_total";
/// Histogram of Newton iterations per answer (`query`).
pub const NEWTON_ITERATIONS: &str = "sublevel_newton_iterations";
/// Counter of answers whose solve did not converge (`query`).
pub const NON_CONVERGED: &str = "sublevel_query_non_converged_total";
/// Counter of answers from the level-0 SDP (`query`).
pub const SDP_FALLBACKS: &str = "sublevel_query_sdp_fallbacks_total";
/// Counter of warm-start cache outcomes (`query`, `outcome` = `hit` | `miss`).
pub const WARM_START: &str = "sublevel_warm_start_total";
/// Gauge of fit and group jobs queued or running.
pub const FIT_QUEUE_DEPTH: &str = "sublevel_fit_queue_depth";
/// Histogram of job durations in seconds (`kind`, `outcome`).
pub const FIT_DURATION: &str = "sublevel_fit_duration_seconds";
/// Histogram of store transaction latency in seconds (`operation`).
pub const STORE_COMMIT: &str = "sublevel_store_commit_seconds";
/// Counter of connections closed by admission (`reason`; see [`crate::admission`]).
pub const CONNECTIONS_CLOSED: &str = "sublevel_connections_closed_total";
/// Counter of calls refused by admission (`reason`; see [`crate::admission`]).
pub const REQUESTS_REFUSED: &str = "sublevel_requests_refused_total";

/// Bucket bounds of the latency histograms, in seconds (50 µs … 5 min).
const SECONDS_BUCKETS: [f64; 16] =
    [5e-5, 1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 2.5e-2, 0.1, 0.5, 1.0, 5.0, 30.0, 120.0, 300.0];
/// Bucket bounds of the Newton-iteration histogram.
const ITERATION_BUCKETS: [f64; 8] = [1.0, 2.0, 3.0, 5.0, 8.0, 13.0, 21.0, 50.0];

/// Installs the process-wide Prometheus recorder and serves its text format at
/// `http://ADDR/metrics` on `listener` (any other path answers 404), on the current tokio
/// runtime. Returns the address served.
///
/// # Errors
/// [`Error::Io`] when a recorder is already installed in this process or the listener has no
/// address.
pub fn install_prometheus(listener: tokio::net::TcpListener) -> Result<std::net::SocketAddr> {
    let bad = |e: String| Error::Io(std::io::Error::other(format!("metrics: {e}")));
    let recorder = PrometheusBuilder::new()
        .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), &SECONDS_BUCKETS)
        .and_then(|b| b.set_buckets_for_metric(Matcher::Full(NEWTON_ITERATIONS.into()), &ITERATION_BUCKETS))
        .map_err(|e| bad(e.to_string()))?
        .build_recorder();
    let handle = recorder.handle();
    metrics::set_global_recorder(recorder).map_err(|e| bad(e.to_string()))?;
    let addr = listener.local_addr()?;
    let upkeep = handle.clone();
    tokio::spawn(async move {
        // Drains the histograms' raw samples into their buckets (bounded memory between scrapes).
        let mut tick = tokio::time::interval(Duration::from_secs(5));
        loop {
            tick.tick().await;
            upkeep.run_upkeep();
        }
    });
    tokio::spawn(serve_http(listener, handle));
    tracing::info!(%addr, "serving Prometheus metrics at /metrics");
    Ok(addr)
}

/// A minimal HTTP/1 server: one `GET /metrics` per connection, then close.
async fn serve_http(listener: tokio::net::TcpListener, handle: PrometheusHandle) {
    loop {
        let socket = match listener.accept().await {
            Ok((socket, _)) => socket,
            Err(e) => {
                tracing::warn!(error = %e, "metrics: accept failed");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let handle = handle.clone();
        tokio::spawn(async move {
            if let Err(e) = tokio::time::timeout(Duration::from_secs(10), answer_http(socket, &handle)).await {
                tracing::debug!(error = %e, "metrics: slow client dropped");
            }
        });
    }
}

/// Reads one request head (at most 8 KiB) and answers it.
async fn answer_http(mut socket: tokio::net::TcpStream, handle: &PrometheusHandle) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") && head.len() < 8192 {
        match socket.read(&mut buf).await {
            Ok(0) | Err(_) => break,
            Ok(n) => head.extend_from_slice(&buf[..n]),
        }
    }
    let line = String::from_utf8_lossy(&head);
    let mut words = line.split_whitespace();
    let (status, content_type, body) = match (words.next(), words.next()) {
        (Some("GET"), Some("/metrics")) => ("200 OK", "text/plain; version=0.0.4", handle.render()),
        _ => ("404 Not Found", "text/plain", "only GET /metrics is served here\n".to_owned()),
    };
    let reply = format!(
        "HTTP/1.1 {status}\r\ncontent-type: {content_type}\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = socket.write_all(reply.as_bytes()).await;
    let _ = socket.shutdown().await;
}

/// The canonical name of a gRPC status code (`OK`, `INVALID_ARGUMENT`, …).
fn code_name(code: i32) -> &'static str {
    const NAMES: [&str; 17] = [
        "OK",
        "CANCELLED",
        "UNKNOWN",
        "INVALID_ARGUMENT",
        "DEADLINE_EXCEEDED",
        "NOT_FOUND",
        "ALREADY_EXISTS",
        "PERMISSION_DENIED",
        "RESOURCE_EXHAUSTED",
        "FAILED_PRECONDITION",
        "ABORTED",
        "OUT_OF_RANGE",
        "UNIMPLEMENTED",
        "INTERNAL",
        "UNAVAILABLE",
        "DATA_LOSS",
        "UNAUTHENTICATED",
    ];
    usize::try_from(code).ok().and_then(|k| NAMES.get(k).copied()).unwrap_or("UNKNOWN")
}

/// The `grpc-status` of a header or trailer map, when present.
fn grpc_status(headers: &HeaderMap) -> Option<i32> {
    headers.get("grpc-status").and_then(|v| v.to_str().ok()).and_then(|v| v.parse().ok())
}

/// Most bytes of a client's `x-request-id` that is kept (a longer one is replaced).
const MAX_REQUEST_ID_BYTES: usize = 128;

/// The request id: the client's `x-request-id` when it is 1–128 visible ASCII characters, else
/// 16 random hex digits.
fn request_id(headers: &HeaderMap) -> String {
    let given = headers
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .filter(|s| !s.is_empty() && s.len() <= MAX_REQUEST_ID_BYTES && s.bytes().all(|b| b.is_ascii_graphic()));
    given.map_or_else(|| format!("{:016x}", rand::random::<u64>()), str::to_owned)
}

/// An RPC whose status is not known yet: what to record when it is.
#[derive(Debug)]
struct Pending {
    method: String,
    start: Instant,
    span: tracing::Span,
}

impl Pending {
    /// Records the RPC's count, status and latency, and logs it at debug level in its span.
    fn finish(self, code: i32) {
        let elapsed = self.start.elapsed();
        let code = code_name(code);
        metrics::counter!(RPC_REQUESTS, "method" => self.method.clone(), "code" => code).increment(1);
        metrics::histogram!(RPC_DURATION, "method" => self.method).record(elapsed.as_secs_f64());
        self.span.in_scope(|| {
            // u64, not u128: tracing records u128 as a string (JSON logs would quote it).
            let elapsed_us = u64::try_from(elapsed.as_micros()).unwrap_or(u64::MAX);
            tracing::debug!(code, elapsed_us, "rpc finished");
        });
    }
}

/// The layer of metrics, spans and request ids (see the module docs).
#[derive(Clone, Copy, Debug, Default)]
pub struct RpcLayer;

impl<S> tower::Layer<S> for RpcLayer {
    type Service = RpcService<S>;
    fn layer(&self, inner: S) -> Self::Service {
        RpcService { inner }
    }
}

/// The service [`RpcLayer`] wraps around the router.
#[derive(Clone, Debug)]
pub struct RpcService<S> {
    inner: S,
}

impl<S, B, R> Service<Request<B>> for RpcService<S>
where
    S: Service<Request<B>, Response = Response<R>>,
    S::Future: Send + 'static,
    R: tonic::codegen::Body<Data = Bytes> + Send + 'static,
{
    type Response = Response<RecordedBody<R>>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = std::result::Result<Self::Response, Self::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<std::result::Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request<B>) -> Self::Future {
        let method = req.uri().path().to_owned();
        let id = request_id(req.headers());
        let span = tracing::info_span!("rpc", method = %method, request_id = %id);
        let fut = span.in_scope(|| self.inner.call(req));
        let pending = Pending { method, start: Instant::now(), span: span.clone() };
        Box::pin(
            async move {
                let response = fut.await?;
                let (mut parts, body) = response.into_parts();
                if let Ok(v) = HeaderValue::from_str(&id) {
                    parts.headers.insert("x-request-id", v);
                }
                let pending = match grpc_status(&parts.headers) {
                    // Trailers-only: the status is already known.
                    Some(code) => {
                        pending.finish(code);
                        None
                    }
                    None => Some(pending),
                };
                Ok(Response::from_parts(parts, RecordedBody { inner: Box::pin(body), pending }))
            }
            .instrument(span),
        )
    }
}

/// A response body that records its RPC when the trailers (with `grpc-status`) pass; a body
/// dropped before them (the client went away) counts as CANCELLED.
pub struct RecordedBody<B> {
    /// Boxed so that this wrapper is `Unpin` whatever `B` is.
    inner: Pin<Box<B>>,
    pending: Option<Pending>,
}

impl<B> std::fmt::Debug for RecordedBody<B> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordedBody").field("pending", &self.pending).finish_non_exhaustive()
    }
}

impl<B: tonic::codegen::Body<Data = Bytes>> tonic::codegen::Body for RecordedBody<B> {
    type Data = Bytes;
    type Error = B::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<std::result::Result<http_body::Frame<Bytes>, Self::Error>>> {
        let this = self.get_mut();
        let polled = this.inner.as_mut().poll_frame(cx);
        let code = match &polled {
            Poll::Ready(Some(Ok(frame))) => frame.trailers_ref().map(|t| grpc_status(t).unwrap_or(2)),
            Poll::Ready(Some(Err(_))) | Poll::Ready(None) => Some(2),
            Poll::Pending => None,
        };
        // Take the pending record only once the status is known.
        if let Some(p) = code.and_then(|code| this.pending.take().map(|p| (p, code))) {
            p.0.finish(p.1);
        }
        polled
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.inner.size_hint()
    }
}

impl<B> Drop for RecordedBody<B> {
    fn drop(&mut self) {
        if let Some(p) = self.pending.take() {
            p.finish(tonic::Code::Cancelled as i32);
        }
    }
}

/// Records one query answer of kind `query` (`distance`, `growth`): its Newton solve and where
/// it came from (`source` is a `pb::AnswerSource`).
pub(crate) fn query_answer(query: &'static str, solve: Option<&super::pb::SolveInfo>, source: i32) {
    use super::pb::AnswerSource;
    metrics::counter!(QUERY_ANSWERS, "query" => query).increment(1);
    if let Some(s) = solve {
        metrics::histogram!(NEWTON_ITERATIONS, "query" => query).record(f64::from(s.iterations));
        if !s.converged {
            metrics::counter!(NON_CONVERGED, "query" => query).increment(1);
        }
        let outcome = if s.warm_started { "hit" } else { "miss" };
        metrics::counter!(WARM_START, "query" => query, "outcome" => outcome).increment(1);
    }
    if source == AnswerSource::SdpFallback as i32 || source == AnswerSource::SdpLowerBound as i32 {
        metrics::counter!(SDP_FALLBACKS, "query" => query).increment(1);
    }
}

/// Records the answers of a `BatchQuery` (pairs form).
pub(crate) fn batch_answers(answers: &[super::pb::QueryAnswer]) {
    use super::pb::query_answer::Answer;
    for a in answers {
        match &a.answer {
            Some(Answer::Distance(d)) => query_answer("distance", d.solve.as_ref(), d.source),
            Some(Answer::Growth(g)) => query_answer("growth", g.solve.as_ref(), g.source),
            Some(Answer::Collide(c)) => query_answer("collide", c.solve.as_ref(), 0),
            None => {}
        }
    }
}

/// Sets the fit queue gauge to `depth` jobs.
pub(crate) fn fit_queue_depth(depth: usize) {
    metrics::gauge!(FIT_QUEUE_DEPTH).set(depth as f64);
}

/// Records a finished job of `kind` (`fit`, `group`) that ran for `elapsed` in its slot.
pub(crate) fn fit_finished(kind: &'static str, state: JobRecordState, elapsed: Duration) {
    let outcome = match state {
        JobRecordState::Succeeded => "succeeded",
        JobRecordState::Failed => "failed",
        JobRecordState::Cancelled => "cancelled",
        JobRecordState::Running | JobRecordState::Interrupted => "interrupted",
    };
    metrics::histogram!(FIT_DURATION, "kind" => kind, "outcome" => outcome).record(elapsed.as_secs_f64());
}

/// A [`Store`] that times every write transaction into [`STORE_COMMIT`] (reads pass untimed).
pub struct TimedStore {
    inner: Box<dyn Store>,
}

impl TimedStore {
    /// Wraps `inner`.
    pub fn new(inner: Box<dyn Store>) -> Self {
        Self { inner }
    }

    /// Runs one write `f` and records its latency under `operation`.
    fn timed<T>(&self, operation: &'static str, f: impl FnOnce(&dyn Store) -> Result<T>) -> Result<T> {
        let start = Instant::now();
        let out = f(self.inner.as_ref());
        metrics::histogram!(STORE_COMMIT, "operation" => operation).record(start.elapsed().as_secs_f64());
        out
    }
}

impl std::fmt::Debug for TimedStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TimedStore").finish_non_exhaustive()
    }
}

impl Store for TimedStore {
    fn put_body(&self, id: &str, record: &BodyRecord) -> Result<()> {
        self.timed("put_body", |s| s.put_body(id, record))
    }
    fn get_body(&self, id: &str) -> Result<Option<BodyRecord>> {
        self.inner.get_body(id)
    }
    fn list_bodies(&self) -> Result<Vec<(String, BodyRecord)>> {
        self.inner.list_bodies()
    }
    fn delete_body(&self, id: &str) -> Result<bool> {
        self.timed("delete_body", |s| s.delete_body(id))
    }
    fn put_robot(&self, id: &str, record: &RobotRecord) -> Result<()> {
        self.timed("put_robot", |s| s.put_robot(id, record))
    }
    fn list_robots(&self) -> Result<Vec<(String, RobotRecord)>> {
        self.inner.list_robots()
    }
    fn delete_robot(&self, id: &str) -> Result<bool> {
        self.timed("delete_robot", |s| s.delete_robot(id))
    }
    fn put_scene(&self, id: &str, meta: &SceneMeta) -> Result<()> {
        self.timed("put_scene", |s| s.put_scene(id, meta))
    }
    fn get_scene(&self, id: &str) -> Result<Option<SceneRecord>> {
        self.inner.get_scene(id)
    }
    fn list_scenes(&self) -> Result<Vec<(String, SceneRecord)>> {
        self.inner.list_scenes()
    }
    fn delete_scene(&self, id: &str) -> Result<bool> {
        self.timed("delete_scene", |s| s.delete_scene(id))
    }
    fn put_instances(&self, scene_id: &str, instances: &[(&str, &InstanceRecord)], frequent: bool) -> Result<()> {
        let operation = if frequent { "put_poses" } else { "put_instances" };
        self.timed(operation, |s| s.put_instances(scene_id, instances, frequent))
    }
    fn delete_instance(&self, scene_id: &str, instance_id: &str) -> Result<bool> {
        self.timed("delete_instance", |s| s.delete_instance(scene_id, instance_id))
    }
    fn put_job(&self, id: &str, record: &JobRecord) -> Result<()> {
        self.timed("put_job", |s| s.put_job(id, record))
    }
    fn list_jobs(&self) -> Result<Vec<(String, JobRecord)>> {
        self.inner.list_jobs()
    }
    fn delete_jobs(&self, ids: &[&str]) -> Result<()> {
        self.timed("delete_jobs", |s| s.delete_jobs(ids))
    }
    fn quarantine(&self, table: &str, key: &str, reason: &str) -> Result<()> {
        self.timed("quarantine", |s| s.quarantine(table, key, reason))
    }
    fn shared(&self) -> bool {
        self.inner.shared()
    }
    fn quarantined(&self) -> Result<Vec<QuarantinedRecord>> {
        self.inner.quarantined()
    }
    fn replace_instances(&self, scene_id: &str, remove: &[&str], add: &[(&str, &InstanceRecord)]) -> Result<()> {
        self.timed("replace_instances", |s| s.replace_instances(scene_id, remove, add))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_ids_are_kept_when_sane_and_made_otherwise() {
        let mut h = HeaderMap::new();
        h.insert("x-request-id", HeaderValue::from_static("abc-123"));
        assert_eq!(request_id(&h), "abc-123");
        h.insert("x-request-id", HeaderValue::from_static("has space"));
        let made = request_id(&h);
        assert_eq!(made.len(), 16);
        assert!(made.bytes().all(|b| b.is_ascii_hexdigit()), "{made}");
        assert_eq!(request_id(&HeaderMap::new()).len(), 16);
        assert_eq!(
            (code_name(0), code_name(8), code_name(16), code_name(99)),
            ("OK", "RESOURCE_EXHAUSTED", "UNAUTHENTICATED", "UNKNOWN")
        );
    }
}
