//! Queries and answers: solve statuses, distance and growth answers (with certificates, gradients
//! and signed distances), query options, and the pairs of `BatchQuery`.

use super::scenes::{point_to_proto, vector_to_proto};
use super::{prefix_field, require_id};
use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::Real;
use sublevel_query::{
    AnswerSource, CertificateSummary, CertifyMode, DistanceResult, GrowthResult, PoseGradient, SolveStatus,
};
use sublevel_scene::{DistanceReply, GrowthReply, QueryAnswer, QueryKind, QueryOptions, TreeInfo};

/// A solve status as the proto enum.
pub fn status_to_proto(s: SolveStatus) -> pb::SolveStatus {
    match s {
        SolveStatus::Converged => pb::SolveStatus::Converged,
        SolveStatus::MaxIterations => pb::SolveStatus::MaxIterations,
        SolveStatus::Stalled => pb::SolveStatus::Stalled,
    }
}

fn solve_info(status: SolveStatus, iterations: usize, kkt_residual: Real, warm_started: bool) -> pb::SolveInfo {
    pb::SolveInfo {
        converged: status.converged(),
        status: status_to_proto(status) as i32,
        iterations: u32::try_from(iterations).unwrap_or(u32::MAX),
        kkt_residual,
        warm_started,
        precision_limited: false,
    }
}

/// A distance answer as the proto message.
pub fn distance_to_proto(r: &DistanceResult) -> pb::DistanceAnswer {
    pb::DistanceAnswer {
        distance: r.distance,
        witness_a: Some(point_to_proto(&r.witness_a)),
        witness_b: Some(point_to_proto(&r.witness_b)),
        normal: Some(vector_to_proto(&r.normal)),
        overlapping: r.overlapping,
        solve: Some(solve_info(r.status, r.iterations, r.kkt_residual, r.warm_started)),
        ..Default::default()
    }
}

/// A growth answer as the proto message.
pub fn growth_to_proto(r: &GrowthResult) -> pb::GrowthAnswer {
    pb::GrowthAnswer {
        value: r.value,
        minimizer: Some(point_to_proto(&r.minimizer)),
        multiplier: r.multiplier,
        separated: r.value > 1.0,
        solve: Some(solve_info(r.status, r.iterations, r.kkt_residual, r.warm_started)),
        ..Default::default()
    }
}

/// An answer source as the proto enum.
pub fn source_to_proto(s: AnswerSource) -> pb::AnswerSource {
    match s {
        AnswerSource::Newton => pb::AnswerSource::Newton,
        AnswerSource::SdpFallback => pb::AnswerSource::SdpFallback,
        AnswerSource::SdpLowerBound => pb::AnswerSource::SdpLowerBound,
    }
}

/// A certificate summary as the proto message.
pub fn certificate_to_proto(c: &CertificateSummary) -> pb::Certificate {
    pb::Certificate {
        bound: c.bound,
        verified_bound: c.verified_bound,
        agrees: c.agrees,
        relative_gap: c.relative_gap,
        gram_min_eigenvalue: c.gram_min_eigenvalue,
        solve_seconds: c.solve_seconds,
        verified: c.verified,
        newton_value: c.newton_value.unwrap_or(Real::NAN),
        solver_status: super::sdp_status_to_proto(c.solver_status) as i32,
    }
}

/// The tree part of a compound pair's answer as the proto message.
pub fn tree_to_proto(t: &TreeInfo) -> pb::TreeAnswer {
    let count = |n: usize| u64::try_from(n).unwrap_or(u64::MAX);
    let node = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
    pb::TreeAnswer {
        lower: t.lower,
        upper: t.upper,
        level: node(t.level),
        leaves: t.leaves.map(|(a, b)| pb::LeafPair { node_a: node(a), node_b: node(b) }),
        pairs_evaluated: count(t.pairs_evaluated),
        pairs_pruned_by_spheres: count(t.pairs_pruned_by_spheres),
        within_tolerance: t.within_tolerance,
    }
}

/// Checks a compound pair's bound tolerance (`DistanceRequest.tolerance` and the like).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` unless it is finite and ≥ 0 meters.
pub fn tree_tolerance(field: &str, tolerance: Real) -> Result<Real> {
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(Error::invalid(field, format!("must be finite and >= 0 meters, got {tolerance}")));
    }
    Ok(tolerance)
}

/// A pose gradient as the proto message.
pub fn gradient_to_proto(g: &PoseGradient) -> pb::PoseGradient {
    pb::PoseGradient { linear: Some(vector_to_proto(&g.linear)), angular: Some(vector_to_proto(&g.angular)) }
}

/// A certified distance answer (with optional gradients) as the proto message; `solve.converged`
/// is the certified answer's `converged`.
pub fn distance_reply_to_proto(r: &DistanceReply) -> pb::DistanceAnswer {
    let c = &r.answer;
    let mut out = distance_to_proto(&c.result);
    if let Some(solve) = out.solve.as_mut() {
        solve.converged = c.converged;
        solve.precision_limited = r.precision_limited;
    }
    out.source = source_to_proto(c.source) as i32;
    out.certificate = c.certificate.as_ref().map(certificate_to_proto);
    out.lower_bound = c.lower_bound;
    out.tight = c.tight;
    out.tree = r.tree.as_ref().map(tree_to_proto);
    if let Some((ga, gb)) = &r.gradients {
        out.gradient_a = Some(gradient_to_proto(ga));
        out.gradient_b = Some(gradient_to_proto(gb));
    }
    if r.signed && !c.lower_bound {
        match &r.penetration {
            Some(p) => {
                out.signed_distance = -p.depth;
                out.penetration_depth = p.depth;
                out.penetration_normal = Some(vector_to_proto(&p.normal));
                if r.gradients.is_some() {
                    let (ga, gb) = sublevel_query::penetration::penetration_gradient(p);
                    out.signed_gradient_a = Some(gradient_to_proto(&ga));
                    out.signed_gradient_b = Some(gradient_to_proto(&gb));
                }
            }
            None => {
                out.signed_distance = c.result.distance;
                out.signed_gradient_a = out.gradient_a;
                out.signed_gradient_b = out.gradient_b;
            }
        }
    }
    out
}

/// A certified growth answer (with optional gradients) as the proto message.
pub fn growth_reply_to_proto(r: &GrowthReply) -> pb::GrowthAnswer {
    let c = &r.answer;
    let mut out = growth_to_proto(&c.result);
    if let Some(solve) = out.solve.as_mut() {
        solve.converged = c.converged;
        solve.precision_limited = r.precision_limited;
    }
    out.source = source_to_proto(c.source) as i32;
    out.certificate = c.certificate.as_ref().map(certificate_to_proto);
    out.lower_bound = c.lower_bound;
    out.tight = c.tight;
    if let Some((g1, g2)) = &r.gradients {
        out.gradient_1 = Some(gradient_to_proto(g1));
        out.gradient_2 = Some(gradient_to_proto(g2));
    }
    out.tree = r.tree.as_ref().map(tree_to_proto);
    out
}

/// The query options of a request's `certify` / `with_gradient` flags.
pub fn query_options(certify: bool, with_gradient: bool) -> QueryOptions {
    QueryOptions {
        mode: if certify { CertifyMode::Certify } else { CertifyMode::Newton },
        with_gradient,
        cold: false,
        signed: false,
        tolerance: 0.0,
    }
}

/// A batch answer as the proto message.
pub fn answer_to_proto(a: &QueryAnswer) -> pb::QueryAnswer {
    let answer = match a {
        QueryAnswer::Distance(d) => pb::query_answer::Answer::Distance(distance_reply_to_proto(d)),
        QueryAnswer::Growth(g) => pb::query_answer::Answer::Growth(growth_reply_to_proto(g)),
        QueryAnswer::Collide(c) => pb::query_answer::Answer::Collide(pb::CollideAnswer {
            collides: c.collides,
            distance: c.distance,
            decided_by_bounds: c.decided_by_bounds,
            solve: c.solve.as_ref().and_then(|d| distance_reply_to_proto(d).solve),
            margin: c.margin,
            tree: c.tree.as_ref().map(tree_to_proto),
        }),
    };
    pb::QueryAnswer { answer: Some(answer) }
}

/// Validates the pairs of a `BatchQuery`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `pairs[k].kind` / `pairs[k].first` / `pairs[k].second`;
/// [`Error::ResourceExhausted`] above `max_pairs`.
pub fn pairs_from_proto(pairs: &[pb::QueryPair], max_pairs: usize) -> Result<Vec<sublevel_scene::QueryPair>> {
    if pairs.len() > max_pairs {
        return Err(Error::ResourceExhausted(format!(
            "`pairs`: {} entries exceed the limit of {max_pairs}",
            pairs.len()
        )));
    }
    pairs
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let kind = match pb::QueryKind::try_from(p.kind) {
                Ok(pb::QueryKind::Distance) => QueryKind::Distance,
                Ok(pb::QueryKind::Growth) => QueryKind::Growth,
                _ => return Err(Error::invalid(format!("pairs[{k}].kind"), "must be DISTANCE or GROWTH")),
            };
            let at = |e| prefix_field(e, &format!("pairs[{k}]"));
            require_id("first", &p.first).map_err(at)?;
            require_id("second", &p.second).map_err(at)?;
            let tolerance = tree_tolerance(&format!("pairs[{k}].tolerance"), p.tolerance)?;
            Ok(sublevel_scene::QueryPair {
                kind,
                first: p.first.clone(),
                second: p.second.clone(),
                options: QueryOptions { signed: p.signed, tolerance, ..query_options(p.certify, p.with_gradient) },
                margin: 0.0,
            })
        })
        .collect()
}
