//! `sublevel-lab robot-fidelity`: the fidelity dial charted, speed against wrong verdicts on the
//! mesh labels of `robot-labels` (the 14 000 MotionBenchMaker Panda configurations), one row per
//! level ([`sublevel_robot::fidelity`]): the block path's mean and median time per configuration
//! (one thread), misses (mesh collisions called free: none at any level), false collisions as a
//! share of the mesh-free configurations, and the share the lanes left to the single path. With
//! `--vamp DIR` (the robots peer's `results/` folder, run in the same hour) VAMP's point joins
//! the chart: its `path_validate_ns_per_config` and its share of missed mesh collisions.

use crate::chart::plot_points;
use crate::robot_labels::{average, evaluate, median, RobotLabelsArgs};
use std::path::PathBuf;
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};

/// Arguments of `sublevel-lab robot-fidelity`.
#[derive(clap::Args, Debug)]
pub struct RobotFidelityArgs {
    /// The labels, robot and scenes (as `robot-labels`; its `--fidelity` is replaced by each
    /// level of `--levels`).
    #[command(flatten)]
    labels: RobotLabelsArgs,
    /// The levels, comma-separated: `mesh`, `bodies`, `spheres:TOLERANCE` (meters).
    #[arg(long, default_value = "mesh,bodies,spheres:0.01,spheres:0.03,spheres:0.05,spheres:0.1,spheres:0.3")]
    levels: String,
    /// The robots peer's results folder (`vamp_check.json`, `vamp_vs_mesh_by_scenario.csv`).
    #[arg(long)]
    vamp: Option<PathBuf>,
    /// Where the chart goes (PNG).
    #[arg(long, default_value = "target/robot_fidelity.png")]
    png: PathBuf,
}

/// One point of the chart.
struct Row {
    name: String,
    mean_us: Real,
    median_us: Real,
    misses: usize,
    false_pct: Real,
    left_pct: Real,
}

/// VAMP's time per configuration (µs) and share of missed mesh collisions (%).
fn vamp_point(dir: &std::path::Path) -> Result<(Real, Real)> {
    let read = |name: &str| {
        std::fs::read_to_string(dir.join(name)).map_err(|e| Error::invalid("--vamp", format!("{name}: {e}")))
    };
    let check: serde_json::Value =
        serde_json::from_str(&read("vamp_check.json")?).map_err(|e| Error::invalid("--vamp", e.to_string()))?;
    let ns = check["path_validate_ns_per_config"]
        .as_f64()
        .ok_or_else(|| Error::invalid("--vamp", "vamp_check.json lacks path_validate_ns_per_config"))?;
    let csv = read("vamp_vs_mesh_by_scenario.csv")?;
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let column = header
        .iter()
        .position(|h| *h == "misses_pct_of_colliding")
        .ok_or_else(|| Error::invalid("--vamp", "no misses_pct_of_colliding column"))?;
    let all = lines
        .find(|l| l.starts_with("all,"))
        .ok_or_else(|| Error::invalid("--vamp", "no `all` row in vamp_vs_mesh_by_scenario.csv"))?;
    let misses = all
        .split(',')
        .nth(column)
        .and_then(|v| v.parse::<Real>().ok())
        .ok_or_else(|| Error::invalid("--vamp", "misses_pct_of_colliding is not a number"))?;
    Ok((ns / 1e3, misses))
}

/// Runs `sublevel-lab robot-fidelity`.
///
/// # Errors
/// A level that does not parse (naming `--levels`), files that cannot be read, a check that
/// fails.
pub fn run(args: RobotFidelityArgs) -> Result<()> {
    let mut rows = Vec::new();
    for level in args.levels.split(',').map(str::trim).filter(|l| !l.is_empty()) {
        let (name, tolerance) = match level.split_once(':') {
            Some((name, t)) => (
                name,
                t.parse::<Real>().map_err(|_| Error::invalid("--levels", format!("`{level}`: not a tolerance")))?,
            ),
            None => (level, 0.0),
        };
        let mut labels = args.labels.clone();
        (labels.fidelity, labels.tolerance) = (name.to_owned(), tolerance);
        let fidelity = labels.level()?;
        let tallies = evaluate(&labels)?;
        let (mut n, mut free, mut false_any, mut misses, mut left) = (0, 0, 0, 0, 0);
        let mut ns = Vec::new();
        for t in tallies.values() {
            n += t.n;
            free += t.mesh_free;
            false_any += t.false_any;
            misses += t.miss_world.max(t.miss_self);
            left += t.lanes_left;
            ns.extend(&t.verdict_ns);
        }
        let row = Row {
            name: fidelity.to_string(),
            mean_us: average(&ns) / 1e3,
            median_us: median(&mut ns) / 1e3,
            misses,
            false_pct: 100.0 * false_any as Real / free.max(1) as Real,
            left_pct: 100.0 * left as Real / n.max(1) as Real,
        };
        eprintln!("{}: mean {:.2} µs, {:.2} % false collisions", row.name, row.mean_us, row.false_pct);
        rows.push(row);
    }
    println!("| level | mean per configuration (µs) | median (µs) | misses | false collisions (% of mesh-free) | left to the single path (%) |");
    println!("|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {:.2} | {:.2} | {} | {:.2} | {:.1} |",
            r.name, r.mean_us, r.median_us, r.misses, r.false_pct, r.left_pct
        );
    }
    let mut points: Vec<(String, Real, Real, Real)> =
        rows.iter().map(|r| (r.name.clone(), r.mean_us, r.false_pct, Real::NAN)).collect();
    if let Some(dir) = &args.vamp {
        let (us, misses) = vamp_point(dir)?;
        println!("| VAMP 0.6.4 (spheres, SIMD) | {us:.3} | | {misses:.2} % of mesh collisions | | |");
        points.push((format!("VAMP ({misses:.1} % misses)"), us, misses, Real::NAN));
    }
    plot_points(
        &args.png,
        "Fidelity dial: speed against wrong verdicts (MotionBenchMaker Panda labels)",
        ("mean time per configuration, blocks of 8, one thread [µs] (log)", "wrong verdicts [%]"),
        &points,
        "Sublevel: false collisions (0 misses at every level); VAMP: misses",
    )
}
