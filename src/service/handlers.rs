//! The `sublevel.v1.Sublevel` handlers: validate → call the core → convert.

use super::convert::{self as cv, prefix_field, require_id};
use super::jobs::{is_terminal, FitJobs, GroupJob};
use super::limits::{self, check_room, SdpSlots};
use super::pb::{self, sublevel_server::Sublevel};
use super::ServerConfig;
use crate::body::BodyFile;
use crate::fit::mesh::parse_points_limited;
use crate::fit::sos_convexity::admit_uploaded;
use crate::query::CertifyMode;
use crate::scene::planner::{AnswerSink, PlannerAnswers, PlannerRequest, QueryView};
use crate::scene::{Catalog, QueryAnswer, QueryOptions};
use crate::{Error, Result};
use std::sync::Arc;
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::Stream;
use tonic::{Request, Response, Status};

/// The service state shared by all requests.
#[derive(Debug)]
pub struct SublevelService {
    catalog: Arc<Catalog>,
    config: ServerConfig,
    pub(crate) jobs: Arc<FitJobs>,
    /// Slots of blocking SDP query work (`ServerConfig::max_concurrent_sdp`).
    sdp: SdpSlots,
}

impl SublevelService {
    /// A service over `catalog` with `config`'s limits.
    pub fn new(catalog: Arc<Catalog>, config: ServerConfig) -> Self {
        let jobs = Arc::new(FitJobs::new(catalog.clone(), config.max_concurrent_fits, config.max_fit_queue));
        let sdp = SdpSlots::new(config.max_concurrent_sdp);
        Self { catalog, config, jobs, sdp }
    }
}

/// Answers a planner request on a view into `sink`: inline on the async worker when it holds
/// only Newton queries (microseconds each), on the blocking pool when one asks for a certificate
/// (an SDP). Returns the view (moved back out of the blocking pool) with the filled sink.
async fn run_view<S: AnswerSink + Send + 'static>(
    catalog: Arc<Catalog>,
    sdp: &SdpSlots,
    mut view: QueryView,
    request: PlannerRequest,
    mut sink: S,
) -> (QueryView, Result<S, Status>) {
    let certify = request.queries.iter().any(|q| q.options.mode == CertifyMode::Certify);
    let answers = request.queries.len() * request.states.len().max(1);
    if !off_workers(&catalog, view.scene_id(), certify, answers) {
        // Newton only: an answer that needs the SDP sends the whole request to the blocking pool.
        match view.run_newton_only_into(&catalog, &request, &mut sink) {
            Ok(true) => return (view, Ok(sink)),
            Ok(false) => {}
            Err(e) => return (view, Err(Status::from(e))),
        }
    }
    let scene = view.scene_id().to_owned();
    match sdp
        .run(move || {
            let out = view.run_into(&catalog, &request, &mut sink).map(|()| sink);
            Ok((view, out))
        })
        .await
    {
        Ok((view, out)) => (view, out.map_err(Status::from)),
        Err(e) => (QueryView::new(&scene), Err(e)),
    }
}

/// Answers planner request `planner` (validated from `req`) on `view` and builds the reply.
/// States and answers both in columns (the sampling planner's batch) are written to the answer
/// columns as they are solved; every other request collects its answers first.
async fn answer_planner(
    catalog: Arc<Catalog>,
    sdp: &SdpSlots,
    view: QueryView,
    req: &pb::QueryRequest,
    planner: PlannerRequest,
    start: std::time::Instant,
) -> (QueryView, Result<pb::QueryResponse, Status>) {
    let columns = cv::columns_kind(req);
    let state_columns = req.state_columns.is_some();
    match columns {
        Some(kind) if state_columns => {
            let rows = planner.queries.len() * planner.states.len();
            let (view, out) = run_view(catalog, sdp, view, planner, cv::ColumnsSink::new(kind, rows)).await;
            let reply = out.map(|c| pb::QueryResponse {
                request_id: req.request_id,
                server_seconds: start.elapsed().as_secs_f64(),
                columns: Some(c.finish()),
                ..Default::default()
            });
            (view, reply)
        }
        _ => {
            let answers = PlannerAnswers::for_request(&planner);
            let (view, out) = run_view(catalog, sdp, view, planner, answers).await;
            let reply = out.map(|a| {
                let seconds = start.elapsed().as_secs_f64();
                cv::planner_answers_to_proto(&a, req.request_id, seconds, columns)
            });
            (view, reply)
        }
    }
}

/// Most answers a query request computes inline on an async worker (about 1 µs each); larger
/// requests run on the blocking pool so they never hold up other connections.
const INLINE_ANSWERS: usize = 256;

/// Cost of one answer between compound bodies in units of a single-body answer: a tree query
/// solves a few to a few tens of node pairs (tens of µs), so a request with a compound body goes
/// to the blocking pool from [`INLINE_ANSWERS`] / this many answers on.
const COMPOUND_ANSWER_COST: usize = 32;

/// Whether a query request is slow work, to run off the async workers: it asks for certificates
/// (an SDP each), its scene holds a nonconvex body (SDP lower bounds), or it has more than
/// [`INLINE_ANSWERS`] answers (counting [`COMPOUND_ANSWER_COST`] per answer in a scene with a
/// compound body). A compound query that needs an SDP (a leaf pair Newton did not resolve) is
/// re-run on the SDP slots as any `needs_sdp` answer is.
fn off_workers(catalog: &Catalog, scene_id: &str, certify: bool, answers: usize) -> bool {
    certify
        || answers > INLINE_ANSWERS
        || catalog.has_nonconvex(scene_id)
        || (answers.saturating_mul(COMPOUND_ANSWER_COST) > INLINE_ANSWERS && catalog.has_compound(scene_id))
}

/// Runs query work `f` inline when it is microseconds, else on the blocking pool (see
/// [`off_workers`]). `f` gets the certification mode to use instead of the queries' own: inline
/// [`CertifyMode::NewtonOnly`] (no SDP ever runs on an async worker); when `needs_sdp` says an
/// answer needed the SDP fallback, `f` runs again on the blocking pool with the queries' own modes
/// (`None`), which gives the answers a first run there would have given.
async fn query_work<T: Send + 'static>(
    catalog: &Arc<Catalog>,
    sdp: &SdpSlots,
    scene_id: &str,
    certify: bool,
    answers: usize,
    f: impl Fn(&Catalog, Option<CertifyMode>) -> Result<T> + Send + 'static,
    needs_sdp: impl Fn(&T) -> bool,
) -> Result<T, Status> {
    if !off_workers(catalog, scene_id, certify, answers) {
        let out = f(catalog, Some(CertifyMode::NewtonOnly)).map_err(Status::from)?;
        if !needs_sdp(&out) {
            return Ok(out);
        }
    }
    let catalog = catalog.clone();
    sdp.run(move || f(&catalog, None)).await
}

/// Runs blocking work (an fsync'd store write, mesh parsing, an SDP) on tokio's blocking pool.
pub(crate) async fn blocking<T: Send + 'static>(f: impl FnOnce() -> Result<T> + Send + 'static) -> Result<T, Status> {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => r.map_err(Status::from),
        Err(e) => Err(Status::internal(format!("worker failed: {e}"))),
    }
}

type Reply<T> = Result<Response<T>, Status>;

/// An `UploadBody` request's body, parsed: a single body file (with the field it came from) or a
/// compound body file (issue 14).
enum Upload {
    Single(Box<BodyFile>, &'static str),
    Compound(crate::compound::CompoundFile),
}

/// One QueryStream: its requests, its private view of the scene (from the first request on).
struct QueryStreamState {
    inbound: tonic::Streaming<pb::QueryRequest>,
    catalog: Arc<Catalog>,
    sdp: SdpSlots,
    view: Option<QueryView>,
    /// (most answers, most poses) of one request.
    limits: (usize, usize),
    done: bool,
}

impl QueryStreamState {
    /// Answers one request of the stream on its view (created by the first request; later ones
    /// may repeat its scene id or leave it empty).
    async fn answer(&mut self, req: pb::QueryRequest) -> Result<pb::QueryResponse, Status> {
        let start = std::time::Instant::now();
        let planner = cv::planner_request_from_proto(&req, self.limits.0, self.limits.1)?;
        let current = match self.view.take() {
            None => QueryView::new(require_id("scene_id", &req.scene_id)?),
            Some(v) if req.scene_id.is_empty() || req.scene_id == v.scene_id() => v,
            Some(v) => {
                let message = format!(
                    "a stream answers one scene: `{}` after `{}`",
                    crate::error::clip(&req.scene_id),
                    v.scene_id()
                );
                self.view = Some(v);
                return Err(Error::invalid("scene_id", message).into());
            }
        };
        let (back, reply) = answer_planner(self.catalog.clone(), &self.sdp, current, &req, planner, start).await;
        self.view = Some(back);
        reply
    }
}

impl SublevelService {
    /// `StartFitJob` with `parts` / `auto_parts` (a compound fit, issue 14): the mesh (OFF, with
    /// triangles) is parsed off the async workers, the settings checked, the job started.
    async fn start_compound_fit(
        &self,
        req: pb::StartFitJobRequest,
        fit: &cv::FitOptions,
        settings: crate::fit::FitSettings,
        parts: crate::compound::PartCount,
    ) -> Reply<pb::StartFitJobResponse> {
        let compound = cv::compound_settings(&req, fit, settings)?;
        let mesh = match req.source {
            Some(pb::start_fit_job_request::Source::Mesh(mesh)) => mesh,
            _ => {
                return Err(Error::invalid(
                    "mesh",
                    "a compound fit (`parts` or `auto_parts`) needs `mesh`: a triangle mesh in OFF format",
                )
                .into())
            }
        };
        if mesh.data.is_empty() {
            return Err(Error::invalid("mesh.data", "must not be empty").into());
        }
        if cv::mesh_format_from_proto(&mesh)? != crate::fit::mesh::MeshFormat::Off {
            return Err(
                Error::invalid("mesh.format", "a compound fit decomposes the mesh's faces: send an OFF mesh").into()
            );
        }
        let max = self.config.max_fit_points;
        let mesh = blocking(move || {
            let mesh = crate::fit::mesh::parse_off_mesh(&mesh.data, max)?;
            cv::check_point_count("mesh", mesh.vertices.len(), max)?;
            if mesh.triangles.is_empty() {
                return Err(Error::invalid("mesh.data", "the OFF mesh has no faces to decompose"));
            }
            Ok(mesh)
        })
        .await?;
        let job_id = self.jobs.start_compound(req.name, mesh, parts, compound).await?;
        Ok(Response::new(pb::StartFitJobResponse { job_id }))
    }
}

#[tonic::async_trait]
impl Sublevel for SublevelService {
    async fn start_fit_job(&self, request: Request<pb::StartFitJobRequest>) -> Reply<pb::StartFitJobResponse> {
        let req = request.into_inner();
        let fit = cv::fit_options(&req)?;
        if req.name.len() > crate::scene::MAX_NAME_BYTES {
            return Err(Error::invalid("name", format!("at most {} bytes", crate::scene::MAX_NAME_BYTES)).into());
        }
        // Every setting is checked before a job exists (a bad combination such as logdet_h with
        // a relaxation is INVALID_ARGUMENT here, not a failed job).
        let mut settings = self.config.fit.clone();
        settings.degree = fit.degree;
        settings.method = fit.method;
        settings.convexity_relaxation = fit.convexity_relaxation;
        settings.validate()?;
        check_room(limits::BODIES, self.catalog.bodies().len(), self.config.max_bodies)?;
        let max = self.config.max_fit_points;
        if let Some(parts) = cv::part_count(&req)? {
            return self.start_compound_fit(req, &fit, settings, parts).await;
        }
        let top_degree = fit.auto.as_ref().and_then(|(d, _)| d.iter().max().copied()).unwrap_or(fit.degree);
        let points = match req.source {
            None => return Err(Error::invalid("source", "set `points` or `mesh`").into()),
            Some(pb::start_fit_job_request::Source::Points(cloud)) => {
                let points = cv::points_from_proto(&cloud, max)?;
                cv::check_cloud("points", &points, top_degree)?;
                points
            }
            Some(pb::start_fit_job_request::Source::Mesh(mesh)) => {
                if mesh.data.is_empty() {
                    return Err(Error::invalid("mesh.data", "must not be empty").into());
                }
                let format = cv::mesh_format_from_proto(&mesh)?;
                blocking(move || {
                    let points = parse_points_limited(&mesh.data, format, max)?;
                    cv::check_point_count("mesh", points.len(), max)?;
                    cv::check_cloud("mesh", &points, top_degree)?;
                    Ok(points)
                })
                .await?
            }
        };
        let job_id = self.jobs.start(req.name, points, settings, fit.auto).await?;
        Ok(Response::new(pb::StartFitJobResponse { job_id }))
    }

    type WatchFitJobStream = ReceiverStream<Result<pb::FitJobUpdate, Status>>;

    async fn watch_fit_job(&self, request: Request<pb::WatchFitJobRequest>) -> Reply<Self::WatchFitJobStream> {
        let job_id = request.into_inner().job_id;
        let mut rx = self.jobs.watch(require_id("job_id", &job_id)?)?;
        let mut stop = self.jobs.stop_signal();
        let (tx, out) = tokio::sync::mpsc::channel(16);
        tokio::spawn(async move {
            let shutting_down =
                || Status::unavailable("server shutting down: the job is interrupted; no body will be stored");
            loop {
                let update = rx.borrow_and_update().clone();
                let done = is_terminal(&update);
                if tx.send(Ok(update)).await.is_err() || done {
                    break;
                }
                if *stop.borrow() {
                    let _ = tx.send(Err(shutting_down())).await;
                    break;
                }
                tokio::select! {
                    changed = rx.changed() => if changed.is_err() {
                        // The job's task ended without a terminal update (runtime shutting down).
                        let _ = tx.send(Err(shutting_down())).await;
                        break;
                    },
                    _ = stop.changed() => {
                        let _ = tx.send(Err(shutting_down())).await;
                        break;
                    }
                }
            }
        });
        Ok(Response::new(ReceiverStream::new(out)))
    }

    async fn get_fit_job(&self, request: Request<pb::GetFitJobRequest>) -> Reply<pb::GetFitJobResponse> {
        let job_id = request.into_inner().job_id;
        let job = self.jobs.get(require_id("job_id", &job_id)?)?;
        Ok(Response::new(pb::GetFitJobResponse { job: Some(job) }))
    }

    async fn list_fit_jobs(&self, request: Request<pb::ListFitJobsRequest>) -> Reply<pb::ListFitJobsResponse> {
        let req = request.into_inner();
        let (jobs, next_page_token) =
            cv::page(self.jobs.list(), |j| j.job_id.as_str(), req.page_size, &req.page_token)?;
        Ok(Response::new(pb::ListFitJobsResponse { jobs, next_page_token }))
    }

    async fn cancel_fit_job(&self, request: Request<pb::CancelFitJobRequest>) -> Reply<pb::CancelFitJobResponse> {
        let job_id = request.into_inner().job_id;
        let job = self.jobs.cancel(require_id("job_id", &job_id)?).await?;
        Ok(Response::new(pb::CancelFitJobResponse { job: Some(job) }))
    }

    async fn upload_body(&self, request: Request<pb::UploadBodyRequest>) -> Reply<pb::UploadBodyResponse> {
        let req = request.into_inner();
        let upload = match req.body {
            None => return Err(Error::invalid("body", "set `body_json` or `data`").into()),
            Some(pb::upload_body_request::Body::BodyJson(text)) => {
                let value: serde_json::Value =
                    serde_json::from_str(&text).map_err(|e| Error::invalid("body_json", e.to_string()))?;
                if crate::compound::file::is_compound_json(&value) {
                    // A compound body (issue 14): a containment tree of bodies.
                    let file: crate::compound::CompoundFile =
                        serde_json::from_value(value).map_err(|e| Error::invalid("body_json", e.to_string()))?;
                    Upload::Compound(file)
                } else {
                    let mut file: BodyFile =
                        serde_json::from_value(value).map_err(|e| Error::invalid("body_json", e.to_string()))?;
                    if file.report.method.is_empty() {
                        file.report = cv::uploaded_report();
                    }
                    Upload::Single(Box::new(file), "body_json")
                }
            }
            Some(pb::upload_body_request::Body::Data(data)) => {
                Upload::Single(Box::new(cv::body_file_from_proto(&data)?), "data")
            }
        };
        if req.name.len() > crate::scene::MAX_NAME_BYTES {
            return Err(Error::invalid("name", format!("at most {} bytes", crate::scene::MAX_NAME_BYTES)).into());
        }
        check_room(limits::BODIES, self.catalog.bodies().len(), self.config.max_bodies)?;
        let catalog = self.catalog.clone();
        // The sos-convexity certificate is an SDP (one per node of a compound body): off the
        // async workers, like the store write.
        let (body_id, nonconvex, margin, nodes) = blocking(move || match upload {
            Upload::Single(file, prefix) => {
                let admitted = admit_uploaded(*file).map_err(|e| prefix_field(e, prefix))?;
                let nonconvex = admitted.body.report.nonconvex;
                let margin = admitted.certificate.as_ref().map_or(f64::NAN, |c| c.margin);
                let id = catalog.add_body(&req.name, admitted.body)?;
                Ok((id, nonconvex, margin, 1))
            }
            Upload::Compound(file) => {
                let (tree, margin) = cv::admit_compound(file, "body_json")?;
                let nodes = tree.node_count();
                let id = catalog.add_compound_body(&req.name, tree)?;
                Ok((id, false, margin, nodes))
            }
        })
        .await?;
        let nodes = u32::try_from(nodes).unwrap_or(u32::MAX);
        Ok(Response::new(pb::UploadBodyResponse { body_id, nonconvex, convexity_margin: margin, nodes }))
    }

    async fn get_body(&self, request: Request<pb::GetBodyRequest>) -> Reply<pb::GetBodyResponse> {
        let req = request.into_inner();
        let entry = self.catalog.body(require_id("body_id", &req.body_id)?)?;
        let file = entry.body.to_file();
        let body_json = match &entry.tree {
            Some(tree) => serde_json::to_string(&tree.to_file()),
            None => serde_json::to_string(&file),
        }
        .map_err(Error::from)?;
        Ok(Response::new(pb::GetBodyResponse {
            body_id: entry.id.clone(),
            name: entry.name.clone(),
            data: Some(cv::body_file_to_proto(&file)),
            body_json,
            nodes: u32::try_from(entry.node_count()).unwrap_or(u32::MAX),
        }))
    }

    async fn list_bodies(&self, request: Request<pb::ListBodiesRequest>) -> Reply<pb::ListBodiesResponse> {
        let req = request.into_inner();
        let (page, next_page_token) =
            cv::page(self.catalog.bodies(), |e| e.id.as_str(), req.page_size, &req.page_token)?;
        let bodies = page.iter().map(|e| cv::body_summary(e)).collect();
        Ok(Response::new(pb::ListBodiesResponse { bodies, next_page_token }))
    }

    async fn delete_body(&self, request: Request<pb::DeleteBodyRequest>) -> Reply<pb::DeleteBodyResponse> {
        let id = request.into_inner().body_id;
        require_id("body_id", &id)?;
        let catalog = self.catalog.clone();
        blocking(move || catalog.delete_body(&id)).await?;
        Ok(Response::new(pb::DeleteBodyResponse {}))
    }

    async fn create_scene(&self, request: Request<pb::CreateSceneRequest>) -> Reply<pb::CreateSceneResponse> {
        let name = request.into_inner().name;
        check_room(limits::SCENES, self.catalog.scenes().len(), self.config.max_scenes)?;
        let catalog = self.catalog.clone();
        let scene_id = blocking(move || catalog.create_scene(&name)).await?;
        Ok(Response::new(pb::CreateSceneResponse { scene_id }))
    }

    async fn get_scene(&self, request: Request<pb::GetSceneRequest>) -> Reply<pb::GetSceneResponse> {
        let id = request.into_inner().scene_id;
        let scene = self.catalog.get_scene(require_id("scene_id", &id)?)?;
        Ok(Response::new(cv::scene_to_proto(&scene)))
    }

    async fn list_scenes(&self, request: Request<pb::ListScenesRequest>) -> Reply<pb::ListScenesResponse> {
        let req = request.into_inner();
        let (page, next_page_token) =
            cv::page(self.catalog.scenes(), |s| s.id.as_str(), req.page_size, &req.page_token)?;
        let scenes = page
            .into_iter()
            .map(|s| pb::SceneSummary {
                scene_id: s.id,
                name: s.name,
                num_instances: u32::try_from(s.instances.len()).unwrap_or(u32::MAX),
            })
            .collect();
        Ok(Response::new(pb::ListScenesResponse { scenes, next_page_token }))
    }

    async fn delete_scene(&self, request: Request<pb::DeleteSceneRequest>) -> Reply<pb::DeleteSceneResponse> {
        let id = request.into_inner().scene_id;
        require_id("scene_id", &id)?;
        let catalog = self.catalog.clone();
        blocking(move || catalog.delete_scene(&id)).await?;
        Ok(Response::new(pb::DeleteSceneResponse {}))
    }

    async fn add_instance(&self, request: Request<pb::AddInstanceRequest>) -> Reply<pb::AddInstanceResponse> {
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        require_id("body_id", &req.body_id)?;
        let pose = cv::pose_from_proto("pose", req.pose.as_ref())?;
        let held = self.catalog.get_scene(&req.scene_id)?.instances.len();
        check_room(limits::INSTANCES, held, self.config.max_instances_per_scene)?;
        let catalog = self.catalog.clone();
        let instance_id = blocking(move || catalog.add_instance(&req.scene_id, &req.body_id, pose)).await?;
        Ok(Response::new(pb::AddInstanceResponse { instance_id }))
    }

    async fn set_poses(&self, request: Request<pb::SetPosesRequest>) -> Reply<pb::SetPosesResponse> {
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        let poses = cv::poses_from_proto(&req.poses, self.config.max_poses_per_call)?;
        // On the blocking pool: a pose commit is redb's eventual durability, which still writes
        // (and may sync) the file, so it must not sit on an async worker.
        let catalog = self.catalog.clone();
        let updated = blocking(move || catalog.set_poses(&req.scene_id, &poses)).await?;
        Ok(Response::new(pb::SetPosesResponse { updated: u32::try_from(updated).unwrap_or(u32::MAX) }))
    }

    async fn remove_instance(&self, request: Request<pb::RemoveInstanceRequest>) -> Reply<pb::RemoveInstanceResponse> {
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        require_id("instance_id", &req.instance_id)?;
        let catalog = self.catalog.clone();
        blocking(move || catalog.remove_instance(&req.scene_id, &req.instance_id)).await?;
        Ok(Response::new(pb::RemoveInstanceResponse {}))
    }

    async fn distance(&self, request: Request<pb::DistanceRequest>) -> Reply<pb::DistanceResponse> {
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        require_id("instance_a", &req.instance_a)?;
        require_id("instance_b", &req.instance_b)?;
        let tolerance = cv::tree_tolerance("tolerance", req.tolerance)?;
        let options = crate::scene::QueryOptions {
            signed: req.signed,
            tolerance,
            ..cv::query_options(req.certify, req.with_gradient)
        };
        let scene = req.scene_id.clone();
        let r = query_work(
            &self.catalog,
            &self.sdp,
            &scene,
            req.certify,
            1,
            move |c, mode| {
                let options = QueryOptions { mode: mode.unwrap_or(options.mode), ..options };
                c.distance_with(&req.scene_id, &req.instance_a, &req.instance_b, &options)
            },
            |r| r.answer.needs_sdp,
        )
        .await?;
        let answer = cv::distance_reply_to_proto(&r);
        super::metrics::query_answer("distance", answer.solve.as_ref(), answer.source);
        Ok(Response::new(pb::DistanceResponse { answer: Some(answer) }))
    }

    async fn growth(&self, request: Request<pb::GrowthRequest>) -> Reply<pb::GrowthResponse> {
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        require_id("instance_1", &req.instance_1)?;
        require_id("instance_2", &req.instance_2)?;
        let options = cv::query_options(req.certify, req.with_gradient);
        let scene = req.scene_id.clone();
        let r = query_work(
            &self.catalog,
            &self.sdp,
            &scene,
            req.certify,
            1,
            move |c, mode| {
                let options = QueryOptions { mode: mode.unwrap_or(options.mode), ..options };
                c.growth_with(&req.scene_id, &req.instance_1, &req.instance_2, &options)
            },
            |r| r.answer.needs_sdp,
        )
        .await?;
        let answer = cv::growth_reply_to_proto(&r);
        super::metrics::query_answer("growth", answer.solve.as_ref(), answer.source);
        Ok(Response::new(pb::GrowthResponse { answer: Some(answer) }))
    }

    async fn batch_query(&self, request: Request<pb::BatchQueryRequest>) -> Reply<pb::BatchQueryResponse> {
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        if let Some(columns) = req.columns {
            if !req.pairs.is_empty() {
                return Err(Error::invalid("columns", "set either `pairs` or `columns`, not both").into());
            }
            let c = cv::pair_columns_from_proto(&columns, self.config.max_batch_pairs)?;
            let (scene, n, kind) = (req.scene_id.clone(), c.first.len(), c.kind);
            let answers = query_work(
                &self.catalog,
                &self.sdp,
                &scene,
                false,
                n,
                move |catalog, mode| {
                    catalog.batch_columns(
                        &req.scene_id,
                        &c.instance_ids,
                        (&c.first, &c.second),
                        c.kind,
                        QueryOptions { mode: mode.unwrap_or_default(), cold: c.cold, ..QueryOptions::default() },
                        c.margin,
                    )
                },
                |a| a.iter().any(QueryAnswer::needs_sdp),
            )
            .await?;
            let columns = Some(cv::answers_to_columns(kind, &answers));
            return Ok(Response::new(pb::BatchQueryResponse { answers: Vec::new(), columns }));
        }
        let pairs = cv::pairs_from_proto(&req.pairs, self.config.max_batch_pairs)?;
        let certify = pairs.iter().any(|p| p.options.mode == CertifyMode::Certify);
        let (scene, n) = (req.scene_id.clone(), pairs.len());
        let answers = query_work(
            &self.catalog,
            &self.sdp,
            &scene,
            certify,
            n,
            move |c, mode| c.batch_with(&req.scene_id, &pairs, mode),
            |a| a.iter().any(QueryAnswer::needs_sdp),
        )
        .await?;
        let answers: Vec<pb::QueryAnswer> = answers.iter().map(cv::answer_to_proto).collect();
        super::metrics::batch_answers(&answers);
        Ok(Response::new(pb::BatchQueryResponse { answers, columns: None }))
    }

    async fn start_group_job(&self, request: Request<pb::StartGroupJobRequest>) -> Reply<pb::StartGroupJobResponse> {
        use crate::fit::containment::{ContainmentSettings, CONTAINMENT_DEGREES, MAX_CONTAINED_BODIES};
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        let degree = req.degree as usize;
        if !CONTAINMENT_DEGREES.contains(&degree) {
            return Err(Error::invalid("degree", format!("must be 2, 4 or 6, got {}", req.degree)).into());
        }
        let settings = ContainmentSettings {
            degree,
            multiplier_degree: req.multiplier_degree as usize,
            volume_samples: self.config.fit.volume_samples,
            seed: self.config.fit.seed,
            solver_tolerance: self.config.fit.solver_tolerance,
            max_solver_iterations: self.config.fit.max_solver_iterations,
            linear_solver: self.config.fit.linear_solver,
        };
        settings.validate()?;
        if req.name.len() > crate::scene::MAX_NAME_BYTES {
            return Err(Error::invalid("name", format!("at most {} bytes", crate::scene::MAX_NAME_BYTES)).into());
        }
        let mut seen = std::collections::HashSet::new();
        for (k, id) in req.instance_ids.iter().enumerate() {
            require_id(&format!("instance_ids[{k}]"), id)?;
            if !seen.insert(id.as_str()) {
                return Err(Error::invalid("instance_ids", format!("instance `{id}` appears twice")).into());
            }
        }
        let too_many = |n: usize| {
            Status::from(Error::ResourceExhausted(format!(
                "instance_ids: at most {MAX_CONTAINED_BODIES} instances per group, got {n}"
            )))
        };
        if req.instance_ids.len() > MAX_CONTAINED_BODIES {
            return Err(too_many(req.instance_ids.len()));
        }
        let instances = self.catalog.posed_instances(&req.scene_id, &req.instance_ids)?;
        if instances.is_empty() {
            return Err(Error::invalid("instance_ids", "fewer than 1 instance to group (the scene is empty)").into());
        }
        if instances.len() > MAX_CONTAINED_BODIES {
            return Err(too_many(instances.len()));
        }
        let job = GroupJob { scene_id: req.scene_id, instances, name: req.name, replace: req.replace, settings };
        let job_id = self.jobs.start_group(job).await?;
        Ok(Response::new(pb::StartGroupJobResponse { job_id }))
    }

    async fn query(&self, request: Request<pb::QueryRequest>) -> Reply<pb::QueryResponse> {
        let start = std::time::Instant::now();
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        let planner =
            cv::planner_request_from_proto(&req, self.config.max_batch_pairs, self.config.max_poses_per_call)?;
        let view = QueryView::new(&req.scene_id);
        let (_, reply) = answer_planner(self.catalog.clone(), &self.sdp, view, &req, planner, start).await;
        Ok(Response::new(reply?))
    }

    type QueryStreamStream = std::pin::Pin<Box<dyn Stream<Item = Result<pb::QueryResponse, Status>> + Send>>;

    async fn query_stream(
        &self,
        request: Request<tonic::Streaming<pb::QueryRequest>>,
    ) -> Reply<Self::QueryStreamStream> {
        // The response stream is driven by the connection itself: each poll reads the next
        // request and answers it (no task and channel between them, so a planner step costs no
        // thread hand-over). It ends after the client's last request or the first error.
        let state = QueryStreamState {
            inbound: request.into_inner(),
            catalog: self.catalog.clone(),
            sdp: self.sdp.clone(),
            view: None,
            limits: (self.config.max_batch_pairs, self.config.max_poses_per_call),
            done: false,
        };
        let out = futures_util::stream::unfold(state, |mut st| async move {
            if st.done {
                return None;
            }
            let reply = match st.inbound.message().await {
                Ok(Some(req)) => st.answer(req).await,
                Ok(None) => return None,
                Err(status) => Err(status),
            };
            st.done = reply.is_err();
            Some((reply, st))
        });
        Ok(Response::new(Box::pin(out)))
    }

    async fn check_scene(&self, request: Request<pb::CheckSceneRequest>) -> Reply<pb::CheckSceneResponse> {
        let start = std::time::Instant::now();
        let req = request.into_inner();
        require_id("scene_id", &req.scene_id)?;
        for (k, id) in req.instance_ids.iter().enumerate() {
            require_id(&format!("instance_ids[{k}]"), id)?;
        }
        let overrides = cv::poses_from_proto(&req.poses, self.config.max_poses_per_call)?;
        let catalog = self.catalog.clone();
        // Up to n(n−1)/2 solves: off the async workers, cancelled with the request.
        let check = limits::cancellable_blocking(move || {
            crate::scene::planner::check_scene(&catalog, &req.scene_id, req.margin, &req.instance_ids, &overrides)
        })
        .await?;
        Ok(Response::new(cv::scene_check_to_proto(&check, start.elapsed().as_secs_f64())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::ellipsoid;
    use crate::math::pose_from_parts;
    use crate::query::{AnswerSource, NewtonParams};
    use crate::scene::planner::{CandidateStates, PlannerAnswers};
    use crate::scene::store::MemoryStore;

    /// A catalog whose Newton solver stops after one iteration (so it never converges on two
    /// ellipsoids) with a scene of two separated ellipsoids: (catalog, scene, a, b).
    fn one_iteration_scene() -> (Arc<Catalog>, String, String, String) {
        let params = NewtonParams { max_iterations: 1, ..NewtonParams::default() };
        let catalog = Catalog::open(Box::new(MemoryStore::new()), params).unwrap();
        let b1 = catalog.add_body("e1", ellipsoid([0.0; 3], [0.5, 0.2, 0.3]).unwrap()).unwrap();
        let b2 = catalog.add_body("e2", ellipsoid([0.0; 3], [0.25, 0.4, 0.2]).unwrap()).unwrap();
        let s = catalog.create_scene("s").unwrap();
        let q = [0.9238795325112867, 0.0, 0.3826834323650898, 0.0];
        let a =
            catalog.add_instance(&s, &b1, pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0; 3]).unwrap()).unwrap();
        let b = catalog.add_instance(&s, &b2, pose_from_parts("pose", q, [1.5, 0.3, -0.2]).unwrap()).unwrap();
        (Arc::new(catalog), s, a, b)
    }

    /// Newton does not converge: the inline mode (`NewtonOnly`) reports "needs the SDP" without
    /// solving one and keeps no warm start; the service (which answers such a request inline
    /// first) returns exactly the SDP fallback's answer of a catalog asked directly.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn an_unconverged_newton_answer_is_solved_off_the_workers_with_the_fallback() {
        let (catalog, s, a, b) = one_iteration_scene();
        let only = QueryOptions { mode: CertifyMode::NewtonOnly, ..QueryOptions::default() };
        let inline = catalog.distance_with(&s, &a, &b, &only).unwrap();
        assert!(inline.answer.needs_sdp);
        assert!(!inline.answer.converged);
        assert_eq!(inline.answer.source, AnswerSource::Newton);
        assert!(inline.answer.certificate.is_none(), "no SDP was solved");
        assert_eq!(catalog.cached_warm_starts(&s).unwrap(), 0, "an answer needing the SDP keeps no warm start");
        let g = catalog.growth_with(&s, &a, &b, &only).unwrap();
        assert!(g.answer.needs_sdp && g.answer.certificate.is_none());
        // A planner view: no answers, no warm starts kept.
        let mut view = QueryView::new(&s);
        assert!(view.run_newton_only(&catalog, &request_of(&a, &b)).unwrap().is_none());
        assert_eq!(view.warm_starts(), 0);

        // The reference: a fresh identical catalog asked in the normal mode (the fallback SDP).
        let (reference, rs, ra, rb) = one_iteration_scene();
        let want = reference.distance_with(&rs, &ra, &rb, &QueryOptions::default()).unwrap();
        assert_eq!(want.answer.source, AnswerSource::SdpFallback);
        assert!(want.answer.converged);
        let want_growth = reference.growth_with(&rs, &ra, &rb, &QueryOptions::default()).unwrap();
        assert_eq!(want_growth.answer.source, AnswerSource::SdpFallback);

        let service = SublevelService::new(catalog.clone(), crate::service::ServerConfig::default());
        let request = pb::DistanceRequest {
            scene_id: s.clone(),
            instance_a: a.clone(),
            instance_b: b.clone(),
            ..Default::default()
        };
        let got = service.distance(Request::new(request)).await.unwrap().into_inner().answer.unwrap();
        assert_eq!(got.source, pb::AnswerSource::SdpFallback as i32);
        assert!(got.solve.as_ref().unwrap().converged);
        assert!(want.answer.result.distance > 0.1, "{}", want.answer.result.distance);
        assert!(
            (got.distance - want.answer.result.distance).abs() <= 1e-12,
            "{} vs {}",
            got.distance,
            want.answer.result.distance
        );
        let request = pb::GrowthRequest {
            scene_id: s.clone(),
            instance_1: a.clone(),
            instance_2: b.clone(),
            ..Default::default()
        };
        let got = service.growth(Request::new(request)).await.unwrap().into_inner().answer.unwrap();
        assert_eq!(got.source, pb::AnswerSource::SdpFallback as i32);
        assert!(
            (got.value - want_growth.answer.result.value).abs()
                <= 1e-12 * want_growth.answer.result.value.abs().max(1.0)
        );

        // The planner path: the view answers the fallback's value too.
        let request = request_of(&a, &b);
        let answers = PlannerAnswers::for_request(&request);
        let (view, out) = run_view(catalog.clone(), &service.sdp, QueryView::new(&s), request, answers).await;
        let PlannerAnswers::Single(answers) = out.unwrap() else { panic!("one list of answers") };
        let crate::scene::QueryAnswer::Distance(d) = &answers[0] else { panic!("a distance answer") };
        assert_eq!(d.answer.source, AnswerSource::SdpFallback);
        assert!(!d.answer.needs_sdp);
        assert!((d.answer.result.distance - want.answer.result.distance).abs() <= 1e-12);
        assert_eq!(view.warm_starts(), 1, "the blocking run keeps its warm start");

        // States and answers in columns (rows written as solved): the inline run stops at the
        // first row needing the SDP and clears what it wrote; the blocking run gives the
        // fallback's distance on the first row, and the rows after it (warm-started from it, so
        // Newton converges there) agree within 1e-9 m.
        let pose_b = pose_from_parts("pose", [0.9238795325112867, 0.0, 0.3826834323650898, 0.0], [1.5, 0.3, -0.2]);
        let states = CandidateStates::Columns { instance_ids: vec![b.clone()], poses: vec![pose_b.unwrap(); 3] };
        let request = PlannerRequest { states, ..request_of(&a, &b) };
        let mut sink = cv::ColumnsSink::new(crate::scene::QueryKind::Distance, 3);
        assert!(!QueryView::new(&s).run_newton_only_into(&catalog, &request, &mut sink).unwrap());
        assert!(sink.finish().value.is_empty(), "the inline run's rows are cleared");
        let sink = cv::ColumnsSink::new(crate::scene::QueryKind::Distance, 3);
        let (_, out) = run_view(catalog.clone(), &service.sdp, QueryView::new(&s), request, sink).await;
        let rows = out.unwrap().finish();
        assert_eq!(rows.value.len(), 3);
        for (k, v) in rows.value.iter().enumerate() {
            let tol = if k == 0 { 1e-12 } else { 1e-9 };
            assert!((v - want.answer.result.distance).abs() <= tol, "row {k}: {v} vs {}", want.answer.result.distance);
            assert!(rows.converged[k] && !rows.lower_bound[k]);
        }
    }

    /// States in columns built in-process (not through the converter) are validated by the view:
    /// a pose count that is no multiple of the instances, a repeated and an unknown instance are
    /// refused naming the field, and the view is left unchanged.
    #[test]
    fn a_view_refuses_bad_state_columns_naming_the_field() {
        let (catalog, s, a, b) = one_iteration_scene();
        let pose = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 3.0]).unwrap();
        let columns = |ids: &[&str], poses: usize| PlannerRequest {
            states: CandidateStates::Columns {
                instance_ids: ids.iter().map(|id| (*id).to_owned()).collect(),
                poses: vec![pose; poses],
            },
            ..request_of(&a, &b)
        };
        let field_of = |request: &PlannerRequest| match QueryView::new(&s).run(&catalog, request) {
            Err(crate::Error::InvalidArgument { field, .. }) => field,
            other => panic!("expected INVALID_ARGUMENT, got {other:?}"),
        };
        assert_eq!(field_of(&columns(&[&a, &b], 3)), "state_columns.poses");
        assert_eq!(field_of(&columns(&[], 0)), "state_columns.poses");
        assert_eq!(field_of(&columns(&[&b, &a, &b], 3)), "state_columns.instance_ids[2]");
        assert_eq!(field_of(&columns(&[&a, "i-nowhere"], 4)), "state_columns.instance_ids[1]");
        let mut view = QueryView::new(&s);
        assert!(view.run(&catalog, &columns(&[&a, "i-nowhere"], 4)).is_err());
        assert_eq!(view.warm_starts(), 0);
        // Two valid states: one answer list per state.
        let PlannerAnswers::PerState(states) = view.run(&catalog, &columns(&[&a, &b], 4)).unwrap() else {
            panic!("answers per state");
        };
        assert_eq!(states.iter().map(Vec::len).collect::<Vec<_>>(), [1, 1]);
    }

    fn request_of(a: &str, b: &str) -> PlannerRequest {
        let pair = crate::scene::QueryPair {
            kind: crate::scene::QueryKind::Distance,
            first: a.to_owned(),
            second: b.to_owned(),
            options: QueryOptions::default(),
            margin: 0.0,
        };
        PlannerRequest { queries: vec![pair], ..PlannerRequest::default() }
    }
}
