//! Bodies and fits: fit options and point clouds of `StartFitJob` (with the cloud checks that keep
//! the SDP numerically sound), fit stages and reports, body files as structured proto fields, body
//! summaries.

use crate::pb;
use crate::{Error, Result};
use sublevel_core::body::{BodyFile, FitReport, SUPPORTED_DEGREES};
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Point3, Real, Vector3};
use sublevel_fit::mesh::MeshFormat;
use sublevel_fit::{FitMethod, FitStage};
use sublevel_scene::BodyEntry;

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
    pub method: sublevel_fit::FitMethod,
    /// Relaxed-convexity parameter c ≥ 0 (eq. "VAG.param.convex").
    pub convexity_relaxation: Real,
    /// With `auto_degree`: the candidate degrees and the relative volume tolerance.
    pub auto: Option<(Vec<usize>, Real)>,
}

/// Validates the fit options of a request: `degree` (2, 4, 6, 8; with `auto_degree`, or for a
/// compound fit (`parts` / `auto_parts`), 0 or one of them, the highest candidate: 0 is automatic), `method` (empty means logdet_p), `convexity_relaxation` (finite,
/// ≥ 0) and `volume_tolerance` (finite, in [0, 1); 0 means 0.05 with `auto_degree`).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `degree`, `method`, `convexity_relaxation` or
/// `volume_tolerance`.
pub fn fit_options(req: &pb::StartFitJobRequest) -> Result<FitOptions> {
    let named = if req.method.trim().is_empty() { None } else { Some(req.method.trim().parse::<FitMethod>()?) };
    let method = match (fit_method_from_proto(req.fit_method)?, named) {
        (Some(v), Some(n)) if v != n => {
            return Err(Error::invalid(
                "fit_method",
                format!("names {} but `method` names {}; set one of them", v.name(), n.name()),
            ))
        }
        (Some(m), _) | (None, Some(m)) => m,
        (None, None) => FitMethod::LogDetP,
    };
    let c = req.convexity_relaxation;
    if !(c.is_finite() && c >= 0.0) {
        return Err(Error::invalid("convexity_relaxation", format!("must be finite and >= 0, got {c}")));
    }
    let tol = req.volume_tolerance;
    if !(tol.is_finite() && (0.0..1.0).contains(&tol)) {
        return Err(Error::invalid("volume_tolerance", format!("must be in [0, 1), got {tol}")));
    }
    // A compound fit (`parts` / `auto_parts`) picks each part's degree itself unless one is given:
    // `degree` 0 there means automatic, as `sublevel fit --parts` defaults to.
    let compound = req.parts > 0 || req.auto_parts;
    let automatic = req.auto_degree || (compound && req.degree == 0);
    if !automatic {
        return Ok(FitOptions { degree: fit_degree(req.degree)?, method, convexity_relaxation: c, auto: None });
    }
    let top = if req.degree == 0 { 8 } else { fit_degree(req.degree)? };
    let degrees: Vec<usize> = SUPPORTED_DEGREES.iter().copied().filter(|d| *d <= top).collect();
    let tol = if req.volume_tolerance == 0.0 { 0.05 } else { req.volume_tolerance };
    sublevel_fit::auto::validate_auto(&degrees, tol)?;
    Ok(FitOptions { degree: degrees[0], method, convexity_relaxation: c, auto: Some((degrees, tol)) })
}

/// The compound part count of a `StartFitJobRequest`: `None` for a single-body fit
/// (`parts` 0, `auto_parts` false), `Fixed(n)` for `parts` n, `Auto` for `auto_parts`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `parts` (both set, or above
/// [`sublevel_fit::compound::decompose::MAX_PARTS`]) or `tolerance` (`auto_parts` without one).
pub fn part_count(req: &pb::StartFitJobRequest) -> Result<Option<sublevel_fit::compound::PartCount>> {
    use sublevel_fit::compound::decompose::MAX_PARTS;
    use sublevel_fit::compound::PartCount;
    match (req.parts, req.auto_parts) {
        (0, false) => Ok(None),
        (0, true) if req.tolerance == 0.0 => {
            Err(Error::invalid("tolerance", "`auto_parts` needs a leaf-excess tolerance in meters (> 0)"))
        }
        (0, true) => Ok(Some(PartCount::Auto)),
        (_, true) => Err(Error::invalid("parts", "set `parts` or `auto_parts`, not both")),
        (n, false) if n as usize > MAX_PARTS => {
            Err(Error::invalid("parts", format!("at most {MAX_PARTS} parts, got {n}")))
        }
        (n, false) => Ok(Some(PartCount::Fixed(n as usize))),
    }
}

/// The settings of a compound fit job: the server's fit settings for every leaf, leaf degrees
/// `degree` (or with `auto_degree` the candidates up to `degree`, at most 6 — the containment
/// parents take degrees ≤ 6), the request's `volume_tolerance` and leaf-excess `tolerance`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `degree` (8 without `auto_degree`), `tolerance` (not finite
/// or < 0) or a field of [`sublevel_fit::compound::CompoundSettings::validate`].
pub fn compound_settings(
    req: &pb::StartFitJobRequest,
    fit: &FitOptions,
    settings: sublevel_fit::FitSettings,
) -> Result<sublevel_fit::compound::CompoundSettings> {
    let t = req.tolerance;
    if !(t.is_finite() && t >= 0.0) {
        return Err(Error::invalid("tolerance", format!("must be a finite number >= 0 meters, got {t}")));
    }
    let (degrees, volume_tolerance) = match &fit.auto {
        Some((degrees, tol)) => (degrees.iter().copied().filter(|&d| d <= 6).collect::<Vec<_>>(), *tol),
        None if fit.degree > 6 => {
            return Err(Error::invalid("degree", "compound parts are fitted at degree 2, 4 or 6 (containment)"))
        }
        None => (vec![fit.degree], 0.05),
    };
    let defaults = sublevel_fit::compound::CompoundSettings::default();
    let compound = sublevel_fit::compound::CompoundSettings {
        fit: settings,
        degrees,
        volume_tolerance,
        excess_tolerance: (t > 0.0).then_some(t),
        ..defaults
    };
    compound.validate()?;
    Ok(compound)
}

/// Unpacks a point cloud `x0, y0, z0, x1, …`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points.xyz` for a length that is not a multiple of 3 or a
/// non-finite coordinate or one beyond [`sublevel_core::math::MAX_COORDINATE`]; [`Error::ResourceExhausted`] above `max_points` points.
pub fn points_from_proto(cloud: &pb::PointCloud, max_points: usize) -> Result<Vec<Point3>> {
    let xyz = &cloud.xyz;
    if !xyz.len().is_multiple_of(3) {
        return Err(Error::invalid("points.xyz", format!("length {} is not a multiple of 3", xyz.len())));
    }
    check_point_count("points.xyz", xyz.len() / 3, max_points)?;
    if let Some(i) = xyz.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid("points.xyz", format!("coordinate {i} is not finite")));
    }
    sublevel_core::math::check_coordinates("points.xyz", xyz)?;
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
/// ±[`sublevel_core::math::MAX_COORDINATE`], not all on one plane or line (the smallest eigenvalue of
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
        sublevel_core::math::check_coordinates(&format!("{field}[{k}]"), p.coords.as_slice())?;
    }
    let n = points.len() as Real;
    let mean = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let cov = points.iter().fold(sublevel_core::math::Matrix3::zeros(), |a, p| {
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
        status: sdp_status_to_proto(r.solver_status) as i32,
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
        solver_status: sublevel_core::conic::SdpStatus::parse(&r.solver_status),
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
        degree_choice: r.degree_choice.as_ref().map(|c| sublevel_core::body::DegreeChoice {
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
        solver_certificate: r.solver_certificate.as_ref().map(|c| sublevel_core::body::SolverCertificate {
            primal_objective: c.primal_objective,
            dual_objective: c.dual_objective,
            primal_residual: c.primal_residual,
            dual_residual: c.dual_residual,
        }),
        candidate_volumes: r.candidate_volumes.iter().map(|c| (c.name.clone(), c.volume)).collect(),
        // The wire report does not carry the structured solve details (the notes do, in prose).
        solve: None,
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
/// [`sublevel_core::Body::from_file`]). An absent report becomes method `"uploaded"`.
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

/// Most nodes of an uploaded compound body: the largest tree `sublevel fit --parts` builds
/// (2 × [`sublevel_fit::compound::decompose::MAX_PARTS`] − 1, a binary tree over its most parts). Each
/// node is certified sos-convex on upload (an SDP each), so the bound also caps that work.
pub const MAX_COMPOUND_NODES: usize = 2 * sublevel_fit::compound::decompose::MAX_PARTS - 1;

/// Admits an uploaded compound body file (`UploadBody.body_json` with `nodes`): at most
/// [`MAX_COMPOUND_NODES`] nodes; the tree shape, format and every node's body and excess checked
/// ([`sublevel_core::compound::CompoundBody::from_file`]); then every node admitted as an uploaded single body is
/// ([`sublevel_fit::sos_convexity::admit_uploaded`]: finite report, sos-convexity certificate). A node that is not sos-convex
/// is refused: the branch and bound uses node distances as lower bounds, which only a convex
/// node's Newton answer is. Then every parent is certified to contain its children
/// ([`sublevel_fit::compound::certify::certify_tree`]: a parent that provably does not is refused,
/// one short of a certificate by less is rescaled). Returns the body and the smallest certified
/// sos-convexity margin over its nodes.
///
/// Runs up to three SDPs per node: call it off the async workers.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `{field}.nodes` (too many), `{field}.format`,
/// `{field}.root`, `{field}.nodes[i].<…>` (e.g. `body_json.nodes[3].body.scale`),
/// `{field}.nodes[i].body` for a node that is not sos-convex, or `{field}.nodes[i]` for a parent
/// that does not contain a child (with the child's point outside it); [`Error::Numerical`] when Clarabel
/// rejects a certificate program.
pub fn admit_compound(
    mut file: sublevel_fit::compound::CompoundFile,
    field: &str,
) -> Result<(sublevel_fit::compound::CompoundBody, Real)> {
    use crate::convert::prefix_field;
    use sublevel_fit::compound::{CompoundBody, CompoundNode};
    if file.nodes.len() > MAX_COMPOUND_NODES {
        return Err(Error::invalid(
            format!("{field}.nodes"),
            format!("{} nodes exceed the limit of {MAX_COMPOUND_NODES} per compound body", file.nodes.len()),
        ));
    }
    for node in &mut file.nodes {
        if node.body.report.method.is_empty() {
            node.body.report = uploaded_report();
        }
    }
    // The cheap checks first (shape, every field), before one SDP per node.
    CompoundBody::from_file(file.clone()).map_err(|e| prefix_field(e, field))?;
    let mut nodes = Vec::with_capacity(file.nodes.len());
    let mut margin = Real::INFINITY;
    for (i, n) in file.nodes.into_iter().enumerate() {
        let at = format!("{field}.nodes[{i}].body");
        let admitted = sublevel_fit::sos_convexity::admit_uploaded(n.body).map_err(|e| prefix_field(e, &at))?;
        if admitted.body.report.nonconvex {
            return Err(Error::invalid(
                at,
                "is not certified sos-convex; every node of a compound body must be (its distances bound the leaves below it only when it is convex)",
            ));
        }
        if let Some(c) = &admitted.certificate {
            margin = margin.min(c.margin);
        }
        nodes.push(CompoundNode {
            body: admitted.body,
            children: n.children,
            depth: n.depth,
            excess: n.excess.unwrap_or(Real::NAN),
            triangles: n.triangles,
            fit_seconds: n.fit_seconds,
        });
    }
    // Every parent must contain its children: the tree queries bound a parent's leaves by it.
    sublevel_fit::compound::certify::certify_tree(&mut nodes).map_err(|e| prefix_field(e, field))?;
    let body = CompoundBody::new(nodes, file.root, file.report).map_err(|e| prefix_field(e, field))?;
    Ok((body, if margin.is_finite() { margin } else { Real::NAN }))
}

/// A body entry as the proto summary (from what is known without building the body:
/// [`BodyEntry::facts`]).
pub fn body_summary(e: &BodyEntry) -> pb::BodySummary {
    let facts = e.facts();
    pb::BodySummary {
        body_id: e.id.clone(),
        name: e.name.clone(),
        degree: facts.degree as u32,
        method: facts.method.clone(),
        // A halfspace's volume is infinite: 0, as an unknown volume.
        volume: if facts.volume.is_finite() { facts.volume } else { 0.0 },
        nodes: u32::try_from(e.node_count()).unwrap_or(u32::MAX),
        primitive: facts.primitive.unwrap_or_default().to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_report_round_trips_through_the_wire_format_with_its_certificate() {
        let report = FitReport {
            method: "trace_p".into(),
            solver_status: sublevel_core::conic::SdpStatus::Solved,
            volume: 0.303,
            volume_std_error: 0.001,
            convexity_relaxation: 10.0,
            nonconvex: true,
            notes: vec!["kept the smallest of 2 solves".into()],
            solver_certificate: Some(sublevel_core::body::SolverCertificate {
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
}

/// The `fit_method` enum field as the core's method (None when unset).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `fit_method` for an undefined enum value.
pub fn fit_method_from_proto(value: i32) -> Result<Option<FitMethod>> {
    Ok(match pb::FitMethod::try_from(value) {
        Ok(pb::FitMethod::Unspecified) => None,
        Ok(pb::FitMethod::LogdetP) => Some(FitMethod::LogDetP),
        Ok(pb::FitMethod::TraceP) => Some(FitMethod::TraceP),
        Ok(pb::FitMethod::LogdetH) => Some(FitMethod::LogDetH),
        Ok(pb::FitMethod::TraceH) => Some(FitMethod::TraceH),
        Ok(pb::FitMethod::InverseMoment) => Some(FitMethod::InverseMoment),
        Err(_) => return Err(Error::invalid("fit_method", format!("undefined value {value}"))),
    })
}

/// The format of a mesh message: the `mesh_format` enum when set, else the `format` text.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `mesh.format` when neither names a format, a name is
/// unknown, or the two disagree; `mesh.mesh_format` for an undefined enum value.
pub fn mesh_format_from_proto(mesh: &pb::Mesh) -> Result<MeshFormat> {
    let value = match pb::MeshFormat::try_from(mesh.mesh_format) {
        Ok(pb::MeshFormat::Unspecified) => None,
        Ok(pb::MeshFormat::Off) => Some(MeshFormat::Off),
        Ok(pb::MeshFormat::Obj) => Some(MeshFormat::Obj),
        Ok(pb::MeshFormat::Stl) => Some(MeshFormat::Stl),
        Ok(pb::MeshFormat::Ply) => Some(MeshFormat::Ply),
        Ok(pb::MeshFormat::Xyz) => Some(MeshFormat::Xyz),
        Ok(pb::MeshFormat::Dae) => Some(MeshFormat::Dae),
        Err(_) => return Err(Error::invalid("mesh.mesh_format", format!("undefined value {}", mesh.mesh_format))),
    };
    #[allow(deprecated)]
    let text = mesh.format.trim();
    let named = if text.is_empty() {
        None
    } else {
        Some(text.parse::<MeshFormat>().map_err(|e| Error::invalid("mesh.format", e.to_string()))?)
    };
    match (value, named) {
        (Some(v), Some(n)) if v != n => Err(Error::invalid(
            "mesh.format",
            format!("names {} but `mesh_format` is {}; set one of them", n.name(), v.name()),
        )),
        (Some(f), _) | (None, Some(f)) => Ok(f),
        (None, None) => Err(Error::invalid("mesh.format", "must name the format (off, obj, stl, ply, xyz)")),
    }
}

/// An SDP status as the proto enum (the value behind `FitReport.status` and
/// `Certificate.solver_status`).
pub fn sdp_status_to_proto(s: SdpStatus) -> pb::SolverStatus {
    match s {
        SdpStatus::Solved => pb::SolverStatus::Solved,
        SdpStatus::AlmostSolved => pb::SolverStatus::AlmostSolved,
        SdpStatus::Unsolved => pb::SolverStatus::Unsolved,
        SdpStatus::PrimalInfeasible => pb::SolverStatus::PrimalInfeasible,
        SdpStatus::DualInfeasible => pb::SolverStatus::DualInfeasible,
        SdpStatus::AlmostPrimalInfeasible => pb::SolverStatus::AlmostPrimalInfeasible,
        SdpStatus::AlmostDualInfeasible => pb::SolverStatus::AlmostDualInfeasible,
        SdpStatus::MaxIterations => pb::SolverStatus::MaxIterations,
        SdpStatus::MaxTime => pb::SolverStatus::MaxTime,
        SdpStatus::NumericalError => pb::SolverStatus::NumericalError,
        SdpStatus::InsufficientProgress => pb::SolverStatus::InsufficientProgress,
        SdpStatus::CallbackTerminated => pb::SolverStatus::CallbackTerminated,
        SdpStatus::ClosedForm => pb::SolverStatus::ClosedForm,
        SdpStatus::NotRun => pb::SolverStatus::NotRun,
        SdpStatus::Unknown => pb::SolverStatus::Unknown,
    }
}

#[cfg(test)]
mod enum_tests {
    use super::*;

    #[test]
    fn enum_fields_win_and_must_agree_with_the_text() {
        let mesh = |text: &str, value: pb::MeshFormat| {
            #[allow(deprecated)]
            pb::Mesh { data: Vec::new(), format: text.into(), mesh_format: value as i32 }
        };
        assert_eq!(mesh_format_from_proto(&mesh("", pb::MeshFormat::Ply)).unwrap(), MeshFormat::Ply);
        assert_eq!(mesh_format_from_proto(&mesh("OFF", pb::MeshFormat::Unspecified)).unwrap(), MeshFormat::Off);
        assert_eq!(mesh_format_from_proto(&mesh("stl", pb::MeshFormat::Stl)).unwrap(), MeshFormat::Stl);
        for bad in [
            mesh("off", pb::MeshFormat::Obj),
            mesh("", pb::MeshFormat::Unspecified),
            mesh("vtk", pb::MeshFormat::Unspecified),
        ] {
            assert!(
                matches!(mesh_format_from_proto(&bad), Err(Error::InvalidArgument { field, .. }) if field == "mesh.format")
            );
        }
        let undefined = pb::Mesh { mesh_format: 99, ..mesh("", pb::MeshFormat::Unspecified) };
        assert!(
            matches!(mesh_format_from_proto(&undefined), Err(Error::InvalidArgument { field, .. }) if field == "mesh.mesh_format")
        );

        let req = |text: &str, value: pb::FitMethod| pb::StartFitJobRequest {
            degree: 4,
            method: text.into(),
            fit_method: value as i32,
            ..Default::default()
        };
        assert_eq!(fit_options(&req("", pb::FitMethod::TraceH)).unwrap().method, FitMethod::TraceH);
        assert_eq!(fit_options(&req("logdet_h", pb::FitMethod::Unspecified)).unwrap().method, FitMethod::LogDetH);
        assert_eq!(fit_options(&req("", pb::FitMethod::Unspecified)).unwrap().method, FitMethod::LogDetP);
        assert!(matches!(
            fit_options(&req("trace_p", pb::FitMethod::LogdetP)),
            Err(Error::InvalidArgument { field, .. }) if field == "fit_method"
        ));
        // Degree 0: refused for a single-body fit, automatic (among 2, 4, 6 for the parts) for a
        // compound one.
        let single = pb::StartFitJobRequest { degree: 0, ..Default::default() };
        assert!(matches!(fit_options(&single), Err(Error::InvalidArgument { field, .. }) if field == "degree"));
        let parts = pb::StartFitJobRequest { degree: 0, parts: 4, ..Default::default() };
        let options = fit_options(&parts).unwrap();
        let compound = compound_settings(&parts, &options, sublevel_fit::FitSettings::default()).unwrap();
        assert_eq!(compound.degrees, vec![2, 4, 6]);
        // Every core status has its own proto value, and the text form travels beside it.
        let values: std::collections::HashSet<i32> =
            SdpStatus::ALL.iter().map(|s| sdp_status_to_proto(*s) as i32).collect();
        assert_eq!(values.len(), SdpStatus::ALL.len());
        assert!(!values.contains(&(pb::SolverStatus::Unspecified as i32)));
        let report = report_to_proto(&FitReport { solver_status: SdpStatus::AlmostSolved, ..Default::default() });
        assert_eq!(
            (report.status, report.solver_status.as_str()),
            (pb::SolverStatus::AlmostSolved as i32, "AlmostSolved")
        );
    }
}
