//! Mesh and point-cloud loading (OFF, OBJ, STL, PLY). STUB.

use crate::math::Point3;
use crate::Result;

/// Reads the vertices of a mesh file; the format follows the extension.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] for an unknown format or an unparsable file.
pub fn load_points(path: &std::path::Path) -> Result<Vec<Point3>> {
    let bytes = std::fs::read(path)?;
    parse_points(&bytes, path.extension().and_then(|e| e.to_str()).unwrap_or(""))
}

/// Parses mesh bytes in the given format (`off`, `obj`, `stl`, `ply`, or `xyz` for "x y z" lines).
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `mesh` for an unknown format or unparsable bytes.
pub fn parse_points(_bytes: &[u8], format: &str) -> Result<Vec<Point3>> {
    Err(crate::Error::invalid("mesh", format!("format `{format}` not implemented yet")))
}
