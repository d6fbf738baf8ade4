//! Level-0 sos certificates (paper eq. "distance.lasserre" with scalar multipliers, and its
//! analogue for eq. "overlap"), solved by Clarabel. STUB.
use crate::body::Body;
use crate::math::{Isometry3, Point3, Real};
use crate::Result;

/// Level-0 SDP bound on the squared distance.
#[derive(Clone, Debug)]
pub struct DistanceCertificate {
    /// γ*: lower bound on the squared distance (exact for sos-convex bodies).
    pub squared_distance: Real,
    /// √max(γ*, 0).
    pub distance: Real,
    /// Multiplier τ ≥ 0 of body A's constraint.
    pub tau: Real,
    /// Multiplier ξ ≥ 0 of body B's constraint.
    pub xi: Real,
    /// Witness points recovered from the Gram matrix's kernel, when available.
    pub witnesses: Option<(Point3, Point3)>,
    /// Clarabel's status.
    pub solver_status: String,
    /// Seconds inside Clarabel.
    pub solve_seconds: Real,
}

/// Level-0 SDP bound on d(p₁‖p₂).
#[derive(Clone, Debug)]
pub struct GrowthCertificate {
    /// γ*: lower bound on d(p₁‖p₂) (exact for sos-convex bodies).
    pub value: Real,
    /// Multiplier τ ≥ 0.
    pub tau: Real,
    /// Clarabel's status.
    pub solver_status: String,
    /// Seconds inside Clarabel.
    pub solve_seconds: Real,
}

/// Certifies the distance between two posed bodies.
///
/// # Errors
/// [`crate::Error::Numerical`] when Clarabel returns no usable solution.
pub fn certify_distance(_a: &Body, _pose_a: &Isometry3, _b: &Body, _pose_b: &Isometry3) -> Result<DistanceCertificate> {
    Err(crate::Error::Numerical("not implemented".into()))
}

/// Certifies d(p₁‖p₂).
///
/// # Errors
/// [`crate::Error::Numerical`] when Clarabel returns no usable solution.
pub fn certify_growth(_p1: &Body, _pose1: &Isometry3, _p2: &Body, _pose2: &Isometry3) -> Result<GrowthCertificate> {
    Err(crate::Error::Numerical("not implemented".into()))
}
