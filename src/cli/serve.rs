//! `sublevel serve --addr 127.0.0.1:50051 --data-dir DIR [--demo]`: runs the gRPC server until
//! Ctrl-C (or SIGTERM), logging with `tracing` to stderr (filter with `RUST_LOG`, default `info`);
//! stdout carries only the demo ids and the `listening on ADDR` line.
//!
//! `--demo` makes sure the store holds two bodies named `chair_101` and `human_10` (embedded in
//! the binary) and a scene `demo` with one instance of each, side by side; the fitted Panda
//! (`data/robots/panda/panda.robot.json`, embedded) as the robot `panda`; and the MotionBenchMaker
//! planning scene `bookshelf_small/scene0001.yaml` (embedded) imported as the scene `mbm_bookshelf`
//! with the Panda placed in it at the origin, at the scene's joint positions. It prints their ids;
//! a second start finds them by name and adds nothing.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use sublevel::body::BodyFile;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::robot::RobotFile;
use sublevel::scene::moveit::{ImportPlan, MeshImport, PlanningScene};
use sublevel::scene::{Catalog, SceneRobot, StoredPose};
use sublevel::service::{open_catalog, serve_catalog, ServerConfig};
use sublevel::{Body, Error, Result};

/// The demo chair (a degree-4 fit of `chair_101.off`, in body-file JSON).
const DEMO_CHAIR: &str = include_str!("../../data/demo/chair_101.json");
/// The demo human (a degree-4 fit of `human_10.off`, in body-file JSON).
const DEMO_HUMAN: &str = include_str!("../../data/demo/human_10.json");
/// Name of the demo scene.
const DEMO_SCENE: &str = "demo";
/// The demo robot: the Panda fitted from its URDF, SRDF and meshes (`sublevel robot fit`, a
/// robot file of about 1.2 MB).
const DEMO_PANDA: &str = include_str!("../../data/robots/panda/panda.robot.json");
/// Name of the demo robot.
const DEMO_ROBOT: &str = "panda";
/// The demo planning scene: MotionBenchMaker's first `bookshelf_small` scene for the Panda
/// (MoveIt YAML, primitives only).
const DEMO_MBM_SCENE: &[u8] = include_bytes!("../../data/robots/mbm_panda/scenes/bookshelf_small/scene0001.yaml");
/// Name of the scene imported from [`DEMO_MBM_SCENE`].
const DEMO_MBM_SCENE_NAME: &str = "mbm_bookshelf";

/// Arguments of `sublevel serve`.
#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "SUBLEVEL_ADDR", default_value = "127.0.0.1:50051")]
    addr: SocketAddr,
    /// Directory of the database (created if missing).
    #[arg(long, env = "SUBLEVEL_DATA_DIR", default_value = "./sublevel-data")]
    data_dir: PathBuf,
    /// Preload the demo bodies `chair_101`, `human_10` and the scene `demo`, the robot `panda` and
    /// the scene `mbm_bookshelf` holding it (idempotent).
    #[arg(long, env = "SUBLEVEL_DEMO")]
    demo: bool,
    /// Async worker threads (connections, HTTP/2, small queries). Default: one less than the
    /// CPUs, at least one — the rest is left to the blocking pool (certificates, fits, large
    /// batches) and to co-located clients. On a 2-core machine one worker answers a planner's 20-pair
    /// stream step in ~100 µs p50 against ~150 µs with two (docs/performance.md).
    #[arg(long, env = "SUBLEVEL_ASYNC_WORKERS")]
    async_workers: Option<usize>,
    /// Shutdown grace, TLS and authentication (`cli::serve_ops`).
    #[command(flatten)]
    security: super::serve_ops::SecurityArgs,
    /// Limits, metrics, log format and the config file (`cli::serve_config`).
    #[command(flatten)]
    pub ops: super::serve_config::OpsArgs,
}

/// The default number of async workers: CPUs − 1, at least 1.
fn default_async_workers() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get().saturating_sub(1).max(1))
}

/// Runs `sublevel serve`.
pub fn run(args: ServeArgs) -> Result<()> {
    super::serve_config::init_logging(args.ops.log_format);
    let workers = args.async_workers.unwrap_or_else(default_async_workers);
    if workers == 0 {
        return Err(Error::invalid("--async-workers", "must be at least 1"));
    }
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(workers).enable_all().build()?;
    let outcome = runtime.block_on(async move {
        let shutdown = shutdown_signal()?;
        let mut config = ServerConfig { data_dir: args.data_dir.clone(), ..ServerConfig::default() };
        args.ops.apply(&mut config)?;
        args.security.apply(&mut config)?;
        super::serve_config::start_metrics(&args.ops).await?;
        let catalog = open_catalog(&config)?;
        if args.demo {
            let demo = seed_demo(&catalog)?;
            println!("demo: body chair_101 = {}", demo.chair);
            println!("demo: body human_10  = {}", demo.human);
            println!("demo: scene demo     = {} (instances {}, {})", demo.scene, demo.instances[0], demo.instances[1]);
            println!("demo: robot panda = {}", demo.robot);
            println!("demo: scene mbm_bookshelf = {} (robot panda)", demo.mbm_scene);
        }
        let listener = tokio::net::TcpListener::bind(args.addr).await?;
        let addr = listener.local_addr()?;
        tracing::info!(%addr, data_dir = %args.data_dir.display(), "listening");
        // On stdout too, for scripts and tests that bind port 0.
        println!("listening on {addr}");
        serve_catalog(listener, catalog, config, shutdown).await
    });
    // The server waited (within --shutdown-grace) for requests to drain and cancelled jobs to
    // record their end; whatever still runs on the blocking pool now is abandoned.
    runtime.shutdown_background();
    outcome
}

/// A future that completes on Ctrl-C or (on Unix) SIGTERM, as sent by `docker stop` and
/// Kubernetes. The handlers are installed now, before the server announces its address, so a
/// signal that arrives at any later moment stops the server gracefully (a handler installed on
/// first poll would leave a window in which SIGTERM kills the process outright).
fn shutdown_signal() -> Result<impl std::future::Future<Output = ()>> {
    #[cfg(unix)]
    let (mut interrupt, mut term) = {
        use tokio::signal::unix::{signal, SignalKind};
        (signal(SignalKind::interrupt())?, signal(SignalKind::terminate())?)
    };
    Ok(async move {
        #[cfg(unix)]
        tokio::select! {
            _ = interrupt.recv() => {},
            _ = term.recv() => {},
        }
        #[cfg(not(unix))]
        if let Err(e) = tokio::signal::ctrl_c().await {
            tracing::error!(error = %e, "cannot listen for Ctrl-C");
            std::future::pending::<()>().await;
        }
        tracing::info!("shutdown requested");
    })
}

/// Ids of the demo data.
struct Demo {
    chair: String,
    human: String,
    scene: String,
    instances: [String; 2],
    robot: String,
    mbm_scene: String,
}

/// Finds a body by name, or stores the embedded one.
fn ensure_body(catalog: &Catalog, name: &str, json: &str) -> Result<String> {
    if let Some(e) = catalog.bodies().into_iter().find(|e| e.name == name) {
        return Ok(e.id.clone());
    }
    let file: BodyFile = serde_json::from_str(json)?;
    let body =
        Body::from_file(file).map_err(|e| Error::invalid(format!("embedded demo body {name}"), e.to_string()))?;
    catalog.add_body(name, body)
}

/// Seeds (or finds) the demo bodies and scene. The human stands beside the chair, one combined
/// "radius" (normalization scales) away along x, so they start apart.
fn seed_demo(catalog: &Arc<Catalog>) -> Result<Demo> {
    let chair = ensure_body(catalog, "chair_101", DEMO_CHAIR)?;
    let human = ensure_body(catalog, "human_10", DEMO_HUMAN)?;
    let scene = match catalog.scenes().into_iter().find(|s| s.name == DEMO_SCENE) {
        Some(s) => s.id,
        None => catalog.create_scene(DEMO_SCENE)?,
    };
    let view = catalog.get_scene(&scene)?;
    let find = |body: &str| view.instances.iter().find(|i| i.body_id == body).map(|i| i.id.clone());
    let chair_body = catalog.body(&chair)?;
    let human_body = catalog.body(&human)?;
    let gap = 1.5 * (chair_body.body()?.scale() + human_body.body()?.scale());
    let at = |x: f64| -> Result<Isometry3> { pose_from_parts("demo pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, 0.0]) };
    let i_chair = match find(&chair) {
        Some(id) => id,
        None => catalog.add_instance(&scene, &chair, at(0.0)?)?,
    };
    let i_human = match find(&human) {
        Some(id) => id,
        None => catalog.add_instance(&scene, &human, at(gap)?)?,
    };
    let robot = ensure_robot(catalog)?;
    let mbm_scene = ensure_robot_scene(catalog, &robot)?;
    Ok(Demo { chair, human, scene, instances: [i_chair, i_human], robot, mbm_scene })
}

/// Finds the robot named `panda`, or stores the embedded one. Building it (its bodies and its
/// meshes' BVHs) takes a fraction of a second on a release build.
fn ensure_robot(catalog: &Catalog) -> Result<String> {
    if let Some(e) = catalog.robots().into_iter().find(|e| e.name == DEMO_ROBOT) {
        return Ok(e.id.clone());
    }
    let file: RobotFile = serde_json::from_str(DEMO_PANDA)?;
    let entry =
        catalog.add_robot(DEMO_ROBOT, file).map_err(|e| Error::invalid("embedded demo robot panda", e.to_string()))?;
    Ok(entry.id.clone())
}

/// Finds the scene named `mbm_bookshelf`, or imports the embedded planning scene under that name
/// (as `ImportScene` does: one primitive body per distinct shape, the objects as named
/// instances, the allowed-collision matrix and the robot state kept with the scene). Places
/// robot `robot_id` in it at the origin (MotionBenchMaker's virtual joint is the identity) unless
/// it already holds that robot; the scene's joint positions stay those of its robot state.
fn ensure_robot_scene(catalog: &Catalog, robot_id: &str) -> Result<String> {
    let scene_id = match catalog.scenes().into_iter().find(|s| s.name == DEMO_MBM_SCENE_NAME) {
        Some(s) => s.id,
        None => {
            let invalid = |e: Error| Error::invalid("embedded demo scene mbm_bookshelf", e.to_string());
            let parsed = PlanningScene::from_yaml(DEMO_MBM_SCENE).map_err(invalid)?;
            let plan = ImportPlan::new(&parsed, MeshImport::Skip).map_err(invalid)?;
            catalog.import_plan(DEMO_MBM_SCENE_NAME, &plan)?.scene_id
        }
    };
    // A robot deleted since it was placed reads as an error here: place the demo robot again.
    let placed = catalog.placed_robot(&scene_id).ok().flatten();
    if placed.is_none_or(|p| p.robot_id != robot_id) {
        let record = SceneRobot {
            robot_id: robot_id.to_owned(),
            base: StoredPose::from_isometry(&Isometry3::identity()),
            attached: Vec::new(),
            link_padding: Vec::new(),
        };
        catalog.set_scene_robot(&scene_id, record, None)?;
    }
    Ok(scene_id)
}
