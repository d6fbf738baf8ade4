//! Inverse kinematics: joint configurations that put a link at a pose.
//!
//! A planner given a pose goal for its end effector (MoveIt's KDL / TRAC-IK plugins, cuRobo) first
//! turns it into goal configurations, then checks those for collision itself. This module finds
//! them numerically, by damped least squares on the frame Jacobian
//! ([`RobotModel::frame_jacobian`]), from the caller's seeds and then from random restarts.
//!
//! ```text
//! goal      link L at pose (R*, p*) in the world, within ε_p meters and ε_o radians
//! reached   (R(q), p(q)) = FK(q)_L                                   (RobotModel::forward_kinematics)
//! errors    e_p = p* − p(q)            position error  |e_p|          (meters)
//!           e_o = log(R* R(q)ᵀ)        rotation vector, |e_o| = angle (radians, in [0, π])
//! solved    |e_p| ≤ ε_p  and  |e_o| ≤ ε_o
//!
//! e  = [e_p; w · e_o]                   w = orientation weight (m/rad), 0 when ε_o ≥ π
//! J  = [J_v; w · J_ω]                   6 × dof, at the link's origin
//! λ² = λ₀² + ½ |e|²                     adaptive damping (Sugihara 2011)
//! Δq = Jᵀ (J Jᵀ + λ² I₆)⁻¹ e            damped least squares (Wampler 1986; Buss 2004, eq. 11)
//! Δq ← Δq · min(1, s_max / max_k |Δq_k|)
//! q  ← clamp(q + Δq)                   into the limits; continuous joints wrapped to (−π, π]
//! ```
//!
//! Damped least squares stays bounded near singular configurations where the pseudoinverse
//! blows up (C. W. Wampler, *Manipulator inverse kinematic solutions based on vector formulations
//! and damped least-squares methods*, IEEE SMC 1986; S. R. Buss, *Introduction to Inverse
//! Kinematics with Jacobian Transpose, Pseudoinverse and Damped Least Squares methods*, 2004).
//! The damping grows with the error (T. Sugihara, *Solvability-unconcerned inverse kinematics by the
//! Levenberg–Marquardt method*, IEEE T-RO 2011): long, careful steps far away, Gauss–Newton
//! convergence near a solution. Clamping into the joint limits is KDL's `ChainIkSolverPos_NR_JL`;
//! restarting from random configurations once a descent stalls is TRAC-IK's remedy for the local
//! minima that clamping and the reach create (P. Beeson, B. Ames, *TRAC-IK*, Humanoids 2015).
//!
//! Limits: a local method. A descent either reaches the tolerances within
//! [`IkSettings::max_iterations`] or is abandoned; an unreachable pose yields no solution after
//! every seed and restart has been tried, not a proof that none exists. Collisions are the
//! caller's to check: [`IkSolver::next_solution`] hands distinct solutions over one at a time.

use crate::model::{JointKind, RobotModel};
use crate::{Error, Result};
use nalgebra::{Matrix6, Matrix6xX, Vector6};
use rand::Rng;
use std::f64::consts::PI;
use sublevel_core::math::{Isometry3, Point3, Real};

/// A pose goal for one link: where its frame should be in the world, and how closely.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseGoal {
    /// The link whose frame is placed (the end effector, e.g. the Panda's `panda_hand`), by its
    /// URDF name.
    pub link: String,
    /// The link frame's target pose in the world frame (meters; the same world as the base pose
    /// given to the solver).
    pub pose: Isometry3,
    /// Largest accepted distance between the reached and the target origin (meters, ≥ 0).
    pub position_tolerance: Real,
    /// Largest accepted angle of the rotation between the reached and the target orientation
    /// (radians, ≥ 0). A value ≥ π accepts any orientation: the goal is then position only and
    /// the orientation is left out of the descent.
    pub orientation_tolerance: Real,
}

impl PoseGoal {
    /// A goal for `link` at `pose` with the round-trip tolerances of the tests: 1 mm and
    /// 0.01 rad.
    pub fn new(link: impl Into<String>, pose: Isometry3) -> Self {
        Self { link: link.into(), pose, position_tolerance: 1e-3, orientation_tolerance: 1e-2 }
    }

    /// Whether the goal ignores orientation (`orientation_tolerance` ≥ π).
    pub fn is_position_only(&self) -> bool {
        self.orientation_tolerance >= PI
    }

    /// The errors of a reached link pose against the goal: (distance between the origins in
    /// meters, angle of `R_target · R_reachedᵀ` in radians, in [0, π]).
    pub fn errors(&self, reached: &Isometry3) -> (Real, Real) {
        let position = (self.pose.translation.vector - reached.translation.vector).norm();
        let orientation = self.pose.rotation.angle_to(&reached.rotation);
        (position, orientation)
    }

    /// Checks the goal against `model` and returns the link's index.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `goal.link` (no such link), `goal.pose` (a non-finite
    /// translation or rotation), `goal.position_tolerance` or `goal.orientation_tolerance` (NaN,
    /// infinite or negative; an infinite orientation tolerance is accepted: position only).
    pub fn validate(&self, model: &RobotModel) -> Result<usize> {
        let link = model.link_index(&self.link).ok_or_else(|| {
            Error::invalid(
                "goal.link",
                format!("link `{}` is not a link of robot `{}`", sublevel_core::error::clip(&self.link), model.name),
            )
        })?;
        let t = self.pose.translation.vector;
        let r = self.pose.rotation.coords;
        if !(t.iter().all(|v| v.is_finite()) && r.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid("goal.pose", "the target pose must be finite"));
        }
        if !(self.position_tolerance.is_finite() && self.position_tolerance >= 0.0) {
            return Err(Error::invalid(
                "goal.position_tolerance",
                format!("must be a finite length ≥ 0 in meters, got {}", self.position_tolerance),
            ));
        }
        if self.orientation_tolerance.is_nan() || self.orientation_tolerance < 0.0 {
            return Err(Error::invalid(
                "goal.orientation_tolerance",
                format!("must be an angle ≥ 0 in radians (≥ π: position only), got {}", self.orientation_tolerance),
            ));
        }
        Ok(link)
    }
}

/// Tunables of the damped-least-squares descent and its restarts (module docs give the update).
#[derive(Clone, Debug, PartialEq)]
pub struct IkSettings {
    /// Iterations of one descent before it is abandoned (default 100).
    pub max_iterations: usize,
    /// The damping floor λ₀ (meters, ≥ 0; default 1e-2); the damping used is
    /// `λ² = λ₀² + ½ |e|²`.
    pub damping: Real,
    /// Largest change of any configuration entry in one iteration (radians or meters, > 0;
    /// default 0.5): a longer step is scaled down whole, keeping its direction.
    pub max_step: Real,
    /// Random restarts after the caller's seeds (default 16): configurations drawn uniformly
    /// within the joint limits (continuous joints in [−π, π]).
    pub random_seeds: usize,
    /// Meters of position error one radian of orientation error is worth in the descent (≥ 0;
    /// default 0.5, about half a 7-dof arm's reach). It shapes the path, not the tolerances; 0
    /// leaves orientation out of the descent, which then meets an orientation tolerance < π only
    /// by chance.
    pub orientation_weight: Real,
    /// Solutions closer than this to one already returned (largest entry difference, radians or
    /// meters; continuous joints modulo 2π) are skipped (≥ 0; default 1e-3).
    pub distinct: Real,
    /// How many solutions [`solve_ik`] collects before it stops (default 1).
    pub max_solutions: usize,
}

impl Default for IkSettings {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            damping: 1e-2,
            max_step: 0.5,
            random_seeds: 16,
            orientation_weight: 0.5,
            distinct: 1e-3,
            max_solutions: 1,
        }
    }
}

impl IkSettings {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `settings.<field>` for a zero `max_iterations`, a
    /// non-finite or negative `damping`, `orientation_weight` or `distinct`, or a `max_step` that
    /// is not finite and positive.
    pub fn validate(&self) -> Result<()> {
        if self.max_iterations == 0 {
            return Err(Error::invalid("settings.max_iterations", "must be at least 1"));
        }
        for (field, v) in
            [("damping", self.damping), ("orientation_weight", self.orientation_weight), ("distinct", self.distinct)]
        {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("settings.{field}"), format!("must be finite and ≥ 0, got {v}")));
            }
        }
        if !(self.max_step.is_finite() && self.max_step > 0.0) {
            return Err(Error::invalid("settings.max_step", format!("must be finite and > 0, got {}", self.max_step)));
        }
        Ok(())
    }
}

/// A configuration that reaches a pose goal.
#[derive(Clone, Debug, PartialEq)]
pub struct IkSolution {
    /// The configuration (one entry per [`RobotModel::variable_names`], radians or meters),
    /// within the joint limits; continuous joints in (−π, π].
    pub q: Vec<Real>,
    /// Distance between the reached and the target origin (meters, ≤ the goal's tolerance).
    pub position_error: Real,
    /// Angle between the reached and the target orientation (radians, ≤ the goal's tolerance).
    pub orientation_error: Real,
    /// Iterations of the descent that found it (0: its seed already reached the goal).
    pub iterations: usize,
}

/// Solutions of one pose goal, one after another: the caller's seeds first, in order, then
/// [`IkSettings::random_seeds`] random restarts, each descending once (module docs); solutions
/// within [`IkSettings::distinct`] of an earlier one are skipped. A planner pulls solutions with
/// [`IkSolver::next_solution`] until one is free of collision.
#[derive(Clone, Debug)]
pub struct IkSolver<'a> {
    model: &'a RobotModel,
    base: Isometry3,
    goal: PoseGoal,
    link: usize,
    settings: IkSettings,
    /// The caller's seeds, already clamped into the limits; consumed from the front.
    seeds: Vec<Vec<Real>>,
    next_seed: usize,
    random_left: usize,
    found: Vec<Vec<Real>>,
    attempts: usize,
    /// No descent starts past this instant ([`IkSolver::set_deadline`]).
    deadline: Option<std::time::Instant>,
    /// Scratch reused by every iteration: link poses and the 6 × dof Jacobian.
    poses: Vec<Isometry3>,
    jacobian: Matrix6xX<Real>,
}

impl<'a> IkSolver<'a> {
    /// A solver for `goal` on `model` with its root link at `base` (world frame, meters), starting
    /// from `seeds` (each one configuration, one entry per [`RobotModel::variable_names`]; entries
    /// outside the limits are clamped into them).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] as [`PoseGoal::validate`] and [`IkSettings::validate`]; naming
    /// `base` (non-finite) or `seeds[i]` / `seeds[i][k]` (wrong length, non-finite entry).
    pub fn new(
        model: &'a RobotModel,
        base: &Isometry3,
        goal: &PoseGoal,
        seeds: &[Vec<Real>],
        settings: &IkSettings,
    ) -> Result<Self> {
        let link = goal.validate(model)?;
        settings.validate()?;
        if !(base.translation.vector.iter().chain(base.rotation.coords.iter()).all(|v| v.is_finite())) {
            return Err(Error::invalid("base", "the base pose must be finite"));
        }
        let mut clamped = Vec::with_capacity(seeds.len());
        for (i, seed) in seeds.iter().enumerate() {
            model.check_configuration(&format!("seeds[{i}]"), seed)?;
            clamped.push(seed.iter().enumerate().map(|(k, &v)| clamp_entry(model, k, v)).collect());
        }
        Ok(Self {
            model,
            base: *base,
            goal: goal.clone(),
            link,
            settings: settings.clone(),
            seeds: clamped,
            next_seed: 0,
            random_left: settings.random_seeds,
            found: Vec::new(),
            attempts: 0,
            deadline: None,
            poses: Vec::new(),
            jacobian: Matrix6xX::zeros(model.dof()),
        })
    }

    /// Stops [`IkSolver::next_solution`] at `deadline`: no descent starts after it (one that
    /// has started runs its iteration budget out, a few milliseconds at most).
    pub fn set_deadline(&mut self, deadline: std::time::Instant) {
        self.deadline = Some(deadline);
    }

    /// The next distinct solution, or `None` once every seed and random restart has been tried
    /// or the deadline ([`IkSolver::set_deadline`]) has passed. Draws random restarts from `rng`
    /// (uniform within the limits) after the caller's seeds.
    pub fn next_solution(&mut self, rng: &mut impl Rng) -> Option<IkSolution> {
        loop {
            if self.deadline.is_some_and(|d| std::time::Instant::now() >= d) {
                return None;
            }
            let start = if self.next_seed < self.seeds.len() {
                self.next_seed += 1;
                self.seeds[self.next_seed - 1].clone()
            } else if self.random_left > 0 {
                self.random_left -= 1;
                random_configuration(self.model, rng)
            } else {
                return None;
            };
            self.attempts += 1;
            let Some(solution) = self.descend(start) else { continue };
            if self.found.iter().any(|f| distance(self.model, f, &solution.q) < self.settings.distinct) {
                continue;
            }
            self.found.push(solution.q.clone());
            return Some(solution);
        }
    }

    /// Descents run so far (seeds and random restarts, successful or not).
    pub fn attempts(&self) -> usize {
        self.attempts
    }

    /// One damped-least-squares descent from `q` (within the limits): a solution, or `None` if it
    /// did not reach the tolerances within the iteration budget.
    fn descend(&mut self, mut q: Vec<Real>) -> Option<IkSolution> {
        let model = self.model;
        let target = self.goal.pose;
        let w = if self.goal.is_position_only() { 0.0 } else { self.settings.orientation_weight };
        let lambda0 = self.settings.damping * self.settings.damping;
        for iteration in 0..=self.settings.max_iterations {
            // q stays finite (seeds checked, steps bounded), so this cannot fail.
            model.forward_kinematics(&q, &self.base, &mut self.poses).ok()?;
            let reached = self.poses[self.link];
            let (position_error, orientation_error) = self.goal.errors(&reached);
            if position_error <= self.goal.position_tolerance && orientation_error <= self.goal.orientation_tolerance {
                return Some(IkSolution { q, position_error, orientation_error, iterations: iteration });
            }
            if iteration == self.settings.max_iterations {
                break;
            }
            let ep = target.translation.vector - reached.translation.vector;
            let eo = (target.rotation * reached.rotation.inverse()).scaled_axis() * w;
            let e = Vector6::new(ep.x, ep.y, ep.z, eo.x, eo.y, eo.z);
            let origin = Point3::from(reached.translation.vector);
            model.frame_jacobian(&self.poses, self.link, &origin, &mut self.jacobian);
            self.jacobian.fixed_rows_mut::<3>(3).scale_mut(w);
            let lambda2 = lambda0 + 0.5 * e.norm_squared();
            let mut dq = dls_step(&self.jacobian, &e, lambda2)?;
            // Joints at a limit that the step pushes further out would only be clamped back:
            // drop their columns and solve again, so that the other joints take up the motion.
            let mut blocked = false;
            for (k, &v) in q.iter().enumerate() {
                if let Some((lo, hi)) = model.variable_joint(k).limits {
                    if (v <= lo && dq[k] < 0.0) || (v >= hi && dq[k] > 0.0) {
                        self.jacobian.column_mut(k).fill(0.0);
                        blocked = true;
                    }
                }
            }
            if blocked {
                dq = dls_step(&self.jacobian, &e, lambda2)?;
            }
            let longest = dq.amax();
            if longest > self.settings.max_step {
                dq *= self.settings.max_step / longest;
            }
            for (k, v) in q.iter_mut().enumerate() {
                *v = clamp_entry(model, k, *v + dq[k]);
            }
        }
        None
    }
}

/// Distinct solutions of `goal` for `model` with its root at `base`: up to
/// [`IkSettings::max_solutions`] of them, in the order [`IkSolver::next_solution`] finds them
/// (the caller's `seeds` first, then random restarts drawn from `rng`). Empty when no descent
/// reached the tolerances, e.g. for a pose beyond the robot's reach. Damped least squares with
/// random restarts (module docs; Wampler 1986, Buss 2004, Sugihara 2011, TRAC-IK 2015).
///
/// # Errors
/// As [`IkSolver::new`].
pub fn solve_ik(
    model: &RobotModel,
    base: &Isometry3,
    goal: &PoseGoal,
    seeds: &[Vec<Real>],
    settings: &IkSettings,
    rng: &mut impl Rng,
) -> Result<Vec<IkSolution>> {
    let mut solver = IkSolver::new(model, base, goal, seeds, settings)?;
    let mut out = Vec::new();
    while out.len() < settings.max_solutions {
        match solver.next_solution(rng) {
            Some(solution) => out.push(solution),
            None => break,
        }
    }
    Ok(out)
}

/// The damped-least-squares step `Jᵀ (J Jᵀ + λ² I₆)⁻¹ e` (Buss 2004, eq. 11); `None` only if the
/// 6 × 6 system is not positive definite (λ² = 0 at a singular configuration).
fn dls_step(j: &Matrix6xX<Real>, e: &Vector6<Real>, lambda2: Real) -> Option<nalgebra::DVector<Real>> {
    let a = j * j.transpose() + Matrix6::identity() * lambda2;
    let y = a.cholesky()?.solve(e);
    Some(j.transpose() * y)
}

/// A configuration drawn uniformly within the joint limits (continuous joints in [−π, π]), one
/// entry per [`RobotModel::variable_names`].
pub fn random_configuration(model: &RobotModel, rng: &mut impl Rng) -> Vec<Real> {
    (0..model.dof())
        .map(|k| {
            let (lo, hi) = model.variable_joint(k).limits.unwrap_or((-PI, PI));
            if hi > lo {
                rng.random_range(lo..=hi)
            } else {
                lo
            }
        })
        .collect()
}

/// Entry k moved into its joint's limits, or wrapped to (−π, π] for a continuous joint.
fn clamp_entry(model: &RobotModel, k: usize, v: Real) -> Real {
    let joint = model.variable_joint(k);
    match (joint.kind, joint.limits) {
        (_, Some((lo, hi))) => v.clamp(lo, hi),
        (JointKind::Continuous, None) => wrap_angle(v),
        (_, None) => v,
    }
}

/// `v` modulo 2π in (−π, π].
fn wrap_angle(v: Real) -> Real {
    let r = (v + PI).rem_euclid(2.0 * PI) - PI;
    if r <= -PI {
        r + 2.0 * PI
    } else {
        r
    }
}

/// The largest entry difference of two configurations; continuous joints modulo 2π.
fn distance(model: &RobotModel, a: &[Real], b: &[Real]) -> Real {
    a.iter()
        .zip(b)
        .enumerate()
        .map(|(k, (x, y))| {
            let d = x - y;
            if model.variable_joint(k).kind == JointKind::Continuous {
                wrap_angle(d).abs()
            } else {
                d.abs()
            }
        })
        .fold(0.0, Real::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_lands_in_the_half_open_interval() {
        for (v, want) in
            [(PI, PI), (-PI, PI), (3.0 * PI, PI), (0.5, 0.5), (-0.5 - 2.0 * PI, -0.5), (7.0, 7.0 - 2.0 * PI)]
        {
            assert!((wrap_angle(v) - want).abs() < 1e-12, "{v} -> {} (want {want})", wrap_angle(v));
        }
    }
}
