//! Cloud validation, normalization and the convex hull.
//!
//! Normalization: the cloud's axis-aligned bounding box is centered and scaled isotropically into
//! the cube [−1, 1]³ (its longest side spans [−1, 1]):
//!
//! ```text
//! center = midpoint of the axis-aligned bounding box of the cloud
//! scale  = half the longest side of that box      so every u = (x − center)/scale lies in [−1, 1]³
//! ```
//!
//! The log det P and log det H fits are affine-invariant up to a constant (see
//! [`super::logdet_p`]), so for them this choice only affects conditioning. The relaxed-convexity
//! fits (p + c(‖u‖²)ᵈ sos-convex, paper eq. "VAG.param.convex") and the trace objectives are not:
//! in x-coordinates the relaxation reads c·scale^(−2d)·‖x − center‖^(2d), so a smaller scale relaxes
//! more. Measured on the paper's five shapes (`sublevel fit --relaxation c`, log det P), the
//! bounding-cube scale gave a smaller or equal volume than the enclosing-ball scale
//! (max |xᵢ − center|) in every one of the 20 cells 2d ∈ {4, 6} × c ∈ {10, 100} — e.g. chair
//! 2d = 6: c = 10 0.588 → 0.449, c = 100 0.287 → 0.208 — and moved the trace rows by at most ±1.7 %;
//! centering at the input origin instead of the box midpoint was larger on 8 of 9 cells tried.
//! The box midpoint (rather than the vertex mean) does not depend on how densely a mesh samples
//! each region; monomials of degree ≤ 8 of the cloud stay within 3⁴ = 81 in magnitude.
//!
//! A cloud is rejected before parry sees it (parry's quickhull can panic on degenerate input)
//! when it is empty, has a non-finite coordinate, has fewer than 4 points, or is flat: no four
//! points span a tetrahedron whose height exceeds [`FLATNESS_TOLERANCE`] times the cloud's radius.

use crate::math::{Point3, Real, Vector3};
use crate::{Error, Result};

/// Relative thickness below which a cloud counts as collinear / coplanar.
pub const FLATNESS_TOLERANCE: Real = 1e-7;

/// A validated, normalized cloud and its convex hull (all in normalized coordinates).
#[derive(Clone, Debug)]
pub struct NormalizedCloud {
    /// Normalization center (input units).
    pub center: Vector3,
    /// Normalization scale (input units, > 0).
    pub scale: Real,
    /// Every input point, normalized: uᵢ = (xᵢ − center)/scale, |uᵢ| ≤ 1.
    pub points: Vec<Vector3>,
    /// Convex-hull vertices (normalized).
    pub hull_vertices: Vec<Vector3>,
    /// Hull triangles as indices into `hull_vertices`, counter-clockwise seen from outside.
    pub hull_triangles: Vec<[u32; 3]>,
}

impl NormalizedCloud {
    /// Volume enclosed by the hull triangles in normalized units (divergence theorem: signed
    /// tetrahedra from the hull's vertex centroid).
    pub fn hull_volume_normalized(&self) -> Real {
        let n = self.hull_vertices.len().max(1) as Real;
        let o = self.hull_vertices.iter().fold(Vector3::zeros(), |a, v| a + v) / n;
        let six_v: Real = self
            .hull_triangles
            .iter()
            .map(|t| {
                let a = self.hull_vertices[t[0] as usize] - o;
                let b = self.hull_vertices[t[1] as usize] - o;
                let c = self.hull_vertices[t[2] as usize] - o;
                a.dot(&b.cross(&c))
            })
            .sum();
        six_v.abs() / 6.0
    }

    /// Hull volume in cubic input units.
    pub fn hull_volume(&self) -> Real {
        self.hull_volume_normalized() * self.scale.powi(3)
    }
}

/// Validates, normalizes and computes the convex hull of a cloud.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for an empty, non-finite, too small or flat cloud,
/// or when the hull computation fails on it.
pub fn normalize_and_hull(points: &[Point3]) -> Result<NormalizedCloud> {
    if points.is_empty() {
        return Err(Error::invalid("points", "the cloud is empty; need at least 4 non-coplanar points"));
    }
    if let Some(i) = points.iter().position(|p| !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite())) {
        return Err(Error::invalid("points", format!("point {i} has a non-finite coordinate: {:?}", points[i].coords)));
    }
    if points.len() < 4 {
        return Err(Error::invalid(
            "points",
            format!("{} points cannot enclose a volume; need at least 4 non-coplanar points", points.len()),
        ));
    }
    let mut lo = points[0].coords;
    let mut hi = points[0].coords;
    for p in points {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    let center = (lo + hi) * 0.5;
    let scale = ((hi - lo) * 0.5).max();
    if !(scale > 0.0 && scale.is_finite()) {
        return Err(Error::invalid("points", "all points coincide (or the cloud's extent overflows)"));
    }
    let u: Vec<Vector3> = points.iter().map(|p| (p.coords - center) / scale).collect();
    check_full_dimensional(&u)?;

    let pts: Vec<parry3d_f64::math::Vector3> =
        u.iter().map(|v| parry3d_f64::math::Vector3::new(v.x, v.y, v.z)).collect();
    let hull = std::panic::catch_unwind(|| parry3d_f64::transformation::try_convex_hull(&pts));
    let (verts, tris) = match hull {
        Ok(Ok(h)) => h,
        Ok(Err(e)) => return Err(Error::invalid("points", format!("convex hull failed: {e:?}"))),
        Err(_) => return Err(Error::invalid("points", "convex hull failed on this (near-degenerate) cloud")),
    };
    if verts.len() < 4 || tris.len() < 4 {
        return Err(Error::invalid("points", "the convex hull is flat; need at least 4 non-coplanar points"));
    }
    let hull_vertices: Vec<Vector3> = verts.iter().map(|v| Vector3::new(v.x, v.y, v.z)).collect();
    Ok(NormalizedCloud { center, scale, points: u, hull_vertices, hull_triangles: tris })
}

/// Rejects normalized clouds (radius 1) that lie within [`FLATNESS_TOLERANCE`] of a plane.
fn check_full_dimensional(u: &[Vector3]) -> Result<()> {
    let a = u[0];
    let far = |score: &dyn Fn(&Vector3) -> Real| -> (usize, Real) {
        u.iter().enumerate().map(|(i, v)| (i, score(v))).fold((0, 0.0), |best, c| if c.1 > best.1 { c } else { best })
    };
    let (ib, db) = far(&|v| (v - a).norm());
    if db <= FLATNESS_TOLERANCE {
        return Err(Error::invalid("points", "all points coincide; need at least 4 non-coplanar points"));
    }
    let dir = (u[ib] - a) / db;
    let (ic, dc) = far(&|v| {
        let w = v - a;
        (w - dir * w.dot(&dir)).norm()
    });
    if dc <= FLATNESS_TOLERANCE {
        return Err(Error::invalid("points", "all points are collinear; need at least 4 non-coplanar points"));
    }
    let normal = (u[ib] - a).cross(&(u[ic] - a)).normalize();
    let (_, dd) = far(&|v| (v - a).dot(&normal).abs());
    if dd <= FLATNESS_TOLERANCE {
        return Err(Error::invalid("points", "all points are coplanar; need at least 4 non-coplanar points"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field_of(e: Error) -> String {
        match e {
            Error::InvalidArgument { field, reason } => format!("{field}: {reason}"),
            other => panic!("expected InvalidArgument, got {other}"),
        }
    }

    #[test]
    fn cube_hull_volume_and_normalization() {
        // Unit cube [1, 3]³ plus interior points: hull volume 8, center (2, 2, 2), scale √3.
        let mut pts = Vec::new();
        for i in 0..8 {
            pts.push(Point3::new(
                1.0 + 2.0 * (i & 1) as Real,
                1.0 + 2.0 * ((i >> 1) & 1) as Real,
                1.0 + 2.0 * ((i >> 2) & 1) as Real,
            ));
        }
        pts.push(Point3::new(2.0, 2.1, 1.9));
        pts.push(Point3::new(1.5, 2.5, 2.5));
        let c = normalize_and_hull(&pts).unwrap();
        assert!((c.center - Vector3::new(2.0, 2.0, 2.0)).norm() < 1e-15);
        // Cube [1, 3]³: half the longest side is 1, so the normalized cube is exactly [−1, 1]³.
        assert!((c.scale - 1.0).abs() < 1e-15);
        assert!(c.points.iter().all(|u| u.amax() <= 1.0 + 1e-15));
        assert_eq!(c.hull_vertices.len(), 8);
        assert!((c.hull_volume() - 8.0).abs() < 1e-12, "{}", c.hull_volume());
    }

    #[test]
    fn degenerate_clouds_are_rejected_by_name() {
        let flat: Vec<Point3> = (0..20).map(|i| Point3::new(i as Real, (i * i % 7) as Real, 0.5)).collect();
        assert!(field_of(normalize_and_hull(&flat).unwrap_err()).contains("points: all points are coplanar"));
        let line: Vec<Point3> = (0..20).map(|i| Point3::new(i as Real, 2.0 * i as Real, 1.0)).collect();
        assert!(field_of(normalize_and_hull(&line).unwrap_err()).contains("collinear"));
        let same = vec![Point3::new(1.0, 1.0, 1.0); 5];
        assert!(field_of(normalize_and_hull(&same).unwrap_err()).contains("coincide"));
        let three = [Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 1.0, 0.0)];
        assert!(field_of(normalize_and_hull(&three).unwrap_err()).contains("3 points"));
        assert!(field_of(normalize_and_hull(&[]).unwrap_err()).contains("empty"));
        let mut nan = flat.clone();
        nan[3].y = Real::NAN;
        assert!(field_of(normalize_and_hull(&nan).unwrap_err()).contains("point 3 has a non-finite"));
        let mut inf = flat;
        inf[0].z = Real::INFINITY;
        assert!(field_of(normalize_and_hull(&inf).unwrap_err()).contains("non-finite"));
    }
}
