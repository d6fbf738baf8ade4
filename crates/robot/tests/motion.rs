//! Motions certified by conservative advancement, against closed forms: a ball on a rail moving
//! into, past and through obstacles, and a thin plate that sampling at VAMP's resolution (32
//! configurations per unit of joint distance) steps over.

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
