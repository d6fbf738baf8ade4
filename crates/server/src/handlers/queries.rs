//! Queries: `Distance`, `Growth`, `BatchQuery`, `Query`, `QueryStream`, `CheckScene`, and where
//! their work runs: inline on the async workers when it is microseconds of Newton solves, on the
//! batch slots of the blocking pool when it is more Newton work than that, on the SDP slots when
//! it needs an SDP ([`off_workers`], [`crate::limits`]).

use super::robots::RobotChecks;
use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id, to_status};
use crate::limits::QueryPools;
use crate::pb;
use crate::{Error, Result};
use std::sync::Arc;
use sublevel_query::CertifyMode;
use sublevel_scene::planner::{AnswerSink, PlannerAnswers, PlannerRequest, QueryView};
use sublevel_scene::{Catalog, QueryAnswer, QueryOptions};
use tokio_stream::Stream;
use tonic::{Request, Response, Status};

/// The response stream of `QueryStream`: driven by the connection itself (see [`query_stream`]).
pub(super) type QueryStream = std::pin::Pin<Box<dyn Stream<Item = Result<pb::QueryResponse, Status>> + Send>>;

/// Answers a planner request on a view into `sink`: inline on the async worker when it holds
/// only a few Newton queries (microseconds each), on the batch slots when it holds more, on the
/// SDP slots when one asks for a certificate or the scene is nonconvex. An answer that needs the
/// SDP sends the whole request on to the SDP slots. Returns the view (moved back out of the
/// blocking pool) with the filled sink.
pub(super) async fn run_view<S: AnswerSink + Send + 'static>(
    catalog: Arc<Catalog>,
    pools: &QueryPools,
    mut view: QueryView,
    request: PlannerRequest,
    mut sink: S,
) -> (QueryView, Result<S, Status>) {
    let certify = request.queries.iter().any(|q| q.options.mode == CertifyMode::Certify);
    let answers = request.queries.len() * request.states.len().max(1);
    let scene = view.scene_id().to_owned();
    let mut request = request;
    if !off_workers(&catalog, view.scene_id(), certify, answers) {
        // Newton only: an answer that needs the SDP sends the whole request to the blocking pool.
        match view.run_newton_only_into(&catalog, &request, &mut sink) {
            Ok(true) => return (view, Ok(sink)),
            Ok(false) => {}
            Err(e) => return (view, Err(to_status(e))),
        }
    } else if !needs_sdp_slots(&catalog, &scene, certify) {
        let c = catalog.clone();
        let batch = pools
            .batch
            .run(move || {
                let done = view.run_newton_only_into(&c, &request, &mut sink);
                Ok((view, request, sink, done))
            })
            .await;
        match batch {
            Ok((v, _, s, Ok(true))) => return (v, Ok(s)),
            Ok((v, r, s, Ok(false))) => (view, request, sink) = (v, r, s),
            Ok((v, _, _, Err(e))) => return (v, Err(to_status(e))),
            Err(e) => return (QueryView::new(&scene), Err(e)),
        }
    }
    match pools
        .sdp
        .run(move || {
            let out = view.run_into(&catalog, &request, &mut sink).map(|()| sink);
            Ok((view, out))
        })
        .await
    {
        Ok((view, out)) => (view, out.map_err(to_status)),
        Err(e) => (QueryView::new(&scene), Err(e)),
    }
}

/// Answers planner request `planner` (validated from `req`) on `view` and builds the reply.
/// States and answers both in columns (the sampling planner's batch) are written to the answer
/// columns as they are solved; every other request collects its answers first.
async fn answer_planner(
    catalog: Arc<Catalog>,
    pools: &QueryPools,
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
            let (view, out) = run_view(catalog, pools, view, planner, cv::ColumnsSink::new(kind, rows)).await;
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
            let (view, out) = run_view(catalog, pools, view, planner, answers).await;
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

/// Whether blocking query work belongs on the SDP slots from the start: it asks for certificates
/// or its scene holds a nonconvex body (SDP lower bounds); all other blocking work starts on the
/// batch slots.
fn needs_sdp_slots(catalog: &Catalog, scene_id: &str, certify: bool) -> bool {
    certify || catalog.has_nonconvex(scene_id)
}

/// Whether a query request is slow work, to run off the async workers: it asks for certificates
/// (an SDP each), its scene holds a nonconvex body (SDP lower bounds), it has more than
/// [`INLINE_ANSWERS`] answers (counting [`COMPOUND_ANSWER_COST`] per answer in a scene with a
/// compound body), or some stored body is not built yet (after a start, until the warm-up is
/// done: a first use builds the body, milliseconds to seconds). A compound query that needs an
/// SDP (a leaf pair Newton did not resolve) is re-run on the SDP slots as any `needs_sdp` answer
/// is.
fn off_workers(catalog: &Catalog, scene_id: &str, certify: bool, answers: usize) -> bool {
    certify
        || answers > INLINE_ANSWERS
        || catalog.bodies_pending() > 0
        || catalog.has_nonconvex(scene_id)
        || (answers.saturating_mul(COMPOUND_ANSWER_COST) > INLINE_ANSWERS && catalog.has_compound(scene_id))
}

/// Runs query work `f` inline when it is microseconds, on the batch slots when it is more Newton
/// work, on the SDP slots when it needs SDPs (see [`off_workers`], [`needs_sdp_slots`]). `f` gets
/// the certification mode to use instead of the queries' own: inline and on the batch slots
/// [`CertifyMode::NewtonOnly`] (no SDP ever runs there); when `needs_sdp` says an answer needed the
/// SDP fallback, `f` runs again on the SDP slots with the queries' own modes (`None`), which gives
/// the answers a first run there would have given.
async fn query_work<T: Send + 'static>(
    catalog: &Arc<Catalog>,
    pools: &QueryPools,
    scene_id: &str,
    certify: bool,
    answers: usize,
    f: impl Fn(&Catalog, Option<CertifyMode>) -> Result<T> + Send + Sync + 'static,
    needs_sdp: impl Fn(&T) -> bool,
) -> Result<T, Status> {
    let f = Arc::new(f);
    if !off_workers(catalog, scene_id, certify, answers) {
        let out = f(catalog, Some(CertifyMode::NewtonOnly)).map_err(to_status)?;
        if !needs_sdp(&out) {
            return Ok(out);
        }
    } else if !needs_sdp_slots(catalog, scene_id, certify) {
        let (c, work) = (catalog.clone(), f.clone());
        let out = pools.batch.run(move || work(&c, Some(CertifyMode::NewtonOnly))).await?;
        if !needs_sdp(&out) {
            return Ok(out);
        }
    }
    let catalog = catalog.clone();
    pools.sdp.run(move || f(&catalog, None)).await
}

/// The checks a planner request carries beside its queries: robot states and motions, instance
/// motions.
#[derive(Default)]
struct ViewChecks {
    states: Option<pb::CheckConfigurationsRequest>,
    motions: Option<pb::CheckMotionsRequest>,
    instance_motions: Option<pb::CheckInstanceMotionsRequest>,
}

impl ViewChecks {
    /// Takes them out of `req` (the queries are answered without them).
    fn take(req: &mut pb::QueryRequest) -> Self {
        Self {
            states: req.robot_states.take(),
            motions: req.robot_motions.take(),
            instance_motions: req.instance_motions.take(),
        }
    }
}

/// Answers the checks a planner request carries beside its queries ([`ViewChecks`]) on the view
/// the request left (its poses applied), into `reply`.
///
/// # Errors
/// INVALID_ARGUMENT naming `robot_states.scene_id` (`robot_motions.`, `instance_motions.`) when
/// it names another scene than the view's; the checks' own errors, their fields prefixed by
/// `robot_states.` (`robot_motions.`, `instance_motions.`).
async fn view_checks(
    robots: &RobotChecks,
    view: &QueryView,
    checks: ViewChecks,
    reply: &mut pb::QueryResponse,
) -> Result<(), Status> {
    let scene = |field: &str, id: &mut String| {
        if id.is_empty() || id == view.scene_id() {
            *id = view.scene_id().to_owned();
            Ok(())
        } else {
            Err(to_status(Error::invalid(format!("{field}.scene_id"), "must be empty or the request's scene")))
        }
    };
    let prefixed = |field: &'static str| {
        move |e: super::HandlerError| match e {
            super::HandlerError::Core(e) => to_status(cv::prefix_field(e, field)),
            other => Status::from(other),
        }
    };
    if let Some(mut req) = checks.states {
        scene("robot_states", &mut req.scene_id)?;
        let out = robots.configurations(req, view.pose_overrides()).await.map_err(prefixed("robot_states"))?;
        reply.robot_states = Some(out);
    }
    if let Some(mut req) = checks.motions {
        scene("robot_motions", &mut req.scene_id)?;
        let out = robots.motions(req, view.pose_overrides()).await.map_err(prefixed("robot_motions"))?;
        reply.robot_motions = Some(out);
    }
    if let Some(mut req) = checks.instance_motions {
        scene("instance_motions", &mut req.scene_id)?;
        let out = super::motions::instance_motions(robots, req, view.pose_overrides())
            .await
            .map_err(prefixed("instance_motions"))?;
        reply.instance_motions = Some(out);
    }
    Ok(())
}

/// One QueryStream: its requests, its private view of the scene (from the first request on).
struct QueryStreamState {
    inbound: tonic::Streaming<pb::QueryRequest>,
    catalog: Arc<Catalog>,
    pools: QueryPools,
    robots: RobotChecks,
    view: Option<QueryView>,
    /// (most answers, most poses) of one request.
    limits: (usize, usize),
    done: bool,
}

impl QueryStreamState {
    /// Answers one request of the stream on its view (created by the first request; later ones
    /// may repeat its scene id or leave it empty).
    async fn answer(&mut self, mut req: pb::QueryRequest) -> Result<pb::QueryResponse, Status> {
        let start = std::time::Instant::now();
        let checks = ViewChecks::take(&mut req);
        let planner = cv::planner_request_from_proto(&req, self.limits.0, self.limits.1).map_err(to_status)?;
        let current = match self.view.take() {
            None => QueryView::new(require_id("scene_id", &req.scene_id).map_err(to_status)?),
            Some(v) if req.scene_id.is_empty() || req.scene_id == v.scene_id() => v,
            Some(v) => {
                let message = format!(
                    "a stream answers one scene: `{}` after `{}`",
                    sublevel_core::error::clip(&req.scene_id),
                    v.scene_id()
                );
                self.view = Some(v);
                return Err(to_status(Error::invalid("scene_id", message)));
            }
        };
        let (back, reply) = answer_planner(self.catalog.clone(), &self.pools, current, &req, planner, start).await;
        let mut reply = reply;
        if let Ok(out) = &mut reply {
            if let Err(e) = view_checks(&self.robots, &back, checks, out).await {
                reply = Err(e);
            } else {
                out.server_seconds = start.elapsed().as_secs_f64();
            }
        }
        self.view = Some(back);
        reply
    }
}

/// `Distance`: the certified distance between two instances ([`query_work`]).
pub(super) async fn distance(
    svc: &SublevelService,
    request: Request<pb::DistanceRequest>,
) -> Handled<pb::DistanceResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    require_id("instance_a", &req.instance_a)?;
    require_id("instance_b", &req.instance_b)?;
    let tolerance = cv::tree_tolerance("tolerance", req.tolerance)?;
    let options = sublevel_scene::QueryOptions {
        signed: req.signed,
        tolerance,
        ..cv::query_options(req.certify, req.with_gradient)
    };
    let scene = req.scene_id.clone();
    let r = query_work(
        &svc.catalog,
        &svc.pools,
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
    crate::metrics::query_answer("distance", answer.solve.as_ref(), answer.source);
    Ok(Response::new(pb::DistanceResponse { answer: Some(answer) }))
}

/// `Growth`: the certified growth measure between two instances ([`query_work`]).
pub(super) async fn growth(svc: &SublevelService, request: Request<pb::GrowthRequest>) -> Handled<pb::GrowthResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    require_id("instance_1", &req.instance_1)?;
    require_id("instance_2", &req.instance_2)?;
    let options = cv::query_options(req.certify, req.with_gradient);
    let scene = req.scene_id.clone();
    let r = query_work(
        &svc.catalog,
        &svc.pools,
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
    crate::metrics::query_answer("growth", answer.solve.as_ref(), answer.source);
    Ok(Response::new(pb::GrowthResponse { answer: Some(answer) }))
}

/// `BatchQuery`: many queries of one scene, as pairs or as columns ([`query_work`]).
pub(super) async fn batch_query(
    svc: &SublevelService,
    request: Request<pb::BatchQueryRequest>,
) -> Handled<pb::BatchQueryResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    if let Some(columns) = req.columns {
        if !req.pairs.is_empty() {
            return Err(Error::invalid("columns", "set either `pairs` or `columns`, not both").into());
        }
        let c = cv::pair_columns_from_proto(&columns, svc.config.max_batch_pairs)?;
        let (scene, n, kind) = (req.scene_id.clone(), c.first.len(), c.kind);
        let answers = query_work(
            &svc.catalog,
            &svc.pools,
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
    let pairs = cv::pairs_from_proto(&req.pairs, svc.config.max_batch_pairs)?;
    let certify = pairs.iter().any(|p| p.options.mode == CertifyMode::Certify);
    let (scene, n) = (req.scene_id.clone(), pairs.len());
    let answers = query_work(
        &svc.catalog,
        &svc.pools,
        &scene,
        certify,
        n,
        move |c, mode| c.batch_with(&req.scene_id, &pairs, mode),
        |a| a.iter().any(QueryAnswer::needs_sdp),
    )
    .await?;
    let answers: Vec<pb::QueryAnswer> = answers.iter().map(cv::answer_to_proto).collect();
    crate::metrics::batch_answers(&answers);
    Ok(Response::new(pb::BatchQueryResponse { answers, columns: None }))
}

/// `Query`: a planner request on a fresh view of the scene ([`answer_planner`]).
pub(super) async fn query(svc: &SublevelService, request: Request<pb::QueryRequest>) -> Handled<pb::QueryResponse> {
    let start = std::time::Instant::now();
    let mut req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let checks = ViewChecks::take(&mut req);
    let planner = cv::planner_request_from_proto(&req, svc.config.max_batch_pairs, svc.config.max_poses_per_call)?;
    let view = QueryView::new(&req.scene_id);
    let (view, reply) = answer_planner(svc.catalog.clone(), &svc.pools, view, &req, planner, start).await;
    let mut reply = reply?;
    view_checks(&RobotChecks::of(svc), &view, checks, &mut reply).await?;
    reply.server_seconds = start.elapsed().as_secs_f64();
    Ok(Response::new(reply))
}

/// `QueryStream`: planner requests on one view of a scene for the stream's lifetime.
pub(super) async fn query_stream(
    svc: &SublevelService,
    request: Request<tonic::Streaming<pb::QueryRequest>>,
) -> Handled<QueryStream> {
    // The response stream is driven by the connection itself: each poll reads the next
    // request and answers it (no task and channel between them, so a planner step costs no
    // thread hand-over). It ends after the client's last request or the first error.
    let state = QueryStreamState {
        inbound: request.into_inner(),
        catalog: svc.catalog.clone(),
        pools: svc.pools.clone(),
        robots: RobotChecks::of(svc),
        view: None,
        limits: (svc.config.max_batch_pairs, svc.config.max_poses_per_call),
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

/// `CheckScene`: every pair of a scene closer than a margin, off the async workers and cancelled
/// with the request.
pub(super) async fn check_scene(
    svc: &SublevelService,
    request: Request<pb::CheckSceneRequest>,
) -> Handled<pb::CheckSceneResponse> {
    let start = std::time::Instant::now();
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    for (k, id) in req.instance_ids.iter().enumerate() {
        require_id(&format!("instance_ids[{k}]"), id)?;
    }
    let overrides = cv::poses_from_proto(&req.poses, svc.config.max_poses_per_call)?;
    let catalog = svc.catalog.clone();
    // Up to n(n−1)/2 solves: on the batch slots (the SDP slots for a nonconvex scene), cancelled
    // with the request.
    let slots = if svc.catalog.has_nonconvex(&req.scene_id) { &svc.pools.sdp } else { &svc.pools.batch };
    let (check, robot) = slots
        .run(move || {
            // The pairs and the robot read the scene apart: should it change in between, both are
            // read again (a few times at most), so that the answer is of one scene version.
            let mut attempt = 0;
            loop {
                attempt += 1;
                let check = sublevel_scene::planner::check_scene(
                    &catalog,
                    &req.scene_id,
                    req.margin,
                    &req.instance_ids,
                    &overrides,
                )?;
                // The scene's robot, at its joint positions, within the margin as padding.
                let options =
                    sublevel_robot::CheckOptions { padding: req.margin, distance: true, ..Default::default() };
                let robot = catalog.check_scene_robot(&req.scene_id, &options, &overrides)?;
                if robot.as_ref().is_some_and(|r| r.world.scene_version != check.scene_version) && attempt < 4 {
                    continue;
                }
                let robot = robot.map(|r| {
                    let mut out = pb::CheckConfigurationsResponse {
                        joint_names: r.placed.robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
                        scene_version: r.world.scene_version,
                        ..Default::default()
                    };
                    cv::push_configuration_answers(&mut out, &[r.answer], &r.placed.robot, &r.world.objects, false);
                    out
                });
                return Ok((check, robot));
            }
        })
        .await?;
    let mut out = cv::scene_check_to_proto(&check, start.elapsed().as_secs_f64());
    out.robot = robot;
    Ok(Response::new(out))
}
