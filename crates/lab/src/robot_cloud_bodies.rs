//! The bodies model of `sublevel-lab robot-clouds --bodies`: each scene's cloud as the
//! sos-convex bodies of its clusters ([`CloudBodies`]), timed on the first frame and on a second
//! frame of the same scene with new depth noise (bodies reused while they still contain every
//! point's ball grown by `--body-slack`), then the first `--body-configs` configurations checked
//! against them: every robot geometry's sos body (a link mesh's root body, a primitive itself)
//! against every cluster body whose box its ball reaches, by the Newton / active-set distance
//! (`sublevel_query::shape::shape_distance`), and by the service's check: [`RobotChecker`] with
//! every cluster body a world object (`WorldShape::Body`: the link meshes' triangles against the
//! convex body). The verdicts are compared with the points model's and the primitives'. With
//! `--plan`, the problem is planned against the bodies too: solved, median plan time, its ratio to
//! the primitives' (planned again beside it), and the paths whose every edge conservative
//! advancement proves free of the true primitives.

use crate::robot_clouds::RobotCloudsArgs;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::Result;
use sublevel_fit::sdp::ConvexityCone;
use sublevel_plan::{plan, Goal, PlanSettings, PlanStatus, RobotValidity};
use sublevel_query::shape::{shape_distance, ShapeRef};
use sublevel_robot::cloud::bodies::{CloudBodies, CloudBodySettings};
use sublevel_robot::world::WorldBody;
use sublevel_robot::{
    CheckOptions, FittedRobot, LinkShape, MotionChecker, MotionOptions, PointCloud, RobotChecker, WorldObject,
};

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
    /// The service's check (link meshes against the bodies): seconds, and its errors.
    exact_seconds: Real,
    exact_false_vs_points: usize,
    exact_misses_vs_points: usize,
    /// `--plan`: problems solved against the bodies, plan seconds against the bodies and the
    /// primitives (both solved), and bodies' paths free of the primitives.
    solved: usize,
    plan_seconds: Vec<Real>,
    truth_plan_seconds: Vec<Real>,
    paths_free: usize,
}

/// A problem's start and goal configurations.
pub(crate) type Endpoints<'a> = (&'a [Real], &'a [Real]);

/// One problem: `frames` are the cloud's points and a second frame's, `configs` the problem's
/// configurations, `problem` its start and goal when it is planned (`--plan`).
pub(crate) fn bodies(
    robot: &FittedRobot,
    args: &RobotCloudsArgs,
    frames: (&[[Real; 3]], &[[Real; 3]]),
    truth: &[WorldObject],
    allowed: &dyn Fn(&str, &str) -> Option<bool>,
    (configs, problem): (&[Vec<Real>], Option<Endpoints<'_>>),
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
    let objects = model
        .clusters()
        .iter()
        .map(|c| Ok(WorldObject::body("camera", std::sync::Arc::new(WorldBody::new(c.body.clone())?), identity)))
        .collect::<Result<Vec<_>>>()?;
    let mut on_bodies = RobotChecker::new(robot, objects.clone(), allowed)?;
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
        let exact = on_bodies.check(q, &identity, &options)?.world;
        t.exact_seconds += clock.elapsed().as_secs_f64();
        let clock = std::time::Instant::now();
        let points = on_points.check(q, &identity, &options)?.world;
        t.points_seconds += clock.elapsed().as_secs_f64();
        let truth = on_truth.check(q, &identity, &options)?.world;
        t.configs += 1;
        t.false_vs_points += usize::from(hit && !points);
        t.misses_vs_points += usize::from(!hit && points);
        t.false_vs_truth += usize::from(hit && !truth);
        t.misses_vs_truth += usize::from(!hit && truth);
        t.exact_false_vs_points += usize::from(exact && !points);
        t.exact_misses_vs_points += usize::from(!exact && points);
    }
    if let Some((start, goal)) = problem {
        plan_bodies(robot, args, (start, goal), objects, truth, allowed, t)?;
    }
    Ok(())
}

/// Plans the problem against the bodies and against the primitives; a bodies path is checked
/// edge by edge against the primitives by conservative advancement.
fn plan_bodies(
    robot: &FittedRobot,
    args: &RobotCloudsArgs,
    (start, goal): (&[Real], &[Real]),
    bodies: Vec<WorldObject>,
    truth: &[WorldObject],
    allowed: &dyn Fn(&str, &str) -> Option<bool>,
    t: &mut BodyTally,
) -> Result<()> {
    let settings =
        PlanSettings { timeout: std::time::Duration::from_secs_f64(args.timeout), ..PlanSettings::default() };
    let base = Isometry3::identity();
    let asked = Goal::Configurations(vec![goal.to_vec()]);
    let mut seconds = [None, None];
    let mut path = Vec::new();
    for (k, w) in [bodies, truth.to_vec()].into_iter().enumerate() {
        let mut checker = RobotChecker::new(robot, w, allowed)?;
        let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, base, settings.padding);
        let clock = std::time::Instant::now();
        let out = plan(&mut validity, start, &asked, &settings, &std::sync::atomic::AtomicBool::new(false))?;
        if out.status == PlanStatus::Solved {
            seconds[k] = Some(clock.elapsed().as_secs_f64());
            if k == 0 {
                path = out.path;
            }
        } else if k == 0 {
            let status = format!("{:?}", out.status);
            eprintln!("bodies plan: {}", status.chars().take(200).collect::<String>());
        }
    }
    if let [Some(b), Some(p)] = seconds {
        t.plan_seconds.push(b);
        t.truth_plan_seconds.push(p);
    }
    if seconds[0].is_none() {
        return Ok(());
    }
    t.solved += 1;
    let mut on_truth = RobotChecker::new(robot, truth.to_vec(), allowed)?;
    let mut motions = MotionChecker::new(&mut on_truth)?;
    let mut free = true;
    for edge in path.windows(2) {
        free &= motions.check_motion(&edge[0], &edge[1], &base, &MotionOptions::default())?.valid;
    }
    t.paths_free += usize::from(free);
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
    all.exact_seconds += t.exact_seconds;
    all.exact_false_vs_points += t.exact_false_vs_points;
    all.exact_misses_vs_points += t.exact_misses_vs_points;
    all.solved += t.solved;
    all.plan_seconds.extend(t.plan_seconds);
    all.truth_plan_seconds.extend(t.truth_plan_seconds);
    all.paths_free += t.paths_free;
}

/// Prints the bodies' table, one row per scenario.
pub(crate) fn table(rows: &[(String, BodyTally)]) {
    println!();
    println!(
        "| scenario | median clusters | outlier points | first frame (ms, median) | Clarabel per fit (ms, median) | first frame's bodies (liters) | second frame (ms, median) | of it: cluster / check / rescale + fit (medians) | reused | \
         rescaled | refitted | configurations | µs/config, bodies | µs/config, points (single) | collide where points do not | \
         free where points collide | false collisions vs primitives | misses vs primitives | µs/config, service check | \
         service check: collide where points do not | service check: free where points collide | solved, bodies | \
         median plan ms, bodies / primitives | ratio | bodies paths free of the primitives |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, t) in rows {
        let per = |s: Real| 1e6 * s / t.configs.max(1) as Real;
        let plan_ms = 1e3 * crate::robot_edges::median(&t.plan_seconds);
        let truth_ms = 1e3 * crate::robot_edges::median(&t.truth_plan_seconds);
        println!(
            "| {name} | {:.0} | {} of {} | {:.0} | {:.1} | {:.1} | {:.0} | {} | {} | {} | {} | {} | {:.1} | {:.1} | {} | {} | {} | {} | {:.1} | {} | {} | {} | {:.1} / {:.1} | {:.1} | {} |",
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
            per(t.exact_seconds),
            t.exact_false_vs_points,
            t.exact_misses_vs_points,
            t.solved,
            plan_ms,
            truth_ms,
            plan_ms / truth_ms,
            t.paths_free,
        );
    }
}
