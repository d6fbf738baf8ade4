//! Request messages of the service as they arrive off the wire, through the public validators of
//! `sublevel::service::convert`. The first byte picks the message type (mod 6), the rest is its
//! protobuf encoding. Ok or Err, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use prost::Message;
use sublevel::service::convert as cv;
use sublevel::service::pb;

/// Limits as a server might configure them, small enough to keep an execution fast.
const MAX_POINTS: usize = 100_000;
const MAX_POSES: usize = 100_000;
const MAX_PAIRS: usize = 10_000;

fn start_fit_job(req: pb::StartFitJobRequest) {
    let degree = cv::fit_options(&req).map_or(8, |o| o.auto.map_or(o.degree, |(d, _)| *d.last().unwrap_or(&8)));
    let points = match &req.source {
        Some(pb::start_fit_job_request::Source::Points(cloud)) => cv::points_from_proto(cloud, MAX_POINTS),
        Some(pb::start_fit_job_request::Source::Mesh(mesh)) => {
            cv::mesh_format_from_proto(mesh).and_then(|format| sublevel::fit::mesh::parse_points_limited(&mesh.data, format, MAX_POINTS))
        }
        None => return,
    };
    if let Ok(points) = points {
        let _ = cv::check_cloud("points", &points, degree);
    }
}

fn upload_body(req: pb::UploadBodyRequest) {
    let file = match &req.body {
        Some(pb::upload_body_request::Body::BodyJson(json)) => {
            serde_json::from_str::<sublevel::body::BodyFile>(json).map_err(sublevel::Error::from)
        }
        Some(pb::upload_body_request::Body::Data(data)) => cv::body_file_from_proto(data),
        Some(pb::upload_body_request::Body::Primitive(p)) => {
            let _ = cv::primitive_from_proto(p, "primitive");
            return;
        }
        None => return,
    };
    if let Ok(file) = file {
        let _ = sublevel::Body::from_file(file);
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&which, bytes)) = data.split_first() else { return };
    match which % 6 {
        0 => {
            if let Ok(req) = pb::StartFitJobRequest::decode(bytes) {
                start_fit_job(req);
            }
        }
        1 => {
            if let Ok(req) = pb::UploadBodyRequest::decode(bytes) {
                upload_body(req);
            }
        }
        2 => {
            if let Ok(req) = pb::SetPosesRequest::decode(bytes) {
                let _ = cv::require_id("scene_id", &req.scene_id);
                let _ = cv::poses_from_proto(&req.poses, MAX_POSES);
            }
        }
        3 => {
            if let Ok(req) = pb::BatchQueryRequest::decode(bytes) {
                let _ = cv::require_id("scene_id", &req.scene_id);
                let _ = cv::pairs_from_proto(&req.pairs, MAX_PAIRS);
                if let Some(columns) = &req.columns {
                    let _ = cv::pair_columns_from_proto(columns, MAX_PAIRS);
                }
            }
        }
        5 => {
            if let Ok(req) = pb::QueryRequest::decode(bytes) {
                let _ = cv::planner_request_from_proto(&req, MAX_PAIRS, MAX_POSES);
            }
        }
        _ => {
            if let Ok(req) = pb::AddInstanceRequest::decode(bytes) {
                let _ = cv::require_id("scene_id", &req.scene_id);
                let _ = cv::require_id("body_id", &req.body_id);
                let _ = cv::pose_from_proto("pose", req.pose.as_ref());
            }
        }
    }
});
