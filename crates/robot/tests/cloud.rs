//! Point-cloud obstacles against a brute-force pass over every point ball, on the fitted Panda:
//! a cloud sampled on the faces of a shelf and a post in front of the robot, plus scattered
//! points, with noise radius 1 cm (and 0), paddings 0 and 2 cm, random configurations within
//! the joint limits:
//!
//! - [`RobotChecker::check`]'s and [`RobotChecker::check_block`]'s world verdicts equal the brute
//!   force's, which asks parry for the distance from every point's ball to every link geometry
//!   (a mesh's triangles, a primitive's solid) that its bounding ball does not rule out;
//! - the minimum distance of a check that asks for it equals the brute force's minimum to 1e-9 m,
//!   its witness points lie on the link and on the point ball;
//! - a motion that conservative advancement proves free has every configuration sampled along it
//!   at 2 mm of joint travel brute-force free, and one it finds in contact has a brute-force
//!   colliding configuration within the tolerance of the contact it reports;
//! - the self filter removes exactly the point balls the brute force finds within its padding.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_robot::cloud::filter::self_filter;
use sublevel_robot::{
    CheckOptions, FittedRobot, LinkShape, MotionChecker, MotionOptions, PointCloud, RobotChecker, WorldObject,
};

fn panda() -> FittedRobot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    FittedRobot::load(&path).unwrap()
}

/// Points on the faces of boxes (center, half extents) at about `spacing`, and `scatter` random
/// points in the robot's workspace.
fn shelf_cloud(rng: &mut ChaCha8Rng, spacing: Real, scatter: usize) -> Vec<[Real; 3]> {
    let boxes = [
        (Vector3::new(0.55, 0.0, 0.4), Vector3::new(0.15, 0.4, 0.01)),
        (Vector3::new(0.55, 0.0, 0.8), Vector3::new(0.15, 0.4, 0.01)),
        (Vector3::new(0.7, 0.0, 0.6), Vector3::new(0.01, 0.4, 0.2)),
        (Vector3::new(0.35, -0.35, 0.3), Vector3::new(0.03, 0.03, 0.3)),
    ];
    let mut points = Vec::new();
    for (c, h) in boxes {
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let (nu, nv) = ((2.0 * h[u] / spacing).ceil() as usize, (2.0 * h[v] / spacing).ceil() as usize);
            for side in [-1.0, 1.0] {
                for i in 0..=nu {
                    for j in 0..=nv {
                        let mut p = c;
                        p[axis] += side * h[axis];
                        p[u] += -h[u] + 2.0 * h[u] * i as Real / nu as Real + rng.random_range(-0.003..0.003);
                        p[v] += -h[v] + 2.0 * h[v] * j as Real / nv as Real + rng.random_range(-0.003..0.003);
                        points.push([p.x, p.y, p.z]);
                    }
                }
            }
        }
    }
    for _ in 0..scatter {
        points.push([rng.random_range(-0.8..0.8), rng.random_range(-0.8..0.8), rng.random_range(0.0..1.2)]);
    }
    points
}

fn random_configuration(rng: &mut ChaCha8Rng, robot: &FittedRobot) -> Vec<Real> {
    (0..robot.model.dof())
        .map(|k| {
            let (lo, hi) = robot.model.variable_joint(k).limits.unwrap_or((-PI, PI));
            rng.random_range(lo..=hi)
        })
        .collect()
}

/// The brute force: the smallest distance from a point ball to a link geometry at `q`, over the
/// pairs within `reach` of each other by bounding balls (∞ when none), by parry's ball–shape
/// distance (0 on contact).
fn brute_distance(robot: &FittedRobot, q: &[Real], cloud: &[[Real; 3]], radius: Real, reach: Real) -> Real {
    let mut poses = Vec::new();
    robot.model.forward_kinematics(q, &Isometry3::identity(), &mut poses).unwrap();
    let ball = parry3d_f64::shape::Ball::new(radius.max(1e-12));
    let mut best = Real::INFINITY;
    for g in &robot.geometries {
        let pose = poses[g.link] * g.origin;
        let c = pose.transform_point(&g.sphere.0.into()).coords;
        let (shape, offset): (parry3d_f64::shape::SharedShape, Isometry3) = match &g.shape {
            LinkShape::Mesh { exact, .. } => (exact.clone(), Isometry3::identity()),
            LinkShape::Primitive(p) => primitive_shape(p),
        };
        let placed = parry(&(pose * offset));
        for p in cloud {
            let v = Vector3::from(*p);
            if (v - c).norm() > g.sphere.1 + radius + reach {
                continue;
            }
            let at = parry(&Isometry3::translation(v.x, v.y, v.z));
            let d = parry3d_f64::query::distance(&placed, shape.as_ref(), &at, &ball).unwrap().distance;
            // A zero radius is a point: parry's tiny ball stands for it.
            best = best.min(if radius == 0.0 { d + 1e-12 } else { d });
        }
    }
    best
}

fn primitive_shape(p: &sublevel_core::primitive::Primitive) -> (parry3d_f64::shape::SharedShape, Isometry3) {
    use sublevel_core::primitive::Primitive;
    match *p {
        Primitive::Box { half_extents: h } => {
            (parry3d_f64::shape::SharedShape::cuboid(h.x, h.y, h.z), Isometry3::identity())
        }
        Primitive::Sphere { radius } => (parry3d_f64::shape::SharedShape::ball(radius), Isometry3::identity()),
        Primitive::Cylinder { radius, half_height } => (
            parry3d_f64::shape::SharedShape::cylinder(half_height, radius),
            Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2),
        ),
        Primitive::Capsule { radius, half_height } => (
            parry3d_f64::shape::SharedShape::capsule(
                parry3d_f64::math::Vector::new(0.0, 0.0, -half_height),
                parry3d_f64::math::Vector::new(0.0, 0.0, half_height),
                radius,
            ),
            Isometry3::identity(),
        ),
        Primitive::Halfspace { .. } => unreachable!("no link is a halfspace"),
    }
}

fn parry(iso: &Isometry3) -> parry3d_f64::math::Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    parry3d_f64::math::Pose::from_parts(
        parry3d_f64::math::Vector::new(t.x, t.y, t.z),
        parry3d_f64::math::Rot3::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

#[test]
fn verdicts_and_distances_equal_brute_force() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let points = shelf_cloud(&mut rng, 0.02, 300);
    let base = Isometry3::identity();
    let (mut collisions, mut free) = (0, 0);
    for radius in [0.01, 0.0] {
        let cloud = Arc::new(PointCloud::new(points.clone(), radius).unwrap());
        let world = vec![WorldObject::points("camera", cloud, Isometry3::identity())];
        let mut single = RobotChecker::new(&robot, world.clone(), &|_, _| None).unwrap();
        let mut block = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
        for padding in [0.0, 0.02] {
            let verdict = CheckOptions { padding, distance: false, self_collision: false, gradient: false };
            let configs: Vec<Vec<Real>> = (0..120).map(|_| random_configuration(&mut rng, &robot)).collect();
            let flat: Vec<Real> = configs.iter().flatten().copied().collect();
            let mut lanes = Vec::new();
            block.check_block(&flat, &base, &verdict, false, &mut lanes).unwrap();
            for (k, q) in configs.iter().enumerate() {
                let brute = brute_distance(&robot, q, &points, radius, padding + 1e-6);
                let a = single.check(q, &base, &verdict).unwrap();
                // Within a micrometer of the padding either answer is right.
                if (brute - padding).abs() > 1e-9 {
                    assert_eq!(a.world, brute <= padding, "config {k}, r {radius}, padding {padding}: {brute}");
                    assert_eq!(lanes[k].world, brute <= padding, "block config {k}: {brute}");
                }
                if a.world {
                    collisions += 1;
                } else {
                    free += 1;
                }
            }
            // Distances, where the robot is free of the cloud.
            let options = CheckOptions { padding: 0.0, distance: true, self_collision: false, gradient: false };
            for q in configs.iter().take(40) {
                let a = single.check(q, &base, &options).unwrap();
                let brute = brute_distance(&robot, q, &points, radius, 10.0);
                if brute > 1e-6 {
                    assert!((a.distance - brute).abs() < 1e-9, "distance {} vs brute force {brute}", a.distance);
                    let (x, y) = a.witnesses.unwrap();
                    assert!(((x - y).norm() - a.distance).abs() < 1e-9);
                } else {
                    assert!(a.world);
                }
            }
        }
    }
    // The sample has both kinds of answer.
    assert!(collisions > 50 && free > 50, "{collisions} colliding, {free} free");
}

#[test]
fn certified_motions_keep_every_sample_free() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let points = shelf_cloud(&mut rng, 0.03, 0);
    let radius = 0.01;
    let cloud = Arc::new(PointCloud::new(points.clone(), radius).unwrap());
    let world = vec![WorldObject::points("camera", cloud, Isometry3::identity())];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let options = MotionOptions { padding: 0.0, tolerance: 1e-3, max_steps: 100_000 };
    let base = Isometry3::identity();
    let (mut valid, mut contact) = (0, 0);
    for _ in 0..24 {
        let a = random_configuration(&mut rng, &robot);
        let b: Vec<Real> = a.iter().map(|v| v + rng.random_range(-0.6..0.6)).collect();
        if brute_distance(&robot, &a, &points, radius, 0.0) <= 0.0 {
            continue;
        }
        let answer = motions.check_motion(&a, &b, &base, &options).unwrap();
        assert!(answer.decided);
        let travel = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, Real::max);
        let n = (travel / 0.002).ceil().max(1.0) as usize;
        let at = |t: Real| a.iter().zip(&b).map(|(x, y)| x + (y - x) * t).collect::<Vec<_>>();
        if answer.valid {
            valid += 1;
            for i in 0..=n {
                let q = at(i as Real / n as Real);
                assert!(brute_distance(&robot, &q, &points, radius, 0.0) > 0.0, "sample {i}/{n} collides");
            }
        } else {
            contact += 1;
            let t = answer.contact.unwrap();
            // Up to the contact every sample is free of the cloud.
            for i in 0..n {
                let s = i as Real / n as Real;
                if s < t - 1e-9 {
                    assert!(brute_distance(&robot, &at(s), &points, radius, 0.0) > 0.0, "sample {s} before {t}");
                }
            }
            // A world contact (not a self contact) is within the tolerance of a point ball.
            if answer.pair.is_some_and(|(_, o)| o.is_some()) {
                let q = answer.contact_q.unwrap();
                assert!(brute_distance(&robot, &q, &points, radius, 1e-3) <= options.tolerance + 1e-9);
            }
        }
    }
    assert!(valid > 0 && contact > 0, "{valid} free, {contact} in contact");
}

#[test]
fn self_filter_removes_the_points_on_the_arm() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let points = shelf_cloud(&mut rng, 0.02, 3000);
    let (radius, padding) = (0.01, 0.02);
    for _ in 0..5 {
        let q = random_configuration(&mut rng, &robot);
        let mut kept = points.clone();
        let removed = self_filter(&robot, &q, &Isometry3::identity(), radius, padding, &mut kept).unwrap();
        let expect: Vec<[Real; 3]> = points
            .iter()
            .filter(|p| brute_distance(&robot, &q, &[**p], radius, padding + 1e-6) > padding)
            .copied()
            .collect();
        assert_eq!(kept, expect);
        assert_eq!(removed, points.len() - expect.len());
    }
}
