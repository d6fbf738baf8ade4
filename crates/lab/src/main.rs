//! The `sublevel-lab` command: the paper's reproduction (`table1`, `fit-time`), benchmarks against
//! peers (`bench`), charts (`chart`), the stability suite (`stability`) and the server's start-up
//! time on a large store (`startup`), the exact primitives beside coal (`primitives`), a fitted
//! robot's checks against mesh labels (`robot-labels`) and its sampled edges (`robot-edges`).
//!
//! ```text
//! cargo run --release -p sublevel-lab -- bench --csv out/bench.csv
//! ```
//!
//! The default data paths (`data/psb`, `tests/data`) are relative to the current directory: run
//! the commands from the repository root, or name the folders.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod bench;
mod chart;
mod chart_compound;
mod csv_file;
mod fit_time;
mod peer_coal;
mod peer_parry;
mod primitives;
mod robot_cloud_bodies;
mod robot_clouds;
mod robot_edges;
mod robot_fidelity;
mod robot_labels;
mod stability;
mod startup;
mod table1;

/// The same allocator as the `sublevel` binary, so that timings match what the service does.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// Sublevel's lab: the paper's reproduction, benchmarks against peers, charts, the stability suite.
#[derive(Parser)]
#[command(name = "sublevel-lab", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Benchmark fits and queries on the paper's shapes.
    Bench(bench::BenchArgs),
    /// Run the stability suite (hard query configurations, Newton vs the SDP) and print a table.
    Stability(stability::StabilityArgs),
    /// Reproduce the paper's Table 1 (bounding volumes of the five shapes) next to its numbers.
    Table1(table1::Table1Args),
    /// Fit time against degree, log det P vs log det H (the paper's construction-time figure).
    FitTime(fit_time::FitTimeArgs),
    /// Charts: speed against accuracy per model, Newton tolerance against time and error.
    Chart(chart::ChartArgs),
    /// Start-up time of `sublevel serve` on a store of N bodies: open, listening, health, warm-up.
    Startup(startup::StartupArgs),
    /// Exact primitives' distance queries beside coal on the same cases; a body against a box.
    Primitives(primitives::PrimitivesArgs),
    /// A fitted robot's configuration checks against mesh-exact labels (misses, false
    /// collisions, distance error, time per configuration), per scenario.
    RobotLabels(robot_labels::RobotLabelsArgs),
    /// The fidelity dial charted: each level's time per configuration against its false
    /// collisions on the mesh labels, with VAMP's point.
    RobotFidelity(robot_fidelity::RobotFidelityArgs),
    /// Sampled start–goal edges of the MotionBenchMaker problems: rakes (`rake_motion`, blocks of
    /// 8) beside one sample at a time, time per checked sample.
    RobotEdges(robot_edges::RobotEdgesArgs),
    /// The MotionBenchMaker problems with each scene seen by simulated depth cameras: cloud checks
    /// against the brute force and the primitives, update times, planning with clouds.
    RobotClouds(robot_clouds::RobotCloudsArgs),
}

fn main() -> std::process::ExitCode {
    // One OpenBLAS thread per SDP solve unless OPENBLAS_NUM_THREADS says otherwise (its workers
    // spin in the kernel on these small solves; see `sublevel_core::blas`).
    sublevel_core::blas::init_blas_threads();
    let matches = Cli::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let result = match cli.command {
        Command::Bench(a) => bench::run(a),
        Command::Stability(a) => stability::run(a),
        Command::Table1(a) => table1::run(a),
        Command::FitTime(a) => fit_time::run(a),
        Command::Chart(a) => chart::run(a),
        Command::Startup(a) => startup::run(a),
        Command::Primitives(a) => primitives::run(a),
        Command::RobotLabels(a) => robot_labels::run(a),
        Command::RobotFidelity(a) => robot_fidelity::run(a),
        Command::RobotEdges(a) => robot_edges::run(a),
        Command::RobotClouds(a) => robot_clouds::run(a),
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
