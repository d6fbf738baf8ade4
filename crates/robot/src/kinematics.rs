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

use crate::model::{JointValue, RobotModel};
use crate::Result;
use sublevel_core::math::{Isometry3, Real};

impl RobotModel {
    /// The value of every joint (radians or meters; 0 for fixed joints) at configuration `q`, in
    /// the order of [`RobotModel::joints`].
    ///
    /// # Errors
    /// As [`RobotModel::check_configuration`] (field `q`).
    pub fn joint_values(&self, q: &[Real]) -> Result<Vec<Real>> {
        self.check_configuration("q", q)?;
        Ok(self
            .joints()
            .iter()
            .map(|j| match j.value {
                JointValue::Fixed => 0.0,
                JointValue::Variable(k) => q[k],
                JointValue::Mimic { variable, multiplier, offset } => multiplier * q[variable] + offset,
            })
            .collect())
    }

    /// Every link's pose in the world at configuration `q` (one entry per
    /// [`RobotModel::variable_names`], radians or meters) with the root link at `base`; `out` is
    /// resized to [`RobotModel::links`]' length and indexed like it. Joint limits are not checked
    /// ([`RobotModel::check_limits`] does).
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] naming `q` (wrong length) or `q[k]` (not finite).
    pub fn forward_kinematics(&self, q: &[Real], base: &Isometry3, out: &mut Vec<Isometry3>) -> Result<()> {
        let values = self.joint_values(q)?;
        out.clear();
        out.resize(self.links().len(), Isometry3::identity());
        out[self.root()] = *base;
        for (joint, &v) in self.joints().iter().zip(&values) {
            out[joint.child] = out[joint.parent] * joint.transform(v);
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
}
