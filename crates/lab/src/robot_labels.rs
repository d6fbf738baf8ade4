//! `sublevel-lab robot-labels`: a fitted robot's configuration checks against mesh-exact labels
//! (the MotionBenchMaker Panda labels of the robots peer: pinocchio + coal on the collision meshes,
//! 14 000 configurations over 7 scenarios × 10 scenes), per scenario:
//!
//! - misses: configurations the meshes call colliding that the check calls free (world, self);
//! - false collisions: mesh-free configurations called colliding, as % of the mesh-free ones,
//!   with the mesh clearance of those that remain;
//! - the minimum robot–world distance against the mesh-exact one (never above it; the mean and
//!   worst error where both call the robot free of the world);
//! - time per configuration, one thread: the full answer (distance, world, self) and the verdict
//!   alone (world pairs stop at the first collision, no distance), medians.
//!
//! The table's last column times the other path (single with blocks, blocks with `--single`) on
//! the same configurations right after, so that the two means compare within one run; their
//! verdicts must agree.
//!
//! The verdicts the misses and false collisions are counted from are the block path's
//! ([`RobotChecker::check_block`], the scene's configurations in blocks of [`BLOCK`], the time
//! per configuration a block's over its size), or with `--single` one
//! [`RobotChecker::check`] call per configuration; either must agree with the full answer's.

use csv::StringRecord;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;
use sublevel_core::math::{Isometry3, Real};
use sublevel_core::{Error, Result};
use sublevel_robot::{
    CheckOptions, ConfigurationAnswer, Fidelity, FittedRobot, MotionChecker, MotionOptions, RobotChecker, BLOCK,
};
use sublevel_scene::moveit::{allowed_override, world_objects, PlanningScene};

/// Arguments of `sublevel-lab robot-labels`.
#[derive(clap::Args, Debug, Clone)]
pub struct RobotLabelsArgs {
    /// The fitted robot (`sublevel robot fit`).
    #[arg(long, default_value = "data/robots/panda/panda.robot.json")]
    robot: PathBuf,
    /// The labels CSV (`scenario, scene, idx, kind, q1..q7, collides, collides_world,
    /// collides_self, min_world_dist_m, colliding_pairs`).
    /// The default holds the labels of the collision meshes as their OBJ files define them
    /// (`scripts/peers/relabel_panda.py`); the robots peer's own labels, read by coal's mesh
    /// loader, are its `labels/mbm_panda_labels.csv` (data/robots/SOURCE.md).
    #[arg(long, default_value = "data/robots/mbm_panda/labels_obj.csv")]
    labels: PathBuf,
    /// The planning scenes: `DIR/SCENARIO{suffix}/sceneNNNN.yaml`.
    #[arg(long, default_value = "data/robots/mbm_panda/scenes")]
    problems: PathBuf,
    /// Suffix of the scenario folders (`_panda` for MotionBenchMaker's extracted problems).
    #[arg(long, default_value = "")]
    suffix: String,
    /// Check only every k-th labelled configuration.
    #[arg(long, default_value_t = 1)]
    every: usize,
    /// Print every miss and the worst distance errors.
    #[arg(long)]
    verbose: bool,
    /// Check without the sphere-tree stage (`RobotChecker::set_sphere_stage`), the reference it
    /// is measured against.
    #[arg(long)]
    no_sphere_stage: bool,
    /// Check without the contact proofs (`RobotChecker::set_contact_proofs`), the reference they
    /// are measured against.
    #[arg(long)]
    no_contact_proofs: bool,
    /// The verdicts one `check` call per configuration instead of in blocks of 8 (`check_block`).
    #[arg(long)]
    single: bool,
    /// The level of the checks (`RobotChecker::set_fidelity`): mesh, bodies or spheres. At a
    /// conservative level the block and single paths may differ in false collisions (each
    /// calls free only what a body containing the meshes shows free), so their agreement is
    /// not required.
    #[arg(long, default_value = "mesh")]
    pub fidelity: String,
    /// The spheres level's tolerance (meters; 0: its default).
    #[arg(long, default_value_t = 0.0)]
    pub tolerance: Real,
}

impl RobotLabelsArgs {
    /// The level asked for.
    ///
    /// # Errors
    /// An unknown level or a tolerance out of range, naming `--fidelity` or `--tolerance`.
    pub fn level(&self) -> Result<Fidelity> {
        Fidelity::parse("fidelity", &self.fidelity, Some(self.tolerance))
    }
}

#[derive(Default)]
pub(crate) struct Tally {
    pub(crate) n: usize,
    pub(crate) mesh_colliding: usize,
    pub(crate) mesh_free: usize,
    ours_colliding: usize,
    pub(crate) miss_world: usize,
    pub(crate) miss_self: usize,
    false_world: usize,
    false_self: usize,
    pub(crate) false_any: usize,
    false_clearance: Vec<Real>,
    /// Configurations the block path's lanes left to the single path.
    pub(crate) lanes_left: usize,
    /// The mesh clearance of the configurations falsely called colliding with the world.
    false_world_clearance: Vec<Real>,
    dist_err: Vec<Real>,
    above: usize,
    unconverged: usize,
    exact_pairs: usize,
    full_ns: Vec<Real>,
    pub(crate) verdict_ns: Vec<Real>,
    /// The other path's verdict times on the same configurations (the single path's with blocks,
    /// the blocks' with `--single`), timed right after, for a ratio in one run.
    other_ns: Vec<Real>,
}

pub(crate) fn average(v: &[Real]) -> Real {
    v.iter().sum::<Real>() / v.len().max(1) as Real
}

pub(crate) fn median(v: &mut [Real]) -> Real {
    if v.is_empty() {
        return Real::NAN;
    }
    v.sort_by(Real::total_cmp);
    v[v.len() / 2]
}

fn field<'a>(r: &'a StringRecord, h: &StringRecord, name: &str) -> Result<&'a str> {
    let i = h.iter().position(|x| x == name).ok_or_else(|| Error::invalid("labels", format!("no column {name}")))?;
    r.get(i).ok_or_else(|| Error::invalid("labels", format!("a row lacks {name}")))
}

fn num(r: &StringRecord, h: &StringRecord, name: &str) -> Result<Real> {
    field(r, h, name)?.parse::<Real>().map_err(|e| Error::invalid("labels", format!("{name}: {e}")))
}

/// A checker of `robot` in the planning scene `scene_no` of `scenario` (its primitives and its
/// allowed-collision matrix).
fn scene_checker<'r>(
    args: &RobotLabelsArgs,
    robot: &'r FittedRobot,
    scenario: &str,
    scene_no: u32,
) -> Result<RobotChecker<'r>> {
    let path = args.problems.join(format!("{scenario}{}", args.suffix)).join(format!("scene{scene_no:04}.yaml"));
    let bytes = std::fs::read(&path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?;
    let scene = PlanningScene::from_yaml(&bytes)?;
    let (world, _) = world_objects(&scene)?;
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(robot, world, &allowed)?;
    checker.set_sphere_stage(!args.no_sphere_stage);
    checker.set_contact_proofs(!args.no_contact_proofs);
    checker.set_fidelity(args.level()?)?;
    Ok(checker)
}

/// Runs `sublevel-lab robot-labels`.
///
/// # Errors
/// Files that cannot be read; a label row or a scene that does not parse; a check that fails.
pub fn run(args: RobotLabelsArgs) -> Result<()> {
    let mut tallies = evaluate(&args)?;
    if args.single {
        println!("verdicts: one `check` call per configuration");
    } else {
        println!("verdicts: `check_block` in blocks of {BLOCK} (time per configuration: a block's over its size)");
    }
    print_table(&mut tallies);
    let motions = evaluate_motions(&args, None)?;
    println!("\nstart–goal motions of the scenes (conservative advancement, tolerance 1 mm), against their 100 labelled samples:");
    println!("| scenario | motions | valid | invalid, a sample collides | invalid, every sample free | inconsistent | median steps | median time (µs) |");
    println!("|---|---|---|---|---|---|---|---|");
    for (name, m) in motions {
        let mut steps = m.steps.clone();
        let mut times = m.micros.clone();
        println!(
            "| {name} | {} | {} | {} | {} | {} | {:.0} | {:.0} |",
            m.n,
            m.valid,
            m.invalid_sampled,
            m.invalid_unsampled,
            m.inconsistent,
            median(&mut steps),
            median(&mut times)
        );
    }
    Ok(())
}

/// Start–goal motions of one scenario.
#[derive(Default)]
struct MotionTally {
    n: usize,
    valid: usize,
    /// Invalid, and a labelled sample of the segment collides.
    invalid_sampled: usize,
    /// Invalid, though all 100 labelled samples are free (a contact between samples, or within
    /// the tolerance).
    invalid_unsampled: usize,
    /// Valid with a colliding sample, or a contact after the first colliding sample.
    inconsistent: usize,
    steps: Vec<Real>,
    micros: Vec<Real>,
}

/// A labelled sample of a start–goal segment: its index, configuration and whether it collides.
type Sample = (usize, Vec<Real>, bool);

/// Each labelled scene's start–goal motion (the `line` configurations are its samples at
/// t = (idx − 100) / 99) checked by conservative advancement, against the samples' labels.
fn evaluate_motions(args: &RobotLabelsArgs, only: Option<&[&str]>) -> Result<BTreeMap<String, MotionTally>> {
    let robot = FittedRobot::load(&args.robot)?;
    let mut reader = csv::Reader::from_path(&args.labels).map_err(|e| Error::invalid("labels", e.to_string()))?;
    let header = reader.headers().map_err(|e| Error::invalid("labels", e.to_string()))?.clone();
    let mut lines: BTreeMap<(String, u32), Vec<Sample>> = BTreeMap::new();
    for r in reader.records() {
        let r = r.map_err(|e| Error::invalid("labels", e.to_string()))?;
        if field(&r, &header, "kind")? != "line"
            || only.is_some_and(|o| !o.contains(&field(&r, &header, "scenario").unwrap_or("")))
        {
            continue;
        }
        let scene: u32 = field(&r, &header, "scene")?.parse().map_err(|_| Error::invalid("labels", "scene"))?;
        let idx: usize = field(&r, &header, "idx")?.parse().map_err(|_| Error::invalid("labels", "idx"))?;
        let q = (1..=robot.model.dof()).map(|j| num(&r, &header, &format!("q{j}"))).collect::<Result<_>>()?;
        let collides = num(&r, &header, "collides")? > 0.5;
        lines.entry((field(&r, &header, "scenario")?.to_owned(), scene)).or_default().push((idx, q, collides));
    }
    let mut out: BTreeMap<String, MotionTally> = BTreeMap::new();
    let options = MotionOptions::default();
    for ((scenario, scene_no), mut samples) in lines {
        samples.sort_by_key(|s| s.0);
        let mut checker = scene_checker(args, &robot, &scenario, scene_no)?;
        let mut motions = MotionChecker::new(&mut checker)?;
        let (Some(first), Some(last)) = (samples.first(), samples.last()) else { continue };
        let start = Instant::now();
        let a = motions.check_motion(&first.1, &last.1, &Isometry3::identity(), &options)?;
        let micros = start.elapsed().as_secs_f64() * 1e6;
        let n = samples.len().max(2) as Real - 1.0;
        let first_colliding = samples.iter().position(|s| s.2).map(|k| k as Real / n);
        let t = out.entry(scenario).or_default();
        t.n += 1;
        t.steps.push(a.steps as Real);
        t.micros.push(micros);
        match (a.valid, first_colliding, a.contact) {
            (true, None, _) => t.valid += 1,
            (true, Some(_), _) => t.inconsistent += 1,
            (false, Some(f), Some(c)) if c <= f + 1e-9 => t.invalid_sampled += 1,
            (false, None, Some(_)) => t.invalid_unsampled += 1,
            _ => t.inconsistent += 1,
        }
    }
    Ok(out)
}

/// The verdicts of `qs` under `options`: one [`RobotChecker::check`] call each with `single`,
/// else [`RobotChecker::check_block`] on blocks of [`BLOCK`]; each configuration's time
/// (nanoseconds; in a block, the block's over its size) pushed to `times`.
fn verdicts(
    checker: &mut RobotChecker<'_>,
    qs: &[Vec<Real>],
    options: &CheckOptions,
    single: bool,
    times: &mut Vec<Real>,
) -> Result<Vec<ConfigurationAnswer>> {
    let base = Isometry3::identity();
    let mut out = Vec::with_capacity(qs.len());
    if single {
        for q in qs {
            let s = Instant::now();
            out.push(checker.check(q, &base, options)?);
            times.push(s.elapsed().as_nanos() as Real);
        }
        return Ok(out);
    }
    let mut flat = Vec::new();
    for block in qs.chunks(BLOCK) {
        flat.clear();
        flat.extend(block.iter().flatten());
        let s = Instant::now();
        checker.check_block(&flat, &base, options, false, &mut out)?;
        let each = s.elapsed().as_nanos() as Real / block.len() as Real;
        times.extend(std::iter::repeat_n(each, block.len()));
    }
    Ok(out)
}

/// Checks the labelled configurations, per scenario.
pub(crate) fn evaluate(args: &RobotLabelsArgs) -> Result<BTreeMap<String, Tally>> {
    let robot = FittedRobot::load(&args.robot)?;
    let mut reader = csv::Reader::from_path(&args.labels).map_err(|e| Error::invalid("labels", e.to_string()))?;
    let header = reader.headers().map_err(|e| Error::invalid("labels", e.to_string()))?.clone();
    let rows: Vec<StringRecord> =
        reader.records().collect::<std::result::Result<_, _>>().map_err(|e| Error::invalid("labels", e.to_string()))?;
    let dof = robot.model.dof();
    // Group rows by scene, keeping their order.
    let mut by_scene: BTreeMap<(String, u32), Vec<&StringRecord>> = BTreeMap::new();
    for (k, r) in rows.iter().enumerate() {
        if k % args.every.max(1) != 0 {
            continue;
        }
        let scene: u32 = field(r, &header, "scene")?.parse().map_err(|_| Error::invalid("labels", "scene"))?;
        by_scene.entry((field(r, &header, "scenario")?.to_owned(), scene)).or_default().push(r);
    }
    let mut tallies: BTreeMap<String, Tally> = BTreeMap::new();
    let base = Isometry3::identity();
    let full = CheckOptions::default();
    let verdict = CheckOptions { distance: false, ..CheckOptions::default() };
    for ((scenario, scene_no), rows) in &by_scene {
        let mut checker = scene_checker(args, &robot, scenario, *scene_no)?;
        let t = tallies.entry(scenario.clone()).or_default();
        let qs: Vec<Vec<Real>> = rows
            .iter()
            .map(|r| (1..=dof).map(|j| num(r, &header, &format!("q{j}"))).collect::<Result<_>>())
            .collect::<Result<_>>()?;
        let before = checker.block_counts();
        let verdicts = verdicts(&mut checker, &qs, &verdict, args.single, &mut t.verdict_ns)?;
        let after = checker.block_counts();
        t.lanes_left += (after.1 - before.1) as usize;
        let other = self::verdicts(&mut checker, &qs, &verdict, !args.single, &mut t.other_ns)?;
        let flags = |v: &[ConfigurationAnswer]| v.iter().map(|a| (a.world, a.self_collision)).collect::<Vec<_>>();
        let exact = args.level()?.is_mesh();
        if exact && flags(&other) != flags(&verdicts) {
            return Err(Error::Numerical(format!("{scenario} scene {scene_no}: the block and single verdicts differ")));
        }
        for ((r, q), v) in rows.iter().zip(&qs).zip(&verdicts) {
            let mesh = num(r, &header, "collides")? > 0.5;
            let mesh_world = num(r, &header, "collides_world")? > 0.5;
            let mesh_self = num(r, &header, "collides_self")? > 0.5;
            let mesh_dist = num(r, &header, "min_world_dist_m")?;
            let s = Instant::now();
            let a = checker.check(q, &base, &full)?;
            t.full_ns.push(s.elapsed().as_nanos() as Real);
            if exact && (v.world != a.world || v.self_collision != a.self_collision || v.collides != a.collides) {
                return Err(Error::Numerical(format!(
                    "{scenario} scene {scene_no} idx {}: the verdict-only check disagrees with the full one",
                    field(r, &header, "idx")?
                )));
            }
            t.n += 1;
            t.exact_pairs += a.pairs_exact;
            t.unconverged += usize::from(!a.converged);
            t.ours_colliding += usize::from(v.collides);
            if mesh {
                t.mesh_colliding += 1;
            } else {
                t.mesh_free += 1;
            }
            let idx = field(r, &header, "idx")?;
            if mesh_world && !v.world {
                t.miss_world += 1;
                if args.verbose {
                    eprintln!(
                        "miss (world): {scenario} {scene_no} idx {idx} pairs {}",
                        field(r, &header, "colliding_pairs")?
                    );
                }
            }
            if mesh_self && !v.self_collision {
                t.miss_self += 1;
                if args.verbose {
                    eprintln!(
                        "miss (self): {scenario} {scene_no} idx {idx} pairs {}",
                        field(r, &header, "colliding_pairs")?
                    );
                }
            }
            t.false_world += usize::from(!mesh_world && v.world);
            if !mesh_world && v.world {
                t.false_world_clearance.push(mesh_dist);
            }
            t.false_self += usize::from(!mesh_self && v.self_collision);
            if !mesh && v.collides {
                if args.verbose {
                    let pair =
                        a.pair.map(|(g, o)| format!("{} – {}", robot.geometries[g].name, checker.world()[o].name));
                    let self_pair = a
                        .self_pair
                        .map(|(x, y)| format!("{} – {}", robot.geometries[x].name, robot.geometries[y].name));
                    eprintln!("false collision: {scenario} {scene_no} idx {idx} world {} {pair:?} self {} {self_pair:?}, mesh clearance {mesh_dist}", a.world, a.self_collision);
                }
                t.false_any += 1;
                t.false_clearance.push(mesh_dist);
            }
            if !mesh_world && !a.world {
                let err = mesh_dist - a.distance;
                if a.distance > mesh_dist + 1e-5 {
                    t.above += 1;
                    if args.verbose {
                        eprintln!(
                            "distance above the mesh's: {scenario} {scene_no} idx {idx}: {} > {mesh_dist}",
                            a.distance
                        );
                    }
                }
                t.dist_err.push(err);
            }
        }
    }
    Ok(tallies)
}

fn print_table(tallies: &mut BTreeMap<String, Tally>) {
    println!(
        "| scenario | configs | mesh colliding | misses (world / self) | false collisions (world / self) | false % of mesh-free | distance above mesh | mean / max distance error (mm) | pairs on meshes per config | not converged | full check median (µs) | verdict median (µs) | verdict mean (µs) | other path's mean (µs) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut all = Tally::default();
    for (name, t) in tallies.iter_mut() {
        row(name, t);
        all.n += t.n;
        all.mesh_colliding += t.mesh_colliding;
        all.mesh_free += t.mesh_free;
        all.miss_world += t.miss_world;
        all.miss_self += t.miss_self;
        all.false_world += t.false_world;
        all.false_self += t.false_self;
        all.false_any += t.false_any;
        all.false_clearance.extend(&t.false_clearance);
        all.dist_err.extend(&t.dist_err);
        all.above += t.above;
        all.unconverged += t.unconverged;
        all.exact_pairs += t.exact_pairs;
        all.full_ns.extend(&t.full_ns);
        all.verdict_ns.extend(&t.verdict_ns);
        all.other_ns.extend(&t.other_ns);
    }
    row("all", &mut all);
    let mut c = all.false_clearance.clone();
    c.sort_by(Real::total_cmp);
    let bins = [0.001, 0.002, 0.005, 0.01, 0.02, 0.05, Real::INFINITY];
    let mut lo = 0.0;
    let mut hist = Vec::new();
    for hi in bins {
        let n = c.iter().filter(|&&x| x >= lo && x < hi).count();
        hist.push(format!(
            "[{:.0}, {}) mm: {n}",
            lo * 1e3,
            if hi.is_finite() { format!("{:.0}", hi * 1e3) } else { "∞".into() }
        ));
        lo = hi;
    }
    println!("\nmesh clearance of the false collisions (meters of min world distance): {}", hist.join(", "));
    let left: usize = tallies.values().map(|t| t.lanes_left).sum();
    println!(
        "configurations the lanes left to the single path: {left} of {} ({:.1} %)",
        all.n,
        100.0 * left as Real / all.n.max(1) as Real
    );
}

fn row(name: &str, t: &mut Tally) {
    let mean =
        if t.dist_err.is_empty() { Real::NAN } else { t.dist_err.iter().sum::<Real>() / t.dist_err.len() as Real };
    let max = t.dist_err.iter().copied().fold(0.0, Real::max);
    println!(
        "| {name} | {} | {} | {} / {} | {} / {} | {:.2} % | {} | {:.2} / {:.1} | {:.2} | {} | {:.1} | {:.1} | {:.2} | {:.2} |",
        t.n,
        t.mesh_colliding,
        t.miss_world,
        t.miss_self,
        t.false_world,
        t.false_self,
        100.0 * t.false_any as Real / t.mesh_free.max(1) as Real,
        t.above,
        mean * 1e3,
        max * 1e3,
        t.exact_pairs as Real / t.n.max(1) as Real,
        t.unconverged,
        median(&mut t.full_ns) / 1e3,
        median(&mut t.verdict_ns) / 1e3,
        average(&t.verdict_ns) / 1e3,
        average(&t.other_ns) / 1e3,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The repository's Panda, labels and scenes, every `every`-th configuration.
    fn repository_args(every: usize, verbose: bool) -> RobotLabelsArgs {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        RobotLabelsArgs {
            robot: root.join("data/robots/panda/panda.robot.json"),
            labels: root.join("data/robots/mbm_panda/labels_obj.csv"),
            problems: root.join("data/robots/mbm_panda/scenes"),
            suffix: String::new(),
            every,
            verbose,
            no_sphere_stage: false,
            no_contact_proofs: false,
            single: false,
            fidelity: "mesh".into(),
            tolerance: 0.0,
        }
    }

    /// Every tenth of the 14 000 MotionBenchMaker Panda configurations, against the labels of
    /// pinocchio + coal on the OBJ meshes as written (`scripts/peers/relabel_panda.py`): no miss,
    /// no false collision, the minimum world distance equal to coal's to 10 µm (both GJK; the
    /// labels are rounded to 1 µm), every answer converged.
    #[test]
    fn the_panda_checks_agree_with_the_mesh_labels() {
        let args = repository_args(10, true);
        let tallies = evaluate(&args).unwrap();
        assert_eq!(tallies.len(), 7, "seven scenarios");
        let n: usize = tallies.values().map(|t| t.n).sum();
        let colliding: usize = tallies.values().map(|t| t.mesh_colliding).sum();
        assert_eq!(n, 1400);
        assert!(colliding > 300 && colliding < n - 300, "both verdicts present: {colliding} colliding");
        for (name, t) in &tallies {
            assert_eq!((t.miss_world, t.miss_self), (0, 0), "{name}: misses");
            assert_eq!((t.false_world, t.false_self), (0, 0), "{name}: false collisions");
            assert_eq!(t.above, 0, "{name}: a distance above the mesh's");
            assert_eq!(t.unconverged, 0, "{name}: not converged");
            let worst = t.dist_err.iter().fold(0.0, |m: Real, e| m.max(e.abs()));
            assert!(worst < 1e-5, "{name}: distance differs from coal's by {worst} m");
        }
    }

    /// Every conservative level against the labels (every 10th configuration): no miss, no
    /// distance above the meshes', and false collisions only within the sphere tolerance of
    /// contact (world pairs) at the spheres levels.
    #[test]
    fn no_fidelity_level_misses_a_labelled_collision() {
        for (level, tolerance) in [("bodies", 0.0), ("spheres", 0.01), ("spheres", 0.03), ("spheres", 0.2)] {
            let args = RobotLabelsArgs { fidelity: level.into(), tolerance, ..repository_args(10, false) };
            let tallies = evaluate(&args).unwrap();
            let mut false_collisions = 0;
            for (name, t) in &tallies {
                assert_eq!((t.miss_world, t.miss_self), (0, 0), "{level} {tolerance}: {name}: misses");
                assert_eq!(t.above, 0, "{level} {tolerance}: {name}: a distance above the mesh's");
                false_collisions += t.false_any;
                if level == "spheres" {
                    let far = t.false_world_clearance.iter().copied().fold(0.0, Real::max);
                    assert!(
                        far <= tolerance + 1e-5,
                        "{level} {tolerance}: {name}: a world false collision {far} m out"
                    );
                }
            }
            assert!(false_collisions > 0, "{level} {tolerance}: conservative near contact");
        }
    }

    /// The block path and the single path count the same verdicts (every 25th configuration).
    #[test]
    fn the_block_and_the_single_verdicts_give_the_same_tallies() {
        let block = evaluate(&repository_args(25, false)).unwrap();
        let single = evaluate(&RobotLabelsArgs { single: true, ..repository_args(25, false) }).unwrap();
        assert_eq!(block.len(), 7);
        let counts = |t: &Tally| (t.n, t.ours_colliding, t.miss_world, t.miss_self, t.false_world, t.false_self);
        for (name, b) in &block {
            assert_eq!(counts(b), counts(&single[name]), "{name}");
            assert_eq!(b.verdict_ns.len(), b.n, "{name}: a time per configuration");
        }
    }

    /// The minimum world distance's joint-space gradient on the Panda against central
    /// differences of the distance (h = 1e-6 rad), at the uniform labelled configurations of a
    /// table_pick scene that are free of the world.
    #[test]
    fn the_panda_distance_gradient_matches_central_differences() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        let robot = FittedRobot::load(&root.join("data/robots/panda/panda.robot.json")).unwrap();
        let scene = PlanningScene::from_yaml(
            &std::fs::read(root.join("data/robots/mbm_panda/scenes/table_pick/scene0001.yaml")).unwrap(),
        )
        .unwrap();
        let (world, _) = world_objects(&scene).unwrap();
        let allowed = allowed_override(&scene);
        let mut checker = RobotChecker::new(&robot, world, &allowed).unwrap();
        let labels = std::fs::read_to_string(root.join("data/robots/mbm_panda/labels_obj.csv")).unwrap();
        let id = Isometry3::identity();
        let options = CheckOptions { gradient: true, ..CheckOptions::default() };
        let (h, mut checked, mut worst) = (1e-6, 0, 0.0 as Real);
        for line in labels.lines().filter(|l| l.starts_with("table_pick,1,") && l.contains(",uniform,")) {
            let c: Vec<&str> = line.split(',').collect();
            if c[12] == "1" {
                continue;
            }
            let q: Vec<Real> = c[4..11].iter().map(|x| x.parse().unwrap()).collect();
            let g = checker.check(&q, &id, &options).unwrap().gradient.unwrap();
            for k in 0..7 {
                let mut d = |s: Real| {
                    let mut p = q.clone();
                    p[k] += s;
                    checker.check(&p, &id, &CheckOptions::default()).unwrap().distance
                };
                let fd = (d(h) - d(-h)) / (2.0 * h);
                worst = worst.max((g[k] - fd).abs());
            }
            checked += 1;
        }
        eprintln!("gradient: {checked} configurations, worst difference {worst:e} m/rad");
        assert!(checked >= 50, "{checked} configurations");
        assert!(worst < 1e-4, "worst |∂d/∂q − central difference| {worst} m/rad");
    }

    /// The start–goal motions of the box, cage and table_under_pick scenes: a motion proven valid
    /// has no colliding sample, and an invalid one reports its first contact no later than the
    /// first colliding sample.
    #[test]
    fn panda_motions_agree_with_their_labelled_samples() {
        let args = repository_args(1, false);
        let motions = evaluate_motions(&args, Some(&["box", "cage", "table_under_pick"])).unwrap();
        let n: usize = motions.values().map(|m| m.n).sum();
        let valid: usize = motions.values().map(|m| m.valid).sum();
        let sampled: usize = motions.values().map(|m| m.invalid_sampled).sum();
        assert_eq!(n, 30);
        assert!(sampled > 20, "{valid} valid, {sampled} invalid at a sample");
        for (name, m) in &motions {
            assert_eq!(m.inconsistent, 0, "{name}");
        }
    }
}
