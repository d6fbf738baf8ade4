//! Starts and goals given by joint names, as MoveIt's messages give them: a start state of named
//! joint positions, goal joint constraints with tolerances. Shared by the service's `Plan` and
//! `sublevel robot plan`.

use crate::plan::{Goal, JointRegion};
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};
use sublevel_robot::RobotModel;

/// One joint constraint: `(joint name, position, tolerance below, tolerance above)` (radians or
/// meters; tolerances ≥ 0).
pub type JointConstraint = (String, Real, Real, Real);

/// The start configuration of a MoveIt start state: the robot's moving joints from `given`
/// (joints of the URDF the robot does not move, such as fixed or mimic fingers, ignored), the
/// others from `defaults` (a scene's joint positions), else 0. A name that is not a joint of the
/// URDF is refused, as MoveIt refuses a joint state naming a variable its model lacks: a
/// misspelled start would otherwise be planned from the scene's positions, a start the client
/// never gave.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field.joint_state.name[k]` for a name that is not a joint
/// of the robot or is repeated, `field` or `field[k]` for a value that is not finite or is
/// outside the joint's limits.
pub fn start_from_joints(
    model: &RobotModel,
    field: &str,
    given: &[(String, Real)],
    defaults: &[(String, Real)],
) -> Result<Vec<Real>> {
    for (k, (name, _)) in given.iter().enumerate() {
        let at = || format!("{field}.joint_state.name[{k}]");
        if !model.joints().iter().any(|j| j.name == *name) {
            return Err(Error::invalid(
                at(),
                format!(
                    "`{}` is not a joint of the robot; its moving joints: {:?}",
                    sublevel_core::error::clip(name),
                    model.variable_names()
                ),
            ));
        }
        if given[..k].iter().any(|(m, _)| m == name) {
            return Err(Error::invalid(at(), format!("`{}` is repeated", sublevel_core::error::clip(name))));
        }
        if !given[k].1.is_finite() {
            return Err(Error::invalid(format!("{field}.joint_state.position[{k}]"), "must be finite"));
        }
    }
    let q: Vec<Real> = model
        .variable_names()
        .iter()
        .map(|n| {
            given
                .iter()
                .find(|(m, _)| m == n)
                .or_else(|| defaults.iter().find(|(m, _)| m == n))
                .map_or(0.0, |(_, v)| *v)
        })
        .collect();
    model.check_limits(field, &q)?;
    Ok(q)
}

/// The goal of joint constraints, the joints not named at `start`'s values: one goal
/// configuration when every tolerance is 0, else a [`JointRegion`].
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field[k].joint_name` (not a moving joint of the robot, or
/// repeated), `field[k].position` (not finite), `field[k].tolerance_below` / `_above` (negative or
/// not finite), or `field` (the center outside the limits).
pub fn joint_goal(model: &RobotModel, field: &str, constraints: &[JointConstraint], start: &[Real]) -> Result<Goal> {
    let names = model.variable_names();
    let mut center = start.to_vec();
    let (mut below, mut above) = (vec![0.0; names.len()], vec![0.0; names.len()]);
    let mut seen = vec![false; names.len()];
    for (k, (name, position, b, a)) in constraints.iter().enumerate() {
        let j = names.iter().position(|n| n == name).ok_or_else(|| {
            Error::invalid(
                format!("{field}[{k}].joint_name"),
                format!(
                    "`{}` is not a moving joint of the robot; its joints: {names:?}",
                    sublevel_core::error::clip(name)
                ),
            )
        })?;
        if std::mem::replace(&mut seen[j], true) {
            return Err(Error::invalid(format!("{field}[{k}].joint_name"), format!("`{name}` is repeated")));
        }
        if !position.is_finite() {
            return Err(Error::invalid(format!("{field}[{k}].position"), "must be finite"));
        }
        for (what, v) in [("tolerance_below", b), ("tolerance_above", a)] {
            if !(v.is_finite() && *v >= 0.0) {
                return Err(Error::invalid(format!("{field}[{k}].{what}"), format!("must be finite and ≥ 0, got {v}")));
            }
        }
        center[j] = *position;
        below[j] = *b;
        above[j] = *a;
    }
    model.check_limits(field, &center)?;
    if below.iter().chain(&above).all(|v| *v == 0.0) {
        return Ok(Goal::Configurations(vec![center]));
    }
    Ok(Goal::Region(JointRegion { center, below, above }))
}
