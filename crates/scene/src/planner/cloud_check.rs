//! The point clouds of [`super::check_scene`]: each checked instance against each of the scene's
//! clouds, reported as one pair (instance id, cloud name) with the distance to the cloud's
//! nearest point ball when it overlaps or lies within the margin.
//!
//! ```text
//! candidates  a bounded instance: the points within its bounding ball grown by r + m (one
//!             k-d tree radius query), each with a lower bound max(box gap, ball gap) − r;
//!             a halfspace: the point deepest along its normal (a pass over the points)
//! solves      candidates by increasing lower bound, each the exact distance between the
//!             instance and the point's ball (sublevel_query::shape: a Sphere of radius r at
//!             the point; a compound body searched leaf by leaf), stopping at the first overlap
//!             or once the lower bound reaches the best distance found
//! ```
//!
//! A point ball of radius under 1 µm (noise radius 0) is solved as a 1 µm ball and its distance
//! corrected by the difference: an overlap with it is within 1 µm of the point.
//!
//! A cloud of the bodies model ([`crate::catalog::CloudBodiesModel`]) is its cluster bodies: the
//! candidates are the bodies whose box lies within the margin of the instance's box, solved as
//! body pairs by increasing box gap, with the same stopping rule; the pair reports the nearest.

use super::check::world_aabb;
use super::{SceneCheck, ScenePair};
use crate::answer::{self, DistanceReply, Posed, QueryKind, QueryOptions, QueryPair};
use crate::cache::WarmStartCache;
use crate::catalog::{CloudBodiesModel, CloudSet, PosedInstance};
use crate::Result;
use std::sync::Arc;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_core::primitive::Primitive;
use sublevel_query::CertifyParams;
use sublevel_robot::PointCloud;

/// Smallest ball radius solved (meters): see the module docs.
const MIN_BALL_RADIUS: Real = 1e-6;

/// Adds to `out` the pairs of the instances of `all` marked in `is_focus` with the clouds of
/// `clouds` that overlap or lie closer than `margin` (module docs), counting the pairs
/// (`all_pairs`), those with candidate points (`candidate_pairs`) and the solves.
///
/// # Errors
/// [`crate::Error::Cancelled`] when the request was abandoned.
pub(super) fn cloud_pairs(
    all: &[PosedInstance],
    is_focus: &[bool],
    clouds: &CloudSet,
    margin: Real,
    params: &CertifyParams,
    out: &mut SceneCheck,
) -> Result<()> {
    if clouds.is_empty() {
        return Ok(());
    }
    // The sphere side's body is read by no step of a primitive pair (sublevel_query::dispatch).
    let stand_in = Arc::new(sublevel_core::body::ellipsoid([0.0; 3], [1.0; 3])?);
    let mut scratch = WarmStartCache::default();
    let mut near = Vec::new();
    for (inst, _) in all.iter().zip(is_focus).filter(|(_, f)| **f) {
        for (name, c) in clouds.iter() {
            out.all_pairs += 1;
            if let Some(model) = &c.bodies {
                body_pair(inst, name, model, margin, params, &mut scratch, out)?;
                continue;
            }
            let cloud = &c.cloud;
            let candidates = candidates(inst, cloud, margin, &mut near);
            let r = cloud.radius();
            let solved = MIN_BALL_RADIUS.max(r);
            let ball = |k: usize| {
                let p = cloud.point(k);
                let b = Posed {
                    body: stand_in.clone(),
                    tree: None,
                    primitive: Some(Primitive::Sphere { radius: solved }),
                    pose: Isometry3::translation(p.x, p.y, p.z),
                };
                (b, solved - r)
            };
            nearest_pair(inst, name, candidates, margin, params, &mut scratch, out, ball)?;
        }
    }
    Ok(())
}

/// The pair of instance `inst` and the bodies model `model` of cloud `name` (module docs):
/// pushed to `out` when the nearest body overlaps the instance or lies within `margin`.
fn body_pair(
    inst: &PosedInstance,
    name: &str,
    model: &CloudBodiesModel,
    margin: Real,
    params: &CertifyParams,
    scratch: &mut WarmStartCache,
    out: &mut SceneCheck,
) -> Result<()> {
    let boxed = world_aabb(inst);
    let mut candidates: Vec<(Real, usize)> = model
        .objects
        .iter()
        .enumerate()
        .filter_map(|(k, b)| {
            let lower = match (boxed, b.body().bounding_box()) {
                (Some((lo, hi)), Some((c, h))) => {
                    (lo - c.coords - h).sup(&(c.coords - h - hi)).sup(&Vector3::zeros()).norm()
                }
                _ => 0.0,
            };
            (lower <= margin).then_some((lower, k))
        })
        .collect();
    candidates.sort_by(|x, y| x.0.total_cmp(&y.0));
    let body = |k: usize| {
        let b = model.objects[k].shared().clone();
        (Posed { body: b, tree: None, primitive: None, pose: Isometry3::identity() }, 0.0)
    };
    nearest_pair(inst, name, candidates, margin, params, scratch, out, body)
}

/// The pair of instance `inst` and cloud `name` from `candidates` (a lower bound of the distance
/// and an index, by increasing bound): each solved against `obstacle(k)` (a posed shape and a
/// correction added to a free distance) until one overlaps or the bound reaches the best distance;
/// the nearest is pushed to `out` when it overlaps or lies within `margin`. Counts the pair as a
/// candidate pair (when it has candidates) and every solve.
///
/// # Errors
/// [`crate::Error::Cancelled`] when the request was abandoned.
#[allow(clippy::too_many_arguments)]
fn nearest_pair(
    inst: &PosedInstance,
    name: &str,
    candidates: Vec<(Real, usize)>,
    margin: Real,
    params: &CertifyParams,
    scratch: &mut WarmStartCache,
    out: &mut SceneCheck,
    obstacle: impl Fn(usize) -> (Posed, Real),
) -> Result<()> {
    if candidates.is_empty() {
        return Ok(());
    }
    out.candidate_pairs += 1;
    let pair = QueryPair {
        kind: QueryKind::Distance,
        first: inst.id.clone(),
        second: name.to_owned(),
        options: QueryOptions { cold: true, ..QueryOptions::default() },
        margin,
    };
    let a = Posed { body: inst.body.clone(), tree: inst.tree.clone(), primitive: inst.primitive, pose: inst.pose };
    let mut best: Option<DistanceReply> = None;
    for (lower, k) in candidates {
        if best.as_ref().is_some_and(|b| b.answer.result.distance <= lower) {
            break;
        }
        sublevel_core::cancel::check()?;
        out.narrow_phase_solves += 1;
        let (b, correction) = obstacle(k);
        let mut d = answer::any_distance_reply(pair.view(), &a, &b, scratch, params, None);
        let result = &mut d.answer.result;
        if !result.overlapping {
            result.distance += correction;
        }
        let overlapping = result.overlapping;
        if overlapping || best.as_ref().is_none_or(|b| d.answer.result.distance < b.answer.result.distance) {
            best = Some(d);
        }
        if overlapping {
            break;
        }
    }
    if let Some(d) = best {
        let res = &d.answer.result;
        if res.overlapping || res.distance < margin {
            out.pairs.push(ScenePair { first: inst.id.clone(), second: name.to_owned(), distance: d });
        }
    }
    Ok(())
}

/// The points of `cloud` whose ball may lie within `margin` of instance `inst`, each with a lower
/// bound of that distance, by increasing bound (module docs); `near` is scratch.
fn candidates(inst: &PosedInstance, cloud: &PointCloud, margin: Real, near: &mut Vec<usize>) -> Vec<(Real, usize)> {
    let r = cloud.radius();
    if let Some(Primitive::Halfspace { normal, offset }) = inst.primitive {
        // {x : n·x ≤ d} in the world: n_w = R n, d_w = d + n_w·t.
        let n = inst.pose.rotation * normal;
        let d = offset + n.dot(&inst.pose.translation.vector);
        let deepest = (0..cloud.len()).map(|k| (n.dot(&cloud.point(k)) - d, k)).min_by(|x, y| x.0.total_cmp(&y.0));
        return deepest
            .map(|(gap, k)| (gap.max(0.0) - r, k))
            .filter(|(lower, _)| *lower <= margin)
            .into_iter()
            .collect();
    }
    let (center, radius, aabb) = match world_aabb(inst) {
        Some((lo, hi)) => ((lo + hi) * 0.5, (hi - lo).norm() * 0.5, Some((lo, hi))),
        None => match inst.body.bounding_sphere() {
            Some((c, radius)) => (inst.pose.transform_point(&c).coords, radius, None),
            // Nothing bounds it: no candidate (a body without a bounding volume is refused
            // elsewhere before it gets here).
            None => return Vec::new(),
        },
    };
    near.clear();
    cloud.within(&center, radius + r + margin, near);
    let mut out: Vec<(Real, usize)> = near
        .iter()
        .map(|&k| {
            let p = cloud.point(k);
            let ball = (p - center).norm() - radius;
            let boxed =
                aabb.map_or(0.0, |(lo, hi): (Vector3, Vector3)| (lo - p).sup(&(p - hi)).sup(&Vector3::zeros()).norm());
            (ball.max(boxed) - r, k)
        })
        .filter(|(lower, _)| *lower <= margin)
        .collect();
    out.sort_by(|x, y| x.0.total_cmp(&y.0));
    out
}
