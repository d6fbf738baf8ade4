//! `sublevel-lab stability [--data tests/data] [--pairs 4] [--csv out/stability.csv]`: the
//! stability suite of [`suite`] as a report: per case the number of queries, the share certified
//! (Newton agrees with the level-0 SDP) and flagged (answered by a verified SDP fallback), the
//! median Newton iterations and the largest error of Newton against the SDP. Run it from the
//! repository root (the default `--data` folder is a relative path).

use super::csv_file::CsvFile;
use suite::{run_case, stability_cases};

pub mod suite;
#[cfg(test)]
mod tests;
use sublevel_core::{Body, Error, Result};
use sublevel_query::CertifyParams;

/// Columns of `stability --csv`, one record per case.
pub const CSV_COLUMNS: [&str; 9] = [
    "case",
    "n",
    "certified_percent",
    "flagged_percent",
    "unresolved",
    "median_iterations",
    "max_relative_error",
    "max_abs_error_near_zero",
    "seconds",
];

/// Arguments of `sublevel-lab stability`.
#[derive(clap::Args, Debug)]
pub struct StabilityArgs {
    /// Directory of the bundled body files (`<shape>.deg<2d>.json`).
    #[arg(long, default_value = "tests/data")]
    data: std::path::PathBuf,
    /// Degrees 2d of the bodies of the main cases.
    #[arg(long, default_value = "2,4,6", value_delimiter = ',')]
    degrees: Vec<usize>,
    /// Also run the degree-8 case (seconds per certificate).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    degree8: bool,
    /// Configurations per case (each gives a distance and a growth query).
    #[arg(long, default_value_t = 4)]
    pairs: usize,
    /// Seed of the random directions and rotations.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Also write the table as CSV to this file.
    #[arg(long)]
    csv: Option<std::path::PathBuf>,
    /// Print one line per flagged or unresolved query.
    #[arg(long)]
    verbose: bool,
}

fn load_degree(dir: &std::path::Path, degree: usize) -> Result<Vec<Body>> {
    let mut out = Vec::new();
    let mut names: Vec<_> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with(&format!(".deg{degree}.json")))
        .collect();
    names.sort();
    for p in names {
        out.push(Body::load(&p)?);
    }
    Ok(out)
}

/// Runs `sublevel-lab stability`.
pub fn run(args: StabilityArgs) -> Result<()> {
    if args.pairs == 0 {
        return Err(Error::invalid("--pairs", "must be at least 1"));
    }
    let mut bodies = Vec::new();
    for d in &args.degrees {
        bodies.extend(load_degree(&args.data, *d)?);
    }
    let extra = if args.degree8 { load_degree(&args.data, 8)? } else { Vec::new() };
    if bodies.is_empty() {
        return Err(Error::invalid("--data", format!("no <shape>.deg<2d>.json bodies in {}", args.data.display())));
    }
    let cases = stability_cases(&bodies, &extra, args.pairs, args.seed)?;
    let params = CertifyParams::default();
    println!(
        "{:<38} {:>4} {:>10} {:>10} {:>10} {:>8} {:>12} {:>12} {:>8}",
        "case", "n", "certified", "flagged", "unresolved", "med.it", "max rel err", "max abs ≈0", "s"
    );
    let mut rows: Vec<[String; 9]> = Vec::new();
    let mut details = Vec::new();
    let (mut total, mut good) = (0, 0);
    for case in &cases {
        let start = std::time::Instant::now();
        let r = run_case(case, &params);
        let secs = start.elapsed().as_secs_f64();
        println!(
            "{:<38} {:>4} {:>9.1}% {:>9.1}% {:>10} {:>8.1} {:>12.2e} {:>12.2e} {:>8.2}",
            r.name,
            r.n,
            r.certified_percent(),
            r.flagged_percent(),
            r.unresolved,
            r.median_iterations,
            r.max_relative_error,
            r.max_absolute_error_near_zero,
            secs
        );
        rows.push([
            r.name.to_string(),
            r.n.to_string(),
            format!("{:.2}", r.certified_percent()),
            format!("{:.2}", r.flagged_percent()),
            r.unresolved.to_string(),
            r.median_iterations.to_string(),
            format!("{:e}", r.max_relative_error),
            format!("{:e}", r.max_absolute_error_near_zero),
            format!("{secs:.3}"),
        ]);
        total += r.n;
        good += r.certified + r.flagged;
        details.extend(r.failures);
    }
    println!("certified or flagged with a verified fallback: {good} of {total} queries");
    if args.verbose {
        for d in &details {
            println!("  {d}");
        }
    }
    if let Some(path) = &args.csv {
        let mut csv = CsvFile::create(path, &CSV_COLUMNS)?;
        for r in &rows {
            csv.record(r)?;
        }
        csv.finish()?;
    }
    Ok(())
}
