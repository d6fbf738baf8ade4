//! Certified answers: the Newton / active-set answer with the level-0 sos certificate attached on
//! request, an SDP fallback when Newton fails, and SDP lower bounds for nonconvex bodies (paper §IV,
//! eqs. "distance", "distance.lasserre", "overlap"; §IV-A on nonconvex bodies).
//!
//! # Policy
//!
//! | situation | answer | `source` | `converged` |
//! |---|---|---|---|
//! | sos-convex bodies, Newton converged, [`CertifyMode::Newton`] | Newton's | `Newton` | true |
//! | sos-convex bodies, Newton converged, [`CertifyMode::Certify`], agrees with the SDP | Newton's | `Newton` | true |
//! | sos-convex bodies, Newton did not converge (either mode) | the SDP's value and moment witnesses | `SdpFallback` | SDP verified |
//! | [`CertifyMode::Certify`], Newton converged but disagrees with a verified SDP | the SDP's | `SdpFallback` | true |
//! | either body nonconvex (`report.nonconvex`) | the SDP's verified lower bound | `SdpLowerBound` | SDP verified |
//! | [`CertifyMode::NewtonOnly`], Newton did not converge or a body is nonconvex | Newton's, `needs_sdp = true` (no SDP solved) | `Newton` | false |
//!
//! No answer is silently wrong: an answer that is neither a converged Newton answer nor a verified
//! SDP answer has `converged = false`, and a disagreement is visible in
//! [`CertificateSummary::agrees`].
//!
//! # Agreement rule
//!
//! Values are compared in the program's own objective: the **squared** distance (m²) and d(p₁‖p₂)
//! (dimensionless). Newton's value `n` and the SDP bound `s` agree when
//! `|n − s| ≤ agreement_relative · |s|` or `|n − s| ≤ agreement_absolute` (fields of
//! [`CertificateParams`], default 10⁻⁶ and 10⁻⁹; the absolute branch covers values near 0:
//! touching and overlapping pairs, where the SDP's bound is 0 up to its tolerance).
//! An overlapping distance answer (0) is certified by its common witness point: when it lies in both
//! bodies (p(x) ≤ 1 + [`CertificateParams::overlap_point_tolerance`] for each), the value 0 is
//! attained at a feasible point and is a lower bound of any squared distance, so it is optimal; the
//! SDP then only has to not contradict it (bound ≤ `agreement_absolute`). This covers overlaps where the SDP ends
//! `AlmostSolved` a few 1e-9 below 0 with an unverifiable a-posteriori bound.
//! A growth answer whose constraint is inactive (multiplier 0: p₁'s unconstrained minimizer lies
//! in body 2, [`growth`](mod@crate::growth) case 1) is certified the same way: p₁ is convex, so a
//! stationary point is its global minimum, and it lies in body 2, so that minimum is d(p₁‖p₂). The
//! SDP then only has to not contradict it: the smaller of its bound and its verified bound at most
//! `agreement_absolute` above the value. On badly scaled bodies (the stability suite's
//! 1 × 1 × 10⁻³ m slab, p₁'s coefficients up to 10⁶) Clarabel may end `AlmostSolved` with a bound
//! a few 10⁻⁹ above the value 0 and a negative verified bound, depending on the host's BLAS
//! kernels.
//!
//! # Verified SDP
//!
//! An SDP answer is *verified* when Clarabel ended `Solved` or `AlmostSolved` and the a-posteriori
//! bound (module [`super::sdp_certificate`], "A-posteriori check") is within the agreement rule of
//! the bound itself (a certificate whose corrected Gram matrices are PSD up to that slack).
//!
//! # Nonconvex bodies
//!
//! Newton's KKT points are only local for nonconvex bodies, so they are not used. The level-0 sos
//! program is still a valid relaxation: its verified γ is a lower bound on the squared distance
//! (resp. on d(p₁‖p₂)). The witnesses are the first-order moments of the dual (moment) solution (the
//! points the relaxation's optimal measure is concentrated on when it is tight: then the moment
//! matrix has rank one and the witnesses span the kernel of the Gram matrix, paper §IV-A). When they
//! are feasible (each p'(x) ≤ 1 + [`CertificateParams::witness_feasibility_tolerance`]) and their
//! objective meets the bound (within the agreement rule), the bound is attained: `tight = true` and
//! the lower bound is the answer.
//!
//! [`certified_distance`] and [`certify_newton_distance`] apply the policy to distance queries,
//! [`certified_growth`] to the growth measure. Every tolerance of the policy is a field of
//! [`CertificateParams`] (`CertifyParams::certificate`).

mod distance;
mod growth;
#[cfg(test)]
mod tests;

pub use distance::{certified_distance, certify_newton_distance};
pub use growth::certified_growth;

use crate::distance::DistanceResult;
use crate::growth::GrowthResult;
use crate::newton::NewtonParams;
use crate::sdp_certificate::CertificateParams;
use std::ops::ControlFlow;
use sublevel_core::body::Body;
use sublevel_core::conic::SdpStatus;
use sublevel_core::math::{Isometry3, Point3, Real};

/// The default absolute tolerance of the agreement rule ([`CertificateParams::agreement_absolute`]),
/// in the objective's units (m² for the squared distance; dimensionless for d(p₁‖p₂)): the floor
/// of [`CertificateSummary::relative_gap`]'s denominator under the default settings.
pub const AGREEMENT_ABSOLUTE: Real = CertificateParams::DEFAULT.agreement_absolute;

/// When to solve the level-0 SDP certificate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CertifyMode {
    /// Fast path (default): the SDP runs only when Newton did not converge (or a body is nonconvex).
    #[default]
    Newton,
    /// Always solve the SDP, attach it, and compare it with Newton's answer.
    Certify,
    /// Newton only, never an SDP (for callers on an async worker): when Newton converged the
    /// answer is [`CertifyMode::Newton`]'s; when it did not (or a body is nonconvex) the answer is
    /// Newton's unconverged one with `source = Newton`, `converged = false`, no certificate and
    /// [`Certified::needs_sdp`] set. The caller then asks again in [`CertifyMode::Newton`] off
    /// the async workers, which gives the answer the SDP fallback gives.
    NewtonOnly,
}

/// Where a certified answer's value and points come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum AnswerSource {
    /// The Newton / active-set solver (converged; in [`CertifyMode::Certify`] also checked).
    Newton,
    /// The level-0 SDP, because Newton did not converge or disagreed with a verified SDP.
    SdpFallback,
    /// The level-0 SDP's lower bound, because a body is nonconvex (paper §IV-A).
    SdpLowerBound,
}

/// Which certificate a [`CertificateSummary`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CertificateKind {
    /// The level-0 sos relaxation of the query (paper §IV-A).
    Level0,
    /// A separating hyperplane through Newton's witness points, each body's support excess
    /// bounded by a small SDP (separated distance queries).
    SeparatingHyperplane,
}

impl CertificateKind {
    /// The text form (`"level0"`, `"separating_hyperplane"`).
    pub fn as_str(&self) -> &'static str {
        match self {
            CertificateKind::Level0 => "level0",
            CertificateKind::SeparatingHyperplane => "separating_hyperplane",
        }
    }
}

/// The level-0 certificate of one query, in the answer's units.
#[derive(Clone, Debug, PartialEq)]
pub struct CertificateSummary {
    /// The SDP bound γ*: the squared distance (m²) or d(p₁‖p₂) (dimensionless).
    pub bound: Real,
    /// The a-posteriori verified lower bound, same units (see [`super::sdp_certificate`]).
    pub verified_bound: Real,
    /// Whether Newton's value agrees with `bound` by the module's agreement rule (always false for
    /// nonconvex bodies, where Newton is not run).
    pub agrees: bool,
    /// |newton − bound| / max(|bound|, [`CertificateParams::agreement_absolute`]) (0 when Newton
    /// was not run).
    pub relative_gap: Real,
    /// Smallest eigenvalue over the corrected Gram blocks (objective units; ≥ 0: exact sos identity).
    pub gram_min_eigenvalue: Real,
    /// Seconds inside Clarabel.
    pub solve_seconds: Real,
    /// Clarabel's final status (`Solved` or `AlmostSolved` for a verified certificate).
    pub solver_status: SdpStatus,
    /// Which certificate: the level-0 sos relaxation of the query, or a separating hyperplane
    /// through Newton's witness points (cheaper; tried first for separated distance queries).
    pub kind: CertificateKind,
    /// Whether the certificate is verified (module docs, "Verified SDP").
    pub verified: bool,
    /// Newton's value that was compared (squared distance or d(p₁‖p₂)), when Newton ran; kept even
    /// when the answer was replaced by the SDP's.
    pub newton_value: Option<Real>,
}

/// A certified answer: the solver's result `R` with where it comes from and its certificate.
#[derive(Clone, Debug)]
pub struct Certified<R> {
    /// The answer. For `source != Newton` its value and points are the SDP's (distance: `distance`,
    /// witnesses, normal, `overlapping`; growth: `value`, `minimizer`, `multiplier`), while
    /// `status`, `iterations`, `kkt_residual` stay Newton's when Newton ran; the warm start is
    /// seeded from the SDP's solution when it is verified.
    pub result: R,
    /// Where the answer comes from.
    pub source: AnswerSource,
    /// The certificate, when one was solved.
    pub certificate: Option<CertificateSummary>,
    /// True when the answer is only a lower bound (nonconvex bodies): the value is ≤ the true one,
    /// and a distance's `overlapping` then means "not proven separated".
    pub lower_bound: bool,
    /// Lower bounds only: the moment witnesses are feasible and attain the bound (so it is exact).
    pub tight: bool,
    /// True when the answer is a converged Newton answer or a verified SDP answer.
    pub converged: bool,
    /// [`CertifyMode::NewtonOnly`] only: the answer needs the SDP (Newton did not converge or a
    /// body is nonconvex), which was not solved; ask again in [`CertifyMode::Newton`].
    pub needs_sdp: bool,
}

impl<R> Certified<R> {
    /// Newton's answer as it is (`source = Newton`, not a lower bound).
    pub fn newton(result: R, certificate: Option<CertificateSummary>, converged: bool) -> Self {
        Self {
            result,
            source: AnswerSource::Newton,
            certificate,
            lower_bound: false,
            tight: false,
            converged,
            needs_sdp: false,
        }
    }

    /// An answer that could not be solved (a refused or failed query): `result` as a lower bound,
    /// not converged, no certificate.
    pub fn unresolved(result: R) -> Self {
        Self { lower_bound: true, ..Self::newton(result, None, false) }
    }

    /// Newton's unconverged answer of [`CertifyMode::NewtonOnly`], marked as needing the SDP.
    fn sdp_needed(result: R) -> Self {
        Self { needs_sdp: true, ..Self::newton(result, None, false) }
    }

    /// The SDP's answer in place of Newton's (`source = SdpFallback`), with its certificate.
    fn sdp_fallback(result: R, certificate: CertificateSummary, converged: bool) -> Self {
        Self {
            source: AnswerSource::SdpFallback,
            certificate: Some(certificate),
            ..Self::newton(result, None, converged)
        }
    }

    /// The SDP's lower bound for a nonconvex body (`source = SdpLowerBound`), with its
    /// certificate when one was solved; `tight` when its witnesses attain it.
    fn sdp_lower_bound(result: R, certificate: Option<CertificateSummary>, tight: bool, converged: bool) -> Self {
        Self {
            source: AnswerSource::SdpLowerBound,
            certificate,
            lower_bound: true,
            tight,
            ..Self::newton(result, None, converged)
        }
    }

    /// The answer of the policy (module docs) for Newton's answer `newton` (converged when
    /// `newton_ok`) where it needs no SDP: [`CertifyMode::NewtonOnly`] with an unconverged answer or
    /// a nonconvex body (`nonconvex`), or a converged answer outside [`CertifyMode::Certify`].
    /// Otherwise `newton` comes back, for the SDP.
    fn without_sdp(newton: R, newton_ok: bool, nonconvex: bool, mode: CertifyMode) -> ControlFlow<Self, R> {
        if mode == CertifyMode::NewtonOnly && (nonconvex || !newton_ok) {
            return ControlFlow::Break(Self::sdp_needed(newton));
        }
        if newton_ok && mode != CertifyMode::Certify {
            return ControlFlow::Break(Self::newton(newton, None, true));
        }
        ControlFlow::Continue(newton)
    }
}

/// A certified distance answer (paper eq. "distance" / "distance.lasserre").
pub type CertifiedDistance = Certified<DistanceResult>;

/// A certified growth answer d(p₁‖p₂) (paper eq. "overlap").
pub type CertifiedGrowth = Certified<GrowthResult>;

/// Settings of a certified query: the Newton solver's and the certificate's.
#[derive(Clone, Copy, Debug, Default)]
pub struct CertifyParams {
    /// Tolerances of the Newton / active-set solver.
    pub newton: NewtonParams,
    /// Settings of the level-0 SDP certificate.
    pub certificate: CertificateParams,
}

/// The agreement rule of the module docs, with the tolerances of `params`
/// ([`CertificateParams::agreement_relative`], [`CertificateParams::agreement_absolute`]).
pub fn values_agree(newton: Real, sdp: Real, params: &CertificateParams) -> bool {
    let gap = (newton - sdp).abs();
    gap <= params.agreement_relative * sdp.abs() || gap <= params.agreement_absolute
}

fn relative_gap(newton: Real, sdp: Real, params: &CertificateParams) -> Real {
    (newton - sdp).abs() / sdp.abs().max(params.agreement_absolute)
}

/// The summary of a certificate (bound, verified bound, least Gram eigenvalue, seconds, Clarabel's
/// status) against Newton's value `newton`, by the agreement rule of `params`.
fn summary(
    bound: Real,
    verified_bound: Real,
    eig: Real,
    seconds: Real,
    status: SdpStatus,
    newton: Option<Real>,
    params: &CertificateParams,
) -> CertificateSummary {
    let verified = values_agree(verified_bound, bound, params) && status.is_usable();
    CertificateSummary {
        bound,
        verified_bound,
        agrees: newton.is_some_and(|n| values_agree(n, bound, params)),
        relative_gap: newton.map_or(0.0, |n| relative_gap(n, bound, params)),
        gram_min_eigenvalue: eig,
        solve_seconds: seconds,
        solver_status: status,
        kind: CertificateKind::Level0,
        verified,
        newton_value: newton,
    }
}

/// The agreement rule for a growth answer whose constraint is inactive (module docs): the SDP's
/// lower bound does not exceed Newton's `value` by more than
/// [`CertificateParams::agreement_absolute`], judged by the smaller of its bound and its
/// a-posteriori verified bound (the rigorous one: on badly scaled bodies Clarabel may end
/// `AlmostSolved` with a bound a few 10⁻⁹ too high).
fn inactive_growth_agrees(s: &CertificateSummary, value: Real, params: &CertificateParams) -> bool {
    s.bound.min(s.verified_bound) <= value + params.agreement_absolute
}

/// Whether `x` (world frame) lies in `body` posed by `pose`, up to
/// [`CertificateParams::overlap_point_tolerance`].
fn in_body(body: &Body, pose: &Isometry3, x: &Point3, params: &CertificateParams) -> bool {
    body.value_at(&(pose.inverse() * x)) <= 1.0 + params.overlap_point_tolerance
}

fn is_nonconvex(a: &Body, b: &Body) -> bool {
    a.report.nonconvex || b.report.nonconvex
}

/// A moment-recovered point moved onto `body` (under `pose`) when it lies slightly outside: Newton
/// steps on p'(x) = 1 along the gradient (the least displacement to first order). The moments of a
/// thin body (axis ratio 1e-3) are accurate to ~1e-8 m, which can exceed the level tolerance
/// [`CertificateParams::witness_feasibility_tolerance`] by itself. `None` when the point is not
/// within [`CertificateParams::projection_max_shift`] × scale of the body or the steps do not
/// reach p' ≤ 1 + 1e-12.
fn project_to_body(body: &Body, pose: &Isometry3, x: &Point3, params: &CertificateParams) -> Option<Point3> {
    let posed = body.posed(pose);
    let start = x.coords;
    let mut y = start;
    for _ in 0..50 {
        let e = posed.eval(&y);
        if !e.value.is_finite() {
            return None;
        }
        if e.value <= 1.0 + 1e-12 {
            return ((y - start).norm() <= params.projection_max_shift * body.scale()).then_some(Point3::from(y));
        }
        let g2 = e.gradient.norm_squared();
        if g2 == 0.0 {
            return None;
        }
        // Aim slightly inside the level set so rounding lands on the feasible side.
        y -= e.gradient * ((e.value - (1.0 - 1e-13)) / g2);
    }
    None
}
