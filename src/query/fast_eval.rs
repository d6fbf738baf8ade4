//! Hot-path evaluation of a posed body for the Newton solvers: p'(x) = p(A x + b) through the
//! body's precomputed derivative tables ([`crate::poly::FastPoly`]), with the Hessian computed
//! only when a Newton step needs it (`∇ₓ = Aᵀ∇ᵤ`, `∇²ₓ = Aᵀ∇²ᵤA`, A = Rᵀ/scale).
//!
//! Also the closed-form small linear algebra of the KKT systems (3 × 3 inverses by cofactors,
//! block elimination of the 4 × 4 growth and 8 × 8 distance systems).

use crate::body::PosedBody;
use crate::math::{Matrix3, Real, Vector3};
use crate::poly::FastPoly;

/// A posed body's world → normalized map and its fast evaluator.
#[derive(Clone, Copy)]
pub(crate) struct FastPosed<'a> {
    poly: &'a FastPoly,
    a: Matrix3,
    at: Matrix3,
    b: Vector3,
    /// 1/scale when A = I/scale (the body posed without rotation, as the frame body of every
    /// query is): then ∇ₓ = ∇ᵤ/scale and ∇²ₓ = ∇²ᵤ/scale², with no matrix products.
    unrotated: Option<Real>,
}

/// Value, world gradient and (when evaluated) the normalized-frame Hessian at one point (one
/// evaluation pass); the world Hessian `Aᵀ∇²ᵤA` is formed only when a Newton step needs it
/// ([`FastPosed::hessian`]).
pub(crate) struct PosedEval {
    pub value: Real,
    pub gradient: Vector3,
    hessian_u: Option<Matrix3>,
}

impl<'a> FastPosed<'a> {
    /// The evaluator of a posed body.
    #[inline(always)]
    pub fn new(pb: &PosedBody<'a>) -> Self {
        let a = *pb.linear();
        let q = pb.pose.rotation.quaternion();
        let unrotated = (q.i == 0.0 && q.j == 0.0 && q.k == 0.0).then(|| 1.0 / pb.body.scale());
        Self {
            poly: pb.body.fast_polynomial(),
            a,
            at: a.transpose(),
            b: pb.to_normalized(&Vector3::zeros()),
            unrotated,
        }
    }

    /// u = A x + b.
    #[inline(always)]
    fn normalized(&self, x: &Vector3) -> Vector3 {
        match self.unrotated {
            Some(k) => x * k + self.b,
            None => self.a * x + self.b,
        }
    }

    /// ∇ₓ = Aᵀ∇ᵤ.
    #[inline(always)]
    fn world_gradient(&self, g: &Vector3) -> Vector3 {
        match self.unrotated {
            Some(k) => g * k,
            None => self.at * g,
        }
    }

    /// p'(x).
    #[inline(always)]
    pub fn value(&self, x: &Vector3) -> Real {
        self.poly.value(&self.normalized(x))
    }

    /// p'(x) and ∇p'(x).
    #[inline(always)]
    pub fn value_gradient(&self, x: &Vector3) -> (Real, Vector3) {
        let (v, g) = self.poly.value_gradient(&self.normalized(x));
        (v, self.world_gradient(&g))
    }

    /// p'(x), ∇p'(x) and, when `hessian` is set, (deferred) ∇²p'(x), in one pass.
    #[inline(always)]
    pub fn eval(&self, x: &Vector3, hessian: bool) -> PosedEval {
        let u = self.normalized(x);
        if hessian {
            let e = self.poly.eval(&u);
            PosedEval { value: e.value, gradient: self.world_gradient(&e.gradient), hessian_u: Some(e.hessian) }
        } else {
            let (value, g) = self.poly.value_gradient(&u);
            PosedEval { value, gradient: self.world_gradient(&g), hessian_u: None }
        }
    }

    /// ∇²p'(x) from an evaluation of [`Self::eval`] at x that included the Hessian.
    #[inline(always)]
    pub fn hessian(&self, e: &PosedEval) -> Option<Matrix3> {
        let h = e.hessian_u?;
        Some(match self.unrotated {
            Some(k) => h * (k * k),
            None => congruence_sym(&self.a, &h),
        })
    }
}

/// Aᵀ H A for a symmetric H, computing the six entries of the upper triangle (45 products
/// instead of the 54 of two general 3 × 3 products).
#[inline(always)]
fn congruence_sym(a: &Matrix3, h: &Matrix3) -> Matrix3 {
    let t = h * a;
    let e = |i: usize, j: usize| a[(0, i)] * t[(0, j)] + a[(1, i)] * t[(1, j)] + a[(2, i)] * t[(2, j)];
    let (m00, m01, m02, m11, m12, m22) = (e(0, 0), e(0, 1), e(0, 2), e(1, 1), e(1, 2), e(2, 2));
    Matrix3::new(m00, m01, m02, m01, m11, m12, m02, m12, m22)
}

/// max |vᵢ| (plain comparisons; nalgebra's `amax` goes through generic SIMD traits on the hot path).
#[inline(always)]
pub(crate) fn abs_max(v: &Vector3) -> Real {
    v.x.abs().max(v.y.abs()).max(v.z.abs())
}

/// KKT residual (2-norm, relative to the solver's stationarity scale) below which the next trial
/// point is evaluated without Hessians: it is expected to be converged, and if not, the next step
/// reuses the last Hessians (a chord step), refreshed when that step does not halve the residual.
pub(crate) const CHORD_RESIDUAL: Real = 1e-3;

/// Inverse of a symmetric 3 × 3 matrix by cofactors, reading the upper triangle only (six
/// cofactors instead of nine); `None` when (nearly) singular relative to its entries
/// (|det| ≤ 10⁻¹⁴ max|mᵢⱼ|³, or non-finite). The KKT blocks `2I + λ∇²p'` and their Schur
/// complements are symmetric; rounding asymmetry of the world Hessians below is ignored.
#[inline(always)]
pub(crate) fn inverse_sym3(m: &Matrix3) -> Option<Matrix3> {
    let (a, b, c) = (m[(0, 0)], m[(0, 1)], m[(0, 2)]);
    let (d, e, f) = (m[(1, 1)], m[(1, 2)], m[(2, 2)]);
    let c00 = d * f - e * e;
    let c01 = c * e - b * f;
    let c02 = b * e - c * d;
    let det = a * c00 + b * c01 + c * c02;
    let s = a.abs().max(b.abs()).max(c.abs()).max(d.abs()).max(e.abs()).max(f.abs());
    if !(det.is_finite() && det.abs() > 1e-14 * s * s * s && s > 0.0) {
        return None;
    }
    let k = 1.0 / det;
    let (i00, i01, i02) = (c00 * k, c01 * k, c02 * k);
    let (i11, i12, i22) = ((a * f - c * c) * k, (b * c - a * e) * k, (a * d - b * b) * k);
    Some(Matrix3::new(i00, i01, i02, i01, i11, i12, i02, i12, i22))
}

/// Solves the growth KKT system `[W g; gᵀ 0] [dx; dμ] = −[r; c]` by eliminating dx
/// (dμ = (c − gᵀW⁻¹r)/(gᵀW⁻¹g)); `None` when W or the Schur complement is singular.
#[inline(always)]
pub(crate) fn solve_kkt4(w: &Matrix3, g: &Vector3, r: &Vector3, c: Real) -> Option<(Vector3, Real)> {
    let wi = inverse_sym3(w)?;
    let wg = wi * g;
    let wr = wi * r;
    let s = g.dot(&wg);
    if !(s.is_finite() && s.abs() > 1e-300) {
        return None;
    }
    let dmu = (c - g.dot(&wr)) / s;
    let dx = -(wr + wg * dmu);
    (dx.iter().all(|v| v.is_finite()) && dmu.is_finite()).then_some((dx, dmu))
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
/// by block elimination: the 6 × 6 block M = [[Wa, −2I], [−2I, Wb]] through Wa⁻¹ and the Schur
/// complement Wb − 4Wa⁻¹, then the 2 × 2 Schur complement GᵀM⁻¹G of the constraints.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn solve_kkt8(
    wa: &Matrix3,
    wb: &Matrix3,
    ga: &Vector3,
    gb: &Vector3,
    ra: &Vector3,
    rb: &Vector3,
    ca: Real,
    cb: Real,
) -> Option<(Vector3, Vector3, [Real; 2])> {
    let ai = inverse_sym3(wa)?;
    let si = inverse_sym3(&(wb - ai * 4.0))?;
    // M⁻¹ [f; g] = [p; q] with q = Si (g + 2 Ai f), p = Ai f + 2 Ai q; the two constraint columns
    // have a zero half each, so eight 3 × 3 products in all.
    let t0 = ai * ra;
    let q0 = si * (rb + t0 * 2.0);
    let p0 = t0 + ai * q0 * 2.0;
    let t1 = ai * ga;
    let q1 = si * t1 * 2.0;
    let p1 = t1 + ai * q1 * 2.0;
    let q2 = si * gb;
    let p2 = ai * q2 * 2.0;
    let (s11, s12, s21, s22) = (ga.dot(&p1), ga.dot(&p2), gb.dot(&q1), gb.dot(&q2));
    let det = s11 * s22 - s12 * s21;
    let scale = (s11.abs() + s12.abs()) * (s21.abs() + s22.abs());
    if !(det.is_finite() && det.abs() > 1e-14 * scale && scale > 0.0) {
        return None;
    }
    let (h1, h2) = (ca - ga.dot(&p0), cb - gb.dot(&q0));
    let l1 = (s22 * h1 - s12 * h2) / det;
    let l2 = (s11 * h2 - s21 * h1) / det;
    let dx = -(p0 + p1 * l1 + p2 * l2);
    let dy = -(q0 + q1 * l1 + q2 * l2);
    // One sum carries any NaN or infinity of the eight components.
    let ok = (dx.sum() + dy.sum() + l1 + l2).is_finite();
    ok.then_some((dx, dy, [l1, l2]))
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
        let body = crate::body::ellipsoid([0.1, -0.2, 0.0], [0.9, 0.3, 0.5]).unwrap();
        let pose = crate::math::pose_from_parts("p", [0.9, 0.1, 0.3, 0.3], [1.0, -2.0, 0.5]).unwrap();
        let pb = PosedBody::new(&body, &pose);
        let f = FastPosed::new(&pb);
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
            assert!((f.hessian(&full).unwrap() - r.hessian).amax() <= 1e-12 * scale);
            assert!(f.hessian(&vg).is_none());
            assert!((f.value(&x) - r.value).abs() <= 1e-12 * scale);
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
            let (dx, dmu) = solve_kkt4(&w, &g, &r, c).unwrap();
            assert!((dx - dense.fixed_rows::<3>(0)).amax() < 1e-9 * (1.0 + dense.amax()));
            assert!((dmu - dense[3]).abs() < 1e-9 * (1.0 + dense.amax()));
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
            let (dx, dy, dl) = solve_kkt8(&wa, &wb, &ga, &gb, &ra, &rb, ca, cb).unwrap();
            let tol = 1e-9 * (1.0 + dense.amax());
            assert!((dx - dense.fixed_rows::<3>(0)).amax() < tol);
            assert!((dy - dense.fixed_rows::<3>(3)).amax() < tol);
            assert!((dl[0] - dense[6]).abs() < tol && (dl[1] - dense[7]).abs() < tol);
        }
        assert!(inverse_sym3(&Matrix3::zeros()).is_none());
        for _ in 0..20 {
            let m = random_spd(&mut rng);
            let inv = inverse_sym3(&m).unwrap();
            assert!((inv * m - Matrix3::identity()).amax() < 1e-10 * (1.0 + inv.amax() * m.amax()));
        }
    }
}
