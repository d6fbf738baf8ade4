//! OFF, the Princeton Shape Benchmark's format (the paper's chair and human), ASCII only:
//!
//! ```text
//! OFF                       header; the counts may follow on the same line (`OFF nV nF nE`)
//! nV nF nE                  vertex, face and edge counts (nE is not used)
//! x y z                     nV vertex lines
//! k i₁ … i_k [r g b [a]]    nF face lines: k 0-based vertex indices, then an optional color
//! ```
//!
//! `#` starts a comment; blank lines are skipped. One parser, [`read_off`], serves both uses: a fit
//! needs only the vertices ([`super::parse_points_limited`] skips the face lines unread, so a fit
//! never fails on a face), the exact mesh–mesh distance of `sublevel-lab bench` / `chart` needs the
//! faces too ([`parse_off_mesh`]), split into triangle fans.
//!
//! # Limits
//!
//! The vertex count is checked against `max_points` and, like the face count, against the bytes
//! after the counts line (every vertex line takes at least `0 0 0\n`, every face line `0\n`)
//! before anything is reserved. A header that declares more than the bytes hold reserves nothing:
//! the lines present are still read (bounded by the input), so the error names the first bad line
//! or where the file ends. The triangles are bounded by the input too (each index takes at least
//! two bytes).

use super::limits::{echo, exhausted, invalid, parse_coord, plural, text};
use super::TriangleMesh;
use sublevel_core::math::Point3;
use sublevel_core::Result;

/// Shortest OFF vertex line, `0 0 0\n`.
const OFF_MIN_VERTEX_BYTES: usize = 6;

/// Shortest OFF face line, `0\n` (a face without vertices).
const OFF_MIN_FACE_BYTES: usize = 2;

/// The triangle mesh of an OFF file ([`parse_off_mesh`]): a [`TriangleMesh`], as every format gives.
pub type OffMesh = TriangleMesh;

/// Parses an ASCII OFF file with its faces (see the module documentation), at most `max_points`
/// vertices.
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] naming `mesh` for text that is not OFF, a header that
/// declares more vertices or faces than the bytes can hold, a non-finite coordinate, a face index
/// that is not a vertex of the file, or a file without vertices;
/// [`sublevel_core::Error::ResourceExhausted`] naming `mesh` when the header declares more than
/// `max_points` vertices.
pub fn parse_off_mesh(bytes: &[u8], max_points: usize) -> Result<TriangleMesh> {
    let mesh = read_off(bytes, max_points, true)?;
    if mesh.vertices.is_empty() {
        return Err(invalid("the off file has no vertices"));
    }
    Ok(mesh)
}

/// Reads the header, the counts and the vertices of an OFF file and, when `with_faces`, its faces
/// (split into triangle fans); without, the face lines are skipped unread and `triangles` is
/// empty.
pub(super) fn read_off(bytes: &[u8], max_points: usize, with_faces: bool) -> Result<TriangleMesh> {
    let s = text(bytes, "off")?;
    // Meaningful lines: (1-based number, byte offset just past the line, content without comment).
    let mut lines = s
        .split_inclusive('\n')
        .enumerate()
        .scan(0usize, |end, (i, raw)| {
            *end += raw.len();
            Some((i + 1, *end, raw.split('#').next().unwrap_or("").trim()))
        })
        .filter(|(_, _, l)| !l.is_empty());
    let (hl, header_end, header) = lines.next().ok_or_else(|| invalid("off file is empty"))?;
    let mut counts_toks: Vec<&str> = Vec::new();
    let (mut counts_line, mut counts_end) = (hl, header_end);
    if let Some(rest) = header.strip_prefix("OFF") {
        if !rest.is_empty() && !rest.starts_with(char::is_whitespace) {
            return Err(invalid(format!("off line {hl}: unsupported header `{}` (only OFF)", echo(header))));
        }
        counts_toks.extend(rest.split_whitespace());
    } else {
        return Err(invalid(format!("off line {hl}: expected header `OFF`, found `{}`", echo(header))));
    }
    if counts_toks.is_empty() {
        let (l, end, c) = lines.next().ok_or_else(|| invalid("off file ends after its header"))?;
        (counts_line, counts_end) = (l, end);
        counts_toks.extend(c.split_whitespace());
    }
    let nv: usize = counts_toks
        .first()
        .and_then(|t| t.parse().ok())
        .ok_or_else(|| invalid(format!("off line {counts_line}: expected vertex/face/edge counts `nV nF nE`")))?;
    let Some(nf) = counts_toks.get(1).and_then(|t| t.parse::<usize>().ok()) else {
        return Err(invalid(format!("off line {counts_line}: expected counts `nV nF nE`")));
    };
    // Every vertex line takes at least `0 0 0\n`, the last may lack its newline. A header that
    // declares more than the bytes hold reserves nothing: the lines present are still checked
    // (bounded by the input) so the error names the first bad line or where the file ends.
    let remaining = s.len() - counts_end;
    let fits = nv.saturating_mul(OFF_MIN_VERTEX_BYTES) <= remaining.saturating_add(1);
    if fits && nv > max_points {
        return Err(exhausted(format!(
            "the off header declares {nv} vertices, which exceeds the limit of {max_points} points"
        )));
    }
    let mut pts = Vec::with_capacity(if fits { nv } else { 0 });
    let lie = || {
        format!(
            "{nv} {} need at least {} bytes after the counts line, the file has {remaining}",
            plural(nv as u128, "vertex", "vertices"),
            nv.saturating_mul(OFF_MIN_VERTEX_BYTES)
        )
    };
    let mut vertices_end = counts_end;
    for k in 0..nv {
        let Some((l, end, c)) = lines.next() else {
            let why = if fits { String::new() } else { format!(" ({})", lie()) };
            return Err(invalid(format!("off file ends after {k} of {nv} vertices{why}")));
        };
        let mut it = c.split_whitespace();
        let x = parse_coord(it.next(), l, "off")?;
        let y = parse_coord(it.next(), l, "off")?;
        let z = parse_coord(it.next(), l, "off")?;
        if fits {
            pts.push(Point3::new(x, y, z));
        }
        vertices_end = end;
    }
    if !fits {
        // Unreachable (nv valid lines take the bytes counted above), kept as a guard.
        return Err(invalid(format!("off header declares more vertices than the file holds ({})", lie())));
    }
    let mut triangles = Vec::new();
    if with_faces {
        read_faces(&mut lines, nv, nf, s.len() - vertices_end, &mut triangles)?;
    }
    Ok(TriangleMesh { vertices: pts, triangles })
}

/// Reads `nf` face lines (after the vertices; `remaining` bytes follow them) into `triangles`,
/// each face split into a fan. Checks every index against the `nv` vertices.
fn read_faces<'a>(
    lines: &mut impl Iterator<Item = (usize, usize, &'a str)>,
    nv: usize,
    nf: usize,
    remaining: usize,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<()> {
    // As for the vertices: reserve only what the bytes can hold, still read the lines present.
    let fits = nf.saturating_mul(OFF_MIN_FACE_BYTES) <= remaining.saturating_add(1);
    if fits {
        triangles.reserve(nf);
    }
    let mut face: Vec<u32> = Vec::new();
    for f in 0..nf {
        let Some((l, _, c)) = lines.next() else {
            let why = if fits {
                String::new()
            } else {
                format!(
                    " ({nf} {} need at least {} bytes after the vertices, the file has {remaining})",
                    plural(nf as u128, "face", "faces"),
                    nf.saturating_mul(OFF_MIN_FACE_BYTES)
                )
            };
            return Err(invalid(format!("off file ends after {f} of {nf} faces{why}")));
        };
        let mut it = c.split_whitespace();
        let k: usize = it
            .next()
            .and_then(|t| t.parse().ok())
            .ok_or_else(|| invalid(format!("off line {l}: expected a face `k i₁ … i_k`")))?;
        face.clear();
        for j in 0..k {
            let tok = it.next().ok_or_else(|| {
                invalid(format!(
                    "off line {l}: the face has {j} of its {k} vertex {}",
                    plural(k as u128, "index", "indices")
                ))
            })?;
            let i = tok.parse::<u32>().ok().filter(|&i| (i as usize) < nv).ok_or_else(|| {
                invalid(format!("off line {l}: `{}` is not a vertex index (the file has {nv} vertices)", echo(tok)))
            })?;
            face.push(i);
        }
        // The rest of the line (a color) is ignored.
        for j in 1..k.saturating_sub(1) {
            triangles.push([face[0], face[j], face[j + 1]]);
        }
    }
    Ok(())
}
