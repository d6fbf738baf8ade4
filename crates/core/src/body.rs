//! A body: the 1-sublevel set `{x : p((x − center)/scale) ≤ 1}` of a sos-convex polynomial, in the
//! mesh's own units (meters), and the same body under a rigid pose.
//!
//! ```text
//! body frame:   S = { x ∈ ℝ³ : p(u) ≤ 1 },  u = (x − c) / s          (c = center, s = scale > 0)
//! posed (R,t):  S' = { x : p(u) ≤ 1 },       u = (Rᵀ(x − t) − c) / s  (paper §IV-C)
//! ```
//!
//! A pose never touches the coefficients: [`PosedBody`] maps the query point into the normalized
//! frame with one affine map `u = A x + b` (A = Rᵀ/s, b = −(Rᵀt + c)/s), and maps derivatives back
//! (`∇ₓ = Aᵀ∇ᵤ`, `∇²ₓ = Aᵀ∇²ᵤA`).
//!
//! The JSON body file (see [`BodyFile`]) holds `degree`, `exponents`, `coefficients`, `center`,
//! `scale` and the fit `report`.

use crate::math::{Isometry3, Matrix3, Point3, Real, Vector3};
use crate::poly::{Eval, FastPoly, Polynomial, RadialTable, SupportBound, SupportTable};
use crate::{Error, Result};
use serde::{Deserialize, Serialize};

pub use crate::report::{DegreeChoice, FitReport, SolveDetails, SolverCertificate};

/// Degrees a body may have (2d ∈ {2, 4, 6, 8}).
pub const SUPPORTED_DEGREES: [usize; 4] = [2, 4, 6, 8];

/// A body's on-disk / on-wire JSON form.
///
/// `p(x) = Σₖ coefficients[k] · u^a v^b w^c` with `[a, b, c] = exponents[k]` and
/// `(u, v, w) = (x − center) / scale`, x in the mesh's units.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BodyFile {
    /// Total degree 2d ∈ {2, 4, 6, 8}.
    pub degree: usize,
    /// Exponent triples `[a, b, c]`, one per coefficient.
    pub exponents: Vec<[u8; 3]>,
    /// Coefficients, same length as `exponents`.
    pub coefficients: Vec<Real>,
    /// Normalization center `[x, y, z]` in mesh units.
    pub center: [Real; 3],
    /// Normalization scale (> 0) in mesh units.
    pub scale: Real,
    /// How the body was fitted.
    #[serde(default)]
    pub report: FitReport,
}

/// A validated body: polynomial in normalized coordinates plus its normalization.
#[derive(Clone, Debug)]
pub struct Body {
    polynomial: Polynomial,
    center: Vector3,
    scale: Real,
    /// Minimizer of p in normalized coordinates: an interior point every solver may start from.
    interior_u: Vector3,
    /// p at `interior_u` (< 1 for a body with interior).
    min_value: Real,
    /// Precomputed derivative tables of `polynomial` for the query hot path.
    fast: FastPoly,
    /// Radial function of {p ≤ 1} about `interior_u`: the boundary points of cold starts.
    radial: RadialTable,
    /// Support map of {p ≤ 1} (normalized units): the facing points of cold distance starts.
    support: SupportTable,
    /// A box containing {p ≤ 1} in normalized coordinates
    /// ([`crate::poly::support::bounding_box_from_support`], from supporting halfspaces; `None`
    /// for a nonconvex body, whose halfspaces prove nothing).
    bounding_box_u: Option<(Vector3, Vector3)>,
    /// [`Body::bounding_sphere`], computed once (the cold distance start tests it on every query).
    sphere: Option<(Point3, Real)>,
    /// The four-point table of `fast` ([`Body::soa_polynomial`]), built on first use (only the
    /// batch solvers read it).
    soa: std::sync::OnceLock<crate::poly::SoaPoly>,
    /// Certified upper bounds of the support function (normalized units), from the support map,
    /// its tangent halfspaces and the box; `None` for a nonconvex body (as the box).
    support_bound: Option<SupportBound>,
    /// Fit report.
    pub report: FitReport,
}

impl Body {
    /// Validates and builds a body from a polynomial in normalized coordinates.
    ///
    /// Checks: degree ∈ {2, 4, 6, 8}; center finite and within ±[`crate::math::MAX_COORDINATE`]; a
    /// convex body's bounding box within ±[`crate::math::MAX_COORDINATE`] too;
    /// scale in [`crate::math::SCALE_RANGE`]; coefficients finite; p has a minimizer with
    /// p < 1 there and a positive-definite Hessian (a bounded sublevel set with interior). For a
    /// body whose report says `nonconvex`, a strict local minimizer found by modified Newton from
    /// the best point of a grid over the normalized unit cube is accepted when Newton from the
    /// origin fails.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `degree`, `center`, `scale` or `coefficients`.
    pub fn new(polynomial: Polynomial, center: [Real; 3], scale: Real, report: FitReport) -> Result<Self> {
        let degree = polynomial.degree();
        if !SUPPORTED_DEGREES.contains(&degree) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {degree}")));
        }
        if center.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("center", "must be three finite numbers"));
        }
        crate::math::check_coordinates("center", &center)?;
        let (lo, hi) = crate::math::SCALE_RANGE;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(Error::invalid("scale", format!("must be finite and > 0, got {scale}")));
        }
        if !(lo..=hi).contains(&scale) {
            return Err(Error::invalid("scale", format!("must lie in [{lo:e}, {hi:e}] meters, got {scale:e}")));
        }
        if let Some(i) = polynomial.coefficients().iter().position(|c| !c.is_finite()) {
            return Err(Error::invalid("coefficients", format!("entry {i} is not finite")));
        }
        let found = minimize_convex(&polynomial).or_else(|| {
            // A nonconvex body (relaxed convexity, inverse moment): any strict local minimizer
            // with p < 1 is an interior point.
            if report.nonconvex {
                minimize_from_grid(&polynomial)
            } else {
                None
            }
        });
        let (interior_u, min_value) = found.ok_or_else(|| {
            Error::invalid(
                "coefficients",
                "p has no minimizer with positive-definite Hessian: not a bounded convex body",
            )
        })?;
        if min_value >= 1.0 {
            return Err(Error::invalid(
                "coefficients",
                format!("the sublevel set {{p ≤ 1}} is empty or flat (min p = {min_value:.6} ≥ 1)"),
            ));
        }
        let fast = polynomial.fast();
        let radial = RadialTable::new(&fast, &interior_u);
        // An ellipsoid's support map in closed form (the bounding ellipsoids of primitives, built
        // at every scene import), any other body's by search.
        let support =
            SupportTable::quadratic(&polynomial).unwrap_or_else(|| SupportTable::new(&fast, &radial, &interior_u));
        // The box's six support points come from the support table (exact nodes on the axes)
        // rather than from six new solves, which would dominate loading a compound body of many
        // nodes.
        let bounding_box_u = if report.nonconvex {
            None
        } else {
            let table = |e: &Vector3| support.support(e).ok_or_else(|| Error::Numerical("no support point".into()));
            crate::poly::support::bounding_box_from_support(&polynomial, table).ok()
        };
        let support_bound = bounding_box_u.map(|(lo, hi)| SupportBound::new(&fast, &support, &lo, &hi));
        let center = Vector3::from(center);
        let sphere = bounding_box_u
            .map(|(lo, hi)| (Point3::from(center + (lo + hi) * (0.5 * scale)), 0.5 * (hi - lo).norm() * scale));
        // The body's real size, not only its scale: tiny coefficients make {p ≤ 1} huge.
        if let Some((c, r)) = &sphere {
            let reach = c.coords.abs().max() + r;
            if reach > crate::math::MAX_COORDINATE || reach.is_nan() {
                return Err(Error::invalid(
                    "coefficients",
                    format!(
                        "the body reaches {reach:e} m from the origin, beyond ±{:e} m (p's unit sublevel set is far larger than `scale`)",
                        crate::math::MAX_COORDINATE
                    ),
                ));
            }
        }
        Ok(Self {
            polynomial,
            center,
            scale,
            interior_u,
            min_value,
            fast,
            radial,
            support,
            bounding_box_u,
            sphere,
            soa: std::sync::OnceLock::new(),
            support_bound,
            report,
        })
    }

    /// Parses and validates a body from its JSON file form.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for mismatched lengths or any check of [`Body::new`].
    pub fn from_file(file: BodyFile) -> Result<Self> {
        if file.exponents.len() != file.coefficients.len() {
            return Err(Error::invalid(
                "coefficients",
                format!("{} coefficients for {} exponents", file.coefficients.len(), file.exponents.len()),
            ));
        }
        if !SUPPORTED_DEGREES.contains(&file.degree) {
            return Err(Error::invalid("degree", format!("must be one of 2, 4, 6, 8, got {}", file.degree)));
        }
        let terms: Vec<([u8; 3], Real)> =
            file.exponents.iter().copied().zip(file.coefficients.iter().copied()).collect();
        let p = Polynomial::from_terms(file.degree, &terms)?;
        Body::new(p, file.center, file.scale, file.report)
    }

    /// The JSON file form (dense: every monomial of the basis, in graded-lex order).
    pub fn to_file(&self) -> BodyFile {
        BodyFile {
            degree: self.polynomial.degree(),
            exponents: self.polynomial.exponents().to_vec(),
            coefficients: self.polynomial.coefficients().to_vec(),
            center: [self.center.x, self.center.y, self.center.z],
            scale: self.scale,
            report: self.report.clone(),
        }
    }

    /// Reads a body file (JSON).
    ///
    /// # Errors
    /// [`Error::Io`], [`Error::Json`], or any validation error of [`Body::from_file`].
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)?;
        Body::from_file(serde_json::from_str(&text)?)
    }

    /// Writes the body file (pretty JSON).
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Json`].
    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        std::fs::write(path, serde_json::to_string_pretty(&self.to_file())?)?;
        Ok(())
    }

    /// Total degree 2d.
    pub fn degree(&self) -> usize {
        self.polynomial.degree()
    }

    /// The polynomial in normalized coordinates u = (x − center)/scale.
    pub fn polynomial(&self) -> &Polynomial {
        &self.polynomial
    }

    /// The polynomial with its gradient / Hessian coefficient tables precomputed (built once in
    /// [`Body::new`]; the query solvers evaluate through it).
    pub fn fast_polynomial(&self) -> &FastPoly {
        &self.fast
    }

    /// The polynomial's four-point evaluation table ([`crate::poly::SoaPoly`]): the kernel of the
    /// batch solvers (`sublevel_query::batch`), which evaluate four pairs of the same two bodies
    /// per pass. Built on the first call (about 1 µs at 2d = 6), then shared.
    pub fn soa_polynomial(&self) -> &crate::poly::SoaPoly {
        self.soa.get_or_init(|| crate::poly::SoaPoly::new(&self.fast))
    }

    /// Normalization center in body-frame units.
    pub fn center(&self) -> Vector3 {
        self.center
    }

    /// Normalization scale (> 0).
    pub fn scale(&self) -> Real {
        self.scale
    }

    /// Minimizer of p in the body frame (meters): a point deep inside the body.
    pub fn interior_point(&self) -> Point3 {
        Point3::from(self.center + self.interior_u * self.scale)
    }

    /// Minimum of p over ℝ³ (< 1).
    pub fn min_value(&self) -> Real {
        self.min_value
    }

    /// p at a body-frame point (meters).
    pub fn value_at(&self, x: &Point3) -> Real {
        self.polynomial.value(&((x.coords - self.center) / self.scale))
    }

    /// The support map of the body (normalized units; built once in [`Body::new`]).
    pub fn support_table(&self) -> &SupportTable {
        &self.support
    }

    /// The radial function of the body about its interior point (normalized units; built once in
    /// [`Body::new`]).
    pub fn radial_table(&self) -> &RadialTable {
        &self.radial
    }

    /// The body under a pose.
    pub fn posed(&self, pose: &Isometry3) -> PosedBody<'_> {
        PosedBody::new(self, pose)
    }

    /// A sphere containing the body, in the body frame: (center, radius) in meters — the center
    /// of its bounding box and the box's half diagonal. `None` for a nonconvex body (no proven
    /// bound). Broad phases and collide-with-margin queries test these before any solve.
    pub fn bounding_sphere(&self) -> Option<(Point3, Real)> {
        self.sphere
    }

    /// A box containing the body, axis-aligned in the body frame: its center and half extents
    /// (meters, body frame). It is the box of supporting halfspaces
    /// ([`crate::poly::support::bounding_box_from_support`]) solved when the body was built
    /// (tangent planes of the convex sublevel set, so it contains the whole set, not only sampled
    /// points); `None` for a nonconvex body. The cheap lower bounds of the tree queries
    /// (`sublevel_query::tree`) project these boxes.
    pub fn bounding_box(&self) -> Option<(Point3, Vector3)> {
        let (lo, hi) = self.bounding_box_u?;
        let c = (lo + hi) * 0.5;
        Some((Point3::from(self.center + c * self.scale), (hi - lo) * (0.5 * self.scale)))
    }

    /// An upper bound of the body's support function in the body-frame direction `n` (meters; any
    /// length, the bound scales with |n|): `≥ max{n·x : x in the body}`, from the certified
    /// support table of [`SupportBound`] (within ~1 % of the support value between its tabulated
    /// directions, exact to rounding at them). +∞ for a zero or non-finite `n`; `None` for a
    /// nonconvex body. The cheap lower bounds of the tree queries (`sublevel_query::tree`) take
    /// the separating-axis gap of two bodies from it.
    #[inline]
    pub fn support_upper(&self, n: &Vector3) -> Option<Real> {
        let bound = self.support_bound.as_ref()?;
        Some(n.dot(&self.center) + self.scale * bound.upper(n))
    }

    /// The certified support bounds of the body in normalized coordinates ([`SupportBound`]);
    /// `None` for a nonconvex body. [`SupportBound::in_frame`] with [`Body::center`] and
    /// [`Body::scale`] gives them in the body frame (meters).
    pub fn support_bound(&self) -> Option<&SupportBound> {
        self.support_bound.as_ref()
    }

    /// An estimate of the body's support point in the body-frame direction `n` (any nonzero
    /// length; meters, body frame), interpolated in its [`SupportTable`]: a point near the
    /// boundary where n·x is largest, not a certified one. `None` for a zero or non-finite `n`.
    #[inline]
    pub fn support_estimate(&self, n: &Vector3) -> Option<Point3> {
        // n·x = n·center + scale·n·u: the same direction in normalized coordinates.
        Some(Point3::from(self.center + self.support.support(n)? * self.scale))
    }

    /// The axis-aligned world box of the body under `pose` (the 8 corners of its body-frame
    /// bounding box, posed), `None` for a nonconvex body.
    pub fn world_aabb(&self, pose: &Isometry3) -> Option<(Vector3, Vector3)> {
        let (lo, hi) = self.bounding_box_u?;
        let posed = self.posed(pose);
        let mut wlo = Vector3::repeat(Real::INFINITY);
        let mut whi = Vector3::repeat(Real::NEG_INFINITY);
        for corner in 0..8 {
            let u = Vector3::from_fn(|k, _| if (corner >> k) & 1 == 0 { lo[k] } else { hi[k] });
            let x = posed.from_normalized(&u);
            wlo = wlo.inf(&x);
            whi = whi.sup(&x);
        }
        Some((wlo, whi))
    }
}

/// A body under a rigid pose: evaluates `p(A x + b)` and its world-frame derivatives.
#[derive(Clone, Copy, Debug)]
pub struct PosedBody<'a> {
    /// The body.
    pub body: &'a Body,
    /// The pose (body frame → world).
    pub pose: Isometry3,
    a: Matrix3,
    b: Vector3,
}

impl<'a> PosedBody<'a> {
    /// The body under the identity pose (`A = I/scale`, `b = −center/scale`), without the
    /// quaternion → matrix work of [`Self::new`]: the frame body of a query solved in that body's
    /// own frame (far from that frame's origin a query translates it, [`Self::translated`]).
    #[inline]
    pub fn unposed(body: &'a Body) -> Self {
        Self::translated(body, &Vector3::zeros())
    }

    /// The body translated by `offset` (meters, no rotation): [`Self::unposed`] in a working frame
    /// whose origin is the body frame's point −`offset`, again without quaternion → matrix work
    /// (`A = I/scale`, `b = −(center + offset)/scale`, with center + offset formed first, so the
    /// map stays exact to the rounding of the working frame's small coordinates).
    #[inline]
    pub fn translated(body: &'a Body, offset: &Vector3) -> Self {
        let inv_s = 1.0 / body.scale;
        Self {
            body,
            pose: Isometry3::translation(offset.x, offset.y, offset.z),
            a: Matrix3::from_diagonal_element(inv_s),
            b: -(body.center + offset) * inv_s,
        }
    }

    /// Precomputes the world → normalized map `u = A x + b`.
    #[inline(always)]
    pub fn new(body: &'a Body, pose: &Isometry3) -> Self {
        let rt = pose.rotation.to_rotation_matrix().matrix().transpose();
        let inv_s = 1.0 / body.scale;
        let a = rt * inv_s;
        let b = -(rt * pose.translation.vector + body.center) * inv_s;
        Self { body, pose: *pose, a, b }
    }

    /// The body-frame point `local` in world coordinates, R·local + t, through the stored matrix
    /// A = Rᵀ/scale (R = scale·Aᵀ: one transposed matrix–vector product instead of a quaternion
    /// rotation).
    #[inline]
    pub fn to_world(&self, local: &Vector3) -> Vector3 {
        self.a.tr_mul(local) * self.body.scale + self.pose.translation.vector
    }

    /// The linear part A of the world → normalized map (Rᵀ/scale).
    pub fn linear(&self) -> &Matrix3 {
        &self.a
    }

    /// Normalized coordinates of a world point.
    #[inline]
    pub fn to_normalized(&self, x: &Vector3) -> Vector3 {
        self.a * x + self.b
    }

    /// World point of normalized coordinates (through [`Self::to_world`]'s matrix form).
    #[inline]
    pub fn from_normalized(&self, u: &Vector3) -> Vector3 {
        self.to_world(&(self.body.center + u * self.body.scale))
    }

    /// p'(x) = p(A x + b) at a world point.
    #[inline]
    pub fn value(&self, x: &Vector3) -> Real {
        self.body.polynomial.value(&self.to_normalized(x))
    }

    /// p'(x), ∇p'(x), ∇²p'(x) at a world point (exact).
    #[inline]
    pub fn eval(&self, x: &Vector3) -> Eval {
        let e = self.body.polynomial.eval(&self.to_normalized(x));
        let at = self.a.transpose();
        Eval { value: e.value, gradient: at * e.gradient, hessian: at * e.hessian * self.a }
    }

    /// The interior point (minimizer of p') in world coordinates.
    #[inline(always)]
    pub fn interior_point(&self) -> Vector3 {
        self.from_normalized(&self.body.interior_u)
    }

    /// The boundary point on the ray from the interior point towards `target` (world, meters), read
    /// off the body's [`RadialTable`] (within a few percent of the boundary; a start for Newton,
    /// not an answer), or `target` itself when the table puts it inside the body.
    #[inline(always)]
    pub fn boundary_towards(&self, target: &Vector3) -> Vector3 {
        let c = self.interior_point();
        let d = target - c;
        let du = self.a * d;
        let n = du.norm();
        if n.is_nan() || n <= 0.0 {
            return c;
        }
        c + d * (self.body.radial.radius(&du) / n).min(1.0)
    }

    /// The body's support point in the world direction `n` (any nonzero length): the point of the
    /// body maximizing n·x, read off its [`SupportTable`] (interpolated between tabulated
    /// directions: a start for Newton, not an answer). `None` for a zero or non-finite `n`.
    #[inline(always)]
    pub fn support(&self, n: &Vector3) -> Option<Vector3> {
        // n·x = scale·(Rᵀn)·u + const, and A n = Rᵀn/scale points the same way.
        Some(self.from_normalized(&self.body.support.support(&(self.a * n))?))
    }
}

/// Minimizes a convex polynomial by damped Newton from the origin; `None` unless it converges to
/// a point with positive-definite Hessian.
fn minimize_convex(p: &Polynomial) -> Option<(Vector3, Real)> {
    descend(p, Vector3::zeros(), |e| Some(-nalgebra::Cholesky::new(e.hessian)?.solve(&e.gradient)))
}

/// A strict local minimizer of a possibly nonconvex polynomial: Newton with the Hessian's
/// eigenvalues replaced by max(|λ|, δ) (a descent direction everywhere) and backtracking, started
/// from the point of a 9 × 9 × 9 grid over [−1, 1]³ (the normalized cloud's cube) with the
/// smallest p; `None` unless it ends at a point with positive-definite Hessian.
fn minimize_from_grid(p: &Polynomial) -> Option<(Vector3, Real)> {
    let mut u = Vector3::zeros();
    let mut best = p.value(&u);
    for i in 0..9 {
        for j in 0..9 {
            for k in 0..9 {
                let v = Vector3::new(i as Real / 4.0 - 1.0, j as Real / 4.0 - 1.0, k as Real / 4.0 - 1.0);
                let pv = p.value(&v);
                if pv < best {
                    best = pv;
                    u = v;
                }
            }
        }
    }
    descend(p, u, |e| {
        let eig = e.hessian.symmetric_eigen();
        let scale = eig.eigenvalues.iter().fold(0.0 as Real, |m, v| m.max(v.abs()));
        let floor = 1e-10 * (1.0 + scale);
        let mut step = Vector3::zeros();
        for k in 0..3 {
            let v = eig.eigenvectors.column(k);
            step -= v * (v.dot(&e.gradient) / eig.eigenvalues[k].abs().max(floor));
        }
        Some(step)
    })
}

/// Damped Newton descent from `u` with the step rule `newton_step` (None: give up, no minimizer)
/// and an Armijo backtracking line search; ends at [`finish`].
fn descend(
    p: &Polynomial,
    mut u: Vector3,
    newton_step: impl Fn(&crate::poly::Eval) -> Option<Vector3>,
) -> Option<(Vector3, Real)> {
    let mut e = p.eval(&u);
    for _ in 0..200 {
        let step = newton_step(&e)?;
        let decrement = -e.gradient.dot(&step);
        if decrement.is_nan() || decrement < 1e-24 {
            break;
        }
        let mut alpha = 1.0;
        loop {
            let trial = u + step * alpha;
            let v = p.value(&trial);
            if v.is_finite() && v <= e.value - 0.25 * alpha * decrement {
                u = trial;
                break;
            }
            alpha *= 0.5;
            if alpha < 1e-12 {
                return finish(p, u);
            }
        }
        e = p.eval(&u);
    }
    finish(p, u)
}

fn finish(p: &Polynomial, u: Vector3) -> Option<(Vector3, Real)> {
    let e = p.eval(&u);
    nalgebra::Cholesky::new(e.hessian)?;
    (e.gradient.norm() < 1e-6 * (1.0 + e.value.abs())).then_some((u, e.value))
}

/// An axis-aligned ellipsoid body `Σ ((xᵢ − cᵢ)/rᵢ)² ≤ 1` of degree 2, for tests and examples.
///
/// # Errors
/// [`Error::InvalidArgument`] if a radius is not finite and > 0.
pub fn ellipsoid(center: [Real; 3], radii: [Real; 3]) -> Result<Body> {
    if radii.iter().any(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(Error::invalid("radii", "must be finite and > 0"));
    }
    let s = radii.iter().cloned().fold(0.0, Real::max);
    let terms =
        [([2, 0, 0], (s / radii[0]).powi(2)), ([0, 2, 0], (s / radii[1]).powi(2)), ([0, 0, 2], (s / radii[2]).powi(2))];
    let report = FitReport { method: "closed_form_ellipsoid".into(), containment_rescale: 1.0, ..Default::default() };
    Body::new(Polynomial::from_terms(2, &terms)?, center, s, report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::pose_from_parts;

    #[test]
    fn solve_details_round_trip_and_unknown_names_read_as_none() {
        use crate::report::KktSolver;
        use crate::report::Normalization;
        let d = SolveDetails {
            iterations: 23,
            linear_solver: Some(KktSolver::Qdldl),
            frame: Some(Normalization::PrincipalBox),
            rows_per_round: vec![384, 684],
            contained_bodies: 0,
            multiplier_degree: None,
        };
        let json = serde_json::to_value(&d).unwrap();
        assert_eq!(json["linear_solver"], "qdldl");
        assert_eq!(json["frame"], "principal_box");
        assert_eq!(serde_json::from_value::<SolveDetails>(json).unwrap(), d);
        // Another writer's names never make a body file unreadable.
        let other: SolveDetails =
            serde_json::from_str(r#"{"iterations": 3, "linear_solver": "pardiso", "frame": "custom"}"#).unwrap();
        assert_eq!((other.iterations, other.linear_solver, other.frame), (3, None, None));
    }

    #[test]
    fn ellipsoid_membership_and_pose() {
        let e = ellipsoid([1.0, 0.0, 0.0], [2.0, 1.0, 0.5]).unwrap();
        assert!((e.value_at(&Point3::new(3.0, 0.0, 0.0)) - 1.0).abs() < 1e-12);
        assert!((e.value_at(&Point3::new(1.0, 0.0, 0.5)) - 1.0).abs() < 1e-12);
        assert!((e.interior_point() - Point3::new(1.0, 0.0, 0.0)).norm() < 1e-9);
        // Rotate 90° about z and translate by (0, 0, 5): the long axis now points along y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let pose = pose_from_parts("pose", [h, 0.0, 0.0, h], [0.0, 0.0, 5.0]).unwrap();
        let pb = e.posed(&pose);
        let tip = Vector3::new(0.0, 3.0, 5.0); // R (3,0,0) + t
        assert!((pb.value(&tip) - 1.0).abs() < 1e-12);
        let ev = pb.eval(&tip);
        // Outward normal at the tip is +y; ∇ of Σ(x/r)² there has magnitude 2/r = 1.
        assert!((ev.gradient - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        assert!((pb.interior_point() - Vector3::new(0.0, 1.0, 5.0)).norm() < 1e-9);
    }

    #[test]
    fn json_round_trip_and_validation() {
        let e = ellipsoid([0.5, -1.0, 2.0], [1.0, 2.0, 3.0]).unwrap();
        let text = serde_json::to_string(&e.to_file()).unwrap();
        let back = Body::from_file(serde_json::from_str(&text).unwrap()).unwrap();
        assert_eq!(back.polynomial(), e.polynomial());
        let mut bad = e.to_file();
        bad.degree = 3;
        assert!(Body::from_file(bad).unwrap_err().to_string().contains("degree"));
        let mut bad = e.to_file();
        bad.scale = -1.0;
        assert!(Body::from_file(bad).unwrap_err().to_string().contains("scale"));
        // A valid scale with tiny coefficients: {p ≤ 1} reaches 1e150 m (radius 1/√1e-300 of
        // the unit scale), so the body is refused for its real size.
        let mut huge = e.to_file();
        huge.coefficients.iter_mut().for_each(|c| *c *= 1e-300);
        let err = Body::from_file(huge).unwrap_err();
        assert!(matches!(&err, Error::InvalidArgument { field, .. } if field == "coefficients"), "{err}");
        // 1e-6 of the coefficients: a thousand times larger (3 km), still accepted.
        let mut large = e.to_file();
        large.coefficients.iter_mut().for_each(|c| *c *= 1e-6);
        let large = Body::from_file(large).unwrap();
        assert!((large.bounding_sphere().unwrap().1 / e.bounding_sphere().unwrap().1 - 1e3).abs() < 10.0);
        let mut bad = e.to_file();
        bad.coefficients.iter_mut().for_each(|c| *c = -*c);
        assert!(Body::from_file(bad).unwrap_err().to_string().contains("coefficients"));
    }

    #[test]
    fn nonconvex_bodies_get_a_local_minimizer() {
        // p = (x² − 1/2)² + y² + z² + 0.1: Newton from the origin meets the indefinite Hessian
        // diag(−2, 2, 2); the minimizers are (±1/√2, 0, 0) with p = 0.1 and Hessian diag(4, 2, 2).
        let terms = [([4, 0, 0], 1.0), ([2, 0, 0], -1.0), ([0, 0, 0], 0.35), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0)];
        let p = Polynomial::from_terms(4, &terms).unwrap();
        let convex = FitReport::default();
        assert!(Body::new(p.clone(), [0.0; 3], 1.0, convex).unwrap_err().to_string().contains("coefficients"));
        let report = FitReport { nonconvex: true, ..Default::default() };
        let body = Body::new(p, [1.0, 2.0, 3.0], 2.0, report).unwrap();
        assert!((body.min_value() - 0.1).abs() < 1e-12, "{}", body.min_value());
        let u = (body.interior_point().coords - Vector3::new(1.0, 2.0, 3.0)) / 2.0;
        assert!((u.x.abs() - 0.5f64.sqrt()).abs() < 1e-8 && u.y.abs() < 1e-8 && u.z.abs() < 1e-8, "{u}");
    }
}
