//! The growth certificate (module docs of [`super`], "Growth" and "Conditioning"): `max γ` such
//! that `p₁' − γ − τ(1 − p₂')` is sos in three variables w, both polynomials expanded in the affine
//! frame `x = o + ρ R w` (body 2's normalized frame, then by default one centered at the first
//! pass's minimizer).

use super::frame::Frame;
use super::level0::{embed, solve_level0, Level0Solution};
use super::verify::{radius_estimate, verify_level0};
use super::witness::moments_first_order;
use super::CertificateParams;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::poly::gram::GramStructure;
use sublevel_core::Result;

/// Level-0 SDP bound on d(p₁‖p₂).
#[derive(Clone, Debug)]
pub struct GrowthCertificate {
    /// γ*: lower bound on d(p₁‖p₂) (dimensionless; exact for sos-convex bodies).
    pub value: Real,
    /// Multiplier τ ≥ 0 (0 when the constraint is inactive).
    pub tau: Real,
    /// The minimizer x* in world coordinates, recovered from the first-order moments; `None` when
    /// not finite or infeasible by more than [`CertificateParams::witness_feasibility_tolerance`].
    pub minimizer: Option<Point3>,
    /// The same first-order moments mapped to a world point without the feasibility filter (`None`
    /// only when not finite); for nonconvex bodies it may lie outside body 2.
    pub moment_minimizer: Option<Point3>,
    /// Clarabel's final status (`Solved` or `AlmostSolved`; other statuses are errors).
    pub solver_status: sublevel_core::conic::SdpStatus,
    /// Seconds inside Clarabel (both passes).
    pub solve_seconds: Real,
    /// Interior-point iterations (both passes).
    pub iterations: u32,
    /// Side N of the Gram matrix (C(3 + d, d)).
    pub gram_size: usize,
    /// A-posteriori lower bound on d(p₁‖p₂) from the returned certificate: `value` when the Gram
    /// matrix, corrected so that the sos identity holds exactly, is PSD; otherwise `value` minus
    /// |λ_min| times a bound on ‖z(w)‖² over body 2 (which uses an estimate of body 2's radius, so
    /// this is a careful, not a rigorous, bound). Compare it with `value` to judge the certificate.
    pub verified_value: Real,
    /// Max |coefficient residual| of the sos identity p₁' − γ − τ(1 − p₂') = z(w)ᵀQz(w) as returned
    /// (objective units, in the certificate's frame).
    pub residual: Real,
    /// Smallest eigenvalue of the corrected Gram matrix (≥ 0 means the identity is an exact sos
    /// certificate up to floating-point rounding).
    pub gram_min_eigenvalue: Real,
}

/// Certifies d(p₁‖p₂) for body `p1` under `pose1` and body `p2` under `pose2` (level-0 analogue
/// of paper eq. "overlap") with [`CertificateParams::default`].
///
/// # Errors
/// [`sublevel_core::Error::Numerical`] when Clarabel returns no usable solution.
pub fn certify_growth(p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3) -> Result<GrowthCertificate> {
    certify_growth_with_params(p1, pose1, p2, pose2, &CertificateParams::default())
}

/// [`certify_growth`] with explicit solver settings.
///
/// Expands both bodies' polynomials in the certificate's variables (module docs, "Conditioning":
/// body 2's normalized frame, then by default a second pass centered at the first pass's
/// minimizer), builds the 3-variable Gram form of half-degree d = max(deg p₁, deg p₂)/2, maximizes
/// γ, recovers the minimizer from the moments and checks the certificate a posteriori.
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] naming `params.tolerance` / `params.max_iterations`;
/// [`sublevel_core::Error::Numerical`] naming Clarabel's status when it is neither `Solved` nor
/// `AlmostSolved`.
pub fn certify_growth_with_params(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    params: &CertificateParams,
) -> Result<GrowthCertificate> {
    params.validate()?;
    let r2 = *pose2.rotation.to_rotation_matrix().matrix();
    let (mut seconds, mut iterations) = (0.0, 0);
    let frame = if params.recenter {
        // Pass 1: body 2's normalized frame, loose tolerance, only to locate the minimizer.
        let loose = CertificateParams { tolerance: params.tolerance.max(params.presolve_tolerance), ..*params };
        let center = match solve_growth_in(p1, pose1, p2, pose2, &Frame::of_body(p2, pose2), &loose) {
            Ok(first) => {
                seconds += first.sol.sol.solve_seconds;
                iterations += first.sol.sol.iterations;
                first.minimizer
            }
            Err(_) => None,
        }
        .unwrap_or_else(|| growth_center_guess(p1, pose1, p2, pose2));
        Frame { origin: center, rotation: r2, scale: params.recenter_scale * p1.scale().min(p2.scale()) }
    } else {
        Frame::of_body(p2, pose2)
    };
    let run = solve_growth_in(p1, pose1, p2, pose2, &frame, params)?;
    seconds += run.sol.sol.solve_seconds;
    iterations += run.sol.sol.iterations;
    // Feasible-set bound for the a-posteriori check: ‖w‖ ≤ (s₂/ρ)(R₂ + ‖v_o‖), v_o the frame
    // origin in body 2's normalized coordinates.
    let v_origin = p2.posed(pose2).to_normalized(&frame.origin);
    let w_bound = p2.scale() / frame.scale * (radius_estimate(p2) + v_origin.norm());
    let d = run.blocks[0].half_basis.iter().map(|e| e.iter().map(|&k| k as usize).sum::<usize>()).max().unwrap_or(0);
    let z_bound = (0..=d).map(|k| w_bound.powi(2 * k as i32)).sum::<Real>();
    let check = verify_level0(&run.blocks, &run.objective, &[run.constraint.as_slice()], &run.sol, &[z_bound]);
    let sol = &run.sol.sol;
    Ok(GrowthCertificate {
        value: sol.x[run.sol.gamma],
        tau: sol.x[run.sol.multipliers[0]],
        minimizer: run.minimizer.map(Point3::from),
        moment_minimizer: run.moment_minimizer.map(Point3::from),
        solver_status: sol.status.into(),
        solve_seconds: seconds,
        iterations,
        gram_size: run.blocks[0].size(),
        verified_value: check.bound,
        residual: check.residual,
        gram_min_eigenvalue: check.min_eigenvalue,
    })
}

/// One solved growth program with its data (for the a-posteriori check).
struct GrowthRun {
    blocks: [GramStructure; 1],
    objective: Vec<Real>,
    constraint: Vec<Real>,
    sol: Level0Solution,
    /// Moment-recovered minimizer (world), if finite and feasible.
    minimizer: Option<Vector3>,
    /// The same moments without the feasibility filter, if finite.
    moment_minimizer: Option<Vector3>,
}

/// Solves the growth program in `frame`'s variables.
fn solve_growth_in(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    frame: &Frame,
    params: &CertificateParams,
) -> Result<GrowthRun> {
    let d = p1.degree().max(p2.degree()) / 2;
    let gram = GramStructure::new(3, d);
    let objective = embed(&frame.compose(p1, pose1), &gram, 0);
    let constraint = embed(&frame.compose(p2, pose2), &gram, 0);
    let blocks = [gram];
    let sol = solve_level0(&blocks, &objective, &[constraint.as_slice()], params)?;
    let b2 = p2.posed(pose2);
    let moment_minimizer = moments_first_order(&blocks[0], &sol, 3).map(|w| frame.world(&w));
    let minimizer = moment_minimizer.filter(|x| b2.value(x) <= 1.0 + params.witness_feasibility_tolerance);
    Ok(GrowthRun { blocks, objective, constraint, sol, minimizer, moment_minimizer })
}

/// A geometric guess of the growth minimizer: p₁'s interior point if it lies in body 2, else where
/// the segment from body 2's interior point towards it leaves body 2.
fn growth_center_guess(p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3) -> Vector3 {
    let c1 = p1.posed(pose1).interior_point();
    let b2 = p2.posed(pose2);
    let c2 = b2.interior_point();
    if b2.value(&c1) <= 1.0 {
        return c1;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if b2.value(&(c2 + (c1 - c2) * mid)) <= 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    c2 + (c1 - c2) * lo
}
