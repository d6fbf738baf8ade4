//! Profiling driver for cold queries: the chair_101 / human_10 bodies at one degree, the cold
//! poses of `sublevel-lab bench` (t ~ U[−2.5, 2.5]³, q = normalize(U[−1, 1]⁴), seed 7), each
//! distance and growth query repeated; prints the median time per query and the iteration
//! breakdown (separated vs overlapping answers). Run it from the repository root (it reads the
//! bundled bodies from `tests/data`), under `perf record -g` for the profile:
//!
//! ```text
//! cargo run --release -p sublevel-lab --example cold_profile -- 6 [repeats=200] [distance|growth|both]
//! cargo build --release -p sublevel-lab --example cold_profile
//! perf record -g target/release/examples/cold_profile 6 400 distance && perf report
//! ```
//!
//! The third argument `scales` checks and times the batch where single precision runs short (the
//! pair rescaled to 3 mm / 100 m / 1 cm and moved 1 km or 10 km from a frame's origin; see
//! `scales`), with the Newton iterations of both solvers.
//!
//! The third argument `steps` times warm starts against cold ones by the size of the pose step
//! from the warm start's answer (random steps of relative size s from each cold pose; what
//! `NewtonParams::warm_reach` is set from), and `chain` the cold poses asked in a row, each
//! warm-started from the answer at the pose before (a request of random candidate states that are
//! not marked cold).
//!
//! The third argument `warm` times the warm queries instead: the 500-step slide and turn of
//! `sublevel-lab bench` (each step's distance and growth query repeated from the previous step's warm
//! starts), so `--toggle-collect` on `distance` / `growth` profiles warm queries.
//!
//! A fifth argument `save=PATH` writes every pose's distance and growth value (one line per pose);
//! `check=PATH` compares them with such a file and fails unless every answer is within 10⁻⁹
//! relative (of max(|old|, 1 mm) for distances, of max(|old|, 1) for growth values): a change to
//! the solvers' starts or steps must not change the answers.
//!
//! With `SUBLEVEL_FLUSH_SUBNORMALS=1` (x86-64) the process runs with subnormal inputs read as zero
//! and subnormal results flushed to zero (MXCSR DAZ + FTZ): the answers stay the same, and any
//! difference in time means some code path multiplies subnormal numbers — each a microcode assist
//! of about a hundred cycles on Intel cores. Compare a run with and one without after a change to
//! the solvers: the unset payload of an `Option<f64>` that the compiler multiplies in a blended
//! branch holds whatever bits were there, which may be subnormal and then slow every query.

use rand::{Rng, SeedableRng};
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_core::Body;
use sublevel_query::{distance, growth, NewtonParams};

fn main() -> sublevel_core::Result<()> {
    if std::env::var_os("SUBLEVEL_FLUSH_SUBNORMALS").is_some() {
        sublevel_kernels::cpu::flush_subnormals();
    }
    let args: Vec<String> = std::env::args().collect();
    let degree: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let repeats: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(200);
    let which = args.get(3).map(String::as_str).unwrap_or("both");
    let answers = args.get(4).map(String::as_str).unwrap_or("");
    let dir = std::path::Path::new("tests/data");
    let chair = Body::load(&dir.join(format!("chair_101.deg{degree}.json")))?;
    let human = Body::load(&dir.join(format!("human_10.deg{degree}.json")))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let poses: Vec<Isometry3> = (0..300)
        .map(|_| {
            let t = Vector3::new(rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5), rng.random_range(-2.5..2.5));
            let q = nalgebra::Quaternion::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            Isometry3::from_parts(t.into(), UnitQuaternion::new_normalize(q))
        })
        .collect();
    let id = Isometry3::identity();
    let params = NewtonParams::default();
    if which == "warm" {
        return warm(&chair, &human, degree, repeats, &params);
    }
    if which == "batch" {
        return batch(&chair, &human, &poses, degree, repeats, &params);
    }
    if which == "scales" {
        return scales(&chair, &human, &poses, degree, repeats, &params);
    }
    if which == "steps" {
        return steps(&chair, &human, &poses, degree, repeats, &params);
    }
    if which == "chain" {
        return chain(&chair, &human, &poses, degree, repeats, &params);
    }
    let (mut sep, mut ovl, mut it_sep, mut it_ovl, mut conv) = (0usize, 0usize, 0usize, 0usize, 0usize);
    let mut hist = [0usize; 12];
    let (mut g_runs, mut g_it, mut g_hist) = (0usize, 0usize, [0usize; 12]);
    let (mut td, mut tg) = (Vec::new(), Vec::new());
    // (distance, growth value) per pose; NaN where not run.
    let mut values: Vec<(Real, Real)> = Vec::with_capacity(poses.len());
    for p in &poses {
        if which != "growth" {
            let t = Instant::now();
            let mut d = distance(&chair, p, &human, &id, None, &params);
            for _ in 1..repeats {
                d = std::hint::black_box(distance(&chair, p, &human, &id, None, &params));
            }
            td.push(t.elapsed().as_secs_f64() * 1e6 / repeats as Real);
            conv += usize::from(d.status.converged());
            hist[d.iterations.min(11)] += 1;
            if d.overlapping {
                ovl += 1;
                it_ovl += d.iterations;
            } else {
                sep += 1;
                it_sep += d.iterations;
            }
        }
        let mut value = (Real::NAN, Real::NAN);
        if which != "growth" {
            value.0 = distance(&chair, p, &human, &id, None, &params).distance;
        }
        if which != "distance" {
            let t = Instant::now();
            let mut g = growth(&chair, p, &human, &id, None, &params);
            for _ in 1..repeats {
                g = std::hint::black_box(growth(&chair, p, &human, &id, None, &params));
            }
            tg.push(t.elapsed().as_secs_f64() * 1e6 / repeats as Real);
            value.1 = g.value;
            g_runs += 1;
            g_it += g.iterations;
            g_hist[g.iterations.min(11)] += 1;
        }
        values.push(value);
    }
    println!("2d = {degree}: distance cold median {:.3} µs, growth cold median {:.3} µs", median(td), median(tg));
    println!(
        "distance: {sep} separated ({:.2} it/query), {ovl} overlapping ({:.2} it/query), converged {conv}",
        it_sep as Real / sep.max(1) as Real,
        it_ovl as Real / ovl.max(1) as Real
    );
    println!("iterations histogram (0..=10, 11+): {hist:?}");
    println!("growth: {:.2} it/query, histogram (0..=10, 11+): {g_hist:?}", g_it as Real / g_runs.max(1) as Real);
    if let Some(path) = answers.strip_prefix("save=") {
        let text: String = values.iter().map(|(d, g)| format!("{d:.17e} {g:.17e}\n")).collect();
        std::fs::write(path, text)?;
    } else if let Some(path) = answers.strip_prefix("check=") {
        let text = std::fs::read_to_string(path)?;
        let mut worst: Real = 0.0;
        let mut compared = 0usize;
        for (line, (d, g)) in text.lines().zip(&values) {
            let old: Vec<Real> = line.split_whitespace().filter_map(|v| v.parse().ok()).collect();
            let [d0, g0] = old[..] else { continue };
            for (new, old, floor) in [(*d, d0, 1e-3), (*g, g0, 1.0)] {
                if new.is_finite() && old.is_finite() {
                    worst = worst.max((new - old).abs() / old.abs().max(floor));
                    compared += 1;
                }
            }
        }
        println!("answers: {compared} compared with {path}, largest relative difference {worst:.2e}");
        assert!(worst <= 1e-9 && compared > 0, "answers changed");
    }
    Ok(())
}

/// `f` called `repeats` times (at least once): µs per call, and the last call's result.
fn timed<R>(repeats: usize, mut f: impl FnMut() -> R) -> (Real, R) {
    let t = Instant::now();
    let mut r = f();
    for _ in 1..repeats {
        r = std::hint::black_box(f());
    }
    (t.elapsed().as_secs_f64() * 1e6 / repeats.max(1) as Real, r)
}

/// One query kind solved cold and warm-started at the same poses: µs per query and Newton
/// iterations of each, and how many warm-started answers kept their warm start.
#[derive(Default)]
struct ColdWarm {
    cold: Vec<Real>,
    warm: Vec<Real>,
    cold_iterations: usize,
    warm_iterations: usize,
    warm_started: usize,
}

impl ColdWarm {
    /// One pose: the cold (µs, iterations) and the warm-started (µs, iterations, warm-started).
    fn add(&mut self, cold: (Real, usize), warm: (Real, usize, bool)) {
        self.cold.push(cold.0);
        self.cold_iterations += cold.1;
        self.warm.push(warm.0);
        self.warm_iterations += warm.1;
        self.warm_started += usize::from(warm.2);
    }

    /// Medians and means (µs), iterations per query and the warm-started count.
    fn summary(&self) -> String {
        let n = self.cold.len().max(1) as Real;
        let mean = |v: &[Real]| v.iter().sum::<Real>() / n;
        format!(
            "cold {:.3} / warm {:.3} µs, means {:.3} / {:.3} ({:.2} / {:.2} it, {} warm-started)",
            median(self.cold.clone()),
            median(self.warm.clone()),
            mean(&self.cold),
            mean(&self.warm),
            self.cold_iterations as Real / n,
            self.warm_iterations as Real / n,
            self.warm_started,
        )
    }
}

/// The cold poses asked in a row with warm starts, each from the answer at the pose before (what a
/// request of many candidate states asks when its queries are not cold: each state warm-started
/// from the last), against the same poses cold: median µs, iterations and warm-started answers.
fn chain(
    chair: &Body,
    human: &Body,
    poses: &[Isometry3],
    degree: usize,
    repeats: usize,
    params: &NewtonParams,
) -> sublevel_core::Result<()> {
    let id = Isometry3::identity();
    let (mut tally, mut worst) = (ColdWarm::default(), 0.0 as Real);
    let mut last: Option<std::sync::Arc<sublevel_query::DistanceWarmStart>> = None;
    for p in poses {
        let (tc, c) = timed(repeats, || distance(chair, p, human, &id, None, params));
        let (tw, w) = timed(repeats, || distance(chair, p, human, &id, last.as_deref(), params));
        tally.add((tc, c.iterations), (tw, w.iterations, w.warm_started));
        worst = worst.max((w.distance - c.distance).abs());
        last = Some(w.warm_start);
    }
    println!(
        "2d = {degree}, each pose warm-started from the answer at the pose before: distance {}; largest difference {worst:.1e} m",
        tally.summary()
    );
    Ok(())
}

/// Warm starts against cold starts by the size of the pose step from the warm start's answer: at
/// each cold pose, the chair moved by a random step of relative size s (translation s·L/√2 m,
/// rotation s/√2 rad, L the sum of the bodies' scales), distance and growth from the answer
/// before the step against cold: median µs and iterations per s.
fn steps(
    chair: &Body,
    human: &Body,
    poses: &[Isometry3],
    degree: usize,
    repeats: usize,
    params: &NewtonParams,
) -> sublevel_core::Result<()> {
    let id = Isometry3::identity();
    let len = chair.scale() + human.scale();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut unit = || {
        let v = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        v.normalize()
    };
    for s in [0.01, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 2.0] {
        let (mut d, mut g) = (ColdWarm::default(), ColdWarm::default());
        for p in poses {
            let step = Isometry3::from_parts(
                (unit() * (s * len / 2f64.sqrt())).into(),
                UnitQuaternion::from_scaled_axis(unit() * (s / 2f64.sqrt())),
            );
            let q = step * p;
            let d0 = distance(chair, p, human, &id, None, params);
            let g0 = growth(chair, p, human, &id, None, params);
            let (tc, c) = timed(repeats, || distance(chair, &q, human, &id, None, params));
            let (tw, w) = timed(repeats, || distance(chair, &q, human, &id, Some(&d0.warm_start), params));
            d.add((tc, c.iterations), (tw, w.iterations, w.warm_started));
            let (tc, c) = timed(repeats, || growth(chair, &q, human, &id, None, params));
            let (tw, w) = timed(repeats, || growth(chair, &q, human, &id, Some(&g0.warm_start), params));
            g.add((tc, c.iterations), (tw, w.iterations, w.warm_started));
        }
        println!("2d = {degree}, step {s:5.3}: distance {}; growth {}", d.summary(), g.summary());
    }
    Ok(())
}

/// The warm queries of `sublevel-lab bench`: the chair slides through the human while turning slowly
/// (500 steps), each step's queries repeated `repeats` times from the previous step's warm starts;
/// prints the median times and the warm-started share.
fn warm(chair: &Body, human: &Body, degree: usize, repeats: usize, params: &NewtonParams) -> sublevel_core::Result<()> {
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, 1.0, 0.1));
    let id = Isometry3::identity();
    let (mut td, mut tg, mut warm_d, mut warm_g, mut conv) = (Vec::new(), Vec::new(), 0usize, 0usize, 0usize);
    let (mut wd, mut wg) = (None, None);
    // Newton iterations of the warm-started answers (0..=5, 6+), distance and growth.
    let (mut hist_d, mut hist_g) = ([0usize; 7], [0usize; 7]);
    for k in 0..500 {
        let s = k as Real / 499.0;
        let pose = Isometry3::from_parts(
            Vector3::new(-2.5 + 5.0 * s, 0.3, 0.1).into(),
            UnitQuaternion::from_axis_angle(&axis, 1.5 * s),
        );
        let t = Instant::now();
        let mut d = distance(chair, &pose, human, &id, wd.as_deref(), params);
        for _ in 1..repeats {
            d = std::hint::black_box(distance(chair, &pose, human, &id, wd.as_deref(), params));
        }
        td.push(t.elapsed().as_secs_f64() * 1e6 / repeats as Real);
        let t = Instant::now();
        let mut g = growth(chair, &pose, human, &id, wg.as_deref(), params);
        for _ in 1..repeats {
            g = std::hint::black_box(growth(chair, &pose, human, &id, wg.as_deref(), params));
        }
        tg.push(t.elapsed().as_secs_f64() * 1e6 / repeats as Real);
        warm_d += usize::from(d.warm_started);
        warm_g += usize::from(g.warm_started);
        if d.warm_started {
            hist_d[d.iterations.min(6)] += 1;
        }
        if g.warm_started {
            hist_g[g.iterations.min(6)] += 1;
        }
        conv += usize::from(d.status.converged()) + usize::from(g.status.converged());
        wd = Some(d.warm_start);
        wg = Some(g.warm_start);
    }
    println!("2d = {degree}: distance warm median {:.3} µs, growth warm median {:.3} µs", median(td), median(tg));
    println!("warm-started: distance {warm_d} / 500, growth {warm_g} / 500; converged {conv} / 1000");
    println!("warm-started iterations (0..=5, 6+): distance {hist_d:?}, growth {hist_g:?}");
    Ok(())
}

/// The 300 cold poses as one batch ([`sublevel_query::batch::cold_distances`], four pairs per
/// SIMD pass; with and without warm starts) against the same poses one [`distance`] at a time:
/// `repeats` rounds, the three alternated; prints the median time per pair of each and the ratios,
/// and checks that every batch answer is the single-pair answer (distance within 10⁻⁹ m, same
/// overlap flag, converged).
fn batch(
    chair: &Body,
    human: &Body,
    poses: &[Isometry3],
    degree: usize,
    repeats: usize,
    params: &NewtonParams,
) -> sublevel_core::Result<()> {
    use sublevel_query::batch::cold_distances;
    let id = Isometry3::identity();
    let pairs: Vec<(Isometry3, Isometry3)> = poses.iter().map(|p| (*p, id)).collect();
    let singles: Vec<_> = poses.iter().map(|p| distance(chair, p, human, &id, None, params)).collect();
    let mut worst: Real = 0.0;
    for warm_starts in [true, false] {
        let batch = cold_distances(chair, human, &pairs, params, warm_starts);
        for (s, b) in singles.iter().zip(&batch) {
            assert!(b.status.converged() && s.overlapping == b.overlapping, "{s:?} vs {b:?}");
            assert!((s.witness_a - b.witness_a).norm() <= 1e-6 && (s.witness_b - b.witness_b).norm() <= 1e-6);
            worst = worst.max((s.distance - b.distance).abs());
        }
    }
    assert!(worst <= 1e-9, "batch answers differ by {worst:e} m");
    let (ms, [mw, mb]) = single_and_batch_times(chair, human, &pairs, params, repeats, [true, false]);
    let n = pairs.len() as Real;
    let batch = cold_distances(chair, human, &pairs, params, false);
    let it_s: usize = singles.iter().map(|d| d.iterations).sum();
    let it_b: usize = batch.iter().map(|d| d.iterations).sum();
    println!(
        "2d = {degree}: cold distance per pair, one at a time {ms:.3} µs; batch {mw:.3} µs with warm starts \
         ({:.2}×), {mb:.3} µs without ({:.2}× the single-query rate)",
        ms / mw,
        ms / mb
    );
    println!(
        "Newton iterations {:.2} vs {:.2} per pair; largest distance difference {worst:.1e} m",
        it_s as Real / n,
        it_b as Real / n
    );
    Ok(())
}

/// The batch where single precision runs short: the chair / human pair rescaled and moved (a
/// 3 mm chair; the chair's center 1 km from its frame's origin, posed where it was; a 100 m chair
/// against a 1.7 cm human, the poses' translations × 100; both 1 cm, the poses' translations ×
/// 0.01, and so with the chair's center 10 km from its frame's origin). Checks every batch answer
/// against the single-pair one (as `batch`) and prints the batch's rate over single queries and
/// both solvers' Newton iterations for each case.
fn scales(
    chair: &Body,
    human: &Body,
    poses: &[Isometry3],
    degree: usize,
    repeats: usize,
    params: &NewtonParams,
) -> sublevel_core::Result<()> {
    use sublevel_query::batch::cold_distances;
    let id = Isometry3::identity();
    let rescaled = |body: &Body, k: Real, shift: Vector3| {
        let c = body.center() * k + shift;
        Body::new(body.polynomial().clone(), [c.x, c.y, c.z], body.scale() * k, Default::default())
    };
    let o = Vector3::new(800.0, -500.0, 300.0);
    let moved = Isometry3::translation(-o.x, -o.y, -o.z);
    let far = Vector3::new(8000.0, -5000.0, 3000.0);
    let far_moved = Isometry3::translation(-far.x, -far.y, -far.z);
    // The cold poses with their translations × k, then moved by `m` (in the chair's frame).
    let scaled = |k: Real, m: &Isometry3| -> Vec<(Isometry3, Isometry3)> {
        poses.iter().map(|p| (Isometry3::from_parts((p.translation.vector * k).into(), p.rotation) * m, id)).collect()
    };
    let cases = [
        (
            "3 mm chair",
            rescaled(chair, 0.003, Vector3::zeros())?,
            human.clone(),
            poses.iter().map(|p| (*p, id)).collect::<Vec<_>>(),
        ),
        (
            "chair's center 1 km out",
            rescaled(chair, 1.0, o)?,
            human.clone(),
            poses.iter().map(|p| (p * moved, id)).collect(),
        ),
        (
            "100 m chair, 1.7 cm human",
            rescaled(chair, 100.0, Vector3::zeros())?,
            rescaled(human, 0.01, Vector3::zeros())?,
            scaled(100.0, &id),
        ),
        (
            "1 cm bodies",
            rescaled(chair, 0.01, Vector3::zeros())?,
            rescaled(human, 0.01, Vector3::zeros())?,
            scaled(0.01, &id),
        ),
        (
            "1 cm bodies, the chair's center 10 km from its frame's origin",
            rescaled(chair, 0.01, far)?,
            rescaled(human, 0.01, Vector3::zeros())?,
            scaled(0.01, &far_moved),
        ),
    ];
    for (name, a, b, pairs) in &cases {
        let mut worst: Real = 0.0;
        let batch = cold_distances(a, b, pairs, params, false);
        let (mut single_iterations, mut batch_iterations) = (0, 0);
        for ((pa, pb), d) in pairs.iter().zip(&batch) {
            let s = distance(a, pa, b, pb, None, params);
            assert!(d.status.converged() && s.overlapping == d.overlapping, "{name}: {s:?} vs {d:?}");
            worst = worst.max((s.distance - d.distance).abs() / (1.0 + s.distance));
            (single_iterations, batch_iterations) = (single_iterations + s.iterations, batch_iterations + d.iterations);
        }
        assert!(worst <= 1e-9, "{name}: batch answers differ by {worst:e} of 1 + the distance");
        let (ms, [mb]) = single_and_batch_times(a, b, pairs, params, repeats, [false]);
        println!(
            "2d = {degree}, {name}: cold distance per pair one at a time {ms:.3} µs, batch {mb:.3} µs ({:.2}× the \
             single-query rate); Newton iterations {single_iterations} one at a time, {batch_iterations} in the \
             batch; largest difference {worst:.1e} of 1 + the distance",
            ms / mb
        );
    }
    Ok(())
}

/// Median µs per pair of the `pairs` solved one [`distance`] at a time, and as one batch
/// ([`sublevel_query::batch::cold_distances`]) for each warm-start setting of `batches`: `repeats`
/// rounds, the runs of a round one after the other (alternated, so a slow minute slows them all).
fn single_and_batch_times<const K: usize>(
    a: &Body,
    b: &Body,
    pairs: &[(Isometry3, Isometry3)],
    params: &NewtonParams,
    repeats: usize,
    batches: [bool; K],
) -> (Real, [Real; K]) {
    let n = pairs.len() as Real;
    let (mut single, mut batch) = (Vec::new(), std::array::from_fn::<Vec<Real>, K, _>(|_| Vec::new()));
    for _ in 0..repeats {
        let t = Instant::now();
        for (pa, pb) in pairs {
            std::hint::black_box(distance(a, pa, b, pb, None, params));
        }
        single.push(t.elapsed().as_secs_f64() * 1e6 / n);
        for (times, warm_starts) in batch.iter_mut().zip(batches) {
            let t = Instant::now();
            std::hint::black_box(sublevel_query::batch::cold_distances(a, b, pairs, params, warm_starts));
            times.push(t.elapsed().as_secs_f64() * 1e6 / n);
        }
    }
    (median(single), batch.map(median))
}

/// Median of the per-pose times (NaN when none were taken, e.g. growth in `distance` mode).
fn median(mut v: Vec<Real>) -> Real {
    v.sort_by(|a, b| a.total_cmp(b));
    v.get(v.len() / 2).copied().unwrap_or(Real::NAN)
}
