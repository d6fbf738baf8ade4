//! # sublevel-kernels
//!
//! The evaluation kernels of Sublevel and the only crate of the workspace with `unsafe` code and
//! `std::arch`: every other crate says `#![forbid(unsafe_code)]`, but for one foreign call in
//! `sublevel_core::blas` (OpenBLAS's thread count).
//!
//! - [`monomial`]: the graded-lex monomial basis in three variables and its O(1) indexing;
//! - [`fast`]: [`FastPoly`] and [`SoaPoly`], value / gradient / Hessian of a polynomial by nested
//!   Horner schemes over per-body derivative tables, one point at a time or four / eight points
//!   per pass (the query hot path, paper §IV);
//! - [`cpu`]: CPU feature detection, [`Avx2Fma`] (the proof that AVX2 and FMA code may run) and
//!   [`Avx2Fma::run`], which compiles a solver written once for AVX2 + FMA;
//! - [`lanes`]: the lane types the query solvers are written in once ([`Scalar`], and on x86-64
//!   [`F4`] and [`F8`], AVX registers made only with an [`Avx2Fma`] proof);
//! - [`Sym3`] and [`Eval`]: the kernels' symmetric-matrix and evaluation types.
//!
//! Every `unsafe` block states why it is sound (`// SAFETY:`); each rests on one of two facts: an
//! [`Avx2Fma`] value exists only on a CPU that runs AVX2 and FMA, and a table row is as long as
//! the load that reads it.

#![warn(missing_docs)]

pub mod cpu;
pub mod fast;
pub mod lanes;
pub mod monomial;

pub use cpu::{cpu_has_avx2_fma, Avx2Fma};
pub use fast::{FastPoly, Soa4Eval, Soa8Eval32, SoaPoly, SymEval};
pub use lanes::{Lane, LaneMask, Scalar};
#[cfg(target_arch = "x86_64")]
pub use lanes::{F4, F8, M4, M8};

/// The floating-point type of every computation (as `sublevel_core::math::Real`).
pub type Real = f64;
/// A vector in ℝ³.
pub type Vector3 = nalgebra::Vector3<Real>;
/// A 3 × 3 matrix.
pub type Matrix3 = nalgebra::Matrix3<Real>;

/// Largest total degree 2d of a polynomial the kernels evaluate (bodies have 2d ∈ {2, 4, 6, 8}).
pub const MAX_DEGREE: usize = 8;

/// Value, gradient and Hessian of a polynomial at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eval {
    /// p(u).
    pub value: Real,
    /// ∇p(u), shape 3.
    pub gradient: Vector3,
    /// ∇²p(u), symmetric 3 × 3.
    pub hessian: Matrix3,
}

/// A symmetric 3 × 3 matrix by its upper triangle `[xx, xy, xz, yy, yz, zz]`, the order the
/// Hessian kernels of [`FastPoly`] produce it in (their `[xx, xy, xz, yy]` and
/// `[yz, zz]` lanes). The query solvers carry their Hessians and KKT blocks in this form: 6 entries
/// to copy, scale and add instead of the 9 of a [`Matrix3`] (paper §IV; the blocks `2I + λ∇²p'`
/// of the distance KKT system and `∇²p₁' + μ∇²p₂'` of the growth one are symmetric).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sym3(pub [Real; 6]);

impl Sym3 {
    /// The upper triangle of `m` (its lower triangle is not read).
    pub fn from_upper(m: &Matrix3) -> Self {
        Self([m[(0, 0)], m[(0, 1)], m[(0, 2)], m[(1, 1)], m[(1, 2)], m[(2, 2)]])
    }

    /// The full symmetric matrix.
    pub fn to_matrix(&self) -> Matrix3 {
        let [xx, xy, xz, yy, yz, zz] = self.0;
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }

    /// `k · self`.
    #[inline(always)]
    pub fn scaled(&self, k: Real) -> Self {
        Self(self.0.map(|v| v * k))
    }
}
