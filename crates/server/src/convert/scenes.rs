//! Geometry, scenes and poses: points, vectors and poses (validated: finite, in range, unit
//! quaternions), instances, scenes, and the entries of `SetPoses`.

use super::{prefix_field, require_id};
use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::{pose_from_parts, pose_to_parts, Isometry3, Point3, Vector3};
use sublevel_scene::{InstanceView, SceneView};

/// A core point as a proto point.
pub fn point_to_proto(p: &Point3) -> pb::Vec3 {
    pb::Vec3 { x: p.x, y: p.y, z: p.z }
}

/// A core vector as a proto vector.
pub fn vector_to_proto(v: &Vector3) -> pb::Vec3 {
    pb::Vec3 { x: v.x, y: v.y, z: v.z }
}

/// A validated pose; `field` names the pose (e.g. `poses[3].pose`). An absent pose, rotation or
/// translation means identity / zero.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field.translation` for a non-finite translation or
/// `field.rotation` for a non-finite or non-unit quaternion.
pub fn pose_from_proto(field: &str, pose: Option<&pb::Pose>) -> Result<Isometry3> {
    let Some(pose) = pose else { return Ok(Isometry3::identity()) };
    // Field names are built only on error (this runs once per pose of every planner step).
    let t = pose.translation.as_ref().map_or([0.0; 3], |t| [t.x, t.y, t.z]);
    if t.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(format!("{field}.translation"), "must be three finite numbers (meters)"));
    }
    sublevel_core::math::check_coordinates("translation", &t).map_err(|e| prefix_field(e, field))?;
    let q = pose.rotation.as_ref().map_or([1.0, 0.0, 0.0, 0.0], |q| [q.w, q.x, q.y, q.z]);
    pose_from_parts("rotation", q, t).map_err(|e| prefix_field(e, field))
}

/// A pose as a proto pose.
pub fn pose_to_proto(pose: &Isometry3) -> pb::Pose {
    let (q, t) = pose_to_parts(pose);
    pb::Pose {
        rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
        translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
    }
}

/// An instance as the proto message.
pub fn instance_to_proto(i: &InstanceView) -> pb::Instance {
    pb::Instance { instance_id: i.id.clone(), body_id: i.body_id.clone(), pose: Some(pose_to_proto(&i.pose)) }
}

/// A scene as the proto response, with its robot (`robot`) when it has one.
pub fn scene_to_proto(s: &SceneView, robot: Option<&sublevel_scene::PlacedRobot>) -> pb::GetSceneResponse {
    let positions = &s.planning.joint_positions;
    pb::GetSceneResponse {
        scene_id: s.id.clone(),
        name: s.name.clone(),
        instances: s.instances.iter().map(instance_to_proto).collect(),
        robot: robot.map(|r| super::scene_robot_to_proto(r, positions)),
        joint_positions: positions
            .iter()
            .map(|(name, position)| pb::JointPosition { name: name.clone(), position: *position })
            .collect(),
        point_clouds: s.clouds.values().map(|c| super::cloud_summary(c)).collect(),
        scene_version: s.version,
    }
}

/// Validates the entries of a `SetPoses` request.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `poses[k].instance_id` (empty) or `poses[k].pose.rotation` /
/// `poses[k].pose.translation`; [`Error::ResourceExhausted`] above `max_poses`.
pub fn poses_from_proto(poses: &[pb::InstancePose], max_poses: usize) -> Result<Vec<(String, Isometry3)>> {
    if poses.len() > max_poses {
        return Err(Error::ResourceExhausted(format!(
            "`poses`: {} entries exceed the limit of {max_poses}",
            poses.len()
        )));
    }
    poses
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let at = |e| prefix_field(e, &format!("poses[{k}]"));
            require_id("instance_id", &p.instance_id).map_err(at)?;
            Ok((p.instance_id.clone(), pose_from_proto("pose", p.pose.as_ref()).map_err(at)?))
        })
        .collect()
}

/// Reads `ImportSceneRequest.scene` (YAML or JSON bytes) into a planning scene and its import
/// plan ([`sublevel_scene::moveit::ImportPlan`]), its meshes planned for fits or skipped as
/// `meshes` says, with at most `max_objects` collision objects (the server's
/// `--max-instances-per-scene`: every object is at least one instance), counted as the parser
/// reads them, before any is validated.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `scene` when neither form is set, `yaml` / `json` for bytes
/// that do not parse (or breach the YAML budget of their size), or `yaml.<path>` /
/// `json.<path>` for the scene's first field that does not validate (e.g.
/// `yaml.world.collision_objects[3].primitive_poses[0]`); [`Error::ResourceExhausted`] naming
/// `yaml.world.collision_objects` (or `json.…`) and `--max-instances-per-scene` for more objects.
pub fn planning_scene_from_proto(
    scene: Option<&pb::import_scene_request::Scene>,
    meshes: sublevel_scene::moveit::MeshImport,
    max_objects: usize,
) -> Result<(sublevel_scene::moveit::PlanningScene, sublevel_scene::moveit::ImportPlan)> {
    use sublevel_scene::moveit::{ImportPlan, PlanningScene};
    let (parsed, field) = match scene {
        None => return Err(Error::invalid("scene", "set `yaml` or `json`")),
        Some(pb::import_scene_request::Scene::Yaml(bytes)) => {
            (PlanningScene::from_yaml_with_limit(bytes, max_objects), "yaml")
        }
        Some(pb::import_scene_request::Scene::Json(bytes)) => {
            (PlanningScene::from_json_with_limit(bytes, max_objects), "json")
        }
    };
    // The parser names the whole document `scene`; the request's field is `yaml` or `json`.
    let located = |e: Error| match e {
        Error::InvalidArgument { field: f, reason } if f == "scene" => Error::invalid(field, reason),
        Error::ResourceExhausted(_) => {
            let limit = crate::limits::INSTANCES;
            Error::ResourceExhausted(format!(
                "limit reached: `{field}.world.collision_objects` holds more than {max_objects} collision objects, and a scene holds at most {max_objects} instances (set by {} / {})",
                limit.flag, limit.env
            ))
        }
        other => super::prefix_field(other, field),
    };
    let scene = parsed.map_err(located)?;
    let plan = ImportPlan::new(&scene, meshes).map_err(located)?;
    Ok((scene, plan))
}

/// The compound settings of `ImportScene`'s mesh fits: the server's fit settings `fit` for every
/// leaf, the default leaf degrees (2, 4, 6) and parents, and the leaf-excess tolerance
/// `mesh_tolerance` in meters (0: the default, 1 % of each mesh's bounding-box diagonal, as
/// `sublevel fit --parts auto`).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `mesh_tolerance` when it is not a finite number ≥ 0, or a
/// field of [`sublevel_fit::compound::CompoundSettings::validate`].
pub fn import_mesh_settings(
    mesh_tolerance: f64,
    fit: sublevel_fit::FitSettings,
) -> Result<sublevel_fit::compound::CompoundSettings> {
    let t = mesh_tolerance;
    if !(t.is_finite() && t >= 0.0) {
        return Err(Error::invalid("mesh_tolerance", format!("must be a finite number >= 0 meters, got {t}")));
    }
    let settings = sublevel_fit::compound::CompoundSettings {
        fit,
        excess_tolerance: (t > 0.0).then_some(t),
        ..sublevel_fit::compound::CompoundSettings::default()
    };
    settings.validate()?;
    Ok(settings)
}

/// A planned mesh as the triangle mesh a compound fit takes (vertices as written: the mesh's
/// frame, meters).
pub fn planned_mesh_to_fit(mesh: &sublevel_scene::moveit::PlannedMesh) -> sublevel_fit::mesh::TriangleMesh {
    sublevel_fit::mesh::TriangleMesh {
        vertices: mesh.vertices.iter().map(|v| Point3::new(v[0], v[1], v[2])).collect(),
        triangles: mesh.triangles.clone(),
    }
}

/// An imported planning scene as the `ImportScene` response: the instances and skipped shapes of
/// `plan` as written (`imported`), its meshes with their fit jobs (`mesh_jobs[k]` the job of
/// `plan.meshes[k]`), with `scene`'s allowed-collision matrix and robot state.
pub fn imported_scene_to_proto(
    imported: &sublevel_scene::moveit::ImportedScene,
    plan: &sublevel_scene::moveit::ImportPlan,
    scene: &sublevel_scene::moveit::PlanningScene,
    mesh_jobs: &[String],
) -> pb::ImportSceneResponse {
    let count = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    let instances = imported
        .instances
        .iter()
        .map(|i| pb::ImportedInstance {
            name: i.planned.name.clone(),
            object_id: i.planned.object_id.clone(),
            shape_index: count(i.planned.shape_index),
            instance_id: i.instance_id.clone(),
            body_id: i.body_id.clone(),
            kind: i.planned.kind.to_owned(),
            pose: Some(pose_to_proto(&i.planned.pose)),
            frame_id: i.planned.frame_id.clone(),
            note: i.planned.note.clone(),
        })
        .collect();
    let skipped = plan
        .skipped
        .iter()
        .map(|s| pb::SkippedShape {
            object_id: s.object_id.clone(),
            shape_index: count(s.shape_index),
            kind: s.kind.to_owned(),
            pose: Some(pose_to_proto(&s.pose)),
            reason: s.reason.clone(),
        })
        .collect();
    let meshes = plan
        .meshes
        .iter()
        .zip(mesh_jobs)
        .map(|(m, job_id)| pb::ImportedMesh {
            name: m.name.clone(),
            object_id: m.object_id.clone(),
            shape_index: count(m.shape_index),
            job_id: job_id.clone(),
            pose: Some(pose_to_proto(&m.pose)),
            frame_id: m.frame_id.clone(),
            vertices: count(m.vertices.len()),
            triangles: count(m.triangles.len()),
        })
        .collect();
    let allowed_collision = scene.allowed_collision.as_ref().map(|acm| pb::AllowedCollisionMatrix {
        names: acm.names.clone(),
        rows: acm.allowed.iter().map(|r| pb::AllowedCollisionRow { allowed: r.clone() }).collect(),
        default_names: acm.defaults.iter().map(|(n, _)| n.clone()).collect(),
        default_allowed: acm.defaults.iter().map(|(_, a)| *a).collect(),
    });
    let joint_positions = scene
        .joint_positions
        .iter()
        .map(|(name, position)| pb::JointPosition { name: name.clone(), position: *position })
        .collect();
    pb::ImportSceneResponse {
        scene_id: imported.scene_id.clone(),
        name: imported.name.clone(),
        instances,
        skipped,
        objects: count(scene.objects.len()),
        bodies: count(imported.body_ids.len()),
        allowed_collision,
        joint_positions,
        meshes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_validation_names_the_field() {
        let bad = pb::Pose { rotation: Some(pb::Quaternion { w: 1.0, x: 1.0, y: 0.0, z: 0.0 }), translation: None };
        let e = pose_from_proto("poses[3].pose", Some(&bad)).unwrap_err();
        assert!(e.to_string().contains("poses[3].pose.rotation"), "{e}");
        let nan = pb::Pose { rotation: None, translation: Some(pb::Vec3 { x: f64::NAN, y: 0.0, z: 0.0 }) };
        let e = pose_from_proto("pose", Some(&nan)).unwrap_err();
        assert!(e.to_string().contains("pose.translation"), "{e}");
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let p = pose_from_parts("p", [h, 0.0, h, 0.0], [1.0, -2.0, 3.0]).unwrap();
        let back = pose_from_proto("p", Some(&pose_to_proto(&p))).unwrap();
        assert!((back.to_homogeneous() - p.to_homogeneous()).amax() < 1e-15);
    }
}
