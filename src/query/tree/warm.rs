//! Warm starts of tree queries: one [`DistanceWarmStart`] / [`GrowthWarmStart`] per node pair.

use crate::query::{DistanceWarmStart, GrowthWarmStart};
use std::collections::HashMap;
use std::sync::Arc;

/// Most node pairs a [`TreeWarmStart`] keeps; pairs beyond it are solved cold next time.
pub const MAX_WARM_PAIRS: usize = 1024;

/// Solver states of the node pairs solved by the last tree query of one ordered pair of trees,
/// keyed by `(node of A, node of B)`.
///
/// Pass the `warm_start` of an answer to the next query of the same two trees (any poses; nearby
/// poses make it pay off). Only the pairs the last query solved are kept (at most
/// [`MAX_WARM_PAIRS`]), so the cache follows the active leaf pairs as the bodies move and never
/// grows with the trees.
#[derive(Clone, Debug, Default)]
pub struct TreeWarmStart {
    pub(crate) distance: HashMap<(usize, usize), Arc<DistanceWarmStart>>,
    pub(crate) growth: HashMap<(usize, usize), Arc<GrowthWarmStart>>,
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

    pub(crate) fn distance_of(&self, pair: (usize, usize)) -> Option<&DistanceWarmStart> {
        self.distance.get(&pair).map(|w| w.as_ref())
    }

    pub(crate) fn growth_of(&self, pair: (usize, usize)) -> Option<&GrowthWarmStart> {
        self.growth.get(&pair).map(|w| w.as_ref())
    }

    pub(crate) fn keep_distance(&mut self, pair: (usize, usize), w: Arc<DistanceWarmStart>) {
        if self.distance.len() < MAX_WARM_PAIRS || self.distance.contains_key(&pair) {
            self.distance.insert(pair, w);
        }
    }

    pub(crate) fn keep_growth(&mut self, pair: (usize, usize), w: Arc<GrowthWarmStart>) {
        if self.growth.len() < MAX_WARM_PAIRS || self.growth.contains_key(&pair) {
            self.growth.insert(pair, w);
        }
    }
}
