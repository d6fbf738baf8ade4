//! The containment tree of a compound fit (paper §V): leaves grouped bottom-up into parents that
//! contain them by the S-procedure, or their children's box ellipsoid where that fails or is
//! looser; [`super::build`] calls it after the leaf fits.

use super::build::CompoundSettings;
use super::surface::MeshSurface;
use super::CompoundNode;
use crate::containment::contain_bodies;
use crate::FitProgress;
use crate::{Error, Result};
use std::time::Instant;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real};

/// Diagonal (meters) of the box around two nodes' bounding boxes (a convex body always has one).
fn union_diagonal(a: &Body, b: &Body) -> Real {
    let id = Isometry3::identity();
    match (a.world_aabb(&id), b.world_aabb(&id)) {
        (Some((la, ha)), Some((lb, hb))) => (ha.sup(&hb) - la.inf(&lb)).norm(),
        _ => Real::INFINITY,
    }
}

/// Groups the leaves bottom-up into parents (see the module docs); returns every node, leaves
/// first, the root last.
/// Progress fractions run from `start` to 1.
pub(super) fn build_tree(
    mut nodes: Vec<CompoundNode>,
    surface: &MeshSurface,
    settings: &CompoundSettings,
    start: Real,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Vec<CompoundNode>> {
    let parents_total = nodes.len().saturating_sub(1).max(1) as Real;
    let mut level: Vec<usize> = (0..nodes.len()).collect();
    let mut made = 0usize;
    while level.len() > 1 {
        let mut pairs: Vec<(Real, usize, usize)> = Vec::new();
        for (x, &i) in level.iter().enumerate() {
            for &j in &level[x + 1..] {
                pairs.push((union_diagonal(&nodes[i].body, &nodes[j].body), i, j));
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut used = vec![false; nodes.len()];
        let mut next = Vec::new();
        let mut failure = None;
        for (_, i, j) in pairs {
            if used[i] || used[j] {
                continue;
            }
            made += 1;
            let mut inner = |p: &FitProgress| {
                progress(&FitProgress {
                    stage: p.stage,
                    fraction: (start + (1.0 - start) * (made as Real - 1.0 + p.fraction) / parents_total).min(1.0),
                    message: format!("parent {made}: {}", p.message),
                    part: None,
                })
            };
            // A pair the solver cannot contain is skipped: its nodes pair otherwise, or move up.
            let parent = match fit_parent(&nodes, [i, j], surface, settings, &mut inner) {
                Ok(p) => p,
                Err(Error::Numerical(m)) => {
                    made -= 1;
                    failure = Some(m);
                    continue;
                }
                Err(e) => return Err(e),
            };
            used[i] = true;
            used[j] = true;
            nodes.push(parent);
            next.push(nodes.len() - 1);
        }
        if next.is_empty() {
            return Err(Error::Numerical(failure.unwrap_or_else(|| "no pair of nodes could be contained".into())));
        }
        next.extend(level.iter().copied().filter(|&i| !used[i]));
        level = next;
    }
    Ok(nodes)
}

/// One parent around two nodes (paper §V containment), degree lowered if the multipliers would
/// need degree > 2, and retried at degree 2 when the solver fails.
fn fit_parent(
    nodes: &[CompoundNode],
    children: [usize; 2],
    surface: &MeshSurface,
    settings: &CompoundSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<CompoundNode> {
    let t0 = Instant::now();
    let id = Isometry3::identity();
    let bodies: Vec<(&Body, Isometry3)> = children.iter().map(|&c| (&nodes[c].body, id)).collect();
    let lowest = bodies.iter().map(|(b, _)| b.degree()).min().unwrap_or(2);
    let degree = settings.parent_degree.min(lowest + 2);
    let attempt = |degree: usize, progress: &mut dyn FnMut(&FitProgress)| {
        let s = settings.containment.clone().with_degree(degree).with_multiplier_degree(degree.saturating_sub(lowest));
        contain_bodies(&bodies, &s, progress)
    };
    let mut body = match attempt(degree, progress) {
        Ok(b) => b,
        Err(Error::Numerical(m)) => {
            let retried = if degree > 2 { attempt(2, progress) } else { Err(Error::Numerical(m.clone())) };
            match retried {
                Ok(mut b) => {
                    b.report.notes.push(format!("degree {degree} containment failed ({m}); degree 2 kept"));
                    b
                }
                Err(Error::Numerical(m2)) => {
                    let mut b = box_ellipsoid(&bodies)?;
                    b.report.notes.push(format!(
                        "containment SDP failed ({m}; at degree 2: {m2}): the parent is the ellipsoid through the corners of the children's bounding box"
                    ));
                    b
                }
                Err(e) => return Err(e),
            }
        }
        Err(e) => return Err(e),
    };
    let mut excess = surface.excess(&body, settings.excess_samples)?;
    // A §V parent can come out far looser than the box ellipsoid (a poorly scaled solve: up to
    // kilometers of excess on chair_101); the tighter of the two is kept.
    if let Ok(mut fallback) = box_ellipsoid(&bodies) {
        let e = surface.excess(&fallback, settings.excess_samples)?;
        if e < excess {
            fallback.report.notes.push(format!(
                "the ellipsoid through the corners of the children's bounding box (excess {e:.4} m) kept: tighter than the degree-{} containment fit (excess {excess:.4} m)",
                body.degree()
            ));
            excess = e;
            body = fallback;
        }
    }
    Ok(CompoundNode {
        body,
        children: children.to_vec(),
        depth: 0,
        excess,
        triangles: children.iter().map(|&c| nodes[c].triangles).sum(),
        fit_seconds: t0.elapsed().as_secs_f64(),
    })
}

/// The ellipsoid through the corners of the box around the children's bounding boxes
/// (semi-axes √3 × the box's half extents, widened by 1e-9 relative): it contains the box, hence
/// the children's bodies, exactly (convexity). The parent when the containment SDP fails at every
/// degree, whenever it is tighter than the §V fit (by sampled excess), and a candidate
/// replacement of a parent shown not to contain a child (`certify::certify_tree_repairing`).
///
/// # Errors
/// [`Error::Numerical`] when a child has no bounding box (not convex).
pub(super) fn box_ellipsoid(bodies: &[(&Body, Isometry3)]) -> Result<Body> {
    let mut lo = sublevel_core::math::Vector3::repeat(Real::INFINITY);
    let mut hi = sublevel_core::math::Vector3::repeat(Real::NEG_INFINITY);
    for (b, pose) in bodies {
        let (l, h) = b
            .world_aabb(pose)
            .ok_or_else(|| Error::Numerical("a child of the parent has no bounding box (not convex)".into()))?;
        lo = lo.inf(&l);
        hi = hi.sup(&h);
    }
    let c = (lo + hi) * 0.5;
    let radii = ((hi - lo) * (0.5 * 3.0_f64.sqrt() * (1.0 + 1e-9))).map(|r| r.max(1e-9));
    sublevel_core::body::ellipsoid([c.x, c.y, c.z], [radii.x, radii.y, radii.z])
        .map_err(|e| Error::Numerical(format!("the box ellipsoid of a parent: {e}")))
}

/// Sets every node's depth from the root down.
pub(super) fn set_depths(nodes: &mut [CompoundNode], root: usize) {
    let mut stack = vec![(root, 0)];
    while let Some((i, d)) = stack.pop() {
        nodes[i].depth = d;
        for &c in &nodes[i].children.clone() {
            stack.push((c, d + 1));
        }
    }
}
