//! Warm starts of tree queries: one [`DistanceWarmStart`] / [`GrowthWarmStart`] per node pair, and
//! the active leaf pair of the last distance answer.

#[cfg(doc)]
use super::TreeQueryParams;
use crate::{DistanceWarmStart, GrowthWarmStart};
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real, Vector3};

/// Solver states of the node pairs solved by the last tree query of one ordered pair of trees,
/// keyed by `(node of A, node of B)`, the last answer's active leaf pair, and the *cut* of the
/// last search with its lower bounds.
///
/// Pass the `warm_start` of an answer to the next query of the same two trees (any poses; nearby
/// poses make it pay off). Only the pairs the last query solved are kept (at most
/// [`TreeQueryParams::max_warm_pairs`]), so the cache follows the active leaf pairs as the bodies move and never
/// grows with the trees. A query solves the active leaf pair first (one warm solve gives a tight
/// upper bound at once), then checks the cut: every leaf pair lies below one of its node pairs,
/// whose lower bound less the motion since still decides most of them without
/// touching the trees; only the pairs it no longer decides are searched again.
#[derive(Clone, Debug, Default)]
pub struct TreeWarmStart {
    /// A short list searched linearly rather than a hash map: a query solves a handful of pairs,
    /// and one allocation per query is cheaper than hashing and rehashing.
    pub(crate) distance: Vec<((usize, usize), Arc<DistanceWarmStart>)>,
    pub(crate) growth: Vec<((usize, usize), Arc<GrowthWarmStart>)>,
    /// The best leaf pair of the last distance or margin answer (the active pair).
    pub(crate) active: Option<(usize, usize)>,
    /// The cut of the last search, when it kept one: node pairs covering every leaf pair, each
    /// with a lower bound of its leaf pairs' distances at `cut_pose`.
    pub(crate) cut: Option<Cut>,
}

/// The terminal node pairs of a search (pruned, solved, or left in the queue) with their lower
/// bounds: every leaf pair of the two trees lies below at least one of them.
///
/// Most pairs stay in the cut for many queries with only their bound changing, so the pairs are
/// shared between successive warm starts (`base`, behind an `Arc`) and each query writes only
/// their bounds (`lower`, 8 bytes a pair instead of a copy of each pair); pairs added since the
/// base was built are in `extra`, until a query folds them into a new base.
#[derive(Clone, Debug)]
pub(crate) struct Cut {
    /// Pairs shared with earlier warm starts (their own `lower` field is stale: see `lower`).
    pub(crate) base: Arc<Vec<CutPair>>,
    /// The bound of each base pair at `pose`; NaN for a pair no longer in the cut.
    pub(crate) lower: Vec<Real>,
    /// Pairs added since the base was built, with their bounds at `pose`.
    pub(crate) extra: Vec<CutPair>,
    /// The relative pose `pose_a⁻¹·pose_b` at which the bounds hold.
    pub(crate) pose: Isometry3,
    /// Node counts of the trees the cut belongs to (a cut of other trees is ignored).
    pub(crate) nodes: (usize, usize),
    /// Pairs far above the threshold, checked as one group ([`FarPairs`]); `None` when none.
    pub(crate) far: Option<Arc<FarPairs>>,
    /// First pair of `far` still in the group (the ones before are among the near pairs).
    pub(crate) far_start: usize,
}

/// The pairs of a [`Cut`] whose bounds were far above the query's threshold when it was built,
/// kept with their bounds at the pose of that query and checked as one group: the relative motion
/// of B since then moves every point of B's node boxes by at most `‖t − t₀‖ + ‖R − R₀‖₂·reach`
/// (see [`CutPair`]), so while `min_lower` less that still reaches a query's threshold, none of
/// them needs looking at. A warm query then costs its near pairs only, not the whole cut (most
/// of chair_101 × human_10's ~95 cut pairs are far from the active pair).
#[derive(Debug)]
pub(crate) struct FarPairs {
    /// The pairs, with their bounds at `pose`, in increasing order of bound: as the motion
    /// grows, a query releases the first ones to the search (see [`Cut::far_start`]).
    pub(crate) pairs: Vec<CutPair>,
    /// The relative pose `pose_a⁻¹·pose_b` at which their bounds hold.
    pub(crate) pose: Isometry3,
    /// The largest `‖c‖ + ‖h‖` of their B node boxes (B's frame, meters): how far a point of
    /// them lies from B's origin.
    pub(crate) reach: Real,
}

/// How far any point of B within `reach` meters of B's origin moves (A's frame, meters) when B's
/// relative pose goes from `from` to `to`: `‖t − t₀‖ + ‖R − R₀‖₂·reach`, with ‖R − R₀‖₂ = 2 sin(θ/2)
/// (twice the norm of the imaginary part of R R₀⁻¹), rounding included (`slack` relative to the
/// terms, [`TreeQueryParams::cheap_slack`]; [`FarPairs`]).
pub(crate) fn displacement(from: &Isometry3, to: &Isometry3, reach: Real, slack: Real) -> Real {
    let k = (2.0 * (to.rotation * from.rotation.inverse()).imag().norm()).min(2.0);
    let shift = to.translation.vector;
    let m = (shift - from.translation.vector).norm() + k * reach;
    m * (1.0 + 1e-12) + slack * (1.0 + reach + shift.norm())
}

impl Cut {
    /// Number of pairs in the cut.
    pub(crate) fn len(&self) -> usize {
        self.lower.iter().filter(|l| !l.is_nan()).count()
            + self.extra.len()
            + self.far.as_ref().map_or(0, |f| f.pairs.len() - self.far_start)
    }

    /// The pairs of the cut with their current bounds (the far pairs' moved by `displacement` with
    /// the rounding slack `slack`).
    #[cfg(test)]
    pub(crate) fn pairs(&self, slack: Real) -> impl Iterator<Item = CutPair> + '_ {
        let base =
            self.base.iter().zip(&self.lower).filter(|(_, l)| !l.is_nan()).map(|(p, &l)| CutPair { lower: l, ..*p });
        let far = self.far.iter().flat_map(move |f| {
            let moved = displacement(&f.pose, &self.pose, f.reach, slack);
            f.pairs[self.far_start..].iter().map(move |p| CutPair { lower: p.lower - moved, ..*p })
        });
        base.chain(self.extra.iter().copied()).chain(far)
    }
}

/// One node pair of a [`Cut`].
///
/// After a relative motion of B from the cut's pose (R₀, t₀) to (R, t) in A's frame, every point
/// `c + w` of B's node (its bounding box: center c, half extents h, B's frame) moved by
/// `(R − R₀) c + t − t₀` plus `(R − R₀) w`. So the separating gap along a fixed unit axis n (A's
/// frame) moved by at least
///
/// ```text
/// n·((R − R₀) c + t − t₀) − Σₖ hₖ |((R − R₀)ᵀ n)ₖ|
/// ```
///
/// and any distance by at least `−‖(R − R₀) c + t − t₀‖ − ‖R − R₀‖₂ ‖h‖` (‖R − R₀‖₂ = 2 sin(θ/2),
/// θ the angle between the rotations); `lower` plus that is still a lower bound of the pair's
/// leaf distances: distance is 1-Lipschitz in the points of either set, and a gap along n bounds
/// the distance of every pair of subsets (containment).
#[derive(Clone, Copy, Debug)]
pub(crate) struct CutPair {
    pub(crate) a: u32,
    pub(crate) b: u32,
    /// Lower bound of the distance of every leaf pair below (meters), and of the separating gap
    /// along `axis` when there is one.
    pub(crate) lower: Real,
    /// A unit axis (A's frame, from A towards B) along which `lower` bounds the pair's separating
    /// gap (a solved leaf pair's normal, or the axis of its cheap bound); zero when none.
    /// Re-evaluating the gap along it at the new pose is nearly as tight as a solve
    /// ([`super::search::CheapBounds::axis_gap`]).
    pub(crate) axis: Vector3,
    /// A's support value along `axis`, `h_A(axis)` (meters, A's frame; NaN until computed): A is
    /// fixed in its own frame, so re-evaluating the gap along the same axis needs only B's
    /// support bound.
    pub(crate) support_a: Real,
    /// Bounding box of B's node (center and half extents, B's frame, meters); half extents +∞
    /// without one. Kept here rather than read from the tree: the motion bound of every kept pair
    /// reads it on every warm query, and the copy is faster than the look-up, though it makes
    /// the pair 104 bytes instead of 48 when a query folds or regroups the cut.
    pub(crate) box_b: (Vector3, Vector3),
    /// `1 + ‖c‖₁ + Σ hₖ` (meters): the scale of the rounding slack of the motion bound.
    pub(crate) size: Real,
}

impl TreeWarmStart {
    /// Number of node pairs with a distance warm start.
    pub fn distance_pairs(&self) -> usize {
        self.distance.len()
    }

    /// Number of node pairs with a growth warm start.
    pub fn growth_pairs(&self) -> usize {
        self.growth.len()
    }

    /// The active leaf pair (node of A, node of B) of the answer this state comes from, if any:
    /// the pair the next query solves first.
    pub fn active_pair(&self) -> Option<(usize, usize)> {
        self.active
    }

    /// Number of node pairs of the kept cut (0 when none is kept): the pairs the next query checks
    /// by their motion bounds before searching.
    pub fn cut_pairs(&self) -> usize {
        self.cut.as_ref().map_or(0, Cut::len)
    }

    pub(crate) fn distance_of(&self, pair: (usize, usize)) -> Option<&DistanceWarmStart> {
        self.distance.iter().find(|(p, _)| *p == pair).map(|(_, w)| w.as_ref())
    }

    pub(crate) fn growth_of(&self, pair: (usize, usize)) -> Option<&GrowthWarmStart> {
        self.growth.iter().find(|(p, _)| *p == pair).map(|(_, w)| w.as_ref())
    }

    /// Keeps the distance warm start `w` of node pair `pair`, unless `cap` pairs are kept already
    /// ([`TreeQueryParams::max_warm_pairs`]).
    pub(crate) fn keep_distance(&mut self, pair: (usize, usize), w: Arc<DistanceWarmStart>, cap: usize) {
        if let Some(slot) = self.distance.iter_mut().find(|(p, _)| *p == pair) {
            slot.1 = w;
        } else if self.distance.len() < cap {
            self.distance.push((pair, w));
        }
    }

    /// Keeps the growth warm start `w` of node pair `pair`, unless `cap` pairs are kept already
    /// ([`TreeQueryParams::max_warm_pairs`]).
    pub(crate) fn keep_growth(&mut self, pair: (usize, usize), w: Arc<GrowthWarmStart>, cap: usize) {
        if let Some(slot) = self.growth.iter_mut().find(|(p, _)| *p == pair) {
            slot.1 = w;
        } else if self.growth.len() < cap {
            self.growth.push((pair, w));
        }
    }
}
