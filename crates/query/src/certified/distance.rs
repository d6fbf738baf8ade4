//! The policy of the module docs for distance queries: Newton's answer, its level-0 certificate
//! or separating-hyperplane certificate, the SDP fallback, and the SDP lower bound for nonconvex
//! bodies (paper eqs. "distance", "distance.lasserre").

use super::{
    in_body, is_nonconvex, project_to_body, summary, values_agree, CertificateKind, CertificateSummary,
    CertifiedDistance, CertifyMode, CertifyParams,
};
use crate::distance::{distance, DistanceResult, DistanceWarmStart};
use crate::growth::GrowthWarmStart;
use crate::newton::SolveStatus;
use crate::sdp_certificate::{
    certify_distance_with_params, certify_separation, CertificateParams, DistanceCertificate,
};
use std::ops::ControlFlow;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};

fn distance_summary(c: &DistanceCertificate, newton: Option<Real>, cert: &CertificateParams) -> CertificateSummary {
    summary(
        c.squared_distance,
        c.verified_squared_distance,
        c.gram_min_eigenvalue,
        c.solve_seconds,
        c.solver_status,
        newton,
        cert,
    )
}

/// Whether `x` (world frame) lies in both posed bodies up to
/// [`CertificateParams::overlap_point_tolerance`]: a primal certificate that the distance is 0.
fn common_point_certifies_overlap(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    x: &Point3,
    cert: &CertificateParams,
) -> bool {
    in_body(a, pose_a, x, cert) && in_body(b, pose_b, x, cert)
}

/// Distance between body `a` under `pose_a` and body `b` under `pose_b` with the policy of the
/// module docs. `warm` and `params.newton` are passed to [`distance`], `params.certificate` to the
/// certificate.
///
/// Never fails: a certificate that cannot be solved leaves `certificate = None` (and, when Newton
/// did not converge either, `converged = false`).
pub fn certified_distance(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    warm: Option<&DistanceWarmStart>,
    params: &CertifyParams,
    mode: CertifyMode,
) -> CertifiedDistance {
    let cert = &params.certificate;
    let nonconvex = is_nonconvex(a, b);
    if nonconvex && mode != CertifyMode::NewtonOnly {
        return distance_lower_bound(a, pose_a, b, pose_b, cert);
    }
    let newton = distance(a, pose_a, b, pose_b, warm, &params.newton);
    certify_newton_distance(a, pose_a, b, pose_b, newton, params, mode)
}

/// [`certified_distance`] from Newton's answer `newton` of the same query (e.g. one of the batch
/// solver's, [`crate::batch::cold_distances`]), for two convex bodies (a nonconvex body's
/// answer is the SDP's lower bound, which [`certified_distance`] gives without Newton).
pub fn certify_newton_distance(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    newton: DistanceResult,
    params: &CertifyParams,
    mode: CertifyMode,
) -> CertifiedDistance {
    let cert = &params.certificate;
    let newton_ok = newton.status.converged();
    let newton = match CertifiedDistance::without_sdp(newton, newton_ok, is_nonconvex(a, b), mode) {
        ControlFlow::Break(answer) => return answer,
        ControlFlow::Continue(newton) => newton,
    };
    let n2 = newton.distance * newton.distance;
    let Ok(c) = certify_distance_with_params(a, pose_a, b, pose_b, cert) else {
        return CertifiedDistance::newton(newton, None, newton_ok);
    };
    let mut s = distance_summary(&c, Some(n2), cert);
    if newton_ok && newton.overlapping && common_point_certifies_overlap(a, pose_a, b, pose_b, &newton.witness_a, cert)
    {
        // Distance 0 is proven by the common witness point itself (objective 0 at a feasible
        // point, and a squared distance is ≥ 0); the SDP only has to not contradict it.
        s.agrees = s.bound <= cert.agreement_absolute;
        s.relative_gap = 0.0;
    }
    if newton_ok && !s.agrees && !newton.overlapping {
        // The joint program disagrees with a converged separated answer: check Newton's witnesses
        // by the separating-hyperplane certificate (one body per program, better conditioned).
        if let Some(h) = separation_summary(a, pose_a, b, pose_b, &newton, cert, &s) {
            return CertifiedDistance::newton(newton, Some(h), true);
        }
    }
    if newton_ok && (s.agrees || !s.verified) {
        // Agreement, or an unverified certificate that cannot overrule a converged KKT point.
        return CertifiedDistance::newton(newton, Some(s), true);
    }
    let witnesses = c.witnesses.or_else(|| {
        let (x, y) = c.moment_witnesses?;
        Some((project_to_body(a, pose_a, &x, cert)?, project_to_body(b, pose_b, &y, cert)?))
    });
    let converged = s.verified && witnesses.is_some();
    let c = DistanceCertificate { witnesses, ..c };
    let result = distance_from_certificate(&c, pose_a, pose_b, newton, a.scale().max(b.scale()), converged, cert);
    CertifiedDistance::sdp_fallback(result, s, converged)
}

/// The separating-hyperplane certificate of Newton's separated answer
/// ([`crate::sdp_certificate::certify_separation`]) as a summary of the squared distance, when it
/// is verified and agrees with Newton (its witnesses lie on their bodies, so ‖x − y‖ is also an
/// upper bound); `None` otherwise. `joint` is the joint program's summary (its time is added).
fn separation_summary(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    newton: &DistanceResult,
    cert: &CertificateParams,
    joint: &CertificateSummary,
) -> Option<CertificateSummary> {
    let on_body = |body: &Body, pose: &Isometry3, p: &Point3| {
        (body.value_at(&(pose.inverse() * p)) - 1.0).abs() <= cert.witness_feasibility_tolerance
    };
    if !(on_body(a, pose_a, &newton.witness_a) && on_body(b, pose_b, &newton.witness_b)) {
        return None;
    }
    let h = certify_separation(a, pose_a, b, pose_b, &newton.witness_a, &newton.witness_b, cert).ok()?;
    let n2 = newton.distance * newton.distance;
    let square = |d: Real| d.max(0.0) * d.max(0.0);
    let mut s = summary(
        square(h.lower_bound),
        square(h.verified_lower_bound),
        h.gram_min_eigenvalue,
        joint.solve_seconds + h.solve_seconds,
        h.solver_status,
        Some(n2),
        cert,
    );
    s.kind = CertificateKind::SeparatingHyperplane;
    (s.verified && s.agrees).then_some(s)
}

/// The distance answer carried by a certificate (value, moment witnesses, multipliers as warm start);
/// `newton` supplies the solver diagnostics and the points when the moments are unusable.
fn distance_from_certificate(
    c: &DistanceCertificate,
    pose_a: &Isometry3,
    pose_b: &Isometry3,
    newton: DistanceResult,
    length: Real,
    verified: bool,
    cert: &CertificateParams,
) -> DistanceResult {
    let d = c.squared_distance.max(0.0).sqrt();
    // Overlap: γ = 0 up to the SDP's tolerance, relative to the bodies' size
    // ([`CertificateParams::overlap_relative`]).
    let overlapping = c.squared_distance <= cert.overlap_relative * length * length;
    let (x, y) = c.witnesses.unwrap_or((newton.witness_a, newton.witness_b));
    let normal = unit_normal(&x, &y, overlapping);
    let (x, y) = if overlapping { (x, x) } else { (x, y) };
    let warm_start = DistanceWarmStart {
        a_local: (pose_a.inverse() * x).coords,
        b_local: (pose_b.inverse() * y).coords,
        multipliers: [c.tau, c.xi],
        valid: verified && !overlapping && c.tau > 0.0 && c.xi > 0.0,
        growth: GrowthWarmStart::default(),
        relative_pose: pose_a.inverse() * pose_b,
        trail: Default::default(),
    };
    DistanceResult {
        distance: if overlapping { 0.0 } else { d },
        witness_a: x,
        witness_b: y,
        normal,
        overlapping,
        warm_start: std::sync::Arc::new(warm_start),
        ..newton
    }
}

/// The unit normal (y − x)/‖y − x‖ of an SDP answer's witnesses; zero when it is `overlapping`
/// or the witnesses coincide.
fn unit_normal(x: &Point3, y: &Point3, overlapping: bool) -> Vector3 {
    let diff = y - x;
    if overlapping || diff.norm() == 0.0 {
        Vector3::zeros()
    } else {
        diff / diff.norm()
    }
}

fn distance_lower_bound(
    a: &Body,
    pose_a: &Isometry3,
    b: &Body,
    pose_b: &Isometry3,
    cert: &CertificateParams,
) -> CertifiedDistance {
    let empty = DistanceResult {
        distance: 0.0,
        witness_a: pose_a * a.interior_point(),
        witness_b: pose_b * b.interior_point(),
        normal: Vector3::zeros(),
        overlapping: true,
        status: SolveStatus::Stalled,
        iterations: 0,
        kkt_residual: Real::NAN,
        warm_started: false,
        warm_start: Default::default(),
    };
    let Ok(c) = certify_distance_with_params(a, pose_a, b, pose_b, cert) else {
        // Distance 0 is a (trivial) valid lower bound.
        return CertifiedDistance::sdp_lower_bound(empty, None, false, false);
    };
    let s = distance_summary(&c, None, cert);
    let bound = c.verified_squared_distance.min(c.squared_distance).max(0.0);
    let length = a.scale().max(b.scale());
    // Witness candidates: from the kernel of the Gram matrix (paper §IV-A, when one-dimensional)
    // and from the first-order moments. Of those lying in their bodies, the one whose distance
    // comes closest to the bound (interior-point kernels are accurate only to about the square
    // root of the solver's tolerance, the moments to the tolerance); else the first available.
    let is_feasible = |(x, y): &(Point3, Point3)| {
        a.value_at(&(pose_a.inverse() * x)) <= 1.0 + cert.witness_feasibility_tolerance
            && b.value_at(&(pose_b.inverse() * y)) <= 1.0 + cert.witness_feasibility_tolerance
    };
    let candidates = [c.kernel_witnesses, c.moment_witnesses];
    let gap = |(x, y): &&(Point3, Point3)| ((y - x).norm_squared() - bound).abs();
    let chosen = candidates
        .iter()
        .flatten()
        .filter(|w| is_feasible(w))
        .min_by(|p, q| gap(p).total_cmp(&gap(q)))
        .or(candidates.iter().flatten().next());
    let (x, y) = chosen.copied().unwrap_or((empty.witness_a, empty.witness_b));
    let feasible = chosen.is_some_and(is_feasible);
    let tight = feasible && s.verified && values_agree((y - x).norm_squared(), bound, cert);
    let overlapping = bound <= cert.overlap_relative * length * length;
    let normal = unit_normal(&x, &y, overlapping);
    let result = DistanceResult {
        distance: if overlapping { 0.0 } else { bound.sqrt() },
        witness_a: x,
        witness_b: y,
        normal,
        overlapping,
        ..empty
    };
    let converged = s.verified;
    CertifiedDistance::sdp_lower_bound(result, Some(s), tight, converged)
}
