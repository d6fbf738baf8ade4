//! Fast value / gradient / Hessian evaluation of one polynomial at many points (the query hot
//! path, paper §IV) through per-body derivative coefficient tables.
//!
//! For p(u) = Σ_α c_α u^α (graded-lex monomial basis, |α| ≤ 2d) every derivative is again a
//! polynomial in the same basis, truncated to lower degree:
//!
//! ```text
//! ∂ᵢ p(u)   = Σ_{|β| ≤ 2d−1} (βᵢ + 1) c_{β+eᵢ} u^β
//! ∂ᵢ∂ⱼ p(u) = Σ_{|β| ≤ 2d−2} (βᵢ + 1)(βⱼ + 1 + δᵢⱼ) c_{β+eᵢ+eⱼ} u^β
//! ```
//!
//! The coefficients of p, ∇p and ∇²p are rearranged once per body ([`FastPoly::new`]) into
//! interleaved tables: row β holds `[c_β, ∂ₓ, ∂ᵧ, ∂_z]` (4 lanes) and `[xx, xy, xz, yy, yz, zz, 0, 0]`
//! (8 lanes). One evaluation builds the monomial vector z(u) (one multiplication per monomial, in
//! graded-lex order: degree k is `x·z_{k−1}`, then `y·(the y, z part of z_{k−1})`, then `z^k`) and
//! takes lane-wise dot products with the tables: independent fused multiply–adds over contiguous
//! rows, which the compiler maps to SIMD registers. On x86-64 CPUs with AVX2 and FMA (detected at
//! run time) the kernels are compiled for those instructions; elsewhere they run the portable code.
//! The kernels are specialised per degree 2d ∈ 0..=8 by const generics, so every loop has constant
//! bounds.
//!
//! Cost at 2d = 6: 84 monomials, 84 4-lane FMAs for value + gradient, 35 more 8-lane FMAs for the
//! Hessian.

use super::monomial::{basis_len, graded_exponents3, index3};
use super::polynomial::{Polynomial, MAX_DEGREE};
use crate::math::{Matrix3, Real, Vector3};

/// Rows of the value / gradient table: monomials of degree ≤ 8 in three variables (165), padded to
/// a multiple of 4.
pub const MAX_MONOMIALS: usize = 168;

/// Rows of the Hessian table: monomials of degree ≤ 6 (84), the Hessian of a degree-8 polynomial.
const MAX_HESSIAN_MONOMIALS: usize = 84;

/// The per-body coefficient tables (see the module docs); rows beyond the body's basis are zero.
#[derive(Clone, Debug, PartialEq)]
struct Tables {
    /// c_β (for value-only evaluations).
    coef: [Real; MAX_MONOMIALS],
    /// [c_β, coefficient of u^β in ∂ₓp, ∂ᵧp, ∂_zp].
    value_gradient: [[Real; 4]; MAX_MONOMIALS],
    /// Coefficients of u^β in [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, 0, 0].
    hessian: [[Real; 8]; MAX_HESSIAN_MONOMIALS],
}

/// A polynomial with its derivative coefficient tables for the fast kernels (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FastPoly {
    degree: usize,
    len: usize,
    tables: Box<Tables>,
}

/// a·b + c, fused when the kernel is compiled with FMA.
#[inline(always)]
fn fmadd<const FMA: bool>(a: Real, b: Real, c: Real) -> Real {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// Appends the degree-K block of the monomial vector from the degree-(K − 1) block: `x·z_{K−1}`,
/// then `y·(the x-free part of z_{K−1})`, then `z^K` (graded-lex order, [`index3`]). K is a constant,
/// so every index is known at compile time.
#[inline(always)]
fn degree_block<const K: usize, const N: usize>(m: &mut [Real; N], u: &Vector3) {
    let prev = (K - 1) * K * (K + 1) / 6;
    let cur = K * (K + 1) * (K + 2) / 6;
    let len_prev = K * (K + 1) / 2;
    for i in 0..len_prev {
        m[cur + i] = u.x * m[prev + i];
    }
    for i in 0..K {
        m[cur + len_prev + i] = u.y * m[cur - K + i];
    }
    m[cur + len_prev + K] = u.z * m[cur - 1];
}

/// The monomial vector z(u) of degree ≤ D in graded-lex order ([`index3`]); entries from C(D+3, 3)
/// to N are zero.
#[inline(always)]
fn monomials<const D: usize, const N: usize>(u: &Vector3) -> [Real; N] {
    let mut m = [0.0; N];
    m[0] = 1.0;
    macro_rules! blocks {
        ($($k:literal),*) => {
            $(if D >= $k {
                degree_block::<$k, N>(&mut m, u);
            })*
        };
    }
    blocks!(1, 2, 3, 4, 5, 6, 7, 8);
    m
}

/// p(u).
#[inline(always)]
fn value_kernel<const D: usize, const N: usize, const FMA: bool>(t: &Tables, u: &Vector3) -> Real {
    let m = monomials::<D, N>(u);
    let mut acc = [0.0; 4];
    for (mk, ck) in m.chunks_exact(4).zip(t.coef[..N].chunks_exact(4)) {
        for j in 0..4 {
            acc[j] = fmadd::<FMA>(mk[j], ck[j], acc[j]);
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// Adds four rows of the value / gradient table, weighted by their monomials `m`, into `acc`.
#[inline(always)]
fn accumulate_value_gradient<const FMA: bool>(acc: &mut [[Real; 4]; 4], m: &[Real], rows: &[[Real; 4]]) {
    for ((a, &mk), row) in acc.iter_mut().zip(m).zip(rows) {
        for l in 0..4 {
            a[l] = fmadd::<FMA>(mk, row[l], a[l]);
        }
    }
}

/// Sums the four partial accumulators of [`accumulate_value_gradient`] into (p, ∇p).
#[inline(always)]
fn reduce_value_gradient(acc: &[[Real; 4]; 4]) -> (Real, Vector3) {
    let s = |l: usize| (acc[0][l] + acc[1][l]) + (acc[2][l] + acc[3][l]);
    (s(0), Vector3::new(s(1), s(2), s(3)))
}

/// p(u) and ∇p(u).
#[inline(always)]
fn gradient_kernel<const D: usize, const N: usize, const FMA: bool>(t: &Tables, u: &Vector3) -> (Real, Vector3) {
    let m = monomials::<D, N>(u);
    let mut acc = [[0.0; 4]; 4];
    for (mk, rows) in m.chunks_exact(4).zip(t.value_gradient[..N].chunks_exact(4)) {
        accumulate_value_gradient::<FMA>(&mut acc, mk, rows);
    }
    reduce_value_gradient(&acc)
}

/// p(u), ∇p(u) and ∇²p(u); NH = rows of the Hessian table in use (a multiple of 4, ≤ N).
#[inline(always)]
fn full_kernel<const D: usize, const N: usize, const NH: usize, const FMA: bool>(
    t: &Tables,
    u: &Vector3,
) -> super::Eval {
    let m = monomials::<D, N>(u);
    let mut acc = [[0.0; 4]; 4];
    let mut h = [[0.0; 8]; 2];
    let (m_low, m_high) = m.split_at(NH);
    let (vg_low, vg_high) = t.value_gradient[..N].split_at(NH);
    for ((mk, rows), hrows) in m_low.chunks_exact(4).zip(vg_low.chunks_exact(4)).zip(t.hessian[..NH].chunks_exact(4)) {
        accumulate_value_gradient::<FMA>(&mut acc, mk, rows);
        let [h0, h1] = &mut h;
        for l in 0..8 {
            h0[l] = fmadd::<FMA>(mk[0], hrows[0][l], h0[l]);
            h1[l] = fmadd::<FMA>(mk[1], hrows[1][l], h1[l]);
        }
        for l in 0..8 {
            h0[l] = fmadd::<FMA>(mk[2], hrows[2][l], h0[l]);
            h1[l] = fmadd::<FMA>(mk[3], hrows[3][l], h1[l]);
        }
    }
    for (mk, rows) in m_high.chunks_exact(4).zip(vg_high.chunks_exact(4)) {
        accumulate_value_gradient::<FMA>(&mut acc, mk, rows);
    }
    let (value, gradient) = reduce_value_gradient(&acc);
    let s = |l: usize| h[0][l] + h[1][l];
    let (xx, xy, xz, yy, yz, zz) = (s(0), s(1), s(2), s(3), s(4), s(5));
    super::Eval { value, gradient, hessian: Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz) }
}

/// Calls `$kernel::<D, N, …, FMA>` for the runtime degree `$d` (0..=8): N = C(D+3, 3) and
/// NH = C(D+1, 3) rounded up to a multiple of 4.
macro_rules! dispatch {
    ($d:expr, value, $fma:expr, $($arg:expr),*) => {
        match $d {
            0 => value_kernel::<0, 4, $fma>($($arg),*),
            1 => value_kernel::<1, 4, $fma>($($arg),*),
            2 => value_kernel::<2, 12, $fma>($($arg),*),
            3 => value_kernel::<3, 20, $fma>($($arg),*),
            4 => value_kernel::<4, 36, $fma>($($arg),*),
            5 => value_kernel::<5, 56, $fma>($($arg),*),
            6 => value_kernel::<6, 84, $fma>($($arg),*),
            7 => value_kernel::<7, 120, $fma>($($arg),*),
            _ => value_kernel::<8, 168, $fma>($($arg),*),
        }
    };
    ($d:expr, gradient, $fma:expr, $($arg:expr),*) => {
        match $d {
            0 => gradient_kernel::<0, 4, $fma>($($arg),*),
            1 => gradient_kernel::<1, 4, $fma>($($arg),*),
            2 => gradient_kernel::<2, 12, $fma>($($arg),*),
            3 => gradient_kernel::<3, 20, $fma>($($arg),*),
            4 => gradient_kernel::<4, 36, $fma>($($arg),*),
            5 => gradient_kernel::<5, 56, $fma>($($arg),*),
            6 => gradient_kernel::<6, 84, $fma>($($arg),*),
            7 => gradient_kernel::<7, 120, $fma>($($arg),*),
            _ => gradient_kernel::<8, 168, $fma>($($arg),*),
        }
    };
    ($d:expr, full, $fma:expr, $($arg:expr),*) => {
        match $d {
            0 => full_kernel::<0, 4, 0, $fma>($($arg),*),
            1 => full_kernel::<1, 4, 0, $fma>($($arg),*),
            2 => full_kernel::<2, 12, 4, $fma>($($arg),*),
            3 => full_kernel::<3, 20, 4, $fma>($($arg),*),
            4 => full_kernel::<4, 36, 12, $fma>($($arg),*),
            5 => full_kernel::<5, 56, 20, $fma>($($arg),*),
            6 => full_kernel::<6, 84, 36, $fma>($($arg),*),
            7 => full_kernel::<7, 120, 56, $fma>($($arg),*),
            _ => full_kernel::<8, 168, 84, $fma>($($arg),*),
        }
    };
}

/// The kernels compiled for AVX2 + FMA (x86-64-v3). Callers must have checked [`has_fma`].
#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn value(d: usize, t: &Tables, u: &Vector3) -> Real {
        dispatch!(d, value, true, t, u)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn value_gradient(d: usize, t: &Tables, u: &Vector3) -> (Real, Vector3) {
        dispatch!(d, gradient, true, t, u)
    }

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn eval(d: usize, t: &Tables, u: &Vector3) -> crate::poly::Eval {
        dispatch!(d, full, true, t, u)
    }
}

/// Whether this CPU runs the AVX2 + FMA kernels (detected once, then a cached flag).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn has_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

impl FastPoly {
    /// Builds the derivative coefficient tables of `p` (degree ≤ 8; any degree the crate accepts).
    pub fn new(p: &Polynomial) -> Self {
        let degree = p.degree().min(MAX_DEGREE);
        let len = basis_len(3, degree);
        let c = p.coefficients();
        let coef_of = |e: [usize; 3]| -> Real {
            if e.iter().sum::<usize>() > degree {
                return 0.0;
            }
            c.get(index3([e[0] as u8, e[1] as u8, e[2] as u8])).copied().unwrap_or(0.0)
        };
        let mut t = Tables {
            coef: [0.0; MAX_MONOMIALS],
            value_gradient: [[0.0; 4]; MAX_MONOMIALS],
            hessian: [[0.0; 8]; MAX_HESSIAN_MONOMIALS],
        };
        for (k, e) in graded_exponents3(degree).into_iter().enumerate() {
            let b = [e[0] as usize, e[1] as usize, e[2] as usize];
            let plus = |i: usize, j: Option<usize>| {
                let mut f = b;
                f[i] += 1;
                if let Some(j) = j {
                    f[j] += 1;
                }
                f
            };
            let value = coef_of(b);
            t.coef[k] = value;
            let mut row = [value, 0.0, 0.0, 0.0];
            for i in 0..3 {
                row[i + 1] = (b[i] + 1) as Real * coef_of(plus(i, None));
            }
            t.value_gradient[k] = row;
            if k < MAX_HESSIAN_MONOMIALS {
                let mut h = [0.0; 8];
                for (l, (i, j)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].into_iter().enumerate() {
                    let factor = if i == j { (b[i] + 1) * (b[i] + 2) } else { (b[i] + 1) * (b[j] + 1) };
                    h[l] = factor as Real * coef_of(plus(i, Some(j)));
                }
                t.hessian[k] = h;
            }
        }
        Self { degree, len, tables: Box::new(t) }
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
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::value(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, value, false, &self.tables, u)
    }

    /// p(u) and ∇p(u).
    #[inline]
    pub fn value_gradient(&self, u: &Vector3) -> (Real, Vector3) {
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::value_gradient(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, gradient, false, &self.tables, u)
    }

    /// p(u), ∇p(u) and ∇²p(u) in one pass.
    #[inline]
    pub fn eval(&self, u: &Vector3) -> super::Eval {
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::eval(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, full, false, &self.tables, u)
    }

    /// The portable kernels (no AVX2 / FMA), for tests of both code paths.
    #[cfg(test)]
    fn eval_portable(&self, u: &Vector3) -> (Real, (Real, Vector3), super::Eval) {
        (
            dispatch!(self.degree, value, false, &self.tables, u),
            dispatch!(self.degree, gradient, false, &self.tables, u),
            dispatch!(self.degree, full, false, &self.tables, u),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn monomial_vector_follows_the_graded_lex_basis() {
        let u = Vector3::new(1.3, -0.7, 0.4);
        let m = monomials::<8, 168>(&u);
        for (k, e) in graded_exponents3(8).into_iter().enumerate() {
            let expected = u.x.powi(e[0] as i32) * u.y.powi(e[1] as i32) * u.z.powi(e[2] as i32);
            assert!((m[k] - expected).abs() <= 1e-14 * expected.abs().max(1.0), "{e:?}");
        }
        assert!(m[165..].iter().all(|&v| v == 0.0));
    }

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
                let r = p.eval(&u);
                let scale = 1.0 + r.value.abs() + r.gradient.amax() + r.hessian.amax();
                let (pv, pg, pe) = f.eval_portable(&u);
                for e in [f.eval(&u), pe] {
                    assert!((r.value - e.value).abs() <= 1e-12 * scale, "degree {degree}");
                    assert!((r.gradient - e.gradient).amax() <= 1e-12 * scale, "degree {degree}");
                    assert!((r.hessian - e.hessian).amax() <= 1e-12 * scale, "degree {degree}");
                }
                for v in [f.value(&u), pv] {
                    assert!((v - r.value).abs() <= 1e-12 * scale);
                }
                for (v, g) in [f.value_gradient(&u), pg] {
                    assert!((v - r.value).abs() <= 1e-12 * scale && (g - r.gradient).amax() <= 1e-12 * scale);
                }
            }
        }
    }
}
