//! Shared machinery of the Newton / active-set query solvers: statuses, tolerances, the exact
//! boundary search along a segment, and the warm-start predictor ([`MotionTrail`]) that
//! extrapolates earlier answers of a pair along the motion.
//!
//! Both queries are convex programs with one or two smooth convex constraints `g(x) = p'(x) − 1 ≤ 0`
//! (paper §IV-A, §IV-B). The solvers share one strategy:
//!
//! ```text
//! 1. active-set Newton on the KKT system with every constraint active, from a warm start (when
//!    its answer lies within [`NewtonParams::warm_reach`] of the bodies' size) or a geometric
//!    cold start;
//!    globalized by a backtracking line search on ‖KKT residual‖ ([`step_accepted`]) with
//!    stationarity in units of the smaller body's size, so that a run does not depend on the
//!    bodies' size ([`merit_length`]);
//! 2. if that does not converge to a KKT point with positive multipliers, a primal log-barrier
//!    path ([`barrier_path`]: always globally convergent on these convex problems, started from
//!    the bodies' interior points), then the active-set Newton polish from the barrier's point.
//! ```
//!
//! A KKT point with nonnegative multipliers of a convex program is its global minimizer, so a
//! converged answer is the answer.
//!
//! Every tolerance, cap and threshold of the solvers is a field of [`NewtonParams`], the settings
//! each query receives; the default is the tuned value.

use crate::batch::BatchSettings;
use serde::{Deserialize, Serialize};
use sublevel_core::body::{Body, PosedBody};
use sublevel_core::math::{Isometry3, Real, Vector3, NEWTON_KKT_TOLERANCE, NEWTON_MAX_ITERATIONS};
use sublevel_core::poly::radial::ray_crossing;

/// The working frame of a query between body `a` (frame of reference) and body `b` posed by `rel`
/// in A's frame: A's frame moved to the origin `o` (meters, A's frame), the interior point of the
/// smaller body, with both bodies posed in it. Returns (o, A, B).
///
/// Newton's iterates and the bodies' normalized coordinates are then exact to the rounding of
/// coordinates about as large as the bodies and their gap, not of A's frame: a 1 mm body next to
/// a 1 m body whose center lies 1 km from its own frame's origin (a body fitted in site
/// coordinates) has its points at ~10³ m in A's frame, where rounding (10⁻¹³ m) is 10⁻¹⁰ of its
/// size, the KKT tolerance, so Newton could not converge there.
/// A translation keeps A unrotated (its gradients and Hessians scaled, not rotated).
///
/// Where coordinates stay below [`NewtonParams::frame_shift_ratio`] times the smaller body's size
/// (bounded by |t_rel|₁ + |c_a|₁ + |c_b|₁, the bodies' centers in their frames) the frame is A's
/// own (o = 0): rounding is then below 10⁻¹³ of either body's size at the default ratio, and the
/// common query skips the shift.
#[inline(always)]
pub(crate) fn working_frame<'a>(
    a: &'a Body,
    b: &'a Body,
    rel: &Isometry3,
    params: &NewtonParams,
) -> (Vector3, PosedBody<'a>, PosedBody<'a>) {
    let (o, bb) = posed_in_frame(b, rel, frame_origin(a, b, rel, params.frame_shift_ratio));
    (o, PosedBody::translated(a, &-o), bb)
}

/// The length L (meters) by which the Newton runs' line searches measure stationarity: the smaller
/// body's normalization scale.
///
/// A KKT residual mixes stationarity with the constraints p' − 1 (dimensionless): 2(x − y) + λ∇p'
/// in meters for the distance, ∇p₁' + μ∇p₂' in 1/m for the growth measure. Scaling a problem by
/// k scales Newton's iterates by k (Newton's method is invariant under a change of units) but the
/// stationarity residuals by k (distance) or 1/k (growth), so a merit ‖r‖₂ would weigh them
/// differently against the constraints at every size: on small bodies the distance line search
/// would cut nearly every step to reduce |p' − 1| alone, and large bodies would slow the growth
/// runs likewise. Stationarity in units of L (the distance's divided by L, the growth measure's
/// times L) makes the merits, and the runs, the same at every size (the convergence tests stay
/// absolute). The bench bodies have scales near 1, where the runs are the unit-length ones'.
#[inline(always)]
pub(crate) fn merit_length(a: &Body, b: &Body) -> Real {
    a.scale().min(b.scale())
}

/// The origin of [`working_frame`] in A's frame: `None` where A's own frame serves (coordinates
/// below `shift_ratio` ([`NewtonParams::frame_shift_ratio`]) times the smaller body's size), else
/// the smaller body's interior point.
#[inline(always)]
pub(crate) fn frame_origin(a: &Body, b: &Body, rel: &Isometry3, shift_ratio: Real) -> Option<Vector3> {
    let reach = rel.translation.vector.abs().sum() + a.center().abs().sum() + b.center().abs().sum();
    if reach <= shift_ratio * a.scale().min(b.scale()) {
        return None;
    }
    Some(if a.scale() <= b.scale() { a.interior_point().coords } else { (rel * b.interior_point()).coords })
}

/// The working frame's origin (zero for `None`, [`frame_origin`]) and B posed in it: `rel` (B's
/// pose in A's frame) with the translation less the origin, the same rotation.
#[inline(always)]
pub(crate) fn posed_in_frame<'a>(b: &'a Body, rel: &Isometry3, origin: Option<Vector3>) -> (Vector3, PosedBody<'a>) {
    match origin {
        None => (Vector3::zeros(), PosedBody::new(b, rel)),
        Some(o) => (o, PosedBody::new(b, &Isometry3::from_parts((rel.translation.vector - o).into(), rel.rotation))),
    }
}

/// How a query solve ended (a value, not an error; paper §IV).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum SolveStatus {
    /// KKT residual below tolerance with valid multipliers: the answer is the global optimum.
    Converged,
    /// The iteration cap was reached first; the answer is the last iterate.
    MaxIterations,
    /// No further progress was possible (line search failure, singular system).
    Stalled,
}

impl SolveStatus {
    /// True for [`SolveStatus::Converged`].
    pub fn converged(self) -> bool {
        self == SolveStatus::Converged
    }
}

/// Settings of the Newton / active-set solvers: the single-pair [`distance()`](crate::distance())
/// and [`growth()`](crate::growth()) and the batch solver's lanes ([`crate::batch`]). Each field is
/// one tolerance, cap or threshold of the solvers, documented with what a larger value trades; the
/// default ([`NewtonParams::DEFAULT`]) is the value the solvers are tuned to on the bundled bodies
/// (`crates/lab/examples/cold_profile.rs`).
///
/// Change a field with struct update syntax, so that fields added later keep their defaults:
///
/// ```
/// use sublevel_query::NewtonParams;
///
/// let params = NewtonParams { kkt_tolerance: 1e-12, ..NewtonParams::default() };
/// assert_eq!(params.max_iterations, NewtonParams::default().max_iterations);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonParams {
    /// Tolerance on the ∞-norm of the KKT residual (objective units per meter for stationarity,
    /// dimensionless for the constraints p' − 1); default 10⁻¹⁰. Smaller: more accurate answers,
    /// more iterations.
    pub kkt_tolerance: Real,
    /// Cap on Newton iterations per phase (the barrier path takes up to four times as many
    /// steps); default 100. Larger: fewer answers end at the cap, slower failures.
    pub max_iterations: usize,
    /// Iteration cap of a warm-started run, after which the query takes the cold path; default 8.
    /// From a predicted start Newton converges in one or two iterations, so a run that needs more
    /// has lost its way (the active set changed: a growth constraint turning inactive, bodies
    /// starting to touch). Larger: fewer warm runs given up, more iterations spent on runs that
    /// fail anyway.
    pub warm_iterations: usize,
    /// Largest relative-pose step from a warm start's answer at which the warm start is used, in
    /// units of the two bodies' summed scales (a rotation by θ counts as θ times that length);
    /// default 0.5, past which the query starts cold. Larger: warm starts used from farther away,
    /// fewer cold solves, more iterations per warm query. On the bench's chair / human poses warm
    /// and cold queries cost the same near 0.5 (warm runs from far answers fail, and the growth
    /// measure then starts from a far minimizer); without a limit, a sampling planner's candidate
    /// states asked in a row cost several times a cold query each.
    pub warm_reach: Real,
    /// Largest extrapolation of the warm start's motion predictor ([`MotionTrail`]), in units of
    /// the last step between answers; default 2. Larger: predictions over longer steps (worse
    /// starts where the motion bends); smaller: the plain last answer as start sooner.
    pub max_extrapolation: Real,
    /// Predicted ratio μ_next/μ_last of the growth measure's multiplier below which a warm start
    /// first checks whether the constraint has turned inactive (one evaluation of p₂' at p₁'s
    /// minimizer); default 0.75 (a smooth motion changes μ far less per query). Larger: more
    /// such checks, fewer warm runs lost to a constraint that turned inactive.
    pub falling_multiplier: Real,
    /// Iteration cap of the speculative cold distance run from the separated start (the batch
    /// lanes' cap too), after which the growth-first path takes over; default 30. Larger: fewer
    /// pairs fall to the growth-first path, more iterations spent on runs that fail.
    pub speculative_iterations: usize,
    /// Line-search merit, relative to its stationarity scale, below which the next trial point is
    /// evaluated without Hessians (expected converged; if not, the next step reuses the last
    /// Hessians, a chord step, refreshed when it does not halve the merit); default 3·10⁻⁴.
    /// Larger: fewer Hessian evaluations, more iterations; 0: never a chord step. On the bench's
    /// cold poses lower values save no iterations and evaluate more Hessians, higher ones add
    /// iterations.
    pub chord_residual: Real,
    /// Most trial points of one backtracking line search (the step halves after each rejected
    /// one), and the rejected trial points in a row after which a batch lane leaves; default 40.
    /// Larger: runs stall later, after more evaluations.
    pub line_search_steps: usize,
    /// Relative tolerance |p' − 1| of the exact boundary point of A that starts the distance solve
    /// from the growth minimizer (near contact, where the radial table's estimate may lie past
    /// B); default 10⁻⁴. Smaller: a start closer to A's boundary, more steps of the boundary
    /// search.
    pub start_boundary_tolerance: Real,
    /// Margin d(p_a‖p_b) − 1 below which a pair whose separated Newton solve fails is answered as
    /// touching (distance 0, the growth minimizer as witness: at exact tangency the separated KKT
    /// system is degenerate); default 10⁻⁹. Larger: more near-touching pairs answered as touching
    /// without the barrier path, with a larger distance error (about this times the bodies' size).
    pub touch_growth_tolerance: Real,
    /// Coordinates (meters) up to this multiple of the smaller body's size keep a query in A's
    /// frame; past it the query runs in a working frame at the smaller body's interior point
    /// (`working_frame`); default 10³, where A's frame rounds to 10⁻¹³ of the smaller body's size.
    /// Larger: fewer queries pay the frame shift, coarser rounding relative to a small body far
    /// from A's frame origin; smaller: the shift for more queries.
    pub frame_shift_ratio: Real,
    /// Settings of the batch solver's lanes ([`crate::batch::cold_distances`]).
    pub batch: BatchSettings,
}

impl NewtonParams {
    /// The default settings (a constant, for contexts that need one).
    pub const DEFAULT: Self = Self {
        kkt_tolerance: NEWTON_KKT_TOLERANCE,
        max_iterations: NEWTON_MAX_ITERATIONS,
        warm_iterations: 8,
        warm_reach: 0.5,
        max_extrapolation: 2.0,
        falling_multiplier: 0.75,
        speculative_iterations: 30,
        chord_residual: 3e-4,
        line_search_steps: 40,
        start_boundary_tolerance: 1e-4,
        touch_growth_tolerance: 1e-9,
        frame_shift_ratio: 1e3,
        batch: BatchSettings::DEFAULT,
    };
}

impl Default for NewtonParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}
/// Whether the backtracking line search of a Newton run accepts the trial point at step length
/// `alpha`, of merit `r1`, against the merit `r0` of the current point: sufficient decrease,
/// r₁ ≤ (1 − 10⁻⁴α)·r₀, for a step from fresh Hessians; a chord step (`fresh` false: the
/// Hessians of an earlier point) must at least halve the merit, else the caller refreshes the
/// Hessians and stops the search. A NaN or infinite merit is never accepted.
#[inline(always)]
pub(crate) fn step_accepted(r0: Real, r1: Real, alpha: Real, fresh: bool) -> bool {
    let bound = if fresh { (1.0 - 1e-4 * alpha) * r0 } else { 0.5 * r0 };
    r1.is_finite() && r1 <= bound
}

/// An iterate of a log-barrier path ([`barrier_path`]): one point, or the pair of points of the
/// distance problem.
pub(crate) trait BarrierPoint: Copy {
    /// The point moved by `alpha` times the Newton step `step`.
    fn stepped(&self, step: &Self, alpha: Real) -> Self;
}

impl BarrierPoint for Vector3 {
    #[inline(always)]
    fn stepped(&self, step: &Self, alpha: Real) -> Self {
        self + step * alpha
    }
}

impl BarrierPoint for (Vector3, Vector3) {
    #[inline(always)]
    fn stepped(&self, step: &Self, alpha: Real) -> Self {
        (self.0 + step.0 * alpha, self.1 + step.1 * alpha)
    }
}

/// The primal log-barrier path of the query solvers, their globally convergent fallback: for
/// t = `t0`, t0/10, t0/100, … it centers on `min φ_t(x)`, φ_t = objective − t·Σ log(−gᵢ(x)), by
/// damped Newton steps, from the strictly feasible `start` (the bodies' interior points), until
/// `done(x, t)`; at most 4 × `params.max_iterations` Newton steps in all.
///
/// `center(x, t)` gives the Newton step of φ_t at x, its decrement −∇φ_tᵀΔx, and φ_t(x) (`None`
/// when x is not strictly feasible); `None` when the Hessian is not positive definite, which ends
/// the path. A centering stops when the decrement falls to 10⁻³·t; each step backtracks from 1
/// until `phi(x, t)` (φ_t at a trial point, `None` outside the feasible set) decreases by a
/// quarter of the decrement times the step length, and the path ends when α falls below 10⁻¹².
/// Returns the last point, the last t (the multiplier estimates are t/(−gᵢ)), and the Newton
/// steps taken.
pub(crate) fn barrier_path<P: BarrierPoint>(
    start: P,
    t0: Real,
    params: &NewtonParams,
    mut center: impl FnMut(&P, Real) -> Option<(P, Real, Option<Real>)>,
    mut phi: impl FnMut(&P, Real) -> Option<Real>,
    done: impl Fn(&P, Real) -> bool,
) -> (P, Real, usize) {
    let (mut x, mut t) = (start, t0);
    let mut it = 0;
    let max_it = params.max_iterations * 4;
    'outer: while it < max_it {
        // Centering.
        loop {
            if it >= max_it {
                break 'outer;
            }
            let Some((step, dec, phi0)) = center(&x, t) else { break 'outer };
            it += 1;
            if dec <= 1e-3 * t {
                break;
            }
            let Some(phi0) = phi0 else { break 'outer };
            let mut alpha = 1.0;
            loop {
                let xt = x.stepped(&step, alpha);
                if phi(&xt, t).is_some_and(|p| p <= phi0 - 0.25 * alpha * dec) {
                    x = xt;
                    break;
                }
                alpha *= 0.5;
                if alpha < 1e-12 {
                    break 'outer;
                }
            }
        }
        if done(&x, t) {
            break;
        }
        t *= 0.1;
    }
    (x, t, it)
}

/// The point where the segment from `inside` (p' < 1) to `outside` (p' > 1) crosses the boundary
/// p' = 1 to machine precision (see [`boundary_on_segment_within`]).
#[cfg(test)]
pub(crate) fn boundary_on_segment(body: &PosedBody<'_>, inside: &Vector3, outside: &Vector3) -> Vector3 {
    boundary_on_segment_within(body, inside, outside, 1e-15)
}

/// The point where the segment from `inside` (p' < 1) to `outside` (p' > 1) crosses the boundary
/// p' = 1, to |p' − 1| ≤ `tolerance` ([`ray_crossing`] in the body's normalized coordinates: the
/// world → normalized map is affine, so the segment parameter is the same).
pub(crate) fn boundary_on_segment_within(
    body: &PosedBody<'_>,
    inside: &Vector3,
    outside: &Vector3,
    tolerance: Real,
) -> Vector3 {
    let dir = outside - inside;
    let s = ray_crossing(body.body.fast_polynomial(), &body.to_normalized(inside), &(body.linear() * dir), tolerance);
    inside + dir * s
}

/// Whether the bounding spheres of the two posed bodies are disjoint ([`sublevel_core::Body::bounding_sphere`];
/// false for a nonconvex body, which has none). Then the bodies are separated, which spares the
/// distance solver's cold start its overlap tests (two evaluations) and, past 2d = 2, its radial
/// points (two table look-ups), for a test of about 90 instructions (the spheres are cached in the
/// body, the centers mapped through the posed bodies' matrices). The growth solver's one
/// evaluation it would spare (p₂ at p₁'s minimizer) costs about what this test does, so it does
/// not ask.
#[inline(always)]
pub(crate) fn spheres_apart(b1: &PosedBody<'_>, b2: &PosedBody<'_>) -> bool {
    match (b1.body.bounding_sphere(), b2.body.bounding_sphere()) {
        (Some((c1, r1)), Some((c2, r2))) => {
            (b1.to_world(&c1.coords) - b2.to_world(&c2.coords)).norm_squared() > (r1 + r2) * (r1 + r2)
        }
        _ => false,
    }
}

/// A relative-pose step `from → to` as a 6-vector: translation in meters, then the rotation vector
/// times `length` meters (so that rotations and translations are compared on one scale).
///
/// The rotation vector is taken in its small-angle form 2·sign(w)·(x, y, z) of the step's quaternion
/// (exact direction; magnitude 2 sin(θ/2) ≈ θ for the small steps that matter here).
#[inline(always)]
pub(crate) fn pose_step(from: &Isometry3, to: &Isometry3, length: Real) -> [Real; 6] {
    let q = to.rotation * from.rotation.inverse();
    let s = if q.w < 0.0 { -2.0 * length } else { 2.0 * length };
    let t = to.translation.vector - q * from.translation.vector;
    [t.x, t.y, t.z, q.i * s, q.j * s, q.k * s]
}

/// a · b for 6-vectors, written out (the iterator form compiles to a loop through `Zip`, a
/// noticeable share of a warm query's instructions).
#[inline(always)]
fn dot6(a: &[Real; 6], b: &[Real; 6]) -> Real {
    (a[0] * b[0] + a[1] * b[1]) + (a[2] * b[2] + a[3] * b[3]) + (a[4] * b[4] + a[5] * b[5])
}

/// The step `d` in units of the step `d1` before it, when the two are nearly parallel (cosine ≥ 0.9)
/// and `d1` is not negligible; `None` otherwise.
#[cfg(test)]
fn step_ratio(d1: &[Real; 6], d: &[Real; 6]) -> Option<Real> {
    step_ratio_with(d1, dot6(d1, d1), d)
}

/// `step_ratio` with ‖d₁‖² given (`n1`), for several steps measured against one d₁.
#[inline(always)]
fn step_ratio_with(d1: &[Real; 6], n1: Real, d: &[Real; 6]) -> Option<Real> {
    let n = dot6(d, d);
    if !(n1 > 1e-24 && n.is_finite()) {
        return None;
    }
    let c = dot6(d, d1);
    (c > 0.0 && c * c >= 0.81 * n1 * n).then_some(c / n1)
}

/// One earlier solution of a pair along a motion, for the predictor of a warm start
/// ([`MotionTrail`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrailPoint<const N: usize> {
    /// The solution: points in body frames (meters), then the multipliers.
    pub state: [Real; N],
    /// The relative-pose step (`pose_step`) from this solution's pose to the next newer one's.
    pub step: [Real; 6],
}

/// Earlier solutions a [`MotionTrail`] keeps besides the last one (so the predictor is at most
/// cubic).
pub const TRAIL_LENGTH: usize = 3;

/// Up to [`TRAIL_LENGTH`] solutions of a pair before the last one, newest first, with the
/// relative-pose steps between them: with them a warm start extrapolates the last solution along
/// the motion instead of restarting from it (a polynomial continuation predictor).
///
/// ```text
/// nodes along the motion, in units of the last step d₁ (steps projected on d₁, cosine ≥ 0.9):
///   t_last = 0,  t₁ = −1,  t₂ = t₁ − τ₂,  t₃ = t₂ − τ₃      current pose at t = σ
/// s(σ) ≈ Σᵢ wᵢ sᵢ,  wᵢ = Πⱼ≠ᵢ (σ − tⱼ)/(tᵢ − tⱼ)          (Lagrange extrapolation)
/// ```
///
/// Along a smooth motion a predictor through k + 1 nodes is off by O(‖step‖^(k+1)) (the plain warm
/// start by O(‖step‖)), so one Newton step (quadratic convergence) usually reaches the KKT
/// tolerance. The chain of nodes stops at the first step that is not nearly parallel to d₁ or whose
/// length ratio leaves [1/4, 4], and the prediction is the plain warm start when the current step
/// turns away from d₁ or exceeds [`NewtonParams::max_extrapolation`] (default 2) times d₁.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionTrail<const N: usize> {
    /// The earlier solutions, newest first.
    pub points: [Option<TrailPoint<N>>; TRAIL_LENGTH],
}

/// Whether a relative-pose step ([`pose_step`]) from a warm start's answer is small enough for
/// the warm start to beat a cold start ([`NewtonParams::warm_reach`] of `length`, the bodies'
/// summed scales, meters); false for a NaN step.
#[inline(always)]
pub(crate) fn within_warm_reach(step: &[Real; 6], length: Real, params: &NewtonParams) -> bool {
    let reach = params.warm_reach * length;
    dot6(step, step) <= reach * reach
}

impl<const N: usize> MotionTrail<N> {
    /// The trail of an answer whose solve started from the last solution `last` (with its own
    /// trail `trail`) and moved by the relative-pose step `step` to the new answer.
    #[inline(always)]
    pub(crate) fn extend(last: &[Real; N], trail: &MotionTrail<N>, step: [Real; 6]) -> Self {
        let mut points = [None; TRAIL_LENGTH];
        points[0] = Some(TrailPoint { state: *last, step });
        points[1..].copy_from_slice(&trail.points[..TRAIL_LENGTH - 1]);
        Self { points }
    }

    /// Whether the trail holds no earlier solution (the prediction is then the last solution).
    pub fn is_empty(&self) -> bool {
        self.points[0].is_none()
    }

    /// The predicted solution after the relative-pose step `step` from the last solution `last`,
    /// extrapolated at most `max_extrapolation` times the last step
    /// ([`NewtonParams::max_extrapolation`]); entries from `first_multiplier` on are multipliers,
    /// kept at or above half their last value. The flag says whether a multiplier was raised to
    /// that floor (the extrapolation sees it falling fast: its constraint may be turning inactive).
    #[inline(always)]
    pub(crate) fn predict(
        &self,
        last: &[Real; N],
        step: &[Real; 6],
        first_multiplier: usize,
        max_extrapolation: Real,
    ) -> ([Real; N], bool) {
        let Some(p) = &self.points[0] else { return (*last, false) };
        let n1 = dot6(&p.step, &p.step);
        let Some(sigma) = step_ratio_with(&p.step, n1, step).filter(|s| *s <= max_extrapolation) else {
            return (*last, false);
        };
        // Nodes: t[0] = 0 (last), t[1] = −1 (previous), then the earlier ones while their steps
        // stay nearly parallel to the last step and of comparable length; states[i] at t[i].
        let mut t = [0.0; TRAIL_LENGTH + 1];
        let mut states = [last; TRAIL_LENGTH + 1];
        t[1] = -1.0;
        states[1] = &p.state;
        let mut nodes = 2;
        for q in self.points[1..].iter() {
            let Some(q) = q else { break };
            match step_ratio_with(&p.step, n1, &q.step).filter(|r| (0.25..=4.0).contains(r)) {
                Some(r) => {
                    t[nodes] = t[nodes - 1] - r;
                    states[nodes] = &q.state;
                    nodes += 1;
                }
                None => break,
            }
        }
        // Lagrange weights wᵢ = Πⱼ≠ᵢ (σ − tⱼ) / Πⱼ≠ᵢ (tᵢ − tⱼ): one division per node.
        let mut out = [0.0; N];
        for i in 0..nodes {
            let (mut num, mut den) = (1.0, 1.0);
            for j in 0..nodes {
                if j != i {
                    num *= sigma - t[j];
                    den *= t[i] - t[j];
                }
            }
            let w = num / den;
            for (o, s) in out.iter_mut().zip(states[i].iter()) {
                *o += w * s;
            }
        }
        let mut floored = false;
        for i in first_multiplier..N {
            if out[i] < 0.5 * last[i] {
                out[i] = 0.5 * last[i];
                floored = true;
            }
        }
        (out, floored)
    }
}

#[cfg(test)]
mod trail_tests {
    use super::*;
    use sublevel_core::math::UnitQuaternion;

    /// The predictor's default extrapolation limit.
    const SIGMA: Real = NewtonParams::DEFAULT.max_extrapolation;

    /// A smooth motion: translation and rotation both linear in s.
    fn pose(s: Real) -> Isometry3 {
        Isometry3::from_parts(
            Vector3::new(0.3 * s, -0.1 * s, 0.05).into(),
            UnitQuaternion::from_euler_angles(0.2 * s, 0.0, -0.1 * s),
        )
    }

    /// A trail through the solutions `state(s)` at the motion parameters `at` (oldest first),
    /// returning the trail, the last state and the step from the last pose to `pose(next)`.
    fn trail_through(
        state: impl Fn(Real) -> [Real; 2],
        at: &[Real],
        next: Real,
    ) -> (MotionTrail<2>, [Real; 2], [Real; 6]) {
        let mut trail = MotionTrail::default();
        for w in at.windows(2) {
            trail = MotionTrail::extend(&state(w[0]), &trail, pose_step(&pose(w[0]), &pose(w[1]), 1.0));
        }
        let last = *at.last().unwrap();
        (trail, state(last), pose_step(&pose(last), &pose(next), 1.0))
    }

    #[test]
    fn step_ratio_measures_steps_along_a_motion() {
        let step = |a: Real, b: Real| pose_step(&pose(a), &pose(b), 1.0);
        // Uniform steps: 1; a half step: 1/2 (to second order in the step).
        assert!((step_ratio(&step(0.0, 0.1), &step(0.1, 0.2)).unwrap() - 1.0).abs() < 1e-3);
        assert!((step_ratio(&step(0.0, 0.1), &step(0.1, 0.15)).unwrap() - 0.5).abs() < 1e-3);
        // Reversal, a standstill before, and a sideways step: no ratio (the plain warm start).
        assert!(step_ratio(&step(0.0, 0.1), &step(0.1, 0.0)).is_none());
        assert!(step_ratio(&step(0.1, 0.1), &step(0.1, 0.2)).is_none());
        let side = Isometry3::from_parts(Vector3::new(0.03, 0.5, 0.05).into(), pose(0.1).rotation);
        assert!(step_ratio(&step(0.0, 0.1), &pose_step(&pose(0.1), &side, 1.0)).is_none());
    }

    #[test]
    fn predictor_reproduces_polynomial_paths_exactly() {
        // Along a straight motion (pure translation) the step ratios are exact, so a solution that
        // is a cubic in the motion parameter is reproduced by the four-node predictor to rounding,
        // with uneven steps; with three nodes a quadratic, with two a line.
        let line = |s: Real| Isometry3::translation(0.3 * s, -0.1 * s, 0.2 * s);
        let cubic = |s: Real| [1.0 + 2.0 * s - 3.0 * s * s + 5.0 * s * s * s, 0.7 - s * s * s];
        let at = [0.0, 0.1, 0.25, 0.3];
        let mut trail = MotionTrail::default();
        for w in at.windows(2) {
            trail = MotionTrail::extend(&cubic(w[0]), &trail, pose_step(&line(w[0]), &line(w[1]), 1.0));
        }
        let step = pose_step(&line(0.3), &line(0.38), 1.0);
        let p = trail.predict(&cubic(0.3), &step, 2, SIGMA).0;
        let e = cubic(0.38);
        assert!((p[0] - e[0]).abs() < 1e-12 && (p[1] - e[1]).abs() < 1e-12, "{p:?} vs {e:?}");
        // Two nodes (one earlier answer): the secant line through the last two.
        let one = MotionTrail::extend(&cubic(0.25), &MotionTrail::default(), pose_step(&line(0.25), &line(0.3), 1.0));
        let p = one.predict(&cubic(0.3), &step, 2, SIGMA).0;
        let secant = cubic(0.3)[0] + 1.6 * (cubic(0.3)[0] - cubic(0.25)[0]);
        assert!((p[0] - secant).abs() < 1e-12, "{} vs {secant}", p[0]);
    }

    #[test]
    fn predictor_is_third_order_along_a_curved_motion() {
        // A smooth solution along a rotating motion: the cubic predictor's error shrinks like the
        // fourth power of the step (halving the step: 16× smaller; measured 16.3×).
        let state = |s: Real| [(2.0 * s).sin(), (1.0 + s).ln()];
        let err = |h: Real| {
            let (trail, last, step) =
                trail_through(state, &[0.5, 0.5 + h, 0.5 + 2.0 * h, 0.5 + 3.0 * h], 0.5 + 4.0 * h);
            let p = trail.predict(&last, &step, 2, SIGMA).0;
            (p[0] - state(0.5 + 4.0 * h)[0]).abs()
        };
        let (e1, e2) = (err(0.02), err(0.01));
        assert!(e1 < 1e-5 && e2 < e1 / 12.0, "errors {e1:e} at h = 0.02, {e2:e} at h = 0.01");
    }

    #[test]
    fn predictor_falls_back_on_reversals_and_turns() {
        let state = |s: Real| [s, 1.0 + s];
        // Reversal of the motion: the plain warm start (the last solution).
        let (trail, last, step) = trail_through(state, &[0.0, 0.1, 0.2], 0.1);
        assert_eq!(trail.predict(&last, &step, 2, SIGMA), (last, false));
        // A step more than twice the last: the plain warm start.
        let (trail, last, step) = trail_through(state, &[0.0, 0.1, 0.2], 0.5);
        assert_eq!(trail.predict(&last, &step, 2, SIGMA), (last, false));
        // Multipliers stay at or above half their last value.
        let falling = |s: Real| [s, 1.0 - 4.0 * s];
        let (trail, last, step) = trail_through(falling, &[0.0, 0.1, 0.2], 0.35);
        let (p, floored) = trail.predict(&last, &step, 1, SIGMA);
        assert!(floored);
        assert_eq!(p[1], 0.5 * last[1]);
        assert!((p[0] - 0.35).abs() < 1e-3, "{p:?}");
    }
}
