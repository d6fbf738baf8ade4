//! Every conversion between proto messages and core types, the request validation that goes with
//! them, and the crate's single `Error → tonic::Status` mapping.
//!
//! | [`Error`]            | gRPC code            |
//! |----------------------|----------------------|
//! | `InvalidArgument`    | INVALID_ARGUMENT, with a `google.rpc.BadRequest` field violation |
//! | `NotFound`           | NOT_FOUND            |
//! | `ResourceExhausted`  | RESOURCE_EXHAUSTED   |
//! | `FailedPrecondition` | FAILED_PRECONDITION  |
//! | `Numerical`          | INTERNAL             |
//! | `Storage`, `Io`      | UNAVAILABLE          |
//! | `Json`               | INVALID_ARGUMENT (only request JSON is parsed in handlers) |
//!
//! Field names in messages use the request's vocabulary with indices, e.g.
//! `poses[3].pose.rotation` or `data.coefficients`.

//! The conversions live in one file per area, all re-exported here:
//!
//! | file            | area                                                                          |
//! |-----------------|-------------------------------------------------------------------------------|
//! | `errors.rs`     | `Error → Status` (google.rpc BadRequest details), field labels                |
//! | `bodies.rs`     | fit options, point clouds and their checks, reports, body files               |
//! | `primitives.rs` | exact primitives (box, sphere, cylinder, capsule, halfspace)                  |
//! | `scenes.rs`     | points, vectors, poses, instances, scenes, `SetPoses` entries, MoveIt imports |
//! | `clouds.rs`     | point-cloud frames (PointCloud2 bytes, depth images), filters, counts         |
//! | `queries.rs`    | answers, certificates, gradients, query options, batch pairs                  |
//! | `planner.rs`    | pair / answer columns, planner requests and answers, scene checks             |
//! | `robots.rs`     | robot summaries, configuration columns, configuration and motion answers      |
//! | `motions.rs`    | rigid-body motions of scene instances: pose columns, options, answer columns  |
//! | `plans.rs`      | `Plan`: settings, the start and the goal (typed or MoveIt text), the answer   |
//!
//! Ids and pages, shared by every area, are here.

use crate::{Error, Result};

mod bodies;
mod clouds;
mod errors;
mod motions;
mod planner;
mod plans;
mod primitives;
#[cfg(test)]
mod properties;
mod queries;
mod robots;
mod scenes;

pub use bodies::{
    admit_compound, body_file_from_proto, body_file_to_proto, body_summary, check_cloud, check_point_count,
    compound_settings, fit_degree, fit_method_from_proto, fit_options, fit_stage_to_proto, mesh_format_from_proto,
    min_thickness, part_count, points_from_proto, report_from_proto, report_to_proto, sdp_status_to_proto,
    uploaded_report, FitOptions, MAX_COMPOUND_NODES,
};
pub use clouds::{
    bodies_report_to_proto, cloud_filter, cloud_frame, cloud_model, cloud_summary, depth_points,
    filter_counts_to_proto, frame_points, packed_points, DEFAULT_DEPTH_SCALE,
};
pub use errors::{prefix_field, to_status};
pub use motions::{instance_motions_from_proto, instance_motions_to_proto, InstanceMotions};
pub use planner::{
    answers_to_columns, columns_kind, pair_columns_from_proto, planner_answers_to_proto, planner_request_from_proto,
    scene_check_to_proto, ColumnsSink, PairColumns,
};
pub use plans::{
    plan_ends, plan_response, plan_settings, timing_request, trajectory_request, trajectory_response, PlanEnds,
};
pub use primitives::{primitive_from_proto, primitive_to_proto};
pub use queries::{
    answer_to_proto, certificate_to_proto, distance_reply_to_proto, distance_to_proto, gradient_to_proto,
    growth_reply_to_proto, growth_to_proto, pairs_from_proto, query_options, source_to_proto, status_to_proto,
    tree_to_proto, tree_tolerance,
};
pub use robots::{
    attached_record_from_proto, configuration_rows, configurations_from_proto, fidelity, motion_options,
    motion_samples, padding, push_configuration_answers, push_motion_answers, resolution, robot_summary,
    scene_robot_to_proto, MAX_CONFIGURATIONS_PER_CALL, MAX_SAMPLES_PER_MOTION,
};
pub use scenes::{
    import_mesh_settings, imported_scene_to_proto, instance_to_proto, planned_mesh_to_fit, planning_scene_from_proto,
    point_to_proto, pose_from_proto, pose_to_proto, poses_from_proto, scene_to_proto, vector_to_proto,
};

/// Longest accepted id, in bytes (ids the server makes are 18 bytes, e.g. `b-3f29c0d1a4e5b6c7`).
pub const MAX_ID_BYTES: usize = 128;

/// Rejects an empty or over-long id (an over-long one is never echoed back whole).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field`.
pub fn require_id<'a>(field: &str, id: &'a str) -> Result<&'a str> {
    if id.is_empty() {
        return Err(Error::invalid(field, "must not be empty"));
    }
    if id.len() > MAX_ID_BYTES {
        return Err(Error::invalid(
            field,
            format!("{} bytes, at most {MAX_ID_BYTES} (starts `{}`)", id.len(), sublevel_core::error::clip(id)),
        ));
    }
    Ok(id)
}

/// Default and largest page of a List call.
pub const MAX_PAGE_SIZE: usize = 1000;

/// One page of `items` (ordered by id): those after `page_token` (the last id of the previous
/// page; empty: from the start), at most `page_size` (0: [`MAX_PAGE_SIZE`]; capped there), and
/// the token of the next page (empty after the last). The list's ids are `{prefix}-` and 16
/// lowercase hex digits (`b` bodies, `s` scenes, `j` jobs), and so is every token it hands out.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `page_token` when it is not an id of this list's form (a
/// forged or mistyped token would otherwise give a wrong page silently).
pub fn page<T>(
    items: Vec<T>,
    id: impl Fn(&T) -> &str,
    prefix: &str,
    page_size: u32,
    page_token: &str,
) -> Result<(Vec<T>, String)> {
    let well_formed = page_token
        .strip_prefix(prefix)
        .and_then(|t| t.strip_prefix('-'))
        .is_some_and(|h| h.len() == 16 && h.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)));
    if !(page_token.is_empty() || well_formed) {
        return Err(Error::invalid(
            "page_token",
            format!(
                "not a `next_page_token` of this list (`{prefix}-` and 16 hex digits), got `{}`",
                sublevel_core::error::clip(page_token)
            ),
        ));
    }
    let size = match page_size as usize {
        0 => MAX_PAGE_SIZE,
        n => n.min(MAX_PAGE_SIZE),
    };
    let mut page: Vec<T> = items.into_iter().filter(|t| page_token.is_empty() || id(t) > page_token).collect();
    let more = page.len() > size;
    page.truncate(size);
    let next = if more { page.last().map(|t| id(t).to_owned()).unwrap_or_default() } else { String::new() };
    Ok((page, next))
}
