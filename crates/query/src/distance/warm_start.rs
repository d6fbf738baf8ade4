//! The warm start of a distance query: the last separated answer of a pair in the bodies' own
//! frames, the growth measure's warm start of its overlap test, and the motion trail that
//! extrapolates the next start ([`MotionTrail`]); whether a warm start is within reach of a query.

use crate::growth::{GrowthStart, GrowthWarmStart};
use crate::newton::{pose_step, within_warm_reach, MotionTrail, NewtonParams};
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real, Vector3};

/// Solver state carried between queries of one pair, in body frames so it follows the poses.
///
/// The default holds no answer (`valid` false): a query started from it runs cold.
#[derive(Clone, Copy, Debug, Default)]
pub struct DistanceWarmStart {
    /// Witness on A in A's body frame (meters).
    pub a_local: Vector3,
    /// Witness on B in B's body frame (meters).
    pub b_local: Vector3,
    /// Multipliers (λ_a, λ_b) of the two constraints.
    pub multipliers: [Real; 2],
    /// Whether `a_local`, `b_local`, `multipliers` hold a converged separated answer.
    pub valid: bool,
    /// Warm start of the overlap test d(p_a‖p_b).
    pub growth: GrowthWarmStart,
    /// Relative pose pose_a⁻¹·pose_b at which the witnesses were solved.
    pub relative_pose: Isometry3,
    /// Earlier separated answers of the same pair along the motion: with them the next query
    /// extrapolates along the motion ([`MotionTrail`]) instead of restarting from the last
    /// witnesses. State layout: `[a_local (3), b_local (3), λ_a, λ_b]`.
    pub trail: MotionTrail<8>,
}

impl DistanceWarmStart {
    /// The state `[a_local, b_local, λ_a, λ_b]` of the motion trail.
    pub(super) fn state(&self) -> [Real; 8] {
        let (a, b, l) = (&self.a_local, &self.b_local, &self.multipliers);
        [a.x, a.y, a.z, b.x, b.y, b.z, l[0], l[1]]
    }

    /// Start (witness on A in A's frame, witness on B in B's frame, multipliers) after the
    /// relative-pose step `step` from this answer: extrapolated along the motion from the earlier
    /// answers ([`MotionTrail::predict`], at most [`NewtonParams::max_extrapolation`] times the
    /// last step), else the last answer.
    #[inline(always)]
    pub(super) fn predict(&self, step: &[Real; 6], params: &NewtonParams) -> (Vector3, Vector3, [Real; 2]) {
        if self.trail.is_empty() {
            return (self.a_local, self.b_local, self.multipliers);
        }
        let s = self.trail.predict(&self.state(), step, 6, params.max_extrapolation).0;
        (Vector3::new(s[0], s[1], s[2]), Vector3::new(s[3], s[4], s[5]), [s[6], s[7]])
    }

    /// Whether [`distance()`](super::distance()) between `a` and `b` at relative pose `rel` =
    /// pose_a⁻¹·pose_b starts from this warm start (its separated answer or its overlap test's
    /// growth answer) rather than cold, with the default settings: a warm start whose answer lies
    /// more than half the bodies' summed scales away costs more than a cold start and is not used
    /// ([`NewtonParams::warm_reach`]; [`Self::reaches_with`] for other settings).
    pub fn reaches(&self, a: &Body, b: &Body, rel: &Isometry3) -> bool {
        self.reaches_with(a, b, rel, &NewtonParams::DEFAULT)
    }

    /// [`Self::reaches`] for a query with the settings `params` (their
    /// [`NewtonParams::warm_reach`]).
    pub fn reaches_with(&self, a: &Body, b: &Body, rel: &Isometry3, params: &NewtonParams) -> bool {
        let length = a.scale() + b.scale();
        self.separated_step(rel, length, params).is_some()
            || self.growth_start(rel, a.scale(), length, params).is_some()
    }

    /// The relative-pose step ([`pose_step`], rotations weighted by `length`, the bodies' summed
    /// scales) from this warm start's separated answer to `rel`, when that answer is valid and
    /// within [`NewtonParams::warm_reach`] of `length`.
    #[inline(always)]
    pub(super) fn separated_step(&self, rel: &Isometry3, length: Real, params: &NewtonParams) -> Option<[Real; 6]> {
        if !self.valid {
            return None;
        }
        let step = pose_step(&self.relative_pose, rel, length);
        within_warm_reach(&step, length, params).then_some(step)
    }

    /// The overlap test's warm start for a query at `rel` (its growth measure runs at rel⁻¹, A's
    /// scale `a_scale` weighing rotations), when valid and within reach of `length`.
    #[inline(always)]
    pub(super) fn growth_start(
        &self,
        rel: &Isometry3,
        a_scale: Real,
        length: Real,
        params: &NewtonParams,
    ) -> Option<GrowthStart<'_>> {
        if !self.growth.valid {
            return None;
        }
        Some(self.growth.towards(&rel.inverse(), a_scale)).filter(|s| within_warm_reach(&s.step, length, params))
    }
}

/// Whether the warm start of a [`distance()`](super::distance()) answer between `a` and `b` at
/// relative pose `from` would be used by a query at relative pose `to` (both pose_a⁻¹·pose_b), with
/// the default settings: the step between them is within half the bodies' summed scales
/// ([`NewtonParams::warm_reach`]), else the query starts cold. What a request of many candidate
/// states asks to decide which states gain from the state before; [`warm_start_reaches_with`]
/// for other settings.
pub fn warm_start_reaches(a: &Body, b: &Body, from: &Isometry3, to: &Isometry3) -> bool {
    warm_start_reaches_with(a, b, from, to, &NewtonParams::DEFAULT)
}

/// [`warm_start_reaches`] for queries with the settings `params` (their
/// [`NewtonParams::warm_reach`]).
pub fn warm_start_reaches_with(a: &Body, b: &Body, from: &Isometry3, to: &Isometry3, params: &NewtonParams) -> bool {
    let length = a.scale() + b.scale();
    within_warm_reach(&pose_step(from, to, length), length, params)
}
