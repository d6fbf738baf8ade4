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

/// A scene as the proto response.
pub fn scene_to_proto(s: &SceneView) -> pb::GetSceneResponse {
    pb::GetSceneResponse {
        scene_id: s.id.clone(),
        name: s.name.clone(),
        instances: s.instances.iter().map(instance_to_proto).collect(),
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
