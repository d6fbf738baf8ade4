//! Point clouds of scenes: `UpdatePointCloud`, `RemovePointCloud` (docs/point_clouds.md).
//!
//! ```text
//! check     the frame's fields and size against --max-frame-points, the bodies settings:
//!           on the async worker, before any point is decoded (microseconds)
//! wait      one unit per point of --max-frame-points-in-flight (a semaphore: frames past it
//!           wait, holding no thread; the call's deadline still applies)
//! build     decode, deproject, filter, k-d tree on tokio's blocking pool, holding no catalog
//!           lock (Catalog::build_point_cloud); the units are returned once the cloud is built
//! bodies    clusters (at most bodies.max_clusters) and fits, for the bodies model
//! store     the built cloud swapped into its scene under the scene's lock
//!           (Catalog::set_point_cloud)
//! ```
//!
//! The work runs in a cancellation scope ([`crate::runtime::cancellable_blocking_until`]) whose
//! flag is set when the client goes away (the handler's future is dropped) and just before the
//! call's deadline ([`crate::deadline::CallDeadline`]): the filters, the clustering and the fits
//! stop at their next check (a fit's solver at its next iteration), and the store, which looks
//! at the flag under the scene's lock, never stores an abandoned update.
//!
//! The prepared robot checkers ([`super::prepared`]) compare the scene version and the cloud set
//! they were built from at every use, so no check runs against a replaced cloud.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, require_id};
use crate::deadline::CallDeadline;
use crate::limits::CLOUD_BYTES;
use crate::pb;
use crate::runtime::{blocking, cancellable_blocking_until, past};
use crate::Error;
use std::time::{Duration, Instant};
use tonic::{Request, Response, Status};

/// How long before the call's deadline its work is cancelled: a cloud stored later than this
/// might land after the client was answered DEADLINE_EXCEEDED.
const STORE_MARGIN: Duration = Duration::from_millis(5);

/// `UpdatePointCloud`: the frame checked, its share of the decoding budget awaited, then turned
/// into a cloud off the async workers and swapped into its scene (module docs).
pub(super) async fn update_point_cloud(
    svc: &SublevelService,
    request: Request<pb::UpdatePointCloudRequest>,
) -> Handled<pb::UpdatePointCloudResponse> {
    let start = Instant::now();
    let deadline = request.extensions().get::<CallDeadline>().map(|d| d.0.checked_sub(STORE_MARGIN).unwrap_or(d.0));
    let req = request.into_inner();
    require_id("scene_id", &req.scene_id)?;
    let points = cv::frame_points(&req, svc.config.max_frame_points)?;
    let model = cv::cloud_model(&req)?;
    let budget = svc.cloud_frames.clone();
    let units = points.clamp(1, svc.config.max_frame_points_in_flight.max(1));
    let permit = budget
        .acquire_many_owned(u32::try_from(units).unwrap_or(u32::MAX))
        .await
        .map_err(|_| Status::unavailable("the server is shutting down"))?;
    let catalog = svc.catalog.clone();
    let max_bytes = svc.config.max_cloud_bytes;
    let work = cancellable_blocking_until(deadline, move || {
        // A bad name fails before the frame's work is spent (and is checked again at the swap).
        catalog.check_point_cloud_name(&req.scene_id, &req.name)?;
        let frame = cv::cloud_frame(&req)?;
        let pb::UpdatePointCloudRequest { scene_id, name, .. } = req;
        let mut built = catalog.build_point_cloud(&scene_id, &frame)?;
        drop(frame);
        drop(permit);
        if let Some(settings) = &model {
            catalog
                .build_cloud_bodies(&scene_id, &name, &mut built, settings)
                .map_err(|e| cv::prefix_field(e, "bodies"))?;
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
    });
    let (update, counts, report) = work.await.map_err(|status| match status.code() {
        tonic::Code::Cancelled if past(deadline) => Status::deadline_exceeded(format!(
            "UpdatePointCloud: the call's deadline passed before the cloud was stored; nothing was stored \
             ({:.0} ms spent)",
            start.elapsed().as_secs_f64() * 1e3
        )),
        _ => status,
    })?;
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
