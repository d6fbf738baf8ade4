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

/// Validates a cloud and normalizes it: (center, scale, uᵢ = (xᵢ − center)/scale).
///
/// # Errors
/// As [`normalize_and_hull`], except the hull's own failures.
fn validate_and_normalize(points: &[Point3]) -> Result<(Vector3, Real, Vec<Vector3>)> {
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
    Ok((center, scale, u))
}

/// Validates, normalizes and computes the convex hull of a cloud.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for an empty, non-finite, too small or flat cloud,
/// or when the hull computation fails on it.
pub fn normalize_and_hull(points: &[Point3]) -> Result<NormalizedCloud> {
    let (center, scale, u) = validate_and_normalize(points)?;
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

/// Thickness below which a fit thickens a near-flat cloud ([`thicken_flat`]), relative to the
/// longest side of the cloud's bounding box.
///
/// Why: the log det program's optimum for a slab of relative thickness t has Gram eigenvalues
/// spread by about t^(−2) (an ellipsoid's axes ratio 1/t at 2d = 2, its powers above), and Clarabel
/// (tolerance 10⁻⁶, static regularization 10⁻⁷, [`crate::sdp`]) cannot resolve that. A
/// six-vertex 50 × 30 mm slab, bounding-cube frame: 2d = 2 solves down to t = 3·10⁻⁵ (88
/// iterations) and fails (`InsufficientProgress`) at 10⁻⁵, 2d = 4 fails below 10⁻³, 2d = 6 takes 79
/// iterations at 10⁻³ and 37 at 3·10⁻³ (15–20 on a solid part). The UR5's `wrist3.stl` has such a
/// part: a 7.2 mm hexagonal cap whose six vertices differ by 3.4·10⁻⁸ m across its plane
/// (t = 4.7·10⁻⁶, float32 rounding of a flat face), above the coplanarity test
/// ([`FLATNESS_TOLERANCE`]), so `--parts auto` ended `InsufficientProgress`.
///
/// Thickening gives such a cloud a hull with volume (at t = 4.7·10⁻⁶ the hull solid's inertia had
/// no positive eigenvalues, so no principal axes) and bounds the body's coefficients (about
/// t^(−2d)); the solve itself is then made well conditioned by the principal frame
/// ([`PRINCIPAL_FRAME_ASPECT`]: on the slab thickened to 3·10⁻³, 2d = 6 still failed in the
/// bounding cube). Thickening to 3·10⁻³ of the longest side moves the body by at most 1.5·10⁻³ of
/// it (0.15 × the compound fit's default excess tolerance, 10⁻² of the mesh's diagonal, for a part
/// as large as the mesh).
pub const MIN_RELATIVE_THICKNESS: Real = 3e-3;

/// Aspect (thinnest / longest side of the cloud's bounding box in the principal axes of its hull)
/// below which a log det fit (c = 0) set to solve in the bounding cube solves in the principal box
/// ([`Normalization::PrincipalBox`]) instead: the same optimum (the program is affine-invariant),
/// better conditioned. The 50 × 30 mm slab of [`MIN_RELATIVE_THICKNESS`], aspect t: in the cube
/// 11–16 Clarabel iterations at t = 0.1, 23–28 at 10⁻², 26–37 at 3·10⁻³, and 2d = 6 fails on the
/// slab thickened to 3·10⁻³ (`InsufficientProgress`); in the principal box 10–14 iterations at every
/// t and degree (2d = 6 at 10⁻²: 0.9 s instead of 2.8 s).
pub const PRINCIPAL_FRAME_ASPECT: Real = 1e-2;

/// How [`thicken_flat`] thickened a cloud.
#[derive(Clone, Debug, PartialEq)]
pub struct Thickening {
    /// Each thin principal axis of the cloud (unit vector, input frame) and the cloud's extent
    /// along it before thickening (input units).
    pub axes: Vec<(Vector3, Real)>,
    /// The cloud's extent along each of those axes after (input units).
    pub thickness: Real,
    /// The thickness relative to the longest side of the cloud's bounding box.
    pub relative: Real,
}

impl Thickening {
    /// The fit report's note.
    pub fn note(&self) -> String {
        let axes: Vec<String> =
            self.axes.iter().map(|(n, e)| format!("{e:.3e} along ({:.4}, {:.4}, {:.4})", n.x, n.y, n.z)).collect();
        format!(
            "near-flat cloud (extent {}, below {} × its longest side): thickened to {:.3e} (every point kept, \
             and projected onto both faces of a slab of that thickness about it); the body contains the slab, \
             hence every point",
            axes.join(", "),
            self.relative,
            self.thickness
        )
    }
}

/// A near-flat cloud made thick enough for the fit SDPs to be well conditioned (see
/// [`MIN_RELATIVE_THICKNESS`]), or None when it already is.
///
/// The cloud's principal axes (covariance of its points) are taken in order of increasing
/// variance; along each axis n over which the cloud extends less than h = `min_relative` × the
/// longest side of its bounding box, every point x so far is kept and projected onto the two
/// planes x·n = m ± h/2 (m the middle of the cloud's extent along n), so that the cloud spans the
/// slab of thickness h about itself. A body containing the returned points contains the input
/// points (they are among them) and the slab's prism (one axis: 3 × the points; a needle: 9 ×).
///
/// # Errors
/// As [`normalize_and_hull`] for a cloud it refuses (empty, non-finite, fewer than 4 points,
/// coplanar to within [`FLATNESS_TOLERANCE`]): such a cloud is refused, not thickened.
pub fn thicken_flat(points: &[Point3], min_relative: Real) -> Result<Option<(Vec<Point3>, Thickening)>> {
    let (center, scale, u) = validate_and_normalize(points)?;
    let n = u.len() as Real;
    let mean = u.iter().fold(Vector3::zeros(), |a, v| a + v) / n;
    let cov = u.iter().fold(Matrix3::zeros(), |a, v| a + (v - mean) * (v - mean).transpose()) / n;
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    // Normalized units: the longest side of the bounding box is 2.
    let h = 2.0 * min_relative;
    let mut cloud: Vec<Vector3> = u;
    let mut axes = Vec::new();
    for k in order {
        let axis = eig.eigenvectors.column(k).normalize();
        let (lo, hi) = cloud
            .iter()
            .map(|v| v.dot(&axis))
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(l, h), x| (l.min(x), h.max(x)));
        if hi - lo >= h {
            continue;
        }
        axes.push((axis, (hi - lo) * scale));
        let mid = 0.5 * (lo + hi);
        let before = cloud.len();
        cloud.reserve(2 * before);
        for i in 0..before {
            let v = cloud[i];
            let along = v.dot(&axis);
            cloud.push(v + axis * (mid - 0.5 * h - along));
            cloud.push(v + axis * (mid + 0.5 * h - along));
        }
    }
    if axes.is_empty() {
        return Ok(None);
    }
    // The input points unchanged (bit for bit), then the projections back in input units.
    let mut out: Vec<Point3> = points.to_vec();
    out.extend(cloud[points.len()..].iter().map(|v| Point3::from(v * scale + center)));
    Ok(Some((out, Thickening { axes, thickness: h * scale, relative: min_relative })))
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

    /// A slab is thickened along its normal only, a needle along both thin axes; the output
    /// starts with the input points unchanged and spans h along every thin axis; a solid cloud
    /// is left alone and a coplanar one still refused.
    #[test]
    fn thicken_flat_spans_the_minimum_thickness_along_the_thin_axes() {
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
        let corners = |sides: Vector3| -> Vec<Point3> {
            (0..8)
                .map(|i| {
                    let c = Vector3::new((i & 1) as Real, ((i >> 1) & 1) as Real, ((i >> 2) & 1) as Real)
                        - Vector3::repeat(0.5);
                    Point3::from(rot * c.component_mul(&sides) + Vector3::new(1.0, 2.0, 3.0))
                })
                .collect()
        };
        let h = 3e-3;
        for (sides, thin) in [(Vector3::new(4.0, 2.0, 1e-6), 1), (Vector3::new(4.0, 1e-6, 2e-6), 2)] {
            let points = corners(sides);
            let (out, t) = thicken_flat(&points, h).unwrap().expect("thin");
            assert_eq!(&out[..8], &points[..]);
            assert_eq!(out.len(), 8 * 3usize.pow(thin as u32));
            assert_eq!(t.axes.len(), thin);
            let (lo, hi) = points
                .iter()
                .fold((points[0].coords, points[0].coords), |(l, u), p| (l.inf(&p.coords), u.sup(&p.coords)));
            assert!((t.thickness - h * (hi - lo).max()).abs() < 1e-12, "{}", t.thickness);
            for (axis, before) in &t.axes {
                let along: Vec<Real> = out.iter().map(|p| p.coords.dot(axis)).collect();
                let span = along.iter().fold(Real::NEG_INFINITY, |a, &b| a.max(b))
                    - along.iter().fold(Real::INFINITY, |a, &b| a.min(b));
                assert!((span - t.thickness).abs() < 1e-9, "span {span}");
                assert!(*before < 1e-5);
            }
            assert!(t.note().contains(&format!("thickened to {:.3e}", t.thickness)), "{}", t.note());
        }
        assert!(thicken_flat(&corners(Vector3::new(4.0, 2.0, 0.1)), h).unwrap().is_none());
        let flat = corners(Vector3::new(4.0, 2.0, 0.0));
        assert!(field_of(thicken_flat(&flat, h).unwrap_err()).contains("coplanar"));
    }
}
