//! Integration tests: exact primitives on the command line. `sublevel primitive` writes and
//! validates primitive files; `sublevel query distance` answers them against primitives and single
//! bodies with `query::shape::shape_distance`, checked against closed forms and against the library
//! call itself, and refuses what it does not answer (compound bodies, growth, `--certify`).

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Output;
use sublevel::body::ellipsoid;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::primitive::{Primitive, PrimitiveFile};
use sublevel::query::shape::{shape_distance, ShapeRef};
use sublevel::Body;

/// Runs `sublevel ARGS…`.
fn sublevel(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sublevel")).args(args).output().unwrap()
}

/// `sublevel primitive SHAPE DIMS… --output DIR/NAME.json`, which must succeed; the file's path.
fn primitive(dir: &Path, name: &str, shape: &[&str]) -> String {
    let path = dir.join(format!("{name}.json"));
    let path = path.to_str().unwrap().to_owned();
    let out = sublevel(&[&["primitive"], shape, &["--output", &path]].concat());
    assert!(out.status.success(), "{shape:?}: {}", String::from_utf8_lossy(&out.stderr));
    path
}

/// `sublevel query distance A B ARGS… --json`, which must succeed; its answer.
fn distance(a: &str, b: &str, args: &[&str]) -> Value {
    let out = sublevel(&[&["query", "distance", a, b], args, &["--json"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `sublevel ARGS…`, which must fail cleanly (non-zero exit, no panic); its stderr.
fn fails(args: &[&str]) -> String {
    let out = sublevel(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} succeeded: {}", String::from_utf8_lossy(&out.stdout));
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    stderr
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn point(v: &Value) -> [f64; 3] {
    [f(&v[0]), f(&v[1]), f(&v[2])]
}

fn repo_file(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn primitive_command_writes_validated_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.json");
    let p = path.to_str().unwrap();
    let out = sublevel(&["primitive", "box", "1", "2", "3", "--output", p]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&path).unwrap();
    let written: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(written, json!({"primitive": "box", "size": [1.0, 2.0, 3.0]}));
    assert_eq!(serde_json::from_str::<PrimitiveFile>(&text).unwrap(), PrimitiveFile::Box { size: [1.0, 2.0, 3.0] });
    let summary = String::from_utf8_lossy(&out.stdout);
    assert_eq!(summary.lines().count(), 1, "{summary}");
    assert!(summary.starts_with("box: size 1 × 2 × 3 m, volume 6.000000 m³"), "{summary}");

    // Every kind; negative numbers are values (a halfspace's normal), and the normal is normalized.
    let out = sublevel(&["primitive", "halfspace", "0", "0", "-2", "1", "--output", p]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(
        Primitive::load(&path).unwrap().to_file(),
        PrimitiveFile::Halfspace { normal: [0.0, 0.0, -1.0], offset: 0.5 }
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("volume unbounded"));
    for (shape, file) in [
        (&["sphere", "0.5"][..], PrimitiveFile::Sphere { radius: 0.5 }),
        (&["cylinder", "0.1", "0.4"][..], PrimitiveFile::Cylinder { radius: 0.1, height: 0.4 }),
        (&["capsule", "0.1", "0"][..], PrimitiveFile::Capsule { radius: 0.1, height: 0.0 }),
    ] {
        let out = sublevel(&[&["primitive"], shape, &["--output", p]].concat());
        assert!(out.status.success(), "{shape:?}: {}", String::from_utf8_lossy(&out.stderr));
        assert_eq!(Primitive::load(&path).unwrap().to_file(), file);
    }

    // Bad dimensions fail, naming the field, and write nothing.
    let bad = dir.path().join("bad.json");
    let b = bad.to_str().unwrap();
    for (shape, field) in [
        (&["box", "1", "-2", "3"][..], "`size[1]`"),
        (&["sphere", "nan"][..], "`radius`"),
        (&["cylinder", "1", "0"][..], "`height`"),
        (&["halfspace", "0", "0", "0", "1"][..], "`normal`"),
    ] {
        let stderr = fails(&[&["primitive"], shape, &["--output", b]].concat());
        assert!(stderr.contains(field), "{shape:?}: {stderr}");
        assert!(!bad.exists(), "{shape:?}");
    }
}

#[test]
fn primitive_pairs_match_closed_forms() {
    let dir = tempfile::tempdir().unwrap();
    let cube = primitive(dir.path(), "cube", &["box", "1", "1", "1"]);
    let box2 = primitive(dir.path(), "box2", &["box", "2", "2", "2"]);
    let ball = primitive(dir.path(), "ball", &["sphere", "1"]);
    let small = primitive(dir.path(), "small", &["sphere", "0.5"]);
    let floor = primitive(dir.path(), "floor", &["halfspace", "0", "0", "1", "0"]);

    // Two unit cubes 3 m apart: the faces x = 0.5 and x = 2.5 face each other, distance 2.
    let v = distance(&cube, &cube, &["--pose-b", "1,0,0,0,3,0,0"]);
    assert_eq!(f(&v["distance"]), 2.0, "{v}");
    let (wa, wb) = (point(&v["witness_a"]), point(&v["witness_b"]));
    assert!((wa[0] - 0.5).abs() <= 1e-12 && (wb[0] - 2.5).abs() <= 1e-12, "{v}");
    for w in [wa, wb] {
        assert!(w[1].abs() <= 0.5 + 1e-12 && w[2].abs() <= 0.5 + 1e-12, "{v}");
    }
    assert_eq!(point(&v["normal"]), [1.0, 0.0, 0.0], "{v}");
    assert_eq!((&v["query"], &v["overlapping"], &v["converged"]), (&json!("distance"), &json!(false), &json!(true)));
    assert_eq!((&v["method"], &v["status"]), (&json!("ActiveSet"), &json!("Converged")), "{v}");
    assert!((f(&v["certified_lower_bound"]) - 2.0).abs() <= 1e-12, "{v}");
    for field in ["iterations", "kkt_residual", "microseconds"] {
        assert!(v[field].is_number(), "{field}: {v}");
    }

    // A ball of radius 1 at the origin and a box of size 2 at x = 3: the face x = 2, distance 1.
    let v = distance(&ball, &box2, &["--pose-b", "1,0,0,0,3,0,0"]);
    assert_eq!(f(&v["distance"]), 1.0, "{v}");
    assert_eq!((point(&v["witness_a"]), point(&v["witness_b"])), ([1.0, 0.0, 0.0], [2.0, 0.0, 0.0]), "{v}");
    assert_eq!(v["method"], "ClosedForm");

    // The floor z ≤ 0 and a ball of radius 0.5 at z = 2: distance 1.5.
    let v = distance(&floor, &small, &["--pose-b", "1,0,0,0,0,0,2"]);
    assert_eq!(f(&v["distance"]), 1.5, "{v}");
    assert_eq!((point(&v["witness_a"]), point(&v["witness_b"])), ([0.0, 0.0, 0.0], [0.0, 0.0, 1.5]), "{v}");
    assert_eq!(v["method"], "ClosedForm");

    // Overlapping cubes: distance 0.
    let v = distance(&cube, &cube, &["--pose-b", "1,0,0,0,0.5,0.2,0"]);
    assert_eq!((f(&v["distance"]), &v["overlapping"]), (0.0, &json!(true)), "{v}");

    // Text output: one `field: value` line per field.
    let out = sublevel(&["query", "distance", &ball, &box2, "--pose-b", "1,0,0,0,3,0,0"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().any(|l| l.trim() == "distance: 1.0"), "{text}");
}

#[test]
fn primitive_against_body_files_matches_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let cube = primitive(dir.path(), "cube", &["box", "1", "1", "1"]);
    let cylinder = primitive(dir.path(), "cylinder", &["cylinder", "0.2", "0.6"]);

    // A sphere body (an ellipsoid fit of equal radii) of radius 0.3 against the unit cube 2 m
    // away: 2 − 0.5 − 0.3, both orders.
    let sphere = dir.path().join("sphere.json");
    ellipsoid([0.0; 3], [0.3; 3]).unwrap().save(&sphere).unwrap();
    let sphere = sphere.to_str().unwrap();
    let v = distance(&cube, sphere, &["--pose-b", "1,0,0,0,2,0,0"]);
    assert_eq!(v["converged"], true, "{v}");
    assert!((f(&v["distance"]) - 1.2).abs() < 1e-9, "{v}");
    // The separating plane through the body's support point certifies it.
    assert!((f(&v["certified_lower_bound"]) - 1.2).abs() < 1e-9, "{v}");
    let v = distance(sphere, &cube, &["--pose-a", "1,0,0,0,2,0,0"]);
    assert!((f(&v["distance"]) - 1.2).abs() < 1e-9, "{v}");

    // A fitted chair against a cylinder and a box far away, turned: the CLI answers what the library does.
    let chair = repo_file("data/demo/chair_101.json");
    let body = Body::load(&chair).unwrap();
    let chair = chair.to_str().unwrap();
    let q = [0.9238795, 0.0, 0.3826834, 0.0];
    let pose_a: Isometry3 = pose_from_parts("a", q, [0.0, 0.0, 0.0]).unwrap();
    let pose_b: Isometry3 = pose_from_parts("b", [1.0, 0.0, 0.0, 0.0], [4.0, 0.5, 0.0]).unwrap();
    for file in [&cylinder, &cube] {
        let p = Primitive::load(Path::new(file)).unwrap();
        let v = distance(chair, file, &["--pose-a", "0.9238795,0,0.3826834,0,0,0,0", "--pose-b", "1,0,0,0,4,0.5,0"]);
        let reference = shape_distance(ShapeRef::Body(&body), &pose_a, ShapeRef::Primitive(&p), &pose_b, None).unwrap();
        assert_eq!(v["converged"], true, "{v}");
        assert!(f(&v["distance"]) > 0.0, "{v}");
        assert!((f(&v["distance"]) - reference.distance).abs() <= 1e-12, "{v} {reference:?}");
        let wa = point(&v["witness_a"]);
        assert!((0..3).all(|i| (wa[i] - reference.witness_a[i]).abs() <= 1e-9), "{v} {reference:?}");
        assert_eq!(v["method"], "ActiveSet");
    }
}

#[test]
fn what_the_primitive_path_does_not_answer_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cube = primitive(dir.path(), "cube", &["box", "1", "1", "1"]);
    let floor = primitive(dir.path(), "floor", &["halfspace", "0", "0", "1", "0"]);
    let compound = repo_file("data/compound/chair_101.json");
    let compound = compound.to_str().unwrap();
    let body = repo_file("data/demo/chair_101.json");
    let body = body.to_str().unwrap();

    let stderr = fails(&["query", "distance", &cube, compound, "--pose-b", "1,0,0,0,3,0,0"]);
    assert!(stderr.contains("`b`") && stderr.contains("compound body is not supported yet"), "{stderr}");
    let stderr = fails(&["query", "distance", compound, &cube]);
    assert!(stderr.contains("`a`") && stderr.contains("compound body is not supported yet"), "{stderr}");
    let stderr = fails(&["query", "growth", &cube, body]);
    assert!(stderr.contains("sos-convex bodies only"), "{stderr}");
    let stderr = fails(&["query", "distance", &cube, body, "--certify"]);
    assert!(stderr.contains("`--certify`"), "{stderr}");
    let stderr = fails(&["query", "distance", &floor, &floor]);
    assert!(stderr.contains("two halfspaces"), "{stderr}");

    // A primitive file with a bad field names the side and the field.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"primitive": "box", "size": [1, -2, 3]}"#).unwrap();
    let stderr = fails(&["query", "distance", &cube, bad.to_str().unwrap()]);
    assert!(stderr.contains("`b.size[1]`"), "{stderr}");
}

/// Inside contact the answer's signed distance is minus the penetration depth (a sphere half sunk
/// into a box: closed form), and `--gradient` prints its pose gradients: the normal along the
/// translations.
#[test]
fn query_reports_the_signed_distance_and_its_gradient() {
    let dir = tempfile::tempdir().unwrap();
    let cube = primitive(dir.path(), "cube", &["box", "2", "2", "2"]);
    let ball = primitive(dir.path(), "ball", &["sphere", "0.5"]);
    // The ball's center 0.2 m inside the cube's +x face: depth 0.7 along +x.
    let v = distance(&cube, &ball, &["--pose-b", "1,0,0,0,0.8,0.1,0", "--gradient"]);
    assert!(v["overlapping"].as_bool().unwrap());
    assert!((f(&v["signed_distance"]) + 0.7).abs() < 1e-12, "{v}");
    assert!(v["signed_distance_converged"].as_bool().unwrap());
    let lin_b = point(&v["gradient_b"]["linear"]);
    assert!((lin_b[0] - 1.0).abs() < 1e-12 && lin_b[1].abs() < 1e-12 && lin_b[2].abs() < 1e-12, "{v}");
    let lin_a = point(&v["gradient_a"]["linear"]);
    assert!((lin_a[0] + 1.0).abs() < 1e-12, "{v}");
}
