//! Forward kinematics against pinocchio 4.1's `framesForwardKinematics` (reference poses written by
//! `tests/data/fk_reference.py`): every link of a test robot with every joint kind (prismatic,
//! continuous beyond ±π, revolute with unaligned axes and rotated origins, a mimic joint, fixed
//! joints, a branch) and of the Panda, at 20 random configurations each, to 1e-12 m in translation
//! and 1e-12 in every rotation entry.

use std::collections::HashMap;
use sublevel_core::math::Isometry3;
use sublevel_robot::RobotModel;

#[derive(serde::Deserialize)]
struct Reference {
    joints: Vec<String>,
    configs: Vec<Vec<f64>>,
    links: HashMap<String, Vec<[f64; 12]>>,
}

fn data(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

/// Compares every link pose of `model` with the reference; returns the worst (translation,
/// rotation) differences.
fn compare(model: &RobotModel, reference: &Reference) -> (f64, f64) {
    let names: Vec<&str> = model.variable_names();
    assert_eq!(names, reference.joints.iter().map(String::as_str).collect::<Vec<_>>());
    let (mut worst_t, mut worst_r) = (0.0f64, 0.0f64);
    for (c, q) in reference.configs.iter().enumerate() {
        let poses = model.link_poses(q, &Isometry3::identity()).unwrap();
        for (link, want) in &reference.links {
            let k = model.link_index(link).unwrap_or_else(|| panic!("link {link}"));
            let (t, r) = (poses[k].translation.vector, poses[k].rotation.to_rotation_matrix());
            let want = want[c];
            for i in 0..3 {
                worst_t = worst_t.max((t[i] - want[i]).abs());
                for j in 0..3 {
                    worst_r = worst_r.max((r[(i, j)] - want[3 + 3 * i + j]).abs());
                }
            }
        }
    }
    (worst_t, worst_r)
}

#[test]
fn every_joint_kind_matches_pinocchio() {
    let model = RobotModel::from_urdf_file(&data("gantry.urdf")).unwrap();
    let reference: Reference = serde_json::from_str(&std::fs::read_to_string(data("gantry_fk.json")).unwrap()).unwrap();
    assert_eq!(model.dof(), 4, "rail, spin, shoulder, elbow; `follow` mimics `elbow`");
    assert_eq!(reference.links.len(), 8);
    let (t, r) = compare(&model, &reference);
    println!("worst translation {t:e} m, rotation {r:e}");
    assert!(t <= 1e-12 && r <= 1e-12, "worst translation {t:e} m, rotation {r:e}");
}

#[test]
fn the_panda_matches_pinocchio() {
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.urdf");
    let model = RobotModel::from_urdf_file(&urdf).unwrap();
    let reference: Reference = serde_json::from_str(&std::fs::read_to_string(data("panda_fk.json")).unwrap()).unwrap();
    assert_eq!(model.dof(), 7);
    assert_eq!(model.links().len(), 13);
    let (t, r) = compare(&model, &reference);
    println!("worst translation {t:e} m, rotation {r:e}");
    assert!(t <= 1e-12 && r <= 1e-12, "worst translation {t:e} m, rotation {r:e}");
}
