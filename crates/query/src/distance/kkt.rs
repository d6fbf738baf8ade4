//! The separated KKT system of the distance at one iterate (paper §IV-A, eq. "distance"):
//!
//! ```text
//! r_a = 2(x − y) + λ_a ∇p_a'(x),   r_b = −2(x − y) + λ_b ∇p_b'(y),   c_a = p_a'(x) − 1,   c_b = p_b'(y) − 1
//! ```
//!
//! its residuals and line-search merit, least-squares multipliers for a cold start, and the
//! Newton step of the 8 × 8 system (closed-form block elimination, dense LU when singular).

use crate::fast_eval::{abs_max, max_plain, shifted, solve_kkt8, FastPosed, PosedEval};
use crate::newton::SolveStatus;
use nalgebra::{SMatrix, SVector};
use sublevel_core::math::{Matrix3, Real, Sym3, Vector3};

/// Least-squares multipliers of `2(x − y) + λ_a ∇p_a' = 0`, `−2(x − y) + λ_b ∇p_b' = 0` for the
/// gradients `ga` at x and `gb` at y, clamped positive.
#[inline(always)]
pub(super) fn initial_multipliers(ga: &Vector3, gb: &Vector3, x: &Vector3, y: &Vector3) -> [Real; 2] {
    let d = y - x;
    let la = 2.0 * d.dot(ga) / ga.norm_squared().max(Real::MIN_POSITIVE);
    let lb = -2.0 * d.dot(gb) / gb.norm_squared().max(Real::MIN_POSITIVE);
    let fix = |l: Real, g: &Vector3| if l.is_finite() && l > 0.0 { l } else { 2.0 * d.norm() / g.norm().max(1e-300) };
    [fix(la, ga), fix(lb, gb)]
}

/// The end of a separated Newton run: the last point (frame of body A), its multipliers, how the
/// run ended, its Newton steps and the final ∞-norm of the KKT residual.
pub(crate) struct KktOut {
    pub(crate) x: Vector3,
    pub(crate) y: Vector3,
    pub(crate) lam: [Real; 2],
    pub(crate) status: SolveStatus,
    pub(crate) iterations: usize,
    pub(crate) residual: Real,
}

impl KktOut {
    /// The run's points moved by `o` (meters): from a query's working frame back to A's frame
    /// ([`working_frame`](crate::newton::working_frame)).
    #[inline(always)]
    pub(crate) fn moved(mut self, o: &Vector3) -> Self {
        self.x += o;
        self.y += o;
        self
    }
}

type Vec8 = SVector<Real, 8>;
type Mat8 = SMatrix<Real, 8, 8>;

/// Value, gradient and residual of the KKT system at one iterate, with the Hessians when they were
/// evaluated (one pass per body either way).
pub(super) struct KktPoint {
    pub(super) ea: PosedEval,
    pub(super) eb: PosedEval,
    ra: Vector3,
    rb: Vector3,
    ca: Real,
    cb: Real,
}

impl KktPoint {
    #[inline(always)]
    pub(super) fn new<const FMA: bool>(
        fa: &FastPosed<'_, FMA>,
        fb: &FastPosed<'_, FMA>,
        x: &Vector3,
        y: &Vector3,
        lam: [Real; 2],
        hessian: bool,
    ) -> Self {
        let ea = fa.eval(x, hessian);
        let eb = fb.eval(y, hessian);
        let (ca, cb) = (ea.value - 1.0, eb.value - 1.0);
        let mut pt = Self { ea, eb, ra: Vector3::zeros(), rb: Vector3::zeros(), ca, cb };
        pt.set_multipliers(x, y, lam);
        pt
    }

    /// Recomputes the stationarity residuals for the multipliers `lam` (no new evaluation).
    #[inline(always)]
    pub(super) fn set_multipliers(&mut self, x: &Vector3, y: &Vector3, lam: [Real; 2]) {
        let d = (x - y) * 2.0;
        self.ra = d + self.ea.gradient * lam[0];
        self.rb = -d + self.eb.gradient * lam[1];
    }

    #[inline(always)]
    pub(super) fn norm_inf(&self) -> Real {
        max_plain(max_plain(abs_max(&self.ra), abs_max(&self.rb)), max_plain(self.ca.abs(), self.cb.abs()))
    }

    /// The line search's merit ‖(r_a/L, r_b/L, p_a' − 1, p_b' − 1)‖₂ for `w2` = 1/L²
    /// ([`merit_length`](crate::newton::merit_length)): stationarity in units of L, so that it
    /// weighs the same against the (dimensionless) constraints whatever the bodies' size. NaN or
    /// infinite with any residual.
    #[inline(always)]
    pub(super) fn merit(&self, w2: Real) -> Real {
        ((self.ra.norm_squared() + self.rb.norm_squared()) * w2 + self.ca * self.ca + self.cb * self.cb).sqrt()
    }
}

/// The Newton step for the Hessians `(ha, hb)` at `pt`: closed-form block elimination, dense LU if
/// that is singular.
#[inline(always)]
pub(super) fn newton_step<const FMA: bool>(
    h: &(Sym3, Sym3),
    pt: &KktPoint,
    lam: [Real; 2],
) -> Option<(Vector3, Vector3, [Real; 2])> {
    let wa = shifted::<FMA>(&h.0, lam[0], 2.0);
    let wb = shifted::<FMA>(&h.1, lam[1], 2.0);
    let (ga, gb) = (&pt.ea.gradient, &pt.eb.gradient);
    if let Some(step) = solve_kkt8::<FMA>(&wa, &wb, ga, gb, &pt.ra, &pt.rb, pt.ca, pt.cb) {
        return Some(step);
    }
    newton_step_lu(&wa, &wb, pt)
}

/// [`newton_step`] by dense LU when the block elimination meets a singular block.
#[cold]
#[inline(never)]
fn newton_step_lu(wa: &Sym3, wb: &Sym3, pt: &KktPoint) -> Option<(Vector3, Vector3, [Real; 2])> {
    let two = Matrix3::identity() * 2.0;
    let (wa, wb) = (&wa.to_matrix(), &wb.to_matrix());
    let (ga, gb) = (&pt.ea.gradient, &pt.eb.gradient);
    let mut jac = Mat8::zeros();
    jac.fixed_view_mut::<3, 3>(0, 0).copy_from(wa);
    jac.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-two));
    jac.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-two));
    jac.fixed_view_mut::<3, 3>(3, 3).copy_from(wb);
    jac.fixed_view_mut::<3, 1>(0, 6).copy_from(ga);
    jac.fixed_view_mut::<3, 1>(3, 7).copy_from(gb);
    jac.fixed_view_mut::<1, 3>(6, 0).copy_from(&ga.transpose());
    jac.fixed_view_mut::<1, 3>(7, 3).copy_from(&gb.transpose());
    let r = Vec8::from_column_slice(&[pt.ra.x, pt.ra.y, pt.ra.z, pt.rb.x, pt.rb.y, pt.rb.z, pt.ca, pt.cb]);
    let step = jac.lu().solve(&(-r))?;
    Some((Vector3::new(step[0], step[1], step[2]), Vector3::new(step[3], step[4], step[5]), [step[6], step[7]]))
}
