//! Motions certified by conservative advancement, against closed forms: a ball on a rail moving
//! into, past and through obstacles, and a thin plate that sampling at VAMP's resolution (32
//! configurations per unit of joint distance) steps over; and on the fitted Panda, carried bounds
//! against the reference and against dense sampling on the meshes.

use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_robot::{fit_robot, MotionChecker, MotionOptions, RobotChecker, RobotFitSettings, WorldObject};
use sublevel_robot::{CheckOptions, FittedRobot};

/// A ball of radius `r` on a prismatic rail along x (no mesh: nothing to fit).
fn rail(r: Real) -> (FittedRobot, tempfile::TempDir) {
    let urdf = format!(
        r#"<robot name="rail"><link name="base"/>
        <link name="ball"><collision><geometry><sphere radius="{r}"/></geometry></collision></link>
        <joint name="x" type="prismatic"><parent link="base"/><child link="ball"/><axis xyz="1 0 0"/>
          <limit lower="-2" upper="2" effort="1" velocity="1"/></joint></robot>"#
    );
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("rail.urdf"), urdf).unwrap();
    let robot = fit_robot(&dir.path().join("rail.urdf"), None, &RobotFitSettings::default(), &|_| {}).unwrap();
    (robot, dir)
}

fn object(name: &str, primitive: Primitive, at: [Real; 3]) -> WorldObject {
    WorldObject::primitive(name, primitive, Isometry3::translation(at[0], at[1], at[2]))
}

#[test]
fn a_ball_moving_into_a_ball_or_a_box_stops_at_the_exact_contact() {
    let (robot, _dir) = rail(0.05);
    let id = Isometry3::identity();
    // Contact when the ball's center reaches x = 0.85: t* = 0.85 / 1.5 for both obstacles.
    for obstacle in [Primitive::Sphere { radius: 0.1 }, Primitive::Box { half_extents: Vector3::new(0.1, 0.3, 0.3) }] {
        let world = vec![object("o", obstacle, [1.0, 0.0, 0.0])];
        let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
        let mut motions = MotionChecker::new(&mut checker).unwrap();
        for tolerance in [1e-3, 1e-6] {
            let options = MotionOptions { tolerance, ..Default::default() };
            let a = motions.check_motion(&[0.0], &[1.5], &id, &options).unwrap();
            let exact = 0.85 / 1.5;
            let t = a.contact.unwrap();
            assert!(!a.valid && a.decided);
            assert!(
                t <= exact && t >= exact - tolerance / 1.5 - 1e-12,
                "{obstacle:?} tol {tolerance}: t {t} vs {exact}"
            );
            assert_eq!(a.pair, Some((0, Some(0))));
            assert!(a.steps < 40, "{} steps", a.steps);
        }
        // Backwards from beyond the obstacle's far side: contact at x = 1.15, t* = (2 − 1.15) / 2.
        let options = MotionOptions { tolerance: 1e-6, ..Default::default() };
        let a = motions.check_motion(&[2.0], &[0.0], &id, &options).unwrap();
        assert!((a.contact.unwrap() - 0.85 / 2.0).abs() < 1e-6);
    }
}

#[test]
fn a_ball_passing_an_obstacle_is_valid_and_padding_closes_the_gap() {
    let (robot, _dir) = rail(0.05);
    let id = Isometry3::identity();
    // The ball passes 0.05 m from the obstacle's surface.
    let world = vec![object("o", Primitive::Sphere { radius: 0.1 }, [1.0, 0.2, 0.0])];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let a = motions.check_motion(&[0.0], &[2.0], &id, &MotionOptions::default()).unwrap();
    assert!(a.valid && a.decided && a.contact.is_none(), "{a:?}");
    // With 6 cm of padding the ball comes within it at the point where the distance falls to 0.06:
    // |(x − 1, 0.2)| = 0.21 → x = 1 − √(0.21² − 0.2²).
    let options = MotionOptions { padding: 0.06, tolerance: 1e-6, ..Default::default() };
    let a = motions.check_motion(&[0.0], &[2.0], &id, &options).unwrap();
    let x = 1.0 - (0.21f64.powi(2) - 0.04).sqrt();
    assert!((a.contact.unwrap() * 2.0 - x).abs() < 1e-5, "{:?} vs {}", a.contact, x / 2.0);
    // The same 6 cm as the ball's link padding (3 of them global, 3 the link's): the same contact.
    drop(motions);
    checker.set_link_padding(&[("ball".to_owned(), 0.03)]).unwrap();
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let options = MotionOptions { padding: 0.03, tolerance: 1e-6, ..Default::default() };
    let a = motions.check_motion(&[0.0], &[2.0], &id, &options).unwrap();
    assert!((a.contact.unwrap() * 2.0 - x).abs() < 1e-5, "{:?} vs {}", a.contact, x / 2.0);
}

#[test]
fn sampling_at_vamps_resolution_steps_over_a_thin_plate_that_the_motion_check_finds() {
    let (robot, _dir) = rail(0.005);
    let id = Isometry3::identity();
    // A 2 mm plate between the samples x = 15/32 and 16/32.
    let plate_x = 15.5 / 32.0;
    let world =
        vec![object("plate", Primitive::Box { half_extents: Vector3::new(0.001, 0.5, 0.5) }, [plate_x, 0.0, 0.0])];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    // VAMP validates a segment of joint length 1 at 32 configurations per unit: every one is free.
    for i in 0..=32 {
        let q = i as Real / 32.0;
        let a = checker.check(&[q], &id, &CheckOptions { distance: false, ..Default::default() }).unwrap();
        assert!(!a.collides, "sample {i} collides");
    }
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let options = MotionOptions { tolerance: 1e-6, ..Default::default() };
    let a = motions.check_motion(&[0.0], &[1.0], &id, &options).unwrap();
    let exact = plate_x - 0.001 - 0.005;
    assert!(!a.valid);
    assert!((a.contact.unwrap() - exact).abs() <= 1e-6, "{:?} vs {exact}", a.contact);
}

#[test]
fn bad_motion_input_is_refused_naming_the_field() {
    let (robot, _dir) = rail(0.05);
    let mut checker = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let id = Isometry3::identity();
    let field = |e: sublevel_robot::Error| match e {
        sublevel_robot::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other}"),
    };
    assert_eq!(field(motions.check_motion(&[0.0, 1.0], &[1.0], &id, &MotionOptions::default()).unwrap_err()), "q0");
    assert_eq!(field(motions.check_motion(&[0.0], &[Real::NAN], &id, &MotionOptions::default()).unwrap_err()), "q1[0]");
    let bad = MotionOptions { tolerance: 0.0, ..Default::default() };
    assert_eq!(field(motions.check_motion(&[0.0], &[1.0], &id, &bad).unwrap_err()), "tolerance");
    // No world and no self pair: valid in one step.
    let a = motions.check_motion(&[0.0], &[1.0], &id, &MotionOptions::default()).unwrap();
    assert!(a.valid && a.steps == 1);
}

/// A deterministic uniform sample in [lo, hi] (xorshift, no dependency).
fn uniform(state: &mut u64, lo: Real, hi: Real) -> Real {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    lo + (hi - lo) * ((*state >> 11) as Real / (1u64 << 53) as Real)
}

/// The fitted Panda (meshes, sphere trees, clearance tables) among boxes, balls and cylinders:
/// random joint-space segments — planner-edge lengths from free configurations — checked with
/// carried bounds (the default) and without (every pair bounded again at every step, exact mesh
/// searches), each against 400 configurations sampled along the segment on the meshes. Each
/// answer is sound: a valid motion has no colliding sample, a contact comes no later than the first
/// colliding sample and is one (its configuration collides within `padding + tolerance`). The two
/// agree on all but grazing motions (a contact within the tolerance, which either may step over).
#[test]
fn carried_bounds_answer_as_the_reference_and_as_dense_sampling_on_the_panda() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    let robot = FittedRobot::load(&path).unwrap();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut world = Vec::new();
    for k in 0..12 {
        let at = [uniform(&mut state, 0.2, 0.7), uniform(&mut state, -0.5, 0.5), uniform(&mut state, 0.05, 0.9)];
        let angle = uniform(&mut state, 0.0, std::f64::consts::PI);
        let primitive = match k % 3 {
            0 => Primitive::Box {
                half_extents: Vector3::new(
                    uniform(&mut state, 0.02, 0.2),
                    uniform(&mut state, 0.02, 0.2),
                    uniform(&mut state, 0.01, 0.1),
                ),
            },
            1 => Primitive::Sphere { radius: uniform(&mut state, 0.03, 0.12) },
            _ => Primitive::Cylinder {
                radius: uniform(&mut state, 0.01, 0.06),
                half_height: uniform(&mut state, 0.05, 0.2),
            },
        };
        let pose = Isometry3::new(Vector3::new(at[0], at[1], at[2]), Vector3::new(angle, 0.3 * angle, 0.0));
        world.push(WorldObject::primitive(format!("o{k}"), primitive, pose));
    }
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let id = Isometry3::identity();
    let limits: Vec<(Real, Real)> =
        (0..robot.model.dof()).map(|k| robot.model.variable_joint(k).limits.unwrap_or((-3.0, 3.0))).collect();
    let options = MotionOptions::default();
    let threshold = options.padding + options.tolerance;
    let verdict = CheckOptions { distance: false, ..Default::default() };
    let within = CheckOptions { padding: threshold + 1e-9, distance: false, ..Default::default() };
    let mut motions = MotionChecker::new(&mut checker).unwrap();
    let (mut free, mut contacts, mut world, mut grazing) = (0, 0, 0, 0);
    let (mut steps, mut micros) = ([0usize; 2], [0.0; 2]);
    let mut segments = 0;
    while segments < 120 {
        let q0: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        if motions.checker().check(&q0, &id, &within).unwrap().collides {
            continue;
        }
        // A planner's edge: up to 2 rad of joint distance, within the limits.
        let length = uniform(&mut state, 0.1, 2.0);
        let direction: Vec<Real> = limits.iter().map(|_| uniform(&mut state, -1.0, 1.0)).collect();
        let norm = direction.iter().map(|d| d * d).sum::<Real>().sqrt();
        let q1: Vec<Real> = q0
            .iter()
            .zip(&direction)
            .zip(&limits)
            .map(|((q, d), &(lo, hi))| (q + length * d / norm).clamp(lo, hi))
            .collect();
        segments += 1;
        let mut answers = Vec::new();
        for (k, carried) in [true, false].into_iter().enumerate() {
            motions.set_carried_bounds(carried);
            let clock = std::time::Instant::now();
            answers.push(motions.check_motion(&q0, &q1, &id, &options).unwrap());
            micros[k] += clock.elapsed().as_secs_f64() * 1e6;
        }
        motions.set_carried_bounds(true);
        let samples = 400;
        let first_colliding = (0..=samples).map(|k| k as Real / samples as Real).find(|t| {
            let q: Vec<Real> = q0.iter().zip(&q1).map(|(a, b)| a + t * (b - a)).collect();
            motions.checker().check(&q, &id, &verdict).unwrap().collides
        });
        for (a, name) in answers.iter().zip(["carried", "reference"]) {
            assert!(a.decided, "{name}: {a:?}");
            match (a.valid, a.contact, first_colliding) {
                (true, _, None) => {}
                (true, _, Some(f)) => panic!("{name}: valid, but the sample at t = {f} collides: {q0:?} → {q1:?}"),
                (false, Some(c), f) => {
                    assert!(
                        f.is_none_or(|f| c <= f + 1e-12),
                        "{name}: contact at {c} after the colliding sample {f:?}"
                    );
                    let q = a.contact_q.as_ref().unwrap();
                    assert!(
                        motions.checker().check(q, &id, &within).unwrap().collides,
                        "{name}: no contact within {threshold} m at t = {c}"
                    );
                }
                (false, None, _) => panic!("{name}: invalid without a contact: {a:?}"),
            }
        }
        let (a, b) = (&answers[0], &answers[1]);
        steps[0] += a.steps;
        steps[1] += b.steps;
        if a.valid != b.valid {
            // Both sound (above): the motion comes within the tolerance without colliding.
            assert!(first_colliding.is_none(), "{a:?} against {b:?}");
            grazing += 1;
        } else if a.valid {
            free += 1;
        } else {
            contacts += 1;
            world += usize::from(a.self_pair.is_none());
        }
    }
    println!(
        "{free} free, {contacts} contacts ({world} with the world), {grazing} grazing; carried: {} steps, {:.0} µs; \
         reference: {} steps, {:.0} µs",
        steps[0], micros[0], steps[1], micros[1]
    );
    assert!(free >= 20 && world >= 10 && contacts > world, "{free} free, {contacts} contacts ({world} world)");
    assert!(grazing <= 3, "{grazing} grazing motions answered differently");
}
