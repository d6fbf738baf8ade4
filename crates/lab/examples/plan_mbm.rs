//! RRT-Connect in process on the MotionBenchMaker problems, with this library as its collision
//! checker: states by `RobotChecker::check` (the verdict alone), edges either sampled at VAMP's
//! resolution (32 configurations per unit of joint distance, `--edges sampled`) or certified by
//! conservative advancement (`MotionChecker::check_motion`, `--edges certified`). Every path found
//! by sampling is then checked by conservative advancement: the report says how many sampled paths
//! have an edge it cannot certify (one that comes within its 1 mm tolerance of an obstacle), and
//! how many of those collide between VAMP's samples (found by sampling such edges 100× denser).
//!
//! ```text
//! cargo run --release -p sublevel-lab --example plan_mbm -- [--edges sampled|certified] [--timeout S]
//!     [--range R] [--seed N] [--robot data/robots/panda/panda.robot.json]
//!     [--problems data/robots/mbm_panda] [--scenarios a,b,...] [--limit 10]
//! ```
//!
//! Problems 1 to `--limit` of each scenario: `PROBLEMS/scenes/SCENARIO/sceneNNNN.yaml` with
//! `PROBLEMS/requests/SCENARIO/requestNNNN.yaml` (the repository's 10 per scenario), or the
//! MotionBenchMaker archive's layout, `PROBLEMS/problems/SCENARIO_panda/{scene,request}NNNN.yaml`
//! (all 100: `tar xjf data/robots/mbm_panda/problems.tar.bz2 -C /tmp`, then
//! `--problems /tmp --limit 100`).
//! RRT-Connect (Kuffner and LaValle, ICRA 2000): two trees, from the start and from the goal; each
//! round samples a configuration uniformly in the joint limits, extends one tree towards it by at
//! most `range` (joint-space Euclidean, radians), then grows the other tree towards the new node
//! until it connects or is blocked, and swaps the trees. No path simplification.

use rand::{Rng, SeedableRng};
use std::time::{Duration, Instant};
use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{CheckOptions, FittedRobot, MotionChecker, MotionOptions, RobotChecker};
use sublevel_scene::moveit::{allowed_override, world_objects, MotionPlanRequest, PlanningScene};

struct Settings {
    certified: bool,
    timeout: Duration,
    range: Real,
    seed: u64,
    robot: String,
    problems: String,
    scenarios: Vec<String>,
    limit: usize,
}

fn settings() -> Result<Settings, String> {
    let mut s = Settings {
        certified: false,
        timeout: Duration::from_secs(5),
        range: 1.0,
        seed: 1,
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
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let value = args.get(i + 1).cloned().ok_or(format!("{} needs a value", args[i]))?;
        match args[i].as_str() {
            "--edges" => s.certified = value == "certified",
            "--timeout" => s.timeout = Duration::from_secs_f64(value.parse().map_err(|e| format!("--timeout: {e}"))?),
            "--range" => s.range = value.parse().map_err(|e| format!("--range: {e}"))?,
            "--seed" => s.seed = value.parse().map_err(|e| format!("--seed: {e}"))?,
            "--robot" => s.robot = value,
            "--problems" => s.problems = value,
            "--scenarios" => s.scenarios = value.split(',').map(String::from).collect(),
            "--limit" => s.limit = value.parse().map_err(|e| format!("--limit: {e}"))?,
            other => return Err(format!("unknown argument {other}")),
        }
        i += 2;
    }
    Ok(s)
}

/// A tree of configurations.
struct Tree {
    nodes: Vec<Vec<Real>>,
    parent: Vec<usize>,
}

impl Tree {
    fn nearest(&self, q: &[Real]) -> usize {
        let d = |a: &[Real]| a.iter().zip(q).map(|(x, y)| (x - y) * (x - y)).sum::<Real>();
        (0..self.nodes.len()).min_by(|&a, &b| d(&self.nodes[a]).total_cmp(&d(&self.nodes[b]))).unwrap_or(0)
    }
    fn path_to_root(&self, mut i: usize) -> Vec<Vec<Real>> {
        let mut out = vec![self.nodes[i].clone()];
        while i != 0 {
            i = self.parent[i];
            out.push(self.nodes[i].clone());
        }
        out
    }
}

/// Counts of one planning run.
#[derive(Default)]
struct Counts {
    states: usize,
    edges: usize,
}

struct Planner<'c, 'r> {
    checker: RobotChecker<'r>,
    motions: Option<MotionChecker<'c, 'r>>,
    certified: bool,
    counts: Counts,
}

fn distance(a: &[Real], b: &[Real]) -> Real {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<Real>().sqrt()
}

impl Planner<'_, '_> {
    fn state_free(&mut self, q: &[Real]) -> bool {
        self.counts.states += 1;
        let options = CheckOptions { distance: false, ..CheckOptions::default() };
        self.checker.check(q, &Isometry3::identity(), &options).map(|a| !a.collides).unwrap_or(false)
    }

    /// The edge a → b: sampled at 32 per unit of joint distance (b included, in van der Corput
    /// order), or certified.
    fn edge_free(&mut self, a: &[Real], b: &[Real]) -> bool {
        self.counts.edges += 1;
        if self.certified {
            let m = self.motions.as_mut().expect("certified edges need a motion checker");
            return m
                .check_motion(a, b, &Isometry3::identity(), &MotionOptions::default())
                .map(|r| r.valid)
                .unwrap_or(false);
        }
        let n = ((distance(a, b) * 32.0).ceil() as usize).max(1);
        van_der_corput(n).into_iter().all(|i| {
            let t = i as Real / n as Real;
            let q: Vec<Real> = a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect();
            self.state_free(&q)
        })
    }
}

/// `1..=n` ordered as OMPL's discrete motion validator checks an edge: the end first, then each
/// next index halving the largest gap left, so a collision anywhere is found in a few checks.
fn van_der_corput(n: usize) -> Vec<usize> {
    let mut order = vec![n];
    let mut seen = vec![false; n + 1];
    seen[n] = true;
    let mut step = n;
    while step > 1 {
        step = step.div_ceil(2);
        for k in (step..n).step_by(step) {
            if !std::mem::replace(&mut seen[k], true) {
                order.push(k);
            }
        }
    }
    order.extend((1..n).filter(|&k| !seen[k]));
    order
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let s = settings()?;
    let robot = FittedRobot::load(s.robot.as_ref())?;
    let names = robot.model.variable_names().iter().map(|n| n.to_string()).collect::<Vec<_>>();
    let limits: Vec<(Real, Real)> = (0..robot.model.dof())
        .map(|k| robot.model.variable_joint(k).limits.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI)))
        .collect();
    println!(
        "RRT-Connect, range {} rad, edges {}, timeout {:.1} s, seed {}",
        s.range,
        if s.certified { "certified (conservative advancement)" } else { "sampled at 32 per unit (VAMP's resolution)" },
        s.timeout.as_secs_f64(),
        s.seed
    );
    println!("| scenario | problems | solved | median time (ms) | median states checked | median edges | sampled paths: an edge not certified (within 1 mm) / colliding between samples |");
    println!("|---|---|---|---|---|---|---|");
    for scenario in &s.scenarios {
        let (mut solved, mut total, mut crossing, mut near) = (0, 0, 0, 0);
        let (mut times, mut states, mut edges) = (Vec::new(), Vec::new(), Vec::new());
        for k in 1..=s.limit {
            let mut scene_path = format!("{}/scenes/{scenario}/scene{k:04}.yaml", s.problems);
            let mut request_path = format!("{}/requests/{scenario}/request{k:04}.yaml", s.problems);
            if !std::path::Path::new(&scene_path).exists() {
                scene_path = format!("{}/problems/{scenario}_panda/scene{k:04}.yaml", s.problems);
                request_path = format!("{}/problems/{scenario}_panda/request{k:04}.yaml", s.problems);
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
            let mut motion_checker = RobotChecker::new(&robot, world.clone(), &allowed)?;
            let motions = if s.certified { Some(MotionChecker::new(&mut motion_checker)?) } else { None };
            let mut planner = Planner {
                checker: RobotChecker::new(&robot, world.clone(), &allowed)?,
                motions,
                certified: s.certified,
                counts: Counts::default(),
            };
            total += 1;
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s.seed);
            let clock = Instant::now();
            let path = plan(&mut planner, &start, &goal, &limits, s.range, s.timeout, &mut rng);
            let elapsed = clock.elapsed();
            if let Some(path) = path {
                solved += 1;
                times.push(elapsed.as_secs_f64() * 1e3);
                states.push(planner.counts.states as Real);
                edges.push(planner.counts.edges as Real);
                if !s.certified {
                    // Every edge of the sampled path, certified.
                    let mut check = RobotChecker::new(&robot, world, &allowed)?;
                    let mut m = MotionChecker::new(&mut check)?;
                    let flagged: Vec<(Vec<Real>, Vec<Real>)> = path
                        .windows(2)
                        .filter(|w| {
                            m.check_motion(&w[0], &w[1], &Isometry3::identity(), &MotionOptions::default())
                                .map(|r| !r.valid)
                                .unwrap_or(true)
                        })
                        .map(|w| (w[0].clone(), w[1].clone()))
                        .collect();
                    drop(m);
                    if !flagged.is_empty() {
                        near += 1;
                    }
                    // Sampled 100× denser (3 200 per unit of joint distance): a collision between
                    // VAMP's samples.
                    let dense = flagged.iter().any(|(a, b)| {
                        let n = ((distance(a, b) * 3200.0).ceil() as usize).max(1);
                        (0..=n).any(|i| {
                            let t = i as Real / n as Real;
                            let q: Vec<Real> = a.iter().zip(b).map(|(x, y)| x + t * (y - x)).collect();
                            check
                                .check(
                                    &q,
                                    &Isometry3::identity(),
                                    &CheckOptions { distance: false, ..Default::default() },
                                )
                                .map(|r| r.collides)
                                .unwrap_or(true)
                        })
                    });
                    crossing += usize::from(dense);
                }
            }
        }
        let median = |v: &mut Vec<Real>| {
            v.sort_by(Real::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(Real::NAN)
        };
        println!(
            "| {scenario} | {total} | {solved} | {:.1} | {:.0} | {:.0} | {} |",
            median(&mut times),
            median(&mut states),
            median(&mut edges),
            if s.certified { "—".to_string() } else { format!("{near} / {crossing} of {solved}") }
        );
    }
    Ok(())
}

/// RRT-Connect from `start` to `goal` (module docs); the path, start first, or `None` at the
/// timeout or when an end is in collision.
fn plan(
    planner: &mut Planner<'_, '_>,
    start: &[Real],
    goal: &[Real],
    limits: &[(Real, Real)],
    range: Real,
    timeout: Duration,
    rng: &mut impl Rng,
) -> Option<Vec<Vec<Real>>> {
    if !planner.state_free(start) || !planner.state_free(goal) {
        return None;
    }
    let clock = Instant::now();
    let mut a = Tree { nodes: vec![start.to_vec()], parent: vec![0] };
    let mut b = Tree { nodes: vec![goal.to_vec()], parent: vec![0] };
    let mut a_is_start = true;
    if planner.edge_free(start, goal) {
        return Some(vec![start.to_vec(), goal.to_vec()]);
    }
    while clock.elapsed() < timeout {
        let sample: Vec<Real> = limits.iter().map(|&(lo, hi)| rng.random_range(lo..=hi)).collect();
        if let Some(new) = extend(planner, &mut a, &sample, range) {
            let target = a.nodes[new].clone();
            // Connect: grow b towards the new node until it reaches it or is blocked.
            loop {
                match extend(planner, &mut b, &target, range) {
                    Some(reached) if distance(&b.nodes[reached], &target) < 1e-12 => {
                        let mut from_a = a.path_to_root(new);
                        from_a.reverse();
                        let from_b = b.path_to_root(reached);
                        let mut path = from_a;
                        path.extend(from_b.into_iter().skip(1));
                        if !a_is_start {
                            path.reverse();
                        }
                        return Some(path);
                    }
                    Some(_) => continue,
                    None => break,
                }
            }
        }
        std::mem::swap(&mut a, &mut b);
        a_is_start = !a_is_start;
    }
    None
}

/// Extends `tree` towards `target` by at most `range`; the new node's index, or `None` when the
/// edge is blocked.
fn extend(planner: &mut Planner<'_, '_>, tree: &mut Tree, target: &[Real], range: Real) -> Option<usize> {
    let near = tree.nearest(target);
    let from = tree.nodes[near].clone();
    let d = distance(&from, target);
    if d < 1e-12 {
        return None;
    }
    let f = (range / d).min(1.0);
    let q: Vec<Real> = from.iter().zip(target).map(|(x, y)| x + f * (y - x)).collect();
    if !planner.state_free(&q) || !planner.edge_free(&from, &q) {
        return None;
    }
    tree.nodes.push(q);
    tree.parent.push(near);
    Some(tree.nodes.len() - 1)
}
