//! Integration tests: robots over gRPC. The fitted Panda (`data/robots/panda/panda.robot.json`)
//! uploaded, a MotionBenchMaker scene imported (its allowed-collision matrix and robot state kept
//! with it), and the scene's labelled configurations checked by `CheckConfigurations` against the
//! mesh-exact labels (`data/robots/mbm_panda/labels_obj.csv`, pinocchio + coal on the collision
//! meshes): the same verdicts, distances within 10 µm of coal's and never above them; the answers
//! equal the in-process checker's bit for bit. `CheckMotions` on the scene's start–goal request
//! agrees with the labels along that line and with the in-process motion checker. Errors name
//! their fields; robots and planning contexts survive a restart.

use crate::util::{assert_status, config, Server};
use std::path::PathBuf;
use sublevel::robot::{CheckOptions, FittedRobot, MotionChecker, MotionOptions, RobotChecker};
use sublevel::scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots").join(path)
}

/// The labelled configurations of one scene: (kind, q, collides, min world distance).
fn labels(scenario: &str, scene: u32) -> Vec<(String, Vec<f64>, bool, f64)> {
    let text = std::fs::read_to_string(data("mbm_panda/labels_obj.csv")).unwrap();
    text.lines()
        .skip(1)
        .filter_map(|line| {
            let c: Vec<&str> = line.split(',').collect();
            (c[0] == scenario && c[1].parse::<u32>().unwrap() == scene).then(|| {
                let q = c[4..11].iter().map(|v| v.parse().unwrap()).collect();
                (c[3].to_owned(), q, c[11] == "1", c[14].parse().unwrap_or(f64::INFINITY))
            })
        })
        .collect()
}

async fn upload_panda(c: &mut SublevelClient<Channel>) -> pb::RobotSummary {
    let bytes = std::fs::read(data("panda/panda.robot.json")).unwrap();
    let req = pb::UploadRobotRequest { name: "panda".into(), robot_file: bytes };
    c.upload_robot(req).await.unwrap().into_inner().robot.unwrap()
}

async fn import(c: &mut SublevelClient<Channel>, yaml: &[u8]) -> String {
    let req = pb::ImportSceneRequest {
        name: String::new(),
        scene: Some(pb::import_scene_request::Scene::Yaml(yaml.to_vec())),
        ..Default::default()
    };
    c.import_scene(req).await.unwrap().into_inner().scene_id
}

fn columns(names: &[&str], rows: &[Vec<f64>]) -> Option<pb::ConfigurationColumns> {
    Some(pb::ConfigurationColumns {
        joint_names: names.iter().map(|s| (*s).to_owned()).collect(),
        values: rows.iter().flatten().copied().collect(),
    })
}

const JOINTS: [&str; 7] =
    ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5", "panda_joint6", "panda_joint7"];

#[tokio::test]
async fn configurations_and_motions_over_grpc_agree_with_the_mesh_labels_and_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let summary = upload_panda(&mut c).await;
    let robot = FittedRobot::load(&data("panda/panda.robot.json")).unwrap();
    assert_eq!(summary.joint_names, robot.model.variable_names());
    for k in 0..robot.model.dof() {
        let (lo, hi) = robot.model.variable_joint(k).limits.unwrap();
        assert_eq!((summary.lower[k], summary.upper[k]), (lo, hi));
    }
    assert_eq!(summary.geometries as usize, robot.geometries.len());
    assert_eq!(summary.self_pairs, 21);

    let yaml = std::fs::read(data("mbm_panda/scenes/bookshelf_small/scene0001.yaml")).unwrap();
    let scene_id = import(&mut c, &yaml).await;
    let rows = labels("bookshelf_small", 1);
    assert_eq!(rows.len(), 200);
    let q: Vec<Vec<f64>> = rows.iter().map(|r| r.1.clone()).collect();
    let req = pb::CheckConfigurationsRequest {
        robot_id: summary.robot_id.clone(),
        scene_id: scene_id.clone(),
        configurations: columns(&JOINTS, &q),
        distance: true,
        ..Default::default()
    };
    let got = c.check_configurations(req).await.unwrap().into_inner();
    assert_eq!(got.count, 200);
    assert_eq!(got.witnesses.len(), 6 * 200);

    // The in-process checker on the parsed scene, as `sublevel robot check` runs it.
    let scene = PlanningScene::from_yaml(&yaml).unwrap();
    let (world, _) = world_objects(&scene).unwrap();
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(&robot, world, &allowed).unwrap();
    let base = sublevel::math::Isometry3::identity();
    let (mut colliding, mut free) = (0, 0);
    for (i, (_, q, collides, label_distance)) in rows.iter().enumerate() {
        let a = checker.check(q, &base, &CheckOptions::default()).unwrap();
        assert_eq!(got.collides[i], a.collides, "configuration {i}");
        assert_eq!(got.distance[i].to_bits(), a.distance.to_bits(), "configuration {i}");
        // Against coal on the meshes: the same verdict; free distances within 10 µm, never above.
        assert_eq!(got.collides[i], *collides, "configuration {i} against the label");
        assert!(got.converged[i]);
        if *collides {
            colliding += 1;
            assert!(!got.robot_link[i].is_empty() || !got.self_link_a[i].is_empty(), "configuration {i}");
        } else if got.distance[i].is_finite() && label_distance.is_finite() {
            free += 1;
            assert!((got.distance[i] - label_distance).abs() <= 1e-5, "{i}: {} vs {label_distance}", got.distance[i]);
            // The witness points are that far apart.
            let w = &got.witnesses[6 * i..6 * i + 6];
            let gap = ((w[0] - w[3]).powi(2) + (w[1] - w[4]).powi(2) + (w[2] - w[5]).powi(2)).sqrt();
            assert!((gap - got.distance[i]).abs() <= 1e-9, "{i}: witnesses {gap} vs {}", got.distance[i]);
            assert!(!got.world_object[i].is_empty() && got.robot_link[i].starts_with("panda_"));
        }
    }
    assert!(colliding > 10 && free > 100, "{colliding} colliding, {free} free");

    // A grasped ball on the hand: the answers of the library's `attach`, bit for bit.
    let ball = pb::AttachedObject {
        link: "panda_hand".into(),
        name: "ball".into(),
        primitive: Some(pb::Primitive { kind: pb::PrimitiveKind::Sphere as i32, radius: 0.05, ..Default::default() }),
        origin: Some(crate::util::at([0.0, 0.0, 0.15])),
    };
    let req = pb::CheckConfigurationsRequest {
        robot_id: summary.robot_id.clone(),
        scene_id: scene_id.clone(),
        configurations: columns(&JOINTS, &q),
        distance: true,
        attached: vec![ball],
        ..Default::default()
    };
    let held = c.check_configurations(req).await.unwrap().into_inner();
    let mut holding = robot.clone();
    holding
        .attach(
            "panda_hand",
            "ball",
            sublevel::Primitive::Sphere { radius: 0.05 },
            sublevel::math::Isometry3::translation(0.0, 0.0, 0.15),
        )
        .unwrap();
    let (world_objects_again, _) = world_objects(&scene).unwrap();
    let mut with_ball = RobotChecker::new(&holding, world_objects_again, &allowed).unwrap();
    let mut touched = 0;
    for (i, q) in q.iter().enumerate() {
        let a = with_ball.check(q, &base, &CheckOptions::default()).unwrap();
        assert_eq!((held.collides[i], held.distance[i].to_bits()), (a.collides, a.distance.to_bits()), "{i}");
        assert!(held.distance[i] <= got.distance[i], "{i}: holding more cannot be farther");
        touched += usize::from(held.robot_geometry[i] == "ball");
    }
    assert!(touched > 0, "the ball is the closest geometry somewhere");

    // The start–goal motion of the scene's request: invalid exactly when a labelled configuration
    // on its line collides, as the in-process motion checker answers.
    let request = MotionPlanRequest::from_yaml(
        &std::fs::read(data("mbm_panda/requests/bookshelf_small/request0001.yaml")).unwrap(),
    )
    .unwrap();
    let pick = |joints: &[(String, f64)]| -> Vec<f64> {
        JOINTS.iter().map(|j| joints.iter().find(|(n, _)| n == j).unwrap().1).collect()
    };
    let (q0, q1) = (pick(&request.start), pick(&request.goal));
    let req = pb::CheckMotionsRequest {
        robot_id: summary.robot_id.clone(),
        scene_id: scene_id.clone(),
        start: columns(&JOINTS, std::slice::from_ref(&q0)),
        end: columns(&JOINTS, std::slice::from_ref(&q1)),
        ..Default::default()
    };
    let m = c.check_motions(req).await.unwrap().into_inner();
    let mut motion = MotionChecker::new(&mut checker).unwrap();
    let local = motion.check_motion(&q0, &q1, &base, &MotionOptions::default()).unwrap();
    assert_eq!((m.valid[0], m.decided[0], m.steps[0] as usize), (local.valid, local.decided, local.steps));
    let line_collides = rows.iter().any(|r| r.0 == "line" && r.2);
    assert!(m.decided[0]);
    assert_eq!(m.valid[0], !line_collides);
    if !m.valid[0] {
        assert_eq!(m.contact_t[0].to_bits(), local.contact.unwrap().to_bits());
        assert!(m.contact_t[0] > 0.0 && m.contact_t[0] <= 1.0);
        assert_eq!(m.contact_configuration.len(), 7);
    }
    server.stop().await;
}

#[tokio::test]
async fn robot_requests_name_their_fields_and_robots_survive_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let robot_id = upload_panda(&mut c).await.robot_id;
    let yaml = std::fs::read(data("mbm_panda/scenes/table_pick/scene0001.yaml")).unwrap();
    let scene_id = import(&mut c, &yaml).await;
    let zero = vec![vec![0.0; 7]];
    let check = |names: &[&str], rows: &[Vec<f64>]| pb::CheckConfigurationsRequest {
        robot_id: robot_id.clone(),
        scene_id: scene_id.clone(),
        configurations: columns(names, rows),
        ..Default::default()
    };

    assert_status(
        c.upload_robot(pb::UploadRobotRequest { name: String::new(), robot_file: b"{}".to_vec() }).await,
        Code::InvalidArgument,
        "robot_file",
    );
    let mut broken: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("panda/panda.robot.json")).unwrap()).unwrap();
    broken["geometries"][0]["link"] = "no_such_link".into();
    assert_status(
        c.upload_robot(pb::UploadRobotRequest { name: String::new(), robot_file: broken.to_string().into_bytes() })
            .await,
        Code::InvalidArgument,
        "robot_file.geometries[0].link",
    );
    // A mesh vertex outside its root body would make the sos bound unsound: refused.
    let mut outside: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data("panda/panda.robot.json")).unwrap()).unwrap();
    let k = outside["geometries"].as_array().unwrap().iter().position(|g| g.get("mesh").is_some()).unwrap();
    outside["geometries"][k]["mesh"]["vertices"][0] = serde_json::json!([3.0, 3.0, 3.0]);
    assert_status(
        c.upload_robot(pb::UploadRobotRequest { name: String::new(), robot_file: outside.to_string().into_bytes() })
            .await,
        Code::InvalidArgument,
        &format!("robot_file.geometries[{k}].compound.nodes["),
    );
    let mut req = check(&JOINTS, &zero);
    req.robot_id = "r-0000000000000000".into();
    assert_status(c.check_configurations(req).await, Code::NotFound, "robot");
    assert_status(
        c.check_configurations(check(&["elbow"], &[vec![0.0]])).await,
        Code::InvalidArgument,
        "configurations.joint_names[0]",
    );
    assert_status(
        c.check_configurations(check(&JOINTS, &[vec![0.0; 6]])).await,
        Code::InvalidArgument,
        "configurations.values",
    );
    assert_status(
        c.check_configurations(check(&JOINTS, &[vec![0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]])).await,
        Code::InvalidArgument,
        "configurations.values[2]",
    );
    let mut req = check(&JOINTS, &zero);
    req.attached = vec![pb::AttachedObject {
        link: "panda_tail".into(),
        name: "x".into(),
        primitive: Some(pb::Primitive { kind: pb::PrimitiveKind::Sphere as i32, radius: 0.1, ..Default::default() }),
        origin: None,
    }];
    assert_status(c.check_configurations(req).await, Code::InvalidArgument, "attached[0].link");
    let mut req = check(&JOINTS, &zero);
    req.padding = -1.0;
    assert_status(c.check_configurations(req).await, Code::InvalidArgument, "padding");
    let req = pb::CheckMotionsRequest {
        robot_id: robot_id.clone(),
        scene_id: scene_id.clone(),
        start: columns(&JOINTS, &zero),
        end: columns(&JOINTS, &[vec![0.0; 7], vec![0.0; 7]]),
        ..Default::default()
    };
    assert_status(c.check_motions(req).await, Code::InvalidArgument, "end.values");
    // A scene holding a fitted body is not a robot's world.
    let fitted = c.create_scene(pb::CreateSceneRequest { name: "fitted".into() }).await.unwrap().into_inner().scene_id;
    let sphere = crate::util::upload_sphere(&mut c, "ball", [0.0; 3], 0.1).await;
    crate::util::add(&mut c, &fitted, &sphere, crate::util::at([2.0, 0.0, 0.0])).await;
    let mut req = check(&JOINTS, &zero);
    req.scene_id = fitted;
    assert_status(c.check_configurations(req).await, Code::FailedPrecondition, "fitted body");

    // Joints left out take the scene's robot state: joint 7 alone given, the rest from the YAML.
    let scene = PlanningScene::from_yaml(&yaml).unwrap();
    let state: Vec<f64> =
        JOINTS.iter().map(|j| scene.joint_positions.iter().find(|(n, _)| n == j).map_or(0.0, |p| p.1)).collect();
    let partial = c.check_configurations(check(&["panda_joint7"], &[vec![state[6]]])).await.unwrap().into_inner();
    let full = c
        .check_configurations(pb::CheckConfigurationsRequest {
            distance: true,
            ..check(&JOINTS, std::slice::from_ref(&state))
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(partial.collides, full.collides);
    server.stop().await;

    // A restart finds the robot and the scene's planning context (names, matrix, state).
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let listed = c.list_robots(pb::ListRobotsRequest {}).await.unwrap().into_inner().robots;
    assert_eq!(listed.iter().map(|r| r.robot_id.as_str()).collect::<Vec<_>>(), [robot_id.as_str()]);
    let again = c
        .check_configurations(pb::CheckConfigurationsRequest { distance: true, ..check(&JOINTS, &[state]) })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(again.distance[0].to_bits(), full.distance[0].to_bits());
    assert_eq!(again.world_object, full.world_object);
    c.delete_robot(pb::DeleteRobotRequest { robot_id: robot_id.clone() }).await.unwrap();
    assert_status(c.get_robot(pb::GetRobotRequest { robot_id }).await, Code::NotFound, "robot");
    server.stop().await;
}

/// A robot of two cube meshes (one as `package://`, one relative to the URDF) and a URDF box on a
/// prismatic joint; the SRDF allows base–tip.
const SLIDER_URDF: &str = r#"<robot name="slider">
  <link name="base"><collision><geometry><mesh filename="package://parts/meshes/cube.obj" scale="0.2 0.2 0.2"/></geometry></collision></link>
  <link name="arm"><collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision></link>
  <link name="tip"><collision><geometry><mesh filename="meshes/tip.obj" scale="0.1 0.1 0.1"/></geometry></collision></link>
  <joint name="slide" type="prismatic"><parent link="base"/><child link="arm"/><origin xyz="0.5 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="turn" type="revolute"><parent link="arm"/><child link="tip"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 0 1"/><limit lower="-3.2" upper="3.2" effort="1" velocity="1"/></joint>
</robot>"#;

const SLIDER_SRDF: &str =
    r#"<robot name="slider"><disable_collisions link1="base" link2="tip" reason="Never"/></robot>"#;

/// The unit cube [−0.5, 0.5]³ (OBJ quads).
const CUBE: &str = "v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\n\
v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

#[tokio::test]
async fn a_robot_fit_job_stores_a_robot_whose_checks_meet_the_closed_forms() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let meshes: std::collections::HashMap<String, Vec<u8>> = [
        ("package://parts/meshes/cube.obj".to_owned(), CUBE.as_bytes().to_vec()),
        ("meshes/tip.obj".to_owned(), CUBE.as_bytes().to_vec()),
    ]
    .into();
    let request = |meshes: std::collections::HashMap<String, Vec<u8>>| pb::StartRobotFitJobRequest {
        name: String::new(),
        urdf: SLIDER_URDF.into(),
        srdf: SLIDER_SRDF.into(),
        meshes,
        tolerance: 0.2,
        max_parts: 2,
        leaves: false,
    };
    // Validated before a job exists: a missing mesh, an unsafe name, malformed SRDF XML.
    let mut missing = meshes.clone();
    missing.remove("meshes/tip.obj");
    assert_status(c.start_robot_fit_job(request(missing)).await, Code::InvalidArgument, "meshes[meshes/tip.obj]");
    let mut unsafe_name = meshes.clone();
    unsafe_name.insert("../escape.obj".into(), CUBE.as_bytes().to_vec());
    assert_status(c.start_robot_fit_job(request(unsafe_name)).await, Code::InvalidArgument, "meshes[../escape.obj]");
    let mut bad = request(meshes.clone());
    bad.srdf = r#"<robot name="slider"><disable_collisions link1="base"/></robot>"#.into();
    assert_status(c.start_robot_fit_job(bad).await, Code::InvalidArgument, "srdf.disable_collisions[0]");

    let job_id = c.start_robot_fit_job(request(meshes)).await.unwrap().into_inner().job_id;
    let updates = crate::util::watch_to_end(&mut c, job_id.clone()).await;
    let last = updates.last().unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    assert!(last.body_id.is_empty() && last.robot_id.starts_with("r-"), "{last:?}");
    assert!(updates.iter().any(|u| u.message.contains("[2/2]")), "progress per mesh: {updates:?}");
    let job = c.get_fit_job(pb::GetFitJobRequest { job_id }).await.unwrap().into_inner().job.unwrap();
    assert_eq!((job.kind.as_str(), job.robot_id.as_str()), ("robot", last.robot_id.as_str()));
    let robot = c.get_robot(pb::GetRobotRequest { robot_id: last.robot_id.clone() }).await.unwrap().into_inner();
    let robot = robot.robot.unwrap();
    assert_eq!((robot.name.as_str(), robot.joint_names.clone()), ("slider", vec!["slide".to_owned(), "turn".into()]));
    assert_eq!((robot.lower.clone(), robot.upper.clone()), (vec![-1.0, -3.2], vec![1.0, 3.2]));
    // base–arm and arm–tip are checked; base–tip is allowed by the SRDF.
    assert_eq!((robot.geometries, robot.self_pairs), (3, 2));

    // A box of half side 0.1 at (1.2, 0, 0): the arm (half side 0.1 at x = 0.5 + slide) is
    // 0.5 − slide away, the base cube (half side 0.1) 0.9 away, the tip above the arm.
    let scene = c.create_scene(pb::CreateSceneRequest { name: "wall".into() }).await.unwrap().into_inner().scene_id;
    let wall = c
        .upload_body(pb::UploadBodyRequest {
            name: "wall".into(),
            body: Some(pb::upload_body_request::Body::Primitive(pb::Primitive {
                kind: pb::PrimitiveKind::Box as i32,
                size: vec![0.2, 0.2, 0.2],
                ..Default::default()
            })),
        })
        .await
        .unwrap()
        .into_inner()
        .body_id;
    crate::util::add(&mut c, &scene, &wall, crate::util::at([1.2, 0.0, 0.0])).await;
    let slides = [-0.2, 0.0, 0.3, 0.45, 0.55];
    let answer = c
        .check_configurations(pb::CheckConfigurationsRequest {
            robot_id: robot.robot_id.clone(),
            scene_id: scene.clone(),
            configurations: columns(&["slide"], &slides.iter().map(|&s| vec![s]).collect::<Vec<_>>()),
            distance: true,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    for (i, &s) in slides.iter().enumerate() {
        let exact = (0.5 - s).max(0.0);
        assert_eq!(answer.collides[i], s >= 0.5, "slide {s}");
        assert!((answer.distance[i] - exact).abs() <= 1e-9, "slide {s}: {} vs {exact}", answer.distance[i]);
        if s < 0.5 {
            assert_eq!(answer.robot_link[i], "arm");
        }
    }
    server.stop().await;
}
