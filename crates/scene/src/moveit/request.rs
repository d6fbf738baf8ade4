//! A MoveIt motion plan request (`moveit_msgs/MotionPlanRequest`, YAML or JSON) as the
//! MotionBenchMaker problems write it: the start state's joint positions, the goal's joint
//! constraints and the planning group. Other constraints, tolerances and planner settings are
//! not read.

use crate::{Error, Result};
use serde::Deserialize;
use sublevel_core::math::Real;

/// A motion plan request: start and goal joint positions by name (radians, meters).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MotionPlanRequest {
    /// The planning group (`group_name`; empty when absent).
    pub group_name: String,
    /// The start state's joint positions, in message order.
    pub start: Vec<(String, Real)>,
    /// The first goal constraint's joint positions, in message order.
    pub goal: Vec<(String, Real)>,
    /// Their tolerances, in the same order: (below, above), radians or meters, ≥ 0 (0 when the
    /// message leaves them out).
    pub goal_tolerances: Vec<(Real, Real)>,
}

#[derive(Deserialize)]
struct RawRequest {
    #[serde(default)]
    group_name: String,
    #[serde(default)]
    start_state: RawStart,
    #[serde(default)]
    goal_constraints: Vec<RawGoal>,
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

impl MotionPlanRequest {
    /// The goal's joint constraints as `(joint, position, tolerance below, tolerance above)`, in
    /// message order (radians or meters).
    pub fn goal_constraints(&self) -> Vec<(String, Real, Real, Real)> {
        self.goal
            .iter()
            .zip(&self.goal_tolerances)
            .map(|((n, v), (below, above))| (n.clone(), *v, *below, *above))
            .collect()
    }

    /// Reads a request from YAML (or JSON) bytes.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `request` for bytes that are not the message,
    /// `start_state.joint_state` when names and positions differ in number,
    /// `goal_constraints` when there is no joint goal, or the first non-finite position.
    pub fn from_yaml(bytes: &[u8]) -> Result<Self> {
        let raw: RawRequest = super::parse_yaml("request", bytes)?;
        let js = raw.start_state.joint_state;
        if js.name.len() != js.position.len() {
            return Err(Error::invalid(
                "start_state.joint_state",
                format!("{} names for {} positions", js.name.len(), js.position.len()),
            ));
        }
        if let Some(k) = js.position.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("start_state.joint_state.position[{k}]"), "must be finite"));
        }
        let goal: Vec<(String, Real)> = raw
            .goal_constraints
            .first()
            .map(|g| g.joint_constraints.iter().map(|c| (c.joint_name.clone(), c.position)).collect())
            .unwrap_or_default();
        if goal.is_empty() {
            return Err(Error::invalid("goal_constraints", "no joint constraints: a joint-space goal is needed"));
        }
        if let Some(k) = goal.iter().position(|(_, v)| !v.is_finite()) {
            return Err(Error::invalid(
                format!("goal_constraints[0].joint_constraints[{k}].position"),
                "must be finite",
            ));
        }
        let goal_tolerances: Vec<(Real, Real)> =
            raw.goal_constraints[0].joint_constraints.iter().map(|c| (c.tolerance_below, c.tolerance_above)).collect();
        for (k, (below, above)) in goal_tolerances.iter().enumerate() {
            for (name, v) in [("tolerance_below", below), ("tolerance_above", above)] {
                if !(v.is_finite() && *v >= 0.0) {
                    return Err(Error::invalid(
                        format!("goal_constraints[0].joint_constraints[{k}].{name}"),
                        format!("must be finite and ≥ 0, got {v}"),
                    ));
                }
            }
        }
        Ok(Self {
            group_name: raw.group_name,
            start: js.name.into_iter().zip(js.position).collect(),
            goal,
            goal_tolerances,
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
    }
}
