//! Where the block path spends its time: every labelled MotionBenchMaker configuration checked
//! with `check_block` in blocks of 8, `REPEATS` passes (the best pass per configuration), then the
//! configurations the lanes decided alone and those they left pairs of to the single path
//! (`RobotChecker::block_counts`), each set timed on its own. `BLOCK_PROFILE_SET=0` (or `1`) times
//! only that set after one pass over all, for a profiler.
//!
//! ```text
//! cargo run --release -p sublevel-lab --example block_profile -- \
//!     data/robots/panda/panda.robot.json data/robots/mbm_panda/scenes data/robots/mbm_panda/labels_obj.csv [REPEATS]
//! ```

use std::collections::BTreeMap;
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{CheckOptions, FittedRobot, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, PlanningScene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: block_profile ROBOT.json SCENES_DIR LABELS.csv [REPEATS]");
        std::process::exit(2);
    }
    let robot = FittedRobot::load(args[1].as_ref())?;
    let repeats: usize = args.get(4).map_or(Ok(20), |s| s.parse())?;
    let dof = robot.model.dof();
    let text = std::fs::read_to_string(&args[3])?;
    let mut scenes: BTreeMap<(String, u32), Vec<Real>> = BTreeMap::new();
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        let q: Vec<Real> = c[4..4 + dof].iter().map(|x| x.parse()).collect::<Result<_, _>>()?;
        scenes.entry((c[0].to_owned(), c[1].parse()?)).or_default().extend(q);
    }
    let mut planning = Vec::new();
    for (scenario, scene) in scenes.keys() {
        let path = format!("{}/{scenario}/scene{scene:04}.yaml", args[2]);
        planning.push(PlanningScene::from_yaml(&std::fs::read(path)?)?);
    }
    let mut checkers = Vec::new();
    for (s, q) in planning.iter().zip(scenes.values()) {
        let (world, _) = world_objects(s)?;
        checkers.push((RobotChecker::new(&robot, world, &allowed_override(s))?, q));
    }
    let options = CheckOptions { distance: false, ..Default::default() };
    let n: usize = scenes.values().map(|q| q.len() / dof).sum();
    let mut out = Vec::new();
    let mut best = Real::INFINITY;
    let mut colliding = 0;
    let only: Option<usize> = std::env::var("BLOCK_PROFILE_SET").ok().and_then(|v| v.parse().ok());
    for _ in 0..if only.is_some() { 1 } else { repeats } {
        let t = Instant::now();
        colliding = 0;
        for (checker, q) in &mut checkers {
            for block in q.chunks(8 * dof) {
                out.clear();
                checker.check_block(block, &Isometry3::identity(), &options, false, &mut out)?;
                colliding += out.iter().filter(|a| a.collides).count();
            }
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e9 / n as f64);
    }
    println!("{n} configurations, {colliding} colliding, best pass {best:.0} ns per configuration");
    // The configurations split by whether the lanes decided them alone or left pairs to the
    // single path (`block_counts`), each set timed in blocks of 8 on its own.
    let mut sets = [Vec::new(), Vec::new()];
    for (checker, q) in &mut checkers {
        let mut mine = [Vec::new(), Vec::new()];
        for row in q.chunks(dof) {
            out.clear();
            let before = checker.block_counts().1;
            checker.check_block(row, &Isometry3::identity(), &options, false, &mut out)?;
            let tail = checker.block_counts().1 > before;
            mine[usize::from(tail)].extend_from_slice(row);
        }
        for k in 0..2 {
            sets[k].push(std::mem::take(&mut mine[k]));
        }
    }
    for (k, name) in ["lanes alone", "left to the single path"].iter().enumerate() {
        if only.is_some_and(|o| o != k) {
            continue;
        }
        let count: usize = sets[k].iter().map(|q| q.len() / dof).sum();
        let mut best = Real::INFINITY;
        for _ in 0..repeats {
            let t = Instant::now();
            for ((checker, _), q) in checkers.iter_mut().zip(&sets[k]) {
                for block in q.chunks(8 * dof) {
                    out.clear();
                    checker.check_block(block, &Isometry3::identity(), &options, false, &mut out)?;
                }
            }
            best = best.min(t.elapsed().as_secs_f64() * 1e9 / count.max(1) as f64);
        }
        println!(
            "{name:24} {count:6} configurations ({:.1} %), best pass {best:.0} ns per configuration",
            100.0 * count as f64 / n as f64
        );
    }
    Ok(())
}
