//! Best-first branch and bound over two containment trees: distance with a tolerance, and the
//! margin query "closer than m?" (module docs of [`super`]).
//!
//! The settings and answers are in `results`, the cheap lower bounds of node pairs in `bounds`,
//! and the warm start's cut (resuming a search from the last one's) in `cut`.

mod bounds;
mod cut;
mod results;

pub use bounds::axis_lower_bound;
pub(crate) use bounds::CheapBounds;
pub use results::{LeafPairAnswer, TreeDistanceResult, TreeMarginResult, TreeQueryParams};

use super::warm::{CutPair, FarPairs, TreeWarmStart};
use super::{check_tree, BodyTree};
use crate::{certified_distance, distance, AnswerSource, CertifyMode, CertifyParams};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use sublevel_core::error::{Error, Result};
use sublevel_core::math::{Isometry3, Real, Vector3};

/// Distance between the models of trees `a` (under `pose_a`) and `b` (under `pose_b`): bounds
/// `lower ≤ min over leaf pairs dist(A_i, B_j) ≤ upper` with `upper − lower ≤ params.tolerance`, by
/// best-first branch and bound (module docs of [`super`]; paper §V containment, eq. "distance" per
/// pair).
///
/// `warm` is the `warm_start` of the previous answer for the same two trees.
///
/// # Errors
/// [`Error::InvalidArgument`] for a broken tree (`tree_a`, `tree_b`) or bad settings
/// ([`TreeQueryParams::validate`]). Solver failures are not errors: see `converged`.
pub fn tree_distance<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
    a: &A,
    pose_a: &Isometry3,
    b: &B,
    pose_b: &Isometry3,
    warm: Option<&TreeWarmStart>,
    params: &TreeQueryParams,
) -> Result<TreeDistanceResult> {
    let mut s = Search::new(a, pose_a, b, pose_b, warm, params, Goal::Distance(params.tolerance))?;
    let stop = s.run();
    let warm_start = s.finish();
    let lower = stop.min(s.upper).min(s.pruned_min).min(s.unresolved_min).max(0.0);
    let best = s.best.map(|i| s.leaf_pairs[i].clone());
    let converged = s.unresolved_min == Real::INFINITY;
    Ok(TreeDistanceResult {
        lower,
        upper: s.upper,
        best,
        within_tolerance: converged && s.upper - lower <= params.tolerance * (1.0 + 1e-12) + 1e-15,
        converged,
        leaf_pairs: s.leaf_pairs,
        level: s.level,
        pairs_evaluated: s.pairs,
        pairs_pruned_by_spheres: s.sphere_pruned,
        unconverged_solves: s.unconverged,
        warm_start,
    })
}

/// The margin query "are the models of `a` and `b` closer than `margin`?" (collide with margin):
/// branch and bound that descends only node pairs closer than `margin` and stops at the first leaf
/// pair closer than it, so a pair whose roots are farther apart is answered at level 0.
///
/// `margin` in meters (finite, ≥ 0). Closer than `margin` means a model distance below it; at
/// `margin` 0, a model distance of 0 (touching or overlapping), as a single pair's collide
/// answers (`overlapping || distance < margin`).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `margin`, `tree_a`, `tree_b` or a setting.
pub fn tree_closer_than<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
    a: &A,
    pose_a: &Isometry3,
    b: &B,
    pose_b: &Isometry3,
    margin: Real,
    warm: Option<&TreeWarmStart>,
    params: &TreeQueryParams,
) -> Result<TreeMarginResult> {
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::invalid("margin", format!("must be finite and ≥ 0 m, got {margin}")));
    }
    // Closer than a margin m > 0 means a distance below m; at m = 0 it means touching or
    // overlapping (distance 0), as for a single pair: every bound below the smallest positive
    // distance counts.
    let margin = effective_margin(margin);
    let mut s = Search::new(a, pose_a, b, pose_b, warm, params, Goal::Margin(margin))?;
    let stop = s.run();
    let warm_start = s.finish();
    let lower = stop.min(s.pruned_min).min(s.unresolved_min);
    let (closer, converged, bound) = if s.upper < margin {
        (true, true, s.upper)
    } else if lower < margin {
        // An unresolved leaf pair or the pair cap: cannot rule the margin out.
        (true, false, lower)
    } else {
        (false, true, lower)
    };
    let leaves = s.best.filter(|_| s.upper < margin).map(|i| s.leaf_pairs[i].leaves);
    Ok(TreeMarginResult {
        closer,
        converged,
        bound,
        leaves,
        level: s.level,
        pairs_evaluated: s.pairs,
        pairs_pruned_by_spheres: s.sphere_pruned,
        warm_start,
    })
}

/// The margin a margin query compares distances with: `margin`, or the smallest positive number
/// for a zero margin (so that `distance < margin` holds exactly for distance 0, touching).
fn effective_margin(margin: Real) -> Real {
    margin.max(Real::MIN_POSITIVE)
}

#[derive(Clone, Copy)]
enum Goal {
    Distance(Real),
    Margin(Real),
}

/// A node pair (node `a` of tree A, node `b` of tree B) waiting in a best-first queue: the
/// `BinaryHeap` pops the smallest `lower` first (a distance or margin query's lower bound, the
/// overlap test's growth value).
#[derive(Clone, Copy)]
pub(super) struct Entry {
    pub(super) lower: Real,
    /// Tie-break among equal lower bounds (most often 0 for overlapping boxes): the raw box gap,
    /// negative when the boxes overlap; the deepest overlap is refined first.
    key: Real,
    /// The axis `lower` is the separating gap along (zero when none; [`CutPair::axis`]).
    axis: Vector3,
    pub(super) a: usize,
    pub(super) b: usize,
}

impl Entry {
    /// The pair (`a`, `b`) queued by `lower` alone (no tie-break, no axis).
    pub(super) fn pair(lower: Real, a: usize, b: usize) -> Self {
        Self { lower, key: lower, axis: Vector3::zeros(), a, b }
    }
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    /// Reversed, so that the max-heap pops the smallest lower bound first.
    fn cmp(&self, other: &Self) -> Ordering {
        other.lower.total_cmp(&self.lower).then_with(|| other.key.total_cmp(&self.key))
    }
}

/// Which node of a pair to split: the non-leaf one, else the one with the larger bounding sphere.
pub(crate) fn split_a<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(a: &A, na: usize, b: &B, nb: usize) -> bool {
    if a.children(na).is_empty() {
        return false;
    }
    if b.children(nb).is_empty() {
        return true;
    }
    a.node_radius(na) >= b.node_radius(nb)
}

struct Search<'t, A: ?Sized, B: ?Sized> {
    a: &'t A,
    pose_a: &'t Isometry3,
    b: &'t B,
    pose_b: &'t Isometry3,
    params: &'t TreeQueryParams,
    goal: Goal,
    old: Option<&'t TreeWarmStart>,
    fresh: TreeWarmStart,
    cheap: CheapBounds,
    heap: BinaryHeap<Entry>,
    upper: Real,
    best: Option<usize>,
    leaf_pairs: Vec<LeafPairAnswer>,
    /// The leaf pair solved before the search (the previous answer's active pair).
    seeded: Option<(usize, usize)>,
    /// The cut of this search: every terminal node pair with its lower bound (see [`Cut`](super::warm::Cut)): the
    /// pairs of the previous cut's base kept, with their new bounds (`base_lower`, NaN for a pair
    /// that left), and every other pair (`cut`).
    cut: Vec<CutPair>,
    base: Option<std::sync::Arc<Vec<CutPair>>>,
    base_lower: Vec<Real>,
    /// The previous cut's far group, when some of its pairs are still decided by its bound
    /// (carried as is, from `far_start` on).
    far: Option<std::sync::Arc<FarPairs>>,
    /// First pair of `far` still in the group (the ones before were released to the search).
    far_start: usize,
    /// How far B's root box moved since the previous cut's pose (meters; NaN without a cut): the
    /// step of the motion, which sets the far group's margin ([`TreeQueryParams::far_steps`]).
    step: Real,
    /// Smallest lower bound of the pairs pruned (they were not refined further).
    pruned_min: Real,
    /// Smallest lower bound of the leaf pairs left unresolved (and of pairs left by the cap).
    unresolved_min: Real,
    level: usize,
    pairs: usize,
    sphere_pruned: usize,
    unconverged: usize,
}

impl<'t, A: BodyTree + ?Sized, B: BodyTree + ?Sized> Search<'t, A, B> {
    fn new(
        a: &'t A,
        pose_a: &'t Isometry3,
        b: &'t B,
        pose_b: &'t Isometry3,
        old: Option<&'t TreeWarmStart>,
        params: &'t TreeQueryParams,
        goal: Goal,
    ) -> Result<Self> {
        params.validate()?;
        if !a.structure_checked() {
            check_tree(a, "tree_a")?;
        }
        if !b.structure_checked() {
            check_tree(b, "tree_b")?;
        }
        Ok(Self {
            a,
            pose_a,
            b,
            pose_b,
            params,
            goal,
            old,
            // Sized for a warm query (a solve or two), so that they are allocated once.
            fresh: TreeWarmStart { distance: Vec::with_capacity(4), ..TreeWarmStart::default() },
            cheap: CheapBounds::new(pose_a, pose_b, params.cheap_slack),
            heap: BinaryHeap::new(),
            upper: Real::INFINITY,
            best: None,
            leaf_pairs: Vec::with_capacity(2),
            seeded: None,
            cut: Vec::with_capacity(32),
            base: None,
            base_lower: Vec::new(),
            far: None,
            far_start: 0,
            step: Real::NAN,
            pruned_min: Real::INFINITY,
            unresolved_min: Real::INFINITY,
            level: 0,
            pairs: 0,
            sphere_pruned: 0,
            unconverged: 0,
        })
    }

    /// Pairs with a lower bound at or above this need no refinement.
    fn threshold(&self) -> Real {
        match self.goal {
            Goal::Distance(tol) => self.upper - tol,
            Goal::Margin(m) => m,
        }
    }

    /// Whether the query is decided (margin: a leaf pair closer than the margin).
    fn decided(&self) -> bool {
        matches!(self.goal, Goal::Margin(m) if self.upper < m)
    }

    fn is_leaf_pair(&self, na: usize, nb: usize) -> bool {
        self.a.children(na).is_empty() && self.b.children(nb).is_empty()
    }

    /// Records a terminal node pair of this search (see [`Cut`](super::warm::Cut)).
    fn keep(&mut self, na: usize, nb: usize, lower: Real, axis: Vector3) {
        let box_b = self.b.node_box(nb).unwrap_or((Vector3::zeros(), Vector3::repeat(Real::INFINITY)));
        let size = 1.0 + box_b.0.abs().sum() + box_b.1.sum();
        self.cut.push(CutPair { a: na as u32, b: nb as u32, lower, axis, support_a: Real::NAN, box_b, size });
    }

    /// Runs the search; returns the lower bound of the pairs left in the queue (+∞ when empty).
    ///
    /// Order of work: (1) the previous answer's active leaf pair,
    /// warm-started, for a tight upper bound at once; (2) the previous search's cut, whose pairs
    /// keep their bounds less the motion since ([`Search::resume`]), or else the root pair;
    /// (3) best-first descent on the cheap bounds ([`CheapBounds`]), which prune without any
    /// solve; (4) leaf pairs solved when popped (unless a refined axis prunes them), internal
    /// pairs only by margin queries.
    fn run(&mut self) -> Real {
        self.seed();
        if !self.resume() {
            // A search from the roots queues a few dozen pairs (52 on chair_101 × human_10).
            self.heap.reserve(64);
            self.consider(self.a.root(), self.b.root(), 0.0);
        }
        while let Some(e) = self.heap.pop() {
            if self.decided() || e.lower >= self.threshold() {
                self.drain(e);
                return e.lower;
            }
            if self.pairs >= self.params.max_pairs {
                self.unresolved_min = self.unresolved_min.min(e.lower);
                self.drain(e);
                return e.lower;
            }
            if self.is_leaf_pair(e.a, e.b) {
                if self.seeded != Some((e.a, e.b)) && !self.pruned_by_axis(e.a, e.b, e.lower, &e.axis) {
                    self.leaf(e.a, e.b, e.lower);
                }
                continue;
            }
            let mut lower = e.lower;
            if matches!(self.goal, Goal::Margin(_)) {
                let (l, axis) = self.internal(e.a, e.b, lower);
                lower = l;
                if lower >= self.threshold() {
                    self.pruned_min = self.pruned_min.min(lower);
                    self.keep(e.a, e.b, lower, axis);
                    continue;
                }
            }
            self.expand(e.a, e.b, lower);
        }
        Real::INFINITY
    }

    /// Splits an internal pair with lower bound `lower` ([`split_a`]) and considers its children.
    fn expand(&mut self, na: usize, nb: usize, lower: Real) {
        // The trees outlive `self`'s borrow: iterate their child slices without copying them.
        let (a, b) = (self.a, self.b);
        let split = split_a(a, na, b, nb);
        let children = if split { a.children(na) } else { b.children(nb) };
        for &c in children {
            let (ca, cb) = if split { (c, nb) } else { (na, c) };
            self.consider(ca, cb, lower);
        }
    }

    /// Moves the popped entry `e` and every pair left in the queue into the cut.
    fn drain(&mut self, e: Entry) {
        self.keep(e.a, e.b, e.lower, e.axis);
        while let Some(e) = self.heap.pop() {
            self.keep(e.a, e.b, e.lower, e.axis);
        }
    }

    /// Solves the previous answer's active leaf pair first (when it is still a leaf pair of these
    /// trees and its cheap bound does not already rule it out of a margin query).
    fn seed(&mut self) {
        let Some((na, nb)) = self.old.and_then(|w| w.active) else { return };
        if na >= self.a.node_count() || nb >= self.b.node_count() || !self.is_leaf_pair(na, nb) {
            return;
        }
        // A distance query has no threshold yet (+∞): no bound rules the pair out.
        let threshold = self.threshold();
        if threshold.is_finite() {
            let gap = self.cheap.gap_axis(self.a, na, self.b, nb).map_or(0.0, |g| g.0).max(0.0);
            if gap >= threshold {
                return;
            }
        }
        self.pairs += 1;
        let answer = self.solve_leaf(na, nb);
        if answer.exact {
            self.seeded = Some((na, nb));
            self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
            self.take_leaf(answer, 0.0);
        }
        // An unresolved seed is solved again in the search, where its lower bound is known.
    }

    /// Cheap bound of one node pair whose parent pair had lower bound `parent_lower`: pruned when
    /// it reaches the threshold, else queued.
    fn consider(&mut self, na: usize, nb: usize, parent_lower: Real) {
        let gap = self.cheap.gap_axis(self.a, na, self.b, nb);
        let lower = gap.map_or(parent_lower, |g| g.0.max(parent_lower));
        if lower >= self.threshold() {
            self.sphere_pruned += 1;
            self.pruned_min = self.pruned_min.min(lower);
            // The axis only when the bound is the gap along it (not the parent's bound).
            let axis = gap.filter(|g| g.0 >= parent_lower).map_or(Vector3::zeros(), |g| g.1);
            self.keep(na, nb, lower, axis);
            return;
        }
        self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
        let axis = gap.filter(|g| g.0 >= parent_lower).map_or(Vector3::zeros(), |g| g.1);
        self.heap.push(Entry { lower, key: gap.map_or(lower, |g| g.0), axis, a: na, b: nb });
    }

    /// Whether the separating-axis gap of leaf pair (na, nb) along a refined axis reaches the
    /// threshold ([`CheapBounds::refined_gap`]), so that the pair needs no solve.
    fn pruned_by_axis(&mut self, na: usize, nb: usize, lower: Real, start: &Vector3) -> bool {
        let Some((g, axis)) = self.cheap.refined_gap(self.a, na, self.b, nb, start) else { return false };
        if g.max(lower) < self.threshold() {
            return false;
        }
        self.sphere_pruned += 1;
        self.pruned_min = self.pruned_min.min(g.max(lower));
        if g >= lower {
            self.keep(na, nb, g, axis);
        } else {
            self.keep(na, nb, lower, Vector3::zeros());
        }
        true
    }

    /// Solves a leaf pair popped with lower bound `lower` and records it.
    fn leaf(&mut self, na: usize, nb: usize, lower: Real) {
        self.pairs += 1;
        let answer = self.solve_leaf(na, nb);
        if !answer.exact {
            self.unresolved_min = self.unresolved_min.min(lower);
        }
        self.take_leaf(answer, lower);
    }

    /// Records a solved leaf pair (popped with lower bound `lower`): the upper bound and the
    /// active pair when it is the best so far, and its cut entry (its exact distance and normal,
    /// or `lower` when unresolved).
    fn take_leaf(&mut self, answer: LeafPairAnswer, lower: Real) {
        let (na, nb) = answer.leaves;
        if answer.exact {
            let r = &answer.result;
            let axis = if r.overlapping { Vector3::zeros() } else { self.pose_a.rotation.inverse() * r.normal };
            self.keep(na, nb, r.distance, axis);
        } else {
            self.keep(na, nb, lower, Vector3::zeros());
        }
        if answer.exact && answer.result.distance < self.upper {
            self.upper = answer.result.distance;
            self.best = Some(self.leaf_pairs.len());
            self.fresh.active = Some(answer.leaves);
        }
        self.leaf_pairs.push(answer);
    }

    /// Newton lower bound of an internal pair (containment: it bounds every leaf pair below) and
    /// its normal (A's frame; zero when overlapping); `lower` when the solve does not converge.
    fn internal(&mut self, na: usize, nb: usize, lower: Real) -> (Real, Vector3) {
        self.pairs += 1;
        let warm = self.old.and_then(|w| w.distance_of((na, nb)));
        let r = distance(self.a.body(na), self.pose_a, self.b.body(nb), self.pose_b, warm, &self.params.newton);
        self.fresh.keep_distance((na, nb), r.warm_start.clone(), self.params.max_warm_pairs);
        if r.status.converged() && r.distance > lower {
            let axis = if r.overlapping { Vector3::zeros() } else { self.pose_a.rotation.inverse() * r.normal };
            (r.distance, axis)
        } else {
            if !r.status.converged() {
                self.unconverged += 1;
            }
            (lower, Vector3::zeros())
        }
    }

    /// Solves a leaf pair by Newton, with the SDP when asked or as fallback (module docs).
    fn solve_leaf(&mut self, na: usize, nb: usize) -> LeafPairAnswer {
        let (ba, bb) = (self.a.body(na), self.b.body(nb));
        let warm = self.old.and_then(|w| w.distance_of((na, nb)));
        let p = self.params;
        let nonconvex = ba.report.nonconvex || bb.report.nonconvex;
        let answer = if p.certify == CertifyMode::Certify || nonconvex {
            self.certified(na, nb, warm, p.certify)
        } else {
            let r = distance(ba, self.pose_a, bb, self.pose_b, warm, &p.newton);
            if r.status.converged() {
                LeafPairAnswer {
                    leaves: (na, nb),
                    result: r,
                    exact: true,
                    source: AnswerSource::Newton,
                    certificate: None,
                }
            } else if p.sdp_fallback {
                self.unconverged += 1;
                self.certified(na, nb, None, CertifyMode::Newton)
            } else {
                self.unconverged += 1;
                LeafPairAnswer {
                    leaves: (na, nb),
                    result: r,
                    exact: false,
                    source: AnswerSource::Newton,
                    certificate: None,
                }
            }
        };
        self.fresh.keep_distance((na, nb), answer.result.warm_start.clone(), self.params.max_warm_pairs);
        answer
    }

    fn certified(
        &self,
        na: usize,
        nb: usize,
        warm: Option<&crate::DistanceWarmStart>,
        mode: CertifyMode,
    ) -> LeafPairAnswer {
        let cp = CertifyParams { newton: self.params.newton, certificate: self.params.certificate };
        let c = certified_distance(self.a.body(na), self.pose_a, self.b.body(nb), self.pose_b, warm, &cp, mode);
        LeafPairAnswer {
            leaves: (na, nb),
            exact: c.converged && !c.lower_bound,
            result: c.result,
            source: c.source,
            certificate: c.certificate,
        }
    }
}
