//! `sublevel bench`: fit times per degree on the chair, and cold / warm query times for distance
//! and growth between the chair and the human (paper Table 2), measured side by side in one run.
//! Queries use the bundled fitted bodies (`--bodies`), so a 2d = 8 row does not need a long fit.
//!
//! Query times are medians over poses of the mean of `--repeats` back-to-back calls on the same
//! input (a warm call reuses the previous pose's warm start, so repeating it is the same work).

use super::csv_file::CsvFile;
use super::peer_coal::CoalFigures;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use std::time::Instant;
use sublevel::fit::{fit_points, mesh::load_points, FitSettings};
use sublevel::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel::query::{distance, growth, DistanceWarmStart, GrowthWarmStart, NewtonParams};
use sublevel::{Body, Error, Result};

/// Columns of `bench --csv`, one record per degree (times in µs unless named `_s`; errors in
/// meters against the exact mesh–mesh distance).
/// The `coal_*` and `*_over_coal` columns come from `--peer` (empty without it): coal's medians and
/// ours / coal's GJK on the hulls (cold over cold, warm over warm; below 1 is faster than coal).
/// The last three are the batch solver ([`sublevel::query::batch::cold_distances`]): all cold
/// poses one at a time and as one batch, alternated `--repeats` times, µs per pair (medians over
/// the rounds), and single time / batch time (the batch's rate in units of the single-query rate).
/// The `collide_*` columns time a planner's cold collide query (margin 0) at all cold poses, one at
/// a time, alternated with the distance rounds: µs per pair with the bounding spheres alone before
/// the solve (`collide_cold_spheres_us`), with the planner's cheap tests
/// ([`sublevel::scene::planner::collide_cheap`]: the spheres, the separating axis, then a common
/// point; `collide_cold_us`), and how many pairs those tests decided (`collide_decided_by_bounds`,
/// the common point's included); the last two, with the spheres and the axis but no common-point
/// test (`collide_cold_bounds_only_us`), and the pairs the common point proved overlapping.
/// The `coal_*collide*` columns come from the collide peer's lines in `--peer`
/// (`scripts/peer-coal-collide`; empty without them): coal's boolean collide on the hulls, mean µs
/// per pose, narrow phase alone and behind its broad phase's world AABB test, and ours
/// (`collide_cold_us`) over the latter.
pub const CSV_COLUMNS: [&str; 40] = [
    "degree",
    "fit_chair_s",
    "distance_cold_us",
    "distance_warm_us",
    "growth_cold_us",
    "growth_warm_us",
    "paper_s",
    "speedup_cold",
    "speedup_warm",
    "converged",
    "total",
    "parry_hull_cold_us",
    "parry_hull_warm_us",
    "parry_mesh_us",
    "hull_over_ours_cold",
    "hull_over_ours_warm",
    "err_mean_m",
    "err_max_m",
    "hull_err_mean_m",
    "hull_err_max_m",
    "coal_gjk_cold_us",
    "coal_gjk_warm_us",
    "coal_nesterov_cold_us",
    "coal_nesterov_warm_us",
    "coal_mesh_us",
    "distance_cold_over_coal",
    "distance_warm_over_coal",
    "growth_cold_over_coal",
    "growth_warm_over_coal",
    "distance_cold_single_us",
    "distance_cold_batch_us",
    "batch_over_single_rate",
    "collide_cold_spheres_us",
    "collide_cold_us",
    "collide_decided_by_bounds",
    "coal_collide_cold_us",
    "coal_aabb_collide_cold_us",
    "collide_cold_over_coal",
    "collide_cold_bounds_only_us",
    "collide_touching_by_common_point",
];

/// The paper's Table 2: distance query times (seconds, MATLAB fmincon) at 2d = 2, 4, 6, 8.
pub const PAPER_TABLE2_SECONDS: [(usize, Real); 4] = [(2, 0.08), (4, 0.083), (6, 0.13), (8, 0.34)];

/// Arguments of `sublevel bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Folder with chair_101.off and human_10.off (the paper's shapes).
    #[arg(long, default_value = "data/psb")]
    psb: std::path::PathBuf,
    /// Degrees 2d of the query benchmark, comma separated.
    #[arg(long, default_value = "2,4,6,8", value_delimiter = ',')]
    degrees: Vec<usize>,
    /// Degrees 2d at which the chair's fit is timed (2d = 8 takes about half a minute); the flag
    /// without values times no fit.
    #[arg(long, default_value = "2,4,6,8", value_delimiter = ',', num_args = 0..)]
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
    /// Cold poses at which the exact mesh–mesh distance is computed (slow) for the error columns.
    #[arg(long, default_value_t = 100)]
    mesh_poses: usize,
    /// Optional CSV output of the summary table.
    #[arg(long)]
    csv: Option<std::path::PathBuf>,
    /// Output of the coal peer script (`bash ../shared/peers/coal/run.sh > coal.txt`, run just
    /// before in the same session): its figures and the ratios ours / coal are printed beside ours
    /// and fill the `coal_*` / `*_over_coal` CSV columns.
    #[arg(long)]
    peer: Option<std::path::PathBuf>,
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
pub fn time_us<T>(repeats: usize, mut f: impl FnMut() -> T) -> (Real, T) {
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

/// The random chair poses around the human of the cold queries (mix of separated and overlapping).
pub fn cold_poses(seed: u64, n: usize) -> Vec<Isometry3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let t = Vector3::new(rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5));
            Isometry3::from_parts(t.into(), random_rotation(&mut rng))
        })
        .collect()
}

/// The warm motion: the chair slides through the human while turning slowly (paper Fig. "penetration").
pub fn motion_poses(n: usize) -> Vec<Isometry3> {
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, 1.0, 0.1));
    let n = n.max(2);
    (0..n)
        .map(|k| {
            let s = k as Real / (n - 1) as Real;
            let t = Vector3::new(-2.5 + 5.0 * s, 0.3, 0.1);
            Isometry3::from_parts(t.into(), UnitQuaternion::from_axis_angle(&axis, 1.5 * s))
        })
        .collect()
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
    /// Mean / max |ours − exact mesh–mesh| over the separated ground-truth poses (meters).
    err: (Real, Real),
    /// All cold poses one at a time / as one batch (µs per pair, medians over rounds).
    single_us: Real,
    batch_us: Real,
    /// Cold collide (margin 0) at all cold poses ([`CollideTimes`]).
    collide: CollideTimes,
}

/// A planner's cold collide queries (margin 0) at all cold poses, one at a time: µs per pair
/// (medians over rounds) with the bounding spheres alone before the distance solve, with the
/// spheres then the separating axis ([`sublevel::scene::planner::collide_lower_bound`]), and with
/// the planner's cheap tests (those bounds, then a common point:
/// [`sublevel::scene::planner::collide_cheap`]); the pairs the bounds cleared and those the common
/// point proved overlapping.
#[derive(Clone, Copy, Default)]
struct CollideTimes {
    spheres_us: Real,
    axis_us: Real,
    cheap_us: Real,
    decided: usize,
    touching: usize,
    pairs: usize,
}

/// The parry3d-f64 side of the benchmark (degree-independent).
struct PeerRow {
    hull_cold: Real,
    hull_warm: Real,
    mesh: Real,
    /// Exact mesh–mesh distances at the first `exact.len()` cold poses.
    exact: Vec<Real>,
    hull_err: (Real, Real),
}

fn bench_peers(args: &BenchArgs, peers: &PeerShapes, cold: &[Isometry3], motion: &[Isometry3]) -> PeerRow {
    let human_pose = Isometry3::identity();
    let hull_cold =
        median(cold.iter().map(|p| time_us(args.repeats, || peers.hull_distance(p, &human_pose)).0).collect());
    let mut dir = parry3d_f64::math::Vector::ZERO;
    let mut hw = Vec::new();
    for (k, p) in motion.iter().enumerate() {
        let start = dir;
        let (us, _) = time_us(args.repeats, || {
            dir = start;
            peers.hull_distance_warm(p, &human_pose, &mut dir)
        });
        if k > 0 {
            hw.push(us);
        }
    }
    let n_exact = args.mesh_poses.min(cold.len());
    let mut mesh_us = Vec::new();
    let mut exact = Vec::new();
    for p in &cold[..n_exact] {
        let (us, d) = time_us(1, || peers.mesh_distance(p, &human_pose));
        mesh_us.push(us);
        exact.push(d);
    }
    let hull: Vec<Real> = cold[..n_exact].iter().map(|p| peers.hull_distance(p, &human_pose)).collect();
    PeerRow { hull_cold, hull_warm: median(hw), mesh: median(mesh_us), hull_err: error_stats(&hull, &exact), exact }
}

/// Runs `sublevel bench`.
pub fn run(args: BenchArgs) -> Result<()> {
    let chair = load_points(&args.psb.join("chair_101.off"))?;
    let human = load_points(&args.psb.join("human_10.off"))?;
    if args.repeats == 0 {
        return Err(Error::invalid("--repeats", "must be at least 1"));
    }
    let coal = args.peer.as_deref().map(CoalFigures::load).transpose()?;
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
    let cold = cold_poses(args.seed, args.poses);
    let motion = motion_poses(args.motion_steps);
    let peers = PeerShapes::new(
        &load_off_mesh(&args.psb.join("chair_101.off"))?,
        &load_off_mesh(&args.psb.join("human_10.off"))?,
    )?;
    eprintln!("timing parry3d-f64 (hull GJK, mesh–mesh on {} poses)", args.mesh_poses.min(cold.len()));
    let peer = bench_peers(&args, &peers, &cold, &motion);
    let mut rows = Vec::new();
    for &degree in &args.degrees {
        let (chair_body, human_body) = load_or_fit_pair(&args.bodies, degree, &chair, &human)?;
        let fit_s = fit_times.iter().find(|(d, _)| *d == degree).map(|f| f.1).unwrap_or(Real::NAN);
        rows.push(bench_queries(&args, degree, &chair_body, &human_body, fit_s, &params, &cold, &motion, &peer.exact));
    }
    print_table(&rows, &peer);
    if let Some(c) = &coal {
        print_coal(&rows, c);
    }
    if let Some(path) = &args.csv {
        let mut csv = CsvFile::create(path, &CSV_COLUMNS)?;
        for r in &rows {
            let v = r.values();
            csv.record([
                r.degree.to_string(),
                format!("{:.4}", v[0]),
                format!("{:.3}", v[1]),
                format!("{:.3}", v[2]),
                format!("{:.3}", v[3]),
                format!("{:.3}", v[4]),
                format!("{}", v[5]),
                format!("{:.0}", v[6]),
                format!("{:.0}", v[7]),
                r.converged.to_string(),
                r.total.to_string(),
                format!("{:.3}", peer.hull_cold),
                format!("{:.3}", peer.hull_warm),
                format!("{:.1}", peer.mesh),
                format!("{:.3}", peer.hull_cold / r.dist_cold),
                format!("{:.3}", peer.hull_warm / r.dist_warm),
                format!("{:.5}", r.err.0),
                format!("{:.5}", r.err.1),
                format!("{:.5}", peer.hull_err.0),
                format!("{:.5}", peer.hull_err.1),
                opt(coal.map(|c| c.gjk_cold_us), 3),
                opt(coal.map(|c| c.gjk_warm_us), 3),
                opt(coal.map(|c| c.nesterov_cold_us), 3),
                opt(coal.map(|c| c.nesterov_warm_us), 3),
                opt(coal.map(|c| c.mesh_us), 1),
                opt(coal.map(|c| r.dist_cold / c.gjk_cold_us), 3),
                opt(coal.map(|c| r.dist_warm / c.gjk_warm_us), 3),
                opt(coal.map(|c| r.growth_cold / c.gjk_cold_us), 3),
                opt(coal.map(|c| r.growth_warm / c.gjk_warm_us), 3),
                format!("{:.3}", r.single_us),
                format!("{:.3}", r.batch_us),
                format!("{:.3}", r.single_us / r.batch_us),
                format!("{:.3}", r.collide.spheres_us),
                format!("{:.3}", r.collide.cheap_us),
                (r.collide.decided + r.collide.touching).to_string(),
                opt(coal.map(|c| c.collide_us), 3),
                opt(coal.map(|c| c.aabb_collide_us), 3),
                opt(coal.map(|c| r.collide.cheap_us / c.aabb_collide_us), 3),
                format!("{:.3}", r.collide.axis_us),
                r.collide.touching.to_string(),
            ])?;
        }
        eprintln!("wrote {}", csv.finish()?.display());
    }
    Ok(())
}

/// The body fitted to `points` at `degree`, loaded from `{name}.deg{2d}.json` under `dir`, or
/// fitted on the spot (log det P, 20 000 volume samples) when that file is missing.
///
/// # Errors
/// Any load or fit error.
pub fn load_or_fit_body(
    dir: &std::path::Path,
    name: &str,
    degree: usize,
    points: &[sublevel::math::Point3],
) -> Result<Body> {
    let path = dir.join(format!("{name}.deg{degree}.json"));
    if path.exists() {
        return Body::load(&path);
    }
    eprintln!("{} missing: fitting {name} at 2d = {degree}", path.display());
    let settings = FitSettings { degree, volume_samples: 20_000, ..FitSettings::default() };
    fit_points(points, &settings, &mut |_| {})
}

/// The bundled chair and human bodies at `degree` ([`load_or_fit_body`] of chair_101 and
/// human_10).
///
/// # Errors
/// Any load or fit error.
pub fn load_or_fit_pair(
    dir: &std::path::Path,
    degree: usize,
    chair: &[sublevel::math::Point3],
    human: &[sublevel::math::Point3],
) -> Result<(Body, Body)> {
    Ok((load_or_fit_body(dir, "chair_101", degree, chair)?, load_or_fit_body(dir, "human_10", degree, human)?))
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

#[allow(clippy::too_many_arguments)]
fn bench_queries(
    args: &BenchArgs,
    degree: usize,
    chair: &Body,
    human: &Body,
    fit_chair_s: Real,
    params: &NewtonParams,
    cold: &[Isometry3],
    motion: &[Isometry3],
    exact: &[Real],
) -> Row {
    let human_pose = Isometry3::identity();
    let (mut dc, mut gc) = (Vec::new(), Vec::new());
    let mut converged = 0;
    let mut total = 0;
    let mut ours = Vec::new();
    for (i, pose) in cold.iter().enumerate() {
        let (us, d) = time_us(args.repeats, || distance(chair, pose, human, &human_pose, None, params));
        dc.push(us);
        if i < exact.len() {
            ours.push(d.distance);
        }
        let (us, g) = time_us(args.repeats, || growth(chair, pose, human, &human_pose, None, params));
        gc.push(us);
        converged += usize::from(d.status.converged()) + usize::from(g.status.converged());
        total += 2;
    }
    let (mut dw, mut gw) = (Vec::new(), Vec::new());
    let mut wd: Option<Arc<DistanceWarmStart>> = None;
    let mut wg: Option<Arc<GrowthWarmStart>> = None;
    for (k, pose) in motion.iter().enumerate() {
        let (us, d) = time_us(args.repeats, || distance(chair, pose, human, &human_pose, wd.as_deref(), params));
        let (usg, g) = time_us(args.repeats, || growth(chair, pose, human, &human_pose, wg.as_deref(), params));
        if k > 0 {
            dw.push(us);
            gw.push(usg);
        }
        converged += usize::from(d.status.converged()) + usize::from(g.status.converged());
        total += 2;
        wd = Some(d.warm_start);
        wg = Some(g.warm_start);
    }
    let (single_us, batch_us, collide) = batch_against_single(args.repeats, chair, human, cold, params);
    Row {
        degree,
        fit_chair_s,
        single_us,
        batch_us,
        collide,
        dist_cold: median(dc),
        dist_warm: median(dw),
        growth_cold: median(gc),
        growth_warm: median(gw),
        converged,
        total,
        err: error_stats(&ours, exact),
    }
}

/// The cold distance queries at all `cold` poses one at a time ([`distance`]) and as one batch
/// ([`sublevel::query::batch::cold_distances`], no warm starts kept: what a cold batch query of a
/// planner asks), alternated `repeats` times with the cold collide queries ([`CollideTimes`]): µs
/// per pair, medians over the rounds.
fn batch_against_single(
    repeats: usize,
    chair: &Body,
    human: &Body,
    cold: &[Isometry3],
    params: &NewtonParams,
) -> (Real, Real, CollideTimes) {
    use sublevel::scene::planner::{collide_cheap, collide_lower_bound, sphere_lower_bound, CheapCollide};
    let id = Isometry3::identity();
    let pairs: Vec<(Isometry3, Isometry3)> = cold.iter().map(|p| (*p, id)).collect();
    let n = pairs.len().max(1) as Real;
    // The planner's collide at margin 0 (`answer_pair_with`): a bound above the margin answers
    // "clear", else the cold distance solve decides.
    let collides = |p: &Isometry3, bound: Option<Real>| {
        bound.is_none_or(|lower| lower <= 0.0) && distance(chair, p, human, &id, None, params).overlapping
    };
    let spheres = |p: &Isometry3| collides(p, sphere_lower_bound(chair, p, human, &id));
    let axis = |p: &Isometry3| collides(p, collide_lower_bound(chair, p, human, &id, 0.0));
    // The planner's path (`answer_pair_with`): a cheap decision, else the solve.
    let cheap = |p: &Isometry3| match collide_cheap(chair, p, human, &id, 0.0) {
        Some(CheapCollide::Clear(_)) => false,
        Some(CheapCollide::Touching(_)) => true,
        None => distance(chair, p, human, &id, None, params).overlapping,
    };
    let decided =
        cold.iter().filter(|p| collide_lower_bound(chair, p, human, &id, 0.0).is_some_and(|l| l > 0.0)).count();
    let touching = cold
        .iter()
        .filter(|p| matches!(collide_cheap(chair, p, human, &id, 0.0), Some(CheapCollide::Touching(_))))
        .count();
    let (mut single, mut batch, mut with_spheres, mut with_axis) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut with_cheap = Vec::new();
    for _ in 0..repeats {
        let t = Instant::now();
        for p in cold {
            std::hint::black_box(spheres(p));
        }
        with_spheres.push(t.elapsed().as_secs_f64() * 1e6 / n);
        let t = Instant::now();
        for p in cold {
            std::hint::black_box(axis(p));
        }
        with_axis.push(t.elapsed().as_secs_f64() * 1e6 / n);
        let t = Instant::now();
        for p in cold {
            std::hint::black_box(cheap(p));
        }
        with_cheap.push(t.elapsed().as_secs_f64() * 1e6 / n);
        let t = Instant::now();
        for p in cold {
            std::hint::black_box(distance(chair, p, human, &id, None, params));
        }
        single.push(t.elapsed().as_secs_f64() * 1e6 / n);
        let t = Instant::now();
        std::hint::black_box(sublevel::query::batch::cold_distances(chair, human, &pairs, params, false));
        batch.push(t.elapsed().as_secs_f64() * 1e6 / n);
    }
    let collide = CollideTimes {
        spheres_us: median(with_spheres),
        axis_us: median(with_axis),
        cheap_us: median(with_cheap),
        decided,
        touching,
        pairs: cold.len(),
    };
    (median(single), median(batch), collide)
}

fn print_table(rows: &[Row], peer: &PeerRow) {
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
    for r in rows {
        println!(
            "2d = {}: cold distance at all cold poses, {:.3} µs per pair one at a time, {:.3} µs as one batch \
             (8 pairs per SIMD pass in single precision, then 4): {:.2}x the single-query rate",
            r.degree,
            r.single_us,
            r.batch_us,
            r.single_us / r.batch_us
        );
    }
    for r in rows {
        let c = &r.collide;
        println!(
            "2d = {}: cold collide (margin 0) at all cold poses, {:.3} µs per pair with the spheres, the separating axis \
             and a common point; {:.3} µs without the common point, {:.3} µs with the spheres alone ({:.2}x); the \
             bounds clear {} of {}, the common point proves {} overlapping",
            r.degree,
            c.cheap_us,
            c.axis_us,
            c.spheres_us,
            c.spheres_us / c.cheap_us,
            c.decided,
            c.pairs,
            c.touching
        );
    }
    println!();
    let n_sep = peer.exact.iter().filter(|d| **d > 0.0).count();
    println!(
        "peers (parry3d-f64, same poses): GJK on the convex hulls cold {:.2} µs, warm {:.2} µs; exact mesh–mesh {:.1} µs",
        peer.hull_cold, peer.hull_warm, peer.mesh
    );
    println!(
        "{:>8} {:>10} {:>10} {:>12} {:>12} {:>13} {:>13}",
        "model", "cold µs", "warm µs", "hull/ours c", "hull/ours w", "err mean [m]", "err max [m]"
    );
    for r in rows {
        println!(
            "{:>8} {:>10.2} {:>10.2} {:>11.2}x {:>11.2}x {:>13.4} {:>13.4}",
            format!("sos 2d={}", r.degree),
            r.dist_cold,
            r.dist_warm,
            peer.hull_cold / r.dist_cold,
            peer.hull_warm / r.dist_warm,
            r.err.0,
            r.err.1
        );
    }
    println!(
        "{:>8} {:>10.2} {:>10.2} {:>12} {:>12} {:>13.4} {:>13.4}",
        "hull GJK", peer.hull_cold, peer.hull_warm, "1.00x", "1.00x", peer.hull_err.0, peer.hull_err.1
    );
    println!(
        "{:>8} {:>10.1} {:>10} {:>12} {:>12} {:>13} {:>13}",
        "mesh", peer.mesh, "-", "-", "-", "0 (truth)", "0 (truth)"
    );
    println!(
        "errors: |model − exact mesh–mesh distance| over the {n_sep} separated poses of the first {} cold poses.",
        peer.exact.len()
    );
}

/// A CSV field: the value with `digits` decimals, empty when absent or not finite.
fn opt(v: Option<Real>, digits: usize) -> String {
    v.filter(|v| v.is_finite()).map(|v| format!("{v:.digits$}")).unwrap_or_default()
}

/// coal's figures (from `--peer`) and the ratios ours / coal's GJK on the hulls, per degree.
fn print_coal(rows: &[Row], c: &CoalFigures) {
    println!();
    println!(
        "coal 3.0.3 (--peer; hulls of {} / {} vertices): GJK cold {:.2} µs, warm {:.2} µs; Nesterov GJK cold {:.2} µs, \
         warm {:.2} µs; exact mesh–mesh (BVH) {:.1} µs",
        c.hull_vertices[0], c.hull_vertices[1], c.gjk_cold_us, c.gjk_warm_us, c.nesterov_cold_us, c.nesterov_warm_us, c.mesh_us
    );
    println!(
        "{:>8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "model", "dist cold", "/coal", "dist warm", "/coal", "grow cold", "/coal", "grow warm", "/coal"
    );
    for r in rows {
        println!(
            "{:>8} {:>10.2} {:>9.2}x {:>10.2} {:>9.2}x {:>10.2} {:>9.2}x {:>10.2} {:>9.2}x",
            format!("sos 2d={}", r.degree),
            r.dist_cold,
            r.dist_cold / c.gjk_cold_us,
            r.dist_warm,
            r.dist_warm / c.gjk_warm_us,
            r.growth_cold,
            r.growth_cold / c.gjk_cold_us,
            r.growth_warm,
            r.growth_warm / c.gjk_warm_us
        );
    }
    println!("{:>8} {:>10.2} {:>10} {:>10.2} {:>10}", "coal GJK", c.gjk_cold_us, "1.00x", c.gjk_warm_us, "1.00x");
    println!(
        "/coal: our median over coal's median GJK on the hulls (cold over cold, warm over warm); below 1 is faster. \
         Issue 15's targets: 2d = 6 cold ≤ 0.6x, warm ≤ 0.3x; 2d = 8 cold ≤ 1x."
    );
    if c.aabb_collide_us.is_nan() {
        return;
    }
    let [decided, colliding, poses] = c.collide_counts;
    println!(
        "coal collide (boolean, margin 0, mean over {poses} cold poses, {colliding} touching): narrow phase alone \
         {:.2} µs; behind its broad phase's world AABB test {:.2} µs (the AABBs decide {decided})",
        c.collide_us, c.aabb_collide_us
    );
    for r in rows {
        let k = &r.collide;
        println!(
            "2d = {}: cold collide {:.3} µs (the cheap tests decide {} of {}) = {:.2}x coal's AABB + GJK, {:.2}x its \
             narrow phase",
            r.degree,
            k.cheap_us,
            k.decided + k.touching,
            k.pairs,
            k.cheap_us / c.aabb_collide_us,
            k.cheap_us / c.collide_us
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Peer baselines (parry3d-f64) and the exact mesh–mesh ground truth, shared with `sublevel chart`.
// ---------------------------------------------------------------------------------------------

/// A triangle mesh read from an OFF file: vertices (meters) and triangles (polygons fanned).
#[derive(Debug)]
pub struct OffMesh {
    /// Vertex positions.
    pub vertices: Vec<sublevel::math::Point3>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

/// Reads an OFF mesh with its faces (polygons are split into fans) with the fit's OFF parser
/// ([`sublevel::fit::mesh::parse_off_mesh`]: the same header and limit checks).
///
/// # Errors
/// [`Error::Io`] when unreadable; [`Error::InvalidArgument`] naming `mesh` (with the path) for
/// malformed text; [`Error::ResourceExhausted`] beyond the default vertex limit.
pub fn load_off_mesh(path: &std::path::Path) -> Result<OffMesh> {
    use sublevel::fit::mesh::{parse_off_mesh, DEFAULT_MAX_MESH_POINTS};
    let mesh = parse_off_mesh(&std::fs::read(path)?, DEFAULT_MAX_MESH_POINTS).map_err(|e| match e {
        Error::InvalidArgument { field, reason } => Error::invalid(field, format!("{}: {reason}", path.display())),
        other => other,
    })?;
    Ok(OffMesh { vertices: mesh.vertices, triangles: mesh.triangles })
}

fn parry_vec(p: &sublevel::math::Point3) -> parry3d_f64::math::Vector {
    parry3d_f64::math::Vector::new(p.x, p.y, p.z)
}

/// Our pose as parry's (glam) pose.
pub fn parry_pose(iso: &Isometry3) -> parry3d_f64::math::Pose {
    let q = iso.rotation.quaternion();
    let t = iso.translation.vector;
    parry3d_f64::math::Pose::from_parts(
        parry3d_f64::math::Vector::new(t.x, t.y, t.z),
        parry3d_f64::math::Rot3::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

/// The peer shapes of one pair: convex hulls (for GJK) and the triangle meshes (exact distance).
pub struct PeerShapes {
    /// Convex hull of A's points.
    pub hull_a: parry3d_f64::shape::ConvexPolyhedron,
    /// Convex hull of B's points.
    pub hull_b: parry3d_f64::shape::ConvexPolyhedron,
    /// A's triangle mesh.
    pub mesh_a: parry3d_f64::shape::TriMesh,
    /// B's triangle mesh.
    pub mesh_b: parry3d_f64::shape::TriMesh,
}

impl PeerShapes {
    /// Builds the hulls and meshes from two OFF meshes.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `mesh` when parry rejects a hull or a mesh.
    pub fn new(a: &OffMesh, b: &OffMesh) -> Result<Self> {
        let hull = |m: &OffMesh| {
            let pts: Vec<_> = m.vertices.iter().map(parry_vec).collect();
            parry3d_f64::shape::ConvexPolyhedron::from_convex_hull(&pts)
                .ok_or_else(|| Error::invalid("mesh", "parry could not build the convex hull"))
        };
        let tri = |m: &OffMesh| {
            parry3d_f64::shape::TriMesh::new(m.vertices.iter().map(parry_vec).collect(), m.triangles.clone())
                .map_err(|e| Error::invalid("mesh", format!("parry rejected the triangle mesh: {e:?}")))
        };
        Ok(Self { hull_a: hull(a)?, hull_b: hull(b)?, mesh_a: tri(a)?, mesh_b: tri(b)? })
    }

    /// Cold GJK distance between the hulls (`parry3d_f64::query::distance`).
    pub fn hull_distance(&self, pose_a: &Isometry3, pose_b: &Isometry3) -> Real {
        parry3d_f64::query::distance(&parry_pose(pose_a), &self.hull_a, &parry_pose(pose_b), &self.hull_b)
            .map_or(Real::NAN, |d| d.distance)
    }

    /// Warm GJK distance between the hulls: the simplex starts from `dir` (A's frame, the previous
    /// closest-point difference), which is updated.
    pub fn hull_distance_warm(
        &self,
        pose_a: &Isometry3,
        pose_b: &Isometry3,
        dir: &mut parry3d_f64::math::Vector,
    ) -> Real {
        use parry3d_f64::query::gjk::{self, CsoPoint, GJKResult, VoronoiSimplex};
        let pos12 = parry_pose(pose_a).inv_mul(&parry_pose(pose_b));
        let back = -pos12.translation;
        let n = if dir.length_squared() > 1e-24 {
            dir.normalize()
        } else if back.length_squared() > 1e-24 {
            back.normalize()
        } else {
            parry3d_f64::math::Vector::X
        };
        let mut simplex = VoronoiSimplex::new();
        simplex.reset(CsoPoint::from_shapes(&pos12, &self.hull_a, &self.hull_b, n));
        match gjk::closest_points(&pos12, &self.hull_a, &self.hull_b, Real::MAX, true, &mut simplex) {
            GJKResult::ClosestPoints(p1, p2, _) => {
                *dir = p1 - p2;
                dir.length()
            }
            _ => 0.0,
        }
    }

    /// Exact distance between the triangle meshes (the ground truth).
    pub fn mesh_distance(&self, pose_a: &Isometry3, pose_b: &Isometry3) -> Real {
        parry3d_f64::query::distance(&parry_pose(pose_a), &self.mesh_a, &parry_pose(pose_b), &self.mesh_b)
            .map_or(Real::NAN, |d| d.distance)
    }
}

/// Mean and max of |model − exact| over the poses where the exact distance is positive.
pub fn error_stats(model: &[Real], exact: &[Real]) -> (Real, Real) {
    let errs: Vec<Real> = model.iter().zip(exact).filter(|(_, e)| **e > 0.0).map(|(m, e)| (m - e).abs()).collect();
    if errs.is_empty() {
        return (Real::NAN, Real::NAN);
    }
    (errs.iter().sum::<Real>() / errs.len() as Real, errs.iter().cloned().fold(0.0, Real::max))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_stats_skip_overlapping_poses() {
        let (mean, max) = error_stats(&[0.9, 2.0, 0.0], &[1.0, 2.5, 0.0]);
        assert!((mean - 0.3).abs() < 1e-12 && (max - 0.5).abs() < 1e-12);
        assert!(error_stats(&[1.0], &[0.0]).0.is_nan());
    }

    #[test]
    fn off_mesh_fans_polygons() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.off");
        std::fs::write(&path, "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n").unwrap();
        let m = load_off_mesh(&path).unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        std::fs::write(&path, "OFF\n1 1 0\n0 0 0\n3 0 1 2\n").unwrap();
        assert!(load_off_mesh(&path).unwrap_err().to_string().contains("mesh"));
    }

    #[test]
    fn median_of_odd_and_even_samples() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(vec![]).is_nan());
    }
}
