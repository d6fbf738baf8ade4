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
//! [`FitMethod::LogDetP`](crate::FitMethod::LogDetP)), so for them this choice only affects
//! conditioning. The relaxed-convexity fits (p + c(‖u‖²)ᵈ sos-convex, paper eq.
//! "VAG.param.convex") and the trace objectives are not:
//! in x-coordinates the relaxation reads c·scale^(−2d)·‖x − center‖^(2d), so a smaller scale relaxes
//! more. Measured on the paper's five shapes (`sublevel fit --relaxation c`, log det P), the
//! bounding-cube scale gave a smaller or equal volume than the enclosing-ball scale
//! (max |xᵢ − center|) in every one of the 20 cells 2d ∈ {4, 6} × c ∈ {10, 100} — e.g. chair
//! 2d = 6: c = 10 0.588 → 0.449, c = 100 0.287 → 0.208 — and moved the trace rows by at most ±1.7 %;
//! centering at the input origin instead of the box midpoint was larger on 8 of 9 cells tried.
//! The box midpoint (rather than the vertex mean) does not depend on how densely a mesh samples
//! each region; monomials of degree ≤ 8 of the cloud stay within 3⁴ = 81 in magnitude.
//!
//! The body is always stored in this bounding-cube frame, but a fit may solve its SDP in another
//! affine frame ([`Normalization`], [`NormalizedCloud::reframed`]) and compose the result back
//! exactly. For the frame-dependent objectives (trace, c > 0) the fit solves in the bounding cube
//! and in the principal box (the hull solid's principal axes, each side of the bounding box in
//! those axes mapped onto [−1, 1]) and keeps the smaller body (`FitSettings::alternate_normalization`).
//! Measured on Table 1's 65 cells of those rows (one run each, 200 000 samples): ≤ 1.02 × the paper
//! on 29 cells in the bounding cube, 29 in the principal cube, 45 in the principal box, 45
//! whitened; the smaller of cube and principal box on 47 (e.g. chair 2d = 6, c = 10: 0.449 →
//! 0.303), all four frames 48. The anisotropic frames help the relaxed rows most: c(‖u‖²)ᵈ then
//! weighs each principal direction by the cloud's extent along it.
//!
//! A cloud is rejected before parry sees it (parry's quickhull can panic on degenerate input)
//! when it is empty, has a non-finite coordinate, has fewer than 4 points, or is flat: no four
//! points span a tetrahedron whose height exceeds [`FLATNESS_TOLERANCE`] times the cloud's radius.

use crate::{Error, Result};
use sublevel_core::math::{Matrix3, Point3, Real, Vector3};
pub use sublevel_core::report::Normalization;

/// Parses an optional normalization: `"none"` is None, any other name as [`Normalization`].
///
/// # Errors
/// [`Error::InvalidArgument`] naming `normalization` for an unknown name.
pub fn parse_optional_normalization(s: &str) -> Result<Option<Normalization>> {
    if s == "none" {
        Ok(None)
    } else {
        s.parse().map(Some)
    }
}

/// An affine change of coordinates `u_fit = linear · u + offset` from the body's normalized
/// coordinates u to the frame a fit is solved in (see [`Normalization`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Linear part (invertible).
    pub linear: Matrix3,
    /// Offset.
    pub offset: Vector3,
}

impl Frame {
    /// The identity (the body's own frame).
    pub fn identity() -> Self {
        Self { linear: Matrix3::identity(), offset: Vector3::zeros() }
    }

    /// True for the identity frame.
    pub fn is_identity(&self) -> bool {
        self.linear == Matrix3::identity() && self.offset == Vector3::zeros()
    }

    /// u ↦ u_fit.
    pub fn apply(&self, u: &Vector3) -> Vector3 {
        self.linear * u + self.offset
    }

    /// |det linear|: a volume in the fit frame divided by it is the volume in u.
    pub fn jacobian(&self) -> Real {
        self.linear.determinant().abs()
    }
}

impl NormalizedCloud {
    /// Centroid and second central moments (covariance × volume) of the hull as a solid, in
    /// normalized units: sums over the tetrahedra (o, a, b, c) of the hull triangles with
    /// ∫ x xᵀ dV = V/20·(Σ vᵢvᵢᵀ + (Σ vᵢ)(Σ vᵢ)ᵀ) over the four vertices.
    fn hull_inertia(&self) -> (Real, Vector3, Matrix3) {
        let n = self.hull_vertices.len().max(1) as Real;
        let o = self.hull_vertices.iter().fold(Vector3::zeros(), |a, v| a + v) / n;
        let (mut vol, mut first, mut second) = (0.0, Vector3::zeros(), Matrix3::zeros());
        for t in &self.hull_triangles {
            let [a, b, c] = t.map(|i| self.hull_vertices[i as usize] - o);
            let v = a.dot(&b.cross(&c)) / 6.0;
            let sum = a + b + c;
            vol += v;
            first += sum * (v / 4.0);
            second += (a * a.transpose() + b * b.transpose() + c * c.transpose() + sum * sum.transpose()) * (v / 20.0);
        }
        let mean = first / vol;
        let central = second / vol - mean * mean.transpose();
        (vol.abs(), mean + o, central)
    }

    /// The frame of `normalization` for this cloud and the cloud in it (points and hull vertices
    /// mapped, same triangles; `center` and `scale` stay the body's).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `points` when the hull solid has no volume to take axes
    /// from (cannot happen for a cloud [`normalize_and_hull`] accepted).
    pub fn reframed(&self, normalization: Normalization) -> Result<(Frame, NormalizedCloud)> {
        let map_by = |frame: Frame| {
            let map = |v: &Vector3| frame.apply(v);
            let cloud = NormalizedCloud {
                center: self.center,
                scale: self.scale,
                points: self.points.iter().map(map).collect(),
                hull_vertices: self.hull_vertices.iter().map(map).collect(),
                hull_triangles: self.hull_triangles.clone(),
            };
            (frame, cloud)
        };
        match normalization {
            Normalization::BoundingCube => return Ok((Frame::identity(), self.clone())),
            // x = scale·u + center.
            Normalization::Input => {
                return Ok(map_by(Frame { linear: Matrix3::identity() * self.scale, offset: self.center }));
            }
            _ => {}
        }
        let (vol, centroid, cov) = self.hull_inertia();
        let eig = cov.symmetric_eigen();
        if !(vol > 0.0 && eig.eigenvalues.min() > 0.0) {
            return Err(Error::invalid("points", "the convex hull has no volume to take principal axes from"));
        }
        // Axes sorted by decreasing variance, right-handed.
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
        let mut r = Matrix3::from_columns(&order.map(|i| eig.eigenvectors.column(i).into_owned()));
        if r.determinant() < 0.0 {
            r.column_mut(2).neg_mut();
        }
        let lambda = Vector3::from(order.map(|i| eig.eigenvalues[i]));
        let rotated: Vec<Vector3> = self.points.iter().map(|u| r.transpose() * u).collect();
        let (mut lo, mut hi) = (rotated[0], rotated[0]);
        for v in &rotated {
            lo = lo.inf(v);
            hi = hi.sup(v);
        }
        let half = (hi - lo) * 0.5;
        let mid = (hi + lo) * 0.5;
        // u_fit = D (Rᵀu − shift): D diagonal.
        let (d, shift) = match normalization {
            Normalization::PrincipalCube => (Vector3::repeat(1.0 / half.max()), mid),
            Normalization::PrincipalBox => (half.map(|h| 1.0 / h), mid),
            _ => {
                let w = lambda.map(|l| 1.0 / l.sqrt());
                let g = r.transpose() * centroid;
                let k = rotated.iter().map(|v| (v - g).component_mul(&w).amax()).fold(0.0, Real::max);
                (w / k, g)
            }
        };
        let linear = Matrix3::from_diagonal(&d) * r.transpose();
        Ok(map_by(Frame { linear, offset: -d.component_mul(&shift) }))
    }
}

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

    /// A rotated 4 × 2 × 1 box (corners plus interior points): its principal axes are the box's
    /// edges, so `PrincipalBox` maps it exactly onto [−1, 1]³ (normalized volume 8), `PrincipalCube`
    /// onto [−1, 1] × [−½, ½] × [−¼, ¼], and `Whitened` gives the hull solid an isotropic
    /// covariance; every frame keeps |u|∞ ≤ 1 and scales volumes by |det L|.
    #[test]
    fn principal_frames_of_a_rotated_box() {
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
        let sides = Vector3::new(4.0, 2.0, 1.0);
        let mut pts = Vec::new();
        for i in 0..8 {
            let c =
                Vector3::new((i & 1) as Real, ((i >> 1) & 1) as Real, ((i >> 2) & 1) as Real) - Vector3::repeat(0.5);
            pts.push(Point3::from(rot * c.component_mul(&sides) + Vector3::new(5.0, -1.0, 2.0)));
        }
        pts.push(Point3::new(5.1, -0.9, 2.0));
        let cloud = normalize_and_hull(&pts).unwrap();
        let body_volume = cloud.hull_volume_normalized();
        for (norm, volume, extents) in [
            (Normalization::PrincipalBox, 8.0, Vector3::new(1.0, 1.0, 1.0)),
            (Normalization::PrincipalCube, 1.0, Vector3::new(1.0, 0.5, 0.25)),
        ] {
            let (frame, fit) = cloud.reframed(norm).unwrap();
            assert!((fit.hull_volume_normalized() - volume).abs() < 1e-9, "{norm:?}: {}", fit.hull_volume_normalized());
            assert!((body_volume * frame.jacobian() - volume).abs() < 1e-9, "{norm:?}");
            let amax = fit.points.iter().fold(Vector3::zeros(), |m, u| m.sup(&u.abs()));
            assert!((amax - extents).amax() < 1e-9, "{norm:?}: {amax:?}");
        }
        let (_, white) = cloud.reframed(Normalization::Whitened).unwrap();
        let (_, _, cov) = white.hull_inertia();
        let iso = cov.trace() / 3.0;
        assert!((cov - Matrix3::identity() * iso).amax() < 1e-9 * iso, "{cov}");
        assert!(white.points.iter().all(|u| u.amax() <= 1.0 + 1e-12));
        let (id, same) = cloud.reframed(Normalization::BoundingCube).unwrap();
        assert!(id.is_identity() && same.points == cloud.points);
        for n in Normalization::ALL {
            assert_eq!(n.name().parse::<Normalization>().unwrap(), n);
        }
        assert!("pca".parse::<Normalization>().is_err());
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
