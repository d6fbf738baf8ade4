//! `sublevel bench`: fit times per degree on the chair, and cold / warm query times for distance
//! and growth between the chair and the human (paper Table 2), measured side by side in one run.
//! Queries use the bundled fitted bodies (`--bodies`), so a 2d = 8 row does not need a long fit.
//!
//! Query times are medians over poses of the mean of `--repeats` back-to-back calls on the same
//! input (a warm call reuses the previous pose's warm start, so repeating it is the same work).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;
use sublevel::fit::{fit_points, mesh::load_points, FitSettings};
use sublevel::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel::query::{distance, growth, DistanceWarmStart, GrowthWarmStart, NewtonParams};
use sublevel::{Body, Error, Result};

/// The paper's Table 2: distance query times (seconds, MATLAB fmincon) at 2d = 2, 4, 6, 8.
pub const PAPER_TABLE2_SECONDS: [(usize, Real); 4] = [(2, 0.08), (4, 0.083), (6, 0.13), (8, 0.34)];

/// Arguments of `sublevel bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Folder with chair_101.off and human_10.off (the paper's shapes).
    #[arg(long, default_value = "../shared/data/psb")]
    psb: std::path::PathBuf,
    /// Degrees 2d of the query benchmark, comma separated.
    #[arg(long, default_value = "2,4,6,8", value_delimiter = ',')]
    degrees: Vec<usize>,
    /// Degrees 2d at which the chair's fit is timed (2d = 8 takes about half a minute).
    #[arg(long, default_value = "2,4,6,8", value_delimiter = ',')]
    fit_degrees: Vec<usize>,
    /// Folder of bundled fitted bodies `{chair_101,human_10}.deg{2d}.json`; a degree whose files are
    /// missing is fitted on the spot.
    #[arg(long, default_value = "tests/data")]
    bodies: std::path::PathBuf,
    /// Random pose pairs for the cold queries.
    #[arg(long, default_value_t = 500)]
    poses: usize,
    /// Steps of the smooth motion for the warm queries.
    #[arg(long, default_value_t = 500)]
    motion_steps: usize,
    /// Back-to-back calls averaged per timed query.
    #[arg(long, default_value_t = 20)]
    repeats: usize,
    /// Seed of the random poses.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Optional CSV output of the summary table.
    #[arg(long)]
    csv: Option<std::path::PathBuf>,
}

/// Median of a sample (NaN for an empty one).
pub fn median(mut v: Vec<Real>) -> Real {
    if v.is_empty() {
        return Real::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Times `f` as the mean of `repeats` back-to-back calls, in microseconds.
fn time_us<T>(repeats: usize, mut f: impl FnMut() -> T) -> (Real, T) {
    let start = Instant::now();
    let mut out = f();
    for _ in 1..repeats {
        out = std::hint::black_box(f());
    }
    (start.elapsed().as_secs_f64() * 1e6 / repeats as Real, out)
}

fn random_rotation(rng: &mut ChaCha8Rng) -> UnitQuaternion {
    let q = nalgebra::Quaternion::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    UnitQuaternion::new_normalize(q)
}

/// One row of the summary.
struct Row {
    degree: usize,
    fit_chair_s: Real,
    dist_cold: Real,
    dist_warm: Real,
    growth_cold: Real,
    growth_warm: Real,
    converged: usize,
    total: usize,
}

/// Runs `sublevel bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    let chair = load_points(&args.psb.join("chair_101.off"))?;
    let human = load_points(&args.psb.join("human_10.off"))?;
    if args.repeats == 0 {
        return Err(Error::invalid("--repeats", "must be at least 1"));
    }
    let params = NewtonParams::default();
    let mut fit_times = Vec::new();
    for &degree in &args.fit_degrees {
        let settings = FitSettings { degree, volume_samples: 20_000, ..FitSettings::default() };
        let t = Instant::now();
        let body = fit_points(&chair, &settings, &mut |_| {})?;
        let secs = t.elapsed().as_secs_f64();
        eprintln!("fit chair_101 at 2d = {degree}: {secs:.2} s, volume {:.3}", body.report.volume);
        fit_times.push((degree, secs));
    }
    let mut rows = Vec::new();
    for &degree in &args.degrees {
        let load_or_fit = |name: &str, points: &[sublevel::math::Point3]| -> Result<Body> {
            let path = args.bodies.join(format!("{name}.deg{degree}.json"));
            if path.exists() {
                return Body::load(&path);
            }
            eprintln!("{} missing: fitting {name} at 2d = {degree}", path.display());
            let settings = FitSettings { degree, volume_samples: 20_000, ..FitSettings::default() };
            fit_points(points, &settings, &mut |_| {})
        };
        let chair_body = load_or_fit("chair_101", &chair)?;
        let human_body = load_or_fit("human_10", &human)?;
        let fit_s = fit_times.iter().find(|(d, _)| *d == degree).map(|f| f.1).unwrap_or(Real::NAN);
        rows.push(bench_queries(&args, degree, &chair_body, &human_body, fit_s, &params));
    }
    print_table(&rows);
    if let Some(path) = &args.csv {
        let mut text = String::from(
            "degree,fit_chair_s,distance_cold_us,distance_warm_us,growth_cold_us,growth_warm_us,paper_s,speedup_cold,speedup_warm,converged,total\n",
        );
        for r in &rows {
            let v = r.values();
            text.push_str(&format!(
                "{},{:.4},{:.3},{:.3},{:.3},{:.3},{},{:.0},{:.0},{},{}\n",
                r.degree, v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], r.converged, r.total
            ));
        }
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        std::fs::write(path, text)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

impl Row {
    /// fit s, distance cold/warm µs, growth cold/warm µs, paper s, speed-up cold, speed-up warm.
    fn values(&self) -> [Real; 8] {
        let paper = paper_seconds(self.degree);
        [
            self.fit_chair_s,
            self.dist_cold,
            self.dist_warm,
            self.growth_cold,
            self.growth_warm,
            paper,
            paper * 1e6 / self.dist_cold,
            paper * 1e6 / self.dist_warm,
        ]
    }
}

fn paper_seconds(degree: usize) -> Real {
    PAPER_TABLE2_SECONDS.iter().find(|(d, _)| *d == degree).map(|p| p.1).unwrap_or(Real::NAN)
}

fn bench_queries(
    args: &BenchArgs,
    degree: usize,
    chair: &Body,
    human: &Body,
    fit_chair_s: Real,
    params: &NewtonParams,
) -> Row {
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let human_pose = Isometry3::identity();
    let (mut dc, mut gc) = (Vec::new(), Vec::new());
    let mut converged = 0;
    let mut total = 0;
    // Cold: random chair poses around the human (mix of separated and overlapping).
    for _ in 0..args.poses {
        let t = Vector3::new(rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5));
        let pose = Isometry3::from_parts(t.into(), random_rotation(&mut rng));
        let (us, d) = time_us(args.repeats, || distance(chair, &pose, human, &human_pose, None, params));
        dc.push(us);
        let (us, g) = time_us(args.repeats, || growth(chair, &pose, human, &human_pose, None, params));
        gc.push(us);
        converged += usize::from(d.status.converged()) + usize::from(g.status.converged());
        total += 2;
    }
    // Warm: the chair slides through the human while turning slowly (paper Fig. "penetration").
    let (mut dw, mut gw) = (Vec::new(), Vec::new());
    let mut wd: Option<DistanceWarmStart> = None;
    let mut wg: Option<GrowthWarmStart> = None;
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, 1.0, 0.1));
    let n = args.motion_steps.max(2);
    for k in 0..n {
        let s = k as Real / (n - 1) as Real;
        let t = Vector3::new(-2.5 + 5.0 * s, 0.3, 0.1);
        let pose = Isometry3::from_parts(t.into(), UnitQuaternion::from_axis_angle(&axis, 1.5 * s));
        let (us, d) = time_us(args.repeats, || distance(chair, &pose, human, &human_pose, wd.as_ref(), params));
        let (usg, g) = time_us(args.repeats, || growth(chair, &pose, human, &human_pose, wg.as_ref(), params));
        if k > 0 {
            dw.push(us);
            gw.push(usg);
        }
        converged += usize::from(d.status.converged()) + usize::from(g.status.converged());
        total += 2;
        wd = Some(d.warm_start);
        wg = Some(g.warm_start);
    }
    Row {
        degree,
        fit_chair_s,
        dist_cold: median(dc),
        dist_warm: median(dw),
        growth_cold: median(gc),
        growth_warm: median(gw),
        converged,
        total,
    }
}

fn print_table(rows: &[Row]) {
    println!("chair_101 vs human_10; query times are medians in microseconds (in-process, this machine)");
    println!(
        "{:>3} {:>9} {:>10} {:>10} {:>10} {:>10} {:>9} {:>11} {:>11} {:>10}",
        "2d", "fit chair", "dist cold", "dist warm", "grow cold", "grow warm", "paper", "x cold", "x warm", "converged"
    );
    for r in rows {
        let v = r.values();
        let fit = if v[0].is_nan() { "-".to_string() } else { format!("{:.2}s", v[0]) };
        println!(
            "{:>3} {:>9} {:>10.2} {:>10.2} {:>10.2} {:>10.2} {:>8.3}s {:>10.0}x {:>10.0}x {:>5}/{:<5}",
            r.degree, fit, v[1], v[2], v[3], v[4], v[5], v[6], v[7], r.converged, r.total
        );
    }
    println!("x cold / x warm: speed-up of our distance query over the paper's Table 2 (MATLAB fmincon).");
    println!("fit chair: `-` where the fit was not timed (--fit-degrees); the queries then use the bundled bodies.");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_samples() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(vec![]).is_nan());
    }
}
