//! Step 0 of the dispatch: pairs with an exact primitive (box, sphere, cylinder, capsule,
//! halfspace; [`sublevel_core::primitive`]) on either side, answered by [`shape_distance`].
//!
//! ```text
//! primitive – primitive        shape_distance (closed forms, the active-set method)
//! primitive – single body      shape_distance (the active-set method with the body's p(u) ≤ 1)
//! primitive – compound body    best-first search over the containment tree: a node's distance
//!                              bounds every leaf below it (the node contains them, paper §V), so
//!                              the first leaf taken off the queue is the closest leaf
//! ```
//!
//! The compound case answers the distance to the closest **leaf** (conservative: the leaves
//! contain the mesh), as the tree queries between two compound bodies do:
//!
//! ```text
//! queue ← (root, bound 0)
//! loop: take the node of smallest bound
//!       not solved yet  → solve shape_distance(primitive, node body); requeue with that distance
//!                         (its bounding sphere's gap when the solve did not converge)
//!       a leaf, solved  → the answer (every queued bound is at least its distance)
//!       else            → queue its children, each bounded by max(parent distance, sphere gap)
//! ```
//!
//! A node pair never solved when the search ends is counted as pruned by its bounding sphere.
//! Growth queries are defined for sos-convex polynomials only (eq. "overlap"); two halfspaces have
//! no finite distance. [`refusal`] names both before anything is solved.

use super::{PosedRef, QueryKind};
use crate::shape::{shape_distance, ShapeDistance, ShapeRef, ShapeWarmStart};
use crate::{Error, Result};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::primitive::Primitive;

/// Whether a query between `a` and `b` takes step 0 (either side is an exact primitive).
#[inline]
pub fn is_primitive_pair(a: &PosedRef<'_>, b: &PosedRef<'_>) -> bool {
    a.primitive.is_some() || b.primitive.is_some()
}

/// Which side of a pair a refusal names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PairSide {
    /// The first instance (A, or p₁).
    First,
    /// The second instance (B, or p₂).
    Second,
}

/// Why a query of `kind` between `a` and `b` cannot be answered, naming the side at fault; `None`
/// when it can. Growth is defined for sos-convex bodies only (a primitive on either side is
/// refused, the primitive's side named); a distance or collide query between two halfspaces has
/// no finite answer (the second side named).
pub fn refusal(kind: QueryKind, a: &PosedRef<'_>, b: &PosedRef<'_>) -> Option<(PairSide, String)> {
    match kind {
        QueryKind::Growth => {
            let (side, p) = match (a.primitive, b.primitive) {
                (Some(p), _) => (PairSide::First, p),
                (None, Some(p)) => (PairSide::Second, p),
                (None, None) => return None,
            };
            Some((
                side,
                format!(
                    "is a {} primitive: the growth measure is defined for sos-convex bodies; ask for the distance",
                    p.kind()
                ),
            ))
        }
        QueryKind::Distance | QueryKind::Collide => match (a.primitive, b.primitive) {
            (Some(Primitive::Halfspace { .. }), Some(Primitive::Halfspace { .. })) => Some((
                PairSide::Second,
                "is a halfspace, as is the other instance: two halfspaces have no finite distance".to_owned(),
            )),
            _ => None,
        },
    }
}

/// The answer of a pair with a primitive ([`primitive_pair_distance`]).
#[derive(Clone, Copy, Debug)]
pub struct ShapePairAnswer {
    /// The distance answer, in the pair's order (witness A on the first side). For a compound
    /// side: the closest leaf's.
    pub distance: ShapeDistance,
    /// Whether a side is a compound body (the answer is then the closest leaf's).
    pub compound: bool,
    /// Compound side: the closest leaf pair, as (node of the first side, node of the second), a
    /// primitive or single body being node 0.
    pub leaves: Option<(usize, usize)>,
    /// Compound side: the depth of the closest leaf in its tree (0 otherwise).
    pub level: usize,
    /// Shape solves run (1 without a compound side).
    pub pairs_evaluated: usize,
    /// Compound side: tree nodes queued but never solved (their bounds could not beat the answer).
    pub pairs_pruned_by_spheres: usize,
    /// Whether a side is a nonconvex body: its answer is a local solution only.
    pub nonconvex: bool,
}

impl ShapePairAnswer {
    /// Whether the answer is the proven global minimum: converged, with no nonconvex side.
    pub fn converged(&self) -> bool {
        self.distance.status.converged() && !self.nonconvex
    }
}

/// One side as the shape query sees it (a compound body: its root's body).
fn shape<'p>(side: &PosedRef<'p>) -> ShapeRef<'p> {
    match side.primitive {
        Some(p) => ShapeRef::Primitive(p),
        None => ShapeRef::Body(side.body),
    }
}

/// Distance between two posed sides of which at least one is a primitive (module docs), in the
/// pair's order. `warm` is the previous answer's [`ShapeDistance::warm_start`] of the same ordered
/// pair (ignored when a side is compound: each node pair runs cold).
///
/// # Errors
/// [`Error::InvalidArgument`] for two halfspaces (see [`refusal`]); [`Error::Numerical`] where a
/// body's support point fails (a nonconvex body against a halfspace).
pub fn primitive_pair_distance(
    a: &PosedRef<'_>,
    b: &PosedRef<'_>,
    warm: Option<&ShapeWarmStart>,
) -> Result<ShapePairAnswer> {
    let nonconvex = [a, b].iter().any(|s| s.primitive.is_none() && s.body.report.nonconvex);
    let (tree, first) =
        match (a.primitive.is_none().then_some(a.tree).flatten(), b.primitive.is_none().then_some(b.tree).flatten()) {
            (Some(t), _) => (t, true),
            (None, Some(t)) => (t, false),
            (None, None) => {
                let distance = shape_distance(shape(a), &a.pose, shape(b), &b.pose, warm)?;
                return Ok(ShapePairAnswer {
                    distance,
                    compound: false,
                    leaves: None,
                    level: 0,
                    pairs_evaluated: 1,
                    pairs_pruned_by_spheres: 0,
                    nonconvex,
                });
            }
        };
    let (other, tree_pose, other_pose) = if first { (b, &a.pose, &b.pose) } else { (a, &b.pose, &a.pose) };
    let found = closest_leaf(tree, tree_pose, shape(other), other_pose)?;
    let mut distance = found.distance;
    if first {
        // The search solved (primitive, node): swap back to (compound, primitive).
        distance = swapped(distance);
    }
    Ok(ShapePairAnswer {
        distance,
        compound: true,
        leaves: Some(if first { (found.node, 0) } else { (0, found.node) }),
        level: tree.depth(found.node),
        pairs_evaluated: found.solves,
        pairs_pruned_by_spheres: found.unsolved,
        nonconvex,
    })
}

/// `d` with its two sides exchanged.
fn swapped(mut d: ShapeDistance) -> ShapeDistance {
    std::mem::swap(&mut d.witness_a, &mut d.witness_b);
    d.normal = -d.normal;
    d.warm_start = ShapeWarmStart::default();
    d
}

/// A queued node of the search: its bound and whether it has been solved.
struct Queued {
    bound: Real,
    node: usize,
    solved: Option<ShapeDistance>,
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Queued {}
impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Queued {
    /// Reversed on the bound (a min-queue on `BinaryHeap`); solved nodes first among equal bounds,
    /// so a solved leaf ends the search before an unsolved node of the same bound is solved.
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .bound
            .total_cmp(&self.bound)
            .then_with(|| self.solved.is_some().cmp(&other.solved.is_some()))
            .then_with(|| other.node.cmp(&self.node))
    }
}

/// What the search over a tree found.
struct Found {
    /// The closest leaf's answer, as (shape, leaf).
    distance: ShapeDistance,
    node: usize,
    solves: usize,
    unsolved: usize,
}

/// The gap between the bounding spheres of a tree node (posed by `tree_pose`) and of `other`
/// (posed by `other_pose`): a lower bound of their distance; 0 where a side has no bounding sphere
/// (a halfspace, a nonconvex body).
fn sphere_gap(
    tree: &CompoundBody,
    node: usize,
    tree_pose: &Isometry3,
    other: ShapeRef<'_>,
    other_pose: &Isometry3,
) -> Real {
    let Some((c, r)) = tree.body(node).bounding_sphere() else { return 0.0 };
    let (oc, or) = match other {
        ShapeRef::Primitive(p) if p.is_bounded() => (other_pose.translation.vector, p.bounding_radius()),
        ShapeRef::Body(body) => match body.bounding_sphere() {
            Some((bc, br)) => ((other_pose * bc).coords, br),
            None => return 0.0,
        },
        ShapeRef::Primitive(_) => return 0.0,
    };
    ((tree_pose * c).coords - oc).norm() - r - or
}

/// The best-first search of the module docs: the leaf of `tree` closest to `other`.
fn closest_leaf(
    tree: &CompoundBody,
    tree_pose: &Isometry3,
    other: ShapeRef<'_>,
    other_pose: &Isometry3,
) -> Result<Found> {
    let mut queue = BinaryHeap::new();
    queue.push(Queued { bound: 0.0, node: tree.root(), solved: None });
    let mut solves = 0;
    while let Some(q) = queue.pop() {
        match q.solved {
            None => {
                let d = shape_distance(other, other_pose, ShapeRef::Body(tree.body(q.node)), tree_pose, None)?;
                solves += 1;
                let bound = if d.status.converged() {
                    d.distance.max(q.bound)
                } else {
                    sphere_gap(tree, q.node, tree_pose, other, other_pose).max(q.bound)
                };
                queue.push(Queued { bound, node: q.node, solved: Some(d) });
            }
            Some(d) if tree.children(q.node).is_empty() => {
                return Ok(Found { distance: d, node: q.node, solves, unsolved: queue.len() });
            }
            Some(d) => {
                let parent = if d.status.converged() { d.distance } else { q.bound };
                for &child in tree.children(q.node) {
                    let gap = sphere_gap(tree, child, tree_pose, other, other_pose);
                    queue.push(Queued { bound: gap.max(parent), node: child, solved: None });
                }
            }
        }
    }
    Err(Error::Numerical("the containment tree has no leaf".into()))
}

/// A lower bound of the distance between two posed sides of which at least one is a primitive,
/// from their bounding spheres (a primitive's about its frame's origin, a body's own, a compound
/// body's root's); `None` when a side has none (a halfspace, a nonconvex body). A collide query
/// whose bound exceeds its margin is answered "clear" with no solve.
pub fn primitive_lower_bound(a: &PosedRef<'_>, b: &PosedRef<'_>) -> Option<Real> {
    let sphere = |s: &PosedRef<'_>| match s.primitive {
        Some(p) if p.is_bounded() => Some((s.pose.translation.vector, p.bounding_radius())),
        Some(_) => None,
        None => s.body.bounding_sphere().map(|(c, r)| ((s.pose * c).coords, r)),
    };
    let (ca, ra) = sphere(a)?;
    let (cb, rb) = sphere(b)?;
    Some(((ca - cb).norm() - ra - rb).max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::body::ellipsoid;
    use sublevel_core::compound::{CompoundBody, CompoundNode, CompoundReport};
    use sublevel_core::math::Vector3;

    fn posed<'p>(body: &'p sublevel_core::body::Body, primitive: Option<&'p Primitive>, x: Real) -> PosedRef<'p> {
        PosedRef { body, tree: None, primitive, pose: Isometry3::translation(x, 0.0, 0.0) }
    }

    /// A box against a sphere 2 m apart along x: 2 − 0.5 − 0.25 exactly, in either order, with the
    /// witnesses on the two surfaces; the sphere bound below it.
    #[test]
    fn a_box_and_a_sphere_at_their_closed_form() {
        let stand_in = ellipsoid([0.0; 3], [1.0; 3]).unwrap();
        let cube = Primitive::Box { half_extents: Vector3::repeat(0.5) };
        let ball = Primitive::Sphere { radius: 0.25 };
        let (a, b) = (posed(&stand_in, Some(&cube), 0.0), posed(&stand_in, Some(&ball), 2.0));
        let ab = primitive_pair_distance(&a, &b, None).unwrap();
        assert!(ab.converged() && !ab.compound);
        assert!((ab.distance.distance - 1.25).abs() < 1e-12, "{}", ab.distance.distance);
        assert!((ab.distance.witness_a.x - 0.5).abs() < 1e-12 && (ab.distance.witness_b.x - 1.75).abs() < 1e-12);
        let ba = primitive_pair_distance(&b, &a, None).unwrap();
        assert!((ba.distance.distance - 1.25).abs() < 1e-12);
        assert!((ba.distance.witness_a.x - 1.75).abs() < 1e-12);
        let lower = primitive_lower_bound(&a, &b).unwrap();
        assert!(lower <= 1.25 && lower > 0.0, "{lower}");
        assert!(refusal(QueryKind::Distance, &a, &b).is_none());
        assert_eq!(refusal(QueryKind::Growth, &a, &b).map(|r| r.0), Some(PairSide::First));
        let floor = Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 };
        let h = posed(&stand_in, Some(&floor), 0.0);
        assert_eq!(refusal(QueryKind::Collide, &h, &h).map(|r| r.0), Some(PairSide::Second));
        assert!(primitive_lower_bound(&a, &h).is_none());
    }

    /// A compound body of two balls (r = 0.5 at x = ±1, under a root ellipsoid holding both)
    /// against a sphere: the closest leaf's distance, whichever side the tree is on.
    #[test]
    fn a_compound_body_answers_with_its_closest_leaf() {
        let leaf = |x: Real| CompoundNode {
            body: ellipsoid([x, 0.0, 0.0], [0.5; 3]).unwrap(),
            children: vec![],
            depth: 1,
            excess: 0.0,
            triangles: 0,
            fit_seconds: 0.0,
        };
        let root = CompoundNode {
            body: ellipsoid([0.0; 3], [1.8, 0.9, 0.9]).unwrap(),
            children: vec![1, 2],
            depth: 0,
            excess: 0.0,
            triangles: 0,
            fit_seconds: 0.0,
        };
        let tree = CompoundBody::new(vec![root, leaf(-1.0), leaf(1.0)], 0, CompoundReport::default()).unwrap();
        let ball = Primitive::Sphere { radius: 0.25 };
        let stand_in = ellipsoid([0.0; 3], [1.0; 3]).unwrap();
        let c = PosedRef { body: tree.body(0), tree: Some(&tree), primitive: None, pose: Isometry3::identity() };
        // The ball at (1, 2, 0): 2 − 0.5 − 0.25 = 1.25 from the leaf at x = 1 (node 2).
        let s = PosedRef { pose: Isometry3::translation(1.0, 2.0, 0.0), ..posed(&stand_in, Some(&ball), 0.0) };
        for (first, second, leaves) in [(&c, &s, (2, 0)), (&s, &c, (0, 2))] {
            let d = primitive_pair_distance(first, second, None).unwrap();
            assert!(d.compound && d.converged());
            assert!((d.distance.distance - 1.25).abs() < 1e-9, "{}", d.distance.distance);
            assert_eq!(d.leaves, Some(leaves));
            assert_eq!(d.level, 1);
            let on_leaf = if leaves.0 == 2 { d.distance.witness_a } else { d.distance.witness_b };
            assert!(((on_leaf.coords - Vector3::new(1.0, 0.0, 0.0)).norm() - 0.5).abs() < 1e-9);
        }
    }
}
