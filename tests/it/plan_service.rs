//! Integration tests: `Plan` over gRPC against a real server. The fitted Panda uploaded, a
//! MotionBenchMaker scene imported; plans asked for by the MotionBenchMaker request text, by typed
//! configurations and by the goal's end-effector pose: each solved with a certified path from the
//! start to the goal, every edge confirmed free by dense sampling on the meshes in process (3 200
//! configurations per unit of joint distance, 100× the search's resolution). Bad requests name
//! their field; colliding ends are statuses naming the pair; a plan whose client went away frees
//! its planning slot.

use crate::util::{assert_status, config, Server};
use std::path::PathBuf;
use std::time::Duration;
use sublevel::math::{Isometry3, Real};
use sublevel::plan::JointSpace;
use sublevel::robot::{CheckOptions, FittedRobot, RobotChecker};
use sublevel::scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

/// A file of `data/robots`.
pub(crate) fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots").join(path)
}

/// The Panda's seven arm joints.
pub(crate) const JOINTS: [&str; 7] =
    ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7"];

/// Panda configurations as columns of [`JOINTS`].
pub(crate) fn columns(rows: &[Vec<f64>]) -> Option<pb::ConfigurationColumns> {
    Some(pb::ConfigurationColumns {
        joint_names: JOINTS.iter().map(|s| (*s).to_owned()).collect(),
        values: rows.iter().flatten().copied().collect(),
    })
}

/// The Panda uploaded and `scenario`'s first scene imported: (robot id, scene id, scene, request).
async fn setup(c: &mut SublevelClient<Channel>, scenario: &str) -> (String, String, PlanningScene, String) {
    let bytes = std::fs::read(data("panda/panda.robot.json")).unwrap();
    let robot = c
        .upload_robot(pb::UploadRobotRequest { name: "panda".into(), robot_file: bytes })
        .await
        .unwrap()
        .into_inner()
        .robot
        .unwrap()
        .robot_id;
    let yaml = std::fs::read(data(&format!("mbm_panda/scenes/{scenario}/scene0001.yaml"))).unwrap();
    let req = pb::ImportSceneRequest {
        scene: Some(pb::import_scene_request::Scene::Yaml(yaml.clone())),
        ..Default::default()
    };
    let scene_id = c.import_scene(req).await.unwrap().into_inner().scene_id;
    let request = std::fs::read_to_string(data(&format!("mbm_panda/requests/{scenario}/request0001.yaml"))).unwrap();
    (robot, scene_id, PlanningScene::from_yaml(&yaml).unwrap(), request)
}

/// The path's rows.
fn rows(r: &pb::PlanResponse) -> Vec<Vec<f64>> {
    r.path.chunks(r.joint_names.len()).map(<[f64]>::to_vec).collect()
}

/// Every edge of `path` free on the meshes at 3 200 samples per unit of joint distance.
fn assert_dense_free(robot: &FittedRobot, scene: &PlanningScene, path: &[Vec<f64>]) {
    let (world, _) = world_objects(scene).unwrap();
    let allowed = allowed_override(scene);
    let mut checker = RobotChecker::new(robot, world, &allowed).unwrap();
    let space = JointSpace::of(&robot.model);
    let options = CheckOptions { distance: false, ..CheckOptions::default() };
    let mut q = Vec::new();
    for (e, w) in path.windows(2).enumerate() {
        let n = ((space.distance(&w[0], &w[1]) * 3200.0).ceil() as usize).max(1);
        for i in 0..=n {
            space.interpolate(&w[0], &w[1], i as Real / n as Real, &mut q);
            assert!(!checker.check(&q, &Isometry3::identity(), &options).unwrap().collides, "edge {e}, sample {i}/{n}");
        }
    }
}

fn plan_request(robot: &str, scene: &str) -> pb::PlanRequest {
    pb::PlanRequest {
        robot_id: robot.into(),
        scene_id: scene.into(),
        settings: Some(pb::PlanSettings { timeout: Some(20.0), ..Default::default() }),
        ..Default::default()
    }
}

#[tokio::test]
async fn plans_from_moveit_text_typed_configurations_and_poses_are_certified_and_dense_sampling_agrees() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot_id, scene_id, scene, text) = setup(&mut c, "box").await;
    let robot = FittedRobot::load(&data("panda/panda.robot.json")).unwrap();
    let request = MotionPlanRequest::from_yaml(text.as_bytes()).unwrap();
    let pick = |joints: &[(String, f64)]| -> Vec<f64> {
        JOINTS.iter().map(|n| joints.iter().find(|(m, _)| m == n).unwrap().1).collect()
    };
    let (start, goal) = (pick(&request.start), pick(&request.goal));

    // The MotionBenchMaker request as text.
    let mut req = plan_request(&robot_id, &scene_id);
    req.motion_plan_request = Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(text.clone()));
    let by_text = c.plan(req).await.unwrap().into_inner();
    assert_eq!(by_text.status(), pb::PlanStatus::Solved, "{by_text:?}");
    assert!(by_text.certified && by_text.unproven_edges.is_empty());
    assert_eq!(by_text.joint_names, JOINTS);
    let path = rows(&by_text);
    assert_eq!(path.len(), by_text.waypoints as usize);
    assert_eq!((path.first(), path.last()), (Some(&start), Some(&goal)));
    assert_eq!(by_text.goal, goal);
    let space = JointSpace::of(&robot.model);
    let length: f64 = path.windows(2).map(|w| space.distance(&w[0], &w[1])).sum();
    assert!((length - by_text.length).abs() < 1e-9 && length >= space.distance(&start, &goal) - 1e-12);
    let t = by_text.timing.unwrap();
    assert!(t.total >= t.search + t.simplify + t.certify && by_text.edges_certified >= path.len() as u64 - 1);
    assert_dense_free(&robot, &scene, &path);

    // The same problem in typed fields: the same seed, the same path.
    let mut req = plan_request(&robot_id, &scene_id);
    req.start = columns(std::slice::from_ref(&start));
    req.goal_configurations = columns(std::slice::from_ref(&goal));
    let typed = c.plan(req).await.unwrap().into_inner();
    assert_eq!(typed.status(), pb::PlanStatus::Solved);
    assert_eq!(typed.path, by_text.path);

    // The goal as the hand's pose (forward kinematics of the goal configuration).
    let hand = robot.model.link_index("panda_hand").unwrap();
    let target = robot.model.link_poses(&goal, &Isometry3::identity()).unwrap()[hand];
    let (q, t) = (target.rotation.into_inner(), target.translation.vector);
    let mut req = plan_request(&robot_id, &scene_id);
    req.start = columns(std::slice::from_ref(&start));
    req.goal_pose = Some(pb::PoseGoal {
        link: "panda_hand".into(),
        pose: Some(crate::util::pose([q.w, q.i, q.j, q.k], [t.x, t.y, t.z])),
        position_tolerance: 1e-3,
        orientation_tolerance: 1e-2,
    });
    let by_pose = c.plan(req).await.unwrap().into_inner();
    assert_eq!(by_pose.status(), pb::PlanStatus::Solved, "{by_pose:?}");
    let path = rows(&by_pose);
    let end = robot.model.link_poses(path.last().unwrap(), &Isometry3::identity()).unwrap()[hand];
    assert!((end.translation.vector - target.translation.vector).norm() <= 1e-3);
    assert!(end.rotation.angle_to(&target.rotation) <= 1e-2);
    assert_eq!(by_pose.goal, *path.last().unwrap());
    assert_dense_free(&robot, &scene, &path);
}

#[tokio::test]
async fn bad_plans_name_their_field_and_colliding_ends_name_the_pair() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot_id, scene_id, _, text) = setup(&mut c, "box").await;
    let request = MotionPlanRequest::from_yaml(text.as_bytes()).unwrap();
    let start: Vec<f64> = JOINTS.iter().map(|n| request.start.iter().find(|(m, _)| m == n).unwrap().1).collect();
    let goal: Vec<f64> = JOINTS.iter().map(|n| request.goal.iter().find(|(m, _)| m == n).unwrap().1).collect();
    let typed = |s: Vec<f64>, g: Vec<f64>| {
        let mut r = plan_request(&robot_id, &scene_id);
        r.start = columns(&[s]);
        r.goal_configurations = columns(&[g]);
        r
    };
    let mut unknown = typed(start.clone(), goal.clone());
    unknown.start.as_mut().unwrap().joint_names[0] = "elbow".into();
    assert_status(c.plan(unknown).await, Code::InvalidArgument, "start.joint_names[0]");
    let mut nan = goal.clone();
    nan[3] = f64::NAN;
    assert_status(c.plan(typed(start.clone(), nan)).await, Code::InvalidArgument, "goal_configurations.values[3]");
    let mut outside = start.clone();
    outside[1] = 3.0;
    assert_status(c.plan(typed(outside, goal.clone())).await, Code::InvalidArgument, "start.values[1]");
    let mut short = typed(start.clone(), goal.clone());
    short.goal_configurations.as_mut().unwrap().values.pop();
    assert_status(c.plan(short).await, Code::InvalidArgument, "goal_configurations.values");
    let mut zero = typed(start.clone(), goal.clone());
    zero.settings = Some(pb::PlanSettings { timeout: Some(0.0), ..Default::default() });
    assert_status(c.plan(zero).await, Code::InvalidArgument, "settings.timeout");
    let mut none = plan_request(&robot_id, &scene_id);
    none.start = columns(std::slice::from_ref(&start));
    assert_status(c.plan(none).await, Code::InvalidArgument, "goal_configurations");
    let mut both = typed(start.clone(), goal.clone());
    both.motion_plan_request = Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(text.clone()));
    assert_status(c.plan(both).await, Code::InvalidArgument, "start");
    let mut bad_link = plan_request(&robot_id, &scene_id);
    bad_link.goal_pose = Some(pb::PoseGoal { link: "gripper".into(), ..Default::default() });
    assert_status(c.plan(bad_link).await, Code::InvalidArgument, "goal_pose.link");
    let mut bad_text = plan_request(&robot_id, &scene_id);
    bad_text.motion_plan_request = Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml("[1, 2".into()));
    assert_status(c.plan(bad_text).await, Code::InvalidArgument, "motion_plan_request_yaml");

    // Colliding ends: the first configuration of this scene the mesh labels call colliding.
    let labels = std::fs::read_to_string(data("mbm_panda/labels_obj.csv")).unwrap();
    let down: Vec<f64> = labels
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|c| c[0] == "box" && c[1] == "1" && c[11] == "1")
        .map(|c| c[4..11].iter().map(|v| v.parse().unwrap()).collect())
        .unwrap();
    let r = c.plan(typed(down.clone(), goal.clone())).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::StartInCollision, "{r:?}");
    assert!(r.message.contains("collides with") && r.path.is_empty(), "{}", r.message);
    let r = c.plan(typed(start.clone(), down)).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::GoalInCollision, "{r:?}");
    assert!(r.message.contains("link `panda_"), "{}", r.message);
}

#[tokio::test]
async fn a_plan_whose_client_went_away_frees_its_slot() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(sublevel::service::ServerConfig { max_concurrent_plans: 1, ..config(dir.path()) }).await;
    let mut c = server.client().await;
    let (robot_id, scene_id, _, text) = setup(&mut c, "cage").await;
    // A search made slow on purpose (tiny steps, edges sampled at the finest resolution allowed):
    // it would run its full 60 s.
    let mut slow = plan_request(&robot_id, &scene_id);
    slow.motion_plan_request = Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(text.clone()));
    slow.settings =
        Some(pb::PlanSettings { timeout: Some(60.0), range: 1e-3, resolution: 1000.0, ..Default::default() });
    let mut gone = c.clone();
    let call = tokio::time::timeout(Duration::from_millis(300), gone.plan(slow.clone())).await;
    assert!(call.is_err(), "the slow plan answered within 300 ms");
    drop(gone);
    // The one planning slot is free again: a plan asked now is answered well before the slow one's
    // 60 s would have ended.
    let mut quick = plan_request(&robot_id, &scene_id);
    quick.motion_plan_request = Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(text));
    let r = tokio::time::timeout(Duration::from_secs(30), c.plan(quick)).await.expect("the slot stayed taken");
    assert_eq!(r.unwrap().into_inner().status(), pb::PlanStatus::Solved);
    // The call's own deadline caps the plan: answered TIMED_OUT (or DEADLINE_EXCEEDED), never late.
    let mut capped = tonic::Request::new(slow);
    capped.set_timeout(Duration::from_millis(500));
    match c.plan(capped).await {
        Ok(r) => assert_eq!(r.into_inner().status(), pb::PlanStatus::TimedOut),
        Err(e) => assert_eq!(e.code(), Code::DeadlineExceeded),
    }
}

/// A planar three-joint arm of boxes (not the Panda): links of 0.5, 0.4 and 0.2 m at z = 0.1,
/// each joint about z. Fitted by the service from its URDF alone (primitives stay exact).
const ARM_URDF: &str = r#"<robot name="planar3">
  <link name="base"><collision><geometry><cylinder radius="0.05" length="0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0.25 0 0"/><geometry><box size="0.5 0.06 0.06"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.2 0 0"/><geometry><box size="0.4 0.05 0.05"/></geometry></collision></link>
  <link name="l3"><collision><origin xyz="0.1 0 0"/><geometry><box size="0.2 0.04 0.04"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/><axis xyz="0 0 1"/><limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0"/><axis xyz="0 0 1"/><limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>
</robot>"#;

/// Its SRDF: adjacent links touch at their joints.
const ARM_SRDF: &str = r#"<robot name="planar3">
  <disable_collisions link1="base" link2="l1" reason="Adjacent"/>
  <disable_collisions link1="l1" link2="l2" reason="Adjacent"/>
  <disable_collisions link1="l2" link2="l3" reason="Adjacent"/>
</robot>"#;

/// A post (0.1 × 0.1 × 0.4 m box) at (0.7, 0, 0.2): the arm stretched cannot sweep past it.
const POST_SCENE: &str = "name: post
world:
  collision_objects:
    - id: post
      header: {frame_id: world}
      primitives:
        - type: box
          dimensions: [0.1, 0.1, 0.4]
      primitive_poses:
        - position: [0.7, 0.0, 0.2]
          orientation: [0, 0, 0, 1]
";

#[tokio::test]
async fn a_robot_fitted_from_another_urdf_plans_with_no_code_change() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let fit = pb::StartRobotFitJobRequest { urdf: ARM_URDF.into(), srdf: ARM_SRDF.into(), ..Default::default() };
    let job_id = c.start_robot_fit_job(fit).await.unwrap().into_inner().job_id;
    let last = crate::util::watch_to_end(&mut c, job_id).await.pop().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    let req = pb::ImportSceneRequest {
        scene: Some(pb::import_scene_request::Scene::Yaml(POST_SCENE.as_bytes().to_vec())),
        ..Default::default()
    };
    let scene_id = c.import_scene(req).await.unwrap().into_inner().scene_id;
    // Stretched along +y to stretched along −y: the straight joint-space line sweeps the arm
    // through the post at x = 0.7.
    let (start, goal) = (vec![1.5, 0.0, 0.0], vec![-1.5, 0.0, 0.0]);
    let names = ["j1", "j2", "j3"].map(String::from).to_vec();
    let cols = |q: &[f64]| Some(pb::ConfigurationColumns { joint_names: names.clone(), values: q.to_vec() });
    let mut req = plan_request(&last.robot_id, &scene_id);
    req.start = cols(&start);
    req.goal_configurations = cols(&goal);
    let r = c.plan(req).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert!(r.certified);
    assert_eq!(r.joint_names, names);
    let path = rows(&r);
    assert_eq!((path.first(), path.last()), (Some(&start), Some(&goal)));
    assert!(path.len() > 2, "the straight line collides: the path must go round");
    // The same robot fitted in process from the same URDF, and the scene: every edge free on
    // dense samples (the arm's boxes against the post's box, exact).
    let robot = sublevel::robot::fit_robot_text(
        ARM_URDF.into(),
        Some(ARM_SRDF),
        sublevel::robot::MeshSource::Memory(&Default::default()),
        &Default::default(),
        &|_| {},
    )
    .unwrap();
    let scene = PlanningScene::from_yaml(POST_SCENE.as_bytes()).unwrap();
    assert_dense_free(&robot, &scene, &path);
    // The straight line itself does collide (so the plan did go round).
    let (world, _) = world_objects(&scene).unwrap();
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let options = CheckOptions { distance: false, ..CheckOptions::default() };
    assert!(checker.check(&[0.0, 0.0, 0.0], &Isometry3::identity(), &options).unwrap().collides);
}
