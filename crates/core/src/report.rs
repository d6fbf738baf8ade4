//! What a fit reports about the body it produced (paper §III, Table 1 columns), and the two
//! named options a report records: the linear solver of the SDP's KKT systems and the frame the
//! program was written in. The fit formulations live in `sublevel_fit`; these types live here
//! because every body file carries its report.

use crate::math::Real;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// What the fit that produced a body reported (paper §III, Table 1 columns).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// Formulation, e.g. `"logdet_p"` (eq. "VAG.log.det"); `"uploaded"` for bodies sent as-is.
    pub method: String,
    /// The SDP solver's final status (text form `"Solved"`, `"AlmostSolved"`, …, `"closed_form"`
    /// for the inverse moment; see [`crate::conic::SdpStatus`]).
    #[serde(default)]
    pub solver_status: crate::conic::SdpStatus,
    /// Seconds spent inside Clarabel.
    pub solve_seconds: Real,
    /// Seconds for the whole fit (hull, problem build, solve, checks, volume).
    pub total_seconds: Real,
    /// Number of input points.
    pub num_points: usize,
    /// Number of convex-hull vertices used as containment constraints.
    pub num_hull_vertices: usize,
    /// Volume of the body in cubic mesh units (seeded Monte Carlo).
    pub volume: Real,
    /// Standard error of `volume`.
    pub volume_std_error: Real,
    /// Volume of the convex hull of the input points.
    pub hull_volume: Real,
    /// max over all input points of p(xᵢ) after the final rescale; ≤ 1 always.
    pub max_point_value: Real,
    /// Factor the solved polynomial was divided by so that every point satisfies p(xᵢ) ≤ 1 (1 when
    /// the solver's answer already contained every point).
    pub containment_rescale: Real,
    /// Smallest eigenvalue of the sos-convexity Gram matrix (the convexity margin), if known.
    pub convexity_margin: Option<Real>,
    /// Free-form notes (e.g. why a degree was chosen).
    #[serde(default)]
    pub notes: Vec<String>,
    /// Relaxed-convexity parameter c of eq. "VAG.param.convex" the fit used (0: p sos-convex).
    #[serde(default)]
    pub convexity_relaxation: Real,
    /// True when the fit did not impose sos-convexity on p (c > 0, inverse moment): the body may be
    /// nonconvex, and queries on it answer with level-0 SDP lower bounds (paper §IV-A).
    #[serde(default)]
    pub nonconvex: bool,
    /// Why this degree was chosen, when the fit chose it (`--degree auto`).
    #[serde(default)]
    pub degree_choice: Option<DegreeChoice>,
    /// Clarabel's optimality certificate of the fit's SDP (the last solve; None for fits without
    /// an SDP and for bodies read from files or the wire that do not carry it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solver_certificate: Option<SolverCertificate>,
    /// When the fit solved several candidates and kept the smallest body (frame-dependent
    /// objectives, see `sublevel_fit::FitSettings::alternate_normalization`): each candidate as
    /// (`"frame"` or `"frame/basis basis"`, volume in cubic mesh units), in solve order; the kept
    /// body is the one of smallest volume. Empty for a single solve.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub candidate_volumes: Vec<(String, Real)>,
    /// How the kept SDP was solved, as values (the notes say the same in prose). None for bodies
    /// without an SDP fit and for files written before this field.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solve: Option<SolveDetails>,
}

/// How a fit's SDP was solved (structured; see [`FitReport::solve`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SolveDetails {
    /// Interior-point iterations of the kept solve, all attempts and containment rounds.
    pub iterations: u32,
    /// Clarabel's KKT solver (`faer` or `qdldl`); None when unknown.
    #[serde(default, with = "crate::report::named_option")]
    pub linear_solver: Option<crate::report::KktSolver>,
    /// The frame the SDP was solved in (`cube`, `principal_box`, …; paper-frame `input`); None
    /// for containment (its own normalization: the bodies' bounding boxes).
    #[serde(default, with = "crate::report::named_option")]
    pub frame: Option<crate::report::Normalization>,
    /// Containment rows of each round, for fits whose rows were added in rounds (c > 0 or
    /// `rows_in_rounds`); empty for one solve.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rows_per_round: Vec<usize>,
    /// Bodies contained (paper §V containment); 0 for point fits.
    #[serde(default)]
    pub contained_bodies: usize,
    /// Degree 2k of the S-procedure multipliers (containment only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub multiplier_degree: Option<usize>,
}

/// The primal and dual objective values of a fit's SDP at the solver's last iterate, stated for
/// the maximized objective: log det X' (X = P or H written in the scaled monomial basis, which
/// shifts log det X by a constant, see `sublevel_fit::FitMethod::LogDetP`) or −trace X⁻¹ (eq. "VAG.log.det",
/// "Magnani.log.det").
///
/// By weak duality the dual objective bounds the program's optimum from above, so
/// `dual_objective − primal_objective` (the absolute gap, in units of log det) bounds how far the
/// returned body's objective is below the optimum, up to the stated residuals. The log det
/// programs are strictly concave in the Gram matrix, so their optimum is unique: a small gap pins
/// the body down.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SolverCertificate {
    /// Objective of the primal iterate (a lower bound of the optimum when it is feasible).
    pub primal_objective: Real,
    /// Objective of the dual iterate (an upper bound of the optimum when it is feasible).
    pub dual_objective: Real,
    /// Clarabel's relative primal residual (feasibility of the primal iterate).
    pub primal_residual: Real,
    /// Clarabel's relative dual residual.
    pub dual_residual: Real,
}

impl FitReport {
    /// Every floating-point figure of the report with its field name (e.g. `volume`,
    /// `degree_choice.candidates[1].volume`, `solver_certificate.dual_objective`).
    fn numbers_mut(&mut self) -> Vec<(String, &mut Real)> {
        let mut out: Vec<(String, &mut Real)> = vec![
            ("solve_seconds".into(), &mut self.solve_seconds),
            ("total_seconds".into(), &mut self.total_seconds),
            ("volume".into(), &mut self.volume),
            ("volume_std_error".into(), &mut self.volume_std_error),
            ("hull_volume".into(), &mut self.hull_volume),
            ("max_point_value".into(), &mut self.max_point_value),
            ("containment_rescale".into(), &mut self.containment_rescale),
            ("convexity_relaxation".into(), &mut self.convexity_relaxation),
        ];
        if let Some(m) = self.convexity_margin.as_mut() {
            out.push(("convexity_margin".into(), m));
        }
        if let Some(c) = self.degree_choice.as_mut() {
            out.push(("degree_choice.volume_tolerance".into(), &mut c.volume_tolerance));
            for (k, (_, v, e)) in c.candidates.iter_mut().enumerate() {
                out.push((format!("degree_choice.candidates[{k}].volume"), v));
                out.push((format!("degree_choice.candidates[{k}].std_error"), e));
            }
        }
        if let Some(c) = self.solver_certificate.as_mut() {
            out.push(("solver_certificate.primal_objective".into(), &mut c.primal_objective));
            out.push(("solver_certificate.dual_objective".into(), &mut c.dual_objective));
            out.push(("solver_certificate.primal_residual".into(), &mut c.primal_residual));
            out.push(("solver_certificate.dual_residual".into(), &mut c.dual_residual));
        }
        for (k, (_, v)) in self.candidate_volumes.iter_mut().enumerate() {
            out.push((format!("candidate_volumes[{k}].volume"), v));
        }
        out
    }

    /// Checks that every figure of the report is a finite number (JSON has no NaN or infinity: a
    /// stored one would come back as `null` and make the record unreadable).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `prefix.field` (e.g. `report.volume`) for the first
    /// non-finite figure.
    pub fn check_finite(&self, prefix: &str) -> Result<()> {
        let mut copy = self.clone();
        for (name, v) in copy.numbers_mut() {
            if !v.is_finite() {
                return Err(Error::invalid(format!("{prefix}.{name}"), format!("must be a finite number, got {v}")));
            }
        }
        Ok(())
    }

    /// Replaces every non-finite figure by a representable one (±inf by ±`f64::MAX`, NaN by 0)
    /// and says so in `notes`, one note per figure; returns how many were replaced. For derived
    /// figures of a fit that overflowed (e.g. the volume of an enormous cloud), so the body can
    /// still be stored and read back.
    pub fn sanitize_non_finite(&mut self) -> usize {
        let mut notes = Vec::new();
        for (name, v) in self.numbers_mut() {
            if v.is_finite() {
                continue;
            }
            let was = *v;
            *v = if v.is_nan() { 0.0 } else { Real::MAX.copysign(was) };
            notes.push(format!("{name} was {was} (overflow or undefined); stored as {:e}", *v));
        }
        let n = notes.len();
        self.notes.extend(notes);
        n
    }
}

impl SolverCertificate {
    /// `|dual − primal|`, the absolute duality gap in units of the objective.
    pub fn gap(&self) -> Real {
        (self.dual_objective - self.primal_objective).abs()
    }
}

/// How `--degree auto` chose a body's degree: the lowest degree whose volume is within
/// `volume_tolerance` (relative) of the next degree's.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DegreeChoice {
    /// Relative volume tolerance τ asked for.
    pub volume_tolerance: Real,
    /// Every degree fitted, with its volume and standard error: `(2d, volume, std_error)`.
    pub candidates: Vec<(usize, Real, Real)>,
    /// The degree kept.
    pub chosen: usize,
    /// One sentence saying why.
    pub reason: String,
}

/// Direct solver of Clarabel's KKT systems. The fit SDPs' KKT matrices have dense fill (the
/// dense G block and the PSD blocks), so a supernodal factorization (faer, blocked dense
/// kernels, threads) is much faster than QDLDL's simplicial one there.
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

    /// The other one (the last retry of a fit's solve switches solver).
    pub fn other(&self) -> Self {
        match self {
            KktSolver::Faer => KktSolver::Qdldl,
            KktSolver::Qdldl => KktSolver::Faer,
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

/// The coordinates a fit's SDP is written in, relative to the body's normalized coordinates
/// `u = (x − center)/scale` (the bounding cube above, which is also what the body file stores).
///
/// The log det P and log det H programs are affine-invariant (their optimal body does not depend
/// on this choice at all: `z(Au + b) = T z(u)` with `det T` constant, and sos-convexity is
/// preserved by affine maps); the relaxed-convexity term c(‖u‖²)ᵈ and the trace objectives
/// trace X⁻¹ are not, so for them the frame is a modeling choice. Every frame is fixed by the
/// convex hull as a solid (its volume, centroid and inertia), so it depends neither on how densely
/// a mesh samples a region nor on the file's axes:
///
/// ```text
/// BoundingCube   u_fit = u                                   (the default; the body's own frame)
/// PrincipalCube  u_fit = Rᵀ(x − m)/s      R = principal axes of the hull solid's inertia,
///                                         m, s = midpoint and half the longest side of the
///                                         cloud's bounding box in those axes
/// PrincipalBox   u_fit = S⁻¹Rᵀ(x − m)     S = diag of the three half sides (that box → [−1, 1]³)
/// Whitened       u_fit = Λ^(−1/2)Rᵀ(x − g)/k   g = hull centroid, Λ = inertia eigenvalues (the hull
///                                         solid's covariance becomes k⁻²·I), k so |u_fit|∞ ≤ 1
/// Input          u_fit = x                    the input's own coordinates, no centering or scaling
/// ```
///
/// `Input` writes each program literally as the paper states it: p(xᵢ) ≤ 1 on the data points
/// themselves, c(Σ xᵢ²)ᵈ in their coordinates and z(x) the plain monomials of x (the paper names
/// no normalization; the five Table 1 meshes come centered with max ‖xᵢ‖ = 1, and their hull
/// volumes match the paper unscaled). It is not a default candidate: it is the reference frame
/// of `sublevel-lab table1`'s "stated program" check for the frame-dependent rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Normalization {
    /// The axis-aligned bounding cube of the cloud (no change of frame).
    #[default]
    BoundingCube,
    /// The bounding cube in the principal axes of the hull solid (a rotation and an isotropic scale).
    PrincipalCube,
    /// The bounding box in the principal axes, each side mapped onto [−1, 1] (anisotropic).
    PrincipalBox,
    /// The hull solid whitened (identity covariance up to one isotropic factor), then scaled into
    /// [−1, 1]³.
    Whitened,
    /// The input's own coordinates (no centering, no scaling): the programs as the paper writes them.
    Input,
}

impl Normalization {
    /// Every normalization.
    pub const ALL: [Normalization; 5] = [
        Normalization::BoundingCube,
        Normalization::PrincipalCube,
        Normalization::PrincipalBox,
        Normalization::Whitened,
        Normalization::Input,
    ];

    /// Name in the CLI and fit notes (`"cube"`, `"principal_cube"`, `"principal_box"`, `"whitened"`,
    /// `"input"`).
    pub fn name(&self) -> &'static str {
        match self {
            Normalization::BoundingCube => "cube",
            Normalization::PrincipalCube => "principal_cube",
            Normalization::PrincipalBox => "principal_box",
            Normalization::Whitened => "whitened",
            Normalization::Input => "input",
        }
    }
}

impl std::str::FromStr for Normalization {
    type Err = Error;

    /// Parses a name of [`Normalization::name`].
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `normalization` for an unknown name.
    fn from_str(s: &str) -> Result<Self> {
        Normalization::ALL.iter().copied().find(|n| n.name() == s).ok_or_else(|| {
            Error::invalid(
                "normalization",
                format!("must be one of cube, principal_cube, principal_box, whitened, input, got {s:?}"),
            )
        })
    }
}

/// A named option (a type with a `name()` text form and `FromStr`) as its name in JSON, read
/// back leniently: an unknown name reads as None, so a file from another writer still loads.
pub mod named_option {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Types with a stable text name.
    pub trait Named: Sized + std::str::FromStr {
        /// The text form.
        fn text(&self) -> &'static str;
    }

    impl Named for super::KktSolver {
        fn text(&self) -> &'static str {
            self.name()
        }
    }

    impl Named for super::Normalization {
        fn text(&self) -> &'static str {
            self.name()
        }
    }

    /// Writes the name (or null).
    pub fn serialize<T: Named, S: Serializer>(value: &Option<T>, s: S) -> Result<S::Ok, S::Error> {
        match value {
            Some(v) => s.serialize_str(v.text()),
            None => s.serialize_none(),
        }
    }

    /// Reads a name; unknown names and null read as None.
    pub fn deserialize<'de, T: Named, D: Deserializer<'de>>(d: D) -> Result<Option<T>, D::Error> {
        let text: Option<String> = Option::deserialize(d)?;
        Ok(text.and_then(|t| t.parse().ok()))
    }
}
