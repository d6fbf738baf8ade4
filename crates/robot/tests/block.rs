//! Block checks against single checks: on random robots (the gantry of `data/gantry.urdf` with
//! random URDF primitives on its links, the slider of `data/slider.urdf` with its fitted meshes,
//! the fitted Panda), random worlds of primitives (box, sphere, cylinder, capsule, halfspace) at
//! random poses, random configurations (within the joint limits, and some outside), paddings 0
//! and > 0, a link padding on some link, self-collision on and off:
//!
//! - [`RobotChecker::check_block`]'s verdicts (collides, world, self) equal
//!   [`RobotChecker::check`]'s lane by lane, in blocks of 1, 3, 8 and 13 configurations (a full
//!   block, tails), and with `stop_at_first_collision` the answers end at the first colliding one;
//! - [`RobotChecker::first_collision`] is the first colliding index of the single checks, and
//!   [`RobotChecker::any_collision`] whether there is one;
//! - [`RobotChecker::rake_motion`]'s collision parameter is the smallest colliding sample's of the
//!   first rake block that holds one, and its sample count the samples of the blocks up to it,
//!   both computed here from single checks of the samples and [`rake_order`].
//!
//! The reference checker and the block checker are separate instances (no shared warm starts).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::{
    fit_robot, fit_robot_text, rake_order, CheckOptions, ConfigurationAnswer, FittedRobot, MeshSource, RobotChecker,
    RobotFitSettings, WorldObject, BLOCK,
};

const GANTRY: &str = include_str!("data/gantry.urdf");
const SLIDER: &str = include_str!("data/slider.urdf");
const CUBE: &str = include_str!("data/cube.obj");

/// A random URDF collision element: a box, sphere, cylinder or capsule at a random origin.
fn collision(rng: &mut ChaCha8Rng) -> String {
    let mut r = |lo: Real, hi: Real| rng.random_range(lo..hi);
    let origin = format!(
        r#"<origin xyz="{} {} {}" rpy="{} {} {}"/>"#,
        r(-0.1, 0.1),
        r(-0.1, 0.1),
        r(-0.1, 0.1),
        r(-PI, PI),
        r(-PI, PI),
        r(-PI, PI)
    );
    let geometry = match (r(0.0, 4.0)) as usize {
        0 => format!(r#"<box size="{} {} {}"/>"#, r(0.03, 0.15), r(0.03, 0.15), r(0.03, 0.15)),
        1 => format!(r#"<sphere radius="{}"/>"#, r(0.02, 0.08)),
        2 => format!(r#"<cylinder radius="{}" length="{}"/>"#, r(0.015, 0.05), r(0.05, 0.25)),
        _ => format!(r#"<capsule radius="{}" length="{}"/>"#, r(0.015, 0.05), r(0.05, 0.25)),
    };
    format!("<collision>{origin}<geometry>{geometry}</geometry></collision>")
}

/// The gantry (every joint kind: prismatic, continuous, revolute, mimic, fixed) with one or two
/// random primitives on most links.
fn gantry(rng: &mut ChaCha8Rng) -> FittedRobot {
    let mut urdf = GANTRY.to_owned();
    for link in ["base", "carriage", "spindle", "arm", "forearm", "follower", "tool", "camera"] {
        if rng.random_bool(0.8) {
            let parts = (0..rng.random_range(1..=2)).map(|_| collision(rng)).collect::<String>();
            urdf =
                urdf.replace(&format!(r#"<link name="{link}"/>"#), &format!(r#"<link name="{link}">{parts}</link>"#));
        }
    }
    let meshes = std::collections::HashMap::new();
    fit_robot_text(urdf, None, MeshSource::Memory(&meshes), &RobotFitSettings::default(), &|_| {}).unwrap()
}

/// The slider: a base cube mesh, a prismatic box arm, a turning cube mesh tip (fitted bodies).
fn slider() -> (FittedRobot, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE).unwrap();
    std::fs::write(dir.path().join("slider.urdf"), SLIDER).unwrap();
    let mut settings = RobotFitSettings { cache_dir: Some(dir.path().join("cache")), ..Default::default() };
    settings.compound.excess_tolerance = Some(0.2);
    settings.compound.max_parts = 2;
    let robot = fit_robot(&dir.path().join("slider.urdf"), None, &settings, &|_| {}).unwrap();
    (robot, dir)
}

fn panda() -> FittedRobot {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    FittedRobot::load(&path).unwrap()
}

fn random_pose(rng: &mut ChaCha8Rng, center: Vector3, spread: Real) -> Isometry3 {
    let mut r = |lo: Real, hi: Real| rng.random_range(lo..hi);
    let axis = Vector3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)).normalize();
    let at = center + Vector3::new(r(-spread, spread), r(-spread, spread), r(-spread, spread));
    Isometry3::new(at, axis * r(-PI, PI))
}

/// One to six primitives around `center`, and sometimes a floor (a halfspace, slightly tilted).
fn random_world(rng: &mut ChaCha8Rng, center: Vector3, spread: Real) -> Vec<WorldObject> {
    let mut world = Vec::new();
    for k in 0..rng.random_range(1..=6) {
        let mut r = |lo: Real, hi: Real| rng.random_range(lo..hi);
        let p = match (r(0.0, 4.0)) as usize {
            0 => Primitive::Box { half_extents: Vector3::new(r(0.02, 0.2), r(0.02, 0.2), r(0.02, 0.2)) },
            1 => Primitive::Sphere { radius: r(0.02, 0.15) },
            2 => Primitive::Cylinder { radius: r(0.02, 0.12), half_height: r(0.02, 0.2) },
            _ => Primitive::Capsule { radius: r(0.02, 0.1), half_height: r(0.0, 0.2) },
        };
        let pose = random_pose(rng, center, spread);
        world.push(WorldObject::primitive(format!("object{k}"), p, pose));
    }
    if rng.random_bool(0.3) {
        let normal = Vector3::new(rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2), 1.0).normalize();
        let offset = center.z + rng.random_range(-1.5..0.0) * spread;
        let pose = random_pose(rng, Vector3::zeros(), 1e-9);
        // The halfspace {normal·u ≤ offset} in the object's frame, placed by a turn of the frame
        // and the same turn of the normal back: the world sees `normal` unchanged.
        let local = pose.rotation.inverse() * normal;
        world.push(WorldObject::primitive("floor", Primitive::Halfspace { normal: local, offset }, pose));
    }
    world
}

/// Each configuration entry's range: the joint limits, [−π, π] for a continuous joint.
fn bounds(robot: &FittedRobot) -> Vec<(Real, Real)> {
    (0..robot.model.dof()).map(|k| robot.model.variable_joint(k).limits.unwrap_or((-PI, PI))).collect()
}

/// A configuration within `bounds`, or (one in six) with entries up to 0.5 outside them.
fn random_configuration(rng: &mut ChaCha8Rng, bounds: &[(Real, Real)]) -> Vec<Real> {
    let outside = if rng.random_bool(1.0 / 6.0) { 0.5 } else { 0.0 };
    bounds.iter().map(|&(lo, hi)| rng.random_range(lo - outside..hi + outside)).collect()
}

fn verdict(a: &ConfigurationAnswer) -> (bool, bool, bool) {
    (a.collides, a.world, a.self_collision)
}

/// What one robot's cases saw, to make sure both verdicts and every branch were exercised.
#[derive(Debug, Default)]
struct Seen {
    lanes: usize,
    colliding: usize,
    free: usize,
    first_none: usize,
    first_later: usize,
    rake_free: usize,
    rake_first_block: usize,
    rake_later_block: usize,
}

/// The rake of `a → b` from single checks: `n = max(1, ⌈‖b − a‖ · resolution⌉)` samples
/// `a + (i / n)(b − a)`, i = 1..=n, taken block by block in [`rake_order`]: the smallest colliding
/// `i / n` of the first block holding one, the samples of the blocks up to it, and its index.
fn rake_reference(
    reference: &mut RobotChecker<'_>,
    a: &[Real],
    b: &[Real],
    resolution: Real,
    base: &Isometry3,
    padding: Real,
) -> (Option<Real>, usize, usize) {
    let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
    let length = a.iter().zip(b).map(|(x, y)| (y - x) * (y - x)).sum::<Real>().sqrt();
    let n = ((length * resolution).ceil() as usize).max(1);
    let mut checked = 0;
    for (j, chunk) in rake_order(n, BLOCK).chunks(BLOCK).enumerate() {
        checked += chunk.len();
        let hit = chunk
            .iter()
            .copied()
            .filter(|&i| {
                let t = i as Real / n as Real;
                let q: Vec<Real> = a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect();
                reference.check(&q, base, &options).unwrap().collides
            })
            .min();
        if let Some(i) = hit {
            return (Some(i as Real / n as Real), checked, j);
        }
    }
    (None, checked, 0)
}

/// `cases` random worlds around `center` for `robot`, each with random options, configurations,
/// blocks, first collisions and rakes, checked against single checks.
fn compare(robot: &FittedRobot, rng: &mut ChaCha8Rng, cases: usize, center: Vector3, spread: Real) -> Seen {
    let bounds = bounds(robot);
    let links: Vec<String> = robot
        .geometries
        .iter()
        .map(|g| robot.model.links()[g.link].name.clone())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut seen = Seen::default();
    for case in 0..cases {
        let world = random_world(rng, center, spread);
        let mut reference = RobotChecker::new(robot, world.clone(), &|_, _| None).unwrap();
        let mut block = RobotChecker::new(robot, world, &|_, _| None).unwrap();
        if rng.random_bool(0.5) && !links.is_empty() {
            let link = links[rng.random_range(0..links.len())].clone();
            let padding = [(link, rng.random_range(0.0..0.05))];
            reference.set_link_padding(&padding).unwrap();
            block.set_link_padding(&padding).unwrap();
        }
        let base = if rng.random_bool(0.3) { random_pose(rng, Vector3::zeros(), 0.1) } else { Isometry3::identity() };
        let padding = if rng.random_bool(0.5) { 0.0 } else { rng.random_range(0.001..0.05) };
        let options = CheckOptions {
            padding,
            distance: rng.random_bool(0.15),
            self_collision: rng.random_bool(0.7),
            gradient: false,
        };
        let what = format!("case {case}: padding {padding}, options {options:?}, base {base:?}");

        // Blocks of 1, 3, 8, 13 against the single checks, lane by lane.
        let configs: Vec<Vec<Real>> = (0..13).map(|_| random_configuration(rng, &bounds)).collect();
        let singles: Vec<ConfigurationAnswer> =
            configs.iter().map(|q| reference.check(q, &base, &options).unwrap()).collect();
        for size in [1, 3, 8, 13] {
            let start = rng.random_range(0..=13 - size);
            let flat: Vec<Real> = configs[start..start + size].concat();
            let mut out = Vec::new();
            block.check_block(&flat, &base, &options, false, &mut out).unwrap();
            assert_eq!(out.len(), size, "{what}: block of {size}");
            for (lane, a) in out.iter().enumerate() {
                let single = &singles[start + lane];
                assert_eq!(
                    verdict(a),
                    verdict(single),
                    "{what}: block of {size}, lane {lane}, q {:?}",
                    configs[start + lane]
                );
            }
            seen.lanes += size;
            // Stopping at the first collision: the same answers, up to and including it.
            let mut stopped = vec![];
            block.check_block(&flat, &base, &options, true, &mut stopped).unwrap();
            let first = singles[start..start + size].iter().position(|a| a.collides);
            assert_eq!(stopped.len(), first.map_or(size, |i| i + 1), "{what}: block of {size}, stopping");
            for (lane, a) in stopped.iter().enumerate() {
                assert_eq!(
                    verdict(a),
                    verdict(&singles[start + lane]),
                    "{what}: stopping block of {size}, lane {lane}"
                );
            }
        }
        seen.colliding += singles.iter().filter(|a| a.collides).count();
        seen.free += singles.iter().filter(|a| !a.collides).count();

        // The first collision (world and self, at the padding): the single checks' first, on a
        // sequence of the free configurations (in a random order) before the colliding ones.
        let verdict_options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
        let collides: Vec<bool> =
            configs.iter().map(|q| reference.check(q, &base, &verdict_options).unwrap().collides).collect();
        let mut sequence: Vec<usize> = (0..13).collect();
        for k in (1..13).rev() {
            sequence.swap(k, rng.random_range(0..=k));
        }
        sequence.sort_by_key(|&k| collides[k]);
        let n = rng.random_range(1..=13);
        let expected = sequence[..n].iter().position(|&k| collides[k]);
        let flat: Vec<Real> = sequence[..n].iter().flat_map(|&k| configs[k].iter().copied()).collect();
        assert_eq!(block.first_collision(&flat, &base, padding).unwrap(), expected, "{what}: first of {n}");
        assert_eq!(block.any_collision(&flat, &base, padding).unwrap(), expected.is_some(), "{what}: any of {n}");
        match expected {
            None => seen.first_none += 1,
            Some(0) => {}
            Some(_) => seen.first_later += 1,
        }

        // Rakes: a random segment, a short one, and a long one between free ends (where a
        // collision can hide between the first block's samples).
        for kind in 0..3 {
            let mut a = random_configuration(rng, &bounds);
            let mut b = random_configuration(rng, &bounds);
            if kind == 1 {
                let s = rng.random_range(0.02..0.3);
                b = a.iter().zip(&b).map(|(x, y)| x + s * (y - x)).collect();
            }
            for _ in 0..20 {
                let free = |q: &[Real], c: &mut RobotChecker| !c.check(q, &base, &verdict_options).unwrap().collides;
                if kind < 2 || (free(&a, &mut reference) && free(&b, &mut reference)) {
                    break;
                }
                a = random_configuration(rng, &bounds);
                b = random_configuration(rng, &bounds);
            }
            let resolution = if kind == 2 { 32.0 } else { [3.0, 8.0, 32.0][rng.random_range(0..3)] };
            let rake = block.rake_motion(&a, &b, resolution, &base, padding).unwrap();
            let (expected, checked, block_index) = rake_reference(&mut reference, &a, &b, resolution, &base, padding);
            assert_eq!(rake.collision, expected, "{what}: rake at resolution {resolution}, {a:?} → {b:?}");
            assert_eq!(rake.samples, checked, "{what}: rake at resolution {resolution}, samples checked");
            match (expected, block_index) {
                (None, _) => seen.rake_free += 1,
                (Some(_), 0) => seen.rake_first_block += 1,
                (Some(_), _) => seen.rake_later_block += 1,
            }
        }
    }
    seen
}

#[test]
fn rake_order_spreads_each_block_along_the_segment_and_visits_every_sample_once() {
    for n in 1..100 {
        for lanes in [1, 3, 8] {
            let order = rake_order(n, lanes);
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (1..=n).collect::<Vec<_>>(), "n {n}, lanes {lanes}");
            // Block j holds j + 1, j + 1 + s, …, s = ⌈n / lanes⌉ (the closed form).
            let s = n.div_ceil(lanes);
            let first: Vec<usize> = (0..lanes).map(|k| 1 + k * s).filter(|&i| i <= n).collect();
            assert_eq!(&order[..first.len()], &first[..], "n {n}, lanes {lanes}");
        }
    }
}

#[test]
fn gantry_blocks_agree_with_single_checks() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut total = Seen::default();
    for _ in 0..6 {
        let robot = gantry(&mut rng);
        let seen = compare(&robot, &mut rng, 60, Vector3::new(0.2, -0.1, 0.6), 0.6);
        total.lanes += seen.lanes;
        total.colliding += seen.colliding;
        total.free += seen.free;
        total.first_none += seen.first_none;
        total.first_later += seen.first_later;
        total.rake_free += seen.rake_free;
        total.rake_first_block += seen.rake_first_block;
        total.rake_later_block += seen.rake_later_block;
    }
    eprintln!("gantry: {total:?}");
    assert!(total.colliding > 300 && total.free > 300, "{total:?}");
    assert!(total.first_none > 10 && total.first_later > 10, "{total:?}");
    assert!(total.rake_free > 10 && total.rake_first_block > 10 && total.rake_later_block > 3, "{total:?}");
}

#[test]
fn slider_blocks_agree_with_single_checks() {
    let (robot, _dir) = slider();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let seen = compare(&robot, &mut rng, 300, Vector3::new(0.5, 0.0, 0.3), 0.5);
    eprintln!("slider: {seen:?}");
    assert!(seen.colliding > 200 && seen.free > 200, "{seen:?}");
    assert!(seen.first_none > 10 && seen.first_later > 10, "{seen:?}");
    assert!(seen.rake_free > 10 && seen.rake_first_block > 10 && seen.rake_later_block >= 1, "{seen:?}");
}

#[test]
fn panda_blocks_agree_with_single_checks() {
    let robot = panda();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let seen = compare(&robot, &mut rng, 200, Vector3::new(0.4, 0.0, 0.5), 0.5);
    eprintln!("panda: {seen:?}");
    assert!(seen.colliding > 200 && seen.free > 200, "{seen:?}");
    assert!(seen.first_none > 10 && seen.first_later > 10, "{seen:?}");
    assert!(seen.rake_free > 10 && seen.rake_first_block > 10 && seen.rake_later_block > 3, "{seen:?}");
}

#[test]
fn bad_blocks_are_refused_naming_the_field() {
    let robot = panda();
    let mut checker = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    let field = |e: sublevel_robot::Error| match e {
        sublevel_robot::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other}"),
    };
    let id = Isometry3::identity();
    let q = [0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.7];
    let mut flat = [q, q, q].concat();
    let mut out = Vec::new();
    let options = CheckOptions::default();
    assert_eq!(field(checker.check_block(&flat[..20], &id, &options, false, &mut out).unwrap_err()), "configurations");
    flat[7 * 2 + 4] = Real::INFINITY;
    out.clear();
    assert_eq!(
        field(checker.check_block(&flat, &id, &options, false, &mut out).unwrap_err()),
        "configurations[2].q[4]"
    );
    assert!(out.is_empty(), "refused before any configuration is checked");
    assert_eq!(field(checker.first_collision(&flat, &id, 0.0).unwrap_err()), "configurations[2].q[4]");
    assert_eq!(field(checker.first_collision(&flat[..7], &id, -1.0).unwrap_err()), "padding");
    assert_eq!(field(checker.rake_motion(&q[..6], &q, 32.0, &id, 0.0).unwrap_err()), "start");
    assert_eq!(field(checker.rake_motion(&q, &flat[14..], 32.0, &id, 0.0).unwrap_err()), "end[4]");
    assert_eq!(field(checker.rake_motion(&q, &q, 0.0, &id, 0.0).unwrap_err()), "resolution");
    assert_eq!(field(checker.rake_motion(&q, &q, Real::NAN, &id, 0.0).unwrap_err()), "resolution");
    // An empty block: no answers, no collision.
    out.clear();
    checker.check_block(&[], &id, &options, false, &mut out).unwrap();
    assert!(out.is_empty());
    assert_eq!(checker.first_collision(&[], &id, 0.0).unwrap(), None);
    assert!(!checker.any_collision(&[], &id, 0.0).unwrap());
    assert_eq!(field(checker.any_collision(&flat, &id, 0.0).unwrap_err()), "configurations[2].q[4]");
}
