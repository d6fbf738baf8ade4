//! # sublevel-core
//!
//! The core of Sublevel: bodies modeled as 1-sublevel sets of sos-convex polynomials,
//! `{x ∈ ℝ³ : p(x) ≤ 1}`, following Ahmadi, Hall, Makadia and Sindhwani, *Geometry of 3D
//! Environments and Sum of Squares Polynomials*, Robotics: Science and Systems XIII (RSS 2017);
//! equation labels in the docs are those of the paper's LaTeX source (version 7).
//!
//! - [`math`]: `Real = f64`, point / vector / pose aliases, tolerances, CPU feature detection.
//! - [`error`]: the one error enum of the Sublevel crates.
//! - [`cancel`]: cancellation scopes for long solves (fits, certificates, scene checks).
//! - [`poly`]: monomial basis, polynomials with exact derivatives, Gram forms (paper §II), the
//!   fast evaluation kernels and the support / radial tables.
//! - [`conic`]: a small builder for Clarabel cone programs (shared by fits and certificates).
//! - [`report`]: what a fit reports about its body (paper §III).
//! - [`body`]: a fitted body and the same body under a pose (paper §IV-C).
//! - [`primitive`]: exact primitives (box, sphere, cylinder, capsule, halfspace), bodies given by
//!   a few affine or quadratic constraints instead of a fitted polynomial.
//! - [`compound`]: compound bodies, a containment tree of bodies (paper §V), and its file format.
//! - [`blas`]: the thread count of the BLAS behind the SDP solves (one, unless the user sets
//!   `OPENBLAS_NUM_THREADS`).
//!
//! The fits live in `sublevel-fit`, the queries in `sublevel-query`.

#![warn(missing_docs)]
// `deny`, not `forbid`: the `blas` module allows the one foreign call to OpenBLAS.
#![deny(unsafe_code)]

pub mod blas;
pub mod body;
pub mod cancel;
pub mod compound;
pub mod conic;
pub mod error;
pub mod math;
pub mod poly;
pub mod primitive;
pub mod report;

pub use body::{Body, PosedBody};
pub use error::{Error, Result};
pub use primitive::{Primitive, PrimitiveFile};
