//! Building compound bodies (paper §V): a nonconvex mesh is split into convex parts by a convex
//! decomposition, each part is fitted as a sos-convex body, and the parts are grouped bottom-up
//! into a containment tree whose parents contain their children by the S-procedure
//! ([`crate::containment`]). The tree type and its file format are `sublevel_core::compound`,
//! re-exported here.
//!
//! Files: [`decompose`] (VHACD parts of whole triangles), [`build`] (leaf fits, the tree, the
//! part-count search: [`fit_compound`]), [`surface`] (the Hausdorff excess of a node over the
//! mesh), `tree` (the containment tree over the leaves), [`check`] (every triangle covered), [`certify`] (every parent contains its children).

pub use sublevel_core::compound::*;

pub mod build;
pub mod certify;
pub mod check;
pub mod decompose;
pub mod surface;
mod tree;

#[cfg(test)]
mod build_tests;

pub use build::{fit_compound, CompoundSettings, PartCount};
