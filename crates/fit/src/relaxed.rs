//! Containment rows in rounds, for fits whose body may be nonconvex (paper §III-B-2, eq.
//! "VAG.param.convex": p + c(‖u‖²)ᵈ sos-convex).
//!
//! Without convexity, containing the hull vertices no longer implies containing the cloud, so
//! every point must satisfy p(uᵢ) ≤ 1. Rather than one row per point (thousands of dense rows),
//! the program is solved in rounds:
//!
//! ```text
//! rows ← hull vertices ∪ a strided subsample of INITIAL_SAMPLE points
//! repeat (at most MAX_ROUNDS times):
//!     solve; evaluate p on every point
//!     violated ← points with p(uᵢ) > 1 + VIOLATION_TOLERANCE that are not rows yet
//!     if none: stop;  else add the ROUND_ADD worst violated points as rows
//! ```
//!
//! Each round's program is a relaxation of the program with all points, so its optimum is at
//! least as good; when no point is violated the round's optimum is feasible for the full program,
//! hence optimal for it (up to the violation tolerance, which the caller's final rescale absorbs).
//! If the round cap is reached the caller still rescales p to contain every point — points are
//! never dropped.

use super::hull::NormalizedCloud;
use super::sdp::{usable_status, Containment, GramProgram, ProblemSpec, SolverSettings};
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::Polynomial;
use sublevel_core::Result;

/// Points of the subsample added to the hull vertices in the first round.
pub const INITIAL_SAMPLE: usize = 64;
/// Most violated points added per round.
pub const ROUND_ADD: usize = 300;
/// Rounds before giving up on adding rows (the final rescale then restores containment).
pub const MAX_ROUNDS: usize = 12;
/// Clarabel's `max_step_fraction` in the rounds (default 0.99).
pub const ROUND_STEP_FRACTION: Real = 0.9;
/// p(uᵢ) above 1 + this counts as violated. Smaller overshoots are left to the caller's final
/// rescale, which divides p by at most 1 + 1e-4 and so shrinks the volume by about 1e-4 · 3/(2d)
/// relative — far below the 1 % Monte Carlo error — while saving a whole round for a handful of
/// barely violated points (chair, 2d = 6, c = 10: three rounds → two).
pub const VIOLATION_TOLERANCE: Real = 1e-4;

/// The last round's solution.
#[derive(Debug)]
pub struct RoundsOutcome {
    /// p = zᵀ P z of the last round (normalized coordinates, before any rescale).
    pub polynomial: Polynomial,
    /// Sos Gram matrix P (N × N).
    pub gram: nalgebra::DMatrix<Real>,
    /// Sos-convexity Gram matrix of p + c(‖u‖²)ᵈ (M × M).
    pub convexity_gram: nalgebra::DMatrix<Real>,
    /// Clarabel's status of the last round.
    pub status: SdpStatus,
    /// Seconds inside Clarabel, all rounds.
    pub solve_seconds: Real,
    /// Interior-point iterations, all rounds.
    pub iterations: u32,
    /// Containment rows of each round.
    pub rows_per_round: Vec<usize>,
    /// False when the round cap was reached (or a round failed) with points still violated.
    pub converged: bool,
    /// Set when a round after the first ended without a usable solution and the previous
    /// round's solution was kept (says which round and its status).
    pub failed_round: Option<String>,
    /// Primal / dual objectives of the last round's solve.
    pub certificate: sublevel_core::body::SolverCertificate,
}

/// Solves `spec` with containment rows added in rounds (see the module docs), calling
/// `progress(round, iteration, primal cost)` after each interior-point iteration.
///
/// Clarabel's default step fraction 0.99 stalls (`InsufficientProgress` after ~8 iterations) on
/// the chair with a few hundred redundant containment rows beyond the hull; the rounds therefore
/// use [`ROUND_STEP_FRACTION`] (and [`GramProgram::solve_with_retry`] shortens it further if
/// needed).
///
/// # Errors
/// Whatever [`GramProgram::build`] or [`GramProgram::solve`] return, and
/// [`sublevel_core::Error::Numerical`] for an unusable solver status in the first round (a later failed
/// round keeps the previous round's solution, see [`RoundsOutcome::failed_round`]).
pub fn solve_in_rounds(
    cloud: &NormalizedCloud,
    spec: &ProblemSpec,
    settings: &SolverSettings,
    progress: &mut dyn FnMut(usize, u32, Real),
) -> Result<RoundsOutcome> {
    let n = cloud.points.len();
    // Hull vertices are cloud points: mark them (by exact coordinates) so that no point becomes
    // a duplicate row (duplicate rows stall Clarabel).
    let key = |u: &Vector3| [u.x.to_bits(), u.y.to_bits(), u.z.to_bits()];
    let hull: std::collections::HashSet<[u64; 3]> = cloud.hull_vertices.iter().map(key).collect();
    let mut in_rows: Vec<bool> = cloud.points.iter().map(|u| hull.contains(&key(u))).collect();
    let mut rows: Vec<Vector3> = cloud.hull_vertices.clone();
    let stride = n.div_ceil(INITIAL_SAMPLE).max(1);
    for i in (0..n).step_by(stride) {
        if !in_rows[i] {
            in_rows[i] = true;
            rows.push(cloud.points[i]);
        }
    }
    let mut rows_per_round = Vec::new();
    let mut last: Option<RoundsOutcome> = None;
    let (mut solve_seconds, mut iterations) = (0.0, 0);
    for round in 0..MAX_ROUNDS {
        rows_per_round.push(rows.len());
        let problem = GramProgram::build(spec, Containment::Points(&rows))?;
        let raw =
            problem.solve_with_retry(settings, Some(ROUND_STEP_FRACTION), &mut |it, cost| progress(round, it, cost))?;
        solve_seconds += raw.solve_seconds;
        iterations += raw.iterations;
        let status = match (usable_status(raw.status, "fit"), last.take()) {
            (Ok(s), _) => s,
            (Err(e), None) => return Err(e),
            // A later round failed: keep the previous round's solution (the caller's rescale
            // restores containment of the points it violates).
            (Err(_), Some(mut prev)) => {
                prev.solve_seconds = solve_seconds;
                prev.iterations = iterations;
                prev.rows_per_round = rows_per_round;
                prev.failed_round = Some(format!("round {} ended with status {}", round + 1, raw.status));
                return Ok(prev);
            }
        };
        let gram = problem.gram(&raw.x);
        let polynomial = problem.polynomial_of_gram(&gram)?;
        let mut violated: Vec<(Real, usize)> = cloud
            .points
            .iter()
            .enumerate()
            .filter(|(i, _)| !in_rows[*i])
            .map(|(i, u)| (polynomial.value(u), i))
            .filter(|(v, _)| v.is_nan() || *v > 1.0 + VIOLATION_TOLERANCE)
            .collect();
        let done = violated.is_empty();
        let outcome = RoundsOutcome {
            polynomial,
            gram,
            convexity_gram: problem.convexity_gram(&raw.x),
            status,
            solve_seconds,
            iterations,
            rows_per_round: rows_per_round.clone(),
            converged: done,
            failed_round: None,
            certificate: raw.certificate,
        };
        if done || round + 1 == MAX_ROUNDS {
            return Ok(outcome);
        }
        last = Some(outcome);
        // Worst first (NaN counts as worst).
        violated.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap_or(std::cmp::Ordering::Less));
        for &(_, i) in violated.iter().take(ROUND_ADD) {
            in_rows[i] = true;
            rows.push(cloud.points[i]);
        }
    }
    Err(sublevel_core::Error::Numerical("containment rounds ended without a solution".into()))
}
