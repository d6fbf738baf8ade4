//! `sublevel cloud bench`: how fast a depth camera's frames become queryable obstacles, and, with
//! `--seconds`, whether a cloud replaced at sensor rate holds the server's memory flat.
//!
//! ```text
//! sublevel cloud bench [--addr HOST:PORT [--pid PID]] [--robot ROBOT.json] [--scene SCENE.yaml]
//!                      [--updates 300] [--warmup 10] [--rate 30] [--format both|depth|packed]
//!                      [--noise 0.002] [--frames 4] [--config Q1,…,Q7] [--json OUT]
//!                      [--seconds S [--check-rate 100] [--sample-every 10] [--max-rss-growth-mib M]]
//! ```
//!
//! **Frames.** The planning scene's world (`--scene`, a MoveIt YAML; default MotionBenchMaker's
//! `bookshelf_small/scene0001`) is rendered by the simulated depth camera
//! ([`sublevel::robot::cloud::render`]) at 640 × 480 (fx = fy = 554, the principal point at the
//! center) from a camera at `--eye` looking at `--target` (default (2, 0, 1.4) → (0.5, 0, 0.4),
//! the shelf seen from its front and above), out to 6 m, with Gaussian depth noise of σ `--noise`
//! meters; `--frames` frames of different noise draws are sent in turn. The scene stands in a
//! room — a floor at z = −5 cm and walls 3 m high, 3 m from the origin — so that, as in a real
//! camera's frame, every pixel has a depth (`--no-room`: the scene's objects alone, most pixels
//! holes). Each is sent as
//!
//! - **depth**: `depth_u16`, millimeters (a 16UC1 image, 614 400 bytes), deprojected on the server;
//! - **packed**: the same frame deprojected here into a `PointCloud2` body of float32 x, y, z
//!   records padded to 16 bytes (as `depth_image_proc` writes them), holes left out.
//!
//! Both take the camera pose as `sensor_pose` and the default filter (2 cm voxel grid) and
//! noise radius (1 cm).
//!
//! **Latency.** The server (`--addr`, else `sublevel serve` started as a child process on a
//! loopback port over a temporary data directory) gets the robot (`--robot`, default the fitted
//! Panda) uploaded into a new scene (`SetSceneRobot` at `--config`, default the MotionBenchMaker
//! start state). Per format, after `--warmup` updates, `--updates` are sent at `--rate` Hz (0:
//! back to back), each followed at once by one `CheckConfigurations` of `--config` against the
//! scene's robot: the update's round trip (request sent → answer), the server's own `seconds`, the
//! points kept, and the first check's answer after the update (from the update sent, and alone)
//! are reported as median, p95 and max (hdrhistogram, µs resolution). Every check must read the
//! update's scene version or a later one.
//!
//! **Soak** (`--seconds`): the same loop for that long (formats alternating with `--format both`)
//! while a second connection sends one-configuration checks at `--check-rate` Hz (0: back to
//! back), and the server's resident memory (`VmRSS` of `/proc/PID/status`: the child's, or
//! `--pid` for a server at `--addr` on this machine) is sampled every `--sample-every` seconds.
//! The series, first, last and max are printed, and the growth from the second sample on (the
//! first interval holds the warm-up: connections, frame buffers, the allocator's first pages);
//! `--max-rss-growth-mib` fails the run when that growth exceeds it.

mod tally;

use super::cloud::{bearer, depth_u16_image, io, numbers, packed_points, request, status};
use hdrhistogram::Histogram;
use std::io::BufRead;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use sublevel::math::{Isometry3, Vector3};
use sublevel::primitive::Primitive;
use sublevel::robot::cloud::depth::{deproject, DepthPixels, Intrinsics};
use sublevel::robot::cloud::render::{look_at, render_depth, DepthNoise};
use sublevel::robot::world::WorldObject;
use sublevel::scene::moveit::{world_objects, PlanningScene};
use sublevel::service::convert::pose_to_proto;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::{Error, Result};
use tally::{histogram, micros, Tally};
use tonic::metadata::{Ascii, MetadataValue};
use tonic::transport::Channel;

/// The simulated camera: 640 × 480, a 60° horizontal field of view.
const CAMERA: Intrinsics = Intrinsics { width: 640, height: 480, fx: 554.0, fy: 554.0, cx: 319.5, cy: 239.5 };

/// The cloud's name in the scene.
const CLOUD: &str = "camera";

/// Which frames are sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FrameFormat {
    /// Both, one after the other (alternating in a soak).
    Both,
    /// 16-bit depth images (millimeters), deprojected on the server.
    Depth,
    /// Packed float32 points (`PointCloud2` records of 16 bytes).
    Packed,
}

/// Arguments of `sublevel cloud bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// A running server, `host:port` or an `http://` URI; absent: `sublevel serve` started as a
    /// child process on a loopback port.
    #[arg(long, alias = "server")]
    addr: Option<String>,
    /// The process id of the server at `--addr` (on this machine), whose memory is sampled.
    #[arg(long, requires = "addr")]
    pid: Option<u32>,
    /// A bearer token (`serve --auth-tokens`; UploadRobot needs an admin token).
    #[arg(long, env = "SUBLEVEL_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// The robot file (`sublevel robot fit`).
    #[arg(long, default_value = "data/robots/panda/panda.robot.json")]
    robot: PathBuf,
    /// The rendered world: a MoveIt planning scene (YAML).
    #[arg(long, default_value = "data/robots/mbm_panda/scenes/bookshelf_small/scene0001.yaml")]
    scene: PathBuf,
    /// The camera's position, `x,y,z` (meters).
    #[arg(long, default_value = "2.0,0,1.4", allow_hyphen_values = true)]
    eye: String,
    /// The point the camera looks at, `x,y,z` (meters).
    #[arg(long, default_value = "0.5,0,0.4", allow_hyphen_values = true)]
    target: String,
    /// Render the scene's objects alone, without the room (floor and walls) that gives every
    /// pixel a depth.
    #[arg(long)]
    no_room: bool,
    /// Standard deviation of the depth noise, meters.
    #[arg(long, default_value_t = 0.002)]
    noise: f64,
    /// Frames rendered (distinct noise draws), sent in turn.
    #[arg(long, default_value_t = 4)]
    frames: usize,
    /// Which frames are sent.
    #[arg(long, value_enum, default_value_t = FrameFormat::Both)]
    format: FrameFormat,
    /// Measured updates per format.
    #[arg(long, default_value_t = 300)]
    updates: usize,
    /// Updates per format sent before the measured ones.
    #[arg(long, default_value_t = 10)]
    warmup: usize,
    /// Updates per second (0: back to back).
    #[arg(long, default_value_t = 30.0)]
    rate: f64,
    /// The checked configuration, one value per robot joint (default: the Panda's
    /// MotionBenchMaker start state 0,−0.785,0,−2.356,0,1.571,0.785).
    #[arg(long, allow_hyphen_values = true)]
    config: Option<String>,
    /// Soak for this many seconds instead of `--updates`.
    #[arg(long)]
    seconds: Option<f64>,
    /// Soak: one-configuration checks per second on a second connection (0: back to back).
    #[arg(long, default_value_t = 100.0)]
    check_rate: f64,
    /// Soak: seconds between samples of the server's resident memory.
    #[arg(long, default_value_t = 10.0)]
    sample_every: f64,
    /// Soak: fail when the last memory sample exceeds the second (the first after warm-up) by
    /// more than this (MiB).
    #[arg(long)]
    max_rss_growth_mib: Option<f64>,
    /// How the server models the cloud: `points` or `bodies` (its clusters fitted by sos bodies,
    /// warm-started from the previous frame's; docs/point_clouds.md).
    #[arg(long, value_enum, default_value_t = BenchModel::Points)]
    model: BenchModel,
    /// Write the figures as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// The cloud model of `--model`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchModel {
    /// Every kept point a ball.
    Points,
    /// Euclidean clusters, each fitted by a convex sos body.
    Bodies,
}

/// The Panda's MotionBenchMaker start state.
const READY: [f64; 7] = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];

/// Runs `sublevel cloud bench`.
///
/// # Errors
/// Files that cannot be read or do not validate, bad arguments (named), a server that cannot be
/// started or reached or answers an error, a check that read an older scene version than its
/// update's, a soak whose memory grew beyond `--max-rss-growth-mib`.
pub fn run(args: BenchArgs) -> Result<()> {
    let soak = args.seconds.is_some();
    if args.updates == 0 || !(1..=64).contains(&args.frames) {
        return Err(Error::invalid("--updates/--frames", "must be ≥ 1 (frames at most 64)"));
    }
    for (flag, v, max) in [("--rate", args.rate, 1000.0), ("--check-rate", args.check_rate, 100_000.0)] {
        if !(v.is_finite() && (0.0..=max).contains(&v)) {
            return Err(Error::invalid(flag, format!("must be in [0, {max}] per second (0: back to back), got {v}")));
        }
    }
    if let Some(s) = args.seconds {
        if !(s.is_finite() && (1.0..=86_400.0).contains(&s)) {
            return Err(Error::invalid("--seconds", format!("must be in [1, 86400], got {s}")));
        }
    }
    if !(args.sample_every.is_finite() && (0.1..=3600.0).contains(&args.sample_every)) {
        return Err(Error::invalid("--sample-every", format!("must be in [0.1, 3600] s, got {}", args.sample_every)));
    }
    let token = bearer(&args.token)?;
    let frames = Frames::render(&args)?;
    let robot_file = std::fs::read(&args.robot)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read --robot {}: {e}", args.robot.display())))?;
    let mut own = None;
    let (addr, pid) = match &args.addr {
        Some(a) => (a.clone(), args.pid),
        None => {
            let server = ChildServer::spawn()?;
            let found = (server.addr.clone(), Some(server.child.id()));
            own = Some(server);
            found
        }
    };
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let outcome = runtime.block_on(async {
        let (mut session, joints) = Session::open(&addr, token, robot_file).await?;
        session.model = match args.model {
            BenchModel::Points => pb::CloudModel::Points,
            BenchModel::Bodies => pb::CloudModel::Bodies,
        } as i32;
        let result = match session.setup(joints, args.config.as_deref()).await {
            Ok(()) if soak => soak_run(&args, &frames, &mut session, &addr, pid).await,
            Ok(()) => bench_run(&args, &frames, &mut session, pid).await,
            Err(e) => Err(e),
        };
        session.close().await;
        result
    });
    drop(own);
    let report = outcome?;
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)? + "\n")?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// A room around the origin: a floor (top face at z = −5 cm, below the robot's base) and four walls 3 m high whose inner
/// faces stand 3 m from the origin, all 10 cm thick.
fn room() -> Vec<WorldObject> {
    let slab = |name: &str, half: [f64; 3], at: [f64; 3]| {
        WorldObject::primitive(
            name,
            Primitive::Box { half_extents: Vector3::from(half) },
            Isometry3::translation(at[0], at[1], at[2]),
        )
    };
    vec![
        slab("room_floor", [3.1, 3.1, 0.05], [0.0, 0.0, -0.1]),
        slab("room_wall_x-", [0.05, 3.1, 1.5], [-3.05, 0.0, 1.5]),
        slab("room_wall_x+", [0.05, 3.1, 1.5], [3.05, 0.0, 1.5]),
        slab("room_wall_y-", [3.1, 0.05, 1.5], [0.0, -3.05, 1.5]),
        slab("room_wall_y+", [3.1, 0.05, 1.5], [0.0, 3.05, 1.5]),
    ]
}

/// The rendered frames in both encodings, and the camera.
struct Frames {
    depth: Vec<pb::DepthImage>,
    packed: Vec<pb::PackedPoints>,
    camera: Isometry3,
    /// Valid pixels per frame (the packed frames' points).
    returns: Vec<usize>,
}

impl Frames {
    fn render(args: &BenchArgs) -> Result<Frames> {
        let bytes = std::fs::read(&args.scene)
            .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read --scene {}: {e}", args.scene.display())))?;
        let scene = PlanningScene::from_yaml(&bytes)?;
        let (mut world, _) = world_objects(&scene)?;
        if !args.no_room {
            world.extend(room());
        }
        let v = |flag: &str, text: &str| numbers(flag, text, 3).map(|v| Vector3::new(v[0], v[1], v[2]));
        let camera = look_at(v("--eye", &args.eye)?, v("--target", &args.target)?, Vector3::z())
            .map_err(|e| Error::invalid("--eye/--target", e.to_string()))?;
        let start = Instant::now();
        let (mut depth, mut packed, mut returns) = (Vec::new(), Vec::new(), Vec::new());
        let k = [CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy];
        for seed in 0..args.frames as u64 {
            let noise = DepthNoise { sigma: args.noise, seed };
            let meters = render_depth(&world, &camera, &CAMERA, 6.0, Some(noise))
                .map_err(|e| Error::invalid("--noise", e.to_string()))?;
            // Millimeters; holes (0) and depths beyond 65.535 m stay holes.
            let mm: Vec<u16> = meters
                .iter()
                .map(|&d| {
                    let v = (f64::from(d) * 1e3).round();
                    if v >= 1.0 && v <= f64::from(u16::MAX) {
                        v as u16
                    } else {
                        0
                    }
                })
                .collect();
            let mut points = Vec::new();
            deproject(DepthPixels::U16(&mm), &CAMERA, 1e-3, &mut points)?;
            returns.push(points.len());
            packed.push(packed_points(&points, 16));
            depth.push(depth_u16_image(CAMERA.width as u32, CAMERA.height as u32, &mm, k, 1e-3));
        }
        println!(
            "rendered {} frames of {} × {} ({} objects, σ {} m) in {:.2} s: {} returns per frame (first), depth {} bytes, packed {} bytes",
            args.frames,
            CAMERA.width,
            CAMERA.height,
            world.len(),
            args.noise,
            start.elapsed().as_secs_f64(),
            returns[0],
            CAMERA.pixels() * 2,
            packed[0].data.len()
        );
        Ok(Frames { depth, packed, camera, returns })
    }

    /// Frame `k` of `format` (not `Both`).
    fn frame(&self, format: FrameFormat, k: usize) -> pb::update_point_cloud_request::Frame {
        use pb::update_point_cloud_request::Frame;
        match format {
            FrameFormat::Packed => Frame::Points(self.packed[k % self.packed.len()].clone()),
            _ => Frame::Depth(self.depth[k % self.depth.len()].clone()),
        }
    }
}

/// `sublevel serve` as a child process over a temporary data directory; killed and removed on drop.
struct ChildServer {
    child: std::process::Child,
    addr: String,
    dir: PathBuf,
}

impl ChildServer {
    fn spawn() -> Result<ChildServer> {
        let dir = std::env::temp_dir().join(format!("sublevel-cloud-bench-{}", std::process::id()));
        let mut command = std::process::Command::new(std::env::current_exe()?);
        command.args(["serve", "--addr", "127.0.0.1:0", "--data-dir"]).arg(&dir);
        if std::env::var_os("RUST_LOG").is_none() {
            command.env("RUST_LOG", "warn");
        }
        let mut child = command.stdout(std::process::Stdio::piped()).spawn()?;
        let mut lines = std::io::BufReader::new(child.stdout.take().ok_or_else(|| io("serve", "no stdout"))?).lines();
        let addr = loop {
            match lines.next() {
                Some(Ok(line)) => {
                    if let Some(a) = line.strip_prefix("listening on ") {
                        break a.to_owned();
                    }
                }
                _ => {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Err(io("serve", "the server ended before it listened"));
                }
            }
        };
        // Keep draining its stdout so that it never blocks on a full pipe.
        std::thread::spawn(move || lines.for_each(drop));
        println!("started `sublevel serve` (pid {}) on {addr}", child.id());
        Ok(ChildServer { child, addr, dir })
    }
}

impl Drop for ChildServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The server's resident memory (`VmRSS`), bytes.
fn resident_bytes(pid: u32) -> Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .map_err(|e| io(&format!("cannot read /proc/{pid}/status (--pid)"), e))?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map(|kib| kib * 1024)
        .ok_or_else(|| io(&format!("/proc/{pid}/status"), "no VmRSS line"))
}

/// The scene, robot and check request on the server, and a client.
struct Session {
    client: SublevelClient<Channel>,
    token: Option<MetadataValue<Ascii>>,
    scene: String,
    robot: String,
    check: pb::CheckConfigurationsRequest,
    /// `pb::CloudModel` of every update.
    model: i32,
}

impl Session {
    /// Connects and uploads the robot; returns its joints too.
    async fn open(
        addr: &str,
        token: Option<MetadataValue<Ascii>>,
        robot_file: Vec<u8>,
    ) -> Result<(Session, Vec<String>)> {
        let channel = super::loadtest::connect(&super::loadtest::endpoint(addr)?).await?;
        let mut client = SublevelClient::new(channel).max_decoding_message_size(usize::MAX);
        let robot = client
            .upload_robot(request("", &token, pb::UploadRobotRequest { name: "cloud-bench".into(), robot_file }))
            .await
            .map_err(|s| status("UploadRobot", s))?
            .into_inner()
            .robot
            .ok_or_else(|| io("UploadRobot", "no robot in the answer"))?;
        let session = Session {
            client,
            token,
            scene: String::new(),
            robot: robot.robot_id,
            check: Default::default(),
            model: pb::CloudModel::Points as i32,
        };
        Ok((session, robot.joint_names))
    }

    /// Creates the scene with the robot at `config` (`--config`: one value per joint of
    /// `joints`), and the check request of that configuration.
    async fn setup(&mut self, joints: Vec<String>, config: Option<&str>) -> Result<()> {
        let values = match config {
            Some(text) => numbers("--config", text, joints.len())?,
            None if joints.len() == READY.len() => READY.to_vec(),
            None => vec![0.0; joints.len()],
        };
        let scene = self
            .client
            .create_scene(request("", &self.token, pb::CreateSceneRequest { name: "cloud-bench".into() }))
            .await
            .map_err(|s| status("CreateScene", s))?
            .into_inner()
            .scene_id;
        self.scene = scene.clone();
        let columns = pb::ConfigurationColumns { joint_names: joints, values };
        let set = pb::SetSceneRobotRequest {
            scene_id: scene.clone(),
            robot_id: self.robot.clone(),
            joint_positions: Some(columns.clone()),
            ..Default::default()
        };
        self.client.set_scene_robot(request(&scene, &self.token, set)).await.map_err(|s| status("SetSceneRobot", s))?;
        self.check =
            pb::CheckConfigurationsRequest { scene_id: scene, configurations: Some(columns), ..Default::default() };
        Ok(())
    }

    /// Deletes the scene (and its cloud) and the robot; failures are printed.
    async fn close(&mut self) {
        if !self.scene.is_empty() {
            let r = request(&self.scene, &self.token, pb::DeleteSceneRequest { scene_id: self.scene.clone() });
            if let Err(s) = self.client.delete_scene(r).await {
                eprintln!("warning: could not delete the scene {}: {}", self.scene, s.message());
            }
        }
        let r = request("", &self.token, pb::DeleteRobotRequest { robot_id: self.robot.clone() });
        if let Err(s) = self.client.delete_robot(r).await {
            eprintln!("warning: could not delete the robot {}: {}", self.robot, s.message());
        }
    }

    fn update(&self, frame: pb::update_point_cloud_request::Frame, camera: &Isometry3) -> pb::UpdatePointCloudRequest {
        pb::UpdatePointCloudRequest {
            scene_id: self.scene.clone(),
            name: CLOUD.into(),
            frame: Some(frame),
            sensor_pose: Some(pose_to_proto(camera)),
            noise_radius: None,
            filter: None,
            model: self.model,
            bodies: None,
        }
    }

    /// One update and the check right after it, recorded in `tally` when given.
    async fn step(&mut self, message: pb::UpdatePointCloudRequest, tally: Option<&mut Tally>) -> Result<()> {
        let update = request(&self.scene, &self.token, message);
        let check = request(&self.scene, &self.token, self.check.clone());
        let sent = Instant::now();
        let r = self.client.update_point_cloud(update).await.map_err(|s| status("UpdatePointCloud", s))?.into_inner();
        let updated = Instant::now();
        let a = self.client.check_configurations(check).await.map_err(|s| status("CheckConfigurations", s))?;
        let answered = Instant::now();
        let a = a.into_inner();
        if let Some(t) = tally {
            let c = r.counts.unwrap_or_default();
            t.update.saturating_record(micros(updated - sent));
            t.server.saturating_record((1e6 * r.seconds).round() as u64);
            t.first_check.saturating_record(micros(answered - sent));
            t.check.saturating_record(micros(answered - updated));
            t.kept.push(c.kept);
            t.holes.push(c.holes);
            if let Some(b) = &r.bodies {
                t.bodies.push([b.clusters, b.reused, b.rescaled, b.fitted].map(u64::from));
                t.body_seconds.push([b.cluster_seconds, b.fit_seconds]);
            }
            t.input = c.input;
            t.memory = r.memory_bytes;
            t.colliding += u64::from(a.collides.first().copied().unwrap_or(false));
            t.stale += u64::from(a.scene_version < r.scene_version);
        }
        Ok(())
    }
}

/// The formats `--format` names.
fn formats(format: FrameFormat) -> Vec<FrameFormat> {
    match format {
        FrameFormat::Both => vec![FrameFormat::Depth, FrameFormat::Packed],
        f => vec![f],
    }
}

/// Sleeps until update `k` of a loop started at `start` is due at `rate` per second (0: now).
async fn pace(start: Instant, rate: f64, k: u64) {
    if rate > 0.0 {
        tokio::time::sleep_until((start + Duration::from_secs_f64(k as f64 / rate)).into()).await;
    }
}

async fn bench_run(args: &BenchArgs, frames: &Frames, s: &mut Session, pid: Option<u32>) -> Result<serde_json::Value> {
    let rss_before = pid.map(resident_bytes).transpose()?;
    let mut results = Vec::new();
    let mut stale = 0;
    for format in formats(args.format) {
        let mut tally = Tally::new(format);
        let start = Instant::now();
        for k in 0..args.warmup + args.updates {
            pace(start, args.rate, k as u64).await;
            let message = s.update(frames.frame(format, k), &frames.camera);
            s.step(message, (k >= args.warmup).then_some(&mut tally)).await?;
        }
        let rate = if args.rate > 0.0 { format!("{} Hz", args.rate) } else { "back to back".into() };
        print!("{rate}, after {} warm-up updates — ", args.warmup);
        results.push(tally.report());
        stale += tally.stale;
    }
    let rss_after = pid.map(resident_bytes).transpose()?;
    if let (Some(a), Some(b)) = (rss_before, rss_after) {
        println!("server resident memory {:.1} MiB before, {:.1} MiB after", mib(a), mib(b));
    }
    if stale > 0 {
        return Err(Error::Numerical(format!("{stale} checks read a scene version older than their update's")));
    }
    Ok(serde_json::json!({
        "frame": {"width": CAMERA.width, "height": CAMERA.height, "noise_m": args.noise, "frames": args.frames,
                  "returns_first": frames.returns[0]},
        "rate_hz": args.rate,
        "warmup": args.warmup,
        "results": results,
        "rss_before_bytes": rss_before,
        "rss_after_bytes": rss_after,
    }))
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

/// What the concurrent checker measured.
struct Checks {
    latency: Histogram<u64>,
    errors: u64,
    stale: u64,
}

/// One-configuration checks on a connection of their own at `rate` per second until `stop`.
async fn checker(
    addr: String,
    token: Option<MetadataValue<Ascii>>,
    check: pb::CheckConfigurationsRequest,
    rate: f64,
    stop: Arc<AtomicBool>,
) -> Result<Checks> {
    let channel = super::loadtest::connect(&super::loadtest::endpoint(&addr)?).await?;
    let mut client = SublevelClient::new(channel).max_decoding_message_size(usize::MAX);
    let mut out = Checks { latency: histogram(), errors: 0, stale: 0 };
    let (start, mut k, mut version) = (Instant::now(), 0u64, 0u64);
    while !stop.load(Ordering::Relaxed) {
        pace(start, rate, k).await;
        k += 1;
        let sent = Instant::now();
        match client.check_configurations(request(&check.scene_id, &token, check.clone())).await {
            Ok(a) => {
                out.latency.saturating_record(micros(sent.elapsed()));
                // One connection, one request at a time: the versions read never go back.
                let v = a.into_inner().scene_version;
                out.stale += u64::from(v < version);
                version = version.max(v);
            }
            Err(_) => out.errors += 1,
        }
    }
    Ok(out)
}

async fn soak_run(
    args: &BenchArgs,
    frames: &Frames,
    s: &mut Session,
    addr: &str,
    pid: Option<u32>,
) -> Result<serde_json::Value> {
    let seconds = args.seconds.unwrap_or(0.0);
    let stop = Arc::new(AtomicBool::new(false));
    let checks =
        tokio::spawn(checker(addr.to_owned(), s.token.clone(), s.check.clone(), args.check_rate, stop.clone()));
    let formats = formats(args.format);
    let mut tallies: Vec<Tally> = formats.iter().map(|&f| Tally::new(f)).collect();
    if pid.is_none() {
        println!("no --pid for the server at --addr: its memory is not sampled");
    }
    let mut series: Vec<(f64, u64)> = Vec::new();
    let start = Instant::now();
    let (mut k, mut next_sample) = (0u64, 0.0);
    let mut failure = None;
    loop {
        let t = start.elapsed().as_secs_f64();
        if let Some(pid) = pid {
            if t >= next_sample || t >= seconds {
                let rss = resident_bytes(pid)?;
                println!("  t {:>6.1} s  server VmRSS {:>8.1} MiB  ({} updates)", t, mib(rss), k);
                series.push((t, rss));
                next_sample += args.sample_every;
            }
        }
        if t >= seconds {
            break;
        }
        pace(start, args.rate, k).await;
        let f = k as usize % formats.len();
        let message = s.update(frames.frame(formats[f], k as usize / formats.len()), &frames.camera);
        if let Err(e) = s.step(message, Some(&mut tallies[f])).await {
            failure = Some(e);
            break;
        }
        k += 1;
    }
    stop.store(true, Ordering::Relaxed);
    let checks = checks.await.map_err(|e| io("checker task", e))??;
    if let Some(e) = failure {
        return Err(e);
    }
    let elapsed = start.elapsed().as_secs_f64();
    println!("soak: {k} updates in {elapsed:.0} s ({:.1} per second)", k as f64 / elapsed);
    let results: Vec<serde_json::Value> = tallies.iter().map(Tally::report).collect();
    let h = &checks.latency;
    println!(
        "concurrent checks: {} ({:.0} per second), median {:.2} ms, p95 {:.2} ms, max {:.2} ms, {} errors",
        h.len(),
        h.len() as f64 / elapsed,
        h.value_at_quantile(0.5) as f64 / 1e3,
        h.value_at_quantile(0.95) as f64 / 1e3,
        h.max() as f64 / 1e3,
        checks.errors
    );
    let stale: u64 = tallies.iter().map(|t| t.stale).sum::<u64>() + checks.stale;
    let mut growth = None;
    if let (Some(&(_, first)), Some(&(_, last))) = (series.first(), series.last()) {
        let max = series.iter().map(|&(_, b)| b).max().unwrap_or(0);
        println!(
            "server VmRSS: first {:.1} MiB, last {:.1} MiB ({:+.1} MiB), max {:.1} MiB over {} samples",
            mib(first),
            mib(last),
            mib(last) - mib(first),
            mib(max),
            series.len()
        );
        // The first interval holds the warm-up (connection and frame buffers, the allocator's
        // first pages): growth is judged from the second sample on, when there are three or more.
        let settled = if series.len() >= 3 { series[1].1 } else { first };
        let settled_max = series.iter().skip(usize::from(series.len() >= 3)).map(|&(_, b)| b).max().unwrap_or(0);
        println!(
            "  after the first interval: {:.1} MiB → {:.1} MiB ({:+.1} MiB), max {:.1} MiB",
            mib(settled),
            mib(last),
            mib(last) - mib(settled),
            mib(settled_max)
        );
        growth = Some(mib(last) - mib(settled));
    }
    let report = serde_json::json!({
        "seconds": elapsed,
        "updates": k,
        "rate_hz": args.rate,
        "results": results,
        "checks": {"count": h.len(), "rate_hz": args.check_rate, "errors": checks.errors,
                   "median_ms": h.value_at_quantile(0.5) as f64 / 1e3,
                   "p95_ms": h.value_at_quantile(0.95) as f64 / 1e3},
        "rss_growth_after_first_interval_mib": growth,
        "rss": series.iter().map(|&(t, b)| serde_json::json!({"t": t, "bytes": b})).collect::<Vec<_>>(),
    });
    if stale > 0 || checks.errors > 0 {
        return Err(Error::Numerical(format!(
            "{stale} checks read an older scene version than one seen before, {} concurrent checks failed",
            checks.errors
        )));
    }
    if let (Some(g), Some(max)) = (growth, args.max_rss_growth_mib) {
        if g > max {
            return Err(Error::ResourceExhausted(format!(
                "the server's resident memory grew by {g:.1} MiB, more than --max-rss-growth-mib {max}"
            )));
        }
    }
    Ok(report)
}
