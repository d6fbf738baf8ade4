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
use crate::math::{Real, Vector3, NEWTON_KKT_TOLERANCE, NEWTON_MAX_ITERATIONS};
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
/// p' = 1, by safeguarded Newton on the convex 1-D function s ↦ p'(inside + s (outside − inside)).
pub(crate) fn boundary_on_segment(body: &PosedBody<'_>, inside: &Vector3, outside: &Vector3) -> Vector3 {
    let dir = outside - inside;
    let (mut lo, mut hi) = (0.0, 1.0);
    let mut s = 1.0;
    for _ in 0..100 {
        let x = inside + dir * s;
        let (v, g) = body.body.fast_polynomial().value_gradient(&body.to_normalized(&x));
        let r = v - 1.0;
        if r.abs() < 1e-15 {
            break;
        }
        if r > 0.0 {
            hi = s;
        } else {
            lo = s;
        }
        let slope = (body.linear().transpose() * g).dot(&dir);
        let mut next = if slope > 0.0 { s - r / slope } else { 0.5 * (lo + hi) };
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
