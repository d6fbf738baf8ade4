//! Four- and eight-point evaluation tables ([`SoaPoly`]): the kernels of the batch solvers.

use super::*;

/// Quantities per row of a [`SoaPoly`]: [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, r_x, r_y, r_z, w].
pub(super) const SOA_WIDTH: usize = 10;

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
/// solver (`sublevel_query::batch`, four pairs of one body pair per pass). Each row (degree
/// ≤ 2d − 2, Horner order) holds the ten quantities of [`FastPoly`]'s Euler scheme; a pass
/// multiplies each coefficient into four points at once, so the same multiply–adds serve four
/// points and the Euler combination runs four points per instruction (AVX2 + FMA; elsewhere, and
/// below 2d = 2, one [`FastPoly::eval`] per point). The coefficients are stored replicated, so
/// that each is the memory operand of its multiply–add (AVX2 has no broadcast operand): four times
/// up to 2d = 6 ([`WideRow`], one point per lane), twice above ([`PairRow`], two points of two
/// quantities per register), where four copies no longer fit the first-level cache
/// ([`WIDE_MAX_ROWS`]).
///
/// Per point (`kernel_timing`, independent points) against [`FastPoly::eval`] one point at a time:
/// 6.5 vs 8.4 ns at 2d = 2, 10.6 vs 14.5 at 2d = 4, 22.3 vs 32.2 at 2d = 6 (at the floor of the
/// two FMA units: 350 four-lane multiply–adds per pass of four points). At 2d = 8 the pair table
/// takes about 0.7 of the time of a table with one copy of each coefficient broadcast before each
/// multiply–add; at 2d = 4 and 6 the two run alike, and the replicated table is kept there.
///
/// A third table holds the rows rounded to `f32` for [`SoaPoly::eval4_rows_f32`] (the batch
/// solver's coarse stage): 13 KB per body at 2d = 8.
#[derive(Clone, Debug)]
pub struct SoaPoly {
    fast: FastPoly,
    pub(super) table: SoaTable,
    /// The rows rounded to single precision, in pairs ([`PairRow32`]).
    single: Vec<PairRow32>,
}

/// The rows of a [`SoaPoly`] in the layout its kernel reads.
#[derive(Clone, Debug)]
pub(super) enum SoaTable {
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
pub(super) struct PairRow(pub(super) [[Real; 4]; SOA_WIDTH / 2]);

/// A [`SoaPoly`] row in single precision as five pairs of quantities, `[c₀ ×4, c₁ ×4]`,
/// `[c₂ ×4, c₃ ×4]`, … (160 bytes, each entry on a 32-byte boundary): the memory operand of an
/// eight-lane `f32` multiply–add over four points of two quantities ([`SoaPoly::eval4_rows_f32`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct PairRow32(pub(super) [[f32; 8]; SOA_WIDTH / 2]);

/// A [`SoaPoly`] row with each of its ten coefficients replicated into four lanes (320 bytes,
/// each entry on a 32-byte boundary): the four-lane memory operand of a multiply–add.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct WideRow(pub(super) [[Real; 4]; SOA_WIDTH]);

/// Most rows of a replicated table ([`WideRow`]): the 35 rows of 2d = 6 (11 KB; 2d ≤ 6). Larger
/// tables are stored in pairs ([`PairRow`]).
///
/// At 2d = 6 the replicated table makes the kernel about 10 % faster than a broadcast table
/// (22.3 against 24.6 ns per point) and a 300-pair batch about 5 % faster. At 2d = 8 its 84 rows
/// would take 27 KB per body: two bodies no longer fit the 32 KB first-level data cache, and the
/// batch runs about 12 % slower than from a table stored once.
pub(super) const WIDE_MAX_ROWS: usize = 35;

/// The rows of a [`SoaPoly`] (degree ≤ 2d − 2, Horner order; none below 2d = 2): the ten
/// quantities [∂ₓₓp, ∂ₓᵧp, ∂ₓ_zp, ∂ᵧᵧp, ∂ᵧ_zp, ∂_z_zp, r_x, r_y, r_z, w] of each monomial.
pub(super) fn soa_rows(fast: &FastPoly) -> Vec<[Real; SOA_WIDTH]> {
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
pub(super) fn wide_table(rows: &[[Real; SOA_WIDTH]]) -> Vec<WideRow> {
    rows.iter().map(|r| WideRow(r.map(|c| [c; 4]))).collect()
}

/// `rows` rounded to `f32`, as pairs of quantities, each coefficient replicated four times
/// ([`PairRow32`]).
pub(super) fn pair32_table(rows: &[[Real; SOA_WIDTH]]) -> Vec<PairRow32> {
    rows.iter().map(|r| PairRow32(std::array::from_fn(|k| std::array::from_fn(|i| r[2 * k + i / 4] as f32)))).collect()
}

/// `rows` as pairs of quantities, each coefficient replicated twice ([`PairRow`]).
pub(super) fn pair_table(rows: &[[Real; SOA_WIDTH]]) -> Vec<PairRow> {
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
    /// (`sublevel_query::batch`), never for an answer. Elsewhere than on AVX2 + FMA, two
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
    /// (the layout of the batch solvers' lanes, `sublevel_query::batch`).
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
