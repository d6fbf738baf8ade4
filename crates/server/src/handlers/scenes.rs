//! Scenes and their instances: `CreateScene`, `GetScene`, `ListScenes`, `DeleteScene`,
//! `AddInstance`, `SetPoses`, `RemoveInstance`, `ImportScene`.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::jobs::MeshPlacement;
use crate::limits::{self, check_room, check_room_for};
use crate::pb;
use crate::runtime::blocking;
use sublevel_fit::compound::PartCount;
use sublevel_scene::moveit::{ImportPlan, MeshImport};
use tonic::{Request, Response, Status};

/// `CreateScene`: a new empty scene.
pub(super) async fn create_scene(
    svc: &SublevelService,
    request: Request<pb::CreateSceneRequest>,
) -> Handled<pb::CreateSceneResponse> {
    let name = request.into_inner().name;
    check_room(limits::SCENES, svc.catalog.scenes().len(), svc.config.max_scenes)?;
    let catalog = svc.catalog.clone();
    let scene_id = blocking(move || catalog.create_scene(&name)).await?;
    Ok(Response::new(pb::CreateSceneResponse { scene_id }))
}

/// `GetScene`: a scene with its instances and poses.
pub(super) async fn get_scene(
    svc: &SublevelService,
    request: Request<pb::GetSceneRequest>,
) -> Handled<pb::GetSceneResponse> {
    let id = request.into_inner().scene_id;
    require_id("scene_id", &id)?;
    let catalog = svc.catalog.clone();
    // The scene's robot is built (its attached objects added) on first use: off the workers.
    let (scene, robot) = blocking(move || {
        let scene = catalog.get_scene(&id)?;
        // A robot deleted since it was placed is left out here; the checks name it.
        let robot = catalog.placed_robot(&id).ok().flatten();
        Ok((scene, robot))
    })
    .await?;
    Ok(Response::new(cv::scene_to_proto(&scene, robot.as_deref())))
}

/// `ListScenes`: a page of the scenes, by id.
pub(super) async fn list_scenes(
    svc: &SublevelService,
    request: Request<pb::ListScenesRequest>,
) -> Handled<pb::ListScenesResponse> {
    let req = request.into_inner();
    let (page, next_page_token) =
        cv::page(svc.catalog.scenes(), |s| s.id.as_str(), "s", req.page_size, &req.page_token)?;
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

/// `DeleteScene`: deletes a scene with its instances.
pub(super) async fn delete_scene(
    svc: &SublevelService,
    request: Request<pb::DeleteSceneRequest>,
) -> Handled<pb::DeleteSceneResponse> {
    let id = request.into_inner().scene_id;
    require_id("scene_id", &id)?;
    let catalog = svc.catalog.clone();
    let forget = id.clone();
    blocking(move || catalog.delete_scene(&id)).await?;
    svc.prepared.forget_scene(&forget);
    Ok(Response::new(pb::DeleteSceneResponse {}))
}

/// `AddInstance`: places a stored body in a scene at a pose.
pub(super) async fn add_instance(
    svc: &SublevelService,
    request: Request<pb::AddInstanceRequest>,
) -> Handled<pb::AddInstanceResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    require_id("body_id", &req.body_id)?;
    let pose = cv::pose_from_proto("pose", req.pose.as_ref())?;
    let held = svc.catalog.get_scene(&req.scene_id)?.instances.len();
    check_room(limits::INSTANCES, held, svc.config.max_instances_per_scene)?;
    let catalog = svc.catalog.clone();
    let instance_id = blocking(move || catalog.add_instance(&req.scene_id, &req.body_id, pose)).await?;
    Ok(Response::new(pb::AddInstanceResponse { instance_id }))
}

/// `SetPoses`: moves instances of a scene, all or nothing.
pub(super) async fn set_poses(
    svc: &SublevelService,
    request: Request<pb::SetPosesRequest>,
) -> Handled<pb::SetPosesResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let poses = cv::poses_from_proto(&req.poses, svc.config.max_poses_per_call)?;
    // On the blocking pool: a pose commit is redb's eventual durability, which still writes
    // (and may sync) the file, so it must not sit on an async worker.
    let catalog = svc.catalog.clone();
    let updated = blocking(move || catalog.set_poses(&req.scene_id, &poses)).await?;
    Ok(Response::new(pb::SetPosesResponse { updated: u32::try_from(updated).unwrap_or(u32::MAX) }))
}

/// `RemoveInstance`: removes an instance (and its warm starts) from a scene.
pub(super) async fn remove_instance(
    svc: &SublevelService,
    request: Request<pb::RemoveInstanceRequest>,
) -> Handled<pb::RemoveInstanceResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    require_id("instance_id", &req.instance_id)?;
    let catalog = svc.catalog.clone();
    blocking(move || catalog.remove_instance(&req.scene_id, &req.instance_id)).await?;
    Ok(Response::new(pb::RemoveInstanceResponse {}))
}

/// `ImportScene`: reads a MoveIt planning scene, checks its counts against the limits, writes
/// it as a new scene of primitive instances ([`sublevel_scene::moveit::ImportPlan`]), then starts
/// one compound fit job per mesh ([`start_mesh_fits`]).
pub(super) async fn import_scene(
    svc: &SublevelService,
    request: Request<pb::ImportSceneRequest>,
) -> Handled<pb::ImportSceneResponse> {
    let req = request.into_inner();
    let settings = cv::import_mesh_settings(req.mesh_tolerance, svc.config.fit.clone())?;
    let meshes = if req.skip_meshes { MeshImport::Skip } else { MeshImport::Fit };
    // Parsing a large scene takes milliseconds: off the async workers.
    let source = req.scene;
    let max_objects = svc.config.max_instances_per_scene;
    let (scene, plan) = blocking(move || cv::planning_scene_from_proto(source.as_ref(), meshes, max_objects)).await?;
    let fitted = plan.meshes.len();
    check_room(limits::SCENES, svc.catalog.scenes().len(), svc.config.max_scenes)?;
    check_room_for(limits::BODIES, svc.catalog.bodies().len(), plan.bodies.len() + fitted, svc.config.max_bodies)?;
    check_room_for(limits::INSTANCES, 0, plan.instances.len() + fitted, svc.config.max_instances_per_scene)?;
    check_room_for(limits::FIT_QUEUE, svc.jobs.queued(), fitted, svc.config.max_fit_queue)?;
    for m in &plan.meshes {
        cv::check_point_count(&format!("mesh `{}`", m.name), m.vertices.len(), svc.config.max_fit_points)?;
    }
    let catalog = svc.catalog.clone();
    let (imported, plan) = blocking(move || catalog.import_plan(&req.name, &plan).map(|i| (i, plan))).await?;
    let jobs = start_mesh_fits(svc, &imported.scene_id, &plan, settings).await?;
    Ok(Response::new(cv::imported_scene_to_proto(&imported, &plan, &scene, &jobs)))
}

/// Starts the compound fit job of each planned mesh of an imported scene (`parts` auto; the fit
/// runs on the fitting slots, off the async workers): each stores its body with the mesh and
/// adds the instance to `scene_id` at the mesh's pose, under its planning name. Returns the job
/// ids in the plan's order. Should a job not start (the queue filled meanwhile, the server
/// stopping), the scene is deleted again (the jobs already started then store their bodies and
/// say that the instance was not added) and the error returned.
async fn start_mesh_fits(
    svc: &SublevelService,
    scene_id: &str,
    plan: &ImportPlan,
    settings: sublevel_fit::compound::CompoundSettings,
) -> Result<Vec<String>, Status> {
    let mut jobs = Vec::with_capacity(plan.meshes.len());
    for m in &plan.meshes {
        let place = MeshPlacement {
            scene_id: scene_id.to_owned(),
            name: m.name.clone(),
            pose: m.pose,
            max_instances: svc.config.max_instances_per_scene,
        };
        let started = svc
            .jobs
            .start_compound_placed(
                body_name(&m.name),
                cv::planned_mesh_to_fit(m),
                PartCount::Auto,
                settings.clone(),
                Some(place),
            )
            .await;
        match started {
            Ok(job_id) => jobs.push(job_id),
            Err(status) => {
                let catalog = svc.catalog.clone();
                let id = scene_id.to_owned();
                let _ = blocking(move || catalog.delete_scene(&id)).await;
                return Err(status);
            }
        }
    }
    Ok(jobs)
}

/// A mesh body's name: its planning name, cut at a character boundary to the longest name the
/// catalog stores ([`sublevel_scene::MAX_NAME_BYTES`]).
fn body_name(name: &str) -> String {
    let mut end = name.len().min(sublevel_scene::MAX_NAME_BYTES);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    name[..end].to_owned()
}
