//! Certified lower bounds of the distance between the moving instance and one static obstacle,
//! at two levels: a cheap one (bounding spheres, separating axis) and a refined one (the exact or
//! proven distance of the pair's kind). Every value returned is a lower bound of the true distance
//! (meters); `exact` says whether it is also within a fraction of the tolerance of it.
//!
//! ```text
//! pair (moving, obstacle)       cheap (level 0)                  refined (level 1)
//! primitive – primitive         bounding spheres                 shape_distance: its separating-plane
//!                                                                certificate (exact support functions)
//! primitive – single body       bounding spheres                 shape_distance, then the plane bound
//!                                                                below along its normal
//! primitive – compound body     bounding spheres                 the least over the tree's leaves of
//!                                                                the row above, leaves taken in the
//!                                                                order of their sphere gaps
//! single – single body          spheres, then separating axis    Newton (warm along the motion), then
//!                                                                the plane bound; a nonconvex body or
//!                                                                an unconverged solve: the level-0
//!                                                                SDP's verified bound
//! compound – any body           root bounding spheres            the tree search's lower bound (warm
//!                                                                along the motion)
//! ```
//!
//! **The plane bound.** For a unit normal n (from the moving side A towards B) every pair of points
//! has `‖x − y‖ ≥ n·(y − x)`, so
//!
//! ```text
//! dist(A, B) ≥ min_{y∈B} n·y − max_{x∈A} n·x = −H_B(−n) − H_A(n)
//! ```
//!
//! for any upper bounds H of the support functions. A primitive's support function is a closed
//! form. A convex body `{p ≤ 1}` lies in the halfspace of its tangent plane at any point x
//! (`p(w) ≥ p(x) + g·(w − x)` with `g = ∇p(x)`) and in its bounding box, so weak duality of
//! `max{e·w : g·w ≤ c, w ∈ box}` gives, for every λ ≥ 0,
//!
//! ```text
//! H(e) = min( h_box(e),  λ c + h_box(e − λ g) ),   c = g·x + 1 − p(x),   λ = e·g / g·g
//! ```
//!
//! whatever the accuracy of x. At the solver's witness points the tangent planes are normal to n
//! up to the KKT residual, so the bound meets the solver's distance to about that residual times
//! the box's size: the solver finds the distance, the planes prove a bound of it. A bound is
//! `exact` when it lies within [`EXACT_FRACTION`] of the tolerance of the solver's distance; only
//! exact bounds report a contact.

use crate::answer::Posed;
use std::sync::Arc;
use sublevel_core::body::Body;
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_query::dispatch::{self, PosedRef};
use sublevel_query::shape::{shape_distance, ShapeRef, ShapeWarmStart};
use sublevel_query::tree::{tree_distance, TreeWarmStart};
use sublevel_query::{certified_distance, distance, AnswerSource, CertifyMode, CertifyParams, DistanceWarmStart};

/// A refined bound counts as exact when it is within this fraction of the tolerance of the
/// solver's distance (the claim of a contact answer: the distance there is at most
/// `padding + (1 + EXACT_FRACTION) · tolerance`).
pub const EXACT_FRACTION: Real = 0.25;

/// Relative rounding pad of a primitive's support value (meters per meter of the terms).
const PRIMITIVE_ROUNDING: Real = 1e-12;

/// Rounding pad of a body's tangent-plane support bound, per meter of its bounding box's
/// diagonal: as [`sublevel_core::poly::SupportBound`] pads its nodes, it covers the evaluation
/// error of p and ∇p at the witness.
const BODY_ROUNDING: Real = 1e-9;

/// A certified lower bound of a pair's distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Bound {
    /// The bound (meters, ≥ 0).
    pub(super) lower: Real,
    /// Whether it lies within [`EXACT_FRACTION`] of the tolerance of the pair's distance.
    pub(super) exact: bool,
}

impl Bound {
    /// A bound that proves nothing more than `lower` (not exact).
    fn loose(lower: Real) -> Self {
        Self { lower: lower.max(0.0), exact: false }
    }

    /// A proven bound `lower` against the solver's distance `solved` (meters), exact when within
    /// `slack` of it.
    fn against(lower: Real, solved: Real, slack: Real) -> Self {
        let lower = lower.max(0.0);
        Self { lower, exact: (solved - lower).abs() <= slack }
    }
}

/// How a pair is bounded (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Route {
    Primitives,
    PrimitiveBody,
    PrimitiveLeaves,
    Bodies,
    Trees,
}

/// One obstacle of a motion, with the warm starts its refined bounds keep along the motion.
pub(super) struct Obstacle {
    /// Index of the obstacle among the scene's instances.
    pub(super) index: usize,
    route: Route,
    /// The leaves of the obstacle's or the moving body's tree (primitive – compound pairs).
    leaves: Vec<usize>,
    shape: ShapeWarmStart,
    distance: Option<Arc<DistanceWarmStart>>,
    tree: Option<TreeWarmStart>,
}

impl Obstacle {
    /// The obstacle `index` posed as `o`, against the moving side `m`.
    pub(super) fn new(index: usize, m: &PosedRef<'_>, o: &PosedRef<'_>) -> Self {
        let route = if m.primitive.is_some() && o.primitive.is_some() {
            Route::Primitives
        } else if m.primitive.is_some() || o.primitive.is_some() {
            if m.tree.is_some() || o.tree.is_some() {
                Route::PrimitiveLeaves
            } else {
                Route::PrimitiveBody
            }
        } else if m.tree.is_some() || o.tree.is_some() {
            Route::Trees
        } else {
            Route::Bodies
        };
        let leaves = match (route, m.tree.or(o.tree)) {
            (Route::PrimitiveLeaves, Some(t)) => leaves_of(t),
            _ => Vec::new(),
        };
        Self { index, route, leaves, shape: ShapeWarmStart::default(), distance: None, tree: None }
    }

    /// The cheap lower bound (level 0, meters, ≥ 0): bounding spheres, and the separating axis of
    /// two single bodies; 0 where a side has none (a halfspace, a nonconvex body).
    pub(super) fn cheap(&self, m: &PosedRef<'_>, o: &PosedRef<'_>) -> Real {
        let bound = match self.route {
            Route::Primitives | Route::PrimitiveBody | Route::PrimitiveLeaves => dispatch::primitive_lower_bound(m, o),
            Route::Trees => dispatch::sphere_lower_bound(m.body, &m.pose, o.body, &o.pose),
            Route::Bodies => dispatch::collide_lower_bound(m.body, &m.pose, o.body, &o.pose, Real::INFINITY),
        };
        bound.unwrap_or(0.0).max(0.0)
    }

    /// The refined bound (level 1; module docs), with `tolerance` the motion's contact tolerance
    /// (meters); `cheap` is the pair's level-0 bound, kept where the refinement proves less.
    /// Keeps the pair's warm starts for the next pose of the motion.
    pub(super) fn refined(
        &mut self,
        m: &PosedRef<'_>,
        o: &PosedRef<'_>,
        params: &CertifyParams,
        tolerance: Real,
        cheap: Real,
    ) -> Bound {
        let slack = EXACT_FRACTION * tolerance;
        let bound = match self.route {
            Route::Primitives | Route::PrimitiveBody => {
                let (bound, warm) = shape_bound(m, o, Some(&self.shape), slack);
                if let Some(w) = warm {
                    self.shape = w;
                }
                bound
            }
            Route::PrimitiveLeaves => self.leaves_bound(m, o, slack),
            Route::Bodies => self.bodies_bound(m, o, params, slack),
            Route::Trees => {
                let tree_params = dispatch::tree_params(params, CertifyMode::Newton, slack);
                match tree_distance(m.as_tree(), &m.pose, o.as_tree(), &o.pose, self.tree.as_ref(), &tree_params) {
                    Ok(r) => {
                        self.tree = Some(r.warm_start);
                        Bound { lower: r.lower.max(0.0), exact: r.within_tolerance }
                    }
                    Err(_) => Bound::loose(0.0),
                }
            }
        };
        if bound.lower < cheap {
            Bound { lower: cheap, ..bound }
        } else {
            bound
        }
    }

    /// Two single bodies: Newton warm-started along the motion and the plane bound at its
    /// witnesses; the level-0 SDP's verified bound for a nonconvex body or an unconverged solve.
    fn bodies_bound(&mut self, m: &PosedRef<'_>, o: &PosedRef<'_>, params: &CertifyParams, slack: Real) -> Bound {
        let (a, b) = (m.body, o.body);
        if !(a.report.nonconvex || b.report.nonconvex) {
            let r = distance(a, &m.pose, b, &o.pose, self.distance.as_deref(), &params.newton);
            if r.status.converged() {
                self.distance = Some(r.warm_start.clone());
                if r.overlapping {
                    // Distance 0 is proven by a point in both bodies.
                    let inside = |body: &Body, pose: &Isometry3| {
                        body.value_at(&pose.inverse_transform_point(&r.witness_a)) <= 1.0 + 1e-9
                    };
                    return if inside(a, &m.pose) && inside(b, &o.pose) {
                        Bound { lower: 0.0, exact: true }
                    } else {
                        Bound::loose(0.0)
                    };
                }
                return match plane_bound(m, &r.witness_a, o, &r.witness_b, &r.normal) {
                    Some(lower) => Bound::against(lower, r.distance, slack),
                    None => Bound::loose(0.0),
                };
            }
            self.distance = None;
        }
        // The SDP: a verified lower bound (slow; for what Newton cannot prove).
        let c = certified_distance(a, &m.pose, b, &o.pose, None, params, CertifyMode::Newton);
        let verified = c.certificate.as_ref().filter(|s| s.verified && c.converged);
        match (c.source, verified) {
            (AnswerSource::SdpFallback, Some(s)) => {
                Bound::against(s.bound.min(s.verified_bound).max(0.0).sqrt(), c.result.distance, slack)
            }
            (AnswerSource::SdpLowerBound, Some(_)) => Bound { lower: c.result.distance.max(0.0), exact: c.tight },
            _ => Bound::loose(0.0),
        }
    }

    /// A primitive against a compound body: the least bound over the tree's leaves, each leaf's
    /// refined only while its sphere gap is below the least refined so far.
    fn leaves_bound(&self, m: &PosedRef<'_>, o: &PosedRef<'_>, slack: Real) -> Bound {
        let tree_on_m = m.tree.is_some() && m.primitive.is_none();
        let Some(tree) = (if tree_on_m { m.tree } else { o.tree }) else { return Bound::loose(0.0) };
        let leaf = |k: usize| {
            let side = if tree_on_m { m } else { o };
            PosedRef { body: tree.body(k), tree: None, primitive: None, pose: side.pose }
        };
        let pair = |k: usize| if tree_on_m { (leaf(k), *o) } else { (*m, leaf(k)) };
        let mut order: Vec<(Real, usize)> = self
            .leaves
            .iter()
            .map(|&k| {
                let (a, b) = pair(k);
                (dispatch::primitive_lower_bound(&a, &b).unwrap_or(0.0).max(0.0), k)
            })
            .collect();
        order.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut best = Bound { lower: Real::INFINITY, exact: true };
        for (gap, k) in order {
            if gap >= best.lower {
                break;
            }
            let (a, b) = pair(k);
            let (bound, _) = shape_bound(&a, &b, None, slack);
            let bound = Bound { lower: bound.lower.max(gap), ..bound };
            if bound.lower < best.lower {
                best = bound;
            }
        }
        if best.lower.is_finite() {
            best
        } else {
            Bound::loose(0.0)
        }
    }
}

/// The leaves of a tree (nodes without children).
fn leaves_of(tree: &CompoundBody) -> Vec<usize> {
    (0..tree.node_count()).filter(|&k| tree.children(k).is_empty()).collect()
}

/// A side as the shape query sees it.
fn shape<'p>(side: &PosedRef<'p>) -> ShapeRef<'p> {
    match side.primitive {
        Some(p) => ShapeRef::Primitive(p),
        None => ShapeRef::Body(side.body),
    }
}

/// A pair with a primitive and no compound side: `shape_distance` (warm from `warm`), then its
/// separating-plane certificate (two primitives) or the plane bound of the module docs; the new
/// warm start when the solve converged.
fn shape_bound(
    m: &PosedRef<'_>,
    o: &PosedRef<'_>,
    warm: Option<&ShapeWarmStart>,
    slack: Real,
) -> (Bound, Option<ShapeWarmStart>) {
    let Ok(d) = shape_distance(shape(m), &m.pose, shape(o), &o.pose, warm.filter(|w| w.valid)) else {
        return (Bound::loose(0.0), None);
    };
    if !d.status.converged() {
        return (Bound::loose(0.0), None);
    }
    let warm = Some(d.warm_start);
    if d.overlapping {
        // A converged overlap: the active set's common point.
        return (Bound { lower: 0.0, exact: true }, warm);
    }
    let lower = match d.lower_bound {
        Some(lower) => Some(lower),
        None => plane_bound(m, &d.witness_a, o, &d.witness_b, &d.normal),
    };
    match lower {
        Some(lower) => (Bound::against(lower, d.distance, slack), warm),
        None => (Bound::loose(0.0), warm),
    }
}

/// The plane bound `−H_B(−n) − H_A(n)` (module docs) along the unit normal `n` from side `a`
/// towards side `b` (world), with the tangent planes of bodies taken at the witnesses `xa`, `xb`
/// (world); `None` for a nonconvex body or an unbounded support.
pub(super) fn plane_bound(a: &PosedRef<'_>, xa: &Point3, b: &PosedRef<'_>, xb: &Point3, n: &Vector3) -> Option<Real> {
    let n = n.try_normalize(0.0)?;
    let ha = support_upper(a, &n, xa)?;
    let hb = support_upper(b, &-n, xb)?;
    let gap = -ha - hb;
    gap.is_finite().then_some(gap)
}

/// An upper bound of `max e·w` over the posed side (world, `e` a unit vector): a primitive's
/// support function, or a convex body's tangent-plane bound at `witness` (world).
fn support_upper(side: &PosedRef<'_>, e: &Vector3, witness: &Point3) -> Option<Real> {
    let local = side.pose.rotation.inverse_transform_vector(e);
    let offset = e.dot(&side.pose.translation.vector);
    let h = match side.primitive {
        Some(p) => {
            let h = p.support_value(&local);
            h + PRIMITIVE_ROUNDING * h.abs()
        }
        None => tangent_support(side.body, &local, &side.pose.inverse_transform_point(witness))?,
    };
    let total = offset + h;
    total.is_finite().then_some(total + PRIMITIVE_ROUNDING * offset.abs())
}

/// The tangent-plane bound H(e) of the module docs for the convex body `body` in its own frame:
/// direction `e`, tangent point `x` (meters); `None` for a nonconvex body (no bounding box).
pub(super) fn tangent_support(body: &Body, e: &Vector3, x: &Point3) -> Option<Real> {
    if body.report.nonconvex {
        return None;
    }
    let (center, half) = body.bounding_box()?;
    let h_box = |v: &Vector3| v.dot(&center.coords) + v.abs().dot(&half);
    let eval = body.posed(&Isometry3::identity()).eval(&x.coords);
    let g = eval.gradient;
    let gg = g.norm_squared();
    let lam = e.dot(&g) / gg;
    let mut bound = h_box(e);
    if eval.value.is_finite() && gg.is_finite() && gg > 0.0 && lam.is_finite() && lam > 0.0 {
        let c = g.dot(&x.coords) + 1.0 - eval.value;
        let dual = lam * c + h_box(&(e - g * lam));
        if dual.is_finite() {
            bound = bound.min(dual);
        }
    }
    Some(bound + BODY_ROUNDING * 2.0 * half.norm() * e.norm())
}

/// The moving side's reach: an upper bound of `‖x‖` over its points in its own frame (meters),
/// the arm of the rotation in the motion bound. A bounded primitive's bounding radius about its
/// frame's origin; a body's (a compound body's root's, which contains every leaf) smaller of its
/// bounding sphere's and bounding box's farthest distance from the origin. `None` for a halfspace
/// or a body with neither (nonconvex).
pub(super) fn reach(posed: &Posed) -> Option<Real> {
    if let Some(p) = &posed.primitive {
        return p.is_bounded().then(|| p.bounding_radius());
    }
    let sphere = posed.body.bounding_sphere().map(|(c, r)| c.coords.norm() + r);
    let boxed = posed.body.bounding_box().map(|(c, h)| (c.coords.abs() + h).norm());
    match (sphere, boxed) {
        (Some(s), Some(b)) => Some(s.min(b)),
        (s, b) => s.or(b),
    }
}
