//! `sublevel fit MESH --degree 6 [--method trace_h] [--relaxation 10] --output body.json`: fit a body to a mesh (paper §III-A) and
//! write its JSON body file. Progress (stage and Clarabel iteration) goes to stderr, a one-line
//! summary to stdout. `--degree auto --volume-tolerance τ` fits 2, 4, 6, 8 in turn and keeps the
//! lowest degree within τ of the next one (see [`sublevel::fit::auto`]).
//!
//! With `--parts N|auto` the mesh (a triangle mesh: OFF, OBJ, STL, PLY or COLLADA) becomes a compound
//! body instead: a convex decomposition fitted part by part under a containment tree (see
//! [`super::fit_compound`] and [`sublevel::compound`]); `--tolerance T` is then the leaf-excess
//! tolerance in meters (for `--parts auto` by default 1 % of the mesh's bounding-box diagonal).

use std::io::Write;
use std::path::PathBuf;
use sublevel::fit::sdp::TraceBasis;
use sublevel::fit::{auto, fit_points, mesh, FitMethod, FitProgress, FitSettings, FitStage};

/// `--degree`: a total degree 2d, or `auto`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DegreeArg {
    /// A fixed total degree 2d.
    Fixed(usize),
    /// Choose among 2, 4, 6, 8 by `--volume-tolerance` (see [`sublevel::fit::auto`]).
    Auto,
}

impl std::str::FromStr for DegreeArg {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(DegreeArg::Auto);
        }
        s.parse::<usize>().map(DegreeArg::Fixed).map_err(|_| format!("expected 2, 4, 6, 8 or auto, got {s:?}"))
    }
}

/// Arguments of `sublevel fit`.
#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Mesh or point cloud (.off, .obj, .stl, .ply, .xyz).
    pub mesh: PathBuf,
    /// Total degree 2d of the polynomial: 2, 4, 6, 8, or `auto` (the lowest degree whose volume
    /// is within --volume-tolerance of the next degree's; with --parts, per part: the lowest of
    /// 2, 4, 6 whose excess is within --tolerance). Default: 4, and `auto` with --parts.
    #[arg(long, short)]
    pub degree: Option<DegreeArg>,
    /// With `--degree auto`: relative volume tolerance τ; a degree is kept when the next one
    /// shrinks the volume by no more than τ.
    #[arg(long, default_value_t = 0.05)]
    pub volume_tolerance: f64,
    /// Formulation (paper §III): logdet_p, trace_p, logdet_h, trace_h or inverse_moment.
    #[arg(long, default_value = "logdet_p")]
    pub method: String,
    /// Relaxed-convexity parameter c ≥ 0 of eq. "VAG.param.convex" (p + c‖u‖^{2d} sos-convex, u the
    /// bounding box normalized into [−1, 1]³); c > 0 only with logdet_p or trace_p.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub relaxation: f64,
    /// Where to write the body file (JSON); defaults to the mesh path with extension `.body.json`.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
    /// Format of MESH when its extension does not say (off, obj, stl, ply, dae, xyz).
    #[arg(long)]
    pub format: Option<String>,
    /// Monte Carlo samples for the volume estimate (raised until the std. error is below 1 %).
    #[arg(long, default_value_t = 200_000)]
    pub samples: usize,
    /// Seed of the volume estimate.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// With --parts: the leaf-excess tolerance T in meters (`--parts auto` keeps the fewest parts
    /// whose max leaf excess is ≤ T, refining up to --max-parts, and each part the lowest degree
    /// within T). Default with `--parts auto`: 1 % of the mesh's bounding-box diagonal (2–3 mm on
    /// the Panda's links, 0.19–0.33 m diagonals). Every leaf above T is reported and fails the command unless
    /// --allow-tolerance-miss. Without --parts: Clarabel's gap tolerance (same as
    /// --solver-tolerance).
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// With --parts: a leaf whose excess is above --tolerance is reported as a warning only (exit
    /// status 0) instead of failing the command.
    #[arg(long)]
    pub allow_tolerance_miss: bool,
    /// Clarabel's gap and feasibility tolerance (see `FitSettings::solver_tolerance`; default 1e-6).
    #[arg(long)]
    pub solver_tolerance: Option<f64>,
    /// Fit a compound body: at most N convex parts (VHACD), or `auto` (the fewest parts within
    /// --tolerance). The mesh must be a triangle mesh (OFF, OBJ, STL, PLY or COLLADA with faces); its
    /// vertices are welded first (a triangle soup becomes an indexed mesh). Without it, one body
    /// is fitted.
    #[arg(long)]
    pub parts: Option<String>,
    /// With --parts: boundary samples per node for the excess (one-sided Hausdorff, meters).
    #[arg(long, default_value_t = sublevel::compound::surface::DEFAULT_EXCESS_SAMPLES)]
    pub excess_samples: usize,
    /// With --parts: VHACD voxel resolution.
    #[arg(long, default_value_t = sublevel::compound::decompose::DEFAULT_RESOLUTION)]
    pub resolution: u32,
    /// With --parts: degree 2d of the parent bodies of the containment tree (2, 4 or 6).
    #[arg(long, default_value_t = 4)]
    pub parent_degree: usize,
    /// With --parts auto: most leaves the refinement may reach (2..=64).
    #[arg(long, default_value_t = sublevel::compound::build::DEFAULT_MAX_PARTS)]
    pub max_parts: usize,
    /// Clarabel's iteration cap.
    #[arg(long, default_value_t = 200)]
    pub max_iterations: u32,
    /// Direct solver of Clarabel's KKT systems: faer or qdldl.
    #[arg(long, default_value = "faer")]
    pub linear_solver: String,
    /// Threads of the KKT factorization (faer only; 0 = solver's choice, 1 = sequential).
    #[arg(long, default_value_t = 1)]
    pub solver_threads: u32,
    /// Clarabel's iterative refinement of the KKT solves (off by default, see
    /// `FitSettings::iterative_refinement`).
    #[arg(long)]
    pub refinement: bool,
    /// Frame the SDP is solved in: cube (default), principal_cube, principal_box, whitened or input
    /// (`fit::hull::Normalization`; log det P / H give the same body in every frame).
    #[arg(long, default_value = "cube")]
    pub normalization: String,
    /// Second frame of the frame-dependent fits (trace objectives, --relaxation c > 0): solved there
    /// too, the smaller body kept. principal_box (default), cube, principal_cube, whitened, input, or none.
    #[arg(long, default_value = "principal_box")]
    pub alternate_normalization: String,
    /// Monomial basis of the trace objectives: both (default: solve in each, keep the smaller
    /// body), plain (the paper's monomials) or scaled (`fit::sdp::TraceBasis`).
    #[arg(long, default_value = "both")]
    pub trace_basis: String,
    /// Cone of the sos-convexity Gram matrix: psd (default, sos-convex as in the paper), or sdd /
    /// dd, the sdsos / dsos inner approximations of paper §VI (an SOCP / LP constraint in its
    /// place; a larger body that depends on the frame). logdet_p and trace_p only.
    #[arg(long, default_value = "psd")]
    pub convexity_cone: String,
    /// No progress on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `sublevel fit`.
///
/// # Errors
/// Whatever loading, fitting or writing returns (see [`sublevel::fit::fit_points`]).
pub fn run(args: FitArgs) -> sublevel::Result<()> {
    if args.parts.is_some() {
        return super::fit_compound::run(args);
    }
    let points = match &args.format {
        Some(f) => mesh::parse_points(&std::fs::read(&args.mesh)?, f.parse()?)?,
        None => mesh::load_points(&args.mesh)?,
    };
    let settings = fit_settings(&args)?;
    let mut progress = progress_printer(args.quiet);
    let body = match args.degree.unwrap_or(DegreeArg::Fixed(4)) {
        DegreeArg::Fixed(_) => fit_points(&points, &settings, &mut progress)?,
        DegreeArg::Auto => {
            auto::fit_auto(&points, &settings, &auto::DEFAULT_AUTO_DEGREES, args.volume_tolerance, &mut progress)?
        }
    };
    let output = args.output.clone().unwrap_or_else(|| args.mesh.with_extension("body.json"));
    body.save(&output)?;
    let r = &body.report;
    let name = args.mesh.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let method = if r.convexity_relaxation > 0.0 {
        format!("{} (c = {})", r.method, r.convexity_relaxation)
    } else {
        r.method.clone()
    };
    println!(
        "{name}: degree {} {method} {}, {} points / {} hull vertices, volume {:.4} ± {:.4} (hull {:.4}), solve {:.2} s, total {:.2} s -> {}",
        body.degree(),
        r.solver_status,
        r.num_points,
        r.num_hull_vertices,
        r.volume,
        r.volume_std_error,
        r.hull_volume,
        r.solve_seconds,
        r.total_seconds,
        output.display()
    );
    if let Some(choice) = &r.degree_choice {
        let list: Vec<String> = choice.candidates.iter().map(|(d, v, e)| format!("2d={d}: {v:.4} ± {e:.4}")).collect();
        println!("degree auto (τ = {}): {}; {}", choice.volume_tolerance, list.join(", "), choice.reason);
    }
    Ok(())
}

/// The leaf / single-body fit settings of `args` (everything but the compound options).
///
/// # Errors
/// [`sublevel::Error::InvalidArgument`] naming `relaxation`, `method`, `linear_solver`,
/// `normalization`, `alternate_normalization`, `trace_basis` or `convexity_cone`.
pub fn fit_settings(args: &FitArgs) -> sublevel::Result<FitSettings> {
    let method: FitMethod = args.method.parse()?;
    let c = args.relaxation;
    if !(c.is_finite() && c >= 0.0) {
        return Err(sublevel::Error::invalid("relaxation", format!("must be finite and ≥ 0, got {c}")));
    }
    if c > 0.0 && !matches!(method, FitMethod::LogDetP | FitMethod::TraceP) {
        return Err(sublevel::Error::invalid(
            "relaxation",
            format!("only logdet_p and trace_p take --relaxation, not {}", method.name()),
        ));
    }
    Ok(FitSettings {
        degree: match args.degree {
            Some(DegreeArg::Fixed(d)) => d,
            Some(DegreeArg::Auto) => 2,
            None => 4,
        },
        method,
        convexity_relaxation: c,
        volume_samples: args.samples,
        seed: args.seed,
        // With --parts, --tolerance is the excess tolerance (meters), not Clarabel's.
        solver_tolerance: args
            .solver_tolerance
            .or(if args.parts.is_none() { args.tolerance } else { None })
            .unwrap_or(1e-6),
        max_solver_iterations: args.max_iterations,
        linear_solver: args.linear_solver.parse()?,
        solver_threads: args.solver_threads,
        iterative_refinement: args.refinement,
        normalization: args.normalization.parse()?,
        alternate_normalization: sublevel::fit::hull::parse_optional_normalization(&args.alternate_normalization)?,
        rows_in_rounds: false,
        convexity_cone: args.convexity_cone.parse()?,
        trace_basis: match args.trace_basis.as_str() {
            "both" => None,
            "plain" => Some(TraceBasis::Plain),
            "scaled" => Some(TraceBasis::Scaled),
            other => {
                return Err(sublevel::Error::invalid(
                    "trace_basis",
                    format!("must be one of both, plain, scaled, got {other:?}"),
                ))
            }
        },
    })
}

/// A progress callback writing to stderr (Clarabel iterations overwrite one line), or nothing
/// when `quiet`.
pub fn progress_printer(quiet: bool) -> impl FnMut(&FitProgress) {
    let mut stderr = std::io::stderr();
    move |p: &FitProgress| {
        if quiet {
            return;
        }
        // Clarabel iterations overwrite one line; every other stage gets its own line.
        let _ = if p.stage == FitStage::Solve {
            write!(stderr, "\r[{:>3.0}%] {:?}: {}\x1b[K", p.fraction * 100.0, p.stage, p.message)
        } else {
            write!(stderr, "\n[{:>3.0}%] {:?}: {}", p.fraction * 100.0, p.stage, p.message)
        };
        if p.stage == FitStage::Done {
            let _ = writeln!(stderr);
        }
    }
}
