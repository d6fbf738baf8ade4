//! Shape distances against closed forms, their separating-plane certificates and coal.

use super::*;
use rand::{Rng, SeedableRng};
use sublevel_core::math::UnitQuaternion;
use sublevel_core::primitive::PrimitiveFile;

fn prim(file: PrimitiveFile) -> Primitive {
    Primitive::from_file(&file).unwrap()
}

fn shapes() -> Vec<(&'static str, Primitive)> {
    vec![
        ("box", prim(PrimitiveFile::Box { size: [0.4, 0.3, 0.2] })),
        ("board", prim(PrimitiveFile::Box { size: [1.2, 1.0, 0.04] })),
        ("cylinder", prim(PrimitiveFile::Cylinder { radius: 0.05, height: 0.3 })),
        ("can", prim(PrimitiveFile::Cylinder { radius: 0.1, height: 0.2 })),
        ("sphere", prim(PrimitiveFile::Sphere { radius: 0.1 })),
        ("capsule", prim(PrimitiveFile::Capsule { radius: 0.05, height: 0.3 })),
    ]
}

fn random_pose(rng: &mut impl Rng, spread: Real) -> Isometry3 {
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    ));
    let t =
        Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * spread;
    Isometry3::from_parts(t.into(), q)
}

/// Signed distance of a world point to a posed primitive's boundary.
fn surface_gap(p: &Primitive, pose: &Isometry3, x: &Point3) -> Real {
    p.closest_boundary_point(&pose.inverse_transform_point(x).coords).0
}

/// Every pair of primitive types at random poses: converged, witnesses on both surfaces, and the
/// separating-plane lower bound equal to the distance (the duality certificate of the optimum).
#[test]
fn random_primitive_pairs_are_certified_optimal() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let list = shapes();
    let mut worst_gap: Real = 0.0;
    let mut worst_surface: Real = 0.0;
    let mut iters = 0;
    let mut count = 0;
    for (na, a) in &list {
        for (nb, b) in &list {
            for _ in 0..300 {
                let pa = random_pose(&mut rng, 0.2);
                let pb = random_pose(&mut rng, 0.6);
                let r = shape_distance(ShapeRef::Primitive(a), &pa, ShapeRef::Primitive(b), &pb, None).unwrap();
                assert_eq!(r.status, SolveStatus::Converged, "{na}-{nb} {pa:?} {pb:?} {r:?}");
                iters += r.iterations;
                count += 1;
                if r.overlapping {
                    assert!(surface_gap(a, &pa, &r.witness_a) <= 1e-12, "{na}-{nb} {r:?}");
                    assert!(surface_gap(b, &pb, &r.witness_b) <= 1e-12, "{na}-{nb} {r:?}");
                    continue;
                }
                let ga = surface_gap(a, &pa, &r.witness_a).abs();
                let gb = surface_gap(b, &pb, &r.witness_b).abs();
                worst_surface = worst_surface.max(ga).max(gb);
                assert!((r.distance - (r.witness_b - r.witness_a).norm()).abs() < 1e-14);
                let lb = r.lower_bound.unwrap();
                worst_gap = worst_gap.max(r.distance - lb);
                assert!(
                    r.distance - lb <= 1e-10 && lb - r.distance <= 1e-12,
                    "{na}-{nb} gap {} {r:?}",
                    r.distance - lb
                );
            }
        }
    }
    eprintln!(
        "worst certificate gap {worst_gap:e} m, worst surface gap {worst_surface:e} m, mean iterations {}",
        iters as f64 / count as f64
    );
    assert!(worst_surface <= 1e-12);
}

/// A quadratic body p(u) = ‖u‖² is a ball: against every primitive the active-set answer equals the
/// sphere's closed form.
#[test]
fn a_ball_body_matches_the_sphere_closed_form() {
    use sublevel_core::body::FitReport;
    use sublevel_core::poly::Polynomial;
    let radius = 0.1;
    let p = Polynomial::from_terms(2, &[([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0)]).unwrap();
    let ball = Body::new(p, [0.0; 3], radius, FitReport::default()).unwrap();
    let sphere = prim(PrimitiveFile::Sphere { radius });
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut worst: Real = 0.0;
    for (name, other) in shapes().into_iter().filter(|(n, _)| *n != "sphere") {
        for _ in 0..300 {
            let pa = random_pose(&mut rng, 0.2);
            let pb = random_pose(&mut rng, 0.6);
            let exact =
                shape_distance(ShapeRef::Primitive(&sphere), &pa, ShapeRef::Primitive(&other), &pb, None).unwrap();
            let r = shape_distance(ShapeRef::Body(&ball), &pa, ShapeRef::Primitive(&other), &pb, None).unwrap();
            assert_eq!(r.status, SolveStatus::Converged, "{name} {r:?}");
            assert_eq!(r.overlapping, exact.overlapping, "{name} {r:?} {exact:?}");
            worst = worst.max((r.distance - exact.distance).abs());
            assert!((r.distance - exact.distance).abs() <= 1e-12, "{name} {} vs {}", r.distance, exact.distance);
            if !r.overlapping {
                assert!(
                    (r.witness_a - exact.witness_a).norm() <= 1e-6 && (r.witness_b - exact.witness_b).norm() <= 1e-6
                );
            }
        }
    }
    eprintln!("ball body against primitives: worst |Δd| {worst:e} m");
}

/// Degree-6 sos-convex bodies against every primitive: converged, the body's witness on its
/// boundary, the primitive's on its surface, and the separating plane through the witnesses
/// certifies the distance (the body's support value from its own support-point solve).
#[test]
fn bodies_against_primitives_are_certified_by_the_separating_plane() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut worst: Real = 0.0;
    let mut iterations = 0;
    let mut count = 0;
    for seed in 0..4 {
        let body = crate::test_bodies::random_body(6, seed);
        for (name, other) in shapes() {
            for _ in 0..60 {
                let pa = random_pose(&mut rng, 0.2);
                let mut pb = random_pose(&mut rng, 1.5);
                pb.translation.vector *= 1.5;
                let r = shape_distance(ShapeRef::Body(&body), &pa, ShapeRef::Primitive(&other), &pb, None).unwrap();
                assert_eq!(r.status, SolveStatus::Converged, "{name} {r:?}");
                iterations += r.iterations;
                count += 1;
                let on_body = body.value_at(&pa.inverse_transform_point(&r.witness_a));
                assert!(on_body <= 1.0 + 1e-10, "{name} p = {on_body}");
                assert!(surface_gap(&other, &pb, &r.witness_b) <= 1e-12);
                if r.overlapping {
                    continue;
                }
                assert!((on_body - 1.0).abs() <= 1e-10, "{name} p = {on_body}");
                let lower =
                    separating_plane_bound(ShapeRef::Body(&body), &pa, ShapeRef::Primitive(&other), &pb, &r.normal)
                        .unwrap();
                worst = worst.max(r.distance - lower);
                assert!(r.distance - lower <= 1e-9 && lower <= r.distance + 1e-9, "{name}: {} vs {lower}", r.distance);
            }
        }
    }
    eprintln!(
        "bodies against primitives: worst certificate gap {worst:e} m, mean iterations {}",
        iterations as f64 / count as f64
    );
}

/// A warm start from the previous answer along a motion gives the cold answer; for a body in no
/// more iterations; between boxes, capsules and spheres the cold start is used (nearly exact).
#[test]
fn warm_starts_follow_a_motion() {
    let list = shapes();
    let body = crate::test_bodies::random_body(6, 1);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut pairs: Vec<(String, ShapeRef<'_>, ShapeRef<'_>)> = Vec::new();
    for (na, a) in &list {
        pairs.push((format!("body-{na}"), ShapeRef::Body(&body), ShapeRef::Primitive(a)));
        for (nb, b) in &list {
            pairs.push((format!("{na}-{nb}"), ShapeRef::Primitive(a), ShapeRef::Primitive(b)));
        }
    }
    for (name, a, b) in pairs {
        let pa = random_pose(&mut rng, 0.1);
        let start = if matches!(a, ShapeRef::Body(_)) { 2.5 } else { 0.7 };
        let mut pb = Isometry3::from_parts(Vector3::new(start, 0.1, 0.05).into(), random_pose(&mut rng, 0.0).rotation);
        let mut warm = ShapeWarmStart::default();
        let (mut warm_iterations, mut cold_iterations) = (0, 0);
        for _ in 0..100 {
            pb.translation.vector -= Vector3::new(0.004, 0.0, 0.0);
            pb.rotation = UnitQuaternion::from_euler_angles(0.01, 0.0, 0.005) * pb.rotation;
            let cold = shape_distance(a, &pa, b, &pb, None).unwrap();
            let w = shape_distance(a, &pa, b, &pb, Some(&warm)).unwrap();
            assert_eq!(w.status, SolveStatus::Converged);
            assert_eq!(w.overlapping, cold.overlapping, "{name}");
            assert!((w.distance - cold.distance).abs() <= 1e-10, "{name}: {} vs {}", w.distance, cold.distance);
            warm = w.warm_start;
            warm_iterations += w.iterations;
            cold_iterations += cold.iterations;
        }
        if name.starts_with("body") {
            assert!(warm_iterations <= cold_iterations, "{name}: warm {warm_iterations} cold {cold_iterations}");
        } else if !name.contains("cylinder") && !name.contains("can") {
            assert_eq!(warm_iterations, cold_iterations, "{name}");
        }
    }
}

/// Where active-set methods fail: degenerate contacts with closed-form distances, each certified
/// (converged, exact to 10⁻¹² m between primitives, 10⁻¹⁰ m with a body) at gaps from 1 cm down to
/// 1 nm; touching, each is overlapping or within that tolerance, and unconverged answers are
/// flagged (never a distance above the tolerance).
#[test]
fn stability_suite_degenerate_contacts() {
    use std::f64::consts::FRAC_PI_4;
    let cube = prim(PrimitiveFile::Box { size: [1.0; 3] });
    let tiny = prim(PrimitiveFile::Box { size: [1e-6; 3] });
    let capsule = prim(PrimitiveFile::Capsule { radius: 0.1, height: 2.0 });
    let ball = {
        use sublevel_core::body::FitReport;
        use sublevel_core::poly::Polynomial;
        let p = Polynomial::from_terms(2, &[([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0)]).unwrap();
        Body::new(p, [0.0; 3], 0.3, FitReport::default()).unwrap()
    };
    let floor = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: 0.0 });
    let at = |t: [Real; 3], q: UnitQuaternion| Isometry3::from_parts(Vector3::from(t).into(), q);
    let id = UnitQuaternion::identity();
    // The unit cube with its body diagonal along z (lowest corner √3/2 below its center).
    let corner_down = UnitQuaternion::rotation_between(&Vector3::new(1.0, 1.0, 1.0), &-Vector3::z()).unwrap();
    let edge_x = UnitQuaternion::from_euler_angles(FAC, 0.0, 0.0);
    const FAC: Real = FRAC_PI_4;
    let edge_y = UnitQuaternion::from_euler_angles(0.0, FAC, 0.0);
    let s3 = 3f64.sqrt() / 2.0;
    let s2 = 2f64.sqrt() / 2.0;
    for h in [1e-2, 1e-5, 1e-9, 0.0] {
        let diag = Vector3::new(0.0, 1.0, 1.0).normalize();
        let capsule_pose = at(
            (Vector3::new(0.2, 0.5, 0.5) + diag * (0.1 + h)).into(),
            UnitQuaternion::from_euler_angles(0.0, FAC * 2.0, 0.0),
        );
        let cases: Vec<(&str, ShapeRef<'_>, Isometry3, ShapeRef<'_>, Isometry3)> = vec![
            (
                "corner on face",
                ShapeRef::Primitive(&cube),
                Isometry3::identity(),
                ShapeRef::Primitive(&cube),
                at([0.1, -0.2, 0.5 + s3 + h], corner_down),
            ),
            (
                "edge across edge",
                ShapeRef::Primitive(&cube),
                at([0.0; 3], edge_x),
                ShapeRef::Primitive(&cube),
                at([0.0, 0.0, 2.0 * s2 + h], edge_y),
            ),
            (
                "coplanar faces",
                ShapeRef::Primitive(&cube),
                Isometry3::identity(),
                ShapeRef::Primitive(&cube),
                at([0.3, 0.2, 1.0 + h], id),
            ),
            (
                "capsule along an edge",
                ShapeRef::Primitive(&cube),
                Isometry3::identity(),
                ShapeRef::Primitive(&capsule),
                capsule_pose,
            ),
            (
                "floor touching a body",
                ShapeRef::Primitive(&floor),
                Isometry3::identity(),
                ShapeRef::Body(&ball),
                at([0.2, 0.1, 0.3 + h], id),
            ),
            (
                "micrometer box on a face",
                ShapeRef::Primitive(&tiny),
                at([0.1, 0.1, 0.5 + 0.5e-6 + h], id),
                ShapeRef::Primitive(&cube),
                Isometry3::identity(),
            ),
            (
                "body on a face",
                ShapeRef::Body(&ball),
                at([0.1, -0.3, 0.8 + h], corner_down),
                ShapeRef::Primitive(&cube),
                Isometry3::identity(),
            ),
        ];
        for (name, a, pa, b, pb) in cases {
            for (a, pa, b, pb) in [(a, pa, b, pb), (b, pb, a, pa)] {
                let r = shape_distance(a, &pa, b, &pb, None).unwrap();
                let tolerance =
                    if matches!(a, ShapeRef::Body(_)) || matches!(b, ShapeRef::Body(_)) { 1e-10 } else { 1e-12 };
                if h == 0.0 {
                    // Touching: overlapping, or within the tolerance and either converged or
                    // flagged (a curved body touching a face has a zero multiplier: Newton slows
                    // to linear convergence there).
                    assert!(r.overlapping || r.distance <= tolerance, "{name} touching: {r:?}");
                    assert!(
                        r.overlapping
                            || r.status.converged()
                            || matches!(a, ShapeRef::Body(_))
                            || matches!(b, ShapeRef::Body(_))
                    );
                } else {
                    assert_eq!(r.status, SolveStatus::Converged, "{name} at {h}: {r:?}");
                    assert!(!r.overlapping, "{name} at {h}: {r:?}");
                    assert!(
                        (r.distance - h).abs() <= tolerance,
                        "{name} at {h}: {} off by {:e}",
                        r.distance,
                        r.distance - h
                    );
                }
            }
        }
    }
}

/// Pose gradients against central differences of the answer itself: the distance of separated
/// pairs of every primitive type, and the signed distance of overlapping pairs where the depth is
/// exact (box–box along translations, sphere–box, capsule–capsule, a floor under a box).
#[test]
fn gradients_match_finite_differences() {
    use crate::gradient::perturb_pose;
    let list = shapes();
    let floor = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: 0.0 });
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let eps = 1e-6;
    let twist = |k: usize, s: Real| {
        let mut v = Vector3::zeros();
        let mut w = Vector3::zeros();
        if k < 3 {
            v[k] = s;
        } else {
            w[k - 3] = s;
        }
        (v, w)
    };
    // Two boxes in contact touch along a face or an edge: the depth's derivative along a rotation is
    // then one-sided (a subgradient), so their check covers the translations only.
    let check = |name: &str, a: &Primitive, pa: &Isometry3, b: &Primitive, pb: &Isometry3, signed: bool| {
        let components = if signed && name == "box-box" { 3 } else { 6 };
        let value = |pa: &Isometry3, pb: &Isometry3| {
            let s = shape_signed_distance(ShapeRef::Primitive(a), pa, ShapeRef::Primitive(b), pb, None).unwrap();
            if signed {
                s.value
            } else {
                s.distance.distance
            }
        };
        let s = shape_signed_distance(ShapeRef::Primitive(a), pa, ShapeRef::Primitive(b), pb, None).unwrap();
        let (ga, gb) = if signed { s.gradient() } else { s.distance.gradient() };
        for k in 0..components {
            let (v, w) = twist(k, eps);
            let fd_a = (value(&perturb_pose(pa, &v, &w), pb) - value(&perturb_pose(pa, &-v, &-w), pb)) / (2.0 * eps);
            let fd_b = (value(pa, &perturb_pose(pb, &v, &w)) - value(pa, &perturb_pose(pb, &-v, &-w))) / (2.0 * eps);
            assert!((fd_a - ga.to_array()[k]).abs() <= 1e-5, "{name} a[{k}]: fd {fd_a} vs {}", ga.to_array()[k]);
            assert!((fd_b - gb.to_array()[k]).abs() <= 1e-5, "{name} b[{k}]: fd {fd_b} vs {}", gb.to_array()[k]);
        }
    };
    for (na, a) in &list {
        for (nb, b) in &list {
            let mut done = 0;
            while done < 5 {
                let pa = random_pose(&mut rng, 0.2);
                let pb = random_pose(&mut rng, 0.8);
                let r = shape_distance(ShapeRef::Primitive(a), &pa, ShapeRef::Primitive(b), &pb, None).unwrap();
                if r.distance > 1e-3 {
                    check(&format!("{na}-{nb}"), a, &pa, b, &pb, false);
                    done += 1;
                }
            }
        }
    }
    let cube = prim(PrimitiveFile::Box { size: [0.4, 0.3, 0.2] });
    let ball = prim(PrimitiveFile::Sphere { radius: 0.1 });
    let capsule = prim(PrimitiveFile::Capsule { radius: 0.05, height: 0.3 });
    for (name, a, b, spread) in [
        ("box-box", &cube, &cube, 0.15),
        ("sphere-box", &ball, &cube, 0.12),
        ("capsule-capsule", &capsule, &capsule, 0.05),
        ("floor-box", &floor, &cube, 0.05),
    ] {
        let mut done = 0;
        while done < 10 {
            let pa = if name == "floor-box" { Isometry3::identity() } else { random_pose(&mut rng, 0.05) };
            let pb = random_pose(&mut rng, spread);
            let s = shape_signed_distance(ShapeRef::Primitive(a), &pa, ShapeRef::Primitive(b), &pb, None).unwrap();
            if s.value < -1e-3 && s.converged {
                check(name, a, &pa, b, &pb, true);
                done += 1;
            }
        }
    }
}
