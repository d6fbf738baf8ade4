//! `sublevel-lab robot-clouds`: the MotionBenchMaker Panda problems with each scene seen by
//! simulated depth cameras, as CAPT's benchmark renders them (Ramsey et al., RSS 2024): the
//! scene's primitives ray-cast into 640 × 480 depth frames with Gaussian depth noise from
//! `--cameras` views around the workspace, each frame deprojected, voxel-filtered and merged into
//! one cloud obstacle, the points near the robot at the start configuration removed (the self
//! filter a real arm in view needs). Per scenario, one thread:
//!
//! - **update**: the median time from one depth frame to a queryable cloud (deprojection,
//!   filters, k-d tree) and the median points kept per scene;
//! - **exactness**: `--configs` random configurations per problem checked against the cloud by
//!   [`RobotChecker::check_block`], against the brute force over every filtered point ball
//!   ([`reference_gap`]): misses and false collisions (both must be 0);
//! - **model**: the cloud's verdicts against the true primitives' (the scene as a planner given
//!   exact shapes sees it): false collisions (the inflation of noise and voxels) and misses (what
//!   the cameras did not see);
//! - **time per configuration**: block checks against the cloud and against the primitives, the
//!   same configurations (world pairs only);
//! - **planning** (`--plan`): [`sublevel_plan::plan`] against the cloud and against the
//!   primitives: solved within the timeout, median plan times and their ratio, and the solved
//!   paths whose every edge conservative advancement proves free of the true primitives.
//!
//! With `SUBLEVEL_CLOUD_STATS=1` it also prints the exact pairs and stage times of the checks, each
//! cloud plan's stage times, and, where a cloud path meets the primitives, the pair, the place on
//! the edge and the robot's distance to the cloud there (what the cameras did not see).
//!
//! ```text
//! mkdir -p /tmp/mbm && tar xjf data/robots/mbm_panda/problems.tar.bz2 -C /tmp/mbm
//! cargo run --release -p sublevel-lab -- robot-clouds --problems /tmp/mbm --limit 100 --plan
//! ```

use crate::robot_edges::{median, problem_paths, read};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::{Error, Result};
use sublevel_plan::{plan, Goal, PlanSettings, PlanStatus, RobotValidity};
use sublevel_robot::cloud::depth::{deproject, DepthPixels, Intrinsics};
use sublevel_robot::cloud::filter::{self_filter, voxel_grid, CloudFilter, FilterCounts};
use sublevel_robot::cloud::reference_gap;
use sublevel_robot::cloud::render::{look_at, render_depth, DepthNoise};
use sublevel_robot::{CheckOptions, FittedRobot, MotionChecker, MotionOptions, PointCloud, RobotChecker, WorldObject};
use sublevel_scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};

/// Arguments of `sublevel-lab robot-clouds`.
#[derive(clap::Args, Debug)]
pub struct RobotCloudsArgs {
    /// The fitted robot (`sublevel robot fit`).
    #[arg(long, default_value = "data/robots/panda/panda.robot.json")]
    robot: PathBuf,
    /// The problems, as `robot-edges` takes them.
    #[arg(long, default_value = "data/robots/mbm_panda")]
    problems: PathBuf,
    /// Scenarios, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "bookshelf_small,bookshelf_tall,bookshelf_thin,box,cage,table_pick,table_under_pick"
    )]
    scenarios: Vec<String>,
    /// Problems 1 to this of each scenario (missing ones are skipped).
    #[arg(long, default_value_t = 10)]
    limit: usize,
    /// Random configurations checked per problem.
    #[arg(long, default_value_t = 143)]
    configs: usize,
    /// Depth cameras around the workspace (1–6: behind the robot, front, left, right, then low
    /// front-left and front-right).
    #[arg(long, default_value_t = 4)]
    cameras: usize,
    /// Voxel edge of the filter (meters).
    #[arg(long, default_value_t = 0.02)]
    voxel: Real,
    /// Noise radius of the points (meters).
    #[arg(long, default_value_t = 0.02)]
    pub(crate) radius: Real,
    /// Standard deviation of the depth noise (meters).
    #[arg(long, default_value_t = 0.002)]
    noise: Real,
    /// Padding of the self filter at the start configuration (meters).
    #[arg(long, default_value_t = 0.02)]
    self_padding: Real,
    /// Skip the brute force (for profiles of the checks alone; the exactness columns read 0).
    #[arg(long)]
    no_reference: bool,
    /// Plan each problem against the cloud and against the primitives.
    #[arg(long)]
    plan: bool,
    /// Also model each cloud as bodies (clusters fitted by sos-convex bodies): fit times, reuse
    /// on a second frame with new noise, and the first `--body-configs` configurations checked
    /// against them.
    #[arg(long)]
    bodies: bool,
    /// Configurations per problem checked against the bodies.
    #[arg(long, default_value_t = 30)]
    pub(crate) body_configs: usize,
    /// Slack of the bodies' reuse test (meters): a body is kept while it contains every new
    /// point's ball grown by this much.
    #[arg(long, default_value_t = 0.005)]
    pub(crate) body_slack: Real,
    /// Largest growth by rescaling of a body since its last fit (1: never rescale, always refit).
    #[arg(long, default_value_t = 1.25)]
    pub(crate) body_rescale_limit: Real,
    /// Threads fitting a frame's clusters at once (0: the machine's parallelism).
    #[arg(long, default_value_t = 0)]
    pub(crate) body_threads: usize,
    /// Cone of the bodies' sos-convexity Gram matrix: psd, or the sdsos / dsos approximations
    /// sdd and dd (paper §VI), which are solved in the bounding cube alone.
    #[arg(long, default_value = "psd", value_parser = ["psd", "sdd", "dd"])]
    pub(crate) body_cone: String,
    /// Planning timeout (seconds).
    #[arg(long, default_value_t = 1.0)]
    pub(crate) timeout: Real,
    /// Seed of the configurations and the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// The simulated camera: 640 × 480, 60° horizontal field of view.
const CAMERA: Intrinsics = Intrinsics { width: 640, height: 480, fx: 554.0, fy: 554.0, cx: 319.5, cy: 239.5 };

/// The camera poses: behind and above the robot, then in front, left and right of the workspace,
/// then two low in front, left and right (they see the undersides of shelves and tables), all
/// looking at its middle.
fn cameras(n: usize) -> Result<Vec<Isometry3>> {
    let target = Vector3::new(0.5, 0.0, 0.4);
    let up = Vector3::z();
    [
        Vector3::new(-0.6, 0.0, 1.6),
        Vector3::new(2.2, 0.0, 1.4),
        Vector3::new(0.5, 2.0, 1.4),
        Vector3::new(0.5, -2.0, 1.4),
        Vector3::new(2.0, 1.0, 0.1),
        Vector3::new(2.0, -1.0, 0.1),
    ]
    .iter()
    .take(n)
    .map(|eye| look_at(*eye, target, up))
    .collect()
}

/// One scenario's figures.
#[derive(Default)]
pub(crate) struct Tally {
    problems: usize,
    points: Vec<Real>,
    frame_seconds: Vec<Real>,
    configs: usize,
    misses: usize,
    false_collisions: usize,
    model_false: usize,
    model_misses: usize,
    truth_colliding: usize,
    cloud_seconds: Real,
    truth_seconds: Real,
    solved: usize,
    truth_solved: usize,
    plan_seconds: Vec<Real>,
    truth_plan_seconds: Vec<Real>,
    paths_free: usize,
    bodies: crate::robot_cloud_bodies::BodyTally,
}

/// Runs `sublevel-lab robot-clouds`.
///
/// # Errors
/// Bad arguments (named), files that cannot be read or parsed, a check that fails.
pub fn run(args: RobotCloudsArgs) -> Result<()> {
    if !(1..=6).contains(&args.cameras) {
        return Err(Error::invalid("--cameras", format!("must be 1–6, got {}", args.cameras)));
    }
    let robot = FittedRobot::load(&args.robot)?;
    let names: Vec<String> = robot.model.variable_names().iter().map(|s| s.to_string()).collect();
    let base = Isometry3::identity();
    let views = cameras(args.cameras)?;
    let filter = CloudFilter { voxel: args.voxel, max_range: 6.0, ..CloudFilter::default() };
    println!(
        "{} camera(s) 640×480, depth noise σ {} m, voxel {} m, noise radius {} m, self filter {} m at the start; \
         {} configurations per problem; one thread",
        args.cameras, args.noise, args.voxel, args.radius, args.self_padding, args.configs
    );
    println!(
        "| scenario | problems | median points | frame → obstacle (ms) | configurations | misses vs brute force | \
         false vs brute force | colliding (primitives) | cloud false collisions | cloud misses | block µs/config, cloud | \
         block µs/config, primitives | ratio | solved, cloud | solved, primitives | median plan ms, cloud | \
         median plan ms, primitives | ratio | paths free of the primitives |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(args.seed);
    let mut all = Tally::default();
    let mut bodies = Vec::new();
    for scenario in &args.scenarios {
        let mut t = Tally::default();
        for k in 1..=args.limit {
            let (scene_path, request_path) = problem_paths(&args.problems, scenario, k);
            if !scene_path.exists() {
                continue;
            }
            let scene = PlanningScene::from_yaml(&read(&scene_path)?)?;
            let request = MotionPlanRequest::from_yaml(&read(&request_path)?)?;
            let pick = |joints: &[(String, Real)]| -> Vec<Real> {
                names.iter().map(|n| joints.iter().find(|(m, _)| m == n).map_or(0.0, |(_, v)| *v)).collect()
            };
            let (start, goal) = (pick(&request.start), pick(&request.goal));
            let (truth, _) = world_objects(&scene)?;
            let allowed = allowed_override(&scene);
            t.problems += 1;
            // The frames, each timed from depth image to obstacle, then merged.
            let mut merged = Vec::new();
            for (v, camera) in views.iter().enumerate() {
                let noise = DepthNoise { sigma: args.noise, seed: args.seed ^ (k * 8 + v) as u64 };
                let depth = render_depth(&truth, camera, &CAMERA, 6.0, Some(noise))?;
                let clock = Instant::now();
                let mut points = Vec::with_capacity(depth.len());
                deproject(DepthPixels::F32(&depth), &CAMERA, 1.0, &mut points)?;
                let mut counts = FilterCounts::default();
                let kept = filter.apply(&points, camera, &mut counts)?;
                let one = PointCloud::new(kept.clone(), args.radius)?;
                t.frame_seconds.push(clock.elapsed().as_secs_f64());
                drop(one);
                merged.extend(kept);
            }
            let mut merged = voxel_grid(&merged, args.voxel);
            self_filter(&robot, &start, &base, args.radius, args.self_padding, &mut merged)?;
            t.points.push(merged.len() as Real);
            let cloud = Arc::new(PointCloud::new(merged.clone(), args.radius)?);
            let world = vec![WorldObject::points("camera", cloud, Isometry3::identity())];
            let mut on_cloud = RobotChecker::new(&robot, world.clone(), &allowed)?;
            let mut on_truth = RobotChecker::new(&robot, truth.clone(), &allowed)?;
            let configs = check_configurations(&robot, &mut rng, &args, &merged, &mut on_cloud, &mut on_truth, &mut t)?;
            if args.bodies {
                let frames = views
                    .iter()
                    .enumerate()
                    .map(|(v, camera)| {
                        let noise = DepthNoise { sigma: args.noise, seed: args.seed ^ (k * 8 + v) as u64 ^ 0x5eed };
                        let depth = render_depth(&truth, camera, &CAMERA, 6.0, Some(noise))?;
                        let mut points = Vec::new();
                        deproject(DepthPixels::F32(&depth), &CAMERA, 1.0, &mut points)?;
                        filter.apply(&points, camera, &mut FilterCounts::default())
                    })
                    .collect::<Result<Vec<_>>>()?;
                let mut second = voxel_grid(&frames.concat(), args.voxel);
                self_filter(&robot, &start, &base, args.radius, args.self_padding, &mut second)?;
                crate::robot_cloud_bodies::bodies(
                    &robot,
                    &args,
                    (&merged, &second),
                    &truth,
                    &allowed,
                    (&configs, args.plan.then_some((start.as_slice(), goal.as_slice()))),
                    &mut t.bodies,
                )?;
            }
            if args.plan {
                plan_both(&robot, &args, (&start, &goal), world, &truth, &allowed, &mut t)?;
            }
        }
        row(scenario, &t);
        bodies.push((scenario.clone(), t.bodies.clone()));
        merge(&mut all, t);
    }
    if all.problems == 0 {
        return Err(Error::invalid(
            "--problems",
            format!(
                "no problem found in {}: give the folder holding scenes/SCENARIO/sceneNNNN.yaml and \
                 requests/…, or problems/SCENARIO_panda/ (the archive unpacked)",
                args.problems.display()
            ),
        ));
    }
    row("all", &all);
    if args.bodies {
        bodies.push(("all".into(), all.bodies.clone()));
        crate::robot_cloud_bodies::table(&bodies);
    }
    if all.misses + all.false_collisions > 0 {
        return Err(Error::Numerical(format!(
            "{} misses and {} false collisions against the brute force",
            all.misses, all.false_collisions
        )));
    }
    Ok(())
}

/// Random configurations against the cloud (block checks) and the primitives: exactness against
/// the brute force, the model's errors against the primitives, the times.
fn check_configurations(
    robot: &FittedRobot,
    rng: &mut rand_chacha::ChaCha8Rng,
    args: &RobotCloudsArgs,
    points: &[[Real; 3]],
    on_cloud: &mut RobotChecker<'_>,
    on_truth: &mut RobotChecker<'_>,
    t: &mut Tally,
) -> Result<Vec<Vec<Real>>> {
    use rand::Rng;
    let base = Isometry3::identity();
    let dof = robot.model.dof();
    let mut flat = Vec::with_capacity(args.configs * dof);
    for _ in 0..args.configs {
        for k in 0..dof {
            let (lo, hi) =
                robot.model.variable_joint(k).limits.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI));
            flat.push(rng.random_range(lo..=hi));
        }
    }
    let options = CheckOptions { padding: 0.0, distance: false, self_collision: false, gradient: false };
    let (mut cloud, mut truth) = (Vec::new(), Vec::new());
    // Untimed first runs build the block plans.
    on_cloud.check_block(&flat[..dof], &base, &options, false, &mut cloud)?;
    on_truth.check_block(&flat[..dof], &base, &options, false, &mut truth)?;
    cloud.clear();
    truth.clear();
    let clock = Instant::now();
    on_cloud.check_block(&flat, &base, &options, false, &mut cloud)?;
    t.cloud_seconds += clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    on_truth.check_block(&flat, &base, &options, false, &mut truth)?;
    t.truth_seconds += clock.elapsed().as_secs_f64();
    if std::env::var_os("SUBLEVEL_CLOUD_STATS").is_some() {
        let exact: usize = cloud.iter().map(|a| a.pairs_exact).sum();
        let proved: usize = cloud.iter().map(|a| a.pairs_proved).sum();
        let with_exact = cloud.iter().filter(|a| a.pairs_exact > 0).count();
        eprintln!(
            "exact pairs {exact}, proved {proved}, configurations with exact pairs {with_exact} of {}",
            cloud.len()
        );
    }
    let mut poses = Vec::new();
    for (i, q) in flat.chunks(dof).enumerate() {
        robot.model.forward_kinematics(q, &base, &mut poses)?;
        let brute = if args.no_reference {
            cloud[i].world
        } else {
            reference_gap(robot, &poses, points, args.radius, 1e-6) <= 0.0
        };
        t.configs += 1;
        t.misses += usize::from(brute && !cloud[i].world);
        t.false_collisions += usize::from(!brute && cloud[i].world);
        t.truth_colliding += usize::from(truth[i].world);
        t.model_false += usize::from(cloud[i].world && !truth[i].world);
        t.model_misses += usize::from(!cloud[i].world && truth[i].world);
    }
    Ok(flat.chunks(dof).map(|q| q.to_vec()).collect())
}

/// Plans the problem against the cloud and against the primitives; a cloud's path is checked
/// edge by edge against the primitives by conservative advancement.
fn plan_both(
    robot: &FittedRobot,
    args: &RobotCloudsArgs,
    (start, goal): (&[Real], &[Real]),
    world: Vec<WorldObject>,
    truth: &[WorldObject],
    allowed: &dyn Fn(&str, &str) -> Option<bool>,
    t: &mut Tally,
) -> Result<()> {
    let settings = PlanSettings { timeout: Duration::from_secs_f64(args.timeout), ..PlanSettings::default() };
    let base = Isometry3::identity();
    let asked = Goal::Configurations(vec![goal.to_vec()]);
    let stats = std::env::var_os("SUBLEVEL_CLOUD_STATS").is_some();
    let cloud_world = if stats { world.clone() } else { Vec::new() };
    for (cloud, w) in [(true, world), (false, truth.to_vec())] {
        let mut checker = RobotChecker::new(robot, w, allowed)?;
        let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, base, settings.padding);
        let clock = Instant::now();
        let out = plan(&mut validity, start, &asked, &settings, &AtomicBool::new(false))?;
        let seconds = clock.elapsed().as_secs_f64();
        if out.status != PlanStatus::Solved {
            let status = format!("{:?}", out.status);
            eprintln!(
                "{} plan: {}",
                if cloud { "cloud" } else { "primitives" },
                status.chars().take(200).collect::<String>()
            );
            continue;
        }
        if !cloud {
            t.truth_solved += 1;
            t.truth_plan_seconds.push(seconds);
            continue;
        }
        t.solved += 1;
        t.plan_seconds.push(seconds);
        if stats {
            let m = &out.timing;
            eprintln!(
                "cloud plan {:.1} ms: search {:.1}, simplify {:.1}, certify {:.1}",
                seconds * 1e3,
                m.search.as_secs_f64() * 1e3,
                m.simplify.as_secs_f64() * 1e3,
                m.certify.as_secs_f64() * 1e3
            );
        }
        let mut on_truth = RobotChecker::new(robot, truth.to_vec(), allowed)?;
        let mut motions = MotionChecker::new(&mut on_truth)?;
        let mut free = true;
        for edge in out.path.windows(2) {
            let answer = motions.check_motion(&edge[0], &edge[1], &base, &MotionOptions::default())?;
            free &= answer.valid;
            if let (true, false, Some(q), Some((g, o))) = (stats, answer.valid, &answer.contact_q, answer.pair) {
                // Where a cloud path meets the primitives: the pair, and how far the cloud is there.
                let mut on_cloud = RobotChecker::new(robot, cloud_world.clone(), allowed)?;
                let seen = on_cloud.check(q, &base, &CheckOptions { distance: true, ..CheckOptions::default() })?;
                eprintln!(
                    "cloud path meets the primitives: {} – {} at t {:.3}; robot–cloud distance there {:.4} m",
                    robot.geometries[g].name,
                    o.map_or("itself".into(), |o| truth[o].name.clone()),
                    answer.contact.unwrap_or(Real::NAN),
                    seen.distance
                );
            }
        }
        t.paths_free += usize::from(free);
    }
    Ok(())
}

fn merge(all: &mut Tally, t: Tally) {
    all.problems += t.problems;
    all.points.extend(t.points);
    all.frame_seconds.extend(t.frame_seconds);
    all.configs += t.configs;
    all.misses += t.misses;
    all.false_collisions += t.false_collisions;
    all.model_false += t.model_false;
    all.model_misses += t.model_misses;
    all.truth_colliding += t.truth_colliding;
    all.cloud_seconds += t.cloud_seconds;
    all.truth_seconds += t.truth_seconds;
    all.solved += t.solved;
    all.truth_solved += t.truth_solved;
    all.plan_seconds.extend(t.plan_seconds);
    all.truth_plan_seconds.extend(t.truth_plan_seconds);
    all.paths_free += t.paths_free;
    crate::robot_cloud_bodies::merge(&mut all.bodies, t.bodies);
}

fn row(name: &str, t: &Tally) {
    let per = |s: Real| 1e6 * s / t.configs.max(1) as Real;
    let (plan_ms, truth_ms) = (1e3 * median(&t.plan_seconds), 1e3 * median(&t.truth_plan_seconds));
    println!(
        "| {name} | {} | {:.0} | {:.1} | {} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.1} | {} | {} | {:.2} | {:.2} | \
         {:.2} | {} |",
        t.problems,
        median(&t.points),
        1e3 * median(&t.frame_seconds),
        t.configs,
        t.misses,
        t.false_collisions,
        t.truth_colliding,
        t.model_false,
        t.model_misses,
        per(t.cloud_seconds),
        per(t.truth_seconds),
        t.cloud_seconds / t.truth_seconds.max(1e-12),
        t.solved,
        t.truth_solved,
        plan_ms,
        truth_ms,
        plan_ms / truth_ms,
        t.paths_free,
    );
}
