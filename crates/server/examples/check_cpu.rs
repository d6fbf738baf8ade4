//! The server's CPU time per `CheckConfigurations` request, measured from outside the server.
//!
//! ```text
//! cargo run --release -p sublevel-server --example check_cpu -- [--server BIN] [--requests 20000]
//!                                                             [--columns 1] [--scene SCENE.yaml]
//! ```
//!
//! A server runs as a child process on a loopback port over a temporary data directory: `BIN
//! serve` when `--server` names a `sublevel` binary, else this example itself (the server of this
//! checkout, on CPUs − 1 async workers as `sublevel serve` runs). The fitted Panda
//! (`data/robots/panda/panda.robot.json`) is uploaded and a MotionBenchMaker scene imported
//! (`bookshelf_small/scene0001.yaml` unless `--scene`); then one client sends `--requests`
//! requests of `--columns` configurations each (drawn uniformly within the joint limits, 64
//! distinct requests in turn), one at a time, after a warm-up ([`warm_up`]). The figure is the child's
//! user + system CPU time (`/proc/PID/stat`, in 10 ms ticks: enough requests make it precise)
//! over those requests, divided by their number; the client's wall time per request beside it.
//! `--floor` measures `ListRobots` requests the same way: what any small request costs the server
//! (HTTP/2, tonic, the service's layers) beside its check.
//!
//! `--in-process` calls the service's `CheckConfigurations` handler directly instead, on this
//! process's current-thread runtime, no transport: the CPU time of this process (its blocking
//! threads included) per request is the handler's own cost. It also times what every request
//! paid before the server kept its checkers: reading the robot's world from the catalog and
//! building a checker of it (`Catalog::robot_world`, `RobotChecker::new`, `set_link_padding`).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Instant;
use sublevel_server::pb::{self, sublevel_client::SublevelClient};

/// Clock ticks per second of `/proc/PID/stat` (USER_HZ, 100 on Linux).
const TICKS_PER_SECOND: f64 = 100.0;

type Failure = Box<dyn std::error::Error>;

fn main() -> Result<(), Failure> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("serve-child") {
        return serve_child(Path::new(&args[2]));
    }
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let requests: usize = flag("--requests").map_or(Ok(20_000), |v| v.parse())?;
    let columns: usize = flag("--columns").map_or(Ok(1), |v| v.parse())?;
    let floor = args.iter().any(|a| a == "--floor");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scene = flag("--scene")
        .map_or_else(|| root.join("data/robots/mbm_panda/scenes/bookshelf_small/scene0001.yaml"), PathBuf::from);
    if args.iter().any(|a| a == "--in-process") {
        return in_process(&root, &scene, requests, columns);
    }
    let dir = std::env::temp_dir().join(format!("sublevel-check-cpu-{}", std::process::id()));
    let mut child = match flag("--server") {
        Some(bin) => Command::new(bin)
            .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
            .arg(&dir)
            .stdout(Stdio::piped())
            .spawn()?,
        None => Command::new(std::env::current_exe()?).arg("serve-child").arg(&dir).stdout(Stdio::piped()).spawn()?,
    };
    let outcome = measure(&mut child, &root, &scene, requests, columns, floor);
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
    outcome
}

/// Runs this checkout's server on `dir` until killed, printing `listening on ADDR`.
fn serve_child(dir: &Path) -> Result<(), Failure> {
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get().saturating_sub(1).max(1));
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(workers).enable_all().build()?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        println!("listening on {}", listener.local_addr()?);
        let config = sublevel_server::ServerConfig { data_dir: dir.to_owned(), ..Default::default() };
        sublevel_server::serve(listener, config, std::future::pending()).await?;
        Ok(())
    })
}

/// The user + system CPU seconds of process `pid` (`self`: this one).
fn cpu_seconds(pid: impl std::fmt::Display) -> Result<f64, Failure> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the command name (which may hold spaces) in parentheses: state is field 3,
    // utime and stime are fields 14 and 15.
    let rest = &stat[stat.rfind(')').ok_or("no command name in /proc/PID/stat")? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>()? + fields[12].parse::<f64>()?;
    Ok(ticks / TICKS_PER_SECOND)
}

fn measure(
    child: &mut Child,
    root: &Path,
    scene: &Path,
    requests: usize,
    columns: usize,
    floor: bool,
) -> Result<(), Failure> {
    let stdout = child.stdout.take().ok_or("no stdout")?;
    let mut lines = BufReader::new(stdout).lines();
    let addr = loop {
        let line = lines.next().ok_or("the server ended before it listened")??;
        if let Some(addr) = line.strip_prefix("listening on ") {
            break addr.to_owned();
        }
    };
    // Keep draining the child's stdout so it never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    let pid = child.id();
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(async move {
        let mut c = SublevelClient::connect(format!("http://{addr}")).await?;
        let robot_file = std::fs::read(root.join("data/robots/panda/panda.robot.json"))?;
        let robot = c
            .upload_robot(pb::UploadRobotRequest { name: "panda".into(), robot_file })
            .await?
            .into_inner()
            .robot
            .ok_or("no robot")?;
        let yaml = std::fs::read(scene)?;
        let scene_id = c
            .import_scene(pb::ImportSceneRequest {
                scene: Some(pb::import_scene_request::Scene::Yaml(yaml)),
                ..Default::default()
            })
            .await?
            .into_inner()
            .scene_id;
        let reqs = requests_of(&robot, &scene_id, columns);
        let mut colliding = 0usize;
        for k in 0..warm_up(columns) {
            c.check_configurations(reqs[k % reqs.len()].clone()).await?;
        }
        if floor {
            let req = pb::ListRobotsRequest {};
            let cpu0 = cpu_seconds(pid)?;
            let start = Instant::now();
            for _ in 0..requests {
                c.list_robots(req).await?;
            }
            let wall = start.elapsed().as_secs_f64();
            let cpu = cpu_seconds(pid)? - cpu0;
            println!(
                "{requests} ListRobots requests: server CPU {:.1} µs per request, client wall {:.1} µs per request",
                1e6 * cpu / requests as f64,
                1e6 * wall / requests as f64
            );
        }
        let cpu0 = cpu_seconds(pid)?;
        let start = Instant::now();
        for k in 0..requests {
            let answer = c.check_configurations(reqs[k % reqs.len()].clone()).await?.into_inner();
            colliding += answer.collides.iter().filter(|&&x| x).count();
        }
        let wall = start.elapsed().as_secs_f64();
        let cpu = cpu_seconds(pid)? - cpu0;
        println!(
            "{requests} requests of {columns} configuration(s) ({colliding} colliding answers): server CPU {:.1} µs per \
             request ({:.2} µs per configuration), client wall {:.1} µs per request",
            1e6 * cpu / requests as f64,
            1e6 * cpu / (requests * columns) as f64,
            1e6 * wall / requests as f64
        );
        Ok(())
    })
}

/// Requests sent before the measured ones: 1000, or fewer of many configurations (64 000
/// configurations, at least 64 requests).
fn warm_up(columns: usize) -> usize {
    (64_000 / columns.max(1)).clamp(64, 1000)
}

/// 64 distinct requests of `columns` configurations each, uniform within the joint limits
/// (xorshift draws).
fn requests_of(robot: &pb::RobotSummary, scene_id: &str, columns: usize) -> Vec<pb::CheckConfigurationsRequest> {
    let mut state = 0x9E37_79B9_7F4A_7C15_u64;
    let mut draw = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..64)
        .map(|_| pb::CheckConfigurationsRequest {
            robot_id: robot.robot_id.clone(),
            scene_id: scene_id.to_owned(),
            configurations: Some(pb::ConfigurationColumns {
                joint_names: Vec::new(),
                values: (0..columns)
                    .flat_map(|_| {
                        robot.lower.iter().zip(&robot.upper).map(|(lo, hi)| lo + (hi - lo) * draw()).collect::<Vec<_>>()
                    })
                    .collect(),
            }),
            ..Default::default()
        })
        .collect()
}

/// The handler alone: a service over a temporary catalog, called without transport.
fn in_process(root: &Path, scene: &Path, requests: usize, columns: usize) -> Result<(), Failure> {
    use sublevel_server::pb::sublevel_server::Sublevel;
    use tonic::Request;
    let dir = std::env::temp_dir().join(format!("sublevel-check-cpu-{}", std::process::id()));
    let config = sublevel_server::ServerConfig { data_dir: dir.clone(), ..Default::default() };
    let catalog = sublevel_server::open_catalog(&config)?;
    let svc = sublevel_server::SublevelService::new(catalog.clone(), config);
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let outcome = runtime.block_on(async {
        let robot_file = std::fs::read(root.join("data/robots/panda/panda.robot.json"))?;
        let robot = svc
            .upload_robot(Request::new(pb::UploadRobotRequest { name: "panda".into(), robot_file }))
            .await?
            .into_inner()
            .robot
            .ok_or("no robot")?;
        let yaml = std::fs::read(scene)?;
        let import =
            pb::ImportSceneRequest { scene: Some(pb::import_scene_request::Scene::Yaml(yaml)), ..Default::default() };
        let scene_id = svc.import_scene(Request::new(import)).await?.into_inner().scene_id;
        let reqs = requests_of(&robot, &scene_id, columns);
        for k in 0..warm_up(columns) {
            svc.check_configurations(Request::new(reqs[k % reqs.len()].clone())).await?;
        }
        let mut colliding = 0usize;
        let cpu0 = cpu_seconds("self")?;
        let start = Instant::now();
        for k in 0..requests {
            let answer = svc.check_configurations(Request::new(reqs[k % reqs.len()].clone())).await?.into_inner();
            colliding += answer.collides.iter().filter(|&&x| x).count();
        }
        let wall = start.elapsed().as_secs_f64();
        let cpu = cpu_seconds("self")? - cpu0;
        println!(
            "in process, {requests} handler calls of {columns} configuration(s) ({colliding} colliding answers): CPU \
             {:.1} µs per call ({:.2} µs per configuration), wall {:.1} µs per call",
            1e6 * cpu / requests as f64,
            1e6 * cpu / (requests * columns) as f64,
            1e6 * wall / requests as f64
        );

        // What each request paid before: the world read and a checker built.
        let robot = catalog.robot(&robot.robot_id)?.robot.clone();
        let builds = 20_000;
        let cpu0 = cpu_seconds("self")?;
        for _ in 0..builds {
            let world = catalog.robot_world(&scene_id)?;
            let allowed = world.planning.allowed_override();
            let mut checker = sublevel_robot::RobotChecker::new(&robot, world.objects.clone(), &allowed)?;
            checker.set_link_padding(&[])?;
            std::hint::black_box(&checker);
        }
        let cpu = cpu_seconds("self")? - cpu0;
        println!("  the world read and a checker built: CPU {:.1} µs each ({builds} times)", 1e6 * cpu / builds as f64);
        Ok::<_, Failure>(())
    });
    let _ = std::fs::remove_dir_all(&dir);
    outcome
}
