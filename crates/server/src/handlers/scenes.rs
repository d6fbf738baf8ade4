//! Scenes and their instances: `CreateScene`, `GetScene`, `ListScenes`, `DeleteScene`,
//! `AddInstance`, `SetPoses`, `RemoveInstance`.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::limits::{self, check_room};
use crate::pb;
use crate::runtime::blocking;
use tonic::{Request, Response};

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
    let scene = svc.catalog.get_scene(require_id("scene_id", &id)?)?;
    Ok(Response::new(cv::scene_to_proto(&scene)))
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
    blocking(move || catalog.delete_scene(&id)).await?;
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
