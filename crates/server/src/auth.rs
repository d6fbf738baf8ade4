//! Bearer-token authentication with two roles, as a tower layer in front of every service.
//!
//! The token file (`serve --auth-tokens FILE`) holds one token per line with its role; `#`
//! starts a comment, blank lines are ignored:
//!
//! ```text
//! # role  token (at least 16 characters, no spaces)
//! admin   3f1c0b7e9a5d4c2b8e6f0a1d2c3b4a59
//! read    9e8d7c6b5a4f3e2d1c0b9a8f7e6d5c4b
//! ```
//!
//! Clients send `authorization: Bearer <token>` metadata. Each `sublevel.v1.Sublevel` method is
//! a read or a write ([`method_role`]):
//!
//! | method | role needed |
//! |---|---|
//! | Get*, List*, WatchFitJob, Distance, Growth, BatchQuery, Query, QueryStream, CheckScene | read (or admin) |
//! | every other method: uploads, deletes, scene and instance changes, SetPoses, point clouds (UpdatePointCloud, RemovePointCloud), StartFitJob, StartGroupJob, CancelFitJob | admin |
//! | `grpc.health.v1.Health/*`, `grpc.reflection.*` | none (probes and tooling stay open) |
//!
//! No or an unknown token: UNAUTHENTICATED; a read token on a write: PERMISSION_DENIED. A method
//! not in the read list needs admin, so an RPC added later is admin-only until it is listed.
//! Tokens are compared in constant time. Without `--auth-tokens` the layer lets every request
//! through (the default: no authentication).

use crate::{Error, Result};
use std::future::Future;
use std::path::Path;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use tonic::codegen::http::{Request, Response};
use tonic::codegen::Service;
use tonic::Status;

/// What a token may do.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Role {
    /// Reads and queries.
    Read,
    /// Everything: reads, queries, writes and deletes.
    Admin,
}

/// Shortest token accepted in a token file (a guessable token is worse than none: it looks safe).
pub const MIN_TOKEN_CHARS: usize = 16;

/// The tokens of a token file with their roles.
#[derive(Clone)]
pub struct AuthTokens {
    tokens: Vec<(Vec<u8>, Role)>,
}

impl std::fmt::Debug for AuthTokens {
    /// Never prints a token.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let admins = self.tokens.iter().filter(|(_, r)| *r == Role::Admin).count();
        f.debug_struct("AuthTokens").field("admin", &admins).field("read", &(self.tokens.len() - admins)).finish()
    }
}

impl AuthTokens {
    /// Parses a token file's text (see the module docs); `origin` names it in errors.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `origin:line` for an unknown role, a missing or short
    /// token, extra words or a token listed twice; also when the file holds no token.
    pub fn parse(text: &str, origin: &str) -> Result<Self> {
        let mut tokens: Vec<(Vec<u8>, Role)> = Vec::new();
        for (k, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let at = format!("{origin}:{}", k + 1);
            let mut words = line.split_whitespace();
            let role = match words.next() {
                Some("admin") => Role::Admin,
                Some("read") => Role::Read,
                Some(other) => return Err(Error::invalid(at, format!("unknown role {other:?} (admin or read)"))),
                None => continue,
            };
            let Some(token) = words.next() else {
                return Err(Error::invalid(at, "a token must follow the role"));
            };
            if words.next().is_some() {
                return Err(Error::invalid(at, "expected `ROLE TOKEN` (a token has no spaces)"));
            }
            if token.chars().count() < MIN_TOKEN_CHARS {
                return Err(Error::invalid(at, format!("a token needs at least {MIN_TOKEN_CHARS} characters")));
            }
            if tokens.iter().any(|(t, _)| t == token.as_bytes()) {
                return Err(Error::invalid(at, "this token is listed twice"));
            }
            tokens.push((token.as_bytes().to_vec(), role));
        }
        if tokens.is_empty() {
            return Err(Error::invalid(origin, "the token file holds no token"));
        }
        Ok(Self { tokens })
    }

    /// Reads and parses a token file.
    ///
    /// # Errors
    /// [`Error::Io`] when it cannot be read; those of [`AuthTokens::parse`].
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::Io(std::io::Error::new(e.kind(), format!("{}: {e}", path.display()))))?;
        Self::parse(&text, &path.display().to_string())
    }

    /// The role of `token`, if it is listed (every entry is compared, in constant time each).
    pub fn role(&self, token: &[u8]) -> Option<Role> {
        let mut found = None;
        for (t, role) in &self.tokens {
            if constant_time_eq(t, token) {
                found = Some(*role);
            }
        }
        found
    }
}

/// Equality of two byte strings whose time depends only on their lengths.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The methods of `sublevel.v1.Sublevel` that a read token may call.
const READ_METHODS: &[&str] = &[
    "WatchFitJob",
    "GetFitJob",
    "ListFitJobs",
    "GetBody",
    "ListBodies",
    "GetScene",
    "ListScenes",
    "Distance",
    "Growth",
    "BatchQuery",
    "Query",
    "QueryStream",
    "CheckScene",
    "GetRobot",
    "ListRobots",
    "CheckConfigurations",
    "CheckMotions",
    "CheckInstanceMotions",
];

/// The role a request path needs: None for health and reflection (always open), Read for the
/// methods in the read list, Admin for everything else.
pub fn method_role(path: &str) -> Option<Role> {
    if path.starts_with("/grpc.health.v1.Health/") || path.starts_with("/grpc.reflection.") {
        return None;
    }
    match path.strip_prefix("/sublevel.v1.Sublevel/") {
        Some(method) if READ_METHODS.contains(&method) => Some(Role::Read),
        _ => Some(Role::Admin),
    }
}

/// Decides a request: Ok when `authorization` carries a token whose role covers `path`.
///
/// # Errors
/// UNAUTHENTICATED without a valid bearer token; PERMISSION_DENIED for a read token on a write.
pub fn authorize(tokens: &AuthTokens, path: &str, authorization: Option<&[u8]>) -> Result<(), Status> {
    let Some(needed) = method_role(path) else {
        return Ok(());
    };
    let token = authorization.and_then(|v| v.strip_prefix(b"Bearer ")).map(<[u8]>::trim_ascii);
    let Some(token) = token.filter(|t| !t.is_empty()) else {
        return Err(Status::unauthenticated("missing `authorization: Bearer <token>` metadata"));
    };
    match tokens.role(token) {
        None => Err(Status::unauthenticated("unknown bearer token")),
        Some(role) if role >= needed => Ok(()),
        Some(_) => {
            let method = path.rsplit('/').next().unwrap_or(path);
            Err(Status::permission_denied(format!("`{method}` changes the store: it needs an admin token")))
        }
    }
}

/// The [`tower::Layer`] that checks tokens (see the module docs); `None` lets everything through.
#[derive(Clone, Debug, Default)]
pub struct AuthLayer {
    tokens: Option<Arc<AuthTokens>>,
}

impl AuthLayer {
    /// A layer checking `tokens`, or letting every request through when `None`.
    pub fn new(tokens: Option<Arc<AuthTokens>>) -> Self {
        Self { tokens }
    }
}

impl<S> tower::Layer<S> for AuthLayer {
    type Service = AuthService<S>;
    fn layer(&self, inner: S) -> Self::Service {
        AuthService { inner, tokens: self.tokens.clone() }
    }
}

/// The service [`AuthLayer`] wraps around the router.
#[derive(Clone, Debug)]
pub struct AuthService<S> {
    inner: S,
    tokens: Option<Arc<AuthTokens>>,
}

impl<S, B, R> Service<Request<B>> for AuthService<S>
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

    fn call(&mut self, req: Request<B>) -> Self::Future {
        if let Some(tokens) = &self.tokens {
            let header = req.headers().get("authorization").map(|v| v.as_bytes());
            if let Err(status) = authorize(tokens, req.uri().path(), header) {
                tracing::info!(path = req.uri().path(), code = ?status.code(), "request refused");
                return Box::pin(std::future::ready(Ok(status.into_http())));
            }
        }
        Box::pin(self.inner.call(req))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::Code;

    const ADMIN: &str = "admin-0123456789abcdef";
    const READ: &str = "read-0123456789abcdef";

    fn tokens() -> AuthTokens {
        AuthTokens::parse(&format!("# roles\nadmin {ADMIN}\n\n  read\t{READ}  # a reader\n"), "tokens").unwrap()
    }

    #[test]
    fn token_files_parse_and_bad_lines_are_named() {
        let t = tokens();
        assert_eq!(t.role(ADMIN.as_bytes()), Some(Role::Admin));
        assert_eq!(t.role(READ.as_bytes()), Some(Role::Read));
        assert_eq!(t.role(b"admin-0123456789abcdeX"), None);
        assert_eq!(format!("{t:?}"), "AuthTokens { admin: 1, read: 1 }");
        for (text, needle) in [
            ("root 0123456789abcdef0", "tokens:1"),
            ("admin", "must follow"),
            ("read short", "16 characters"),
            ("read 0123456789abcdef0 extra", "no spaces"),
            ("read 0123456789abcdef0\nadmin 0123456789abcdef0", "tokens:2"),
            ("# nothing\n", "no token"),
        ] {
            let e = AuthTokens::parse(text, "tokens").expect_err(text).to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn methods_map_to_roles() {
        assert_eq!(method_role("/grpc.health.v1.Health/Check"), None);
        assert_eq!(method_role("/grpc.reflection.v1.ServerReflection/ServerReflectionInfo"), None);
        for read in [
            "Distance",
            "QueryStream",
            "ListBodies",
            "GetFitJob",
            "WatchFitJob",
            "CheckScene",
            "GetRobot",
            "ListRobots",
            "CheckConfigurations",
            "CheckMotions",
            "CheckInstanceMotions",
        ] {
            assert_eq!(method_role(&format!("/sublevel.v1.Sublevel/{read}")), Some(Role::Read), "{read}");
        }
        for write in [
            "UploadBody",
            "DeleteBody",
            "CreateScene",
            "DeleteScene",
            "AddInstance",
            "SetPoses",
            "RemoveInstance",
            "StartFitJob",
            "StartGroupJob",
            "CancelFitJob",
            "StartRobotFitJob",
            "UploadRobot",
            "DeleteRobot",
            "SetSceneRobot",
            "SetJointPositions",
            "AttachObject",
            "DetachObject",
            "ClearSceneRobot",
            "UpdatePointCloud",
            "RemovePointCloud",
            "SomethingNew",
        ] {
            assert_eq!(method_role(&format!("/sublevel.v1.Sublevel/{write}")), Some(Role::Admin), "{write}");
        }
    }

    #[test]
    fn requests_are_authorized_by_role() {
        let t = tokens();
        let bearer = |s: &str| format!("Bearer {s}").into_bytes();
        let write = "/sublevel.v1.Sublevel/DeleteScene";
        let read = "/sublevel.v1.Sublevel/Distance";
        assert!(authorize(&t, "/grpc.health.v1.Health/Check", None).is_ok());
        assert_eq!(authorize(&t, read, None).unwrap_err().code(), Code::Unauthenticated);
        assert_eq!(authorize(&t, read, Some(b"Bearer ")).unwrap_err().code(), Code::Unauthenticated);
        assert_eq!(authorize(&t, read, Some(ADMIN.as_bytes())).unwrap_err().code(), Code::Unauthenticated);
        assert_eq!(
            authorize(&t, read, Some(&bearer("nope-0123456789abcdef"))).unwrap_err().code(),
            Code::Unauthenticated
        );
        assert!(authorize(&t, read, Some(&bearer(READ))).is_ok());
        assert!(authorize(&t, read, Some(&bearer(ADMIN))).is_ok());
        let denied = authorize(&t, write, Some(&bearer(READ))).unwrap_err();
        assert_eq!(denied.code(), Code::PermissionDenied);
        assert!(denied.message().contains("DeleteScene"), "{}", denied.message());
        assert!(authorize(&t, write, Some(&bearer(ADMIN))).is_ok());
    }
}
