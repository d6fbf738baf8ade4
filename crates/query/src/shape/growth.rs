//! The growth distance of a primitive against a shape.
//!
//! For a sos-convex body the paper's growth measure is `d(p₁‖p₂) = min p₁(x) s.t. p₂(x) ≤ 1`
//! (eq. "overlap"): > 1 apart, = 1 touching, < 1 overlapping. A primitive has several constraints
//! and no one polynomial; its p₁ is its gauge about its center c (Minkowski functional),
//!
//! ```text
//! γ_A(x) = min { t ≥ 0 : x ∈ c + t (A − c) },        d(A‖B) = min_{x ∈ B} γ_A(x),
//! ```
//!
//! the factor by which A must be scaled about its center to touch B: the growth distance of Ong
//! and Gilbert (*Growth distances: new measures for object separation and penetration*, IEEE T-RA
//! 12(6), 1996). It has the body measure's meaning (> 1, = 1, < 1) and its sublevel set
//! `{γ_A ≤ 1}` is A. For a box, γ_A(u) = max_i |u_i| / h_i.
//!
//! It is found from the distance: t ↦ dist(c + t(A − c), B) is convex and decreasing until the
//! scaled A touches B, with derivative `−n·(x_A − c)/t` at the witnesses (the envelope theorem,
//! n the unit normal from A to B). Newton's method on it, started below the root at
//! `t₀ = dist(c, B) / R_A` (the scaled A lies inside the ball of radius t R_A about c), climbs to
//! the root monotonically: each tangent of a convex decreasing function meets zero below the root.

use super::{shape_distance, ShapeRef};
use crate::{Error, Result};
use sublevel_core::math::{Isometry3, Point3, Real};
use sublevel_core::primitive::Primitive;

/// Answer of [`shape_growth`].
#[derive(Clone, Copy, Debug)]
pub struct ShapeGrowth {
    /// d(A‖B) (dimensionless): > 1 apart, = 1 touching, < 1 overlapping; 0 when B holds A's
    /// center.
    pub value: Real,
    /// Where A scaled by `value` about its center touches B (world, meters).
    pub contact: Point3,
    /// Whether Newton's method reached the root (distance of the scaled A to B below 10⁻¹² of
    /// A's size, or steps below 10⁻¹⁴ of the value).
    pub converged: bool,
    /// Newton steps (each one distance query).
    pub iterations: usize,
}

/// A scaled by `t` about its own center (t > 0).
fn scaled(a: &Primitive, t: Real) -> Primitive {
    match *a {
        Primitive::Box { half_extents } => Primitive::Box { half_extents: half_extents * t },
        Primitive::Sphere { radius } => Primitive::Sphere { radius: radius * t },
        Primitive::Cylinder { radius, half_height } => {
            Primitive::Cylinder { radius: radius * t, half_height: half_height * t }
        }
        Primitive::Capsule { radius, half_height } => {
            Primitive::Capsule { radius: radius * t, half_height: half_height * t }
        }
        Primitive::Halfspace { .. } => *a,
    }
}

/// The growth distance d(A‖B) of the bounded primitive `a` posed by `pose_a` against the shape
/// `b` posed by `pose_b` (module docs).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `a` for a halfspace (no center to grow about); the errors of
/// [`shape_distance`].
pub fn shape_growth(a: &Primitive, pose_a: &Isometry3, b: ShapeRef<'_>, pose_b: &Isometry3) -> Result<ShapeGrowth> {
    if !a.is_bounded() {
        return Err(Error::invalid("a", "a halfspace has no center to grow about; grow the other shape"));
    }
    let c = pose_a.translation.vector;
    let size = a.scale();
    // dist(c, B): a point as a vanishing sphere.
    let point = Primitive::Sphere { radius: 1e-300 };
    let d0 = shape_distance(ShapeRef::Primitive(&point), pose_a, b, pose_b, None)?;
    if d0.overlapping {
        return Ok(ShapeGrowth { value: 0.0, contact: Point3::from(c), converged: true, iterations: 0 });
    }
    let mut t = d0.distance / a.bounding_radius();
    let mut contact = d0.witness_b;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < 60 {
        iterations += 1;
        let grown = scaled(a, t);
        let r = shape_distance(ShapeRef::Primitive(&grown), pose_a, b, pose_b, None)?;
        contact = r.witness_a;
        if r.overlapping || r.distance <= 1e-12 * size {
            converged = true;
            break;
        }
        // d'(t) = −n·(x_A − c)/t.
        let slope = r.normal.dot(&(r.witness_a.coords - c)) / t;
        if slope <= 0.0 {
            break;
        }
        let step = r.distance / slope;
        t += step;
        if step <= 1e-14 * t {
            converged = true;
            break;
        }
    }
    Ok(ShapeGrowth { value: t, contact, converged, iterations })
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::math::{UnitQuaternion, Vector3};
    use sublevel_core::primitive::PrimitiveFile;

    fn prim(file: PrimitiveFile) -> Primitive {
        Primitive::from_file(&file).unwrap()
    }

    /// Closed forms: a box growing towards a sphere along its x axis, a sphere growing towards a
    /// box (the center's distance over the radius), overlap below 1 and a contained center at 0.
    #[test]
    fn growth_matches_closed_forms() {
        let cube = prim(PrimitiveFile::Box { size: [0.4, 0.6, 0.2] });
        let ball = prim(PrimitiveFile::Sphere { radius: 0.1 });
        let at = |x: Real, y: Real, z: Real| Isometry3::translation(x, y, z);
        for (x, expected) in [(1.1, 5.0), (0.25, 0.75), (0.3 + 1e-9, 1.0 + 5e-9)] {
            let g = shape_growth(&cube, &Isometry3::identity(), ShapeRef::Primitive(&ball), &at(x, 0.0, 0.0)).unwrap();
            assert!(g.converged, "{g:?}");
            assert!((g.value - expected).abs() <= 1e-12 * expected, "x = {x}: {} vs {expected}", g.value);
            assert!((g.contact - Point3::new(x - 0.1, 0.0, 0.0)).norm() <= 1e-9, "{g:?}");
        }
        let g = shape_growth(&ball, &at(0.0, 0.0, 0.6), ShapeRef::Primitive(&cube), &Isometry3::identity()).unwrap();
        assert!((g.value - 5.0).abs() <= 1e-12, "{g:?}");
        let g = shape_growth(&ball, &at(0.05, 0.0, 0.0), ShapeRef::Primitive(&cube), &Isometry3::identity()).unwrap();
        assert_eq!(g.value, 0.0);
        let floor = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: 0.0 });
        assert!(shape_growth(&floor, &Isometry3::identity(), ShapeRef::Primitive(&ball), &at(0.0, 0.0, 1.0)).is_err());
        // A box above the floor, turned: its lowest corner's gauge.
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 0.1);
        let pose = Isometry3::from_parts(Vector3::new(0.0, 0.0, 0.5).into(), q);
        let g = shape_growth(&cube, &pose, ShapeRef::Primitive(&floor), &Isometry3::identity()).unwrap();
        let lowest = cube.support_value(&(q.inverse() * -Vector3::z()));
        assert!((g.value - 0.5 / lowest).abs() <= 1e-12, "{} vs {}", g.value, 0.5 / lowest);
    }

    /// On random poses of every pair: the growth exceeds 1 exactly when the shapes are apart, and A
    /// scaled by it touches B.
    #[test]
    fn growth_agrees_with_the_distance() {
        use rand::{Rng, SeedableRng};
        let shapes = [
            prim(PrimitiveFile::Box { size: [0.4, 0.3, 0.2] }),
            prim(PrimitiveFile::Cylinder { radius: 0.1, height: 0.2 }),
            prim(PrimitiveFile::Sphere { radius: 0.1 }),
            prim(PrimitiveFile::Capsule { radius: 0.05, height: 0.3 }),
        ];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut pose = |spread: Real| {
            let q = UnitQuaternion::from_euler_angles(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            );
            let t = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                * spread;
            Isometry3::from_parts(t.into(), q)
        };
        for a in &shapes {
            for b in &shapes {
                for _ in 0..40 {
                    let (pa, pb) = (pose(0.1), pose(0.5));
                    let g = shape_growth(a, &pa, ShapeRef::Primitive(b), &pb).unwrap();
                    assert!(g.converged, "{a:?} {b:?} {g:?}");
                    let d = shape_distance(ShapeRef::Primitive(a), &pa, ShapeRef::Primitive(b), &pb, None).unwrap();
                    assert_eq!(g.value > 1.0, !d.overlapping, "{} {d:?}", g.value);
                    if g.value > 0.0 {
                        let grown = scaled(a, g.value);
                        let touch = shape_distance(ShapeRef::Primitive(&grown), &pa, ShapeRef::Primitive(b), &pb, None)
                            .unwrap();
                        assert!(touch.distance <= 1e-11, "{touch:?}");
                        let shrunk = scaled(a, g.value * (1.0 - 1e-6));
                        let apart =
                            shape_distance(ShapeRef::Primitive(&shrunk), &pa, ShapeRef::Primitive(b), &pb, None)
                                .unwrap();
                        assert!(!apart.overlapping, "{apart:?}");
                    }
                }
            }
        }
    }
}
