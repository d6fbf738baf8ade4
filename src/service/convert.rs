//! Every conversion between proto messages and core types, the request validation that goes with
//! them, and the crate's single `Error → tonic::Status` mapping.
//!
//! | [`Error`]            | gRPC code            |
//! |----------------------|----------------------|
//! | `InvalidArgument`    | INVALID_ARGUMENT     |
//! | `NotFound`           | NOT_FOUND            |
//! | `ResourceExhausted`  | RESOURCE_EXHAUSTED   |
//! | `FailedPrecondition` | FAILED_PRECONDITION  |
//! | `Numerical`          | INTERNAL             |
//! | `Storage`, `Io`      | UNAVAILABLE          |
//! | `Json`               | INVALID_ARGUMENT (only request JSON is parsed in handlers) |
//!
//! Field names in messages use the request's vocabulary with indices, e.g.
//! `poses[3].pose.rotation` or `data.coefficients`.

use super::pb;
use crate::body::{BodyFile, FitReport, SUPPORTED_DEGREES};
use crate::fit::FitStage;
use crate::math::{pose_from_parts, pose_to_parts, Isometry3, Point3, Real, Vector3};
use crate::query::{
    AnswerSource, CertificateSummary, CertifyMode, DistanceResult, GrowthResult, PoseGradient, SolveStatus,
};
use crate::scene::{
    BodyEntry, DistanceReply, GrowthReply, InstanceView, QueryAnswer, QueryKind, QueryOptions, SceneView,
};
use crate::{Error, Result};
use tonic::{Code, Status};

impl From<Error> for Status {
    fn from(e: Error) -> Self {
        let code = match &e {
            Error::InvalidArgument { .. } | Error::Json(_) => Code::InvalidArgument,
            Error::NotFound { .. } => Code::NotFound,
            Error::ResourceExhausted(_) => Code::ResourceExhausted,
            Error::FailedPrecondition(_) => Code::FailedPrecondition,
            Error::Numerical(_) => Code::Internal,
            Error::Storage(_) | Error::Io(_) => Code::Unavailable,
        };
        Status::new(code, e.to_string())
    }
}

/// Re-labels an [`Error::InvalidArgument`]'s field as `prefix.field` (other errors unchanged), so
/// errors of core validation name the field as the client sent it.
pub fn prefix_field(e: Error, prefix: &str) -> Error {
    match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: format!("{prefix}.{field}"), reason }
        }
        other => other,
    }
}

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
            format!("{} bytes, at most {MAX_ID_BYTES} (starts `{}`)", id.len(), crate::error::clip(id)),
        ));
    }
    Ok(id)
}

// ---------------------------------------------------------------------------------------------
// Geometry
// ---------------------------------------------------------------------------------------------

/// Default and largest page of a List call.
pub const MAX_PAGE_SIZE: usize = 1000;

/// One page of `items` (ordered by id): those after `page_token` (the last id of the previous
/// page; empty: from the start), at most `page_size` (0: [`MAX_PAGE_SIZE`]; capped there), and
/// the token of the next page (empty after the last).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `page_token` when it is longer than an id can be.
pub fn page<T>(items: Vec<T>, id: impl Fn(&T) -> &str, page_size: u32, page_token: &str) -> Result<(Vec<T>, String)> {
    if page_token.len() > MAX_ID_BYTES {
        return Err(Error::invalid("page_token", format!("at most {MAX_ID_BYTES} bytes (a `next_page_token`)")));
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

/// A core point as a proto point.
pub fn point_to_proto(p: &Point3) -> pb::Vec3 {
    pb::Vec3 { x: p.x, y: p.y, z: p.z }
}

/// A core vector as a proto vector.
pub fn vector_to_proto(v: &Vector3) -> pb::Vec3 {
    pb::Vec3 { x: v.x, y: v.y, z: v.z }
}

/// A validated pose; `field` names the pose (e.g. `poses[3].pose`). An absent pose, rotation or
/// translation means identity / zero.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field.translation` for a non-finite translation or
/// `field.rotation` for a non-finite or non-unit quaternion.
pub fn pose_from_proto(field: &str, pose: Option<&pb::Pose>) -> Result<Isometry3> {
    let Some(pose) = pose else { return Ok(Isometry3::identity()) };
    // Field names are built only on error (this runs once per pose of every planner step).
    let t = pose.translation.as_ref().map_or([0.0; 3], |t| [t.x, t.y, t.z]);
    if t.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(format!("{field}.translation"), "must be three finite numbers (meters)"));
    }
    crate::math::check_coordinates("translation", &t).map_err(|e| prefix_field(e, field))?;
    let q = pose.rotation.as_ref().map_or([1.0, 0.0, 0.0, 0.0], |q| [q.w, q.x, q.y, q.z]);
    pose_from_parts("rotation", q, t).map_err(|e| prefix_field(e, field))
}

/// A pose as a proto pose.
pub fn pose_to_proto(pose: &Isometry3) -> pb::Pose {
    let (q, t) = pose_to_parts(pose);
    pb::Pose {
        rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
        translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
    }
}

// ---------------------------------------------------------------------------------------------
// Bodies and fits
// ---------------------------------------------------------------------------------------------

/// Checks a requested fit degree.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `degree` unless it is 2, 4, 6 or 8.
pub fn fit_degree(degree: u32) -> Result<usize> {
    let d = degree as usize;
    if !SUPPORTED_DEGREES.contains(&d) {
        return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {degree}")));
    }
    Ok(d)
}

/// The fit options of a `StartFitJobRequest` (everything but the points and the name).
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Total degree 2d (with `auto`: the lowest candidate).
    pub degree: usize,
    /// Formulation.
    pub method: crate::fit::FitMethod,
    /// Relaxed-convexity parameter c ≥ 0 (eq. "VAG.param.convex").
    pub convexity_relaxation: Real,
    /// With `auto_degree`: the candidate degrees and the relative volume tolerance.
    pub auto: Option<(Vec<usize>, Real)>,
}

/// Validates the fit options of a request: `degree` (2, 4, 6, 8; with `auto_degree` 0 or one of
/// them, the highest candidate), `method` (empty means logdet_p), `convexity_relaxation` (finite,
/// ≥ 0) and `volume_tolerance` (finite, in [0, 1); 0 means 0.05 with `auto_degree`).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `degree`, `method`, `convexity_relaxation` or
/// `volume_tolerance`.
pub fn fit_options(req: &pb::StartFitJobRequest) -> Result<FitOptions> {
    let method = if req.method.trim().is_empty() {
        crate::fit::FitMethod::LogDetP
    } else {
        req.method.trim().parse::<crate::fit::FitMethod>()?
    };
    let c = req.convexity_relaxation;
    if !(c.is_finite() && c >= 0.0) {
        return Err(Error::invalid("convexity_relaxation", format!("must be finite and >= 0, got {c}")));
    }
    let tol = req.volume_tolerance;
    if !(tol.is_finite() && (0.0..1.0).contains(&tol)) {
        return Err(Error::invalid("volume_tolerance", format!("must be in [0, 1), got {tol}")));
    }
    if !req.auto_degree {
        return Ok(FitOptions { degree: fit_degree(req.degree)?, method, convexity_relaxation: c, auto: None });
    }
    let top = if req.degree == 0 { 8 } else { fit_degree(req.degree)? };
    let degrees: Vec<usize> = SUPPORTED_DEGREES.iter().copied().filter(|d| *d <= top).collect();
    let tol = if req.volume_tolerance == 0.0 { 0.05 } else { req.volume_tolerance };
    crate::fit::auto::validate_auto(&degrees, tol)?;
    Ok(FitOptions { degree: degrees[0], method, convexity_relaxation: c, auto: Some((degrees, tol)) })
}

/// Unpacks a point cloud `x0, y0, z0, x1, …`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points.xyz` for a length that is not a multiple of 3 or a
/// non-finite coordinate or one beyond [`crate::math::MAX_COORDINATE`]; [`Error::ResourceExhausted`] above `max_points` points.
pub fn points_from_proto(cloud: &pb::PointCloud, max_points: usize) -> Result<Vec<Point3>> {
    let xyz = &cloud.xyz;
    if !xyz.len().is_multiple_of(3) {
        return Err(Error::invalid("points.xyz", format!("length {} is not a multiple of 3", xyz.len())));
    }
    check_point_count("points.xyz", xyz.len() / 3, max_points)?;
    if let Some(i) = xyz.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid("points.xyz", format!("coordinate {i} is not finite")));
    }
    crate::math::check_coordinates("points.xyz", xyz)?;
    Ok(xyz.chunks_exact(3).map(|c| Point3::new(c[0], c[1], c[2])).collect())
}

/// Fails with [`Error::ResourceExhausted`] naming `field` when `n > max_points`.
///
/// # Errors
/// As described.
pub fn check_point_count(field: &str, n: usize, max_points: usize) -> Result<()> {
    if n > max_points {
        return Err(Error::ResourceExhausted(format!(
            "`{field}`: {n} points exceed the limit of {max_points} per fit"
        )));
    }
    Ok(())
}

/// Smallest accepted ratio of a cloud's thinnest to its longest principal extent (square root of
/// the covariance eigenvalue ratio) for a fit of degree `degree`.
///
/// Measured on this project's machine (300 points, uniform in a box of sides 1 × ε × ε or
/// 1 × 1 × ε): at 2d ≥ 4 Clarabel ends `NumericalError` / `InsufficientProgress` at ε = 1e-3 and
/// solves at ε = 3e-3; at 2d = 2 it fails at ε = 1e-5 and solves at 1e-4. The limits leave a
/// factor of ~1.5–2 of margin.
pub fn min_thickness(degree: usize) -> Real {
    if degree <= 2 {
        5e-5
    } else {
        2e-3
    }
}

/// Checks that a cloud can enclose a body with interior: at least 4 finite points within
/// ±[`crate::math::MAX_COORDINATE`], not all on one plane or line (the smallest eigenvalue of
/// their covariance is not negligible), and not thinner than [`min_thickness`] of `degree`
/// (the highest degree the fit will try).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field`.
pub fn check_cloud(field: &str, points: &[Point3], degree: usize) -> Result<()> {
    if points.len() < 4 {
        return Err(Error::invalid(field, format!("need at least 4 points, got {}", points.len())));
    }
    if points.iter().any(|p| !p.coords.iter().all(|v| v.is_finite())) {
        return Err(Error::invalid(field, "every coordinate must be finite"));
    }
    for (k, p) in points.iter().enumerate() {
        crate::math::check_coordinates(&format!("{field}[{k}]"), p.coords.as_slice())?;
    }
    let n = points.len() as Real;
    let mean = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = points.iter().fold(crate::math::Matrix3::zeros(), |a, p| {
        let d = p.coords - mean;
        a + d * d.transpose()
    }) / n;
    let eig = cov.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if hi.is_nan() || hi <= 0.0 || lo <= 1e-12 * hi {
        return Err(Error::invalid(
            field,
            format!("degenerate cloud: the points lie on a plane, a line or one point (covariance eigenvalues {lo:.3e} … {hi:.3e})"),
        ));
    }
    let thickness = (lo / hi).sqrt();
    let min = min_thickness(degree);
    if thickness < min {
        return Err(Error::invalid(
            field,
            format!(
                "degenerate cloud for a degree-{degree} fit: its thinnest principal extent is {thickness:.1e} of its \
                 longest, below {min:.0e} (a needle or a nearly flat sheet; the SDP is numerically unreliable there; \
                 thicken the cloud{})",
                if degree > 2 { " or fit degree 2" } else { "" }
            ),
        ));
    }
    Ok(())
}

/// A core fit stage as the proto enum.
pub fn fit_stage_to_proto(stage: FitStage) -> pb::FitStage {
    match stage {
        FitStage::Hull => pb::FitStage::Hull,
        FitStage::Build => pb::FitStage::Build,
        FitStage::Solve => pb::FitStage::Solve,
        FitStage::Verify => pb::FitStage::Verify,
        FitStage::Volume => pb::FitStage::Volume,
        FitStage::Done => pb::FitStage::Done,
    }
}

/// A fit report as the proto message.
pub fn report_to_proto(r: &FitReport) -> pb::FitReport {
    pb::FitReport {
        method: r.method.clone(),
        solver_status: r.solver_status.to_string(),
        solve_seconds: r.solve_seconds,
        total_seconds: r.total_seconds,
        num_points: r.num_points as u64,
        num_hull_vertices: r.num_hull_vertices as u64,
        volume: r.volume,
        volume_std_error: r.volume_std_error,
        hull_volume: r.hull_volume,
        max_point_value: r.max_point_value,
        containment_rescale: r.containment_rescale,
        convexity_margin: r.convexity_margin,
        notes: r.notes.clone(),
        convexity_relaxation: r.convexity_relaxation,
        nonconvex: r.nonconvex,
        degree_choice: r.degree_choice.as_ref().map(|c| pb::DegreeChoice {
            volume_tolerance: c.volume_tolerance,
            degrees: c.candidates.iter().map(|k| k.0 as u32).collect(),
            volumes: c.candidates.iter().map(|k| k.1).collect(),
            volume_std_errors: c.candidates.iter().map(|k| k.2).collect(),
            chosen: c.chosen as u32,
            reason: c.reason.clone(),
        }),
        solver_certificate: r.solver_certificate.map(|c| pb::SolverCertificate {
            primal_objective: c.primal_objective,
            dual_objective: c.dual_objective,
            primal_residual: c.primal_residual,
            dual_residual: c.dual_residual,
        }),
        candidate_volumes: r
            .candidate_volumes
            .iter()
            .map(|(name, volume)| pb::CandidateVolume { name: name.clone(), volume: *volume })
            .collect(),
    }
}

/// A proto fit report as the core one.
pub fn report_from_proto(r: &pb::FitReport) -> FitReport {
    FitReport {
        method: r.method.clone(),
        solver_status: crate::conic::SdpStatus::parse(&r.solver_status),
        solve_seconds: r.solve_seconds,
        total_seconds: r.total_seconds,
        num_points: r.num_points as usize,
        num_hull_vertices: r.num_hull_vertices as usize,
        volume: r.volume,
        volume_std_error: r.volume_std_error,
        hull_volume: r.hull_volume,
        max_point_value: r.max_point_value,
        containment_rescale: r.containment_rescale,
        convexity_margin: r.convexity_margin,
        notes: r.notes.clone(),
        convexity_relaxation: r.convexity_relaxation,
        nonconvex: r.nonconvex,
        degree_choice: r.degree_choice.as_ref().map(|c| crate::body::DegreeChoice {
            volume_tolerance: c.volume_tolerance,
            candidates: c
                .degrees
                .iter()
                .zip(&c.volumes)
                .zip(&c.volume_std_errors)
                .map(|((&d, &v), &e)| (d as usize, v, e))
                .collect(),
            chosen: c.chosen as usize,
            reason: c.reason.clone(),
        }),
        solver_certificate: r.solver_certificate.as_ref().map(|c| crate::body::SolverCertificate {
            primal_objective: c.primal_objective,
            dual_objective: c.dual_objective,
            primal_residual: c.primal_residual,
            dual_residual: c.dual_residual,
        }),
        candidate_volumes: r.candidate_volumes.iter().map(|c| (c.name.clone(), c.volume)).collect(),
    }
}

/// A body file as structured proto fields.
pub fn body_file_to_proto(f: &BodyFile) -> pb::BodyData {
    pb::BodyData {
        degree: f.degree as u32,
        exponents: f.exponents.iter().flat_map(|e| e.iter().map(|&v| u32::from(v))).collect(),
        coefficients: f.coefficients.clone(),
        center: Some(pb::Vec3 { x: f.center[0], y: f.center[1], z: f.center[2] }),
        scale: f.scale,
        report: Some(report_to_proto(&f.report)),
    }
}

/// Structured proto fields as a body file (not yet validated as a body: see
/// [`crate::Body::from_file`]). An absent report becomes method `"uploaded"`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `data.exponents` for a length that is not 3 × the number of
/// coefficients or an exponent above 8.
pub fn body_file_from_proto(d: &pb::BodyData) -> Result<BodyFile> {
    if d.exponents.len() != 3 * d.coefficients.len() {
        return Err(Error::invalid(
            "data.exponents",
            format!(
                "{} entries for {} coefficients; expected 3 per coefficient",
                d.exponents.len(),
                d.coefficients.len()
            ),
        ));
    }
    let exponents = d
        .exponents
        .chunks_exact(3)
        .enumerate()
        .map(|(k, c)| {
            let e = |v: u32| u8::try_from(v).ok().filter(|&v| v <= 8);
            match (e(c[0]), e(c[1]), e(c[2])) {
                (Some(a), Some(b), Some(cc)) => Ok([a, b, cc]),
                _ => Err(Error::invalid(format!("data.exponents[{k}]"), format!("exponent {c:?} exceeds 8"))),
            }
        })
        .collect::<Result<Vec<_>>>()?;
    let report = d.report.as_ref().map_or_else(uploaded_report, report_from_proto);
    Ok(BodyFile {
        degree: d.degree as usize,
        exponents,
        coefficients: d.coefficients.clone(),
        center: d.center.as_ref().map_or([0.0; 3], |c| [c.x, c.y, c.z]),
        scale: d.scale,
        report,
    })
}

/// The report of a body uploaded without one.
pub fn uploaded_report() -> FitReport {
    FitReport { method: "uploaded".into(), containment_rescale: 1.0, ..Default::default() }
}

/// A body entry as the proto summary.
pub fn body_summary(e: &BodyEntry) -> pb::BodySummary {
    pb::BodySummary {
        body_id: e.id.clone(),
        name: e.name.clone(),
        degree: e.body.degree() as u32,
        method: e.body.report.method.clone(),
        volume: e.body.report.volume,
    }
}

// ---------------------------------------------------------------------------------------------
// Scenes
// ---------------------------------------------------------------------------------------------

/// An instance as the proto message.
pub fn instance_to_proto(i: &InstanceView) -> pb::Instance {
    pb::Instance { instance_id: i.id.clone(), body_id: i.body_id.clone(), pose: Some(pose_to_proto(&i.pose)) }
}

/// A scene as the proto response.
pub fn scene_to_proto(s: &SceneView) -> pb::GetSceneResponse {
    pb::GetSceneResponse {
        scene_id: s.id.clone(),
        name: s.name.clone(),
        instances: s.instances.iter().map(instance_to_proto).collect(),
    }
}

/// Validates the entries of a `SetPoses` request.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `poses[k].instance_id` (empty) or `poses[k].pose.rotation` /
/// `poses[k].pose.translation`; [`Error::ResourceExhausted`] above `max_poses`.
pub fn poses_from_proto(poses: &[pb::InstancePose], max_poses: usize) -> Result<Vec<(String, Isometry3)>> {
    if poses.len() > max_poses {
        return Err(Error::ResourceExhausted(format!(
            "`poses`: {} entries exceed the limit of {max_poses}",
            poses.len()
        )));
    }
    poses
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let at = |e| prefix_field(e, &format!("poses[{k}]"));
            require_id("instance_id", &p.instance_id).map_err(at)?;
            Ok((p.instance_id.clone(), pose_from_proto("pose", p.pose.as_ref()).map_err(at)?))
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Queries
// ---------------------------------------------------------------------------------------------

/// A solve status as the proto enum.
pub fn status_to_proto(s: SolveStatus) -> pb::SolveStatus {
    match s {
        SolveStatus::Converged => pb::SolveStatus::Converged,
        SolveStatus::MaxIterations => pb::SolveStatus::MaxIterations,
        SolveStatus::Stalled => pb::SolveStatus::Stalled,
    }
}

fn solve_info(status: SolveStatus, iterations: usize, kkt_residual: Real, warm_started: bool) -> pb::SolveInfo {
    pb::SolveInfo {
        converged: status.converged(),
        status: status_to_proto(status) as i32,
        iterations: u32::try_from(iterations).unwrap_or(u32::MAX),
        kkt_residual,
        warm_started,
        precision_limited: false,
    }
}

/// A distance answer as the proto message.
pub fn distance_to_proto(r: &DistanceResult) -> pb::DistanceAnswer {
    pb::DistanceAnswer {
        distance: r.distance,
        witness_a: Some(point_to_proto(&r.witness_a)),
        witness_b: Some(point_to_proto(&r.witness_b)),
        normal: Some(vector_to_proto(&r.normal)),
        overlapping: r.overlapping,
        solve: Some(solve_info(r.status, r.iterations, r.kkt_residual, r.warm_started)),
        ..Default::default()
    }
}

/// A growth answer as the proto message.
pub fn growth_to_proto(r: &GrowthResult) -> pb::GrowthAnswer {
    pb::GrowthAnswer {
        value: r.value,
        minimizer: Some(point_to_proto(&r.minimizer)),
        multiplier: r.multiplier,
        separated: r.value > 1.0,
        solve: Some(solve_info(r.status, r.iterations, r.kkt_residual, r.warm_started)),
        ..Default::default()
    }
}

/// An answer source as the proto enum.
pub fn source_to_proto(s: AnswerSource) -> pb::AnswerSource {
    match s {
        AnswerSource::Newton => pb::AnswerSource::Newton,
        AnswerSource::SdpFallback => pb::AnswerSource::SdpFallback,
        AnswerSource::SdpLowerBound => pb::AnswerSource::SdpLowerBound,
    }
}

/// A certificate summary as the proto message.
pub fn certificate_to_proto(c: &CertificateSummary) -> pb::Certificate {
    pb::Certificate {
        bound: c.bound,
        verified_bound: c.verified_bound,
        agrees: c.agrees,
        relative_gap: c.relative_gap,
        gram_min_eigenvalue: c.gram_min_eigenvalue,
        solve_seconds: c.solve_seconds,
        verified: c.verified,
        newton_value: c.newton_value.unwrap_or(Real::NAN),
    }
}

/// A pose gradient as the proto message.
pub fn gradient_to_proto(g: &PoseGradient) -> pb::PoseGradient {
    pb::PoseGradient { linear: Some(vector_to_proto(&g.linear)), angular: Some(vector_to_proto(&g.angular)) }
}

/// A certified distance answer (with optional gradients) as the proto message; `solve.converged`
/// is the certified answer's `converged`.
pub fn distance_reply_to_proto(r: &DistanceReply) -> pb::DistanceAnswer {
    let c = &r.answer;
    let mut out = distance_to_proto(&c.result);
    if let Some(solve) = out.solve.as_mut() {
        solve.converged = c.converged;
        solve.precision_limited = r.precision_limited;
    }
    out.source = source_to_proto(c.source) as i32;
    out.certificate = c.certificate.as_ref().map(certificate_to_proto);
    out.lower_bound = c.lower_bound;
    out.tight = c.tight;
    if let Some((ga, gb)) = &r.gradients {
        out.gradient_a = Some(gradient_to_proto(ga));
        out.gradient_b = Some(gradient_to_proto(gb));
    }
    if r.signed && !c.lower_bound {
        match &r.penetration {
            Some(p) => {
                out.signed_distance = -p.depth;
                out.penetration_depth = p.depth;
                out.penetration_normal = Some(vector_to_proto(&p.normal));
                if r.gradients.is_some() {
                    let (ga, gb) = crate::query::penetration::penetration_gradient(p);
                    out.signed_gradient_a = Some(gradient_to_proto(&ga));
                    out.signed_gradient_b = Some(gradient_to_proto(&gb));
                }
            }
            None => {
                out.signed_distance = c.result.distance;
                out.signed_gradient_a = out.gradient_a;
                out.signed_gradient_b = out.gradient_b;
            }
        }
    }
    out
}

/// A certified growth answer (with optional gradients) as the proto message.
pub fn growth_reply_to_proto(r: &GrowthReply) -> pb::GrowthAnswer {
    let c = &r.answer;
    let mut out = growth_to_proto(&c.result);
    if let Some(solve) = out.solve.as_mut() {
        solve.converged = c.converged;
        solve.precision_limited = r.precision_limited;
    }
    out.source = source_to_proto(c.source) as i32;
    out.certificate = c.certificate.as_ref().map(certificate_to_proto);
    out.lower_bound = c.lower_bound;
    out.tight = c.tight;
    if let Some((g1, g2)) = &r.gradients {
        out.gradient_1 = Some(gradient_to_proto(g1));
        out.gradient_2 = Some(gradient_to_proto(g2));
    }
    out
}

/// The query options of a request's `certify` / `with_gradient` flags.
pub fn query_options(certify: bool, with_gradient: bool) -> QueryOptions {
    QueryOptions {
        mode: if certify { CertifyMode::Certify } else { CertifyMode::Newton },
        with_gradient,
        cold: false,
        signed: false,
    }
}

/// A batch answer as the proto message.
pub fn answer_to_proto(a: &QueryAnswer) -> pb::QueryAnswer {
    let answer = match a {
        QueryAnswer::Distance(d) => pb::query_answer::Answer::Distance(distance_reply_to_proto(d)),
        QueryAnswer::Growth(g) => pb::query_answer::Answer::Growth(growth_reply_to_proto(g)),
        QueryAnswer::Collide(c) => pb::query_answer::Answer::Collide(pb::CollideAnswer {
            collides: c.collides,
            distance: c.distance,
            decided_by_bounds: c.decided_by_bounds,
            solve: c.solve.as_ref().and_then(|d| distance_reply_to_proto(d).solve),
            margin: c.margin,
        }),
    };
    pb::QueryAnswer { answer: Some(answer) }
}

/// Validates the pairs of a `BatchQuery`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `pairs[k].kind` / `pairs[k].first` / `pairs[k].second`;
/// [`Error::ResourceExhausted`] above `max_pairs`.
pub fn pairs_from_proto(pairs: &[pb::QueryPair], max_pairs: usize) -> Result<Vec<crate::scene::QueryPair>> {
    if pairs.len() > max_pairs {
        return Err(Error::ResourceExhausted(format!(
            "`pairs`: {} entries exceed the limit of {max_pairs}",
            pairs.len()
        )));
    }
    pairs
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let kind = match pb::QueryKind::try_from(p.kind) {
                Ok(pb::QueryKind::Distance) => QueryKind::Distance,
                Ok(pb::QueryKind::Growth) => QueryKind::Growth,
                _ => return Err(Error::invalid(format!("pairs[{k}].kind"), "must be DISTANCE or GROWTH")),
            };
            let at = |e| prefix_field(e, &format!("pairs[{k}]"));
            require_id("first", &p.first).map_err(at)?;
            require_id("second", &p.second).map_err(at)?;
            Ok(crate::scene::QueryPair {
                kind,
                first: p.first.clone(),
                second: p.second.clone(),
                options: QueryOptions { signed: p.signed, ..query_options(p.certify, p.with_gradient) },
                margin: 0.0,
            })
        })
        .collect()
}

/// The queries of a `BatchQuery` in columns (`BatchQueryRequest.columns`), validated.
#[derive(Clone, Debug)]
pub struct PairColumns {
    /// The kind of every pair.
    pub kind: QueryKind,
    /// The instances the pairs index.
    pub instance_ids: Vec<String>,
    /// Index of each pair's first instance.
    pub first: Vec<u32>,
    /// Index of each pair's second instance.
    pub second: Vec<u32>,
    /// COLLIDE: the margin in meters.
    pub margin: Real,
}

/// Validates `BatchQueryRequest.columns`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `columns.kind`, `columns.instance_ids[k]`, `columns.second`
/// (length), `columns.first[k]` / `columns.second[k]` (index out of range) or `columns.margin`;
/// [`Error::ResourceExhausted`] above `max_pairs` pairs or instance ids.
pub fn pair_columns_from_proto(c: &pb::PairColumns, max_pairs: usize) -> Result<PairColumns> {
    let kind = match pb::QueryKind::try_from(c.kind) {
        Ok(pb::QueryKind::Distance) => QueryKind::Distance,
        Ok(pb::QueryKind::Growth) => QueryKind::Growth,
        Ok(pb::QueryKind::Collide) => QueryKind::Collide,
        _ => return Err(Error::invalid("columns.kind", "must be DISTANCE, GROWTH or COLLIDE")),
    };
    for (field, n) in [("columns.first", c.first.len()), ("columns.instance_ids", c.instance_ids.len())] {
        if n > max_pairs {
            return Err(Error::ResourceExhausted(format!("`{field}`: {n} entries exceed the limit of {max_pairs}")));
        }
    }
    if c.first.len() != c.second.len() {
        return Err(Error::invalid(
            "columns.second",
            format!("has {} entries, `columns.first` has {}", c.second.len(), c.first.len()),
        ));
    }
    for (k, id) in c.instance_ids.iter().enumerate() {
        require_id("id", id).map_err(|_| {
            Error::invalid(format!("columns.instance_ids[{k}]"), format!("must be 1 to {MAX_ID_BYTES} bytes"))
        })?;
    }
    for (field, column) in [("columns.first", &c.first), ("columns.second", &c.second)] {
        if let Some((k, i)) = column.iter().enumerate().find(|(_, &i)| i as usize >= c.instance_ids.len()) {
            return Err(Error::invalid(
                format!("{field}[{k}]"),
                format!("index {i} is outside columns.instance_ids (length {})", c.instance_ids.len()),
            ));
        }
    }
    if kind == QueryKind::Collide && !(c.margin.is_finite() && c.margin >= 0.0) {
        return Err(Error::invalid("columns.margin", format!("must be finite and >= 0 meters, got {}", c.margin)));
    }
    Ok(PairColumns {
        kind,
        instance_ids: c.instance_ids.clone(),
        first: c.first.clone(),
        second: c.second.clone(),
        margin: c.margin,
    })
}

/// Answers of a columns request as `AnswerColumns`: one entry per answer in every column (three
/// for points), `decided_by_bounds` for COLLIDE only.
pub fn answers_to_columns(kind: QueryKind, answers: &[QueryAnswer]) -> pb::AnswerColumns {
    let n = answers.len();
    let mut c = pb::AnswerColumns {
        kind: match kind {
            QueryKind::Distance => pb::QueryKind::Distance,
            QueryKind::Growth => pb::QueryKind::Growth,
            QueryKind::Collide => pb::QueryKind::Collide,
        } as i32,
        value: Vec::with_capacity(n),
        point_a: Vec::with_capacity(3 * n),
        point_b: Vec::with_capacity(3 * n),
        converged: Vec::with_capacity(n),
        overlapping: Vec::with_capacity(n),
        lower_bound: Vec::with_capacity(n),
        decided_by_bounds: Vec::with_capacity(if kind == QueryKind::Collide { n } else { 0 }),
    };
    let nan = [Real::NAN; 3];
    for a in answers {
        let (value, pa, pb_, converged, overlapping, lower_bound) = match a {
            QueryAnswer::Distance(d) => {
                let (r, w) = (&d.answer.result, &d.answer);
                (
                    r.distance,
                    r.witness_a.coords.into(),
                    r.witness_b.coords.into(),
                    w.converged,
                    r.overlapping,
                    w.lower_bound,
                )
            }
            QueryAnswer::Growth(g) => {
                let (r, w) = (&g.answer.result, &g.answer);
                let x: [Real; 3] = r.minimizer.coords.into();
                (r.value, x, x, w.converged, r.value <= 1.0, w.lower_bound)
            }
            QueryAnswer::Collide(col) => {
                c.decided_by_bounds.push(col.decided_by_bounds);
                match &col.solve {
                    Some(d) => {
                        let r = &d.answer.result;
                        let (wa, wb) = (r.witness_a.coords.into(), r.witness_b.coords.into());
                        (col.distance, wa, wb, d.answer.converged, col.collides, d.answer.lower_bound)
                    }
                    None => (col.distance, nan, nan, true, col.collides, false),
                }
            }
        };
        c.value.push(value);
        c.point_a.extend_from_slice(&pa);
        c.point_b.extend_from_slice(&pb_);
        c.converged.push(converged);
        c.overlapping.push(overlapping);
        c.lower_bound.push(lower_bound);
    }
    c
}

// ---------------------------------------------------------------------------------------------
// Planner requests (Query, QueryStream, CheckScene)
// ---------------------------------------------------------------------------------------------

/// Validates a planner request: its poses (`poses[k]`), candidate states
/// (`states[s].poses[k]`) and queries (`queries[k].kind` / `.first` / `.second` / `.margin`).
/// `max_answers` bounds queries × max(1, states).
///
/// # Errors
/// [`Error::InvalidArgument`] naming the field; [`Error::ResourceExhausted`] above `max_answers`
/// answers or `max_poses` poses in all.
pub fn planner_request_from_proto(
    req: &pb::QueryRequest,
    max_answers: usize,
    max_poses: usize,
) -> Result<crate::scene::planner::PlannerRequest> {
    let answers = req.queries.len().saturating_mul(req.states.len().max(1));
    if answers > max_answers {
        return Err(Error::ResourceExhausted(format!(
            "`queries` × `states`: {} × {} = {answers} answers exceed the limit of {max_answers}",
            req.queries.len(),
            req.states.len().max(1)
        )));
    }
    let total_poses = req.poses.len() + req.states.iter().map(|s| s.poses.len()).sum::<usize>();
    if total_poses > max_poses {
        return Err(Error::ResourceExhausted(format!("{total_poses} poses in all exceed the limit of {max_poses}")));
    }
    let poses = poses_from_proto(&req.poses, max_poses)?;
    let states = req
        .states
        .iter()
        .enumerate()
        .map(|(s, st)| poses_from_proto(&st.poses, max_poses).map_err(|e| prefix_field(e, &format!("states[{s}]"))))
        .collect::<Result<Vec<_>>>()?;
    if let Some(columns) = &req.columns {
        if !req.queries.is_empty() {
            return Err(Error::invalid("columns", "set either `queries` or `columns`, not both"));
        }
        let c = pair_columns_from_proto(columns, max_answers)?;
        if c.first.len().saturating_mul(req.states.len().max(1)) > max_answers {
            return Err(Error::ResourceExhausted(format!(
                "`columns` × `states`: {} × {} answers exceed the limit of {max_answers}",
                c.first.len(),
                req.states.len().max(1)
            )));
        }
        let queries = c
            .first
            .iter()
            .zip(&c.second)
            .map(|(&i, &j)| crate::scene::QueryPair {
                kind: c.kind,
                first: c.instance_ids[i as usize].clone(),
                second: c.instance_ids[j as usize].clone(),
                options: QueryOptions::default(),
                margin: c.margin,
            })
            .collect();
        return Ok(crate::scene::planner::PlannerRequest { poses, queries, states });
    }
    let queries = req
        .queries
        .iter()
        .enumerate()
        .map(|(k, q)| {
            let kind = match pb::QueryKind::try_from(q.kind) {
                Ok(pb::QueryKind::Distance) => QueryKind::Distance,
                Ok(pb::QueryKind::Growth) => QueryKind::Growth,
                Ok(pb::QueryKind::Collide) => QueryKind::Collide,
                _ => return Err(Error::invalid(format!("queries[{k}].kind"), "must be DISTANCE, GROWTH or COLLIDE")),
            };
            let at = |e| prefix_field(e, &format!("queries[{k}]"));
            require_id("first", &q.first).map_err(at)?;
            require_id("second", &q.second).map_err(at)?;
            if !(q.margin.is_finite() && q.margin >= 0.0) {
                return Err(Error::invalid(
                    format!("queries[{k}].margin"),
                    format!("must be finite and >= 0 meters, got {}", q.margin),
                ));
            }
            let mut options = query_options(q.certify, q.with_gradient);
            options.cold = q.cold;
            options.signed = q.signed;
            Ok(crate::scene::QueryPair {
                kind,
                first: q.first.clone(),
                second: q.second.clone(),
                options,
                margin: q.margin,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(crate::scene::planner::PlannerRequest { poses, queries, states })
}

/// The answers of a planner request as the proto response.
///
/// `columns`: the request asked in columns (`QueryRequest.columns`) of this kind, so the answers
/// go in `columns` rather than one message each.
pub fn planner_answers_to_proto(
    answers: &crate::scene::planner::PlannerAnswers,
    request_id: u64,
    server_seconds: f64,
    columns: Option<QueryKind>,
) -> pb::QueryResponse {
    use crate::scene::planner::PlannerAnswers;
    let mut out = pb::QueryResponse { request_id, server_seconds, ..Default::default() };
    match (answers, columns) {
        (PlannerAnswers::Single(a), None) => out.answers = a.iter().map(answer_to_proto).collect(),
        (PlannerAnswers::Single(a), Some(kind)) => out.columns = Some(answers_to_columns(kind, a)),
        (PlannerAnswers::PerState(states), _) => {
            out.states = states
                .iter()
                .map(|a| pb::StateAnswers {
                    any_collision: a.iter().any(|x| matches!(x, QueryAnswer::Collide(c) if c.collides)),
                    answers: if columns.is_none() { a.iter().map(answer_to_proto).collect() } else { Vec::new() },
                    columns: columns.map(|kind| answers_to_columns(kind, a)),
                })
                .collect();
        }
    }
    out
}

/// The kind of a planner request asked in columns (`QueryRequest.columns`), if it is.
pub fn columns_kind(req: &pb::QueryRequest) -> Option<QueryKind> {
    let c = req.columns.as_ref()?;
    match pb::QueryKind::try_from(c.kind) {
        Ok(pb::QueryKind::Distance) => Some(QueryKind::Distance),
        Ok(pb::QueryKind::Growth) => Some(QueryKind::Growth),
        Ok(pb::QueryKind::Collide) => Some(QueryKind::Collide),
        _ => None,
    }
}

/// A scene check as the proto response.
pub fn scene_check_to_proto(c: &crate::scene::planner::SceneCheck, server_seconds: f64) -> pb::CheckSceneResponse {
    pb::CheckSceneResponse {
        pairs: c
            .pairs
            .iter()
            .map(|p| pb::ScenePair {
                first: p.first.clone(),
                second: p.second.clone(),
                distance: Some(distance_reply_to_proto(&p.distance)),
            })
            .collect(),
        instances: u32::try_from(c.instances).unwrap_or(u32::MAX),
        candidate_pairs: c.candidate_pairs,
        narrow_phase_solves: c.narrow_phase_solves,
        all_pairs: c.all_pairs,
        server_seconds,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_report_round_trips_through_the_wire_format_with_its_certificate() {
        let report = FitReport {
            method: "trace_p".into(),
            solver_status: crate::conic::SdpStatus::Solved,
            volume: 0.303,
            volume_std_error: 0.001,
            convexity_relaxation: 10.0,
            nonconvex: true,
            notes: vec!["kept the smallest of 2 solves".into()],
            solver_certificate: Some(crate::body::SolverCertificate {
                primal_objective: -22.6269,
                dual_objective: -22.6268,
                primal_residual: 1.3e-8,
                dual_residual: 1.8e-7,
            }),
            candidate_volumes: vec![("cube".into(), 0.449), ("principal_box".into(), 0.303)],
            ..FitReport::default()
        };
        let wire = report_to_proto(&report);
        assert_eq!(wire.candidate_volumes.len(), 2);
        assert_eq!(wire.solver_certificate.as_ref().map(|c| c.dual_objective), Some(-22.6268));
        assert_eq!(report_from_proto(&wire), report);
        // A report without a certificate (inverse moment, uploaded) stays without one.
        let plain = FitReport { method: "inverse_moment".into(), ..FitReport::default() };
        assert_eq!(report_from_proto(&report_to_proto(&plain)), plain);
    }

    #[test]
    fn errors_map_to_codes_and_keep_the_field() {
        let s = Status::from(Error::invalid("poses[3].pose.rotation", "bad"));
        assert_eq!(s.code(), Code::InvalidArgument);
        assert!(s.message().contains("poses[3].pose.rotation"));
        assert_eq!(Status::from(Error::not_found("scene", "s-1")).code(), Code::NotFound);
        assert_eq!(Status::from(Error::ResourceExhausted("x".into())).code(), Code::ResourceExhausted);
        assert_eq!(Status::from(Error::Numerical("x".into())).code(), Code::Internal);
        assert_eq!(Status::from(Error::Storage("x".into())).code(), Code::Unavailable);
    }

    #[test]
    fn degenerate_clouds_are_rejected() {
        let cube: Vec<Point3> =
            (0..8).map(|i| Point3::new((i & 1) as Real, ((i >> 1) & 1) as Real, ((i >> 2) & 1) as Real)).collect();
        assert!(check_cloud("points", &cube, 8).is_ok());
        let plane: Vec<Point3> = cube.iter().map(|p| Point3::new(p.x, p.y, 0.0)).collect();
        let e = check_cloud("mesh", &plane, 2).unwrap_err();
        assert!(e.to_string().contains("`mesh`") && e.to_string().contains("degenerate"), "{e}");
        assert!(check_cloud("points", &cube[..3], 2).is_err());
        // A sheet 1 × 1 × 1e-3: fine at 2d = 2, refused at 2d ≥ 4 (where the SDP fails).
        let sheet: Vec<Point3> = cube.iter().map(|p| Point3::new(p.x, p.y, 1e-3 * p.z)).collect();
        assert!(check_cloud("points", &sheet, 2).is_ok());
        let e = check_cloud("points", &sheet, 4).unwrap_err();
        assert!(e.to_string().contains("degree-4") && e.to_string().contains("1.0e-3"), "{e}");
    }

    #[test]
    fn pose_validation_names_the_field() {
        let bad = pb::Pose { rotation: Some(pb::Quaternion { w: 1.0, x: 1.0, y: 0.0, z: 0.0 }), translation: None };
        let e = pose_from_proto("poses[3].pose", Some(&bad)).unwrap_err();
        assert!(e.to_string().contains("poses[3].pose.rotation"), "{e}");
        let nan = pb::Pose { rotation: None, translation: Some(pb::Vec3 { x: f64::NAN, y: 0.0, z: 0.0 }) };
        let e = pose_from_proto("pose", Some(&nan)).unwrap_err();
        assert!(e.to_string().contains("pose.translation"), "{e}");
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let p = pose_from_parts("p", [h, 0.0, h, 0.0], [1.0, -2.0, 3.0]).unwrap();
        let back = pose_from_proto("p", Some(&pose_to_proto(&p))).unwrap();
        assert!((back.to_homogeneous() - p.to_homogeneous()).amax() < 1e-15);
    }
}

/// Properties of request validation over random inputs (proptest): every validator answers
/// (never panics) and accepts exactly what its documentation says.
#[cfg(test)]
mod properties {
    use super::*;
    use proptest::prelude::*;

    /// Finite numbers of every magnitude, the non-finite ones, and the edges of the range.
    fn any_number() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -2.0e6..2.0e6f64,
            1 => prop::num::f64::ANY,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(crate::math::MAX_COORDINATE),
            1 => Just(-crate::math::MAX_COORDINATE - 1.0),
        ]
    }

    proptest! {
        #[test]
        fn pose_validation_accepts_exactly_finite_unit_poses_in_range(
            q in prop::array::uniform4(any_number()),
            t in prop::array::uniform3(any_number()),
        ) {
            let pose = pb::Pose {
                rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
                translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
            };
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            let ok = q.iter().chain(&t).all(|v| v.is_finite())
                && t.iter().all(|v| v.abs() <= crate::math::MAX_COORDINATE)
                && (norm - 1.0).abs() <= crate::math::UNIT_QUATERNION_TOLERANCE;
            match pose_from_proto("poses[7].pose", Some(&pose)) {
                Ok(_) => prop_assert!(ok),
                Err(Error::InvalidArgument { field, .. }) => {
                    prop_assert!(!ok);
                    prop_assert!(field.starts_with("poses[7].pose"), "{}", field);
                }
                Err(other) => prop_assert!(false, "unexpected {other:?}"),
            }
        }

        #[test]
        fn unit_quaternions_in_range_are_accepted(
            axis in prop::array::uniform3(-1.0..1.0f64),
            angle in -10.0..10.0f64,
            t in prop::array::uniform3(-1.0e6..1.0e6f64),
        ) {
            let a = nalgebra::Vector3::from(axis);
            prop_assume!(a.norm() > 1e-3);
            let q = nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(a), angle);
            let pose = pb::Pose {
                rotation: Some(pb::Quaternion { w: q.w, x: q.i, y: q.j, z: q.k }),
                translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
            };
            prop_assert!(pose_from_proto("pose", Some(&pose)).is_ok());
        }

        #[test]
        fn point_clouds_are_checked_for_length_count_and_range(
            xyz in prop::collection::vec(any_number(), 0..40),
            max_points in 0usize..15,
        ) {
            let ok = xyz.len() % 3 == 0
                && xyz.len() / 3 <= max_points
                && xyz.iter().all(|v| v.is_finite() && v.abs() <= crate::math::MAX_COORDINATE);
            match points_from_proto(&pb::PointCloud { xyz: xyz.clone() }, max_points) {
                Ok(points) => {
                    prop_assert!(ok);
                    prop_assert_eq!(points.len() * 3, xyz.len());
                }
                Err(Error::InvalidArgument { field, .. }) => {
                    prop_assert!(!ok);
                    prop_assert_eq!(field, "points.xyz");
                }
                Err(Error::ResourceExhausted(m)) => {
                    prop_assert!(xyz.len() / 3 > max_points);
                    prop_assert!(m.contains("points.xyz"));
                }
                Err(other) => prop_assert!(false, "unexpected {other:?}"),
            }
        }

        #[test]
        fn ids_are_accepted_from_1_to_128_bytes_and_never_echoed_whole(id in ".{0,300}") {
            match require_id("scene_id", &id) {
                Ok(_) => prop_assert!(!id.is_empty() && id.len() <= MAX_ID_BYTES),
                Err(e) => {
                    prop_assert!(id.is_empty() || id.len() > MAX_ID_BYTES);
                    prop_assert!(e.to_string().len() < 200 + crate::error::CLIP_BYTES, "{}", e);
                }
            }
        }

        #[test]
        fn body_data_with_random_shapes_is_refused_or_admitted_without_panicking(
            degree in 0u32..12,
            exponents in prop::collection::vec(0u32..12, 0..30),
            coefficients in prop::collection::vec(any_number(), 0..10),
            scale in any_number(),
        ) {
            let data = pb::BodyData { degree, exponents, coefficients, center: None, scale, report: None };
            if let Ok(file) = body_file_from_proto(&data) {
                // Whatever the core says, it says it with an error, not a panic.
                let _ = crate::Body::from_file(file);
            }
        }

        #[test]
        fn reports_with_a_non_finite_figure_are_refused_naming_it(
            volume in any_number(),
            seconds in any_number(),
            margin in prop::option::of(any_number()),
        ) {
            let report = FitReport { volume, total_seconds: seconds, convexity_margin: margin, ..FitReport::default() };
            let finite = volume.is_finite() && seconds.is_finite() && margin.is_none_or(f64::is_finite);
            match report.check_finite("data.report") {
                Ok(()) => prop_assert!(finite),
                Err(Error::InvalidArgument { field, .. }) => {
                    prop_assert!(!finite);
                    prop_assert!(field.starts_with("data.report."));
                }
                Err(other) => prop_assert!(false, "unexpected {other:?}"),
            }
            let mut sanitized = report.clone();
            let replaced = sanitized.sanitize_non_finite();
            prop_assert_eq!(replaced == 0, finite);
            prop_assert!(sanitized.check_finite("r").is_ok());
            prop_assert!(crate::scene::store::encode("body", &sanitized).is_ok());
        }
    }
}
