//! Integration tests: point clouds on the command line. `sublevel cloud load` sends a PCD file and
//! a 16-bit depth PNG to a running server's scene (the scene then lists the cloud with the points
//! kept) and refuses bad input naming the flag or the file; `sublevel cloud bench` measures both
//! frame formats and soaks the server while sampling its memory.

use crate::util::ChildServer;
use serde_json::Value;
use std::path::Path;
use std::process::Output;
use sublevel::service::pb;

fn sublevel(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_sublevel"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .unwrap()
}

/// Runs `sublevel ARGS` off the test's runtime; asserts success and returns stdout.
async fn ok(args: Vec<String>) -> String {
    let out = tokio::task::spawn_blocking(move || sublevel(&args.iter().map(String::as_str).collect::<Vec<_>>()))
        .await
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// Runs `sublevel ARGS`; asserts failure and returns stderr.
async fn fails(args: Vec<String>) -> String {
    let out = tokio::task::spawn_blocking(move || sublevel(&args.iter().map(String::as_str).collect::<Vec<_>>()))
        .await
        .unwrap();
    assert!(!out.status.success(), "expected a failure: {}", String::from_utf8_lossy(&out.stdout));
    String::from_utf8(out.stderr).unwrap()
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| (*a).to_owned()).collect()
}

/// A binary PCD of three points 1 m in front of the sensor and one NaN point.
fn write_pcd(path: &Path) {
    let mut bytes =
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\nPOINTS 4\nDATA binary\n"
            .to_vec();
    for p in [[0.0f32, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0], [f32::NAN, f32::NAN, f32::NAN]] {
        for v in p {
            bytes.extend(v.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A 4 × 3 16-bit depth PNG: 1 m everywhere but one hole.
fn write_png(path: &Path) {
    let mut samples = Vec::new();
    for k in 0..12u16 {
        samples.extend(if k == 5 { 0u16 } else { 1000 }.to_be_bytes());
    }
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), 4, 3);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    encoder.write_header().unwrap().write_image_data(&samples).unwrap();
}

#[tokio::test]
async fn cloud_load_sends_pcd_and_depth_png_files_and_refuses_bad_input_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let server = ChildServer::spawn(&dir.path().join("data"));
    let mut c = server.client().await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "cli".into() }).await.unwrap().into_inner().scene_id;
    let (pcd, png) = (dir.path().join("cloud.pcd"), dir.path().join("depth.png"));
    write_pcd(&pcd);
    write_png(&png);
    let base = |file: &Path, name: &str| {
        strings(&["cloud", "load", file.to_str().unwrap(), "--addr", &server.addr, "--scene", &scene, "--name", name])
    };

    let mut args = base(&pcd, "lidar");
    args.extend(strings(&["--voxel", "0", "--noise-radius", "0.02", "--sensor-pose", "1,0,0,0,0,0,0.5", "--json"]));
    let r: Value = serde_json::from_str(ok(args).await.trim()).unwrap();
    assert_eq!((r["counts"]["input"].as_u64(), r["counts"]["holes"].as_u64()), (Some(4), Some(1)));
    assert_eq!(r["counts"]["kept"].as_u64(), Some(3));
    let version = r["scene_version"].as_u64().unwrap();
    assert!(version >= 2, "{r}");

    let mut args = base(&png, "camera");
    args.extend(strings(&["--fx", "2", "--fy", "2", "--cx", "1.5", "--cy", "1", "--voxel", "0"]));
    let text = ok(args).await;
    assert!(text.contains("11 points kept of 12"), "{text}");
    assert!(text.contains("1 holes"), "{text}");

    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    let clouds: Vec<(&str, u64, f64)> =
        view.point_clouds.iter().map(|p| (p.name.as_str(), p.points, p.noise_radius)).collect();
    assert_eq!(clouds, [("camera", 11, 0.01), ("lidar", 3, 0.02)]);
    assert!(view.scene_version > version);

    // Bad input: named by flag or file, or the server's answer.
    let e = fails(base(&png, "camera")).await;
    assert!(e.contains("--fx") && e.contains("depth.png"), "{e}");
    let mut args = base(&pcd, "lidar");
    args.extend(strings(&["--fx", "2"]));
    assert!(fails(args).await.contains("`--fx`: only a depth image"));
    let mut args = base(&pcd, "lidar");
    args.extend(strings(&["--sensor-pose", "1,0,0"]));
    assert!(fails(args).await.contains("`--sensor-pose`"));
    std::fs::write(dir.path().join("bad.pcd"), "FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nDATA ascii\n1 2\n").unwrap();
    let e = fails(base(&dir.path().join("bad.pcd"), "lidar")).await;
    assert!(e.contains("bad.pcd") && e.contains("no `z` field"), "{e}");
    let mut args = base(&pcd, "lidar");
    args[6] = "no-such-scene".into();
    let e = fails(args).await;
    assert!(e.contains("UpdatePointCloud") && e.contains("NotFound"), "{e}");
}

#[tokio::test]
async fn cloud_bench_measures_both_formats_and_the_soak_samples_the_servers_memory() {
    let dir = tempfile::tempdir().unwrap();
    let server = ChildServer::spawn(&dir.path().join("data"));
    let json = dir.path().join("bench.json");
    let bench = ["cloud", "bench", "--addr", &server.addr, "--frames", "1", "--rate", "0"];
    let mut args = strings(&bench);
    args.extend(strings(&["--updates", "3", "--warmup", "1", "--json", json.to_str().unwrap()]));
    ok(args).await;
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let results = r["results"].as_array().unwrap();
    assert_eq!(results.len(), 2, "{r}");
    for f in results {
        assert_eq!(f["updates"].as_u64(), Some(3), "{f}");
        let kept = f["points_kept_median"].as_u64().unwrap();
        assert!(kept > 100, "{f}");
        assert!(f["first_check"]["median_ms"].as_f64().unwrap() >= f["update"]["median_ms"].as_f64().unwrap());
    }
    assert_eq!(results[0]["points_input"].as_u64(), Some(640 * 480));

    let pid = server.child.id().to_string();
    let mut args = strings(&bench);
    args.extend(strings(&["--pid", &pid, "--seconds", "2", "--sample-every", "0.5", "--check-rate", "50"]));
    args.extend(strings(&["--json", json.to_str().unwrap()]));
    let text = ok(args).await;
    assert!(text.contains("server VmRSS: first"), "{text}");
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(r["rss"].as_array().unwrap().len() >= 4, "{r}");
    assert!(r["checks"]["count"].as_u64().unwrap() > 10, "{r}");
    assert_eq!(r["checks"]["errors"].as_u64(), Some(0));

    // The scene and robot it made are gone.
    let mut c = server.client().await;
    let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner();
    assert!(scenes.scenes.is_empty(), "{scenes:?}");
    let e = fails(strings(&["cloud", "bench", "--addr", &server.addr, "--config", "1,2"])).await;
    assert!(e.contains("`--config`"), "{e}");
}
