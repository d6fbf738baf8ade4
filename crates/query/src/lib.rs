//! # sublevel-query
//!
//! Proximity queries between posed bodies (paper §IV): Euclidean distance with witness points and
//! the growth measure d(p₁‖p₂), solved by a warm-started Newton / active-set method, and their
//! level-0 sos certificates.
//!
//! # Settings
//!
//! The solvers' tunable tolerances, iteration caps and thresholds are fields of the settings
//! struct that travels with the query, each with a default (the tuned value; also the struct's
//! `DEFAULT` constant) and a doc comment that says what a larger value trades, as Clarabel's
//! `DefaultSettings`. Change fields with struct update syntax,
//! `NewtonParams { warm_reach: 1.0, ..NewtonParams::default() }`:
//!
//! - [`NewtonParams`]: the Newton / active-set solvers of [`distance()`] and [`growth()`] —
//!   tolerance, caps, warm-start reach and predictor, chord steps, line search, working frame —
//!   with the batch lanes' thresholds nested in [`BatchSettings`] (`NewtonParams::batch`);
//! - [`CertificateParams`](sdp_certificate::CertificateParams): the level-0 SDP certificates
//!   (Clarabel's tolerance and cap, the recentering pass, witness recovery) and the agreement rule
//!   of the certified answers; [`CertifyParams`] pairs it with the [`NewtonParams`];
//! - [`TreeQueryParams`](tree::TreeQueryParams): the tree queries of compound bodies — their
//!   tolerance and pair cap, the cheap bounds' rounding slack, the far group of a warm cut and the
//!   sizes of a warm start — with the [`NewtonParams`] and `CertificateParams` of the node pairs.
//!
//! The constants that remain are structural: array sizes and lane counts (the motion trail's
//! length, a const generic; the SIMD lanes' widths; the start tables' grid, the radial tables'),
//! sentinels, and the per-lane-type singularity and underflow limits of the lane arithmetic
//! (properties of `f64` and `f32`, not choices). Constants of the methods themselves (the line
//! search's sufficient decrease 10⁻⁴, the barrier path's schedule, the predictor's test for
//! parallel steps) stay in the code beside their derivation. [`batch::MIN_LANE_BATCH`] and
//! [`certified::AGREEMENT_ABSOLUTE`] name two defaults for callers that hold no settings.

#![warn(missing_docs)]
// No `unsafe` code: the evaluation kernels, the SIMD lane types and the AVX2 + FMA dispatch live in
// `sublevel-kernels`.
#![forbid(unsafe_code)]

pub use sublevel_core::{Error, Result};

/// Defines `[vis] fn $name(args) -> ret` that runs `$body::<true>` compiled for AVX2 + FMA when
/// the CPU has them (through [`sublevel_kernels::Avx2Fma::run`], after a cached check), else the
/// portable `$body::<false>`. `$body` is `#[inline(always)]` and generic over `const FMA: bool`
/// (fused arithmetic in [`fast_eval`]), so each build is one copy of the whole solver:
/// three-operand and fused instructions cut the Newton loop's own instructions by about a fifth.
///
/// The query entry points [`distance()`] and [`growth()`] are dispatched the same way, so that the
/// code around their Newton runs (pose algebra, the warm start's predictor, the answer) is compiled
/// with three-operand AVX instructions too (it has no fused arithmetic: LLVM does not contract
/// a·b + c, so its answers are bit-identical to the portable build's).
macro_rules! avx2_dispatch {
    ($(#[$meta:meta])* $vis:vis fn $name:ident => $body:ident($($arg:ident: $ty:ty),* $(,)?) -> $ret:ty) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            if let Some(cpu) = sublevel_kernels::Avx2Fma::detect() {
                return cpu.run(#[inline(always)] move || $body::<true>($($arg),*));
            }
            $body::<false>($($arg),*)
        }
    };
}

pub mod batch;
pub mod certified;
pub mod dispatch;
pub mod distance;
pub(crate) mod fast_eval;
pub mod gradient;
pub mod growth;
pub(crate) mod lane_algebra;
pub mod newton;
pub mod penetration;
pub mod sdp_certificate;
pub mod shape;
pub mod tree;

pub use batch::BatchSettings;
pub use certified::{
    certified_distance, certified_growth, certify_newton_distance, AnswerSource, CertificateKind, CertificateSummary,
    Certified, CertifiedDistance, CertifiedGrowth, CertifyMode, CertifyParams,
};
pub use distance::{
    common_point, distance, segment_common_point, warm_start_reaches, warm_start_reaches_with, DistanceResult,
    DistanceWarmStart,
};
pub use gradient::{distance_gradient, growth_gradient, witness_gradient, PoseGradient};
pub use growth::{growth, GrowthResult, GrowthWarmStart};
pub use newton::{NewtonParams, SolveStatus};

#[cfg(test)]
pub(crate) mod test_bodies {
    //! Non-trivial sos-convex test bodies: p(u) = ½‖u‖² + Σᵢ (aᵢ·u + bᵢ)^{2d} is sos-convex (each even
    //! power of an affine form has yᵀ∇²y = c·((a·u + b)^{d−1}(a·y))², a square).
    use rand::{Rng, SeedableRng};
    use sublevel_core::body::{Body, FitReport};
    use sublevel_core::math::{Real, Vector3};
    use sublevel_core::poly::Polynomial;

    /// A random body of total degree `degree`, scaled so that p ≤ 1 is a body of size ~1.
    pub fn random_body(degree: usize, seed: u64) -> Body {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut p = Polynomial::from_terms(degree, &[([2, 0, 0], 0.5), ([0, 2, 0], 0.5), ([0, 0, 2], 0.5)]).unwrap();
        for _ in 0..4 {
            let a = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let b: Real = rng.random_range(-0.3..0.3);
            let lin =
                Polynomial::from_terms(1, &[([0, 0, 0], b), ([1, 0, 0], a.x), ([0, 1, 0], a.y), ([0, 0, 1], a.z)])
                    .unwrap();
            let mut pow = Polynomial::from_terms(0, &[([0, 0, 0], 1.0)]).unwrap();
            for _ in 0..degree {
                pow = pow.mul(&lin).unwrap();
            }
            for (c, e) in pow.coefficients().iter().zip(pow.exponents()) {
                let k = sublevel_core::poly::monomial::index3(*e);
                p.coefficients_mut()[k] += c;
            }
        }
        let center = [rng.random_range(-0.2..0.2), 0.1, -0.1];
        Body::new(p, center, 0.7, FitReport::default()).unwrap()
    }

    /// The first `count` cold poses of `sublevel-lab bench` (its `cold_poses(7, count)`: the chair's
    /// translation ~ U[−2.5, 2.5]³ m, rotation normalize(U[−1, 1]⁴), the human at the identity).
    pub fn bench_cold_poses(count: usize) -> Vec<sublevel_core::math::Isometry3> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut u = |lo: Real, hi: Real| rng.random_range(lo..hi);
        (0..count)
            .map(|_| {
                let t = Vector3::new(u(-2.5, 2.5), u(-2.5, 2.5), u(-2.5, 2.5));
                let q = nalgebra::Quaternion::new(u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0));
                sublevel_core::math::Isometry3::from_parts(
                    t.into(),
                    sublevel_core::math::UnitQuaternion::new_normalize(q),
                )
            })
            .collect()
    }

    /// chair_101 and human_10 fitted at 2d = `degree`, the bundled bodies of `tests/data`.
    pub fn bench_bodies(degree: usize) -> (Body, Body) {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("tests/data");
        let load = |name: &str| Body::load(&dir.join(format!("{name}.deg{degree}.json"))).unwrap();
        (load("chair_101"), load("human_10"))
    }
}

#[cfg(test)]
mod brute_force_tests {
    use super::test_bodies::random_body;
    use super::*;
    use rand::{Rng, SeedableRng};
    use sublevel_core::body::PosedBody;
    use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};

    /// Boundary points of a posed body along `n` Fibonacci directions from its interior point.
    fn boundary_samples(b: &PosedBody<'_>, n: usize) -> Vec<Vector3> {
        let c = b.interior_point();
        let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
                let r = (1.0 - z * z).sqrt();
                let dir = Vector3::new(r * (golden * i as Real).cos(), r * (golden * i as Real).sin(), z);
                let far = c + dir * 100.0;
                super::newton::boundary_on_segment(b, &c, &far)
            })
            .collect()
    }

    #[test]
    fn higher_degree_bodies_match_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for (i, degree) in [4usize, 6, 8, 4, 6, 8].into_iter().enumerate() {
            let a = random_body(degree, 100 + i as u64);
            let b = random_body(degree, 200 + i as u64);
            let pose_a = Isometry3::from_parts(
                Vector3::new(rng.random_range(-1.0..1.0), 0.0, 0.0).into(),
                UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random()),
            );
            let pose_b = Isometry3::from_parts(
                Vector3::new(if i < 3 { 2.5 } else { 1.5 }, rng.random_range(-0.5..0.5), 0.3).into(),
                UnitQuaternion::from_euler_angles(rng.random(), rng.random(), rng.random()),
            );
            let d = distance(&a, &pose_a, &b, &pose_b, None, &NewtonParams::default());
            let g = growth(&a, &pose_a, &b, &pose_b, None, &NewtonParams::default());
            assert!(d.status.converged() && g.status.converged(), "degree {degree}: {d:?} {g:?}");
            let (pa, pb) = (a.posed(&pose_a), b.posed(&pose_b));
            let sa = boundary_samples(&pa, 3000);
            let sb = boundary_samples(&pb, 3000);
            // Brute-force growth: min of p_a' over B's boundary samples (an upper bound, tight to
            // the sampling resolution).
            let brute_g = sb.iter().map(|x| pa.value(x)).fold(Real::INFINITY, Real::min);
            assert!(g.value <= brute_g + 1e-9, "degree {degree}: newton {} > brute {brute_g}", g.value);
            assert!((brute_g - g.value) / g.value < 2e-2, "degree {degree}: newton {} vs brute {brute_g}", g.value);
            if d.overlapping {
                // A common witness inside both bodies proves the overlap.
                let (va, vb) = (pa.value(&d.witness_a.coords), pb.value(&d.witness_a.coords));
                assert!(va <= 1.0 + 1e-9 && vb <= 1.0 + 1e-9, "degree {degree}: {va} {vb} {d:?} {g:?}");
                assert!(g.value <= 1.0);
                continue;
            }
            // Brute-force distance over the sample pairs (upper bound).
            let mut brute_d = Real::INFINITY;
            for x in &sa {
                for y in &sb {
                    brute_d = brute_d.min((x - y).norm());
                }
            }
            assert!(d.distance <= brute_d + 1e-9, "degree {degree}: newton {} > brute {brute_d}", d.distance);
            assert!(brute_d - d.distance < 3e-2 * brute_d.max(0.1), "degree {degree}: {} vs {brute_d}", d.distance);
            // The witnesses are on the boundaries.
            assert!((pa.value(&d.witness_a.coords) - 1.0).abs() < 1e-9);
            assert!((pb.value(&d.witness_b.coords) - 1.0).abs() < 1e-9);
        }
    }
}
