//! The a-posteriori check of a level-0 solution (module docs of [`super`], "A-posteriori
//! check"): fold the coefficient residual into the Gram blocks so that the sos identity holds
//! exactly, and lower γ by the blocks' negative eigenvalues times a bound on ‖z(w)‖² over the
//! bodies (from [`radius_estimate`]).

use super::level0::Level0Solution;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::poly::gram::{triangle_index, triangle_len, GramStructure};

/// Estimated radius of a body in its normalized coordinates, max ‖u‖ over {p ≤ 1}: the largest
/// boundary distance along 256 rays (Fibonacci directions) from the interior point, plus 10 %.
/// An estimate, not a bound (a thin spike between rays could be missed).
pub(super) fn radius_estimate(body: &Body) -> Real {
    let c = body.posed(&Isometry3::identity()).to_normalized(&body.interior_point().coords);
    let p = body.polynomial();
    let n = 256;
    let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
    let mut r_max: Real = 0.0;
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
        let r = (1.0 - z * z).sqrt();
        let dir = Vector3::new(r * (golden * i as Real).cos(), r * (golden * i as Real).sin(), z);
        let mut hi = 1.0;
        while p.value(&(c + dir * hi)) <= 1.0 && hi < 1e6 {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if p.value(&(c + dir * mid)) <= 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        r_max = r_max.max((c + dir * hi).norm());
    }
    1.1 * r_max
}

/// Result of the a-posteriori check of a level-0 solution.
pub(super) struct Verification {
    /// Max |coefficient residual| of the sos identity with the returned (γ, τ ≥ 0, Q).
    pub(super) residual: Real,
    /// Smallest eigenvalue over the Gram blocks after folding the residual into them.
    pub(super) min_eigenvalue: Real,
    /// γ + Σ_b min(λ_b, 0) · Z_b: a lower bound on the program's true optimum provided Z_b bounds
    /// ‖z_b(w)‖² on the feasible set.
    pub(super) bound: Real,
}

/// Checks a level-0 solution a posteriori: takes the Gram blocks from Clarabel's PSD slacks
/// (strictly inside the cone), the multipliers clamped at 0, computes the coefficient residual
/// r = Σ_b z_bᵀQ_b z_b − (f − γ − Σₖ τₖ(1 − gₖ)), folds each r_α into one Gram entry of a block
/// holding w^α (a diagonal entry when possible), so that the identity holds exactly with the
/// corrected blocks Q_b', and bounds f − γ ≥ Σ_b λ_min(Q_b') ‖z_b‖² on the feasible set.
pub(super) fn verify_level0(
    blocks: &[GramStructure],
    objective: &[Real],
    constraints: &[&[Real]],
    level0: &Level0Solution,
    z_bounds: &[Real],
) -> Verification {
    let sol = &level0.sol;
    let gamma = sol.x[level0.gamma];
    let taus: Vec<Real> = level0.multipliers.iter().map(|&c| sol.x[c].max(0.0)).collect();
    let mut grams: Vec<nalgebra::DMatrix<Real>> = blocks
        .iter()
        .zip(&level0.psd_rows)
        .map(|(g, &row)| {
            sublevel_core::poly::gram::unpack_triangle(&sol.s[row..row + triangle_len(g.size())], g.size())
        })
        .collect();
    let nf = objective.len();
    let mut r = vec![0.0; nf];
    for (g, q) in blocks.iter().zip(&grams) {
        for (rk, ck) in r.iter_mut().zip(g.polynomial_of(q)) {
            *rk += ck;
        }
    }
    for (alpha, rk) in r.iter_mut().enumerate() {
        let mut rhs = objective[alpha];
        if alpha == 0 {
            rhs -= gamma;
        }
        for (tau, g) in taus.iter().zip(constraints) {
            rhs -= tau * (if alpha == 0 { 1.0 } else { 0.0 } - g[alpha]);
        }
        *rk -= rhs;
    }
    let residual = r.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
    // Fold: subtract r_α from one entry (i, j) with z_i z_j = w^α, a diagonal one when possible.
    let mut target: Vec<Option<(usize, usize, usize)>> = vec![None; nf];
    for (b, g) in blocks.iter().enumerate() {
        for j in 0..g.size() {
            for i in 0..=j {
                let slot = &mut target[g.product_of_entry[triangle_index(i, j)]];
                if slot.is_none() || (i == j && slot.is_some_and(|(_, si, sj)| si != sj)) {
                    *slot = Some((b, i, j));
                }
            }
        }
    }
    for (&ra, t) in r.iter().zip(&target) {
        match *t {
            Some((b, i, j)) if i == j => grams[b][(i, i)] -= ra,
            Some((b, i, j)) => {
                grams[b][(i, j)] -= 0.5 * ra;
                grams[b][(j, i)] -= 0.5 * ra;
            }
            None => {}
        }
    }
    let mut min_eigenvalue = Real::INFINITY;
    let mut bound = gamma;
    for (q, z) in grams.into_iter().zip(z_bounds) {
        let lambda = q.symmetric_eigenvalues().min();
        min_eigenvalue = min_eigenvalue.min(lambda);
        bound += lambda.min(0.0) * z;
    }
    Verification { residual, min_eigenvalue, bound }
}
