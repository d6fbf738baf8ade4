//! Integration tests: deadlines and isolation. A certify batch past its
//! deadline answers DEADLINE_EXCEEDED and frees its SDP slot; the server's `--max-request-ms`
//! caps calls without a client deadline; plain queries of one scene keep their latency while fits
//! and certify batches run beside them on another.

use crate::util::{add, at, config, demo_bodies, sphere_points, upload_body, upload_sphere, Server};
use std::time::{Duration, Instant};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::ServerConfig;
use tonic::transport::Channel;
use tonic::Code;

/// The demo scene (chair at the origin, human one combined scale away): (scene, chair, human).
async fn demo_scene(c: &mut SublevelClient<Channel>) -> (String, String, String) {
    let (chair, human) = demo_bodies();
    let (b_chair, b_human) = (upload_body(c, "chair_101", &chair).await, upload_body(c, "human_10", &human).await);
    let scene = c.create_scene(pb::CreateSceneRequest { name: "demo".into() }).await.unwrap().into_inner().scene_id;
    let gap = 1.5 * (chair.scale() + human.scale());
    let i_chair = add(c, &scene, &b_chair, at([0.0; 3])).await;
    let i_human = add(c, &scene, &b_human, at([gap, 0.0, 0.0])).await;
    (scene, i_chair, i_human)
}

/// A BatchQuery of `n` certified distance pairs (an SDP each, ~10 ms on this machine).
fn certify_batch(scene: &str, a: &str, b: &str, n: usize) -> pb::BatchQueryRequest {
    let pair = pb::QueryPair {
        kind: pb::QueryKind::Distance as i32,
        first: a.into(),
        second: b.into(),
        certify: true,
        ..Default::default()
    };
    pb::BatchQueryRequest { scene_id: scene.into(), pairs: vec![pair; n], columns: None }
}

/// A certified distance: converged, certificate verified and agreeing, and its value equal to the
/// plain Newton answer of the same pair (1e-6 relative): the reference the SDP must meet.
async fn assert_certified(c: &mut SublevelClient<Channel>, scene: &str, a: &str, b: &str, timeout: Duration) {
    let req = |certify| pb::DistanceRequest {
        scene_id: scene.into(),
        instance_a: a.into(),
        instance_b: b.into(),
        certify,
        ..Default::default()
    };
    let plain = c.distance(req(false)).await.unwrap().into_inner().answer.unwrap();
    let mut r = tonic::Request::new(req(true));
    r.set_timeout(timeout);
    let d = c.distance(r).await.expect("certify after the expired batch").into_inner().answer.unwrap();
    assert!(d.solve.as_ref().unwrap().converged, "{d:?}");
    let cert = d.certificate.as_ref().unwrap();
    assert!(cert.verified && cert.agrees, "{cert:?}");
    assert!((d.distance - plain.distance).abs() <= 1e-6 * plain.distance, "{} vs {}", d.distance, plain.distance);
}

/// One SDP slot; a 3 000-pair certify batch (tens of seconds of SDPs) with a 50 ms deadline
/// answers DEADLINE_EXCEEDED within a second, and a certified Distance right after gets the slot
/// (it would wait behind the batch if the batch kept running) and answers within 5 s.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_expired_certify_batch_answers_deadline_exceeded_and_frees_its_sdp_slot() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(ServerConfig { max_concurrent_sdp: 1, ..config(dir.path()) }).await;
    let mut c = server.client().await;
    let (scene, chair, human) = demo_scene(&mut c).await;

    let mut req = tonic::Request::new(certify_batch(&scene, &chair, &human, 3000));
    req.set_timeout(Duration::from_millis(50));
    let start = Instant::now();
    let e = c.batch_query(req).await.expect_err("the batch cannot finish in 50 ms");
    let waited = start.elapsed();
    // The server answers DEADLINE_EXCEEDED 2 ms before the deadline; tonic's client enforces the
    // same deadline itself and reports CANCELLED "Timeout expired" when its timer fires first
    // (a loaded machine delays the server's answer). Either way the call ends at the deadline.
    match e.code() {
        Code::DeadlineExceeded => {
            assert!(e.message().contains("grpc-timeout") && e.message().contains("BatchQuery"), "{}", e.message())
        }
        Code::Cancelled => assert_eq!(e.message(), "Timeout expired", "{e:?}"),
        _ => panic!("{e:?}"),
    }
    assert!(waited < Duration::from_secs(1), "DEADLINE_EXCEEDED after {waited:?}");

    assert_certified(&mut c, &scene, &chair, &human, Duration::from_secs(5)).await;
    server.stop().await;
}

/// `--max-request-ms` applies to calls that carry no deadline, with a message naming the flag.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_cap_bounds_calls_without_a_client_deadline() {
    let dir = tempfile::tempdir().unwrap();
    // The scene is set up without the cap (an upload's fsync and certificate can pass 100 ms on a
    // loaded machine), then the capped server serves the same store.
    let uncapped = Server::start(config(dir.path())).await;
    let (scene, chair, human) = demo_scene(&mut uncapped.client().await).await;
    uncapped.stop().await;
    let capped = ServerConfig { max_request_time: Some(Duration::from_millis(100)), ..config(dir.path()) };
    let server = Server::start(capped).await;
    let mut c = server.client().await;
    let start = Instant::now();
    let e = c.batch_query(certify_batch(&scene, &chair, &human, 3000)).await.expect_err("capped at 100 ms");
    assert_eq!(e.code(), Code::DeadlineExceeded, "{e:?}");
    assert!(e.message().contains("--max-request-ms"), "{}", e.message());
    assert!(start.elapsed() < Duration::from_secs(1), "{:?}", start.elapsed());
    // Short calls pass under the cap (a plain distance: microseconds).
    let d = crate::util::distance(&mut c, &scene, &chair, &human).await;
    assert!(d.solve.unwrap().converged);
    server.stop().await;
}

/// Latency summary of one series, in milliseconds.
struct Summary {
    p50: f64,
    p99: f64,
    max: f64,
}

fn summarize(mut ms: Vec<f64>) -> Summary {
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() as f64 - 1.0) * q).round() as usize];
    Summary { p50: at(0.5), p99: at(0.99), max: ms[ms.len() - 1] }
}

/// `n` plain Distance queries of two unit spheres 3 m apart (closed form: 1 m), paced 2 ms apart;
/// every answer is checked against the closed form (1e-9) and its latency kept.
async fn timed_queries(c: &mut SublevelClient<Channel>, scene: &str, a: &str, b: &str, n: usize) -> Vec<f64> {
    let mut ms = Vec::with_capacity(n);
    for _ in 0..n {
        let start = Instant::now();
        let d = crate::util::distance(c, scene, a, b).await;
        ms.push(start.elapsed().as_secs_f64() * 1e3);
        assert!(d.solve.as_ref().unwrap().converged);
        assert!((d.distance - 1.0).abs() <= 1e-9, "{}", d.distance);
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    ms
}

/// Isolation: p99 of plain Distance queries on scene A, idle and then while a degree-6 fit and
/// two clients sending certify batches run on scene B, stays within max(3 × idle, idle + 10 ms)
/// (the absolute floor absorbs a loaded 2-core machine, where a p99 of 9 ms against an idle 2.8 ms
/// was seen: this checks isolation — a fit or a batch on the async workers would hold queries for
/// its whole solve — not speed).
/// Prints the table of deadline and isolation figures.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plain_queries_keep_their_latency_beside_fits_and_certify_batches() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let body = upload_sphere(&mut c, "unit", [0.0; 3], 1.0).await;
    let scene_a = c.create_scene(pb::CreateSceneRequest { name: "a".into() }).await.unwrap().into_inner().scene_id;
    let ia = add(&mut c, &scene_a, &body, at([0.0; 3])).await;
    let ib = add(&mut c, &scene_a, &body, at([3.0, 0.0, 0.0])).await;
    let (scene_b, chair, human) = demo_scene(&mut c).await;

    let n = 300;
    let idle = summarize(timed_queries(&mut c, &scene_a, &ia, &ib, n).await);

    // Load on scene B: one degree-6 fit (seconds of SDP iterations) and two certify-batch clients.
    let fit = pb::StartFitJobRequest {
        name: "load".into(),
        degree: 6,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud {
            xyz: sphere_points([0.0; 3], 1.0, 2000),
        })),
        ..Default::default()
    };
    let job = c.start_fit_job(fit).await.unwrap().into_inner().job_id;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut loaders = Vec::new();
    for _ in 0..2 {
        let (mut lc, stop) = (server.client().await, stop.clone());
        let req = certify_batch(&scene_b, &chair, &human, 20);
        loaders.push(tokio::spawn(async move {
            let mut batches = 0u32;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let answers = lc.batch_query(req.clone()).await.unwrap().into_inner().answers;
                assert_eq!(answers.len(), 20);
                batches += 1;
            }
            batches
        }));
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let running = c.get_fit_job(pb::GetFitJobRequest { job_id: job.clone() }).await.unwrap().into_inner();
    let state = running.job.unwrap().state;
    let loaded = summarize(timed_queries(&mut c, &scene_a, &ia, &ib, n).await);
    let still = c.get_fit_job(pb::GetFitJobRequest { job_id: job.clone() }).await.unwrap().into_inner();
    let state_after = still.job.unwrap().state;
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let mut batches = 0;
    for l in loaders {
        batches += l.await.unwrap();
    }
    let _ = c.cancel_fit_job(pb::CancelFitJobRequest { job_id: job }).await;

    println!("mixed load: {n} plain Distance queries on scene A (ms), {batches} certify batches of 20 on scene B");
    println!("| | p50 | p99 | max |\n|---|---|---|---|");
    println!("| idle | {:.3} | {:.3} | {:.3} |", idle.p50, idle.p99, idle.max);
    println!("| fit 2d=6 + 2 certify clients | {:.3} | {:.3} | {:.3} |", loaded.p50, loaded.p99, loaded.max);
    println!("fit job state before / after the loaded series: {state:?} / {state_after:?} (1 = running)");
    assert!(batches >= 2, "the certify clients never finished a batch");
    assert_eq!(state, pb::JobState::Running as i32, "the fit was not running during the loaded series");
    let bound = (3.0 * idle.p99).max(idle.p99 + 10.0);
    assert!(loaded.p99 <= bound, "loaded p99 {:.3} ms > {bound:.3} ms (idle p99 {:.3} ms)", loaded.p99, idle.p99);
    server.stop().await;
}
