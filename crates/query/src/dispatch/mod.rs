//! How a query between two posed bodies is answered: the one place that picks the solver.
//!
//! A caller (the scene's catalog and planner) knows its queries by instance ids and keeps their
//! warm starts; this module decides, from the bodies, their poses and what is asked, which path a
//! pair takes. The decision runs in this order, cheapest first, and the first step that applies
//! answers the pair:
//!
//! ```text
//! 0. primitive pair     either side is an exact primitive (box, sphere, cylinder, capsule,
//!                       halfspace) → shapes::primitive_pair_distance: shape_distance, a compound
//!                       side searched leaf by leaf (shapes module docs); a collide query first
//!                       asks the bounding spheres (shapes::primitive_lower_bound)
//! 1. compound pair      either side is a compound body (a containment tree, paper §V)
//!                       → the branch and bound over the trees (tree::tree_distance, tree_collide,
//!                         tree_closer_than) with tree_params(mode); a single body on the other
//!                         side is a one-node tree (PosedRef::as_tree)
//! 2. cheap collide      a collide-with-margin query between two convex single bodies
//!                       → collide_lower_bound: bounding spheres (≈ 20 ns), then the separating
//!                         axis (≈ 0.14 µs); a lower bound above the margin answers "clear"
//!                       → common_point: a point inside both bodies answers "touching"
//!                       (collide_cheap; no Newton solve runs for a decided pair)
//! 3. batch lanes        cold distance and collide queries (PairAsk::lane_candidate) of one body
//!                       pair, at least `BatchSettings::min_lane_batch` of them
//!                       → batch::cold_distances: several pairs per SIMD pass (lane_distances)
//! 4. one by one         everything else: one warm-started Newton / active-set solve
//!                       (certified_distance, certified_growth), certified or with the SDP
//!                       fallback as the query's CertifyMode says
//! ```
//!
//! Steps 2 and 3 run ahead of the answers of a whole request ([`lane_distances`]): their results
//! are [`Ahead`] values by query index ([`LaneAnswers`]), which the caller hands to its per-pair
//! answer path; a pair with [`Ahead::Nothing`] takes step 4 (or, for a collide query, step 2 then
//! 4: [`Ahead::collide_route`]). A request of many candidate states (a sampling planner's batch)
//! routes each query of each state with [`state_route`]: besides the cold queries, a query whose
//! warm start would not be used (the pair moved more than half the bodies' summed scales since it
//! was last solved) takes the lanes too, asking them to keep warm starts.
//!
//! Every path answers what the plain solver answers: the lanes give [`crate::distance()`]'s cold
//! answers ([`crate::batch`]), and a cheap decision only says what a solve would say (a certified
//! lower bound above the margin, or a proven common point).

mod shapes;

pub use shapes::{
    is_primitive_pair, primitive_lower_bound, primitive_pair_distance, refusal, PairSide, ShapePairAnswer,
};

use crate::batch::cold_distances;
use crate::tree::{BodyTree, TreeQueryParams};
use crate::{CertifyMode, CertifyParams, DistanceResult, DistanceWarmStart, NewtonParams};
use sublevel_core::body::Body;
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::{Isometry3, Point3, Real};
use sublevel_core::primitive::Primitive;

/// Which query to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QueryKind {
    /// Euclidean distance between the first and the second body (eq. "distance").
    Distance,
    /// Growth measure d(first ‖ second) (eq. "overlap").
    Growth,
    /// Collide-with-margin: is the distance below the query's margin ([`PairAsk::margin`])?
    Collide,
}

/// What the dispatch reads of one query: its kind, certification mode, whether it is cold, and
/// the collide margin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairAsk {
    /// Which query.
    pub kind: QueryKind,
    /// The certification mode ([`CertifyMode::Certify`] queries never take the lanes).
    pub mode: CertifyMode,
    /// Solved cold: no warm start is read nor kept.
    pub cold: bool,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: Real,
}

impl PairAsk {
    /// Whether the query is of a kind the batch solver's lanes solve, cold or not: distance or
    /// collide outside [`CertifyMode::Certify`].
    #[inline]
    pub fn lane_kind(&self) -> bool {
        matches!(self.kind, QueryKind::Distance | QueryKind::Collide) && self.mode != CertifyMode::Certify
    }

    /// Whether the query asks for what the lanes give ([`crate::batch`]): a cold distance or
    /// collide query (no warm start to keep) outside [`CertifyMode::Certify`].
    #[inline]
    pub fn lane_candidate(&self) -> bool {
        self.lane_kind() && self.cold
    }
}

/// A body at a pose, borrowed: what the dispatch reads of one side of a pair.
#[derive(Clone, Copy, Debug)]
pub struct PosedRef<'p> {
    /// The body; a compound body's root body (which contains every node's body). For a primitive,
    /// a body that contains it (its bounding ellipsoid) — a stand-in for a halfspace, which no
    /// body contains — read by no step: a primitive pair takes step 0.
    pub body: &'p Body,
    /// A compound body's containment tree; `None` for a single body.
    pub tree: Option<&'p CompoundBody>,
    /// An exact primitive: the side is this set, not `body` (step 0); `None` for a fitted body.
    pub primitive: Option<&'p Primitive>,
    /// The pose (body frame → world).
    pub pose: Isometry3,
}

impl<'p> PosedRef<'p> {
    /// The body as a containment tree: a compound body's tree, or a single body as a one-node
    /// tree.
    #[inline]
    pub fn as_tree(&self) -> &'p dyn BodyTree {
        match self.tree {
            Some(t) => t,
            None => self.body,
        }
    }

    /// A single body with proven bounds (not compound, not nonconvex): the only kind the cheap
    /// collide tests and the lanes take.
    #[inline]
    fn single_convex(&self) -> bool {
        self.tree.is_none() && self.primitive.is_none() && !self.body.report.nonconvex
    }
}

/// Whether a query between `a` and `b` goes to the tree queries (step 1: either side is
/// compound, and neither is a primitive, which takes step 0).
#[inline]
pub fn is_compound_pair(a: &PosedRef<'_>, b: &PosedRef<'_>) -> bool {
    (a.tree.is_some() || b.tree.is_some()) && !is_primitive_pair(a, b)
}

/// The tree-query settings of a compound pair's query in `mode` with distance tolerance
/// `tolerance` (meters; a negative or non-finite tolerance counts as 0). [`CertifyMode::Certify`]
/// certifies every leaf pair; [`CertifyMode::NewtonOnly`] solves no SDP, so a leaf pair Newton
/// does not resolve stays unresolved and the answer says it needs the SDP.
pub fn tree_params(params: &CertifyParams, mode: CertifyMode, tolerance: Real) -> TreeQueryParams {
    TreeQueryParams {
        newton: params.newton,
        certificate: params.certificate,
        certify: if mode == CertifyMode::Certify { CertifyMode::Certify } else { CertifyMode::Newton },
        sdp_fallback: mode != CertifyMode::NewtonOnly,
        tolerance: if tolerance.is_finite() && tolerance >= 0.0 { tolerance } else { 0.0 },
        ..TreeQueryParams::default()
    }
}

/// Lower bound of the distance between two posed bodies from their bounding spheres (0 when the
/// spheres overlap), or `None` when a body has no proven bound (nonconvex).
pub fn sphere_lower_bound(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Real> {
    let (ca, ra) = a.bounding_sphere()?;
    let (cb, rb) = b.bounding_sphere()?;
    Some(((pose_a * ca) - (pose_b * cb)).norm() - ra - rb).map(|d| d.max(0.0))
}

/// A certified lower bound of the distance between two posed convex single bodies (meters), the
/// cheapest test first: the bounding spheres' gap ([`sphere_lower_bound`], about 20 ns); when that
/// does not exceed `margin`, the larger of it and the separating-axis gap along the line between
/// the bodies' box centers ([`crate::tree::axis_lower_bound`], about 0.14 µs, from their
/// certified support bounds). A collide query whose bound exceeds its margin is answered "clear"
/// with no solve. `None` when a body has no proven bound (nonconvex).
///
/// On the 300 cold chair_101 / human_10 poses of `sublevel-lab bench` at 2d = 6 and margin 0, the
/// spheres decide 161 pairs and the axis 104 of the 139 others, leaving 35 distance solves (22
/// of them overlapping pairs) instead of 139.
pub fn collide_lower_bound(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3, margin: Real) -> Option<Real> {
    let spheres = sphere_lower_bound(a, pose_a, b, pose_b)?;
    if spheres > margin {
        return Some(spheres);
    }
    Some(crate::tree::axis_lower_bound(a, pose_a, b, pose_b).map_or(spheres, |axis| axis.max(spheres)))
}

/// A scene check's cheap lower bound of a candidate pair's distance (meters), before any solve:
/// [`collide_lower_bound`] for two single bodies, the root bodies' bounding spheres
/// ([`sphere_lower_bound`]) when either is compound, the bounding spheres of
/// [`primitive_lower_bound`] when either is a primitive; `None` when a side has no proven bound
/// (nonconvex, a halfspace: the pair is always solved).
pub fn pair_lower_bound(a: &PosedRef<'_>, b: &PosedRef<'_>, margin: Real) -> Option<Real> {
    if is_primitive_pair(a, b) {
        primitive_lower_bound(a, b)
    } else if is_compound_pair(a, b) {
        sphere_lower_bound(a.body, &a.pose, b.body, &b.pose)
    } else {
        collide_lower_bound(a.body, &a.pose, b.body, &b.pose, margin)
    }
}

/// What the cheap tests decide of a collide query between two posed convex single bodies, before
/// any solve ([`collide_cheap`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CheapCollide {
    /// Clear of the margin: a certified lower bound of the distance above it (meters,
    /// [`collide_lower_bound`]).
    Clear(Real),
    /// Overlapping: a point of both bodies (world, meters; [`crate::common_point`]) proves
    /// distance 0.
    Touching(Point3),
}

/// The collide query's cheap tests (step 2), cheapest first: the lower bounds
/// ([`collide_lower_bound`]), which clear a pair farther apart than `margin`; then, for a pair they
/// do not clear, a common point of the two bodies on the segment between their interior points or
/// at their facing support points ([`crate::common_point`]), which proves overlap. `None` when
/// neither decides (a distance solve does), or when a body has no proven bound (nonconvex).
///
/// On the 300 cold chair_101 / human_10 poses of `sublevel-lab bench` at 2d = 6 and margin 0, the
/// bounds leave 35 pairs, 22 of them overlapping; the common point decides most of those, whose
/// solves (a failed separated run, then the growth measure) cost the most.
pub fn collide_cheap(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3, margin: Real) -> Option<CheapCollide> {
    let lower = collide_lower_bound(a, pose_a, b, pose_b, margin)?;
    if lower > margin {
        return Some(CheapCollide::Clear(lower));
    }
    crate::common_point(a, pose_a, b, pose_b).map(CheapCollide::Touching)
}

/// What [`lane_distances`] settled of a query ahead of its answer.
#[derive(Clone, Debug, Default)]
pub enum Ahead {
    /// Nothing: the query is answered from scratch (step 4; a collide query tries the cheap tests
    /// first, [`Ahead::collide_route`]).
    #[default]
    Nothing,
    /// Newton's answer of a distance or collide query, solved on the batch solver's lanes
    /// ([`crate::batch::cold_distances`]; a collide query only when the cheap tests did not
    /// decide it, [`collide_cheap`]).
    Newton(DistanceResult),
    /// A collide query the cheap tests decided ([`collide_cheap`]): clear (a certified lower bound
    /// of the distance above the query's margin) or touching (a common point).
    Cheap(CheapCollide),
}

/// How a collide query between two single bodies goes on ([`Ahead::collide_route`]).
#[derive(Clone, Debug)]
pub enum CollideRoute {
    /// The cheap tests decided it: no solve.
    Decided(CheapCollide),
    /// A distance solve decides it: Newton's answer from the lanes when they gave one (to be
    /// certified as the query's mode says), else `None` (solve it one by one).
    Solve(Option<DistanceResult>),
}

impl Ahead {
    /// Newton's answer, if the lanes solved it.
    #[inline]
    pub fn into_newton(self) -> Option<DistanceResult> {
        match self {
            Ahead::Newton(answer) => Some(answer),
            _ => None,
        }
    }

    /// The route of a collide query between the single bodies `a` and `b` with margin `margin`
    /// (meters), given what was settled ahead: the cheap tests' decision (taken from `self`, else
    /// asked here, [`collide_cheap`]), or the distance solve with the lanes' Newton answer if any.
    pub fn collide_route(self, a: &PosedRef<'_>, b: &PosedRef<'_>, margin: Real) -> CollideRoute {
        match self {
            Ahead::Cheap(decided) => CollideRoute::Decided(decided),
            Ahead::Newton(answer) => CollideRoute::Solve(Some(answer)),
            Ahead::Nothing => match collide_cheap(a.body, &a.pose, b.body, &b.pose, margin) {
                Some(decided) => CollideRoute::Decided(decided),
                None => CollideRoute::Solve(None),
            },
        }
    }
}

/// What was settled ahead of the answers ([`lane_distances`]), by query index; empty when nothing
/// was (no allocation on the paths that have no cold queries).
#[derive(Debug, Default)]
pub struct LaneAnswers(Vec<Ahead>);

impl LaneAnswers {
    /// What was settled of query `k` (taken out; [`Ahead::Nothing`] when nothing was).
    #[inline]
    pub fn take(&mut self, k: usize) -> Ahead {
        self.0.get_mut(k).map(std::mem::take).unwrap_or_default()
    }

    /// Records `ahead` for query `k` of `n`.
    fn set(&mut self, n: usize, k: usize, ahead: Ahead) {
        if self.0.is_empty() {
            self.0 = vec![Ahead::Nothing; n];
        }
        self.0[k] = ahead;
    }
}

/// Where a [`PairAsk::lane_candidate`] between two convex single bodies goes ahead of its answer
/// ([`lane_role`]).
enum LaneRole {
    /// The batch solver's lanes (step 3).
    Lanes,
    /// A collide query the cheap tests decide (step 2, [`collide_cheap`]).
    Cheap(CheapCollide),
}

/// Where a query goes ahead of its answer ([`LaneRole`]); `None` for queries answered one by one
/// (not a [`PairAsk::lane_candidate`], or a body that is compound or nonconvex).
fn lane_role(ask: &PairAsk, a: &PosedRef<'_>, b: &PosedRef<'_>) -> Option<LaneRole> {
    if !(ask.lane_candidate() && a.single_convex() && b.single_convex()) {
        return None;
    }
    let cheap =
        (ask.kind == QueryKind::Collide).then(|| collide_cheap(a.body, &a.pose, b.body, &b.pose, ask.margin)).flatten();
    Some(cheap.map_or(LaneRole::Lanes, LaneRole::Cheap))
}

/// Whether at least `min_lane_batch` ([`crate::BatchSettings::min_lane_batch`]) of `asks` are
/// [`PairAsk::lane_candidate`]s: otherwise no
/// group can reach the lanes and nothing need be gathered.
pub fn enough_lane_candidates(asks: impl Iterator<Item = PairAsk>, min_lane_batch: usize) -> bool {
    asks.filter(PairAsk::lane_candidate).nth(min_lane_batch.max(1) - 1).is_some()
}

/// Steps 2 and 3 of the module docs ahead of a request's answers: Newton's answers of the cold
/// distance solves among the queries `asks` (query k between the two bodies `posed(k)`, `None`
/// to leave it out) that can take the batch solver's lanes, solved several pairs per SIMD pass
/// ([`cold_distances`], with `newton`; each answer with its own warm start when `warm_starts`) in
/// groups of one body pair (the same two [`Body`] values, by address), and the decisions of the
/// collide queries among them that the cheap tests decide ([`collide_cheap`], asked once here,
/// not again per answer). Nothing for the other queries and for groups smaller than
/// `newton.batch.min_lane_batch` (answered one by one).
pub fn lane_distances<'p>(
    asks: impl ExactSizeIterator<Item = PairAsk> + Clone,
    posed: impl Fn(usize) -> Option<(PosedRef<'p>, PosedRef<'p>)>,
    newton: &NewtonParams,
    warm_starts: bool,
) -> LaneAnswers {
    if !enough_lane_candidates(asks.clone(), newton.batch.min_lane_batch) {
        return LaneAnswers::default();
    }
    let n = asks.len();
    let mut out = LaneAnswers::default();
    // The lane queries by body pair (the bodies' addresses), then by index: sorted, each group is
    // one run, in query order.
    let mut lanes: Vec<((usize, usize), usize)> = Vec::new();
    for (k, ask) in asks.enumerate() {
        let Some((a, b)) = posed(k) else { continue };
        match lane_role(&ask, &a, &b) {
            Some(LaneRole::Lanes) => {
                lanes.push(((std::ptr::from_ref(a.body).addr(), std::ptr::from_ref(b.body).addr()), k));
            }
            Some(LaneRole::Cheap(decided)) => out.set(n, k, Ahead::Cheap(decided)),
            None => {}
        }
    }
    lanes.sort_unstable();
    for members in lanes.chunk_by(|x, y| x.0 == y.0).filter(|m| m.len() >= newton.batch.min_lane_batch) {
        let Some((a, b)) = posed(members[0].1) else { continue };
        let poses: Vec<(Isometry3, Isometry3)> =
            members.iter().filter_map(|&(_, k)| posed(k).map(|(a, b)| (a.pose, b.pose))).collect();
        if poses.len() != members.len() {
            continue;
        }
        for (&(_, k), answer) in members.iter().zip(cold_distances(a.body, b.body, &poses, newton, warm_starts)) {
            out.set(n, k, Ahead::Newton(answer));
        }
    }
    out
}

/// How one query of one candidate state is routed ([`state_route`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StateRoute {
    /// Answered one by one (warm-started when it is not cold).
    One,
    /// A cold query: a lane candidate as it is.
    Cold,
    /// A warm query whose warm start would not be used: on the lanes like a cold query, which
    /// then keep its warm start for the caller's cache.
    Far,
}

/// The route of query `ask` in one candidate state of a request: [`StateRoute::Cold`] for a lane
/// candidate; [`StateRoute::Far`] for a distance or collide query (outside
/// [`CertifyMode::Certify`]) between `pair = (a, b, rel)` (`rel` = a.pose⁻¹ · b.pose) whose warm
/// start would not reach the new relative pose ([`crate::warm_start_reaches_with`]: from
/// `before`, the pair's relative pose in the state before; in the first state, from the pair's
/// cached warm start `cached()`, asked only then) — the pair moved more than
/// [`NewtonParams::warm_reach`] of `params` (default half the bodies' summed scales), as between
/// a sampling planner's random candidates; else [`StateRoute::One`] (also without `pair`: the
/// query names no posed pair).
pub fn state_route<'w>(
    ask: &PairAsk,
    pair: Option<(&PosedRef<'_>, &PosedRef<'_>, &Isometry3)>,
    before: Option<&Isometry3>,
    cached: impl FnOnce() -> Option<&'w DistanceWarmStart>,
    params: &NewtonParams,
) -> StateRoute {
    if ask.lane_candidate() {
        return StateRoute::Cold;
    }
    if !ask.lane_kind() || pair.is_some_and(|(a, b, _)| is_primitive_pair(a, b)) {
        return StateRoute::One;
    }
    let far = match (pair, before) {
        (Some((a, b, rel)), Some(prev)) => !crate::warm_start_reaches_with(a.body, b.body, prev, rel, params),
        (Some((a, b, rel)), None) => !cached().is_some_and(|w| w.reaches_with(a.body, b.body, rel, params)),
        (None, _) => false,
    };
    if far {
        StateRoute::Far
    } else {
        StateRoute::One
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::MIN_LANE_BATCH;
    use sublevel_core::body::ellipsoid;
    use sublevel_core::math::Vector3;

    fn ask(kind: QueryKind, mode: CertifyMode, cold: bool) -> PairAsk {
        PairAsk { kind, mode, cold, margin: 0.0 }
    }

    fn at(body: &Body, x: Real) -> PosedRef<'_> {
        PosedRef { body, tree: None, primitive: None, pose: Isometry3::translation(x, 0.0, 0.0) }
    }

    /// Only cold distance and collide queries outside `Certify` are lane candidates.
    #[test]
    fn lane_candidates_are_cold_distance_and_collide_queries_outside_certify() {
        use CertifyMode::*;
        use QueryKind::*;
        assert!(ask(Distance, Newton, true).lane_candidate());
        assert!(ask(Collide, NewtonOnly, true).lane_candidate());
        assert!(!ask(Distance, Newton, false).lane_candidate());
        assert!(ask(Distance, Newton, false).lane_kind());
        assert!(!ask(Distance, Certify, true).lane_kind());
        assert!(!ask(Growth, Newton, true).lane_kind());
        let three = [ask(Distance, Newton, true); 3];
        assert!(!enough_lane_candidates(three.into_iter(), MIN_LANE_BATCH));
        assert!(enough_lane_candidates(three.into_iter().chain([ask(Collide, Newton, true)]), MIN_LANE_BATCH));
    }

    /// Two spheres r = 0.5: far apart the cheap bound clears a collide query (a lower bound of the
    /// 2 m gap above the margin); overlapping, a common point proves the touch; 0.5 m apart with a
    /// 1 m margin, a solve decides.
    #[test]
    fn the_cheap_tests_clear_far_pairs_and_prove_overlap() {
        let s = ellipsoid([0.0; 3], [0.5; 3]).unwrap();
        let (a, far, near) = (at(&s, 0.0), at(&s, 3.0), at(&s, 0.8));
        match collide_cheap(a.body, &a.pose, far.body, &far.pose, 0.1) {
            Some(CheapCollide::Clear(lower)) => assert!(lower > 0.1 && lower <= 2.0 + 1e-12, "{lower}"),
            other => panic!("expected clear, got {other:?}"),
        }
        assert!(matches!(collide_cheap(a.body, &a.pose, near.body, &near.pose, 0.0), Some(CheapCollide::Touching(_))));
        let touching = Ahead::Nothing.collide_route(&a, &near, 0.0);
        assert!(matches!(touching, CollideRoute::Decided(CheapCollide::Touching(_))));
        // 0.5 m apart with a 1 m margin: neither clear nor overlapping.
        let gap = at(&s, 1.5);
        assert!(collide_cheap(a.body, &a.pose, gap.body, &gap.pose, 1.0).is_none());
        assert!(matches!(Ahead::Nothing.collide_route(&a, &gap, 1.0), CollideRoute::Solve(None)));
        assert_eq!(pair_lower_bound(&a, &far, 0.1), collide_lower_bound(a.body, &a.pose, far.body, &far.pose, 0.1));
    }

    /// Cold distance queries of one body pair take the lanes in groups of at least
    /// `MIN_LANE_BATCH` and give the plain solver's cold answers; a smaller group, a warm query
    /// and a growth query are left to the caller; a collide query the cheap tests decide is
    /// settled as such.
    #[test]
    fn lane_distances_groups_cold_queries_by_body_pair() {
        let (big, small) = (ellipsoid([0.0; 3], [0.5; 3]).unwrap(), ellipsoid([0.0; 3], [0.25; 3]).unwrap());
        let other = ellipsoid([0.0; 3], [0.3, 0.2, 0.4]).unwrap();
        let params = NewtonParams::default();
        let cold = ask(QueryKind::Distance, CertifyMode::Newton, true);
        // Queries 0..5: big–small (lanes); 5, 6: big–other (too few); 7 warm; 8 growth; 9 a far
        // collide query.
        let mut asks = vec![cold; 7];
        asks.push(PairAsk { cold: false, ..cold });
        asks.push(PairAsk { kind: QueryKind::Growth, ..cold });
        asks.push(PairAsk { kind: QueryKind::Collide, ..cold });
        let xs: Vec<Real> = (0..asks.len()).map(|k| 1.0 + 0.2 * k as Real).collect();
        let posed = |k: usize| {
            let second = if k == 5 || k == 6 { &other } else { &small };
            Some((at(&big, 0.0), PosedRef { pose: Isometry3::translation(xs[k], 0.1, 0.0), ..at(second, 0.0) }))
        };
        let mut out = lane_distances(asks.iter().copied(), posed, &params, false);
        for (k, x) in xs.iter().enumerate().take(5) {
            let Ahead::Newton(d) = out.take(k) else { panic!("query {k} did not take the lanes") };
            let (a, b) = posed(k).unwrap();
            let want = crate::distance(a.body, &a.pose, b.body, &b.pose, None, &params);
            assert!((d.distance - want.distance).abs() < 1e-9, "{k}: {} vs {}", d.distance, want.distance);
            let gap = Vector3::new(*x, 0.1, 0.0).norm() - 0.75;
            assert!((d.distance - gap).abs() < 1e-9, "{k}: {} vs {gap}", d.distance);
        }
        for k in 5..9 {
            assert!(matches!(out.take(k), Ahead::Nothing), "query {k}");
        }
        assert!(matches!(out.take(9), Ahead::Cheap(CheapCollide::Clear(_))));
        assert!(matches!(out.take(9), Ahead::Nothing), "taken out");
        // Fewer than MIN_LANE_BATCH candidates: nothing at all.
        let mut none = lane_distances(asks[..3].iter().copied(), posed, &params, false);
        assert!((0..3).all(|k| matches!(none.take(k), Ahead::Nothing)));
    }

    /// A warm query of a candidate state takes the lanes only when its warm start is out of
    /// reach: far from the state before, or (first state) from the cached warm start.
    #[test]
    fn a_warm_state_query_takes_the_lanes_only_out_of_reach() {
        let (big, small) = (ellipsoid([0.0; 3], [0.5; 3]).unwrap(), ellipsoid([0.0; 3], [0.25; 3]).unwrap());
        let warm = ask(QueryKind::Distance, CertifyMode::Newton, false);
        let (a, b) = (at(&big, 0.0), at(&small, 1.5));
        let rel = a.pose.inv_mul(&b.pose);
        let near = Isometry3::translation(1.45, 0.0, 0.0);
        let far = Isometry3::translation(3.0, 1.0, 0.0);
        assert_eq!(
            state_route(&warm, Some((&a, &b, &rel)), Some(&near), || None, &NewtonParams::DEFAULT),
            StateRoute::One
        );
        assert_eq!(
            state_route(&warm, Some((&a, &b, &rel)), Some(&far), || None, &NewtonParams::DEFAULT),
            StateRoute::Far
        );
        assert_eq!(state_route(&warm, Some((&a, &b, &rel)), None, || None, &NewtonParams::DEFAULT), StateRoute::Far);
        let d = crate::distance(&big, &Isometry3::identity(), &small, &near, None, &NewtonParams::default());
        assert_eq!(
            state_route(&warm, Some((&a, &b, &rel)), None, || Some(&*d.warm_start), &NewtonParams::DEFAULT),
            StateRoute::One
        );
        assert_eq!(state_route(&warm, None, None, || None, &NewtonParams::DEFAULT), StateRoute::One);
        assert_eq!(
            state_route(&PairAsk { cold: true, ..warm }, None, None, || None, &NewtonParams::DEFAULT),
            StateRoute::Cold
        );
        // The caller's warm reach decides: at 3 (instead of 0.5) summed scales (0.75 m here) the
        // 1.8 m step from `far` is within reach.
        let reach = NewtonParams { warm_reach: 3.0, ..NewtonParams::DEFAULT };
        assert_eq!(state_route(&warm, Some((&a, &b, &rel)), Some(&far), || None, &reach), StateRoute::One);
        let certify = PairAsk { mode: CertifyMode::Certify, ..warm };
        assert_eq!(
            state_route(&certify, Some((&a, &b, &rel)), Some(&far), || None, &NewtonParams::DEFAULT),
            StateRoute::One
        );
    }
}
