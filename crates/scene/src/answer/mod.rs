//! Answering one query between two posed instances, with a warm-start cache keyed by their ids.
//!
//! ```text
//! types.rs     what a query asks and what it answers (kinds, options, pairs, replies)
//! mod.rs       answer_pair: the path sublevel_query::dispatch picks, run with the pair's warm start
//! compound.rs  pairs with a compound body: the tree queries and their warm starts
//! primitive.rs pairs with an exact primitive: shape_distance, its warm starts and certificates
//! ```
//!
//! The decision of how a pair is answered (compound trees, cheap collide bounds, the batch
//! solver's lanes, one warm-started solve) is [`sublevel_query::dispatch`]'s; this module adds
//! what needs the scene: the instance ids that key the warm starts, the cache they live in, and
//! the replies' extras (gradients, penetration, input precision).

mod compound;
mod primitive;
mod types;

pub(crate) use types::warm_kind;
pub use types::{
    precision_limited, CollideReply, DistanceReply, GrowthReply, PairRef, QueryAnswer, QueryKind, QueryOptions,
    QueryPair, TreeInfo, PRECISION_LIMIT,
};

use crate::cache::WarmStartCache;
use std::sync::Arc;
use sublevel_core::body::Body;
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::Isometry3;
use sublevel_core::primitive::Primitive;
use sublevel_query::dispatch::{self, Ahead, CheapCollide, CollideRoute, LaneAnswers, PosedRef};
use sublevel_query::{
    certified_distance, certified_growth, certify_newton_distance, distance_gradient, growth_gradient, AnswerSource,
    CertifyParams, DistanceResult,
};

/// A posed instance of a request's snapshot: its body and its pose in this view.
#[derive(Clone, Debug)]
pub struct Posed {
    /// The body (shared with the catalog); a compound body's root body.
    pub body: Arc<Body>,
    /// A compound body's containment tree (`None` for a single body): queries involving it run
    /// the tree queries ([`sublevel_query::tree`]).
    pub tree: Option<Arc<CompoundBody>>,
    /// The exact primitive the instance is (`body` is then its bounding ellipsoid, or a stand-in
    /// for a halfspace): queries involving it run [`sublevel_query::shape`]. `None` for a fitted
    /// body.
    pub primitive: Option<Primitive>,
    /// The pose in this view (body frame → world).
    pub pose: Isometry3,
}

impl Posed {
    /// This instance borrowed, at its pose: what the dispatcher reads, with no reference count
    /// touched.
    #[inline]
    pub(crate) fn borrowed(&self) -> PosedRef<'_> {
        PosedRef { body: &self.body, tree: self.tree.as_deref(), primitive: self.primitive.as_ref(), pose: self.pose }
    }
}

/// Why query `pair` between `a` and `b` cannot be answered (a growth query with a primitive, a
/// distance or collide query between two halfspaces), as [`Error::InvalidArgument`] naming
/// `field(second)` — the request's field of the first (`false`) or second (`true`) instance;
/// `Ok` for every other pair. Asked of every query before any is solved.
pub(crate) fn check_pair(
    pair: &PairRef<'_>,
    a: &Posed,
    b: &Posed,
    field: impl FnOnce(bool) -> String,
) -> crate::Result<()> {
    if a.primitive.is_none() && b.primitive.is_none() {
        return Ok(());
    }
    match dispatch::refusal(pair.kind, &a.borrowed(), &b.borrowed()) {
        None => Ok(()),
        Some((side, reason)) => {
            let (second, id) = match side {
                dispatch::PairSide::First => (false, pair.first),
                dispatch::PairSide::Second => (true, pair.second),
            };
            let id = sublevel_core::error::clip(id);
            Err(crate::Error::invalid(field(second), format!("instance `{id}` {reason}")))
        }
    }
}

/// Answers one query between two posed instances with the given warm-start cache (ids key it);
/// `options.cold` ignores and leaves no warm start. The core of [`crate::Catalog::batch`] and of
/// [`crate::planner::QueryView::run`].
pub fn answer_pair(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
) -> QueryAnswer {
    answer_pair_with(pair, a, b, cache, params, Ahead::Nothing)
}

/// [`sublevel_query::dispatch::lane_distances`] of queries `pairs` (query k between the two
/// instances `posed(k)`): what is settled ahead of their answers ([`Ahead`]), for
/// [`answer_pair_with`].
pub(crate) fn lane_distances<'p>(
    pairs: &[PairRef<'_>],
    posed: impl Fn(usize) -> Option<(PosedRef<'p>, PosedRef<'p>)>,
    params: &CertifyParams,
    warm_starts: bool,
) -> LaneAnswers {
    dispatch::lane_distances(pairs.iter().map(PairRef::ask), posed, &params.newton, warm_starts)
}

/// [`answer_pair`] with what [`sublevel_query::dispatch::lane_distances`] settled ahead
/// ([`Ahead`]: Newton's answer of a distance or collide query, or a collide query's cheap
/// decision); [`Ahead::Nothing`] answers it here from scratch. The path is the dispatcher's
/// (module docs of [`sublevel_query::dispatch`]).
pub fn answer_pair_with(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
    ahead: Ahead,
) -> QueryAnswer {
    let (ra, rb) = (a.borrowed(), b.borrowed());
    if dispatch::is_primitive_pair(&ra, &rb) {
        return match pair.kind {
            QueryKind::Distance => QueryAnswer::Distance(primitive::distance_reply(pair, &ra, &rb, cache)),
            QueryKind::Collide => QueryAnswer::Collide(primitive::collide_reply(pair, &ra, &rb, cache)),
            // Refused before any query is solved (`check_pair`); should one come here anyway, it is
            // answered as the tree queries answer what they refuse: an unconverged lower bound.
            QueryKind::Growth => QueryAnswer::Growth(unanswered_growth(a, b)),
        };
    }
    if dispatch::is_compound_pair(&ra, &rb) {
        return match pair.kind {
            QueryKind::Distance => QueryAnswer::Distance(compound::distance_reply(pair, &ra, &rb, cache, params)),
            QueryKind::Growth => QueryAnswer::Growth(compound::growth_reply(pair, &ra, &rb, cache, params)),
            QueryKind::Collide => QueryAnswer::Collide(compound::collide_reply(pair, &ra, &rb, cache, params)),
        };
    }
    match pair.kind {
        QueryKind::Distance => QueryAnswer::Distance(distance_reply(pair, a, b, cache, params, ahead.into_newton())),
        QueryKind::Growth => QueryAnswer::Growth(growth_reply(pair, a, b, cache, params)),
        QueryKind::Collide => match ahead.collide_route(&ra, &rb, pair.margin) {
            CollideRoute::Decided(decided) => {
                let (collides, distance) = match decided {
                    CheapCollide::Clear(lower) => (false, lower),
                    CheapCollide::Touching(_) => (true, 0.0),
                };
                QueryAnswer::Collide(CollideReply {
                    collides,
                    distance,
                    decided_by_bounds: true,
                    solve: None,
                    margin: pair.margin,
                    tree: None,
                })
            }
            CollideRoute::Solve(newton) => {
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
        },
    }
}

/// The distance reply of a pair of single bodies: Newton's answer from the lanes (`newton`)
/// certified as the query's mode says, else a solve warm-started from the cache; then the
/// gradients, the input precision and the penetration asked for. Keeps the new warm start unless
/// the query is cold or the answer is a lower bound.
fn distance_reply(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
    newton: Option<DistanceResult>,
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
    let precision_limited = precision_limited(&a.body, &a.pose, &b.body, &b.pose);
    let penetration = (o.signed && r.result.overlapping && !r.lower_bound)
        .then(|| sublevel_query::penetration::penetration(&a.body, &a.pose, &b.body, &b.pose).ok())
        .flatten();
    if !r.lower_bound && !o.cold {
        cache.put_distance(pair.first, pair.second, r.result.warm_start.clone());
    }
    DistanceReply { answer: r, gradients, precision_limited, signed: o.signed, penetration, tree: None }
}

/// The distance reply of any pair: the tree query for a compound pair, else
/// [`distance_reply`] with Newton's answer from the lanes (`newton`) if any.
pub(crate) fn any_distance_reply(
    pair: PairRef<'_>,
    a: &Posed,
    b: &Posed,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
    newton: Option<DistanceResult>,
) -> DistanceReply {
    let (ra, rb) = (a.borrowed(), b.borrowed());
    if dispatch::is_primitive_pair(&ra, &rb) {
        primitive::distance_reply(pair, &ra, &rb, cache)
    } else if dispatch::is_compound_pair(&ra, &rb) {
        compound::distance_reply(pair, &ra, &rb, cache, params)
    } else {
        distance_reply(pair, a, b, cache, params, newton)
    }
}

/// The growth reply of a pair of single bodies, warm-started from the cache; keeps the new warm
/// start unless the query is cold or the answer is a lower bound.
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
    let precision_limited = precision_limited(&a.body, &a.pose, &b.body, &b.pose);
    if !r.lower_bound && !o.cold {
        cache.put_growth(pair.first, pair.second, r.result.warm_start.clone());
    }
    GrowthReply { answer: r, gradients, precision_limited, tree: None }
}

/// The growth reply of a pair the growth measure is not defined for (a primitive side): an
/// unconverged lower bound 0, with no minimizer.
fn unanswered_growth(a: &Posed, b: &Posed) -> GrowthReply {
    let result = sublevel_query::GrowthResult {
        value: 0.0,
        minimizer: sublevel_core::math::Point3::new(f64::NAN, f64::NAN, f64::NAN),
        multiplier: 0.0,
        status: sublevel_query::SolveStatus::Stalled,
        iterations: 0,
        kkt_residual: f64::NAN,
        warm_started: false,
        warm_start: Arc::default(),
    };
    let answer = sublevel_query::CertifiedGrowth::unresolved(result);
    GrowthReply {
        answer,
        gradients: None,
        precision_limited: precision_limited(&a.body, &a.pose, &b.body, &b.pose),
        tree: None,
    }
}
