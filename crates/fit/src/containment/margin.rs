//! Certified containment of one body in another (paper §V, eq. "s.procedure" with p fixed): the
//! check that a compound body's parent holds each of its children, which the tree queries rely on
//! (a parent's distance is a lower bound of its leaves' only when it contains them).
//!
//! For the outer body {p ≤ 1} and the inner body {g ≤ 1}, both in one frame:
//!
//! ```text
//! maximize γ   s.t.   1 − p(x) − γ − τ(x)(1 − g(x))  sos,   τ sos of degree 2k
//! ```
//!
//! On the inner body 1 − g ≥ 0 and τ ≥ 0, so 1 − p ≥ γ there: γ ≥ 0 certifies that the inner body
//! lies in the outer one, and γ is a lower bound of 1 − max p over the inner body (tight for
//! ellipsoids at 2k = 0, by the S-lemma). The program is stated in the inner body's normalized
//! frame (its bounding box centered and scaled to the unit ball), which keeps it well conditioned.

use crate::{Error, Result};
use sublevel_core::body::Body;
use sublevel_core::conic::{quiet_settings, ConicBuilder, Row, SdpStatus};
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::poly::gram::{gram_weight, triangle_index, GramStructure};
use sublevel_core::poly::Polynomial;

/// Slack on the certified margin (dimensionless, in units of the outer polynomial's value): a
/// containment is accepted when γ ≥ −`CONTAINMENT_SLACK`. A parent that the fits made touch its
/// children has γ = 0 up to the solver's accuracy (about 10⁻⁸); this slack lets the inner body
/// reach at most p ≤ 1 + 10⁻⁶ of the outer one, about 10⁻⁶/2d of the outer body's size.
pub const CONTAINMENT_SLACK: Real = 1e-6;

/// Clarabel's tolerances for the margin program.
const SOLVER_TOLERANCE: Real = 1e-9;
/// Clarabel's iteration cap for the margin program.
const SOLVER_ITERATIONS: u32 = 200;

/// The certified containment margin γ of `inner` in `outer`, both at the identity pose (one
/// frame, meters): the largest γ of the program in the module docs with a multiplier τ of degree
/// `multiplier_degree` (0: a nonnegative scalar; 2: a sos quadratic). γ ≥ 0 certifies that every
/// point of `inner` lies in `outer`; γ < 0 says this certificate does not exist at that degree
/// (not that the bodies stick out: try a higher degree).
///
/// The degree is raised to at least deg p − deg g (below it the program is infeasible: the top
/// form of 1 − p would be negative).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `multiplier_degree` (odd, or above 6); [`Error::Numerical`]
/// for a nonconvex inner body (no bounding box), or when Clarabel ends with a status other than
/// `Solved` / `AlmostSolved` (`Infeasible` included: no certificate at that degree).
pub fn containment_margin(outer: &Body, inner: &Body, multiplier_degree: usize) -> Result<Real> {
    if !multiplier_degree.is_multiple_of(2) || multiplier_degree > 6 {
        return Err(Error::invalid("multiplier_degree", format!("must be 0, 2, 4 or 6, got {multiplier_degree}")));
    }
    let id = Isometry3::identity();
    let (lo, hi) = inner
        .world_aabb(&id)
        .ok_or_else(|| Error::Numerical("containment margin: the inner body has no bounding box".into()))?;
    let center = (lo + hi) * 0.5;
    let scale = 0.5 * (hi - lo).norm();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::Numerical(format!("containment margin: the inner body's box has scale {scale}")));
    }
    // Both polynomials in v = (x − center)/scale: q(v) = p(A(center + scale v) + b).
    let in_frame = |body: &Body| {
        let posed = body.posed(&id);
        body.polynomial().compose_affine(&(*posed.linear() * scale), &posed.to_normalized(&center))
    };
    let (p, g) = (in_frame(outer), in_frame(inner));
    let two_k = multiplier_degree.max(p.degree().saturating_sub(g.degree()));
    let two_k = two_k + two_k % 2;
    solve_margin(&p, &g, two_k)
}

/// Solves `max γ s.t. 1 − p − γ − τ(1 − g) = z(v)ᵀ Q z(v), Q ⪰ 0, τ = z_k(v)ᵀ T z_k(v), T ⪰ 0` with
/// τ of degree `two_k`; returns γ.
fn solve_margin(p: &Polynomial, g: &Polynomial, two_k: usize) -> Result<Real> {
    let dd = p.degree().max(two_k + g.degree());
    let dd = dd + dd % 2;
    let gram = GramStructure::new(3, dd / 2);
    let tau = GramStructure::new(3, two_k / 2);
    let index = |e: &[u8]| gram.index_of.get(e).copied();
    let mut builder = ConicBuilder::new();
    let gamma = builder.add_variables(1);
    builder.set_objective(gamma, -1.0);
    let col_t = builder.add_psd_variable(tau.size());
    let col_q = builder.add_psd_variable(gram.size());
    let mut rows: Vec<Row> = vec![Vec::new(); gram.full_basis.len()];
    for j in 0..gram.size() {
        for i in 0..=j {
            let k = triangle_index(i, j);
            rows[gram.product_of_entry[k]].push((col_q + k, gram_weight(i, j)));
        }
    }
    rows[0].push((gamma, 1.0));
    // τ (1 − g): entry (a, b) of T times z_a z_b times each term of 1 − g.
    let h = crate::sdp::program::one_minus_terms(g);
    for b in 0..tau.size() {
        for a in 0..=b {
            let (za, zb) = (&tau.half_basis[a], &tau.half_basis[b]);
            for (e, hc) in &h {
                let mono = [za[0] + zb[0] + e[0], za[1] + zb[1] + e[1], za[2] + zb[2] + e[2]];
                let row =
                    index(&mono).ok_or_else(|| Error::Numerical("containment margin: degree bookkeeping".into()))?;
                rows[row].push((col_t + triangle_index(a, b), gram_weight(a, b) * hc));
            }
        }
    }
    // Right side: the coefficients of 1 − p.
    let mut rhs = vec![0.0; gram.full_basis.len()];
    rhs[0] = 1.0;
    for (e, &c) in p.exponents().iter().zip(p.coefficients()) {
        let row = index(e).ok_or_else(|| Error::Numerical("containment margin: degree bookkeeping".into()))?;
        rhs[row] -= c;
    }
    builder.add_equalities(rows, rhs);
    let sol = builder.solve(quiet_settings(SOLVER_TOLERANCE, SOLVER_ITERATIONS))?;
    let status = SdpStatus::from(sol.status);
    if !status.is_usable() {
        return Err(Error::Numerical(format!(
            "containment margin: Clarabel ended with status {status} after {} iterations",
            sol.iterations
        )));
    }
    Ok(sol.x[gamma])
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::body::{ellipsoid, Body};

    /// A sphere of radius `r` centered at `c` (meters).
    fn sphere(c: [Real; 3], r: Real) -> Body {
        ellipsoid(c, [r; 3]).unwrap()
    }

    #[test]
    fn nested_spheres_have_the_closed_form_margin() {
        // Sphere of radius 1 at the origin; inner sphere of radius r centered at distance t:
        // max p over the inner sphere = (t + r)², so the margin is 1 − (t + r)² (exact at 2k = 0,
        // the S-lemma).
        let outer = sphere([0.0; 3], 1.0);
        for (t, r) in [(0.0, 0.5), (0.3, 0.4), (0.5, 0.5), (0.2, 0.9), (2.0, 0.5)] {
            let inner = sphere([t, 0.0, 0.0], r);
            let gamma = containment_margin(&outer, &inner, 0).unwrap();
            let exact = 1.0 - (t + r) * (t + r);
            assert!((gamma - exact).abs() < 1e-6, "t = {t}, r = {r}: γ = {gamma}, closed form {exact}");
        }
    }

    #[test]
    fn a_parent_smaller_than_its_children_has_the_closed_form_negative_margin() {
        // The hostile tree: a 0.1 m root whose children are 1 m spheres 5 m away.
        // max p over the child = (6/0.1)² = 3600, so γ ≤ 1 − 3600.
        let root = sphere([0.0; 3], 0.1);
        for x in [-5.0, 5.0] {
            let gamma = containment_margin(&root, &sphere([x, 0.0, 0.0], 1.0), 0).unwrap();
            assert!(gamma < -3000.0, "γ = {gamma}");
        }
        // A root of radius 2.5 covering the children only partly: max p = (6/2.5)² = 5.76.
        let gamma = containment_margin(&sphere([0.0; 3], 2.5), &sphere([5.0, 0.0, 0.0], 1.0), 0).unwrap();
        assert!((gamma - (1.0 - 5.76)).abs() < 1e-5, "γ = {gamma}");
        assert!(containment_margin(&root, &root, 1).is_err());
    }
}
