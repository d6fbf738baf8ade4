//! Integration tests: the Panda of the MotionBenchMaker problems read from its URDF and SRDF agrees
//! with the problems' own scenes — the self-collision pairs the SRDF leaves are exactly the robot
//! pairs a scene's allowed-collision matrix does not allow (21, as the peer labels say), and every
//! collision mesh resolves under the package directory (`data/robots/panda`, the VAMP copy of the
//! MotionBenchMaker Panda).

use std::path::PathBuf;
use sublevel::robot::srdf::Semantics;
use sublevel::robot::{resolve_mesh_path, CollisionGeometry, RobotModel};
use sublevel::scene::moveit::PlanningScene;

fn panda_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots/panda")
}

#[test]
fn the_panda_srdf_leaves_the_pairs_the_scenes_check() {
    let dir = panda_dir();
    let robot = RobotModel::from_urdf_file(&dir.join("panda.urdf")).unwrap();
    let srdf = Semantics::from_srdf_file(&dir.join("panda.srdf")).unwrap();
    let pairs = robot.self_collision_pairs(&srdf.disabled_pairs).unwrap();
    assert_eq!(pairs.len(), 21);
    let mut from_srdf: Vec<(String, String)> = pairs
        .iter()
        .map(|&(i, j)| {
            let (a, b) = (robot.links()[i].name.clone(), robot.links()[j].name.clone());
            if a < b {
                (a, b)
            } else {
                (b, a)
            }
        })
        .collect();
    from_srdf.sort();

    let scene =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/robots/mbm_panda/scenes/table_pick/scene0001.yaml");
    let text = std::fs::read(scene).unwrap();
    let acm = PlanningScene::from_yaml(&text).unwrap().allowed_collision.unwrap();
    let mut from_scene = Vec::new();
    for (i, a) in acm.names.iter().enumerate() {
        for b in &acm.names[i + 1..] {
            if !acm.allowed(a, b) {
                from_scene.push(if a < b { (a.clone(), b.clone()) } else { (b.clone(), a.clone()) });
            }
        }
    }
    from_scene.sort();
    assert_eq!(from_srdf, from_scene);

    for link in robot.links() {
        for (k, g) in link.collision.iter().enumerate() {
            let CollisionGeometry::Mesh { filename, .. } = g else { continue };
            let field = format!("link[{}].collision[{k}]", link.name);
            let path = resolve_mesh_path(&field, filename, Some(&dir), std::slice::from_ref(&dir)).unwrap();
            assert!(path.starts_with(&dir) && path.is_file(), "{}", path.display());
        }
    }
}
