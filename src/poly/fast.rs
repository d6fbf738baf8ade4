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
//! Cost at 2d = 6, measured with callgrind (instructions per evaluation; in parentheses the
//! previous kernels over `[f64; L]` left to LLVM's vectorizers, which split the Hessian passes into
//! scalar chains and `vmovsd`/`vmovhpd` pairs): value 116 (129), value + gradient 118 (132), value +
//! gradient + Hessian 220 (439). At 2d = 4: 56 (65), 58 (68), 96 (176); at 2d = 8: 208 (225), 210
//! (228), 431 (952). Before these, a kernel that summed table rows against the monomial vector took
//! 244, 410 and 574 at 2d = 6. The kernels' time follows their count of multiply–adds (a chain of
//! dependent evaluations runs almost as fast as independent ones), so Euler's identity, which
//! drops the rows of the top one or two degrees for a few scalar operations, buys time: a full
//! evaluation at 2d = 6 went from 154 multiply–adds (84 value + gradient rows of degree ≤ 6, 35 +
//! 35 Hessian rows) to 92 (35 + 35 rows of degree ≤ 4, and the [r_z, w] table folded in x to 22
//! four-lane rows), at 2d = 8 from 333 to 218; a value + gradient evaluation from 84 to 56 rows
//! (165 to 120). The value runs the value + gradient scheme (a 4-lane FMA is one instruction, like
//! a scalar one).
//!
//! The two Hessian tables are one table of paired rows read by one pass (`Two`): two independent
//! chains side by side. Measured on this project's machine (AMD EPYC Zen 3 at ~3.2 GHz, the
//! `kernel_timing` example; independent evaluations, medians of three rounds): a full
//! evaluation 81 → 73 ns at 2d = 8, 38.8 → 39.5 ns at 2d = 6 (no change), bit-identical answers;
//! the cold distance query 2–3 % faster at 2d = 4, 6, 8. That is about 1.35 cycles per
//! multiply–add at 2d = 6, where the FMA units peak at 0.5 and their latency is 4 (a synthetic loop
//! on the same machine): neither bound alone, and more rows always cost more — the value +
//! gradient pass split the same way into its even and odd powers of x (68 rows instead of 56, two
//! chains) ran 28 % slower (29 → 37 ns), and dropping the scheduling barriers moved a full
//! evaluation to 42 ns and a value + gradient one to 27 ns.

use super::monomial::{basis_len, index3};
use super::polynomial::{Polynomial, MAX_DEGREE};
use crate::math::{Real, Sym3, Vector3};

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
/// aligns a box to 16 bytes only, and a table at 16 mod 32 splits every other row load in two:
/// measured on this project's machine (`kernel_timing`, the same binary with and without the
/// alignment, medians of three rounds), a full evaluation took 39.8 → 32.2 ns at 2d = 6 and
/// 73.1 → 54.7 ns at 2d = 8, a value + gradient one 28.8 → 23.4 and 48.3 → 39.4 ns; a synthetic C
/// kernel of the same shape ran 18.5 ns from an aligned table and 28.1 ns from one offset by 8 or
/// 16 bytes. Before, which bodies paid it depended on where the allocator put their tables.
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
/// ([`FastPoly::eval`] returns the same as a [`super::Eval`], with the full Hessian).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SymEval {
    /// p(u).
    pub value: Real,
    /// ∇p(u).
    pub gradient: Vector3,
    /// ∇²p(u), upper triangle.
    pub hessian: Sym3,
}

impl From<SymEval> for super::Eval {
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

/// The kernels compiled for AVX2 + FMA (x86-64-v3) over `__m256d` / `__m128d` accumulators.
/// Callers must have checked [`has_fma`].
#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::*;
    use std::arch::asm;
    use std::arch::x86_64::{
        __m256, __m256d, _mm256_castps256_ps128, _mm256_cvtpd_ps, _mm256_cvtps_pd, _mm256_extractf128_ps,
        _mm256_fmadd_pd, _mm256_fmadd_ps, _mm256_load_pd, _mm256_load_ps, _mm256_loadu_pd, _mm256_loadu_ps,
        _mm256_mul_pd, _mm256_permute2f128_pd, _mm256_permute2f128_ps, _mm256_permute4x64_pd, _mm256_set1_pd,
        _mm256_set1_ps, _mm256_set_m128, _mm256_storeu_pd, _mm256_storeu_ps, _mm256_sub_pd,
    };

    /// Proof that the CPU runs AVX2 and FMA: its only constructor is compiled with those features,
    /// so safe code can only call it from code that is itself only run on such a CPU.
    #[derive(Clone, Copy)]
    struct Avx2Fma(());

    impl Avx2Fma {
        /// The proof (callable only where AVX2 and FMA are enabled).
        #[target_feature(enable = "avx2,fma")]
        fn new() -> Self {
            Self(())
        }
    }

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
        dispatch!(d, value_kernel::<F64x4>(Avx2Fma::new(), t, u))
    }

    /// p(u) and ∇p(u) for degree `d` (0..=8).
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn value_gradient(d: usize, t: &Tables, u: &Vector3) -> (Real, Vector3) {
        dispatch!(d, gradient_kernel::<F64x4>(Avx2Fma::new(), t, u))
    }

    /// p(u), ∇p(u) and ∇²p(u) for degree `d` (0..=8).
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn eval(d: usize, t: &Tables, u: &Vector3) -> SymEval {
        dispatch!(d, full_kernel::<F64x4>(Avx2Fma::new(), t, u))
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
        /// instruction per quantity instead of a broadcast and a multiply–add (the broadcast table
        /// it replaced). With no broadcast registers a pass of four quantities fits the 16 AVX
        /// registers (12 accumulators and the three coordinates): passes of 4, 3, 3 quantities ran
        /// as fast as 3, 3, 2, 2 (22.2 vs 22.3 ns per point at 2d = 6) with one pass fewer.
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
        four_point!(d, wide_kernel(Avx2Fma::new(), rows, u))
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
        four_point!(d, pair_kernel(Avx2Fma::new(), rows, u))
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
        four_point!(d, pair32_kernel(Avx2Fma::new(), rows, u))
    }

    /// The Horner sums of the five quantity pairs of a single-precision pair table at four points
    /// (`q`: each coordinate twice, [`Coord32`]): the passes of [`SoaPoly::eval4_rows_f32`], three
    /// and two quantity pairs ([`Pair32Acc`]). Not inlined: inlined twice into one kernel, LLVM
    /// interleaves the two groups' passes beyond the 16 AVX registers and spills (the batch ran
    /// 15–30 % slower so).
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn pair32_sums<const D: usize>(rows: &[PairRow32], q: &Point<Coord32>) -> [__m256; 5] {
        let cpu = Avx2Fma::new();
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
        four_point!(d, pair32x8_kernel(Avx2Fma::new(), rows, u))
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
            let g = [
                _mm256_fmadd_pd(hu[0], k1, hi[1]),
                _mm256_fmadd_pd(hu[1], k1, hi[2]),
                _mm256_fmadd_pd(hu[2], k1, hi[3]),
            ];
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
}

/// Quantities per row of a [`SoaPoly`]: [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, r_x, r_y, r_z, w].
const SOA_WIDTH: usize = 10;

/// p, ∇p and ∇²p at four points, one array entry per point (structure of arrays).
#[derive(Clone, Copy, Debug, Default)]
pub struct Soa4Eval {
    /// p at each point.
    pub value: [Real; 4],
    /// ∂ₓp, ∂ᵧp, ∂_zp, each at the four points.
    pub gradient: [[Real; 4]; 3],
    /// ∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, each at the four points.
    pub hessian: [[Real; 4]; 6],
}

/// p, ∇p and ∇²p at eight points in single precision, one array entry per point (structure of
/// arrays): [`SoaPoly::eval8_rows_f32`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Soa8Eval32 {
    /// p at each point.
    pub value: [f32; 8],
    /// ∂ₓp, ∂ᵧp, ∂_zp, each at the eight points.
    pub gradient: [[f32; 8]; 3],
    /// ∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, each at the eight points.
    pub hessian: [[f32; 8]; 6],
}

/// A polynomial's full-evaluation table laid out for four points per pass: the kernel of the batch
/// solver ([`crate::query::batch`], four pairs of one body pair per pass). Each row (degree
/// ≤ 2d − 2, Horner order) holds the ten quantities of [`FastPoly`]'s Euler scheme; a pass
/// multiplies each coefficient into four points at once, so the same multiply–adds serve four
/// points and the Euler combination runs four points per instruction (AVX2 + FMA; elsewhere, and
/// below 2d = 2, one [`FastPoly::eval`] per point). The coefficients are stored replicated, so
/// that each is the memory operand of its multiply–add (AVX2 has no broadcast operand): four times
/// up to 2d = 6 ([`WideRow`], one point per lane), twice above ([`PairRow`], two points of two
/// quantities per register), where four copies no longer fit the first-level cache
/// ([`WIDE_MAX_ROWS`]).
///
/// Measured per point on this project's machine (`examples/kernel_timing`, AMD EPYC Zen 3,
/// independent points, medians of three rounds), against [`FastPoly::eval`] one point at a time:
/// 6.5 vs 8.4 ns at 2d = 2, 10.6 vs 14.5 at 2d = 4, 22.3 vs 32.2 at 2d = 6 (at the floor of the
/// two FMA units: 350 four-lane multiply–adds per pass of four points). At 2d = 8 the table these
/// replaced, one copy of each coefficient broadcast before each multiply–add, ran 48.2 vs 54.8 ns
/// in a quiet hour: twice the instructions per row of the one-point kernel. The pair table at
/// 2d = 8, alternated with that build ten times on a loaded host (issue 15's seventh session): a
/// median of 60.1 against 85.4 ns per point (fastest runs 43.6 and 50.8 ns, run-by-run ratio
/// 0.72), and at 2d = 4 and 6 the pair table ran as fast as the replicated one (ratios 1.03 and
/// 0.96, within the noise), so those keep it.
///
/// A third table holds the rows rounded to `f32` for [`SoaPoly::eval4_rows_f32`] (the batch
/// solver's coarse stage): 13 KB per body at 2d = 8.
#[derive(Clone, Debug)]
pub struct SoaPoly {
    fast: FastPoly,
    table: SoaTable,
    /// The rows rounded to single precision, in pairs ([`PairRow32`]).
    single: Vec<PairRow32>,
}

/// The rows of a [`SoaPoly`] in the layout its kernel reads.
#[derive(Clone, Debug)]
enum SoaTable {
    /// Every coefficient replicated into four lanes, when that table is small enough to stay in
    /// the first-level cache beside the other body's ([`WIDE_MAX_ROWS`]).
    Wide(Vec<WideRow>),
    /// The quantities in pairs, each coefficient replicated twice ([`PairRow`]), for larger tables.
    Pair(Vec<PairRow>),
}

/// A [`SoaPoly`] row as five pairs of quantities, `[c₀, c₀, c₁, c₁]`, `[c₂, c₂, c₃, c₃]`, …
/// (160 bytes, each entry on a 32-byte boundary): the memory operand of a multiply–add over two
/// points of two quantities each, at half the replicated table's size ([`WideRow`]): 13 KB per
/// body at 2d = 8, so two bodies share the 32 KB first-level data cache.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct PairRow([[Real; 4]; SOA_WIDTH / 2]);

/// A [`SoaPoly`] row in single precision as five pairs of quantities, `[c₀ ×4, c₁ ×4]`,
/// `[c₂ ×4, c₃ ×4]`, … (160 bytes, each entry on a 32-byte boundary): the memory operand of an
/// eight-lane `f32` multiply–add over four points of two quantities ([`SoaPoly::eval4_rows_f32`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct PairRow32([[f32; 8]; SOA_WIDTH / 2]);

/// A [`SoaPoly`] row with each of its ten coefficients replicated into four lanes (320 bytes,
/// each entry on a 32-byte boundary): the four-lane memory operand of a multiply–add.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(crate) struct WideRow([[Real; 4]; SOA_WIDTH]);

/// Most rows of a replicated table ([`WideRow`]): the 35 rows of 2d = 6 (11 KB; 2d ≤ 6). Larger
/// tables are stored in pairs ([`PairRow`]).
///
/// Measured on this project's machine (`examples/kernel_timing`, `examples/cold_profile D 20
/// batch`, the two tables alternated in one session): at 2d = 6, 22.3 instead of 24.6 ns per
/// point for the kernel against the broadcast table and a 300-pair batch about 5 % faster (1.37
/// vs 1.45 µs per pair on a loaded host). At 2d = 8 the 84 rows take 27 KB per body: two bodies
/// no longer fit the 32 KB first-level data cache, and the batch ran 12 % slower than from the
/// broadcast table (1.75 vs 1.54 µs per pair).
const WIDE_MAX_ROWS: usize = 35;

/// The rows of a [`SoaPoly`] (degree ≤ 2d − 2, Horner order; none below 2d = 2): the ten
/// quantities [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, r_x, r_y, r_z, w] of each monomial.
fn soa_rows(fast: &FastPoly) -> Vec<[Real; SOA_WIDTH]> {
    let d = fast.degree;
    let mut rows = Vec::new();
    if d >= 2 {
        let folded = fold_exponents(d - 2);
        for (k, e) in horner_exponents(d - 2).into_iter().enumerate() {
            let [h, m] = fast.tables.hessian[k];
            // [r_z, w] of (a, b, c): the even half of the folded row of (a, b, c) or the odd
            // half of the row of (a − 1, b, c).
            let even = e[0] % 2 == 0;
            let key = if even { e } else { [e[0] - 1, e[1], e[2]] };
            let f = folded.iter().position(|g| *g == key).map_or([0.0; 4], |i| fast.tables.tail[i]);
            let (rz, w) = if even { (f[0], f[1]) } else { (f[2], f[3]) };
            rows.push([h[0], h[1], h[2], h[3], m[0], m[1], m[2], m[3], rz, w]);
        }
    }
    rows
}

/// `rows` with every coefficient replicated four times ([`WideRow`]).
fn wide_table(rows: &[[Real; SOA_WIDTH]]) -> Vec<WideRow> {
    rows.iter().map(|r| WideRow(r.map(|c| [c; 4]))).collect()
}

/// `rows` rounded to `f32`, as pairs of quantities, each coefficient replicated four times
/// ([`PairRow32`]).
fn pair32_table(rows: &[[Real; SOA_WIDTH]]) -> Vec<PairRow32> {
    rows.iter().map(|r| PairRow32(std::array::from_fn(|k| std::array::from_fn(|i| r[2 * k + i / 4] as f32)))).collect()
}

/// `rows` as pairs of quantities, each coefficient replicated twice ([`PairRow`]).
fn pair_table(rows: &[[Real; SOA_WIDTH]]) -> Vec<PairRow> {
    rows.iter().map(|r| PairRow(std::array::from_fn(|k| [r[2 * k], r[2 * k], r[2 * k + 1], r[2 * k + 1]]))).collect()
}

impl SoaPoly {
    /// The four-point table of `fast` (same polynomial).
    pub fn new(fast: &FastPoly) -> Self {
        let rows = soa_rows(fast);
        let table = if rows.len() <= WIDE_MAX_ROWS {
            SoaTable::Wide(wide_table(&rows))
        } else {
            SoaTable::Pair(pair_table(&rows))
        };
        Self { fast: fast.clone(), table, single: pair32_table(&rows) }
    }

    /// [`SoaPoly::eval4_rows`] in single precision: the coefficients and the points rounded to
    /// `f32`, the Horner sums run in eight-lane `f32` registers (two quantities of four points per
    /// multiply–add: half the multiply–adds), then widened for Euler's identity. Relative errors of
    /// order 10⁻⁶ (the tables' `f32` rounding times their cancellation): for Newton steps far from
    /// the answer, never for an answer (the batch solver's coarse stage runs the same sums eight
    /// points at a time, [`SoaPoly::eval8_rows_f32`]; `examples/kernel_timing` times and checks
    /// this one). Elsewhere than on AVX2 + FMA, the double-precision [`SoaPoly::eval4_rows`].
    pub fn eval4_rows_f32(&self, u: &[[Real; 4]; 3]) -> Soa4Eval {
        #[cfg(target_arch = "x86_64")]
        if self.fast.degree >= 2 && has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::eval4_pair32(self.fast.degree, &self.single, u) };
        }
        self.eval4_rows(u)
    }

    /// p, ∇p and ∇²p at the eight points `u` (normalized coordinates, `u[i]`: coordinate i of
    /// each point) in single precision throughout: the single-precision table's Horner sums for
    /// two groups of four points per eight-lane multiply–add (the multiply–adds of
    /// [`SoaPoly::eval4_rows_f32`] per point), Euler's identity in eight `f32` lanes. Relative
    /// errors of order 10⁻⁶–10⁻⁵ on the project's bodies: for the batch solver's coarse stage
    /// ([`crate::query::batch`]), never for an answer. Elsewhere than on AVX2 + FMA, two
    /// double-precision [`SoaPoly::eval4_rows`] rounded to `f32`.
    pub fn eval8_rows_f32(&self, u: &[[f32; 8]; 3]) -> Soa8Eval32 {
        #[cfg(target_arch = "x86_64")]
        if self.fast.degree >= 2 && has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::eval8_pair32(self.fast.degree, &self.single, u) };
        }
        let mut out = Soa8Eval32::default();
        for half in 0..2 {
            let e = self.eval4_rows(&std::array::from_fn(|c| std::array::from_fn(|i| u[c][4 * half + i].into())));
            for i in 0..4 {
                out.value[4 * half + i] = e.value[i] as f32;
                for c in 0..3 {
                    out.gradient[c][4 * half + i] = e.gradient[c][i] as f32;
                }
                for c in 0..6 {
                    out.hessian[c][4 * half + i] = e.hessian[c][i] as f32;
                }
            }
        }
        out
    }

    /// p, ∇p and ∇²p at the four points `u` (normalized coordinates).
    pub fn eval4(&self, u: &[Vector3; 4]) -> Soa4Eval {
        self.eval4_rows(&std::array::from_fn(|i| [u[0][i], u[1][i], u[2][i], u[3][i]]))
    }

    /// [`SoaPoly::eval4`] with the points' coordinates by rows: `u[i][k]` is coordinate i of point k
    /// (the layout of the batch solvers' lanes, [`crate::query::batch`]).
    pub fn eval4_rows(&self, u: &[[Real; 4]; 3]) -> Soa4Eval {
        #[cfg(target_arch = "x86_64")]
        if self.fast.degree >= 2 && has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe {
                match &self.table {
                    SoaTable::Wide(rows) => x86::eval4_wide(self.fast.degree, rows, u),
                    SoaTable::Pair(rows) => x86::eval4_pair(self.fast.degree, rows, u),
                }
            };
        }
        let mut out = Soa4Eval::default();
        for (i, value) in out.value.iter_mut().enumerate() {
            let e = self.fast.eval_sym(&Vector3::new(u[0][i], u[1][i], u[2][i]));
            *value = e.value;
            for j in 0..3 {
                out.gradient[j][i] = e.gradient[j];
            }
            for j in 0..6 {
                out.hessian[j][i] = e.hessian.0[j];
            }
        }
        out
    }
}

/// Whether this CPU runs the AVX2 + FMA kernels ([`crate::math::cpu_has_avx2_fma`], the check the
/// query solvers' builds use too).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn has_fma() -> bool {
    crate::math::cpu_has_avx2_fma()
}

impl FastPoly {
    /// Builds the derivative coefficient tables of `p` (degree ≤ 8; any degree the crate accepts).
    pub fn new(p: &Polynomial) -> Self {
        let degree = p.degree().min(MAX_DEGREE);
        let len = basis_len(3, degree);
        let c = p.coefficients();
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
    pub fn eval(&self, u: &Vector3) -> super::Eval {
        self.eval_sym(u).into()
    }

    /// [`Self::eval`] with the Hessian's upper triangle (the query solvers' form).
    #[inline]
    pub(crate) fn eval_sym(&self, u: &Vector3) -> SymEval {
        #[cfg(target_arch = "x86_64")]
        if has_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked at run time just above).
            return unsafe { x86::eval(self.degree, &self.tables, u) };
        }
        dispatch!(self.degree, full_kernel::<Portable>((), &self.tables, u))
    }

    /// [`Self::value`] through the AVX2 + FMA kernel, without the run-time check: for the query
    /// solvers' AVX2 builds, which made that check once per solve.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`crate::math::cpu_has_avx2_fma`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn value_avx2(&self, u: &Vector3) -> Real {
        // SAFETY: the caller guarantees AVX2 and FMA.
        unsafe { x86::value(self.degree, &self.tables, u) }
    }

    /// [`Self::value_gradient`] through the AVX2 + FMA kernel, without the run-time check.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`crate::math::cpu_has_avx2_fma`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn value_gradient_avx2(&self, u: &Vector3) -> (Real, Vector3) {
        // SAFETY: the caller guarantees AVX2 and FMA.
        unsafe { x86::value_gradient(self.degree, &self.tables, u) }
    }

    /// [`Self::eval_sym`] through the AVX2 + FMA kernel, without the run-time check.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA ([`crate::math::cpu_has_avx2_fma`]).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn eval_sym_avx2(&self, u: &Vector3) -> SymEval {
        // SAFETY: the caller guarantees AVX2 and FMA.
        unsafe { x86::eval(self.degree, &self.tables, u) }
    }

    /// The portable kernels (no AVX2 / FMA), for tests of both code paths.
    #[cfg(test)]
    fn eval_portable(&self, u: &Vector3) -> (Real, (Real, Vector3), super::Eval) {
        (
            dispatch!(self.degree, value_kernel::<Portable>((), &self.tables, u)),
            dispatch!(self.degree, gradient_kernel::<Portable>((), &self.tables, u)),
            dispatch!(self.degree, full_kernel::<Portable>((), &self.tables, u)).into(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn horner_order_covers_the_basis_once() {
        for d in 0..=MAX_DEGREE {
            let e = horner_exponents(d);
            assert_eq!(e.len(), basis_len(3, d));
            let mut seen: Vec<usize> = e.iter().map(|e| index3([e[0] as u8, e[1] as u8, e[2] as u8])).collect();
            seen.sort_unstable();
            assert_eq!(seen, (0..basis_len(3, d)).collect::<Vec<_>>());
        }
    }

    #[test]
    fn folded_order_matches_the_folded_schemes() {
        // The row counts of `fold_0` … `fold_6`, and each row's odd partner (a + 1, b, c) is the
        // row of the same (b, c) one power of x up (zero beyond the degree).
        for (d, rows) in [1, 3, 7, 13, 22, 34, 50].into_iter().enumerate() {
            let e = fold_exponents(d);
            assert_eq!(e.len(), rows, "degree {d}");
            assert!(e.iter().all(|e| e[0] % 2 == 0 && e.iter().sum::<usize>() <= d));
        }
        assert_eq!(fold_exponents(6).len(), MAX_FOLDED_ROWS);
    }

    #[test]
    fn four_point_table_matches_reference_eval_at_every_degree() {
        // SoaPoly::eval4 against the reference evaluator (Polynomial::eval, the monomial sums) at
        // four random points per pass, every degree 0–8 (2d < 2 takes the one-point path).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for degree in 0..=MAX_DEGREE {
            let coeffs: Vec<Real> = (0..basis_len(3, degree)).map(|_| rng.random_range(-1.0..1.0)).collect();
            let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
            let soa = SoaPoly::new(&FastPoly::new(&p));
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
            let soa = SoaPoly::new(&FastPoly::new(&p));
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
        if has_fma() {
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
            let soa = SoaPoly::new(&FastPoly::new(&p));
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
    fn pair_table_gives_the_replicated_tables_answers_to_the_bit() {
        // Up to 2d = 6 the four-point kernel reads the replicated table, above it the pair table;
        // each quantity's Horner chain is the same sequence of fused multiply–adds over either, so
        // both give the same bits at every degree.
        if !has_fma() {
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for degree in 2..=MAX_DEGREE {
            let coeffs: Vec<Real> = (0..basis_len(3, degree)).map(|_| rng.random_range(-1.0..1.0)).collect();
            let fast = FastPoly::new(&Polynomial::from_coefficients(degree, coeffs).unwrap());
            let soa = SoaPoly::new(&fast);
            assert_eq!(matches!(soa.table, SoaTable::Pair(_)), degree > 6, "degree {degree}");
            let rows = soa_rows(&fast);
            let (wide, pair) = (wide_table(&rows), pair_table(&rows));
            let u: [[Real; 4]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.5..1.5)));
            // SAFETY: the CPU runs AVX2 and FMA (checked above).
            let (a, b) = unsafe { (x86::eval4_wide(degree, &wide, &u), x86::eval4_pair(degree, &pair, &u)) };
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "degree {degree}");
        }
    }

    #[test]
    fn fast_eval_matches_reference_eval_at_every_degree() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for degree in 0..=MAX_DEGREE {
            let n = basis_len(3, degree);
            let coeffs: Vec<Real> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let p = Polynomial::from_coefficients(degree, coeffs).unwrap();
            let f = FastPoly::new(&p);
            assert_eq!(f.len(), n);
            for _ in 0..20 {
                let u =
                    Vector3::new(rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5), rng.random_range(-1.5..1.5));
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
}
