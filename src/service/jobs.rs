//! Background fit and grouping jobs: a bounded number run on tokio's blocking pool; each job
//! publishes its progress on a `watch` channel (latest value wins, so a slow watcher never slows a
//! fit) and keeps a [`JobRecord`] in the store, so a job that a restart interrupted answers
//! `JOB_STATE_INTERRUPTED` instead of NOT_FOUND.
//!
//! Shutdown: [`FitJobs::stop`] marks the registry stopping; a job that finishes its SDP after that
//! stores nothing (its record stays `running` and the next start marks it `interrupted`), and
//! the server process does not wait for running solves (see `cli::serve`).

use super::convert::fit_stage_to_proto;
use super::pb;
use crate::fit::auto::fit_auto;
use crate::fit::{fit_points, FitProgress, FitSettings};
use crate::math::{Point3, Real};
use crate::scene::{Catalog, JobRecord, JobRecordState};
use crate::{Error, Result};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::{watch, Semaphore};
use tonic::Status;

/// Once this many jobs are remembered in memory, starting another forgets every finished one
/// (their outcome is still answered from the store's job records).
const MAX_REMEMBERED_JOBS: usize = 1024;

/// The fit jobs of one server.
#[derive(Debug)]
pub(crate) struct FitJobs {
    /// A std mutex (not tokio's): it guards a map lookup or insert, never held across an await.
    jobs: Mutex<HashMap<String, watch::Receiver<pb::FitJobUpdate>>>,
    /// Fitting slots: fits are CPU-heavy SDP solves, so only a few may run at once.
    slots: Arc<Semaphore>,
    /// Jobs queued or running (`sublevel_fit_queue_depth`); at most `max_queue`.
    pending: Arc<AtomicUsize>,
    /// `ServerConfig::max_fit_queue`.
    max_queue: usize,
    /// Where bodies and job records go.
    catalog: Arc<Catalog>,
    /// Set by [`FitJobs::stop`]: finishing jobs store nothing.
    stopping: Arc<AtomicBool>,
    /// Turns true on [`FitJobs::stop`], so `WatchFitJob` streams end and let the server drain.
    stop_signal: watch::Sender<bool>,
}

fn update(job_id: &str, stage: pb::FitStage, fraction: f64, message: &str, state: pb::JobState) -> pb::FitJobUpdate {
    pb::FitJobUpdate {
        job_id: job_id.to_owned(),
        stage: stage as i32,
        fraction,
        message: message.to_owned(),
        state: state as i32,
        body_id: String::new(),
        error: String::new(),
    }
}

pub(crate) fn is_terminal(u: &pb::FitJobUpdate) -> bool {
    u.state != pb::JobState::Running as i32
}

fn failed(job_id: &str, error: &str) -> pb::FitJobUpdate {
    tracing::warn!(%job_id, %error, "job failed");
    let mut u = update(job_id, pb::FitStage::Done, 1.0, "job failed", pb::JobState::Failed);
    u.error = error.to_owned();
    u
}

/// The terminal update a stored record stands for (a record still `running` without a live job
/// was interrupted).
fn update_of_record(job_id: &str, r: &JobRecord) -> pb::FitJobUpdate {
    let (state, stage) = match r.state {
        JobRecordState::Succeeded => (pb::JobState::Succeeded, pb::FitStage::Done),
        JobRecordState::Failed => (pb::JobState::Failed, pb::FitStage::Done),
        JobRecordState::Running | JobRecordState::Interrupted => (pb::JobState::Interrupted, pb::FitStage::Done),
    };
    let mut u = update(job_id, stage, 1.0, &r.message, state);
    u.body_id = r.body_id.clone();
    u.error = if r.state == JobRecordState::Running && r.error.is_empty() {
        "interrupted: the server stopped while the job was running; no body was stored".into()
    } else {
        r.error.clone()
    };
    u
}

fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
}

/// A grouping job's inputs, validated by the handler (paper §V).
#[derive(Debug)]
pub(crate) struct GroupJob {
    /// The scene the instances belong to.
    pub(crate) scene_id: String,
    /// The grouped instances with their bodies and poses, read when the job was started.
    pub(crate) instances: Vec<crate::scene::PosedInstance>,
    /// Name of the body to store (the job id when empty).
    pub(crate) name: String,
    /// Replace the grouped instances by one instance of the new body at identity pose.
    pub(crate) replace: bool,
    /// Degrees, samples, tolerance.
    pub(crate) settings: crate::fit::containment::ContainmentSettings,
}

/// What a job's work returns: the stored body's id and the final message.
type Outcome = Result<(String, String)>;

impl FitJobs {
    pub(crate) fn new(catalog: Arc<Catalog>, max_concurrent: usize, max_queue: usize) -> Self {
        Self {
            jobs: Mutex::new(HashMap::new()),
            slots: Arc::new(Semaphore::new(max_concurrent.max(1))),
            pending: Arc::new(AtomicUsize::new(0)),
            max_queue,
            catalog,
            stopping: Arc::new(AtomicBool::new(false)),
            stop_signal: watch::channel(false).0,
        }
    }

    /// Marks the registry stopping: jobs that finish from now on store nothing, and every
    /// `WatchFitJob` stream ends with UNAVAILABLE (an open stream would hold the server's
    /// graceful shutdown until the fit ends).
    pub(crate) fn stop(&self) {
        self.stopping.store(true, Ordering::SeqCst);
        self.stop_signal.send_replace(true);
    }

    /// A receiver that turns true when the server stops.
    pub(crate) fn stop_signal(&self) -> watch::Receiver<bool> {
        self.stop_signal.subscribe()
    }

    /// Registers a new job (its record is written to the store before the id is returned) and
    /// returns its id, the body name and the progress sender. The job counts against the queue
    /// depth from here until [`FitJobs::spawn`]'s task ends.
    ///
    /// # Errors
    /// RESOURCE_EXHAUSTED when `max_queue` jobs are queued or running; UNAVAILABLE when the
    /// record cannot be written.
    async fn register(
        &self,
        kind: &str,
        name: String,
    ) -> Result<(String, String, watch::Sender<pb::FitJobUpdate>), Status> {
        let taken =
            self.pending.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| (n < self.max_queue).then_some(n + 1));
        if let Err(n) = taken {
            return Err(super::limits::exhausted(super::limits::FIT_QUEUE, n, self.max_queue).into());
        }
        super::metrics::fit_queue_depth(self.pending.load(Ordering::SeqCst));
        let registered = self.register_record(kind, name).await;
        if registered.is_err() {
            let left = self.pending.fetch_sub(1, Ordering::SeqCst).saturating_sub(1);
            super::metrics::fit_queue_depth(left);
        }
        registered
    }

    /// The body of [`FitJobs::register`] after the queue admitted the job.
    async fn register_record(
        &self,
        kind: &str,
        name: String,
    ) -> Result<(String, String, watch::Sender<pb::FitJobUpdate>), Status> {
        let job_id = format!("j-{:016x}", rand::random::<u64>());
        let name = if name.is_empty() { job_id.clone() } else { name };
        let record = JobRecord {
            kind: kind.to_owned(),
            name: name.clone(),
            state: JobRecordState::Running,
            body_id: String::new(),
            error: String::new(),
            message: "waiting for a fitting slot".into(),
            created_unix_ms: now_ms(),
        };
        let catalog = self.catalog.clone();
        let id = job_id.clone();
        super::handlers::blocking(move || catalog.record_job(&id, &record)).await?;
        let first = update(
            &job_id,
            pb::FitStage::Queued,
            0.0,
            &format!("waiting for a fitting slot ({kind})"),
            pb::JobState::Running,
        );
        let (tx, rx) = watch::channel(first);
        let mut jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        if jobs.len() >= MAX_REMEMBERED_JOBS {
            jobs.retain(|_, rx| !is_terminal(&rx.borrow()));
        }
        jobs.insert(job_id.clone(), rx);
        Ok((job_id, name, tx))
    }

    /// Runs `work` in a fitting slot on the blocking pool, publishing its progress on `tx` and
    /// its outcome on `tx` and in the job's record.
    fn spawn(
        &self,
        job_id: String,
        kind: &'static str,
        name: String,
        tx: watch::Sender<pb::FitJobUpdate>,
        work: impl FnOnce(&mut dyn FnMut(&FitProgress), &AtomicBool) -> Outcome + Send + 'static,
    ) {
        let slots = self.slots.clone();
        let catalog = self.catalog.clone();
        let stopping = self.stopping.clone();
        let pending = self.pending.clone();
        tokio::spawn(async move {
            let permit = slots.acquire_owned().await;
            tracing::info!(job_id = %job_id, kind, "job started");
            let started = std::time::Instant::now();
            let tx = Arc::new(tx);
            let tx_work = tx.clone();
            let id_work = job_id.clone();
            let stop_work = stopping.clone();
            let outcome = tokio::task::spawn_blocking(move || -> Outcome {
                let _permit = permit;
                let mut progress = |p: &FitProgress| {
                    let stage = fit_stage_to_proto(p.stage);
                    let message = if kind == "fit" { p.message.clone() } else { format!("{kind}: {}", p.message) };
                    tx_work.send_replace(update(&id_work, stage, p.fraction, &message, pb::JobState::Running));
                };
                work(&mut progress, &stop_work)
            })
            .await;
            let left = pending.fetch_sub(1, Ordering::SeqCst).saturating_sub(1);
            super::metrics::fit_queue_depth(left);
            let (last, state) = match outcome {
                Ok(Ok((body_id, message))) => {
                    tracing::info!(job_id = %job_id, %body_id, "job succeeded");
                    let mut u = update(&job_id, pb::FitStage::Done, 1.0, &message, pb::JobState::Succeeded);
                    u.body_id = body_id;
                    (u, JobRecordState::Succeeded)
                }
                Ok(Err(e)) if stopping.load(Ordering::SeqCst) => {
                    let mut u = update(&job_id, pb::FitStage::Done, 1.0, "interrupted", pb::JobState::Interrupted);
                    u.error = e.to_string();
                    (u, JobRecordState::Interrupted)
                }
                Ok(Err(e)) => (failed(&job_id, &e.to_string()), JobRecordState::Failed),
                Err(join) => (failed(&job_id, &format!("{kind} aborted: {join}")), JobRecordState::Failed),
            };
            super::metrics::fit_finished(kind, state, started.elapsed());
            let record = JobRecord {
                kind: kind.to_owned(),
                name,
                state,
                body_id: last.body_id.clone(),
                error: last.error.clone(),
                message: last.message.clone(),
                created_unix_ms: now_ms(),
            };
            let id = job_id.clone();
            let written = tokio::task::spawn_blocking(move || catalog.record_job(&id, &record)).await;
            if let Ok(Err(e)) | Err(e) = written.map_err(|j| Error::Storage(j.to_string())) {
                tracing::error!(job_id = %job_id, error = %e, "cannot record the job's outcome");
            }
            tx.send_replace(last);
        });
    }

    /// Starts fitting `points` (already validated) and returns the job id. On success the body is
    /// stored in the catalog under `name` (the job id when empty). With `auto = Some((degrees, τ))`
    /// the degree is chosen by [`fit_auto`] (progress messages then name the degree being fitted).
    ///
    /// # Errors
    /// UNAVAILABLE when the job's record cannot be written.
    pub(crate) async fn start(
        &self,
        name: String,
        points: Vec<Point3>,
        settings: FitSettings,
        auto: Option<(Vec<usize>, Real)>,
    ) -> Result<String, Status> {
        let (job_id, name, tx) = self.register("fit", name).await?;
        tracing::info!(
            job_id = %job_id,
            points = points.len(),
            degree = settings.degree,
            method = settings.method.name(),
            auto = auto.is_some(),
            "fit queued"
        );
        let catalog = self.catalog.clone();
        let body_name = name.clone();
        self.spawn(job_id.clone(), "fit", name, tx, move |progress, stopping| {
            let mut body = match &auto {
                None => fit_points(&points, &settings, progress)?,
                Some((degrees, tol)) => fit_auto(&points, &settings, degrees, *tol, progress)?,
            };
            body.report.sanitize_non_finite();
            if stopping.load(Ordering::SeqCst) {
                return Err(Error::Numerical("abandoned: the server is shutting down; no body was stored".into()));
            }
            Ok((catalog.add_body(&body_name, body)?, "fit stored".into()))
        });
        Ok(job_id)
    }

    /// Starts a grouping job (it shares the fitting slots and the job registry with fits, so
    /// `WatchFitJob` streams it) and returns its id. On success the containing body is stored in
    /// the catalog and, with `replace`, the grouped instances are replaced by it atomically; the
    /// terminal update carries the body id (and names the new instance in its message).
    ///
    /// # Errors
    /// UNAVAILABLE when the job's record cannot be written.
    pub(crate) async fn start_group(&self, job: GroupJob) -> Result<String, Status> {
        let (job_id, name, tx) = self.register("group", job.name.clone()).await?;
        tracing::info!(job_id = %job_id, instances = job.instances.len(), degree = job.settings.degree, "group queued");
        let catalog = self.catalog.clone();
        let body_name = name.clone();
        self.spawn(job_id.clone(), "group", name, tx, move |progress, stopping| {
            let pairs: Vec<(&crate::Body, crate::math::Isometry3)> =
                job.instances.iter().map(|i| (i.body.as_ref(), i.pose)).collect();
            let mut body = crate::fit::containment::contain_bodies(&pairs, &job.settings, progress)?;
            body.report.sanitize_non_finite();
            if stopping.load(Ordering::SeqCst) {
                return Err(Error::Numerical("abandoned: the server is shutting down; no body was stored".into()));
            }
            let body_id = catalog.add_body(&body_name, body)?;
            if !job.replace {
                return Ok((body_id, "group stored".into()));
            }
            let removed: Vec<String> = job.instances.iter().map(|i| i.id.clone()).collect();
            let pose = crate::math::Isometry3::identity();
            let iid = catalog.replace_instances(&job.scene_id, &removed, &body_id, pose)?;
            Ok((body_id, format!("group stored; scene instance {iid} replaces the grouped instances")))
        });
        Ok(job_id)
    }

    /// The progress channel of a job: the live one, or for a job of an earlier run of the server
    /// a channel holding the terminal update its stored record stands for.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `job`) when no job of that id was ever recorded.
    pub(crate) fn watch(&self, job_id: &str) -> Result<watch::Receiver<pb::FitJobUpdate>> {
        if let Some(rx) = self.jobs.lock().unwrap_or_else(|e| e.into_inner()).get(job_id).cloned() {
            return Ok(rx);
        }
        let record = self.catalog.job(job_id).ok_or_else(|| Error::not_found("job", job_id))?;
        let (_tx, rx) = watch::channel(update_of_record(job_id, &record));
        Ok(rx)
    }
}
