//! Warm starts of a scene's queries, keyed by (query kind, ordered pair of instances).
//!
//! The Newton / active-set solvers (paper §IV) converge in a handful of iterations when started
//! from the previous answer of the same pair; the answer's `warm_start` is stored here and handed
//! back on the next query. Warm starts are expressed in body frames, so they survive pose changes;
//! they only become meaningless when an instance disappears, which is what
//! [`WarmStartCache::invalidate_instance`] handles.
//!
//! A pair involving a compound body keeps a [`TreeWarmStart`] instead (one solver
//! state per node pair of the two trees), under the same key: a pair is either compound or not
//! for the lifetime of its instances, so the distance (growth) kind copies, merges and drops both
//! tables together. A pair with an exact primitive keeps its [`ShapeWarmStart`] (the active-set
//! method's parameters, working set and multipliers) under the distance kind the same way.

use std::collections::HashMap;
use std::sync::Arc;
use sublevel_query::shape::ShapeWarmStart;
use sublevel_query::tree::TreeWarmStart;
use sublevel_query::{DistanceWarmStart, GrowthWarmStart};

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

/// Hasher of the cache's maps: foldhash (fast, non-cryptographic). The keys are instance ids of
/// one scene; a client choosing ids to collide only slows its own scene's queries.
type Fast = foldhash::fast::RandomState;

/// One kind's warm starts: first instance → second instance → state. Two levels so a lookup by
/// `(&str, &str)` allocates nothing (a lookup is on the hot path of every query).
type PairMap<W> = HashMap<String, HashMap<String, W, Fast>, Fast>;

/// Warm starts of one scene. States are shared (`Arc`) with the answers that produced them: a
/// distance warm start with its motion trail is about 1 KB, and an answer hands its new one over
/// without copying it.
#[derive(Debug, Default)]
pub struct WarmStartCache {
    distance: PairMap<Arc<DistanceWarmStart>>,
    growth: PairMap<Arc<GrowthWarmStart>>,
    /// Tree queries of pairs with a compound body: distance and collide-with-margin.
    tree_distance: PairMap<Arc<TreeWarmStart>>,
    /// Tree queries of pairs with a compound body: growth (overlap by d(p₁‖p₂)).
    tree_growth: PairMap<Arc<TreeWarmStart>>,
    /// Pairs with an exact primitive: distance and collide-with-margin (a few hundred bytes,
    /// copied rather than shared).
    shape: PairMap<ShapeWarmStart>,
}

fn get<'a, W>(map: &'a PairMap<W>, a: &str, b: &str) -> Option<&'a W> {
    map.get(a)?.get(b)
}

fn put<W>(map: &mut PairMap<W>, a: &str, b: &str, warm: W) {
    let inner = match map.get_mut(a) {
        Some(inner) => inner,
        None => map.entry(a.to_owned()).or_default(),
    };
    match inner.get_mut(b) {
        Some(slot) => *slot = warm,
        None => {
            inner.insert(b.to_owned(), warm);
        }
    }
}

fn count<W>(map: &PairMap<W>) -> usize {
    map.values().map(HashMap::len).sum()
}

fn drop_instance<W>(map: &mut PairMap<W>, id: &str) {
    map.remove(id);
    map.retain(|_, inner| {
        inner.remove(id);
        !inner.is_empty()
    });
}

impl WarmStartCache {
    /// The stored distance warm start of the ordered pair (a, b), if any.
    pub fn distance(&self, a: &str, b: &str) -> Option<&DistanceWarmStart> {
        get(&self.distance, a, b).map(|w| &**w)
    }

    /// Stores the distance warm start of (a, b), replacing the previous one.
    pub fn put_distance(&mut self, a: &str, b: &str, warm: Arc<DistanceWarmStart>) {
        put(&mut self.distance, a, b, warm);
    }

    /// The stored growth warm start of the ordered pair (p₁, p₂), if any.
    pub fn growth(&self, p1: &str, p2: &str) -> Option<&GrowthWarmStart> {
        get(&self.growth, p1, p2).map(|w| &**w)
    }

    /// Stores the growth warm start of (p₁, p₂), replacing the previous one.
    pub fn put_growth(&mut self, p1: &str, p2: &str, warm: Arc<GrowthWarmStart>) {
        put(&mut self.growth, p1, p2, warm);
    }

    /// The stored tree-distance warm start of the ordered pair (a, b) (a compound pair), if any.
    pub fn tree_distance(&self, a: &str, b: &str) -> Option<&TreeWarmStart> {
        get(&self.tree_distance, a, b).map(|w| &**w)
    }

    /// Stores the tree-distance warm start of (a, b), replacing the previous one.
    pub fn put_tree_distance(&mut self, a: &str, b: &str, warm: Arc<TreeWarmStart>) {
        put(&mut self.tree_distance, a, b, warm);
    }

    /// The stored tree-growth warm start of the ordered pair (p₁, p₂) (a compound pair), if any.
    pub fn tree_growth(&self, p1: &str, p2: &str) -> Option<&TreeWarmStart> {
        get(&self.tree_growth, p1, p2).map(|w| &**w)
    }

    /// Stores the tree-growth warm start of (p₁, p₂), replacing the previous one.
    pub fn put_tree_growth(&mut self, p1: &str, p2: &str, warm: Arc<TreeWarmStart>) {
        put(&mut self.tree_growth, p1, p2, warm);
    }

    /// The stored warm start of the ordered pair (a, b) with an exact primitive, if any.
    pub fn shape(&self, a: &str, b: &str) -> Option<&ShapeWarmStart> {
        get(&self.shape, a, b)
    }

    /// Stores the warm start of (a, b) with an exact primitive, replacing the previous one.
    pub fn put_shape(&mut self, a: &str, b: &str, warm: ShapeWarmStart) {
        put(&mut self.shape, a, b, warm);
    }

    /// Whether a warm start is stored for `key`.
    pub fn contains(&self, key: &PairKey) -> bool {
        match key.kind {
            WarmKind::Distance => {
                get(&self.distance, &key.first, &key.second).is_some()
                    || get(&self.tree_distance, &key.first, &key.second).is_some()
                    || get(&self.shape, &key.first, &key.second).is_some()
            }
            WarmKind::Growth => {
                get(&self.growth, &key.first, &key.second).is_some()
                    || get(&self.tree_growth, &key.first, &key.second).is_some()
            }
        }
    }

    /// Copies the warm start of `kind` for the ordered pair (a, b) (single or tree), if any and
    /// not already there, into `into` (the state is shared, not copied).
    pub fn copy_pair(&self, into: &mut WarmStartCache, kind: WarmKind, a: &str, b: &str) {
        fn copy<W: Clone>(from: &PairMap<W>, into: &mut PairMap<W>, a: &str, b: &str) {
            if let (Some(w), None) = (get(from, a, b), get(into, a, b)) {
                put(into, a, b, w.clone());
            }
        }
        match kind {
            WarmKind::Distance => {
                copy(&self.distance, &mut into.distance, a, b);
                copy(&self.tree_distance, &mut into.tree_distance, a, b);
                copy(&self.shape, &mut into.shape, a, b);
            }
            WarmKind::Growth => {
                copy(&self.growth, &mut into.growth, a, b);
                copy(&self.tree_growth, &mut into.tree_growth, a, b);
            }
        }
    }

    /// Moves every warm start of `other` whose two instances pass `keep` into this cache,
    /// replacing what is stored for the same pair.
    pub fn merge(&mut self, other: WarmStartCache, keep: impl Fn(&str) -> bool) {
        fn merge_map<W>(into: &mut PairMap<W>, from: PairMap<W>, keep: &impl Fn(&str) -> bool) {
            for (a, inner) in from {
                if !keep(&a) {
                    continue;
                }
                for (b, w) in inner {
                    if keep(&b) {
                        put(into, &a, &b, w);
                    }
                }
            }
        }
        merge_map(&mut self.distance, other.distance, &keep);
        merge_map(&mut self.growth, other.growth, &keep);
        merge_map(&mut self.tree_distance, other.tree_distance, &keep);
        merge_map(&mut self.tree_growth, other.tree_growth, &keep);
        merge_map(&mut self.shape, other.shape, &keep);
    }

    /// Drops every warm start involving `instance_id` (on either side, both kinds).
    pub fn invalidate_instance(&mut self, instance_id: &str) {
        drop_instance(&mut self.distance, instance_id);
        drop_instance(&mut self.growth, instance_id);
        drop_instance(&mut self.tree_distance, instance_id);
        drop_instance(&mut self.tree_growth, instance_id);
        drop_instance(&mut self.shape, instance_id);
    }

    /// Number of stored warm starts (both kinds).
    pub fn len(&self) -> usize {
        count(&self.distance)
            + count(&self.growth)
            + count(&self.tree_distance)
            + count(&self.tree_growth)
            + count(&self.shape)
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
        c.put_growth("a", "b", Arc::new(g));
        c.put_growth("b", "c", Arc::new(g));
        c.put_distance("c", "a", Arc::default());
        c.put_distance("b", "c", Arc::default());
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

    #[test]
    fn copy_and_merge_share_states_and_drop_removed_instances() {
        let mut scene = WarmStartCache::default();
        let g = GrowthWarmStart { valid: true, multiplier: 3.0, ..Default::default() };
        scene.put_growth("a", "b", Arc::new(g));
        let mut scratch = WarmStartCache::default();
        scene.copy_pair(&mut scratch, WarmKind::Growth, "a", "b");
        scene.copy_pair(&mut scratch, WarmKind::Distance, "a", "b"); // none stored: nothing copied
        assert_eq!(scratch.len(), 1);
        assert!(Arc::ptr_eq(&scene.growth["a"]["b"], &scratch.growth["a"]["b"]), "shared, not copied");
        // New states in the scratch: one for a live pair, one involving a removed instance `x`.
        let newer = GrowthWarmStart { valid: true, multiplier: 4.0, ..Default::default() };
        scratch.put_growth("a", "b", Arc::new(newer));
        scratch.put_distance("b", "x", Arc::default());
        scene.merge(scratch, |id| id != "x");
        assert_eq!(scene.growth("a", "b").map(|w| w.multiplier), Some(4.0));
        assert!(scene.distance("b", "x").is_none());
        assert_eq!(scene.len(), 1);
    }
}
