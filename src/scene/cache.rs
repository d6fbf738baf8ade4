//! Warm starts of a scene's queries, keyed by (query kind, ordered pair of instances).
//!
//! The Newton / active-set solvers (paper §IV) converge in a handful of iterations when started
//! from the previous answer of the same pair; the answer's `warm_start` is stored here and handed
//! back on the next query. Warm starts are expressed in body frames, so they survive pose changes;
//! they only become meaningless when an instance disappears, which is what
//! [`WarmStartCache::invalidate_instance`] handles.

use crate::query::{DistanceWarmStart, GrowthWarmStart};
use std::collections::HashMap;

/// Which query a warm start belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum WarmKind {
    /// Distance (eq. "distance").
    Distance,
    /// Growth measure (eq. "overlap").
    Growth,
}

/// Key of a warm start: the query kind and the ordered pair of instance ids. Order matters:
/// d(p₁‖p₂) ≠ d(p₂‖p₁), and the distance solver's state is stored per side.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PairKey {
    /// Query kind.
    pub kind: WarmKind,
    /// First instance (A, or p₁).
    pub first: String,
    /// Second instance (B, or p₂).
    pub second: String,
}

/// Warm starts of one scene.
#[derive(Debug, Default)]
pub struct WarmStartCache {
    distance: HashMap<(String, String), DistanceWarmStart>,
    growth: HashMap<(String, String), GrowthWarmStart>,
}

impl WarmStartCache {
    /// The stored distance warm start of the ordered pair (a, b), if any.
    pub fn distance(&self, a: &str, b: &str) -> Option<&DistanceWarmStart> {
        self.distance.get(&(a.to_owned(), b.to_owned()))
    }

    /// Stores the distance warm start of (a, b), replacing the previous one.
    pub fn put_distance(&mut self, a: &str, b: &str, warm: DistanceWarmStart) {
        self.distance.insert((a.to_owned(), b.to_owned()), warm);
    }

    /// The stored growth warm start of the ordered pair (p₁, p₂), if any.
    pub fn growth(&self, p1: &str, p2: &str) -> Option<&GrowthWarmStart> {
        self.growth.get(&(p1.to_owned(), p2.to_owned()))
    }

    /// Stores the growth warm start of (p₁, p₂), replacing the previous one.
    pub fn put_growth(&mut self, p1: &str, p2: &str, warm: GrowthWarmStart) {
        self.growth.insert((p1.to_owned(), p2.to_owned()), warm);
    }

    /// Whether a warm start is stored for `key`.
    pub fn contains(&self, key: &PairKey) -> bool {
        let k = (key.first.clone(), key.second.clone());
        match key.kind {
            WarmKind::Distance => self.distance.contains_key(&k),
            WarmKind::Growth => self.growth.contains_key(&k),
        }
    }

    /// Drops every warm start involving `instance_id` (on either side, both kinds).
    pub fn invalidate_instance(&mut self, instance_id: &str) {
        self.distance.retain(|(a, b), _| a != instance_id && b != instance_id);
        self.growth.retain(|(a, b), _| a != instance_id && b != instance_id);
    }

    /// Number of stored warm starts (both kinds).
    pub fn len(&self) -> usize {
        self.distance.len() + self.growth.len()
    }

    /// True when nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalidation_drops_exactly_the_pairs_of_an_instance() {
        let mut c = WarmStartCache::default();
        let g = GrowthWarmStart { valid: true, multiplier: 2.0, ..Default::default() };
        c.put_growth("a", "b", g);
        c.put_growth("b", "c", g);
        c.put_distance("c", "a", DistanceWarmStart::default());
        c.put_distance("b", "c", DistanceWarmStart::default());
        assert_eq!(c.len(), 4);
        assert_eq!(c.growth("a", "b").map(|w| w.multiplier), Some(2.0));
        assert!(c.growth("b", "a").is_none(), "pairs are ordered");
        c.invalidate_instance("a");
        assert_eq!(c.len(), 2);
        let key = |kind, f: &str, s: &str| PairKey { kind, first: f.into(), second: s.into() };
        assert!(!c.contains(&key(WarmKind::Growth, "a", "b")));
        assert!(!c.contains(&key(WarmKind::Distance, "c", "a")));
        assert!(c.contains(&key(WarmKind::Growth, "b", "c")));
        assert!(c.contains(&key(WarmKind::Distance, "b", "c")));
    }
}
