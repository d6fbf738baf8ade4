//! The robot of a scene: `SetSceneRobot`, `ClearSceneRobot`, `SetJointPositions`, `AttachObject`,
//! `DetachObject`.
//!
//! Each change is validated whole by the catalog before it is written (all or nothing); building
//! the robot with its attached objects copies the stored robot (milliseconds for a robot of
//! meshes), so every change runs off the async workers.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::pb;
use crate::runtime::blocking;
use crate::{Error, Result};
use std::sync::Arc;
use sublevel_scene::{Catalog, PlacedRobot, SceneRobot, StoredPose};
use tonic::{Request, Response};

/// The scene's robot as the API shows it, after a change.
fn shown(catalog: &Catalog, scene_id: &str, placed: &PlacedRobot) -> Result<pb::SceneRobot> {
    let scene = catalog.get_scene(scene_id)?;
    Ok(cv::scene_robot_to_proto(placed, &scene.planning.joint_positions))
}

/// The joints and values of a `joint_positions` field (one configuration).
fn positions(columns: Option<&pb::ConfigurationColumns>) -> Option<(Vec<String>, Vec<f64>)> {
    columns
        .filter(|c| !c.joint_names.is_empty() || !c.values.is_empty())
        .map(|c| (c.joint_names.clone(), c.values.clone()))
}

/// `SetSceneRobot`: places a stored robot in a scene.
pub(super) async fn set_scene_robot(
    svc: &SublevelService,
    request: Request<pb::SetSceneRobotRequest>,
) -> Handled<pb::SetSceneRobotResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    require_id("robot_id", &req.robot_id)?;
    let base = cv::pose_from_proto("base", req.base.as_ref())?;
    let attached = req
        .attached
        .iter()
        .enumerate()
        .map(|(k, a)| cv::attached_record_from_proto(a, &format!("attached[{k}]"), k))
        .collect::<Result<Vec<_>>>()?;
    let record = SceneRobot {
        robot_id: req.robot_id,
        base: StoredPose::from_isometry(&base),
        attached,
        link_padding: req.link_padding.into_iter().collect(),
    };
    let joints = positions(req.joint_positions.as_ref());
    let catalog = svc.catalog.clone();
    let robot = blocking(move || {
        let joints = joints.as_ref().map(|(n, v)| (n.as_slice(), v.as_slice()));
        let placed = catalog.set_scene_robot(&req.scene_id, record, joints)?;
        shown(&catalog, &req.scene_id, &placed)
    })
    .await?;
    Ok(Response::new(pb::SetSceneRobotResponse { robot: Some(robot) }))
}

/// `ClearSceneRobot`: removes a scene's robot.
pub(super) async fn clear_scene_robot(
    svc: &SublevelService,
    request: Request<pb::ClearSceneRobotRequest>,
) -> Handled<pb::ClearSceneRobotResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let catalog = svc.catalog.clone();
    let removed = blocking(move || catalog.clear_scene_robot(&req.scene_id)).await?;
    Ok(Response::new(pb::ClearSceneRobotResponse { removed }))
}

/// `SetJointPositions`: sets joint positions of a scene's robot, all or nothing.
pub(super) async fn set_joint_positions(
    svc: &SublevelService,
    request: Request<pb::SetJointPositionsRequest>,
) -> Handled<pb::SetJointPositionsResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let (names, values) = positions(req.joint_positions.as_ref())
        .ok_or_else(|| Error::invalid("joint_positions", "required: the joints to set and their values"))?;
    let catalog = svc.catalog.clone();
    let robot = blocking(move || {
        catalog.set_joint_positions(&req.scene_id, &names, &values)?;
        let placed =
            catalog.placed_robot(&req.scene_id)?.ok_or_else(|| Error::not_found("scene robot", &req.scene_id))?;
        shown(&catalog, &req.scene_id, &placed)
    })
    .await?;
    Ok(Response::new(pb::SetJointPositionsResponse { robot: Some(robot) }))
}

/// `AttachObject`: attaches an object to a link of a scene's robot.
pub(super) async fn attach_object(
    svc: &SublevelService,
    request: Request<pb::AttachObjectRequest>,
) -> Handled<pb::AttachObjectResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let attached = req.attached.as_ref().ok_or_else(|| Error::invalid("attached", "required"))?;
    if attached.name.is_empty() {
        return Err(Error::invalid("attached.name", "required: the name DetachObject will use").into());
    }
    let record = cv::attached_record_from_proto(attached, "attached", 0)?;
    let catalog = svc.catalog.clone();
    let robot = blocking(move || {
        let placed = catalog.attach_object(&req.scene_id, record)?;
        shown(&catalog, &req.scene_id, &placed)
    })
    .await?;
    Ok(Response::new(pb::AttachObjectResponse { robot: Some(robot) }))
}

/// `DetachObject`: detaches an object from a scene's robot.
pub(super) async fn detach_object(
    svc: &SublevelService,
    request: Request<pb::DetachObjectRequest>,
) -> Handled<pb::DetachObjectResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    if req.name.is_empty() {
        return Err(Error::invalid("name", "required").into());
    }
    let catalog = svc.catalog.clone();
    let robot = blocking(move || {
        let placed: Arc<PlacedRobot> = catalog.detach_object(&req.scene_id, &req.name)?;
        shown(&catalog, &req.scene_id, &placed)
    })
    .await?;
    Ok(Response::new(pb::DetachObjectResponse { robot: Some(robot) }))
}
