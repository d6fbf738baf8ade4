//! Certificates against closed forms (spheres, ellipsoids by support functions) and brute force
//! over the boundary (quartic and sextic bodies).

use super::*;
use sublevel_core::body::{ellipsoid, Body, FitReport};
use sublevel_core::math::pose_from_parts;
use sublevel_core::math::{Isometry3, Point3, Vector3};
use sublevel_core::poly::Polynomial;

fn pose(q: [Real; 4], t: [Real; 3]) -> Isometry3 {
    let n = q.iter().map(|v| v * v).sum::<Real>().sqrt();
    pose_from_parts("pose", [q[0] / n, q[1] / n, q[2] / n, q[3] / n], t).unwrap()
}

/// `p(u) = a‖u‖² + b Σ uᵢ^(2k)`: sos-convex (a sum of sos-convex terms), degree 2k, minimum 0 at 0.
fn power_body(k: u8, a: Real, b: Real, center: [Real; 3], scale: Real) -> Body {
    let terms =
        [([2, 0, 0], a), ([0, 2, 0], a), ([0, 0, 2], a), ([2 * k, 0, 0], b), ([0, 2 * k, 0], b), ([0, 0, 2 * k], b)];
    Body::new(Polynomial::from_terms(2 * k as usize, &terms).unwrap(), center, scale, FitReport::default()).unwrap()
}

fn dir(theta: Real, phi: Real) -> Vector3 {
    Vector3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
}

/// Brute-force minimum of `f` over the unit sphere: a 90 × 180 grid in (θ, φ), then a compass
/// search from the best grid point with steps halved down to 1e-10 rad.
fn sphere_min(f: impl Fn(&Vector3) -> Real) -> (Real, Vector3) {
    let (nt, np) = (90, 180);
    let (ht, hp) = (std::f64::consts::PI / nt as Real, 2.0 * std::f64::consts::PI / np as Real);
    let mut best = (Real::INFINITY, 0.0, 0.0);
    for i in 0..=nt {
        for j in 0..np {
            let (t, p) = (i as Real * ht, j as Real * hp);
            let v = f(&dir(t, p));
            if v < best.0 {
                best = (v, t, p);
            }
        }
    }
    let (mut v, mut t, mut p) = best;
    let mut h = ht;
    while h > 1e-10 {
        let mut improved = false;
        for (dt, dp) in [(h, 0.0), (-h, 0.0), (0.0, h), (0.0, -h), (h, h), (-h, -h), (h, -h), (-h, h)] {
            let w = f(&dir(t + dt, p + dp));
            if w < v {
                (v, t, p) = (w, t + dt, p + dp);
                improved = true;
            }
        }
        if !improved {
            h *= 0.5;
        }
    }
    (v, dir(t, p))
}

/// Boundary point of a posed body whose polynomial has its minimum 0 at u = 0, in direction n
/// of its normalized frame: p(ρ n) = 1 by bisection on ρ.
fn boundary(body: &Body, pose: &Isometry3, n: &Vector3) -> Point3 {
    let (mut lo, mut hi) = (0.0, 1.0);
    while body.polynomial().value(&(n * hi)) < 1.0 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if body.polynomial().value(&(n * mid)) < 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    pose * Point3::from(body.center() + n * (0.5 * (lo + hi) * body.scale()))
}

/// Brute-force distance from a posed body (minimum 0 at u = 0) to a sphere: min over the
/// body's boundary of ‖x − c‖, minus r.
fn brute_distance_to_sphere(body: &Body, pose: &Isometry3, c: &Point3, r: Real) -> Real {
    sphere_min(|n| (boundary(body, pose, n) - c).norm()).0 - r
}

/// Brute-force d(p₁‖p₂) when p₁'s minimizer lies outside body 2: min of p₁' over body 2's boundary.
fn brute_growth(p1: &Body, pose1: &Isometry3, p2: &Body, pose2: &Isometry3) -> Real {
    let b1 = p1.posed(pose1);
    sphere_min(|n| b1.value(&boundary(p2, pose2, n).coords)).0
}

/// Support function of a posed axis-aligned ellipsoid {Σ((xᵢ − cᵢ)/rᵢ)² ≤ 1}:
/// h(n) = n·(R c + t) + ‖diag(r) Rᵀ n‖.
fn ellipsoid_support(c: [Real; 3], r: [Real; 3], pose: &Isometry3, n: &Vector3) -> Real {
    let local = pose.rotation.inverse() * n;
    let center = pose * Point3::new(c[0], c[1], c[2]);
    n.dot(&center.coords) + Vector3::new(r[0] * local.x, r[1] * local.y, r[2] * local.z).norm()
}

/// Brute-force distance between separated posed ellipsoids by separating-plane duality:
/// dist = max over unit n of [−h_B(−n) − h_A(n)].
fn brute_ellipsoid_distance(
    ca: [Real; 3],
    ra: [Real; 3],
    pa: &Isometry3,
    cb: [Real; 3],
    rb: [Real; 3],
    pb: &Isometry3,
) -> Real {
    -sphere_min(|n| ellipsoid_support(cb, rb, pb, &-n) + ellipsoid_support(ca, ra, pa, n)).0
}

fn sphere(c: [Real; 3], r: Real) -> Body {
    ellipsoid(c, [r; 3]).unwrap()
}

#[test]
fn sphere_distance_matches_closed_form_with_witnesses() {
    let (c1, r1, c2, r2) = (Vector3::new(0.3, -0.2, 0.1), 0.7, Vector3::new(2.1, 0.9, -0.4), 0.5);
    let a = sphere([0.0; 3], r1);
    let b = sphere([0.0; 3], r2);
    let pa = pose([0.9, 0.2, -0.1, 0.3], c1.into());
    let pb = pose([0.4, -0.5, 0.6, 0.1], c2.into());
    let cert = certify_distance(&a, &pa, &b, &pb).unwrap();
    let expected = (c2 - c1).norm() - r1 - r2;
    assert!((cert.distance - expected).abs() < 1e-6, "{} vs {expected}", cert.distance);
    assert!((cert.squared_distance - expected * expected).abs() < 1e-6);
    assert_eq!(cert.gram_sizes, vec![7, 4, 4]);
    assert_eq!(cert.solver_status, sublevel_core::conic::SdpStatus::Solved);
    assert!(cert.residual < 1e-8, "residual {}", cert.residual);
    let verified = cert.verified_squared_distance;
    assert!(verified <= expected * expected + 1e-9 && verified > expected * expected - 1e-7, "{cert:?}");
    // KKT: 2(x − y) + τ∇p_a = 0 with ∇p_a = 2(x − c₁)/r₁², |x − c₁| = r₁  ⇒  τ = r₁ · dist.
    assert!((cert.tau - r1 * expected).abs() < 1e-5, "tau {}", cert.tau);
    assert!((cert.xi - r2 * expected).abs() < 1e-5, "xi {}", cert.xi);
    let (x, y) = cert.witnesses.unwrap();
    let n = (c2 - c1).normalize();
    assert!((x.coords - (c1 + n * r1)).norm() < 1e-5, "x* = {x}");
    assert!((y.coords - (c2 - n * r2)).norm() < 1e-5, "y* = {y}");
    // Paper §IV-A: the same witnesses from the kernel of the (1, u, v) Gram block.
    let (xk, yk) = cert.kernel_witnesses.expect("one-dimensional Gram kernel");
    assert!((xk.coords - (c1 + n * r1)).norm() < 1e-4, "kernel x* = {xk}");
    assert!((yk.coords - (c2 - n * r2)).norm() < 1e-4, "kernel y* = {yk}");
}

#[test]
fn separating_hyperplane_bound_matches_sphere_support_functions() {
    let (c1, r1, c2, r2) = (Vector3::new(0.3, -0.2, 0.1), 0.7, Vector3::new(2.1, 0.9, -0.4), 0.5);
    let (a, b) = (sphere([0.0; 3], r1), sphere([0.0; 3], r2));
    let pa = pose([0.9, 0.2, -0.1, 0.3], c1.into());
    let pb = pose([0.4, -0.5, 0.6, 0.1], c2.into());
    let params = CertificateParams::default();
    // At the true witnesses the excesses vanish and the bound is the distance.
    let n = (c2 - c1).normalize();
    let expected = (c2 - c1).norm() - r1 - r2;
    let (x, y) = (Point3::from(c1 + n * r1), Point3::from(c2 - n * r2));
    let h = certify_separation(&a, &pa, &b, &pb, &x, &y, &params).unwrap();
    assert!((h.lower_bound - expected).abs() < 1e-6, "{h:?}");
    assert!(h.verified_lower_bound <= expected + 1e-9 && expected - h.verified_lower_bound < 1e-6, "{h:?}");
    assert!(h.excess.0.abs() < 1e-6 && h.excess.1.abs() < 1e-6, "{h:?}");
    // Off-optimal points on the spheres: the bound is that of the hyperplane of normal
    // m = (y − x)/‖y − x‖, closed form m·(c₂ − c₁) − r₁ − r₂ (sphere support functions).
    let tilt = (n + Vector3::new(0.0, 0.3, 0.2)).normalize();
    let (x, y) = (Point3::from(c1 + tilt * r1), Point3::from(c2 - tilt * r2));
    let m = (y - x).normalize();
    let plane = m.dot(&(c2 - c1)) - r1 - r2;
    let h = certify_separation(&a, &pa, &b, &pb, &x, &y, &params).unwrap();
    assert!((h.lower_bound - plane).abs() < 1e-6, "{} vs {plane}", h.lower_bound);
    assert!(h.verified_lower_bound <= expected + 1e-9 && plane < expected);
    assert!(certify_separation(&a, &pa, &b, &pb, &x, &x, &params).is_err());
}

#[test]
fn overlapping_spheres_certify_zero() {
    let a = sphere([0.5, 0.0, 0.0], 1.0);
    let b = sphere([0.0, 0.0, 0.0], 0.8);
    let cert = certify_distance(&a, &Isometry3::identity(), &b, &pose([1.0, 0.0, 0.0, 0.0], [1.2, 0.3, 0.0])).unwrap();
    assert!(cert.squared_distance.abs() <= 1e-7, "γ = {}", cert.squared_distance);
    let (x, y) = cert.witnesses.unwrap();
    assert!((x - y).norm() < 1e-4);
    assert!(a.value_at(&x) <= 1.0 + 1e-6);
}

#[test]
fn sphere_growth_matches_closed_form() {
    let s1 = sphere([0.0; 3], 0.5);
    let s2 = sphere([0.0; 3], 0.8);
    for (k, t2) in [[3.0, 0.2, -0.1], [1.5, -0.4, 0.3], [0.9, 0.1, 0.0], [0.2, 0.1, 0.1]].iter().enumerate() {
        let (c1, c2) = (Vector3::new(0.1, 0.2, 0.3), Vector3::from(*t2));
        let p1 = pose([0.8, 0.1, 0.5, -0.2], c1.into());
        let p2 = pose([0.3, 0.9, 0.0, 0.4], c2.into());
        let cert = certify_growth(&s1, &p1, &s2, &p2).unwrap();
        let expected = ((c1 - c2).norm() - 0.8).max(0.0).powi(2) / 0.25;
        assert!((cert.value - expected).abs() < 1e-7 * expected.max(1.0), "case {k}: {} vs {expected}", cert.value);
        // The a-posteriori check: exact identity up to a tiny residual, bound below the truth.
        assert_eq!(cert.solver_status, sublevel_core::conic::SdpStatus::Solved, "case {k}");
        assert!(cert.residual < 1e-8 * expected.max(1.0), "case {k}: residual {}", cert.residual);
        assert!(cert.verified_value <= expected + 1e-9 * expected.max(1.0), "case {k}: {cert:?}");
        assert!(cert.value - cert.verified_value < 1e-7 * expected.max(1.0), "case {k}: {cert:?}");
        // The single-pass (plain frame) certificate gives the same value.
        let plain = CertificateParams { recenter: false, ..Default::default() };
        let single = certify_growth_with_params(&s1, &p1, &s2, &p2, &plain).unwrap();
        assert!((single.value - expected).abs() < 1e-7 * expected.max(1.0), "case {k}: {single:?}");
        if expected > 0.0 {
            let x = cert.minimizer.unwrap();
            let want = c2 + (c1 - c2).normalize() * 0.8;
            assert!((x.coords - want).norm() < 1e-4, "case {k}: x* = {x}");
        }
    }
}

#[test]
fn rotated_ellipsoids_match_brute_force_and_are_pose_invariant() {
    let (ca, ra) = ([0.1, -0.2, 0.0], [0.9, 0.3, 0.5]);
    let (cb, rb) = ([0.0, 0.3, 0.1], [0.4, 1.0, 0.2]);
    let a = ellipsoid(ca, ra).unwrap();
    let b = ellipsoid(cb, rb).unwrap();
    let pa = pose([0.9, 0.1, 0.3, 0.3], [0.2, -0.1, 0.4]);
    let pb = pose([0.2, -0.7, 0.4, 0.5], [2.6, 1.0, -0.4]);
    let cert = certify_distance(&a, &pa, &b, &pb).unwrap();
    let brute = brute_ellipsoid_distance(ca, ra, &pa, cb, rb, &pb);
    assert!(brute > 0.3, "test pair must be separated, brute = {brute}");
    assert!((cert.distance - brute).abs() < 1e-6, "{} vs brute {brute}", cert.distance);
    let (x, y) = cert.witnesses.unwrap();
    assert!(((x - y).norm() - brute).abs() < 1e-5);
    assert!((a.value_at(&(pa.inverse() * x)) - 1.0).abs() < 1e-5);

    let g = certify_growth(&a, &pa, &b, &pb).unwrap();
    let g_brute = brute_growth(&a, &pa, &b, &pb);
    assert!((g.value - g_brute).abs() < 1e-6 * g_brute.max(1.0), "{} vs brute {g_brute}", g.value);
    let g21 = certify_growth(&b, &pb, &a, &pa).unwrap();
    let g21_brute = brute_growth(&b, &pb, &a, &pa);
    assert!((g21.value - g21_brute).abs() < 1e-6 * g21_brute.max(1.0), "{} vs {g21_brute}", g21.value);

    // Same rigid motion applied to both bodies: both certificates unchanged.
    let motion = pose([0.3, 0.5, -0.6, 0.2], [10.0, -4.0, 7.5]);
    let (ma, mb) = (motion * pa, motion * pb);
    let moved = certify_distance(&a, &ma, &b, &mb).unwrap();
    assert!((moved.squared_distance - cert.squared_distance).abs() < 1e-7);
    let moved_g = certify_growth(&a, &ma, &b, &mb).unwrap();
    assert!((moved_g.value - g.value).abs() < 1e-7 * g.value.max(1.0));
    let (mx, _) = moved.witnesses.unwrap();
    assert!((mx - motion * x).norm() < 1e-5);
}

#[test]
fn quartic_body_matches_brute_force() {
    // p = 0.2‖u‖² + (u₁⁴ + u₂⁴ + u₃⁴), a rounded cube, scale 0.6.
    let quartic = power_body(2, 0.2, 1.0, [0.1, 0.0, -0.1], 0.6);
    let pq = pose([0.7, 0.3, -0.2, 0.5], [0.3, 0.2, -0.1]);
    let ball = sphere([0.0; 3], 0.4);
    let c = Point3::new(1.6, 1.0, 0.5);
    let pc = pose([1.0, 0.0, 0.0, 0.0], c.coords.into());
    let cert = certify_distance(&quartic, &pq, &ball, &pc).unwrap();
    assert_eq!(cert.gram_sizes, vec![7, 10, 10]);
    let brute = brute_distance_to_sphere(&quartic, &pq, &c, 0.4);
    assert!(brute > 0.2, "brute {brute}");
    assert!((cert.distance - brute).abs() < 1e-6, "{} vs brute {brute}", cert.distance);
    // The full 6-variable Gram form (N = 28) gives the same bound.
    let full = CertificateParams { full_gram: true, ..Default::default() };
    let cert_full = certify_distance_with_params(&quartic, &pq, &ball, &pc, &full).unwrap();
    assert_eq!(cert_full.gram_sizes, vec![28]);
    assert!((cert_full.squared_distance - cert.squared_distance).abs() < 1e-7);
    let ((x, _), (xf, _)) = (cert.witnesses.unwrap(), cert_full.witnesses.unwrap());
    assert!((x - xf).norm() < 1e-4);

    // Growth both ways against an ellipsoid.
    let e = ellipsoid([0.0; 3], [0.3, 0.7, 0.4]).unwrap();
    let pe = pose([0.5, 0.5, 0.5, -0.5], [1.2, -0.6, 0.5]);
    let g = certify_growth(&quartic, &pq, &e, &pe).unwrap();
    let g_brute = brute_growth(&quartic, &pq, &e, &pe);
    assert!((g.value - g_brute).abs() < 1e-6 * g_brute.max(1.0), "{} vs brute {g_brute}", g.value);
    let g = certify_growth(&e, &pe, &quartic, &pq).unwrap();
    let g_brute = brute_growth(&e, &pe, &quartic, &pq);
    assert!((g.value - g_brute).abs() < 1e-6 * g_brute.max(1.0), "{} vs brute {g_brute}", g.value);
}

#[test]
fn sextic_body_matches_brute_force() {
    let sextic = power_body(3, 0.3, 2.0, [0.0; 3], 0.5);
    let ps = pose([0.6, -0.2, 0.7, 0.1], [-0.2, 0.1, 0.0]);
    let c = Point3::new(-1.1, 0.8, 0.6);
    let ball = sphere([0.0; 3], 0.3);
    let cert = certify_distance(&sextic, &ps, &ball, &pose([1.0, 0.0, 0.0, 0.0], c.coords.into())).unwrap();
    assert_eq!(cert.gram_sizes, vec![7, 20, 20]);
    let brute = brute_distance_to_sphere(&sextic, &ps, &c, 0.3);
    assert!((cert.distance - brute).abs() < 1e-6, "{} vs brute {brute}", cert.distance);
}

#[test]
fn invalid_params_name_the_field() {
    let s = sphere([0.0; 3], 1.0);
    let id = Isometry3::identity();
    let bad = CertificateParams { tolerance: -1.0, ..Default::default() };
    let err = certify_distance_with_params(&s, &id, &s, &id, &bad).unwrap_err();
    assert!(err.to_string().contains("params.tolerance"), "{err}");
    let bad = CertificateParams { max_iterations: 0, ..Default::default() };
    let err = certify_growth_with_params(&s, &id, &s, &id, &bad).unwrap_err();
    assert!(err.to_string().contains("params.max_iterations"), "{err}");
    // Too few iterations is a Numerical error naming Clarabel's status.
    let few = CertificateParams { max_iterations: 1, ..Default::default() };
    let err =
        certify_distance_with_params(&s, &id, &s, &pose([1.0, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0]), &few).unwrap_err();
    assert!(err.to_string().contains("MaxIterations"), "{err}");
}

/// Solve times at 2d = 2, 4, 6 (run with `cargo test --release --lib solve_times -- --ignored --nocapture`).
#[test]
#[ignore]
fn solve_times() {
    let bodies =
        [sphere([0.0; 3], 0.5), power_body(2, 0.2, 1.0, [0.0; 3], 0.5), power_body(3, 0.2, 1.0, [0.0; 3], 0.5)];
    let pa = pose([0.9, 0.1, 0.3, 0.3], [0.0; 3]);
    let pb = pose([0.2, -0.7, 0.4, 0.5], [1.5, 0.4, -0.2]);
    for body in &bodies {
        let reps = 10;
        let (mut td, mut tg, mut wall) = (0.0, 0.0, 0.0);
        let (mut n_d, mut n_g) = (Vec::new(), 0);
        for _ in 0..reps {
            let start = std::time::Instant::now();
            let d = certify_distance(body, &pa, body, &pb).unwrap();
            wall += start.elapsed().as_secs_f64();
            td += d.solve_seconds;
            n_d = d.gram_sizes;
            let g = certify_growth(body, &pa, body, &pb).unwrap();
            tg += g.solve_seconds;
            n_g = g.gram_size;
        }
        println!(
            "2d = {}: distance N = {n_d:?}: {:.2} ms in Clarabel ({:.2} ms with build); growth N = {n_g}: {:.2} ms",
            body.degree(),
            1e3 * td / reps as Real,
            1e3 * wall / reps as Real,
            1e3 * tg / reps as Real
        );
        if body.degree() <= 4 {
            let full = CertificateParams { full_gram: true, ..Default::default() };
            let d = certify_distance_with_params(body, &pa, body, &pb, &full).unwrap();
            println!("   full 6-variable form N = {:?}: {:.2} ms", d.gram_sizes, 1e3 * d.solve_seconds);
        }
    }
}
