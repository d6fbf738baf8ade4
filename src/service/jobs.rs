//! Background fit jobs: a bounded number of fits run on tokio's blocking pool; each job publishes
//! its progress on a `watch` channel (latest value wins, so a slow watcher never slows a fit).

use super::convert::fit_stage_to_proto;
use super::pb;
use crate::fit::auto::fit_auto;
use crate::fit::{fit_points, FitProgress, FitSettings};
use crate::math::{Point3, Real};
use crate::scene::Catalog;
use crate::{Error, Result};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tokio::sync::{watch, Semaphore};

/// Once this many jobs are remembered, starting another forgets every finished one (their ids
/// then answer NOT_FOUND).
const MAX_REMEMBERED_JOBS: usize = 1024;

/// The fit jobs of one server.
#[derive(Debug)]
pub(crate) struct FitJobs {
    /// A std mutex (not tokio's): it guards a map lookup or insert, never held across an await.
    jobs: Mutex<HashMap<String, watch::Receiver<pb::FitJobUpdate>>>,
    /// Fitting slots: fits are CPU-heavy SDP solves, so only a few may run at once.
    slots: Arc<Semaphore>,
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

impl FitJobs {
    pub(crate) fn new(max_concurrent: usize) -> Self {
        Self { jobs: Mutex::new(HashMap::new()), slots: Arc::new(Semaphore::new(max_concurrent.max(1))) }
    }

    /// Starts fitting `points` (already validated) and returns the job id. On success the body is
    /// stored in `catalog` under `name` (the job id when empty). With `auto = Some((degrees, τ))`
    /// the degree is chosen by [`fit_auto`] (progress messages then name the degree being fitted).
    pub(crate) fn start(
        &self,
        catalog: Arc<Catalog>,
        name: String,
        points: Vec<Point3>,
        settings: FitSettings,
        auto: Option<(Vec<usize>, Real)>,
    ) -> String {
        let job_id = format!("j-{:016x}", rand::random::<u64>());
        let first = update(&job_id, pb::FitStage::Queued, 0.0, "waiting for a fitting slot", pb::JobState::Running);
        let (tx, rx) = watch::channel(first);
        {
            let mut jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
            if jobs.len() >= MAX_REMEMBERED_JOBS {
                jobs.retain(|_, rx| !is_terminal(&rx.borrow()));
            }
            jobs.insert(job_id.clone(), rx);
        }
        let name = if name.is_empty() { job_id.clone() } else { name };
        let slots = self.slots.clone();
        let id = job_id.clone();
        tokio::spawn(async move {
            let permit = slots.acquire_owned().await;
            tracing::info!(
                job_id = %id,
                points = points.len(),
                degree = settings.degree,
                method = settings.method.name(),
                auto = auto.is_some(),
                "fit started"
            );
            let tx = Arc::new(tx);
            let tx_fit = tx.clone();
            let id_fit = id.clone();
            let outcome = tokio::task::spawn_blocking(move || -> Result<String> {
                let _permit = permit;
                let mut progress = |p: &FitProgress| {
                    let stage = fit_stage_to_proto(p.stage);
                    tx_fit.send_replace(update(&id_fit, stage, p.fraction, &p.message, pb::JobState::Running));
                };
                let body = match &auto {
                    None => fit_points(&points, &settings, &mut progress)?,
                    Some((degrees, tol)) => fit_auto(&points, &settings, degrees, *tol, &mut progress)?,
                };
                catalog.add_body(&name, body)
            })
            .await;
            let last = match outcome {
                Ok(Ok(body_id)) => {
                    tracing::info!(job_id = %id, %body_id, "fit succeeded");
                    let mut u = update(&id, pb::FitStage::Done, 1.0, "fit stored", pb::JobState::Succeeded);
                    u.body_id = body_id;
                    u
                }
                Ok(Err(e)) => failed(&id, &e.to_string()),
                Err(join) => failed(&id, &format!("fit aborted: {join}")),
            };
            tx.send_replace(last);
        });
        job_id
    }

    /// The progress channel of a job.
    pub(crate) fn watch(&self, job_id: &str) -> Result<watch::Receiver<pb::FitJobUpdate>> {
        let jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        jobs.get(job_id).cloned().ok_or_else(|| Error::not_found("job", job_id))
    }
}

fn failed(job_id: &str, error: &str) -> pb::FitJobUpdate {
    tracing::warn!(%job_id, %error, "fit failed");
    let mut u = update(job_id, pb::FitStage::Done, 1.0, "fit failed", pb::JobState::Failed);
    u.error = error.to_owned();
    u
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

impl FitJobs {
    /// Registers a new job and returns its id and progress sender.
    fn register(&self, message: &str) -> (String, watch::Sender<pb::FitJobUpdate>) {
        let job_id = format!("j-{:016x}", rand::random::<u64>());
        let first = update(&job_id, pb::FitStage::Queued, 0.0, message, pb::JobState::Running);
        let (tx, rx) = watch::channel(first);
        let mut jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        if jobs.len() >= MAX_REMEMBERED_JOBS {
            jobs.retain(|_, rx| !is_terminal(&rx.borrow()));
        }
        jobs.insert(job_id.clone(), rx);
        (job_id, tx)
    }

    /// Starts a grouping job (it shares the fitting slots and the job registry with fits, so
    /// `WatchFitJob` streams it) and returns its id. On success the containing body is stored in
    /// `catalog` and, with `replace`, the grouped instances are replaced by it atomically; the
    /// terminal update carries the body id (and names the new instance in its message).
    pub(crate) fn start_group(&self, catalog: Arc<Catalog>, job: GroupJob) -> String {
        let (job_id, tx) = self.register("waiting for a fitting slot (group)");
        let name = if job.name.is_empty() { job_id.clone() } else { job.name.clone() };
        let slots = self.slots.clone();
        let id = job_id.clone();
        tokio::spawn(async move {
            let permit = slots.acquire_owned().await;
            tracing::info!(job_id = %id, instances = job.instances.len(), degree = job.settings.degree, "group started");
            let tx = Arc::new(tx);
            let tx_fit = tx.clone();
            let id_fit = id.clone();
            let outcome = tokio::task::spawn_blocking(move || -> Result<(String, Option<String>)> {
                let _permit = permit;
                let mut progress = |p: &FitProgress| {
                    let stage = fit_stage_to_proto(p.stage);
                    let message = format!("group: {}", p.message);
                    tx_fit.send_replace(update(&id_fit, stage, p.fraction, &message, pb::JobState::Running));
                };
                let pairs: Vec<(&crate::Body, crate::math::Isometry3)> =
                    job.instances.iter().map(|i| (i.body.as_ref(), i.pose)).collect();
                let body = crate::fit::containment::contain_bodies(&pairs, &job.settings, &mut progress)?;
                let body_id = catalog.add_body(&name, body)?;
                if !job.replace {
                    return Ok((body_id, None));
                }
                let removed: Vec<String> = job.instances.iter().map(|i| i.id.clone()).collect();
                let pose = crate::math::Isometry3::identity();
                let instance_id = catalog.replace_instances(&job.scene_id, &removed, &body_id, pose)?;
                Ok((body_id, Some(instance_id)))
            })
            .await;
            let last = match outcome {
                Ok(Ok((body_id, instance))) => {
                    tracing::info!(job_id = %id, %body_id, "group succeeded");
                    let message = match instance {
                        Some(iid) => format!("group stored; scene instance {iid} replaces the grouped instances"),
                        None => "group stored".to_owned(),
                    };
                    let mut u = update(&id, pb::FitStage::Done, 1.0, &message, pb::JobState::Succeeded);
                    u.body_id = body_id;
                    u
                }
                Ok(Err(e)) => failed(&id, &e.to_string()),
                Err(join) => failed(&id, &format!("group aborted: {join}")),
            };
            tx.send_replace(last);
        });
        job_id
    }
}
