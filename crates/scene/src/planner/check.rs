//! [`check_scene`]: every pair of a scene closer than a margin, with a broad phase.

use super::{check_unique, ids_of};
use crate::answer::{self, DistanceReply, PairRef, Posed, QueryKind, QueryOptions, QueryPair};
use crate::cache::WarmStartCache;
use crate::catalog::Catalog;
use crate::{Error, Result};
use std::collections::HashMap;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_query::dispatch::{self, PosedRef};

/// A pair found by [`check_scene`].
#[derive(Clone, Debug)]
pub struct ScenePair {
    /// First instance (the smaller id; the instance of an instance–cloud pair).
    pub first: String,
    /// Second instance, or the name of a point cloud.
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
    /// Pairs a brute-force check examines (instance–cloud pairs included).
    pub all_pairs: u64,
    /// The scene version the check read ([`Catalog::scene_version`]).
    pub scene_version: u64,
}

/// Every pair of a scene (or of `focus` against the rest) that overlaps or lies closer than
/// `margin` meters, with `overrides` applied to the stored poses (not stored). Broad phase: a BVH
/// (parry's) over the posed bounding boxes grown by `margin / 2`; then the bounding spheres, and
/// for two single bodies the separating axis ([`sublevel_query::dispatch::pair_lower_bound`]);
/// then cold distance solves on what remains. A nonconvex body or a halfspace (no bounded box) is
/// a candidate for every pair; a pair of two halfspaces (no finite distance) is never reported.
/// Pairs with a primitive are solved by [`sublevel_query::shape`], converged or not as each
/// answer says. Each checked instance is also checked against each of the scene's point clouds,
/// one pair per instance and cloud (the nearest point ball). Instances, poses and clouds are
/// read under one lock: one moment of the scene, whose version the check reports.
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
    let (mut all, clouds, scene_version) = catalog.posed_scene(scene_id)?;
    let index: HashMap<String, usize> = all.iter().enumerate().map(|(k, i)| (i.id.clone(), k)).collect();
    for (k, (id, pose)) in overrides.iter().enumerate() {
        let at = *index
            .get(id)
            .ok_or_else(|| Error::not_found_at(format!("poses[{k}].instance_id"), "instance", id.as_str()))?;
        all[at].pose = *pose;
    }
    let mut is_focus = vec![focus.is_empty(); all.len()];
    for (k, id) in focus.iter().enumerate() {
        let at =
            *index.get(id).ok_or_else(|| Error::not_found_at(format!("instance_ids[{k}]"), "instance", id.as_str()))?;
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
    let far = sublevel_core::math::MAX_COORDINATE * 4.0;
    let boxes: Vec<Aabb> = all
        .iter()
        .map(|i| match world_aabb(i) {
            Some((lo, hi)) => {
                let (lo, hi) = (lo.add_scalar(-half), hi.add_scalar(half));
                Aabb::new([lo.x, lo.y, lo.z].into(), [hi.x, hi.y, hi.z].into())
            }
            None => Aabb::new([-far; 3].into(), [far; 3].into()),
        })
        .collect();
    let mut out = SceneCheck { instances: n, all_pairs, scene_version, ..SceneCheck::default() };
    let params = catalog.certify_params();
    super::cloud_check::cloud_pairs(&all, &is_focus, &clouds, margin, &params, &mut out)?;
    if n < 2 {
        out.pairs.sort_by(|x, y| x.distance.answer.result.distance.total_cmp(&y.distance.answer.result.distance));
        return Ok(out);
    }
    let bvh = Bvh::from_leaves(BvhBuildStrategy::Binned, &boxes);
    let mut candidates: Vec<(usize, usize)> = bvh
        .leaf_pairs(&bvh, |x, y| x.aabb().intersects(&y.aabb()))
        .map(|(i, j)| (i as usize, j as usize))
        .filter(|&(i, j)| i < j && (is_focus[i] || is_focus[j]) && !(halfspace(&all[i]) && halfspace(&all[j])))
        .collect();
    candidates.sort_unstable();
    candidates.dedup();
    out.candidate_pairs += candidates.len() as u64;
    let options = QueryOptions { cold: true, ..QueryOptions::default() };
    let mut scratch = WarmStartCache::default();
    // The narrow phase: the candidates the cheap bounds do not clear (a compound body's root
    // sphere; two single bodies' spheres, then their separating axis), as cold distance queries;
    // those of one body pair solved on the batch solver's lanes first.
    let solves: Vec<(usize, usize)> = candidates
        .into_iter()
        .filter(|&(i, j)| {
            let at = |k: usize| PosedRef {
                body: &all[k].body,
                tree: all[k].tree.as_deref(),
                primitive: all[k].primitive.as_ref(),
                pose: all[k].pose,
            };
            dispatch::pair_lower_bound(&at(i), &at(j), margin).is_none_or(|lower| lower <= margin)
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
            let posed = |k: usize| Posed {
                body: all[k].body.clone(),
                tree: all[k].tree.clone(),
                primitive: all[k].primitive,
                pose: all[k].pose,
            };
            (posed(i), posed(j))
        })
        .collect();
    let views: Vec<PairRef<'_>> = queries.iter().map(QueryPair::view).collect();
    let mut newton = answer::lane_distances(
        &views,
        |k| Some((posed_pairs[k].0.borrowed(), posed_pairs[k].1.borrowed())),
        &params,
        false,
    );
    for (k, (pair, (pa, pb))) in views.into_iter().zip(&posed_pairs).enumerate() {
        // An abandoned request (deadline passed) stops here, see `Catalog::batch`.
        sublevel_core::cancel::check()?;
        out.narrow_phase_solves += 1;
        let d = answer::any_distance_reply(pair, pa, pb, &mut scratch, &params, newton.take(k).into_newton());
        let r = &d.answer.result;
        if r.overlapping || r.distance < margin {
            out.pairs.push(ScenePair { first: pair.first.to_owned(), second: pair.second.to_owned(), distance: d });
        }
    }
    out.pairs.sort_by(|x, y| x.distance.answer.result.distance.total_cmp(&y.distance.answer.result.distance));
    Ok(out)
}

/// The world box of a posed instance: a primitive's own (its frame's half extents under the
/// rotation, `|R|·h` about the translation), a body's from its bounding box; `None` without a
/// bounded one (a halfspace, a nonconvex body).
pub(super) fn world_aabb(i: &crate::PosedInstance) -> Option<(Vector3, Vector3)> {
    match &i.primitive {
        Some(p) => {
            let h = p.local_half_extents()?;
            let r = i.pose.rotation.to_rotation_matrix().into_inner().abs();
            let reach = r * h;
            let t = i.pose.translation.vector;
            Some((t - reach, t + reach))
        }
        None => i.body.world_aabb(&i.pose),
    }
}

/// Whether an instance is a halfspace.
fn halfspace(i: &crate::PosedInstance) -> bool {
    i.primitive.is_some_and(|p| !p.is_bounded())
}
