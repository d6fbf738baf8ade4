//! The sampled edge check of [`RobotValidity`] (its samples in rakes, checked in blocks) against
//! the one-sample-at-a-time check in OMPL's order ([`sampled_edge_free`]) and against every
//! sample checked alone by [`RobotChecker::check`]: the verdicts are equal on random Panda
//! segments among MotionBenchMaker scenes, and a continuous joint's edge goes the shorter way
//! round (a closed-form world).

use rand::{Rng, SeedableRng};
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::primitive::Primitive;
use sublevel_plan::validity::sampled_edge_free;
use sublevel_plan::{
    fix_start_bounds, joint_goal, start_from_joints, Goal, JointSpace, RobotValidity, Validity,
    START_STATE_MAX_BOUNDS_ERROR,
};
use sublevel_robot::{
    fit_robot_text, CheckOptions, FittedRobot, MeshSource, MotionChecker, RobotChecker, RobotFitSettings, WorldObject,
};
use sublevel_scene::moveit::{allowed_override, world_objects, PlanningScene};

fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Whether every sample `i / n`, i = 1..=n, of `a → b` is free, each checked alone (the
/// reference: no order, no blocks).
fn every_sample_free(
    checker: &mut RobotChecker<'_>,
    space: &JointSpace,
    a: &[Real],
    b: &[Real],
    resolution: Real,
    padding: Real,
) -> bool {
    let n = ((space.distance(a, b) * resolution).ceil() as usize).max(1);
    let options = CheckOptions { padding, distance: false, self_collision: true, gradient: false };
    let mut q = Vec::new();
    (1..=n).all(|i| {
        space.interpolate(a, b, i as Real / n as Real, &mut q);
        !checker.check(&q, &Isometry3::identity(), &options).unwrap().collides
    })
}

#[test]
fn rake_edges_agree_with_one_sample_at_a_time_on_random_panda_segments() {
    let robot = FittedRobot::load(&root().join("data/robots/panda/panda.robot.json")).unwrap();
    let space = JointSpace::of(&robot.model);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let (mut free, mut colliding, mut samples) = (0, 0, 0);
    for (scenario, padding, margin) in [("bookshelf_small", 0.0, 0.0), ("box", 0.0, 0.002), ("cage", 0.01, 0.0)] {
        let path = root().join(format!("data/robots/mbm_panda/scenes/{scenario}/scene0001.yaml"));
        let scene = PlanningScene::from_yaml(&std::fs::read(path).unwrap()).unwrap();
        let (world, _) = world_objects(&scene).unwrap();
        let allowed = allowed_override(&scene);
        let mut reference = RobotChecker::new(&robot, world.clone(), &allowed).unwrap();
        let mut checker = RobotChecker::new(&robot, world, &allowed).unwrap();
        let mut validity =
            RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), Isometry3::identity(), padding);
        validity.set_search_margin(margin);
        let options =
            CheckOptions { padding: padding + margin, distance: false, self_collision: true, gradient: false };
        let mut edges = 0;
        while edges < 250 {
            // A free start (as the planner's edges have), an end up to 3 away within the limits.
            let a: Vec<Real> = space.bounds.iter().map(|&(lo, hi)| rng.random_range(lo..hi)).collect();
            if reference.check(&a, &Isometry3::identity(), &options).unwrap().collides {
                continue;
            }
            let direction: Vec<Real> = (0..a.len()).map(|_| rng.random_range(-1.0..1.0)).collect();
            let norm = direction.iter().map(|d| d * d).sum::<Real>().sqrt();
            let length = rng.random_range(0.02..3.0);
            let b: Vec<Real> = (0..a.len())
                .map(|k| {
                    let (lo, hi) = space.bounds[k];
                    (a[k] + length * direction[k] / norm).clamp(lo, hi)
                })
                .collect();
            let resolution = if edges % 4 == 3 { 8.0 } else { 32.0 };
            let n = ((space.distance(&a, &b) * resolution).ceil() as usize).max(1);
            let before = validity.counts();
            let rake = validity.edge_free(&a, &b, resolution).unwrap();
            let after = validity.counts();
            let one_at_a_time = sampled_edge_free(&mut validity, &a, &b, resolution).unwrap();
            let every = every_sample_free(&mut reference, &space, &a, &b, resolution, padding + margin);
            assert_eq!(rake, one_at_a_time, "{scenario} edge {edges}: rakes vs sample order, {a:?} → {b:?}");
            assert_eq!(rake, every, "{scenario} edge {edges}: rakes vs every sample alone, {a:?} → {b:?}");
            assert_eq!(after.edges, before.edges + 1);
            let checked = after.states - before.states;
            if rake {
                assert_eq!(checked, n, "{scenario} edge {edges}: a free edge checks its {n} samples");
                free += 1;
            } else {
                assert!(checked >= 1 && checked <= n, "{scenario} edge {edges}: {checked} of {n} samples");
                colliding += 1;
            }
            samples += n;
            edges += 1;
        }
    }
    assert!(free >= 200 && colliding >= 100, "both verdicts present: {free} free, {colliding} colliding edges");
    eprintln!("{free} free, {colliding} colliding edges, {samples} samples");
}

#[test]
fn bad_edges_are_refused_naming_the_end() {
    let robot = FittedRobot::load(&root().join("data/robots/panda/panda.robot.json")).unwrap();
    let mut checker = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    let mut validity = RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), Isometry3::identity(), 0.0);
    let field = |e: sublevel_core::Error| match e {
        sublevel_core::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other}"),
    };
    let q = [0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.7];
    assert_eq!(field(validity.edge_free(&q[..6], &q, 32.0).unwrap_err()), "start");
    let mut bad = q;
    bad[3] = Real::NAN;
    assert_eq!(field(validity.edge_free(&q, &bad, 32.0).unwrap_err()), "end[3]");
    assert!(validity.edge_free(&q, &q, 32.0).unwrap(), "a free point is a free edge");
}

/// One link on a continuous joint about z: a box 0.4 × 0.1 × 0.1 centered 0.5 m along the link's
/// x axis, so at angle θ it spans radii [0.3, 0.7] in direction θ.
const TURNER: &str = r#"<robot name="turner">
  <link name="base"/>
  <link name="arm"><collision><origin xyz="0.5 0 0"/><geometry><box size="0.4 0.1 0.1"/></geometry></collision></link>
  <joint name="turn" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/></joint>
</robot>"#;

#[test]
fn a_continuous_joint_edge_goes_the_shorter_way_round() {
    let meshes = std::collections::HashMap::new();
    let robot = fit_robot_text(TURNER.into(), None, MeshSource::Memory(&meshes), &RobotFitSettings::default(), &|_| {})
        .unwrap();
    // A ball at angle 0 (x = 0.5): the arm meets it for |θ| ≤ about 0.18 rad (the box's half
    // width 0.05 plus the ball's radius 0.03, at radius 0.5), never near θ = ±π.
    let world =
        vec![WorldObject::primitive("ball", Primitive::Sphere { radius: 0.03 }, Isometry3::translation(0.5, 0.0, 0.0))];
    let mut checker = RobotChecker::new(&robot, world, &|_, _| None).unwrap();
    let id = Isometry3::identity();
    // Linear interpolation from 3.0 to −3.0 passes θ = 0: the rake along the straight line collides.
    let linear = checker.rake_motion(&[3.0], &[-3.0], 32.0, &id, 0.0).unwrap();
    let t = linear.collision.expect("the long way round passes the ball");
    assert!((t - 0.5).abs() < 0.05, "{t}");
    let mut validity = RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), id, 0.0);
    assert!(validity.space().wraps[0]);
    // The short way, through ±π, is free (the arm's closest approach to the ball: at θ = ±3.0).
    assert!(validity.edge_free(&[3.0], &[-3.0], 32.0).unwrap());
    assert!(sampled_edge_free(&mut validity, &[3.0], &[-3.0], 32.0).unwrap());
    let n = ((2.0 * PI - 6.0) * 32.0).ceil() as usize;
    assert_eq!(validity.counts().states, n + n, "the rakes and the one-at-a-time check, every sample");
    // From 1.0 to −1.0 the short way passes θ = 0.
    assert!(!validity.edge_free(&[1.0], &[-1.0], 32.0).unwrap());
    assert!(!sampled_edge_free(&mut validity, &[1.0], &[-1.0], 32.0).unwrap());
    drop(validity);
    // The ball at θ = π instead (x = −0.5): the short way from 2.8 to −2.8 meets it (both ends 0.34 rad off it, free), the straight
    // line does not.
    let behind = vec![WorldObject::primitive(
        "ball",
        Primitive::Sphere { radius: 0.03 },
        Isometry3::translation(-0.5, 0.0, 0.0),
    )];
    let mut checker = RobotChecker::new(&robot, behind, &|_, _| None).unwrap();
    assert_eq!(checker.rake_motion(&[2.8], &[-2.8], 32.0, &id, 0.0).unwrap().collision, None);
    let mut validity = RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), id, 0.0);
    assert!(!validity.edge_free(&[2.8], &[-2.8], 32.0).unwrap());
    assert!(!sampled_edge_free(&mut validity, &[2.8], &[-2.8], 32.0).unwrap());
    assert!(validity.state_free(&[2.8]).unwrap() && validity.state_free(&[-2.8]).unwrap());
}

/// A deadline reaches inside the long answers: past it, a free edge at the finest resolution
/// allowed answers "not free" before its first block, without checking a configuration, and a
/// certificate (the box scene's request, from the start to just before the straight line's first
/// contact) stops undecided within [`sublevel_robot::advance::STOP_EVERY`] steps; without a
/// deadline the same edge is free (the every-sample reference agrees) and the certificate proves
/// the motion free in more steps.
#[test]
fn a_deadline_stops_edges_and_certificates_conservatively() {
    let robot = FittedRobot::load(&root().join("data/robots/panda/panda.robot.json")).unwrap();
    let space = JointSpace::of(&robot.model);
    let path = root().join("data/robots/mbm_panda/scenes/box/scene0001.yaml");
    let scene = PlanningScene::from_yaml(&std::fs::read(path).unwrap()).unwrap();
    let (world, _) = world_objects(&scene).unwrap();
    let allowed = allowed_override(&scene);
    let mut reference = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    let mut free = RobotChecker::new(&robot, Vec::new(), &|_, _| None).unwrap();
    let mut edges = RobotValidity::new(MotionChecker::new(&mut free).unwrap(), Isometry3::identity(), 0.0);
    // The Panda's ready pose, and joint 1 turned by one radian: free all along, with no world.
    let a = vec![0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let mut b = a.clone();
    b[0] = 1.0;
    let resolution = sublevel_plan::MAX_RESOLUTION;
    assert!(every_sample_free(&mut reference, &space, &a, &b, resolution, 0.0));
    edges.set_deadline(Some(std::time::Instant::now()));
    assert!(!edges.edge_free(&a, &b, resolution).unwrap());
    assert_eq!(edges.counts().states, 0, "the stopped edge checked configurations");
    edges.set_deadline(None);
    assert!(edges.edge_free(&a, &b, resolution).unwrap());
    assert_eq!(edges.counts().states, 1000);

    let text = std::fs::read(root().join("data/robots/mbm_panda/requests/box/request0001.yaml")).unwrap();
    let request = sublevel_scene::moveit::MotionPlanRequest::from_yaml(&text).unwrap();
    let names = robot.model.variable_names();
    let pick = |joints: &[(String, Real)]| -> Vec<Real> {
        names.iter().map(|n| joints.iter().find(|(m, _)| m == n).unwrap().1).collect()
    };
    let (q0, goal) = (pick(&request.start), pick(&request.goal));
    // Up to just before the straight line's first contact (t ≈ 0.0974): free, and ending within
    // millimeters of the box, where conservative advancement takes small steps.
    let q1: Vec<Real> = q0.iter().zip(&goal).map(|(a, b)| a + 0.0970 * (b - a)).collect();
    let mut checker = RobotChecker::new(&robot, world, &allowed).unwrap();
    let mut certified = RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), Isometry3::identity(), 0.0);
    certified.set_deadline(Some(std::time::Instant::now()));
    assert_eq!(certified.certify(&q0, &q1, 1e-3).unwrap(), sublevel_plan::Certificate::Undecided);
    let stopped = certified.counts().advancement_steps;
    assert!(stopped <= sublevel_robot::advance::STOP_EVERY, "{stopped} steps past the deadline");
    certified.set_deadline(None);
    assert_eq!(certified.certify(&q0, &q1, 1e-3).unwrap(), sublevel_plan::Certificate::Free);
    let full = certified.counts().advancement_steps - stopped;
    assert!(full > stopped, "the whole certificate took {full} steps, the stopped one {stopped}");
}

/// Every setting that sizes a plan's work is bounded: just inside each bound validates, just
/// outside is refused naming the setting.
#[test]
fn plan_settings_are_bounded() {
    use std::time::Duration;
    use sublevel_plan::PlanSettings;
    let field = |s: PlanSettings| match s.validate() {
        Ok(()) => String::new(),
        Err(sublevel_core::Error::InvalidArgument { field, .. }) => field,
        Err(e) => panic!("{e}"),
    };
    let d = PlanSettings::default;
    assert_eq!(field(d()), "");
    let edge = [
        (PlanSettings { resolution: 1000.0, ..d() }, PlanSettings { resolution: 1000.5, ..d() }, "resolution"),
        (PlanSettings { tolerance: 0.1, ..d() }, PlanSettings { tolerance: 1e300, ..d() }, "tolerance"),
        (PlanSettings { padding: 1.0, ..d() }, PlanSettings { padding: 1.01, ..d() }, "padding"),
        (PlanSettings { max_goals: 64, ..d() }, PlanSettings { max_goals: 65, ..d() }, "max_goals"),
        (PlanSettings { smoothing_passes: 8, ..d() }, PlanSettings { smoothing_passes: 9, ..d() }, "smoothing_passes"),
        (
            PlanSettings { timeout: Duration::from_secs(3600), ..d() },
            PlanSettings { timeout: Duration::from_secs(3601), ..d() },
            "timeout",
        ),
    ];
    for (inside, outside, name) in edge {
        assert_eq!(field(inside), "", "{name}");
        assert_eq!(field(outside), name);
    }
}

/// A revolute joint printed at five digits (±3.14159), a prismatic torso and a continuous wrist.
const BOUNDED_URDF: &str = r#"<robot name="bounded">
  <link name="base"/><link name="torso"/><link name="arm"/><link name="hand"/>
  <joint name="torso_lift" type="prismatic"><parent link="base"/><child link="torso"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.4" effort="1" velocity="1"/></joint>
  <joint name="wrist_roll" type="revolute"><parent link="torso"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3.14159" upper="3.14159" effort="1" velocity="1"/></joint>
  <joint name="spin" type="continuous"><parent link="arm"/><child link="hand"/><axis xyz="1 0 0"/></joint>
</robot>"#;

/// The bound of ±π as URDFs print it, at five digits.
#[allow(clippy::approx_constant)]
const PRINTED_PI: f64 = 3.14159;

#[test]
fn starts_and_goals_near_the_limits_are_taken_as_moveit_takes_them() {
    let model = sublevel_robot::RobotModel::from_urdf_str(BOUNDED_URDF).unwrap();
    let field = |e: sublevel_core::Error| match e {
        sublevel_core::Error::InvalidArgument { field, .. } => field,
        other => panic!("{other:?}"),
    };
    // A start at ±π, 2.65e-6 past the printed bound: moved onto it, said; the continuous joint
    // and values inside are kept.
    let given = [("wrist_roll".to_owned(), -PI), ("torso_lift".to_owned(), 0.2), ("spin".to_owned(), 7.0)];
    let (q, moved) = start_from_joints(&model, "start", &given, &[], START_STATE_MAX_BOUNDS_ERROR).unwrap();
    assert_eq!(q, vec![0.2, -PRINTED_PI, 7.0]);
    assert_eq!(moved.len(), 1);
    assert!(moved[0].starts_with("start[1]: joint `wrist_roll`") && moved[0].contains("-3.14159"), "{}", moved[0]);
    // 0.05 past the bound is still moved (MoveIt's default), 0.0501 is refused naming the entry;
    // a value within the rounding margin is moved silently.
    let mut q = vec![0.45, 0.0, 0.0];
    assert_eq!(fix_start_bounds(&model, "start", &mut q, 0.05).unwrap().len(), 1);
    assert_eq!(q[0], 0.4);
    assert_eq!(field(fix_start_bounds(&model, "s", &mut [0.4501, 0.0, 0.0], 0.05).unwrap_err()), "s[0]");
    let mut q = vec![0.4 + 1e-12, PRINTED_PI + 1e-10, 0.0];
    assert!(fix_start_bounds(&model, "start", &mut q, 0.05).unwrap().is_empty());
    assert_eq!(q, vec![0.4, PRINTED_PI, 0.0]);
    // With a bound error of 0, only rounding is moved.
    assert_eq!(field(fix_start_bounds(&model, "s", &mut [0.0, -PI, 0.0], 0.0).unwrap_err()), "s[1]");

    // A goal at π with a tolerance of 0.01 meets the limits: the region is cut to [π − 0.01,
    // PRINTED_PI] and centered on the bound, and the answer says so.
    let start = vec![0.2, 0.0, 0.0];
    let constraints = vec![("wrist_roll".to_owned(), PI, 0.01, 0.01)];
    let (goal, moved) = joint_goal(&model, "goal", &constraints, &start, 0.05).unwrap();
    let Goal::Region(r) = goal else { panic!("{goal:?}") };
    assert_eq!(r.center[1], PRINTED_PI);
    assert!((r.center[1] - r.below[1] - (PI - 0.01)).abs() < 1e-12 && r.above[1] == 0.0, "{r:?}");
    assert!(moved.len() == 1 && moved[0].starts_with("goal[0].position: joint `wrist_roll`"), "{moved:?}");
    // A goal interval that misses the limits by more than the bound error is refused; one exactly
    // on the bound within rounding is a single configuration, moved silently.
    let off = vec![("torso_lift".to_owned(), 0.6, 0.05, 0.05)];
    assert_eq!(field(joint_goal(&model, "goal", &off, &start, 0.05).unwrap_err()), "goal[0].position");
    let rounding = vec![("wrist_roll".to_owned(), -(PRINTED_PI + 7e-16), 0.0, 0.0)];
    let (goal, moved) = joint_goal(&model, "goal", &rounding, &start, 0.05).unwrap();
    assert_eq!(goal, Goal::Configurations(vec![vec![0.2, -PRINTED_PI, 0.0]]));
    assert!(moved.is_empty());
    // A goal at −π with no tolerance, 2.65e-6 past the bound: taken at the bound, as MoveIt's
    // JointConstraint takes it, and said; with no bound error, refused.
    let exact = vec![("wrist_roll".to_owned(), -PI, 0.0, 0.0)];
    let (goal, moved) = joint_goal(&model, "goal", &exact, &start, 0.05).unwrap();
    assert_eq!(goal, Goal::Configurations(vec![vec![0.2, -PRINTED_PI, 0.0]]));
    assert!(moved.len() == 1 && moved[0].contains("misses its limits"), "{moved:?}");
    assert_eq!(field(joint_goal(&model, "goal", &exact, &start, 0.0).unwrap_err()), "goal[0].position");
}
