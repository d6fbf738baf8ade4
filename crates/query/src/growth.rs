//! The growth measure d(p₁‖p₂) (paper §IV-B, eq. "overlap"):
//!
//! ```text
//! d(p₁‖p₂) = min p₁'(x)  s.t.  p₂'(x) ≤ 1        (> 1 separated, = 1 touching, < 1 overlapping)
//! ```
//!
//! The problem is solved in body 2's frame (p₂ with the identity pose, p₁ under the relative pose
//! pose₂⁻¹·pose₁), so large world coordinates never enter the arithmetic. Three cases:
//!
//! 1. the unconstrained minimizer of p₁ (precomputed per body) satisfies p₂' ≤ 1: the constraint is
//!    inactive and d = min p₁ (multiplier 0);
//! 2. otherwise the constraint is active, and Newton's method solves the KKT system
//!    `∇p₁' + μ∇p₂' = 0, p₂' = 1` (4 × 4, exact Hessians), from the previous answers extrapolated
//!    along the motion (warm start, [`MotionTrail`]; capped at [`NewtonParams::warm_iterations`],
//!    and case 1 is checked first when the predicted μ falls fast,
//!    [`NewtonParams::falling_multiplier`]) or from the boundary point of body 2 towards
//!    p₁'s minimizer read off body 2's radial table (cold start, [`sublevel_core::poly::RadialTable`]);
//! 3. if that fails, a log-barrier path `min p₁' − t·log(1 − p₂')` from body 2's interior point, then
//!    the KKT polish.

use super::fast_eval::{abs_max, max_plain, solve_kkt4, sym_add_scaled, FastPosed, PosedEval};
use super::newton::{
    barrier_path, merit_length, pose_step, step_accepted, within_warm_reach, MotionTrail, NewtonParams, SolveStatus,
};
use sublevel_core::body::{Body, PosedBody};
use sublevel_core::math::{Isometry3, Matrix3, Point3, Real, Sym3, Vector3};

/// Answer of a growth query: d(p₁‖p₂) = min p₁'(x) s.t. p₂'(x) ≤ 1 (paper eq. "overlap").
#[derive(Clone, Debug)]
pub struct GrowthResult {
    /// d(p₁‖p₂) (dimensionless): > 1 separated, = 1 touching, < 1 overlapping.
    pub value: Real,
    /// The minimizer x* in world coordinates (meters); it lies in body 2.
    pub minimizer: Point3,
    /// Multiplier μ ≥ 0 of p₂'(x) ≤ 1 (0 when the constraint is inactive).
    pub multiplier: Real,
    /// How the solve ended; only [`SolveStatus::Converged`] answers are certified optimal.
    pub status: SolveStatus,
    /// Newton iterations over all phases.
    pub iterations: usize,
    /// Final ∞-norm of the KKT residual.
    pub kkt_residual: Real,
    /// Whether the solve started from a warm start and converged from it.
    pub warm_started: bool,
    /// State for warm-starting the next query of the same pair.
    pub warm_start: std::sync::Arc<GrowthWarmStart>,
}

/// Growth solver state carried between queries of one pair, in body 2's own frame so that it
/// follows the pose.
///
/// The default holds no answer (`valid` false): a query started from it runs cold.
#[derive(Clone, Copy, Debug, Default)]
pub struct GrowthWarmStart {
    /// Minimizer in body 2's frame (meters).
    pub local: Vector3,
    /// Multiplier μ.
    pub multiplier: Real,
    /// Whether this holds a usable state.
    pub valid: bool,
    /// Relative pose pose₂⁻¹·pose₁ at which `local` was solved.
    pub relative_pose: Isometry3,
    /// Earlier answers of the same pair along the motion (kept while answers are warm-started):
    /// with them the next query extrapolates along the motion ([`MotionTrail`]) instead of
    /// restarting from `local`. State layout: `[local.x, local.y, local.z, multiplier]`.
    pub trail: MotionTrail<4>,
}

/// A warm start with the relative-pose step ([`pose_step`]) from its answer to the current query.
#[derive(Clone, Copy)]
pub(crate) struct GrowthStart<'a> {
    pub warm: &'a GrowthWarmStart,
    pub step: [Real; 6],
}

impl GrowthWarmStart {
    /// This warm start for a query at relative pose `rel`; `length` weighs rotations (meters).
    #[inline(always)]
    pub(crate) fn towards(&self, rel: &Isometry3, length: Real) -> GrowthStart<'_> {
        GrowthStart { warm: self, step: pose_step(&self.relative_pose, rel, length) }
    }

    /// The state after an answer (`local`, `multiplier`, converged or not) at relative pose `rel`,
    /// extending the trail of the warm start it started from (if that held an active-constraint
    /// answer) for the predictor.
    pub(crate) fn after(
        start: Option<GrowthStart<'_>>,
        local: Vector3,
        multiplier: Real,
        valid: bool,
        rel: Isometry3,
    ) -> Self {
        let trail = match start.filter(|s| s.warm.valid && s.warm.multiplier > 0.0 && valid && multiplier > 0.0) {
            Some(s) => MotionTrail::extend(&s.warm.state(), &s.warm.trail, s.step),
            None => MotionTrail::default(),
        };
        Self { local, multiplier, valid, relative_pose: rel, trail }
    }

    fn state(&self) -> [Real; 4] {
        [self.local.x, self.local.y, self.local.z, self.multiplier]
    }

    /// Start (minimizer in body 2's frame, multiplier) after the relative-pose step `step`:
    /// extrapolated along the motion from the earlier answers ([`MotionTrail::predict`]), else the
    /// last answer; the flag says the multiplier is falling fast (below
    /// [`NewtonParams::falling_multiplier`] times the last: the constraint may be turning
    /// inactive; a smooth motion changes μ far less per query).
    fn predict(&self, step: &[Real; 6], params: &NewtonParams) -> (Vector3, Real, bool) {
        if self.trail.is_empty() {
            return (self.local, self.multiplier, false);
        }
        let (s, floored) = self.trail.predict(&self.state(), step, 3, params.max_extrapolation);
        (Vector3::new(s[0], s[1], s[2]), s[3], floored || s[3] < params.falling_multiplier * self.multiplier)
    }
}

avx2_dispatch! {
    /// d(p₁‖p₂) for body `p1` posed by `pose1` and body `p2` posed by `pose2` (paper eq. "overlap").
    ///
    /// `warm` is the `warm_start` of a previous answer for the same ordered pair (any poses). The
    /// answer always says whether it converged; it never panics on valid bodies.
    pub fn growth => growth_body(
        p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3, warm: Option<&GrowthWarmStart>,
        params: &NewtonParams,
    ) -> GrowthResult
}

/// The body of [`growth()`], inlined into each of its builds (`FMA` only selects the build).
#[inline(always)]
fn growth_body<const FMA: bool>(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    warm: Option<&GrowthWarmStart>,
    params: &NewtonParams,
) -> GrowthResult {
    let rel = pose2.inverse() * pose1;
    // Body 2's frame moved to the smaller body's interior point (core.x comes back in body 2's
    // frame through b2's pose).
    let (_, b2, b1) = super::newton::working_frame(p2, p1, &rel, params);
    // A warm start past `warm_reach` of the bodies' size costs more than a cold start: none then.
    let reach = p1.scale() + p2.scale();
    let start = warm.map(|w| w.towards(&rel, p1.scale())).filter(|s| within_warm_reach(&s.step, reach, params));
    let core = solve_growth(&b1, &b2, start, params);
    GrowthResult {
        value: core.value,
        minimizer: pose2 * Point3::from(core.x),
        multiplier: core.mu,
        status: core.status,
        iterations: core.iterations,
        kkt_residual: core.residual,
        warm_started: core.warm_started,
        warm_start: std::sync::Arc::new(GrowthWarmStart::after(start, core.x, core.mu, core.status.converged(), rel)),
    }
}

/// Growth answer in the common frame of the two posed bodies.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GrowthCore {
    pub value: Real,
    pub x: Vector3,
    pub mu: Real,
    pub status: SolveStatus,
    pub iterations: usize,
    pub residual: Real,
    pub warm_started: bool,
}

avx2_dispatch! {
    /// Solves d(p₁‖p₂) with both bodies posed in one common frame, from the warm start `start` (its
    /// `local` is in body 2's frame) when given.
    pub(crate) fn solve_growth => solve_growth_body(
        b1: &PosedBody<'_>, b2: &PosedBody<'_>, start: Option<GrowthStart<'_>>, params: &NewtonParams,
    ) -> GrowthCore
}

/// The body of [`solve_growth`], inlined into each of its builds. `FMA` only selects the build
/// (the AVX2 one compiles the starts and tests with VEX encoding and inlines their look-ups); the
/// arithmetic is the same in both, so are the answers, bit for bit.
#[inline(always)]
fn solve_growth_body<const FMA: bool>(
    b1: &PosedBody<'_>,
    b2: &PosedBody<'_>,
    start: Option<GrowthStart<'_>>,
    params: &NewtonParams,
) -> GrowthCore {
    // Case 1: the unconstrained minimizer of p₁ lies in body 2.
    let c1 = b1.interior_point();
    let inactive = |iterations: usize| {
        (FastPosed::new(b2).value(&c1) <= 1.0).then(|| {
            let (_, g1) = FastPosed::new(b1).value_gradient(&c1);
            GrowthCore {
                value: b1.body.min_value(),
                x: b2.pose.inverse_transform_vector(&(c1 - b2.pose.translation.vector)),
                mu: 0.0,
                status: SolveStatus::Converged,
                iterations,
                residual: abs_max(&g1),
                warm_started: false,
            }
        })
    };
    // For convex bodies the warm start goes first: a converged KKT point with μ > 0 is then the
    // global minimizer (and cannot occur when p₁'s minimizer lies strictly inside body 2). A
    // nonconvex body (relaxed convexity) checks case 1 first, as its KKT points may be local.
    let convex = !b1.body.report.nonconvex && !b2.body.report.nonconvex;
    if !convex {
        if let Some(core) = inactive(0) {
            return core;
        }
    }
    let mut iterations = 0;
    if let Some(s) = start.filter(|s| s.warm.valid && s.warm.multiplier > 0.0) {
        let (local, mu, falling) = s.warm.predict(&s.step, params);
        // A multiplier falling fast may reach 0: check the inactive case first then.
        if convex && falling {
            if let Some(core) = inactive(0) {
                return core;
            }
        }
        let x0 = b2.pose * Point3::from(local);
        let out = kkt_newton(b1, b2, x0.coords, Some(mu), params, params.warm_iterations, true);
        iterations += out.iterations;
        if out.status.converged() {
            return GrowthCore { iterations, warm_started: true, ..out.with_frame(b2) };
        }
    }
    if convex {
        if let Some(core) = inactive(iterations) {
            return core;
        }
    }
    // Case 2: active constraint, Newton on the KKT system from the cold start.
    let c2 = b2.interior_point();
    // At the minimizer ∇p₁' = −μ∇p₂': x is body 2's support point in the direction −∇p₁'(x), so
    // one look-up from the radial start (body 2's boundary towards c₁) starts closer to it.
    // The interpolated support point lies inside body 2 (feasible): it replaces the radial start
    // only when p₁' is lower there (the radial start is exact for spheres).
    let x0 = b2.boundary_towards(&c1);
    let f1 = FastPosed::new(b1);
    let (v0, g1) = f1.value_gradient(&x0);
    let x0 = b2.support(&-g1).filter(|x| f1.value(x) < v0).unwrap_or(x0);
    let out = kkt_newton(b1, b2, x0, None, params, params.max_iterations, false);
    iterations += out.iterations;
    if out.status.converged() {
        return GrowthCore { iterations, ..out.with_frame(b2) };
    }
    // Case 3: barrier path from body 2's interior, then the polish.
    let (xb, mub, it_b) = barrier(b1, b2, &c2, params);
    iterations += it_b;
    let out = kkt_newton(b1, b2, xb, Some(mub), params, params.max_iterations, false);
    iterations += out.iterations;
    GrowthCore { iterations, ..out.with_frame(b2) }
}

/// Least-squares multiplier of ∇f + μ∇g = 0 for the gradients `gf`, `gg` at one point, clamped
/// positive.
#[inline(always)]
fn initial_multiplier(gf: &Vector3, gg: &Vector3) -> Real {
    let mu = -gf.dot(gg) / gg.norm_squared().max(Real::MIN_POSITIVE);
    if mu.is_finite() && mu > 0.0 {
        mu
    } else {
        gf.norm() / gg.norm().max(Real::MIN_POSITIVE)
    }
}

/// Result of one KKT Newton run (x in the common frame).
struct KktOut {
    x: Vector3,
    mu: Real,
    value: Real,
    status: SolveStatus,
    iterations: usize,
    residual: Real,
}

impl KktOut {
    /// The answer with its minimizer in body 2's frame (the warm start's coordinates).
    #[inline(always)]
    fn with_frame(self, b2: &PosedBody<'_>) -> GrowthCore {
        let local = b2.pose.inverse_transform_vector(&(self.x - b2.pose.translation.vector));
        GrowthCore {
            value: self.value,
            x: local,
            mu: self.mu,
            status: self.status,
            iterations: self.iterations,
            residual: self.residual,
            warm_started: false,
        }
    }
}

/// Values, gradients and Hessians of both bodies at x (the barrier path).
struct KktState {
    f: Real,
    gf: Vector3,
    hf: Matrix3,
    g: Real,
    gg: Vector3,
    hg: Matrix3,
}

/// The barrier path's state at x through the fast evaluators (one full pass per body, cheaper
/// than the generic [`PosedBody::eval`]).
fn kkt_state(f1: &FastPosed<'_>, f2: &FastPosed<'_>, x: &Vector3) -> Option<KktState> {
    let (e1, e2) = (f1.eval(x, true), f2.eval(x, true));
    let (hf, hg) = (f1.hessian(&e1)?.to_matrix(), f2.hessian(&e2)?.to_matrix());
    Some(KktState { f: e1.value, gf: e1.gradient, hf, g: e2.value - 1.0, gg: e2.gradient, hg })
}

/// Value, gradient and residual `[∇f + μ∇g; g]` at one iterate, with the Hessians when they were
/// evaluated (one pass per body either way).
struct KktPoint {
    e1: PosedEval,
    e2: PosedEval,
    r: Vector3,
    c: Real,
}

impl KktPoint {
    #[inline(always)]
    fn new<const FMA: bool>(
        f1: &FastPosed<'_, FMA>,
        f2: &FastPosed<'_, FMA>,
        x: &Vector3,
        mu: Real,
        hessian: bool,
    ) -> Self {
        let e1 = f1.eval(x, hessian);
        let e2 = f2.eval(x, hessian);
        let r = e1.gradient + e2.gradient * mu;
        let c = e2.value - 1.0;
        Self { e1, e2, r, c }
    }

    #[inline(always)]
    fn norm_inf(&self) -> Real {
        max_plain(abs_max(&self.r), self.c.abs())
    }

    /// The line search's merit ‖(L·r, p₂' − 1)‖₂ for `l2` = L² ([`merit_length`]): stationarity
    /// (1/m) times L, so that it weighs the same against the (dimensionless) constraint whatever
    /// the bodies' size. NaN or infinite with any residual.
    #[inline(always)]
    fn merit(&self, l2: Real) -> Real {
        (self.r.norm_squared() * l2 + self.c * self.c).sqrt()
    }
}

/// The Newton step for the Hessians `(h1, h2)` at `pt`: closed-form elimination, dense LU if that is
/// singular.
#[inline(always)]
fn newton_step<const FMA: bool>(h: &(Sym3, Sym3), pt: &KktPoint, mu: Real) -> Option<(Vector3, Real)> {
    let w = sym_add_scaled::<FMA>(&h.0, mu, &h.1);
    if let Some(step) = solve_kkt4::<FMA>(&w, &pt.e2.gradient, &pt.r, pt.c) {
        return Some(step);
    }
    newton_step_lu(&w, pt)
}

/// [`newton_step`] by dense LU when the elimination meets a singular block.
#[cold]
#[inline(never)]
fn newton_step_lu(w: &Sym3, pt: &KktPoint) -> Option<(Vector3, Real)> {
    let gg = &pt.e2.gradient;
    let mut k = nalgebra::Matrix4::<Real>::zeros();
    k.fixed_view_mut::<3, 3>(0, 0).copy_from(&w.to_matrix());
    k.fixed_view_mut::<3, 1>(0, 3).copy_from(gg);
    k.fixed_view_mut::<1, 3>(3, 0).copy_from(&gg.transpose());
    let step = k.lu().solve(&-nalgebra::Vector4::new(pt.r.x, pt.r.y, pt.r.z, pt.c))?;
    Some((Vector3::new(step[0], step[1], step[2]), step[3]))
}

avx2_dispatch! {
    /// Active-set Newton on `∇f + μ∇g = 0, g = 0` from x0 and the multiplier `mu0` (least squares at
    /// the start when `None`), at most `cap` Newton steps (and [`NewtonParams::max_iterations`]),
    /// globalized by backtracking on the merit ‖(L·r, p₂' − 1)‖₂
    /// ([`merit_length`]); a `warm` run gives up (Stalled)
    /// when μ turns nonpositive. Every point is evaluated once; near the solution (residual below
    /// [`NewtonParams::chord_residual`]) trial points skip the Hessians and a further step reuses
    /// the last ones (chord step), refreshed when it stalls.
    fn kkt_newton => kkt_newton_body(
        b1: &PosedBody<'_>, b2: &PosedBody<'_>, x0: Vector3, mu0: Option<Real>, params: &NewtonParams,
        cap: usize, warm: bool,
    ) -> KktOut
}

/// The body of [`kkt_newton`], inlined into each of its builds.
#[inline(always)]
fn kkt_newton_body<const FMA: bool>(
    b1: &PosedBody<'_>,
    b2: &PosedBody<'_>,
    x0: Vector3,
    mu0: Option<Real>,
    params: &NewtonParams,
    cap: usize,
    warm: bool,
) -> KktOut {
    // The cap passed apart from the settings: a capped copy of them (a few hundred bytes) would
    // be written on every warm query.
    let cap = cap.min(params.max_iterations);
    let (f1, f2) = (FastPosed::<FMA>::build(b1), FastPosed::<FMA>::build(b2));
    let mut x = x0;
    let mut pt = KktPoint::new(&f1, &f2, &x, mu0.unwrap_or_default(), true);
    // Without a start for the multiplier: least squares from the first point's gradients.
    let mut mu = mu0.unwrap_or_else(|| initial_multiplier(&pt.e1.gradient, &pt.e2.gradient));
    if mu0.is_none() {
        pt.r = pt.e1.gradient + pt.e2.gradient * mu;
    }
    let mut hess: Option<(Sym3, Sym3)> = None;
    let mut status = SolveStatus::MaxIterations;
    let mut it = 0;
    // Scale stationarity by the objective's gradient so far-apart bodies (large p₁) are judged fairly.
    let scale = |pt: &KktPoint| 1.0 + abs_max(&pt.e1.gradient);
    let stationary = |pt: &KktPoint| pt.norm_inf() <= params.kkt_tolerance * scale(pt);
    // The line search's merit weighs stationarity (1/m) by L and its level by the same L
    // ([`merit_length`]), so the run does not depend on the bodies' size.
    let len = merit_length(b1.body, b2.body);
    let l2 = len * len;
    let merit_scale = |pt: &KktPoint| 1.0 + len * abs_max(&pt.e1.gradient);
    while it < cap {
        // The 2-norm carries any NaN or infinity of the residual (the ∞-norm's plain maxima do not).
        let r0 = pt.merit(l2);
        if !r0.is_finite() {
            status = SolveStatus::Stalled;
            break;
        }
        // A KKT point is the answer when μ > 0; otherwise it is not the minimizer and Newton does
        // not leave it: stop instead of iterating there up to the cap, and leave it to the
        // barrier path.
        if stationary(&pt) {
            status = if mu > 0.0 { SolveStatus::Converged } else { SolveStatus::Stalled };
            break;
        }
        // Fresh Hessians when this point has them, else the last ones (chord step).
        let fresh = match (f1.hessian(&pt.e1), f2.hessian(&pt.e2)) {
            (Some(h1), Some(h2)) => {
                hess = Some((h1, h2));
                true
            }
            _ => false,
        };
        let Some(h) = hess else {
            pt = KktPoint::new(&f1, &f2, &x, mu, true);
            continue;
        };
        it += 1;
        let Some((dx, dmu)) = newton_step::<FMA>(&h, &pt, mu) else {
            status = SolveStatus::Stalled;
            break;
        };
        let cheap = r0 <= params.chord_residual * merit_scale(&pt);
        // A cold run keeps μ ≥ μ/2 per step: the KKT points with μ < 0 (maxima and saddles of p₁
        // on body 2's boundary) attract Newton from some starts and are not the answer.
        let mut alpha = if !warm && mu > 0.0 && mu + dmu < 0.5 * mu { 0.5 * mu / -dmu } else { 1.0 };
        let mut accepted = false;
        for _ in 0..params.line_search_steps {
            let xt = x + dx * alpha;
            let mt = mu + dmu * alpha;
            let tr = KktPoint::new(&f1, &f2, &xt, mt, !cheap);
            if step_accepted(r0, tr.merit(l2), alpha, fresh) {
                (x, mu, pt) = (xt, mt, tr);
                accepted = true;
                break;
            }
            if !fresh {
                break;
            }
            alpha *= 0.5;
        }
        if !accepted {
            if !fresh {
                pt = KktPoint::new(&f1, &f2, &x, mu, true);
                continue;
            }
            status = SolveStatus::Stalled;
            break;
        }
        // A warm run whose multiplier turns nonpositive is following a constraint that is turning
        // inactive: leave it to the inactive check and the cold path.
        if warm && mu <= 0.0 {
            status = SolveStatus::Stalled;
            break;
        }
    }
    if status == SolveStatus::MaxIterations && mu > 0.0 && stationary(&pt) && pt.merit(l2).is_finite() {
        status = SolveStatus::Converged;
    }
    KktOut { x, mu, value: pt.e1.value, status, iterations: it, residual: pt.norm_inf() }
}

/// Log-barrier path `min f − t·log(−g)` from a strictly feasible point, t → 0 ([`barrier_path`]);
/// returns the final point, the multiplier estimate t/(−g), and the Newton iterations spent.
fn barrier(b1: &PosedBody<'_>, b2: &PosedBody<'_>, start: &Vector3, params: &NewtonParams) -> (Vector3, Real, usize) {
    let (f1, f2) = (FastPosed::new(b1), FastPosed::new(b2));
    let center = |x: &Vector3, t: Real| {
        let st = kkt_state(&f1, &f2, x)?;
        let s = -st.g;
        let grad = st.gf + st.gg * (t / s);
        let hess = st.hf + st.hg * (t / s) + st.gg * st.gg.transpose() * (t / (s * s));
        let chol = nalgebra::Cholesky::new(hess)?;
        let dx = -chol.solve(&grad);
        let dec = -grad.dot(&dx);
        Some((dx, dec, Some(st.f - t * s.ln())))
    };
    let phi = |x: &Vector3, t: Real| {
        let gt = f2.value(x) - 1.0;
        (gt < 0.0).then(|| f1.value(x) - t * (-gt).ln())
    };
    let done = |x: &Vector3, t: Real| t < 1e-10 * (1.0 + f1.value(x).abs());
    let (x, t, it) = barrier_path(*start, 1.0_f64.max(f1.value(start).abs()), params, center, phi, done);
    let s = (1.0 - f2.value(&x)).max(Real::MIN_POSITIVE);
    (x, t / s, it)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::body::ellipsoid;
    use sublevel_core::math::pose_from_parts;

    /// Spheres p = ‖x − c‖²/r²: d(p₁‖p₂) = (max(0, ‖c₁ − c₂‖ − r₂))² / r₁² (closed form).
    fn sphere_growth(c1: Vector3, r1: Real, c2: Vector3, r2: Real) -> Real {
        ((c1 - c2).norm() - r2).max(0.0).powi(2) / (r1 * r1)
    }

    #[test]
    fn spheres_match_closed_form_cold_and_warm() {
        let s1 = ellipsoid([0.0; 3], [0.5; 3]).unwrap();
        let s2 = ellipsoid([0.0; 3], [0.8; 3]).unwrap();
        let id = Isometry3::identity();
        let mut warm: Option<GrowthWarmStart> = None;
        let mut cold_iters = 0;
        let mut warm_iters = 0;
        for k in 0..40 {
            let c2 = Vector3::new(3.0 - 0.05 * k as Real, 0.2, -0.1);
            let pose2 = pose_from_parts("p", [1.0, 0.0, 0.0, 0.0], [c2.x, c2.y, c2.z]).unwrap();
            let r = growth(&s1, &id, &s2, &pose2, warm.as_ref(), &NewtonParams::default());
            let expected = sphere_growth(Vector3::zeros(), 0.5, c2, 0.8);
            assert!(r.status.converged(), "k = {k}: {r:?}");
            assert!((r.value - expected).abs() <= 1e-9 * expected.max(1.0), "k = {k}: {} vs {expected}", r.value);
            let cold = growth(&s1, &id, &s2, &pose2, None, &NewtonParams::default());
            assert!((cold.value - expected).abs() <= 1e-9 * expected.max(1.0));
            if k > 0 && expected > 0.0 {
                cold_iters += cold.iterations;
                warm_iters += r.iterations;
            }
            warm = Some(*r.warm_start);
        }
        // Spheres: the cold start (boundary point on the line of centers) is already optimal.
        assert_eq!(cold_iters, 0);
        assert!(warm_iters > 0);
    }

    #[test]
    fn warm_starts_save_iterations_on_ellipsoids() {
        let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
        let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
        let n = (0.81_f64 + 0.01 + 0.09 + 0.09).sqrt();
        let pose1 = pose_from_parts("p", [0.9 / n, 0.1 / n, 0.3 / n, 0.3 / n], [0.0; 3]).unwrap();
        let mut warm: Option<GrowthWarmStart> = None;
        let (mut cold_iters, mut warm_iters) = (0, 0);
        for k in 0..30 {
            let ang = 0.02 * k as Real;
            let (s, c) = (0.5 * ang).sin_cos();
            let pose2 = pose_from_parts("p", [c, 0.0, s, 0.0], [2.5 - 0.03 * k as Real, 0.4, 0.1]).unwrap();
            let w = growth(&e1, &pose1, &e2, &pose2, warm.as_ref(), &NewtonParams::default());
            let cold = growth(&e1, &pose1, &e2, &pose2, None, &NewtonParams::default());
            assert!(w.status.converged() && cold.status.converged());
            assert!((w.value - cold.value).abs() <= 1e-9 * cold.value.max(1.0), "{} vs {}", w.value, cold.value);
            // Feasibility and optimality against the closed-form ellipsoid: p₂'(x*) = 1.
            let local2 = pose2.inverse() * w.minimizer;
            assert!((e2.value_at(&local2) - 1.0).abs() < 1e-9);
            if k > 0 {
                assert!(w.warm_started);
                cold_iters += cold.iterations;
                warm_iters += w.iterations;
            }
            warm = Some(*w.warm_start);
        }
        assert!(warm_iters < cold_iters, "warm {warm_iters} vs cold {cold_iters}");
    }

    #[test]
    fn contained_minimizer_gives_inactive_constraint() {
        let small = ellipsoid([0.0; 3], [0.2, 0.3, 0.4]).unwrap();
        let big = ellipsoid([0.0; 3], [2.0; 3]).unwrap();
        let id = Isometry3::identity();
        let r = growth(&small, &id, &big, &id, None, &NewtonParams::default());
        assert_eq!(r.value, 0.0);
        assert_eq!(r.multiplier, 0.0);
        assert!(r.status.converged());
    }

    #[test]
    fn rotated_ellipsoid_matches_brute_force() {
        // p₁: unit sphere at origin; p₂: ellipsoid radii (1, 0.2, 0.2) rotated 90° about z, at (2, 0, 0).
        // Its long axis is along y, so the closest point to the origin is (1.8, 0, 0): d = 1.8².
        let s1 = ellipsoid([0.0; 3], [1.0; 3]).unwrap();
        let e2 = ellipsoid([0.0; 3], [1.0, 0.2, 0.2]).unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let pose2 = pose_from_parts("p", [h, 0.0, 0.0, h], [2.0, 0.0, 0.0]).unwrap();
        let r = growth(&s1, &Isometry3::identity(), &e2, &pose2, None, &NewtonParams::default());
        assert!(r.status.converged());
        assert!((r.value - 1.8 * 1.8).abs() < 1e-9, "{}", r.value);
        assert!((r.minimizer - Point3::new(1.8, 0.0, 0.0)).norm() < 1e-6);
    }
}
