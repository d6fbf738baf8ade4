//! Integration tests: fit jobs through the service (progress streams, auto degree, validated
//! options), `serve --demo` seeding (bodies, scenes, the Panda and its bookshelf scene) across
//! restarts, and the end-to-end run of the paper's chair
//! sliding through the human.

use crate::util::{add, assert_status, at, config, distance, growth, set_pose, sphere_points, ChildServer, Server};
use std::path::Path;
use sublevel::math::{pose_from_parts, Isometry3, Point3};
use sublevel::service::pb;
use tonic::Code;

/// A fit job's updates are well formed and end in a terminal state; a successful fit stores a
/// body that contains every input point (p ≤ 1), retrievable by the reported id.
#[tokio::test]
async fn fit_job_streams_progress_to_a_terminal_state() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let xyz = sphere_points([0.2, -0.1, 0.3], 0.5, 300);
    let req = pb::StartFitJobRequest {
        name: "ball".into(),
        degree: 2,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud { xyz: xyz.clone() })),
        ..Default::default()
    };
    let job_id = c.start_fit_job(req).await.unwrap().into_inner().job_id;
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id: job_id.clone() }).await.unwrap().into_inner();
    let mut updates = Vec::new();
    while let Some(u) = stream.message().await.unwrap() {
        updates.push(u);
    }
    let last = updates.last().unwrap().clone();
    assert!(updates.iter().all(|u| u.job_id == job_id && (0.0..=1.0).contains(&u.fraction)));
    assert!(updates[..updates.len() - 1].iter().all(|u| u.state == pb::JobState::Running as i32));
    assert_eq!(last.stage, pb::FitStage::Done as i32);
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    let got = c.get_body(pb::GetBodyRequest { body_id: last.body_id.clone() }).await.unwrap().into_inner();
    assert_eq!(got.name, "ball");
    let body = sublevel::Body::from_file(serde_json::from_str(&got.body_json).unwrap()).unwrap();
    // Containment on every input point, and (2d = 2, points on a sphere) the fit is that sphere:
    // p = 1 on every point to the solver's accuracy.
    for p in xyz.chunks(3) {
        let val = body.value_at(&Point3::new(p[0], p[1], p[2]));
        assert!(val <= 1.0 + 1e-9, "point {p:?} outside: p = {val}");
        assert!(val >= 1.0 - 1e-4, "point {p:?} not on the fitted sphere: p = {val}");
    }
    // Watching a finished job replays its terminal update.
    let mut again = c.watch_fit_job(pb::WatchFitJobRequest { job_id }).await.unwrap().into_inner();
    assert_eq!(again.message().await.unwrap().unwrap(), last);
    assert!(again.message().await.unwrap().is_none());
    server.stop().await;
}

/// A fit job with `auto_degree` fits 2 then 4 on an ellipsoid cloud and keeps 2d = 2 (degree 4
/// is not smaller), recording the choice in the body's report; bad fit options are refused
/// before a job exists, naming the field.
#[tokio::test]
async fn fit_job_with_auto_degree_and_validated_options() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    // Points on an ellipsoid with radii 0.5, 0.3, 0.2 (a stretched sphere cloud).
    let xyz: Vec<f64> = sphere_points([0.0; 3], 1.0, 400)
        .chunks(3)
        .flat_map(|p| [0.1 + 0.5 * p[0], -0.2 + 0.3 * p[1], 0.2 * p[2]])
        .collect();
    let req = |method: &str, c: f64, tol: f64| pb::StartFitJobRequest {
        name: "auto".into(),
        degree: 4,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud { xyz: xyz.clone() })),
        method: method.into(),
        convexity_relaxation: c,
        auto_degree: true,
        volume_tolerance: tol,
        ..Default::default()
    };
    assert_status(c.start_fit_job(req("simplex", 0.0, 0.05)).await, Code::InvalidArgument, "method");
    assert_status(c.start_fit_job(req("", -1.0, 0.05)).await, Code::InvalidArgument, "convexity_relaxation");
    assert_status(c.start_fit_job(req("", f64::NAN, 0.05)).await, Code::InvalidArgument, "convexity_relaxation");
    assert_status(c.start_fit_job(req("", 0.0, 1.5)).await, Code::InvalidArgument, "volume_tolerance");
    let mut bad_degree = req("", 0.0, 0.05);
    bad_degree.degree = 5;
    assert_status(c.start_fit_job(bad_degree).await, Code::InvalidArgument, "degree");

    let job_id = c.start_fit_job(req("logdet_p", 0.0, 0.05)).await.unwrap().into_inner().job_id;
    let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id }).await.unwrap().into_inner();
    let mut last = None;
    while let Some(u) = stream.message().await.unwrap() {
        if u.state == pb::JobState::Running as i32 && u.stage != pb::FitStage::Queued as i32 {
            assert!(u.message.starts_with("degree 2: ") || u.message.starts_with("degree 4: "), "{}", u.message);
        }
        last = Some(u);
    }
    let last = last.unwrap();
    assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
    let got = c.get_body(pb::GetBodyRequest { body_id: last.body_id }).await.unwrap().into_inner();
    let body = sublevel::Body::from_file(serde_json::from_str(&got.body_json).unwrap()).unwrap();
    assert_eq!(body.degree(), 2);
    let choice = body.report.degree_choice.clone().expect("degree choice recorded");
    assert_eq!(choice.chosen, 2);
    assert_eq!(choice.volume_tolerance, 0.05);
    assert_eq!(choice.candidates.iter().map(|c| c.0).collect::<Vec<_>>(), vec![2, 4]);
    assert!(choice.reason.starts_with("degree 2 was kept because degree 4"), "{}", choice.reason);
    // The 2d = 2 candidate is the ellipsoid itself: volume 4/3 π · 0.5 · 0.3 · 0.2 within 3 std errors.
    let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.5 * 0.3 * 0.2;
    let (_, v2, e2) = choice.candidates[0];
    assert!((v2 - exact).abs() <= 3.0 * e2 + 1e-3 * exact, "{v2} ± {e2} vs {exact}");
    server.stop().await;
}

/// The labelled configurations of MotionBenchMaker's bookshelf_small scene 1 (the demo's
/// `mbm_bookshelf`): panda_joint1..7 in radians, and whether the collision meshes collide.
fn bookshelf_labels() -> Vec<(Vec<f64>, bool)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/robots/mbm_panda/labels_obj.csv");
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter_map(|line| {
            let c: Vec<&str> = line.split(',').collect();
            (c[0] == "bookshelf_small" && c[1] == "1")
                .then(|| (c[4..11].iter().map(|v| v.parse().unwrap()).collect(), c[11] == "1"))
        })
        .collect()
}

/// The demo's ids as `serve --demo` printed them: `(what, name)` → id (the word after `=`).
fn demo_ids(startup: &[String]) -> std::collections::HashMap<(String, String), String> {
    startup
        .iter()
        .filter_map(|l| {
            let rest = l.strip_prefix("demo: ")?;
            let (left, right) = rest.split_once('=')?;
            let mut what = left.split_whitespace();
            let key = (what.next()?.to_owned(), what.next()?.to_owned());
            Some((key, right.split_whitespace().next()?.to_owned()))
        })
        .collect()
}

/// `sublevel serve --demo` seeds the demo bodies and scene, the robot `panda` and the scene
/// `mbm_bookshelf` holding it once, across restarts; the ids it prints are those the API lists,
/// and the Panda in `mbm_bookshelf` answers the labelled configurations as the meshes do.
///
/// Multi-threaded: the test blocks a thread on the child process while the client's connection
/// task must stay alive to answer the server's graceful-shutdown GOAWAY.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn demo_seeding_is_idempotent_across_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let labels = bookshelf_labels();
    assert_eq!(labels.len(), 200);
    let mut seen = Vec::new();
    for _ in 0..2 {
        let mut server = ChildServer::spawn_with(dir.path(), &["--demo"]);
        let ids = demo_ids(&server.startup);
        let id = |what: &str, name: &str| ids[&(what.to_owned(), name.to_owned())].clone();
        let mut c = server.client().await;
        let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
        for name in ["chair_101", "human_10"] {
            let named: Vec<_> = bodies.iter().filter(|b| b.name == name).map(|b| b.body_id.clone()).collect();
            assert_eq!(named, [id("body", name)]);
        }
        let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes;
        let mut names: Vec<_> = scenes.iter().map(|s| s.name.as_str()).collect();
        names.sort();
        assert_eq!(names, ["demo", "mbm_bookshelf"]);
        let demo = scenes.iter().find(|s| s.name == "demo").unwrap();
        assert_eq!((demo.scene_id.clone(), demo.num_instances), (id("scene", "demo"), 2));
        // The demo pair starts apart.
        let view = c.get_scene(pb::GetSceneRequest { scene_id: demo.scene_id.clone() }).await.unwrap().into_inner();
        let d = distance(&mut c, &view.scene_id, &view.instances[0].instance_id, &view.instances[1].instance_id).await;
        assert!(d.distance > 0.0 && !d.overlapping, "{d:?}");

        // The robot, once, and the bookshelf scene holding it.
        let robots = c.list_robots(pb::ListRobotsRequest::default()).await.unwrap().into_inner().robots;
        assert_eq!(robots.len(), 1);
        assert_eq!((robots[0].name.as_str(), robots[0].robot_id.clone()), ("panda", id("robot", "panda")));
        let shelf = scenes.iter().find(|s| s.name == "mbm_bookshelf").unwrap();
        assert_eq!(shelf.scene_id, id("scene", "mbm_bookshelf"));
        let view = c.get_scene(pb::GetSceneRequest { scene_id: shelf.scene_id.clone() }).await.unwrap().into_inner();
        assert_eq!(view.instances.len(), shelf.num_instances as usize);
        assert!(view.instances.len() >= 3, "the bookshelf's boards: {view:?}");
        assert_eq!(view.robot.as_ref().map(|r| r.robot_id.as_str()), Some(robots[0].robot_id.as_str()));
        // Every labelled configuration, the robot taken from the scene: the meshes' verdicts.
        let req = pb::CheckConfigurationsRequest {
            scene_id: shelf.scene_id.clone(),
            configurations: Some(pb::ConfigurationColumns {
                joint_names: (1..=7).map(|k| format!("panda_joint{k}")).collect(),
                values: labels.iter().flat_map(|(q, _)| q.iter().copied()).collect(),
            }),
            ..Default::default()
        };
        let answer = c.check_configurations(req).await.unwrap().into_inner();
        let want: Vec<bool> = labels.iter().map(|(_, collides)| *collides).collect();
        assert_eq!(answer.collides, want);
        assert!(want.contains(&true) && want.contains(&false));
        seen.push(std::mem::take(&mut server.startup));
        drop(c);
        // Graceful stop by SIGTERM to the child we started.
        server.signal("-TERM");
        let exit = server.child.wait().unwrap();
        assert!(exit.success(), "the server must exit 0 on SIGTERM: {exit:?}");
    }
    assert_eq!(seen[0], seen[1], "a restart must report the same ids");
    assert!(seen[0].iter().any(|l| l.contains("chair_101")));
    assert!(seen[0].iter().any(|l| l.starts_with("demo: robot panda = r-")), "{:?}", seen[0]);
    assert!(seen[0].iter().any(|l| l.starts_with("demo: scene mbm_bookshelf = s-")), "{:?}", seen[0]);
}

/// The point 6: fit the paper's chair and human at degree 4 through the service, slide
/// the chair through the human, check every answer against the level-0 sos certificate, and check
/// that warm starts save Newton iterations.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn end_to_end_chair_slides_through_human() {
    use sublevel::query::sdp_certificate::{certify_distance, certify_growth};
    use sublevel::query::NewtonParams;
    let psb = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/psb");
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;

    let mut bodies = Vec::new();
    for name in ["chair_101", "human_10"] {
        let data = std::fs::read(psb.join(format!("{name}.off"))).unwrap();
        let req = pb::StartFitJobRequest {
            name: name.into(),
            degree: 4,
            source: Some(pb::start_fit_job_request::Source::Mesh(pb::Mesh {
                data,
                mesh_format: pb::MeshFormat::Off as i32,
                ..Default::default()
            })),
            ..Default::default()
        };
        let job_id = c.start_fit_job(req).await.unwrap().into_inner().job_id;
        let last = crate::util::watch_to_end(&mut c, job_id).await.pop().unwrap();
        assert_eq!(last.state, pb::JobState::Succeeded as i32, "{last:?}");
        let got = c.get_body(pb::GetBodyRequest { body_id: last.body_id.clone() }).await.unwrap().into_inner();
        let body = sublevel::Body::from_file(serde_json::from_str(&got.body_json).unwrap()).unwrap();
        assert_eq!(body.degree(), 4);
        bodies.push((last.body_id, body));
    }
    let scene = c.create_scene(pb::CreateSceneRequest { name: "slide".into() }).await.unwrap().into_inner().scene_id;
    let human_pose = Isometry3::identity();
    let i_human = add(&mut c, &scene, &bodies[1].0, at([0.0; 3])).await;
    let slide = |k: usize| -> Isometry3 {
        let s = k as f64 / 23.0;
        let ang = 0.3 * s;
        pose_from_parts("slide", [(ang / 2.0).cos(), 0.0, 0.0, (ang / 2.0).sin()], [-1.6 + 3.2 * s, 0.1, 0.05]).unwrap()
    };
    let proto_pose = |p: &Isometry3| sublevel::service::convert::pose_to_proto(p);
    let i_chair = add(&mut c, &scene, &bodies[0].0, proto_pose(&slide(0))).await;
    let (chair, human) = (&bodies[0].1, &bodies[1].1);
    let (mut warm_iters, mut cold_iters) = (0usize, 0usize);
    let (mut overlapping, mut separated, mut warm_answers) = (0, 0, 0);
    for k in 0..24 {
        let pose_chair = slide(k);
        set_pose(&mut c, &scene, &i_chair, proto_pose(&pose_chair)).await;
        let d = distance(&mut c, &scene, &i_chair, &i_human).await;
        let g = growth(&mut c, &scene, &i_chair, &i_human).await;
        let (ds, gs) = (d.solve.unwrap(), g.solve.unwrap());
        assert!(ds.converged && gs.converged, "k = {k}: {d:?} {g:?}");
        let cd = certify_distance(chair, &pose_chair, human, &human_pose).unwrap();
        let sq = d.distance * d.distance;
        assert!(
            (cd.squared_distance.max(0.0) - sq).abs() <= 1e-6 * sq.max(1.0),
            "k = {k}: {} vs {}",
            cd.squared_distance,
            sq
        );
        let cg = certify_growth(chair, &pose_chair, human, &human_pose).unwrap();
        assert!((cg.value - g.value).abs() <= 1e-6 * cg.value.abs().max(1.0), "k = {k}: {} vs {}", cg.value, g.value);
        if d.overlapping {
            overlapping += 1;
        } else {
            separated += 1;
        }
        if k > 0 {
            warm_answers += usize::from(ds.warm_started) + usize::from(gs.warm_started);
            warm_iters += (ds.iterations + gs.iterations) as usize;
            let params = NewtonParams::default();
            let cold_d = sublevel::query::distance(chair, &pose_chair, human, &human_pose, None, &params);
            let cold_g = sublevel::query::growth(chair, &pose_chair, human, &human_pose, None, &params);
            assert!((cold_d.distance - d.distance).abs() <= 1e-8 * d.distance.max(1.0));
            cold_iters += cold_d.iterations + cold_g.iterations;
        }
    }
    eprintln!(
        "end-to-end: {overlapping} overlapping / {separated} separated poses; Newton iterations over 23 moves: warm {warm_iters} vs cold {cold_iters}"
    );
    assert!(overlapping > 0 && separated > 0, "the slide must pass through: {overlapping} / {separated}");
    assert!(warm_answers >= 23, "only {warm_answers} of 46 answers were warm-started");
    assert!(warm_iters < cold_iters, "warm {warm_iters} vs cold {cold_iters}");
    server.stop().await;
}
