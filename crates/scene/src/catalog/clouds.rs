//! Point-cloud obstacles of a scene, from depth sensors, and the scene version.
//!
//! ```text
//! frame    sensor-frame points (a PointCloud2's x, y, z, or a deprojected depth image)
//!   │      build_point_cloud: off every lock — filters (holes, range, workspace, voxel,
//!   │      outliers), the self filter at the scene robot's joint positions, the k-d tree
//!   ▼
//! cloud    world-frame points, each a ball of the noise radius (sublevel_robot::cloud)
//!   │      set_point_cloud: under the scene's lock — name and limits checked, the scene's
//!   ▼      cloud set replaced whole, the scene version raised
//! scene    robot_world adds every cloud as WorldObject::points(name, cloud, identity), or, for
//!          the bodies model, every cluster body as WorldObject::body(name, body, identity)
//! ```
//!
//! **Two models.** A cloud is its points (each a ball of the noise radius; exact against the
//! filtered cloud) or, when the frame asks for it, bodies ([`Catalog::build_cloud_bodies`]): the
//! points' Euclidean clusters, each fitted by a convex sos body containing its points' balls
//! ([`sublevel_robot::cloud::bodies`]). The bodies are updated online: the previous frame's
//! bodies of the same cloud are the warm start, so a cluster whose body still contains it keeps
//! it, a slightly grown one is rescaled, and only the rest are fitted. Switching a cloud from one
//! model to the other starts the bodies afresh.
//!
//! **In memory only.** Clouds are sensor data, replaced at sensor rate: they live with the
//! scene's in-memory state and are never written to the store. A restarted server, or another
//! replica sharing the store, has none until the sensor bridge sends the next frame; deleting the
//! scene drops them.
//!
//! **Atomic replacement.** A scene's clouds are one `Arc<CloudSet>` replaced whole under the
//! scene's lock, and every reader (the robot world, a scene view, CheckScene) clones that `Arc`
//! under the same lock as the instances it reads, so a check sees the old cloud or the new one,
//! never a mix, and never a cloud with instances of another moment.
//!
//! **Scene version.** A per-scene counter: 1 when the scene is created (or loaded after a
//! restart: versions are in memory too), raised by every change — instances added, moved or
//! removed, the planning context (robot, joint positions, attached objects), a cloud set or
//! removed. The checks report the version of the scene they read.
//!
//! **Limits.** At most [`MAX_CLOUDS_PER_SCENE`] clouds per scene, at most
//! [`sublevel_robot::cloud::MAX_CLOUD_POINTS`] points per cloud, and a server-wide total of cloud
//! memory passed by the caller (the server's `--max-cloud-bytes`, default
//! [`DEFAULT_MAX_CLOUD_BYTES`]). The memory counted is the clouds a scene holds now: a cloud just
//! replaced may live on in a check still running.

use super::{check_name, Catalog, PosedInstance, SceneState};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use sublevel_core::error::show_real;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::cloud::bodies::{CloudBodies, CloudBodySettings, UpdateReport};
use sublevel_robot::cloud::filter::{self_filter, CloudFilter, FilterCounts};
use sublevel_robot::cloud::{PointCloud, MAX_NOISE_RADIUS};
use sublevel_robot::world::WorldBody;

/// Most point clouds one scene holds; one more is `ResourceExhausted` naming `name`.
pub const MAX_CLOUDS_PER_SCENE: usize = 16;

/// The default server-wide limit of point-cloud memory (2 GiB).
pub const DEFAULT_MAX_CLOUD_BYTES: usize = 2 << 30;

/// The default noise radius of a cloud's points (meters): each point is a ball of this radius.
pub const DEFAULT_NOISE_RADIUS: Real = 0.01;

/// The default padding of the self filter (meters).
pub const DEFAULT_SELF_FILTER_PADDING: Real = 0.02;

/// Bytes counted per body of the bodies model, for the memory limit: an upper estimate of a
/// degree-4 body with its query tables (polynomial forms, support and radial tables, bounds).
pub const BODY_MEMORY_BYTES: usize = 64 << 10;

/// A cloud's bodies model (module docs): the clusters with their bodies, kept for the next
/// frame's warm start, and the bodies as world objects.
#[derive(Clone, Debug)]
pub struct CloudBodiesModel {
    /// The clusters and their bodies (world frame, meters).
    pub state: CloudBodies,
    /// Each cluster's body as an obstacle, in the order of the clusters.
    pub objects: Vec<Arc<WorldBody>>,
    /// What the update that made them did.
    pub report: UpdateReport,
}

/// A point cloud of a scene (module docs).
#[derive(Debug)]
pub struct SceneCloud {
    /// Its name, unique among the scene's clouds and instances (the name the checks report and
    /// the allowed-collision matrix uses).
    pub name: String,
    /// The points (world frame, meters), each a ball of the cloud's noise radius.
    pub cloud: Arc<PointCloud>,
    /// What the filters did to the frame it was built from.
    pub counts: FilterCounts,
    /// The scene version its update produced.
    pub version: u64,
    /// Bytes it holds ([`PointCloud::memory_bytes`], and [`BODY_MEMORY_BYTES`] per body).
    pub memory_bytes: usize,
    /// The bodies model, when the cloud has it; `None`: the points model.
    pub bodies: Option<Arc<CloudBodiesModel>>,
}

/// A scene's point clouds by name.
pub type CloudSet = BTreeMap<String, Arc<SceneCloud>>;

/// A sensor frame to turn into a cloud obstacle ([`Catalog::build_point_cloud`]).
#[derive(Clone, Debug)]
pub struct CloudFrame {
    /// The frame's points in the sensor frame (meters), holes (NaN, ±∞) included: they are
    /// counted and dropped.
    pub points: Vec<[f32; 3]>,
    /// Holes found before `points` was made (a depth image's pixels without a depth): counted as
    /// input and as holes.
    pub holes: usize,
    /// Sensor frame → world.
    pub sensor_pose: Isometry3,
    /// Every kept point is a ball of this radius (meters, 0 to
    /// [`sublevel_robot::cloud::MAX_NOISE_RADIUS`]).
    pub noise_radius: Real,
    /// The filters.
    pub filter: CloudFilter,
    /// The self filter's padding (meters ≥ 0): points whose ball comes within it of the scene's
    /// robot at the scene's joint positions are dropped; `None` keeps them.
    pub self_filter: Option<Real>,
}

/// A cloud built from a frame, not yet in its scene ([`Catalog::set_point_cloud`]).
#[derive(Debug)]
pub struct BuiltCloud {
    /// The world-frame points with their k-d tree.
    pub cloud: PointCloud,
    /// What each filter dropped.
    pub counts: FilterCounts,
    /// The bodies model ([`Catalog::build_cloud_bodies`]); `None`: the points model.
    pub bodies: Option<CloudBodiesModel>,
}

impl BuiltCloud {
    /// Bytes the cloud will hold: its points and tree, and [`BODY_MEMORY_BYTES`] per body.
    pub fn memory_bytes(&self) -> usize {
        self.cloud.memory_bytes() + self.bodies.as_ref().map_or(0, |b| b.objects.len() * BODY_MEMORY_BYTES)
    }
}

/// What [`Catalog::set_point_cloud`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CloudUpdate {
    /// The scene version the update produced.
    pub scene_version: u64,
    /// Bytes the new cloud holds.
    pub memory_bytes: usize,
}

/// [`Error::Cancelled`] when the calling thread's cancellation scope ([`sublevel_core::cancel`])
/// has been cancelled: the update was abandoned (its client went away, or its deadline passed).
fn check_abandoned() -> Result<()> {
    if sublevel_core::cancel::is_cancelled() {
        return Err(Error::Cancelled(
            "the point-cloud update was abandoned (its client went away or its deadline passed); nothing was stored"
                .into(),
        ));
    }
    Ok(())
}

/// Rejects a noise radius outside `[0, MAX_NOISE_RADIUS]` naming `noise_radius`.
fn check_noise_radius(radius: Real) -> Result<()> {
    if radius.is_finite() && (0.0..=MAX_NOISE_RADIUS).contains(&radius) {
        return Ok(());
    }
    Err(Error::invalid(
        "noise_radius",
        format!("must be finite, in [0, {MAX_NOISE_RADIUS}] m, got {}", show_real(radius)),
    ))
}

/// Rejects a cloud name that is empty, longer than [`super::MAX_NAME_BYTES`], or the name or id
/// of an instance of the scene or of an object attached to its robot (names the checks report
/// and the allowed-collision matrix reads), naming `name`.
fn check_cloud_name(s: &SceneState, name: &str) -> Result<()> {
    if name.is_empty() {
        return Err(Error::invalid("name", "must not be empty: name the cloud (1 to 256 bytes)"));
    }
    check_name("name", name)?;
    let shown = sublevel_core::error::clip(name);
    let attached = s.planning.robot.iter().flat_map(|r| r.attached.iter().map(|a| &a.name));
    if s.instances.contains_key(name) || s.planning.names.values().chain(attached).any(|n| n == name) {
        return Err(Error::invalid(
            "name",
            format!("`{shown}` is the name of an object of the scene: name the point cloud otherwise"),
        ));
    }
    Ok(())
}

impl Catalog {
    /// Checks that scene `scene_id` exists and `name` is a name its next cloud may take (the
    /// same rule [`Catalog::set_point_cloud`] applies, and not the name of a link of the scene's
    /// robot: the allowed-collision matrix would read the link's row for the cloud), before a
    /// frame's work is spent.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::InvalidArgument`] naming `name`.
    pub fn check_point_cloud_name(&self, scene_id: &str, name: &str) -> Result<()> {
        self.with_scene(scene_id, |s| check_cloud_name(s, name))?;
        if let Ok(Some(placed)) = self.placed_robot(scene_id) {
            if placed.robot.model.link_index(name).is_some() {
                return Err(Error::invalid(
                    "name",
                    format!(
                        "`{}` is a link of the scene's robot: name the point cloud otherwise",
                        sublevel_core::error::clip(name)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Builds the cloud of `frame` for scene `scene_id` (module docs): filters, self filter (the
    /// scene's robot, with its attached objects, at the scene's joint positions and base), k-d
    /// tree. Takes milliseconds to a second for a large frame and holds no lock while it works:
    /// call it off the async workers.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::InvalidArgument`] naming `noise_radius`,
    /// `sensor_pose`, `filter.…` or `filter.self_filter_padding`;
    /// [`Error::FailedPrecondition`] for the self filter of a scene without a robot (or whose
    /// robot was deleted); [`Error::ResourceExhausted`] naming `points` past
    /// [`sublevel_robot::cloud::MAX_CLOUD_POINTS`] points kept; [`Error::Cancelled`] when the
    /// calling thread's cancellation scope ([`sublevel_core::cancel`]) is cancelled, looked at
    /// between the filters, the self filter and the k-d tree.
    pub fn build_point_cloud(&self, scene_id: &str, frame: &CloudFrame) -> Result<BuiltCloud> {
        check_noise_radius(frame.noise_radius)?;
        frame.filter.validate()?;
        if let Some(padding) = frame.self_filter {
            if !(padding.is_finite() && padding >= 0.0) {
                return Err(Error::invalid(
                    "filter.self_filter_padding",
                    format!("must be finite and >= 0 m, got {}", show_real(padding)),
                ));
            }
        }
        let positions = self.with_scene(scene_id, |s| Ok(s.planning.joint_positions.clone()))?;
        let robot = match frame.self_filter {
            None => None,
            Some(padding) => {
                let placed = self.placed_robot(scene_id)?.ok_or_else(|| {
                    Error::FailedPrecondition(format!(
                        "filter.self_filter: scene `{scene_id}` has no robot to filter out; place one \
                         (SetSceneRobot) or turn the self filter off"
                    ))
                })?;
                let q = placed.configuration(&positions);
                Some((placed, q, padding))
            }
        };
        let mut counts = FilterCounts { input: frame.holes, holes: frame.holes, ..FilterCounts::default() };
        let mut points = frame.filter.apply(&frame.points, &frame.sensor_pose, &mut counts)?;
        check_abandoned()?;
        if let Some((placed, q, padding)) = robot {
            counts.robot = self_filter(&placed.robot, &q, &placed.base, frame.noise_radius, padding, &mut points)?;
        }
        counts.kept = points.len();
        check_abandoned()?;
        let cloud = PointCloud::new(points, frame.noise_radius).map_err(|e| match e {
            Error::InvalidArgument { field, reason } if field == "radius" => Error::invalid("noise_radius", reason),
            other => other,
        })?;
        Ok(BuiltCloud { cloud, counts, bodies: None })
    }

    /// Gives `built` the bodies model (module docs): its points clustered and each cluster fitted
    /// by a convex body, warm-started from the bodies of the cloud `name` of scene `scene_id`
    /// when it has them ([`CloudBodies::update`]). Fits take tens of milliseconds each, on
    /// `settings.threads` threads, holding no lock: call it off the async workers.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::InvalidArgument`] naming a field of
    /// `settings` ([`CloudBodySettings::validate`]); [`Error::Cancelled`] when the request was
    /// abandoned.
    pub fn build_cloud_bodies(
        &self,
        scene_id: &str,
        name: &str,
        built: &mut BuiltCloud,
        settings: &CloudBodySettings,
    ) -> Result<()> {
        let previous = self.with_scene(scene_id, |s| {
            Ok(s.clouds.get(name).and_then(|c| c.bodies.as_ref()).map(|b| b.state.clone()))
        })?;
        let mut state = previous.unwrap_or_default();
        let report = state.update(built.cloud.points(), built.cloud.radius(), settings)?;
        let objects = state
            .clusters()
            .iter()
            .map(|c| WorldBody::new(c.body.clone()).map(Arc::new))
            .collect::<Result<Vec<_>>>()?;
        built.bodies = Some(CloudBodiesModel { state, objects, report });
        Ok(())
    }

    /// Sets (or replaces) the cloud `name` of scene `scene_id` to `built`, atomically, under the
    /// scene's lock; raises the scene version. `max_total_bytes` bounds the memory of every
    /// scene's clouds together, this one's replacement counted in place of the old.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::InvalidArgument`] naming `name` (empty, too
    /// long, the name of an instance or attached object); [`Error::ResourceExhausted`] naming
    /// `name` when the scene holds [`MAX_CLOUDS_PER_SCENE`] other clouds, or naming the cloud
    /// memory with its numbers when the total would pass `max_total_bytes`;
    /// [`Error::Cancelled`] when the calling thread's cancellation scope
    /// ([`sublevel_core::cancel`]) is cancelled, looked at under the scene's lock: an abandoned
    /// update is never stored. Nothing changes on error.
    pub fn set_point_cloud(
        &self,
        scene_id: &str,
        name: &str,
        built: BuiltCloud,
        max_total_bytes: usize,
    ) -> Result<CloudUpdate> {
        let new = built.memory_bytes();
        let cloud = Arc::new(built.cloud);
        let bodies = built.bodies.map(Arc::new);
        self.with_scene(scene_id, |s| {
            check_abandoned()?;
            check_cloud_name(s, name)?;
            let old = s.clouds.get(name).map(|c| c.memory_bytes);
            if old.is_none() && s.clouds.len() >= MAX_CLOUDS_PER_SCENE {
                return Err(Error::ResourceExhausted(format!(
                    "name: scene `{scene_id}` holds {} point clouds, the most a scene may hold \
                     ({MAX_CLOUDS_PER_SCENE}); replace one by its name or remove one (RemovePointCloud)",
                    s.clouds.len()
                )));
            }
            let old = old.unwrap_or(0);
            self.cloud_bytes
                .fetch_update(Ordering::AcqRel, Ordering::Acquire, |held| {
                    let next = held.saturating_sub(old) + new;
                    (next <= max_total_bytes).then_some(next)
                })
                .map_err(|held| {
                    Error::ResourceExhausted(format!(
                        "point-cloud memory: the server's clouds hold {held} bytes ({old} of them this cloud's), \
                         and this frame's cloud of {} points takes {new} bytes, over the limit of \
                         {max_total_bytes} bytes; crop the frame (filter.workspace, filter.max_range), \
                         coarsen it (filter.voxel) or remove clouds",
                        cloud.len()
                    ))
                })?;
            let version = s.changed();
            let entry =
                SceneCloud { name: name.to_owned(), cloud, counts: built.counts, version, memory_bytes: new, bodies };
            let mut next = (*s.clouds).clone();
            next.insert(name.to_owned(), Arc::new(entry));
            s.clouds = Arc::new(next);
            Ok(CloudUpdate { scene_version: version, memory_bytes: new })
        })
    }

    /// Removes the cloud `name` of scene `scene_id`; returns the scene version it produced.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kinds `scene`, `point cloud`).
    pub fn remove_point_cloud(&self, scene_id: &str, name: &str) -> Result<u64> {
        self.with_scene(scene_id, |s| {
            let Some(old) = s.clouds.get(name) else { return Err(Error::not_found("point cloud", name)) };
            self.cloud_bytes.fetch_sub(old.memory_bytes, Ordering::AcqRel);
            let mut next = (*s.clouds).clone();
            next.remove(name);
            s.clouds = Arc::new(next);
            Ok(s.changed())
        })
    }

    /// The version of scene `scene_id` (module docs).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`).
    pub fn scene_version(&self, scene_id: &str) -> Result<u64> {
        self.with_scene(scene_id, |s| Ok(s.version))
    }

    /// Bytes held by the point clouds of every scene.
    pub fn cloud_bytes(&self) -> usize {
        self.cloud_bytes.load(Ordering::Acquire)
    }

    /// Every instance of scene `scene_id` posed (ordered by id), its clouds and its version, all
    /// read under one lock: one moment of the scene (CheckScene's input). Bodies not built yet
    /// are built after the lock is released.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::FailedPrecondition`] naming a body that does
    /// not validate.
    pub fn posed_scene(&self, scene_id: &str) -> Result<(Vec<PosedInstance>, Arc<CloudSet>, u64)> {
        let (read, clouds, version) = self.with_scene(scene_id, |s| {
            let read: Vec<_> =
                s.instances.iter().map(|(id, inst)| (id.clone(), inst.entry.clone(), inst.pose)).collect();
            Ok((read, s.clouds.clone(), s.version))
        })?;
        let posed = read
            .into_iter()
            .map(|(id, entry, pose)| PosedInstance::of(id, &entry, pose))
            .collect::<Result<Vec<_>>>()?;
        Ok((posed, clouds, version))
    }

    /// Drops the clouds of a scene being deleted (its lock held) from the memory count.
    pub(super) fn release_clouds(&self, s: &mut SceneState) {
        let held: usize = s.clouds.values().map(|c| c.memory_bytes).sum();
        self.cloud_bytes.fetch_sub(held, Ordering::AcqRel);
        s.clouds = Arc::default();
    }
}
