//! Queries between two instances of which at least one is a compound body: the branch and bound
//! over containment trees ([`sublevel_query::tree`]), step 1 of [`sublevel_query::dispatch`].
//!
//! ```text
//! distance(a, b)   tree_distance      lower ≤ min over leaf pairs dist(A_i, B_j) ≤ upper
//!                                     the answer's distance is `lower` (conservative); witnesses,
//!                                     normal, gradients and certificate are the best leaf pair's
//! growth(1, 2)     tree_collide       overlap iff some leaf pair has d(p_1i‖p_2j) ≤ 1; the value is
//!                  (exhaustive)       the smallest such d, +∞ when no leaf pair overlaps
//! collide(a, b, m) tree_closer_than   stops at the coarsest tree level that decides "closer than m"
//! ```
//!
//! A single body on either side is a one-node tree. Warm starts are kept per ordered instance pair
//! as a [`sublevel_query::tree::TreeWarmStart`] (one solver state per node pair) in the same caches
//! as single-body warm starts. [`CertifyMode::NewtonOnly`] (the async workers' mode) runs no SDP: a
//! leaf pair whose Newton solve does not converge stays unresolved and the answer says it needs the
//! SDP ([`TreeInfo::needs_sdp`]), so the service asks again on its SDP slots.

use super::types::{precision_limited, CollideReply, DistanceReply, GrowthReply, PairRef, TreeInfo};
use crate::cache::WarmStartCache;
use std::sync::Arc;
use sublevel_core::math::{Point3, Real, Vector3};
use sublevel_query::dispatch::{tree_params, PosedRef};
use sublevel_query::tree::{tree_closer_than, tree_collide, tree_distance};
use sublevel_query::{
    AnswerSource, CertifiedDistance, CertifiedGrowth, CertifyMode, CertifyParams, DistanceResult, GrowthResult,
    SolveStatus,
};

/// A distance result standing for "no leaf pair resolved": distance `lower`, no witnesses (NaN).
fn unresolved_distance(lower: Real) -> DistanceResult {
    let nan = Point3::new(Real::NAN, Real::NAN, Real::NAN);
    DistanceResult {
        distance: lower,
        witness_a: nan,
        witness_b: nan,
        normal: Vector3::zeros(),
        overlapping: lower <= 0.0,
        status: SolveStatus::Stalled,
        iterations: 0,
        kkt_residual: Real::NAN,
        warm_started: false,
        warm_start: Arc::default(),
    }
}

/// A growth result standing for "no leaf pair overlaps" (value +∞) or "none resolved".
fn empty_growth(value: Real, status: SolveStatus) -> GrowthResult {
    GrowthResult {
        value,
        minimizer: Point3::new(Real::NAN, Real::NAN, Real::NAN),
        multiplier: 0.0,
        status,
        iterations: 0,
        kkt_residual: 0.0,
        warm_started: false,
        warm_start: Arc::default(),
    }
}

/// Distance between a compound pair (module docs); `pair.options.cold` ignores and leaves no warm
/// start. An invalid tree cannot reach here (trees are validated when stored); should the tree
/// query refuse anyway, the answer is an unconverged lower bound 0.
pub(crate) fn distance_reply(
    pair: PairRef<'_>,
    a: &PosedRef<'_>,
    b: &PosedRef<'_>,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
) -> DistanceReply {
    let o = &pair.options;
    let warm = if o.cold { None } else { cache.tree_distance(pair.first, pair.second) };
    let tp = tree_params(params, o.mode, o.tolerance);
    let limited = precision_limited(a.body, &a.pose, b.body, &b.pose);
    let t = match tree_distance(a.as_tree(), &a.pose, b.as_tree(), &b.pose, warm, &tp) {
        Ok(t) => t,
        Err(e) => {
            tracing::warn!(error = %e, "tree distance query refused");
            let answer = CertifiedDistance::unresolved(unresolved_distance(0.0));
            return DistanceReply {
                answer,
                gradients: None,
                precision_limited: limited,
                signed: o.signed,
                penetration: None,
                tree: None,
            };
        }
    };
    let needs_sdp = o.mode == CertifyMode::NewtonOnly && !t.converged;
    let gradients = if o.with_gradient { t.gradient() } else { None };
    let best = t.best.as_ref().filter(|l| l.exact);
    let mut result = best.map_or_else(|| unresolved_distance(t.lower), |l| l.result.clone());
    result.distance = t.lower;
    result.overlapping = t.overlapping();
    let info = TreeInfo {
        lower: t.lower,
        upper: t.upper,
        level: t.level,
        leaves: best.map(|l| l.leaves),
        pairs_evaluated: t.pairs_evaluated,
        pairs_pruned_by_spheres: t.pairs_pruned_by_spheres,
        within_tolerance: t.within_tolerance,
        needs_sdp,
    };
    let answer = CertifiedDistance {
        result,
        source: best.map_or(AnswerSource::Newton, |l| l.source),
        certificate: best.and_then(|l| l.certificate.clone()),
        lower_bound: false,
        tight: false,
        converged: t.converged && t.within_tolerance,
        needs_sdp,
    };
    if !o.cold && !needs_sdp {
        cache.put_tree_distance(pair.first, pair.second, Arc::new(t.warm_start));
    }
    DistanceReply {
        answer,
        gradients,
        precision_limited: limited,
        signed: o.signed,
        penetration: None,
        tree: Some(info),
    }
}

/// Growth between a compound pair (module docs): the smallest d over overlapping leaf pairs.
pub(crate) fn growth_reply(
    pair: PairRef<'_>,
    a: &PosedRef<'_>,
    b: &PosedRef<'_>,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
) -> GrowthReply {
    let o = &pair.options;
    let warm = if o.cold { None } else { cache.tree_growth(pair.first, pair.second) };
    let tp = tree_params(params, o.mode, 0.0);
    let limited = precision_limited(a.body, &a.pose, b.body, &b.pose);
    let refused = |e: sublevel_core::Error| {
        tracing::warn!(error = %e, "tree growth query refused");
        let answer = CertifiedGrowth::unresolved(empty_growth(0.0, SolveStatus::Stalled));
        GrowthReply { answer, gradients: None, precision_limited: limited, tree: None }
    };
    let t = match tree_collide(a.as_tree(), &a.pose, b.as_tree(), &b.pose, true, warm, &tp) {
        Ok(t) => t,
        Err(e) => return refused(e),
    };
    let needs_sdp = o.mode == CertifyMode::NewtonOnly && !t.converged;
    let result = match (&t.growth, t.colliding) {
        (Some(g), _) => g.clone(),
        // Separated: no leaf pair overlaps.
        (None, false) => empty_growth(Real::INFINITY, SolveStatus::Converged),
        // Colliding without a resolved pair: the conservative "not proven separated".
        (None, true) => empty_growth(0.0, SolveStatus::Stalled),
    };
    let info = TreeInfo {
        lower: result.value,
        upper: result.value,
        level: t.level,
        leaves: t.leaves,
        pairs_evaluated: t.pairs_evaluated,
        pairs_pruned_by_spheres: t.pairs_pruned_by_spheres,
        within_tolerance: t.converged,
        needs_sdp,
    };
    let gradients = if o.with_gradient { t.gradient } else { None };
    let answer = CertifiedGrowth {
        result,
        source: AnswerSource::Newton,
        certificate: None,
        lower_bound: false,
        tight: false,
        converged: t.converged,
        needs_sdp,
    };
    if !o.cold && !needs_sdp {
        cache.put_tree_growth(pair.first, pair.second, Arc::new(t.warm_start));
    }
    GrowthReply { answer, gradients, precision_limited: limited, tree: Some(info) }
}

/// Collide-with-margin between a compound pair: "closer than `pair.margin`?", decided at the
/// coarsest tree level that can (module docs).
pub(crate) fn collide_reply(
    pair: PairRef<'_>,
    a: &PosedRef<'_>,
    b: &PosedRef<'_>,
    cache: &mut WarmStartCache,
    params: &CertifyParams,
) -> CollideReply {
    let o = &pair.options;
    let warm = if o.cold { None } else { cache.tree_distance(pair.first, pair.second) };
    let tp = tree_params(params, o.mode, 0.0);
    let t = match tree_closer_than(a.as_tree(), &a.pose, b.as_tree(), &b.pose, pair.margin, warm, &tp) {
        Ok(t) => t,
        Err(e) => {
            tracing::warn!(error = %e, "tree collide query refused");
            return CollideReply {
                collides: true,
                distance: 0.0,
                decided_by_bounds: false,
                solve: None,
                margin: pair.margin,
                tree: None,
            };
        }
    };
    let needs_sdp = o.mode == CertifyMode::NewtonOnly && !t.converged;
    let info = TreeInfo {
        lower: t.bound,
        upper: t.bound,
        level: t.level,
        leaves: t.leaves,
        pairs_evaluated: t.pairs_evaluated,
        pairs_pruned_by_spheres: t.pairs_pruned_by_spheres,
        within_tolerance: t.converged,
        needs_sdp,
    };
    if !o.cold && !needs_sdp {
        cache.put_tree_distance(pair.first, pair.second, Arc::new(t.warm_start));
    }
    CollideReply {
        collides: t.closer,
        distance: t.bound,
        decided_by_bounds: t.pairs_evaluated == 0,
        solve: None,
        margin: pair.margin,
        tree: Some(info),
    }
}
