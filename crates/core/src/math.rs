//! Scalar type, geometric aliases and the tolerances shared by the whole crate.
//!
//! Every length is in meters, every rotation is a unit quaternion `(w, x, y, z)`, and a pose
//! `(R, t)` maps body-frame points to world points by `x_world = R x_body + t` (paper §IV-C).
//! Keeping the aliases and tolerances in one place (as parry does) means a solver never invents
//! its own epsilon.

/// The floating-point type of every computation in the crate.
pub type Real = f64;
/// A point in ℝ³ (meters).
pub type Point3 = nalgebra::Point3<Real>;
/// A vector in ℝ³ (meters, or meters⁻¹ for gradients).
pub type Vector3 = nalgebra::Vector3<Real>;
/// A 3 × 3 matrix (Hessians, rotation matrices).
pub type Matrix3 = nalgebra::Matrix3<Real>;
/// A rigid motion: unit-quaternion rotation followed by a translation in meters.
pub type Isometry3 = nalgebra::Isometry3<Real>;
/// A unit quaternion `(w, x, y, z)`.
pub type UnitQuaternion = nalgebra::UnitQuaternion<Real>;

/// How far a quaternion's norm may stray from 1 before it is rejected as "not a unit
/// quaternion" rather than silently renormalized (1e-6 absorbs f32 round trips of clients).
pub const UNIT_QUATERNION_TOLERANCE: Real = 1e-6;

/// Largest accepted magnitude of a coordinate or translation, in meters (1000 km).
///
/// Beyond it an f64 keeps fewer than ~10 fractional digits of a millimeter-scale body's
/// normalized coordinates (ulp(1e6) ≈ 1.2e-10 m), and far beyond it (1e154 and up) squared
/// distances overflow or the offset between two bodies is lost to rounding before any solver
/// runs. Poses, point clouds and body centers outside `[-MAX_COORDINATE, MAX_COORDINATE]` are
/// rejected as invalid arguments.
pub const MAX_COORDINATE: Real = 1.0e6;

/// Smallest and largest accepted body scale (the normalization length of a body file), in meters:
/// from a micrometer to [`MAX_COORDINATE`].
pub const SCALE_RANGE: (Real, Real) = (1.0e-6, MAX_COORDINATE);

/// Checks that every coordinate is finite and within [`MAX_COORDINATE`] meters.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `field`, saying which entry is wrong and why.
pub fn check_coordinates(field: &str, values: &[Real]) -> crate::Result<()> {
    for (k, v) in values.iter().enumerate() {
        if !v.is_finite() {
            return Err(crate::Error::invalid(field, format!("entry {k} is {v}, not a finite number")));
        }
        if v.abs() > MAX_COORDINATE {
            return Err(crate::Error::invalid(
                field,
                format!("entry {k} is {v:e} m, beyond the supported range ±{MAX_COORDINATE:e} m"),
            ));
        }
    }
    Ok(())
}

/// Default KKT-residual tolerance of the Newton / active-set query solvers (absolute, in the
/// units of the normalized problem).
pub const NEWTON_KKT_TOLERANCE: Real = 1e-10;

/// Default iteration cap of the Newton / active-set query solvers.
pub const NEWTON_MAX_ITERATIONS: usize = 100;

/// Builds a pose from a unit quaternion `(w, x, y, z)` and a translation `(tx, ty, tz)` in meters.
///
/// # Errors
/// [`crate::Error::InvalidArgument`] naming `field` when any entry is not finite, a translation
/// exceeds [`MAX_COORDINATE`] meters, or the quaternion's norm differs from 1 by more than
/// [`UNIT_QUATERNION_TOLERANCE`].
pub fn pose_from_parts(field: &str, q: [Real; 4], t: [Real; 3]) -> crate::Result<Isometry3> {
    if q.iter().chain(t.iter()).any(|v| !v.is_finite()) {
        return Err(crate::Error::invalid(field, "quaternion and translation must be finite numbers"));
    }
    if let Some(v) = t.iter().find(|v| v.abs() > MAX_COORDINATE) {
        return Err(crate::Error::invalid(
            field,
            format!("translation {v:e} m is beyond the supported range ±{MAX_COORDINATE:e} m"),
        ));
    }
    let norm = q.iter().map(|v| v * v).sum::<Real>().sqrt();
    if (norm - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
        return Err(crate::Error::invalid(
            field,
            format!("quaternion (w,x,y,z) must have unit norm, got norm {norm:.9}"),
        ));
    }
    let quat = nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]);
    let rot = UnitQuaternion::new_normalize(quat);
    Ok(Isometry3::from_parts(nalgebra::Translation3::new(t[0], t[1], t[2]), rot))
}

/// Splits a pose into its unit quaternion `[w, x, y, z]` and translation `[tx, ty, tz]` (meters).
pub fn pose_to_parts(pose: &Isometry3) -> ([Real; 4], [Real; 3]) {
    let q = pose.rotation.quaternion();
    let t = pose.translation.vector;
    ([q.w, q.i, q.j, q.k], [t.x, t.y, t.z])
}

pub use sublevel_kernels::{cpu_has_avx2_fma, Sym3};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_round_trip_and_validation() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let pose = pose_from_parts("pose", [h, 0.0, 0.0, h], [1.0, 2.0, 3.0]).unwrap();
        let (q, t) = pose_to_parts(&pose);
        assert!((q[0] - h).abs() < 1e-15 && (q[3] - h).abs() < 1e-15);
        assert_eq!(t, [1.0, 2.0, 3.0]);
        // 90° about z maps x̂ to ŷ, then translates.
        let p = pose * Point3::new(1.0, 0.0, 0.0);
        assert!((p - Point3::new(1.0, 3.0, 3.0)).norm() < 1e-12);
        let err = pose_from_parts("pose_a", [1.0, 1.0, 0.0, 0.0], [0.0; 3]).unwrap_err();
        assert!(err.to_string().contains("pose_a"));
        assert!(pose_from_parts("p", [f64::NAN, 0.0, 0.0, 0.0], [0.0; 3]).is_err());
        // Beyond ±1e6 m the offset between two bodies is lost to rounding: refused.
        let far = pose_from_parts("pose_b", [1.0, 0.0, 0.0, 0.0], [1e154, 0.0, 0.0]).unwrap_err();
        assert!(far.to_string().contains("pose_b") && far.to_string().contains("range"), "{far}");
        assert!(pose_from_parts("p", [1.0, 0.0, 0.0, 0.0], [-1e6, 1e6, 0.0]).is_ok());
        assert!(check_coordinates("xyz", &[0.0, 1e6 + 1.0]).unwrap_err().to_string().contains("entry 1"));
    }
}
