//! Fast value / gradient / Hessian evaluation of one polynomial at many points (the query hot
//! path, paper §IV), without a monomial table.
//!
//! The coefficients are rearranged once per body into triangular (c, b, a) order, and p is
//! evaluated as nested sums over the exponents of z, y, x:
//!
//! ```text
//! p(u) = Σ_c w^c Σ_b v^b Σ_a c_abc u^a          a + b + c ≤ 2d
//! S_j(b, c) = Σ_a c_abc ∂ʲ(u^a)                 j = 0, 1, 2   (x-derivatives, dot products)
//! T_jk(c)   = Σ_b S_j(b, c) ∂ᵏ(v^b)            j + k ≤ 2     (mixed x/y derivatives)
//! ∂ʲₓ∂ᵏᵧ∂ˡ_z p = Σ_c T_jk(c) ∂ˡ(w^c)             j + k + l ≤ 2
//! ```
//!
//! Value, gradient and Hessian come out of one pass (about 3 fused multiply–adds per coefficient
//! at the inner level, all sums independent). The kernels are specialised per degree 2d ∈ 0..=8
//! by a const generic, so the triangular loops have constant bounds and unroll.

use super::monomial::{basis_len, index3};
use super::polynomial::{Polynomial, MAX_DEGREE};
use crate::math::{Matrix3, Real, Vector3};

/// Number of monomials of degree ≤ 8 in three variables (the largest basis).
pub const MAX_MONOMIALS: usize = 165;

/// A polynomial with its coefficients rearranged for the fast kernels (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FastPoly {
    degree: usize,
    len: usize,
    /// c_abc in (c, b, a) triangular order (c outermost, a innermost, all ascending); zero padded.
    coef: [Real; MAX_MONOMIALS],
}

/// Powers t^k and their first and second derivatives k t^(k−1), k (k − 1) t^(k−2), k ≤ D.
#[inline(always)]
fn powers<const D: usize>(t: Real) -> ([Real; MAX_DEGREE + 1], [Real; MAX_DEGREE + 1], [Real; MAX_DEGREE + 1]) {
    let mut p = [0.0; MAX_DEGREE + 1];
    let mut d = [0.0; MAX_DEGREE + 1];
    let mut dd = [0.0; MAX_DEGREE + 1];
    p[0] = 1.0;
    for k in 1..=D {
        p[k] = p[k - 1] * t;
        d[k] = k as Real * p[k - 1];
        if k >= 2 {
            dd[k] = (k * (k - 1)) as Real * p[k - 2];
        }
    }
    (p, d, dd)
}

/// p(u).
#[inline(always)]
fn value_kernel<const D: usize>(coef: &[Real; MAX_MONOMIALS], u: &Vector3) -> Real {
    let (px, _, _) = powers::<D>(u.x);
    let (py, _, _) = powers::<D>(u.y);
    let (pz, _, _) = powers::<D>(u.z);
    let mut v = 0.0;
    let mut k = 0;
    for (c, &wc) in pz.iter().enumerate().take(D + 1) {
        let mut t = 0.0;
        for (b, &vb) in py.iter().enumerate().take(D + 1 - c) {
            let n = D + 1 - b - c;
            let mut s = 0.0;
            for (q, pa) in coef[k..k + n].iter().zip(&px) {
                s += q * pa;
            }
            k += n;
            t += s * vb;
        }
        v += t * wc;
    }
    v
}

/// p(u) and ∇p(u).
#[inline(always)]
fn gradient_kernel<const D: usize>(coef: &[Real; MAX_MONOMIALS], u: &Vector3) -> (Real, Vector3) {
    let (px, dx, _) = powers::<D>(u.x);
    let (py, dy, _) = powers::<D>(u.y);
    let (pz, dz, _) = powers::<D>(u.z);
    let mut o = [0.0; 4];
    let mut k = 0;
    for c in 0..D + 1 {
        let mut t = [0.0; 3];
        for b in 0..D + 1 - c {
            let n = D + 1 - b - c;
            let (mut s0, mut s1) = (0.0, 0.0);
            for ((q, pa), da) in coef[k..k + n].iter().zip(&px).zip(&dx) {
                s0 += q * pa;
                s1 += q * da;
            }
            k += n;
            t[0] += s0 * py[b];
            t[1] += s1 * py[b];
            t[2] += s0 * dy[b];
        }
        o[0] += t[0] * pz[c];
        o[1] += t[1] * pz[c];
        o[2] += t[2] * pz[c];
        o[3] += t[0] * dz[c];
    }
    (o[0], Vector3::new(o[1], o[2], o[3]))
}

/// p(u), ∇p(u) and ∇²p(u).
#[inline(always)]
fn full_kernel<const D: usize>(coef: &[Real; MAX_MONOMIALS], u: &Vector3) -> super::Eval {
    let (px, dx, ddx) = powers::<D>(u.x);
    let (py, dy, ddy) = powers::<D>(u.y);
    let (pz, dz, ddz) = powers::<D>(u.z);
    // o = [p, px, py, pz, pxx, pxy, pxz, pyy, pyz, pzz]
    let mut o = [0.0; 10];
    let mut k = 0;
    for c in 0..D + 1 {
        // t = [T00, T10, T20, T01, T11, T02]
        let mut t = [0.0; 6];
        for b in 0..D + 1 - c {
            let n = D + 1 - b - c;
            let (mut s0, mut s1, mut s2) = (0.0, 0.0, 0.0);
            for (((q, pa), da), dda) in coef[k..k + n].iter().zip(&px).zip(&dx).zip(&ddx) {
                s0 += q * pa;
                s1 += q * da;
                s2 += q * dda;
            }
            k += n;
            t[0] += s0 * py[b];
            t[1] += s1 * py[b];
            t[2] += s2 * py[b];
            t[3] += s0 * dy[b];
            t[4] += s1 * dy[b];
            t[5] += s0 * ddy[b];
        }
        o[0] += t[0] * pz[c];
        o[1] += t[1] * pz[c];
        o[2] += t[3] * pz[c];
        o[3] += t[0] * dz[c];
        o[4] += t[2] * pz[c];
        o[5] += t[4] * pz[c];
        o[6] += t[1] * dz[c];
        o[7] += t[5] * pz[c];
        o[8] += t[3] * dz[c];
        o[9] += t[0] * ddz[c];
    }
    super::Eval {
        value: o[0],
        gradient: Vector3::new(o[1], o[2], o[3]),
        hessian: Matrix3::new(o[4], o[5], o[6], o[5], o[7], o[8], o[6], o[8], o[9]),
    }
}

/// Calls `$kernel::<D>` for the runtime degree `$d` (0..=8).
macro_rules! dispatch {
    ($d:expr, $kernel:ident, $($arg:expr),*) => {
        match $d {
            0 => $kernel::<0>($($arg),*),
            1 => $kernel::<1>($($arg),*),
            2 => $kernel::<2>($($arg),*),
            3 => $kernel::<3>($($arg),*),
            4 => $kernel::<4>($($arg),*),
            5 => $kernel::<5>($($arg),*),
            6 => $kernel::<6>($($arg),*),
            7 => $kernel::<7>($($arg),*),
            _ => $kernel::<8>($($arg),*),
        }
    };
}

impl FastPoly {
    /// Rearranges the coefficients of `p` (degree ≤ 8; any degree the crate accepts).
    pub fn new(p: &Polynomial) -> Self {
        let degree = p.degree().min(MAX_DEGREE);
        let len = basis_len(3, degree);
        let c = p.coefficients();
        let mut coef = [0.0; MAX_MONOMIALS];
        let mut k = 0;
        for ec in 0..=degree {
            for eb in 0..=degree - ec {
                for ea in 0..=degree - eb - ec {
                    let i = index3([ea as u8, eb as u8, ec as u8]);
                    coef[k] = c.get(i).copied().unwrap_or(0.0);
                    k += 1;
                }
            }
        }
        Self { degree, len, coef }
    }

    /// Total degree bound 2d.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Number of monomials N = C(2d + 3, 3).
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for an empty basis (never for a valid polynomial: N ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// p(u).
    #[inline]
    pub fn value(&self, u: &Vector3) -> Real {
        dispatch!(self.degree, value_kernel, &self.coef, u)
    }

    /// p(u) and ∇p(u).
    #[inline]
    pub fn value_gradient(&self, u: &Vector3) -> (Real, Vector3) {
        dispatch!(self.degree, gradient_kernel, &self.coef, u)
    }

    /// p(u), ∇p(u) and ∇²p(u) in one pass.
    #[inline]
    pub fn eval(&self, u: &Vector3) -> super::Eval {
        dispatch!(self.degree, full_kernel, &self.coef, u)
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
                let (v, g) = f.value_gradient(&u);
                assert!((v - r.value).abs() <= 1e-12 * scale && (g - r.gradient).amax() <= 1e-12 * scale);
            }
        }
    }
}
