//! The one integration-test binary (one link step instead of many): modules by area.

mod fit;
mod gradient;
mod group;
mod hardening;
mod ops;
mod planner;
mod query;
mod service;
mod service_jobs;
mod stability;
mod table;
mod transport;
mod util;
