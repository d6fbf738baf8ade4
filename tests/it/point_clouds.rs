//! Integration tests: sensor frames over the transport. A 640 × 480 float32 depth frame (1.2 MB)
//! and a million-point PointCloud2 at 16 bytes per point (16 MB) are accepted whole; a frame over
//! `--max-message-bytes` is refused by the transport before the handler runs (OUT_OF_RANGE naming
//! the flag), and the scene keeps its cloud. A frame over `--max-frame-points` is refused before
//! it is decoded, concurrent frames decode within `--max-frame-points-in-flight`, an abandoned
//! bodies update stores nothing, a frame's clusters are bounded, and intrinsics and settings no
//! sensor has are refused naming the field.

use crate::util::{config, ChildServer, Server};
use std::time::{Duration, Instant};
use sublevel::service::pb;
use sublevel::service::ServerConfig;
use tonic::Code;

/// `n` PointCloud2 records of 16 bytes (x, y, z, intensity): points in a 1 m cube 0.5–1.5 m in
/// front of the sensor (a fixed pseudo-random sequence).
fn cloud2(n: usize) -> pb::PackedPoints {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut data = Vec::with_capacity(16 * n);
    for _ in 0..n {
        for v in [next() - 0.5, next() - 0.5, next() + 0.5, 100.0] {
            data.extend(v.to_le_bytes());
        }
    }
    pb::PackedPoints { data, point_step: 16, ..Default::default() }
}

fn update(scene: &str, frame: pb::update_point_cloud_request::Frame) -> pb::UpdatePointCloudRequest {
    pb::UpdatePointCloudRequest {
        scene_id: scene.into(),
        name: "camera".into(),
        frame: Some(frame),
        ..Default::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_sensor_frames_pass_the_transport_and_larger_ones_are_refused_before_the_handler() {
    use pb::update_point_cloud_request::Frame;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "sensor".into() }).await.unwrap().into_inner().scene_id;

    // 640 × 480 float32 depths of 2 m: 1.2 MB.
    let pixels: Vec<u8> = std::iter::repeat_n(2.0f32.to_le_bytes(), 640 * 480).flatten().collect();
    assert_eq!(pixels.len(), 1_228_800);
    let depth = pb::DepthImage {
        width: 640,
        height: 480,
        fx: 525.0,
        fy: 525.0,
        cx: 319.5,
        cy: 239.5,
        pixels: Some(pb::depth_image::Pixels::DepthF32(pixels)),
        depth_scale: 0.0,
    };
    let r = c.update_point_cloud(update(&scene, Frame::Depth(depth))).await.unwrap().into_inner();
    let counts = r.counts.unwrap();
    assert_eq!((counts.input, counts.holes), (307_200, 0));
    // The wall spans x = ±319.5 · 2 / 525 = ±1.217 m (voxel columns −61 … 60 of 2 cm) and
    // y = ±239.5 · 2 / 525 = ±0.912 m (rows −46 … 45), in one layer; its pixels are 3.8 mm apart,
    // so the 2 cm voxel grid keeps one point in each of those 122 × 92 voxels.
    assert_eq!((counts.kept, counts.voxel), (122 * 92, 307_200 - 122 * 92), "{counts:?}");

    // A million points at 16 bytes each: 16 MB.
    let points = cloud2(1_000_000);
    assert_eq!(points.data.len(), 16_000_000);
    let r2 = c.update_point_cloud(update(&scene, Frame::Points(points))).await.unwrap().into_inner();
    let counts = r2.counts.unwrap();
    assert_eq!((counts.input, counts.holes, counts.range), (1_000_000, 0, 0));
    assert_eq!(r2.scene_version, r.scene_version + 1);
    // A 1 m cube on a 2 cm grid: 50³ voxels, 8 points each on average, all but a few dozen
    // occupied (e⁻⁸ of them empty).
    assert!(counts.kept > 124_000 && counts.kept <= 125_000, "{counts:?}");
    server.stop().await;

    // A server whose frames may be 8 MiB: a 9.6 MB frame is refused by the transport.
    let small = ServerConfig { max_message_bytes: 8 << 20, ..config(dir.path()) };
    let server = Server::start(small).await;
    let mut c = server.client().await;
    let err = c.update_point_cloud(update(&scene, Frame::Points(cloud2(600_000)))).await.unwrap_err();
    assert_eq!(err.code(), Code::OutOfRange, "{err:?}");
    assert!(err.message().contains("--max-message-bytes"), "{}", err.message());
    // Clouds are in memory only: the restarted server's scene has none.
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    assert!(view.point_clouds.is_empty() && view.scene_version == 1, "{view:?}");
    server.stop().await;
}

/// A depth image of `width` × `height` 16-bit pixels (`depth` of each pixel in millimeters).
fn depth_u16(width: u32, height: u32, depth: impl Fn(usize) -> u16) -> pb::DepthImage {
    let pixels = (0..(width * height) as usize).flat_map(|i| depth(i).to_le_bytes()).collect();
    pb::DepthImage {
        width,
        height,
        fx: 1000.0,
        fy: 1000.0,
        cx: width as f64 / 2.0 - 0.5,
        cy: height as f64 / 2.0 - 0.5,
        pixels: Some(pb::depth_image::Pixels::DepthU16(pixels)),
        depth_scale: 0.0,
    }
}

/// A 4096 × 4096 depth image (32 MiB, under the message limit) is past the default
/// `--max-frame-points` (2048 × 2048): it is refused from its width and height, before a pixel
/// is read (the server used to deproject and filter its 16.7 million pixels, hundreds of MB,
/// before refusing it for the points kept). The largest frame allowed, 2048 × 2048 float32
/// (16 MiB), passes the default message limit and is accepted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_maximum_depth_frame_is_refused_before_decoding() {
    use pb::update_point_cloud_request::Frame;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "big".into() }).await.unwrap().into_inner().scene_id;

    let huge = depth_u16(4096, 4096, |_| 1500);
    let clock = Instant::now();
    let err = c.update_point_cloud(update(&scene, Frame::Depth(huge))).await.unwrap_err();
    let took = clock.elapsed();
    assert_eq!(err.code(), Code::ResourceExhausted, "{err:?}");
    let m = err.message();
    assert!(m.contains("depth.width × depth.height: 4096 × 4096 = 16777216 pixels"), "{m}");
    assert!(m.contains("4194304") && m.contains("--max-frame-points"), "{m}");
    // The 32 MiB message's transfer and decoding are most of it.
    assert!(took < Duration::from_secs(3), "{took:?}");

    // 2048 × 2048 float32 depths of 2 m: 16 MiB, accepted.
    let pixels: Vec<u8> = std::iter::repeat_n(2.0f32.to_le_bytes(), 2048 * 2048).flatten().collect();
    let largest =
        pb::DepthImage { pixels: Some(pb::depth_image::Pixels::DepthF32(pixels)), ..depth_u16(2048, 2048, |_| 0) };
    let r = c.update_point_cloud(update(&scene, Frame::Depth(largest))).await.unwrap().into_inner();
    let counts = r.counts.unwrap();
    assert_eq!((counts.input, counts.holes), (2048 * 2048, 0), "{counts:?}");
    server.stop().await;
}

/// The peak resident memory of process `pid` (kB), from /proc.
fn peak_rss_kb(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Eight concurrent 1024 × 1024 frames of scattered depths with no voxel grid, each refused
/// after filtering for keeping more than 1 000 000 points, on a `sublevel serve` whose frames
/// decode one at a time (`--max-frame-points-in-flight 1048576`): the server's peak memory grows
/// by at most the budget (1 048 576 points × `FRAME_BYTES_PER_POINT`) and the eight messages.
/// Decoded all at once, the eight took about eight times one frame's working memory.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_refused_frames_stay_within_the_frame_budget() {
    use pb::update_point_cloud_request::Frame;
    let dir = tempfile::tempdir().unwrap();
    let side = 1024u32;
    let n = (side * side) as usize;
    let in_flight = n.to_string();
    let server = ChildServer::spawn_with(
        dir.path(),
        &["--max-frame-points", &in_flight, "--max-frame-points-in-flight", &in_flight],
    );
    let pid = server.child.id();
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "flood".into() }).await.unwrap().into_inner().scene_id;
    // Depths 0.5–8.7 m, scattered: no two pixels in one voxel, every one kept.
    let frame = depth_u16(side, side, |i| 500 + ((i as u64 * 2_654_435_761) % 8192) as u16);
    let request = pb::UpdatePointCloudRequest {
        filter: Some(pb::CloudFilter { voxel: Some(0.0), ..Default::default() }),
        ..update(&scene, Frame::Depth(frame))
    };
    let before = peak_rss_kb(pid);
    let calls: Vec<_> = (0..8)
        .map(|_| {
            let (mut c, request) = (c.clone(), request.clone());
            tokio::spawn(async move { c.update_point_cloud(request).await })
        })
        .collect();
    for call in calls {
        let err = call.await.unwrap().unwrap_err();
        assert_eq!(err.code(), Code::ResourceExhausted, "{err:?}");
        assert!(err.message().contains("points after filtering"), "{}", err.message());
    }
    let grown = (peak_rss_kb(pid).saturating_sub(before)) * 1024;
    let budget = n * sublevel::service::FRAME_BYTES_PER_POINT;
    let messages = 8 * 2 * (2 * n);
    eprintln!("peak grew by {} MiB (budget {} MiB + messages {} MiB)", grown >> 20, budget >> 20, messages >> 20);
    assert!(grown < (budget + messages) as u64, "peak grew by {grown} bytes");
}

/// `n` clusters of `per` points, each in a 4 cm ball, their centers 0.5 m apart on a grid in
/// front of the sensor (world frame = sensor frame), as 12-byte PointCloud2 records.
fn clumps(n: usize, per: usize) -> pb::PackedPoints {
    let mut data = Vec::new();
    for k in 0..n {
        let center = [(k % 8) as f32 * 0.5 - 1.75, (k / 8) as f32 * 0.5 - 1.0, 3.0];
        for i in 0..per {
            let t = i as f32 * 2.399_963;
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / per as f32;
            let rho = (1.0 - z * z).sqrt() * 0.04;
            for (c, d) in center.iter().zip([rho * t.cos(), rho * t.sin(), z * 0.04]) {
                data.extend((c + d).to_le_bytes());
            }
        }
    }
    pb::PackedPoints { data, ..Default::default() }
}

/// A bodies update of a few dozen clusters (a second or more of fits) sent with a 150 ms
/// deadline: the client gets DEADLINE_EXCEEDED and the cloud never appears in the scene (it used
/// to be fitted to the end and stored). The same frame without a deadline is stored, in less
/// time than this test watched the scene for.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_abandoned_bodies_update_is_not_stored() {
    use pb::update_point_cloud_request::Frame;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "late".into() }).await.unwrap().into_inner().scene_id;
    let request = pb::UpdatePointCloudRequest {
        filter: Some(pb::CloudFilter { voxel: Some(0.0), ..Default::default() }),
        model: pb::CloudModel::Bodies as i32,
        ..update(&scene, Frame::Points(clumps(24, 40)))
    };
    let mut late = tonic::Request::new(request.clone());
    late.set_timeout(Duration::from_millis(150));
    let err = c.update_point_cloud(late).await.unwrap_err();
    assert_eq!(err.code(), Code::DeadlineExceeded, "{err:?}");

    let watched = Duration::from_secs(6);
    let clock = Instant::now();
    while clock.elapsed() < watched {
        let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
        assert!(view.point_clouds.is_empty(), "an abandoned update was stored: {:?}", view.point_clouds);
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let r = c.update_point_cloud(request).await.unwrap().into_inner();
    assert_eq!(r.bodies.unwrap().clusters, 24);
    assert!(r.seconds < watched.as_secs_f64(), "the whole update took {} s: watch longer", r.seconds);
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene }).await.unwrap().into_inner();
    assert_eq!(view.point_clouds.len(), 1);
    server.stop().await;
}

/// 2000 scattered points with `min_points` 1 are about as many clusters, each a fit: refused
/// after clustering, before any fit, naming `bodies.max_clusters` with the count (the server
/// used to fit them all, half a minute). Within the bound the frame is fitted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clusters_per_frame_are_bounded() {
    use pb::update_point_cloud_request::Frame;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "dust".into() }).await.unwrap().into_inner().scene_id;
    let mut scattered = cloud2(2000);
    // Spread the 1 m cube to 8 m: points some 60 cm apart, each its own cluster.
    for record in scattered.data.chunks_exact_mut(16) {
        for k in 0..2 {
            let v = f32::from_le_bytes(record[4 * k..4 * k + 4].try_into().unwrap()) * 8.0;
            record[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    let bodies = |frame, o: pb::CloudBodyOptions| pb::UpdatePointCloudRequest {
        filter: Some(pb::CloudFilter { voxel: Some(0.0), ..Default::default() }),
        model: pb::CloudModel::Bodies as i32,
        bodies: Some(o),
        ..update(&scene, frame)
    };
    let one = pb::CloudBodyOptions { min_points: 1, ..Default::default() };
    let clock = Instant::now();
    let err = c.update_point_cloud(bodies(Frame::Points(scattered), one)).await.unwrap_err();
    assert_eq!(err.code(), Code::InvalidArgument, "{err:?}");
    assert!(err.message().contains("bodies.max_clusters") && err.message().contains("more than the 256"), "{err:?}");
    assert!(clock.elapsed() < Duration::from_secs(5), "{:?}", clock.elapsed());

    let few = pb::CloudBodyOptions { max_clusters: 3, ..Default::default() };
    let err = c.update_point_cloud(bodies(Frame::Points(clumps(4, 20)), few)).await.unwrap_err();
    assert!(err.message().contains("4 clusters"), "{err:?}");
    let r = c.update_point_cloud(bodies(Frame::Points(clumps(3, 20)), few)).await.unwrap().into_inner();
    assert_eq!(r.bodies.unwrap().clusters, 3);
    server.stop().await;
}

/// Focal lengths of 1e-300 pixels, a depth scale of 1e300 m per unit and a clustering tolerance
/// of 1e300 m are refused naming the field, the number shown in a few characters.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn absurd_intrinsics_are_refused_naming_the_field() {
    use pb::update_point_cloud_request::Frame;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "odd".into() }).await.unwrap().into_inner().scene_id;
    let image = || depth_u16(64, 48, |_| 1000);
    let cases = [
        ("depth.fx", "1e-300", update(&scene, Frame::Depth(pb::DepthImage { fx: 1e-300, ..image() }))),
        ("depth.fy", "1e-300", update(&scene, Frame::Depth(pb::DepthImage { fy: 1e-300, ..image() }))),
        ("depth.depth_scale", "1e300", update(&scene, Frame::Depth(pb::DepthImage { depth_scale: 1e300, ..image() }))),
        (
            "bodies.tolerance",
            "1e300",
            pb::UpdatePointCloudRequest {
                model: pb::CloudModel::Bodies as i32,
                bodies: Some(pb::CloudBodyOptions { tolerance: 1e300, ..Default::default() }),
                ..update(&scene, Frame::Depth(image()))
            },
        ),
    ];
    for (field, shown, request) in cases {
        let err = c.update_point_cloud(request).await.unwrap_err();
        assert_eq!(err.code(), Code::InvalidArgument, "{err:?}");
        let m = err.message();
        assert!(m.contains(field) && m.contains(shown) && m.len() < 300, "{field}: {m}");
    }
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene }).await.unwrap().into_inner();
    assert!(view.point_clouds.is_empty());
    server.stop().await;
}
