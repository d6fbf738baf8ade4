//! `sublevel-lab primitives`: the exact primitives' distance queries beside coal 3.0.3 on the same
//! cases (`scripts/peers/coal_primitives.py` writes them; `crates/query/tests/data/coal_primitives.csv`
//! holds 150 per pair type), and a fitted 2d = 6 body against a box beside the same body against
//! the body the box bounds.
//!
//! ```text
//! cargo run --release -p sublevel-lab -- primitives [--cases FILE.csv] [--coal]
//! ```
//!
//! Per pair type: the median over cases of the mean time of a cold distance query (no warm start),
//! of a warm one along coal's motion (B moves 1 mm and turns 0.5 mrad per step about fixed world
//! axes, 50 steps, each query warm-started from the last), and the worst disagreement with coal's
//! distance on the separated cases. `--coal` runs `scripts/peers/coal_primitives.sh` on the same
//! file in the same run and prints the ratios ours / coal's.

mod cases;

use crate::bench::median;
pub use cases::{load_cases, pair_shapes, Case};
use std::collections::BTreeMap;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_core::primitive::{Primitive, PrimitiveFile};
use sublevel_core::{Error, Result};
use sublevel_query::shape::{shape_distance, ShapeRef, ShapeWarmStart};
use sublevel_query::{distance, NewtonParams};

/// Arguments of `sublevel-lab primitives`.
#[derive(clap::Args, Debug)]
pub struct PrimitivesArgs {
    /// Cases: the CSV of `scripts/peers/coal_primitives.py`.
    #[arg(long, default_value = "crates/query/tests/data/coal_primitives.csv")]
    cases: PathBuf,
    /// Repetitions of each cold query and of each motion (the mean is a case's time).
    #[arg(long, default_value_t = 20)]
    reps: usize,
    /// Also run coal's timing bench on the same cases (`scripts/peers/coal_primitives.sh`) and print
    /// the ratios.
    #[arg(long)]
    coal: bool,
    /// Folder of the bundled fitted bodies (`chair_101.deg6.json`, `human_10.deg6.json`).
    #[arg(long, default_value = "tests/data")]
    bodies: PathBuf,
}

/// Timings of one pair type (nanoseconds, medians over cases).
#[derive(Clone, Copy, Debug, Default)]
struct PairTimes {
    cases: usize,
    cold_ns: Real,
    warm_ns: Real,
    worst_error: Real,
}

/// The motion of coal's warm bench: step `k` moves B by k mm along `dir` and turns it by
/// k · 0.5 mrad about `axis` (world frame).
fn motion(pose_b: &Isometry3, steps: usize) -> Vec<Isometry3> {
    let dir = Vector3::new(1.0, -2.0, 0.5).normalize();
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.3, 0.4, 1.0));
    (0..steps)
        .map(|k| {
            let turn = UnitQuaternion::from_axis_angle(&axis, k as Real * 5e-4);
            Isometry3::from_parts((pose_b.translation.vector + dir * (k as Real * 1e-3)).into(), turn * pose_b.rotation)
        })
        .collect()
}

/// Mean nanoseconds of `f` over `reps` runs.
fn mean_ns(reps: usize, mut f: impl FnMut()) -> Real {
    let t = Instant::now();
    for _ in 0..reps {
        f();
    }
    t.elapsed().as_secs_f64() * 1e9 / reps as Real
}

/// Times one side pair at one case: cold, and warm along the motion.
fn time_case(a: ShapeRef<'_>, b: ShapeRef<'_>, c: &Case, reps: usize) -> Result<(Real, Real, Real)> {
    let answer = shape_distance(a, &c.pose_a, b, &c.pose_b, None)?;
    let cold = mean_ns(reps, || {
        black_box(shape_distance(a, black_box(&c.pose_a), b, black_box(&c.pose_b), None).ok());
    });
    let path = motion(&c.pose_b, 50);
    let warm = mean_ns(reps, || {
        let mut w = ShapeWarmStart::default();
        for p in &path[1..] {
            if let Ok(r) = shape_distance(a, &c.pose_a, b, black_box(p), Some(&w)) {
                w = r.warm_start;
            }
        }
    }) / (path.len() - 1) as Real;
    let error = if c.overlapping { 0.0 } else { (answer.distance - c.distance).abs() };
    Ok((cold, warm, error))
}

/// Runs `sublevel-lab primitives`.
pub fn run(args: PrimitivesArgs) -> Result<()> {
    let cases = load_cases(&args.cases)?;
    let mut per_pair: BTreeMap<String, Vec<(Real, Real, Real)>> = BTreeMap::new();
    for c in &cases {
        let (a, b) = pair_shapes(&c.pair)?;
        let t = time_case(ShapeRef::Primitive(&a), ShapeRef::Primitive(&b), c, args.reps)?;
        per_pair.entry(c.pair.clone()).or_default().push(t);
    }
    let mut ours: BTreeMap<String, PairTimes> = BTreeMap::new();
    for (pair, v) in per_pair {
        let worst_error = v.iter().map(|t| t.2).fold(0.0, Real::max);
        let times = PairTimes {
            cases: v.len(),
            cold_ns: median(v.iter().map(|t| t.0).collect()),
            warm_ns: median(v.iter().map(|t| t.1).collect()),
            worst_error,
        };
        ours.insert(pair, times);
    }
    let coal = if args.coal { coal_times(&args.cases)? } else { BTreeMap::new() };
    println!(
        "{:>20} {:>6} {:>9} {:>9} {:>9} {:>9} {:>8} {:>8} {:>12}",
        "pair", "cases", "cold ns", "warm ns", "coal cold", "coal warm", "cold ×", "warm ×", "max |Δd| m"
    );
    for (pair, t) in &ours {
        let (cc, cw) = coal.get(pair).copied().unwrap_or((Real::NAN, Real::NAN));
        println!(
            "{pair:>20} {:>6} {:>9.0} {:>9.0} {:>9.0} {:>9.0} {:>8.2} {:>8.2} {:>12.1e}",
            t.cases,
            t.cold_ns,
            t.warm_ns,
            cc,
            cw,
            t.cold_ns / cc,
            t.warm_ns / cw,
            t.worst_error
        );
    }
    body_against_box(&args, &cases)
}

/// coal's cold and warm medians per pair from `scripts/peers/coal_primitives.sh` on `cases`.
fn coal_times(cases: &std::path::Path) -> Result<BTreeMap<String, (Real, Real)>> {
    let out = std::process::Command::new("bash").arg("scripts/peers/coal_primitives.sh").arg(cases).output()?;
    if !out.status.success() {
        return Err(Error::Numerical(format!(
            "scripts/peers/coal_primitives.sh failed: {}",
            String::from_utf8_lossy(&out.stderr)
        )));
    }
    let mut times = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let v: serde_json::Value = serde_json::from_str(line)?;
        if let (Some(pair), Some(cold), Some(warm)) = (v["pair"].as_str(), v["cold_ns"].as_f64(), v["warm_ns"].as_f64())
        {
            times.insert(pair.to_string(), (cold, warm));
        }
    }
    Ok(times)
}

/// The chair fitted at 2d = 6 against the human fitted at 2d = 6 and against the box that bounds
/// the human (its axis-aligned box from the body's support function), at the same poses: the
/// cost of a box in a scene next to the cost of a fitted body there.
fn body_against_box(args: &PrimitivesArgs, cases: &[Case]) -> Result<()> {
    let chair = Body::load(&args.bodies.join("chair_101.deg6.json"))?;
    let human = Body::load(&args.bodies.join("human_10.deg6.json"))?;
    let (lo, hi) = bounding_box(&human)?;
    let boxed = Primitive::from_file(&PrimitiveFile::Box { size: (hi - lo).into() })?;
    let box_pose = Isometry3::translation(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), 0.5 * (lo.z + hi.z));
    // The chair at the cases' A poses scaled out to the bodies' size (~1.6 m): mostly separated.
    let poses: Vec<Isometry3> = cases
        .iter()
        .step_by(5)
        .map(|c| Isometry3::from_parts((c.pose_b.translation.vector * 4.0).into(), c.pose_b.rotation))
        .collect();
    let params = NewtonParams::DEFAULT;
    let mut body_times = Vec::new();
    let mut box_times = Vec::new();
    for p in &poses {
        body_times.push(mean_ns(args.reps, || {
            black_box(distance(&chair, black_box(p), &human, &Isometry3::identity(), None, &params));
        }));
        box_times.push(mean_ns(args.reps, || {
            black_box(
                shape_distance(ShapeRef::Body(&chair), black_box(p), ShapeRef::Primitive(&boxed), &box_pose, None).ok(),
            );
        }));
    }
    let (body, boxes) = (median(body_times), median(box_times));
    println!(
        "2d = 6 chair, {} poses, cold: against the human body {body:.0} ns, against its bounding box {boxes:.0} ns (× {:.2})",
        poses.len(),
        boxes / body
    );
    Ok(())
}

/// The axis-aligned bounding box (lower, upper corners, meters) of a body from its support points
/// along ±x, ±y, ±z.
fn bounding_box(body: &Body) -> Result<(Vector3, Vector3)> {
    let mut lo = Vector3::zeros();
    let mut hi = Vector3::zeros();
    for i in 0..3 {
        let e = Vector3::ith(i, 1.0);
        hi[i] = sublevel_query::penetration::support_point(body, &Isometry3::identity(), &e)?.coords[i];
        lo[i] = sublevel_query::penetration::support_point(body, &Isometry3::identity(), &-e)?.coords[i];
    }
    Ok((lo, hi))
}
