//! `sublevel cloud load` and `sublevel cloud bench`: point-cloud obstacles on a running server
//! (docs/point_clouds.md).
//!
//! ```text
//! sublevel cloud load FILE --scene ID --name NAME [--addr HOST:PORT] [--sensor-pose w,x,y,z,tx,ty,tz]
//!                     [--noise-radius R] [--voxel V] [--min-range M] [--max-range M]
//!                     [--workspace x0,y0,z0,x1,y1,z1] [--outliers] [--self-filter [--self-filter-padding P]]
//!                     [--fx FX --fy FY --cx CX --cy CY [--depth-scale 0.001]] [--json]
//! sublevel cloud bench [--addr HOST:PORT [--pid PID]] [--updates 300] [--rate 30] [--seconds S] ...   (cloud_bench.rs)
//! ```
//!
//! `load` reads one sensor file ([`super::cloud_files`]: `.pcd`, `.ply`, `.xyz`, or a 16-bit depth
//! `.png` with its intrinsics), sends it as one `UpdatePointCloud` frame — points as a packed
//! float32 x, y, z `PointCloud2` body, a depth image as `depth_u16` for the server to deproject —
//! and prints the answer: the scene version the update produced, what each filter dropped, the
//! cloud's memory, the server's seconds and the round trip.

use super::cloud_files::{read_frame, FileFrame};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use sublevel::math::Isometry3;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::{Error, Result};
use tonic::metadata::{Ascii, MetadataValue};

/// Arguments of `sublevel cloud`.
#[derive(clap::Args, Debug)]
pub struct CloudArgs {
    #[command(subcommand)]
    command: CloudCommand,
}

/// What `sublevel cloud` does.
#[derive(clap::Subcommand, Debug)]
enum CloudCommand {
    /// Send a sensor file (.pcd, .ply, .xyz, or a 16-bit depth .png with --fx --fy --cx --cy) to
    /// a scene as the point-cloud obstacle NAME (`UpdatePointCloud`) and print the answer.
    Load(LoadArgs),
    /// Measure point-cloud updates: rendered 640 × 480 depth frames of a planning scene sent as
    /// depth images and as packed points, each followed by a robot check; with --seconds, a soak
    /// that samples the server's resident memory.
    Bench(super::cloud_bench::BenchArgs),
}

/// Arguments of `sublevel cloud load`.
#[derive(clap::Args, Debug)]
struct LoadArgs {
    /// The sensor file: .pcd (ascii, binary, binary_compressed), .ply, .xyz (.txt, .pts), or a
    /// 16-bit grayscale depth .png.
    file: PathBuf,
    /// The scene's id.
    #[arg(long)]
    scene: String,
    /// The cloud's name: a cloud of that name is replaced, else one is added.
    #[arg(long)]
    name: String,
    /// `host:port` of the server (or an `http://` URI).
    #[arg(long, env = "SUBLEVEL_ADDR", default_value = "127.0.0.1:50051")]
    addr: String,
    /// A bearer token (`serve --auth-tokens`).
    #[arg(long, env = "SUBLEVEL_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Seconds to wait for the connection and the answer.
    #[arg(long, default_value_t = 60.0)]
    timeout: f64,
    /// The sensor's (optical) frame in the world, `w,x,y,z,tx,ty,tz` (a unit quaternion, then
    /// meters); default: identity, the points are in the world frame.
    #[arg(long, allow_hyphen_values = true)]
    sensor_pose: Option<String>,
    /// Radius of every kept point's ball, meters in [0, 1] (server default 0.01).
    #[arg(long)]
    noise_radius: Option<f64>,
    /// Voxel-grid edge, meters (server default 0.02; 0 turns the grid off).
    #[arg(long)]
    voxel: Option<f64>,
    /// Drop points nearer the sensor than this, meters.
    #[arg(long)]
    min_range: Option<f64>,
    /// Drop points farther from the sensor than this, meters (server default 10).
    #[arg(long)]
    max_range: Option<f64>,
    /// Keep only the points in this world box, `x0,y0,z0,x1,y1,z1` (meters).
    #[arg(long, allow_hyphen_values = true)]
    workspace: Option<String>,
    /// Remove statistical outliers (8 neighbours, 2 standard deviations).
    #[arg(long)]
    outliers: bool,
    /// Drop the points within the self-filter padding of the scene's robot.
    #[arg(long)]
    self_filter: bool,
    /// Padding of the self filter, meters (server default 0.02).
    #[arg(long, requires = "self_filter")]
    self_filter_padding: Option<f64>,
    /// Focal length along x of a depth image, pixels.
    #[arg(long)]
    fx: Option<f64>,
    /// Focal length along y of a depth image, pixels.
    #[arg(long)]
    fy: Option<f64>,
    /// Principal point x of a depth image, pixels.
    #[arg(long, allow_hyphen_values = true)]
    cx: Option<f64>,
    /// Principal point y of a depth image, pixels.
    #[arg(long, allow_hyphen_values = true)]
    cy: Option<f64>,
    /// Meters per unit of a depth image's pixels.
    #[arg(long, default_value_t = 0.001)]
    depth_scale: f64,
    /// How the checks see the cloud: `points` (every kept point a ball) or `bodies` (Euclidean
    /// clusters, each fitted by a convex sos body; docs/point_clouds.md).
    #[arg(long, default_value = "points", value_parser = ["points", "bodies"])]
    model: String,
    /// Degree 2d of the bodies model's bodies: 2 or 4 (server default 4).
    #[arg(long)]
    body_degree: Option<u32>,
    /// Largest step within one cluster of the bodies model, meters (server default 0.05).
    #[arg(long)]
    body_tolerance: Option<f64>,
    /// Print the answer as one JSON object.
    #[arg(long)]
    json: bool,
}

/// Runs `sublevel cloud`.
///
/// # Errors
/// As the subcommand: a file that cannot be read or parsed (named), a flag that does not validate
/// (named), a server that cannot be reached or answers an error (its code and message).
pub fn run(args: CloudArgs) -> Result<()> {
    match args.command {
        CloudCommand::Load(a) => load(a),
        CloudCommand::Bench(a) => super::cloud_bench::run(a),
    }
}

/// A client-side failure as the crate's [`Error::Io`].
pub(crate) fn io(what: &str, e: impl std::fmt::Display) -> Error {
    Error::Io(std::io::Error::other(format!("{what}: {e}")))
}

/// A failed call as an error naming the call, the status code and the server's message.
pub(crate) fn status(what: &str, s: tonic::Status) -> Error {
    io(what, format!("{:?}: {}", s.code(), s.message()))
}

/// `Bearer TOKEN` as a metadata value.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `--token` when it is not printable ASCII without spaces.
pub(crate) fn bearer(token: &Option<String>) -> Result<Option<MetadataValue<Ascii>>> {
    token
        .as_ref()
        .map(|t| {
            format!("Bearer {t}")
                .parse::<MetadataValue<Ascii>>()
                .map_err(|_| Error::invalid("--token", "must be printable ASCII without spaces"))
        })
        .transpose()
}

/// A request with the scene routing header (`x-scene-id`, for a sharding proxy) and the bearer
/// token when there is one.
pub(crate) fn request<T>(scene: &str, token: &Option<MetadataValue<Ascii>>, message: T) -> tonic::Request<T> {
    let mut r =
        if scene.is_empty() { tonic::Request::new(message) } else { sublevel::service::scene_request(scene, message) };
    if let Some(v) = token {
        r.metadata_mut().insert("authorization", v.clone());
    }
    r
}

/// Points as a `PointCloud2` body of `step` bytes per point (12 or more): little-endian float32
/// x, y, z at offsets 0, 4, 8, the rest of each record zero.
pub(crate) fn packed_points(points: &[[f32; 3]], step: usize) -> pb::PackedPoints {
    let step = step.max(12);
    let mut data = vec![0u8; points.len() * step];
    for (record, p) in data.chunks_exact_mut(step).zip(points) {
        for (k, v) in p.iter().enumerate() {
            record[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    pb::PackedPoints { data, point_step: step as u32, ..Default::default() }
}

/// A 16-bit depth image as the proto message (`depth_u16`, little-endian).
pub(crate) fn depth_u16_image(
    width: u32,
    height: u32,
    pixels: &[u16],
    [fx, fy, cx, cy]: [f64; 4],
    depth_scale: f64,
) -> pb::DepthImage {
    pb::DepthImage {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        pixels: Some(pb::depth_image::Pixels::DepthU16(pixels.iter().flat_map(|d| d.to_le_bytes()).collect())),
        depth_scale,
    }
}

/// `text` as `n` comma-separated finite numbers, named by `flag` on error.
pub(crate) fn numbers(flag: &str, text: &str, n: usize) -> Result<Vec<f64>> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| Error::invalid(flag, format!("expected {n} comma-separated finite numbers, got `{text}`")))?;
    if v.len() != n {
        return Err(Error::invalid(flag, format!("expected {n} comma-separated numbers, got {}", v.len())));
    }
    Ok(v)
}

/// The flags' filter (absent fields take the server's defaults).
fn filter(args: &LoadArgs) -> Result<pb::CloudFilter> {
    let mut f = pb::CloudFilter { voxel: args.voxel, self_filter: args.self_filter, ..Default::default() };
    f.self_filter_padding = args.self_filter_padding;
    for (flag, v) in [("--min-range", args.min_range), ("--max-range", args.max_range)] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0 || flag == "--min-range" && v == 0.0) {
                return Err(Error::invalid(flag, format!("must be a finite distance in meters, got {v}")));
            }
        }
    }
    f.min_range = args.min_range.unwrap_or(0.0);
    f.max_range = args.max_range.unwrap_or(0.0);
    if let Some(w) = &args.workspace {
        let v = numbers("--workspace", w, 6)?;
        if (0..3).any(|k| v[k] > v[k + 3]) {
            return Err(Error::invalid(
                "--workspace",
                "the min corner x0,y0,z0 must not exceed the max corner x1,y1,z1",
            ));
        }
        f.workspace_min = Some(pb::Vec3 { x: v[0], y: v[1], z: v[2] });
        f.workspace_max = Some(pb::Vec3 { x: v[3], y: v[4], z: v[5] });
    }
    if args.outliers {
        f.outliers = Some(pb::OutlierFilter::default());
    }
    Ok(f)
}

/// The frame of the file: packed points, or a depth image with the flags' intrinsics.
fn frame(args: &LoadArgs) -> Result<(pb::update_point_cloud_request::Frame, usize)> {
    use pb::update_point_cloud_request::Frame;
    let intrinsics = [("--fx", args.fx), ("--fy", args.fy), ("--cx", args.cx), ("--cy", args.cy)];
    let given: Vec<&str> = intrinsics.iter().filter(|(_, v)| v.is_some()).map(|(f, _)| *f).collect();
    let file = args.file.display();
    match read_frame(&args.file)? {
        FileFrame::Points(points) => {
            if let Some(flag) = given.first() {
                return Err(Error::invalid(
                    *flag,
                    format!("only a depth image (.png) takes intrinsics, {file} holds points"),
                ));
            }
            Ok((Frame::Points(packed_points(&points, 12)), points.len()))
        }
        FileFrame::Depth { width, height, pixels } => {
            let mut k = [0.0; 4];
            for (slot, (flag, v)) in k.iter_mut().zip(intrinsics) {
                let v = v.ok_or_else(|| {
                    Error::invalid(flag, format!("the depth image {file} needs its intrinsics --fx, --fy, --cx, --cy"))
                })?;
                let positive = flag == "--fx" || flag == "--fy";
                if !v.is_finite() || positive && v <= 0.0 {
                    return Err(Error::invalid(
                        flag,
                        format!("must be finite{}, got {v}", if positive { " and > 0" } else { "" }),
                    ));
                }
                *slot = v;
            }
            if !(args.depth_scale.is_finite() && args.depth_scale > 0.0) {
                return Err(Error::invalid(
                    "--depth-scale",
                    format!("must be finite and > 0 m per unit, got {}", args.depth_scale),
                ));
            }
            let n = pixels.len();
            Ok((Frame::Depth(depth_u16_image(width, height, &pixels, k, args.depth_scale)), n))
        }
    }
}

/// The request fields the server's errors name, and the flags that set them.
const FIELD_FLAGS: [(&str, &str); 16] = [
    ("name", "--name"),
    ("sensor_pose", "--sensor-pose"),
    ("noise_radius", "--noise-radius"),
    ("filter.min_range", "--min-range"),
    ("filter.max_range", "--max-range"),
    ("filter.workspace", "--workspace"),
    ("filter.voxel", "--voxel"),
    ("filter.self_filter_padding", "--self-filter-padding"),
    ("filter.self_filter", "--self-filter"),
    ("depth.fx", "--fx"),
    ("depth.fy", "--fy"),
    ("depth.cx", "--cx"),
    ("depth.cy", "--cy"),
    ("depth.depth_scale", "--depth-scale"),
    ("bodies.degree", "--body-degree"),
    ("bodies.tolerance", "--body-tolerance"),
];

fn load(args: LoadArgs) -> Result<()> {
    if args.scene.is_empty() || args.name.is_empty() {
        return Err(Error::invalid(if args.scene.is_empty() { "--scene" } else { "--name" }, "must not be empty"));
    }
    if let Some(r) = args.noise_radius {
        if !(r.is_finite() && (0.0..=1.0).contains(&r)) {
            return Err(Error::invalid("--noise-radius", format!("must be in [0, 1] m, got {r}")));
        }
    }
    let sensor_pose = match &args.sensor_pose {
        Some(text) => Some(sublevel::service::convert::pose_to_proto(&pose(text)?)),
        None => None,
    };
    let token = bearer(&args.token)?;
    let filter = filter(&args)?;
    let (frame, input) = frame(&args)?;
    let message = pb::UpdatePointCloudRequest {
        scene_id: args.scene.clone(),
        name: args.name.clone(),
        frame: Some(frame),
        sensor_pose,
        noise_radius: args.noise_radius,
        filter: Some(filter),
        model: if args.model == "bodies" { pb::CloudModel::Bodies } else { pb::CloudModel::Points } as i32,
        bodies: Some(pb::CloudBodyOptions {
            degree: args.body_degree.unwrap_or(0),
            tolerance: args.body_tolerance.unwrap_or(0.0),
            ..Default::default()
        }),
    };
    let timeout = Duration::from_secs_f64(args.timeout.clamp(0.01, 3600.0));
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let (reply, seconds) = runtime.block_on(async {
        let endpoint = super::loadtest::endpoint(&args.addr)?.connect_timeout(timeout);
        let channel = super::loadtest::connect(&endpoint).await?;
        let mut client = SublevelClient::new(channel).max_encoding_message_size(usize::MAX);
        let mut r = request(&args.scene, &token, message);
        r.set_timeout(timeout);
        let start = Instant::now();
        let reply = client.update_point_cloud(r).await.map_err(|s| {
            // The server names the request's field: say which flag set it.
            match FIELD_FLAGS.iter().find(|(field, _)| s.message().contains(&format!("`{field}"))) {
                Some((_, flag)) => io("UpdatePointCloud", format!("{:?}: {} (set by {flag})", s.code(), s.message())),
                None => status("UpdatePointCloud", s),
            }
        })?;
        Ok::<_, Error>((reply.into_inner(), start.elapsed().as_secs_f64()))
    })?;
    let c = reply.counts.unwrap_or_default();
    if args.json {
        let value = serde_json::json!({
            "scene_id": args.scene,
            "name": args.name,
            "file": args.file.display().to_string(),
            "scene_version": reply.scene_version,
            "counts": {
                "input": c.input, "holes": c.holes, "range": c.range, "workspace": c.workspace,
                "voxel": c.voxel, "outliers": c.outliers, "robot": c.robot, "kept": c.kept,
            },
            "memory_bytes": reply.memory_bytes,
            "bodies": reply.bodies.as_ref().map(|b| serde_json::json!({
                "clusters": b.clusters, "outliers": b.outliers, "reused": b.reused, "rescaled": b.rescaled,
                "fitted": b.fitted, "fallbacks": b.fallbacks,
                "cluster_seconds": b.cluster_seconds, "fit_seconds": b.fit_seconds,
            })),
            "server_seconds": reply.seconds,
            "round_trip_seconds": seconds,
        });
        println!("{value}");
    } else {
        println!(
            "cloud `{}` of scene {}: scene version {}, {} points kept of {input} read from {}",
            args.name,
            args.scene,
            reply.scene_version,
            c.kept,
            args.file.display()
        );
        println!(
            "  dropped: {} holes, {} out of range, {} outside the workspace, {} merged by the voxel grid, {} outliers, {} on the robot",
            c.holes, c.range, c.workspace, c.voxel, c.outliers, c.robot
        );
        if let Some(b) = &reply.bodies {
            println!(
                "  bodies: {} clusters ({} reused, {} rescaled, {} fitted, {} fits failed to a ball), {} outlier points; \
                 clustering {:.1} ms, fits {:.1} ms",
                b.clusters,
                b.reused,
                b.rescaled,
                b.fitted,
                b.fallbacks,
                b.outliers,
                1e3 * b.cluster_seconds,
                1e3 * b.fit_seconds
            );
        }
        println!(
            "  memory {:.1} KiB, server {:.2} ms, round trip {:.2} ms",
            reply.memory_bytes as f64 / 1024.0,
            1e3 * reply.seconds,
            1e3 * seconds
        );
    }
    Ok(())
}

/// `--sensor-pose`: `w,x,y,z,tx,ty,tz`.
fn pose(text: &str) -> Result<Isometry3> {
    let v = numbers("--sensor-pose", text, 7)?;
    sublevel::math::pose_from_parts("--sensor-pose", [v[0], v[1], v[2], v[3]], [v[4], v[5], v[6]])
}
