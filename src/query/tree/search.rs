//! Best-first branch and bound over two containment trees: distance with a tolerance, and the
//! margin query "closer than m?" (module docs of [`super`]).

use super::warm::{Cut, CutPair, FarPairs, TreeWarmStart, MAX_CUT_PAIRS};
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
    /// The deepest tree level reached: max over the node pairs queued or solved by this query of
    /// max(depth in A, depth in B) (pairs of the warm start's cut kept by their motion bounds
    /// are not counted).
    pub level: usize,
    /// Node pairs solved (Newton solves, leaf pairs included).
    pub pairs_evaluated: usize,
    /// Node pairs decided by cheap bounds alone (no solve): separating-axis gaps of their boxes
    /// and support bounds, which contain the bounding spheres' gap, and the pairs of the warm
    /// start's cut kept by their motion bounds (module docs of [`super`]).
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

#[derive(Clone, Copy)]
enum Goal {
    Distance(Real),
    Margin(Real),
}

/// A node pair waiting in the queue with its lower bound.
#[derive(Clone, Copy)]
struct Entry {
    lower: Real,
    /// Tie-break among equal lower bounds (most often 0 for overlapping boxes): the raw box gap,
    /// negative when the boxes overlap; the deepest overlap is refined first.
    key: Real,
    /// The axis `lower` is the separating gap along (zero when none; [`CutPair::axis`]).
    axis: Vector3,
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

/// The cheap lower bounds of one query: tree B is seen in tree A's frame (every node of a tree
/// shares the tree's pose).
///
/// For a unit axis `L`, the projections of two sets onto `L` are intervals, and any two points
/// `x ∈ A`, `y ∈ B` satisfy `‖x − y‖ ≥ |L·(x − y)|`; so the gap between the projected intervals
/// of two sets containing the bodies is a lower bound of the bodies' distance (the separating
/// axis test). The sets are the certified support bounds of the leaves below each node
/// ([`BodyTree::support_upper`]: for a compound body, the leaves' convex hull, tighter than the
/// containment fits) and the nodes' boxes; the axis is the direction between the box centers
/// ([`CheapBounds::gap_axis`]), refined towards the witnesses' normal before a leaf pair is
/// solved ([`CheapBounds::refined_gap`]), or the axis a kept cut pair was decided along.
/// Measured on chair_101 × human_10 (cold poses of `tree_profile`): 7.2 leaf solves per query
/// with the boxes' separating axes alone, 2.1 with the bodies' support bounds, 1.5 with the
/// leaves' hulls at the parents.
pub(crate) struct CheapBounds {
    /// Pose of B's frame in A's frame, `pose_a⁻¹·pose_b`.
    rel: Isometry3,
    /// Rotation of B's frame in A's frame.
    rot: crate::math::Matrix3,
    /// Translation of B's frame in A's frame.
    shift: Vector3,
}

/// Relative slack of the cheap bounds (meters per meter of center distance): rounding of the box
/// projections never makes a bound exceed the true gap.
pub(crate) const CHEAP_SLACK: Real = 1e-12;

/// A certified lower bound of the distance between two posed convex bodies (meters), from their
/// boxes and certified support bounds along the line between the boxes' centers
/// ([`CheapBounds::gap_axis`]: the larger of the boxes' projected gap and the separating-axis gap
/// `n·t − h_B(−Rᵀn) − h_A(n)` of [`crate::poly::SupportBound`], less [`CHEAP_SLACK`]); negative
/// or zero when that axis does not separate them. `None` for a nonconvex body (no certified
/// bound). About 0.14 µs, against about 2 µs for a cold distance solve at 2d = 6.
///
/// On the 300 cold chair_101 / human_10 poses of `sublevel bench`, at margin 0, it shows
/// separation (bound > 0) for 125 / 104 / 88 (2d = 4 / 6 / 8) of the pairs whose bounding spheres
/// overlap, of the 139 / 117 / 100 separated ones among them; refining the axis towards the
/// witnesses (two support look-ups a round, as the tree queries do) showed none more.
pub fn axis_lower_bound(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Real> {
    CheapBounds::new(pose_a, pose_b).gap_axis(a, 0, b, 0).map(|(gap, _)| gap)
}

/// A cut pair goes to the far group of the next warm start ([`FarPairs`]) when its bound exceeds
/// the threshold by more than this many times the last step's motion; the group then releases its
/// pairs to the search one by one as the motion since its pose uses up their margin. Measured with
/// `tree_profile` (chair_101 × human_10, the bench's 500-step warm motion, median warm query):
/// 2.9 µs without a far group; 2.3 / 2.4 / 2.5 µs at 1 / 2 / 4 steps (about half of the ~95 cut
/// pairs stay near: a search ends with most pairs just above its threshold).
const FAR_STEPS: Real = 1.0;

/// Fewest pairs worth a far group: below it, every pair stays near.
const MIN_FAR_PAIRS: usize = 8;

impl CheapBounds {
    pub(crate) fn new(pose_a: &Isometry3, pose_b: &Isometry3) -> Self {
        let rel = pose_a.inverse() * pose_b;
        let rot = *rel.rotation.to_rotation_matrix().matrix();
        Self { rot, shift: rel.translation.vector, rel }
    }

    /// Lower bound of the distance between bodies `a` (tree A) and `b` (tree B), meters; negative
    /// when the boxes overlap (then only 0 is a bound); `None` for a nonconvex body (no box).
    #[cfg(test)]
    pub(crate) fn gap(&self, a: &crate::body::Body, b: &crate::body::Body) -> Option<Real> {
        self.gap_axis(a, 0, b, 0).map(|(g, _)| g)
    }

    /// [`CheapBounds::gap`] and its axis: the separating-axis gap of nodes `na` of A and `nb` of B
    /// along the direction n between their box centers (A's frame, from A towards B), the best of
    /// their boxes' projections and the certified support bounds of their leaves
    /// ([`CheapBounds::axis_gap`]), slack subtracted. The bound is also a lower bound of the gap
    /// along n, which the motion bounds of a kept cut follow ([`super::warm::CutPair`]). `None`
    /// for a nonconvex body.
    ///
    /// The boxes' own separating axes (their six face normals) decided almost no pair of
    /// chair_101 × human_10 that n did not, at twice the cost, so they are not tried.
    pub(crate) fn gap_axis<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
        &self,
        a: &A,
        na: usize,
        b: &B,
        nb: usize,
    ) -> Option<(Real, Vector3)> {
        let (ca, ha) = a.node_box(na)?;
        let (cb, hb) = b.node_box(nb)?;
        let d = self.rot * cb + self.shift - ca;
        let norm = d.norm();
        let n = if norm > 0.0 { d / norm } else { Vector3::x() };
        let m = self.rot.transpose() * n;
        // The boxes' projections on n (contains the bounding spheres' gap ‖d‖ − r_A − r_B, by
        // Cauchy–Schwarz: Σ hₖ |nₖ| ≤ ‖h‖) and the leaves' support bounds along n.
        let boxes = norm - ha.dot(&n.abs()) - hb.dot(&m.abs());
        let g = n.dot(&self.shift) - b.support_upper(nb, &-m)? - a.support_upper(na, &n)?;
        Some((g.max(boxes) - CHEAP_SLACK * (1.0 + norm + g.abs()), n))
    }

    /// The separating-axis gap along an axis refined towards the witnesses' normal: from `start`
    /// (a unit axis, e.g. the pair's normal in an earlier query; zero for the direction between
    /// the box centers), twice `n ← (y − x)/‖y − x‖` with x, y the estimated
    /// support points of A along n and of B along −n ([`crate::body::Body::support_estimate`]); the best
    /// [`CheapBounds::axis_gap`] of the axes tried, slack subtracted (meters), and its axis.
    /// `None` for a nonconvex body.
    pub(crate) fn refined_gap<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
        &self,
        a: &A,
        na: usize,
        b: &B,
        nb: usize,
        start: &Vector3,
    ) -> Option<(Real, Vector3)> {
        let (ba, bb) = (a.body(na), b.body(nb));
        let (ca, _) = a.node_box(na)?;
        let (cb, _) = b.node_box(nb)?;
        let d = self.rot * cb + self.shift - ca;
        let mut n = if *start == Vector3::zeros() { d.try_normalize(0.0)? } else { *start };
        let mut best = (Real::NEG_INFINITY, n);
        for _ in 0..2 {
            let x = ba.support_estimate(&n)?;
            let z = bb.support_estimate(&-(self.rot.transpose() * n))?;
            let y = self.rot * z.coords + self.shift;
            n = match (y - x.coords).try_normalize(0.0) {
                Some(m) => m,
                None => break,
            };
            let g = self.axis_gap(a, na, b, nb, &n)?;
            if g > best.0 {
                best = (g, n);
            }
        }
        Some((best.0 - CHEAP_SLACK * (1.0 + d.norm()), best.1))
    }

    /// The separating-axis gap of nodes `na` of A and `nb` of B along the unit axis `n` (A's
    /// frame, meters) from the certified support bounds of their leaves
    /// ([`BodyTree::support_upper`]):
    ///
    /// ```text
    /// min_{y ∈ B} n·y − max_{x ∈ A} n·x = n·t − h_B(−Rᵀn) − h_A(n)     (B posed by (R, t) in A's frame)
    /// ```
    ///
    /// a lower bound of dist(A, B) for every unit n, equal to it at the witnesses' normal (up to
    /// the support table's interpolation). `None` for a nonconvex body. Without slack: callers
    /// subtract [`CHEAP_SLACK`].
    #[inline]
    pub(crate) fn axis_gap<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
        &self,
        a: &A,
        na: usize,
        b: &B,
        nb: usize,
        n: &Vector3,
    ) -> Option<Real> {
        let ha = a.support_upper(na, n)?;
        let hb = b.support_upper(nb, &-(self.rot.transpose() * n))?;
        Some(n.dot(&self.shift) - hb - ha)
    }

    /// How far any point of B within `reach` meters of B's origin moved (A's frame, meters) from
    /// the relative pose `from` to this query's: `‖t − t₀‖ + ‖R − R₀‖₂·reach`, rounding included
    /// ([`FarPairs`]).
    fn displacement(&self, from: &Isometry3, reach: Real) -> Real {
        super::warm::displacement(from, &self.rel, reach)
    }

    /// The motion of B from the relative pose `from` to this query's, in A's frame: `(R − R₀, t − t₀)`
    /// and `‖R − R₀‖₂ = 2 sin(θ/2)` ([`super::warm::CutPair`]).
    fn motion_since(&self, from: &Isometry3) -> (crate::math::Matrix3, Vector3, Real) {
        let turn = self.rot - from.rotation.to_rotation_matrix().matrix();
        // 2 sin(θ/2) = 2 ‖imaginary part‖ of the unit quaternion R R₀⁻¹ (no trigonometry).
        let k = 2.0 * (self.rel.rotation * from.rotation.inverse()).imag().norm();
        (turn, self.shift - from.translation.vector, k.min(2.0))
    }
}

/// The motion of B relative to A since a kept cut's pose, and the bound of how far it moved a
/// cut pair's separating gap ([`super::warm::CutPair`]).
struct Motion {
    /// Rows of (R − R₀)ᵀ, for w = (R − R₀)ᵀ n.
    turn_t: [Vector3; 3],
    turn: crate::math::Matrix3,
    /// t − t₀.
    shift: Vector3,
    /// ‖R − R₀‖₂ = 2 sin(θ/2).
    k: Real,
    /// Rounding slack per meter of the terms.
    slack: Real,
}

impl Motion {
    fn new(cheap: &CheapBounds, from: &Isometry3) -> Self {
        let (turn, shift, k) = cheap.motion_since(from);
        let turn_t = [turn.column(0).into_owned(), turn.column(1).into_owned(), turn.column(2).into_owned()];
        Self { turn_t, turn, shift, k, slack: CHEAP_SLACK * (1.0 + shift.norm()) }
    }

    /// The bound `lower` of pair `p` (at the cut's pose) moved to this query's pose. B's node box
    /// (c, h) moved by (R − R₀)c + t − t₀ at its center; along the pair's axis n the gap moves by
    /// n·((R − R₀)c + t − t₀) = w·c + n·(t − t₀) with w = (R − R₀)ᵀn, less Σ hₖ|wₖ| for the box;
    /// without an axis, by the length (written out: this runs for every kept pair of every warm
    /// query).
    #[inline(always)]
    fn moved(&self, p: &CutPair, lower: Real) -> Real {
        let (c, h, n) = (&p.box_b.0, &p.box_b.1, &p.axis);
        let along = if n.x == 0.0 && n.y == 0.0 && n.z == 0.0 {
            -(self.turn * c + self.shift).norm() - self.k * h.norm()
        } else {
            let w = [self.turn_t[0].dot(n), self.turn_t[1].dot(n), self.turn_t[2].dot(n)];
            w[0] * c.x + w[1] * c.y + w[2] * c.z + n.dot(&self.shift)
                - (h.x * w[0].abs() + h.y * w[1].abs() + h.z * w[2].abs())
        };
        lower + along - self.slack * (p.size + lower.abs())
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
    /// The cut of this search: every terminal node pair with its lower bound (see [`Cut`]): the
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
    /// step of the motion, which sets the far group's margin ([`FAR_STEPS`]).
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
            cheap: CheapBounds::new(pose_a, pose_b),
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

    /// Records a terminal node pair of this search (see [`Cut`]).
    fn keep(&mut self, na: usize, nb: usize, lower: Real, axis: Vector3) {
        let box_b = self.b.node_box(nb).unwrap_or((Vector3::zeros(), Vector3::repeat(Real::INFINITY)));
        let size = 1.0 + box_b.0.abs().sum() + box_b.1.sum();
        self.cut.push(CutPair { a: na as u32, b: nb as u32, lower, axis, support_a: Real::NAN, box_b, size });
    }

    /// Runs the search; returns the lower bound of the pairs left in the queue (+∞ when empty).
    ///
    /// Order of work (issue 14 part 2, speed targets): (1) the previous answer's active leaf pair,
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

    /// Starts from the previous search's cut instead of the root pair, when the warm start has
    /// one for these trees: each pair's bound less the motion since ([`CutPair`]) is kept when it
    /// still reaches the threshold; else the pair's cheap bounds are evaluated again (along its
    /// axis, then [`CheapBounds::gap`]), and the pairs still below the threshold are queued.
    /// Returns false without a usable cut.
    fn resume(&mut self) -> bool {
        let Some(cut) = self.old.and_then(|w| w.cut.as_ref()) else { return false };
        if cut.nodes != (self.a.node_count(), self.b.node_count()) {
            return false;
        }
        if self.threshold() <= 0.0 && !self.decided() {
            // Overlap within the tolerance: every bound (≥ 0) decides; the root pair covers all.
            self.pruned_min = self.pruned_min.min(0.0);
            self.keep(self.a.root(), self.b.root(), 0.0, Vector3::zeros());
            return true;
        }
        let motion = Motion::new(&self.cheap, &cut.pose);
        let (nodes_a, nodes_b) = cut.nodes;
        // Constant during the loops: the upper bound only changes when a leaf pair is solved.
        let (threshold, decided) = (self.threshold(), self.decided());
        let seeded = self.seeded.map_or((usize::MAX, usize::MAX), |s| s);
        let valid = |p: &CutPair| {
            (p.a as usize) < nodes_a && (p.b as usize) < nodes_b && (p.a as usize, p.b as usize) != seeded
        };
        // The shared pairs: only their bounds are written.
        self.base_lower.reserve_exact(cut.base.len());
        for (p, &lower) in cut.base.iter().zip(&cut.lower) {
            if lower.is_nan() || !valid(p) {
                self.base_lower.push(Real::NAN);
                continue;
            }
            let bound = motion.moved(p, lower);
            if bound >= threshold || decided {
                self.base_lower.push(bound);
                self.sphere_pruned += 1;
                self.pruned_min = self.pruned_min.min(bound);
            } else {
                self.base_lower.push(Real::NAN);
                self.revisit(CutPair { lower: bound, ..*p }, threshold);
            }
        }
        self.base = Some(cut.base.clone());
        for p in &cut.extra {
            if !valid(p) {
                continue;
            }
            let bound = motion.moved(p, p.lower);
            if bound >= threshold || decided {
                self.carry(CutPair { lower: bound, ..*p });
            } else {
                self.revisit(CutPair { lower: bound, ..*p }, threshold);
            }
        }
        if let Some((c, h)) = self.b.node_box(self.b.root()) {
            self.step = self.cheap.displacement(&cut.pose, c.norm() + h.norm());
        }
        if let Some(far) = cut.far.as_ref() {
            // The group's pairs in increasing order of bound: release those whose bound less the
            // motion since the group's pose no longer decides them; the rest stay grouped.
            let moved = self.cheap.displacement(&far.pose, far.reach);
            let mut start = cut.far_start;
            let mut motion: Option<Motion> = None;
            while start < far.pairs.len() && !decided && far.pairs[start].lower - moved < threshold {
                let p = far.pairs[start];
                start += 1;
                if !valid(&p) {
                    continue;
                }
                let bound = motion.get_or_insert_with(|| Motion::new(&self.cheap, &far.pose)).moved(&p, p.lower);
                if bound >= threshold {
                    self.carry(CutPair { lower: bound, ..p });
                } else {
                    self.revisit(CutPair { lower: bound, ..p }, threshold);
                }
            }
            if start < far.pairs.len() {
                let bound = far.pairs[start].lower - moved;
                self.sphere_pruned += far.pairs.len() - start;
                self.pruned_min = self.pruned_min.min(bound);
                self.far = Some(far.clone());
                self.far_start = start;
            }
        }
        true
    }

    /// A pair of the previous cut whose moved bound (`p.lower`) no longer decides it, evaluated
    /// again at this pose: along its axis (A's support along it is kept), then by the cheap
    /// bounds; kept when it decides, else queued. (Splitting internal pairs decided by less than a
    /// step's motion, so that their children carry more margin, cost more than re-evaluating
    /// them: 3.4 against 2.6 µs median on the bench's warm motion.)
    fn revisit(&mut self, p: CutPair, threshold: Real) {
        let (na, nb) = (p.a as usize, p.b as usize);
        let mut q = p;
        if p.axis != Vector3::zeros() {
            if p.support_a.is_nan() {
                q.support_a = self.a.support_upper(na, &p.axis).unwrap_or(Real::INFINITY);
            }
            if let Some(hb) = self.b.support_upper(nb, &-(self.cheap.rot.transpose() * p.axis)) {
                let g = p.axis.dot(&self.cheap.shift) - hb - q.support_a;
                q.lower = q.lower.max(g - CHEAP_SLACK * (1.0 + g.abs() + q.support_a.abs()));
            }
        }
        if q.lower.is_nan() || q.lower < 0.0 {
            // 0 bounds the distance but not the gap along the axis (it may be negative).
            q = CutPair { lower: 0.0, axis: Vector3::zeros(), support_a: Real::NAN, ..q };
        }
        if q.lower >= threshold {
            self.carry(q);
            return;
        }
        if q.axis != Vector3::zeros() && self.is_leaf_pair(na, nb) {
            // A leaf pair near the best one: the axis refined from its own, when popped, decides
            // it better than the centers' direction.
            self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
            self.heap.push(Entry { lower: q.lower, key: q.lower, axis: q.axis, a: na, b: nb });
            return;
        }
        let mut key = q.lower;
        if let Some((g, n)) = self.cheap.gap_axis(self.a, na, self.b, nb) {
            key = g;
            if g > q.lower {
                q = CutPair { lower: g, axis: n, support_a: Real::NAN, ..q };
            }
        }
        if q.lower >= threshold {
            self.carry(q);
        } else {
            self.level = self.level.max(self.a.depth(na).max(self.b.depth(nb)));
            self.heap.push(Entry { lower: q.lower, key, axis: q.axis, a: na, b: nb });
        }
    }

    /// Keeps a pair of the previous cut whose bound still decides it.
    #[inline]
    fn carry(&mut self, p: CutPair) {
        self.sphere_pruned += 1;
        self.pruned_min = self.pruned_min.min(p.lower);
        self.cut.push(p);
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
        self.fresh.keep_distance((na, nb), r.warm_start.clone());
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

    /// The state for the next query: solver warm starts, the active pair, and the cut (when not
    /// larger than [`MAX_CUT_PAIRS`]). The previous base is shared again while the pairs added
    /// since stay few and most of its pairs are still in the cut; else every pair goes to a new
    /// base.
    fn finish(&mut self) -> TreeWarmStart {
        let mut fresh = std::mem::take(&mut self.fresh);
        let alive = self.base_lower.iter().filter(|l| !l.is_nan()).count();
        let far_len = self.far.as_ref().map_or(0, |f| f.pairs.len() - self.far_start);
        if alive + self.cut.len() + far_len > MAX_CUT_PAIRS {
            return fresh;
        }
        // A new far group when there is none, or when it released more pairs than it holds.
        if self.step.is_finite() && (self.far.is_none() || self.far_start > far_len) {
            if let Some(cut) = self.regroup(fresh.active) {
                fresh.cut = Some(cut);
                return fresh;
            }
        }
        let dead = self.base_lower.len() - alive;
        let (base, lower, extra) = match self.base.take() {
            // Folding copies every pair (a few kilobytes): only when the pairs added since the
            // last fold, or the pairs gone, outnumber the kept ones.
            Some(base) if self.cut.len() <= 32 + alive && dead <= alive => {
                (base, std::mem::take(&mut self.base_lower), std::mem::take(&mut self.cut))
            }
            old => {
                let mut pairs = Vec::with_capacity(alive + self.cut.len());
                if let Some(old) = old {
                    let kept = old.iter().zip(&self.base_lower).filter(|(_, l)| !l.is_nan());
                    pairs.extend(kept.map(|(p, &l)| CutPair { lower: l, ..*p }));
                }
                pairs.append(&mut self.cut);
                let lower = pairs.iter().map(|p| p.lower).collect();
                (std::sync::Arc::new(pairs), lower, Vec::new())
            }
        };
        fresh.cut = Some(Cut {
            base,
            lower,
            extra,
            pose: self.cheap.rel,
            nodes: (self.a.node_count(), self.b.node_count()),
            far: self.far.take(),
            far_start: self.far_start,
        });
        fresh
    }

    /// The cut of the next warm start with a new far group ([`FarPairs`]): the pairs whose bound
    /// exceeds the final threshold by more than [`FAR_STEPS`] times this step's motion (not the
    /// active pair, not a pair without a box), in increasing order of bound; the others near (a
    /// new base). The old far group's pairs take their bounds moved to this pose. `None` (the
    /// pairs stay as they are) when fewer than [`MIN_FAR_PAIRS`] would be far or the threshold
    /// is not finite.
    fn regroup(&mut self, active: Option<(usize, usize)>) -> Option<Cut> {
        let threshold = self.threshold();
        let margin = FAR_STEPS * self.step;
        if !(threshold.is_finite() && margin.is_finite()) {
            return None;
        }
        let is_far = |p: &CutPair| {
            p.lower - threshold > margin
                && p.box_b.1.iter().all(|h| h.is_finite())
                && active != Some((p.a as usize, p.b as usize))
        };
        let old_far = self.far.as_ref().map(|f| (&f.pairs[self.far_start..], Motion::new(&self.cheap, &f.pose)));
        let kept = self.base.iter().flat_map(|b| b.iter().zip(&self.base_lower)).filter(|(_, l)| !l.is_nan());
        let pairs = kept
            .map(|(p, &l)| CutPair { lower: l, ..*p })
            .chain(self.cut.iter().copied())
            .chain(old_far.iter().flat_map(|(f, m)| f.iter().map(|p| CutPair { lower: m.moved(p, p.lower), ..*p })));
        let count = pairs.clone().filter(is_far).count();
        if count < MIN_FAR_PAIRS {
            return None;
        }
        let (mut far, mut near) = (Vec::with_capacity(count), Vec::new());
        let mut reach: Real = 0.0;
        for p in pairs {
            if is_far(&p) {
                reach = reach.max(p.box_b.0.norm() + p.box_b.1.norm());
                far.push(p);
            } else {
                near.push(p);
            }
        }
        far.sort_unstable_by(|x, y| x.lower.total_cmp(&y.lower));
        let lower = near.iter().map(|p| p.lower).collect();
        let rel = self.cheap.rel;
        Some(Cut {
            base: std::sync::Arc::new(near),
            lower,
            extra: Vec::new(),
            pose: rel,
            nodes: (self.a.node_count(), self.b.node_count()),
            far: Some(std::sync::Arc::new(FarPairs { pairs: far, pose: rel, reach })),
            far_start: 0,
        })
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
