//! `sublevel robot plan`: a MoveIt MotionPlanRequest planned offline (no server), the same planner
//! as the `Plan` RPC (docs/planning.md).
//!
//! ```text
//! sublevel robot plan robot.json --scene SCENE.yaml --request REQUEST.yaml [--timeout 1] [--seed 1]
//!     [--padding 0] [--no-simplify] [--smoothing 0] [--json]
//!     [--trajectory [--joint-limits joint_limits.yaml] [--sample-dt 0.01] [--max-deviation 0.1]
//!      [--velocity-scaling 1] [--acceleration-scaling 1] [--moveit]]
//! ```
//!
//! With `--trajectory` the path is timed as `Plan` times it (docs/planning.md, "Timed
//! trajectories"); `--moveit` prints it as a MoveIt `moveit_msgs/RobotTrajectory` in YAML.

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use sublevel::math::{Isometry3, Real};
use sublevel::plan::trajectory::{
    joint_limits, timed_trajectory, TimedTrajectory, TimingSettings, TrajectoryRequest, DEFAULT_MAX_DEVIATION,
    DEFAULT_SAMPLE_DT,
};
use sublevel::plan::{
    joint_goal, plan, start_from_joints, PlanSettings, PlanStatus, RobotValidity, START_STATE_MAX_BOUNDS_ERROR,
};
use sublevel::robot::{FittedRobot, MotionChecker, RobotChecker};
use sublevel::scene::moveit::{allowed_override, world_objects, JointLimitsYaml, MotionPlanRequest, PlanningScene};
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
    /// Time the path: blended corners proven free, time-optimal within the joint limits.
    #[arg(long)]
    trajectory: bool,
    /// A MoveIt joint_limits.yaml (velocity and acceleration limits) for `--trajectory`.
    #[arg(long)]
    joint_limits: Option<PathBuf>,
    /// Seconds between the trajectory's points.
    #[arg(long, default_value_t = DEFAULT_SAMPLE_DT)]
    sample_dt: Real,
    /// Most joint-space distance a blended corner passes from its waypoint (0: stop at each).
    #[arg(long, default_value_t = DEFAULT_MAX_DEVIATION)]
    max_deviation: Real,
    /// Factor in (0, 1] on the velocity limits (else the request's, the file's default, 1).
    #[arg(long)]
    velocity_scaling: Option<Real>,
    /// Factor in (0, 1] on the acceleration limits.
    #[arg(long)]
    acceleration_scaling: Option<Real>,
    /// Print the trajectory as a MoveIt RobotTrajectory (YAML) instead of the table.
    #[arg(long)]
    moveit: bool,
    #[command(flatten)]
    fidelity: super::fidelity::FidelityArgs,
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
    checker.set_fidelity(args.fidelity.level()?)?;
    let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, Isometry3::identity(), settings.padding);
    // The joints the goal names move (MoveIt's planning group); the others stay at the start's.
    let moving: Vec<bool> =
        robot.model.variable_names().iter().map(|n| constraints.iter().any(|c| c.0 == *n)).collect();
    validity.hold_all_but(&moving, &start);
    let clock = Instant::now();
    let out = plan(&mut validity, &start, &goal, &settings, &AtomicBool::new(false))?;
    let wall = clock.elapsed();
    let names: Vec<&str> = robot.model.variable_names();
    let timed = match (args.trajectory, out.path.is_empty()) {
        (true, false) => {
            let ask = trajectory_request(&args, &robot, &request, &moving)?;
            Some(timed_trajectory(&mut validity, &out.path, &ask, settings.tolerance)?)
        }
        _ => None,
    };
    if args.moveit {
        let Some(t) = &timed else {
            return Err(sublevel::Error::invalid("--moveit", format!("no trajectory: the plan is {:?}", out.status)));
        };
        let stdout = std::io::stdout();
        let mut w = std::io::BufWriter::new(stdout.lock());
        write_moveit(&mut w, &names, t)?;
        return Ok(());
    }
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
            "trajectory": timed.as_ref().map(|t| serde_json::json!({
                "time_from_start": t.trajectory.time_from_start,
                "positions": t.trajectory.positions,
                "velocities": t.trajectory.velocities,
                "accelerations": t.trajectory.accelerations,
                "duration": t.trajectory.duration,
                "max_velocity": t.limits.velocity,
                "max_acceleration": t.limits.acceleration,
                "certified": out.certified,
                "blends": t.blends.arcs_certified,
                "blends_tightened": t.blends.tightened,
                "stops": t.stops,
                "corner_deviation": t.blends.path.deviation,
                "seconds": t.seconds,
            })),
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
    if let Some(t) = &timed {
        writeln!(
            w,
            "trajectory: {:.4} s, {} points, {} blends ({} tightened), {} stops, certified: {}, timed in {:.2} ms \
             (blends {:.2}, timing {:.2}, sampling {:.2})",
            t.trajectory.duration,
            t.trajectory.time_from_start.len(),
            t.blends.arcs_certified,
            t.blends.tightened,
            t.stops,
            out.certified,
            t.seconds * 1e3,
            t.stage_seconds[0] * 1e3,
            t.stage_seconds[1] * 1e3,
            t.stage_seconds[2] * 1e3
        )?;
    }
    Ok(())
}

/// The trajectory request of `--trajectory`: limits from `--joint-limits`, the URDF, or the
/// defaults (a warning on stderr per joint that took one), the scaling factors from the flags,
/// the request, the file, else 1.
fn trajectory_request(
    args: &PlanArgs,
    robot: &FittedRobot,
    request: &MotionPlanRequest,
    moving: &[bool],
) -> Result<TrajectoryRequest> {
    let names = robot.model.variable_names();
    let (mut velocity_scaling, mut acceleration_scaling) = (None, None);
    let (mut velocity, mut acceleration) = Default::default();
    if let Some(path) = &args.joint_limits {
        let file = JointLimitsYaml::from_yaml(&read(path)?)?;
        let maps = file.for_joints(&names);
        for name in &maps.skipped {
            eprintln!("warning: {}: joint `{name}` is not a moving joint of the robot; skipped", path.display());
        }
        (velocity, acceleration) = (maps.velocity, maps.acceleration);
        (velocity_scaling, acceleration_scaling) =
            (file.default_velocity_scaling_factor, file.default_acceleration_scaling_factor);
    }
    let (limits, warnings) = joint_limits(&robot.model, &velocity, &acceleration, moving)?;
    for line in warnings {
        eprintln!("warning: {line}");
    }
    let timing = TimingSettings {
        velocity_scaling: args
            .velocity_scaling
            .or(request.max_velocity_scaling_factor)
            .or(velocity_scaling)
            .unwrap_or(1.0),
        acceleration_scaling: args
            .acceleration_scaling
            .or(request.max_acceleration_scaling_factor)
            .or(acceleration_scaling)
            .unwrap_or(1.0),
        ..TimingSettings::default()
    };
    timing.validate().map_err(|e| match e {
        sublevel::Error::InvalidArgument { field, reason } => {
            sublevel::Error::InvalidArgument { field: format!("--{}", field.replace('_', "-")), reason }
        }
        other => other,
    })?;
    Ok(TrajectoryRequest { limits, timing, sample_dt: args.sample_dt, max_deviation: args.max_deviation })
}

/// `t` as a MoveIt `moveit_msgs/RobotTrajectory` in YAML: `joint_trajectory` with its joint names
/// and points (`time_from_start` as `sec` and `nanosec`).
fn write_moveit(w: &mut impl Write, names: &[&str], t: &TimedTrajectory) -> Result<()> {
    let list = |v: &[Real]| v.iter().map(|x| format!("{x:.9}")).collect::<Vec<_>>().join(", ");
    writeln!(w, "joint_trajectory:")?;
    writeln!(w, "  joint_names: [{}]", names.join(", "))?;
    writeln!(w, "  points:")?;
    let tr = &t.trajectory;
    for i in 0..tr.time_from_start.len() {
        let time = tr.time_from_start[i];
        let (sec, nanosec) = (time.floor(), ((time - time.floor()) * 1e9).round().min(999_999_999.0));
        writeln!(w, "    - positions: [{}]", list(&tr.positions[i]))?;
        writeln!(w, "      velocities: [{}]", list(&tr.velocities[i]))?;
        writeln!(w, "      accelerations: [{}]", list(&tr.accelerations[i]))?;
        writeln!(w, "      time_from_start: {{sec: {sec}, nanosec: {nanosec}}}")?;
    }
    writeln!(w, "multi_dof_joint_trajectory: {{joint_names: [], points: []}}")?;
    Ok(())
}
