//! Mesh and point-cloud loading: OFF, OBJ, STL (ASCII and binary), PLY (ASCII and binary),
//! COLLADA, XYZ.
//!
//! A single-body fit needs only the vertices ([`parse_points`]: the convex hull is recomputed);
//! a compound fit and the exact mesh–mesh distance of `sublevel-lab bench` and `chart` need the
//! faces too: [`load_triangle_mesh`] reads a [`TriangleMesh`] from OFF, OBJ, STL, PLY or COLLADA (the
//! same parsers and limits, faces split into triangle fans), and [`weld_mesh`] merges the
//! repeated vertices of a triangle soup before a decomposition.
//!
//! ```text
//! off   "OFF" header line (also "OFF nV nF nE" on one line), then "nV nF nE", nV lines "x y z",
//!       then nF faces "k i₁ … i_k"; '#' comments and blank lines skipped            (off.rs)
//! obj   `v x y z [w]` lines and `f` lines of every object and group; the rest skipped (obj.rs)
//! stl   ASCII or binary; vertices of equal coordinates merged by stl_io  (stl.rs, via stl_io)
//! ply   the `vertex` element's x, y, z properties (any numeric type) and the `face`  (ply.rs)
//!       element's `vertex_indices` lists; ascii, binary_little_endian or binary_big_endian;
//!       other elements are checked and skipped
//! dae   COLLADA: every instanced mesh, in meters (unit, up axis and node transforms  (dae.rs,
//!       applied)                                                        via mesh-loader)
//! xyz   one "x y z" per line (commas allowed, extra columns ignored; no faces)       (xyz.rs)
//! ```
//!
//! # Untrusted input
//!
//! The bytes come from clients, so no count a file declares is trusted. Before anything is
//! reserved or handed to a third-party parser, every format checks its counts
//! ([`parse_points_limited`]):
//!
//! - against the input's size: a header promising more items than the bytes after it can hold
//!   is [`sublevel_core::Error::InvalidArgument`] naming `mesh` (PLY, every element: the sum of its property sizes
//!   per binary item, 2 bytes per property per ascii line; binary STL: 50 bytes per triangle;
//!   OFF: 6 bytes per vertex line, where nothing is reserved and the error names the first bad
//!   line or where the file ends);
//! - against `max_points`: more declared vertices (OFF, PLY), more `v` lines (OBJ), more point
//!   lines (XYZ) or more than 3 × `max_points` triangles (STL) is [`sublevel_core::Error::ResourceExhausted`]
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
//!
//! The limits, error constructors and the clipping of client text every format shares live in
//! `limits.rs`.

mod dae;
mod limits;
mod obj;
mod off;
mod ply;
mod stl;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod triangle_tests;
mod weld;
mod xyz;

pub use off::{parse_off_mesh, OffMesh};
pub use ply::MAX_PLY_HEADER_BYTES;
pub use sublevel_core::compound::WeldReport;
pub use weld::{weld_mesh, WeldedMesh, DEFAULT_WELD_TOLERANCE};

use limits::{echo, exhausted, guarded, invalid};
use sublevel_core::math::Point3;
use sublevel_core::Result;

/// A triangle mesh: vertices and triangles of indices into them ([`load_triangle_mesh`],
/// [`parse_off_mesh`]).
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions, in the file's units (meters for the bundled shapes).
    pub vertices: Vec<Point3>,
    /// The faces as triangles of indices into `vertices`: a polygon `i₁ … i_k` is split into the
    /// fan (i₁, i_j, i_{j+1}), j = 2 … k − 1, so it gives k − 2 triangles and a face of fewer
    /// than 3 vertices none (consumers such as parry's `TriMesh` take triangles only).
    pub triangles: Vec<[u32; 3]>,
}

/// The `max_points` of [`parse_points`] and [`load_points`].
pub const DEFAULT_MAX_MESH_POINTS: usize = 10_000_000;

/// A mesh or point-cloud file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Object File Format (Princeton Shape Benchmark): `OFF`, counts, vertices, faces.
    Off,
    /// Wavefront OBJ: `v x y z` lines (faces optional).
    Obj,
    /// STL, binary or ASCII.
    Stl,
    /// PLY, ASCII or binary.
    Ply,
    /// COLLADA (`.dae`): the triangles of every instanced mesh, in meters.
    Dae,
    /// One `x y z` line per point (also `.txt`, `.pts`).
    Xyz,
}

impl MeshFormat {
    /// Every format.
    pub const ALL: [MeshFormat; 6] =
        [MeshFormat::Off, MeshFormat::Obj, MeshFormat::Stl, MeshFormat::Ply, MeshFormat::Dae, MeshFormat::Xyz];

    /// The lower-case name (`"off"`, `"obj"`, `"stl"`, `"ply"`, `"dae"`, `"xyz"`).
    pub fn name(&self) -> &'static str {
        match self {
            MeshFormat::Off => "off",
            MeshFormat::Obj => "obj",
            MeshFormat::Stl => "stl",
            MeshFormat::Ply => "ply",
            MeshFormat::Dae => "dae",
            MeshFormat::Xyz => "xyz",
        }
    }

    /// The format of a file name's extension (case-insensitive; `txt` and `pts` are `xyz`).
    ///
    /// # Errors
    /// As [`MeshFormat::from_str`](std::str::FromStr) for an unknown or missing extension.
    pub fn of_path(path: &std::path::Path) -> Result<Self> {
        path.extension().and_then(|e| e.to_str()).unwrap_or("").parse()
    }
}

impl std::str::FromStr for MeshFormat {
    type Err = sublevel_core::Error;

    /// Parses a format name: `off`, `obj`, `stl`, `ply`, `dae`, or `xyz` / `txt` / `pts`
    /// (case-insensitive, a leading dot is ignored).
    ///
    /// # Errors
    /// [`sublevel_core::Error::InvalidArgument`] naming `mesh` for any other name.
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().trim_start_matches('.').to_ascii_lowercase().as_str() {
            "off" => Ok(MeshFormat::Off),
            "obj" => Ok(MeshFormat::Obj),
            "stl" => Ok(MeshFormat::Stl),
            "ply" => Ok(MeshFormat::Ply),
            "dae" => Ok(MeshFormat::Dae),
            "xyz" | "txt" | "pts" => Ok(MeshFormat::Xyz),
            other => {
                Err(invalid(format!("unknown format `{}`; expected one of off, obj, stl, ply, dae, xyz", echo(other))))
            }
        }
    }
}

/// Reads the vertices of a mesh file; the format follows the extension (case-insensitive).
///
/// # Errors
/// [`sublevel_core::Error::Io`] when the file cannot be read; otherwise as [`parse_points`].
pub fn load_points(path: &std::path::Path) -> Result<Vec<Point3>> {
    let format = MeshFormat::of_path(path)?;
    let bytes = std::fs::read(path)?;
    parse_points(&bytes, format)
}

/// [`parse_points_limited`] with [`DEFAULT_MAX_MESH_POINTS`].
///
/// # Errors
/// As [`parse_points_limited`].
pub fn parse_points(bytes: &[u8], format: MeshFormat) -> Result<Vec<Point3>> {
    parse_points_limited(bytes, format, DEFAULT_MAX_MESH_POINTS)
}

/// Parses mesh bytes in the given format, returning at most `max_points` vertices. Declared counts are checked against `max_points` and against the size of `bytes`
/// before anything is allocated (see the module documentation).
///
/// # Errors
/// [`sublevel_core::Error::InvalidArgument`] naming `mesh` for unparsable bytes, a header
/// that declares more than the bytes can hold, a non-finite coordinate, or a file without
/// vertices; [`sublevel_core::Error::ResourceExhausted`] naming `mesh` when the file declares or holds more than
/// `max_points` vertices.
pub fn parse_points_limited(bytes: &[u8], format: MeshFormat, max_points: usize) -> Result<Vec<Point3>> {
    let fmt = format.name();
    let points = match format {
        MeshFormat::Off => off::read_off(bytes, max_points, false)?.vertices,
        MeshFormat::Xyz => xyz::parse_xyz(bytes, max_points)?,
        MeshFormat::Obj => obj::parse_obj(bytes, max_points)?,
        MeshFormat::Stl => {
            stl::check_stl_counts(bytes, max_points)?;
            guarded("stl", || stl::parse_stl(bytes))?
        }
        MeshFormat::Ply => ply::parse_ply(bytes, max_points)?,
        MeshFormat::Dae => dae::parse_dae_mesh(bytes, max_points)?.vertices,
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

/// Parses a triangle mesh — vertices and faces, every face split into a triangle fan — from OFF,
/// OBJ (every object and group merged), STL (ASCII or binary), PLY (the `face` element's
/// `vertex_indices`) or COLLADA (every instanced mesh, in meters), with the limits of [`parse_points_limited`] (at most `max_points`
/// vertices; counts checked against the size of `bytes` first). Coordinates are as in the file
/// (meters for a fit); vertices are not welded ([`weld_mesh`] does that).
///
/// # Errors
/// As [`parse_points_limited`], and [`sublevel_core::Error::InvalidArgument`] naming `mesh` for
/// XYZ (a point cloud) or a file without faces (a point-cloud PLY or OBJ), a face index that
/// names no vertex, or a face of fewer than 3 vertices in OBJ.
pub fn load_triangle_mesh(bytes: &[u8], format: MeshFormat, max_points: usize) -> Result<TriangleMesh> {
    let fmt = format.name();
    let mesh = match format {
        MeshFormat::Off => off::read_off(bytes, max_points, true)?,
        MeshFormat::Obj => obj::parse_obj_mesh(bytes, max_points)?,
        MeshFormat::Stl => {
            stl::check_stl_counts(bytes, max_points)?;
            guarded("stl", || stl::parse_stl_mesh(bytes))?
        }
        MeshFormat::Ply => ply::parse_ply_mesh(bytes, max_points)?,
        MeshFormat::Dae => dae::parse_dae_mesh(bytes, max_points)?,
        MeshFormat::Xyz => {
            return Err(invalid(
                "an xyz file is a point cloud without faces; a triangle mesh needs off, obj, stl, ply or dae",
            ))
        }
    };
    if mesh.vertices.is_empty() {
        return Err(invalid(format!("the {fmt} file has no vertices")));
    }
    if mesh.vertices.len() > max_points {
        return Err(exhausted(format!(
            "the {fmt} file has {} vertices, which exceeds the limit of {max_points} points",
            mesh.vertices.len()
        )));
    }
    if let Some(i) = mesh.vertices.iter().position(|p| !p.coords.iter().all(|c| c.is_finite())) {
        return Err(invalid(format!("vertex {i} has a non-finite coordinate")));
    }
    if mesh.triangles.is_empty() {
        let what = match format {
            MeshFormat::Ply => "no `face` element with vertex lists (a point cloud?)",
            MeshFormat::Obj => "no `f` lines (a point cloud?)",
            _ => "no faces",
        };
        return Err(invalid(format!(
            "the {fmt} file has {} vertices but {what}: a triangle mesh is needed",
            mesh.vertices.len()
        )));
    }
    Ok(mesh)
}

/// [`load_triangle_mesh`] of a file, the format from `format` or else the path's extension.
///
/// # Errors
/// [`sublevel_core::Error::Io`] when the file cannot be read; otherwise as
/// [`load_triangle_mesh`], with the file's path in the message.
pub fn load_triangle_mesh_file(
    path: &std::path::Path,
    format: Option<MeshFormat>,
    max_points: usize,
) -> Result<TriangleMesh> {
    let format = match format {
        Some(f) => f,
        None => MeshFormat::of_path(path)?,
    };
    let bytes = std::fs::read(path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?;
    load_triangle_mesh(&bytes, format, max_points).map_err(|e| match e {
        sublevel_core::Error::InvalidArgument { field, reason } => {
            sublevel_core::Error::InvalidArgument { field, reason: format!("{}: {reason}", path.display()) }
        }
        sublevel_core::Error::ResourceExhausted(m) => {
            sublevel_core::Error::ResourceExhausted(format!("{}: {m}", path.display()))
        }
        other => other,
    })
}
