//! Welding a triangle mesh before a convex decomposition.
//!
//! A triangle soup — every STL, many OBJ exports — gives each triangle its own three vertices, so
//! a decomposition that follows the mesh's connectivity sees disconnected triangles. Welding
//! merges the vertices closer than ε, drops the triangles that collapse and the repeated ones:
//!
//! ```text
//! ε = τ · diag,  diag the diagonal of the bounding box of the triangles' vertices (meters),
//!                τ = DEFAULT_WELD_TOLERANCE = 1e-9 by default (τ = 0: equal coordinates only)
//! vertices  in file order: vertex v joins the first kept vertex w with ‖v − w‖ ≤ ε among those
//!           in the 27 grid cells (side ε) around v's cell, else it is kept; O(n) expected
//! triangles a triangle with two corners merged (zero area) is dropped; one whose three vertices
//!           (in any order) repeat an earlier triangle is dropped; vertices that no kept triangle
//!           uses are dropped
//! ```
//!
//! Triangles whose three distinct vertices are collinear (zero area without a merge) are kept:
//! their segment is part of the surface, and dropping it could leave it outside every part.
//!
//! A merged vertex moves by at most ε (1e-10 m on a 0.1 m link at the default τ), far below any
//! fit's accuracy; a compound fit also contains the original positions of merged vertices
//! ([`WeldedMesh::source`] maps them), so its body covers the mesh as read.

use super::TriangleMesh;
use crate::{Error, Result};
use std::collections::{HashMap, HashSet};
use sublevel_core::compound::WeldReport;
use sublevel_core::math::{Point3, Real};

/// Default relative weld tolerance τ: vertices closer than τ × the bounding-box diagonal merge.
/// 1e-9 merges the copies of a vertex that a soup repeats (equal, or differing in the last digits
/// of a text export) and nothing a modeller meant as two vertices.
pub const DEFAULT_WELD_TOLERANCE: Real = 1e-9;

/// A welded mesh ([`weld_mesh`]).
#[derive(Clone, Debug, PartialEq)]
pub struct WeldedMesh {
    /// The welded mesh: vertices in the order of their first appearance in the input, every one
    /// used by a triangle; triangles in input order, corners in input order.
    pub mesh: TriangleMesh,
    /// For every input vertex, the index of the welded vertex it became, or `None` when no kept
    /// triangle uses it.
    pub source: Vec<Option<u32>>,
    /// Counts of what was merged and dropped; `tolerance` is ε in meters.
    pub report: WeldReport,
}

/// Welds `mesh` (see the module docs): vertices within `relative_tolerance` × the bounding-box
/// diagonal of the triangles' vertices merged, collapsed and repeated triangles and unused
/// vertices dropped.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `weld_tolerance` when `relative_tolerance` is not finite or
/// not in [0, 1), or `mesh` when a triangle names a vertex out of range, a used vertex has a
/// non-finite coordinate, or no triangle is left (every one collapsed, or none given).
pub fn weld_mesh(mesh: &TriangleMesh, relative_tolerance: Real) -> Result<WeldedMesh> {
    if !(relative_tolerance.is_finite() && (0.0..1.0).contains(&relative_tolerance)) {
        return Err(Error::invalid("weld_tolerance", format!("must be in [0, 1), got {relative_tolerance}")));
    }
    let n = mesh.vertices.len();
    if let Some(k) = mesh.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
        return Err(Error::invalid("mesh", format!("triangle {k} names a vertex beyond the {n} vertices")));
    }
    let mut used = vec![false; n];
    for t in &mesh.triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    let (mut lo, mut hi) = (
        Point3::new(Real::INFINITY, Real::INFINITY, Real::INFINITY),
        -Point3::new(Real::INFINITY, Real::INFINITY, Real::INFINITY),
    );
    for (i, p) in mesh.vertices.iter().enumerate().filter(|(i, _)| used[*i]) {
        if !p.coords.iter().all(|c| c.is_finite()) {
            return Err(Error::invalid("mesh", format!("vertex {i} has a non-finite coordinate")));
        }
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let diagonal = if lo.x <= hi.x { (hi - lo).norm() } else { 0.0 };
    let eps = relative_tolerance * diagonal;

    // Representatives: index into `mesh.vertices` of every kept vertex, by grid cell.
    let mut welded_of: Vec<Option<u32>> = vec![None; n];
    let mut reps: Vec<u32> = Vec::new();
    let mut merged_vertices = 0usize;
    if eps > 0.0 {
        let cell = |p: &Point3| -> [i64; 3] {
            let c = (p - lo) / eps;
            [c.x.floor() as i64, c.y.floor() as i64, c.z.floor() as i64]
        };
        let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for v in (0..n).filter(|&v| used[v]) {
            let p = &mesh.vertices[v];
            let c = cell(p);
            let mut found: Option<u32> = None;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let key = [c[0] + dx, c[1] + dy, c[2] + dz];
                        for &r in grid.get(&key).into_iter().flatten() {
                            let w = reps[r as usize] as usize;
                            if (mesh.vertices[w] - p).norm() <= eps && found.is_none_or(|f| r < f) {
                                found = Some(r);
                            }
                        }
                    }
                }
            }
            match found {
                Some(r) => {
                    welded_of[v] = Some(r);
                    merged_vertices += 1;
                }
                None => {
                    let r = reps.len() as u32;
                    reps.push(v as u32);
                    grid.entry(c).or_default().push(r);
                    welded_of[v] = Some(r);
                }
            }
        }
    } else {
        // Equal coordinates only (−0 equals 0).
        let key = |p: &Point3| p.coords.map(|c| if c == 0.0 { 0u64 } else { c.to_bits() });
        let mut seen: HashMap<[u64; 3], u32> = HashMap::new();
        for v in (0..n).filter(|&v| used[v]) {
            let k = key(&mesh.vertices[v]);
            let k = [k.x, k.y, k.z];
            match seen.get(&k) {
                Some(&r) => {
                    welded_of[v] = Some(r);
                    merged_vertices += 1;
                }
                None => {
                    let r = reps.len() as u32;
                    reps.push(v as u32);
                    seen.insert(k, r);
                    welded_of[v] = Some(r);
                }
            }
        }
    }

    // Triangles over representatives.
    let mut kept: Vec<[u32; 3]> = Vec::with_capacity(mesh.triangles.len());
    let mut seen: HashSet<[u32; 3]> = HashSet::with_capacity(mesh.triangles.len());
    let (mut degenerate, mut duplicate) = (0usize, 0usize);
    for t in &mesh.triangles {
        let w = t.map(|i| welded_of[i as usize].unwrap_or(u32::MAX));
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] {
            degenerate += 1;
            continue;
        }
        let mut key = w;
        key.sort_unstable();
        if !seen.insert(key) {
            duplicate += 1;
            continue;
        }
        kept.push(w);
    }
    if kept.is_empty() {
        return Err(Error::invalid(
            "mesh",
            format!(
                "no triangle is left after welding ({} triangles, {degenerate} of them collapsed to zero area)",
                mesh.triangles.len()
            ),
        ));
    }

    // Compact: representatives used by a kept triangle, in order of first appearance.
    let mut final_of_rep: Vec<Option<u32>> = vec![None; reps.len()];
    for t in &kept {
        for &r in t {
            final_of_rep[r as usize] = Some(0);
        }
    }
    let mut vertices = Vec::new();
    for (r, slot) in final_of_rep.iter_mut().enumerate() {
        if slot.is_some() {
            *slot = Some(vertices.len() as u32);
            vertices.push(mesh.vertices[reps[r] as usize]);
        }
    }
    let triangles: Vec<[u32; 3]> =
        kept.iter().map(|t| t.map(|r| final_of_rep[r as usize].unwrap_or(u32::MAX))).collect();
    let source: Vec<Option<u32>> = welded_of.iter().map(|w| w.and_then(|r| final_of_rep[r as usize])).collect();
    let report = WeldReport {
        tolerance: eps,
        vertices_before: n,
        vertices_after: vertices.len(),
        merged_vertices,
        unused_vertices: n - merged_vertices - vertices.len(),
        triangles_before: mesh.triangles.len(),
        triangles_after: triangles.len(),
        degenerate_triangles: degenerate,
        duplicate_triangles: duplicate,
    };
    Ok(WeldedMesh { mesh: TriangleMesh { vertices, triangles }, source, report })
}
