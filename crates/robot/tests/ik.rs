//! Inverse kinematics and the frame Jacobian against independent references: central differences
//! of forward kinematics (Jacobian, to 1e-6), the closed-form IK of a planar two-link arm (law of
//! cosines, to 1e-6 m), and Panda round trips checked by forward kinematics.

use nalgebra::Translation3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Point3, Real, UnitQuaternion, Vector3};
use sublevel_robot::ik::random_configuration;
use sublevel_robot::{solve_ik, Error, IkSettings, IkSolver, PoseGoal, RobotModel};

fn panda() -> RobotModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.urdf");
    RobotModel::from_urdf_file(&path).unwrap()
}

fn gantry() -> RobotModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gantry.urdf");
    RobotModel::from_urdf_file(&path).unwrap()
}

/// A base pose off the identity, so that world and root frames differ.
fn base() -> Isometry3 {
    Isometry3::from_parts(Translation3::new(0.3, -0.2, 0.1), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7))
}

/// Largest difference between `frame_jacobian` and central differences (step 1e-6) of forward
/// kinematics, over every link of `model`, at a point fixed on the link off its origin.
fn jacobian_vs_differences(model: &RobotModel, configs: usize, seed: u64) -> Real {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let base = base();
    let h = 1e-6;
    let local = Point3::new(0.05, -0.03, 0.08);
    let mut worst: Real = 0.0;
    let mut jacobian = nalgebra::Matrix6xX::zeros(0);
    for _ in 0..configs {
        let q = random_configuration(model, &mut rng);
        let poses = model.link_poses(&q, &base).unwrap();
        for link in 0..model.links().len() {
            let x = poses[link] * local;
            model.frame_jacobian(&poses, link, &x, &mut jacobian);
            let mut point = Vec::new();
            model.point_jacobian(&poses, link, &x, &mut point);
            for k in 0..model.dof() {
                let (mut plus, mut minus) = (q.clone(), q.clone());
                plus[k] += h;
                minus[k] -= h;
                let (tp, tm) =
                    (model.link_poses(&plus, &base).unwrap()[link], model.link_poses(&minus, &base).unwrap()[link]);
                let linear = ((tp * local) - (tm * local)) / (2.0 * h);
                let angular = (tp.rotation * tm.rotation.inverse()).scaled_axis() / (2.0 * h);
                let column = jacobian.column(k);
                for i in 0..3 {
                    worst = worst.max((column[i] - linear[i]).abs()).max((column[3 + i] - angular[i]).abs());
                    assert_eq!(column[i], point[k][i], "linear rows are point_jacobian's");
                }
            }
        }
    }
    worst
}

#[test]
fn frame_jacobian_matches_central_differences_on_the_panda() {
    let worst = jacobian_vs_differences(&panda(), 20, 1);
    eprintln!("panda: worst Jacobian difference {worst:e}");
    assert!(worst < 1e-6, "worst difference {worst:e}");
}

#[test]
fn frame_jacobian_matches_central_differences_with_every_joint_kind() {
    // Prismatic rail, continuous spindle, unaligned revolute axes and a mimic joint (× −0.5).
    let worst = jacobian_vs_differences(&gantry(), 20, 2);
    eprintln!("gantry: worst Jacobian difference {worst:e}");
    assert!(worst < 1e-6, "worst difference {worst:e}");
}

const L1: Real = 0.7;
const L2: Real = 0.4;

/// A planar arm: two revolute joints about z (the second continuous), links of lengths L1 and L2,
/// and a tool frame at the end of the second.
fn planar() -> RobotModel {
    let urdf = format!(
        r#"<robot name="planar">
  <link name="base"/><link name="upper"/><link name="lower"/><link name="tip"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-3.14159" upper="3.14159" effort="1" velocity="1"/>
  </joint>
  <joint name="elbow" type="continuous">
    <parent link="upper"/><child link="lower"/><origin xyz="{L1} 0 0"/><axis xyz="0 0 1"/>
  </joint>
  <joint name="tool" type="fixed">
    <parent link="lower"/><child link="tip"/><origin xyz="{L2} 0 0"/>
  </joint>
</robot>"#
    );
    RobotModel::from_urdf_str(&urdf).unwrap()
}

/// The two closed-form solutions (elbow down and up) reaching (x, y) in the arm's plane.
fn planar_closed_form(x: Real, y: Real) -> [[Real; 2]; 2] {
    let c2 = ((x * x + y * y - L1 * L1 - L2 * L2) / (2.0 * L1 * L2)).clamp(-1.0, 1.0);
    let q2 = c2.acos();
    [q2, -q2].map(|q2| [y.atan2(x) - (L2 * q2.sin()).atan2(L1 + L2 * q2.cos()), q2])
}

/// The planar arm's tip position, independently of the crate's forward kinematics.
fn planar_fk(q: &[Real]) -> (Real, Real) {
    (L1 * q[0].cos() + L2 * (q[0] + q[1]).cos(), L1 * q[0].sin() + L2 * (q[0] + q[1]).sin())
}

/// Difference of two angles modulo 2π, in [0, π].
fn angle_difference(a: Real, b: Real) -> Real {
    let d = (a - b).rem_euclid(2.0 * PI);
    d.min(2.0 * PI - d)
}

#[test]
fn planar_arm_matches_the_law_of_cosines() {
    let model = planar();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let settings = IkSettings { max_solutions: 2, ..IkSettings::default() };
    for _ in 0..50 {
        // Targets strictly inside the annulus |L1 − L2| < r < L1 + L2, at any bearing.
        let r = rng.random_range((L1 - L2) + 0.02..(L1 + L2) - 0.02);
        let bearing: Real = rng.random_range(-PI..PI);
        let (x, y) = (r * bearing.cos(), r * bearing.sin());
        let goal = PoseGoal {
            link: "tip".into(),
            pose: Isometry3::translation(x, y, 0.0),
            position_tolerance: 1e-6,
            orientation_tolerance: PI,
        };
        let solutions =
            solve_ik(&model, &Isometry3::identity(), &goal, &[vec![0.1, 0.1]], &settings, &mut rng).unwrap();
        assert!(!solutions.is_empty(), "no solution for ({x}, {y})");
        let exact = planar_closed_form(x, y);
        for s in &solutions {
            let (fx, fy) = planar_fk(&s.q);
            assert!(((fx - x).powi(2) + (fy - y).powi(2)).sqrt() <= 1e-6, "tip at ({fx}, {fy}), target ({x}, {y})");
            // One of the two closed-form branches, to the accuracy 1e-6 m allows at these lever arms.
            let nearest = exact
                .iter()
                .map(|e| angle_difference(e[0], s.q[0]).max(angle_difference(e[1], s.q[1])))
                .fold(Real::INFINITY, Real::min);
            assert!(nearest < 1e-4, "q {:?} is {nearest} rad from both closed forms {exact:?}", s.q);
            assert!(s.q[1] > -PI && s.q[1] <= PI, "continuous elbow wrapped: {}", s.q[1]);
        }
    }
}

#[test]
fn planar_arm_full_pose_reaches_the_closed_form_heading() {
    let model = planar();
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    for _ in 0..20 {
        let q = random_configuration(&model, &mut rng);
        let (x, y) = planar_fk(&q);
        let heading = q[0] + q[1];
        let goal = PoseGoal {
            link: "tip".into(),
            pose: Isometry3::new(Vector3::new(x, y, 0.0), Vector3::z() * heading),
            position_tolerance: 1e-6,
            orientation_tolerance: 1e-6,
        };
        let solutions =
            solve_ik(&model, &Isometry3::identity(), &goal, &[vec![0.0, 0.0]], &IkSettings::default(), &mut rng)
                .unwrap();
        let s = solutions.first().unwrap_or_else(|| panic!("no solution for q* = {q:?}"));
        // A planar pose (x, y, heading) has exactly one solution: q*.
        assert!(angle_difference(s.q[0], q[0]) < 1e-5 && angle_difference(s.q[1], q[1]) < 1e-5, "{:?} vs {q:?}", s.q);
    }
}

#[test]
fn planar_arm_beyond_reach_has_no_solution() {
    let model = planar();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for target in [Vector3::new(L1 + L2 + 0.01, 0.0, 0.0), Vector3::new(0.0, -1.5, 0.0), Vector3::new(0.3, 0.0, 0.2)] {
        let goal = PoseGoal {
            link: "tip".into(),
            pose: Isometry3::translation(target.x, target.y, target.z),
            position_tolerance: 1e-6,
            orientation_tolerance: PI,
        };
        let settings = IkSettings { max_solutions: 10, ..IkSettings::default() };
        let mut solver = IkSolver::new(&model, &Isometry3::identity(), &goal, &[vec![0.0, 0.0]], &settings).unwrap();
        assert!(solver.next_solution(&mut rng).is_none(), "a solution for {target:?}");
        assert_eq!(solver.attempts(), 1 + settings.random_seeds, "every seed and restart tried");
        // With a deadline that has passed, no descent starts: a planner's deadline bounds the
        // restarts of an unreachable pose.
        let mut late = IkSolver::new(&model, &Isometry3::identity(), &goal, &[vec![0.0, 0.0]], &settings).unwrap();
        late.set_deadline(std::time::Instant::now());
        assert!(late.next_solution(&mut rng).is_none());
        assert_eq!(late.attempts(), 0, "no descent after the deadline");
    }
}

#[test]
fn panda_round_trips() {
    let model = panda();
    let base = base();
    let hand = model.link_index("panda_hand").unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    // MoveIt's `ready` pose: unrelated to the targets.
    let seed = vec![0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
    let settings = IkSettings::default();
    let (mut solved, mut iterations, mut attempts) = (0, 0, 0);
    for _ in 0..200 {
        let target = random_configuration(&model, &mut rng);
        let goal = PoseGoal::new("panda_hand", model.link_poses(&target, &base).unwrap()[hand]);
        let mut solver = IkSolver::new(&model, &base, &goal, std::slice::from_ref(&seed), &settings).unwrap();
        let Some(s) = solver.next_solution(&mut rng) else { continue };
        solved += 1;
        iterations += s.iterations;
        attempts += solver.attempts();
        model.check_limits("q", &s.q).unwrap();
        let (dp, dr) = goal.errors(&model.link_poses(&s.q, &base).unwrap()[hand]);
        assert!(dp <= 1e-3 && dr <= 1e-2, "reached within {dp} m and {dr} rad");
        assert!((dp - s.position_error).abs() < 1e-15 && (dr - s.orientation_error).abs() < 1e-15);
    }
    eprintln!("panda round trips: {solved}/200, {attempts} descents, {iterations} iterations in successful descents");
    assert!(solved >= 198, "{solved}/200 solved");
}

#[test]
fn panda_solutions_are_distinct() {
    let model = panda();
    let hand = model.link_index("panda_hand").unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let target = random_configuration(&model, &mut rng);
    let goal = PoseGoal::new("panda_hand", model.link_poses(&target, &Isometry3::identity()).unwrap()[hand]);
    let settings = IkSettings { max_solutions: 5, ..IkSettings::default() };
    let solutions = solve_ik(&model, &Isometry3::identity(), &goal, &[], &settings, &mut rng).unwrap();
    assert!(solutions.len() >= 2, "a redundant arm has many solutions; got {}", solutions.len());
    for (i, a) in solutions.iter().enumerate() {
        for b in &solutions[..i] {
            let gap = a.q.iter().zip(&b.q).map(|(x, y)| (x - y).abs()).fold(0.0, Real::max);
            assert!(gap >= settings.distinct, "solutions {gap} apart");
        }
    }
}

#[test]
fn gantry_round_trips_with_prismatic_continuous_and_mimic_joints() {
    let model = gantry();
    let tool = model.link_index("tool").unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let mut solved = 0;
    for _ in 0..50 {
        let target = random_configuration(&model, &mut rng);
        let goal = PoseGoal::new("tool", model.link_poses(&target, &base()).unwrap()[tool]);
        let solutions = solve_ik(&model, &base(), &goal, &[vec![0.0; 4]], &IkSettings::default(), &mut rng).unwrap();
        if let Some(s) = solutions.first() {
            solved += 1;
            model.check_limits("q", &s.q).unwrap();
            let (dp, dr) = goal.errors(&model.link_poses(&s.q, &base()).unwrap()[tool]);
            assert!(dp <= 1e-3 && dr <= 1e-2);
        }
    }
    assert!(solved >= 49, "{solved}/50 solved");
}

fn field(e: Error) -> String {
    match e {
        Error::InvalidArgument { field, .. } => field,
        other => panic!("not an invalid argument: {other}"),
    }
}

#[test]
fn bad_input_names_the_field() {
    let model = planar();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let good = PoseGoal::new("tip", Isometry3::translation(0.5, 0.0, 0.0));
    let s = IkSettings::default();
    let id = Isometry3::identity();
    let mut solve = |goal: &PoseGoal, seeds: &[Vec<Real>], settings: &IkSettings| {
        solve_ik(&model, &id, goal, seeds, settings, &mut rng).map(|_| ()).map_err(field)
    };
    assert_eq!(solve(&PoseGoal { link: "hand".into(), ..good.clone() }, &[], &s), Err("goal.link".into()));
    let nan = PoseGoal { position_tolerance: Real::NAN, ..good.clone() };
    assert_eq!(solve(&nan, &[], &s), Err("goal.position_tolerance".into()));
    let negative = PoseGoal { orientation_tolerance: -0.1, ..good.clone() };
    assert_eq!(solve(&negative, &[], &s), Err("goal.orientation_tolerance".into()));
    let nan = PoseGoal { orientation_tolerance: Real::NAN, ..good.clone() };
    assert_eq!(solve(&nan, &[], &s), Err("goal.orientation_tolerance".into()));
    let far = PoseGoal { pose: Isometry3::translation(Real::INFINITY, 0.0, 0.0), ..good.clone() };
    assert_eq!(solve(&far, &[], &s), Err("goal.pose".into()));
    assert_eq!(solve(&good, &[vec![0.0, 0.0], vec![0.0]], &s), Err("seeds[1]".into()));
    assert_eq!(solve(&good, &[vec![0.0, Real::NAN]], &s), Err("seeds[0][1]".into()));
    assert_eq!(solve(&good, &[], &IkSettings { max_step: 0.0, ..s.clone() }), Err("settings.max_step".into()));
    assert_eq!(solve(&good, &[], &IkSettings { damping: -1.0, ..s.clone() }), Err("settings.damping".into()));
    // A seed outside the limits is clamped into them, not refused.
    assert_eq!(solve(&good, &[vec![10.0, 10.0]], &s), Ok(()));
    // Position only with an infinite orientation tolerance is valid.
    assert_eq!(solve(&PoseGoal { orientation_tolerance: Real::INFINITY, ..good }, &[], &s), Ok(()));
}
