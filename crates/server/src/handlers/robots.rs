//! Robots: `StartRobotFitJob`, `UploadRobot`, `GetRobot`, `ListRobots`, `DeleteRobot`, `CheckConfigurations`,
//! `CheckMotions`.
//!
//! Checks run on the batch slots, split in chunks of configurations (or motions) over as many
//! slots as the batch pool has and the work fills ([`chunks`]), on checkers prepared once per
//! robot and scene and kept across requests ([`super::prepared`], [`super::robot_checks`]).

pub(super) use super::prepared::Asked;
use super::prepared::PreparedCheckers;
use super::{Handled, HandlerError, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::jobs::RobotFitInput;
use crate::pb;
use crate::runtime::blocking;
use crate::Error;
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::srdf::Semantics;
use sublevel_robot::{CollisionGeometry, FittedRobot, RobotFitSettings, RobotModel};
use sublevel_scene::RobotWorld;
use tonic::{Request, Response};

/// Fewest configurations worth a chunk of their own (a configuration takes 5–200 µs).
const MIN_CHUNK: usize = 32;

/// `StartRobotFitJob`: validates the URDF, the SRDF and the meshes (every mesh the URDF names is
/// sent, under a safe name), then starts the fit as a job.
pub(super) async fn start_robot_fit_job(
    svc: &SublevelService,
    request: Request<pb::StartRobotFitJobRequest>,
) -> Handled<pb::StartRobotFitJobResponse> {
    let req = request.into_inner();
    if req.name.len() > sublevel_scene::MAX_NAME_BYTES {
        return Err(Error::invalid("name", format!("at most {} bytes", sublevel_scene::MAX_NAME_BYTES)).into());
    }
    let model = RobotModel::from_urdf_str(&req.urdf).map_err(|e| cv::prefix_field(e, "urdf"))?;
    let (srdf, allowed) = if req.srdf.trim().is_empty() {
        (None, Vec::new())
    } else {
        // Entries naming links the URDF lacks are skipped (the fit report says which), as
        // MoveIt's SRDF loader skips them.
        let (semantics, _) =
            Semantics::from_srdf_str(&req.srdf).map_err(|e| cv::prefix_field(e, "srdf"))?.known_to(&model);
        let allowed: Vec<[String; 2]> =
            semantics.disabled_pairs.iter().map(|d| [d.link1.clone(), d.link2.clone()]).collect();
        (Some(req.srdf), allowed)
    };
    // One rule for mesh names, the URDF's and the request's keys alike; the job reads only the
    // bytes sent, by the exact name the URDF writes, and never a file of the server's disk.
    for (name, bytes) in &req.meshes {
        let field = format!("meshes[{}]", sublevel_core::error::clip(name));
        sublevel_robot::check_mesh_name(&field, name)?;
        if bytes.is_empty() {
            return Err(Error::invalid(field, "empty file").into());
        }
    }
    for link in model.links() {
        for (k, c) in link.collision.iter().enumerate() {
            if let CollisionGeometry::Mesh { filename, .. } = c {
                let field = format!("urdf.link[{}].collision[{k}].mesh", sublevel_core::error::clip(&link.name));
                sublevel_robot::check_mesh_name(&field, filename)?;
                if !req.meshes.contains_key(filename) {
                    return Err(Error::invalid(
                        format!("meshes[{}]", sublevel_core::error::clip(filename)),
                        format!("link `{}` collision {k} names this mesh: send its bytes under this name", link.name),
                    )
                    .into());
                }
            }
        }
    }
    sublevel_robot::limits::check_self_pairs(&model, &allowed)?;
    // Half the cores, for the meshes and then the clearance tables: a robot fit must not take
    // every core from the queries.
    let threads = (std::thread::available_parallelism().map_or(2, |n| n.get()) / 2).max(1);
    let mut settings = RobotFitSettings {
        cache_dir: Some(svc.config.data_dir.join("robot-fit-cache")),
        threads,
        clearance: Some(sublevel_robot::clearance::ClearanceSettings { threads, ..Default::default() }),
        ..RobotFitSettings::default()
    };
    settings.leaves = req.leaves;
    settings.compound.excess_tolerance = (req.tolerance != 0.0).then_some(req.tolerance);
    if req.max_parts != 0 {
        settings.compound.max_parts = req.max_parts as usize;
    }
    settings.compound.validate().map_err(|e| match e {
        Error::InvalidArgument { reason, .. } => Error::invalid("tolerance / max_parts", reason),
        other => other,
    })?;
    let name = if req.name.is_empty() { model.name.clone() } else { req.name };
    let input = RobotFitInput { urdf: req.urdf, srdf, meshes: req.meshes.into_iter().collect(), settings };
    let job_id = svc.jobs.start_robot(name, input).await?;
    Ok(Response::new(pb::StartRobotFitJobResponse { job_id }))
}

/// Mebibytes of robot files `UploadRobot` validates at once. Building a robot from its file (the
/// parsed vertices, the bodies, the meshes' BVHs, sphere trees and inner balls) takes about ten
/// times the file's size at its peak, so this bounds the memory of concurrent uploads near
/// 700 MB; a file takes one unit per started MiB (at most the whole budget) and larger uploads
/// wait their turn, holding no thread.
pub(crate) const ROBOT_BUILD_BUDGET_MIB: u32 = 64;

/// `UploadRobot`: validates the robot file (building its bodies and mesh BVHs, off the async
/// workers, within [`ROBOT_BUILD_BUDGET_MIB`]) and stores it.
pub(super) async fn upload_robot(
    svc: &SublevelService,
    request: Request<pb::UploadRobotRequest>,
) -> Handled<pb::UploadRobotResponse> {
    let req = request.into_inner();
    let catalog = svc.catalog.clone();
    let units = req.robot_file.len().div_ceil(1 << 20).clamp(1, ROBOT_BUILD_BUDGET_MIB as usize) as u32;
    let _budget = svc
        .robot_builds
        .clone()
        .acquire_many_owned(units)
        .await
        .map_err(|_| tonic::Status::unavailable("the server is shutting down"))?;
    let entry = blocking(move || {
        let file = serde_json::from_slice(&req.robot_file)
            .map_err(|e| Error::invalid("robot_file", format!("not a robot file (sublevel.robot.v1 JSON): {e}")))?;
        catalog.add_robot(&req.name, file).map_err(|e| cv::prefix_field(e, "robot_file"))
    })
    .await?;
    Ok(Response::new(pb::UploadRobotResponse { robot: Some(cv::robot_summary(&entry)) }))
}

/// `GetRobot`: a stored robot's summary.
pub(super) async fn get_robot(
    svc: &SublevelService,
    request: Request<pb::GetRobotRequest>,
) -> Handled<pb::GetRobotResponse> {
    let id = request.into_inner().robot_id;
    let catalog = svc.catalog.clone();
    let entry = blocking(move || catalog.robot(require_id("robot_id", &id)?)).await?;
    Ok(Response::new(pb::GetRobotResponse { robot: Some(cv::robot_summary(&entry)) }))
}

/// `ListRobots`: every stored robot's summary.
pub(super) async fn list_robots(
    svc: &SublevelService,
    _request: Request<pb::ListRobotsRequest>,
) -> Handled<pb::ListRobotsResponse> {
    let robots = svc.catalog.robots().iter().map(|e| cv::robot_summary(e)).collect();
    Ok(Response::new(pb::ListRobotsResponse { robots }))
}

/// `DeleteRobot`: deletes a stored robot.
pub(super) async fn delete_robot(
    svc: &SublevelService,
    request: Request<pb::DeleteRobotRequest>,
) -> Handled<pb::DeleteRobotResponse> {
    let id = request.into_inner().robot_id;
    require_id("robot_id", &id)?;
    let catalog = svc.catalog.clone();
    let forget = id.clone();
    blocking(move || catalog.delete_robot(&id)).await?;
    svc.prepared.forget_robot(&forget);
    Ok(Response::new(pb::DeleteRobotResponse {}))
}

/// The robot, the world, the base pose and the link padding of a check request.
pub(super) struct Setting {
    /// The robot, with the request's attached objects (a copy of the stored robot when there
    /// are any: its meshes' BVHs shared, its vertices copied).
    pub(super) robot: Arc<FittedRobot>,
    /// The scene's world and planning state.
    pub(super) world: Arc<RobotWorld>,
    /// The robot's root pose.
    pub(super) base: Isometry3,
    /// Padding per link (meters).
    pub(super) link_padding: Arc<[(String, Real)]>,
}

/// What the robot checks need of the service: the catalog, the batch slots and their number,
/// the prepared checkers. The unary checks and the query streams (whose requests may carry robot
/// checks) share it.
#[derive(Clone, Debug)]
pub(super) struct RobotChecks {
    pub(super) catalog: Arc<sublevel_scene::Catalog>,
    pub(super) pools: crate::limits::QueryPools,
    pub(super) slots: usize,
    pub(super) prepared: Arc<PreparedCheckers>,
}

impl RobotChecks {
    /// The robot checks of `svc`.
    pub(super) fn of(svc: &SublevelService) -> Self {
        Self {
            catalog: svc.catalog.clone(),
            pools: svc.pools.clone(),
            slots: svc.config.batch_workers,
            prepared: svc.prepared.clone(),
        }
    }

    /// Whether the robot and the scene of a check read from memory alone: no shared store
    /// (which may load them from the database) and every stored body built (a first use builds
    /// it).
    pub(super) fn in_memory(&self) -> bool {
        !self.catalog.shared_store() && self.catalog.bodies_pending() == 0
    }

    /// A check's robot, scene (empty: no world), base and link padding, from its prepared setting
    /// ([`super::prepared`]): read inline when they are in memory ([`RobotChecks::in_memory`]),
    /// else off the async workers. With no `robot_id`, the scene's robot with its base (unless
    /// the request gives one), attached objects (the request's added) and link padding (the
    /// request's replacing it link by link).
    pub(super) async fn setting(&self, mut asked: Asked) -> Result<Setting, HandlerError> {
        let base = asked.base.take().map(|b| cv::pose_from_proto("base", Some(&b))).transpose()?;
        let prepared = self.prepared(asked).await?;
        Ok(Setting {
            robot: prepared.robot.clone(),
            world: prepared.world.clone(),
            base: base.unwrap_or(prepared.base),
            link_padding: prepared.link_padding.clone().into(),
        })
    }
}

/// Splits `0..n` into balanced chunks for the batch slots: at most one per slot, and none under
/// half of [`MIN_CHUNK`].
pub(super) fn chunks(n: usize, slots: usize) -> Vec<std::ops::Range<usize>> {
    let count = n.div_ceil(MIN_CHUNK).clamp(1, slots.max(1));
    // Balanced: sizes differ by at most one.
    (0..count).map(|i| i * n / count..(i + 1) * n / count).filter(|r| !r.is_empty()).collect()
}

/// `CheckConfigurations`: configurations checked in chunks on the batch slots, answered in columns.
pub(super) async fn check_configurations(
    svc: &SublevelService,
    request: Request<pb::CheckConfigurationsRequest>,
) -> Handled<pb::CheckConfigurationsResponse> {
    let out = RobotChecks::of(svc).configurations(request.into_inner(), Vec::new()).await?;
    Ok(Response::new(out))
}

/// `CheckMotions`: motions certified by conservative advancement, or sampled at the request's
/// resolution, in chunks on the batch slots, answered in columns.
pub(super) async fn check_motions(
    svc: &SublevelService,
    request: Request<pb::CheckMotionsRequest>,
) -> Handled<pb::CheckMotionsResponse> {
    let out = RobotChecks::of(svc).motions(request.into_inner(), Vec::new()).await?;
    Ok(Response::new(out))
}

#[cfg(test)]
mod tests {
    use super::chunks;

    #[test]
    fn chunks_cover_every_index_once_and_respect_the_slots() {
        for (n, slots) in [(0, 4), (1, 4), (31, 4), (33, 4), (1000, 3), (1000, 64), (64, 1)] {
            let c = chunks(n, slots);
            assert!(c.len() <= slots.max(1), "{n} {slots}: {c:?}");
            let flat: Vec<usize> = c.iter().flat_map(|r| r.clone()).collect();
            assert_eq!(flat, (0..n).collect::<Vec<_>>(), "{n} {slots}");
            if c.len() > 1 {
                assert!(c.iter().all(|r| r.len() >= MIN_CHUNK_FLOOR), "{n} {slots}: {c:?}");
            }
        }
    }

    const MIN_CHUNK_FLOOR: usize = super::MIN_CHUNK / 2;
}
