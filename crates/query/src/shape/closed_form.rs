//! The closed forms of the shape queries: a halfspace against a bounded shape, a sphere against a
//! primitive, two capsules. Both are exact: the first needs the shape's lowest point along the halfspace's
//! normal (its support point along −n), the second the primitive's closest boundary point to the
//! sphere's center ([`Primitive::closest_boundary_point`]).

use super::{CoreGap, ShapeDistance, ShapeMethod, ShapeRef, ShapeWarmStart};
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
        core: None,
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
    let mut out = answer(x, y, distance, overlapping, swapped);
    // The outward normal of the primitive at q, towards the center (or away from it inside).
    let outward = if signed != 0.0 { (Point3::from(c) - q) / signed } else { Vector3::zeros() };
    if outward.norm_squared() > 0.0 {
        let (normal, point_a, point_b, radii) = if swapped {
            (outward, q, Point3::from(c), (0.0, radius))
        } else {
            (-outward, Point3::from(c), q, (radius, 0.0))
        };
        out.core = Some(CoreGap { gap: signed, normal, point_a, point_b, radii });
    }
    out
}

/// Two capsules `a` (posed by `pose_a`) and `b`: the closest points of their axis segments
/// (Ericson, *Real-Time Collision Detection*, §5.1.9: the unconstrained minimizer of the segments'
/// squared distance clamped to the parameter square, one edge at a time), less both radii.
pub(super) fn capsules(a: &Primitive, pose_a: &Isometry3, b: &Primitive, pose_b: &Isometry3) -> ShapeDistance {
    let (Primitive::Capsule { radius: ra, half_height: ha }, Primitive::Capsule { radius: rb, half_height: hb }) =
        (*a, *b)
    else {
        unreachable!("called with two capsules")
    };
    let axis_a = pose_a.rotation * Vector3::z();
    let axis_b = pose_b.rotation * Vector3::z();
    let pa = pose_a.translation.vector - axis_a * ha;
    let pb = pose_b.translation.vector - axis_b * hb;
    let (da, db) = (axis_a * (2.0 * ha), axis_b * (2.0 * hb));
    let r = pa - pb;
    let (aa, ee, f) = (da.norm_squared(), db.norm_squared(), db.dot(&r));
    let (s, t) = if aa == 0.0 && ee == 0.0 {
        (0.0, 0.0)
    } else if aa == 0.0 {
        (0.0, (f / ee).clamp(0.0, 1.0))
    } else {
        let c = da.dot(&r);
        if ee == 0.0 {
            ((-c / aa).clamp(0.0, 1.0), 0.0)
        } else {
            let bb = da.dot(&db);
            let denom = aa * ee - bb * bb;
            // Parallel axes (denom = 0): any s is a minimizer's start; 0 keeps it on the segment.
            let s = if denom > 0.0 { ((bb * f - c * ee) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let t = (bb * s + f) / ee;
            if t < 0.0 {
                ((-c / aa).clamp(0.0, 1.0), 0.0)
            } else if t > 1.0 {
                (((bb - c) / aa).clamp(0.0, 1.0), 1.0)
            } else {
                (s, t)
            }
        }
    };
    let x = Point3::from(pa + da * s);
    let y = Point3::from(pb + db * t);
    let gap = y - x;
    let core = gap.norm();
    let distance = core - ra - rb;
    let overlapping = distance <= 0.0;
    let n = if core > 0.0 { gap / core } else { Vector3::zeros() };
    let (wa, wb) = if overlapping {
        let common = x + n * ra.min(core);
        (common, common)
    } else {
        (x + n * ra, y - n * rb)
    };
    let mut out = answer(wa, wb, distance, overlapping, false);
    if core > 0.0 {
        out.core = Some(CoreGap { gap: core, normal: n, point_a: x, point_b: y, radii: (ra, rb) });
    }
    out
}
