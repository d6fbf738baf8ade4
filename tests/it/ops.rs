//! Integration tests: operations. The operator's limits answer RESOURCE_EXHAUSTED naming their
//! flag; `--metrics-addr` serves Prometheus text whose counters match the calls made; request ids
//! come back in the response metadata; `--log-format json` writes JSON lines.

use crate::util::{
    add, assert_status, at, config, distance, sphere_points, upload_body, upload_sphere, ChildServer, Server,
};
use std::io::{BufRead, Read, Write};
use sublevel::body::ellipsoid;
use sublevel::service::pb;
use sublevel::service::ServerConfig;
use tonic::Code;

/// Scenes, bodies and instances per scene: the call after the limit is RESOURCE_EXHAUSTED naming
/// the flag, and nothing was written.
#[tokio::test]
async fn count_limits_answer_resource_exhausted_naming_their_flag() {
    let dir = tempfile::tempdir().unwrap();
    let limits = ServerConfig { max_scenes: 2, max_bodies: 2, max_instances_per_scene: 2, ..config(dir.path()) };
    let server = Server::start(limits).await;
    let mut c = server.client().await;

    let s1 = c.create_scene(pb::CreateSceneRequest { name: "a".into() }).await.unwrap().into_inner().scene_id;
    c.create_scene(pb::CreateSceneRequest { name: "b".into() }).await.unwrap();
    let third = c.create_scene(pb::CreateSceneRequest { name: "c".into() }).await;
    assert_status(third, Code::ResourceExhausted, "2 scenes of at most 2 (set by --max-scenes / SUBLEVEL_MAX_SCENES)");
    assert_eq!(c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes.len(), 2);

    let b1 = upload_sphere(&mut c, "one", [0.0; 3], 0.5).await;
    upload_sphere(&mut c, "two", [0.0; 3], 0.5).await;
    let json = serde_json::to_string(&sublevel::body::ellipsoid([0.0; 3], [0.2; 3]).unwrap().to_file()).unwrap();
    let req = pb::UploadBodyRequest { name: "three".into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
    assert_status(c.upload_body(req).await, Code::ResourceExhausted, "--max-bodies");
    let fit = pb::StartFitJobRequest {
        degree: 2,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud {
            xyz: sphere_points([0.0; 3], 1.0, 100),
        })),
        ..Default::default()
    };
    assert_status(c.start_fit_job(fit).await, Code::ResourceExhausted, "2 bodies of at most 2");
    assert_eq!(c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies.len(), 2);

    add(&mut c, &s1, &b1, at([0.0; 3])).await;
    add(&mut c, &s1, &b1, at([2.0, 0.0, 0.0])).await;
    let req = pb::AddInstanceRequest { scene_id: s1.clone(), body_id: b1.clone(), pose: Some(at([4.0, 0.0, 0.0])) };
    assert_status(c.add_instance(req).await, Code::ResourceExhausted, "2 instances in the scene of at most 2");
    let view = c.get_scene(pb::GetSceneRequest { scene_id: s1 }).await.unwrap().into_inner();
    assert_eq!(view.instances.len(), 2);
    server.stop().await;
}

/// A fit queue of depth 1: a second job while the first is queued or running is
/// RESOURCE_EXHAUSTED; once the first finished, a new one is admitted.
#[tokio::test]
async fn a_full_fit_queue_answers_resource_exhausted_until_a_job_ends() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(ServerConfig { max_fit_queue: 1, ..config(dir.path()) }).await;
    let mut c = server.client().await;
    let fit = || pb::StartFitJobRequest {
        degree: 2,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud {
            xyz: sphere_points([0.0; 3], 1.0, 200),
        })),
        ..Default::default()
    };
    let first = c.start_fit_job(fit()).await.unwrap().into_inner().job_id;
    assert_status(
        c.start_fit_job(fit()).await,
        Code::ResourceExhausted,
        "1 fit and group jobs queued or running of at most 1 (set by --max-fit-queue / SUBLEVEL_MAX_FIT_QUEUE)",
    );
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id: first }).await.unwrap().into_inner();
    let mut last = None;
    while let Some(u) = stream.message().await.unwrap() {
        last = Some(u);
    }
    assert_eq!(last.unwrap().state, pb::JobState::Succeeded as i32);
    // The slot is released just after the terminal update is published.
    let mut admitted = None;
    for _ in 0..100 {
        match c.start_fit_job(fit()).await {
            Ok(r) => {
                admitted = Some(r.into_inner().job_id);
                break;
            }
            Err(e) => {
                assert_eq!(e.code(), Code::ResourceExhausted, "{e:?}");
                tokio::time::sleep(std::time::Duration::from_millis(20)).await;
            }
        }
    }
    assert!(admitted.is_some(), "the queue never freed its slot");
    server.stop().await;
}

/// `GET /metrics` over a plain TCP connection; returns the body.
fn scrape(addr: &str) -> String {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.write_all(b"GET /metrics HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let (head, body) = out.split_once("\r\n\r\n").unwrap();
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    body.to_owned()
}

/// The value of the sample `name{…}` whose labels include every one of `labels`.
fn sample(text: &str, name: &str, labels: &[&str]) -> Option<f64> {
    text.lines().filter(|l| !l.starts_with('#')).find_map(|l| {
        let (series, value) = l.rsplit_once(' ')?;
        let (n, rest) = series.split_once('{').unwrap_or((series, ""));
        (n == name && labels.iter().all(|x| rest.contains(x))).then(|| value.parse().unwrap())
    })
}

/// A `sublevel serve --metrics-addr 127.0.0.1:0` process: after a few calls, the scrape counts
/// exactly those calls, by method and status, and the query counters match the answers.
#[tokio::test]
async fn the_metrics_endpoint_counts_the_calls_made() {
    let dir = tempfile::tempdir().unwrap();
    let server = ChildServer::spawn_with(dir.path(), &["--metrics-addr", "127.0.0.1:0"]);
    let metrics = server.startup.iter().find_map(|l| l.strip_prefix("metrics on ")).unwrap().to_owned();
    let mut c = server.client().await;

    let b1 = upload_body(&mut c, "one", &ellipsoid([0.0; 3], [0.5, 0.4, 0.3]).unwrap()).await;
    let b2 = upload_body(&mut c, "two", &ellipsoid([0.0; 3], [0.3, 0.2, 0.25]).unwrap()).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let i1 = add(&mut c, &scene, &b1, at([0.0; 3])).await;
    let i2 = add(&mut c, &scene, &b2, at([2.0, 0.0, 0.0])).await;
    let (mut iterations, mut warm) = (0.0, 0.0);
    for _ in 0..3 {
        let d = distance(&mut c, &scene, &i1, &i2).await;
        // Along x: 2 − 0.5 − 0.3.
        assert!((d.distance - 1.2).abs() < 1e-6, "{}", d.distance);
        let solve = d.solve.unwrap();
        iterations += f64::from(solve.iterations);
        warm += f64::from(u8::from(solve.warm_started));
    }
    // One NOT_FOUND, with a request id of ours that comes back.
    let mut req = tonic::Request::new(pb::DistanceRequest {
        scene_id: "nope".into(),
        instance_a: i1.clone(),
        instance_b: i2.clone(),
        ..Default::default()
    });
    req.metadata_mut().insert("x-request-id", "test-req-42".parse().unwrap());
    let e = c.distance(req).await.unwrap_err();
    assert_eq!(e.code(), Code::NotFound);
    assert_eq!(e.metadata().get("x-request-id").unwrap(), "test-req-42");
    // Without one, the server makes one (16 hex digits).
    let r = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap();
    let made = r.metadata().get("x-request-id").unwrap().to_str().unwrap().to_owned();
    assert!(made.len() == 16 && made.bytes().all(|b| b.is_ascii_hexdigit()), "{made}");

    let text = scrape(&metrics);
    let m = r#"method="/sublevel.v1.Sublevel/Distance""#;
    let requests = "sublevel_rpc_requests_total";
    assert_eq!(sample(&text, requests, &[m, r#"code="OK""#]), Some(3.0), "{text}");
    assert_eq!(sample(&text, requests, &[m, r#"code="NOT_FOUND""#]), Some(1.0));
    let upload = r#"method="/sublevel.v1.Sublevel/UploadBody""#;
    assert_eq!(sample(&text, requests, &[upload, r#"code="OK""#]), Some(2.0));
    assert_eq!(sample(&text, "sublevel_rpc_duration_seconds_count", &[m]), Some(4.0));
    let inf = sample(&text, "sublevel_rpc_duration_seconds_bucket", &[m, r#"le="+Inf""#]);
    assert_eq!(inf, Some(4.0));
    let q = r#"query="distance""#;
    assert_eq!(sample(&text, "sublevel_query_answers_total", &[q]), Some(3.0));
    assert_eq!(sample(&text, "sublevel_newton_iterations_sum", &[q]), Some(iterations));
    assert_eq!(sample(&text, "sublevel_newton_iterations_count", &[q]), Some(3.0));
    let hits = sample(&text, "sublevel_warm_start_total", &[q, r#"outcome="hit""#]).unwrap_or(0.0);
    let misses = sample(&text, "sublevel_warm_start_total", &[q, r#"outcome="miss""#]).unwrap_or(0.0);
    assert_eq!((hits, misses), (warm, 3.0 - warm));
    assert_eq!(sample(&text, "sublevel_query_non_converged_total", &[q]).unwrap_or(0.0), 0.0);
    assert_eq!(sample(&text, "sublevel_query_sdp_fallbacks_total", &[q]).unwrap_or(0.0), 0.0);
    let puts = sample(&text, "sublevel_store_commit_seconds_count", &[r#"operation="put_body""#]);
    assert_eq!(puts, Some(2.0));
    assert!(sample(&text, "sublevel_store_commit_seconds_count", &[r#"operation="put_scene""#]).unwrap() >= 1.0);
    assert!(text.contains("# TYPE sublevel_rpc_duration_seconds histogram"), "{text}");
}

/// `--log-format json`: stderr lines are JSON objects.
#[test]
fn json_logs_are_json_lines() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sublevel"))
        .args(["serve", "--addr", "127.0.0.1:0", "--log-format", "json", "--data-dir"])
        .arg(dir.path())
        .env("RUST_LOG", "info")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    let _ = child.kill();
    let _ = child.wait();
    let v: serde_json::Value = serde_json::from_str(&first).unwrap_or_else(|e| panic!("{e}: {first}"));
    assert_eq!(v["level"], "INFO", "{first}");
    assert!(v["fields"]["message"].is_string(), "{first}");
}
