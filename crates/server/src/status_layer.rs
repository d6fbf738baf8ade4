//! A tower layer that gives the two statuses tonic produces before a handler runs the meaning a
//! client expects:
//!
//! | tonic says | the client gets |
//! |---|---|
//! | INTERNAL "failed to decode Protobuf message: …" (bytes that are not the request message) | INVALID_ARGUMENT "request: cannot decode the `…` protobuf message: …" |
//! | UNIMPLEMENTED with an empty message (a method no service here has) | UNIMPLEMENTED "unknown method `/pkg.Service/Method`; this server implements …" |
//!
//! Both come back as *trailers-only* responses (status in the HTTP headers), which is all this
//! layer looks at; handler statuses pass through unchanged.

use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};
use tonic::codegen::http::{HeaderMap, HeaderValue, Request, Response};
use tonic::codegen::Service;
use tonic::Code;

/// The services this server implements, for the UNIMPLEMENTED message.
const SERVICES: &str = "sublevel.v1.Sublevel, grpc.health.v1.Health, grpc.reflection.v1.ServerReflection and \
                        grpc.reflection.v1alpha.ServerReflection";

/// The [`tower::Layer`]-shaped wrapper (see the module docs).
#[derive(Clone, Copy, Debug, Default)]
pub struct StatusLayer;

impl<S> tower::Layer<S> for StatusLayer {
    type Service = StatusService<S>;
    fn layer(&self, inner: S) -> Self::Service {
        StatusService { inner }
    }
}

/// The service [`StatusLayer`] wraps around the router.
#[derive(Clone, Debug)]
pub struct StatusService<S> {
    inner: S,
}

/// Percent-encodes a grpc-message value (the gRPC spec's encoding: printable ASCII except `%`
/// stays; everything else becomes `%XX` of its UTF-8 bytes).
fn encode_message(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for b in text.bytes() {
        if (0x20..=0x7e).contains(&b) && b != b'%' {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// Decodes a percent-encoded grpc-message value (lossy on invalid UTF-8).
fn decode_message(raw: &[u8]) -> String {
    let mut bytes = Vec::with_capacity(raw.len());
    let mut i = 0;
    while i < raw.len() {
        if raw[i] == b'%' && i + 2 < raw.len() {
            if let Ok(v) = u8::from_str_radix(std::str::from_utf8(&raw[i + 1..i + 3]).unwrap_or("zz"), 16) {
                bytes.push(v);
                i += 3;
                continue;
            }
        }
        bytes.push(raw[i]);
        i += 1;
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// Rewrites the status headers of a trailers-only response, as described in the module docs.
pub fn rewrite_status(headers: &mut HeaderMap, path: &str) {
    let Some(code) = headers.get("grpc-status").and_then(|v| v.to_str().ok()).and_then(|v| v.parse::<i32>().ok())
    else {
        return;
    };
    let message = headers.get("grpc-message").map(|v| decode_message(v.as_bytes())).unwrap_or_default();
    let method = path.rsplit('/').next().unwrap_or(path);
    let (new_code, new_message) = if code == Code::Internal as i32 && message.starts_with("failed to decode") {
        (Code::InvalidArgument, format!("request: cannot decode the protobuf message of `{method}`: {message}"))
    } else if code == Code::Unimplemented as i32 && message.is_empty() {
        let shown = sublevel_core::error::clip(path);
        (Code::Unimplemented, format!("unknown method `{shown}`; this server implements {SERVICES}"))
    } else {
        return;
    };
    headers.insert("grpc-status", HeaderValue::from(new_code as i32));
    if let Ok(v) = HeaderValue::from_str(&encode_message(&new_message)) {
        headers.insert("grpc-message", v);
    }
}

impl<S, B, R> Service<Request<B>> for StatusService<S>
where
    S: Service<Request<B>, Response = Response<R>>,
    S::Future: Send + 'static,
{
    type Response = Response<R>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Self::Response, Self::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request<B>) -> Self::Future {
        let path = req.uri().path().to_owned();
        let fut = self.inner.call(req);
        Box::pin(async move {
            let mut response = fut.await?;
            rewrite_status(response.headers_mut(), &path);
            Ok(response)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decode_errors_become_invalid_argument_and_unknown_methods_get_a_message() {
        let mut h = HeaderMap::new();
        h.insert("grpc-status", HeaderValue::from(13));
        h.insert("grpc-message", HeaderValue::from_static("failed to decode Protobuf message: buffer underflow"));
        rewrite_status(&mut h, "/sublevel.v1.Sublevel/Distance");
        assert_eq!(h["grpc-status"], "3");
        let m = decode_message(h["grpc-message"].as_bytes());
        assert!(m.contains("`Distance`") && m.contains("buffer underflow"), "{m}");

        let mut h = HeaderMap::new();
        h.insert("grpc-status", HeaderValue::from(12));
        rewrite_status(&mut h, "/nope.Service/Do");
        assert_eq!(h["grpc-status"], "12");
        let m = decode_message(h["grpc-message"].as_bytes());
        assert!(m.contains("/nope.Service/Do") && m.contains("sublevel.v1.Sublevel"), "{m}");

        // Handler statuses pass unchanged.
        let mut h = HeaderMap::new();
        h.insert("grpc-status", HeaderValue::from(13));
        h.insert("grpc-message", HeaderValue::from_static("numerical failure: x"));
        rewrite_status(&mut h, "/sublevel.v1.Sublevel/Distance");
        assert_eq!(h["grpc-status"], "13");
        assert_eq!(encode_message("a%b é"), "a%25b %C3%A9");
        assert_eq!(decode_message(b"a%25b %C3%A9"), "a%b é");
    }
}
