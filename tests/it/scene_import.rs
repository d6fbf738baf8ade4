//! Integration tests: `ImportScene` and `sublevel scene import`. One MotionBenchMaker Panda scene
//! of every scenario (`data/robots/mbm_panda/problems.tar.bz2`, as `sublevel_scene::moveit`'s
//! tests read it) imported over gRPC: as many instances as the YAML has
//! primitives, and CheckScene / Distance answers equal to `shape_distance` on the parsed shapes;
//! planes, meshes, JSON, bad scenes and limits; the command line.

use crate::util::{assert_status, config, Server};
use std::collections::BTreeSet;
use sublevel::query::shape::{shape_distance, ShapeRef};
use sublevel::scene::moveit::{PlanningScene, Shape};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::ServerConfig;
use sublevel_core::primitive::{Primitive, PrimitiveFile};
use tonic::transport::Channel;
use tonic::Code;

/// The first scene (`scene0001.yaml`) of every MotionBenchMaker Panda scenario, unpacked from the
/// archive into `dir`: (scenario, YAML text).
fn motionbenchmaker_scenes(dir: &std::path::Path) -> Vec<(String, String)> {
    let archive = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/robots/mbm_panda/problems.tar.bz2");
    let status = std::process::Command::new("tar").arg("xjf").arg(&archive).arg("-C").arg(dir).status().unwrap();
    assert!(status.success());
    let mut scenes: Vec<(String, String)> = std::fs::read_dir(dir.join("problems"))
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read_to_string(path.join("scene0001.yaml")).unwrap())
        })
        .collect();
    scenes.sort();
    scenes
}

/// The exact primitive of a parsed MoveIt shape (boxes, spheres and cylinders only).
fn primitive_of(shape: &Shape) -> Primitive {
    let file = match shape {
        Shape::Box { size } => PrimitiveFile::Box { size: *size },
        Shape::Sphere { radius } => PrimitiveFile::Sphere { radius: *radius },
        Shape::Cylinder { height, radius } => PrimitiveFile::Cylinder { radius: *radius, height: *height },
        other => panic!("unexpected shape {other:?}"),
    };
    Primitive::from_file(&file).unwrap()
}

/// Lines whose key is `type:` (a primitive), as the parser's own test counts them.
fn primitive_count(text: &str) -> usize {
    text.lines().map(str::trim_start).filter(|l| l.strip_prefix("- ").unwrap_or(l).starts_with("type:")).count()
}

async fn import(c: &mut SublevelClient<Channel>, yaml: &str) -> pb::ImportSceneResponse {
    let req = pb::ImportSceneRequest {
        name: String::new(),
        scene: Some(pb::import_scene_request::Scene::Yaml(yaml.as_bytes().to_vec())),
        ..Default::default()
    };
    c.import_scene(req).await.unwrap().into_inner()
}

/// Every scenario's first scene: one instance per primitive (named by object id), the ACM and the
/// robot state echoed; CheckScene at 2 cm reports exactly the pairs that `shape_distance` puts
/// within 2 cm on the parsed shapes, and Distance between two boxes is `shape_distance`'s.
#[tokio::test]
async fn motionbenchmaker_scenes_import_and_answer_as_their_parsed_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(&dir.path().join("data"))).await;
    let mut c = server.client().await;
    let scenes = motionbenchmaker_scenes(dir.path());
    assert_eq!(scenes.len(), 7);
    let mut close_pairs = 0;
    for (scenario, yaml) in &scenes {
        let parsed = PlanningScene::from_yaml(yaml.as_bytes()).unwrap();
        let r = import(&mut c, yaml).await;
        assert_eq!(r.instances.len(), primitive_count(yaml), "{scenario}");
        assert_eq!((r.objects as usize, r.skipped.len()), (parsed.objects.len(), 0), "{scenario}");
        assert!(r.bodies as usize <= r.instances.len());
        assert_eq!(r.allowed_collision.as_ref().map(|a| a.names.len()), Some(11), "{scenario}");
        assert_eq!(r.joint_positions.len(), 9, "{scenario}");
        let view = c.get_scene(pb::GetSceneRequest { scene_id: r.scene_id.clone() }).await.unwrap().into_inner();
        assert_eq!(view.instances.len(), r.instances.len());

        // The parsed shapes by instance name (object id, `#k` when an object has several).
        let mut shapes = Vec::new();
        for o in &parsed.objects {
            for (k, s) in o.shapes.iter().enumerate() {
                let name = if o.shapes.len() > 1 { format!("{}#{k}", o.id) } else { o.id.clone() };
                shapes.push((name, primitive_of(&s.shape), s.pose));
            }
        }
        let names: Vec<&str> = r.instances.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(names, shapes.iter().map(|s| s.0.as_str()).collect::<Vec<_>>(), "{scenario}");

        let margin = 0.02;
        let mut want = BTreeSet::new();
        for i in 0..shapes.len() {
            for j in i + 1..shapes.len() {
                let (a, b) = (&shapes[i], &shapes[j]);
                let d = shape_distance(ShapeRef::Primitive(&a.1), &a.2, ShapeRef::Primitive(&b.1), &b.2, None).unwrap();
                if d.overlapping || d.distance < margin {
                    want.insert((a.0.clone().min(b.0.clone()), a.0.clone().max(b.0.clone())));
                }
            }
        }
        let check = pb::CheckSceneRequest { scene_id: r.scene_id.clone(), margin, ..Default::default() };
        let found = c.check_scene(check).await.unwrap().into_inner();
        let name_of = |id: &str| r.instances.iter().find(|i| i.instance_id == id).unwrap().name.clone();
        let got: BTreeSet<(String, String)> = found
            .pairs
            .iter()
            .map(|p| {
                let (x, y) = (name_of(&p.first), name_of(&p.second));
                (x.clone().min(y.clone()), x.max(y))
            })
            .collect();
        assert_eq!(got, want, "{scenario}");
        close_pairs += got.len();
        assert!(found.pairs.iter().all(|p| p.distance.as_ref().unwrap().solve.as_ref().unwrap().converged));

        // Distance between the first two boxes: shape_distance's answer.
        let boxes: Vec<usize> = (0..shapes.len()).filter(|k| r.instances[*k].kind == "box").take(2).collect();
        if let [i, j] = boxes[..] {
            let req = pb::DistanceRequest {
                scene_id: r.scene_id.clone(),
                instance_a: r.instances[i].instance_id.clone(),
                instance_b: r.instances[j].instance_id.clone(),
                ..Default::default()
            };
            let got = c.distance(req).await.unwrap().into_inner().answer.unwrap();
            let (a, b) = (&shapes[i], &shapes[j]);
            let d = shape_distance(ShapeRef::Primitive(&a.1), &a.2, ShapeRef::Primitive(&b.1), &b.2, None).unwrap();
            assert!((got.distance - d.distance).abs() < 1e-9, "{scenario}: {} vs {}", got.distance, d.distance);
        }
    }
    assert!(close_pairs >= 7, "the scenes' shelves, walls and tables touch: {close_pairs} pairs");
    server.stop().await;
}

/// A scene in JSON with a plane (a floor 0.1 m below its object's frame), a cone and a mesh: the
/// plane is the halfspace under it, the cone its cylinder with a note, the mesh skipped with its
/// reason (`skip_meshes`); a bad scene names its field, an empty request names `scene`, and a scene over the
/// instance limit is refused with nothing written.
#[tokio::test]
async fn planes_cones_meshes_json_errors_and_limits() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(ServerConfig { max_instances_per_scene: 3, ..config(dir.path()) }).await;
    let mut c = server.client().await;
    let json = r#"{"name": "room", "world": {"collision_objects": [
        {"id": "floor", "header": {"frame_id": "world"}, "pose": {"position": [0, 0, -0.1]},
         "planes": [{"coef": [0, 0, 1, 0]}], "plane_poses": [{}]},
        {"id": "funnel", "primitives": [{"type": "cone", "dimensions": [0.4, 0.1]}],
         "primitive_poses": [{"position": [0, 0, 0.5]}],
         "meshes": [{"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "triangles": [{"vertex_indices": [0, 1, 2]}]}],
         "mesh_poses": [{"position": [2, 0, 0]}]}]}}"#;
    let req = pb::ImportSceneRequest {
        name: "mine".into(),
        scene: Some(pb::import_scene_request::Scene::Json(json.as_bytes().to_vec())),
        skip_meshes: true,
        ..Default::default()
    };
    let r = c.import_scene(req).await.unwrap().into_inner();
    assert_eq!(r.name, "mine");
    let kinds: Vec<(&str, &str)> = r.instances.iter().map(|i| (i.name.as_str(), i.kind.as_str())).collect();
    assert_eq!(kinds, [("floor", "halfspace"), ("funnel#0", "cylinder")]);
    assert!(r.instances[1].note.contains("cone"));
    assert_eq!(r.instances[0].frame_id, "world");
    assert_eq!((r.skipped.len(), r.meshes.len()), (1, 0));
    assert_eq!(
        (r.skipped[0].object_id.as_str(), r.skipped[0].shape_index, r.skipped[0].kind.as_str()),
        ("funnel", 1, "mesh")
    );
    assert!(r.skipped[0].reason.contains("StartFitJob"));
    // The cylinder (height 0.4 at z = 0.5: bottom at 0.3) over the floor at z = −0.1.
    let req = pb::DistanceRequest {
        scene_id: r.scene_id.clone(),
        instance_a: r.instances[0].instance_id.clone(),
        instance_b: r.instances[1].instance_id.clone(),
        ..Default::default()
    };
    let d = c.distance(req).await.unwrap().into_inner().answer.unwrap();
    assert!((d.distance - 0.4).abs() < 1e-12, "{}", d.distance);

    let bad = "world:\n  collision_objects:\n    - id: o\n      primitives: [{type: box, dimensions: [1, 2]}]\n      primitive_poses: [{}]\n";
    let req =
        pb::ImportSceneRequest { scene: Some(pb::import_scene_request::Scene::Yaml(bad.into())), ..Default::default() };
    assert_status(
        c.import_scene(req).await,
        Code::InvalidArgument,
        "yaml.world.collision_objects[0].primitives[0].dimensions",
    );
    assert_status(c.import_scene(pb::ImportSceneRequest::default()).await, Code::InvalidArgument, "scene");
    let many = "world:\n  collision_objects:\n    - id: o\n      primitives: [{type: sphere, dimensions: [1]}, {type: sphere, dimensions: [1]}, {type: sphere, dimensions: [1]}, {type: sphere, dimensions: [1]}]\n      primitive_poses: [{}, {}, {}, {}]\n";
    let req = pb::ImportSceneRequest {
        scene: Some(pb::import_scene_request::Scene::Yaml(many.into())),
        ..Default::default()
    };
    assert_status(c.import_scene(req).await, Code::ResourceExhausted, "--max-instances-per-scene");
    let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes;
    assert_eq!(scenes.len(), 1, "a refused import writes nothing");
    server.stop().await;
}

/// The box mesh scene of the tests' data (`tests/data/box_mesh.scene.yaml`): a closed box mesh
/// 0.2 × 0.1 × 0.3 m, composed to span [1, 1.3] × [2.0, 2.2] × [0.65, 0.75] m, and a ball of
/// radius 0.05 m at (1.5, 2.4, 0.9).
fn box_mesh_scene() -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/box_mesh.scene.yaml");
    std::fs::read_to_string(path).unwrap()
}

/// Leaf-excess tolerance of the box mesh's fit in these tests, meters.
const BOX_TOLERANCE: f64 = 0.02;

/// The exact distance between the box mesh and the ball: from the ball's center to the box
/// [1, 1.3] × [2.0, 2.2] × [0.65, 0.75], (0.2, 0.2, 0.15) away, less the radius.
fn box_ball_distance() -> f64 {
    (0.2f64 * 0.2 + 0.2 * 0.2 + 0.15 * 0.15).sqrt() - 0.05
}

/// A planning scene's mesh is fitted by a compound fit job: the answer lists the mesh with its
/// job and composed pose, the ball is imported at once; when the job ends the scene holds an
/// instance named `crate` at the composed pose (its planning name kept, read back from the store
/// after a restart), GetBody reports the mesh kept with the body (and the store holds its
/// vertices as written), and the distance to the ball lies within the body's max leaf excess below
/// the exact one; robot configurations checked against the scene answer as the closed form of
/// a ball against the box. A scene deleted before its mesh's job ends: the job succeeds, the body stored,
/// the message saying the instance was not added. A bad `mesh_tolerance` is refused.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mesh_is_fitted_and_placed_at_its_composed_pose() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let server = Server::start(config(&data)).await;
    let mut c = server.client().await;
    let yaml = box_mesh_scene();
    let request = |tolerance: f64| pb::ImportSceneRequest {
        scene: Some(pb::import_scene_request::Scene::Yaml(yaml.clone().into_bytes())),
        mesh_tolerance: tolerance,
        ..Default::default()
    };
    assert_status(c.import_scene(request(-1.0)).await, Code::InvalidArgument, "mesh_tolerance");
    assert_status(c.import_scene(request(f64::NAN)).await, Code::InvalidArgument, "mesh_tolerance");
    let started = std::time::Instant::now();
    let r = c.import_scene(request(BOX_TOLERANCE)).await.unwrap().into_inner();
    assert!(r.skipped.is_empty(), "{:?}", r.skipped);
    assert_eq!(r.instances.iter().map(|i| i.name.as_str()).collect::<Vec<_>>(), ["ball"]);
    assert_eq!(r.meshes.len(), 1);
    let m = &r.meshes[0];
    assert_eq!((m.name.as_str(), m.object_id.as_str(), m.shape_index), ("crate", "crate", 0));
    assert_eq!((m.vertices, m.triangles, m.frame_id.as_str()), (8, 12, "world"));
    let p = m.pose.as_ref().unwrap();
    let (t, q) = (p.translation.as_ref().unwrap(), p.rotation.as_ref().unwrap());
    // t_o + R_o t_m = (1, 2, 0.5) + (0, 0.1, 0.2); q_o ⊗ q_m = (½, ½, ½, ½) (tests/data).
    assert!((t.x - 1.0).abs() < 1e-15 && (t.y - 2.1).abs() < 1e-15 && (t.z - 0.7).abs() < 1e-15, "{t:?}");
    assert!([q.w, q.x, q.y, q.z].iter().all(|v| (v - 0.5).abs() < 1e-15), "{q:?}");

    let updates = crate::util::watch_to_end(&mut c, m.job_id.clone()).await;
    let last = updates.last().unwrap().clone();
    eprintln!("box mesh fit: {:.1} s, {}", started.elapsed().as_secs_f64(), last.message);
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    assert!(last.message.contains("`crate` added to scene"), "{}", last.message);
    let job = c.get_fit_job(pb::GetFitJobRequest { job_id: m.job_id.clone() }).await.unwrap().into_inner().job.unwrap();
    assert_eq!((job.body_id.as_str(), job.name.as_str()), (last.body_id.as_str(), "crate"));

    let view = c.get_scene(pb::GetSceneRequest { scene_id: r.scene_id.clone() }).await.unwrap().into_inner();
    assert_eq!(view.instances.len(), 2);
    let placed = view.instances.iter().find(|i| i.body_id == last.body_id).expect("the mesh's instance");
    let pose = placed.pose.as_ref().unwrap();
    assert_eq!(pose.translation, p.translation);
    assert!((pose.rotation.as_ref().unwrap().w - 0.5).abs() < 1e-15);
    let body = c.get_body(pb::GetBodyRequest { body_id: last.body_id.clone() }).await.unwrap().into_inner();
    assert_eq!((body.mesh_vertices, body.mesh_triangles), (8, 12));
    // The max leaf excess: the stored tree's, or for a body of one node (stored as a single
    // body, its excess not kept) the job message's, rounded up from its 4 decimals.
    let tree = sublevel::compound::CompoundBody::from_json(&body.body_json).unwrap();
    let said: f64 = last.message.split("max leaf excess ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap();
    let excess = if tree.node_count() > 1 { tree.max_leaf_excess() } else { said + 5e-5 };
    assert!((excess - said).abs() <= 5e-5 + 1e-12, "{excess} vs the message's {said}");
    // The tolerance is a target (a convex box decomposes into one part): the excess is small
    // against the box, not necessarily below it.
    assert!(excess > 0.0 && excess < 0.1, "max leaf excess {excess}");

    // The fitted body contains the mesh: its distance to the ball is at most the exact one, and
    // at least the exact one less the excess.
    let ball = &r.instances[0].instance_id;
    let exact = box_ball_distance();
    let d = crate::util::distance(&mut c, &r.scene_id, &placed.instance_id, ball).await;
    assert!(d.distance <= exact + 1e-9, "{} > exact {exact}", d.distance);
    assert!(d.distance >= exact - excess - 1e-9, "{} < exact {exact} − excess {excess}", d.distance);

    // Robot checks take the kept mesh as an exact obstacle: the one-joint arm of
    // `tests/data/arm.robot.json` (a ball of radius 0.1 m, 0.5 m from its base) based at
    // (1.15, 1.5, 0.7) sweeps past and into the box, and every answer is the closed form of the
    // ball against the box and the scene's ball.
    let arm = include_bytes!("../data/arm.robot.json").to_vec();
    let robot = c.upload_robot(pb::UploadRobotRequest { name: "arm".into(), robot_file: arm }).await.unwrap();
    let robot_id = robot.into_inner().robot.unwrap().robot_id;
    let qs: Vec<f64> = (0..=24).map(|k| -0.3 + 0.1 * f64::from(k)).collect();
    let base = pb::Pose {
        rotation: Some(pb::Quaternion { w: 1.0, ..Default::default() }),
        translation: Some(pb::Vec3 { x: 1.15, y: 1.5, z: 0.7 }),
    };
    let check = pb::CheckConfigurationsRequest {
        robot_id,
        scene_id: r.scene_id.clone(),
        base: Some(base),
        configurations: Some(pb::ConfigurationColumns { joint_names: vec!["j".into()], values: qs.clone() }),
        distance: true,
        ..Default::default()
    };
    let a = c.check_configurations(check).await.unwrap().into_inner();
    let (mut free, mut colliding) = (0, 0);
    for (k, q) in qs.iter().enumerate() {
        let center = [1.15 + 0.5 * q.cos(), 1.5 + 0.5 * q.sin(), 0.7];
        let gap = |lo: f64, hi: f64, x: f64| (lo - x).max(x - hi).max(0.0);
        let to_box =
            (gap(1.0, 1.3, center[0]).powi(2) + gap(2.0, 2.2, center[1]).powi(2) + gap(0.65, 0.75, center[2]).powi(2))
                .sqrt()
                - 0.1;
        let to_ball = ((center[0] - 1.5).powi(2) + (center[1] - 2.4).powi(2) + (center[2] - 0.9).powi(2)).sqrt() - 0.15;
        let expected = to_box.min(to_ball);
        assert!(a.converged[k], "q {q}");
        if expected > 1e-9 {
            free += 1;
            assert!(!a.world[k], "q {q}: free at {expected} m");
            assert!((a.distance[k] - expected).abs() < 1e-8, "q {q}: {} vs {expected}", a.distance[k]);
            let closest = if to_box < to_ball { "crate" } else { "ball" };
            assert_eq!(a.world_object[k], closest, "q {q}");
        } else {
            colliding += 1;
            assert!(a.world[k] && a.distance[k] == 0.0, "q {q}: colliding at {expected} m");
        }
    }
    assert!(free > 5 && colliding > 5, "{free} free, {colliding} colliding");

    // Deleted before its job ends: the body is stored, the instance not added.
    let again = c.import_scene(request(BOX_TOLERANCE)).await.unwrap().into_inner();
    c.delete_scene(pb::DeleteSceneRequest { scene_id: again.scene_id.clone() }).await.unwrap();
    let last_again = crate::util::watch_to_end(&mut c, again.meshes[0].job_id.clone()).await.pop().unwrap();
    assert_eq!(last_again.state, pb::JobState::Succeeded as i32, "{last_again:?}");
    assert!(
        last_again.message.contains("was not added") && last_again.message.contains("not found"),
        "{}",
        last_again.message
    );
    c.get_body(pb::GetBodyRequest { body_id: last_again.body_id.clone() }).await.unwrap();
    server.stop().await;

    // What the store holds: the planning name, and the mesh as written (the body's frame).
    let catalog = sublevel::scene::Catalog::open(
        Box::new(sublevel::scene::store::RedbStore::open_dir(&data).unwrap()),
        Default::default(),
    )
    .unwrap();
    let scene = catalog.get_scene(&r.scene_id).unwrap();
    assert_eq!(scene.planning.names.get(&placed.instance_id).map(String::as_str), Some("crate"));
    assert_eq!(scene.planning.names.get(ball).map(String::as_str), Some("ball"));
    let mesh = catalog.body(&last.body_id).unwrap().mesh().cloned().expect("the mesh is kept");
    let parsed = PlanningScene::from_yaml(yaml.as_bytes()).unwrap();
    let Shape::Mesh { vertices, triangles } = &parsed.objects[0].shapes[0].shape else { panic!("not a mesh") };
    assert_eq!((&mesh.vertices, &mesh.triangles), (vertices, triangles));
}

/// `sublevel scene import FILE --addr A --name N` prints the new scene's id on its first line,
/// then the summary.
#[tokio::test]
async fn the_command_line_imports_a_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(&dir.path().join("data"))).await;
    let scenes = motionbenchmaker_scenes(dir.path());
    let (scenario, yaml) = &scenes[0];
    let file = dir.path().join("scene.yaml");
    std::fs::write(&file, yaml).unwrap();
    let addr = server.addr().to_string();
    let out = tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_sublevel"))
            .args(["scene", "import"])
            .arg(&file)
            .args(["--addr", &addr, "--name", "bench"])
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    let scene_id = lines.next().unwrap().to_owned();
    let summary = lines.next().unwrap();
    let n = primitive_count(yaml);
    assert!(summary.starts_with("scene `bench`: "), "{summary}");
    assert!(summary.contains(&format!("{n} instances")), "{scenario}: {summary}");
    let mut c = server.client().await;
    let view = c.get_scene(pb::GetSceneRequest { scene_id }).await.unwrap().into_inner();
    assert_eq!((view.name.as_str(), view.instances.len()), ("bench", n));
    server.stop().await;
}
