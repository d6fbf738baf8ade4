//! What a query between two instances asks ([`QueryKind`], [`QueryOptions`], [`QueryPair`],
//! [`PairRef`]) and what it answers ([`QueryAnswer`]: [`DistanceReply`], [`GrowthReply`],
//! [`CollideReply`]).

use crate::cache::WarmKind;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real};
use sublevel_query::dispatch::PairAsk;
use sublevel_query::{CertifiedDistance, CertifiedGrowth, CertifyMode, PoseGradient};

pub use sublevel_query::dispatch::QueryKind;

/// Per-query options: certification mode and pose gradients.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct QueryOptions {
    /// [`CertifyMode::Newton`] (default: the SDP only as a fallback) or [`CertifyMode::Certify`]
    /// (always attach the level-0 certificate); see [`sublevel_query::certified`].
    pub mode: CertifyMode,
    /// Also return the gradients of the value with respect to both poses
    /// ([`sublevel_query::gradient`]).
    pub with_gradient: bool,
    /// Solve cold: ignore the pair's warm start and leave none behind.
    pub cold: bool,
    /// Distance queries: also the penetration depth when overlapping (signed distance,
    /// [`sublevel_query::penetration`]).
    pub signed: bool,
    /// Distance queries of pairs with a compound body: stop refining once the bounds are within
    /// this many meters (upper − lower ≤ tolerance; [`sublevel_query::tree::TreeQueryParams`]).
    /// 0 (default): the exact distance of the two models. Finite and ≥ 0 (checked by the
    /// callers that take it from outside). Ignored by single-body pairs.
    pub tolerance: Real,
}

/// What a query between a compound body and another body adds to its answer: the
/// branch and bound's bounds and cost ([`sublevel_query::tree`]). `None` on single-body pairs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeInfo {
    /// Lower bound of the models' distance (meters; distance and collide queries; the answer's
    /// distance). Growth queries: the answer's d.
    pub lower: Real,
    /// Upper bound of the models' distance (meters): the best leaf pair's distance (+∞ when no
    /// leaf pair was resolved). Growth and collide queries: equal to `lower`.
    pub upper: Real,
    /// The deepest tree level reached (0: decided by the root pair).
    pub level: usize,
    /// The active leaf pair (node of the first body's tree, node of the second's), when one
    /// decided (a single body is node 0 of its one-node tree).
    pub leaves: Option<(usize, usize)>,
    /// Node pairs solved (Newton solves, leaf pairs included).
    pub pairs_evaluated: usize,
    /// Node pairs decided by their bounding spheres alone (no solve).
    pub pairs_pruned_by_spheres: usize,
    /// Distance: upper − lower ≤ the tolerance asked for (and no leaf pair stayed unresolved).
    pub within_tolerance: bool,
    /// [`CertifyMode::NewtonOnly`] only: a leaf pair needs the SDP that mode does not solve.
    pub needs_sdp: bool,
}

/// One query of a batch: a kind, an ordered pair of instance ids and its options.
#[derive(Clone, Debug)]
pub struct QueryPair {
    /// Which query.
    pub kind: QueryKind,
    /// First instance (A, or p₁).
    pub first: String,
    /// Second instance (B, or p₂).
    pub second: String,
    /// Certification and gradient options.
    pub options: QueryOptions,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: Real,
}

impl QueryPair {
    /// This query by reference ([`PairRef`]).
    pub fn view(&self) -> PairRef<'_> {
        PairRef {
            kind: self.kind,
            first: &self.first,
            second: &self.second,
            options: self.options,
            margin: self.margin,
        }
    }
}

/// One query with borrowed instance ids: what [`crate::planner::answer_pair`] needs (the ids key
/// the warm starts). Built from a [`QueryPair`] ([`QueryPair::view`]) or from columns
/// ([`crate::Catalog::batch_columns`]) without allocating.
#[derive(Clone, Copy, Debug)]
pub struct PairRef<'a> {
    /// Which query.
    pub kind: QueryKind,
    /// First instance (A, or p₁).
    pub first: &'a str,
    /// Second instance (B, or p₂).
    pub second: &'a str,
    /// Certification and gradient options.
    pub options: QueryOptions,
    /// For [`QueryKind::Collide`]: the margin in meters (≥ 0); ignored otherwise.
    pub margin: Real,
}

impl PairRef<'_> {
    /// What the dispatcher reads of this query ([`sublevel_query::dispatch`]).
    #[inline]
    pub fn ask(&self) -> PairAsk {
        PairAsk { kind: self.kind, mode: self.options.mode, cold: self.options.cold, margin: self.margin }
    }
}

/// A certified distance answer with optional pose gradients.
#[derive(Clone, Debug)]
pub struct DistanceReply {
    /// The answer with its source and certificate.
    pub answer: CertifiedDistance,
    /// (∂D/∂ξ_a, ∂D/∂ξ_b) when asked for and the answer is not a lower bound (twists, see
    /// [`sublevel_query::gradient`]).
    pub gradients: Option<(PoseGradient, PoseGradient)>,
    /// The inputs limit the accuracy (see [`precision_limited`]).
    pub precision_limited: bool,
    /// The signed distance was asked for ([`QueryOptions::signed`]).
    pub signed: bool,
    /// With [`QueryOptions::signed`] on an overlapping answer of convex bodies: the penetration
    /// (not computed for compound pairs).
    pub penetration: Option<sublevel_query::penetration::Penetration>,
    /// Compound pairs: the bounds and cost of the tree query ([`TreeInfo`]).
    pub tree: Option<TreeInfo>,
}

/// A certified growth answer with optional pose gradients.
#[derive(Clone, Debug)]
pub struct GrowthReply {
    /// The answer with its source and certificate.
    pub answer: CertifiedGrowth,
    /// (∂d/∂ξ₁, ∂d/∂ξ₂) when asked for and the answer is not a lower bound.
    pub gradients: Option<(PoseGradient, PoseGradient)>,
    /// The inputs limit the accuracy (see [`precision_limited`]).
    pub precision_limited: bool,
    /// Compound pairs: the tree query's level and cost ([`TreeInfo`]).
    pub tree: Option<TreeInfo>,
}

/// Relative precision in a body's normalized coordinates below which an answer is flagged as
/// limited by its inputs: 1e-9, ten times the Newton KKT tolerance's square root region.
pub const PRECISION_LIMIT: Real = 1e-9;

/// True when one unit in the last place of the largest coordinate involved (the two poses'
/// translations and the bodies' centers, meters) exceeds [`PRECISION_LIMIT`] of the smaller
/// body's scale: the query's inputs already carry that error in normalized coordinates, before
/// any solver runs (e.g. a 1 mm body 500 km from the origin).
pub fn precision_limited(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> bool {
    let mag = [
        pose_a.translation.vector.amax(),
        pose_b.translation.vector.amax(),
        a.center().amax() + a.scale(),
        b.center().amax() + b.scale(),
    ]
    .into_iter()
    .fold(0.0, Real::max);
    mag * Real::EPSILON > PRECISION_LIMIT * a.scale().min(b.scale())
}

/// The answer of one query of a batch.
///
/// The distance variant is larger (its warm start carries earlier answers for the motion
/// predictor); answers are built once per query and moved, so boxing it would only add an
/// allocation to every query.
#[derive(Clone, Debug)]
#[allow(clippy::large_enum_variant)]
pub enum QueryAnswer {
    /// A distance answer.
    Distance(DistanceReply),
    /// A growth answer.
    Growth(GrowthReply),
    /// A collide-with-margin answer.
    Collide(CollideReply),
}

impl QueryAnswer {
    /// Whether this answer of a [`CertifyMode::NewtonOnly`] query needs the SDP that mode does not
    /// solve ([`sublevel_query::Certified::needs_sdp`]): ask again in [`CertifyMode::Newton`].
    pub fn needs_sdp(&self) -> bool {
        match self {
            QueryAnswer::Distance(d) => d.answer.needs_sdp,
            QueryAnswer::Growth(g) => g.answer.needs_sdp,
            QueryAnswer::Collide(c) => {
                c.solve.as_ref().is_some_and(|d| d.answer.needs_sdp) || c.tree.is_some_and(|t| t.needs_sdp)
            }
        }
    }
}

/// The answer of a collide-with-margin query.
#[derive(Clone, Debug)]
pub struct CollideReply {
    /// True when the bodies overlap or their distance is below `margin`.
    pub collides: bool,
    /// The solved distance (meters), or with `decided_by_bounds` a certified lower bound
    /// ([`sublevel_query::dispatch::collide_lower_bound`]: the bounding spheres, then the
    /// separating axis) when clear, and 0 when a common point proved overlap
    /// ([`sublevel_query::dispatch::collide_cheap`]).
    pub distance: Real,
    /// The cheap tests decided ([`sublevel_query::dispatch::collide_cheap`]: the bounding spheres
    /// or the separating axis cleared the margin, or a common point proved overlap): no solve ran.
    pub decided_by_bounds: bool,
    /// The distance solve, when one ran.
    pub solve: Option<DistanceReply>,
    /// The margin asked for (meters).
    pub margin: Real,
    /// Compound pairs: the tree query's bounds, level and cost (`distance` is then the deciding
    /// bound of [`sublevel_query::tree::TreeMarginResult`]; `solve` is `None`).
    pub tree: Option<TreeInfo>,
}

/// The warm-start table a query kind uses (collide queries solve distances).
pub(crate) fn warm_kind(kind: QueryKind) -> WarmKind {
    match kind {
        QueryKind::Distance | QueryKind::Collide => WarmKind::Distance,
        QueryKind::Growth => WarmKind::Growth,
    }
}
