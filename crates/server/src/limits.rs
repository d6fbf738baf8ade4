//! The operator's limits on what the server holds and runs (see [`super::ServerConfig`] and the
//! "Configuration" table of docs/operations.md, which `sublevel serve --print-config-table`
//! generates).
//!
//! Count limits (scenes, bodies, instances per scene, queued fit jobs) are checked before the
//! write that would exceed them and answer RESOURCE_EXHAUSTED naming the limit, its flag and its
//! environment variable. The check reads the catalog and the write follows, so concurrent
//! creations may overshoot a limit by at most the number of calls in flight — a soft limit that
//! protects memory and disk, not an invariant.
//!
//! Blocking query work runs in one of two [`Slots`] pools ([`QueryPools`]), each a semaphore in
//! front of tokio's blocking pool; a request waits for a slot asynchronously, holding no thread:
//!
//! - **batch** ([`super::ServerConfig::batch_workers`], default the CPUs): Newton-only work too
//!   large for an async worker — big batches, planner requests, compound scenes, CheckScene;
//! - **SDP** ([`super::ServerConfig::max_concurrent_sdp`], default half the CPUs, at least 2):
//!   certificates, nonconvex scenes, and the rare answer Newton could not settle;
//! - **plans** ([`super::ServerConfig::max_concurrent_plans`], default half the CPUs, at least
//!   1): `Plan` calls, each holding its slot for up to its whole timeout.
//!
//! Separate pools so that large batches (microseconds per pair, all cores' worth of them) never
//! wait behind seconds-long SDP solves or plans, and a burst of `certify` or `Plan` calls cannot
//! take every thread: however many plans clients send, the batch slots stay free for the checks,
//! and the plans queue among themselves (a plan's timeout counts its wait, [`Slots::run_before`]).

use crate::runtime::cancellable_blocking;
use crate::{Error, Result};
use std::sync::Arc;
use tokio::sync::Semaphore;
use tonic::Status;

/// One named count limit: what is counted, its `serve` flag and environment variable.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limit {
    /// What is counted, e.g. `scenes` (plural, for the message).
    pub(crate) what: &'static str,
    /// The `sublevel serve` flag that sets it, e.g. `--max-scenes`.
    pub(crate) flag: &'static str,
    /// Its environment variable, e.g. `SUBLEVEL_MAX_SCENES`.
    pub(crate) env: &'static str,
}

/// `--max-scenes`.
pub(crate) const SCENES: Limit = Limit { what: "scenes", flag: "--max-scenes", env: "SUBLEVEL_MAX_SCENES" };
/// `--max-bodies`.
pub(crate) const BODIES: Limit = Limit { what: "bodies", flag: "--max-bodies", env: "SUBLEVEL_MAX_BODIES" };
/// `--max-instances-per-scene`.
pub(crate) const INSTANCES: Limit = Limit {
    what: "instances in the scene",
    flag: "--max-instances-per-scene",
    env: "SUBLEVEL_MAX_INSTANCES_PER_SCENE",
};
/// `--max-cloud-bytes`: bytes of point clouds, all scenes together (checked by the catalog under
/// the scene's lock, so it holds exactly, not softly).
pub(crate) const CLOUD_BYTES: Limit =
    Limit { what: "bytes of point clouds", flag: "--max-cloud-bytes", env: "SUBLEVEL_MAX_CLOUD_BYTES" };
/// `--max-frame-points`: points of one sensor frame (a depth image's pixels, a PointCloud2's
/// records), checked before the frame is decoded.
pub(crate) const FRAME_POINTS: Limit =
    Limit { what: "points of a frame", flag: "--max-frame-points", env: "SUBLEVEL_MAX_FRAME_POINTS" };
/// `--max-fit-queue`.
pub(crate) const FIT_QUEUE: Limit =
    Limit { what: "fit and group jobs queued or running", flag: "--max-fit-queue", env: "SUBLEVEL_MAX_FIT_QUEUE" };

/// Checks that one more item fits under `limit`: `Ok` while `current < max`.
///
/// # Errors
/// [`Error::ResourceExhausted`] (RESOURCE_EXHAUSTED) naming the limit, its value, its flag and its
/// environment variable when `current >= max`.
pub(crate) fn check_room(limit: Limit, current: usize, max: usize) -> Result<()> {
    if current < max {
        return Ok(());
    }
    Err(exhausted(limit, current, max))
}

/// Checks that `adding` more items fit under `limit`: `Ok` while `current + adding <= max`.
///
/// # Errors
/// [`Error::ResourceExhausted`] naming the limit, what is held and what would be added, its flag
/// and its environment variable.
pub(crate) fn check_room_for(limit: Limit, current: usize, adding: usize, max: usize) -> Result<()> {
    if current.saturating_add(adding) <= max {
        return Ok(());
    }
    Err(Error::ResourceExhausted(format!(
        "limit reached: {current} {} and {adding} more exceed at most {max} (set by {} / {})",
        limit.what, limit.flag, limit.env
    )))
}

/// The RESOURCE_EXHAUSTED error of a full `limit` holding `current` of at most `max` items.
pub(crate) fn exhausted(limit: Limit, current: usize, max: usize) -> Error {
    Error::ResourceExhausted(format!(
        "limit reached: {current} {} of at most {max} (set by {} / {})",
        limit.what, limit.flag, limit.env
    ))
}

/// Slots for blocking work: a semaphore in front of tokio's blocking pool.
#[derive(Clone, Debug)]
pub(crate) struct Slots {
    /// Permits = the configured concurrency (at least 1).
    slots: Arc<Semaphore>,
}

/// The two pools of blocking query work (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct QueryPools {
    /// Newton-only work too large for an async worker.
    pub(crate) batch: Slots,
    /// SDP work: certificates, nonconvex scenes, SDP fallbacks.
    pub(crate) sdp: Slots,
    /// `Plan` calls.
    pub(crate) plans: Slots,
}

impl QueryPools {
    /// `batch` batch slots, `sdp` SDP slots and `plans` planning slots.
    pub(crate) fn new(batch: usize, sdp: usize, plans: usize) -> Self {
        Self { batch: Slots::new(batch), sdp: Slots::new(sdp), plans: Slots::new(plans) }
    }
}

/// The default size of the batch pool: the CPUs this process may use.
pub fn default_batch_workers() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

/// The default number of SDP slots: half the CPUs, at least 2 (an SDP solve is single-threaded,
/// on one OpenBLAS thread unless `OPENBLAS_NUM_THREADS` says otherwise, and takes milliseconds to
/// seconds; half the cores keeps the rest for batches and the async workers).
pub fn default_sdp_slots() -> usize {
    (default_batch_workers() / 2).max(2)
}

/// The default number of plans running at once: half the CPUs, at least 1 (a plan keeps one
/// core busy for up to its timeout; the other half stays with the checks).
pub fn default_plan_slots() -> usize {
    (default_batch_workers() / 2).max(1)
}

/// The default number of fit jobs running at once: a quarter of the CPUs, at least 1 (a fit is
/// seconds to minutes of SDP solving; the rest queue).
pub fn default_fit_slots() -> usize {
    (default_batch_workers() / 4).max(1)
}

impl Slots {
    /// `n` slots (0 is taken as 1: no slot at all would make calls wait forever).
    pub(crate) fn new(n: usize) -> Self {
        Self { slots: Arc::new(Semaphore::new(n.max(1))) }
    }

    /// Runs `f` on the blocking pool once a slot is free; the slot is held until `f` returns.
    ///
    /// `f` runs in a [`sublevel_core::cancel::cancellable`] scope whose flag is set when the returned
    /// future is dropped before `f` finished (the request's deadline passed, the client went
    /// away): Clarabel solves inside stop at their next iteration and batches before their next
    /// pair (see [`super::deadline`]), so an abandoned request frees its slot at once instead of
    /// finishing work nobody reads.
    ///
    /// # Errors
    /// `f`'s error as a status; INTERNAL when the worker panicked.
    pub(crate) async fn run<T: Send + 'static>(
        &self,
        f: impl FnOnce() -> Result<T> + Send + 'static,
    ) -> Result<T, Status> {
        let permit =
            self.slots.clone().acquire_owned().await.map_err(|_| Status::unavailable("the server is shutting down"))?;
        cancellable_blocking(move || {
            let _permit = permit;
            f()
        })
        .await
    }

    /// As [`Slots::run`], but gives up waiting for a slot at `deadline`: `Ok(None)` when no slot
    /// was free before it (`f` never ran). Work whose time budget counts from its arrival (a
    /// plan's timeout) waits no longer than that budget.
    ///
    /// # Errors
    /// As [`Slots::run`].
    pub(crate) async fn run_before<T: Send + 'static>(
        &self,
        deadline: std::time::Instant,
        f: impl FnOnce() -> Result<T> + Send + 'static,
    ) -> Result<Option<T>, Status> {
        let acquire = self.slots.clone().acquire_owned();
        let permit = match tokio::time::timeout_at(deadline.into(), acquire).await {
            Err(_) => return Ok(None),
            Ok(permit) => permit.map_err(|_| Status::unavailable("the server is shutting down"))?,
        };
        cancellable_blocking(move || {
            let _permit = permit;
            f()
        })
        .await
        .map(Some)
    }

    /// Slots free right now (for tests and metrics).
    #[cfg(test)]
    pub(crate) fn available(&self) -> usize {
        self.slots.available_permits()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn a_full_limit_names_its_flag_and_variable() {
        assert!(check_room(SCENES, 2, 3).is_ok());
        let e = check_room(SCENES, 3, 3).unwrap_err();
        assert_eq!(
            e.to_string(),
            "resource exhausted: limit reached: 3 scenes of at most 3 (set by --max-scenes / SUBLEVEL_MAX_SCENES)"
        );
        assert_eq!(crate::convert::to_status(e).code(), tonic::Code::ResourceExhausted);
    }

    /// Eight 20 ms jobs in two slots: never more than two at once.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn sdp_slots_bound_the_concurrent_blocking_work() {
        let slots = Slots::new(2);
        let running = Arc::new(AtomicUsize::new(0));
        let peak = Arc::new(AtomicUsize::new(0));
        let mut tasks = Vec::new();
        for _ in 0..8 {
            let (slots, running, peak) = (slots.clone(), running.clone(), peak.clone());
            tasks.push(tokio::spawn(async move {
                slots
                    .run(move || {
                        let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                        peak.fetch_max(now, Ordering::SeqCst);
                        std::thread::sleep(std::time::Duration::from_millis(20));
                        running.fetch_sub(1, Ordering::SeqCst);
                        Ok(())
                    })
                    .await
            }));
        }
        for t in tasks {
            t.await.unwrap().unwrap();
        }
        assert_eq!(peak.load(Ordering::SeqCst), 2);
    }

    /// A dropped caller cancels its blocking work: the work sees the flag, returns early and its
    /// slot is free again.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dropping_the_caller_cancels_the_work_and_frees_the_slot() {
        let slots = Slots::new(1);
        let (tx, rx) = std::sync::mpsc::channel();
        let work = slots.run(move || {
            let start = std::time::Instant::now();
            while !sublevel_core::cancel::is_cancelled() {
                assert!(start.elapsed() < std::time::Duration::from_secs(10), "never cancelled");
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            tx.send(start.elapsed()).unwrap();
            Ok(())
        });
        let out = tokio::time::timeout(std::time::Duration::from_millis(30), work).await;
        assert!(out.is_err(), "the work ran past the timeout");
        let ran = tokio::task::spawn_blocking(move || rx.recv_timeout(std::time::Duration::from_secs(5)))
            .await
            .unwrap()
            .expect("the work saw the cancel flag");
        assert!(ran >= std::time::Duration::from_millis(25), "{ran:?}");
        // The permit is released when the closure returns, just after it reported.
        for _ in 0..500 {
            if slots.available() == 1 {
                break;
            }
            tokio::time::sleep(std::time::Duration::from_millis(2)).await;
        }
        assert_eq!(slots.available(), 1);
        let after = slots.run(|| Ok(sublevel_core::cancel::is_cancelled())).await.unwrap();
        assert!(!after, "a new request starts uncancelled");
    }
}
