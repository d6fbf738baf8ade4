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

/// MoveIt's default `start_state_max_bounds_error` (its `FixStartStateBounds` planning request
/// adapter): a start value this far or less outside its joint's limits (radians or meters) is
/// moved onto the limit and planned from there; one farther out is refused.
pub const START_STATE_MAX_BOUNDS_ERROR: Real = 0.05;

/// Moves a start configuration `q` into the joint limits, as MoveIt's `FixStartStateBounds`
/// adapter does: each value at most `max_error` (radians or meters) outside its joint's limits is
/// moved onto the nearer limit. Also a line per value moved past the rounding margin
/// ([`sublevel_robot::model::LIMIT_ROUNDING`], moved silently), naming `field[k]`, the joint, the
/// value and where it went, for the answer.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field[k]` for a value farther than `max_error` outside its
/// joint's limits, or not finite; `field` for a configuration of the wrong length.
pub fn fix_start_bounds(model: &RobotModel, field: &str, q: &mut [Real], max_error: Real) -> Result<Vec<String>> {
    model.check_configuration(field, q)?;
    let mut moved = Vec::new();
    for (k, v) in q.iter_mut().enumerate() {
        let joint = model.variable_joint(k);
        let Some((lo, hi)) = joint.limits else { continue };
        let inside = v.clamp(lo, hi);
        let by = (*v - inside).abs();
        if by > max_error {
            return Err(Error::invalid(
                format!("{field}[{k}]"),
                format!(
                    "joint `{}` at {v} is outside its limits [{lo}, {hi}] by {by:.3e}, more than the \
                     start_state_max_bounds_error of {max_error} that is moved into them",
                    joint.name
                ),
            ));
        }
        if !joint.admits(*v) {
            moved.push(format!(
                "{field}[{k}]: joint `{}` at {v} is outside its limits [{lo}, {hi}] by {by:.3e}; planned from {inside} \
                 (start_state_max_bounds_error {max_error})",
                joint.name
            ));
        }
        *v = inside;
    }
    Ok(moved)
}

/// The start configuration of a MoveIt start state: the robot's moving joints from `given`
/// (joints of the URDF the robot does not move, such as fixed or mimic fingers, ignored), the
/// others from `defaults` (a scene's joint positions), else 0; values up to `max_error` outside
/// the limits moved into them ([`fix_start_bounds`]). A name that is not a joint of the URDF is
/// refused, as MoveIt refuses a joint state naming a variable its model lacks: a misspelled start
/// would otherwise be planned from the scene's positions, a start the client never gave. Also the
/// lines of [`fix_start_bounds`].
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field.joint_state.name[k]` for a name that is not a joint
/// of the robot or is repeated, `field.joint_state.position[k]` for a value that is not finite,
/// `field[k]` for one farther than `max_error` outside the joint's limits.
pub fn start_from_joints(
    model: &RobotModel,
    field: &str,
    given: &[(String, Real)],
    defaults: &[(String, Real)],
    max_error: Real,
) -> Result<(Vec<Real>, Vec<String>)> {
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
    let mut q: Vec<Real> = model
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
    let moved = fix_start_bounds(model, field, &mut q, max_error)?;
    Ok((q, moved))
}

/// The goal of joint constraints, the joints not named at `start`'s values: one goal
/// configuration when every tolerance is 0, else a [`JointRegion`]. Constraints are taken as
/// MoveIt's `JointConstraint` takes them: one whose interval `[position − tolerance_below,
/// position + tolerance_above]` meets its joint's limits (up to
/// [`sublevel_robot::model::LIMIT_ROUNDING`]) is cut to them, and a position outside them moved to
/// the nearest point of the cut interval; one whose interval misses the limits by at most
/// `max_error` (radians or meters; MoveIt moves it by any distance) is taken at the nearer limit.
/// Each move of a position past the rounding margin is a line naming `field[k].position` in the
/// second return value.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field[k].joint_name` (not a moving joint of the robot, or
/// repeated), `field[k].position` (not finite, or an interval that misses the limits by more than
/// `max_error`: a goal that far out is more likely a wrong joint or unit than a rounding),
/// `field[k].tolerance_below` / `_above` (negative or not finite), or `field` (a joint not
/// constrained whose `start` value is outside the limits).
pub fn joint_goal(
    model: &RobotModel,
    field: &str,
    constraints: &[JointConstraint],
    start: &[Real],
    max_error: Real,
) -> Result<(Goal, Vec<String>)> {
    let names = model.variable_names();
    let mut center = start.to_vec();
    let (mut below, mut above) = (vec![0.0; names.len()], vec![0.0; names.len()]);
    let mut seen = vec![false; names.len()];
    let mut moved = Vec::new();
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
        let joint = model.variable_joint(j);
        let (from, to) = (position - b, position + a);
        let (c, lo_cut, hi_cut) = match joint.limits {
            None => (*position, from, to),
            Some((lo, hi)) => {
                // The interval's point nearest the limits: inside them when the two meet.
                let nearest = if to < lo {
                    to
                } else if from > hi {
                    from
                } else {
                    from.max(lo)
                };
                let by = (nearest - nearest.clamp(lo, hi)).abs();
                if !joint.admits(nearest) && by > max_error {
                    return Err(Error::invalid(
                        format!("{field}[{k}].position"),
                        format!(
                            "joint `{}`: the goal interval [{from}, {to}] (position {position} − {b}, + {a}) misses \
                             its limits [{lo}, {hi}] by {by:.3e}, more than the start_state_max_bounds_error of \
                             {max_error} that is moved onto them",
                            joint.name
                        ),
                    ));
                }
                let (l, h) = (from.max(lo).min(hi), to.min(hi).max(lo));
                let c = position.clamp(l, h);
                if !joint.admits(nearest) {
                    moved.push(format!(
                        "{field}[{k}].position: joint `{}`: the goal interval [{from}, {to}] misses its limits [{lo}, \
                         {hi}] by {by:.3e}; the goal is taken at the limit {c} (start_state_max_bounds_error \
                         {max_error}), as MoveIt's JointConstraint takes it",
                        joint.name
                    ));
                } else if !joint.admits(*position) {
                    moved.push(format!(
                        "{field}[{k}].position: joint `{}` at {position} is outside its limits [{lo}, {hi}]; the goal \
                         is taken at {c}, in the limits and within the constraint's tolerances",
                        joint.name
                    ));
                }
                (c, l, h)
            }
        };
        center[j] = c;
        below[j] = c - lo_cut;
        above[j] = hi_cut - c;
    }
    model.check_limits(field, &center)?;
    if below.iter().chain(&above).all(|v| *v == 0.0) {
        return Ok((Goal::Configurations(vec![center]), moved));
    }
    Ok((Goal::Region(JointRegion { center, below, above }), moved))
}
