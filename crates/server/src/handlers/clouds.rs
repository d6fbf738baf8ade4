//! Point clouds of scenes: `UpdatePointCloud`, `RemovePointCloud` (docs/point_clouds.md).
//!
//! A frame is decoded, deprojected, filtered and put in its k-d tree on tokio's blocking pool,
//! holding no catalog lock ([`sublevel_scene::Catalog::build_point_cloud`]); only the swap of the
//! built cloud into its scene takes the scene's lock ([`sublevel_scene::Catalog::set_point_cloud`]).
//! The prepared robot checkers ([`super::prepared`]) compare the scene version and the cloud set
//! they were built from at every use, so no check runs against a replaced cloud.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::limits::CLOUD_BYTES;
use crate::pb;
use crate::runtime::blocking;
use crate::Error;
use std::time::Instant;
use tonic::{Request, Response};

/// `UpdatePointCloud`: the frame turned into a cloud off the async workers, then swapped into its
/// scene.
pub(super) async fn update_point_cloud(
    svc: &SublevelService,
    request: Request<pb::UpdatePointCloudRequest>,
) -> Handled<pb::UpdatePointCloudResponse> {
    let start = Instant::now();
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let catalog = svc.catalog.clone();
    let max_bytes = svc.config.max_cloud_bytes;
    let (update, counts, report) = blocking(move || {
        // A bad name fails before the frame's work is spent (and is checked again at the swap).
        catalog.check_point_cloud_name(&req.scene_id, &req.name)?;
        let frame = cv::cloud_frame(&req)?;
        let model = cv::cloud_model(&req)?;
        let pb::UpdatePointCloudRequest { scene_id, name, .. } = req;
        let mut built = catalog.build_point_cloud(&scene_id, &frame)?;
        drop(frame);
        if let Some(settings) = &model {
            catalog.build_cloud_bodies(&scene_id, &name, &mut built, settings)?;
        }
        let counts = built.counts;
        let report = built.bodies.as_ref().map(|b| cv::bodies_report_to_proto(&b.report));
        let update = catalog.set_point_cloud(&scene_id, &name, built, max_bytes).map_err(|e| match e {
            Error::ResourceExhausted(m) if m.starts_with("point-cloud memory") => {
                Error::ResourceExhausted(format!("{m} (set by {} / {})", CLOUD_BYTES.flag, CLOUD_BYTES.env))
            }
            other => other,
        })?;
        Ok((update, counts, report))
    })
    .await?;
    Ok(Response::new(pb::UpdatePointCloudResponse {
        scene_version: update.scene_version,
        counts: Some(cv::filter_counts_to_proto(&counts)),
        memory_bytes: update.memory_bytes as u64,
        seconds: start.elapsed().as_secs_f64(),
        bodies: report,
    }))
}

/// `RemovePointCloud`: drops a cloud of a scene.
pub(super) async fn remove_point_cloud(
    svc: &SublevelService,
    request: Request<pb::RemovePointCloudRequest>,
) -> Handled<pb::RemovePointCloudResponse> {
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let catalog = svc.catalog.clone();
    let scene_version = blocking(move || catalog.remove_point_cloud(&req.scene_id, &req.name)).await?;
    Ok(Response::new(pb::RemovePointCloudResponse { scene_version }))
}
