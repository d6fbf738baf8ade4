//! Subcommands of the `sublevel` binary; each file owns its clap arguments and its `run`.

pub mod cloud;
pub mod cloud_bench;
pub mod cloud_files;
pub mod fidelity;
pub mod fit;
pub mod fit_compound;
pub mod group;
pub mod health;
pub mod loadtest;
pub mod primitive;
pub mod query;
pub mod robot;
pub mod robot_bench;
mod robot_plan;
pub mod scene;
pub mod serve;
pub mod serve_config;
pub mod serve_ops;
pub mod shard_probe;
