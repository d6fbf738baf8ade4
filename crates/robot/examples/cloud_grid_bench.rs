//! Times a point cloud's gap grid: the build, radius queries and block checks of the fitted Panda
//! against a shelf-like cloud, alone and with two far points (±9.9e5 m on every axis) that
//! stretch the cloud's box, and the memory of a two-point frame with its points 10 m apart.
//!
//! ```text
//! cargo run --release -p sublevel-robot --example cloud_grid_bench [-- ROUNDS [FAR_ROUNDS [SCATTER]]]
//! ```
//!
//! Prints one line per case: points, memory (bytes), build (ms), radius queries (ns each), block
//! checks of 300 configurations (µs per configuration); each time the thread's time on the CPU
//! (Linux's schedstat, so that other processes' load counts less; it advances by scheduler ticks,
//! so each round repeats the queries 5 times and the checks 10 times), the median of ROUNDS rounds
//! (default 5), FAR_ROUNDS (default 1) for the cloud with the far points; SCATTER (default 0)
//! random points added in the robot's workspace.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::sync::Arc;
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real, Vector3};
use sublevel_robot::{CheckOptions, FittedRobot, PointCloud, RobotChecker, WorldObject};

/// Points on the faces of a shelf's boards and a post at about `spacing` (meters), and `scatter`
/// random points in the robot's workspace (the cloud of `tests/cloud.rs`).
fn shelf_cloud(rng: &mut ChaCha8Rng, spacing: Real, scatter: usize) -> Vec<[Real; 3]> {
    let boxes = [
        (Vector3::new(0.55, 0.0, 0.4), Vector3::new(0.15, 0.4, 0.01)),
        (Vector3::new(0.55, 0.0, 0.8), Vector3::new(0.15, 0.4, 0.01)),
        (Vector3::new(0.7, 0.0, 0.6), Vector3::new(0.01, 0.4, 0.2)),
        (Vector3::new(0.35, -0.35, 0.3), Vector3::new(0.03, 0.03, 0.3)),
    ];
    let mut points = Vec::new();
    for (c, h) in boxes {
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let (nu, nv) = ((2.0 * h[u] / spacing).ceil() as usize, (2.0 * h[v] / spacing).ceil() as usize);
            for side in [-1.0, 1.0] {
                for i in 0..=nu {
                    for j in 0..=nv {
                        let mut p = c;
                        p[axis] += side * h[axis];
                        p[u] += -h[u] + 2.0 * h[u] * i as Real / nu as Real + rng.random_range(-0.003..0.003);
                        p[v] += -h[v] + 2.0 * h[v] * j as Real / nv as Real + rng.random_range(-0.003..0.003);
                        points.push([p.x, p.y, p.z]);
                    }
                }
            }
        }
    }
    for _ in 0..scatter {
        points.push([rng.random_range(-0.8..0.8), rng.random_range(-0.8..0.8), rng.random_range(0.0..1.2)]);
    }
    points
}

/// The calling thread's time on the CPU (seconds), from `/proc/thread-self/schedstat` (Linux);
/// the wall clock's elapsed time where it cannot be read.
fn cpu_seconds(wall: &Instant) -> Real {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .map_or_else(|| wall.elapsed().as_secs_f64(), |ns| ns as Real * 1e-9)
}

/// The median of `v` (NaN when empty).
fn median(mut v: Vec<Real>) -> Real {
    v.sort_by(Real::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(Real::NAN)
}

fn main() {
    let count = |k: usize, default: usize| std::env::args().nth(k).map_or(default, |s| s.parse().expect("a count"));
    let (rounds, far_rounds, scatter) = (count(1, 5), count(2, 1), count(3, 0));
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.robot.json");
    let robot = FittedRobot::load(&path).expect("the fitted Panda");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let shelf = shelf_cloud(&mut rng, 0.02, scatter);
    let mut far = shelf.clone();
    far.push([9.9e5; 3]);
    far.push([-9.9e5; 3]);
    // Query centers in the workspace and radii up to the grid's reach; configurations within the
    // joint limits.
    let queries: Vec<(Vector3, Real)> = (0..200_000)
        .map(|_| {
            let x = Vector3::new(rng.random_range(-0.8..0.8), rng.random_range(-0.8..0.8), rng.random_range(0.0..1.2));
            (x, rng.random_range(0.0..0.1))
        })
        .collect();
    let configs: Vec<Real> = (0..300)
        .flat_map(|_| {
            (0..robot.model.dof())
                .map(|k| {
                    let (lo, hi) = robot.model.variable_joint(k).limits.unwrap_or((-PI, PI));
                    rng.random_range(lo..=hi)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let options = CheckOptions { padding: 0.0, distance: false, self_collision: false, gradient: false };
    let base = Isometry3::identity();
    let epoch = Instant::now();
    let clock = || cpu_seconds(&epoch);
    println!("case\tpoints\tmemory_bytes\tbuild_ms\tquery_ns\tblock_us_per_config\tcolliding");
    for (name, points, rounds) in [("shelf", &shelf, rounds), ("shelf+far", &far, far_rounds)] {
        let (mut build, mut query, mut block) = (Vec::new(), Vec::new(), Vec::new());
        let (mut memory, mut hits, mut colliding) = (0, 0, 0);
        for _ in 0..rounds {
            let t = clock();
            let cloud = Arc::new(PointCloud::new(points.clone(), 0.01).expect("a valid cloud"));
            build.push((clock() - t) * 1e3);
            memory = cloud.memory_bytes();
            let t = clock();
            for _ in 0..5 {
                hits = queries.iter().filter(|(x, r)| cloud.any_within(x, *r)).count();
            }
            query.push((clock() - t) * 1e9 / (5 * queries.len()) as Real);
            let world = vec![WorldObject::points("camera", cloud, Isometry3::identity())];
            let mut checker = RobotChecker::new(&robot, world, &|_, _| None).expect("a checker");
            let mut lanes = Vec::new();
            let t = clock();
            for _ in 0..10 {
                lanes.clear();
                checker.check_block(&configs, &base, &options, false, &mut lanes).expect("block check");
            }
            block.push((clock() - t) * 1e6 / 3000.0);
            colliding = lanes.iter().filter(|a| a.world).count();
        }
        println!(
            "{name}\t{}\t{memory}\t{:.2}\t{:.1}\t{:.2}\t{colliding} (queries within: {hits})",
            points.len(),
            median(build),
            median(query),
            median(block),
        );
    }
    // Two points 10 m apart: the memory of the frame.
    let pair = PointCloud::new(vec![[0.0; 3], [10.0, 10.0, 10.0]], 0.01).expect("a valid cloud");
    println!("two points 10 m apart: {} bytes", pair.memory_bytes());
}
