//! The robot crate's one integration-test binary: forward kinematics against pinocchio, the URDF
//! model's closed forms and errors, SRDF reading, the motion bound against brute force.

mod fk;
mod model;
mod motion;
mod srdf;
