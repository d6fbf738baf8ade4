//! # Sublevel
//!
//! Real-time collision queries between bodies modeled as 1-sublevel sets of sos-convex
//! polynomials, `{x ∈ ℝ³ : p(x) ≤ 1}`, following Ahmadi, Hall, Makadia and Sindhwani,
//! *Geometry of 3D Environments and Sum of Squares Polynomials*, Robotics: Science and Systems XIII
//! (RSS 2017).
//!
//! This crate is the `sublevel` binary and a facade over the workspace's crates, each re-exported
//! under the name of its floor:
//!
//! - [`math`], [`error`], [`poly`], [`conic`], [`body`], [`primitive`], [`report`], [`cancel`]:
//!   `sublevel-core`;
//! - [`fit`] (`sublevel-fit`): fitting bodies (paper §III) and, in [`compound`], compound bodies
//!   (paper §V);
//! - [`query`] (`sublevel-query`): distance and growth queries and their certificates (§IV), and
//!   in [`query::shape`] distances with exact primitives;
//! - [`robot`] (`sublevel-robot`): URDF robot models and forward kinematics;
//! - [`scene`] (`sublevel-scene`): scenes, warm-start caches, stores;
//! - [`service`] (`sublevel-server`): the gRPC API `sublevel.v1`.
//!
//! A library user of the query engine depends on `sublevel-query` alone, which compiles neither
//! tonic, tokio, redb nor plotters.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub use sublevel_core::{body, cancel, conic, error, math, poly, primitive, report};
pub use sublevel_core::{Body, Error, PosedBody, Primitive, Result};
pub use sublevel_fit as fit;
pub use sublevel_fit::compound;
pub use sublevel_plan as plan;
pub use sublevel_query as query;
pub use sublevel_robot as robot;
pub use sublevel_scene as scene;
pub use sublevel_server as service;
