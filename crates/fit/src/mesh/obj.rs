//! Wavefront OBJ: the `v x y z [w]` lines of every object. Read here rather than by tobj, which
//! stores every face before returning positions, returns none for a point cloud without faces,
//! and panics on some relative normal indices (module docs of [`super`]). The `v` lines are
//! counted against `max_points` before anything is reserved.

use super::limits::{exhausted, invalid, parse_coord, text};
use sublevel_core::math::Point3;
use sublevel_core::Result;

/// `v x y z [w]` lines (a 4th value divides, more values, e.g. colors, are ignored); every other
/// statement (faces, normals, texture coordinates, groups, materials) is skipped unread, so a
/// point-cloud OBJ without faces gives its points and no face is stored.
pub(super) fn parse_obj(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
    let s = text(bytes, "obj")?;
    // (line number, the values after `v`)
    let vertex_lines = || {
        s.lines().enumerate().filter_map(|(i, line)| {
            let mut toks = line.split('#').next().unwrap_or("").split_whitespace();
            (toks.next() == Some("v")).then_some((i + 1, toks))
        })
    };
    let n = vertex_lines().count();
    if n > max_points {
        return Err(exhausted(format!(
            "the obj file has {n} `v` lines, which exceeds the limit of {max_points} points"
        )));
    }
    let mut pts = Vec::with_capacity(n);
    for (line, mut toks) in vertex_lines() {
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
    Ok(pts)
}
