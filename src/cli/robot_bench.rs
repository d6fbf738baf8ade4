//! `sublevel robot bench`: the speed of configuration checks, in process on one thread and over
//! gRPC in columns, on one robot in one planning scene.
//!
//! ```text
//! sublevel robot bench robot.json --scene SCENE.yaml [--samples 1000] [--batch 64] [--repeats 5]
//!                      [--columns 1000] [--concurrency 2] [--seconds 3] [--addr HOST:PORT] [--json OUT]
//! ```
//!
//! The configurations are `--samples` uniform draws within the joint limits (continuous joints in
//! [−π, π]), seeded (`--seed`), as a sampling planner draws its states. In process, on this
//! thread ([`RobotChecker`], the server's own code):
//!
//! - **single**: every configuration checked alone (verdict: world and self), each call timed;
//! - **block**: blocks of [`BLOCK`] (8) configurations, one [`RobotChecker::check_block`] call
//!   each (the SIMD kernel decides the lanes it can), time per configuration, beside the same
//!   blocks checked one `check` call per configuration (the single path's mean per block);
//! - **batch**: the same for blocks of `--batch` configurations;
//! - **distance**: the verdict plus the minimum robot–world distance, each call timed.
//!
//! Each figure is the median over every timing of `--repeats` passes over the configurations;
//! the block verdicts are compared with the single ones (a disagreement is an error).
//!
//! Over gRPC: the robot uploaded and the scene imported into a server (`--addr`, else one started
//! in this process on a loopback port over a temporary data directory), then `--concurrency`
//! client tasks, each on its own connection, send `CheckConfigurations` requests of `--columns`
//! configurations in a closed loop for `--seconds`: configurations per second over all tasks and
//! the request latency (p50, p99). What it uploaded and imported is deleted at the end.

use super::loadtest::{connect, endpoint};
use hdrhistogram::Histogram;
use rand::{Rng, SeedableRng};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use sublevel::math::{Isometry3, Real};
use sublevel::robot::{CheckOptions, FittedRobot, RobotChecker, BLOCK};
use sublevel::scene::moveit::{allowed_override, world_objects, PlanningScene};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::{Error, Result};

/// Arguments of `sublevel robot bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// The robot file (`sublevel robot fit`).
    robot: PathBuf,
    /// The world: a MoveIt planning scene (YAML, or JSON for `.json`).
    #[arg(long)]
    scene: PathBuf,
    /// Configurations drawn uniformly within the joint limits.
    #[arg(long, default_value_t = 1000)]
    samples: usize,
    /// Seed of the draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Configurations per block of the in-process batch figure.
    #[arg(long, default_value_t = 64)]
    batch: usize,
    /// Passes over the configurations of each in-process figure (its median is over all of them).
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Configurations per `CheckConfigurations` request.
    #[arg(long, default_value_t = 1000)]
    columns: usize,
    /// gRPC client tasks, each on its own connection.
    #[arg(long, default_value_t = 2)]
    concurrency: usize,
    /// Seconds of the gRPC load (0 skips it).
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// A running server, `host:port`; absent: one started in this process on a loopback port.
    #[arg(long)]
    addr: Option<String>,
    /// Write the figures as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    fidelity: super::fidelity::FidelityArgs,
}

/// Runs `sublevel robot bench`.
///
/// # Errors
/// Files that cannot be read or do not validate, bad arguments (named), a server that cannot be
/// reached or refuses the robot or the scene.
pub fn run(args: BenchArgs) -> Result<()> {
    if args.samples == 0 || args.batch == 0 || args.columns == 0 || !(1..=64).contains(&args.concurrency) {
        return Err(Error::invalid(
            "--samples/--batch/--columns/--concurrency",
            "must be ≥ 1 (concurrency at most 64)",
        ));
    }
    if !(1..=1000).contains(&args.repeats) {
        return Err(Error::invalid("--repeats", format!("must be in [1, 1000], got {}", args.repeats)));
    }
    if !(args.seconds.is_finite() && (0.0..=600.0).contains(&args.seconds)) {
        return Err(Error::invalid("--seconds", format!("must be in [0, 600], got {}", args.seconds)));
    }
    let robot = FittedRobot::load(&args.robot)?;
    let scene_bytes = std::fs::read(&args.scene)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", args.scene.display())))?;
    let is_json = args.scene.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let scene = if is_json { PlanningScene::from_json(&scene_bytes)? } else { PlanningScene::from_yaml(&scene_bytes)? };
    let configs = samples(&robot, args.samples, args.seed);

    let (world, _) = world_objects(&scene)?;
    let allowed = allowed_override(&scene);
    let mut checker = RobotChecker::new(&robot, world, &allowed)?;
    let level = args.fidelity.level()?;
    checker.set_fidelity(level)?;
    let base = Isometry3::identity();
    let verdict = CheckOptions { distance: false, ..CheckOptions::default() };
    let repeats = args.repeats;
    // The single verdicts, the reference of the block ones.
    let verdicts: Vec<bool> =
        configs.iter().map(|q| checker.check(q, &base, &verdict).map(|a| a.collides)).collect::<Result<_>>()?;
    let colliding = verdicts.iter().filter(|&&c| c).count();
    let single = median((0..repeats).flat_map(|_| configs.iter()).map(|q| {
        let start = Instant::now();
        let a = checker.check(q, &base, &verdict);
        a.map(|_| start.elapsed().as_secs_f64())
    }))?;
    let mut disagreements = 0usize;
    let mut blocks = |size: usize, checker: &mut RobotChecker| -> Result<Real> {
        let mut flat = Vec::new();
        let mut out = Vec::new();
        let mut times = Vec::new();
        for _ in 0..repeats {
            for (k, block) in configs.chunks(size).enumerate() {
                flat.clear();
                flat.extend(block.iter().flatten());
                out.clear();
                let start = Instant::now();
                checker.check_block(&flat, &base, &verdict, false, &mut out)?;
                times.push(start.elapsed().as_secs_f64() / block.len() as Real);
                // At a conservative level the two paths may differ in false collisions only.
                let expected = &verdicts[k * size..k * size + block.len()];
                disagreements += out.iter().zip(expected).filter(|(a, &e)| a.collides != e && level.is_mesh()).count();
            }
        }
        median(times.into_iter().map(Ok))
    };
    let block = blocks(BLOCK, &mut checker)?;
    let batch = blocks(args.batch, &mut checker)?;
    if disagreements > 0 {
        return Err(Error::Numerical(format!(
            "{disagreements} block verdicts differ from the single checks' (over {repeats} passes)"
        )));
    }
    // The same blocks, one `check` call per configuration: the single path's mean per block.
    let singles = |size: usize, checker: &mut RobotChecker| {
        median((0..repeats).flat_map(|_| configs.chunks(size)).map(|block| {
            let start = Instant::now();
            for q in block {
                checker.check(q, &base, &verdict)?;
            }
            Ok(start.elapsed().as_secs_f64() / block.len() as Real)
        }))
    };
    let block_single = singles(BLOCK, &mut checker)?;
    let batch_single = singles(args.batch, &mut checker)?;
    let distance = median((0..repeats).flat_map(|_| configs.iter()).map(|q| {
        let start = Instant::now();
        checker.check(q, &base, &CheckOptions::default()).map(|_| start.elapsed().as_secs_f64())
    }))?;
    println!(
        "{} configurations ({colliding} colliding), {} world objects, one thread, medians over {repeats} passes:",
        configs.len(),
        checker.world().len()
    );
    println!("  single           median {:>9.2} µs per configuration", 1e6 * single);
    println!("  block of {:<6}  median {:>9.2} µs per configuration (check_block)", BLOCK, 1e6 * block);
    println!("  block of {:<6}  median {:>9.2} µs per configuration (check, one by one)", BLOCK, 1e6 * block_single);
    println!("  batch of {:<6}  median {:>9.2} µs per configuration (check_block)", args.batch, 1e6 * batch);
    println!(
        "  batch of {:<6}  median {:>9.2} µs per configuration (check, one by one)",
        args.batch,
        1e6 * batch_single
    );
    println!("  with distance    median {:>9.2} µs per configuration", 1e6 * distance);

    let grpc = if args.seconds > 0.0 {
        let robot_json = std::fs::read(&args.robot)?;
        let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
        let figures = runtime.block_on(remote(&args, robot_json, scene_bytes, is_json, &configs))?;
        println!(
            "  gRPC, {} tasks × {} configurations per request: {:.0} configurations/s, request p50 {:.2} ms, p99 {:.2} ms ({} requests)",
            args.concurrency, args.columns, figures.per_second, figures.p50_ms, figures.p99_ms, figures.requests
        );
        Some(figures)
    } else {
        None
    };
    if let Some(path) = &args.json {
        let value = serde_json::json!({
            "samples": configs.len(),
            "colliding": colliding,
            "world_objects": checker.world().len(),
            "single_us": 1e6 * single,
            "batch": args.batch,
            "batch_us": 1e6 * batch,
            "distance_us": 1e6 * distance,
            "repeats": repeats,
            "block": BLOCK,
            "block_us": 1e6 * block,
            "fidelity": level.to_string(),
            "block_single_us": 1e6 * block_single,
            "batch_single_us": 1e6 * batch_single,
            "grpc": grpc.map(|g| serde_json::json!({
                "concurrency": args.concurrency,
                "columns": args.columns,
                "configurations_per_s": g.per_second,
                "request_p50_ms": g.p50_ms,
                "request_p99_ms": g.p99_ms,
                "requests": g.requests,
            })),
        });
        std::fs::write(path, serde_json::to_string_pretty(&value)? + "\n")?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// `n` configurations drawn uniformly within the joint limits (continuous joints in [−π, π]).
fn samples(robot: &FittedRobot, n: usize, seed: u64) -> Vec<Vec<Real>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let limits: Vec<(Real, Real)> = (0..robot.model.dof())
        .map(|k| robot.model.variable_joint(k).limits.unwrap_or((-std::f64::consts::PI, std::f64::consts::PI)))
        .collect();
    (0..n).map(|_| limits.iter().map(|&(lo, hi)| lo + (hi - lo) * rng.random::<Real>()).collect()).collect()
}

/// The median of timings (seconds).
fn median(times: impl Iterator<Item = Result<Real>>) -> Result<Real> {
    let mut t = times.collect::<Result<Vec<_>>>()?;
    t.sort_by(Real::total_cmp);
    Ok(t.get(t.len() / 2).copied().unwrap_or(Real::NAN))
}

/// What the gRPC load measured.
#[derive(Clone, Copy, Debug)]
struct Grpc {
    per_second: Real,
    p50_ms: Real,
    p99_ms: Real,
    requests: u64,
}

fn io(what: &str, e: impl std::fmt::Display) -> Error {
    Error::Io(std::io::Error::other(format!("{what}: {e}")))
}

/// A latency histogram: 1 µs to 10 minutes, 3 significant digits.
fn histogram() -> Result<Histogram<u64>> {
    Histogram::new_with_bounds(1, 600_000_000, 3).map_err(|e| io("histogram", e))
}

/// A directory removed when dropped.
struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Uploads, imports, loads, cleans up.
async fn remote(
    args: &BenchArgs,
    robot_json: Vec<u8>,
    scene_bytes: Vec<u8>,
    is_json: bool,
    configs: &[Vec<Real>],
) -> Result<Grpc> {
    let level = args.fidelity.level()?;
    // A server of our own when none is named, on a loopback port over a temporary directory.
    let mut own = None;
    let addr = match &args.addr {
        Some(a) => a.clone(),
        None => {
            let dir = TempDir(std::env::temp_dir().join(format!("sublevel-robot-bench-{}", std::process::id())));
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
            let addr = listener.local_addr()?.to_string();
            let config = sublevel::service::ServerConfig { data_dir: dir.0.clone(), ..Default::default() };
            let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
            let handle = tokio::spawn(sublevel::service::serve(listener, config, async move {
                let _ = stopped.await;
            }));
            own = Some((dir, stop, handle));
            addr
        }
    };
    let endpoint = endpoint(&addr)?;
    let mut admin = SublevelClient::new(connect(&endpoint).await?).max_decoding_message_size(usize::MAX);
    let robot = admin
        .upload_robot(pb::UploadRobotRequest { name: "bench".into(), robot_file: robot_json })
        .await
        .map_err(|s| io("UploadRobot", s))?
        .into_inner()
        .robot
        .ok_or_else(|| io("UploadRobot", "no robot in the answer"))?;
    let scene = pb::ImportSceneRequest {
        name: "robot-bench".into(),
        scene: Some(if is_json {
            pb::import_scene_request::Scene::Json(scene_bytes)
        } else {
            pb::import_scene_request::Scene::Yaml(scene_bytes)
        }),
        // Robot checks take exact primitives: a mesh's fitted body would be refused.
        skip_meshes: true,
        ..Default::default()
    };
    let imported = admin.import_scene(scene).await.map_err(|s| io("ImportScene", s))?.into_inner();

    let requests: Vec<pb::CheckConfigurationsRequest> = configs
        .chunks(args.columns)
        .filter(|c| c.len() == args.columns || configs.len() < args.columns)
        .map(|c| pb::CheckConfigurationsRequest {
            robot_id: robot.robot_id.clone(),
            scene_id: imported.scene_id.clone(),
            configurations: Some(pb::ConfigurationColumns {
                joint_names: Vec::new(),
                values: c.iter().flatten().copied().collect(),
            }),
            fidelity: Some(pb::Fidelity { level: level.name().to_owned(), tolerance: level.tolerance() }),
            ..Default::default()
        })
        .collect();
    let deadline = Duration::from_secs_f64(args.seconds);
    let start = Instant::now();
    let mut tasks = Vec::new();
    for task in 0..args.concurrency {
        let (endpoint, requests) = (endpoint.clone(), requests.clone());
        tasks.push(tokio::spawn(async move {
            let mut client = SublevelClient::new(connect(&endpoint).await?).max_decoding_message_size(usize::MAX);
            let mut latency = histogram()?;
            let mut done = 0u64;
            let mut k = task;
            while start.elapsed() < deadline {
                let req = requests[k % requests.len()].clone();
                k += 1;
                let sent = Instant::now();
                let answer = client.check_configurations(req).await.map_err(|s| io("CheckConfigurations", s))?;
                latency.saturating_record(sent.elapsed().as_micros() as u64);
                done += u64::from(answer.into_inner().count);
            }
            Ok::<_, Error>((done, latency))
        }));
    }
    let mut total = 0u64;
    let mut latency = histogram()?;
    let mut failure = None;
    for t in tasks {
        match t.await.map_err(|e| io("client task", e)).and_then(|r| r) {
            Ok((n, h)) => {
                total += n;
                latency.add(h).map_err(|e| io("histogram", e))?;
            }
            Err(e) => failure = Some(e),
        }
    }
    let seconds = start.elapsed().as_secs_f64();

    let _ = admin.delete_scene(pb::DeleteSceneRequest { scene_id: imported.scene_id.clone() }).await;
    let mut bodies: Vec<&String> = imported.instances.iter().map(|i| &i.body_id).collect();
    bodies.sort();
    bodies.dedup();
    for body_id in bodies {
        let _ = admin.delete_body(pb::DeleteBodyRequest { body_id: body_id.clone() }).await;
    }
    let _ = admin.delete_robot(pb::DeleteRobotRequest { robot_id: robot.robot_id }).await;
    if let Some((_dir, stop, handle)) = own {
        let _ = stop.send(());
        let _ = handle.await;
    }
    if let Some(e) = failure {
        return Err(e);
    }
    Ok(Grpc {
        per_second: total as Real / seconds,
        p50_ms: latency.value_at_quantile(0.5) as Real / 1e3,
        p99_ms: latency.value_at_quantile(0.99) as Real / 1e3,
        requests: latency.len(),
    })
}
