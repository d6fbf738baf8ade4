//! Growth-based overlap test between two containment trees (paper eq. "overlap", §V containment).
//!
//! ```text
//! d(p_A‖p_B) > 1  ⇔  A ∩ B = ∅    and    A_child ⊆ A, B_child ⊆ B  ⇒  A_child ∩ B_child = ∅
//! ```
//!
//! so a node pair with d > 1 (or disjoint bounding boxes, [`super::search::CheapBounds`]) is pruned
//! with everything below it, and the models collide iff some leaf pair has d ≤ 1. Pairs are refined
//! smallest d first; the exhaustive variant visits every overlapping leaf pair and reports the
//! smallest d as the depth measure (the lower, the deeper body B reaches into A's level sets).

use super::search::{split_a, CheapBounds, Entry, TreeQueryParams};
use super::warm::TreeWarmStart;
use super::{check_tree, BodyTree};
use crate::{certified_growth, growth, growth_gradient, CertifyMode, CertifyParams, GrowthResult, PoseGradient};
use std::collections::BinaryHeap;
use sublevel_core::error::Result;
use sublevel_core::math::Isometry3;

/// Answer of [`tree_collide`].
#[derive(Clone, Debug)]
pub struct TreeCollideResult {
    /// Whether the models overlap (some leaf pair with d(p_A‖p_B) ≤ 1). When `converged` is false
    /// this is the conservative `true`.
    pub colliding: bool,
    /// True when every pair that decided the answer converged.
    pub converged: bool,
    /// The overlapping leaf pair with the smallest d found (node of A, node of B).
    pub leaves: Option<(usize, usize)>,
    /// Its growth answer d(p_A‖p_B) (dimensionless; the depth measure).
    pub growth: Option<GrowthResult>,
    /// Pose gradients of that d with respect to pose A and pose B ([`growth_gradient`]).
    pub gradient: Option<(PoseGradient, PoseGradient)>,
    /// The deepest tree level reached (0: decided by the root pair).
    pub level: usize,
    /// Node pairs solved.
    pub pairs_evaluated: usize,
    /// Node pairs decided by their bounding boxes alone (cheap bounds, no solve).
    pub pairs_pruned_by_spheres: usize,
    /// State for warm-starting the next query of the same two trees.
    pub warm_start: TreeWarmStart,
}

/// Whether the models of trees `a` (under `pose_a`) and `b` (under `pose_b`) overlap, by the
/// growth measure d(p_A‖p_B) per node pair (module docs). `exhaustive = false` stops at the first
/// overlapping leaf pair; `true` visits them all and returns the one with the smallest d.
/// `params.newton` and `params.sdp_fallback` apply; `params.tolerance` does not.
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] for a broken tree (`tree_a`, `tree_b`) or bad settings.
pub fn tree_collide<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
    a: &A,
    pose_a: &Isometry3,
    b: &B,
    pose_b: &Isometry3,
    exhaustive: bool,
    warm: Option<&TreeWarmStart>,
    params: &TreeQueryParams,
) -> Result<TreeCollideResult> {
    params.validate()?;
    check_tree(a, "tree_a")?;
    check_tree(b, "tree_b")?;
    let mut fresh = TreeWarmStart::default();
    let cheap = CheapBounds::new(pose_a, pose_b, params.cheap_slack);
    let mut heap = BinaryHeap::new();
    let (mut level, mut pairs, mut sphere_pruned) = (0, 0, 0);
    let mut converged = true;
    let mut found: Option<((usize, usize), GrowthResult)> = None;
    heap.push(Entry::pair(0.0, a.root(), b.root()));
    let mut first = true;
    while let Some(e) = heap.pop() {
        let candidates: Vec<(usize, usize)> = if first {
            first = false;
            vec![(e.a, e.b)]
        } else if split_a(a, e.a, b, e.b) {
            a.children(e.a).iter().map(|&c| (c, e.b)).collect()
        } else {
            b.children(e.b).iter().map(|&c| (e.a, c)).collect()
        };
        for (na, nb) in candidates {
            let (ba, bb) = (a.body(na), b.body(nb));
            // A pair decided by its cheap bounds was reached too: its level counts.
            level = level.max(a.depth(na).max(b.depth(nb)));
            if cheap.gap_axis(a, na, b, nb).is_some_and(|g| g.0 > 0.0) {
                sphere_pruned += 1;
                continue;
            }
            if pairs >= params.max_pairs {
                converged = false;
                continue;
            }
            pairs += 1;
            let w = warm.and_then(|w| w.growth_of((na, nb)));
            let leaf = a.children(na).is_empty() && b.children(nb).is_empty();
            let mut r = growth(ba, pose_a, bb, pose_b, w, &params.newton);
            let mut ok = r.status.converged();
            if leaf && !ok && params.sdp_fallback {
                let cp = CertifyParams { newton: params.newton, certificate: params.certificate };
                let c = certified_growth(ba, pose_a, bb, pose_b, None, &cp, CertifyMode::Newton);
                ok = c.converged && !c.lower_bound;
                r = c.result;
            }
            fresh.keep_growth((na, nb), r.warm_start.clone(), params.max_warm_pairs);
            if ok && r.value > 1.0 {
                continue;
            }
            if !leaf {
                // Overlapping or unconverged: descend (never pruned on an unconverged value).
                heap.push(Entry::pair(if ok { r.value } else { 0.0 }, na, nb));
                continue;
            }
            if !ok {
                converged = false;
                continue;
            }
            if found.as_ref().is_none_or(|(_, f)| r.value < f.value) {
                found = Some(((na, nb), r));
            }
        }
        if found.is_some() && !exhaustive {
            break;
        }
    }
    let colliding = found.is_some() || !converged;
    let gradient = found.as_ref().map(|((na, _), r)| growth_gradient(a.body(*na), pose_a, r));
    Ok(TreeCollideResult {
        colliding,
        converged: found.is_some() || converged,
        leaves: found.as_ref().map(|(l, _)| *l),
        growth: found.map(|(_, r)| r),
        gradient,
        level,
        pairs_evaluated: pairs,
        pairs_pruned_by_spheres: sphere_pruned,
        warm_start: fresh,
    })
}
