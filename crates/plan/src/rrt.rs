//! RRT-Connect (Kuffner and LaValle, ICRA 2000): two trees, one rooted at the start and one at
//! the goals (several goal configurations are several roots of the one goal tree), grown towards
//! each other.
//!
//! ```text
//! first: the straight edge start → each goal, when it is free, is the path
//! round: draw a configuration (the Halton sampler; with probability goal_bias, a root of the
//!        other tree instead)
//!        EXTEND the active tree towards it: from its nearest node, one step of at most `range`
//!        (joint-space distance), kept when the new node and the edge to it are free
//!        CONNECT the other tree to the new node: EXTEND it towards the node again and again until
//!        it reaches the node (a path) or is blocked
//!        swap the trees
//! until: a path, the deadline, or the cancel flag
//! ```
//!
//! Two refinements, both on by default, as VAMP's RRT-Connect has them:
//! - **Dynamic domains** (Yershova, Jaillet, Siméon and LaValle, ICRA 2005): a node whose sampled
//!   extension was blocked gets a radius ([`DOMAIN_RADIUS`]), and a later sample farther than its
//!   nearest node's radius is dropped unchecked, so the search stops spending checks on samples
//!   beyond obstacles next to the tree; the radius shrinks by a factor (1 − α) at each further
//!   failure, down to [`DOMAIN_MIN_RADIUS`], and grows by (1 + α) at each success. The connect
//!   step ignores the domains.
//! - **Balance**: the trees take turns, except that a tree of at most half the other's size keeps the
//!   turn, so a goal tree boxed in (a grasp inside a cage) grows as fast as the open one.
//!
//! Edges are checked by the checker's sampled test ([`Validity::edge_free`]) at the settings'
//! resolution; nearest neighbours by a linear scan of the tree's nodes, stored flat.

use crate::space::{HaltonSampler, JointSpace};
use crate::validity::Validity;
use rand::Rng;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use sublevel_core::math::Real;
use sublevel_core::Result;

/// Settings of one RRT-Connect search.
#[derive(Clone, Copy, Debug)]
pub struct SearchSettings {
    /// The longest step an extension takes (joint-space distance, > 0).
    pub range: Real,
    /// Samples per unit of joint-space distance on an edge (> 0).
    pub resolution: Real,
    /// The chance that a round draws a root of the other tree instead of a sample (in [0, 1)).
    pub goal_bias: Real,
    /// Whether the sampled extensions keep a dynamic domain per node (module docs).
    pub dynamic_domain: bool,
    /// Whether a tree of at most half the other's size keeps the turn (module docs).
    pub balance: bool,
}

/// The dynamic domain's radius given to a node at its first failed extension (joint-space
/// distance; Yershova et al.'s R, VAMP's default).
pub const DOMAIN_RADIUS: Real = 4.0;
/// The smallest radius a dynamic domain shrinks to.
pub const DOMAIN_MIN_RADIUS: Real = 1.0;
/// The factor a finite domain grows by at a successful extension (1 + α) and shrinks by at a
/// failed one (1 − α).
pub const DOMAIN_ALPHA: Real = 1e-4;

/// A tree of configurations, stored flat (`dof` entries a node).
struct Tree {
    dof: usize,
    nodes: Vec<Real>,
    /// Each node's parent; a root is its own parent.
    parent: Vec<usize>,
    /// Each node's dynamic-domain radius (+∞ until an extension from it fails).
    radius: Vec<Real>,
    roots: usize,
}

impl Tree {
    fn new(dof: usize, roots: &[Vec<Real>]) -> Self {
        let mut t = Self { dof, nodes: Vec::new(), parent: Vec::new(), radius: Vec::new(), roots: roots.len() };
        for (k, r) in roots.iter().enumerate() {
            t.nodes.extend_from_slice(r);
            t.parent.push(k);
            t.radius.push(Real::INFINITY);
        }
        t
    }
    fn len(&self) -> usize {
        self.parent.len()
    }
    fn node(&self, i: usize) -> &[Real] {
        &self.nodes[i * self.dof..(i + 1) * self.dof]
    }
    fn push(&mut self, q: &[Real], parent: usize) -> usize {
        self.nodes.extend_from_slice(q);
        self.parent.push(parent);
        self.radius.push(Real::INFINITY);
        self.len() - 1
    }
    fn nearest(&self, space: &JointSpace, q: &[Real]) -> usize {
        let (mut best, mut best_d) = (0, Real::INFINITY);
        for i in 0..self.len() {
            let node = self.node(i);
            let mut d = 0.0;
            for k in 0..self.dof {
                let e = space.delta(k, q[k], node[k]);
                d += e * e;
                if d >= best_d {
                    break;
                }
            }
            if d < best_d {
                best = i;
                best_d = d;
            }
        }
        best
    }
    /// The nodes from `i` up to its root, `i` first; and the root's index.
    fn to_root(&self, mut i: usize) -> (Vec<Vec<Real>>, usize) {
        let mut out = vec![self.node(i).to_vec()];
        while self.parent[i] != i {
            i = self.parent[i];
            out.push(self.node(i).to_vec());
        }
        (out, i)
    }
}

/// Why a search ended without a path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SearchStop {
    /// The deadline passed.
    Deadline,
    /// The cancel flag was set.
    Cancelled,
}

/// When a search must stop: a deadline and a cancel flag.
#[derive(Clone, Copy, Debug)]
pub struct Budget<'a> {
    /// The instant the search stops at.
    pub deadline: Instant,
    /// Set by the caller to stop the search early.
    pub cancel: &'a AtomicBool,
}

impl Budget<'_> {
    /// Why the search must stop now, if it must.
    pub fn stopped(&self) -> Option<SearchStop> {
        if self.cancel.load(Ordering::Relaxed) {
            Some(SearchStop::Cancelled)
        } else if Instant::now() >= self.deadline {
            Some(SearchStop::Deadline)
        } else {
            None
        }
    }
}

/// A path found by [`connect`]: the configurations from the start to the goal reached, and that
/// goal's index in the goals given.
#[derive(Clone, Debug)]
pub struct Found {
    /// The waypoints, start first.
    pub path: Vec<Vec<Real>>,
    /// The index of the goal reached.
    pub goal: usize,
    /// Nodes in both trees when the path was found.
    pub nodes: usize,
}

/// RRT-Connect from `start` to any of `goals` (module docs); `start` and the goals must be free.
///
/// # Errors
/// The checker's errors.
pub fn connect(
    checker: &mut dyn Validity,
    start: &[Real],
    goals: &[Vec<Real>],
    settings: &SearchSettings,
    sampler: &mut HaltonSampler,
    rng: &mut impl Rng,
    budget: Budget<'_>,
) -> Result<std::result::Result<Found, SearchStop>> {
    let space = checker.space().clone();
    for (g, goal) in goals.iter().enumerate() {
        if checker.edge_free(start, goal, settings.resolution)? {
            return Ok(Ok(Found { path: vec![start.to_vec(), goal.clone()], goal: g, nodes: 1 + goals.len() }));
        }
    }
    let dof = start.len();
    let mut a = Tree::new(dof, &[start.to_vec()]);
    let mut b = Tree::new(dof, goals);
    let mut a_is_start = true;
    let (mut sample, mut step) = (Vec::with_capacity(dof), Vec::with_capacity(dof));
    loop {
        if let Some(stop) = budget.stopped() {
            return Ok(Err(stop));
        }
        if settings.goal_bias > 0.0 && rng.random::<Real>() < settings.goal_bias {
            let root = rng.random_range(0..b.roots);
            sample.clear();
            sample.extend_from_slice(b.node(root));
        } else {
            sampler.next_in(&space, &mut sample);
        }
        let domain = settings.dynamic_domain;
        if let Some(new) = extend(checker, &space, &mut a, &sample, settings, domain, &mut step)? {
            let target = a.node(new).to_vec();
            loop {
                if let Some(stop) = budget.stopped() {
                    return Ok(Err(stop));
                }
                match extend(checker, &space, &mut b, &target, settings, false, &mut step)? {
                    Some(reached) if space.distance_squared(b.node(reached), &target) < 1e-24 => {
                        let (mut from_a, a_root) = a.to_root(new);
                        from_a.reverse();
                        let (from_b, b_root) = b.to_root(reached);
                        let mut path = from_a;
                        path.extend(from_b.into_iter().skip(1));
                        let goal = if a_is_start { b_root } else { a_root };
                        if !a_is_start {
                            path.reverse();
                        }
                        return Ok(Ok(Found { path, goal, nodes: a.len() + b.len() }));
                    }
                    Some(_) => continue,
                    None => break,
                }
            }
        }
        if passes_turn(settings.balance, a.len(), b.len()) {
            std::mem::swap(&mut a, &mut b);
            a_is_start = !a_is_start;
        }
    }
}

/// Whether the tree that just grew (`grown` nodes) passes the turn to the other (`other` nodes):
/// always without balance; with it, unless the grown tree holds at most half the other's nodes
/// (|grown − other| ≥ grown, VAMP's rule with a tree ratio of 1).
fn passes_turn(balance: bool, grown: usize, other: usize) -> bool {
    !balance || grown.abs_diff(other) < grown
}

/// Extends `tree` towards `target` by at most the range; the new node's index, or `None` when
/// the target is the nearest node itself, lies outside that node's dynamic domain (`domain`:
/// checked and updated), or the step is blocked.
fn extend(
    checker: &mut dyn Validity,
    space: &JointSpace,
    tree: &mut Tree,
    target: &[Real],
    settings: &SearchSettings,
    domain: bool,
    step: &mut Vec<Real>,
) -> Result<Option<usize>> {
    let near = tree.nearest(space, target);
    let from = tree.node(near).to_vec();
    let d = space.distance(&from, target);
    if d < 1e-12 || (domain && d > tree.radius[near]) {
        return Ok(None);
    }
    let t = (settings.range / d).min(1.0);
    if t < 1.0 {
        space.interpolate(&from, target, t, step);
    } else {
        step.clear();
        step.extend_from_slice(target);
    }
    // The edge's samples start with its end: the new node itself.
    let free = checker.edge_free(&from, step, settings.resolution)?;
    if domain {
        let r = &mut tree.radius[near];
        *r = match (free, r.is_finite()) {
            (true, true) => *r * (1.0 + DOMAIN_ALPHA),
            (true, false) => *r,
            (false, true) => (*r * (1.0 - DOMAIN_ALPHA)).max(DOMAIN_MIN_RADIUS),
            (false, false) => DOMAIN_RADIUS,
        };
    }
    if !free {
        return Ok(None);
    }
    Ok(Some(tree.push(step, near)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validity::{Certificate, CheckCounts};

    /// The plane [−10, 10]², blocked for x > −0.5; counts the sampled edges it was asked about.
    struct HalfPlane {
        space: JointSpace,
        edges: usize,
    }

    impl Validity for HalfPlane {
        fn space(&self) -> &JointSpace {
            &self.space
        }
        fn state_free(&mut self, q: &[Real]) -> Result<bool> {
            Ok(q[0] <= -0.5)
        }
        fn edge_free(&mut self, _a: &[Real], b: &[Real], _resolution: Real) -> Result<bool> {
            self.edges += 1;
            Ok(b[0] <= -0.5)
        }
        fn certify(&mut self, _a: &[Real], _b: &[Real], _tolerance: Real) -> Result<Certificate> {
            Ok(Certificate::Undecided)
        }
        fn counts(&self) -> CheckCounts {
            CheckCounts::default()
        }
        fn collision(&mut self, _q: &[Real]) -> Result<Option<String>> {
            Ok(None)
        }
    }

    #[test]
    fn dynamic_domains_follow_yershova_et_al_and_drop_far_samples_unchecked() {
        let mut checker = HalfPlane { space: JointSpace::boxed(vec![(-10.0, 10.0), (-10.0, 10.0)]), edges: 0 };
        let settings =
            SearchSettings { range: 1.0, resolution: 32.0, goal_bias: 0.0, dynamic_domain: true, balance: true };
        let space = checker.space().clone();
        let mut tree = Tree::new(2, &[vec![-1.0, 0.0]]);
        let mut step = Vec::new();
        let mut go = |tree: &mut Tree, target: [Real; 2], domain: bool, checker: &mut HalfPlane| {
            extend(checker, &space, tree, &target, &settings, domain, &mut step).unwrap()
        };
        // First failure: the radius R; a second one shrinks it by (1 − α).
        assert_eq!(go(&mut tree, [1.0, 0.0], true, &mut checker), None);
        assert_eq!((tree.radius[0], checker.edges), (DOMAIN_RADIUS, 1));
        assert_eq!(go(&mut tree, [2.0, 0.0], true, &mut checker), None);
        assert_eq!((tree.radius[0], checker.edges), (DOMAIN_RADIUS * (1.0 - DOMAIN_ALPHA), 2));
        // A sample beyond the radius (4.5 from the node) is dropped without a check.
        assert_eq!(go(&mut tree, [3.5, 0.0], true, &mut checker), None);
        assert_eq!(checker.edges, 2);
        // Without the domain the same sample is checked, and the radius is left alone.
        assert_eq!(go(&mut tree, [3.5, 0.0], false, &mut checker), None);
        assert_eq!((tree.radius[0], checker.edges), (DOMAIN_RADIUS * (1.0 - DOMAIN_ALPHA), 3));
        // The radius never falls below the minimum.
        tree.radius[0] = DOMAIN_MIN_RADIUS * (1.0 + 0.5 * DOMAIN_ALPHA);
        assert_eq!(go(&mut tree, [-0.2, 0.0], true, &mut checker), None);
        assert_eq!(tree.radius[0], DOMAIN_MIN_RADIUS);
        // A success grows a finite radius by (1 + α); the new node starts unbounded, one range
        // step (1.0) from its parent.
        let new = go(&mut tree, [-1.0, 0.5], true, &mut checker).unwrap();
        assert_eq!(tree.radius[0], DOMAIN_MIN_RADIUS * (1.0 + DOMAIN_ALPHA));
        assert_eq!((tree.node(new), tree.radius[new], tree.parent[new]), (&[-1.0, 0.5][..], Real::INFINITY, 0));
    }

    #[test]
    fn a_tree_of_at_most_half_the_others_size_keeps_the_turn() {
        assert!(!passes_turn(true, 10, 30));
        assert!(!passes_turn(true, 10, 20));
        assert!(passes_turn(true, 10, 19));
        assert!(passes_turn(true, 30, 10));
        assert!(passes_turn(false, 10, 30));
    }
}
