//! The settings of the tree queries and their answers.

use super::super::warm::TreeWarmStart;
use crate::sdp_certificate::CertificateParams;
use crate::{
    distance_gradient, AnswerSource, CertificateSummary, CertifyMode, DistanceResult, NewtonParams, PoseGradient,
};
use sublevel_core::error::{Error, Result};
use sublevel_core::math::Real;

/// Settings of the tree queries: the search's tolerance and limits, the rounding slack of its
/// cheap bounds, the far group of a warm cut and the sizes of a warm start, and the settings of
/// each node pair's Newton solve and certificate. The default ([`TreeQueryParams::DEFAULT`]) is
/// the tuned value of each; change fields with struct update syntax,
/// `TreeQueryParams { tolerance: 1e-3, ..TreeQueryParams::default() }`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeQueryParams {
    /// Settings of the Newton / active-set solves of each node pair.
    pub newton: NewtonParams,
    /// Distance queries stop refining once `upper − lower ≤ tolerance` (meters, finite, ≥ 0;
    /// default 0: the exact distance of the model).
    pub tolerance: Real,
    /// [`CertifyMode::Certify`] attaches a level-0 certificate to every leaf pair solved (slow: one
    /// SDP per leaf pair); [`CertifyMode::Newton`] (default) solves SDPs only as fallback.
    pub certify: CertifyMode,
    /// Settings of the certificates.
    pub certificate: CertificateParams,
    /// Whether a leaf pair whose Newton solve did not converge is solved again with the level-0 SDP
    /// fallback ([`certified_distance`](crate::certified_distance)); default true. Without it the
    /// pair stays unresolved.
    pub sdp_fallback: bool,
    /// Cap on the node pairs solved by one query (≥ 1; default 100 000); a query that reaches it
    /// stops with valid but wider bounds (`within_tolerance = false`).
    pub max_pairs: usize,
    /// Relative slack subtracted from the cheap lower bounds (meters per meter of the terms: box
    /// centers' distance, gaps, supports, motion), so that rounding of the box and support
    /// projections never makes a bound exceed the true gap; default 10⁻¹². Larger: a wider margin
    /// against rounding, bounds looser by about that relative amount; smaller than the rounding of
    /// the terms, a bound may exceed the true gap.
    pub cheap_slack: Real,
    /// A warm cut's pair joins the far group of the next warm start (checked as one, by its
    /// bound less the motion since) when its bound exceeds the threshold by more than this many
    /// times the last step's motion; default 1. Larger: fewer, farther pairs in the group, more
    /// pairs checked one by one each query; smaller: more pairs in the group, released to the
    /// search sooner as the motion uses up their margin. On the bench's warm motion
    /// (`crates/lab/examples/tree_profile.rs`) one step gives the fastest warm queries, a far
    /// group a fifth faster than none.
    pub far_steps: Real,
    /// Fewest pairs worth a far group, below which every pair of the cut stays near; default 8.
    /// Larger: small cuts skip the group's bookkeeping and check every pair each query.
    pub min_far_pairs: usize,
    /// Most node pairs whose Newton warm starts a [`TreeWarmStart`](super::super::TreeWarmStart)
    /// keeps, beyond which pairs are solved cold next time; default 1024. Larger: more memory per
    /// warm start, fewer cold solves after a query that solved many pairs.
    pub max_warm_pairs: usize,
    /// Most node pairs of a kept cut; a query whose cut is larger keeps none, and the next query
    /// searches from the roots again; default 4096. Checking a kept pair costs a few nanoseconds,
    /// a search from the roots a few microseconds (chair_101 × human_10 keeps 20–150 pairs along
    /// the bench's motion). Larger: more memory per warm start, fewer searches from the roots.
    pub max_cut_pairs: usize,
}

impl TreeQueryParams {
    /// The default settings (a constant, for contexts that need one).
    pub const DEFAULT: Self = Self {
        newton: NewtonParams::DEFAULT,
        tolerance: 0.0,
        certify: CertifyMode::Newton,
        certificate: CertificateParams::DEFAULT,
        sdp_fallback: true,
        max_pairs: 100_000,
        cheap_slack: 1e-12,
        far_steps: 1.0,
        min_far_pairs: 8,
        max_warm_pairs: 1024,
        max_cut_pairs: 4096,
    };
}

impl Default for TreeQueryParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl TreeQueryParams {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `tolerance` (not finite or < 0) or `max_pairs` (0).
    pub fn validate(&self) -> Result<()> {
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::invalid("tolerance", format!("must be finite and ≥ 0 m, got {}", self.tolerance)));
        }
        if self.max_pairs == 0 {
            return Err(Error::invalid("max_pairs", "must be ≥ 1"));
        }
        Ok(())
    }
}

/// The answer of one leaf pair (a part of A against a part of B).
#[derive(Clone, Debug)]
pub struct LeafPairAnswer {
    /// (node of tree A, node of tree B); both leaves.
    pub leaves: (usize, usize),
    /// The distance answer of the two leaf bodies (world frame, meters).
    pub result: DistanceResult,
    /// Whether `result.distance` is the pair's exact distance (a converged Newton answer or a
    /// verified SDP answer): only such answers set the upper bound.
    pub exact: bool,
    /// Where the answer comes from (Newton, or the SDP fallback).
    pub source: AnswerSource,
    /// The level-0 certificate, when one was solved ([`CertifyMode::Certify`] or a fallback).
    pub certificate: Option<CertificateSummary>,
}

/// Answer of [`tree_distance`](super::tree_distance): bounds on the model distance
/// `min over leaf pairs dist(A_i, B_j)`.
#[derive(Clone, Debug)]
pub struct TreeDistanceResult {
    /// A lower bound of the model distance (meters): the conservative answer. Every leaf contains
    /// its part of the mesh, so this is also a lower bound of the mesh distance.
    pub lower: Real,
    /// An upper bound of the model distance (meters): the distance of the best leaf pair solved
    /// (`best`); +∞ when no leaf pair was resolved.
    pub upper: Real,
    /// The best leaf pair (the active pair: witnesses, normal, certificate, pose gradient).
    pub best: Option<LeafPairAnswer>,
    /// Every leaf pair solved, in the order solved (certificates per leaf pair).
    pub leaf_pairs: Vec<LeafPairAnswer>,
    /// The deepest tree level reached: max over the node pairs queued or solved by this query of
    /// max(depth in A, depth in B) (pairs of the warm start's cut kept by their motion bounds
    /// are not counted).
    pub level: usize,
    /// Node pairs solved (Newton solves, leaf pairs included).
    pub pairs_evaluated: usize,
    /// Node pairs decided by cheap bounds alone (no solve): separating-axis gaps of their boxes
    /// and support bounds, which contain the bounding spheres' gap, and the pairs of the warm
    /// start's cut kept by their motion bounds (module docs of [`crate::tree`]).
    pub pairs_pruned_by_spheres: usize,
    /// Solves that did not converge (internal pairs: only descended, never used as bounds).
    pub unconverged_solves: usize,
    /// True when both bounds are proven: no leaf pair stayed unresolved.
    pub converged: bool,
    /// True when `upper − lower ≤ tolerance` (false when `max_pairs` stopped the search or a leaf
    /// pair stayed unresolved).
    pub within_tolerance: bool,
    /// State for warm-starting the next query of the same two trees.
    pub warm_start: TreeWarmStart,
}

impl TreeDistanceResult {
    /// True when the best leaf pair overlaps (the model bodies collide: distance 0).
    pub fn overlapping(&self) -> bool {
        self.best.as_ref().is_some_and(|b| b.exact && b.result.overlapping)
    }

    /// Pose gradients of the distance with respect to pose A and pose B, from the active leaf pair
    /// ([`distance_gradient`], same convention); `None` without a resolved leaf pair.
    pub fn gradient(&self) -> Option<(PoseGradient, PoseGradient)> {
        self.best.as_ref().filter(|b| b.exact).map(|b| distance_gradient(&b.result))
    }
}

/// Answer of [`tree_closer_than`](super::tree_closer_than).
#[derive(Clone, Debug)]
pub struct TreeMarginResult {
    /// Whether the models are closer than the margin (distance < m). When `converged` is false
    /// this is the conservative answer `true` ("cannot rule it out").
    pub closer: bool,
    /// True when the answer is proven by converged solves (or bounding spheres).
    pub converged: bool,
    /// The deciding bound (meters): a leaf pair's distance < m when closer, else a lower bound ≥ m.
    pub bound: Real,
    /// The leaf pair closer than the margin, when there is one.
    pub leaves: Option<(usize, usize)>,
    /// The deepest tree level reached (0: decided by the root pair; pairs of the warm start's
    /// cut kept by their motion bounds are not counted).
    pub level: usize,
    /// Node pairs solved.
    pub pairs_evaluated: usize,
    /// Node pairs decided by cheap bounds alone (no solve; as
    /// [`TreeDistanceResult::pairs_pruned_by_spheres`]).
    pub pairs_pruned_by_spheres: usize,
    /// State for warm-starting the next query of the same two trees.
    pub warm_start: TreeWarmStart,
}
