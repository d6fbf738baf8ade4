//! Fast value / gradient / Hessian evaluation of one polynomial at many points (the query hot
//! path, paper §IV) through per-body derivative coefficient tables and nested Horner schemes.
//!
//! For p(u) = Σ_α c_α u^α (monomials of degree ≤ 2d) every derivative is again a polynomial of
//! lower degree:
//!
//! ```text
//! ∂ᵢ p(u)   = Σ_{|β| ≤ 2d−1} (βᵢ + 1) c_{β+eᵢ} u^β
//! ∂ᵢ∂ⱼ p(u) = Σ_{|β| ≤ 2d−2} (βᵢ + 1)(βⱼ + 1 + δᵢⱼ) c_{β+eᵢ+eⱼ} u^β
//! ```
//!
//! A full evaluation reads only the rows of degree ≤ 2d − 2, through Euler's identity for
//! homogeneous parts (u·∇pₖ = k pₖ): with D = 2d,
//!
//! ```text
//! ∇p = ∇²p u / (D − 1) + r,   rᵢ = Σₖ (D − 1 − k)/(D − 1) (∂ᵢp)ₖ                  (degree ≤ D − 2)
//! p  = (2 u·∇p − uᵀ∇²p u / (D − 1)) / D + w,   w = Σₖ (D − 1 − k)(D − k)/(D(D − 1)) pₖ  (degree ≤ D − 2)
//! ```
//!
//! and a value or value + gradient evaluation only the rows of degree ≤ 2d − 1
//! (p = u·∇p / D + s, s = Σₖ (D − k)/D pₖ). The coefficients are rearranged once per body
//! ([`FastPoly::new`]) into lane-interleaved rows — `[s, ∂ₓ, ∂ᵧ, ∂_z]` for |β| ≤ 2d − 1;
//! `[xx, xy, xz, yy]`, `[yz, zz, r_x, r_y]` and `[r_z, w]` for |β| ≤ 2d − 2 — ordered for a nested
//! Horner scheme (exponent a of x, then b of y, then c of z, each descending):
//!
//! ```text
//! q(u) = Σ_a x^a Σ_b y^b Σ_c r_abc z^c  =  Horner in x of (Horner in y of (chains of Horner in z))
//! ```
//!
//! One evaluation is then a sequence of lane-wise fused multiply–adds `acc ← acc·z + row` (then ·y,
//! ·x) over contiguous rows: no monomial vector is built, and the many short z chains are
//! independent. Each Horner sum starts from its top term (no multiply–add with zero). The chain
//! lengths of every degree are literals (macro `horner_fn!`), so each scheme compiles to
//! straight-line code, written once over a lane accumulator (trait `Acc`). On x86-64 CPUs with
//! AVX2 and FMA (detected at run time) the accumulators are `__m256d` (4-lane tables) and `__m128d`
//! ([yz, zz]) registers: one `vfmadd` per row with the row as its memory operand, no scalar lanes.
//! An empty `asm!` after each power of x pins the running sum, else LLVM hoists every z chain above
//! the y and x steps and spills. Elsewhere the portable code runs on `[f64; L]` arrays with unfused
//! a·b + c.
//!
//! Cost (callgrind, instructions per evaluation at 2d = 4 / 6 / 8): value 56 / 116 / 208, value +
//! gradient 58 / 118 / 210, value + gradient + Hessian 96 / 220 / 431. The kernels' time follows
//! their count of multiply–adds (a chain of dependent evaluations runs almost as fast as
//! independent ones), so Euler's identity, which drops the rows of the top one or two degrees for
//! a few scalar operations, buys time: a full evaluation at 2d = 6 takes 92 multiply–adds (35 + 35
//! Hessian rows of degree ≤ 4 and the [r_z, w] table folded in x to 22 four-lane rows) where the
//! plain derivative tables would take 154, at 2d = 8 218 instead of 333; a value + gradient
//! evaluation reads 56 rows instead of 84. The value runs the value + gradient scheme (a 4-lane FMA
//! is one instruction, like a scalar one).
//!
//! The two Hessian tables are one table of paired rows read by one pass (`Two`): two independent
//! chains side by side, which the processor overlaps where two separate passes would not (about
//! 10 % faster at 2d = 8, bit-identical answers). The value + gradient pass is not split that
//! way: its even and odd powers of x would take 68 rows instead of 56. The scheduling barriers
//! matter as much: without them a full evaluation at 2d = 6 takes about 42 instead of 39 ns.
//! See docs/performance.md for the measurements.

use crate::cpu::Avx2Fma;
use crate::monomial::{basis_len, index3};
use crate::{Eval, Real, Sym3, Vector3, MAX_DEGREE};

/// Rows of the value / gradient table: monomials of degree ≤ 7 (120), the gradient of a degree-8
/// polynomial.
const MAX_GRADIENT_MONOMIALS: usize = 120;

/// Rows of the Hessian tables: monomials of degree ≤ 6 (84), the Hessian of a degree-8 polynomial.
const MAX_HESSIAN_MONOMIALS: usize = 84;

/// Rows of the folded [r_z, w] table at degree 6 ([`fold_exponents`]).
const MAX_FOLDED_ROWS: usize = 50;

/// The per-body coefficient tables (see the module docs); rows beyond the body's basis are zero.
/// D is the degree bound 2d, p = Σₖ pₖ its homogeneous parts.
///
/// Aligned to a cache line (64 bytes), so that no 32-byte row straddles two lines. The allocator
/// aligns a box to 16 bytes only, and a table at 16 mod 32 splits every other row load in two: a
/// full evaluation then takes about a fifth longer (39.8 against 32.2 ns at 2d = 6, 73.1 against
/// 54.7 ns at 2d = 8, `kernel_timing`), for whichever bodies the allocator happened to misplace.
#[derive(Clone, Debug, PartialEq)]
#[repr(align(64))]
struct Tables {
    /// Coefficients of u^β (|β| ≤ D − 1) in [s, ∂ₓp, ∂ᵧp, ∂_zp] with s = Σₖ (D − k)/D · pₖ, so that
    /// p = u·∇p / D + s (Euler's identity u·∇pₖ = k pₖ; the degree-D part of s vanishes).
    value_gradient: [[Real; 4]; MAX_GRADIENT_MONOMIALS],
    /// Coefficients of u^β (|β| ≤ D − 2) in two 4-lane halves, [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp] and
    /// [∂ᵧ_zp, ∂_z_zp, r_x, r_y], where rᵢ = Σₖ (D − 1 − k)/(D − 1) · (∂ᵢp)ₖ, so that
    /// ∇p = ∇²p u / (D − 1) + r (Euler's identity on the gradient; its degree-(D − 1) part
    /// vanishes). Both halves of a row are read by one pass ([`Two`]): two independent chains of
    /// multiply–adds side by side.
    hessian: [[[Real; 4]; 2]; MAX_HESSIAN_MONOMIALS],
    /// [r_z, w] with w = Σₖ (D − 1 − k)(D − k)/(D(D − 1)) · pₖ, so that
    /// p = (2 u·∇p − uᵀ∇²p u / (D − 1)) / D + w; folded in x to fill four lanes: q = E(x², y, z) +
    /// x·O(x², y, z) for the parts E, O of even and odd powers of x, the row of (a, b, c), a even
    /// ([`fold_exponents`]), holding [E, O] = [q_(a,b,c), q_(a+1,b,c)] for q = r_z, w (zero beyond
    /// degree D − 2). 22 rows instead of 35 at 2d = 6, 50 instead of 84 at 2d = 8.
    tail: [[Real; 4]; MAX_FOLDED_ROWS],
}

/// A polynomial with its derivative coefficient tables for the fast kernels (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct FastPoly {
    degree: usize,
    len: usize,
    tables: Box<Tables>,
}

/// The exponents (a, b, c) of degree ≤ `d` in the order of the nested Horner scheme: a descending,
/// then b descending, then c descending.
fn horner_exponents(d: usize) -> Vec<[usize; 3]> {
    let mut out = Vec::with_capacity(basis_len(3, d));
    for a in (0..=d).rev() {
        for b in (0..=d - a).rev() {
            for c in (0..=d - a - b).rev() {
                out.push([a, b, c]);
            }
        }
    }
    out
}

/// The exponents (a, b, c) of degree ≤ `d` with a even, in Horner order: the rows of the folded
/// table ([`Tables::tail`]), a Horner scheme in x² whose groups have the chain lengths of the even
/// powers of x.
fn fold_exponents(d: usize) -> Vec<[usize; 3]> {
    horner_exponents(d).into_iter().filter(|e| e[0] % 2 == 0).collect()
}

/// A lane-wise accumulator of the Horner schemes: one value per lane of a table row. The schemes
/// (`horner_fn!`) are written once over this trait; [`Lanes`] is the portable implementation,
/// `x86::F64x4` the AVX2 + FMA one.
trait Acc: Copy {
    /// One table row (the lanes in memory).
    type Row;
    /// What creating an accumulator needs besides a row: nothing for the portable lanes, the
    /// proof that the CPU runs AVX2 and FMA for the x86 registers.
    type Cpu: Copy;
    /// A coordinate broadcast to every lane.
    type Coord: Copy;

    /// `t` in every lane.
    fn splat(cpu: Self::Cpu, t: Real) -> Self::Coord;
    /// The accumulator holding `row`.
    fn load(cpu: Self::Cpu, row: &Self::Row) -> Self;
    /// `self·t + row`, lane-wise (fused on x86).
    fn mul_add_row(self, t: Self::Coord, row: &Self::Row) -> Self;
    /// `self·t + c`, lane-wise (fused on x86).
    fn mul_add(self, t: Self::Coord, c: Self) -> Self;

    /// `self`, computed before any later table load: a scheduling barrier after each power of x
    /// and at the end of a scheme (without it LLVM computes every z chain of the x86 kernels
    /// first, then the y and x steps, and spills). Emits no instruction; the identity here.
    #[inline(always)]
    fn pin(self) -> Self {
        self
    }
}

/// Two accumulators run side by side over rows of two halves: one pass over a table of paired
/// rows is two independent chains of multiply–adds, interleaved instruction by instruction. A
/// Horner pass is a chain of dependent multiply–adds, so a single one runs at the FMA latency
/// (about a third of the FMA units' throughput); the processor's scheduler sees only a few dozen
/// instructions ahead, so separate passes do not overlap, while interleaved ones do.
#[derive(Clone, Copy)]
struct Two<A>(A, A);

impl<A: Acc> Acc for Two<A> {
    type Row = [A::Row; 2];
    type Cpu = A::Cpu;
    type Coord = A::Coord;

    #[inline(always)]
    fn splat(cpu: Self::Cpu, t: Real) -> Self::Coord {
        A::splat(cpu, t)
    }

    #[inline(always)]
    fn load(cpu: Self::Cpu, row: &Self::Row) -> Self {
        Self(A::load(cpu, &row[0]), A::load(cpu, &row[1]))
    }

    #[inline(always)]
    fn mul_add_row(self, t: Self::Coord, row: &Self::Row) -> Self {
        Self(self.0.mul_add_row(t, &row[0]), self.1.mul_add_row(t, &row[1]))
    }

    #[inline(always)]
    fn mul_add(self, t: Self::Coord, c: Self) -> Self {
        Self(self.0.mul_add(t, c.0), self.1.mul_add(t, c.1))
    }

    #[inline(always)]
    fn pin(self) -> Self {
        Self(self.0.pin(), self.1.pin())
    }
}

impl<A: Quad> Two<A> {
    /// The lanes of both halves.
    #[inline(always)]
    fn lanes(self) -> [[Real; 4]; 2] {
        [self.0.lanes(), self.1.lanes()]
    }
}

/// A 4-lane accumulator (every table has four lanes): the type parameter of the kernels.
trait Quad: Acc<Row = [Real; 4]> {
    /// The lanes.
    fn lanes(self) -> [Real; 4];
}

/// The portable accumulator: `L` lanes, unfused a·b + c (no FMA).
#[derive(Clone, Copy)]
struct Lanes<const L: usize>([Real; L]);

impl<const L: usize> Lanes<L> {
    /// `self·t + c` lane-wise, unfused.
    #[inline(always)]
    fn step(mut self, t: Real, c: &[Real; L]) -> Self {
        for (a, c) in self.0.iter_mut().zip(c) {
            *a = *a * t + *c;
        }
        self
    }
}

impl<const L: usize> Acc for Lanes<L> {
    type Row = [Real; L];
    type Cpu = ();
    type Coord = Real;

    #[inline(always)]
    fn splat((): (), t: Real) -> Real {
        t
    }

    #[inline(always)]
    fn load((): (), row: &[Real; L]) -> Self {
        Self(*row)
    }

    #[inline(always)]
    fn mul_add_row(self, t: Real, row: &[Real; L]) -> Self {
        self.step(t, row)
    }

    #[inline(always)]
    fn mul_add(self, t: Real, c: Self) -> Self {
        self.step(t, &c.0)
    }
}

/// The portable 4-lane accumulator.
type Portable = Lanes<4>;

impl Quad for Portable {
    #[inline(always)]
    fn lanes(self) -> [Real; 4] {
        self.0
    }
}

/// Horner in z along the chain of M rows starting at `*k` (the top coefficient first), then
/// `*k += M`: M is a constant, so the loop unrolls.
#[inline(always)]
fn chain<const M: usize, A: Acc>(cpu: A::Cpu, rows: &[A::Row], k: &mut usize, z: A::Coord) -> A {
    let mut acc = A::load(cpu, &rows[*k]);
    for row in &rows[*k + 1..*k + M] {
        acc = acc.mul_add_row(z, row);
    }
    *k += M;
    acc
}

/// The evaluation point with each coordinate broadcast to every lane.
#[derive(Clone, Copy)]
struct Point<C> {
    x: C,
    y: C,
    z: C,
}

impl<C: Copy> Point<C> {
    /// `u` broadcast for accumulator `A`.
    #[inline(always)]
    fn splat<A: Acc<Coord = C>>(cpu: A::Cpu, u: &Vector3) -> Self {
        Self { x: A::splat(cpu, u.x), y: A::splat(cpu, u.y), z: A::splat(cpu, u.z) }
    }
}

/// Horner in y over the z chains of one power of x (lengths `$m0, $m…`, the top power of y
/// first); the first chain starts the sum (no multiply–add with zero).
macro_rules! horner_y {
    ($cpu:ident, $rows:ident, $k:ident, $p:ident; $m0:literal $(, $m:literal)*) => {{
        let acc_y = chain::<$m0, A>($cpu, $rows, &mut $k, $p.z);
        $(
            let acc_y = acc_y.mul_add($p.y, chain::<$m, A>($cpu, $rows, &mut $k, $p.z));
        )*
        acc_y
    }};
}

/// Defines `$name::<A>(cpu, rows, p)`: Σ rows[(a, b, c)] x^a y^b z^c lane-wise over the $n rows of
/// one degree in Horner order ([`horner_exponents`]), as Horner in x of Horner in y of the z
/// chains whose lengths are listed per power of x (descending); every count is a literal, so the
/// whole scheme is straight-line code. Each Horner sum starts from its top term (no multiply–add
/// with zero).
macro_rules! horner_fn {
    ($name:ident, $n:literal; [$($m0:literal),*] $(, [$($m:literal),*])*) => {
        #[inline(always)]
        fn $name<A: Acc>(cpu: A::Cpu, rows: &[A::Row], p: Point<A::Coord>) -> A {
            let rows = &rows[..$n];
            let mut k = 0usize;
            let acc_x = horner_y!(cpu, rows, k, p; $($m0),*);
            $(
                let acc_x = acc_x.pin().mul_add(p.x, horner_y!(cpu, rows, k, p; $($m),*));
            )*
            debug_assert_eq!(k, $n);
            acc_x.pin()
        }
    };
}

horner_fn!(horner_0, 1; [1]);
horner_fn!(horner_1, 4; [1],[1,2]);
horner_fn!(horner_2, 10; [1],[1,2],[1,2,3]);
horner_fn!(horner_3, 20; [1],[1,2],[1,2,3],[1,2,3,4]);
horner_fn!(horner_4, 35; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5]);
horner_fn!(horner_5, 56; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6]);
horner_fn!(horner_6, 84; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6],[1,2,3,4,5,6,7]);
horner_fn!(horner_7, 120; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6],[1,2,3,4,5,6,7],[1,2,3,4,5,6,7,8]);
horner_fn!(horner_8, 165; [1],[1,2],[1,2,3],[1,2,3,4],[1,2,3,4,5],[1,2,3,4,5,6],[1,2,3,4,5,6,7],[1,2,3,4,5,6,7,8],[1,2,3,4,5,6,7,8,9]);

// The folded schemes: the groups of even powers of x only, evaluated at (x², y, z).
horner_fn!(fold_0, 1; [1]);
horner_fn!(fold_1, 3; [1,2]);
horner_fn!(fold_2, 7; [1],[1,2,3]);
horner_fn!(fold_3, 13; [1,2],[1,2,3,4]);
horner_fn!(fold_4, 22; [1],[1,2,3],[1,2,3,4,5]);
horner_fn!(fold_5, 34; [1,2],[1,2,3,4],[1,2,3,4,5,6]);
horner_fn!(fold_6, 50; [1],[1,2,3],[1,2,3,4,5],[1,2,3,4,5,6,7]);

/// `$f::<$a>($cpu, $rows, $u)` for the scheme `$f` listed for the runtime degree `$d` (the last
/// one for any larger `$d`).
macro_rules! scheme_of_degree {
    ($d:expr, [$($n:literal => $f:ident),*; $last:ident], $a:ty, $cpu:expr, $rows:expr, point = $p:expr) => {{
        let p = $p;
        match $d {
            $($n => $f::<$a>($cpu, $rows, p),)*
            _ => $last::<$a>($cpu, $rows, p),
        }
    }};
    ($d:expr, [$($n:literal => $f:ident),*; $last:ident], $a:ty, $cpu:expr, $rows:expr, $u:expr) => {
        scheme_of_degree!($d, [$($n => $f),*; $last], $a, $cpu, $rows, point = Point::splat::<$a>($cpu, $u))
    };
}

/// The folded Horner scheme of degree `$d` (0..=6) at `$u` = (x², y, z).
macro_rules! fold_of_degree {
    ($d:expr, $a:ty, $cpu:expr, $rows:expr, $u:expr) => {
        scheme_of_degree!(
            $d,
            [0 => fold_0, 1 => fold_1, 2 => fold_2, 3 => fold_3, 4 => fold_4, 5 => fold_5; fold_6],
            $a, $cpu, $rows, $u
        )
    };
}

/// The Horner scheme of degree `$d` (0..=8) with accumulator `$a` over `$rows`.
macro_rules! horner_of_degree {
    ($d:expr, $a:ty, $cpu:expr, $rows:expr, $($u:tt)+) => {
        scheme_of_degree!(
            $d,
            [0 => horner_0, 1 => horner_1, 2 => horner_2, 3 => horner_3, 4 => horner_4, 5 => horner_5,
             6 => horner_6, 7 => horner_7; horner_8],
            $a, $cpu, $rows, $($u)+
        )
    };
}

/// u · v, unfused (the same rounding on every code path).
#[inline(always)]
fn dot3(u: &Vector3, v: &Vector3) -> Real {
    u.x * v.x + u.y * v.y + u.z * v.z
}

/// p(u) and ∇p(u) for degree `D` (a constant at every call site): one pass over the rows of
/// degree ≤ D − 1, then p = u·∇p / D + s.
#[inline(always)]
fn gradient_kernel<const D: usize, Q: Quad>(cpu: Q::Cpu, t: &Tables, u: &Vector3) -> (Real, Vector3) {
    let r = horner_of_degree!(D.saturating_sub(1), Q, cpu, &t.value_gradient, u).lanes();
    let g = Vector3::new(r[1], r[2], r[3]);
    // D = 0: the constant is s itself (and ∇p = 0).
    let value = if D == 0 { r[0] } else { dot3(u, &g) * (1.0 / D as Real) + r[0] };
    (value, g)
}

/// p(u).
#[inline(always)]
fn value_kernel<const D: usize, Q: Quad>(cpu: Q::Cpu, t: &Tables, u: &Vector3) -> Real {
    gradient_kernel::<D, Q>(cpu, t, u).0
}

/// p(u), ∇p(u) and the upper triangle of ∇²p(u): the fast kernels' full evaluation
/// ([`FastPoly::eval`] returns the same as an [`Eval`], with the full Hessian).
#[derive(Clone, Copy, Debug)]
pub struct SymEval {
    /// p(u).
    pub value: Real,
    /// ∇p(u).
    pub gradient: Vector3,
    /// ∇²p(u), upper triangle.
    pub hessian: Sym3,
}

impl From<SymEval> for Eval {
    fn from(e: SymEval) -> Self {
        Self { value: e.value, gradient: e.gradient, hessian: e.hessian.to_matrix() }
    }
}

/// p(u), ∇p(u) and ∇²p(u) from the rows of degree ≤ D − 2 only (D ≥ 2; below, the value +
/// gradient pass and a zero Hessian): ∇p = ∇²p u / (D − 1) + r and
/// p = (2 u·∇p − uᵀ∇²p u / (D − 1)) / D + w (see [`Tables`]).
#[inline(always)]
fn full_kernel<const D: usize, Q: Quad>(cpu: Q::Cpu, t: &Tables, u: &Vector3) -> SymEval {
    if D < 2 {
        let (value, gradient) = gradient_kernel::<D, Q>(cpu, t, u);
        return SymEval { value, gradient, hessian: Sym3::default() };
    }
    let [h, m] = horner_of_degree!(D - 2, Two<Q>, cpu, &t.hessian, u).lanes();
    let f = fold_of_degree!(D - 2, Q, cpu, &t.tail, &Vector3::new(u.x * u.x, u.y, u.z)).lanes();
    let n = [f[0] + u.x * f[2], f[1] + u.x * f[3]];
    let hessian = Sym3([h[0], h[1], h[2], h[3], m[0], m[1]]);
    let hu = Vector3::new(
        h[0] * u.x + h[1] * u.y + h[2] * u.z,
        h[1] * u.x + h[3] * u.y + m[0] * u.z,
        h[2] * u.x + m[0] * u.y + m[1] * u.z,
    );
    let (k1, k2) = (1.0 / (D - 1) as Real, 1.0 / D as Real);
    let gradient = hu * k1 + Vector3::new(m[2], m[3], n[0]);
    let value = (2.0 * dot3(u, &gradient) - dot3(u, &hu) * k1) * k2 + n[1];
    SymEval { value, gradient, hessian }
}

/// Calls `$kernel::<D, $q>($args)` for the runtime degree `$d` (0..=8).
macro_rules! dispatch {
    ($d:expr, $kernel:ident::<$q:ty>($($arg:expr),*)) => {
        match $d {
            0 => $kernel::<0, $q>($($arg),*),
            1 => $kernel::<1, $q>($($arg),*),
            2 => $kernel::<2, $q>($($arg),*),
            3 => $kernel::<3, $q>($($arg),*),
            4 => $kernel::<4, $q>($($arg),*),
            5 => $kernel::<5, $q>($($arg),*),
            6 => $kernel::<6, $q>($($arg),*),
            7 => $kernel::<7, $q>($($arg),*),
            _ => $kernel::<8, $q>($($arg),*),
        }
    };
}

#[cfg(target_arch = "x86_64")]
mod x86;

mod soa;
use soa::*;
pub use soa::{Soa4Eval, Soa8Eval32, SoaPoly};

/// Whether this CPU runs the AVX2 + FMA kernels ([`crate::cpu_has_avx2_fma`], the check the
/// query solvers' builds use too).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn has_fma() -> bool {
    crate::cpu_has_avx2_fma()
}

impl FastPoly {
    /// Builds the derivative coefficient tables of p(u) = Σ_α c_α u^α from its degree bound 2d
    /// (at most [`MAX_DEGREE`]; larger is clamped) and its coefficients in the graded-lex order of
    /// [`crate::monomial`] (`coefficients[index3(α)]` = c_α; missing entries are zero).
    pub fn new(degree: usize, coefficients: &[Real]) -> Self {
        let degree = degree.min(MAX_DEGREE);
        let len = basis_len(3, degree);
        let c = coefficients;
        let coef_of = |e: [usize; 3]| -> Real {
            if e.iter().sum::<usize>() > degree {
                return 0.0;
            }
            c.get(index3([e[0] as u8, e[1] as u8, e[2] as u8])).copied().unwrap_or(0.0)
        };
        let plus = |b: [usize; 3], i: usize, j: Option<usize>| {
            let mut f = b;
            f[i] += 1;
            if let Some(j) = j {
                f[j] += 1;
            }
            f
        };
        let mut t = Tables {
            value_gradient: [[0.0; 4]; MAX_GRADIENT_MONOMIALS],
            hessian: [[[0.0; 4]; 2]; MAX_HESSIAN_MONOMIALS],
            tail: [[0.0; 4]; MAX_FOLDED_ROWS],
        };
        // Coefficient of u^b in ∂ᵢp.
        let grad_of = |b: [usize; 3], i: usize| (b[i] + 1) as Real * coef_of(plus(b, i, None));
        let d = degree as Real;
        // rᵢ = Σₖ (D − 1 − k)/(D − 1) (∂ᵢp)ₖ: the weight of a row of degree |b| (D ≥ 2).
        let r_weight = |b: [usize; 3]| (d - 1.0 - (b[0] + b[1] + b[2]) as Real) / (d - 1.0);
        for (k, b) in horner_exponents(degree.saturating_sub(1)).into_iter().enumerate() {
            // s = Σₖ (D − k)/D pₖ (the constant itself at D = 0).
            let weight = if degree == 0 { 1.0 } else { (d - (b[0] + b[1] + b[2]) as Real) / d };
            t.value_gradient[k] = [weight * coef_of(b), grad_of(b, 0), grad_of(b, 1), grad_of(b, 2)];
        }
        if degree >= 2 {
            for (k, b) in horner_exponents(degree - 2).into_iter().enumerate() {
                let mut h = [0.0; 6];
                for (l, (i, j)) in [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)].into_iter().enumerate() {
                    let factor = if i == j { (b[i] + 1) * (b[i] + 2) } else { (b[i] + 1) * (b[j] + 1) };
                    h[l] = factor as Real * coef_of(plus(b, i, Some(j)));
                }
                let rw = r_weight(b);
                t.hessian[k] = [[h[0], h[1], h[2], h[3]], [h[4], h[5], rw * grad_of(b, 0), rw * grad_of(b, 1)]];
            }
            // [r_z, w] at (a, b, c) (zero beyond degree D − 2), folded in x.
            let tail_of = |b: [usize; 3]| -> [Real; 2] {
                if b.iter().sum::<usize>() > degree - 2 {
                    return [0.0; 2];
                }
                let k_b = (b[0] + b[1] + b[2]) as Real;
                let ww = (d - 1.0 - k_b) * (d - k_b) / (d * (d - 1.0));
                [r_weight(b) * grad_of(b, 2), ww * coef_of(b)]
            };
            for (k, b) in fold_exponents(degree - 2).into_iter().enumerate() {
                let (even, odd) = (tail_of(b), tail_of(plus(b, 0, None)));
                t.tail[k] = [even[0], even[1], odd[0], odd[1]];
            }
        }
        Self { degree, len, tables: Box::new(t) }
    }

    /// Total degree bound 2d.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Number of monomials N = C(2d + 3, 3).
    pub fn len(&self) -> usize {
        self.len
    }

    /// True for an empty basis (never for a valid polynomial: N ≥ 1).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// p(u).
    #[inline]
    pub fn value(&self, u: &Vector3) -> Real {
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::value(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, value_kernel::<Portable>((), &self.tables, u))
    }

    /// p(u) and ∇p(u).
    #[inline]
    pub fn value_gradient(&self, u: &Vector3) -> (Real, Vector3) {
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::value_gradient(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, gradient_kernel::<Portable>((), &self.tables, u))
    }

    /// p(u), ∇p(u) and ∇²p(u) in one pass.
    #[inline]
    pub fn eval(&self, u: &Vector3) -> Eval {
        self.eval_sym(u).into()
    }

    /// [`Self::eval`] with the Hessian's upper triangle (the query solvers' form).
    #[inline]
    pub fn eval_sym(&self, u: &Vector3) -> SymEval {
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::eval(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, full_kernel::<Portable>((), &self.tables, u))
    }

    /// [`Self::value`] through the AVX2 + FMA kernel, without the run-time check: for the query
    /// solvers' AVX2 builds, which made that check once per solve (`cpu` is its proof).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub fn value_avx2(&self, cpu: Avx2Fma, u: &Vector3) -> Real {
        let _ = cpu;
        // SAFETY: `cpu` proves the CPU runs AVX2 and FMA.
        unsafe { x86::value(self.degree, &self.tables, u) }
    }

    /// [`Self::value_gradient`] through the AVX2 + FMA kernel, without the run-time check.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub fn value_gradient_avx2(&self, cpu: Avx2Fma, u: &Vector3) -> (Real, Vector3) {
        let _ = cpu;
        // SAFETY: `cpu` proves the CPU runs AVX2 and FMA.
        unsafe { x86::value_gradient(self.degree, &self.tables, u) }
    }

    /// [`Self::eval_sym`] through the AVX2 + FMA kernel, without the run-time check.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub fn eval_sym_avx2(&self, cpu: Avx2Fma, u: &Vector3) -> SymEval {
        let _ = cpu;
        // SAFETY: `cpu` proves the CPU runs AVX2 and FMA.
        unsafe { x86::eval(self.degree, &self.tables, u) }
    }

    /// The portable kernels (no AVX2 / FMA) whatever the CPU: value, value and gradient, and the
    /// full evaluation. The reference the AVX2 + FMA build is tested against.
    pub fn eval_portable(&self, u: &Vector3) -> (Real, (Real, Vector3), Eval) {
        (
            dispatch!(self.degree, value_kernel::<Portable>((), &self.tables, u)),
            dispatch!(self.degree, gradient_kernel::<Portable>((), &self.tables, u)),
            dispatch!(self.degree, full_kernel::<Portable>((), &self.tables, u)).into(),
        )
    }
}

#[cfg(test)]
mod tests;
