//! The radial function of a sublevel set seen from an interior point, tabulated once per body: the
//! cold starts of the query solvers read boundary points off it instead of searching along a ray
//! at query time.
//!
//! A convex body {u : p(u) ≤ 1} with an interior point c is star-shaped about c, so every ray
//! c + s·ω (‖ω‖ = 1) leaves it exactly once, at s = r(ω):
//!
//! ```text
//! r(ω) = the s > 0 with p(c + s ω) = 1
//! ```
//!
//! [`RadialTable`] samples r on a cube map: the direction ω is projected on the cube [−1, 1]³
//! (the face of its largest coordinate, face coordinates (a, b) ∈ [−1, 1]²), each face carries a
//! (G + 1) × (G + 1) grid of nodes ([`RADIAL_GRID`] = G), and [`RadialTable::radius`] interpolates
//! bilinearly between the four nodes around (a, b). The boundary point read off the table is
//! within a few percent of the boundary (4.3 % in radius at worst on a 3:1 ellipsoid), which is all a Newton start
//! needs: the KKT iterations make the constraint exact, and the measured iteration counts of the
//! cold queries are the same as from boundary points exact to 10⁻⁴.
//!
//! Rays are solved by `ray_crossing`: safeguarded Newton (bracketed by bisection) on the gauge
//! s ↦ p(c + s·v)^(1/2d) − 1, nearly linear along rays for a polynomial dominated by its top form.
//! For a nonconvex body (relaxed convexity) the table holds the first crossing the search brackets;
//! it is still only a start.

use super::FastPoly;
use crate::math::{Real, Vector3};

/// Grid cells per cube-face side G of a [`RadialTable`] ((G + 1)² nodes per face, 6 faces).
pub const RADIAL_GRID: usize = 8;

const NODES: usize = RADIAL_GRID + 1;

/// The radial function r(ω) of {p ≤ 1} about an interior point, on a cube map (see the module
/// docs); normalized units (the body's polynomial coordinates).
#[derive(Clone, Debug, PartialEq)]
pub struct RadialTable {
    /// r at the nodes: face-major, then row (b), then column (a).
    radius: Box<[[Real; NODES * NODES]; 6]>,
}

/// Face and face coordinates (a, b) ∈ [−1, 1]² of a direction: faces +x, −x, +y, −y, +z, −z; the
/// face coordinates are the other two components (in cyclic order) over the largest one's modulus.
#[inline(always)]
pub(super) fn face_coordinates(v: &Vector3) -> (usize, Real, Real) {
    let (ax, ay, az) = (v.x.abs(), v.y.abs(), v.z.abs());
    if ax >= ay && ax >= az {
        (usize::from(v.x < 0.0), v.y / ax, v.z / ax)
    } else if ay >= az {
        (2 + usize::from(v.y < 0.0), v.z / ay, v.x / ay)
    } else {
        (4 + usize::from(v.z < 0.0), v.x / az, v.y / az)
    }
}

/// The (unnormalized) direction of node `k = j·(grid + 1) + i` of a cube map with `grid` cells per
/// face side, on `face`: face coordinates a = −1 + 2i/grid, b = −1 + 2j/grid ([`face_direction`]).
pub(super) fn node_direction(face: usize, k: usize, grid: usize) -> Vector3 {
    let (i, j) = (k % (grid + 1), k / (grid + 1));
    face_direction(face, -1.0 + 2.0 * i as Real / grid as Real, -1.0 + 2.0 * j as Real / grid as Real)
}

/// The (unnormalized) direction of face coordinates (a, b) on `face`; inverse of
/// [`face_coordinates`] up to a positive factor.
pub(super) fn face_direction(face: usize, a: Real, b: Real) -> Vector3 {
    let s = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    match face / 2 {
        0 => Vector3::new(s, a, b),
        1 => Vector3::new(b, s, a),
        _ => Vector3::new(a, b, s),
    }
}

impl RadialTable {
    /// The radii at the nodes, face-major (node `k = j·(G + 1) + i` of face f at `[f][k]`, G =
    /// [`RADIAL_GRID`]): the four-lane look-ups of the batch solvers read them directly
    /// (`sublevel_query::batch`; same cells and interpolation as [`Self::radius`]).
    pub fn nodes(&self) -> &[[Real; NODES * NODES]; 6] {
        &self.radius
    }

    /// Tabulates the radial function of {p ≤ 1} about `center` (normalized coordinates, with
    /// p(center) < 1): 6·(G + 1)² ray solves to |p − 1| ≤ 10⁻⁸.
    pub fn new(p: &FastPoly, center: &Vector3) -> Self {
        let mut radius = Box::new([[0.0; NODES * NODES]; 6]);
        for (face, nodes) in radius.iter_mut().enumerate() {
            for (k, r) in nodes.iter_mut().enumerate() {
                let dir = node_direction(face, k, RADIAL_GRID).normalize();
                *r = ray_radius(p, center, &dir);
            }
        }
        Self { radius }
    }

    /// r along the direction of `v` (any nonzero length; normalized units): bilinear
    /// interpolation on the cube map. Returns 0 for a zero or non-finite `v`.
    #[inline(always)]
    pub fn radius(&self, v: &Vector3) -> Real {
        let (face, a, b) = face_coordinates(v);
        if !(a.is_finite() && b.is_finite()) {
            return 0.0;
        }
        let half = 0.5 * RADIAL_GRID as Real;
        let (fa, fb) = ((a + 1.0) * half, (b + 1.0) * half);
        let (i, j) = ((fa as usize).min(RADIAL_GRID - 1), (fb as usize).min(RADIAL_GRID - 1));
        let (ta, tb) = (fa - i as Real, fb - j as Real);
        let r = &self.radius[face];
        let k = j * NODES + i;
        let low = r[k] + (r[k + 1] - r[k]) * ta;
        let high = r[k + NODES] + (r[k + NODES + 1] - r[k + NODES]) * ta;
        low + (high - low) * tb
    }
}

/// Distance from `center` to the boundary along the unit direction `dir`: the ray is extended by
/// doubling until it leaves the body (up to 2²⁰ normalized units, returned as is when it never
/// does), then solved by [`ray_crossing`].
fn ray_radius(p: &FastPoly, center: &Vector3, dir: &Vector3) -> Real {
    let mut reach = 1.0;
    while p.value(&(center + dir * reach)) <= 1.0 {
        reach *= 2.0;
        if reach > 1048576.0 {
            return reach;
        }
    }
    reach * ray_crossing(p, center, &(dir * reach), 1e-8)
}

/// The s ∈ [0, 1] where the segment `inside + s·dir` crosses p = 1, to |p − 1| ≤ `tolerance`,
/// for p(inside) < 1 < p(inside + dir) (normalized coordinates).
///
/// Safeguarded Newton (bracketed by bisection) on the gauge s ↦ p(inside + s·dir)^(1/2d) − 1
/// rather than on p − 1: for a polynomial dominated by its top-degree form the gauge is nearly
/// linear along the segment, so from a far outside point Newton lands near the boundary in one or
/// two steps, where Newton on p itself would shrink s only by a factor ≈ 1 − 1/(2d) per step.
pub fn ray_crossing(p: &FastPoly, inside: &Vector3, dir: &Vector3, tolerance: Real) -> Real {
    let inv_degree = 1.0 / p.degree().max(1) as Real;
    let (mut lo, mut hi) = (0.0, 1.0);
    let mut s = 1.0;
    for _ in 0..100 {
        let (v, g) = p.value_gradient(&(inside + dir * s));
        let r = v - 1.0;
        if r.abs() <= tolerance {
            break;
        }
        if r > 0.0 {
            hi = s;
        } else {
            lo = s;
        }
        let slope = g.dot(dir);
        let mut next = if slope > 0.0 && v > 0.0 {
            // Newton on φ = v^(1/2d): s − (φ − 1)/φ', φ' = φ·slope/(2d·v).
            let phi = v.powf(inv_degree);
            s - (phi - 1.0) * v / (inv_degree * phi * slope)
        } else {
            0.5 * (lo + hi)
        };
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - s).abs() < 1e-16 {
            s = next;
            break;
        }
        s = next;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poly::Polynomial;
    use rand::{Rng, SeedableRng};

    /// The ellipsoid p(u) = Σ (uᵢ/rᵢ)²: r(ω) = 1/√(Σ (ωᵢ/rᵢ)²) in closed form.
    fn ellipsoid(radii: [Real; 3]) -> FastPoly {
        let terms: Vec<([u8; 3], Real)> = (0..3)
            .map(|i| {
                let mut e = [0u8; 3];
                e[i] = 2;
                (e, 1.0 / (radii[i] * radii[i]))
            })
            .collect();
        Polynomial::from_terms(2, &terms).unwrap().fast()
    }

    #[test]
    fn face_coordinates_invert_face_directions() {
        for face in 0..6 {
            for (a, b) in [(0.0, 0.0), (0.5, -0.25), (-0.99, 0.98), (0.9, 0.99)] {
                let (f, a2, b2) = face_coordinates(&(face_direction(face, a, b) * 3.0));
                assert_eq!(f, face);
                assert!((a - a2).abs() < 1e-15 && (b - b2).abs() < 1e-15, "face {face}: ({a}, {b})");
            }
        }
    }

    #[test]
    fn ellipsoid_radius_matches_closed_form_within_interpolation_error() {
        let radii = [0.9, 0.5, 0.3];
        let table = RadialTable::new(&ellipsoid(radii), &Vector3::zeros());
        let exact = |w: &Vector3| 1.0 / (0..3).map(|i| (w[i] / radii[i]).powi(2)).sum::<Real>().sqrt();
        // Nodes are exact to the ray tolerance (|p − 1| ≤ 1e-8, so r to 1e-8 relative).
        for face in 0..6 {
            let w = face_direction(face, 0.25, -0.5).normalize();
            assert!((table.radius(&w) - exact(&w)).abs() <= 1e-8 * exact(&w));
        }
        // Between nodes: bilinear interpolation, within 5 % on this 3:1 ellipsoid (the largest
        // error, near the long axis where r changes fastest, is measured at 4.3 %).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut worst: Real = 0.0;
        for _ in 0..2000 {
            let w = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let (r, e) = (table.radius(&w), exact(&w.normalize()));
            worst = worst.max((r - e).abs() / e);
        }
        assert!(worst <= 0.05, "largest relative error {worst}");
        assert_eq!(table.radius(&Vector3::zeros()), 0.0);
    }

    #[test]
    fn ray_crossing_meets_the_tolerance() {
        let p = ellipsoid([0.9, 0.5, 0.3]);
        let inside = Vector3::new(0.1, 0.0, 0.05);
        let dir = Vector3::new(3.0, -1.0, 2.0);
        let s = ray_crossing(&p, &inside, &dir, 1e-13);
        assert!((p.value(&(inside + dir * s)) - 1.0).abs() <= 1e-13);
        assert!(s > 0.0 && s < 1.0);
    }
}
