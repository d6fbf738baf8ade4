//! `sublevel shard-probe`: the client side of the scale-out test (`deploy/local/scale-out-test.sh`,
//! `deploy/SCALING.md`). It talks to a scene-sharding proxy and sends every scene-scoped call with
//! the `x-scene-id` metadata the proxy hashes on.
//!
//! ```text
//! setup   upload a unit-diameter sphere, create --scenes scenes with two instances each, the
//!         second 2 + k/100 m from the first (distance = 1 + k/100 m, closed form); write the
//!         scene ids to --scenes-file
//! owners  one Distance per scene; print which upstream answered (the proxy's
//!         `x-sublevel-upstream` response header)
//! move    set the second instance of every scene 0.5 m further (distance + 0.5 m)
//! check   one Distance per scene against the closed form (--moved: + 0.5 m); prints failures by
//!         code; exit status 1 when any scene fails
//! load    --concurrency tasks (one connection each) send Distance calls round-robin over the
//!         scenes for --duration seconds; prints answered calls per second (every answer checked)
//! ```

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::{Error, Result};
use tonic::transport::Channel;

use sublevel::service::SCENE_ID_HEADER;

/// What the probe does (module docs).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Create the scenes and write their ids.
    Setup,
    /// Print the upstream that answers each scene.
    Owners,
    /// Move the second instance of every scene 0.5 m further.
    Move,
    /// Check every scene's distance against the closed form.
    Check,
    /// Measure Distance throughput over all scenes.
    Load,
}

/// Arguments of `sublevel shard-probe`.
#[derive(clap::Args, Debug)]
pub struct ShardProbeArgs {
    /// What to do.
    #[arg(value_enum)]
    mode: Mode,
    /// `host:port` of the proxy (or of one server).
    #[arg(long, default_value = "127.0.0.1:50050")]
    addr: String,
    /// File of scene ids, one a line (written by `setup`, read by the others).
    #[arg(long)]
    scenes_file: PathBuf,
    /// Scenes `setup` creates.
    #[arg(long, default_value_t = 6)]
    scenes: usize,
    /// `check`: expect the distances after `move`.
    #[arg(long)]
    moved: bool,
    /// `load`: seconds of load.
    #[arg(long, default_value_t = 5.0)]
    duration: f64,
    /// `load`: concurrent client tasks, one connection each.
    #[arg(long, default_value_t = 4)]
    concurrency: usize,
}

/// Sphere radius (m).
const RADIUS: f64 = 0.5;

/// Centre distance of scene k's two spheres before `move` (m).
fn gap(k: usize) -> f64 {
    2.0 + k as f64 / 100.0
}

/// A request carrying the routing metadata of `scene`.
fn scoped<T>(scene: &str, message: T) -> Result<tonic::Request<T>> {
    let mut r = tonic::Request::new(message);
    let value = scene.parse().map_err(|_| Error::invalid("scene_id", "not a valid metadata value"))?;
    r.metadata_mut().insert(SCENE_ID_HEADER, value);
    r.set_timeout(Duration::from_secs(10));
    Ok(r)
}

fn status(e: tonic::Status) -> Error {
    Error::Io(std::io::Error::other(format!("{:?}: {}", e.code(), e.message())))
}

async fn connect(addr: &str) -> Result<SublevelClient<Channel>> {
    let channel = Channel::from_shared(format!("http://{addr}"))
        .map_err(|e| Error::invalid("--addr", e.to_string()))?
        .connect()
        .await
        .map_err(|e| Error::Io(std::io::Error::other(format!("cannot connect to {addr}: {e}"))))?;
    Ok(SublevelClient::new(channel))
}

/// One scene of the file: its id and the instance ids `a`, `b` (stored as `scene a b`).
struct Scene {
    id: String,
    a: String,
    b: String,
}

fn read_scenes(path: &PathBuf) -> Result<Vec<Scene>> {
    let text = std::fs::read_to_string(path)?;
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            match f.as_slice() {
                [id, a, b] => Ok(Scene { id: (*id).into(), a: (*a).into(), b: (*b).into() }),
                _ => Err(Error::invalid("--scenes-file", format!("bad line {l:?}"))),
            }
        })
        .collect()
}

fn at(x: f64) -> pb::Pose {
    pb::Pose {
        rotation: Some(pb::Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }),
        translation: Some(pb::Vec3 { x, y: 0.0, z: 0.0 }),
    }
}

/// One Distance of scene `s`: (distance, upstream header).
async fn distance(c: &mut SublevelClient<Channel>, s: &Scene) -> std::result::Result<(f64, String), tonic::Status> {
    let req = pb::DistanceRequest {
        scene_id: s.id.clone(),
        instance_a: s.a.clone(),
        instance_b: s.b.clone(),
        ..Default::default()
    };
    let r = c.distance(scoped(&s.id, req).map_err(|e| tonic::Status::invalid_argument(e.to_string()))?).await?;
    let upstream = r.metadata().get("x-sublevel-upstream").and_then(|v| v.to_str().ok()).unwrap_or("-").to_owned();
    let d = r.into_inner().answer.map_or(f64::NAN, |a| a.distance);
    Ok((d, upstream))
}

/// Runs `sublevel shard-probe`.
pub fn run(args: ShardProbeArgs) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(probe(args))
}

async fn probe(args: ShardProbeArgs) -> Result<()> {
    let mut c = connect(&args.addr).await?;
    if args.mode == Mode::Setup {
        let json = serde_json::to_string(&sublevel::body::ellipsoid([0.0; 3], [RADIUS; 3])?.to_file())?;
        let up = pb::UploadBodyRequest {
            name: "probe-sphere".into(),
            body: Some(pb::upload_body_request::Body::BodyJson(json)),
        };
        let body = c.upload_body(up).await.map_err(status)?.into_inner().body_id;
        let mut lines = String::new();
        for k in 0..args.scenes {
            let create = pb::CreateSceneRequest { name: format!("probe-{k}") };
            let id = c.create_scene(create).await.map_err(status)?.into_inner().scene_id;
            let mut ids = Vec::new();
            for x in [0.0, gap(k)] {
                let add = pb::AddInstanceRequest { scene_id: id.clone(), body_id: body.clone(), pose: Some(at(x)) };
                ids.push(c.add_instance(scoped(&id, add)?).await.map_err(status)?.into_inner().instance_id);
            }
            lines.push_str(&format!("{id} {} {}\n", ids[0], ids[1]));
        }
        std::fs::write(&args.scenes_file, lines)?;
        println!("setup: {} scenes of two spheres (body {body})", args.scenes);
        return Ok(());
    }
    let scenes = read_scenes(&args.scenes_file)?;
    let offset = if args.moved { 0.5 } else { 0.0 };
    match args.mode {
        Mode::Setup => Ok(()),
        Mode::Owners => {
            for s in &scenes {
                let (d, up) = distance(&mut c, s).await.map_err(status)?;
                println!("scene {} -> {up} (distance {d:.6} m)", s.id);
            }
            Ok(())
        }
        Mode::Move => {
            for (k, s) in scenes.iter().enumerate() {
                let poses = vec![pb::InstancePose { instance_id: s.b.clone(), pose: Some(at(gap(k) + 0.5)) }];
                let req = pb::SetPosesRequest { scene_id: s.id.clone(), poses };
                c.set_poses(scoped(&s.id, req)?).await.map_err(status)?;
            }
            println!("move: {} scenes moved 0.5 m apart", scenes.len());
            Ok(())
        }
        Mode::Check => {
            let mut failed = 0;
            for (k, s) in scenes.iter().enumerate() {
                let want = gap(k) - 2.0 * RADIUS + offset;
                match distance(&mut c, s).await {
                    Ok((d, up)) if (d - want).abs() <= 1e-9 => println!("scene {} ok on {up}: {d:.6} m", s.id),
                    Ok((d, up)) => {
                        failed += 1;
                        println!("scene {} WRONG on {up}: {d} m, closed form {want} m", s.id);
                    }
                    Err(e) => {
                        failed += 1;
                        println!("scene {} FAILED: {:?} {}", s.id, e.code(), e.message());
                    }
                }
            }
            println!("check: {} of {} scenes answered the closed form", scenes.len() - failed, scenes.len());
            if failed > 0 {
                return Err(Error::Io(std::io::Error::other(format!("{failed} scenes failed"))));
            }
            Ok(())
        }
        Mode::Load => load(&args, scenes, offset).await,
    }
}

async fn load(args: &ShardProbeArgs, scenes: Vec<Scene>, offset: f64) -> Result<()> {
    let scenes = Arc::new(scenes);
    let (answered, wrong, failed) =
        (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let end = Instant::now() + Duration::from_secs_f64(args.duration);
    let start = Instant::now();
    let mut tasks = Vec::new();
    for t in 0..args.concurrency.max(1) {
        let mut c = connect(&args.addr).await?;
        let (scenes, answered, wrong, failed) = (scenes.clone(), answered.clone(), wrong.clone(), failed.clone());
        tasks.push(tokio::spawn(async move {
            let mut k = t;
            while Instant::now() < end {
                let i = k % scenes.len();
                k += 1;
                match distance(&mut c, &scenes[i]).await {
                    Ok((d, _)) if (d - (gap(i) - 2.0 * RADIUS + offset)).abs() <= 1e-9 => {
                        answered.fetch_add(1, Ordering::Relaxed)
                    }
                    Ok(_) => wrong.fetch_add(1, Ordering::Relaxed),
                    Err(e) => {
                        if failed.fetch_add(1, Ordering::Relaxed) == 0 {
                            eprintln!("first failed answer (scene {i}): {e}");
                        }
                        0
                    }
                };
            }
        }));
    }
    for t in tasks {
        let _ = t.await;
    }
    let secs = start.elapsed().as_secs_f64();
    let n = answered.load(Ordering::Relaxed);
    let (w, f) = (wrong.load(Ordering::Relaxed), failed.load(Ordering::Relaxed));
    println!(
        "load: {n} answers in {secs:.2} s = {:.0} answers/s ({} tasks; {w} wrong, {f} failed)",
        n as f64 / secs,
        args.concurrency
    );
    if w + f > 0 {
        return Err(Error::Io(std::io::Error::other(format!("{w} wrong and {f} failed answers"))));
    }
    Ok(())
}
