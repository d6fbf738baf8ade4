//! The one integration-test binary (one link step instead of many): modules by area.

mod admission;
mod deadlines;
mod fit;
mod gradient;
mod group;
mod hardening;
mod instance_motions;
mod jobs_api;
mod ops;
mod planner;
mod primitive_cli;
mod primitives;
mod query;
mod query_compound;
mod robot;
mod robot_cli;
mod robot_service;
mod scene_import;
mod scene_robot;
mod security;
mod service;
mod service_compound;
mod service_jobs;
mod transport;
mod util;
