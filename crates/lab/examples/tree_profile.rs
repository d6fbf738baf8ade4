//! Profiling driver for compound (tree) distance queries: chair_101 against human_10
//! (data/compound), the cold poses and the warm motion of `sublevel-lab bench` /
//! `sublevel-lab chart speed-accuracy` (seed 7); prints median cold and warm times per query and
//! the work per query (node pairs solved, pairs pruned by cheap bounds, leaf pairs solved). Run it
//! from the repository root (it reads `data/compound`):
//!
//! ```text
//! cargo build --release -p sublevel-lab --example tree_profile
//! target/release/examples/tree_profile [repeats=20] [tolerance=0] [poses=100] [motion=200] [cold|warm|both]
//! valgrind --tool=callgrind target/release/examples/tree_profile 1 0 30 30
//! ```

use rand::{Rng, SeedableRng};
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_fit::compound::CompoundBody;
use sublevel_query::tree::{tree_closer_than, tree_distance, TreeQueryParams, TreeWarmStart};

fn median(mut v: Vec<Real>) -> Real {
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        Real::NAN
    } else {
        v[v.len() / 2]
    }
}

fn mean(v: &[usize]) -> Real {
    v.iter().sum::<usize>() as Real / v.len().max(1) as Real
}

fn main() -> sublevel_core::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: usize, d: &str| args.get(k).cloned().unwrap_or_else(|| d.to_string());
    let repeats: usize = arg(1, "20").parse().unwrap_or(20);
    let tolerance: Real = arg(2, "0").parse().unwrap_or(0.0);
    let n_poses: usize = arg(3, "100").parse().unwrap_or(100);
    let n_motion: usize = arg(4, "200").parse().unwrap_or(200);
    let which = arg(5, "both");
    let dir = std::path::Path::new("data/compound");
    let chair = CompoundBody::load(&dir.join("chair_101.json"))?;
    let human = CompoundBody::load(&dir.join("human_10.json"))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let poses: Vec<Isometry3> = (0..n_poses)
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
    let axis = nalgebra::Unit::new_normalize(Vector3::new(0.2, 1.0, 0.1));
    let motion: Vec<Isometry3> = (0..n_motion.max(2))
        .map(|k| {
            let s = k as Real / (n_motion.max(2) - 1) as Real;
            let t = Vector3::new(-2.5 + 5.0 * s, 0.3, 0.1);
            Isometry3::from_parts(t.into(), UnitQuaternion::from_axis_angle(&axis, 1.5 * s))
        })
        .collect();
    let id = Isometry3::identity();
    let params = TreeQueryParams { tolerance, ..TreeQueryParams::default() };

    let (mut cold, mut pairs, mut leaves, mut pruned) = (vec![], vec![], vec![], vec![]);
    let mut overlapping = 0;
    for p in poses.iter().filter(|_| which != "warm") {
        let start = Instant::now();
        let mut r = tree_distance(&chair, p, &human, &id, None, &params)?;
        for _ in 1..repeats {
            r = std::hint::black_box(tree_distance(&chair, p, &human, &id, None, &params)?);
        }
        cold.push(start.elapsed().as_secs_f64() * 1e6 / repeats as Real);
        pairs.push(r.pairs_evaluated);
        leaves.push(r.leaf_pairs.len());
        pruned.push(r.pairs_pruned_by_spheres);
        overlapping += usize::from(r.upper <= 0.0);
    }
    println!(
        "cold: median {:.2} us; per query: {:.1} node pairs solved ({:.1} leaf pairs), {:.1} pruned by cheap bounds; {overlapping}/{} overlapping",
        median(cold),
        mean(&pairs),
        mean(&leaves),
        mean(&pruned),
        poses.len()
    );

    let (mut warm, mut pairs, mut leaves, mut pruned) = (vec![], vec![], vec![], vec![]);
    let mut state: Option<TreeWarmStart> = None;
    for (k, p) in motion.iter().enumerate().filter(|_| which != "cold") {
        let start = Instant::now();
        let mut r = tree_distance(&chair, p, &human, &id, state.as_ref(), &params)?;
        for _ in 1..repeats {
            r = std::hint::black_box(tree_distance(&chair, p, &human, &id, state.as_ref(), &params)?);
        }
        let us = start.elapsed().as_secs_f64() * 1e6 / repeats as Real;
        if k > 0 {
            warm.push(us);
            pairs.push(r.pairs_evaluated);
            leaves.push(r.leaf_pairs.len());
            pruned.push(r.pairs_pruned_by_spheres);
        }
        state = Some(r.warm_start);
    }
    let mut sorted = warm.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let q = |f: Real| sorted.get(((sorted.len() as Real - 1.0) * f) as usize).copied().unwrap_or(Real::NAN);
    let by_solves = |n: usize| median(warm.iter().zip(&leaves).filter(|(_, &l)| l == n).map(|(&t, _)| t).collect());
    let count = |n: usize| leaves.iter().filter(|&&l| l == n).count();
    println!(
        "warm quantiles 10/25/50/75/90 %: {:.2} {:.2} {:.2} {:.2} {:.2} us; median with 0/1/2 leaf solves: {:.2} ({}) {:.2} ({}) {:.2} ({})",
        q(0.1), q(0.25), q(0.5), q(0.75), q(0.9), by_solves(0), count(0), by_solves(1), count(1), by_solves(2), count(2)
    );
    println!(
        "warm: median {:.2} us; per query: {:.1} node pairs solved ({:.1} leaf pairs), {:.1} pruned by cheap bounds",
        median(warm),
        mean(&pairs),
        mean(&leaves),
        mean(&pruned)
    );

    let mut levels = vec![0usize; 8];
    let mut margin_us = vec![];
    for p in &poses {
        let start = Instant::now();
        let m = tree_closer_than(&chair, p, &human, &id, 0.05, None, &params)?;
        margin_us.push(start.elapsed().as_secs_f64() * 1e6);
        levels[m.level.min(7)] += 1;
    }
    println!("margin 0.05: median {:.2} us; level histogram {levels:?}", median(margin_us));
    Ok(())
}
