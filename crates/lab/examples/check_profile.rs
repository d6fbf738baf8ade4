//! Where a configuration check spends its time, on a fitted robot and the MotionBenchMaker
//! labels: the verdict with world pairs only, self pairs only, both, and the full answer with the
//! minimum distance (medians per configuration, one thread, overall and per scenario), with the
//! pairs each stage took — with one stage (`inner`: the inner balls' contact proofs, the default;
//! `spheres`: the sphere trees) off and on, each configuration timed both ways in turn, and the
//! answers that differ between the two (none expected). The mean is what a batch costs per
//! configuration.
//!
//! ```text
//! cargo run --release -p sublevel-lab --example check_profile -- \
//!     data/robots/panda/panda.robot.json data/robots/mbm_panda/scenes data/robots/mbm_panda/labels_obj.csv \
//!     [EVERY] [inner|spheres]
//! ```

use std::collections::BTreeMap;
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
    let start = Instant::now();
    let robot = FittedRobot::load(args[1].as_ref())?;
    println!("robot read in {:.3} s (sphere trees included)", start.elapsed().as_secs_f64());
    let every: usize = args.get(4).map_or(Ok(10), |s| s.parse())?;
    let stage = args.get(5).map_or("inner", String::as_str);
    if stage != "inner" && stage != "spheres" {
        return Err(format!("the stage is inner or spheres, got {stage:?}").into());
    }
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
        // Two checkers per scene, the sphere stage off and on, timed on the same configuration
        // one after the other (the same run, the same machine state).
        let mut times = [Vec::new(), Vec::new()];
        let mut by_scenario: BTreeMap<String, [Vec<Real>; 2]> = BTreeMap::new();
        let mut counts = [[0usize; 5]; 2];
        let mut disagree = 0;
        let mut current = None;
        let mut checkers = None;
        let mut scene_keep;
        for (row, (scenario, scene, q)) in rows.iter().enumerate() {
            if current != Some((scenario.clone(), *scene)) {
                let path = format!("{}/{scenario}/scene{scene:04}.yaml", args[2]);
                scene_keep = PlanningScene::from_yaml(&std::fs::read(path)?)?;
                let (mut world, _) = world_objects(&scene_keep)?;
                if name == "verdict, self only" {
                    world.clear();
                }
                let allowed = allowed_override(&scene_keep);
                let mut off = RobotChecker::new(&robot, world.clone(), &allowed)?;
                if stage == "inner" {
                    off.set_contact_proofs(false);
                } else {
                    off.set_sphere_stage(false);
                }
                checkers = Some([off, RobotChecker::new(&robot, world, &allowed)?]);
                current = Some((scenario.clone(), *scene));
            }
            let cs = checkers.as_mut().ok_or("no checker")?;
            let mut answers = [None, None];
            // Alternate which goes first: the second finds the caches warm.
            let turns = if row % 2 == 0 { [0, 1] } else { [1, 0] };
            for k in turns {
                let c = &mut cs[k];
                let t = Instant::now();
                let a = c.check(q, &Isometry3::identity(), &options)?;
                let us = t.elapsed().as_nanos() as Real / 1e3;
                times[k].push(us);
                by_scenario.entry(scenario.clone()).or_default()[k].push(us);
                counts[k][0] += a.pairs_pruned;
                counts[k][1] += a.pairs_spheres;
                counts[k][2] += a.pairs_model;
                counts[k][3] += a.pairs_exact;
                counts[k][4] += a.pairs_proved;
                answers[k] = Some(a);
            }
            let (Some(a), Some(b)) = (&answers[0], &answers[1]) else { continue };
            let same_distance = !options.distance || a.distance == b.distance || (a.distance - b.distance).abs() < 1e-9;
            if a.world != b.world || a.self_collision != b.self_collision || !same_distance {
                disagree += 1;
            }
        }
        let n = rows.len() as Real;
        for (k, state) in ["off", "on "].iter().enumerate() {
            let t = &mut times[k];
            let mean = t.iter().sum::<Real>() / n;
            t.sort_by(Real::total_cmp);
            println!(
                "{name:24} {stage} {state} median {:7.2} µs  mean {:7.2} µs  p90 {:7.2} µs  per configuration: {:.2} pairs by balls/boxes, {:.2} by sphere trees, {:.3} proved by inner balls, {:.2} sos solves, {:.2} on the meshes",
                t[t.len() / 2],
                mean,
                t[t.len() * 9 / 10],
                counts[k][0] as Real / n,
                counts[k][1] as Real / n,
                counts[k][4] as Real / n,
                counts[k][2] as Real / n,
                counts[k][3] as Real / n
            );
        }
        println!("{name:24} answers that differ with the stage on: {disagree}");
        for (scenario, t) in &mut by_scenario {
            let [off, on] = t;
            off.sort_by(Real::total_cmp);
            on.sort_by(Real::total_cmp);
            let mean = |t: &[Real]| t.iter().sum::<Real>() / t.len() as Real;
            println!(
                "    {scenario:18} median off {:7.2} µs  on {:7.2} µs   mean off {:7.2} µs  on {:7.2} µs",
                off[off.len() / 2],
                on[on.len() / 2],
                mean(off),
                mean(on)
            );
        }
    }
    Ok(())
}
