//! Clarabel for every fit SDP: one set of solver settings, one solve with progress, one retry
//! policy, one status mapping, and the exact containment rescale after the solve.

use super::program::GramProgram;
use crate::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultInfo, DefaultSettings, DefaultSolver, IPSolver};
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::Polynomial;
pub use sublevel_core::report::KktSolver;

/// Clarabel's `max_step_fraction` for every fit SDP (Clarabel's default is 0.99). On the five
/// Table 1 shapes at 2d = 6 and 8 (scaled bases, tolerance 1e-6, no refinement), 0.99 stalled
/// once (octopus 2d = 6: `InsufficientProgress` after 19 iterations, solved by the 0.9 retry) and
/// ended `AlmostSolved` once; 0.9 solved all ten in 20–28 iterations (chair 2d = 8: 21 vs 23).
pub const FIT_STEP_FRACTION: Real = 0.9;

/// Clarabel's `static_regularization_constant` for every fit SDP (Clarabel's default is 1e-8).
/// With 1e-8 the KKT solves lose accuracy near the optimum: the step length drops to 0 with the
/// dual residual at ~4e-6 and the fit ends `AlmostSolved` (log det H: chair 2d = 4 and 6, hand and
/// octopus 2d = 6, chair 2d = 8 `NumericalError`, then the retries; trace H⁻¹: chair, hand and
/// octopus at 2d = 6, scaled basis; log det P: octopus 2d = 6, gap 3.8e-5). With 1e-7 all five
/// Table 1 shapes end `Solved` at 2d = 6 for every objective (log det H chair: gap 1.2e-4 → 8.8e-7
/// in log det units, 17 → 20 iterations; log det P octopus: gap 1.3e-5, volume 0.7027 → 0.7028,
/// within its Monte Carlo error 0.0021) and the chair at 2d = 4 and 8 too (log det H 2d = 8: 20
/// iterations, one solve instead of a failed one plus retries). Fit times are unchanged within the
/// noise. Only the regularization of the linear solves changes; the stopping test is on the true
/// residuals.
pub const FIT_STATIC_REGULARIZATION: Real = 1e-7;

/// Clarabel's settings for a fit SDP, in one place: every fit (point clouds, containment,
/// the sos-convexity certificate of uploaded bodies) builds its Clarabel settings from this.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverSettings {
    /// Clarabel's gap and feasibility tolerance (`tol_gap_abs`, `tol_gap_rel`, `tol_feas`).
    pub tolerance: Real,
    /// Interior-point iteration cap.
    pub max_iterations: u32,
    /// Direct solver of the KKT systems.
    pub linear_solver: KktSolver,
    /// Threads of the KKT factorization (faer); 0 lets faer choose.
    pub threads: u32,
    /// Iterative refinement of the KKT solves (the retries always turn it on).
    pub iterative_refinement: bool,
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-8,
            max_iterations: 200,
            linear_solver: KktSolver::Faer,
            threads: 1,
            iterative_refinement: false,
        }
    }
}

impl SolverSettings {
    /// Clarabel's settings: quiet, these tolerances, [`FIT_STEP_FRACTION`] and
    /// [`FIT_STATIC_REGULARIZATION`].
    pub fn clarabel(&self) -> DefaultSettings<Real> {
        let mut s = sublevel_core::conic::quiet_settings(self.tolerance, self.max_iterations);
        s.max_step_fraction = FIT_STEP_FRACTION;
        s.direct_solve_method = self.linear_solver.name().into();
        s.max_threads = self.threads;
        s.iterative_refinement_enable = self.iterative_refinement;
        s.static_regularization_constant = FIT_STATIC_REGULARIZATION;
        s
    }
}

/// Clarabel's raw answer.
#[derive(Clone, Debug)]
pub struct RawSolution {
    /// Primal variables.
    pub x: Vec<Real>,
    /// Final status.
    pub status: SdpStatus,
    /// Seconds inside Clarabel (all attempts).
    pub solve_seconds: Real,
    /// Interior-point iterations (all attempts).
    pub iterations: u32,
    /// Primal / dual objectives (maximized form) and residuals of the last iterate.
    pub certificate: sublevel_core::body::SolverCertificate,
}

impl GramProgram {
    /// Solves with Clarabel, calling `progress(iteration, primal cost)` after every interior-point
    /// iteration (Clarabel's termination callback, forwarded over a channel from a scoped solver
    /// thread because the callback must be `Send + Sync + 'static`).
    ///
    /// Inside a [`sublevel_core::cancel::cancellable`] scope the callback returns true once the
    /// scope's flag is set, so the solve stops at the end of the current iteration.
    ///
    /// # Errors
    /// [`Error::Cancelled`] when the scope's flag was set before or during the solve;
    /// [`Error::Numerical`] when Clarabel rejects the data or the solver thread panics. A status
    /// other than `Solved` is returned in the solution, not as an error (see [`usable_status`]).
    pub fn solve(&self, settings: DefaultSettings<Real>, progress: &mut dyn FnMut(u32, Real)) -> Result<RawSolution> {
        // Read on the calling thread: the scope is thread-local and the solve runs on its own.
        sublevel_core::cancel::check()?;
        let cancel = sublevel_core::cancel::current();
        let (tx, rx) = std::sync::mpsc::channel::<(u32, Real)>();
        let raw = std::thread::scope(|scope| {
            let handle = scope.spawn(move || -> Result<RawSolution> {
                let p = CscMatrix::zeros((self.num_vars, self.num_vars));
                let mut solver = DefaultSolver::new(&p, &self.q, &self.a, &self.b, &self.cones, settings)
                    .map_err(|e| Error::Numerical(format!("Clarabel rejected the fit problem: {e}")))?;
                solver.set_termination_callback(move |info: &DefaultInfo<Real>| {
                    let _ = tx.send((info.iterations, info.cost_primal));
                    cancel.as_ref().is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
                });
                solver.solve();
                let sol = &solver.solution;
                Ok(RawSolution {
                    x: sol.x.clone(),
                    status: sol.status.into(),
                    solve_seconds: sol.solve_time,
                    iterations: sol.iterations,
                    // Clarabel minimizes qᵀx = −(the maximized objective).
                    certificate: sublevel_core::body::SolverCertificate {
                        primal_objective: -sol.obj_val,
                        dual_objective: -sol.obj_val_dual,
                        primal_residual: sol.r_prim,
                        dual_residual: sol.r_dual,
                    },
                })
            });
            for (it, cost) in rx {
                progress(it, cost);
            }
            handle.join().map_err(|_| Error::Numerical("the Clarabel solver thread panicked".into()))?
        })?;
        if raw.status == SdpStatus::CallbackTerminated {
            return Err(Error::Cancelled(format!("the fit was cancelled at Clarabel iteration {}", raw.iterations)));
        }
        Ok(raw)
    }

    /// [`GramProgram::solve`] with `settings`, re-solved with a shorter interior-point step
    /// (`max_step_fraction` 0.9, then 0.7, then 0.9 with the other KKT solver) while Clarabel ends
    /// with `InsufficientProgress` or `NumericalError`, every retry with iterative refinement on;
    /// the returned time and iterations add up every attempt, and `progress` sees the iterations
    /// numbered across attempts. `step_fraction` caps the first attempt's step (None:
    /// [`FIT_STEP_FRACTION`]).
    ///
    /// # Errors
    /// As [`GramProgram::solve`].
    pub fn solve_with_retry(
        &self,
        settings: &SolverSettings,
        step_fraction: Option<Real>,
        progress: &mut dyn FnMut(u32, Real),
    ) -> Result<RawSolution> {
        let mut first = settings.clarabel();
        if let Some(f) = step_fraction {
            first.max_step_fraction = first.max_step_fraction.min(f);
        }
        let mut raw = self.solve(first.clone(), progress)?;
        for (fraction, other_solver) in [(0.9, false), (0.7, false), (0.9, true)] {
            if !matches!(raw.status, SdpStatus::InsufficientProgress | SdpStatus::NumericalError)
                || (!other_solver && first.max_step_fraction <= fraction)
            {
                continue;
            }
            let mut retry = first.clone();
            retry.max_step_fraction = retry.max_step_fraction.min(fraction);
            // A retry is the careful path: refined KKT solves (they cost a third of the time).
            retry.iterative_refinement_enable = true;
            if other_solver {
                retry.direct_solve_method = settings.linear_solver.other().name().into();
            }
            // Iterations keep counting across attempts so that progress never goes back.
            let offset = raw.iterations;
            let next = self.solve(retry, &mut |it, cost| progress(offset + it, cost))?;
            raw = RawSolution {
                solve_seconds: raw.solve_seconds + next.solve_seconds,
                iterations: raw.iterations + next.iterations,
                ..next
            };
        }
        Ok(raw)
    }
}

/// Maps every solver status explicitly: `Solved` / `AlmostSolved` give a usable answer; every
/// other status is an [`Error::Numerical`] naming it and what it usually means for `what` (e.g.
/// `"fit"`, `"containment"`).
///
/// # Errors
/// [`Error::Numerical`] for every status other than `Solved` and `AlmostSolved`.
pub fn usable_status(status: SdpStatus, what: &str) -> Result<SdpStatus> {
    let hint = match status {
        SdpStatus::Solved | SdpStatus::AlmostSolved => return Ok(status),
        SdpStatus::Unsolved => " (the solver did not run)",
        SdpStatus::PrimalInfeasible if what == "containment" => " (no p of this degree passes the S-procedure)",
        SdpStatus::DualInfeasible | SdpStatus::AlmostDualInfeasible => " (log det unbounded: too few hull vertices?)",
        SdpStatus::MaxIterations => " (raise max_solver_iterations)",
        _ => "",
    };
    Err(Error::Numerical(format!("the {what} SDP ended with status {status}{hint}")))
}

/// Largest value of p over `points` (−∞ for none).
pub fn max_on(poly: &Polynomial, points: &[Vector3]) -> Real {
    points.iter().map(|u| poly.value(u)).fold(Real::NEG_INFINITY, Real::max)
}

/// Divides p until `max_i p(uᵢ) ≤ 1` holds in floating point on `points` (one division almost
/// always suffices). The evaluation of p / m can still round to 1 + a few ulps (hand, 2d = 6,
/// c = 10, trace: 1.0000000000000004 after four divisions), so every later division adds a
/// margin of 4ᵏ·10⁻¹⁵ (k = 1, 2, …; at most 3·10⁻¹³ relative in all, far below the Monte Carlo
/// error). Returns (max value, the factor p was divided by). Used after every fit SDP: point
/// clouds (every input point) and containment (boundary samples of every contained body).
///
/// # Errors
/// [`Error::Numerical`] when the largest value is not finite and positive, or stays above 1.
pub fn rescale_to_contain(poly: &mut Polynomial, points: &[Vector3]) -> Result<(Real, Real)> {
    let mut max_value = max_on(poly, points);
    if !max_value.is_finite() || max_value <= 0.0 {
        return Err(Error::Numerical(format!("the fitted polynomial has max value {max_value} on the points")));
    }
    let mut rescale = 1.0;
    for k in 0..6 {
        if max_value <= 1.0 {
            break;
        }
        let divisor = max_value * (1.0 + if k == 0 { 0.0 } else { 1e-15 * (4.0 as Real).powi(k) });
        poly.scale(1.0 / divisor);
        rescale *= divisor;
        max_value = max_on(poly, points);
    }
    if max_value > 1.0 {
        return Err(Error::Numerical(format!("could not rescale p to contain every point (max {max_value})")));
    }
    Ok((max_value, rescale))
}
