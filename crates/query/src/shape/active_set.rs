//! The active-set Newton (SQP) method for the distance between two convex sets given by several
//! constraints each (paper §IV-A, eq. "distance", for sets `{x : gⱼ(x) ≤ 1, j = 1..m}`).
//!
//! Each side is a *core* in its own parameters u, posed in the working frame as
//! `x = origin + M u`, swept by a ball of radius r (0 but for spheres and capsules):
//!
//! ```text
//! core       dim  constraints on u                              M
//! point       0   —                                             —
//! segment     1   −h ≤ u ≤ h                                    R e_z
//! box         3   −h_i ≤ u_i ≤ h_i                              R
//! cylinder    3   c(u) = (u_x² + u_y² − ρ²) / 2ρ ≤ 0, |u_z| ≤ h  R
//! body        3   c(u) = p(u) − 1 ≤ 0 (normalized coordinates)   R · scale
//! ```
//!
//! The distance of the cores, `min ½‖x(u) − y(v)‖²`, is a convex program with a convex quadratic
//! objective, simple bounds and at most one smooth constraint per side; the shapes' distance is
//! that of the cores less r_a + r_b. The working set holds the bounds at which a variable is fixed
//! (the variable leaves the system) and the smooth constraints treated as equalities; each
//! iteration solves the Newton-KKT system of the equality-constrained problem
//!
//! ```text
//! [ H + ρI   Aᵀ ] [ d  ]   [ −∇f ]         H = JᵀJ + Σ λ_s ∇²c_s   (free variables)
//! [ A        0  ] [ λ⁺ ] = [ −c  ]         A = ∇c_s                 (active smooth constraints)
//! ```
//!
//! (ρ = 10⁻¹⁰ of H's diagonal: JᵀJ is singular along parallel faces, where any minimizer will
//! do), steps as far as the first blocking bound or smooth constraint (which joins the working
//! set), and, once the step vanishes, drops the constraint whose multiplier has the wrong sign
//! (the most negative, scaled to meters). Within one side the constraints involve distinct
//! coordinates (a box's bounds, a cylinder's disk and axis), so their gradients are independent
//! and the multipliers unique. On bounds alone (box, segment, point pairs) this is the primal
//! active-set method of a convex QP and ends exactly in finitely many steps; with a curved
//! constraint active, Newton converges quadratically. A stationary point of the working set with
//! multipliers of the right sign is a KKT point of the convex program: the global minimizer.
//!
//! Warm starts keep the parameters, the working set and the multipliers, all in the sides' own
//! coordinates, so they follow the poses.

// The solver indexes parallel fixed-size arrays (parameters, their Jacobian columns, steps and
// working set) by parameter number; iterators over one of them would hide the others.
#![allow(clippy::needless_range_loop)]

use super::ShapeRef;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Matrix3, Real, Vector3};
use sublevel_core::poly::radial::ray_crossing;
use sublevel_core::primitive::Primitive;

/// Largest number of parameters of a pair (two 3-parameter cores).
const MAX_VARS: usize = 6;
/// Largest KKT system: the parameters and one smooth constraint per side.
const MAX_KKT: usize = MAX_VARS + 2;

/// The constraints of one side's core (module docs).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Core<'a> {
    Point,
    Segment { half: Real },
    Box { half: Vector3 },
    Cylinder { radius: Real, half: Real },
    Body(&'a Body),
}

/// Where a parameter sits in the working set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fix {
    /// Not fixed by a bound.
    #[default]
    Free,
    /// At its lower bound.
    Lower,
    /// At its upper bound.
    Upper,
}

/// One side of a pair in the working frame: `x = origin + map · u` over the core, swept by a ball
/// of `radius`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Side<'a> {
    pub core: Core<'a>,
    pub dim: usize,
    pub origin: Vector3,
    pub map: Matrix3,
    /// Radius of the ball sweeping the core (sphere, capsule), meters.
    pub radius: Real,
    /// Meters per unit of u (the body's normalization scale; 1 for primitives).
    pub unit: Real,
    /// A length of the side's size (meters), for relative tolerances.
    pub scale: Real,
}

impl<'a> Side<'a> {
    /// The side of `shape` posed by `pose` in the working frame; `None` for a halfspace (answered
    /// in closed form, never by this method).
    pub fn new(shape: ShapeRef<'a>, pose: &Isometry3) -> Option<Self> {
        let r = pose.rotation.to_rotation_matrix().into_inner();
        let t = pose.translation.vector;
        let side = |core, dim, map, radius, scale| Side { core, dim, origin: t, map, radius, unit: 1.0, scale };
        Some(match shape {
            ShapeRef::Primitive(p) => match *p {
                Primitive::Sphere { radius } => side(Core::Point, 0, Matrix3::zeros(), radius, radius),
                Primitive::Capsule { radius, half_height } => {
                    let mut m = Matrix3::zeros();
                    m.set_column(0, &r.column(2));
                    side(Core::Segment { half: half_height }, 1, m, radius, radius + half_height)
                }
                Primitive::Box { half_extents } => {
                    side(Core::Box { half: half_extents }, 3, r, 0.0, half_extents.max())
                }
                Primitive::Cylinder { radius, half_height } => {
                    side(Core::Cylinder { radius, half: half_height }, 3, r, 0.0, radius.max(half_height))
                }
                Primitive::Halfspace { .. } => return None,
            },
            ShapeRef::Body(b) => Side {
                core: Core::Body(b),
                dim: 3,
                origin: t + r * b.center(),
                map: r * b.scale(),
                radius: 0.0,
                unit: b.scale(),
                scale: b.scale(),
            },
        })
    }

    /// The core's point at parameters `u` (working frame).
    #[inline(always)]
    pub fn point(&self, u: &[Real]) -> Vector3 {
        let mut x = self.origin;
        for (i, ui) in u.iter().enumerate().take(self.dim) {
            x += self.map.column(i) * *ui;
        }
        x
    }

    /// The bounds (lower, upper) of parameter `i`, if it has any.
    #[inline(always)]
    fn bound(&self, i: usize) -> Option<(Real, Real)> {
        match self.core {
            Core::Segment { half } => Some((-half, half)),
            Core::Box { half } => Some((-half[i], half[i])),
            Core::Cylinder { half, .. } if i == 2 => Some((-half, half)),
            _ => None,
        }
    }

    /// Whether the core has a smooth constraint (cylinder's disk, body's polynomial).
    #[inline(always)]
    fn has_smooth(&self) -> bool {
        matches!(self.core, Core::Cylinder { .. } | Core::Body(_))
    }

    /// The smooth constraint c(u) ≤ 0 at `u`, its gradient and Hessian in u.
    #[inline(always)]
    fn smooth(&self, u: &[Real]) -> (Real, Vector3, Matrix3) {
        match self.core {
            Core::Cylinder { radius, .. } => (
                (u[0] * u[0] + u[1] * u[1] - radius * radius) / (2.0 * radius),
                Vector3::new(u[0] / radius, u[1] / radius, 0.0),
                Matrix3::from_diagonal(&Vector3::new(1.0 / radius, 1.0 / radius, 0.0)),
            ),
            Core::Body(b) => {
                let e = b.fast_polynomial().eval_sym(&Vector3::new(u[0], u[1], u[2]));
                (e.value - 1.0, e.gradient, e.hessian.to_matrix())
            }
            _ => (0.0, Vector3::zeros(), Matrix3::zeros()),
        }
    }

    /// Meters per unit of the smooth constraint's value near the boundary: c is in meters for the
    /// cylinder; p − 1 changes by about |∇p| per normalized unit for a body.
    #[inline(always)]
    fn smooth_unit(&self, gradient: &Vector3) -> Real {
        match self.core {
            Core::Body(b) => b.scale() / gradient.norm().max(1e-300),
            _ => 1.0,
        }
    }

    /// Moves `u` onto the smooth constraint's boundary c = 0: exactly for the cylinder's disk
    /// (radial scaling); for a body by one Newton correction along ∇p where that lands on the
    /// boundary (c = O(‖step‖²) after a short Newton step), else to the boundary point on the ray
    /// from the body's interior point through u.
    #[inline(always)]
    fn retract(&self, u: &mut [Real]) {
        match self.core {
            Core::Cylinder { radius, .. } => {
                let rho = u[0].hypot(u[1]);
                if rho > 0.0 {
                    u[0] *= radius / rho;
                    u[1] *= radius / rho;
                }
            }
            Core::Body(b) => {
                let p = b.fast_polynomial();
                let mut v = Vector3::new(u[0], u[1], u[2]);
                // Newton corrections along ∇p: enough after a short step.
                let mut done = false;
                let (mut value, mut g) = p.value_gradient(&v);
                for _ in 0..6 {
                    let g2 = g.norm_squared();
                    if (value - 1.0).abs() <= 1e-14 {
                        done = true;
                        break;
                    }
                    if g2 <= 0.0 || (value - 1.0).abs() > 0.5 {
                        break;
                    }
                    v -= g * ((value - 1.0) / g2);
                    if (value - 1.0).abs() <= 1e-8 {
                        // Newton's projection converges quadratically: from 10⁻⁸ one step
                        // leaves p − 1 at rounding level.
                        done = true;
                        break;
                    }
                    (value, g) = p.value_gradient(&v);
                }
                if !done {
                    // Far off: the boundary point on the ray from the interior point through v.
                    let inside = (b.interior_point().coords - b.center()) / b.scale();
                    let mut dir = v - inside;
                    if dir.norm_squared() == 0.0 {
                        return;
                    }
                    for _ in 0..60 {
                        if p.value(&(inside + dir)) > 1.0 {
                            break;
                        }
                        dir *= 2.0;
                    }
                    v = inside + dir * ray_crossing(p, &inside, &dir, 1e-15);
                }
                u[..3].copy_from_slice(v.as_slice());
            }
            _ => {}
        }
    }

    /// The first α ∈ (0, 1] where the inactive smooth constraint becomes active along
    /// u + α d (u strictly feasible), or `None` if it stays satisfied up to α = 1.
    fn smooth_crossing(&self, u: &[Real], d: &[Real]) -> Option<Real> {
        match self.core {
            Core::Cylinder { radius, .. } => {
                // |(u + α d)_xy|² = ρ²: a α² + 2 b α + c = 0 with c ≤ 0.
                let a = d[0] * d[0] + d[1] * d[1];
                let b = u[0] * d[0] + u[1] * d[1];
                let c = u[0] * u[0] + u[1] * u[1] - radius * radius;
                if a <= 0.0 || (a + 2.0 * b + c) <= 0.0 {
                    return None;
                }
                let disc = (b * b - a * c).max(0.0).sqrt();
                // The positive root, in the form without cancellation.
                let alpha = if b >= 0.0 { -c / (b + disc) } else { (disc - b) / a };
                Some(alpha.clamp(0.0, 1.0))
            }
            Core::Body(b) => {
                let p = b.fast_polynomial();
                let u0 = Vector3::new(u[0], u[1], u[2]);
                let dv = Vector3::new(d[0], d[1], d[2]);
                if p.value(&(u0 + dv)) <= 1.0 {
                    return None;
                }
                if p.value(&u0) >= 1.0 {
                    return Some(0.0);
                }
                Some(ray_crossing(p, &u0, &dv, 1e-14))
            }
            _ => None,
        }
    }

    /// The core's parameters nearest to the working-frame point `target` for primitives (exact
    /// projection), or the body's support point along the direction from its interior point to
    /// `target` (its support table's, the closest point of a far target); with the working set
    /// they lie on.
    pub fn start_towards(&self, target: &Vector3) -> ([Real; 3], [Fix; 3], bool) {
        let local = |m: &Matrix3| m.transpose() * (target - self.origin);
        let mut u = [0.0; 3];
        let mut fix = [Fix::Free; 3];
        let clamp = |v: Real, h: Real, f: &mut Fix| {
            if v >= h {
                *f = Fix::Upper;
                h
            } else if v <= -h {
                *f = Fix::Lower;
                -h
            } else {
                v
            }
        };
        match self.core {
            Core::Point => (u, fix, false),
            Core::Segment { half } => {
                let s = self.map.column(0).dot(&(target - self.origin));
                u[0] = clamp(s, half, &mut fix[0]);
                (u, fix, false)
            }
            Core::Box { half } => {
                let l = local(&self.map);
                for i in 0..3 {
                    u[i] = clamp(l[i], half[i], &mut fix[i]);
                }
                (u, fix, false)
            }
            Core::Cylinder { radius, half } => {
                let l = local(&self.map);
                let rho = l.x.hypot(l.y);
                let active = rho >= radius;
                let k = if active { radius / rho } else { 1.0 };
                u[0] = l.x * k;
                u[1] = l.y * k;
                u[2] = clamp(l.z, half, &mut fix[2]);
                (u, fix, active)
            }
            Core::Body(b) => {
                let l = local(&self.map) / (b.scale() * b.scale());
                let inside = (b.interior_point().coords - b.center()) / b.scale();
                let dir = l - inside;
                if dir.norm_squared() == 0.0 || b.fast_polynomial().value(&l) <= 1.0 {
                    return ([l.x, l.y, l.z], fix, false);
                }
                // The support point along the direction to the target: the closest boundary
                // point of a far target (the radial point where the table has none).
                let v = b.support_table().support(&dir).unwrap_or_else(|| {
                    let dir = dir.normalize();
                    inside + dir * b.radial_table().radius(&dir)
                });
                ([v.x, v.y, v.z], fix, true)
            }
        }
    }
}

/// The state of a solve: parameters of both sides (A's first), their working set, and the
/// smooth constraints' activity and multipliers (A, B).
#[derive(Clone, Copy, Debug, Default)]
pub struct ActiveSetState {
    /// Parameters: A's `dim` values, then B's.
    pub u: [Real; MAX_VARS],
    /// Bounds in the working set, per parameter.
    pub fix: [Fix; MAX_VARS],
    /// Whether each side's smooth constraint is in the working set.
    pub smooth: [bool; 2],
    /// Multipliers of the smooth constraints.
    pub lambda: [Real; 2],
}

/// How a run ended.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Outcome {
    pub state: ActiveSetState,
    pub converged: bool,
    pub iterations: usize,
    /// ∞-norm of the KKT residual in meters: stationarity on the free parameters and the active
    /// smooth constraints' values (each scaled to meters).
    pub kkt_residual: Real,
}

/// Solves the dense system `m x = rhs` of size `n` by Gaussian elimination with partial pivoting;
/// false when singular.
#[inline(always)]
fn solve_dense(n: usize, m: &mut [[Real; MAX_KKT]; MAX_KKT], rhs: &mut [Real; MAX_KKT]) -> bool {
    let mut inverse = [0.0; MAX_KKT];
    for k in 0..n {
        let mut p = k;
        for i in k + 1..n {
            if m[i][k].abs() > m[p][k].abs() {
                p = i;
            }
        }
        if m[p][k] == 0.0 || !m[p][k].is_finite() {
            return false;
        }
        m.swap(k, p);
        rhs.swap(k, p);
        let inv = 1.0 / m[k][k];
        inverse[k] = inv;
        for i in k + 1..n {
            let f = m[i][k] * inv;
            if f != 0.0 {
                for j in k..n {
                    m[i][j] -= f * m[k][j];
                }
                rhs[i] -= f * rhs[k];
            }
        }
    }
    for k in (0..n).rev() {
        let mut s = rhs[k];
        for j in k + 1..n {
            s -= m[k][j] * rhs[j];
        }
        rhs[k] = s * inverse[k];
    }
    true
}

/// Tolerances of a run, meters.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tolerances {
    /// A step whose displacement of both points is below this counts as vanished.
    pub step: Real,
    /// Stationarity and multiplier signs are met within `relative` of the gap ‖x − y‖ plus
    /// `absolute` (meters): the gradient of ½‖x − y‖² is at most the gap, so a relative test is the
    /// same at every distance, and the absolute floor decides touching cores.
    pub relative: Real,
    /// The absolute floor of the stationarity and sign tests (meters).
    pub absolute: Real,
    /// Active smooth constraints' values (scaled to meters) below this are met.
    pub feasibility: Real,
    /// Iteration cap.
    pub max_iterations: usize,
}

/// Takes the constraint `k` (a parameter's bound, or `MAX_VARS + side` for a smooth constraint)
/// out of the working set.
fn release(state: &mut ActiveSetState, k: usize) {
    if k >= MAX_VARS {
        state.smooth[k - MAX_VARS] = false;
        state.lambda[k - MAX_VARS] = 0.0;
    } else {
        state.fix[k] = Fix::Free;
    }
}

/// Runs the active-set Newton method between `a` and `b` from `state` (module docs).
pub(crate) fn solve(a: &Side, b: &Side, mut state: ActiveSetState, tol: &Tolerances) -> Outcome {
    let (na, nb) = (a.dim, b.dim);
    let n = na + nb;
    let side_of = |k: usize| if k < na { (a, k, 0usize) } else { (b, k - na, 1usize) };
    // The column of J (∂(x − y)/∂w_k) for each parameter.
    let mut jac = [Vector3::zeros(); MAX_VARS];
    for (k, col) in jac.iter_mut().enumerate().take(n) {
        let (s, i, which) = side_of(k);
        *col = if which == 0 { s.map.column(i).into() } else { -s.map.column(i) };
    }
    let sides = [a, b];
    let offsets = [0, na];
    // Smooth constraints can only be active on sides that have one.
    for (s, side) in sides.iter().enumerate() {
        if !side.has_smooth() {
            state.smooth[s] = false;
        }
    }

    for s in 0..2 {
        if state.smooth[s] {
            sides[s].retract(&mut state.u[offsets[s]..offsets[s] + 3]);
        }
    }
    // Least-squares multipliers of active smooth constraints that have none yet (a cold start):
    // λ = −(∇c · g)/‖∇c‖² over the side's free parameters, g the gradient of ½‖x − y‖². With
    // them the first Newton step already sees the constraint's curvature.
    let r0 = a.point(&state.u[..na]) - b.point(&state.u[na..n]);
    for s in 0..2 {
        if state.smooth[s] && state.lambda[s] <= 0.0 {
            let o = offsets[s];
            let (_, grad, _) = sides[s].smooth(&state.u[o..o + 3]);
            let (mut num, mut den) = (0.0, 0.0);
            for i in 0..3 {
                if state.fix[o + i] == Fix::Free {
                    num += grad[i] * jac[o + i].dot(&r0);
                    den += grad[i] * grad[i];
                }
            }
            if den > 0.0 {
                state.lambda[s] = (-num / den).max(0.0);
            }
        }
    }
    let mut iterations = 0;
    let mut converged = false;
    let mut kkt_residual = Real::INFINITY;
    while iterations < tol.max_iterations {
        iterations += 1;
        let w = &state.u;
        let r = a.point(&w[..na]) - b.point(&w[na..n]);
        // The active smooth constraints: (side, value, gradient, Hessian).
        let mut smooth = [(0usize, 0.0, Vector3::zeros(), Matrix3::zeros()); 2];
        let mut ns = 0;
        for s in 0..2 {
            if state.smooth[s] {
                let (c, g, h) = sides[s].smooth(&w[offsets[s]..offsets[s] + 3]);
                smooth[ns] = (s, c, g, h);
                ns += 1;
            }
        }
        // Free parameters.
        let mut free = [0usize; MAX_VARS];
        let mut nf = 0;
        for k in 0..n {
            if state.fix[k] == Fix::Free {
                free[nf] = k;
                nf += 1;
            }
        }
        // Assemble the KKT system.
        let dim = nf + ns;
        let mut m = [[0.0; MAX_KKT]; MAX_KKT];
        let mut rhs = [0.0; MAX_KKT];
        let mut diag_max: Real = 0.0;
        for p in 0..nf {
            let kp = free[p];
            for q in p..nf {
                let kq = free[q];
                let mut h = jac[kp].dot(&jac[kq]);
                let (_, ip, wp) = side_of(kp);
                let (_, iq, wq) = side_of(kq);
                if wp == wq && state.smooth[wp] {
                    for &(s, _, _, ref hs) in &smooth[..ns] {
                        if s == wp {
                            h += state.lambda[s].max(0.0) * hs[(ip, iq)];
                        }
                    }
                }
                m[p][q] = h;
                m[q][p] = h;
            }
            diag_max = diag_max.max(m[p][p]);
            rhs[p] = -jac[kp].dot(&r);
        }
        let rho = 1e-10 * diag_max.max(Real::MIN_POSITIVE);
        for (p, row) in m.iter_mut().enumerate().take(nf) {
            row[p] += rho;
        }
        for (j, &(s, c, ref g, _)) in smooth[..ns].iter().enumerate() {
            for p in 0..nf {
                let (_, i, which) = side_of(free[p]);
                let v = if which == s { g[i] } else { 0.0 };
                m[nf + j][p] = v;
                m[p][nf + j] = v;
            }
            rhs[nf + j] = -c;
        }
        let mut sol = rhs;
        if !solve_dense(dim, &mut m, &mut sol) {
            break;
        }
        let mut d = [0.0; MAX_VARS];
        for p in 0..nf {
            d[free[p]] = sol[p];
        }
        let mut lambda_new = state.lambda;
        for (j, &(s, ..)) in smooth[..ns].iter().enumerate() {
            lambda_new[s] = sol[nf + j];
        }
        // The displacement of the points (meters).
        let mut dx = Vector3::zeros();
        let mut dy = Vector3::zeros();
        for k in 0..n {
            if k < na {
                dx += jac[k] * d[k];
            } else {
                dy -= jac[k] * d[k];
            }
        }
        let step = dx.norm().max(dy.norm());
        let feasible =
            smooth[..ns].iter().all(|&(s, c, ref g, _)| (c * sides[s].smooth_unit(g)).abs() <= tol.feasibility);
        let kkt_tol = tol.relative * r.norm() + tol.absolute;
        // The gap after the step: x(u) is affine in u for every core, so r + J d is exact. A step
        // that leaves the gap unchanged to rounding slides along a degenerate direction (parallel
        // faces or axes), where every point is a minimizer.
        let predicted = (r + dx - dy).norm();
        let unchanged = (r.norm() - predicted).abs() <= tol.absolute + 1e-14 * r.norm();
        // Ratio test: the first bound or inactive smooth constraint the step meets.
        let mut alpha = 1.0;
        let mut block: Option<(usize, Fix)> = None; // parameter k and its bound, or MAX_VARS + side
        for &k in &free[..nf] {
            let (s, i, _) = side_of(k);
            if let Some((lo, hi)) = s.bound(i) {
                let target = state.u[k] + alpha * d[k];
                if target > hi && d[k] > 0.0 {
                    alpha = ((hi - state.u[k]) / d[k]).clamp(0.0, alpha);
                    block = Some((k, Fix::Upper));
                } else if target < lo && d[k] < 0.0 {
                    alpha = ((lo - state.u[k]) / d[k]).clamp(0.0, alpha);
                    block = Some((k, Fix::Lower));
                }
            }
        }
        for s in 0..2 {
            if sides[s].has_smooth() && !state.smooth[s] {
                let o = offsets[s];
                let scaled = [d[o] * alpha, d[o + 1] * alpha, d[o + 2] * alpha];
                if let Some(t) = sides[s].smooth_crossing(&state.u[o..o + 3], &scaled) {
                    alpha *= t;
                    block = Some((MAX_VARS + s, Fix::Free));
                }
            }
        }
        // The multipliers' signs at a point stationary on the working set: the constraint whose
        // multiplier is most negative (a parameter k, or MAX_VARS + side for a smooth
        // constraint), and the stationarity residual (meters).
        let check = |state: &ActiveSetState, r: &Vector3| -> (Option<usize>, Real) {
            let mut worst: Option<(usize, Real)> = None; // (index: parameter k, or MAX_VARS + side)
            let mut stationarity: Real = 0.0;
            for k in 0..n {
                let (s, i, which) = side_of(k);
                let mut gl = jac[k].dot(r);
                for &(t, _, ref g, _) in &smooth[..ns] {
                    if t == which {
                        gl += state.lambda[t] * g[i];
                    }
                }
                // Scaled to meters per meter of motion of the point.
                let scaled = gl / s.map.column(i).norm().max(1e-300);
                let mu = match state.fix[k] {
                    Fix::Free => {
                        stationarity = stationarity.max(scaled.abs());
                        continue;
                    }
                    Fix::Lower => scaled,
                    Fix::Upper => -scaled,
                };
                if mu < -kkt_tol && worst.is_none_or(|(_, v)| mu < v) {
                    worst = Some((k, mu));
                }
            }
            for &(s, c, ref g, _) in &smooth[..ns] {
                // λ ∇c in meters: λ |∇c| / (meters per unit of u).
                let mu = state.lambda[s] * g.norm() / sides[s].unit;
                stationarity = stationarity.max((c * sides[s].smooth_unit(g)).abs());
                if mu < -kkt_tol && worst.is_none_or(|(_, v)| mu < v) {
                    worst = Some((MAX_VARS + s, mu));
                }
            }
            (worst.map(|(k, _)| k), stationarity)
        };
        if (step <= tol.step || unchanged) && feasible && block.is_none() {
            // Stationary on the working set: take the last (tiny) step, which the model predicts
            // exactly for the affine cores, then the multipliers decide.
            for k in 0..n {
                state.u[k] += d[k];
            }
            for s in 0..2 {
                if state.smooth[s] {
                    sides[s].retract(&mut state.u[offsets[s]..offsets[s] + 3]);
                }
            }
            let r = a.point(&state.u[..na]) - b.point(&state.u[na..n]);
            state.lambda = lambda_new;
            let (worst, stationarity) = check(&state, &r);
            kkt_residual = stationarity;
            match worst {
                None => {
                    converged = true;
                    break;
                }
                Some(k) => release(&mut state, k),
            }
            continue;
        }
        // Backtracking on the objective: iterates stay on their active smooth constraints
        // (retracted after each step), so f decreases along the Newton direction (a descent
        // direction of f on that surface) and the iteration cannot cycle between curved faces.
        let f0 = 0.5 * r.norm_squared();
        let slope: Real = (0..n).map(|k| jac[k].dot(&r) * d[k]).sum();
        // Rounding of f and of the retraction (p − 1 to ~10⁻¹⁴).
        let slack = 1e-13 * r.norm() * a.scale.min(b.scale) + (1e-3 * tol.step).powi(2);
        let mut trial = state.u;
        let mut halvings = 0;
        for _ in 0..40 {
            for k in 0..n {
                trial[k] = state.u[k] + alpha * d[k];
            }
            let before = a.point(&trial[..na]) - b.point(&trial[na..n]);
            for s in 0..2 {
                if state.smooth[s] {
                    sides[s].retract(&mut trial[offsets[s]..offsets[s] + 3]);
                }
            }
            let rt = a.point(&trial[..na]) - b.point(&trial[na..n]);
            let ft = 0.5 * rt.norm_squared();
            if ft <= f0 + 1e-4 * alpha * slope.min(0.0) + slack {
                break;
            }
            // Near the solution the retraction onto a curved boundary moves the point by
            // O(‖d‖²), as much as the step gains (the Maratos effect): a short full Newton step
            // is taken when f grows by no more than that move allows.
            if alpha == 1.0 && step <= 1e-4 * (a.scale.min(b.scale)) {
                let shift = (rt - before).norm();
                if ft <= f0 + slack + 2.0 * shift * r.norm() {
                    break;
                }
                // A short step that f rejects is rounding: shorter ones are too.
                halvings = 40;
                break;
            }
            alpha *= 0.5;
            halvings += 1;
            block = None;
        }
        if halvings == 40 {
            // No decrease along the step: rounding dominates it. The point converged if it is
            // stationary to 10⁻⁸ of the gap (the distance then to ~10⁻¹⁶ of it) with multipliers
            // of the right sign.
            state.lambda = lambda_new;
            let (worst, stationarity) = check(&state, &r);
            kkt_residual = stationarity;
            match worst {
                None => {
                    converged = stationarity <= 1e-8 * r.norm() + tol.absolute;
                    break;
                }
                Some(k) => release(&mut state, k),
            }
            continue;
        }
        state.u = trial;
        state.lambda = lambda_new;
        match block {
            Some((k, _)) if k >= MAX_VARS => {
                let s = k - MAX_VARS;
                state.smooth[s] = true;
                state.lambda[s] = 0.0;
                sides[s].retract(&mut state.u[offsets[s]..offsets[s] + 3]);
            }
            Some((k, f)) => {
                let (s, i, _) = side_of(k);
                let (lo, hi) = s.bound(i).unwrap_or((0.0, 0.0));
                state.u[k] = if f == Fix::Upper { hi } else { lo };
                state.fix[k] = f;
            }
            None => {}
        }
    }
    Outcome { state, converged, iterations, kkt_residual }
}
