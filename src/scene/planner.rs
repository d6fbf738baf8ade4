//! What a motion planner asks of a scene: queries on a private view of it, many candidate states
//! per call, collide-with-margin tests decided as cheaply as possible, and scene-wide checks with
//! a broad phase.
//!
//! ```text
//! QueryView      the stored scene + this client's pose overrides + this client's warm starts
//!   run(request) = apply its pose updates (all or nothing), then answer its queries — once, or
//!                  once per candidate state (the state's poses on top, dropped afterwards)
//! collide(a, b, m) = bounding spheres farther apart than m → false, no solve (a few ns)
//!                    otherwise the distance solve (warm-started): distance < m or overlapping
//! check_scene    posed bounding boxes grown by m/2 → BVH (parry) → candidate pairs
//!                → bounding spheres → distance solves → pairs closer than m, by distance
//! ```
//!
//! Nothing here takes a scene's lock while solving: the instances a request names are read (a
//! body `Arc` and a pose each) under the lock, then every solve runs on that snapshot.

use super::cache::WarmStartCache;
use super::catalog::{Catalog, DistanceReply, GrowthReply, PairRef, QueryAnswer, QueryKind, QueryOptions, QueryPair};
use crate::body::Body;
use crate::math::{Isometry3, Real};
use crate::query::{
    certified_distance, certified_growth, certify_newton_distance, distance_gradient, growth_gradient, AnswerSource,
    CertifyMode, CertifyParams,
};
use crate::{Error, Result};
use std::collections::HashMap;
use std::sync::Arc;

/// The answer of a collide-with-margin query.
#[derive(Clone, Debug)]
pub struct CollideReply {
    /// True when the bodies overlap or their distance is below `margin`.
    pub collides: bool,
    /// The solved distance (meters), or with `decided_by_bounds` a certified lower bound
    /// ([`collide_lower_bound`]: the bounding spheres, then the separating axis) when clear, and 0
    /// when a common point proved overlap ([`collide_cheap`]).
    pub distance: Real,
    /// The cheap tests decided ([`collide_cheap`]: the bounding spheres or the separating axis
    /// cleared the margin, or a common point proved overlap): no solve ran.
    pub decided_by_bounds: bool,
    /// The distance solve, when one ran.
    pub solve: Option<DistanceReply>,
    /// The margin asked for (meters).
    pub margin: Real,
    /// Compound pairs: the tree query's bounds, level and cost (`distance` is then the deciding
    /// bound of [`crate::query::tree::TreeMarginResult`]; `solve` is `None`).
    pub tree: Option<super::catalog::TreeInfo>,
}

/// A posed instance of a request's snapshot: its body and its pose in this view.
#[derive(Clone, Debug)]
pub struct Posed {
    /// The body (shared with the catalog); a compound body's root body.
    pub body: Arc<Body>,
    /// A compound body's containment tree (`None` for a single body): queries involving it run
    /// the tree queries ([`super::compound_pairs`]).
    pub tree: Option<Arc<crate::compound::CompoundBody>>,
    /// The pose in this view (body frame → world).
    pub pose: Isometry3,
}

impl Posed {
    /// This instance borrowed, at its pose.
    #[inline]
    pub(crate) fn borrowed(&self) -> PosedRef<'_> {
        PosedRef { body: &self.body, tree: self.tree.as_ref(), pose: self.pose }
    }
}

/// A [`Posed`] borrowed, at a pose of its own (a candidate state's): what the batch solver's lanes
/// read, with no reference count touched.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PosedRef<'p> {
    /// The body.
    body: &'p Arc<Body>,
    /// A compound body's containment tree.
    tree: Option<&'p Arc<crate::compound::CompoundBody>>,
    /// The pose (body frame → world).
    pose: Isometry3,
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
/// the bodies' box centers ([`crate::query::tree::axis_lower_bound`], about 0.14 µs, from their
/// certified support bounds). A collide query whose bound exceeds its margin is answered "clear"
/// with no solve (`decided_by_bounds`). `None` when a body has no proven bound (nonconvex).
///
/// On the 300 cold chair_101 / human_10 poses of `sublevel bench` at 2d = 6 and margin 0, the
/// spheres decide 161 pairs and the axis 104 of the 139 others, leaving 35 distance solves (22
/// of them overlapping pairs) instead of 139.
pub fn collide_lower_bound(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3, margin: Real) -> Option<Real> {
    let spheres = sphere_lower_bound(a, pose_a, b, pose_b)?;
    if spheres > margin {
        return Some(spheres);
    }
    Some(crate::query::tree::axis_lower_bound(a, pose_a, b, pose_b).map_or(spheres, |axis| axis.max(spheres)))
}

/// What the cheap tests decide of a collide query between two posed convex single bodies, before
/// any solve ([`collide_cheap`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CheapCollide {
    /// Clear of the margin: a certified lower bound of the distance above it (meters,
    /// [`collide_lower_bound`]).
    Clear(Real),
    /// Overlapping: a point of both bodies (world, meters; [`crate::query::common_point`]) proves
    /// distance 0.
    Touching(crate::math::Point3),
}

/// The collide query's cheap tests, cheapest first: the lower bounds ([`collide_lower_bound`]),
/// which clear a pair farther apart than `margin`; then, for a pair they do not clear, a common
/// point of the two bodies on the segment between their interior points or at their facing support
/// points ([`crate::query::common_point`]), which proves overlap. `None` when neither decides
/// (a distance solve does), or when a body has no proven bound (nonconvex).
///
/// On the 300 cold chair_101 / human_10 poses of `sublevel bench` at 2d = 6 and margin 0, the
/// bounds leave 35 pairs, 22 of them overlapping; the common point decides most of those, whose
/// solves (a failed separated run, then the growth measure) cost the most.
pub fn collide_cheap(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3, margin: Real) -> Option<CheapCollide> {
    let lower = collide_lower_bound(a, pose_a, b, pose_b, margin)?;
    if lower > margin {
        return Some(CheapCollide::Clear(lower));
    }
    crate::query::common_point(a, pose_a, b, pose_b).map(CheapCollide::Touching)
}

/// Answers one query between two posed instances with the given warm-start cache (ids key it);
/// `options.cold` ignores and leaves no warm start. The core of [`Catalog::batch`] and of
/// [`QueryView::run`].
pub fn answer_pair(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
) -> QueryAnswer {
    answer_pair_with(pair, a, b, cache, params, Ahead::Nothing)
}

/// Whether a query asks for what the batch solver's SIMD lanes give ([`crate::query::batch`]): a
/// cold distance or collide query (no warm start to keep) outside [`CertifyMode::Certify`].
fn lane_candidate(kind: QueryKind, options: &QueryOptions) -> bool {
    lane_kind(kind, options) && options.cold
}

/// Whether a query is of a kind the lanes solve, cold or not: distance or collide outside
/// [`CertifyMode::Certify`].
fn lane_kind(kind: QueryKind, options: &QueryOptions) -> bool {
    matches!(kind, QueryKind::Distance | QueryKind::Collide) && options.mode != CertifyMode::Certify
}

/// Where a [`lane_candidate`] between two convex single bodies goes ahead of
/// [`answer_pair_with`] ([`lane_role`]).
enum LaneRole {
    /// The batch solver's lanes.
    Lanes,
    /// A collide query the cheap tests decide ([`collide_cheap`]).
    Cheap(CheapCollide),
}

/// Where a query goes ahead of [`answer_pair_with`] ([`LaneRole`]); `None` for queries answered
/// one by one (not a [`lane_candidate`], or a body that is compound or nonconvex).
fn lane_role(pair: &PairRef<'_>, a: &PosedRef<'_>, b: &PosedRef<'_>) -> Option<LaneRole> {
    let single_convex = |p: &PosedRef<'_>| p.tree.is_none() && !p.body.report.nonconvex;
    if !(lane_candidate(pair.kind, &pair.options) && single_convex(a) && single_convex(b)) {
        return None;
    }
    let cheap = (pair.kind == QueryKind::Collide)
        .then(|| collide_cheap(a.body, &a.pose, b.body, &b.pose, pair.margin))
        .flatten();
    Some(cheap.map_or(LaneRole::Lanes, LaneRole::Cheap))
}

/// Whether at least [`crate::query::batch::MIN_LANE_BATCH`] of `queries` are
/// [`lane_candidate`]s: otherwise no group can reach the lanes and nothing need be gathered.
fn enough_lane_candidates<'q>(queries: impl Iterator<Item = (QueryKind, &'q QueryOptions)>) -> bool {
    queries.filter(|(kind, o)| lane_candidate(*kind, o)).nth(crate::query::batch::MIN_LANE_BATCH - 1).is_some()
}

/// What [`lane_distances`] settled of a query ahead of [`answer_pair_with`].
#[derive(Clone, Debug, Default)]
pub enum Ahead {
    /// Nothing: [`answer_pair_with`] answers the query from scratch.
    #[default]
    Nothing,
    /// Newton's answer of a cold distance or collide query, solved on the batch solver's lanes
    /// ([`crate::query::batch::cold_distances`]; a collide query only when the cheap tests did not
    /// decide it, [`collide_cheap`]).
    Newton(crate::query::DistanceResult),
    /// A collide query the cheap tests decided ([`collide_cheap`]): clear (a certified lower bound
    /// of the distance above the query's margin) or touching (a common point).
    Cheap(CheapCollide),
}

impl Ahead {
    /// Newton's answer, if the lanes solved it.
    fn into_newton(self) -> Option<crate::query::DistanceResult> {
        match self {
            Ahead::Newton(answer) => Some(answer),
            _ => None,
        }
    }
}

/// What was settled ahead of the answers ([`lane_distances`]), by query index; empty when nothing
/// was (no allocation on the paths that have no cold queries).
#[derive(Default)]
pub(crate) struct LaneAnswers(Vec<Ahead>);

impl LaneAnswers {
    /// What was settled of query `k` (taken out).
    pub(crate) fn take(&mut self, k: usize) -> Ahead {
        self.0.get_mut(k).map(std::mem::take).unwrap_or_default()
    }
}

/// Newton's answers of the cold distance solves among `pairs` (each with its two posed instances
/// from `posed`) that can take the batch solver's lanes ([`lane_role`]), solved several pairs per
/// SIMD pass ([`crate::query::batch::cold_distances`]) in groups of one body pair, and the
/// decisions of the collide queries among them that the cheap tests decide ([`collide_cheap`],
/// asked once here, not again per answer); nothing for the other queries and for groups smaller than
/// [`crate::query::batch::MIN_LANE_BATCH`] (answered one by one by [`answer_pair`]). Give them to
/// [`answer_pair_with`].
pub(crate) fn lane_distances<'p>(
    pairs: &[PairRef<'_>],
    posed: impl Fn(usize) -> Option<(PosedRef<'p>, PosedRef<'p>)>,
    params: &CertifyParams,
    warm_starts: bool,
) -> LaneAnswers {
    use crate::query::batch::{cold_distances, MIN_LANE_BATCH};
    if !enough_lane_candidates(pairs.iter().map(|p| (p.kind, &p.options))) {
        return LaneAnswers::default();
    }
    // Eligible queries by body pair (the bodies' addresses), in order within each group.
    let mut groups: HashMap<(*const crate::Body, *const crate::Body), Vec<usize>, foldhash::fast::RandomState> =
        HashMap::default();
    let mut out = LaneAnswers::default();
    for (k, pair) in pairs.iter().enumerate() {
        let Some((a, b)) = posed(k) else { continue };
        match lane_role(pair, &a, &b) {
            Some(LaneRole::Lanes) => groups.entry((Arc::as_ptr(a.body), Arc::as_ptr(b.body))).or_default().push(k),
            Some(LaneRole::Cheap(decided)) => {
                if out.0.is_empty() {
                    out.0 = vec![Ahead::Nothing; pairs.len()];
                }
                out.0[k] = Ahead::Cheap(decided);
            }
            None => {}
        }
    }
    for members in groups.values().filter(|m| m.len() >= MIN_LANE_BATCH) {
        let Some((a, b)) = posed(members[0]) else { continue };
        let poses: Vec<(Isometry3, Isometry3)> =
            members.iter().filter_map(|&k| posed(k).map(|(a, b)| (a.pose, b.pose))).collect();
        if poses.len() != members.len() {
            continue;
        }
        if out.0.is_empty() {
            out.0 = vec![Ahead::Nothing; pairs.len()];
        }
        for (&k, answer) in members.iter().zip(cold_distances(a.body, b.body, &poses, &params.newton, warm_starts)) {
            out.0[k] = Ahead::Newton(answer);
        }
    }
    out
}

/// [`answer_pair`] with what [`lane_distances`] settled ahead ([`Ahead`]: Newton's answer of a
/// distance or collide query, or a collide query's cheap decision); [`Ahead::Nothing`] answers it
/// here from scratch.
pub fn answer_pair_with(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
    ahead: Ahead,
) -> QueryAnswer {
    if super::compound_pairs::is_compound_pair(a, b) {
        use super::compound_pairs as cp;
        return match pair.kind {
            QueryKind::Distance => QueryAnswer::Distance(cp::distance_reply(pair, a, b, cache, params)),
            QueryKind::Growth => QueryAnswer::Growth(cp::growth_reply(pair, a, b, cache, params)),
            QueryKind::Collide => QueryAnswer::Collide(cp::collide_reply(pair, a, b, cache, params)),
        };
    }
    match pair.kind {
        QueryKind::Distance => QueryAnswer::Distance(distance_reply(pair, a, b, cache, params, ahead.into_newton())),
        QueryKind::Growth => QueryAnswer::Growth(growth_reply(pair, a, b, cache, params)),
        QueryKind::Collide => {
            // The cheap tests, unless asked ahead: the lanes took only what they did not decide.
            let (cheap, newton) = match ahead {
                Ahead::Cheap(decided) => (Some(decided), None),
                Ahead::Newton(answer) => (None, Some(answer)),
                Ahead::Nothing => (collide_cheap(&a.body, &a.pose, &b.body, &b.pose, pair.margin), None),
            };
            if let Some(decided) = cheap {
                let (collides, distance) = match decided {
                    CheapCollide::Clear(lower) => (false, lower),
                    CheapCollide::Touching(_) => (true, 0.0),
                };
                return QueryAnswer::Collide(CollideReply {
                    collides,
                    distance,
                    decided_by_bounds: true,
                    solve: None,
                    margin: pair.margin,
                    tree: None,
                });
            }
            let d = distance_reply(pair, a, b, cache, params, newton);
            let r = &d.answer.result;
            let collides = r.overlapping || r.distance < pair.margin;
            QueryAnswer::Collide(CollideReply {
                collides,
                distance: r.distance,
                decided_by_bounds: false,
                margin: pair.margin,
                solve: Some(d),
                tree: None,
            })
        }
    }
}

fn distance_reply(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
    newton: Option<crate::query::DistanceResult>,
) -> DistanceReply {
    let o = &pair.options;
    let r = match newton {
        Some(n) => certify_newton_distance(&a.body, &a.pose, &b.body, &b.pose, n, params, o.mode),
        None => {
            let warm = if o.cold { None } else { cache.distance(pair.first, pair.second) };
            certified_distance(&a.body, &a.pose, &b.body, &b.pose, warm, params, o.mode)
        }
    };
    let gradients = (o.with_gradient && r.source != AnswerSource::SdpLowerBound).then(|| distance_gradient(&r.result));
    let precision_limited = super::catalog::precision_limited(&a.body, &a.pose, &b.body, &b.pose);
    let penetration = (o.signed && r.result.overlapping && !r.lower_bound)
        .then(|| crate::query::penetration::penetration(&a.body, &a.pose, &b.body, &b.pose).ok())
        .flatten();
    if !r.lower_bound && !o.cold {
        cache.put_distance(pair.first, pair.second, r.result.warm_start.clone());
    }
    DistanceReply { answer: r, gradients, precision_limited, signed: o.signed, penetration, tree: None }
}

fn growth_reply(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
) -> GrowthReply {
    let o = &pair.options;
    let warm = if o.cold { None } else { cache.growth(pair.first, pair.second) };
    let r = certified_growth(&a.body, &a.pose, &b.body, &b.pose, warm, params, o.mode);
    let gradients = (o.with_gradient && r.source != AnswerSource::SdpLowerBound)
        .then(|| growth_gradient(&a.body, &a.pose, &r.result));
    let precision_limited = super::catalog::precision_limited(&a.body, &a.pose, &b.body, &b.pose);
    if !r.lower_bound && !o.cold {
        cache.put_growth(pair.first, pair.second, r.result.warm_start.clone());
    }
    GrowthReply { answer: r, gradients, precision_limited, tree: None }
}

/// A planner request on a [`QueryView`] (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct PlannerRequest {
    /// Pose updates of the view, applied before the queries (validated: unknown or repeated
    /// instances reject the whole request).
    pub poses: Vec<(String, Isometry3)>,
    /// The queries, answered in order.
    pub queries: Vec<QueryPair>,
    /// Candidate states: when there are any, the queries are answered once per state, with the
    /// state's poses on top of the view.
    pub states: CandidateStates,
}

/// The candidate states of a [`PlannerRequest`], as a client sends them.
#[derive(Clone, Debug)]
pub enum CandidateStates {
    /// Each state its own list of (instance id, pose) (`QueryRequest.states`); an unknown or
    /// repeated instance is named `states[s].poses[k].instance_id`.
    Lists(Vec<Vec<(String, Isometry3)>>),
    /// Every state poses the same instances, in order (`QueryRequest.state_columns`): instance
    /// `instance_ids[k]` of state s is at `poses[s · instance_ids.len() + k]`, so that no state
    /// carries a name or a list of its own; an unknown or repeated instance is named
    /// `state_columns.instance_ids[k]`, and a length that is no multiple of the instances
    /// `state_columns.poses`.
    Columns {
        /// The instances every state poses.
        instance_ids: Vec<String>,
        /// Their poses, state-major.
        poses: Vec<Isometry3>,
    },
}

impl Default for CandidateStates {
    /// No candidate state.
    fn default() -> Self {
        Self::Lists(Vec::new())
    }
}

impl CandidateStates {
    /// The number of states (0 for columns without instances).
    pub fn len(&self) -> usize {
        match self {
            Self::Lists(states) => states.len(),
            Self::Columns { instance_ids, poses } => poses.len().checked_div(instance_ids.len()).unwrap_or(0),
        }
    }

    /// True when there is no state (the queries are answered once).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The answers of a [`PlannerRequest`]: one list of answers, or one per candidate state.
#[derive(Clone, Debug)]
pub enum PlannerAnswers {
    /// Answers of a request without states.
    Single(Vec<QueryAnswer>),
    /// Answers per candidate state.
    PerState(Vec<Vec<QueryAnswer>>),
}

impl PlannerAnswers {
    /// No answer yet, shaped for `request`: [`PlannerAnswers::Single`] without candidate states,
    /// else one empty list per state.
    pub fn for_request(request: &PlannerRequest) -> Self {
        match request.states.len() {
            0 => Self::Single(Vec::new()),
            n => Self::PerState(vec![Vec::new(); n]),
        }
    }
}

/// Where a planner run puts its answers ([`QueryView::run_into`]), as they are solved: a caller
/// that writes them out at once (e.g. the service's answer columns) never holds them all.
pub trait AnswerSink {
    /// Takes the answer of query `query` (its index in [`PlannerRequest::queries`]) in candidate
    /// state `state` (0 without states). Answers come state by state, queries in order.
    fn push(&mut self, state: usize, query: usize, answer: QueryAnswer);

    /// Forgets every answer pushed so far (a Newton-only run stopped at an answer that needs the
    /// SDP, [`QueryView::run_newton_only_into`], is then run again from its start).
    fn clear(&mut self);
}

impl AnswerSink for PlannerAnswers {
    /// Appends to the answers of `state` (a state outside [`PlannerAnswers::for_request`]'s shape
    /// is ignored).
    fn push(&mut self, state: usize, _query: usize, answer: QueryAnswer) {
        match self {
            Self::Single(a) => a.push(answer),
            Self::PerState(s) => {
                if let Some(a) = s.get_mut(state) {
                    a.push(answer);
                }
            }
        }
    }

    fn clear(&mut self) {
        match self {
            Self::Single(a) => a.clear(),
            Self::PerState(s) => s.iter_mut().for_each(Vec::clear),
        }
    }
}

/// The posed instances of one request, by id.
type PosedMap<'a> = HashMap<&'a str, Posed, foldhash::fast::RandomState>;

/// A client's private view of a scene: pose overrides and warm starts of its own (see the module
/// docs). A QueryStream holds one for its lifetime; a unary Query uses a fresh one.
#[derive(Debug)]
pub struct QueryView {
    scene_id: String,
    overrides: HashMap<String, Isometry3, foldhash::fast::RandomState>,
    cache: WarmStartCache,
}

/// An error naming the first instance id of `ids` that appears twice, as `field(k)`.
fn check_unique<'a>(
    field: impl Fn(usize) -> String,
    ids: impl ExactSizeIterator<Item = &'a str> + Clone,
) -> Result<()> {
    let repeated = |k: usize, id: &str| Err(Error::invalid(field(k), format!("instance `{id}` appears twice")));
    // A state poses a few instances: pairwise comparison, no set (nor field name) per state.
    if ids.len() <= 16 {
        for (k, id) in ids.clone().enumerate() {
            if ids.clone().take(k).any(|p| p == id) {
                return repeated(k, id);
            }
        }
        return Ok(());
    }
    let mut seen = std::collections::HashSet::new();
    for (k, id) in ids.enumerate() {
        if !seen.insert(id) {
            return repeated(k, id);
        }
    }
    Ok(())
}

/// The ids of a list of poses.
fn ids_of(poses: &[(String, Isometry3)]) -> impl ExactSizeIterator<Item = &str> + Clone {
    poses.iter().map(|(id, _)| id.as_str())
}

impl QueryView {
    /// An empty view of `scene_id` (stored poses, no warm starts).
    pub fn new(scene_id: &str) -> Self {
        Self { scene_id: scene_id.to_owned(), overrides: HashMap::default(), cache: WarmStartCache::default() }
    }

    /// The scene this view looks at.
    pub fn scene_id(&self) -> &str {
        &self.scene_id
    }

    /// Number of warm starts this view holds.
    pub fn warm_starts(&self) -> usize {
        self.cache.len()
    }

    /// Applies `request.poses`, then answers its queries (see the module docs).
    ///
    /// # Errors
    /// [`Error::NotFound`] for the scene or an instance a query names; [`Error::InvalidArgument`]
    /// naming `poses[k].instance_id` / `states[s].poses[k].instance_id` for an unknown or repeated
    /// instance (the view is then unchanged).
    pub fn run(&mut self, catalog: &Catalog, request: &PlannerRequest) -> Result<PlannerAnswers> {
        let mut answers = PlannerAnswers::for_request(request);
        self.run_into(catalog, request, &mut answers)?;
        Ok(answers)
    }

    /// [`QueryView::run`] with each answer handed to `sink` as it is solved.
    ///
    /// # Errors
    /// As [`QueryView::run`] (`sink` then holds no answer).
    pub fn run_into(&mut self, catalog: &Catalog, request: &PlannerRequest, sink: &mut dyn AnswerSink) -> Result<()> {
        if self.run_with(catalog, request, false, sink)? {
            Ok(())
        } else {
            Err(Error::Numerical("an answer needs the SDP outside CertifyMode::NewtonOnly".into()))
        }
    }

    /// [`QueryView::run`] without any SDP (for an async worker): every query is answered in
    /// [`CertifyMode::NewtonOnly`] (a request asking for a certificate must not come here). When an
    /// answer needs the SDP ([`QueryAnswer::needs_sdp`]) it returns `None` and keeps none of the
    /// request's warm starts, so [`QueryView::run`] then gives exactly the answers it would have
    /// given first (the pose updates, already applied, are applied again to the same values).
    ///
    /// # Errors
    /// As [`QueryView::run`].
    pub fn run_newton_only(&mut self, catalog: &Catalog, request: &PlannerRequest) -> Result<Option<PlannerAnswers>> {
        let mut answers = PlannerAnswers::for_request(request);
        Ok(self.run_newton_only_into(catalog, request, &mut answers)?.then_some(answers))
    }

    /// [`QueryView::run_newton_only`] with each answer handed to `sink` as it is solved. Returns
    /// false, with `sink` cleared ([`AnswerSink::clear`]), at the first answer that needs the SDP
    /// (none of the request's warm starts is kept then).
    ///
    /// # Errors
    /// As [`QueryView::run`].
    pub fn run_newton_only_into(
        &mut self,
        catalog: &Catalog,
        request: &PlannerRequest,
        sink: &mut dyn AnswerSink,
    ) -> Result<bool> {
        self.run_with(catalog, request, true, sink)
    }

    /// Validates and resolves `request`, then answers it into `sink`; false (and `sink` cleared)
    /// when `newton_only` and an answer needs the SDP.
    fn run_with(
        &mut self,
        catalog: &Catalog,
        request: &PlannerRequest,
        newton_only: bool,
        sink: &mut dyn AnswerSink,
    ) -> Result<bool> {
        check_unique(|k| format!("poses[{k}].instance_id"), ids_of(&request.poses))?;
        let mut ids: Vec<&str> = ids_of(&request.poses).collect();
        match &request.states {
            CandidateStates::Lists(states) => {
                for (s, state) in states.iter().enumerate() {
                    check_unique(|k| format!("states[{s}].poses[{k}].instance_id"), ids_of(state))?;
                }
                ids.extend(states.iter().flat_map(|s| ids_of(s)));
            }
            CandidateStates::Columns { instance_ids, poses } => {
                let n = instance_ids.len();
                if n == 0 || !poses.len().is_multiple_of(n) {
                    return Err(Error::invalid(
                        "state_columns.poses",
                        format!(
                            "has {} poses: expected a multiple of the {n} instances of `state_columns.instance_ids`",
                            poses.len()
                        ),
                    ));
                }
                let names = instance_ids.iter().map(String::as_str);
                check_unique(|k| format!("state_columns.instance_ids[{k}]"), names.clone())?;
                ids.extend(names);
            }
        }
        ids.extend(request.queries.iter().flat_map(|q| [q.first.as_str(), q.second.as_str()]));
        ids.sort_unstable();
        ids.dedup();
        let stored = catalog.posed_by_ids(&self.scene_id, &ids).map_err(|e| match e {
            Error::NotFound { kind: "instance", id } => {
                let field = request
                    .poses
                    .iter()
                    .position(|(p, _)| *p == id)
                    .map(|k| format!("poses[{k}].instance_id"))
                    .or_else(|| match &request.states {
                        CandidateStates::Lists(states) => states.iter().enumerate().find_map(|(s, st)| {
                            let k = st.iter().position(|(p, _)| *p == id)?;
                            Some(format!("states[{s}].poses[{k}].instance_id"))
                        }),
                        CandidateStates::Columns { instance_ids, .. } => instance_ids
                            .iter()
                            .position(|p| *p == id)
                            .map(|k| format!("state_columns.instance_ids[{k}]")),
                    });
                match field {
                    Some(f) => Error::invalid(f, format!("no instance `{id}` in scene `{}`", self.scene_id)),
                    None => Error::NotFound { kind: "instance", id },
                }
            }
            other => other,
        })?;
        for (id, pose) in &request.poses {
            match self.overrides.get_mut(id) {
                Some(p) => *p = *pose,
                None => {
                    self.overrides.insert(id.clone(), *pose);
                }
            }
        }
        let mut posed: PosedMap<'_> = HashMap::with_capacity_and_hasher(ids.len(), Default::default());
        for (id, mut p) in ids.into_iter().zip(stored) {
            if let Some(pose) = self.overrides.get(id) {
                p.pose = *pose;
            }
            posed.insert(id, p);
        }
        let params = catalog.certify_params();
        if !newton_only {
            return Ok(self.answer_states(request, &mut posed, &params, None, sink));
        }
        // The request's warm starts go to a scratch cache, kept only when no answer needs the SDP.
        let mut scratch = WarmStartCache::default();
        for q in request.queries.iter().filter(|q| !q.options.cold) {
            self.cache.copy_pair(&mut scratch, super::catalog::warm_kind(q.kind), &q.first, &q.second);
        }
        let saved = std::mem::replace(&mut self.cache, scratch);
        let done = self.answer_states(request, &mut posed, &params, Some(CertifyMode::NewtonOnly), sink);
        let scratch = std::mem::replace(&mut self.cache, saved);
        if !done {
            sink.clear();
            return Ok(false);
        }
        self.cache.merge(scratch, |_| true);
        Ok(true)
    }

    /// The queries answered once, or once per candidate state, into `sink`; `mode` overrides each
    /// query's. Takes the instances out of `posed`. With `mode` [`CertifyMode::NewtonOnly`] it
    /// stops at the first answer that needs the SDP and returns false.
    fn answer_states(
        &mut self,
        request: &PlannerRequest,
        posed: &mut PosedMap<'_>,
        params: &CertifyParams,
        mode: Option<CertifyMode>,
        sink: &mut dyn AnswerSink,
    ) -> bool {
        let nq = request.queries.len();
        // The request's instances by slot, each query's two slots and each state's posed slots
        // resolved once (by name only for states given as lists), so that no state hashes an id
        // or touches a reference count.
        let (ids, mut slots): (Vec<&str>, Vec<Posed>) = posed.drain().unzip();
        let slot_of: HashMap<&str, usize, foldhash::fast::RandomState> =
            ids.iter().enumerate().map(|(i, id)| (*id, i)).collect();
        let slot = |id: &str| slot_of.get(id).copied();
        let pairs: Vec<Option<(usize, usize)>> =
            request.queries.iter().map(|q| slot(&q.first).zip(slot(&q.second))).collect();
        if request.states.is_empty() {
            // Cold queries of one body pair among the request's queries: on the batch solver's lanes.
            let mut newton = LaneAnswers::default();
            if enough_lane_candidates(request.queries.iter().map(|q| (q.kind, &q.options))) {
                let views: Vec<PairRef<'_>> = request.queries.iter().map(|q| with_mode(q.view(), mode)).collect();
                let at = |k: usize| pairs[k].map(|(i, j)| (slots[i].borrowed(), slots[j].borrowed()));
                newton = lane_distances(&views, at, params, false);
            }
            return self.answer_slots(&request.queries, &pairs, &slots, params, mode, (&mut newton, 0, 0), sink);
        }
        // States in columns: the slots of their instances, resolved once.
        let columns: Vec<Option<usize>> = match &request.states {
            CandidateStates::Lists(_) => Vec::new(),
            CandidateStates::Columns { instance_ids, .. } => instance_ids.iter().map(|id| slot(id)).collect(),
        };
        let state_slots = |s: usize, buf: &mut Vec<(usize, Isometry3)>| {
            buf.clear();
            match &request.states {
                CandidateStates::Lists(states) => {
                    buf.extend(states[s].iter().filter_map(|(id, pose)| Some((slot(id)?, *pose))));
                }
                CandidateStates::Columns { poses, .. } => {
                    let state = &poses[s * columns.len()..(s + 1) * columns.len()];
                    buf.extend(columns.iter().zip(state).filter_map(|(c, pose)| Some(((*c)?, *pose))));
                }
            }
        };
        let states = request.states.len();
        let mut buf = Vec::new();
        let mut newton = state_lane_distances(request, &slots, &pairs, state_slots, params, mode, &self.cache);
        // The poses a state replaces, restored after it.
        let mut saved: Vec<(usize, Isometry3)> = Vec::new();
        for s in 0..states {
            state_slots(s, &mut buf);
            saved.extend(buf.iter().map(|&(i, pose)| (i, std::mem::replace(&mut slots[i].pose, pose))));
            if !self.answer_slots(&request.queries, &pairs, &slots, params, mode, (&mut newton, s * nq, s), sink) {
                return false;
            }
            for (i, pose) in saved.drain(..).rev() {
                slots[i].pose = pose;
            }
        }
        true
    }

    /// The queries answered at the poses of the request's instances `slots`, into `sink` as
    /// candidate state `newton.2` (0 without states): query q between `slots[pairs[q].0]` and
    /// `slots[pairs[q].1]` (skipped when `None`), with what was settled ahead (Newton's answers,
    /// collide bounds) where `newton.0` has it (query q at index `newton.1 + q`, taken from it).
    /// With `mode` [`CertifyMode::NewtonOnly`] it stops at the first answer that needs the SDP and
    /// returns false.
    #[allow(clippy::too_many_arguments)]
    fn answer_slots(
        &mut self,
        queries: &[QueryPair],
        pairs: &[Option<(usize, usize)>],
        slots: &[Posed],
        params: &CertifyParams,
        mode: Option<CertifyMode>,
        newton: (&mut LaneAnswers, usize, usize),
        sink: &mut dyn AnswerSink,
    ) -> bool {
        let (newton, offset, state) = newton;
        for (q, (query, ij)) in queries.iter().zip(pairs).enumerate() {
            let Some((i, j)) = *ij else { continue };
            let pair = with_mode(query.view(), mode);
            let answer = answer_pair_with(pair, &slots[i], &slots[j], &mut self.cache, params, newton.take(offset + q));
            if mode.is_some() && answer.needs_sdp() {
                return false;
            }
            sink.push(state, q, answer);
        }
        true
    }
}

/// `pair` with its certification mode replaced by `mode` when given.
fn with_mode(mut pair: PairRef<'_>, mode: Option<CertifyMode>) -> PairRef<'_> {
    if let Some(mode) = mode {
        pair.options.mode = mode;
    }
    pair
}

/// Newton's answers of a request's distance and collide queries across its candidate states from
/// the batch solver's lanes ([`lane_distances`]: each query's pair in every state is one column
/// of one body pair), entry `s · queries + q` for state s and query q: the cold ones, and the
/// others whose warm start would not be used ([`crate::query::warm_start_reaches`]: for state 0
/// the pair's cached warm start, for a later state the pair's relative pose in the state before,
/// more than half the bodies' summed scales away, as between a sampling planner's random
/// candidates), solved on lanes that keep warm starts for the cache. Empty (every answer solved one
/// by one) when fewer than [`crate::query::batch::MIN_LANE_BATCH`] of them are. The request's
/// instances are `slots`, query q's pair is `pairs[q]` (slot indices), `state_slots(s, buf)` fills
/// `buf` with state s's (slot, pose) and `cache` holds the warm starts the queries would start
/// from.
#[allow(clippy::too_many_arguments)]
fn state_lane_distances(
    request: &PlannerRequest,
    slots: &[Posed],
    pairs: &[Option<(usize, usize)>],
    state_slots: impl Fn(usize, &mut Vec<(usize, Isometry3)>),
    params: &CertifyParams,
    mode: Option<CertifyMode>,
    cache: &WarmStartCache,
) -> LaneAnswers {
    let states = request.states.len();
    let candidates = (0..states).flat_map(|_| request.queries.iter().map(|q| (q.kind, &q.options)));
    if candidates.filter(|(kind, o)| lane_kind(*kind, o)).nth(crate::query::batch::MIN_LANE_BATCH - 1).is_none() {
        return LaneAnswers::default();
    }
    let n = states * request.queries.len();
    let (mut views, mut snapshot) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut buf = Vec::new();
    // Each query's relative pose pose_a⁻¹·pose_b in the state before.
    let mut before: Vec<Option<Isometry3>> = vec![None; request.queries.len()];
    let mut warm_lanes = false;
    for s in 0..states {
        state_slots(s, &mut buf);
        // Slot i at this state's pose.
        let at = |i: usize| {
            let p = &slots[i];
            let pose = buf.iter().find(|(k, _)| *k == i).map_or(p.pose, |(_, pose)| *pose);
            PosedRef { pose, ..p.borrowed() }
        };
        for ((q, query), ij) in request.queries.iter().enumerate().zip(pairs) {
            let mut pair = with_mode(query.view(), mode);
            let posed = ij.map(|(i, j)| (at(i), at(j)));
            let rel = posed.as_ref().map(|(a, b)| a.pose.inv_mul(&b.pose));
            let far = || match (&posed, &rel, &before[q]) {
                (Some((a, b)), Some(rel), Some(prev)) => !crate::query::warm_start_reaches(a.body, b.body, prev, rel),
                (Some((a, b)), Some(rel), None) => {
                    !cache.distance(pair.first, pair.second).is_some_and(|w| w.reaches(a.body, b.body, rel))
                }
                _ => false,
            };
            let cold = lane_candidate(pair.kind, &pair.options);
            let lanes = cold || (lane_kind(pair.kind, &pair.options) && far());
            if lanes && !cold {
                // Routed like a cold query; the lanes keep its warm start for the cache.
                pair.options.cold = true;
                warm_lanes = true;
            }
            before[q] = rel;
            snapshot.push(if lanes { posed } else { None });
            views.push(pair);
        }
    }
    lane_distances(&views, |k| snapshot[k], params, warm_lanes)
}

/// A pair found by [`check_scene`].
#[derive(Clone, Debug)]
pub struct ScenePair {
    /// First instance (the smaller id).
    pub first: String,
    /// Second instance.
    pub second: String,
    /// Their distance answer.
    pub distance: DistanceReply,
}

/// The outcome of [`check_scene`], with its cost.
#[derive(Clone, Debug, Default)]
pub struct SceneCheck {
    /// Pairs that overlap or lie within the margin, by increasing distance.
    pub pairs: Vec<ScenePair>,
    /// Instances checked.
    pub instances: usize,
    /// Pairs whose grown bounding boxes intersect (the BVH's output).
    pub candidate_pairs: u64,
    /// Distance solves run.
    pub narrow_phase_solves: u64,
    /// Pairs a brute-force check examines.
    pub all_pairs: u64,
}

/// Every pair of a scene (or of `focus` against the rest) that overlaps or lies closer than
/// `margin` meters, with `overrides` applied to the stored poses (not stored). Broad phase: a BVH
/// (parry's) over the posed bounding boxes grown by `margin / 2`; then the bounding spheres, and
/// for two single bodies the separating axis ([`collide_lower_bound`]); then cold distance solves
/// on what remains. A nonconvex body (no proven bound) is a candidate for
/// every pair.
///
/// # Errors
/// [`Error::NotFound`] for the scene or a `focus` / override instance; [`Error::InvalidArgument`]
/// naming `margin` (negative or not finite) or a repeated override.
pub fn check_scene(
    catalog: &Catalog,
    scene_id: &str,
    margin: Real,
    focus: &[String],
    overrides: &[(String, Isometry3)],
) -> Result<SceneCheck> {
    use parry3d_f64::bounding_volume::{Aabb, BoundingVolume};
    use parry3d_f64::partitioning::{Bvh, BvhBuildStrategy};
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::invalid("margin", format!("must be finite and >= 0 meters, got {margin}")));
    }
    check_unique(|k| format!("poses[{k}].instance_id"), ids_of(overrides))?;
    let mut all = catalog.posed_instances(scene_id, &[])?;
    let index: HashMap<String, usize> = all.iter().enumerate().map(|(k, i)| (i.id.clone(), k)).collect();
    for (k, (id, pose)) in overrides.iter().enumerate() {
        let at = *index.get(id).ok_or_else(|| {
            Error::invalid(format!("poses[{k}].instance_id"), format!("no instance `{id}` in scene `{scene_id}`"))
        })?;
        all[at].pose = *pose;
    }
    let mut is_focus = vec![focus.is_empty(); all.len()];
    for (k, id) in focus.iter().enumerate() {
        let at = *index.get(id).ok_or_else(|| Error::not_found("instance", id.as_str())).map_err(|e| {
            if let Error::NotFound { .. } = e {
                Error::invalid(format!("instance_ids[{k}]"), format!("no instance `{id}` in scene `{scene_id}`"))
            } else {
                e
            }
        })?;
        is_focus[at] = true;
    }
    let n = all.len();
    let k = is_focus.iter().filter(|f| **f).count();
    let all_pairs = if focus.is_empty() {
        (n * n.saturating_sub(1) / 2) as u64
    } else {
        (k * (n - k) + k * k.saturating_sub(1) / 2) as u64
    };
    let half = 0.5 * margin;
    let far = crate::math::MAX_COORDINATE * 4.0;
    let boxes: Vec<Aabb> = all
        .iter()
        .map(|i| match i.body.world_aabb(&i.pose) {
            Some((lo, hi)) => {
                let (lo, hi) = (lo.add_scalar(-half), hi.add_scalar(half));
                Aabb::new([lo.x, lo.y, lo.z].into(), [hi.x, hi.y, hi.z].into())
            }
            None => Aabb::new([-far; 3].into(), [far; 3].into()),
        })
        .collect();
    let mut out = SceneCheck { instances: n, all_pairs, ..SceneCheck::default() };
    if n < 2 {
        return Ok(out);
    }
    let bvh = Bvh::from_leaves(BvhBuildStrategy::Binned, &boxes);
    let mut candidates: Vec<(usize, usize)> = bvh
        .leaf_pairs(&bvh, |x, y| x.aabb().intersects(&y.aabb()))
        .map(|(i, j)| (i as usize, j as usize))
        .filter(|&(i, j)| i < j && (is_focus[i] || is_focus[j]))
        .collect();
    candidates.sort_unstable();
    candidates.dedup();
    out.candidate_pairs = candidates.len() as u64;
    let params = catalog.certify_params();
    let options = QueryOptions { cold: true, ..QueryOptions::default() };
    let mut scratch = WarmStartCache::default();
    // The narrow phase: the candidates the cheap bounds do not clear (a compound body's root
    // sphere; two single bodies' spheres, then their separating axis), as cold distance queries;
    // those of one body pair solved on the batch solver's lanes first.
    let solves: Vec<(usize, usize)> = candidates
        .into_iter()
        .filter(|&(i, j)| {
            let (a, b) = (&all[i], &all[j]);
            let lower = if a.tree.is_none() && b.tree.is_none() {
                collide_lower_bound(&a.body, &a.pose, &b.body, &b.pose, margin)
            } else {
                sphere_lower_bound(&a.body, &a.pose, &b.body, &b.pose)
            };
            lower.is_none_or(|lower| lower <= margin)
        })
        .collect();
    let queries: Vec<QueryPair> = solves
        .iter()
        .map(|&(i, j)| QueryPair {
            kind: QueryKind::Distance,
            first: all[i].id.clone(),
            second: all[j].id.clone(),
            options,
            margin,
        })
        .collect();
    let posed_pairs: Vec<(Posed, Posed)> = solves
        .iter()
        .map(|&(i, j)| {
            let posed = |k: usize| Posed { body: all[k].body.clone(), tree: all[k].tree.clone(), pose: all[k].pose };
            (posed(i), posed(j))
        })
        .collect();
    let views: Vec<PairRef<'_>> = queries.iter().map(QueryPair::view).collect();
    let mut newton =
        lane_distances(&views, |k| Some((posed_pairs[k].0.borrowed(), posed_pairs[k].1.borrowed())), &params, false);
    for (k, (pair, (pa, pb))) in views.into_iter().zip(&posed_pairs).enumerate() {
        // An abandoned request (deadline passed) stops here, see `Catalog::batch`.
        crate::fit::cancel::check()?;
        out.narrow_phase_solves += 1;
        let d = if super::compound_pairs::is_compound_pair(pa, pb) {
            super::compound_pairs::distance_reply(pair, pa, pb, &mut scratch, &params)
        } else {
            distance_reply(pair, pa, pb, &mut scratch, &params, newton.take(k).into_newton())
        };
        let r = &d.answer.result;
        if r.overlapping || r.distance < margin {
            out.pairs.push(ScenePair { first: pair.first.to_owned(), second: pair.second.to_owned(), distance: d });
        }
    }
    out.pairs.sort_by(|x, y| x.distance.answer.result.distance.total_cmp(&y.distance.answer.result.distance));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::ellipsoid;
    use crate::math::Vector3;

    /// Spheres r = 0.5 at the origin ("a") and r = 0.25 ("b", moved by the states), a non-cold
    /// distance query a → b over states putting b at `xs`: the routed answers (state s at index s)
    /// with the cache `cache`.
    fn routed(xs: &[[Real; 3]], cache: &WarmStartCache) -> Vec<Ahead> {
        let big = Arc::new(ellipsoid([0.0; 3], [0.5; 3]).unwrap());
        let small = Arc::new(ellipsoid([0.0; 3], [0.25; 3]).unwrap());
        let slots = vec![
            Posed { body: big, tree: None, pose: Isometry3::identity() },
            Posed { body: small, tree: None, pose: Isometry3::identity() },
        ];
        let at = |x: &[Real; 3]| Isometry3::translation(x[0], x[1], x[2]);
        let request = PlannerRequest {
            queries: vec![QueryPair {
                kind: QueryKind::Distance,
                first: "a".into(),
                second: "b".into(),
                options: QueryOptions::default(),
                margin: 0.0,
            }],
            states: CandidateStates::Lists(xs.iter().map(|x| vec![("b".to_string(), at(x))]).collect()),
            ..Default::default()
        };
        let state_slots = |s: usize, buf: &mut Vec<(usize, Isometry3)>| {
            buf.clear();
            buf.push((1, at(&xs[s])));
        };
        let params = CertifyParams::default();
        let mut lanes = state_lane_distances(&request, &slots, &[Some((0, 1))], state_slots, &params, None, cache);
        (0..xs.len()).map(|s| lanes.take(s)).collect()
    }

    /// Candidate states far apart (steps of 0.94 m between spheres of summed scale 0.75 m: past the
    /// warm start's reach) take the lanes although the query is not cold, and their answers match
    /// the closed form ‖c_b‖ − 0.75 (10⁻⁹ m) and keep valid warm starts for the cache; a trajectory
    /// of 5 cm steps stays off the lanes (each state warm-started from the one before: only the
    /// first, without a cached warm start, would take them, and one pair is no batch); a cached
    /// warm start near the first state keeps that state off them.
    #[test]
    fn far_candidate_states_take_the_lanes_and_a_trajectory_does_not() {
        let far: Vec<[Real; 3]> = (0..8).map(|k| [1.5 + 0.5 * k as Real, 0.8 * (k % 2) as Real, 0.0]).collect();
        let answers = routed(&far, &WarmStartCache::default());
        for (x, a) in far.iter().zip(&answers) {
            let Ahead::Newton(d) = a else { panic!("state at {x:?} did not take the lanes: {a:?}") };
            let gap = Vector3::from(*x).norm() - 0.75;
            assert!((d.distance - gap).abs() < 1e-9, "{x:?}: {} vs {gap}", d.distance);
            assert!(d.status.converged() && d.warm_start.valid, "{x:?}: {d:?}");
        }
        let near: Vec<[Real; 3]> = (0..8).map(|k| [1.5 + 0.05 * k as Real, 0.0, 0.0]).collect();
        assert!(routed(&near, &WarmStartCache::default()).iter().all(|a| matches!(a, Ahead::Nothing)));
        // With a cached warm start near the first state: still none.
        let (big, small) = (ellipsoid([0.0; 3], [0.5; 3]).unwrap(), ellipsoid([0.0; 3], [0.25; 3]).unwrap());
        let id = Isometry3::identity();
        let d = crate::query::distance(
            &big,
            &id,
            &small,
            &Isometry3::translation(1.45, 0.0, 0.0),
            None,
            &Default::default(),
        );
        let mut cache = WarmStartCache::default();
        cache.put_distance("a", "b", d.warm_start);
        assert!(routed(&near, &cache).iter().all(|a| matches!(a, Ahead::Nothing)));
        // The far states with that cache: the first starts from the cached warm start 5 cm away,
        // the rest take the lanes.
        let answers = routed(&far, &cache);
        assert!(matches!(answers[0], Ahead::Nothing));
        assert!(answers[1..].iter().all(|a| matches!(a, Ahead::Newton(_))));
    }
}
