//! Dense trivariate polynomials in the graded-lex monomial basis, with allocation-free value,
//! gradient and Hessian evaluation.
//!
//! ```text
//! p(u) = Σₖ cₖ · u₁^aₖ u₂^bₖ u₃^cₖ,     k over the graded-lex basis of degree ≤ deg
//! ∂p/∂uᵢ, ∂²p/∂uᵢ∂uⱼ by differentiating each monomial (exact; no finite differences)
//! ```
//!
//! Evaluation builds the power tables `u^0 … u^deg` once per call (and their first and second
//! derivatives), so each term costs a handful of multiplications and nothing is allocated. Rigid
//! motions never expand the polynomial on the query path (paper §IV-C): the caller maps the query
//! point into the body frame instead ([`crate::body::PosedBody`]). [`Polynomial::compose_affine`]
//! exists only for building SDP certificates.

use super::monomial::{basis_len, graded_exponents3, index3};
use super::FastPoly;
use crate::math::{Matrix3, Real, Vector3};
use serde::{Deserialize, Serialize};

pub use sublevel_kernels::MAX_DEGREE;

/// A trivariate polynomial of total degree ≤ `degree`, dense in the graded-lex basis.
///
/// Serialized as `{degree, coefficients}`; deserializing goes through
/// [`Polynomial::from_coefficients`], so a read polynomial is validated and has its exponent table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "PolynomialData")]
pub struct Polynomial {
    degree: usize,
    /// Coefficients in graded-lex order; length `C(degree + 3, 3)`.
    coefficients: Vec<Real>,
    /// Exponents of the basis, cached so evaluation does not recompute them.
    #[serde(skip, default)]
    exponents: Vec<[u8; 3]>,
}

/// The serialized fields of a [`Polynomial`], validated on the way in.
#[derive(Deserialize)]
struct PolynomialData {
    degree: usize,
    coefficients: Vec<Real>,
}

impl TryFrom<PolynomialData> for Polynomial {
    type Error = crate::Error;

    fn try_from(d: PolynomialData) -> crate::Result<Self> {
        Polynomial::from_coefficients(d.degree, d.coefficients)
    }
}

pub use sublevel_kernels::Eval;

impl Polynomial {
    /// The zero polynomial of degree bound `degree` (≤ [`MAX_DEGREE`]).
    ///
    /// # Panics
    /// Never for `degree ≤ MAX_DEGREE`; larger degrees are clamped by the callers' validation.
    pub fn zero(degree: usize) -> Self {
        let degree = degree.min(MAX_DEGREE);
        Self { degree, coefficients: vec![0.0; basis_len(3, degree)], exponents: graded_exponents3(degree) }
    }

    /// Builds a polynomial from graded-lex coefficients (length `C(degree + 3, 3)`).
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] when `degree > 8`, the length is wrong, or a coefficient is
    /// not finite.
    pub fn from_coefficients(degree: usize, coefficients: Vec<Real>) -> crate::Result<Self> {
        if degree > MAX_DEGREE {
            return Err(crate::Error::invalid("degree", format!("must be at most {MAX_DEGREE}, got {degree}")));
        }
        let n = basis_len(3, degree);
        if coefficients.len() != n {
            return Err(crate::Error::invalid(
                "coefficients",
                format!("degree {degree} needs {n} coefficients, got {}", coefficients.len()),
            ));
        }
        if let Some(i) = coefficients.iter().position(|c| !c.is_finite()) {
            return Err(crate::Error::invalid("coefficients", format!("entry {i} is not finite")));
        }
        Ok(Self { degree, coefficients, exponents: graded_exponents3(degree) })
    }

    /// Builds a polynomial from `(exponent, coefficient)` terms; repeated exponents add up.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] when an exponent's total degree exceeds `degree`, or
    /// `degree > 8`, or a coefficient is not finite.
    pub fn from_terms(degree: usize, terms: &[([u8; 3], Real)]) -> crate::Result<Self> {
        if degree > MAX_DEGREE {
            return Err(crate::Error::invalid("degree", format!("must be at most {MAX_DEGREE}, got {degree}")));
        }
        let mut p = Self::zero(degree);
        for (i, (e, c)) in terms.iter().enumerate() {
            let k = e.iter().map(|&v| v as usize).sum::<usize>();
            if k > degree {
                return Err(crate::Error::invalid(
                    format!("exponents[{i}]"),
                    format!("monomial {e:?} has degree {k} > {degree}"),
                ));
            }
            if !c.is_finite() {
                return Err(crate::Error::invalid(format!("coefficients[{i}]"), "not finite"));
            }
            p.coefficients[index3(*e)] += c;
        }
        Ok(p)
    }

    /// The degree bound of the basis (the polynomial's true degree may be lower).
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Coefficients in graded-lex order.
    pub fn coefficients(&self) -> &[Real] {
        &self.coefficients
    }

    /// Mutable coefficients in graded-lex order.
    pub fn coefficients_mut(&mut self) -> &mut [Real] {
        &mut self.coefficients
    }

    /// Exponent triples of the basis, parallel to [`Self::coefficients`].
    pub fn exponents(&self) -> &[[u8; 3]] {
        &self.exponents
    }

    /// Restores the cached exponent table after deserialization.
    pub fn rebuild_cache(&mut self) {
        self.exponents = graded_exponents3(self.degree);
    }

    /// p(u).
    pub fn value(&self, u: &Vector3) -> Real {
        let (px, py, pz) = (powers(u.x, self.degree), powers(u.y, self.degree), powers(u.z, self.degree));
        let mut acc = 0.0;
        for (c, e) in self.coefficients.iter().zip(&self.exponents) {
            acc += c * px[e[0] as usize] * py[e[1] as usize] * pz[e[2] as usize];
        }
        acc
    }

    /// p(u) and ∇p(u).
    pub fn value_gradient(&self, u: &Vector3) -> (Real, Vector3) {
        let d = self.degree;
        let (px, py, pz) = (powers(u.x, d), powers(u.y, d), powers(u.z, d));
        let (dx, dy, dz) = (dpowers(&px, d), dpowers(&py, d), dpowers(&pz, d));
        let (mut v, mut g) = (0.0, [0.0; 3]);
        for (c, e) in self.coefficients.iter().zip(&self.exponents) {
            let (a, b, cc) = (e[0] as usize, e[1] as usize, e[2] as usize);
            let yz = py[b] * pz[cc];
            v += c * px[a] * yz;
            g[0] += c * dx[a] * yz;
            g[1] += c * px[a] * dy[b] * pz[cc];
            g[2] += c * px[a] * py[b] * dz[cc];
        }
        (v, Vector3::new(g[0], g[1], g[2]))
    }

    /// p(u), ∇p(u) and ∇²p(u), exactly and without allocating.
    pub fn eval(&self, u: &Vector3) -> Eval {
        let d = self.degree;
        let (px, py, pz) = (powers(u.x, d), powers(u.y, d), powers(u.z, d));
        let (dx, dy, dz) = (dpowers(&px, d), dpowers(&py, d), dpowers(&pz, d));
        let (ddx, ddy, ddz) = (ddpowers(&px, d), ddpowers(&py, d), ddpowers(&pz, d));
        let mut v = 0.0;
        let mut g = [0.0; 3];
        let mut h = [0.0; 6]; // xx, xy, xz, yy, yz, zz
        for (c, e) in self.coefficients.iter().zip(&self.exponents) {
            if *c == 0.0 {
                continue;
            }
            let (a, b, cc) = (e[0] as usize, e[1] as usize, e[2] as usize);
            let (x0, y0, z0) = (px[a], py[b], pz[cc]);
            let (x1, y1, z1) = (dx[a], dy[b], dz[cc]);
            v += c * x0 * y0 * z0;
            g[0] += c * x1 * y0 * z0;
            g[1] += c * x0 * y1 * z0;
            g[2] += c * x0 * y0 * z1;
            h[0] += c * ddx[a] * y0 * z0;
            h[1] += c * x1 * y1 * z0;
            h[2] += c * x1 * y0 * z1;
            h[3] += c * x0 * ddy[b] * z0;
            h[4] += c * x0 * y1 * z1;
            h[5] += c * x0 * y0 * ddz[cc];
        }
        Eval {
            value: v,
            gradient: Vector3::new(g[0], g[1], g[2]),
            hessian: Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]),
        }
    }

    /// Product of two polynomials, truncated to nothing (the degree bound is the sum, ≤ 8).
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] when the sum of degree bounds exceeds 8.
    pub fn mul(&self, other: &Polynomial) -> crate::Result<Polynomial> {
        let deg = self.degree + other.degree;
        if deg > MAX_DEGREE {
            return Err(crate::Error::invalid("degree", format!("product degree {deg} exceeds {MAX_DEGREE}")));
        }
        let mut out = Polynomial::zero(deg);
        for (ci, ei) in self.coefficients.iter().zip(&self.exponents) {
            if *ci == 0.0 {
                continue;
            }
            for (cj, ej) in other.coefficients.iter().zip(&other.exponents) {
                if *cj == 0.0 {
                    continue;
                }
                out.coefficients[index3([ei[0] + ej[0], ei[1] + ej[1], ei[2] + ej[2]])] += ci * cj;
            }
        }
        Ok(out)
    }

    /// q(x) = p(A x + b): the polynomial composed with an affine map, expanded in the graded-lex
    /// basis of the same degree. Used to state SDP certificates in one frame; never on the query
    /// path.
    pub fn compose_affine(&self, a: &Matrix3, b: &Vector3) -> Polynomial {
        let d = self.degree;
        // Linear forms Lᵢ(x) = Aᵢ·x + bᵢ and their powers Lᵢ^k, k = 0..=d.
        let mut pw: Vec<Vec<Polynomial>> = Vec::with_capacity(3);
        for i in 0..3 {
            let li = Polynomial::from_terms(
                1,
                &[([0, 0, 0], b[i]), ([1, 0, 0], a[(i, 0)]), ([0, 1, 0], a[(i, 1)]), ([0, 0, 1], a[(i, 2)])],
            )
            .unwrap_or_else(|_| Polynomial::zero(1));
            let mut list = vec![Polynomial::from_terms(0, &[([0, 0, 0], 1.0)]).unwrap_or_else(|_| Polynomial::zero(0))];
            for k in 1..=d {
                let next = list[k - 1].mul(&li).unwrap_or_else(|_| Polynomial::zero(k));
                list.push(next);
            }
            pw.push(list);
        }
        let mut out = Polynomial::zero(d);
        for (c, e) in self.coefficients.iter().zip(&self.exponents) {
            if *c == 0.0 {
                continue;
            }
            let xy = pw[0][e[0] as usize].mul(&pw[1][e[1] as usize]).unwrap_or_else(|_| Polynomial::zero(0));
            let xyz = xy.mul(&pw[2][e[2] as usize]).unwrap_or_else(|_| Polynomial::zero(0));
            for (cc, ee) in xyz.coefficients.iter().zip(&xyz.exponents) {
                out.coefficients[index3(*ee)] += c * cc;
            }
        }
        out
    }

    /// Multiplies every coefficient by `s`.
    pub fn scale(&mut self, s: Real) {
        self.coefficients.iter_mut().for_each(|c| *c *= s);
    }
}

/// `[t^0, t^1, …, t^d, 0, …]`.
#[inline(always)]
fn powers(t: Real, d: usize) -> [Real; MAX_DEGREE + 1] {
    let mut p = [0.0; MAX_DEGREE + 1];
    p[0] = 1.0;
    for k in 1..=d {
        p[k] = p[k - 1] * t;
    }
    p
}

/// `[0, 1, 2t, 3t², …]`: derivatives of the powers.
#[inline(always)]
fn dpowers(p: &[Real; MAX_DEGREE + 1], d: usize) -> [Real; MAX_DEGREE + 1] {
    let mut q = [0.0; MAX_DEGREE + 1];
    for k in 1..=d {
        q[k] = k as Real * p[k - 1];
    }
    q
}

/// `[0, 0, 2, 6t, …]`: second derivatives of the powers.
#[inline(always)]
fn ddpowers(p: &[Real; MAX_DEGREE + 1], d: usize) -> [Real; MAX_DEGREE + 1] {
    let mut q = [0.0; MAX_DEGREE + 1];
    for k in 2..=d {
        q[k] = (k * (k - 1)) as Real * p[k - 2];
    }
    q
}

impl Polynomial {
    /// The fast evaluator of this polynomial ([`FastPoly`], the query hot path's kernels).
    pub fn fast(&self) -> FastPoly {
        FastPoly::new(self.degree(), self.coefficients())
    }
}

#[cfg(test)]
mod tests {
    /// A deserialized polynomial is validated and evaluates like the original (its exponent
    /// table is rebuilt, not left empty); a wrong coefficient count is refused.
    #[test]
    fn deserialized_polynomial_is_validated_and_evaluates() {
        let p = Polynomial::from_coefficients(2, (0..10).map(|k| k as Real * 0.5 - 1.0).collect()).unwrap();
        let back: Polynomial = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
        let u = Vector3::new(0.3, -0.7, 1.1);
        assert_eq!(back.value(&u), p.value(&u));
        let short = r#"{"degree":2,"coefficients":[1.0,2.0]}"#;
        assert!(serde_json::from_str::<Polynomial>(short).is_err());
    }

    use super::*;

    fn sample() -> Polynomial {
        // p = 1 + 2x - y z + 3 x^2 y^2 + x^4 + z^6 - 0.5 x y z^3
        Polynomial::from_terms(
            6,
            &[
                ([0, 0, 0], 1.0),
                ([1, 0, 0], 2.0),
                ([0, 1, 1], -1.0),
                ([2, 2, 0], 3.0),
                ([4, 0, 0], 1.0),
                ([0, 0, 6], 1.0),
                ([1, 1, 3], -0.5),
            ],
        )
        .unwrap()
    }

    fn closed_form(u: &Vector3) -> Real {
        let (x, y, z) = (u.x, u.y, u.z);
        1.0 + 2.0 * x - y * z + 3.0 * x * x * y * y + x.powi(4) + z.powi(6) - 0.5 * x * y * z.powi(3)
    }

    #[test]
    fn value_matches_closed_form() {
        let p = sample();
        for u in [Vector3::new(0.3, -0.7, 1.1), Vector3::new(-1.2, 0.4, 0.0), Vector3::zeros()] {
            assert!((p.value(&u) - closed_form(&u)).abs() < 1e-12);
            assert!((p.eval(&u).value - closed_form(&u)).abs() < 1e-12);
        }
    }

    #[test]
    fn gradient_and_hessian_match_central_differences() {
        let p = sample();
        let u = Vector3::new(0.3, -0.7, 1.1);
        let e = p.eval(&u);
        let h = 1e-5;
        for i in 0..3 {
            let mut up = u;
            let mut um = u;
            up[i] += h;
            um[i] -= h;
            let fd = (closed_form(&up) - closed_form(&um)) / (2.0 * h);
            assert!((e.gradient[i] - fd).abs() < 1e-7, "grad {i}");
            let gd = (p.eval(&up).gradient - p.eval(&um).gradient) / (2.0 * h);
            for j in 0..3 {
                assert!((e.hessian[(j, i)] - gd[j]).abs() < 1e-6, "hess {j}{i}");
            }
        }
        let (v, g) = p.value_gradient(&u);
        assert!((v - e.value).abs() < 1e-14 && (g - e.gradient).norm() < 1e-13);
    }

    #[test]
    fn compose_affine_agrees_with_pointwise_evaluation() {
        let p = sample();
        let a = Matrix3::new(0.2, -0.9, 0.1, 0.5, 0.3, -0.4, 0.0, 0.7, 1.2);
        let b = Vector3::new(0.1, -0.2, 0.3);
        let q = p.compose_affine(&a, &b);
        for x in [Vector3::new(0.3, -0.7, 1.1), Vector3::new(-1.0, 0.5, 0.2)] {
            assert!((q.value(&x) - p.value(&(a * x + b))).abs() < 1e-10);
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert!(Polynomial::from_coefficients(10, vec![]).is_err());
        assert!(Polynomial::from_coefficients(2, vec![0.0; 9]).is_err());
        assert!(Polynomial::from_coefficients(2, vec![f64::NAN; 10]).is_err());
        assert!(Polynomial::from_terms(2, &[([3, 0, 0], 1.0)]).is_err());
    }
}
