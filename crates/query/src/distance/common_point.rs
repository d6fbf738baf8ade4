//! Overlap shown without a solve: a point common to two posed bodies, checked by evaluating both
//! polynomials, from the segment between their interior points and their facing support points.

use crate::fast_eval::FastPosed;
use sublevel_core::body::{Body, PosedBody};
use sublevel_core::math::{Isometry3, Point3, Vector3};

/// A point common to the two posed bodies (world coordinates, meters), found without a solve on
/// the segment between their interior points: A's interior point when it lies in B, B's when it
/// lies in A, else the middle of the stretch where the bodies' radial tables put the segment
/// inside both. Every candidate is checked by evaluating both polynomials (p_a'(z) ≤ 1 and
/// p_b'(z) ≤ 1), so a returned point proves that the bodies overlap (distance 0); `None` proves
/// nothing, and a solver decides. Costs at most four value evaluations and two radial look-ups.
///
/// The overlap certificate of a collide query whose cheap lower bounds do not clear it
/// (`sublevel_scene::planner::collide_cheap`): the overlapping pairs are the costliest ones of a
/// cold distance solve (a separated run that fails, then the growth measure; paper §IV-A, eq.
/// "distance"), and an overlap shows no separating axis, so only a common point decides them
/// cheaply.
pub fn segment_common_point(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Point3> {
    let (ba, bb) = (PosedBody::new(a, pose_a), PosedBody::new(b, pose_b));
    let (fa, fb) = (FastPosed::new(&ba), FastPosed::new(&bb));
    let inside_both = |z: &Vector3| fa.value(z) <= 1.0 && fb.value(z) <= 1.0;
    segment_candidates(&ba, &bb, &inside_both).map(Point3::from)
}

/// [`segment_common_point`]'s candidates (world coordinates) checked by `inside_both`.
fn segment_candidates(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    inside_both: &impl Fn(&Vector3) -> bool,
) -> Option<Vector3> {
    let (ca, cb) = (ba.interior_point(), bb.interior_point());
    if let Some(z) = [ca, cb].into_iter().find(inside_both) {
        return Some(z);
    }
    // The segment meets A on about [ca, x0] and B on about [y0, cb]: when B's crossing comes
    // first, the two stretches overlap around their middle.
    let (x0, y0) = (ba.boundary_towards(&cb), bb.boundary_towards(&ca));
    let z = (x0 + y0) * 0.5;
    ((y0 - ca).norm_squared() < (x0 - ca).norm_squared() && inside_both(&z)).then_some(z)
}

/// A point common to the two posed bodies (world coordinates, meters), found without a solve:
/// [`segment_common_point`]'s candidates on the segment between the interior points, then the
/// bodies' support points facing each other along that segment — A's towards B, B's towards A
/// (read off their support tables, [`PosedBody::support`]) — and the middle between them. Every
/// candidate is checked by evaluating both polynomials, so a returned point proves overlap
/// (distance 0); `None` proves nothing. Costs at most ten value evaluations and four table
/// look-ups.
///
/// Where bodies overlap off the segment between their interior points (elongated or bent shapes
/// meeting at an angle), the facing support points often lie in the other body: on the cold
/// chair_101 / human_10 poses of `sublevel-lab bench` they prove most of the overlapping pairs the
/// segment misses, each of which a collide query would otherwise solve (a failed separated run and
/// the growth measure, the costliest cold solves).
pub fn common_point(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Point3> {
    let (ba, bb) = (PosedBody::new(a, pose_a), PosedBody::new(b, pose_b));
    let (fa, fb) = (FastPosed::new(&ba), FastPosed::new(&bb));
    let inside_both = |z: &Vector3| fa.value(z) <= 1.0 && fb.value(z) <= 1.0;
    if let Some(z) = segment_candidates(&ba, &bb, &inside_both) {
        return Some(Point3::from(z));
    }
    let axis = bb.interior_point() - ba.interior_point();
    let (x, y) = (ba.support(&axis)?, bb.support(&-axis)?);
    [x, y, (x + y) * 0.5].into_iter().find(inside_both).map(Point3::from)
}
