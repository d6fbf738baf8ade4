//! The shared test harness of the service tests (service, service_jobs, planner, transport,
//! hardening, group): one in-process server fixture on 127.0.0.1:0 with a shutdown channel, one
//! `sublevel serve` child-process fixture, and the small client helpers every RPC test uses.

use std::io::BufRead;
use std::path::Path;
use sublevel::body::ellipsoid;
use sublevel::math::Vector3;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::{serve, ServerConfig};
use tonic::transport::Channel;
use tonic::Code;

/// A server in this process on 127.0.0.1:0 with a shutdown channel.
pub(crate) struct Server {
    addr: std::net::SocketAddr,
    shutdown: tokio::sync::oneshot::Sender<()>,
    handle: tokio::task::JoinHandle<sublevel::Result<()>>,
}

impl Server {
    /// Serves `config` on a throwaway loopback port.
    pub(crate) async fn start(config: ServerConfig) -> Server {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (shutdown, rx) = tokio::sync::oneshot::channel::<()>();
        let handle = tokio::spawn(serve(listener, config, async move {
            let _ = rx.await;
        }));
        Server { addr, shutdown, handle }
    }

    /// The address it listens on.
    pub(crate) fn addr(&self) -> std::net::SocketAddr {
        self.addr
    }

    /// A client on its own connection, without a decoding size limit.
    pub(crate) async fn client(&self) -> SublevelClient<Channel> {
        SublevelClient::new(self.channel().await).max_decoding_message_size(usize::MAX)
    }

    /// A new connection to the server (for health, reflection or raw calls).
    pub(crate) async fn channel(&self) -> Channel {
        Channel::from_shared(format!("http://{}", self.addr)).unwrap().connect().await.unwrap()
    }

    /// Shuts the server down and waits until `serve` returned `Ok`.
    pub(crate) async fn stop(self) {
        self.shutdown.send(()).unwrap();
        self.handle.await.unwrap().unwrap();
    }
}

/// A `sublevel serve` child process on 127.0.0.1:0 over a data directory (killed on drop).
pub(crate) struct ChildServer {
    /// The process (tests send it signals and wait for its exit).
    pub(crate) child: std::process::Child,
    /// `host:port` it listens on.
    pub(crate) addr: String,
    /// What it printed on stdout before `listening on …` (e.g. the seeded demo ids).
    pub(crate) startup: Vec<String>,
}

impl ChildServer {
    /// `sublevel serve --addr 127.0.0.1:0 --data-dir DIR`.
    pub(crate) fn spawn(dir: &Path) -> ChildServer {
        Self::spawn_with(dir, &[])
    }

    /// Like [`ChildServer::spawn`] with more `serve` arguments (e.g. `--demo`).
    pub(crate) fn spawn_with(dir: &Path, args: &[&str]) -> ChildServer {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sublevel"))
            .args(["serve", "--addr", "127.0.0.1:0"])
            .args(args)
            .arg("--data-dir")
            .arg(dir)
            .env("RUST_LOG", "warn")
            .env("OPENBLAS_NUM_THREADS", "1")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
        let mut startup = Vec::new();
        let addr = loop {
            let line = lines.next().expect("server exited before listening").unwrap();
            if let Some(a) = line.strip_prefix("listening on ") {
                break a.to_owned();
            }
            startup.push(line);
        };
        ChildServer { child, addr, startup }
    }

    /// A client on a new connection.
    pub(crate) async fn client(&self) -> SublevelClient<Channel> {
        let channel = Channel::from_shared(format!("http://{}", self.addr)).unwrap().connect().await.unwrap();
        SublevelClient::new(channel)
    }

    /// Sends `kill SIG` (e.g. `-TERM`, `-KILL`) to the process.
    pub(crate) fn signal(&self, sig: &str) {
        let status = std::process::Command::new("kill").args([sig, &self.child.id().to_string()]).status().unwrap();
        assert!(status.success(), "kill {sig}");
    }
}

impl Drop for ChildServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The default server settings over the data directory `dir`.
pub(crate) fn config(dir: &Path) -> ServerConfig {
    ServerConfig { data_dir: dir.to_path_buf(), ..ServerConfig::default() }
}

/// A proto pose from a quaternion (w, x, y, z) and a translation.
pub(crate) fn pose(q: [f64; 4], t: [f64; 3]) -> pb::Pose {
    pb::Pose {
        rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
        translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
    }
}

/// A proto pose without rotation at `t`.
pub(crate) fn at(t: [f64; 3]) -> pb::Pose {
    pose([1.0, 0.0, 0.0, 0.0], t)
}

/// A proto vector (present) as a core vector.
pub(crate) fn v(p: &Option<pb::Vec3>) -> Vector3 {
    let p = p.as_ref().unwrap();
    Vector3::new(p.x, p.y, p.z)
}

/// Every update of fit job `job_id` until its terminal one (the stream's end), in order.
pub(crate) async fn watch_to_end(c: &mut SublevelClient<Channel>, job_id: String) -> Vec<pb::FitJobUpdate> {
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id }).await.unwrap().into_inner();
    let mut updates = Vec::new();
    while let Some(u) = stream.message().await.unwrap() {
        updates.push(u);
    }
    assert!(!updates.is_empty(), "a watch stream ended without an update");
    updates
}

/// Uploads a sphere of radius `r` around `center` (a degree-2 ellipsoid body) as JSON.
pub(crate) async fn upload_sphere(c: &mut SublevelClient<Channel>, name: &str, center: [f64; 3], r: f64) -> String {
    upload_body(c, name, &ellipsoid(center, [r; 3]).unwrap()).await
}

/// Uploads a body given as a `Body` (its JSON file form) and returns its id.
pub(crate) async fn upload_body(c: &mut SublevelClient<Channel>, name: &str, body: &sublevel::Body) -> String {
    let json = serde_json::to_string(&body.to_file()).unwrap();
    let req = pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
    c.upload_body(req).await.unwrap().into_inner().body_id
}

/// The bundled demo chair and human (degree 4).
pub(crate) fn demo_bodies() -> (sublevel::Body, sublevel::Body) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo");
    (
        sublevel::Body::load(&dir.join("chair_101.json")).unwrap(),
        sublevel::Body::load(&dir.join("human_10.json")).unwrap(),
    )
}

/// Adds an instance of `body` at `p` and returns its id.
pub(crate) async fn add(c: &mut SublevelClient<Channel>, scene: &str, body: &str, p: pb::Pose) -> String {
    let req = pb::AddInstanceRequest { scene_id: scene.into(), body_id: body.into(), pose: Some(p) };
    c.add_instance(req).await.unwrap().into_inner().instance_id
}

/// The `Distance` answer of instances `a`, `b`.
pub(crate) async fn distance(c: &mut SublevelClient<Channel>, scene: &str, a: &str, b: &str) -> pb::DistanceAnswer {
    let req = pb::DistanceRequest {
        scene_id: scene.into(),
        instance_a: a.into(),
        instance_b: b.into(),
        ..Default::default()
    };
    c.distance(req).await.unwrap().into_inner().answer.unwrap()
}

/// The `Growth` answer of instances `a`, `b`.
pub(crate) async fn growth(c: &mut SublevelClient<Channel>, scene: &str, a: &str, b: &str) -> pb::GrowthAnswer {
    let req =
        pb::GrowthRequest { scene_id: scene.into(), instance_1: a.into(), instance_2: b.into(), ..Default::default() };
    c.growth(req).await.unwrap().into_inner().answer.unwrap()
}

/// Sets one instance's pose (asserts one update).
pub(crate) async fn set_pose(c: &mut SublevelClient<Channel>, scene: &str, inst: &str, p: pb::Pose) {
    let poses = vec![pb::InstancePose { instance_id: inst.into(), pose: Some(p) }];
    let r = c.set_poses(pb::SetPosesRequest { scene_id: scene.into(), poses }).await.unwrap();
    assert_eq!(r.into_inner().updated, 1);
}

/// Asserts that a call failed with `code` and a message that mentions `needle`.
pub(crate) fn assert_status(r: Result<impl std::fmt::Debug, tonic::Status>, code: Code, needle: &str) {
    let e = r.expect_err("request should fail");
    assert_eq!(e.code(), code, "{e:?}");
    assert!(e.message().contains(needle), "`{}` should mention `{needle}`", e.message());
}

/// Points on a sphere of radius r around c (Fibonacci lattice), as `x0, y0, z0, x1, …`.
pub(crate) fn sphere_points(c: [f64; 3], r: f64, n: usize) -> Vec<f64> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .flat_map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - z * z).sqrt();
            let th = golden * i as f64;
            [c[0] + r * rho * th.cos(), c[1] + r * rho * th.sin(), c[2] + r * z]
        })
        .collect()
}
