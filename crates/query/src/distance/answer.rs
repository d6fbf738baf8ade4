//! The answers of a distance query: the overlapping (touching) answer at the growth minimizer,
//! and the separated answer of a converged KKT point with the warm start it leaves.

use super::kkt::KktOut;
use super::{DistanceResult, DistanceWarmStart};
use crate::growth::GrowthWarmStart;
use crate::newton::{MotionTrail, SolveStatus};
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};

/// The answer for overlapping (or touching) bodies: distance 0, both witnesses at the growth
/// minimizer `p` (world, meters), no normal; the growth solve's `status`, `iterations` and final
/// ∞-norm KKT `residual`, with the warm start it keeps.
pub(crate) fn overlapping_answer(
    p: Point3,
    status: SolveStatus,
    iterations: usize,
    residual: Real,
    warm_started: bool,
    warm_start: std::sync::Arc<DistanceWarmStart>,
) -> DistanceResult {
    DistanceResult {
        distance: 0.0,
        witness_a: p,
        witness_b: p,
        normal: Vector3::zeros(),
        overlapping: true,
        status,
        iterations,
        kkt_residual: residual,
        warm_started,
        warm_start,
    }
}

/// Whether a converged separated KKT point (x, y) is clear of contact: ‖y − x‖ above 10⁻⁶ of the
/// bodies' sizes. Near contact (x ≈ y) the multipliers lose meaning and the growth test decides.
#[inline]
pub(crate) fn clear_of_contact(x: &Vector3, y: &Vector3, a: &Body, b: &Body) -> bool {
    (y - x).norm() > 1e-6 * (a.scale() + b.scale())
}

/// The answer of a converged (or last) separated KKT point `out` in the relative frame `rel`, with
/// its warm start: the trail of `previous` (the last answer and the relative-pose step from it)
/// extended by that answer (built only here, where it is kept).
#[inline(always)]
pub(crate) fn finish(
    pose_a: &Isometry3,
    rel: &Isometry3,
    out: KktOut,
    iterations: usize,
    warm_started: bool,
    growth: &GrowthWarmStart,
    previous: Option<(&DistanceWarmStart, [Real; 6])>,
) -> DistanceResult {
    let b_local = rel.inverse_transform_point(&Point3::from(out.y));
    let valid = out.status.converged();
    let trail = match previous {
        Some((w, step)) if valid => MotionTrail::extend(&w.state(), &w.trail, step),
        _ => MotionTrail::default(),
    };
    let warm_start = std::sync::Arc::new(DistanceWarmStart {
        a_local: out.x,
        b_local: b_local.coords,
        multipliers: out.lam,
        valid,
        growth: *growth,
        relative_pose: *rel,
        trail,
    });
    separated_answer(pose_a, &out, iterations, warm_started, warm_start)
}

/// The answer of a separated KKT point `out` (frame of body A, posed by `pose_a`) with the given
/// warm start.
#[inline(always)]
pub(crate) fn separated_answer(
    pose_a: &Isometry3,
    out: &KktOut,
    iterations: usize,
    warm_started: bool,
    warm_start: std::sync::Arc<DistanceWarmStart>,
) -> DistanceResult {
    let diff = out.y - out.x;
    let dist = diff.norm();
    // One rotation matrix for the three world vectors (a quaternion rotation costs twice a product).
    let r = pose_a.rotation.to_rotation_matrix();
    let t = pose_a.translation.vector;
    let normal = if dist > 0.0 { r * (diff / dist) } else { Vector3::zeros() };
    DistanceResult {
        distance: dist,
        witness_a: Point3::from(r * out.x + t),
        witness_b: Point3::from(r * out.y + t),
        normal,
        overlapping: false,
        status: out.status,
        iterations,
        kkt_residual: out.residual,
        warm_started,
        warm_start,
    }
}
