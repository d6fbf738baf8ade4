//! `sublevel-lab bench`: fit times per degree on the chair, and cold / warm query times for distance
//! and growth between the chair and the human (paper Table 2), measured side by side in one run.
//! Queries use the bundled fitted bodies (`--bodies`), so a 2d = 8 row does not need a long fit.
//! Run it from the repository root: the default `--psb` and `--bodies` folders are relative paths.
//!
//! Query times are medians over poses of the mean of `--repeats` back-to-back calls on the same
//! input (a warm call reuses the previous pose's warm start, so repeating it is the same work).
//! The peers (parry3d-f64's GJK on the hulls, the exact mesh–mesh distance) are in
//! [`crate::peer_parry`]; the printed tables and the CSV file in [`report`].

mod report;

use crate::peer_coal::CoalFigures;
use crate::peer_parry::{error_stats, load_off_mesh, PeerShapes};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_core::{Body, Error, Result};
use sublevel_fit::{fit_points, mesh::load_points, FitSettings};
use sublevel_query::{distance, growth, DistanceWarmStart, GrowthWarmStart, NewtonParams};

/// The paper's Table 2: distance query times (seconds, MATLAB fmincon) at 2d = 2, 4, 6, 8.
pub const PAPER_TABLE2_SECONDS: [(usize, Real); 4] = [(2, 0.08), (4, 0.083), (6, 0.13), (8, 0.34)];

/// Arguments of `sublevel-lab bench`.
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
    /// Output of the coal peer script (`bash PEERS/coal/run.sh data/psb/chair_101.off
    /// data/psb/human_10.off > coal.txt`, PEERS being where the peer benchmarks are checked out;
    /// run just before on the same machine, whose speed drifts between minutes): its figures and
    /// the ratios ours / coal are printed beside ours and fill the `coal_*` / `*_over_coal` CSV
    /// columns.
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
/// spheres then the separating axis ([`sublevel_scene::planner::collide_lower_bound`]), and with
/// the planner's cheap tests (those bounds, then a common point:
/// [`sublevel_scene::planner::collide_cheap`]); the pairs the bounds cleared and those the common
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

/// Runs `sublevel-lab bench`.
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
    report::print_table(&rows, &peer);
    if let Some(c) = &coal {
        report::print_coal(&rows, c);
    }
    if let Some(path) = &args.csv {
        report::write_csv(path, &rows, &peer, coal.as_ref())?;
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
    points: &[sublevel_core::math::Point3],
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
    chair: &[sublevel_core::math::Point3],
    human: &[sublevel_core::math::Point3],
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

/// The cold distance queries at all `cold` poses one at a time ([`distance()`]) and as one batch
/// ([`sublevel_query::batch::cold_distances`], no warm starts kept: what a cold batch query of a
/// planner asks), alternated `repeats` times with the cold collide queries ([`CollideTimes`]): µs
/// per pair, medians over the rounds.
fn batch_against_single(
    repeats: usize,
    chair: &Body,
    human: &Body,
    cold: &[Isometry3],
    params: &NewtonParams,
) -> (Real, Real, CollideTimes) {
    use sublevel_scene::planner::{collide_cheap, collide_lower_bound, sphere_lower_bound, CheapCollide};
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
        std::hint::black_box(sublevel_query::batch::cold_distances(chair, human, &pairs, params, false));
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
