//! The fidelity dial ([`sublevel_robot::fidelity`]) against the meshes: on the fitted Panda among
//! random worlds of primitives (boxes, spheres, cylinders, capsules, a floor), at random
//! configurations within the joint limits, paddings 0 and 2 cm, every conservative level's
//! verdicts are compared with the `mesh` level's, by the single path and by blocks:
//!
//! - **no miss**: every configuration the meshes call colliding collides at every level;
//! - **free is free**: every configuration a level calls free is free on the meshes (the same
//!   statement, read the other way), and its answer says `mesh`;
//! - a collision the meshes do not see is labelled with the level (`ConfigurationAnswer::fidelity`);
//! - a conservative distance never exceeds the meshes' (a certified lower bound, to 1e-9 m);
//! - a sphere cut of tolerance t has no false collision farther than `padding + t` from contact.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::{CheckOptions, Fidelity, FittedRobot, RobotChecker, WorldObject};

fn panda() -> FittedRobot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    FittedRobot::load(&path).unwrap()
}

/// Two to six primitives within reach of the Panda, and sometimes a floor.
fn random_world(rng: &mut ChaCha8Rng) -> Vec<WorldObject> {
    let mut world = Vec::new();
    for k in 0..rng.random_range(2..=6) {
        let mut r = |lo: Real, hi: Real| rng.random_range(lo..hi);
        let p = match (r(0.0, 4.0)) as usize {
            0 => Primitive::Box { half_extents: Vector3::new(r(0.02, 0.25), r(0.02, 0.25), r(0.01, 0.1)) },
            1 => Primitive::Sphere { radius: r(0.02, 0.12) },
            2 => Primitive::Cylinder { radius: r(0.02, 0.08), half_height: r(0.05, 0.2) },
            _ => Primitive::Capsule { radius: r(0.02, 0.08), half_height: r(0.0, 0.2) },
        };
        let axis = Vector3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)).normalize();
        let at = Vector3::new(r(0.2, 0.7), r(-0.5, 0.5), r(0.1, 0.9));
        world.push(WorldObject::primitive(format!("object{k}"), p, Isometry3::new(at, axis * r(-PI, PI))));
    }
    if rng.random_bool(0.3) {
        let normal = Vector3::z();
        let floor = Primitive::Halfspace { normal, offset: rng.random_range(-0.05..0.1) };
        world.push(WorldObject::primitive("floor", floor, Isometry3::identity()));
    }
    world
}

/// Counts over one level's comparisons.
#[derive(Debug, Default)]
struct Tally {
    configurations: usize,
    mesh_colliding: usize,
    false_collisions: usize,
}

/// Compares `level` with the meshes on `cases` random worlds × `per_case` configurations.
fn compare(robot: &FittedRobot, level: Fidelity, cases: usize, per_case: usize, seed: u64) -> Tally {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let bounds: Vec<(Real, Real)> =
        (0..robot.model.dof()).map(|k| robot.model.variable_joint(k).limits.unwrap_or((-PI, PI))).collect();
    let base = Isometry3::identity();
    let mut tally = Tally::default();
    for _ in 0..cases {
        let world = random_world(&mut rng);
        let mut mesh = RobotChecker::new(robot, world.clone(), &|_, _| None).unwrap();
        let mut model = RobotChecker::new(robot, world.clone(), &|_, _| None).unwrap();
        let mut blocks = RobotChecker::new(robot, world, &|_, _| None).unwrap();
        model.set_fidelity(level).unwrap();
        blocks.set_fidelity(level).unwrap();
        let padding = if rng.random_bool(0.5) { 0.0 } else { 0.02 };
        let configs: Vec<Vec<Real>> =
            (0..per_case).map(|_| bounds.iter().map(|&(lo, hi)| rng.random_range(lo..hi)).collect()).collect();
        let verdict = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        let distance = CheckOptions { distance: true, ..verdict };
        let flat: Vec<Real> = configs.iter().flatten().copied().collect();
        let mut block_answers = Vec::new();
        blocks.check_block(&flat, &base, &verdict, false, &mut block_answers).unwrap();
        for (q, from_block) in configs.iter().zip(&block_answers) {
            let exact = mesh.check(q, &base, &distance).unwrap();
            let single = model.check(q, &base, &verdict).unwrap();
            let with_distance = model.check(q, &base, &distance).unwrap();
            tally.configurations += 1;
            tally.mesh_colliding += usize::from(exact.collides);
            for (path, a) in [("single", &single), ("block", from_block), ("distance", &with_distance)] {
                let at = format!("{level} {path} q={q:?} padding={padding}");
                if exact.collides {
                    assert!(a.collides, "a miss at {at}: the meshes collide ({:?} {:?})", exact.pair, exact.self_pair);
                } else if a.collides {
                    assert_ne!(a.fidelity, Fidelity::Mesh, "{at}: a false collision labelled mesh");
                } else {
                    assert_eq!(a.fidelity, Fidelity::Mesh, "{at}: a free verdict is the meshes' own");
                }
                if let Fidelity::Spheres { tolerance } = level {
                    if a.collides && !exact.collides && a.world && !exact.self_collision && !a.self_collision {
                        assert!(
                            exact.distance <= padding + tolerance + 1e-9,
                            "{at}: a sphere-model collision {} m from the meshes' contact",
                            exact.distance
                        );
                    }
                }
            }
            tally.false_collisions += usize::from(single.collides && !exact.collides);
            if !exact.world && !with_distance.world {
                assert!(
                    with_distance.distance <= exact.distance + 1e-9,
                    "{level}: distance {} above the meshes' {} at q={q:?}",
                    with_distance.distance,
                    exact.distance
                );
            }
        }
    }
    tally
}

fn check_level(level: Fidelity, seed: u64) {
    let robot = panda();
    let tally = compare(&robot, level, 12, 64, seed);
    eprintln!("{level}: {tally:?}");
    // Both kinds of configuration were seen, and the level is conservative somewhere.
    assert!(tally.mesh_colliding > 50 && tally.mesh_colliding + 50 < tally.configurations, "{tally:?}");
    assert!(tally.false_collisions > 0, "{tally:?}");
}

#[test]
fn bodies_never_miss_a_mesh_collision() {
    check_level(Fidelity::Bodies, 1);
}

#[test]
fn spheres_never_miss_a_mesh_collision() {
    check_level(Fidelity::Spheres { tolerance: 0.03 }, 2);
}

#[test]
fn coarse_spheres_never_miss_a_mesh_collision() {
    check_level(Fidelity::Spheres { tolerance: 0.2 }, 3);
}

#[test]
fn fine_spheres_never_miss_a_mesh_collision() {
    check_level(Fidelity::Spheres { tolerance: 0.01 }, 4);
}

/// The closest point of triangle `abc` to `p` (Ericson, Real-Time Collision Detection, 5.1.5).
fn closest_on_triangle(p: &Vector3, a: &Vector3, b: &Vector3, c: &Vector3) -> Vector3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// The Panda's sphere models as the lanes test them: at each tolerance, every ball's surface
/// (sampled in 64 directions) lies within the tolerance of the mesh (brute force over every
/// triangle), and every triangle, sampled on a barycentric grid of 4 steps per edge, lies in
/// the balls: the model holds the mesh and reaches no farther than asked.
#[test]
fn sphere_models_hold_the_meshes_within_the_tolerance() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let directions: Vec<Vector3> = (0..64)
        .map(|_| {
            Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                .normalize()
        })
        .collect();
    for tolerance in [0.05, 0.1, 0.3] {
        let mut checker = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
        checker.set_fidelity(Fidelity::Spheres { tolerance }).unwrap();
        let mut sizes = Vec::new();
        for (k, g) in robot.geometries.iter().enumerate() {
            let sublevel_robot::LinkShape::Mesh { vertices, triangles, .. } = &g.shape else { continue };
            let cut = checker.sphere_cut(k);
            sizes.push(cut.len());
            if cut.is_empty() {
                continue;
            }
            let corners: Vec<[Vector3; 3]> = triangles.iter().map(|t| t.map(|i| vertices[i as usize].coords)).collect();
            let to_mesh = |x: &Vector3| {
                corners
                    .iter()
                    .map(|[a, b, c]| (closest_on_triangle(x, a, b, c) - x).norm())
                    .fold(Real::INFINITY, Real::min)
            };
            for s in cut {
                for d in &directions {
                    let reach = to_mesh(&(s.center + d * s.radius));
                    assert!(reach <= tolerance + 1e-9, "{}: a ball reaches {reach} m past the mesh", g.name);
                }
            }
            let inside = |x: &Vector3| cut.iter().any(|s| (x - s.center).norm() <= s.radius + 1e-12);
            for [a, b, c] in &corners {
                for i in 0..=4 {
                    for j in 0..=4 - i {
                        let (u, v) = (i as Real / 4.0, j as Real / 4.0);
                        assert!(inside(&(a + (b - a) * u + (c - a) * v)), "{}: a point outside the model", g.name);
                    }
                }
            }
        }
        eprintln!("tolerance {tolerance}: lane balls per link {sizes:?}");
        assert!(sizes.iter().any(|&n| n > 0), "tolerance {tolerance}: no model within the lanes' size");
    }
}
