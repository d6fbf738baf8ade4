//! The load test against a real server on 127.0.0.1:0: every scenario's answers match an
//! in-process catalog, arguments are checked, the chair's path is smooth and closed.

use super::in_process::LocalScene;
use super::report::Outcome;
use super::scene::{chair_pose, isometry, Op, PATH_STEPS};
use super::{execute, LoadtestArgs, Scenario, StreamQuery};
use std::time::Instant;
use sublevel::scene::QueryKind;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};

fn args(addr: &str, scenario: Scenario) -> LoadtestArgs {
    LoadtestArgs {
        addr: addr.to_owned(),
        scenario,
        concurrency: 2,
        duration: 1.0,
        requests: None,
        rate: None,
        pairs: 20,
        stream_query: StreamQuery::Distance,
        margin: 0.05,
        shared_channel: false,
        columns: false,
        in_process_seconds: 0.1,
        json: None,
    }
}

/// The largest |gRPC distance − in-process Catalog distance| and the smallest distance, over
/// every recorded answer at the stored pose (unary, batch: K local answers, computed once) and
/// the answers of at least 1000 stream states (all of them when fewer; each state's chair pose
/// set on a fresh local catalog, an independent path from the server's stream view).
fn max_deviation(outcome: &Outcome) -> (f64, f64) {
    let local = LocalScene::new(&outcome.layout).unwrap();
    let catalog = local.catalog();
    let distance = |j: usize| {
        let q = local.pair(&outcome.layout, j, QueryKind::Distance, 0.0);
        catalog.distance(&local.scene, &q.first, &q.second).unwrap().distance
    };
    let home: Vec<f64> = (0..outcome.layout.pair_humans.len()).map(distance).collect();
    let states = outcome.records.iter().filter(|r| r.chair.is_some()).count();
    let stride = (states / 1000).max(1);
    let (mut worst, mut nearest) = (0.0f64, f64::INFINITY);
    let mut compare = |d: f64, expected: f64| {
        nearest = nearest.min(expected);
        worst = worst.max((d - expected).abs());
    };
    for r in &outcome.records {
        assert_eq!(r.pairs.len(), r.distances.len());
        if r.chair.is_none() {
            r.pairs.iter().zip(&r.distances).for_each(|(&j, &d)| compare(d, home[j]));
        }
    }
    for r in outcome.records.iter().filter(|r| r.chair.is_some()).step_by(stride) {
        let chair = isometry(r.chair.as_ref().unwrap()).unwrap();
        catalog.set_poses(&local.scene, &[(local.chair.clone(), chair)]).unwrap();
        r.pairs.iter().zip(&r.distances).for_each(|(&j, &d)| compare(d, distance(j)));
    }
    (worst, nearest)
}

#[test]
fn every_scenario_answers_every_pair_like_the_catalog() {
    let dir = tempfile::tempdir().unwrap();
    let server = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let listener = server.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let config = sublevel::service::ServerConfig { data_dir: dir.path().to_path_buf(), ..Default::default() };
    let handle = server.spawn(sublevel::service::serve(listener, config, async move {
        let _ = stopped.await;
    }));

    for scenario in [Scenario::Unary, Scenario::Batch, Scenario::Stream, Scenario::Mixed] {
        let t0 = Instant::now();
        let outcome = execute(&args(&addr, scenario), true).unwrap();
        let ran = t0.elapsed();
        let r = &outcome.report;
        let name = scenario.name();
        assert!(r.errors.is_empty(), "{name}: errors {:?}", r.errors);
        let f = &r.overall;
        assert!(f.requests > 10, "{name}: only {} requests", f.requests);
        // One pair per unary request, K per batch or stream request.
        let by_kind = |op: Op| {
            outcome.records.iter().filter(|x| x.pairs.len() == if op == Op::Unary { 1 } else { 20 }).count() as u64
        };
        assert_eq!(outcome.records.len() as u64, f.requests, "{name}");
        assert_eq!(f.pair_queries, by_kind(Op::Unary) + 20 * by_kind(Op::Batch), "{name}");
        if scenario != Scenario::Unary && scenario != Scenario::Mixed {
            assert_eq!(f.pair_queries, 20 * f.requests, "{name}");
        }
        assert_eq!(r.histogram_count, f.requests, "{name}");
        assert!(f.p50_us <= f.p90_us && f.p90_us <= f.p99_us && f.p99_us <= f.p999_us && f.p999_us <= f.max_us);
        assert!(f.p50_us > 0);
        assert!(r.duration_s > 0.9 && r.duration_s < 2.5, "{name}: {} s", r.duration_s);
        assert!(r.in_process.is_some_and(|p| p.pair_queries_per_s > 0.0));
        let (worst, nearest) = max_deviation(&outcome);
        assert!(nearest > 0.05, "{name}: every pair should stay separated, nearest {nearest} m");
        assert!(worst <= 1e-9, "{name}: a gRPC distance differs from the Catalog's by {worst:e}");
        let json = r.json();
        for key in [
            "scenario",
            "p50_us",
            "p90_us",
            "p99_us",
            "p999_us",
            "max_us",
            "requests_per_s",
            "pair_queries_per_s",
            "errors",
            "concurrency",
            "duration_s",
            "pairs_per_request",
        ] {
            assert!(json.get(key).is_some(), "{name}: JSON lacks {key}");
        }
        eprintln!(
            "{name}: {} requests, {} pairs, nearest pair {nearest:.3} m, largest deviation {worst:.1e} m, run {:.2} s, checked in {:.2} s",
            f.requests,
            f.pair_queries,
            ran.as_secs_f64(),
            t0.elapsed().as_secs_f64()
        );
    }

    // Open loop: a bounded timetable, every request sent and answered.
    let mut open = args(&addr, Scenario::Stream);
    open.rate = Some(200.0);
    open.duration = 0.5;
    open.requests = Some(60);
    open.in_process_seconds = 0.0;
    let outcome = execute(&open, false).unwrap();
    let r = &outcome.report;
    assert!(r.errors.is_empty(), "open loop: {:?}", r.errors);
    assert_eq!(r.overall.requests, 60);
    assert_eq!(r.unsent, 0);
    assert!(r.send_lag.is_some() && r.in_process.is_none());
    // 60 requests at 200/s take 0.3 s of timetable.
    assert!(r.duration_s > 0.25 && r.duration_s < 1.0, "{} s", r.duration_s);

    // Nothing of the load test is left on the server.
    let left = server.block_on(async {
        let mut c = SublevelClient::connect(format!("http://{addr}")).await.unwrap();
        let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes.len();
        let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies.len();
        (scenes, bodies)
    });
    assert_eq!(left, (0, 0));
    stop.send(()).unwrap();
    server.block_on(handle).unwrap().unwrap();
}

#[test]
fn arguments_are_checked() {
    let mut a = args("127.0.0.1:1", Scenario::Unary);
    a.concurrency = 0;
    assert!(execute(&a, false).unwrap_err().to_string().contains("--concurrency"));
    let mut a = args("127.0.0.1:1", Scenario::Unary);
    a.rate = Some(0.0);
    assert!(execute(&a, false).unwrap_err().to_string().contains("--rate"));
    // Nothing listens on port 1: a connection error, not a hang.
    let a = args("127.0.0.1:1", Scenario::Unary);
    assert!(execute(&a, false).is_err());
}

#[test]
fn the_chair_path_is_smooth_and_closed() {
    let a = chair_pose(0, 1, 0);
    let b = chair_pose(0, 1, PATH_STEPS);
    assert!((a.1[0] - b.1[0]).abs() < 1e-12);
    for step in 0..PATH_STEPS {
        let (p, q) = (chair_pose(1, 3, step), chair_pose(1, 3, step + 1));
        let dt = ((p.1[0] - q.1[0]).powi(2) + (p.1[1] - q.1[1]).powi(2)).sqrt();
        assert!(dt < 1e-3, "step {step}: {dt} m");
        let norm: f64 = p.0.iter().map(|x| x * x).sum();
        assert!((norm - 1.0).abs() < 1e-12);
    }
}
