//! # sublevel-plan
//!
//! Motion planning for a fitted robot among a world: one call from a start configuration to a
//! goal, answered with a path whose every edge is proven free.
//!
//! ```text
//! request   start, goal (configurations, or a joint region), settings (timeout, seed, range,
//!           padding, simplification)
//! goals     the start and the goal configurations checked: a colliding start or no free goal
//!           ends the plan, naming the pair
//! search    RRT-Connect (Kuffner and LaValle, 2000) from the start to every goal at once, Halton
//!           samples, edges checked at 32 samples per unit of joint distance, in
//!           blocks of 8 spread along the edge (rakes)                            [`rrt`]
//! simplify  redundant waypoints dropped, random shortcuts, optional corner cutting [`simplify`]
//! certify   every edge proven free by conservative advancement; one that is not is split, or
//!           re-planned with certified edges in the time left                     [`certify`]
//! time      on request, the path's corners blended by arcs proven free, then time-optimal within
//!           the joints' velocity and acceleration limits (TOPP-RA)            [`trajectory`]
//! ```
//!
//! The planner sees its checker through [`Validity`] ([`RobotValidity`] for a fitted robot among
//! a world, [`sublevel_robot::MotionChecker`] underneath), so the search is the same for any
//! robot and any checker. The same request with the same seed gives the same path.
//!
//! This crate knows nothing of scenes or gRPC: the service and the command line turn their
//! requests into a [`plan`] call.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod certify;
pub mod joints;
mod plan;
pub mod rrt;
pub mod simplify;
pub mod space;
pub mod trajectory;
pub mod validity;

pub use certify::certificate_tolerance;
pub use joints::{fix_start_bounds, joint_goal, start_from_joints, JointConstraint, START_STATE_MAX_BOUNDS_ERROR};
pub use plan::{
    check_configuration, plan, Goal, JointRegion, PlanOutcome, PlanSettings, PlanStatus, PlanTiming, MAX_GOALS,
    MAX_PADDING, MAX_RESOLUTION, MAX_SHORTCUT_ATTEMPTS, MAX_SMOOTHING_PASSES, MAX_TIMEOUT, MAX_TOLERANCE,
};
pub use space::{HaltonSampler, JointSpace};
pub use trajectory::{
    certify_blends, time_path, BlendCertificate, BlendedPath, JointLimits, Timing, TimingSettings, Trajectory,
};
pub use validity::{Certificate, CheckCounts, RobotValidity, Validity};
