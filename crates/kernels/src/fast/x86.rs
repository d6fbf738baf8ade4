//! The kernels compiled for AVX2 + FMA (x86-64-v3) over `__m256d` / `__m128d` accumulators.
//! Callers hold an [`Avx2Fma`] proof or have checked [`super::has_fma`].

use super::*;
use std::arch::asm;
use std::arch::x86_64::{
    __m256, __m256d, _mm256_castps256_ps128, _mm256_cvtpd_ps, _mm256_cvtps_pd, _mm256_extractf128_ps, _mm256_fmadd_pd,
    _mm256_fmadd_ps, _mm256_load_pd, _mm256_load_ps, _mm256_loadu_pd, _mm256_loadu_ps, _mm256_mul_pd,
    _mm256_permute2f128_pd, _mm256_permute2f128_ps, _mm256_permute4x64_pd, _mm256_set1_pd, _mm256_set1_ps,
    _mm256_set_m128, _mm256_storeu_pd, _mm256_storeu_ps, _mm256_sub_pd,
};

/// Defines the scheduling barrier `$pin` for a `$vec` register of class `$reg`: an empty `asm!`
/// the compiler must compute the value before (and may assume touches memory, so no later
/// table load moves ahead of it). No instruction: the template is an assembler comment.
macro_rules! pin_fn {
    ($pin:ident, $vec:ty, $reg:ident) => {
        #[target_feature(enable = "avx2,fma")]
        #[inline]
        fn $pin(mut v: $vec) -> $vec {
            // SAFETY: the template is an assembler comment: no instruction runs, no memory or
            // flag is touched and `v` stays in its register.
            unsafe { asm!("/* {0} */", inout($reg) v, options(nostack, preserves_flags)) };
            v
        }
    };
}

/// Defines the accumulator `$name` of `$n` lanes in one `$reg` register (`$vec`, loaded and
/// broadcast by `$load` / `$set1`, fused by `$fmadd`) with its scheduling barrier `$pin`
/// (`pin_fn!`).
macro_rules! simd_acc {
    ($(#[$doc:meta])* $name:ident, $vec:ty, $n:literal, $reg:ident, $set1:ident, $load:ident, $fmadd:ident, $pin:ident) => {
        pin_fn!($pin, $vec, $reg);

        $(#[$doc])*
        #[derive(Clone, Copy)]
        struct $name($vec, Avx2Fma);

        impl Acc for $name {
            type Row = [Real; $n];
            type Cpu = Avx2Fma;
            type Coord = Self;

            #[inline(always)]
            fn splat(cpu: Avx2Fma, t: Real) -> Self {
                // SAFETY: `cpu` proves the CPU runs AVX2 (and so SSE2).
                Self(unsafe { $set1(t) }, cpu)
            }

            #[inline(always)]
            fn load(cpu: Avx2Fma, row: &[Real; $n]) -> Self {
                // SAFETY: `row` is `$n` readable `f64` (an unaligned load); `cpu` proves AVX2.
                Self(unsafe { $load(row.as_ptr()) }, cpu)
            }

            #[inline(always)]
            fn mul_add_row(self, t: Self, row: &[Real; $n]) -> Self {
                // SAFETY: `row` is `$n` readable `f64` (an unaligned load, folded into the
                // FMA); `self.1` proves AVX2 and FMA.
                Self(unsafe { $fmadd(self.0, t.0, $load(row.as_ptr())) }, self.1)
            }

            #[inline(always)]
            fn mul_add(self, t: Self, c: Self) -> Self {
                // SAFETY: `self.1` proves AVX2 and FMA.
                Self(unsafe { $fmadd(self.0, t.0, c.0) }, self.1)
            }

            #[inline(always)]
            fn pin(self) -> Self {
                // SAFETY: `self.1` proves AVX2 (the register class of the barrier).
                Self(unsafe { $pin(self.0) }, self.1)
            }

        }

        impl $name {
            /// The lanes.
            #[inline(always)]
            fn to_lanes(self) -> [Real; $n] {
                // SAFETY: the register is `$n` `f64` in lane order; every bit pattern is a
                // valid `f64`.
                unsafe { std::mem::transmute::<$vec, [Real; $n]>(self.0) }
            }
        }
    };
}

simd_acc!(
    /// Four lanes in one AVX register (every table).
    F64x4, __m256d, 4, ymm_reg, _mm256_set1_pd, _mm256_loadu_pd, _mm256_fmadd_pd, pin4
);
impl Quad for F64x4 {
    #[inline(always)]
    fn lanes(self) -> [Real; 4] {
        self.to_lanes()
    }
}

/// p(u) for degree `d` (0..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn value(d: usize, t: &Tables, u: &Vector3) -> Real {
    dispatch!(d, value_kernel::<F64x4>(Avx2Fma::enabled(), t, u))
}

/// p(u) and ∇p(u) for degree `d` (0..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn value_gradient(d: usize, t: &Tables, u: &Vector3) -> (Real, Vector3) {
    dispatch!(d, gradient_kernel::<F64x4>(Avx2Fma::enabled(), t, u))
}

/// p(u), ∇p(u) and ∇²p(u) for degree `d` (0..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn eval(d: usize, t: &Tables, u: &Vector3) -> SymEval {
    dispatch!(d, full_kernel::<F64x4>(Avx2Fma::enabled(), t, u))
}

/// Defines the accumulator `$name<OFF, N>`: `N` of the ten quantities of a [`SoaPoly`] row
/// type `$row` (from entry `OFF`) at four points, one point per lane, where `$coefficient`
/// gives a row's entry `i` in all four lanes (an unsafe AVX load: the accumulator's proof
/// `Avx2Fma` is in scope wherever it runs).
macro_rules! soa_acc {
    ($(#[$doc:meta])* $name:ident, $row:ty, |$r:ident, $i:ident| $coefficient:expr) => {
        $(#[$doc])*
        #[derive(Clone, Copy)]
        struct $name<const OFF: usize, const N: usize>([__m256d; N], Avx2Fma);

        impl<const OFF: usize, const N: usize> Acc for $name<OFF, N> {
            type Row = $row;
            type Cpu = Avx2Fma;
            type Coord = F64x4;

            #[inline(always)]
            fn splat(cpu: Avx2Fma, t: Real) -> F64x4 {
                F64x4::splat(cpu, t)
            }

            #[inline(always)]
            fn load(cpu: Avx2Fma, $r: &$row) -> Self {
                // SAFETY: `$coefficient` reads entry `OFF + i` of the row; `cpu` proves AVX2.
                Self(std::array::from_fn(|$i| unsafe { $coefficient }), cpu)
            }

            #[inline(always)]
            fn mul_add_row(self, t: F64x4, $r: &$row) -> Self {
                // SAFETY: as in `load`; `self.1` proves AVX2 and FMA.
                Self(std::array::from_fn(|$i| unsafe { _mm256_fmadd_pd(self.0[$i], t.0, $coefficient) }), self.1)
            }

            #[inline(always)]
            fn mul_add(self, t: F64x4, c: Self) -> Self {
                // SAFETY: `self.1` proves AVX2 and FMA.
                Self(std::array::from_fn(|i| unsafe { _mm256_fmadd_pd(self.0[i], t.0, c.0[i]) }), self.1)
            }

            #[inline(always)]
            fn pin(self) -> Self {
                // SAFETY: `self.1` proves AVX2 (the register class of the barrier).
                Self(self.0.map(|v| unsafe { pin4(v) }), self.1)
            }
        }
    };
}

soa_acc!(
    /// `N` quantities of the replicated table ([`WideRow`]) at four points, one point per
    /// lane: each coefficient is read as a four-lane vector (each entry of a `WideRow` is four
    /// `f64` at a 32-byte boundary), the memory operand of its multiply–add, so a row costs one
    /// instruction per quantity instead of a broadcast and a multiply–add. With no broadcast
    /// registers a pass of four quantities fits the 16 AVX registers (12 accumulators and the
    /// three coordinates): passes of 4, 3, 3 quantities run as fast as 3, 3, 2, 2 with one pass
    /// fewer.
    WideAcc, WideRow, |row, i| _mm256_load_pd(row.0[OFF + i].as_ptr())
);

/// The four points of the four-point kernels (`u[i]`: coordinate i of each point), one point
/// per lane.
#[inline(always)]
fn four_points(cpu: Avx2Fma, u: &[[Real; 4]; 3]) -> Point<F64x4> {
    // SAFETY: each `u[i]` is four readable `f64`; `cpu` proves AVX2.
    let coordinate = |i: usize| F64x4(unsafe { _mm256_loadu_pd(u[i].as_ptr()) }, cpu);
    Point { x: coordinate(0), y: coordinate(1), z: coordinate(2) }
}

/// `$kernel::<D>(args)` for the runtime degree `$d` (2..=8; larger as 8): the four-point
/// kernels' dispatch.
macro_rules! four_point {
    ($d:expr, $kernel:ident($($arg:expr),*)) => {
        match $d {
            2 => $kernel::<2>($($arg),*),
            3 => $kernel::<3>($($arg),*),
            4 => $kernel::<4>($($arg),*),
            5 => $kernel::<5>($($arg),*),
            6 => $kernel::<6>($($arg),*),
            7 => $kernel::<7>($($arg),*),
            _ => $kernel::<8>($($arg),*),
        }
    };
}

/// [`SoaPoly::eval4`] over the replicated table (2d ≤ 6): three passes, of 4, 3 and 3
/// quantities.
#[inline(always)]
fn wide_kernel<const D: usize>(cpu: Avx2Fma, rows: &[WideRow], u: &[[Real; 4]; 3]) -> Soa4Eval {
    let p = four_points(cpu, u);
    let a = horner_of_degree!(D - 2, WideAcc<0, 4>, cpu, rows, point = p).0;
    let b = horner_of_degree!(D - 2, WideAcc<4, 3>, cpu, rows, point = p).0;
    let c = horner_of_degree!(D - 2, WideAcc<7, 3>, cpu, rows, point = p).0;
    euler4::<D>(cpu, p, [a[0], a[1], a[2], a[3], b[0]], [b[1], b[2], c[0], c[1], c[2]])
}

/// [`SoaPoly::eval4`] over the replicated table, for degree `d` (2..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn eval4_wide(d: usize, rows: &[WideRow], u: &[[Real; 4]; 3]) -> Soa4Eval {
    four_point!(d, wide_kernel(Avx2Fma::enabled(), rows, u))
}

/// A coordinate of four points p₀ … p₃ as two registers of two points each, [c₀, c₁, c₀, c₁]
/// and [c₂, c₃, c₂, c₃]: the multiplier of a [`PairAcc`].
#[derive(Clone, Copy)]
struct Coord2(__m256d, __m256d);

/// Two quantities (the pair `Q` of a [`PairRow`]) at four points: `[q(p₀), q(p₁), q'(p₀),
/// q'(p₁)]` and the same for p₂, p₃. Each row entry `[c, c, c', c']` is the memory operand of
/// both multiply–adds (no broadcast), and the pass keeps six accumulators (z chain, y and x
/// sums) and six coordinate registers live: 12 of the 16 AVX registers.
#[derive(Clone, Copy)]
struct PairAcc<const Q: usize>([__m256d; 2], Avx2Fma);

impl<const Q: usize> Acc for PairAcc<Q> {
    type Row = PairRow;
    type Cpu = Avx2Fma;
    type Coord = Coord2;

    #[inline(always)]
    fn splat(cpu: Avx2Fma, t: Real) -> Coord2 {
        let v = F64x4::splat(cpu, t).0;
        Coord2(v, v)
    }

    #[inline(always)]
    fn load(cpu: Avx2Fma, row: &PairRow) -> Self {
        // SAFETY: entry `Q` of a `PairRow` is four `f64` at a 32-byte boundary; `cpu` proves AVX2.
        let v = unsafe { _mm256_load_pd(row.0[Q].as_ptr()) };
        Self([v, v], cpu)
    }

    #[inline(always)]
    fn mul_add_row(self, t: Coord2, row: &PairRow) -> Self {
        // SAFETY: as in `load`; `self.1` proves AVX2 and FMA.
        unsafe {
            let r = _mm256_load_pd(row.0[Q].as_ptr());
            Self([_mm256_fmadd_pd(self.0[0], t.0, r), _mm256_fmadd_pd(self.0[1], t.1, r)], self.1)
        }
    }

    #[inline(always)]
    fn mul_add(self, t: Coord2, c: Self) -> Self {
        // SAFETY: `self.1` proves AVX2 and FMA.
        unsafe { Self([_mm256_fmadd_pd(self.0[0], t.0, c.0[0]), _mm256_fmadd_pd(self.0[1], t.1, c.0[1])], self.1) }
    }

    #[inline(always)]
    fn pin(self) -> Self {
        // SAFETY: `self.1` proves AVX2 (the register class of the barrier).
        Self(self.0.map(|v| unsafe { pin4(v) }), self.1)
    }
}

/// [`SoaPoly::eval4`] over the pair table ([`PairRow`]): five passes, one per quantity pair.
#[inline(always)]
fn pair_kernel<const D: usize>(cpu: Avx2Fma, rows: &[PairRow], u: &[[Real; 4]; 3]) -> Soa4Eval {
    let p = four_points(cpu, u);
    // SAFETY (both closures): `cpu` proves AVX2.
    let split = |c: F64x4| unsafe {
        Coord2(_mm256_permute4x64_pd::<0b01_00_01_00>(c.0), _mm256_permute4x64_pd::<0b11_10_11_10>(c.0))
    };
    let q = Point { x: split(p.x), y: split(p.y), z: split(p.z) };
    let unzip = |a: [__m256d; 2]| unsafe {
        [_mm256_permute2f128_pd::<0x20>(a[0], a[1]), _mm256_permute2f128_pd::<0x31>(a[0], a[1])]
    };
    let a = unzip(horner_of_degree!(D - 2, PairAcc<0>, cpu, rows, point = q).0);
    let b = unzip(horner_of_degree!(D - 2, PairAcc<1>, cpu, rows, point = q).0);
    let c = unzip(horner_of_degree!(D - 2, PairAcc<2>, cpu, rows, point = q).0);
    let e = unzip(horner_of_degree!(D - 2, PairAcc<3>, cpu, rows, point = q).0);
    let f = unzip(horner_of_degree!(D - 2, PairAcc<4>, cpu, rows, point = q).0);
    euler4::<D>(cpu, p, [a[0], a[1], b[0], b[1], c[0]], [c[1], e[0], e[1], f[0], f[1]])
}

/// [`SoaPoly::eval4`] over the pair table, for degree `d` (2..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn eval4_pair(d: usize, rows: &[PairRow], u: &[[Real; 4]; 3]) -> Soa4Eval {
    four_point!(d, pair_kernel(Avx2Fma::enabled(), rows, u))
}

pin_fn!(pin8, __m256, ymm_reg);

/// A coordinate of four points in single precision, twice: [c₀, c₁, c₂, c₃, c₀, c₁, c₂, c₃],
/// the multiplier of a [`Pair32Acc`].
#[derive(Clone, Copy)]
struct Coord32(__m256);

/// `N` quantity pairs of a [`PairRow32`] (from pair `OFF`) at four points in single precision:
/// each register holds `[q(p₀), …, q(p₃), q'(p₀), …, q'(p₃)]`, and each row entry
/// `[c, c, c, c, c', c', c', c']` is the memory operand of its multiply–add. Half the
/// multiply–adds of the double-precision pair table ([`PairAcc`]) for the same four points.
#[derive(Clone, Copy)]
struct Pair32Acc<const OFF: usize, const N: usize>([__m256; N], Avx2Fma);

impl<const OFF: usize, const N: usize> Acc for Pair32Acc<OFF, N> {
    type Row = PairRow32;
    type Cpu = Avx2Fma;
    type Coord = Coord32;

    #[inline(always)]
    fn splat(_cpu: Avx2Fma, t: Real) -> Coord32 {
        // SAFETY: `_cpu` proves AVX2.
        Coord32(unsafe { _mm256_set1_ps(t as f32) })
    }

    #[inline(always)]
    fn load(cpu: Avx2Fma, row: &PairRow32) -> Self {
        // SAFETY: entry `OFF + i` of a `PairRow32` is eight `f32` at a 32-byte boundary; `cpu`
        // proves AVX2.
        Self(std::array::from_fn(|i| unsafe { _mm256_load_ps(row.0[OFF + i].as_ptr()) }), cpu)
    }

    #[inline(always)]
    fn mul_add_row(self, t: Coord32, row: &PairRow32) -> Self {
        // SAFETY: as in `load`; `self.1` proves AVX2 and FMA.
        Self(
            std::array::from_fn(|i| unsafe {
                _mm256_fmadd_ps(self.0[i], t.0, _mm256_load_ps(row.0[OFF + i].as_ptr()))
            }),
            self.1,
        )
    }

    #[inline(always)]
    fn mul_add(self, t: Coord32, c: Self) -> Self {
        // SAFETY: `self.1` proves AVX2 and FMA.
        Self(std::array::from_fn(|i| unsafe { _mm256_fmadd_ps(self.0[i], t.0, c.0[i]) }), self.1)
    }

    #[inline(always)]
    fn pin(self) -> Self {
        // SAFETY: `self.1` proves AVX2 (the register class of the barrier).
        Self(self.0.map(|v| unsafe { pin8(v) }), self.1)
    }
}

/// [`SoaPoly::eval4_rows_f32`] over the single-precision pair table: two passes (three and two
/// quantity pairs), the sums widened to `f64` for Euler's identity.
#[inline(always)]
fn pair32_kernel<const D: usize>(cpu: Avx2Fma, rows: &[PairRow32], u: &[[Real; 4]; 3]) -> Soa4Eval {
    let p = four_points(cpu, u);
    // SAFETY (both closures): `cpu` proves AVX2.
    let narrow = |c: F64x4| unsafe {
        let h = _mm256_cvtpd_ps(c.0);
        Coord32(_mm256_set_m128(h, h))
    };
    let q = Point { x: narrow(p.x), y: narrow(p.y), z: narrow(p.z) };
    let widen = |v: __m256| unsafe {
        [_mm256_cvtps_pd(_mm256_castps256_ps128(v)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v))]
    };
    let a = horner_of_degree!(D - 2, Pair32Acc<0, 3>, cpu, rows, point = q).0;
    let b = horner_of_degree!(D - 2, Pair32Acc<3, 2>, cpu, rows, point = q).0;
    let (a0, a1, a2, b0, b1) = (widen(a[0]), widen(a[1]), widen(a[2]), widen(b[0]), widen(b[1]));
    euler4::<D>(cpu, p, [a0[0], a0[1], a1[0], a1[1], a2[0]], [a2[1], b0[0], b0[1], b1[0], b1[1]])
}

/// [`SoaPoly::eval4_rows_f32`] over the single-precision pair table, for degree `d` (2..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn eval4_pair32(d: usize, rows: &[PairRow32], u: &[[Real; 4]; 3]) -> Soa4Eval {
    four_point!(d, pair32_kernel(Avx2Fma::enabled(), rows, u))
}

/// The Horner sums of the five quantity pairs of a single-precision pair table at four points
/// (`q`: each coordinate twice, [`Coord32`]): the passes of [`SoaPoly::eval4_rows_f32`], three
/// and two quantity pairs ([`Pair32Acc`]). Not inlined: inlined twice into one kernel, LLVM
/// interleaves the two groups' passes beyond the 16 AVX registers and spills (the batch ran
/// 15–30 % slower so).
#[target_feature(enable = "avx2,fma")]
#[inline(never)]
fn pair32_sums<const D: usize>(rows: &[PairRow32], q: &Point<Coord32>) -> [__m256; 5] {
    let cpu = Avx2Fma::enabled();
    let a = horner_of_degree!(D - 2, Pair32Acc<0, 3>, cpu, rows, point = *q).0;
    let b = horner_of_degree!(D - 2, Pair32Acc<3, 2>, cpu, rows, point = *q).0;
    [a[0], a[1], a[2], b[0], b[1]]
}

/// [`SoaPoly::eval8_rows_f32`] over the single-precision pair table: [`pair32_sums`] for
/// points 0–3 and 4–7, then Euler's identity in eight `f32` lanes.
#[inline(always)]
fn pair32x8_kernel<const D: usize>(cpu: Avx2Fma, rows: &[PairRow32], u: &[[f32; 8]; 3]) -> Soa8Eval32 {
    // SAFETY (all four closures): each `u[i]` is eight readable `f32`; `cpu` proves AVX2.
    let coordinate = |i: usize| unsafe { _mm256_loadu_ps(u[i].as_ptr()) };
    let (x, y, z) = (coordinate(0), coordinate(1), coordinate(2));
    let lo = |c: __m256| Coord32(unsafe { _mm256_permute2f128_ps::<0x00>(c, c) });
    let hi = |c: __m256| Coord32(unsafe { _mm256_permute2f128_ps::<0x11>(c, c) });
    // SAFETY: `cpu` proves AVX2 and FMA.
    let s0 = unsafe { pair32_sums::<D>(rows, &Point { x: lo(x), y: lo(y), z: lo(z) }) };
    // SAFETY: as above.
    let s1 = unsafe { pair32_sums::<D>(rows, &Point { x: hi(x), y: hi(y), z: hi(z) }) };
    // [q(p₀…₃), q'(p₀…₃)] and [q(p₄…₇), q'(p₄…₇)] → [q(p₀…₇)], [q'(p₀…₇)].
    let unzip = |k: usize| unsafe {
        [_mm256_permute2f128_ps::<0x20>(s0[k], s1[k]), _mm256_permute2f128_ps::<0x31>(s0[k], s1[k])]
    };
    let (a, b, c, e, f) = (unzip(0), unzip(1), unzip(2), unzip(3), unzip(4));
    euler8::<D>(cpu, [x, y, z], [a[0], a[1], b[0], b[1], c[0]], [c[1], e[0], e[1], f[0], f[1]])
}

/// [`SoaPoly::eval8_rows_f32`] over the single-precision pair table, for degree `d` (2..=8).
#[target_feature(enable = "avx2,fma")]
pub(super) fn eval8_pair32(d: usize, rows: &[PairRow32], u: &[[f32; 8]; 3]) -> Soa8Eval32 {
    four_point!(d, pair32x8_kernel(Avx2Fma::enabled(), rows, u))
}

/// p and ∇p at the four points (x, y, z) from the Horner sums `lo` = [xx, xy, xz, yy, yz] and
/// `hi` = [zz, r_x, r_y, r_z, w] of a [`SoaPoly`] row table: Euler's identity as in
/// `full_kernel`, four points per instruction.
#[inline(always)]
fn euler_value_gradient<const D: usize>(
    _cpu: Avx2Fma,
    [x, y, z]: [__m256d; 3],
    lo: [__m256d; 5],
    hi: [__m256d; 5],
) -> (__m256d, [__m256d; 3]) {
    // SAFETY: `_cpu` proves AVX2 and FMA.
    unsafe {
        let (xx, xy, xz, yy, yz, zz) = (lo[0], lo[1], lo[2], lo[3], lo[4], hi[0]);
        let dot =
            |a: __m256d, b: __m256d, c: __m256d| _mm256_fmadd_pd(c, z, _mm256_fmadd_pd(b, y, _mm256_mul_pd(a, x)));
        let hu = [dot(xx, xy, xz), dot(xy, yy, yz), dot(xz, yz, zz)];
        let (k1, k2) = (_mm256_set1_pd(1.0 / (D - 1) as Real), _mm256_set1_pd(1.0 / D as Real));
        let g =
            [_mm256_fmadd_pd(hu[0], k1, hi[1]), _mm256_fmadd_pd(hu[1], k1, hi[2]), _mm256_fmadd_pd(hu[2], k1, hi[3])];
        let two = _mm256_set1_pd(2.0);
        let value = _mm256_fmadd_pd(
            _mm256_sub_pd(_mm256_mul_pd(two, dot(g[0], g[1], g[2])), _mm256_mul_pd(dot(hu[0], hu[1], hu[2]), k1)),
            k2,
            hi[4],
        );
        (value, g)
    }
}

/// p, ∇p and ∇²p at the four points `p` from the Horner sums `lo` and `hi`
/// ([`euler_value_gradient`]).
#[inline(always)]
fn euler4<const D: usize>(cpu: Avx2Fma, p: Point<F64x4>, lo: [__m256d; 5], hi: [__m256d; 5]) -> Soa4Eval {
    let (value, g) = euler_value_gradient::<D>(cpu, [p.x.0, p.y.0, p.z.0], lo, hi);
    // SAFETY: `cpu` proves AVX2.
    unsafe {
        // Element by element, no array `map`: a closure called through `map` may be compiled
        // out of line without AVX (measured: 42 instead of 22 ns per point at 2d = 6).
        let mut out = Soa4Eval::default();
        _mm256_storeu_pd(out.value.as_mut_ptr(), value);
        for (o, v) in out.gradient.iter_mut().zip(g) {
            _mm256_storeu_pd(o.as_mut_ptr(), v);
        }
        for (o, v) in out.hessian.iter_mut().zip([lo[0], lo[1], lo[2], lo[3], lo[4], hi[0]]) {
            _mm256_storeu_pd(o.as_mut_ptr(), v);
        }
        out
    }
}

/// p, ∇p and ∇²p at eight points in single precision from the `f32` Horner sums `lo` and `hi`
/// (eight lanes each): the Hessian as summed, p and ∇p by [`euler_value_gradient`] in double
/// precision, four points at a time, then rounded. (Euler's identity in `f32` cancels: its
/// hand-offs cost the batch's fine stage 8 % more double-precision evaluations at 2d = 8.)
#[inline(always)]
fn euler8<const D: usize>(cpu: Avx2Fma, p: [__m256; 3], lo: [__m256; 5], hi: [__m256; 5]) -> Soa8Eval32 {
    // SAFETY: `cpu` proves AVX2 (all three closures and the block).
    let widen = |v: __m256| unsafe {
        [_mm256_cvtps_pd(_mm256_castps256_ps128(v)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v))]
    };
    let narrow = |a: __m256d, b: __m256d| unsafe { _mm256_set_m128(_mm256_cvtpd_ps(b), _mm256_cvtpd_ps(a)) };
    // Written out (no array `map` over registers, see `euler4`).
    let (x, y, z) = (widen(p[0]), widen(p[1]), widen(p[2]));
    let l = [widen(lo[0]), widen(lo[1]), widen(lo[2]), widen(lo[3]), widen(lo[4])];
    let h = [widen(hi[0]), widen(hi[1]), widen(hi[2]), widen(hi[3]), widen(hi[4])];
    let (v0, g0) = euler_value_gradient::<D>(
        cpu,
        [x[0], y[0], z[0]],
        [l[0][0], l[1][0], l[2][0], l[3][0], l[4][0]],
        [h[0][0], h[1][0], h[2][0], h[3][0], h[4][0]],
    );
    let (v1, g1) = euler_value_gradient::<D>(
        cpu,
        [x[1], y[1], z[1]],
        [l[0][1], l[1][1], l[2][1], l[3][1], l[4][1]],
        [h[0][1], h[1][1], h[2][1], h[3][1], h[4][1]],
    );
    unsafe {
        let mut out = Soa8Eval32::default();
        _mm256_storeu_ps(out.value.as_mut_ptr(), narrow(v0, v1));
        for (k, o) in out.gradient.iter_mut().enumerate() {
            _mm256_storeu_ps(o.as_mut_ptr(), narrow(g0[k], g1[k]));
        }
        for (o, v) in out.hessian.iter_mut().zip([lo[0], lo[1], lo[2], lo[3], lo[4], hi[0]]) {
            _mm256_storeu_ps(o.as_mut_ptr(), v);
        }
        out
    }
}
