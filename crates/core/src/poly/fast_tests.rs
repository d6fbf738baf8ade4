//! The fast kernels ([`FastPoly`], [`SoaPoly`]) against the reference evaluator
//! ([`Polynomial::eval`], the monomial sums with exact derivatives) at every degree.

use super::monomial::basis_len;
use super::{Polynomial, SoaPoly, MAX_DEGREE};
use crate::math::{Real, Vector3};
use rand::{Rng, SeedableRng};

#[test]
fn four_point_table_matches_reference_eval_at_every_degree() {
    // SoaPoly::eval4 against the reference evaluator (Polynomial::eval, the monomial sums) at
    // four random points per pass, every degree 0–8 (2d < 2 takes the one-point path).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    for degree in 0..=MAX_DEGREE {
        let coeffs: Vec<Real> = (0..basis_len(3, degree)).map(|_| rng.random_range(-1.0..1.0)).collect();
        let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
        let soa = SoaPoly::new(&p.fast());
        for _ in 0..10 {
            let u: [Vector3; 4] = std::array::from_fn(|_| {
                Vector3::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5))
            });
            let e = soa.eval4(&u);
            for (i, u) in u.iter().enumerate() {
                let r = p.eval(u);
                let scale = 1.0 + r.value.abs() + r.gradient.amax() + r.hessian.amax();
                assert!((r.value - e.value[i]).abs() <= 1e-12 * scale, "degree {degree}");
                for j in 0..3 {
                    assert!((r.gradient[j] - e.gradient[j][i]).abs() <= 1e-12 * scale, "degree {degree}");
                }
                for (k, (a, b)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].into_iter().enumerate() {
                    assert!((r.hessian[(a, b)] - e.hessian[k][i]).abs() <= 1e-12 * scale, "degree {degree}");
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[test]
fn single_precision_table_is_within_f32_rounding_of_the_reference() {
    // SoaPoly::eval4_rows_f32 against the reference evaluator at every degree 2–8, random
    // coefficients in [−1, 1] and points in [−1.5, 1.5]³. Its error is rounding: at most a few
    // units of f32 (6·10⁻⁸) per multiply–add of a Horner chain (3·2d deep) times the sum of
    // the terms' magnitudes, which the polynomial with |c_α| evaluated at |u| gives. Asserted:
    // 10⁻⁶ of that bound (value, gradient, Hessian; measured 1.5·10⁻⁷); and the rounding is single precision
    // indeed where the AVX2 kernel runs (some error above 10⁻¹² of it).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut largest: Real = 0.0;
    for degree in 2..=MAX_DEGREE {
        let coeffs: Vec<Real> = (0..basis_len(3, degree)).map(|_| rng.random_range(-1.0..1.0)).collect();
        let magnitudes = Polynomial::from_coefficients(degree, coeffs.iter().map(|c| c.abs()).collect()).unwrap();
        let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
        let soa = SoaPoly::new(&p.fast());
        for _ in 0..20 {
            let u: [[Real; 4]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.5..1.5)));
            let e = soa.eval4_rows_f32(&u);
            for (i, value) in e.value.iter().enumerate() {
                let point = Vector3::new(u[0][i], u[1][i], u[2][i]);
                let (r, m) = (p.eval(&point), magnitudes.eval(&point.abs()));
                let bound = 1.0 + m.value + m.gradient.amax() + m.hessian.amax();
                let mut worst = (r.value - value).abs();
                for j in 0..3 {
                    worst = worst.max((r.gradient[j] - e.gradient[j][i]).abs());
                }
                for (k, (a, b)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].into_iter().enumerate() {
                    worst = worst.max((r.hessian[(a, b)] - e.hessian[k][i]).abs());
                }
                assert!(worst <= 1e-6 * bound, "degree {degree}: error {worst:e} of bound {bound:e}");
                largest = largest.max(worst / bound);
            }
        }
    }
    // (Without AVX2 + FMA the double-precision kernel answers: no such rounding.)
    #[cfg(target_arch = "x86_64")]
    if crate::math::cpu_has_avx2_fma() {
        assert!(largest > 1e-12, "no single-precision rounding seen ({largest:e})");
    }
}

#[test]
fn eight_point_single_precision_kernel_is_within_f32_rounding_of_the_reference() {
    // SoaPoly::eval8_rows_f32 (the batch's coarse stage) against the reference evaluator at
    // every degree 2–8, random coefficients in [−1, 1] and points in [−1.5, 1.5]³ (given in
    // f32, so the reference is taken at the rounded points): within 10⁻⁶ of the terms'
    // magnitude bound, as `single_precision_table_is_within_f32_rounding_of_the_reference`
    // asserts for the four-point kernel (value, gradient, Hessian at all eight lanes).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(10);
    for degree in 2..=MAX_DEGREE {
        let coeffs: Vec<Real> = (0..basis_len(3, degree)).map(|_| rng.random_range(-1.0..1.0)).collect();
        let magnitudes = Polynomial::from_coefficients(degree, coeffs.iter().map(|c| c.abs()).collect()).unwrap();
        let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
        let soa = SoaPoly::new(&p.fast());
        for _ in 0..10 {
            let u: [[f32; 8]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.5..1.5)));
            let e = soa.eval8_rows_f32(&u);
            for (i, value) in e.value.iter().enumerate() {
                let point = Vector3::new(u[0][i].into(), u[1][i].into(), u[2][i].into());
                let (r, m) = (p.eval(&point), magnitudes.eval(&point.abs()));
                let bound = 1.0 + m.value + m.gradient.amax() + m.hessian.amax();
                let mut worst = (r.value - Real::from(*value)).abs();
                for j in 0..3 {
                    worst = worst.max((r.gradient[j] - Real::from(e.gradient[j][i])).abs());
                }
                for (k, (a, b)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].into_iter().enumerate() {
                    worst = worst.max((r.hessian[(a, b)] - Real::from(e.hessian[k][i])).abs());
                }
                assert!(worst <= 1e-6 * bound, "degree {degree}, lane {i}: error {worst:e} of bound {bound:e}");
            }
        }
    }
}

#[test]
fn fast_eval_matches_reference_eval_at_every_degree() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    for degree in 0..=MAX_DEGREE {
        let n = basis_len(3, degree);
        let coeffs: Vec<Real> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
        let f = p.fast();
        assert_eq!(f.len(), n);
        for _ in 0..20 {
            let u = Vector3::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5));
            let r = p.eval(&u);
            let scale = 1.0 + r.value.abs() + r.gradient.amax() + r.hessian.amax();
            let (pv, pg, pe) = f.eval_portable(&u);
            for e in [f.eval(&u), pe] {
                assert!((r.value - e.value).abs() <= 1e-12 * scale, "degree {degree}");
                assert!((r.gradient - e.gradient).amax() <= 1e-12 * scale, "degree {degree}");
                assert!((r.hessian - e.hessian).amax() <= 1e-12 * scale, "degree {degree}");
            }
            for v in [f.value(&u), pv] {
                assert!((v - r.value).abs() <= 1e-12 * scale);
            }
            for (v, g) in [f.value_gradient(&u), pg] {
                assert!((v - r.value).abs() <= 1e-12 * scale && (g - r.gradient).amax() <= 1e-12 * scale);
            }
        }
    }
}
