//! The bodies model of `sublevel-lab robot-clouds --bodies`: each scene's cloud as the
//! sos-convex bodies of its clusters ([`CloudBodies`]), timed on the first frame and on a second
//! frame of the same scene with new depth noise (bodies reused while they still contain every
//! point's ball grown by `--body-slack`), then the first `--body-configs` configurations checked
//! against them: every robot geometry's sos body (a link mesh's root body, a primitive itself)
//! against every cluster body whose box its ball reaches, by the Newton / active-set distance
//! (`sublevel_query::shape::shape_distance`). The verdicts are compared with the points model's
//! and the primitives'.

use crate::robot_clouds::RobotCloudsArgs;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::Result;
use sublevel_fit::sdp::ConvexityCone;
use sublevel_query::shape::{shape_distance, ShapeRef};
use sublevel_robot::cloud::bodies::{CloudBodies, CloudBodySettings};
use sublevel_robot::{CheckOptions, FittedRobot, LinkShape, PointCloud, RobotChecker, WorldObject};

/// The bodies model's figures for a set of problems.
#[derive(Clone, Default)]
pub(crate) struct BodyTally {
    clusters: Vec<Real>,
    first_seconds: Vec<Real>,
    /// The first frame's bodies' volume (m³, Monte Carlo) and their fits' Clarabel seconds.
    volume: Real,
    solve_seconds: Vec<Real>,
    next_seconds: Vec<Real>,
    /// The second frame's clustering, reuse checks, and rescales and fits (seconds).
    next_parts: [Vec<Real>; 3],
    reused: usize,
    rescaled: usize,
    refitted: usize,
    outliers: usize,
    points: usize,
    configs: usize,
    seconds: Real,
    points_seconds: Real,
    false_vs_points: usize,
    misses_vs_points: usize,
    false_vs_truth: usize,
    misses_vs_truth: usize,
}

/// One problem: `frames` are the cloud's points and a second frame's, `configs` the problem's
/// configurations.
pub(crate) fn bodies(
    robot: &FittedRobot,
    args: &RobotCloudsArgs,
    frames: (&[[Real; 3]], &[[Real; 3]]),
    truth: &[WorldObject],
    allowed: &dyn Fn(&str, &str) -> Option<bool>,
    configs: &[Vec<Real>],
    t: &mut BodyTally,
) -> Result<()> {
    let mut settings = CloudBodySettings {
        slack: args.body_slack,
        rescale_limit: args.body_rescale_limit,
        threads: args.body_threads,
        ..CloudBodySettings::default()
    };
    let cone: ConvexityCone = args.body_cone.parse()?;
    if cone != ConvexityCone::Psd {
        settings.fit = settings.fit.with_convexity_cone(cone).with_alternate_normalization(None);
    }
    let mut model = CloudBodies::new();
    let first = model.update(frames.0, args.radius, &settings)?;
    t.first_seconds.push(first.total_seconds);
    t.volume += model.bodies().map(|b| b.report.volume).sum::<Real>();
    t.solve_seconds.extend(model.bodies().map(|b| b.report.solve_seconds));
    t.clusters.push(first.clusters as Real);
    t.outliers += first.outliers;
    t.points += first.points;
    let next = model.update(frames.1, args.radius, &settings)?;
    t.next_seconds.push(next.total_seconds);
    for (v, s) in t.next_parts.iter_mut().zip([next.cluster_seconds, next.check_seconds, next.fit_seconds]) {
        v.push(s);
    }
    t.reused += next.reused;
    t.rescaled += next.rescaled;
    t.refitted += next.refitted;
    // The configurations against the bodies of the second frame, its points and the primitives.
    let cloud = std::sync::Arc::new(PointCloud::new(frames.1.to_vec(), args.radius)?);
    let mut on_points =
        RobotChecker::new(robot, vec![WorldObject::points("camera", cloud, Isometry3::identity())], allowed)?;
    let mut on_truth = RobotChecker::new(robot, truth.to_vec(), allowed)?;
    let options = CheckOptions { padding: 0.0, distance: false, self_collision: false, gradient: false };
    let identity = Isometry3::identity();
    let boxes: Vec<(Vector3, Vector3)> =
        model.clusters().iter().map(|c| (c.bounds.0, c.bounds.1.add_scalar(args.radius * 3f64.sqrt()))).collect();
    let mut poses = Vec::new();
    for q in configs.iter().take(args.body_configs) {
        let clock = std::time::Instant::now();
        robot.model.forward_kinematics(q, &identity, &mut poses)?;
        let mut hit = false;
        'geometries: for g in &robot.geometries {
            let pose = poses[g.link] * g.origin;
            let c = pose.transform_point(&g.sphere.0.into()).coords;
            let shape = match &g.shape {
                LinkShape::Mesh { body, .. } => ShapeRef::Body(body),
                LinkShape::Primitive(p) => ShapeRef::Primitive(p),
            };
            for (cluster, (bc, h)) in model.clusters().iter().zip(&boxes) {
                let out = ((c - bc).abs() - h).map(|v| v.max(0.0)).norm();
                if out > g.sphere.1 {
                    continue;
                }
                let d = shape_distance(shape, &pose, ShapeRef::Body(&cluster.body), &identity, None)?;
                // Not converged counts as contact: the model stays conservative.
                if d.overlapping || !d.status.converged() || d.distance <= 0.0 {
                    hit = true;
                    break 'geometries;
                }
            }
        }
        t.seconds += clock.elapsed().as_secs_f64();
        let clock = std::time::Instant::now();
        let points = on_points.check(q, &identity, &options)?.world;
        t.points_seconds += clock.elapsed().as_secs_f64();
        let truth = on_truth.check(q, &identity, &options)?.world;
        t.configs += 1;
        t.false_vs_points += usize::from(hit && !points);
        t.misses_vs_points += usize::from(!hit && points);
        t.false_vs_truth += usize::from(hit && !truth);
        t.misses_vs_truth += usize::from(!hit && truth);
    }
    Ok(())
}

pub(crate) fn merge(all: &mut BodyTally, t: BodyTally) {
    all.clusters.extend(t.clusters);
    all.first_seconds.extend(t.first_seconds);
    all.volume += t.volume;
    all.solve_seconds.extend(t.solve_seconds);
    all.next_seconds.extend(t.next_seconds);
    for (a, b) in all.next_parts.iter_mut().zip(t.next_parts) {
        a.extend(b);
    }
    all.reused += t.reused;
    all.rescaled += t.rescaled;
    all.refitted += t.refitted;
    all.outliers += t.outliers;
    all.points += t.points;
    all.configs += t.configs;
    all.seconds += t.seconds;
    all.points_seconds += t.points_seconds;
    all.false_vs_points += t.false_vs_points;
    all.misses_vs_points += t.misses_vs_points;
    all.false_vs_truth += t.false_vs_truth;
    all.misses_vs_truth += t.misses_vs_truth;
}

/// Prints the bodies' table, one row per scenario.
pub(crate) fn table(rows: &[(String, BodyTally)]) {
    println!();
    println!(
        "| scenario | median clusters | outlier points | first frame (ms, median) | Clarabel per fit (ms, median) | first frame's bodies (liters) | second frame (ms, median) | of it: cluster / check / rescale + fit (medians) | reused | \
         rescaled | refitted | configurations | µs/config, bodies | µs/config, points (single) | collide where points do not | \
         free where points collide | false collisions vs primitives | misses vs primitives |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, t) in rows {
        let per = |s: Real| 1e6 * s / t.configs.max(1) as Real;
        println!(
            "| {name} | {:.0} | {} of {} | {:.0} | {:.1} | {:.1} | {:.0} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {} | {} | {} | {} |",
            crate::robot_edges::median(&t.clusters),
            t.outliers,
            t.points,
            1e3 * crate::robot_edges::median(&t.first_seconds),
            1e3 * crate::robot_edges::median(&t.solve_seconds),
            1e3 * t.volume,
            1e3 * crate::robot_edges::median(&t.next_seconds),
            t.next_parts.iter().map(|v| format!("{:.0}", 1e3 * crate::robot_edges::median(v))).collect::<Vec<_>>().join(" / "),
            t.reused,
            t.rescaled,
            t.refitted,
            t.configs,
            per(t.seconds),
            per(t.points_seconds),
            t.false_vs_points,
            t.misses_vs_points,
            t.false_vs_truth,
            t.misses_vs_truth,
        );
    }
}
