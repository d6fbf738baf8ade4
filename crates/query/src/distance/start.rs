//! Where the separated Newton run starts: the cold starts read off the bodies' support and radial
//! tables ([`sublevel_core::poly::SupportTable`], [`sublevel_core::poly::RadialTable`]), and the
//! log-barrier path from the interior points, the globally convergent fallback.

use crate::fast_eval::FastPosed;
use crate::newton::{barrier_path, spheres_apart, NewtonParams};
use nalgebra::{SMatrix, SVector};
use sublevel_core::body::PosedBody;
use sublevel_core::math::{Real, Vector3};

/// The cold start of the speculative separated Newton run, in the frame of `ba`: when the bounding
/// spheres are disjoint (and neither body is an ellipsoid), the support points towards each other,
/// refined once towards the optimal normal ([`bisector_start`]); otherwise, when the segment
/// between the interior points shows separation, the closer of the
/// support and the segment's boundary points ([`segment_start`]); `None` when neither shows
/// separation (the growth measure decides).
///
/// Past 2d = 2 the support points alone start as well as the closer of them and the segment's
/// points and spare two radial look-ups; an ellipsoid keeps the comparison (exact for spheres).
///
/// Inlined, with its look-ups, into each build of [`distance()`](super::distance()): out of line
/// it would be compiled for the baseline x86-64 target (SSE2, no FMA) even inside the AVX2 build,
/// with a call per look-up. The arithmetic is the same, so are the starts, bit for bit.
#[inline(always)]
pub(crate) fn cold_start(ba: &PosedBody<'_>, bb: &PosedBody<'_>) -> Option<(Vector3, Vector3)> {
    let (ca, cb) = (ba.interior_point(), bb.interior_point());
    let apart = spheres_apart(ba, bb);
    let quadric = ba.body.degree() <= 2 || bb.body.degree() <= 2;
    let axis = cb - ca;
    match (apart && !quadric).then(|| supports_towards(ba, bb, &axis)).flatten() {
        Some(start) => Some(bisector_start(ba, bb, start, &axis)),
        None => segment_start(ba, bb, &ca, &cb, apart),
    }
}

/// The support points h_A(n) and h_B(−n) for n = `axis` ([`PosedBody::support`]), when both
/// bodies have them.
#[inline(always)]
fn supports_towards(ba: &PosedBody<'_>, bb: &PosedBody<'_>, axis: &Vector3) -> Option<(Vector3, Vector3)> {
    Some((ba.support(axis)?, bb.support(&-axis)?))
}

/// One refinement of the facing support points `start` = (h_A(n), h_B(−n)) for n = `axis`: the
/// support points for the bisector of n and the direction y − x between them, kept when they are
/// closer to each other (the optimal normal makes y − x parallel to n; the bisector damps the
/// fixed-point step n ← y − x, which overshoots on the interpolated support map).
///
/// One round saves about half a Newton iteration per separated cold query on the chair / human
/// cold poses of `sublevel-lab bench`; past it the table's interpolation, not the direction, limits
/// the start.
#[inline(always)]
fn bisector_start(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    start: (Vector3, Vector3),
    axis: &Vector3,
) -> (Vector3, Vector3) {
    let d = start.1 - start.0;
    let n = d / d.norm() + axis / axis.norm();
    match supports_towards(ba, bb, &n) {
        Some(s) if (s.1 - s.0).norm_squared() < d.norm_squared() => s,
        _ => start,
    }
}

/// The cold start of a pair shown separated — by disjoint bounding spheres (`apart`), else by the
/// segment between its interior points `ca`, `cb` (each outside the other body, and A's boundary
/// crossing before B's) — through [`support_start`]; `None` when neither shows it.
#[inline(always)]
fn segment_start(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    ca: &Vector3,
    cb: &Vector3,
    apart: bool,
) -> Option<(Vector3, Vector3)> {
    if !apart {
        let (fa, fb) = (FastPosed::new(ba), FastPosed::new(bb));
        if !(fb.value(ca) > 1.0 && fa.value(cb) > 1.0) {
            return None;
        }
    }
    let x0 = ba.boundary_towards(cb);
    let y0 = bb.boundary_towards(ca);
    // With disjoint spheres A's crossing comes first (each lies in its own sphere).
    (apart || (x0 - ca).norm_squared() < (y0 - ca).norm_squared()).then(|| support_start(ba, bb, x0, y0, &(cb - ca)))
}

/// The cold start of a pair separated along the segment between its interior points: the support
/// points x = h_A(n), y = h_B(−n) for n = `axis` (the direction from A's interior point to B's),
/// read off the bodies' support tables ([`PosedBody::support`]), when they are closer to each other
/// than the radial start (`x0`, `y0`), else the radial start.
///
/// On the chair / human cold poses of `sublevel-lab bench` this start takes about one Newton iteration
/// fewer than the radial start. One look-up per body: further alternations n ← y − x overshoot on
/// the interpolated support map, and the table's interpolation, not only the direction, limits the
/// start.
#[inline(always)]
fn support_start(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    x0: Vector3,
    y0: Vector3,
    axis: &Vector3,
) -> (Vector3, Vector3) {
    match (ba.support(axis), bb.support(&-axis)) {
        // Both starts are (nearly) feasible pairs: keep the closer one (the radial start is exact
        // for spheres, whose witnesses lie on the line of centers).
        (Some(x), Some(y)) if (y - x).norm_squared() < (y0 - x0).norm_squared() => (x, y),
        _ => (x0, y0),
    }
}

/// Log-barrier path `min ‖x − y‖² − t(log(1 − p_a') + log(1 − p_b'))` from the interior points,
/// t → 0 ([`barrier_path`]); returns the final points, multiplier estimates t/(1 − p') and the
/// iterations spent.
pub(super) fn barrier(
    ba: &PosedBody<'_>,
    bb: &PosedBody<'_>,
    params: &NewtonParams,
) -> (Vector3, Vector3, [Real; 2], usize) {
    let (x, y) = (ba.interior_point(), bb.interior_point());
    let f0 = (x - y).norm_squared();
    let phi = |(x, y): &(Vector3, Vector3), t: Real| -> Option<Real> {
        let (ga, gb) = (1.0 - ba.value(x), 1.0 - bb.value(y));
        (ga > 0.0 && gb > 0.0).then(|| (x - y).norm_squared() - t * (ga.ln() + gb.ln()))
    };
    let center = |p: &(Vector3, Vector3), t: Real| {
        let (x, y) = p;
        let (ea, eb) = (ba.eval(x), bb.eval(y));
        let (sa, sb) = (1.0 - ea.value, 1.0 - eb.value);
        let d = x - y;
        let ga = d * 2.0 + ea.gradient * (t / sa);
        let gb = -d * 2.0 + eb.gradient * (t / sb);
        let two = nalgebra::Matrix3::<Real>::identity() * 2.0;
        let haa = two + ea.hessian * (t / sa) + ea.gradient * ea.gradient.transpose() * (t / (sa * sa));
        let hbb = two + eb.hessian * (t / sb) + eb.gradient * eb.gradient.transpose() * (t / (sb * sb));
        let mut h = SMatrix::<Real, 6, 6>::zeros();
        h.fixed_view_mut::<3, 3>(0, 0).copy_from(&haa);
        h.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-two));
        h.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-two));
        h.fixed_view_mut::<3, 3>(3, 3).copy_from(&hbb);
        let g = SVector::<Real, 6>::from_column_slice(&[ga.x, ga.y, ga.z, gb.x, gb.y, gb.z]);
        let chol = nalgebra::Cholesky::new(h)?;
        let step = -chol.solve(&g);
        let dec = -g.dot(&step);
        let (dx, dy) = (Vector3::new(step[0], step[1], step[2]), Vector3::new(step[3], step[4], step[5]));
        Some(((dx, dy), dec, phi(p, t)))
    };
    let done = |(x, y): &(Vector3, Vector3), t: Real| t < 1e-12 * (1.0 + (x - y).norm_squared());
    let ((x, y), t, it) = barrier_path((x, y), f0.max(1e-12), params, center, phi, done);
    let sa = (1.0 - ba.value(&x)).max(Real::MIN_POSITIVE);
    let sb = (1.0 - bb.value(&y)).max(Real::MIN_POSITIVE);
    (x, y, [t / sa, t / sb], it)
}
