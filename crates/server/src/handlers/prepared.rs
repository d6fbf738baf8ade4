//! Prepared robot checkers, kept across requests until their scene or robot changes.
//!
//! A check request names a robot, a scene (its objects moved by a query stream's view), attached
//! objects and link padding. Reading that setting from the catalog (the world's objects, the
//! robot with its attached objects) and building a [`RobotChecker`] for it (its pair lists and
//! scratch) costs far more than checking one configuration, so the service keeps them:
//!
//! - **Key**: the robot id (empty: the scene's robot), the scene id, the request's attached
//!   objects (encoded), its link padding (by link) and the ids of the instances its view moves.
//!   The base pose is not part of it: it is an argument of every check.
//! - **Version**, compared at every use: the stored robot (the catalog's `Arc`, or the scene
//!   robot's), the scene's planning context (its `Arc`: every change of names, allowed-collision
//!   matrix, joint positions or scene robot replaces it), every instance's id and pose (the
//!   view's poses applied), the scene version and the scene's point clouds (the `Arc` of its
//!   cloud set, replaced whole by every cloud update: a checker never answers against a replaced
//!   cloud). Instance ids are never reused and an instance never changes its
//!   body; robots are immutable under their id. The entry holds the `Arc`s it compares, so none
//!   is freed and its address reused while the entry lives. An entry whose version differs is
//!   stale: it is dropped and a new one built. Deleting a scene or a robot drops its entries.
//! - **Bound**: at most four entries per batch slot (at least eight), the least recently used
//!   dropped first; each keeps at most one idle checker per
//!   batch slot and one more (the inline checks on the async workers).
//!
//! A checker is used by one thread at a time: a request (or a chunk of one) takes an idle
//! checker of its entry ([`Prepared::take`]), or builds one when all are in use, and gives it
//! back after ([`Prepared::put`]). A checker is owned with its robot ([`Checker`], a
//! `self_cell`), so an entry can be shared by threads behind an `Arc`.

use crate::convert as cv;
use crate::pb;
use crate::{Error, Result};
use prost::Message;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{FittedRobot, RobotChecker};
use sublevel_scene::{Catalog, CloudSet, PlanningContext, RobotWorld};

self_cell::self_cell!(
    /// A configuration checker that owns the robot it checks (the robot with a request's
    /// attached objects, shared by every checker of its entry).
    pub(super) struct Checker {
        owner: Arc<FittedRobot>,
        #[not_covariant]
        dependent: RobotChecker,
    }
);

/// What a check request says of its robot and world.
pub(super) struct Asked {
    /// The robot's id; empty: the scene's robot.
    pub(super) robot_id: String,
    /// The scene's id; empty: no world (self collisions only).
    pub(super) scene_id: String,
    /// The robot's root pose; `None`: the scene robot's base, else the identity. Not part of
    /// the prepared setting (its checks take the base as an argument).
    pub(super) base: Option<pb::Pose>,
    /// Objects attached to links for this request.
    pub(super) attached: Vec<pb::AttachedObject>,
    /// Padding per link (meters), replacing the scene robot's link by link.
    pub(super) link_padding: HashMap<String, Real>,
    /// Pose overrides of scene instances (instance id → pose): a query stream's view.
    pub(super) poses: Vec<(String, Isometry3)>,
}

impl Asked {
    /// The setting a request names, its fields moved out of the request (`base` left to the
    /// caller, which passes it to each check).
    pub(super) fn taken(
        robot_id: &mut String,
        scene_id: &mut String,
        attached: &mut Vec<pb::AttachedObject>,
        link_padding: &mut HashMap<String, Real>,
        poses: Vec<(String, Isometry3)>,
    ) -> Self {
        Self {
            robot_id: std::mem::take(robot_id),
            scene_id: std::mem::take(scene_id),
            base: None,
            attached: std::mem::take(attached),
            link_padding: std::mem::take(link_padding),
            poses,
        }
    }
}

/// The key of a prepared setting (module docs).
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
struct Key {
    robot_id: String,
    scene_id: String,
    /// The request's attached objects, protobuf-encoded in order.
    attached: Vec<u8>,
    /// The request's link padding by link name, the padding's bits.
    link_padding: Vec<(String, u64)>,
    /// The instances the request's view moves, sorted.
    moved: Vec<String>,
}

impl Key {
    fn of(asked: &Asked) -> Self {
        let mut attached = Vec::new();
        for a in &asked.attached {
            // Length-delimited, so two lists never encode alike.
            a.encode_length_delimited(&mut attached).unwrap_or_default();
        }
        let mut link_padding: Vec<(String, u64)> =
            asked.link_padding.iter().map(|(l, p)| (l.clone(), p.to_bits())).collect();
        link_padding.sort_unstable();
        let mut moved: Vec<String> = asked.poses.iter().map(|(id, _)| id.clone()).collect();
        moved.sort_unstable();
        Self { robot_id: asked.robot_id.clone(), scene_id: asked.scene_id.clone(), attached, link_padding, moved }
    }
}

/// What a prepared setting was built from (module docs): equal versions, equal checkers.
#[derive(Clone, Debug)]
struct Version {
    /// The stored robot, before the request's attached objects.
    robot: Arc<FittedRobot>,
    /// The scene's planning context; `None` without a scene.
    planning: Option<Arc<PlanningContext>>,
    /// Every instance of the scene by id, at its pose (the view's poses applied).
    instances: Vec<(String, Isometry3)>,
    /// The scene version (0 without a scene).
    scene_version: u64,
    /// The scene's point clouds; `None` without a scene.
    clouds: Option<Arc<CloudSet>>,
}

impl Version {
    /// Whether `self` is the version of the scene `view` (with `poses` applied) and `robot`.
    fn is(
        &self,
        robot: &Arc<FittedRobot>,
        view: Option<&sublevel_scene::SceneView>,
        poses: &[(String, Isometry3)],
    ) -> bool {
        if !Arc::ptr_eq(&self.robot, robot) {
            return false;
        }
        match (view, &self.planning) {
            (None, None) => self.instances.is_empty(),
            (Some(view), Some(planning)) => {
                Arc::ptr_eq(&view.planning, planning)
                    && view.version == self.scene_version
                    && self.clouds.as_ref().is_some_and(|c| Arc::ptr_eq(&view.clouds, c))
                    && view.instances.len() == self.instances.len()
                    && view.instances.iter().zip(&self.instances).all(|(i, (id, pose))| {
                        i.id == *id && *pose == poses.iter().find(|(p, _)| *p == i.id).map_or(i.pose, |(_, p)| *p)
                    })
            }
            _ => false,
        }
    }
}

/// A setting ready for checks: the robot (with the request's attached objects), the world (the
/// view's poses applied), the default base, the link padding, and idle checkers of them.
pub(super) struct Prepared {
    version: Version,
    /// The robot with the request's attached objects.
    pub(super) robot: Arc<FittedRobot>,
    /// The scene's world and planning state, the view's poses applied.
    pub(super) world: Arc<RobotWorld>,
    /// The robot's root pose when the request gives none: the scene robot's base, else the
    /// identity.
    pub(super) base: Isometry3,
    /// Padding per link (meters).
    pub(super) link_padding: Vec<(String, Real)>,
    /// Checkers not in use.
    idle: Mutex<Vec<Checker>>,
    /// Most idle checkers kept.
    max_idle: usize,
    /// When it was last used ([`PreparedCheckers`]'s clock).
    used: AtomicU64,
}

impl std::fmt::Debug for Prepared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prepared").field("objects", &self.world.objects.len()).finish_non_exhaustive()
    }
}

/// A poisoned lock is safe to keep using here: every critical section is one push, pop, insert
/// or removal.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Prepared {
    /// A checker of this setting not in use by anyone else: an idle one, else a new one (the
    /// world's objects copied into its pair lists).
    ///
    /// # Errors
    /// As [`RobotChecker::new`] and [`RobotChecker::set_link_padding`] (naming the link).
    pub(super) fn take(&self) -> Result<Checker> {
        if let Some(checker) = lock(&self.idle).pop() {
            return Ok(checker);
        }
        self.build()
    }

    /// Gives back a checker taken from this setting, to be used again (dropped when enough are
    /// idle), at the mesh level (its other level's plan kept for the next switch).
    pub(super) fn put(&self, mut checker: Checker) {
        // Idle checkers check at the meshes' level: a request that wants another sets it.
        if checker.with_dependent_mut(|_, c| c.set_fidelity(sublevel_robot::Fidelity::Mesh)).is_err() {
            return;
        }
        let mut idle = lock(&self.idle);
        if idle.len() < self.max_idle {
            idle.push(checker);
        }
    }

    fn build(&self) -> Result<Checker> {
        Checker::try_new(self.robot.clone(), |robot| {
            let allowed = self.world.planning.allowed_override();
            let mut checker = RobotChecker::new(robot, self.world.objects.clone(), &allowed)?;
            checker.set_link_padding(&self.link_padding)?;
            Ok(checker)
        })
    }
}

/// The service's prepared settings (module docs).
#[derive(Debug)]
pub(crate) struct PreparedCheckers {
    entries: Mutex<HashMap<Key, Arc<Prepared>>>,
    /// Counts uses, for the least recently used entry.
    clock: AtomicU64,
    /// Most entries kept: four per batch slot, at least eight.
    max_entries: usize,
    /// Most idle checkers per entry: one per batch slot, and one more.
    max_idle: usize,
}

impl PreparedCheckers {
    /// An empty cache for a service of `slots` batch slots.
    pub(crate) fn new(slots: usize) -> Self {
        let slots = slots.max(1);
        Self {
            entries: Mutex::new(HashMap::new()),
            clock: AtomicU64::new(0),
            max_entries: (4 * slots).max(8),
            max_idle: slots + 1,
        }
    }

    /// Drops the entries of scene `scene_id` (deleted).
    pub(crate) fn forget_scene(&self, scene_id: &str) {
        lock(&self.entries).retain(|k, _| k.scene_id != scene_id);
    }

    /// Drops the entries that name robot `robot_id` (deleted).
    pub(crate) fn forget_robot(&self, robot_id: &str) {
        lock(&self.entries).retain(|k, _| k.robot_id != robot_id);
    }

    /// The prepared setting of `asked` in `catalog`: the kept one when its version is current,
    /// else a new one (its first checker built, so that a bad setting fails here), kept in place
    /// of the stale one. Reads the catalog: call it off the async workers unless the robot and
    /// the scene are in memory.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kinds `scene`, `robot`); [`Error::FailedPrecondition`] (a scene
    /// holding a fitted body without its mesh, a deleted scene robot); [`Error::InvalidArgument`]
    /// naming `robot_id` (none given, and the scene has no robot), `attached[k]…` or the link
    /// padding's link.
    pub(super) fn get(&self, catalog: &Catalog, asked: &Asked) -> Result<Arc<Prepared>> {
        let key = Key::of(asked);
        let view = if asked.scene_id.is_empty() {
            None
        } else {
            Some(catalog.get_scene(cv::require_id("scene_id", &asked.scene_id)?)?)
        };
        let robot = if asked.robot_id.is_empty() {
            let placed = match &view {
                Some(view) => catalog.placed_robot(&view.id)?,
                None => None,
            };
            placed.ok_or_else(no_robot)?.robot.clone()
        } else {
            catalog.robot(cv::require_id("robot_id", &asked.robot_id)?)?.robot.clone()
        };
        let kept = lock(&self.entries).get(&key).cloned();
        if let Some(prepared) = kept.filter(|p| p.version.is(&robot, view.as_ref(), &asked.poses)) {
            prepared.used.store(self.clock.fetch_add(1, Ordering::Relaxed), Ordering::Relaxed);
            return Ok(prepared);
        }
        let prepared = Arc::new(self.prepare(catalog, asked)?);
        // Its first checker: a setting that does not build fails now, and is not kept.
        let first = prepared.build()?;
        prepared.put(first);
        prepared.used.store(self.clock.fetch_add(1, Ordering::Relaxed), Ordering::Relaxed);
        let mut entries = lock(&self.entries);
        if entries.len() >= self.max_entries && !entries.contains_key(&key) {
            let oldest = entries.iter().min_by_key(|(_, p)| p.used.load(Ordering::Relaxed)).map(|(k, _)| k.clone());
            if let Some(oldest) = oldest {
                entries.remove(&oldest);
            }
        }
        entries.insert(key, prepared.clone());
        Ok(prepared)
    }

    /// Reads the setting of `asked` from the catalog and builds its robot and world.
    fn prepare(&self, catalog: &Catalog, asked: &Asked) -> Result<Prepared> {
        let mut world = if asked.scene_id.is_empty() {
            RobotWorld::empty()
        } else {
            catalog.robot_world(cv::require_id("scene_id", &asked.scene_id)?)?
        };
        world.with_poses(asked.poses.iter().map(|(id, p)| (id.as_str(), p)));
        let (source, base, mut padding) = if asked.robot_id.is_empty() {
            let placed = world.robot.clone().ok_or_else(no_robot)?;
            (placed.robot.clone(), placed.base, placed.link_padding.clone())
        } else {
            let entry = catalog.robot(cv::require_id("robot_id", &asked.robot_id)?)?;
            (entry.robot.clone(), Isometry3::identity(), Vec::new())
        };
        for (link, p) in &asked.link_padding {
            match padding.iter_mut().find(|(l, _)| l == link) {
                Some(entry) => entry.1 = *p,
                None => padding.push((link.clone(), *p)),
            }
        }
        let version = Version {
            robot: source.clone(),
            planning: (!asked.scene_id.is_empty()).then(|| world.planning.clone()),
            instances: world.instance_ids.iter().cloned().zip(world.objects.iter().map(|o| o.pose)).collect(),
            scene_version: world.scene_version,
            clouds: (!asked.scene_id.is_empty()).then(|| world.clouds.clone()),
        };
        let scene_attached: Vec<&str> = match (&world.robot, asked.robot_id.is_empty()) {
            (Some(placed), true) => placed.record.attached.iter().map(|a| a.name.as_str()).collect(),
            _ => Vec::new(),
        };
        check_names(&source, &world, &scene_attached, &asked.attached)?;
        Ok(Prepared {
            version,
            robot: with_attached(&source, &asked.attached)?,
            world: Arc::new(world),
            base,
            link_padding: padding,
            idle: Mutex::new(Vec::new()),
            max_idle: self.max_idle,
            used: AtomicU64::new(0),
        })
    }
}

/// Refuses a setting in which one name stands for things of two kinds: a link of the robot, a
/// scene object (an instance, by its planning-scene name or id), a point cloud, an object
/// attached by the request. The allowed-collision matrix and the answers key pairs by name, so a
/// cloud named like a link would take the link's row of the matrix (and with it every pair the
/// matrix allows the link), turning an obstacle into free space; MoveIt keeps one namespace for
/// links, world objects and attached objects for the same reason.
///
/// # Errors
/// [`Error::FailedPrecondition`] naming the scene's object or cloud that shares a link's name, or
/// the cloud that shares an object's name or the name of an object attached to the scene's
/// robot (`scene_attached`; the scene must be changed); [`Error::InvalidArgument`] naming
/// `attached[k].name` (a control character, or the name of a link, object or cloud).
fn check_names(
    robot: &FittedRobot,
    world: &RobotWorld,
    scene_attached: &[&str],
    attached: &[pb::AttachedObject],
) -> Result<()> {
    let links = robot.model.links();
    let is_link = |name: &str| links.iter().any(|l| l.name == name);
    let instances = &world.objects[..world.instance_ids.len()];
    let clouds: Vec<&str> = world.clouds.keys().map(String::as_str).collect();
    for o in instances {
        if is_link(&o.name) {
            return Err(Error::FailedPrecondition(format!(
                "object `{}` of the scene has the name of a link of the robot: the allowed-collision matrix would read                  the link's entries for it; rename the object",
                sublevel_core::error::clip(&o.name)
            )));
        }
    }
    for name in &clouds {
        let clash = if is_link(name) {
            Some("a link of the robot")
        } else if instances.iter().any(|o| o.name == *name) {
            Some("an object of the scene")
        } else if scene_attached.contains(name) {
            Some("an object attached to the scene's robot")
        } else {
            None
        };
        if let Some(what) = clash {
            return Err(Error::FailedPrecondition(format!(
                "point cloud `{}` of the scene has the name of {what}: the allowed-collision matrix would read its                  entries for the cloud; remove the cloud (RemovePointCloud) and send it under another name",
                sublevel_core::error::clip(name)
            )));
        }
    }
    for (k, a) in attached.iter().enumerate() {
        let field = format!("attached[{k}].name");
        if let Some(c) = a.name.chars().find(|c| c.is_control()) {
            return Err(Error::invalid(field, format!("holds the control character U+{:04X}", c as u32)));
        }
        let clash = if is_link(&a.name) {
            Some("a link of the robot")
        } else if instances.iter().any(|o| o.name == a.name) {
            Some("an object of the scene")
        } else if clouds.contains(&a.name.as_str()) {
            Some("a point cloud of the scene")
        } else {
            None
        };
        if let Some(what) = clash {
            return Err(Error::invalid(
                field,
                format!(
                    "`{}` is the name of {what}: name the attached object otherwise",
                    sublevel_core::error::clip(&a.name)
                ),
            ));
        }
    }
    Ok(())
}

/// The error of a check that names no robot in a scene without one.
fn no_robot() -> Error {
    Error::invalid("robot_id", "required: name a robot, or a scene holding one (SetSceneRobot)")
}

/// `robot` with `attached` objects added (`robot` itself when there are none: a copy of it when
/// there are, its meshes' BVHs shared, its vertices copied).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `attached[k]` and its field.
pub(super) fn with_attached(robot: &Arc<FittedRobot>, attached: &[pb::AttachedObject]) -> Result<Arc<FittedRobot>> {
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

#[cfg(test)]
#[path = "prepared_tests.rs"]
mod tests;
