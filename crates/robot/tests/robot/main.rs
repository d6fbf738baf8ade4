//! The robot crate's one integration-test binary: forward kinematics against pinocchio, the URDF
//! model's closed forms and errors, SRDF reading.

mod fk;
mod model;
mod srdf;
