//! Shared machinery of the Newton / active-set query solvers: statuses, tolerances, and the
//! one-dimensional boundary search used to build cold starts.
//!
//! Both queries are convex programs with one or two smooth convex constraints `g(x) = p'(x) − 1 ≤ 0`
//! (paper §IV-A, §IV-B). The solvers share one strategy:
//!
//! ```text
//! 1. active-set Newton on the KKT system with every constraint active, from a warm start or a
//!    geometric cold start; globalized by a backtracking line search on ‖KKT residual‖;
//! 2. if that does not converge to a KKT point with positive multipliers, a primal log-barrier
//!    path (always globally convergent on these convex problems, started from the bodies'
//!    interior points), then the active-set Newton polish from the barrier's point.
//! ```
//!
//! A KKT point with nonnegative multipliers of a convex program is its global minimizer, so a
//! converged answer is the answer.

use crate::body::PosedBody;
use crate::math::{Isometry3, Real, Vector3, NEWTON_KKT_TOLERANCE, NEWTON_MAX_ITERATIONS};
use serde::{Deserialize, Serialize};

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

/// Relative tolerance |p' − 1| of the boundary points that only start a Newton solve (its KKT
/// iterations make the constraint exact).
pub(crate) const START_BOUNDARY_TOLERANCE: Real = 1e-4;

/// The point where the segment from `inside` (p' < 1) to `outside` (p' > 1) crosses the boundary
/// p' = 1, to |p' − 1| ≤ `tolerance`.
///
/// Safeguarded Newton (bracketed by bisection) on the gauge s ↦ p'(inside + s·dir)^(1/2d) − 1
/// rather than on p' − 1: for a polynomial dominated by its top-degree form the gauge is nearly
/// linear along the segment, so from a far outside point Newton lands near the boundary in one or
/// two steps, where Newton on p' itself would shrink s only by a factor ≈ 1 − 1/(2d) per step.
pub(crate) fn boundary_on_segment_within(
    body: &PosedBody<'_>,
    inside: &Vector3,
    outside: &Vector3,
    tolerance: Real,
) -> Vector3 {
    let dir = outside - inside;
    let inv_degree = 1.0 / body.body.degree().max(1) as Real;
    let (mut lo, mut hi) = (0.0, 1.0);
    let mut s = 1.0;
    for _ in 0..100 {
        let x = inside + dir * s;
        let (v, g) = body.body.fast_polynomial().value_gradient(&body.to_normalized(&x));
        let r = v - 1.0;
        if r.abs() <= tolerance {
            break;
        }
        if r > 0.0 {
            hi = s;
        } else {
            lo = s;
        }
        let slope = (body.linear().transpose() * g).dot(&dir);
        let mut next = if slope > 0.0 && v > 0.0 {
            // Newton on φ = v^(1/2d): s − (φ − 1)/φ', φ' = φ·slope/(2d·v).
            let phi = v.powf(inv_degree);
            s - (phi - 1.0) * v / (inv_degree * phi * slope)
        } else {
            0.5 * (lo + hi)
        };
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - s).abs() < 1e-16 {
            s = next;
            break;
        }
        s = next;
    }
    inside + dir * s
}

/// Secant coefficient of a warm start along a motion: the current relative-pose step expressed as
/// a multiple σ of the previous one, so that a solution s(T) known at the last two relative poses
/// `previous`, `last` predicts `s(current) ≈ s(last) + σ (s(last) − s(previous))` (linear
/// extrapolation, error O(‖step‖²) along a smooth motion instead of O(‖step‖) for the plain warm
/// start).
///
/// Steps are compared as 6-vectors (translation in meters, rotation vector × `length` meters).
/// Returns 0 (the plain warm start) when the previous step is negligible or the two steps are not
/// nearly parallel (cosine below 0.9), and at most 2.
pub(crate) fn secant_coefficient(previous: &Isometry3, last: &Isometry3, current: &Isometry3, length: Real) -> Real {
    // Rotation vector of the step by its small-angle form 2·sign(w)·(x, y, z) of the quaternion
    // (exact direction; magnitude 2 sin(θ/2) ≈ θ for the small steps that matter here).
    let step = |from: &Isometry3, to: &Isometry3| {
        let q = to.rotation * from.rotation.inverse();
        let s = if q.w < 0.0 { -2.0 * length } else { 2.0 * length };
        let t = to.translation.vector - q * from.translation.vector;
        [t.x, t.y, t.z, q.i * s, q.j * s, q.k * s]
    };
    let (d1, d) = (step(previous, last), step(last, current));
    let dot = |a: &[Real; 6], b: &[Real; 6]| a.iter().zip(b).map(|(x, y)| x * y).sum::<Real>();
    let (n1, n) = (dot(&d1, &d1), dot(&d, &d));
    if !(n1 > 1e-24 && n.is_finite()) {
        return 0.0;
    }
    let c = dot(&d, &d1);
    if c <= 0.0 || c * c < 0.81 * n1 * n {
        return 0.0;
    }
    (c / n1).min(2.0)
}

/// Linear extrapolation `last + σ (last − previous)` of a warm-started multiplier, kept at or above
/// half of `last` (a multiplier of an active constraint stays positive).
pub(crate) fn extrapolate_multiplier(last: Real, previous: Real, sigma: Real) -> Real {
    (last + (last - previous) * sigma).max(0.5 * last)
}

#[cfg(test)]
mod secant_tests {
    use super::*;
    use crate::math::UnitQuaternion;

    #[test]
    fn secant_coefficient_measures_steps_along_a_motion() {
        let pose = |s: Real| {
            Isometry3::from_parts(
                Vector3::new(0.3 * s, -0.1 * s, 0.05).into(),
                UnitQuaternion::from_euler_angles(0.2 * s, 0.0, -0.1 * s),
            )
        };
        // Uniform steps: σ = 1; a half step: σ = 1/2 (to second order in the step).
        assert!((secant_coefficient(&pose(0.0), &pose(0.1), &pose(0.2), 1.0) - 1.0).abs() < 1e-3);
        assert!((secant_coefficient(&pose(0.0), &pose(0.1), &pose(0.15), 1.0) - 0.5).abs() < 1e-3);
        // Reversal, a standstill before, and a sideways step give the plain warm start.
        assert_eq!(secant_coefficient(&pose(0.0), &pose(0.1), &pose(0.0), 1.0), 0.0);
        assert_eq!(secant_coefficient(&pose(0.1), &pose(0.1), &pose(0.2), 1.0), 0.0);
        let side = Isometry3::from_parts(Vector3::new(0.03, 0.5, 0.05).into(), pose(0.1).rotation);
        assert_eq!(secant_coefficient(&pose(0.0), &pose(0.1), &side, 1.0), 0.0);
    }
}
