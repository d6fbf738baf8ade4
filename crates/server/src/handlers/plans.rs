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
use sublevel_plan::{PlanOutcome, RobotValidity};
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
    if let Some(left) = call_deadline {
        settings.timeout = settings.timeout.min(left.saturating_sub(ANSWER_MARGIN).max(LEAST_PLAN_TIME));
    }
    let deadline = clock + settings.timeout;
    let checks = RobotChecks::of(svc);
    let asked = Asked {
        robot_id: req.robot_id.clone(),
        scene_id: req.scene_id.clone(),
        base: req.base,
        attached: req.attached.clone(),
        link_padding: req.link_padding.clone(),
        poses: Vec::new(),
    };
    let Setting { robot, world, base, link_padding } = checks.setting(asked).await?;
    let cv::PlanEnds { start, goal, warnings, moving } = cv::plan_ends(&req, &robot, &world.planning.joint_positions)?;
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
            sublevel_plan::plan(&mut validity, &start, &goal, &settings, &cancel).map(Some)
        })
        .await?
        .flatten();
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
    out.planning_joints =
        robot.model.variable_names().iter().zip(&moving).filter(|(_, m)| **m).map(|(n, _)| (*n).to_owned()).collect();
    if !out.path.is_empty() {
        out.check_tolerance = sublevel_plan::certificate_tolerance(settings.tolerance);
    }
    Ok(Response::new(out))
}
