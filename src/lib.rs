//! # Sublevel
//!
//! Real-time collision queries between bodies modeled as 1-sublevel sets of sos-convex
//! polynomials, `{x ∈ ℝ³ : p(x) ≤ 1}`, following Ahmadi, Hall, Makadia and Sindhwani,
//! *Geometry of 3D Environments and Sum of Squares Polynomials*, Robotics: Science and Systems XIII
//! (RSS 2017); equation labels in the docs are those of the paper's LaTeX source (version 7).
//!
//! # Layout
//!
//! - [`math`]: `Real = f64`, point / vector / pose aliases, tolerances.
//! - [`error`]: the crate's one error enum.
//! - [`poly`]: monomial basis, polynomials with exact derivatives, Gram forms (paper §II).
//! - [`conic`]: a small builder for Clarabel cone programs (shared by fits and certificates).
//! - [`body`]: a fitted body and the same body under a pose (paper §IV-C).
//! - [`compound`]: compound bodies — a convex decomposition of a mesh fitted part by part,
//!   grouped into a containment tree of bodies (paper §V), with its file format.
//! - [`fit`]: fitting bodies to point clouds with Clarabel (paper §III), mesh loading.
//! - [`query`]: distance and growth queries by warm-started Newton / active-set methods, and
//!   their level-0 sos certificates (paper §IV-A, §IV-B); `query::tree`: the same queries between
//!   containment trees (compound bodies) by branch and bound (paper §V).
//! - [`scene`]: scenes of posed instances, warm-start caches, the persistent store.
//! - [`service`]: the gRPC API (`sublevel.v1`); the only module that knows tonic.
//!
//! The math core (`poly`, `conic`, `body`, `compound`, `fit`, `query`, `scene`) never imports `service`.

#![warn(missing_docs)]

pub mod body;
pub mod compound;
pub mod conic;
pub mod error;
pub mod fit;
pub mod math;
pub mod poly;
pub mod query;
pub mod scene;
#[cfg(feature = "server")]
pub mod service;

pub use body::{Body, PosedBody};
pub use error::{Error, Result};
