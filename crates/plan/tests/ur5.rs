//! The planner on a second robot, the UR5 with its Robotiq gripper (`data/robots/ur5`): a
//! post placed where the straight joint-space motion's wrist passes, so the direct motion
//! collides; the plan goes around it, every edge certified, and every edge re-checked
//! independently by dense sampling on the meshes (3 200 configurations per unit of joint
//! distance, 100× the search's resolution). The path is then timed within the URDF's velocity
//! limits (and MoveIt's default acceleration, said in the warnings): at rest at both ends, within
//! the limits at every 1 ms sample, and every sample free on the meshes.

use std::sync::atomic::AtomicBool;
use std::time::Duration;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_plan::trajectory::{joint_limits, timed_trajectory, TimingSettings, TrajectoryRequest};
use sublevel_plan::{plan, Goal, JointSpace, PlanSettings, PlanStatus, RobotValidity};
use sublevel_robot::{CheckOptions, FittedRobot, MotionChecker, RobotChecker, WorldObject};

#[test]
fn the_ur5_plans_around_a_post_with_a_certified_path_that_dense_sampling_confirms() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let robot = FittedRobot::load(&root.join("data/robots/ur5/ur5.robot.json")).unwrap();
    let dof = robot.model.dof();
    let names = robot.model.variable_names();
    let at = |values: [Real; 6]| -> Vec<Real> {
        let joints = [
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint",
        ];
        (0..dof).map(|k| joints.iter().position(|j| *j == names[k]).map_or(0.0, |i| values[i])).collect()
    };
    let start = at([-1.3, -1.2, 1.4, -1.7, -1.57, 0.0]);
    let goal = at([1.3, -1.2, 1.4, -1.7, -1.57, 0.0]);
    let base = Isometry3::identity();
    // A post 8 cm wide and 1.2 m tall through the wrist's position halfway along the direct motion.
    let middle: Vec<Real> = start.iter().zip(&goal).map(|(a, b)| 0.5 * (a + b)).collect();
    let poses = robot.model.link_poses(&middle, &base).unwrap();
    let wrist = robot.model.link_index("wrist_2_link").unwrap();
    let p = poses[wrist].translation.vector;
    let post = WorldObject::primitive(
        "post",
        Primitive::Box { half_extents: Vector3::new(0.04, 0.04, 0.6) },
        Isometry3::translation(p.x, p.y, 0.6),
    );
    let world = vec![post];
    let allowed = |_: &str, _: &str| None;
    let mut dense = RobotChecker::new(&robot, world.clone(), &allowed).unwrap();
    let options = CheckOptions { distance: false, ..CheckOptions::default() };
    assert!(!dense.check(&start, &base, &options).unwrap().collides, "the start is free");
    assert!(!dense.check(&goal, &base, &options).unwrap().collides, "the goal is free");
    assert!(dense.check(&middle, &base, &options).unwrap().world, "the direct motion hits the post");

    let mut checker = RobotChecker::new(&robot, world, &allowed).unwrap();
    let mut validity = RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), base, 0.0);
    let settings = PlanSettings { timeout: Duration::from_secs(20), ..PlanSettings::default() };
    let out =
        plan(&mut validity, &start, &Goal::Configurations(vec![goal.clone()]), &settings, &AtomicBool::new(false))
            .unwrap();
    assert_eq!(out.status, PlanStatus::Solved, "{:?} {:?}", out.timing, out.counts);
    assert!(out.certified);
    assert_eq!(out.path.first(), Some(&start));
    assert_eq!(out.path.last(), Some(&goal));
    assert!(out.path.len() >= 3, "the direct motion collides, so the path has a waypoint");
    let space = JointSpace::of(&robot.model);
    let mut q = Vec::new();
    for (e, w) in out.path.windows(2).enumerate() {
        let n = ((space.distance(&w[0], &w[1]) * 3200.0).ceil() as usize).max(1);
        for i in 0..=n {
            space.interpolate(&w[0], &w[1], i as Real / n as Real, &mut q);
            assert!(!dense.check(&q, &base, &options).unwrap().collides, "edge {e} collides at sample {i} of {n}");
        }
    }

    // Timed within the URDF's velocity limits (3.15 rad/s), MoveIt's default 1 rad/s² each.
    let none = Default::default();
    let (limits, warnings) = joint_limits(&robot.model, &none, &none, &vec![true; dof]).unwrap();
    assert!(limits.velocity.iter().all(|v| *v == 3.15), "{:?}", limits.velocity);
    assert!(limits.acceleration.iter().all(|a| *a == 1.0));
    assert_eq!(warnings.len(), dof, "{warnings:?}");
    assert!(warnings.iter().all(|w| w.contains("no acceleration limit")), "{warnings:?}");
    let ask = TrajectoryRequest {
        limits: limits.clone(),
        timing: TimingSettings::default(),
        sample_dt: 1e-3,
        max_deviation: 0.1,
    };
    let timed = timed_trajectory(&mut validity, &out.path, &ask, settings.tolerance).unwrap();
    let t = &timed.trajectory;
    assert_eq!(t.positions[0], start);
    assert_eq!(t.positions.last(), Some(&goal));
    assert!(t.velocities[0].iter().chain(t.velocities.last().unwrap()).all(|v| *v == 0.0));
    for (i, (q, (v, a))) in t.positions.iter().zip(t.velocities.iter().zip(&t.accelerations)).enumerate() {
        for j in 0..dof {
            assert!(
                v[j].abs() <= limits.velocity[j] * (1.0 + 1e-6) && a[j].abs() <= limits.acceleration[j] * (1.0 + 1e-6)
            );
        }
        assert!(!dense.check(q, &base, &options).unwrap().collides, "sample {i} collides");
    }
}
