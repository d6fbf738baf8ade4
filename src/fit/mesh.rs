//! Mesh and point-cloud loading: OFF, OBJ, STL (ASCII and binary), PLY (ASCII and binary), XYZ.
//!
//! Only vertices are returned (faces are irrelevant to a fit: the convex hull is recomputed).
//!
//! ```text
//! off   "OFF" header line (also "OFF nV nF nE" on one line), then "nV nF nE", nV lines "x y z",
//!       faces ignored; '#' comments and blank lines skipped             (parsed here)
//! obj   `v x y z` lines of every object                                  (tobj)
//! stl   ASCII or binary; shared vertices merged by stl_io               (stl_io)
//! ply   the `vertex` element's x, y, z properties (any numeric type)    (ply-rs)
//! xyz   one "x y z" per line (commas allowed, extra columns ignored)     (parsed here)
//! ```
//!
//! Every failure is [`crate::Error::InvalidArgument`] naming `mesh`, with the line number for
//! the text formats parsed here; third-party parsers run under `catch_unwind`, so malformed bytes
//! never panic.

use crate::math::{Point3, Real};
use crate::{Error, Result};

/// Reads the vertices of a mesh file; the format follows the extension (case-insensitive).
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::InvalidArgument`] naming `mesh` for an
/// unknown format or an unparsable file.
pub fn load_points(path: &std::path::Path) -> Result<Vec<Point3>> {
    let bytes = std::fs::read(path)?;
    parse_points(&bytes, path.extension().and_then(|e| e.to_str()).unwrap_or(""))
}

/// Parses mesh bytes in the given format (`off`, `obj`, `stl`, `ply`, or `xyz` for "x y z" lines;
/// case-insensitive, a leading dot is ignored).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `mesh` for an unknown format, unparsable bytes, a
/// non-finite coordinate, or a file without vertices.
pub fn parse_points(bytes: &[u8], format: &str) -> Result<Vec<Point3>> {
    let fmt = format.trim_start_matches('.').to_ascii_lowercase();
    let points = match fmt.as_str() {
        "off" => parse_off(bytes)?,
        "xyz" | "txt" | "pts" => parse_xyz(bytes)?,
        "obj" => guarded("obj", || parse_obj(bytes))?,
        "stl" => guarded("stl", || parse_stl(bytes))?,
        "ply" => guarded("ply", || parse_ply(bytes))?,
        other => {
            return Err(Error::invalid(
                "mesh",
                format!("unknown format `{other}`; expected one of off, obj, stl, ply, xyz"),
            ))
        }
    };
    if points.is_empty() {
        return Err(Error::invalid("mesh", format!("the {fmt} file has no vertices")));
    }
    if let Some(i) = points.iter().position(|p| !p.coords.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid("mesh", format!("vertex {i} has a non-finite coordinate")));
    }
    Ok(points)
}

/// Runs a third-party parser, turning a panic into an error naming `mesh`.
fn guarded(fmt: &str, f: impl FnOnce() -> Result<Vec<Point3>>) -> Result<Vec<Point3>> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| Err(Error::invalid("mesh", format!("malformed {fmt} file (the parser gave up)"))))
}

fn text(bytes: &[u8], fmt: &str) -> Result<String> {
    String::from_utf8(bytes.to_vec()).map_err(|e| Error::invalid("mesh", format!("{fmt} file is not UTF-8 text: {e}")))
}

fn parse_coord(tok: Option<&str>, line: usize, fmt: &str) -> Result<Real> {
    let tok = tok.ok_or_else(|| Error::invalid("mesh", format!("{fmt} line {line}: expected 3 coordinates")))?;
    let v: Real =
        tok.parse().map_err(|_| Error::invalid("mesh", format!("{fmt} line {line}: `{tok}` is not a number")))?;
    if !v.is_finite() {
        return Err(Error::invalid("mesh", format!("{fmt} line {line}: coordinate `{tok}` is not finite")));
    }
    Ok(v)
}

/// ASCII OFF (the PSB files): header, counts, vertices; faces are skipped unread.
fn parse_off(bytes: &[u8]) -> Result<Vec<Point3>> {
    let s = text(bytes, "off")?;
    // Meaningful lines with their 1-based numbers; comments stripped.
    let mut lines = s
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("").trim()))
        .filter(|(_, l)| !l.is_empty());
    let (hl, header) = lines.next().ok_or_else(|| Error::invalid("mesh", "off file is empty"))?;
    let mut counts_toks: Vec<&str> = Vec::new();
    let mut counts_line = hl;
    if let Some(rest) = header.strip_prefix("OFF") {
        if !rest.is_empty() && !rest.starts_with(char::is_whitespace) {
            return Err(Error::invalid("mesh", format!("off line {hl}: unsupported header `{header}` (only OFF)")));
        }
        counts_toks.extend(rest.split_whitespace());
    } else {
        return Err(Error::invalid("mesh", format!("off line {hl}: expected header `OFF`, found `{header}`")));
    }
    if counts_toks.is_empty() {
        let (l, c) = lines.next().ok_or_else(|| Error::invalid("mesh", "off file ends after its header"))?;
        counts_line = l;
        counts_toks.extend(c.split_whitespace());
    }
    let nv: usize = counts_toks.first().and_then(|t| t.parse().ok()).ok_or_else(|| {
        Error::invalid("mesh", format!("off line {counts_line}: expected vertex/face/edge counts `nV nF nE`"))
    })?;
    if counts_toks.len() < 2 || counts_toks[1].parse::<usize>().is_err() {
        return Err(Error::invalid("mesh", format!("off line {counts_line}: expected counts `nV nF nE`")));
    }
    let mut pts = Vec::with_capacity(nv.min(10_000_000));
    for k in 0..nv {
        let (l, c) =
            lines.next().ok_or_else(|| Error::invalid("mesh", format!("off file ends after {k} of {nv} vertices")))?;
        let mut it = c.split_whitespace();
        let x = parse_coord(it.next(), l, "off")?;
        let y = parse_coord(it.next(), l, "off")?;
        let z = parse_coord(it.next(), l, "off")?;
        pts.push(Point3::new(x, y, z));
    }
    Ok(pts)
}

/// One "x y z" per line; commas or whitespace separate; extra columns (normals, colors) ignored.
fn parse_xyz(bytes: &[u8]) -> Result<Vec<Point3>> {
    let s = text(bytes, "xyz")?;
    let mut pts = Vec::new();
    for (i, line) in s.lines().enumerate() {
        let l = line.split('#').next().unwrap_or("").trim();
        if l.is_empty() {
            continue;
        }
        let mut it = l.split(|c: char| c.is_whitespace() || c == ',').filter(|t| !t.is_empty());
        let x = parse_coord(it.next(), i + 1, "xyz")?;
        let y = parse_coord(it.next(), i + 1, "xyz")?;
        let z = parse_coord(it.next(), i + 1, "xyz")?;
        pts.push(Point3::new(x, y, z));
    }
    Ok(pts)
}

fn parse_obj(bytes: &[u8]) -> Result<Vec<Point3>> {
    let mut reader = std::io::BufReader::new(bytes);
    let opts = tobj::LoadOptions { single_index: false, triangulate: false, ..Default::default() };
    let (models, _) = tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| Error::invalid("mesh", format!("malformed obj file: {e}")))?;
    let mut pts = Vec::new();
    for m in models {
        for v in m.mesh.positions.chunks_exact(3) {
            pts.push(Point3::new(v[0] as Real, v[1] as Real, v[2] as Real));
        }
    }
    Ok(pts)
}

fn parse_stl(bytes: &[u8]) -> Result<Vec<Point3>> {
    let mut cur = std::io::Cursor::new(bytes);
    let mesh = stl_io::read_stl(&mut cur).map_err(|e| Error::invalid("mesh", format!("malformed stl file: {e}")))?;
    Ok(mesh.vertices.iter().map(|v| Point3::new(v[0] as Real, v[1] as Real, v[2] as Real)).collect())
}

fn parse_ply(bytes: &[u8]) -> Result<Vec<Point3>> {
    use ply_rs::ply::Property;
    let parser = ply_rs::parser::Parser::<ply_rs::ply::DefaultElement>::new();
    let mut cur = std::io::Cursor::new(bytes);
    let ply = parser.read_ply(&mut cur).map_err(|e| Error::invalid("mesh", format!("malformed ply file: {e}")))?;
    let verts = ply.payload.get("vertex").ok_or_else(|| Error::invalid("mesh", "ply file has no `vertex` element"))?;
    let num = |p: Option<&Property>, name: &str, i: usize| -> Result<Real> {
        Ok(match p {
            Some(Property::Float(v)) => *v as Real,
            Some(Property::Double(v)) => *v,
            Some(Property::Char(v)) => *v as Real,
            Some(Property::UChar(v)) => *v as Real,
            Some(Property::Short(v)) => *v as Real,
            Some(Property::UShort(v)) => *v as Real,
            Some(Property::Int(v)) => *v as Real,
            Some(Property::UInt(v)) => *v as Real,
            Some(_) => return Err(Error::invalid("mesh", format!("ply vertex {i}: `{name}` is a list, not a number"))),
            None => return Err(Error::invalid("mesh", format!("ply vertex {i}: missing property `{name}`"))),
        })
    };
    verts
        .iter()
        .enumerate()
        .map(|(i, v)| Ok(Point3::new(num(v.get("x"), "x", i)?, num(v.get("y"), "y", i)?, num(v.get("z"), "z", i)?)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expect_mesh_error(r: Result<Vec<Point3>>, needle: &str) {
        match r {
            Err(Error::InvalidArgument { field, reason }) => {
                assert_eq!(field, "mesh");
                assert!(reason.contains(needle), "`{reason}` lacks `{needle}`");
            }
            other => panic!("expected InvalidArgument(mesh), got {other:?}"),
        }
    }

    #[test]
    fn off_parses_and_reports_line_numbers() {
        let off = b"OFF\n# a comment\n4 1 0\n0 0 0\n1 0 0\n0 1.5 0\n0 0 -2e-1\n3 0 1 2\n";
        let p = parse_points(off, "off").unwrap();
        assert_eq!(
            p,
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.5, 0.0),
                Point3::new(0.0, 0.0, -0.2)
            ]
        );
        // Counts on the header line.
        assert_eq!(parse_points(b"OFF 1 0 0\n1 2 3\n", ".OFF").unwrap(), vec![Point3::new(1.0, 2.0, 3.0)]);
        expect_mesh_error(parse_points(b"OFF\n2 0 0\n1 2 3\n4 x 6\n", "off"), "off line 4: `x` is not a number");
        expect_mesh_error(parse_points(b"OFF\n3 0 0\n1 2 3\n", "off"), "ends after 1 of 3 vertices");
        expect_mesh_error(parse_points(b"PLY\n", "off"), "off line 1: expected header");
        expect_mesh_error(parse_points(b"OFF\nfoo\n", "off"), "off line 2");
        expect_mesh_error(parse_points(b"OFF\n1 0 0\n1 2\n", "off"), "off line 3: expected 3 coordinates");
        expect_mesh_error(parse_points(b"OFF\n1 0 0\n1 2 inf\n", "off"), "not finite");
        expect_mesh_error(parse_points(b"", "off"), "empty");
        expect_mesh_error(parse_points(&[0xff, 0xfe, 0x00], "off"), "UTF-8");
    }

    #[test]
    fn xyz_parses_and_reports_line_numbers() {
        let p = parse_points(b"1 2 3\n\n4,5,6 0 0 1\n# end\n", "xyz").unwrap();
        assert_eq!(p, vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)]);
        expect_mesh_error(parse_points(b"1 2 3\n1 2\n", "xyz"), "xyz line 2");
        expect_mesh_error(parse_points(b"\n\n", "xyz"), "no vertices");
    }

    #[test]
    fn obj_parses_vertices() {
        let obj = b"# cube corner\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1.25\nf 1 2 3\nf 1 2 4\n";
        let p = parse_points(obj, "OBJ").unwrap();
        assert_eq!(p.len(), 4);
        assert_eq!(p[3], Point3::new(0.0, 0.0, 1.25));
        expect_mesh_error(parse_points(b"v 1 2 zz\n", "obj"), "obj");
    }

    fn stl_binary(tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut out = vec![0u8; 80];
        out.extend((tris.len() as u32).to_le_bytes());
        for t in tris {
            out.extend([0f32; 3].iter().flat_map(|v| v.to_le_bytes()));
            for v in t {
                out.extend(v.iter().flat_map(|c| c.to_le_bytes()));
            }
            out.extend([0u8; 2]);
        }
        out
    }

    #[test]
    fn stl_ascii_and_binary_parse() {
        let ascii = b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 2 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 0 3\nendloop\nendfacet\nendsolid t\n";
        let mut p = parse_points(ascii, "stl").unwrap();
        p.sort_by(|a, b| a.coords.iter().partial_cmp(b.coords.iter()).unwrap());
        assert_eq!(
            p,
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(0.0, 0.0, 3.0),
                Point3::new(0.0, 2.0, 0.0),
                Point3::new(1.0, 0.0, 0.0)
            ]
        );
        let bin = stl_binary(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]]);
        let mut q = parse_points(&bin, "stl").unwrap();
        q.sort_by(|a, b| a.coords.iter().partial_cmp(b.coords.iter()).unwrap());
        assert_eq!(q, vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.0, 2.0, 0.0), Point3::new(1.0, 0.0, 0.0)]);
        // Truncated binary: header promises 5 triangles, holds 1.
        let mut bad = bin.clone();
        bad[80] = 5;
        expect_mesh_error(parse_points(&bad, "stl"), "stl");
        expect_mesh_error(parse_points(b"solid x\nfacet normal 0 0\n", "stl"), "stl");
    }

    #[test]
    fn ply_ascii_and_binary_parse() {
        let ascii = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0.5\n0 2 -1\n3 0 1 2\n";
        let p = parse_points(ascii, "ply").unwrap();
        assert_eq!(p, vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.5), Point3::new(0.0, 2.0, -1.0)]);
        let mut bin =
            b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
                .to_vec();
        for v in [1.0f32, 2.0, 3.0, -4.0, 0.5, 6.0] {
            bin.extend(v.to_le_bytes());
        }
        let q = parse_points(&bin, "ply").unwrap();
        assert_eq!(q, vec![Point3::new(1.0, 2.0, 3.0), Point3::new(-4.0, 0.5, 6.0)]);
        expect_mesh_error(parse_points(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2\n", "ply"), "ply");
        expect_mesh_error(
            parse_points(
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
                "ply",
            ),
            "missing property `z`",
        );
        expect_mesh_error(parse_points(b"not a ply", "ply"), "ply");
    }

    #[test]
    fn unknown_format_is_named() {
        expect_mesh_error(parse_points(b"1 2 3", "vtk"), "unknown format `vtk`");
    }
}
