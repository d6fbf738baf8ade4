//! Best-first branch and bound over two containment trees: distance with a tolerance, and the
//! margin query "closer than m?" (module docs of [`super`]).

use super::warm::TreeWarmStart;
use super::{check_tree, BodyTree};
use crate::body::Body;
use crate::error::{Error, Result};
use crate::math::{Isometry3, Real};
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
    /// Node pairs decided by their bounding spheres alone (no solve).
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
    /// Node pairs decided by their bounding spheres alone.
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
        other.lower.total_cmp(&self.lower)
    }
}

/// Lower bound of the distance of two bodies from their bounding spheres (free, no solve);
/// `None` for a nonconvex body (no proven sphere).
pub(crate) fn sphere_gap(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Real> {
    let (ca, ra) = a.bounding_sphere()?;
    let (cb, rb) = b.bounding_sphere()?;
    Some(((pose_a * ca) - (pose_b * cb)).norm() - ra - rb)
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
    heap: BinaryHeap<Entry>,
    upper: Real,
    best: Option<usize>,
    leaf_pairs: Vec<LeafPairAnswer>,
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
            fresh: TreeWarmStart::default(),
            heap: BinaryHeap::new(),
            upper: Real::INFINITY,
            best: None,
            leaf_pairs: Vec::new(),
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

    /// Runs the search; returns the lower bound of the pairs left in the queue (+∞ when empty).
    fn run(&mut self) -> Real {
        self.visit(self.a.root(), self.b.root(), 0.0);
        while let Some(e) = self.heap.pop() {
            if self.decided() {
                return e.lower;
            }
            if e.lower >= self.threshold() {
                return e.lower;
            }
            if self.pairs >= self.params.max_pairs {
                self.unresolved_min = self.unresolved_min.min(e.lower);
                return e.lower;
            }
            // The trees outlive `self`'s borrow: iterate their child slices without copying them.
            let (a, b) = (self.a, self.b);
            let split = split_a(a, e.a, b, e.b);
            let children = if split { a.children(e.a) } else { b.children(e.b) };
            for &c in children {
                let (ca, cb) = if split { (c, e.b) } else { (e.a, c) };
                self.visit(ca, cb, e.lower);
                if self.decided() {
                    break;
                }
            }
        }
        Real::INFINITY
    }

    /// Bounds one node pair whose parent pair had lower bound `parent_lower`.
    fn visit(&mut self, na: usize, nb: usize, parent_lower: Real) {
        let (ba, bb) = (self.a.body(na), self.b.body(nb));
        if let Some(gap) = sphere_gap(ba, self.pose_a, bb, self.pose_b) {
            let bound = gap.max(parent_lower);
            if bound >= self.threshold() {
                self.sphere_pruned += 1;
                self.pruned_min = self.pruned_min.min(bound);
                return;
            }
        }
        self.pairs += 1;
        self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
        if self.a.children(na).is_empty() && self.b.children(nb).is_empty() {
            let answer = self.solve_leaf(na, nb);
            if answer.exact {
                if answer.result.distance < self.upper {
                    self.upper = answer.result.distance;
                    self.best = Some(self.leaf_pairs.len());
                }
            } else {
                self.unresolved_min = self.unresolved_min.min(parent_lower);
            }
            self.leaf_pairs.push(answer);
            return;
        }
        let warm = self.old.and_then(|w| w.distance_of((na, nb)));
        let r = distance(ba, self.pose_a, bb, self.pose_b, warm, &self.params.newton);
        self.fresh.keep_distance((na, nb), r.warm_start.clone());
        let lower = if r.status.converged() {
            r.distance.max(parent_lower)
        } else {
            self.unconverged += 1;
            parent_lower
        };
        if lower >= self.threshold() {
            self.pruned_min = self.pruned_min.min(lower);
        } else {
            self.heap.push(Entry { lower, a: na, b: nb });
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
