//! A planning scene as the world a robot's configurations are checked in
//! ([`sublevel_robot::check`]): its primitives and planes as exact primitives and its meshes as
//! exact triangle meshes, in the scene's frame, named by their collision objects' ids (`ID#k` for
//! an object's k-th shape, k ≥ 1), as [`ImportPlan`] names them (cones as the cylinders that
//! contain them).

use super::{AllowedCollisionMatrix, ImportPlan, MeshImport, PlanningScene, Shape, SkippedShape};
use crate::Result;
use std::sync::Arc;
use sublevel_core::math::Point3;
use sublevel_robot::{WorldMesh, WorldObject};

/// The world objects of `scene` — its primitives and planes first, then its meshes — and the
/// shapes left out (none today; kept for shapes a later MoveIt adds).
///
/// # Errors
/// As [`ImportPlan::new`]; [`crate::Error::InvalidArgument`] naming
/// `world.collision_objects[ID].meshes[k]` for a mesh that does not validate
/// ([`WorldMesh::new`]).
pub fn world_objects(scene: &PlanningScene) -> Result<(Vec<WorldObject>, Vec<SkippedShape>)> {
    let plan = ImportPlan::new(scene, MeshImport::Skip)?;
    let mut objects: Vec<WorldObject> =
        plan.instances.iter().map(|i| WorldObject::primitive(i.name.clone(), plan.bodies[i.body].1, i.pose)).collect();
    for object in &scene.objects {
        for (k, placed) in object.shapes.iter().enumerate() {
            let Shape::Mesh { vertices, triangles } = &placed.shape else { continue };
            let points = vertices.iter().map(|v| Point3::new(v[0], v[1], v[2])).collect();
            let mesh = WorldMesh::new(points, triangles.clone(), None).map_err(|e| {
                crate::Error::invalid(
                    format!("world.collision_objects[{}].meshes[{k}]", sublevel_core::error::clip(&object.id)),
                    e.to_string(),
                )
            })?;
            let name = super::instance_name(&object.id, object.shapes.len(), k);
            objects.push(WorldObject::mesh(name, Arc::new(mesh), placed.pose));
        }
    }
    let skipped = plan.skipped.into_iter().filter(|s| s.kind != "mesh").collect();
    Ok((objects, skipped))
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

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_robot::WorldShape;

    /// The test scene's four table shapes are primitives; the wedge's mesh is an exact mesh at
    /// its pose (z = 2), named by its object's id, and nothing is left out.
    #[test]
    fn a_scene_mesh_is_an_exact_mesh_object() {
        let scene = PlanningScene::from_yaml(super::super::tests::ROS_SCENE.as_bytes()).unwrap();
        let (objects, skipped) = world_objects(&scene).unwrap();
        let names: Vec<&str> = objects.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["table#0", "table#1", "table#2", "table#3", "wedge"]);
        assert!(skipped.is_empty());
        let WorldShape::Mesh(mesh) = &objects[4].shape else { panic!("{:?}", objects[4].shape) };
        assert_eq!(
            (mesh.vertices().len(), mesh.triangles(), mesh.body().is_none()),
            (4, &[[0, 1, 2], [0, 1, 3]][..], true)
        );
        assert_eq!(objects[4].pose.translation.vector, sublevel_core::math::Vector3::new(0.0, 0.0, 2.0));
    }
}
