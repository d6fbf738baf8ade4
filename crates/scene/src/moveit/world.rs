//! A planning scene as the world a robot's configurations are checked in
//! ([`sublevel_robot::check`]): its primitives and planes as exact primitives in the scene's
//! frame, named by their collision objects' ids (`ID#k` for an object's k-th shape, k ≥ 1), as
//! [`ImportPlan`] imports them (cones as the cylinders that contain them, meshes skipped with
//! the reason).

use super::{AllowedCollisionMatrix, ImportPlan, MeshImport, PlanningScene, SkippedShape};
use crate::Result;
use sublevel_robot::WorldObject;

/// The world objects of `scene` and the shapes left out (meshes).
///
/// # Errors
/// As [`ImportPlan::new`] (meshes skipped: robot checks take exact primitives).
pub fn world_objects(scene: &PlanningScene) -> Result<(Vec<WorldObject>, Vec<SkippedShape>)> {
    let plan = ImportPlan::new(scene, MeshImport::Skip)?;
    let objects = plan
        .instances
        .iter()
        .map(|i| WorldObject { name: i.name.clone(), primitive: plan.bodies[i.body].1, pose: i.pose })
        .collect();
    Ok((objects, plan.skipped))
}

/// The allowed-collision override of `scene` for [`sublevel_robot::RobotChecker::new`]: the
/// matrix's entry when the scene has a matrix naming both (or a default entry of either), else
/// `None` (the robot's own defaults).
pub fn allowed_override(scene: &PlanningScene) -> impl Fn(&str, &str) -> Option<bool> + '_ {
    move |a, b| acm_override(scene.allowed_collision.as_ref()?, a, b)
}

/// The entry of `acm` for the pair `a`, `b` when the matrix names both (or has a default entry of
/// either), else `None`.
pub fn acm_override(acm: &AllowedCollisionMatrix, a: &str, b: &str) -> Option<bool> {
    let named = |n: &str| acm.names.iter().any(|m| m == n) || acm.defaults.iter().any(|(m, _)| m == n);
    let either_default = acm.defaults.iter().any(|(m, _)| m == a || m == b);
    if (named(a) && named(b)) || either_default {
        Some(acm.allowed(a, b))
    } else {
        None
    }
}
