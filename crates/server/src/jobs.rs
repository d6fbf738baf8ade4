//! Background fit and grouping jobs: a bounded number run on tokio's blocking pool; each job
//! publishes its progress on a `watch` channel (latest value wins, so a slow watcher never slows a
//! fit) and keeps a [`JobRecord`] in the store, so `GetFitJob` / `ListFitJobs` answer jobs of
//! earlier runs and a job that a crash interrupted answers `JOB_STATE_INTERRUPTED` instead of
//! NOT_FOUND.
//!
//! Cancellation: every job has a flag ([`sublevel_core::cancel`]). `CancelFitJob` sets it: a queued
//! job never starts, a running fit stops at its next Clarabel iteration (or stage boundary), and
//! the job is recorded `cancelled` with no body stored.
//!
//! Shutdown: [`FitJobs::stop`] cancels every job the same way (recorded `cancelled`, the error
//! saying the server shut down; jobs are not resumed after a restart) and ends every
//! `WatchFitJob` stream; [`FitJobs::wait_idle`] lets the server wait, within its grace, until
//! every job has recorded its end. A job whose end could not be recorded before the process
//! exited (grace expired, crash) reads `interrupted` after the next start.

use super::convert::{fit_stage_to_proto, to_status};
use super::pb;
use crate::{Error, Result};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use sublevel_core::math::{Point3, Real};
use sublevel_fit::auto::fit_auto;
use sublevel_fit::{fit_points, FitProgress, FitSettings, PartProgress};
use sublevel_scene::{Catalog, JobRecord, JobRecordState};
use tokio::sync::{watch, Notify, Semaphore};
use tonic::Status;

/// Once this many jobs are remembered in memory, starting another forgets every finished one
/// (their outcome is still answered from the store's job records).
const MAX_REMEMBERED_JOBS: usize = 1024;

/// A job of this run of the server.
#[derive(Debug)]
struct LiveJob {
    /// Its progress (the latest update).
    rx: watch::Receiver<pb::FitJobUpdate>,
    /// Set to cancel it: read by the fit at every Clarabel iteration ([`sublevel_core::cancel`]).
    cancel: Arc<AtomicBool>,
    /// Wakes the job's task while it waits for a fitting slot, so a queued job ends at once.
    wake: Arc<Notify>,
    /// `fit` or `group`.
    kind: &'static str,
    /// Name of the body it stores.
    name: String,
    /// Creation time (ms since the Unix epoch).
    created_unix_ms: u64,
}

impl LiveJob {
    /// Asks the job to stop (idempotent).
    fn cancel(&self) {
        self.cancel.store(true, Ordering::SeqCst);
        self.wake.notify_one();
    }
}

/// The fit jobs of one server.
#[derive(Debug)]
pub(crate) struct FitJobs {
    /// A std mutex (not tokio's): it guards a map lookup or insert, never held across an await.
    jobs: Mutex<HashMap<String, LiveJob>>,
    /// Fitting slots: fits are CPU-heavy SDP solves, so only a few may run at once.
    slots: Arc<Semaphore>,
    /// Jobs queued or running (`sublevel_fit_queue_depth`); at most `max_queue`.
    pending: Arc<AtomicUsize>,
    /// `ServerConfig::max_fit_queue`.
    max_queue: usize,
    /// Where bodies and job records go.
    catalog: Arc<Catalog>,
    /// Set by [`FitJobs::stop`]: cancelled jobs say the server shut down.
    stopping: Arc<AtomicBool>,
    /// Turns true on [`FitJobs::stop`], so `WatchFitJob` streams end and let the server drain.
    stop_signal: watch::Sender<bool>,
    /// Jobs registered whose end is not recorded yet ([`FitJobs::wait_idle`] waits for 0).
    active: Arc<watch::Sender<usize>>,
}

/// A robot fit's validated inputs (see [`FitJobs::start_robot`]).
#[derive(Debug)]
pub(crate) struct RobotFitInput {
    /// The URDF text.
    pub(crate) urdf: String,
    /// The SRDF text, when given.
    pub(crate) srdf: Option<String>,
    /// Mesh files by the exact name the URDF gives them (`package://NAME/PATH` or a relative
    /// path, checked by [`sublevel_robot::check_mesh_name`]): the only mesh bytes the job reads.
    pub(crate) meshes: HashMap<String, Vec<u8>>,
    /// The fit's settings.
    pub(crate) settings: sublevel_robot::RobotFitSettings,
}

/// One `FitJobUpdate`; `part` is the compound fit's part being fitted (`part` / `parts` 0 without).
fn update(
    job_id: &str,
    stage: pb::FitStage,
    fraction: f64,
    message: &str,
    state: pb::JobState,
    part: Option<PartProgress>,
) -> pb::FitJobUpdate {
    let (part, parts) = part.map_or((0, 0), |p| (saturate_u32(p.index), saturate_u32(p.count)));
    pb::FitJobUpdate {
        job_id: job_id.to_owned(),
        stage: stage as i32,
        fraction,
        message: message.to_owned(),
        state: state as i32,
        body_id: String::new(),
        error: String::new(),
        part,
        parts,
        robot_id: String::new(),
    }
}

fn saturate_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

pub(crate) fn is_terminal(u: &pb::FitJobUpdate) -> bool {
    u.state != pb::JobState::Running as i32
}

fn failed(job_id: &str, error: &str) -> pb::FitJobUpdate {
    tracing::warn!(%job_id, %error, "job failed");
    let mut u = update(job_id, pb::FitStage::Done, 1.0, "job failed", pb::JobState::Failed, None);
    u.error = error.to_owned();
    u
}

/// The proto state of a stored record's state (a record still `running` without a live job was
/// interrupted).
fn state_of_record(state: JobRecordState) -> pb::JobState {
    match state {
        JobRecordState::Succeeded => pb::JobState::Succeeded,
        JobRecordState::Failed => pb::JobState::Failed,
        JobRecordState::Cancelled => pb::JobState::Cancelled,
        JobRecordState::Running | JobRecordState::Interrupted => pb::JobState::Interrupted,
    }
}

/// The error text of a stored record (a record still `running` without a live job explains it).
fn error_of_record(r: &JobRecord) -> String {
    if r.state == JobRecordState::Running && r.error.is_empty() {
        "interrupted: the server stopped while the job was running; no body was stored".into()
    } else {
        r.error.clone()
    }
}

/// The terminal update a stored record stands for.
fn update_of_record(job_id: &str, r: &JobRecord) -> pb::FitJobUpdate {
    let mut u = update(job_id, pb::FitStage::Done, 1.0, &r.message, state_of_record(r.state), None);
    set_stored_id(&mut u, &r.kind, r.body_id.clone());
    u.error = error_of_record(r);
    u
}

/// A job as GetFitJob reports it, from its stored record (a finished job, or one of an earlier
/// run).
fn job_of_record(job_id: &str, r: &JobRecord) -> pb::FitJob {
    pb::FitJob {
        job_id: job_id.to_owned(),
        kind: r.kind.clone(),
        name: r.name.clone(),
        state: state_of_record(r.state) as i32,
        stage: pb::FitStage::Done as i32,
        fraction: 1.0,
        message: r.message.clone(),
        body_id: if r.kind == ROBOT_KIND { String::new() } else { r.body_id.clone() },
        error: error_of_record(r),
        created_unix_ms: r.created_unix_ms,
        finished_unix_ms: r.finished_unix_ms,
        robot_id: if r.kind == ROBOT_KIND { r.body_id.clone() } else { String::new() },
    }
}

/// The kind of a robot fit job. Its record keeps the stored robot's id in `body_id`.
pub(crate) const ROBOT_KIND: &str = "robot";

/// Puts the id a job stored into the update: `robot_id` for a robot fit, else `body_id`.
fn set_stored_id(u: &mut pb::FitJobUpdate, kind: &str, id: String) {
    if kind == ROBOT_KIND {
        u.robot_id = id;
    } else {
        u.body_id = id;
    }
}

/// A live job as GetFitJob reports it, from its latest update.
fn job_of_live(job: &LiveJob, u: &pb::FitJobUpdate) -> pb::FitJob {
    pb::FitJob {
        job_id: u.job_id.clone(),
        kind: job.kind.to_owned(),
        name: job.name.clone(),
        state: u.state,
        stage: u.stage,
        fraction: u.fraction,
        message: u.message.clone(),
        body_id: u.body_id.clone(),
        error: u.error.clone(),
        created_unix_ms: job.created_unix_ms,
        finished_unix_ms: 0,
        robot_id: u.robot_id.clone(),
    }
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
    pub(crate) instances: Vec<sublevel_scene::PosedInstance>,
    /// Name of the body to store (the job id when empty).
    pub(crate) name: String,
    /// Replace the grouped instances by one instance of the new body at identity pose.
    pub(crate) replace: bool,
    /// Degrees, samples, tolerance.
    pub(crate) settings: sublevel_fit::containment::ContainmentSettings,
}

/// Where a compound fit's body goes once stored (see [`FitJobs::start_compound_placed`]): an
/// instance in a scene, as `ImportScene` places a planning scene's mesh.
#[derive(Debug)]
pub(crate) struct MeshPlacement {
    /// The scene the instance is added to.
    pub(crate) scene_id: String,
    /// The instance's planning name ([`sublevel_scene::PlanningContext::names`]).
    pub(crate) name: String,
    /// Its pose: the mesh's frame (the body's frame) in the scene.
    pub(crate) pose: sublevel_core::math::Isometry3,
    /// The scene's instance limit (`--max-instances-per-scene`) when the job ends.
    pub(crate) max_instances: usize,
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
            active: Arc::new(watch::channel(0).0),
        }
    }

    /// Marks the registry stopping: every queued and running job is cancelled (a running fit
    /// stops at its next Clarabel iteration; each is recorded `cancelled`, saying the server
    /// shut down), jobs started from now on are refused, and every `WatchFitJob` stream ends with
    /// UNAVAILABLE (an open stream would hold the server's graceful shutdown).
    pub(crate) fn stop(&self) {
        self.stopping.store(true, Ordering::SeqCst);
        self.stop_signal.send_replace(true);
        for job in self.jobs.lock().unwrap_or_else(|e| e.into_inner()).values() {
            job.cancel();
        }
    }

    /// Jobs queued or running now (the `--max-fit-queue` count).
    pub(crate) fn queued(&self) -> usize {
        self.pending.load(Ordering::SeqCst)
    }

    /// Completes once every registered job has recorded its end (at once when none runs).
    pub(crate) async fn wait_idle(&self) {
        let mut rx = self.active.subscribe();
        let _ = rx.wait_for(|n| *n == 0).await;
    }

    /// A receiver that turns true when the server stops.
    pub(crate) fn stop_signal(&self) -> watch::Receiver<bool> {
        self.stop_signal.subscribe()
    }

    /// Registers a new job (its record is written to the store before the id is returned) and
    /// returns its id, the body name, the progress sender, its cancellation flag and wake-up. The
    /// job counts against the queue depth from here until [`FitJobs::spawn`]'s task ends.
    ///
    /// # Errors
    /// UNAVAILABLE while the server stops or when the record cannot be written;
    /// RESOURCE_EXHAUSTED when `max_queue` jobs are queued or running.
    async fn register(&self, kind: &'static str, name: String) -> Result<Registered, Status> {
        if self.stopping.load(Ordering::SeqCst) {
            return Err(Status::unavailable("server shutting down: no new jobs"));
        }
        let taken =
            self.pending.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| (n < self.max_queue).then_some(n + 1));
        if let Err(n) = taken {
            return Err(to_status(super::limits::exhausted(super::limits::FIT_QUEUE, n, self.max_queue)));
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
    async fn register_record(&self, kind: &'static str, name: String) -> Result<Registered, Status> {
        let job_id = format!("j-{:016x}", rand::random::<u64>());
        let name = if name.is_empty() { job_id.clone() } else { name };
        let created_unix_ms = now_ms();
        let record = JobRecord {
            kind: kind.to_owned(),
            name: name.clone(),
            state: JobRecordState::Running,
            body_id: String::new(),
            error: String::new(),
            message: "waiting for a fitting slot".into(),
            created_unix_ms,
            finished_unix_ms: 0,
        };
        let catalog = self.catalog.clone();
        let id = job_id.clone();
        super::runtime::blocking(move || catalog.record_job(&id, &record)).await?;
        let first = update(
            &job_id,
            pb::FitStage::Queued,
            0.0,
            &format!("waiting for a fitting slot ({kind})"),
            pb::JobState::Running,
            None,
        );
        let (tx, rx) = watch::channel(first);
        let cancel = Arc::new(AtomicBool::new(false));
        let wake = Arc::new(Notify::new());
        let live =
            LiveJob { rx, cancel: cancel.clone(), wake: wake.clone(), kind, name: name.clone(), created_unix_ms };
        let mut jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        if jobs.len() >= MAX_REMEMBERED_JOBS {
            jobs.retain(|_, j| !is_terminal(&j.rx.borrow()));
        }
        jobs.insert(job_id.clone(), live);
        self.active.send_modify(|n| *n += 1);
        // A stop that raced with this registration still cancels the job.
        if self.stopping.load(Ordering::SeqCst) {
            cancel.store(true, Ordering::SeqCst);
            wake.notify_one();
        }
        Ok(Registered { job_id, name, created_unix_ms, tx, cancel, wake })
    }

    /// Runs `work` in a fitting slot on the blocking pool, inside a cancellation scope of the
    /// job's flag, publishing its progress on `tx` and its outcome on `tx` and in the job's
    /// record. A job cancelled while it waits for a slot never runs.
    fn spawn(
        &self,
        job: Registered,
        kind: &'static str,
        work: impl FnOnce(&mut dyn FnMut(&FitProgress)) -> Outcome + Send + 'static,
    ) {
        let slots = self.slots.clone();
        let catalog = self.catalog.clone();
        let stopping = self.stopping.clone();
        let active = self.active.clone();
        let pending = self.pending.clone();
        let Registered { job_id, name, created_unix_ms, tx, cancel, wake } = job;
        tokio::spawn(async move {
            let permit = tokio::select! {
                biased;
                () = wake.notified() => None,
                p = slots.acquire_owned() => p.ok(),
            };
            let started = std::time::Instant::now();
            let tx = Arc::new(tx);
            let outcome = match permit {
                Some(permit) if !cancel.load(Ordering::SeqCst) => {
                    tracing::info!(job_id = %job_id, kind, "job started");
                    let tx_work = tx.clone();
                    let id_work = job_id.clone();
                    let flag = cancel.clone();
                    tokio::task::spawn_blocking(move || -> Outcome {
                        let _permit = permit;
                        let mut progress = |p: &FitProgress| {
                            let stage = fit_stage_to_proto(p.stage);
                            let message =
                                if kind == "fit" { p.message.clone() } else { format!("{kind}: {}", p.message) };
                            tx_work.send_replace(update(
                                &id_work,
                                stage,
                                p.fraction,
                                &message,
                                pb::JobState::Running,
                                p.part,
                            ));
                        };
                        sublevel_core::cancel::cancellable(flag, || work(&mut progress))
                    })
                    .await
                }
                _ => Ok(Err(Error::Cancelled("before it started".into()))),
            };
            let left = pending.fetch_sub(1, Ordering::SeqCst).saturating_sub(1);
            super::metrics::fit_queue_depth(left);
            let (last, state) = match outcome {
                Ok(Ok((body_id, message))) => {
                    tracing::info!(job_id = %job_id, %body_id, "job succeeded");
                    let mut u = update(&job_id, pb::FitStage::Done, 1.0, &message, pb::JobState::Succeeded, None);
                    set_stored_id(&mut u, kind, body_id);
                    (u, JobRecordState::Succeeded)
                }
                Ok(Err(e)) if cancel.load(Ordering::SeqCst) || matches!(e, Error::Cancelled(_)) => {
                    let why = if stopping.load(Ordering::SeqCst) {
                        "cancelled: the server is shutting down; no body was stored"
                    } else {
                        "cancelled by CancelFitJob; no body was stored"
                    };
                    tracing::info!(job_id = %job_id, error = %e, "job cancelled");
                    let mut u = update(&job_id, pb::FitStage::Done, 1.0, "cancelled", pb::JobState::Cancelled, None);
                    u.error = format!("{why} ({e})");
                    (u, JobRecordState::Cancelled)
                }
                Ok(Err(e)) => (failed(&job_id, &e.to_string()), JobRecordState::Failed),
                Err(join) => (failed(&job_id, &format!("{kind} aborted: {join}")), JobRecordState::Failed),
            };
            super::metrics::fit_finished(kind, state, started.elapsed());
            let record = JobRecord {
                kind: kind.to_owned(),
                name,
                state,
                body_id: if kind == ROBOT_KIND { last.robot_id.clone() } else { last.body_id.clone() },
                error: last.error.clone(),
                message: last.message.clone(),
                created_unix_ms,
                finished_unix_ms: now_ms(),
            };
            let id = job_id.clone();
            let written = tokio::task::spawn_blocking(move || catalog.record_job(&id, &record)).await;
            if let Ok(Err(e)) | Err(e) = written.map_err(|j| Error::Storage(j.to_string())) {
                tracing::error!(job_id = %job_id, error = %e, "cannot record the job's outcome");
            }
            tx.send_replace(last);
            active.send_modify(|n| *n = n.saturating_sub(1));
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
        let job = self.register("fit", name).await?;
        let (job_id, name) = (job.job_id.clone(), job.name.clone());
        tracing::info!(
            job_id = %job_id,
            points = points.len(),
            degree = settings.degree,
            method = settings.method.name(),
            auto = auto.is_some(),
            "fit queued"
        );
        let catalog = self.catalog.clone();
        self.spawn(job, "fit", move |progress| {
            let mut body = match &auto {
                None => fit_points(&points, &settings, progress)?,
                Some((degrees, tol)) => fit_auto(&points, &settings, degrees, *tol, progress)?,
            };
            body.report.sanitize_non_finite();
            // A cancellation that arrived after the last solver iteration still stores nothing.
            sublevel_core::cancel::check()?;
            Ok((catalog.add_body(&name, body)?, "fit stored".into()))
        });
        Ok(job_id)
    }

    /// Starts a compound fit ([`sublevel_fit::compound::fit_compound`]) of `mesh` (validated:
    /// OFF with triangles) and returns the job id. Progress reports the part being fitted
    /// (`FitJobUpdate.part` / `parts`); on success the compound body is stored under `name` (the
    /// job id when empty) after checking that every mesh triangle lies inside a leaf body.
    ///
    /// # Errors
    /// UNAVAILABLE when the job's record cannot be written.
    pub(crate) async fn start_compound(
        &self,
        name: String,
        mesh: sublevel_fit::mesh::OffMesh,
        parts: sublevel_fit::compound::PartCount,
        settings: sublevel_fit::compound::CompoundSettings,
    ) -> Result<String, Status> {
        self.start_compound_placed(name, mesh, parts, settings, None).await
    }

    /// [`FitJobs::start_compound`] that, with a placement, also keeps the mesh with the stored
    /// body ([`sublevel_scene::MeshRecord`], the mesh's vertices as given: the body's frame) and
    /// then adds an instance of the body to the placement's scene
    /// ([`sublevel_scene::Catalog::add_named_instance`]). When the instance cannot be added (the
    /// scene was deleted, or is full) the job still succeeds, the body stored, and its message
    /// says why the instance was not added.
    ///
    /// # Errors
    /// UNAVAILABLE when the job's record cannot be written.
    pub(crate) async fn start_compound_placed(
        &self,
        name: String,
        mesh: sublevel_fit::mesh::OffMesh,
        parts: sublevel_fit::compound::PartCount,
        settings: sublevel_fit::compound::CompoundSettings,
        placement: Option<MeshPlacement>,
    ) -> Result<String, Status> {
        let job = self.register("fit", name).await?;
        let (job_id, name) = (job.job_id.clone(), job.name.clone());
        tracing::info!(job_id = %job_id, vertices = mesh.vertices.len(), triangles = mesh.triangles.len(), ?parts, placed = placement.is_some(), "compound fit queued");
        let catalog = self.catalog.clone();
        self.spawn(job, "fit", move |progress| {
            let body = sublevel_fit::compound::fit_compound(&mesh, Some(&name), parts, &settings, progress)?;
            let uncovered = sublevel_fit::compound::check::uncovered_triangles(&body, &mesh);
            if !uncovered.is_empty() {
                return Err(Error::Numerical(format!(
                    "{} of {} triangles are not inside any leaf body (first: {:?})",
                    uncovered.len(),
                    mesh.triangles.len(),
                    &uncovered[..uncovered.len().min(5)]
                )));
            }
            let mut file = body.to_file();
            for node in &mut file.nodes {
                node.body.report.sanitize_non_finite();
            }
            let body = sublevel_fit::compound::CompoundBody::from_file(file)?;
            sublevel_core::cancel::check()?;
            let message = format!(
                "compound fit stored: {} parts, {} nodes, max leaf excess {:.4} m",
                body.leaf_count(),
                body.node_count(),
                body.max_leaf_excess()
            );
            let Some(place) = placement else {
                return Ok((catalog.add_compound_body(&name, body)?, message));
            };
            let kept = sublevel_scene::MeshRecord {
                vertices: mesh.vertices.iter().map(|p| [p.x, p.y, p.z]).collect(),
                triangles: mesh.triangles.clone(),
            };
            let body_id = catalog.add_fitted_body(&name, body, Some(kept))?;
            let scene = &place.scene_id;
            let added = catalog.add_named_instance(scene, &body_id, place.pose, &place.name, place.max_instances);
            let message = match added {
                Ok(iid) => format!("{message}; instance {iid} `{}` added to scene {scene}", place.name),
                Err(e) => format!("{message}; the instance `{}` was not added to scene {scene}: {e}", place.name),
            };
            Ok((body_id, message))
        });
        Ok(job_id)
    }

    /// Starts a robot fit ([`sublevel_robot::fit_robot_text`]) of validated inputs and returns the
    /// job id. The meshes are read from the request's bytes only (nothing is written or read on
    /// the server's disk but the fit cache `input.settings.cache_dir`), fitted one per thread of
    /// `input.settings.threads`; progress reports each mesh fitted or read from the cache and each
    /// clearance table. On success the robot is stored under `name`. A cancellation reaches every
    /// stage: the mesh fits stop at their next Clarabel iteration, the clearance tables at their
    /// next block of cells, and nothing is stored.
    ///
    /// # Errors
    /// UNAVAILABLE when the job's record cannot be written.
    pub(crate) async fn start_robot(&self, name: String, input: RobotFitInput) -> Result<String, Status> {
        let job = self.register(ROBOT_KIND, name).await?;
        let (job_id, name) = (job.job_id.clone(), job.name.clone());
        tracing::info!(job_id = %job_id, meshes = input.meshes.len(), "robot fit queued");
        let catalog = self.catalog.clone();
        self.spawn(job, ROBOT_KIND, move |progress| {
            let RobotFitInput { urdf, srdf, meshes, settings } = input;
            let (tx, rx) = std::sync::mpsc::channel::<sublevel_robot::RobotFitProgress>();
            let flag = sublevel_core::cancel::current();
            // The fit reports from its own threads; this thread relays to the job's progress.
            let robot = std::thread::scope(|scope| {
                let fit = scope.spawn(move || {
                    let report = move |p: &sublevel_robot::RobotFitProgress| {
                        let _ = tx.send(p.clone());
                    };
                    sublevel_core::cancel::within(flag, || {
                        let source = sublevel_robot::MeshSource::Memory(&meshes);
                        sublevel_robot::fit_robot_text(urdf, srdf.as_deref(), source, &settings, &report)
                    })
                });
                for p in rx {
                    progress(&FitProgress {
                        stage: sublevel_fit::FitStage::Solve,
                        fraction: p.done as Real / p.total.max(1) as Real,
                        message: format!("[{}/{}] {}", p.done, p.total, p.message),
                        part: None,
                    });
                }
                fit.join().unwrap_or_else(|_| Err(Error::Numerical("the robot fit panicked".into())))
            })?;
            sublevel_core::cancel::check()?;
            let r = &robot.file.report;
            let message = format!(
                "robot fit stored: {} geometries, {} meshes fitted, {} from the cache, {} self pairs",
                robot.geometries.len(),
                r.fitted,
                r.cached,
                robot.self_pairs.len()
            );
            let entry = catalog.add_robot(&name, robot.file)?;
            Ok((entry.id.clone(), message))
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
        let registered = self.register("group", job.name.clone()).await?;
        let (job_id, name) = (registered.job_id.clone(), registered.name.clone());
        tracing::info!(job_id = %job_id, instances = job.instances.len(), degree = job.settings.degree, "group queued");
        let catalog = self.catalog.clone();
        self.spawn(registered, "group", move |progress| {
            let pairs: Vec<(&sublevel_core::Body, sublevel_core::math::Isometry3)> =
                job.instances.iter().map(|i| (i.body.as_ref(), i.pose)).collect();
            let mut body = sublevel_fit::containment::contain_bodies(&pairs, &job.settings, progress)?;
            body.report.sanitize_non_finite();
            sublevel_core::cancel::check()?;
            let body_id = catalog.add_body(&name, body)?;
            if !job.replace {
                return Ok((body_id, "group stored".into()));
            }
            let removed: Vec<String> = job.instances.iter().map(|i| i.id.clone()).collect();
            let pose = sublevel_core::math::Isometry3::identity();
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
        if let Some(job) = self.jobs.lock().unwrap_or_else(|e| e.into_inner()).get(job_id) {
            return Ok(job.rx.clone());
        }
        let record = self.catalog.job(job_id).ok_or_else(|| Error::not_found("job", job_id))?;
        let (_tx, rx) = watch::channel(update_of_record(job_id, &record));
        Ok(rx)
    }

    /// A job as GetFitJob reports it: the live job's latest update while it is queued or
    /// running, else its stored record (which is written before the terminal update is sent).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `job`) when no job of that id was ever recorded.
    pub(crate) fn get(&self, job_id: &str) -> Result<pb::FitJob> {
        let live = self.jobs.lock().unwrap_or_else(|e| e.into_inner()).get(job_id).map(|j| {
            let u = j.rx.borrow().clone();
            (is_terminal(&u), job_of_live(j, &u))
        });
        match (live, self.catalog.job(job_id)) {
            (Some((false, job)), _) => Ok(job),
            (_, Some(record)) => Ok(job_of_record(job_id, &record)),
            (Some((true, job)), None) => Ok(job),
            (None, None) => Err(Error::not_found("job", job_id)),
        }
    }

    /// Every recorded job, ordered by id, as [`FitJobs::get`] reports each.
    pub(crate) fn list(&self) -> Vec<pb::FitJob> {
        let records = self.catalog.jobs();
        let jobs = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        records
            .into_iter()
            .map(|(id, record)| match jobs.get(&id) {
                Some(j) if !is_terminal(&j.rx.borrow()) => job_of_live(j, &j.rx.borrow()),
                _ => job_of_record(&id, &record),
            })
            .collect()
    }

    /// Cancels a job (see `CancelFitJob`) and waits until it has stopped, at most
    /// [`CANCEL_WAIT`] (then the job is returned still running, its cancellation pending). A
    /// finished job, or one of an earlier run, is returned unchanged.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `job`) when no job of that id was ever recorded.
    pub(crate) async fn cancel(&self, job_id: &str) -> Result<pb::FitJob> {
        let rx = self.jobs.lock().unwrap_or_else(|e| e.into_inner()).get(job_id).map(|j| {
            j.cancel();
            j.rx.clone()
        });
        if let Some(mut rx) = rx {
            tracing::info!(%job_id, "job cancellation requested");
            let _ = tokio::time::timeout(CANCEL_WAIT, rx.wait_for(is_terminal)).await;
        }
        self.get(job_id)
    }
}

/// Longest time `CancelFitJob` waits for the job to stop (one Clarabel iteration of a 2d = 8 fit
/// takes well under a second on this project's machine).
const CANCEL_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// A job just registered: what [`FitJobs::spawn`] needs to run it.
struct Registered {
    job_id: String,
    name: String,
    created_unix_ms: u64,
    tx: watch::Sender<pb::FitJobUpdate>,
    cancel: Arc<AtomicBool>,
    wake: Arc<Notify>,
}
