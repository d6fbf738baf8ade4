//! Fitting bodies to point clouds (paper §III).
//!
//! STUB: owned by the fit work; the signatures below are the contract the rest of the crate uses.

use crate::body::Body;
use crate::math::{Point3, Real};
use crate::Result;

pub mod mesh;

/// Which formulation a fit uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FitMethod {
    /// Maximize log det P of the sos Gram matrix, p sos-convex (eq. "VAG.log.det").
    #[default]
    LogDetP,
}

/// Settings of a fit.
#[derive(Clone, Debug)]
pub struct FitSettings {
    /// Total degree 2d ∈ {2, 4, 6, 8}.
    pub degree: usize,
    /// Formulation.
    pub method: FitMethod,
    /// Monte Carlo samples for the volume estimate.
    pub volume_samples: usize,
    /// Seed of the volume estimate.
    pub seed: u64,
    /// Clarabel's gap and feasibility tolerance.
    pub solver_tolerance: Real,
    /// Clarabel's iteration cap.
    pub max_solver_iterations: u32,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            degree: 4,
            method: FitMethod::LogDetP,
            volume_samples: 200_000,
            seed: 1,
            solver_tolerance: 1e-8,
            max_solver_iterations: 200,
        }
    }
}

/// Stages a fit reports progress for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitStage {
    /// Computing the convex hull.
    Hull,
    /// Building the cone program.
    Build,
    /// Clarabel is solving.
    Solve,
    /// Checking containment on every point (and rescaling).
    Verify,
    /// Estimating the volume.
    Volume,
    /// Finished.
    Done,
}

/// One progress report of a fit.
#[derive(Clone, Debug)]
pub struct FitProgress {
    /// Current stage.
    pub stage: FitStage,
    /// Overall completion in [0, 1].
    pub fraction: Real,
    /// Human-readable detail.
    pub message: String,
}

/// Fits a body to a point cloud.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] for an empty, non-finite or degenerate cloud or bad settings.
pub fn fit_points(
    _points: &[Point3],
    _settings: &FitSettings,
    _progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    Err(crate::Error::Numerical("fit not implemented yet".into()))
}
