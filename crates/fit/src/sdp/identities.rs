//! The coefficient identities of a Gram form and of sos-convexity, solved for one entry each.
//!
//! ```text
//! sos:            c_α = Σ_{zᵢzⱼ = u^α} (2 − δᵢⱼ) Pᵢⱼ                     one per monomial α, |α| ≤ 2d
//! sos-convexity:  yᵀ∇²(p + c q) y = w(u, y)ᵀ G w(u, y),  w = y ⊗ z_{d−1}(u)
//!                 one per y-pair k ≤ l and monomial β, |β| ≤ 2d − 2     (q = (‖u‖²)ᵈ, c ≥ 0)
//! ```
//!
//! Neither becomes an equality row. Each identity is solved for one entry of svec(X) (its
//! pivot, a diagonal entry when it has one), so X is an affine image of the coefficient columns
//! and of its other entries (free columns): [`solve_identities`] returns every svec entry as an
//! [`AffineEntry`]. Compared with columns for every entry plus equality rows, this removes
//! 165 + 504 rows and as many columns at 2d = 8, and above all the coupling of the dense G block
//! with the 504 equality rows in the factorization (0.65 → 0.41 s per interior-point iteration
//! on the chair).
//!
//! The Gram matrices are written in scaled monomial bases u^α/σ_α ([`basis_scales`]): log det
//! changes by a constant, the body not at all, but the matrices at the optimum no longer span
//! many decades.

use crate::{Error, Result};
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::gram::{gram_weight, triangle_index};
use sublevel_core::poly::monomial::{basis_len, graded_exponents3, index3};
use sublevel_core::poly::Polynomial;

/// One entry of a packed Gram matrix as an affine function of the program's columns:
/// `Σ coef·x[col] + constant`.
#[derive(Clone, Debug, Default)]
pub(crate) struct AffineEntry {
    /// (column, coefficient) pairs.
    pub(crate) terms: Vec<(usize, Real)>,
    /// The constant part.
    pub(crate) constant: Real,
}

/// Values of affine entries at the column vector x.
pub(crate) fn evaluate(entries: &[AffineEntry], x: &[Real]) -> Vec<Real> {
    entries.iter().map(|e| e.constant + e.terms.iter().map(|&(col, coef)| coef * x[col]).sum::<Real>()).collect()
}

/// Index of the unordered y-pair (k ≤ l) among (0,0), (0,1), (0,2), (1,1), (1,2), (2,2): the
/// row block of the sos-convexity identities of yₖyₗ.
pub(crate) fn pair_index(k: usize, l: usize) -> usize {
    let (k, l) = if k <= l { (k, l) } else { (l, k) };
    match (k, l) {
        (0, 0) => 0,
        (0, 1) => 1,
        (0, 2) => 2,
        (1, 1) => 3,
        (1, 2) => 4,
        _ => 5,
    }
}

/// Sum of two exponent triples.
pub(crate) fn add3(a: [u8; 3], b: [u8; 3]) -> [u8; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Scales σ_α of the monomials u^α of a Gram basis: their root mean square over `points` (the
/// containment points, normalized coordinates), or 1 when `identity` is set (trace objectives:
/// trace X⁻¹ is not invariant under a diagonal change of basis), when there are no points or
/// the mean is not positive. On the unit ball u^α of degree 4 is ~10⁻² on a cloud, so without
/// the scales the Gram matrices at the optimum span many decades (chair 2d = 8: log det P crept
/// on for ~15 iterations after the gap was small; scaled, it settles to 7 digits in 21–23).
pub(crate) fn basis_scales(exponents: &[[u8; 3]], points: &[Vector3], identity: bool) -> Vec<Real> {
    exponents
        .iter()
        .map(|e| {
            if identity || points.is_empty() {
                return 1.0;
            }
            let mean = points
                .iter()
                .map(|u| (u.x.powi(e[0] as i32) * u.y.powi(e[1] as i32) * u.z.powi(e[2] as i32)).powi(2))
                .sum::<Real>()
                / points.len() as Real;
            if mean.is_finite() && mean > 1e-300 {
                mean.sqrt()
            } else {
                1.0
            }
        })
        .collect()
}

/// X = Σ⁻¹ X' Σ⁻¹ for the Gram matrix X' in the scaled basis z/σ.
pub(crate) fn unscale(mut scaled: nalgebra::DMatrix<Real>, scales: &[Real]) -> nalgebra::DMatrix<Real> {
    for j in 0..scaled.ncols() {
        for i in 0..scaled.nrows() {
            scaled[(i, j)] /= scales[i] * scales[j];
        }
    }
    scaled
}

/// Solves linear identities `Σ_{e ∈ group} w_e·svec(X)_e = known(group)` (group entries given as
/// (svec index, w_e, on the diagonal)) for one entry of each group (its pivot: a diagonal entry
/// when the group has one), returning every entry of svec(X) (length `len`) as an affine
/// function of the columns: the other entries become free columns numbered from `first_col` in
/// group order, and `known(g)` gives the right side of group g as (terms, constant). Every entry
/// must belong to exactly one group.
pub(crate) fn solve_identities(
    groups: &[Vec<(usize, Real, bool)>],
    len: usize,
    first_col: usize,
    known: impl Fn(usize) -> (Vec<(usize, Real)>, Real),
) -> Vec<AffineEntry> {
    let mut image = vec![AffineEntry::default(); len];
    let mut next = first_col;
    for (g, group) in groups.iter().enumerate() {
        let Some(&(pivot, w_pivot, _)) = group.iter().find(|(_, _, diagonal)| *diagonal).or(group.first()) else {
            continue;
        };
        let (terms, constant) = known(g);
        let mut pivot_terms: Vec<(usize, Real)> = terms.into_iter().map(|(col, v)| (col, v / w_pivot)).collect();
        for &(e, w, _) in group.iter().filter(|(e, _, _)| *e != pivot) {
            image[e] = AffineEntry { terms: vec![(next, 1.0)], constant: 0.0 };
            pivot_terms.push((next, -w / w_pivot));
            next += 1;
        }
        image[pivot] = AffineEntry { terms: pivot_terms, constant: constant / w_pivot };
    }
    image
}

/// Entries of svec(P) (N × N, half basis `half` scaled by `scale`) grouped by the coefficient
/// identity c_α they enter, with their weights (2 − δᵢⱼ)/(√2^(1−δᵢⱼ) σᵢσⱼ): one group per
/// monomial of degree ≤ 2d.
pub(crate) fn sos_groups(half: &[[u8; 3]], scale: &[Real], num_monomials: usize) -> Vec<Vec<(usize, Real, bool)>> {
    let mut groups = vec![Vec::new(); num_monomials];
    for j in 0..half.len() {
        for i in 0..=j {
            let w = gram_weight(i, j) / (scale[i] * scale[j]);
            groups[index3(add3(half[i], half[j]))].push((triangle_index(i, j), w, i == j));
        }
    }
    groups
}

/// Entries of svec(G) (M × M, M = 3·|low|, basis y ⊗ z_{d−1}/σ) grouped by the sos-convexity
/// identity (y-pair, monomial β of degree ≤ 2d − 2) they enter, with their svec weights.
pub(crate) fn convexity_groups(low: &[[u8; 3]], scale: &[Real], d: usize) -> Vec<Vec<(usize, Real, bool)>> {
    let nl = low.len();
    let m = 3 * nl;
    let lb = basis_len(3, 2 * d - 2);
    let mut groups = vec![Vec::new(); 6 * lb];
    for bcol in 0..m {
        for acol in 0..=bcol {
            let (ka, ia) = (acol / nl, acol % nl);
            let (kb, ib) = (bcol / nl, bcol % nl);
            let w = gram_weight(acol, bcol) / (scale[ia] * scale[ib]);
            groups[pair_index(ka, kb) * lb + index3(add3(low[ia], low[ib]))].push((
                triangle_index(acol, bcol),
                w,
                acol == bcol,
            ));
        }
    }
    groups
}

/// The Hessian side of the sos-convexity identities: for each identity (y-pair k ≤ l,
/// monomial β of degree ≤ 2d − 2), the terms f·c_α/τ_α of yᵀ∇²p y on the coefficient columns
/// (`col_c + α`, columns holding τ_α c_α) and the constant −c·(yᵀ∇²q y)_β of the relaxation
/// (eq. "VAG.param.convex"; q = (‖u‖²)ᵈ, 0 when `relaxation` is 0).
pub(crate) fn hessian_identities(
    d: usize,
    col_c: usize,
    scale_c: &[Real],
    relaxation: Real,
) -> (Vec<Vec<(usize, Real)>>, Vec<Real>) {
    let lb = basis_len(3, 2 * d - 2);
    let mut constant = vec![0.0; 6 * lb];
    let mut terms: Vec<Vec<(usize, Real)>> = vec![Vec::new(); 6 * lb];
    let q = if relaxation > 0.0 { norm_power_coefficients(d) } else { vec![0.0; basis_len(3, 2 * d)] };
    for_each_hessian_term(d, |row, ci, f| {
        terms[row].push((col_c + ci, f / scale_c[ci]));
        constant[row] -= relaxation * f * q[ci];
    });
    (terms, constant)
}

/// The derivative formula of yᵀ∇²p y for p of degree 2d in the graded-lex basis: calls
/// `term(row, α, f)` for every coefficient index α and identity row (y-pair k ≤ l, monomial
/// β = α − eₖ − eₗ of degree ≤ 2d − 2, row = pair·C(2d+1, 3) + index(β)) to which c_α contributes
/// f·c_α (f = αₖ(αₖ − 1) for k = l, 2αₖαₗ otherwise). Shared by the fits' identities and the
/// sos-convexity certificate of uploaded bodies.
pub(crate) fn for_each_hessian_term(d: usize, mut term: impl FnMut(usize, usize, Real)) {
    let lb = basis_len(3, 2 * d - 2);
    for (ci, alpha) in graded_exponents3(2 * d).iter().enumerate() {
        for k in 0..3 {
            for l in k..3 {
                let (ak, al) = (alpha[k] as usize, alpha[l] as usize);
                let f = if k == l { (ak * ak.saturating_sub(1)) as Real } else { 2.0 * (ak * al) as Real };
                if f == 0.0 {
                    continue;
                }
                let mut beta = *alpha;
                beta[k] -= 1;
                beta[l] -= 1;
                term(pair_index(k, l) * lb + index3(beta), ci, f);
            }
        }
    }
}

/// Size of svec(G) minus the free entries: the number of sos-convexity identities at half
/// degree d (6 y-pairs × monomials of degree ≤ 2d − 2).
pub(crate) fn num_convexity_identities(d: usize) -> usize {
    6 * basis_len(3, 2 * d - 2)
}

/// Coefficients of q(u) = (u₁² + u₂² + u₃²)ᵈ in the graded-lex basis of degree 2d (multinomial
/// theorem: q = Σ_{a+b+c=d} d!/(a! b! c!) u₁^{2a} u₂^{2b} u₃^{2c}); the relaxation term of eq.
/// "VAG.param.convex".
pub fn norm_power_coefficients(d: usize) -> Vec<Real> {
    let fact = |k: usize| (1..=k).map(|v| v as Real).product::<Real>();
    let mut q = vec![0.0; basis_len(3, 2 * d)];
    for a in 0..=d {
        for b in 0..=d - a {
            let c = d - a - b;
            q[index3([2 * a as u8, 2 * b as u8, 2 * c as u8])] = fact(d) / (fact(a) * fact(b) * fact(c));
        }
    }
    q
}

/// p = z(x)ᵀ P z(x) expanded in the graded-lex basis of degree 2d, for a symmetric N × N matrix
/// P over the half basis z of degree ≤ d (exactly sos for P ⪰ 0).
///
/// # Errors
/// [`Error::Numerical`] when P has the wrong size or a coefficient is not finite.
pub fn polynomial_of_gram(half_degree: usize, p: &nalgebra::DMatrix<Real>) -> Result<Polynomial> {
    let half = graded_exponents3(half_degree);
    if p.nrows() != half.len() || p.ncols() != half.len() {
        return Err(Error::Numerical(format!(
            "Gram matrix is {}×{}, expected {}×{}",
            p.nrows(),
            p.ncols(),
            half.len(),
            half.len()
        )));
    }
    let mut c = vec![0.0; basis_len(3, 2 * half_degree)];
    for j in 0..half.len() {
        for i in 0..=j {
            c[index3(add3(half[i], half[j]))] += if i == j { 1.0 } else { 2.0 } * p[(i, j)];
        }
    }
    Polynomial::from_coefficients(2 * half_degree, c)
        .map_err(|e| Error::Numerical(format!("unusable Gram matrix: {e}")))
}
