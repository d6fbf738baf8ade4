//! The verdict's cost on configurations drawn uniformly within the joint limits, as a sampling
//! planner draws them (and as `sublevel robot bench` does), split by outcome: free, colliding with
//! the world, colliding with itself only. Per outcome: how many, the mean and median time (one
//! thread), its share of the total, and the pairs that reached the meshes. The draws are seeded
//! (a fixed linear congruential generator), so the same configurations are checked in every run:
//! run it under callgrind for instruction counts that do not depend on the machine's load.
//!
//! ```text
//! cargo run --release -p sublevel-lab --example uniform_profile -- \
//!     data/robots/panda/panda.robot.json data/robots/mbm_panda/scenes/bookshelf_small/scene0001.yaml [N]
//! valgrind --tool=callgrind --toggle-collect='*RobotChecker*check*' \
//!     target/release/examples/uniform_profile ROBOT.json SCENE.yaml [N]
//! ```
//!
//! `N` configurations (default 4 000) are checked once to warm up, then once timed.

use std::time::Instant;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{CheckOptions, FittedRobot, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, PlanningScene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: uniform_profile ROBOT.json SCENE.yaml [N]");
        std::process::exit(2);
    }
    let robot = FittedRobot::load(args[1].as_ref())?;
    let scene = PlanningScene::from_yaml(&std::fs::read(&args[2])?)?;
    let n: usize = args.get(3).map_or(Ok(4000), |s| s.parse())?;
    let (world, _) = world_objects(&scene)?;
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(&robot, world, &allowed)?;
    let model = &robot.model;
    let mut state = 1u64;
    let mut next = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as Real / (1u64 << 53) as Real
    };
    let configs: Vec<Vec<Real>> = (0..n)
        .map(|_| {
            (0..model.dof())
                .map(|k| {
                    // Continuous joints (no limits) over one turn.
                    let (lo, hi) =
                        model.variable_joint(k).limits.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI));
                    lo + (hi - lo) * next()
                })
                .collect()
        })
        .collect();
    let base = Isometry3::identity();
    let options = CheckOptions { distance: false, ..Default::default() };
    for q in &configs {
        checker.check(q, &base, &options)?;
    }
    const OUTCOMES: [&str; 3] = ["free", "world", "self only"];
    let mut times: [Vec<f64>; 3] = Default::default();
    let mut exact = [0usize; 3];
    for q in &configs {
        let start = Instant::now();
        let a = checker.check(q, &base, &options)?;
        let t = start.elapsed().as_secs_f64() * 1e6;
        let k = if !a.collides {
            0
        } else if a.world {
            1
        } else {
            2
        };
        times[k].push(t);
        exact[k] += a.pairs_exact;
    }
    let total: f64 = times.iter().flatten().sum();
    println!("{n} uniform configurations, verdict (world and self), one thread:");
    for (k, name) in OUTCOMES.iter().enumerate() {
        let t = &mut times[k];
        t.sort_by(f64::total_cmp);
        let sum: f64 = t.iter().sum();
        let median = t.get(t.len() / 2).copied().unwrap_or(Real::NAN);
        println!(
            "  {name:<10} {:>6} configurations  mean {:>7.2} µs  median {:>7.2} µs  {:>5.1} % of the time  {:>5} pairs on the meshes",
            t.len(),
            sum / t.len().max(1) as f64,
            median,
            100.0 * sum / total,
            exact[k]
        );
    }
    println!("  all        mean {:.2} µs per configuration", total / n.max(1) as f64);
    Ok(())
}
