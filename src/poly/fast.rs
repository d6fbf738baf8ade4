//! Precomputed derivative tables for fast value / gradient / Hessian evaluation of one polynomial
//! at many points (the query hot path, paper §IV).
//!
//! ```text
//! m_k(u) = u^aₖ v^bₖ w^cₖ                     all monomials of degree ≤ 2d from power tables,
//!                                              walked in graded-lex order
//! p    = Σ_{k < N}   cₖ  m_k                   N  = C(2d + 3, 3)
//! ∇p   = Σ_{k < N₁}  gₖ  m_k   (gₖ ∈ ℝ³)       N₁ = C(2d + 2, 3): ∂p/∂uᵢ has degree 2d − 1
//! ∇²p  = Σ_{k < N₂}  hₖ  m_k   (hₖ ∈ ℝ⁶)       N₂ = C(2d + 1, 3)
//! ```
//!
//! The coefficient rows gₖ, hₖ are the coefficients of the derivative polynomials in the same
//! graded-lex basis, precomputed once per body, so one evaluation is one pass building the monomial
//! table and three fused multiply–add loops over fixed-width rows (no allocation, no power tables,
//! no per-term index arithmetic). The Hessian pass is separate ([`FastPoly::hessian`]) so a line
//! search or a convergence check can stop after value and gradient.

use super::monomial::{basis_len, index3};
use super::polynomial::{Polynomial, MAX_DEGREE};
use crate::math::{Matrix3, Real, Vector3};

/// Number of monomials of degree ≤ 8 in three variables (the largest monomial table).
pub const MAX_MONOMIALS: usize = 165;

/// The monomial values `m_k(u)` of one point, graded-lex order; only the first
/// [`FastPoly::len`] entries are meaningful.
#[derive(Clone, Copy, Debug)]
pub struct Monomials {
    /// `m_k(u)`, k < N.
    pub values: [Real; MAX_MONOMIALS],
}

/// A polynomial with its gradient and Hessian coefficient tables precomputed (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FastPoly {
    degree: usize,
    /// Value coefficients cₖ, length N.
    value: Vec<Real>,
    /// Rows `[cₖ, ∂ₓ, ∂ᵧ, ∂_z]` for k < N₁ (value coefficient and the gradient polynomials').
    grad: Vec<[Real; 4]>,
    /// Rows `[xx, xy, xz, yy, yz, zz]` of the Hessian polynomials, k < N₂.
    hess: Vec<[Real; 6]>,
}

impl FastPoly {
    /// Precomputes the derivative tables of `p` (degree ≤ 8; any degree the crate accepts).
    pub fn new(p: &Polynomial) -> Self {
        let degree = p.degree().min(MAX_DEGREE);
        let n = basis_len(3, degree);
        let n1 = if degree >= 1 { basis_len(3, degree - 1) } else { 0 };
        let n2 = if degree >= 2 { basis_len(3, degree - 2) } else { 0 };
        let exps = p.exponents();
        let c = p.coefficients();
        let coef = |e: [u8; 3]| -> Real {
            let k = index3(e);
            if (e[0] + e[1] + e[2]) as usize <= degree && k < n {
                c[k]
            } else {
                0.0
            }
        };
        let shift = |e: &[u8; 3], d: [u8; 3]| [e[0] + d[0], e[1] + d[1], e[2] + d[2]];
        let f = |v: u8| v as Real;
        let mut grad = Vec::with_capacity(n1);
        for e in exps.iter().take(n1) {
            grad.push([
                coef(*e),
                f(e[0] + 1) * coef(shift(e, [1, 0, 0])),
                f(e[1] + 1) * coef(shift(e, [0, 1, 0])),
                f(e[2] + 1) * coef(shift(e, [0, 0, 1])),
            ]);
        }
        let mut hess = Vec::with_capacity(n2);
        for e in exps.iter().take(n2) {
            hess.push([
                f(e[0] + 2) * f(e[0] + 1) * coef(shift(e, [2, 0, 0])),
                f(e[0] + 1) * f(e[1] + 1) * coef(shift(e, [1, 1, 0])),
                f(e[0] + 1) * f(e[2] + 1) * coef(shift(e, [1, 0, 1])),
                f(e[1] + 2) * f(e[1] + 1) * coef(shift(e, [0, 2, 0])),
                f(e[1] + 1) * f(e[2] + 1) * coef(shift(e, [0, 1, 1])),
                f(e[2] + 2) * f(e[2] + 1) * coef(shift(e, [0, 0, 2])),
            ]);
        }
        Self { degree, value: c[..n].to_vec(), grad, hess }
    }

    /// Total degree bound 2d.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Number of monomials N = C(2d + 3, 3).
    pub fn len(&self) -> usize {
        self.value.len()
    }

    /// True for an empty basis (never for a valid polynomial: N ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.value.is_empty()
    }

    /// The monomial table `m_k(u)`, k < N, from power tables (two multiplies per monomial, all
    /// independent), walking the graded-lex order structurally.
    #[inline]
    pub fn monomials(&self, u: &Vector3) -> Monomials {
        let d = self.degree;
        let (mut px, mut py, mut pz) = ([1.0; MAX_DEGREE + 1], [1.0; MAX_DEGREE + 1], [1.0; MAX_DEGREE + 1]);
        for i in 1..=d {
            px[i] = px[i - 1] * u.x;
            py[i] = py[i - 1] * u.y;
            pz[i] = pz[i - 1] * u.z;
        }
        let mut m = [0.0; MAX_MONOMIALS];
        let mut k = 0;
        for t in 0..=d {
            for a in (0..=t).rev() {
                let xa = px[a];
                for b in (0..=t - a).rev() {
                    m[k] = xa * py[b] * pz[t - a - b];
                    k += 1;
                }
            }
        }
        Monomials { values: m }
    }

    /// p(u) from a monomial table.
    #[inline]
    pub fn value_from(&self, m: &Monomials) -> Real {
        let mut acc = [0.0; 4];
        let chunks = self.value.chunks_exact(4);
        let rest = chunks.remainder();
        let n4 = self.value.len() - rest.len();
        for (c, mm) in chunks.zip(m.values[..n4].chunks_exact(4)) {
            for j in 0..4 {
                acc[j] += c[j] * mm[j];
            }
        }
        let mut v = (acc[0] + acc[1]) + (acc[2] + acc[3]);
        for (c, mm) in rest.iter().zip(&m.values[n4..self.value.len()]) {
            v += c * mm;
        }
        v
    }

    /// p(u) and ∇p(u) from a monomial table.
    #[inline]
    pub fn value_gradient_from(&self, m: &Monomials) -> (Real, Vector3) {
        let n1 = self.grad.len();
        let mut acc = [0.0; 4];
        for (row, &mk) in self.grad.iter().zip(&m.values[..n1]) {
            for j in 0..4 {
                acc[j] += row[j] * mk;
            }
        }
        let mut v = acc[0];
        for (c, mk) in self.value[n1..].iter().zip(&m.values[n1..self.value.len()]) {
            v += c * mk;
        }
        (v, Vector3::new(acc[1], acc[2], acc[3]))
    }

    /// ∇²p(u) from a monomial table.
    #[inline]
    pub fn hessian_from(&self, m: &Monomials) -> Matrix3 {
        let n2 = self.hess.len();
        let mut h = [0.0; 6];
        for (row, &mk) in self.hess.iter().zip(&m.values[..n2]) {
            for j in 0..6 {
                h[j] += row[j] * mk;
            }
        }
        Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5])
    }

    /// p(u).
    #[inline]
    pub fn value(&self, u: &Vector3) -> Real {
        self.value_from(&self.monomials(u))
    }

    /// p(u) and ∇p(u).
    #[inline]
    pub fn value_gradient(&self, u: &Vector3) -> (Real, Vector3) {
        self.value_gradient_from(&self.monomials(u))
    }

    /// p(u), ∇p(u) and ∇²p(u).
    #[inline]
    pub fn eval(&self, u: &Vector3) -> super::Eval {
        let m = self.monomials(u);
        let (value, gradient) = self.value_gradient_from(&m);
        super::Eval { value, gradient, hessian: self.hessian_from(&m) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn fast_eval_matches_reference_eval_at_every_degree() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for degree in 0..=MAX_DEGREE {
            let n = basis_len(3, degree);
            let coeffs: Vec<Real> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
            let f = FastPoly::new(&p);
            assert_eq!(f.len(), n);
            for _ in 0..20 {
                let u =
                    Vector3::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5));
                let (r, e) = (p.eval(&u), f.eval(&u));
                let scale = 1.0 + r.value.abs() + r.gradient.amax() + r.hessian.amax();
                assert!((r.value - e.value).abs() <= 1e-12 * scale, "degree {degree}");
                assert!((r.gradient - e.gradient).amax() <= 1e-12 * scale, "degree {degree}");
                assert!((r.hessian - e.hessian).amax() <= 1e-12 * scale, "degree {degree}");
                assert!((f.value(&u) - r.value).abs() <= 1e-12 * scale);
            }
        }
    }
}
