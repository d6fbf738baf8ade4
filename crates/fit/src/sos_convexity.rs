//! The sos-convexity certificate of a given polynomial (paper §II, Definition of sos-convexity):
//! is `yᵀ∇²p(x) y` a sum of squares, and by what margin?
//!
//! ```text
//! maximize    t
//! subject to  yᵀ ∇²p(x) y = w(x, y)ᵀ (G' + t I) w(x, y),   G' ⪰ 0,   w = y ⊗ z_{d−1}(x)
//! ```
//!
//! One equality row per y-pair `k ≤ l` and monomial x^β of degree ≤ 2d − 2 (the same identities
//! the fits impose, here with p fixed, so the Hessian side is the right-hand side). The program is
//! always feasible (t → −∞) and bounded (`t ‖w‖² ≤ yᵀ∇²p y` at every (x, y)), so its optimum t* is
//! the largest multiple of `Σ y_k² Σ zᵢ(x)²` that can be taken from the Hessian form while it
//! stays sos: t* ≥ 0 certifies p sos-convex (hence convex), and t* is the *convexity margin* the
//! fits report (`FitReport::convexity_margin`, the smallest eigenvalue of the Gram matrix they
//! found). Uploaded bodies are checked with it before they are stored.
//!
//! Sizes: G' is M × M with M = 3·C(d+2, 3) (3, 12, 30, 60 at 2d = 2, 4, 6, 8), with 6·C(2d+1, 3)
//! equality rows (60, 210, 504 at 2d = 4, 6, 8). Measured on the bundled chair bodies (test
//! profile, machine loaded): 0.04 s at 2d = 4, 1.4 s at 2d = 6, 30 s at 2d = 8 — the equality rows
//! couple to the dense G block in every factorization (the fits avoid that by solving the
//! identities into G's affine image; this check keeps them as rows). Callers run it off the
//! async workers; fit jobs never pay it (their bodies carry the certificate of their own SDP).

use super::sdp::identities::{add3, for_each_hessian_term};
use super::sdp::pair_index;
use crate::{Error, Result};
use sublevel_core::conic::{ConicBuilder, Row, SdpStatus};
use sublevel_core::math::Real;
use sublevel_core::poly::gram::{gram_weight, triangle_index};
use sublevel_core::poly::monomial::{basis_len, graded_exponents3, index3};
use sublevel_core::poly::Polynomial;

/// Relative tolerance on the margin: t* ≥ −`SOS_CONVEXITY_TOLERANCE` × (largest |Hessian
/// coefficient|) counts as sos-convex (the solver's own accuracy is about 1e-9 relative).
pub const SOS_CONVEXITY_TOLERANCE: Real = 1e-7;

/// The outcome of [`sos_convexity_margin`].
#[derive(Clone, Debug, PartialEq)]
pub struct SosConvexity {
    /// The optimal margin t* (normalized coordinates; same units as the coefficients of p).
    pub margin: Real,
    /// Largest |coefficient| of yᵀ∇²p y, the scale `margin` is compared with.
    pub hessian_scale: Real,
    /// True when `margin ≥ −SOS_CONVEXITY_TOLERANCE × hessian_scale` and the solve succeeded.
    pub certified: bool,
    /// Clarabel's final status (`NotRun` when p has no quadratic part to certify).
    pub solver_status: SdpStatus,
    /// Seconds inside Clarabel.
    pub solve_seconds: Real,
}

/// Solves the program of the module docs for `p` (degree 2d ∈ {2, 4, 6, 8}, normalized
/// coordinates).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `degree` for a degree outside {2, 4, 6, 8};
/// [`Error::Numerical`] when Clarabel rejects the problem. A solve that ends without a usable
/// status is not an error: it returns `certified = false` with the status.
pub fn sos_convexity_margin(p: &Polynomial) -> Result<SosConvexity> {
    let degree = p.degree();
    if !sublevel_core::body::SUPPORTED_DEGREES.contains(&degree) {
        return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {degree}")));
    }
    let d = degree / 2;
    let low = graded_exponents3(d - 1);
    let nl = low.len();
    let m = 3 * nl;
    let lb = basis_len(3, degree - 2);

    // Right-hand side: the coefficients of yᵀ∇²p y, by (y-pair, x-monomial of degree ≤ 2d − 2).
    let mut rhs = vec![0.0; 6 * lb];
    let coefficients = p.coefficients();
    for_each_hessian_term(d, |row, ci, f| rhs[row] += f * coefficients[ci]);
    let hessian_scale = rhs.iter().fold(0.0, |a: Real, v| a.max(v.abs()));
    if hessian_scale == 0.0 {
        // p is affine: no Hessian, not a body (its sublevel sets are half-spaces).
        return Ok(SosConvexity {
            margin: 0.0,
            hessian_scale,
            certified: false,
            solver_status: SdpStatus::NotRun,
            solve_seconds: 0.0,
        });
    }
    // Scale the rows so the program is solved in units of the largest coefficient.
    let inv = 1.0 / hessian_scale;

    let mut b = ConicBuilder::new();
    let col_t = b.add_variables(1);
    let col_g = b.add_psd_variable(m);
    b.set_objective(col_t, -1.0);
    let mut rows: Vec<Row> = vec![Vec::new(); 6 * lb];
    for bcol in 0..m {
        for acol in 0..=bcol {
            let (ka, ia) = (acol / nl, acol % nl);
            let (kb, ib) = (bcol / nl, bcol % nl);
            let row = pair_index(ka, kb) * lb + index3(add3(low[ia], low[ib]));
            rows[row].push((col_g + triangle_index(acol, bcol), gram_weight(acol, bcol)));
        }
    }
    // t · wᵀ I w = t Σ_k y_k² Σ_i z_i(x)².
    for k in 0..3 {
        for z in &low {
            rows[pair_index(k, k) * lb + index3(add3(*z, *z))].push((col_t, 1.0));
        }
    }
    b.add_equalities(rows, rhs.iter().map(|v| v * inv).collect());
    // The fits' solver choices (faer's supernodal LDLᵀ for the dense G block, static
    // regularization, step fraction): QDLDL took 2.2 s at 2d = 6 and 122 s at 2d = 8 here.
    let settings = super::SolverSettings {
        tolerance: 1e-8,
        max_iterations: 100,
        iterative_refinement: true,
        ..Default::default()
    };
    let sol = b.solve(settings.clarabel())?;
    let margin = sol.x[col_t] * hessian_scale;
    let usable = sol.usable() && margin.is_finite();
    Ok(SosConvexity {
        margin,
        hessian_scale,
        certified: usable && margin >= -SOS_CONVEXITY_TOLERANCE * hessian_scale,
        solver_status: sol.status.into(),
        solve_seconds: sol.solve_seconds,
    })
}

/// A direction along which p does not grow to +∞, among `n` nearly uniform unit directions and
/// their opposites (a Fibonacci sphere), or `None`.
///
/// Along a ray, `p(t·u) = Σₖ aₖ(u) tᵏ` with `aₖ(u) = Σ_{|α| = k} c_α u^α`; p → +∞ along it iff the
/// highest-order coefficient that is not negligible (|aₖ| > 1e-12 · max |c|) has even k and is
/// positive. {p ≤ 1} is bounded when that holds on every ray; one failing direction proves it
/// unbounded. Used for bodies that are not sos-convex, where the positive-definite Hessian at the
/// minimizer does not imply boundedness (for a convex p it does).
pub fn unbounded_direction(p: &Polynomial, n: usize) -> Option<[Real; 3]> {
    let degree = p.degree();
    let scale = p.coefficients().iter().fold(0.0, |a: Real, c| a.max(c.abs()));
    let golden = std::f64::consts::PI * (3.0 - (5.0 as Real).sqrt());
    let n = n.max(2);
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = golden * i as Real;
        for sign in [1.0, -1.0] {
            let u = [sign * r * phi.cos(), sign * r * phi.sin(), sign * z];
            let mut a = vec![0.0; degree + 1];
            for (e, &c) in p.exponents().iter().zip(p.coefficients()) {
                let k = e.iter().map(|&v| v as usize).sum::<usize>();
                a[k] += c * u[0].powi(e[0] as i32) * u[1].powi(e[1] as i32) * u[2].powi(e[2] as i32);
            }
            let lead = a.iter().enumerate().rev().find(|(_, v)| v.abs() > 1e-12 * scale);
            match lead {
                Some((k, v)) if k % 2 == 0 && k > 0 && *v > 0.0 => {}
                _ => return Some(u),
            }
        }
    }
    None
}

/// Directions sampled by [`admit_uploaded`] for the boundedness check of a nonconvex body.
pub const BOUNDEDNESS_DIRECTIONS: usize = 4096;

/// What [`admit_uploaded`] found.
#[derive(Clone, Debug)]
pub struct Admission {
    /// The validated body (its report updated: `nonconvex`, `convexity_margin`, a note).
    pub body: sublevel_core::Body,
    /// The certificate, when one was solved (not for bodies uploaded as nonconvex).
    pub certificate: Option<SosConvexity>,
}

/// Admits a body sent by a client: every figure of its report finite, its sos-convexity
/// certified ([`sos_convexity_margin`]) unless the report already says `nonconvex`, a body that
/// fails the certificate stored as nonconvex (so its answers are SDP lower bounds, never Newton
/// optima), and a nonconvex body's sublevel set bounded ([`unbounded_direction`] over
/// [`BOUNDEDNESS_DIRECTIONS`] directions). Then the
/// checks of [`sublevel_core::Body::from_file`].
///
/// Runs an SDP (milliseconds to a few tenths of a second): call it off the async workers.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `report.<field>` for a non-finite figure, `coefficients` for
/// an unbounded or empty sublevel set, or any field [`sublevel_core::Body::from_file`] names;
/// [`Error::Numerical`] when Clarabel rejects the certificate program.
pub fn admit_uploaded(mut file: sublevel_core::body::BodyFile) -> Result<Admission> {
    file.report.check_finite("report")?;
    if file.exponents.len() != file.coefficients.len() {
        return Err(Error::invalid(
            "coefficients",
            format!("{} coefficients for {} exponents", file.coefficients.len(), file.exponents.len()),
        ));
    }
    if !sublevel_core::body::SUPPORTED_DEGREES.contains(&file.degree) {
        return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {}", file.degree)));
    }
    let terms: Vec<([u8; 3], Real)> = file.exponents.iter().copied().zip(file.coefficients.iter().copied()).collect();
    let p = Polynomial::from_terms(file.degree, &terms)?;
    let mut certificate = None;
    if !file.report.nonconvex {
        let c = sos_convexity_margin(&p)?;
        file.report.convexity_margin = Some(c.margin);
        if c.certified {
            file.report.notes.push(format!(
                "upload: sos-convexity certified, margin {:.3e} (Clarabel {})",
                c.margin, c.solver_status
            ));
        } else {
            file.report.nonconvex = true;
            file.report.notes.push(format!(
                "upload: not sos-convex (certificate margin {:.3e}, Clarabel {}): stored as nonconvex; \
                 queries answer with level-0 SDP lower bounds",
                c.margin, c.solver_status
            ));
        }
        certificate = Some(c);
    }
    if file.report.nonconvex {
        if let Some(dir) = unbounded_direction(&p, BOUNDEDNESS_DIRECTIONS) {
            return Err(Error::invalid(
                "coefficients",
                format!(
                    "the sublevel set {{p ≤ 1}} is unbounded: p does not grow along the direction \
                     ({:.3}, {:.3}, {:.3}) of the normalized coordinates",
                    dir[0], dir[1], dir[2]
                ),
            ));
        }
    }
    let body = sublevel_core::Body::from_file(file)?;
    Ok(Admission { body, certificate })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ‖u‖² (a ball) is sos-convex with margin exactly 2: yᵀ∇²p y = 2‖y‖² = 2 wᵀIw at 2d = 2.
    #[test]
    fn ball_margin_is_the_closed_form() {
        let p = Polynomial::from_terms(2, &[([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0)]).unwrap();
        let c = sos_convexity_margin(&p).unwrap();
        assert!(c.certified, "{c:?}");
        assert!((c.margin - 2.0).abs() < 1e-6, "{c:?}");
    }

    /// ‖u‖⁴ is sos-convex (a classic example); u⁴ + v⁴ + w⁴ too; ‖u‖² − u⁴ is not convex
    /// (∂²/∂u² = 2 − 12u² < 0 for |u| > 0.41) and its certificate fails clearly.
    #[test]
    fn quartics_convex_and_not() {
        let norm4 = Polynomial::from_terms(
            4,
            &[
                ([4, 0, 0], 1.0),
                ([0, 4, 0], 1.0),
                ([0, 0, 4], 1.0),
                ([2, 2, 0], 2.0),
                ([2, 0, 2], 2.0),
                ([0, 2, 2], 2.0),
            ],
        )
        .unwrap();
        let c = sos_convexity_margin(&norm4).unwrap();
        assert!(c.certified, "{c:?}");
        let bad = Polynomial::from_terms(4, &[([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0), ([4, 0, 0], -1.0)])
            .unwrap();
        let c = sos_convexity_margin(&bad).unwrap();
        assert!(!c.certified, "{c:?}");
        assert!(c.margin < -0.1 * c.hessian_scale, "{c:?}");
        // −u⁴ wins along the u axis: unbounded sublevel set, found near that axis.
        let dir = unbounded_direction(&bad, 2000).expect("unbounded");
        let far = sublevel_core::math::Vector3::from(dir) * 1e4;
        assert!(bad.value(&far) < -1.0, "p must fall without bound along {dir:?}");
        assert_eq!(unbounded_direction(&norm4, 2000), None);
        // A "jack" ‖u‖² + 30(u²v² + v²w² + u²w²): its quartic part vanishes on the axes, where the
        // quadratic part still grows, so it is bounded (and not sos-convex).
        let k = 30.0;
        let jack = Polynomial::from_terms(
            4,
            &[([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0), ([2, 2, 0], k), ([0, 2, 2], k), ([2, 0, 2], k)],
        )
        .unwrap();
        assert_eq!(unbounded_direction(&jack, 4096), None);
        assert!(!sos_convexity_margin(&jack).unwrap().certified);
        // An affine p is no body; a cubic term makes one side of every ray it touches unbounded.
        let cubic =
            Polynomial::from_terms(4, &[([4, 0, 0], 1.0), ([0, 4, 0], 1.0), ([0, 0, 4], 1.0), ([3, 0, 0], 1.0)])
                .unwrap();
        assert_eq!(unbounded_direction(&cubic, 4096), None, "x⁴ dominates x³ on every ray");
    }
}
