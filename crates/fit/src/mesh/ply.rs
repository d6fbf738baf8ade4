//! PLY, ascii or binary (either endianness), read here rather than by ply-rs, which trusts the
//! header (module docs of [`super`]). The header is bounded ([`MAX_PLY_HEADER_BYTES`], at most
//! [`MAX_PLY_ELEMENTS`] elements of at most [`MAX_PLY_PROPERTIES`] properties); every element's
//! count is checked against the bytes after the header (the sum of its property sizes per binary
//! item, 2 bytes per property per ascii line) and the vertex count against `max_points` before
//! anything is reserved. Only the `vertex` element's x, y, z are kept and, for a triangle mesh
//! ([`parse_ply_mesh`]), the `face` element's `vertex_indices` (or `vertex_index`) lists, split
//! into triangle fans; every other list property is skipped, never stored. The triangles are
//! bounded by the input (every list item takes at least one byte).

use super::limits::{echo, exhausted, invalid, plural};
use super::TriangleMesh;
use crate::{Error, Result};
use sublevel_core::math::Point3;

/// Longest accepted PLY header (from `ply` to `end_header`), in bytes.
pub const MAX_PLY_HEADER_BYTES: usize = 64 * 1024;

/// Most elements a PLY header may declare.
pub(super) const MAX_PLY_ELEMENTS: usize = 64;

/// Most properties one PLY element may declare.
pub(super) const MAX_PLY_PROPERTIES: usize = 256;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PlyEncoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PlyScalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl PlyScalar {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            Self::I8 => "char",
            Self::U8 => "uchar",
            Self::I16 => "short",
            Self::U16 => "ushort",
            Self::I32 => "int",
            Self::U32 => "uint",
            Self::F32 => "float",
            Self::F64 => "double",
        }
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }

    /// An ascii value of this type, as a number.
    fn parse_text(self, tok: &str) -> Option<f64> {
        let (lo, hi) = match self {
            Self::F32 => return tok.parse::<f32>().ok().map(f64::from),
            Self::F64 => return tok.parse::<f64>().ok(),
            Self::I8 => (i64::from(i8::MIN), i64::from(i8::MAX)),
            Self::U8 => (0, i64::from(u8::MAX)),
            Self::I16 => (i64::from(i16::MIN), i64::from(i16::MAX)),
            Self::U16 => (0, i64::from(u16::MAX)),
            Self::I32 => (i64::from(i32::MIN), i64::from(i32::MAX)),
            Self::U32 => (0, i64::from(u32::MAX)),
        };
        tok.parse::<i64>().ok().filter(|v| (lo..=hi).contains(v)).map(|v| v as f64)
    }

    /// A binary value of this type from the first [`PlyScalar::size`] bytes of `b`.
    fn read(self, b: &[u8], big: bool) -> f64 {
        fn arr<const N: usize>(b: &[u8]) -> [u8; N] {
            let mut a = [0u8; N];
            a.copy_from_slice(&b[..N]);
            a
        }
        macro_rules! num {
            ($t:ty) => {{
                let a = arr(b);
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        match self {
            Self::I8 => f64::from(b[0] as i8),
            Self::U8 => f64::from(b[0]),
            Self::I16 => f64::from(num!(i16)),
            Self::U16 => f64::from(num!(u16)),
            Self::I32 => f64::from(num!(i32)),
            Self::U32 => f64::from(num!(u32)),
            Self::F32 => f64::from(num!(f32)),
            Self::F64 => num!(f64),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PlyKind {
    Scalar(PlyScalar),
    /// Length type, item type.
    List(PlyScalar, PlyScalar),
}

#[derive(Debug)]
struct PlyProperty {
    name: String,
    kind: PlyKind,
}

#[derive(Debug)]
struct PlyElement {
    name: String,
    count: u64,
    props: Vec<PlyProperty>,
}

impl PlyElement {
    /// Fewest bytes one item can take: binary, the sum of the scalar sizes (a list at least its
    /// length); ascii, one line with a value per property and separators (2 bytes per property,
    /// 1 for an empty line).
    fn min_bytes(&self, encoding: PlyEncoding) -> u64 {
        if encoding == PlyEncoding::Ascii {
            return (2 * self.props.len()).max(1) as u64;
        }
        self.props
            .iter()
            .map(|p| match p.kind {
                PlyKind::Scalar(t) | PlyKind::List(t, _) => t.size() as u64,
            })
            .sum()
    }

    /// `vertex` counts as "vertices", other elements as "`face` elements".
    fn items(&self, n: u64) -> String {
        match (self.name.as_str(), n) {
            ("vertex", 1) => "vertex".into(),
            ("vertex", _) => "vertices".into(),
            (name, 1) => format!("`{}` element", echo(name)),
            (name, _) => format!("`{}` elements", echo(name)),
        }
    }
}

#[derive(Debug)]
struct PlyHeader {
    encoding: PlyEncoding,
    elements: Vec<PlyElement>,
    /// Offset of the first byte after the `end_header` line.
    body_start: usize,
    /// Number of header lines (the body starts on line `lines + 1`).
    lines: usize,
}

/// Reads and checks the PLY header: magic line, `format`, `comment` / `obj_info`, `element NAME
/// COUNT`, `property TYPE NAME`, `property list LENGTH_TYPE ITEM_TYPE NAME`, `end_header`.
fn ply_header(bytes: &[u8]) -> Result<PlyHeader> {
    if !bytes.starts_with(b"ply") {
        return Err(invalid("ply file does not start with a `ply` line"));
    }
    let region = &bytes[..bytes.len().min(MAX_PLY_HEADER_BYTES)];
    let too_long = || invalid(format!("ply header is longer than {MAX_PLY_HEADER_BYTES} bytes (no `end_header` line)"));
    let mut encoding: Option<PlyEncoding> = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    let (mut pos, mut line_no) = (0usize, 0usize);
    loop {
        if pos >= region.len() {
            return Err(if region.len() < bytes.len() {
                too_long()
            } else {
                invalid("ply file ends before its `end_header` line")
            });
        }
        let (raw, next) = match region[pos..].iter().position(|&b| b == b'\n') {
            Some(i) => (&region[pos..pos + i], pos + i + 1),
            None if region.len() < bytes.len() => return Err(too_long()),
            None => (&region[pos..], region.len()),
        };
        line_no += 1;
        let line =
            std::str::from_utf8(raw).map_err(|_| invalid(format!("ply line {line_no}: the header is not text")))?;
        let line = line.strip_suffix('\r').unwrap_or(line);
        let bad = |what: String| invalid(format!("ply line {line_no}: {what}"));
        let mut toks = line.split_ascii_whitespace();
        let keyword = toks.next();
        if line_no == 1 {
            if keyword != Some("ply") || toks.next().is_some() {
                return Err(invalid("ply file does not start with a `ply` line"));
            }
            pos = next;
            continue;
        }
        match keyword {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                let enc = match toks.next() {
                    Some("ascii") => PlyEncoding::Ascii,
                    Some("binary_little_endian") => PlyEncoding::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyEncoding::BinaryBigEndian,
                    _ => return Err(bad("expected `format ascii|binary_little_endian|binary_big_endian 1.0`".into())),
                };
                let version_ok = toks.next().and_then(|v| v.split_once('.')).is_some_and(|(a, b)| {
                    !a.is_empty() && !b.is_empty() && a.bytes().chain(b.bytes()).all(|c| c.is_ascii_digit())
                });
                if !version_ok || toks.next().is_some() {
                    return Err(bad("expected a version such as `1.0` after the format".into()));
                }
                if encoding.is_some_and(|e| e != enc) {
                    return Err(bad("a second, different `format` line".into()));
                }
                encoding = Some(enc);
            }
            Some("element") => {
                let (Some(name), Some(count), None) = (toks.next(), toks.next(), toks.next()) else {
                    return Err(bad("expected `element NAME COUNT`".into()));
                };
                let count: u64 = count.parse().map_err(|_| {
                    bad(format!("element count `{}` is not an integer in 0..=18446744073709551615", echo(count)))
                })?;
                if elements.len() == MAX_PLY_ELEMENTS {
                    return Err(bad(format!("more than {MAX_PLY_ELEMENTS} elements")));
                }
                if elements.iter().any(|e| e.name == name) {
                    return Err(bad(format!("element `{}` is declared twice", echo(name))));
                }
                elements.push(PlyElement { name: name.to_owned(), count, props: Vec::new() });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return Err(bad("`property` before any `element`".into()));
                };
                let scalar = |t: Option<&str>| -> Result<PlyScalar> {
                    let t = t.unwrap_or("");
                    PlyScalar::from_name(t).ok_or_else(|| bad(format!("unknown property type `{}`", echo(t))))
                };
                let kind = match toks.next() {
                    Some("list") => {
                        let len = scalar(toks.next())?;
                        if !len.is_integer() {
                            return Err(bad(format!("a list length must have an integer type, not `{}`", len.name())));
                        }
                        PlyKind::List(len, scalar(toks.next())?)
                    }
                    t => PlyKind::Scalar(scalar(t)?),
                };
                let (Some(name), None) = (toks.next(), toks.next()) else {
                    return Err(bad("expected `property TYPE NAME` or `property list LENGTH_TYPE TYPE NAME`".into()));
                };
                if element.props.len() == MAX_PLY_PROPERTIES {
                    return Err(bad(format!(
                        "element `{}` has more than {MAX_PLY_PROPERTIES} properties",
                        echo(&element.name)
                    )));
                }
                if element.props.iter().any(|p| p.name == name) {
                    return Err(bad(format!("property `{}` is declared twice", echo(name))));
                }
                element.props.push(PlyProperty { name: name.to_owned(), kind });
            }
            Some("end_header") if toks.next().is_none() => {
                let encoding = encoding.ok_or_else(|| invalid("ply header has no `format` line"))?;
                return Ok(PlyHeader { encoding, elements, body_start: next, lines: line_no });
            }
            Some(other) => return Err(bad(format!("unexpected header line starting with `{}`", echo(other)))),
        }
        pos = next;
    }
}

/// The `vertex` element's x, y, z of a PLY file, after every count was checked (module docs).
pub(super) fn parse_ply(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
    read_ply(bytes, max_points, false).map(|m| m.vertices)
}

/// The vertices and the `face` element's vertex lists (split into triangle fans) of a PLY file;
/// a file without a `face` element (a point cloud) gives no triangles.
pub(super) fn parse_ply_mesh(bytes: &[u8], max_points: usize) -> Result<TriangleMesh> {
    read_ply(bytes, max_points, true)
}

/// The element and property index of the face lists: element `face`, list property
/// `vertex_indices` or `vertex_index` of an integer item type.
fn face_lists(h: &PlyHeader) -> Result<Option<(usize, usize)>> {
    let Some(fi) = h.elements.iter().position(|e| e.name == "face") else {
        return Ok(None);
    };
    let face = &h.elements[fi];
    let Some(pi) = face.props.iter().position(|p| p.name == "vertex_indices" || p.name == "vertex_index") else {
        return Err(invalid("ply `face` element has no list property `vertex_indices` (or `vertex_index`)"));
    };
    match face.props[pi].kind {
        PlyKind::List(_, item) if item.is_integer() => Ok(Some((fi, pi))),
        PlyKind::List(_, item) => Err(invalid(format!(
            "ply face property `{}` must list integers, not `{}`",
            face.props[pi].name,
            item.name()
        ))),
        PlyKind::Scalar(_) => Err(invalid(format!("ply face property `{}` is not a list", face.props[pi].name))),
    }
}

/// Collects the vertex lists of one face into triangles (a fan); indices are checked against the
/// vertex count once every element is read.
struct FaceSink {
    /// (element, property) of the face lists.
    at: (usize, usize),
    /// The current face's vertex indices.
    face: Vec<u32>,
    triangles: Vec<[u32; 3]>,
}

impl FaceSink {
    fn push_index(&mut self, v: f64, item: u64) -> Result<()> {
        if !(0.0..=f64::from(u32::MAX)).contains(&v) {
            return Err(malformed_ply(format!("face {}: vertex index {v} is out of range", item + 1)));
        }
        self.face.push(v as u32);
        Ok(())
    }

    fn end_face(&mut self) {
        for j in 1..self.face.len().saturating_sub(1) {
            self.triangles.push([self.face[0], self.face[j], self.face[j + 1]]);
        }
        self.face.clear();
    }
}

fn read_ply(bytes: &[u8], max_points: usize, with_faces: bool) -> Result<TriangleMesh> {
    let h = ply_header(bytes)?;
    let body = &bytes[h.body_start..];
    let available = body.len() as u128;
    // An ascii body may lack its last newline: one byte of slack.
    let slack = u128::from(h.encoding == PlyEncoding::Ascii);
    let mut total: u128 = 0;
    for e in &h.elements {
        let min = e.min_bytes(h.encoding);
        let need = u128::from(e.count) * u128::from(min);
        if need > available + slack {
            return Err(invalid(format!(
                "ply header declares {} {} but the file has {available} {} after its header (at least {min} {} per {})",
                e.count,
                e.items(e.count),
                plural(available, "byte", "bytes"),
                plural(min, "byte", "bytes"),
                e.items(1),
            )));
        }
        total += need;
    }
    if total > available + slack {
        return Err(invalid(format!(
            "ply header declares elements that need at least {total} bytes but the file has {available} {} after its \
             header",
            plural(available, "byte", "bytes")
        )));
    }
    let vi = h
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| invalid("ply file has no `vertex` element"))?;
    let vertex = &h.elements[vi];
    if vertex.count > max_points as u64 {
        return Err(exhausted(format!(
            "the ply header declares {} vertices, which exceeds the limit of {max_points} points",
            vertex.count
        )));
    }
    let mut xyz = [0usize; 3];
    for (slot, name) in xyz.iter_mut().zip(["x", "y", "z"]) {
        let i = vertex
            .props
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| invalid(format!("ply `vertex` element is missing property `{name}`")))?;
        if matches!(vertex.props[i].kind, PlyKind::List(..)) {
            return Err(invalid(format!("ply vertex property `{name}` is a list, not a number")));
        }
        *slot = i;
    }
    let mut faces = match with_faces {
        true => face_lists(&h)?.map(|at| FaceSink { at, face: Vec::new(), triangles: Vec::new() }),
        false => None,
    };
    let vertices = match h.encoding {
        PlyEncoding::Ascii => ply_ascii_body(&h, body, vi, xyz, faces.as_mut())?,
        PlyEncoding::BinaryLittleEndian => ply_binary_body(&h, body, vi, xyz, false, faces.as_mut())?,
        PlyEncoding::BinaryBigEndian => ply_binary_body(&h, body, vi, xyz, true, faces.as_mut())?,
    };
    let triangles = faces.map(|f| f.triangles).unwrap_or_default();
    if let Some((k, t)) = triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&i| i as usize >= vertices.len())) {
        return Err(malformed_ply(format!(
            "triangle {k} names vertex {} but the file has {} vertices",
            t.iter().max().copied().unwrap_or(0),
            vertices.len()
        )));
    }
    Ok(TriangleMesh { vertices, triangles })
}

/// An error about the PLY body (after the header).
fn malformed_ply(what: String) -> Error {
    invalid(format!("malformed ply file: {what}"))
}

/// One item per line, values separated by whitespace; extra values at the end of a line are
/// ignored (as most readers do).
fn ply_ascii_body(
    h: &PlyHeader,
    body: &[u8],
    vi: usize,
    xyz: [usize; 3],
    mut faces: Option<&mut FaceSink>,
) -> Result<Vec<Point3>> {
    let mut lines = body.split(|&b| b == b'\n');
    let mut line_no = h.lines;
    let mut pts = Vec::new();
    for (ei, e) in h.elements.iter().enumerate() {
        let is_vertex = ei == vi;
        if is_vertex {
            // Checked above: count ≤ max_points and ≤ the body's size.
            pts.reserve_exact(e.count as usize);
        }
        for i in 0..e.count {
            let Some(raw) = lines.next() else {
                return Err(malformed_ply(format!("the file ends after {i} of {} {}", e.count, e.items(e.count))));
            };
            line_no += 1;
            let line =
                std::str::from_utf8(raw).map_err(|_| malformed_ply(format!("line {line_no}: the line is not text")))?;
            let mut toks = line.split_ascii_whitespace();
            let mut value = |t: PlyScalar, p: &PlyProperty| -> Result<f64> {
                let tok = toks.next().ok_or_else(|| {
                    malformed_ply(format!(
                        "line {line_no}: too few values for {} (nothing for property `{}`)",
                        e.items(1),
                        echo(&p.name)
                    ))
                })?;
                t.parse_text(tok).ok_or_else(|| {
                    malformed_ply(format!(
                        "line {line_no}: `{}` is not a valid {} (property `{}` of {})",
                        echo(tok),
                        t.name(),
                        echo(&p.name),
                        e.items(1)
                    ))
                })
            };
            let mut v = [0.0; 3];
            for (pi, p) in e.props.iter().enumerate() {
                match p.kind {
                    PlyKind::Scalar(t) => {
                        let x = value(t, p)?;
                        if is_vertex {
                            if let Some(k) = xyz.iter().position(|&j| j == pi) {
                                v[k] = x;
                            }
                        }
                    }
                    PlyKind::List(len_type, item) => {
                        // Integer-typed, so exact; each item needs its own value on this line.
                        let n = value(len_type, p)?;
                        if n < 0.0 {
                            return Err(malformed_ply(format!(
                                "line {line_no}: list `{}` has negative length {n}",
                                echo(&p.name)
                            )));
                        }
                        let sink = faces.as_deref_mut().filter(|f| f.at == (ei, pi));
                        match sink {
                            Some(sink) => {
                                for _ in 0..n as u64 {
                                    sink.push_index(value(item, p)?, i)?;
                                }
                                sink.end_face();
                            }
                            None => {
                                for _ in 0..n as u64 {
                                    value(item, p)?;
                                }
                            }
                        }
                    }
                }
            }
            if is_vertex {
                pts.push(Point3::new(v[0], v[1], v[2]));
            }
        }
    }
    Ok(pts)
}

/// Items packed back to back; list items are skipped unread.
fn ply_binary_body(
    h: &PlyHeader,
    body: &[u8],
    vi: usize,
    xyz: [usize; 3],
    big: bool,
    mut faces: Option<&mut FaceSink>,
) -> Result<Vec<Point3>> {
    /// The next value of type `t` at `*pos`, or `None` past the end.
    fn take(body: &[u8], pos: &mut usize, t: PlyScalar, big: bool) -> Option<f64> {
        let b = body.get(*pos..*pos + t.size())?;
        *pos += t.size();
        Some(t.read(b, big))
    }
    let mut pos = 0usize;
    let mut pts = Vec::new();
    for (ei, e) in h.elements.iter().enumerate() {
        if e.props.is_empty() {
            continue; // items of no bytes
        }
        let is_vertex = ei == vi;
        if is_vertex {
            // Checked above: count ≤ max_points and ≤ the body's size.
            pts.reserve_exact(e.count as usize);
        }
        for i in 0..e.count {
            let truncated = || malformed_ply(format!("the data ends inside {} {} of {}", e.items(1), i + 1, e.count));
            let mut v = [0.0; 3];
            for (pi, p) in e.props.iter().enumerate() {
                match p.kind {
                    PlyKind::Scalar(t) => {
                        let x = take(body, &mut pos, t, big).ok_or_else(truncated)?;
                        if is_vertex {
                            if let Some(k) = xyz.iter().position(|&j| j == pi) {
                                v[k] = x;
                            }
                        }
                    }
                    PlyKind::List(len_type, item) => {
                        let n = take(body, &mut pos, len_type, big).ok_or_else(truncated)?;
                        if n < 0.0 {
                            return Err(malformed_ply(format!(
                                "{} {}: list `{}` has negative length {n}",
                                e.items(1),
                                i + 1,
                                echo(&p.name)
                            )));
                        }
                        // Integer-typed, so exact; the items are skipped unless they are the
                        // face lists.
                        let skip = (n as u64).checked_mul(item.size() as u64).ok_or_else(truncated)?;
                        if skip > (body.len() - pos) as u64 {
                            return Err(truncated());
                        }
                        match faces.as_deref_mut().filter(|f| f.at == (ei, pi)) {
                            Some(sink) => {
                                for _ in 0..n as u64 {
                                    let v = take(body, &mut pos, item, big).ok_or_else(truncated)?;
                                    sink.push_index(v, i)?;
                                }
                                sink.end_face();
                            }
                            None => pos += skip as usize,
                        }
                    }
                }
            }
            if is_vertex {
                pts.push(Point3::new(v[0], v[1], v[2]));
            }
        }
    }
    Ok(pts)
}
