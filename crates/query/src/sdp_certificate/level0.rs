//! The generic level-0 sos program shared by every certificate: given the objective f and the
//! constraints gₖ as coefficients in a common monomial basis, and the Gram blocks the sos
//! polynomial is written with,
//!
//! ```text
//! max γ   s.t.   f − γ − Σₖ τₖ (1 − gₖ) = Σ_b z_b(w)ᵀ Q_b z_b(w),   Q_b ⪰ 0,   τₖ ≥ 0
//! ```
//!
//! one equality row per monomial, one PSD cone per block, solved by Clarabel. Solved and
//! AlmostSolved are solutions; every other status is an error naming it.

use super::CertificateParams;
use crate::{Error, Result};
use sublevel_core::conic::{quiet_settings, ConicBuilder, ConicSolution, Row};
use sublevel_core::math::Real;
use sublevel_core::poly::gram::{gram_weight, triangle_index, GramStructure};
use sublevel_core::poly::Polynomial;

/// Columns and dual positions of a solved level-0 program.
pub(super) struct Level0Solution {
    /// Clarabel's solution (primal x, slacks s, duals z, status, time).
    pub(super) sol: ConicSolution,
    /// Column of γ in `sol.x`.
    pub(super) gamma: usize,
    /// Columns of the multipliers τₖ in `sol.x`, one per constraint.
    pub(super) multipliers: Vec<usize>,
    /// First row (in `sol.s`) of each Gram block's PSD slack.
    pub(super) psd_rows: Vec<usize>,
    /// For each monomial of the full basis, its equality row's index in `sol.z` (if it has one).
    pub(super) row_of: Vec<Option<usize>>,
}

/// Solves `max γ s.t. f − γ − Σₖ τₖ (1 − gₖ) = Σ_b z_b(w)ᵀ Q_b z_b(w), Q_b ⪰ 0, τ ≥ 0`, with f and gₖ
/// given by their coefficients in the blocks' common `full_basis`. Row α reads
/// `Σ_b (weights) svec(Q_b) + γ [α = 0] + Σₖ τₖ ([α = 0] − gₖ,α) = f_α`; monomials no term touches
/// get no row.
pub(super) fn solve_level0(
    blocks: &[GramStructure],
    objective: &[Real],
    constraints: &[&[Real]],
    params: &CertificateParams,
) -> Result<Level0Solution> {
    let nf = blocks.first().map_or(0, |g| g.full_basis.len());
    let mut builder = ConicBuilder::new();
    let gamma = builder.add_variables(1);
    let first_tau = builder.add_variables(constraints.len());
    let multipliers: Vec<usize> = (0..constraints.len()).map(|k| first_tau + k).collect();
    builder.set_objective(gamma, -1.0);

    let mut rows: Vec<Row> = vec![Vec::new(); nf];
    let mut psd_rows = Vec::with_capacity(blocks.len());
    for gram in blocks {
        psd_rows.push(builder.num_rows());
        let q = builder.add_psd_variable(gram.size());
        for j in 0..gram.size() {
            for i in 0..=j {
                let k = triangle_index(i, j);
                rows[gram.product_of_entry[k]].push((q + k, gram_weight(i, j)));
            }
        }
    }
    rows[0].push((gamma, 1.0));
    for (k, g) in constraints.iter().enumerate() {
        for (alpha, row) in rows.iter_mut().enumerate() {
            let coeff = if alpha == 0 { 1.0 } else { 0.0 } - g[alpha];
            if coeff != 0.0 {
                row.push((multipliers[k], coeff));
            }
        }
    }
    let first_row = builder.num_rows();
    let mut row_of = vec![None; nf];
    let (mut kept, mut rhs) = (Vec::new(), Vec::new());
    for (alpha, row) in rows.into_iter().enumerate() {
        if row.is_empty() {
            if objective[alpha] != 0.0 {
                return Err(Error::Numerical(format!(
                    "level-0 sos certificate: monomial {alpha} of the objective is outside every Gram block"
                )));
            }
            continue;
        }
        row_of[alpha] = Some(first_row + kept.len());
        kept.push(row);
        rhs.push(objective[alpha]);
    }
    builder.add_equalities(kept, rhs);
    builder.add_inequalities(multipliers.iter().map(|&c| vec![(c, -1.0)]).collect(), vec![0.0; multipliers.len()]);

    let sol = builder.solve(quiet_settings(params.tolerance, params.max_iterations))?;
    // Every status is mapped by `SdpStatus::from` (Clarabel's, variant for variant); only
    // Solved / AlmostSolved give a usable certificate.
    let status = sublevel_core::conic::SdpStatus::from(sol.status);
    if status.is_usable() {
        Ok(Level0Solution { sol, gamma, multipliers, psd_rows, row_of })
    } else {
        Err(Error::Numerical(format!(
            "level-0 sos certificate: Clarabel ended with status {status} after {} iterations",
            sol.iterations
        )))
    }
}

/// The exponent vector in `n` variables with one added to each listed variable.
pub(super) fn unit_exponent(n: usize, vars: &[usize]) -> Vec<u8> {
    let mut e = vec![0u8; n];
    for &i in vars {
        e[i] += 1;
    }
    e
}

/// Coefficients of a trivariate polynomial in `gram.full_basis`, its variables placed at
/// positions `offset..offset + 3` of the Gram structure's variables.
pub(super) fn embed(p: &Polynomial, gram: &GramStructure, offset: usize) -> Vec<Real> {
    let n = gram.full_basis[0].len();
    let mut out = vec![0.0; gram.full_basis.len()];
    for (c, e) in p.coefficients().iter().zip(p.exponents()) {
        if *c == 0.0 {
            continue;
        }
        let mut ex = vec![0u8; n];
        ex[offset..offset + 3].copy_from_slice(e);
        // Every monomial of p has degree ≤ 2d, so it is in the full basis.
        if let Some(&k) = gram.index_of.get(&ex) {
            out[k] += c;
        }
    }
    out
}
