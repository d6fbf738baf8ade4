//! `sublevel robot fit` and `sublevel robot check`: robots fitted from URDF (and SRDF), and joint
//! configurations checked against a MoveIt planning scene, offline (no server).
//!
//! ```text
//! sublevel robot fit ROBOT.urdf [--srdf ROBOT.srdf] [--package-dir DIR]... [--leaves [--tolerance T]] --output robot.json
//! sublevel robot tables robot.json [--max-loss 0.004] [--output OUT.json]
//! sublevel robot check robot.json --scene SCENE.yaml --configs Q.csv [--json] [--gradient] [--padding P] [--no-distance]
//! sublevel robot bench robot.json --scene SCENE.yaml [--columns 1000] [--addr HOST:PORT]   (robot_bench.rs)
//! sublevel robot plan robot.json --scene SCENE.yaml --request REQUEST.yaml [--json]        (robot_plan.rs)
//! ```

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;
use sublevel::math::{Isometry3, Real};
use sublevel::robot::clearance::{build_clearance_tables, ClearanceSettings};
use sublevel::robot::{fit_robot, CheckOptions, FittedRobot, RobotChecker, RobotFitSettings};
use sublevel::scene::moveit::{allowed_override, world_objects, PlanningScene};
use sublevel::{Error, Result};

/// Arguments of `sublevel robot`.
#[derive(clap::Args, Debug)]
pub struct RobotArgs {
    #[command(subcommand)]
    command: RobotCommand,
}

/// What `sublevel robot` does.
#[derive(clap::Subcommand, Debug)]
enum RobotCommand {
    /// Fit a robot from its URDF: every link mesh becomes a compound sos-convex body containing
    /// it, URDF primitives stay exact, the SRDF's disabled pairs become the allowed pairs.
    Fit(FitArgs),
    /// Build (again) a fitted robot's clearance tables: the meshes' distance over the joints of
    /// the self pairs moved by one or two joints, looked up before the sphere trees.
    Tables(TablesArgs),
    /// Check joint configurations of a fitted robot against a MoveIt planning scene: collides
    /// (world, self), minimum robot–world distance and its pair.
    Check(CheckArgs),
    /// Measure configuration checks: in process on one thread (single, in blocks, with
    /// distance) and over gRPC in columns.
    Bench(super::robot_bench::BenchArgs),
    /// Plan a MoveIt MotionPlanRequest among a planning scene: RRT-Connect, simplification, every
    /// edge of the path certified by conservative advancement (docs/planning.md).
    Plan(super::robot_plan::PlanArgs),
}

/// Arguments of `sublevel robot fit`.
#[derive(clap::Args, Debug)]
struct FitArgs {
    /// The robot's URDF.
    urdf: PathBuf,
    /// The robot's SRDF: its `disable_collisions` pairs are never checked for self-collision.
    #[arg(long)]
    srdf: Option<PathBuf>,
    /// A directory holding ROS packages: `package://NAME/PATH` is read as `DIR/NAME/PATH`
    /// (repeatable; relative mesh paths are read from the URDF's directory).
    #[arg(long = "package-dir")]
    package_dirs: Vec<PathBuf>,
    /// Also fit each link mesh's compound tree (its leaves under the root, `--parts auto`): minutes
    /// per robot. Default: one sos-convex body per mesh, what the checks read, about a second each.
    #[arg(long)]
    leaves: bool,
    /// With `--leaves`: leaf-excess tolerance T of every link mesh's compound fit, meters (default:
    /// 1 % of each mesh's bounding-box diagonal). Leaves above it are reported; the checks stay exact.
    #[arg(long)]
    tolerance: Option<Real>,
    /// With `--leaves`: most leaves of one link's compound body (2..=64).
    #[arg(long, default_value_t = 32)]
    max_parts: usize,
    /// Where fitted link meshes are cached (by content): default `$XDG_CACHE_HOME/sublevel/links`
    /// or `~/.cache/sublevel/links`.
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Fit every mesh again, not reading the cache (its entries are rewritten).
    #[arg(long)]
    no_cache: bool,
    /// Meshes fitted at once (0: one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Build no clearance tables (self pairs moved by one or two joints are then decided by the
    /// sphere trees and the meshes alone: the same answers, slower).
    #[arg(long)]
    no_clearance_tables: bool,
    /// Where to write the robot file.
    #[arg(short, long)]
    output: PathBuf,
    /// No progress on stderr.
    #[arg(short, long)]
    quiet: bool,
}

/// Arguments of `sublevel robot tables`.
#[derive(clap::Args, Debug)]
struct TablesArgs {
    /// The robot file (`sublevel robot fit`).
    robot: PathBuf,
    /// Most the tables' distance bound may lose at a cell's corner, meters (sets the cell size).
    #[arg(long, default_value_t = 0.004)]
    max_loss: Real,
    /// Most cells per table.
    #[arg(long, default_value_t = 1 << 17)]
    max_cells: usize,
    /// Where to write the robot file (default: over the input).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Arguments of `sublevel robot check`.
#[derive(clap::Args, Debug)]
struct CheckArgs {
    /// The robot file (`sublevel robot fit`).
    robot: PathBuf,
    /// The world: a MoveIt planning scene (YAML, or JSON for `.json`); its allowed-collision
    /// matrix overrides the robot's, its robot state gives the joints the configurations omit.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Configurations: a header of joint names, then one configuration per row (radians,
    /// meters). Joints not listed keep the scene's robot state, else 0.
    #[arg(long)]
    configs: PathBuf,
    /// One JSON line per configuration instead of the table.
    #[arg(long)]
    json: bool,
    /// Padding around every robot geometry, meters.
    #[arg(long, default_value_t = 0.0)]
    padding: Real,
    /// Do not check self-collision.
    #[arg(long)]
    no_self: bool,
    /// Verdicts only, no minimum distance (`distance` empty / null): the configurations are then
    /// decided in blocks of 8 by the SIMD kernel where it can (`RobotChecker::check_block`); with
    /// the distance each is checked alone.
    #[arg(long, conflicts_with = "gradient")]
    no_distance: bool,
    /// With --json: also `gradient`, ∂distance/∂q per configuration entry (meters per radian or
    /// meter), when the robot is free of the world.
    #[arg(long)]
    gradient: bool,
    #[command(flatten)]
    fidelity: super::fidelity::FidelityArgs,
}

/// Runs `sublevel robot`.
///
/// # Errors
/// As the subcommand: files that cannot be read, a URDF / SRDF / scene / CSV field that does not
/// validate (named), a fit that fails.
pub fn run(args: RobotArgs) -> Result<()> {
    match args.command {
        RobotCommand::Fit(a) => fit(a),
        RobotCommand::Tables(a) => tables(a),
        RobotCommand::Check(a) => check(a),
        RobotCommand::Bench(a) => super::robot_bench::run(a),
        RobotCommand::Plan(a) => super::robot_plan::run(a),
    }
}

fn default_cache() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("sublevel").join("links"))
}

fn fit(args: FitArgs) -> Result<()> {
    let mut settings =
        RobotFitSettings { package_dirs: args.package_dirs.clone(), threads: args.threads, ..Default::default() };
    settings.compound.excess_tolerance = args.tolerance;
    settings.compound.max_parts = args.max_parts;
    settings.compound.validate()?;
    settings.cache_dir = args.cache.clone().or_else(default_cache);
    settings.refresh_cache = args.no_cache;
    settings.clearance = (!args.no_clearance_tables).then(ClearanceSettings::default);
    settings.leaves = args.leaves;
    let start = Instant::now();
    let quiet = args.quiet;
    let progress = move |p: &sublevel::robot::RobotFitProgress| {
        if !quiet {
            eprintln!("[{}/{}] {}", p.done, p.total, p.message);
        }
    };
    let robot = fit_robot(&args.urdf, args.srdf.as_deref(), &settings, &progress)?;
    robot.save(&args.output)?;
    let r = &robot.file.report;
    let links = robot.model.links().iter().filter(|l| !l.collision.is_empty()).count();
    eprintln!(
        "{}: {} links with geometry, {} geometries, {} meshes fitted, {} from the cache, {} self pairs checked, {:.1} s -> {}",
        robot.model.name,
        links,
        robot.geometries.len(),
        r.fitted,
        r.cached,
        robot.self_pairs.len(),
        start.elapsed().as_secs_f64(),
        args.output.display()
    );
    for n in &r.notes {
        eprintln!("  {n}");
    }
    for f in &r.fallbacks {
        eprintln!("  fallback taken: {f}");
    }
    for w in &r.warnings {
        eprintln!("  warning: {w}");
    }
    for [a, b] in &r.rigid_pairs {
        eprintln!("  not checked: {a} – {b} (one rigid body: joined by fixed joints)");
    }
    Ok(())
}

fn tables(args: TablesArgs) -> Result<()> {
    let robot = FittedRobot::load(&args.robot)?;
    let settings = ClearanceSettings { max_loss: args.max_loss, max_cells: args.max_cells, threads: 0 };
    let start = Instant::now();
    let files = build_clearance_tables(&robot, &settings, &|message| eprintln!("{message}"))?;
    let n = files.len();
    let robot = robot.with_clearance(files)?;
    let output = args.output.unwrap_or(args.robot);
    robot.save(&output)?;
    let cells: usize = robot.clearance.iter().map(|t| t.len()).sum();
    eprintln!("{n} clearance tables, {cells} cells, {:.1} s -> {}", start.elapsed().as_secs_f64(), output.display());
    Ok(())
}

/// Reads `Q.csv`: the joint names of the header and the rows, as full configurations of `robot`
/// (joints not listed from `defaults`, else 0).
fn read_configs(path: &std::path::Path, robot: &FittedRobot, defaults: &[(String, Real)]) -> Result<Vec<Vec<Real>>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?;
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<String> = lines
        .next()
        .ok_or_else(|| Error::invalid("configs", "empty file: expected a header of joint names"))?
        .split(',')
        .map(|s| s.trim().to_owned())
        .collect();
    let mut values = Vec::new();
    for (row, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != header.len() {
            return Err(Error::invalid(
                format!("configs.row[{row}]"),
                format!("{} values for the {} columns of the header", cells.len(), header.len()),
            ));
        }
        for (c, cell) in cells.iter().enumerate() {
            values.push(cell.parse::<Real>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                Error::invalid(format!("configs.row[{row}].{}", header[c]), format!("`{cell}` is not a finite number"))
            })?);
        }
    }
    robot.model.configurations("configs", &header, &values, defaults).map_err(|e| match e {
        Error::InvalidArgument { field, reason } => {
            Error::InvalidArgument { field: field.replacen("configs.joint_names", "configs.header", 1), reason }
        }
        other => other,
    })
}

fn check(args: CheckArgs) -> Result<()> {
    let robot = FittedRobot::load(&args.robot)?;
    let scene = match &args.scene {
        Some(path) => {
            let bytes = std::fs::read(path)
                .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display())))?;
            if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
                PlanningScene::from_json(&bytes)?
            } else {
                PlanningScene::from_yaml(&bytes)?
            }
        }
        None => PlanningScene::default(),
    };
    let (world, skipped) = world_objects(&scene)?;
    for s in &skipped {
        eprintln!("warning: {}[{}] ({}) left out: {}", s.object_id, s.shape_index, s.kind, s.reason);
    }
    let configs = read_configs(&args.configs, &robot, &scene.joint_positions)?;
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(&robot, world, &allowed)?;
    checker.set_fidelity(args.fidelity.level()?)?;
    let options = CheckOptions {
        padding: args.padding,
        distance: !args.no_distance,
        self_collision: !args.no_self,
        gradient: args.gradient,
    };
    let base = Isometry3::identity();
    // Every configuration through the block path: its verdicts are the single check's; with a
    // distance asked (the default here) it checks each configuration alone.
    let start = Instant::now();
    let flat: Vec<Real> = configs.iter().flatten().copied().collect();
    let mut answers = Vec::with_capacity(configs.len());
    checker.check_block(&flat, &base, &options, false, &mut answers).map_err(|e| match e {
        Error::InvalidArgument { field, reason } => Error::InvalidArgument {
            field: match field.strip_prefix("configurations[") {
                Some(rest) => format!("configs.row[{rest}"),
                None if field == "padding" => "--padding".to_owned(),
                None => format!("configs.{field}"),
            },
            reason,
        },
        other => other,
    })?;
    let seconds = start.elapsed().as_secs_f64();
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    if !args.json {
        writeln!(out, "{:>6} {:>8} {:>6} {:>5} {:>12}  pair", "config", "collides", "world", "self", "distance_m")?;
    }
    let (mut colliding, mut unconverged) = (0usize, 0usize);
    for (i, a) in answers.iter().enumerate() {
        colliding += usize::from(a.collides);
        unconverged += usize::from(!a.converged);
        let name = |g: usize| robot.geometries[g].name.clone();
        let pair = match (a.world, a.self_pair) {
            (false, Some((x, y))) if a.self_collision && a.pair.is_none() => Some((name(x), name(y))),
            _ => a.pair.map(|(g, o)| (name(g), checker.world()[o].name.clone())),
        };
        let self_pair = a.self_pair.map(|(x, y)| (name(x), name(y)));
        if args.json {
            let line = serde_json::json!({
                "config": i,
                "collides": a.collides,
                "world": a.world,
                "self": a.self_collision,
                "distance": if a.distance.is_finite() { serde_json::json!(a.distance) } else { serde_json::Value::Null },
                "pair": pair.as_ref().map(|(x, y)| [x, y]),
                "self_pair": self_pair.as_ref().map(|(x, y)| [x, y]),
                "converged": a.converged,
                "fidelity": a.fidelity.name(),
                "gradient": &a.gradient,
            });
            writeln!(out, "{line}")?;
        } else {
            let shown = match (&pair, &self_pair) {
                (_, Some((x, y))) if a.self_collision && !a.world => format!("{x} – {y} (self)"),
                (Some((x, y)), _) => format!("{x} – {y}"),
                _ => String::new(),
            };
            writeln!(
                out,
                "{i:>6} {:>8} {:>6} {:>5} {:>12.6}  {shown}",
                a.collides, a.world, a.self_collision, a.distance
            )?;
        }
    }
    out.flush()?;
    eprintln!(
        "{} configurations, {colliding} colliding, {unconverged} not converged; {:.1} µs per configuration (one thread)",
        configs.len(),
        1e6 * seconds / configs.len().max(1) as Real
    );
    Ok(())
}
