//! Level-0 sos certificates for the two queries, solved by Clarabel: the SDP references the
//! Newton / active-set solvers are checked against (paper §IV-A eq. "distance.lasserre" with
//! scalar multipliers, and its analogue for eq. "overlap").
//!
//! # Distance
//!
//! ```text
//! max γ   s.t.   ‖x − y‖² − γ − τ (1 − p_a'(x)) − ξ (1 − p_b'(y))  is sos,   τ, ξ ≥ 0
//! ```
//!
//! Every feasible γ is a lower bound on the squared distance; for sos-convex bodies the bound is
//! exact already at this level (paper §IV-A, Lasserre 2009). Each point is written in its own
//! body's normalized coordinates, so no posed polynomial is ever expanded:
//!
//! ```text
//! x = R_a (c_a + s_a u) + t_a,   y = R_b (c_b + s_b v) + t_b
//! x − y = δ + M w,   w = (u, v) ∈ ℝ⁶,   δ = R_a c_a + t_a − R_b c_b − t_b,   M = [s_a R_a | −s_b R_b]
//! ```
//!
//! so `‖x − y‖²` is a quadratic in w and the constraints are the bodies' own polynomials `p_a(u)`,
//! `p_b(v)`. The sos condition is a 6-variable Gram form of half-degree d = max(d_a, d_b)
//! (N = 7, 28, 84, 210 at 2d = 2, 4, 6, 8): one PSD block, one equality row per monomial of degree
//! ≤ 2d. The objective is divided by `L² = max(s_a, s_b)²` for conditioning and scaled back. (With
//! [`CertificateParams::recenter`], the default, the final pass uses shifted and scaled coordinates
//! `u = û + κ_a w_a`, `v = v̂ + κ_b w_b` instead: see "Conditioning".)
//!
//! # Block structure (default)
//!
//! The full 6-variable Gram matrix costs O(N⁶) per interior-point iteration (Clarabel factors its
//! N(N+1)/2-sized dense block: ~0.3 s at 2d = 4, minutes at 2d = 6). By default the sos polynomial
//! is instead written as a sum of three smaller Gram forms,
//!
//! ```text
//! ‖x − y‖² − γ − τ(1 − p_a(u)) − ξ(1 − p_b(v)) = σ₀(1, u, v) + σ_a(z_d(u)) + σ_b(z_d(v))
//! ```
//!
//! (sizes 7, C(3+d, d), C(3+d, d)). Any feasible γ is still a lower bound, and it stays exact for
//! sos-convex bodies: at the optimum, write τ p_a(u) = τ[p_a(u*) + ∇p_a(u*)ᵀ(u − u*)] + τ B_a(u),
//! where the Bregman remainder B_a is sos for sos-convex p_a (Helton–Nie); what is left of the
//! Lagrangian is a convex quadratic with zero gradient and value at (u*, v*), i.e. a sos quadratic
//! in (1, u, v). [`CertificateParams::full_gram`] selects the full form.
//!
//! # Growth
//!
//! ```text
//! d(p₁‖p₂) = min p₁'(x) s.t. p₂'(x) ≤ 1;      level 0:  max γ  s.t.  p₁'(x) − γ − τ (1 − p₂'(x)) sos,  τ ≥ 0
//! ```
//!
//! stated in affine variables w (world `x = o + ρ R w`, see "Conditioning"); both bodies' polynomials
//! are expanded in w with [`crate::poly::Polynomial::compose_affine`] (3-variable Gram form,
//! N = 4, 10, 20, 35).
//!
//! # Conditioning (two passes)
//!
//! In a body's own normalized frame the fitted bodies give badly scaled programs: a thin body (the
//! human's limbs) has coefficients up to 2·10⁴ at 2d = 6, and expanding it about a far-away origin
//! multiplies them further, while the answer is O(1). Clarabel then stalls at `AlmostSolved`
//! (reduced tolerances, ~1e-4) with errors up to 1e-4 and γ above the true minimum. Any affine
//! choice of variables gives the same program (the sos cone of degree ≤ 2d is invariant), so by
//! default ([`CertificateParams::recenter`]) the program is solved twice: a loose pass (tolerance
//! 1e-7) in the plain frame (body 2's normalized coordinates for growth; each body's own for
//! distance) locates the minimizer from the moments, then the program is re-solved with the
//! variables centered there and scaled to half the smaller body's scale (growth: `o = x̂`,
//! `R = R₂`, `ρ = ½ min(s₁, s₂)`; distance: `u = û + κ_a w_a`, `κ_a = ρ/s_a`, likewise for b,
//! objective divided by ρ²). The centered monomial basis is well scaled where the Gram matrix is
//! singular (at the minimizer). On the bundled chair/human fits (120 pairs at 2d = 4, 6 at 2d = 6)
//! every growth certificate then ends `Solved` and agrees with Newton to 3·10⁻¹⁰ (2d = 4) and
//! 9·10⁻⁹ (2d = 6) relative; the distance to 1.4·10⁻⁹. Overlapping distance pairs (γ = 0 on a
//! whole region, a degenerate optimum) may still end `AlmostSolved`, with accurate values that the
//! a-posteriori check below confirms. The cost is roughly 1.5× a single solve.
//!
//! # A-posteriori check
//!
//! After the final solve the certificate is checked: the Gram blocks Q_b are taken from Clarabel's
//! PSD slacks (strictly inside the cone), the multipliers clamped at τ ≥ 0, and the coefficient
//! residual `r = Σ_b z_bᵀ Q_b z_b − (f − γ − Σ τₖ(1 − gₖ))` is folded into one Gram entry per
//! monomial (diagonal when possible), so that the sos identity holds exactly with the corrected
//! blocks Q_b'. If every λ_min(Q_b') ≥ 0, γ is certified as is; otherwise, on the feasible set,
//! `f − γ ≥ Σ_b λ_min(Q_b') ‖z_b(w)‖²` with `‖z_b(w)‖² ≤ Σ_k B^{2k}`, B a bound on ‖w‖ over the
//! bodies, gives the reported `verified_*` value. B uses a radius estimate of each body (256 rays,
//! +10 %), and floating-point rounding of the eigenvalues is not accounted for: a careful, not a
//! rigorous, bound.
//!
//! # Witnesses from the moments
//!
//! Clarabel's dual variables of the coefficient-matching rows are the pseudo-moments `y_α = L(w^α)`
//! of the optimal measure (`y₀ = 1` because γ's column is the constant row; the dual of the PSD
//! block is the moment matrix). For sos-convex bodies Jensen's inequality for sos-convex
//! polynomials gives `p(L(w)) ≤ L(p(w)) ≤ 1`, so the first-order moments `(u*, v*)` are feasible
//! points whose objective equals the bound: they are the minimizers. They are mapped back to world
//! points.
//!
//! # Limits
//!
//! Only exact for sos-convex bodies (for merely convex bodies γ is a lower bound). Degree-8 pairs
//! give a 210 × 210 Gram matrix and take seconds: these are references, not the query path.

use crate::body::Body;
use crate::conic::{quiet_settings, ConicBuilder, ConicSolution, Row};
use crate::math::{Isometry3, Matrix3, Point3, Real, Vector3};
use crate::poly::gram::{gram_weight, triangle_index, triangle_len, GramStructure};
use crate::poly::monomial::graded_exponents;
use crate::poly::Polynomial;
use crate::{Error, Result};
use clarabel::solver::SolverStatus;

/// Level-0 SDP bound on the squared distance.
#[derive(Clone, Debug)]
pub struct DistanceCertificate {
    /// γ*: lower bound on the squared distance in m² (exact for sos-convex bodies); ≈ 0 (up to the
    /// solver tolerance, possibly slightly negative) when the bodies overlap.
    pub squared_distance: Real,
    /// √max(γ*, 0) in meters.
    pub distance: Real,
    /// Multiplier τ ≥ 0 of body A's constraint (m², the objective's units).
    pub tau: Real,
    /// Multiplier ξ ≥ 0 of body B's constraint (m²).
    pub xi: Real,
    /// Witness points (x*, y*) in world coordinates, recovered from the first-order moments of the
    /// dual (moment) solution; `None` when the moments are not finite or the recovered points violate
    /// their body's constraint by more than [`WITNESS_FEASIBILITY_TOLERANCE`].
    pub witnesses: Option<(Point3, Point3)>,
    /// The same first-order moments mapped to world points without the feasibility filter (`None`
    /// only when not finite). For nonconvex bodies (paper §IV-A) they may lie outside their body;
    /// when both are feasible and ‖x − y‖² meets the bound, the lower bound is tight.
    pub moment_witnesses: Option<(Point3, Point3)>,
    /// Witness points from the kernel of the Gram matrix (paper §IV-A): the first Gram block has
    /// basis (1, u, v), and at a minimizer the certificate σ vanishes, so (1, u*, v*) spans its
    /// kernel; read off when that kernel is one-dimensional (`None` otherwise, e.g. for a pair with
    /// several minimizers). Unfiltered: for nonconvex bodies they may lie outside their body.
    pub kernel_witnesses: Option<(Point3, Point3)>,
    /// Clarabel's status (`"Solved"` or `"AlmostSolved"`; other statuses are errors).
    pub solver_status: String,
    /// Seconds inside Clarabel (both passes).
    pub solve_seconds: Real,
    /// Interior-point iterations (both passes).
    pub iterations: u32,
    /// Sides of the Gram blocks: `[7, C(3 + d, d), C(3 + d, d)]` for the block-structured form,
    /// `[C(6 + d, d)]` for the full 6-variable form (see [`CertificateParams::full_gram`]).
    pub gram_sizes: Vec<usize>,
    /// A-posteriori lower bound on the squared distance (m²) from the returned certificate:
    /// `squared_distance` when the Gram blocks, corrected so that the sos identity holds exactly,
    /// are PSD; otherwise lowered by |λ_min| times a bound on ‖z(w)‖² over the bodies (which uses
    /// estimates of their radii: careful, not rigorous). See the module docs.
    pub verified_squared_distance: Real,
    /// Max |coefficient residual| of the sos identity as returned (m²).
    pub residual: Real,
    /// Smallest eigenvalue over the corrected Gram blocks (m²; ≥ 0 means an exact sos certificate
    /// up to floating-point rounding).
    pub gram_min_eigenvalue: Real,
}

/// Level-0 SDP bound on d(p₁‖p₂).
#[derive(Clone, Debug)]
pub struct GrowthCertificate {
    /// γ*: lower bound on d(p₁‖p₂) (dimensionless; exact for sos-convex bodies).
    pub value: Real,
    /// Multiplier τ ≥ 0 (0 when the constraint is inactive).
    pub tau: Real,
    /// The minimizer x* in world coordinates, recovered from the first-order moments; `None` when
    /// not finite or infeasible by more than [`WITNESS_FEASIBILITY_TOLERANCE`].
    pub minimizer: Option<Point3>,
    /// The same first-order moments mapped to a world point without the feasibility filter (`None`
    /// only when not finite); for nonconvex bodies it may lie outside body 2.
    pub moment_minimizer: Option<Point3>,
    /// Clarabel's status (`"Solved"` or `"AlmostSolved"`; other statuses are errors).
    pub solver_status: String,
    /// Seconds inside Clarabel (both passes).
    pub solve_seconds: Real,
    /// Interior-point iterations (both passes).
    pub iterations: u32,
    /// Side N of the Gram matrix (C(3 + d, d)).
    pub gram_size: usize,
    /// A-posteriori lower bound on d(p₁‖p₂) from the returned certificate: `value` when the Gram
    /// matrix, corrected so that the sos identity holds exactly, is PSD; otherwise `value` minus
    /// |λ_min| times a bound on ‖z(w)‖² over body 2 (which uses an estimate of body 2's radius, so
    /// this is a careful, not a rigorous, bound). Compare it with `value` to judge the certificate.
    pub verified_value: Real,
    /// Max |coefficient residual| of the sos identity p₁' − γ − τ(1 − p₂') = z(w)ᵀQz(w) as returned
    /// (objective units, in the certificate's frame).
    pub residual: Real,
    /// Smallest eigenvalue of the corrected Gram matrix (≥ 0 means the identity is an exact sos
    /// certificate up to floating-point rounding).
    pub gram_min_eigenvalue: Real,
}

/// How far a moment-recovered witness may exceed its body's level (p − 1, dimensionless) and still
/// be reported; the SDP's own feasibility tolerance is far below this.
pub const WITNESS_FEASIBILITY_TOLERANCE: Real = 1e-5;

/// Solver settings of the certificates.
#[derive(Clone, Copy, Debug)]
pub struct CertificateParams {
    /// Clarabel's gap and feasibility tolerances (absolute and relative); default 1e-10, which
    /// makes the bound accurate to about 1e-8 relative on well-scaled pairs.
    pub tolerance: Real,
    /// Clarabel's iteration cap; default 200.
    pub max_iterations: u32,
    /// Distance only: use one full 6-variable Gram block (N = C(6 + d, d): 28, 84, 210 at 2d = 4,
    /// 6, 8) instead of the default block-structured form (module docs, "Block structure"). Both
    /// give the exact distance for sos-convex bodies; the full form is a (possibly) stronger bound for
    /// other bodies but costs O(N⁶) per Clarabel iteration (about 0.3 s at 2d = 4, minutes at 2d = 6).
    pub full_gram: bool,
    /// Solve twice: a loose first pass (tolerance 1e-7) locates the minimizer, then the program is
    /// re-solved with its variables centered there and scaled to half the smaller body's scale
    /// (module docs, "Conditioning"). Default `true`; without it, near-touching pairs of the fitted
    /// bodies can end `AlmostSolved` with errors up to 1e-4.
    pub recenter: bool,
}

impl Default for CertificateParams {
    fn default() -> Self {
        Self { tolerance: 1e-10, max_iterations: 200, full_gram: false, recenter: true }
    }
}

impl CertificateParams {
    fn validate(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(Error::invalid("params.tolerance", format!("must be in (0, 1), got {}", self.tolerance)));
        }
        if self.max_iterations == 0 {
            return Err(Error::invalid("params.max_iterations", "must be at least 1"));
        }
        Ok(())
    }
}

/// Certifies the distance between body `a` under `pose_a` and body `b` under `pose_b` (paper
/// eq. "distance.lasserre", level 0) with [`CertificateParams::default`].
///
/// # Errors
/// [`crate::Error::Numerical`] when Clarabel returns no usable solution.
pub fn certify_distance(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Result<DistanceCertificate> {
    certify_distance_with_params(a, pose_a, b, pose_b, &CertificateParams::default())
}

/// [`certify_distance`] with explicit solver settings.
///
/// Builds the Gram form described in the module docs (block-structured by default), maximizes γ
/// (by default twice, the second pass recentered at the first pass's witnesses: module docs,
/// "Conditioning"), recovers the witnesses from the moments and checks the certificate a
/// posteriori.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `params.tolerance` / `params.max_iterations`;
/// [`crate::Error::Numerical`] naming Clarabel's status when it is neither `Solved` nor
/// `AlmostSolved`.
pub fn certify_distance_with_params(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    params: &CertificateParams,
) -> Result<DistanceCertificate> {
    params.validate()?;
    let plain = (BodyFrame::identity(), BodyFrame::identity(), a.scale().max(b.scale()));
    let (mut seconds, mut iterations) = (0.0, 0);
    let (frame_a, frame_b, len) = if params.recenter {
        // Pass 1 in the bodies' own normalized frames, loose tolerance, to locate the witnesses.
        let loose = CertificateParams { tolerance: params.tolerance.max(PRESOLVE_TOLERANCE), ..*params };
        match solve_distance_in(a, pose_a, b, pose_b, &plain, &loose) {
            Ok(first) => {
                seconds += first.sol.sol.solve_seconds;
                iterations += first.sol.sol.iterations;
                match first.witnesses_normalized {
                    Some((u, v)) => {
                        let rho = RECENTER_SCALE * a.scale().min(b.scale());
                        (
                            BodyFrame { origin: u, scale: rho / a.scale() },
                            BodyFrame { origin: v, scale: rho / b.scale() },
                            rho,
                        )
                    }
                    None => plain,
                }
            }
            Err(_) => plain,
        }
    } else {
        plain
    };
    let frames = (frame_a, frame_b, len);
    let run = solve_distance_in(a, pose_a, b, pose_b, &frames, params)?;
    seconds += run.sol.sol.solve_seconds;
    iterations += run.sol.sol.iterations;
    // ‖w_a‖ ≤ (R_a + ‖u_o‖)/κ_a on body a, likewise for b (module docs, "A-posteriori check").
    let ba = (radius_estimate(a) + frame_a.origin.norm()) / frame_a.scale;
    let bb = (radius_estimate(b) + frame_b.origin.norm()) / frame_b.scale;
    let d = a.degree().max(b.degree()) / 2;
    let powers = |r2: Real| (0..=d).map(|k| r2.powi(k as i32)).sum::<Real>();
    let z_bounds: Vec<Real> = if params.full_gram {
        vec![powers(ba * ba + bb * bb)]
    } else {
        vec![1.0 + ba * ba + bb * bb, powers(ba * ba), powers(bb * bb)]
    };
    let constraints = [run.pa.as_slice(), run.pb.as_slice()];
    let check = verify_level0(&run.blocks, &run.objective, &constraints, &run.sol, &z_bounds);
    let sol = &run.sol.sol;
    let len2 = len * len;
    let gamma = sol.x[run.sol.gamma] * len2;
    let witnesses = run.witnesses_normalized.map(|(u, v)| (world_point(a, pose_a, &u), world_point(b, pose_b, &v)));
    let moment_witnesses =
        run.moments_normalized.map(|(u, v)| (world_point(a, pose_a, &u), world_point(b, pose_b, &v)));
    let kernel_witnesses = run.kernel_normalized.map(|(u, v)| (world_point(a, pose_a, &u), world_point(b, pose_b, &v)));
    Ok(DistanceCertificate {
        squared_distance: gamma,
        distance: gamma.max(0.0).sqrt(),
        tau: sol.x[run.sol.multipliers[0]] * len2,
        xi: sol.x[run.sol.multipliers[1]] * len2,
        witnesses,
        moment_witnesses,
        kernel_witnesses,
        solver_status: format!("{:?}", sol.status),
        solve_seconds: seconds,
        iterations,
        gram_sizes: run.blocks.iter().map(GramStructure::size).collect(),
        verified_squared_distance: check.bound * len2,
        residual: check.residual * len2,
        gram_min_eigenvalue: check.min_eigenvalue * len2,
    })
}

/// A body's certificate variables: normalized coordinates `u = origin + scale · w`.
#[derive(Clone, Copy, Debug)]
struct BodyFrame {
    origin: Vector3,
    scale: Real,
}

impl BodyFrame {
    fn identity() -> Self {
        Self { origin: Vector3::zeros(), scale: 1.0 }
    }
}

/// One solved distance program with its data.
struct DistanceRun {
    blocks: Vec<GramStructure>,
    objective: Vec<Real>,
    pa: Vec<Real>,
    pb: Vec<Real>,
    sol: Level0Solution,
    /// Moment-recovered witnesses in the bodies' normalized coordinates, if finite and feasible.
    witnesses_normalized: Option<(Vector3, Vector3)>,
    /// The same moments without the feasibility filter, if finite.
    moments_normalized: Option<(Vector3, Vector3)>,
    /// Witnesses from the kernel of the first Gram block (paper §IV-A), unfiltered, if the kernel
    /// is one-dimensional.
    kernel_normalized: Option<(Vector3, Vector3)>,
}

/// Solves the distance program with body a's variables in `frames.0`, body b's in `frames.1`, and
/// the objective divided by `frames.2`² (meters²).
fn solve_distance_in(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    frames: &(BodyFrame, BodyFrame, Real),
    params: &CertificateParams,
) -> Result<DistanceRun> {
    let (fa, fb, len) = *frames;
    let d = a.degree().max(b.degree()) / 2;
    let blocks = if params.full_gram {
        vec![GramStructure::new(6, d)]
    } else {
        // (1, u, v) for the quadratic part; z_d(u) and z_d(v) for each body's own polynomial.
        let pad = |e: &Vec<u8>, offset: usize| {
            let mut out = vec![0u8; 6];
            out[offset..offset + 3].copy_from_slice(e);
            out
        };
        let half3 = graded_exponents(3, d);
        vec![
            GramStructure::with_half_basis(6, graded_exponents(6, 1), 2 * d),
            GramStructure::with_half_basis(6, half3.iter().map(|e| pad(e, 0)).collect(), 2 * d),
            GramStructure::with_half_basis(6, half3.iter().map(|e| pad(e, 3)).collect(), 2 * d),
        ]
    };
    let gram = &blocks[0];
    let ra = *pose_a.rotation.to_rotation_matrix().matrix();
    let rb = *pose_b.rotation.to_rotation_matrix().matrix();
    // x = R_a(c_a + s_a(u_o + κ_a w_a)) + t_a, likewise y; x − y = δ + M w, everything divided by L.
    let xa0 = ra * (a.center() + fa.origin * a.scale()) + pose_a.translation.vector;
    let xb0 = rb * (b.center() + fb.origin * b.scale()) + pose_b.translation.vector;
    let delta = (xa0 - xb0) / len;
    let mut m = nalgebra::Matrix3x6::<Real>::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(ra * (a.scale() * fa.scale / len)));
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(rb * (-b.scale() * fb.scale / len)));
    let g = m.transpose() * m;
    let lin = m.transpose() * delta;

    let nf = gram.full_basis.len();
    let mut objective = vec![0.0; nf];
    objective[0] = delta.norm_squared();
    for i in 0..6 {
        objective[gram.index_of[&unit_exponent(6, &[i])]] += 2.0 * lin[i];
        for j in i..6 {
            let w = if i == j { 1.0 } else { 2.0 };
            objective[gram.index_of[&unit_exponent(6, &[i, j])]] += w * g[(i, j)];
        }
    }
    let compose =
        |body: &Body, f: &BodyFrame| body.polynomial().compose_affine(&(Matrix3::identity() * f.scale), &f.origin);
    let pa = embed(&compose(a, &fa), gram, 0);
    let pb = embed(&compose(b, &fb), gram, 3);
    let sol = solve_level0(&blocks, &objective, &[pa.as_slice(), pb.as_slice()], params)?;
    let moments_normalized = moments_first_order(&blocks[0], &sol, 6).map(|w| {
        let u = fa.origin + Vector3::new(w[0], w[1], w[2]) * fa.scale;
        let v = fb.origin + Vector3::new(w[3], w[4], w[5]) * fb.scale;
        (u, v)
    });
    let witnesses_normalized = moments_normalized.filter(|(u, v)| {
        a.polynomial().value(u) <= 1.0 + WITNESS_FEASIBILITY_TOLERANCE
            && b.polynomial().value(v) <= 1.0 + WITNESS_FEASIBILITY_TOLERANCE
    });
    let kernel_normalized = kernel_point(&blocks[0], &sol, 6).map(|w| {
        let u = fa.origin + Vector3::new(w[0], w[1], w[2]) * fa.scale;
        let v = fb.origin + Vector3::new(w[3], w[4], w[5]) * fb.scale;
        (u, v)
    });
    Ok(DistanceRun { blocks, objective, pa, pb, sol, witnesses_normalized, moments_normalized, kernel_normalized })
}

/// Certifies d(p₁‖p₂) for body `p1` under `pose1` and body `p2` under `pose2` (level-0 analogue
/// of paper eq. "overlap") with [`CertificateParams::default`].
///
/// # Errors
/// [`crate::Error::Numerical`] when Clarabel returns no usable solution.
pub fn certify_growth(p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3) -> Result<GrowthCertificate> {
    certify_growth_with_params(p1, pose1, p2, pose2, &CertificateParams::default())
}

/// [`certify_growth`] with explicit solver settings.
///
/// Expands both bodies' polynomials in the certificate's variables (module docs, "Conditioning":
/// body 2's normalized frame, then by default a second pass centered at the first pass's
/// minimizer), builds the 3-variable Gram form of half-degree d = max(deg p₁, deg p₂)/2, maximizes
/// γ, recovers the minimizer from the moments and checks the certificate a posteriori.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `params.tolerance` / `params.max_iterations`;
/// [`crate::Error::Numerical`] naming Clarabel's status when it is neither `Solved` nor
/// `AlmostSolved`.
pub fn certify_growth_with_params(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    params: &CertificateParams,
) -> Result<GrowthCertificate> {
    params.validate()?;
    let r2 = *pose2.rotation.to_rotation_matrix().matrix();
    let (mut seconds, mut iterations) = (0.0, 0);
    let frame = if params.recenter {
        // Pass 1: body 2's normalized frame, loose tolerance, only to locate the minimizer.
        let loose = CertificateParams { tolerance: params.tolerance.max(PRESOLVE_TOLERANCE), ..*params };
        let center = match solve_growth_in(p1, pose1, p2, pose2, &Frame::of_body(p2, pose2), &loose) {
            Ok(first) => {
                seconds += first.sol.sol.solve_seconds;
                iterations += first.sol.sol.iterations;
                first.minimizer
            }
            Err(_) => None,
        }
        .unwrap_or_else(|| growth_center_guess(p1, pose1, p2, pose2));
        Frame { origin: center, rotation: r2, scale: RECENTER_SCALE * p1.scale().min(p2.scale()) }
    } else {
        Frame::of_body(p2, pose2)
    };
    let run = solve_growth_in(p1, pose1, p2, pose2, &frame, params)?;
    seconds += run.sol.sol.solve_seconds;
    iterations += run.sol.sol.iterations;
    // Feasible-set bound for the a-posteriori check: ‖w‖ ≤ (s₂/ρ)(R₂ + ‖v_o‖), v_o the frame
    // origin in body 2's normalized coordinates.
    let v_origin = p2.posed(pose2).to_normalized(&frame.origin);
    let w_bound = p2.scale() / frame.scale * (radius_estimate(p2) + v_origin.norm());
    let d = run.blocks[0].half_basis.iter().map(|e| e.iter().map(|&k| k as usize).sum::<usize>()).max().unwrap_or(0);
    let z_bound = (0..=d).map(|k| w_bound.powi(2 * k as i32)).sum::<Real>();
    let check = verify_level0(&run.blocks, &run.objective, &[run.constraint.as_slice()], &run.sol, &[z_bound]);
    let sol = &run.sol.sol;
    Ok(GrowthCertificate {
        value: sol.x[run.sol.gamma],
        tau: sol.x[run.sol.multipliers[0]],
        minimizer: run.minimizer.map(Point3::from),
        moment_minimizer: run.moment_minimizer.map(Point3::from),
        solver_status: format!("{:?}", sol.status),
        solve_seconds: seconds,
        iterations,
        gram_size: run.blocks[0].size(),
        verified_value: check.bound,
        residual: check.residual,
        gram_min_eigenvalue: check.min_eigenvalue,
    })
}

/// Certificate of a separating hyperplane between two posed bodies (the dual view of paper eq.
/// "distance"): for witness candidates x̄ (on A), ȳ (on B) and n = (ȳ − x̄)/‖ȳ − x̄‖,
///
/// ```text
/// d(A, B) ≥ n·(ȳ − x̄) − e_A − e_B,   e_A = max_{x ∈ A} n·(x − x̄),   e_B = max_{y ∈ B} n·(ȳ − y)
/// ```
///
/// (the slab between the two supporting planes of normal n is free of both bodies). Each excess is
/// a level-0 SDP in three variables over one body alone, exact for sos-convex bodies (Jensen's
/// inequality), and verified a posteriori like the other certificates. At Newton's witnesses the
/// excesses vanish and the bound equals the distance. Used when the joint six-variable certificate
/// is inaccurate: its Gram matrix mixes both bodies' scales (a 1e-3 slab beside a 1 m body), these
/// programs see one body each.
#[derive(Clone, Debug)]
pub struct SeparationCertificate {
    /// n·(ȳ − x̄) − e_A − e_B with the solver's excesses (meters).
    pub lower_bound: Real,
    /// The same with the a-posteriori verified excess bounds: a proven lower bound (meters).
    pub verified_lower_bound: Real,
    /// (e_A, e_B) from the solver (meters, ≥ 0 up to its tolerance).
    pub excess: (Real, Real),
    /// Smallest eigenvalue over both corrected Gram matrices (meters).
    pub gram_min_eigenvalue: Real,
    /// The worse of the two Clarabel statuses (`"Solved"` unless one is `"AlmostSolved"`).
    pub solver_status: String,
    /// Seconds inside Clarabel (both programs).
    pub solve_seconds: Real,
}

/// [`SeparationCertificate`] for witness candidates `x` (on A) and `y` (on B), world frame.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `witnesses` when x = y (no normal) or a parameter of
/// `params`; [`crate::Error::Numerical`] when Clarabel fails on either program.
pub fn certify_separation(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    x: &Point3,
    y: &Point3,
    params: &CertificateParams,
) -> Result<SeparationCertificate> {
    params.validate()?;
    let gap = y - x;
    let len = gap.norm();
    if !(len > 0.0 && len.is_finite()) {
        return Err(Error::invalid("witnesses", "the two witness points coincide: no separating normal"));
    }
    let n = gap / len;
    let ea = support_excess(a, pose_a, &x.coords, &n, params)?;
    let eb = support_excess(b, pose_b, &y.coords, &-n, params)?;
    let worse = if ea.3 == "Solved" { eb.3.clone() } else { ea.3.clone() };
    Ok(SeparationCertificate {
        lower_bound: len - ea.0 - eb.0,
        verified_lower_bound: len - ea.1 - eb.1,
        excess: (ea.0, eb.0),
        gram_min_eigenvalue: ea.2.min(eb.2),
        solver_status: worse,
        solve_seconds: ea.4 + eb.4,
    })
}

/// max_{x ∈ body} m·(x − o) by the level-0 SDP `max γ' s.t. −m·(x − o) − γ − τ(1 − p) sos` in the
/// body's rotation and scale, centered at o: (excess, verified upper bound on it, Gram λ_min,
/// status, seconds).
fn support_excess(
    body: &Body,
    pose: &Isometry3,
    o: &Vector3,
    m: &Vector3,
    params: &CertificateParams,
) -> Result<(Real, Real, Real, String, Real)> {
    let rotation = *pose.rotation.to_rotation_matrix().matrix();
    let frame = Frame { origin: *o, rotation, scale: body.scale() };
    let d = body.degree() / 2;
    let gram = GramStructure::new(3, d);
    let mut objective = vec![0.0; gram.full_basis.len()];
    // −m·(x − o) with x − o = scale · R w.
    let mw = rotation.transpose() * m * (-frame.scale);
    for i in 0..3 {
        objective[gram.index_of[&unit_exponent(3, &[i])]] = mw[i];
    }
    let constraint = embed(&frame.compose(body, pose), &gram, 0);
    let blocks = [gram];
    let sol = solve_level0(&blocks, &objective, &[constraint.as_slice()], params)?;
    let v_origin = body.posed(pose).to_normalized(o);
    let w_bound = radius_estimate(body) + v_origin.norm();
    let z_bound = (0..=d).map(|k| w_bound.powi(2 * k as i32)).sum::<Real>();
    let check = verify_level0(&blocks, &objective, &[constraint.as_slice()], &sol, &[z_bound]);
    let gamma = sol.sol.x[sol.gamma];
    Ok((-gamma, -check.bound, check.min_eigenvalue, format!("{:?}", sol.sol.status), sol.sol.solve_seconds))
}

/// Tolerance of the first (locating) pass of a recentered certificate.
const PRESOLVE_TOLERANCE: Real = 1e-7;

/// Scale ρ of the recentered frame relative to the smaller body's scale.
const RECENTER_SCALE: Real = 0.5;

/// An affine frame of the certificate's variables w: world point `x = origin + scale · rotation · w`.
#[derive(Clone, Copy, Debug)]
struct Frame {
    origin: Vector3,
    rotation: Matrix3,
    scale: Real,
}

impl Frame {
    /// The body's own normalized frame (w = u).
    fn of_body(body: &Body, pose: &Isometry3) -> Self {
        let rotation = *pose.rotation.to_rotation_matrix().matrix();
        Self { origin: rotation * body.center() + pose.translation.vector, rotation, scale: body.scale() }
    }

    /// The body's polynomial in this frame's variables: `p(A w + b)` with `u = A w + b`.
    fn compose(&self, body: &Body, pose: &Isometry3) -> Polynomial {
        let rt: Matrix3 = pose.rotation.to_rotation_matrix().matrix().transpose();
        let a = rt * self.rotation * (self.scale / body.scale());
        let b = (rt * (self.origin - pose.translation.vector) - body.center()) / body.scale();
        body.polynomial().compose_affine(&a, &b)
    }

    fn world(&self, w: &[Real]) -> Vector3 {
        self.origin + self.rotation * Vector3::new(w[0], w[1], w[2]) * self.scale
    }
}

/// One solved growth program with its data (for the a-posteriori check).
struct GrowthRun {
    blocks: [GramStructure; 1],
    objective: Vec<Real>,
    constraint: Vec<Real>,
    sol: Level0Solution,
    /// Moment-recovered minimizer (world), if finite and feasible.
    minimizer: Option<Vector3>,
    /// The same moments without the feasibility filter, if finite.
    moment_minimizer: Option<Vector3>,
}

/// Solves the growth program in `frame`'s variables.
fn solve_growth_in(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    frame: &Frame,
    params: &CertificateParams,
) -> Result<GrowthRun> {
    let d = p1.degree().max(p2.degree()) / 2;
    let gram = GramStructure::new(3, d);
    let objective = embed(&frame.compose(p1, pose1), &gram, 0);
    let constraint = embed(&frame.compose(p2, pose2), &gram, 0);
    let blocks = [gram];
    let sol = solve_level0(&blocks, &objective, &[constraint.as_slice()], params)?;
    let b2 = p2.posed(pose2);
    let moment_minimizer = moments_first_order(&blocks[0], &sol, 3).map(|w| frame.world(&w));
    let minimizer = moment_minimizer.filter(|x| b2.value(x) <= 1.0 + WITNESS_FEASIBILITY_TOLERANCE);
    Ok(GrowthRun { blocks, objective, constraint, sol, minimizer, moment_minimizer })
}

/// A geometric guess of the growth minimizer: p₁'s interior point if it lies in body 2, else where
/// the segment from body 2's interior point towards it leaves body 2.
fn growth_center_guess(p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3) -> Vector3 {
    let c1 = p1.posed(pose1).interior_point();
    let b2 = p2.posed(pose2);
    let c2 = b2.interior_point();
    if b2.value(&c1) <= 1.0 {
        return c1;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if b2.value(&(c2 + (c1 - c2) * mid)) <= 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    c2 + (c1 - c2) * lo
}

/// Estimated radius of a body in its normalized coordinates, max ‖u‖ over {p ≤ 1}: the largest
/// boundary distance along 256 rays (Fibonacci directions) from the interior point, plus 10 %.
/// An estimate, not a bound (a thin spike between rays could be missed).
fn radius_estimate(body: &Body) -> Real {
    let c = body.posed(&Isometry3::identity()).to_normalized(&body.interior_point().coords);
    let p = body.polynomial();
    let n = 256;
    let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
    let mut r_max: Real = 0.0;
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
        let r = (1.0 - z * z).sqrt();
        let dir = Vector3::new(r * (golden * i as Real).cos(), r * (golden * i as Real).sin(), z);
        let mut hi = 1.0;
        while p.value(&(c + dir * hi)) <= 1.0 && hi < 1e6 {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if p.value(&(c + dir * mid)) <= 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        r_max = r_max.max((c + dir * hi).norm());
    }
    1.1 * r_max
}

/// Result of the a-posteriori check of a level-0 solution.
struct Verification {
    /// Max |coefficient residual| of the sos identity with the returned (γ, τ ≥ 0, Q).
    residual: Real,
    /// Smallest eigenvalue over the Gram blocks after folding the residual into them.
    min_eigenvalue: Real,
    /// γ + Σ_b min(λ_b, 0) · Z_b: a lower bound on the program's true optimum provided Z_b bounds
    /// ‖z_b(w)‖² on the feasible set.
    bound: Real,
}

/// Checks a level-0 solution a posteriori: takes the Gram blocks from Clarabel's PSD slacks
/// (strictly inside the cone), the multipliers clamped at 0, computes the coefficient residual
/// r = Σ_b z_bᵀQ_b z_b − (f − γ − Σₖ τₖ(1 − gₖ)), folds each r_α into one Gram entry of a block
/// holding w^α (a diagonal entry when possible), so that the identity holds exactly with the
/// corrected blocks Q_b', and bounds f − γ ≥ Σ_b λ_min(Q_b') ‖z_b‖² on the feasible set.
fn verify_level0(
    blocks: &[GramStructure],
    objective: &[Real],
    constraints: &[&[Real]],
    level0: &Level0Solution,
    z_bounds: &[Real],
) -> Verification {
    let sol = &level0.sol;
    let gamma = sol.x[level0.gamma];
    let taus: Vec<Real> = level0.multipliers.iter().map(|&c| sol.x[c].max(0.0)).collect();
    let mut grams: Vec<nalgebra::DMatrix<Real>> = blocks
        .iter()
        .zip(&level0.psd_rows)
        .map(|(g, &row)| crate::poly::gram::unpack_triangle(&sol.s[row..row + triangle_len(g.size())], g.size()))
        .collect();
    let nf = objective.len();
    let mut r = vec![0.0; nf];
    for (g, q) in blocks.iter().zip(&grams) {
        for (rk, ck) in r.iter_mut().zip(g.polynomial_of(q)) {
            *rk += ck;
        }
    }
    for (alpha, rk) in r.iter_mut().enumerate() {
        let mut rhs = objective[alpha];
        if alpha == 0 {
            rhs -= gamma;
        }
        for (tau, g) in taus.iter().zip(constraints) {
            rhs -= tau * (if alpha == 0 { 1.0 } else { 0.0 } - g[alpha]);
        }
        *rk -= rhs;
    }
    let residual = r.iter().fold(0.0, |m: Real, v| m.max(v.abs()));
    // Fold: subtract r_α from one entry (i, j) with z_i z_j = w^α, a diagonal one when possible.
    let mut target: Vec<Option<(usize, usize, usize)>> = vec![None; nf];
    for (b, g) in blocks.iter().enumerate() {
        for j in 0..g.size() {
            for i in 0..=j {
                let slot = &mut target[g.product_of_entry[triangle_index(i, j)]];
                if slot.is_none() || (i == j && slot.is_some_and(|(_, si, sj)| si != sj)) {
                    *slot = Some((b, i, j));
                }
            }
        }
    }
    for (&ra, t) in r.iter().zip(&target) {
        match *t {
            Some((b, i, j)) if i == j => grams[b][(i, i)] -= ra,
            Some((b, i, j)) => {
                grams[b][(i, j)] -= 0.5 * ra;
                grams[b][(j, i)] -= 0.5 * ra;
            }
            None => {}
        }
    }
    let mut min_eigenvalue = Real::INFINITY;
    let mut bound = gamma;
    for (q, z) in grams.into_iter().zip(z_bounds) {
        let lambda = q.symmetric_eigenvalues().min();
        min_eigenvalue = min_eigenvalue.min(lambda);
        bound += lambda.min(0.0) * z;
    }
    Verification { residual, min_eigenvalue, bound }
}

/// Columns and dual positions of a solved level-0 program.
struct Level0Solution {
    sol: ConicSolution,
    gamma: usize,
    multipliers: Vec<usize>,
    /// First row (in `sol.s`) of each Gram block's PSD slack.
    psd_rows: Vec<usize>,
    /// For each monomial of the full basis, its equality row's index in `sol.z` (if it has one).
    row_of: Vec<Option<usize>>,
}

/// Solves `max γ s.t. f − γ − Σₖ τₖ (1 − gₖ) = Σ_b z_b(w)ᵀ Q_b z_b(w), Q_b ⪰ 0, τ ≥ 0`, with f and gₖ
/// given by their coefficients in the blocks' common `full_basis`. Row α reads
/// `Σ_b (weights) svec(Q_b) + γ [α = 0] + Σₖ τₖ ([α = 0] − gₖ,α) = f_α`; monomials no term touches
/// get no row.
fn solve_level0(
    blocks: &[GramStructure],
    objective: &[Real],
    constraints: &[&[Real]],
    params: &CertificateParams,
) -> Result<Level0Solution> {
    let nf = blocks.first().map_or(0, |g| g.full_basis.len());
    let mut builder = ConicBuilder::new();
    let gamma = builder.add_variables(1);
    let first_tau = builder.add_variables(constraints.len());
    let multipliers: Vec<usize> = (0..constraints.len()).map(|k| first_tau + k).collect();
    builder.set_objective(gamma, -1.0);

    let mut rows: Vec<Row> = vec![Vec::new(); nf];
    let mut psd_rows = Vec::with_capacity(blocks.len());
    for gram in blocks {
        psd_rows.push(builder.num_rows());
        let q = builder.add_psd_variable(gram.size());
        for j in 0..gram.size() {
            for i in 0..=j {
                let k = triangle_index(i, j);
                rows[gram.product_of_entry[k]].push((q + k, gram_weight(i, j)));
            }
        }
    }
    rows[0].push((gamma, 1.0));
    for (k, g) in constraints.iter().enumerate() {
        for (alpha, row) in rows.iter_mut().enumerate() {
            let coeff = if alpha == 0 { 1.0 } else { 0.0 } - g[alpha];
            if coeff != 0.0 {
                row.push((multipliers[k], coeff));
            }
        }
    }
    let first_row = builder.num_rows();
    let mut row_of = vec![None; nf];
    let (mut kept, mut rhs) = (Vec::new(), Vec::new());
    for (alpha, row) in rows.into_iter().enumerate() {
        if row.is_empty() {
            if objective[alpha] != 0.0 {
                return Err(Error::Numerical(format!(
                    "level-0 sos certificate: monomial {alpha} of the objective is outside every Gram block"
                )));
            }
            continue;
        }
        row_of[alpha] = Some(first_row + kept.len());
        kept.push(row);
        rhs.push(objective[alpha]);
    }
    builder.add_equalities(kept, rhs);
    builder.add_inequalities(multipliers.iter().map(|&c| vec![(c, -1.0)]).collect(), vec![0.0; multipliers.len()]);

    let sol = builder.solve(quiet_settings(params.tolerance, params.max_iterations))?;
    match sol.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            Ok(Level0Solution { sol, gamma, multipliers, psd_rows, row_of })
        }
        SolverStatus::Unsolved
        | SolverStatus::PrimalInfeasible
        | SolverStatus::DualInfeasible
        | SolverStatus::AlmostPrimalInfeasible
        | SolverStatus::AlmostDualInfeasible
        | SolverStatus::MaxIterations
        | SolverStatus::MaxTime
        | SolverStatus::NumericalError
        | SolverStatus::InsufficientProgress
        | SolverStatus::CallbackTerminated => Err(Error::Numerical(format!(
            "level-0 sos certificate: Clarabel ended with status {:?} after {} iterations",
            sol.status, sol.iterations
        ))),
    }
}

/// The exponent vector in `n` variables with one added to each listed variable.
fn unit_exponent(n: usize, vars: &[usize]) -> Vec<u8> {
    let mut e = vec![0u8; n];
    for &i in vars {
        e[i] += 1;
    }
    e
}

/// Coefficients of a trivariate polynomial in `gram.full_basis`, its variables placed at
/// positions `offset..offset + 3` of the Gram structure's variables.
fn embed(p: &Polynomial, gram: &GramStructure, offset: usize) -> Vec<Real> {
    let n = gram.full_basis[0].len();
    let mut out = vec![0.0; gram.full_basis.len()];
    for (c, e) in p.coefficients().iter().zip(p.exponents()) {
        if *c == 0.0 {
            continue;
        }
        let mut ex = vec![0u8; n];
        ex[offset..offset + 3].copy_from_slice(e);
        // Every monomial of p has degree ≤ 2d, so it is in the full basis.
        if let Some(&k) = gram.index_of.get(&ex) {
            out[k] += c;
        }
    }
    out
}

/// First-order pseudo-moments `L(w₁), …, L(wₙ)` from the duals of the equality rows, normalized by
/// `L(1)`; `None` unless finite.
fn moments_first_order(gram: &GramStructure, level0: &Level0Solution, n: usize) -> Option<Vec<Real>> {
    let z = &level0.sol.z;
    let y0 = *z.get(level0.row_of[0]?)?;
    if !(y0.is_finite() && y0.abs() > 1e-12) {
        return None;
    }
    let w: Vec<Real> = (0..n)
        .map(|i| level0.row_of[gram.index_of[&unit_exponent(n, &[i])]].and_then(|r| z.get(r)).map(|v| v / y0))
        .collect::<Option<_>>()?;
    w.iter().all(|v| v.is_finite()).then_some(w)
}

/// Smallest-eigenvalue ratio λ₀/λ_max of a Gram block below which its eigenvector counts as a
/// kernel vector, and the gap λ₁/λ_max the next eigenvalue must exceed for the kernel to be
/// one-dimensional ([`kernel_point`]).
const KERNEL_RELATIVE_EIGENVALUE: Real = 1e-5;

/// The point w* recovered from the kernel of the first Gram block (paper §IV-A): the sos
/// certificate `σ(w) = Σ_b z_b(w)ᵀ Q_b z_b(w)` vanishes at a minimizer, so each `Q_b z_b(w*) = 0`.
/// The first block's basis starts `(1, w₁, …, wₙ)`, so a one-dimensional kernel spanned by v gives
/// `w* = (v₁, …, vₙ)/v₀`. `None` when the smallest eigenvalue is not small relative to the largest,
/// the kernel has dimension > 1 (no unique minimizer to read off), or v₀ ≈ 0.
fn kernel_point(gram: &GramStructure, level0: &Level0Solution, n: usize) -> Option<Vec<Real>> {
    let size = gram.size();
    let row = *level0.psd_rows.first()?;
    let q = crate::poly::gram::unpack_triangle(level0.sol.s.get(row..row + triangle_len(size))?, size);
    let eig = nalgebra::SymmetricEigen::new(q);
    let mut order: Vec<usize> = (0..size).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let top = eig.eigenvalues[order[size - 1]].abs().max(Real::MIN_POSITIVE);
    let (l0, l1) = (eig.eigenvalues[order[0]], eig.eigenvalues.get(order.get(1).copied()?).copied()?);
    if !(l0.abs() <= KERNEL_RELATIVE_EIGENVALUE * top && l1 > KERNEL_RELATIVE_EIGENVALUE * top) {
        return None;
    }
    let v = eig.eigenvectors.column(order[0]);
    let v0 = v[0];
    if !(v0.abs() > 1e-8 && size > n) {
        return None;
    }
    let w: Vec<Real> = (1..=n).map(|i| v[i] / v0).collect();
    w.iter().all(|x| x.is_finite()).then_some(w)
}

/// World point of normalized coordinates `u` of `body` under `pose`.
fn world_point(body: &Body, pose: &Isometry3, u: &Vector3) -> Point3 {
    pose * Point3::from(body.center() + u * body.scale())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{ellipsoid, FitReport};
    use crate::math::pose_from_parts;

    fn pose(q: [Real; 4], t: [Real; 3]) -> Isometry3 {
        let n = q.iter().map(|v| v * v).sum::<Real>().sqrt();
        pose_from_parts("pose", [q[0] / n, q[1] / n, q[2] / n, q[3] / n], t).unwrap()
    }

    /// `p(u) = a‖u‖² + b Σ uᵢ^(2k)`: sos-convex (a sum of sos-convex terms), degree 2k, minimum 0 at 0.
    fn power_body(k: u8, a: Real, b: Real, center: [Real; 3], scale: Real) -> Body {
        let terms = [
            ([2, 0, 0], a),
            ([0, 2, 0], a),
            ([0, 0, 2], a),
            ([2 * k, 0, 0], b),
            ([0, 2 * k, 0], b),
            ([0, 0, 2 * k], b),
        ];
        Body::new(Polynomial::from_terms(2 * k as usize, &terms).unwrap(), center, scale, FitReport::default()).unwrap()
    }

    fn dir(theta: Real, phi: Real) -> Vector3 {
        Vector3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
    }

    /// Brute-force minimum of `f` over the unit sphere: a 90 × 180 grid in (θ, φ), then a compass
    /// search from the best grid point with steps halved down to 1e-10 rad.
    fn sphere_min(f: impl Fn(&Vector3) -> Real) -> (Real, Vector3) {
        let (nt, np) = (90, 180);
        let (ht, hp) = (std::f64::consts::PI / nt as Real, 2.0 * std::f64::consts::PI / np as Real);
        let mut best = (Real::INFINITY, 0.0, 0.0);
        for i in 0..=nt {
            for j in 0..np {
                let (t, p) = (i as Real * ht, j as Real * hp);
                let v = f(&dir(t, p));
                if v < best.0 {
                    best = (v, t, p);
                }
            }
        }
        let (mut v, mut t, mut p) = best;
        let mut h = ht;
        while h > 1e-10 {
            let mut improved = false;
            for (dt, dp) in [(h, 0.0), (-h, 0.0), (0.0, h), (0.0, -h), (h, h), (-h, -h), (h, -h), (-h, h)] {
                let w = f(&dir(t + dt, p + dp));
                if w < v {
                    (v, t, p) = (w, t + dt, p + dp);
                    improved = true;
                }
            }
            if !improved {
                h *= 0.5;
            }
        }
        (v, dir(t, p))
    }

    /// Boundary point of a posed body whose polynomial has its minimum 0 at u = 0, in direction n
    /// of its normalized frame: p(ρ n) = 1 by bisection on ρ.
    fn boundary(body: &Body, pose: &Isometry3, n: &Vector3) -> Point3 {
        let (mut lo, mut hi) = (0.0, 1.0);
        while body.polynomial().value(&(n * hi)) < 1.0 {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if body.polynomial().value(&(n * mid)) < 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        pose * Point3::from(body.center() + n * (0.5 * (lo + hi) * body.scale()))
    }

    /// Brute-force distance from a posed body (minimum 0 at u = 0) to a sphere: min over the
    /// body's boundary of ‖x − c‖, minus r.
    fn brute_distance_to_sphere(body: &Body, pose: &Isometry3, c: &Point3, r: Real) -> Real {
        sphere_min(|n| (boundary(body, pose, n) - c).norm()).0 - r
    }

    /// Brute-force d(p₁‖p₂) when p₁'s minimizer lies outside body 2: min of p₁' over body 2's boundary.
    fn brute_growth(p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3) -> Real {
        let b1 = p1.posed(pose1);
        sphere_min(|n| b1.value(&boundary(p2, pose2, n).coords)).0
    }

    /// Support function of a posed axis-aligned ellipsoid {Σ((xᵢ − cᵢ)/rᵢ)² ≤ 1}:
    /// h(n) = n·(R c + t) + ‖diag(r) Rᵀ n‖.
    fn ellipsoid_support(c: [Real; 3], r: [Real; 3], pose: &Isometry3, n: &Vector3) -> Real {
        let local = pose.rotation.inverse() * n;
        let center = pose * Point3::new(c[0], c[1], c[2]);
        n.dot(&center.coords) + Vector3::new(r[0] * local.x, r[1] * local.y, r[2] * local.z).norm()
    }

    /// Brute-force distance between separated posed ellipsoids by separating-plane duality:
    /// dist = max over unit n of [−h_B(−n) − h_A(n)].
    fn brute_ellipsoid_distance(
        ca: [Real; 3],
        ra: [Real; 3],
        pa: &Isometry3,
        cb: [Real; 3],
        rb: [Real; 3],
        pb: &Isometry3,
    ) -> Real {
        -sphere_min(|n| ellipsoid_support(cb, rb, pb, &-n) + ellipsoid_support(ca, ra, pa, n)).0
    }

    fn sphere(c: [Real; 3], r: Real) -> Body {
        ellipsoid(c, [r; 3]).unwrap()
    }

    #[test]
    fn sphere_distance_matches_closed_form_with_witnesses() {
        let (c1, r1, c2, r2) = (Vector3::new(0.3, -0.2, 0.1), 0.7, Vector3::new(2.1, 0.9, -0.4), 0.5);
        let a = sphere([0.0; 3], r1);
        let b = sphere([0.0; 3], r2);
        let pa = pose([0.9, 0.2, -0.1, 0.3], c1.into());
        let pb = pose([0.4, -0.5, 0.6, 0.1], c2.into());
        let cert = certify_distance(&a, &pa, &b, &pb).unwrap();
        let expected = (c2 - c1).norm() - r1 - r2;
        assert!((cert.distance - expected).abs() < 1e-6, "{} vs {expected}", cert.distance);
        assert!((cert.squared_distance - expected * expected).abs() < 1e-6);
        assert_eq!(cert.gram_sizes, vec![7, 4, 4]);
        assert_eq!(cert.solver_status, "Solved");
        assert!(cert.residual < 1e-8, "residual {}", cert.residual);
        let verified = cert.verified_squared_distance;
        assert!(verified <= expected * expected + 1e-9 && verified > expected * expected - 1e-7, "{cert:?}");
        // KKT: 2(x − y) + τ∇p_a = 0 with ∇p_a = 2(x − c₁)/r₁², |x − c₁| = r₁  ⇒  τ = r₁ · dist.
        assert!((cert.tau - r1 * expected).abs() < 1e-5, "tau {}", cert.tau);
        assert!((cert.xi - r2 * expected).abs() < 1e-5, "xi {}", cert.xi);
        let (x, y) = cert.witnesses.unwrap();
        let n = (c2 - c1).normalize();
        assert!((x.coords - (c1 + n * r1)).norm() < 1e-5, "x* = {x}");
        assert!((y.coords - (c2 - n * r2)).norm() < 1e-5, "y* = {y}");
        // Paper §IV-A: the same witnesses from the kernel of the (1, u, v) Gram block.
        let (xk, yk) = cert.kernel_witnesses.expect("one-dimensional Gram kernel");
        assert!((xk.coords - (c1 + n * r1)).norm() < 1e-4, "kernel x* = {xk}");
        assert!((yk.coords - (c2 - n * r2)).norm() < 1e-4, "kernel y* = {yk}");
    }

    #[test]
    fn separating_hyperplane_bound_matches_sphere_support_functions() {
        let (c1, r1, c2, r2) = (Vector3::new(0.3, -0.2, 0.1), 0.7, Vector3::new(2.1, 0.9, -0.4), 0.5);
        let (a, b) = (sphere([0.0; 3], r1), sphere([0.0; 3], r2));
        let pa = pose([0.9, 0.2, -0.1, 0.3], c1.into());
        let pb = pose([0.4, -0.5, 0.6, 0.1], c2.into());
        let params = CertificateParams::default();
        // At the true witnesses the excesses vanish and the bound is the distance.
        let n = (c2 - c1).normalize();
        let expected = (c2 - c1).norm() - r1 - r2;
        let (x, y) = (Point3::from(c1 + n * r1), Point3::from(c2 - n * r2));
        let h = certify_separation(&a, &pa, &b, &pb, &x, &y, &params).unwrap();
        assert!((h.lower_bound - expected).abs() < 1e-6, "{h:?}");
        assert!(h.verified_lower_bound <= expected + 1e-9 && expected - h.verified_lower_bound < 1e-6, "{h:?}");
        assert!(h.excess.0.abs() < 1e-6 && h.excess.1.abs() < 1e-6, "{h:?}");
        // Off-optimal points on the spheres: the bound is that of the hyperplane of normal
        // m = (y − x)/‖y − x‖, closed form m·(c₂ − c₁) − r₁ − r₂ (sphere support functions).
        let tilt = (n + Vector3::new(0.0, 0.3, 0.2)).normalize();
        let (x, y) = (Point3::from(c1 + tilt * r1), Point3::from(c2 - tilt * r2));
        let m = (y - x).normalize();
        let plane = m.dot(&(c2 - c1)) - r1 - r2;
        let h = certify_separation(&a, &pa, &b, &pb, &x, &y, &params).unwrap();
        assert!((h.lower_bound - plane).abs() < 1e-6, "{} vs {plane}", h.lower_bound);
        assert!(h.verified_lower_bound <= expected + 1e-9 && plane < expected);
        assert!(certify_separation(&a, &pa, &b, &pb, &x, &x, &params).is_err());
    }

    #[test]
    fn overlapping_spheres_certify_zero() {
        let a = sphere([0.5, 0.0, 0.0], 1.0);
        let b = sphere([0.0, 0.0, 0.0], 0.8);
        let cert =
            certify_distance(&a, &Isometry3::identity(), &b, &pose([1.0, 0.0, 0.0, 0.0], [1.2, 0.3, 0.0])).unwrap();
        assert!(cert.squared_distance.abs() <= 1e-7, "γ = {}", cert.squared_distance);
        let (x, y) = cert.witnesses.unwrap();
        assert!((x - y).norm() < 1e-4);
        assert!(a.value_at(&x) <= 1.0 + 1e-6);
    }

    #[test]
    fn sphere_growth_matches_closed_form() {
        let s1 = sphere([0.0; 3], 0.5);
        let s2 = sphere([0.0; 3], 0.8);
        for (k, t2) in [[3.0, 0.2, -0.1], [1.5, -0.4, 0.3], [0.9, 0.1, 0.0], [0.2, 0.1, 0.1]].iter().enumerate() {
            let (c1, c2) = (Vector3::new(0.1, 0.2, 0.3), Vector3::from(*t2));
            let p1 = pose([0.8, 0.1, 0.5, -0.2], c1.into());
            let p2 = pose([0.3, 0.9, 0.0, 0.4], c2.into());
            let cert = certify_growth(&s1, &p1, &s2, &p2).unwrap();
            let expected = ((c1 - c2).norm() - 0.8).max(0.0).powi(2) / 0.25;
            assert!((cert.value - expected).abs() < 1e-7 * expected.max(1.0), "case {k}: {} vs {expected}", cert.value);
            // The a-posteriori check: exact identity up to a tiny residual, bound below the truth.
            assert_eq!(cert.solver_status, "Solved", "case {k}");
            assert!(cert.residual < 1e-8 * expected.max(1.0), "case {k}: residual {}", cert.residual);
            assert!(cert.verified_value <= expected + 1e-9 * expected.max(1.0), "case {k}: {cert:?}");
            assert!(cert.value - cert.verified_value < 1e-7 * expected.max(1.0), "case {k}: {cert:?}");
            // The single-pass (plain frame) certificate gives the same value.
            let plain = CertificateParams { recenter: false, ..Default::default() };
            let single = certify_growth_with_params(&s1, &p1, &s2, &p2, &plain).unwrap();
            assert!((single.value - expected).abs() < 1e-7 * expected.max(1.0), "case {k}: {single:?}");
            if expected > 0.0 {
                let x = cert.minimizer.unwrap();
                let want = c2 + (c1 - c2).normalize() * 0.8;
                assert!((x.coords - want).norm() < 1e-4, "case {k}: x* = {x}");
            }
        }
    }

    #[test]
    fn rotated_ellipsoids_match_brute_force_and_are_pose_invariant() {
        let (ca, ra) = ([0.1, -0.2, 0.0], [0.9, 0.3, 0.5]);
        let (cb, rb) = ([0.0, 0.3, 0.1], [0.4, 1.0, 0.2]);
        let a = ellipsoid(ca, ra).unwrap();
        let b = ellipsoid(cb, rb).unwrap();
        let pa = pose([0.9, 0.1, 0.3, 0.3], [0.2, -0.1, 0.4]);
        let pb = pose([0.2, -0.7, 0.4, 0.5], [2.6, 1.0, -0.4]);
        let cert = certify_distance(&a, &pa, &b, &pb).unwrap();
        let brute = brute_ellipsoid_distance(ca, ra, &pa, cb, rb, &pb);
        assert!(brute > 0.3, "test pair must be separated, brute = {brute}");
        assert!((cert.distance - brute).abs() < 1e-6, "{} vs brute {brute}", cert.distance);
        let (x, y) = cert.witnesses.unwrap();
        assert!(((x - y).norm() - brute).abs() < 1e-5);
        assert!((a.value_at(&(pa.inverse() * x)) - 1.0).abs() < 1e-5);

        let g = certify_growth(&a, &pa, &b, &pb).unwrap();
        let g_brute = brute_growth(&a, &pa, &b, &pb);
        assert!((g.value - g_brute).abs() < 1e-6 * g_brute.max(1.0), "{} vs brute {g_brute}", g.value);
        let g21 = certify_growth(&b, &pb, &a, &pa).unwrap();
        let g21_brute = brute_growth(&b, &pb, &a, &pa);
        assert!((g21.value - g21_brute).abs() < 1e-6 * g21_brute.max(1.0), "{} vs {g21_brute}", g21.value);

        // Same rigid motion applied to both bodies: both certificates unchanged.
        let motion = pose([0.3, 0.5, -0.6, 0.2], [10.0, -4.0, 7.5]);
        let (ma, mb) = (motion * pa, motion * pb);
        let moved = certify_distance(&a, &ma, &b, &mb).unwrap();
        assert!((moved.squared_distance - cert.squared_distance).abs() < 1e-7);
        let moved_g = certify_growth(&a, &ma, &b, &mb).unwrap();
        assert!((moved_g.value - g.value).abs() < 1e-7 * g.value.max(1.0));
        let (mx, _) = moved.witnesses.unwrap();
        assert!((mx - motion * x).norm() < 1e-5);
    }

    #[test]
    fn quartic_body_matches_brute_force() {
        // p = 0.2‖u‖² + (u₁⁴ + u₂⁴ + u₃⁴), a rounded cube, scale 0.6.
        let quartic = power_body(2, 0.2, 1.0, [0.1, 0.0, -0.1], 0.6);
        let pq = pose([0.7, 0.3, -0.2, 0.5], [0.3, 0.2, -0.1]);
        let ball = sphere([0.0; 3], 0.4);
        let c = Point3::new(1.6, 1.0, 0.5);
        let pc = pose([1.0, 0.0, 0.0, 0.0], c.coords.into());
        let cert = certify_distance(&quartic, &pq, &ball, &pc).unwrap();
        assert_eq!(cert.gram_sizes, vec![7, 10, 10]);
        let brute = brute_distance_to_sphere(&quartic, &pq, &c, 0.4);
        assert!(brute > 0.2, "brute {brute}");
        assert!((cert.distance - brute).abs() < 1e-6, "{} vs brute {brute}", cert.distance);
        // The full 6-variable Gram form (N = 28) gives the same bound.
        let full = CertificateParams { full_gram: true, ..Default::default() };
        let cert_full = certify_distance_with_params(&quartic, &pq, &ball, &pc, &full).unwrap();
        assert_eq!(cert_full.gram_sizes, vec![28]);
        assert!((cert_full.squared_distance - cert.squared_distance).abs() < 1e-7);
        let ((x, _), (xf, _)) = (cert.witnesses.unwrap(), cert_full.witnesses.unwrap());
        assert!((x - xf).norm() < 1e-4);

        // Growth both ways against an ellipsoid.
        let e = ellipsoid([0.0; 3], [0.3, 0.7, 0.4]).unwrap();
        let pe = pose([0.5, 0.5, 0.5, -0.5], [1.2, -0.6, 0.5]);
        let g = certify_growth(&quartic, &pq, &e, &pe).unwrap();
        let g_brute = brute_growth(&quartic, &pq, &e, &pe);
        assert!((g.value - g_brute).abs() < 1e-6 * g_brute.max(1.0), "{} vs brute {g_brute}", g.value);
        let g = certify_growth(&e, &pe, &quartic, &pq).unwrap();
        let g_brute = brute_growth(&e, &pe, &quartic, &pq);
        assert!((g.value - g_brute).abs() < 1e-6 * g_brute.max(1.0), "{} vs brute {g_brute}", g.value);
    }

    #[test]
    fn sextic_body_matches_brute_force() {
        let sextic = power_body(3, 0.3, 2.0, [0.0; 3], 0.5);
        let ps = pose([0.6, -0.2, 0.7, 0.1], [-0.2, 0.1, 0.0]);
        let c = Point3::new(-1.1, 0.8, 0.6);
        let ball = sphere([0.0; 3], 0.3);
        let cert = certify_distance(&sextic, &ps, &ball, &pose([1.0, 0.0, 0.0, 0.0], c.coords.into())).unwrap();
        assert_eq!(cert.gram_sizes, vec![7, 20, 20]);
        let brute = brute_distance_to_sphere(&sextic, &ps, &c, 0.3);
        assert!((cert.distance - brute).abs() < 1e-6, "{} vs brute {brute}", cert.distance);
    }

    #[test]
    fn invalid_params_name_the_field() {
        let s = sphere([0.0; 3], 1.0);
        let id = Isometry3::identity();
        let bad = CertificateParams { tolerance: -1.0, ..Default::default() };
        let err = certify_distance_with_params(&s, &id, &s, &id, &bad).unwrap_err();
        assert!(err.to_string().contains("params.tolerance"), "{err}");
        let bad = CertificateParams { max_iterations: 0, ..Default::default() };
        let err = certify_growth_with_params(&s, &id, &s, &id, &bad).unwrap_err();
        assert!(err.to_string().contains("params.max_iterations"), "{err}");
        // Too few iterations is a Numerical error naming Clarabel's status.
        let few = CertificateParams { max_iterations: 1, ..Default::default() };
        let err =
            certify_distance_with_params(&s, &id, &s, &pose([1.0, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0]), &few).unwrap_err();
        assert!(err.to_string().contains("MaxIterations"), "{err}");
    }

    /// Solve times at 2d = 2, 4, 6 (run with `cargo test --release --lib solve_times -- --ignored --nocapture`).
    #[test]
    #[ignore]
    fn solve_times() {
        let bodies =
            [sphere([0.0; 3], 0.5), power_body(2, 0.2, 1.0, [0.0; 3], 0.5), power_body(3, 0.2, 1.0, [0.0; 3], 0.5)];
        let pa = pose([0.9, 0.1, 0.3, 0.3], [0.0; 3]);
        let pb = pose([0.2, -0.7, 0.4, 0.5], [1.5, 0.4, -0.2]);
        for body in &bodies {
            let reps = 10;
            let (mut td, mut tg, mut wall) = (0.0, 0.0, 0.0);
            let (mut n_d, mut n_g) = (Vec::new(), 0);
            for _ in 0..reps {
                let start = std::time::Instant::now();
                let d = certify_distance(body, &pa, body, &pb).unwrap();
                wall += start.elapsed().as_secs_f64();
                td += d.solve_seconds;
                n_d = d.gram_sizes;
                let g = certify_growth(body, &pa, body, &pb).unwrap();
                tg += g.solve_seconds;
                n_g = g.gram_size;
            }
            println!(
                "2d = {}: distance N = {n_d:?}: {:.2} ms in Clarabel ({:.2} ms with build); growth N = {n_g}: {:.2} ms",
                body.degree(),
                1e3 * td / reps as Real,
                1e3 * wall / reps as Real,
                1e3 * tg / reps as Real
            );
            if body.degree() <= 4 {
                let full = CertificateParams { full_gram: true, ..Default::default() };
                let d = certify_distance_with_params(body, &pa, body, &pb, &full).unwrap();
                println!("   full 6-variable form N = {:?}: {:.2} ms", d.gram_sizes, 1e3 * d.solve_seconds);
            }
        }
    }
}
