//! The cone programs of every SDP fit of paper §III: objective log det or trace (of the inverse)
//! of the sos Gram matrix P (ours, eq. "VAG.log.det") or of the sos-convexity Gram matrix H
//! (Magnani et al., eq. "Magnani.log.det"), optionally with relaxed convexity (eq.
//! "VAG.param.convex": p + c(‖u‖²)ᵈ sos-convex, objective on P only). One builder,
//! [`LogDetProblem::build_spec`], serves all four objectives; the log det P program below is
//! its default case.
//!
//! ```text
//! objective block on X ∈ {P (N × N), H = G (M × M)}:
//!   log det X:      [[X, Z], [Zᵀ, diag Z]] ⪰ 0,  (tᵢ, 1, Zᵢᵢ) ∈ K_exp,  maximize Σ tᵢ
//!   trace X⁻¹:      [[V, I], [I, X]] ⪰ 0,  minimize trace V           (Schur: V ⪰ X⁻¹)
//! the other Gram matrix gets a plain PSD cone (G ⪰ 0, or P ⪰ 0 i.e. p sos for Magnani's forms)
//! relaxed convexity: the sos-convexity identities read yᵀ∇²p y − wᵀGw = −c yᵀ∇²q y, q = (‖u‖²)ᵈ
//! ```
//!
//! The log det P program in detail:
//!
//! ```text
//! maximize    log det P
//! subject to  p(x) = z(x)ᵀ P z(x),                      z = graded-lex monomials of degree ≤ d
//!             yᵀ ∇²p(x) y = w(x, y)ᵀ G w(x, y),  G ⪰ 0,  w = y ⊗ z_{d−1}(x)   (p sos-convex)
//!             p(uᵢ) ≤ 1                                  for every convex-hull vertex uᵢ
//! ```
//!
//! A convex sublevel set that contains the hull vertices contains the whole cloud, so only the
//! hull vertices become rows. `log det P` is written with Clarabel's PSD and exponential cones:
//!
//! ```text
//! [ P   Z       ]
//! [ Zᵀ  diag(Z) ] ⪰ 0,   Z lower triangular,   (tᵢ, 1, Zᵢᵢ) ∈ K_exp  (Zᵢᵢ ≥ exp(tᵢ)),   maximize Σ tᵢ
//! ```
//!
//! At the optimum `Σ tᵢ = log det P`. The big block already implies `P ⪰ 0`, so P has no cone of
//! its own. Clarabel's chordal decomposition splits the big block along its sparsity (the
//! diag Z corner) into cliques of size ≤ N + 1, so the dense 60 × 60 G cone dominates each
//! KKT factorization at 2d = 8.
//!
//! **No equality rows, no redundant columns.** The coefficient identities c_α = Σ (2 − δᵢⱼ)Pᵢⱼ
//! (one per monomial of degree ≤ 2d) and the sos-convexity identities (one per y-pair and
//! monomial of degree ≤ 2d − 2) are each solved for one entry of svec(P) or svec(G) (its pivot,
//! a diagonal entry when there is one): P and G are affine images of the columns
//! `free entries of P | Z | t | c | free entries of G`, written straight into the rows of their
//! cones. Compared with columns for every entry plus equality rows, this removes 165 + 504 rows
//! and as many columns at 2d = 8, and above all the coupling of the dense G block with the 504
//! equality rows in the factorization: 0.65 → 0.41 s per interior-point iteration on the chair.
//!
//! **Scaled monomial bases.** P, G and c are written in the bases u^α/σ_α, σ_α the root mean
//! square of u^α over the containment points (see `basis_scales`): log det changes by a
//! constant, the body not at all, but the Gram matrices at the optimum no longer span many
//! decades. In plain monomials the objective crept on for ~15 iterations after the gap was
//! small (chair 2d = 8: log det P 114.79–114.93 at "Solved" 1e-8 depending on settings, volume
//! off by 0.2–0.4 %); scaled, it settles to 7 digits (114.94358) in 21–23 iterations. Trace
//! objectives keep the plain basis for their objective matrix (trace X⁻¹ is not invariant under a
//! diagonal change of basis). G's cone holds G' − εI ([`CONVEXITY_FLOOR`]) so that the solver's
//! last residual cannot leave the certified convexity margin negative.
//!
//! Sizes (N = C(d+3, 3), M = 3·C(d+2, 3), L = C(2d+3, 3)):
//!
//! ```text
//! 2d   N    M   big block   G block   identities in P (L)   in G 6·C(2d+1, 3)   columns   rows
//!  2   4    3     8×8        3×3            10                     6                24     374
//!  4  10   12    20×20      12×12           35                    60               138     638
//!  6  20   30    40×40      30×30           84                   210               695    1665
//!  8  35   60    70×70      60×60          165                   504              2621    4740
//! ```
//! (rows with the chair's 320 hull vertices; the former layout with equality rows had 40 / 233 /
//! 989 / 3290 columns and 390 / 733 / 1959 / 5409 rows.)
//!
//! The problem is affine-invariant up to a constant in the objective (a translation or scaling of
//! x maps z(x) by a triangular / diagonal matrix of constant determinant), so normalizing the cloud
//! only improves conditioning; it does not change the fitted body.

use crate::math::{Real, Vector3};
use crate::poly::gram::{gram_weight, triangle_index, triangle_len, unpack_triangle};
use crate::poly::monomial::{basis_len, graded_exponents3, index3};
use crate::poly::Polynomial;
use crate::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultInfo, DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

/// Column layout and data of the cone program `min qᵀx s.t. b − A x ∈ K`.
#[derive(Debug)]
pub struct LogDetProblem {
    /// Half degree d (the body has degree 2d).
    pub half_degree: usize,
    /// Side N of the Gram matrix P.
    pub gram_size: usize,
    /// Side M of the sos-convexity Gram matrix G.
    pub convexity_gram_size: usize,
    /// First column of the free entries of svec(P) (Clarabel's packed triangle, off-diagonals
    /// × √2, scaled basis); use [`LogDetProblem::gram`] for P itself.
    pub col_p: usize,
    /// First column of the free entries of svec(G) (the last columns); use
    /// [`LogDetProblem::convexity_gram`] for G itself.
    pub col_g: usize,
    /// First column of the coefficients of p (graded lex, degree ≤ 2d), each times its scale τ_α.
    pub col_c: usize,
    /// Number of columns.
    pub num_vars: usize,
    q: Vec<Real>,
    a: CscMatrix<Real>,
    b: Vec<Real>,
    cones: Vec<SupportedConeT<Real>>,
    /// svec(G) as affine functions of the columns (the sos-convexity identities solved for one
    /// entry each).
    gram_image: Vec<AffineEntry>,
    /// svec(P) as affine functions of the columns (the coefficient identities solved for one
    /// entry each).
    p_image: Vec<AffineEntry>,
    /// Scales σ of the half-basis monomials (P's basis is z/σ).
    scale_p: Vec<Real>,
    /// Scales σ of the degree ≤ d − 1 monomials (G's basis is y ⊗ z_{d−1}/σ).
    scale_g: Vec<Real>,
}

/// Triplet accumulator for `b − A x ∈ K`, rows appended cone by cone.
#[derive(Default)]
struct Rows {
    ii: Vec<usize>,
    jj: Vec<usize>,
    vv: Vec<Real>,
    b: Vec<Real>,
    cones: Vec<SupportedConeT<Real>>,
}

impl Rows {
    fn next_row(&self) -> usize {
        self.b.len()
    }
    fn push(&mut self, row: usize, col: usize, v: Real) {
        if v != 0.0 {
            self.ii.push(row);
            self.jj.push(col);
            self.vv.push(v);
        }
    }
    /// Row `row` of a cone block holding the value of `entry` (slack s = b − A x = entry): pushes
    /// −coefficient for every term and returns the constant, the row's share of b.
    fn push_affine(&mut self, row: usize, entry: &AffineEntry) -> Real {
        for &(col, coef) in &entry.terms {
            self.push(row, col, -coef);
        }
        entry.constant
    }
}

/// Smallest eigenvalue the program requires of the sos-convexity Gram matrix G' (scaled basis,
/// see [`basis_scales`]; G = Σ⁻¹G'Σ⁻¹ with σ ≤ 1 on the unit ball, so λ_min(G) ≥ this too). A
/// floor of 10⁻⁶ keeps the certified convexity margin positive after the solver's last residual
/// (about 10⁻⁹ in G', up to −5·10⁻⁷ in G at 2d = 8 without it) and moves the body by ~10⁻⁶.
pub const CONVEXITY_FLOOR: Real = 1e-6;

/// Scales σ_α of the monomials u^α of a Gram basis: their root mean square over `points` (the
/// containment points, normalized coordinates), or 1 when `identity` is set (trace objectives:
/// trace X⁻¹ is not invariant under a diagonal change of basis), when there are no points or
/// the mean is not positive. The fit writes P and G in the basis u^α/σ_α: log det changes by a
/// constant, the body not at all, but the Gram matrices at the optimum have entries of order one
/// instead of spanning many decades (on the unit ball, u^α of degree 4 is ~10⁻² on the cloud).
fn basis_scales(exponents: &[[u8; 3]], points: &[Vector3], identity: bool) -> Vec<Real> {
    exponents
        .iter()
        .map(|e| {
            if identity || points.is_empty() {
                return 1.0;
            }
            let mean = points
                .iter()
                .map(|u| (u.x.powi(e[0] as i32) * u.y.powi(e[1] as i32) * u.z.powi(e[2] as i32)).powi(2))
                .sum::<Real>()
                / points.len() as Real;
            if mean.is_finite() && mean > 1e-300 {
                mean.sqrt()
            } else {
                1.0
            }
        })
        .collect()
}

/// X = Σ⁻¹ X' Σ⁻¹ for the Gram matrix X' in the scaled basis z/σ.
fn unscale(mut scaled: nalgebra::DMatrix<Real>, scales: &[Real]) -> nalgebra::DMatrix<Real> {
    for j in 0..scaled.ncols() {
        for i in 0..scaled.nrows() {
            scaled[(i, j)] /= scales[i] * scales[j];
        }
    }
    scaled
}

/// Values of affine entries at x.
fn evaluate(entries: &[AffineEntry], x: &[Real]) -> Vec<Real> {
    entries.iter().map(|e| e.constant + e.terms.iter().map(|&(col, coef)| coef * x[col]).sum::<Real>()).collect()
}

/// Solves linear identities `Σ_{e ∈ group} w_e·svec(X)_e = known(group)` (group entries given as
/// (svec index, w_e, on the diagonal)) for one entry of each group (its pivot: a diagonal entry
/// when the group has one), returning every entry
/// of svec(X) (length `len`) as an affine function of the columns: the other entries become
/// free columns numbered from `first_col` in group order, and `known(g)` gives the right side of
/// group g as (terms, constant). Every entry must belong to exactly one group.
fn solve_identities(
    groups: &[Vec<(usize, Real, bool)>],
    len: usize,
    first_col: usize,
    known: impl Fn(usize) -> (Vec<(usize, Real)>, Real),
) -> Vec<AffineEntry> {
    let mut image = vec![AffineEntry::default(); len];
    let mut next = first_col;
    for (g, group) in groups.iter().enumerate() {
        let Some(&(pivot, w_pivot, _)) = group.iter().find(|(_, _, diagonal)| *diagonal).or(group.first()) else {
            continue;
        };
        let (terms, constant) = known(g);
        let mut pivot_terms: Vec<(usize, Real)> = terms.into_iter().map(|(col, v)| (col, v / w_pivot)).collect();
        for &(e, w, _) in group.iter().filter(|(e, _, _)| *e != pivot) {
            image[e] = AffineEntry { terms: vec![(next, 1.0)], constant: 0.0 };
            pivot_terms.push((next, -w / w_pivot));
            next += 1;
        }
        image[pivot] = AffineEntry { terms: pivot_terms, constant: constant / w_pivot };
    }
    image
}

/// One entry of a packed Gram matrix as an affine function of the columns: Σ coef·x[col] + constant.
#[derive(Clone, Debug, Default)]
struct AffineEntry {
    terms: Vec<(usize, Real)>,
    constant: Real,
}

/// Index of the unordered y-pair (k ≤ l) among (0,0), (0,1), (0,2), (1,1), (1,2), (2,2).
pub(crate) fn pair_index(k: usize, l: usize) -> usize {
    let (k, l) = if k <= l { (k, l) } else { (l, k) };
    match (k, l) {
        (0, 0) => 0,
        (0, 1) => 1,
        (0, 2) => 2,
        (1, 1) => 3,
        (1, 2) => 4,
        _ => 5,
    }
}

/// The objective of a fit (paper §III-A): log det or trace of the inverse of a Gram matrix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Objective {
    /// Maximize log det X through `[[X, Z], [Zᵀ, diag Z]] ⪰ 0` and exponential cones.
    LogDet,
    /// Minimize trace V with `[[V, I], [I, X]] ⪰ 0`, i.e. V ⪰ X⁻¹ (Schur complement).
    Trace,
}

/// Which Gram matrix the objective acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjectiveMatrix {
    /// The sos Gram matrix P of p = z(x)ᵀ P z(x) (N × N; eq. "VAG.log.det", ours).
    P,
    /// The sos-convexity Gram matrix H = G of yᵀ∇²p y = wᵀ H w (M × M; eq. "Magnani.log.det").
    H,
}

/// What to build: degree, objective × matrix, and the relaxed-convexity parameter c.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProblemSpec {
    /// Half degree d (the body has degree 2d), 1..=4.
    pub half_degree: usize,
    /// log det or trace.
    pub objective: Objective,
    /// P (ours) or H (Magnani et al.).
    pub matrix: ObjectiveMatrix,
    /// c ≥ 0 of eq. "VAG.param.convex": p + c(‖u‖²)ᵈ sos-convex instead of p, u normalized
    /// coordinates. Only with the objective on P.
    pub convexity_relaxation: Real,
    /// Basis in which a trace objective takes trace X⁻¹ (log det does not depend on it).
    pub trace_basis: TraceBasis,
}

/// The monomial basis of the trace objective trace X⁻¹ (not invariant under a diagonal change of
/// basis, unlike log det): the plain monomials u^α, or the monomials scaled by their root mean
/// square over the containment points (u^α/σ_α, the basis the program is written in). Neither is
/// tighter on every shape (Table 1 shapes: scaled is smaller at c = 0 on all ten 2d = 4/6 fits,
/// plain on four of five at 2d = 6, c = 10), so the fit solves both and keeps the smaller body
/// ([`crate::fit::FitSettings`], method `trace_p` / `trace_h`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TraceBasis {
    /// Plain monomials u^α.
    #[default]
    Plain,
    /// Monomials scaled by their RMS over the points.
    Scaled,
}

impl ProblemSpec {
    /// The log det P program of eq. "VAG.log.det" (c = 0).
    pub fn log_det_p(half_degree: usize) -> Self {
        Self {
            half_degree,
            objective: Objective::LogDet,
            matrix: ObjectiveMatrix::P,
            convexity_relaxation: 0.0,
            trace_basis: TraceBasis::Plain,
        }
    }
}

/// Coefficients of q(u) = (u₁² + u₂² + u₃²)ᵈ in the graded-lex basis of degree 2d (multinomial
/// theorem: q = Σ_{a+b+c=d} d!/(a! b! c!) u₁^{2a} u₂^{2b} u₃^{2c}).
pub fn norm_power_coefficients(d: usize) -> Vec<Real> {
    let fact = |k: usize| (1..=k).map(|v| v as Real).product::<Real>();
    let mut q = vec![0.0; basis_len(3, 2 * d)];
    for a in 0..=d {
        for b in 0..=d - a {
            let c = d - a - b;
            q[index3([2 * a as u8, 2 * b as u8, 2 * c as u8])] = fact(d) / (fact(a) * fact(b) * fact(c));
        }
    }
    q
}

/// p = z(x)ᵀ P z(x) expanded in the graded-lex basis of degree 2d, for a symmetric N × N matrix
/// P over the half basis z of degree ≤ d (exactly sos for P ⪰ 0).
///
/// # Errors
/// [`Error::Numerical`] when P has the wrong size or a coefficient is not finite.
pub fn polynomial_of_gram(half_degree: usize, p: &nalgebra::DMatrix<Real>) -> Result<Polynomial> {
    let half = graded_exponents3(half_degree);
    if p.nrows() != half.len() || p.ncols() != half.len() {
        return Err(Error::Numerical(format!(
            "Gram matrix is {}×{}, expected {}×{}",
            p.nrows(),
            p.ncols(),
            half.len(),
            half.len()
        )));
    }
    let mut c = vec![0.0; basis_len(3, 2 * half_degree)];
    for j in 0..half.len() {
        for i in 0..=j {
            let e = [half[i][0] + half[j][0], half[i][1] + half[j][1], half[i][2] + half[j][2]];
            c[index3(e)] += if i == j { 1.0 } else { 2.0 } * p[(i, j)];
        }
    }
    Polynomial::from_coefficients(2 * half_degree, c)
        .map_err(|e| Error::Numerical(format!("unusable Gram matrix: {e}")))
}

impl LogDetProblem {
    /// Builds the log det P program of eq. "VAG.log.det" for half degree `d ∈ 1..=4` and the
    /// normalized hull vertices `hull` (shorthand for [`LogDetProblem::build_spec`] with
    /// [`ProblemSpec::log_det_p`]).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree` when `d` is outside 1..=4.
    pub fn build(d: usize, hull: &[Vector3]) -> Result<Self> {
        Self::build_spec(&ProblemSpec::log_det_p(d), hull)
    }

    /// Builds the program of `spec` with one containment row `p(uᵢ) ≤ 1` per point of `points`
    /// (normalized coordinates).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree` when `d` is outside 1..=4, or
    /// `convexity_relaxation` when c is negative or not finite, or c > 0 with the objective on H
    /// (the relaxed Gram matrix would enter the objective, see paper §III-B-2).
    pub fn build_spec(spec: &ProblemSpec, points: &[Vector3]) -> Result<Self> {
        let d = spec.half_degree;
        if !(1..=4).contains(&d) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {}", 2 * d)));
        }
        let c_relax = spec.convexity_relaxation;
        if !(c_relax.is_finite() && c_relax >= 0.0) {
            return Err(Error::invalid("convexity_relaxation", format!("must be finite and ≥ 0, got {c_relax}")));
        }
        if c_relax > 0.0 && spec.matrix == ObjectiveMatrix::H {
            return Err(Error::invalid(
                "convexity_relaxation",
                "relaxed convexity needs the objective on P (logdet_p or trace_p), not on H",
            ));
        }
        let half = graded_exponents3(d);
        let n = half.len();
        let low = graded_exponents3(d - 1);
        let nl = low.len();
        let m = 3 * nl;
        let full = graded_exponents3(2 * d);
        let l = full.len();
        // Side of the matrix the objective acts on.
        let k = match spec.matrix {
            ObjectiveMatrix::P => n,
            ObjectiveMatrix::H => m,
        };

        // Columns: P | objective extras | c | G, where the extras are Z (lower triangle, packed
        // as the upper triangle of Zᵀ) and t for log det, V for trace. For log det P this is the
        // original layout P | Z | t | c | G.
        let col_p = 0;
        let col_x0 = col_p + triangle_len(n) - l;
        let (col_z, col_t, col_v, col_c) = match spec.objective {
            Objective::LogDet => (col_x0, col_x0 + triangle_len(k), 0, col_x0 + triangle_len(k) + k),
            Objective::Trace => (0, 0, col_x0, col_x0 + triangle_len(k)),
        };
        let col_g = col_c + l;
        // Free entries of svec(G): all but one per sos-convexity identity (see (2)).
        let num_vars = col_g + triangle_len(m) - 6 * basis_len(3, 2 * d - 2);
        let z_col = |i: usize, j: usize| col_z + triangle_index(j, i); // Z(i, j), i ≥ j

        let mut r = Rows::default();

        // (1) c_α = Σ_{zᵢzⱼ = x^α} (2 − δᵢⱼ) Pᵢⱼ (svec weight √2 off the diagonal): not rows
        // either; each identity is solved for one svec entry of P (a diagonal entry when x^α is a
        // square), so P is an affine image of c and of its other entries (the free columns).
        // P and G are written in the basis of scaled monomials (see `basis_scales`): svec entries
        // of σᵢσⱼPᵢⱼ, so an entry enters its identity with weight (2 − δᵢⱼ)/(√2^(1−δᵢⱼ) σᵢσⱼ).
        let plain_trace = spec.objective == Objective::Trace && spec.trace_basis == TraceBasis::Plain;
        let scale_p = basis_scales(&half, points, plain_trace && spec.matrix == ObjectiveMatrix::P);
        let scale_g = basis_scales(&low, points, plain_trace && spec.matrix == ObjectiveMatrix::H);
        // The coefficient columns hold τ_α c_α (τ the same root mean square over the full basis).
        let scale_c = basis_scales(&full, points, false);
        let mut p_groups: Vec<Vec<(usize, Real, bool)>> = vec![Vec::new(); l];
        for j in 0..n {
            for i in 0..=j {
                let e = [half[i][0] + half[j][0], half[i][1] + half[j][1], half[i][2] + half[j][2]];
                let w = gram_weight(i, j) / (scale_p[i] * scale_p[j]);
                p_groups[index3(e)].push((triangle_index(i, j), w, i == j));
            }
        }
        let p_image = solve_identities(&p_groups, triangle_len(n), col_p, |alpha| {
            (vec![(col_c + alpha, 1.0 / scale_c[alpha])], 0.0)
        });
        // (2) yᵀ∇²(p + c q) y = wᵀ G w, q = (‖u‖²)ᵈ: one identity per (y-pair k ≤ l, x-monomial β of
        // degree ≤ 2d − 2), Σ_α f·c_α − Σ_{e ∈ group} w_e·svec(G)_e = −c·(yᵀ∇²q y)_β. The identities
        // are not rows: each one is solved for one svec entry of G (its pivot, a diagonal entry when
        // the group has one), so G is an affine image of c and of its other entries (the free
        // columns Y), and only G's PSD cone (or the objective block, for H) carries those rows.
        let lb = basis_len(3, 2 * d - 2);
        let mut rhs2 = vec![0.0; 6 * lb];
        let mut hess_c: Vec<Vec<(usize, Real)>> = vec![Vec::new(); 6 * lb];
        let q_relax = if c_relax > 0.0 { norm_power_coefficients(d) } else { vec![0.0; l] };
        for (ci, alpha) in full.iter().enumerate() {
            for k in 0..3 {
                for ll in k..3 {
                    let ak = alpha[k] as usize;
                    let al = alpha[ll] as usize;
                    let f = if k == ll { (ak * ak.saturating_sub(1)) as Real } else { 2.0 * (ak * al) as Real };
                    if f == 0.0 {
                        continue;
                    }
                    let mut beta = *alpha;
                    beta[k] -= 1;
                    beta[ll] -= 1;
                    let row = pair_index(k, ll) * lb + index3(beta);
                    hess_c[row].push((col_c + ci, f / scale_c[ci]));
                    rhs2[row] -= c_relax * f * q_relax[ci];
                }
            }
        }
        // Entries of svec(G) grouped by the identity they enter, with their svec weights.
        let mut groups: Vec<Vec<(usize, Real, bool)>> = vec![Vec::new(); 6 * lb];
        for bcol in 0..m {
            for acol in 0..=bcol {
                let (ka, ia) = (acol / nl, acol % nl);
                let (kb, ib) = (bcol / nl, bcol % nl);
                let beta = [low[ia][0] + low[ib][0], low[ia][1] + low[ib][1], low[ia][2] + low[ib][2]];
                let w = gram_weight(acol, bcol) / (scale_g[ia] * scale_g[ib]);
                groups[pair_index(ka, kb) * lb + index3(beta)].push((triangle_index(acol, bcol), w, acol == bcol));
            }
        }
        let gram_image = solve_identities(&groups, triangle_len(m), col_g, |row| (hess_c[row].clone(), -rhs2[row]));

        // (3) p(uᵢ) ≤ 1 on the containment points: 1 − Σ c_α uᵢ^α ≥ 0.
        if !points.is_empty() {
            let poly = Polynomial::zero(2 * d);
            for u in points {
                let row = r.next_row();
                for (k, e) in poly.exponents().iter().enumerate() {
                    let v = u.x.powi(e[0] as i32) * u.y.powi(e[1] as i32) * u.z.powi(e[2] as i32);
                    r.push(row, col_c + k, v / scale_c[k]);
                }
                r.b.push(1.0);
            }
            r.cones.push(SupportedConeT::NonnegativeConeT(points.len()));
        }

        // svec entry e of the matrix X the objective acts on (P: a column; H = G: its affine image).
        let p_entry = |e: usize| p_image[e].clone();
        let x_entry = |e: usize| match spec.matrix {
            ObjectiveMatrix::P => p_entry(e),
            ObjectiveMatrix::H => gram_image[e].clone(),
        };

        // (4) The objective block, a 2k × 2k packed triangle of affine expressions holding X:
        //     log det: [[X, Z], [Zᵀ, diag Z]] ⪰ 0;   trace: [[V, I], [I, X]] ⪰ 0.
        let kk = 2 * k;
        let base4 = r.next_row();
        let s2 = std::f64::consts::SQRT_2;
        let mut b4 = vec![0.0; triangle_len(kk)];
        for j in 0..kk {
            for i in 0..=j {
                let row = base4 + triangle_index(i, j);
                match spec.objective {
                    Objective::LogDet => {
                        if j < k {
                            b4[triangle_index(i, j)] += r.push_affine(row, &x_entry(triangle_index(i, j)));
                        } else if i < k {
                            let jz = j - k;
                            if i >= jz {
                                r.push(row, z_col(i, jz), -s2);
                            }
                        } else if i == j {
                            r.push(row, z_col(i - k, i - k), -1.0);
                        }
                    }
                    Objective::Trace => {
                        if j < k {
                            r.push(row, col_v + triangle_index(i, j), -1.0);
                        } else if i < k {
                            if i == j - k {
                                b4[triangle_index(i, j)] = s2;
                            }
                        } else {
                            let e = triangle_index(i - k, j - k);
                            b4[triangle_index(i, j)] += r.push_affine(row, &x_entry(e));
                        }
                    }
                }
            }
        }
        r.b.extend(b4);
        r.cones.push(SupportedConeT::PSDTriangleConeT(kk));

        // (5) The other Gram matrix gets a cone of its own: G ⪰ 0 (objective on P) or P ⪰ 0
        // (objective on H: p sos).
        let size_o = match spec.matrix {
            ObjectiveMatrix::P => m,
            ObjectiveMatrix::H => n,
        };
        let base5 = r.next_row();
        // G's cone holds G' − εI (ε = CONVEXITY_FLOOR, scaled basis): the solver's last residual
        // cannot then leave G' (exactly tied to p by the identities) with a negative eigenvalue.
        for j in 0..size_o {
            for i in 0..=j {
                let e = triangle_index(i, j);
                let (entry, floor) = match spec.matrix {
                    ObjectiveMatrix::P => (&gram_image[e], if i == j { CONVEXITY_FLOOR } else { 0.0 }),
                    ObjectiveMatrix::H => (&p_entry(e), 0.0),
                };
                let constant = r.push_affine(base5 + e, entry);
                r.b.push(constant - floor);
            }
        }
        r.cones.push(SupportedConeT::PSDTriangleConeT(size_o));

        let mut q = vec![0.0; num_vars];
        match spec.objective {
            // (6) (tᵢ, 1, Zᵢᵢ) ∈ K_exp: Zᵢᵢ ≥ exp(tᵢ); maximize Σ tᵢ.
            Objective::LogDet => {
                for i in 0..k {
                    let row = r.next_row();
                    r.push(row, col_t + i, -1.0);
                    r.push(row + 2, z_col(i, i), -1.0);
                    r.b.extend([0.0, 1.0, 0.0]);
                    r.cones.push(SupportedConeT::ExponentialConeT());
                }
                q[col_t..col_t + k].iter_mut().for_each(|v| *v = -1.0);
            }
            // Minimize trace V.
            Objective::Trace => {
                for i in 0..k {
                    q[col_v + triangle_index(i, i)] = 1.0;
                }
            }
        }
        let a = CscMatrix::new_from_triplets(r.b.len(), num_vars, r.ii, r.jj, r.vv);
        Ok(Self {
            half_degree: d,
            gram_size: n,
            convexity_gram_size: m,
            col_p,
            col_g,
            col_c,
            num_vars,
            q,
            a,
            b: r.b,
            cones: r.cones,
            gram_image,
            p_image,
            scale_p,
            scale_g,
        })
    }

    /// Number of constraint rows.
    pub fn num_rows(&self) -> usize {
        self.b.len()
    }

    /// Solves with Clarabel, calling `progress(iteration, primal cost)` after every interior-point
    /// iteration (Clarabel's termination callback, forwarded over a channel from a scoped solver
    /// thread because the callback must be `Send + Sync + 'static`).
    ///
    /// # Errors
    /// [`Error::Numerical`] when Clarabel rejects the data or the solver thread panics. A status
    /// other than `Solved` is returned in the solution, not as an error (see [`usable_status`]).
    pub fn solve(&self, settings: DefaultSettings<Real>, progress: &mut dyn FnMut(u32, Real)) -> Result<RawSolution> {
        let (tx, rx) = std::sync::mpsc::channel::<(u32, Real)>();
        std::thread::scope(|scope| {
            let handle = scope.spawn(move || -> Result<RawSolution> {
                let p = CscMatrix::zeros((self.num_vars, self.num_vars));
                let mut solver = DefaultSolver::new(&p, &self.q, &self.a, &self.b, &self.cones, settings)
                    .map_err(|e| Error::Numerical(format!("Clarabel rejected the fit problem: {e}")))?;
                solver.set_termination_callback(move |info: &DefaultInfo<Real>| {
                    let _ = tx.send((info.iterations, info.cost_primal));
                    false
                });
                solver.solve();
                let sol = &solver.solution;
                Ok(RawSolution {
                    x: sol.x.clone(),
                    status: sol.status,
                    solve_seconds: sol.solve_time,
                    iterations: sol.iterations,
                    // Clarabel minimizes qᵀx = −(the maximized objective).
                    certificate: crate::body::SolverCertificate {
                        primal_objective: -sol.obj_val,
                        dual_objective: -sol.obj_val_dual,
                        primal_residual: sol.r_prim,
                        dual_residual: sol.r_dual,
                    },
                })
            });
            for (it, cost) in rx {
                progress(it, cost);
            }
            handle.join().map_err(|_| Error::Numerical("the Clarabel solver thread panicked".into()))?
        })
    }

    /// [`LogDetProblem::solve`], re-solved with a shorter interior-point step (Clarabel's
    /// `max_step_fraction` 0.9, then 0.7, then 0.9 with the other KKT solver of faer / QDLDL)
    /// while Clarabel ends with `InsufficientProgress` or `NumericalError`, every retry with
    /// iterative refinement on; the returned time and iterations add up every attempt, and
    /// `progress` sees the iterations numbered across attempts.
    ///
    /// # Errors
    /// As [`LogDetProblem::solve`].
    pub fn solve_with_retry(
        &self,
        settings: &DefaultSettings<Real>,
        progress: &mut dyn FnMut(u32, Real),
    ) -> Result<RawSolution> {
        let mut raw = self.solve(settings.clone(), progress)?;
        let other_solver = if settings.direct_solve_method == "qdldl" { "faer" } else { "qdldl" };
        for (fraction, solver) in [(0.9, None), (0.7, None), (0.9, Some(other_solver))] {
            if !matches!(raw.status, SolverStatus::InsufficientProgress | SolverStatus::NumericalError)
                || (solver.is_none() && settings.max_step_fraction <= fraction)
            {
                continue;
            }
            let mut retry = settings.clone();
            retry.max_step_fraction = retry.max_step_fraction.min(fraction);
            // A retry is the careful path: refined KKT solves (they cost a third of the time).
            retry.iterative_refinement_enable = true;
            if let Some(s) = solver {
                retry.direct_solve_method = s.into();
            }
            // Iterations keep counting across attempts so that progress never goes back.
            let offset = raw.iterations;
            let next = self.solve(retry, &mut |it, cost| progress(offset + it, cost))?;
            raw = RawSolution {
                solve_seconds: raw.solve_seconds + next.solve_seconds,
                iterations: raw.iterations + next.iterations,
                ..next
            };
        }
        Ok(raw)
    }

    /// The Gram matrix P (N × N) from a solution.
    pub fn gram(&self, x: &[Real]) -> nalgebra::DMatrix<Real> {
        let scaled = unpack_triangle(&evaluate(&self.p_image, x), self.gram_size);
        unscale(scaled, &self.scale_p)
    }

    /// The sos-convexity Gram matrix G (M × M) from a solution.
    pub fn convexity_gram(&self, x: &[Real]) -> nalgebra::DMatrix<Real> {
        let scaled = unpack_triangle(&evaluate(&self.gram_image, x), self.convexity_gram_size);
        let nl = self.scale_g.len();
        let scales: Vec<Real> = (0..self.convexity_gram_size).map(|a| self.scale_g[a % nl]).collect();
        unscale(scaled, &scales)
    }

    /// p = z(x)ᵀ P z(x) expanded in the graded-lex basis of degree 2d (exactly sos for P ⪰ 0).
    ///
    /// # Errors
    /// [`Error::Numerical`] when a coefficient is not finite.
    pub fn polynomial_of_gram(&self, p: &nalgebra::DMatrix<Real>) -> Result<Polynomial> {
        polynomial_of_gram(self.half_degree, p)
    }
}

/// Clarabel's raw answer.
#[derive(Clone, Debug)]
pub struct RawSolution {
    /// Primal variables.
    pub x: Vec<Real>,
    /// Final status.
    pub status: SolverStatus,
    /// Seconds inside Clarabel.
    pub solve_seconds: Real,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Primal / dual objectives (maximized form) and residuals of the last iterate.
    pub certificate: crate::body::SolverCertificate,
}

/// Maps every Clarabel status explicitly: `Solved` / `AlmostSolved` give a usable answer (its
/// name is recorded in the report); everything else is an [`Error::Numerical`] naming the status.
///
/// # Errors
/// [`Error::Numerical`] for every status other than `Solved` and `AlmostSolved`.
pub fn usable_status(status: SolverStatus) -> Result<&'static str> {
    let why = match status {
        SolverStatus::Solved => return Ok("Solved"),
        SolverStatus::AlmostSolved => return Ok("AlmostSolved"),
        SolverStatus::Unsolved => "Unsolved (the solver did not run)",
        SolverStatus::PrimalInfeasible => "PrimalInfeasible",
        SolverStatus::DualInfeasible => "DualInfeasible (log det unbounded: too few hull vertices?)",
        SolverStatus::AlmostPrimalInfeasible => "AlmostPrimalInfeasible",
        SolverStatus::AlmostDualInfeasible => "AlmostDualInfeasible (log det unbounded: too few hull vertices?)",
        SolverStatus::MaxIterations => "MaxIterations (raise max_solver_iterations)",
        SolverStatus::MaxTime => "MaxTime",
        SolverStatus::NumericalError => "NumericalError",
        SolverStatus::InsufficientProgress => "InsufficientProgress",
        SolverStatus::CallbackTerminated => "CallbackTerminated",
    };
    Err(Error::Numerical(format!("the fit SDP ended with status {why}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poly::gram::GramStructure;

    /// Coefficients of yᵀ∇²p y (p given by its graded-lex coefficients `c`) and of wᵀGw, both
    /// indexed by six-variable exponents (x1, x2, x3, y1, y2, y3): the first directly from the
    /// derivative formula, the second through an independent `GramStructure` expansion.
    fn hessian_and_gram_coefficients(d: usize, c: &[Real], g: &nalgebra::DMatrix<Real>) -> Vec<(Real, Real)> {
        let full = graded_exponents3(2 * d);
        let low = graded_exponents3(d - 1);
        let mut half6 = Vec::new();
        for k in 0..3 {
            for e in &low {
                let mut v = vec![e[0], e[1], e[2], 0, 0, 0];
                v[3 + k] = 1;
                half6.push(v);
            }
        }
        let gs = GramStructure::with_half_basis(6, half6, 2 * d);
        let rhs6 = gs.polynomial_of(g);
        let mut out = Vec::new();
        for k in 0..3 {
            for l in k..3 {
                for beta in &graded_exponents3(2 * d - 2) {
                    let mut lhs = 0.0;
                    for (ci, a) in full.iter().enumerate() {
                        let ok = if k == l { a[k] >= 2 } else { a[k] >= 1 && a[l] >= 1 };
                        if !ok {
                            continue;
                        }
                        let mut bb = *a;
                        bb[k] -= 1;
                        bb[l] -= 1;
                        if bb != *beta {
                            continue;
                        }
                        let f =
                            if k == l { (a[k] as f64) * (a[k] as f64 - 1.0) } else { 2.0 * a[k] as f64 * a[l] as f64 };
                        lhs += f * c[ci];
                    }
                    let mut e6 = vec![beta[0], beta[1], beta[2], 0, 0, 0];
                    e6[3 + k] += 1;
                    e6[3 + l] += 1;
                    out.push((lhs, rhs6[gs.index_of[&e6]]));
                }
            }
        }
        out
    }

    /// The sos-convexity identities are built into G's affine image: for arbitrary c and
    /// arbitrary free columns of G, the G returned by `convexity_gram` satisfies
    /// coeff(yᵀ∇²p y) = coeff(wᵀGw) for every monomial, checked against an independent expansion
    /// through `GramStructure` in six variables (x, y); the free columns reappear as entries of G.
    #[test]
    fn gram_image_satisfies_the_sos_convexity_identities() {
        for d in 1..=3 {
            let prob = LogDetProblem::build(d, &[]).unwrap();
            let l = basis_len(3, 2 * d);
            let mut x = vec![0.0; prob.num_vars];
            for (k, v) in x.iter_mut().enumerate().skip(prob.col_c) {
                *v = (k as f64 * 0.618_034).fract() - 0.5; // distinct values
            }
            let c = x[prob.col_c..prob.col_c + l].to_vec();
            let g = prob.convexity_gram(&x);
            let mut checked = 0;
            for (lhs, rhs) in hessian_and_gram_coefficients(d, &c, &g) {
                assert!((lhs - rhs).abs() < 1e-12 * (1.0 + lhs.abs()), "d = {d}: {lhs} vs {rhs}");
                checked += 1;
            }
            assert_eq!(checked, 6 * basis_len(3, 2 * d - 2));
            // Every free column is an entry of svec(G), each used once.
            let svec = evaluate(&prob.gram_image, &x);
            let free: Vec<Real> = x[prob.col_g..].to_vec();
            for v in &free {
                assert_eq!(svec.iter().filter(|s| *s == v).count(), 1, "d = {d}: free value {v}");
            }
            assert_eq!(prob.num_vars - prob.col_g, triangle_len(prob.convexity_gram_size) - checked);
        }
    }

    /// With relaxation c, p = −c(‖u‖²)ᵈ with the free entries of G at 0 gives G = 0
    /// (yᵀ∇²(p + c q)y = 0 = wᵀ0w), p = 0 gives the Gram matrix of c·yᵀ∇²q y (independent
    /// expansion), and q's coefficients evaluate to (‖u‖²)ᵈ.
    #[test]
    fn relaxed_identities_move_c_q_into_the_gram_image() {
        for d in 1..=4 {
            let q = norm_power_coefficients(d);
            let poly = Polynomial::from_coefficients(2 * d, q.clone()).unwrap();
            let u = Vector3::new(0.3, -0.7, 1.1);
            assert!((poly.value(&u) - u.norm_squared().powi(d as i32)).abs() < 1e-12);
            let spec = ProblemSpec { convexity_relaxation: 2.5, ..ProblemSpec::log_det_p(d) };
            let prob = LogDetProblem::build_spec(&spec, &[]).unwrap();
            let mut x = vec![0.0; prob.num_vars];
            for (k, v) in q.iter().enumerate() {
                x[prob.col_c + k] = -2.5 * v;
            }
            let g = prob.convexity_gram(&x);
            assert!(g.amax() < 1e-12, "d = {d}: |G| = {}", g.amax());
            if d <= 3 {
                let g0 = prob.convexity_gram(&vec![0.0; prob.num_vars]);
                assert!(g0.amax() > 1.0);
                let cq: Vec<Real> = q.iter().map(|v| 2.5 * v).collect();
                for (lhs, rhs) in hessian_and_gram_coefficients(d, &cq, &g0) {
                    assert!((lhs - rhs).abs() < 1e-12 * (1.0 + lhs.abs()), "d = {d}: {lhs} vs {rhs}");
                }
            }
        }
        let bad = ProblemSpec { matrix: ObjectiveMatrix::H, convexity_relaxation: 1.0, ..ProblemSpec::log_det_p(2) };
        assert!(matches!(
            LogDetProblem::build_spec(&bad, &[]),
            Err(Error::InvalidArgument { field, .. }) if field == "convexity_relaxation"
        ));
    }

    #[test]
    fn every_status_is_mapped() {
        assert_eq!(usable_status(SolverStatus::Solved).unwrap(), "Solved");
        assert_eq!(usable_status(SolverStatus::AlmostSolved).unwrap(), "AlmostSolved");
        for s in [
            SolverStatus::Unsolved,
            SolverStatus::PrimalInfeasible,
            SolverStatus::DualInfeasible,
            SolverStatus::AlmostPrimalInfeasible,
            SolverStatus::AlmostDualInfeasible,
            SolverStatus::MaxIterations,
            SolverStatus::MaxTime,
            SolverStatus::NumericalError,
            SolverStatus::InsufficientProgress,
            SolverStatus::CallbackTerminated,
        ] {
            let e = usable_status(s).unwrap_err();
            assert!(matches!(e, Error::Numerical(_)));
            assert!(e.to_string().contains(&format!("{s:?}")), "{e}");
        }
    }
}
