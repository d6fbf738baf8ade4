//! Integration tests: the service path a planner meets. A round trip over loopback must cost a
//! round trip plus the work, never a Nagle / delayed-ACK stall (~40 ms, 100× a unary call), which
//! is what accepted sockets without TCP_NODELAY gave BatchQuery replies of a few kilobytes.

use crate::util::{add, at, config, demo_bodies, upload_body, Server};
use std::time::{Duration, Instant};
use sublevel::service::pb;

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

/// The fastest of several timed calls: noise on a shared machine only adds time, and a Nagle /
/// delayed-ACK stall adds ~40 ms to every call, so the fastest call shows a stall and hides noise.
fn fastest(v: &[Duration]) -> Duration {
    v.iter().copied().min().unwrap_or_default()
}

/// Slack over the expected cost that still rules out a stall (a stall costs ~40 ms per call).
const STALL_SLACK: Duration = Duration::from_millis(15);

/// BatchQuery of 1, 5, 19, 100 and 1000 pairs and SetPoses + a 19-pair BatchQuery (a planner's
/// state check), each timed from the Rust client: the fastest call of each kind costs at most the
/// fastest unary Distance plus the batch's own in-process work (measured here, five times over for
/// encoding) plus 15 ms. A stall adds ~40 ms to every call and fails this by far; noise on a loaded
/// machine does not (it would have to delay every one of 40 calls). This is a regression check for
/// the stall, not a speed target: the medians are printed, and the speed figures live in
/// `sublevel loadtest` and `clients/python/examples/round_trips.py`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batch_round_trips_cost_no_stall() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (chair, human) = demo_bodies();
    let b_chair = upload_body(&mut c, "chair", &chair).await;
    let b_human = upload_body(&mut c, "human", &human).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "t".into() }).await.unwrap().into_inner().scene_id;
    let i_chair = add(&mut c, &scene, &b_chair, at([0.0; 3])).await;
    let i_human = add(&mut c, &scene, &b_human, at([2.9, 0.0, 0.0])).await;

    let distance = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: i_chair.clone(),
        instance_b: i_human.clone(),
        ..Default::default()
    };
    for _ in 0..20 {
        c.distance(distance.clone()).await.unwrap();
    }
    let mut unary_times = Vec::new();
    for _ in 0..60 {
        let t = Instant::now();
        c.distance(distance.clone()).await.unwrap();
        unary_times.push(t.elapsed());
    }
    let unary = fastest(&unary_times);
    let unary_median = median(unary_times);

    // In-process cost of one warm pair query, to budget the batch's own work.
    let catalog = sublevel::scene::Catalog::open(
        Box::new(sublevel::scene::store::RedbStore::open_dir(tempfile::tempdir().unwrap().path()).unwrap()),
        sublevel::query::NewtonParams::default(),
    )
    .unwrap();
    let (bc, bh) = (catalog.add_body("c", chair.clone()).unwrap(), catalog.add_body("h", human.clone()).unwrap());
    let s = catalog.create_scene("s").unwrap();
    let ic = catalog.add_instance(&s, &bc, sublevel::math::Isometry3::identity()).unwrap();
    let ih = catalog
        .add_instance(&s, &bh, sublevel::math::pose_from_parts("p", [1.0, 0.0, 0.0, 0.0], [2.9, 0.0, 0.0]).unwrap())
        .unwrap();
    let t = Instant::now();
    for _ in 0..1000 {
        catalog.distance(&s, &ic, &ih).unwrap();
    }
    let per_pair = t.elapsed() / 1000;

    let pair = |k: usize| pb::QueryPair {
        kind: if k.is_multiple_of(2) { pb::QueryKind::Distance } else { pb::QueryKind::Growth } as i32,
        first: i_chair.clone(),
        second: i_human.clone(),
        certify: false,
        with_gradient: false,
        signed: false,
        tolerance: 0.0,
    };
    let mut report =
        vec![format!("unary Distance median {unary_median:?} (fastest {unary:?}), in-process pair {per_pair:?}")];
    for n in [1usize, 5, 19, 100, 1000] {
        let req = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: (0..n).map(pair).collect(), columns: None };
        c.batch_query(req.clone()).await.unwrap();
        let rounds = if n >= 1000 { 15 } else { 40 };
        let mut times = Vec::new();
        for _ in 0..rounds {
            let t = Instant::now();
            let r = c.batch_query(req.clone()).await.unwrap().into_inner();
            times.push(t.elapsed());
            assert_eq!(r.answers.len(), n);
        }
        let (fast, m) = (fastest(&times), median(times));
        let budget = unary + per_pair * (5 * n as u32) + STALL_SLACK;
        report.push(format!("BatchQuery {n:>4} pairs: median {m:?}, fastest {fast:?} (budget {budget:?})"));
        assert!(fast <= budget, "{}", report.join("\n"));
    }
    // A QueryStream message: move the chair in the stream's own view, 19 distance queries.
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    let mut answers = c.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await.unwrap().into_inner();
    let stream_queries: Vec<pb::PlannerQuery> = (0..19)
        .map(|_| pb::PlannerQuery {
            kind: pb::QueryKind::Distance as i32,
            first: i_chair.clone(),
            second: i_human.clone(),
            ..Default::default()
        })
        .collect();
    let mut times = Vec::new();
    for k in 0..60 {
        let t = Instant::now();
        let req = pb::QueryRequest {
            scene_id: scene.clone(),
            poses: vec![pb::InstancePose {
                instance_id: i_chair.clone(),
                pose: Some(at([0.005 * k as f64, 0.0, 0.0])),
            }],
            queries: stream_queries.clone(),
            request_id: k,
            ..Default::default()
        };
        tx.send(req).await.unwrap();
        let r = answers.message().await.unwrap().unwrap();
        times.push(t.elapsed());
        assert_eq!((r.request_id, r.answers.len()), (k, 19));
    }
    let (fast, m) = (fastest(&times[10..]), median(times[10..].to_vec()));
    let budget = unary + per_pair * (5 * 19) + STALL_SLACK;
    report.push(format!("QueryStream message, 19 pairs: median {m:?}, fastest {fast:?} (budget {budget:?})"));
    assert!(fast <= budget, "{}", report.join("\n"));
    drop(tx);

    // A planner's state check: move one instance, query 19 pairs.
    let req = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: (0..19).map(pair).collect(), columns: None };
    let mut times = Vec::new();
    for k in 0..40 {
        let t = Instant::now();
        let poses =
            vec![pb::InstancePose { instance_id: i_chair.clone(), pose: Some(at([0.01 * k as f64, 0.0, 0.0])) }];
        c.set_poses(pb::SetPosesRequest { scene_id: scene.clone(), poses }).await.unwrap();
        c.batch_query(req.clone()).await.unwrap();
        times.push(t.elapsed());
    }
    let (fast, m) = (fastest(&times), median(times));
    let budget = unary * 2 + per_pair * (5 * 19) + STALL_SLACK;
    report.push(format!("SetPoses + BatchQuery 19 pairs: median {m:?}, fastest {fast:?} (budget {budget:?})"));
    assert!(fast <= budget, "{}", report.join("\n"));
    eprintln!("{}", report.join("\n"));
    server.stop().await;
}
