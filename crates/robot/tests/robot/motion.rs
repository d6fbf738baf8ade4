//! The motion bound against brute force: on the test robot with every joint kind, along 200 random
//! joint-space segments, no point within a link's radius moves farther (from its start, at any of
//! 101 configurations along the segment) than the bound; on a one-joint arm the bound is the arc
//! length, so small steps are tight to 1 %.

use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
#[allow(unused_imports)]
use sublevel_robot::motion::{LinkMotion, MotionBounds};
use sublevel_robot::RobotModel;

fn gantry() -> RobotModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gantry.urdf");
    RobotModel::from_urdf_file(&path).unwrap()
}

/// A deterministic uniform sample in [lo, hi] (xorshift, no dependency).
fn uniform(state: &mut u64, lo: Real, hi: Real) -> Real {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    lo + (hi - lo) * ((*state >> 11) as Real / (1u64 << 53) as Real)
}

#[test]
fn no_point_moves_farther_than_the_bound() {
    let robot = gantry();
    let radius = 0.15;
    let bounds = robot.motion_bounds(&vec![radius; robot.links().len()]).unwrap();
    // Points within the radius of each link's origin: the origin and 14 points on the sphere.
    let mut points = vec![Vector3::zeros()];
    for d in [Vector3::x(), Vector3::y(), Vector3::z(), -Vector3::x(), -Vector3::y(), -Vector3::z()] {
        points.push(d * radius);
    }
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                points.push(Vector3::new(sx, sy, sz).normalize() * radius);
            }
        }
    }
    let limits: Vec<(Real, Real)> = (0..robot.dof())
        .map(|k| robot.variable_joint(k).limits.unwrap_or((-2.0 * std::f64::consts::PI, 2.0 * std::f64::consts::PI)))
        .collect();
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut tightest: Real = 0.0;
    for _ in 0..200 {
        let q0: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        let q1: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        let dq: Vec<Real> = q0.iter().zip(&q1).map(|(a, b)| b - a).collect();
        let start = robot.link_poses(&q0, &Isometry3::identity()).unwrap();
        for s in 1..=100 {
            let t = s as Real / 100.0;
            let q: Vec<Real> = q0.iter().zip(&dq).map(|(a, d)| a + t * d).collect();
            let now = robot.link_poses(&q, &Isometry3::identity()).unwrap();
            for l in 0..robot.links().len() {
                let bound = bounds.displacement(l, &dq);
                for p in &points {
                    let moved = (now[l] * Point3::from(*p) - start[l] * Point3::from(*p)).norm();
                    assert!(moved <= bound + 1e-12, "link {} moved {moved} > bound {bound}", robot.links()[l].name);
                    if bound > 0.0 {
                        tightest = tightest.max(moved / bound);
                    }
                }
            }
        }
    }
    println!("largest displacement / bound: {tightest:.3}");
    // The root never moves; the mimic follower's coefficient on `elbow` is |−0.5| times its reach.
    assert!(bounds.coefficients(robot.link_index("base").unwrap()).iter().all(|&c| c == 0.0));
    let follower = bounds.coefficients(robot.link_index("follower").unwrap());
    assert!((follower[3] - 0.5 * radius).abs() < 1e-15, "{follower:?}");
}

/// The bound at a configuration ([`sublevel_robot::MotionBounds::at`]) against brute force: from a
/// random point q(t) of 200 random segments, no point within a link's radius moves farther in a
/// step of s (at 20 steps up to the segment's end) than `min(s·D, s·A + s²·B/2, s·V + s²·G/2)`, and no two points
/// of two links come closer by more than their relative bound ([`MotionBounds::relative`]); returns the
/// median ratio of that bound to the configuration-free `s·D` at s = 0.05.
fn local_bound_holds(robot: &RobotModel, radius: Real, seed: u64) -> Real {
    let bounds = robot.motion_bounds(&vec![radius; robot.links().len()]).unwrap();
    let mut points = vec![Vector3::zeros()];
    for d in [Vector3::x(), Vector3::y(), Vector3::z(), -Vector3::x(), -Vector3::y(), -Vector3::z()] {
        points.push(d * radius);
    }
    let limits: Vec<(Real, Real)> = (0..robot.dof())
        .map(|k| robot.variable_joint(k).limits.unwrap_or((-2.0 * std::f64::consts::PI, 2.0 * std::f64::consts::PI)))
        .collect();
    let mut state = seed;
    let mut gains = Vec::new();
    for _ in 0..200 {
        let q0: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        let q1: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        let dq: Vec<Real> = q0.iter().zip(&q1).map(|(a, b)| b - a).collect();
        let t = uniform(&mut state, 0.0, 0.9);
        let at = |t: Real| -> Vec<Real> { q0.iter().zip(&dq).map(|(a, d)| a + t * d).collect() };
        let start = robot.link_poses(&at(t), &Isometry3::identity()).unwrap();
        let motion: Vec<_> = (0..robot.links().len()).map(|l| bounds.at(robot, l, &start, &dq)).collect();
        for m in &motion {
            if m.full > 0.0 {
                let s = 0.05;
                gains.push(m.displacement(s) / (s * m.full));
            }
        }
        let links = robot.links().len();
        let pairs: Vec<_> = (0..links)
            .flat_map(|a| (a + 1..links).map(move |b| (a, b)))
            .map(|(a, b)| ((a, b), bounds.relative(robot, (a, b), bounds.below_common(a, b), &start, &dq)))
            .collect();
        for k in 1..=20 {
            let s = (1.0 - t) * k as Real / 20.0;
            let now = robot.link_poses(&at(t + s), &Isometry3::identity()).unwrap();
            // Two links close by no more than their relative bound: every point pair's distance.
            for &((a, b), m) in &pairs {
                let bound = m.displacement(s);
                for p in &points {
                    for r in &points {
                        let gap =
                            |poses: &[Isometry3]| (poses[a] * Point3::from(*p) - poses[b] * Point3::from(*r)).norm();
                        let closed = gap(&start) - gap(&now);
                        assert!(closed <= bound + 1e-12, "links {a}, {b} closed {closed} > bound {bound}");
                    }
                }
            }
            for (l, m) in motion.iter().enumerate() {
                let bound = m.displacement(s);
                for p in &points {
                    let moved = (now[l] * Point3::from(*p) - start[l] * Point3::from(*p)).norm();
                    assert!(
                        moved <= bound + 1e-12,
                        "link {} moved {moved} > bound {bound} in {s}",
                        robot.links()[l].name
                    );
                }
            }
        }
    }
    gains.sort_by(|a, b| a.total_cmp(b));
    gains[gains.len() / 2]
}

/// The bound of a ball on each link ([`MotionBounds::at_ball`], [`MotionBounds::relative_balls`])
/// against brute force, as [`local_bound_holds`]: a ball of radius `radius / 2` whose center lies
/// within `radius / 2` of the link's origin (so within the link's radius), its center, 14 points
/// on its surface and 4 inside; returns the median ratio of the ball's bound to the link's by its
/// lever arms alone (`min(s·D, s·A + s²·B/2)` of [`MotionBounds::at`]) at s = 0.05.
fn ball_bound_holds(robot: &RobotModel, radius: Real, seed: u64) -> Real {
    let bounds = robot.motion_bounds(&vec![radius; robot.links().len()]).unwrap();
    let limits: Vec<(Real, Real)> = (0..robot.dof())
        .map(|k| robot.variable_joint(k).limits.unwrap_or((-2.0 * std::f64::consts::PI, 2.0 * std::f64::consts::PI)))
        .collect();
    let links = robot.links().len();
    let mut state = seed;
    let unit = |state: &mut u64| {
        let v = Vector3::new(uniform(state, -1.0, 1.0), uniform(state, -1.0, 1.0), uniform(state, -1.0, 1.0));
        v / v.norm().max(1e-9)
    };
    let r = radius / 2.0;
    let mut ratios = Vec::new();
    for _ in 0..100 {
        // Each link's ball (link frame) and points in it.
        let balls: Vec<(Vector3, Vec<Vector3>)> = (0..links)
            .map(|_| {
                let center = unit(&mut state) * uniform(&mut state, 0.0, r);
                let mut points = vec![center];
                for d in [Vector3::x(), Vector3::y(), Vector3::z(), -Vector3::x(), -Vector3::y(), -Vector3::z()] {
                    points.push(center + d * r);
                }
                for _ in 0..8 {
                    points.push(center + unit(&mut state) * r);
                }
                for _ in 0..4 {
                    points.push(center + unit(&mut state) * uniform(&mut state, 0.0, r));
                }
                (center, points)
            })
            .collect();
        let q0: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        let q1: Vec<Real> = limits.iter().map(|&(lo, hi)| uniform(&mut state, lo, hi)).collect();
        let dq: Vec<Real> = q0.iter().zip(&q1).map(|(a, b)| b - a).collect();
        let t = uniform(&mut state, 0.0, 0.9);
        let at = |t: Real| -> Vec<Real> { q0.iter().zip(&dq).map(|(a, d)| a + t * d).collect() };
        let start = robot.link_poses(&at(t), &Isometry3::identity()).unwrap();
        let centers: Vec<Vector3> = (0..links).map(|l| (start[l] * Point3::from(balls[l].0)).coords).collect();
        let motion: Vec<_> = (0..links).map(|l| bounds.at_ball(robot, l, &start, &dq, (&centers[l], r))).collect();
        for (l, m) in motion.iter().enumerate() {
            if m.full > 0.0 {
                // Against the link's bound by its lever arms alone (no speed measured).
                let link = LinkMotion { speed: Real::INFINITY, ..bounds.at(robot, l, &start, &dq) };
                ratios.push(m.displacement(0.05) / link.displacement(0.05));
            }
        }
        let pairs: Vec<_> = (0..links)
            .flat_map(|a| (a + 1..links).map(move |b| (a, b)))
            .map(|(a, b)| {
                let balls = ((&centers[a], r), (&centers[b], r));
                ((a, b), bounds.relative_balls(robot, (a, b), bounds.below_common(a, b), &start, &dq, balls))
            })
            .collect();
        for k in 1..=20 {
            let s = (1.0 - t) * k as Real / 20.0;
            let now = robot.link_poses(&at(t + s), &Isometry3::identity()).unwrap();
            for &((a, b), m) in &pairs {
                let bound = m.displacement(s);
                for p in balls[a].1.iter().step_by(2) {
                    for q in balls[b].1.iter().step_by(2) {
                        let gap =
                            |poses: &[Isometry3]| (poses[a] * Point3::from(*p) - poses[b] * Point3::from(*q)).norm();
                        let closed = gap(&start) - gap(&now);
                        assert!(closed <= bound + 1e-12, "balls of links {a}, {b} closed {closed} > bound {bound}");
                    }
                }
            }
            for (l, m) in motion.iter().enumerate() {
                let bound = m.displacement(s);
                for p in &balls[l].1 {
                    let moved = (now[l] * Point3::from(*p) - start[l] * Point3::from(*p)).norm();
                    assert!(
                        moved <= bound + 1e-12,
                        "the ball of link {} moved {moved} > bound {bound} in {s}",
                        robot.links()[l].name
                    );
                }
            }
        }
    }
    ratios.sort_by(|a, b| a.total_cmp(b));
    ratios[ratios.len() / 2]
}

#[test]
fn the_bound_of_a_ball_on_a_link_holds_and_is_tighter_than_the_links() {
    let median = ball_bound_holds(&gantry(), 0.15, 0x5851_f42d_4c95_7f2d);
    println!("gantry: median ball bound / link lever-arm bound at s = 0.05: {median:.3}");
    assert!(median <= 1.0);
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.urdf");
    let panda = RobotModel::from_urdf_file(&urdf).unwrap();
    let median = ball_bound_holds(&panda, 0.12, 0x1405_7b7e_f767_814f);
    println!("panda: median ball bound / link lever-arm bound at s = 0.05: {median:.3}");
    assert!(median < 0.8, "{median}");
}

#[test]
fn the_bound_at_a_configuration_holds_and_is_tighter() {
    let median = local_bound_holds(&gantry(), 0.15, 0x2545_f491_4f6c_dd1d);
    println!("gantry: median bound at a configuration / configuration-free bound at s = 0.05: {median:.3}");
    assert!(median < 1.0);
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.urdf");
    let panda = RobotModel::from_urdf_file(&urdf).unwrap();
    let median = local_bound_holds(&panda, 0.12, 0x9e37_79b9_7f4a_7c15);
    println!("panda: median bound at a configuration / configuration-free bound at s = 0.05: {median:.3}");
    assert!(median < 0.8, "{median}");
}

#[test]
fn a_one_joint_arm_is_bounded_by_its_arc_length() {
    let urdf = r#"<robot name="arm"><link name="a"/><link name="b"/>
        <joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint></robot>"#;
    let robot = RobotModel::from_urdf_str(urdf).unwrap();
    let r = 0.8;
    let bounds = robot.motion_bounds(&[0.0, r]).unwrap();
    assert_eq!(bounds.coefficients(1), &[r]);
    // A point at distance r from the axis turning by Δ moves the chord 2r·sin(Δ/2) ≤ r·Δ.
    for delta in [1e-3, 0.01, 0.1] {
        let chord = 2.0 * r * (delta / 2.0_f64).sin();
        let bound = bounds.displacement(1, &[delta]);
        assert!(chord <= bound && bound <= 1.01 * chord, "Δ {delta}: chord {chord}, bound {bound}");
    }
    assert!(robot.motion_bounds(&[0.0]).is_err());
    assert!(robot.motion_bounds(&[0.0, -1.0]).is_err());
}
