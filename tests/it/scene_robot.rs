//! Integration tests: the robot of a scene over gRPC. The fitted Panda placed in an imported
//! MotionBenchMaker scene, moved by `SetJointPositions` to labelled configurations, checked by
//! `CheckScene` against the mesh-exact labels (pinocchio + coal on the collision meshes); checks
//! naming no robot answer exactly as the same checks naming the robot, its attached objects and
//! padding; changes are all or nothing, name their fields, and survive a restart.

use crate::util::{assert_status, config, Server};
use std::path::PathBuf;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots").join(path)
}

const JOINTS: [&str; 7] =
    ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7"];

/// The labelled configurations of bookshelf_small scene 1: (q, collides, min world distance).
fn labels() -> Vec<(Vec<f64>, bool, f64)> {
    let text = std::fs::read_to_string(data("mbm_panda/labels_obj.csv")).unwrap();
    text.lines()
        .skip(1)
        .filter_map(|line| {
            let c: Vec<&str> = line.split(',').collect();
            (c[0] == "bookshelf_small" && c[1] == "1").then(|| {
                let q = c[4..11].iter().map(|v| v.parse().unwrap()).collect();
                (q, c[11] == "1", c[14].parse().unwrap_or(f64::INFINITY))
            })
        })
        .collect()
}

fn joints(q: &[f64]) -> Option<pb::ConfigurationColumns> {
    Some(pb::ConfigurationColumns { joint_names: JOINTS.iter().map(|s| (*s).to_owned()).collect(), values: q.to_vec() })
}

fn ball(radius: f64) -> pb::Primitive {
    pb::Primitive { kind: pb::PrimitiveKind::Sphere as i32, radius, ..Default::default() }
}

async fn setup(c: &mut SublevelClient<Channel>) -> (String, String) {
    let bytes = std::fs::read(data("panda/panda.robot.json")).unwrap();
    let robot = c.upload_robot(pb::UploadRobotRequest { name: "panda".into(), robot_file: bytes }).await.unwrap();
    let yaml = std::fs::read(data("mbm_panda/scenes/bookshelf_small/scene0001.yaml")).unwrap();
    let req = pb::ImportSceneRequest {
        name: String::new(),
        scene: Some(pb::import_scene_request::Scene::Yaml(yaml)),
        ..Default::default()
    };
    let scene_id = c.import_scene(req).await.unwrap().into_inner().scene_id;
    (robot.into_inner().robot.unwrap().robot_id, scene_id)
}

async fn check_scene_robot(c: &mut SublevelClient<Channel>, scene_id: &str) -> pb::CheckConfigurationsResponse {
    let req = pb::CheckSceneRequest { scene_id: scene_id.into(), ..Default::default() };
    c.check_scene(req).await.unwrap().into_inner().robot.expect("the scene has a robot")
}

#[tokio::test]
async fn a_scene_robot_is_checked_at_its_joint_positions_against_the_mesh_labels() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot_id, scene_id) = setup(&mut c).await;
    let rows = labels();
    let colliding = rows.iter().find(|r| r.1).unwrap();
    let free: Vec<_> = rows.iter().filter(|r| !r.1 && r.2.is_finite()).take(3).collect();

    // Without a robot, CheckScene has no robot answer and SetJointPositions has nothing to move.
    let req = pb::CheckSceneRequest { scene_id: scene_id.clone(), ..Default::default() };
    assert!(c.check_scene(req).await.unwrap().into_inner().robot.is_none());
    let req = pb::SetJointPositionsRequest { scene_id: scene_id.clone(), joint_positions: joints(&colliding.0) };
    assert_status(c.set_joint_positions(req).await, Code::FailedPrecondition, "no robot");

    let req = pb::SetSceneRobotRequest {
        scene_id: scene_id.clone(),
        robot_id: robot_id.clone(),
        joint_positions: joints(&colliding.0),
        ..Default::default()
    };
    let placed = c.set_scene_robot(req).await.unwrap().into_inner().robot.unwrap();
    assert_eq!(placed.robot_id, robot_id);
    let shown: Vec<f64> = placed.joint_positions.iter().take(7).map(|j| j.position).collect();
    assert_eq!(shown, colliding.0);
    let got = check_scene_robot(&mut c, &scene_id).await;
    assert_eq!((got.count, got.collides[0]), (1, true), "a configuration the meshes call colliding");

    // Moved to free configurations: free, at the meshes' distance within 10 µm and never above.
    for (q, _, label) in &free {
        let req = pb::SetJointPositionsRequest { scene_id: scene_id.clone(), joint_positions: joints(q) };
        c.set_joint_positions(req).await.unwrap();
        let got = check_scene_robot(&mut c, &scene_id).await;
        assert!(!got.collides[0]);
        assert!(got.distance[0] <= label + 1e-9 && got.distance[0] >= label - 1e-5, "{} vs {label}", got.distance[0]);
    }

    // All or nothing: an unknown joint is named and moves nothing.
    let before = c.get_scene(pb::GetSceneRequest { scene_id: scene_id.clone() }).await.unwrap().into_inner();
    let mut bad = joints(&free[0].0).unwrap();
    bad.joint_names[3] = "elbow".into();
    let req = pb::SetJointPositionsRequest { scene_id: scene_id.clone(), joint_positions: Some(bad) };
    assert_status(c.set_joint_positions(req).await, Code::InvalidArgument, "joint_positions.joint_names[3]");
    let after = c.get_scene(pb::GetSceneRequest { scene_id: scene_id.clone() }).await.unwrap().into_inner();
    assert_eq!(before.joint_positions, after.joint_positions);
    assert_eq!(after.robot.unwrap().joint_positions, before.robot.unwrap().joint_positions);

    // A grasped ball and link padding: checks naming no robot answer as the same checks naming
    // the robot, the ball and the padding, bit for bit.
    let can = pb::AttachedObject {
        link: "panda_hand".into(),
        name: "can".into(),
        primitive: Some(ball(0.04)),
        origin: Some(pb::Pose {
            rotation: Some(pb::Quaternion { w: 1.0, ..Default::default() }),
            translation: Some(pb::Vec3 { x: 0.0, y: 0.0, z: 0.1 }),
        }),
    };
    let req = pb::AttachObjectRequest { scene_id: scene_id.clone(), attached: Some(can.clone()) };
    let placed = c.attach_object(req).await.unwrap().into_inner().robot.unwrap();
    assert_eq!(placed.attached.len(), 1);
    let mut bad = can.clone();
    bad.link = "gripper".into();
    let req = pb::AttachObjectRequest { scene_id: scene_id.clone(), attached: Some(bad) };
    assert_status(c.attach_object(req).await, Code::InvalidArgument, "attached.link");
    let padding: std::collections::HashMap<String, f64> = [("panda_link7".to_owned(), 0.01)].into();
    let req = pb::SetSceneRobotRequest {
        scene_id: scene_id.clone(),
        robot_id: robot_id.clone(),
        attached: vec![can.clone()],
        link_padding: padding.clone(),
        ..Default::default()
    };
    c.set_scene_robot(req).await.unwrap();
    let q: Vec<f64> = rows.iter().take(40).flat_map(|r| r.0.clone()).collect();
    let req = pb::CheckConfigurationsRequest {
        scene_id: scene_id.clone(),
        configurations: joints(&q),
        distance: true,
        ..Default::default()
    };
    let by_scene = c.check_configurations(req.clone()).await.unwrap().into_inner();
    let named = pb::CheckConfigurationsRequest {
        robot_id: robot_id.clone(),
        attached: vec![can],
        link_padding: padding,
        ..req
    };
    let by_name = c.check_configurations(named).await.unwrap().into_inner();
    assert_eq!(by_scene.count, 40);
    assert_eq!(by_scene.collides, by_name.collides);
    assert_eq!(by_scene.robot_geometry, by_name.robot_geometry);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&by_scene.distance), bits(&by_name.distance));
    let motion = pb::CheckMotionsRequest {
        scene_id: scene_id.clone(),
        start: joints(&free[0].0),
        end: joints(&free[1].0),
        ..Default::default()
    };
    let by_scene = c.check_motions(motion.clone()).await.unwrap().into_inner();
    let by_name = c
        .check_motions(pb::CheckMotionsRequest {
            robot_id: robot_id.clone(),
            attached: vec![placed.attached[0].clone()],
            link_padding: [("panda_link7".to_owned(), 0.01)].into(),
            ..motion
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((by_scene.valid, by_scene.steps), (by_name.valid, by_name.steps));
    server.stop().await;

    // A restart finds the scene's robot, its ball, padding and joint positions.
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let scene = c.get_scene(pb::GetSceneRequest { scene_id: scene_id.clone() }).await.unwrap().into_inner();
    let robot = scene.robot.unwrap();
    assert_eq!((robot.attached.len(), robot.link_padding["panda_link7"]), (1, 0.01));
    let shown: Vec<f64> = robot.joint_positions.iter().take(7).map(|j| j.position).collect();
    assert_eq!(shown, free[2].0);
    let req = pb::DetachObjectRequest { scene_id: scene_id.clone(), name: "cup".into() };
    assert_status(c.detach_object(req).await, Code::NotFound, "cup");
    let req = pb::DetachObjectRequest { scene_id: scene_id.clone(), name: "can".into() };
    assert!(c.detach_object(req).await.unwrap().into_inner().robot.unwrap().attached.is_empty());
    let removed = c.clear_scene_robot(pb::ClearSceneRobotRequest { scene_id: scene_id.clone() }).await.unwrap();
    assert!(removed.into_inner().removed);
    let req = pb::CheckConfigurationsRequest { scene_id, configurations: joints(&free[0].0), ..Default::default() };
    assert_status(c.check_configurations(req).await, Code::InvalidArgument, "robot_id");
    server.stop().await;
}

/// The one-joint arm of `tests/data/arm.robot.json`: a revolute joint `j` about z at the base;
/// link `arm` holds a ball of radius 0.1 m at (0.5, 0, 0) in its frame, so at j = θ the ball's
/// center is (0.5 cos θ, 0.5 sin θ, 0).
fn arm_file() -> Vec<u8> {
    include_bytes!("../data/arm.robot.json").to_vec()
}

fn at(x: f64, y: f64) -> pb::Pose {
    pb::Pose {
        rotation: Some(pb::Quaternion { w: 1.0, ..Default::default() }),
        translation: Some(pb::Vec3 { x, y, z: 0.0 }),
    }
}

fn arm_states(q: &[f64]) -> pb::CheckConfigurationsRequest {
    pb::CheckConfigurationsRequest {
        configurations: Some(pb::ConfigurationColumns { joint_names: vec!["j".into()], values: q.to_vec() }),
        distance: true,
        ..Default::default()
    }
}

/// Joint configurations as the states of a planner stream: checked against the stream's private
/// view (its poses), with motions certified there, against closed forms; the stored scene and a
/// unary Query never see the view's poses.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn query_streams_check_joint_configurations_and_motions_on_their_view() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let robot = c.upload_robot(pb::UploadRobotRequest { name: "arm".into(), robot_file: arm_file() }).await.unwrap();
    let robot_id = robot.into_inner().robot.unwrap().robot_id;
    let scene_id = c.create_scene(pb::CreateSceneRequest { name: "cell".into() }).await.unwrap().into_inner().scene_id;
    let req =
        pb::UploadBodyRequest { name: "ball".into(), body: Some(pb::upload_body_request::Body::Primitive(ball(0.2))) };
    let body_id = c.upload_body(req).await.unwrap().into_inner().body_id;
    // The obstacle: a ball of radius 0.2 m at (0.5, 1, 0).
    let req = pb::AddInstanceRequest { scene_id: scene_id.clone(), body_id, pose: Some(at(0.5, 1.0)) };
    let obstacle = c.add_instance(req).await.unwrap().into_inner().instance_id;
    let req = pb::SetSceneRobotRequest { scene_id: scene_id.clone(), robot_id, ..Default::default() };
    c.set_scene_robot(req).await.unwrap();

    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut answers = c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    // j = 0: centers 1 m apart, 0.7 m between the balls; j = π/2: √0.5 − 0.3.
    let half_pi = std::f64::consts::FRAC_PI_2;
    tx.send(pb::QueryRequest {
        scene_id: scene_id.clone(),
        robot_states: Some(arm_states(&[0.0, half_pi])),
        ..Default::default()
    })
    .await
    .unwrap();
    let r = answers.message().await.unwrap().unwrap().robot_states.unwrap();
    assert!(
        (r.distance[0] - 0.7).abs() < 1e-9 && (r.distance[1] - (0.5f64.sqrt() - 0.3)).abs() < 1e-9,
        "{:?}",
        r.distance
    );

    // The stream moves the obstacle onto the ball's circle at 45°: j = 0 is then
    // 2 · 0.5 · sin(π/8) − 0.3 from it, and the motion j: 0 → π/2 touches it where the chord
    // sin(|θ − π/4| / 2) falls to 0.3, at θ* = π/4 − 2 asin(0.3), t* = θ* / (π/2).
    let c45 = 0.5 * std::f64::consts::FRAC_1_SQRT_2;
    let motion = pb::CheckMotionsRequest {
        start: Some(pb::ConfigurationColumns { joint_names: vec!["j".into()], values: vec![0.0] }),
        end: Some(pb::ConfigurationColumns { joint_names: vec!["j".into()], values: vec![half_pi] }),
        ..Default::default()
    };
    tx.send(pb::QueryRequest {
        poses: vec![pb::InstancePose { instance_id: obstacle.clone(), pose: Some(at(c45, c45)) }],
        robot_states: Some(arm_states(&[0.0])),
        robot_motions: Some(motion.clone()),
        ..Default::default()
    })
    .await
    .unwrap();
    let r = answers.message().await.unwrap().unwrap();
    let states = r.robot_states.unwrap();
    let expected = (std::f64::consts::PI / 8.0).sin() - 0.3;
    assert!((states.distance[0] - expected).abs() < 1e-9, "{} vs {expected}", states.distance[0]);
    let motions = r.robot_motions.unwrap();
    let t_star = (std::f64::consts::FRAC_PI_4 - 2.0 * 0.3f64.asin()) / half_pi;
    assert!(!motions.valid[0] && motions.decided[0]);
    // Reported no later than t*, and within the 1 mm tolerance of it (the ball moves at most
    // 0.6 · π/2 m per unit of t).
    let t = motions.contact_t[0];
    assert!(t <= t_star + 1e-12 && t >= t_star - 1e-3 / (0.6 * half_pi) - 1e-9, "{t} vs {t_star}");

    // Stopping at the first collision: j = π/4 touches the obstacle, so j = π/2 is not checked.
    let quarter = std::f64::consts::FRAC_PI_4;
    for stop in [true, false] {
        let states =
            pb::CheckConfigurationsRequest { stop_at_first_collision: stop, ..arm_states(&[0.0, quarter, half_pi]) };
        tx.send(pb::QueryRequest { robot_states: Some(states), ..Default::default() }).await.unwrap();
        let r = answers.message().await.unwrap().unwrap().robot_states.unwrap();
        let expected: &[bool] = if stop { &[false, true] } else { &[false, true, false] };
        assert_eq!((r.count as usize, r.collides.as_slice()), (expected.len(), expected));
    }

    // Errors name their fields, prefixed: another scene, an unknown joint.
    let mut other = arm_states(&[0.0]);
    other.scene_id = "s-0000000000000000".into();
    tx.send(pb::QueryRequest { robot_states: Some(other), ..Default::default() }).await.unwrap();
    assert_status(answers.message().await, Code::InvalidArgument, "robot_states.scene_id");

    // The stored scene never saw the stream's pose: a unary Query and CheckScene answer 0.7 m.
    let req =
        pb::QueryRequest { scene_id: scene_id.clone(), robot_states: Some(arm_states(&[0.0])), ..Default::default() };
    let r = c.query(req).await.unwrap().into_inner().robot_states.unwrap();
    assert!((r.distance[0] - 0.7).abs() < 1e-9);
    let mut bad = arm_states(&[0.0]);
    bad.configurations.as_mut().unwrap().joint_names[0] = "k".into();
    let req = pb::QueryRequest { scene_id: scene_id.clone(), robot_states: Some(bad), ..Default::default() };
    assert_status(c.query(req).await, Code::InvalidArgument, "robot_states.configurations.joint_names[0]");
    let robot = check_scene_robot(&mut c, &scene_id).await;
    assert!((robot.distance[0] - 0.7).abs() < 1e-9);
    server.stop().await;
}
