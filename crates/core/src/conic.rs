//! A small builder for Clarabel cone programs, shared by the fit SDPs and the query certificates.
//!
//! Clarabel solves
//!
//! ```text
//! minimize ½ xᵀPx + qᵀx   subject to   A x + s = b,  s ∈ K = K₁ × K₂ × …
//! ```
//!
//! The builder appends blocks of rows, each with its cone, in order; variables are plain columns.
//! PSD blocks use Clarabel's packed-triangle convention (see [`crate::poly::gram`]). A variable
//! matrix `Q ⪰ 0` is introduced by [`ConicBuilder::add_psd_variable`], which adds the `N(N+1)/2`
//! columns `s = svec(Q)` and the rows `−s + slack = 0, slack ∈ PSD`.

use crate::poly::gram::triangle_len;
use crate::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

/// One sparse row: `(column, value)` pairs.
pub type Row = Vec<(usize, f64)>;

/// Final status of an SDP (a fit, a containment, a certificate), carried as a value through the
/// core and turned into text only at the edges (JSON, proto, CLI): Clarabel's `SolverStatus`
/// mirrored variant for variant, plus the outcomes of answers that ran no SDP.
///
/// Text form ([`SdpStatus::as_str`], also its serde form): Clarabel's variant names
/// (`"Solved"`, `"AlmostSolved"`, …), `"closed_form"` and `"NotRun"`; any other text reads back as
/// [`SdpStatus::Unknown`] (a body file or upload from another writer never fails to load over it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum SdpStatus {
    /// Solved to the requested tolerance.
    Solved,
    /// Solved to Clarabel's reduced tolerances.
    AlmostSolved,
    /// The solver did not run.
    Unsolved,
    /// Certificate of primal infeasibility.
    PrimalInfeasible,
    /// Certificate of dual infeasibility (an unbounded objective).
    DualInfeasible,
    /// Primal infeasibility to reduced tolerances.
    AlmostPrimalInfeasible,
    /// Dual infeasibility to reduced tolerances.
    AlmostDualInfeasible,
    /// The iteration cap was reached.
    MaxIterations,
    /// The time limit was reached.
    MaxTime,
    /// A numerical failure (e.g. a KKT factorization).
    NumericalError,
    /// The iterates stopped making progress.
    InsufficientProgress,
    /// A callback stopped the solve.
    CallbackTerminated,
    /// No SDP: the answer has a closed form (the inverse moment fit, paper §III-B-1).
    ClosedForm,
    /// No SDP was run (nothing to solve, or a report that predates the field).
    #[default]
    NotRun,
    /// A status text this version does not know (kept readable, never an error).
    Unknown,
}

impl SdpStatus {
    /// Every status, in declaration order.
    pub const ALL: [SdpStatus; 15] = [
        SdpStatus::Solved,
        SdpStatus::AlmostSolved,
        SdpStatus::Unsolved,
        SdpStatus::PrimalInfeasible,
        SdpStatus::DualInfeasible,
        SdpStatus::AlmostPrimalInfeasible,
        SdpStatus::AlmostDualInfeasible,
        SdpStatus::MaxIterations,
        SdpStatus::MaxTime,
        SdpStatus::NumericalError,
        SdpStatus::InsufficientProgress,
        SdpStatus::CallbackTerminated,
        SdpStatus::ClosedForm,
        SdpStatus::NotRun,
        SdpStatus::Unknown,
    ];

    /// The text form (Clarabel's variant name, `"closed_form"`, `"NotRun"`, `"Unknown"`).
    pub fn as_str(&self) -> &'static str {
        match self {
            SdpStatus::Solved => "Solved",
            SdpStatus::AlmostSolved => "AlmostSolved",
            SdpStatus::Unsolved => "Unsolved",
            SdpStatus::PrimalInfeasible => "PrimalInfeasible",
            SdpStatus::DualInfeasible => "DualInfeasible",
            SdpStatus::AlmostPrimalInfeasible => "AlmostPrimalInfeasible",
            SdpStatus::AlmostDualInfeasible => "AlmostDualInfeasible",
            SdpStatus::MaxIterations => "MaxIterations",
            SdpStatus::MaxTime => "MaxTime",
            SdpStatus::NumericalError => "NumericalError",
            SdpStatus::InsufficientProgress => "InsufficientProgress",
            SdpStatus::CallbackTerminated => "CallbackTerminated",
            SdpStatus::ClosedForm => "closed_form",
            SdpStatus::NotRun => "NotRun",
            SdpStatus::Unknown => "Unknown",
        }
    }

    /// Reads the text form; unknown text (and the empty string of old reports: [`SdpStatus::NotRun`])
    /// never fails.
    pub fn parse(s: &str) -> Self {
        if s.is_empty() {
            return SdpStatus::NotRun;
        }
        SdpStatus::ALL.into_iter().find(|v| v.as_str() == s).unwrap_or(SdpStatus::Unknown)
    }

    /// True for `Solved` and `AlmostSolved`: the solver's answer may be used.
    pub fn is_usable(&self) -> bool {
        matches!(self, SdpStatus::Solved | SdpStatus::AlmostSolved)
    }
}

impl std::fmt::Display for SdpStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl From<SolverStatus> for SdpStatus {
    fn from(s: SolverStatus) -> Self {
        match s {
            SolverStatus::Solved => SdpStatus::Solved,
            SolverStatus::AlmostSolved => SdpStatus::AlmostSolved,
            SolverStatus::Unsolved => SdpStatus::Unsolved,
            SolverStatus::PrimalInfeasible => SdpStatus::PrimalInfeasible,
            SolverStatus::DualInfeasible => SdpStatus::DualInfeasible,
            SolverStatus::AlmostPrimalInfeasible => SdpStatus::AlmostPrimalInfeasible,
            SolverStatus::AlmostDualInfeasible => SdpStatus::AlmostDualInfeasible,
            SolverStatus::MaxIterations => SdpStatus::MaxIterations,
            SolverStatus::MaxTime => SdpStatus::MaxTime,
            SolverStatus::NumericalError => SdpStatus::NumericalError,
            SolverStatus::InsufficientProgress => SdpStatus::InsufficientProgress,
            SolverStatus::CallbackTerminated => SdpStatus::CallbackTerminated,
        }
    }
}

impl serde::Serialize for SdpStatus {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> serde::Deserialize<'de> for SdpStatus {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        let s = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
        Ok(SdpStatus::parse(&s))
    }
}

/// Accumulates a cone program for Clarabel.
#[derive(Default, Debug)]
pub struct ConicBuilder {
    num_vars: usize,
    /// Linear objective q (grown as variables are added).
    q: Vec<f64>,
    rows: Vec<Row>,
    b: Vec<f64>,
    cones: Vec<SupportedConeT<f64>>,
}

/// What Clarabel returned.
#[derive(Clone, Debug)]
pub struct ConicSolution {
    /// Primal variables x.
    pub x: Vec<f64>,
    /// Dual variables z (one per row).
    pub z: Vec<f64>,
    /// Slacks s (one per row).
    pub s: Vec<f64>,
    /// Solver status.
    pub status: SolverStatus,
    /// Primal objective qᵀx.
    pub objective: f64,
    /// Seconds inside Clarabel.
    pub solve_seconds: f64,
    /// Interior-point iterations.
    pub iterations: u32,
}

impl ConicSolution {
    /// True for `Solved` and `AlmostSolved`.
    pub fn usable(&self) -> bool {
        matches!(self.status, SolverStatus::Solved | SolverStatus::AlmostSolved)
    }
}

impl ConicBuilder {
    /// An empty program.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds `n` free variables; returns the first column.
    pub fn add_variables(&mut self, n: usize) -> usize {
        let first = self.num_vars;
        self.num_vars += n;
        self.q.resize(self.num_vars, 0.0);
        first
    }

    /// Adds a symmetric `n × n` variable constrained PSD; returns the first column of its packed
    /// triangle (length `n(n+1)/2`, Clarabel's order and √2 scaling).
    pub fn add_psd_variable(&mut self, n: usize) -> usize {
        let len = triangle_len(n);
        let first = self.add_variables(len);
        let rows: Vec<Row> = (0..len).map(|k| vec![(first + k, -1.0)]).collect();
        self.add_rows(rows, vec![0.0; len], SupportedConeT::PSDTriangleConeT(n));
        first
    }

    /// Sets the objective coefficient of column `col` (minimization).
    pub fn set_objective(&mut self, col: usize, value: f64) {
        self.q[col] = value;
    }

    /// Appends equality rows `row · x = rhs`.
    pub fn add_equalities(&mut self, rows: Vec<Row>, rhs: Vec<f64>) {
        let n = rows.len();
        if n > 0 {
            self.add_rows(rows, rhs, SupportedConeT::ZeroConeT(n));
        }
    }

    /// Appends inequality rows `row · x ≤ rhs`.
    pub fn add_inequalities(&mut self, rows: Vec<Row>, rhs: Vec<f64>) {
        let n = rows.len();
        if n > 0 {
            self.add_rows(rows, rhs, SupportedConeT::NonnegativeConeT(n));
        }
    }

    /// Appends rows `b − A x ∈ cone` for an arbitrary cone (rows given as A, right side b).
    pub fn add_rows(&mut self, rows: Vec<Row>, rhs: Vec<f64>, cone: SupportedConeT<f64>) {
        debug_assert_eq!(rows.len(), rhs.len());
        self.rows.extend(rows);
        self.b.extend(rhs);
        self.cones.push(cone);
    }

    /// Number of variables so far.
    pub fn num_variables(&self) -> usize {
        self.num_vars
    }

    /// Number of constraint rows so far.
    pub fn num_rows(&self) -> usize {
        self.rows.len()
    }

    /// Solves with Clarabel (P = 0: every program here has a linear objective).
    ///
    /// Inside a [`crate::cancel::cancellable`] scope the solve stops at the end of the
    /// interior-point iteration during which the scope's flag was set (status
    /// `CallbackTerminated`, an unusable solution).
    ///
    /// # Errors
    /// [`Error::Numerical`] when Clarabel rejects the problem data or settings. A solve that ends
    /// with a non-`Solved` status is not an error: the status is in the returned solution.
    pub fn solve(&self, settings: DefaultSettings<f64>) -> Result<ConicSolution> {
        let m = self.rows.len();
        let n = self.num_vars;
        let (mut ii, mut jj, mut vv) = (Vec::new(), Vec::new(), Vec::new());
        for (r, row) in self.rows.iter().enumerate() {
            for &(c, v) in row {
                if v != 0.0 {
                    ii.push(r);
                    jj.push(c);
                    vv.push(v);
                }
            }
        }
        let a = CscMatrix::new_from_triplets(m, n, ii, jj, vv);
        let p = CscMatrix::zeros((n, n));
        let mut solver = DefaultSolver::new(&p, &self.q, &a, &self.b, &self.cones, settings)
            .map_err(|e| Error::Numerical(format!("Clarabel rejected the problem: {e}")))?;
        if let Some(flag) = crate::cancel::current() {
            // Inside a cancellation scope (a request whose deadline may pass): stop at the end of
            // the current interior-point iteration once the flag is set (CallbackTerminated).
            solver.set_termination_callback(move |_| flag.load(std::sync::atomic::Ordering::Relaxed));
        }
        solver.solve();
        let sol = &solver.solution;
        Ok(ConicSolution {
            x: sol.x.clone(),
            z: sol.z.clone(),
            s: sol.s.clone(),
            status: sol.status,
            objective: sol.obj_val,
            solve_seconds: sol.solve_time,
            iterations: sol.iterations,
        })
    }
}

/// Clarabel settings with quiet output and the given tolerances (Clarabel's defaults are 1e-8).
///
/// The KKT solver is pinned to QDLDL on one thread: these small certificate SDPs were validated with
/// it, and on a shared 2-core machine a multi-threaded factorization only spins. (Fits choose their
/// own solver through `sublevel_fit::FitSettings`.)
pub fn quiet_settings(tol: f64, max_iter: u32) -> DefaultSettings<f64> {
    DefaultSettings {
        verbose: false,
        direct_solve_method: "qdldl".to_string(),
        max_threads: 1,
        tol_gap_abs: tol,
        tol_gap_rel: tol,
        tol_feas: tol,
        max_iter,
        ..DefaultSettings::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smallest_eigenvalue_by_sdp() {
        // max t s.t. M − t I ⪰ 0 for M = [[2, 1], [1, 2]]: t = 1 (smallest eigenvalue).
        // Write M − t I = Q, Q ⪰ 0: entries Q00 = 2 − t, Q01 = 1, Q11 = 2 − t.
        let mut b = ConicBuilder::new();
        let t = b.add_variables(1);
        let q = b.add_psd_variable(2);
        b.set_objective(t, -1.0);
        let s2 = std::f64::consts::SQRT_2;
        b.add_equalities(
            vec![vec![(q, 1.0), (t, 1.0)], vec![(q + 1, 1.0)], vec![(q + 2, 1.0), (t, 1.0)]],
            vec![2.0, s2, 2.0],
        );
        let sol = b.solve(quiet_settings(1e-9, 100)).unwrap();
        assert!(sol.usable());
        assert!((sol.x[t] - 1.0).abs() < 1e-7, "t = {}", sol.x[t]);
    }
}
