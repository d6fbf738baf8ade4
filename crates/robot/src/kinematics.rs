//! Forward kinematics: the pose of every link in the world for a joint configuration.
//!
//! ```text
//! T_world(root)  = base
//! T_world(child) = T_world(parent) · origin_j · motion_j(value_j)      for each joint j, parents first
//! value_j        = q[k]                        (a configuration entry)
//!                = multiplier · q[k] + offset  (a mimic joint)
//! ```
//!
//! One pass over the joints in tree order ([`crate::RobotModel::joints`]); each step is one
//! isometry product. Checked against pinocchio 4.1 (`framesForwardKinematics`, the BODY frames)
//! on the Panda and on a test robot with every joint kind to 1e-12 m and 1e-12 in every rotation
//! entry (`tests/fk.rs`).

use crate::model::{JointKind, JointValue, RobotModel};
use crate::Result;
use nalgebra::Matrix6xX;
use std::ops::AddAssign;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};

impl RobotModel {
    /// The value of every joint (radians or meters; 0 for fixed joints) at configuration `q`, in
    /// the order of [`RobotModel::joints`].
    ///
    /// # Errors
    /// As [`RobotModel::check_configuration`] (field `q`).
    pub fn joint_values(&self, q: &[Real]) -> Result<Vec<Real>> {
        self.check_configuration("q", q)?;
        Ok(self.joints().iter().map(|j| joint_value(j.value, q)).collect())
    }

    /// Every link's pose in the world at configuration `q` (one entry per
    /// [`RobotModel::variable_names`], radians or meters) with the root link at `base`; `out` is
    /// resized to [`RobotModel::links`]' length and indexed like it. Joint limits are not checked
    /// ([`RobotModel::check_limits`] does).
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] naming `q` (wrong length) or `q[k]` (not finite).
    pub fn forward_kinematics(&self, q: &[Real], base: &Isometry3, out: &mut Vec<Isometry3>) -> Result<()> {
        self.check_configuration("q", q)?;
        out.clear();
        out.resize(self.links().len(), Isometry3::identity());
        out[self.root()] = *base;
        for joint in self.joints() {
            // No vector of values: this is every check's first step.
            out[joint.child] = out[joint.parent] * joint.transform(joint_value(joint.value, q));
        }
        Ok(())
    }

    /// [`RobotModel::forward_kinematics`] into a new vector.
    ///
    /// # Errors
    /// As [`RobotModel::forward_kinematics`].
    pub fn link_poses(&self, q: &[Real], base: &Isometry3) -> Result<Vec<Isometry3>> {
        let mut out = Vec::new();
        self.forward_kinematics(q, base, &mut out)?;
        Ok(out)
    }

    /// The point Jacobian of a point fixed on link `link`: `out[k]` = ∂x/∂q_k, the velocity of the
    /// point `x` (world frame, meters) per unit of configuration entry k, at the configuration
    /// whose link poses are `link_poses` ([`RobotModel::forward_kinematics`]). For each joint on
    /// the chain from the root to the link, with world axis `a` through the joint frame's origin
    /// `p` (Siciliano et al., *Robotics*, §3.1):
    ///
    /// ```text
    /// revolute, continuous   ∂x/∂v = a × (x − p)
    /// prismatic              ∂x/∂v = a
    /// ```
    ///
    /// and `v = q_k` (a configuration entry) or `v = m · q_k + c` (a mimic joint: m times that).
    /// `out` is resized to [`RobotModel::dof`] entries.
    pub fn point_jacobian(&self, link_poses: &[Isometry3], link: usize, x: &Point3, out: &mut Vec<Vector3>) {
        out.clear();
        out.resize(self.dof(), Vector3::zeros());
        self.for_each_chain_joint(link_poses, link, |k, m, kind, a, p| {
            out[k] += m * linear_column(kind, a, p, x);
        });
    }

    /// The frame (geometric) Jacobian of link `link` at the point `x` fixed on it: a 6 × dof
    /// matrix whose column k is the twist per unit of configuration entry k, linear rows first —
    /// rows 0..3 are ∂x/∂q_k (the point's velocity, world frame, meters per radian or per meter,
    /// exactly [`RobotModel::point_jacobian`]) and rows 3..6 are the link's angular velocity
    /// (world frame, radians per radian, 0 per meter). With each chain joint's world axis `a`
    /// through its frame's origin `p` (Siciliano et al., *Robotics*, §3.1.3, eq. 3.30):
    ///
    /// ```text
    ///                        linear         angular
    /// revolute, continuous   a × (x − p)    a
    /// prismatic              a              0
    /// ```
    ///
    /// and a mimic joint `v = m · q_k + c` adds m times its column to column k. `link_poses` are
    /// [`RobotModel::forward_kinematics`]' at the configuration; `out` is resized to 6 × dof.
    /// Checked against central differences of forward kinematics on the Panda and on a test robot
    /// with every joint kind to 1e-6 (`tests/ik.rs`).
    pub fn frame_jacobian(&self, link_poses: &[Isometry3], link: usize, x: &Point3, out: &mut Matrix6xX<Real>) {
        if out.ncols() != self.dof() {
            *out = Matrix6xX::zeros(self.dof());
        } else {
            out.fill(0.0);
        }
        self.for_each_chain_joint(link_poses, link, |k, m, kind, a, p| {
            let linear = m * linear_column(kind, a, p, x);
            let angular = match kind {
                JointKind::Prismatic => Vector3::zeros(),
                _ => m * a,
            };
            let mut column = out.column_mut(k);
            column.fixed_rows_mut::<3>(0).add_assign(&linear);
            column.fixed_rows_mut::<3>(3).add_assign(&angular);
        });
    }

    /// Calls `f(k, m, kind, a, p)` for each moving joint on the chain from `link` to the root:
    /// configuration entry `k`, multiplier `m` (1, or a mimic's), the joint's kind, its world axis
    /// `a` and its frame's world origin `p`.
    fn for_each_chain_joint(
        &self,
        link_poses: &[Isometry3],
        link: usize,
        mut f: impl FnMut(usize, Real, JointKind, &Vector3, &Vector3),
    ) {
        let mut at = link;
        while let Some(j) = self.links().get(at).and_then(|l| l.parent_joint) {
            let joint = &self.joints()[j];
            at = joint.parent;
            let (k, m) = match joint.value {
                JointValue::Fixed => continue,
                JointValue::Variable(k) => (k, 1.0),
                JointValue::Mimic { variable, multiplier, .. } => (variable, multiplier),
            };
            if joint.kind == JointKind::Fixed {
                continue;
            }
            let frame = link_poses[joint.parent] * joint.origin;
            f(k, m, joint.kind, &(frame.rotation * joint.axis), &frame.translation.vector);
        }
    }
}

/// The linear velocity of point `x` per unit of a joint's value: `a × (x − p)` (revolute,
/// continuous) or `a` (prismatic).
fn linear_column(kind: JointKind, a: &Vector3, p: &Vector3, x: &Point3) -> Vector3 {
    match kind {
        JointKind::Prismatic => *a,
        _ => a.cross(&(x.coords - p)),
    }
}

/// A joint's value at configuration `q` (already checked): 0 fixed, `q[k]`, or a mimic's
/// `multiplier · q[k] + offset`.
fn joint_value(value: JointValue, q: &[Real]) -> Real {
    match value {
        JointValue::Fixed => 0.0,
        JointValue::Variable(k) => q[k],
        JointValue::Mimic { variable, multiplier, offset } => multiplier * q[variable] + offset,
    }
}
