//! Hot-path evaluation of a posed body for the Newton solvers: p'(x) = p(A x + b) through the
//! body's precomputed derivative tables ([`sublevel_core::poly::FastPoly`]), with the Hessian computed
//! only when a Newton step needs it (`∇ₓ = Aᵀ∇ᵤ`, `∇²ₓ = Aᵀ∇²ᵤA`, A = Rᵀ/scale).
//!
//! Also the single-pair solvers' entry points to the KKT systems' small linear algebra
//! ([`crate::lane_algebra`] on one lane: 3 × 3 inverses by cofactors, block elimination of the
//! 4 × 4 growth and 8 × 8 distance systems).

use crate::lane_algebra::{self, S3, V3};
use sublevel_core::body::PosedBody;
use sublevel_core::math::{Matrix3, Real, Sym3, Vector3};
use sublevel_core::poly::{FastPoly, SymEval};
use sublevel_kernels::{Avx2Fma, Scalar};

/// a·b + c, fused when `FMA` (the solvers' AVX2 + FMA builds, see
/// [`sublevel_core::math::cpu_has_avx2_fma`]); two roundings otherwise, never a library call.
#[inline(always)]
pub(crate) fn fmadd<const FMA: bool>(a: Real, b: Real, c: Real) -> Real {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// M v for a 3 × 3 matrix (column-major: M v = m₀ vₓ + m₁ v_y + m₂ v_z), fused where `FMA`.
#[inline(always)]
pub(crate) fn mat_vec<const FMA: bool>(m: &Matrix3, v: &Vector3) -> Vector3 {
    let row = |i: usize| fmadd::<FMA>(m[(i, 2)], v.z, fmadd::<FMA>(m[(i, 1)], v.y, m[(i, 0)] * v.x));
    Vector3::new(row(0), row(1), row(2))
}

/// S v for a symmetric 3 × 3 matrix, fused where `FMA`.
#[inline(always)]
pub(crate) fn sym_mat_vec<const FMA: bool>(s: &Sym3, v: &Vector3) -> Vector3 {
    let [xx, xy, xz, yy, yz, zz] = s.0;
    Vector3::new(
        fmadd::<FMA>(xz, v.z, fmadd::<FMA>(xy, v.y, xx * v.x)),
        fmadd::<FMA>(yz, v.z, fmadd::<FMA>(yy, v.y, xy * v.x)),
        fmadd::<FMA>(zz, v.z, fmadd::<FMA>(yz, v.y, xz * v.x)),
    )
}

/// `d·I + k·S`, fused where `FMA` (the KKT blocks `2I + λ∇²p'`; [`lane_algebra::shifted`] on
/// one lane).
#[inline(always)]
pub(crate) fn shifted<const FMA: bool>(s: &Sym3, k: Real, d: Real) -> Sym3 {
    from_lane_sym(lane_algebra::shifted(&lane_sym::<FMA>(s), Scalar(k), Scalar(d)))
}

/// A vector as one lane of [`lane_algebra`].
#[inline(always)]
fn lane_vector<const FMA: bool>(v: &Vector3) -> V3<Scalar<FMA>> {
    V3([Scalar(v.x), Scalar(v.y), Scalar(v.z)])
}

/// One lane of [`lane_algebra`] as a vector.
#[inline(always)]
fn from_lane_vector<const FMA: bool>(v: V3<Scalar<FMA>>) -> Vector3 {
    Vector3::new(v.0[0].0, v.0[1].0, v.0[2].0)
}

/// A symmetric matrix as one lane of [`lane_algebra`].
#[inline(always)]
fn lane_sym<const FMA: bool>(s: &Sym3) -> S3<Scalar<FMA>> {
    s.0.map(Scalar)
}

/// One lane of [`lane_algebra`] as a symmetric matrix.
#[inline(always)]
fn from_lane_sym<const FMA: bool>(s: S3<Scalar<FMA>>) -> Sym3 {
    Sym3(s.map(|v| v.0))
}

/// `a + k·b` entrywise, fused where `FMA`.
#[inline(always)]
pub(crate) fn sym_add_scaled<const FMA: bool>(a: &Sym3, k: Real, b: &Sym3) -> Sym3 {
    Sym3(std::array::from_fn(|i| fmadd::<FMA>(k, b.0[i], a.0[i])))
}

/// a · b, fused where `FMA`.
#[inline(always)]
pub(crate) fn dot<const FMA: bool>(a: &Vector3, b: &Vector3) -> Real {
    fmadd::<FMA>(a.z, b.z, fmadd::<FMA>(a.y, b.y, a.x * b.x))
}

/// A posed body's world → normalized map and its fast evaluator; `FMA` selects fused arithmetic
/// for the solvers' AVX2 + FMA builds (the default `false` is the portable one).
#[derive(Clone, Copy)]
pub(crate) struct FastPosed<'a, const FMA: bool = false> {
    poly: &'a FastPoly,
    a: Matrix3,
    at: Matrix3,
    b: Vector3,
    /// A = I/scale (the body posed without rotation, as the frame body of every query is): then
    /// u = x/scale + b, ∇ₓ = ∇ᵤ/scale and ∇²ₓ = ∇²ᵤ/scale², with no matrix products.
    unrotated: bool,
    /// 1/scale, always set (not an `Option`'s payload): LLVM computes both arms of the
    /// `unrotated` branches and blends them, and an unset payload's stack garbage could be a
    /// subnormal number, whose every multiply takes a microcode assist on Intel cores (a third
    /// more time per cold distance query at 2d = 6 when it is one).
    inv_scale: Real,
    /// The proof that the CPU runs the AVX2 + FMA kernels when `FMA` (checked once in
    /// [`Self::build`]): the evaluations call them directly instead of through [`FastPoly`]'s
    /// per-call check. Always `None` (and unread) off x86-64.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    avx2: Option<Avx2Fma>,
}

/// Value, world gradient and (when evaluated) the normalized-frame Hessian's upper triangle at
/// one point (one evaluation pass); the world Hessian `Aᵀ∇²ᵤA` is formed only when a Newton step
/// needs it ([`FastPosed::hessian`]).
pub(crate) struct PosedEval {
    pub value: Real,
    pub gradient: Vector3,
    hessian_u: Option<Sym3>,
}

/// `$s.poly.$avx2(cpu, $u)` (the AVX2 + FMA kernel, no CPU check) when `$s` was built for it,
/// else `$s.poly.$portable($u)` (which checks the CPU and dispatches).
macro_rules! through_kernel {
    ($s:ident, $avx2:ident, $portable:ident, $u:ident) => {{
        #[cfg(target_arch = "x86_64")]
        if FMA {
            if let Some(cpu) = $s.avx2 {
                return $s.poly.$avx2(cpu, $u);
            }
        }
        $s.poly.$portable($u)
    }};
}

impl<'a> FastPosed<'a> {
    /// The evaluator of a posed body, portable arithmetic.
    #[inline(always)]
    pub fn new(pb: &PosedBody<'a>) -> Self {
        Self::build(pb)
    }
}

impl<'a, const FMA: bool> FastPosed<'a, FMA> {
    /// The evaluator of a posed body, fused arithmetic where `FMA`.
    #[inline(always)]
    pub fn build(pb: &PosedBody<'a>) -> Self {
        let a = *pb.linear();
        let q = pb.pose.rotation.quaternion();
        Self {
            poly: pb.body.fast_polynomial(),
            a,
            at: a.transpose(),
            b: pb.to_normalized(&Vector3::zeros()),
            unrotated: q.i == 0.0 && q.j == 0.0 && q.k == 0.0,
            inv_scale: 1.0 / pb.body.scale(),
            avx2: if FMA { Avx2Fma::detect() } else { None },
        }
    }

    /// p(u) through the kernel this evaluator was built for.
    #[inline(always)]
    fn poly_value(&self, u: &Vector3) -> Real {
        through_kernel!(self, value_avx2, value, u)
    }

    /// p(u) and ∇p(u) through the kernel this evaluator was built for.
    #[inline(always)]
    fn poly_value_gradient(&self, u: &Vector3) -> (Real, Vector3) {
        through_kernel!(self, value_gradient_avx2, value_gradient, u)
    }

    /// p(u), ∇p(u) and ∇²p(u) (upper triangle) through the kernel this evaluator was built for.
    #[inline(always)]
    fn poly_eval(&self, u: &Vector3) -> SymEval {
        through_kernel!(self, eval_sym_avx2, eval_sym, u)
    }

    /// u = A x + b.
    #[inline(always)]
    fn normalized(&self, x: &Vector3) -> Vector3 {
        if self.unrotated {
            let k = self.inv_scale;
            Vector3::new(fmadd::<FMA>(x.x, k, self.b.x), fmadd::<FMA>(x.y, k, self.b.y), fmadd::<FMA>(x.z, k, self.b.z))
        } else {
            mat_vec::<FMA>(&self.a, x) + self.b
        }
    }

    /// ∇ₓ = Aᵀ∇ᵤ.
    #[inline(always)]
    fn world_gradient(&self, g: &Vector3) -> Vector3 {
        if self.unrotated {
            g * self.inv_scale
        } else {
            mat_vec::<FMA>(&self.at, g)
        }
    }

    /// p'(x).
    #[inline(always)]
    pub fn value(&self, x: &Vector3) -> Real {
        self.poly_value(&self.normalized(x))
    }

    /// p'(x) and ∇p'(x).
    #[inline(always)]
    pub fn value_gradient(&self, x: &Vector3) -> (Real, Vector3) {
        let (v, g) = self.poly_value_gradient(&self.normalized(x));
        (v, self.world_gradient(&g))
    }

    /// p'(x), ∇p'(x) and, when `hessian` is set, (deferred) ∇²p'(x), in one pass.
    #[inline(always)]
    pub fn eval(&self, x: &Vector3, hessian: bool) -> PosedEval {
        let u = self.normalized(x);
        if hessian {
            let e = self.poly_eval(&u);
            PosedEval { value: e.value, gradient: self.world_gradient(&e.gradient), hessian_u: Some(e.hessian) }
        } else {
            let (value, g) = self.poly_value_gradient(&u);
            PosedEval { value, gradient: self.world_gradient(&g), hessian_u: None }
        }
    }

    /// ∇²p'(x) (upper triangle) from an evaluation of [`Self::eval`] at x that included the
    /// Hessian.
    #[inline(always)]
    pub fn hessian(&self, e: &PosedEval) -> Option<Sym3> {
        let h = e.hessian_u?;
        Some(if self.unrotated {
            h.scaled(self.inv_scale * self.inv_scale)
        } else {
            congruence_sym::<FMA>(&self.a, &h)
        })
    }
}

/// Aᵀ H A for a symmetric H: the six entries of the upper triangle (45 products instead of the 54
/// of two general 3 × 3 products).
#[inline(always)]
fn congruence_sym<const FMA: bool>(a: &Matrix3, h: &Sym3) -> Sym3 {
    // Columns a_j of A and h_j = H a_j; entry (i, j) = a_i · h_j.
    let col = |j: usize| Vector3::new(a[(0, j)], a[(1, j)], a[(2, j)]);
    let (a0, a1, a2) = (col(0), col(1), col(2));
    let (h0, h1, h2) = (sym_mat_vec::<FMA>(h, &a0), sym_mat_vec::<FMA>(h, &a1), sym_mat_vec::<FMA>(h, &a2));
    let (m00, m01, m02) = (dot::<FMA>(&a0, &h0), dot::<FMA>(&a0, &h1), dot::<FMA>(&a0, &h2));
    let (m11, m12, m22) = (dot::<FMA>(&a1, &h1), dot::<FMA>(&a1, &h2), dot::<FMA>(&a2, &h2));
    Sym3([m00, m01, m02, m11, m12, m22])
}

/// max |vᵢ| (plain comparisons; nalgebra's `amax` goes through generic SIMD traits on the hot path).
/// A NaN entry is not propagated (nor is it by `f64::max`): callers test finiteness separately.
#[inline(always)]
pub(crate) fn abs_max(v: &Vector3) -> Real {
    max_plain(max_plain(v.x.abs(), v.y.abs()), v.z.abs())
}

/// max(a, b) without NaN handling (one `maxsd`, where `f64::max` adds a NaN test and a blend):
/// for bounds whose NaN inputs are caught by another test.
#[inline(always)]
pub(crate) fn max_plain(a: Real, b: Real) -> Real {
    if a > b {
        a
    } else {
        b
    }
}

/// Inverse of a symmetric 3 × 3 matrix by cofactors (six cofactors instead of nine); `None` when
/// (nearly) singular relative to its entries (|det| ≤ 10⁻¹⁴ max|mᵢⱼ|³, or non-finite):
/// [`lane_algebra::inverse_sym`] on one lane. The KKT blocks `2I + λ∇²p'` and their Schur
/// complements are symmetric.
#[cfg(test)]
#[inline(always)]
pub(crate) fn inverse_sym3<const FMA: bool>(m: &Sym3) -> Option<Sym3> {
    let (inv, ok) = lane_algebra::inverse_sym(&lane_sym::<FMA>(m));
    ok.then(|| from_lane_sym(inv))
}

/// Solves the growth KKT system `[W g; gᵀ 0] [dx; dμ] = −[r; c]` by eliminating dx
/// (dμ = (c − gᵀW⁻¹r)/(gᵀW⁻¹g)): [`lane_algebra::solve_kkt4`] on one lane; `None` when W or the
/// Schur complement is singular, or the step is not finite.
#[inline(always)]
pub(crate) fn solve_kkt4<const FMA: bool>(w: &Sym3, g: &Vector3, r: &Vector3, c: Real) -> Option<(Vector3, Real)> {
    let (dx, dmu, ok) = lane_algebra::solve_kkt4(&lane_sym::<FMA>(w), lane_vector(g), lane_vector(r), Scalar(c));
    ok.then(|| (from_lane_vector(dx), dmu.0))
}

/// Solves the distance KKT system (8 × 8)
///
/// ```text
/// [ Wa  −2I  ga  0 ] [dx]     [ra]
/// [ −2I  Wb  0  gb ] [dy]  = −[rb]
/// [ gaᵀ  0   0   0 ] [dλa]    [ca]
/// [ 0   gbᵀ  0   0 ] [dλb]    [cb]
/// ```
///
/// by block elimination ([`lane_algebra::solve_kkt8`] on one lane); `None` when a block is
/// singular or the step is not finite.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn solve_kkt8<const FMA: bool>(
    wa: &Sym3,
    wb: &Sym3,
    ga: &Vector3,
    gb: &Vector3,
    ra: &Vector3,
    rb: &Vector3,
    ca: Real,
    cb: Real,
) -> Option<(Vector3, Vector3, [Real; 2])> {
    let (l, v) = (lane_sym::<FMA>, lane_vector::<FMA>);
    let (dx, dy, dl, ok) = lane_algebra::solve_kkt8(&l(wa), &l(wb), v(ga), v(gb), v(ra), v(rb), Scalar(ca), Scalar(cb));
    ok.then(|| (from_lane_vector(dx), from_lane_vector(dy), [dl[0].0, dl[1].0]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{SMatrix, SVector};
    use rand::{Rng, SeedableRng};

    fn random_spd(rng: &mut rand_chacha::ChaCha8Rng) -> Matrix3 {
        let b = Matrix3::from_fn(|_, _| rng.random_range(-1.0..1.0));
        b * b.transpose() + Matrix3::identity() * 0.1
    }

    #[test]
    fn posed_eval_matches_reference_with_and_without_hessian() {
        let body = sublevel_core::body::ellipsoid([0.1, -0.2, 0.0], [0.9, 0.3, 0.5]).unwrap();
        let pose = sublevel_core::math::pose_from_parts("p", [0.9, 0.1, 0.3, 0.3], [1.0, -2.0, 0.5]).unwrap();
        let pb = PosedBody::new(&body, &pose);
        let f = FastPosed::new(&pb);
        let fused = FastPosed::<true>::build(&pb);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for _ in 0..20 {
            let x = Vector3::new(rng.random_range(0.0..2.0), rng.random_range(-3.0..-1.0), rng.random_range(0.0..1.0));
            let r = pb.eval(&x);
            let (full, vg) = (f.eval(&x, true), f.eval(&x, false));
            let scale = 1.0 + r.value.abs() + r.gradient.amax() + r.hessian.amax();
            for e in [&full, &vg] {
                assert!((e.value - r.value).abs() <= 1e-12 * scale);
                assert!((e.gradient - r.gradient).amax() <= 1e-12 * scale);
            }
            assert!((f.hessian(&full).unwrap().to_matrix() - r.hessian).amax() <= 1e-12 * scale);
            assert!(f.hessian(&vg).is_none());
            assert!((f.value(&x) - r.value).abs() <= 1e-12 * scale);
            // The fused-arithmetic evaluator of the AVX2 + FMA solver builds.
            let e = fused.eval(&x, true);
            assert!((e.value - r.value).abs() <= 1e-12 * scale && (e.gradient - r.gradient).amax() <= 1e-12 * scale);
            assert!((fused.hessian(&e).unwrap().to_matrix() - r.hessian).amax() <= 1e-12 * scale);
        }
    }

    #[test]
    fn block_solves_match_dense_lu() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let v = |rng: &mut rand_chacha::ChaCha8Rng| {
            Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
        };
        for _ in 0..50 {
            // Growth 4 × 4.
            let (w, g, r, c) = (random_spd(&mut rng), v(&mut rng), v(&mut rng), rng.random_range(-1.0..1.0));
            let mut k = nalgebra::Matrix4::<Real>::zeros();
            k.fixed_view_mut::<3, 3>(0, 0).copy_from(&w);
            k.fixed_view_mut::<3, 1>(0, 3).copy_from(&g);
            k.fixed_view_mut::<1, 3>(3, 0).copy_from(&g.transpose());
            let dense = k.lu().solve(&-nalgebra::Vector4::new(r.x, r.y, r.z, c)).unwrap();
            // Both arithmetic builds (fused: the solvers' AVX2 + FMA copies).
            let ws = Sym3::from_upper(&w);
            for (dx, dmu) in [solve_kkt4::<false>(&ws, &g, &r, c).unwrap(), solve_kkt4::<true>(&ws, &g, &r, c).unwrap()]
            {
                assert!((dx - dense.fixed_rows::<3>(0)).amax() < 1e-9 * (1.0 + dense.amax()));
                assert!((dmu - dense[3]).abs() < 1e-9 * (1.0 + dense.amax()));
            }
            // Distance 8 × 8.
            let two = Matrix3::identity() * 2.0;
            let (wa, wb) = (two + random_spd(&mut rng), two + random_spd(&mut rng));
            let (ga, gb, ra, rb) = (v(&mut rng), v(&mut rng), v(&mut rng), v(&mut rng));
            let (ca, cb) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let mut j = SMatrix::<Real, 8, 8>::zeros();
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&wa);
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-two));
            j.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-two));
            j.fixed_view_mut::<3, 3>(3, 3).copy_from(&wb);
            j.fixed_view_mut::<3, 1>(0, 6).copy_from(&ga);
            j.fixed_view_mut::<3, 1>(3, 7).copy_from(&gb);
            j.fixed_view_mut::<1, 3>(6, 0).copy_from(&ga.transpose());
            j.fixed_view_mut::<1, 3>(7, 3).copy_from(&gb.transpose());
            let rhs = -SVector::<Real, 8>::from_column_slice(&[ra.x, ra.y, ra.z, rb.x, rb.y, rb.z, ca, cb]);
            let dense = j.lu().solve(&rhs).unwrap();
            let tol = 1e-9 * (1.0 + dense.amax());
            let (wa, wb) = (Sym3::from_upper(&wa), Sym3::from_upper(&wb));
            for (dx, dy, dl) in [
                solve_kkt8::<false>(&wa, &wb, &ga, &gb, &ra, &rb, ca, cb).unwrap(),
                solve_kkt8::<true>(&wa, &wb, &ga, &gb, &ra, &rb, ca, cb).unwrap(),
            ] {
                assert!((dx - dense.fixed_rows::<3>(0)).amax() < tol);
                assert!((dy - dense.fixed_rows::<3>(3)).amax() < tol);
                assert!((dl[0] - dense[6]).abs() < tol && (dl[1] - dense[7]).abs() < tol);
            }
        }
        assert!(inverse_sym3::<false>(&Sym3::default()).is_none());
        assert!(inverse_sym3::<true>(&Sym3([1.0, 0.0, 0.0, Real::NAN, 0.0, 1.0])).is_none());
        for _ in 0..20 {
            let m = random_spd(&mut rng);
            let s = Sym3::from_upper(&m);
            for inv in [inverse_sym3::<false>(&s).unwrap(), inverse_sym3::<true>(&s).unwrap()] {
                let inv = inv.to_matrix();
                assert!((inv * m - Matrix3::identity()).amax() < 1e-10 * (1.0 + inv.amax() * m.amax()));
            }
            // The symmetric helpers against nalgebra's products.
            let (v, k) = (v(&mut rng), rng.random_range(-2.0..2.0));
            for mv in [sym_mat_vec::<false>(&s, &v), sym_mat_vec::<true>(&s, &v)] {
                assert!((mv - m * v).amax() < 1e-12 * (1.0 + m.amax() * v.amax()));
            }
            let two = Matrix3::identity() * 2.0;
            assert!((shifted::<true>(&s, k, 2.0).to_matrix() - (two + m * k)).amax() < 1e-12 * (1.0 + m.amax()));
            assert!((sym_add_scaled::<true>(&s, k, &s).to_matrix() - m * (1.0 + k)).amax() < 1e-12 * (1.0 + m.amax()));
        }
    }
}
