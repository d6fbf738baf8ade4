//! The lane arithmetic of the block checks: loads and stores of a block's reals, and sine and
//! cosine in lanes for forward kinematics.

use sublevel_core::math::Real;
use sublevel_kernels::{Lane, LaneMask, Scalar};

/// A lane type the block kernel runs in: [`Scalar`] (one configuration per block, the portable
/// build) or, on x86-64 with AVX2 + FMA, [`sublevel_kernels::F4`] (four, in double precision).
pub(crate) trait Lanes: Lane {
    /// Configurations per block.
    const WIDTH: usize;
    /// Lanes `v[0..WIDTH]` (`v` holds at least that many reals).
    fn load(cpu: Self::Cpu, v: &[Real]) -> Self;
    /// Lane-wise floor.
    fn floor(self) -> Self;
    /// Lane `i`'s value (`i < WIDTH`).
    fn lane(self, i: usize) -> Real;
}

impl<const FMA: bool> Lanes for Scalar<FMA> {
    const WIDTH: usize = 1;
    #[inline(always)]
    fn load((): (), v: &[Real]) -> Self {
        Scalar(v[0])
    }
    #[inline(always)]
    fn floor(self) -> Self {
        Scalar(self.0.floor())
    }
    #[inline(always)]
    fn lane(self, _: usize) -> Real {
        self.0
    }
}

#[cfg(target_arch = "x86_64")]
impl Lanes for sublevel_kernels::F4 {
    const WIDTH: usize = 4;
    #[inline(always)]
    fn load(cpu: sublevel_kernels::Avx2Fma, v: &[Real]) -> Self {
        let mut a = [0.0; 4];
        a.copy_from_slice(&v[..4]);
        Self::load(cpu, &a)
    }
    #[inline(always)]
    fn floor(self) -> Self {
        sublevel_kernels::F4::floor(self)
    }
    #[inline(always)]
    fn lane(self, i: usize) -> Real {
        self.to_array()[i]
    }
}

/// π/2 to its first 33 bits: k · P1 is exact for |k| < 2²⁰.
const PIO2_HI: Real = 1.570_796_326_734_125_6;
/// π/2 − [`PIO2_HI`], rounded.
const PIO2_LO: Real = 6.077_100_506_506_192e-11;

/// Largest |angle| (radians) the lanes reduce to within a few units in the last place:
/// [`sin_cos`] is exact to about 1e-16 absolute below it; larger angles are left to the
/// single-configuration path.
pub(crate) const MAX_ANGLE: Real = 1.0e5;

/// (sin x, cos x) per lane, for |x| ≤ [`MAX_ANGLE`]: x = k·π/2 + r (Cody–Waite reduction in two
/// parts, |r| ≤ π/4), Taylor series of sin r to r¹⁷ and cos r to r¹⁸ (truncation below 1e-19 on
/// |r| ≤ π/4), then the quadrant k mod 4 swaps and negates them.
#[inline(always)]
pub(crate) fn sin_cos<L: Lanes>(x: L) -> (L, L) {
    let c = |v: Real| x.constant(v);
    let k = x.mul_add(c(std::f64::consts::FRAC_2_PI), c(0.5)).floor();
    let r = k.mul_add(c(-PIO2_LO), k.mul_add(c(-PIO2_HI), x));
    let r2 = r * r;
    // sin r = r (1 − r²/3! + r⁴/5! − …), cos r = 1 − r²/2! + r⁴/4! − …
    let mut s = c(SIN[SIN.len() - 1]);
    for &a in SIN[..SIN.len() - 1].iter().rev() {
        s = s.mul_add(r2, c(a));
    }
    let s = s * r;
    let mut co = c(COS[COS.len() - 1]);
    for &a in COS[..COS.len() - 1].iter().rev() {
        co = co.mul_add(r2, c(a));
    }
    // m = k mod 4: odd quadrants swap sine and cosine; sine is negated for m ∈ {2, 3}, cosine
    // for m ∈ {1, 2}.
    let m = k - c(4.0) * (k * c(0.25)).floor();
    let odd = c(0.5).lt(m - c(2.0) * (m * c(0.5)).floor());
    let sin = L::select(odd, co, s);
    let cos = L::select(odd, s, co);
    let neg_sin = c(1.5).lt(m);
    let neg_cos = c(0.5).lt(m).and(m.lt(c(2.5)));
    (L::select(neg_sin, -sin, sin), L::select(neg_cos, -cos, cos))
}

/// Taylor coefficients of sin r / r in r²: (−1)ⁿ / (2n + 1)!, n = 0..=8.
const SIN: [Real; 9] = [
    1.0,
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 1_307_674_368_000.0,
    1.0 / 355_687_428_096_000.0,
];

/// Taylor coefficients of cos r in r²: (−1)ⁿ / (2n)!, n = 0..=9.
const COS: [Real; 10] = [
    1.0,
    -1.0 / 2.0,
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 20_922_789_888_000.0,
    -1.0 / 6_402_373_705_728_000.0,
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lane_sine_and_cosine_match_the_library_to_a_few_ulps() {
        let mut x = -MAX_ANGLE;
        let mut worst: Real = 0.0;
        while x <= MAX_ANGLE {
            for y in [x, x * 1e-5, x * 1e-3 + 0.3] {
                let (s, c) = sin_cos(Scalar::<false>(y));
                worst = worst.max((s.0 - y.sin()).abs()).max((c.0 - y.cos()).abs());
            }
            x += 0.937;
        }
        // Quadrant boundaries.
        for k in -8..=8 {
            for d in [-1e-12, 0.0, 1e-12] {
                let y = k as Real * std::f64::consts::FRAC_PI_2 + d;
                let (s, c) = sin_cos(Scalar::<true>(y));
                worst = worst.max((s.0 - y.sin()).abs()).max((c.0 - y.cos()).abs());
            }
        }
        assert!(worst < 4e-15, "worst error {worst}");
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_lanes_agree_with_the_scalar_lane() {
        let Some(cpu) = sublevel_kernels::Avx2Fma::detect() else { return };
        let xs = [-3.1, 0.7, 2.0e4, -1.234_567];
        let (s, c) = cpu.run(|| sin_cos(<sublevel_kernels::F4 as Lanes>::load(cpu, &xs)));
        let (s, c) = (s.to_array(), c.to_array());
        for (i, x) in xs.iter().enumerate() {
            assert!((s[i] - x.sin()).abs() < 4e-15 && (c[i] - x.cos()).abs() < 4e-15, "lane {i}");
        }
    }
}
