//! MoveIt planning scenes: both message spellings, pose composition against hand-computed values,
//! errors naming their field, hostile YAML, and every MotionBenchMaker Panda scene counted
//! against its own text.

use super::*;
use sublevel_core::math::Point3;

/// A scene in the spelling of `rostopic echo` (maps, integer primitive codes, ACM entries).
pub(super) const ROS_SCENE: &str = r#"
name: kitchen
robot_state:
  joint_state:
    name: [j1, j2]
    position: [0.5, -1.25]
allowed_collision_matrix:
  entry_names: [link_a, table]
  entry_values:
    - enabled: [false, true]
    - enabled: [true, false]
  default_entry_names: [floor]
  default_entry_values: [true]
world:
  collision_objects:
    - id: table
      header: {frame_id: world}
      pose:
        position: {x: 1.0, y: 0.0, z: 0.0}
        orientation: {x: 0.0, y: 0.0, z: 0.707, w: 0.707}
      primitives:
        - type: 1
          dimensions: [1.2, 1.0, 0.04]
        - {type: 2, dimensions: [0.1]}
      primitive_poses:
        - position: {x: 0.5, y: 0.0, z: 0.0}
          orientation: {x: 0.0, y: 0.0, z: 0.0, w: 0.0}
        - position: {x: 0.0, y: 0.0, z: 1.0}
      planes:
        - coef: [0.0, 0.0, 2.0, -1.0]
      plane_poses:
        - {}
    - id: wedge
      meshes:
        - vertices: [{x: 0, y: 0, z: 0}, {x: 1, y: 0, z: 0}, {x: 0, y: 1, z: 0}, {x: 0, y: 0, z: 1}]
          triangles:
            - vertex_indices: [0, 1, 2]
            - vertex_indices: [0, 1, 3]
      mesh_poses:
        - position: {x: 0, y: 0, z: 2}
    - id: table
      operation: 3
      primitives: [{type: cylinder, dimensions: [0.3, 0.05]}]
      primitive_poses: [{position: [0, 0, 0], orientation: [0, 0, 0, 1]}]
"#;

#[test]
fn a_ros_spelled_scene_reads_with_its_poses_composed() {
    let s = PlanningScene::from_yaml(ROS_SCENE.as_bytes()).unwrap();
    assert_eq!(s.name, "kitchen");
    assert_eq!(s.joint_positions, vec![("j1".to_owned(), 0.5), ("j2".to_owned(), -1.25)]);
    assert_eq!(s.objects.len(), 2, "APPEND merges into `table`");
    let table = &s.objects[0];
    assert_eq!((table.id.as_str(), table.frame_id.as_str()), ("table", "world"));
    assert_eq!(table.shapes.len(), 4);
    assert_eq!(table.shapes[0].shape, Shape::Box { size: [1.2, 1.0, 0.04] });
    // Object at (1, 0, 0) turned 90° about z (0.707 normalized); the box 0.5 m along the
    // object's x lands at (1, 0.5, 0), its x axis along the world's y.
    let p = table.shapes[0].pose;
    assert!((p.translation.vector - Point3::new(1.0, 0.5, 0.0).coords).norm() < 1e-12, "{p:?}");
    let x_axis = p.rotation * sublevel_core::math::Vector3::x();
    assert!((x_axis - sublevel_core::math::Vector3::y()).norm() < 1e-12, "{x_axis:?}");
    assert_eq!(table.shapes[1].shape, Shape::Sphere { radius: 0.1 });
    assert!((table.shapes[1].pose.translation.vector - Point3::new(1.0, 0.0, 1.0).coords).norm() < 1e-12);
    // Plane 2z − 1 = 0 normalized to z − 0.5 = 0, placed by the object's pose alone.
    assert_eq!(table.shapes[2].shape, Shape::Plane { normal: [0.0, 0.0, 1.0], offset: -0.5 });
    assert_eq!(table.shapes[3].shape, Shape::Cylinder { height: 0.3, radius: 0.05 });
    // No object pose: the APPENDed shape's pose is its own.
    assert!((table.shapes[3].pose.translation.vector).norm() < 1e-15);
    let Shape::Mesh { vertices, triangles } = &s.objects[1].shapes[0].shape else { panic!("a mesh") };
    assert_eq!((vertices.len(), triangles.as_slice()), (4, &[[0, 1, 2], [0, 1, 3]][..]));
    assert_eq!(s.objects[1].shapes[0].pose.translation.vector.z, 2.0);
    let acm = s.allowed_collision.unwrap();
    assert!(acm.allowed("link_a", "table") && acm.allowed("table", "link_a"));
    assert!(!acm.allowed("link_a", "link_a"));
    assert!(acm.allowed("link_a", "floor"), "the default entry of `floor` allows everything");
    assert!(!acm.allowed("link_a", "shelf"));
}

/// The same scene as JSON reads to the same value.
#[test]
fn json_reads_like_yaml() {
    let json = r#"{"name": "j", "world": {"collision_objects": [{"id": "b",
        "primitives": [{"type": "box", "dimensions": [1, 2, 3]}],
        "primitive_poses": [{"position": [1, 2, 3], "orientation": [0, 0, 0, 1]}]}]}}"#;
    let yaml = "name: j\nworld:\n  collision_objects:\n    - id: b\n      primitives: [{type: box, dimensions: [1, 2, 3]}]\n      primitive_poses: [{position: [1, 2, 3], orientation: [0, 0, 0, 1]}]\n";
    assert_eq!(PlanningScene::from_yaml(json.as_bytes()).unwrap(), PlanningScene::from_yaml(yaml.as_bytes()).unwrap());
}

/// Each bad input is refused naming the field it is in.
#[test]
fn errors_name_their_field() {
    let object = |body: &str| format!("world:\n  collision_objects:\n    - id: o\n{body}");
    let cases = [
        (
            object("      primitives: [{type: box, dimensions: [1, 2]}]\n      primitive_poses: [{}]\n"),
            "world.collision_objects[0].primitives[0].dimensions",
        ),
        (
            object("      primitives: [{type: sphere, dimensions: [-1]}]\n      primitive_poses: [{}]\n"),
            "world.collision_objects[0].primitives[0].dimensions[0]",
        ),
        (object("      primitives: [{type: torus, dimensions: [1]}]\n      primitive_poses: [{}]\n"), "world.collision_objects[0].primitives[0].type"),
        (object("      primitives: [{type: sphere, dimensions: [1]}]\n"), "world.collision_objects[0].primitive_poses"),
        (
            object("      primitives: [{type: sphere, dimensions: [1]}]\n      primitive_poses: [{orientation: [0, 0, 0, 2]}]\n"),
            "world.collision_objects[0].primitive_poses[0].orientation",
        ),
        (
            object("      primitives: [{type: sphere, dimensions: [1]}]\n      primitive_poses: [{position: [1e300, 0, 0]}]\n"),
            "world.collision_objects[0].primitive_poses[0].position",
        ),
        (object("      operation: 1\n      primitives: [{type: 2, dimensions: [1]}]\n      primitive_poses: [{}]\n"), "world.collision_objects[0].operation"),
        (object("      planes: [{coef: [0, 0, 0, 1]}]\n      plane_poses: [{}]\n"), "world.collision_objects[0].planes[0].coef"),
        (
            object("      meshes: [{vertices: [[0, 0, 0]], triangles: [{vertex_indices: [0, 0, 7]}]}]\n      mesh_poses: [{}]\n"),
            "world.collision_objects[0].meshes[0].triangles[0].vertex_indices",
        ),
        (object(""), "world.collision_objects[0]"),
        (
            "allowed_collision_matrix:\n  entry_names: [a, b]\n  entry_values: [[false, true]]\n".to_owned(),
            "allowed_collision_matrix.entry_values",
        ),
        ("robot_state:\n  joint_state:\n    name: [a]\n    position: [1, 2]\n".to_owned(), "robot_state.joint_state.position"),
        ("world: [1, 2\n".to_owned(), "scene"),
    ];
    for (yaml, field) in cases {
        match PlanningScene::from_yaml(yaml.as_bytes()) {
            Err(Error::InvalidArgument { field: f, reason }) => assert_eq!(f, field, "{yaml}: {reason}"),
            other => panic!("{yaml}: {other:?}"),
        }
    }
    let twice = format!(
        "{}    - id: o\n      primitives: [{{type: 2, dimensions: [1]}}]\n      primitive_poses: [{{}}]\n",
        object("      primitives: [{type: 2, dimensions: [1]}]\n      primitive_poses: [{}]\n")
    );
    let Err(Error::InvalidArgument { field, .. }) = PlanningScene::from_yaml(twice.as_bytes()) else { panic!() };
    assert_eq!(field, "world.collision_objects[1].id");
}

/// A "billion laughs" alias bomb is refused by the parser's budget instead of expanding.
#[test]
fn an_alias_bomb_is_refused() {
    let mut yaml = String::from("a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n");
    for k in 1..10 {
        let refs = vec![format!("*a{}", k - 1); 10].join(", ");
        yaml.push_str(&format!("a{k}: &a{k} [{refs}]\n"));
    }
    yaml.push_str("name: bomb\n");
    let e = PlanningScene::from_yaml(yaml.as_bytes()).unwrap_err();
    assert!(matches!(&e, Error::InvalidArgument { field, .. } if field == "scene"), "{e}");
    // Refused by the budget of its own size, not the parser's default million events.
    let budget = YamlBudget::for_text(yaml.len());
    assert_eq!(budget.max_replayed_events, yaml.len() + YAML_BUDGET_BASE);
    assert!(budget.max_replayed_events < 5_000 && budget.max_recorded_anchor_events < 5_000, "{budget:?}");
    let Error::InvalidArgument { reason, .. } = &e else { unreachable!() };
    assert!(reason.contains(&format!("{} replayed alias events", budget.max_replayed_events)), "{reason}");
}

/// The 516-byte bomb of the probe (strings under anchors, nine levels, in a field the scene
/// ignores, a field it reads, and the robot state's names) is refused by the budget of its size
/// whatever field holds it; the same text without aliases is read.
#[test]
fn an_alias_bomb_is_refused_by_the_budget_of_its_size_in_any_field() {
    let bomb = |key: &str| {
        let mut yaml = String::from("l0: &l0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n");
        for k in 1..9 {
            yaml.push_str(&format!("l{k}: &l{k} [{}]\n", vec![format!("*l{}", k - 1); 9].join(",")));
        }
        yaml.push_str(&format!("{key}: *l8\n"));
        yaml
    };
    for key in ["extra", "name", "robot_state: {joint_state: {name: *l8}}\nx"] {
        let yaml = bomb(key);
        assert!(yaml.len() < 600, "{}", yaml.len());
        let e = PlanningScene::from_yaml(yaml.as_bytes()).unwrap_err();
        let Error::InvalidArgument { field, reason } = &e else { panic!("{e}") };
        assert_eq!(field, "scene");
        assert!(reason.contains("budget of a"), "{reason}");
    }
    let plain = "l0: [lol, lol]\nname: fine\n";
    assert_eq!(PlanningScene::from_yaml(plain.as_bytes()).unwrap().name, "fine");
}

fn boxes(n: usize) -> String {
    let mut yaml = String::from("world:\n  collision_objects:\n");
    for k in 0..n {
        yaml.push_str(&format!(
            "    - id: box{k}\n      header: {{frame_id: world}}\n      primitives: [{{type: box, dimensions: [0.1, 0.2, 0.3]}}]\n      primitive_poses: [{{position: [{k}, 0, 0], orientation: [0, 0, 0, 1]}}]\n"
        ));
    }
    yaml
}

/// The node budget follows the text: 20 000 boxes (past the parser's default 250 000 nodes)
/// read as YAML as they do as JSON; the object limit stops the parse at the first object past it,
/// as ResourceExhausted naming `world.collision_objects`.
#[test]
fn many_objects_read_and_the_object_limit_stops_the_parse() {
    let yaml = boxes(20_000);
    let scene = PlanningScene::from_yaml(yaml.as_bytes()).unwrap();
    assert_eq!(scene.objects.len(), 20_000);
    assert_eq!(PlanningScene::from_yaml_with_limit(yaml.as_bytes(), 20_000).unwrap().objects.len(), 20_000);
    let e = PlanningScene::from_yaml_with_limit(yaml.as_bytes(), 19_999).unwrap_err();
    assert!(
        matches!(&e, Error::ResourceExhausted(m) if m.contains("world.collision_objects") && m.contains("19999")),
        "{e}"
    );
    let json = r#"{"world": {"collision_objects": [
        {"id": "a", "primitives": [{"type": 2, "dimensions": [1]}], "primitive_poses": [{}]},
        {"id": "b", "primitives": [{"type": 2, "dimensions": [1]}], "primitive_poses": [{}]}]}}"#;
    assert_eq!(PlanningScene::from_json_with_limit(json.as_bytes(), 2).unwrap().objects.len(), 2);
    assert!(matches!(PlanningScene::from_json_with_limit(json.as_bytes(), 1), Err(Error::ResourceExhausted(_))));
    // The limit is this parse's only: the next one on the thread has the default again.
    assert_eq!(PlanningScene::from_json(json.as_bytes()).unwrap().objects.len(), 2);
}

/// A shape is checked at the pose it is stored at — its object's pose composed with its own — by
/// the store's rule: 9·10⁵ + 9·10⁵ m is refused naming the shape's pose; 5·10⁵ + 5·10⁵ m (the
/// edge) is read.
#[test]
fn a_composed_pose_beyond_the_range_is_refused_naming_the_shape_pose() {
    let scene = |x: f64| {
        format!(
            "world:\n  collision_objects:\n    - id: a\n      primitives: [{{type: 2, dimensions: [1]}}]\n      primitive_poses: [{{}}]\n    - id: far\n      pose: {{position: [{x}, 0, 0]}}\n      primitives: [{{type: 2, dimensions: [1]}}]\n      primitive_poses: [{{position: [{x}, 0, 0]}}]\n"
        )
    };
    let e = PlanningScene::from_yaml(scene(9e5).as_bytes()).unwrap_err();
    let Error::InvalidArgument { field, reason } = &e else { panic!("{e}") };
    assert_eq!(field, "world.collision_objects[1].primitive_poses[0]");
    assert!(reason.contains("composed") && reason.contains("1.8e6"), "{reason}");
    let edge = PlanningScene::from_yaml(scene(5e5).as_bytes()).unwrap();
    assert_eq!(edge.objects[1].shapes[0].pose.translation.vector.x, 1e6);
}

/// One minimum-size rule (1 µm, `MIN_DIMENSION`) for every dimension, naming it: 10⁻³⁰⁰ m and
/// 10⁻²⁰⁰ m alike; 1 µm is read.
#[test]
fn dimensions_below_a_micrometer_are_refused_naming_the_dimension() {
    let scene = |d: &str| {
        format!("world:\n  collision_objects:\n    - id: a\n      primitives: [{{type: box, dimensions: [{d}, 1, 1]}}]\n      primitive_poses: [{{}}]\n")
    };
    for tiny in ["1e-300", "1e-200", "9.99e-7"] {
        let e = PlanningScene::from_yaml(scene(tiny).as_bytes()).unwrap_err();
        let Error::InvalidArgument { field, reason } = &e else { panic!("{e}") };
        assert_eq!(field, "world.collision_objects[0].primitives[0].dimensions[0]");
        assert!(reason.contains("1e-6"), "{reason}");
    }
    assert!(PlanningScene::from_yaml(scene("1e-6").as_bytes()).is_ok());
}

/// Instance names are unique and bounded: an object `a#1` beside an object `a` of two shapes
/// (which names `a#0`, `a#1`) is refused naming the later object's id, whichever comes first; an
/// id over `MAX_NAME_BYTES` is refused naming it.
#[test]
fn instance_names_are_unique_and_ids_bounded() {
    let two = "    - id: a\n      primitives: [{type: 2, dimensions: [1]}, {type: 2, dimensions: [2]}]\n      primitive_poses: [{}, {}]\n";
    let named = "    - id: a#1\n      primitives: [{type: 2, dimensions: [1]}]\n      primitive_poses: [{}]\n";
    for (text, later) in [(format!("{two}{named}"), 1), (format!("{named}{two}"), 1)] {
        let yaml = format!("world:\n  collision_objects:\n{text}");
        let e = PlanningScene::from_yaml(yaml.as_bytes()).unwrap_err();
        let Error::InvalidArgument { field, reason } = &e else { panic!("{e}") };
        assert_eq!(field, &format!("world.collision_objects[{later}].id"));
        assert!(reason.contains("a#1"), "{reason}");
    }
    let long = "n".repeat(crate::MAX_NAME_BYTES + 1);
    let yaml = format!("world:\n  collision_objects:\n    - id: {long}\n      primitives: [{{type: 2, dimensions: [1]}}]\n      primitive_poses: [{{}}]\n");
    let e = PlanningScene::from_yaml(yaml.as_bytes()).unwrap_err();
    assert!(matches!(&e, Error::InvalidArgument { field, .. } if field == "world.collision_objects[0].id"), "{e}");
}

/// Lines of `text` whose key is exactly `key` (`key:` or `- key:` at any indentation).
fn keyed_lines(text: &str, key: &str) -> usize {
    text.lines()
        .map(str::trim_start)
        .filter(|l| l.strip_prefix("- ").unwrap_or(l).starts_with(&format!("{key}:")))
        .count()
}

/// Every MotionBenchMaker Panda scene (7 scenarios × 100, `data/robots/mbm_panda/problems.tar.bz2`,
/// unpacked with `tar`) reads; each scene's objects and shapes are as many as its text has `id:`
/// and `type:` keys, and the 700 scenes hold 5 500 boxes and 2 700 cylinders (counted with grep).
#[test]
fn every_motionbenchmaker_panda_scene_reads() {
    let archive = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/mbm_panda/problems.tar.bz2");
    let dir = tempfile::tempdir().unwrap();
    let status = std::process::Command::new("tar").arg("xjf").arg(&archive).arg("-C").arg(dir.path()).status().unwrap();
    assert!(status.success());
    let (mut scenes, mut boxes, mut cylinders) = (0, 0, 0);
    for scenario in std::fs::read_dir(dir.path().join("problems")).unwrap() {
        for file in std::fs::read_dir(scenario.unwrap().path()).unwrap() {
            let path = file.unwrap().path();
            if !path.file_name().unwrap().to_string_lossy().starts_with("scene") {
                continue;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            let scene = PlanningScene::from_yaml(text.as_bytes()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert_eq!(scene.objects.len(), keyed_lines(&text, "id"), "{}", path.display());
            assert_eq!(scene.shape_count(), keyed_lines(&text, "type"), "{}", path.display());
            assert_eq!(scene.allowed_collision.as_ref().map(|a| a.names.len()), Some(11), "{}", path.display());
            for shape in scene.objects.iter().flat_map(|o| &o.shapes) {
                match shape.shape {
                    Shape::Box { .. } => boxes += 1,
                    Shape::Cylinder { .. } => cylinders += 1,
                    _ => panic!("{}: only boxes and cylinders expected", path.display()),
                }
            }
            scenes += 1;
        }
    }
    assert_eq!((scenes, boxes, cylinders), (700, 5500, 2700));
}
