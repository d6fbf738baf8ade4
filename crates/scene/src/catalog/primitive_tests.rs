//! Exact primitives in the catalog: stored beside their bounding ellipsoid, reopened, answered at
//! their closed forms and as `shape_distance` answers them directly, against fitted and compound
//! bodies, in scene checks and planner views; growth and two halfspaces refused naming the field.

use super::*;
use crate::answer::{QueryAnswer, QueryKind, QueryOptions, QueryPair};
use crate::planner::{check_scene, PlannerAnswers, PlannerRequest, QueryView};
use crate::store::RedbStore;
use sublevel_core::body::ellipsoid;
use sublevel_core::math::{pose_from_parts, Real, Vector3};
use sublevel_core::primitive::{Primitive, PrimitiveFile};
use sublevel_query::shape::{shape_distance, ShapeRef};

fn open(dir: &std::path::Path) -> Catalog {
    Catalog::open(Box::new(RedbStore::open_dir(dir).unwrap()), NewtonParams::default()).unwrap()
}

/// A pose: rotation by `angle` about z, then translation `t`.
fn pose(angle: Real, t: [Real; 3]) -> Isometry3 {
    let (s, c) = (0.5 * angle).sin_cos();
    pose_from_parts("pose", [c, 0.0, 0.0, s], t).unwrap()
}

fn prim(file: PrimitiveFile) -> Primitive {
    Primitive::from_file(&file).unwrap()
}

/// A unit cube and a ball r = 0.25: 2 m apart along x the distance is 2 − 0.5 − 0.25; with the
/// cube turned 45° about z its corner faces the ball, 2 − √½ − 0.25. Both equal `shape_distance`
/// on the same shapes; collide queries at margins either side of the distance, a far pair cleared
/// by the bounding spheres; the record keeps the primitive beside a bounding ellipsoid that builds
/// and contains the cube, and everything answers the same after a reopen.
#[test]
fn a_box_and_a_sphere_answer_their_closed_forms_and_survive_a_reopen() {
    let dir = tempfile::tempdir().unwrap();
    let cube = prim(PrimitiveFile::Box { size: [1.0; 3] });
    let ball = prim(PrimitiveFile::Sphere { radius: 0.25 });
    let (scene, a, b, box_id);
    {
        let c = open(dir.path());
        box_id = c.add_primitive("cube", cube).unwrap();
        let ball_id = c.add_primitive("ball", ball).unwrap();
        scene = c.create_scene("s").unwrap();
        a = c.add_instance(&scene, &box_id, pose(0.0, [0.0; 3])).unwrap();
        b = c.add_instance(&scene, &ball_id, pose(0.0, [2.0, 0.0, 0.0])).unwrap();
        let d = c.distance_with(&scene, &a, &b, &QueryOptions::default()).unwrap();
        assert!((d.answer.result.distance - 1.25).abs() < 1e-12, "{}", d.answer.result.distance);
        assert!(d.answer.converged && !d.answer.lower_bound && d.tree.is_none());
        assert!((d.answer.result.witness_a.x - 0.5).abs() < 1e-12);
        assert!((d.answer.result.witness_b.x - 1.75).abs() < 1e-12);
        let facts = c.body(&box_id).unwrap().facts().clone();
        assert_eq!((facts.primitive, facts.degree, facts.volume, facts.nodes), (Some("box"), 0, 1.0, 1));
    }
    let c = open(dir.path());
    assert_eq!(c.quarantined(), 0);
    c.set_poses(&scene, &[(a.clone(), pose(std::f64::consts::FRAC_PI_4, [0.0; 3]))]).unwrap();
    let d = c.distance_with(&scene, &a, &b, &QueryOptions { with_gradient: true, ..Default::default() }).unwrap();
    let want = 2.0 - 0.5f64.sqrt() - 0.25;
    assert!((d.answer.result.distance - want).abs() < 1e-12, "{} vs {want}", d.answer.result.distance);
    let direct = shape_distance(
        ShapeRef::Primitive(&cube),
        &pose(std::f64::consts::FRAC_PI_4, [0.0; 3]),
        ShapeRef::Primitive(&ball),
        &pose(0.0, [2.0, 0.0, 0.0]),
        None,
    )
    .unwrap();
    assert_eq!(d.answer.result.distance, direct.distance);
    assert_eq!(d.answer.result.witness_a, direct.witness_a);
    // The gradient of the distance in B's translation is the unit normal (+x here).
    let (_, gb) = d.gradients.unwrap();
    assert!((gb.linear - Vector3::x()).norm() < 1e-9, "{:?}", gb.linear);
    // A certificate: the separating plane, a lower bound within rounding of the distance.
    let cert = c
        .distance_with(
            &scene,
            &a,
            &b,
            &QueryOptions { mode: sublevel_query::CertifyMode::Certify, ..Default::default() },
        )
        .unwrap()
        .answer
        .certificate
        .unwrap();
    assert!(cert.verified && cert.agrees && (cert.bound.sqrt() - want).abs() < 1e-9, "{cert:?}");
    // Collide: within 1.1 m (the distance is 1.043) but not within 1.0 m.
    let collide = |margin: Real| QueryPair {
        kind: QueryKind::Collide,
        first: a.clone(),
        second: b.clone(),
        options: QueryOptions::default(),
        margin,
    };
    let answers = c.batch(&scene, &[collide(1.1), collide(1.0)]).unwrap();
    let flags: Vec<bool> = answers
        .iter()
        .map(|x| match x {
            QueryAnswer::Collide(r) => r.collides,
            _ => panic!("a collide answer"),
        })
        .collect();
    assert_eq!(flags, [true, false]);
    c.set_poses(&scene, &[(b.clone(), pose(0.0, [9.0, 0.0, 0.0]))]).unwrap();
    let QueryAnswer::Collide(far) = &c.batch(&scene, &[collide(0.1)]).unwrap()[0] else { panic!() };
    assert!(far.decided_by_bounds && !far.collides && far.distance <= 9.0 - 0.75);
    // The record: the primitive, and a bounding ellipsoid that builds and holds the cube's corners.
    let record = BodyRecord::primitive("cube", &cube).unwrap();
    assert_eq!(record.primitive, Some(PrimitiveFile::Box { size: [1.0; 3] }));
    let bound = Body::from_file(record.body).unwrap();
    for k in 0..8 {
        let corner = Vector3::from_fn(|i, _| if (k >> i) & 1 == 0 { -0.5 } else { 0.5 });
        assert!(bound.value_at(&corner.into()) <= 1.0 + 1e-12);
    }
}

/// A floor (halfspace z ≤ 0) under a box and a cylinder: their heights above it, exactly; two
/// floors are refused naming `instance_b`, growth with a primitive naming the primitive's field;
/// the halfspace's record body is one no reader builds (an older reader quarantines it).
#[test]
fn halfspaces_answer_heights_and_refuse_what_has_no_answer() {
    let dir = tempfile::tempdir().unwrap();
    let c = open(dir.path());
    let floor = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 2.0], offset: 0.0 });
    let floor_id = c.add_primitive("floor", floor).unwrap();
    let box_id = c.add_primitive("box", prim(PrimitiveFile::Box { size: [0.4, 0.4, 0.2] })).unwrap();
    let can_id = c.add_primitive("can", prim(PrimitiveFile::Cylinder { radius: 0.1, height: 0.3 })).unwrap();
    let fitted = c.add_body("ball", ellipsoid([0.0; 3], [0.2; 3]).unwrap()).unwrap();
    let s = c.create_scene("s").unwrap();
    let f = c.add_instance(&s, &floor_id, pose(0.0, [0.0; 3])).unwrap();
    let g = c.add_instance(&s, &floor_id, pose(0.0, [0.0, 0.0, -1.0])).unwrap();
    let bx = c.add_instance(&s, &box_id, pose(0.3, [1.0, 2.0, 0.5])).unwrap();
    let can = c.add_instance(&s, &can_id, pose(0.0, [0.0, 1.0, 0.2])).unwrap();
    let ball = c.add_instance(&s, &fitted, pose(0.0, [0.0, -1.0, 0.7])).unwrap();
    let height = |x: &str| c.distance(&s, &f, x).unwrap().distance;
    assert!((height(&bx) - 0.4).abs() < 1e-12);
    assert!((height(&can) - 0.05).abs() < 1e-12);
    assert!((height(&ball) - 0.5).abs() < 1e-9, "{}", height(&ball));
    // The fitted ball against the can's side, their centers level and 2 m apart: 2 − 0.2 − 0.1.
    c.set_poses(&s, &[(ball.clone(), pose(0.0, [0.0, -1.0, 0.2]))]).unwrap();
    let d = c.distance(&s, &ball, &can).unwrap();
    assert!((d.distance - 1.7).abs() < 1e-7, "{}", d.distance);
    match c.distance_with(&s, &f, &g, &QueryOptions::default()) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "instance_b");
            assert!(reason.contains("two halfspaces"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    match c.growth_with(&s, &bx, &ball, &QueryOptions::default()) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "instance_1");
            assert!(reason.contains("growth measure is defined for sos-convex bodies"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    let pairs = [QueryPair {
        kind: QueryKind::Growth,
        first: ball.clone(),
        second: can.clone(),
        options: QueryOptions::default(),
        margin: 0.0,
    }];
    assert!(matches!(c.batch(&s, &pairs), Err(Error::InvalidArgument { field, .. }) if field == "pairs[0].second"));
    let record = BodyRecord::primitive("floor", &floor).unwrap();
    assert!(Body::from_file(record.body).is_err(), "a halfspace's record body must not build");
    assert_eq!(c.body(&floor_id).unwrap().facts().primitive, Some("halfspace"));
}

/// A compound body (the dumbbell: spheres r = 0.4 at x = ±0.5 under a root r = 1) against a ball
/// primitive: the closest leaf's distance, with the leaf and level in the tree answer.
#[test]
fn a_compound_body_against_a_primitive_answers_with_its_closest_leaf() {
    let dir = tempfile::tempdir().unwrap();
    let c = open(dir.path());
    let tree = c.add_compound_body("dumbbell", super::tests::dumbbell()).unwrap();
    let ball = c.add_primitive("ball", prim(PrimitiveFile::Sphere { radius: 0.3 })).unwrap();
    let s = c.create_scene("s").unwrap();
    let a = c.add_instance(&s, &tree, pose(0.0, [0.0; 3])).unwrap();
    let b = c.add_instance(&s, &ball, pose(0.0, [2.0, 0.0, 0.0])).unwrap();
    for (first, second, leaves) in [(&a, &b, (2, 0)), (&b, &a, (0, 2))] {
        let d = c.distance_with(&s, first, second, &QueryOptions::default()).unwrap();
        // 2 − 0.5 − 0.4 − 0.3: the +x part (the root alone would say 0.7).
        assert!((d.answer.result.distance - 0.8).abs() < 1e-9, "{}", d.answer.result.distance);
        let t = d.tree.unwrap();
        assert_eq!((t.leaves, t.level), (Some(leaves), 1));
        assert!(d.answer.converged && t.within_tolerance);
    }
}

/// A scene check over a floor, a second floor, three boxes and a fitted ball finds exactly the
/// pairs that `shape_distance` puts within the margin, never the two floors.
#[test]
fn a_scene_check_finds_what_the_shape_queries_find() {
    let dir = tempfile::tempdir().unwrap();
    let c = open(dir.path());
    let floor = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: 0.0 });
    let cube = prim(PrimitiveFile::Box { size: [0.5; 3] });
    let ball = ellipsoid([0.0; 3], [0.2; 3]).unwrap();
    let ids = (c.add_primitive("floor", floor).unwrap(), c.add_primitive("cube", cube).unwrap());
    let ball_id = c.add_body("ball", ball.clone()).unwrap();
    let s = c.create_scene("s").unwrap();
    let placed: Vec<(String, Option<Primitive>, Isometry3)> = vec![
        (ids.0.clone(), Some(floor), pose(0.0, [0.0; 3])),
        (ids.0.clone(), Some(floor), pose(0.0, [5.0, 0.0, -0.5])),
        (ids.1.clone(), Some(cube), pose(0.2, [0.0, 0.0, 0.27])),
        (ids.1.clone(), Some(cube), pose(0.5, [0.6, 0.0, 0.3])),
        (ids.1.clone(), Some(cube), pose(0.0, [3.0, 3.0, 2.0])),
        (ball_id, None, pose(0.0, [0.0, 0.5, 0.6])),
    ];
    let inst: Vec<String> = placed.iter().map(|(b, _, p)| c.add_instance(&s, b, *p).unwrap()).collect();
    let margin = 0.1;
    let check = check_scene(&c, &s, margin, &[], &[]).unwrap();
    let mut found: Vec<(String, String)> = check.pairs.iter().map(|p| (p.first.clone(), p.second.clone())).collect();
    found.sort();
    let mut want = Vec::new();
    for i in 0..placed.len() {
        for j in i + 1..placed.len() {
            let shape = |k: usize| match &placed[k].1 {
                Some(p) => ShapeRef::Primitive(p),
                None => ShapeRef::Body(&ball),
            };
            let Ok(d) = shape_distance(shape(i), &placed[i].2, shape(j), &placed[j].2, None) else { continue };
            if d.overlapping || d.distance < margin {
                let (x, y) = (inst[i].clone(), inst[j].clone());
                want.push(if x < y { (x, y) } else { (y, x) });
            }
        }
    }
    want.sort();
    assert_eq!(found, want);
    assert!(found.len() >= 3, "{found:?}");
    assert!(check.pairs.iter().all(|p| p.distance.answer.converged));
}

/// A planner view answers collide queries with primitives per candidate state, and refuses a
/// growth query with a primitive naming `queries[k].first` before its pose updates apply.
#[test]
fn a_planner_view_answers_primitives_and_refuses_growth_before_moving() {
    let dir = tempfile::tempdir().unwrap();
    let c = open(dir.path());
    let cube = c.add_primitive("cube", prim(PrimitiveFile::Box { size: [1.0; 3] })).unwrap();
    let cap = c.add_primitive("cap", prim(PrimitiveFile::Capsule { radius: 0.1, height: 0.4 })).unwrap();
    let s = c.create_scene("s").unwrap();
    let a = c.add_instance(&s, &cube, pose(0.0, [0.0; 3])).unwrap();
    let b = c.add_instance(&s, &cap, pose(0.0, [1.0, 0.0, 0.0])).unwrap();
    let mut view = QueryView::new(&s);
    let collide = QueryPair {
        kind: QueryKind::Collide,
        first: a.clone(),
        second: b.clone(),
        options: QueryOptions::default(),
        margin: 0.05,
    };
    // States: the capsule (axis along z) at x = 1.0, 0.63, 0.58: gaps 0.4, 0.03, overlap.
    let states = [1.0, 0.63, 0.58].iter().map(|x| vec![(b.clone(), pose(0.0, [*x, 0.0, 0.0]))]).collect();
    let request = PlannerRequest {
        queries: vec![collide],
        states: crate::planner::CandidateStates::Lists(states),
        ..Default::default()
    };
    let PlannerAnswers::PerState(answers) = view.run(&c, &request).unwrap() else { panic!() };
    let flags: Vec<bool> = answers
        .iter()
        .map(|a| match &a[0] {
            QueryAnswer::Collide(r) => r.collides,
            _ => panic!(),
        })
        .collect();
    assert_eq!(flags, [false, true, true]);
    let growth = QueryPair {
        kind: QueryKind::Growth,
        first: a.clone(),
        second: b.clone(),
        options: QueryOptions::default(),
        margin: 0.0,
    };
    let moved = PlannerRequest {
        poses: vec![(b.clone(), pose(0.0, [5.0, 0.0, 0.0]))],
        queries: vec![growth],
        ..Default::default()
    };
    match view.run(&c, &moved) {
        Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "queries[0].first"),
        other => panic!("{other:?}"),
    }
    // The pose update did not apply: the capsule is still at x = 1 in the view.
    let distance = QueryPair { kind: QueryKind::Distance, margin: 0.0, ..request.queries[0].clone() };
    let PlannerAnswers::Single(answers) =
        view.run(&c, &PlannerRequest { queries: vec![distance], ..Default::default() }).unwrap()
    else {
        panic!()
    };
    let QueryAnswer::Distance(d) = &answers[0] else { panic!() };
    assert!((d.answer.result.distance - 0.4).abs() < 1e-12, "{}", d.answer.result.distance);
}

/// Warm starts of a primitive pair with a curved side are kept per ordered pair and used on the
/// next query; a cold query neither reads nor keeps one.
#[test]
fn primitive_pairs_keep_their_warm_starts() {
    let dir = tempfile::tempdir().unwrap();
    let c = open(dir.path());
    let cube = c.add_primitive("cube", prim(PrimitiveFile::Box { size: [1.0; 3] })).unwrap();
    let can = c.add_primitive("can", prim(PrimitiveFile::Cylinder { radius: 0.2, height: 1.0 })).unwrap();
    let s = c.create_scene("s").unwrap();
    let a = c.add_instance(&s, &cube, pose(0.3, [0.0; 3])).unwrap();
    let b = c.add_instance(&s, &can, pose(0.0, [1.2, 0.3, 0.2])).unwrap();
    let cold = QueryOptions { cold: true, ..Default::default() };
    c.distance_with(&s, &a, &b, &cold).unwrap();
    assert_eq!(c.cached_warm_starts(&s).unwrap(), 0);
    let first = c.distance(&s, &a, &b).unwrap();
    assert_eq!(c.cached_warm_starts(&s).unwrap(), 1);
    c.set_poses(&s, &[(b.clone(), pose(0.01, [1.21, 0.3, 0.2]))]).unwrap();
    let next = c.distance(&s, &a, &b).unwrap();
    assert!(!first.warm_started && next.warm_started);
    let direct = shape_distance(
        ShapeRef::Primitive(&prim(PrimitiveFile::Box { size: [1.0; 3] })),
        &pose(0.3, [0.0; 3]),
        ShapeRef::Primitive(&prim(PrimitiveFile::Cylinder { radius: 0.2, height: 1.0 })),
        &pose(0.01, [1.21, 0.3, 0.2]),
        None,
    )
    .unwrap();
    assert!((next.distance - direct.distance).abs() < 1e-12, "{} vs {}", next.distance, direct.distance);
    c.remove_instance(&s, &b).unwrap();
    assert_eq!(c.cached_warm_starts(&s).unwrap(), 0);
}
