//! Subcommands of the `sublevel` binary; each file owns its clap arguments and its `run`.

pub mod bench;
pub mod chart;
pub mod chart_compound;
pub mod csv_file;
pub mod fit;
pub mod fit_compound;
pub mod fit_time;
pub mod group;
pub mod health;
pub mod loadtest;
pub mod peer_coal;
pub mod query;
pub mod serve;
pub mod serve_config;
pub mod serve_ops;
pub mod shard_probe;
pub mod stability;
pub mod table1;
