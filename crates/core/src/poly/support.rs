//! Support points of a sublevel set, tabulated once per body: the cold distance start reads the
//! points of the two bodies that face each other off these tables.
//!
//! The support point of a convex body K = {u : p(u) ≤ 1} in the direction m is the maximizer of
//! m·u over K; with p sos-convex it satisfies the KKT conditions
//!
//! ```text
//! m = λ ∇p(u),   p(u) = 1,   λ > 0
//! ```
//!
//! The witnesses (x*, y*) of the distance between two separated convex bodies are support points:
//! x* = h_A(n), y* = h_B(−n) for the unit normal n = (y* − x*)/‖y* − x*‖ (paper §IV-A, the KKT
//! system of eq. "distance": 2(x − y) + λ_a∇p_a' = 0 says ∇p_a'(x) ∥ n). So a few support
//! look-ups from the direction between the interior points give a start close to the witnesses,
//! where the radial table's boundary points on the segment between the interior points can be far
//! off for elongated bodies.
//!
//! [`SupportTable`] samples the support map on the cube map of [`super::RadialTable`] (same faces
//! and [`SUPPORT_GRID`] cells per face side): each node's support point is solved once (start: the
//! best of the radial table's boundary points on a finer grid, then Newton on the KKT system above
//! to |p − 1| ≤ 10⁻¹⁰), and [`SupportTable::support`] interpolates bilinearly between the four
//! nodes around the direction. The interpolated point is a start for Newton, not an answer.

use super::radial::{face_coordinates, node_direction};
use super::{FastPoly, RadialTable};
use crate::math::{Real, Vector3};
use crate::poly::Polynomial;
use crate::{Error, Result};

/// Grid cells per cube-face side of a [`SupportTable`] ((G + 1)² nodes per face, 6 faces).
pub const SUPPORT_GRID: usize = 8;

const NODES: usize = SUPPORT_GRID + 1;

/// Cells per face side of the candidate boundary points the node solves start from.
const CANDIDATE_GRID: usize = 16;

/// The support map u*(m) of {p ≤ 1} on a cube map of directions m (see the module docs);
/// normalized units (the body's polynomial coordinates).
#[derive(Clone, Debug, PartialEq)]
pub struct SupportTable {
    /// Support points at the nodes: face-major, then row (b), then column (a).
    points: Box<[[[Real; 3]; NODES * NODES]; 6]>,
}

impl SupportTable {
    /// The support points at the nodes (normalized units), face-major (node `k = j·(G + 1) + i` of
    /// face f at `[f][k]`, G = [`SUPPORT_GRID`]): the four-lane look-ups of the batch solvers read
    /// them directly (`sublevel_query::batch`; same cells and interpolation as [`Self::support`]).
    pub fn nodes(&self) -> &[[[Real; 3]; NODES * NODES]; 6] {
        &self.points
    }

    /// Tabulates the support map of {p ≤ 1} from its radial table about `center` (normalized
    /// coordinates, p(center) < 1). Each node starts from the best candidate boundary point and is
    /// polished by at most 12 Newton steps; a node whose Newton run does not reach a KKT point
    /// (|p − 1| ≤ 10⁻¹⁰, λ > 0) keeps the candidate (on the boundary to the radial table's accuracy).
    pub fn new(p: &FastPoly, radial: &RadialTable, center: &Vector3) -> Self {
        // The candidates' coordinates in three arrays: the search for each node's best
        // candidate is then one pass of multiply-adds and compares.
        let n = 6 * (CANDIDATE_GRID + 1) * (CANDIDATE_GRID + 1);
        let (mut xs, mut ys, mut zs) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
        for face in 0..6 {
            for k in 0..(CANDIDATE_GRID + 1) * (CANDIDATE_GRID + 1) {
                let dir = node_direction(face, k, CANDIDATE_GRID).normalize();
                let c = center + dir * radial.radius(&dir);
                xs.push(c.x);
                ys.push(c.y);
                zs.push(c.z);
            }
        }
        let mut points = Box::new([[[0.0; 3]; NODES * NODES]; 6]);
        for (face, nodes) in points.iter_mut().enumerate() {
            for (k, node) in nodes.iter_mut().enumerate() {
                let m = node_direction(face, k, SUPPORT_GRID).normalize();
                let best = best_candidate(&m, &xs, &ys, &zs).map_or(*center, |i| Vector3::new(xs[i], ys[i], zs[i]));
                let u = polish(p, &m, best).or_else(|| support_by_penalty(p, &m, best)).unwrap_or(best);
                *node = [u.x, u.y, u.z];
            }
        }
        Self { points }
    }

    /// The table of a quadratic p (2d = 2, an ellipsoid) in closed form, with no search: with
    /// p(u) = uᵀQu + bᵀu + c, Q positive definite, center u₀ = −Q⁻¹b/2 and ρ = 1 − p(u₀) > 0,
    ///
    /// ```text
    /// u*(m) = u₀ + √ρ · Q⁻¹m / √(mᵀQ⁻¹m)
    /// ```
    ///
    /// (∇p(u*) = 2√ρ·m/√(mᵀQ⁻¹m) ∥ m and p(u*) = 1: the KKT point of the module docs). `None`
    /// when p is not of degree 2, Q is not positive definite, or ρ ≤ 0 (then [`Self::new`]
    /// applies). A primitive's bounding ellipsoid is built this way when a scene is imported.
    pub fn quadratic(p: &Polynomial) -> Option<Self> {
        if p.degree() != 2 {
            return None;
        }
        let (mut q, mut b, mut c) = (crate::math::Matrix3::zeros(), Vector3::zeros(), 0.0);
        for (e, &v) in p.exponents().iter().zip(p.coefficients()) {
            let at: Vec<usize> = (0..3).flat_map(|i| std::iter::repeat_n(i, e[i] as usize)).collect();
            match at[..] {
                [] => c += v,
                [i] => b[i] += v,
                [i, j] if i == j => q[(i, i)] += v,
                [i, j] => {
                    q[(i, j)] += 0.5 * v;
                    q[(j, i)] += 0.5 * v;
                }
                _ => return None,
            }
        }
        let chol = q.cholesky()?;
        let center = chol.solve(&b) * -0.5;
        let rho = 1.0 - (center.dot(&(q * center)) + b.dot(&center) + c);
        if !(rho.is_finite() && rho > 0.0) {
            return None;
        }
        let root = rho.sqrt();
        let mut points = Box::new([[[0.0; 3]; NODES * NODES]; 6]);
        for (face, nodes) in points.iter_mut().enumerate() {
            for (k, node) in nodes.iter_mut().enumerate() {
                let m = node_direction(face, k, SUPPORT_GRID);
                let w = chol.solve(&m);
                let u = center + w * (root / m.dot(&w).sqrt());
                if !(u.x.is_finite() && u.y.is_finite() && u.z.is_finite()) {
                    return None;
                }
                *node = [u.x, u.y, u.z];
            }
        }
        Some(Self { points })
    }

    /// The (interpolated) support point in the direction of `m` (any nonzero length; normalized
    /// units). Returns `None` for a zero or non-finite `m`.
    #[inline(always)]
    pub fn support(&self, m: &Vector3) -> Option<Vector3> {
        let (face, a, b) = face_coordinates(m);
        if !(a.is_finite() && b.is_finite()) {
            return None;
        }
        let half = 0.5 * SUPPORT_GRID as Real;
        let (fa, fb) = ((a + 1.0) * half, (b + 1.0) * half);
        let (i, j) = (grid_cell(fa), grid_cell(fb));
        let (ta, tb) = (fa - i as Real, fb - j as Real);
        let r = &self.points[face];
        let k = j * NODES + i;
        let lerp = |p: &[Real; 3], q: &[Real; 3], t: Real| {
            Vector3::new(p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t, p[2] + (q[2] - p[2]) * t)
        };
        let low = lerp(&r[k], &r[k + 1], ta);
        let high = lerp(&r[k + NODES], &r[k + NODES + 1], ta);
        Some(low + (high - low) * tb)
    }
}

/// The index of the candidate `(xs[i], ys[i], zs[i])` farthest along `m` (the last of equals;
/// `None` when there is none or every product is NaN).
fn best_candidate(m: &Vector3, xs: &[Real], ys: &[Real], zs: &[Real]) -> Option<usize> {
    let (mut best, mut at) = (Real::NEG_INFINITY, None);
    for (i, ((x, y), z)) in xs.iter().zip(ys).zip(zs).enumerate() {
        let d = m.x * x + m.y * y + m.z * z;
        if d >= best {
            best = d;
            at = Some(i);
        }
    }
    at
}

/// Certified upper bounds of the support function `h(m) = max{m·u : p(u) ≤ 1}` of a convex body
/// (normalized units) at the nodes of the [`SupportTable`]'s cube map, and their interpolation:
/// an upper bound of h in every direction (the tight cheap bounds of the tree queries,
/// `sublevel_query::tree`).
///
/// At a node direction v (unnormalized, `face_direction(face, a_i, b_j)`) with tabulated support
/// point s, convexity gives the supporting halfspace of the tangent plane at s, and the body's
/// box [lo, hi] ([`bounding_box_from_support`]) contains the body too; weak duality of
/// `max{v·w : g·w ≤ c, w ∈ box}` bounds h(v) whatever the accuracy of s:
///
/// ```text
/// g = ∇p(s),  c = g·s + 1 − p(s):   p(w) ≥ p(s) + g·(w − s)  ⇒  {p ≤ 1} ⊂ {w : g·w ≤ c}
/// H(v) = min( h_box(v),  λc + h_box(v − λg) ),   λ = v·g / g·g ≥ 0,
/// h_box(e) = e·(lo + hi)/2 + Σₖ |eₖ| (hiₖ − loₖ)/2
/// ```
///
/// Between nodes, h is sublinear (positively homogeneous and subadditive) and a direction m on
/// face f is a nonnegative combination of its cell's four node directions with the bilinear
/// weights of its face coordinates (face_direction is linear in (a, b)):
///
/// ```text
/// m / |m_f| = Σ w_ij v_ij,  w_ij ≥ 0, Σ w_ij = 1   ⇒   h(m) ≤ |m_f| Σ w_ij H(v_ij)
/// ```
///
/// The interpolation error is second order in the cell's angle (11° at most): on a sphere the
/// bound exceeds h by < 1 %. Valid only for convex p (a nonconvex body has no such table).
#[derive(Clone, Debug, PartialEq)]
pub struct SupportBound {
    /// H at the nodes (same layout as [`SupportTable`]'s points), padded for rounding.
    h: Box<[[Real; NODES * NODES]; 6]>,
}

impl SupportBound {
    /// Bounds the support function of the convex body `{p ≤ 1}` at the nodes of `table` (its
    /// support map), using the box `(lo, hi)` that contains the body (normalized units). Each node
    /// is padded by 10⁻⁹ of the box's width times |v| for rounding (as the box itself is).
    pub fn new(p: &FastPoly, table: &SupportTable, lo: &Vector3, hi: &Vector3) -> Self {
        let mid = (lo + hi) * 0.5;
        let half = (hi - lo) * 0.5;
        let h_box = |e: &Vector3| e.dot(&mid) + e.abs().dot(&half);
        let pad = 1e-9 * (hi - lo).norm();
        let mut h = Box::new([[0.0; NODES * NODES]; 6]);
        for (face, nodes) in h.iter_mut().enumerate() {
            for (k, node) in nodes.iter_mut().enumerate() {
                let v = node_direction(face, k, SUPPORT_GRID);
                let s = Vector3::from(table.points[face][k]);
                let (ps, g) = p.value_gradient(&s);
                let mut bound = h_box(&v);
                let gg = g.norm_squared();
                let lam = v.dot(&g) / gg;
                if ps.is_finite() && gg.is_finite() && gg > 0.0 && lam.is_finite() && lam > 0.0 {
                    let c = g.dot(&s) + 1.0 - ps;
                    let dual = lam * c + h_box(&(v - g * lam));
                    if dual.is_finite() {
                        bound = bound.min(dual);
                    }
                }
                *node = bound + pad * v.norm();
            }
        }
        Self { h }
    }

    /// The same bound for the body in the coordinates `x = center + scale·u` (scale > 0; e.g. a
    /// body's frame in meters): `h_x(v) = v·center + scale·h_u(v)` at every node, padded by 10⁻¹²
    /// of the terms for rounding.
    pub fn in_frame(&self, center: &Vector3, scale: Real) -> Self {
        let mut h = self.h.clone();
        for (face, nodes) in h.iter_mut().enumerate() {
            for (k, value) in nodes.iter_mut().enumerate() {
                let v = node_direction(face, k, SUPPORT_GRID);
                let (offset, spread) = (v.dot(center), scale * *value);
                *value = offset + spread + 1e-12 * (offset.abs() + spread.abs());
            }
        }
        Self { h }
    }

    /// The bound of the union of two sets given in the same coordinates (node-wise max): the
    /// support function of a union is the max of the two (and that of its convex hull too).
    pub fn union(&self, other: &Self) -> Self {
        let mut h = self.h.clone();
        for (mine, theirs) in h.iter_mut().zip(other.h.iter()) {
            for (x, y) in mine.iter_mut().zip(theirs.iter()) {
                *x = x.max(*y);
            }
        }
        Self { h }
    }

    /// The tighter of two bounds of the same set (node-wise min): both are upper bounds of its
    /// support function at every node, so is their min.
    pub fn tighten(&mut self, other: &Self) {
        for (mine, theirs) in self.h.iter_mut().zip(other.h.iter()) {
            for (x, y) in mine.iter_mut().zip(theirs.iter()) {
                *x = x.min(*y);
            }
        }
    }

    /// An upper bound of `max{m·u : p(u) ≤ 1}` (normalized units) for any `m`: +∞ for a zero or
    /// non-finite `m` (a bound that bounds nothing).
    #[inline]
    pub fn upper(&self, m: &Vector3) -> Real {
        // face_coordinates without branches (the directions of successive calls vary, and a
        // mispredicted face costs more than the arithmetic) and with one division: the axis i of
        // the largest component (ties: any of them, every face's table bounds its directions),
        // the face 2i + (mᵢ < 0), and the grid coordinates (a + 1)·G/2 of a = m_{i+1}/|mᵢ|,
        // b = m_{i+2}/|mᵢ| (face_direction's order: x → (y, z), y → (z, x), z → (x, y)).
        let c = [m.x, m.y, m.z];
        let (ax, ay, az) = (c[0].abs(), c[1].abs(), c[2].abs());
        let i = usize::from(ay > ax && ay >= az) + 2 * usize::from(az > ax && az > ay);
        let major = c[i].abs();
        let face = 2 * i + usize::from(c[i] < 0.0);
        let (u, v) = (c[(i + 1) % 3], c[(i + 2) % 3]);
        let half = 0.5 * SUPPORT_GRID as Real;
        let scale = half / major;
        let (fa, fb) = (u * scale + half, v * scale + half);
        if !(fa.is_finite() && fb.is_finite()) {
            return Real::INFINITY;
        }
        let (i, j) = (grid_cell(fa), grid_cell(fb));
        // Clamped into [0, 1]: the weights stay nonnegative whatever the rounding.
        let (ta, tb) = ((fa - i as Real).clamp(0.0, 1.0), (fb - j as Real).clamp(0.0, 1.0));
        let r = &self.h[face];
        let k = j * NODES + i;
        let low = r[k] + (r[k + 1] - r[k]) * ta;
        let high = r[k + NODES] + (r[k + NODES + 1] - r[k + NODES]) * ta;
        major * (low + (high - low) * tb)
    }
}

/// The cell of a grid coordinate `f ∈ [0, G]`, clamped into `0..G`. Through i32: f64 → i32 is
/// one instruction, f64 → usize a branchy saturating sequence (about a quarter of the
/// instructions of [`SupportBound::upper`]).
#[inline(always)]
fn grid_cell(f: Real) -> usize {
    (f as i32).clamp(0, SUPPORT_GRID as i32 - 1) as usize
}

/// Newton on `m = λ∇p(u)`, `p(u) = 1` from the boundary point `start` (unit `m`); `Some` only
/// when it ends on the boundary (|p − 1| ≤ 10⁻¹⁰) with λ > 0 and a stationarity residual ≤ 10⁻⁹.
fn polish(p: &FastPoly, m: &Vector3, start: Vector3) -> Option<Vector3> {
    let mut u = start;
    let (_, g0) = p.value_gradient(&u);
    let mut lam = m.dot(&g0) / g0.norm_squared().max(Real::MIN_POSITIVE);
    for _ in 0..12 {
        let e = p.eval(&u);
        let r = e.gradient * lam - m;
        let c = e.value - 1.0;
        if c.abs() <= 1e-10 && r.norm() <= 1e-9 && lam > 0.0 {
            // A KKT point with λ > 0 maximizes m·u over a convex body.
            return Some(u);
        }
        let mut jac = nalgebra::Matrix4::<Real>::zeros();
        jac.fixed_view_mut::<3, 3>(0, 0).copy_from(&(e.hessian * lam));
        jac.fixed_view_mut::<3, 1>(0, 3).copy_from(&e.gradient);
        jac.fixed_view_mut::<1, 3>(3, 0).copy_from(&e.gradient.transpose());
        let rhs = nalgebra::Vector4::new(-r.x, -r.y, -r.z, -c);
        let step = jac.lu().solve(&rhs)?;
        u += Vector3::new(step[0], step[1], step[2]);
        lam += step[3];
        if !(u.iter().all(|v| v.is_finite()) && lam.is_finite()) {
            return None;
        }
    }
    None
}

/// The support point in the unit direction `m` as the minimizer u(t) of the convex function
/// `p(u) − t·m·u` at the t where `p(u(t)) = 1` (then ∇p(u) = t m: the KKT point of
/// `max m·u s.t. p ≤ 1` with λ = 1/t), from the boundary point `start`: damped Newton for u(t),
/// safeguarded Newton for t on g(t) = p(u(t)) − 1, which increases with t (dg/dt = t mᵀ∇²p⁻¹m),
/// with a tangent predictor u += Δt ∇²p⁻¹m. The fallback of [`polish`]: plain Newton on the KKT
/// system diverges from the radial table's candidate on thin bodies (15 % of the nodes of the
/// bundled compound chair's parts, whose tables then kept the candidates and loosened their
/// support bounds). Same acceptance test as [`polish`]; `None` when it is not met.
fn support_by_penalty(p: &FastPoly, m: &Vector3, start: Vector3) -> Option<Vector3> {
    let mut u = start;
    let (_, g0) = p.value_gradient(&u);
    let along = m.dot(&g0);
    // At the start ∇p ≈ t m along m: t = |∇p|² / m·∇p (the least-squares 1/λ), or |∇p| when the
    // candidate's normal points away from m (the bracketing of t takes over).
    let mut t = if along > 0.0 { g0.norm_squared() / along } else { g0.norm() };
    if !(t.is_finite() && t > 0.0) {
        return None;
    }
    let (mut lo, mut hi) = (0.0, Real::INFINITY);
    let solve = |h: &crate::math::Matrix3, v: &Vector3| -> Option<Vector3> {
        let reg = crate::math::Matrix3::identity() * (1e-14 * (1.0 + h.norm()));
        Some(nalgebra::Cholesky::new(h + reg)?.solve(v))
    };
    for _ in 0..60 {
        // u(t): damped Newton on f(u) = p(u) − t m·u (convex).
        for _ in 0..50 {
            let e = p.eval(&u);
            let grad = e.gradient - m * t;
            let mut step = solve(&e.hessian, &grad).map_or(-grad, |s| -s);
            // Where ∇²p is (nearly) singular (a flat point of a thin body) the step is huge:
            // capped at the scale of the body (normalized coordinates: |u| ≲ 1).
            let cap = 1.0 + u.norm();
            let length = step.norm();
            if length > cap {
                step *= cap / length;
            }
            let dec = -grad.dot(&step);
            if dec.is_nan() || dec <= 1e-30 * (1.0 + t * t) {
                break;
            }
            let f0 = e.value - t * m.dot(&u);
            let mut alpha = 1.0;
            while alpha > 1e-12 {
                let trial = u + step * alpha;
                let (pt, gt) = p.value_gradient(&trial);
                let ft = pt - t * m.dot(&trial);
                // Near the minimizer f's decrease drowns in rounding: a step that halves the
                // gradient is accepted too.
                let descent = ft.is_finite() && ft <= f0 - 0.25 * alpha * dec;
                if descent || (gt - m * t).norm() <= 0.5 * grad.norm() {
                    u = trial;
                    break;
                }
                alpha *= 0.5;
            }
            if alpha <= 1e-12 {
                break;
            }
        }
        let e = p.eval(&u);
        let g = e.value - 1.0;
        let r = e.gradient / t - m;
        if g.abs() <= 1e-10 && r.norm() <= 1e-9 {
            return Some(u);
        }
        if g > 0.0 {
            hi = t;
        } else {
            lo = t;
        }
        let dir = solve(&e.hessian, m)?;
        let slope = t * m.dot(&dir);
        let newton = t - g / slope;
        let next = if slope > 0.0 && newton > lo && newton < hi {
            newton
        } else if hi.is_finite() && lo > 0.0 {
            (lo * hi).sqrt()
        } else if hi.is_finite() {
            0.25 * hi
        } else {
            4.0 * lo
        };
        if !(next.is_finite() && next > 0.0) {
            return None;
        }
        // Tangent predictor, capped as the Newton steps are.
        let (shift, cap) = (dir * (next - t), 1.0 + u.norm());
        u += shift * (cap / shift.norm().max(cap));
        t = next;
    }
    None
}

/// The axis-aligned bounding box `(lo, hi)` of `{p ≤ 1}` from the points `support(e)` near its
/// support points along the six axis directions e = ±eₖ (e.g. a body's tabulated support map,
/// [`SupportTable`], whose cube map has a node on every axis): the box contains the body whatever their accuracy.
///
/// # Errors
/// [`Error::Numerical`] when the six supporting halfspaces do not form a box-like polytope, and
/// any error of `support`.
pub fn bounding_box_from_support(
    p: &Polynomial,
    mut support: impl FnMut(&Vector3) -> Result<Vector3>,
) -> Result<(Vector3, Vector3)> {
    // planes[k][s]: normal and offset for direction (−1)^s eₖ.
    let mut planes = [[(Vector3::zeros(), 0.0); 2]; 3];
    for (k, pair) in planes.iter_mut().enumerate() {
        for (s, plane) in pair.iter_mut().enumerate() {
            let mut e = Vector3::zeros();
            e[k] = if s == 0 { 1.0 } else { -1.0 };
            let v = support(&e)?;
            let (pv, n) = p.value_gradient(&v);
            let along = n.dot(&e);
            if along.is_nan() || along <= 0.9 * n.norm() {
                return Err(Error::Numerical(format!("support normal {n} is not close to the axis {e}")));
            }
            *plane = (n, n.dot(&v) + 1.0 - pv);
        }
    }
    let mut lo = Vector3::repeat(Real::INFINITY);
    let mut hi = Vector3::repeat(Real::NEG_INFINITY);
    for corner in 0..8 {
        let pick = |k: usize| planes[k][(corner >> k) & 1];
        let (a, b) = ((0..3).map(|k| pick(k).0.transpose()).collect::<Vec<_>>(), Vector3::from_fn(|k, _| pick(k).1));
        let m = crate::math::Matrix3::from_rows(&a);
        let x =
            m.lu().solve(&b).ok_or_else(|| Error::Numerical("singular corner system in the bounding box".into()))?;
        // The corner must satisfy the three opposite halfspaces (cube-like combinatorics).
        for (k, pair) in planes.iter().enumerate() {
            let (n, c) = pair[1 - ((corner >> k) & 1)];
            if n.dot(&x) > c + 1e-9 * (1.0 + c.abs()) {
                return Err(Error::Numerical("the supporting halfspaces do not form a box-like polytope".into()));
            }
        }
        lo = lo.inf(&x);
        hi = hi.sup(&x);
    }
    let pad = (hi - lo) * 1e-9;
    Ok((lo - pad, hi + pad))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Matrix3;
    use crate::poly::radial::face_direction;
    use crate::poly::Polynomial;
    use rand::{Rng, SeedableRng};

    /// p(u) = Σ (uᵢ/rᵢ)² and its support table about the origin.
    fn ellipsoid_table(radii: [Real; 3]) -> (FastPoly, SupportTable) {
        let terms: Vec<([u8; 3], Real)> = (0..3)
            .map(|i| {
                let mut e = [0u8; 3];
                e[i] = 2;
                (e, 1.0 / (radii[i] * radii[i]))
            })
            .collect();
        let p = Polynomial::from_terms(2, &terms).unwrap().fast();
        let center = Vector3::zeros();
        let table = SupportTable::new(&p, &RadialTable::new(&p, &center), &center);
        (p, table)
    }

    #[test]
    fn best_candidate_is_the_last_maximum_of_the_products() {
        // Against a plain scan of m·u (nalgebra's dot), with repeated points for ties.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let pts: Vec<Vector3> = (0..300)
            .map(|k| {
                if k % 7 == 6 {
                    Vector3::new(0.5, -0.25, 0.125)
                } else {
                    Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                }
            })
            .collect();
        let (xs, ys, zs): (Vec<Real>, Vec<Real>, Vec<Real>) =
            (pts.iter().map(|p| p.x).collect(), pts.iter().map(|p| p.y).collect(), pts.iter().map(|p| p.z).collect());
        for case in 0..200 {
            let m = if case == 0 {
                Vector3::new(1.0, -0.5, 0.25)
            } else {
                Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
            };
            let top = pts.iter().map(|p| m.dot(p)).fold(Real::NEG_INFINITY, Real::max);
            let last = pts.iter().rposition(|p| m.dot(p) == top);
            assert_eq!(best_candidate(&m, &xs, &ys, &zs), last, "case {case}");
        }
        assert_eq!(best_candidate(&Vector3::x(), &[], &[], &[]), None);
    }

    #[test]
    fn ellipsoid_support_matches_closed_form() {
        // p(u) = Σ (uᵢ/rᵢ)²: u*(m) = D² m / ‖D m‖ with D = diag(r).
        let radii = [0.9, 0.5, 0.3];
        let (_, table) = ellipsoid_table(radii);
        let exact = |m: &Vector3| {
            let dm = Vector3::new(radii[0] * m.x, radii[1] * m.y, radii[2] * m.z);
            Vector3::new(radii[0] * dm.x, radii[1] * dm.y, radii[2] * dm.z) / dm.norm()
        };
        // Nodes are solved to Newton's tolerance.
        for face in 0..6 {
            let m = face_direction(face, 0.25, -0.5);
            let err = (table.support(&m).unwrap() - exact(&m)).norm();
            assert!(err <= 1e-8, "face {face}: {err}");
        }
        // Between nodes: the support value m·u within 7 % of h(m) = ‖D m‖ on this 3:1 ellipsoid
        // (measured 6.6 % at worst, near the long axis where the support point moves fastest).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut worst: Real = 0.0;
        for _ in 0..2000 {
            let m = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                .normalize();
            let u = table.support(&m).unwrap();
            let h = m.dot(&exact(&m));
            worst = worst.max((h - m.dot(&u)).abs() / h);
        }
        assert!(worst <= 0.07, "largest relative support-value error {worst}");
        assert!(table.support(&Vector3::zeros()).is_none());
    }

    #[test]
    fn a_quadratic_table_in_closed_form_equals_the_searched_one() {
        // A rotated, off-center ellipsoid: p(u) = (u − c)ᵀ Rᵀ D⁻² R (u − c) + 0.2 expanded into
        // monomials (cross and linear terms), its table in closed form against the Newton search
        // of `SupportTable::new`, node by node, and p = 1, ∇p ∥ m at every node.
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let d = Matrix3::from_diagonal(&Vector3::new(1.0 / 0.64, 1.0 / 0.09, 1.0 / 0.25));
        let q = r.transpose() * d * r;
        let c = Vector3::new(0.1, -0.2, 0.05);
        let b = -2.0 * q * c;
        let k = c.dot(&(q * c)) + 0.2;
        let mut terms = vec![([0, 0, 0], k)];
        for i in 0..3 {
            let mut e = [0u8; 3];
            e[i] = 1;
            terms.push((e, b[i]));
            for j in i..3 {
                let mut e = [0u8; 3];
                e[i] += 1;
                e[j] += 1;
                terms.push((e, if i == j { q[(i, i)] } else { 2.0 * q[(i, j)] }));
            }
        }
        let p = Polynomial::from_terms(2, &terms).unwrap();
        let closed = SupportTable::quadratic(&p).unwrap();
        let fast = p.fast();
        let searched = SupportTable::new(&fast, &RadialTable::new(&fast, &c), &c);
        for face in 0..6 {
            for (node, (u, v)) in closed.nodes()[face].iter().zip(&searched.nodes()[face]).enumerate() {
                let (u, v) = (Vector3::from(*u), Vector3::from(*v));
                assert!((u - v).norm() <= 1e-8, "face {face} node {node}: {u} against {v}");
                let (value, gradient) = p.value_gradient(&u);
                let m = node_direction(face, node, SUPPORT_GRID).normalize();
                assert!((value - 1.0).abs() <= 1e-12, "p = {value}");
                assert!((gradient.normalize() - m).norm() <= 1e-12);
            }
        }
        // Not quadratic, or an empty sublevel set: no closed form.
        let quartic = Polynomial::from_terms(4, &[([4, 0, 0], 1.0), ([0, 4, 0], 1.0), ([0, 0, 4], 1.0)]).unwrap();
        assert!(SupportTable::quadratic(&quartic).is_none());
        let empty =
            Polynomial::from_terms(2, &[([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0), ([0, 0, 0], 1.5)]);
        assert!(SupportTable::quadratic(&empty.unwrap()).is_none());
    }

    #[test]
    fn support_bound_is_above_and_close_to_the_ellipsoid_support_function() {
        // h(m) = ‖D m‖ for p(u) = Σ (uᵢ/rᵢ)², and the exact box is [−r, r].
        let radii = [0.9, 0.5, 0.3];
        let (p, table) = ellipsoid_table(radii);
        let r = Vector3::from(radii);
        let bound = SupportBound::new(&p, &table, &(-r * 1.001), &(r * 1.001));
        let exact = |m: &Vector3| Vector3::new(radii[0] * m.x, radii[1] * m.y, radii[2] * m.z).norm();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut worst: Real = 0.0;
        for _ in 0..5000 {
            let m = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                * rng.random_range(0.1..3.0);
            let (h, hb) = (exact(&m), bound.upper(&m));
            assert!(hb >= h, "{m}: bound {hb} below h {h}");
            worst = worst.max((hb - h) / h);
        }
        // Second order in the cell angle: measured 6.8 % at worst on this 3:1 ellipsoid, near
        // the short axes where h curves most (h ≈ 0.3 + 1.2 δ² there, δ up to half a cell).
        assert!(worst <= 0.08, "largest relative excess {worst}");
        // At the nodes, exact up to the padding.
        for face in 0..6 {
            let m = face_direction(face, 0.25, -0.5);
            assert!((bound.upper(&m) - exact(&m)).abs() <= 1e-8, "face {face}");
        }
        assert_eq!(bound.upper(&Vector3::zeros()), Real::INFINITY);
    }

    #[test]
    fn thin_quartic_table_is_exact_at_every_node() {
        // p(u) = Σ (uᵢ/rᵢ)⁴ (sos-convex: separable convex), a 50:1 slab. By Hölder,
        // u*(m)ᵢ = rᵢ sign(mᵢ) (|mᵢ| rᵢ)^(1/3) / (Σⱼ (|mⱼ| rⱼ)^(4/3))^(1/4).
        let radii: [Real; 3] = [1.0, 0.02, 0.3];
        let terms: Vec<([u8; 3], Real)> = (0..3)
            .map(|i| {
                let mut e = [0u8; 3];
                e[i] = 4;
                (e, radii[i].powi(-4))
            })
            .collect();
        let p = Polynomial::from_terms(4, &terms).unwrap().fast();
        let exact = |m: &Vector3| {
            let w = Vector3::from_fn(|i, _| (m[i].abs() * radii[i]).powf(1.0 / 3.0));
            let norm = (0..3).map(|i| (m[i].abs() * radii[i]).powf(4.0 / 3.0)).sum::<Real>().powf(0.25);
            Vector3::from_fn(|i, _| radii[i] * m[i].signum() * w[i] / norm)
        };
        let center = Vector3::zeros();
        let radial = RadialTable::new(&p, &center);
        let table = SupportTable::new(&p, &radial, &center);
        let (mut newton_failures, mut nodes) = (0, 0);
        for (face, points) in table.points.iter().enumerate() {
            for (k, u) in points.iter().enumerate() {
                let m = node_direction(face, k, SUPPORT_GRID).normalize();
                // The support value and the boundary: the point itself is ill-determined along
                // the quartic's flat directions (e.g. uᵢ near 0, where ∂²p/∂uᵢ² = 12uᵢ²/rᵢ⁴ → 0).
                let u = Vector3::from(*u);
                let (h, err) = (m.dot(&exact(&m)), (m.dot(&u) - m.dot(&exact(&m))).abs());
                assert!(err <= 1e-10 * h && (p.value(&u) - 1.0).abs() <= 1e-9, "face {face} node {k}: {err}");
                // The fallback is what makes it exact: plain Newton on the KKT system from the same
                // candidate fails on part of the nodes of so thin a body.
                let c = (CANDIDATE_GRID + 1) * (CANDIDATE_GRID + 1);
                let start = (0..6 * c)
                    .map(|i| node_direction(i / c, i % c, CANDIDATE_GRID).normalize())
                    .map(|dir| dir * radial.radius(&dir))
                    .max_by(|u, v| m.dot(u).total_cmp(&m.dot(v)))
                    .unwrap();
                newton_failures += usize::from(polish(&p, &m, start).is_none());
                nodes += 1;
            }
        }
        assert!(newton_failures > 0, "plain Newton converged at all {nodes} nodes");
        // From a poor start (the boundary point in a direction 90° away) the fallback still lands
        // on the exact support point.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200 {
            let m = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                .normalize();
            let side = m.cross(&Vector3::new(0.3, -0.5, 0.8)).normalize();
            let u = support_by_penalty(&p, &m, side * radial.radius(&side)).unwrap();
            let (h, err) = (m.dot(&exact(&m)), (m.dot(&u) - m.dot(&exact(&m))).abs());
            assert!(err <= 1e-10 * h && (p.value(&u) - 1.0).abs() <= 1e-9, "{m}: {u} vs {}", exact(&m));
        }
    }
}
