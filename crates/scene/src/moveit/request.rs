//! A MoveIt motion plan request (`moveit_msgs/MotionPlanRequest`, YAML or JSON) as the
//! MotionBenchMaker problems write it: the start state's joint positions, the goals' joint
//! constraints, the planning group and the scaling factors of the velocity and acceleration
//! limits (for the timed trajectory). Other planner settings (planner id, attempts, the
//! workspace) are not read; constraints the planner cannot honor (a goal's position,
//! orientation or visibility constraints, path and trajectory constraints) are refused, naming
//! the field, rather than ignored.

use crate::{Error, Result};
use serde::de::IgnoredAny;
use serde::Deserialize;
use sublevel_core::math::Real;

/// A motion plan request: start and goal joint positions by name (radians, meters).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MotionPlanRequest {
    /// The planning group (`group_name`; empty when absent).
    pub group_name: String,
    /// The start state's joint positions, in message order (each name once).
    pub start: Vec<(String, Real)>,
    /// The first goal constraint's joint positions, in message order.
    pub goal: Vec<(String, Real)>,
    /// Their tolerances, in the same order: (below, above), radians or meters, ≥ 0 (0 when the
    /// message leaves them out).
    pub goal_tolerances: Vec<(Real, Real)>,
    /// Every goal constraint (MoveIt plans to any one of them), each as
    /// `(joint, position, tolerance below, tolerance above)` in message order; the first is
    /// `goal` with `goal_tolerances`.
    pub goals: Vec<Vec<(String, Real, Real, Real)>>,
    /// `max_velocity_scaling_factor`, in (0, 1], when the message gives one other than 0 (MoveIt
    /// reads 0 as "the default").
    pub max_velocity_scaling_factor: Option<Real>,
    /// `max_acceleration_scaling_factor`, likewise.
    pub max_acceleration_scaling_factor: Option<Real>,
}

#[derive(Deserialize)]
struct RawRequest {
    #[serde(default)]
    group_name: String,
    #[serde(default)]
    start_state: RawStart,
    #[serde(default)]
    goal_constraints: Vec<RawGoal>,
    #[serde(default)]
    path_constraints: Option<RawGoal>,
    #[serde(default)]
    trajectory_constraints: Option<RawTrajectory>,
    #[serde(default)]
    max_velocity_scaling_factor: Real,
    #[serde(default)]
    max_acceleration_scaling_factor: Real,
}

#[derive(Deserialize, Default)]
struct RawStart {
    #[serde(default)]
    joint_state: RawJoints,
}

#[derive(Deserialize, Default)]
struct RawJoints {
    #[serde(default)]
    name: Vec<String>,
    #[serde(default)]
    position: Vec<Real>,
}

#[derive(Deserialize)]
struct RawGoal {
    #[serde(default)]
    joint_constraints: Vec<RawConstraint>,
    #[serde(default)]
    position_constraints: Vec<IgnoredAny>,
    #[serde(default)]
    orientation_constraints: Vec<IgnoredAny>,
    #[serde(default)]
    visibility_constraints: Vec<IgnoredAny>,
}

#[derive(Deserialize)]
struct RawTrajectory {
    #[serde(default)]
    constraints: Vec<IgnoredAny>,
}

#[derive(Deserialize)]
struct RawConstraint {
    joint_name: String,
    position: Real,
    #[serde(default)]
    tolerance_below: Real,
    #[serde(default)]
    tolerance_above: Real,
}

impl RawGoal {
    /// The constraint kinds this goal holds that the planner does not take, by field name.
    fn unsupported(&self) -> Option<&'static str> {
        [
            ("position_constraints", self.position_constraints.len()),
            ("orientation_constraints", self.orientation_constraints.len()),
            ("visibility_constraints", self.visibility_constraints.len()),
        ]
        .into_iter()
        .find(|(_, n)| *n > 0)
        .map(|(field, _)| field)
    }
}

impl MotionPlanRequest {
    /// The first goal's joint constraints as `(joint, position, tolerance below, tolerance
    /// above)`, in message order (radians or meters).
    pub fn goal_constraints(&self) -> Vec<(String, Real, Real, Real)> {
        self.goals.first().cloned().unwrap_or_default()
    }

    /// Reads a request from YAML (or JSON) bytes.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `request` for bytes that are not the message,
    /// `start_state.joint_state` when names and positions differ in number,
    /// `start_state.joint_state.name[k]` for a repeated name, the first non-finite position,
    /// `goal_constraints` when there is no goal, `goal_constraints[k]` for a goal without joint
    /// constraints, `goal_constraints[k].joint_constraints[j].…` for a position that is not
    /// finite or a tolerance that is negative or not finite, `goal_constraints[k].position_constraints`
    /// (and `orientation_constraints`, `visibility_constraints`), `path_constraints` and
    /// `trajectory_constraints` when they hold a constraint (the planner takes joint goals only).
    pub fn from_yaml(bytes: &[u8]) -> Result<Self> {
        let raw: RawRequest = super::parse_yaml("request", bytes)?;
        let js = raw.start_state.joint_state;
        if js.name.len() != js.position.len() {
            return Err(Error::invalid(
                "start_state.joint_state",
                format!("{} names for {} positions", js.name.len(), js.position.len()),
            ));
        }
        for (k, name) in js.name.iter().enumerate() {
            if js.name[..k].contains(name) {
                return Err(Error::invalid(
                    format!("start_state.joint_state.name[{k}]"),
                    format!("`{}` is repeated", sublevel_core::error::clip(name)),
                ));
            }
        }
        if let Some(k) = js.position.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("start_state.joint_state.position[{k}]"), "must be finite"));
        }
        if let Some(path) = &raw.path_constraints {
            if !path.joint_constraints.is_empty() || path.unsupported().is_some() {
                return Err(Error::invalid(
                    "path_constraints",
                    "path constraints are not supported: the planner takes a start and joint goals",
                ));
            }
        }
        if raw.trajectory_constraints.is_some_and(|t| !t.constraints.is_empty()) {
            return Err(Error::invalid(
                "trajectory_constraints",
                "trajectory constraints are not supported: the planner takes a start and joint goals",
            ));
        }
        if raw.goal_constraints.is_empty() {
            return Err(Error::invalid("goal_constraints", "no goal: a joint-space goal is needed"));
        }
        let mut goals = Vec::with_capacity(raw.goal_constraints.len());
        for (g, goal) in raw.goal_constraints.iter().enumerate() {
            if let Some(kind) = goal.unsupported() {
                return Err(Error::invalid(
                    format!("goal_constraints[{g}].{kind}"),
                    "not supported: give the goal as joint constraints (or use the typed goal_pose)",
                ));
            }
            if goal.joint_constraints.is_empty() {
                return Err(Error::invalid(
                    format!("goal_constraints[{g}]"),
                    "no joint constraints: a joint-space goal is needed",
                ));
            }
            let mut constraints = Vec::with_capacity(goal.joint_constraints.len());
            for (k, c) in goal.joint_constraints.iter().enumerate() {
                let field = format!("goal_constraints[{g}].joint_constraints[{k}]");
                if !c.position.is_finite() {
                    return Err(Error::invalid(format!("{field}.position"), "must be finite"));
                }
                for (name, v) in [("tolerance_below", c.tolerance_below), ("tolerance_above", c.tolerance_above)] {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(Error::invalid(
                            format!("{field}.{name}"),
                            format!("must be finite and ≥ 0, got {}", sublevel_core::error::show_real(v)),
                        ));
                    }
                }
                constraints.push((c.joint_name.clone(), c.position, c.tolerance_below, c.tolerance_above));
            }
            goals.push(constraints);
        }
        let mut factors = [None, None];
        for (k, (name, v)) in [
            ("max_velocity_scaling_factor", raw.max_velocity_scaling_factor),
            ("max_acceleration_scaling_factor", raw.max_acceleration_scaling_factor),
        ]
        .into_iter()
        .enumerate()
        {
            if v != 0.0 {
                if !(v > 0.0 && v <= 1.0) {
                    return Err(Error::invalid(
                        name,
                        format!("must be in (0, 1] (or 0 for the default), got {}", sublevel_core::error::show_real(v)),
                    ));
                }
                factors[k] = Some(v);
            }
        }
        Ok(Self {
            max_velocity_scaling_factor: factors[0],
            max_acceleration_scaling_factor: factors[1],
            group_name: raw.group_name,
            start: js.name.into_iter().zip(js.position).collect(),
            goal: goals[0].iter().map(|(n, v, _, _)| (n.clone(), *v)).collect(),
            goal_tolerances: goals[0].iter().map(|(_, _, b, a)| (*b, *a)).collect(),
            goals,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_motionbenchmaker_request_reads_its_start_and_goal() {
        let path =
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/robots/mbm_panda/requests/table_pick/request0001.yaml");
        let r = MotionPlanRequest::from_yaml(&std::fs::read(path).unwrap()).unwrap();
        assert_eq!(r.group_name, "panda_arm");
        assert_eq!(r.start.len(), 9);
        assert_eq!(r.start[3], ("panda_joint4".to_owned(), -2.356));
        assert_eq!(r.start[8], ("panda_finger_joint2".to_owned(), 0.065));
        assert_eq!(r.goal.len(), 7);
        assert_eq!(r.goal[0], ("panda_joint1".to_owned(), -1.451140183264752));
        assert_eq!(r.goal[6], ("panda_joint7".to_owned(), 0.8869533207576928));
        assert_eq!(r.goal_tolerances, vec![(0.0, 0.0); 7]);
        let with = "goal_constraints: [{joint_constraints: [{joint_name: a, position: 1, tolerance_below: 0.1, tolerance_above: 0.2}]}]";
        assert_eq!(MotionPlanRequest::from_yaml(with.as_bytes()).unwrap().goal_tolerances, vec![(0.1, 0.2)]);
        // MotionBenchMaker's files give no scaling factors (MoveIt reads 0 as its default).
        assert_eq!((r.max_velocity_scaling_factor, r.max_acceleration_scaling_factor), (None, None));
        let scaled = format!("{with}\nmax_velocity_scaling_factor: 0.5\nmax_acceleration_scaling_factor: 0");
        let scaled = MotionPlanRequest::from_yaml(scaled.as_bytes()).unwrap();
        assert_eq!((scaled.max_velocity_scaling_factor, scaled.max_acceleration_scaling_factor), (Some(0.5), None));
    }

    #[test]
    fn a_bad_request_is_refused_naming_the_field() {
        let field = |text: &str| match MotionPlanRequest::from_yaml(text.as_bytes()).unwrap_err() {
            Error::InvalidArgument { field, .. } => field,
            other => panic!("{other}"),
        };
        assert_eq!(field("start_state: {joint_state: {name: [a, b], position: [1]}}"), "start_state.joint_state");
        assert_eq!(field("start_state: {joint_state: {name: [a], position: [1]}}"), "goal_constraints");
        assert_eq!(field("- 1\n- 2\n"), "request");
        let goal = "goal_constraints: [{joint_constraints: [{joint_name: a, position: 1}]}]";
        assert_eq!(
            field(&format!("start_state: {{joint_state: {{name: [a, b, a], position: [1, 2, 3]}}}}\n{goal}")),
            "start_state.joint_state.name[2]"
        );
        assert_eq!(
            field("goal_constraints: [{joint_constraints: [{joint_name: a, position: 1}]}, {joint_constraints: [{joint_name: a, position: .nan}]}]"),
            "goal_constraints[1].joint_constraints[0].position"
        );
        assert_eq!(
            field("goal_constraints: [{joint_constraints: [{joint_name: a, position: 1}], position_constraints: [{link_name: hand}]}]"),
            "goal_constraints[0].position_constraints"
        );
        assert_eq!(field("goal_constraints: [{position_constraints: []}]"), "goal_constraints[0]");
        assert_eq!(
            field(&format!("{goal}\npath_constraints: {{joint_constraints: [{{joint_name: a, position: 1}}]}}")),
            "path_constraints"
        );
        assert_eq!(field(&format!("{goal}\nmax_velocity_scaling_factor: 1.5")), "max_velocity_scaling_factor");
        assert_eq!(field(&format!("{goal}\nmax_acceleration_scaling_factor: -1")), "max_acceleration_scaling_factor");
        // Empty constraint lists, as MoveIt writes them, are no constraint.
        let empty = format!("{goal}\npath_constraints: {{name: '', joint_constraints: [], position_constraints: []}}");
        assert_eq!(MotionPlanRequest::from_yaml(empty.as_bytes()).unwrap().goals.len(), 1);
    }
}
