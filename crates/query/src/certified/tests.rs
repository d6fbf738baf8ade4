use super::*;
use crate::newton::SolveStatus;
use sublevel_core::body::{ellipsoid, FitReport};
use sublevel_core::math::{pose_from_parts, UnitQuaternion, Vector3};
use sublevel_core::poly::Polynomial;

/// A nonconvex "jack": p(u) = ‖u‖² + k(u₁²u₂² + u₂²u₃² + u₁²u₃²) (sos, not convex for large k),
/// flagged nonconvex. Star-shaped about 0 with the closed-form boundary radius below.
fn jack(k: Real, scale: Real) -> Body {
    let terms = [([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0), ([2, 2, 0], k), ([0, 2, 2], k), ([2, 0, 2], k)];
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
    assert!(d.result.distance >= 0.0 && d.result.distance <= brute + 1e-9, "lb {} vs brute {brute}", d.result.distance);
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
    let w = crate::distance(&e1, &id, &e2, &pb, Some(&d.result.warm_start), &Default::default());
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
    let cert = CertificateParams::default();
    assert!(inactive_growth_agrees(&summary(2.4287605829478495e-9, -4.023593409991625e-8), 0.0, &cert));
    assert!(inactive_growth_agrees(&summary(5e-10, 5e-10), 0.0, &cert));
    // A rigorous bound above the attained value by more than the absolute tolerance contradicts it.
    assert!(!inactive_growth_agrees(&summary(2e-3, 1e-3), 0.0, &cert));
    assert!(!inactive_growth_agrees(&summary(0.31, 0.31), 0.3, &cert));
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
