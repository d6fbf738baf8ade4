//! The small linear algebra of the Newton / active-set solvers' KKT systems, written once over a
//! lane type ([`Lane`]): 3-vectors, symmetric and general 3 × 3 matrices per lane, 3 × 3 inverses by
//! cofactors, and the block eliminations of the 4 × 4 growth and 8 × 8 distance systems (paper
//! §IV-A, §IV-B). The single-pair solvers run them on one [`Scalar`](sublevel_kernels::Scalar) lane
//! ([`crate::fast_eval`]), the batch solvers on four `f64` or eight `f32` lanes
//! ([`crate::batch`]).
//!
//! Every function is `#[inline(always)]`: it is compiled into its caller's build (portable, or
//! AVX2 + FMA), where a lane operation is one instruction.

use sublevel_core::math::Vector3;
use sublevel_kernels::{Lane, LaneMask};

/// A 3-vector per lane.
#[derive(Clone, Copy, Debug)]
pub(crate) struct V3<F>(pub(crate) [F; 3]);

impl<F: Lane> V3<F> {
    /// The same vector in every lane.
    #[inline(always)]
    pub(crate) fn splat(cpu: F::Cpu, v: &Vector3) -> Self {
        Self([F::splat(cpu, v.x), F::splat(cpu, v.y), F::splat(cpu, v.z)])
    }

    #[inline(always)]
    pub(crate) fn add(self, o: Self) -> Self {
        Self([self.0[0] + o.0[0], self.0[1] + o.0[1], self.0[2] + o.0[2]])
    }

    #[inline(always)]
    pub(crate) fn sub(self, o: Self) -> Self {
        Self([self.0[0] - o.0[0], self.0[1] - o.0[1], self.0[2] - o.0[2]])
    }

    #[inline(always)]
    pub(crate) fn scale(self, s: F) -> Self {
        Self([self.0[0] * s, self.0[1] * s, self.0[2] * s])
    }

    /// self · s + c, fused.
    #[inline(always)]
    pub(crate) fn mul_add(self, s: F, c: Self) -> Self {
        Self([self.0[0].mul_add(s, c.0[0]), self.0[1].mul_add(s, c.0[1]), self.0[2].mul_add(s, c.0[2])])
    }

    #[inline(always)]
    pub(crate) fn neg(self) -> Self {
        Self([-self.0[0], -self.0[1], -self.0[2]])
    }

    /// `a` where `m`, else `b`.
    #[inline(always)]
    pub(crate) fn select(m: F::Mask, a: Self, b: Self) -> Self {
        Self([F::select(m, a.0[0], b.0[0]), F::select(m, a.0[1], b.0[1]), F::select(m, a.0[2], b.0[2])])
    }

    #[inline(always)]
    pub(crate) fn dot(self, o: Self) -> F {
        self.0[2].mul_add(o.0[2], self.0[1].mul_add(o.0[1], self.0[0] * o.0[0]))
    }
}

/// A symmetric 3 × 3 matrix per lane, upper triangle [xx, xy, xz, yy, yz, zz].
pub(crate) type S3<F> = [F; 6];

/// A general 3 × 3 matrix per lane, row-major `m[3 i + j]`.
pub(crate) type M3<F> = [F; 9];

/// S v.
#[inline(always)]
pub(crate) fn sym_mul<F: Lane>(s: &S3<F>, v: V3<F>) -> V3<F> {
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
pub(crate) fn mat_mul<F: Lane>(m: &M3<F>, v: V3<F>) -> V3<F> {
    let [x, y, z] = v.0;
    V3([
        m[2].mul_add(z, m[1].mul_add(y, m[0] * x)),
        m[5].mul_add(z, m[4].mul_add(y, m[3] * x)),
        m[8].mul_add(z, m[7].mul_add(y, m[6] * x)),
    ])
}

/// Mᵀ v (the transpose is a renaming of registers).
#[inline(always)]
pub(crate) fn mat_t_mul<F: Lane>(m: &M3<F>, v: V3<F>) -> V3<F> {
    mat_mul(&[m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8]], v)
}

/// Mᵀ H M for a symmetric H (upper triangle; [`crate::fast_eval`]'s congruence, per lane).
#[inline(always)]
pub(crate) fn congruence<F: Lane>(m: &M3<F>, h: &S3<F>) -> S3<F> {
    let (a0, a1, a2) = (V3([m[0], m[3], m[6]]), V3([m[1], m[4], m[7]]), V3([m[2], m[5], m[8]]));
    let (h0, h1, h2) = (sym_mul(h, a0), sym_mul(h, a1), sym_mul(h, a2));
    [a0.dot(h0), a0.dot(h1), a0.dot(h2), a1.dot(h1), a1.dot(h2), a2.dot(h2)]
}

/// `d·I + k·S`.
#[inline(always)]
pub(crate) fn shifted<F: Lane>(s: &S3<F>, k: F, d: F) -> S3<F> {
    let [xx, xy, xz, yy, yz, zz] = *s;
    [k.mul_add(xx, d), k * xy, k * xz, k.mul_add(yy, d), k * yz, k.mul_add(zz, d)]
}

/// Inverse of a symmetric 3 × 3 matrix by cofactors per lane, with the lanes where it is (nearly)
/// singular marked false (|det| ≤ [`Lane::SINGULAR`]·max|mᵢⱼ|³, or not finite).
#[inline(always)]
pub(crate) fn inverse_sym<F: Lane>(m: &S3<F>) -> (S3<F>, F::Mask) {
    let [a, b, c, d, e, f] = *m;
    let c00 = d.mul_add(f, -(e * e));
    let c01 = c.mul_add(e, -(b * f));
    let c02 = b.mul_add(e, -(c * d));
    let det = a.mul_add(c00, b.mul_add(c01, c * c02));
    let s = a.abs().max(b.abs()).max(c.abs().max(d.abs())).max(e.abs().max(f.abs()));
    let ok = (a.constant(F::SINGULAR) * s * s * s).lt(det.abs()).and(det.finite()).and(a.constant(0.0).lt(s));
    let k = a.constant(1.0) / det;
    let inv =
        [c00 * k, c01 * k, c02 * k, a.mul_add(f, -(c * c)) * k, b.mul_add(c, -(a * e)) * k, a.mul_add(d, -(b * b)) * k];
    (inv, ok)
}

/// The Newton step of the distance KKT system per lane ([`crate::fast_eval::solve_kkt8`]'s
/// block elimination): (dx, dy, [dλa, dλb]) and the lanes where it exists.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn solve_kkt8<F: Lane>(
    wa: &S3<F>,
    wb: &S3<F>,
    ga: V3<F>,
    gb: V3<F>,
    ra: V3<F>,
    rb: V3<F>,
    ca: F,
    cb: F,
) -> (V3<F>, V3<F>, [F; 2], F::Mask) {
    let (two, four) = (ca.constant(2.0), ca.constant(4.0));
    let (ai, ok_a) = inverse_sym(wa);
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
        .and((ca.constant(F::SINGULAR) * scale).lt(det.abs()))
        .and(ca.constant(0.0).lt(scale))
        .and(det.finite())
        .and(sum.finite());
    (dx, dy, [l1, l2], ok)
}

/// The growth Newton step per lane ([`crate::fast_eval::solve_kkt4`]'s elimination):
/// (dx, dμ) of `[W g; gᵀ 0] [dx; dμ] = −[r; c]` and the lanes where it exists.
#[inline(always)]
pub(crate) fn solve_kkt4<F: Lane>(w: &S3<F>, g: V3<F>, r: V3<F>, c: F) -> (V3<F>, F, F::Mask) {
    let (wi, ok_w) = inverse_sym(w);
    let (wg, wr) = (sym_mul(&wi, g), sym_mul(&wi, r));
    let s = g.dot(wg);
    let dmu = (c - g.dot(wr)) / s;
    let dx = wg.mul_add(dmu, wr).neg();
    let sum = dx.0[0] + dx.0[1] + dx.0[2] + dmu;
    let ok = ok_w.and(c.constant(F::TINY).lt(s.abs())).and(s.finite()).and(sum.finite());
    (dx, dmu, ok)
}

/// max(|v₀|, |v₁|, |v₂|) per lane.
#[inline(always)]
pub(crate) fn abs_max<F: Lane>(v: V3<F>) -> F {
    v.0[0].abs().max(v.0[1].abs()).max(v.0[2].abs())
}

/// The least-squares multiplier `l` where it is finite and positive, else 2‖x − y‖ / ‖g‖
/// (`g2` = ‖g‖²), per lane (the single-pair solver's initial multipliers).
#[inline(always)]
pub(crate) fn positive_multiplier<F: Lane>(l: F, g2: F, dist: F) -> F {
    let fallback = l.constant(2.0) * dist / g2.sqrt().max(l.constant(F::TINY));
    F::select(l.finite().and(l.constant(0.0).lt(l)), l, fallback)
}
