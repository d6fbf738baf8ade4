//! The `sublevel` command: `serve`, `fit`, `group`, `primitive`, `query`, `health`, `loadtest`,
//! `shard-probe`, `scene`, `robot`, `cloud`.
//! The paper's reproduction, benchmarks and charts are the `sublevel-lab` command (crates/lab).

#![forbid(unsafe_code)]

mod cli;

/// The binary's allocator: mimalloc keeps freed pages for the next request, where glibc's arenas
/// grow and trim (and fault fresh pages) on every large one: 4096 candidate states in one Query
/// took 16.8 ms of server time with glibc's allocator, 8.9 ms with mimalloc.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// Sublevel: collision queries between sos-convex polynomial bodies.
#[derive(Parser)]
#[command(name = "sublevel", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the gRPC server.
    Serve(cli::serve::ServeArgs),
    /// Fit a body to a mesh or point cloud and write its JSON body file.
    Fit(cli::fit::FitArgs),
    /// Contain posed body files with one sos-convex body (paper §V) and write its body file.
    Group(cli::group::GroupArgs),
    /// Write an exact primitive's file (box, sphere, cylinder, capsule, halfspace).
    Primitive(cli::primitive::PrimitiveArgs),
    /// Run a distance or growth query between two body or primitive files.
    Query(cli::query::QueryArgs),
    /// Load-test a running server over gRPC: latency histograms, throughput, errors by status.
    Loadtest(cli::loadtest::LoadtestArgs),
    /// Check a server's gRPC health (exit 0 when SERVING), for container healthchecks.
    Health(cli::health::HealthArgs),
    /// Scale-out test client: set up, route, move, check and load scenes through a sharding proxy.
    ShardProbe(cli::shard_probe::ShardProbeArgs),
    /// Scenes on a running server: `scene import` reads a MoveIt planning scene into a new scene.
    Scene(cli::scene::SceneArgs),
    /// Robots: `robot fit` fits a URDF robot's links, `robot check` checks joint configurations
    /// against a planning scene (collides, world / self, minimum distance), offline.
    Robot(cli::robot::RobotArgs),
    /// Point clouds on a running server: `cloud load` sends a sensor file (.pcd, .ply, depth .png)
    /// as a scene's point-cloud obstacle, `cloud bench` measures updates and soaks the server.
    Cloud(cli::cloud::CloudArgs),
}

fn main() -> std::process::ExitCode {
    // One OpenBLAS thread per SDP solve unless OPENBLAS_NUM_THREADS says otherwise (its workers
    // spin in the kernel on these small solves; see `sublevel_core::blas`).
    sublevel_core::blas::init_blas_threads();
    // Parsed through the matches, so that `serve --config` can tell a flag or variable from a default.
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let result = match cli.command {
        Command::Serve(a) => cli::serve_config::prepare(a, matches.subcommand_matches("serve"))
            .and_then(|a| a.map_or(Ok(()), cli::serve::run)),
        Command::Fit(a) => cli::fit::run(a),
        Command::Group(a) => cli::group::run(a),
        Command::Primitive(a) => cli::primitive::run(a),
        Command::Query(a) => cli::query::run(a),
        Command::Loadtest(a) => cli::loadtest::run(a),
        Command::Health(a) => cli::health::run(a),
        Command::ShardProbe(a) => cli::shard_probe::run(a),
        Command::Scene(a) => cli::scene::run(a),
        Command::Robot(a) => cli::robot::run(a),
        Command::Cloud(a) => cli::cloud::run(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// Every subcommand's arguments are well formed (unique names, groups, env vars): clap checks
    /// this only when a command is built, i.e. at the first run of that subcommand.
    #[test]
    fn every_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }
}
