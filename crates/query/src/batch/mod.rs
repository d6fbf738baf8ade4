//! Batch solvers: many cold distance queries between the same two bodies — one pair of a
//! planner's query across its candidate states, or one body pair of a scene check — solved
//! several pairs at a time, one pair per SIMD lane.
//!
//! ```text
//! queue of pairs ──► coarse stage, 8 f32 lanes (2d ≥ 4): per round, for 8 trial points at once
//!                      p_a, p_b at 8 points in single precision, gradients, Hessians, KKT
//!                      residuals and 8 × 8 KKT solves in 8-lane f32 arithmetic; until a lane's
//!                      residual is below 10⁻³ of the scale: its state handed to
//!                ──► fine stage, 4 f64 lanes (one pair each): per round, for the 4 trial points
//!                      p_a at 4 points, p_b at 4 points      SoaPoly: one pass per body
//!                      gradients, Hessians, KKT residuals    4-lane arithmetic
//!                      8 × 8 KKT solves (block elimination)  4-lane arithmetic
//!                    then per lane: accept the trial point or halve its step (backtracking on
//!                    the single-pair solver's merit, ‖KKT residual‖₂ with stationarity in units
//!                    of the smaller body's size), converged → answer, the lane takes the next pair
//!                    (2d = 8: a predicted last point checked at once without Hessians)
//! pairs without a separated start, and lanes that stall, reach the iteration cap or end near
//! contact ──► the single-pair solver's growth-first path, where its own separated run would hand
//! them (so they are not solved twice): its growth solve on 4 lanes too (4 × 4 KKT solves),
//! the overlapping answers from there, the rest (A's minimizer inside B, growth > 1, lanes that
//! fail) on the single-pair solver
//! ```
//!
//! The thresholds of the stages are the fields of [`BatchSettings`] (`NewtonParams::batch`); the
//! figures below are their defaults.
//!
//! Pairs with a body of degree 2d ≥ 4 ([`BatchSettings::coarse_min_degree`]) run in two stages;
//! at 2d = 2 the fine stage runs alone. The **coarse stage** (`lanes::coarse`) takes eight pairs
//! per pass: its lane arithmetic runs in eight-lane `f32` registers (the same instructions as
//! four-lane `f64` ones, twice the pairs) and its points are evaluated in single precision
//! ([`sublevel_core::poly::SoaPoly::eval8_rows_f32`]: the single-precision table's Horner sums,
//! two quantities of four points per eight-lane multiply–add, half the multiply–adds of the
//! double-precision kernel; p and ∇p from them by Euler's identity in double precision), until a
//! lane's residual is below 10⁻³ of the stationarity scale ([`BatchSettings::coarse_residual`]).
//! The lane then hands its point, multipliers and Newton step to the **fine stage** (four `f64`
//! lanes, the double-precision kernel), which goes on from that step's trial point to the same
//! tolerance. The single-precision kernel errs by at most 1.1·10⁻⁵ relative on the project's
//! bodies (`kernel_timing` prints it), so the coarse steps are Newton steps, and two or three
//! double-precision steps finish a pair; answers agree with the single-pair ones to the KKT
//! tolerance (2·10⁻¹¹ m on the chair / human poses). When the coarse queue runs dry the lanes
//! still running hand off as they are and run first in the fine stage, beside the others (so no
//! slow pair runs alone); a lane that ends the coarse stage otherwise (nonfinite, singular,
//! stalled, at the cap) starts again in the fine stage from its cold start, so single precision
//! never decides a pair. The coarse lanes hold their points as displacements from each pair's
//! start points, so single precision does not depend on where the bodies sit in A's frame or on
//! how their sizes compare (a 100 m body against a 1.7 cm one, a body 1 km from its frame's
//! origin: see `lanes::coarse`).
//!
//! A pair's last point needs no Hessians: it is only checked. Where a fine-stage lane accepts a
//! point at a residual below 10⁻⁵ of the stationarity scale ([`BatchSettings::verify_residual`]),
//! Newton's quadratic convergence puts its next trial point below the tolerance, so that point is
//! checked at once, for that lane alone, by the single-pair solver's value + gradient kernels
//! (`Lanes::verify`: 19 instead of 32 ns per point at 2d = 8), and the lane gives its answer and
//! takes the next pair; a trial point that fails the check (about 10 of 1440 per 300-pair batch at
//! 2d = 8) is evaluated with its Hessians in the next round as before. Only pairs with a body of
//! 2d = 8 run the checks ([`BatchSettings::verify_min_degree`]): below, the four-point kernel is
//! cheap beside a check's scalar work.
//!
//! The lanes run the single-pair solver's cold separated Newton run ([`distance`]: same start, same
//! KKT system, same line search and tolerance, same iteration cap,
//! [`NewtonParams::speculative_iterations`]) with one difference: every
//! trial point is evaluated with its Hessians (the four-point kernel evaluates them at no extra
//! cost), so there are no chord steps. A converged lane's answer is therefore the single-pair
//! answer to the KKT tolerance (not to the bit); a KKT point with positive multipliers of this
//! convex program is its global minimizer either way. A lane that leaves without an answer goes on
//! where the single-pair solver's own run would fail over to, its growth-first path, instead of
//! the whole single-pair solver (which would repeat the failed run).
//!
//! The cold starts are computed four pairs at a time too: the posed interior points, the
//! bounding-sphere test and both bodies' support and radial look-ups (the nodes gathered from the
//! tables) in 4-lane arithmetic, the same starts as the single-pair solver's up to rounding. The
//! overlapping pairs' growth solves run on four lanes too (`lanes::solve_growth_on_lanes`, the
//! same start, KKT system, line search and tolerance as the single-pair growth solve, Hessians at
//! every trial point) when at least [`BatchSettings::min_growth_lanes`] pairs are left. Per round
//! of four lanes at 2d = 6: two kernel passes of about 88 ns and about 115 ns of lane arithmetic;
//! outside the rounds, the cold starts and the overlapping pairs bound the gain. The batch's rate
//! over single queries at each degree is in docs/performance.md ("Batch lanes", "Today's
//! figures").
//!
//! The lanes' code has no closures over `F4` values: a closure compiled out of line runs without
//! the AVX target features. Building an 848-byte warm start per answer costs 8–40 % more time
//! (`cold_distances(…, true)`; it varies with the allocator's state), so the service's cold
//! queries, which keep none, ask for none.

use super::distance::{distance, DistanceResult};
use super::newton::NewtonParams;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real};

/// Settings of the batch solver's lanes ([`cold_distances`]), the field `batch` of
/// [`NewtonParams`]; the Newton runs on the lanes take their tolerance, caps and line search from
/// the enclosing [`NewtonParams`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatchSettings {
    /// Fewest pairs worth the lanes, below which the batch answers pair by pair; default 4.
    /// Larger: small batches skip the lanes' setup (cold starts, queues) and miss their speed-up.
    pub min_lane_batch: usize,
    /// Fewest pairs left without an answer worth the growth lanes (below, the single-pair
    /// solver); default 4. A round costs two four-point passes (about 88 ns at 2d = 6) whatever
    /// the lanes hold, against two one-point evaluations (about 32 ns each) per pair on the
    /// single-pair solver, so fewer than three live lanes lose. Larger: more overlapping pairs on
    /// the single-pair solver.
    pub min_growth_lanes: usize,
    /// Merit, relative to its scale 1 + 2‖x − y‖/L, below which a lane leaves the coarse stage
    /// (single precision) for the fine one (double precision); default 10⁻³. The `f32` kernel's
    /// relative errors on the project's bodies are at most 2.4·10⁻⁵ (2d = 8; 10⁻⁷–10⁻⁶ at
    /// 2d ≤ 6), 40 times below it, so the coarse steps are Newton steps to that accuracy, and two
    /// or three double-precision steps reach the tolerance from there. Larger: fewer
    /// single-precision steps, more double-precision ones; smaller: hand-offs nearer the kernel's
    /// rounding, where a coarse lane may stall.
    pub coarse_residual: Real,
    /// Bound on the error of a coarse-stage merit relative to its scale 1 + 2‖x − y‖/L, added to a
    /// hand-off's merit; default 10⁻⁴, 4 times the `f32` kernel's largest relative error on the
    /// project's bodies. Without it a pair that starts at its answer (spheres: the radial start is
    /// exact) compares its double-precision residuals with a single-precision one at the rounding
    /// level, and its line search stalls. Larger: the fine stage's first step accepted more
    /// readily; smaller: more stalls after a hand-off.
    pub coarse_noise: Real,
    /// Least degree 2d of the higher-degree body of a pair for which the batch runs the coarse
    /// stage; default 4 (at 2d = 2 the single-precision kernel saves less than the stage's
    /// bookkeeping costs; from 2d = 4 the eight lanes make the batch faster). Smaller: the coarse
    /// stage at lower degrees too.
    pub coarse_min_degree: usize,
    /// Least degree 2d of the higher-degree body of a pair for which the fine stage checks
    /// predicted last points by value + gradient evaluations (`Lanes::verify`); default 8 (below,
    /// the four-point kernel is cheap beside a check's scalar work, and the checks make the batch
    /// no faster at 2d = 6 and slower at 2d ≤ 4). Smaller: checks at lower degrees too.
    pub verify_min_degree: usize,
    /// Merit, relative to its scale 1 + 2‖x − y‖/L, at an accepted point below which the fine
    /// stage checks the next trial point by value + gradient evaluations (Newton's quadratic
    /// convergence then lands below the tolerance); default 10⁻⁵. Larger: more checks, more of
    /// them failing (the point is then evaluated with its Hessians in the next round); smaller:
    /// fewer rounds saved (at 2d = 8 5·10⁻⁶ to 3·10⁻⁵ cost the same, and 2·10⁻⁶ misses the first
    /// fine step's residual).
    pub verify_residual: Real,
}

impl BatchSettings {
    /// The default settings (a constant, for contexts that need one).
    pub const DEFAULT: Self = Self {
        min_lane_batch: 4,
        min_growth_lanes: 4,
        coarse_residual: 1e-3,
        coarse_noise: 1e-4,
        coarse_min_degree: 4,
        verify_min_degree: 8,
        verify_residual: 1e-5,
    };
}

impl Default for BatchSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The default of [`BatchSettings::min_lane_batch`], for the callers that route queries to the
/// lanes before they hold settings.
pub const MIN_LANE_BATCH: usize = BatchSettings::DEFAULT.min_lane_batch;

/// Cold distance answers for the pairs `poses` (pose of `a`, pose of `b`; body frame → world) of
/// the bodies `a` and `b`, in order: the answers [`distance`] gives with no warm start, eight or
/// four pairs per SIMD pass (see the module docs). Pairs go through [`distance`] one by one when there are
/// fewer than `params.batch.min_lane_batch` ([`BatchSettings::min_lane_batch`]), when the CPU
/// lacks AVX2 + FMA, or when a body has degree below 2.
///
/// With `warm_starts` false, the answers the lanes give share one empty warm start (an invalid
/// [`super::DistanceWarmStart`]: a query started from it runs cold) instead of one allocation
/// each: for callers that drop them (cold queries of a planner, scene checks). Measured on the
/// chair / human cold poses at 2d = 6 (`examples/cold_profile 6 20 batch`), the 848-byte warm
/// starts of a 300-pair batch add 8–40 % to its time (it varies with the allocator's state).
///
/// Never panics on valid bodies; each answer says whether it converged.
pub fn cold_distances(
    a: &Body,
    b: &Body,
    poses: &[(Isometry3, Isometry3)],
    params: &NewtonParams,
    warm_starts: bool,
) -> Vec<DistanceResult> {
    #[cfg(target_arch = "x86_64")]
    if poses.len() >= params.batch.min_lane_batch && a.degree() >= 2 && b.degree() >= 2 {
        if let Some(cpu) = sublevel_kernels::Avx2Fma::detect() {
            return lanes::solve(cpu, a, b, poses, params, warm_starts);
        }
    }
    poses.iter().map(|(pa, pb)| distance(a, pa, b, pb, None, params)).collect()
}

/// The four-lane solver (x86-64 only: AVX2 + FMA registers).
#[cfg(target_arch = "x86_64")]
mod lanes;

#[cfg(test)]
mod tests;
