//! The one integration-test binary (one link step instead of many): modules by area.

mod fit;
mod group;
mod query;
mod service;
