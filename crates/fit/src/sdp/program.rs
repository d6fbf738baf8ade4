//! The cone program of every fit: one builder for the point-cloud fits (paper §III) and the
//! containment of bodies (paper §V).

use super::identities::{
    add3, basis_scales, convexity_groups, evaluate, hessian_identities, num_convexity_identities, polynomial_of_gram,
    solve_identities, sos_groups, unscale, AffineEntry,
};
use crate::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::SupportedConeT;
use sublevel_core::math::{Real, Vector3};
use sublevel_core::poly::gram::{gram_weight, triangle_index, triangle_len, unpack_triangle};
use sublevel_core::poly::monomial::{basis_len, graded_exponents3, index3};
use sublevel_core::poly::Polynomial;

/// Smallest eigenvalue the program requires of the sos-convexity Gram matrix G' (scaled basis,
/// see [`super::identities`]; G = Σ⁻¹G'Σ⁻¹ with σ ≤ 1 on the unit ball, so λ_min(G) ≥ this too). A
/// floor of 10⁻⁶ keeps the certified convexity margin positive after the solver's last residual
/// (about 10⁻⁹ in G', up to −5·10⁻⁷ in G at 2d = 8 without it) and moves the body by ~10⁻⁶.
pub const CONVEXITY_FLOOR: Real = 1e-6;

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

/// The monomial basis of the trace objective trace X⁻¹ (not invariant under a diagonal change of
/// basis, unlike log det): the plain monomials u^α, or the monomials scaled by their root mean
/// square over the containment points (u^α/σ_α, the basis the program is written in). Neither is
/// tighter on every shape (Table 1 shapes: scaled is smaller at c = 0 on all ten 2d = 4/6 fits,
/// plain on four of five at 2d = 6, c = 10), so the fit solves both and keeps the smaller body
/// ([`crate::FitSettings`], method `trace_p` / `trace_h`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TraceBasis {
    /// Plain monomials u^α.
    #[default]
    Plain,
    /// Monomials scaled by their RMS over the points.
    Scaled,
}

/// The cone the sos-convexity Gram matrix G − εI is kept in when the objective acts on P
/// (paper §VI: "dsos / sdsos" inner approximations of the psd cone by Ahmadi and Majumdar, "DSOS
/// and SDSOS optimization", SIAM J. Appl. Algebra Geom. 2019). The smaller cones leave p
/// sos-convex (a dd or sdd matrix is psd) but fit a larger body, and, unlike the psd cone, depend on
/// the frame and the monomial basis the program is written in (the scaled basis of
/// [`super::identities`]; sdd is invariant under its diagonal scaling, dd is not).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ConvexityCone {
    /// G − εI ⪰ 0: one M × M psd cone (the paper's sos-convexity).
    #[default]
    Psd,
    /// G − εI scaled diagonally dominant: a sum of M(M − 1)/2 psd 2 × 2 blocks, each a
    /// 3-dimensional second-order cone (sdsos: an SOCP constraint).
    Sdd,
    /// G − εI diagonally dominant: Gᵢᵢ − ε ≥ Σⱼ |Gᵢⱼ| (dsos: linear constraints).
    Dd,
}

impl ConvexityCone {
    /// Every cone, the psd cone first.
    pub const ALL: [ConvexityCone; 3] = [ConvexityCone::Psd, ConvexityCone::Sdd, ConvexityCone::Dd];

    /// The cone's name: `psd`, `sdd` or `dd`.
    pub fn name(self) -> &'static str {
        match self {
            ConvexityCone::Psd => "psd",
            ConvexityCone::Sdd => "sdd",
            ConvexityCone::Dd => "dd",
        }
    }
}

impl std::str::FromStr for ConvexityCone {
    type Err = Error;

    /// `psd`, `sdd` or `dd` ([`ConvexityCone::name`]).
    fn from_str(s: &str) -> Result<Self> {
        ConvexityCone::ALL
            .into_iter()
            .find(|c| c.name() == s)
            .ok_or_else(|| Error::invalid("convexity_cone", format!("must be one of psd, sdd, dd, got {s:?}")))
    }
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
    /// The cone of G − εI (objective on P only; on H, G is the objective's matrix and stays psd).
    pub convexity_cone: ConvexityCone,
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
            convexity_cone: ConvexityCone::Psd,
        }
    }

    /// The objective's name in progress messages (`"log det P"`, `"−trace H⁻¹"`, …).
    pub fn objective_label(&self) -> &'static str {
        match (self.objective, self.matrix) {
            (Objective::LogDet, ObjectiveMatrix::P) => "log det P",
            (Objective::LogDet, ObjectiveMatrix::H) => "log det H",
            (Objective::Trace, ObjectiveMatrix::P) => "−trace P⁻¹",
            (Objective::Trace, ObjectiveMatrix::H) => "−trace H⁻¹",
        }
    }
}

/// What the body must contain: the constraint block that distinguishes a point fit from a
/// containment of bodies.
#[derive(Clone, Copy, Debug)]
pub enum Containment<'a> {
    /// `p(uᵢ) ≤ 1` for every point (normalized coordinates): one nonnegative row each (paper
    /// §III; for a convex p the hull vertices suffice). The points also set the basis scales.
    Points(&'a [Vector3]),
    /// The S-procedure of paper §V for each body {gᵢ ≤ 1} (its polynomial in normalized
    /// coordinates, degree ≥ 2): `1 − p − τᵢ(1 − gᵢ)` sos (eq. "s.procedure") with τᵢ sos of
    /// degree 2k ∈ {0, 2} (eq. "tau.sos"), matched coefficient by coefficient against a Gram
    /// form Qᵢ ⪰ 0 of degree Dᵢ = max(2d, 2k + deg gᵢ) (rounded up to even).
    Bodies {
        /// The bodies' polynomials gᵢ in normalized coordinates.
        polynomials: &'a [Polynomial],
        /// 2k ∈ {0, 2}: 0 makes τᵢ a nonnegative scalar, 2 a sos quadratic z₁ᵀTᵢz₁, Tᵢ ⪰ 0 (4 × 4).
        multiplier_degree: usize,
        /// Points of the bodies (normalized coordinates) that set the monomial basis scales.
        samples: &'a [Vector3],
    },
}

/// The cone program `min qᵀx s.t. b − A x ∈ K` of a fit, with its column layout.
///
/// ```text
/// columns:  free entries of P | Z, t (log det) or V (trace) | τ_α c_α | free entries of G | τᵢ, Qᵢ
/// objective block on X ∈ {P (N × N), H = G (M × M)}:
///   log det X:      [[X, Z], [Zᵀ, diag Z]] ⪰ 0,  (tᵢ, 1, Zᵢᵢ) ∈ K_exp,  maximize Σ tᵢ
///   trace X⁻¹:      [[V, I], [I, X]] ⪰ 0,  minimize trace V           (Schur: V ⪰ X⁻¹)
/// the other Gram matrix gets a plain PSD cone (G − εI ⪰ 0, or P ⪰ 0 i.e. p sos for H)
/// containment: p(uᵢ) ≤ 1 rows, or per body τᵢ ⪰ 0, Qᵢ ⪰ 0 and its coefficient equalities
/// ```
#[derive(Debug)]
pub struct GramProgram {
    /// Half degree d (the body has degree 2d).
    pub half_degree: usize,
    /// Side N of the Gram matrix P.
    pub gram_size: usize,
    /// Side M of the sos-convexity Gram matrix G.
    pub convexity_gram_size: usize,
    /// First column of the free entries of svec(P) (Clarabel's packed triangle, off-diagonals
    /// × √2, scaled basis); use [`GramProgram::gram`] for P itself.
    pub col_p: usize,
    /// First column of the free entries of svec(G); use [`GramProgram::convexity_gram`] for G.
    pub col_g: usize,
    /// First column of the coefficients of p (graded lex, degree ≤ 2d), each times its scale τ_α.
    pub col_c: usize,
    /// Per contained body: first column of its multiplier (the scalar τᵢ, or svec(Tᵢ) for 2k = 2).
    pub col_tau: Vec<usize>,
    /// Per contained body: degree Dᵢ of its s.procedure polynomial.
    pub sprocedure_degrees: Vec<usize>,
    /// Number of columns.
    pub num_vars: usize,
    pub(super) q: Vec<Real>,
    pub(super) a: CscMatrix<Real>,
    pub(super) b: Vec<Real>,
    pub(super) cones: Vec<SupportedConeT<Real>>,
    /// svec(G) as affine functions of the columns.
    pub(crate) gram_image: Vec<AffineEntry>,
    /// svec(P) as affine functions of the columns.
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
    /// A PSD cone on the n × n matrix held by `n(n+1)/2` consecutive columns from `col`.
    fn psd_columns(&mut self, col: usize, n: usize) {
        let base = self.next_row();
        for e in 0..triangle_len(n) {
            self.push(base + e, col + e, -1.0);
        }
        self.b.extend(std::iter::repeat_n(0.0, triangle_len(n)));
        self.cones.push(SupportedConeT::PSDTriangleConeT(n));
    }
    /// Equality rows `Σ coef·x[col] = rhs` (Clarabel's zero cone).
    fn equalities(&mut self, rows: Vec<Vec<(usize, Real)>>, rhs: Vec<Real>) {
        let base = self.next_row();
        let len = rows.len();
        for (k, row) in rows.into_iter().enumerate() {
            for (col, v) in row {
                self.push(base + k, col, v);
            }
        }
        self.b.extend(rhs);
        self.cones.push(SupportedConeT::ZeroConeT(len));
    }
}

impl GramProgram {
    /// Builds the log det P program of eq. "VAG.log.det" for half degree `d ∈ 1..=4` with
    /// containment rows on the normalized hull vertices `hull`.
    ///
    /// # Errors
    /// As [`GramProgram::build`].
    pub fn log_det_p(d: usize, hull: &[Vector3]) -> Result<Self> {
        Self::build(&ProblemSpec::log_det_p(d), Containment::Points(hull))
    }

    /// Builds the program of `spec` with the constraint block `containment`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree` when d is outside 1..=4, `convexity_relaxation`
    /// when c is negative or not finite, or c > 0 with the objective on H (the relaxed Gram
    /// matrix would enter the objective, see paper §III-B-2), `convexity_cone` other than psd with
    /// the objective on H, `multiplier_degree` outside {0, 2},
    /// or `bodies` (none, or one of degree < 2).
    pub fn build(spec: &ProblemSpec, containment: Containment<'_>) -> Result<Self> {
        let d = spec.half_degree;
        if !(1..=4).contains(&d) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {}", 2 * d)));
        }
        let c_relax = spec.convexity_relaxation;
        if !(c_relax.is_finite() && c_relax >= 0.0) {
            return Err(Error::invalid("convexity_relaxation", format!("must be finite and ≥ 0, got {c_relax}")));
        }
        if spec.convexity_cone != ConvexityCone::Psd && spec.matrix == ObjectiveMatrix::H {
            return Err(Error::invalid(
                "convexity_cone",
                "dd and sdd need the objective on P (logdet_p or trace_p): on H, G is the objective's psd matrix",
            ));
        }
        if c_relax > 0.0 && spec.matrix == ObjectiveMatrix::H {
            return Err(Error::invalid(
                "convexity_relaxation",
                "relaxed convexity needs the objective on P (logdet_p or trace_p), not on H",
            ));
        }
        let scale_points = match containment {
            Containment::Points(points) => points,
            Containment::Bodies { polynomials, multiplier_degree, samples } => {
                if ![0, 2].contains(&multiplier_degree) {
                    return Err(Error::invalid(
                        "multiplier_degree",
                        format!("must be 0 or 2, got {multiplier_degree}"),
                    ));
                }
                if polynomials.is_empty() {
                    return Err(Error::invalid("bodies", "need at least one body to contain"));
                }
                if let Some(i) = polynomials.iter().position(|g| g.degree() < 2) {
                    return Err(Error::invalid(format!("bodies[{i}]"), "must have degree at least 2"));
                }
                samples
            }
        };
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
        // as the upper triangle of Zᵀ) and t for log det, V for trace.
        let col_p = 0;
        let col_x0 = col_p + triangle_len(n) - l;
        let (col_z, col_t, col_v, col_c) = match spec.objective {
            Objective::LogDet => (col_x0, col_x0 + triangle_len(k), 0, col_x0 + triangle_len(k) + k),
            Objective::Trace => (0, 0, col_x0, col_x0 + triangle_len(k)),
        };
        let col_g = col_c + l;
        // Free entries of svec(G): all but one per sos-convexity identity.
        let mut num_vars = col_g + triangle_len(m) - num_convexity_identities(d);
        let z_col = |i: usize, j: usize| col_z + triangle_index(j, i); // Z(i, j), i ≥ j

        let mut r = Rows::default();

        // (1) The coefficient identities, each solved for one svec entry of P: P is an affine
        // image of c and of its other entries. Entries are σᵢσⱼPᵢⱼ (scaled basis).
        let plain_trace = spec.objective == Objective::Trace && spec.trace_basis == TraceBasis::Plain;
        let scale_p = basis_scales(&half, scale_points, plain_trace && spec.matrix == ObjectiveMatrix::P);
        let scale_g = basis_scales(&low, scale_points, plain_trace && spec.matrix == ObjectiveMatrix::H);
        // The coefficient columns hold τ_α c_α (τ the same root mean square over the full basis).
        let scale_c = basis_scales(&full, scale_points, false);
        let p_image = solve_identities(&sos_groups(&half, &scale_p, l), triangle_len(n), col_p, |alpha| {
            (vec![(col_c + alpha, 1.0 / scale_c[alpha])], 0.0)
        });
        // (2) yᵀ∇²(p + c q) y = wᵀ G w, each identity solved for one svec entry of G.
        let (hess, rhs) = hessian_identities(d, col_c, &scale_c, c_relax);
        let gram_image = solve_identities(&convexity_groups(&low, &scale_g, d), triangle_len(m), col_g, |row| {
            (hess[row].clone(), -rhs[row])
        });

        // (3) Containment.
        let mut col_tau = Vec::new();
        let mut sprocedure_degrees = Vec::new();
        match containment {
            // p(uᵢ) ≤ 1: 1 − Σ c_α uᵢ^α ≥ 0.
            Containment::Points(points) => {
                if !points.is_empty() {
                    for u in points {
                        let row = r.next_row();
                        for (kc, e) in full.iter().enumerate() {
                            let v = u.x.powi(e[0] as i32) * u.y.powi(e[1] as i32) * u.z.powi(e[2] as i32);
                            r.push(row, col_c + kc, v / scale_c[kc]);
                        }
                        r.b.push(1.0);
                    }
                    r.cones.push(SupportedConeT::NonnegativeConeT(points.len()));
                }
            }
            // Per body: τᵢ sos, and p + τᵢ(1 − gᵢ) + z_sᵀ Qᵢ z_s = 1 coefficient by coefficient.
            Containment::Bodies { polynomials, multiplier_degree, .. } => {
                let z1 = graded_exponents3(1);
                for gi in polynomials {
                    let dd = (2 * d).max(multiplier_degree + gi.degree());
                    let dd = dd + dd % 2;
                    let zs = graded_exponents3(dd / 2);
                    let ns = zs.len();
                    let tau = num_vars;
                    if multiplier_degree == 0 {
                        num_vars += 1;
                        let row = r.next_row();
                        r.push(row, tau, -1.0);
                        r.b.push(0.0);
                        r.cones.push(SupportedConeT::NonnegativeConeT(1));
                    } else {
                        num_vars += triangle_len(z1.len());
                        r.psd_columns(tau, z1.len());
                    }
                    let col_q = num_vars;
                    num_vars += triangle_len(ns);
                    r.psd_columns(col_q, ns);
                    let rows_len = basis_len(3, dd);
                    let mut rows: Vec<Vec<(usize, Real)>> = vec![Vec::new(); rows_len];
                    for (kc, alpha) in full.iter().enumerate() {
                        rows[index3(*alpha)].push((col_c + kc, 1.0 / scale_c[kc]));
                    }
                    // h = 1 − gᵢ.
                    let h = one_minus_terms(gi);
                    if multiplier_degree == 0 {
                        for (e, hc) in &h {
                            rows[index3(*e)].push((tau, *hc));
                        }
                    } else {
                        for bj in 0..z1.len() {
                            for ai in 0..=bj {
                                let w = gram_weight(ai, bj);
                                let mono = add3(z1[ai], z1[bj]);
                                for (e, hc) in &h {
                                    rows[index3(add3(mono, *e))].push((tau + triangle_index(ai, bj), w * hc));
                                }
                            }
                        }
                    }
                    for bj in 0..ns {
                        for ai in 0..=bj {
                            rows[index3(add3(zs[ai], zs[bj]))]
                                .push((col_q + triangle_index(ai, bj), gram_weight(ai, bj)));
                        }
                    }
                    let mut rhs = vec![0.0; rows_len];
                    rhs[0] = 1.0;
                    r.equalities(rows, rhs);
                    col_tau.push(tau);
                    sprocedure_degrees.push(dd);
                }
            }
        }

        // svec entry e of the matrix X the objective acts on (P: a column; H = G: its affine image).
        let x_entry = |e: usize| match spec.matrix {
            ObjectiveMatrix::P => &p_image[e],
            ObjectiveMatrix::H => &gram_image[e],
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
                            b4[triangle_index(i, j)] += r.push_affine(row, x_entry(triangle_index(i, j)));
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
                            b4[triangle_index(i, j)] += r.push_affine(row, x_entry(e));
                        }
                    }
                }
            }
        }
        r.b.extend(b4);
        r.cones.push(SupportedConeT::PSDTriangleConeT(kk));

        // (5) The other Gram matrix gets a cone of its own: G − εI ⪰ 0 (objective on P; ε =
        // CONVEXITY_FLOOR, so that the solver's last residual cannot leave G with a negative
        // eigenvalue) or P ⪰ 0 (objective on H: p sos).
        let size_o = match spec.matrix {
            ObjectiveMatrix::P => m,
            ObjectiveMatrix::H => n,
        };
        if spec.matrix == ObjectiveMatrix::P && spec.convexity_cone != ConvexityCone::Psd {
            num_vars = convexity_cone_rows(&mut r, &gram_image, m, spec.convexity_cone, num_vars);
        } else {
            let base5 = r.next_row();
            for j in 0..size_o {
                for i in 0..=j {
                    let e = triangle_index(i, j);
                    let (entry, floor) = match spec.matrix {
                        ObjectiveMatrix::P => (&gram_image[e], if i == j { CONVEXITY_FLOOR } else { 0.0 }),
                        ObjectiveMatrix::H => (&p_image[e], 0.0),
                    };
                    let constant = r.push_affine(base5 + e, entry);
                    r.b.push(constant - floor);
                }
            }
            r.cones.push(SupportedConeT::PSDTriangleConeT(size_o));
        }

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
            col_tau,
            sprocedure_degrees,
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

    /// The Gram matrix P (N × N) from a solution x.
    pub fn gram(&self, x: &[Real]) -> nalgebra::DMatrix<Real> {
        let scaled = unpack_triangle(&evaluate(&self.p_image, x), self.gram_size);
        unscale(scaled, &self.scale_p)
    }

    /// The sos-convexity Gram matrix G (M × M) from a solution x.
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

/// The rows keeping G − εI (its packed triangle `gram`, off-diagonals × √2; M × M) in the dd or
/// sdd cone, with the auxiliary columns from `col`; returns the new column count.
///
/// ```text
/// sdd: G − εI = Σ_{i<j} Eᵢⱼ([[aᵢⱼ, Gᵢⱼ], [Gᵢⱼ, cᵢⱼ]]), each block psd ⇔ (a + c, a − c, 2Gᵢⱼ) ∈ SOC₃;
///      Gᵢᵢ − ε = Σ_{j>i} aᵢⱼ + Σ_{j<i} cⱼᵢ (equalities)
/// dd:  tᵢⱼ ≥ ±Gᵢⱼ,  Gᵢᵢ − ε − Σ_{j≠i} tᵢⱼ ≥ 0 (nonnegative rows)
/// ```
fn convexity_cone_rows(r: &mut Rows, gram: &[AffineEntry], m: usize, cone: ConvexityCone, col: usize) -> usize {
    let s2 = std::f64::consts::SQRT_2;
    let per_pair = if cone == ConvexityCone::Sdd { 2 } else { 1 };
    // Per diagonal entry i: the auxiliary columns whose sum it must equal (sdd) or exceed (dd).
    let mut diagonal: Vec<Vec<(usize, Real)>> = vec![Vec::new(); m];
    let mut pair = 0;
    for j in 0..m {
        for i in 0..j {
            let e = &gram[triangle_index(i, j)];
            let aux = col + per_pair * pair;
            pair += 1;
            let row = r.next_row();
            match cone {
                ConvexityCone::Sdd => {
                    let (a, c) = (aux, aux + 1);
                    diagonal[i].push((a, 1.0));
                    diagonal[j].push((c, 1.0));
                    r.push(row, a, -1.0);
                    r.push(row, c, -1.0);
                    r.push(row + 1, a, -1.0);
                    r.push(row + 1, c, 1.0);
                    // 2Gᵢⱼ = √2 × the packed entry.
                    for &(k, coef) in &e.terms {
                        r.push(row + 2, k, -s2 * coef);
                    }
                    r.b.extend([0.0, 0.0, s2 * e.constant]);
                    r.cones.push(SupportedConeT::SecondOrderConeT(3));
                }
                ConvexityCone::Dd | ConvexityCone::Psd => {
                    diagonal[i].push((aux, 1.0));
                    diagonal[j].push((aux, 1.0));
                    // t − Gᵢⱼ ≥ 0 and t + Gᵢⱼ ≥ 0, Gᵢⱼ = packed / √2.
                    for (k, sign) in [(0, 1.0), (1, -1.0)] {
                        r.push(row + k, aux, -1.0);
                        for &(c, coef) in &e.terms {
                            r.push(row + k, c, sign * coef / s2);
                        }
                        r.b.push(-sign * e.constant / s2);
                    }
                    r.cones.push(SupportedConeT::NonnegativeConeT(2));
                }
            }
        }
    }
    // The diagonal rows: Gᵢᵢ − ε − Σ aux (= 0 for sdd, ≥ 0 for dd).
    let base = r.next_row();
    for (i, aux) in diagonal.iter().enumerate() {
        let e = &gram[triangle_index(i, i)];
        let constant = r.push_affine(base + i, e);
        for &(k, coef) in aux {
            r.push(base + i, k, coef);
        }
        r.b.push(constant - CONVEXITY_FLOOR);
    }
    r.cones.push(match cone {
        ConvexityCone::Sdd => SupportedConeT::ZeroConeT(m),
        _ => SupportedConeT::NonnegativeConeT(m),
    });
    col + per_pair * pair
}

/// The nonzero terms (exponent, coefficient) of 1 − g: the factor the S-procedure multiplier τ
/// multiplies (paper §V, eq. "s.procedure"). g's basis holds the constant monomial.
pub(crate) fn one_minus_terms(g: &Polynomial) -> Vec<([u8; 3], Real)> {
    g.exponents()
        .iter()
        .zip(g.coefficients())
        .map(|(e, &c)| (*e, if *e == [0, 0, 0] { 1.0 - c } else { -c }))
        .filter(|(_, c)| *c != 0.0)
        .collect()
}
