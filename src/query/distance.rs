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
//! extrapolated along the motion ([`MotionTrail`]); the run is capped at 8 iterations and
//! gives up when a multiplier turns nonpositive (the bodies start to touch). Cold: when the segment
//! between the interior points leaves A before it enters B, Newton starts from the boundary points
//! of A towards B and of B towards A read off the bodies' radial tables
//! ([`crate::poly::RadialTable`]), with least-squares multipliers, and a converged answer with
//! positive multipliers needs no overlap test; otherwise (or when that run fails) the growth
//! measure decides overlap and the growth minimizer on B with the exact boundary point of A towards
//! it is the start. A log-barrier path from the two interior points is the globally convergent
//! fallback. A KKT point with λ_a, λ_b > 0 is the global minimizer of this convex program.

use super::fast_eval::{abs_max, max_plain, shifted, solve_kkt8, FastPosed, PosedEval, CHORD_RESIDUAL};
use super::growth::{solve_growth, GrowthStart, GrowthWarmStart};
use super::newton::{
    boundary_on_segment_within, merit_length, pose_step, spheres_apart, within_warm_reach, working_frame, MotionTrail,
    NewtonParams, SolveStatus, START_BOUNDARY_TOLERANCE, WARM_ITERATIONS,
};
use crate::body::{Body, PosedBody};
use crate::math::{Isometry3, Matrix3, Point3, Real, Sym3, Vector3};
use nalgebra::{SMatrix, SVector};

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

/// Solver state carried between queries of one pair, in body frames so it follows the poses.
#[derive(Clone, Copy, Debug)]
pub struct DistanceWarmStart {
    /// Witness on A in A's body frame (meters).
    pub a_local: Vector3,
    /// Witness on B in B's body frame (meters).
    pub b_local: Vector3,
    /// Multipliers (λ_a, λ_b) of the two constraints.
    pub multipliers: [Real; 2],
    /// Whether `a_local`, `b_local`, `multipliers` hold a converged separated answer.
    pub valid: bool,
    /// Warm start of the overlap test d(p_a‖p_b).
    pub growth: GrowthWarmStart,
    /// Relative pose pose_a⁻¹·pose_b at which the witnesses were solved.
    pub relative_pose: Isometry3,
    /// Earlier separated answers of the same pair along the motion: with them the next query
    /// extrapolates along the motion ([`MotionTrail`]) instead of restarting from the last
    /// witnesses. State layout: `[a_local (3), b_local (3), λ_a, λ_b]`.
    pub trail: MotionTrail<8>,
}

impl Default for DistanceWarmStart {
    fn default() -> Self {
        Self {
            a_local: Vector3::zeros(),
            b_local: Vector3::zeros(),
            multipliers: [0.0; 2],
            valid: false,
            growth: GrowthWarmStart::default(),
            relative_pose: Isometry3::identity(),
            trail: MotionTrail::default(),
        }
    }
}

impl DistanceWarmStart {
    fn state(&self) -> [Real; 8] {
        let (a, b, l) = (&self.a_local, &self.b_local, &self.multipliers);
        [a.x, a.y, a.z, b.x, b.y, b.z, l[0], l[1]]
    }

    /// Start (witness on A in A's frame, witness on B in B's frame, multipliers) after the
    /// relative-pose step `step` from this answer: extrapolated along the motion from the earlier
    /// answers ([`MotionTrail::predict`]), else the last answer.
    #[inline(always)]
    fn predict(&self, step: &[Real; 6]) -> (Vector3, Vector3, [Real; 2]) {
        if self.trail.is_empty() {
            return (self.a_local, self.b_local, self.multipliers);
        }
        let s = self.trail.predict(&self.state(), step, 6).0;
        (Vector3::new(s[0], s[1], s[2]), Vector3::new(s[3], s[4], s[5]), [s[6], s[7]])
    }
}

impl DistanceWarmStart {
    /// Whether [`distance()`] between `a` and `b` at relative pose `rel` = pose_a⁻¹·pose_b starts
    /// from this warm start (its separated answer or its overlap test's growth answer) rather
    /// than cold: a warm start whose answer lies more than half the bodies' summed scales away
    /// costs more than a cold start and is not used (`query::newton::WARM_REACH`).
    pub fn reaches(&self, a: &Body, b: &Body, rel: &Isometry3) -> bool {
        let length = a.scale() + b.scale();
        self.separated_step(rel, length).is_some() || self.growth_start(rel, a.scale(), length).is_some()
    }

    /// The relative-pose step ([`pose_step`], rotations weighted by `length`, the bodies' summed
    /// scales) from this warm start's separated answer to `rel`, when that answer is valid and
    /// within [`WARM_REACH`](super::newton::WARM_REACH) of `length`.
    #[inline(always)]
    fn separated_step(&self, rel: &Isometry3, length: Real) -> Option<[Real; 6]> {
        if !self.valid {
            return None;
        }
        let step = pose_step(&self.relative_pose, rel, length);
        within_warm_reach(&step, length).then_some(step)
    }

    /// The overlap test's warm start for a query at `rel` (its growth measure runs at rel⁻¹, A's
    /// scale `a_scale` weighing rotations), when valid and within reach of `length`.
    #[inline(always)]
    fn growth_start(&self, rel: &Isometry3, a_scale: Real, length: Real) -> Option<GrowthStart<'_>> {
        if !self.growth.valid {
            return None;
        }
        Some(self.growth.towards(&rel.inverse(), a_scale)).filter(|s| within_warm_reach(&s.step, length))
    }
}

/// Whether the warm start of a [`distance()`] answer between `a` and `b` at relative pose `from`
/// would be used by a query at relative pose `to` (both pose_a⁻¹·pose_b): the step between them
/// is within half the bodies' summed scales (`query::newton::WARM_REACH`), else the query starts
/// cold. What a request of many candidate states asks to decide which states gain from the
/// state before.
pub fn warm_start_reaches(a: &Body, b: &Body, from: &Isometry3, to: &Isometry3) -> bool {
    let length = a.scale() + b.scale();
    within_warm_reach(&pose_step(from, to, length), length)
}

/// d(p_a‖p_b) − 1 below which a pair whose separated Newton solve fails is answered as touching.
const TOUCH_GROWTH_TOLERANCE: Real = 1e-9;

/// Iteration cap of the speculative cold Newton run from the interior-point segment (the full
/// growth-first path follows when it does not converge).
pub(super) const SPECULATIVE_ITERATIONS: usize = 30;

avx2_dispatch! {
    /// Distance between body `a` posed by `pose_a` and body `b` posed by `pose_b` (paper eq.
    /// "distance").
    ///
    /// `warm` is the `warm_start` of a previous answer for the same ordered pair. Never panics on
    /// valid bodies; the answer says whether it converged.
    pub fn distance, distance_avx2 => distance_body(
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
    let (o, ba, bb) = working_frame(a, b, &rel);
    let mut iterations = 0;

    // The trail of this answer: the last separated answer and its own trail, with the step from it,
    // unless that answer lies more than WARM_REACH of the bodies' size away (a warm start from
    // there costs more than a cold start).
    let length = a.scale() + b.scale();
    let previous = warm.and_then(|w| Some((w, w.separated_step(&rel, length)?)));
    if let Some((w, step)) = &previous {
        let (a0, b0, lam0) = w.predict(step);
        let y0 = bb.to_world(&b0);
        let capped = NewtonParams { max_iterations: params.max_iterations.min(WARM_ITERATIONS), ..*params };
        let out = kkt_newton(&ba, &bb, a0 - o, y0, Some(lam0), &capped, true);
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
    let growth_start = warm.and_then(|w| w.growth_start(&rel, a.scale(), length));
    if growth_start.is_none() {
        if let Some((x0, y0)) = cold_start(&ba, &bb) {
            let capped = NewtonParams { max_iterations: params.max_iterations.min(SPECULATIVE_ITERATIONS), ..*params };
            let out = kkt_newton(&ba, &bb, x0, y0, None, &capped, false);
            iterations += out.iterations;
            if out.status.converged() && clear_of_contact(&out.x, &out.y, a, b) {
                return finish(pose_a, &rel, out.moved(&o), iterations, false, &GrowthWarmStart::default(), previous);
            }
        }
    }

    growth_first(pose_a, &rel, &o, &ba, &bb, growth_start, previous, params, iterations)
}

/// The answer for overlapping (or touching) bodies: distance 0, both witnesses at the growth
/// minimizer `p` (world, meters), no normal; the growth solve's `status`, `iterations` and final
/// ∞-norm KKT `residual`, with the warm start it keeps.
pub(super) fn overlapping_answer(
    p: Point3,
    status: SolveStatus,
    iterations: usize,
    residual: Real,
    warm_started: bool,
    warm_start: std::sync::Arc<DistanceWarmStart>,
) -> DistanceResult {
    DistanceResult {
        distance: 0.0,
        witness_a: p,
        witness_b: p,
        normal: Vector3::zeros(),
        overlapping: true,
        status,
        iterations,
        kkt_residual: residual,
        warm_started,
        warm_start,
    }
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
    let (o, ba, bb) = working_frame(a, b, &rel);
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
    let x0 = boundary_on_segment_within(ba, &ba.interior_point(), &y0, START_BOUNDARY_TOLERANCE);
    let out = kkt_newton(ba, bb, x0, y0, None, params, false);
    iterations += out.iterations;
    if out.status.converged() {
        return finish(pose_a, rel, out.moved(o), iterations, false, &growth_warm, previous);
    }
    // Touching within the growth solve's tolerance: at exact tangency the separated KKT system is
    // degenerate (x = y, λ → 0), so Newton cannot converge there; the growth answer is the
    // touching point (the distance is below ~TOUCH_GROWTH_TOLERANCE × the bodies' size).
    if g.status.converged() && g.value <= 1.0 + TOUCH_GROWTH_TOLERANCE {
        return touching(iterations);
    }
    let (xb, yb, lamb, it_b) = barrier(ba, bb, params);
    iterations += it_b;
    let out = kkt_newton(ba, bb, xb, yb, Some(lamb), params, false);
    iterations += out.iterations;
    finish(pose_a, rel, out.moved(o), iterations, false, &growth_warm, previous)
}

/// The cold start of the speculative separated Newton run, in the frame of `ba`: when the bounding
/// spheres are disjoint (and neither body is an ellipsoid), the support points towards each other,
/// refined once towards the optimal normal ([`bisector_start`]); otherwise, when the segment
/// between the interior points shows separation, the closer of the
/// support and the segment's boundary points ([`segment_start`]); `None` when neither shows
/// separation (the growth measure decides).
///
/// Past 2d = 2 the support points alone start as well as the closer of them and the segment's
/// points (5.88 vs 5.90 Newton iterations at 2d = 6, 6.03 vs 6.05 at 2d = 8) and spare two radial
/// look-ups; an ellipsoid keeps the comparison (exact for spheres).
///
/// Inlined, with its look-ups, into each build of [`distance()`]: out of line it was compiled for
/// the baseline x86-64 target (SSE2, no FMA) even inside the AVX2 build, a call per look-up. The
/// same arithmetic, so the same starts to the bit; on the bench's cold poses 2.8 % fewer
/// instructions per cold distance query at 2d = 6 and 0.93× the time (`perf` had put 7 % of the
/// time in the out-of-line support look-ups, 1.9 % of the instructions).
#[inline(always)]
pub(super) fn cold_start(ba: &PosedBody<'_>, bb: &PosedBody<'_>) -> Option<(Vector3, Vector3)> {
    let (ca, cb) = (ba.interior_point(), bb.interior_point());
    let apart = spheres_apart(ba, bb);
    let quadric = ba.body.degree() <= 2 || bb.body.degree() <= 2;
    let axis = cb - ca;
    match (apart && !quadric).then(|| supports_towards(ba, bb, &axis)).flatten() {
        Some(start) => Some(bisector_start(ba, bb, start, &axis)),
        None => segment_start(ba, bb, &ca, &cb, apart),
    }
}

/// A point common to the two posed bodies (world coordinates, meters), found without a solve on
/// the segment between their interior points: A's interior point when it lies in B, B's when it
/// lies in A, else the middle of the stretch where the bodies' radial tables put the segment
/// inside both. Every candidate is checked by evaluating both polynomials (p_a'(z) ≤ 1 and
/// p_b'(z) ≤ 1), so a returned point proves that the bodies overlap (distance 0); `None` proves
/// nothing, and a solver decides. Costs at most four value evaluations and two radial look-ups.
///
/// The overlap certificate of a collide query whose cheap lower bounds do not clear it
/// ([`crate::scene::planner::collide_cheap`]): the overlapping pairs are the costliest ones of a
/// cold distance solve (a separated run that fails, then the growth measure; paper §IV-A, eq.
/// "distance"), and an overlap shows no separating axis, so only a common point decides them
/// cheaply.
pub fn segment_common_point(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Point3> {
    let (ba, bb) = (PosedBody::new(a, pose_a), PosedBody::new(b, pose_b));
    let (fa, fb) = (FastPosed::new(&ba), FastPosed::new(&bb));
    let inside_both = |z: &Vector3| fa.value(z) <= 1.0 && fb.value(z) <= 1.0;
    segment_candidates(&ba, &bb, &inside_both).map(Point3::from)
}

/// [`segment_common_point`]'s candidates (world coordinates) checked by `inside_both`.
fn segment_candidates(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    inside_both: &impl Fn(&Vector3) -> bool,
) -> Option<Vector3> {
    let (ca, cb) = (ba.interior_point(), bb.interior_point());
    if let Some(z) = [ca, cb].into_iter().find(inside_both) {
        return Some(z);
    }
    // The segment meets A on about [ca, x0] and B on about [y0, cb]: when B's crossing comes
    // first, the two stretches overlap around their middle.
    let (x0, y0) = (ba.boundary_towards(&cb), bb.boundary_towards(&ca));
    let z = (x0 + y0) * 0.5;
    ((y0 - ca).norm_squared() < (x0 - ca).norm_squared() && inside_both(&z)).then_some(z)
}

/// A point common to the two posed bodies (world coordinates, meters), found without a solve:
/// [`segment_common_point`]'s candidates on the segment between the interior points, then the
/// bodies' support points facing each other along that segment — A's towards B, B's towards A
/// (read off their support tables, [`PosedBody::support`]) — and the middle between them. Every
/// candidate is checked by evaluating both polynomials, so a returned point proves overlap
/// (distance 0); `None` proves nothing. Costs at most ten value evaluations and four table
/// look-ups.
///
/// Where bodies overlap off the segment between their interior points (elongated or bent shapes
/// meeting at an angle), the facing support points often lie in the other body: on the 300 cold
/// chair_101 / human_10 poses of `sublevel bench`, of the overlapping pairs the segment misses
/// (19 / 13 / 10 / 11 of 38 / 26 / 22 / 21 at 2d = 2 / 4 / 6 / 8) they prove 17 / 11 / 6 / 7, each
/// of which a collide query would otherwise solve (a failed separated run and the growth measure,
/// the costliest cold solves).
pub fn common_point(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Point3> {
    let (ba, bb) = (PosedBody::new(a, pose_a), PosedBody::new(b, pose_b));
    let (fa, fb) = (FastPosed::new(&ba), FastPosed::new(&bb));
    let inside_both = |z: &Vector3| fa.value(z) <= 1.0 && fb.value(z) <= 1.0;
    if let Some(z) = segment_candidates(&ba, &bb, &inside_both) {
        return Some(Point3::from(z));
    }
    let axis = bb.interior_point() - ba.interior_point();
    let (x, y) = (ba.support(&axis)?, bb.support(&-axis)?);
    [x, y, (x + y) * 0.5].into_iter().find(inside_both).map(Point3::from)
}

/// Whether a converged separated KKT point (x, y) is clear of contact: ‖y − x‖ above 10⁻⁶ of the
/// bodies' sizes. Near contact (x ≈ y) the multipliers lose meaning and the growth test decides.
#[inline]
pub(super) fn clear_of_contact(x: &Vector3, y: &Vector3, a: &Body, b: &Body) -> bool {
    (y - x).norm() > 1e-6 * (a.scale() + b.scale())
}

/// The answer of a converged (or last) separated KKT point `out` in the relative frame `rel`, with
/// its warm start: the trail of `previous` (the last answer and the relative-pose step from it)
/// extended by that answer (built only here, where it is kept).
#[inline(always)]
pub(super) fn finish(
    pose_a: &Isometry3,
    rel: &Isometry3,
    out: KktOut,
    iterations: usize,
    warm_started: bool,
    growth: &GrowthWarmStart,
    previous: Option<(&DistanceWarmStart, [Real; 6])>,
) -> DistanceResult {
    let b_local = rel.inverse_transform_point(&Point3::from(out.y));
    let valid = out.status.converged();
    let trail = match previous {
        Some((w, step)) if valid => MotionTrail::extend(&w.state(), &w.trail, step),
        _ => MotionTrail::default(),
    };
    let warm_start = std::sync::Arc::new(DistanceWarmStart {
        a_local: out.x,
        b_local: b_local.coords,
        multipliers: out.lam,
        valid,
        growth: *growth,
        relative_pose: *rel,
        trail,
    });
    separated_answer(pose_a, &out, iterations, warm_started, warm_start)
}

/// The answer of a separated KKT point `out` (frame of body A, posed by `pose_a`) with the given
/// warm start.
#[inline(always)]
pub(super) fn separated_answer(
    pose_a: &Isometry3,
    out: &KktOut,
    iterations: usize,
    warm_started: bool,
    warm_start: std::sync::Arc<DistanceWarmStart>,
) -> DistanceResult {
    let diff = out.y - out.x;
    let dist = diff.norm();
    // One rotation matrix for the three world vectors (a quaternion rotation costs twice a product).
    let r = pose_a.rotation.to_rotation_matrix();
    let t = pose_a.translation.vector;
    let normal = if dist > 0.0 { r * (diff / dist) } else { Vector3::zeros() };
    DistanceResult {
        distance: dist,
        witness_a: Point3::from(r * out.x + t),
        witness_b: Point3::from(r * out.y + t),
        normal,
        overlapping: false,
        status: out.status,
        iterations,
        kkt_residual: out.residual,
        warm_started,
        warm_start,
    }
}

/// The support points h_A(n) and h_B(−n) for n = `axis` ([`PosedBody::support`]), when both
/// bodies have them.
#[inline(always)]
fn supports_towards(ba: &PosedBody<'_>, bb: &PosedBody<'_>, axis: &Vector3) -> Option<(Vector3, Vector3)> {
    Some((ba.support(axis)?, bb.support(&-axis)?))
}

/// One refinement of the facing support points `start` = (h_A(n), h_B(−n)) for n = `axis`: the
/// support points for the bisector of n and the direction y − x between them, kept when they are
/// closer to each other (the optimal normal makes y − x parallel to n; the bisector damps the
/// fixed-point step n ← y − x, which overshoots on the interpolated support map).
///
/// Measured on the chair / human cold poses of `sublevel bench` (`examples/cold_profile`,
/// callgrind): 5.20 instead of 5.68 Newton iterations per separated cold distance query at 2d = 6
/// (5.36 vs 5.87 at 2d = 8, 4.95 vs 5.44 at 2d = 4) and 2.8 % (3.7 %) fewer instructions per
/// query. The step n ← y − x itself saves 0.07 iterations; a second bisector round 0.15 more at
/// equal instructions; more rounds nothing (table points at the exact optimal normal take 4.97
/// iterations: past one round the table's interpolation, not the direction, limits the start).
#[inline(always)]
fn bisector_start(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    start: (Vector3, Vector3),
    axis: &Vector3,
) -> (Vector3, Vector3) {
    let d = start.1 - start.0;
    let n = d / d.norm() + axis / axis.norm();
    match supports_towards(ba, bb, &n) {
        Some(s) if (s.1 - s.0).norm_squared() < d.norm_squared() => s,
        _ => start,
    }
}

/// The cold start of a pair shown separated — by disjoint bounding spheres (`apart`), else by the
/// segment between its interior points `ca`, `cb` (each outside the other body, and A's boundary
/// crossing before B's) — through [`support_start`]; `None` when neither shows it.
#[inline(always)]
fn segment_start(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    ca: &Vector3,
    cb: &Vector3,
    apart: bool,
) -> Option<(Vector3, Vector3)> {
    if !apart {
        let (fa, fb) = (FastPosed::new(ba), FastPosed::new(bb));
        if !(fb.value(ca) > 1.0 && fa.value(cb) > 1.0) {
            return None;
        }
    }
    let x0 = ba.boundary_towards(cb);
    let y0 = bb.boundary_towards(ca);
    // With disjoint spheres A's crossing comes first (each lies in its own sphere).
    (apart || (x0 - ca).norm_squared() < (y0 - ca).norm_squared()).then(|| support_start(ba, bb, x0, y0, &(cb - ca)))
}

/// The cold start of a pair separated along the segment between its interior points: the support
/// points x = h_A(n), y = h_B(−n) for n = `axis` (the direction from A's interior point to B's),
/// read off the bodies' support tables ([`PosedBody::support`]), when they are closer to each other
/// than the radial start (`x0`, `y0`), else the radial start.
///
/// Measured on the chair / human cold poses of `sublevel bench` (2d = 6, 278 separated of 300):
/// 6.21 Newton iterations per separated query against 7.21 from the radial start; further
/// alternations n ← y − x made it worse (10.4 iterations after 2 or 3 rounds: the interpolated
/// support map overshoots), so there is one look-up per body.
///
/// The table, not only the direction, limits this start (measured on the same poses): table
/// points at the exact optimal normal still take 4.97 iterations at 2d = 6 (4.67 at 2d = 4, 5.47
/// at 2d = 8), 4.36 with a 16-cell grid, whose look-ups at the center direction take 5.92 (no
/// gain); a safeguarded Newton ascent of the dual n·(y(n) − x(n)) on the tables (finite-difference
/// support-map derivatives, 3 rounds, 16-cell grid) reached 5.13 iterations but cost 25 % more
/// instructions per query (6 look-ups of ~200 instructions a round, more failed runs).
#[inline(always)]
fn support_start(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    x0: Vector3,
    y0: Vector3,
    axis: &Vector3,
) -> (Vector3, Vector3) {
    match (ba.support(axis), bb.support(&-axis)) {
        // Both starts are (nearly) feasible pairs: keep the closer one (the radial start is exact
        // for spheres, whose witnesses lie on the line of centers).
        (Some(x), Some(y)) if (y - x).norm_squared() < (y0 - x0).norm_squared() => (x, y),
        _ => (x0, y0),
    }
}

/// Least-squares multipliers of `2(x − y) + λ_a ∇p_a' = 0`, `−2(x − y) + λ_b ∇p_b' = 0` for the
/// gradients `ga` at x and `gb` at y, clamped positive.
#[inline(always)]
fn initial_multipliers(ga: &Vector3, gb: &Vector3, x: &Vector3, y: &Vector3) -> [Real; 2] {
    let d = y - x;
    let la = 2.0 * d.dot(ga) / ga.norm_squared().max(Real::MIN_POSITIVE);
    let lb = -2.0 * d.dot(gb) / gb.norm_squared().max(Real::MIN_POSITIVE);
    let fix = |l: Real, g: &Vector3| if l.is_finite() && l > 0.0 { l } else { 2.0 * d.norm() / g.norm().max(1e-300) };
    [fix(la, ga), fix(lb, gb)]
}

/// The end of a separated Newton run: the last point (frame of body A), its multipliers, how the
/// run ended, its Newton steps and the final ∞-norm of the KKT residual.
pub(super) struct KktOut {
    pub(super) x: Vector3,
    pub(super) y: Vector3,
    pub(super) lam: [Real; 2],
    pub(super) status: SolveStatus,
    pub(super) iterations: usize,
    pub(super) residual: Real,
}

impl KktOut {
    /// The run's points moved by `o` (meters): from a query's working frame back to A's frame
    /// ([`working_frame`](super::newton::working_frame)).
    #[inline(always)]
    pub(super) fn moved(mut self, o: &Vector3) -> Self {
        self.x += o;
        self.y += o;
        self
    }
}

type Vec8 = SVector<Real, 8>;
type Mat8 = SMatrix<Real, 8, 8>;

/// Value, gradient and residual of the KKT system at one iterate, with the Hessians when they were
/// evaluated (one pass per body either way).
struct KktPoint {
    ea: PosedEval,
    eb: PosedEval,
    ra: Vector3,
    rb: Vector3,
    ca: Real,
    cb: Real,
}

impl KktPoint {
    #[inline(always)]
    fn new<const FMA: bool>(
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
    fn set_multipliers(&mut self, x: &Vector3, y: &Vector3, lam: [Real; 2]) {
        let d = (x - y) * 2.0;
        self.ra = d + self.ea.gradient * lam[0];
        self.rb = -d + self.eb.gradient * lam[1];
    }

    #[inline(always)]
    fn norm_inf(&self) -> Real {
        max_plain(max_plain(abs_max(&self.ra), abs_max(&self.rb)), max_plain(self.ca.abs(), self.cb.abs()))
    }

    /// The line search's merit ‖(r_a/L, r_b/L, p_a' − 1, p_b' − 1)‖₂ for `w2` = 1/L²
    /// ([`merit_length`]): stationarity in units of L, so that it weighs the same against the
    /// (dimensionless) constraints whatever the bodies' size. NaN or infinite with any residual.
    #[inline(always)]
    fn merit(&self, w2: Real) -> Real {
        ((self.ra.norm_squared() + self.rb.norm_squared()) * w2 + self.ca * self.ca + self.cb * self.cb).sqrt()
    }
}

/// The Newton step for the Hessians `(ha, hb)` at `pt`: closed-form block elimination, dense LU if
/// that is singular.
#[inline(always)]
fn newton_step<const FMA: bool>(
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

avx2_dispatch! {
    /// Active-set Newton on the 8 × 8 KKT system from (x0, y0) and the multipliers `lam0` (least
    /// squares at the start when `None`), globalized by backtracking on the scale-free merit
    /// ‖(r_a/L, r_b/L, p_a' − 1, p_b' − 1)‖₂ ([`merit_length`]); a `warm` run gives up
    /// (Stalled) when a multiplier turns nonpositive. Every point is evaluated once; near the
    /// solution (residual below [`CHORD_RESIDUAL`]) trial points skip the Hessians and a further
    /// step reuses the last ones (chord step), refreshed when it stalls.
    fn kkt_newton, kkt_newton_avx2 => kkt_newton_body(
        ba: &PosedBody<'_>, bb: &PosedBody<'_>, x0: Vector3, y0: Vector3, lam0: Option<[Real; 2]>,
        params: &NewtonParams, warm: bool,
    ) -> KktOut
}

/// The body of [`kkt_newton`], inlined into each of its builds.
#[inline(always)]
fn kkt_newton_body<const FMA: bool>(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    x0: Vector3,
    y0: Vector3,
    lam0: Option<[Real; 2]>,
    params: &NewtonParams,
    warm: bool,
) -> KktOut {
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
    while it < params.max_iterations {
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
        let cheap = r0 <= CHORD_RESIDUAL * merit_scale(&x, &y);
        let mut alpha = 1.0;
        let mut accepted = false;
        // The trial points are evaluated into `pt` itself (its Hessians are in `hess` already):
        // no copy of the accepted point. A rejected line search re-evaluates the current point.
        for _ in 0..40 {
            let (xt, yt) = (x + dx * alpha, y + dy * alpha);
            let lt = [lam[0] + dl[0] * alpha, lam[1] + dl[1] * alpha];
            pt = KktPoint::new(&fa, &fb, &xt, &yt, lt, !cheap);
            let r1 = pt.merit(w2);
            // A chord step must at least halve the residual; otherwise refresh the Hessians here.
            let bound = if fresh { (1.0 - 1e-4 * alpha) * r0 } else { 0.5 * r0 };
            if r1.is_finite() && r1 <= bound {
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

/// Log-barrier path `min ‖x − y‖² − t(log(1 − p_a') + log(1 − p_b'))` from the interior points,
/// t → 0; returns the final points, multiplier estimates t/(1 − p') and the iterations spent.
fn barrier(ba: &PosedBody<'_>, bb: &PosedBody<'_>, params: &NewtonParams) -> (Vector3, Vector3, [Real; 2], usize) {
    let mut x = ba.interior_point();
    let mut y = bb.interior_point();
    let f0 = (x - y).norm_squared();
    let mut t = f0.max(1e-12);
    let mut it = 0;
    let max_it = params.max_iterations * 4;
    let phi = |x: &Vector3, y: &Vector3, t: Real| -> Option<Real> {
        let (ga, gb) = (1.0 - ba.value(x), 1.0 - bb.value(y));
        (ga > 0.0 && gb > 0.0).then(|| (x - y).norm_squared() - t * (ga.ln() + gb.ln()))
    };
    'outer: while it < max_it {
        loop {
            if it >= max_it {
                break 'outer;
            }
            let (ea, eb) = (ba.eval(&x), bb.eval(&y));
            let (sa, sb) = (1.0 - ea.value, 1.0 - eb.value);
            let d = x - y;
            let ga = d * 2.0 + ea.gradient * (t / sa);
            let gb = -d * 2.0 + eb.gradient * (t / sb);
            let two = nalgebra::Matrix3::<Real>::identity() * 2.0;
            let haa = two + ea.hessian * (t / sa) + ea.gradient * ea.gradient.transpose() * (t / (sa * sa));
            let hbb = two + eb.hessian * (t / sb) + eb.gradient * eb.gradient.transpose() * (t / (sb * sb));
            let mut h = SMatrix::<Real, 6, 6>::zeros();
            h.fixed_view_mut::<3, 3>(0, 0).copy_from(&haa);
            h.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-two));
            h.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-two));
            h.fixed_view_mut::<3, 3>(3, 3).copy_from(&hbb);
            let g = SVector::<Real, 6>::from_column_slice(&[ga.x, ga.y, ga.z, gb.x, gb.y, gb.z]);
            let Some(chol) = nalgebra::Cholesky::new(h) else { break 'outer };
            let step = -chol.solve(&g);
            let dec = -g.dot(&step);
            it += 1;
            if dec <= 1e-3 * t {
                break;
            }
            let Some(phi0) = phi(&x, &y, t) else { break 'outer };
            let (dx, dy) = (Vector3::new(step[0], step[1], step[2]), Vector3::new(step[3], step[4], step[5]));
            let mut alpha = 1.0;
            loop {
                let (xt, yt) = (x + dx * alpha, y + dy * alpha);
                if let Some(p) = phi(&xt, &yt, t) {
                    if p <= phi0 - 0.25 * alpha * dec {
                        (x, y) = (xt, yt);
                        break;
                    }
                }
                alpha *= 0.5;
                if alpha < 1e-12 {
                    break 'outer;
                }
            }
        }
        if t < 1e-12 * (1.0 + (x - y).norm_squared()) {
            break;
        }
        t *= 0.1;
    }
    let sa = (1.0 - ba.value(&x)).max(Real::MIN_POSITIVE);
    let sb = (1.0 - bb.value(&y)).max(Real::MIN_POSITIVE);
    (x, y, [t / sa, t / sb], it)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::ellipsoid;
    use crate::math::{pose_from_parts, UnitQuaternion};
    use rand::{Rng, SeedableRng};

    #[test]
    fn common_points_prove_overlap_and_only_overlap() {
        // Spheres of radii 0.5 and 0.3 (centers 0.1 off their frames' origins) at center distances
        // from 0 to 1.2 m along a tilted line: they overlap below 0.8 m. A common point is returned
        // only for overlapping ones, and lies in both (closed-form membership, 1e-12); nested or
        // deeply overlapping ones always get one (the segment between the centers meets both).
        let (a, b) = (ellipsoid([0.1, 0.0, 0.0], [0.5; 3]).unwrap(), ellipsoid([0.0, -0.1, 0.0], [0.3; 3]).unwrap());
        let pose_a = pose_from_parts("a", [0.8, 0.0, 0.6, 0.0], [1.0, -2.0, 0.5]).unwrap();
        let center_a = pose_a * Point3::new(0.1, 0.0, 0.0);
        let dir = Vector3::new(0.6, 0.0, 0.8);
        let mut found = 0;
        for k in 0..=60 {
            let gap = 0.02 * k as Real;
            let pose_b = pose_from_parts("b", [0.6, 0.8, 0.0, 0.0], [0.0; 3]).unwrap();
            // Place B's center at center_a + gap · dir.
            let offset = center_a.coords + dir * gap - pose_b.rotation * Vector3::new(0.0, -0.1, 0.0);
            let pose_b = Isometry3::from_parts(offset.into(), pose_b.rotation);
            let center_b = pose_b * Point3::new(0.0, -0.1, 0.0);
            let z = segment_common_point(&a, &pose_a, &b, &pose_b);
            if gap >= 0.8 {
                assert!(z.is_none(), "gap {gap}: no common point for separated spheres, got {z:?}");
                continue;
            }
            let z = z.unwrap_or_else(|| panic!("gap {gap}: overlapping spheres need a common point"));
            assert!((z - center_a).norm() <= 0.5 + 1e-12 && (z - center_b).norm() <= 0.3 + 1e-12, "gap {gap}: {z:?}");
            found += 1;
        }
        assert_eq!(found, 40);
    }

    #[test]
    fn facing_support_points_prove_overlap_off_the_segment() {
        // Two thin ellipsoids meeting at a corner (A along x, radii 1, 0.1, 0.1 at the origin; B
        // along y, radii 0.1, 1, 0.1 at (0.95, 0.95, 0)): they overlap around (0.95, 0, 0), but
        // the segment between their centers leaves A at t ≈ 0.1 and enters B at t ≈ 0.9, so only
        // the facing support points find a common point (their middle, (0.967, −0.018, 0) in
        // closed form, lies in both with p ≈ 0.97).
        let a = ellipsoid([0.0; 3], [1.0, 0.1, 0.1]).unwrap();
        let b = ellipsoid([0.95, 0.95, 0.0], [0.1, 1.0, 0.1]).unwrap();
        let id = Isometry3::identity();
        // Closed-form membership of a world point in both.
        let inside = |z: &Point3| {
            let pa = z.x * z.x + (z.y / 0.1).powi(2) + (z.z / 0.1).powi(2);
            let pb = ((z.x - 0.95) / 0.1).powi(2) + (z.y - 0.95).powi(2) + (z.z / 0.1).powi(2);
            pa <= 1.0 + 1e-12 && pb <= 1.0 + 1e-12
        };
        assert!(distance(&a, &id, &b, &id, None, &NewtonParams::default()).overlapping);
        assert_eq!(segment_common_point(&a, &id, &b, &id), None);
        let z = common_point(&a, &id, &b, &id).expect("the facing support points meet");
        assert!(inside(&z), "{z:?}");
        // Over random poses of a thin rod (radii 0.1, 1, 0.1, centered in its frame) within 0.8 m of
        // A's center, a common point is returned only where the distance solver finds overlap, and
        // always lies in both (closed form); it finds more overlaps than the segment alone.
        let rod = ellipsoid([0.0; 3], [0.1, 1.0, 0.1]).unwrap();
        let in_both = |z: &Point3, pose: &Isometry3| {
            let w = pose.inverse_transform_point(z);
            let pa = z.x * z.x + (z.y / 0.1).powi(2) + (z.z / 0.1).powi(2);
            pa <= 1.0 + 1e-12 && (w.x / 0.1).powi(2) + w.y * w.y + (w.z / 0.1).powi(2) <= 1.0 + 1e-12
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let (mut overlapping, mut found, mut on_segment) = (0, 0, 0);
        for _ in 0..400 {
            let t = Vector3::from_fn(|_, _| rng.random_range(-0.8..0.8));
            let q = nalgebra::Quaternion::from(nalgebra::Vector4::from_fn(|_, _| rng.random_range(-1.0..1.0)));
            let pose = Isometry3::from_parts(t.into(), UnitQuaternion::new_normalize(q));
            let d = distance(&a, &id, &rod, &pose, None, &NewtonParams::default());
            overlapping += usize::from(d.overlapping);
            let segment = segment_common_point(&a, &id, &rod, &pose);
            on_segment += usize::from(segment.is_some());
            match common_point(&a, &id, &rod, &pose) {
                Some(z) => {
                    found += 1;
                    assert!(d.overlapping && in_both(&z, &pose), "{z:?} at {pose:?}");
                }
                None => assert!(segment.is_none()),
            }
        }
        // Thin rods crossing like an X often share no candidate point (a solve decides those).
        assert!(
            overlapping > 40 && found > on_segment,
            "{found} ({on_segment} on the segment) of {overlapping} overlaps"
        );
    }

    #[test]
    fn spheres_match_closed_form_along_a_motion() {
        let s1 = ellipsoid([0.1, 0.0, 0.0], [0.5; 3]).unwrap();
        let s2 = ellipsoid([0.0; 3], [0.8; 3]).unwrap();
        let pose_a = pose_from_parts("a", [0.8, 0.6, 0.0, 0.0], [10.0, -3.0, 2.0]).unwrap();
        let center_a = pose_a * Point3::new(0.1, 0.0, 0.0);
        let mut warm: Option<DistanceWarmStart> = None;
        let (mut cold_it, mut warm_it) = (0, 0);
        for k in 0..60 {
            let c2 = center_a.coords + Vector3::new(3.0 - 0.05 * k as Real, 0.3, -0.2);
            let pose_b = pose_from_parts("b", [0.6, 0.0, 0.8, 0.0], [c2.x, c2.y, c2.z]).unwrap();
            let expected = ((c2 - center_a.coords).norm() - 1.3).max(0.0);
            let r = distance(&s1, &pose_a, &s2, &pose_b, warm.as_ref(), &NewtonParams::default());
            let c = distance(&s1, &pose_a, &s2, &pose_b, None, &NewtonParams::default());
            for res in [&r, &c] {
                assert!(res.status.converged(), "k = {k}: {res:?}");
                assert!((res.distance - expected).abs() < 1e-9, "k = {k}: {} vs {expected}", res.distance);
                assert_eq!(res.overlapping, expected == 0.0);
            }
            if expected > 0.0 {
                // Witnesses lie on the surfaces along the line of centers.
                assert!(((r.witness_a - center_a).norm() - 0.5).abs() < 1e-8);
                assert!(((r.witness_b.coords - c2).norm() - 0.8).abs() < 1e-8);
                let n = (c2 - center_a.coords).normalize();
                assert!((r.normal - n).norm() < 1e-8);
                if k > 0 {
                    cold_it += c.iterations;
                    warm_it += r.iterations;
                }
            }
            warm = Some(*r.warm_start);
        }
        // Spheres: the cold start on the line of centers is already optimal.
        assert_eq!(cold_it, 0);
        assert!(warm_it > 0);
    }

    #[test]
    fn warm_starts_save_iterations_on_ellipsoids() {
        let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
        let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
        let mut warm: Option<DistanceWarmStart> = None;
        let (mut cold_it, mut warm_it) = (0, 0);
        for k in 0..30 {
            let (s, c) = (0.01 * k as Real).sin_cos();
            let pose_b = pose_from_parts("b", [c, 0.0, s, 0.0], [2.5 - 0.03 * k as Real, 0.4, 0.1]).unwrap();
            let w = distance(&e1, &Isometry3::identity(), &e2, &pose_b, warm.as_ref(), &NewtonParams::default());
            let cold = distance(&e1, &Isometry3::identity(), &e2, &pose_b, None, &NewtonParams::default());
            assert!(w.status.converged() && cold.status.converged());
            assert!((w.distance - cold.distance).abs() < 1e-9);
            // Witnesses on the surfaces and the normal along the witness segment.
            assert!((e1.value_at(&w.witness_a) - 1.0).abs() < 1e-9);
            assert!((e2.value_at(&(pose_b.inverse() * w.witness_b)) - 1.0).abs() < 1e-9);
            if k > 0 {
                assert!(w.warm_started);
                cold_it += cold.iterations;
                warm_it += w.iterations;
            }
            warm = Some(*w.warm_start);
        }
        assert!(warm_it < cold_it, "warm {warm_it} vs cold {cold_it}");
    }

    /// A warm start whose answer lies past `WARM_REACH` (half the bodies' summed scales, here
    /// 0.5 · (0.9 + 1.0) = 0.95 m) is not used: distance and growth then run exactly as cold (the
    /// same answer to the bit, the same iterations, not warm-started; before, warm starts from
    /// random poses cost 2.8× a cold query: `examples/cold_profile 6 20 chain`); one 5 cm away is used
    /// and agrees with the cold answer to 10⁻⁹. `DistanceWarmStart::reaches` and
    /// `warm_start_reaches` say the same.
    #[test]
    fn warm_starts_past_their_reach_are_not_used() {
        use crate::query::growth::growth;
        let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
        let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
        let (id, params) = (Isometry3::identity(), NewtonParams::default());
        let p0 = pose_from_parts("b", [1.0, 0.0, 0.0, 0.0], [2.5, 0.4, 0.1]).unwrap();
        let (s, c) = (0.01 as Real).sin_cos();
        let near = pose_from_parts("b", [c, s, 0.0, 0.0], [2.46, 0.42, 0.1]).unwrap();
        let far = pose_from_parts("b", [0.8, 0.0, 0.6, 0.0], [-1.5, 1.2, 0.3]).unwrap();
        let d0 = distance(&e1, &id, &e2, &p0, None, &params);
        let g0 = growth(&e1, &id, &e2, &p0, None, &params);
        for (pose, used) in [(near, true), (far, false)] {
            let (w, c) = (
                distance(&e1, &id, &e2, &pose, Some(&d0.warm_start), &params),
                distance(&e1, &id, &e2, &pose, None, &params),
            );
            assert!(w.status.converged() && c.status.converged());
            assert_eq!((w.warm_started, d0.warm_start.reaches(&e1, &e2, &pose)), (used, used));
            assert_eq!(warm_start_reaches(&e1, &e2, &p0, &pose), used);
            let (gw, gc) = (
                growth(&e1, &id, &e2, &pose, Some(&g0.warm_start), &params),
                growth(&e1, &id, &e2, &pose, None, &params),
            );
            assert_eq!(gw.warm_started, used);
            if used {
                assert!((w.distance - c.distance).abs() < 1e-9 && (gw.value - gc.value).abs() < 1e-9 * gc.value);
            } else {
                assert_eq!((w.distance.to_bits(), w.iterations), (c.distance.to_bits(), c.iterations));
                assert_eq!((gw.value.to_bits(), gw.iterations), (gc.value.to_bits(), gc.iterations));
            }
        }
    }

    #[test]
    fn elongated_ellipsoids_against_brute_force() {
        // Two needles crossing at right angles, 0.3 apart along z: distance 0.3 − 2·0.05 = 0.2.
        let n1 = ellipsoid([0.0; 3], [2.0, 0.05, 0.05]).unwrap();
        let n2 = ellipsoid([0.0; 3], [2.0, 0.05, 0.05]).unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let pose_b = pose_from_parts("b", [h, 0.0, 0.0, h], [0.0, 0.0, 0.3]).unwrap();
        let r = distance(&n1, &Isometry3::identity(), &n2, &pose_b, None, &NewtonParams::default());
        assert!(r.status.converged());
        assert!((r.distance - 0.2).abs() < 1e-9, "{}", r.distance);
    }

    /// Distance from the point `z` (relative to the center) to the axis-aligned ellipsoid with
    /// semi-axes `r`, for `z` outside it: the closest point is x_i = z_i r_i² / (r_i² + t) with
    /// t ≥ 0 the root of Σ (x_i / r_i)² = 1 (decreasing in t), found by bisection.
    fn point_to_ellipsoid(z: &Vector3, r: &[Real; 3]) -> Real {
        let x = |t: Real| Vector3::from_fn(|i, _| z[i] * r[i] * r[i] / (r[i] * r[i] + t));
        let f = |t: Real| (0..3).map(|i| (x(t)[i] / r[i]).powi(2)).sum::<Real>() - 1.0;
        let (mut lo, mut hi) = (0.0, 1.0);
        while f(hi) > 0.0 {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (z - x(hi)).norm()
    }

    #[test]
    fn small_bodies_far_from_the_frame_origin_converge_to_the_closed_form() {
        // A 0.9 × 0.3 × 0.5 m ellipsoid whose center lies 10 km (and 1 km) from its own frame's
        // origin (a body fitted in site coordinates), posed anywhere, and a 1 mm / 1 cm sphere 0.1
        // mm to 1 cm from it. In A's frame the points lie ~10⁴ m out, where rounding (~10⁻¹² m) is
        // 10⁻⁹ of the sphere: before the query's working frame moved to the smaller body, about
        // half of these ran hundreds of iterations and ended unconverged. Every answer converges
        // to the closed form (point-to-ellipsoid distance minus the radius, 1e-9 m), and the
        // growth measure of two spheres (1 m and 1 mm, 10 km out) matches (|c₁ − c₂| − r₂)²/r₁²
        // inside and outside, to 1e-9 relative.
        let params = NewtonParams::default();
        let radii = [0.9, 0.3, 0.5];
        let pose_a = pose_from_parts("a", [0.8, 0.0, 0.6, 0.0], [3.0, -1.0, 2.0]).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let mut runs = 0;
        for offset in [1e4, 1e3] {
            let center = Vector3::new(offset, -0.6 * offset, 0.3 * offset);
            let a = ellipsoid([center.x, center.y, center.z], radii).unwrap();
            for radius in [1e-3, 1e-2] {
                let b = ellipsoid([0.0; 3], [radius; 3]).unwrap();
                for gap in [1e-4, 1e-3, 1e-2] {
                    for _ in 0..20 {
                        let m = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)).normalize();
                        // A's boundary point along m (A's frame), then B's center `gap + radius` out
                        // along the normal there.
                        let s = 1.0 / (0..3).map(|i| (m[i] / radii[i]).powi(2)).sum::<Real>().sqrt();
                        let n = Vector3::from_fn(|i, _| m[i] * s / (radii[i] * radii[i])).normalize();
                        let z = m * s + n * (gap + radius);
                        let q = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
                        let rot = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(q.x, q.y, q.z, 0.5));
                        let pose_b = pose_a * Isometry3::from_parts((center + z).into(), rot);
                        let expected = point_to_ellipsoid(&z, &radii) - radius;
                        let d = distance(&a, &pose_a, &b, &pose_b, None, &params);
                        assert!(d.status.converged() && !d.overlapping, "offset {offset}, radius {radius}: {d:?}");
                        assert!(
                            (d.distance - expected).abs() <= 1e-9,
                            "offset {offset}, radius {radius}, gap {gap}: {} vs {expected}",
                            d.distance
                        );
                        assert!(((d.witness_b - d.witness_a).norm() - d.distance).abs() <= 1e-9);
                        // The reversed pair (the small body as the frame of reference).
                        let r = distance(&b, &pose_b, &a, &pose_a, None, &params);
                        assert!(r.status.converged() && (r.distance - expected).abs() <= 1e-9, "{r:?}");
                        runs += 1;
                    }
                }
            }
        }
        assert_eq!(runs, 240);
        let center = Vector3::new(1e4, -6e3, 3e3);
        let big = ellipsoid([center.x, center.y, center.z], [1.0; 3]).unwrap();
        let small = ellipsoid([0.0; 3], [1e-3; 3]).unwrap();
        for along in [0.5, 0.999, 1.0005, 1.01] {
            let m = Vector3::new(0.48, -0.6, 0.64);
            let pose_b = Isometry3::translation(center.x + along * m.x, center.y + along * m.y, center.z + along * m.z);
            let g = crate::query::growth::growth(&big, &Isometry3::identity(), &small, &pose_b, None, &params);
            let expected = (along - 1e-3) * (along - 1e-3);
            assert!(g.status.converged(), "along {along}: {g:?}");
            assert!((g.value - expected).abs() <= 1e-9 * expected.max(1.0), "along {along}: {} vs {expected}", g.value);
        }
    }

    #[test]
    fn cold_runs_do_not_depend_on_the_bodies_size() {
        // The bench's chair / human pair (2d = 6) at its first 100 cold poses, scaled by k: the
        // same problem in other units (a 1 mm, 1 cm, 10 cm, 10 m and 1 km chair). Reference: the
        // unit problem's answers — each distance k times the scaled one's (to 1e-9 of k(1 + d)),
        // witnesses to 1e-7·k, growth values equal (dimensionless, to 1e-9 of max(1, value)) — and
        // its Newton iterations: the scaled runs of each query take within 3 % of them (measured
        // on 300 poses: distance 1642 / 1657 / 1668 at k ≤ 0.1 / 1 / 10³, growth 1561–1572
        // against 1570). With ‖r‖₂ as the line searches' merit, 1 cm bodies took 1.7× and 1 mm
        // bodies 3.9× the distance iterations, 1 km bodies 1.27× the growth iterations.
        use crate::query::growth::{growth, GrowthResult};
        let (chair, human) = crate::query::test_bodies::bench_bodies(6);
        let poses = crate::query::test_bodies::bench_cold_poses(100);
        let params = NewtonParams::default();
        let id = Isometry3::identity();
        let unit: Vec<(DistanceResult, GrowthResult)> = poses
            .iter()
            .map(|p| (distance(&chair, p, &human, &id, None, &params), growth(&chair, p, &human, &id, None, &params)))
            .collect();
        let unit_iterations = |pick: fn(&(DistanceResult, GrowthResult)) -> usize| unit.iter().map(pick).sum::<usize>();
        let (unit_d, unit_g) = (unit_iterations(|u| u.0.iterations), unit_iterations(|u| u.1.iterations));
        let rescaled = |body: &Body, k: Real| {
            let c = body.center() * k;
            Body::new(body.polynomial().clone(), [c.x, c.y, c.z], body.scale() * k, Default::default()).unwrap()
        };
        for k in [1e-3, 1e-2, 1e-1, 10.0, 1e3] {
            let (a, b) = (rescaled(&chair, k), rescaled(&human, k));
            let (mut iterations_d, mut iterations_g) = (0, 0);
            for (p, (u, ug)) in poses.iter().zip(&unit) {
                let pk = Isometry3::from_parts((p.translation.vector * k).into(), p.rotation);
                let d = distance(&a, &pk, &b, &id, None, &params);
                assert!(d.status.converged() && d.overlapping == u.overlapping, "k = {k}: {d:?}");
                assert!(
                    (d.distance - k * u.distance).abs() <= 1e-9 * k * (1.0 + u.distance),
                    "k = {k}: {d:?} vs {u:?}"
                );
                let w = (d.witness_a.coords - u.witness_a.coords * k).norm();
                assert!(w <= 1e-7 * k, "k = {k}: witness on A {w:e} m off");
                let g = growth(&a, &pk, &b, &id, None, &params);
                assert!(g.status.converged(), "k = {k}: {g:?}");
                assert!((g.value - ug.value).abs() <= 1e-9 * ug.value.max(1.0), "k = {k}: {} vs {}", g.value, ug.value);
                iterations_d += d.iterations;
                iterations_g += g.iterations;
            }
            for (what, n, unit_n) in [("distance", iterations_d, unit_d), ("growth", iterations_g, unit_g)] {
                let ratio = n as Real / unit_n as Real;
                assert!((0.97..=1.03).contains(&ratio), "k = {k}: {n} against {unit_n} {what} Newton iterations");
            }
        }
    }

    #[test]
    fn warm_starts_agree_with_cold_answers_through_contact_and_back() {
        // Two ellipsoids on a smooth motion that approaches, passes through (overlap, touching,
        // one inside the other's growth range) and separates again; the warm answers (cubic
        // predictor, give-up on nonpositive multipliers) must equal the cold ones at every step.
        let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
        let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
        let params = NewtonParams::default();
        let (mut wd, mut wg): (Option<DistanceWarmStart>, Option<GrowthWarmStart>) = (None, None);
        let (mut warm_it, mut cold_it, mut overlapping) = (0, 0, 0);
        for k in 0..120 {
            let s = k as Real / 119.0;
            let (sn, cs) = (0.6 * s).sin_cos();
            let pose_b = pose_from_parts("b", [cs, 0.0, sn, 0.0], [3.0 - 6.0 * s, 0.3, 0.1 * (3.0 * s).sin()]).unwrap();
            let id = Isometry3::identity();
            let d = distance(&e1, &id, &e2, &pose_b, wd.as_ref(), &params);
            let c = distance(&e1, &id, &e2, &pose_b, None, &params);
            let g = super::super::growth::growth(&e1, &id, &e2, &pose_b, wg.as_ref(), &params);
            let gc = super::super::growth::growth(&e1, &id, &e2, &pose_b, None, &params);
            assert!(d.status.converged() && c.status.converged(), "k = {k}: {d:?}");
            assert!(g.status.converged() && gc.status.converged(), "k = {k}: {g:?}");
            assert!((d.distance - c.distance).abs() <= 1e-9, "k = {k}: {} vs {}", d.distance, c.distance);
            assert_eq!(d.overlapping, c.overlapping, "k = {k}");
            assert!((g.value - gc.value).abs() <= 1e-9 * gc.value.max(1.0), "k = {k}: {} vs {}", g.value, gc.value);
            overlapping += usize::from(c.overlapping);
            if k > 0 {
                warm_it += d.iterations + g.iterations;
                cold_it += c.iterations + gc.iterations;
            }
            wd = Some(*d.warm_start);
            wg = Some(*g.warm_start);
        }
        assert!(overlapping > 10 && overlapping < 100, "the motion must pass through: {overlapping}");
        assert!(2 * warm_it < cold_it, "warm {warm_it} vs cold {cold_it} iterations");
    }
}

/// How good a cold start has to be: Newton from the exact witnesses moved by δ·(size of A + size of
/// B) in a random direction and put back on the boundaries (least-squares multipliers, as a cold
/// start). The iteration counts are deterministic; this pins down the ceiling of any better start.
#[cfg(test)]
mod start_quality {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Mean Newton iterations from witnesses perturbed by `delta`, and how many runs reached the
    /// reference distance to 1e-8 m, over the separated ones of the first `count` cold poses of
    /// `sublevel bench` (chair_101 against human_10 at 2d = `degree`).
    fn iterations_from_perturbed_witnesses(degree: usize, count: usize, delta: Real) -> (Real, usize, usize) {
        let (a, b) = crate::query::test_bodies::bench_bodies(degree);
        let poses = crate::query::test_bodies::bench_cold_poses(count);
        let params = NewtonParams::default();
        let id = Isometry3::identity();
        let mut jitter_rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let (mut runs, mut iterations, mut reached) = (0usize, 0usize, 0usize);
        for p in &poses {
            let d = distance(&a, p, &b, &id, None, &params);
            if d.overlapping || !d.status.converged() {
                continue;
            }
            // The solver's frame is A's: B posed by p⁻¹.
            let rel = p.inv_mul(&id);
            let (ba, bb) = (PosedBody::unposed(&a), PosedBody::new(&b, &rel));
            let len = a.scale() + b.scale();
            let mut moved = |w: &Point3, body: &PosedBody<'_>| {
                let j = Vector3::from_fn(|_, _| jitter_rng.random_range(-1.0..1.0));
                let c = body.interior_point();
                let w = p.inverse_transform_point(w).coords + j * (delta * len);
                boundary_on_segment_within(body, &c, &(c + (w - c) * 10.0), 1e-12)
            };
            let (x0, y0) = (moved(&d.witness_a, &ba), moved(&d.witness_b, &bb));
            let out = kkt_newton(&ba, &bb, x0, y0, None, &params, false);
            runs += 1;
            iterations += out.iterations;
            reached += usize::from(out.status.converged() && ((out.y - out.x).norm() - d.distance).abs() < 1e-8);
        }
        (iterations as Real / runs as Real, runs, reached)
    }

    #[test]
    fn even_millimeter_starts_take_three_newton_iterations() {
        // Measured on all 300 poses (2d = 6 / 8): δ = 1e-3: 2.99 / 3.11 iterations; 1e-2: 4.08 /
        // 4.27; 3e-2: 5.03 / 5.40; 1e-1: 6.60 / 7.14 (2 and 5 runs of ~280 end elsewhere). The
        // support-table start takes 5.90 / 6.05, i.e. it is worth δ ≈ 3e-2 (about 10 cm here).
        for (delta, low, high) in [(1e-3, 2.5, 3.5), (1e-2, 3.5, 4.6), (3e-2, 4.5, 5.6)] {
            let (mean, runs, reached) = iterations_from_perturbed_witnesses(6, 100, delta);
            assert!(runs > 80, "{runs} separated poses");
            assert_eq!(reached, runs, "δ = {delta}: every run reaches the reference distance");
            assert!((low..=high).contains(&mean), "δ = {delta}: {mean:.2} iterations per query");
        }
    }
}
