//! Integration tests: fitting (paper §III-A, eq. "VAG.log.det") and mesh loading.

use std::sync::OnceLock;
use sublevel::fit::{fit_points, mesh, FitProgress, FitSettings, FitStage, KktSolver};
use sublevel::math::{Matrix3, Point3, Real, UnitQuaternion, Vector3};
use sublevel::{Body, Error};

fn psb(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/psb").join(name)
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
    assert!(matches!(r.solver_status.as_str(), "Solved" | "AlmostSolved"));
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
    assert!(ra.notes.iter().any(|n| n.contains("(faer)")) && rb.notes.iter().any(|n| n.contains("(qdldl)")));
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
    let same = mesh::parse_points(&std::fs::read(psb("chair_101.off")).unwrap(), "OFF").unwrap();
    assert_eq!(same.len(), 8499);
}
