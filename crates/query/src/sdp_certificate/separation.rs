//! The separating-hyperplane certificate: a lower bound on the distance from two witness
//! candidates, as the width of the slab between two supporting planes of one normal. Each
//! supporting plane is a level-0 SDP over one body alone (its support function,
//! [`support_excess`]), so the program never mixes the two bodies' scales.

use super::frame::Frame;
use super::level0::{embed, solve_level0, unit_exponent};
use super::verify::{radius_estimate, verify_level0};
use super::CertificateParams;
use crate::{Error, Result};
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::poly::gram::GramStructure;

/// Certificate of a separating hyperplane between two posed bodies (the dual view of paper eq.
/// "distance"): for witness candidates x̄ (on A), ȳ (on B) and n = (ȳ − x̄)/‖ȳ − x̄‖,
///
/// ```text
/// d(A, B) ≥ n·(ȳ − x̄) − e_A − e_B,   e_A = max_{x ∈ A} n·(x − x̄),   e_B = max_{y ∈ B} n·(ȳ − y)
/// ```
///
/// (the slab between the two supporting planes of normal n is free of both bodies). Each excess is
/// a level-0 SDP in three variables over one body alone, exact for sos-convex bodies (Jensen's
/// inequality), and verified a posteriori like the other certificates. At Newton's witnesses the
/// excesses vanish and the bound equals the distance. Used when the joint six-variable certificate
/// is inaccurate: its Gram matrix mixes both bodies' scales (a 1e-3 slab beside a 1 m body), these
/// programs see one body each.
#[derive(Clone, Debug)]
pub struct SeparationCertificate {
    /// n·(ȳ − x̄) − e_A − e_B with the solver's excesses (meters).
    pub lower_bound: Real,
    /// The same with the a-posteriori verified excess bounds: a proven lower bound (meters).
    pub verified_lower_bound: Real,
    /// (e_A, e_B) from the solver (meters, ≥ 0 up to its tolerance).
    pub excess: (Real, Real),
    /// Smallest eigenvalue over both corrected Gram matrices (meters).
    pub gram_min_eigenvalue: Real,
    /// The worse of the two Clarabel statuses (`"Solved"` unless one is `"AlmostSolved"`).
    pub solver_status: sublevel_core::conic::SdpStatus,
    /// Seconds inside Clarabel (both programs).
    pub solve_seconds: Real,
}

/// [`SeparationCertificate`] for witness candidates `x` (on A) and `y` (on B), world frame.
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] naming `witnesses` when x = y (no normal) or a parameter of
/// `params`; [`sublevel_core::Error::Numerical`] when Clarabel fails on either program.
pub fn certify_separation(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    x: &Point3,
    y: &Point3,
    params: &CertificateParams,
) -> Result<SeparationCertificate> {
    params.validate()?;
    let gap = y - x;
    let len = gap.norm();
    if !(len > 0.0 && len.is_finite()) {
        return Err(Error::invalid("witnesses", "the two witness points coincide: no separating normal"));
    }
    let n = gap / len;
    let ea = support_excess(a, pose_a, &x.coords, &n, params)?;
    let eb = support_excess(b, pose_b, &y.coords, &-n, params)?;
    let worse =
        if ea.solver_status == sublevel_core::conic::SdpStatus::Solved { eb.solver_status } else { ea.solver_status };
    Ok(SeparationCertificate {
        lower_bound: len - ea.excess - eb.excess,
        verified_lower_bound: len - ea.verified_excess - eb.verified_excess,
        excess: (ea.excess, eb.excess),
        gram_min_eigenvalue: ea.gram_min_eigenvalue.min(eb.gram_min_eigenvalue),
        solver_status: worse,
        solve_seconds: ea.solve_seconds + eb.solve_seconds,
    })
}

/// One body's support excess `e = max_{x ∈ body} m·(x − o)` (meters), as solved and as verified:
/// the half of a [`SeparationCertificate`] that concerns one body.
#[derive(Clone, Debug)]
struct SupportExcess {
    /// e from the solver (−γ* of the level-0 program; ≥ 0 up to its tolerance when o is on the
    /// body's boundary, since o itself is feasible).
    excess: Real,
    /// An upper bound on e from the a-posteriori check (the program's verified lower bound on
    /// −e, negated), so that subtracting it from the gap keeps the distance bound proven.
    verified_excess: Real,
    /// Smallest eigenvalue of the corrected Gram matrix (meters; ≥ 0 means an exact certificate).
    gram_min_eigenvalue: Real,
    /// Clarabel's status (`"Solved"` or `"AlmostSolved"`; other statuses are errors).
    solver_status: sublevel_core::conic::SdpStatus,
    /// Seconds inside Clarabel.
    solve_seconds: Real,
}

/// max_{x ∈ body} m·(x − o) by the level-0 SDP `max γ' s.t. −m·(x − o) − γ − τ(1 − p) sos` in the
/// body's rotation and scale, centered at o (world frame, meters; `m` a unit vector).
fn support_excess(
    body: &Body,
    pose: &Isometry3,
    o: &Vector3,
    m: &Vector3,
    params: &CertificateParams,
) -> Result<SupportExcess> {
    let rotation = *pose.rotation.to_rotation_matrix().matrix();
    let frame = Frame { origin: *o, rotation, scale: body.scale() };
    let d = body.degree() / 2;
    let gram = GramStructure::new(3, d);
    let mut objective = vec![0.0; gram.full_basis.len()];
    // −m·(x − o) with x − o = scale · R w.
    let mw = rotation.transpose() * m * (-frame.scale);
    for i in 0..3 {
        objective[gram.index_of[&unit_exponent(3, &[i])]] = mw[i];
    }
    let constraint = embed(&frame.compose(body, pose), &gram, 0);
    let blocks = [gram];
    let sol = solve_level0(&blocks, &objective, &[constraint.as_slice()], params)?;
    let v_origin = body.posed(pose).to_normalized(o);
    let w_bound = radius_estimate(body) + v_origin.norm();
    let z_bound = (0..=d).map(|k| w_bound.powi(2 * k as i32)).sum::<Real>();
    let check = verify_level0(&blocks, &objective, &[constraint.as_slice()], &sol, &[z_bound]);
    let gamma = sol.sol.x[sol.gamma];
    Ok(SupportExcess {
        excess: -gamma,
        verified_excess: -check.bound,
        gram_min_eigenvalue: check.min_eigenvalue,
        solver_status: sol.sol.status.into(),
        solve_seconds: sol.sol.solve_seconds,
    })
}
