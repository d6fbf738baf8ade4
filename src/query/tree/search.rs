//! Best-first branch and bound over two containment trees: distance with a tolerance, and the
//! margin query "closer than m?" (module docs of [`super`]).

use super::warm::{SolvedPair, TreeWarmStart};
use super::{check_tree, BodyTree};
use crate::body::Body;
use crate::error::{Error, Result};
use crate::math::{Isometry3, Real, Vector3};
use crate::query::sdp_certificate::CertificateParams;
use crate::query::{
    certified_distance, distance, distance_gradient, AnswerSource, CertificateSummary, CertifyMode, CertifyParams,
    DistanceResult, NewtonParams, PoseGradient,
};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Settings of the tree queries.
#[derive(Clone, Copy, Debug)]
pub struct TreeQueryParams {
    /// Tolerances of the Newton / active-set solves of each node pair.
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
    /// fallback ([`certified_distance`]); default true. Without it the pair stays unresolved.
    pub sdp_fallback: bool,
    /// Cap on the node pairs solved by one query (≥ 1; default 100 000); a query that reaches it
    /// stops with valid but wider bounds (`within_tolerance = false`).
    pub max_pairs: usize,
}

impl Default for TreeQueryParams {
    fn default() -> Self {
        Self {
            newton: NewtonParams::default(),
            tolerance: 0.0,
            certify: CertifyMode::Newton,
            certificate: CertificateParams::default(),
            sdp_fallback: true,
            max_pairs: 100_000,
        }
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

/// Answer of [`tree_distance`]: bounds on the model distance `min over leaf pairs dist(A_i, B_j)`.
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
    /// The deepest tree level reached: max over solved node pairs of max(depth in A, depth in B).
    pub level: usize,
    /// Node pairs solved (Newton solves, leaf pairs included).
    pub pairs_evaluated: usize,
    /// Node pairs decided by cheap bounds alone (no solve): the separating-axis gap of their
    /// bounding boxes, which contains the bounding spheres' gap (module docs of [`super`]).
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

/// Answer of [`tree_closer_than`].
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
    /// The deepest tree level reached (0: decided by the root pair).
    pub level: usize,
    /// Node pairs solved.
    pub pairs_evaluated: usize,
    /// Node pairs decided by cheap bounds alone (bounding boxes, no solve).
    pub pairs_pruned_by_spheres: usize,
    /// State for warm-starting the next query of the same two trees.
    pub warm_start: TreeWarmStart,
}

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
        warm_start: s.fresh,
    })
}

/// The margin query "are the models of `a` and `b` closer than `margin`?" (collide with margin):
/// branch and bound that descends only node pairs closer than `margin` and stops at the first leaf
/// pair closer than it, so a pair whose roots are farther apart is answered at level 0.
///
/// `margin` in meters (finite, ≥ 0; 0 asks for overlap, touching counts as not closer).
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
    let mut s = Search::new(a, pose_a, b, pose_b, warm, params, Goal::Margin(margin))?;
    let stop = s.run();
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
        warm_start: s.fresh,
    })
}

#[derive(Clone, Copy)]
enum Goal {
    Distance(Real),
    Margin(Real),
}

/// A node pair waiting in the queue with its lower bound.
struct Entry {
    lower: Real,
    /// Tie-break among equal lower bounds (most often 0 for overlapping boxes): the raw box gap,
    /// negative when the boxes overlap; the deepest overlap is refined first.
    key: Real,
    a: usize,
    b: usize,
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

/// The cheap lower bounds of one query: tree B's boxes are seen in tree A's frame, where A's boxes
/// are axis-aligned (every node of a tree shares the tree's pose).
///
/// For a unit axis `L`, the projections of two sets onto `L` are intervals, and any two points
/// `x ∈ A`, `y ∈ B` satisfy `‖x − y‖ ≥ |L·(x − y)|`; so the gap between the projected intervals
/// of two boxes containing the bodies is a lower bound of the bodies' distance (the separating
/// axis test). [`CheapBounds::gap`] takes the best of A's three face normals, B's three and the
/// direction between the box centers; the last one alone already dominates the bounding spheres'
/// gap `‖c_B − c_A‖ − r_A − r_B` (Cauchy–Schwarz: Σ h_k |n·e_k| ≤ ‖h‖).
pub(crate) struct CheapBounds {
    /// Pose of B's frame in A's frame, `pose_a⁻¹·pose_b`.
    rel: Isometry3,
    /// Rotation of B's frame in A's frame.
    rot: crate::math::Matrix3,
    /// |rot| entrywise.
    abs_rot: crate::math::Matrix3,
    /// Translation of B's frame in A's frame.
    shift: Vector3,
}

/// Relative slack of the cheap bounds (meters per meter of center distance): rounding of the box
/// projections never makes a bound exceed the true gap.
const CHEAP_SLACK: Real = 1e-12;

impl CheapBounds {
    pub(crate) fn new(pose_a: &Isometry3, pose_b: &Isometry3) -> Self {
        let rel = pose_a.inverse() * pose_b;
        let rot = *rel.rotation.to_rotation_matrix().matrix();
        Self { rot, abs_rot: rot.abs(), shift: rel.translation.vector, rel }
    }

    /// Lower bound of a leaf pair's distance now from its exact distance `solved.distance` at
    /// another relative pose (meters): every point of B (body `b`, inside its bounding sphere
    /// (c, r)) moved by at most `δ = ‖rel·c − rel₀·c‖ + 2 sin(θ/2)·r` relative to A, θ the angle of
    /// the rotation between the two poses (‖R − R₀‖₂ = 2 sin(θ/2)), so `dist ≥ solved.distance − δ`.
    pub(crate) fn motion_bound(&self, b: &Body, solved: &SolvedPair) -> Option<Real> {
        let (c, r) = b.bounding_sphere()?;
        let moved = (self.rel * c - solved.relative_pose * c).norm();
        let angle = (self.rel.rotation * solved.relative_pose.rotation.inverse()).angle();
        let delta = moved + 2.0 * (0.5 * angle).sin() * r;
        Some(solved.distance - delta - CHEAP_SLACK * (1.0 + solved.distance + delta))
    }

    /// Lower bound of the distance between bodies `a` (tree A) and `b` (tree B), meters; negative
    /// when the boxes overlap (then only 0 is a bound); `None` for a nonconvex body (no box).
    pub(crate) fn gap(&self, a: &Body, b: &Body) -> Option<Real> {
        let (ca, ha) = a.bounding_box()?;
        let (cb, hb) = b.bounding_box()?;
        // B's center relative to A's, in A's frame and in B's frame.
        let d = self.rot * cb.coords + self.shift - ca.coords;
        let db = self.rot.transpose() * d;
        // B's half extents along A's axes and A's along B's.
        let hb_in_a = self.abs_rot * hb;
        let ha_in_b = self.abs_rot.transpose() * ha;
        let mut gap = Real::NEG_INFINITY;
        for k in 0..3 {
            gap = gap.max(d[k].abs() - ha[k] - hb_in_a[k]);
            gap = gap.max(db[k].abs() - hb[k] - ha_in_b[k]);
        }
        let norm = d.norm();
        if norm > 0.0 {
            let reach = ha.dot(&d.abs()) + hb.dot(&db.abs());
            gap = gap.max(norm - reach / norm);
        }
        Some(gap - CHEAP_SLACK * (1.0 + norm))
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
    let radius = |body: &Body| body.bounding_sphere().map_or(body.scale(), |s| s.1);
    radius(a.body(na)) >= radius(b.body(nb))
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
        check_tree(a, "tree_a")?;
        check_tree(b, "tree_b")?;
        Ok(Self {
            a,
            pose_a,
            b,
            pose_b,
            params,
            goal,
            old,
            fresh: TreeWarmStart {
                distance: Vec::with_capacity(16),
                growth: Vec::new(),
                active: None,
                solved: Vec::with_capacity(8),
            },
            cheap: CheapBounds::new(pose_a, pose_b),
            heap: BinaryHeap::with_capacity(32),
            upper: Real::INFINITY,
            best: None,
            leaf_pairs: Vec::with_capacity(4),
            seeded: None,
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

    /// Runs the search; returns the lower bound of the pairs left in the queue (+∞ when empty).
    ///
    /// Order of work (issue 14 part 2, speed targets): (1) the previous answer's active leaf pair,
    /// warm-started, for a tight upper bound at once; (2) best-first descent on the cheap box
    /// bounds ([`CheapBounds`]) and the motion bounds of pairs solved before, which prune without
    /// any solve; (3) leaf pairs solved when popped, internal pairs only by margin queries.
    fn run(&mut self) -> Real {
        self.seed();
        self.consider(self.a.root(), self.b.root(), 0.0);
        while let Some(e) = self.heap.pop() {
            if self.decided() || e.lower >= self.threshold() {
                return e.lower;
            }
            if self.pairs >= self.params.max_pairs {
                self.unresolved_min = self.unresolved_min.min(e.lower);
                return e.lower;
            }
            if self.is_leaf_pair(e.a, e.b) {
                if self.seeded != Some((e.a, e.b)) && !self.pruned_by_motion(e.a, e.b, e.lower) {
                    self.leaf(e.a, e.b, e.lower);
                }
                continue;
            }
            let mut lower = e.lower;
            if matches!(self.goal, Goal::Margin(_)) {
                lower = self.internal(e.a, e.b, lower);
                if lower >= self.threshold() {
                    self.pruned_min = self.pruned_min.min(lower);
                    continue;
                }
            }
            // The trees outlive `self`'s borrow: iterate their child slices without copying them.
            let (a, b) = (self.a, self.b);
            let split = split_a(a, e.a, b, e.b);
            let children = if split { a.children(e.a) } else { b.children(e.b) };
            for &c in children {
                let (ca, cb) = if split { (c, e.b) } else { (e.a, c) };
                self.consider(ca, cb, lower);
            }
        }
        Real::INFINITY
    }

    /// Solves the previous answer's active leaf pair first (when it is still a leaf pair of these
    /// trees and its cheap bound does not already rule it out of a margin query).
    fn seed(&mut self) {
        let Some((na, nb)) = self.old.and_then(|w| w.active) else { return };
        if na >= self.a.node_count() || nb >= self.b.node_count() || !self.is_leaf_pair(na, nb) {
            return;
        }
        let gap = self.cheap.gap(self.a.body(na), self.b.body(nb)).unwrap_or(0.0).max(0.0);
        if gap >= self.threshold() {
            return;
        }
        self.pairs += 1;
        let answer = self.solve_leaf(na, nb);
        if answer.exact {
            self.seeded = Some((na, nb));
            self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
            self.take_leaf(answer);
        }
        // An unresolved seed is solved again in the search, where its lower bound is known.
    }

    /// Cheap bound of one node pair whose parent pair had lower bound `parent_lower`: pruned when
    /// it reaches the threshold, else queued.
    fn consider(&mut self, na: usize, nb: usize, parent_lower: Real) {
        let gap = self.cheap.gap(self.a.body(na), self.b.body(nb));
        let lower = gap.map_or(parent_lower, |g| g.max(parent_lower));
        if lower >= self.threshold() {
            self.sphere_pruned += 1;
            self.pruned_min = self.pruned_min.min(lower);
            return;
        }
        self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
        self.heap.push(Entry { lower, key: gap.unwrap_or(lower), a: na, b: nb });
    }

    /// Whether the previous answers' exact distance of leaf pair (na, nb), less the motion since
    /// ([`CheapBounds::motion_bound`]), already reaches the threshold; such a pair keeps its
    /// record for the next query.
    fn pruned_by_motion(&mut self, na: usize, nb: usize, lower: Real) -> bool {
        let Some(solved) = self.old.and_then(|w| w.solved_of((na, nb))) else { return false };
        let Some(bound) = self.cheap.motion_bound(self.b.body(nb), solved) else { return false };
        let bound = bound.max(lower);
        if bound < self.threshold() {
            return false;
        }
        self.sphere_pruned += 1;
        self.pruned_min = self.pruned_min.min(bound);
        self.fresh.solved.push(*solved);
        true
    }

    /// Solves a leaf pair popped with lower bound `lower` and records it.
    fn leaf(&mut self, na: usize, nb: usize, lower: Real) {
        self.pairs += 1;
        let answer = self.solve_leaf(na, nb);
        if !answer.exact {
            self.unresolved_min = self.unresolved_min.min(lower);
        }
        self.take_leaf(answer);
    }

    fn take_leaf(&mut self, answer: LeafPairAnswer) {
        if answer.exact {
            self.fresh.solved.push(SolvedPair {
                pair: answer.leaves,
                distance: answer.result.distance,
                relative_pose: self.cheap.rel,
            });
        }
        if answer.exact && answer.result.distance < self.upper {
            self.upper = answer.result.distance;
            self.best = Some(self.leaf_pairs.len());
            self.fresh.active = Some(answer.leaves);
        }
        self.leaf_pairs.push(answer);
    }

    /// Newton lower bound of an internal pair (containment: it bounds every leaf pair below);
    /// `lower` when the solve does not converge.
    fn internal(&mut self, na: usize, nb: usize, lower: Real) -> Real {
        self.pairs += 1;
        let warm = self.old.and_then(|w| w.distance_of((na, nb)));
        let r = distance(self.a.body(na), self.pose_a, self.b.body(nb), self.pose_b, warm, &self.params.newton);
        self.fresh.keep_distance((na, nb), r.warm_start.clone());
        if r.status.converged() {
            r.distance.max(lower)
        } else {
            self.unconverged += 1;
            lower
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
        self.fresh.keep_distance((na, nb), answer.result.warm_start.clone());
        answer
    }

    fn certified(
        &self,
        na: usize,
        nb: usize,
        warm: Option<&crate::query::DistanceWarmStart>,
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
