//! The catalog against a real redb store: persistence across reopen, warm starts that follow
//! their pair, all-or-nothing pose batches.

use super::*;
use crate::answer::QueryOptions;
use crate::store::RedbStore;
use sublevel_core::body::ellipsoid;
use sublevel_core::math::pose_from_parts;

fn at(x: f64) -> Isometry3 {
    pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, 0.0]).unwrap()
}

fn open(dir: &std::path::Path) -> Catalog {
    Catalog::open(Box::new(RedbStore::open_dir(dir).unwrap()), NewtonParams::default()).unwrap()
}

#[test]
fn catalog_persists_and_warm_starts_follow_the_pair() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, i1, i2);
    {
        let c = open(dir.path());
        let b1 = c.add_body("r1", ellipsoid([0.0; 3], [0.5; 3]).unwrap()).unwrap();
        let b2 = c.add_body("r2", ellipsoid([0.0; 3], [0.25; 3]).unwrap()).unwrap();
        scene = c.create_scene("s").unwrap();
        i1 = c.add_instance(&scene, &b1, at(0.0)).unwrap();
        i2 = c.add_instance(&scene, &b2, at(2.0)).unwrap();
        // Spheres: distance = ‖c₁ − c₂‖ − r₁ − r₂.
        let d = c.distance(&scene, &i1, &i2).unwrap();
        assert!((d.distance - 1.25).abs() < 1e-9, "{}", d.distance);
        assert!(!d.warm_started);
        // A step of 0.2 m, within the warm start's reach (half the summed scales).
        c.set_poses(&scene, &[(i2.clone(), at(1.8))]).unwrap();
        let d = c.distance(&scene, &i1, &i2).unwrap();
        assert!((d.distance - 1.05).abs() < 1e-9, "{}", d.distance);
        assert!(d.warm_started);
        // Growth of spheres: (‖c₁ − c₂‖ − r₂)² / r₁².
        let g = c.growth(&scene, &i1, &i2).unwrap();
        assert!((g.value - (1.55f64 / 0.5).powi(2)).abs() < 1e-9, "{}", g.value);
        assert_eq!(c.cached_warm_starts(&scene).unwrap(), 2);
        // A bad batch entry changes nothing; an unknown instance is NotFound.
        let err = c.set_poses(&scene, &[(i2.clone(), at(9.0)), ("i-nope".into(), at(0.0))]).unwrap_err();
        assert!(err.to_string().contains("poses[1].instance_id"), "{err}");
        assert!(matches!(c.distance(&scene, &i1, "i-nope"), Err(Error::NotFound { .. })));
        // The body is in use.
        assert!(
            matches!(c.delete_body(&b1), Err(Error::FailedPrecondition(m)) if m.contains("remove the instance first"))
        );
    }
    let c = open(dir.path());
    let v = c.get_scene(&scene).unwrap();
    assert_eq!(v.instances.len(), 2);
    let p2 = v.instances.iter().find(|i| i.id == i2).unwrap().pose;
    assert!((p2.translation.vector.x - 1.8).abs() < 1e-15, "the failed batch must not have moved i2");
    assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0, "warm starts are memory only");
    let d = c.distance(&scene, &i1, &i2).unwrap();
    assert!((d.distance - 1.05).abs() < 1e-9);
    c.remove_instance(&scene, &i1).unwrap();
    assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0);
    c.delete_scene(&scene).unwrap();
    assert!(matches!(c.get_scene(&scene), Err(Error::NotFound { .. })));
    drop(c);
    let c = open(dir.path());
    assert!(c.get_scene(&scene).is_err());
    assert_eq!(c.bodies().len(), 2);
}

/// A dumbbell containment tree: root sphere r = 1 at the origin containing spheres r = 0.4 at
/// x = ±0.5.
fn dumbbell() -> CompoundBody {
    use sublevel_core::compound::{CompoundNode, CompoundReport};
    let node = |c: [f64; 3], r: f64, children: Vec<usize>, depth: usize| CompoundNode {
        body: ellipsoid(c, [r; 3]).unwrap(),
        children,
        depth,
        excess: 0.0,
        triangles: 0,
        fit_seconds: 0.0,
    };
    let nodes = vec![
        node([0.0; 3], 1.0, vec![1, 2], 0),
        node([-0.5, 0.0, 0.0], 0.4, vec![], 1),
        node([0.5, 0.0, 0.0], 0.4, vec![], 1),
    ];
    CompoundBody::new(nodes, 0, CompoundReport::default()).unwrap()
}

/// A record written before compound bodies (`{name, body}`, no `compound` field) still loads as
/// the single body it is; a compound body survives a reopen with its whole tree, and its queries
/// answer the closed form (sphere distances) with a tree warm start kept per instance pair.
#[test]
fn old_single_records_load_and_compound_bodies_survive_a_reopen() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = ellipsoid([0.0; 3], [0.3; 3]).unwrap();
    // The single-body record form (`{name, body}`), as JSON text.
    let old = format!(r#"{{"name":"old","body":{}}}"#, serde_json::to_string(&sphere.to_file()).unwrap());
    let rec: BodyRecord = serde_json::from_str(&old).unwrap();
    assert!(rec.compound.is_none());
    assert!(!serde_json::to_string(&rec).unwrap().contains("compound"), "single records keep the old form");
    let (scene, a, b, old_id, tree_id);
    {
        let store = RedbStore::open_dir(dir.path()).unwrap();
        store.put_body("b-old", &rec).unwrap();
        drop(store);
        let c = open(dir.path());
        old_id = "b-old".to_owned();
        assert!(c.body(&old_id).unwrap().tree.is_none());
        tree_id = c.add_compound_body("dumbbell", dumbbell()).unwrap();
        scene = c.create_scene("s").unwrap();
        a = c.add_instance(&scene, &tree_id, at(0.0)).unwrap();
        b = c.add_instance(&scene, &old_id, at(2.0)).unwrap();
    }
    let c = open(dir.path());
    assert_eq!(c.quarantined(), 0);
    let entry = c.body(&tree_id).unwrap();
    assert_eq!(entry.node_count(), 3);
    assert_eq!(c.body(&old_id).unwrap().node_count(), 1);
    assert!(c.has_compound(&scene));
    // Closest: the +x part, 2 − 0.5 − 0.4 − 0.3 = 0.8 (the root alone says 0.7).
    let d = c.distance_with(&scene, &a, &b, &QueryOptions::default()).unwrap();
    let t = d.tree.unwrap();
    assert!((d.answer.result.distance - 0.8).abs() < 1e-7, "{}", d.answer.result.distance);
    assert!((t.upper - 0.8).abs() < 1e-7 && t.level == 1 && t.leaves == Some((2, 0)), "{t:?}");
    assert!(d.answer.converged);
    assert_eq!(c.cached_warm_starts(&scene).unwrap(), 1, "one tree warm start for the pair");
    // The reverse pair: the same distance, node ids swapped.
    let d = c.distance_with(&scene, &b, &a, &QueryOptions::default()).unwrap();
    assert!((d.answer.result.distance - 0.8).abs() < 1e-7);
    assert_eq!(d.tree.unwrap().leaves, Some((0, 2)));
    // Growth: separated (no leaf pair overlaps) → +∞.
    let g = c.growth_with(&scene, &a, &b, &QueryOptions::default()).unwrap();
    assert!(g.answer.result.value.is_infinite() && g.answer.converged);
    c.remove_instance(&scene, &b).unwrap();
    assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0, "tree warm starts go with their instance");
}
