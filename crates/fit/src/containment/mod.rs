//! Containment of polynomial sublevel sets (paper §V): one sos-convex body around many bodies.
//!
//! Given posed bodies `Sᵢ = {x : gᵢ(x) ≤ 1}`, `gᵢ(x) = pᵢ((Rᵢᵀ(x − tᵢ) − cᵢ)/sᵢ)` (their world-frame
//! polynomials, [`Polynomial::compose_affine`]), find one sos-convex p of degree 2d whose unit
//! sublevel set contains their union and has small volume:
//!
//! ```text
//! maximize    log det P
//! subject to  p(x) = z(x)ᵀ P z(x),                       z = monomials of degree ≤ d
//!             p sos-convex                                (eq. "p.sosconvex")
//!             1 − p(x) − τᵢ(x)(1 − gᵢ(x))  sos,           (eq. "s.procedure")
//!             τᵢ sos of degree 2k,                        (eq. "tau.sos")     i = 1..m
//! ```
//!
//! This is the S-procedure: on Sᵢ, `1 − gᵢ ≥ 0` and `τᵢ ≥ 0`, so `1 − p ≥ τᵢ(1 − gᵢ) ≥ 0`. The union
//! is contained by containing each body separately (one s.procedure constraint per body, each with
//! its own multiplier τᵢ). Multiplier degrees: `2k = 0` (τᵢ a nonnegative scalar — already a valid
//! certificate, and lossless for ellipsoids in ellipsoids by the S-lemma) or `2k = 2`
//! (`τᵢ = z₁ᵀ Tᵢ z₁`, `Tᵢ ⪰ 0` 4 × 4, z₁ = (1, x, y, z)). The s.procedure polynomial has degree
//! `Dᵢ = max(2d, 2k + deg gᵢ)`; its Gram matrix `Qᵢ ⪰ 0` is indexed by the monomials of degree
//! ≤ Dᵢ/2, and one equation per monomial of degree ≤ Dᵢ matches coefficients:
//!
//! ```text
//! c_γ(p) + c_γ(τᵢ · (1 − gᵢ)) + Σ_{a ≤ b, z_a z_b = x^γ} (2 − δ_ab) Qᵢ,ab = [γ = 0]
//! ```
//!
//! The program is the fits' own ([`super::sdp::GramProgram`] with [`Containment::Bodies`]):
//! `log det P`, sos-convexity, scaled monomial bases, the convexity floor, Clarabel's settings and
//! retries, and the exact rescale after the solve are shared with the point-cloud fits, so a fix
//! to any of them reaches both.
//!
//! World coordinates are first normalized, `v = (x − c)/s` with c the midpoint of the union of the
//! bodies' bounding boxes and s half its diagonal (so every body lies in the unit ball); the
//! problem is affine-invariant up to a constant in the objective, so this only helps conditioning.
//! The result is a [`Body`] with that center and scale, in world coordinates (use it at identity
//! pose). After the solve, p is checked on boundary samples of every input body (bisection along
//! rays from each body's interior point) and divided by the largest value above 1, as the point
//! fit does; the report records the rescale.
//!
//! Sizes (per body, with the same degree for every body): at 2d = 4 and deg g = 4, 2k = 0, each
//! body adds a 10 × 10 Gram and 35 equations; 2k = 2 raises its degree to 6 (20 × 20, 84 rows).

mod margin;
pub use margin::{containment_margin, CONTAINMENT_SLACK};

use super::sdp::{rescale_to_contain, usable_status, Containment, GramProgram, ProblemSpec, SolverSettings};
use super::{report, volume, FitProgress, FitStage, KktSolver};
use crate::{Error, Result};
use sublevel_core::body::{Body, FitReport};
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::poly::Polynomial;

/// Degrees 2d the containing polynomial may have.
pub const CONTAINMENT_DEGREES: [usize; 3] = [2, 4, 6];

/// Degrees 2k the multipliers τᵢ may have (0: nonnegative scalars).
pub const MULTIPLIER_DEGREES: [usize; 2] = [0, 2];

/// Most bodies one containment SDP accepts (each adds a Gram block and its equations).
pub const MAX_CONTAINED_BODIES: usize = 16;

/// Boundary points sampled per input body to verify (and restore) containment after the solve.
pub const BOUNDARY_SAMPLES_PER_BODY: usize = 2000;

/// Settings of [`contain_bodies`].
#[derive(Clone, Debug)]
pub struct ContainmentSettings {
    /// Total degree 2d ∈ {2, 4, 6} of the containing polynomial p.
    pub degree: usize,
    /// Degree 2k ∈ {0, 2} of the sos multipliers τᵢ (eq. "tau.sos").
    pub multiplier_degree: usize,
    /// Monte Carlo samples of the volume estimate (at least; see [`volume::monte_carlo_volume`]).
    pub volume_samples: usize,
    /// Seed of the volume estimate.
    pub seed: u64,
    /// Clarabel's gap and feasibility tolerance.
    pub solver_tolerance: Real,
    /// Clarabel's iteration cap.
    pub max_solver_iterations: u32,
    /// Direct solver of Clarabel's KKT systems.
    pub linear_solver: KktSolver,
}

impl Default for ContainmentSettings {
    fn default() -> Self {
        Self {
            degree: 4,
            multiplier_degree: 0,
            volume_samples: 200_000,
            seed: 1,
            solver_tolerance: 1e-8,
            max_solver_iterations: 200,
            linear_solver: KktSolver::default(),
        }
    }
}

impl ContainmentSettings {
    /// Sets the degree 2d of p.
    pub fn with_degree(mut self, degree: usize) -> Self {
        self.degree = degree;
        self
    }

    /// Sets the degree 2k of the multipliers.
    pub fn with_multiplier_degree(mut self, degree: usize) -> Self {
        self.multiplier_degree = degree;
        self
    }

    /// Sets the Monte Carlo sample count.
    pub fn with_volume_samples(mut self, samples: usize) -> Self {
        self.volume_samples = samples;
        self
    }

    /// Sets Clarabel's tolerance.
    pub fn with_solver_tolerance(mut self, tol: Real) -> Self {
        self.solver_tolerance = tol;
        self
    }

    /// Clarabel's settings of the containment SDP (one thread; see [`SolverSettings`]).
    pub fn solver_settings(&self) -> SolverSettings {
        SolverSettings {
            tolerance: self.solver_tolerance,
            max_iterations: self.max_solver_iterations,
            linear_solver: self.linear_solver,
            threads: 1,
            iterative_refinement: false,
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree`, `multiplier_degree`, `volume_samples`,
    /// `solver_tolerance` or `max_solver_iterations`.
    pub fn validate(&self) -> Result<()> {
        if !CONTAINMENT_DEGREES.contains(&self.degree) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, got {}", self.degree)));
        }
        if !MULTIPLIER_DEGREES.contains(&self.multiplier_degree) {
            return Err(Error::invalid("multiplier_degree", format!("must be 0 or 2, got {}", self.multiplier_degree)));
        }
        super::validate_solver_fields(self.volume_samples, self.solver_tolerance, self.max_solver_iterations)
    }
}

/// `n` unit directions, well spread (a Fibonacci spiral).
fn directions(n: usize) -> Vec<Vector3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let th = golden * i as Real;
            Vector3::new(r * th.cos(), r * th.sin(), z)
        })
        .collect()
}

/// Points on the boundary `{p = 1}` of a posed body, in world coordinates (meters): one per ray
/// from the body's interior point along `n` well-spread directions (in the body's normalized
/// frame), found by bisection to 1e-13 of the ray parameter. Each returned point lies on the
/// outer side (p ≥ 1 up to rounding), so checking a container on them is conservative.
///
/// # Errors
/// [`Error::Numerical`] when a ray does not leave the body (p not coercive).
pub fn boundary_points(body: &Body, pose: &Isometry3, n: usize) -> Result<Vec<Point3>> {
    let posed = body.posed(pose);
    let p = body.polynomial();
    let u0 = (body.interior_point().coords - body.center()) / body.scale();
    let mut out = Vec::with_capacity(n);
    for dir in directions(n) {
        let mut hi = 1.0;
        let mut tries = 0;
        while p.value(&(u0 + dir * hi)) <= 1.0 {
            hi *= 2.0;
            tries += 1;
            if tries > 60 {
                return Err(Error::Numerical("a ray from the interior point never leaves the body".into()));
            }
        }
        let mut lo = 0.0;
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if p.value(&(u0 + dir * mid)) <= 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo < 1e-13 * hi {
                break;
            }
        }
        out.push(Point3::from(posed.from_normalized(&(u0 + dir * hi))));
    }
    Ok(out)
}

/// World-frame axis-aligned box containing a posed body: the body-frame box of
/// [`volume::bounding_box`] with its 8 corners mapped by the pose.
fn world_box(body: &Body, pose: &Isometry3) -> Result<(Vector3, Vector3)> {
    body.world_aabb(pose).ok_or_else(|| Error::Numerical("no bounding box for a nonconvex body".into()))
}

/// Finds one sos-convex body `{x : p((x − c)/s) ≤ 1}` of degree 2d containing every posed body
/// (paper §V, eqs. "p.sosconvex", "s.procedure", "tau.sos"), maximizing log det P.
///
/// `bodies` are `(body, pose)` pairs (pose: body frame → world, meters). The result lives in world
/// coordinates (use it at identity pose); its center c and scale s are the midpoint and half
/// diagonal of the union of the bodies' bounding boxes. Its report holds method `"containment"`,
/// the solver status, times, the number of boundary samples checked (`num_points`), the largest
/// p on them and the rescale that made it ≤ 1, the Monte Carlo volume, the convexity margin, and
/// notes with m, 2d and 2k. Progress is reported through `progress` (stages Hull = normalizing,
/// Build, Solve, Verify, Volume, Done).
///
/// # Errors
/// [`Error::InvalidArgument`] naming a settings field or `bodies` (empty, or a non-finite pose
/// `bodies[i].pose`); [`Error::ResourceExhausted`] above [`MAX_CONTAINED_BODIES`] bodies;
/// [`Error::Numerical`] when Clarabel ends with a status other than `Solved` / `AlmostSolved` or
/// the result is not a bounded body.
pub fn contain_bodies(
    bodies: &[(&Body, Isometry3)],
    settings: &ContainmentSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    let start = std::time::Instant::now();
    settings.validate()?;
    if bodies.is_empty() {
        return Err(Error::invalid("bodies", "need at least one body to contain"));
    }
    if bodies.len() > MAX_CONTAINED_BODIES {
        return Err(Error::ResourceExhausted(format!(
            "at most {MAX_CONTAINED_BODIES} bodies per containment, got {}",
            bodies.len()
        )));
    }
    for (i, (body, _)) in bodies.iter().enumerate() {
        // The top-degree form of 1 − p − τᵢ(1 − gᵢ) must be nonnegative; with 2k + deg gᵢ < 2d it
        // is −p's, so p's top form would vanish and log det P = −∞ (the paper's 2k = 2d − deg gᵢ).
        if settings.multiplier_degree + body.degree() < settings.degree {
            return Err(Error::invalid(
                "multiplier_degree",
                format!(
                    "2k + deg g must be at least 2d = {}: body {i} has degree {}, so 2k must be at least {}",
                    settings.degree,
                    body.degree(),
                    settings.degree - body.degree()
                ),
            ));
        }
    }
    for (i, (_, pose)) in bodies.iter().enumerate() {
        let q = pose.rotation.quaternion();
        if !(pose.translation.vector.iter().all(|v| v.is_finite()) && q.coords.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(format!("bodies[{i}].pose"), "must be finite"));
        }
    }

    report(progress, FitStage::Hull, 0.0, format!("normalizing: union of {} bounding boxes", bodies.len()));
    let mut lo = Vector3::repeat(Real::INFINITY);
    let mut hi = Vector3::repeat(Real::NEG_INFINITY);
    for (body, pose) in bodies {
        let (a, b) = world_box(body, pose)?;
        lo = lo.inf(&a);
        hi = hi.sup(&b);
    }
    let center = (lo + hi) * 0.5;
    let scale = 0.5 * (hi - lo).norm();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::Numerical(format!("the union of bounding boxes has scale {scale}")));
    }
    // gᵢ(v) = pᵢ(Aᵢ(c + s v) + bᵢ) = pᵢ((s Aᵢ) v + (Aᵢ c + bᵢ)).
    let g: Vec<Polynomial> = bodies
        .iter()
        .map(|(body, pose)| {
            let posed = body.posed(pose);
            let a = *posed.linear();
            body.polynomial().compose_affine(&(a * scale), &posed.to_normalized(&center))
        })
        .collect();

    let d = settings.degree / 2;
    report(
        progress,
        FitStage::Build,
        0.05,
        format!(
            "building the degree-{} containment program of {} bodies (multipliers of degree {})",
            settings.degree,
            bodies.len(),
            settings.multiplier_degree
        ),
    );
    // The boundary samples every result is checked on (normalized coordinates); they also set
    // the monomial basis scales of the program.
    let samples = BOUNDARY_SAMPLES_PER_BODY;
    let mut checks = Vec::with_capacity(samples * bodies.len());
    for (body, pose) in bodies {
        for x in boundary_points(body, pose, samples)? {
            checks.push((x.coords - center) / scale);
        }
    }
    let problem = GramProgram::build(
        &ProblemSpec::log_det_p(d),
        Containment::Bodies { polynomials: &g, multiplier_degree: settings.multiplier_degree, samples: &checks },
    )?;

    report(
        progress,
        FitStage::Solve,
        0.1,
        format!("Clarabel: {} variables, {} rows", problem.num_vars, problem.num_rows()),
    );
    let sol = problem.solve_with_retry(&settings.solver_settings(), None, &mut |it, cost| {
        let frac = 0.1 + 0.7 * (it as Real / 40.0).min(1.0);
        report(progress, FitStage::Solve, frac, format!("Clarabel iteration {it}, log det P ≈ {:.6}", -cost));
    })?;
    let status = usable_status(sol.status, "containment")?;

    super::cancel::check()?;
    report(
        progress,
        FitStage::Verify,
        0.8,
        format!(
            "Clarabel {status} in {} iterations; checking p ≤ 1 on {samples} boundary points per body",
            sol.iterations
        ),
    );
    let mut poly = problem.polynomial_of_gram(&problem.gram(&sol.x))?;
    let (max_value, rescale) = rescale_to_contain(&mut poly, &checks)?;
    let margin = (problem.convexity_gram(&sol.x) / rescale)
        .symmetric_eigenvalues()
        .iter()
        .copied()
        .fold(Real::INFINITY, Real::min);

    let mut fit_report = FitReport {
        method: "containment".into(),
        solver_status: status,
        solve_seconds: sol.solve_seconds,
        solver_certificate: Some(sol.certificate),
        solve: Some(sublevel_core::body::SolveDetails {
            iterations: sol.iterations,
            linear_solver: Some(settings.linear_solver),
            frame: None,
            rows_per_round: Vec::new(),
            contained_bodies: bodies.len(),
            multiplier_degree: Some(settings.multiplier_degree),
        }),
        num_points: checks.len(),
        max_point_value: max_value,
        containment_rescale: rescale,
        convexity_margin: Some(margin),
        notes: vec![
            format!(
                "containment of m = {} bodies, 2d = {}, 2k = {} (s.procedure degrees {:?}); Clarabel {} iterations ({})",
                bodies.len(),
                settings.degree,
                settings.multiplier_degree,
                problem.sprocedure_degrees,
                sol.iterations,
                settings.linear_solver.name()
            ),
            "normalized by center = midpoint of the union of bounding boxes, scale = half its diagonal".into(),
        ],
        ..Default::default()
    };
    let body = Body::new(poly, [center.x, center.y, center.z], scale, fit_report.clone())
        .map_err(|e| Error::Numerical(format!("the containing polynomial is not a bounded convex body: {e}")))?;

    super::cancel::check()?;
    report(progress, FitStage::Volume, 0.85, format!("Monte Carlo volume, {} samples", settings.volume_samples));
    let interior = (body.interior_point().coords - center) / scale;
    let est = volume::monte_carlo_volume(body.polynomial(), &interior, settings.volume_samples, settings.seed)?;
    let s3 = scale.powi(3);
    fit_report.volume = est.volume * s3;
    fit_report.volume_std_error = est.std_error * s3;
    fit_report.total_seconds = start.elapsed().as_secs_f64();
    let mut body = body;
    body.report = fit_report;
    report(
        progress,
        FitStage::Done,
        1.0,
        format!("volume {:.4} ± {:.4}", body.report.volume, body.report.volume_std_error),
    );
    Ok(body)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::body::ellipsoid;

    #[test]
    fn settings_and_inputs_are_validated_by_field() {
        let e = ellipsoid([0.0; 3], [1.0; 3]).unwrap();
        let one = [(&e, Isometry3::identity())];
        for (s, field) in [
            (ContainmentSettings::default().with_degree(3), "degree"),
            (ContainmentSettings::default().with_degree(8), "degree"),
            (ContainmentSettings::default().with_multiplier_degree(1), "multiplier_degree"),
            (ContainmentSettings::default().with_multiplier_degree(4), "multiplier_degree"),
            (ContainmentSettings::default().with_volume_samples(0), "volume_samples"),
            (ContainmentSettings::default().with_solver_tolerance(Real::NAN), "solver_tolerance"),
        ] {
            match contain_bodies(&one, &s, &mut |_| {}) {
                Err(Error::InvalidArgument { field: f, .. }) => assert_eq!(f, field),
                other => panic!("expected InvalidArgument({field}), got {other:?}"),
            }
        }
        match contain_bodies(&[], &ContainmentSettings::default(), &mut |_| {}) {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "bodies"),
            other => panic!("expected InvalidArgument(bodies), got {other:?}"),
        }
        let many: Vec<(&Body, Isometry3)> = (0..=MAX_CONTAINED_BODIES).map(|_| (&e, Isometry3::identity())).collect();
        assert!(matches!(
            contain_bodies(&many, &ContainmentSettings::default(), &mut |_| {}),
            Err(Error::ResourceExhausted(_))
        ));
    }
}
