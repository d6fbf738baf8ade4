//! XYZ point lists (also `.txt`, `.pts`): one "x y z" per line; commas or whitespace separate;
//! extra columns (normals, colors) are ignored; `#` comments and blank lines are skipped. The
//! point lines are counted against `max_points` before anything is reserved.

use super::limits::{exhausted, parse_coord, text};
use sublevel_core::math::Point3;
use sublevel_core::Result;

/// One "x y z" per line; commas or whitespace separate; extra columns (normals, colors) ignored.
pub(super) fn parse_xyz(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
    let s = text(bytes, "xyz")?;
    let data_lines = || {
        s.lines()
            .enumerate()
            .map(|(i, line)| (i + 1, line.split('#').next().unwrap_or("").trim()))
            .filter(|(_, l)| !l.is_empty())
    };
    let n = data_lines().count();
    if n > max_points {
        return Err(exhausted(format!(
            "the xyz file has {n} point lines, which exceeds the limit of {max_points} points"
        )));
    }
    let mut pts = Vec::with_capacity(n);
    for (line, l) in data_lines() {
        let mut it = l.split(|c: char| c.is_whitespace() || c == ',').filter(|t| !t.is_empty());
        let x = parse_coord(it.next(), line, "xyz")?;
        let y = parse_coord(it.next(), line, "xyz")?;
        let z = parse_coord(it.next(), line, "xyz")?;
        pts.push(Point3::new(x, y, z));
    }
    Ok(pts)
}
