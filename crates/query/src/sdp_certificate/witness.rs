//! Witness points of a solved level-0 program (module docs of [`super`], "Witnesses from the
//! moments"): the first-order pseudo-moments of the dual solution, and the kernel of the first
//! Gram block (paper §IV-A).

use super::level0::{unit_exponent, Level0Solution};
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::poly::gram::{triangle_len, GramStructure};

/// First-order pseudo-moments `L(w₁), …, L(wₙ)` from the duals of the equality rows, normalized by
/// `L(1)`; `None` unless finite.
pub(super) fn moments_first_order(gram: &GramStructure, level0: &Level0Solution, n: usize) -> Option<Vec<Real>> {
    let z = &level0.sol.z;
    let y0 = *z.get(level0.row_of[0]?)?;
    if !(y0.is_finite() && y0.abs() > 1e-12) {
        return None;
    }
    let w: Vec<Real> = (0..n)
        .map(|i| level0.row_of[gram.index_of[&unit_exponent(n, &[i])]].and_then(|r| z.get(r)).map(|v| v / y0))
        .collect::<Option<_>>()?;
    w.iter().all(|v| v.is_finite()).then_some(w)
}

/// The point w* recovered from the kernel of the first Gram block (paper §IV-A): the sos
/// certificate `σ(w) = Σ_b z_b(w)ᵀ Q_b z_b(w)` vanishes at a minimizer, so each `Q_b z_b(w*) = 0`.
/// The first block's basis starts `(1, w₁, …, wₙ)`, so a one-dimensional kernel spanned by v gives
/// `w* = (v₁, …, vₙ)/v₀`. `None` when the smallest eigenvalue is not below `relative` times the
/// largest, the kernel has dimension > 1 (the next eigenvalue not above `relative` times the
/// largest: no unique minimizer to read off), or v₀ ≈ 0
/// ([`CertificateParams::kernel_relative_eigenvalue`](super::CertificateParams::kernel_relative_eigenvalue)).
pub(super) fn kernel_point(
    gram: &GramStructure,
    level0: &Level0Solution,
    n: usize,
    relative: Real,
) -> Option<Vec<Real>> {
    let size = gram.size();
    let row = *level0.psd_rows.first()?;
    let q = sublevel_core::poly::gram::unpack_triangle(level0.sol.s.get(row..row + triangle_len(size))?, size);
    let eig = nalgebra::SymmetricEigen::new(q);
    let mut order: Vec<usize> = (0..size).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let top = eig.eigenvalues[order[size - 1]].abs().max(Real::MIN_POSITIVE);
    let (l0, l1) = (eig.eigenvalues[order[0]], eig.eigenvalues.get(order.get(1).copied()?).copied()?);
    if !(l0.abs() <= relative * top && l1 > relative * top) {
        return None;
    }
    let v = eig.eigenvectors.column(order[0]);
    let v0 = v[0];
    if !(v0.abs() > 1e-8 && size > n) {
        return None;
    }
    let w: Vec<Real> = (1..=n).map(|i| v[i] / v0).collect();
    w.iter().all(|x| x.is_finite()).then_some(w)
}

/// World point of normalized coordinates `u` of `body` under `pose`.
pub(super) fn world_point(body: &Body, pose: &Isometry3, u: &Vector3) -> Point3 {
    pose * Point3::from(body.center() + u * body.scale())
}
