//! Integration tests: sensor frames over the transport. A 640 × 480 float32 depth frame (1.2 MB)
//! and a million-point PointCloud2 at 16 bytes per point (16 MB) are accepted whole; a frame over
//! `--max-message-bytes` is refused by the transport before the handler runs (OUT_OF_RANGE naming
//! the flag), and the scene keeps its cloud.

use crate::util::{config, Server};
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
