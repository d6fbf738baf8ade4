//! The exact stage of the robot checks and the cheap box bounds before it: parry's shapes for
//! link meshes, mesh obstacles and primitives (triangles against triangles or solids, as coal and
//! FCL decide contact), and oriented boxes with their separating-axis gap.

use crate::{Error, Result};
use parry3d_f64::query::ClosestPoints;
use parry3d_f64::shape::SharedShape;
use std::f64::consts::FRAC_PI_2;
use sublevel_core::math::{Isometry3, Point3, Real, UnitQuaternion, Vector3};
use sublevel_core::primitive::Primitive;

/// One geometry's exact shape for the mesh stage, and the pose offset parry's shape needs.
pub(crate) struct ExactShape {
    pub(crate) shape: SharedShape,
    /// parry shape frame → geometry frame (a cylinder's axis is y in parry, z here).
    pub(crate) offset: Isometry3,
}

pub(crate) fn exact_primitive(p: &Primitive) -> ExactShape {
    let v = |x: Real, y: Real, z: Real| parry3d_f64::math::Vector::new(x, y, z);
    let id = Isometry3::identity();
    match *p {
        Primitive::Box { half_extents: h } => ExactShape { shape: SharedShape::cuboid(h.x, h.y, h.z), offset: id },
        Primitive::Sphere { radius } => ExactShape { shape: SharedShape::ball(radius), offset: id },
        Primitive::Cylinder { radius, half_height } => ExactShape {
            shape: SharedShape::cylinder(half_height, radius),
            offset: Isometry3::from_parts(
                Vector3::zeros().into(),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), FRAC_PI_2),
            ),
        },
        Primitive::Capsule { radius, half_height } => ExactShape {
            shape: SharedShape::capsule(v(0.0, 0.0, -half_height), v(0.0, 0.0, half_height), radius),
            offset: id,
        },
        Primitive::Halfspace { normal, offset } => ExactShape {
            shape: SharedShape::halfspace(v(normal.x, normal.y, normal.z).normalize()),
            offset: Isometry3::translation(normal.x * offset, normal.y * offset, normal.z * offset),
        },
    }
}

pub(crate) fn parry_pose(iso: &Isometry3) -> parry3d_f64::math::Pose {
    let q = iso.rotation.quaternion();
    let t = iso.translation.vector;
    parry3d_f64::math::Pose::from_parts(
        parry3d_f64::math::Vector::new(t.x, t.y, t.z),
        parry3d_f64::math::Rot3::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

/// A box placed in the world: center, rotation columns and half extents (meters).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlacedBox {
    pub(crate) center: Vector3,
    pub(crate) axes: sublevel_core::math::Matrix3,
    pub(crate) half: Vector3,
}

impl PlacedBox {
    pub(crate) fn new(pose: &Isometry3, local: &(Vector3, Vector3)) -> Self {
        Self {
            center: pose.transform_point(&local.0.into()).coords,
            axes: *pose.rotation.to_rotation_matrix().matrix(),
            half: local.1,
        }
    }

    /// Half the box's extent along the unit axis `n`.
    pub(crate) fn radius(&self, n: &Vector3) -> Real {
        (0..3).map(|i| self.half[i] * self.axes.column(i).dot(n).abs()).sum()
    }
}

/// A lower bound of the distance between two boxes (meters; ≤ 0 when they overlap): the largest
/// gap between their projections over the 15 separating axes of two boxes (Gottschalk, Lin and
/// Manocha, OBBTree, 1996): `dist ≥ |n·(c_b − c_a)| − r_a(n) − r_b(n)` for any unit `n`.
pub(crate) fn box_gap(a: &PlacedBox, b: &PlacedBox) -> Real {
    box_gap_past(a, b, Real::INFINITY)
}

/// As [`box_gap`], the axes tried faces first and the search stopped at the first gap above
/// `stop` (still a lower bound of the distance; the callers only ask whether it exceeds `stop`).
pub(crate) fn box_gap_past(a: &PlacedBox, b: &PlacedBox, stop: Real) -> Real {
    let d = b.center - a.center;
    // Rounding of the projections: a hair below the exact gap.
    let hair = 1e-12 * (d.norm() + a.half.norm() + b.half.norm());
    let mut gap = Real::NEG_INFINITY;
    let mut axis = |n: Vector3| {
        let len = n.norm();
        if len > 1e-9 {
            let n = n / len;
            gap = gap.max(n.dot(&d).abs() - a.radius(&n) - b.radius(&n) - hair);
        }
        gap > stop
    };
    for i in 0..3 {
        if axis(a.axes.column(i).into_owned()) || axis(b.axes.column(i).into_owned()) {
            return gap;
        }
    }
    for i in 0..3 {
        for j in 0..3 {
            if axis(a.axes.column(i).cross(&b.axes.column(j))) {
                return gap;
            }
        }
    }
    gap
}

/// The outcome of one pair.
pub(crate) enum PairOutcome {
    /// Free, at least this far apart (meters), with witnesses (robot side first) and whether the
    /// value is the mesh-exact one.
    Free { distance: Real, witnesses: Option<(Point3, Point3)> },
    /// Colliding (within the padding).
    Collides,
}

/// Whether two exact shapes (parry) intersect or come within `padding`.
pub(crate) fn exact_collides(
    pa: &parry3d_f64::math::Pose,
    a: &ExactShape,
    pb: &parry3d_f64::math::Pose,
    b: &ExactShape,
    padding: Real,
) -> Result<bool> {
    let unsupported = |_| Error::Numerical("the exact mesh stage does not support this shape pair".into());
    if padding == 0.0 {
        return parry3d_f64::query::intersection_test(pa, a.shape.as_ref(), pb, b.shape.as_ref())
            .map(|r| r.intersecting)
            .map_err(unsupported);
    }
    Ok(!matches!(
        parry3d_f64::query::closest_points(pa, a.shape.as_ref(), pb, b.shape.as_ref(), padding).map_err(unsupported)?,
        ClosestPoints::Disjoint
    ))
}

/// Two exact shapes (parry): collides within `padding`, else their distance and closest points;
/// a pair farther apart than `max_dist` is answered free at +∞ without its points (the search
/// stops at that distance, much sooner than a full one).
pub(crate) fn exact_pair(
    pa: &parry3d_f64::math::Pose,
    a: &ExactShape,
    pb: &parry3d_f64::math::Pose,
    b: &ExactShape,
    padding: Real,
    max_dist: Real,
) -> Result<PairOutcome> {
    let unsupported = |_| Error::Numerical("the exact mesh stage does not support this shape pair".into());
    let max_dist = if max_dist.is_finite() { max_dist.max(padding) } else { Real::MAX };
    match parry3d_f64::query::closest_points(pa, a.shape.as_ref(), pb, b.shape.as_ref(), max_dist)
        .map_err(unsupported)?
    {
        ClosestPoints::Intersecting => Ok(PairOutcome::Collides),
        ClosestPoints::WithinMargin(p1, p2) => {
            let (x, y) = (Point3::new(p1.x, p1.y, p1.z), Point3::new(p2.x, p2.y, p2.z));
            let d = (x - y).norm();
            if d <= padding {
                Ok(PairOutcome::Collides)
            } else {
                Ok(PairOutcome::Free { distance: d, witnesses: Some((x, y)) })
            }
        }
        ClosestPoints::Disjoint => Ok(PairOutcome::Free { distance: Real::INFINITY, witnesses: None }),
    }
}
