//! Integration tests: pose gradients (`query::gradient`) against central finite differences that
//! re-solve the query at perturbed poses (pose ← exp(ξ^)·pose, left / world-frame twists).
//!
//! Tolerance: each of the 12 components (two poses × 6) agrees with the finite difference to
//! `1e-5 · max(1, ‖∇‖∞)` (relative to the gradient's size; step h = 1e-5 m / rad, so the O(h²)
//! truncation and the O(ε/h) rounding of the re-solved values, ε ≈ 1e-13 relative, stay far below).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;
use sublevel::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel::query::gradient::perturb_pose;
use sublevel::query::{distance, distance_gradient, growth, growth_gradient, NewtonParams, PoseGradient};
use sublevel::Body;

const H: Real = 1e-5;
const TOL: Real = 1e-5;

fn load(file: &str) -> Body {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests").join("data").join(file);
    Body::load(&p).unwrap()
}

/// Central differences of `f` along the 6 twist components of pose `which` (0 or 1).
fn finite_difference(
    f: &dyn Fn(&Isometry3, &Isometry3) -> Real,
    pa: &Isometry3,
    pb: &Isometry3,
    which: usize,
) -> [Real; 6] {
    let mut out = [0.0; 6];
    for (k, o) in out.iter_mut().enumerate() {
        let mut xi = [0.0; 6];
        let mut eval = |s: Real| {
            xi[k] = s * H;
            let (v, w) = (Vector3::new(xi[0], xi[1], xi[2]), Vector3::new(xi[3], xi[4], xi[5]));
            if which == 0 {
                f(&perturb_pose(pa, &v, &w), pb)
            } else {
                f(pa, &perturb_pose(pb, &v, &w))
            }
        };
        *o = (eval(1.0) - eval(-1.0)) / (2.0 * H);
    }
    out
}

fn assert_close(what: &str, g: &PoseGradient, fd: &[Real; 6]) {
    let a = g.to_array();
    let scale = a.iter().chain(fd.iter()).fold(1.0_f64, |m, v| m.max(v.abs()));
    for k in 0..6 {
        assert!(
            (a[k] - fd[k]).abs() <= TOL * scale,
            "{what}: component {k}: analytic {a:?} vs finite difference {fd:?}"
        );
    }
}

fn random_pose(rng: &mut ChaCha8Rng, center: Vector3, spread: Real) -> Isometry3 {
    let t = center
        + Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * spread;
    Isometry3::from_parts(t.into(), UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random()))
}

/// Separated chair/human pairs at 2d = 2, 4, 6: ∂D/∂ξ_a, ∂D/∂ξ_b match finite differences, and the
/// two gradients cancel (a rigid motion of both leaves D unchanged).
#[test]
fn distance_gradient_matches_finite_differences() {
    let params = NewtonParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for degree in [2, 4, 6] {
        let a = load(&format!("chair_101.deg{degree}.json"));
        let b = load(&format!("human_10.deg{degree}.json"));
        let mut checked = 0;
        for _ in 0..20 {
            if checked == 2 {
                break;
            }
            let pa = random_pose(&mut rng, Vector3::zeros(), 0.3);
            let pb = random_pose(&mut rng, Vector3::new(1.8, 0.3, 0.0), 0.4);
            let r = distance(&a, &pa, &b, &pb, None, &params);
            if r.overlapping || !r.status.converged() || r.distance < 0.05 {
                continue;
            }
            let f = |x: &Isometry3, y: &Isometry3| {
                let s = distance(&a, x, &b, y, Some(&r.warm_start), &params);
                assert!(s.status.converged() && !s.overlapping);
                s.distance
            };
            let (ga, gb) = distance_gradient(&r);
            assert_close(&format!("2d = {degree}: dD/dξ_a"), &ga, &finite_difference(&f, &pa, &pb, 0));
            assert_close(&format!("2d = {degree}: dD/dξ_b"), &gb, &finite_difference(&f, &pa, &pb, 1));
            assert!((ga.linear + gb.linear).norm() < 1e-12 && (ga.angular + gb.angular).norm() < 1e-9);
            checked += 1;
        }
        assert_eq!(checked, 2, "2d = {degree}: too few separated pairs drawn");
    }
}

/// d(p₁‖p₂) both overlapping (value < 1, constraint active) and separated, at 2d = 2, 4, 6.
#[test]
fn growth_gradient_matches_finite_differences() {
    let params = NewtonParams::default();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for degree in [2, 4, 6] {
        let a = load(&format!("chair_101.deg{degree}.json"));
        let b = load(&format!("human_10.deg{degree}.json"));
        let (mut overlapping, mut separated) = (0, 0);
        for _ in 0..60 {
            if overlapping >= 1 && separated >= 1 {
                break;
            }
            let spread = if overlapping == 0 { 0.35 } else { 1.0 };
            let pa = random_pose(&mut rng, Vector3::zeros(), 0.2);
            let pb = random_pose(&mut rng, Vector3::new(2.0 * spread, 0.0, 0.0), 0.3);
            let r = growth(&a, &pa, &b, &pb, None, &params);
            if !r.status.converged() || r.multiplier <= 0.0 {
                continue;
            }
            let is_overlap = r.value < 1.0;
            if (is_overlap && overlapping >= 1) || (!is_overlap && separated >= 1) {
                continue;
            }
            let f = |x: &Isometry3, y: &Isometry3| {
                let s = growth(&a, x, &b, y, Some(&r.warm_start), &params);
                assert!(s.status.converged());
                s.value
            };
            let (g1, g2) = growth_gradient(&a, &pa, &r);
            let what = if is_overlap { "overlapping" } else { "separated" };
            assert_close(&format!("2d = {degree} {what}: dG/dξ_1"), &g1, &finite_difference(&f, &pa, &pb, 0));
            assert_close(&format!("2d = {degree} {what}: dG/dξ_2"), &g2, &finite_difference(&f, &pa, &pb, 1));
            if is_overlap {
                overlapping += 1;
            } else {
                separated += 1;
            }
        }
        assert!(overlapping >= 1 && separated >= 1, "2d = {degree}: {overlapping} overlapping, {separated} separated");
    }
}

/// Inactive growth constraint (p₁'s minimizer inside body 2) and overlapping distance: the value
/// is locally constant, the gradients are zero, and so are the finite differences.
#[test]
fn locally_constant_values_have_zero_gradients() {
    let params = NewtonParams::default();
    let small = sublevel::body::ellipsoid([0.0; 3], [0.1, 0.2, 0.15]).unwrap();
    let big = load("human_10.deg4.json");
    let pb = Isometry3::identity();
    let pa = Isometry3::translation(big.interior_point().x, big.interior_point().y, big.interior_point().z);
    let r = growth(&small, &pa, &big, &pb, None, &params);
    assert!(r.status.converged() && r.multiplier == 0.0, "{r:?}");
    let (g1, g2) = growth_gradient(&small, &pa, &r);
    assert_eq!((g1, g2), (PoseGradient::default(), PoseGradient::default()));
    let f = |x: &Isometry3, y: &Isometry3| growth(&small, x, &big, y, None, &params).value;
    assert!(finite_difference(&f, &pa, &pb, 0).iter().all(|v| v.abs() < 1e-9));
    let d = distance(&small, &pa, &big, &pb, None, &params);
    assert!(d.overlapping);
    assert_eq!(distance_gradient(&d), (PoseGradient::default(), PoseGradient::default()));
}
