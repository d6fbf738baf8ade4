//! Point clouds of a scene against brute force: a cloud on a known sphere checked against the
//! one-joint arm (verdicts and distances equal a pass over every point ball), filter counts
//! computed by hand, replacement (verdict and version), limits and the errors' fields.

use super::*;
use crate::store::MemoryStore;
use crate::{SceneRobot, StoredPose};
use sublevel_core::math::{pose_from_parts, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::cloud::filter::{CloudFilter, FilterCounts};
use sublevel_robot::{CheckOptions, RobotChecker, RobotFile};

/// The one-joint arm of `tests/data/arm.robot.json`: a revolute joint `j` about z at the base;
/// link `arm` holds a ball of radius 0.1 m at (0.5, 0, 0) in its frame.
fn arm() -> RobotFile {
    serde_json::from_str(include_str!("../../../../tests/data/arm.robot.json")).unwrap()
}

/// The arm ball's center (world) at joint angle `j`, the base at the origin.
fn arm_ball(j: Real) -> Vector3 {
    Vector3::new(0.5 * j.cos(), 0.5 * j.sin(), 0.0)
}

const ARM_RADIUS: Real = 0.1;

/// A catalog with the arm placed in a new scene: (catalog, scene id).
fn cell() -> (Catalog, String) {
    let c = Catalog::open(Box::new(MemoryStore::new()), NewtonParams::default()).unwrap();
    let robot = c.add_robot("", arm()).unwrap();
    let scene = c.create_scene("cell").unwrap();
    let record = SceneRobot {
        robot_id: robot.id.clone(),
        base: StoredPose::from_isometry(&Isometry3::identity()),
        attached: vec![],
        link_padding: vec![],
    };
    c.set_scene_robot(&scene, record, None).unwrap();
    (c, scene)
}

/// `n` points on the sphere of `radius` about `center` (a Fibonacci lattice; world frame).
fn sphere_points(center: Vector3, radius: Real, n: usize) -> Vec<Vector3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|k| {
            let z = 1.0 - 2.0 * (k as Real + 0.5) / n as Real;
            let rho = (1.0 - z * z).sqrt();
            let a = golden * k as Real;
            center + radius * Vector3::new(rho * a.cos(), rho * a.sin(), z)
        })
        .collect()
}

/// The sensor: 1 m above the cell, looking down at an angle.
fn sensor() -> Isometry3 {
    let half = 0.4_f64;
    pose_from_parts("sensor", [half.cos(), half.sin(), 0.0, 0.0], [0.2, -0.3, 1.0]).unwrap()
}

/// A frame of world points `world` as the sensor at [`sensor`] sees them (float32, sensor frame),
/// no filter but the defaults' range, no voxel grid.
fn frame_of(world: &[Vector3], noise_radius: Real) -> CloudFrame {
    let s = sensor();
    let points = world
        .iter()
        .map(|p| {
            let q = s.inverse_transform_point(&(*p).into());
            [q.x as f32, q.y as f32, q.z as f32]
        })
        .collect();
    CloudFrame {
        points,
        holes: 0,
        sensor_pose: s,
        noise_radius,
        filter: CloudFilter { voxel: 0.0, ..CloudFilter::default() },
        self_filter: None,
    }
}

/// Sets cloud `name` of `scene` from world points `world`; returns the update.
fn set(c: &Catalog, scene: &str, name: &str, world: &[Vector3], noise_radius: Real) -> CloudUpdate {
    let built = c.build_point_cloud(scene, &frame_of(world, noise_radius)).unwrap();
    c.set_point_cloud(scene, name, built, DEFAULT_MAX_CLOUD_BYTES).unwrap()
}

/// The scene robot checked at joint angle `j` against the scene's world (clouds included).
fn check(c: &Catalog, scene: &str, j: Real, padding: Real) -> sublevel_robot::ConfigurationAnswer {
    let world = c.robot_world(scene).unwrap();
    let placed = world.robot.clone().unwrap();
    let allowed = world.planning.allowed_override();
    let mut checker = RobotChecker::new(&placed.robot, world.objects.clone(), &allowed).unwrap();
    let options = CheckOptions { padding, distance: true, ..CheckOptions::default() };
    checker.check(&[j], &placed.base, &options).unwrap()
}

#[test]
fn a_cloud_on_a_sphere_collides_exactly_when_brute_force_says_so() {
    let (c, scene) = cell();
    let center = Vector3::new(0.5, 0.5, 0.0);
    let world = sphere_points(center, 0.15, 400);
    let r = 0.01;
    let update = set(&c, &scene, "camera", &world, r);
    let stored = c.get_scene(&scene).unwrap().clouds["camera"].cloud.clone();
    assert_eq!(stored.len(), 400);
    // The points came back to the world within float32 rounding.
    for (p, q) in world.iter().zip(stored.points()) {
        assert!((p - Vector3::from(*q)).norm() < 1e-6, "{p:?} {q:?}");
    }
    assert_eq!(update.scene_version, c.scene_version(&scene).unwrap());
    let (mut colliding, mut free) = (0, 0);
    for padding in [0.0, 0.02] {
        for k in -60..=60 {
            let j = k as Real * 0.05;
            let ball = arm_ball(j);
            // Brute force over every stored point ball.
            let nearest =
                stored.points().iter().map(|p| (Vector3::from(*p) - ball).norm()).fold(Real::INFINITY, Real::min);
            let gap = nearest - ARM_RADIUS - r;
            if (gap - padding).abs() < 1e-7 {
                continue;
            }
            let answer = check(&c, &scene, j, padding);
            assert_eq!(answer.world, gap <= padding, "j = {j}, padding {padding}: gap {gap}");
            if answer.world {
                colliding += 1;
                assert_eq!(answer.distance, 0.0);
            } else {
                free += 1;
                assert!((answer.distance - gap).abs() < 1e-9, "j = {j}: {} vs {gap}", answer.distance);
            }
            // The pair names the cloud.
            let (_, object) = answer.pair.unwrap();
            assert_eq!(c.robot_world(&scene).unwrap().objects[object].name, "camera");
        }
    }
    assert!(colliding > 5 && free > 50, "{colliding} colliding, {free} free");
    // The scene's own check (its joint positions) agrees.
    for j in [0.0, 0.8] {
        c.set_joint_positions(&scene, &["j".into()], &[j]).unwrap();
        let nearest =
            stored.points().iter().map(|p| (Vector3::from(*p) - arm_ball(j)).norm()).fold(Real::INFINITY, Real::min);
        let answer = c.check_scene_robot(&scene, &CheckOptions::default(), &[]).unwrap().unwrap().answer;
        assert_eq!(answer.world, nearest - ARM_RADIUS - r <= 0.0, "j = {j}");
        assert_eq!(answer.world, j == 0.8);
    }
}

#[test]
fn filter_counts_equal_the_hand_count() {
    let (c, scene) = cell();
    // Identity sensor; range 0.5–3 m, workspace z <= 2, voxel 0.1 m.
    let filter = CloudFilter {
        min_range: 0.5,
        max_range: 3.0,
        workspace: Some((Vector3::new(-5.0, -5.0, -5.0), Vector3::new(5.0, 5.0, 2.0))),
        voxel: 0.1,
        outliers: None,
    };
    let nan = f32::NAN;
    let points = vec![
        [nan, 0.0, 1.0],
        [0.0, f32::INFINITY, 1.0],
        [0.0, 0.0, nan],
        [0.0, 0.0, 0.2],    // range: nearer than 0.5
        [0.0, 0.0, 3.5],    // range: beyond 3
        [0.0, 0.0, 2.5],    // workspace: z > 2
        [1.01, 1.01, 1.01], // one voxel [1, 1.1)³: four points
        [1.02, 1.03, 1.04],
        [1.05, 1.05, 1.05],
        [1.09, 1.01, 1.02],
        [0.55, 0.0, 1.55],  // a voxel of its own
        [-0.55, 0.0, 1.55], // and another
    ];
    let frame = CloudFrame {
        points,
        holes: 5,
        sensor_pose: Isometry3::identity(),
        noise_radius: 0.005,
        filter,
        self_filter: None,
    };
    let built = c.build_point_cloud(&scene, &frame).unwrap();
    let expected =
        FilterCounts { input: 17, holes: 8, range: 2, workspace: 1, voxel: 3, outliers: 0, robot: 0, kept: 3 };
    assert_eq!(built.counts, expected);
    assert_eq!(built.cloud.len(), 3);
    // The voxel's mean.
    let mean = Vector3::new(1.0425, 1.025, 1.03);
    assert!(built.cloud.points().iter().any(|p| (Vector3::from(*p) - mean).norm() < 1e-6));
    let update = c.set_point_cloud(&scene, "depth", built, DEFAULT_MAX_CLOUD_BYTES).unwrap();
    let stored = &c.get_scene(&scene).unwrap().clouds["depth"];
    assert_eq!(
        (stored.counts, stored.version, stored.memory_bytes),
        (expected, update.scene_version, update.memory_bytes)
    );
    assert_eq!(c.cloud_bytes(), update.memory_bytes);
}

#[test]
fn the_self_filter_drops_the_arms_own_points() {
    let (c, scene) = cell();
    c.set_joint_positions(&scene, &["j".into()], &[0.5]).unwrap();
    // 100 points 3 mm off the arm's ball (their balls, of 5 mm, touch it) and 50 on a far sphere.
    let mut world = sphere_points(arm_ball(0.5), ARM_RADIUS + 0.003, 100);
    world.extend(sphere_points(Vector3::new(-1.0, 0.0, 0.0), 0.2, 50));
    let mut frame = frame_of(&world, 0.005);
    frame.self_filter = Some(DEFAULT_SELF_FILTER_PADDING);
    let built = c.build_point_cloud(&scene, &frame).unwrap();
    assert_eq!((built.counts.robot, built.counts.kept, built.cloud.len()), (100, 50, 50));
    // Without it the arm collides with its own image; with it, it is free.
    c.set_point_cloud(&scene, "cam", built, DEFAULT_MAX_CLOUD_BYTES).unwrap();
    assert!(!check(&c, &scene, 0.5, 0.0).world);
    let built = c.build_point_cloud(&scene, &frame_of(&world, 0.005)).unwrap();
    assert_eq!(built.counts.robot, 0);
    c.set_point_cloud(&scene, "cam", built, DEFAULT_MAX_CLOUD_BYTES).unwrap();
    assert!(check(&c, &scene, 0.5, 0.0).world);
}

#[test]
fn a_replaced_cloud_changes_the_verdict_and_the_version() {
    let (c, scene) = cell();
    let v0 = c.scene_version(&scene).unwrap();
    let near = sphere_points(arm_ball(0.0), 0.105, 200);
    let far = sphere_points(Vector3::new(0.0, 0.0, 2.0), 0.12, 200);
    let first = set(&c, &scene, "cam", &near, 0.01);
    assert_eq!(first.scene_version, v0 + 1);
    assert!(check(&c, &scene, 0.0, 0.0).world);
    let world = c.robot_world(&scene).unwrap();
    assert_eq!(world.scene_version, v0 + 1);
    // The allowed-collision matrix reads the cloud's name as an instance's.
    let mut planning = (*c.get_scene(&scene).unwrap().planning).clone();
    let version = c.scene_version(&scene).unwrap();
    planning.allowed_collision = Some(crate::moveit::AllowedCollisionMatrix {
        names: vec!["arm".into(), "cam".into()],
        allowed: vec![vec![false, true], vec![true, false]],
        defaults: Vec::new(),
    });
    c.set_planning(&scene, planning.clone()).unwrap();
    assert!(!check(&c, &scene, 0.0, 0.0).world, "contacts of the arm with `cam` are allowed");
    planning.allowed_collision = None;
    c.set_planning(&scene, planning).unwrap();
    assert!(check(&c, &scene, 0.0, 0.0).world);
    assert_eq!(c.scene_version(&scene).unwrap(), version + 2);
    let v0 = v0 + 2;
    let second = set(&c, &scene, "cam", &far, 0.01);
    assert_eq!(second.scene_version, v0 + 2);
    assert!(!check(&c, &scene, 0.0, 0.0).world);
    // A world read before the replacement still holds the old cloud, whole.
    assert_eq!(world.clouds["cam"].cloud.points().len(), 200);
    assert!(world.clouds["cam"].cloud.any_within(&arm_ball(0.0), 0.2));
    // Every other change raises the version too.
    let ball = c.add_primitive("ball", Primitive::Sphere { radius: 0.1 }).unwrap();
    let at = |x: Real| pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 3.0, 0.0]).unwrap();
    let i = c.add_instance(&scene, &ball, at(0.0)).unwrap();
    assert_eq!(c.scene_version(&scene).unwrap(), v0 + 3);
    c.set_poses(&scene, &[(i.clone(), at(1.0))]).unwrap();
    c.set_joint_positions(&scene, &["j".into()], &[0.3]).unwrap();
    c.remove_instance(&scene, &i).unwrap();
    assert_eq!(c.scene_version(&scene).unwrap(), v0 + 6);
    assert_eq!(c.remove_point_cloud(&scene, "cam").unwrap(), v0 + 7);
    assert!(c.get_scene(&scene).unwrap().clouds.is_empty() && c.cloud_bytes() == 0);
    assert!(matches!(c.remove_point_cloud(&scene, "cam"), Err(Error::NotFound { .. })));
    assert_eq!(c.scene_version(&scene).unwrap(), v0 + 7);
}

#[test]
fn bad_clouds_name_their_field_and_change_nothing() {
    let (c, scene) = cell();
    let world = sphere_points(Vector3::new(2.0, 0.0, 0.0), 0.1, 50);
    let ball = c.add_primitive("ball", Primitive::Sphere { radius: 0.1 }).unwrap();
    let instance = c.add_named_instance(&scene, &ball, Isometry3::identity(), "table", 100).unwrap();
    let field = |e: Error| match e {
        Error::InvalidArgument { field, .. } => field,
        other => panic!("{other:?}"),
    };
    let built = || c.build_point_cloud(&scene, &frame_of(&world, 0.01)).unwrap();
    for name in ["", "table", instance.as_str(), &"x".repeat(257)] {
        assert_eq!(field(c.set_point_cloud(&scene, name, built(), DEFAULT_MAX_CLOUD_BYTES).unwrap_err()), "name");
        assert_eq!(field(c.check_point_cloud_name(&scene, name).unwrap_err()), "name");
    }
    let mut frame = frame_of(&world, 0.01);
    frame.noise_radius = -1.0;
    assert_eq!(field(c.build_point_cloud(&scene, &frame).unwrap_err()), "noise_radius");
    frame.noise_radius = 0.01;
    frame.filter.voxel = -0.1;
    assert_eq!(field(c.build_point_cloud(&scene, &frame).unwrap_err()), "filter.voxel");
    frame.filter.voxel = 0.0;
    assert!(matches!(c.build_point_cloud("s-nowhere", &frame), Err(Error::NotFound { .. })));
    frame.self_filter = Some(Real::NAN);
    assert_eq!(field(c.build_point_cloud(&scene, &frame).unwrap_err()), "filter.self_filter_padding");
    // The self filter needs a robot.
    let bare = c.create_scene("bare").unwrap();
    frame.self_filter = Some(0.02);
    match c.build_point_cloud(&bare, &frame) {
        Err(Error::FailedPrecondition(m)) => assert!(m.contains("filter.self_filter"), "{m}"),
        other => panic!("{other:?}"),
    }
    // An instance may not take a cloud's name.
    set(&c, &scene, "camera", &world, 0.01);
    let taken = c.add_named_instance(&scene, &ball, Isometry3::identity(), "camera", 100).unwrap_err();
    assert_eq!(field(taken), "name");
    // The memory limit: the total with the replacement counted in place of the old cloud.
    let one = built().cloud.memory_bytes();
    let version = c.scene_version(&scene).unwrap();
    match c.set_point_cloud(&scene, "second", built(), one + one / 2) {
        Err(Error::ResourceExhausted(m)) => {
            assert!(m.contains("point-cloud memory") && m.contains(&format!("{one} bytes")), "{m}")
        }
        other => panic!("{other:?}"),
    }
    c.set_point_cloud(&scene, "camera", built(), one).unwrap();
    assert_eq!(c.cloud_bytes(), one);
    assert_eq!(c.scene_version(&scene).unwrap(), version + 1);
    // At most 16 clouds per scene; replacing one of them still works.
    for k in 1..MAX_CLOUDS_PER_SCENE {
        c.set_point_cloud(&scene, &format!("cam{k}"), built(), DEFAULT_MAX_CLOUD_BYTES).unwrap();
    }
    match c.set_point_cloud(&scene, "one more", built(), DEFAULT_MAX_CLOUD_BYTES) {
        Err(Error::ResourceExhausted(m)) => assert!(m.starts_with("name:") && m.contains("16"), "{m}"),
        other => panic!("{other:?}"),
    }
    c.set_point_cloud(&scene, "cam3", built(), DEFAULT_MAX_CLOUD_BYTES).unwrap();
    assert_eq!(c.get_scene(&scene).unwrap().clouds.len(), MAX_CLOUDS_PER_SCENE);
    assert_eq!(c.cloud_bytes(), MAX_CLOUDS_PER_SCENE * one);
    // Deleting the scene frees its clouds' memory.
    c.delete_scene(&scene).unwrap();
    assert_eq!(c.cloud_bytes(), 0);
}

#[test]
fn check_scene_reports_instances_near_a_cloud() {
    let c = Catalog::open(Box::new(MemoryStore::new()), NewtonParams::default()).unwrap();
    let scene = c.create_scene("s").unwrap();
    let ball = c.add_primitive("ball", Primitive::Sphere { radius: 0.2 }).unwrap();
    let block = c.add_primitive("block", Primitive::Box { half_extents: Vector3::new(0.1, 0.2, 0.3) }).unwrap();
    let floor = c.add_primitive("floor", Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 }).unwrap();
    let at = |x: Real, z: Real| pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, z]).unwrap();
    let near = c.add_instance(&scene, &ball, at(0.0, 1.0)).unwrap();
    let box_id = c.add_instance(&scene, &block, at(3.0, 1.0)).unwrap();
    let floor_id = c.add_instance(&scene, &floor, at(0.0, -0.5)).unwrap();
    // A sphere of points of radius 0.3 about (0.6, 0, 1): the ball's surface is 0.1 m from the
    // nearest point, less the noise radius.
    let r = 0.01;
    let points = sphere_points(Vector3::new(0.6, 0.0, 1.0), 0.3, 2000);
    set(&c, &scene, "cam", &points, r);
    let stored = c.get_scene(&scene).unwrap().clouds["cam"].cloud.clone();
    let points: Vec<Vector3> = stored.points().iter().map(|p| Vector3::from(*p)).collect();
    let brute_ball =
        points.iter().map(|p| (p - Vector3::new(0.0, 0.0, 1.0)).norm()).fold(Real::INFINITY, Real::min) - 0.2 - r;
    let brute_floor = points.iter().map(|p| p.z + 0.5).fold(Real::INFINITY, Real::min) - r;
    let check = crate::planner::check_scene(&c, &scene, 0.2, &[], &[]).unwrap();
    assert_eq!(check.scene_version, c.scene_version(&scene).unwrap());
    let pair = |a: &str| check.pairs.iter().find(|p| p.first == a && p.second == "cam");
    let d = &pair(&near).expect("the ball is within the margin").distance.answer.result;
    assert!(!d.overlapping && (d.distance - brute_ball).abs() < 1e-9, "{} vs {brute_ball}", d.distance);
    assert!(pair(&box_id).is_none(), "the box is 2 m away");
    // The floor is 1.2 m below the cloud's lowest point: outside the margin.
    assert!(brute_floor > 0.2 && pair(&floor_id).is_none());
    // With a larger margin the floor pair appears, at its closed-form distance.
    let check = crate::planner::check_scene(&c, &scene, 1.5, &[], &[]).unwrap();
    let d = &check.pairs.iter().find(|p| p.first == floor_id && p.second == "cam").unwrap().distance.answer.result;
    assert!((d.distance - brute_floor).abs() < 1e-9, "{} vs {brute_floor}", d.distance);
    // Moved into the cloud (a pose override): overlapping.
    let check =
        crate::planner::check_scene(&c, &scene, 0.0, std::slice::from_ref(&near), &[(near.clone(), at(0.35, 1.0))])
            .unwrap();
    let p = check.pairs.iter().find(|p| p.first == near && p.second == "cam").unwrap();
    assert!(p.distance.answer.result.overlapping);
}

#[test]
fn the_bodies_model_is_one_body_per_cluster_in_checks_and_check_scene() {
    let c = Catalog::open(Box::new(MemoryStore::new()), NewtonParams::default()).unwrap();
    let scene = c.create_scene("s").unwrap();
    let ball = c.add_primitive("ball", Primitive::Sphere { radius: 0.2 }).unwrap();
    let block = c.add_primitive("block", Primitive::Box { half_extents: Vector3::new(0.1, 0.2, 0.3) }).unwrap();
    let at = |x: Real, z: Real| pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, z]).unwrap();
    let near = c.add_instance(&scene, &ball, at(0.0, 1.0)).unwrap();
    let far = c.add_instance(&scene, &block, at(3.0, 1.0)).unwrap();
    // Two blobs 0.5 m apart (two clusters) and a lone point (an outlier).
    let r = 0.01;
    let mut points = sphere_points(Vector3::new(0.6, 0.0, 1.0), 0.1, 400);
    points.extend(sphere_points(Vector3::new(0.6, 0.0, 1.6), 0.1, 400));
    points.push(Vector3::new(-2.0, 0.0, 0.0));
    let mut built = c.build_point_cloud(&scene, &frame_of(&points, r)).unwrap();
    let settings = sublevel_robot::cloud::bodies::CloudBodySettings::default();
    c.build_cloud_bodies(&scene, "cam", &mut built, &settings).unwrap();
    let report = built.bodies.as_ref().unwrap().report.clone();
    assert_eq!((report.clusters, report.outliers, report.refitted), (2, 1, 2));
    let update = c.set_point_cloud(&scene, "cam", built, DEFAULT_MAX_CLOUD_BYTES).unwrap();
    assert!(update.memory_bytes >= 2 * BODY_MEMORY_BYTES);
    // The robot world holds the two bodies, named by the cloud.
    let world = c.robot_world(&scene).unwrap();
    let kinds: Vec<_> = world.objects.iter().filter(|o| o.name == "cam").map(|o| o.shape.kind()).collect();
    assert_eq!(kinds, ["body", "body"]);

    // The ball's surface is 0.6 − 0.1 − r − 0.2 from the nearest point ball (brute force); the
    // bodies contain those balls, so their distance is at most that, and they hug them.
    let stored = c.get_scene(&scene).unwrap().clouds["cam"].cloud.clone();
    let inliers = &stored.points()[..800];
    let brute = inliers
        .iter()
        .map(|p| (Vector3::from(*p) - Vector3::new(0.0, 0.0, 1.0)).norm())
        .fold(Real::INFINITY, Real::min)
        - 0.2
        - r;
    let check = crate::planner::check_scene(&c, &scene, 0.4, &[], &[]).unwrap();
    let pair = |a: &str| check.pairs.iter().find(|p| p.first == a && p.second == "cam");
    let d = &pair(&near).expect("the ball is within the margin").distance.answer.result;
    assert!(!d.overlapping && d.distance <= brute + 1e-9 && d.distance > brute - 0.03, "{} vs {brute}", d.distance);
    assert!(pair(&far).is_none(), "the box is 2 m away");

    // Moved into the first blob: overlapping its body.
    let into = [(near.clone(), at(0.55, 1.0))];
    let check = crate::planner::check_scene(&c, &scene, 0.0, std::slice::from_ref(&near), &into).unwrap();
    assert!(pair_overlaps(&check, &near));

    // The same frame again: both bodies kept, no fit.
    let mut again = c.build_point_cloud(&scene, &frame_of(&points, r)).unwrap();
    c.build_cloud_bodies(&scene, "cam", &mut again, &settings).unwrap();
    let report = &again.bodies.as_ref().unwrap().report;
    assert_eq!((report.reused, report.refitted), (2, 0));
}

fn pair_overlaps(check: &crate::planner::SceneCheck, first: &str) -> bool {
    check.pairs.iter().any(|p| p.first == first && p.second == "cam" && p.distance.answer.result.overlapping)
}

/// An update whose cancellation scope is cancelled (its client went away, its deadline passed)
/// is refused under the scene's lock: nothing is stored, the memory count and version unchanged.
#[test]
fn an_abandoned_update_is_not_stored() {
    let (c, scene) = cell();
    let world = sphere_points(Vector3::new(1.0, 0.0, 0.0), 0.2, 50);
    let built = c.build_point_cloud(&scene, &frame_of(&world, 0.01)).unwrap();
    let version = c.scene_version(&scene).unwrap();
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let out = sublevel_core::cancel::cancellable(flag.clone(), || {
        c.set_point_cloud(&scene, "cam", built, DEFAULT_MAX_CLOUD_BYTES)
    });
    assert!(matches!(out, Err(Error::Cancelled(_))), "{out:?}");
    assert_eq!((c.scene_version(&scene).unwrap(), c.cloud_bytes()), (version, 0));
    let frame = frame_of(&world, 0.01);
    let out = sublevel_core::cancel::cancellable(flag, || c.build_point_cloud(&scene, &frame));
    assert!(matches!(out, Err(Error::Cancelled(_))), "{out:?}");
}
