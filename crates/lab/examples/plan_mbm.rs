//! The MotionBenchMaker Panda problems planned in process by `sublevel-plan` (RRT-Connect,
//! simplification, every edge of the path certified by conservative advancement), one
//! [`sublevel_plan::plan`] call per problem: the table gives, per scenario, the problems solved,
//! the median wall time of a plan and of its stages, and the median path length.
//!
//! ```text
//! cargo run --release -p sublevel-lab --example plan_mbm -- [--timeout S] [--range R] [--goal-bias P] [--seed N]
//!     [--no-simplify] [--no-dynamic-domain] [--no-balance] [--shortcuts N] [--smoothing PASSES] [--padding M] [--search-margin M] [--pose-goal LINK]
//!     [--robot data/robots/panda/panda.robot.json] [--problems data/robots/mbm_panda]
//!     [--scenarios a,b,...] [--limit 10] [--fidelity mesh|bodies|spheres[:TOLERANCE]]
//! ```
//!
//! With `--pose-goal panda_hand` the goal is that link's pose at the request's joint goal (forward
//! kinematics), reached within 1 mm and 0.01 rad (inverse kinematics, then the plan); the table's
//! last column counts the paths whose last waypoint, by forward kinematics, is within them.
//!
//! Problems 1 to `--limit` of each scenario: `PROBLEMS/scenes/SCENARIO/sceneNNNN.yaml` with
//! `PROBLEMS/requests/SCENARIO/requestNNNN.yaml` (the repository's 10 per scenario), or the
//! MotionBenchMaker archive's layout, `PROBLEMS/problems/SCENARIO_panda/{scene,request}NNNN.yaml`
//! (all 100: `tar xjf data/robots/mbm_panda/problems.tar.bz2 -C /tmp`, then
//! `--problems /tmp --limit 100`).

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};
use sublevel_core::math::{Isometry3, Real};
use sublevel_plan::{plan, Goal, PlanSettings, PlanStatus, RobotValidity};
use sublevel_robot::ik::PoseGoal;
use sublevel_robot::{Fidelity, FittedRobot, MotionChecker, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};

struct Args {
    settings: PlanSettings,
    /// The goal as the end-effector link's pose (forward kinematics of the request's joint goal)
    /// instead of the joint goal: the link's name.
    pose_goal: Option<String>,
    robot: String,
    problems: String,
    scenarios: Vec<String>,
    limit: usize,
    /// The level of the search's checks (`--fidelity LEVEL[:TOLERANCE]`).
    fidelity: Fidelity,
}

fn args() -> Result<Args, String> {
    let mut a = Args {
        settings: PlanSettings::default(),
        pose_goal: None,
        robot: "data/robots/panda/panda.robot.json".into(),
        problems: "data/robots/mbm_panda".into(),
        scenarios: [
            "bookshelf_small",
            "bookshelf_tall",
            "bookshelf_thin",
            "box",
            "cage",
            "table_pick",
            "table_under_pick",
        ]
        .map(String::from)
        .to_vec(),
        limit: 10,
        fidelity: Fidelity::Mesh,
    };
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < argv.len() {
        if argv[i] == "--no-simplify" {
            a.settings.simplify = false;
            i += 1;
            continue;
        }
        if argv[i] == "--no-dynamic-domain" || argv[i] == "--no-balance" {
            if argv[i] == "--no-balance" {
                a.settings.balance = false;
            } else {
                a.settings.dynamic_domain = false;
            }
            i += 1;
            continue;
        }
        let value = argv.get(i + 1).cloned().ok_or(format!("{} needs a value", argv[i]))?;
        let number = |what: &str| value.parse::<Real>().map_err(|e| format!("{what}: {e}"));
        match argv[i].as_str() {
            "--timeout" => a.settings.timeout = Duration::from_secs_f64(number("--timeout")?),
            "--range" => a.settings.range = number("--range")?,
            "--goal-bias" => a.settings.goal_bias = number("--goal-bias")?,
            "--padding" => a.settings.padding = number("--padding")?,
            "--search-margin" => a.settings.search_margin = number("--search-margin")?,
            "--seed" => a.settings.seed = value.parse().map_err(|e| format!("--seed: {e}"))?,
            "--shortcuts" => a.settings.shortcut_attempts = value.parse().map_err(|e| format!("--shortcuts: {e}"))?,
            "--smoothing" => a.settings.smoothing_passes = value.parse().map_err(|e| format!("--smoothing: {e}"))?,
            "--robot" => a.robot = value,
            "--pose-goal" => a.pose_goal = Some(value),
            "--problems" => a.problems = value,
            "--scenarios" => a.scenarios = value.split(',').map(String::from).collect(),
            "--limit" => a.limit = value.parse().map_err(|e| format!("--limit: {e}"))?,
            "--fidelity" => {
                let (level, tolerance) = match value.split_once(':') {
                    Some((l, t)) => (l, Some(t.parse::<Real>().map_err(|e| format!("--fidelity: {e}"))?)),
                    None => (value.as_str(), None),
                };
                a.fidelity = Fidelity::parse("fidelity", level, tolerance).map_err(|e| format!("--fidelity: {e}"))?;
            }
            other => return Err(format!("unknown argument {other}")),
        }
        i += 2;
    }
    Ok(a)
}

fn median(v: &mut [Real]) -> Real {
    v.sort_by(Real::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(Real::NAN)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a = args()?;
    let robot = FittedRobot::load(a.robot.as_ref())?;
    let names: Vec<String> = robot.model.variable_names().iter().map(|n| n.to_string()).collect();
    let s = &a.settings;
    println!(
        "sublevel-plan: RRT-Connect (range {}, edges sampled at {} per unit), simplification {}, every edge certified \
         (padding {} m); timeout {:.1} s, seed {}",
        s.range,
        s.resolution,
        if s.simplify { "on" } else { "off" },
        s.padding,
        s.timeout.as_secs_f64(),
        s.seed
    );
    println!("| scenario | problems | solved | median plan (ms) | search | simplify | certify | median length | median waypoints | median certified edges | median advancement steps | median states | pose goal reached |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for scenario in &a.scenarios {
        let (mut total, mut solved, mut within) = (0, 0, 0);
        let mut columns: [Vec<Real>; 9] = Default::default();
        for k in 1..=a.limit {
            let mut scene_path = format!("{}/scenes/{scenario}/scene{k:04}.yaml", a.problems);
            let mut request_path = format!("{}/requests/{scenario}/request{k:04}.yaml", a.problems);
            if !std::path::Path::new(&scene_path).exists() {
                scene_path = format!("{}/problems/{scenario}_panda/scene{k:04}.yaml", a.problems);
                request_path = format!("{}/problems/{scenario}_panda/request{k:04}.yaml", a.problems);
            }
            let Ok(scene_bytes) = std::fs::read(&scene_path) else { continue };
            let scene = PlanningScene::from_yaml(&scene_bytes)?;
            let request = MotionPlanRequest::from_yaml(&std::fs::read(&request_path)?)?;
            let pick = |joints: &[(String, Real)]| -> Vec<Real> {
                names.iter().map(|n| joints.iter().find(|(m, _)| m == n).map_or(0.0, |(_, v)| *v)).collect()
            };
            let (start, goal) = (pick(&request.start), pick(&request.goal));
            let (world, _) = world_objects(&scene)?;
            let allowed = allowed_override(&scene);
            let mut checker = RobotChecker::new(&robot, world, &allowed)?;
            checker.set_fidelity(a.fidelity)?;
            let mut validity = RobotValidity::new(MotionChecker::new(&mut checker)?, Isometry3::identity(), s.padding);
            total += 1;
            let clock = Instant::now();
            let target = match &a.pose_goal {
                Some(link) => {
                    let l = robot.model.link_index(link).ok_or(format!("--pose-goal: no link `{link}`"))?;
                    Some((l, robot.model.link_poses(&goal, &Isometry3::identity())?[l]))
                }
                None => None,
            };
            let asked = match (&a.pose_goal, &target) {
                (Some(link), Some((_, pose))) => Goal::Pose(PoseGoal::new(link.clone(), *pose)),
                _ => Goal::Configurations(vec![goal]),
            };
            let out = plan(&mut validity, &start, &asked, s, &AtomicBool::new(false))?;
            if let (Some((l, pose)), Some(end)) = (target, out.path.last()) {
                let reached = robot.model.link_poses(end, &Isometry3::identity())?[l];
                let (dp, da) = PoseGoal::new("", pose).errors(&reached);
                within += usize::from(dp <= 1e-3 && da <= 1e-2);
            }
            let elapsed = clock.elapsed();
            if out.status != PlanStatus::Solved {
                let kind = format!("{:?}", out.status);
                eprintln!("{scenario} {k}: {}", kind.chars().take(160).collect::<String>());
            }
            if out.status == PlanStatus::Solved {
                solved += 1;
                let ms = |d: Duration| d.as_secs_f64() * 1e3;
                let t = &out.timing;
                for (c, v) in columns.iter_mut().zip([
                    ms(elapsed),
                    ms(t.search),
                    ms(t.simplify),
                    ms(t.certify),
                    out.length,
                    out.path.len() as Real,
                    out.counts.edges_certified as Real,
                    out.counts.advancement_steps as Real,
                    out.counts.states as Real,
                ]) {
                    c.push(v);
                }
            }
        }
        let [plan_ms, search, simplify, certify, length, waypoints, certified, steps, states] = &mut columns;
        println!(
            "| {scenario} | {total} | {solved} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} | {:.0} | {:.0} | {:.0} | {} |",
            median(plan_ms),
            median(search),
            median(simplify),
            median(certify),
            median(length),
            median(waypoints),
            median(certified),
            median(steps),
            median(states),
            if a.pose_goal.is_some() { within.to_string() } else { "—".into() }
        );
    }
    Ok(())
}
