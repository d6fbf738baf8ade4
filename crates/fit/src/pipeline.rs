//! The fit pipeline behind [`super::fit_points`]: frames and bases to try, one SDP (or the
//! containment rounds) per candidate, then verify (exact containment), body and volume.

use super::hull;
use super::inverse_moment;
use super::relaxed;
use super::sdp::{
    rescale_to_contain, usable_status, Containment, GramProgram, Objective, ObjectiveMatrix, ProblemSpec, TraceBasis,
};
use super::settings::report;
use super::volume;
use super::{FitMethod, FitProgress, FitSettings, FitStage};
use crate::{Error, Result};
use sublevel_core::body::{Body, FitReport, SolveDetails};
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Point3, Real};
use sublevel_core::poly::Polynomial;

/// What a formulation hands to the common verify / volume stages.
pub(crate) struct Solved {
    /// p before the containment rescale (normalized coordinates).
    pub(crate) poly: Polynomial,
    pub(crate) solver_status: SdpStatus,
    pub(crate) solve_seconds: Real,
    /// Sos-convexity Gram matrix of p (or of p + c q when relaxed), if the method has one.
    pub(crate) convexity_gram: Option<nalgebra::DMatrix<Real>>,
    /// Sos Gram matrix P of p = zᵀPz, for the volume box of a nonconvex body.
    pub(crate) sos_gram: Option<nalgebra::DMatrix<Real>>,
    pub(crate) nonconvex: bool,
    /// Primal / dual objectives of the (last) SDP solve, if there was one.
    pub(crate) certificate: Option<sublevel_core::body::SolverCertificate>,
    pub(crate) notes: Vec<String>,
    /// How the SDP was solved (None without an SDP).
    pub(crate) details: Option<SolveDetails>,
}

fn spec_of(settings: &FitSettings, trace_basis: TraceBasis) -> ProblemSpec {
    let (objective, matrix) = match settings.method {
        FitMethod::TraceP => (Objective::Trace, ObjectiveMatrix::P),
        FitMethod::LogDetH => (Objective::LogDet, ObjectiveMatrix::H),
        FitMethod::TraceH => (Objective::Trace, ObjectiveMatrix::H),
        FitMethod::LogDetP | FitMethod::InverseMoment => (Objective::LogDet, ObjectiveMatrix::P),
    };
    ProblemSpec {
        half_degree: settings.degree / 2,
        objective,
        matrix,
        convexity_relaxation: settings.convexity_relaxation,
        trace_basis,
        convexity_cone: settings.convexity_cone,
    }
}

/// [`super::fit_points`]: every candidate frame and basis, each through [`finish`]; the
/// smallest body is kept.
///
/// A near-flat cloud is thickened first ([`hull::thicken_flat`], [`hull::MIN_RELATIVE_THICKNESS`]):
/// the body is fitted to the thickened cloud, which holds every input point, and its report says so.
pub(super) fn fit(points: &[Point3], settings: &FitSettings, progress: &mut dyn FnMut(&FitProgress)) -> Result<Body> {
    let start = std::time::Instant::now();
    settings.validate()?;
    report(progress, FitStage::Hull, 0.0, format!("convex hull of {} points", points.len()));
    let thickened = hull::thicken_flat(points, hull::MIN_RELATIVE_THICKNESS)?;
    let cloud = thickened.as_ref().map_or(points, |(p, _)| p.as_slice());
    let mut body = fit_cloud(start, points.len(), cloud, settings, progress)?;
    if let Some((_, thickening)) = &thickened {
        body.report.notes.push(thickening.note());
    }
    Ok(body)
}

/// [`fit`] on the cloud to fit (`points`, the input's `num_points` points or a thickened cloud
/// holding them).
fn fit_cloud(
    start: std::time::Instant,
    num_points: usize,
    points: &[Point3],
    settings: &FitSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    let rounds = settings.rows_in_rounds || settings.convexity_relaxation > 0.0;
    let body_cloud = hull::normalize_and_hull(points)?;
    // The SDP is solved in the frame of `settings.normalization`; the body is stored in the
    // bounding-cube frame of `body_cloud` (identity frame by default). A flat cloud is solved in
    // its principal box instead when the objective gives the same body in every frame.
    let flat = flat_frame(&body_cloud, settings);
    let flat_aspect = flat.as_ref().map(|f| f.3);
    let mut in_flat_frame;
    let settings = match &flat {
        Some((normalization, _, _, _)) => {
            in_flat_frame = FitSettings { normalization: *normalization, ..settings.clone() };
            in_flat_frame.alternate_normalization = None;
            &in_flat_frame
        }
        None => settings,
    };
    let (frame, cloud) = match flat {
        Some((_, frame, cloud, _)) => (frame, cloud),
        None => body_cloud.reframed(settings.normalization)?,
    };
    let frames = Frames { body: &body_cloud, frame, fit: &cloud };
    let d = settings.degree / 2;
    if settings.method == FitMethod::InverseMoment {
        report(progress, FitStage::Build, 0.05, format!("degree-{} moment matrix of {} points", 2 * d, points.len()));
        let solved = inverse_moment::solve(d, &cloud.points)?;
        return finish(start, num_points, &frames, solved, settings, progress);
    }
    // Frame-dependent objectives are solved in every candidate frame (and, for the trace
    // objectives, in both monomial bases, see `TraceBasis`); the smallest body is kept. Every
    // candidate contains every point (each goes through `finish`).
    let mut spaces = vec![(settings.normalization, frame, cloud)];
    if let Some(alt) = settings.alternate_normalization {
        if settings.depends_on_frame() && alt != settings.normalization {
            let (alt_frame, alt_cloud) = body_cloud.reframed(alt)?;
            spaces.push((alt, alt_frame, alt_cloud));
        }
    }
    let is_trace = matches!(settings.method, FitMethod::TraceP | FitMethod::TraceH);
    let bases: &[TraceBasis] = match settings.trace_basis {
        None if is_trace => &[TraceBasis::Plain, TraceBasis::Scaled],
        Some(TraceBasis::Scaled) if is_trace => &[TraceBasis::Scaled],
        _ => &[TraceBasis::Plain],
    };
    let mut best: Option<Body> = None;
    let mut first_error: Option<Error> = None;
    let mut tried = Vec::new();
    let mut candidates = Vec::new();
    let mut solve_seconds = 0.0;
    for (normalization, frame, cloud) in &spaces {
        let frames = Frames { body: &body_cloud, frame: *frame, fit: cloud };
        let in_frame = FitSettings { normalization: *normalization, ..settings.clone() };
        for &basis in bases {
            let solved = if rounds {
                solve_in_rounds(cloud, &in_frame, basis, progress)
            } else {
                solve_on_hull(cloud, &in_frame, basis, progress)
            };
            let name = match basis {
                TraceBasis::Plain if bases.len() > 1 => format!("{}/plain basis", normalization.name()),
                TraceBasis::Scaled => format!("{}/scaled basis", normalization.name()),
                TraceBasis::Plain => normalization.name().to_string(),
            };
            match solved.and_then(|solved| finish(start, num_points, &frames, solved, &in_frame, progress)) {
                Ok(body) => {
                    solve_seconds += body.report.solve_seconds;
                    tried.push(format!("{name} {:.4}", body.report.volume));
                    candidates.push((name, body.report.volume));
                    if best.as_ref().is_none_or(|b| body.report.volume < b.report.volume) {
                        best = Some(body);
                    }
                }
                Err(e) => {
                    tried.push(format!("{name} failed ({e})"));
                    first_error.get_or_insert(e);
                }
            }
        }
    }
    let Some(mut body) = best else {
        return Err(first_error.unwrap_or_else(|| Error::Numerical("no fit was attempted".into())));
    };
    if tried.len() > 1 {
        body.report.notes.push(format!(
            "kept the smallest of {} solves, each containing every point (volumes: {})",
            tried.len(),
            tried.join(", ")
        ));
        body.report.solve_seconds = solve_seconds;
        body.report.total_seconds = start.elapsed().as_secs_f64();
        body.report.candidate_volumes = candidates;
    }
    if let Some(aspect) = flat_aspect {
        body.report.notes.push(format!(
            "flat cloud (principal aspect {aspect:.2e} < {}): solved in the principal box, the same log det optimum, better conditioned",
            hull::PRINCIPAL_FRAME_ASPECT
        ));
    }
    Ok(body)
}

/// The principal box ([`hull::Normalization::PrincipalBox`]) for a flat cloud, with the cloud in
/// it and its aspect (thinnest / longest side of the box), when the fit would solve in the bounding
/// cube and its optimum does not depend on the frame (log det P or H, c = 0); None otherwise.
fn flat_frame(
    body_cloud: &hull::NormalizedCloud,
    settings: &FitSettings,
) -> Option<(hull::Normalization, hull::Frame, hull::NormalizedCloud, Real)> {
    if settings.normalization != hull::Normalization::BoundingCube
        || settings.depends_on_frame()
        || settings.method == FitMethod::InverseMoment
    {
        return None;
    }
    let (frame, cloud) = body_cloud.reframed(hull::Normalization::PrincipalBox).ok()?;
    // linear = D·Rᵀ: its row norms are 1 / the box's half sides.
    let rows = (0..3).map(|i| frame.linear.row(i).norm());
    let (lo, hi) = rows.fold((Real::INFINITY, 0.0 as Real), |(lo, hi), r| (lo.min(r), hi.max(r)));
    let aspect = lo / hi;
    (aspect < hull::PRINCIPAL_FRAME_ASPECT).then_some((hull::Normalization::PrincipalBox, frame, cloud, aspect))
}

/// c = 0: one SDP with containment rows on the hull vertices.
fn solve_on_hull(
    cloud: &hull::NormalizedCloud,
    settings: &FitSettings,
    trace_basis: TraceBasis,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Solved> {
    let spec = spec_of(settings, trace_basis);
    report(
        progress,
        FitStage::Build,
        0.05,
        format!("building the degree-{} program on {} hull vertices", settings.degree, cloud.hull_vertices.len()),
    );
    let problem = GramProgram::build(&spec, Containment::Points(&cloud.hull_vertices))?;
    report(
        progress,
        FitStage::Solve,
        0.1,
        format!("Clarabel: {} variables, {} rows", problem.num_vars, problem.num_rows()),
    );
    let label = spec.objective_label();
    let raw = problem.solve_with_retry(&settings.solver_settings(), None, &mut |it, cost| {
        // Interior-point methods take 20–40 iterations here; map them onto [0.1, 0.8].
        let frac = 0.1 + 0.7 * (it as Real / 40.0).min(1.0);
        report(progress, FitStage::Solve, frac, format!("Clarabel iteration {it}, {label} ≈ {:.6}", -cost));
    })?;
    let status = usable_status(raw.status, "fit")?;
    let gram = problem.gram(&raw.x);
    Ok(Solved {
        poly: problem.polynomial_of_gram(&gram)?,
        solver_status: status,
        solve_seconds: raw.solve_seconds,
        convexity_gram: Some(problem.convexity_gram(&raw.x)),
        sos_gram: Some(gram),
        nonconvex: false,
        certificate: Some(raw.certificate),
        notes: vec![format!(
            "normalized by center = bounding-box midpoint, scale = half its longest side; Clarabel {} iterations ({})",
            raw.iterations,
            settings.linear_solver.name()
        )],
        details: Some(SolveDetails {
            iterations: raw.iterations,
            linear_solver: Some(settings.linear_solver),
            frame: Some(settings.normalization),
            ..Default::default()
        }),
    })
}

/// Containment rows in rounds (relaxed convexity, or any c with [`FitSettings::rows_in_rounds`]).
fn solve_in_rounds(
    cloud: &hull::NormalizedCloud,
    settings: &FitSettings,
    trace_basis: TraceBasis,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Solved> {
    let spec = spec_of(settings, trace_basis);
    report(
        progress,
        FitStage::Build,
        0.05,
        format!(
            "degree-{} program, c = {}, containment rows in rounds over {} points",
            settings.degree,
            settings.convexity_relaxation,
            cloud.points.len()
        ),
    );
    let label = spec.objective_label();
    let out = relaxed::solve_in_rounds(cloud, &spec, &settings.solver_settings(), &mut |round, it, cost| {
        // Round r takes [0.1 + 0.7(1 − 1/(r+1)), 0.1 + 0.7(1 − 1/(r+2))].
        let r = round as Real;
        let lo = 0.1 + 0.7 * (1.0 - 1.0 / (r + 1.0));
        let hi = 0.1 + 0.7 * (1.0 - 1.0 / (r + 2.0));
        let frac = lo + (hi - lo) * (it as Real / 40.0).min(1.0);
        report(
            progress,
            FitStage::Solve,
            frac,
            format!("Clarabel iteration {it} (containment round {}), {label} ≈ {:.6}", round + 1, -cost),
        );
    })?;
    let rows: Vec<String> = out.rows_per_round.iter().map(|r| r.to_string()).collect();
    let mut notes = vec![
        format!(
            "normalized by center = bounding-box midpoint, scale = half its longest side; Clarabel {} iterations in all ({})",
            out.iterations,
            settings.linear_solver.name()
        ),
        format!(
            "relaxed convexity c = {} (normalized coordinates, bounding box in [−1, 1]³): {} containment round(s), rows {} of {} points",
            settings.convexity_relaxation,
            out.rows_per_round.len(),
            rows.join(" → "),
            cloud.points.len()
        ),
    ];
    if let Some(why) = &out.failed_round {
        notes.push(format!("{why}: kept the previous round's solution; the final rescale restores containment"));
    } else if !out.converged {
        notes.push(format!(
            "round cap {} reached with points still outside; the final rescale restores containment",
            relaxed::MAX_ROUNDS
        ));
    }
    Ok(Solved {
        poly: out.polynomial,
        solver_status: out.status,
        solve_seconds: out.solve_seconds,
        convexity_gram: Some(out.convexity_gram),
        sos_gram: Some(out.gram),
        nonconvex: settings.convexity_relaxation > 0.0,
        certificate: Some(out.certificate),
        notes,
        details: Some(SolveDetails {
            iterations: out.iterations,
            linear_solver: Some(settings.linear_solver),
            frame: Some(settings.normalization),
            rows_per_round: out.rows_per_round.clone(),
            ..Default::default()
        }),
    })
}

/// The body's normalized cloud, the frame the SDP was solved in and the cloud in that frame.
struct Frames<'a> {
    body: &'a hull::NormalizedCloud,
    frame: hull::Frame,
    fit: &'a hull::NormalizedCloud,
}

/// Verify (containment rescale), body construction and volume, common to every method.
///
/// `solved.poly` is in the fit frame; the body stores p_body(u) = p_fit(L u + o) (exact
/// composition, [`Polynomial::compose_affine`]) in the bounding-cube frame, and containment is
/// checked on every point in both frames. The volume is estimated in the fit frame and divided
/// by |det L|.
fn finish(
    start: std::time::Instant,
    num_points: usize,
    frames: &Frames<'_>,
    solved: Solved,
    settings: &FitSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    super::cancel::check()?;
    report(progress, FitStage::Verify, 0.8, format!("checking p ≤ 1 on all {} points", num_points));
    let mut poly_fit = solved.poly;
    let (mut max_value, mut rescale) = rescale_to_contain(&mut poly_fit, &frames.fit.points)?;
    let mut notes = solved.notes;
    let poly = if frames.frame.is_identity() {
        poly_fit.clone()
    } else {
        let mut composed = poly_fit.compose_affine(&frames.frame.linear, &frames.frame.offset);
        let (max_body, extra) = rescale_to_contain(&mut composed, &frames.body.points)?;
        if extra != 1.0 {
            poly_fit.scale(1.0 / extra);
            rescale *= extra;
        }
        max_value = max_body;
        notes.push(format!(
            "SDP solved in the {} frame (u_fit = L·u + o, |det L| = {:.6}); body stored in the bounding-cube frame",
            settings.normalization.name(),
            frames.frame.jacobian()
        ));
        composed
    };
    let margin = solved
        .convexity_gram
        .map(|g| (g / rescale).symmetric_eigenvalues().iter().copied().fold(Real::INFINITY, Real::min));

    let cloud = frames.body;
    let mut fit_report = FitReport {
        method: settings.method.name().into(),
        solver_status: solved.solver_status,
        solve_seconds: solved.solve_seconds,
        total_seconds: 0.0,
        num_points,
        num_hull_vertices: cloud.hull_vertices.len(),
        volume: 0.0,
        volume_std_error: 0.0,
        hull_volume: cloud.hull_volume(),
        max_point_value: max_value,
        containment_rescale: rescale,
        convexity_margin: margin,
        notes,
        convexity_relaxation: settings.convexity_relaxation,
        nonconvex: solved.nonconvex,
        solver_certificate: solved.certificate,
        solve: solved.details,
        ..Default::default()
    };
    let center = [cloud.center.x, cloud.center.y, cloud.center.z];
    let body = Body::new(poly, center, cloud.scale, fit_report.clone())
        .map_err(|e| Error::Numerical(format!("the fitted polynomial is not a bounded body: {e}")))?;

    super::cancel::check()?;
    report(progress, FitStage::Volume, 0.85, format!("Monte Carlo volume, {} samples", settings.volume_samples));
    let est = if solved.nonconvex {
        let gram = solved
            .sos_gram
            .ok_or_else(|| Error::Numerical("a nonconvex body needs its sos Gram matrix for the volume box".into()))?;
        let lambda = (gram / rescale).symmetric_eigenvalues().iter().copied().fold(Real::INFINITY, Real::min);
        let est = volume::monte_carlo_volume_sos(&poly_fit, lambda, settings.volume_samples, settings.seed)?;
        fit_report.notes.push(format!(
            "volume box: cells of side {:.4} covering {{p ≤ 1}} inside the ball |u| ≤ {:.3} (λ_min(P) = {lambda:.3e})",
            est.cell_side, est.radius
        ));
        est.estimate
    } else {
        let interior = frames.frame.apply(&((body.interior_point().coords - cloud.center) / cloud.scale));
        volume::monte_carlo_volume(&poly_fit, &interior, settings.volume_samples, settings.seed)?
    };
    let to_input_units = cloud.scale.powi(3) / frames.frame.jacobian();
    fit_report.volume = est.volume * to_input_units;
    fit_report.volume_std_error = est.std_error * to_input_units;
    fit_report.total_seconds = start.elapsed().as_secs_f64();
    // A derived figure that overflowed (e.g. the volume of an enormous cloud) is stored as a
    // representable number with a note: JSON has no infinity, and the body file must read back.
    fit_report.sanitize_non_finite();
    let mut body = body;
    body.report = fit_report;
    report(
        progress,
        FitStage::Done,
        1.0,
        format!(
            "volume {:.4} ± {:.4} (hull {:.4})",
            body.report.volume, body.report.volume_std_error, body.report.hull_volume
        ),
    );
    Ok(body)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit_points;
    use sublevel_core::math::Vector3;

    /// A hexagon 50 mm × 30 mm whose six vertices alternate between two planes 10⁻⁸ m (10⁻⁵ mm)
    /// apart, turned off the axes and moved: relative thickness 2·10⁻⁷, just above the coplanarity
    /// test, far below [`hull::MIN_RELATIVE_THICKNESS`].
    fn sliver() -> Vec<Point3> {
        let rot = nalgebra::Rotation3::from_euler_angles(0.4, -0.9, 0.3);
        let offset = Vector3::new(0.1, -0.2, 0.043);
        [(-25.0, 0.0), (-12.5, 15.0), (12.5, 15.0), (25.0, 0.0), (12.5, -15.0), (-12.5, -15.0)]
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| {
                let z = if k % 2 == 0 { 0.0 } else { 1e-8 };
                Point3::from(rot * Vector3::new(x * 1e-3, y * 1e-3, z) + offset)
            })
            .collect()
    }

    /// Before the thickening and the principal frame, every degree ended `InsufficientProgress` or
    /// `NumericalError` on this cloud (2d = 2 fails from a relative thickness of 10⁻⁵ down).
    #[test]
    fn a_near_flat_sliver_fits_solved_and_contains_its_points() {
        let points = sliver();
        let normal = nalgebra::Rotation3::from_euler_angles(0.4, -0.9, 0.3) * Vector3::z();
        let center = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / 6.0;
        for degree in [2, 4, 6] {
            let settings = FitSettings { degree, volume_samples: 20_000, ..FitSettings::default() };
            let body = fit_points(&points, &settings, &mut |_| {}).unwrap_or_else(|e| panic!("2d = {degree}: {e}"));
            assert_eq!(body.report.solver_status, SdpStatus::Solved, "2d = {degree}");
            assert!(body.report.max_point_value <= 1.0, "2d = {degree}");
            for p in &points {
                assert!(body.value_at(p) <= 1.0, "2d = {degree}: p = {} at {p}", body.value_at(p));
            }
            let notes = body.report.notes.join("\n");
            assert!(notes.contains("near-flat cloud") && notes.contains("principal box"), "{notes}");
            // Thickened to 3·10⁻³ × 50 mm = 0.15 mm: the body stays within a millimeter of the
            // hexagon's plane, and spans it (its center is inside).
            assert!(body.value_at(&Point3::from(center)) < 1.0, "2d = {degree}");
            for side in [-1.0, 1.0] {
                let off = Point3::from(center + normal * (side * 1e-3));
                assert!(body.value_at(&off) > 1.0, "2d = {degree}: 1 mm off the plane, p = {}", body.value_at(&off));
            }
            let iterations = body.report.solve.as_ref().map_or(0, |s| s.iterations);
            assert!(iterations <= 30, "2d = {degree}: {iterations} Clarabel iterations");
        }
    }
}
