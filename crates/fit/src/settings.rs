//! Fit settings, methods and progress reports (paper §III).

use super::hull;
use super::sdp::{self, KktSolver, SolverSettings};
use crate::{Error, Result};
use sublevel_core::math::Real;

/// Which formulation a fit uses (paper §III; the body file's `report.method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FitMethod {
    /// Maximize log det P of the sos Gram matrix, p sos-convex (eq. "VAG.log.det").
    #[default]
    LogDetP,
    /// Minimize trace P⁻¹ via [[V, I],[I, P]] ⪰ 0, p sos-convex (trace form of eq. "VAG.log.det").
    TraceP,
    /// Magnani et al.: maximize log det H of the sos-convexity Gram matrix (eq. "Magnani.log.det").
    LogDetH,
    /// Magnani et al. with the trace objective: minimize trace H⁻¹ (paper §III-A-1).
    TraceH,
    /// Lasserre–Pauwels inverse moment polynomial z(x)ᵀ M_d⁻¹ z(x), scaled to the smallest level
    /// containing every point (eq. "inverse.moment.poly"); no SDP, no convexity.
    InverseMoment,
}

impl FitMethod {
    /// Every method, in Table 1 order.
    pub const ALL: [FitMethod; 5] =
        [FitMethod::LogDetP, FitMethod::TraceP, FitMethod::LogDetH, FitMethod::TraceH, FitMethod::InverseMoment];

    /// The method's name in fit reports, the CLI and the gRPC fit job (`"logdet_p"`, `"trace_p"`,
    /// `"logdet_h"`, `"trace_h"`, `"inverse_moment"`).
    pub fn name(&self) -> &'static str {
        match self {
            FitMethod::LogDetP => "logdet_p",
            FitMethod::TraceP => "trace_p",
            FitMethod::LogDetH => "logdet_h",
            FitMethod::TraceH => "trace_h",
            FitMethod::InverseMoment => "inverse_moment",
        }
    }
}

impl std::str::FromStr for FitMethod {
    type Err = Error;

    /// Parses a method name (see [`FitMethod::name`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `method` for an unknown name.
    fn from_str(s: &str) -> Result<Self> {
        FitMethod::ALL.iter().copied().find(|m| m.name() == s).ok_or_else(|| {
            Error::invalid(
                "method",
                format!("must be one of logdet_p, trace_p, logdet_h, trace_h, inverse_moment, got {s:?}"),
            )
        })
    }
}

/// Settings of a fit.
#[derive(Clone, Debug)]
pub struct FitSettings {
    /// Total degree 2d ∈ {2, 4, 6, 8}.
    pub degree: usize,
    /// Formulation.
    pub method: FitMethod,
    /// Relaxed-convexity parameter c ≥ 0 of eq. "VAG.param.convex": p + c(‖u‖²)ᵈ is required to be
    /// sos-convex instead of p (u = normalized coordinates). 0 (the default) means p sos-convex.
    /// Only for `LogDetP` and `TraceP`; with c > 0 the body may be nonconvex.
    pub convexity_relaxation: Real,
    /// Monte Carlo samples for the volume estimate (at least; doubled up to 16× until the
    /// relative standard error is below 1 %).
    pub volume_samples: usize,
    /// Seed of the volume estimate.
    pub seed: u64,
    /// Clarabel's gap and feasibility tolerance. 1e-6 by default: the fit programs are written in
    /// scaled monomial bases (see [`sdp`]), where the objective settles to 6 digits by a gap
    /// of 1e-6 and Clarabel's gap stalls near 2–5e-7 at 2d = 6, 8 (a tolerance of 1e-8 then ends
    /// `AlmostSolved` after 2–3 more iterations with the same body). Containment is exact
    /// regardless (the rescale after the solve).
    pub solver_tolerance: Real,
    /// Clarabel's iteration cap.
    pub max_solver_iterations: u32,
    /// Direct solver of Clarabel's KKT systems.
    pub linear_solver: KktSolver,
    /// Threads of the KKT factorization (faer only; 0 lets the solver choose, 1 is sequential).
    /// Sequential by default: on a shared 2-core machine rayon's idle spinning costs more than the
    /// second core gains (2d = 6 chair: 0.8 s sequential vs 1.2–1.5 s on 2 threads under load).
    pub solver_threads: u32,
    /// Clarabel's iterative refinement of every KKT solve. Off by default: the refinement steps
    /// (a product with the whole KKT matrix, dense PSD Hessian blocks included, and two
    /// triangular solves each) took a third of the solve at 2d = 8 (chair: 6.7 s without vs
    /// 9.9 s with, same 23 iterations, log det P equal to 7 digits). The retries of
    /// [`sdp::GramProgram::solve_with_retry`] switch it back on.
    pub iterative_refinement: bool,
    /// The frame the SDP is solved in (see [`hull::Normalization`]); the body file always stores
    /// the bounding-cube frame. The log det P / log det H optimum does not depend on it (affine
    /// invariance); the trace objectives and the relaxed-convexity term c(‖u‖²)ᵈ do.
    pub normalization: hull::Normalization,
    /// A second frame for the objectives that depend on the frame — trace P⁻¹ / trace H⁻¹ and
    /// relaxed convexity c > 0: the fit also solves there and keeps the smaller body (both
    /// contain every point; the report's notes give every volume). `PrincipalBox` by default:
    /// on the 65 Table 1 cells of those rows (five shapes) it is ≤ 1.02 × the paper on 45 cells
    /// against 29 for the bounding cube, the whitened frame 45, the principal-axes cube 29; the
    /// smaller of cube and principal box on 47 (all four frames: 48). Ignored for log det with
    /// c = 0, whose optimum is the same body in every frame, and for the inverse moment.
    pub alternate_normalization: Option<hull::Normalization>,
    /// Monomial basis of the trace objectives (trace P⁻¹, trace H⁻¹; see
    /// [`sdp::TraceBasis`]): None (the default) solves in both the plain and the scaled basis
    /// and keeps the smaller body; `Some(Plain)` is the basis the paper writes its programs in.
    /// Ignored by the log det objectives, which do not depend on it.
    pub trace_basis: Option<sdp::TraceBasis>,
    /// Containment rows in rounds (hull vertices and a subsample first, then the violated
    /// points; see [`super::relaxed`]) whatever c is. The path every fit with c > 0 takes (without
    /// convexity the hull vertices no longer suffice); with c = 0 it solves the same program as
    /// the hull rows with extra inactive rows, so it gives the same body up to the solver
    /// tolerance. Only `LogDetP` and `TraceP`. Off by default.
    pub rows_in_rounds: bool,
    /// The cone of the sos-convexity Gram matrix ([`sdp::ConvexityCone`]): psd (the default, the
    /// paper's sos-convexity), or the sdsos / dsos inner approximations of paper §VI, an SOCP or LP
    /// constraint in place of the psd one. Only with the objective on P (`LogDetP`, `TraceP`); the
    /// body stays convex and contains every point, but is larger, and depends on the frame.
    pub convexity_cone: sdp::ConvexityCone,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            degree: 4,
            method: FitMethod::LogDetP,
            convexity_relaxation: 0.0,
            volume_samples: 200_000,
            seed: 1,
            solver_tolerance: 1e-6,
            max_solver_iterations: 200,
            linear_solver: KktSolver::default(),
            solver_threads: 1,
            iterative_refinement: false,
            normalization: hull::Normalization::BoundingCube,
            alternate_normalization: Some(hull::Normalization::PrincipalBox),
            trace_basis: None,
            rows_in_rounds: false,
            convexity_cone: sdp::ConvexityCone::Psd,
        }
    }
}

impl FitSettings {
    /// Sets the total degree 2d.
    pub fn with_degree(mut self, degree: usize) -> Self {
        self.degree = degree;
        self
    }

    /// Sets the Monte Carlo sample count.
    pub fn with_volume_samples(mut self, samples: usize) -> Self {
        self.volume_samples = samples;
        self
    }

    /// Sets the Monte Carlo seed.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Sets Clarabel's tolerance.
    pub fn with_solver_tolerance(mut self, tol: Real) -> Self {
        self.solver_tolerance = tol;
        self
    }

    /// Sets the formulation.
    pub fn with_method(mut self, method: FitMethod) -> Self {
        self.method = method;
        self
    }

    /// Sets the frame the SDP is solved in.
    pub fn with_normalization(mut self, normalization: hull::Normalization) -> Self {
        self.normalization = normalization;
        self
    }

    /// Sets (or, with None, removes) the second frame of the frame-dependent objectives.
    pub fn with_alternate_normalization(mut self, normalization: Option<hull::Normalization>) -> Self {
        self.alternate_normalization = normalization;
        self
    }

    /// True when the fitted body depends on the frame the SDP is solved in: trace objectives
    /// (trace X⁻¹ changes under a change of monomial basis), relaxed convexity c > 0 (the term
    /// c(‖u‖²)ᵈ is not affine-invariant) and the dd / sdd cones (not invariant under a change of
    /// frame). log det P / log det H with c = 0 and the inverse moment
    /// give the same body in every frame.
    pub fn depends_on_frame(&self) -> bool {
        matches!(self.method, FitMethod::TraceP | FitMethod::TraceH)
            || self.convexity_relaxation > 0.0
            || self.convexity_cone != sdp::ConvexityCone::Psd
    }

    /// Sets the cone of the sos-convexity Gram matrix ([`FitSettings::convexity_cone`]).
    pub fn with_convexity_cone(mut self, cone: sdp::ConvexityCone) -> Self {
        self.convexity_cone = cone;
        self
    }

    /// Sets the relaxed-convexity parameter c (normalized coordinates, eq. "VAG.param.convex").
    pub fn with_relaxation(mut self, c: Real) -> Self {
        self.convexity_relaxation = c;
        self
    }

    /// Sets whether containment rows are added in rounds whatever c is (see
    /// [`FitSettings::rows_in_rounds`]).
    pub fn with_rows_in_rounds(mut self, rounds: bool) -> Self {
        self.rows_in_rounds = rounds;
        self
    }

    /// Clarabel's settings of this fit's SDPs (tolerance, iteration cap, KKT solver, threads,
    /// refinement), built into Clarabel's settings in one place ([`SolverSettings::clarabel`]).
    pub fn solver_settings(&self) -> SolverSettings {
        SolverSettings {
            tolerance: self.solver_tolerance,
            max_iterations: self.max_solver_iterations,
            linear_solver: self.linear_solver,
            threads: self.solver_threads,
            iterative_refinement: self.iterative_refinement,
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree`, `volume_samples`, `solver_tolerance`,
    /// `max_solver_iterations`, `convexity_relaxation` (negative, not finite, or > 0 with a
    /// method other than `LogDetP` / `TraceP`), `convexity_cone` (dd or sdd with a method other
    /// than those) or `method` (rows in rounds with another method).
    pub fn validate(&self) -> Result<()> {
        if !sublevel_core::body::SUPPORTED_DEGREES.contains(&self.degree) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {}", self.degree)));
        }
        validate_solver_fields(self.volume_samples, self.solver_tolerance, self.max_solver_iterations)?;
        let c = self.convexity_relaxation;
        if !(c.is_finite() && c >= 0.0) {
            return Err(Error::invalid("convexity_relaxation", format!("must be finite and ≥ 0, got {c}")));
        }
        if c > 0.0 && !matches!(self.method, FitMethod::LogDetP | FitMethod::TraceP) {
            return Err(Error::invalid(
                "convexity_relaxation",
                format!("only logdet_p and trace_p take a relaxation c > 0, not {}", self.method.name()),
            ));
        }
        if self.convexity_cone != sdp::ConvexityCone::Psd
            && !matches!(self.method, FitMethod::LogDetP | FitMethod::TraceP)
        {
            return Err(Error::invalid(
                "convexity_cone",
                format!("only logdet_p and trace_p take the dd or sdd cone, not {}", self.method.name()),
            ));
        }
        if self.rows_in_rounds && !matches!(self.method, FitMethod::LogDetP | FitMethod::TraceP) {
            return Err(Error::invalid("method", "containment rows in rounds are for logdet_p and trace_p"));
        }
        Ok(())
    }
}

/// Stages a fit reports progress for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitStage {
    /// Computing the convex hull.
    Hull,
    /// Building the cone program.
    Build,
    /// Clarabel is solving.
    Solve,
    /// Checking containment on every point (and rescaling).
    Verify,
    /// Estimating the volume.
    Volume,
    /// Finished.
    Done,
}

/// One progress report of a fit.
#[derive(Clone, Debug)]
pub struct FitProgress {
    /// Current stage.
    pub stage: FitStage,
    /// Overall completion in [0, 1] (never decreases within one fit).
    pub fraction: Real,
    /// Human-readable detail.
    pub message: String,
    /// In a compound fit ([`crate::compound::fit_compound`]), the part whose body is being
    /// fitted; `None` outside the part fits (decomposition, parents) and in single-body fits.
    pub part: Option<PartProgress>,
}

/// Which part of a compound fit a progress report is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PartProgress {
    /// The part being fitted, 1-based.
    pub index: usize,
    /// Parts of the current attempt (VHACD's parts, or the leaves once the refinement's current
    /// split is done); `index ≤ count`.
    pub count: usize,
}

/// Checks the Monte Carlo and solver fields shared by every fit and containment job.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `volume_samples` (not in 1..=1e9), `solver_tolerance` (not in
/// (0, 1e-2)) or `max_solver_iterations` (0).
pub(crate) fn validate_solver_fields(volume_samples: usize, tolerance: Real, max_iterations: u32) -> Result<()> {
    if volume_samples == 0 || volume_samples > 1_000_000_000 {
        return Err(Error::invalid("volume_samples", "must be between 1 and 1e9"));
    }
    if !(tolerance.is_finite() && tolerance > 0.0 && tolerance < 1e-2) {
        return Err(Error::invalid("solver_tolerance", format!("must be in (0, 1e-2), got {tolerance}")));
    }
    if max_iterations == 0 {
        return Err(Error::invalid("max_solver_iterations", "must be at least 1"));
    }
    Ok(())
}

/// Sends one progress report.
pub(crate) fn report(progress: &mut dyn FnMut(&FitProgress), stage: FitStage, fraction: Real, message: String) {
    progress(&FitProgress { stage, fraction, message, part: None });
}
