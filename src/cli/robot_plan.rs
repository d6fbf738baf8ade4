//! `sublevel robot plan`: a MoveIt MotionPlanRequest planned offline (no server), the same planner
//! as the `Plan` RPC (docs/planning.md).
//!
//! ```text
//! sublevel robot plan robot.json --scene SCENE.yaml --request REQUEST.yaml [--timeout 1] [--seed 1]
//!     [--padding 0] [--no-simplify] [--smoothing 0] [--json]
//! ```

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use sublevel::math::{Isometry3, Real};
use sublevel::plan::{
    joint_goal, plan, start_from_joints, PlanSettings, PlanStatus, RobotValidity, START_STATE_MAX_BOUNDS_ERROR,
};
use sublevel::robot::{FittedRobot, MotionChecker, RobotChecker};
use sublevel::scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};
use sublevel::Result;

/// Arguments of `sublevel robot plan`.
#[derive(clap::Args, Debug)]
pub struct PlanArgs {
    /// The robot file (`sublevel robot fit`).
    robot: PathBuf,
    /// The world: a MoveIt planning scene (YAML, or JSON for `.json`); its allowed-collision
    /// matrix overrides the robot's, its robot state gives the joints the request omits.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// The MoveIt MotionPlanRequest (YAML or JSON): its start state and its first goal
    /// constraint's joint constraints (a MotionBenchMaker request file).
    #[arg(long)]
    request: PathBuf,
    /// The whole plan's time, seconds.
    #[arg(long, default_value_t = 1.0)]
    timeout: Real,
    /// The sampler's seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Clearance every robot geometry keeps, meters.
    #[arg(long, default_value_t = 0.0)]
    padding: Real,
    /// Longest extension step of the search (joint-space distance).
    #[arg(long, default_value_t = 1.0)]
    range: Real,
    /// Keep the search's path as found (no shortcuts).
    #[arg(long)]
    no_simplify: bool,
    /// Corner-cutting passes after the shortcuts.
    #[arg(long, default_value_t = 0)]
    smoothing: usize,
    /// One JSON object (status, path, times, counts) instead of the table.
    #[arg(long)]
    json: bool,
}

fn read(path: &PathBuf) -> Result<Vec<u8>> {
    Ok(std::fs::read(path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?)
}

/// Runs `sublevel robot plan`.
///
/// # Errors
/// Files that cannot be read; a scene, request or setting that does not validate (named); the
/// checks' errors.
pub fn run(args: PlanArgs) -> Result<()> {
    let robot = FittedRobot::load(&args.robot)?;
    let scene = match &args.scene {
        Some(path) if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) => {
            PlanningScene::from_json(&read(path)?)?
        }
        Some(path) => PlanningScene::from_yaml(&read(path)?)?,
        None => PlanningScene::default(),
    };
    let request = MotionPlanRequest::from_yaml(&read(&args.request)?)?;
    let (world, skipped) = world_objects(&scene)?;
    for s in &skipped {
        eprintln!("warning: {}[{}] ({}) left out: {}", s.object_id, s.shape_index, s.kind, s.reason);
    }
    let (start, moved) = start_from_joints(
        &robot.model,
        "request.start_state",
        &request.start,
        &scene.joint_positions,
        START_STATE_MAX_BOUNDS_ERROR,
    )?;
    let constraints = request.goal_constraints();
    let (goal, goal_moved) = joint_goal(
        &robot.model,
        "request.goal_constraints[0].joint_constraints",
        &constraints,
        &start,
        START_STATE_MAX_BOUNDS_ERROR,
    )?;
    for line in moved.iter().chain(&goal_moved) {
        eprintln!("warning: {line}");
    }
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        return Err(sublevel::Error::invalid("--timeout", format!("must be > 0 s, got {}", args.timeout)));
    }
    let settings = PlanSettings {
        timeout: Duration::from_secs_f64(args.timeout),
        seed: args.seed,
        range: args.range,
        padding: args.padding,
        simplify: !args.no_simplify,
        smoothing_passes: args.smoothing,
        ..PlanSettings::default()
    };
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(&robot, world, &allowed)?;
    let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, Isometry3::identity(), settings.padding);
    // The joints the goal names move (MoveIt's planning group); the others stay at the start's.
    let moving: Vec<bool> =
        robot.model.variable_names().iter().map(|n| constraints.iter().any(|c| c.0 == *n)).collect();
    validity.hold_all_but(&moving, &start);
    let clock = Instant::now();
    let out = plan(&mut validity, &start, &goal, &settings, &AtomicBool::new(false))?;
    let wall = clock.elapsed();
    let names: Vec<&str> = robot.model.variable_names();
    let (status, message) = match &out.status {
        PlanStatus::Solved => ("solved", String::new()),
        PlanStatus::TimedOut => ("timed_out", String::new()),
        PlanStatus::StartInCollision(w) => ("start_in_collision", w.clone()),
        PlanStatus::GoalInCollision(w) => ("goal_in_collision", w.clone()),
        PlanStatus::GoalUnreachable(w) => ("goal_unreachable", w.clone()),
        PlanStatus::Cancelled => ("cancelled", String::new()),
    };
    let t = &out.timing;
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let stdout = std::io::stdout();
    let mut w = std::io::BufWriter::new(stdout.lock());
    if args.json {
        let json = serde_json::json!({
            "status": status,
            "message": message,
            "joint_names": names,
            "path": out.path,
            "length": out.length,
            "certified": out.certified,
            "unproven_edges": out.unproven,
            "time_s": {"total": wall.as_secs_f64(), "goals": t.goals.as_secs_f64(), "search": t.search.as_secs_f64(),
                       "simplify": t.simplify.as_secs_f64(), "certify": t.certify.as_secs_f64()},
            "states_checked": out.counts.states,
            "edges_checked": out.counts.edges,
            "edges_certified": out.counts.edges_certified,
            "advancement_steps": out.counts.advancement_steps,
            "nodes": out.nodes,
            "repaired": out.repaired,
        });
        writeln!(w, "{json}")?;
        return Ok(());
    }
    writeln!(w, "status: {status}{}", if message.is_empty() { String::new() } else { format!(" ({message})") })?;
    writeln!(
        w,
        "time: {:.2} ms (search {:.2}, simplify {:.2}, certify {:.2}); {} states, {} sampled edges, {} certified edges \
         ({} advancement steps), {} nodes, {} edges repaired",
        ms(wall),
        ms(t.search),
        ms(t.simplify),
        ms(t.certify),
        out.counts.states,
        out.counts.edges,
        out.counts.edges_certified,
        out.counts.advancement_steps,
        out.nodes,
        out.repaired
    )?;
    if out.path.is_empty() {
        return Ok(());
    }
    writeln!(w, "path: {} waypoints, length {:.4}, certified: {}", out.path.len(), out.length, out.certified)?;
    writeln!(w, "{}", names.join(","))?;
    for q in &out.path {
        writeln!(w, "{}", q.iter().map(|v| format!("{v:.6}")).collect::<Vec<_>>().join(","))?;
    }
    Ok(())
}
