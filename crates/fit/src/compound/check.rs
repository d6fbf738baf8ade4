//! The conservativeness check of a compound body: every mesh triangle inside at least one leaf
//! body.
//!
//! A leaf body is convex (sos-convex p), so it contains a triangle exactly when it contains the
//! triangle's three vertices; a triangle is covered when some leaf has `p(v) ≤ 1 + tol` at all
//! three vertices v, with tol = [`COVER_TOLERANCE`] (the fits' final rescale makes p ≤ 1 hold
//! exactly on their points, so the tolerance only absorbs the rounding of a file round trip).
//! Parents contain their children's bodies (paper §V), so covered by a leaf means covered at
//! every level of the tree.

use super::CompoundBody;
use crate::mesh::TriangleMesh;
use sublevel_core::math::Real;

/// Slack on `p(v) ≤ 1` when checking that a vertex lies in a body (dimensionless, in units of
/// the polynomial's value).
pub const COVER_TOLERANCE: Real = 1e-9;

/// Indices of the triangles of `mesh` (vertices in meters) that no leaf body of `body`
/// contains (all three vertices with p ≤ 1 + [`COVER_TOLERANCE`] in one leaf). Empty means the
/// compound body is conservative for this mesh. A triangle naming a vertex out of range counts
/// as uncovered. Cost: one polynomial evaluation per vertex and leaf (vertex values are cached).
pub fn uncovered_triangles(body: &CompoundBody, mesh: &TriangleMesh) -> Vec<usize> {
    let (vertices, triangles) = (&mesh.vertices, &mesh.triangles);
    let leaves: Vec<usize> = body.leaves().collect();
    // inside[l][v]: vertex v inside leaf l (computed lazily: None until asked).
    let mut inside: Vec<Vec<Option<bool>>> = vec![vec![None; vertices.len()]; leaves.len()];
    let mut out = Vec::new();
    for (k, t) in triangles.iter().enumerate() {
        if t.iter().any(|&i| i as usize >= vertices.len()) {
            out.push(k);
            continue;
        }
        let covered = leaves.iter().enumerate().any(|(l, &leaf)| {
            t.iter().all(|&i| {
                let i = i as usize;
                *inside[l][i].get_or_insert_with(|| body.body(leaf).value_at(&vertices[i]) <= 1.0 + COVER_TOLERANCE)
            })
        });
        if !covered {
            out.push(k);
        }
    }
    out
}
