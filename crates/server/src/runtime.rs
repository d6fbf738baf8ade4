//! Blocking work off the async workers: tokio's blocking pool, optionally inside a cancellation
//! scope that the caller's future cancels when it is dropped.
//!
//! Store writes (an fsync'd redb transaction), mesh parsing, sos-convexity certificates and query
//! SDPs take milliseconds to seconds: they never run on an async worker, which would hold up every
//! other connection it serves. The handlers, the jobs and the SDP slots ([`crate::limits`]) all
//! hand such work to the two functions here.

use crate::convert::to_status;
use crate::Result;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use tonic::Status;

/// Runs blocking work (an fsync'd store write, mesh parsing, an SDP) on tokio's blocking pool.
///
/// # Errors
/// `f`'s error as a status; INTERNAL when the worker panicked.
pub(crate) async fn blocking<T: Send + 'static>(f: impl FnOnce() -> Result<T> + Send + 'static) -> Result<T, Status> {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => r.map_err(to_status),
        Err(e) => Err(Status::internal(format!("worker failed: {e}"))),
    }
}

/// Sets its flag when dropped (the future awaiting the work went away), unless disarmed.
struct CancelOnDrop(Option<Arc<AtomicBool>>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        if let Some(flag) = self.0.take() {
            flag.store(true, Ordering::Relaxed);
        }
    }
}

/// Runs `f` on tokio's blocking pool inside a [`sublevel_core::cancel::cancellable`] scope that is
/// cancelled when the returned future is dropped before `f` returned (the request's deadline
/// passed, the client went away): Clarabel solves inside stop at their next iteration and batches
/// before their next pair (see [`crate::deadline`]).
///
/// # Errors
/// `f`'s error as a status; INTERNAL when the worker panicked.
pub(crate) async fn cancellable_blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T> + Send + 'static,
) -> Result<T, Status> {
    let flag = Arc::new(AtomicBool::new(false));
    let mut guard = CancelOnDrop(Some(flag.clone()));
    let out = blocking(move || sublevel_core::cancel::cancellable(flag, f)).await;
    guard.0 = None;
    out
}

/// Aborts its timer task when dropped.
struct AbortOnDrop(Option<tokio::task::JoinHandle<()>>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        if let Some(task) = self.0.take() {
            task.abort();
        }
    }
}

/// [`cancellable_blocking`] whose scope is also cancelled at `deadline` (when given): work that
/// would land after the caller's deadline (a cloud stored, answered DEADLINE_EXCEEDED all the
/// same) sees its flag set first and stops. The caller tells a deadline from a client gone by
/// the clock ([`past`]).
///
/// # Errors
/// `f`'s error as a status; INTERNAL when the worker panicked.
pub(crate) async fn cancellable_blocking_until<T: Send + 'static>(
    deadline: Option<std::time::Instant>,
    f: impl FnOnce() -> Result<T> + Send + 'static,
) -> Result<T, Status> {
    let flag = Arc::new(AtomicBool::new(false));
    let _timer = AbortOnDrop(deadline.map(|at| {
        let flag = flag.clone();
        tokio::spawn(async move {
            tokio::time::sleep_until(at.into()).await;
            flag.store(true, Ordering::Relaxed);
        })
    }));
    let mut guard = CancelOnDrop(Some(flag.clone()));
    let out = blocking(move || sublevel_core::cancel::cancellable(flag, f)).await;
    guard.0 = None;
    out
}

/// Whether `deadline` (when given) has passed.
pub(crate) fn past(deadline: Option<std::time::Instant>) -> bool {
    deadline.is_some_and(|d| std::time::Instant::now() >= d)
}
