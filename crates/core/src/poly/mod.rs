//! Polynomial core: monomial bases, dense trivariate polynomials with exact derivatives, and
//! Gram forms.
//!
//! Bodies are 1-sublevel sets `{x : p(x) ≤ 1}` of sos-convex trivariate polynomials of degree
//! 2d ∈ {2, 4, 6, 8} (paper §III). This module knows nothing of fitting or queries:
//!
//! - [`monomial`]: the graded-lex monomial basis z(x) and O(1) indexing;
//! - [`polynomial`]: [`Polynomial`] with allocation-free value / gradient / Hessian;
//! - [`fast`]: [`FastPoly`], precomputed derivative tables for the query hot path (from
//!   `sublevel-kernels`, re-exported);
//! - [`radial`]: [`RadialTable`], the radial function of a sublevel set about an interior point
//!   (cold starts of the query solvers);
//! - [`support`]: [`SupportTable`], the support map of a sublevel set (cold distance starts), and
//!   [`SupportBound`], certified upper bounds of its support function (cheap distance bounds);
//! - [`gram`]: Gram forms `z(x)ᵀ Q z(x)` in any number of variables, and Clarabel's packed-triangle
//!   convention used by every SDP in the crate.

#[cfg(test)]
mod fast_tests;
pub mod gram;
pub mod polynomial;
pub mod radial;
pub mod support;

pub use polynomial::{Eval, Polynomial, MAX_DEGREE};
pub use radial::RadialTable;
pub use sublevel_kernels::{fast, monomial};
pub use sublevel_kernels::{FastPoly, Soa4Eval, Soa8Eval32, SoaPoly, SymEval};
pub use support::{SupportBound, SupportTable};
