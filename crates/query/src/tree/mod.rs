//! Queries between compound bodies that refine only where the answer needs it (paper §V,
//! containment of sublevel sets).
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
//! Most pairs are decided without a solve, by separating axes. For a unit axis L and sets
//! containing the leaves below each node, the gap between their projections on L bounds every
//! leaf pair's distance:
//!
//! ```text
//! ‖x − y‖ ≥ L·(y − x)  ⇒  dist(A_i, B_j) ≥ min_{y ∈ B} L·y − max_{x ∈ A} L·x = L·t − h_B(−RᵀL) − h_A(L)
//! ```
//!
//! with h the support functions (B posed by (R, t) in A's frame). Every convex body carries
//! certified upper bounds of its support function ([`sublevel_core::poly::SupportBound`]: tangent
//! halfspaces of the sublevel set at tabulated support points, interpolated by sublinearity), and a
//! compound body keeps, per node, the node-wise max of its leaves' bounds (their convex hull, much
//! tighter than the containment fits: [`BodyTree::support_upper`]). The axis is the direction
//! between the nodes' box centers; before a leaf pair is solved, it is refined towards the
//! witnesses' normal with the support tables' points, so that pairs whose distance is well above
//! the best one are decided without a solve. Distance queries solve only leaf pairs, when they
//! reach the front of the queue (Newton solves of internal pairs cost more than the leaf solves
//! they save, the internal bodies being much fatter than their parts); margin queries solve
//! internal pairs too, so that a margin is decided at the coarsest level that can decide it.
//! Overlap is decided the same way by the growth measure d(p₁‖p₂) ([`tree_collide`], paper eq.
//! "overlap").
//!
//! Warm starts ([`TreeWarmStart`]) keep the previous answer's active leaf pair, solver states per
//! node pair, and the search's *cut*: the node pairs where it stopped (pruned, solved, or left in
//! the queue), which cover every leaf pair, each with its lower bound and the axis it holds along.
//! A warm query solves the active pair first (one warm Newton solve gives a tight upper bound at
//! once), then moves each cut pair's bound by the motion since, without touching the trees:
//!
//! ```text
//! gap along n moves by ≥ n·((R − R₀)c + t − t₀) − Σₖ hₖ |((R − R₀)ᵀn)ₖ|    (B's node box: center c, half extents h)
//! ```
//!
//! Only the pairs whose moved bound no longer decides them are evaluated again (along their axis,
//! then by the cheap bounds), and only those still undecided are searched. Pose gradients
//! come from the active leaf pair ([`TreeDistanceResult::gradient`]); certificates, on request,
//! per leaf pair.
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
    axis_lower_bound, tree_closer_than, tree_distance, LeafPairAnswer, TreeDistanceResult, TreeMarginResult,
    TreeQueryParams,
};
pub use warm::TreeWarmStart;

use sublevel_core::body::Body;
use sublevel_core::error::{Error, Result};

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
    /// An upper bound of `max n·x` over the leaves below `node` (for a leaf: its body) for a
    /// direction `n` in the tree's frame (meters; the bound scales with |n|; +∞ for a zero `n`),
    /// `None` without a certified one. The default is the node's own body's bound
    /// ([`Body::support_upper`]: the body contains the leaves below); a tree may keep tighter
    /// ones, e.g. of the leaves' convex hull ([`sublevel_core::compound::CompoundBody::leaf_support_upper`]).
    /// The cheap lower bounds of the queries take separating-axis gaps from it, so it must never
    /// be below the leaves' support function.
    fn support_upper(&self, node: usize, n: &sublevel_core::math::Vector3) -> Option<sublevel_core::math::Real> {
        self.body(node).support_upper(n)
    }
    /// The bounding box of `node`'s body ([`Body::bounding_box`]): its center and half extents
    /// (the tree's frame, meters); `None` for a nonconvex body. A tree may keep them in one array
    /// (the queries' cheap bounds read two per node pair).
    fn node_box(&self, node: usize) -> Option<(sublevel_core::math::Vector3, sublevel_core::math::Vector3)> {
        self.body(node).bounding_box().map(|(c, h)| (c.coords, h))
    }
    /// The radius of `node`'s bounding sphere ([`Body::bounding_sphere`]; the body's scale for a
    /// nonconvex body), meters: which node of a pair the queries split.
    fn node_radius(&self, node: usize) -> sublevel_core::math::Real {
        let body = self.body(node);
        body.bounding_sphere().map_or(body.scale(), |s| s.1)
    }
    /// Whether the structure is known valid (checked when the tree was built, immutable since),
    /// so that queries skip [`check_tree`] (a few microseconds per query on 95-node trees: more
    /// than a warm query's solve). Default false: every query checks.
    fn structure_checked(&self) -> bool {
        false
    }
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
    /// One node, no links: nothing to check.
    fn structure_checked(&self) -> bool {
        true
    }
}

/// A compound body is the containment tree its nodes describe.
impl BodyTree for sublevel_core::compound::CompoundBody {
    fn root(&self) -> usize {
        sublevel_core::compound::CompoundBody::root(self)
    }
    fn node_count(&self) -> usize {
        sublevel_core::compound::CompoundBody::node_count(self)
    }
    fn body(&self, node: usize) -> &Body {
        sublevel_core::compound::CompoundBody::body(self, node)
    }
    fn children(&self, node: usize) -> &[usize] {
        sublevel_core::compound::CompoundBody::children(self, node)
    }
    fn depth(&self, node: usize) -> usize {
        sublevel_core::compound::CompoundBody::depth(self, node)
    }
    fn support_upper(&self, node: usize, n: &sublevel_core::math::Vector3) -> Option<sublevel_core::math::Real> {
        self.leaf_support_upper(node, n)
    }
    fn node_box(&self, node: usize) -> Option<(sublevel_core::math::Vector3, sublevel_core::math::Vector3)> {
        sublevel_core::compound::CompoundBody::node_box(self, node)
    }
    fn node_radius(&self, node: usize) -> sublevel_core::math::Real {
        sublevel_core::compound::CompoundBody::node_radius(self, node)
    }
    /// [`sublevel_core::compound::CompoundBody::new`] checks the same invariants, and the nodes cannot
    /// change afterwards ([`sublevel_core::compound::CompoundBody::single`] is one node).
    fn structure_checked(&self) -> bool {
        true
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
