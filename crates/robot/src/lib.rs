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
//!   base pose — checked against pinocchio's `framesForwardKinematics` to 1e-12 m.
//!
//! This crate knows nothing of scenes or gRPC.

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub use sublevel_core::{Error, Result};

pub mod kinematics;
pub mod model;
pub mod motion;
pub mod srdf;

pub use model::{resolve_mesh_path, CollisionGeometry, Joint, JointKind, JointValue, Link, RobotModel};
pub use srdf::Semantics;
