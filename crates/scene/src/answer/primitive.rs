//! Queries between two instances of which at least one is an exact primitive (box, sphere,
//! cylinder, capsule, halfspace): step 0 of [`sublevel_query::dispatch`].
//!
//! ```text
//! distance(a, b)     primitive_pair_distance: shape_distance (closed forms, the active-set
//!                    method), a compound side searched leaf by leaf (the closest leaf's answer)
//! collide(a, b, m)   the bounding spheres' gap > m → clear, no solve; else the distance:
//!                    collides = overlapping or distance < m
//! growth             refused before anything is solved (defined for sos-convex bodies only)
//! ```
//!
//! `solve.converged` is true only for a converged answer with no nonconvex side (a nonconvex body
//! against a primitive gets a local solution). With [`CertifyMode::Certify`] a separated pair of
//! two primitives carries its separating-plane certificate ([`sublevel_query::shape`]: the plane
//! through the witnesses evaluated with the exact support functions, a lower bound of the
//! distance); no SDP runs for a primitive pair, so [`CertifyMode::NewtonOnly`] never needs one.
//! Warm starts are kept per ordered instance pair unless a side is compound (its node pairs run
//! cold). Signed distances (penetration depths) are not computed for primitive pairs: an
//! overlapping answer's signed distance is 0.

use super::types::{CollideReply, DistanceReply, PairRef, TreeInfo, PRECISION_LIMIT};
use crate::cache::WarmStartCache;
use std::sync::Arc;
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Point3, Real, Vector3};
use sublevel_query::dispatch::{self, PosedRef};
use sublevel_query::{
    distance_gradient, CertificateKind, CertificateSummary, CertifiedDistance, CertifyMode, DistanceResult, SolveStatus,
};

/// The distance reply of a pair with a primitive (module docs). A pair the shape query refuses
/// (two halfspaces, a nonconvex body's support against a halfspace) — the callers refuse the first
/// before asking — answers an unconverged lower bound 0.
pub(crate) fn distance_reply(
    pair: PairRef<'_>,
    a: &PosedRef<'_>,
    b: &PosedRef<'_>,
    cache: &mut WarmStartCache,
) -> DistanceReply {
    let o = &pair.options;
    let warm = if o.cold { None } else { cache.shape(pair.first, pair.second) };
    let limited = precision_limited(a, b);
    let found = match dispatch::primitive_pair_distance(a, b, warm) {
        Ok(found) => found,
        Err(e) => {
            tracing::warn!(error = %e, "primitive distance query refused");
            return DistanceReply {
                answer: CertifiedDistance::unresolved(unresolved()),
                gradients: None,
                precision_limited: limited,
                signed: o.signed,
                penetration: None,
                tree: None,
            };
        }
    };
    let d = &found.distance;
    let converged = found.converged();
    let result = DistanceResult {
        distance: d.distance,
        witness_a: d.witness_a,
        witness_b: d.witness_b,
        normal: d.normal,
        overlapping: d.overlapping,
        status: d.status,
        iterations: d.iterations,
        kkt_residual: d.kkt_residual,
        warm_started: d.warm_started,
        warm_start: Arc::default(),
    };
    let certificate = match (o.mode, d.lower_bound) {
        (CertifyMode::Certify, Some(lower)) => Some(plane_certificate(d.distance, lower)),
        _ => None,
    };
    let gradients = (o.with_gradient && converged).then(|| distance_gradient(&result));
    let tree = found.compound.then_some(TreeInfo {
        lower: d.distance,
        upper: d.distance,
        level: found.level,
        leaves: found.leaves,
        pairs_evaluated: found.pairs_evaluated,
        pairs_pruned_by_spheres: found.pairs_pruned_by_spheres,
        within_tolerance: converged,
        needs_sdp: false,
    });
    if !o.cold && !found.compound && converged {
        cache.put_shape(pair.first, pair.second, d.warm_start);
    }
    let answer = CertifiedDistance::newton(result, certificate, converged);
    DistanceReply { answer, gradients, precision_limited: limited, signed: o.signed, penetration: None, tree }
}

/// The collide-with-margin reply of a pair with a primitive: clear by the bounding spheres when
/// their gap exceeds the margin (no solve), else by the distance reply.
pub(crate) fn collide_reply(
    pair: PairRef<'_>,
    a: &PosedRef<'_>,
    b: &PosedRef<'_>,
    cache: &mut WarmStartCache,
) -> CollideReply {
    if let Some(lower) = dispatch::primitive_lower_bound(a, b).filter(|l| *l > pair.margin) {
        return CollideReply {
            collides: false,
            distance: lower,
            decided_by_bounds: true,
            solve: None,
            margin: pair.margin,
            tree: None,
        };
    }
    let d = distance_reply(pair, a, b, cache);
    let r = &d.answer.result;
    CollideReply {
        collides: r.overlapping || r.distance < pair.margin,
        distance: r.distance,
        decided_by_bounds: false,
        margin: pair.margin,
        tree: d.tree,
        solve: Some(d),
    }
}

/// The separating-plane certificate of a separated pair of primitives, in the units of a distance
/// certificate (squared meters): bound and verified bound are `lower`², and it agrees when
/// `distance − lower` is within 10⁻⁹ m or 10⁻⁶ of the distance.
fn plane_certificate(distance: Real, lower: Real) -> CertificateSummary {
    let lower = lower.max(0.0);
    let gap = (distance - lower).abs();
    CertificateSummary {
        bound: lower * lower,
        verified_bound: lower * lower,
        agrees: gap <= 1e-9 || gap <= 1e-6 * distance,
        relative_gap: gap / distance.max(1e-9),
        gram_min_eigenvalue: 0.0,
        solve_seconds: 0.0,
        solver_status: SdpStatus::ClosedForm,
        kind: CertificateKind::SeparatingHyperplane,
        verified: true,
        newton_value: Some(distance * distance),
    }
}

/// A distance result standing for "not answered": distance 0, no witnesses (NaN).
fn unresolved() -> DistanceResult {
    let nan = Point3::new(Real::NAN, Real::NAN, Real::NAN);
    DistanceResult {
        distance: 0.0,
        witness_a: nan,
        witness_b: nan,
        normal: Vector3::zeros(),
        overlapping: true,
        status: SolveStatus::Stalled,
        iterations: 0,
        kkt_residual: Real::NAN,
        warm_started: false,
        warm_start: Arc::default(),
    }
}

/// [`super::precision_limited`] for sides that may be primitives: one ulp of the largest
/// coordinate involved (a pose's translation, how far a side reaches from it) against
/// [`PRECISION_LIMIT`] of the smaller side's scale ([`sublevel_core::primitive::Primitive::scale`]
/// for a primitive).
fn precision_limited(a: &PosedRef<'_>, b: &PosedRef<'_>) -> bool {
    let side = |s: &PosedRef<'_>| match s.primitive {
        Some(p) => {
            let reach = if p.is_bounded() { p.bounding_radius() } else { p.scale() };
            (s.pose.translation.vector.amax() + reach, p.scale())
        }
        None => (s.pose.translation.vector.amax().max(s.body.center().amax() + s.body.scale()), s.body.scale()),
    };
    let ((ma, sa), (mb, sb)) = (side(a), side(b));
    ma.max(mb) * Real::EPSILON > PRECISION_LIMIT * sa.min(sb)
}
