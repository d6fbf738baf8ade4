//! Euclidean distance between two posed bodies with witness points (paper §IV-A, eq. "distance"):
//!
//! ```text
//! min ‖x − y‖²   s.t.   p_a'(x) ≤ 1,  p_b'(y) ≤ 1
//! ```
//!
//! Solved in body A's frame (A with the identity pose, B under pose_a⁻¹·pose_b), so world
//! offsets never enter the arithmetic. The growth measure decides overlap first: the bodies
//! intersect iff d(p_a‖p_b) ≤ 1, and then the distance is 0 with the growth minimizer as a common
//! witness. Separated bodies have both constraints active, and Newton's method solves the 8 × 8
//! KKT system
//!
//! ```text
//! 2(x − y) + λ_a ∇p_a'(x) = 0,   −2(x − y) + λ_b ∇p_b'(y) = 0,   p_a'(x) = 1,   p_b'(y) = 1
//! ```
//!
//! with exact Hessians, from a warm or a cold start. Warm: the previous answers of the pair,
//! extrapolated along the motion ([`MotionTrail`](crate::newton::MotionTrail)); the run is capped
//! at [`NewtonParams::warm_iterations`] and gives up when a multiplier turns nonpositive (the
//! bodies start to touch). Cold: when the segment
//! between the interior points leaves A before it enters B, Newton starts from the boundary points
//! of A towards B and of B towards A read off the bodies' radial tables
//! ([`sublevel_core::poly::RadialTable`]), with least-squares multipliers, and a converged answer with
//! positive multipliers needs no overlap test; otherwise (or when that run fails) the growth
//! measure decides overlap and the growth minimizer on B with the exact boundary point of A towards
//! it is the start. A log-barrier path from the two interior points is the globally convergent
//! fallback. A KKT point with λ_a, λ_b > 0 is the global minimizer of this convex program.
//!
//! The submodules hold the warm start ([`DistanceWarmStart`]), the cold starts and the barrier
//! path, the KKT system at an iterate, the answers, and the common points that show overlap
//! without a solve ([`common_point`](fn@common_point), [`segment_common_point`]).

mod answer;
mod common_point;
mod kkt;
mod start;
#[cfg(test)]
mod tests;
mod warm_start;

pub(crate) use answer::{clear_of_contact, finish, overlapping_answer, separated_answer};
pub use common_point::{common_point, segment_common_point};
pub(crate) use kkt::KktOut;
pub(crate) use start::cold_start;
pub use warm_start::{warm_start_reaches, warm_start_reaches_with, DistanceWarmStart};

use crate::fast_eval::FastPosed;
use crate::growth::{solve_growth, GrowthStart, GrowthWarmStart};
use crate::newton::{
    boundary_on_segment_within, merit_length, step_accepted, working_frame, NewtonParams, SolveStatus,
};
use kkt::{initial_multipliers, newton_step, KktPoint};
use start::barrier;
use sublevel_core::body::{Body, PosedBody};
use sublevel_core::math::{Isometry3, Point3, Real, Sym3, Vector3};

/// Answer of a distance query; all points in world coordinates (meters).
#[derive(Clone, Debug)]
pub struct DistanceResult {
    /// ‖x* − y*‖ in meters; 0 when the bodies overlap or touch.
    pub distance: Real,
    /// Closest point of body A.
    pub witness_a: Point3,
    /// Closest point of body B (equal to `witness_a` when overlapping).
    pub witness_b: Point3,
    /// Unit normal from A towards B, (y* − x*)/‖y* − x*‖; zero when overlapping.
    pub normal: Vector3,
    /// True when the bodies overlap or touch (d(p_a‖p_b) ≤ 1).
    pub overlapping: bool,
    /// How the solve ended; only [`SolveStatus::Converged`] answers are certified optimal.
    pub status: SolveStatus,
    /// Newton iterations over all phases (growth check included).
    pub iterations: usize,
    /// Final ∞-norm of the KKT residual.
    pub kkt_residual: Real,
    /// Whether the answer came from the warm start.
    pub warm_started: bool,
    /// State for warm-starting the next query of the same pair.
    pub warm_start: std::sync::Arc<DistanceWarmStart>,
}

avx2_dispatch! {
    /// Distance between body `a` posed by `pose_a` and body `b` posed by `pose_b` (paper eq.
    /// "distance").
    ///
    /// `warm` is the `warm_start` of a previous answer for the same ordered pair. Never panics on
    /// valid bodies; the answer says whether it converged.
    pub fn distance => distance_body(
        a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3, warm: Option<&DistanceWarmStart>,
        params: &NewtonParams,
    ) -> DistanceResult
}

/// The body of [`distance()`], inlined into each of its builds (`FMA` only selects the build: the
/// Newton runs it calls dispatch on their own).
#[inline(always)]
fn distance_body<const FMA: bool>(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    warm: Option<&DistanceWarmStart>,
    params: &NewtonParams,
) -> DistanceResult {
    let rel = pose_a.inv_mul(pose_b);
    let (o, ba, bb) = working_frame(a, b, &rel, params);
    let mut iterations = 0;

    // The trail of this answer: the last separated answer and its own trail, with the step from it,
    // unless that answer lies more than `warm_reach` of the bodies' size away (a warm start from
    // there costs more than a cold start).
    let length = a.scale() + b.scale();
    let previous = warm.and_then(|w| Some((w, w.separated_step(&rel, length, params)?)));
    if let Some((w, step)) = &previous {
        let (a0, b0, lam0) = w.predict(step, params);
        let y0 = bb.to_world(&b0);
        let out = kkt_newton(&ba, &bb, a0 - o, y0, Some(lam0), params, params.warm_iterations, true);
        iterations += out.iterations;
        if out.status.converged() {
            return finish(pose_a, &rel, out.moved(&o), iterations, true, &w.growth, previous);
        }
    }

    // Cold start without a growth warm start: separation shown by disjoint bounding spheres (then
    // Newton from the support points towards each other), or by the segment between the interior
    // points (both outside the other body, A's crossing before B's: then Newton from the closer of
    // the support and the segment's boundary points). A converged KKT point with λ_a, λ_b > 0 is
    // the global minimizer, so separation needs no growth solve.
    let growth_start = warm.and_then(|w| w.growth_start(&rel, a.scale(), length, params));
    if growth_start.is_none() {
        if let Some((x0, y0)) = cold_start(&ba, &bb) {
            let out = kkt_newton(&ba, &bb, x0, y0, None, params, params.speculative_iterations, false);
            iterations += out.iterations;
            if out.status.converged() && clear_of_contact(&out.x, &out.y, a, b) {
                return finish(pose_a, &rel, out.moved(&o), iterations, false, &GrowthWarmStart::default(), previous);
            }
        }
    }

    growth_first(pose_a, &rel, &o, &ba, &bb, growth_start, previous, params, iterations)
}

/// The cold distance answer of a pair whose cold start shows no separation ([`cold_start`] gave
/// `None`): the growth-first path of [`distance`], without asking for the start again (the batch
/// solver's pairs that overlap, [`super::batch`]).
pub(super) fn distance_growth_first(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    params: &NewtonParams,
) -> DistanceResult {
    let rel = pose_a.inv_mul(pose_b);
    let (o, ba, bb) = working_frame(a, b, &rel, params);
    growth_first(pose_a, &rel, &o, &ba, &bb, None, None, params, 0)
}

/// [`distance`] from its overlap test on, in the working frame `o` of A and B posed by `rel` =
/// pose_a⁻¹·pose_b ([`working_frame`]: `ba`, `bb`): the growth measure (from the warm start
/// `start`, if any) decides overlap (the touching answer at its minimizer), else Newton from the
/// growth minimizer, else the barrier path; `iterations` spent so far.
#[allow(clippy::too_many_arguments)]
fn growth_first(
    pose_a: &Isometry3,
    rel: &Isometry3,
    o: &Vector3,
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    start: Option<GrowthStart<'_>>,
    previous: Option<(&DistanceWarmStart, [Real; 6])>,
    params: &NewtonParams,
    mut iterations: usize,
) -> DistanceResult {
    // Overlap test by the growth measure.
    let rel_ba = rel.inverse();
    let g = solve_growth(ba, bb, start, params);
    iterations += g.iterations;
    let growth_warm = GrowthWarmStart::after(start, g.x, g.mu, g.status.converged(), rel_ba);
    let touching = |iterations: usize| {
        let warm_start = std::sync::Arc::new(DistanceWarmStart { growth: growth_warm, ..Default::default() });
        let p = pose_a * (rel * Point3::from(g.x));
        overlapping_answer(p, g.status, iterations, g.residual, g.warm_started, warm_start)
    };
    if g.value <= 1.0 {
        return touching(iterations);
    }

    // Separated: cold start from the growth minimizer on B (g.x in B's frame).
    let y0 = bb.to_world(&g.x);
    // Exact boundary point: near contact the radial table's estimate may lie past y0.
    let x0 = boundary_on_segment_within(ba, &ba.interior_point(), &y0, params.start_boundary_tolerance);
    let out = kkt_newton(ba, bb, x0, y0, None, params, params.max_iterations, false);
    iterations += out.iterations;
    if out.status.converged() {
        return finish(pose_a, rel, out.moved(o), iterations, false, &growth_warm, previous);
    }
    // Touching within the growth solve's tolerance: at exact tangency the separated KKT system is
    // degenerate (x = y, λ → 0), so Newton cannot converge there; the growth answer is the
    // touching point (the distance is below ~`touch_growth_tolerance` × the bodies' size).
    if g.status.converged() && g.value <= 1.0 + params.touch_growth_tolerance {
        return touching(iterations);
    }
    let (xb, yb, lamb, it_b) = barrier(ba, bb, params);
    iterations += it_b;
    let out = kkt_newton(ba, bb, xb, yb, Some(lamb), params, params.max_iterations, false);
    iterations += out.iterations;
    finish(pose_a, rel, out.moved(o), iterations, false, &growth_warm, previous)
}

avx2_dispatch! {
    /// Active-set Newton on the 8 × 8 KKT system from (x0, y0) and the multipliers `lam0` (least
    /// squares at the start when `None`), at most `cap` Newton steps (and
    /// [`NewtonParams::max_iterations`]), globalized by backtracking on the scale-free merit
    /// ‖(r_a/L, r_b/L, p_a' − 1, p_b' − 1)‖₂ ([`merit_length`]); a `warm` run gives up
    /// (Stalled) when a multiplier turns nonpositive. Every point is evaluated once; near the
    /// solution (residual below [`NewtonParams::chord_residual`]) trial points skip the Hessians
    /// and a further step reuses the last ones (chord step), refreshed when it stalls.
    #[allow(clippy::too_many_arguments)]
    fn kkt_newton => kkt_newton_body(
        ba: &PosedBody<'_>, bb: &PosedBody<'_>, x0: Vector3, y0: Vector3, lam0: Option<[Real; 2]>,
        params: &NewtonParams, cap: usize, warm: bool,
    ) -> KktOut
}

/// The body of [`kkt_newton`], inlined into each of its builds.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn kkt_newton_body<const FMA: bool>(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    x0: Vector3,
    y0: Vector3,
    lam0: Option<[Real; 2]>,
    params: &NewtonParams,
    cap: usize,
    warm: bool,
) -> KktOut {
    // The cap passed apart from the settings: a capped copy of them (a few hundred bytes) would
    // be written on every warm query.
    let cap = cap.min(params.max_iterations);
    let (fa, fb) = (FastPosed::<FMA>::build(ba), FastPosed::<FMA>::build(bb));
    let (mut x, mut y) = (x0, y0);
    let mut pt = KktPoint::new(&fa, &fb, &x, &y, lam0.unwrap_or_default(), true);
    // Without a start for the multipliers: least squares from the first point's gradients.
    let mut lam = lam0.unwrap_or_else(|| initial_multipliers(&pt.ea.gradient, &pt.eb.gradient, &x, &y));
    if lam0.is_none() {
        pt.set_multipliers(&x, &y, lam);
    }
    let mut hess: Option<(Sym3, Sym3)> = None;
    let mut status = SolveStatus::MaxIterations;
    let mut it = 0;
    let scale = |x: &Vector3, y: &Vector3| 1.0 + 2.0 * (x - y).norm();
    // The line search's merit weighs stationarity (meters) by 1/L and its level by the same L
    // ([`merit_length`]), so the run does not depend on the bodies' size.
    let len = merit_length(ba.body, bb.body);
    let w2 = 1.0 / (len * len);
    let merit_scale = |x: &Vector3, y: &Vector3| 1.0 + 2.0 * (x - y).norm() / len;
    let positive = |lam: [Real; 2]| lam[0] > 0.0 && lam[1] > 0.0;
    let stationary = |pt: &KktPoint, sc: Real| pt.norm_inf() <= params.kkt_tolerance * sc;
    while it < cap {
        // The 2-norm carries any NaN or infinity of the residual (the ∞-norm's plain maxima do not).
        let r0 = pt.merit(w2);
        if !r0.is_finite() {
            status = SolveStatus::Stalled;
            break;
        }
        let sc = scale(&x, &y);
        // A KKT point is the answer when its multipliers are positive; otherwise it is not the
        // minimizer and Newton does not leave it: stop instead of iterating there up to the cap.
        if stationary(&pt, sc) {
            status = if positive(lam) { SolveStatus::Converged } else { SolveStatus::Stalled };
            break;
        }
        // Fresh Hessians when this point has them, else the last ones (chord step).
        let fresh = match (fa.hessian(&pt.ea), fb.hessian(&pt.eb)) {
            (Some(ha), Some(hb)) => {
                hess = Some((ha, hb));
                true
            }
            _ => false,
        };
        let Some(h) = hess else {
            pt = KktPoint::new(&fa, &fb, &x, &y, lam, true);
            continue;
        };
        it += 1;
        let Some((dx, dy, dl)) = newton_step::<FMA>(&h, &pt, lam) else {
            status = SolveStatus::Stalled;
            break;
        };
        // The chord level on the merit's scale 1 + 2‖x − y‖/L.
        let cheap = r0 <= params.chord_residual * merit_scale(&x, &y);
        // The trial points are evaluated into `pt` itself (its Hessians are in `hess` already):
        // no copy of the accepted point. A rejected line search re-evaluates the current point.
        let mut alpha = 1.0;
        let mut accepted = false;
        for _ in 0..params.line_search_steps {
            let (xt, yt) = (x + dx * alpha, y + dy * alpha);
            let lt = [lam[0] + dl[0] * alpha, lam[1] + dl[1] * alpha];
            pt = KktPoint::new(&fa, &fb, &xt, &yt, lt, !cheap);
            if step_accepted(r0, pt.merit(w2), alpha, fresh) {
                (x, y, lam) = (xt, yt, lt);
                accepted = true;
                break;
            }
            if !fresh {
                break;
            }
            alpha *= 0.5;
        }
        if !accepted {
            pt = KktPoint::new(&fa, &fb, &x, &y, lam, true);
            if !fresh {
                continue;
            }
            status = SolveStatus::Stalled;
            break;
        }
        // A warm run whose multipliers turn nonpositive is following bodies that start to touch:
        // leave it to the growth test.
        if warm && (lam[0] <= 0.0 || lam[1] <= 0.0) {
            status = SolveStatus::Stalled;
            break;
        }
    }
    if status == SolveStatus::MaxIterations
        && positive(lam)
        && stationary(&pt, scale(&x, &y))
        && pt.merit(w2).is_finite()
    {
        status = SolveStatus::Converged;
    }
    KktOut { x, y, lam, status, iterations: it, residual: pt.norm_inf() }
}
