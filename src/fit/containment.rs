//! Containment of polynomial sublevel sets (paper §V): one sos-convex body around many bodies.
//!
//! Given posed bodies `Sᵢ = {x : gᵢ(x) ≤ 1}`, `gᵢ(x) = pᵢ((Rᵢᵀ(x − tᵢ) − cᵢ)/sᵢ)` (their world-frame
//! polynomials, [`Polynomial::compose_affine`]), find one sos-convex p of degree 2d whose unit
//! sublevel set contains their union and has small volume:
//!
//! ```text
//! maximize    log det P
//! subject to  p(x) = z(x)ᵀ P z(x),                       z = monomials of degree ≤ d
//!             p sos-convex                                (eq. "p.sosconvex")
//!             1 − p(x) − τᵢ(x)(1 − gᵢ(x))  sos,           (eq. "s.procedure")
//!             τᵢ sos of degree 2k,                        (eq. "tau.sos")     i = 1..m
//! ```
//!
//! This is the S-procedure: on Sᵢ, `1 − gᵢ ≥ 0` and `τᵢ ≥ 0`, so `1 − p ≥ τᵢ(1 − gᵢ) ≥ 0`. The union
//! is contained by containing each body separately (one s.procedure constraint per body, each with
//! its own multiplier τᵢ). Multiplier degrees: `2k = 0` (τᵢ a nonnegative scalar — already a valid
//! certificate, and lossless for ellipsoids in ellipsoids by the S-lemma) or `2k = 2`
//! (`τᵢ = z₁ᵀ Tᵢ z₁`, `Tᵢ ⪰ 0` 4 × 4, z₁ = (1, x, y, z)). The s.procedure polynomial has degree
//! `Dᵢ = max(2d, 2k + deg gᵢ)`; its Gram matrix `Qᵢ ⪰ 0` is indexed by the monomials of degree
//! ≤ Dᵢ/2, and one equation per monomial of degree ≤ Dᵢ matches coefficients:
//!
//! ```text
//! c_γ(p) + c_γ(τᵢ · (1 − gᵢ)) + Σ_{a ≤ b, z_a z_b = x^γ} (2 − δ_ab) Qᵢ,ab = [γ = 0]
//! ```
//!
//! `log det P` and sos-convexity are written exactly as in [`super::logdet_p`] (big block
//! `[[P, Z], [Zᵀ, diag Z]] ⪰ 0`, exponential cones `Zᵢᵢ ≥ exp(tᵢ)`; `yᵀ∇²p y = wᵀ G w`, `G ⪰ 0`).
//!
//! World coordinates are first normalized, `v = (x − c)/s` with c the midpoint of the union of the
//! bodies' bounding boxes and s half its diagonal (so every body lies in the unit ball); the
//! problem is affine-invariant up to a constant in the objective, so this only helps conditioning.
//! The result is a [`Body`] with that center and scale, in world coordinates (use it at identity
//! pose). After the solve, p is checked on boundary samples of every input body (bisection along
//! rays from each body's interior point) and divided by the largest value above 1, as the point
//! fit does; the report records the rescale.
//!
//! Sizes (per body, with the same degree for every body): at 2d = 4 and deg g = 4, 2k = 0, each
//! body adds a 10 × 10 Gram and 35 equations; 2k = 2 raises its degree to 6 (20 × 20, 84 rows).

use super::logdet_p::pair_index;
use super::{report, volume, FitProgress, FitStage, KktSolver};
use crate::body::{Body, FitReport};
use crate::conic::{quiet_settings, ConicBuilder, Row};
use crate::math::{Isometry3, Point3, Real, Vector3};
use crate::poly::gram::{gram_weight, triangle_index, triangle_len, unpack_triangle};
use crate::poly::monomial::{basis_len, graded_exponents3, index3};
use crate::poly::Polynomial;
use crate::{Error, Result};
use clarabel::solver::{SolverStatus, SupportedConeT};

/// Degrees 2d the containing polynomial may have.
pub const CONTAINMENT_DEGREES: [usize; 3] = [2, 4, 6];

/// Degrees 2k the multipliers τᵢ may have (0: nonnegative scalars).
pub const MULTIPLIER_DEGREES: [usize; 2] = [0, 2];

/// Most bodies one containment SDP accepts (each adds a Gram block and its equations).
pub const MAX_CONTAINED_BODIES: usize = 16;

/// Boundary points sampled per input body to verify (and restore) containment after the solve.
pub const BOUNDARY_SAMPLES_PER_BODY: usize = 2000;

/// Settings of [`contain_bodies`].
#[derive(Clone, Debug)]
pub struct ContainmentSettings {
    /// Total degree 2d ∈ {2, 4, 6} of the containing polynomial p.
    pub degree: usize,
    /// Degree 2k ∈ {0, 2} of the sos multipliers τᵢ (eq. "tau.sos").
    pub multiplier_degree: usize,
    /// Monte Carlo samples of the volume estimate (at least; see [`volume::monte_carlo_volume`]).
    pub volume_samples: usize,
    /// Seed of the volume estimate.
    pub seed: u64,
    /// Clarabel's gap and feasibility tolerance.
    pub solver_tolerance: Real,
    /// Clarabel's iteration cap.
    pub max_solver_iterations: u32,
    /// Direct solver of Clarabel's KKT systems.
    pub linear_solver: KktSolver,
}

impl Default for ContainmentSettings {
    fn default() -> Self {
        Self {
            degree: 4,
            multiplier_degree: 0,
            volume_samples: 200_000,
            seed: 1,
            solver_tolerance: 1e-8,
            max_solver_iterations: 200,
            linear_solver: KktSolver::default(),
        }
    }
}

impl ContainmentSettings {
    /// Sets the degree 2d of p.
    pub fn with_degree(mut self, degree: usize) -> Self {
        self.degree = degree;
        self
    }

    /// Sets the degree 2k of the multipliers.
    pub fn with_multiplier_degree(mut self, degree: usize) -> Self {
        self.multiplier_degree = degree;
        self
    }

    /// Sets the Monte Carlo sample count.
    pub fn with_volume_samples(mut self, samples: usize) -> Self {
        self.volume_samples = samples;
        self
    }

    /// Sets Clarabel's tolerance.
    pub fn with_solver_tolerance(mut self, tol: Real) -> Self {
        self.solver_tolerance = tol;
        self
    }

    /// Checks every field.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree`, `multiplier_degree`, `volume_samples`,
    /// `solver_tolerance` or `max_solver_iterations`.
    pub fn validate(&self) -> Result<()> {
        if !CONTAINMENT_DEGREES.contains(&self.degree) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, got {}", self.degree)));
        }
        if !MULTIPLIER_DEGREES.contains(&self.multiplier_degree) {
            return Err(Error::invalid("multiplier_degree", format!("must be 0 or 2, got {}", self.multiplier_degree)));
        }
        super::validate_solver_fields(self.volume_samples, self.solver_tolerance, self.max_solver_iterations)
    }
}

fn add3(a: [u8; 3], b: [u8; 3]) -> [u8; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn degree3(e: [u8; 3]) -> usize {
    e.iter().map(|&v| v as usize).sum()
}

/// The containment program of paper §V in normalized coordinates, built with [`ConicBuilder`].
#[derive(Debug)]
pub struct ContainmentProblem {
    /// Half degree d of p.
    pub half_degree: usize,
    /// Side N of the Gram matrix P.
    pub gram_size: usize,
    /// Side M of the sos-convexity Gram matrix G.
    pub convexity_gram_size: usize,
    /// First column of svec(P).
    pub col_p: usize,
    /// First column of svec(G).
    pub col_g: usize,
    /// First column of the coefficients of p (graded lex, degree ≤ 2d).
    pub col_c: usize,
    /// Per body: first column of its multiplier (the scalar τᵢ, or svec(Tᵢ) for 2k = 2).
    pub col_tau: Vec<usize>,
    /// Per body: degree Dᵢ of its s.procedure polynomial.
    pub sprocedure_degrees: Vec<usize>,
    builder: ConicBuilder,
}

impl ContainmentProblem {
    /// Builds the program for half degree `d ∈ 1..=3`, multiplier degree `2k ∈ {0, 2}` and the
    /// bodies' polynomials `g` (normalized coordinates; each of degree ≥ 2).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree`, `multiplier_degree` or `bodies` (empty).
    pub fn build(d: usize, multiplier_degree: usize, g: &[Polynomial]) -> Result<Self> {
        if !(1..=3).contains(&d) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, got {}", 2 * d)));
        }
        if !MULTIPLIER_DEGREES.contains(&multiplier_degree) {
            return Err(Error::invalid("multiplier_degree", format!("must be 0 or 2, got {multiplier_degree}")));
        }
        if g.is_empty() {
            return Err(Error::invalid("bodies", "need at least one body to contain"));
        }
        let half = graded_exponents3(d);
        let n = half.len();
        let low = graded_exponents3(d - 1);
        let nl = low.len();
        let m = 3 * nl;
        let full = graded_exponents3(2 * d);
        let l = full.len();
        let mut b = ConicBuilder::new();

        // Columns: P | Z (lower triangle, packed as the upper triangle of Zᵀ) | t | c | G.
        let col_p = b.add_variables(triangle_len(n));
        let col_z = b.add_variables(triangle_len(n));
        let col_t = b.add_variables(n);
        let col_c = b.add_variables(l);
        let col_g = b.add_psd_variable(m);
        let z_col = |i: usize, j: usize| col_z + triangle_index(j, i); // Z(i, j), i ≥ j
        for i in 0..n {
            b.set_objective(col_t + i, -1.0);
        }

        // (1) c_α = Σ_{zᵢzⱼ = x^α} (2 − δᵢⱼ) Pᵢⱼ.
        let mut rows: Vec<Row> = (0..l).map(|k| vec![(col_c + k, 1.0)]).collect();
        for j in 0..n {
            for i in 0..=j {
                rows[index3(add3(half[i], half[j]))].push((col_p + triangle_index(i, j), -gram_weight(i, j)));
            }
        }
        b.add_equalities(rows, vec![0.0; l]);

        // (2) sos-convexity: yᵀ∇²p y = wᵀ G w, one row per (y-pair k ≤ l, x-monomial of degree ≤ 2d − 2).
        let lb = basis_len(3, 2 * d - 2);
        let mut rows: Vec<Row> = vec![Vec::new(); 6 * lb];
        for (ci, alpha) in full.iter().enumerate() {
            for k in 0..3 {
                for kk in k..3 {
                    let (ak, al) = (alpha[k] as usize, alpha[kk] as usize);
                    let f = if k == kk { (ak * ak.saturating_sub(1)) as Real } else { 2.0 * (ak * al) as Real };
                    if f == 0.0 {
                        continue;
                    }
                    let mut beta = *alpha;
                    beta[k] -= 1;
                    beta[kk] -= 1;
                    rows[pair_index(k, kk) * lb + index3(beta)].push((col_c + ci, f));
                }
            }
        }
        for bcol in 0..m {
            for acol in 0..=bcol {
                let (ka, ia) = (acol / nl, acol % nl);
                let (kb, ib) = (bcol / nl, bcol % nl);
                let row = pair_index(ka, kb) * lb + index3(add3(low[ia], low[ib]));
                rows[row].push((col_g + triangle_index(acol, bcol), -gram_weight(acol, bcol)));
            }
        }
        b.add_equalities(rows, vec![0.0; 6 * lb]);

        // (3) [[P, Z], [Zᵀ, diag Z]] ⪰ 0 (it implies P ⪰ 0).
        let nn = 2 * n;
        let s2 = std::f64::consts::SQRT_2;
        let mut rows: Vec<Row> = vec![Vec::new(); triangle_len(nn)];
        for j in 0..nn {
            for i in 0..=j {
                let row = &mut rows[triangle_index(i, j)];
                if j < n {
                    row.push((col_p + triangle_index(i, j), -1.0));
                } else if i < n {
                    let jz = j - n;
                    if i >= jz {
                        row.push((z_col(i, jz), -s2));
                    }
                } else if i == j {
                    row.push((z_col(i - n, i - n), -1.0));
                }
            }
        }
        b.add_rows(rows, vec![0.0; triangle_len(nn)], SupportedConeT::PSDTriangleConeT(nn));

        // (4) (tᵢ, 1, Zᵢᵢ) ∈ K_exp: Zᵢᵢ ≥ exp(tᵢ).
        for i in 0..n {
            b.add_rows(
                vec![vec![(col_t + i, -1.0)], Vec::new(), vec![(z_col(i, i), -1.0)]],
                vec![0.0, 1.0, 0.0],
                SupportedConeT::ExponentialConeT(),
            );
        }

        // (5) per body: τᵢ sos, and p + τᵢ(1 − gᵢ) + z_sᵀ Qᵢ z_s = 1 coefficient by coefficient.
        let z1 = graded_exponents3(1);
        let mut col_tau = Vec::with_capacity(g.len());
        let mut sprocedure_degrees = Vec::with_capacity(g.len());
        for gi in g {
            let deg_g = gi.degree();
            let dd = (2 * d).max(multiplier_degree + deg_g);
            let dd = dd + dd % 2;
            let zs = graded_exponents3(dd / 2);
            let ns = zs.len();
            let tau = if multiplier_degree == 0 {
                let col = b.add_variables(1);
                b.add_inequalities(vec![vec![(col, -1.0)]], vec![0.0]);
                col
            } else {
                b.add_psd_variable(z1.len())
            };
            let col_q = b.add_psd_variable(ns);
            let rows_len = basis_len(3, dd);
            let mut rows: Vec<Row> = vec![Vec::new(); rows_len];
            for (k, alpha) in full.iter().enumerate() {
                rows[index3(*alpha)].push((col_c + k, 1.0));
            }
            // h = 1 − gᵢ.
            let h: Vec<([u8; 3], Real)> = gi
                .exponents()
                .iter()
                .zip(gi.coefficients())
                .map(|(e, &c)| (*e, if degree3(*e) == 0 { 1.0 - c } else { -c }))
                .filter(|(_, c)| *c != 0.0)
                .collect();
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
                    rows[index3(add3(zs[ai], zs[bj]))].push((col_q + triangle_index(ai, bj), gram_weight(ai, bj)));
                }
            }
            let mut rhs = vec![0.0; rows_len];
            rhs[0] = 1.0;
            b.add_equalities(rows, rhs);
            col_tau.push(tau);
            sprocedure_degrees.push(dd);
        }

        Ok(Self {
            half_degree: d,
            gram_size: n,
            convexity_gram_size: m,
            col_p,
            col_g,
            col_c,
            col_tau,
            sprocedure_degrees,
            builder: b,
        })
    }

    /// Number of variables.
    pub fn num_variables(&self) -> usize {
        self.builder.num_variables()
    }

    /// Number of constraint rows.
    pub fn num_rows(&self) -> usize {
        self.builder.num_rows()
    }

    /// Solves with Clarabel.
    ///
    /// # Errors
    /// [`Error::Numerical`] when Clarabel rejects the data; a non-`Solved` status is in the answer.
    pub fn solve(&self, settings: clarabel::solver::DefaultSettings<Real>) -> Result<crate::conic::ConicSolution> {
        self.builder.solve(settings)
    }

    /// p = z(x)ᵀ P z(x) from a solution, in the graded-lex basis of degree 2d.
    ///
    /// # Errors
    /// [`Error::Numerical`] when a coefficient is not finite.
    pub fn polynomial(&self, x: &[Real]) -> Result<Polynomial> {
        let p = unpack_triangle(&x[self.col_p..self.col_p + triangle_len(self.gram_size)], self.gram_size);
        let half = graded_exponents3(self.half_degree);
        let mut c = vec![0.0; basis_len(3, 2 * self.half_degree)];
        for j in 0..half.len() {
            for i in 0..=j {
                c[index3(add3(half[i], half[j]))] += if i == j { 1.0 } else { 2.0 } * p[(i, j)];
            }
        }
        Polynomial::from_coefficients(2 * self.half_degree, c)
            .map_err(|e| Error::Numerical(format!("the solver returned an unusable Gram matrix: {e}")))
    }

    /// The sos-convexity Gram matrix G (M × M) from a solution.
    pub fn convexity_gram(&self, x: &[Real]) -> nalgebra::DMatrix<Real> {
        let len = triangle_len(self.convexity_gram_size);
        unpack_triangle(&x[self.col_g..self.col_g + len], self.convexity_gram_size)
    }
}

/// Maps every Clarabel status explicitly (as the point fit does).
fn usable_status(status: SolverStatus) -> Result<&'static str> {
    let why = match status {
        SolverStatus::Solved => return Ok("Solved"),
        SolverStatus::AlmostSolved => return Ok("AlmostSolved"),
        SolverStatus::Unsolved => "Unsolved (the solver did not run)",
        SolverStatus::PrimalInfeasible => "PrimalInfeasible (no p of this degree passes the S-procedure)",
        SolverStatus::DualInfeasible => "DualInfeasible (log det unbounded)",
        SolverStatus::AlmostPrimalInfeasible => "AlmostPrimalInfeasible",
        SolverStatus::AlmostDualInfeasible => "AlmostDualInfeasible",
        SolverStatus::MaxIterations => "MaxIterations (raise max_solver_iterations)",
        SolverStatus::MaxTime => "MaxTime",
        SolverStatus::NumericalError => "NumericalError",
        SolverStatus::InsufficientProgress => "InsufficientProgress",
        SolverStatus::CallbackTerminated => "CallbackTerminated",
    };
    Err(Error::Numerical(format!("the containment SDP ended with status {why}")))
}

/// `n` unit directions, well spread (a Fibonacci spiral).
fn directions(n: usize) -> Vec<Vector3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let th = golden * i as Real;
            Vector3::new(r * th.cos(), r * th.sin(), z)
        })
        .collect()
}

/// Points on the boundary `{p = 1}` of a posed body, in world coordinates (meters): one per ray
/// from the body's interior point along `n` well-spread directions (in the body's normalized
/// frame), found by bisection to 1e-13 of the ray parameter. Each returned point lies on the
/// outer side (p ≥ 1 up to rounding), so checking a container on them is conservative.
///
/// # Errors
/// [`Error::Numerical`] when a ray does not leave the body (p not coercive).
pub fn boundary_points(body: &Body, pose: &Isometry3, n: usize) -> Result<Vec<Point3>> {
    let posed = body.posed(pose);
    let p = body.polynomial();
    let u0 = (body.interior_point().coords - body.center()) / body.scale();
    let mut out = Vec::with_capacity(n);
    for dir in directions(n) {
        let mut hi = 1.0;
        let mut tries = 0;
        while p.value(&(u0 + dir * hi)) <= 1.0 {
            hi *= 2.0;
            tries += 1;
            if tries > 60 {
                return Err(Error::Numerical("a ray from the interior point never leaves the body".into()));
            }
        }
        let mut lo = 0.0;
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if p.value(&(u0 + dir * mid)) <= 1.0 {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo < 1e-13 * hi {
                break;
            }
        }
        out.push(Point3::from(posed.from_normalized(&(u0 + dir * hi))));
    }
    Ok(out)
}

/// World-frame axis-aligned box containing a posed body: the body-frame box of
/// [`volume::bounding_box`] with its 8 corners mapped by the pose.
fn world_box(body: &Body, pose: &Isometry3) -> Result<(Vector3, Vector3)> {
    body.world_aabb(pose).ok_or_else(|| Error::Numerical("no bounding box for a nonconvex body".into()))
}

/// Finds one sos-convex body `{x : p((x − c)/s) ≤ 1}` of degree 2d containing every posed body
/// (paper §V, eqs. "p.sosconvex", "s.procedure", "tau.sos"), maximizing log det P.
///
/// `bodies` are `(body, pose)` pairs (pose: body frame → world, meters). The result lives in world
/// coordinates (use it at identity pose); its center c and scale s are the midpoint and half
/// diagonal of the union of the bodies' bounding boxes. Its report holds method `"containment"`,
/// the solver status, times, the number of boundary samples checked (`num_points`), the largest
/// p on them and the rescale that made it ≤ 1, the Monte Carlo volume, the convexity margin, and
/// notes with m, 2d and 2k. Progress is reported through `progress` (stages Hull = normalizing,
/// Build, Solve, Verify, Volume, Done).
///
/// # Errors
/// [`Error::InvalidArgument`] naming a settings field or `bodies` (empty, or a non-finite pose
/// `bodies[i].pose`); [`Error::ResourceExhausted`] above [`MAX_CONTAINED_BODIES`] bodies;
/// [`Error::Numerical`] when Clarabel ends with a status other than `Solved` / `AlmostSolved` or
/// the result is not a bounded body.
pub fn contain_bodies(
    bodies: &[(&Body, Isometry3)],
    settings: &ContainmentSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Body> {
    let start = std::time::Instant::now();
    settings.validate()?;
    if bodies.is_empty() {
        return Err(Error::invalid("bodies", "need at least one body to contain"));
    }
    if bodies.len() > MAX_CONTAINED_BODIES {
        return Err(Error::ResourceExhausted(format!(
            "at most {MAX_CONTAINED_BODIES} bodies per containment, got {}",
            bodies.len()
        )));
    }
    for (i, (body, _)) in bodies.iter().enumerate() {
        // The top-degree form of 1 − p − τᵢ(1 − gᵢ) must be nonnegative; with 2k + deg gᵢ < 2d it
        // is −p's, so p's top form would vanish and log det P = −∞ (the paper's 2k = 2d − deg gᵢ).
        if settings.multiplier_degree + body.degree() < settings.degree {
            return Err(Error::invalid(
                "multiplier_degree",
                format!(
                    "2k + deg g must be at least 2d = {}: body {i} has degree {}, so 2k must be at least {}",
                    settings.degree,
                    body.degree(),
                    settings.degree - body.degree()
                ),
            ));
        }
    }
    for (i, (_, pose)) in bodies.iter().enumerate() {
        let q = pose.rotation.quaternion();
        if !(pose.translation.vector.iter().all(|v| v.is_finite()) && q.coords.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid(format!("bodies[{i}].pose"), "must be finite"));
        }
    }

    report(progress, FitStage::Hull, 0.0, format!("normalizing: union of {} bounding boxes", bodies.len()));
    let mut lo = Vector3::repeat(Real::INFINITY);
    let mut hi = Vector3::repeat(Real::NEG_INFINITY);
    for (body, pose) in bodies {
        let (a, b) = world_box(body, pose)?;
        lo = lo.inf(&a);
        hi = hi.sup(&b);
    }
    let center = (lo + hi) * 0.5;
    let scale = 0.5 * (hi - lo).norm();
    if !(scale.is_finite() && scale > 0.0) {
        return Err(Error::Numerical(format!("the union of bounding boxes has scale {scale}")));
    }
    // gᵢ(v) = pᵢ(Aᵢ(c + s v) + bᵢ) = pᵢ((s Aᵢ) v + (Aᵢ c + bᵢ)).
    let g: Vec<Polynomial> = bodies
        .iter()
        .map(|(body, pose)| {
            let posed = body.posed(pose);
            let a = *posed.linear();
            body.polynomial().compose_affine(&(a * scale), &posed.to_normalized(&center))
        })
        .collect();

    let d = settings.degree / 2;
    report(
        progress,
        FitStage::Build,
        0.05,
        format!(
            "building the degree-{} containment program of {} bodies (multipliers of degree {})",
            settings.degree,
            bodies.len(),
            settings.multiplier_degree
        ),
    );
    let problem = ContainmentProblem::build(d, settings.multiplier_degree, &g)?;

    report(
        progress,
        FitStage::Solve,
        0.1,
        format!("Clarabel: {} variables, {} rows", problem.num_variables(), problem.num_rows()),
    );
    let mut clarabel = quiet_settings(settings.solver_tolerance, settings.max_solver_iterations);
    clarabel.direct_solve_method = settings.linear_solver.name().into();
    clarabel.max_threads = 1;
    let sol = problem.solve(clarabel)?;
    let status = usable_status(sol.status)?;

    let samples = BOUNDARY_SAMPLES_PER_BODY;
    report(
        progress,
        FitStage::Verify,
        0.8,
        format!(
            "Clarabel {status} in {} iterations; checking p ≤ 1 on {samples} boundary points per body",
            sol.iterations
        ),
    );
    let mut poly = problem.polynomial(&sol.x)?;
    let mut checks = Vec::with_capacity(samples * bodies.len());
    for (body, pose) in bodies {
        for x in boundary_points(body, pose, samples)? {
            checks.push((x.coords - center) / scale);
        }
    }
    let max_on = |p: &Polynomial| checks.iter().map(|v| p.value(v)).fold(Real::NEG_INFINITY, Real::max);
    let mut max_value = max_on(&poly);
    if !max_value.is_finite() || max_value <= 0.0 {
        return Err(Error::Numerical(format!("the containing polynomial has max value {max_value} on the bodies")));
    }
    let mut rescale = 1.0;
    for _ in 0..4 {
        if max_value <= 1.0 {
            break;
        }
        poly.scale(1.0 / max_value);
        rescale *= max_value;
        max_value = max_on(&poly);
    }
    if max_value > 1.0 {
        return Err(Error::Numerical(format!("could not rescale p to contain the bodies (max {max_value})")));
    }
    let margin = (problem.convexity_gram(&sol.x) / rescale)
        .symmetric_eigenvalues()
        .iter()
        .copied()
        .fold(Real::INFINITY, Real::min);

    let mut fit_report = FitReport {
        method: "containment".into(),
        solver_status: status.into(),
        solve_seconds: sol.solve_seconds,
        num_points: checks.len(),
        max_point_value: max_value,
        containment_rescale: rescale,
        convexity_margin: Some(margin),
        notes: vec![
            format!(
                "containment of m = {} bodies, 2d = {}, 2k = {} (s.procedure degrees {:?}); Clarabel {} iterations ({})",
                bodies.len(),
                settings.degree,
                settings.multiplier_degree,
                problem.sprocedure_degrees,
                sol.iterations,
                settings.linear_solver.name()
            ),
            "normalized by center = midpoint of the union of bounding boxes, scale = half its diagonal".into(),
        ],
        ..Default::default()
    };
    let body = Body::new(poly, [center.x, center.y, center.z], scale, fit_report.clone())
        .map_err(|e| Error::Numerical(format!("the containing polynomial is not a bounded convex body: {e}")))?;

    report(progress, FitStage::Volume, 0.85, format!("Monte Carlo volume, {} samples", settings.volume_samples));
    let interior = (body.interior_point().coords - center) / scale;
    let est = volume::monte_carlo_volume(body.polynomial(), &interior, settings.volume_samples, settings.seed)?;
    let s3 = scale.powi(3);
    fit_report.volume = est.volume * s3;
    fit_report.volume_std_error = est.std_error * s3;
    fit_report.total_seconds = start.elapsed().as_secs_f64();
    let mut body = body;
    body.report = fit_report;
    report(
        progress,
        FitStage::Done,
        1.0,
        format!("volume {:.4} ± {:.4}", body.report.volume, body.report.volume_std_error),
    );
    Ok(body)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::ellipsoid;

    #[test]
    fn settings_and_inputs_are_validated_by_field() {
        let e = ellipsoid([0.0; 3], [1.0; 3]).unwrap();
        let one = [(&e, Isometry3::identity())];
        for (s, field) in [
            (ContainmentSettings::default().with_degree(3), "degree"),
            (ContainmentSettings::default().with_degree(8), "degree"),
            (ContainmentSettings::default().with_multiplier_degree(1), "multiplier_degree"),
            (ContainmentSettings::default().with_multiplier_degree(4), "multiplier_degree"),
            (ContainmentSettings::default().with_volume_samples(0), "volume_samples"),
            (ContainmentSettings::default().with_solver_tolerance(Real::NAN), "solver_tolerance"),
        ] {
            match contain_bodies(&one, &s, &mut |_| {}) {
                Err(Error::InvalidArgument { field: f, .. }) => assert_eq!(f, field),
                other => panic!("expected InvalidArgument({field}), got {other:?}"),
            }
        }
        match contain_bodies(&[], &ContainmentSettings::default(), &mut |_| {}) {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "bodies"),
            other => panic!("expected InvalidArgument(bodies), got {other:?}"),
        }
        let many: Vec<(&Body, Isometry3)> = (0..=MAX_CONTAINED_BODIES).map(|_| (&e, Isometry3::identity())).collect();
        assert!(matches!(
            contain_bodies(&many, &ContainmentSettings::default(), &mut |_| {}),
            Err(Error::ResourceExhausted(_))
        ));
    }
}
