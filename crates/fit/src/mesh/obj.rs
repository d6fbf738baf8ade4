//! Wavefront OBJ: the `v x y z [w]` lines of every object and, for a triangle mesh, the `f`
//! lines of every object and group (merged into one mesh). Read here rather than by tobj, which
//! stores every face before returning positions, returns none for a point cloud without faces,
//! and panics on some relative normal indices (module docs of [`super`]). The `v` lines are
//! counted against `max_points` before anything is reserved; the triangles are bounded by the
//! input (every index takes at least two bytes).
//!
//! ```text
//! v x y z [w]             a vertex (a 4th value divides, more values, e.g. colors, are ignored)
//! f i j k …               a face: k ≥ 3 corners `v`, `v/vt`, `v//vn` or `v/vt/vn`; v is 1-based,
//!                         or negative: relative to the vertices read so far (−1 the last one);
//!                         split into the fan (i, j, k), (i, k, l), …
//! ```

use super::limits::{echo, exhausted, invalid, parse_coord, text};
use super::TriangleMesh;
use sublevel_core::math::Point3;
use sublevel_core::Result;

/// `v x y z [w]` lines (a 4th value divides, more values, e.g. colors, are ignored); every other
/// statement (faces, normals, texture coordinates, groups, materials) is skipped unread, so a
/// point-cloud OBJ without faces gives its points and no face is stored.
pub(super) fn parse_obj(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
    Ok(read_obj(bytes, max_points, false)?.vertices)
}

/// The vertices and the faces (split into triangle fans) of every object and group; a file
/// without `f` lines gives no triangles.
pub(super) fn parse_obj_mesh(bytes: &[u8], max_points: usize) -> Result<TriangleMesh> {
    read_obj(bytes, max_points, true)
}

/// One pass over the statements: `v` always, `f` when `with_faces`.
fn read_obj(bytes: &[u8], max_points: usize, with_faces: bool) -> Result<TriangleMesh> {
    let s = text(bytes, "obj")?;
    let statements =
        || s.lines().enumerate().map(|(i, line)| (i + 1, line.split('#').next().unwrap_or("").split_whitespace()));
    let n = statements().filter(|(_, toks)| toks.clone().next() == Some("v")).count();
    if n > max_points {
        return Err(exhausted(format!(
            "the obj file has {n} `v` lines, which exceeds the limit of {max_points} points"
        )));
    }
    let mut pts = Vec::with_capacity(n);
    let mut triangles = Vec::new();
    let mut face: Vec<u32> = Vec::new();
    for (line, mut toks) in statements() {
        match toks.next() {
            Some("v") => {
                let x = parse_coord(toks.next(), line, "obj")?;
                let y = parse_coord(toks.next(), line, "obj")?;
                let z = parse_coord(toks.next(), line, "obj")?;
                let mut p = Point3::new(x, y, z);
                if let (Some(w), None) = (toks.next(), toks.next()) {
                    let w = parse_coord(Some(w), line, "obj")?;
                    if w == 0.0 {
                        return Err(invalid(format!("obj line {line}: the weight w is 0")));
                    }
                    p /= w;
                }
                pts.push(p);
            }
            Some("f") if with_faces => {
                face.clear();
                for tok in toks {
                    face.push(face_index(tok, line, pts.len(), n)?);
                }
                if face.len() < 3 {
                    return Err(invalid(format!(
                        "obj line {line}: a face needs at least 3 vertices, this one has {}",
                        face.len()
                    )));
                }
                for j in 1..face.len() - 1 {
                    triangles.push([face[0], face[j], face[j + 1]]);
                }
            }
            _ => {}
        }
    }
    Ok(TriangleMesh { vertices: pts, triangles })
}

/// The 0-based vertex index of one face corner `v[/vt][/vn]`: `v` is 1-based, or negative and
/// relative to the `read` vertices so far; it must name one of the file's `total` vertices.
fn face_index(tok: &str, line: usize, read: usize, total: usize) -> Result<u32> {
    let v = tok.split('/').next().unwrap_or("");
    let bad = |why: &str| invalid(format!("obj line {line}: face corner `{}` {why}", echo(tok)));
    let i: i64 = v.parse().map_err(|_| bad("does not start with a vertex index"))?;
    let index = match i {
        0 => return Err(bad("has vertex index 0 (indices are 1-based)")),
        i if i > 0 => i - 1,
        i => read as i64 + i,
    };
    if index < 0 || index >= total as i64 {
        return Err(bad(&format!("names no vertex (the file has {total})")));
    }
    u32::try_from(index).map_err(|_| bad("names a vertex beyond the 32-bit index range"))
}
