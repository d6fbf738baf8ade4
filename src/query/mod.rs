//! Proximity queries between posed bodies (paper §IV): Euclidean distance with witness points and
//! the growth measure d(p₁‖p₂), solved by a warm-started Newton / active-set method, and their
//! level-0 sos certificates.

pub mod distance;
pub mod growth;
pub mod newton;
pub mod sdp_certificate;

pub use distance::{distance, DistanceResult, DistanceWarmStart};
pub use growth::{growth, GrowthResult, GrowthWarmStart};
pub use newton::{NewtonParams, SolveStatus};
