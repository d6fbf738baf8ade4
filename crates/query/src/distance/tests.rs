use super::*;
use rand::{Rng, SeedableRng};
use sublevel_core::body::ellipsoid;
use sublevel_core::math::{pose_from_parts, UnitQuaternion};

#[test]
fn common_points_prove_overlap_and_only_overlap() {
    // Spheres of radii 0.5 and 0.3 (centers 0.1 off their frames' origins) at center distances
    // from 0 to 1.2 m along a tilted line: they overlap below 0.8 m. A common point is returned
    // only for overlapping ones, and lies in both (closed-form membership, 1e-12); nested or
    // deeply overlapping ones always get one (the segment between the centers meets both).
    let (a, b) = (ellipsoid([0.1, 0.0, 0.0], [0.5; 3]).unwrap(), ellipsoid([0.0, -0.1, 0.0], [0.3; 3]).unwrap());
    let pose_a = pose_from_parts("a", [0.8, 0.0, 0.6, 0.0], [1.0, -2.0, 0.5]).unwrap();
    let center_a = pose_a * Point3::new(0.1, 0.0, 0.0);
    let dir = Vector3::new(0.6, 0.0, 0.8);
    let mut found = 0;
    for k in 0..=60 {
        let gap = 0.02 * k as Real;
        let pose_b = pose_from_parts("b", [0.6, 0.8, 0.0, 0.0], [0.0; 3]).unwrap();
        // Place B's center at center_a + gap · dir.
        let offset = center_a.coords + dir * gap - pose_b.rotation * Vector3::new(0.0, -0.1, 0.0);
        let pose_b = Isometry3::from_parts(offset.into(), pose_b.rotation);
        let center_b = pose_b * Point3::new(0.0, -0.1, 0.0);
        let z = segment_common_point(&a, &pose_a, &b, &pose_b);
        if gap >= 0.8 {
            assert!(z.is_none(), "gap {gap}: no common point for separated spheres, got {z:?}");
            continue;
        }
        let z = z.unwrap_or_else(|| panic!("gap {gap}: overlapping spheres need a common point"));
        assert!((z - center_a).norm() <= 0.5 + 1e-12 && (z - center_b).norm() <= 0.3 + 1e-12, "gap {gap}: {z:?}");
        found += 1;
    }
    assert_eq!(found, 40);
}

#[test]
fn facing_support_points_prove_overlap_off_the_segment() {
    // Two thin ellipsoids meeting at a corner (A along x, radii 1, 0.1, 0.1 at the origin; B
    // along y, radii 0.1, 1, 0.1 at (0.95, 0.95, 0)): they overlap around (0.95, 0, 0), but
    // the segment between their centers leaves A at t ≈ 0.1 and enters B at t ≈ 0.9, so only
    // the facing support points find a common point (their middle, (0.967, −0.018, 0) in
    // closed form, lies in both with p ≈ 0.97).
    let a = ellipsoid([0.0; 3], [1.0, 0.1, 0.1]).unwrap();
    let b = ellipsoid([0.95, 0.95, 0.0], [0.1, 1.0, 0.1]).unwrap();
    let id = Isometry3::identity();
    // Closed-form membership of a world point in both.
    let inside = |z: &Point3| {
        let pa = z.x * z.x + (z.y / 0.1).powi(2) + (z.z / 0.1).powi(2);
        let pb = ((z.x - 0.95) / 0.1).powi(2) + (z.y - 0.95).powi(2) + (z.z / 0.1).powi(2);
        pa <= 1.0 + 1e-12 && pb <= 1.0 + 1e-12
    };
    assert!(distance(&a, &id, &b, &id, None, &NewtonParams::default()).overlapping);
    assert_eq!(segment_common_point(&a, &id, &b, &id), None);
    let z = common_point(&a, &id, &b, &id).expect("the facing support points meet");
    assert!(inside(&z), "{z:?}");
    // Over random poses of a thin rod (radii 0.1, 1, 0.1, centered in its frame) within 0.8 m of
    // A's center, a common point is returned only where the distance solver finds overlap, and
    // always lies in both (closed form); it finds more overlaps than the segment alone.
    let rod = ellipsoid([0.0; 3], [0.1, 1.0, 0.1]).unwrap();
    let in_both = |z: &Point3, pose: &Isometry3| {
        let w = pose.inverse_transform_point(z);
        let pa = z.x * z.x + (z.y / 0.1).powi(2) + (z.z / 0.1).powi(2);
        pa <= 1.0 + 1e-12 && (w.x / 0.1).powi(2) + w.y * w.y + (w.z / 0.1).powi(2) <= 1.0 + 1e-12
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let (mut overlapping, mut found, mut on_segment) = (0, 0, 0);
    for _ in 0..400 {
        let t = Vector3::from_fn(|_, _| rng.random_range(-0.8..0.8));
        let q = nalgebra::Quaternion::from(nalgebra::Vector4::from_fn(|_, _| rng.random_range(-1.0..1.0)));
        let pose = Isometry3::from_parts(t.into(), UnitQuaternion::new_normalize(q));
        let d = distance(&a, &id, &rod, &pose, None, &NewtonParams::default());
        overlapping += usize::from(d.overlapping);
        let segment = segment_common_point(&a, &id, &rod, &pose);
        on_segment += usize::from(segment.is_some());
        match common_point(&a, &id, &rod, &pose) {
            Some(z) => {
                found += 1;
                assert!(d.overlapping && in_both(&z, &pose), "{z:?} at {pose:?}");
            }
            None => assert!(segment.is_none()),
        }
    }
    // Thin rods crossing like an X often share no candidate point (a solve decides those).
    assert!(overlapping > 40 && found > on_segment, "{found} ({on_segment} on the segment) of {overlapping} overlaps");
}

#[test]
fn spheres_match_closed_form_along_a_motion() {
    let s1 = ellipsoid([0.1, 0.0, 0.0], [0.5; 3]).unwrap();
    let s2 = ellipsoid([0.0; 3], [0.8; 3]).unwrap();
    let pose_a = pose_from_parts("a", [0.8, 0.6, 0.0, 0.0], [10.0, -3.0, 2.0]).unwrap();
    let center_a = pose_a * Point3::new(0.1, 0.0, 0.0);
    let mut warm: Option<DistanceWarmStart> = None;
    let (mut cold_it, mut warm_it) = (0, 0);
    for k in 0..60 {
        let c2 = center_a.coords + Vector3::new(3.0 - 0.05 * k as Real, 0.3, -0.2);
        let pose_b = pose_from_parts("b", [0.6, 0.0, 0.8, 0.0], [c2.x, c2.y, c2.z]).unwrap();
        let expected = ((c2 - center_a.coords).norm() - 1.3).max(0.0);
        let r = distance(&s1, &pose_a, &s2, &pose_b, warm.as_ref(), &NewtonParams::default());
        let c = distance(&s1, &pose_a, &s2, &pose_b, None, &NewtonParams::default());
        for res in [&r, &c] {
            assert!(res.status.converged(), "k = {k}: {res:?}");
            assert!((res.distance - expected).abs() < 1e-9, "k = {k}: {} vs {expected}", res.distance);
            assert_eq!(res.overlapping, expected == 0.0);
        }
        if expected > 0.0 {
            // Witnesses lie on the surfaces along the line of centers.
            assert!(((r.witness_a - center_a).norm() - 0.5).abs() < 1e-8);
            assert!(((r.witness_b.coords - c2).norm() - 0.8).abs() < 1e-8);
            let n = (c2 - center_a.coords).normalize();
            assert!((r.normal - n).norm() < 1e-8);
            if k > 0 {
                cold_it += c.iterations;
                warm_it += r.iterations;
            }
        }
        warm = Some(*r.warm_start);
    }
    // Spheres: the cold start on the line of centers is already optimal.
    assert_eq!(cold_it, 0);
    assert!(warm_it > 0);
}

#[test]
fn warm_starts_save_iterations_on_ellipsoids() {
    let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
    let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
    let mut warm: Option<DistanceWarmStart> = None;
    let (mut cold_it, mut warm_it) = (0, 0);
    for k in 0..30 {
        let (s, c) = (0.01 * k as Real).sin_cos();
        let pose_b = pose_from_parts("b", [c, 0.0, s, 0.0], [2.5 - 0.03 * k as Real, 0.4, 0.1]).unwrap();
        let w = distance(&e1, &Isometry3::identity(), &e2, &pose_b, warm.as_ref(), &NewtonParams::default());
        let cold = distance(&e1, &Isometry3::identity(), &e2, &pose_b, None, &NewtonParams::default());
        assert!(w.status.converged() && cold.status.converged());
        assert!((w.distance - cold.distance).abs() < 1e-9);
        // Witnesses on the surfaces and the normal along the witness segment.
        assert!((e1.value_at(&w.witness_a) - 1.0).abs() < 1e-9);
        assert!((e2.value_at(&(pose_b.inverse() * w.witness_b)) - 1.0).abs() < 1e-9);
        if k > 0 {
            assert!(w.warm_started);
            cold_it += cold.iterations;
            warm_it += w.iterations;
        }
        warm = Some(*w.warm_start);
    }
    assert!(warm_it < cold_it, "warm {warm_it} vs cold {cold_it}");
}

/// A warm start whose answer lies past `NewtonParams::warm_reach` (by default half the bodies'
/// summed scales, here
/// 0.5 · (0.9 + 1.0) = 0.95 m) is not used: distance and growth then run exactly as cold (the
/// same answer to the bit, the same iterations, not warm-started); one 5 cm away is used and
/// agrees with the cold answer to 10⁻⁹. `DistanceWarmStart::reaches` and `warm_start_reaches`
/// say the same.
#[test]
fn warm_starts_past_their_reach_are_not_used() {
    use crate::growth::growth;
    let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
    let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
    let (id, params) = (Isometry3::identity(), NewtonParams::default());
    let p0 = pose_from_parts("b", [1.0, 0.0, 0.0, 0.0], [2.5, 0.4, 0.1]).unwrap();
    let (s, c) = (0.01 as Real).sin_cos();
    let near = pose_from_parts("b", [c, s, 0.0, 0.0], [2.46, 0.42, 0.1]).unwrap();
    let far = pose_from_parts("b", [0.8, 0.0, 0.6, 0.0], [-1.5, 1.2, 0.3]).unwrap();
    let d0 = distance(&e1, &id, &e2, &p0, None, &params);
    let g0 = growth(&e1, &id, &e2, &p0, None, &params);
    for (pose, used) in [(near, true), (far, false)] {
        let (w, c) = (
            distance(&e1, &id, &e2, &pose, Some(&d0.warm_start), &params),
            distance(&e1, &id, &e2, &pose, None, &params),
        );
        assert!(w.status.converged() && c.status.converged());
        assert_eq!((w.warm_started, d0.warm_start.reaches(&e1, &e2, &pose)), (used, used));
        assert_eq!(warm_start_reaches(&e1, &e2, &p0, &pose), used);
        let (gw, gc) =
            (growth(&e1, &id, &e2, &pose, Some(&g0.warm_start), &params), growth(&e1, &id, &e2, &pose, None, &params));
        assert_eq!(gw.warm_started, used);
        if used {
            assert!((w.distance - c.distance).abs() < 1e-9 && (gw.value - gc.value).abs() < 1e-9 * gc.value);
        } else {
            assert_eq!((w.distance.to_bits(), w.iterations), (c.distance.to_bits(), c.iterations));
            assert_eq!((gw.value.to_bits(), gw.iterations), (gc.value.to_bits(), gc.iterations));
        }
    }
}

/// The solvers read the warm start's reach from the settings they receive: with
/// `warm_reach` a hundredth of the bodies' summed scales (1.9 cm here), a warm start 5 cm away is
/// not used (the answer is the cold one to the bit), and with a reach of 10 one 4 m away is within
/// reach; `reaches_with` and `warm_start_reaches_with` say the same.
#[test]
fn warm_reach_is_read_from_the_settings() {
    use crate::growth::growth;
    use crate::warm_start_reaches_with;
    let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
    let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
    let id = Isometry3::identity();
    let short = NewtonParams { warm_reach: 0.01, ..NewtonParams::default() };
    let long = NewtonParams { warm_reach: 10.0, ..NewtonParams::default() };
    let p0 = pose_from_parts("b", [1.0, 0.0, 0.0, 0.0], [2.5, 0.4, 0.1]).unwrap();
    let (s, c) = (0.01 as Real).sin_cos();
    let near = pose_from_parts("b", [c, s, 0.0, 0.0], [2.46, 0.42, 0.1]).unwrap();
    let far = pose_from_parts("b", [0.8, 0.0, 0.6, 0.0], [-1.5, 1.2, 0.3]).unwrap();
    let d0 = distance(&e1, &id, &e2, &p0, None, &short);
    let g0 = growth(&e1, &id, &e2, &p0, None, &short);
    let w = distance(&e1, &id, &e2, &near, Some(&d0.warm_start), &short);
    let c = distance(&e1, &id, &e2, &near, None, &short);
    assert!(!w.warm_started && !d0.warm_start.reaches_with(&e1, &e2, &near, &short));
    assert_eq!((w.distance.to_bits(), w.iterations), (c.distance.to_bits(), c.iterations));
    let (gw, gc) =
        (growth(&e1, &id, &e2, &near, Some(&g0.warm_start), &short), growth(&e1, &id, &e2, &near, None, &short));
    assert!(!gw.warm_started);
    assert_eq!((gw.value.to_bits(), gw.iterations), (gc.value.to_bits(), gc.iterations));
    assert!(!warm_start_reaches_with(&e1, &e2, &p0, &near, &short));
    assert!(d0.warm_start.reaches(&e1, &e2, &near) && !d0.warm_start.reaches(&e1, &e2, &far));
    assert!(d0.warm_start.reaches_with(&e1, &e2, &far, &long) && warm_start_reaches_with(&e1, &e2, &p0, &far, &long));
}

#[test]
fn elongated_ellipsoids_against_brute_force() {
    // Two needles crossing at right angles, 0.3 apart along z: distance 0.3 − 2·0.05 = 0.2.
    let n1 = ellipsoid([0.0; 3], [2.0, 0.05, 0.05]).unwrap();
    let n2 = ellipsoid([0.0; 3], [2.0, 0.05, 0.05]).unwrap();
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let pose_b = pose_from_parts("b", [h, 0.0, 0.0, h], [0.0, 0.0, 0.3]).unwrap();
    let r = distance(&n1, &Isometry3::identity(), &n2, &pose_b, None, &NewtonParams::default());
    assert!(r.status.converged());
    assert!((r.distance - 0.2).abs() < 1e-9, "{}", r.distance);
}

/// Distance from the point `z` (relative to the center) to the axis-aligned ellipsoid with
/// semi-axes `r`, for `z` outside it: the closest point is x_i = z_i r_i² / (r_i² + t) with
/// t ≥ 0 the root of Σ (x_i / r_i)² = 1 (decreasing in t), found by bisection.
fn point_to_ellipsoid(z: &Vector3, r: &[Real; 3]) -> Real {
    let x = |t: Real| Vector3::from_fn(|i, _| z[i] * r[i] * r[i] / (r[i] * r[i] + t));
    let f = |t: Real| (0..3).map(|i| (x(t)[i] / r[i]).powi(2)).sum::<Real>() - 1.0;
    let (mut lo, mut hi) = (0.0, 1.0);
    while f(hi) > 0.0 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (z - x(hi)).norm()
}

#[test]
fn small_bodies_far_from_the_frame_origin_converge_to_the_closed_form() {
    // A 0.9 × 0.3 × 0.5 m ellipsoid whose center lies 10 km (and 1 km) from its own frame's
    // origin (a body fitted in site coordinates), posed anywhere, and a 1 mm / 1 cm sphere 0.1
    // mm to 1 cm from it. In A's frame the points lie ~10⁴ m out, where rounding (~10⁻¹² m) is
    // 10⁻⁹ of the sphere; the query's working frame at the smaller body keeps the iterates
    // exact. Every answer converges to the closed form (point-to-ellipsoid distance minus the radius, 1e-9 m), and the
    // growth measure of two spheres (1 m and 1 mm, 10 km out) matches (|c₁ − c₂| − r₂)²/r₁²
    // inside and outside, to 1e-9 relative.
    let params = NewtonParams::default();
    let radii = [0.9, 0.3, 0.5];
    let pose_a = pose_from_parts("a", [0.8, 0.0, 0.6, 0.0], [3.0, -1.0, 2.0]).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
    let mut runs = 0;
    for offset in [1e4, 1e3] {
        let center = Vector3::new(offset, -0.6 * offset, 0.3 * offset);
        let a = ellipsoid([center.x, center.y, center.z], radii).unwrap();
        for radius in [1e-3, 1e-2] {
            let b = ellipsoid([0.0; 3], [radius; 3]).unwrap();
            for gap in [1e-4, 1e-3, 1e-2] {
                for _ in 0..20 {
                    let m = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0)).normalize();
                    // A's boundary point along m (A's frame), then B's center `gap + radius` out
                    // along the normal there.
                    let s = 1.0 / (0..3).map(|i| (m[i] / radii[i]).powi(2)).sum::<Real>().sqrt();
                    let n = Vector3::from_fn(|i, _| m[i] * s / (radii[i] * radii[i])).normalize();
                    let z = m * s + n * (gap + radius);
                    let q = Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0));
                    let rot = UnitQuaternion::new_normalize(nalgebra::Quaternion::new(q.x, q.y, q.z, 0.5));
                    let pose_b = pose_a * Isometry3::from_parts((center + z).into(), rot);
                    let expected = point_to_ellipsoid(&z, &radii) - radius;
                    let d = distance(&a, &pose_a, &b, &pose_b, None, &params);
                    assert!(d.status.converged() && !d.overlapping, "offset {offset}, radius {radius}: {d:?}");
                    assert!(
                        (d.distance - expected).abs() <= 1e-9,
                        "offset {offset}, radius {radius}, gap {gap}: {} vs {expected}",
                        d.distance
                    );
                    assert!(((d.witness_b - d.witness_a).norm() - d.distance).abs() <= 1e-9);
                    // The reversed pair (the small body as the frame of reference).
                    let r = distance(&b, &pose_b, &a, &pose_a, None, &params);
                    assert!(r.status.converged() && (r.distance - expected).abs() <= 1e-9, "{r:?}");
                    runs += 1;
                }
            }
        }
    }
    assert_eq!(runs, 240);
    let center = Vector3::new(1e4, -6e3, 3e3);
    let big = ellipsoid([center.x, center.y, center.z], [1.0; 3]).unwrap();
    let small = ellipsoid([0.0; 3], [1e-3; 3]).unwrap();
    for along in [0.5, 0.999, 1.0005, 1.01] {
        let m = Vector3::new(0.48, -0.6, 0.64);
        let pose_b = Isometry3::translation(center.x + along * m.x, center.y + along * m.y, center.z + along * m.z);
        let g = crate::growth::growth(&big, &Isometry3::identity(), &small, &pose_b, None, &params);
        let expected = (along - 1e-3) * (along - 1e-3);
        assert!(g.status.converged(), "along {along}: {g:?}");
        assert!((g.value - expected).abs() <= 1e-9 * expected.max(1.0), "along {along}: {} vs {expected}", g.value);
    }
}

#[test]
fn cold_runs_do_not_depend_on_the_bodies_size() {
    // The bench's chair / human pair (2d = 6) at its first 100 cold poses, scaled by k: the
    // same problem in other units (a 1 mm, 1 cm, 10 cm, 10 m and 1 km chair). Reference: the
    // unit problem's answers — each distance k times the scaled one's (to 1e-9 of k(1 + d)),
    // witnesses to 1e-7·k, growth values equal (dimensionless, to 1e-9 of max(1, value)) — and
    // its Newton iterations: the scaled runs of each query take within 3 % of them (the line
    // searches' merit measures stationarity in units of the bodies' size, `merit_length`).
    use crate::growth::{growth, GrowthResult};
    let (chair, human) = crate::test_bodies::bench_bodies(6);
    let poses = crate::test_bodies::bench_cold_poses(100);
    let params = NewtonParams::default();
    let id = Isometry3::identity();
    let unit: Vec<(DistanceResult, GrowthResult)> = poses
        .iter()
        .map(|p| (distance(&chair, p, &human, &id, None, &params), growth(&chair, p, &human, &id, None, &params)))
        .collect();
    let unit_iterations = |pick: fn(&(DistanceResult, GrowthResult)) -> usize| unit.iter().map(pick).sum::<usize>();
    let (unit_d, unit_g) = (unit_iterations(|u| u.0.iterations), unit_iterations(|u| u.1.iterations));
    let rescaled = |body: &Body, k: Real| {
        let c = body.center() * k;
        Body::new(body.polynomial().clone(), [c.x, c.y, c.z], body.scale() * k, Default::default()).unwrap()
    };
    for k in [1e-3, 1e-2, 1e-1, 10.0, 1e3] {
        let (a, b) = (rescaled(&chair, k), rescaled(&human, k));
        let (mut iterations_d, mut iterations_g) = (0, 0);
        for (p, (u, ug)) in poses.iter().zip(&unit) {
            let pk = Isometry3::from_parts((p.translation.vector * k).into(), p.rotation);
            let d = distance(&a, &pk, &b, &id, None, &params);
            assert!(d.status.converged() && d.overlapping == u.overlapping, "k = {k}: {d:?}");
            assert!((d.distance - k * u.distance).abs() <= 1e-9 * k * (1.0 + u.distance), "k = {k}: {d:?} vs {u:?}");
            let w = (d.witness_a.coords - u.witness_a.coords * k).norm();
            assert!(w <= 1e-7 * k, "k = {k}: witness on A {w:e} m off");
            let g = growth(&a, &pk, &b, &id, None, &params);
            assert!(g.status.converged(), "k = {k}: {g:?}");
            assert!((g.value - ug.value).abs() <= 1e-9 * ug.value.max(1.0), "k = {k}: {} vs {}", g.value, ug.value);
            iterations_d += d.iterations;
            iterations_g += g.iterations;
        }
        for (what, n, unit_n) in [("distance", iterations_d, unit_d), ("growth", iterations_g, unit_g)] {
            let ratio = n as Real / unit_n as Real;
            assert!((0.97..=1.03).contains(&ratio), "k = {k}: {n} against {unit_n} {what} Newton iterations");
        }
    }
}

#[test]
fn warm_starts_agree_with_cold_answers_through_contact_and_back() {
    // Two ellipsoids on a smooth motion that approaches, passes through (overlap, touching,
    // one inside the other's growth range) and separates again; the warm answers (cubic
    // predictor, give-up on nonpositive multipliers) must equal the cold ones at every step.
    let e1 = ellipsoid([0.0; 3], [0.9, 0.3, 0.5]).unwrap();
    let e2 = ellipsoid([0.1, 0.0, 0.0], [0.4, 1.0, 0.2]).unwrap();
    let params = NewtonParams::default();
    let (mut wd, mut wg): (Option<DistanceWarmStart>, Option<GrowthWarmStart>) = (None, None);
    let (mut warm_it, mut cold_it, mut overlapping) = (0, 0, 0);
    for k in 0..120 {
        let s = k as Real / 119.0;
        let (sn, cs) = (0.6 * s).sin_cos();
        let pose_b = pose_from_parts("b", [cs, 0.0, sn, 0.0], [3.0 - 6.0 * s, 0.3, 0.1 * (3.0 * s).sin()]).unwrap();
        let id = Isometry3::identity();
        let d = distance(&e1, &id, &e2, &pose_b, wd.as_ref(), &params);
        let c = distance(&e1, &id, &e2, &pose_b, None, &params);
        let g = super::super::growth::growth(&e1, &id, &e2, &pose_b, wg.as_ref(), &params);
        let gc = super::super::growth::growth(&e1, &id, &e2, &pose_b, None, &params);
        assert!(d.status.converged() && c.status.converged(), "k = {k}: {d:?}");
        assert!(g.status.converged() && gc.status.converged(), "k = {k}: {g:?}");
        assert!((d.distance - c.distance).abs() <= 1e-9, "k = {k}: {} vs {}", d.distance, c.distance);
        assert_eq!(d.overlapping, c.overlapping, "k = {k}");
        assert!((g.value - gc.value).abs() <= 1e-9 * gc.value.max(1.0), "k = {k}: {} vs {}", g.value, gc.value);
        overlapping += usize::from(c.overlapping);
        if k > 0 {
            warm_it += d.iterations + g.iterations;
            cold_it += c.iterations + gc.iterations;
        }
        wd = Some(*d.warm_start);
        wg = Some(*g.warm_start);
    }
    assert!(overlapping > 10 && overlapping < 100, "the motion must pass through: {overlapping}");
    assert!(2 * warm_it < cold_it, "warm {warm_it} vs cold {cold_it} iterations");
}

/// How good a cold start has to be: Newton from the exact witnesses moved by δ·(size of A + size of
/// B) in a random direction and put back on the boundaries (least-squares multipliers, as a cold
/// start). The iteration counts are deterministic; this pins down the ceiling of any better start.
mod start_quality {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Mean Newton iterations from witnesses perturbed by `delta`, and how many runs reached the
    /// reference distance to 1e-8 m, over the separated ones of the first `count` cold poses of
    /// `sublevel-lab bench` (chair_101 against human_10 at 2d = `degree`).
    fn iterations_from_perturbed_witnesses(degree: usize, count: usize, delta: Real) -> (Real, usize, usize) {
        let (a, b) = crate::test_bodies::bench_bodies(degree);
        let poses = crate::test_bodies::bench_cold_poses(count);
        let params = NewtonParams::default();
        let id = Isometry3::identity();
        let mut jitter_rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let (mut runs, mut iterations, mut reached) = (0usize, 0usize, 0usize);
        for p in &poses {
            let d = distance(&a, p, &b, &id, None, &params);
            if d.overlapping || !d.status.converged() {
                continue;
            }
            // The solver's frame is A's: B posed by p⁻¹.
            let rel = p.inv_mul(&id);
            let (ba, bb) = (PosedBody::unposed(&a), PosedBody::new(&b, &rel));
            let len = a.scale() + b.scale();
            let mut moved = |w: &Point3, body: &PosedBody<'_>| {
                let j = Vector3::from_fn(|_, _| jitter_rng.random_range(-1.0..1.0));
                let c = body.interior_point();
                let w = p.inverse_transform_point(w).coords + j * (delta * len);
                boundary_on_segment_within(body, &c, &(c + (w - c) * 10.0), 1e-12)
            };
            let (x0, y0) = (moved(&d.witness_a, &ba), moved(&d.witness_b, &bb));
            let out = kkt_newton(&ba, &bb, x0, y0, None, &params, params.max_iterations, false);
            runs += 1;
            iterations += out.iterations;
            reached += usize::from(out.status.converged() && ((out.y - out.x).norm() - d.distance).abs() < 1e-8);
        }
        (iterations as Real / runs as Real, runs, reached)
    }

    #[test]
    fn even_millimeter_starts_take_three_newton_iterations() {
        // Over all 300 poses (2d = 6 and 8) the mean grows from about 3 iterations at δ = 1e-3 to
        // about 7 at δ = 1e-1 (where a few runs end elsewhere); the support-table cold start is
        // worth δ ≈ 3e-2 (about 10 cm here).
        for (delta, low, high) in [(1e-3, 2.5, 3.5), (1e-2, 3.5, 4.6), (3e-2, 4.5, 5.6)] {
            let (mean, runs, reached) = iterations_from_perturbed_witnesses(6, 100, delta);
            assert!(runs > 80, "{runs} separated poses");
            assert_eq!(reached, runs, "δ = {delta}: every run reaches the reference distance");
            assert!((low..=high).contains(&mean), "δ = {delta}: {mean:.2} iterations per query");
        }
    }
}
