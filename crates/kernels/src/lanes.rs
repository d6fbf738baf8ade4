//! Lane types: one real per lane, the arithmetic that the query solvers' Newton / active-set
//! loops are written in once ([`Lane`]), whatever the number of lanes.
//!
//! - [`Scalar`]: one `f64` lane, plain Rust arithmetic (fused multiply-adds where `FMA`: the
//!   solvers' AVX2 + FMA builds), masks are `bool` — the single-pair solvers;
//! - [`F4`]: four `f64` lanes in an AVX register — the batch solvers' double-precision rounds;
//! - [`F8`]: eight `f32` lanes in an AVX register — the batch distance solver's coarse stage
//!   (twice the pairs per instruction).
//!
//! The AVX types are sound to use from safe code because a value of them exists only on a CPU that
//! runs AVX2 and FMA: every constructor takes an [`Avx2Fma`] proof, and the operations on a value
//! read it back ([`Lane::cpu`]). Their methods are `#[inline(always)]`, so inside code compiled for
//! AVX2 + FMA ([`Avx2Fma::run`]) each is one instruction; outside it, each is a call.

#[cfg(target_arch = "x86_64")]
use crate::Avx2Fma;
use crate::Real;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// A lane mask (all bits of a lane set or clear, as the AVX comparisons make it; a `bool` for
/// one lane).
pub trait LaneMask: Copy {
    /// Lanes set in both.
    fn and(self, o: Self) -> Self;
    /// Lanes set in either.
    fn or(self, o: Self) -> Self;
    /// Lanes clear in `self`.
    fn not(self) -> Self;
    /// Bit i set where lane i is.
    fn bits(self) -> u32;
}

/// One real per lane: the operations the query solvers' lane arithmetic needs.
///
/// A lane value is made from a proof that the CPU runs it ([`Lane::Cpu`]: [`Avx2Fma`] for the
/// AVX types, `()` for [`Scalar`]); [`Lane::cpu`] reads the proof back from any value, so that code
/// generic over the lane type makes its constants from its inputs.
pub trait Lane:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    /// The comparisons' masks.
    type Mask: LaneMask;
    /// The proof that the CPU runs this lane type's instructions (zero-sized).
    type Cpu: Copy;
    /// Relative size |det| / s³ (s the largest entry) below which a 3 × 3 block counts as singular:
    /// 10⁻¹⁴ in double precision, 10⁻¹⁰ in single.
    const SINGULAR: Real;
    /// The smallest divisor a multiplier's fallback and the 4 × 4 solve accept (normal numbers of
    /// the lane's precision).
    const TINY: Real;
    /// The proof this value was made with.
    fn cpu(self) -> Self::Cpu;
    /// `v` (rounded to the lane's precision) in every lane.
    fn splat(cpu: Self::Cpu, v: Real) -> Self;
    /// The mask with no lane set.
    fn none(cpu: Self::Cpu) -> Self::Mask;
    /// `v` in every lane, made with `self`'s proof.
    #[inline(always)]
    fn constant(self, v: Real) -> Self {
        Self::splat(self.cpu(), v)
    }
    /// self · b + c (fused, except in [`Scalar`]`<false>`, the portable build).
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// |self| per lane.
    fn abs(self) -> Self;
    /// √self per lane.
    fn sqrt(self) -> Self;
    /// Lane-wise min without NaN handling: `o` where either is NaN (`minpd`'s rule).
    fn min(self, o: Self) -> Self;
    /// Lane-wise max without NaN handling: `o` where either is NaN (`maxpd`'s rule).
    fn max(self, o: Self) -> Self;
    /// Lanes where self ≤ o (false where either is NaN).
    fn le(self, o: Self) -> Self::Mask;
    /// Lanes where self < o (false where either is NaN).
    fn lt(self, o: Self) -> Self::Mask;
    /// `a` where `m`, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Lanes where self is finite.
    #[inline(always)]
    fn finite(self) -> Self::Mask {
        self.abs().lt(self.constant(Real::INFINITY))
    }
}

/// One `f64` lane: the single-pair solvers' arithmetic. `FMA` selects fused multiply-adds (the
/// solvers' AVX2 + FMA builds, where `f64::mul_add` is one instruction); without it, a·b + c in two
/// roundings (the portable build, never a library call).
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
pub struct Scalar<const FMA: bool>(pub Real);

impl LaneMask for bool {
    #[inline(always)]
    fn and(self, o: Self) -> Self {
        self & o
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self | o
    }
    #[inline(always)]
    fn not(self) -> Self {
        !self
    }
    #[inline(always)]
    fn bits(self) -> u32 {
        self as u32
    }
}

/// Implements an arithmetic operator of [`Scalar`] by the `f64` one.
macro_rules! scalar_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const FMA: bool> $tr for Scalar<FMA> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                Self(self.0 $op o.0)
            }
        }
    };
}
scalar_op!(Add, add, +);
scalar_op!(Sub, sub, -);
scalar_op!(Mul, mul, *);
scalar_op!(Div, div, /);

impl<const FMA: bool> Neg for Scalar<FMA> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self(-self.0)
    }
}

impl<const FMA: bool> Lane for Scalar<FMA> {
    type Mask = bool;
    type Cpu = ();
    const SINGULAR: Real = 1e-14;
    const TINY: Real = 1e-300;

    #[inline(always)]
    fn cpu(self) {}

    #[inline(always)]
    fn splat((): (), v: Real) -> Self {
        Self(v)
    }

    #[inline(always)]
    fn none((): ()) -> bool {
        false
    }

    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        if FMA {
            Self(self.0.mul_add(b.0, c.0))
        } else {
            Self(self.0 * b.0 + c.0)
        }
    }

    #[inline(always)]
    fn abs(self) -> Self {
        Self(self.0.abs())
    }

    #[inline(always)]
    fn sqrt(self) -> Self {
        Self(self.0.sqrt())
    }

    #[inline(always)]
    fn min(self, o: Self) -> Self {
        if self.0 < o.0 {
            self
        } else {
            o
        }
    }

    #[inline(always)]
    fn max(self, o: Self) -> Self {
        if self.0 > o.0 {
            self
        } else {
            o
        }
    }

    #[inline(always)]
    fn le(self, o: Self) -> bool {
        self.0 <= o.0
    }

    #[inline(always)]
    fn lt(self, o: Self) -> bool {
        self.0 < o.0
    }

    #[inline(always)]
    fn select(m: bool, a: Self, b: Self) -> Self {
        if m {
            a
        } else {
            b
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub use avx::{F4, F8, M4, M8};

/// The AVX lane types (x86-64).
#[cfg(target_arch = "x86_64")]
mod avx {
    use super::*;
    use std::arch::x86_64::*;

    /// Implements [`Lane`] and the arithmetic operators for the lane type `$t` (register field
    /// `.0`, elements `$e`) and [`LaneMask`] for its mask `$m`, each operation one AVX intrinsic:
    /// the `f64` and `f32` lane types differ only in the intrinsics' suffix and their constants.
    macro_rules! avx_lane {
        (
            $t:ident, $m:ident, $e:ty, singular: $singular:expr, tiny: $tiny:expr,
            set1: $set1:ident, setzero: $setzero:ident, add: $add:ident, sub: $sub:ident,
            mul: $mul:ident, div: $div:ident, fmadd: $fmadd:ident, andnot: $andnot:ident,
            sqrt: $sqrt:ident, min: $min:ident, max: $max:ident, cmp: $cmp:ident,
            blendv: $blendv:ident, and: $and:ident, or: $or:ident, xor: $xor:ident,
            ones: $ones:expr, movemask: $movemask:ident $(,)?
        ) => {
            /// Implements a binary operator of `$t` by one intrinsic.
            macro_rules! binary {
                ($tr:ident, $f:ident, $intr:ident) => {
                    impl $tr for $t {
                        type Output = $t;
                        #[inline(always)]
                        fn $f(self, o: $t) -> $t {
                            // SAFETY: a lane value proves the CPU runs AVX2 and FMA (module docs).
                            $t(unsafe { $intr(self.0, o.0) })
                        }
                    }
                };
            }
            binary!(Add, add, $add);
            binary!(Sub, sub, $sub);
            binary!(Mul, mul, $mul);
            binary!(Div, div, $div);

            impl Neg for $t {
                type Output = $t;
                #[inline(always)]
                fn neg(self) -> $t {
                    // SAFETY: as above (flips the sign bits).
                    $t(unsafe { $xor($set1(-0.0), self.0) })
                }
            }

            impl Lane for $t {
                type Mask = $m;
                type Cpu = Avx2Fma;
                const SINGULAR: Real = $singular;
                const TINY: Real = $tiny;

                #[inline(always)]
                fn cpu(self) -> Avx2Fma {
                    // A lane value exists only on a CPU with AVX2 and FMA (made with a proof).
                    Avx2Fma::proven()
                }

                #[inline(always)]
                #[allow(clippy::unnecessary_cast)]
                fn splat(cpu: Avx2Fma, v: Real) -> Self {
                    let _ = cpu;
                    // SAFETY: `cpu` proves the CPU runs AVX.
                    Self(unsafe { $set1(v as $e) })
                }

                #[inline(always)]
                fn none(cpu: Avx2Fma) -> $m {
                    let _ = cpu;
                    // SAFETY: `cpu` proves the CPU runs AVX.
                    $m(unsafe { $setzero() })
                }

                #[inline(always)]
                fn mul_add(self, b: Self, c: Self) -> Self {
                    // SAFETY: a lane value proves the CPU runs FMA.
                    Self(unsafe { $fmadd(self.0, b.0, c.0) })
                }

                #[inline(always)]
                fn abs(self) -> Self {
                    // SAFETY: a lane value proves the CPU runs AVX (clears the sign bits).
                    Self(unsafe { $andnot($set1(-0.0), self.0) })
                }

                #[inline(always)]
                fn sqrt(self) -> Self {
                    // SAFETY: a lane value proves the CPU runs AVX.
                    Self(unsafe { $sqrt(self.0) })
                }

                #[inline(always)]
                fn min(self, o: Self) -> Self {
                    // SAFETY: a lane value proves the CPU runs AVX.
                    Self(unsafe { $min(self.0, o.0) })
                }

                #[inline(always)]
                fn max(self, o: Self) -> Self {
                    // SAFETY: a lane value proves the CPU runs AVX.
                    Self(unsafe { $max(self.0, o.0) })
                }

                #[inline(always)]
                fn le(self, o: Self) -> $m {
                    // SAFETY: a lane value proves the CPU runs AVX.
                    $m(unsafe { $cmp::<_CMP_LE_OQ>(self.0, o.0) })
                }

                #[inline(always)]
                fn lt(self, o: Self) -> $m {
                    // SAFETY: a lane value proves the CPU runs AVX.
                    $m(unsafe { $cmp::<_CMP_LT_OQ>(self.0, o.0) })
                }

                #[inline(always)]
                fn select(m: $m, a: Self, b: Self) -> Self {
                    // SAFETY: a lane value proves the CPU runs AVX.
                    Self(unsafe { $blendv(b.0, a.0, m.0) })
                }
            }

            impl LaneMask for $m {
                #[inline(always)]
                fn and(self, o: Self) -> Self {
                    // SAFETY: a mask value proves the CPU runs AVX (made from lane values or a
                    // proof).
                    Self(unsafe { $and(self.0, o.0) })
                }

                #[inline(always)]
                fn or(self, o: Self) -> Self {
                    // SAFETY: as above.
                    Self(unsafe { $or(self.0, o.0) })
                }

                #[inline(always)]
                fn not(self) -> Self {
                    // SAFETY: as above.
                    Self(unsafe { $xor(self.0, $ones) })
                }

                #[inline(always)]
                fn bits(self) -> u32 {
                    // SAFETY: as above.
                    unsafe { $movemask(self.0) as u32 }
                }
            }
        };
    }

    /// Four `f64`, one per lane, in an AVX register. Made only with an [`Avx2Fma`] proof.
    #[derive(Clone, Copy, Debug)]
    pub struct F4(__m256d);

    /// A mask of four `f64` lanes; see [`F4`].
    #[derive(Clone, Copy, Debug)]
    pub struct M4(__m256d);

    impl F4 {
        /// The four reals of `v`, lane i = `v[i]`.
        #[inline(always)]
        pub fn load(cpu: Avx2Fma, v: &[Real; 4]) -> Self {
            let _ = cpu;
            // SAFETY: `cpu` proves the CPU runs AVX; `v` is four readable reals.
            Self(unsafe { _mm256_loadu_pd(v.as_ptr()) })
        }

        /// The four lanes as an array.
        #[inline(always)]
        pub fn to_array(self) -> [Real; 4] {
            let mut out = [0.0; 4];
            // SAFETY: a lane value proves the CPU runs AVX; `out` is four writable reals.
            unsafe { _mm256_storeu_pd(out.as_mut_ptr(), self.0) };
            out
        }

        /// Lane-wise floor.
        #[inline(always)]
        pub fn floor(self) -> Self {
            // SAFETY: a lane value proves the CPU runs AVX.
            Self(unsafe { _mm256_floor_pd(self.0) })
        }

        /// `table[stride · k + offset]` per lane, for the node index k of the lane (`self`, a
        /// nonnegative integer in a real): one gather instruction. An index past the table's end
        /// is clamped to its last node and a negative or NaN one to node 0, so every read stays in
        /// `table`; zeros where `table` holds no entry at `offset`.
        #[inline(always)]
        pub fn gather(self, table: &[Real], stride: usize, offset: usize) -> Self {
            let zero = self.constant(0.0);
            let (Some(room), Ok(s)) = (table.len().checked_sub(offset), i32::try_from(stride.max(1))) else {
                return zero;
            };
            if room == 0 {
                return zero;
            }
            // Largest k with s·k + offset < len, and s·k within i32.
            let last = ((room - 1) / s as usize).min(i32::MAX as usize / s as usize);
            // NaN or negative → 0 (`max` returns its second operand for NaN), then ≤ last.
            let k = self.max(zero).min(self.constant(last as Real));
            // SAFETY: a lane value proves the CPU runs AVX2. Each lane reads entry
            // s·k + offset with 0 ≤ k ≤ last, below `table.len()` and within i32 (above), and the
            // conversion of the integral reals k is exact.
            Self(unsafe {
                let idx = _mm_mullo_epi32(_mm256_cvtpd_epi32(k.0), _mm_set1_epi32(s));
                _mm256_i32gather_pd::<8>(table.as_ptr().add(offset), idx)
            })
        }
    }

    avx_lane! {
        F4, M4, f64, singular: 1e-14, tiny: 1e-300,
        set1: _mm256_set1_pd, setzero: _mm256_setzero_pd, add: _mm256_add_pd, sub: _mm256_sub_pd,
        mul: _mm256_mul_pd, div: _mm256_div_pd, fmadd: _mm256_fmadd_pd, andnot: _mm256_andnot_pd,
        sqrt: _mm256_sqrt_pd, min: _mm256_min_pd, max: _mm256_max_pd, cmp: _mm256_cmp_pd,
        blendv: _mm256_blendv_pd, and: _mm256_and_pd, or: _mm256_or_pd, xor: _mm256_xor_pd,
        ones: _mm256_castsi256_pd(_mm256_set1_epi64x(-1)), movemask: _mm256_movemask_pd,
    }

    impl M4 {
        /// Lane i set where `b[i]`.
        #[inline(always)]
        pub fn from_bools(cpu: Avx2Fma, b: [bool; 4]) -> Self {
            let _ = cpu;
            let m = |v: bool| if v { -1i64 } else { 0 };
            // SAFETY: `cpu` proves the CPU runs AVX.
            Self(unsafe { _mm256_castsi256_pd(_mm256_set_epi64x(m(b[3]), m(b[2]), m(b[1]), m(b[0]))) })
        }
    }

    /// Eight `f32`, one per lane, in an AVX register: relative rounding 6·10⁻⁸, for stages whose
    /// answers are refined in double precision. Made only with an [`Avx2Fma`] proof.
    #[derive(Clone, Copy, Debug)]
    pub struct F8(__m256);

    /// A mask of eight `f32` lanes; see [`F8`].
    #[derive(Clone, Copy, Debug)]
    pub struct M8(__m256);

    impl F8 {
        /// The eight `f32` of `v`, lane i = `v[i]`.
        #[inline(always)]
        pub fn load(cpu: Avx2Fma, v: &[f32; 8]) -> Self {
            let _ = cpu;
            // SAFETY: `cpu` proves the CPU runs AVX; `v` is eight readable `f32`.
            Self(unsafe { _mm256_loadu_ps(v.as_ptr()) })
        }

        /// The eight lanes as an array.
        #[inline(always)]
        pub fn to_array(self) -> [f32; 8] {
            let mut out = [0.0; 8];
            // SAFETY: a lane value proves the CPU runs AVX; `out` is eight writable `f32`.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }
    }

    avx_lane! {
        F8, M8, f32, singular: 1e-10, tiny: 1e-30,
        set1: _mm256_set1_ps, setzero: _mm256_setzero_ps, add: _mm256_add_ps, sub: _mm256_sub_ps,
        mul: _mm256_mul_ps, div: _mm256_div_ps, fmadd: _mm256_fmadd_ps, andnot: _mm256_andnot_ps,
        sqrt: _mm256_sqrt_ps, min: _mm256_min_ps, max: _mm256_max_ps, cmp: _mm256_cmp_ps,
        blendv: _mm256_blendv_ps, and: _mm256_and_ps, or: _mm256_or_ps, xor: _mm256_xor_ps,
        ones: _mm256_castsi256_ps(_mm256_set1_epi32(-1)), movemask: _mm256_movemask_ps,
    }

    impl M8 {
        /// Lane i set where `b[i]`.
        #[inline(always)]
        pub fn from_bools(cpu: Avx2Fma, b: [bool; 8]) -> Self {
            let _ = cpu;
            let m = |v: bool| if v { -1i32 } else { 0 };
            // SAFETY: `cpu` proves the CPU runs AVX.
            Self(unsafe {
                _mm256_castsi256_ps(_mm256_set_epi32(
                    m(b[7]),
                    m(b[6]),
                    m(b[5]),
                    m(b[4]),
                    m(b[3]),
                    m(b[2]),
                    m(b[1]),
                    m(b[0]),
                ))
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_lanes_follow_the_avx_rules() {
        let s = Scalar::<true>;
        let (a, b, nan) = (s(1.5), s(-2.0), s(Real::NAN));
        assert_eq!((a + b).0, -0.5);
        assert_eq!(a.mul_add(b, s(4.0)).0, 1.0);
        // min / max return the second operand where either is NaN (minpd / maxpd).
        assert_eq!(a.min(b).0, -2.0);
        assert_eq!(a.max(b).0, 1.5);
        assert!(nan.max(a).0 == 1.5 && a.max(nan).0.is_nan());
        assert!(!nan.le(a) && !a.lt(nan) && !nan.finite() && a.finite());
        assert_eq!(Scalar::select(true.and(false).not(), a, b).0, 1.5);
        assert_eq!(true.bits() + false.bits(), 1);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx_lanes_compute_per_lane_and_gathers_stay_in_the_table() {
        let Some(cpu) = Avx2Fma::detect() else { return };
        cpu.run(|| {
            let x = F4::load(cpu, &[1.0, -2.0, Real::NAN, 9.0]);
            let y = F4::splat(cpu, 2.0);
            assert_eq!(x.mul_add(y, y).to_array()[..2], [4.0, -2.0]);
            assert_eq!(x.le(y).bits(), 0b0011);
            assert_eq!(x.finite().bits(), 0b1011);
            assert_eq!(M4::from_bools(cpu, [true, false, false, true]).not().bits(), 0b0110);
            assert_eq!(F4::select(x.lt(y), x, y).to_array()[..2], [1.0, -2.0]);
            // Table of 5 nodes of 2 reals: node k's second real is 10k + 1.
            let table: Vec<Real> = (0..5).flat_map(|k| [10.0 * k as Real, 10.0 * k as Real + 1.0]).collect();
            let k = F4::load(cpu, &[0.0, 3.0, -7.0, 50.0]);
            assert_eq!(k.gather(&table, 2, 1).to_array(), [1.0, 31.0, 1.0, 41.0]);
            assert_eq!(F4::splat(cpu, Real::NAN).gather(&table, 2, 0).to_array(), [0.0; 4]);
            assert_eq!(k.gather(&table, 2, 10).to_array(), [0.0; 4]);
            let f = F8::load(cpu, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
            assert_eq!((f * f).to_array()[7], 64.0);
            assert_eq!(f.lt(F8::splat(cpu, 3.5)).bits(), 0b0000_0111);
            assert_eq!(M8::from_bools(cpu, [true; 8]).and(F8::none(cpu)).bits(), 0);
        });
    }
}
