//! Pose gradients of the two queries (paper §IV, eqs. "distance" and "overlap") from the KKT
//! conditions and the envelope theorem.
//!
//! # Convention
//!
//! A pose is perturbed on the left, in the world frame: `pose_i ← exp(ξ^) · pose_i` with the twist
//! `ξ = (v, ω)`, `v` a linear velocity in world coordinates \[m\] and `ω` an angular velocity in world
//! coordinates \[rad\] about the **world origin**. To first order a world point of the body moves
//! by `δx = v + ω × x`. The gradient of a query value f is the 6-vector `(∂f/∂v, ∂f/∂ω)` with
//! `f(exp(ξ^)·pose) = f(pose) + ∂f/∂v·v + ∂f/∂ω·ω + O(‖ξ‖²)`. (A twist about the body's own origin t
//! is `ω' = ω`, `v' = v + ω × t`: the angular part of the gradient about t is `∂f/∂ω − t × ∂f/∂v`.)
//!
//! # Derivation
//!
//! The perturbed constraint is `g(x; ξ) = p(pose⁻¹ exp(−ξ^) x) − 1 = p'(x − v − ω × x) − 1`, so
//! `∂g/∂v = −∇p'(x)`, `∂g/∂ω = −x × ∇p'(x)` (∇p' the world gradient). At a KKT point the value's
//! derivative is the Lagrangian's partial derivative (envelope theorem; valid where the minimizer
//! and multipliers are unique and the active set does not change).
//!
//! *Distance* `D = ‖x* − y*‖`, separated: `L = ‖x − y‖² + λ_a g_a + λ_b g_b` with
//! `λ_a∇p_a'(x*) = 2(y* − x*)`, `λ_b∇p_b'(y*) = 2(x* − y*)`. With the unit normal n = (y* − x*)/D:
//!
//! ```text
//! ∂D/∂ξ_a = (−n, −x* × n),      ∂D/∂ξ_b = (n, y* × n)
//! ```
//!
//! (∂D² = 2D ∂D). Overlapping bodies: D ≡ 0 on a neighbourhood of the pose when the interiors
//! overlap, so the gradient is 0; at exact tangency D is not differentiable (the one-sided
//! derivative is the separated formula moving apart, 0 moving in) and 0 is returned as a
//! subgradient-like value.
//!
//! *Growth* `G = min p₁'(x) s.t. p₂'(x) ≤ 1`: `L = p₁'(x) + μ g₂`, with `∂p₁'/∂ξ₁ = (−∇p₁', −x × ∇p₁')`
//! and `∇p₁'(x*) + μ∇p₂'(x*) = 0`:
//!
//! ```text
//! ∂G/∂ξ₁ = (−∇p₁'(x*), −x* × ∇p₁'(x*)),     ∂G/∂ξ₂ = −∂G/∂ξ₁
//! ```
//!
//! With the constraint inactive (μ = 0, p₁'s minimizer inside body 2) ∇p₁'(x*) = 0 and both are 0.
//! Both gradients sum to zero, as they must (moving both bodies rigidly leaves the value unchanged).

use super::distance::DistanceResult;
use super::growth::GrowthResult;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real, Vector3};

/// A gradient with respect to a pose, as a twist (module docs: left perturbation, world frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseGradient {
    /// ∂f/∂v: derivative along a world-frame translation (value units per meter).
    pub linear: Vector3,
    /// ∂f/∂ω: derivative along a world-frame rotation about the world origin (value units per rad).
    pub angular: Vector3,
}

impl PoseGradient {
    /// The gradient as `[∂f/∂v; ∂f/∂ω]`.
    pub fn to_array(&self) -> [Real; 6] {
        [self.linear.x, self.linear.y, self.linear.z, self.angular.x, self.angular.y, self.angular.z]
    }

    /// Directional derivative along the twist `(v, ω)`.
    pub fn along(&self, v: &Vector3, omega: &Vector3) -> Real {
        self.linear.dot(v) + self.angular.dot(omega)
    }
}

/// Gradients of the distance of `r` with respect to pose A and pose B (module docs).
///
/// Zero for overlapping answers (distance identically 0 around the pose; at exact tangency a
/// subgradient). Only meaningful for converged answers of sos-convex bodies.
pub fn distance_gradient(r: &DistanceResult) -> (PoseGradient, PoseGradient) {
    if r.overlapping || r.distance <= 0.0 {
        return (PoseGradient::default(), PoseGradient::default());
    }
    witness_gradient(&r.witness_a.coords, &r.witness_b.coords)
}

/// Gradients of the distance ‖y − x‖ between separated witnesses x (on A) and y (on B) with
/// respect to pose A and pose B, by the envelope theorem: `(−n, −x × n)` and `(n, y × n)`, n the
/// unit normal from x to y (module docs). Every distance query's gradient, whatever the shapes.
pub fn witness_gradient(x: &Vector3, y: &Vector3) -> (PoseGradient, PoseGradient) {
    let n = (y - x) / (y - x).norm();
    (PoseGradient { linear: -n, angular: -x.cross(&n) }, PoseGradient { linear: n, angular: y.cross(&n) })
}

/// Gradients of d(p₁‖p₂) of `r` with respect to pose 1 and pose 2 (module docs), for the bodies
/// and poses the answer was computed with.
///
/// Zero when the constraint is inactive (multiplier 0). Only meaningful for converged answers of
/// sos-convex bodies.
pub fn growth_gradient(p1: &Body, pose1: &Isometry3, r: &GrowthResult) -> (PoseGradient, PoseGradient) {
    if r.multiplier <= 0.0 {
        return (PoseGradient::default(), PoseGradient::default());
    }
    let x = r.minimizer.coords;
    let g1 = p1.posed(pose1).eval(&x).gradient;
    let d1 = PoseGradient { linear: -g1, angular: -x.cross(&g1) };
    (d1, PoseGradient { linear: -d1.linear, angular: -d1.angular })
}

/// `exp(ξ^) · pose` to first order, with `ξ = (v, ω)` (module docs): the rotation by ω about the
/// world origin followed by the translation v. Differs from the exact exponential at second order
/// only, so central finite differences along one component are unaffected.
pub fn perturb_pose(pose: &Isometry3, v: &Vector3, omega: &Vector3) -> Isometry3 {
    Isometry3::new(*v, *omega) * pose
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{distance, NewtonParams};
    use sublevel_core::body::ellipsoid;
    use sublevel_core::math::{pose_from_parts, Point3};

    #[test]
    fn sphere_distance_gradient_matches_closed_form() {
        // Spheres: D = ‖c_b − c_a‖ − r_a − r_b; ∂D/∂t_a = −n; rotating A about the world origin moves
        // its center by ω × c_a: ∂D/∂ω_a = −c_a × n (= −x × n, x = c_a + r_a n, as n × n = 0).
        let a = ellipsoid([0.0; 3], [0.5; 3]).unwrap();
        let b = ellipsoid([0.0; 3], [0.3; 3]).unwrap();
        let pa = pose_from_parts("a", [1.0, 0.0, 0.0, 0.0], [0.2, 1.0, -0.3]).unwrap();
        let pb = pose_from_parts("b", [1.0, 0.0, 0.0, 0.0], [2.0, 0.5, 0.4]).unwrap();
        let r = distance(&a, &pa, &b, &pb, None, &NewtonParams::default());
        let (ga, gb) = distance_gradient(&r);
        let (ca, cb) = (Point3::new(0.2, 1.0, -0.3), Point3::new(2.0, 0.5, 0.4));
        let n = (cb - ca).normalize();
        assert!((ga.linear + n).norm() < 1e-9 && (gb.linear - n).norm() < 1e-9);
        assert!((ga.angular + ca.coords.cross(&n)).norm() < 1e-9, "{ga:?}");
        assert!((gb.angular - cb.coords.cross(&n)).norm() < 1e-9, "{gb:?}");
    }
}
