//! STL, ASCII or binary, read by stl_io (which merges shared vertices) once the counts are
//! checked here: a binary file's triangle count against its size and `3 × max_points`, an ASCII
//! file's `vertex` lines against `9 × max_points`. stl_io runs under [`super::limits::guarded`],
//! and its messages are rewritten as plain sentences ([`foreign_message`]).

use super::limits::{exhausted, foreign_message, invalid, plural};
use super::TriangleMesh;
use sublevel_core::math::{Point3, Real};
use sublevel_core::Result;

/// Binary STL: 80-byte header, u32 little-endian triangle count, 50 bytes per triangle.
const STL_HEADER_BYTES: usize = 84;

/// Bytes of one binary STL triangle: normal and three vertices (12 f32) and a u16 attribute.
const STL_TRIANGLE_BYTES: u64 = 50;

/// Whether stl_io reads `bytes` as ASCII: its first line is UTF-8 text starting with `solid `.
fn stl_is_ascii(bytes: &[u8]) -> bool {
    let first = match bytes.iter().position(|&b| b == b'\n') {
        Some(i) => &bytes[..=i],
        None => bytes,
    };
    first.starts_with(b"solid ") && std::str::from_utf8(first).is_ok()
}

/// Checks the triangle count of a binary STL against the file size and `3 × max_points` (every
/// triangle adds at most 3 vertices; a closed mesh of V vertices has about 2V triangles), or
/// the number of `vertex` lines of an ASCII STL against `9 × max_points`.
pub(super) fn check_stl_counts(bytes: &[u8], max_points: usize) -> Result<()> {
    let max_triangles = max_points.saturating_mul(3) as u64;
    if stl_is_ascii(bytes) {
        let vertex_lines = bytes
            .split(|&b| b == b'\n')
            .filter(|l| std::str::from_utf8(l).ok().and_then(|s| s.split_whitespace().next()) == Some("vertex"))
            .count() as u64;
        let triangles = vertex_lines.div_ceil(3);
        if triangles > max_triangles {
            return Err(exhausted(format!(
                "the stl file has {triangles} triangles ({vertex_lines} `vertex` lines), more than 3 × the limit of \
                 {max_points} points"
            )));
        }
        return Ok(());
    }
    if bytes.len() < STL_HEADER_BYTES {
        return Err(invalid(format!(
            "stl file has {} {}: too short for a binary stl (an 80-byte header and a 4-byte triangle count) \
             and it does not start with `solid ` (ascii)",
            bytes.len(),
            plural(bytes.len() as u128, "byte", "bytes")
        )));
    }
    let count = u64::from(u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]));
    let after = (bytes.len() - STL_HEADER_BYTES) as u64;
    if count * STL_TRIANGLE_BYTES > after {
        return Err(invalid(format!(
            "stl header declares {count} {} but the file has {after} {} after its {STL_HEADER_BYTES}-byte header \
             ({STL_TRIANGLE_BYTES} bytes per triangle)",
            plural(count, "triangle", "triangles"),
            plural(after, "byte", "bytes"),
        )));
    }
    if count > max_triangles {
        return Err(exhausted(format!(
            "the stl header declares {count} triangles, more than 3 × the limit of {max_points} points"
        )));
    }
    Ok(())
}

/// The vertices stl_io reads (shared vertices merged); call [`check_stl_counts`] first.
pub(super) fn parse_stl(bytes: &[u8]) -> Result<Vec<Point3>> {
    Ok(parse_stl_mesh(bytes)?.vertices)
}

/// The vertices and triangles stl_io reads (vertices of exactly equal coordinates merged, so a
/// triangle's corners index shared vertices); call [`check_stl_counts`] first.
pub(super) fn parse_stl_mesh(bytes: &[u8]) -> Result<TriangleMesh> {
    let mut cur = std::io::Cursor::new(bytes);
    let mesh = stl_io::read_stl(&mut cur)
        .map_err(|e| invalid(format!("malformed stl file: {}", foreign_message(&e.to_string()))))?;
    let vertices: Vec<Point3> =
        mesh.vertices.iter().map(|v| Point3::new(v[0] as Real, v[1] as Real, v[2] as Real)).collect();
    let mut triangles = Vec::with_capacity(mesh.faces.len());
    for (k, f) in mesh.faces.iter().enumerate() {
        let mut t = [0u32; 3];
        for (slot, &i) in t.iter_mut().zip(&f.vertices) {
            *slot = u32::try_from(i)
                .ok()
                .filter(|&i| (i as usize) < vertices.len())
                .ok_or_else(|| invalid(format!("stl triangle {k} names vertex {i} of {}", vertices.len())))?;
        }
        triangles.push(t);
    }
    Ok(TriangleMesh { vertices, triangles })
}
