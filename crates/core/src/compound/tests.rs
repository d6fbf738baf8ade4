use super::*;
use crate::body::ellipsoid;
use crate::math::Point3;
use crate::Error;

/// Two unit spheres at x = ±2 under a sphere of radius 3.5 at the origin (which contains both:
/// the farthest point of a child is 3 from the origin).
fn three_node_tree() -> CompoundBody {
    let leaf = |x: Real, excess: Real| CompoundNode {
        body: ellipsoid([x, 0.0, 0.0], [1.0; 3]).unwrap(),
        children: vec![],
        depth: 1,
        excess,
        triangles: 10,
        fit_seconds: 0.25,
    };
    let root = CompoundNode {
        body: ellipsoid([0.0; 3], [3.5; 3]).unwrap(),
        children: vec![0, 1],
        depth: 0,
        excess: 1.5,
        triangles: 20,
        fit_seconds: 1.0,
    };
    let report = CompoundReport { mesh: Some("two_balls".into()), mesh_triangles: 20, ..Default::default() };
    CompoundBody::new(vec![leaf(-2.0, 0.0), leaf(2.0, 0.125), root], 2, report).unwrap()
}

fn expect_invalid<T: std::fmt::Debug>(r: Result<T>, field: &str, needle: &str) {
    match r {
        Err(Error::InvalidArgument { field: f, reason }) => {
            assert_eq!(f, field, "reason: {reason}");
            assert!(reason.contains(needle), "`{reason}` lacks `{needle}`");
        }
        other => panic!("expected InvalidArgument on {field}, got {other:?}"),
    }
}

#[test]
fn single_body_is_a_one_node_tree() {
    let c = CompoundBody::single(ellipsoid([1.0, 2.0, 3.0], [1.0, 2.0, 0.5]).unwrap());
    assert_eq!((c.root(), c.node_count(), c.depth(0), c.height(), c.leaf_count()), (0, 1, 0, 0, 1));
    assert!(c.children(0).is_empty());
    assert_eq!(c.leaves().collect::<Vec<_>>(), vec![0]);
    assert!(c.node(0).excess.is_nan());
    // The ellipsoid's boundary point (1, 2 + 2, 3) has p = 1 (closed form).
    assert!((c.body(0).value_at(&Point3::new(1.0, 4.0, 3.0)) - 1.0).abs() < 1e-12);
}

#[test]
fn tree_accessors_and_file_round_trip() {
    let c = three_node_tree();
    assert_eq!(c.root(), 2);
    assert_eq!(c.children(2), &[0, 1]);
    assert_eq!(c.leaves().collect::<Vec<_>>(), vec![0, 1]);
    assert_eq!((c.height(), c.depth(0), c.depth(2)), (1, 1, 0));
    assert_eq!(c.max_leaf_excess(), 0.125);

    let dir = std::env::temp_dir().join(format!("sublevel-compound-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tree.json");
    c.save(&path).unwrap();
    let back = CompoundBody::load(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!((back.root(), back.node_count()), (2, 3));
    assert_eq!(back.report, c.report);
    for i in 0..3 {
        let (a, b) = (c.node(i), back.node(i));
        assert_eq!(
            (&a.children, a.depth, a.excess, a.triangles, a.fit_seconds),
            (&b.children, b.depth, b.excess, b.triangles, b.fit_seconds)
        );
        // Same set: p agrees at probe points (closed form: |x − c|² / r² for the spheres).
        for x in [Point3::new(0.3, -0.2, 0.9), Point3::new(2.5, 0.0, 0.0), Point3::new(-3.0, 1.0, 0.0)] {
            assert!((a.body.value_at(&x) - b.body.value_at(&x)).abs() < 1e-12);
        }
    }
    // Sphere of radius 1 at x = 2: p(2.5, 0, 0) = 0.25.
    assert!((back.body(1).value_at(&Point3::new(2.5, 0.0, 0.0)) - 0.25).abs() < 1e-12);
}

#[test]
fn single_body_file_loads_as_one_node_tree_and_compound_file_is_not_a_body_file() {
    let demo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("data/demo/chair_101.json");
    let body = crate::Body::load(&demo).unwrap();
    let c = CompoundBody::load(&demo).unwrap();
    assert_eq!(c.node_count(), 1);
    let x = body.interior_point();
    assert_eq!(c.body(c.root()).value_at(&x), body.value_at(&x));

    let text = serde_json::to_string(&three_node_tree().to_file()).unwrap();
    let as_body: std::result::Result<crate::body::BodyFile, _> = serde_json::from_str(&text);
    assert!(as_body.unwrap_err().to_string().contains("missing field"));
}

#[test]
fn unmeasured_excess_is_null_in_the_file() {
    let c = CompoundBody::single(ellipsoid([0.0; 3], [1.0; 3]).unwrap());
    let v = serde_json::to_value(c.to_file()).unwrap();
    assert!(v["nodes"][0]["excess"].is_null());
    assert_eq!(v["format"], COMPOUND_FORMAT);
    let back = CompoundBody::from_json(&v.to_string()).unwrap();
    assert!(back.node(0).excess.is_nan());
}

#[test]
fn malformed_trees_are_refused_naming_the_field() {
    let good = three_node_tree().to_file();
    let edit = |f: &dyn Fn(&mut CompoundFile)| {
        let mut file = good.clone();
        f(&mut file);
        CompoundBody::from_file(file)
    };
    expect_invalid(edit(&|f| f.root = 7), "root", "only 3 nodes");
    expect_invalid(edit(&|f| f.nodes.clear()), "nodes", "at least one node");
    expect_invalid(edit(&|f| f.format = "v0".into()), "format", COMPOUND_FORMAT);
    expect_invalid(edit(&|f| f.nodes[2].children = vec![0, 9]), "nodes[2].children[1]", "only 3 nodes");
    expect_invalid(edit(&|f| f.nodes[2].children = vec![0, 0]), "nodes[2].children[1]", "already has parent");
    expect_invalid(edit(&|f| f.nodes[0].children = vec![2]), "nodes[0].children[0]", "names the root");
    expect_invalid(edit(&|f| f.nodes[2].children = vec![0]), "nodes", "node 1 is neither the root");
    expect_invalid(edit(&|f| f.nodes[1].depth = 3), "nodes[1].depth", "parent's depth + 1 = 1");
    expect_invalid(edit(&|f| f.nodes[2].depth = 1), "nodes[2].depth", "root's depth must be 0");
    expect_invalid(edit(&|f| f.nodes[1].excess = Some(-0.5)), "nodes[1].excess", "≥ 0");
    expect_invalid(edit(&|f| f.nodes[0].body.scale = -1.0), "nodes[0].body.scale", "> 0");
    // A cycle detached from the root: 0 ↔ 1, root 2 alone.
    expect_invalid(
        edit(&|f| {
            f.nodes[2].children.clear();
            f.nodes[0].children = vec![1];
            f.nodes[1].children = vec![0];
        }),
        "nodes",
        "cycle not reachable",
    );
}

#[test]
fn json_errors_surface_as_json_errors() {
    assert!(matches!(CompoundBody::from_json("{\"nodes\": 3}"), Err(Error::Json(_))));
    assert!(matches!(CompoundBody::from_json("not json"), Err(Error::Json(_))));
}
