//! The polytopes standing in for the noise balls of a cloud's points in the fits and checks of
//! [`super`]: a convex body containing a circumscribing polytope's vertices contains the ball.

use crate::{Error, Result};
use sublevel_core::body::Body;
use sublevel_core::math::{Point3, Real, Vector3};

/// Relative outward push of every cover vertex (one part in 10⁹ of the noise radius): the
/// rounding of `p + offset` then never lands a vertex inside the exact circumscribed polytope.
pub const COVER_SLACK: Real = 1e-9;

/// A polytope circumscribing a ball, whose vertices stand in for the ball in fits and
/// containment checks: a convex body containing the vertices contains the polytope, so the ball.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BallCover {
    /// The cube `p + r·[−1, 1]³`: 8 corners at distance r√3 ≈ 1.73 r.
    #[default]
    Cube,
    /// The regular icosahedron with inradius r (faces tangent to the ball): 12 vertices at
    /// distance 1.258 r, a tighter cover for 1.5 × the vertices.
    Icosahedron,
}

impl BallCover {
    /// The cover's name (`"cube"`, `"icosahedron"`).
    pub fn name(&self) -> &'static str {
        match self {
            BallCover::Cube => "cube",
            BallCover::Icosahedron => "icosahedron",
        }
    }

    /// Distance of the vertices from the ball's center over its radius (√3; √3·√(φ² + 1)/φ² ≈ 1.258).
    pub fn reach(&self) -> Real {
        let v = self.unit_vertices();
        v[0].norm() * self.unit_scale()
    }

    /// Vertices of the unit polytope before scaling (cube corners; icosahedron (0, ±1, ±φ) and
    /// its cyclic permutations).
    fn unit_vertices(&self) -> Vec<Vector3> {
        match self {
            BallCover::Cube => (0..8)
                .map(|k| {
                    let s = |b: usize| if k & b == 0 { -1.0 } else { 1.0 };
                    Vector3::new(s(1), s(2), s(4))
                })
                .collect(),
            BallCover::Icosahedron => {
                let phi = (1.0 + Real::sqrt(5.0)) / 2.0;
                let mut v = Vec::with_capacity(12);
                for a in [-1.0, 1.0] {
                    for b in [-phi, phi] {
                        v.push(Vector3::new(0.0, a, b));
                        v.push(Vector3::new(a, b, 0.0));
                        v.push(Vector3::new(b, 0.0, a));
                    }
                }
                v
            }
        }
    }

    /// Scale from the unit polytope to inradius 1: the cube's inradius is 1, the unit
    /// icosahedron's φ²/√3.
    fn unit_scale(&self) -> Real {
        match self {
            BallCover::Cube => 1.0,
            BallCover::Icosahedron => {
                let phi = (1.0 + Real::sqrt(5.0)) / 2.0;
                Real::sqrt(3.0) / (phi * phi)
            }
        }
    }

    /// Vertex offsets of the polytope circumscribing the ball of radius `radius` (meters) about
    /// the origin, pushed out by [`COVER_SLACK`]: `p + offset` for every offset are the vertices
    /// standing in for B(p, radius).
    pub fn offsets(&self, radius: Real) -> Vec<Vector3> {
        let s = radius * self.unit_scale() * (1.0 + COVER_SLACK);
        self.unit_vertices().into_iter().map(|v| v * s).collect()
    }

    /// The cover vertices of the balls of radius `radius` about `points[indices]`: each point's
    /// offsets ([`BallCover::offsets`]) added to it, point by point.
    pub fn vertices(&self, points: &[[Real; 3]], indices: &[usize], radius: Real) -> Vec<Point3> {
        let offsets = self.offsets(radius);
        let mut out = Vec::with_capacity(indices.len() * offsets.len());
        for &i in indices {
            let p = Vector3::from(points[i]);
            out.extend(offsets.iter().map(|o| Point3::from(p + o)));
        }
        out
    }
}

/// Largest value of the body's p at the cover vertices of the balls B(p_i, `radius`),
/// i in `indices`: the body contains every one of those balls when it is ≤ 1 (the body is
/// convex). With `stop_above`, returns as soon as a value exceeds it. −∞ for no points.
pub fn max_cover_value(
    body: &Body,
    points: &[[Real; 3]],
    indices: &[usize],
    radius: Real,
    cover: BallCover,
    stop_above: Option<Real>,
) -> Real {
    let offsets = cover.offsets(radius);
    let limit = stop_above.unwrap_or(Real::INFINITY);
    let mut worst = Real::NEG_INFINITY;
    for &i in indices {
        let p = Vector3::from(points[i]);
        for o in &offsets {
            worst = worst.max(body.value_at(&Point3::from(p + o)));
            if worst > limit {
                return worst;
            }
        }
    }
    worst
}

/// Volume of the convex hull of the balls B(p_i, `radius`) (cubic meters), exactly, by Steiner's
/// formula for the hull K of the centers: V(K) + A(K)·r + (r²/2)·Σ_edges ℓ_e·ψ_e + (4/3)πr³, ψ_e
/// the angle between the outward normals of the faces at edge e. Every convex body containing
/// the balls holds at least this volume: the denominator of a body's tightness.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points` when the centers have no 3-d hull (fewer than 4,
/// coplanar, or parry's hull fails).
pub fn ball_hull_volume(points: &[Point3], radius: Real) -> Result<Real> {
    let pts: Vec<parry3d_f64::math::Vector3> =
        points.iter().map(|p| parry3d_f64::math::Vector3::new(p.x, p.y, p.z)).collect();
    let hull = std::panic::catch_unwind(|| parry3d_f64::transformation::try_convex_hull(&pts));
    let (verts, tris) = match hull {
        Ok(Ok(h)) if h.1.len() >= 4 => h,
        _ => return Err(Error::invalid("points", "the centers have no 3-d convex hull")),
    };
    let v: Vec<Vector3> = verts.iter().map(|p| Vector3::new(p.x, p.y, p.z)).collect();
    let o = v.iter().fold(Vector3::zeros(), |a, p| a + p) / v.len() as Real;
    let mut volume = 0.0;
    let mut area = 0.0;
    let mut normals = Vec::with_capacity(tris.len());
    let mut edges = std::collections::HashMap::new();
    for (f, t) in tris.iter().enumerate() {
        let (a, b, c) = (v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]);
        let n = (b - a).cross(&(c - a));
        volume += (a - o).dot(&(b - o).cross(&(c - o))) / 6.0;
        area += n.norm() / 2.0;
        normals.push(n.try_normalize(0.0).unwrap_or_else(Vector3::zeros));
        for k in 0..3 {
            let (i, j) = (t[k], t[(k + 1) % 3]);
            edges.entry((i.min(j), i.max(j))).or_insert_with(Vec::new).push(f);
        }
    }
    let mut edge_term = 0.0;
    for ((i, j), faces) in &edges {
        if let [f, g] = faces[..] {
            let angle = normals[f].dot(&normals[g]).clamp(-1.0, 1.0).acos();
            edge_term += (v[*i as usize] - v[*j as usize]).norm() * angle;
        }
    }
    let r = radius;
    Ok(volume.abs() + area * r + 0.5 * r * r * edge_term + 4.0 / 3.0 * std::f64::consts::PI * r.powi(3))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covers_circumscribe_the_ball() {
        for cover in [BallCover::Cube, BallCover::Icosahedron] {
            let r = 0.3;
            let v: Vec<Point3> = cover.offsets(r).into_iter().map(Point3::from).collect();
            let pts: Vec<parry3d_f64::math::Vector3> =
                v.iter().map(|p| parry3d_f64::math::Vector3::new(p.x, p.y, p.z)).collect();
            let (hv, tris) = parry3d_f64::transformation::try_convex_hull(&pts).unwrap();
            assert_eq!(hv.len(), v.len(), "{}", cover.name());
            // Every face's plane lies at distance ≥ r from the center: the ball is inside.
            for t in &tris {
                let [a, b, c] = t.map(|k| Vector3::new(hv[k as usize].x, hv[k as usize].y, hv[k as usize].z));
                let n = (b - a).cross(&(c - a)).normalize();
                let d = n.dot(&a).abs();
                assert!(d >= r && d <= r * (1.0 + 1e-8), "{}: face at {d}", cover.name());
            }
            assert!((v[0].coords.norm() - r * cover.reach()).abs() < 1e-9);
        }
        assert!((BallCover::Cube.reach() - 3f64.sqrt()).abs() < 1e-12);
        assert!((BallCover::Icosahedron.reach() - 1.2584).abs() < 1e-4);
    }

    #[test]
    fn steiner_volume_of_a_cube_of_balls() {
        // The unit cube's corners with r = 0.1: 1 + 6r + 3πr² + (4/3)πr³.
        let pts: Vec<Point3> =
            (0..8).map(|k| Point3::new((k & 1) as Real, ((k >> 1) & 1) as Real, ((k >> 2) & 1) as Real)).collect();
        let r = 0.1;
        let pi = std::f64::consts::PI;
        let exact = 1.0 + 6.0 * r + 3.0 * pi * r * r + 4.0 / 3.0 * pi * r.powi(3);
        assert!((ball_hull_volume(&pts, r).unwrap() - exact).abs() < 1e-12);
        assert!(ball_hull_volume(&pts[..3], r).is_err());
    }
}
