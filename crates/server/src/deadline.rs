//! Request deadlines: the client's `grpc-timeout` and the operator's `--max-request-ms`, answered
//! with DEADLINE_EXCEEDED, and the blocking work of an expired request cancelled.
//!
//! ```text
//! client    grpc-timeout: 50m  (tonic: Request::set_timeout; grpcio: timeout=…)
//! layer     deadline = min(grpc-timeout, --max-request-ms) − DEADLINE_MARGIN after arrival
//! expiry    the handler's future is dropped; the client gets DEADLINE_EXCEEDED naming the limit
//! drop      the blocking query work it awaited (Slots::run) sees its cancel flag set:
//!           a running Clarabel solve stops at its next interior-point iteration (termination
//!           callback, sublevel_core::cancel), a batch stops before its next pair; the SDP slot is
//!           free again within one iteration
//! ```
//!
//! tonic's server applies `grpc-timeout` itself too, outside every layer, and answers CANCELLED
//! (its `TimeoutExpired`); this layer fires [`DEADLINE_MARGIN`] earlier so the client sees the
//! code the gRPC specification asks for. Writes that already started (an fsync'd store
//! transaction) are not interrupted: they complete, as gRPC allows for a deadline.
//!
//! Streams (QueryStream, WatchFitJob): the deadline covers the call up to its response headers;
//! a stream's messages are not cut.
//!
//! The layer also puts the moment it will answer DEADLINE_EXCEEDED in the request's extensions
//! ([`CallDeadline`]), so a handler whose work would land after it (`UpdatePointCloud` storing a
//! cloud) can stop that work first and store nothing.

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;
use tonic::codegen::http::{HeaderMap, Request, Response};
use tonic::codegen::Service;
use tonic::Status;

/// How much earlier than the request's own deadline this layer answers DEADLINE_EXCEEDED (so
/// tonic's timer, which answers CANCELLED at the deadline itself, never wins: tokio's timer has a
/// resolution of 1 ms).
pub const DEADLINE_MARGIN: Duration = Duration::from_millis(2);

/// The moment the deadline layer answers a call DEADLINE_EXCEEDED (its deadline less
/// [`DEADLINE_MARGIN`]), in the call's request extensions (`tonic::Request::extensions`); absent
/// when the call has no deadline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CallDeadline(pub std::time::Instant);

/// Parses a `grpc-timeout` header value (gRPC over HTTP/2: at most 8 digits and a unit `H`, `M`,
/// `S`, `m`, `u` or `n`). `None` for a missing or malformed value (then the request has no client
/// deadline, as tonic does).
pub fn parse_grpc_timeout(headers: &HeaderMap) -> Option<Duration> {
    let text = headers.get("grpc-timeout")?.to_str().ok()?;
    if text.len() < 2 || text.len() > 9 {
        return None;
    }
    let (digits, unit) = text.split_at(text.len() - 1);
    let n: u64 = digits.parse().ok()?;
    Some(match unit {
        "H" => Duration::from_secs(n.checked_mul(3600)?),
        "M" => Duration::from_secs(n.checked_mul(60)?),
        "S" => Duration::from_secs(n),
        "m" => Duration::from_millis(n),
        "u" => Duration::from_micros(n),
        "n" => Duration::from_nanos(n),
        _ => return None,
    })
}

/// The tower layer of the module docs; `cap` is `--max-request-ms` (`None`: only the client's
/// deadline applies).
#[derive(Clone, Copy, Debug, Default)]
pub struct DeadlineLayer {
    cap: Option<Duration>,
}

impl DeadlineLayer {
    /// A layer with the operator's cap on every `sublevel.v1` call (`None` for no cap).
    pub fn new(cap: Option<Duration>) -> Self {
        Self { cap }
    }
}

impl<S> tower::Layer<S> for DeadlineLayer {
    type Service = DeadlineService<S>;
    fn layer(&self, inner: S) -> Self::Service {
        DeadlineService { inner, cap: self.cap }
    }
}

/// The service [`DeadlineLayer`] wraps around the router.
#[derive(Clone, Debug)]
pub struct DeadlineService<S> {
    inner: S,
    cap: Option<Duration>,
}

/// The deadline of a request to `path` with `headers` under `cap`, and what set it (for the
/// message). Only `sublevel.v1` calls get one (health and reflection answer at once).
fn request_deadline(path: &str, headers: &HeaderMap, cap: Option<Duration>) -> Option<(Duration, &'static str)> {
    if !path.starts_with("/sublevel.v1.") {
        return None;
    }
    match (parse_grpc_timeout(headers), cap) {
        (Some(c), Some(s)) if s < c => Some((s, "the server's --max-request-ms")),
        (Some(c), _) => Some((c, "the client's deadline (grpc-timeout)")),
        (None, Some(s)) => Some((s, "the server's --max-request-ms")),
        (None, None) => None,
    }
}

impl<S, B, R> Service<Request<B>> for DeadlineService<S>
where
    S: Service<Request<B>, Response = Response<R>>,
    S::Future: Send + 'static,
    R: Default + Send + 'static,
    S::Error: Send + 'static,
{
    type Response = Response<R>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Self::Response, Self::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, mut req: Request<B>) -> Self::Future {
        let Some((limit, source)) = request_deadline(req.uri().path(), req.headers(), self.cap) else {
            return Box::pin(self.inner.call(req));
        };
        let path = req.uri().path().to_owned();
        let wait = limit.saturating_sub(DEADLINE_MARGIN);
        req.extensions_mut().insert(CallDeadline(std::time::Instant::now() + wait));
        let fut = self.inner.call(req);
        Box::pin(async move {
            match tokio::time::timeout(wait, fut).await {
                Ok(out) => out,
                Err(_) => {
                    let method = path.rsplit('/').next().unwrap_or("").to_owned();
                    tracing::info!(%method, ?limit, "deadline exceeded; the request's work is cancelled");
                    let ms = limit.as_secs_f64() * 1e3;
                    Ok(Status::deadline_exceeded(format!("{method}: {source} of {ms:.0} ms passed")).into_http())
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::codegen::http::HeaderValue;

    fn headers(timeout: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert("grpc-timeout", HeaderValue::from_str(timeout).unwrap());
        h
    }

    #[test]
    fn grpc_timeouts_parse_in_every_unit() {
        assert_eq!(parse_grpc_timeout(&headers("50m")), Some(Duration::from_millis(50)));
        assert_eq!(parse_grpc_timeout(&headers("2S")), Some(Duration::from_secs(2)));
        assert_eq!(parse_grpc_timeout(&headers("1H")), Some(Duration::from_secs(3600)));
        assert_eq!(parse_grpc_timeout(&headers("3M")), Some(Duration::from_secs(180)));
        assert_eq!(parse_grpc_timeout(&headers("7u")), Some(Duration::from_micros(7)));
        assert_eq!(parse_grpc_timeout(&headers("9n")), Some(Duration::from_nanos(9)));
        for bad in ["", "m", "5x", "123456789m", "-5m"] {
            assert_eq!(parse_grpc_timeout(&headers(bad)), None, "{bad:?}");
        }
        assert_eq!(parse_grpc_timeout(&HeaderMap::new()), None);
    }

    #[test]
    fn the_shorter_of_client_deadline_and_server_cap_applies_to_sublevel_calls_only() {
        let p = "/sublevel.v1.Sublevel/BatchQuery";
        let cap = Some(Duration::from_secs(1));
        assert_eq!(request_deadline(p, &headers("50m"), cap).unwrap().0, Duration::from_millis(50));
        let (d, source) = request_deadline(p, &headers("5S"), cap).unwrap();
        assert_eq!(d, Duration::from_secs(1));
        assert!(source.contains("--max-request-ms"));
        assert_eq!(request_deadline(p, &HeaderMap::new(), cap).unwrap().0, Duration::from_secs(1));
        assert!(request_deadline(p, &HeaderMap::new(), None).is_none());
        assert!(request_deadline("/grpc.health.v1.Health/Check", &headers("50m"), cap).is_none());
    }
}
