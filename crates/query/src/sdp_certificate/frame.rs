//! Affine frames of the certificates' variables (module docs of [`super`], "Conditioning"): the
//! plain frames (each body's normalized coordinates) and the recentered, rescaled frames of the
//! second pass.

use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Matrix3, Real, Vector3};
use sublevel_core::poly::Polynomial;

/// A body's certificate variables: normalized coordinates `u = origin + scale · w`.
#[derive(Clone, Copy, Debug)]
pub(super) struct BodyFrame {
    /// Normalized coordinates of the frame's origin (the first pass's witness, or 0).
    pub(super) origin: Vector3,
    /// κ = ρ / s: one unit of w in normalized units (1 in the plain frame).
    pub(super) scale: Real,
}

impl BodyFrame {
    /// The plain frame: w = u.
    pub(super) fn identity() -> Self {
        Self { origin: Vector3::zeros(), scale: 1.0 }
    }
}

/// An affine frame of the certificate's variables w: world point `x = origin + scale · rotation · w`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Frame {
    /// World point of w = 0 (meters).
    pub(super) origin: Vector3,
    /// Orientation of the w axes in the world (the body's rotation, so the frame turns with it).
    pub(super) rotation: Matrix3,
    /// Meters per unit of w.
    pub(super) scale: Real,
}

impl Frame {
    /// The body's own normalized frame (w = u).
    pub(super) fn of_body(body: &Body, pose: &Isometry3) -> Self {
        let rotation = *pose.rotation.to_rotation_matrix().matrix();
        Self { origin: rotation * body.center() + pose.translation.vector, rotation, scale: body.scale() }
    }

    /// The body's polynomial in this frame's variables: `p(A w + b)` with `u = A w + b`.
    pub(super) fn compose(&self, body: &Body, pose: &Isometry3) -> Polynomial {
        let rt: Matrix3 = pose.rotation.to_rotation_matrix().matrix().transpose();
        let a = rt * self.rotation * (self.scale / body.scale());
        let b = (rt * (self.origin - pose.translation.vector) - body.center()) / body.scale();
        body.polynomial().compose_affine(&a, &b)
    }

    /// World point of the frame's variables `w` (three entries).
    pub(super) fn world(&self, w: &[Real]) -> Vector3 {
        self.origin + self.rotation * Vector3::new(w[0], w[1], w[2]) * self.scale
    }
}
