//! The compound body file (JSON): the nodes, each a [`BodyFile`] plus its place in the tree and
//! its excess, the root index and the build report.
//!
//! ```text
//! { "format": "sublevel.compound.v1",
//!   "root": 6,
//!   "nodes": [ { "body": {degree, exponents, coefficients, center, scale, report},
//!                "children": [], "depth": 2, "excess": 0.031, "triangles": 812, "fit_seconds": 0.4 },
//!              … ],
//!   "report": { "mesh": "chair_101.off", "attempts": [[4, 4, 0.05, 3.1]], … } }
//! ```
//!
//! A file is recognized as compound by its `nodes` field; a single-body file (a bare
//! [`BodyFile`]) has none and loads as a one-node tree through
//! [`super::CompoundBody::load`]. A compound file is not a body file: [`crate::Body::load`]
//! refuses it (no `degree`, `exponents`, … fields).

use super::{CompoundBody, CompoundNode, CompoundReport};
use crate::body::{Body, BodyFile};
use crate::math::Real;
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// The value of [`CompoundFile::format`] this version writes and reads.
pub const COMPOUND_FORMAT: &str = "sublevel.compound.v1";

/// One node of a compound file.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CompoundNodeFile {
    /// The node's body (same form as a single-body file).
    pub body: BodyFile,
    /// Child node indices; empty for a leaf.
    #[serde(default)]
    pub children: Vec<usize>,
    /// Depth (0 at the root).
    pub depth: usize,
    /// One-sided Hausdorff excess over the mesh in meters; `null` when not measured.
    #[serde(default)]
    pub excess: Option<Real>,
    /// Mesh triangles contained by construction (0 when unknown).
    #[serde(default)]
    pub triangles: usize,
    /// Seconds spent fitting this node (0 when unknown).
    #[serde(default)]
    pub fit_seconds: Real,
}

/// A compound body's on-disk JSON form (see the module docs).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CompoundFile {
    /// Always [`COMPOUND_FORMAT`].
    pub format: String,
    /// Index of the root node.
    pub root: usize,
    /// The nodes of the containment tree.
    pub nodes: Vec<CompoundNodeFile>,
    /// How the tree was built.
    #[serde(default)]
    pub report: CompoundReport,
}

/// Whether a parsed JSON document is a compound file (an object with a `nodes` field) rather
/// than a single-body file.
pub fn is_compound_json(value: &serde_json::Value) -> bool {
    value.get("nodes").is_some()
}

/// Checks that `n` nodes with the given (children, depth, excess) form one tree rooted at
/// `root` with depth 0 at the root and parent + 1 below, and that every measured excess is a
/// finite number ≥ 0.
pub(super) fn check_tree<'a>(
    n: usize,
    root: usize,
    node: impl Fn(usize) -> (&'a Vec<usize>, usize, Real),
) -> Result<()> {
    if n == 0 {
        return Err(Error::invalid("nodes", "a compound body needs at least one node"));
    }
    if root >= n {
        return Err(Error::invalid("root", format!("is {root}, but there are only {n} nodes")));
    }
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for i in 0..n {
        let (children, _, excess) = node(i);
        if excess.is_infinite() || excess < 0.0 {
            return Err(Error::invalid(
                format!("nodes[{i}].excess"),
                format!("must be a finite number ≥ 0 meters, got {excess}"),
            ));
        }
        for (j, &c) in children.iter().enumerate() {
            let field = format!("nodes[{i}].children[{j}]");
            if c >= n {
                return Err(Error::invalid(field, format!("is {c}, but there are only {n} nodes")));
            }
            if c == root {
                return Err(Error::invalid(field, format!("names the root {root}, which has no parent")));
            }
            if let Some(p) = parent[c] {
                return Err(Error::invalid(field, format!("node {c} already has parent {p}; a tree node has one")));
            }
            parent[c] = Some(i);
        }
    }
    if let Some(orphan) = (0..n).find(|&i| i != root && parent[i].is_none()) {
        return Err(Error::invalid("nodes", format!("node {orphan} is neither the root {root} nor anyone's child")));
    }
    // Depths top-down from the root; a node never reached is on a cycle detached from the root.
    let mut seen = vec![false; n];
    let mut stack = vec![root];
    if node(root).1 != 0 {
        return Err(Error::invalid(
            format!("nodes[{root}].depth"),
            format!("the root's depth must be 0, got {}", node(root).1),
        ));
    }
    while let Some(i) = stack.pop() {
        seen[i] = true;
        let (children, depth, _) = node(i);
        for &c in children {
            let d = node(c).1;
            if d != depth + 1 {
                return Err(Error::invalid(
                    format!("nodes[{c}].depth"),
                    format!("must be its parent's depth + 1 = {}, got {d}", depth + 1),
                ));
            }
            stack.push(c);
        }
    }
    if let Some(lost) = seen.iter().position(|s| !s) {
        return Err(Error::invalid("nodes", format!("node {lost} is on a cycle not reachable from the root {root}")));
    }
    Ok(())
}

impl CompoundBody {
    /// Validates and builds a compound body from its file form.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `format` (another format string), `nodes[i].body.<field>`
    /// for an invalid body (see [`Body::from_file`]), or the tree fields of
    /// [`CompoundBody::new`].
    pub fn from_file(file: CompoundFile) -> Result<Self> {
        if file.format != COMPOUND_FORMAT {
            return Err(Error::invalid("format", format!("must be \"{COMPOUND_FORMAT}\", got \"{}\"", file.format)));
        }
        let mut nodes = Vec::with_capacity(file.nodes.len());
        for (i, n) in file.nodes.into_iter().enumerate() {
            let body = Body::from_file(n.body).map_err(|e| match e {
                Error::InvalidArgument { field, reason } => Error::invalid(format!("nodes[{i}].body.{field}"), reason),
                other => other,
            })?;
            let excess = match n.excess {
                Some(e) if !e.is_finite() => {
                    return Err(Error::invalid(format!("nodes[{i}].excess"), "must be a finite number"))
                }
                Some(e) => e,
                None => Real::NAN,
            };
            if !(n.fit_seconds.is_finite() && n.fit_seconds >= 0.0) {
                return Err(Error::invalid(format!("nodes[{i}].fit_seconds"), "must be a finite number ≥ 0"));
            }
            nodes.push(CompoundNode {
                body,
                children: n.children,
                depth: n.depth,
                excess,
                triangles: n.triangles,
                fit_seconds: n.fit_seconds,
            });
        }
        CompoundBody::new(nodes, file.root, file.report)
    }

    /// The file form (an unmeasured excess is written as `null`).
    pub fn to_file(&self) -> CompoundFile {
        CompoundFile {
            format: COMPOUND_FORMAT.to_owned(),
            root: self.root,
            nodes: self
                .nodes
                .iter()
                .map(|n| CompoundNodeFile {
                    body: n.body.to_file(),
                    children: n.children.clone(),
                    depth: n.depth,
                    excess: if n.excess.is_nan() { None } else { Some(n.excess) },
                    triangles: n.triangles,
                    fit_seconds: n.fit_seconds,
                })
                .collect(),
            report: self.report.clone(),
        }
    }
}
