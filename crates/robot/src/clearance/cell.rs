//! One cell of a two-mesh clearance table: the byte stored for the meshes' distance, found by a
//! search that only looks for that byte (pairs that cannot lower it are dropped, boxes and
//! triangles separated by axes across their edges first), never an exact distance it does not need.

use super::PairHint;
use sublevel_core::math::Real;

/// The value stored for the meshes' distance `d` (meters): ⌊(d − 10⁻⁹)/unit⌋, 255 beyond the
/// cap of 255 steps (5.1 cm).
pub(super) fn stored(d: Real, unit: Real) -> u8 {
    if d > 255.0 * unit {
        255
    } else {
        ((d - 1e-9) / unit).floor().clamp(0.0, 255.0) as u8
    }
}

/// A distance at or above which a triangle pair cannot lower a cell's value below `k`
/// ([`stored`]`(d) < k` needs `d < threshold(k)`).
fn threshold(k: u8, unit: Real) -> Real {
    Real::from(k) * unit + 1e-9
}

type PVec = parry3d_f64::math::Vector;

/// Whether every vertex of `v` lies farther than `margin` on one side of the plane of `u` (so
/// the triangles are farther apart than `margin`); false for a degenerate `u`.
fn beyond(u: [PVec; 3], v: [PVec; 3], margin: Real) -> bool {
    let (e1, e2) = (u[1] - u[0], u[2] - u[0]);
    let n = e1.cross(e2);
    let len2 = n.length_squared();
    if len2 <= Real::EPSILON * Real::EPSILON * e1.length_squared() * e2.length_squared() || len2 == 0.0 {
        return false;
    }
    let reach = margin * len2.sqrt();
    let s = v.map(|x| n.dot(x - u[0]));
    s.iter().all(|&s| s > reach) || s.iter().all(|&s| s < -reach)
}

/// Whether one of the nine axes across an edge of each box separates boxes (half sides `h1`
/// about the origin along the axes, and `h2` about `d` along the columns of `r`, `r[k][j]` the
/// k-th coordinate of the j-th column) by more than `margin` (Gottschalk's box test, with the
/// gap divided by the axis' length).
fn boxes_apart(r: &[[Real; 3]; 3], d: &PVec, h1: PVec, h2: PVec, margin: Real) -> bool {
    let (d, h1, h2) = ([d.x, d.y, d.z], [h1.x, h1.y, h1.z], [h2.x, h2.y, h2.z]);
    for i in 0..3 {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        for j in 0..3 {
            let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
            let len2 = 1.0 - r[i][j] * r[i][j];
            if len2 <= 1e-12 {
                continue;
            }
            let ra = h1[i1] * r[i2][j].abs() + h1[i2] * r[i1][j].abs();
            let rb = h2[j1] * r[i][j2].abs() + h2[j2] * r[i][j1].abs();
            let sep = (d[i2] * r[i1][j] - d[i1] * r[i2][j]).abs();
            if sep - ra - rb > margin * len2.sqrt() {
                return true;
            }
        }
    }
    false
}

/// Whether some edge–edge axis separates triangles `u` and `v` by more than `margin` (then they
/// are farther apart than `margin`: a separation along a unit axis bounds the distance below).
fn edges_apart(u: &[PVec; 3], v: &[PVec; 3], margin: Real) -> bool {
    for i in 0..3 {
        let e = u[(i + 1) % 3] - u[i];
        for j in 0..3 {
            let axis = e.cross(v[(j + 1) % 3] - v[j]);
            let len2 = axis.length_squared();
            if len2 <= 1e-30 {
                continue;
            }
            let (pu, pv) = (u.map(|x| axis.dot(x)), v.map(|x| axis.dot(x)));
            let (ulo, uhi) = (pu[0].min(pu[1]).min(pu[2]), pu[0].max(pu[1]).max(pu[2]));
            let (vlo, vhi) = (pv[0].min(pv[1]).min(pv[2]), pv[0].max(pv[1]).max(pv[2]));
            let reach = margin * len2.sqrt();
            if vlo - uhi > reach || ulo - vhi > reach {
                return true;
            }
        }
    }
    false
}

/// A cell's value for two meshes posed by `pa`, `pb` ([`stored`] of their distance, exactly as
/// the exact stage's distance gives it), and whether they intersect (then the value is 0 and the
/// caller looks for the touching triangles).
///
/// The descent of both meshes' trees is the exact stage's (`exact::meshes_closest_points`: box
/// bounds in both frames, the plane test, parry's triangle distance), but it only looks for what
/// can lower the value: a pair of nodes or triangles goes on only while its bound is below
/// [`threshold`] of the value found so far rather than below the best distance itself, and a
/// triangle pair is also dropped when an axis across two of their edges separates them beyond
/// it, before parry's distance. A dropped pair is farther than the threshold, so it could not
/// lower the value. Once the value is 0 only an intersecting pair is looked for.
pub(super) fn mesh_cell(
    ma: &parry3d_f64::shape::TriMesh,
    pa: &parry3d_f64::math::Pose,
    mb: &parry3d_f64::shape::TriMesh,
    pb: &parry3d_f64::math::Pose,
    unit: Real,
    hint: &PairHint,
) -> (u8, bool) {
    use parry3d_f64::query::ClosestPoints;
    use std::cell::Cell;
    let rel = pa.inv_mul(pb);
    let r = parry3d_f64::math::Matrix::from_quat(rel.rotation);
    let abs_r = parry3d_f64::math::Matrix::from_cols(r.x_axis.abs(), r.y_axis.abs(), r.z_axis.abs());
    let (rt, abs_rt) = (r.transpose(), abs_r.transpose());
    let ra = [
        [r.x_axis.x, r.y_axis.x, r.z_axis.x],
        [r.x_axis.y, r.y_axis.y, r.z_axis.y],
        [r.x_axis.z, r.y_axis.z, r.z_axis.z],
    ];
    let t = rel.translation;
    let hair = 1e-9 * (1.0 + t.length() + ma.local_aabb().extents().length() + mb.local_aabb().extents().length());
    // The threshold of the value so far (the smallest positive number once it is 0).
    let margin = Cell::new(threshold(255, unit));
    let value = Cell::new(255u8);
    let identity = parry3d_f64::math::Pose::IDENTITY;
    let mut nearest = (Real::INFINITY, None);
    // One triangle pair; true when they intersect.
    let mut pair = |i: u32, j: u32| -> bool {
        let m = margin.get();
        let (ta, tb) = (ma.triangle(i), mb.triangle(j));
        let u = [ta.a, ta.b, ta.c];
        let v = [rel.transform_point(tb.a), rel.transform_point(tb.b), rel.transform_point(tb.c)];
        if beyond(u, v, m) || beyond(v, u, m) {
            return false;
        }
        if edges_apart(&u, &v, m) {
            return false;
        }
        match parry3d_f64::query::closest_points(&identity, &ta, &rel, &tb, m) {
            Ok(ClosestPoints::Intersecting) => return true,
            Ok(ClosestPoints::WithinMargin(p1, p2)) => {
                let d = (p1 - p2).length();
                // The exact stage calls a distance of 0 a contact too.
                if d <= 0.0 {
                    return true;
                }
                if d < nearest.0 {
                    nearest = (d, Some((i, j)));
                }
                let k = stored(d, unit).min(value.get());
                value.set(k);
                margin.set(if k == 0 { Real::MIN_POSITIVE } else { threshold(k, unit) });
            }
            _ => {}
        }
        false
    };
    let start = hint.get().filter(|&(i, j)| i < ma.num_triangles() as u32 && j < mb.num_triangles() as u32);
    if let Some((i, j)) = start {
        if pair(i, j) {
            return (0, true);
        }
    }
    let lower = |n1: &parry3d_f64::partitioning::BvhNode, n2: &parry3d_f64::partitioning::BvhNode| {
        let (c1, h1) = ((n1.mins() + n1.maxs()) * 0.5, (n1.maxs() - n1.mins()) * 0.5);
        let (c2, h2) = ((n2.mins() + n2.maxs()) * 0.5, (n2.maxs() - n2.mins()) * 0.5);
        let d = r * c2 + t - c1;
        let m = margin.get() + hair;
        let m2 = m * m;
        (d.abs() - h1 - abs_r * h2).max(PVec::ZERO).length_squared() < m2
            && ((rt * d).abs() - h2 - abs_rt * h1).max(PVec::ZERO).length_squared() < m2
            && !boxes_apart(&ra, &d, h1, h2, m)
    };
    for (i, j) in ma.bvh().leaf_pairs(mb.bvh(), lower) {
        if Some((i, j)) != start && pair(i, j) {
            hint.set(Some((i, j)));
            return (0, true);
        }
    }
    if let (_, Some(p)) = nearest {
        hint.set(Some(p));
    }
    (value.get(), false)
}
