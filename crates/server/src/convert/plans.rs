//! `Plan`: the request's settings, start and goal as the planner takes them, and its outcome as
//! the response (docs/planning.md).

use crate::pb;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::time::Duration;
use sublevel_core::math::Real;
use sublevel_plan::trajectory::{
    joint_limits, TimedTrajectory, TimingSettings, TrajectoryRequest, DEFAULT_MAX_DEVIATION, DEFAULT_SAMPLE_DT,
};
use sublevel_plan::{
    fix_start_bounds, joint_goal, start_from_joints, Goal, JointConstraint, PlanOutcome, PlanSettings, PlanStatus,
    START_STATE_MAX_BOUNDS_ERROR,
};
use sublevel_robot::ik::PoseGoal;
use sublevel_robot::FittedRobot;
use sublevel_scene::moveit::{JointLimitsYaml, MotionPlanRequest};

/// The planner settings of a request: absent or zero fields take their defaults; nothing is
/// clamped silently ([`PlanSettings::validate`] gives every range).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `settings.FIELD` for a value out of its range (a 0 s
/// timeout included).
pub fn plan_settings(s: Option<&pb::PlanSettings>) -> Result<PlanSettings> {
    let d = PlanSettings::default();
    let Some(s) = s else { return Ok(d) };
    let or = |v: Real, default: Real| if v == 0.0 { default } else { v };
    let timeout = match s.timeout {
        None => d.timeout,
        Some(t) if t.is_finite() && t > 0.0 && t <= 3600.0 => Duration::from_secs_f64(t),
        Some(t) => {
            return Err(Error::invalid(
                "settings.timeout",
                format!("must be in (0, 3600] seconds, got {}", sublevel_core::error::show_real(t)),
            ));
        }
    };
    let settings = PlanSettings {
        timeout,
        seed: s.seed.unwrap_or(d.seed),
        range: or(s.range, d.range),
        resolution: or(s.resolution, d.resolution),
        goal_bias: s.goal_bias.unwrap_or(d.goal_bias),
        padding: s.padding,
        simplify: s.simplify.unwrap_or(d.simplify),
        shortcut_attempts: d.shortcut_attempts,
        smoothing_passes: s.smoothing_passes as usize,
        tolerance: or(s.tolerance, d.tolerance),
        max_goals: if s.max_goals == 0 { d.max_goals } else { s.max_goals as usize },
        search_margin: d.search_margin,
        dynamic_domain: d.dynamic_domain,
        balance: d.balance,
    };
    settings.validate().map_err(|e| crate::convert::prefix_field(e, "settings"))?;
    Ok(settings)
}

/// What a plan request asks, as the planner takes it ([`plan_ends`]).
#[derive(Clone, Debug)]
pub struct PlanEnds {
    /// The start configuration (radians, meters), moved into the limits.
    pub start: Vec<Real>,
    /// The goal; its configurations hold the joints the plan does not move at the start's values.
    pub goal: Goal,
    /// What was changed to plan them (`PlanResponse.warnings`).
    pub warnings: Vec<String>,
    /// Per configuration entry, whether the plan moves it (`PlanRequest.planning_joints`).
    pub moving: Vec<bool>,
}

/// The start, the goal and the planning joints of a request: its start and goal (its typed fields or
/// its MoveIt MotionPlanRequest text, `defaults` the scene's joint positions, values near the limits
/// moved into them and said in the warnings), then the joints the plan
/// moves: `planning_joints`, else the joints the goal names (a joint goal's constraints, a
/// MotionPlanRequest's goal constraints, goal configurations' `joint_names`), else every joint.
/// The others are held at the start's values: a goal configuration's value of such a joint the
/// goal does not name is set to the start's.
///
/// # Errors
/// [`Error::InvalidArgument`] naming the field: no goal or two kinds of goal, a start of more than
/// one configuration, unknown or repeated joints, values that are not finite or outside the limits
/// past their margins, a malformed MotionPlanRequest, `settings.start_state_max_bounds_error`
/// outside [0, 1]; `planning_joints[k]` for a name that is not a
/// moving joint of the robot or is repeated, `planning_joints` with a pose goal (inverse
/// kinematics moves every joint) or when the goal moves a joint it leaves out.
pub fn plan_ends(req: &pb::PlanRequest, robot: &FittedRobot, defaults: &[(String, Real)]) -> Result<PlanEnds> {
    let model = &robot.model;
    let names = model.variable_names();
    let (start, mut goal, warnings) = ends(req, robot, defaults)?;
    // The joints the goal names; None: every joint.
    let named: Option<Vec<String>> = if let Some(text) = &req.motion_plan_request {
        let bytes = match text {
            pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(t)
            | pb::plan_request::MotionPlanRequest::MotionPlanRequestJson(t) => t,
        };
        let request = MotionPlanRequest::from_yaml(bytes.as_bytes())?;
        Some(request.goals.iter().flatten().map(|c| c.0.clone()).collect())
    } else if !req.goal_joint_constraints.is_empty() {
        Some(req.goal_joint_constraints.iter().map(|c| c.joint_name.clone()).collect())
    } else {
        req.goal_configurations.as_ref().map(|c| c.joint_names.clone()).filter(|n| !n.is_empty())
    };
    let moving: Vec<bool> = if req.planning_joints.is_empty() {
        match &named {
            Some(named) if !matches!(goal, Goal::Pose(_)) => {
                names.iter().map(|n| named.iter().any(|m| m == n)).collect()
            }
            _ => vec![true; names.len()],
        }
    } else {
        if matches!(goal, Goal::Pose(_)) {
            return Err(Error::invalid(
                "planning_joints",
                "a pose goal moves every joint (its inverse kinematics does): leave planning_joints empty",
            ));
        }
        let mut moving = vec![false; names.len()];
        for (k, n) in req.planning_joints.iter().enumerate() {
            let j = names.iter().position(|m| m == n).ok_or_else(|| {
                Error::invalid(
                    format!("planning_joints[{k}]"),
                    format!(
                        "`{}` is not a moving joint of the robot; its joints: {names:?}",
                        sublevel_core::error::clip(n)
                    ),
                )
            })?;
            if std::mem::replace(&mut moving[j], true) {
                return Err(Error::invalid(format!("planning_joints[{k}]"), format!("`{n}` is repeated")));
            }
        }
        moving
    };
    let named_all = named.is_none();
    let names_joint = |k: usize| named_all || named.as_ref().is_some_and(|n| n.iter().any(|m| m == names[k]));
    let held = |k: usize, v: Real| -> Result<Real> {
        if v == start[k] || !names_joint(k) {
            return Ok(start[k]);
        }
        Err(Error::invalid(
            "planning_joints",
            format!(
                "the goal moves joint `{}` from {} to {v}, and it is not among the planning joints",
                names[k], start[k]
            ),
        ))
    };
    match &mut goal {
        Goal::Configurations(qs) => {
            for q in qs.iter_mut() {
                for k in (0..q.len()).filter(|&k| !moving[k]) {
                    q[k] = held(k, q[k])?;
                }
            }
        }
        Goal::Region(r) => {
            for k in (0..r.center.len()).filter(|&k| !moving[k]) {
                r.center[k] = held(k, r.center[k])?;
                (r.below[k], r.above[k]) = (0.0, 0.0);
            }
        }
        Goal::Pose(_) => {}
    }
    Ok(PlanEnds { start, goal, warnings, moving })
}

/// The start configuration and the goal of a request (its typed fields or its MoveIt
/// MotionPlanRequest text), `defaults` the scene's joint positions, and what was changed to plan
/// them (`PlanResponse.warnings`): start values up to `settings.start_state_max_bounds_error`
/// outside the limits moved onto them ([`fix_start_bounds`]), goal constraints taken where their
/// tolerance meets the limits, or at the limit when they miss it by at most as much
/// ([`joint_goal`]). Goal configurations within the rounding margin of
/// a limit ([`sublevel_robot::model::LIMIT_ROUNDING`]) are moved onto it silently.
///
/// # Errors
/// [`Error::InvalidArgument`] naming the field: no goal or two kinds of goal, a start of more than
/// one configuration, unknown or repeated joints, values that are not finite or outside the
/// limits (past the margins above), a malformed MotionPlanRequest,
/// `settings.start_state_max_bounds_error` outside [0, 1].
fn ends(
    req: &pb::PlanRequest,
    robot: &FittedRobot,
    defaults: &[(String, Real)],
) -> Result<(Vec<Real>, Goal, Vec<String>)> {
    let model = &robot.model;
    let max_error = match req.settings.as_ref().and_then(|s| s.start_state_max_bounds_error) {
        None => START_STATE_MAX_BOUNDS_ERROR,
        Some(e) if (0.0..=1.0).contains(&e) => e,
        Some(e) => {
            return Err(Error::invalid(
                "settings.start_state_max_bounds_error",
                format!("must be in [0, 1] (radians or meters), got {}", sublevel_core::error::show_real(e)),
            ))
        }
    };
    if let Some(text) = &req.motion_plan_request {
        let (field, bytes) = match text {
            pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(t) => ("motion_plan_request_yaml", t),
            pb::plan_request::MotionPlanRequest::MotionPlanRequestJson(t) => ("motion_plan_request_json", t),
        };
        let given = [
            ("start", req.start.is_some()),
            ("goal_configurations", req.goal_configurations.is_some()),
            ("goal_joint_constraints", !req.goal_joint_constraints.is_empty()),
            ("goal_pose", req.goal_pose.is_some()),
        ];
        if let Some((other, _)) = given.iter().find(|(_, g)| *g) {
            return Err(Error::invalid(
                *other,
                format!("give the start and the goal either in `{field}` or in the typed fields, not both"),
            ));
        }
        let request =
            MotionPlanRequest::from_yaml(bytes.as_bytes()).map_err(|e| crate::convert::prefix_field(e, field))?;
        return ends_of_moveit(field, &request, robot, defaults, max_error);
    }
    let (start, mut warnings) = match &req.start {
        Some(columns) => {
            if columns.values.len() > sublevel_robot::limits::MAX_MOVING_JOINTS {
                return Err(Error::invalid(
                    "start.values",
                    format!("one start configuration: at most {} values", sublevel_robot::limits::MAX_MOVING_JOINTS),
                ));
            }
            let mut qs =
                model.configurations_outside_limits("start", &columns.joint_names, &columns.values, defaults)?;
            if qs.len() != 1 {
                return Err(Error::invalid("start.values", format!("one start configuration, got {}", qs.len())));
            }
            let mut q = qs.remove(0);
            let moved = fix_start_bounds(model, "start.values", &mut q, max_error)?;
            (q, moved)
        }
        None => start_from_joints(model, "start", &[], defaults, max_error)?,
    };
    let kinds = [req.goal_configurations.is_some(), !req.goal_joint_constraints.is_empty(), req.goal_pose.is_some()];
    match kinds.iter().filter(|k| **k).count() {
        0 => {
            return Err(Error::invalid(
                "goal_configurations",
                "required: goal configurations, joint constraints, a pose goal or a motion_plan_request",
            ))
        }
        1 => {}
        _ => {
            return Err(Error::invalid(
                "goal_pose",
                "give one kind of goal: configurations, joint constraints or a pose",
            ))
        }
    }
    if let Some(columns) = &req.goal_configurations {
        let mut qs = crate::convert::configurations_from_proto("goal_configurations", Some(columns), robot, defaults)?;
        // Within the rounding margin of a limit: onto it, where the planner takes it.
        for q in &mut qs {
            for (k, v) in q.iter_mut().enumerate() {
                *v = model.variable_joint(k).clamp(*v);
            }
        }
        return Ok((start, Goal::Configurations(qs), warnings));
    }
    if let Some(pose) = &req.goal_pose {
        if model.link_index(&pose.link).is_none() {
            return Err(Error::invalid(
                "goal_pose.link",
                format!("`{}` is not a link of the robot", sublevel_core::error::clip(&pose.link)),
            ));
        }
        if pose.pose.is_none() {
            return Err(Error::invalid("goal_pose.pose", "required: the pose the link should reach"));
        }
        let target = crate::convert::pose_from_proto("goal_pose.pose", pose.pose.as_ref())?;
        let mut goal = PoseGoal::new(pose.link.clone(), target);
        for (field, value, slot) in [
            ("goal_pose.position_tolerance", pose.position_tolerance, &mut goal.position_tolerance),
            ("goal_pose.orientation_tolerance", pose.orientation_tolerance, &mut goal.orientation_tolerance),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::invalid(field, format!("must be finite and ≥ 0, got {value}")));
            }
            if value > 0.0 {
                *slot = value;
            }
        }
        return Ok((start, Goal::Pose(goal), warnings));
    }
    let constraints: Vec<JointConstraint> = req
        .goal_joint_constraints
        .iter()
        .map(|c| (c.joint_name.clone(), c.position, c.tolerance_below, c.tolerance_above))
        .collect();
    let (goal, moved) = joint_goal(model, "goal_joint_constraints", &constraints, &start, max_error)?;
    warnings.extend(moved);
    Ok((start, goal, warnings))
}

/// The start and goal of a MoveIt MotionPlanRequest: the start state's joints the robot moves
/// (others of the URDF, such as fixed fingers, ignored; a name the URDF lacks refused), the
/// scene's joint positions for the rest; the goal constraints' joint constraints, each a joint
/// the robot moves. Several goal constraints (MoveIt plans to any one of them) are goal
/// configurations, each exact; a goal region (tolerances) must be the only goal. Start values up
/// to `max_error` outside the limits are moved onto them; what was moved, in the lines returned.
fn ends_of_moveit(
    field: &str,
    request: &MotionPlanRequest,
    robot: &FittedRobot,
    defaults: &[(String, Real)],
    max_error: Real,
) -> Result<(Vec<Real>, Goal, Vec<String>)> {
    let (start, mut warnings) =
        start_from_joints(&robot.model, &format!("{field}.start_state"), &request.start, defaults, max_error)?;
    if request.goals.len() > sublevel_plan::MAX_GOALS {
        return Err(Error::invalid(
            format!("{field}.goal_constraints"),
            format!("at most {} goals, got {}", sublevel_plan::MAX_GOALS, request.goals.len()),
        ));
    }
    let mut configurations = Vec::with_capacity(request.goals.len());
    for (g, constraints) in request.goals.iter().enumerate() {
        let at = format!("{field}.goal_constraints[{g}].joint_constraints");
        let (goal, moved) = joint_goal(&robot.model, &at, constraints, &start, max_error)?;
        warnings.extend(moved);
        match goal {
            Goal::Configurations(qs) => configurations.extend(qs),
            region if request.goals.len() == 1 => return Ok((start, region, warnings)),
            _ => {
                return Err(Error::invalid(
                    format!("{field}.goal_constraints[{g}]"),
                    "a goal with tolerances must be the request's only goal: give several goals without tolerances, \
                     or one goal region",
                ))
            }
        }
    }
    Ok((start, Goal::Configurations(configurations), warnings))
}

/// The response of a plan: its status and message, the path in rows of the robot's joints, the
/// times and counts; `total` the server's time for the whole call.
pub fn plan_response(out: &PlanOutcome, robot: &FittedRobot, total: Duration) -> pb::PlanResponse {
    let (status, message) = match &out.status {
        PlanStatus::Solved => (pb::PlanStatus::Solved, String::new()),
        PlanStatus::TimedOut => (pb::PlanStatus::TimedOut, String::new()),
        PlanStatus::StartInCollision(why) => (pb::PlanStatus::StartInCollision, why.clone()),
        PlanStatus::GoalInCollision(why) => (pb::PlanStatus::GoalInCollision, why.clone()),
        PlanStatus::GoalUnreachable(why) => (pb::PlanStatus::GoalUnreachable, why.clone()),
        PlanStatus::Cancelled => (pb::PlanStatus::Cancelled, String::new()),
    };
    let t = &out.timing;
    pb::PlanResponse {
        status: status as i32,
        message,
        joint_names: robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
        path: out.path.iter().flatten().copied().collect(),
        waypoints: out.path.len() as u32,
        length: out.length,
        certified: out.certified,
        unproven_edges: out.unproven.iter().map(|&e| e as u32).collect(),
        goal: out.goal.clone().unwrap_or_default(),
        timing: Some(pb::PlanTiming {
            goals: t.goals.as_secs_f64(),
            search: t.search.as_secs_f64(),
            simplify: t.simplify.as_secs_f64(),
            certify: t.certify.as_secs_f64(),
            total: total.as_secs_f64(),
        }),
        states_checked: out.counts.states as u64,
        edges_checked: out.counts.edges as u64,
        edges_certified: out.counts.edges_certified as u64,
        advancement_steps: out.counts.advancement_steps as u64,
        nodes: out.nodes as u32,
        repaired: out.repaired as u32,
        // The scene's, which the handler knows.
        scene_version: 0,
        // The plan's settings, which the handler knows.
        check_tolerance: 0.0,
        // The request's, which the handler knows.
        warnings: Vec::new(),
        planning_joints: Vec::new(),
        // The trajectory stage's, which the handler runs.
        trajectory: None,
    }
}

/// The timed trajectory a plan request asks for (`PlanRequest.trajectory`), or `None`, with the
/// warnings of its limits: which joints took default limits, which joints of the
/// `joint_limits_yaml` are not the robot's. Limits and scaling factors are taken as
/// `TrajectorySettings` documents (the request's, then the MotionPlanRequest's factors, then the
/// file's defaults).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `trajectory.FIELD`: a scaling factor outside (0, 1], a
/// `sample_dt` not finite and > 0, a `max_deviation` negative or not finite, a limit not
/// finite and > 0 or naming a joint the robot does not move, a malformed `joint_limits_yaml`;
/// `motion_plan_request_…` for a malformed MotionPlanRequest.
pub fn trajectory_request(
    req: &pb::PlanRequest,
    robot: &FittedRobot,
    moving: &[bool],
) -> Result<Option<(TrajectoryRequest, Vec<String>)>> {
    match &req.trajectory {
        None => Ok(None),
        Some(t) => timing_request(t, req.motion_plan_request.as_ref(), robot, moving).map(Some),
    }
}

/// The timing `t` asks for (fields named `trajectory.…`), with the scaling factors of a
/// MotionPlanRequest text `mpr` when it gives them, and the warnings of its limits (as
/// [`trajectory_request`]).
///
/// # Errors
/// As [`trajectory_request`].
pub fn timing_request(
    t: &pb::TrajectorySettings,
    mpr: Option<&pb::plan_request::MotionPlanRequest>,
    robot: &FittedRobot,
    moving: &[bool],
) -> Result<(TrajectoryRequest, Vec<String>)> {
    let model = &robot.model;
    let names = model.variable_names();
    let mut velocity = BTreeMap::new();
    let mut acceleration = BTreeMap::new();
    let mut warnings = Vec::new();
    let (mut velocity_scaling, mut acceleration_scaling) = (None, None);
    if !t.joint_limits_yaml.is_empty() {
        let file = JointLimitsYaml::from_yaml(t.joint_limits_yaml.as_bytes())
            .map_err(|e| crate::convert::errors::prefix_field(e, "trajectory.joint_limits_yaml"))?;
        let maps = file.for_joints(&names);
        for name in &maps.skipped {
            warnings.push(format!(
                "trajectory.joint_limits_yaml.joint_limits.{}: not a moving joint of the robot; skipped",
                sublevel_core::error::clip(name)
            ));
        }
        velocity = maps.velocity;
        acceleration = maps.acceleration;
        velocity_scaling = file.default_velocity_scaling_factor;
        acceleration_scaling = file.default_acceleration_scaling_factor;
    }
    if let Some(text) = mpr {
        let (field, bytes) = match text {
            pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(t) => ("motion_plan_request_yaml", t),
            pb::plan_request::MotionPlanRequest::MotionPlanRequestJson(t) => ("motion_plan_request_json", t),
        };
        let request = MotionPlanRequest::from_yaml(bytes.as_bytes())
            .map_err(|e| crate::convert::errors::prefix_field(e, field))?;
        velocity_scaling = request.max_velocity_scaling_factor.or(velocity_scaling);
        acceleration_scaling = request.max_acceleration_scaling_factor.or(acceleration_scaling);
    }
    velocity.extend(t.max_velocity.iter().map(|(k, v)| (k.clone(), *v)));
    acceleration.extend(t.max_acceleration.iter().map(|(k, v)| (k.clone(), *v)));
    let (limits, limit_warnings) = joint_limits(model, &velocity, &acceleration, moving)
        .map_err(|e| crate::convert::errors::prefix_field(e, "trajectory"))?;
    warnings.extend(limit_warnings.into_iter().map(|w| format!("trajectory.{w}")));
    let timing = TimingSettings {
        velocity_scaling: t.velocity_scaling.or(velocity_scaling).unwrap_or(1.0),
        acceleration_scaling: t.acceleration_scaling.or(acceleration_scaling).unwrap_or(1.0),
        ..TimingSettings::default()
    };
    timing.validate().map_err(|e| crate::convert::errors::prefix_field(e, "trajectory"))?;
    let sample_dt = t.sample_dt.unwrap_or(DEFAULT_SAMPLE_DT);
    if !(sample_dt.is_finite() && sample_dt > 0.0) {
        return Err(Error::invalid("trajectory.sample_dt", format!("must be finite and > 0 s, got {sample_dt}")));
    }
    let max_deviation = t.max_deviation.unwrap_or(DEFAULT_MAX_DEVIATION);
    if !(max_deviation.is_finite() && max_deviation >= 0.0) {
        return Err(Error::invalid(
            "trajectory.max_deviation",
            format!("must be finite and ≥ 0 (radians or meters), got {max_deviation}"),
        ));
    }
    Ok((TrajectoryRequest { limits, timing, sample_dt, max_deviation }, warnings))
}

/// A timed trajectory as `PlanResponse.trajectory`; `certified` whether the path it times is.
pub fn trajectory_response(t: &TimedTrajectory, robot: &FittedRobot, certified: bool) -> pb::JointTrajectory {
    let tr = &t.trajectory;
    pb::JointTrajectory {
        joint_names: robot.model.variable_names().iter().map(|s| (*s).to_owned()).collect(),
        points: tr.time_from_start.len() as u32,
        time_from_start: tr.time_from_start.clone(),
        positions: tr.positions.iter().flatten().copied().collect(),
        velocities: tr.velocities.iter().flatten().copied().collect(),
        accelerations: tr.accelerations.iter().flatten().copied().collect(),
        duration: tr.duration,
        max_velocity: t.limits.velocity.clone(),
        max_acceleration: t.limits.acceleration.clone(),
        certified,
        blends: t.blends.arcs_certified as u32,
        blends_tightened: t.blends.tightened as u32,
        stops: t.stops as u32,
        seconds: t.seconds,
        corner_deviation: t.blends.path.deviation.clone(),
    }
}
