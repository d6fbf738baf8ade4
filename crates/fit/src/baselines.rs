//! Classical bounding volumes of a point cloud, the baselines of the paper's Table 1
//! (`tab:bounding.volumes`): convex hull, minimum enclosing ball, axis-aligned box, minimum-volume
//! oriented box, and the minimum-volume enclosing ellipsoid (MVEE).
//!
//! Everything is in the cloud's own units (meters); volumes are in cubic units. Each baseline
//! returns its shape, not only its volume, so other code can test containment or pose it.
//!
//! ```text
//! hull      parry's quickhull (the same hull the fits use, see hull.rs)
//! ball      Welzl's randomized algorithm on the hull vertices: exact up to rounding
//! AABB      [min, max] of the coordinates in the file's frame
//! OBB       orientation search: every distinct hull face normal as one box axis, the best
//!           rectangle of the projection (rotating edges of its 2-D hull), then a local rotation
//!           refinement (pattern search over small rotations); the paper's "AABB" column
//! MVEE      Khachiyan's algorithm with Todd–Yildirim away steps, certified by the duality bound
//!           vol(E) ≥ (4π/3)·3^{3/2}·det Σ(u)^{1/2}  for any weights u on the simplex
//! ```
//!
//! The exact minimum-volume box is O'Rourke's O(n³) algorithm; the face-normal search is the
//! practical version (one box face flush with a hull face) and is what common mesh libraries do.
//! It is an upper bound on the true minimum; the refinement can only lower it.

use crate::{Error, Result};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use sublevel_core::math::{Matrix3, Point3, Real, Vector3};

/// Convex hull vertices and triangles of a cloud, in the cloud's units.
#[derive(Clone, Debug)]
pub struct Hull {
    /// Hull vertices.
    pub vertices: Vec<Point3>,
    /// Triangles as indices into `vertices`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Enclosed volume (cubic units).
    pub volume: Real,
}

/// The convex hull of a cloud (via [`super::hull::normalize_and_hull`], mapped back to the
/// cloud's units).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for an empty, non-finite, too small or flat cloud.
pub fn convex_hull(points: &[Point3]) -> Result<Hull> {
    let cloud = super::hull::normalize_and_hull(points)?;
    let vertices = cloud.hull_vertices.iter().map(|u| Point3::from(cloud.center + u * cloud.scale)).collect();
    Ok(Hull { vertices, triangles: cloud.hull_triangles.clone(), volume: cloud.hull_volume() })
}

/// A ball `{x : |x − center| ≤ radius}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingSphere {
    /// Center (cloud units).
    pub center: Point3,
    /// Radius (cloud units, ≥ 0).
    pub radius: Real,
}

impl BoundingSphere {
    /// Volume 4/3 π r³.
    pub fn volume(&self) -> Real {
        4.0 / 3.0 * std::f64::consts::PI * self.radius.powi(3)
    }

    /// Whether `x` lies in the ball (with a relative slack of 1e-9 of the radius for rounding).
    pub fn contains(&self, x: &Point3) -> bool {
        (x - self.center).norm() <= self.radius * (1.0 + 1e-9) + 1e-12
    }

    fn contains_strict(&self, x: &Point3) -> bool {
        (x - self.center).norm_squared() <= self.radius * self.radius * (1.0 + 1e-10) + 1e-24
    }
}

/// A box `{center + R y : |yₖ| ≤ half_extents[k]}` with R = `[axes[0] axes[1] axes[2]]` orthonormal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientedBox {
    /// Center (cloud units).
    pub center: Point3,
    /// Unit axes, orthonormal, right-handed.
    pub axes: [Vector3; 3],
    /// Half extents along `axes` (cloud units, ≥ 0).
    pub half_extents: Vector3,
}

impl OrientedBox {
    /// Volume 8 · h₀ h₁ h₂.
    pub fn volume(&self) -> Real {
        8.0 * self.half_extents.x * self.half_extents.y * self.half_extents.z
    }

    /// Whether `x` lies in the box (with a relative slack of 1e-9 of the largest extent).
    pub fn contains(&self, x: &Point3) -> bool {
        let d = x - self.center;
        let slack = 1e-9 * self.half_extents.max() + 1e-12;
        (0..3).all(|k| self.axes[k].dot(&d).abs() <= self.half_extents[k] + slack)
    }

    /// The tightest box with the given orthonormal axes around `points` (not empty).
    fn fit(axes: [Vector3; 3], points: &[Point3]) -> Self {
        let mut lo = Vector3::repeat(Real::INFINITY);
        let mut hi = Vector3::repeat(Real::NEG_INFINITY);
        for p in points {
            let y = Vector3::new(axes[0].dot(&p.coords), axes[1].dot(&p.coords), axes[2].dot(&p.coords));
            lo = lo.inf(&y);
            hi = hi.sup(&y);
        }
        let mid = (lo + hi) * 0.5;
        let center = Point3::from(axes[0] * mid.x + axes[1] * mid.y + axes[2] * mid.z);
        Self { center, axes, half_extents: (hi - lo) * 0.5 }
    }
}

/// An ellipsoid `{x : (x − center)ᵀ shape (x − center) ≤ 1}`, shape symmetric positive definite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    /// Center (cloud units).
    pub center: Point3,
    /// Shape matrix (1/units²).
    pub shape: Matrix3,
}

impl Ellipsoid {
    /// Volume 4/3 π / sqrt(det shape).
    pub fn volume(&self) -> Real {
        4.0 / 3.0 * std::f64::consts::PI / self.shape.determinant().sqrt()
    }

    /// Whether `x` lies in the ellipsoid (slack 1e-9 on the quadratic form).
    pub fn contains(&self, x: &Point3) -> bool {
        let d = x - self.center;
        d.dot(&(self.shape * d)) <= 1.0 + 1e-9
    }
}

/// The minimum-volume enclosing ellipsoid found by [`mvee_khachiyan`], with its certificate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mvee {
    /// An ellipsoid containing every point (scaled so the farthest point is on its boundary).
    pub ellipsoid: Ellipsoid,
    /// Its volume: an upper bound on the MVEE volume.
    pub volume: Real,
    /// The dual bound (4π/3)·3^{3/2}·det Σ(u)^{1/2}: no ellipsoid containing every point is smaller.
    pub lower_bound: Real,
    /// Iterations of Khachiyan's method.
    pub iterations: usize,
}

impl Mvee {
    /// Relative duality gap `volume / lower_bound − 1` (≥ 0).
    pub fn relative_gap(&self) -> Real {
        self.volume / self.lower_bound - 1.0
    }
}

/// All baselines of one cloud (Table 1 rows "Convex-Hull", "Sphere", "AABB").
#[derive(Clone, Debug)]
pub struct Baselines {
    /// Number of input points.
    pub num_points: usize,
    /// Convex hull.
    pub hull: Hull,
    /// Minimum enclosing ball.
    pub sphere: BoundingSphere,
    /// Axis-aligned box in the file's coordinates.
    pub aabb: OrientedBox,
    /// Minimum-volume oriented box (the paper's "AABB" column).
    pub obb: OrientedBox,
}

/// Computes hull, minimum ball, axis-aligned and oriented boxes of a cloud.
///
/// # Errors
/// As [`convex_hull`].
pub fn baselines(points: &[Point3]) -> Result<Baselines> {
    let hull = convex_hull(points)?;
    let sphere = min_enclosing_ball(&hull.vertices, 7)?;
    let aabb = OrientedBox::fit([Vector3::x(), Vector3::y(), Vector3::z()], &hull.vertices);
    let obb = min_volume_obb(&hull)?;
    Ok(Baselines { num_points: points.len(), hull, sphere, aabb, obb })
}

fn check_points(points: &[Point3]) -> Result<()> {
    if points.is_empty() {
        return Err(Error::invalid("points", "the cloud is empty"));
    }
    if let Some(i) = points.iter().position(|p| !p.coords.iter().all(|v| v.is_finite())) {
        return Err(Error::invalid("points", format!("point {i} has a non-finite coordinate")));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Minimum enclosing ball (Welzl)
// ---------------------------------------------------------------------------------------------

/// The smallest ball through two points (diameter).
fn ball2(a: &Point3, b: &Point3) -> BoundingSphere {
    BoundingSphere { center: nalgebra::center(a, b), radius: 0.5 * (a - b).norm() }
}

/// The smallest ball with three points on its boundary: the circumcircle in their plane
/// (`None` when they are collinear).
fn ball3(a: &Point3, b: &Point3, c: &Point3) -> Option<BoundingSphere> {
    let (u, v) = (b - a, c - a);
    let n = u.cross(&v);
    let nn = n.norm_squared();
    if nn <= 1e-30 * u.norm_squared() * v.norm_squared() || nn == 0.0 {
        return None;
    }
    let off = (v * u.norm_squared() - u * v.norm_squared()).cross(&n) / (2.0 * nn);
    let center = a + off;
    Some(BoundingSphere { center, radius: off.norm().max((b - center).norm()).max((c - center).norm()) })
}

/// The ball with four points on its boundary (`None` when they are coplanar).
fn ball4(a: &Point3, b: &Point3, c: &Point3, d: &Point3) -> Option<BoundingSphere> {
    let m = Matrix3::from_rows(&[(b - a).transpose(), (c - a).transpose(), (d - a).transpose()]);
    let rhs = 0.5 * Vector3::new((b - a).norm_squared(), (c - a).norm_squared(), (d - a).norm_squared());
    let off = m.lu().solve(&rhs)?;
    if !off.iter().all(|v| v.is_finite()) {
        return None;
    }
    let center = a + off;
    let r = [a, b, c, d].iter().map(|p| (*p - center).norm()).fold(0.0, Real::max);
    Some(BoundingSphere { center, radius: r })
}

/// The smallest ball containing a few points (≤ 4), by trying every support set: the fallback
/// for near-degenerate support sets in Welzl's recursion.
fn ball_of_few(pts: &[Point3]) -> BoundingSphere {
    let mut best: Option<BoundingSphere> = None;
    let mut consider = |b: BoundingSphere| {
        if pts.iter().all(|p| b.contains(p)) && best.is_none_or(|x| b.radius < x.radius) {
            best = Some(b);
        }
    };
    let n = pts.len();
    if n == 1 {
        consider(BoundingSphere { center: pts[0], radius: 0.0 });
    }
    for i in 0..n {
        for j in i + 1..n {
            consider(ball2(&pts[i], &pts[j]));
            for k in j + 1..n {
                if let Some(b) = ball3(&pts[i], &pts[j], &pts[k]) {
                    consider(b);
                }
                for l in k + 1..n {
                    if let Some(b) = ball4(&pts[i], &pts[j], &pts[k], &pts[l]) {
                        consider(b);
                    }
                }
            }
        }
    }
    best.unwrap_or_else(|| {
        // Only reachable for non-finite input (rejected earlier): a ball around the first point
        // through the farthest one.
        let r = pts.iter().map(|p| (p - pts[0]).norm()).fold(0.0, Real::max);
        BoundingSphere { center: pts[0], radius: r }
    })
}

/// The minimum enclosing ball of `points`, exact up to rounding (Welzl's randomized incremental
/// algorithm, expected linear time; the points are shuffled with a `ChaCha8` stream seeded by
/// `seed`, so the result is reproducible). Pass hull vertices for speed: the ball only depends on
/// them.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` when empty or not finite.
pub fn min_enclosing_ball(points: &[Point3], seed: u64) -> Result<BoundingSphere> {
    check_points(points)?;
    let mut pts = points.to_vec();
    pts.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    let mut ball = BoundingSphere { center: pts[0], radius: 0.0 };
    for i in 1..pts.len() {
        if ball.contains_strict(&pts[i]) {
            continue;
        }
        // pts[i] is on the boundary of the ball of pts[..=i].
        let q1 = pts[i];
        ball = BoundingSphere { center: q1, radius: 0.0 };
        for j in 0..i {
            if ball.contains_strict(&pts[j]) {
                continue;
            }
            let q2 = pts[j];
            ball = ball2(&q1, &q2);
            for k in 0..j {
                if ball.contains_strict(&pts[k]) {
                    continue;
                }
                let q3 = pts[k];
                ball = ball3(&q1, &q2, &q3).unwrap_or_else(|| ball_of_few(&[q1, q2, q3]));
                for &q4 in pts.iter().take(k) {
                    if ball.contains_strict(&q4) {
                        continue;
                    }
                    ball = ball4(&q1, &q2, &q3, &q4)
                        .filter(|b| b.radius.is_finite())
                        .unwrap_or_else(|| ball_of_few(&[q1, q2, q3, q4]));
                }
            }
        }
    }
    // Rounding can leave a point a few ulps outside; grow the radius to cover every point.
    let r = points.iter().map(|p| (p - ball.center).norm()).fold(ball.radius, Real::max);
    Ok(BoundingSphere { center: ball.center, radius: r })
}

// ---------------------------------------------------------------------------------------------
// Oriented boxes
// ---------------------------------------------------------------------------------------------

/// The axis-aligned box of `points` in their own coordinates.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` when empty or not finite.
pub fn axis_aligned_box(points: &[Point3]) -> Result<OrientedBox> {
    check_points(points)?;
    Ok(OrientedBox::fit([Vector3::x(), Vector3::y(), Vector3::z()], points))
}

/// Andrew's monotone chain: indices of the 2-D convex hull, counter-clockwise.
fn hull_2d(p: &[(Real, Real)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..p.len()).collect();
    idx.sort_by(|&a, &b| p[a].0.total_cmp(&p[b].0).then(p[a].1.total_cmp(&p[b].1)));
    let cross =
        |o: usize, a: usize, b: usize| (p[a].0 - p[o].0) * (p[b].1 - p[o].1) - (p[a].1 - p[o].1) * (p[b].0 - p[o].0);
    let mut h: Vec<usize> = Vec::with_capacity(2 * idx.len());
    for &i in idx.iter() {
        while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], i) <= 0.0 {
            h.pop();
        }
        h.push(i);
    }
    let lower = h.len() + 1;
    for &i in idx.iter().rev().skip(1) {
        while h.len() >= lower && cross(h[h.len() - 2], h[h.len() - 1], i) <= 0.0 {
            h.pop();
        }
        h.push(i);
    }
    h.pop();
    h
}

/// For a unit axis `n`, the best box with `n` as one axis: the minimum-area rectangle of the
/// projection (one side along an edge of the projected hull).
fn best_box_around_axis(n: &Vector3, points: &[Point3]) -> OrientedBox {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let e1 = n.cross(&helper).normalize();
    let e2 = n.cross(&e1);
    let proj: Vec<(Real, Real)> = points.iter().map(|p| (e1.dot(&p.coords), e2.dot(&p.coords))).collect();
    let h = hull_2d(&proj);
    let mut best = (Real::INFINITY, e1, e2);
    for w in 0..h.len() {
        let (a, b) = (proj[h[w]], proj[h[(w + 1) % h.len()]]);
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len = dx.hypot(dy);
        if len <= 0.0 {
            continue;
        }
        let (c, s) = (dx / len, dy / len);
        let (mut lo1, mut hi1, mut lo2, mut hi2) =
            (Real::INFINITY, Real::NEG_INFINITY, Real::INFINITY, Real::NEG_INFINITY);
        for &i in &h {
            let (x, y) = proj[i];
            let (u, v) = (c * x + s * y, -s * x + c * y);
            lo1 = lo1.min(u);
            hi1 = hi1.max(u);
            lo2 = lo2.min(v);
            hi2 = hi2.max(v);
        }
        let area = (hi1 - lo1) * (hi2 - lo2);
        if area < best.0 {
            best = (area, e1 * c + e2 * s, -e1 * s + e2 * c);
        }
    }
    let (a0, a1) = (best.1, best.2);
    OrientedBox::fit([a0, a1, a0.cross(&a1)], points)
}

/// The minimum-volume oriented bounding box of a hull (see the module docs for the search).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for an empty hull.
pub fn min_volume_obb(hull: &Hull) -> Result<OrientedBox> {
    check_points(&hull.vertices)?;
    let v = &hull.vertices;
    // Distinct face normals (coplanar triangles share one).
    let mut normals: Vec<Vector3> = Vec::new();
    for t in &hull.triangles {
        let (a, b, c) = (v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]);
        let n = (b - a).cross(&(c - a));
        let len = n.norm();
        if len <= 0.0 || !len.is_finite() {
            continue;
        }
        let n = n / len;
        if !normals.iter().any(|m| m.dot(&n).abs() > 1.0 - 1e-10) {
            normals.push(n);
        }
    }
    normals.extend([Vector3::x(), Vector3::y(), Vector3::z()]);
    let mut best = OrientedBox::fit([Vector3::x(), Vector3::y(), Vector3::z()], v);
    for n in &normals {
        let b = best_box_around_axis(n, v);
        if b.volume() < best.volume() {
            best = b;
        }
    }
    Ok(refine_obb(best, v))
}

/// Pattern search over small rotations of the box axes: try ± rotations about each box axis by
/// an angle that halves whenever no trial improves the volume.
fn refine_obb(mut best: OrientedBox, points: &[Point3]) -> OrientedBox {
    let mut angle: Real = 0.05;
    while angle > 1e-7 {
        let mut improved = false;
        for k in 0..3 {
            for sign in [-1.0, 1.0] {
                let rot =
                    nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(best.axes[k]), sign * angle);
                let axes = [rot * best.axes[0], rot * best.axes[1], rot * best.axes[2]];
                let trial = OrientedBox::fit(axes, points);
                if trial.volume() < best.volume() * (1.0 - 1e-12) {
                    best = trial;
                    improved = true;
                }
            }
        }
        if !improved {
            angle *= 0.5;
        }
    }
    best
}

// ---------------------------------------------------------------------------------------------
// Minimum-volume enclosing ellipsoid (Khachiyan)
// ---------------------------------------------------------------------------------------------

/// Weighted mean and covariance Σ(u) = Σ uᵢ xᵢxᵢᵀ − x̄x̄ᵀ.
fn moments(points: &[Vector3], u: &[Real]) -> (Vector3, Matrix3) {
    let mut mean = Vector3::zeros();
    let mut second = Matrix3::zeros();
    for (x, &w) in points.iter().zip(u) {
        mean += x * w;
        second += x * x.transpose() * w;
    }
    (mean, second - mean * mean.transpose())
}

/// The minimum-volume enclosing ellipsoid of `points` by Khachiyan's algorithm (Todd–Yildirim
/// variant with away steps) on the lifted points qᵢ = (xᵢ, 1), run until the relative duality
/// gap of the volume is below `tolerance` (or `max_iterations`).
///
/// The returned ellipsoid is the one of the final weights u (center x̄, shape Σ(u)⁻¹/3), scaled so
/// that the farthest point lies on its boundary: it contains every point. Its volume is an upper
/// bound; `lower_bound` = (4π/3)·3^{3/2}·det Σ(u)^{1/2} is a lower bound on the volume of every
/// ellipsoid that contains the points (weak duality: for {(x − c)ᵀH(x − c) ≤ 3} containing the
/// points, tr(HΣ(u)) ≤ 3, so det H · det Σ(u) ≤ 1 by AM–GM). Pass hull vertices for speed.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` for fewer than 4 points, non-finite or flat clouds,
/// or naming `tolerance` unless it is in (0, 1).
pub fn mvee_khachiyan(points: &[Point3], tolerance: Real, max_iterations: usize) -> Result<Mvee> {
    check_points(points)?;
    if points.len() < 4 {
        return Err(Error::invalid("points", "need at least 4 points"));
    }
    if !(tolerance > 0.0 && tolerance < 1.0) {
        return Err(Error::invalid("tolerance", format!("must be in (0, 1), got {tolerance}")));
    }
    // Center and scale for conditioning; volumes scale back by s³.
    let n = points.len();
    let c0 = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n as Real;
    let s = points.iter().map(|p| (p.coords - c0).norm()).fold(0.0, Real::max);
    if s.is_nan() || s <= 0.0 {
        return Err(Error::invalid("points", "all points coincide"));
    }
    let x: Vec<Vector3> = points.iter().map(|p| (p.coords - c0) / s).collect();
    let mut u = vec![1.0 / n as Real; n];
    let dim: Real = 3.0;
    let mut iterations = 0;
    let mut m = vec![0.0; n];
    let (mut upper, mut lower);
    loop {
        let (mean, cov) = moments(&x, &u);
        let chol = nalgebra::Cholesky::new(cov)
            .ok_or_else(|| Error::invalid("points", "the points are coplanar: no ellipsoid with interior"))?;
        let inv = chol.inverse();
        // mᵢ = (xᵢ − x̄)ᵀ Σ⁻¹ (xᵢ − x̄) + 1 = q_iᵀ X(u)⁻¹ q_i of the lifted points.
        for (mi, xi) in m.iter_mut().zip(&x) {
            let d = xi - mean;
            *mi = d.dot(&(inv * d)) + 1.0;
        }
        let (j_max, &m_max) = m.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap_or((0, &0.0));
        // Feasible ellipsoid: (x − x̄)ᵀ Σ⁻¹ (x − x̄) ≤ m_max − 1.
        let det = cov.determinant();
        let unit_ball = 4.0 / 3.0 * std::f64::consts::PI;
        upper = unit_ball * (det * (m_max - 1.0).powi(3)).sqrt();
        lower = unit_ball * (det * dim.powi(3)).sqrt();
        if upper / lower - 1.0 <= tolerance || iterations >= max_iterations {
            let shape = inv / (m_max - 1.0) / (s * s);
            let center = Point3::from(c0 + mean * s);
            let s3 = s.powi(3);
            return Ok(Mvee {
                ellipsoid: Ellipsoid { center, shape },
                volume: upper * s3,
                lower_bound: lower * s3,
                iterations,
            });
        }
        iterations += 1;
        let d1 = dim + 1.0;
        // Away step candidate: the supported point with the smallest mᵢ.
        let (j_min, m_min) = m
            .iter()
            .enumerate()
            .filter(|(i, _)| u[*i] > 0.0)
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, v)| (i, *v))
            .unwrap_or((j_max, m_max));
        if m_max - d1 >= d1 - m_min || u[j_min] <= 0.0 {
            // Khachiyan's step toward the point of largest mᵢ.
            let step = (m_max - d1) / (d1 * (m_max - 1.0));
            u.iter_mut().for_each(|w| *w *= 1.0 - step);
            u[j_max] += step;
        } else {
            // Away step from the supported point of smallest mᵢ, clipped to keep u ≥ 0.
            let uj = u[j_min];
            let step = ((d1 - m_min) / (d1 * (m_min - 1.0))).min(uj / (1.0 - uj));
            u.iter_mut().for_each(|w| *w *= 1.0 + step);
            u[j_min] -= step;
            if u[j_min] < 1e-300 {
                u[j_min] = 0.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    fn rng(seed: u64) -> rand_chacha::ChaCha8Rng {
        rand_chacha::ChaCha8Rng::seed_from_u64(seed)
    }

    /// The minimum ball by brute force: the smallest of all balls spanned by 1–4 points that
    /// contains every point.
    fn brute_force_ball(pts: &[Point3]) -> Real {
        let mut best = Real::INFINITY;
        let n = pts.len();
        let mut consider = |b: Option<BoundingSphere>| {
            if let Some(b) = b {
                if pts.iter().all(|p| (p - b.center).norm() <= b.radius * (1.0 + 1e-9)) {
                    best = best.min(b.radius);
                }
            }
        };
        for i in 0..n {
            for j in i + 1..n {
                consider(Some(ball2(&pts[i], &pts[j])));
                for k in j + 1..n {
                    consider(ball3(&pts[i], &pts[j], &pts[k]));
                    for l in k + 1..n {
                        consider(ball4(&pts[i], &pts[j], &pts[k], &pts[l]));
                    }
                }
            }
        }
        best
    }

    #[test]
    fn welzl_matches_brute_force_on_random_clouds() {
        let mut r = rng(3);
        for trial in 0..30 {
            let n = 5 + trial % 10;
            let pts: Vec<Point3> = (0..n)
                .map(|_| Point3::new(r.random_range(-1.0..1.0), r.random_range(-2.0..2.0), r.random_range(-0.5..0.5)))
                .collect();
            let b = min_enclosing_ball(&pts, trial as u64).unwrap();
            let brute = brute_force_ball(&pts);
            assert!((b.radius - brute).abs() < 1e-9 * brute, "trial {trial}: welzl {} brute {brute}", b.radius);
            assert!(pts.iter().all(|p| b.contains(p)));
        }
    }

    #[test]
    fn ball_of_regular_simplex_and_cube_corners() {
        // Regular tetrahedron with vertices (±1, ±1, ±1), even parity: circumradius √3.
        let tet = [
            Point3::new(1.0, 1.0, 1.0),
            Point3::new(1.0, -1.0, -1.0),
            Point3::new(-1.0, 1.0, -1.0),
            Point3::new(-1.0, -1.0, 1.0),
        ];
        let b = min_enclosing_ball(&tet, 1).unwrap();
        assert!((b.radius - 3f64.sqrt()).abs() < 1e-12, "{}", b.radius);
        assert!(b.center.coords.norm() < 1e-12);
        // Cube [2, 4]³ corners plus interior points: radius √3, center (3, 3, 3).
        let mut cube: Vec<Point3> = (0..8)
            .map(|i| {
                Point3::new(
                    2.0 + 2.0 * (i & 1) as Real,
                    2.0 + 2.0 * ((i >> 1) & 1) as Real,
                    2.0 + 2.0 * (i >> 2) as Real,
                )
            })
            .collect();
        cube.push(Point3::new(3.0, 3.5, 2.5));
        for seed in 0..5 {
            let b = min_enclosing_ball(&cube, seed).unwrap();
            assert!((b.radius - 3f64.sqrt()).abs() < 1e-12, "{}", b.radius);
            assert!((b.center - Point3::new(3.0, 3.0, 3.0)).norm() < 1e-12);
        }
    }

    fn rotation(seed: u64) -> Matrix3 {
        let mut r = rng(seed);
        let axis = Vector3::new(r.random_range(-1.0..1.0), r.random_range(-1.0..1.0), r.random_range(-1.0..1.0));
        *nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), r.random_range(0.3..2.5)).matrix()
    }

    #[test]
    fn obb_of_a_rotated_cuboid_is_the_cuboid() {
        let half = Vector3::new(1.5, 0.7, 0.3);
        let rot = rotation(11);
        let t = Vector3::new(0.4, -2.0, 1.0);
        let mut pts: Vec<Point3> = (0..8)
            .map(|i| {
                let s = Vector3::new(
                    if i & 1 == 0 { -1.0 } else { 1.0 },
                    if i & 2 == 0 { -1.0 } else { 1.0 },
                    if i & 4 == 0 { -1.0 } else { 1.0 },
                );
                Point3::from(rot * half.component_mul(&s) + t)
            })
            .collect();
        let mut r = rng(5);
        for _ in 0..50 {
            let y = Vector3::new(r.random_range(-1.0..1.0), r.random_range(-1.0..1.0), r.random_range(-1.0..1.0));
            pts.push(Point3::from(rot * half.component_mul(&y) + t));
        }
        let hull = convex_hull(&pts).unwrap();
        let obb = min_volume_obb(&hull).unwrap();
        assert!((obb.volume() - 8.0 * 1.5 * 0.7 * 0.3).abs() < 1e-9, "{}", obb.volume());
        assert!((obb.center.coords - t).norm() < 1e-9);
        // Each box axis is (up to sign) a column of the rotation, with the matching extent.
        let mut ext: Vec<Real> = obb.half_extents.iter().copied().collect();
        ext.sort_by(|a, b| a.total_cmp(b));
        assert!((ext[0] - 0.3).abs() < 1e-9 && (ext[1] - 0.7).abs() < 1e-9 && (ext[2] - 1.5).abs() < 1e-9);
        for k in 0..3 {
            let col = rot.column(k).into_owned();
            assert!(obb.axes.iter().any(|a| a.dot(&col).abs() > 1.0 - 1e-9), "axis {k} not recovered");
        }
        assert!(pts.iter().all(|p| obb.contains(p)));
        // The axis-aligned box of the same points is bigger.
        assert!(axis_aligned_box(&pts).unwrap().volume() > obb.volume() * 1.5);
    }

    #[test]
    fn obb_of_a_cube_is_the_cube() {
        let pts: Vec<Point3> =
            (0..8).map(|i| Point3::new((i & 1) as Real, ((i >> 1) & 1) as Real, (i >> 2) as Real)).collect();
        let obb = min_volume_obb(&convex_hull(&pts).unwrap()).unwrap();
        assert!((obb.volume() - 1.0).abs() < 1e-12, "{}", obb.volume());
        assert!((obb.center - Point3::new(0.5, 0.5, 0.5)).norm() < 1e-12);
    }

    #[test]
    fn khachiyan_mvee_of_an_ellipsoid_cloud_is_the_ellipsoid() {
        let (a, b, c) = (2.0, 1.0, 0.5);
        let rot = rotation(21);
        let t = Vector3::new(1.0, 2.0, -3.0);
        let mut r = rng(8);
        let mut pts = Vec::new();
        for i in 0..400 {
            let g = Vector3::new(r.random_range(-1.0..1.0), r.random_range(-1.0..1.0), r.random_range(-1.0..1.0));
            // Surface points, and a few interior ones.
            let y = if i % 4 == 0 { g * 0.5 } else { g.normalize() };
            pts.push(Point3::from(rot * Vector3::new(a * y.x, b * y.y, c * y.z) + t));
        }
        let e = mvee_khachiyan(&pts, 1e-7, 100_000).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * a * b * c;
        assert!(e.relative_gap() <= 1e-7, "gap {}", e.relative_gap());
        assert!(e.lower_bound <= exact * (1.0 + 1e-12) && exact <= e.volume * (1.0 + 1e-12));
        assert!((e.volume - exact).abs() < 1e-4 * exact, "{} vs {exact}", e.volume);
        assert!((e.ellipsoid.center.coords - t).norm() < 1e-4);
        assert!(pts.iter().all(|p| e.ellipsoid.contains(p)));
    }

    #[test]
    fn bad_input_is_rejected_by_field() {
        let field = |r: Result<Mvee>| match r {
            Err(Error::InvalidArgument { field, .. }) => field,
            other => panic!("expected InvalidArgument, got {other:?}"),
        };
        let pts: Vec<Point3> = (0..6).map(|i| Point3::new(i as Real, (i * i) as Real, 0.0)).collect();
        assert_eq!(field(mvee_khachiyan(&pts, 1e-6, 100)), "points");
        assert_eq!(field(mvee_khachiyan(&pts, 0.0, 100)), "tolerance");
        assert_eq!(field(mvee_khachiyan(&[], 1e-6, 100)), "points");
        assert!(min_enclosing_ball(&[Point3::new(Real::NAN, 0.0, 0.0)], 1).is_err());
    }
}
