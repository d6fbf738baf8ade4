//! Properties of request validation over random inputs (proptest): every validator answers
//! (never panics) and accepts exactly what its documentation says.

use super::*;
use crate::pb;
use proptest::prelude::*;
use sublevel_core::body::FitReport;
use sublevel_core::Error;

/// Finite numbers of every magnitude, the non-finite ones, and the edges of the range.
fn any_number() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -2.0e6..2.0e6f64,
        1 => prop::num::f64::ANY,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(sublevel_core::math::MAX_COORDINATE),
        1 => Just(-sublevel_core::math::MAX_COORDINATE - 1.0),
    ]
}

proptest! {
    #[test]
    fn pose_validation_accepts_exactly_finite_unit_poses_in_range(
        q in prop::array::uniform4(any_number()),
        t in prop::array::uniform3(any_number()),
    ) {
        let pose = pb::Pose {
            rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
            translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
        };
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let ok = q.iter().chain(&t).all(|v| v.is_finite())
            && t.iter().all(|v| v.abs() <= sublevel_core::math::MAX_COORDINATE)
            && (norm - 1.0).abs() <= sublevel_core::math::UNIT_QUATERNION_TOLERANCE;
        match pose_from_proto("poses[7].pose", Some(&pose)) {
            Ok(_) => prop_assert!(ok),
            Err(Error::InvalidArgument { field, .. }) => {
                prop_assert!(!ok);
                prop_assert!(field.starts_with("poses[7].pose"), "{}", field);
            }
            Err(other) => prop_assert!(false, "unexpected {other:?}"),
        }
    }

    #[test]
    fn unit_quaternions_in_range_are_accepted(
        axis in prop::array::uniform3(-1.0..1.0f64),
        angle in -10.0..10.0f64,
        t in prop::array::uniform3(-1.0e6..1.0e6f64),
    ) {
        let a = nalgebra::Vector3::from(axis);
        prop_assume!(a.norm() > 1e-3);
        let q = nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(a), angle);
        let pose = pb::Pose {
            rotation: Some(pb::Quaternion { w: q.w, x: q.i, y: q.j, z: q.k }),
            translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
        };
        prop_assert!(pose_from_proto("pose", Some(&pose)).is_ok());
    }

    #[test]
    fn point_clouds_are_checked_for_length_count_and_range(
        xyz in prop::collection::vec(any_number(), 0..40),
        max_points in 0usize..15,
    ) {
        let ok = xyz.len() % 3 == 0
            && xyz.len() / 3 <= max_points
            && xyz.iter().all(|v| v.is_finite() && v.abs() <= sublevel_core::math::MAX_COORDINATE);
        match points_from_proto(&pb::PointCloud { xyz: xyz.clone() }, max_points) {
            Ok(points) => {
                prop_assert!(ok);
                prop_assert_eq!(points.len() * 3, xyz.len());
            }
            Err(Error::InvalidArgument { field, .. }) => {
                prop_assert!(!ok);
                prop_assert_eq!(field, "points.xyz");
            }
            Err(Error::ResourceExhausted(m)) => {
                prop_assert!(xyz.len() / 3 > max_points);
                prop_assert!(m.contains("points.xyz"));
            }
            Err(other) => prop_assert!(false, "unexpected {other:?}"),
        }
    }

    #[test]
    fn ids_are_accepted_from_1_to_128_bytes_and_never_echoed_whole(id in ".{0,300}") {
        match require_id("scene_id", &id) {
            Ok(_) => prop_assert!(!id.is_empty() && id.len() <= MAX_ID_BYTES),
            Err(e) => {
                prop_assert!(id.is_empty() || id.len() > MAX_ID_BYTES);
                prop_assert!(e.to_string().len() < 200 + sublevel_core::error::CLIP_BYTES, "{}", e);
            }
        }
    }

    #[test]
    fn body_data_with_random_shapes_is_refused_or_admitted_without_panicking(
        degree in 0u32..12,
        exponents in prop::collection::vec(0u32..12, 0..30),
        coefficients in prop::collection::vec(any_number(), 0..10),
        scale in any_number(),
    ) {
        let data = pb::BodyData { degree, exponents, coefficients, center: None, scale, report: None };
        if let Ok(file) = body_file_from_proto(&data) {
            // Whatever the core says, it says it with an error, not a panic.
            let _ = sublevel_core::Body::from_file(file);
        }
    }

    #[test]
    fn state_columns_are_admitted_exactly_when_every_pose_is_valid(
        ids in prop::collection::vec("[ab]{1,2}", 0..4),
        numbers in prop::collection::vec(prop_oneof![4 => Just(0.0), 2 => Just(1.0), 1 => any_number()], 0..60),
    ) {
        let columns = pb::StateColumns { instance_ids: ids.clone(), poses: numbers.clone() };
        let req = pb::QueryRequest { state_columns: Some(columns), ..Default::default() };
        let n = ids.len();
        let unique = (0..n).all(|k| !ids[..k].contains(&ids[k]));
        let shaped = n > 0 && !numbers.is_empty() && numbers.len() % (7 * n) == 0;
        let poses_ok = shaped
            && numbers.chunks_exact(7).all(|v| sublevel_core::math::pose_from_parts("p", [v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]]).is_ok());
        match planner_request_from_proto(&req, 1000, 1000) {
            Ok(r) => {
                prop_assert!(unique && poses_ok);
                prop_assert_eq!(r.states.len(), numbers.len() / (7 * n));
                let sublevel_scene::planner::CandidateStates::Columns { instance_ids, poses } = &r.states else {
                    return Err(TestCaseError::fail("states in columns must stay columns"));
                };
                prop_assert_eq!(instance_ids, &ids);
                prop_assert_eq!(poses.len(), numbers.len() / 7);
            }
            Err(Error::InvalidArgument { field, .. }) => {
                prop_assert!(!(unique && poses_ok));
                prop_assert!(field.starts_with("state_columns"), "{field}");
            }
            Err(other) => prop_assert!(false, "unexpected {other:?}"),
        }
    }

    #[test]
    fn reports_with_a_non_finite_figure_are_refused_naming_it(
        volume in any_number(),
        seconds in any_number(),
        margin in prop::option::of(any_number()),
    ) {
        let report = FitReport { volume, total_seconds: seconds, convexity_margin: margin, ..FitReport::default() };
        let finite = volume.is_finite() && seconds.is_finite() && margin.is_none_or(f64::is_finite);
        match report.check_finite("data.report") {
            Ok(()) => prop_assert!(finite),
            Err(Error::InvalidArgument { field, .. }) => {
                prop_assert!(!finite);
                prop_assert!(field.starts_with("data.report."));
            }
            Err(other) => prop_assert!(false, "unexpected {other:?}"),
        }
        let mut sanitized = report.clone();
        let replaced = sanitized.sanitize_non_finite();
        prop_assert_eq!(replaced == 0, finite);
        prop_assert!(sanitized.check_finite("r").is_ok());
        prop_assert!(sublevel_scene::store::encode("body", &sanitized).is_ok());
    }
}
