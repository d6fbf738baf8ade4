//! The policy of the module docs for the growth measure d(p₁‖p₂): Newton's answer, its level-0
//! certificate, the SDP fallback, and the SDP lower bound for nonconvex bodies (paper eq.
//! "overlap").

use super::{
    in_body, inactive_growth_agrees, is_nonconvex, project_to_body, summary, values_agree, CertificateSummary,
    CertifiedGrowth, CertifyMode, CertifyParams,
};
use crate::growth::{growth, GrowthResult, GrowthWarmStart};
use crate::newton::SolveStatus;
use crate::sdp_certificate::{certify_growth_with_params, CertificateParams, GrowthCertificate};
use std::ops::ControlFlow;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real};

fn growth_summary(c: &GrowthCertificate, newton: Option<Real>, cert: &CertificateParams) -> CertificateSummary {
    summary(c.value, c.verified_value, c.gram_min_eigenvalue, c.solve_seconds, c.solver_status, newton, cert)
}

/// d(p₁‖p₂) for body `p1` under `pose1` and body `p2` under `pose2` with the policy of the module
/// docs. `warm` and `params.newton` are passed to [`growth`], `params.certificate` to the certificate.
/// Never fails (see [`certified_distance`](super::certified_distance)).
pub fn certified_growth(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    warm: Option<&GrowthWarmStart>,
    params: &CertifyParams,
    mode: CertifyMode,
) -> CertifiedGrowth {
    let cert = &params.certificate;
    let nonconvex = is_nonconvex(p1, p2);
    if nonconvex && mode != CertifyMode::NewtonOnly {
        return growth_lower_bound(p1, pose1, p2, pose2, cert);
    }
    let newton = growth(p1, pose1, p2, pose2, warm, &params.newton);
    let newton_ok = newton.status.converged();
    let newton = match CertifiedGrowth::without_sdp(newton, newton_ok, nonconvex, mode) {
        ControlFlow::Break(answer) => return answer,
        ControlFlow::Continue(newton) => newton,
    };
    let Ok(c) = certify_growth_with_params(p1, pose1, p2, pose2, cert) else {
        return CertifiedGrowth::newton(newton, None, newton_ok);
    };
    let mut s = growth_summary(&c, Some(newton.value), cert);
    if newton_ok && newton.multiplier == 0.0 && in_body(p2, pose2, &newton.minimizer, cert) {
        // The inactive constraint: the value is p₁'s own minimum (module docs), attained at a point
        // of body 2; the SDP only has to not contradict it.
        s.agrees = inactive_growth_agrees(&s, newton.value, cert);
        s.relative_gap = 0.0;
    }
    if newton_ok && (s.agrees || !s.verified) {
        return CertifiedGrowth::newton(newton, Some(s), true);
    }
    let minimizer = c.minimizer.or_else(|| project_to_body(p2, pose2, &c.moment_minimizer?, cert));
    let converged = s.verified && minimizer.is_some();
    let x = minimizer.unwrap_or(newton.minimizer);
    let result = GrowthResult {
        value: c.value,
        minimizer: x,
        multiplier: c.tau.max(0.0),
        warm_start: std::sync::Arc::new(GrowthWarmStart {
            local: (pose2.inverse() * x).coords,
            multiplier: c.tau.max(0.0),
            valid: converged,
            relative_pose: pose2.inverse() * pose1,
            trail: Default::default(),
        }),
        ..newton
    };
    CertifiedGrowth::sdp_fallback(result, s, converged)
}

fn growth_lower_bound(
    p1: &Body,
    pose1: &Isometry3,
    p2: &Body,
    pose2: &Isometry3,
    cert: &CertificateParams,
) -> CertifiedGrowth {
    let empty = GrowthResult {
        value: 0.0,
        minimizer: pose2 * p2.interior_point(),
        multiplier: 0.0,
        status: SolveStatus::Stalled,
        iterations: 0,
        kkt_residual: Real::NAN,
        warm_started: false,
        warm_start: Default::default(),
    };
    let Ok(c) = certify_growth_with_params(p1, pose1, p2, pose2, cert) else {
        // p₁ ≥ 0 is not guaranteed for every body, so no trivial bound: report unconverged.
        return CertifiedGrowth::sdp_lower_bound(
            GrowthResult { value: Real::NEG_INFINITY, ..empty },
            None,
            false,
            false,
        );
    };
    let s = growth_summary(&c, None, cert);
    let bound = c.verified_value.min(c.value);
    let x: Point3 = c.moment_minimizer.unwrap_or(empty.minimizer);
    let feasible =
        c.moment_minimizer.is_some() && p2.value_at(&(pose2.inverse() * x)) <= 1.0 + cert.witness_feasibility_tolerance;
    let tight = feasible && s.verified && values_agree(p1.value_at(&(pose1.inverse() * x)), bound, cert);
    let result = GrowthResult { value: bound, minimizer: x, multiplier: c.tau.max(0.0), ..empty };
    let converged = s.verified;
    CertifiedGrowth::sdp_lower_bound(result, Some(s), tight, converged)
}
