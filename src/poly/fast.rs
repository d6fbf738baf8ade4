//! Fast value / gradient / Hessian evaluation of one polynomial at many points (the query hot
//! path, paper §IV) through per-body derivative coefficient tables and nested Horner schemes.
//!
//! For p(u) = Σ_α c_α u^α (monomials of degree ≤ 2d) every derivative is again a polynomial of
//! lower degree:
//!
//! ```text
//! ∂ᵢ p(u)   = Σ_{|β| ≤ 2d−1} (βᵢ + 1) c_{β+eᵢ} u^β
//! ∂ᵢ∂ⱼ p(u) = Σ_{|β| ≤ 2d−2} (βᵢ + 1)(βⱼ + 1 + δᵢⱼ) c_{β+eᵢ+eⱼ} u^β
//! ```
//!
//! The coefficients are rearranged once per body ([`FastPoly::new`]) into lane-interleaved rows —
//! `[c_β, ∂ₓ, ∂ᵧ, ∂_z]` for |β| ≤ 2d, `[xx, xy, xz, yy]` and `[yz, zz]` for |β| ≤ 2d − 2 — ordered
//! for a nested Horner scheme (exponent a of x, then b of y, then c of z, each descending):
//!
//! ```text
//! q(u) = Σ_a x^a Σ_b y^b Σ_c r_abc z^c  =  Horner in x of (Horner in y of (chains of Horner in z))
//! ```
//!
//! One evaluation is then a sequence of lane-wise fused multiply–adds `acc ← acc·z + row` (then ·y,
//! ·x) over contiguous rows: no monomial vector is built, and the many short z chains are
//! independent. The chain lengths of every degree are literals (macro `horner_fn!`), so each scheme
//! compiles to straight-line code. On x86-64 CPUs with AVX2 and FMA (detected at run time) the
//! kernels are compiled for those instructions; elsewhere they run the portable code.
//!
//! Cost at 2d = 6, measured with callgrind (instructions per evaluation, the previous kernel that
//! summed table rows against the monomial vector in parentheses): value 140 (244), value + gradient
//! 158 (410), value + gradient + Hessian 467 (574). The value reads lane 0 of the value + gradient
//! rows (the unused lanes are dropped by the compiler).

use super::monomial::{basis_len, index3};
use super::polynomial::{Polynomial, MAX_DEGREE};
use crate::math::{Matrix3, Real, Vector3};

/// Rows of the value / gradient table: monomials of degree ≤ 8 in three variables.
pub const MAX_MONOMIALS: usize = 165;

/// Rows of the Hessian table: monomials of degree ≤ 6 (84), the Hessian of a degree-8 polynomial.
const MAX_HESSIAN_MONOMIALS: usize = 84;

/// The per-body coefficient tables (see the module docs); rows beyond the body's basis are zero.
#[derive(Clone, Debug, PartialEq)]
struct Tables {
    /// [c_β, coefficient of u^β in ∂ₓp, ∂ᵧp, ∂_zp].
    value_gradient: [[Real; 4]; MAX_MONOMIALS],
    /// Coefficients of u^β in [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp] (|β| ≤ 2d − 2).
    hessian: [[Real; 4]; MAX_HESSIAN_MONOMIALS],
    /// Coefficients of u^β in [∂ᵧ_zp, ∂_z_zp] (|β| ≤ 2d − 2).
    ///
    /// One 8-lane table `[xx, xy, xz, yy, yz, zz, 0, 0]` instead of this 4 + 2 split was measured
    /// (issue 15, callgrind, `cold_profile 6 20 distance`): 37.4 M instead of 36.0 M instructions
    /// in the full kernel, so the split stays.
    hessian_yz_zz: [[Real; 2]; MAX_HESSIAN_MONOMIALS],
}

/// A polynomial with its derivative coefficient tables for the fast kernels (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FastPoly {
    degree: usize,
    len: usize,
    tables: Box<Tables>,
}

/// The exponents (a, b, c) of degree ≤ `d` in the order of the nested Horner scheme: a descending,
/// then b descending, then c descending.
fn horner_exponents(d: usize) -> Vec<[usize; 3]> {
    let mut out = Vec::with_capacity(basis_len(3, d));
    for a in (0..=d).rev() {
        for b in (0..=d - a).rev() {
            for c in (0..=d - a - b).rev() {
                out.push([a, b, c]);
            }
        }
    }
    out
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

/// `acc ← acc·t + row`, lane-wise.
#[inline(always)]
fn step<const L: usize, const FMA: bool>(acc: &mut [Real; L], t: Real, row: &[Real; L]) {
    for l in 0..L {
        acc[l] = fmadd::<FMA>(acc[l], t, row[l]);
    }
}

/// Horner in z along one chain of M rows starting at `k` (the top coefficient first): M is a
/// constant, so the loop unrolls.
#[inline(always)]
fn chain<const M: usize, const L: usize, const FMA: bool>(rows: &[[Real; L]], k: usize, z: Real) -> [Real; L] {
    let mut acc = rows[k];
    for row in &rows[k + 1..k + M] {
        step::<L, FMA>(&mut acc, z, row);
    }
    acc
}

/// Defines `$name::<L, FMA>(rows, u)`: Σ rows[(a, b, c)] x^a y^b z^c lane-wise over the $n rows of
/// one degree in Horner order ([`horner_exponents`]), as Horner in x of Horner in y of the z
/// chains whose lengths are listed per power of x (descending); every count is a literal, so the
/// whole scheme is straight-line code.
macro_rules! horner_fn {
    ($name:ident, $n:literal; $([$($m:literal),*]),*) => {
        #[inline(always)]
        fn $name<const L: usize, const FMA: bool>(rows: &[[Real; L]], u: &Vector3) -> [Real; L] {
            let rows = &rows[..$n];
            let mut k = 0usize;
            let mut acc_x = [0.0; L];
            $(
                let mut acc_y = [0.0; L];
                $(
                    let acc_z = chain::<$m, L, FMA>(rows, k, u.z);
                    k += $m;
                    step::<L, FMA>(&mut acc_y, u.y, &acc_z);
                )*
                step::<L, FMA>(&mut acc_x, u.x, &acc_y);
            )*
            let _ = k; // the last chain's increment is not read
            acc_x
        }
    };
}

horner_fn!(horner_0, 1; [1]);
horner_fn!(horner_1, 4; [1],[1,2]);
horner_fn!(horner_2, 10; [1],[1,2],[1,2,3]);
horner_fn!(horner_3, 20; [1],[1,2],[1,2,3],[1,2,3,4]);
horner_fn!(horner_4, 35; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5]);
horner_fn!(horner_5, 56; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6]);
horner_fn!(horner_6, 84; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6],[1,2,3,4,5,6,7]);
horner_fn!(horner_7, 120; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6],[1,2,3,4,5,6,7],[1,2,3,4,5,6,7,8]);
horner_fn!(horner_8, 165; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6],[1,2,3,4,5,6,7],[1,2,3,4,5,6,7,8],[1,2,3,4,5,6,7,8,9]);

/// The Horner scheme of degree `$d` (0..=8) over `$rows` with `$l` lanes.
macro_rules! horner_of_degree {
    ($d:expr, $l:literal, $fma:expr, $rows:expr, $u:expr) => {
        match $d {
            0 => horner_0::<$l, $fma>($rows, $u),
            1 => horner_1::<$l, $fma>($rows, $u),
            2 => horner_2::<$l, $fma>($rows, $u),
            3 => horner_3::<$l, $fma>($rows, $u),
            4 => horner_4::<$l, $fma>($rows, $u),
            5 => horner_5::<$l, $fma>($rows, $u),
            6 => horner_6::<$l, $fma>($rows, $u),
            7 => horner_7::<$l, $fma>($rows, $u),
            _ => horner_8::<$l, $fma>($rows, $u),
        }
    };
}

/// p(u) and ∇p(u) for degree `D` (a constant at every call site).
#[inline(always)]
fn gradient_kernel<const D: usize, const FMA: bool>(t: &Tables, u: &Vector3) -> (Real, Vector3) {
    let r = horner_of_degree!(D, 4, FMA, &t.value_gradient, u);
    (r[0], Vector3::new(r[1], r[2], r[3]))
}

/// p(u).
#[inline(always)]
fn value_kernel<const D: usize, const FMA: bool>(t: &Tables, u: &Vector3) -> Real {
    horner_of_degree!(D, 4, FMA, &t.value_gradient, u)[0]
}

/// p(u), ∇p(u) and ∇²p(u) (the Hessian's rows have degree D − 2; zero for D < 2).
#[inline(always)]
fn full_kernel<const D: usize, const FMA: bool>(t: &Tables, u: &Vector3) -> super::Eval {
    let (value, gradient) = gradient_kernel::<D, FMA>(t, u);
    let hessian = if D >= 2 {
        let h = horner_of_degree!(D - 2, 4, FMA, &t.hessian, u);
        let g = horner_of_degree!(D - 2, 2, FMA, &t.hessian_yz_zz, u);
        Matrix3::new(h[0], h[1], h[2], h[1], h[3], g[0], h[2], g[0], g[1])
    } else {
        Matrix3::zeros()
    };
    super::Eval { value, gradient, hessian }
}

/// Calls `$kernel::<D, FMA>` for the runtime degree `$d` (0..=8).
macro_rules! dispatch {
    ($d:expr, value, $fma:expr, $($arg:expr),*) => { dispatch!(@ $d, value_kernel, $fma, $($arg),*) };
    ($d:expr, gradient, $fma:expr, $($arg:expr),*) => { dispatch!(@ $d, gradient_kernel, $fma, $($arg),*) };
    ($d:expr, full, $fma:expr, $($arg:expr),*) => { dispatch!(@ $d, full_kernel, $fma, $($arg),*) };
    (@ $d:expr, $kernel:ident, $fma:expr, $($arg:expr),*) => {
        match $d {
            0 => $kernel::<0, $fma>($($arg),*),
            1 => $kernel::<1, $fma>($($arg),*),
            2 => $kernel::<2, $fma>($($arg),*),
            3 => $kernel::<3, $fma>($($arg),*),
            4 => $kernel::<4, $fma>($($arg),*),
            5 => $kernel::<5, $fma>($($arg),*),
            6 => $kernel::<6, $fma>($($arg),*),
            7 => $kernel::<7, $fma>($($arg),*),
            _ => $kernel::<8, $fma>($($arg),*),
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
        let plus = |b: [usize; 3], i: usize, j: Option<usize>| {
            let mut f = b;
            f[i] += 1;
            if let Some(j) = j {
                f[j] += 1;
            }
            f
        };
        let mut t = Tables {
            value_gradient: [[0.0; 4]; MAX_MONOMIALS],
            hessian: [[0.0; 4]; MAX_HESSIAN_MONOMIALS],
            hessian_yz_zz: [[0.0; 2]; MAX_HESSIAN_MONOMIALS],
        };
        for (k, b) in horner_exponents(degree).into_iter().enumerate() {
            let mut row = [coef_of(b), 0.0, 0.0, 0.0];
            for i in 0..3 {
                row[i + 1] = (b[i] + 1) as Real * coef_of(plus(b, i, None));
            }
            t.value_gradient[k] = row;
        }
        if degree >= 2 {
            for (k, b) in horner_exponents(degree - 2).into_iter().enumerate() {
                let mut h = [0.0; 6];
                for (l, (i, j)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].into_iter().enumerate() {
                    let factor = if i == j { (b[i] + 1) * (b[i] + 2) } else { (b[i] + 1) * (b[j] + 1) };
                    h[l] = factor as Real * coef_of(plus(b, i, Some(j)));
                }
                t.hessian[k] = [h[0], h[1], h[2], h[3]];
                t.hessian_yz_zz[k] = [h[4], h[5]];
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
    fn horner_order_covers_the_basis_once() {
        for d in 0..=MAX_DEGREE {
            let e = horner_exponents(d);
            assert_eq!(e.len(), basis_len(3, d));
            let mut seen: Vec<usize> = e.iter().map(|e| index3([e[0] as u8, e[1] as u8, e[2] as u8])).collect();
            seen.sort_unstable();
            assert_eq!(seen, (0..basis_len(3, d)).collect::<Vec<_>>());
        }
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
