//! The robot crate's one integration-test binary: forward kinematics against pinocchio, the URDF
//! model's closed forms and errors.

mod fk;
mod model;
