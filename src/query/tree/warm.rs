//! Warm starts of tree queries: one [`DistanceWarmStart`] / [`GrowthWarmStart`] per node pair, and
//! the active leaf pair of the last distance answer.

use crate::query::{DistanceWarmStart, GrowthWarmStart};
use std::sync::Arc;

/// Most node pairs a [`TreeWarmStart`] keeps; pairs beyond it are solved cold next time.
pub const MAX_WARM_PAIRS: usize = 1024;

/// Solver states of the node pairs solved by the last tree query of one ordered pair of trees,
/// keyed by `(node of A, node of B)`, and the last answer's active leaf pair.
///
/// Pass the `warm_start` of an answer to the next query of the same two trees (any poses; nearby
/// poses make it pay off). Only the pairs the last query solved are kept (at most
/// [`MAX_WARM_PAIRS`]), so the cache follows the active leaf pairs as the bodies move and never
/// grows with the trees. A query solves the active leaf pair first (one warm solve gives a tight
/// upper bound at once), then prunes every node pair whose cheap bound exceeds it.
#[derive(Clone, Debug, Default)]
pub struct TreeWarmStart {
    /// A short list searched linearly rather than a hash map: a query solves a handful of pairs,
    /// and one allocation per query is cheaper than hashing and rehashing (issue 14, warm ≤ 2 µs).
    pub(crate) distance: Vec<((usize, usize), Arc<DistanceWarmStart>)>,
    pub(crate) growth: Vec<((usize, usize), Arc<GrowthWarmStart>)>,
    /// The best leaf pair of the last distance or margin answer (the active pair).
    pub(crate) active: Option<(usize, usize)>,
    /// Exact distances of leaf pairs and the relative poses they were solved at: the motion since
    /// then bounds each pair's distance now (`super::search::motion_bound`).
    pub(crate) solved: Vec<SolvedPair>,
}

/// A leaf pair's exact distance at a relative pose `pose_a⁻¹·pose_b`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SolvedPair {
    pub(crate) pair: (usize, usize),
    /// Distance of the pair (meters) at `relative_pose`.
    pub(crate) distance: crate::math::Real,
    pub(crate) relative_pose: crate::math::Isometry3,
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

    pub(crate) fn solved_of(&self, pair: (usize, usize)) -> Option<&SolvedPair> {
        self.solved.iter().find(|s| s.pair == pair)
    }

    pub(crate) fn distance_of(&self, pair: (usize, usize)) -> Option<&DistanceWarmStart> {
        self.distance.iter().find(|(p, _)| *p == pair).map(|(_, w)| w.as_ref())
    }

    pub(crate) fn growth_of(&self, pair: (usize, usize)) -> Option<&GrowthWarmStart> {
        self.growth.iter().find(|(p, _)| *p == pair).map(|(_, w)| w.as_ref())
    }

    pub(crate) fn keep_distance(&mut self, pair: (usize, usize), w: Arc<DistanceWarmStart>) {
        if let Some(slot) = self.distance.iter_mut().find(|(p, _)| *p == pair) {
            slot.1 = w;
        } else if self.distance.len() < MAX_WARM_PAIRS {
            self.distance.push((pair, w));
        }
    }

    pub(crate) fn keep_growth(&mut self, pair: (usize, usize), w: Arc<GrowthWarmStart>) {
        if let Some(slot) = self.growth.iter_mut().find(|(p, _)| *p == pair) {
            slot.1 = w;
        } else if self.growth.len() < MAX_WARM_PAIRS {
            self.growth.push((pair, w));
        }
    }
}
