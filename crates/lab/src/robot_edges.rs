//! `sublevel-lab robot-edges`: sampled edge checks on the MotionBenchMaker Panda problems. Each
//! problem's start–goal segment is sampled at `--resolution` configurations per unit of joint
//! distance (`n = max(1, ⌈‖goal − start‖ · resolution⌉)` samples at t = i / n, i = 1..=n, the
//! start not checked) and checked two ways, one thread:
//!
//! - **rakes**: [`RobotChecker::rake_motion`], blocks of [`BLOCK`] samples spread along the
//!   segment ([`sublevel_robot::rake_order`]) checked by [`RobotChecker::check_block`], stopping
//!   at the first block with a colliding sample;
//! - **one at a time**: one [`RobotChecker::check`] per sample in the order of OMPL's discrete
//!   motion validator ([`sublevel_plan::validity::sample_order`]), stopping at the first
//!   colliding sample.
//!
//! Per scenario: the segments, how many collide (the two ways must agree: a disagreement is
//! counted and reported), the samples each way checked, the time per checked sample (the sum of
//! the segments' median times over `--repeats` runs after an untimed one, over the samples
//! checked) and the median time per segment.
//!
//! ```text
//! mkdir -p /tmp/mbm && tar xjf data/robots/mbm_panda/problems.tar.bz2 -C /tmp/mbm
//! cargo run --release -p sublevel-lab -- robot-edges --problems /tmp/mbm --limit 100
//! ```
//!
//! Problems 1 to `--limit` of each scenario: `PROBLEMS/scenes/SCENARIO/sceneNNNN.yaml` with
//! `PROBLEMS/requests/SCENARIO/requestNNNN.yaml` (the repository's 10 per scenario, the
//! default), or the MotionBenchMaker archive's `PROBLEMS/problems/SCENARIO_panda/{scene,request}NNNN.yaml`.

use std::path::{Path, PathBuf};
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::{Error, Result};
use sublevel_plan::validity::sample_order;
use sublevel_robot::{CheckOptions, FittedRobot, RobotChecker, BLOCK};
use sublevel_scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};

/// Arguments of `sublevel-lab robot-edges`.
#[derive(clap::Args, Debug)]
pub struct RobotEdgesArgs {
    /// The fitted robot (`sublevel robot fit`).
    #[arg(long, default_value = "data/robots/panda/panda.robot.json")]
    robot: PathBuf,
    /// The problems: `DIR/scenes/S/sceneNNNN.yaml` + `DIR/requests/S/requestNNNN.yaml`, or the
    /// archive's `DIR/problems/S_panda/{scene,request}NNNN.yaml`.
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
    #[arg(long, default_value_t = 100)]
    limit: usize,
    /// Samples per unit of joint distance (VAMP's and the planner's 32).
    #[arg(long, default_value_t = 32.0)]
    resolution: Real,
    /// Timed runs of each segment each way (the median is kept).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
}

/// One scenario's segments.
#[derive(Default)]
struct Tally {
    segments: usize,
    colliding: usize,
    disagreements: usize,
    samples: Vec<Real>,
    rake_samples: usize,
    single_samples: usize,
    rake_seconds: Vec<Real>,
    single_seconds: Vec<Real>,
}

pub(crate) fn median(v: &[Real]) -> Real {
    let mut v = v.to_vec();
    v.sort_by(Real::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(Real::NAN)
}

/// The scene and request files of problem `k` of `scenario`, in either layout.
pub(crate) fn problem_paths(problems: &Path, scenario: &str, k: usize) -> (PathBuf, PathBuf) {
    let scene = problems.join(format!("scenes/{scenario}/scene{k:04}.yaml"));
    if scene.exists() {
        return (scene, problems.join(format!("requests/{scenario}/request{k:04}.yaml")));
    }
    let dir = problems.join(format!("problems/{scenario}_panda"));
    (dir.join(format!("scene{k:04}.yaml")), dir.join(format!("request{k:04}.yaml")))
}

pub(crate) fn read(path: &Path) -> Result<Vec<u8>> {
    Ok(std::fs::read(path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?)
}

/// The samples `start + (i / n)(goal − start)` of one segment checked one at a time in OMPL's
/// order: whether one collides, and how many were checked.
fn one_at_a_time(
    checker: &mut RobotChecker<'_>,
    start: &[Real],
    goal: &[Real],
    n: usize,
    q: &mut Vec<Real>,
) -> Result<(bool, usize)> {
    let options = CheckOptions { padding: 0.0, distance: false, self_collision: true, gradient: false };
    let base = Isometry3::identity();
    for (checked, i) in sample_order(n).into_iter().enumerate() {
        let t = i as Real / n as Real;
        q.clear();
        q.extend(start.iter().zip(goal).map(|(x, y)| x + t * (y - x)));
        if checker.check(q, &base, &options)?.collides {
            return Ok((true, checked + 1));
        }
    }
    Ok((false, n))
}

/// Runs `sublevel-lab robot-edges`.
///
/// # Errors
/// Bad arguments (named), files that cannot be read or parsed, a check that fails.
pub fn run(args: RobotEdgesArgs) -> Result<()> {
    if !(args.resolution.is_finite() && args.resolution > 0.0) {
        return Err(Error::invalid("--resolution", format!("must be finite and > 0, got {}", args.resolution)));
    }
    if !(1..=100).contains(&args.repeats) {
        return Err(Error::invalid("--repeats", format!("must be in [1, 100], got {}", args.repeats)));
    }
    let robot = FittedRobot::load(&args.robot)?;
    let names: Vec<String> = robot.model.variable_names().iter().map(|s| s.to_string()).collect();
    let base = Isometry3::identity();
    println!(
        "start–goal segments sampled at {} per unit of joint distance, one thread, each timed {} times (median); \
         rakes: `rake_motion`, blocks of {BLOCK}; one at a time: `check` in OMPL's order",
        args.resolution, args.repeats
    );
    println!(
        "| scenario | segments | colliding | disagreements | median samples | rake samples checked | rake µs per sample | \
         one-at-a-time samples checked | one-at-a-time µs per sample | median segment, rakes (µs) | median segment, one at a time (µs) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut all = Tally::default();
    let mut q = Vec::new();
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
            let (world, _) = world_objects(&scene)?;
            let allowed = allowed_override(&scene);
            let mut checker = RobotChecker::new(&robot, world, &allowed)?;
            let length = start.iter().zip(&goal).map(|(x, y)| (y - x) * (y - x)).sum::<Real>().sqrt();
            let n = ((length * args.resolution).ceil() as usize).max(1);
            let (mut rake_times, mut single_times) = (Vec::new(), Vec::new());
            // One untimed run each way first: the checker's block tables and warm starts built.
            let mut rake = checker.rake_motion(&start, &goal, args.resolution, &base, 0.0)?;
            let mut single = one_at_a_time(&mut checker, &start, &goal, n, &mut q)?;
            for _ in 0..args.repeats {
                let clock = Instant::now();
                rake = checker.rake_motion(&start, &goal, args.resolution, &base, 0.0)?;
                rake_times.push(clock.elapsed().as_secs_f64());
                let clock = Instant::now();
                single = one_at_a_time(&mut checker, &start, &goal, n, &mut q)?;
                single_times.push(clock.elapsed().as_secs_f64());
            }
            t.segments += 1;
            t.colliding += usize::from(rake.collision.is_some());
            if rake.collision.is_some() != single.0 {
                t.disagreements += 1;
                eprintln!("{scenario} {k}: rakes {:?}, one at a time {}", rake.collision, single.0);
            }
            t.samples.push(n as Real);
            t.rake_samples += rake.samples;
            t.single_samples += single.1;
            t.rake_seconds.push(median(&rake_times));
            t.single_seconds.push(median(&single_times));
        }
        row(scenario, &t);
        all.segments += t.segments;
        all.colliding += t.colliding;
        all.disagreements += t.disagreements;
        all.samples.extend(&t.samples);
        all.rake_samples += t.rake_samples;
        all.single_samples += t.single_samples;
        all.rake_seconds.extend(&t.rake_seconds);
        all.single_seconds.extend(&t.single_seconds);
    }
    row("all", &all);
    if all.disagreements > 0 {
        return Err(Error::Numerical(format!(
            "{} segments where the rakes and the one-at-a-time check disagree",
            all.disagreements
        )));
    }
    Ok(())
}

fn row(name: &str, t: &Tally) {
    let per_sample = |seconds: &[Real], samples: usize| 1e6 * seconds.iter().sum::<Real>() / samples.max(1) as Real;
    println!(
        "| {name} | {} | {} | {} | {:.0} | {} | {:.2} | {} | {:.2} | {:.1} | {:.1} |",
        t.segments,
        t.colliding,
        t.disagreements,
        median(&t.samples),
        t.rake_samples,
        per_sample(&t.rake_seconds, t.rake_samples),
        t.single_samples,
        per_sample(&t.single_seconds, t.single_samples),
        1e6 * median(&t.rake_seconds),
        1e6 * median(&t.single_seconds),
    );
}
