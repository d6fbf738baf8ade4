//! The sensor files `sublevel cloud load` reads into one `UpdatePointCloud` frame.
//!
//! ```text
//! .pcd   PCL's point-cloud format, DATA ascii, binary or binary_compressed (LZF, fields stored one
//!        after another): the x, y, z fields (TYPE F, SIZE 4 or 8, COUNT 1), every other field
//!        skipped; NaN coordinates kept (the server counts them as holes); VIEWPOINT ignored
//! .ply   the vertex element's x, y, z (ASCII or binary, the fit crate's bounded PLY reader)
//! .xyz   one `x y z` line per point (also .txt, .pts)
//! .png   a depth image: 16-bit grayscale, one depth per pixel in units of --depth-scale meters
//! ```
//!
//! Every count a header declares is checked against the bytes that follow it before anything is
//! reserved, and a file holds at most [`MAX_FILE_POINTS`] points (a depth image as many pixels),
//! so that a malformed or hostile file fails with an error naming it instead of exhausting memory.

use std::path::Path;
use sublevel::fit::mesh::{parse_points_limited, MeshFormat};
use sublevel::{Error, Result};

/// Most points (or depth pixels) one file may hold: 2²⁴, the server's largest depth image.
pub const MAX_FILE_POINTS: usize = 1 << 24;

/// Longest accepted PCD header, in bytes.
const MAX_PCD_HEADER_BYTES: usize = 64 * 1024;

/// What a sensor file holds.
#[derive(Clone, Debug, PartialEq)]
pub enum FileFrame {
    /// Points in the sensor frame (meters); NaN coordinates are holes.
    Points(Vec<[f32; 3]>),
    /// A 16-bit depth image, row-major.
    Depth {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// The depths, in units of the depth scale; 0 is a hole.
        pixels: Vec<u16>,
    },
}

/// Reads `path` by its extension (case-insensitive): `pcd`, `ply`, `xyz` / `txt` / `pts`, `png`.
///
/// # Errors
/// [`Error::Io`] naming the file when it cannot be read; [`Error::InvalidArgument`] naming the file
/// for an unknown extension or contents that do not parse (with the line, field or byte at fault).
pub fn read_frame(path: &Path) -> Result<FileFrame> {
    let name = path.display().to_string();
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !matches!(ext.as_str(), "pcd" | "ply" | "xyz" | "txt" | "pts" | "png") {
        return Err(Error::invalid(name, "unknown extension: expected .pcd, .ply, .xyz (.txt, .pts) or .png"));
    }
    let bytes = std::fs::read(path).map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {name}: {e}")))?;
    let in_file = |e: Error| match e {
        Error::InvalidArgument { reason, .. } => Error::invalid(name.clone(), reason),
        Error::ResourceExhausted(m) => Error::invalid(name.clone(), m),
        other => other,
    };
    match ext.as_str() {
        "pcd" => parse_pcd(&bytes).map(FileFrame::Points).map_err(in_file),
        "png" => parse_depth_png(&bytes).map_err(in_file),
        _ => {
            let format = if ext == "ply" { MeshFormat::Ply } else { MeshFormat::Xyz };
            let points = parse_points_limited(&bytes, format, MAX_FILE_POINTS).map_err(in_file)?;
            Ok(FileFrame::Points(points.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()))
        }
    }
}

/// A PCD field: its name, element type, size in bytes and count of elements.
#[derive(Clone, Debug)]
struct PcdField {
    name: String,
    kind: u8,
    size: usize,
    count: usize,
}

/// How a PCD file's data section is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PcdData {
    Ascii,
    Binary,
    BinaryCompressed,
}

fn pcd_error(reason: impl Into<String>) -> Error {
    Error::invalid("pcd", reason)
}

/// The numbers of a header line's values, named by its key.
fn header_numbers(key: &str, values: &[&str]) -> Result<Vec<usize>> {
    values
        .iter()
        .map(|v| v.parse::<usize>().map_err(|_| pcd_error(format!("{key}: `{v}` is not a non-negative integer"))))
        .collect()
}

/// Parses a PCD file (module docs) into its x, y, z coordinates, one per point in file order.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `pcd` for a header that is missing a line, declares fields
/// inconsistently or lacks float x, y, z fields, a point count above [`MAX_FILE_POINTS`] or beyond
/// what the data holds, an ASCII line with the wrong number of values or a coordinate that is not
/// a number, or compressed data that does not decompress to the declared size.
pub fn parse_pcd(bytes: &[u8]) -> Result<Vec<[f32; 3]>> {
    let mut at = 0usize;
    let mut fields: Vec<PcdField> = Vec::new();
    let (mut sizes, mut kinds, mut counts) = (None, None, None);
    let (mut width, mut height, mut points) = (None, None, None);
    let data = loop {
        if at >= bytes.len() {
            return Err(pcd_error("the header ends before its DATA line"));
        }
        if at > MAX_PCD_HEADER_BYTES {
            return Err(pcd_error(format!("the header is longer than {MAX_PCD_HEADER_BYTES} bytes")));
        }
        let end = bytes[at..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |k| at + k);
        let line = std::str::from_utf8(&bytes[at..end])
            .map_err(|_| pcd_error(format!("header byte {at}: not UTF-8 text")))?
            .trim();
        at = (end + 1).min(bytes.len());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut words = line.split_whitespace();
        let key = words.next().unwrap_or("").to_ascii_uppercase();
        let values: Vec<&str> = words.collect();
        match key.as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" => {
                fields =
                    values.iter().map(|n| PcdField { name: (*n).to_owned(), kind: b'F', size: 4, count: 1 }).collect()
            }
            "SIZE" => sizes = Some(header_numbers("SIZE", &values)?),
            "COUNT" => counts = Some(header_numbers("COUNT", &values)?),
            "TYPE" => kinds = Some(values.iter().map(|v| v.to_ascii_uppercase()).collect::<Vec<_>>()),
            "WIDTH" | "HEIGHT" | "POINTS" => {
                let n = match header_numbers(&key, &values)?[..] {
                    [n] => n,
                    _ => return Err(pcd_error(format!("{key}: expected one number, got {}", values.len()))),
                };
                *match key.as_str() {
                    "WIDTH" => &mut width,
                    "HEIGHT" => &mut height,
                    _ => &mut points,
                } = Some(n);
            }
            "DATA" => {
                break match values.first().map(|v| v.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => PcdData::Ascii,
                    Some("binary") => PcdData::Binary,
                    Some("binary_compressed") => PcdData::BinaryCompressed,
                    _ => {
                        return Err(pcd_error(format!(
                            "DATA: expected ascii, binary or binary_compressed, got `{}`",
                            values.join(" ")
                        )))
                    }
                };
            }
            other => return Err(pcd_error(format!("unknown header line `{other}`"))),
        }
    };
    if fields.is_empty() {
        return Err(pcd_error("no FIELDS line"));
    }
    let n = fields.len();
    let sizes = sizes.ok_or_else(|| pcd_error("no SIZE line"))?;
    let kinds = kinds.ok_or_else(|| pcd_error("no TYPE line"))?;
    let counts = counts.unwrap_or_else(|| vec![1; n]);
    for (key, len) in [("SIZE", sizes.len()), ("TYPE", kinds.len()), ("COUNT", counts.len())] {
        if len != n {
            return Err(pcd_error(format!("{key}: {len} values for the {n} FIELDS")));
        }
    }
    for (k, f) in fields.iter_mut().enumerate() {
        f.size = sizes[k];
        f.count = counts[k];
        f.kind = match kinds[k].as_str() {
            "F" => b'F',
            "I" => b'I',
            "U" => b'U',
            other => return Err(pcd_error(format!("TYPE of field `{}`: expected F, I or U, got `{other}`", f.name))),
        };
        if ![1, 2, 4, 8].contains(&f.size) || f.count == 0 || f.count > 1 << 16 {
            return Err(pcd_error(format!(
                "field `{}`: SIZE must be 1, 2, 4 or 8 and COUNT 1 to 65536, got {} and {}",
                f.name, f.size, f.count
            )));
        }
    }
    // WIDTH and HEIGHT (1 when absent); a file with POINTS alone is unorganized.
    let (width, height) = match (width, points) {
        (Some(w), _) => (w, height.unwrap_or(1)),
        (None, Some(p)) => (p, 1),
        (None, None) => return Err(pcd_error("neither WIDTH nor POINTS")),
    };
    let total = width.checked_mul(height).filter(|&t| t <= MAX_FILE_POINTS).ok_or_else(|| {
        pcd_error(format!("WIDTH × HEIGHT = {width} × {height} exceeds the limit of {MAX_FILE_POINTS} points"))
    })?;
    let points = points.unwrap_or(total);
    if points != total {
        return Err(pcd_error(format!("POINTS {points} differs from WIDTH × HEIGHT = {width} × {height}")));
    }
    let mut xyz = [0usize; 3];
    for (axis, name) in ["x", "y", "z"].iter().enumerate() {
        let k = fields.iter().position(|f| f.name == *name).ok_or_else(|| pcd_error(format!("no `{name}` field")))?;
        let f = &fields[k];
        if f.kind != b'F' || !matches!(f.size, 4 | 8) || f.count != 1 {
            return Err(pcd_error(format!(
                "field `{name}` must be one float (TYPE F, SIZE 4 or 8, COUNT 1), got TYPE {}, SIZE {}, COUNT {}",
                f.kind as char, f.size, f.count
            )));
        }
        xyz[axis] = k;
    }
    let body = &bytes[at..];
    match data {
        PcdData::Ascii => parse_pcd_ascii(body, &fields, xyz, points),
        PcdData::Binary => {
            let record: usize = fields.iter().map(|f| f.size * f.count).sum();
            if body.len() / record < points {
                return Err(pcd_error(format!(
                    "the binary data holds {} bytes, {points} points of {record} bytes need {}",
                    body.len(),
                    points * record
                )));
            }
            let offset = |k: usize| fields[..k].iter().map(|f| f.size * f.count).sum::<usize>();
            let at = xyz.map(offset);
            Ok((0..points)
                .map(|i| {
                    let r = &body[i * record..];
                    [0, 1, 2].map(|a| float(&r[at[a]..], fields[xyz[a]].size))
                })
                .collect())
        }
        PcdData::BinaryCompressed => {
            let word = |k: usize| body.get(k..k + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
            let (compressed, size) =
                word(0).zip(word(4)).ok_or_else(|| pcd_error("binary_compressed data without its two size words"))?;
            let record: usize = fields.iter().map(|f| f.size * f.count).sum();
            if size != points * record {
                return Err(pcd_error(format!(
                    "binary_compressed: {size} uncompressed bytes declared, {points} points of {record} bytes are {}",
                    points * record
                )));
            }
            let input = body.get(8..8 + compressed).ok_or_else(|| {
                pcd_error(format!("binary_compressed: {compressed} bytes declared, {} present", body.len() - 8))
            })?;
            let plain = lzf_decompress(input, size)?;
            // Fields one after another: field k's values start after every earlier field's.
            let start = |k: usize| points * fields[..k].iter().map(|f| f.size * f.count).sum::<usize>();
            let at = xyz.map(start);
            Ok((0..points)
                .map(|i| [0, 1, 2].map(|a| float(&plain[at[a] + i * fields[xyz[a]].size..], fields[xyz[a]].size)))
                .collect())
        }
    }
}

/// A little-endian float of `size` bytes (4 or 8) at the start of `b`, as f32.
fn float(b: &[u8], size: usize) -> f32 {
    if size == 8 {
        f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f32
    } else {
        f32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
}

/// The points of a PCD file's ASCII data: one line of every field's values per point.
fn parse_pcd_ascii(body: &[u8], fields: &[PcdField], xyz: [usize; 3], points: usize) -> Result<Vec<[f32; 3]>> {
    let text = std::str::from_utf8(body).map_err(|e| pcd_error(format!("the ascii data is not UTF-8: {e}")))?;
    let values: usize = fields.iter().map(|f| f.count).sum();
    // Token index of each coordinate on a line.
    let token = xyz.map(|k| fields[..k].iter().map(|f| f.count).sum::<usize>());
    // At least two bytes per point ("0\n"): a count the text cannot hold fails before reserving.
    if points > text.len() / 2 + 1 {
        return Err(pcd_error(format!("POINTS {points}, but the ascii data holds {} bytes", text.len())));
    }
    let mut out = Vec::with_capacity(points);
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    for i in 0..points {
        let line = lines
            .next()
            .ok_or_else(|| pcd_error(format!("POINTS {points}, but the ascii data ends after {i} points")))?;
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() != values {
            return Err(pcd_error(format!("point {i}: {} values, the fields take {values}", words.len())));
        }
        let mut p = [0f32; 3];
        for a in 0..3 {
            let w = words[token[a]];
            p[a] = w
                .parse::<f64>()
                .map_err(|_| pcd_error(format!("point {i}: `{w}` ({}) is not a number", ["x", "y", "z"][a])))?
                as f32;
        }
        out.push(p);
    }
    Ok(out)
}

/// Decompresses LZF data (liblzf's format, as PCL writes it) into exactly `size` bytes.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `pcd` for a run or reference beyond the input or the output,
/// or output of another size.
pub fn lzf_decompress(input: &[u8], size: usize) -> Result<Vec<u8>> {
    let bad = |at: usize, what: &str| pcd_error(format!("binary_compressed: corrupt LZF data at byte {at}: {what}"));
    let mut out: Vec<u8> = Vec::with_capacity(size);
    let mut i = 0usize;
    while i < input.len() {
        let ctrl = input[i] as usize;
        i += 1;
        if ctrl < 32 {
            // A literal run of ctrl + 1 bytes.
            let run = input.get(i..i + ctrl + 1).ok_or_else(|| bad(i, "a literal run past the end"))?;
            if out.len() + run.len() > size {
                return Err(bad(i, "more bytes than declared"));
            }
            out.extend_from_slice(run);
            i += ctrl + 1;
        } else {
            // A back reference: length (ctrl >> 5) + 2, extended by a byte when 7; distance from
            // the low 5 bits and the next byte, plus one.
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input.get(i).ok_or_else(|| bad(i, "a length past the end"))? as usize;
                i += 1;
            }
            let low = *input.get(i).ok_or_else(|| bad(i, "a reference past the end"))? as usize;
            i += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            len += 2;
            if back > out.len() {
                return Err(bad(i, "a reference before the start"));
            }
            if out.len() + len > size {
                return Err(bad(i, "more bytes than declared"));
            }
            let from = out.len() - back;
            // Byte by byte: a reference may overlap the bytes it produces.
            for k in 0..len {
                out.push(out[from + k]);
            }
        }
    }
    if out.len() != size {
        return Err(pcd_error(format!("binary_compressed: {} bytes decompressed, {size} declared", out.len())));
    }
    Ok(out)
}

/// Decodes a 16-bit grayscale PNG into a depth image (values as stored, in units of the depth
/// scale).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `png` for bytes that do not decode, another color type or
/// bit depth, or more than [`MAX_FILE_POINTS`] pixels.
pub fn parse_depth_png(bytes: &[u8]) -> Result<FileFrame> {
    let bad = |e: png::DecodingError| Error::invalid("png", e.to_string());
    let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(bad)?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    if info.color_type != png::ColorType::Grayscale || info.bit_depth != png::BitDepth::Sixteen {
        return Err(Error::invalid(
            "png",
            format!(
                "a depth image must be 16-bit grayscale, this one is {:?} at {} bits",
                info.color_type, info.bit_depth as u8
            ),
        ));
    }
    if (width as usize).saturating_mul(height as usize) > MAX_FILE_POINTS {
        return Err(Error::invalid("png", format!("{width} × {height} pixels exceeds the limit of {MAX_FILE_POINTS}")));
    }
    let mut buffer = vec![0u8; reader.output_buffer_size()];
    let frame = reader.next_frame(&mut buffer).map_err(bad)?;
    // PNG stores 16-bit samples big-endian, rows of `line_size` bytes.
    let mut pixels = Vec::with_capacity(width as usize * height as usize);
    for row in buffer[..frame.buffer_size()].chunks_exact(frame.line_size) {
        pixels.extend(row[..2 * width as usize].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])));
    }
    Ok(FileFrame::Depth { width, height, pixels })
}

#[cfg(test)]
#[path = "cloud_files_tests.rs"]
mod tests;
