//! `Plan`: a path for a robot among a scene in one call (docs/planning.md). The robot and the
//! scene are read as the robot checks read them ([`RobotChecks`]); the plan runs on one batch
//! slot, its deadline the request's timeout or the call's own deadline, whichever comes first,
//! and stops when the client goes away (the slot's cancel flag).

use super::robots::{Asked, RobotChecks, Setting};
use super::{Handled, SublevelService};
use crate::convert as cv;
use crate::pb;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};
use sublevel_plan::RobotValidity;
use sublevel_robot::{MotionChecker, RobotChecker};
use tonic::{Request, Response};

/// How much of the call's own deadline the plan leaves for answering.
const ANSWER_MARGIN: Duration = Duration::from_millis(20);

/// `Plan`: the request checked, then the plan on a batch slot.
pub(super) async fn plan(svc: &SublevelService, request: Request<pb::PlanRequest>) -> Handled<pb::PlanResponse> {
    let clock = Instant::now();
    let call_deadline = crate::deadline::parse_grpc_timeout(&request.metadata().clone().into_headers());
    let req = request.into_inner();
    let mut settings = cv::plan_settings(req.settings.as_ref())?;
    if let Some(left) = call_deadline {
        settings.timeout = settings.timeout.min(left.saturating_sub(ANSWER_MARGIN).max(Duration::from_millis(1)));
    }
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
    let (start, goal) = cv::plan_ends(&req, &robot, &world.planning.joint_positions)?;
    let scene_version = world.scene_version;
    let planned = robot.clone();
    let outcome = checks
        .pools
        .batch
        .run(move || {
            let allowed = world.planning.allowed_override();
            let mut checker = RobotChecker::new(&planned, world.objects.clone(), &allowed)?;
            checker.set_link_padding(&link_padding)?;
            let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, base, settings.padding);
            let cancel = sublevel_core::cancel::current().unwrap_or_else(|| Arc::new(AtomicBool::new(false)));
            sublevel_plan::plan(&mut validity, &start, &goal, &settings, &cancel)
        })
        .await?;
    let mut out = cv::plan_response(&outcome, &robot, clock.elapsed());
    out.scene_version = scene_version;
    Ok(Response::new(out))
}
