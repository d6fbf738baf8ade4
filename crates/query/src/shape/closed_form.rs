//! The closed forms of the shape queries: a halfspace against a bounded shape, a sphere against a
//! primitive. Both are exact: the first needs the shape's lowest point along the halfspace's
//! normal (its support point along −n), the second the primitive's closest boundary point to the
//! sphere's center ([`Primitive::closest_boundary_point`]).

use super::{ShapeDistance, ShapeMethod, ShapeRef, ShapeWarmStart};
use crate::newton::SolveStatus;
use crate::penetration::support_point;
use crate::Result;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;

/// An answer from the witness `x` on the closed form's own shape and `y` on the other, the
/// distance and overlap; `swapped` when the own shape is the query's B.
fn answer(x: Point3, y: Point3, distance: Real, overlapping: bool, swapped: bool) -> ShapeDistance {
    let (wa, wb) = if swapped { (y, x) } else { (x, y) };
    let normal = if overlapping { Vector3::zeros() } else { (wb - wa) / distance };
    ShapeDistance {
        distance: if overlapping { 0.0 } else { distance },
        witness_a: wa,
        witness_b: wb,
        normal,
        overlapping,
        status: SolveStatus::Converged,
        iterations: 0,
        kkt_residual: 0.0,
        lower_bound: (!overlapping).then_some(distance),
        method: ShapeMethod::ClosedForm,
        warm_started: false,
        warm_start: ShapeWarmStart::default(),
    }
}

/// The halfspace `h` posed by `pose_h` against the bounded shape `other` posed by `pose_o`: the
/// signed height of the other's lowest point along the normal above the plane.
///
/// # Errors
/// [`crate::Error::Numerical`] where a body's support point fails to converge (nonconvex body).
pub(super) fn halfspace(
    h: &Primitive,
    pose_h: &Isometry3,
    other: ShapeRef<'_>,
    pose_o: &Isometry3,
    swapped: bool,
) -> Result<ShapeDistance> {
    let Primitive::Halfspace { normal, offset } = *h else { unreachable!("called with a halfspace") };
    let n = pose_h.rotation * normal;
    let d = offset + n.dot(&pose_h.translation.vector);
    let lowest = match other {
        ShapeRef::Primitive(p) => {
            let e = pose_o.rotation.inverse() * -n;
            // Bounded: the caller refused two halfspaces.
            let local = p.support_point(&e).unwrap_or_else(Vector3::zeros);
            pose_o * Point3::from(local)
        }
        ShapeRef::Body(b) => support_point(b, pose_o, &-n)?,
    };
    let height = n.dot(&lowest.coords) - d;
    let overlapping = height <= 0.0;
    let on_plane = if overlapping { lowest } else { lowest - n * height };
    Ok(answer(on_plane, lowest, height, overlapping, swapped))
}

/// The sphere `s` posed by `pose_s` against the primitive `other` (not a halfspace) posed by
/// `pose_o`: the primitive's signed distance to the center less the radius.
pub(super) fn sphere(
    s: &Primitive,
    pose_s: &Isometry3,
    other: &Primitive,
    pose_o: &Isometry3,
    swapped: bool,
) -> ShapeDistance {
    let Primitive::Sphere { radius } = *s else { unreachable!("called with a sphere") };
    let c = pose_s.translation.vector;
    let local = pose_o.inverse_transform_vector(&(c - pose_o.translation.vector));
    let (signed, q) = other.closest_boundary_point(&local);
    let q = pose_o * Point3::from(q);
    let distance = signed - radius;
    let overlapping = distance <= 0.0;
    let x = if signed > 0.0 {
        Point3::from(c) + (q - Point3::from(c)) * (radius.min(signed) / signed)
    } else {
        Point3::from(c)
    };
    let y = if overlapping { x } else { q };
    answer(x, y, distance, overlapping, swapped)
}
