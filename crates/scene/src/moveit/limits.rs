//! A MoveIt `joint_limits.yaml` (the `moveit_setup_assistant`'s file, ROS 1 or ROS 2 layout):
//! per joint, `has_velocity_limits` / `max_velocity`, `has_acceleration_limits` /
//! `max_acceleration`, `has_jerk_limits` / `max_jerk`, under `joint_limits` (ROS 1) or
//! `robot_description_planning.joint_limits` (ROS 2). A limit counts only where its `has_…` flag
//! is true, as MoveIt's `joint_limits_interface` reads it; `default_velocity_scaling_factor` and
//! `default_acceleration_scaling_factor` are read too. Position limits (`max_position`,
//! `min_position`) are the URDF's and are not read here.

use crate::{Error, Result};
use serde::Deserialize;
use std::collections::BTreeMap;
use sublevel_core::math::Real;

/// One joint's limits from a `joint_limits.yaml`: `None` where the file sets no limit (its
/// `has_…` flag false or absent). Units: radians or meters per second, per second squared, per
/// second cubed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointLimitEntry {
    /// `max_velocity` where `has_velocity_limits` is true.
    pub max_velocity: Option<Real>,
    /// `max_acceleration` where `has_acceleration_limits` is true.
    pub max_acceleration: Option<Real>,
    /// `max_jerk` where `has_jerk_limits` is true.
    pub max_jerk: Option<Real>,
}

/// A `joint_limits.yaml` as read (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointLimitsYaml {
    /// The joints by name, in name order.
    pub joints: BTreeMap<String, JointLimitEntry>,
    /// `default_velocity_scaling_factor`, in (0, 1], where given.
    pub default_velocity_scaling_factor: Option<Real>,
    /// `default_acceleration_scaling_factor`, in (0, 1], where given.
    pub default_acceleration_scaling_factor: Option<Real>,
}

/// The velocity and acceleration limits of a [`JointLimitsYaml`] for one robot
/// ([`JointLimitsYaml::for_joints`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JointLimitMaps {
    /// Velocity limits by joint name, of the robot's joints only.
    pub velocity: BTreeMap<String, Real>,
    /// Acceleration limits by joint name.
    pub acceleration: BTreeMap<String, Real>,
    /// The file's joints that are not among the robot's, in name order.
    pub skipped: Vec<String>,
}

/// The ROS 2 layout: the limits under `robot_description_planning` (other keys ignored).
#[derive(Deserialize, Default)]
struct RawRos2 {
    #[serde(default)]
    robot_description_planning: Option<RawLimits>,
}

#[derive(Deserialize, Default)]
struct RawLimits {
    #[serde(default)]
    joint_limits: BTreeMap<String, RawJoint>,
    #[serde(default)]
    default_velocity_scaling_factor: Option<Real>,
    #[serde(default)]
    default_acceleration_scaling_factor: Option<Real>,
}

#[derive(Deserialize, Default)]
struct RawJoint {
    #[serde(default)]
    has_velocity_limits: bool,
    #[serde(default)]
    max_velocity: Option<Real>,
    #[serde(default)]
    has_acceleration_limits: bool,
    #[serde(default)]
    max_acceleration: Option<Real>,
    #[serde(default)]
    has_jerk_limits: bool,
    #[serde(default)]
    max_jerk: Option<Real>,
}

impl JointLimitsYaml {
    /// The file's limits of the joints in `names` (a robot's moving joints), and the names of
    /// the file's other joints.
    pub fn for_joints(&self, names: &[&str]) -> JointLimitMaps {
        let mut out = JointLimitMaps::default();
        for (name, entry) in &self.joints {
            if !names.contains(&name.as_str()) {
                out.skipped.push(name.clone());
                continue;
            }
            if let Some(v) = entry.max_velocity {
                out.velocity.insert(name.clone(), v);
            }
            if let Some(a) = entry.max_acceleration {
                out.acceleration.insert(name.clone(), a);
            }
        }
        out
    }

    /// Reads a `joint_limits.yaml` text.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `joint_limits` for text that is not such a YAML mapping
    /// (with the parser's line and column), or the field
    /// (`joint_limits.panda_joint1.max_velocity`) of a limit whose flag is true and whose value
    /// is missing, not finite or ≤ 0, or a scaling factor outside (0, 1].
    pub fn from_yaml(bytes: &[u8]) -> Result<Self> {
        // The ROS 2 layout, else the ROS 1 one (the same keys at the top).
        let ros2: RawRos2 = super::parse_yaml("joint_limits", bytes)?;
        let limits = match ros2.robot_description_planning {
            Some(limits) => limits,
            None => super::parse_yaml("joint_limits", bytes)?,
        };
        let mut out = JointLimitsYaml::default();
        for (name, v) in [
            ("default_velocity_scaling_factor", limits.default_velocity_scaling_factor),
            ("default_acceleration_scaling_factor", limits.default_acceleration_scaling_factor),
        ] {
            if let Some(v) = v {
                if !(v > 0.0 && v <= 1.0) {
                    return Err(Error::invalid(name, format!("must be in (0, 1], got {v}")));
                }
            }
        }
        out.default_velocity_scaling_factor = limits.default_velocity_scaling_factor;
        out.default_acceleration_scaling_factor = limits.default_acceleration_scaling_factor;
        for (joint, raw) in limits.joint_limits {
            let clipped = sublevel_core::error::clip(&joint);
            let take = |has: bool, value: Option<Real>, key: &str| -> Result<Option<Real>> {
                if !has {
                    return Ok(None);
                }
                match value {
                    Some(v) if v.is_finite() && v > 0.0 => Ok(Some(v)),
                    Some(v) => Err(Error::invalid(
                        format!("joint_limits.{clipped}.{key}"),
                        format!("must be finite and > 0 where its limit is on, got {v}"),
                    )),
                    None => Err(Error::invalid(
                        format!("joint_limits.{clipped}.{key}"),
                        "missing where its has_… flag is true",
                    )),
                }
            };
            let entry = JointLimitEntry {
                max_velocity: take(raw.has_velocity_limits, raw.max_velocity, "max_velocity")?,
                max_acceleration: take(raw.has_acceleration_limits, raw.max_acceleration, "max_acceleration")?,
                max_jerk: take(raw.has_jerk_limits, raw.max_jerk, "max_jerk")?,
            };
            out.joints.insert(joint, entry);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ros2_and_ros1_layouts_read_the_same_and_flags_turn_limits_off() {
        let ros2 = b"robot_description_planning:\n  joint_limits:\n    j1:\n      has_velocity_limits: true\n      max_velocity: 2.175\n      has_acceleration_limits: true\n      max_acceleration: 3.75\n    finger:\n      has_velocity_limits: true\n      max_velocity: 0.1\n      has_acceleration_limits: false\n      max_acceleration: 0.0\n";
        let ros1 = b"default_velocity_scaling_factor: 0.1\njoint_limits:\n  j1:\n    has_velocity_limits: true\n    max_velocity: 2.175\n    has_acceleration_limits: true\n    max_acceleration: 3.75\n  finger:\n    has_velocity_limits: true\n    max_velocity: 0.1\n";
        let a = JointLimitsYaml::from_yaml(ros2).unwrap();
        let b = JointLimitsYaml::from_yaml(ros1).unwrap();
        assert_eq!(a.joints, b.joints);
        assert_eq!(
            a.joints["j1"],
            JointLimitEntry { max_velocity: Some(2.175), max_acceleration: Some(3.75), max_jerk: None }
        );
        assert_eq!(a.joints["finger"].max_acceleration, None);
        assert_eq!(b.default_velocity_scaling_factor, Some(0.1));
    }

    #[test]
    fn a_limit_that_is_on_and_not_positive_names_its_field() {
        let bad = b"joint_limits:\n  j1:\n    has_acceleration_limits: true\n    max_acceleration: -1\n";
        match JointLimitsYaml::from_yaml(bad) {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "joint_limits.j1.max_acceleration"),
            other => panic!("{other:?}"),
        }
        match JointLimitsYaml::from_yaml(b"joint_limits: [1, 2]") {
            Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "joint_limits"),
            other => panic!("{other:?}"),
        }
    }
}
