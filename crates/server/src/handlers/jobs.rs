//! Fit and grouping jobs: `StartFitJob` (single and compound fits), `WatchFitJob`, `GetFitJob`,
//! `ListFitJobs`, `CancelFitJob`, `StartGroupJob`.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id, to_status};
use crate::jobs::{is_terminal, GroupJob};
use crate::limits::{self, check_room};
use crate::pb;
use crate::runtime::blocking;
use crate::Error;
use sublevel_fit::mesh::parse_points_limited;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

/// `StartFitJob`: checks the settings and the point cloud or mesh (parsed off the async workers), then
/// starts a fit job; `parts` / `auto_parts` start a compound fit ([`start_compound_fit`]).
pub(super) async fn start_fit_job(
    svc: &SublevelService,
    request: Request<pb::StartFitJobRequest>,
) -> Handled<pb::StartFitJobResponse> {
    let req = request.into_inner();
    let fit = cv::fit_options(&req)?;
    if req.name.len() > sublevel_scene::MAX_NAME_BYTES {
        return Err(Error::invalid("name", format!("at most {} bytes", sublevel_scene::MAX_NAME_BYTES)).into());
    }
    // Every setting is checked before a job exists (a bad combination such as logdet_h with
    // a relaxation is INVALID_ARGUMENT here, not a failed job).
    let mut settings = svc.config.fit.clone();
    settings.degree = fit.degree;
    settings.method = fit.method;
    settings.convexity_relaxation = fit.convexity_relaxation;
    settings.validate()?;
    check_room(limits::BODIES, svc.catalog.bodies().len(), svc.config.max_bodies)?;
    let max = svc.config.max_fit_points;
    if let Some(parts) = cv::part_count(&req)? {
        return start_compound_fit(svc, req, &fit, settings, parts).await;
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
    let job_id = svc.jobs.start(req.name, points, settings, fit.auto).await?;
    Ok(Response::new(pb::StartFitJobResponse { job_id }))
}

/// `StartFitJob` with `parts` / `auto_parts` (a compound fit): the triangle mesh (OFF, OBJ, STL
/// or PLY) is parsed off the async workers, the settings checked, the job started (the fit welds
/// the mesh before decomposing it).
async fn start_compound_fit(
    svc: &SublevelService,
    req: pb::StartFitJobRequest,
    fit: &cv::FitOptions,
    settings: sublevel_fit::FitSettings,
    parts: sublevel_fit::compound::PartCount,
) -> Handled<pb::StartFitJobResponse> {
    let compound = cv::compound_settings(&req, fit, settings)?;
    let mesh = match req.source {
        Some(pb::start_fit_job_request::Source::Mesh(mesh)) => mesh,
        _ => {
            return Err(Error::invalid(
                "mesh",
                "a compound fit (`parts` or `auto_parts`) needs `mesh`: a triangle mesh (OFF, OBJ, STL or PLY)",
            )
            .into())
        }
    };
    if mesh.data.is_empty() {
        return Err(Error::invalid("mesh.data", "must not be empty").into());
    }
    let format = cv::mesh_format_from_proto(&mesh)?;
    if format == sublevel_fit::mesh::MeshFormat::Xyz {
        return Err(Error::invalid(
            "mesh.mesh_format",
            "a compound fit decomposes the mesh's faces: send OFF, OBJ, STL or PLY, not a point cloud",
        )
        .into());
    }
    let max = svc.config.max_fit_points;
    let mesh = blocking(move || {
        let mesh = sublevel_fit::mesh::load_triangle_mesh(&mesh.data, format, max).map_err(|e| match e {
            Error::InvalidArgument { reason, .. } => Error::invalid("mesh.data", reason),
            other => other,
        })?;
        cv::check_point_count("mesh", mesh.vertices.len(), max)?;
        if mesh.triangles.is_empty() {
            return Err(Error::invalid("mesh.data", "the mesh has no faces to decompose"));
        }
        Ok(mesh)
    })
    .await?;
    let job_id = svc.jobs.start_compound(req.name, mesh, parts, compound).await?;
    Ok(Response::new(pb::StartFitJobResponse { job_id }))
}

/// `WatchFitJob`: streams a job's updates until a terminal one, or UNAVAILABLE when the server
/// shuts down first.
pub(super) async fn watch_fit_job(
    svc: &SublevelService,
    request: Request<pb::WatchFitJobRequest>,
) -> Handled<ReceiverStream<Result<pb::FitJobUpdate, Status>>> {
    let job_id = request.into_inner().job_id;
    let mut rx = svc.jobs.watch(require_id("job_id", &job_id)?)?;
    let mut stop = svc.jobs.stop_signal();
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

/// `GetFitJob`: one job's latest update.
pub(super) async fn get_fit_job(
    svc: &SublevelService,
    request: Request<pb::GetFitJobRequest>,
) -> Handled<pb::GetFitJobResponse> {
    let job_id = request.into_inner().job_id;
    let job = svc.jobs.get(require_id("job_id", &job_id)?)?;
    Ok(Response::new(pb::GetFitJobResponse { job: Some(job) }))
}

/// `ListFitJobs`: a page of the jobs, by id.
pub(super) async fn list_fit_jobs(
    svc: &SublevelService,
    request: Request<pb::ListFitJobsRequest>,
) -> Handled<pb::ListFitJobsResponse> {
    let req = request.into_inner();
    let (jobs, next_page_token) =
        cv::page(svc.jobs.list(), |j| j.job_id.as_str(), "j", req.page_size, &req.page_token)?;
    Ok(Response::new(pb::ListFitJobsResponse { jobs, next_page_token }))
}

/// `CancelFitJob`: cancels a job and returns its update.
pub(super) async fn cancel_fit_job(
    svc: &SublevelService,
    request: Request<pb::CancelFitJobRequest>,
) -> Handled<pb::CancelFitJobResponse> {
    let job_id = request.into_inner().job_id;
    let job = svc.jobs.cancel(require_id("job_id", &job_id)?).await?;
    Ok(Response::new(pb::CancelFitJobResponse { job: Some(job) }))
}

/// `StartGroupJob`: checks the containment settings and the instances, then starts a grouping
/// job (paper §V).
pub(super) async fn start_group_job(
    svc: &SublevelService,
    request: Request<pb::StartGroupJobRequest>,
) -> Handled<pb::StartGroupJobResponse> {
    use sublevel_fit::containment::{ContainmentSettings, CONTAINMENT_DEGREES, MAX_CONTAINED_BODIES};
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let degree = req.degree as usize;
    if !CONTAINMENT_DEGREES.contains(&degree) {
        return Err(Error::invalid("degree", format!("must be 2, 4 or 6, got {}", req.degree)).into());
    }
    let settings = ContainmentSettings {
        degree,
        multiplier_degree: req.multiplier_degree as usize,
        volume_samples: svc.config.fit.volume_samples,
        seed: svc.config.fit.seed,
        solver_tolerance: svc.config.fit.solver_tolerance,
        max_solver_iterations: svc.config.fit.max_solver_iterations,
        linear_solver: svc.config.fit.linear_solver,
    };
    settings.validate()?;
    if req.name.len() > sublevel_scene::MAX_NAME_BYTES {
        return Err(Error::invalid("name", format!("at most {} bytes", sublevel_scene::MAX_NAME_BYTES)).into());
    }
    let mut seen = std::collections::HashSet::new();
    for (k, id) in req.instance_ids.iter().enumerate() {
        require_id(&format!("instance_ids[{k}]"), id)?;
        if !seen.insert(id.as_str()) {
            return Err(Error::invalid("instance_ids", format!("instance `{id}` appears twice")).into());
        }
    }
    let too_many = |n: usize| {
        to_status(Error::ResourceExhausted(format!(
            "instance_ids: at most {MAX_CONTAINED_BODIES} instances per group, got {n}"
        )))
    };
    if req.instance_ids.len() > MAX_CONTAINED_BODIES {
        return Err(too_many(req.instance_ids.len()).into());
    }
    let instances = svc.catalog.posed_instances(&req.scene_id, &req.instance_ids)?;
    // A primitive is grouped by its bounding ellipsoid (it contains the primitive); a halfspace
    // has none.
    if let Some(k) = instances.iter().position(|i| i.primitive.is_some_and(|p| !p.is_bounded())) {
        let field = if req.instance_ids.is_empty() { "instance_ids".to_owned() } else { format!("instance_ids[{k}]") };
        let id = &instances[k].id;
        return Err(
            Error::invalid(field, format!("instance `{id}` is a halfspace: no bounded body contains it")).into()
        );
    }
    if instances.is_empty() {
        return Err(Error::invalid("instance_ids", "fewer than 1 instance to group (the scene is empty)").into());
    }
    if instances.len() > MAX_CONTAINED_BODIES {
        return Err(too_many(instances.len()).into());
    }
    let job = GroupJob { scene_id: req.scene_id, instances, name: req.name, replace: req.replace, settings };
    let job_id = svc.jobs.start_group(job).await?;
    Ok(Response::new(pb::StartGroupJobResponse { job_id }))
}
