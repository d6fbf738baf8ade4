//! `CheckInstanceMotions`: rigid-body motions of scene instances certified by conservative
//! advancement ([`sublevel_scene::planner::MotionScene`]).
//!
//! The scene is read once (every instance's body and pose, one moment), every moving instance is
//! resolved before any motion runs (so a bad id fails the request at once), then the motions run
//! in balanced chunks on the batch slots, as `CheckMotions` does.

use super::robots::{chunks, RobotChecks};
use super::{Handled, HandlerError, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::pb;
use crate::runtime::blocking;
use crate::Result;
use futures_util::future::try_join_all;
use std::sync::Arc;
use sublevel_core::math::Isometry3;
use sublevel_scene::planner::MotionScene;
use tonic::{Request, Response};

/// `CheckInstanceMotions`: validate the columns, read the scene, check the motions in chunks on
/// the batch slots, answer in columns.
pub(super) async fn check_instance_motions(
    svc: &SublevelService,
    request: Request<pb::CheckInstanceMotionsRequest>,
) -> Handled<pb::CheckInstanceMotionsResponse> {
    let out = instance_motions(&RobotChecks::of(svc), request.into_inner(), Vec::new()).await?;
    Ok(Response::new(out))
}

/// Answers a `CheckInstanceMotions` request with the scene's instances in `poses` (instance id →
/// pose, a planner stream's view) moved there.
pub(super) async fn instance_motions(
    on: &RobotChecks,
    req: pb::CheckInstanceMotionsRequest,
    poses: Vec<(String, Isometry3)>,
) -> Result<pb::CheckInstanceMotionsResponse, HandlerError> {
    let scene_id = require_id("scene_id", &req.scene_id)?.to_owned();
    let motions = Arc::new(cv::instance_motions_from_proto(&req)?);
    let catalog = on.catalog.clone();
    let read = move || MotionScene::read_at(&catalog, &scene_id, &poses);
    let scene = Arc::new(if on.in_memory() { read()? } else { blocking(move || Ok(read())).await?? });
    let moving: Arc<[_]> = motions
        .instance_ids
        .iter()
        .enumerate()
        .map(|(m, id)| scene.moving(&format!("instance_ids[{m}]"), id))
        .collect::<Result<_>>()?;
    let work = chunks(moving.len(), on.slots).into_iter().map(|range| {
        let (scene, motions, moving) = (scene.clone(), motions.clone(), moving.clone());
        on.pools.batch.run(move || {
            Ok(range
                .map(|m| {
                    let (start, end) = &motions.poses[m];
                    scene.check_motion(&moving[m], start, end, &motions.options)
                })
                .collect::<Result<Vec<_>>>())
        })
    });
    let answers = try_join_all(work).await?.into_iter().collect::<Result<Vec<_>>>()?;
    Ok(cv::instance_motions_to_proto(answers.iter().flatten()))
}
