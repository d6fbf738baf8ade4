//! Distance between posed shapes of which at least one is an exact primitive (box, sphere,
//! cylinder, capsule, halfspace; [`sublevel_core::primitive`]), the other a primitive or a fitted
//! sos-convex body: the paper's distance problem (§IV-A, eq. "distance") for convex sets
//! `{x : gⱼ(x) ≤ 1, j = 1..m}` with several constraints each.
//!
//! The answer comes from the cheapest exact method that applies:
//!
//! ```text
//! halfspace {n·x ≤ d} – bounded shape    closed form: the shape's support point along −n
//! sphere – primitive                     closed form: the primitive's closest boundary point to
//!                                        the sphere's center, less the radius
//! capsule – capsule                      closed form: the axis segments' closest points, less
//!                                        both radii
//! everything else                        the active-set Newton method (active_set), warm-started
//! body – body                            distance() (the sos-convex bodies' solver)
//! ```
//!
//! Each is exact: a converged answer is the global minimizer, to rounding. For two primitives the
//! answer carries its certificate, a *lower bound* from the separating plane through the
//! witnesses (support functions are closed forms): `n·y − max_{x∈A} n·x − max_{y∈B} (−n)·y` with
//! n the unit normal; equal to the distance at the optimum (strong duality), below it anywhere else.
//!
//! Two halfspaces have no finite distance in general and are refused; a halfspace against any
//! bounded shape has one.
//!
//! The growth measure of a primitive (its gauge about its center in place of the body's p₁, the
//! growth distance of Ong and Gilbert) is [`shape_growth`].

mod active_set;
mod closed_form;
mod growth;
#[cfg(test)]
mod tests;

pub use active_set::{ActiveSetState, Fix};
pub use growth::{shape_growth, ShapeGrowth};

use crate::gradient::{witness_gradient, PoseGradient};
use crate::newton::{NewtonParams, SolveStatus};
use crate::penetration::{shape_penetration, shape_support_point};
use crate::{Error, Result};
use active_set::{solve, Side, Tolerances};
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;

/// One side of a shape query: an exact primitive or a fitted sos-convex body, borrowed.
#[derive(Clone, Copy, Debug)]
pub enum ShapeRef<'a> {
    /// An exact primitive (its own frame, meters).
    Primitive(&'a Primitive),
    /// A fitted sos-convex body (paper §III).
    Body(&'a Body),
}

impl ShapeRef<'_> {
    /// A length of the shape's size (meters): the primitive's [`Primitive::scale`], the body's
    /// normalization scale.
    pub fn scale(&self) -> Real {
        match self {
            ShapeRef::Primitive(p) => p.scale(),
            ShapeRef::Body(b) => b.scale(),
        }
    }
}

/// Which method answered a shape query (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShapeMethod {
    /// A closed form (halfspace or sphere against a primitive).
    ClosedForm,
    /// The active-set Newton method.
    ActiveSet,
    /// The sos-convex bodies' solver ([`crate::distance()`]).
    BodySolver,
}

/// State carried between queries of one ordered pair: the active-set method's parameters,
/// working set and multipliers in the shapes' own coordinates (so it follows the poses). The
/// default holds nothing (the next query runs cold).
#[derive(Clone, Copy, Debug, Default)]
pub struct ShapeWarmStart {
    /// The last converged state.
    pub state: ActiveSetState,
    /// Whether `state` holds a converged answer.
    pub valid: bool,
}

/// Answer of a shape distance query; points in world coordinates (meters).
#[derive(Clone, Copy, Debug)]
pub struct ShapeDistance {
    /// ‖x* − y*‖ in meters; 0 when the shapes overlap or touch.
    pub distance: Real,
    /// Closest point of shape A.
    pub witness_a: Point3,
    /// Closest point of shape B (a common point, equal to `witness_a`, when overlapping).
    pub witness_b: Point3,
    /// Unit normal from A towards B; zero when overlapping.
    pub normal: Vector3,
    /// True when the shapes overlap or touch.
    pub overlapping: bool,
    /// How the solve ended; only [`SolveStatus::Converged`] answers are the optimum.
    pub status: SolveStatus,
    /// Newton / active-set iterations (0 for a closed form).
    pub iterations: usize,
    /// ∞-norm of the final KKT residual (meters).
    pub kkt_residual: Real,
    /// A certified lower bound on the distance (meters) from the separating plane between two
    /// separated primitives (module docs); `None` where a side is a body or the shapes overlap.
    pub lower_bound: Option<Real>,
    /// Which method answered.
    pub method: ShapeMethod,
    /// Whether the answer came from the warm start.
    pub warm_started: bool,
    /// State for warm-starting the next query of the same ordered pair.
    pub warm_start: ShapeWarmStart,
    /// For shapes swept by a ball (spheres, capsules): the signed gap between the cores (a
    /// sphere's center, a capsule's axis segment; the other shape itself when it is not swept),
    /// the unit normal from A to B, and the cores' points (world). The depth of an overlap whose
    /// cores are apart (gap > 0; for a sphere against a primitive any gap) is exactly the radii
    /// less the gap.
    pub(crate) core: Option<CoreGap>,
}

/// The gap between the cores of swept shapes ([`ShapeDistance::core`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct CoreGap {
    /// Signed gap (meters; negative only for a sphere's center inside a primitive).
    pub gap: Real,
    /// Unit normal from A's core towards B's: translating B along it raises the gap.
    pub normal: Vector3,
    /// A's core point (world).
    pub point_a: Point3,
    /// B's core point (world).
    pub point_b: Point3,
    /// The radii (A, B) sweeping the cores.
    pub radii: (Real, Real),
}

impl ShapeDistance {
    /// Gradients of the distance with respect to pose A and pose B (twists, the convention of
    /// [`crate::gradient`]): the envelope theorem at the witnesses, `(−n, −x_A × n)` and
    /// `(n, x_B × n)`. Zero for overlapping answers (see [`shape_signed_distance`] for a signal
    /// inside contact).
    pub fn gradient(&self) -> (PoseGradient, PoseGradient) {
        if self.overlapping || self.distance <= 0.0 {
            return (PoseGradient::default(), PoseGradient::default());
        }
        witness_gradient(&self.witness_a.coords, &self.witness_b.coords)
    }
}

/// The signed distance of two shapes: their distance when separated, minus the penetration depth
/// (the shortest translation of B that separates them) when overlapping.
#[derive(Clone, Copy, Debug)]
pub struct SignedDistance {
    /// Meters: positive apart, negative overlapping, 0 touching.
    pub value: Real,
    /// Unit normal from A towards B: translating B along it raises the value at unit rate.
    pub normal: Vector3,
    /// A's witness (separated) or support point along the normal (overlapping), world.
    pub point_a: Point3,
    /// B's witness (separated) or support point along minus the normal (overlapping), world.
    pub point_b: Point3,
    /// Whether the value is converged: the distance solve's status, or the depth descent's.
    pub converged: bool,
    /// The distance answer (separated or not) it came from.
    pub distance: ShapeDistance,
}

impl SignedDistance {
    /// Gradients of the signed distance with respect to pose A and pose B (twists): the same form
    /// apart and in contact, `(−n, −x_A × n)` and `(n, x_B × n)`, so an optimizer's signal is
    /// continuous in direction through contact.
    pub fn gradient(&self) -> (PoseGradient, PoseGradient) {
        let n = self.normal;
        (
            PoseGradient { linear: -n, angular: -self.point_a.coords.cross(&n) },
            PoseGradient { linear: n, angular: self.point_b.coords.cross(&n) },
        )
    }
}

/// The signed distance of shape `a` posed by `pose_a` and shape `b` posed by `pose_b`
/// ([`SignedDistance`]): [`shape_distance`], and when the shapes overlap the penetration depth —
/// exact for a halfspace (the shape's depth below its plane), for a sphere against a primitive
/// and for a capsule whose axis stays outside the other shape (the radii less the cores' gap),
/// and for two boxes (separating axes); a descent over directions on the support functions
/// otherwise ([`crate::penetration::shape_penetration`]), whose `converged` flag says whether
/// its gradient vanished.
///
/// # Errors
/// Those of [`shape_distance`] and of the penetration's support points.
pub fn shape_signed_distance(
    a: ShapeRef<'_>,
    pose_a: &Isometry3,
    b: ShapeRef<'_>,
    pose_b: &Isometry3,
    warm: Option<&ShapeWarmStart>,
) -> Result<SignedDistance> {
    let d = shape_distance(a, pose_a, b, pose_b, warm)?;
    if !d.overlapping {
        return Ok(SignedDistance {
            value: d.distance,
            normal: d.normal,
            point_a: d.witness_a,
            point_b: d.witness_b,
            converged: d.status.converged(),
            distance: d,
        });
    }
    // A halfspace: the other shape's lowest point lies `depth` below the plane.
    let plane = |s: ShapeRef<'_>, pose: &Isometry3| match s {
        ShapeRef::Primitive(Primitive::Halfspace { normal, offset }) => {
            let n = pose.rotation * normal;
            Some((n, offset + n.dot(&pose.translation.vector)))
        }
        _ => None,
    };
    if let Some((n, offset)) = plane(a, pose_a) {
        let y = shape_support_point(b, pose_b, &-n)?;
        let height = n.dot(&y.coords) - offset;
        let x = y - n * height;
        return Ok(SignedDistance { value: height, normal: n, point_a: x, point_b: y, converged: true, distance: d });
    }
    if let Some((n, offset)) = plane(b, pose_b) {
        let x = shape_support_point(a, pose_a, &-n)?;
        let height = n.dot(&x.coords) - offset;
        let y = x - n * height;
        return Ok(SignedDistance { value: height, normal: -n, point_a: x, point_b: y, converged: true, distance: d });
    }
    // Swept shapes whose cores are apart: exact.
    if let Some(c) = d.core {
        return Ok(SignedDistance {
            value: c.gap - c.radii.0 - c.radii.1,
            normal: c.normal,
            point_a: c.point_a + c.normal * c.radii.0,
            point_b: c.point_b - c.normal * c.radii.1,
            converged: d.status.converged(),
            distance: d,
        });
    }
    let p = shape_penetration(a, pose_a, b, pose_b)?;
    Ok(SignedDistance {
        value: -p.depth.max(0.0),
        normal: p.normal,
        point_a: p.support_a,
        point_b: p.support_b,
        converged: p.converged,
        distance: d,
    })
}

/// The separating-plane lower bound of the distance between two posed shapes along the unit
/// world direction `normal` (from A towards B): `min_{y∈B} n·y − max_{x∈A} n·x`, from the shapes'
/// support functions (closed forms for primitives, the support-point solve for a body). A lower
/// bound of the distance for every `normal` (negative when the plane does not separate them),
/// equal to it along the optimum's normal (strong duality): the certificate of an answer with a
/// body, whose [`ShapeDistance::lower_bound`] is `None` because a body's support point costs
/// about as much as the distance itself.
///
/// # Errors
/// [`Error::Numerical`] for a halfspace not facing `normal` (unbounded support) or a body whose
/// support point fails (nonconvex).
pub fn separating_plane_bound(
    a: ShapeRef<'_>,
    pose_a: &Isometry3,
    b: ShapeRef<'_>,
    pose_b: &Isometry3,
    normal: &Vector3,
) -> Result<Real> {
    let top_a = normal.dot(&shape_support_point(a, pose_a, normal)?.coords);
    let bottom_b = normal.dot(&shape_support_point(b, pose_b, &-normal)?.coords);
    Ok(bottom_b - top_a)
}

/// Distance between shape `a` posed by `pose_a` and shape `b` posed by `pose_b` (module docs).
///
/// `warm` is the `warm_start` of a previous answer for the same ordered pair. Never panics; the
/// answer says whether it converged.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `b` for two halfspaces (no finite distance);
/// [`Error::Numerical`] where a body's support point fails (a nonconvex body against a
/// halfspace).
pub fn shape_distance(
    a: ShapeRef<'_>,
    pose_a: &Isometry3,
    b: ShapeRef<'_>,
    pose_b: &Isometry3,
    warm: Option<&ShapeWarmStart>,
) -> Result<ShapeDistance> {
    use ShapeRef::{Body as B, Primitive as P};
    match (a, b) {
        (P(Primitive::Halfspace { .. }), P(Primitive::Halfspace { .. })) => {
            Err(Error::invalid("b", "two halfspaces have no finite distance; make one of them a box"))
        }
        (P(h @ Primitive::Halfspace { .. }), other) => closed_form::halfspace(h, pose_a, other, pose_b, false),
        (other, P(h @ Primitive::Halfspace { .. })) => closed_form::halfspace(h, pose_b, other, pose_a, true),
        (P(s @ Primitive::Sphere { .. }), P(other)) => Ok(closed_form::sphere(s, pose_a, other, pose_b, false)),
        (P(other), P(s @ Primitive::Sphere { .. })) => Ok(closed_form::sphere(s, pose_b, other, pose_a, true)),
        (P(ca @ Primitive::Capsule { .. }), P(cb @ Primitive::Capsule { .. })) => {
            Ok(closed_form::capsules(ca, pose_a, cb, pose_b))
        }
        (B(ba), B(bb)) => Ok(body_pair(ba, pose_a, bb, pose_b)),
        _ => Ok(active_set_distance(a, pose_a, b, pose_b, warm)),
    }
}

/// Two bodies: [`crate::distance()`], cold, in this module's answer type.
fn body_pair(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> ShapeDistance {
    let r = crate::distance(a, pose_a, b, pose_b, None, &NewtonParams::DEFAULT);
    ShapeDistance {
        distance: r.distance,
        witness_a: r.witness_a,
        witness_b: r.witness_b,
        normal: r.normal,
        overlapping: r.overlapping,
        status: r.status,
        iterations: r.iterations,
        kkt_residual: r.kkt_residual,
        lower_bound: None,
        method: ShapeMethod::BodySolver,
        warm_started: false,
        warm_start: ShapeWarmStart::default(),
        core: None,
    }
}

/// The active-set method's tolerances for a pair whose smaller side has size `length` (meters):
/// steps below 10⁻¹³ of it; stationarity and multiplier signs within 10⁻¹⁰ of the gap plus
/// 10⁻¹⁴ of the size; smooth constraints within 10⁻¹² of the size.
fn tolerances(length: Real) -> Tolerances {
    Tolerances {
        step: 1e-13 * length,
        relative: 1e-10,
        absolute: 1e-14 * length,
        feasibility: 1e-12 * length,
        max_iterations: 60,
    }
}

/// The cold start: from A's origin, B's nearest core point (or body boundary point) towards it,
/// then A's towards that, then B's again (two rounds of alternating projection; exact for the
/// primitives' cores), with the working sets those points lie on.
fn cold_state(a: &Side, b: &Side) -> ActiveSetState {
    let from = match a.core {
        active_set::Core::Body(body) => {
            a.origin + a.map * ((body.interior_point().coords - body.center()) / body.scale())
        }
        _ => a.origin,
    };
    alternating_state(a, b, &from)
}

/// The start of alternating projection from the working-frame point `from`.
fn alternating_state(a: &Side, b: &Side, from: &Vector3) -> ActiveSetState {
    let mut state = ActiveSetState::default();
    let (na, nb) = (a.dim, b.dim);
    let (ub, _, _) = b.start_towards(from);
    let (ua, fa, sa) = a.start_towards(&b.point(&ub[..nb]));
    let (ub, fb, sb) = b.start_towards(&a.point(&ua[..na]));
    state.u[..na].copy_from_slice(&ua[..na]);
    state.fix[..na].copy_from_slice(&fa[..na]);
    state.u[na..na + nb].copy_from_slice(&ub[..nb]);
    state.fix[na..na + nb].copy_from_slice(&fb[..nb]);
    state.smooth = [sa, sb];
    state
}

/// The active-set answer (module docs), solved in A's frame.
fn active_set_distance(
    a: ShapeRef<'_>,
    pose_a: &Isometry3,
    b: ShapeRef<'_>,
    pose_b: &Isometry3,
    warm: Option<&ShapeWarmStart>,
) -> ShapeDistance {
    let rel = pose_a.inv_mul(pose_b);
    // Both sides exist: halfspaces were answered in closed form.
    let (Some(sa), Some(sb)) = (Side::new(a, &Isometry3::identity()), Side::new(b, &rel)) else {
        unreachable!("halfspaces take the closed form")
    };
    let tol = tolerances(sa.scale.min(sb.scale));
    let mut iterations = 0;
    let mut warm_started = false;
    let mut outcome = None;
    // Between boxes, capsules and spheres the cold start (two rounds of alternating projection onto
    // the cores, exact closed forms) lands on the answer's working set as often as the last answer
    // does, and costs no more: warm starts serve pairs with a curved constraint (a cylinder's side,
    // a body), whose boundary point and multiplier they keep (about a third fewer iterations along
    // small motions).
    let curved = [a, b].iter().any(|s| match s {
        ShapeRef::Body(_) => true,
        ShapeRef::Primitive(p) => matches!(p, Primitive::Cylinder { .. }),
    });
    if let Some(w) = warm.filter(|w| w.valid && curved) {
        let start = w.state;
        let out = solve(&sa, &sb, start, &tol);
        iterations += out.iterations;
        if out.converged {
            warm_started = true;
            outcome = Some(out);
        }
    }
    let out = match outcome {
        Some(o) => o,
        None => {
            let out = solve(&sa, &sb, cold_state(&sa, &sb), &tol);
            iterations += out.iterations;
            out
        }
    };
    let x = sa.point(&out.state.u[..sa.dim]);
    let y = sb.point(&out.state.u[sa.dim..sa.dim + sb.dim]);
    let gap = y - x;
    let core = gap.norm();
    let distance = core - sa.radius - sb.radius;
    // Overlapping cores converge to a gap at rounding level, not exactly 0: a distance within the
    // KKT tolerance counts as touching (the conservative side).
    let overlapping = distance <= 1e-12 * sa.scale.min(sb.scale);
    let (normal, wa, wb) = if overlapping {
        // A common point: on the segment between the cores' points, within both radii.
        let n = if core > 0.0 { gap / core } else { Vector3::zeros() };
        let common = x + n * sa.radius.min(core);
        (Vector3::zeros(), common, common)
    } else {
        let n = gap / core;
        (n, x + n * sa.radius, y - n * sb.radius)
    };
    let lower_bound = match (a, b, overlapping) {
        (ShapeRef::Primitive(pa), ShapeRef::Primitive(pb), false) => {
            let h_a = pa.support_value(&normal);
            let h_b = pb.support_value(&(rel.rotation.inverse() * -normal));
            Some(normal.dot(&rel.translation.vector) - h_b - h_a)
        }
        _ => None,
    };
    ShapeDistance {
        distance: distance.max(0.0),
        witness_a: pose_a * Point3::from(wa),
        witness_b: pose_a * Point3::from(wb),
        normal: pose_a.rotation * normal,
        overlapping,
        status: if out.converged { SolveStatus::Converged } else { SolveStatus::MaxIterations },
        iterations,
        kkt_residual: out.kkt_residual,
        lower_bound,
        method: ShapeMethod::ActiveSet,
        warm_started,
        warm_start: ShapeWarmStart { state: out.state, valid: out.converged },
        // Cores that meet converge to a gap at rounding level: a gap below 10⁻⁹ of the size
        // is taken as meeting (the depth's error then stays below it).
        core: (sa.radius + sb.radius > 0.0 && out.converged && core > 1e-9 * sa.scale.min(sb.scale)).then(|| CoreGap {
            gap: core,
            normal: pose_a.rotation * (gap / core),
            point_a: pose_a * Point3::from(x),
            point_b: pose_a * Point3::from(y),
            radii: (sa.radius, sb.radius),
        }),
    }
}
