//! Robots: `StartRobotFitJob`, `UploadRobot`, `GetRobot`, `ListRobots`, `DeleteRobot`, `CheckConfigurations`,
//! `CheckMotions`.
//!
//! Checks run on the batch slots, split in chunks of configurations (or motions) over as many
//! slots as the batch pool has and the work fills ([`chunks`]); each chunk makes its own
//! [`RobotChecker`] (the robot's meshes and bodies are shared, only the world's pair lists are
//! built, in microseconds).

use super::{Handled, HandlerError, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::jobs::RobotFitInput;
use crate::pb;
use crate::runtime::blocking;
use crate::{Error, Result};
use futures_util::future::try_join_all;
use std::ops::Range;
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::srdf::Semantics;
use sublevel_robot::{
    CheckOptions, CollisionGeometry, FittedRobot, MotionChecker, RobotChecker, RobotFitSettings, RobotModel,
};
use sublevel_scene::RobotWorld;
use tonic::{Request, Response};

/// Fewest configurations worth a chunk of their own (a configuration takes 5–200 µs).
const MIN_CHUNK: usize = 32;

/// Most configurations whose verdicts (no distance) are answered inline on the async worker
/// (tens of µs each, as small query requests are), saving the two hand-offs to the blocking pool
/// that would cost more than the check.
const INLINE_CONFIGURATIONS: usize = 4;

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
        let semantics = Semantics::from_srdf_str(&req.srdf).map_err(|e| cv::prefix_field(e, "srdf"))?;
        model.self_collision_pairs(&semantics.disabled_pairs)?;
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
    blocking(move || catalog.delete_robot(&id)).await?;
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

/// `robot` with `attached` objects added (`robot` itself when there are none).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `attached[k]` and its field.
fn with_attached(robot: &Arc<FittedRobot>, attached: &[pb::AttachedObject]) -> Result<Arc<FittedRobot>> {
    if attached.is_empty() {
        return Ok(robot.clone());
    }
    let mut robot = (**robot).clone();
    for (k, a) in attached.iter().enumerate() {
        let field = format!("attached[{k}]");
        let primitive = a.primitive.as_ref().ok_or_else(|| Error::invalid(format!("{field}.primitive"), "required"))?;
        let primitive = cv::primitive_from_proto(primitive, &format!("{field}.primitive"))?;
        let origin = cv::pose_from_proto(&format!("{field}.origin"), a.origin.as_ref())?;
        let name = if a.name.is_empty() { format!("attached#{k}") } else { a.name.clone() };
        robot.attach(&a.link, &name, primitive, origin).map_err(|e| cv::prefix_field(e, &field))?;
    }
    Ok(Arc::new(robot))
}

/// What the robot checks need of the service: the catalog, the batch slots and their number.
/// The unary checks and the query streams (whose requests may carry robot checks) share it.
#[derive(Clone, Debug)]
pub(super) struct RobotChecks {
    pub(super) catalog: Arc<sublevel_scene::Catalog>,
    pub(super) pools: crate::limits::QueryPools,
    pub(super) slots: usize,
}

/// What a check request says of its robot and world (see [`RobotChecks::setting`]).
pub(super) struct Asked {
    pub(super) robot_id: String,
    pub(super) scene_id: String,
    pub(super) base: Option<pb::Pose>,
    pub(super) attached: Vec<pb::AttachedObject>,
    pub(super) link_padding: std::collections::HashMap<String, Real>,
    /// Pose overrides of scene instances (instance id → pose): a query stream's view.
    pub(super) poses: Vec<(String, Isometry3)>,
}

impl RobotChecks {
    /// The robot checks of `svc`.
    pub(super) fn of(svc: &SublevelService) -> Self {
        Self { catalog: svc.catalog.clone(), pools: svc.pools.clone(), slots: svc.config.batch_workers }
    }

    /// Whether the robot and the scene of a check read from memory alone: no shared store
    /// (which may load them from the database) and every stored body built (a first use builds
    /// it).
    pub(super) fn in_memory(&self) -> bool {
        !self.catalog.shared_store() && self.catalog.bodies_pending() == 0
    }

    /// Reads a check's robot, scene (empty: no world), base and link padding: inline when they
    /// are in memory ([`RobotChecks::in_memory`]), else off the async workers. With no
    /// `robot_id`, the scene's robot with its base (unless the request gives one), attached
    /// objects (the request's added) and link padding (the request's replacing it link by link).
    pub(super) async fn setting(&self, asked: Asked) -> Result<Setting, HandlerError> {
        let Asked { robot_id, scene_id, base, attached, link_padding, poses } = asked;
        let base = base.map(|b| cv::pose_from_proto("base", Some(&b))).transpose().map_err(cv::to_status)?;
        let catalog = self.catalog.clone();
        let read = move || -> Result<Setting> {
            let mut world = if scene_id.is_empty() {
                RobotWorld::empty()
            } else {
                catalog.robot_world(require_id("scene_id", &scene_id)?)?
            };
            world.with_poses(poses.iter().map(|(id, p)| (id.as_str(), p)));
            let (robot, base, mut padding) = if robot_id.is_empty() {
                let placed = world.robot.clone().ok_or_else(|| {
                    Error::invalid("robot_id", "required: name a robot, or a scene holding one (SetSceneRobot)")
                })?;
                (placed.robot.clone(), base.unwrap_or(placed.base), placed.link_padding.clone())
            } else {
                let entry = catalog.robot(require_id("robot_id", &robot_id)?)?;
                (entry.robot.clone(), base.unwrap_or_else(Isometry3::identity), Vec::new())
            };
            for (link, p) in link_padding {
                match padding.iter_mut().find(|(l, _)| *l == link) {
                    Some(entry) => entry.1 = p,
                    None => padding.push((link, p)),
                }
            }
            Ok(Setting {
                robot: with_attached(&robot, &attached)?,
                world: Arc::new(world),
                base,
                link_padding: padding.into(),
            })
        };
        if self.in_memory() {
            Ok(read()?)
        } else {
            // The check's own error stays a core error (its field can still be prefixed).
            Ok(blocking(move || Ok(read())).await??)
        }
    }

    /// Answers a `CheckConfigurations` request, the scene's instances in `poses` moved there:
    /// configurations checked in chunks on the batch slots, answered in columns.
    pub(super) async fn configurations(
        &self,
        req: pb::CheckConfigurationsRequest,
        poses: Vec<(String, Isometry3)>,
    ) -> Result<pb::CheckConfigurationsResponse, HandlerError> {
        let padding = cv::padding(req.padding)?;
        let asked = Asked {
            robot_id: req.robot_id,
            scene_id: req.scene_id,
            base: req.base,
            attached: req.attached,
            link_padding: req.link_padding,
            poses,
        };
        let Setting { robot, world, base, link_padding } = self.setting(asked).await?;
        let configs = Arc::new(cv::configurations_from_proto(
            "configurations",
            req.configurations.as_ref(),
            &robot,
            &world.planning.joint_positions,
        )?);
        let options = CheckOptions {
            padding,
            distance: req.distance || req.gradient,
            self_collision: !req.skip_self,
            gradient: req.gradient,
        };
        let stop = req.stop_at_first_collision;
        let check = move |robot: &FittedRobot, world: &RobotWorld, configs: &[Vec<Real>], range: Range<usize>| {
            let allowed = world.planning.allowed_override();
            let mut checker = RobotChecker::new(robot, world.objects.clone(), &allowed)?;
            checker.set_link_padding(&link_padding)?;
            let mut out = Vec::with_capacity(range.len());
            for c in range {
                let answer = checker
                    .check(&configs[c], &base, &options)
                    .map_err(|e| cv::prefix_field(e, &format!("configurations[{c}]")))?;
                let collides = answer.collides;
                out.push(answer);
                if stop && collides {
                    break;
                }
            }
            Ok(out)
        };
        // A few verdicts are microseconds: answered inline, as small query requests are; the
        // rest (distances reach the meshes' distance searches) in chunks on the batch slots, or
        // in one chunk, in order, when the check stops at the first collision.
        let answers = if configs.len() <= INLINE_CONFIGURATIONS && !options.distance && self.in_memory() {
            vec![check(&robot, &world, &configs, 0..configs.len())?]
        } else {
            let slots = if stop { 1 } else { self.slots };
            let work = chunks(configs.len(), slots).into_iter().map(|range| {
                let (robot, world, configs, check) = (robot.clone(), world.clone(), configs.clone(), check.clone());
                self.pools.batch.run(move || Ok(check(&robot, &world, &configs, range)))
            });
            try_join_all(work).await?.into_iter().collect::<Result<Vec<_>>>()?
        };
        let mut out = pb::CheckConfigurationsResponse {
            joint_names: robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
            ..Default::default()
        };
        for chunk in &answers {
            cv::push_configuration_answers(&mut out, chunk, &robot, &world.objects, req.gradient);
        }
        Ok(out)
    }

    /// Answers a `CheckMotions` request, the scene's instances in `poses` moved there: motions
    /// checked by conservative advancement in chunks on the batch slots, answered in columns.
    pub(super) async fn motions(
        &self,
        req: pb::CheckMotionsRequest,
        poses: Vec<(String, Isometry3)>,
    ) -> Result<pb::CheckMotionsResponse, HandlerError> {
        let options = cv::motion_options(req.padding, req.tolerance, req.max_steps)?;
        let asked = Asked {
            robot_id: req.robot_id,
            scene_id: req.scene_id,
            base: req.base,
            attached: req.attached,
            link_padding: req.link_padding,
            poses,
        };
        let Setting { robot, world, base, link_padding } = self.setting(asked).await?;
        let defaults = &world.planning.joint_positions;
        let names = |c: &Option<pb::ConfigurationColumns>| c.as_ref().map(|c| c.joint_names.clone());
        if let (Some(start), Some(end)) = (names(&req.start), names(&req.end)) {
            if start != end {
                return Err(Error::invalid(
                    "end.joint_names",
                    "names other joints than `start.joint_names`: a motion's end names the joints its start names, \
                     in the same order",
                )
                .into());
            }
        }
        let start = cv::configurations_from_proto("start", req.start.as_ref(), &robot, defaults)?;
        let end = cv::configurations_from_proto("end", req.end.as_ref(), &robot, defaults)?;
        if start.len() != end.len() {
            return Err(Error::invalid(
                "end.values",
                format!("{} end configurations for {} start configurations", end.len(), start.len()),
            )
            .into());
        }
        let motions = Arc::new((start, end));
        let work = chunks(motions.0.len(), self.slots).into_iter().map(|range| {
            let (robot, world, motions, link_padding) =
                (robot.clone(), world.clone(), motions.clone(), link_padding.clone());
            self.pools.batch.run(move || {
                Ok((|| {
                    let allowed = world.planning.allowed_override();
                    let mut checker = RobotChecker::new(&robot, world.objects.clone(), &allowed)?;
                    checker.set_link_padding(&link_padding)?;
                    let mut motion = MotionChecker::new(&mut checker)?;
                    range
                        .map(|m| {
                            motion
                                .check_motion(&motions.0[m], &motions.1[m], &base, &options)
                                .map_err(|e| cv::prefix_field(e, &format!("motions[{m}]")))
                        })
                        .collect::<Result<Vec<_>>>()
                })())
            })
        });
        let answers = try_join_all(work).await?.into_iter().collect::<Result<Vec<_>>>()?;
        let mut out = pb::CheckMotionsResponse {
            joint_names: robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
            ..Default::default()
        };
        for chunk in &answers {
            cv::push_motion_answers(&mut out, chunk, &robot, &world.objects);
        }
        Ok(out)
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

/// `CheckMotions`: motions checked by conservative advancement in chunks on the batch slots,
/// answered in columns.
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
