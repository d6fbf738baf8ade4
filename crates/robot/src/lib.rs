//! # sublevel-robot
//!
//! Robots as planners see them: a URDF kinematic tree whose links carry collision geometry, moved by
//! a joint configuration `q` (radians for revolute and continuous joints, meters for prismatic
//! ones).
//!
//! - [`model`]: the [`RobotModel`] read from URDF (openrr's `urdf-rs` parser): links, joints
//!   (revolute, continuous, prismatic, fixed; mimic joints), limits, collision geometry, and the
//!   order of the configuration's entries.
//! - [`srdf`]: the SRDF's allowed-collision pairs, named configurations and virtual joints, and
//!   the self-collision pairs they leave.
//! - [`motion`]: how far a link can move along a joint-space segment (the bound of conservative
//!   advancement), from the kinematic chain.
//! - [`kinematics`]: forward kinematics — every link's pose in the world for a configuration and a
//!   base pose — checked against pinocchio's `framesForwardKinematics` to 1e-12 m; point and frame
//!   Jacobians.
//! - [`ik`]: inverse kinematics — configurations that put a link at a pose goal, by damped least
//!   squares with random restarts, handed over one distinct solution at a time.
//!
//! - [`fit`]: a robot fitted once — every link mesh a compound sos-convex body containing it
//!   (paper §V), URDF primitives exact, the SRDF's allowed pairs — saved as a robot file
//!   ([`fitted`]).
//! - [`world`]: the world a robot is checked in — named exact primitives, triangle meshes and
//!   point clouds.
//! - [`cloud`]: point-cloud obstacles from depth sensors — filters, depth deprojection, the
//!   points in a k-d tree.
//! - [`spheres`]: sphere trees of link meshes (every point of every triangle inside a chain of
//!   nested balls), the checks' first stage after the ball and box gaps.
//! - [`inner`]: balls inside closed link meshes, which prove a pair colliding without the mesh.
//! - [`clearance`]: joint-space tables of the meshes' distance for self pairs moved by one or two
//!   joints, a lookup before the sphere trees.
//! - [`check`]: configurations checked against the world and for
//!   self-collision: the sos model decides what is far, the meshes what is near; no missed
//!   collision, and the minimum distance never above the meshes'.
//!
//! - [`advance`]: joint-space motions proven free by conservative advancement, or their first
//!   contact, with no sampling resolution.
//!
//! This crate knows nothing of scenes or gRPC.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub use sublevel_core::{Error, Result};

pub mod advance;
mod answer;
pub mod check;
pub mod clearance;
pub mod cloud;
mod exact;
pub mod fidelity;
pub mod fit;
pub mod fitted;
pub mod ik;
pub mod inner;
pub mod kinematics;
pub mod limits;
pub mod model;
pub mod motion;
pub mod spheres;
pub mod srdf;
pub mod world;

pub use advance::{MotionAnswer, MotionChecker, MotionOptions};
pub use check::block::{rake_order, RakeAnswer, BLOCK};
pub use check::{CheckOptions, ConfigurationAnswer, RobotChecker};
pub use cloud::PointCloud;
pub use fidelity::Fidelity;
pub use fit::{check_mesh_name, fit_robot, fit_robot_text, MeshSource, RobotFitProgress, RobotFitSettings};
pub use fitted::{FittedRobot, LinkShape, RobotFile, RobotGeometry};
pub use ik::{solve_ik, IkSettings, IkSolution, IkSolver, PoseGoal};
pub use model::{resolve_mesh_path, CollisionGeometry, Joint, JointKind, JointValue, Link, RobotModel};
pub use srdf::Semantics;
pub use world::{WorldMesh, WorldObject, WorldShape};
