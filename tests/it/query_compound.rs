//! Integration tests: `sublevel query distance|growth` on compound body files
//! against closed-form sphere distances, and single-body files answered as before.

use serde_json::Value;
use std::path::Path;
use sublevel::body::ellipsoid;
use sublevel::compound::{CompoundBody, CompoundNode, CompoundReport};

fn node(center: [f64; 3], radius: f64, children: Vec<usize>, depth: usize) -> CompoundNode {
    let body = ellipsoid(center, [radius; 3]).unwrap();
    CompoundNode { body, children, depth, excess: 0.0, triangles: 0, fit_seconds: 0.0 }
}

/// Root sphere r = 1 at the origin containing spheres r = 0.4 at x = ±0.5 (|±0.5| + 0.4 ≤ 1).
fn write_dumbbell(path: &Path) {
    let nodes = vec![
        node([0.0; 3], 1.0, vec![1, 2], 0),
        node([-0.5, 0.0, 0.0], 0.4, vec![], 1),
        node([0.5, 0.0, 0.0], 0.4, vec![], 1),
    ];
    CompoundBody::new(nodes, 0, CompoundReport::default()).unwrap().save(path).unwrap();
}

fn query(args: &[&str]) -> Value {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sublevel")).arg("query").args(args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn compound_distance_and_growth_match_closed_forms() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    write_dumbbell(&a);
    ellipsoid([0.0; 3], [0.3; 3]).unwrap().save(&b).unwrap();
    let (a, b) = (a.to_str().unwrap(), b.to_str().unwrap());

    // B at x = 2: the +x part is closest, 2 − 0.5 − 0.4 − 0.3 = 0.8 (the root alone says 0.7).
    let v = query(&["distance", a, b, "--pose-b", "1,0,0,0,2,0,0", "--json"]);
    assert_eq!(v["compound"], true);
    for k in ["distance", "lower", "upper"] {
        assert!((v[k].as_f64().unwrap() - 0.8).abs() < 1e-7, "{k}: {v}");
    }
    assert_eq!(v["leaves"], serde_json::json!([2, 0]));
    assert_eq!((v["level"].as_u64(), v["converged"].as_bool()), (Some(1), Some(true)));
    assert!((v["witness_a"][0].as_f64().unwrap() - 0.9).abs() < 1e-7, "{v}");

    // A tolerance wider than the gap between root and parts stops at the roots: [0.7, 0.8].
    let v = query(&["distance", a, b, "--pose-b", "1,0,0,0,2,0,0", "--bound-tolerance", "0.2", "--json"]);
    assert!(v["lower"].as_f64().unwrap() <= 0.8 + 1e-9 && v["upper"].as_f64().unwrap() >= 0.8 - 1e-9, "{v}");
    assert!(v["upper"].as_f64().unwrap() - v["lower"].as_f64().unwrap() <= 0.2 + 1e-12);

    // B at (0, 0.75, 0): inside the root (0.75 − 0.3 < 1) but between the parts:
    // |(±0.5, 0.75)| − 0.4 − 0.3 = 0.2014 > 0, so the models do not collide. The root pair's
    // cheap bound already decides it: a node's support bound is also capped by its leaves' hull
    // (here the capsule around the two parts, reaching y = 0.4 < 0.75 − 0.3), so level 0.
    let v = query(&["growth", a, b, "--pose-b", "1,0,0,0,0,0.75,0", "--json"]);
    assert_eq!((v["separated"].as_bool(), v["level"].as_u64()), (Some(true), Some(0)), "{v}");
    let v = query(&["distance", a, b, "--pose-b", "1,0,0,0,0,0.75,0", "--json"]);
    let exact = (0.25f64 + 0.5625).sqrt() - 0.7;
    assert!((v["distance"].as_f64().unwrap() - exact).abs() < 1e-7, "{v}");

    // B at x = 1.1 overlaps the +x part: d(p_A‖p_B) < 1, collision found at the leaves.
    let v = query(&["growth", a, b, "--pose-b", "1,0,0,0,1.1,0,0", "--json"]);
    assert_eq!((v["separated"].as_bool(), v["leaves"].clone()), (Some(false), serde_json::json!([2, 0])), "{v}");
    assert!(v["value"].as_f64().unwrap() < 1.0);
}

#[test]
fn single_body_files_are_answered_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    ellipsoid([0.0; 3], [1.0; 3]).unwrap().save(&a).unwrap();
    ellipsoid([0.0; 3], [0.3; 3]).unwrap().save(&b).unwrap();
    let v = query(&["distance", a.to_str().unwrap(), b.to_str().unwrap(), "--pose-b", "1,0,0,0,2,0,0", "--json"]);
    assert!(v.get("compound").is_none() && v.get("lower").is_none(), "{v}");
    assert!((v["distance"].as_f64().unwrap() - 0.7).abs() < 1e-9, "{v}");
    assert_eq!(v["source"], "Newton");
}

/// The bundled compound fits of data/compound (chair and human, fitted on branch `cfit`): the tree
/// answer equals the brute-force minimum over all leaf pairs, and margin queries agree with it.
#[test]
fn bundled_compound_bodies_match_brute_force_over_leaf_pairs() {
    use rand::{Rng, SeedableRng};
    use sublevel::math::{Isometry3, UnitQuaternion, Vector3};
    use sublevel::query::tree::{tree_closer_than, tree_distance, TreeQueryParams};
    use sublevel::query::{distance, NewtonParams};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/compound");
    let chair = CompoundBody::load(&root.join("chair_101.json")).expect("data/compound/chair_101.json");
    let human = CompoundBody::load(&root.join("human_10.json")).expect("data/compound/human_10.json");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let id = Isometry3::identity();
    let params = TreeQueryParams::default();
    for case in 0..30 {
        let t = Vector3::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5));
        let q = UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random());
        let pose = Isometry3::from_parts(t.into(), q);
        let mut brute = f64::INFINITY;
        for i in chair.leaves() {
            for j in human.leaves() {
                let r = distance(chair.body(i), &pose, human.body(j), &id, None, &NewtonParams::default());
                assert!(r.status.converged(), "case {case}: leaf pair ({i}, {j})");
                brute = brute.min(r.distance);
            }
        }
        let r = tree_distance(&chair, &pose, &human, &id, None, &params).unwrap();
        assert!(r.converged, "case {case}");
        assert!((r.lower - brute).abs() < 1e-7 && (r.upper - brute).abs() < 1e-7, "case {case}: {r:?} vs {brute}");
        for m in [0.0, 0.05, 0.3] {
            let c = tree_closer_than(&chair, &pose, &human, &id, m, None, &params).unwrap();
            if (brute - m).abs() > 1e-7 {
                assert_eq!(c.closer, brute < m, "case {case} margin {m}: brute {brute}");
            }
        }
    }
}
