//! `sublevel group A.json[@w,x,y,z,tx,ty,tz] B.json[@…] … --degree 4 --multiplier-degree 0 --output group.json`:
//! contain posed bodies with one sos-convex body (paper §V) and write its JSON body file. Progress
//! goes to stderr, a one-line summary (volume, sum of the input volumes, time) to stdout.

use std::io::Write;
use std::path::PathBuf;
use sublevel::fit::containment::{contain_bodies, ContainmentSettings};
use sublevel::fit::{volume, FitProgress};
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::{Body, Error, Result};

/// Arguments of `sublevel group`.
#[derive(clap::Args, Debug)]
pub struct GroupArgs {
    /// Body files (JSON), each optionally posed as `BODY.json@w,x,y,z,tx,ty,tz` (unit quaternion,
    /// translation in meters; identity when omitted).
    #[arg(required = true)]
    pub bodies: Vec<String>,
    /// Total degree 2d of the containing polynomial: 2, 4 or 6.
    #[arg(long, short, default_value_t = 4)]
    pub degree: usize,
    /// Degree 2k of the sos multipliers of the S-procedure: 0 (scalars) or 2.
    #[arg(long, default_value_t = 0)]
    pub multiplier_degree: usize,
    /// Where to write the body file (JSON).
    #[arg(long, short, default_value = "group.json")]
    pub output: PathBuf,
    /// Monte Carlo samples for the volume estimate.
    #[arg(long, default_value_t = 200_000)]
    pub samples: usize,
    /// Seed of the volume estimate.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Clarabel's gap and feasibility tolerance.
    #[arg(long, default_value_t = 1e-8)]
    pub tolerance: f64,
    /// No progress on stderr.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Splits `BODY.json@w,x,y,z,tx,ty,tz` into the path and the pose (identity without `@`).
fn parse_posed(k: usize, arg: &str) -> Result<(PathBuf, Isometry3)> {
    let field = format!("bodies[{k}]");
    let Some((path, pose)) = arg.rsplit_once('@').filter(|(_, p)| p.contains(',')) else {
        return Ok((PathBuf::from(arg), Isometry3::identity()));
    };
    let v: Vec<f64> = pose
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| Error::invalid(&field, format!("pose: expected 7 numbers w,x,y,z,tx,ty,tz: {e}")))?;
    if v.len() != 7 {
        return Err(Error::invalid(&field, format!("pose: expected 7 numbers w,x,y,z,tx,ty,tz, got {}", v.len())));
    }
    Ok((PathBuf::from(path), pose_from_parts(&field, [v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]])?))
}

/// The body's volume: its report's, or a Monte Carlo estimate when the report has none.
fn volume_of(body: &Body, samples: usize, seed: u64) -> Result<f64> {
    if body.report.volume > 0.0 {
        return Ok(body.report.volume);
    }
    let interior = (body.interior_point().coords - body.center()) / body.scale();
    let est = volume::monte_carlo_volume(body.polynomial(), &interior, samples, seed)?;
    Ok(est.volume * body.scale().powi(3))
}

/// Runs `sublevel group`.
///
/// # Errors
/// Whatever loading, the containment SDP or writing returns (see
/// [`sublevel::fit::containment::contain_bodies`]).
pub fn run(args: GroupArgs) -> Result<()> {
    let mut loaded = Vec::with_capacity(args.bodies.len());
    for (k, arg) in args.bodies.iter().enumerate() {
        let (path, pose) = parse_posed(k, arg)?;
        loaded.push((Body::load(&path)?, pose));
    }
    let settings = ContainmentSettings {
        degree: args.degree,
        multiplier_degree: args.multiplier_degree,
        volume_samples: args.samples,
        seed: args.seed,
        solver_tolerance: args.tolerance,
        ..ContainmentSettings::default()
    };
    let quiet = args.quiet;
    let mut stderr = std::io::stderr();
    let mut progress = |p: &FitProgress| {
        if !quiet {
            let _ = writeln!(stderr, "[{:>3.0}%] {:?}: {}", p.fraction * 100.0, p.stage, p.message);
        }
    };
    let pairs: Vec<(&Body, Isometry3)> = loaded.iter().map(|(b, p)| (b, *p)).collect();
    let body = contain_bodies(&pairs, &settings, &mut progress)?;
    body.save(&args.output)?;
    let mut inputs = 0.0;
    for (b, _) in &loaded {
        inputs += volume_of(b, args.samples, args.seed)?;
    }
    let r = &body.report;
    println!(
        "group of {}: degree {} (multipliers {}) {}, volume {:.4} ± {:.4} (sum of inputs {:.4}), solve {:.2} s, total {:.2} s -> {}",
        loaded.len(),
        body.degree(),
        args.multiplier_degree,
        r.solver_status,
        r.volume,
        r.volume_std_error,
        inputs,
        r.solve_seconds,
        r.total_seconds,
        args.output.display()
    );
    Ok(())
}
