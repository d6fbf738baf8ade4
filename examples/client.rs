//! A planner-side client of `sublevel serve --demo`: finds the demo scene, queries distance and
//! growth between the chair and the human, then slides the chair in small steps with `SetPoses`
//! and shows the warm-started answers; checks a sampling planner's batch of candidate states;
//! then asks the demo robot for a plan in its bookshelf scene (`Plan`, one call from a
//! MotionBenchMaker request to a certified path).
//!
//! ```text
//! cargo run --release -- serve --demo          # terminal 1
//! cargo run --release --example client         # terminal 2 (SUBLEVEL_ADDR to point elsewhere)
//! ```
//!
//! Every call about a scene carries the `x-scene-id` metadata ([`scene_request`]), which a
//! scene-sharding proxy routes on (`deploy/SCALING.md`).

use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::scene_request;

fn pose(tx: f64, ty: f64, tz: f64) -> pb::Pose {
    pb::Pose {
        rotation: Some(pb::Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 }),
        translation: Some(pb::Vec3 { x: tx, y: ty, z: tz }),
    }
}

/// One call at a time, so one thread: tokio's current-thread runtime answers a call without
/// handing it between threads. A `ListScenes` round trip took 96–98 µs (median of 1000) with it
/// against 131–154 µs with the multi-thread runtime (`#[tokio::main]`), and the 256 states below as
/// one array 0.45–0.46 against 0.49–0.52 ms, alternated on this project's 2-core VM; a planner
/// that calls from one thread gains the same.
#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let addr = std::env::var("SUBLEVEL_ADDR").unwrap_or_else(|_| "127.0.0.1:50051".into());
    let mut client = SublevelClient::connect(format!("http://{addr}")).await?;

    let bodies = client.list_bodies(pb::ListBodiesRequest::default()).await?.into_inner().bodies;
    let scenes = client.list_scenes(pb::ListScenesRequest::default()).await?.into_inner().scenes;
    let Some(demo) = scenes.iter().find(|s| s.name == "demo") else {
        return Err("no scene named `demo`: start the server with `sublevel serve --demo`".into());
    };
    let scene = client
        .get_scene(scene_request(&demo.scene_id, pb::GetSceneRequest { scene_id: demo.scene_id.clone() }))
        .await?
        .into_inner();
    // The demo scene's bodies (the store holds others, such as the demo bookshelf's boards).
    for b in bodies.iter().filter(|b| scene.instances.iter().any(|i| i.body_id == b.body_id)) {
        println!("body {:<10} {} degree {} volume {:.3}", b.name, b.body_id, b.degree, b.volume);
    }
    let name_of =
        |body_id: &str| bodies.iter().find(|b| b.body_id == body_id).map(|b| b.name.clone()).unwrap_or_default();
    let chair = scene.instances.iter().find(|i| name_of(&i.body_id) == "chair_101").ok_or("no chair instance")?;
    let human = scene.instances.iter().find(|i| name_of(&i.body_id) == "human_10").ok_or("no human instance")?;
    let human_x = human.pose.as_ref().and_then(|p| p.translation.as_ref()).map(|t| t.x).unwrap_or(0.0);

    println!("\nchair slides through the human (human at x = {human_x:.2} m):");
    println!(
        "{:>8} {:>10} {:>11} {:>6} {:>6} {:>12} {:>6} {:>6}",
        "x [m]", "distance", "d(chair|h)", "conv", "iters", "kkt", "warm", ""
    );
    for k in 0..=12 {
        let x = human_x - 2.4 + 0.4 * k as f64;
        client
            .set_poses(scene_request(
                &scene.scene_id,
                pb::SetPosesRequest {
                    scene_id: scene.scene_id.clone(),
                    poses: vec![pb::InstancePose {
                        instance_id: chair.instance_id.clone(),
                        pose: Some(pose(x, 0.0, 0.0)),
                    }],
                },
            ))
            .await?;
        let d = client
            .distance(scene_request(
                &scene.scene_id,
                pb::DistanceRequest {
                    scene_id: scene.scene_id.clone(),
                    instance_a: chair.instance_id.clone(),
                    instance_b: human.instance_id.clone(),
                    ..Default::default()
                },
            ))
            .await?
            .into_inner();
        let g = client
            .growth(scene_request(
                &scene.scene_id,
                pb::GrowthRequest {
                    scene_id: scene.scene_id.clone(),
                    instance_1: chair.instance_id.clone(),
                    instance_2: human.instance_id.clone(),
                    ..Default::default()
                },
            ))
            .await?
            .into_inner();
        let (Some(da), Some(ga)) = (d.answer, g.answer) else { return Err("empty answer".into()) };
        let ds = da.solve.unwrap_or_default();
        println!(
            "{:>8.2} {:>10.4} {:>11.4} {:>6} {:>6} {:>12.1e} {:>6}",
            x, da.distance, ga.value, ds.converged, ds.iterations, ds.kkt_residual, ds.warm_started
        );
    }
    candidate_states(&mut client, &scene.scene_id, &chair.instance_id, &human.instance_id, human_x).await?;
    let Some(shelf) = scenes.iter().find(|s| s.name == "mbm_bookshelf") else {
        return Err("no scene named `mbm_bookshelf`: start the server with `sublevel serve --demo`".into());
    };
    plan(&mut client, &shelf.scene_id).await
}

/// The MotionBenchMaker request of the demo's bookshelf scene (its start state and goal joint
/// constraints, MoveIt's `MotionPlanRequest` as YAML).
const SHELF_REQUEST: &str = include_str!("../data/robots/mbm_panda/requests/bookshelf_small/request0001.yaml");

/// One `Plan` per call for the demo robot in the bookshelf scene, from the MotionBenchMaker
/// request as it is on disk: prints the answer (status, waypoints, length, whether every edge is
/// certified, the server's time per stage) and the median round trip over 21 calls, against the
/// server's own median (`timing.total`): the difference is the client and the transport.
async fn plan(
    client: &mut SublevelClient<tonic::transport::Channel>,
    scene_id: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let request = pb::PlanRequest {
        scene_id: scene_id.to_owned(),
        motion_plan_request: Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(SHELF_REQUEST.into())),
        settings: Some(pb::PlanSettings { timeout: Some(1.0), ..Default::default() }),
        ..Default::default()
    };
    let (mut trips, mut server) = (Vec::new(), Vec::new());
    let mut last = None;
    for _ in 0..21 {
        let start = std::time::Instant::now();
        let r = client.plan(scene_request(scene_id, request.clone())).await?.into_inner();
        trips.push(start.elapsed().as_secs_f64());
        server.push(r.timing.as_ref().map_or(0.0, |t| t.total));
        last = Some(r);
    }
    let r = last.ok_or("no answer")?;
    let status =
        pb::PlanStatus::try_from(r.status).map_or_else(|_| format!("{}", r.status), |s| s.as_str_name().into());
    let t = r.timing.unwrap_or_default();
    println!("\nPlan in mbm_bookshelf (the demo robot, MotionBenchMaker bookshelf_small request 1, 1 s):");
    println!(
        "  {status}: {} waypoints, length {:.3}, certified {}, {} states and {} edges checked{}",
        r.waypoints,
        r.length,
        r.certified,
        r.states_checked,
        r.edges_checked,
        if r.message.is_empty() { String::new() } else { format!(" ({})", r.message) }
    );
    println!(
        "  server: goals {:.2} ms, search {:.2} ms, simplify {:.2} ms, certify {:.2} ms",
        t.goals * 1e3,
        t.search * 1e3,
        t.simplify * 1e3,
        t.certify * 1e3
    );
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (trip, own) = (median(&mut trips), median(&mut server));
    println!(
        "  round trip {:.3} ms median of 21 (the server's own time {:.3} ms: the client and transport add {:.3} ms)",
        trip * 1e3,
        own * 1e3,
        (trip - own) * 1e3
    );
    Ok(())
}

/// A sampling planner's batch: 256 candidate states of the chair (uniform rotations, positions in
/// a 5 m cube around the human) checked in one Query with the distance solved cold (four states
/// per SIMD pass on the server), sent twice: the states as one array of numbers with the answers
/// in one set of columns (`state_columns`), and the states as messages (`states`); then the array
/// again without `cold` (random states lie past the warm starts' reach: the server solves them
/// like cold ones). Prints the median round trip of each over 21 calls and how many states
/// collide.
async fn candidate_states(
    client: &mut SublevelClient<tonic::transport::Channel>,
    scene_id: &str,
    chair: &str,
    human: &str,
    human_x: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let n = 256;
    let mut numbers = Vec::with_capacity(7 * n);
    for _ in 0..n {
        let q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        numbers.extend(q.iter().map(|v| v / norm));
        numbers.extend([
            human_x + rng.random_range(-2.5..2.5),
            rng.random_range(-2.5..2.5),
            rng.random_range(-2.5..2.5),
        ]);
    }
    let columns = pb::PairColumns {
        kind: pb::QueryKind::Distance as i32,
        instance_ids: vec![chair.to_owned(), human.to_owned()],
        first: vec![0],
        second: vec![1],
        margin: 0.0,
        cold: true,
    };
    let packed = pb::QueryRequest {
        scene_id: scene_id.to_owned(),
        columns: Some(columns),
        state_columns: Some(pb::StateColumns { instance_ids: vec![chair.to_owned()], poses: numbers.clone() }),
        ..Default::default()
    };
    let messages = pb::QueryRequest {
        state_columns: None,
        states: numbers
            .chunks_exact(7)
            .map(|v| pb::CandidateState {
                poses: vec![pb::InstancePose {
                    instance_id: chair.to_owned(),
                    pose: Some(pb::Pose {
                        rotation: Some(pb::Quaternion { w: v[0], x: v[1], y: v[2], z: v[3] }),
                        translation: Some(pb::Vec3 { x: v[4], y: v[5], z: v[6] }),
                    }),
                }],
            })
            .collect(),
        ..packed.clone()
    };
    // The same array without `cold`: each state would start from the state before, but random
    // states lie past the warm starts' reach (`NewtonParams::warm_reach`), so the server solves
    // them like cold ones (on the lanes) and keeps their warm starts.
    let mut not_cold = packed.clone();
    if let Some(c) = not_cold.columns.as_mut() {
        c.cold = false;
    }
    println!(
        "
{n} candidate states of the chair in one Query (cold distance to the human):"
    );
    for (name, request) in [
        ("states as one array (state_columns)", &packed),
        ("states as messages (states)", &messages),
        ("states as one array, not cold", &not_cold),
    ] {
        let mut times = Vec::new();
        let mut colliding = 0;
        for _ in 0..21 {
            let start = std::time::Instant::now();
            let r = client.query(scene_request(scene_id, request.clone())).await?.into_inner();
            times.push(start.elapsed().as_secs_f64());
            colliding = match &r.columns {
                Some(c) => c.overlapping.iter().filter(|&&o| o).count(),
                None => r.states.iter().filter(|s| s.columns.as_ref().is_some_and(|c| c.overlapping[0])).count(),
            };
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        println!(
            "  {name:<38} {:>7.3} ms median ({:>5.2} µs per state), {colliding} states collide",
            median * 1e3,
            median * 1e6 / n as f64
        );
    }
    Ok(())
}
