//! Mesh and point-cloud loading: OFF, OBJ, STL (ASCII and binary), PLY (ASCII and binary), XYZ.
//!
//! Only vertices are returned (faces are irrelevant to a fit: the convex hull is recomputed).
//!
//! ```text
//! off   "OFF" header line (also "OFF nV nF nE" on one line), then "nV nF nE", nV lines "x y z",
//!       faces ignored; '#' comments and blank lines skipped             (parsed here)
//! obj   `v x y z [w]` lines of every object; faces and the rest skipped (parsed here)
//! stl   ASCII or binary; shared vertices merged by stl_io               (stl_io)
//! ply   the `vertex` element's x, y, z properties (any numeric type),   (parsed here)
//!       ascii, binary_little_endian or binary_big_endian; other elements are checked and skipped
//! xyz   one "x y z" per line (commas allowed, extra columns ignored)     (parsed here)
//! ```
//!
//! # Untrusted input
//!
//! The bytes come from clients, so no count a file declares is trusted. Before anything is
//! reserved or handed to a third-party parser, every format checks its counts
//! ([`parse_points_limited`]):
//!
//! - against the input's size: a header promising more items than the bytes after it can hold
//!   is [`Error::InvalidArgument`] naming `mesh` (PLY, every element: the sum of its property sizes
//!   per binary item, 2 bytes per property per ascii line; binary STL: 50 bytes per triangle;
//!   OFF: 6 bytes per vertex line, where nothing is reserved and the error names the first bad
//!   line or where the file ends);
//! - against `max_points`: more declared vertices (OFF, PLY), more `v` lines (OBJ), more point
//!   lines (XYZ) or more than 3 × `max_points` triangles (STL) is [`Error::ResourceExhausted`]
//!   naming `mesh`; the parsed vertex count is checked again afterwards (STL merges vertices).
//!
//! The PLY header is bounded ([`MAX_PLY_HEADER_BYTES`], at most 64 elements of at most 256
//! properties each); list properties are skipped, never stored.
//!
//! PLY and OBJ are read here, not by ply-rs and tobj: ply-rs trusts the header (it stores every
//! declared item as a map with cloned property names, and panics on a count beyond `u64`) and
//! reports `Debug` text; tobj stores every face before returning positions, returns none for a
//! point cloud without faces, and panics (overflow) on some relative normal indices (found by
//! fuzzing, `fuzz/regressions/mesh_obj`). stl_io, given only counts checked above, runs under
//! `catch_unwind`, so malformed bytes never panic the server.
//!
//! Error messages are plain sentences with the line number where there is one, and repeat at
//! most a few dozen bytes of the client's text.

use crate::math::{Point3, Real};
use crate::{Error, Result};

/// The `max_points` of [`parse_points`] and [`load_points`].
pub const DEFAULT_MAX_MESH_POINTS: usize = 10_000_000;

/// Longest accepted PLY header (from `ply` to `end_header`), in bytes.
pub const MAX_PLY_HEADER_BYTES: usize = 64 * 1024;

/// Most elements a PLY header may declare.
const MAX_PLY_ELEMENTS: usize = 64;

/// Most properties one PLY element may declare.
const MAX_PLY_PROPERTIES: usize = 256;

/// Shortest OFF vertex line, `0 0 0\n`.
const OFF_MIN_VERTEX_BYTES: usize = 6;

/// Bytes of client text an error message repeats.
const ECHO_BYTES: usize = 48;

/// Longest message taken from a third-party parser.
const FOREIGN_MESSAGE_BYTES: usize = 160;

/// Reads the vertices of a mesh file; the format follows the extension (case-insensitive).
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; otherwise as [`parse_points`].
pub fn load_points(path: &std::path::Path) -> Result<Vec<Point3>> {
    let bytes = std::fs::read(path)?;
    parse_points(&bytes, path.extension().and_then(|e| e.to_str()).unwrap_or(""))
}

/// [`parse_points_limited`] with [`DEFAULT_MAX_MESH_POINTS`].
///
/// # Errors
/// As [`parse_points_limited`].
pub fn parse_points(bytes: &[u8], format: &str) -> Result<Vec<Point3>> {
    parse_points_limited(bytes, format, DEFAULT_MAX_MESH_POINTS)
}

/// Parses mesh bytes in the given format (`off`, `obj`, `stl`, `ply`, or `xyz` / `txt` / `pts` for
/// "x y z" lines; case-insensitive, a leading dot is ignored), returning at most `max_points`
/// vertices. Declared counts are checked against `max_points` and against the size of `bytes`
/// before anything is allocated (see the module documentation).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `mesh` for an unknown format, unparsable bytes, a header
/// that declares more than the bytes can hold, a non-finite coordinate, or a file without
/// vertices; [`Error::ResourceExhausted`] naming `mesh` when the file declares or holds more than
/// `max_points` vertices.
pub fn parse_points_limited(bytes: &[u8], format: &str, max_points: usize) -> Result<Vec<Point3>> {
    let fmt = format.trim_start_matches('.').to_ascii_lowercase();
    let points = match fmt.as_str() {
        "off" => parse_off(bytes, max_points)?,
        "xyz" | "txt" | "pts" => parse_xyz(bytes, max_points)?,
        "obj" => parse_obj(bytes, max_points)?,
        "stl" => {
            check_stl_counts(bytes, max_points)?;
            guarded("stl", || parse_stl(bytes))?
        }
        "ply" => parse_ply(bytes, max_points)?,
        other => {
            return Err(invalid(format!("unknown format `{}`; expected one of off, obj, stl, ply, xyz", echo(other))))
        }
    };
    if points.is_empty() {
        return Err(invalid(format!("the {fmt} file has no vertices")));
    }
    if points.len() > max_points {
        return Err(exhausted(format!(
            "the {fmt} file has {} vertices, which exceeds the limit of {max_points} points",
            points.len()
        )));
    }
    if let Some(i) = points.iter().position(|p| !p.coords.iter().all(|c| c.is_finite())) {
        return Err(invalid(format!("vertex {i} has a non-finite coordinate")));
    }
    Ok(points)
}

fn invalid(reason: impl Into<String>) -> Error {
    Error::invalid("mesh", reason)
}

fn exhausted(reason: String) -> Error {
    Error::ResourceExhausted(format!("`mesh`: {reason}"))
}

/// `s` cut to at most `max` bytes (at a character boundary), `…` appended when cut.
fn clip_to(s: &str, max: usize) -> String {
    if s.len() <= max {
        return s.to_owned();
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &s[..end])
}

/// Client text as an error message repeats it: at most [`ECHO_BYTES`].
fn echo(s: &str) -> String {
    clip_to(s, ECHO_BYTES)
}

fn plural(n: impl Into<u128>, one: &'static str, many: &'static str) -> &'static str {
    if n.into() == 1 {
        one
    } else {
        many
    }
}

/// Runs a third-party parser, turning a panic into an error naming `mesh`.
fn guarded(fmt: &str, f: impl FnOnce() -> Result<Vec<Point3>>) -> Result<Vec<Point3>> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| Err(invalid(format!("malformed {fmt} file (the parser gave up)"))))
}

fn text<'a>(bytes: &'a [u8], fmt: &str) -> Result<&'a str> {
    std::str::from_utf8(bytes).map_err(|e| invalid(format!("{fmt} file is not UTF-8 text: {e}")))
}

fn parse_coord(tok: Option<&str>, line: usize, fmt: &str) -> Result<Real> {
    let tok = tok.ok_or_else(|| invalid(format!("{fmt} line {line}: expected 3 coordinates")))?;
    let v: Real = tok.parse().map_err(|_| invalid(format!("{fmt} line {line}: `{}` is not a number", echo(tok))))?;
    if !v.is_finite() {
        return Err(invalid(format!("{fmt} line {line}: coordinate `{}` is not finite", echo(tok))));
    }
    Ok(v)
}

// ---------------------------------------------------------------------------------------------
// OFF
// ---------------------------------------------------------------------------------------------

/// ASCII OFF (the PSB files): header, counts, vertices; faces are skipped unread.
fn parse_off(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
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
    if counts_toks.len() < 2 || counts_toks[1].parse::<usize>().is_err() {
        return Err(invalid(format!("off line {counts_line}: expected counts `nV nF nE`")));
    }
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
    for k in 0..nv {
        let Some((l, _, c)) = lines.next() else {
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
    }
    if !fits {
        // Unreachable (nv valid lines take the bytes counted above), kept as a guard.
        return Err(invalid(format!("off header declares more vertices than the file holds ({})", lie())));
    }
    Ok(pts)
}

// ---------------------------------------------------------------------------------------------
// XYZ
// ---------------------------------------------------------------------------------------------

/// One "x y z" per line; commas or whitespace separate; extra columns (normals, colors) ignored.
fn parse_xyz(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
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

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

/// `v x y z [w]` lines (a 4th value divides, more values, e.g. colors, are ignored); every other
/// statement (faces, normals, texture coordinates, groups, materials) is skipped unread, so a
/// point-cloud OBJ without faces gives its points and no face is stored.
fn parse_obj(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
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

// ---------------------------------------------------------------------------------------------
// STL
// ---------------------------------------------------------------------------------------------

/// Binary STL: 80-byte header, u32 little-endian triangle count, 50 bytes per triangle.
const STL_HEADER_BYTES: usize = 84;
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
fn check_stl_counts(bytes: &[u8], max_points: usize) -> Result<()> {
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

fn parse_stl(bytes: &[u8]) -> Result<Vec<Point3>> {
    let mut cur = std::io::Cursor::new(bytes);
    let mesh = stl_io::read_stl(&mut cur)
        .map_err(|e| invalid(format!("malformed stl file: {}", foreign_message(&e.to_string()))))?;
    Ok(mesh.vertices.iter().map(|v| Point3::new(v[0] as Real, v[1] as Real, v[2] as Real)).collect())
}

/// A third-party parser's message as a plain sentence: Rust `Debug` lists of strings (stl_io
/// prints tokens as `["outer", "loop"]`) become `` `outer loop` ``, and the whole is cut to
/// [`FOREIGN_MESSAGE_BYTES`] (the tokens are the client's text).
fn foreign_message(msg: &str) -> String {
    let mut out = String::with_capacity(msg.len().min(2 * FOREIGN_MESSAGE_BYTES));
    let mut rest = msg;
    while let Some(start) = rest.find('[') {
        out.push_str(&rest[..start]);
        match debug_string_list(&rest[start..]) {
            Some((words, used)) => {
                out.push('`');
                out.push_str(&words.join(" "));
                out.push('`');
                rest = &rest[start + used..];
            }
            None => {
                out.push('[');
                rest = &rest[start + 1..];
            }
        }
        if out.len() > FOREIGN_MESSAGE_BYTES {
            break;
        }
    }
    out.push_str(rest);
    clip_to(out.trim(), FOREIGN_MESSAGE_BYTES)
}

/// Parses a `Debug`-printed `[&str]` at the start of `s` (`["a", "b\"c"]`, `[]`): the strings
/// and the number of bytes used; `None` if `s` does not start with one.
fn debug_string_list(s: &str) -> Option<(Vec<String>, usize)> {
    let mut chars = s.char_indices().peekable();
    if chars.next()?.1 != '[' {
        return None;
    }
    let mut words = Vec::new();
    if let Some(&(i, ']')) = chars.peek() {
        return Some((words, i + 1));
    }
    loop {
        if chars.next()?.1 != '"' {
            return None;
        }
        let mut w = String::new();
        loop {
            match chars.next()?.1 {
                '"' => break,
                '\\' => w.push(chars.next()?.1),
                c => w.push(c),
            }
        }
        words.push(w);
        match chars.next()? {
            (i, ']') => return Some((words, i + 1)),
            (_, ',') if chars.next()?.1 == ' ' => {}
            _ => return None,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// PLY
// ---------------------------------------------------------------------------------------------

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

fn parse_ply(bytes: &[u8], max_points: usize) -> Result<Vec<Point3>> {
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
    match h.encoding {
        PlyEncoding::Ascii => ply_ascii_body(&h, body, vi, xyz),
        PlyEncoding::BinaryLittleEndian => ply_binary_body(&h, body, vi, xyz, false),
        PlyEncoding::BinaryBigEndian => ply_binary_body(&h, body, vi, xyz, true),
    }
}

fn malformed_ply(what: String) -> Error {
    invalid(format!("malformed ply file: {what}"))
}

/// One item per line, values separated by whitespace; extra values at the end of a line are
/// ignored (as most readers do).
fn ply_ascii_body(h: &PlyHeader, body: &[u8], vi: usize, xyz: [usize; 3]) -> Result<Vec<Point3>> {
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
                        for _ in 0..n as u64 {
                            value(item, p)?;
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
fn ply_binary_body(h: &PlyHeader, body: &[u8], vi: usize, xyz: [usize; 3], big: bool) -> Result<Vec<Point3>> {
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
                        // Integer-typed, so exact; the items are skipped.
                        let skip = (n as u64).checked_mul(item.size() as u64).ok_or_else(truncated)?;
                        if skip > (body.len() - pos) as u64 {
                            return Err(truncated());
                        }
                        pos += skip as usize;
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

    /// `ResourceExhausted` naming `mesh` and containing `needle`.
    fn expect_exhausted(r: Result<Vec<Point3>>, needle: &str) {
        match r {
            Err(Error::ResourceExhausted(msg)) => {
                assert!(msg.starts_with("`mesh`: "), "`{msg}` does not name `mesh`");
                assert!(msg.contains(needle), "`{msg}` lacks `{needle}`");
            }
            other => panic!("expected ResourceExhausted(mesh), got {other:?}"),
        }
    }

    /// A plain sentence: no Rust `Debug` wrappers, no escaped quotes, no multi-line dumps.
    fn assert_plain(e: &Error) {
        let msg = e.to_string();
        for bad in ["Custom {", "kind:", "Error {", "[\"", "\\\"", "\n", "\t", "Some(", "ParseFloatError"] {
            assert!(!msg.contains(bad), "`{msg}` contains `{bad}`");
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

    fn ply_binary(format: &str, header_body: &str, payload: &[u8]) -> Vec<u8> {
        let mut out = format!("ply\nformat {format} 1.0\n{header_body}end_header\n").into_bytes();
        out.extend_from_slice(payload);
        out
    }

    #[test]
    fn ply_lying_headers_fail_before_allocating() {
        // The 64-byte probe: 10^15 vertices promised, none present (ply-rs used to allocate forever).
        let probe = b"ply\nformat ascii 1.0\nelement vertex 1000000000000000\nend_header\n";
        assert_eq!(probe.len(), 64);
        expect_mesh_error(
            parse_points(probe, "ply"),
            "ply header declares 1000000000000000 vertices but the file has 0 bytes after its header \
             (at least 1 byte per vertex)",
        );
        let xyz = "element vertex 1000000000000000\nproperty float x\nproperty float y\nproperty float z\n";
        for format in ["binary_little_endian", "binary_big_endian"] {
            let bin = ply_binary(format, xyz, &[0u8; 12]);
            expect_mesh_error(
                parse_points(&bin, "ply"),
                "ply header declares 1000000000000000 vertices but the file has 12 bytes after its header \
                 (at least 12 bytes per vertex)",
            );
            // A property-less element of huge count costs nothing in binary, but any other lying
            // element is caught too, not only `vertex`.
            let faces = format!("{xyz}element face 4000000000\nproperty list uchar int vertex_indices\n")
                .replace("1000000000000000", "1");
            expect_mesh_error(
                parse_points(&ply_binary(format, &faces, &[0u8; 12]), "ply"),
                "ply header declares 4000000000 `face` elements but the file has 12 bytes after its header \
                 (at least 1 byte per `face` element)",
            );
        }
        let ascii = "ply\nformat ascii 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty \
                     float z\nend_header\n0 0 0\n";
        expect_mesh_error(
            parse_points(ascii.as_bytes(), "ply"),
            "ply header declares 1000 vertices but the file has 6 bytes after its header (at least 6 bytes per vertex)",
        );
        // u64 overflow in a count is a plain error, not a panic.
        expect_mesh_error(
            parse_points(b"ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\nend_header\n", "ply"),
            "ply line 3: element count `99999999999999999999999` is not an integer",
        );
        // Elements that fit one by one but not together.
        let two = ply_binary(
            "binary_little_endian",
            "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement extra 10\n\
             property double w\n",
            &[0u8; 80],
        );
        expect_mesh_error(parse_points(&two, "ply"), "need at least 92 bytes but the file has 80 bytes");
    }

    #[test]
    fn ply_header_is_bounded_and_checked() {
        let mut long = b"ply\nformat ascii 1.0\n".to_vec();
        while long.len() <= MAX_PLY_HEADER_BYTES {
            long.extend_from_slice(b"comment padding padding padding padding padding padding\n");
        }
        long.extend_from_slice(b"end_header\n");
        expect_mesh_error(parse_points(&long, "ply"), "ply header is longer than 65536 bytes");
        let mut many = String::from("ply\nformat ascii 1.0\n");
        for k in 0..=MAX_PLY_ELEMENTS {
            many.push_str(&format!("element e{k} 0\n"));
        }
        many.push_str("end_header\n");
        expect_mesh_error(parse_points(many.as_bytes(), "ply"), "more than 64 elements");
        let mut props = String::from("ply\nformat ascii 1.0\nelement vertex 0\n");
        for k in 0..=MAX_PLY_PROPERTIES {
            props.push_str(&format!("property float p{k}\n"));
        }
        props.push_str("end_header\n");
        expect_mesh_error(parse_points(props.as_bytes(), "ply"), "more than 256 properties");
        for (header, needle) in [
            ("element vertex 1\nelement vertex 2\n", "ply line 4: element `vertex` is declared twice"),
            ("property float x\n", "ply line 3: `property` before any `element`"),
            ("element face 1\nproperty list float int idx\n", "list length must have an integer type, not `float`"),
            ("element vertex 1\nproperty float128 x\n", "unknown property type `float128`"),
            ("element vertex 1\nproperty float x\nproperty float x\n", "property `x` is declared twice"),
            ("elephant 3\n", "ply line 3: unexpected header line starting with `elephant`"),
            ("format binary_big_endian 1.0\n", "a second, different `format` line"),
        ] {
            let ply = format!("ply\nformat ascii 1.0\n{header}end_header\n");
            expect_mesh_error(parse_points(ply.as_bytes(), "ply"), needle);
        }
        expect_mesh_error(
            parse_points(b"ply\nformat ascii 1.0\nelement vertex 1\n", "ply"),
            "ends before its `end_header`",
        );
        expect_mesh_error(parse_points(b"ply\nelement vertex 0\nend_header\n", "ply"), "no `format` line");
        expect_mesh_error(parse_points(b"ply\nformat ascii\nend_header\n", "ply"), "ply line 2: expected a version");
        expect_mesh_error(parse_points(b"ply\nformat ascii 1.0\nend_header\n", "ply"), "no `vertex` element");
    }

    #[test]
    fn ply_binary_elements_lists_and_types_parse() {
        // Big endian, mixed scalar types, a face list before the vertices, an extra vertex column.
        let header = "element face 2\nproperty list uchar int vertex_indices\nelement vertex 2\nproperty short x\n\
                      property double y\nproperty uchar red\nproperty float z\n";
        let mut payload = vec![3u8];
        payload.extend([0i32, 1, 1].iter().flat_map(|v| v.to_be_bytes()));
        payload.push(0u8); // an empty list
        for (x, y, r, z) in [(-3i16, 0.25f64, 7u8, 1.5f32), (4, -2.0, 255, 0.0)] {
            payload.extend(x.to_be_bytes());
            payload.extend(y.to_be_bytes());
            payload.push(r);
            payload.extend(z.to_be_bytes());
        }
        let p = parse_points(&ply_binary("binary_big_endian", header, &payload), "ply").unwrap();
        assert_eq!(p, vec![Point3::new(-3.0, 0.25, 1.5), Point3::new(4.0, -2.0, 0.0)]);
        // Truncated inside the vertices; a list running past the end; a negative list length.
        let cut = &payload[..payload.len() - 2];
        expect_mesh_error(
            parse_points(&ply_binary("binary_big_endian", header, cut), "ply"),
            "malformed ply file: the data ends inside vertex 2 of 2",
        );
        let mut long_list = payload.clone();
        long_list[0] = 200;
        expect_mesh_error(
            parse_points(&ply_binary("binary_big_endian", header, &long_list), "ply"),
            "the data ends inside `face` element 1 of 2",
        );
        let signed = header.replace("list uchar", "list char");
        let mut negative = payload.clone();
        negative[0] = 0xff;
        expect_mesh_error(
            parse_points(&ply_binary("binary_big_endian", &signed, &negative), "ply"),
            "`face` element 1: list `vertex_indices` has negative length -1",
        );
        // CRLF header, property-less element, comments.
        let crlf = "ply\r\nformat ascii 1.0\r\ncomment hi\r\nelement empty 2\r\nelement vertex 1\r\nproperty int x\r\n\
                    property int y\r\nproperty list uchar float z\r\nend_header\r\n\r\n\r\n1 2 1 3.5\r\n";
        expect_mesh_error(parse_points(crlf.as_bytes(), "ply"), "ply vertex property `z` is a list");
        let crlf = crlf.replace("list uchar float z", "float z").replace("1 2 1 3.5", "1 2 3.5");
        assert_eq!(parse_points(crlf.as_bytes(), "ply").unwrap(), vec![Point3::new(1.0, 2.0, 3.5)]);
    }

    #[test]
    fn ply_ascii_errors_name_the_line() {
        let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let ok = format!("{head}0 0 0\n1 1 1\n2 0 1\n");
        assert_eq!(parse_points(ok.as_bytes(), "ply").unwrap().len(), 2);
        for (body, needle) in [
            ("0 0 0\n1 x 1\n2 0 1\n", "malformed ply file: line 11: `x` is not a valid float (property `y` of vertex)"),
            (
                "0 0 0\n1 1\n2 0 1\n",
                "malformed ply file: line 11: too few values for vertex (nothing for property `z`)",
            ),
            (
                "0 0 0\n1 1 1\n3 0 1\n",
                "line 12: too few values for `face` element (nothing for property `vertex_indices`)",
            ),
            ("0 0 0\n1 1 1\n300 0 1\n", "line 12: `300` is not a valid uchar"),
            ("0 0 0      \n1 1 1", "malformed ply file: the file ends after 0 of 1 `face` element"),
        ] {
            let ply = format!("{head}{body}");
            let r = parse_points(ply.as_bytes(), "ply");
            if let Err(e) = &r {
                assert_plain(e);
            }
            expect_mesh_error(r, needle);
        }
    }

    #[test]
    fn off_and_stl_lying_headers_fail_before_allocating() {
        expect_mesh_error(
            parse_points(b"OFF\n1000000000000 0 0\n0 0 0\n", "off"),
            "off file ends after 1 of 1000000000000 vertices (1000000000000 vertices need at least 6000000000000 \
             bytes after the counts line, the file has 6)",
        );
        expect_mesh_error(
            parse_points(b"OFF 3 0 0\n0 0 0\n", "off"),
            "off file ends after 1 of 3 vertices (3 vertices need at least 18 bytes after the counts line, the file has 6)",
        );
        // A lie beyond usize and beyond max_points is still InvalidArgument (the file is malformed).
        expect_mesh_error(
            parse_points_limited(b"OFF 18446744073709551615 0 0\n", "off", 3),
            "off file ends after 0 of 18446744073709551615 vertices",
        );
        // The last line may lack its newline.
        assert_eq!(parse_points(b"OFF 2 0 0\n0 0 0\n1 1 1", "off").unwrap().len(), 2);
        let mut bin = stl_binary(&[[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]]);
        bin[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
        expect_mesh_error(
            parse_points(&bin, "stl"),
            "stl header declares 4294967295 triangles but the file has 50 bytes after its 84-byte header \
             (50 bytes per triangle)",
        );
        expect_mesh_error(parse_points(&[0u8; 83], "stl"), "stl file has 83 bytes: too short for a binary stl");
    }

    #[test]
    fn counts_above_max_points_are_resource_exhausted() {
        let max = 3;
        expect_exhausted(
            parse_points_limited(b"OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n", "off", max),
            "the off header declares 4 vertices, which exceeds the limit of 3 points",
        );
        expect_exhausted(
            parse_points_limited(b"0 0 0\n1 0 0\n# x\n0 1 0\n0 0 1\n", "xyz", max),
            "the xyz file has 4 point lines, which exceeds the limit of 3 points",
        );
        expect_exhausted(
            parse_points_limited(b"v 0 0 0\nv 1 0 0\n  v\t0 1 0\nv 0 0 1\nvn 0 0 1\nf 1 2 3\n", "obj", max),
            "the obj file has 4 `v` lines, which exceeds the limit of 3 points",
        );
        let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                   end_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
        expect_exhausted(
            parse_points_limited(ply.as_bytes(), "ply", max),
            "the ply header declares 4 vertices, which exceeds the limit of 3 points",
        );
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        // 10 triangles > 3 × 3: rejected from the header; 2 triangles with 4 distinct vertices:
        // rejected after merging.
        expect_exhausted(
            parse_points_limited(&stl_binary(&[tri; 10]), "stl", max),
            "the stl header declares 10 triangles, more than 3 × the limit of 3 points",
        );
        let two = stl_binary(&[tri, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]);
        expect_exhausted(
            parse_points_limited(&two, "stl", max),
            "the stl file has 4 vertices, which exceeds the limit of 3 points",
        );
        let facet = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n";
        let ascii = format!("solid t\n{}endsolid t\n", facet.repeat(10));
        expect_exhausted(parse_points_limited(ascii.as_bytes(), "stl", max), "the stl file has 10 triangles");
        // Within the limit everything still parses.
        assert_eq!(parse_points_limited(&stl_binary(&[tri; 9]), "stl", max).unwrap().len(), 3);
        assert_eq!(parse_points_limited(b"OFF 3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "off", max).unwrap().len(), 3);
    }

    #[test]
    fn third_party_errors_are_plain_sentences() {
        let cases: [(&[u8], &str, &str); 5] = [
            (b"solid x\nfacet normal 0 0\n", "stl", "malformed stl file: invalid facet header: `facet normal 0 0`"),
            (
                b"solid x\nfacet normal 0 0 1\nouter lop\n",
                "stl",
                "malformed stl file: expected `outer loop`, got `outer lop`",
            ),
            (b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 1 2 q\n", "stl", "malformed stl file: invalid float"),
            (b"v 1 2 3\nv 1 2 zz\n", "obj", "obj line 2: `zz` is not a number"),
            (b"v 1 2 3\nv 1 2 3 0\n", "obj", "obj line 2: the weight w is 0"),
        ];
        for (bytes, fmt, needle) in cases {
            let r = parse_points(bytes, fmt);
            if let Err(e) = &r {
                assert_plain(e);
            }
            expect_mesh_error(r, needle);
        }
        assert_eq!(foreign_message(r#"got ["a\"b", "c"] and []"#), "got `a\"b c` and ``");
        assert_eq!(foreign_message("[not a list"), "[not a list");
        let long = format!("expected [\"{}\"]", "x".repeat(1000));
        assert!(foreign_message(&long).len() <= FOREIGN_MESSAGE_BYTES + '…'.len_utf8());
        expect_mesh_error(parse_points(b"1 2 3", &"v".repeat(1000)), "unknown format `vvvvv");
        assert!(parse_points(b"1 2 3", &"v".repeat(1000)).unwrap_err().to_string().len() < 200);
    }

    #[test]
    fn psb_chair_parses_with_its_header_count() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/psb/chair_101.off");
        let p = load_points(&path).unwrap();
        assert_eq!(p.len(), 8499);
        assert_eq!(p[0], Point3::new(0.25249, 0.800481, 0.386195));
        // The same bytes under a limit just below and at the count.
        let bytes = std::fs::read(&path).unwrap();
        expect_exhausted(parse_points_limited(&bytes, "off", 8498), "declares 8499 vertices");
        assert_eq!(parse_points_limited(&bytes, "off", 8499).unwrap().len(), 8499);
    }

    #[test]
    fn fuzz_seeds_parse() {
        // The committed seed corpora of the mesh fuzz targets (fuzz/seeds/mesh_*) are valid files.
        let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds");
        let mut n = 0;
        for fmt in ["off", "obj", "stl", "ply", "xyz"] {
            for entry in std::fs::read_dir(seeds.join(format!("mesh_{fmt}"))).unwrap() {
                let path = entry.unwrap().path();
                let bytes = std::fs::read(&path).unwrap();
                let p = parse_points_limited(&bytes, fmt, 100_000).unwrap_or_else(|e| panic!("{path:?}: {e}"));
                assert!(!p.is_empty());
                n += 1;
            }
        }
        assert!(n >= 10, "{n} seeds");
    }

    #[test]
    fn obj_reads_every_v_line_and_skips_the_rest() {
        // A point cloud without faces (tobj returned no positions for it).
        let cloud = b"v 0 0 0\nv 1 0 0\r\nv 0 1 0 # comment\n\tv 0 0 2 2\nv 1 1 1 0.5 0.5 0.5\n";
        assert_eq!(
            parse_points(cloud, "obj").unwrap(),
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(1.0, 0.0, 0.0),
                Point3::new(0.0, 1.0, 0.0),
                Point3::new(0.0, 0.0, 1.0),
                Point3::new(1.0, 1.0, 1.0)
            ]
        );
        // Faces, normals and texture coordinates are not read: out-of-range or overflowing
        // relative indices (a tobj panic found by fuzzing, fuzz/regressions/mesh_obj) do no harm.
        let faces = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/-9223372036854775807 2/-6/1 3//-4\nf 1 7 -9\n";
        assert_eq!(parse_points(faces, "obj").unwrap().len(), 3);
        let crash = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fuzz/regressions/mesh_obj/tobj-normal-index-overflow.obj");
        let _ = parse_points_limited(&std::fs::read(crash).unwrap(), "obj", 100_000);
        expect_mesh_error(parse_points(b"vt 0 0\nf 1 2 3\n", "obj"), "the obj file has no vertices");
    }
}
