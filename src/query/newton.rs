//! Shared machinery of the Newton / active-set query solvers: statuses, tolerances, the exact
//! boundary search along a segment, and the warm-start predictor ([`MotionTrail`]) that
//! extrapolates earlier answers of a pair along the motion.
//!
//! Both queries are convex programs with one or two smooth convex constraints `g(x) = p'(x) − 1 ≤ 0`
//! (paper §IV-A, §IV-B). The solvers share one strategy:
//!
//! ```text
//! 1. active-set Newton on the KKT system with every constraint active, from a warm start (when
//!    its answer lies within [`WARM_REACH`] of the bodies' size) or a geometric cold start; globalized by a backtracking line search on ‖KKT residual‖ with
//!    stationarity in units of the smaller body's size, so that a run does not depend on the
//!    bodies' size ([`merit_length`]);
//! 2. if that does not converge to a KKT point with positive multipliers, a primal log-barrier
//!    path (always globally convergent on these convex problems, started from the bodies'
//!    interior points), then the active-set Newton polish from the barrier's point.
//! ```
//!
//! A KKT point with nonnegative multipliers of a convex program is its global minimizer, so a
//! converged answer is the answer.

use crate::body::{Body, PosedBody};
use crate::math::{Isometry3, Real, Vector3, NEWTON_KKT_TOLERANCE, NEWTON_MAX_ITERATIONS};
use crate::poly::radial::ray_crossing;
use serde::{Deserialize, Serialize};

/// Coordinates (meters) up to this multiple of the smaller body's size keep a query in A's frame
/// ([`working_frame`]).
const FRAME_SHIFT_RATIO: Real = 1e3;

/// The working frame of a query between body `a` (frame of reference) and body `b` posed by `rel`
/// in A's frame: A's frame moved to the origin `o` (meters, A's frame), the interior point of the
/// smaller body, with both bodies posed in it. Returns (o, A, B).
///
/// Newton's iterates and the bodies' normalized coordinates are then exact to the rounding of
/// coordinates about as large as the bodies and their gap, not of A's frame: a 1 mm body next to
/// a 1 m body whose center lies 1 km from its own frame's origin (a body fitted in site
/// coordinates) has its points at ~10³ m in A's frame, where rounding (10⁻¹³ m) is 10⁻¹⁰ of its
/// size, the KKT tolerance; most such queries ran hundreds of iterations and ended unconverged.
/// A translation keeps A unrotated (its gradients and Hessians scaled, not rotated).
///
/// Where coordinates stay below [`FRAME_SHIFT_RATIO`] times the smaller body's size (bounded by
/// |t_rel|₁ + |c_a|₁ + |c_b|₁, the bodies' centers in their frames) the frame is A's own (o = 0):
/// rounding is then below 10⁻¹³ of either body's size, and the common query skips the shift.
#[inline(always)]
pub(crate) fn working_frame<'a>(a: &'a Body, b: &'a Body, rel: &Isometry3) -> (Vector3, PosedBody<'a>, PosedBody<'a>) {
    let (o, bb) = posed_in_frame(b, rel, frame_origin(a, b, rel));
    (o, PosedBody::translated(a, &-o), bb)
}

/// The length L (meters) by which the Newton runs' line searches measure stationarity: the smaller
/// body's normalization scale.
///
/// A KKT residual mixes stationarity with the constraints p' − 1 (dimensionless): 2(x − y) + λ∇p'
/// in meters for the distance, ∇p₁' + μ∇p₂' in 1/m for the growth measure. Scaling a problem by
/// k scales Newton's iterates by k (Newton's method is invariant under a change of units) but the
/// stationarity residuals by k (distance) or 1/k (growth), so a merit ‖r‖₂ weighs them
/// differently against the constraints at every size. On the chair / human cold poses of
/// `sublevel bench` scaled to 1 cm bodies 1–2.5 cm apart, the distance line search then cut nearly
/// every step to 1/32 to reduce |p' − 1| alone: separated cold queries took 1.7× the Newton
/// iterations of the 1 m problem (3.9× at 1 mm; up to 51 instead of 7 on one pose), and growth
/// queries of 1 km bodies took 1.27× (10 km: 2.3×). Stationarity in units of L (the distance's
/// divided by L, the growth measure's times L) makes the merits, and the runs, the same at every
/// size: 1642 distance iterations at 1 mm, 1 cm and 10 cm against 1657 at 1 m (the convergence
/// tests, unchanged, are absolute and end some runs an iteration early). The bench bodies have
/// scales near 1, where the runs are the unit-length ones'.
#[inline(always)]
pub(crate) fn merit_length(a: &Body, b: &Body) -> Real {
    a.scale().min(b.scale())
}

/// The origin of [`working_frame`] in A's frame: `None` where A's own frame serves (coordinates
/// below [`FRAME_SHIFT_RATIO`] times the smaller body's size), else the smaller body's interior
/// point.
#[inline(always)]
pub(crate) fn frame_origin(a: &Body, b: &Body, rel: &Isometry3) -> Option<Vector3> {
    let reach = rel.translation.vector.abs().sum() + a.center().abs().sum() + b.center().abs().sum();
    if reach <= FRAME_SHIFT_RATIO * a.scale().min(b.scale()) {
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

/// Tolerances of the Newton / active-set solvers.
#[derive(Clone, Copy, Debug)]
pub struct NewtonParams {
    /// Tolerance on the ∞-norm of the KKT residual (objective units per meter for stationarity,
    /// dimensionless for the constraints p' − 1).
    pub kkt_tolerance: Real,
    /// Cap on Newton iterations per phase.
    pub max_iterations: usize,
}

impl Default for NewtonParams {
    fn default() -> Self {
        Self { kkt_tolerance: NEWTON_KKT_TOLERANCE, max_iterations: NEWTON_MAX_ITERATIONS }
    }
}

/// The point where the segment from `inside` (p' < 1) to `outside` (p' > 1) crosses the boundary
/// p' = 1 to machine precision (see [`boundary_on_segment_within`]).
#[cfg(test)]
pub(crate) fn boundary_on_segment(body: &PosedBody<'_>, inside: &Vector3, outside: &Vector3) -> Vector3 {
    boundary_on_segment_within(body, inside, outside, 1e-15)
}

/// Relative tolerance |p' − 1| of the exact boundary points that start a Newton solve where the
/// radial table's estimate is not close enough (near contact).
pub(crate) const START_BOUNDARY_TOLERANCE: Real = 1e-4;

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

/// Whether the bounding spheres of the two posed bodies are disjoint ([`crate::Body::bounding_sphere`];
/// false for a nonconvex body, which has none). Then the bodies are separated, which spares the
/// distance solver's cold start its overlap tests (two evaluations) and, past 2d = 2, its radial
/// points (two table look-ups): on the chair / human cold poses of `sublevel bench`
/// (`examples/cold_profile`, same Newton iteration counts within 0.02) 4.4 % of the instructions
/// of a cold distance query at 2d = 6 and 2.5 / 4 % of its median time at 2d = 6 / 8 (the two
/// builds alternated three times). The test itself is about 90 instructions (the spheres are
/// cached in the body, the centers mapped through the posed bodies' matrices). The growth solver's one evaluation it would spare (p₂ at p₁'s
/// minimizer) costs about what this test does, so it does not ask.
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

/// a · b for 6-vectors, written out (the iterator form compiled to a loop through `Zip`: 4 % of a
/// warm distance query's instructions).
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

/// [`step_ratio`] with ‖d₁‖² given (`n1`), for several steps measured against one d₁.
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
    /// The relative-pose step ([`pose_step`]) from this solution's pose to the next newer one's.
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
/// turns away from d₁ or exceeds 2 d₁.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionTrail<const N: usize> {
    /// The earlier solutions, newest first.
    pub points: [Option<TrailPoint<N>>; TRAIL_LENGTH],
}

/// Iteration cap of a warm-started Newton run: from a predicted start Newton converges in one or
/// two iterations, so a run that needs more than this has lost its way (the active set changed,
/// e.g. a growth constraint turning inactive or bodies starting to overlap) and the cold path is
/// cheaper than pressing on.
pub(crate) const WARM_ITERATIONS: usize = 8;

/// Largest relative-pose step from a warm start's answer, in units of the two bodies' summed
/// scales, at which the warm start is used; past it a query starts cold ([`within_warm_reach`]).
///
/// Measured on the chair / human cold poses of `sublevel bench`, each moved by a random step of
/// relative size s from a converged answer (`examples/cold_profile D 10 steps`): warm and cold
/// queries cost the same near s = 0.5 (2d = 6: distance medians 0.80 / 0.81 µs, means 0.92 / 0.90
/// µs; growth 0.71 / 0.72 µs), the warm start wins below (0.57 / 0.82 µs at s = 0.1) and loses
/// above (1.03 / 0.79 µs at s = 1, 1.31 / 0.72 µs at s = 2: warm runs from far answers fail and
/// the growth measure then starts from a far minimizer); 2d = 4 and 8 likewise. Candidate states
/// of a sampling planner asked in a row without `cold` (each warm-started from the state before)
/// cost 2.8× a cold query without this limit (2.22 against 0.79 µs at 2d = 6,
/// `cold_profile 6 20 chain`).
pub const WARM_REACH: Real = 0.5;

/// Whether a relative-pose step ([`pose_step`]) from a warm start's answer is small enough for
/// the warm start to beat a cold start ([`WARM_REACH`] of `length`, the bodies' summed scales,
/// meters); false for a NaN step.
#[inline(always)]
pub(crate) fn within_warm_reach(step: &[Real; 6], length: Real) -> bool {
    let reach = WARM_REACH * length;
    dot6(step, step) <= reach * reach
}

/// Largest extrapolation σ of a predictor (in units of the last step).
const MAX_EXTRAPOLATION: Real = 2.0;

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

    /// The predicted solution after the relative-pose step `step` from the last solution `last`;
    /// entries from `first_multiplier` on are multipliers, kept at or above half their last value.
    /// The flag says whether a multiplier was raised to that floor (the extrapolation sees it
    /// falling fast: its constraint may be turning inactive).
    #[inline(always)]
    pub(crate) fn predict(&self, last: &[Real; N], step: &[Real; 6], first_multiplier: usize) -> ([Real; N], bool) {
        let Some(p) = &self.points[0] else { return (*last, false) };
        let n1 = dot6(&p.step, &p.step);
        let Some(sigma) = step_ratio_with(&p.step, n1, step).filter(|s| *s <= MAX_EXTRAPOLATION) else {
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
    use crate::math::UnitQuaternion;

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
        let p = trail.predict(&cubic(0.3), &step, 2).0;
        let e = cubic(0.38);
        assert!((p[0] - e[0]).abs() < 1e-12 && (p[1] - e[1]).abs() < 1e-12, "{p:?} vs {e:?}");
        // Two nodes (one earlier answer): the secant line through the last two.
        let one = MotionTrail::extend(&cubic(0.25), &MotionTrail::default(), pose_step(&line(0.25), &line(0.3), 1.0));
        let p = one.predict(&cubic(0.3), &step, 2).0;
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
            let p = trail.predict(&last, &step, 2).0;
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
        assert_eq!(trail.predict(&last, &step, 2), (last, false));
        // A step more than twice the last: the plain warm start.
        let (trail, last, step) = trail_through(state, &[0.0, 0.1, 0.2], 0.5);
        assert_eq!(trail.predict(&last, &step, 2), (last, false));
        // Multipliers stay at or above half their last value.
        let falling = |s: Real| [s, 1.0 - 4.0 * s];
        let (trail, last, step) = trail_through(falling, &[0.0, 0.1, 0.2], 0.35);
        let (p, floored) = trail.predict(&last, &step, 1);
        assert!(floored);
        assert_eq!(p[1], 0.5 * last[1]);
        assert!((p[0] - 0.35).abs() < 1e-3, "{p:?}");
    }
}
