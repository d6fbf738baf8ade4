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
//! are expanded in w with [`sublevel_core::poly::Polynomial::compose_affine`] (3-variable Gram form,
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
//! 1e-7, [`CertificateParams::presolve_tolerance`]) in the plain frame (body 2's normalized coordinates for growth; each body's own for
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
//!
//! # Layout
//!
//! ```text
//! distance.rs     the distance certificate (six variables, block-structured or full Gram form)
//! growth.rs       the growth certificate (three variables, expanded in an affine frame)
//! separation.rs   the separating-hyperplane certificate: one support-function SDP per body
//! frame.rs        the affine frames of the certificates' variables (plain and recentered)
//! level0.rs       the generic level-0 program: build, solve with Clarabel, map the status
//! verify.rs       the a-posteriori check and the radius estimate its bound uses
//! witness.rs      witness points from the first-order moments and from the Gram kernel
//! ```

mod distance;
mod frame;
mod growth;
mod level0;
mod separation;
#[cfg(test)]
mod tests;
mod verify;
mod witness;

pub use distance::{certify_distance, certify_distance_with_params, DistanceCertificate};
pub use growth::{certify_growth, certify_growth_with_params, GrowthCertificate};
pub use separation::{certify_separation, SeparationCertificate};

use crate::{Error, Result};
use sublevel_core::math::Real;

/// Settings of the certificates: Clarabel's tolerance and cap, the program's form and its
/// recentering pass, the recovery of witness points, and the agreement rule by which the certified
/// answers compare Newton's values with the SDP's ([`crate::certified`]). The default
/// ([`CertificateParams::DEFAULT`]) is the tuned value of each; change fields with struct update
/// syntax, `CertificateParams { recenter: false, ..CertificateParams::default() }`.
#[derive(Clone, Copy, Debug, PartialEq)]
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
    /// Solve twice: a loose first pass (tolerance `presolve_tolerance`) locates the minimizer, then
    /// the program is re-solved with its variables centered there and scaled to `recenter_scale`
    /// times the smaller body's scale (module docs, "Conditioning"). Default `true`; without it, near-touching pairs of the fitted
    /// bodies can end `AlmostSolved` with errors up to 1e-4.
    pub recenter: bool,
    /// Clarabel's tolerance of the first (locating) pass of a recentered certificate (at least
    /// `tolerance`); default 10⁻⁷. Larger: a cheaper first pass, a less exact center for the
    /// second.
    pub presolve_tolerance: Real,
    /// Scale ρ of the recentered frame relative to the smaller body's scale (module docs,
    /// "Conditioning"); default ½, which keeps the centered variables of order 1 across the
    /// smaller body. Larger or smaller: the centered monomial basis scaled away from that size,
    /// a program conditioned worse.
    pub recenter_scale: Real,
    /// How far a recovered witness may exceed its body's level (p − 1, dimensionless) and still
    /// be reported (the SDP's own feasibility tolerance is far below), and how far Newton's
    /// witnesses may lie off their boundaries for the separating-hyperplane certificate; default
    /// 10⁻⁵. Larger: witnesses reported from less accurate solutions; smaller: fewer witnesses.
    pub witness_feasibility_tolerance: Real,
    /// Smallest-eigenvalue ratio λ₀/λ_max of the first Gram block below which its eigenvector
    /// counts as a kernel vector, and the ratio λ₁/λ_max the next eigenvalue must exceed for the
    /// kernel to be one-dimensional (a witness read off the kernel, paper §IV-A); default 10⁻⁵.
    /// Larger: kernel witnesses from less exact solutions; smaller: fewer kernel witnesses.
    pub kernel_relative_eigenvalue: Real,
    /// Relative tolerance of the agreement rule between Newton's value and the SDP's bound
    /// ([`crate::certified`], "Agreement rule"); default 10⁻⁶. Larger: more answers agree, an SDP
    /// fallback only on larger disagreements; smaller: more fallbacks on the SDP's rounding.
    pub agreement_relative: Real,
    /// Absolute tolerance of the agreement rule, in the objective's units (m² for the squared
    /// distance; dimensionless for d(p₁‖p₂)), for values near 0 (touching and overlapping pairs,
    /// where the SDP's bound is 0 up to its tolerance); default 10⁻⁹. Larger: more near-zero
    /// answers agree.
    pub agreement_absolute: Real,
    /// Slack on p(x) ≤ 1 when a common witness point certifies an overlap (distance 0): the point
    /// lies in both bodies scaled about their interior by at most this relative amount; default
    /// 10⁻⁹. Larger: more overlaps certified by their witness alone, also of bodies that only
    /// nearly touch.
    pub overlap_point_tolerance: Real,
    /// Largest displacement, relative to the body's scale, by which a moment-recovered point
    /// slightly outside its body is moved onto it (the moments of a thin body are accurate to
    /// about 10⁻⁸ m); default 10⁻⁴. Larger: witnesses from farther off the body kept.
    pub projection_max_shift: Real,
    /// An SDP distance answer with γ at most this times the larger body's scale squared counts as
    /// touching or overlapping; default 10⁻¹⁰. Larger: more near-touching SDP answers reported as
    /// overlapping.
    pub overlap_relative: Real,
}

impl CertificateParams {
    /// The default settings (a constant, for contexts that need one).
    pub const DEFAULT: Self = Self {
        tolerance: 1e-10,
        max_iterations: 200,
        full_gram: false,
        recenter: true,
        presolve_tolerance: 1e-7,
        recenter_scale: 0.5,
        witness_feasibility_tolerance: 1e-5,
        kernel_relative_eigenvalue: 1e-5,
        agreement_relative: 1e-6,
        agreement_absolute: 1e-9,
        overlap_point_tolerance: 1e-9,
        projection_max_shift: 1e-4,
        overlap_relative: 1e-10,
    };
}

impl Default for CertificateParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl CertificateParams {
    /// Checks the settings before any program is built.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `params.tolerance` (not in (0, 1)) or
    /// `params.max_iterations` (0).
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
