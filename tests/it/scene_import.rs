//! Integration tests: `ImportScene` and `sublevel scene import`. One MotionBenchMaker Panda scene
//! of every scenario (`../shared/peers/robots/panda/problems.tar.bz2`, as
//! `sublevel_scene::moveit`'s tests find it) imported over gRPC: as many instances as the YAML has
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
    let archive =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/peers/robots/panda/problems.tar.bz2");
    assert!(
        archive.exists(),
        "{} is missing: the MotionBenchMaker scenes are part of the test data",
        archive.display()
    );
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
/// reason; a bad scene names its field, an empty request names `scene`, and a scene over the
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
    };
    let r = c.import_scene(req).await.unwrap().into_inner();
    assert_eq!(r.name, "mine");
    let kinds: Vec<(&str, &str)> = r.instances.iter().map(|i| (i.name.as_str(), i.kind.as_str())).collect();
    assert_eq!(kinds, [("floor", "halfspace"), ("funnel#0", "cylinder")]);
    assert!(r.instances[1].note.contains("cone"));
    assert_eq!(r.instances[0].frame_id, "world");
    assert_eq!(r.skipped.len(), 1);
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
        pb::ImportSceneRequest { name: String::new(), scene: Some(pb::import_scene_request::Scene::Yaml(bad.into())) };
    assert_status(
        c.import_scene(req).await,
        Code::InvalidArgument,
        "yaml.world.collision_objects[0].primitives[0].dimensions",
    );
    assert_status(c.import_scene(pb::ImportSceneRequest::default()).await, Code::InvalidArgument, "scene");
    let many = "world:\n  collision_objects:\n    - id: o\n      primitives: [{type: sphere, dimensions: [1]}, {type: sphere, dimensions: [1]}, {type: sphere, dimensions: [1]}, {type: sphere, dimensions: [1]}]\n      primitive_poses: [{}, {}, {}, {}]\n";
    let req =
        pb::ImportSceneRequest { name: String::new(), scene: Some(pb::import_scene_request::Scene::Yaml(many.into())) };
    assert_status(c.import_scene(req).await, Code::ResourceExhausted, "--max-instances-per-scene");
    let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes;
    assert_eq!(scenes.len(), 1, "a refused import writes nothing");
    server.stop().await;
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
