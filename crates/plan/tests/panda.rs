//! The planner on the Panda among MotionBenchMaker scenes (`data/robots/mbm_panda`, the first
//! problem of each scenario): every problem solved, the path from the request's start to its goal,
//! every edge certified, and every edge re-checked independently by dense sampling on the meshes
//! (3 200 configurations per unit of joint distance, 100× the search's resolution).

use std::sync::atomic::AtomicBool;
use std::time::Duration;
use sublevel_core::math::{Isometry3, Real};
use sublevel_plan::{plan, Goal, JointSpace, PlanSettings, PlanStatus, RobotValidity};
use sublevel_robot::{CheckOptions, FittedRobot, MotionChecker, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};

fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn mbm_panda_problems_are_solved_with_certified_paths_that_dense_sampling_confirms() {
    let robot = FittedRobot::load(&root().join("data/robots/panda/panda.robot.json")).unwrap();
    let names: Vec<String> = robot.model.variable_names().iter().map(|s| s.to_string()).collect();
    for scenario in ["bookshelf_small", "box", "cage", "table_pick"] {
        let dir = root().join("data/robots/mbm_panda");
        let scene =
            PlanningScene::from_yaml(&std::fs::read(dir.join(format!("scenes/{scenario}/scene0001.yaml"))).unwrap())
                .unwrap();
        let request = MotionPlanRequest::from_yaml(
            &std::fs::read(dir.join(format!("requests/{scenario}/request0001.yaml"))).unwrap(),
        )
        .unwrap();
        let pick = |joints: &[(String, Real)]| -> Vec<Real> {
            names.iter().map(|n| joints.iter().find(|(m, _)| m == n).map_or(0.0, |(_, v)| *v)).collect()
        };
        let (start, goal) = (pick(&request.start), pick(&request.goal));
        let (world, _) = world_objects(&scene).unwrap();
        let allowed = allowed_override(&scene);
        let mut checker = RobotChecker::new(&robot, world.clone(), &allowed).unwrap();
        let mut validity = RobotValidity::new(MotionChecker::new(&mut checker).unwrap(), Isometry3::identity(), 0.0);
        let settings = PlanSettings { timeout: Duration::from_secs(20), ..PlanSettings::default() };
        let out =
            plan(&mut validity, &start, &Goal::Configurations(vec![goal.clone()]), &settings, &AtomicBool::new(false))
                .unwrap();
        assert_eq!(
            out.status,
            PlanStatus::Solved,
            "{scenario}: {:?} {:?} nodes {} path {}",
            out.timing,
            out.counts,
            out.nodes,
            out.path.len()
        );
        assert!(out.certified, "{scenario}");
        assert_eq!(out.path.first(), Some(&start));
        assert_eq!(out.path.last(), Some(&goal));
        let space = JointSpace::of(&robot.model);
        assert!(out.length >= space.distance(&start, &goal) - 1e-12);
        assert!(out.counts.edges_certified >= out.path.len() - 1);
        // Independent of the certificate: dense samples of every edge on the meshes.
        let mut dense = RobotChecker::new(&robot, world, &allowed).unwrap();
        let options = CheckOptions { distance: false, ..CheckOptions::default() };
        let mut q = Vec::new();
        for (e, w) in out.path.windows(2).enumerate() {
            let n = ((space.distance(&w[0], &w[1]) * 3200.0).ceil() as usize).max(1);
            for i in 0..=n {
                space.interpolate(&w[0], &w[1], i as Real / n as Real, &mut q);
                let answer = dense.check(&q, &Isometry3::identity(), &options).unwrap();
                assert!(!answer.collides, "{scenario}: edge {e} collides at sample {i} of {n}");
            }
        }
        eprintln!(
            "{scenario}: {} waypoints, length {:.2}, search {:?}, simplify {:?}, certify {:?}, {} repaired",
            out.path.len(),
            out.length,
            out.timing.search,
            out.timing.simplify,
            out.timing.certify,
            out.repaired
        );
    }
}
