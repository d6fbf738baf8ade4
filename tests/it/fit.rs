//! Integration tests: fitting (paper §III-A, eq. "VAG.log.det") and mesh loading.

use std::sync::OnceLock;
use sublevel::fit::{fit_points, mesh, FitProgress, FitSettings, FitStage, KktSolver};
use sublevel::math::{Matrix3, Point3, Real, UnitQuaternion, Vector3};
use sublevel::{Body, Error};

fn psb(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/psb").join(name)
}

/// The chair at 2d = 4, fitted once and shared by the tests that inspect it.
fn chair4() -> &'static (Vec<Point3>, Body, Vec<FitProgress>) {
    static CHAIR: OnceLock<(Vec<Point3>, Body, Vec<FitProgress>)> = OnceLock::new();
    CHAIR.get_or_init(|| {
        let pts = mesh::load_points(&psb("chair_101.off")).unwrap();
        let mut log = Vec::new();
        let body = fit_points(&pts, &FitSettings::default().with_degree(4), &mut |p| log.push(p.clone())).unwrap();
        (pts, body, log)
    })
}

/// Points on the unit sphere: ±eₖ (which make the unit sphere the minimum-volume enclosing
/// ellipsoid, by John's condition Σ uuᵀ = 2I, Σ u = 0) plus a Fibonacci spiral.
fn sphere_points(n: usize) -> Vec<Vector3> {
    let mut v = vec![Vector3::x(), -Vector3::x(), Vector3::y(), -Vector3::y(), Vector3::z(), -Vector3::z()];
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
        let r = (1.0 - z * z).sqrt();
        let th = golden * i as Real;
        v.push(Vector3::new(r * th.cos(), r * th.sin(), z));
    }
    v
}

#[test]
fn ellipsoid_cloud_at_degree_2_gives_back_the_ellipsoid() {
    // Ellipsoid x = c + R diag(radii) u, |u| = 1.
    let radii = Vector3::new(1.5, 1.0, 0.6);
    let rot = UnitQuaternion::from_euler_angles(0.3, -0.5, 1.1);
    let c = Vector3::new(0.3, -0.2, 1.0);
    let r = rot.to_rotation_matrix().into_inner();
    let m = r * Matrix3::from_diagonal(&radii);
    let pts: Vec<Point3> = sphere_points(200).iter().map(|u| Point3::from(c + m * u)).collect();
    let settings = FitSettings::default().with_degree(2).with_solver_tolerance(1e-10);
    let body = fit_points(&pts, &settings, &mut |_| {}).unwrap();

    // The log-det optimum at 2d = 2 is p = 1/4 + 3/4 q with q the minimum-volume enclosing
    // ellipsoid's form (det P = det A · min p, maximized at min p = 1/4), here q(x) = |M⁻¹(x − c)|².
    let minv = m.try_inverse().unwrap();
    let closed = |x: &Vector3| 0.25 + 0.75 * (minv * (x - c)).norm_squared();
    let mut max_err: Real = 0.0;
    for (i, u) in sphere_points(50).iter().enumerate() {
        for s in [0.0, 0.3, 0.9, 1.0, 1.4] {
            let x = c + m * (u * s) + Vector3::new(0.01, -0.02, 0.015) * (i % 3) as Real;
            max_err = max_err.max((body.value_at(&Point3::from(x)) - closed(&x)).abs());
        }
    }
    assert!(max_err < 1e-5, "max |p − closed form| = {max_err:e}");
    // Containment is exact on every point and tight.
    let r = &body.report;
    assert!(r.max_point_value <= 1.0 && r.max_point_value >= 1.0 - 1e-6, "{}", r.max_point_value);
    let exact = 4.0 / 3.0 * std::f64::consts::PI * radii.x * radii.y * radii.z;
    assert!(r.volume_std_error < 0.01 * r.volume);
    assert!((r.volume - exact).abs() < 3.0 * r.volume_std_error, "{} vs {exact} ± {}", r.volume, r.volume_std_error);
    assert_eq!(r.method, "logdet_p");
    assert_eq!(r.num_points, pts.len());
    assert_eq!(r.num_hull_vertices, pts.len());
}

#[test]
fn chair_degree_4_contains_every_vertex() {
    let (pts, body, _) = chair4();
    assert_eq!(pts.len(), 8499);
    let max = pts.iter().map(|x| body.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
    assert!(max <= 1.0 + 1e-12, "max p(xᵢ) = {max}");
    assert!(max >= 1.0 - 1e-6, "max p(xᵢ) = {max}: the fit is not tight");
    let r = &body.report;
    assert!(r.max_point_value <= 1.0 && (r.max_point_value - max).abs() < 1e-12);
    assert_eq!(r.num_hull_vertices, 320);
    assert!((r.hull_volume - 0.6558).abs() < 1e-3, "hull volume {}", r.hull_volume);
    assert!(r.volume >= r.hull_volume, "body {} < hull {}", r.volume, r.hull_volume);
    assert!(r.volume_std_error < 0.01 * r.volume);
    assert!(r.containment_rescale >= 1.0 && r.containment_rescale < 1.0 + 1e-4, "{}", r.containment_rescale);
    assert!(r.solver_status.is_usable(), "{}", r.solver_status);
    assert!(r.total_seconds >= r.solve_seconds && r.solve_seconds > 0.0);
}

#[test]
fn chair_degree_4_is_the_same_with_either_kkt_solver() {
    // The default (faer) fit against an independent solve of the same SDP with QDLDL: the
    // optimum is unique (log det is strictly concave in P and p is linear in P), so both give the
    // same polynomial up to the solver tolerance, and the same volume with the same seed.
    let (pts, body, _) = chair4();
    assert_eq!(FitSettings::default().linear_solver, KktSolver::Faer);
    let settings = FitSettings { linear_solver: KktSolver::Qdldl, ..FitSettings::default().with_degree(4) };
    let other = fit_points(pts, &settings, &mut |_| {}).unwrap();
    let (a, b) = (body.polynomial().coefficients(), other.polynomial().coefficients());
    let scale = a.iter().fold(0.0 as Real, |m, v| m.max(v.abs()));
    let diff = a.iter().zip(b).fold(0.0 as Real, |m, (x, y)| m.max((x - y).abs()));
    assert!(diff < 1e-4 * scale, "max coefficient difference {diff:e} (largest coefficient {scale})");
    let (ra, rb) = (&body.report, &other.report);
    assert!((ra.volume - rb.volume).abs() < ra.volume_std_error, "{} vs {}", ra.volume, rb.volume);
    assert!((ra.volume - 1.222).abs() < 3.0 * ra.volume_std_error, "volume {} ± {}", ra.volume, ra.volume_std_error);
    let kkt = |r: &sublevel::body::FitReport| r.solve.as_ref().and_then(|s| s.linear_solver);
    assert_eq!((kkt(ra), kkt(rb)), (Some(KktSolver::Faer), Some(KktSolver::Qdldl)));
}

/// Largest |p_a(x) − p_b(x)| over the chair's vertices and a grid of its bounding box (p_b ≤ 4,
/// i.e. near the bodies), relative to max(1, p_a(x)).
fn max_relative_difference(a: &Body, b: &Body, pts: &[Point3]) -> Real {
    let (mut lo, mut hi) = (pts[0].coords, pts[0].coords);
    for p in pts {
        lo = lo.inf(&p.coords);
        hi = hi.sup(&p.coords);
    }
    let mid = (lo + hi) * 0.5;
    let half = (hi - lo) * 0.6;
    let grid = (0..11 * 11 * 11).map(|k| {
        let t = |i: usize| (i as Real) / 5.0 - 1.0;
        Point3::from(mid + half.component_mul(&Vector3::new(t(k % 11), t(k / 11 % 11), t(k / 121))))
    });
    pts.iter()
        .copied()
        .chain(grid)
        .map(|x| (a.value_at(&x), b.value_at(&x)))
        .filter(|(pa, _)| *pa <= 4.0)
        .map(|(pa, pb)| (pa - pb).abs() / pa.max(1.0))
        .fold(0.0, Real::max)
}

/// Table 1's "reachable optimum" of the log det P rows, as a checked fact (paper eq.
/// "VAG.log.det", 2d = 4, chair):
/// - invariance: solved in three other frames (principal-axes cube, principal-axes box with
///   anisotropic scaling, whitened hull — rotations, shifts and anisotropic scalings of the
///   bounding cube), the body is the same: p agrees within 1e-3 on every vertex and on a grid
///   around the chair, and the volumes within 3 combined Monte Carlo standard errors;
/// - certificate: Clarabel's dual objective exceeds the primal one by at most its gap tolerance
///   1e-6 relative (7.6e-6 in log det units at |objective| ≈ 20), and a 100× tighter tolerance
///   (1e-8) moves p by less than 3e-4 (measured 6e-5) and the volume by less than one standard
///   error.
///
/// The chair's paper value 1.19 is below ours (1.222 ± 0.004) beyond the error, like its proven
/// 2d = 2 offset (MVEE 1.8425 vs 1.79).
#[test]
fn chair_degree_4_log_det_p_is_the_same_body_in_every_frame_and_at_a_tighter_gap() {
    use sublevel::fit::hull::Normalization;
    let (pts, body, _) = chair4();
    let cert = body.report.solver_certificate.expect("an SDP fit records its certificate");
    assert!(cert.dual_objective >= cert.primal_objective - 1e-9, "{cert:?}");
    // Clarabel stops at an absolute or relative gap of 1e-6 (`solver_tolerance`).
    assert!(cert.gap() <= 1e-6 * cert.primal_objective.abs().max(1.0), "{cert:?}");
    let (v, se) = (body.report.volume, body.report.volume_std_error);
    for norm in [Normalization::PrincipalCube, Normalization::PrincipalBox, Normalization::Whitened] {
        let other =
            fit_points(pts, &FitSettings::default().with_degree(4).with_normalization(norm), &mut |_| {}).unwrap();
        let diff = max_relative_difference(body, &other, pts);
        let (vo, seo) = (other.report.volume, other.report.volume_std_error);
        eprintln!("{}: max |Δp| {diff:.2e}, volume {vo:.4} ± {seo:.4} vs {v:.4} ± {se:.4}", norm.name());
        assert!(diff < 1e-3, "{}: max relative |Δp| = {diff:e}", norm.name());
        assert!((vo - v).abs() <= 3.0 * (se * se + seo * seo).sqrt(), "{}: {vo} ± {seo} vs {v} ± {se}", norm.name());
        let max = pts.iter().map(|x| other.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
        assert!(max <= 1.0, "{}: max p(xᵢ) = {max}", norm.name());
        assert_eq!(other.report.solve.as_ref().and_then(|s| s.frame), Some(norm), "{:?}", other.report.solve);
    }
    let tight =
        fit_points(pts, &FitSettings::default().with_degree(4).with_solver_tolerance(1e-8), &mut |_| {}).unwrap();
    let tight_cert = tight.report.solver_certificate.unwrap();
    let diff = max_relative_difference(body, &tight, pts);
    eprintln!(
        "tol 1e-8: gap {:.2e} ({}), max |Δp| {diff:.2e}, volume {:.4}",
        tight_cert.gap(),
        tight.report.solver_status,
        tight.report.volume
    );
    assert!(tight_cert.gap() <= cert.gap(), "{tight_cert:?} vs {cert:?}");
    assert!(diff < 3e-4, "tolerance 1e-8: max relative |Δp| = {diff:e}");
    assert!((tight.report.volume - v).abs() <= se, "{} vs {v} ± {se}", tight.report.volume);
    assert!(v > 1.19 + 0.005 + 2.0 * se, "paper 1.19 vs ours {v} ± {se}");
}

#[test]
fn chair_degree_4_is_sos_convex() {
    use rand::{Rng, SeedableRng};
    let (_, body, _) = chair4();
    let margin = body.report.convexity_margin.unwrap();
    assert!(margin >= -1e-7, "convexity margin {margin}");
    // Independent check: the Hessian of p is PSD at random points of a box around the body.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let p = body.polynomial();
    for _ in 0..2000 {
        let u = Vector3::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5));
        let h = p.eval(&u).hessian;
        let lmin = h.symmetric_eigenvalues().min();
        assert!(lmin >= -1e-7 * (1.0 + h.norm()), "Hessian eigenvalue {lmin} at {u}");
    }
}

#[test]
fn chair_fit_reports_every_stage_in_order() {
    let (_, _, log) = chair4();
    let order = [FitStage::Hull, FitStage::Build, FitStage::Solve, FitStage::Verify, FitStage::Volume, FitStage::Done];
    let stages: Vec<usize> = log.iter().map(|p| order.iter().position(|s| *s == p.stage).unwrap()).collect();
    assert!(stages.windows(2).all(|w| w[0] <= w[1]), "{stages:?}");
    for (s, stage) in order.iter().enumerate() {
        assert!(stages.contains(&s), "stage {stage:?} never reported");
    }
    assert!(log.windows(2).all(|w| w[0].fraction <= w[1].fraction));
    let iterations = log.iter().filter(|p| p.message.starts_with("Clarabel iteration")).count();
    assert!(iterations >= 5, "only {iterations} Clarabel iterations reported");
    assert_eq!(log.last().unwrap().fraction, 1.0);
}

#[test]
fn body_file_round_trip_keeps_the_fit() {
    let (pts, body, _) = chair4();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chair.json");
    body.save(&path).unwrap();
    let back = Body::load(&path).unwrap();
    assert_eq!(back.report, body.report);
    for x in pts.iter().step_by(97) {
        assert!((back.value_at(x) - body.value_at(x)).abs() < 1e-12);
    }
}

#[test]
fn degenerate_clouds_are_invalid_points() {
    let coplanar: Vec<Point3> =
        (0..50).map(|i| Point3::new((i as Real).sin(), (i as Real * 0.7).cos(), 0.25)).collect();
    let three = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 0.0, 1.0)];
    let mut nan: Vec<Point3> = sphere_points(20).into_iter().map(Point3::from).collect();
    nan[7].x = Real::NAN;
    for (cloud, needle) in [(coplanar, "coplanar"), (three, "3 points"), (nan, "non-finite"), (vec![], "empty")] {
        match fit_points(&cloud, &FitSettings::default(), &mut |_| {}) {
            Err(Error::InvalidArgument { field, reason }) => {
                assert_eq!(field, "points");
                assert!(reason.contains(needle), "{reason}");
            }
            other => panic!("expected InvalidArgument(points), got {other:?}"),
        }
    }
}

#[test]
fn psb_meshes_load_with_their_vertex_counts() {
    for (name, n) in [("chair_101.off", 8499), ("octopus_121.off", 5944)] {
        let p = mesh::load_points(&psb(name)).unwrap();
        assert_eq!(p.len(), n, "{name}");
        // SOURCE.md: largest |v − mean| is 1.000 within 1e-4.
        let mean = p.iter().fold(Vector3::zeros(), |a, x| a + x.coords) / n as Real;
        let r = p.iter().map(|x| (x.coords - mean).norm()).fold(0.0, Real::max);
        assert!((r - 1.0).abs() < 1e-3, "{name}: radius {r}");
    }
    match mesh::load_points(&psb("SOURCE.md")) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "mesh");
            assert!(reason.contains("unknown format `md`"));
        }
        other => panic!("{other:?}"),
    }
    let same = mesh::parse_points(&std::fs::read(psb("chair_101.off")).unwrap(), "OFF".parse().unwrap()).unwrap();
    assert_eq!(same.len(), 8499);
}

// ---- Every formulation of §III (trace / Magnani / relaxed / inverse moment) -------------------

use sublevel::conic::SdpStatus;
use sublevel::fit::FitMethod;

/// The rotated, shifted ellipsoid x = c + M u, |u| = 1 of the degree-2 tests, with its cloud.
struct EllipsoidCloud {
    m: Matrix3,
    c: Vector3,
    pts: Vec<Point3>,
}

fn ellipsoid_cloud() -> EllipsoidCloud {
    let radii = Vector3::new(1.5, 1.0, 0.6);
    let rot = UnitQuaternion::from_euler_angles(0.3, -0.5, 1.1);
    let c = Vector3::new(0.3, -0.2, 1.0);
    let m = rot.to_rotation_matrix().into_inner() * Matrix3::from_diagonal(&radii);
    let pts = sphere_points(200).iter().map(|u| Point3::from(c + m * u)).collect();
    EllipsoidCloud { m, c, pts }
}

/// Exact volume (input units) of the ellipsoid {p ≤ 1} of a degree-2 body: with p(u) = uᵀAu + bᵀu + k
/// in normalized coordinates, {p ≤ 1} = {(u − u₀)ᵀA(u − u₀) ≤ r} with r = 1 − k + bᵀA⁻¹b/4, of volume
/// 4/3 π r^{3/2} / √det A, times scale³.
fn quadratic_body_volume(body: &Body) -> Real {
    let p = body.polynomial();
    let coef = |e: [u8; 3]| p.coefficients()[p.exponents().iter().position(|x| *x == e).unwrap()];
    let a = Matrix3::new(
        coef([2, 0, 0]),
        coef([1, 1, 0]) / 2.0,
        coef([1, 0, 1]) / 2.0,
        coef([1, 1, 0]) / 2.0,
        coef([0, 2, 0]),
        coef([0, 1, 1]) / 2.0,
        coef([1, 0, 1]) / 2.0,
        coef([0, 1, 1]) / 2.0,
        coef([0, 0, 2]),
    );
    let b = Vector3::new(coef([1, 0, 0]), coef([0, 1, 0]), coef([0, 0, 1]));
    let r = 1.0 - coef([0, 0, 0]) + b.dot(&(a.try_inverse().unwrap() * b)) / 4.0;
    4.0 / 3.0 * std::f64::consts::PI * r.powf(1.5) / a.determinant().sqrt() * body.scale().powi(3)
}

#[test]
fn ellipsoid_cloud_at_degree_2_logdet_h_gives_back_the_ellipsoid_and_trace_forms_are_larger() {
    let e = ellipsoid_cloud();
    let minv = e.m.try_inverse().unwrap();
    let q = |x: &Vector3| (minv * (x - e.c)).norm_squared();
    let settings = FitSettings::default().with_degree(2).with_solver_tolerance(1e-10).with_volume_samples(20_000);
    let exact = 4.0 / 3.0 * std::f64::consts::PI * e.m.determinant().abs();
    // Both log det forms are exact at 2d = 2 (paper §III-A-2): log det P returns 1/4 + 3/4 q,
    // log det H (det of the Hessian, any constant shift only lowers det A) returns q itself.
    let ours = fit_points(&e.pts, &settings, &mut |_| {}).unwrap();
    let magnani = fit_points(&e.pts, &settings.clone().with_method(FitMethod::LogDetH), &mut |_| {}).unwrap();
    assert_eq!(magnani.report.method, "logdet_h");
    let mut max_err: Real = 0.0;
    for u in sphere_points(50) {
        for s in [0.0, 0.5, 1.0, 1.3] {
            let x = e.c + e.m * (u * s);
            max_err = max_err.max((magnani.value_at(&Point3::from(x)) - q(&x)).abs());
            max_err = max_err.max((ours.value_at(&Point3::from(x)) - (0.25 + 0.75 * q(&x))).abs());
        }
    }
    assert!(max_err < 1e-5, "max |p − closed form| = {max_err:e}");
    for body in [&ours, &magnani] {
        assert!((quadratic_body_volume(body) - exact).abs() < 1e-5 * exact);
        assert!(body.report.convexity_margin.unwrap() > 0.0);
    }
    // Trace forms: ellipsoids containing every point, never smaller than the minimum-volume one.
    for method in [FitMethod::TraceP, FitMethod::TraceH] {
        let body = fit_points(&e.pts, &settings.clone().with_method(method), &mut |_| {}).unwrap();
        assert_eq!(body.report.method, method.name());
        let max = e.pts.iter().map(|x| body.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
        assert!((1.0 - 1e-6..=1.0 + 1e-12).contains(&max), "{method:?}: max p(xᵢ) = {max}");
        let v = quadratic_body_volume(&body);
        assert!(v >= exact * (1.0 - 1e-6), "{method:?}: volume {v} < minimum {exact}");
        let r = &body.report;
        assert!((r.volume - v).abs() < 4.0 * r.volume_std_error, "{method:?}: MC {} vs exact {v}", r.volume);
        assert!(!r.nonconvex && r.convexity_margin.unwrap() > -1e-9);
        // Both trace bases in both frames (bounding cube, principal box) were solved and the
        // smallest body kept: the report lists the four candidates, the note names them.
        let names: Vec<&str> = r.candidate_volumes.iter().map(|c| c.0.as_str()).collect();
        assert_eq!(
            names,
            ["cube/plain basis", "cube/scaled basis", "principal_box/plain basis", "principal_box/scaled basis"]
        );
        let smallest = r.candidate_volumes.iter().map(|c| c.1).fold(Real::INFINITY, Real::min);
        assert_eq!(smallest, r.volume);
        assert!(r.candidate_volumes.iter().all(|c| c.1 >= exact * (1.0 - 0.01)), "{:?}", r.candidate_volumes);
        assert_eq!(r.candidate_volumes.len(), 4, "{:?}", r.candidate_volumes);
    }
}

#[test]
fn magnani_log_det_h_is_looser_than_ours_on_the_chair() {
    // Paper Table 1, chair at 2d = 4: log det H 1.55, log det P 1.19.
    let (pts, ours, _) = chair4();
    let settings = FitSettings::default().with_degree(4).with_method(FitMethod::LogDetH).with_volume_samples(50_000);
    let magnani = fit_points(pts, &settings, &mut |_| {}).unwrap();
    let (a, b) = (&ours.report, &magnani.report);
    // With `FIT_STATIC_REGULARIZATION` the log det H program solves to full tolerance
    // (Clarabel's default regularization ended it `AlmostSolved`, gap 1.8e-6).
    assert_eq!(b.solver_status, SdpStatus::Solved);
    assert!(
        b.solver_certificate.unwrap().gap() <= 1e-6 * b.solver_certificate.unwrap().primal_objective.abs().max(1.0)
    );
    assert!(
        a.volume + 3.0 * (a.volume_std_error + b.volume_std_error) < b.volume,
        "log det P {} ± {} vs log det H {} ± {}",
        a.volume,
        a.volume_std_error,
        b.volume,
        b.volume_std_error
    );
    let max = pts.iter().map(|x| magnani.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
    assert!(max <= 1.0 + 1e-12, "max p(xᵢ) = {max}");
    assert!(b.convexity_margin.unwrap() > 0.0, "H ≻ 0 at the log det optimum");
}

/// The chair at 2d = 4 with relaxed convexity c = 10, fitted once.
fn chair4_relaxed() -> &'static Body {
    static BODY: OnceLock<Body> = OnceLock::new();
    BODY.get_or_init(|| {
        let (pts, _, _) = chair4();
        let settings = FitSettings::default().with_degree(4).with_relaxation(10.0).with_volume_samples(50_000);
        fit_points(pts, &settings, &mut |_| {}).unwrap()
    })
}

#[test]
fn relaxed_convexity_contains_every_point_and_is_tighter() {
    let (pts, convex, _) = chair4();
    let body = chair4_relaxed();
    let r = &body.report;
    let max = pts.iter().map(|x| body.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
    assert!(max <= 1.0 + 1e-12, "max p(xᵢ) = {max}");
    assert!(max >= 1.0 - 1e-6, "max p(xᵢ) = {max}: the fit is not tight");
    assert!(r.nonconvex && r.convexity_relaxation == 10.0);
    let rounds = &r.solve.as_ref().expect("solve details").rows_per_round;
    assert!(!rounds.is_empty() && rounds.windows(2).all(|w| w[0] < w[1]), "rows per round {rounds:?}");
    assert!(r.containment_rescale <= 1.0 + 1e-4, "rounds left points outside: rescale {}", r.containment_rescale);
    assert!(r.convexity_margin.is_some());
    // Paper Table 1, chair at 2d = 4: c = 10 gives 0.72 against 1.19 for c = 0.
    let c0 = &convex.report;
    assert!(
        r.volume + 3.0 * (r.volume_std_error + c0.volume_std_error) < c0.volume,
        "c = 10: {} ± {}, c = 0: {}",
        r.volume,
        r.volume_std_error,
        c0.volume
    );
    assert!(r.volume_std_error < 0.01 * r.volume);
    // The frame lever (c > 0 depends on the frame): solved in the bounding cube and in the
    // principal box, the smaller body kept — here the principal box (Table 1: 0.789 → 0.707). The
    // brute-force volume below checks the kept body, composed back into the cube frame.
    let names: Vec<&str> = r.candidate_volumes.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(names, ["cube", "principal_box"]);
    let (cube, principal) = (r.candidate_volumes[0].1, r.candidate_volumes[1].1);
    assert!(principal < cube - 3.0 * r.volume_std_error && principal == r.volume, "{:?}", r.candidate_volumes);
    assert_eq!(r.solve.as_ref().and_then(|s| s.frame), Some(sublevel::fit::hull::Normalization::PrincipalBox));
    let (vol, se) = brute_force_volume(body, 1.25, 400_000);
    assert!(
        (r.volume - vol).abs() < 4.0 * (se + r.volume_std_error),
        "{} ± {} vs {vol} ± {se}",
        r.volume,
        r.volume_std_error
    );
}

/// `Normalization::Input` writes eq. "VAG.param.convex" literally in the data's coordinates: the
/// relaxation term is c(Σ xᵢ²)ᵈ in x. Checked by the scaling law it implies: for the cloud
/// y = s·x, p_y(y) = p_x(y/s) turns p_y + c‖y‖^(2d) sos-convex into p_x + c·s^(2d)‖x‖^(2d)
/// sos-convex, and log det changes by a constant, so fitting 2x with c = 1 must give the same body
/// (scaled) as fitting x with c = 2⁴ = 16 at 2d = 4 — while the bounding-cube frame, which
/// normalizes the scale away, gives the same body for x and 2x at equal c.
#[test]
fn input_frame_writes_the_relaxation_in_the_data_coordinates() {
    use sublevel::fit::hull::Normalization;
    let pts = mesh::load_points(&psb("human_10.off")).unwrap();
    let doubled: Vec<Point3> = pts.iter().map(|x| Point3::from(x.coords * 2.0)).collect();
    let fit = |cloud: &[Point3], c: Real, norm: Normalization| {
        let settings = FitSettings::default()
            .with_degree(4)
            .with_relaxation(c)
            .with_volume_samples(50_000)
            .with_normalization(norm)
            .with_alternate_normalization(None);
        fit_points(cloud, &settings, &mut |_| {}).unwrap()
    };
    let (x16, y1, x1) = (
        fit(&pts, 16.0, Normalization::Input),
        fit(&doubled, 1.0, Normalization::Input),
        fit(&pts, 1.0, Normalization::Input),
    );
    // Same body: p_y(2x) = p_x(x) on the points and around them.
    let diff =
        pts.iter().map(|x| (y1.value_at(&Point3::from(x.coords * 2.0)) - x16.value_at(x)).abs()).fold(0.0, Real::max);
    assert!(diff < 1e-4, "max |p_2x(2x) − p_x(x)| = {diff:e}");
    // Two Monte Carlo estimates of the same body: within 3 combined standard errors.
    let (v16, v1, se) = (x16.report.volume, y1.report.volume / 8.0, x16.report.volume_std_error);
    let combined = (se * se + (y1.report.volume_std_error / 8.0).powi(2)).sqrt();
    assert!((v16 - v1).abs() < 3.0 * combined, "x, c = 16: {v16}; 2x, c = 1 (÷ 8): {v1} ± {combined}");
    // Not vacuous: c = 1 on x is a different, larger body.
    assert!(x1.report.volume > v16 + 3.0 * (se + x1.report.volume_std_error), "{} vs {v16}", x1.report.volume);
    // The cube frame normalizes the scale: x and 2x give the same body at the same c.
    let (cx, cy) = (fit(&pts, 1.0, Normalization::BoundingCube), fit(&doubled, 1.0, Normalization::BoundingCube));
    let diff =
        pts.iter().map(|x| (cy.value_at(&Point3::from(x.coords * 2.0)) - cx.value_at(x)).abs()).fold(0.0, Real::max);
    assert!(diff < 1e-4, "cube frame: max |Δp| = {diff:e}");
    for body in [&x16, &y1, &x1] {
        assert_eq!(body.report.solve.as_ref().and_then(|s| s.frame), Some(Normalization::Input));
    }
}

#[test]
fn relaxed_convexity_at_zero_through_the_rounds_equals_log_det_p() {
    let (pts, body, _) = chair4();
    let settings = FitSettings::default().with_degree(4).with_rows_in_rounds(true);
    let rounds = fit_points(pts, &settings, &mut |_| {}).unwrap();
    let (a, b) = (body.polynomial().coefficients(), rounds.polynomial().coefficients());
    let scale = a.iter().fold(0.0 as Real, |m, v| m.max(v.abs()));
    let diff = a.iter().zip(b).fold(0.0 as Real, |m, (x, y)| m.max((x - y).abs()));
    assert!(diff < 1e-4 * scale, "max coefficient difference {diff:e} (largest coefficient {scale})");
    assert!(!rounds.report.nonconvex);
    assert!((rounds.report.volume - body.report.volume).abs() < body.report.volume_std_error);
}

#[test]
fn inverse_moment_at_degree_2_is_the_covariance_ellipsoid() {
    // z = (1, x): M₁ = [[1, x̄ᵀ], [x̄, (1/m) Σ x xᵀ]] and z(x)ᵀ M₁⁻¹ z(x) = 1 + (x − x̄)ᵀ Σ⁻¹ (x − x̄)
    // with Σ = (1/m) Σ (x − x̄)(x − x̄)ᵀ (Schur complement); p is that divided by its max on the cloud.
    let e = ellipsoid_cloud();
    let m = e.pts.len() as Real;
    let mean = e.pts.iter().fold(Vector3::zeros(), |a, x| a + x.coords) / m;
    let cov = e.pts.iter().fold(Matrix3::zeros(), |a, x| a + (x.coords - mean) * (x.coords - mean).transpose()) / m;
    let cinv = cov.try_inverse().unwrap();
    let raw = |x: &Vector3| 1.0 + (x - mean).dot(&(cinv * (x - mean)));
    let gamma = e.pts.iter().map(|x| raw(&x.coords)).fold(Real::NEG_INFINITY, Real::max);
    let settings =
        FitSettings::default().with_degree(2).with_method(FitMethod::InverseMoment).with_volume_samples(20_000);
    let body = fit_points(&e.pts, &settings, &mut |_| {}).unwrap();
    let mut max_err: Real = 0.0;
    for u in sphere_points(40) {
        for s in [0.0, 0.7, 1.0, 1.5] {
            let x = e.c + e.m * (u * s);
            max_err = max_err.max((body.value_at(&Point3::from(x)) - raw(&x) / gamma).abs());
        }
    }
    assert!(max_err < 1e-9, "max |p − closed form| = {max_err:e}");
    // Same axes as the ellipsoid: the Fibonacci cloud's second moment is ≈ I/3, so Σ ≈ M Mᵀ/3.
    let axes = e.m * e.m.transpose() / 3.0;
    assert!((cov - axes).norm() < 0.02 * axes.norm(), "Σ = {cov}, M Mᵀ/3 = {axes}");
    // Containment on every point with max exactly 1 (to rounding), flagged nonconvex, no margin.
    let max = e.pts.iter().map(|x| body.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
    assert!((1.0 - 1e-12..=1.0 + 1e-12).contains(&max), "max p(xᵢ) = {max}");
    let r = &body.report;
    assert!(r.nonconvex && r.convexity_margin.is_none() && r.method == "inverse_moment");
    // Its volume is the ellipsoid's closed form (the body is an ellipsoid at 2d = 2).
    let exact = quadratic_body_volume(&body);
    assert!((r.volume - exact).abs() < 4.0 * r.volume_std_error, "MC {} vs exact {exact}", r.volume);
}

#[test]
fn inverse_moment_on_the_chair_contains_every_point() {
    let (pts, _, _) = chair4();
    let settings =
        FitSettings::default().with_degree(4).with_method(FitMethod::InverseMoment).with_volume_samples(50_000);
    let body = fit_points(pts, &settings, &mut |_| {}).unwrap();
    let max = pts.iter().map(|x| body.value_at(x)).fold(Real::NEG_INFINITY, Real::max);
    assert!((1.0 - 1e-12..=1.0).contains(&max), "max p(xᵢ) = {max}");
    let r = &body.report;
    assert!(body.value_at(&body.interior_point()) < 1.0);
    assert!(r.volume_std_error < 0.01 * r.volume);
    // Independent reference for the covered-cells estimator: plain Monte Carlo in the normalized
    // cube [−1.25, 1.25]³ (the cloud lies in the unit ball; p > 1 on the cube's faces is checked).
    let (vol, se) = brute_force_volume(&body, 1.25, 400_000);
    assert!(
        (r.volume - vol).abs() < 4.0 * (se + r.volume_std_error),
        "{} ± {} vs {vol} ± {se}",
        r.volume,
        r.volume_std_error
    );
}

/// Plain Monte Carlo volume (input units) of a body in the normalized cube [−h, h]³, h the first of
/// h₀, 1.6 h₀, 2.56 h₀, … with p > 1 on a 60 × 60 grid of each face of the cube.
fn brute_force_volume(body: &Body, h0: Real, n: usize) -> (Real, Real) {
    use rand::{Rng, SeedableRng};
    let p = body.polynomial();
    let mut h = h0;
    while !cube_faces_are_outside(p, h) {
        h *= 1.6;
        assert!(h < 10.0, "the body reaches |u| = 10");
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(99);
    let hits = (0..n)
        .filter(|_| {
            let u = Vector3::new(rng.random_range(-h..h), rng.random_range(-h..h), rng.random_range(-h..h));
            p.value(&u) <= 1.0
        })
        .count();
    let f = hits as Real / n as Real;
    let cube = (2.0 * h * body.scale()).powi(3);
    (cube * f, cube * (f * (1.0 - f) / n as Real).sqrt())
}

/// p > 1 on a 60 × 60 grid of each face of [−h, h]³.
fn cube_faces_are_outside(p: &sublevel::poly::Polynomial, h: Real) -> bool {
    for k in 0..3 {
        for s in [-h, h] {
            for i in 0..60 {
                for j in 0..60 {
                    let mut u = Vector3::zeros();
                    u[k] = s;
                    u[(k + 1) % 3] = -h + 2.0 * h * i as Real / 59.0;
                    u[(k + 2) % 3] = -h + 2.0 * h * j as Real / 59.0;
                    if p.value(&u) <= 1.0 {
                        return false;
                    }
                }
            }
        }
    }
    true
}

#[test]
fn bad_relaxation_and_degenerate_moment_clouds_are_invalid() {
    let e = ellipsoid_cloud();
    let base = FitSettings::default().with_degree(2);
    for (s, field) in [
        (base.clone().with_relaxation(-1.0), "convexity_relaxation"),
        (base.clone().with_relaxation(Real::NAN), "convexity_relaxation"),
        (base.clone().with_relaxation(Real::INFINITY), "convexity_relaxation"),
        (base.clone().with_relaxation(10.0).with_method(FitMethod::LogDetH), "convexity_relaxation"),
        (base.clone().with_relaxation(10.0).with_method(FitMethod::TraceH), "convexity_relaxation"),
        (base.clone().with_relaxation(1.0).with_method(FitMethod::InverseMoment), "convexity_relaxation"),
    ] {
        match fit_points(&e.pts, &s, &mut |_| {}) {
            Err(Error::InvalidArgument { field: f, .. }) => assert_eq!(f, field),
            other => panic!("expected InvalidArgument({field}), got {other:?}"),
        }
    }
    // Points on a quadric (the ellipsoid): the degree-4 moment matrix is singular.
    let settings = FitSettings::default().with_degree(4).with_method(FitMethod::InverseMoment);
    match fit_points(&e.pts, &settings, &mut |_| {}) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "points");
            assert!(reason.contains("singular"), "{reason}");
        }
        other => panic!("expected InvalidArgument(points), got {other:?}"),
    }
    match fit_points(&e.pts, &base.with_method(FitMethod::LogDetH).with_rows_in_rounds(true), &mut |_| {}) {
        Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "method"),
        other => panic!("expected InvalidArgument(method), got {other:?}"),
    }
}

/// Two unit cubes at x = ±2 (meters) as a triangle soup in ASCII STL: every triangle its own
/// three `vertex` lines, 24 facets.
fn two_cube_soup_stl() -> String {
    let mut s = String::from("solid two_cubes\n");
    for cx in [-2.0, 2.0] {
        let v = |k: usize| {
            [
                cx + if k & 1 == 0 { -0.5 } else { 0.5 },
                if k & 2 == 0 { -0.5 } else { 0.5 },
                if k & 4 == 0 { -0.5 } else { 0.5 },
            ]
        };
        for q in [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]] {
            for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                s += "facet normal 0 0 0\nouter loop\n";
                for k in t {
                    let p = v(k);
                    s += &format!("vertex {} {} {}\n", p[0], p[1], p[2]);
                }
                s += "endloop\nendfacet\n";
            }
        }
    }
    s + "endsolid two_cubes\n"
}

fn sublevel_fit(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sublevel")).arg("fit").args(args).output().unwrap()
}

#[test]
fn fit_parts_reads_an_stl_soup_welds_it_and_reports_a_tolerance_miss() {
    let dir = tempfile::tempdir().unwrap();
    let stl = dir.path().join("two_cubes.stl");
    std::fs::write(&stl, two_cube_soup_stl()).unwrap();
    let out = dir.path().join("two_cubes.compound.json");
    let (stl, out_s) = (stl.to_str().unwrap(), out.to_str().unwrap());
    let quick = ["--degree", "2", "--excess-samples", "200", "--resolution", "32", "--quiet", "--output", out_s];
    // Degree-2 leaves around unit cubes reach (√3 − 1)/2 ≈ 0.366 m beyond them: T = 0.3 misses
    // at both leaves, and the command fails after writing the file.
    let run = sublevel_fit(&[&[stl, "--parts", "2", "--tolerance", "0.3"][..], &quick[..]].concat());
    let (stdout, stderr) = (String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert!(!run.status.success(), "{stdout}\n{stderr}");
    // stl_io merges the soup's equal vertices: 16 of them, 24 triangles, nothing else to weld.
    assert!(stdout.contains("16 → 16 vertices") || !stdout.contains("welded at"), "{stdout}");
    assert!(stdout.contains("conservative: 24 of 24 triangles"), "{stdout}");
    assert!(stderr.contains("warning: 2 of 2 leaves miss the tolerance 0.3000 m"), "{stderr}");
    assert!(stderr.contains("12 triangles, excess 0.36") && stderr.contains("= 1.2"), "{stderr}");
    assert!(stderr.contains("--allow-tolerance-miss"), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let report = &v["report"];
    assert_eq!(report["tolerance"], 0.3);
    assert_eq!(report["met"], false);
    let misses = report["misses"].as_array().unwrap();
    assert_eq!(misses.len(), 2);
    for m in misses {
        assert_eq!(m["triangles"], 12);
        let e = m["excess"].as_f64().unwrap();
        assert!((e - (3f64.sqrt() - 1.0) / 2.0).abs() < 0.01, "excess {e}");
    }
    // Accepted with --allow-tolerance-miss; met at T = 0.4.
    let run = sublevel_fit(
        &[&[stl, "--parts", "2", "--tolerance", "0.3", "--allow-tolerance-miss"][..], &quick[..]].concat(),
    );
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let run = sublevel_fit(&[&[stl, "--parts", "2", "--tolerance", "0.4"][..], &quick[..]].concat());
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    assert!(String::from_utf8_lossy(&run.stdout).contains("tolerance met"));
}

#[test]
fn fit_parts_names_a_point_cloud_file_without_faces() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("cloud.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n",
    )
    .unwrap();
    let run = sublevel_fit(&[ply.to_str().unwrap(), "--parts", "auto", "--quiet"]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(stderr.contains("cloud.ply") && stderr.contains("no `face` element"), "{stderr}");
}
