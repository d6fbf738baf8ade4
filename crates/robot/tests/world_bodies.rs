//! Sos-convex bodies as world objects (a cloud's bodies model, `WorldShape::Body`) against an
//! independent reference: a ball written as a degree-2 body is checked against the same ball as
//! an exact primitive sphere, on the fitted Panda at random configurations within the joint
//! limits:
//!
//! - [`RobotChecker::check`]'s and [`RobotChecker::check_block`]'s world verdicts equal the
//!   primitive's, at paddings 0 and 2 cm;
//! - the minimum distance is never over the primitive's and within 20 µm under it (a certified
//!   lower bound from parry's GJK on the body's support map, which Newton solves to 1e-13), and
//!   its witnesses are that far apart;
//! - a motion that conservative advancement proves free among the bodies has every sample at
//!   2 mm of joint travel free of the primitives, and a contact it reports lies within the
//!   tolerance of a primitive;
//! - an ellipsoid body (not a ball) collides wherever the box inscribed in it does, and is free
//!   wherever the box around it is (a containment sandwich);
//! - the sphere-tree descent on a distance bound (the body stage's) decides as the primitive
//!   descent does, given the exact distance to a ball.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::sync::Arc;
use sublevel_core::body::ellipsoid;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::world::WorldBody;
use sublevel_robot::{CheckOptions, FittedRobot, MotionChecker, MotionOptions, RobotChecker, WorldObject};

fn panda() -> FittedRobot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    FittedRobot::load(&path).unwrap()
}

fn random_configuration(rng: &mut ChaCha8Rng, robot: &FittedRobot) -> Vec<Real> {
    (0..robot.model.dof())
        .map(|k| {
            let (lo, hi) = robot.model.variable_joint(k).limits.unwrap_or((-PI, PI));
            rng.random_range(lo..=hi)
        })
        .collect()
}

/// Balls in the arm's reach: (center, radius).
const BALLS: [([Real; 3], Real); 3] = [([0.45, 0.0, 0.45], 0.14), ([0.25, -0.35, 0.3], 0.1), ([-0.1, 0.4, 0.6], 0.12)];

/// The balls as bodies and as primitive spheres, named alike.
fn worlds() -> (Vec<WorldObject>, Vec<WorldObject>) {
    let mut bodies = Vec::new();
    let mut spheres = Vec::new();
    for (k, (c, r)) in BALLS.iter().enumerate() {
        let body = Arc::new(ellipsoid(*c, [*r; 3]).unwrap());
        bodies.push(WorldObject::body(format!("b{k}"), Arc::new(WorldBody::new(body).unwrap()), Isometry3::identity()));
        let at = Isometry3::translation(c[0], c[1], c[2]);
        spheres.push(WorldObject::primitive(format!("b{k}"), Primitive::Sphere { radius: *r }, at));
    }
    (bodies, spheres)
}

#[test]
fn body_balls_answer_as_primitive_spheres() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (bodies, spheres) = worlds();
    let base = Isometry3::identity();
    let mut single = RobotChecker::new(&robot, bodies.clone(), &|_, _| None).unwrap();
    let mut block = RobotChecker::new(&robot, bodies, &|_, _| None).unwrap();
    let mut reference = RobotChecker::new(&robot, spheres, &|_, _| None).unwrap();
    let (mut collisions, mut free) = (0, 0);
    for padding in [0.0, 0.02] {
        let verdict = CheckOptions { padding, distance: false, self_collision: false, gradient: false };
        let configs: Vec<Vec<Real>> = (0..100).map(|_| random_configuration(&mut rng, &robot)).collect();
        let flat: Vec<Real> = configs.iter().flatten().copied().collect();
        let mut lanes = Vec::new();
        block.check_block(&flat, &base, &verdict, false, &mut lanes).unwrap();
        let distance = CheckOptions { distance: true, ..verdict };
        for (k, q) in configs.iter().enumerate() {
            let want = reference.check(q, &base, &distance).unwrap();
            let got = single.check(q, &base, &verdict).unwrap();
            // Within 20 µm of the padding either answer is right (the body distance is a lower bound).
            if want.world || want.distance > padding + 2e-5 {
                assert_eq!(got.world, want.world, "config {k}, padding {padding}: {}", want.distance);
                assert_eq!(lanes[k].world, want.world, "block config {k}, padding {padding}");
            }
            if want.world {
                collisions += 1;
            } else {
                free += 1;
            }
            if k < 40 && !want.world {
                let got = single.check(q, &base, &distance).unwrap();
                assert!(!got.world, "config {k}");
                // A certified lower bound, within 20 µm (world::closest_points).
                assert!(
                    got.distance <= want.distance + 1e-9 && got.distance > want.distance - 2e-5,
                    "{} vs {}",
                    got.distance,
                    want.distance
                );
                let (x, y) = got.witnesses.unwrap();
                assert!(((x - y).norm() - got.distance).abs() < 1e-9);
            }
        }
    }
    assert!(collisions > 20 && free > 20, "{collisions} colliding, {free} free");
}

#[test]
fn certified_motions_among_bodies_keep_every_sample_free() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let (bodies, spheres) = worlds();
    let base = Isometry3::identity();
    let mut reference = RobotChecker::new(&robot, spheres, &|_, _| None).unwrap();
    let mut checker = RobotChecker::new(&robot, bodies, &|_, _| None).unwrap();
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let options = MotionOptions { padding: 0.0, tolerance: 1e-3, max_steps: 100_000 };
    let verdict = CheckOptions { padding: 0.0, distance: false, self_collision: false, gradient: false };
    let distance = CheckOptions { distance: true, ..verdict };
    let (mut valid, mut contact) = (0, 0);
    for _ in 0..20 {
        let a = random_configuration(&mut rng, &robot);
        let b: Vec<Real> = a.iter().map(|v| v + rng.random_range(-0.5..0.5)).collect();
        if reference.check(&a, &base, &verdict).unwrap().world {
            continue;
        }
        let answer = motions.check_motion(&a, &b, &base, &options).unwrap();
        assert!(answer.decided);
        let travel = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, Real::max);
        let n = (travel / 0.002).ceil().max(1.0) as usize;
        let at = |t: Real| a.iter().zip(&b).map(|(x, y)| x + (y - x) * t).collect::<Vec<_>>();
        let end = if answer.valid { 1.0 } else { answer.contact.unwrap() - 1e-9 };
        for i in 0..=n {
            let s = i as Real / n as Real;
            if s <= end {
                assert!(!reference.check(&at(s), &base, &verdict).unwrap().world, "sample {s} before {end}");
            }
        }
        if answer.valid {
            valid += 1;
        } else {
            contact += 1;
            if answer.pair.is_some_and(|(_, o)| o.is_some()) {
                let q = answer.contact_q.unwrap();
                let d = reference.check(&q, &base, &distance).unwrap();
                assert!(d.world || d.distance <= options.tolerance + 1e-6, "contact {} from the spheres", d.distance);
            }
        }
    }
    assert!(valid > 0 && contact > 0, "{valid} free, {contact} in contact");
}

#[test]
fn an_ellipsoid_body_collides_between_its_inner_and_outer_boxes() {
    // x²/0.3² + y²/0.05² + z²/0.2² ≤ 1 contains the box of half extents h/√3 and lies in the box
    // of half extents h: a configuration colliding with the inner box collides with the body,
    // and one free of the outer box is free of it.
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(29);
    let (c, h) = (Vector3::new(0.4, 0.1, 0.5), Vector3::new(0.3, 0.05, 0.2));
    let body = Arc::new(ellipsoid(c.into(), h.into()).unwrap());
    let at = Isometry3::translation(c.x, c.y, c.z);
    let world = vec![WorldObject::body("e", Arc::new(WorldBody::new(body).unwrap()), Isometry3::identity())];
    let inner = vec![WorldObject::primitive("e", Primitive::Box { half_extents: h / 3f64.sqrt() }, at)];
    let outer = vec![WorldObject::primitive("e", Primitive::Box { half_extents: h }, at)];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let mut inner = RobotChecker::new(&robot, inner, &|_, _| None).unwrap();
    let mut outer = RobotChecker::new(&robot, outer, &|_, _| None).unwrap();
    let base = Isometry3::identity();
    let verdict = CheckOptions { padding: 0.0, distance: false, self_collision: false, gradient: false };
    let (mut sure, mut clear) = (0, 0);
    for k in 0..150 {
        let q = random_configuration(&mut rng, &robot);
        let got = checker.check(&q, &base, &verdict).unwrap().world;
        if inner.check(&q, &base, &verdict).unwrap().world {
            assert!(got, "config {k} meets the inner box, not the body");
            sure += 1;
        }
        if !outer.check(&q, &base, &verdict).unwrap().world {
            assert!(!got, "config {k} is free of the outer box, not of the body");
            clear += 1;
        }
    }
    assert!(sure > 5 && clear > 5, "{sure} inside, {clear} outside");
}

#[test]
fn sphere_tree_apart_by_a_distance_bound_equals_the_primitive_descent() {
    // `apart_by` with the exact distance to a ball decides as the primitive descent does.
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    let (mut apart, mut near) = (0, 0);
    for g in &robot.geometries {
        let sublevel_robot::LinkShape::Mesh { spheres, .. } = &g.shape else { continue };
        for _ in 0..40 {
            let t = Vector3::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
            let r = nalgebra::Rotation3::from_euler_angles(rng.random(), rng.random(), rng.random()).into_inner();
            let radius = rng.random_range(0.01..0.1);
            let threshold = rng.random_range(0.0..0.05);
            let ball = Primitive::Sphere { radius };
            let want = spheres.apart_from_primitive(&r, &t, &ball, threshold);
            let got = spheres.apart_by(&r, &t, threshold, |x| x.norm() - radius);
            assert_eq!(got, want, "{}: t {t:?}, radius {radius}, threshold {threshold}", g.name);
            if want {
                apart += 1;
            } else {
                near += 1;
            }
        }
    }
    assert!(apart > 20 && near > 20, "{apart} apart, {near} near");
}
