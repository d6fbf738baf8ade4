//! Fitting bodies to point clouds (paper §III: §III-A sos-convex, §III-B relaxed / inverse moment).
//!
//! [`fit_points`] turns a cloud into a [`Body`] `{x : p((x − c)/s) ≤ 1}` with p of
//! degree 2d (sos-convex unless the method relaxes convexity), in five stages, each reported
//! through the progress callback:
//!
//! ```text
//! Hull    validate, normalize (u = (x − c)/s, bounding box in [−1, 1]³), convex hull, and
//!         the frame(s) the SDP is solved in (u_fit = L·u + o; trace and c > 0 fits solve in
//!         the bounding cube and the principal box and keep the smaller body)      (hull.rs)
//! Build   the cone program of the method (log det / trace of P or H)                 (logdet_p.rs)
//!         or the moment matrix (inverse moment)                              (inverse_moment.rs)
//! Solve   Clarabel, one progress report per interior-point iteration; with relaxed
//!         convexity in rounds that add violated points as rows                     (relaxed.rs)
//! Verify  p on EVERY input point; if max p(uᵢ) > 1, divide p by it (exact containment)
//! Volume  seeded Monte Carlo in a provably containing box (convex bodies) or in cells
//!         proven to cover {p ≤ 1} (nonconvex sos bodies)                              (volume.rs)
//! ```
//!
//! Containment is never approximate: after the final rescale `max_i p(uᵢ) ≤ 1` holds in floating
//! point on every input point, and the largest value is recorded in the report.

use crate::body::{Body, FitReport};
use crate::math::{Point3, Real};
use crate::poly::Polynomial;
use crate::{Error, Result};

pub mod auto;
pub mod baselines;
pub mod containment;
pub mod hull;
pub mod inverse_moment;
pub mod logdet_p;
pub mod mesh;
pub mod relaxed;
pub mod sos_convexity;
pub mod volume;

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

/// Direct solver Clarabel uses for its KKT systems (`direct_solve_method`).
///
/// The KKT matrix of the fit holds the dense Hessian blocks of the two PSD cones (at 2d = 8 the
/// 70 × 70 log-det block and the 60 × 60 sos-convexity Gram, i.e. dense 2485² and 1830²
/// blocks), so a supernodal factorization (faer, blocked dense kernels, threads) is much faster
/// than QDLDL's simplicial one there.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum KktSolver {
    /// faer's sparse LDLᵀ (supernodal for dense fill, simplicial otherwise).
    #[default]
    Faer,
    /// QDLDL, Clarabel's simplicial LDLᵀ (its default without the `faer-sparse` feature).
    Qdldl,
}

impl KktSolver {
    /// Clarabel's name of the method (`"faer"`, `"qdldl"`).
    pub fn name(&self) -> &'static str {
        match self {
            KktSolver::Faer => "faer",
            KktSolver::Qdldl => "qdldl",
        }
    }
}

impl std::str::FromStr for KktSolver {
    type Err = Error;

    /// Parses `"faer"` or `"qdldl"`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `linear_solver` for any other name.
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "faer" => Ok(KktSolver::Faer),
            "qdldl" => Ok(KktSolver::Qdldl),
            other => Err(Error::invalid("linear_solver", format!("must be faer or qdldl, got {other:?}"))),
        }
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
    /// scaled monomial bases (see [`logdet_p`]), where the objective settles to 6 digits by a gap
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
    /// [`logdet_p::LogDetProblem::solve_with_retry`] switch it back on.
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
    /// [`logdet_p::TraceBasis`]): None (the default) solves in both the plain and the scaled basis
    /// and keeps the smaller body; `Some(Plain)` is the basis the paper writes its programs in.
    /// Ignored by the log det objectives, which do not depend on it.
    pub trace_basis: Option<logdet_p::TraceBasis>,
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
    /// (trace X⁻¹ changes under a change of monomial basis) and relaxed convexity c > 0 (the term
    /// c(‖u‖²)ᵈ is not affine-invariant). log det P / log det H with c = 0 and the inverse moment
    /// give the same body in every frame.
    pub fn depends_on_frame(&self) -> bool {
        matches!(self.method, FitMethod::TraceP | FitMethod::TraceH) || self.convexity_relaxation > 0.0
    }

    /// Sets the relaxed-convexity parameter c (normalized coordinates, eq. "VAG.param.convex").
    pub fn with_relaxation(mut self, c: Real) -> Self {
        self.convexity_relaxation = c;
        self
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree`, `volume_samples`, `solver_tolerance`,
    /// `max_solver_iterations` or `convexity_relaxation` (negative, not finite, or > 0 with a
    /// method other than `LogDetP` / `TraceP`).
    pub fn validate(&self) -> Result<()> {
        if !crate::body::SUPPORTED_DEGREES.contains(&self.degree) {
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
    /// Overall completion in [0, 1].
    pub fraction: Real,
    /// Human-readable detail.
    pub message: String,
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
    progress(&FitProgress { stage, fraction, message });
}

/// Fits a body to a point cloud with the formulation `settings.method` (paper §III).
///
/// `points` are in the mesh's units (meters). The returned body stores its polynomial in
/// normalized coordinates `u = (x − center)/scale` (see [`hull`] for the choice of center and
/// scale); its report holds the solver status, timings, hull and volume figures, the containment
/// rescale and the convexity margin.
///
/// - `LogDetP`, `TraceP`, `LogDetH`, `TraceH` with c = 0: p sos-convex, containment rows on the
///   convex-hull vertices only (a convex sublevel set containing them contains the cloud); the
///   margin is λ_min of the sos-convexity Gram matrix G of the final, rescaled p.
/// - `LogDetP`, `TraceP` with c = `convexity_relaxation` > 0 (eq. "VAG.param.convex"): p + c(‖u‖²)ᵈ
///   sos-convex in normalized coordinates u (the cloud's bounding box is normalized into [−1, 1]³; see
///   [`hull`] for why this scale). The body may be nonconvex, so containment rows are added in rounds (see
///   [`relaxed`]) until p ≤ 1 on every point; `report.nonconvex` is set and the margin is that of
///   the relaxed Gram matrix (of p + c(‖u‖²)ᵈ, divided by the containment rescale).
/// - `InverseMoment` (eq. "inverse.moment.poly", see [`inverse_moment`]): no SDP, nonconvex, no
///   margin.
///
/// Every body contains every input point: after the final rescale `max_i p(uᵢ) ≤ 1` holds in
/// floating point, and the largest value is recorded in the report.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for an empty, non-finite or degenerate cloud (for the
/// inverse moment also a singular moment matrix), or a settings field; [`Error::Numerical`] when
/// Clarabel ends with a status other than `Solved` / `AlmostSolved` (the status is named) or the
/// result is not a bounded body.
pub fn fit_points(points: &[Point3], settings: &FitSettings, progress: &mut dyn FnMut(&FitProgress)) -> Result<Body> {
    fit_impl(points, settings, settings.convexity_relaxation > 0.0, progress)
}

/// [`fit_points`] for `LogDetP` / `TraceP` with containment rows added in rounds (hull vertices
/// and a subsample first, then the violated points) whatever c is — the path `fit_points` takes
/// for c > 0. With c = 0 it solves the same program as [`fit_points`] with extra inactive rows,
/// so it returns the same body up to the solver tolerance.
///
/// # Errors
/// As [`fit_points`]; [`Error::InvalidArgument`] naming `method` for another method.
pub fn fit_points_in_rounds(
    points: &[Point3],
    settings: &FitSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    if !matches!(settings.method, FitMethod::LogDetP | FitMethod::TraceP) {
        return Err(Error::invalid("method", "containment rounds are for logdet_p and trace_p"));
    }
    fit_impl(points, settings, true, progress)
}

/// What a formulation hands to the common verify / volume stages.
pub(crate) struct Solved {
    /// p before the containment rescale (normalized coordinates).
    pub(crate) poly: Polynomial,
    pub(crate) solver_status: String,
    pub(crate) solve_seconds: Real,
    /// Sos-convexity Gram matrix of p (or of p + c q when relaxed), if the method has one.
    pub(crate) convexity_gram: Option<nalgebra::DMatrix<Real>>,
    /// Sos Gram matrix P of p = zᵀPz, for the volume box of a nonconvex body.
    pub(crate) sos_gram: Option<nalgebra::DMatrix<Real>>,
    pub(crate) nonconvex: bool,
    /// Primal / dual objectives of the (last) SDP solve, if there was one.
    pub(crate) certificate: Option<crate::body::SolverCertificate>,
    pub(crate) notes: Vec<String>,
}

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
/// noise (chair, log det P, 2d = 6 / 8: 0.33 / 3.64 s before, 0.24 / 3.63 s after, one run each at
/// load ≈ 1.4). Only the regularization of the linear solves changes; the stopping test is on the
/// true residuals.
pub const FIT_STATIC_REGULARIZATION: Real = 1e-7;

fn clarabel_settings(settings: &FitSettings) -> clarabel::solver::DefaultSettings<Real> {
    let mut clarabel = crate::conic::quiet_settings(settings.solver_tolerance, settings.max_solver_iterations);
    clarabel.max_step_fraction = FIT_STEP_FRACTION;
    clarabel.direct_solve_method = settings.linear_solver.name().into();
    clarabel.max_threads = settings.solver_threads;
    clarabel.iterative_refinement_enable = settings.iterative_refinement;
    clarabel.static_regularization_constant = FIT_STATIC_REGULARIZATION;
    clarabel
}

fn spec_of(settings: &FitSettings, trace_basis: logdet_p::TraceBasis) -> logdet_p::ProblemSpec {
    use logdet_p::{Objective, ObjectiveMatrix};
    let (objective, matrix) = match settings.method {
        FitMethod::TraceP => (Objective::Trace, ObjectiveMatrix::P),
        FitMethod::LogDetH => (Objective::LogDet, ObjectiveMatrix::H),
        FitMethod::TraceH => (Objective::Trace, ObjectiveMatrix::H),
        FitMethod::LogDetP | FitMethod::InverseMoment => (Objective::LogDet, ObjectiveMatrix::P),
    };
    logdet_p::ProblemSpec {
        half_degree: settings.degree / 2,
        objective,
        matrix,
        convexity_relaxation: settings.convexity_relaxation,
        trace_basis,
    }
}

/// Name of the objective for progress messages.
fn objective_label(spec: &logdet_p::ProblemSpec) -> &'static str {
    use logdet_p::{Objective, ObjectiveMatrix};
    match (spec.objective, spec.matrix) {
        (Objective::LogDet, ObjectiveMatrix::P) => "log det P",
        (Objective::LogDet, ObjectiveMatrix::H) => "log det H",
        (Objective::Trace, ObjectiveMatrix::P) => "−trace P⁻¹",
        (Objective::Trace, ObjectiveMatrix::H) => "−trace H⁻¹",
    }
}

fn fit_impl(
    points: &[Point3],
    settings: &FitSettings,
    rounds: bool,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    let start = std::time::Instant::now();
    settings.validate()?;
    report(progress, FitStage::Hull, 0.0, format!("convex hull of {} points", points.len()));
    let body_cloud = hull::normalize_and_hull(points)?;
    // The SDP is solved in the frame of `settings.normalization`; the body is stored in the
    // bounding-cube frame of `body_cloud` (identity frame by default).
    let (frame, cloud) = body_cloud.reframed(settings.normalization)?;
    let frames = Frames { body: &body_cloud, frame, fit: &cloud };
    let d = settings.degree / 2;
    if settings.method == FitMethod::InverseMoment {
        report(progress, FitStage::Build, 0.05, format!("degree-{} moment matrix of {} points", 2 * d, points.len()));
        let solved = inverse_moment::solve(d, &cloud.points)?;
        return finish(start, points.len(), &frames, solved, settings, progress);
    }
    // Frame-dependent objectives are solved in every candidate frame (and, for the trace
    // objectives, in both monomial bases, see `TraceBasis`); the smallest body is kept. Every
    // candidate contains every point (each goes through `finish`).
    let mut spaces = vec![(settings.normalization, frame, cloud)];
    if let Some(alt) = settings.alternate_normalization {
        if settings.depends_on_frame() && alt != settings.normalization {
            let (alt_frame, alt_cloud) = body_cloud.reframed(alt)?;
            spaces.push((alt, alt_frame, alt_cloud));
        }
    }
    let is_trace = matches!(settings.method, FitMethod::TraceP | FitMethod::TraceH);
    let bases: &[logdet_p::TraceBasis] = match settings.trace_basis {
        None if is_trace => &[logdet_p::TraceBasis::Plain, logdet_p::TraceBasis::Scaled],
        Some(logdet_p::TraceBasis::Scaled) if is_trace => &[logdet_p::TraceBasis::Scaled],
        _ => &[logdet_p::TraceBasis::Plain],
    };
    let mut best: Option<Body> = None;
    let mut first_error: Option<Error> = None;
    let mut tried = Vec::new();
    let mut candidates = Vec::new();
    let mut solve_seconds = 0.0;
    for (normalization, frame, cloud) in &spaces {
        let frames = Frames { body: &body_cloud, frame: *frame, fit: cloud };
        let in_frame = FitSettings { normalization: *normalization, ..settings.clone() };
        for &basis in bases {
            let solved = if rounds {
                solve_in_rounds(cloud, &in_frame, basis, progress)
            } else {
                solve_on_hull(cloud, &in_frame, basis, progress)
            };
            let name = match basis {
                logdet_p::TraceBasis::Plain if bases.len() > 1 => format!("{}/plain basis", normalization.name()),
                logdet_p::TraceBasis::Scaled => format!("{}/scaled basis", normalization.name()),
                logdet_p::TraceBasis::Plain => normalization.name().to_string(),
            };
            match solved.and_then(|solved| finish(start, points.len(), &frames, solved, &in_frame, progress)) {
                Ok(body) => {
                    solve_seconds += body.report.solve_seconds;
                    tried.push(format!("{name} {:.4}", body.report.volume));
                    candidates.push((name, body.report.volume));
                    if best.as_ref().is_none_or(|b| body.report.volume < b.report.volume) {
                        best = Some(body);
                    }
                }
                Err(e) => {
                    tried.push(format!("{name} failed ({e})"));
                    first_error.get_or_insert(e);
                }
            }
        }
    }
    let Some(mut body) = best else {
        return Err(first_error.unwrap_or_else(|| Error::Numerical("no fit was attempted".into())));
    };
    if tried.len() > 1 {
        body.report.notes.push(format!(
            "kept the smallest of {} solves, each containing every point (volumes: {})",
            tried.len(),
            tried.join(", ")
        ));
        body.report.solve_seconds = solve_seconds;
        body.report.total_seconds = start.elapsed().as_secs_f64();
        body.report.candidate_volumes = candidates;
    }
    Ok(body)
}

/// c = 0: one SDP with containment rows on the hull vertices.
fn solve_on_hull(
    cloud: &hull::NormalizedCloud,
    settings: &FitSettings,
    trace_basis: logdet_p::TraceBasis,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Solved> {
    let spec = spec_of(settings, trace_basis);
    report(
        progress,
        FitStage::Build,
        0.05,
        format!("building the degree-{} program on {} hull vertices", settings.degree, cloud.hull_vertices.len()),
    );
    let problem = logdet_p::LogDetProblem::build_spec(&spec, &cloud.hull_vertices)?;
    report(
        progress,
        FitStage::Solve,
        0.1,
        format!("Clarabel: {} variables, {} rows", problem.num_vars, problem.num_rows()),
    );
    let label = objective_label(&spec);
    let raw = problem.solve_with_retry(&clarabel_settings(settings), &mut |it, cost| {
        // Interior-point methods take 20–40 iterations here; map them onto [0.1, 0.8].
        let frac = 0.1 + 0.7 * (it as Real / 40.0).min(1.0);
        report(progress, FitStage::Solve, frac, format!("Clarabel iteration {it}, {label} ≈ {:.6}", -cost));
    })?;
    let status = logdet_p::usable_status(raw.status)?;
    let gram = problem.gram(&raw.x);
    Ok(Solved {
        poly: problem.polynomial_of_gram(&gram)?,
        solver_status: status.into(),
        solve_seconds: raw.solve_seconds,
        convexity_gram: Some(problem.convexity_gram(&raw.x)),
        sos_gram: Some(gram),
        nonconvex: false,
        certificate: Some(raw.certificate),
        notes: vec![format!(
            "normalized by center = bounding-box midpoint, scale = half its longest side; Clarabel {} iterations ({})",
            raw.iterations,
            settings.linear_solver.name()
        )],
    })
}

/// Containment rows in rounds (relaxed convexity, or any c through [`fit_points_in_rounds`]).
fn solve_in_rounds(
    cloud: &hull::NormalizedCloud,
    settings: &FitSettings,
    trace_basis: logdet_p::TraceBasis,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Solved> {
    let spec = spec_of(settings, trace_basis);
    report(
        progress,
        FitStage::Build,
        0.05,
        format!(
            "degree-{} program, c = {}, containment rows in rounds over {} points",
            settings.degree,
            settings.convexity_relaxation,
            cloud.points.len()
        ),
    );
    let label = objective_label(&spec);
    let out = relaxed::solve_in_rounds(cloud, &spec, &clarabel_settings(settings), &mut |round, it, cost| {
        // Round r takes [0.1 + 0.7(1 − 1/(r+1)), 0.1 + 0.7(1 − 1/(r+2))].
        let r = round as Real;
        let lo = 0.1 + 0.7 * (1.0 - 1.0 / (r + 1.0));
        let hi = 0.1 + 0.7 * (1.0 - 1.0 / (r + 2.0));
        let frac = lo + (hi - lo) * (it as Real / 40.0).min(1.0);
        report(
            progress,
            FitStage::Solve,
            frac,
            format!("Clarabel iteration {it} (containment round {}), {label} ≈ {:.6}", round + 1, -cost),
        );
    })?;
    let rows: Vec<String> = out.rows_per_round.iter().map(|r| r.to_string()).collect();
    let mut notes = vec![
        format!(
            "normalized by center = bounding-box midpoint, scale = half its longest side; Clarabel {} iterations in all ({})",
            out.iterations,
            settings.linear_solver.name()
        ),
        format!(
            "relaxed convexity c = {} (normalized coordinates, bounding box in [−1, 1]³): {} containment round(s), rows {} of {} points",
            settings.convexity_relaxation,
            out.rows_per_round.len(),
            rows.join(" → "),
            cloud.points.len()
        ),
    ];
    if let Some(why) = &out.failed_round {
        notes.push(format!("{why}: kept the previous round's solution; the final rescale restores containment"));
    } else if !out.converged {
        notes.push(format!(
            "round cap {} reached with points still outside; the final rescale restores containment",
            relaxed::MAX_ROUNDS
        ));
    }
    Ok(Solved {
        poly: out.polynomial,
        solver_status: out.status.into(),
        solve_seconds: out.solve_seconds,
        convexity_gram: Some(out.convexity_gram),
        sos_gram: Some(out.gram),
        nonconvex: settings.convexity_relaxation > 0.0,
        certificate: Some(out.certificate),
        notes,
    })
}

/// The body's normalized cloud, the frame the SDP was solved in and the cloud in that frame.
struct Frames<'a> {
    body: &'a hull::NormalizedCloud,
    frame: hull::Frame,
    fit: &'a hull::NormalizedCloud,
}

/// Largest value of p over `points` (−∞ for none).
fn max_on(poly: &Polynomial, points: &[crate::math::Vector3]) -> Real {
    points.iter().map(|u| poly.value(u)).fold(Real::NEG_INFINITY, Real::max)
}

/// Divides p until `max_i p(uᵢ) ≤ 1` holds in floating point (one division almost always
/// suffices). The evaluation of p / m can still round to 1 + a few ulps (hand, 2d = 6, c = 10,
/// trace: 1.0000000000000004 after four divisions), so every later division adds a margin of
/// 4ᵏ·10⁻¹⁵ (k = 1, 2, …; at most 3·10⁻¹³ relative in all, far below the Monte Carlo error).
/// Returns (max value, the factor p was divided by).
fn rescale_to_contain(poly: &mut Polynomial, points: &[crate::math::Vector3]) -> Result<(Real, Real)> {
    let mut max_value = max_on(poly, points);
    if !max_value.is_finite() || max_value <= 0.0 {
        return Err(Error::Numerical(format!("fitted polynomial has max value {max_value} on the cloud")));
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

/// Verify (containment rescale), body construction and volume, common to every method.
///
/// `solved.poly` is in the fit frame; the body stores p_body(u) = p_fit(L u + o) (exact
/// composition, [`Polynomial::compose_affine`]) in the bounding-cube frame, and containment is
/// checked on every point in both frames. The volume is estimated in the fit frame and divided
/// by |det L|.
fn finish(
    start: std::time::Instant,
    num_points: usize,
    frames: &Frames<'_>,
    solved: Solved,
    settings: &FitSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    report(progress, FitStage::Verify, 0.8, format!("checking p ≤ 1 on all {} points", num_points));
    let mut poly_fit = solved.poly;
    let (mut max_value, mut rescale) = rescale_to_contain(&mut poly_fit, &frames.fit.points)?;
    let mut notes = solved.notes;
    let poly = if frames.frame.is_identity() {
        poly_fit.clone()
    } else {
        let mut composed = poly_fit.compose_affine(&frames.frame.linear, &frames.frame.offset);
        let (max_body, extra) = rescale_to_contain(&mut composed, &frames.body.points)?;
        if extra != 1.0 {
            poly_fit.scale(1.0 / extra);
            rescale *= extra;
        }
        max_value = max_body;
        notes.push(format!(
            "SDP solved in the {} frame (u_fit = L·u + o, |det L| = {:.6}); body stored in the bounding-cube frame",
            settings.normalization.name(),
            frames.frame.jacobian()
        ));
        composed
    };
    let margin = solved
        .convexity_gram
        .map(|g| (g / rescale).symmetric_eigenvalues().iter().copied().fold(Real::INFINITY, Real::min));

    let cloud = frames.body;
    let mut fit_report = FitReport {
        method: settings.method.name().into(),
        solver_status: solved.solver_status,
        solve_seconds: solved.solve_seconds,
        total_seconds: 0.0,
        num_points,
        num_hull_vertices: cloud.hull_vertices.len(),
        volume: 0.0,
        volume_std_error: 0.0,
        hull_volume: cloud.hull_volume(),
        max_point_value: max_value,
        containment_rescale: rescale,
        convexity_margin: margin,
        notes,
        convexity_relaxation: settings.convexity_relaxation,
        nonconvex: solved.nonconvex,
        solver_certificate: solved.certificate,
        ..Default::default()
    };
    let center = [cloud.center.x, cloud.center.y, cloud.center.z];
    let body = Body::new(poly, center, cloud.scale, fit_report.clone())
        .map_err(|e| Error::Numerical(format!("the fitted polynomial is not a bounded body: {e}")))?;

    report(progress, FitStage::Volume, 0.85, format!("Monte Carlo volume, {} samples", settings.volume_samples));
    let est = if solved.nonconvex {
        let gram = solved
            .sos_gram
            .ok_or_else(|| Error::Numerical("a nonconvex body needs its sos Gram matrix for the volume box".into()))?;
        let lambda = (gram / rescale).symmetric_eigenvalues().iter().copied().fold(Real::INFINITY, Real::min);
        let est = volume::monte_carlo_volume_sos(&poly_fit, lambda, settings.volume_samples, settings.seed)?;
        fit_report.notes.push(format!(
            "volume box: cells of side {:.4} covering {{p ≤ 1}} inside the ball |u| ≤ {:.3} (λ_min(P) = {lambda:.3e})",
            est.cell_side, est.radius
        ));
        est.estimate
    } else {
        let interior = frames.frame.apply(&((body.interior_point().coords - cloud.center) / cloud.scale));
        volume::monte_carlo_volume(&poly_fit, &interior, settings.volume_samples, settings.seed)?
    };
    let to_input_units = cloud.scale.powi(3) / frames.frame.jacobian();
    fit_report.volume = est.volume * to_input_units;
    fit_report.volume_std_error = est.std_error * to_input_units;
    fit_report.total_seconds = start.elapsed().as_secs_f64();
    // A derived figure that overflowed (e.g. the volume of an enormous cloud) is stored as a
    // representable number with a note: JSON has no infinity, and the body file must read back.
    fit_report.sanitize_non_finite();
    let mut body = body;
    body.report = fit_report;
    report(
        progress,
        FitStage::Done,
        1.0,
        format!(
            "volume {:.4} ± {:.4} (hull {:.4})",
            body.report.volume, body.report.volume_std_error, body.report.hull_volume
        ),
    );
    Ok(body)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kkt_solver_names_round_trip() {
        for s in [KktSolver::Faer, KktSolver::Qdldl] {
            assert_eq!(s.name().parse::<KktSolver>().unwrap(), s);
        }
        match "pardiso".parse::<KktSolver>() {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "linear_solver"),
            other => panic!("expected InvalidArgument(linear_solver), got {other:?}"),
        }
    }

    #[test]
    fn settings_are_validated_by_field() {
        let pts: Vec<Point3> =
            (0..10).map(|i| Point3::new(i as Real, (i * i) as Real, (i * i * i % 5) as Real)).collect();
        for (s, field) in [
            (FitSettings::default().with_degree(3), "degree"),
            (FitSettings::default().with_degree(10), "degree"),
            (FitSettings::default().with_volume_samples(0), "volume_samples"),
            (FitSettings::default().with_solver_tolerance(Real::NAN), "solver_tolerance"),
            (FitSettings { max_solver_iterations: 0, ..Default::default() }, "max_solver_iterations"),
        ] {
            match fit_points(&pts, &s, &mut |_| {}) {
                Err(Error::InvalidArgument { field: f, .. }) => assert_eq!(f, field),
                other => panic!("expected InvalidArgument({field}), got {other:?}"),
            }
        }
    }
}
