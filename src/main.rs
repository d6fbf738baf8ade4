//! The `sublevel` command: `serve`, `fit`, `query`, `bench`, `chart`.

mod cli;

/// The binary's allocator: mimalloc keeps freed pages for the next request, where glibc's arenas
/// grew and trimmed (and faulted fresh pages) on every large one: 4096 candidate states in one
/// Query took 16.8 ms of server time with glibc's allocator, 8.9 ms with its trimming turned off
/// (docs/performance-log.md, "Issue 15, fifth session").
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
    /// Run a distance or growth query between two body files.
    Query(cli::query::QueryArgs),
    /// Benchmark fits and queries on the paper's shapes.
    Bench(cli::bench::BenchArgs),
    /// Run the stability suite (hard query configurations, Newton vs the SDP) and print a table.
    Stability(cli::stability::StabilityArgs),
    /// Reproduce the paper's Table 1 (bounding volumes of the five shapes) next to its numbers.
    Table1(cli::table1::Table1Args),
    /// Fit time against degree, log det P vs log det H (the paper's construction-time figure).
    FitTime(cli::fit_time::FitTimeArgs),
    /// Charts: speed against accuracy per model, Newton tolerance against time and error.
    Chart(cli::chart::ChartArgs),
    /// Load-test a running server over gRPC: latency histograms, throughput, errors by status.
    Loadtest(cli::loadtest::LoadtestArgs),
    /// Check a server's gRPC health (exit 0 when SERVING), for container healthchecks.
    Health(cli::health::HealthArgs),
    /// Scale-out test client: set up, route, move, check and load scenes through a sharding proxy.
    ShardProbe(cli::shard_probe::ShardProbeArgs),
}

fn main() -> std::process::ExitCode {
    // Parsed through the matches, so that `serve --config` can tell a flag or variable from a default.
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let result = match cli.command {
        Command::Serve(a) => cli::serve_config::prepare(a, matches.subcommand_matches("serve"))
            .and_then(|a| a.map_or(Ok(()), cli::serve::run)),
        Command::Fit(a) => cli::fit::run(a),
        Command::Group(a) => cli::group::run(a),
        Command::Query(a) => cli::query::run(a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Stability(a) => cli::stability::run(a),
        Command::Table1(a) => cli::table1::run(a),
        Command::FitTime(a) => cli::fit_time::run(a),
        Command::Chart(a) => cli::chart::run(a),
        Command::Loadtest(a) => cli::loadtest::run(a),
        Command::Health(a) => cli::health::run(a),
        Command::ShardProbe(a) => cli::shard_probe::run(a),
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
