//! Rigid-body motions against closed forms: spheres, boxes, a rotating bar, a thin plate that
//! sampling steps over, a floor, compound bodies moving and met; the motion bound and the
//! tangent-plane support bound against brute force.

use super::bounds::tangent_support;
use super::*;
use crate::store::MemoryStore;
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;
use sublevel_core::body::{ellipsoid, Body};
use sublevel_core::math::{Point3, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_query::shape::{shape_distance, ShapeRef};
use sublevel_query::NewtonParams;

/// A scene in an in-memory catalog.
struct World {
    catalog: Catalog,
    scene: String,
}

impl World {
    fn new() -> Self {
        let catalog = Catalog::open(Box::new(MemoryStore::new()), NewtonParams::default()).unwrap();
        let scene = catalog.create_scene("motions").unwrap();
        Self { catalog, scene }
    }

    fn primitive(&self, p: Primitive, pose: Isometry3) -> String {
        let body = self.catalog.add_primitive("p", p).unwrap();
        self.catalog.add_instance(&self.scene, &body, pose).unwrap()
    }

    fn body(&self, b: Body, pose: Isometry3) -> String {
        let body = self.catalog.add_body("b", b).unwrap();
        self.catalog.add_instance(&self.scene, &body, pose).unwrap()
    }

    fn check(&self, id: &str, start: Isometry3, end: Isometry3, options: &MotionOptions) -> InstanceMotionAnswer {
        let scene = MotionScene::read(&self.catalog, &self.scene).unwrap();
        let moving = scene.moving("instance", id).unwrap();
        scene.check_motion(&moving, &start, &end, options).unwrap()
    }
}

fn sphere(radius: Real) -> Primitive {
    Primitive::Sphere { radius }
}

fn cuboid(hx: Real, hy: Real, hz: Real) -> Primitive {
    Primitive::Box { half_extents: Vector3::new(hx, hy, hz) }
}

fn at(x: Real, y: Real, z: Real) -> Isometry3 {
    Isometry3::translation(x, y, z)
}

/// Rotation by `angle` about z at translation `t`.
fn turned(angle: Real, t: [Real; 3]) -> Isometry3 {
    Isometry3::new(Vector3::from(t), Vector3::z() * angle)
}

/// A contact at the exact first contact `t_star` (closed form): reported no later than it, and
/// earlier by at most the tolerance (with the exactness slack) over the closing speed `closing`
/// (meters per unit of the parameter, at t*: a lower bound of the speed before it for these
/// convex approaches).
fn assert_contact(a: &InstanceMotionAnswer, other: &str, t_star: Real, closing: Real, tolerance: Real) {
    assert!(a.decided && !a.valid, "{a:?}");
    let t = a.contact.unwrap_or_else(|| panic!("no contact: {a:?}"));
    assert!(t <= t_star + 1e-12, "contact {t} after the exact {t_star}");
    let early = (1.0 + EXACT_FRACTION) * tolerance / closing;
    assert!(t_star - t <= early + 1e-12, "contact {t} earlier than {t_star} by more than {early}");
    assert_eq!(a.other.as_deref(), Some(other));
    assert!(a.contact_pose.is_some() && a.steps >= 1);
}

/// A sphere r = 0.5 translating 4 m along x into a sphere r = 0.3 centred 3 m ahead: contact when
/// the centres are 0.8 apart, t* = 2.2 / 4; the same at tolerances 1 mm and 10 µm, with the fitted
/// sos ball (a degree-2 body) on either side, warm-started along the motion.
#[test]
fn a_sphere_translating_into_a_sphere_stops_at_the_closed_form() {
    for tolerance in [1e-3, 1e-5] {
        let options = MotionOptions { tolerance, ..MotionOptions::default() };
        for (moving_body, obstacle_body) in [(false, false), (true, false), (false, true), (true, true)] {
            let w = World::new();
            let m = if moving_body {
                w.body(ellipsoid([0.0; 3], [0.5; 3]).unwrap(), at(0.0, 0.0, 0.0))
            } else {
                w.primitive(sphere(0.5), at(0.0, 0.0, 0.0))
            };
            let o = if obstacle_body {
                w.body(ellipsoid([0.0; 3], [0.3; 3]).unwrap(), at(3.0, 0.0, 0.0))
            } else {
                w.primitive(sphere(0.3), at(3.0, 0.0, 0.0))
            };
            let a = w.check(&m, at(0.0, 0.0, 0.0), at(4.0, 0.0, 0.0), &options);
            assert_contact(&a, &o, 2.2 / 4.0, 4.0, tolerance);
            let pose = a.contact_pose.unwrap();
            assert!((pose.translation.vector.x - 4.0 * a.contact.unwrap()).abs() < 1e-12);
        }
    }
}

/// The same sphere passing 1 m beside the other (closest centre distance 1 > 0.8) is free; with
/// 0.25 m of padding it comes within 1.05 at (x − 3)² + 1 = 1.05², closing at (3 − x)/1.05 · 4.
#[test]
fn a_sphere_passing_a_sphere_is_free_unless_padded() {
    let w = World::new();
    let m = w.primitive(sphere(0.5), at(0.0, 0.0, 0.0));
    let o = w.primitive(sphere(0.3), at(3.0, 1.0, 0.0));
    let free = w.check(&m, at(0.0, 0.0, 0.0), at(4.0, 0.0, 0.0), &MotionOptions::default());
    assert!(free.valid && free.decided && free.contact.is_none() && free.other.is_none(), "{free:?}");
    assert!(free.steps > 1, "{free:?}");
    let padded = MotionOptions { padding: 0.25, ..MotionOptions::default() };
    let a = w.check(&m, at(0.0, 0.0, 0.0), at(4.0, 0.0, 0.0), &padded);
    let back = (1.05_f64 * 1.05 - 1.0).sqrt();
    assert_contact(&a, &o, (3.0 - back) / 4.0, back / 1.05 * 4.0, padded.tolerance);
}

/// A unit cube moving 3 m along x into the face of a slab (half thickness 0.2) centred at x = 2:
/// contact when its face reaches 1.8, t* = 1.3 / 3.
#[test]
fn a_box_moving_into_a_box_face_stops_at_the_closed_form() {
    let w = World::new();
    let m = w.primitive(cuboid(0.5, 0.5, 0.5), at(0.0, 0.0, 0.0));
    let o = w.primitive(cuboid(0.2, 1.0, 1.0), at(2.0, 0.0, 0.0));
    let options = MotionOptions::default();
    let a = w.check(&m, at(0.0, 0.0, 0.0), at(3.0, 0.0, 0.0), &options);
    assert_contact(&a, &o, 1.3 / 3.0, 3.0, options.tolerance);
}

/// A bar (half extents 1, 0.05, 0.05) turning 90° about z in place sweeps into a ball r = 0.1
/// centred at ρ = 0.8, α = 60°: in the bar's frame the centre is ρ(cos(α − φ), sin(α − φ)), the
/// gap to the long face ρ sin(α − φ) − 0.15, so φ* = α − asin(0.15/ρ), t* = φ* / (π/2), closing at
/// ρ cos(α − φ*) · π/2 per unit of t.
#[test]
fn a_turning_bar_sweeps_into_a_ball_at_the_closed_form_angle() {
    let (rho, alpha) = (0.8, PI / 3.0);
    let w = World::new();
    let m = w.primitive(cuboid(1.0, 0.05, 0.05), at(0.0, 0.0, 0.0));
    let o = w.primitive(sphere(0.1), at(rho * alpha.cos(), rho * alpha.sin(), 0.0));
    let options = MotionOptions::default();
    let a = w.check(&m, turned(0.0, [0.0; 3]), turned(PI / 2.0, [0.0; 3]), &options);
    let phi = alpha - (0.15 / rho).asin();
    assert_contact(&a, &o, phi / (PI / 2.0), rho * (alpha - phi).cos() * PI / 2.0, options.tolerance);
    // The pose there is the start turned by t·90° about z.
    let (axis_angle, t) = (a.contact_pose.unwrap().rotation.scaled_axis(), a.contact.unwrap());
    assert!((axis_angle.z - t * PI / 2.0).abs() < 1e-12 && axis_angle.xy().norm() < 1e-12);
}

/// A 1 mm plate at x = 1 and a ball r = 1 cm travelling 2 m along x from x = 0.015: sampled at
/// 32 poses per meter of travel (every 3.125 cm) no pose touches it (the nearest samples are 1.6
/// and 1.5 cm from its mid-plane, more than 1.05 cm), while advancement stops at the contact,
/// t* = (1 − 0.0005 − 0.01 − 0.015) / 2.
#[test]
fn advancement_finds_a_thin_plate_that_sampling_steps_over() {
    let w = World::new();
    let (ball, plate) = (sphere(0.01), cuboid(0.0005, 1.0, 1.0));
    let m = w.primitive(ball, at(0.015, 0.0, 0.0));
    let o = w.primitive(plate, at(1.0, 0.0, 0.0));
    let (start, end) = (at(0.015, 0.0, 0.0), at(2.015, 0.0, 0.0));
    let samples = 64;
    for k in 0..=samples {
        let pose = Slerp::new(&start, &end).at(k as Real / samples as Real);
        let d =
            shape_distance(ShapeRef::Primitive(&ball), &pose, ShapeRef::Primitive(&plate), &at(1.0, 0.0, 0.0), None)
                .unwrap();
        assert!(!d.overlapping && d.distance > 0.004, "sample {k}: {}", d.distance);
    }
    let options = MotionOptions::default();
    let a = w.check(&m, start, end, &options);
    assert_contact(&a, &o, (1.0 - 0.0005 - 0.01 - 0.015) / 2.0, 2.0, options.tolerance);
}

/// A ball falling 2 m onto a floor (the halfspace z ≤ 0): contact at z = 0.5, t* = 0.75.
#[test]
fn a_ball_falls_onto_a_floor() {
    let w = World::new();
    let m = w.primitive(sphere(0.5), at(0.0, 0.0, 2.0));
    let floor = w.primitive(Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 }, at(0.0, 0.0, 0.0));
    let options = MotionOptions::default();
    let a = w.check(&m, at(0.0, 0.0, 2.0), at(1.0, 0.0, 0.0), &options);
    assert_contact(&a, &floor, 0.75, 2.0, options.tolerance);
}

/// A free motion among a box, a fitted body and a far sphere: valid and decided, in a few steps
/// (the far sphere is out of reach from the start and never bounded again).
#[test]
fn a_free_motion_is_valid_in_few_steps() {
    let w = World::new();
    let m = w.primitive(sphere(0.5), at(0.0, 0.0, 0.0));
    w.primitive(cuboid(0.5, 0.5, 0.5), at(2.0, 2.0, 0.0));
    w.body(ellipsoid([0.0; 3], [0.4, 0.3, 0.2]).unwrap(), at(2.0, -2.0, 0.0));
    w.primitive(sphere(1.0), at(100.0, 0.0, 0.0));
    let a = w.check(&m, at(0.0, 0.0, 0.0), turned(1.0, [4.0, 0.0, 0.0]), &MotionOptions::default());
    assert!(a.valid && a.decided && a.contact.is_none(), "{a:?}");
    assert!((2..=40).contains(&a.steps), "{a:?}");
}

/// A motion starting in contact answers t = 0 at the start pose; one whose max_steps runs out is
/// undecided and not valid.
#[test]
fn a_colliding_start_answers_zero_and_max_steps_answers_undecided() {
    let w = World::new();
    let m = w.primitive(sphere(0.5), at(0.0, 0.0, 0.0));
    let o = w.primitive(cuboid(0.5, 0.5, 0.5), at(0.8, 0.0, 0.0));
    let a = w.check(&m, at(0.0, 0.0, 0.0), at(-4.0, 0.0, 0.0), &MotionOptions::default());
    assert_eq!((a.contact, a.other.as_deref(), a.steps), (Some(0.0), Some(o.as_str()), 1), "{a:?}");
    assert_eq!(a.contact_pose, Some(at(0.0, 0.0, 0.0)));
    let short = MotionOptions { max_steps: 2, ..MotionOptions::default() };
    let b = w.check(&m, at(0.0, 0.0, 2.0), at(3.0, 0.0, 2.0), &short);
    assert!(!b.valid && !b.decided && b.contact.is_none() && b.steps == 2, "{b:?}");
}

/// Bad input: a halfspace cannot move, an unknown instance is not found, options are checked,
/// each naming its field.
#[test]
fn bad_input_is_refused_naming_the_field() {
    let w = World::new();
    let floor = w.primitive(Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 }, at(0.0, 0.0, 0.0));
    let m = w.primitive(sphere(0.5), at(0.0, 0.0, 2.0));
    let scene = MotionScene::read(&w.catalog, &w.scene).unwrap();
    let e = scene.moving("instance_ids[1]", &floor).unwrap_err();
    assert!(matches!(&e, Error::InvalidArgument { field, .. } if field == "instance_ids[1]"), "{e}");
    let e = scene.moving("instance_ids[2]", "i-nope").unwrap_err();
    assert!(matches!(&e, Error::NotFound { field, .. } if field == "instance_ids[2]"), "{e}");
    let moving = scene.moving("instance_ids[0]", &m).unwrap();
    let id = Isometry3::identity();
    for (bad, field) in [
        (MotionOptions { padding: -1.0, ..Default::default() }, "padding"),
        (MotionOptions { tolerance: 0.0, ..Default::default() }, "tolerance"),
        (MotionOptions { tolerance: Real::NAN, ..Default::default() }, "tolerance"),
        (MotionOptions { max_steps: 0, ..Default::default() }, "max_steps"),
    ] {
        let e = scene.check_motion(&moving, &id, &id, &bad).unwrap_err();
        assert!(matches!(&e, Error::InvalidArgument { field: f, .. } if f == field), "{e}");
    }
}

/// The path: the end pose reached at s = 1 (with q₁ given with either sign), the shorter arc
/// (a 270° turn is a −90° one), and the motion bound ‖p(s₂) − p(s₁)‖ ≤ (‖Δt‖ + rθ)|s₂ − s₁| for
/// the corners of a box on 200 random paths (r its half diagonal).
#[test]
fn the_path_takes_the_shorter_arc_and_obeys_the_motion_bound() {
    let start = turned(0.3, [1.0, 2.0, 3.0]);
    let end = Isometry3::new(Vector3::new(-1.0, 0.5, 2.0), Vector3::new(0.4, -1.2, 0.7));
    let flipped = Isometry3::from_parts(end.translation, UnitQuaternion::new_unchecked(-*end.rotation.quaternion()));
    for e in [end, flipped] {
        let p = Slerp::new(&start, &e);
        let reached = p.at(1.0);
        assert!((reached.translation.vector - end.translation.vector).norm() < 1e-12);
        assert!(reached.rotation.angle_to(&end.rotation) < 1e-9);
        assert!(p.at(0.0).rotation.angle_to(&start.rotation) < 1e-12);
    }
    let quarter = Slerp::new(&turned(0.0, [0.0; 3]), &turned(1.5 * PI, [0.0; 3]));
    assert!((quarter.angle() - PI / 2.0).abs() < 1e-12);
    assert!((quarter.at(0.5).rotation.angle() - PI / 4.0).abs() < 1e-12);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let h = Vector3::new(0.7, 0.2, 0.4);
    let mut random =
        || Vector3::new(rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
    for _ in 0..200 {
        let (a, b) = (Isometry3::new(random(), random()), Isometry3::new(random(), random()));
        let p = Slerp::new(&a, &b);
        let v = p.travel() + h.norm() * p.angle();
        for k in 0..8 {
            let corner = Point3::new(
                if k & 1 == 0 { h.x } else { -h.x },
                if k & 2 == 0 { h.y } else { -h.y },
                if k & 4 == 0 { h.z } else { -h.z },
            );
            for (s1, s2) in [(0.0, 1.0), (0.1, 0.15), (0.5, 0.9)] {
                let moved = (p.at(s2) * corner - p.at(s1) * corner).norm();
                assert!(moved <= v * (s2 - s1) + 1e-12, "{moved} > {}", v * (s2 - s1));
            }
        }
    }
}

/// The tangent-plane bound of an ellipsoid body (radii 0.5, 0.3, 0.2) is never below its exact
/// support function ‖D e‖, from any tangent point (2000 random points and directions), and meets
/// it at the support point.
#[test]
fn the_tangent_plane_bound_is_above_the_support_function_and_tight_at_the_support_point() {
    let radii = Vector3::new(0.5, 0.3, 0.2);
    let body = ellipsoid([0.0; 3], [0.5, 0.3, 0.2]).unwrap();
    let exact = |e: &Vector3| e.component_mul(&radii).norm();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    for _ in 0..2000 {
        let e = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        let x = Point3::new(rng.random_range(-0.8..0.8), rng.random_range(-0.5..0.5), rng.random_range(-0.4..0.4));
        let bound = tangent_support(&body, &e, &x).unwrap();
        assert!(bound >= exact(&e) - 1e-12, "{bound} below {}", exact(&e));
        // The support point of e: D² e / ‖D e‖.
        let s = Point3::from(radii.component_mul(&radii).component_mul(&e) / exact(&e));
        let tight = tangent_support(&body, &e, &s).unwrap();
        assert!(tight >= exact(&e) - 1e-12 && tight - exact(&e) <= 1e-7 * (1.0 + e.norm()), "{tight} vs {}", exact(&e));
    }
}

/// A dumbbell: a containment tree whose root ball r = 1 at the origin contains the leaf balls
/// r = 0.4 at x = ±0.5 (the model is the two leaves).
fn dumbbell() -> sublevel_core::compound::CompoundBody {
    use sublevel_core::compound::{CompoundBody, CompoundNode, CompoundReport};
    let node = |c: [Real; 3], r: Real, children: Vec<usize>, depth: usize| CompoundNode {
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

/// Compound bodies: a ball r = 0.3 (a primitive, then a fitted one) moving 3 m along −x onto the
/// dumbbell's leaf at x = 0.5 touches it at centre x = 1.2, t* = 0.6; the dumbbell turning 90°
/// about z sweeps its leaf (0.5 cos φ, 0.5 sin φ) into a ball r = 0.1 at (0, 0.95, 0): the centres
/// are 0.5 apart at sin φ* = 0.9025 / 0.95, closing at 0.95 cos φ* per radian.
#[test]
fn compound_bodies_move_and_are_met_at_their_closed_forms() {
    let options = MotionOptions::default();
    for fitted in [false, true] {
        let w = World::new();
        let tree = w.catalog.add_compound_body("dumbbell", dumbbell()).unwrap();
        let o = w.catalog.add_instance(&w.scene, &tree, at(0.0, 0.0, 0.0)).unwrap();
        let m = if fitted {
            w.body(ellipsoid([0.0; 3], [0.3; 3]).unwrap(), at(3.0, 0.0, 0.0))
        } else {
            w.primitive(sphere(0.3), at(3.0, 0.0, 0.0))
        };
        let a = w.check(&m, at(3.0, 0.0, 0.0), at(0.0, 0.0, 0.0), &options);
        assert_contact(&a, &o, 0.6, 3.0, options.tolerance);
    }
    let w = World::new();
    let tree = w.catalog.add_compound_body("dumbbell", dumbbell()).unwrap();
    let m = w.catalog.add_instance(&w.scene, &tree, at(0.0, 0.0, 0.0)).unwrap();
    let o = w.primitive(sphere(0.1), at(0.0, 0.95, 0.0));
    let a = w.check(&m, turned(0.0, [0.0; 3]), turned(PI / 2.0, [0.0; 3]), &options);
    let phi = (0.9025_f64 / 0.95).asin();
    assert_contact(&a, &o, phi / (PI / 2.0), 0.95 * phi.cos() * PI / 2.0, options.tolerance);
}
