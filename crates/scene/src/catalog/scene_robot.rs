//! The robot of a scene: a stored robot placed at a base pose, at the scene's joint positions,
//! with its grasped objects and link padding ([`crate::SceneRobot`]).
//!
//! It is stored with the scene's planning context (written through to the store, so it survives
//! a restart) and held in memory, once built, as a [`PlacedRobot`]: the stored robot with its
//! attached objects added, shared by every check through an `Arc` until the scene's robot
//! changes. Every change is validated whole before anything is written (all or nothing).

use super::Catalog;
use super::RobotWorld;
use crate::{AttachedRecord, Error, PlanningContext, Result, SceneRobot};
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::primitive::Primitive;
use sublevel_robot::{CheckOptions, ConfigurationAnswer, FittedRobot, RobotChecker};

/// A scene's robot, ready for checks.
#[derive(Clone, Debug)]
pub struct PlacedRobot {
    /// The stored robot's id.
    pub robot_id: String,
    /// The robot with the scene's attached objects added (the stored one itself when there are
    /// none).
    pub robot: Arc<FittedRobot>,
    /// The pose of its root link in the scene.
    pub base: Isometry3,
    /// Padding per link (link name, meters ≥ 0).
    pub link_padding: Vec<(String, Real)>,
    /// The record it was built from.
    pub record: SceneRobot,
}

impl PlacedRobot {
    /// The robot's configuration at `joint_positions` (by joint name; the robot's joints not
    /// named take 0), in [`sublevel_robot::RobotModel::variable_names`] order.
    pub fn configuration(&self, joint_positions: &[(String, Real)]) -> Vec<Real> {
        self.robot
            .model
            .variable_names()
            .iter()
            .map(|name| joint_positions.iter().find(|(n, _)| n == name).map_or(0.0, |(_, v)| *v))
            .collect()
    }
}

/// The robot of a scene checked at the scene's joint positions ([`Catalog::check_scene_robot`]).
#[derive(Clone, Debug)]
pub struct SceneRobotCheck {
    /// The scene's robot.
    pub placed: Arc<PlacedRobot>,
    /// The world it was checked against.
    pub world: RobotWorld,
    /// Its configuration (the scene's joint positions).
    pub configuration: Vec<Real>,
    /// The answer.
    pub answer: ConfigurationAnswer,
}

/// Builds a scene robot from its record, validating everything it holds.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `base`, `attached[k]` and its field (an unknown link, a
/// name that is repeated, longer than [`crate::MAX_NAME_BYTES`] or a link's name, a halfspace, a
/// pose that is not finite), or `link_padding[LINK]`.
fn build(stored: &Arc<FittedRobot>, record: &SceneRobot) -> Result<PlacedRobot> {
    let base = record.base.to_isometry("base")?;
    let robot = if record.attached.is_empty() {
        stored.clone()
    } else {
        let mut robot = (**stored).clone();
        for (k, a) in record.attached.iter().enumerate() {
            let field = format!("attached[{k}]");
            super::check_name(&format!("{field}.name"), &a.name)?;
            let shown = sublevel_core::error::clip(&a.name);
            if record.attached[..k].iter().any(|b| b.name == a.name) {
                return Err(Error::invalid(format!("{field}.name"), format!("`{shown}` is attached twice")));
            }
            // Contacts are reported, and allowed, by name: an attached object named as a link
            // would be mistaken for it.
            if stored.model.link_index(&a.name).is_some() {
                return Err(Error::invalid(
                    format!("{field}.name"),
                    format!("`{shown}` is the name of a link of the robot: name the attached object otherwise"),
                ));
            }
            let primitive = Primitive::from_file(&a.primitive).map_err(|e| prefix(e, &format!("{field}.primitive")))?;
            let origin = a.origin.to_isometry(&format!("{field}.origin"))?;
            robot.attach(&a.link, &a.name, primitive, origin).map_err(|e| prefix(e, &field))?;
        }
        Arc::new(robot)
    };
    RobotChecker::new(&robot, Vec::new(), &|_, _| None)?.set_link_padding(&record.link_padding)?;
    Ok(PlacedRobot {
        robot_id: record.robot_id.clone(),
        robot,
        base,
        link_padding: record.link_padding.clone(),
        record: record.clone(),
    })
}

/// An error's field prefixed by `prefix` (`prefix.field`).
fn prefix(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: format!("{prefix}.{field}"), reason }
        }
        other => other,
    }
}

impl Catalog {
    /// Places robot `record.robot_id` in scene `scene_id` (replacing the scene's robot, if any),
    /// with its attached objects and link padding; `joint_positions` (name, radians or meters),
    /// when given, become the scene's joint positions for the robot's joints (others keep theirs).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kinds `scene`, `robot`); [`Error::InvalidArgument`] naming `base`,
    /// `attached[k]…` (`attached[k].name` also for the name of one of the scene's objects),
    /// `link_padding[LINK]` or `joint_positions…` (nothing changes then); [`Error::Storage`].
    pub fn set_scene_robot(
        &self,
        scene_id: &str,
        record: SceneRobot,
        joint_positions: Option<(&[String], &[Real])>,
    ) -> Result<Arc<PlacedRobot>> {
        let entry = self.robot(&record.robot_id)?;
        let placed = Arc::new(build(&entry.robot, &record)?);
        self.update_planning(scene_id, |planning| {
            if let Some(k) = record.attached.iter().position(|a| planning.names.values().any(|n| *n == a.name)) {
                return Err(Error::invalid(
                    format!("attached[{k}].name"),
                    format!(
                        "`{}` is the name of an object of the scene: name the attached object otherwise",
                        sublevel_core::error::clip(&record.attached[k].name)
                    ),
                ));
            }
            let mut next = planning.clone();
            if let Some((names, values)) = joint_positions {
                next.joint_positions = merged_positions(&placed.robot, planning, names, values)?;
            }
            next.robot = Some(record.clone());
            Ok(next)
        })?;
        self.cache_placed(scene_id, placed.clone());
        Ok(placed)
    }

    /// Removes the robot of scene `scene_id` (its joint positions stay, as an imported robot
    /// state does). Returns whether there was one.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::Storage`].
    pub fn clear_scene_robot(&self, scene_id: &str) -> Result<bool> {
        let mut had = false;
        self.update_planning(scene_id, |planning| {
            had = planning.robot.is_some();
            Ok(PlanningContext { robot: None, ..planning.clone() })
        })?;
        Ok(had)
    }

    /// Sets joint positions of the robot of scene `scene_id`, all or nothing: `names` each once,
    /// `values` one per name (radians, meters). Joints not named keep their positions.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::FailedPrecondition`] when the scene has no
    /// robot; [`Error::InvalidArgument`] naming `joint_positions.joint_names[k]` (a joint the
    /// robot lacks, fixed or mimic, repeated) or `joint_positions.values…` (nothing changes then);
    /// [`Error::Storage`].
    pub fn set_joint_positions(&self, scene_id: &str, names: &[String], values: &[Real]) -> Result<()> {
        let placed = self.require_placed(scene_id)?;
        self.update_planning(scene_id, |planning| {
            Ok(PlanningContext {
                joint_positions: merged_positions(&placed.robot, planning, names, values)?,
                ..planning.clone()
            })
        })
    }

    /// Attaches an object to a link of the robot of scene `scene_id` (replacing an attached
    /// object of the same name).
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::FailedPrecondition`] when the scene has no
    /// robot; [`Error::InvalidArgument`] naming `attached.link`, `attached.primitive` or
    /// `attached.origin`; [`Error::Storage`].
    pub fn attach_object(&self, scene_id: &str, object: AttachedRecord) -> Result<Arc<PlacedRobot>> {
        let placed = self.require_placed(scene_id)?;
        let mut record = placed.record.clone();
        record.attached.retain(|a| a.name != object.name);
        record.attached.push(object);
        let k = record.attached.len() - 1;
        let attached = self.set_scene_robot(scene_id, record, None).map_err(|e| match e {
            Error::InvalidArgument { field, reason } => {
                Error::InvalidArgument { field: field.replacen(&format!("attached[{k}]"), "attached", 1), reason }
            }
            other => other,
        })?;
        Ok(attached)
    }

    /// Detaches the object `name` from the robot of scene `scene_id`.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kinds `scene`, `attached object`); [`Error::FailedPrecondition`] when
    /// the scene has no robot; [`Error::Storage`].
    pub fn detach_object(&self, scene_id: &str, name: &str) -> Result<Arc<PlacedRobot>> {
        let placed = self.require_placed(scene_id)?;
        let mut record = placed.record.clone();
        let before = record.attached.len();
        record.attached.retain(|a| a.name != name);
        if record.attached.len() == before {
            return Err(Error::not_found("attached object", name));
        }
        self.set_scene_robot(scene_id, record, None)
    }

    /// The robot of scene `scene_id`, built (its attached objects added) on first use and kept
    /// until it changes; `None` when the scene has none.
    ///
    /// # Errors
    /// [`Error::NotFound`] (kind `scene`); [`Error::FailedPrecondition`] when the scene's robot
    /// was deleted or no longer builds.
    pub fn placed_robot(&self, scene_id: &str) -> Result<Option<Arc<PlacedRobot>>> {
        let (planning, cached) = self.with_scene(scene_id, |s| Ok((s.planning.clone(), s.placed.clone())))?;
        let Some(record) = &planning.robot else { return Ok(None) };
        let entry = self.robot(&record.robot_id).map_err(|e| match e {
            Error::NotFound { .. } => Error::FailedPrecondition(format!(
                "the robot `{}` of scene `{scene_id}` was deleted: place a robot again (SetSceneRobot)",
                record.robot_id
            )),
            other => other,
        })?;
        if let Some(placed) =
            cached.filter(|p| p.placed.record == *record && Arc::ptr_eq(&p.robot_source, &entry.robot))
        {
            return Ok(Some(placed.placed.clone()));
        }
        let placed = Arc::new(build(&entry.robot, record).map_err(|e| {
            Error::FailedPrecondition(format!("the robot of scene `{scene_id}` no longer builds: {e}"))
        })?);
        self.cache_placed(scene_id, placed.clone());
        Ok(Some(placed))
    }

    /// The robot of scene `scene_id` checked at the scene's joint positions against the scene's
    /// objects (moved to `poses`, instance id → pose, for this check only) and itself, with the
    /// scene's allowed-collision matrix and the robot's link padding; `None` when the scene has no
    /// robot. The check runs the robot's distance searches (up to milliseconds): call it off the
    /// async workers.
    ///
    /// # Errors
    /// As [`Catalog::robot_world`]; [`Error::InvalidArgument`] from the check.
    pub fn check_scene_robot(
        &self,
        scene_id: &str,
        options: &CheckOptions,
        poses: &[(String, Isometry3)],
    ) -> Result<Option<SceneRobotCheck>> {
        // A scene without a robot has nothing to check, whatever its bodies (fitted bodies, which
        // robot checks refuse as obstacles, included).
        if !self.with_scene(scene_id, |s| Ok(s.planning.robot.is_some()))? {
            return Ok(None);
        }
        let mut world = self.robot_world(scene_id)?;
        let Some(placed) = world.robot.clone() else { return Ok(None) };
        world.with_poses(poses.iter().map(|(id, p)| (id.as_str(), p)));
        let configuration = placed.configuration(&world.planning.joint_positions);
        let answer = {
            let planning = world.planning.clone();
            let allowed = planning.allowed_override();
            let mut checker = RobotChecker::new(&placed.robot, world.objects.clone(), &allowed)?;
            checker.set_link_padding(&placed.link_padding)?;
            checker.check(&configuration, &placed.base, options)?
        };
        Ok(Some(SceneRobotCheck { placed, world, configuration, answer }))
    }

    /// The scene's robot, or [`Error::FailedPrecondition`] when it has none.
    fn require_placed(&self, scene_id: &str) -> Result<Arc<PlacedRobot>> {
        self.placed_robot(scene_id)?.ok_or_else(|| {
            Error::FailedPrecondition(format!("scene `{scene_id}` has no robot: place one first (SetSceneRobot)"))
        })
    }

    /// Keeps `placed` as scene `scene_id`'s built robot while its record stays the scene's.
    fn cache_placed(&self, scene_id: &str, placed: Arc<PlacedRobot>) {
        let Ok(entry) = self.robot(&placed.robot_id) else { return };
        let _ = self.with_scene(scene_id, |s| {
            if s.planning.robot.as_ref() == Some(&placed.record) {
                s.placed = Some(super::PlacedCache { placed, robot_source: entry.robot.clone() });
            }
            Ok(())
        });
    }

    /// Replaces the planning context of scene `scene_id` by `f(current)`, under the scene's lock,
    /// written through to the store (nothing changes when `f` or the store fails).
    pub(super) fn update_planning(
        &self,
        scene_id: &str,
        f: impl FnOnce(&PlanningContext) -> Result<PlanningContext>,
    ) -> Result<()> {
        self.with_scene(scene_id, |s| {
            let planning = f(&s.planning)?;
            let meta = crate::SceneMeta { name: s.name.clone(), planning };
            self.store.put_scene(scene_id, &meta)?;
            s.planning = Arc::new(meta.planning);
            s.changed();
            Ok(())
        })
    }
}

/// The scene's joint positions with `names` set to `values` (one configuration; validated as
/// [`sublevel_robot::RobotModel::configurations`] does, under the field `joint_positions`).
fn merged_positions(
    robot: &FittedRobot,
    planning: &PlanningContext,
    names: &[String],
    values: &[Real],
) -> Result<Vec<(String, Real)>> {
    if names.is_empty() {
        return Err(Error::invalid("joint_positions.joint_names", "name the joints to set"));
    }
    if values.len() != names.len() {
        return Err(Error::invalid(
            "joint_positions.values",
            format!("one value per joint name: {} names, {} values", names.len(), values.len()),
        ));
    }
    robot.model.configurations("joint_positions", names, values, &planning.joint_positions)?;
    let mut out = planning.joint_positions.clone();
    for (name, &value) in names.iter().zip(values) {
        match out.iter_mut().find(|(n, _)| n == name) {
            Some(entry) => entry.1 = value,
            None => out.push((name.clone(), value)),
        }
    }
    Ok(out)
}
