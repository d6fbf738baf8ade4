//! Integration tests: `Plan` over gRPC against a real server. The fitted Panda uploaded, a
//! MotionBenchMaker scene imported; plans asked for by the MotionBenchMaker request text, by typed
//! configurations and by the goal's end-effector pose: each solved with a certified path from the
//! start to the goal, every edge confirmed free by dense sampling on the meshes in process (3 200
//! configurations per unit of joint distance, 100× the search's resolution). Bad requests name
//! their field; colliding ends are statuses naming the pair; a plan whose client went away frees
//! its batch slot.

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

fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots").join(path)
}

const JOINTS: [&str; 7] =
    ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7"];

fn columns(rows: &[Vec<f64>]) -> Option<pb::ConfigurationColumns> {
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
    let server = Server::start(sublevel::service::ServerConfig { batch_workers: 1, ..config(dir.path()) }).await;
    let mut c = server.client().await;
    let (robot_id, scene_id, _, text) = setup(&mut c, "cage").await;
    // A search made slow on purpose (tiny steps, edges sampled 10⁵ times per unit): it
    // would run its full 60 s.
    let mut slow = plan_request(&robot_id, &scene_id);
    slow.motion_plan_request = Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(text.clone()));
    slow.settings = Some(pb::PlanSettings { timeout: Some(60.0), range: 1e-3, resolution: 1e5, ..Default::default() });
    let mut gone = c.clone();
    let call = tokio::time::timeout(Duration::from_millis(300), gone.plan(slow.clone())).await;
    assert!(call.is_err(), "the slow plan answered within 300 ms");
    drop(gone);
    // The one batch slot is free again: a plan asked now is answered well before the slow one's
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
