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
//! `|n − s| ≤ AGREEMENT_RELATIVE · |s|` or `|n − s| ≤ AGREEMENT_ABSOLUTE` (the absolute branch covers
//! values near 0: touching and overlapping pairs, where the SDP's bound is 0 up to its tolerance).
//! An overlapping distance answer (0) is certified by its common witness point: when it lies in both
//! bodies (p(x) ≤ 1 + [`OVERLAP_POINT_TOLERANCE`] for each), the value 0 is attained at a feasible
//! point and is a lower bound of any squared distance, so it is optimal; the SDP then only has to
//! not contradict it (bound ≤ `AGREEMENT_ABSOLUTE`). This covers overlaps where the SDP ends
//! `AlmostSolved` a few 1e-9 below 0 with an unverifiable a-posteriori bound.
//! A growth answer whose constraint is inactive (multiplier 0: p₁'s unconstrained minimizer lies
//! in body 2, [`super::growth`] case 1) is certified the same way: p₁ is convex, so a stationary
//! point is its global minimum, and it lies in body 2, so that minimum is d(p₁‖p₂). The SDP then
//! only has to not contradict it: the smaller of its bound and its verified bound at most
//! `AGREEMENT_ABSOLUTE` above the value. On the stability suite's 1 × 1 × 10⁻³ m slab (p₁'s
//! coefficients up to 10⁶) Clarabel ended `AlmostSolved` with a bound 2.4·10⁻⁹ above the value 0
//! and a verified bound −4·10⁻⁸ on one host (its BLAS kernels) and agreed on another.
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
//! are feasible (each p'(x) ≤ 1 + [`WITNESS_FEASIBILITY_TOLERANCE`]) and their objective meets the
//! bound (within the agreement rule), the bound is attained: `tight = true` and the lower bound
//! is the answer.

use super::distance::{distance, DistanceResult, DistanceWarmStart};
use super::growth::{growth, GrowthResult, GrowthWarmStart};
use super::newton::{NewtonParams, SolveStatus};
use super::sdp_certificate::{
    certify_distance_with_params, certify_growth_with_params, certify_separation, CertificateParams,
    DistanceCertificate, GrowthCertificate, WITNESS_FEASIBILITY_TOLERANCE,
};
use crate::body::Body;
use crate::conic::SdpStatus;
use crate::math::{Isometry3, Point3, Real, Vector3};

/// Relative tolerance of the agreement rule (module docs).
pub const AGREEMENT_RELATIVE: Real = 1e-6;

/// Absolute tolerance of the agreement rule, in the objective's units (m² for the squared
/// distance; dimensionless for d(p₁‖p₂)).
pub const AGREEMENT_ABSOLUTE: Real = 1e-9;

/// Slack on p(x) ≤ 1 when a common witness point certifies an overlap (distance 0): the point lies
/// in both bodies scaled about their interior by at most this relative amount.
pub const OVERLAP_POINT_TOLERANCE: Real = 1e-9;

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
    /// |newton − bound| / max(|bound|, [`AGREEMENT_ABSOLUTE`]) (0 when Newton was not run).
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
    fn newton(result: R, certificate: Option<CertificateSummary>, converged: bool) -> Self {
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

    /// Newton's unconverged answer of [`CertifyMode::NewtonOnly`], marked as needing the SDP.
    fn sdp_needed(result: R) -> Self {
        Self { needs_sdp: true, ..Self::newton(result, None, false) }
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

/// The agreement rule of the module docs.
pub fn values_agree(newton: Real, sdp: Real) -> bool {
    let gap = (newton - sdp).abs();
    gap <= AGREEMENT_RELATIVE * sdp.abs() || gap <= AGREEMENT_ABSOLUTE
}

fn relative_gap(newton: Real, sdp: Real) -> Real {
    (newton - sdp).abs() / sdp.abs().max(AGREEMENT_ABSOLUTE)
}

fn summary(
    bound: Real,
    verified_bound: Real,
    eig: Real,
    seconds: Real,
    status: SdpStatus,
    newton: Option<Real>,
) -> CertificateSummary {
    let verified = values_agree(verified_bound, bound) && status.is_usable();
    CertificateSummary {
        bound,
        verified_bound,
        agrees: newton.is_some_and(|n| values_agree(n, bound)),
        relative_gap: newton.map_or(0.0, |n| relative_gap(n, bound)),
        gram_min_eigenvalue: eig,
        solve_seconds: seconds,
        solver_status: status,
        kind: CertificateKind::Level0,
        verified,
        newton_value: newton,
    }
}

fn distance_summary(c: &DistanceCertificate, newton: Option<Real>) -> CertificateSummary {
    summary(
        c.squared_distance,
        c.verified_squared_distance,
        c.gram_min_eigenvalue,
        c.solve_seconds,
        c.solver_status,
        newton,
    )
}

fn growth_summary(c: &GrowthCertificate, newton: Option<Real>) -> CertificateSummary {
    summary(c.value, c.verified_value, c.gram_min_eigenvalue, c.solve_seconds, c.solver_status, newton)
}

/// The agreement rule for a growth answer whose constraint is inactive (module docs): the SDP's
/// lower bound does not exceed Newton's `value` by more than [`AGREEMENT_ABSOLUTE`], judged by the
/// smaller of its bound and its a-posteriori verified bound (the rigorous one: on badly scaled
/// bodies Clarabel may end `AlmostSolved` with a bound a few 10⁻⁹ too high).
fn inactive_growth_agrees(s: &CertificateSummary, value: Real) -> bool {
    s.bound.min(s.verified_bound) <= value + AGREEMENT_ABSOLUTE
}

/// Whether `x` (world frame) lies in both posed bodies up to [`OVERLAP_POINT_TOLERANCE`]: a primal
/// certificate that the distance is 0.
fn common_point_certifies_overlap(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3, x: &Point3) -> bool {
    in_body(a, pose_a, x) && in_body(b, pose_b, x)
}

/// Whether `x` (world frame) lies in `body` posed by `pose`, up to [`OVERLAP_POINT_TOLERANCE`].
fn in_body(body: &Body, pose: &Isometry3, x: &Point3) -> bool {
    body.value_at(&(pose.inverse() * x)) <= 1.0 + OVERLAP_POINT_TOLERANCE
}

fn is_nonconvex(a: &Body, b: &Body) -> bool {
    a.report.nonconvex || b.report.nonconvex
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
/// solver's, [`crate::query::batch::cold_distances`]), for two convex bodies (a nonconvex body's
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
    let nonconvex = is_nonconvex(a, b);
    let newton_ok = newton.status.converged();
    if mode == CertifyMode::NewtonOnly && (nonconvex || !newton_ok) {
        return CertifiedDistance::sdp_needed(newton);
    }
    if newton_ok && mode != CertifyMode::Certify {
        return CertifiedDistance::newton(newton, None, true);
    }
    let n2 = newton.distance * newton.distance;
    let Ok(c) = certify_distance_with_params(a, pose_a, b, pose_b, cert) else {
        return CertifiedDistance::newton(newton, None, newton_ok);
    };
    let mut s = distance_summary(&c, Some(n2));
    if newton_ok && newton.overlapping && common_point_certifies_overlap(a, pose_a, b, pose_b, &newton.witness_a) {
        // Distance 0 is proven by the common witness point itself (objective 0 at a feasible
        // point, and a squared distance is ≥ 0); the SDP only has to not contradict it.
        s.agrees = s.bound <= AGREEMENT_ABSOLUTE;
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
        Some((project_to_body(a, pose_a, &x)?, project_to_body(b, pose_b, &y)?))
    });
    let converged = s.verified && witnesses.is_some();
    let c = DistanceCertificate { witnesses, ..c };
    let result = distance_from_certificate(&c, pose_a, pose_b, newton, a.scale().max(b.scale()), converged);
    CertifiedDistance {
        result,
        source: AnswerSource::SdpFallback,
        certificate: Some(s),
        lower_bound: false,
        tight: false,
        converged,
        needs_sdp: false,
    }
}

/// The separating-hyperplane certificate of Newton's separated answer
/// ([`super::sdp_certificate::certify_separation`]) as a summary of the squared distance, when it
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
        (body.value_at(&(pose.inverse() * p)) - 1.0).abs() <= WITNESS_FEASIBILITY_TOLERANCE
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
) -> DistanceResult {
    let d = c.squared_distance.max(0.0).sqrt();
    // Overlap: γ = 0 up to the SDP's tolerance, relative to the bodies' size.
    let overlapping = c.squared_distance <= OVERLAP_RELATIVE * length * length;
    let (x, y) = c.witnesses.unwrap_or((newton.witness_a, newton.witness_b));
    let diff = y - x;
    let normal = if overlapping || diff.norm() == 0.0 { Vector3::zeros() } else { diff / diff.norm() };
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

/// A moment-recovered point moved onto `body` (under `pose`) when it lies slightly outside: Newton
/// steps on p'(x) = 1 along the gradient (the least displacement to first order). The moments of a
/// thin body (axis ratio 1e-3) are accurate to ~1e-8 m, which can exceed the level tolerance
/// [`WITNESS_FEASIBILITY_TOLERANCE`] by itself. `None` when the point is not within
/// [`PROJECTION_MAX_SHIFT`] × scale of the body or the steps do not reach p' ≤ 1 + 1e-12.
fn project_to_body(body: &Body, pose: &Isometry3, x: &Point3) -> Option<Point3> {
    let posed = body.posed(pose);
    let start = x.coords;
    let mut y = start;
    for _ in 0..50 {
        let e = posed.eval(&y);
        if !e.value.is_finite() {
            return None;
        }
        if e.value <= 1.0 + 1e-12 {
            return ((y - start).norm() <= PROJECTION_MAX_SHIFT * body.scale()).then_some(Point3::from(y));
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

/// Largest displacement (relative to the body's scale) [`project_to_body`] accepts.
const PROJECTION_MAX_SHIFT: Real = 1e-4;

/// γ ≤ this × (larger body scale)² counts as touching or overlapping in an SDP answer.
const OVERLAP_RELATIVE: Real = 1e-10;

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
        return CertifiedDistance {
            result: empty,
            source: AnswerSource::SdpLowerBound,
            certificate: None,
            lower_bound: true,
            tight: false,
            converged: false,
            needs_sdp: false,
        };
    };
    let s = distance_summary(&c, None);
    let bound = c.verified_squared_distance.min(c.squared_distance).max(0.0);
    let length = a.scale().max(b.scale());
    // Witness candidates: from the kernel of the Gram matrix (paper §IV-A, when one-dimensional)
    // and from the first-order moments. Of those lying in their bodies, the one whose distance
    // comes closest to the bound (interior-point kernels are accurate only to about the square
    // root of the solver's tolerance, the moments to the tolerance); else the first available.
    let is_feasible = |(x, y): &(Point3, Point3)| {
        a.value_at(&(pose_a.inverse() * x)) <= 1.0 + WITNESS_FEASIBILITY_TOLERANCE
            && b.value_at(&(pose_b.inverse() * y)) <= 1.0 + WITNESS_FEASIBILITY_TOLERANCE
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
    let tight = feasible && s.verified && values_agree((y - x).norm_squared(), bound);
    let overlapping = bound <= OVERLAP_RELATIVE * length * length;
    let diff = y - x;
    let normal = if overlapping || diff.norm() == 0.0 { Vector3::zeros() } else { diff / diff.norm() };
    let result = DistanceResult {
        distance: if overlapping { 0.0 } else { bound.sqrt() },
        witness_a: x,
        witness_b: y,
        normal,
        overlapping,
        ..empty
    };
    CertifiedDistance {
        result,
        source: AnswerSource::SdpLowerBound,
        converged: s.verified,
        needs_sdp: false,
        certificate: Some(s),
        lower_bound: true,
        tight,
    }
}

/// d(p₁‖p₂) for body `p1` under `pose1` and body `p2` under `pose2` with the policy of the module
/// docs. `warm` and `params.newton` are passed to [`growth`], `params.certificate` to the certificate.
/// Never fails (see
/// [`certified_distance`]).
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
    if mode == CertifyMode::NewtonOnly && (nonconvex || !newton_ok) {
        return CertifiedGrowth::sdp_needed(newton);
    }
    if newton_ok && mode != CertifyMode::Certify {
        return CertifiedGrowth::newton(newton, None, true);
    }
    let Ok(c) = certify_growth_with_params(p1, pose1, p2, pose2, cert) else {
        return CertifiedGrowth::newton(newton, None, newton_ok);
    };
    let mut s = growth_summary(&c, Some(newton.value));
    if newton_ok && newton.multiplier == 0.0 && in_body(p2, pose2, &newton.minimizer) {
        // The inactive constraint: the value is p₁'s own minimum (module docs), attained at a point
        // of body 2; the SDP only has to not contradict it.
        s.agrees = inactive_growth_agrees(&s, newton.value);
        s.relative_gap = 0.0;
    }
    if newton_ok && (s.agrees || !s.verified) {
        return CertifiedGrowth::newton(newton, Some(s), true);
    }
    let minimizer = c.minimizer.or_else(|| project_to_body(p2, pose2, &c.moment_minimizer?));
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
    CertifiedGrowth {
        result,
        source: AnswerSource::SdpFallback,
        certificate: Some(s),
        lower_bound: false,
        tight: false,
        converged,
        needs_sdp: false,
    }
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
        return CertifiedGrowth {
            result: GrowthResult { value: Real::NEG_INFINITY, ..empty },
            source: AnswerSource::SdpLowerBound,
            certificate: None,
            lower_bound: true,
            tight: false,
            converged: false,
            needs_sdp: false,
        };
    };
    let s = growth_summary(&c, None);
    let bound = c.verified_value.min(c.value);
    let x: Point3 = c.moment_minimizer.unwrap_or(empty.minimizer);
    let feasible =
        c.moment_minimizer.is_some() && p2.value_at(&(pose2.inverse() * x)) <= 1.0 + WITNESS_FEASIBILITY_TOLERANCE;
    let tight = feasible && s.verified && values_agree(p1.value_at(&(pose1.inverse() * x)), bound);
    let result = GrowthResult { value: bound, minimizer: x, multiplier: c.tau.max(0.0), ..empty };
    CertifiedGrowth {
        result,
        source: AnswerSource::SdpLowerBound,
        converged: s.verified,
        needs_sdp: false,
        certificate: Some(s),
        lower_bound: true,
        tight,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{ellipsoid, FitReport};
    use crate::math::{pose_from_parts, UnitQuaternion};
    use crate::poly::Polynomial;

    /// A nonconvex "jack": p(u) = ‖u‖² + k(u₁²u₂² + u₂²u₃² + u₁²u₃²) (sos, not convex for large k),
    /// flagged nonconvex. Star-shaped about 0 with the closed-form boundary radius below.
    fn jack(k: Real, scale: Real) -> Body {
        let terms =
            [([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0), ([2, 2, 0], k), ([0, 2, 2], k), ([2, 0, 2], k)];
        let report = FitReport { nonconvex: true, ..FitReport::default() };
        Body::new(Polynomial::from_terms(4, &terms).unwrap(), [0.0; 3], scale, report).unwrap()
    }

    /// Boundary radius of the jack along unit direction n: r² + k q r⁴ = 1, q = Σ nᵢ²nⱼ².
    fn jack_radius(k: Real, n: &Vector3) -> Real {
        let q = k * (n.x * n.x * n.y * n.y + n.y * n.y * n.z * n.z + n.x * n.x * n.z * n.z);
        if q < 1e-15 {
            return 1.0;
        }
        ((-1.0 + (1.0 + 4.0 * q).sqrt()) / (2.0 * q)).sqrt()
    }

    fn fibonacci(n: usize) -> Vec<Vector3> {
        let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
                let r = (1.0 - z * z).sqrt();
                Vector3::new(r * (golden * i as Real).cos(), r * (golden * i as Real).sin(), z)
            })
            .collect()
    }

    fn jack_boundary(k: Real, scale: Real, pose: &Isometry3, n: usize) -> Vec<Point3> {
        fibonacci(n).iter().map(|d| pose * Point3::from(d * (jack_radius(k, d) * scale))).collect()
    }

    #[test]
    fn jack_is_nonconvex() {
        // (1, 0, 0) and (0, 1, 0) are on the boundary; their midpoint is outside.
        let j = jack(30.0, 1.0);
        assert!((j.value_at(&Point3::new(1.0, 0.0, 0.0)) - 1.0).abs() < 1e-15);
        assert!(j.value_at(&Point3::new(0.5, 0.5, 0.0)) > 2.0);
    }

    #[test]
    fn nonconvex_bodies_get_sdp_lower_bounds_below_brute_force() {
        let k = 30.0;
        let (a, b) = (jack(k, 0.6), jack(k, 0.5));
        let pose_a = Isometry3::from_parts(Default::default(), UnitQuaternion::from_euler_angles(0.2, 0.6, 0.6));
        let pose_b = Isometry3::from_parts(
            nalgebra::Translation3::new(1.6, 0.3, 0.2),
            UnitQuaternion::from_euler_angles(0.4, -0.3, 1.1),
        );
        let params = CertifyParams::default();
        let d = certified_distance(&a, &pose_a, &b, &pose_b, None, &params, CertifyMode::Newton);
        assert_eq!(d.source, AnswerSource::SdpLowerBound);
        assert!(d.lower_bound && d.converged, "{d:?}");
        // Brute force: min over pairs of exact boundary samples (an upper bound on the distance).
        let (sa, sb) = (jack_boundary(k, 0.6, &pose_a, 3000), jack_boundary(k, 0.5, &pose_b, 3000));
        let mut brute = Real::INFINITY;
        for x in &sa {
            for y in &sb {
                brute = brute.min((x - y).norm());
            }
        }
        assert!(brute > 0.2, "test pair must be separated: {brute}");
        assert!(
            d.result.distance >= 0.0 && d.result.distance <= brute + 1e-9,
            "lb {} vs brute {brute}",
            d.result.distance
        );
        if d.tight {
            // Feasible witnesses attaining the bound: the bound is the distance.
            assert!(brute - d.result.distance < 2e-2 * brute, "tight lb {} vs brute {brute}", d.result.distance);
            let (x, y) = (d.result.witness_a, d.result.witness_b);
            assert!(((x - y).norm() - d.result.distance).abs() < 1e-5);
        }

        // Growth d(a‖b): b's boundary samples give an upper bound (a's minimizer lies outside b).
        let g = certified_growth(&a, &pose_a, &b, &pose_b, None, &params, CertifyMode::Certify);
        assert_eq!(g.source, AnswerSource::SdpLowerBound);
        assert!(g.lower_bound);
        let pa = a.posed(&pose_a);
        let brute_g = sb.iter().map(|x| pa.value(&x.coords)).fold(Real::INFINITY, Real::min);
        assert!(g.result.value <= brute_g + 1e-9, "lb {} vs brute {brute_g}", g.result.value);
        if g.tight {
            assert!(brute_g - g.result.value < 2e-2 * brute_g, "tight lb {} vs brute {brute_g}", g.result.value);
        }
    }

    #[test]
    fn tight_lower_bound_for_a_nonconvex_flagged_sphere() {
        // A sphere flagged nonconvex: the level-0 bound is exact and the witnesses feasible, so the
        // answer is a tight lower bound equal to the closed form.
        let mut s = ellipsoid([0.0; 3], [0.5; 3]).unwrap();
        s.report.nonconvex = true;
        let t = ellipsoid([0.0; 3], [0.3; 3]).unwrap();
        let pb = Isometry3::translation(1.5, 0.4, -0.2);
        let d = certified_distance(&s, &Isometry3::identity(), &t, &pb, None, &Default::default(), CertifyMode::Newton);
        let expected = Vector3::new(1.5, 0.4, -0.2).norm() - 0.8;
        assert_eq!(d.source, AnswerSource::SdpLowerBound);
        assert!(d.tight && d.lower_bound && d.converged, "{d:?}");
        assert!(d.result.distance <= expected + 1e-9 && expected - d.result.distance < 1e-6, "{}", d.result.distance);
        let g = certified_growth(&s, &Isometry3::identity(), &t, &pb, None, &Default::default(), CertifyMode::Newton);
        let expected_g = (Vector3::new(1.5, 0.4, -0.2).norm() - 0.3).powi(2) / 0.25;
        assert!(g.tight, "{g:?}");
        assert!((g.result.value - expected_g).abs() < 1e-6 * expected_g, "{} vs {expected_g}", g.result.value);
    }

    #[test]
    fn failed_newton_falls_back_to_the_sdp() {
        // One Newton iteration cannot converge on this ellipsoid pair: the SDP answers instead.
        let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
        let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
        let pb = pose_from_parts("b", [0.6, 0.0, 0.8, 0.0], [2.0, 0.4, 0.1]).unwrap();
        let id = Isometry3::identity();
        let full = CertifyParams::default();
        let reference = certified_distance(&e1, &id, &e2, &pb, None, &full, CertifyMode::Certify);
        assert_eq!(reference.source, AnswerSource::Newton);
        assert!(reference.certificate.as_ref().is_some_and(|c| c.agrees && c.verified), "{reference:?}");
        let crippled = CertifyParams { newton: NewtonParams { max_iterations: 1, ..Default::default() }, ..full };
        let d = certified_distance(&e1, &id, &e2, &pb, None, &crippled, CertifyMode::Newton);
        assert_ne!(d.result.status, SolveStatus::Converged);
        assert_eq!(d.source, AnswerSource::SdpFallback);
        assert!(d.converged && !d.lower_bound);
        assert!((d.result.distance - reference.result.distance).abs() < 1e-6, "{d:?}");
        assert!((d.result.witness_a - reference.result.witness_a).norm() < 1e-4);
        assert!(d.result.warm_start.valid);
        // The SDP-seeded warm start lets the full Newton converge warm.
        let w = crate::query::distance(&e1, &id, &e2, &pb, Some(&d.result.warm_start), &Default::default());
        assert!(w.warm_started && (w.distance - reference.result.distance).abs() < 1e-9);

        let g_ref = certified_growth(&e1, &id, &e2, &pb, None, &full, CertifyMode::Certify);
        let g = certified_growth(&e1, &id, &e2, &pb, None, &crippled, CertifyMode::Newton);
        assert_eq!(g.source, AnswerSource::SdpFallback);
        assert!(g.converged);
        assert!((g.result.value - g_ref.result.value).abs() < 1e-6 * g_ref.result.value, "{g:?}");
    }

    #[test]
    fn inactive_growth_answers_are_judged_by_the_rigorous_bound() {
        // The numbers of the stability suite's slab (1 × 1 × 10⁻³ m) on a host where Clarabel
        // ended `AlmostSolved`: Newton's value 0 (the slab's own minimum, its center inside the
        // other body); the SDP's bound 2.4·10⁻⁹ above it, its verified bound −4·10⁻⁸ below it.
        let summary = |bound: Real, verified_bound: Real| CertificateSummary {
            bound,
            verified_bound,
            agrees: false,
            relative_gap: 1.0,
            gram_min_eigenvalue: -2.4e-9,
            solve_seconds: 0.0,
            solver_status: SdpStatus::AlmostSolved,
            kind: CertificateKind::Level0,
            verified: false,
            newton_value: Some(0.0),
        };
        assert!(inactive_growth_agrees(&summary(2.4287605829478495e-9, -4.023593409991625e-8), 0.0));
        assert!(inactive_growth_agrees(&summary(5e-10, 5e-10), 0.0));
        // A rigorous bound above the attained value by more than the absolute tolerance contradicts it.
        assert!(!inactive_growth_agrees(&summary(2e-3, 1e-3), 0.0));
        assert!(!inactive_growth_agrees(&summary(0.31, 0.31), 0.3));
    }

    #[test]
    fn inactive_growth_is_certified_at_the_first_bodys_minimum() {
        // A small ellipsoid whose center (p₁ = 0 there) lies inside a larger one: d(p₁‖p₂) = 0 with
        // multiplier 0, certified whatever the SDP's last digits.
        let small = ellipsoid([0.0; 3], [0.2, 0.1, 0.05]).unwrap();
        let large = ellipsoid([0.0; 3], [1.0, 0.8, 0.6]).unwrap();
        let pose = pose_from_parts("p", [0.9, 0.1, 0.3, 0.3], [0.2, -0.1, 0.1]).unwrap();
        let id = Isometry3::identity();
        let g = certified_growth(&small, &pose, &large, &id, None, &CertifyParams::default(), CertifyMode::Certify);
        assert_eq!(g.source, AnswerSource::Newton);
        assert!(g.converged && g.result.multiplier == 0.0 && g.result.value.abs() <= 1e-12, "{g:?}");
        assert!((g.result.minimizer - Point3::new(0.2, -0.1, 0.1)).norm() <= 1e-12, "{g:?}");
        let c = g.certificate.expect("Certify mode attaches the SDP");
        assert!(c.agrees && c.bound <= 1e-9 && c.relative_gap == 0.0, "{c:?}");
    }
}
