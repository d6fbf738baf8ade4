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

    /// Half the box's extent along the unit axis `n` (the tests' reference gap uses it).
    #[cfg(test)]
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
    // The separating-axis test of two oriented boxes in a's frame (Gottschalk, Lin and Manocha,
    // SIGGRAPH 1996; Ericson, Real-Time Collision Detection §4.4.1): with C = Aᵀ B, the 15 axes'
    // projections are sums over C's entries, and a cross axis a_i × b_j has length √(1 − C_ij²).
    let d = b.center - a.center;
    let (ea, eb) = (&a.half, &b.half);
    // Rounding of the projections: a hair below the exact gap (1-norms bound the 2-norms).
    let hair = 1e-12 * (d.abs().sum() + ea.abs().sum() + eb.abs().sum());
    let c = a.axes.transpose() * b.axes;
    let abs_c = c.abs();
    let t = a.axes.transpose() * d;
    let mut gap = Real::NEG_INFINITY;
    for i in 0..3 {
        let on_a = t[i].abs() - ea[i] - (eb[0] * abs_c[(i, 0)] + eb[1] * abs_c[(i, 1)] + eb[2] * abs_c[(i, 2)]);
        gap = gap.max(on_a - hair);
        if gap > stop {
            return gap;
        }
        let tb = t[0] * c[(0, i)] + t[1] * c[(1, i)] + t[2] * c[(2, i)];
        let on_b = tb.abs() - (ea[0] * abs_c[(0, i)] + ea[1] * abs_c[(1, i)] + ea[2] * abs_c[(2, i)]) - eb[i];
        gap = gap.max(on_b - hair);
        if gap > stop {
            return gap;
        }
    }
    for i in 0..3 {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let len2 = 1.0 - c[(i, j)] * c[(i, j)];
            if len2 <= 1e-18 {
                // a_i ∥ b_j: the face axes already cover it.
                continue;
            }
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            let projection = (t[i2] * c[(i1, j)] - t[i1] * c[(i2, j)]).abs();
            let ra = ea[i1] * abs_c[(i2, j)] + ea[i2] * abs_c[(i1, j)];
            let rb = eb[j1] * abs_c[(i, j2)] + eb[j2] * abs_c[(i, j1)];
            gap = gap.max((projection - ra - rb) / len2.sqrt() - hair);
            if gap > stop {
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
    if let (Some(ma), Some(mb)) = (a.shape.as_trimesh(), b.shape.as_trimesh()) {
        return Ok(meshes_touch(ma, pa, mb, pb, padding));
    }
    if let Some(m) = a.shape.as_trimesh() {
        if let Some(touch) = mesh_touches_solid(m, pa, b.shape.as_ref(), pb, padding) {
            return Ok(touch);
        }
    }
    if let Some(m) = b.shape.as_trimesh() {
        if let Some(touch) = mesh_touches_solid(m, pb, a.shape.as_ref(), pa, padding) {
            return Ok(touch);
        }
    }
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

/// The closest pair of triangles of two meshes found last (indices in the first and second
/// mesh), where [`exact_pair`] starts its next search of the same two meshes.
pub(crate) type PairHint = std::cell::Cell<Option<(u32, u32)>>;

/// Two exact shapes (parry): collides within `padding`, else their distance and closest points;
/// a pair farther apart than `max_dist` is answered free at +∞ without its points (the search
/// stops at that distance, much sooner than a full one).
///
/// `hint` holds the closest pair of triangles of the last answer for two meshes, where the search
/// starts (a warm start: along a motion the closest triangles change little), and receives the
/// new one; any pair is a valid start, so the answer does not depend on it.
pub(crate) fn exact_pair(
    pa: &parry3d_f64::math::Pose,
    a: &ExactShape,
    pb: &parry3d_f64::math::Pose,
    b: &ExactShape,
    padding: Real,
    max_dist: Real,
    hint: &PairHint,
) -> Result<PairOutcome> {
    let unsupported = |_| Error::Numerical("the exact mesh stage does not support this shape pair".into());
    let max_dist = if max_dist.is_finite() { max_dist.max(padding) } else { Real::MAX };
    let points = match (a.shape.as_trimesh(), b.shape.as_trimesh()) {
        (Some(ma), Some(mb)) => Some(meshes_closest_points(ma, pa, mb, pb, max_dist, hint)),
        (Some(m), None) => mesh_solid_closest_points(m, pa, b.shape.as_ref(), pb, max_dist),
        (None, Some(m)) => mesh_solid_closest_points(m, pb, a.shape.as_ref(), pa, max_dist).map(|c| c.flipped()),
        _ => None,
    };
    let points = match points {
        Some(points) => points,
        None => parry3d_f64::query::closest_points(pa, a.shape.as_ref(), pb, b.shape.as_ref(), max_dist)
            .map_err(unsupported)?,
    };
    match points {
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

/// Whether two triangle meshes (posed by `pa`, `pb`) have triangles within `padding` ≥ 0 of each
/// other (intersecting at 0): the verdict of parry's `intersection_test` (`closest_points` with
/// the padding as margin) on the two meshes, found by a simultaneous descent of both BVHs.
///
/// parry tests a mesh against a mesh one triangle of the first at a time, each against the whole
/// of the second: every triangle whose box meets the second mesh's box costs a descent of the
/// second's BVH, which is most of the first mesh when two links nearly touch. Here a pair of
/// nodes goes on only while their boxes meet — the second's box placed in the first's frame and
/// bounded there by an axis-aligned box, loosened by the padding — so only pairs of triangles
/// with overlapping boxes are tested, each with the triangle–triangle test parry's dispatch
/// reaches. Boxes that meet are a necessary condition for triangles within the padding, so the
/// answer is parry's.
pub(crate) fn meshes_touch(
    ma: &parry3d_f64::shape::TriMesh,
    pa: &parry3d_f64::math::Pose,
    mb: &parry3d_f64::shape::TriMesh,
    pb: &parry3d_f64::math::Pose,
    padding: Real,
) -> bool {
    use parry3d_f64::math::{Matrix, Vector};
    let rel = pa.inv_mul(pb);
    let r = Matrix::from_quat(rel.rotation);
    let abs_r = Matrix::from_cols(r.x_axis.abs(), r.y_axis.abs(), r.z_axis.abs());
    let t = rel.translation;
    // Rounding of the placed boxes: a hair of slack, as the boxes only prune.
    let slack = padding + 1e-9 * (1.0 + t.length() + ma.local_aabb().extents().length());
    let overlap = |n1: &parry3d_f64::partitioning::BvhNode, n2: &parry3d_f64::partitioning::BvhNode| {
        let (c1, h1) = ((n1.mins() + n1.maxs()) * 0.5, (n1.maxs() - n1.mins()) * 0.5);
        let (c2, h2) = ((n2.mins() + n2.maxs()) * 0.5, (n2.maxs() - n2.mins()) * 0.5);
        let d = (r * c2 + t - c1).abs();
        let reach = h1 + abs_r * h2 + Vector::splat(slack);
        d.x <= reach.x && d.y <= reach.y && d.z <= reach.z
    };
    let identity = parry3d_f64::math::Pose::IDENTITY;
    ma.bvh().leaf_pairs(mb.bvh(), overlap).any(|(i, j)| {
        let (ta, tb) = (ma.triangle(i), mb.triangle(j));
        let tb_in_a = [r * tb.a + t, r * tb.b + t, r * tb.c + t];
        if beyond_plane([ta.a, ta.b, ta.c], tb_in_a, padding) || beyond_plane(tb_in_a, [ta.a, ta.b, ta.c], padding) {
            return false;
        }
        if padding == 0.0 {
            if apart_on_common_line([ta.a, ta.b, ta.c], tb_in_a) {
                return false;
            }
            parry3d_f64::query::intersection_test(&identity, &ta, &rel, &tb).is_ok_and(|r| r.intersecting)
        } else {
            parry3d_f64::query::closest_points(&identity, &ta, &rel, &tb, padding)
                .is_ok_and(|c| !matches!(c, ClosestPoints::Disjoint))
        }
    })
}

/// Whether two triangles, each cutting the other's plane, are disjoint: the segments in which
/// they meet the line common to both planes do not overlap, by more than a nanometer (Möller,
/// "A fast triangle–triangle intersection test", JGT 1997). `false` where it cannot tell — planes
/// within 10⁻⁶ rad of parallel, a vertex on the other's plane, a triangle that does not cut the
/// other's plane — which parry's test then decides.
fn apart_on_common_line(u: [parry3d_f64::math::Vector; 3], v: [parry3d_f64::math::Vector; 3]) -> bool {
    let nu = (u[1] - u[0]).cross(u[2] - u[0]);
    let nv = (v[1] - v[0]).cross(v[2] - v[0]);
    let line = nu.cross(nv);
    let len = line.length();
    if len.is_nan() || len <= 1e-6 * nu.length() * nv.length() {
        return false;
    }
    let line = line / len;
    let (Some(on_u), Some(on_v)) =
        (line_interval(u, u.map(|x| nv.dot(x - v[0])), line), line_interval(v, v.map(|x| nu.dot(x - u[0])), line))
    else {
        return false;
    };
    on_u.1 < on_v.0 - 1e-9 || on_v.1 < on_u.0 - 1e-9
}

/// The segment in which triangle `p` meets a plane, as an interval of `line` (a unit vector along
/// the plane): `s` holds the vertices' signed distances to the plane (any positive scale); `None`
/// when a vertex lies on it or all lie on one side.
fn line_interval(
    p: [parry3d_f64::math::Vector; 3],
    s: [Real; 3],
    line: parry3d_f64::math::Vector,
) -> Option<(Real, Real)> {
    if s.contains(&0.0) {
        return None;
    }
    // The lone vertex: the one on its own side.
    let k = if (s[0] > 0.0) == (s[1] > 0.0) {
        2
    } else if (s[0] > 0.0) == (s[2] > 0.0) {
        1
    } else {
        0
    };
    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
    if (s[i] > 0.0) == (s[k] > 0.0) {
        return None;
    }
    let x = p.map(|x| line.dot(x));
    let a = x[k] + (x[i] - x[k]) * (s[k] / (s[k] - s[i]));
    let b = x[k] + (x[j] - x[k]) * (s[k] / (s[k] - s[j]));
    Some((a.min(b), a.max(b)))
}

/// Whether every vertex of triangle `v` lies farther than `padding` on one side of the plane of
/// triangle `u` (so the two are farther apart than `padding`); `false` for a degenerate `u`.
fn beyond_plane(u: [parry3d_f64::math::Vector; 3], v: [parry3d_f64::math::Vector; 3], padding: Real) -> bool {
    let (e1, e2) = (u[1] - u[0], u[2] - u[0]);
    let n = e1.cross(e2);
    let len2 = n.length_squared();
    if len2 <= Real::EPSILON * Real::EPSILON * e1.length_squared() * e2.length_squared() || len2 == 0.0 {
        return false;
    }
    let reach = if padding == 0.0 { 0.0 } else { padding * len2.sqrt() };
    let s = v.map(|x| n.dot(x - u[0]));
    s.iter().all(|&s| s > reach) || s.iter().all(|&s| s < -reach)
}

/// Whether a triangle mesh (posed by `pm`) has a triangle within `padding` ≥ 0 of a bounded
/// convex shape (posed by `ps`): parry's verdict on each triangle, found by a descent of the
/// mesh's BVH that keeps a node only while its box meets the shape's box (an oriented box in the
/// mesh's frame, loosened by the padding; the separating-axis test on both boxes' six face
/// axes). parry keeps the triangles whose boxes meet the shape's axis-aligned bounding box, which
/// for a rotated board or wall holds far more of the mesh. `None` when the shape is unbounded
/// (a halfspace) or composite, which parry's own test answers.
pub(crate) fn mesh_touches_solid(
    mesh: &parry3d_f64::shape::TriMesh,
    pm: &parry3d_f64::math::Pose,
    shape: &dyn parry3d_f64::shape::Shape,
    ps: &parry3d_f64::math::Pose,
    padding: Real,
) -> Option<bool> {
    use parry3d_f64::math::{Matrix, Vector};
    // parry bounds a halfspace by a box of half the largest float: no use as a box.
    if shape.as_composite_shape().is_some() || shape.as_halfspace().is_some() {
        return None;
    }
    let local = shape.compute_local_aabb();
    let (cs, hs) = (local.center(), local.half_extents());
    if !(cs.is_finite() && hs.is_finite()) {
        return None;
    }
    let rel = pm.inv_mul(ps);
    let r = Matrix::from_quat(rel.rotation);
    let abs_r = Matrix::from_cols(r.x_axis.abs(), r.y_axis.abs(), r.z_axis.abs());
    let center = r * cs + rel.translation;
    let slack = padding + 1e-9 * (1.0 + center.length() + hs.length() + mesh.local_aabb().extents().length());
    let reach_mesh_axes = abs_r * hs + Vector::splat(slack);
    let reach_shape_axes = hs + Vector::splat(slack);
    let meets = |node: &parry3d_f64::partitioning::BvhNode| {
        let (c1, h1) = ((node.mins() + node.maxs()) * 0.5, (node.maxs() - node.mins()) * 0.5);
        let d = center - c1;
        let on_mesh = d.abs();
        let reach = reach_mesh_axes + h1;
        if on_mesh.x > reach.x || on_mesh.y > reach.y || on_mesh.z > reach.z {
            return false;
        }
        let on_shape = (r.transpose() * d).abs();
        let reach = reach_shape_axes + abs_r.transpose() * h1;
        on_shape.x <= reach.x && on_shape.y <= reach.y && on_shape.z <= reach.z
    };
    let identity = parry3d_f64::math::Pose::IDENTITY;
    Some(mesh.bvh().leaves(meets).any(|i| {
        let triangle = mesh.triangle(i);
        if triangle_box_gap(&triangle, &r, &center, &hs) > slack {
            return false;
        }
        if padding == 0.0 {
            parry3d_f64::query::intersection_test(&identity, &triangle, &rel, shape).is_ok_and(|r| r.intersecting)
        } else {
            parry3d_f64::query::closest_points(&identity, &triangle, &rel, shape, padding)
                .is_ok_and(|c| !matches!(c, ClosestPoints::Disjoint))
        }
    }))
}

/// A lower bound of the distance from a triangle to an oriented box (center `center`, axes the
/// columns of `r`, half extents `half`, all in the triangle's frame): the largest gap between
/// their projections on the box's three axes and the triangle's normal (meters; ≤ 0 when no
/// such axis separates them).
fn triangle_box_gap(
    triangle: &parry3d_f64::shape::Triangle,
    r: &parry3d_f64::math::Matrix,
    center: &parry3d_f64::math::Vector,
    half: &parry3d_f64::math::Vector,
) -> Real {
    let v = [triangle.a - *center, triangle.b - *center, triangle.c - *center];
    let mut gap = Real::NEG_INFINITY;
    for (axis, h) in [(r.x_axis, half.x), (r.y_axis, half.y), (r.z_axis, half.z)] {
        let p = v.map(|x| axis.dot(x));
        let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        gap = gap.max(lo - h).max(-h - hi);
    }
    let n = (triangle.b - triangle.a).cross(triangle.c - triangle.a);
    let len = n.length();
    if len > 0.0 {
        let n = n / len;
        let reach = half.x * n.dot(r.x_axis).abs() + half.y * n.dot(r.y_axis).abs() + half.z * n.dot(r.z_axis).abs();
        gap = gap.max(n.dot(v[0]).abs() - reach);
    }
    gap
}

/// The closest points of a triangle mesh (posed by `pm`) and a bounded convex shape (posed by
/// `ps`) within `max_dist`, in the world frame, as parry's `closest_points` gives them: a
/// best-first search of the mesh's BVH, each node bounded below by the larger of two box
/// distances — its box to the shape's box bounded in the mesh's frame, and the shape's box to the
/// node's box bounded in the shape's frame — where parry uses only the first with the shape's
/// box bounded in the world's axes. `None` where [`mesh_touches_solid`] is.
pub(crate) fn mesh_solid_closest_points(
    mesh: &parry3d_f64::shape::TriMesh,
    pm: &parry3d_f64::math::Pose,
    shape: &dyn parry3d_f64::shape::Shape,
    ps: &parry3d_f64::math::Pose,
    max_dist: Real,
) -> Option<ClosestPoints> {
    use parry3d_f64::math::{Matrix, Vector};
    if shape.as_composite_shape().is_some() || shape.as_halfspace().is_some() {
        return None;
    }
    let local = shape.compute_local_aabb();
    let (cs, hs) = (local.center(), local.half_extents());
    if !(cs.is_finite() && hs.is_finite()) {
        return None;
    }
    let rel = pm.inv_mul(ps);
    let r = Matrix::from_quat(rel.rotation);
    let abs_r = Matrix::from_cols(r.x_axis.abs(), r.y_axis.abs(), r.z_axis.abs());
    let center = r * cs + rel.translation;
    // Rounding of the placed boxes: the bounds are lowered by a hair.
    let hair = 1e-9 * (1.0 + center.length() + hs.length() + mesh.local_aabb().extents().length());
    let shape_in_mesh = abs_r * hs;
    let lower = |node: &parry3d_f64::partitioning::BvhNode, _: Real| {
        let (c1, h1) = ((node.mins() + node.maxs()) * 0.5, (node.maxs() - node.mins()) * 0.5);
        let d = center - c1;
        let on_mesh = (d.abs() - h1 - shape_in_mesh).max(Vector::ZERO).length();
        let on_shape = ((r.transpose() * d).abs() - hs - abs_r.transpose() * h1).max(Vector::ZERO).length();
        (on_mesh.max(on_shape) - hair).max(0.0)
    };
    let identity = parry3d_f64::math::Pose::IDENTITY;
    let leaf = |i: u32, best: Real| {
        let triangle = mesh.triangle(i);
        if triangle_box_gap(&triangle, &r, &center, &hs) - hair >= best {
            return None;
        }
        let points = parry3d_f64::query::closest_points(&identity, &triangle, &rel, shape, best).ok()?;
        Some(match points {
            ClosestPoints::WithinMargin(p1, p2) => ((p1 - p2).length(), points),
            ClosestPoints::Intersecting => (-Real::MAX, points),
            ClosestPoints::Disjoint => (Real::MAX, points),
        })
    };
    Some(match mesh.bvh().find_best(max_dist, lower, leaf) {
        Some((_, (_, points))) => points.transform_by(pm, pm),
        None => ClosestPoints::Disjoint,
    })
}

/// The closest points of two triangle meshes (posed by `pa`, `pb`) within `max_dist`, in the
/// world frame, as parry's `closest_points` gives them: a simultaneous descent of both BVHs that
/// drops a pair of nodes once a lower bound of their distance — their boxes' distance, each box
/// bounded by an axis-aligned box in the other's frame, the larger of the two — is not below the
/// best distance found so far; each pair of triangles left is tried with the plane test of
/// [`meshes_touch`] and then parry's triangle–triangle closest points. parry instead searches
/// the second mesh once per triangle of the first.
pub(crate) fn meshes_closest_points(
    ma: &parry3d_f64::shape::TriMesh,
    pa: &parry3d_f64::math::Pose,
    mb: &parry3d_f64::shape::TriMesh,
    pb: &parry3d_f64::math::Pose,
    max_dist: Real,
    hint: &PairHint,
) -> ClosestPoints {
    use parry3d_f64::math::{Matrix, Vector};
    use std::cell::Cell;
    let rel = pa.inv_mul(pb);
    let r = Matrix::from_quat(rel.rotation);
    let abs_r = Matrix::from_cols(r.x_axis.abs(), r.y_axis.abs(), r.z_axis.abs());
    let t = rel.translation;
    let hair = 1e-9 * (1.0 + t.length() + ma.local_aabb().extents().length() + mb.local_aabb().extents().length());
    let best = Cell::new(max_dist);
    let lower = |n1: &parry3d_f64::partitioning::BvhNode, n2: &parry3d_f64::partitioning::BvhNode| {
        let (c1, h1) = ((n1.mins() + n1.maxs()) * 0.5, (n1.maxs() - n1.mins()) * 0.5);
        let (c2, h2) = ((n2.mins() + n2.maxs()) * 0.5, (n2.maxs() - n2.mins()) * 0.5);
        let d = r * c2 + t - c1;
        let in_a = (d.abs() - h1 - abs_r * h2).max(Vector::ZERO).length();
        let in_b = ((r.transpose() * d).abs() - h2 - abs_r.transpose() * h1).max(Vector::ZERO).length();
        in_a.max(in_b) - hair < best.get()
    };
    let identity = parry3d_f64::math::Pose::IDENTITY;
    let mut found = ClosestPoints::Disjoint;
    let mut closest = None;
    // The last closest pair first: its distance, an upper bound, prunes the descent from the start.
    if let Some((i, j)) = hint.get().filter(|&(i, j)| i < ma.num_triangles() as u32 && j < mb.num_triangles() as u32) {
        match parry3d_f64::query::closest_points(&identity, &ma.triangle(i), &rel, &mb.triangle(j), max_dist) {
            Ok(ClosestPoints::Intersecting) => return ClosestPoints::Intersecting,
            Ok(ClosestPoints::WithinMargin(p1, p2)) => {
                best.set((p1 - p2).length());
                found = ClosestPoints::WithinMargin(p1, p2);
                closest = Some((i, j));
            }
            _ => {}
        }
    }
    for (i, j) in ma.bvh().leaf_pairs(mb.bvh(), lower) {
        let (ta, tb) = (ma.triangle(i), mb.triangle(j));
        let tb_in_a = [rel.transform_point(tb.a), rel.transform_point(tb.b), rel.transform_point(tb.c)];
        let margin = best.get();
        if margin.is_finite()
            && (beyond_plane([ta.a, ta.b, ta.c], tb_in_a, margin) || beyond_plane(tb_in_a, [ta.a, ta.b, ta.c], margin))
        {
            continue;
        }
        match parry3d_f64::query::closest_points(&identity, &ta, &rel, &tb, margin) {
            Ok(ClosestPoints::Intersecting) => {
                hint.set(Some((i, j)));
                return ClosestPoints::Intersecting;
            }
            Ok(ClosestPoints::WithinMargin(p1, p2)) => {
                let d = (p1 - p2).length();
                if d < best.get() {
                    best.set(d);
                    found = ClosestPoints::WithinMargin(p1, p2);
                    closest = Some((i, j));
                }
            }
            _ => {}
        }
    }
    if closest.is_some() {
        hint.set(closest);
    }
    found.transform_by(pa, pa)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A torus about z (major radius `big`, minor `small`), `n × m` quads cut in triangles: a
    /// non-convex closed mesh whose pairs touch in many places.
    fn torus(big: Real, small: Real, n: u32, m: u32) -> SharedShape {
        let tau = std::f64::consts::TAU;
        let mut points = Vec::new();
        for i in 0..n {
            for j in 0..m {
                let (u, v) = (tau * Real::from(i) / Real::from(n), tau * Real::from(j) / Real::from(m));
                let rho = big + small * v.cos();
                points.push(parry3d_f64::math::Vector::new(rho * u.cos(), rho * u.sin(), small * v.sin()));
            }
        }
        let mut triangles = Vec::new();
        for i in 0..n {
            for j in 0..m {
                let k = |a: u32, b: u32| (a % n) * m + (b % m);
                triangles.push([k(i, j), k(i + 1, j), k(i + 1, j + 1)]);
                triangles.push([k(i, j), k(i + 1, j + 1), k(i, j + 1)]);
            }
        }
        SharedShape::trimesh(points, triangles).expect("a valid torus")
    }

    /// A deterministic pose near the origin: a rotation from a random unit quaternion and a
    /// translation in a cube of half side `reach` (xorshift, so the test needs no crate).
    fn pose(state: &mut u64, reach: Real) -> parry3d_f64::math::Pose {
        let mut next = || {
            *state ^= *state << 13;
            *state ^= *state >> 7;
            *state ^= *state << 17;
            (*state >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
        };
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(next(), next(), next(), next()));
        let t = Vector3::new(next(), next(), next()) * reach;
        parry_pose(&Isometry3::from_parts(t.into(), q))
    }

    /// parry's own verdict on the whole shapes: the reference the descents must reproduce.
    fn parry_verdict(
        pa: &parry3d_f64::math::Pose,
        a: &SharedShape,
        pb: &parry3d_f64::math::Pose,
        b: &SharedShape,
        padding: Real,
    ) -> bool {
        if padding == 0.0 {
            parry3d_f64::query::intersection_test(pa, a.as_ref(), pb, b.as_ref()).expect("supported").intersecting
        } else {
            !matches!(
                parry3d_f64::query::closest_points(pa, a.as_ref(), pb, b.as_ref(), padding).expect("supported"),
                ClosestPoints::Disjoint
            )
        }
    }

    /// The separating-axis gap over the 15 axes, each normalized and projected directly: the
    /// reference of the C = Aᵀ B form.
    fn generic_box_gap(a: &PlacedBox, b: &PlacedBox, stop: Real) -> Real {
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

    #[test]
    fn box_gaps_match_the_axes_projected_directly_and_never_exceed_the_distance() {
        let mut state = 0x1234_5678_9abc_def1;
        let mut separated = 0;
        for k in 0..2000 {
            let (pa, pb) = (pose(&mut state, 0.2), pose(&mut state, 0.4));
            let half = |s: &mut u64| {
                let p = pose(s, 0.1);
                Vector3::new(p.translation.x.abs() + 0.01, p.translation.y.abs() + 1e-6, p.translation.z.abs() + 0.05)
            };
            let (ha, hb) = (half(&mut state), half(&mut state));
            let iso = |p: &parry3d_f64::math::Pose| {
                let (q, t) = (p.rotation, p.translation);
                Isometry3::from_parts(
                    Vector3::new(t.x, t.y, t.z).into(),
                    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z)),
                )
            };
            let a = PlacedBox::new(&iso(&pa), &(Vector3::zeros(), ha));
            let b = PlacedBox::new(&iso(&pb), &(Vector3::zeros(), hb));
            let (got, reference) = (box_gap(&a, &b), generic_box_gap(&a, &b, Real::INFINITY));
            assert!((got - reference).abs() < 1e-12, "box pair {k}: {got} against {reference}");
            // A lower bound of the boxes' distance (parry's, 0 when they overlap).
            let (ca, cb) = (SharedShape::cuboid(ha.x, ha.y, ha.z), SharedShape::cuboid(hb.x, hb.y, hb.z));
            let distance = parry3d_f64::query::distance(&pa, ca.as_ref(), &pb, cb.as_ref()).expect("boxes").distance;
            assert!(got <= distance + 1e-12, "box pair {k}: gap {got} above the distance {distance}");
            if distance > 0.0 {
                separated += 1;
                // The stop: the first axis past it ends the search, with its gap.
                let stopped = box_gap_past(&a, &b, 0.0);
                assert!(stopped <= got + 1e-15 && (stopped > 0.0) == (got > 0.0), "box pair {k}");
            }
        }
        assert!(separated > 300, "{separated} separated pairs");
    }

    #[test]
    fn triangles_apart_on_the_common_line_never_intersect() {
        // Random triangle pairs in a 2 cm cube, against parry's triangle–triangle test.
        let mut state = 0x0bad_5eed_1234_5678;
        let point = |s: &mut u64| pose(s, 0.01).translation;
        let (mut apart, mut intersecting) = (0, 0);
        for k in 0..20_000 {
            let u = [point(&mut state), point(&mut state), point(&mut state)];
            let v = [point(&mut state), point(&mut state), point(&mut state)];
            let id = parry3d_f64::math::Pose::IDENTITY;
            let (tu, tv) = (
                parry3d_f64::shape::Triangle::new(u[0], u[1], u[2]),
                parry3d_f64::shape::Triangle::new(v[0], v[1], v[2]),
            );
            let hit = parry3d_f64::query::intersection_test(&id, &tu, &id, &tv).expect("triangles").intersecting;
            if apart_on_common_line(u, v) {
                assert!(!hit, "triangle pair {k}: called apart, parry finds them intersecting");
                apart += 1;
            }
            intersecting += usize::from(hit);
        }
        // Most pairs that cut each other's planes without meeting are told apart here.
        assert!(apart > 2_000 && intersecting > 2_000, "{apart} apart, {intersecting} intersecting");
    }

    #[test]
    fn mesh_pairs_match_parrys_verdict_on_random_poses() {
        let (a, b) = (torus(0.1, 0.03, 24, 12), torus(0.08, 0.02, 20, 10));
        let mut state = 0x9e37_79b9_7f4a_7c15;
        let (mut counts, mut near) = ([0usize; 2], 0);
        let hint = PairHint::default();
        for k in 0..600 {
            let padding = if k % 2 == 0 { 0.0 } else { 0.01 };
            let (pa, pb) = (pose(&mut state, 0.02), pose(&mut state, 0.16));
            let expected = parry_verdict(&pa, &a, &pb, &b, padding);
            let (ma, mb) = (a.as_trimesh().expect("mesh"), b.as_trimesh().expect("mesh"));
            assert_eq!(meshes_touch(ma, &pa, mb, &pb, padding), expected, "pose {k}, padding {padding}");
            counts[usize::from(expected)] += 1;
            // The closest points within 5 cm: parry's answer, the same distance.
            let reference =
                parry3d_f64::query::closest_points(&pa, a.as_ref(), &pb, b.as_ref(), 0.05).expect("supported");
            // Cold, and warm from the last pose's closest triangles: the same answer.
            let cold = meshes_closest_points(ma, &pa, mb, &pb, 0.05, &PairHint::default());
            let warm = meshes_closest_points(ma, &pa, mb, &pb, 0.05, &hint);
            assert_eq!(cold, warm, "pose {k}");
            match (reference, warm) {
                (ClosestPoints::WithinMargin(a1, a2), ClosestPoints::WithinMargin(b1, b2)) => {
                    let (da, db) = ((a1 - a2).length(), (b1 - b2).length());
                    assert!((da - db).abs() < 1e-9, "pose {k}: {da} against {db}");
                    assert!(a.distance_to_point(&pa, b1, false) < 1e-9);
                    assert!(b.distance_to_point(&pb, b2, false) < 1e-9);
                    near += 1;
                }
                (reference, got) => assert_eq!(reference, got, "pose {k}"),
            }
        }
        assert!(near > 30, "{near} pairs within 5 cm");
        // Both verdicts occur often: the poses straddle contact.
        assert!(counts[0] > 100 && counts[1] > 100, "{counts:?}");
    }

    #[test]
    fn a_mesh_against_primitives_matches_parrys_verdict_on_random_poses() {
        let mesh = ExactShape { shape: torus(0.1, 0.03, 24, 12), offset: Isometry3::identity() };
        let primitives = [
            Primitive::Box { half_extents: Vector3::new(0.3, 0.2, 0.01) },
            Primitive::Cylinder { radius: 0.02, half_height: 0.15 },
            Primitive::Sphere { radius: 0.04 },
            Primitive::Capsule { radius: 0.015, half_height: 0.1 },
        ];
        let mut state = 0x2545_f491_4f6c_dd1d;
        for p in &primitives {
            let solid = exact_primitive(p);
            let (mut counts, mut near) = ([0usize; 2], 0);
            for k in 0..400 {
                let padding = if k % 2 == 0 { 0.0 } else { 0.01 };
                let (pm, ps) = (pose(&mut state, 0.02), pose(&mut state, 0.15));
                let ps = ps * parry_pose(&solid.offset);
                let expected = parry_verdict(&pm, &mesh.shape, &ps, &solid.shape, padding);
                let m = mesh.shape.as_trimesh().expect("mesh");
                let got = mesh_touches_solid(m, &pm, solid.shape.as_ref(), &ps, padding);
                assert_eq!(got, Some(expected), "{p:?}, pose {k}, padding {padding}");
                counts[usize::from(expected)] += 1;
                // The closest points within 5 cm: parry's answer, the same distance.
                let reference =
                    parry3d_f64::query::closest_points(&pm, mesh.shape.as_ref(), &ps, solid.shape.as_ref(), 0.05)
                        .expect("supported");
                let got = mesh_solid_closest_points(m, &pm, solid.shape.as_ref(), &ps, 0.05).expect("bounded");
                match (reference, got) {
                    (ClosestPoints::WithinMargin(a1, a2), ClosestPoints::WithinMargin(b1, b2)) => {
                        let (da, db) = ((a1 - a2).length(), (b1 - b2).length());
                        assert!((da - db).abs() < 1e-9, "{p:?}, pose {k}: {da} against {db}");
                        // Witness points: on the mesh's surface and the solid's.
                        assert!(mesh.shape.distance_to_point(&pm, b1, false) < 1e-9);
                        assert!(solid.shape.distance_to_point(&ps, b2, false) < 1e-9);
                        near += 1;
                    }
                    (reference, got) => assert_eq!(reference, got, "{p:?}, pose {k}"),
                }
            }
            assert!(counts[0] > 50 && counts[1] > 50 && near > 30, "{p:?}: {counts:?}, {near} within 5 cm");
        }
        // A halfspace is unbounded: parry's own test answers it.
        let plane = exact_primitive(&Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 });
        let m = mesh.shape.as_trimesh().expect("mesh");
        let id = parry3d_f64::math::Pose::IDENTITY;
        assert_eq!(mesh_touches_solid(m, &id, plane.shape.as_ref(), &id, 0.0), None);
    }
}
