//! Robots as users bring them, over gRPC: an SRDF naming links its URDF lacks is read as MoveIt
//! reads it (skipped, each with a warning in the robot's summary); links split by fixed joints
//! that overlap are one rigid body, never checked; states on a bound printed at five digits, or
//! rounded past it, are checked; a plan's start up to 0.05 rad past a limit and goal constraints
//! whose tolerance meets the limits are planned, the answer saying what was moved; anything
//! farther is refused naming the field.

use crate::util::{assert_status, config, Server};
use std::f64::consts::PI;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

/// A planar arm on a base split in two overlapping boxes (`base`, `base_2`, joined by a fixed
/// joint, as real URDFs split links), its first joint's limits printed at five digits.
const SPLIT_ARM_URDF: &str = r#"<robot name="split_arm">
  <link name="base"><collision><geometry><box size="0.3 0.3 0.1"/></geometry></collision></link>
  <link name="base_2"><collision><origin xyz="0 0 0.05"/><geometry><box size="0.2 0.2 0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0.25 0 0"/><geometry><box size="0.5 0.06 0.06"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.2 0 0"/><geometry><box size="0.4 0.05 0.05"/></geometry></collision></link>
  <joint name="base_fixed" type="fixed"><parent link="base"/><child link="base_2"/></joint>
  <joint name="j1" type="revolute"><parent link="base_2"/><child link="l1"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/><limit lower="-3.14159" upper="3.14159" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/><axis xyz="0 0 1"/><limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>
</robot>"#;

/// Its SRDF, written for a version of the robot with a bellows: two entries name links this URDF
/// lacks, and none disables base – base_2.
const SPLIT_ARM_SRDF: &str = r#"<robot name="split_arm">
  <disable_collisions link1="base_2" link2="l1" reason="Adjacent"/>
  <disable_collisions link1="bellows_link2" link2="l1" reason="Never"/>
  <disable_collisions link1="l1" link2="l2" reason="Adjacent"/>
  <disable_collisions link1="bellows_link" link2="base" reason="Adjacent"/>
</robot>"#;

/// One configuration of the two joints.
fn cols(q: &[f64]) -> Option<pb::ConfigurationColumns> {
    Some(pb::ConfigurationColumns { joint_names: vec!["j1".into(), "j2".into()], values: q.to_vec() })
}

/// The bound of ±π as URDFs print it, at five digits.
#[allow(clippy::approx_constant)]
const PRINTED_PI: f64 = 3.14159;

/// Fits the split arm with its SRDF by `StartRobotFitJob`; the stored robot's id.
async fn fit_split_arm(c: &mut SublevelClient<Channel>) -> String {
    let fit =
        pb::StartRobotFitJobRequest { urdf: SPLIT_ARM_URDF.into(), srdf: SPLIT_ARM_SRDF.into(), ..Default::default() };
    let job_id = c.start_robot_fit_job(fit).await.unwrap().into_inner().job_id;
    let last = crate::util::watch_to_end(c, job_id).await.pop().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    last.robot_id
}

#[tokio::test]
async fn a_robot_brought_as_moveit_takes_it_loads_checks_and_plans_saying_what_was_moved() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let robot_id = fit_split_arm(&mut c).await;
    let summary =
        c.get_robot(pb::GetRobotRequest { robot_id: robot_id.clone() }).await.unwrap().into_inner().robot.unwrap();
    // The two entries naming links the URDF lacks, each named; the rigid pair listed.
    assert_eq!(summary.fit_warnings.len(), 2, "{:?}", summary.fit_warnings);
    assert!(summary.fit_warnings[0].starts_with("srdf.disable_collisions[1]: skipped, link `bellows_link2`"));
    assert!(summary.fit_warnings[1].starts_with("srdf.disable_collisions[3]: skipped, link `bellows_link`"));
    assert_eq!(summary.rigid_pairs, vec!["base base_2".to_owned()]);
    // Pairs of 4 links with geometry: 6, less base_2–l1, l1–l2 (SRDF) and base–base_2 (rigid).
    assert_eq!(summary.self_pairs, 3);
    assert_eq!((summary.lower[0], summary.upper[0]), (-PRINTED_PI, PRINTED_PI));

    // A state on the printed bound, and one rounded 7e-16 past it: checked, free (the base's
    // overlapping halves are not a self collision). 1e-6 past: refused naming the value.
    let check = |values: Vec<f64>| pb::CheckConfigurationsRequest {
        robot_id: robot_id.clone(),
        configurations: cols(&values),
        ..Default::default()
    };
    let r =
        c.check_configurations(check(vec![-PRINTED_PI, 0.3, -(PRINTED_PI + 7e-16), 0.3])).await.unwrap().into_inner();
    assert_eq!(r.collides, vec![false, false]);
    assert_status(
        c.check_configurations(check(vec![0.0, 0.0, -PRINTED_PI - 1e-6, 0.0])).await,
        Code::InvalidArgument,
        "configurations.values[2]",
    );
    let motion = pb::CheckMotionsRequest {
        robot_id: robot_id.clone(),
        start: cols(&[0.0, 0.0]),
        end: cols(&[(PRINTED_PI + 7e-16), 2.8000000000000003]),
        ..Default::default()
    };
    let r = c.check_motions(motion).await.unwrap().into_inner();
    assert_eq!(r.valid, vec![true]);

    // A start at −π (2.65e-6 past the printed bound), and a goal constraint at π with a tolerance
    // of 0.1: planned from and to the bound, each move said naming its field.
    let plan = |start: &[f64]| pb::PlanRequest {
        robot_id: robot_id.clone(),
        start: cols(start),
        goal_joint_constraints: vec![pb::JointConstraint {
            joint_name: "j1".into(),
            position: PI,
            tolerance_below: 0.1,
            tolerance_above: 0.1,
        }],
        settings: Some(pb::PlanSettings { timeout: Some(10.0), ..Default::default() }),
        ..Default::default()
    };
    let r = c.plan(plan(&[-PI, 0.5])).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert!(r.certified);
    assert_eq!(&r.path[..2], &[-PRINTED_PI, 0.5]);
    let goal_j1 = r.path[r.path.len() - 2];
    assert!((PI - 0.1..=PRINTED_PI).contains(&goal_j1), "{goal_j1}");
    assert_eq!(r.warnings.len(), 2, "{:?}", r.warnings);
    assert!(r.warnings[0].starts_with("start.values[0]: joint `j1`"), "{}", r.warnings[0]);
    assert!(r.warnings[1].starts_with("goal_joint_constraints[0].position: joint `j1`"), "{}", r.warnings[1]);
    // 0.06 past the bound: refused naming the value; the bound error is the request's to set, in
    // [0, 1].
    assert_status(c.plan(plan(&[-PRINTED_PI - 0.06, 0.5])).await, Code::InvalidArgument, "start.values[0]");
    let mut wide = plan(&[-PRINTED_PI - 0.06, 0.5]);
    wide.settings.as_mut().unwrap().start_state_max_bounds_error = Some(0.1);
    let r = c.plan(wide).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    let mut bad = plan(&[0.0, 0.5]);
    bad.settings.as_mut().unwrap().start_state_max_bounds_error = Some(2.0);
    assert_status(c.plan(bad).await, Code::InvalidArgument, "settings.start_state_max_bounds_error");

    // A MoveIt MotionPlanRequest with the start at −π: the same, named in its text's fields; a
    // goal with no tolerance at π is taken at the bound, one 0.1 past it refused.
    let text = |goal: f64, tolerance: f64| {
        format!(
            "start_state:\n  joint_state:\n    name: [j1, j2]\n    position: [{}, 0.5]\n\
             goal_constraints:\n  - joint_constraints:\n      - joint_name: j1\n        position: {goal}\n        \
             tolerance_above: {tolerance}\n        tolerance_below: {tolerance}\n        weight: 1.0\n",
            -PI
        )
    };
    let moveit = |yaml: String| pb::PlanRequest {
        robot_id: robot_id.clone(),
        motion_plan_request: Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(yaml)),
        settings: Some(pb::PlanSettings { timeout: Some(10.0), ..Default::default() }),
        ..Default::default()
    };
    let r = c.plan(moveit(text(1.0, 0.0))).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
    assert!(r.warnings[0].starts_with("motion_plan_request_yaml.start_state[0]: joint `j1`"), "{}", r.warnings[0]);
    let r = c.plan(moveit(text(PI, 0.0))).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert_eq!(r.path[r.path.len() - 2], PRINTED_PI);
    assert_eq!(r.warnings.len(), 2, "{:?}", r.warnings);
    assert!(r.warnings[1].contains("misses its limits"), "{}", r.warnings[1]);
    assert_status(
        c.plan(moveit(text(PI + 0.1, 0.0))).await,
        Code::InvalidArgument,
        "motion_plan_request_yaml.goal_constraints[0].joint_constraints[0].position",
    );
}

#[tokio::test]
async fn a_plan_moves_the_joints_its_goal_names_and_holds_the_others() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let robot_id = fit_split_arm(&mut c).await;
    let request = |planning: &[&str]| pb::PlanRequest {
        robot_id: robot_id.clone(),
        start: cols(&[0.0, 0.5]),
        planning_joints: planning.iter().map(|s| (*s).to_owned()).collect(),
        settings: Some(pb::PlanSettings { timeout: Some(10.0), ..Default::default() }),
        ..Default::default()
    };
    let j2 = |r: &pb::PlanResponse| r.path.chunks(2).map(|q| q[1]).collect::<Vec<_>>();
    // A joint goal naming j1: j2 stays at the start's 0.5 on every waypoint.
    let mut req = request(&[]);
    req.goal_joint_constraints =
        vec![pb::JointConstraint { joint_name: "j1".into(), position: 2.0, ..Default::default() }];
    let r = c.plan(req).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert_eq!(r.planning_joints, vec!["j1".to_owned()]);
    assert!(j2(&r).iter().all(|v| *v == 0.5), "{:?}", r.path);
    // Goal configurations naming j1 only: j2 is held at the start's value (not the scene's 0).
    let mut req = request(&[]);
    req.goal_configurations = Some(pb::ConfigurationColumns { joint_names: vec!["j1".into()], values: vec![-2.0] });
    let r = c.plan(req).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert_eq!(r.goal, vec![-2.0, 0.5]);
    assert!(j2(&r).iter().all(|v| *v == 0.5));
    // Goal configurations of every joint move both; planning_joints that leave out a joint the
    // goal moves are refused, as are unknown names and planning joints with a pose goal.
    let mut req = request(&[]);
    req.goal_configurations = cols(&[-2.0, -0.5]);
    let r = c.plan(req.clone()).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert_eq!(r.planning_joints, vec!["j1".to_owned(), "j2".to_owned()]);
    req.planning_joints = vec!["j1".into()];
    assert_status(c.plan(req.clone()).await, Code::InvalidArgument, "planning_joints");
    req.planning_joints = vec!["j1".into(), "nope".into()];
    assert_status(c.plan(req).await, Code::InvalidArgument, "planning_joints[1]");
    let mut req = request(&["j1"]);
    req.goal_pose = Some(pb::PoseGoal {
        link: "l2".into(),
        pose: Some(pb::Pose {
            rotation: Some(pb::Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }),
            translation: Some(pb::Vec3 { x: 0.5, y: 0.0, z: 0.2 }),
        }),
        ..Default::default()
    });
    assert_status(c.plan(req).await, Code::InvalidArgument, "planning_joints");
}
