//! The Lasserre–Pauwels inverse moment polynomial (paper §III-B-1, eq. "inverse.moment.poly").
//!
//! ```text
//! M_d = (1/m) Σᵢ z(uᵢ) z(uᵢ)ᵀ          (N × N moment matrix of the empirical measure, ALL points)
//! q(u) = z(u)ᵀ M_d⁻¹ z(u),   γ = maxᵢ q(uᵢ),   p = q / γ
//! ```
//!
//! z is the graded-lex basis of degree ≤ d and u the normalized coordinates (q is invariant under
//! the affine normalization: z(Ax + b) = T z(x) with T invertible, so M changes to T M Tᵀ).
//! γ is the smallest level containing every point, so max p(uᵢ) = 1. No SDP; p is sos with Gram
//! matrix M_d⁻¹/γ ≻ 0 but not convex in general.
//!
//! M_d is factored after scaling it to unit diagonal (D^{-1/2} M D^{-1/2}); a pivot below
//! [`SINGULAR_PIVOT`] means the cloud lies (numerically) on an algebraic surface of degree ≤ d,
//! e.g. a sphere at 2d = 4, and M_d has no inverse.

use crate::{Error, Result};
use nalgebra::DMatrix;
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::monomial::graded_exponents3;

/// Smallest admissible squared Cholesky pivot of the unit-diagonal moment matrix.
pub const SINGULAR_PIVOT: Real = 1e-13;

/// The moment matrix M_d = (1/m) Σ z(uᵢ) z(uᵢ)ᵀ (N × N, N = C(d+3, 3)).
pub fn moment_matrix(half_degree: usize, points: &[Vector3]) -> DMatrix<Real> {
    let half = graded_exponents3(half_degree);
    let n = half.len();
    let mut m = DMatrix::<Real>::zeros(n, n);
    let mut z = nalgebra::DVector::<Real>::zeros(n);
    for u in points {
        for (k, e) in half.iter().enumerate() {
            z[k] = u.x.powi(e[0] as i32) * u.y.powi(e[1] as i32) * u.z.powi(e[2] as i32);
        }
        m.ger(1.0, &z, &z, 1.0);
    }
    m / points.len().max(1) as Real
}

/// M_d⁻¹ for the cloud `points` (normalized coordinates).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` when the cloud is empty or M_d is singular.
pub fn inverse_moment_gram(half_degree: usize, points: &[Vector3]) -> Result<DMatrix<Real>> {
    if points.is_empty() {
        return Err(Error::invalid("points", "the cloud is empty"));
    }
    let m = moment_matrix(half_degree, points);
    let n = m.nrows();
    let dinv: Vec<Real> = (0..n).map(|i| 1.0 / m[(i, i)].sqrt()).collect();
    if dinv.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid("points", "the moment matrix has a zero diagonal entry"));
    }
    let scaled = DMatrix::from_fn(n, n, |i, j| m[(i, j)] * dinv[i] * dinv[j]);
    let singular = || {
        Error::invalid(
            "points",
            format!(
                "the degree-{} moment matrix is singular: the cloud lies on an algebraic surface of degree ≤ {}",
                2 * half_degree,
                half_degree
            ),
        )
    };
    let chol = nalgebra::Cholesky::new(scaled).ok_or_else(singular)?;
    let min_pivot = (0..n).map(|i| chol.l_dirty()[(i, i)].powi(2)).fold(Real::INFINITY, Real::min);
    if min_pivot.is_nan() || min_pivot < SINGULAR_PIVOT {
        return Err(singular());
    }
    let inv = chol.inverse();
    Ok(DMatrix::from_fn(n, n, |i, j| 0.5 * (inv[(i, j)] + inv[(j, i)]) * dinv[i] * dinv[j]))
}

/// The inverse moment fit: p = z(u)ᵀ M_d⁻¹ z(u) / γ with max p(uᵢ) = 1 (see the module docs).
///
/// # Errors
/// As [`inverse_moment_gram`]; [`Error::Numerical`] for a non-finite result.
pub(crate) fn solve(half_degree: usize, points: &[Vector3]) -> Result<super::pipeline::Solved> {
    let start = std::time::Instant::now();
    let inv = inverse_moment_gram(half_degree, points)?;
    let mut poly = super::sdp::polynomial_of_gram(half_degree, &inv)?;
    let gamma = points.iter().map(|u| poly.value(u)).fold(Real::NEG_INFINITY, Real::max);
    if !(gamma.is_finite() && gamma > 0.0) {
        return Err(Error::Numerical(format!("inverse moment polynomial has max {gamma} on the cloud")));
    }
    poly.scale(1.0 / gamma);
    Ok(super::pipeline::Solved {
        poly,
        solver_status: sublevel_core::conic::SdpStatus::ClosedForm,
        solve_seconds: start.elapsed().as_secs_f64(),
        convexity_gram: None,
        sos_gram: Some(inv / gamma),
        nonconvex: true,
        certificate: None,
        notes: vec![format!(
            "inverse moment (Lasserre–Pauwels) over all {} points in normalized coordinates; level γ = {gamma:.6e}",
            points.len()
        )],
        details: None,
    })
}
