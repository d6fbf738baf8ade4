//! Queries between compound bodies that refine only where the answer needs it (issue 14, part 2;
//! paper §V, containment of sublevel sets).
//!
//! A compound body is a *containment tree*: every node holds a sos-convex body that contains the
//! bodies of its children (paper §V, eq. "containment", the S-procedure), and the leaves are the
//! parts of the model. Containment makes every node pair's answer a bound for all leaf pairs below
//! it:
//!
//! ```text
//! A_child ⊆ A_node,  B_child ⊆ B_node   ⇒   dist(A_node, B_node) ≤ dist(A_child, B_child)
//!                                         and  A_node ∩ B_node = ∅ ⇒ A_child ∩ B_child = ∅
//! ```
//!
//! so the model's distance `min over leaf pairs (i, j) of dist(A_i, B_j)` is found by best-first
//! branch and bound over the two trees ([`tree_distance`]): node pairs wait in a priority queue by
//! their lower bound; the pair with the smallest one is split (the node with the larger bounding
//! sphere; a leaf is never split); leaf pairs are solved and give upper bounds. A pair is descended
//! only while its lower bound is below `upper − tolerance` (distance) or below the margin
//! ([`tree_closer_than`]), so a far pair is decided at the roots.
//!
//! Most pairs are decided without a solve. Every body carries a box containing it
//! ([`crate::body::Body::bounding_box`], from tangent halfspaces of the convex sublevel set), and
//! the separating-axis gap of two boxes is a lower bound of the bodies' distance:
//!
//! ```text
//! for a unit axis L:  ‖x − y‖ ≥ |L·(x − y)|  ⇒  dist(A, B) ≥ gap of the projections of box_A, box_B on L
//! ```
//!
//! taken over the six face normals and the direction between the box centers (tighter than the
//! bounding spheres' gap, which it contains as a special case). Distance queries solve only leaf
//! pairs, when they reach the front of the queue (measured on chair_101 × human_10: Newton solves
//! of internal pairs cost more than the leaf solves they saved, the internal bodies being much
//! fatter than their parts); margin queries solve internal pairs too, so that a margin is decided
//! at the coarsest level that can decide it. A warm query also bounds every leaf pair solved
//! before by its old distance less the motion since (`dist ≥ d₀ − δ`, δ the largest displacement
//! of B's bounding sphere relative to A). Overlap is
//! decided the same way by the growth measure d(p₁‖p₂) ([`tree_collide`], paper eq. "overlap").
//!
//! Warm starts are kept per node pair in a [`TreeWarmStart`], so a pair solved in the previous
//! query with nearby poses starts from its last answer; the previous answer's active leaf pair is
//! solved first, so a warm query whose active pair is unchanged costs one warm solve plus the
//! cheap bounds that prune the rest. Pose gradients come from the active leaf
//! pair ([`TreeDistanceResult::gradient`]); certificates, on request, per leaf pair.
//!
//! # Limits
//! The answer is the distance between the *models* (the leaf bodies), not the mesh; the leaves'
//! own conservativeness (they contain the mesh's triangles) makes it a lower bound of the mesh
//! distance. Node pairs whose Newton solve does not converge are never used as bounds: their lower
//! bound is their parent's, so they are only descended; a leaf pair whose solve does not converge
//! goes to the level-0 SDP ([`super::certified_distance`]) when allowed, else it stays unresolved
//! and the answer says `converged = false`.

mod collide;
mod search;
#[cfg(test)]
mod tests;
mod warm;

pub use collide::{tree_collide, TreeCollideResult};
pub use search::{
    tree_closer_than, tree_distance, LeafPairAnswer, TreeDistanceResult, TreeMarginResult, TreeQueryParams,
};
pub use warm::TreeWarmStart;

use crate::body::Body;
use crate::error::{Error, Result};

/// A containment tree of bodies: every node's body contains the bodies of its children
/// (paper §V), leaves are the parts of a compound body.
///
/// Node indices run over `0..node_count()`; all bodies are in the tree's own frame (one pose moves
/// the whole tree). Implementations must return valid indices; [`check_tree`] verifies a tree
/// before every query, so a broken one gives an error, never a panic or an endless loop.
pub trait BodyTree {
    /// Index of the root node (the body containing the whole model).
    fn root(&self) -> usize;
    /// Number of nodes (≥ 1).
    fn node_count(&self) -> usize;
    /// The body of `node`, in the tree's own frame (meters).
    fn body(&self, node: usize) -> &Body;
    /// The children of `node`; empty for a leaf.
    fn children(&self, node: usize) -> &[usize];
    /// Depth of `node`: 0 at the root, parent's depth + 1 below.
    fn depth(&self, node: usize) -> usize;
}

/// A single body is a one-node tree (its own root and only leaf), so every tree query accepts it.
impl BodyTree for Body {
    fn root(&self) -> usize {
        0
    }
    fn node_count(&self) -> usize {
        1
    }
    fn body(&self, _node: usize) -> &Body {
        self
    }
    fn children(&self, _node: usize) -> &[usize] {
        &[]
    }
    fn depth(&self, _node: usize) -> usize {
        0
    }
}

/// A compound body (issue 14 part 1) is the containment tree its nodes describe.
impl BodyTree for crate::compound::CompoundBody {
    fn root(&self) -> usize {
        crate::compound::CompoundBody::root(self)
    }
    fn node_count(&self) -> usize {
        crate::compound::CompoundBody::node_count(self)
    }
    fn body(&self, node: usize) -> &Body {
        crate::compound::CompoundBody::body(self, node)
    }
    fn children(&self, node: usize) -> &[usize] {
        crate::compound::CompoundBody::children(self, node)
    }
    fn depth(&self, node: usize) -> usize {
        crate::compound::CompoundBody::depth(self, node)
    }
}

/// Checks the structure of a tree: at least one node, the root in range with depth 0, every child
/// index in range with depth = parent's depth + 1 (so the structure has no cycles), every node
/// but the root the child of exactly one node (so, following parents up to depth 0, every node is
/// reached from the root exactly once).
///
/// Runs before every query, so it allocates nothing for trees of up to 512 nodes (a bit set on
/// the stack) and visits each child link once.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` (e.g. `"tree_a"`) and the broken node.
pub fn check_tree<T: BodyTree + ?Sized>(tree: &T, field: &str) -> Result<()> {
    let n = tree.node_count();
    let root = tree.root();
    if n == 0 || root >= n {
        return Err(Error::invalid(field, format!("root {root} out of range for {n} nodes")));
    }
    if tree.depth(root) != 0 {
        return Err(Error::invalid(field, "the root must have depth 0"));
    }
    let mut small = [0u64; 8];
    let mut large = Vec::new();
    let has_parent: &mut [u64] = if n <= 64 * small.len() {
        &mut small
    } else {
        large.resize(n.div_ceil(64), 0u64);
        &mut large
    };
    let mut links = 0;
    for node in 0..n {
        for &c in tree.children(node) {
            if c >= n || c == root || has_parent[c / 64] & (1 << (c % 64)) != 0 {
                return Err(Error::invalid(field, format!("node {node} has a bad or repeated child {c}")));
            }
            if tree.depth(c) != tree.depth(node) + 1 {
                return Err(Error::invalid(field, format!("node {c}: depth must be its parent's + 1")));
            }
            has_parent[c / 64] |= 1 << (c % 64);
            links += 1;
        }
    }
    if links + 1 != n {
        let orphan = (0..n).find(|&i| i != root && has_parent[i / 64] & (1 << (i % 64)) == 0).unwrap_or(root);
        return Err(Error::invalid(field, format!("node {orphan} is not reached from the root")));
    }
    Ok(())
}
