//! # sublevel-fit
//!
//! Fitting bodies to point clouds (paper §III: §III-A sos-convex, §III-B relaxed / inverse moment).
//!
//! [`fit_points`] turns a cloud into a [`Body`] `{x : p((x − c)/s) ≤ 1}` with p of
//! degree 2d (sos-convex unless the method relaxes convexity), in five stages, each reported
//! through the progress callback:
//!
//! ```text
//! Hull    validate, normalize (u = (x − c)/s, bounding box in [−1, 1]³), convex hull, and
//!         the frame(s) the SDP is solved in (u_fit = L·u + o; trace and c > 0 fits solve in
//!         the bounding cube and the principal box and keep the smaller body)      (hull.rs)
//! Build   the cone program of the method (log det / trace of P or H)                 (sdp/)
//!         or the moment matrix (inverse moment)                              (inverse_moment.rs)
//! Solve   Clarabel, one progress report per interior-point iteration; with relaxed
//!         convexity in rounds that add violated points as rows                     (relaxed.rs)
//! Verify  p on EVERY input point; if max p(uᵢ) > 1, divide p by it (exact containment)
//! Volume  seeded Monte Carlo in a provably containing box (convex bodies) or in cells
//!         proven to cover {p ≤ 1} (nonconvex sos bodies)                              (volume.rs)
//! ```
//!
//! Containment is never approximate: after the final rescale `max_i p(uᵢ) ≤ 1` holds in floating
//! point on every input point, and the largest value is recorded in the report.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

use sublevel_core::body::Body;
use sublevel_core::math::Point3;

pub use sublevel_core::report::FitReport;
pub use sublevel_core::{cancel, Error, Result};

pub mod auto;
pub mod baselines;
pub mod compound;
pub mod containment;
pub mod hull;
pub mod inverse_moment;
pub mod mesh;
mod pipeline;
pub mod relaxed;
pub mod sdp;
pub mod settings;
pub mod sos_convexity;
pub mod volume;

pub use sdp::{KktSolver, SolverSettings, FIT_STATIC_REGULARIZATION, FIT_STEP_FRACTION};
pub(crate) use settings::{report, validate_solver_fields};
pub use settings::{FitMethod, FitProgress, FitSettings, FitStage, PartProgress};

/// Fits a body to a point cloud with the formulation `settings.method` (paper §III).
///
/// `points` are in the mesh's units (meters). The returned body stores its polynomial in
/// normalized coordinates `u = (x − center)/scale` (see [`hull`] for the choice of center and
/// scale); its report holds the solver status, timings, hull and volume figures, the containment
/// rescale and the convexity margin.
///
/// - `LogDetP`, `TraceP`, `LogDetH`, `TraceH` with c = 0: p sos-convex, containment rows on the
///   convex-hull vertices only (a convex sublevel set containing them contains the cloud); the
///   margin is λ_min of the sos-convexity Gram matrix G of the final, rescaled p.
/// - `LogDetP`, `TraceP` with c = `convexity_relaxation` > 0 (eq. "VAG.param.convex"): p + c(‖u‖²)ᵈ
///   sos-convex in normalized coordinates u (the cloud's bounding box is normalized into [−1, 1]³; see
///   [`hull`] for why this scale). The body may be nonconvex, so containment rows are added in rounds (see
///   [`relaxed`]) until p ≤ 1 on every point; `report.nonconvex` is set and the margin is that of
///   the relaxed Gram matrix (of p + c(‖u‖²)ᵈ, divided by the containment rescale).
/// - With [`FitSettings::rows_in_rounds`] the rows are added in rounds for c = 0 too.
/// - `InverseMoment` (eq. "inverse.moment.poly", see [`inverse_moment`]): no SDP, nonconvex, no
///   margin.
///
/// Every body contains every input point: after the final rescale `max_i p(uᵢ) ≤ 1` holds in
/// floating point, and the largest value is recorded in the report.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for an empty, non-finite or degenerate cloud (for the
/// inverse moment also a singular moment matrix), or a settings field; [`Error::Numerical`] when
/// Clarabel ends with a status other than `Solved` / `AlmostSolved` (the status is named) or the
/// result is not a bounded body.
pub fn fit_points(points: &[Point3], settings: &FitSettings, progress: &mut dyn FnMut(&FitProgress)) -> Result<Body> {
    pipeline::fit(points, settings, progress)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::math::Real;
    use sublevel_core::Error;

    #[test]
    fn kkt_solver_names_round_trip() {
        for s in [KktSolver::Faer, KktSolver::Qdldl] {
            assert_eq!(s.name().parse::<KktSolver>().unwrap(), s);
        }
        match "pardiso".parse::<KktSolver>() {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "linear_solver"),
            other => panic!("expected InvalidArgument(linear_solver), got {other:?}"),
        }
    }

    #[test]
    fn settings_are_validated_by_field() {
        let pts: Vec<Point3> =
            (0..10).map(|i| Point3::new(i as Real, (i * i) as Real, (i * i * i % 5) as Real)).collect();
        for (s, field) in [
            (FitSettings::default().with_degree(3), "degree"),
            (FitSettings::default().with_degree(10), "degree"),
            (FitSettings::default().with_volume_samples(0), "volume_samples"),
            (FitSettings::default().with_solver_tolerance(Real::NAN), "solver_tolerance"),
            (FitSettings { max_solver_iterations: 0, ..Default::default() }, "max_solver_iterations"),
            (
                FitSettings::default().with_method(FitMethod::LogDetH).with_convexity_cone(sdp::ConvexityCone::Dd),
                "convexity_cone",
            ),
        ] {
            match fit_points(&pts, &s, &mut |_| {}) {
                Err(Error::InvalidArgument { field: f, .. }) => assert_eq!(f, field),
                other => panic!("expected InvalidArgument({field}), got {other:?}"),
            }
        }
    }
}
