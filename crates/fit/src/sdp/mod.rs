//! The semidefinite programs of every fit, in one place: the point-cloud fits of paper §III
//! (log det or trace of P or H, relaxed convexity) and the containment of bodies of paper §V
//! (S-procedure) are one cone program with two kinds of containment block.
//!
//! ```text
//! maximize    log det X   (or minimize trace X⁻¹),   X = P (ours, eq. "VAG.log.det")
//!                                                     or H = G (Magnani et al., eq. "Magnani.log.det")
//! subject to  p(u) = z(u)ᵀ P z(u),                      z = graded-lex monomials of degree ≤ d
//!             yᵀ∇²(p + c q) y = w(u, y)ᵀ G w(u, y),  G ⪰ 0,  w = y ⊗ z_{d−1}(u)
//!                                                     (p sos-convex; c > 0: eq. "VAG.param.convex")
//! and either  p(uᵢ) ≤ 1                               for every containment point uᵢ   (§III)
//! or          1 − p − τᵢ(1 − gᵢ) sos,  τᵢ sos          for every contained body {gᵢ ≤ 1} (§V)
//! ```
//!
//! - [`identities`]: the coefficient and sos-convexity identities, each solved for one Gram
//!   entry (no equality rows), in scaled monomial bases.
//! - [`program`]: [`GramProgram::build`] writes the objective block (`[[X, Z], [Zᵀ, diag Z]] ⪰ 0`
//!   with exponential cones `Zᵢᵢ ≥ exp(tᵢ)` for log det, `[[V, I], [I, X]] ⪰ 0` for trace), the
//!   other Gram matrix's cone (`G − εI ⪰ 0`, ε = [`CONVEXITY_FLOOR`]) and the containment block.
//! - [`solve`]: one [`SolverSettings`] turned into Clarabel's settings, the solve with progress
//!   and its retries, the status mapping ([`usable_status`]) and the exact containment rescale
//!   ([`rescale_to_contain`]) that every fit applies after its solve.
//!
//! Sizes (N = C(d+3, 3), M = 3·C(d+2, 3), L = C(2d+3, 3)), log det P with the chair's 320 hull
//! vertices:
//!
//! ```text
//! 2d   N    M   big block   G block   identities in P (L)   in G 6·C(2d+1, 3)   columns   rows
//!  2   4    3     8×8        3×3            10                     6                24     374
//!  4  10   12    20×20      12×12           35                    60               138     638
//!  6  20   30    40×40      30×30           84                   210               695    1665
//!  8  35   60    70×70      60×60          165                   504              2621    4740
//! ```
//!
//! The log det programs are affine-invariant up to a constant in the objective (a translation or
//! scaling of u maps z(u) by a triangular / diagonal matrix of constant determinant), so
//! normalizing the cloud only improves conditioning; it does not change the fitted body.

pub mod identities;
pub mod program;
pub mod solve;

pub(crate) use identities::pair_index;
pub use identities::{norm_power_coefficients, polynomial_of_gram};
pub use program::{
    Containment, ConvexityCone, GramProgram, Objective, ObjectiveMatrix, ProblemSpec, TraceBasis, CONVEXITY_FLOOR,
};
pub use solve::{
    max_on, rescale_to_contain, usable_status, KktSolver, RawSolution, SolverSettings, FIT_STATIC_REGULARIZATION,
    FIT_STEP_FRACTION,
};

#[cfg(test)]
mod tests;
