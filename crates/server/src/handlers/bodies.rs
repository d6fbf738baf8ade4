//! Bodies: `UploadBody`, `GetBody`, `ListBodies`, `DeleteBody`.

use super::{Handled, SublevelService};
use crate::convert::{self as cv, prefix_field, require_id};
use crate::limits::{self, check_room};
use crate::pb;
use crate::runtime::blocking;
use crate::Error;
use sublevel_core::body::BodyFile;
use sublevel_fit::sos_convexity::admit_uploaded;
use tonic::{Request, Response};

/// An `UploadBody` request's body, parsed: a single body file (with the field it came from) or a
/// compound body file.
enum Upload {
    Single(Box<BodyFile>, &'static str),
    // Boxed as `Single`'s file is: a compound file's report is several hundred bytes.
    Compound(Box<sublevel_fit::compound::CompoundFile>),
    /// An exact primitive, validated: stored as it is (no certificate to solve).
    Primitive(sublevel_core::primitive::Primitive),
}

/// `UploadBody`: parses a single or compound body file, admits it (its sos-convexity certificate,
/// an SDP per node, off the async workers) and stores it; or validates and stores an exact
/// primitive (no certificate).
pub(super) async fn upload_body(
    svc: &SublevelService,
    request: Request<pb::UploadBodyRequest>,
) -> Handled<pb::UploadBodyResponse> {
    let req = request.into_inner();
    let upload = match req.body {
        None => return Err(Error::invalid("body", "set `body_json`, `data` or `primitive`").into()),
        Some(pb::upload_body_request::Body::Primitive(p)) => {
            Upload::Primitive(cv::primitive_from_proto(&p, "primitive")?)
        }
        Some(pb::upload_body_request::Body::BodyJson(text)) => {
            let value: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| Error::invalid("body_json", e.to_string()))?;
            if sublevel_fit::compound::file::is_compound_json(&value) {
                // A compound body: a containment tree of bodies. The node limit first, before the
                // nodes are converted (300 000 nodes took seconds).
                let count = value["nodes"].as_array().map_or(0, Vec::len);
                if count > cv::MAX_COMPOUND_NODES {
                    return Err(Error::invalid(
                        "body_json.nodes",
                        format!("{count} nodes exceed the limit of {} per compound body", cv::MAX_COMPOUND_NODES),
                    )
                    .into());
                }
                let file: sublevel_fit::compound::CompoundFile =
                    serde_json::from_value(value).map_err(|e| Error::invalid("body_json", e.to_string()))?;
                Upload::Compound(Box::new(file))
            } else {
                let mut file: BodyFile =
                    serde_json::from_value(value).map_err(|e| Error::invalid("body_json", e.to_string()))?;
                if file.report.method.is_empty() {
                    file.report = cv::uploaded_report();
                }
                Upload::Single(Box::new(file), "body_json")
            }
        }
        Some(pb::upload_body_request::Body::Data(data)) => {
            Upload::Single(Box::new(cv::body_file_from_proto(&data)?), "data")
        }
    };
    if req.name.len() > sublevel_scene::MAX_NAME_BYTES {
        return Err(Error::invalid("name", format!("at most {} bytes", sublevel_scene::MAX_NAME_BYTES)).into());
    }
    check_room(limits::BODIES, svc.catalog.bodies().len(), svc.config.max_bodies)?;
    let catalog = svc.catalog.clone();
    // The sos-convexity certificate is an SDP (one per node of a compound body): off the
    // async workers, like the store write.
    let (body_id, nonconvex, margin, nodes) = blocking(move || match upload {
        Upload::Single(file, prefix) => {
            let admitted = admit_uploaded(*file).map_err(|e| prefix_field(e, prefix))?;
            let nonconvex = admitted.body.report.nonconvex;
            let margin = admitted.certificate.as_ref().map_or(f64::NAN, |c| c.margin);
            let id = catalog.add_body(&req.name, admitted.body)?;
            Ok((id, nonconvex, margin, 1))
        }
        Upload::Compound(file) => {
            let (tree, margin) = cv::admit_compound(*file, "body_json")?;
            let nodes = tree.node_count();
            let id = catalog.add_compound_body(&req.name, tree)?;
            Ok((id, false, margin, nodes))
        }
        Upload::Primitive(p) => Ok((catalog.add_primitive(&req.name, p)?, false, f64::NAN, 1)),
    })
    .await?;
    let nodes = u32::try_from(nodes).unwrap_or(u32::MAX);
    Ok(Response::new(pb::UploadBodyResponse { body_id, nonconvex, convexity_margin: margin, nodes }))
}

/// `GetBody`: a stored body with its body file (and compound file), or a primitive with its
/// primitive file.
pub(super) async fn get_body(
    svc: &SublevelService,
    request: Request<pb::GetBodyRequest>,
) -> Handled<pb::GetBodyResponse> {
    let req = request.into_inner();
    let entry = svc.catalog.body(require_id("body_id", &req.body_id)?)?;
    let built = entry.built()?;
    if let Some(p) = &built.primitive {
        return Ok(Response::new(pb::GetBodyResponse {
            body_id: entry.id.clone(),
            name: entry.name.clone(),
            data: None,
            body_json: serde_json::to_string(&p.to_file()).map_err(Error::from)?,
            nodes: 1,
            primitive: Some(cv::primitive_to_proto(p)),
            mesh_vertices: 0,
            mesh_triangles: 0,
        }));
    }
    let file = built.body.to_file();
    let body_json = match &built.tree {
        Some(tree) => serde_json::to_string(&tree.to_file()),
        None => serde_json::to_string(&file),
    }
    .map_err(Error::from)?;
    Ok(Response::new(pb::GetBodyResponse {
        body_id: entry.id.clone(),
        name: entry.name.clone(),
        data: Some(cv::body_file_to_proto(&file)),
        body_json,
        nodes: u32::try_from(entry.node_count()).unwrap_or(u32::MAX),
        primitive: None,
        mesh_vertices: count(entry.mesh().map_or(0, |m| m.vertices.len())),
        mesh_triangles: count(entry.mesh().map_or(0, |m| m.triangles.len())),
    }))
}

fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// `ListBodies`: a page of the bodies, by id.
pub(super) async fn list_bodies(
    svc: &SublevelService,
    request: Request<pb::ListBodiesRequest>,
) -> Handled<pb::ListBodiesResponse> {
    let req = request.into_inner();
    let (page, next_page_token) =
        cv::page(svc.catalog.bodies(), |e| e.id.as_str(), "b", req.page_size, &req.page_token)?;
    let bodies = page.iter().map(|e| cv::body_summary(e)).collect();
    Ok(Response::new(pb::ListBodiesResponse { bodies, next_page_token }))
}

/// `DeleteBody`: deletes a body no instance uses.
pub(super) async fn delete_body(
    svc: &SublevelService,
    request: Request<pb::DeleteBodyRequest>,
) -> Handled<pb::DeleteBodyResponse> {
    let id = request.into_inner().body_id;
    require_id("body_id", &id)?;
    let catalog = svc.catalog.clone();
    blocking(move || catalog.delete_body(&id)).await?;
    Ok(Response::new(pb::DeleteBodyResponse {}))
}
