//! The batch solvers' lane arithmetic, written once over a lane type ([`Lane`]): four `f64` lanes
//! in an AVX register ([`F4`], the solvers' double-precision rounds) or eight `f32` lanes
//! ([`F8`], the distance solver's coarse stage, twice the pairs per instruction). The 3-vectors,
//! symmetric and general 3 × 3 matrices and the closed-form KKT solves are the single-pair
//! solver's ([`crate::fast_eval`]) per lane.
//!
//! Every method runs AVX / AVX2 / FMA instructions: values of these types exist only inside the
//! batch solver's AVX2 + FMA build (`lanes_avx2`), which runs only on CPUs with AVX2 and FMA (the
//! invariant of the `unsafe` blocks below), and the methods are inlined into it.

use std::arch::x86_64::*;
use std::ops::{Add, Div, Mul, Neg, Sub};
use sublevel_core::math::Real;

/// A lane mask (all bits of a lane set or clear), as the AVX comparisons make it.
pub(super) trait LaneMask: Copy + Default {
    /// Lanes set in both.
    fn and(self, o: Self) -> Self;
    /// Lanes set in either.
    fn or(self, o: Self) -> Self;
    /// Lanes clear in `self`.
    fn not(self) -> Self;
    /// Bit i set where lane i is.
    fn bits(self) -> u32;
}

/// One real per lane, in an AVX register: the operations the batch solvers' lane arithmetic needs.
pub(super) trait Lane:
    Copy + Default + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    /// The comparisons' masks.
    type Mask: LaneMask;
    /// Relative size |det| / s³ (s the largest entry) below which a 3 × 3 block counts as singular
    /// ([`crate::fast_eval::inverse_sym3`]'s 10⁻¹⁴ in double precision).
    const SINGULAR: Real;
    /// The smallest divisor a multiplier's fallback and the 4 × 4 solve accept (normal numbers of
    /// the lane's precision).
    const TINY: Real;
    /// `v` (rounded to the lane's precision) in every lane.
    fn splat(v: Real) -> Self;
    /// self · b + c, fused.
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// |self| per lane.
    fn abs(self) -> Self;
    /// √self per lane.
    fn sqrt(self) -> Self;
    /// Lane-wise min without NaN handling (the second operand where either is NaN).
    fn min(self, o: Self) -> Self;
    /// Lane-wise max without NaN handling (see [`crate::fast_eval::max_plain`]).
    fn max(self, o: Self) -> Self;
    /// Lanes where self ≤ o (false where either is NaN).
    fn le(self, o: Self) -> Self::Mask;
    /// Lanes where self < o (false where either is NaN).
    fn lt(self, o: Self) -> Self::Mask;
    /// `a` where `m`, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Lanes where self is finite.
    #[inline(always)]
    fn finite(self) -> Self::Mask {
        self.abs().lt(Self::splat(Real::INFINITY))
    }
}

/// Implements the arithmetic operators of a lane type `$t` (register field `.0`) by intrinsics.
macro_rules! lane_ops {
    ($t:ident, $add:ident, $sub:ident, $mul:ident, $div:ident, $xor:ident, $set1:ident) => {
        impl Add for $t {
            type Output = $t;
            #[inline(always)]
            fn add(self, o: $t) -> $t {
                // SAFETY: see the module docs.
                $t(unsafe { $add(self.0, o.0) })
            }
        }
        impl Sub for $t {
            type Output = $t;
            #[inline(always)]
            fn sub(self, o: $t) -> $t {
                // SAFETY: see the module docs.
                $t(unsafe { $sub(self.0, o.0) })
            }
        }
        impl Mul for $t {
            type Output = $t;
            #[inline(always)]
            fn mul(self, o: $t) -> $t {
                // SAFETY: see the module docs.
                $t(unsafe { $mul(self.0, o.0) })
            }
        }
        impl Div for $t {
            type Output = $t;
            #[inline(always)]
            fn div(self, o: $t) -> $t {
                // SAFETY: see the module docs.
                $t(unsafe { $div(self.0, o.0) })
            }
        }
        impl Neg for $t {
            type Output = $t;
            #[inline(always)]
            fn neg(self) -> $t {
                // SAFETY: see the module docs (flips the sign bits).
                $t(unsafe { $xor($set1(-0.0), self.0) })
            }
        }
        impl Default for $t {
            #[inline(always)]
            fn default() -> Self {
                Self::splat(0.0)
            }
        }
    };
}

/// Four `f64`, one per lane, in an AVX register.
#[derive(Clone, Copy, Debug)]
pub(super) struct F4(pub(super) __m256d);

/// A mask of four `f64` lanes; see [`F4`].
#[derive(Clone, Copy, Debug)]
pub(super) struct M4(__m256d);

impl F4 {
    #[inline(always)]
    pub(super) fn load(v: &[Real; 4]) -> Self {
        // SAFETY: `v` is four readable reals; see the module docs.
        Self(unsafe { _mm256_loadu_pd(v.as_ptr()) })
    }

    #[inline(always)]
    pub(super) fn to_array(self) -> [Real; 4] {
        let mut out = [0.0; 4];
        // SAFETY: `out` is four writable reals; see the module docs.
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), self.0) };
        out
    }

    /// Lane-wise floor.
    #[inline(always)]
    pub(super) fn floor(self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_floor_pd(self.0) })
    }
}

impl Lane for F4 {
    type Mask = M4;
    const SINGULAR: Real = 1e-14;
    const TINY: Real = 1e-300;

    #[inline(always)]
    fn splat(v: Real) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_set1_pd(v) })
    }

    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_fmadd_pd(self.0, b.0, c.0) })
    }

    #[inline(always)]
    fn abs(self) -> Self {
        // SAFETY: see the module docs (clears the sign bits).
        Self(unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0) })
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_sqrt_pd(self.0) })
    }

    #[inline(always)]
    fn min(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_min_pd(self.0, o.0) })
    }

    #[inline(always)]
    fn max(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_max_pd(self.0, o.0) })
    }

    #[inline(always)]
    fn le(self, o: Self) -> M4 {
        // SAFETY: see the module docs.
        M4(unsafe { _mm256_cmp_pd::<_CMP_LE_OQ>(self.0, o.0) })
    }

    #[inline(always)]
    fn lt(self, o: Self) -> M4 {
        // SAFETY: see the module docs.
        M4(unsafe { _mm256_cmp_pd::<_CMP_LT_OQ>(self.0, o.0) })
    }

    #[inline(always)]
    fn select(m: M4, a: Self, b: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_blendv_pd(b.0, a.0, m.0) })
    }
}

lane_ops!(F4, _mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_div_pd, _mm256_xor_pd, _mm256_set1_pd);

impl Default for M4 {
    #[inline(always)]
    fn default() -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_setzero_pd() })
    }
}

impl M4 {
    #[inline(always)]
    pub(super) fn from_bools(b: [bool; 4]) -> Self {
        let m = |v: bool| if v { -1i64 } else { 0 };
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_castsi256_pd(_mm256_set_epi64x(m(b[3]), m(b[2]), m(b[1]), m(b[0]))) })
    }
}

impl LaneMask for M4 {
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_and_pd(self.0, o.0) })
    }

    #[inline(always)]
    fn or(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_or_pd(self.0, o.0) })
    }

    #[inline(always)]
    fn not(self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_xor_pd(self.0, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))) })
    }

    #[inline(always)]
    fn bits(self) -> u32 {
        // SAFETY: see the module docs.
        unsafe { _mm256_movemask_pd(self.0) as u32 }
    }
}

/// Eight `f32`, one per lane, in an AVX register: the coarse stage's lanes (relative rounding
/// 6·10⁻⁸, far below the coarse stage's hand-off residual of 10⁻³).
#[derive(Clone, Copy, Debug)]
pub(super) struct F8(pub(super) __m256);

/// A mask of eight `f32` lanes; see [`F8`].
#[derive(Clone, Copy, Debug)]
pub(super) struct M8(__m256);

impl F8 {
    #[inline(always)]
    pub(super) fn load(v: &[f32; 8]) -> Self {
        // SAFETY: `v` is eight readable `f32`; see the module docs.
        Self(unsafe { _mm256_loadu_ps(v.as_ptr()) })
    }

    #[inline(always)]
    pub(super) fn to_array(self) -> [f32; 8] {
        let mut out = [0.0; 8];
        // SAFETY: `out` is eight writable `f32`; see the module docs.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
        out
    }
}

impl Lane for F8 {
    type Mask = M8;
    const SINGULAR: Real = 1e-10;
    const TINY: Real = 1e-30;

    #[inline(always)]
    fn splat(v: Real) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_set1_ps(v as f32) })
    }

    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_fmadd_ps(self.0, b.0, c.0) })
    }

    #[inline(always)]
    fn abs(self) -> Self {
        // SAFETY: see the module docs (clears the sign bits).
        Self(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_sqrt_ps(self.0) })
    }

    #[inline(always)]
    fn min(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_min_ps(self.0, o.0) })
    }

    #[inline(always)]
    fn max(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_max_ps(self.0, o.0) })
    }

    #[inline(always)]
    fn le(self, o: Self) -> M8 {
        // SAFETY: see the module docs.
        M8(unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(self.0, o.0) })
    }

    #[inline(always)]
    fn lt(self, o: Self) -> M8 {
        // SAFETY: see the module docs.
        M8(unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0) })
    }

    #[inline(always)]
    fn select(m: M8, a: Self, b: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_blendv_ps(b.0, a.0, m.0) })
    }
}

lane_ops!(F8, _mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps, _mm256_div_ps, _mm256_xor_ps, _mm256_set1_ps);

impl Default for M8 {
    #[inline(always)]
    fn default() -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_setzero_ps() })
    }
}

impl M8 {
    #[inline(always)]
    pub(super) fn from_bools(b: [bool; 8]) -> Self {
        let m = |v: bool| if v { -1i32 } else { 0 };
        // SAFETY: see the module docs.
        Self(unsafe {
            _mm256_castsi256_ps(_mm256_set_epi32(
                m(b[7]),
                m(b[6]),
                m(b[5]),
                m(b[4]),
                m(b[3]),
                m(b[2]),
                m(b[1]),
                m(b[0]),
            ))
        })
    }
}

impl LaneMask for M8 {
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_and_ps(self.0, o.0) })
    }

    #[inline(always)]
    fn or(self, o: Self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_or_ps(self.0, o.0) })
    }

    #[inline(always)]
    fn not(self) -> Self {
        // SAFETY: see the module docs.
        Self(unsafe { _mm256_xor_ps(self.0, _mm256_castsi256_ps(_mm256_set1_epi32(-1))) })
    }

    #[inline(always)]
    fn bits(self) -> u32 {
        // SAFETY: see the module docs.
        unsafe { _mm256_movemask_ps(self.0) as u32 }
    }
}

/// A 3-vector per lane.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct V3<F = F4>(pub(super) [F; 3]);

impl<F: Lane> V3<F> {
    /// The same vector in every lane.
    #[inline(always)]
    pub(super) fn splat(v: &sublevel_core::math::Vector3) -> Self {
        Self([F::splat(v.x), F::splat(v.y), F::splat(v.z)])
    }

    #[inline(always)]
    pub(super) fn add(self, o: Self) -> Self {
        Self([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }

    #[inline(always)]
    pub(super) fn sub(self, o: Self) -> Self {
        Self([self.0[0] - o.0[0], self.0[1] - o.0[1], self.0[2] - o.0[2]])
    }

    #[inline(always)]
    pub(super) fn scale(self, s: F) -> Self {
        Self([self.0[0] * s, self.0[1] * s, self.0[2] * s])
    }

    /// self · s + c, fused.
    #[inline(always)]
    pub(super) fn mul_add(self, s: F, c: Self) -> Self {
        Self([self.0[0].mul_add(s, c.0[0]), self.0[1].mul_add(s, c.0[1]), self.0[2].mul_add(s, c.0[2])])
    }

    #[inline(always)]
    pub(super) fn neg(self) -> Self {
        Self([-self.0[0], -self.0[1], -self.0[2]])
    }

    /// `a` where `m`, else `b`.
    #[inline(always)]
    pub(super) fn select(m: F::Mask, a: Self, b: Self) -> Self {
        Self([F::select(m, a.0[0], b.0[0]), F::select(m, a.0[1], b.0[1]), F::select(m, a.0[2], b.0[2])])
    }

    #[inline(always)]
    pub(super) fn dot(self, o: Self) -> F {
        self.0[2].mul_add(o.0[2], self.0[1].mul_add(o.0[1], self.0[0] * o.0[0]))
    }
}

impl V3<F4> {
    /// Lane `i` as a vector.
    #[inline(always)]
    pub fn lane(a: &[[Real; 4]; 3], i: usize) -> sublevel_core::math::Vector3 {
        sublevel_core::math::Vector3::new(a[0][i], a[1][i], a[2][i])
    }

    #[inline(always)]
    pub(super) fn load(v: &[[Real; 4]; 3]) -> Self {
        Self([F4::load(&v[0]), F4::load(&v[1]), F4::load(&v[2])])
    }

    #[inline(always)]
    pub(super) fn to_arrays(self) -> [[Real; 4]; 3] {
        [self.0[0].to_array(), self.0[1].to_array(), self.0[2].to_array()]
    }
}

impl V3<F8> {
    #[inline(always)]
    pub(super) fn load32(v: &[[f32; 8]; 3]) -> Self {
        Self([F8::load(&v[0]), F8::load(&v[1]), F8::load(&v[2])])
    }

    #[inline(always)]
    pub(super) fn to_arrays32(self) -> [[f32; 8]; 3] {
        [self.0[0].to_array(), self.0[1].to_array(), self.0[2].to_array()]
    }
}

/// A symmetric 3 × 3 matrix per lane, upper triangle [xx, xy, xz, yy, yz, zz].
pub(super) type S3<F = F4> = [F; 6];

/// A general 3 × 3 matrix per lane, row-major `m[3 i + j]`.
pub(super) type M3<F = F4> = [F; 9];

/// S v.
#[inline(always)]
pub(super) fn sym_mul<F: Lane>(s: &S3<F>, v: V3<F>) -> V3<F> {
    let [xx, xy, xz, yy, yz, zz] = *s;
    let [x, y, z] = v.0;
    V3([
        xz.mul_add(z, xy.mul_add(y, xx * x)),
        yz.mul_add(z, yy.mul_add(y, xy * x)),
        zz.mul_add(z, yz.mul_add(y, xz * x)),
    ])
}

/// M v.
#[inline(always)]
pub(super) fn mat_mul<F: Lane>(m: &M3<F>, v: V3<F>) -> V3<F> {
    let [x, y, z] = v.0;
    V3([
        m[2].mul_add(z, m[1].mul_add(y, m[0] * x)),
        m[5].mul_add(z, m[4].mul_add(y, m[3] * x)),
        m[8].mul_add(z, m[7].mul_add(y, m[6] * x)),
    ])
}

/// Mᵀ v (the transpose is a renaming of registers).
#[inline(always)]
pub(super) fn mat_t_mul<F: Lane>(m: &M3<F>, v: V3<F>) -> V3<F> {
    mat_mul(&[m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8]], v)
}

/// Mᵀ H M for a symmetric H (upper triangle; [`crate::fast_eval`]'s congruence, per lane).
#[inline(always)]
pub(super) fn congruence<F: Lane>(m: &M3<F>, h: &S3<F>) -> S3<F> {
    let (a0, a1, a2) = (V3([m[0], m[3], m[6]]), V3([m[1], m[4], m[7]]), V3([m[2], m[5], m[8]]));
    let (h0, h1, h2) = (sym_mul(h, a0), sym_mul(h, a1), sym_mul(h, a2));
    [a0.dot(h0), a0.dot(h1), a0.dot(h2), a1.dot(h1), a1.dot(h2), a2.dot(h2)]
}

/// `d·I + k·S`.
#[inline(always)]
pub(super) fn shifted<F: Lane>(s: &S3<F>, k: F, d: F) -> S3<F> {
    let [xx, xy, xz, yy, yz, zz] = *s;
    [k.mul_add(xx, d), k * xy, k * xz, k.mul_add(yy, d), k * yz, k.mul_add(zz, d)]
}

/// Inverse of a symmetric 3 × 3 matrix by cofactors per lane, with the lanes where it is (nearly)
/// singular marked false ([`crate::fast_eval::inverse_sym3`]'s test, per lane, at the lane
/// type's [`Lane::SINGULAR`]).
#[inline(always)]
pub(super) fn inverse_sym<F: Lane>(m: &S3<F>) -> (S3<F>, F::Mask) {
    let [a, b, c, d, e, f] = *m;
    let c00 = d.mul_add(f, -(e * e));
    let c01 = c.mul_add(e, -(b * f));
    let c02 = b.mul_add(e, -(c * d));
    let det = a.mul_add(c00, b.mul_add(c01, c * c02));
    let s = a.abs().max(b.abs()).max(c.abs().max(d.abs())).max(e.abs().max(f.abs()));
    let ok = (F::splat(F::SINGULAR) * s * s * s).lt(det.abs()).and(det.finite()).and(F::default().lt(s));
    let k = F::splat(1.0) / det;
    let inv =
        [c00 * k, c01 * k, c02 * k, a.mul_add(f, -(c * c)) * k, b.mul_add(c, -(a * e)) * k, a.mul_add(d, -(b * b)) * k];
    (inv, ok)
}

/// The Newton step of the distance KKT system per lane ([`crate::fast_eval::solve_kkt8`]'s
/// block elimination): (dx, dy, [dλa, dλb]) and the lanes where it exists.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn solve_kkt8<F: Lane>(
    wa: &S3<F>,
    wb: &S3<F>,
    ga: V3<F>,
    gb: V3<F>,
    ra: V3<F>,
    rb: V3<F>,
    ca: F,
    cb: F,
) -> (V3<F>, V3<F>, [F; 2], F::Mask) {
    let two = F::splat(2.0);
    let (ai, ok_a) = inverse_sym(wa);
    let four = F::splat(4.0);
    let schur: S3<F> = [
        wb[0] - four * ai[0],
        wb[1] - four * ai[1],
        wb[2] - four * ai[2],
        wb[3] - four * ai[3],
        wb[4] - four * ai[4],
        wb[5] - four * ai[5],
    ];
    let (si, ok_s) = inverse_sym(&schur);
    // The scalar step's six products (see its comments): no p₀, p₁, p₂, and s₂₁ = s₁₂.
    let t0 = sym_mul(&ai, ra);
    let t1 = sym_mul(&ai, ga);
    let q0 = sym_mul(&si, t0.mul_add(two, rb));
    let q1 = sym_mul(&si, t1).scale(two);
    let q2 = sym_mul(&si, gb);
    let (s11, s12, s22) = (q1.mul_add(two, ga).dot(t1), two * t1.dot(q2), gb.dot(q2));
    let det = s11 * s22 - s12 * s12;
    let scale = (s11.abs() + s12.abs()) * (s12.abs() + s22.abs());
    let (h1, h2) = (ca - (ga.dot(t0) + two * t1.dot(q0)), cb - gb.dot(q0));
    let l1 = (s22 * h1 - s12 * h2) / det;
    let l2 = (s11 * h2 - s12 * h1) / det;
    // −dy = q₀ + dλa q₁ + dλb q₂; −dx = t₀ + dλa t₁ + 2 Ai (−dy) (Wa dx − 2dy + ga dλa = −ra).
    let dy = q1.mul_add(l1, q0);
    let dy = q2.mul_add(l2, dy);
    let dx = t1.mul_add(l1, t0);
    let dx = sym_mul(&ai, dy).mul_add(two, dx);
    let (dx, dy) = (dx.neg(), dy.neg());
    let sum = dx.0[0] + dx.0[1] + dx.0[2] + dy.0[0] + dy.0[1] + dy.0[2] + l1 + l2;
    let ok = ok_a
        .and(ok_s)
        .and((F::splat(F::SINGULAR) * scale).lt(det.abs()))
        .and(F::default().lt(scale))
        .and(det.finite())
        .and(sum.finite());
    (dx, dy, [l1, l2], ok)
}

/// The growth Newton step per lane ([`crate::fast_eval::solve_kkt4`]'s elimination):
/// (dx, dμ) of `[W g; gᵀ 0] [dx; dμ] = −[r; c]` and the lanes where it exists.
#[inline(always)]
pub(super) fn solve_kkt4<F: Lane>(w: &S3<F>, g: V3<F>, r: V3<F>, c: F) -> (V3<F>, F, F::Mask) {
    let (wi, ok_w) = inverse_sym(w);
    let (wg, wr) = (sym_mul(&wi, g), sym_mul(&wi, r));
    let s = g.dot(wg);
    let dmu = (c - g.dot(wr)) / s;
    let dx = wg.mul_add(dmu, wr).neg();
    let sum = dx.0[0] + dx.0[1] + dx.0[2] + dmu;
    let ok = ok_w.and(F::splat(F::TINY).lt(s.abs())).and(s.finite()).and(sum.finite());
    (dx, dmu, ok)
}

/// max(|v₀|, |v₁|, |v₂|) per lane.
#[inline(always)]
pub(super) fn abs_max<F: Lane>(v: V3<F>) -> F {
    v.0[0].abs().max(v.0[1].abs()).max(v.0[2].abs())
}

/// The least-squares multiplier `l` where it is finite and positive, else 2‖x − y‖ / ‖g‖
/// (`g2` = ‖g‖²), per lane (the single-pair solver's initial multipliers).
#[inline(always)]
pub(super) fn positive_multiplier<F: Lane>(l: F, g2: F, dist: F) -> F {
    let fallback = F::splat(2.0) * dist / g2.sqrt().max(F::splat(F::TINY));
    F::select(l.finite().and(F::default().lt(l)), l, fallback)
}
