//! Compound bodies: a nonconvex mesh modeled by a convex decomposition whose parts are each
//! fitted as a sos-convex body, grouped bottom-up into a containment tree.
//!
//! ```text
//! leaves    parts P₁ … Pₙ: P_k = {x : p_k(x) ≤ 1} ⊇ every triangle assigned to part k
//!           (the part is convex and contains the triangle's three vertices)
//! parents   Q = {x : q(x) ≤ 1} ⊇ P_a ∪ P_b, by the S-procedure of paper §V
//!           (sublevel-set containment: q − 1 − λ(p_a − 1) sos, λ ≥ 0 — `sublevel_fit::containment`)
//! root      one body containing every part body, hence the whole mesh
//! ```
//!
//! Because each triangle of the mesh lies inside at least one leaf body and each parent contains
//! its children's bodies (as sets, not only sampled points), the union of the bodies at any cut
//! of the tree contains the mesh: every distance between two compound bodies' node bodies is a
//! lower bound of the exact mesh–mesh distance, and every "separated" answer is true.
//!
//! Each node also stores its one-sided Hausdorff excess over the mesh, `sup_{x ∈ ∂S} d(x, mesh)`
//! (sampled on the node's boundary, meters): how far its surface reaches beyond the mesh.
//!
//! A single [`Body`] is a one-node tree ([`CompoundBody::single`]); [`CompoundBody::load`] reads a
//! compound file or a single-body file. The file format is [`CompoundFile`].
//!
//! This module holds the tree and its file format ([`file`](mod@file), JSON); the builds (decomposition,
//! leaf fits, containment, the part-count search) live in `sublevel_fit::compound`.

use crate::body::Body;
use crate::math::Real;
use crate::poly::SupportBound;
use crate::Result;
use std::path::Path;

pub mod file;

#[cfg(test)]
mod tests;

pub use file::{CompoundFile, CompoundNodeFile, COMPOUND_FORMAT};

/// One node of a compound body's containment tree.
#[derive(Clone, Debug)]
pub struct CompoundNode {
    /// The node's body; its frame is the compound body's frame (the mesh's coordinates, meters).
    pub body: Body,
    /// Indices into the compound body's nodes; empty for a leaf (a part of the decomposition).
    pub children: Vec<usize>,
    /// Depth in the tree: 0 at the root, parent's depth + 1 below.
    pub depth: usize,
    /// One-sided Hausdorff excess of the node's surface over the mesh (sampled on the boundary,
    /// meters): `max_k d(b_k, mesh)` over boundary samples b_k. `NaN` when not measured (a
    /// single body loaded from a body file: no mesh to measure against).
    pub excess: Real,
    /// Mesh triangles inside this node's body by construction: for a leaf, the triangles
    /// assigned to its part; for a parent, the sum over its children. 0 when unknown.
    pub triangles: usize,
    /// Seconds spent fitting this node's body (point fit for a leaf, containment fit for a
    /// parent, excess sampling included); 0 when unknown.
    pub fit_seconds: Real,
}

/// How a compound body was built: the decomposition, the search over part counts and the
/// timings (all optional figures are `None` for a single body).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CompoundReport {
    /// The mesh the body was fitted to (file name as given), if known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mesh: Option<String>,
    /// Triangles of the mesh.
    #[serde(default)]
    pub mesh_triangles: usize,
    /// Leaf-excess tolerance asked for (`--tolerance`, meters), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<Real>,
    /// Every part count tried by the search, in order: (parts asked of the decomposition,
    /// parts obtained, max leaf excess in meters, seconds for that attempt).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub attempts: Vec<(usize, usize, Real, Real)>,
    /// Seconds of the kept attempt's convex decomposition (VHACD).
    #[serde(default)]
    pub decomposition_seconds: Real,
    /// Seconds of the kept attempt's leaf fits (sum over parts).
    #[serde(default)]
    pub leaf_fit_seconds: Real,
    /// Seconds of the kept attempt's containment tree (sum over parents).
    #[serde(default)]
    pub tree_fit_seconds: Real,
    /// Wall-clock seconds of the whole build, every attempt included.
    #[serde(default)]
    pub total_seconds: Real,
    /// Boundary samples per node used for the excess.
    #[serde(default)]
    pub excess_samples: usize,
    /// Free-form notes (why a part count was chosen, …).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// Whether every leaf's excess is ≤ `tolerance`; `None` without a tolerance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub met: Option<bool>,
    /// The leaves whose excess is above `tolerance` (empty when `met`), largest excess first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub misses: Vec<ToleranceMiss>,
    /// What welding the mesh before its decomposition merged and dropped; `None` when the mesh
    /// was not welded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weld: Option<WeldReport>,
}

/// A leaf whose excess is above the build's tolerance ([`CompoundReport::misses`]).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ToleranceMiss {
    /// Index of the leaf among the compound body's nodes.
    pub node: usize,
    /// Mesh triangles assigned to the leaf.
    pub triangles: usize,
    /// The leaf's one-sided Hausdorff excess over the mesh (sampled, meters).
    pub excess: Real,
}

/// What welding a triangle mesh did (`sublevel_fit::mesh::weld_mesh`): vertices closer than
/// `tolerance` merged, triangles whose corners merged (zero area) and repeated triangles dropped,
/// vertices no triangle uses dropped. Counts before and after, and of each change.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WeldReport {
    /// Distance (meters) below which two vertices were merged.
    pub tolerance: Real,
    /// Vertices of the mesh as read.
    pub vertices_before: usize,
    /// Vertices after welding.
    pub vertices_after: usize,
    /// Vertices merged into an earlier vertex within the tolerance.
    pub merged_vertices: usize,
    /// Vertices dropped because no kept triangle uses them.
    pub unused_vertices: usize,
    /// Triangles of the mesh as read.
    pub triangles_before: usize,
    /// Triangles after welding.
    pub triangles_after: usize,
    /// Triangles dropped because two of their corners merged (zero area).
    pub degenerate_triangles: usize,
    /// Triangles dropped because an earlier triangle has the same three vertices (either
    /// orientation).
    pub duplicate_triangles: usize,
}

/// A compound body: a containment tree of bodies (see the module docs), nodes in one vector.
///
/// Invariants (checked by [`CompoundBody::new`]): at least one node; `root` is a node with no
/// parent and depth 0; every other node has exactly one parent and depth = parent's + 1; every
/// child index is in range (so the nodes form one tree, no cycles).
#[derive(Clone, Debug)]
pub struct CompoundBody {
    nodes: Vec<CompoundNode>,
    root: usize,
    /// Per node, certified support bounds of the union of the leaves below it (the compound
    /// body's frame, meters): derived from the nodes when the tree is built (see
    /// [`CompoundBody::leaf_support_upper`]).
    supports: Vec<Option<SupportBound>>,
    /// Per node, what the tree queries read for every node pair they bound, in one array (the
    /// nodes themselves hold whole bodies, far apart in memory).
    layout: Vec<NodeLayout>,
    /// The children of every node, one after another ([`NodeLayout::children`]).
    child_list: Vec<usize>,
    /// How the tree was built.
    pub report: CompoundReport,
}

impl CompoundBody {
    /// Validates and builds a compound body from its nodes.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] naming `nodes`, `root`, `nodes[i].children[j]`,
    /// `nodes[i].depth` or `nodes[i].excess` when the nodes do not form one tree rooted at
    /// `root` with consistent depths, or an excess is negative.
    pub fn new(nodes: Vec<CompoundNode>, root: usize, report: CompoundReport) -> Result<Self> {
        file::check_tree(nodes.len(), root, |i| (&nodes[i].children, nodes[i].depth, nodes[i].excess))?;
        let supports = leaf_supports(&nodes);
        let (layout, child_list) = node_layout(&nodes);
        Ok(Self { nodes, root, supports, layout, child_list, report })
    }

    /// A one-node tree holding `body` (excess unknown: `NaN`).
    pub fn single(body: Body) -> Self {
        let node =
            CompoundNode { body, children: Vec::new(), depth: 0, excess: Real::NAN, triangles: 0, fit_seconds: 0.0 };
        let nodes = vec![node];
        let supports = leaf_supports(&nodes);
        let (layout, child_list) = node_layout(&nodes);
        Self { nodes, root: 0, supports, layout, child_list, report: CompoundReport::default() }
    }

    /// An upper bound of `max n·x` over the leaves below `node` (for a leaf: its body), for any
    /// direction `n` in the compound body's frame (meters; the bound scales with |n|, +∞ for a
    /// zero or non-finite `n`). `None` when a body below is nonconvex (no certified bound).
    ///
    /// Tighter than the node's own body ([`Body::support_upper`]) where the containment fit is
    /// loose: a parent's table is the node-wise min of its own body's table and the max of its
    /// children's ([`SupportBound::union`], [`SupportBound::tighten`]), i.e. it bounds the convex
    /// hull of its leaves, which every leaf pair below lies in (the tree queries' cheap bounds).
    /// Panics if `node` is out of range.
    pub fn leaf_support_upper(&self, node: usize, n: &crate::math::Vector3) -> Option<Real> {
        self.supports[node].as_ref().map(|t| t.upper(n))
    }

    /// The bounding box of `node`'s body ([`Body::bounding_box`]: center and half extents, the
    /// compound body's frame, meters); `None` for a nonconvex body. Panics if `node` is out of
    /// range.
    pub fn node_box(&self, node: usize) -> Option<(crate::math::Vector3, crate::math::Vector3)> {
        self.layout[node].bbox
    }

    /// The radius of `node`'s bounding sphere ([`Body::bounding_sphere`]; the body's scale for a
    /// nonconvex body), meters. Panics if `node` is out of range.
    pub fn node_radius(&self, node: usize) -> Real {
        self.layout[node].radius
    }

    /// Index of the root node (its body contains every other node's body).
    pub fn root(&self) -> usize {
        self.root
    }

    /// Number of nodes (parts plus parents).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Node `i`. Panics if `i ≥ node_count()` (indices come from this tree).
    pub fn node(&self, i: usize) -> &CompoundNode {
        &self.nodes[i]
    }

    /// Every node, in index order.
    pub fn nodes(&self) -> &[CompoundNode] {
        &self.nodes
    }

    /// Body of node `i` (compound body's frame). Panics if `i` is out of range.
    pub fn body(&self, i: usize) -> &Body {
        &self.nodes[i].body
    }

    /// Children of node `i` (empty for a leaf). Panics if `i` is out of range.
    pub fn children(&self, i: usize) -> &[usize] {
        let (start, len) = self.layout[i].children;
        &self.child_list[start..start + len]
    }

    /// Depth of node `i` (0 at the root). Panics if `i` is out of range.
    pub fn depth(&self, i: usize) -> usize {
        self.layout[i].depth
    }

    /// Indices of the leaves (the parts of the decomposition), in index order.
    pub fn leaves(&self) -> impl Iterator<Item = usize> + '_ {
        self.nodes.iter().enumerate().filter(|(_, n)| n.children.is_empty()).map(|(i, _)| i)
    }

    /// Number of leaves (parts).
    pub fn leaf_count(&self) -> usize {
        self.leaves().count()
    }

    /// Largest leaf excess in meters (`NaN` when any leaf's excess is unknown).
    pub fn max_leaf_excess(&self) -> Real {
        self.leaves().map(|i| self.nodes[i].excess).fold(0.0, |a: Real, e| if e.is_nan() { e } else { a.max(e) })
    }

    /// Height of the tree: the largest depth of any node (0 for a single body).
    pub fn height(&self) -> usize {
        self.nodes.iter().map(|n| n.depth).max().unwrap_or(0)
    }

    /// Reads a compound file, or a single-body file as a one-node tree (a JSON object with a
    /// `nodes` field is a compound file; anything else is read as a body file).
    ///
    /// # Errors
    /// [`crate::Error::Io`], [`crate::Error::Json`], or a validation error of
    /// [`CompoundBody::from_file`] / [`Body::from_file`] naming the field (`nodes[3].body.scale`, …).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)?;
        Self::from_json(&text)
    }

    /// Parses the JSON text of a compound file or a single-body file (see [`CompoundBody::load`]).
    ///
    /// # Errors
    /// As [`CompoundBody::load`], without I/O.
    pub fn from_json(text: &str) -> Result<Self> {
        let value: serde_json::Value = serde_json::from_str(text)?;
        if file::is_compound_json(&value) {
            Self::from_file(serde_json::from_value(value)?)
        } else {
            Ok(Self::single(Body::from_file(serde_json::from_value(value)?)?))
        }
    }

    /// Writes the compound file ([`CompoundFile`], compact JSON: a tree of 31 degree-6 nodes is
    /// ~0.2 MB compact against ~1 MB pretty).
    ///
    /// # Errors
    /// [`crate::Error::Io`] or [`crate::Error::Json`] (e.g. a report figure that is not finite).
    pub fn save(&self, path: &Path) -> Result<()> {
        std::fs::write(path, serde_json::to_string(&self.to_file())?)?;
        Ok(())
    }
}

/// One node's entry of [`CompoundBody`]'s compact layout.
#[derive(Clone, Copy, Debug)]
struct NodeLayout {
    /// [`CompoundBody::node_box`].
    bbox: Option<(crate::math::Vector3, crate::math::Vector3)>,
    /// [`CompoundBody::node_radius`].
    radius: Real,
    /// [`CompoundBody::depth`].
    depth: usize,
    /// Start and length of the node's children in `child_list`.
    children: (usize, usize),
}

/// The compact layout of [`CompoundBody`]: per node its box, sphere radius, depth and children.
/// The tree queries read these from one contiguous array rather than from the nodes' bodies:
/// about a tenth off the median cold query of chair_101 × human_10 (`tree_profile`).
fn node_layout(nodes: &[CompoundNode]) -> (Vec<NodeLayout>, Vec<usize>) {
    let mut child_list = Vec::with_capacity(nodes.len());
    let layout = nodes
        .iter()
        .map(|n| {
            let b = &n.body;
            let start = child_list.len();
            child_list.extend_from_slice(&n.children);
            NodeLayout {
                bbox: b.bounding_box().map(|(c, h)| (c.coords, h)),
                radius: b.bounding_sphere().map_or(b.scale(), |s| s.1),
                depth: n.depth,
                children: (start, n.children.len()),
            }
        })
        .collect();
    (layout, child_list)
}

/// The support tables of [`CompoundBody::leaf_support_upper`], children before parents (depth
/// order; the structure is checked before this runs).
fn leaf_supports(nodes: &[CompoundNode]) -> Vec<Option<SupportBound>> {
    let mut order: Vec<usize> = (0..nodes.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(nodes[i].depth));
    let mut supports: Vec<Option<SupportBound>> = vec![None; nodes.len()];
    for i in order {
        let body = &nodes[i].body;
        let own = body.support_bound().map(|t| t.in_frame(&body.center(), body.scale()));
        let children = &nodes[i].children;
        let mut hull: Option<SupportBound> = None;
        for (k, &c) in children.iter().enumerate() {
            hull = match (k, hull, supports[c].as_ref()) {
                (0, _, Some(t)) => Some(t.clone()),
                (_, Some(h), Some(t)) => Some(h.union(t)),
                _ => None,
            };
            if hull.is_none() {
                break;
            }
        }
        supports[i] = match (own, hull) {
            (Some(mut own), Some(hull)) => {
                own.tighten(&hull);
                Some(own)
            }
            (own, None) if children.is_empty() => own,
            // A parent whose own body is nonconvex: its leaves' hull still bounds them.
            (None, hull) => hull,
            // A leaf below without a certified bound: nothing bounds that leaf.
            (Some(_), None) => None,
        };
    }
    supports
}
