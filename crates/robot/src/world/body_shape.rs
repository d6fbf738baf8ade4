//! A sos-convex body as a parry shape: the exact stage's view of a world body.
//!
//! parry's queries of two convex shapes (GJK for distances and intersection, EPA inside) need only
//! a support map, and a mesh against a convex shape runs them one triangle at a time; so a body
//! with an exact support function is a shape every exact query of [`crate::check`] accepts. The
//! support point in a direction e is the maximizer of e·x on {p ≤ 1}: the KKT system
//! ∇p(x) = μe, p(x) = 1 solved by damped Newton ([`sublevel_query::penetration::support_point`],
//! to a residual of 1e-13). Where Newton fails (it does not for a convex body with a
//! positive-definite Hessian on its boundary), the table's estimate is pushed out to the
//! certified upper bound of the support value along e ([`Body::support_upper`]), so the shape
//! parry sees is never smaller than the body: a miss stays impossible.
//!
//! **Distances.** GJK on a curved shape stalls short of the closest points: where a vertex or an
//! edge of a triangle is closest, parry's estimate (an upper bound) was up to 9 µm over the
//! distance to a ball of 25 cm. [`closest_points`] therefore asks parry within a margin widened
//! by [`GJK_SLACK`] and answers the certified lower bound of the direction n parry found (the unit
//! vector between its witnesses): d ≥ min_{a∈A} n·a − max_{b∈B} n·b, the gap between the two
//! shapes' supporting planes normal to n, with the witness on the body moved along n to that
//! distance. The answer is never over the distance, and was at most 6 µm under it in the tests;
//! a verdict within a padding is therefore conservative.

use parry3d_f64::bounding_volume::{Aabb, BoundingSphere};
use parry3d_f64::mass_properties::MassProperties;
use parry3d_f64::math::{Pose, Real as PReal, Vector as PVector};
use parry3d_f64::query::details::local_ray_intersection_with_support_map_with_params;
use parry3d_f64::query::gjk::VoronoiSimplex;
use parry3d_f64::query::point::local_point_projection_on_support_map;
use parry3d_f64::query::{ClosestPoints, PointProjection, PointQuery, Ray, RayCast, RayIntersection, Unsupported};
use parry3d_f64::shape::{FeatureId, Shape, ShapeType, SupportMap, TypedShape};
use std::sync::Arc;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real, Vector3};

/// A convex body (body frame = the shape's local frame, meters) for parry's support-map queries.
#[derive(Clone, Debug)]
pub(crate) struct BodyShape {
    body: Arc<Body>,
    aabb: Aabb,
    sphere: BoundingSphere,
}

impl BodyShape {
    /// The shape of a convex `body`; `None` for a nonconvex one (no certified bounds).
    pub(crate) fn new(body: Arc<Body>) -> Option<Self> {
        let (c, h) = body.bounding_box()?;
        let (sc, r) = body.bounding_sphere()?;
        let v = |x: &Vector3| PVector::new(x.x, x.y, x.z);
        let aabb = Aabb::new(v(&(c.coords - h)), v(&(c.coords + h)));
        Some(Self { body, aabb, sphere: BoundingSphere::new(v(&sc.coords), r) })
    }

    /// The support point in the unit body-frame direction `e` (module docs).
    fn support(&self, e: &Vector3) -> Vector3 {
        if let Ok(x) = sublevel_query::penetration::support_point(&self.body, &Isometry3::identity(), e) {
            if x.coords.iter().all(|v| v.is_finite()) {
                return x.coords;
            }
        }
        let upper = self.body.support_upper(e).unwrap_or(Real::INFINITY);
        match self.body.support_estimate(e) {
            Some(x) if upper.is_finite() => x.coords + e * (upper - e.dot(&x.coords)).max(0.0),
            _ => self.body.center(),
        }
    }
}

impl SupportMap for BodyShape {
    fn local_support_point(&self, dir: PVector) -> PVector {
        let d = Vector3::new(dir.x, dir.y, dir.z);
        let n = d.norm();
        if !(n.is_finite() && n > 0.0) {
            let c = self.body.center();
            return PVector::new(c.x, c.y, c.z);
        }
        let x = self.support(&(d / n));
        PVector::new(x.x, x.y, x.z)
    }
}

impl PointQuery for BodyShape {
    fn project_local_point(&self, pt: PVector, solid: bool) -> PointProjection {
        local_point_projection_on_support_map(self, &mut VoronoiSimplex::new(), pt, solid)
    }

    fn project_local_point_and_get_feature(&self, pt: PVector) -> (PointProjection, FeatureId) {
        (self.project_local_point(pt, false), FeatureId::Unknown)
    }
}

impl RayCast for BodyShape {
    fn cast_local_ray_and_get_normal(
        &self,
        ray: &Ray,
        max_time_of_impact: PReal,
        solid: bool,
    ) -> Option<RayIntersection> {
        local_ray_intersection_with_support_map_with_params(
            self,
            &mut VoronoiSimplex::new(),
            ray,
            max_time_of_impact,
            solid,
        )
    }
}

impl Shape for BodyShape {
    fn compute_local_aabb(&self) -> Aabb {
        self.aabb
    }

    fn compute_local_bounding_sphere(&self) -> BoundingSphere {
        self.sphere
    }

    fn clone_dyn(&self) -> Box<dyn Shape> {
        Box::new(self.clone())
    }

    fn scale_dyn(&self, _scale: PVector, _num_subdivisions: u32) -> Option<Box<dyn Shape>> {
        None
    }

    fn mass_properties(&self, density: PReal) -> MassProperties {
        // Not used by any query; the bounding ball's stands in.
        MassProperties::from_ball(density, self.sphere.radius)
    }

    fn shape_type(&self) -> ShapeType {
        ShapeType::Custom
    }

    fn as_typed_shape(&self) -> TypedShape<'_> {
        TypedShape::Custom(self)
    }

    fn ccd_thickness(&self) -> PReal {
        let h = self.aabb.half_extents();
        h.x.min(h.y).min(h.z)
    }

    fn ccd_angular_thickness(&self) -> PReal {
        std::f64::consts::FRAC_PI_2
    }

    fn is_convex(&self) -> bool {
        true
    }

    fn as_support_map(&self) -> Option<&dyn SupportMap> {
        Some(self as &dyn SupportMap)
    }

    fn compute_aabb(&self, position: &Pose) -> Aabb {
        self.aabb.transform_by(position)
    }

    fn feature_normal_at_point(&self, _: u32, _: FeatureId, _: PVector) -> Option<PVector> {
        None
    }
}

/// What the cheap tests of a triangle against a body show ([`triangle_quick`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quick {
    /// Farther apart than the margin.
    Apart,
    /// A vertex of the triangle lies in the body: they intersect.
    Touches,
    /// Neither shown: GJK decides.
    Unknown,
}

/// The cheap tests of a parry triangle (`a`, posed by `pa`) against a body shape (posed by `pb`)
/// within `margin` ≥ 0: a vertex with p ≤ 1 is a contact; a separating gap along the triangle's
/// normal (either side) or along the direction from the body's center to the triangle's centroid,
/// taken with the certified upper bound of the body's support function
/// ([`Body::support_upper`]), that exceeds the margin proves them apart. `Unknown` for any other
/// pair of shapes.
fn triangle_quick(pa: &Pose, a: &dyn Shape, pb: &Pose, b: &dyn Shape, margin: PReal) -> Quick {
    let (Some(t), Some(body)) = (a.as_shape::<parry3d_f64::shape::Triangle>(), b.as_shape::<BodyShape>()) else {
        return Quick::Unknown;
    };
    let v = [t.a, t.b, t.c].map(|p| {
        let q = pb.inverse_transform_point(pa.transform_point(p));
        Vector3::new(q.x, q.y, q.z)
    });
    let body = &body.body;
    if v.iter().any(|x| body.value_at(&(*x).into()) <= 1.0) {
        return Quick::Touches;
    }
    let normal = (v[1] - v[0]).cross(&(v[2] - v[0]));
    let toward = (v[0] + v[1] + v[2]) / 3.0 - body.center();
    for u in [normal, -normal, toward] {
        let n = u.norm();
        if !(n > 0.0 && n.is_finite()) {
            continue;
        }
        let u = u / n;
        let Some(upper) = body.support_upper(&u) else { return Quick::Unknown };
        let low = v.iter().map(|x| u.dot(x)).fold(Real::INFINITY, Real::min);
        if low - upper > margin {
            return Quick::Apart;
        }
    }
    Quick::Unknown
}

/// parry's `intersection_test` of two shapes, with the cheap tests of a triangle against a
/// [`BodyShape`] first ([`triangle_quick`]; either order).
///
/// # Errors
/// parry's, for a pair its dispatcher does not support.
pub(crate) fn intersection_test(pa: &Pose, a: &dyn Shape, pb: &Pose, b: &dyn Shape) -> Result<bool, Unsupported> {
    match quick_either(pa, a, pb, b, 0.0) {
        Quick::Apart => Ok(false),
        Quick::Touches => Ok(true),
        Quick::Unknown => parry3d_f64::query::intersection_test(pa, a, pb, b).map(|r| r.intersecting),
    }
}

/// [`triangle_quick`] with the triangle first or second.
fn quick_either(pa: &Pose, a: &dyn Shape, pb: &Pose, b: &dyn Shape, margin: PReal) -> Quick {
    match triangle_quick(pa, a, pb, b, margin) {
        Quick::Unknown => triangle_quick(pb, b, pa, a, margin),
        known => known,
    }
}

/// How far past the asked margin parry's GJK is run on a body pair (meters): above the largest
/// overestimate seen (9 µm), so a pair truly within the margin is never answered disjoint.
pub(crate) const GJK_SLACK: Real = 1e-4;

/// parry's `closest_points` of two shapes, exact where one is a [`BodyShape`] (module docs):
/// `Intersecting`, `WithinMargin` with witnesses whose distance is a certified lower bound of the
/// shapes' distance, or `Disjoint` when that bound exceeds `margin`.
///
/// # Errors
/// parry's, for a pair its dispatcher does not support.
pub(crate) fn closest_points(
    pa: &Pose,
    a: &dyn Shape,
    pb: &Pose,
    b: &dyn Shape,
    margin: PReal,
) -> Result<ClosestPoints, Unsupported> {
    let curved = a.as_shape::<BodyShape>().is_some() || b.as_shape::<BodyShape>().is_some();
    let (Some(sa), Some(sb), true) = (a.as_support_map(), b.as_support_map(), curved) else {
        return parry3d_f64::query::closest_points(pa, a, pb, b, margin);
    };
    match quick_either(pa, a, pb, b, margin) {
        Quick::Apart => return Ok(ClosestPoints::Disjoint),
        Quick::Touches => return Ok(ClosestPoints::Intersecting),
        Quick::Unknown => {}
    }
    let found = parry3d_f64::query::closest_points(pa, a, pb, b, margin + GJK_SLACK)?;
    let ClosestPoints::WithinMargin(p1, p2) = found else { return Ok(found) };
    let upper = (p1 - p2).length();
    if !(upper > 0.0 && upper.is_finite()) {
        return Ok(ClosestPoints::Intersecting);
    }
    let n = (p1 - p2) / upper;
    // min over A of n·a, max over B of n·b: the supporting planes of both shapes normal to n.
    let lower = (n.dot(sa.support_point(pa, -n)) - n.dot(sb.support_point(pb, n))).min(upper);
    if lower <= 0.0 {
        // The direction does not separate them by a provable gap: answered as touching.
        return Ok(ClosestPoints::Intersecting);
    }
    if lower > margin {
        return Ok(ClosestPoints::Disjoint);
    }
    Ok(ClosestPoints::WithinMargin(p1, p1 - n * lower))
}

/// Identity pose in parry's types, for tests.
#[cfg(test)]
fn identity() -> Pose {
    Pose::IDENTITY
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An ellipsoid body x²/a² + y²/b² + z²/c² ≤ 1 at `center`.
    fn ellipsoid(a: Real, b: Real, c: Real, center: Vector3) -> Arc<Body> {
        Arc::new(sublevel_core::body::ellipsoid(center.into(), [a, b, c]).unwrap())
    }

    #[test]
    fn support_points_of_an_ellipsoid_equal_the_closed_form() {
        let body = ellipsoid(0.3, 0.2, 0.1, Vector3::new(0.5, -0.2, 0.1));
        let shape = BodyShape::new(body).unwrap();
        for k in 0..50 {
            let t = k as Real * 0.37;
            let e = Vector3::new(t.cos() * (2.0 * t).sin(), t.sin() * (2.0 * t).sin(), (2.0 * t).cos()).normalize();
            let x = shape.local_support_point(PVector::new(e.x, e.y, e.z));
            // Closed form: x = c + D² e / |D e| with D = diag(a, b, c).
            let d = Vector3::new(0.3, 0.2, 0.1);
            let de = d.component_mul(&e);
            let want = Vector3::new(0.5, -0.2, 0.1) + d.component_mul(&de) / de.norm();
            assert!((Vector3::new(x.x, x.y, x.z) - want).norm() < 1e-9, "{k}: {x:?} vs {want:?}");
        }
    }

    #[test]
    fn gjk_distances_to_a_ball_equal_the_closed_form() {
        // A sphere body of radius 0.25 against parry's ball of radius 0.1: distance = |c| − 0.35.
        let shape = BodyShape::new(ellipsoid(0.25, 0.25, 0.25, Vector3::zeros())).unwrap();
        let ball = parry3d_f64::shape::Ball::new(0.1);
        for (k, c) in [PVector::new(0.6, 0.0, 0.0), PVector::new(0.3, 0.4, -0.2), PVector::new(-0.1, 0.2, 0.5)]
            .into_iter()
            .enumerate()
        {
            let at = Pose::from_translation(c);
            let d = parry3d_f64::query::distance(&identity(), &shape, &at, &ball).unwrap().distance;
            let want: Real = c.length() - 0.35;
            assert!((d - want).abs() < 1e-12, "{k}: {}", d - want);
        }
        let touching = Pose::from_translation(PVector::new(0.3, 0.0, 0.0));
        assert!(parry3d_f64::query::intersection_test(&identity(), &shape, &touching, &ball).unwrap().intersecting);
    }

    #[test]
    fn gjk_distances_to_triangles_equal_the_balls() {
        let shape = BodyShape::new(ellipsoid(0.25, 0.25, 0.25, Vector3::zeros())).unwrap();
        let ball = parry3d_f64::shape::Ball::new(0.25);
        let mut worst: Real = 0.0;
        for k in 0..200 {
            let t = k as Real * 0.61;
            let n = PVector::new(t.cos() * (1.3 * t).sin(), t.sin() * (1.3 * t).sin(), (1.3 * t).cos());
            let u = n.any_orthonormal_vector();
            let v = n.cross(u);
            let c = n * (0.3 + 0.05 * (k % 7) as Real);
            // Faces, edges and vertices closest in turn.
            let shift = (u * (k % 3) as Real + v * (k % 5) as Real) * 0.05;
            let c = c + shift;
            let tri = parry3d_f64::shape::Triangle::new(
                c + u * 0.1 + v * 0.02,
                c - u * 0.07 + v * 0.09,
                c - v * 0.1 + u * 0.01,
            );
            let at = Pose::IDENTITY;
            let want = parry3d_f64::query::distance(&at, &tri, &at, &ball).unwrap().distance;
            let ClosestPoints::WithinMargin(x, y) = closest_points(&at, &tri, &at, &shape, 1.0).unwrap() else {
                panic!("{k}: not within a meter")
            };
            let got = (x - y).length();
            // A lower bound, and a close one.
            assert!(got <= want + 1e-12, "{k}: {got} over {want}");
            worst = worst.max(want - got);
            // Within a margin just under the lower bound: disjoint.
            let under = closest_points(&at, &tri, &at, &shape, got - 1e-9).unwrap();
            assert!(matches!(under, ClosestPoints::Disjoint), "{k}: {under:?}");
        }
        // Measured: 6 µm at worst, where a vertex or an edge is closest.
        assert!(worst < 2e-5, "worst {worst}");
    }

    #[test]
    fn intersection_verdicts_of_triangles_equal_the_balls() {
        // Triangles about a sphere body of radius 0.25 at distances −0.1 to 0.1 from its surface
        // (some with a vertex inside, some crossing it with every vertex outside), against
        // parry's ball.
        let shape = BodyShape::new(ellipsoid(0.25, 0.25, 0.25, Vector3::zeros())).unwrap();
        let ball = parry3d_f64::shape::Ball::new(0.25);
        let at = Pose::IDENTITY;
        let (mut hits, mut misses) = (0, 0);
        for k in 0..300 {
            let t = k as Real * 0.47;
            let n = PVector::new(t.cos() * (1.7 * t).sin(), t.sin() * (1.7 * t).sin(), (1.7 * t).cos());
            let u = n.any_orthonormal_vector();
            let v = n.cross(u);
            let c = n * (0.15 + 0.2 * ((k % 11) as Real / 10.0)) + (u * (k % 3) as Real + v * (k % 4) as Real) * 0.03;
            let size = 0.05 + 0.2 * (k % 5) as Real;
            let tri = parry3d_f64::shape::Triangle::new(c + u * size, c - u * size * 0.5 + v * size, c - v * size);
            let want = parry3d_f64::query::intersection_test(&at, &tri, &at, &ball).unwrap().intersecting;
            let got = intersection_test(&at, &tri, &at, &shape).unwrap();
            // A triangle apart by under a nanometer may go either way.
            let near = !want && parry3d_f64::query::distance(&at, &tri, &at, &ball).unwrap().distance < 1e-9;
            if !near {
                assert_eq!(got, want, "{k}");
                assert_eq!(intersection_test(&at, &shape, &at, &tri).unwrap(), want, "{k} swapped");
            }
            if want {
                hits += 1;
            } else {
                misses += 1;
            }
        }
        assert!(hits > 50 && misses > 50, "{hits} intersecting, {misses} apart");
    }
}
