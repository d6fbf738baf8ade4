//! The catalog against a real redb store: persistence across reopen, warm starts that follow
//! their pair, all-or-nothing pose batches, bodies built on first use or by the warm-up, and
//! stored bodies that no longer validate.

use super::*;
use crate::answer::{QueryKind, QueryOptions, QueryPair};
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
pub(super) fn dumbbell() -> CompoundBody {
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
        assert!(c.body(&old_id).unwrap().built().unwrap().tree.is_none());
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

/// A fitted body stored with its mesh answers the mesh from its entry, also after a reopen
/// (read from the record, without building the body); a bad mesh is refused before anything is
/// written. A named instance registers its planning name and respects the scene's limit.
#[test]
fn a_fitted_body_keeps_its_mesh_and_named_instances_keep_their_names() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = MeshRecord {
        vertices: vec![[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.5]],
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
    };
    let (tree_id, scene, named);
    {
        let c = open(dir.path());
        let bad = MeshRecord { triangles: vec![[0, 1, 4]], ..mesh.clone() };
        let e = c.add_fitted_body("bad", dumbbell(), Some(bad)).unwrap_err();
        assert!(e.to_string().contains("mesh.triangles[0]"), "{e}");
        assert!(c.bodies().is_empty());
        tree_id = c.add_fitted_body("crate", dumbbell(), Some(mesh.clone())).unwrap();
        assert_eq!(c.body(&tree_id).unwrap().mesh().map(|m| m.as_ref()), Some(&mesh));
        let plain = c.add_compound_body("plain", dumbbell()).unwrap();
        assert!(c.body(&plain).unwrap().mesh().is_none());
        scene = c.create_scene("s").unwrap();
        named = c.add_named_instance(&scene, &tree_id, at(1.0), "crate#1", 2).unwrap();
        c.add_instance(&scene, &plain, at(5.0)).unwrap();
        let e = c.add_named_instance(&scene, &tree_id, at(2.0), "crate#2", 2).unwrap_err();
        assert!(matches!(e, Error::ResourceExhausted(_)), "{e}");
        let view = c.get_scene(&scene).unwrap();
        assert_eq!(view.instances.len(), 2);
        assert_eq!(view.planning.names.get(&named).map(String::as_str), Some("crate#1"));
    }
    let c = open(dir.path());
    let entry = c.body(&tree_id).unwrap();
    assert!(!entry.is_settled(), "not built by the reopen");
    assert_eq!(entry.mesh().map(|m| m.as_ref()), Some(&mesh));
    assert_eq!(entry.node_count(), 3);
    let view = c.get_scene(&scene).unwrap();
    assert_eq!(view.planning.names.get(&named).map(String::as_str), Some("crate#1"));
    assert_eq!(view.instances.iter().find(|i| i.id == named).unwrap().pose.translation.vector.x, 1.0);
}

/// A store with three sphere bodies, the dumbbell compound body and one instance of each in one
/// scene (x = 0, 3, 6, 9); returns the scene id and the instance ids in that order.
fn store_with_bodies(dir: &std::path::Path) -> (String, Vec<String>) {
    let c = open(dir);
    let mut bodies: Vec<String> =
        [0.3, 0.4, 0.5].iter().map(|&r| c.add_body("s", ellipsoid([0.0; 3], [r; 3]).unwrap()).unwrap()).collect();
    bodies.push(c.add_compound_body("dumbbell", dumbbell()).unwrap());
    let scene = c.create_scene("s").unwrap();
    let ids = bodies.iter().enumerate().map(|(k, b)| c.add_instance(&scene, b, at(3.0 * k as f64)).unwrap()).collect();
    (scene, ids)
}

/// Opening builds no body; a query builds exactly the bodies it uses and answers what a warmed
/// catalog answers, to the last bit; the warm-up builds the rest, once.
#[test]
fn bodies_build_on_first_use_and_the_warm_up_builds_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, ids) = store_with_bodies(dir.path());
    let pairs = [(0, 1), (1, 3), (3, 2)];
    let warmed: Vec<(f64, f64)> = {
        let c = open(dir.path());
        let w = c.warm_up();
        assert_eq!((w.built, w.quarantined, w.stopped), (4, 0, false));
        assert_eq!(c.bodies_built(), (4, 4));
        pairs
            .iter()
            .map(|&(a, b)| {
                let d = c.distance_with(&scene, &ids[a], &ids[b], &QueryOptions::default()).unwrap();
                (d.answer.result.distance, c.growth(&scene, &ids[a], &ids[b]).unwrap().value)
            })
            .collect()
    };
    let c = open(dir.path());
    assert_eq!(c.bodies_built(), (0, 4), "opening builds no body");
    assert_eq!(c.bodies_pending(), 4);
    // Facts need no build.
    assert!(c.has_compound(&scene) && !c.has_nonconvex(&scene));
    assert_eq!(c.bodies().iter().map(|e| e.node_count()).max(), Some(3));
    assert_eq!(c.bodies_built(), (0, 4));
    let d = c.distance_with(&scene, &ids[0], &ids[1], &QueryOptions::default()).unwrap();
    assert_eq!(c.bodies_built(), (2, 4), "the query built its two bodies, no other");
    let g = c.growth(&scene, &ids[0], &ids[1]).unwrap();
    assert_eq!((d.answer.result.distance, g.value), warmed[0]);
    assert_eq!(c.bodies_built(), (2, 4));
    let w = c.warm_up();
    assert_eq!((w.built, w.quarantined), (2, 0), "the warm-up builds only what was not built");
    assert_eq!((c.bodies_built(), c.bodies_pending()), ((4, 4), 0));
    for (k, &(a, b)) in pairs.iter().enumerate().skip(1) {
        let d = c.distance_with(&scene, &ids[a], &ids[b], &QueryOptions::default()).unwrap();
        let g = c.growth(&scene, &ids[a], &ids[b]).unwrap();
        assert_eq!((d.answer.result.distance, g.value), warmed[k], "pair {k}");
    }
    assert_eq!(c.warm_up().built, 0);
}

/// Concurrent first users of a body wait for one build: every one gets the same body.
#[test]
fn concurrent_first_uses_build_a_body_once() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, ids) = store_with_bodies(dir.path());
    let c = open(dir.path());
    let id = c.get_scene(&scene).unwrap().instances[3].body_id.clone();
    let entry = c.body(&id).unwrap();
    let built: Vec<usize> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..4)
            .map(|_| s.spawn(|| Arc::as_ptr(&entry.built().unwrap().body) as usize))
            .chain([s.spawn(|| {
                c.warm_up();
                Arc::as_ptr(&entry.built().unwrap().body) as usize
            })])
            .collect();
        workers.into_iter().map(|w| w.join().unwrap()).collect()
    });
    assert!(built.windows(2).all(|w| w[0] == w[1]), "{built:?}");
    assert_eq!((c.bodies_built(), c.bodies_pending()), ((4, 4), 0));
    assert!(c.distance(&scene, &ids[0], &ids[3]).is_ok());
}

/// A sphere whose polynomial is negated: −(u² + v² + w²) has no minimizer, so the body no longer
/// validates (the record itself reads back fine).
fn invalid_record() -> BodyRecord {
    let mut file = ellipsoid([0.0; 3], [0.5; 3]).unwrap().to_file();
    for c in &mut file.coefficients {
        *c = -*c;
    }
    assert!(Body::from_file(file.clone()).is_err());
    BodyRecord::single("bad", file)
}

/// A stored body that no longer validates is found when it is built — by the first query that
/// needs it, or by the warm-up: its record moves to the quarantine (kept), every query that needs
/// it answers FAILED_PRECONDITION naming it, and the other bodies still answer.
#[test]
fn a_stored_body_that_does_not_validate_is_quarantined_when_built() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, ids) = store_with_bodies(dir.path());
    let add_bad = |body_id: &str, instance_id: &str| {
        let store = RedbStore::open_dir(dir.path()).unwrap();
        store.put_body(body_id, &invalid_record()).unwrap();
        let rec = InstanceRecord { body_id: body_id.to_owned(), pose: StoredPose::from_isometry(&at(12.0)) };
        store.put_instances(&scene, &[(instance_id, &rec)], false).unwrap();
    };
    add_bad("b-bad", "i-bad");
    {
        let c = open(dir.path());
        assert_eq!(c.quarantined(), 0, "nothing is validated at open");
        assert_eq!(c.bodies_built(), (0, 5));
        assert_eq!(c.body("b-bad").unwrap().facts().degree, 2);
        // First use: quarantined, answered with an error naming it.
        for _ in 0..2 {
            let err = c.distance(&scene, &ids[0], "i-bad").unwrap_err();
            assert!(
                matches!(&err, Error::FailedPrecondition(m) if m.contains("b-bad") && m.contains("quarantine")),
                "{err}"
            );
        }
        assert_eq!(c.quarantined(), 1, "quarantined once");
        let pair = |a: &str, b: &str| QueryPair {
            kind: QueryKind::Distance,
            first: a.to_owned(),
            second: b.to_owned(),
            options: QueryOptions::default(),
            margin: 0.0,
        };
        let batch = [pair(&ids[1], &ids[2]), pair(&ids[2], "i-bad")];
        assert!(matches!(c.batch(&scene, &batch), Err(Error::FailedPrecondition(m)) if m.contains("b-bad")));
        assert!(matches!(c.posed_instances(&scene, &[]), Err(Error::FailedPrecondition(m)) if m.contains("b-bad")));
        assert!(matches!(c.body("b-bad").unwrap().built(), Err(Error::FailedPrecondition(m)) if m.contains("b-bad")));
        // The others still answer.
        assert!((c.distance(&scene, &ids[0], &ids[1]).unwrap().distance - 2.3).abs() < 1e-9);
        let w = c.warm_up();
        assert_eq!(w.quarantined, 0, "found by the query, not again by the warm-up");
        assert_eq!(c.bodies_built(), (4, 5));
        assert_eq!(c.quarantined(), 1);
    }
    // Found by the warm-up this time.
    add_bad("b-bad2", "i-bad2");
    {
        let c = open(dir.path());
        assert_eq!(c.quarantined(), 1, "the first one is still in the quarantine");
        let w = c.warm_up();
        assert_eq!((w.built, w.quarantined), (4, 1));
        assert_eq!(c.quarantined(), 2);
        let err = c.growth(&scene, "i-bad2", &ids[0]).unwrap_err();
        assert!(matches!(&err, Error::FailedPrecondition(m) if m.contains("b-bad2")), "{err}");
        assert!(c.distance(&scene, &ids[3], &ids[2]).is_ok());
    }
    // Both records are kept in the quarantine, out of the bodies table.
    let store = RedbStore::open_dir(dir.path()).unwrap();
    let q = store.quarantined().unwrap();
    let keys: Vec<&str> = q.iter().map(|r| r.key.as_str()).collect();
    assert_eq!(keys, ["b-bad", "b-bad2"]);
    assert!(q.iter().all(|r| r.reason.contains("does not validate") && r.text.contains("\"name\":\"bad\"")), "{q:?}");
    assert!(store.get_body("b-bad").unwrap().is_none());
    drop(store);
    let c = open(dir.path());
    assert_eq!((c.quarantined(), c.bodies().len()), (2, 4));
}
