//! `Plan`: a path for a robot among a scene in one call (docs/planning.md). The robot and the
//! scene are read as the robot checks read them ([`RobotChecks`]); the plan runs on a planning
//! slot of its own ([`crate::limits::QueryPools::plans`]), never on the batch slots the checks
//! use. Its deadline counts from the request's arrival: the request's timeout or the call's own
//! deadline, whichever comes first, covers the wait for a slot as well as the planning, and a
//! plan still waiting at its deadline answers TIMED_OUT without planning. It stops when the
//! client goes away (the slot's cancel flag), and its checker sees the deadline inside every
//! edge and certificate ([`sublevel_plan::Validity::set_deadline`]).

use super::robots::{Asked, RobotChecks, Setting};
use super::{Handled, SublevelService};
use crate::convert as cv;
use crate::pb;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};
use sublevel_plan::{PlanOutcome, RobotValidity, Validity};
use sublevel_robot::{MotionChecker, RobotChecker};
use tonic::{Request, Response};

/// How much of the call's own deadline the plan leaves for answering.
const ANSWER_MARGIN: Duration = Duration::from_millis(20);

/// Least time worth starting a plan with: below it, the plan answers TIMED_OUT at once.
const LEAST_PLAN_TIME: Duration = Duration::from_millis(1);

/// `Plan`: the request checked, then the plan on a planning slot, within its timeout counted
/// from arrival.
pub(super) async fn plan(svc: &SublevelService, request: Request<pb::PlanRequest>) -> Handled<pb::PlanResponse> {
    let clock = Instant::now();
    let call_deadline = crate::deadline::parse_grpc_timeout(&request.metadata().clone().into_headers());
    let req = request.into_inner();
    let mut settings = cv::plan_settings(req.settings.as_ref())?;
    let fidelity = cv::fidelity(req.fidelity.as_ref())?;
    if let Some(left) = call_deadline {
        settings.timeout = settings.timeout.min(left.saturating_sub(ANSWER_MARGIN).max(LEAST_PLAN_TIME));
    }
    let deadline = clock + settings.timeout;
    let checks = RobotChecks::of(svc);
    let asked = asked(&req.robot_id, &req.scene_id, req.base, &req.attached, &req.link_padding);
    let Setting { robot, world, base, link_padding } = checks.setting(asked).await?;
    let cv::PlanEnds { start, goal, warnings, moving } = cv::plan_ends(&req, &robot, &world.planning.joint_positions)?;
    let timed = cv::trajectory_request(&req, &robot, &moving)?;
    let timed_request = timed.as_ref().map(|(r, _)| r.clone());
    let scene_version = world.scene_version;
    let planned = robot.clone();
    let moving_joints = moving.clone();
    let outcome = checks
        .pools
        .plans
        .run_before(deadline, move || {
            let allowed = world.planning.allowed_override();
            let mut checker = RobotChecker::new(&planned, world.objects.clone(), &allowed)?;
            checker.set_link_padding(&link_padding)?;
            checker.set_fidelity(fidelity)?;
            let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, base, settings.padding);
            validity.hold_all_but(&moving_joints, &start);
            // The time left after the wait for the slot, the reading of the setting and the
            // checker's build.
            let left = deadline.saturating_duration_since(Instant::now());
            if left < LEAST_PLAN_TIME {
                return Ok(None);
            }
            settings.timeout = left;
            let cancel = sublevel_core::cancel::current().unwrap_or_else(|| Arc::new(AtomicBool::new(false)));
            let outcome = sublevel_plan::plan(&mut validity, &start, &goal, &settings, &cancel)?;
            // The trajectory stage: the path's blends proven at the plan's tolerance, then timed.
            let trajectory = match &timed_request {
                Some(request) if !outcome.path.is_empty() => Some(sublevel_plan::trajectory::timed_trajectory(
                    &mut validity,
                    &outcome.path,
                    request,
                    settings.tolerance,
                )?),
                _ => None,
            };
            Ok(Some((outcome, trajectory)))
        })
        .await?
        .flatten();
    let (outcome, trajectory) = match outcome {
        Some((outcome, trajectory)) => (Some(outcome), trajectory),
        None => (None, None),
    };
    let mut out = match &outcome {
        Some(outcome) => cv::plan_response(outcome, &robot, clock.elapsed()),
        None => {
            let mut out = cv::plan_response(&PlanOutcome::timed_out(), &robot, clock.elapsed());
            out.message = format!(
                "the timeout ({:.3} s, counted from the request's arrival) passed while the plan waited for a \
                 planning slot: {} plans run at once (--max-concurrent-plans)",
                settings.timeout.as_secs_f64(),
                svc.config.max_concurrent_plans
            );
            out
        }
    };
    out.scene_version = scene_version;
    out.warnings = warnings;
    if let (Some(t), Some(outcome)) = (&trajectory, &outcome) {
        out.trajectory = Some(cv::trajectory_response(t, &robot, outcome.certified));
        out.warnings.extend(timed.map(|(_, w)| w).unwrap_or_default());
    }
    out.planning_joints =
        robot.model.variable_names().iter().zip(&moving).filter(|(_, m)| **m).map(|(n, _)| (*n).to_owned()).collect();
    if !out.path.is_empty() {
        out.check_tolerance = sublevel_plan::certificate_tolerance(settings.tolerance);
    }
    Ok(Response::new(out))
}

/// Seconds a `TimeTrajectory` may take, the wait for a planning slot included, when the call
/// sets no deadline.
const TIME_TRAJECTORY_TIMEOUT: Duration = Duration::from_secs(60);

/// `TimeTrajectory`: a path from any planner checked edge by edge (conservative advancement),
/// then blended, its blends proven, and timed, on a planning slot (docs/planning.md).
pub(super) async fn time_trajectory(
    svc: &SublevelService,
    request: Request<pb::TimeTrajectoryRequest>,
) -> Handled<pb::TimeTrajectoryResponse> {
    let clock = Instant::now();
    let call_deadline = crate::deadline::parse_grpc_timeout(&request.metadata().clone().into_headers());
    let req = request.into_inner();
    let deadline = clock + call_deadline.map_or(TIME_TRAJECTORY_TIMEOUT, |d| d.saturating_sub(ANSWER_MARGIN));
    let checks = RobotChecks::of(svc);
    // Padding and tolerance as a plan's settings check them.
    let settings = cv::plan_settings(Some(&pb::PlanSettings {
        padding: req.padding,
        tolerance: req.tolerance,
        ..pb::PlanSettings::default()
    }))
    .map_err(|e| match e {
        crate::Error::InvalidArgument { field, reason } => {
            crate::Error::InvalidArgument { field: field.trim_start_matches("settings.").to_owned(), reason }
        }
        other => other,
    })?;
    let asked = asked(&req.robot_id, &req.scene_id, req.base, &req.attached, &req.link_padding);
    let Setting { robot, world, base, link_padding } = checks.setting(asked).await?;
    let path: Vec<Vec<sublevel_core::math::Real>> =
        cv::configurations_from_proto("path", req.path.as_ref(), &robot, &world.planning.joint_positions)?;
    let moving: Vec<bool> = (0..robot.model.dof()).map(|k| path.iter().any(|w| w[k] != path[0][k])).collect();
    let (timing, warnings) = cv::timing_request(&req.trajectory.clone().unwrap_or_default(), None, &robot, &moving)?;
    let scene_version = world.scene_version;
    let timed = robot.clone();
    let answer = checks
        .pools
        .plans
        .run_before(deadline, move || {
            let allowed = world.planning.allowed_override();
            let mut checker = RobotChecker::new(&timed, world.objects.clone(), &allowed)?;
            checker.set_link_padding(&link_padding)?;
            let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, base, settings.padding);
            validity.set_deadline(Some(deadline));
            if let Some((edge, certificate)) =
                sublevel_plan::trajectory::first_unproven_edge(&mut validity, &path, settings.tolerance)?
            {
                let why = match certificate {
                    sublevel_plan::Certificate::Contact(t) => {
                        let mut q = Vec::new();
                        validity.space().interpolate(&path[edge], &path[edge + 1], t, &mut q);
                        match validity.collision(&q)? {
                            Some(pair) => format!("{pair} at {t:.4} of the edge"),
                            None => format!(
                                "the robot comes within the contact tolerance ({} m) of a collision at {t:.4} of the edge",
                                settings.tolerance
                            ),
                        }
                    }
                    _ => "it could not be proven free before the deadline".to_owned(),
                };
                return Err(crate::Error::invalid(
                    "path",
                    format!("edge {edge} (waypoint {edge} to {}) is not free at padding {} m: {why}", edge + 1, settings.padding),
                ));
            }
            validity.set_deadline(None);
            sublevel_plan::trajectory::timed_trajectory(&mut validity, &path, &timing, settings.tolerance)
        })
        .await?
        .ok_or_else(|| {
            crate::Error::ResourceExhausted(format!(
                "no planning slot came free before the call's deadline: {} plans run at once (--max-concurrent-plans)",
                svc.config.max_concurrent_plans
            ))
        })?;
    Ok(Response::new(pb::TimeTrajectoryResponse {
        trajectory: Some(cv::trajectory_response(&answer, &robot, true)),
        warnings,
        scene_version,
    }))
}

/// The robot, scene, base, attached objects and link padding a plan or a timing names.
fn asked(
    robot_id: &str,
    scene_id: &str,
    base: Option<pb::Pose>,
    attached: &[pb::AttachedObject],
    link_padding: &std::collections::HashMap<String, sublevel_core::math::Real>,
) -> Asked {
    Asked {
        robot_id: robot_id.to_owned(),
        scene_id: scene_id.to_owned(),
        base,
        attached: attached.to_vec(),
        link_padding: link_padding.clone(),
        poses: Vec::new(),
    }
}
