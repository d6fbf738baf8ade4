//! Stored robots, and a scene as the world of the robot checks.
//!
//! A robot is stored as its robot file ([`RobotRecord`]) and held in memory as the validated
//! [`FittedRobot`] (kinematic model, link bodies, meshes with their BVHs), built once when it is
//! uploaded or the catalog opens, and shared by every check through an `Arc`. A scene becomes the
//! world of [`sublevel_robot::RobotChecker`] through [`Catalog::robot_world`]: its instances of
//! exact primitives and of bodies that kept the mesh they were fitted to (exact mesh obstacles),
//! named as the planning scene it was imported from names them, and its point clouds (named
//! by their names, [`super::clouds`]), with that scene's allowed-collision matrix and robot state.

use super::{check_name, new_id, read, write, Catalog};
use crate::store::Store;
use crate::{Error, PlanningContext, Result, RobotRecord};
use std::collections::BTreeMap;
use std::sync::Arc;
use sublevel_core::math::Isometry3;
use sublevel_robot::{FittedRobot, RobotFile, WorldObject};

/// A stored robot, validated and ready for checks.
#[derive(Debug)]
pub struct RobotEntry {
    /// The robot's id (`r-…`).
    pub id: String,
    /// Its name.
    pub name: String,
    /// The robot: model, geometries, allowed pairs, and the file it was read from.
    pub robot: Arc<FittedRobot>,
}

/// A scene as the world of the robot checks.
#[derive(Clone, Debug)]
pub struct RobotWorld {
    /// The scene's instances as world objects, ordered by instance id.
    pub objects: Vec<WorldObject>,
    /// The instance id of each object.
    pub instance_ids: Vec<String>,
    /// The planning scene's names, allowed-collision matrix and robot state (empty for a scene
    /// not imported from one).
    pub planning: Arc<PlanningContext>,
    /// The robot placed in the scene, when there is one ([`Catalog::set_scene_robot`]).
    pub robot: Option<Arc<super::PlacedRobot>>,
    /// The scene version the world was read at ([`Catalog::scene_version`]); 0 for
    /// [`RobotWorld::empty`].
    pub scene_version: u64,
    /// The scene's point clouds, as read with the instances (their objects follow the
    /// instances' in `objects`).
    pub clouds: Arc<super::CloudSet>,
}

/// Every stored robot, validated; one that no longer validates is moved to the store's quarantine
/// with the reason, and the rest load.
pub(super) fn load(store: &dyn Store) -> Result<BTreeMap<String, Arc<RobotEntry>>> {
    let mut robots = BTreeMap::new();
    for (id, rec) in store.list_robots()? {
        let mut file = rec.file;
        // Robots stored before robot files carried their digest were validated when stored.
        if file.integrity.is_empty() {
            file.seal()?;
        }
        match FittedRobot::from_file(file) {
            Ok(robot) => {
                robots.insert(id.clone(), Arc::new(RobotEntry { id, name: rec.name, robot: Arc::new(robot) }));
            }
            Err(e) => {
                tracing::warn!(robot_id = %id, error = %e, "quarantining robot");
                store.quarantine("robots", &id, &format!("does not validate: {e}"))?;
            }
        }
    }
    Ok(robots)
}

impl RobotWorld {
    /// A world with no object, no planning context and no robot (self-collision checks only).
    pub fn empty() -> Self {
        Self {
            objects: Vec::new(),
            instance_ids: Vec::new(),
            planning: Arc::default(),
            robot: None,
            scene_version: 0,
            clouds: Arc::default(),
        }
    }

    /// Moves the objects of the instances `poses` names (instance id, pose) to those poses;
    /// instances the world lacks are ignored.
    pub fn with_poses<'a>(&mut self, poses: impl IntoIterator<Item = (&'a str, &'a sublevel_core::math::Isometry3)>) {
        for (id, pose) in poses {
            if let Some(k) = self.instance_ids.iter().position(|i| i == id) {
                self.objects[k].pose = *pose;
            }
        }
    }
}

impl Catalog {
    /// Validates a robot file and stores it under a new id. `name` empty: the URDF's robot name.
    /// Building the robot (its bodies, its meshes' BVHs) takes milliseconds to a second: call it
    /// off the async workers.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `name` (too long) or the file's field (as
    /// [`FittedRobot::from_file`]); [`Error::Storage`].
    pub fn add_robot(&self, name: &str, file: RobotFile) -> Result<Arc<RobotEntry>> {
        check_name("name", name)?;
        let robot = FittedRobot::from_file(file)?;
        let name = if name.is_empty() { robot.file.name.clone() } else { name.to_owned() };
        let id = new_id("r");
        self.store.put_robot(&id, &RobotRecord { name: name.clone(), file: robot.file.clone() })?;
        let entry = Arc::new(RobotEntry { id: id.clone(), name, robot: Arc::new(robot) });
        write(&self.robots).insert(id, entry.clone());
        Ok(entry)
    }

    /// The robot `id`. With a shared store, a robot another replica stored since this catalog
    /// opened is loaded here on first use.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `robot`); [`Error::Storage`].
    pub fn robot(&self, id: &str) -> Result<Arc<RobotEntry>> {
        if let Some(entry) = read(&self.robots).get(id).cloned() {
            return Ok(entry);
        }
        if self.store.shared() {
            let loaded = load(self.store.as_ref())?;
            let mut robots = write(&self.robots);
            for (k, entry) in loaded {
                robots.entry(k).or_insert(entry);
            }
            if let Some(entry) = robots.get(id) {
                return Ok(entry.clone());
            }
        }
        Err(Error::not_found("robot", id))
    }

    /// Whether the catalog's store is shared by several replicas (PostgreSQL): then a robot,
    /// scene or body may have to be loaded from the database on first use.
    pub fn shared_store(&self) -> bool {
        self.store.shared()
    }

    /// Every robot, ordered by id.
    pub fn robots(&self) -> Vec<Arc<RobotEntry>> {
        read(&self.robots).values().cloned().collect()
    }

    /// Deletes a robot that no scene holds (as [`Catalog::delete_body`] refuses a body an
    /// instance uses).
    ///
    /// # Errors
    /// [`Error::NotFound`]; [`Error::FailedPrecondition`] naming a scene whose robot it is
    /// ([`Catalog::set_scene_robot`]); [`Error::Storage`].
    pub fn delete_robot(&self, id: &str) -> Result<()> {
        // Lock order: robots, then scenes, then one scene (as bodies → scenes → scene).
        let mut robots = write(&self.robots);
        if !robots.contains_key(id) && !self.store.shared() {
            return Err(Error::not_found("robot", id));
        }
        for scene in super::read(&self.scenes).values() {
            let s = super::lock(scene);
            if s.planning.robot.as_ref().is_some_and(|r| r.robot_id == id) {
                return Err(Error::FailedPrecondition(format!(
                    "robot `{id}` is the robot of scene `{}`; remove it from the scene first (ClearSceneRobot) or delete the scene",
                    s.id
                )));
            }
        }
        let removed = self.store.delete_robot(id)?;
        if robots.remove(id).is_none() && !removed {
            return Err(Error::not_found("robot", id));
        }
        Ok(())
    }

    /// Scene `scene_id` as the world of the robot checks: every instance as a [`WorldObject`]
    /// named by the planning scene's name for it (else its instance id), at its stored pose — an
    /// exact primitive, or the mesh kept with a body fitted to it (an imported planning scene's
    /// mesh, with the body's root for the sos bound) — then every point cloud as a points object
    /// named by its name (its points already in the world frame), all of one moment of the
    /// scene, and the scene's robot ([`Catalog::placed_robot`]).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::FailedPrecondition`] naming an instance of a
    /// fitted body without a kept mesh (robot checks take exact primitives and meshes as
    /// obstacles) or of a body that no longer validates, or a scene robot that was deleted.
    pub fn robot_world(&self, scene_id: &str) -> Result<RobotWorld> {
        let view = self.get_scene(scene_id)?;
        let mut objects = Vec::with_capacity(view.instances.len() + view.clouds.len());
        let mut instance_ids = Vec::with_capacity(view.instances.len());
        for inst in &view.instances {
            let entry = self.body(&inst.body_id)?;
            let name = view.planning.names.get(&inst.id).cloned().unwrap_or_else(|| inst.id.clone());
            if let Some(mesh) = entry.world_mesh() {
                objects.push(WorldObject::mesh(name, mesh?, inst.pose));
            } else if let Some(primitive) = entry.built()?.primitive {
                objects.push(WorldObject::primitive(name, primitive, inst.pose));
            } else {
                return Err(Error::FailedPrecondition(format!(
                    "instance `{}` of scene `{scene_id}` is the fitted body `{}` without its mesh: robot checks take \
                     exact primitives (box, sphere, cylinder, capsule, halfspace) and the meshes of imported planning \
                     scenes as obstacles",
                    inst.id, inst.body_id
                )));
            }
            instance_ids.push(inst.id.clone());
        }
        for c in view.clouds.values() {
            match &c.bodies {
                None => objects.push(WorldObject::points(c.name.clone(), c.cloud.clone(), Isometry3::identity())),
                Some(model) => objects.extend(
                    model.objects.iter().map(|b| WorldObject::body(c.name.clone(), b.clone(), Isometry3::identity())),
                ),
            }
        }
        let robot = self.placed_robot(scene_id)?;
        Ok(RobotWorld {
            objects,
            instance_ids,
            planning: view.planning,
            robot,
            scene_version: view.version,
            clouds: view.clouds,
        })
    }

    /// Replaces the planning context of scene `scene_id` (written through to the store).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::InvalidArgument`] when it would not read back
    /// from the store (a non-finite joint position); [`Error::Storage`].
    pub fn set_planning(&self, scene_id: &str, planning: PlanningContext) -> Result<()> {
        self.update_planning(scene_id, |_| Ok(planning))
    }
}
