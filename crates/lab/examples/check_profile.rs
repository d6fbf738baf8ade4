//! Where a configuration check spends its time, on a fitted robot and the MotionBenchMaker
//! labels: the verdict with world pairs only, self pairs only, both, and the full answer with the
//! minimum distance (medians per configuration, one thread), with the pairs each stage took.
//!
//! ```text
//! cargo run --release -p sublevel-lab --example check_profile -- \
//!     data/robots/panda/panda.robot.json data/robots/mbm_panda/scenes data/robots/mbm_panda/labels_obj.csv [EVERY]
//! ```

use std::time::Instant;
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{CheckOptions, FittedRobot, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, PlanningScene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!("usage: check_profile ROBOT.json SCENES_DIR LABELS.csv [EVERY] (scenes as SCENES_DIR/SCENARIO/sceneNNNN.yaml)");
        std::process::exit(2);
    }
    let robot = FittedRobot::load(args[1].as_ref())?;
    let every: usize = args.get(4).map_or(Ok(10), |s| s.parse())?;
    let text = std::fs::read_to_string(&args[3])?;
    let mut rows: Vec<(String, u32, Vec<Real>)> = Vec::new();
    for (k, line) in text.lines().skip(1).enumerate() {
        if k % every != 0 {
            continue;
        }
        let c: Vec<&str> = line.split(',').collect();
        let q = c[4..4 + robot.model.dof()].iter().map(|x| x.parse()).collect::<Result<_, _>>()?;
        rows.push((c[0].to_owned(), c[1].parse()?, q));
    }
    let variants = [
        ("verdict, world only", CheckOptions { distance: false, self_collision: false, ..Default::default() }),
        ("verdict, self only", CheckOptions { distance: false, self_collision: true, ..Default::default() }),
        ("verdict, world + self", CheckOptions { distance: false, ..Default::default() }),
        ("distance + self", CheckOptions::default()),
    ];
    for (name, options) in variants {
        let mut times = Vec::new();
        let (mut model, mut exact, mut pruned) = (0, 0, 0);
        let mut current = None;
        let mut checker = None;
        let mut scene_keep;
        for (scenario, scene, q) in &rows {
            if current != Some((scenario.clone(), *scene)) {
                let path = format!("{}/{scenario}/scene{scene:04}.yaml", args[2]);
                scene_keep = PlanningScene::from_yaml(&std::fs::read(path)?)?;
                let (mut world, _) = world_objects(&scene_keep)?;
                if name == "verdict, self only" {
                    world.clear();
                }
                let allowed = allowed_override(&scene_keep);
                checker = Some(RobotChecker::new(&robot, world, &allowed)?);
                current = Some((scenario.clone(), *scene));
            }
            let c = checker.as_mut().ok_or("no checker")?;
            let t = Instant::now();
            let a = c.check(q, &Isometry3::identity(), &options)?;
            times.push(t.elapsed().as_nanos() as Real / 1e3);
            model += a.pairs_model;
            exact += a.pairs_exact;
            pruned += a.pairs_pruned;
        }
        times.sort_by(Real::total_cmp);
        let n = rows.len() as Real;
        println!(
            "{name:24} median {:7.1} µs  p90 {:7.1} µs  per configuration: {:.2} pairs by balls, {:.2} sos solves, {:.2} on the meshes",
            times[times.len() / 2],
            times[times.len() * 9 / 10],
            pruned as Real / n,
            model as Real / n,
            exact as Real / n
        );
    }
    Ok(())
}
