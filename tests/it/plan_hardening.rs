//! Integration tests: `Plan` and the point-cloud names as a hostile client uses them, against a
//! real server. Settings that size the work are bounded (a resolution of 1e300 is refused, not an
//! abort) and a plan answers by its timeout even with the longest edges allowed; plans run on
//! slots of their own, so checks never wait behind them, and a plan's timeout counts its wait; a
//! name never stands for two kinds of thing (a cloud named like a link would take the link's row
//! of the allowed-collision matrix); every part of a request is used or refused, naming its field.

use crate::plan_service::{columns, data, JOINTS};
use crate::util::{assert_status, config, Server};
use std::time::{Duration, Instant};
use sublevel::math::Isometry3;
use sublevel::robot::FittedRobot;
use sublevel::scene::moveit::MotionPlanRequest;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use tonic::transport::Channel;
use tonic::Code;

/// The Panda uploaded and `scenario`'s first scene imported: (robot id, scene id, request text,
/// start, goal).
async fn setup(c: &mut SublevelClient<Channel>, scenario: &str) -> (String, String, String, Vec<f64>, Vec<f64>) {
    let bytes = std::fs::read(data("panda/panda.robot.json")).unwrap();
    let robot = c
        .upload_robot(pb::UploadRobotRequest { name: "panda".into(), robot_file: bytes })
        .await
        .unwrap()
        .into_inner()
        .robot
        .unwrap()
        .robot_id;
    let yaml = std::fs::read(data(&format!("mbm_panda/scenes/{scenario}/scene0001.yaml"))).unwrap();
    let req = pb::ImportSceneRequest { scene: Some(pb::import_scene_request::Scene::Yaml(yaml)), ..Default::default() };
    let scene_id = c.import_scene(req).await.unwrap().into_inner().scene_id;
    let text = std::fs::read_to_string(data(&format!("mbm_panda/requests/{scenario}/request0001.yaml"))).unwrap();
    let request = MotionPlanRequest::from_yaml(text.as_bytes()).unwrap();
    let pick =
        |joints: &[(String, f64)]| JOINTS.iter().map(|n| joints.iter().find(|(m, _)| m == n).unwrap().1).collect();
    let (start, goal) = (pick(&request.start), pick(&request.goal));
    (robot, scene_id, text, start, goal)
}

fn typed(robot: &str, scene: &str, start: &[f64], goals: &[Vec<f64>], settings: pb::PlanSettings) -> pb::PlanRequest {
    pb::PlanRequest {
        robot_id: robot.into(),
        scene_id: scene.into(),
        start: columns(&[start.to_vec()]),
        goal_configurations: columns(goals),
        settings: Some(settings),
        ..Default::default()
    }
}

fn yaml(robot: &str, scene: &str, text: &str, settings: pb::PlanSettings) -> pb::PlanRequest {
    pb::PlanRequest {
        robot_id: robot.into(),
        scene_id: scene.into(),
        motion_plan_request: Some(pb::plan_request::MotionPlanRequest::MotionPlanRequestYaml(text.into())),
        settings: Some(settings),
        ..Default::default()
    }
}

/// The first configuration of `scenario`'s first scene that the mesh labels call colliding.
fn colliding(scenario: &str) -> Vec<f64> {
    let labels = std::fs::read_to_string(data("mbm_panda/labels_obj.csv")).unwrap();
    labels
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|c| c[0] == scenario && c[1] == "1" && c[11] == "1")
        .map(|c| c[4..11].iter().map(|v| v.parse().unwrap()).collect())
        .unwrap()
}

/// A slow search on purpose: the finest resolution allowed and tiny steps, on the cage problem,
/// whose plans take milliseconds at the defaults.
fn slow(timeout: f64) -> pb::PlanSettings {
    pb::PlanSettings { timeout: Some(timeout), range: 1e-3, resolution: 1000.0, ..Default::default() }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn settings_that_size_the_work_are_bounded_and_a_plan_answers_by_its_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot, scene, text, start, goal) = setup(&mut c, "cage").await;
    let with = |s: pb::PlanSettings| typed(&robot, &scene, &start, std::slice::from_ref(&goal), s);
    // Each of these aborted the server (1e9, 1e300) or ran far past its timeout (1e7); 1001 is
    // just past the bound.
    for resolution in [1e300, 1e9, 1e7, 1001.0] {
        let r = c.plan(with(pb::PlanSettings { resolution, ..Default::default() })).await;
        assert_status(r, Code::InvalidArgument, "settings.resolution");
    }
    let cases: [(pb::PlanSettings, &str); 6] = [
        (pb::PlanSettings { max_goals: 65, ..Default::default() }, "settings.max_goals"),
        (pb::PlanSettings { smoothing_passes: 9, ..Default::default() }, "settings.smoothing_passes"),
        (pb::PlanSettings { tolerance: 1e300, ..Default::default() }, "settings.tolerance"),
        (pb::PlanSettings { padding: 1e300, ..Default::default() }, "settings.padding"),
        (pb::PlanSettings { timeout: Some(1e300), ..Default::default() }, "settings.timeout"),
        (pb::PlanSettings { timeout: Some(f64::NAN), ..Default::default() }, "settings.timeout"),
    ];
    for (settings, field) in cases {
        let e = c.plan(with(settings)).await.unwrap_err();
        assert_eq!((e.code(), e.message().contains(field)), (Code::InvalidArgument, true), "{field}: {e:?}");
        // A huge number is echoed short, never as hundreds of digits.
        assert!(e.message().len() < 300, "{}", e.message());
    }
    // The longest edges allowed (resolution 1000, steps of a whole joint range) on a 0.4 s plan:
    // answered by the timeout, measured by the server and by the client.
    let long = pb::PlanSettings { timeout: Some(0.4), range: 100.0, resolution: 1000.0, ..Default::default() };
    let clock = Instant::now();
    let r = c.plan(yaml(&robot, &scene, &text, long)).await.unwrap().into_inner();
    let waited = clock.elapsed();
    let total = r.timing.unwrap().total;
    assert!(total <= 0.45, "the plan's own time {total} s passed its 0.4 s timeout by more than 50 ms");
    assert!(waited < Duration::from_millis(1500), "answered after {waited:?}");
    assert!(matches!(r.status(), pb::PlanStatus::Solved | pb::PlanStatus::TimedOut), "{:?}: {}", r.status(), r.message);
    // The server lives on and plans at the defaults.
    let r = c.plan(yaml(&robot, &scene, &text, pb::PlanSettings { timeout: Some(20.0), ..Default::default() })).await;
    assert_eq!(r.unwrap().into_inner().status(), pb::PlanStatus::Solved);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn plans_run_on_their_own_slots_and_their_timeout_counts_from_arrival() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = sublevel::service::ServerConfig { batch_workers: 2, max_concurrent_plans: 1, ..config(dir.path()) };
    let server = Server::start(cfg).await;
    let mut c = server.client().await;
    let (robot, scene, text, start, _) = setup(&mut c, "cage").await;
    // A long plan takes the one planning slot for 4 s.
    let mut first = c.clone();
    let long = yaml(&robot, &scene, &text, slow(4.0));
    let first = tokio::spawn(async move {
        let clock = Instant::now();
        let r = first.plan(long).await.unwrap().into_inner();
        (r, clock.elapsed())
    });
    tokio::time::sleep(Duration::from_millis(300)).await;
    // A 1 s plan behind it answers TIMED_OUT by its own timeout, counted from its arrival, not
    // after the long plan's 4 s.
    let clock = Instant::now();
    let queued = c.plan(yaml(&robot, &scene, &text, slow(1.0))).await.unwrap().into_inner();
    let waited = clock.elapsed();
    assert_eq!(queued.status(), pb::PlanStatus::TimedOut, "{queued:?}");
    assert!(queued.message.contains("--max-concurrent-plans"), "{}", queued.message);
    assert!(queued.path.is_empty() && queued.states_checked == 0);
    assert!(waited < Duration::from_millis(2500), "the queued 1 s plan answered after {waited:?}");
    // A check of 1 000 configurations while the plan runs: the batch slots are free, so it is
    // answered long before the plan ends.
    let q: Vec<Vec<f64>> = (0..1000).map(|i| start.iter().map(|v| v + 1e-4 * (i % 10) as f64).collect()).collect();
    let check = pb::CheckConfigurationsRequest {
        robot_id: robot.clone(),
        scene_id: scene.clone(),
        configurations: columns(&q),
        ..Default::default()
    };
    let got = c.check_configurations(check).await.unwrap().into_inner();
    assert_eq!(got.collides.len(), 1000);
    assert!(!first.is_finished(), "the long plan ended before the check was answered: nothing was shown");
    let (r, took) = first.await.unwrap();
    assert!(matches!(r.status(), pb::PlanStatus::TimedOut | pb::PlanStatus::Solved), "{r:?}");
    assert!(took >= Duration::from_secs(3), "the long plan answered after {took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_part_of_a_plan_request_is_used_or_refused_naming_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot, scene, text, start, goal) = setup(&mut c, "box").await;
    let settings = || pb::PlanSettings { timeout: Some(20.0), ..Default::default() };
    // Eight colliding goals before a free ninth: the free one is found (every goal is checked
    // before max_goals = 8 are kept).
    let down = colliding("box");
    let mut goals = vec![down.clone(); 8];
    goals.push(goal.clone());
    let r = c.plan(typed(&robot, &scene, &start, &goals, settings())).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert_eq!(r.goal, goal);
    // Too many goals, or max_goals past its bound: refused, not clamped.
    let many = vec![goal.clone(); 65];
    assert_status(c.plan(typed(&robot, &scene, &start, &many, settings())).await, Code::InvalidArgument, "goal");
    let clamp = pb::PlanSettings { max_goals: 100, ..settings() };
    let r = c.plan(typed(&robot, &scene, &start, std::slice::from_ref(&goal), clamp)).await;
    assert_status(r, Code::InvalidArgument, "settings.max_goals");

    // The MotionPlanRequest's start state: every name misspelled was planned from the scene's
    // positions; now the first unknown name is refused.
    let field = "motion_plan_request_yaml";
    let misspelled = text.replace("panda_joint", "panda_jiont");
    assert_status(
        c.plan(yaml(&robot, &scene, &misspelled, settings())).await,
        Code::InvalidArgument,
        &format!("{field}.start_state.joint_state.name[0]"),
    );
    let repeated = text.replace("panda_joint2, panda_joint3", "panda_joint2, panda_joint2");
    assert_ne!(repeated, text);
    assert_status(
        c.plan(yaml(&robot, &scene, &repeated, settings())).await,
        Code::InvalidArgument,
        "start_state.joint_state.name[2]",
    );
    // A goal's position constraints are not supported: refused, not ignored.
    let exact = |q: &[f64]| JOINTS.iter().zip(q).map(|(n, v)| format!("{{joint_name: {n}, position: {v}}}")).collect();
    let positioned = request_text(&start, &[exact(&goal)], "position_constraints: [{link_name: panda_hand}], ");
    assert_status(
        c.plan(yaml(&robot, &scene, &positioned, settings())).await,
        Code::InvalidArgument,
        &format!("{field}.goal_constraints[0].position_constraints"),
    );
    // A second goal holding NaN is refused; a second valid goal is planned to (either one).
    let second = |position: &str| {
        request_text(&start, &[exact(&goal), vec![format!("{{joint_name: panda_joint1, position: {position}}}")]], "")
    };
    assert_status(
        c.plan(yaml(&robot, &scene, &second(".nan"), settings())).await,
        Code::InvalidArgument,
        "goal_constraints[1].joint_constraints[0].position",
    );
    let r = c.plan(yaml(&robot, &scene, &second("0.1"), settings())).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    let mut other = start.clone();
    other[0] = 0.1;
    assert!(r.goal == goal || r.goal == other, "{:?}", r.goal);
    // A plan certified at 5 mm padding re-validates by CheckMotions at that padding and the
    // answer's check_tolerance: every edge valid.
    let padded = pb::PlanSettings { padding: 0.005, ..settings() };
    let r = c.plan(typed(&robot, &scene, &start, std::slice::from_ref(&goal), padded)).await.unwrap().into_inner();
    assert_eq!(r.status(), pb::PlanStatus::Solved, "{r:?}");
    assert!((r.check_tolerance - 1e-5).abs() < 1e-18, "{}", r.check_tolerance);
    let path: Vec<Vec<f64>> = r.path.chunks(7).map(<[f64]>::to_vec).collect();
    let recheck = pb::CheckMotionsRequest {
        robot_id: robot.clone(),
        scene_id: scene.clone(),
        start: columns(&path[..path.len() - 1]),
        end: columns(&path[1..]),
        padding: 0.005,
        tolerance: r.check_tolerance,
        ..Default::default()
    };
    let got = c.check_motions(recheck).await.unwrap().into_inner();
    assert_eq!(got.valid, vec![true; path.len() - 1], "{got:?}");
    // A pose goal without its pose was planned to the identity; now it is refused.
    let mut no_pose = typed(&robot, &scene, &start, &[], settings());
    no_pose.goal_configurations = None;
    no_pose.goal_pose = Some(pb::PoseGoal { link: "panda_hand".into(), ..Default::default() });
    assert_status(c.plan(no_pose).await, Code::InvalidArgument, "goal_pose.pose");
}

/// A MotionPlanRequest in YAML: the start state's seven joints, then one goal constraint per
/// entry of `goals` (its joint constraints, each `{joint_name: …, position: …}`), `extra` before
/// each goal's joint constraints.
fn request_text(start: &[f64], goals: &[Vec<String>], extra: &str) -> String {
    let mut text = format!(
        "start_state: {{joint_state: {{name: [{}], position: {start:?}}}}}\ngoal_constraints:\n",
        JOINTS.join(", ")
    );
    for g in goals {
        text.push_str(&format!("  - {{{extra}joint_constraints: [{}]}}\n", g.join(", ")));
    }
    text
}

/// A wall of points, 1 cm apart, 0.4 × 0.4 m in the plane x = `x` centered at (y, z), as a
/// PointCloud2 of 12-byte records in the world frame.
fn wall(x: f32, y: f32, z: f32) -> pb::update_point_cloud_request::Frame {
    let mut data = Vec::new();
    for i in -20..=20 {
        for j in -20..=20 {
            for v in [x, y + 0.01 * i as f32, z + 0.01 * j as f32] {
                data.extend(v.to_le_bytes());
            }
        }
    }
    pb::update_point_cloud_request::Frame::Points(pb::PackedPoints { data, point_step: 12, ..Default::default() })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_name_never_stands_for_two_kinds_of_thing() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    // The bookshelf scene's allowed-collision matrix allows `panda_link3` against almost
    // everything.
    let (robot_id, scene, _, start, goal) = setup(&mut c, "bookshelf_small").await;
    let robot = FittedRobot::load(&data("panda/panda.robot.json")).unwrap();
    let hand = robot.model.link_index("panda_hand").unwrap();
    let at = robot.model.link_poses(&start, &Isometry3::identity()).unwrap()[hand].translation.vector;
    let update = |name: &str| pb::UpdatePointCloudRequest {
        scene_id: scene.clone(),
        name: name.into(),
        frame: Some(wall(at.x as f32, at.y as f32, at.z as f32)),
        ..Default::default()
    };
    let check = |robot_id: &str| pb::CheckConfigurationsRequest {
        robot_id: robot_id.into(),
        scene_id: scene.clone(),
        configurations: columns(std::slice::from_ref(&start)),
        ..Default::default()
    };
    // Named `wall`, the wall through the hand collides with the start.
    c.update_point_cloud(update("wall")).await.unwrap();
    let got = c.check_configurations(check(&robot_id)).await.unwrap().into_inner();
    assert_eq!(got.collides, vec![true], "{got:?}");
    c.remove_point_cloud(pb::RemovePointCloudRequest { scene_id: scene.clone(), name: "wall".into() }).await.unwrap();
    // Named like a link, it was free (the link's row of the matrix); now the checks and plans
    // against the scene are refused, naming the cloud.
    c.update_point_cloud(update("panda_link3")).await.unwrap();
    assert_status(c.check_configurations(check(&robot_id)).await, Code::FailedPrecondition, "panda_link3");
    let plan = typed(&robot_id, &scene, &start, std::slice::from_ref(&goal), Default::default());
    assert_status(c.plan(plan).await, Code::FailedPrecondition, "point cloud `panda_link3`");
    c.remove_point_cloud(pb::RemovePointCloudRequest { scene_id: scene.clone(), name: "panda_link3".into() })
        .await
        .unwrap();
    // With the robot placed in the scene, such a cloud is refused at the update.
    let place = pb::SetSceneRobotRequest { scene_id: scene.clone(), robot_id: robot_id.clone(), ..Default::default() };
    c.set_scene_robot(place).await.unwrap();
    assert_status(c.update_point_cloud(update("panda_link3")).await, Code::InvalidArgument, "name");
    // Names with control bytes are refused.
    for bad in ["wall\0", "wall\nINFO forged", "\u{7}"] {
        assert_status(c.update_point_cloud(update(bad)).await, Code::InvalidArgument, "name");
    }
    // An attached object named like a link, or like the scene's cloud, is refused.
    c.update_point_cloud(update("wall")).await.unwrap();
    for (name, what) in [("panda_link3", "a link"), ("wall", "a point cloud")] {
        let ball = pb::AttachedObject {
            link: "panda_hand".into(),
            name: name.into(),
            primitive: Some(pb::Primitive {
                kind: pb::PrimitiveKind::Sphere as i32,
                radius: 0.02,
                ..Default::default()
            }),
            origin: Some(crate::util::at([0.0, 0.0, 0.1])),
        };
        let mut req = check(&robot_id);
        req.attached = vec![ball];
        let e = c.check_configurations(req).await.unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains("attached[0].name") && e.message().contains(what), "{}", e.message());
    }
}

/// Milliseconds of `n` checks of 1 000 configurations each (the cage scene's start, jittered),
/// one after another; every answer has its 1 000 verdicts.
async fn timed_checks(c: &mut SublevelClient<Channel>, robot: &str, scene: &str, start: &[f64], n: usize) -> Vec<f64> {
    let q: Vec<Vec<f64>> = (0..1000).map(|i| start.iter().map(|v| v + 1e-3 * (i % 17) as f64).collect()).collect();
    let req = pb::CheckConfigurationsRequest {
        robot_id: robot.into(),
        scene_id: scene.into(),
        configurations: columns(&q),
        ..Default::default()
    };
    let mut ms = Vec::with_capacity(n);
    for _ in 0..n {
        let clock = Instant::now();
        let got = c.check_configurations(req.clone()).await.unwrap().into_inner();
        ms.push(clock.elapsed().as_secs_f64() * 1e3);
        assert_eq!(got.collides.len(), 1000);
    }
    ms.sort_by(f64::total_cmp);
    ms
}

/// Isolation: two clients sending long plans without end (each a 1.5 s slow search, the next sent
/// as soon as one answers) leave a third client's 1 000-configuration checks within 10 × their
/// idle p99, and every plan answers within its timeout plus 50 ms by the server's clock. Prints
/// the figures.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn checks_keep_their_latency_beside_plans_without_end() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot, scene, text, start, _) = setup(&mut c, "cage").await;
    let p99 = |ms: &[f64]| ms[((ms.len() as f64 - 1.0) * 0.99).round() as usize];
    let n = 60;
    timed_checks(&mut c, &robot, &scene, &start, 3).await;
    let idle = timed_checks(&mut c, &robot, &scene, &start, n).await;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut planners = Vec::new();
    for _ in 0..2 {
        let (mut pc, stop) = (server.client().await, stop.clone());
        let req = yaml(&robot, &scene, &text, slow(1.5));
        planners.push(tokio::spawn(async move {
            let mut late = Vec::new();
            let mut plans = 0;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let r = pc.plan(req.clone()).await.unwrap().into_inner();
                late.push(r.timing.unwrap().total - 1.5);
                plans += 1;
            }
            (plans, late)
        }));
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let loaded = timed_checks(&mut c, &robot, &scene, &start, n).await;
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let (mut plans, mut late) = (0, Vec::new());
    for p in planners {
        let (k, l) = p.await.unwrap();
        plans += k;
        late.extend(l);
    }
    let worst = late.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    println!("checks of 1 000 configurations beside two clients planning without end ({plans} plans of 1.5 s)");
    println!("| | p50 ms | p99 ms | max ms |\n|---|---|---|---|");
    println!("| idle | {:.2} | {:.2} | {:.2} |", idle[n / 2], p99(&idle), idle[n - 1]);
    println!("| two planning clients | {:.2} | {:.2} | {:.2} |", loaded[n / 2], p99(&loaded), loaded[n - 1]);
    println!("latest plan answer past its timeout: {:.1} ms", worst * 1e3);
    assert!(plans >= 2, "the planning clients never finished a plan");
    assert!(worst <= 0.05, "a plan answered {:.1} ms past its timeout", worst * 1e3);
    assert!(
        p99(&loaded) <= 10.0 * p99(&idle),
        "loaded p99 {:.2} ms > 10 × idle p99 {:.2} ms",
        p99(&loaded),
        p99(&idle)
    );
}

/// Every numeric setting of `Plan` at NaN, ±inf, 1e300, 1e-300, 0 and −1: answered (a status)
/// or refused naming `settings.FIELD`, never another error; the server answers a plain plan after.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_plan_setting_at_hostile_values_is_answered_or_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot, scene, text, _, _) = setup(&mut c, "box").await;
    let base = || pb::PlanSettings { timeout: Some(0.3), ..Default::default() };
    let mut asked = 0;
    for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, 1e-300, 0.0, -1.0] {
        let cases: [(&str, pb::PlanSettings); 6] = [
            ("timeout", pb::PlanSettings { timeout: Some(v), ..base() }),
            ("range", pb::PlanSettings { range: v, ..base() }),
            ("padding", pb::PlanSettings { padding: v, ..base() }),
            ("resolution", pb::PlanSettings { resolution: v, ..base() }),
            ("goal_bias", pb::PlanSettings { goal_bias: Some(v), ..base() }),
            ("tolerance", pb::PlanSettings { tolerance: v, ..base() }),
        ];
        for (field, settings) in cases {
            asked += 1;
            match c.plan(yaml(&robot, &scene, &text, settings)).await {
                Ok(r) => assert_ne!(r.into_inner().status(), pb::PlanStatus::Unspecified, "{field} = {v}"),
                Err(e) => {
                    assert_eq!(e.code(), Code::InvalidArgument, "{field} = {v}: {e:?}");
                    assert!(e.message().contains(&format!("settings.{field}")), "{field} = {v}: {}", e.message());
                }
            }
        }
    }
    for n in [0, 1, 8, 9, 64, 65, u32::MAX] {
        for (field, settings) in [
            ("max_goals", pb::PlanSettings { max_goals: n, ..base() }),
            ("smoothing_passes", pb::PlanSettings { smoothing_passes: n, ..base() }),
        ] {
            asked += 1;
            if let Err(e) = c.plan(yaml(&robot, &scene, &text, settings)).await {
                assert_eq!(e.code(), Code::InvalidArgument, "{field} = {n}: {e:?}");
                assert!(e.message().contains(&format!("settings.{field}")), "{}", e.message());
            }
        }
    }
    assert_eq!(asked, 56);
    let r = c.plan(yaml(&robot, &scene, &text, pb::PlanSettings { timeout: Some(20.0), ..Default::default() })).await;
    assert_eq!(r.unwrap().into_inner().status(), pb::PlanStatus::Solved);
}

/// Two far points no longer stretch a cloud's gap grid: a two-point frame 10 m apart holds well
/// under a megabyte (its dense grid held 31 MB), and a wall with two extra points at ±9.9e5 m holds
/// about what the wall alone holds and gives every configuration the wall's verdict (the far points
/// are out of every link's reach).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn far_points_hold_memory_in_proportion_and_change_no_verdict() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot_id, scene, _, start, _) = setup(&mut c, "cage").await;
    let packed = |points: &[[f32; 3]]| {
        let data = points.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        pb::update_point_cloud_request::Frame::Points(pb::PackedPoints { data, point_step: 12, ..Default::default() })
    };
    let update = |name: &str, frame| pb::UpdatePointCloudRequest {
        scene_id: scene.clone(),
        name: name.into(),
        frame: Some(frame),
        // The far points kept: no range filter.
        filter: Some(pb::CloudFilter { max_range: 2e6, ..Default::default() }),
        ..Default::default()
    };
    let pair = c.update_point_cloud(update("pair", packed(&[[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]))).await;
    let pair = pair.unwrap().into_inner();
    assert_eq!(pair.counts.unwrap().kept, 2);
    assert!(pair.memory_bytes < 1 << 20, "a two-point cloud holds {} bytes", pair.memory_bytes);
    c.remove_point_cloud(pb::RemovePointCloudRequest { scene_id: scene.clone(), name: "pair".into() }).await.unwrap();

    // A 0.4 m wall of points 1 cm apart through the workspace at x = 0.5.
    let mut wall: Vec<[f32; 3]> = Vec::new();
    for i in -20..=20 {
        for j in 0..=40 {
            wall.push([0.5, 0.01 * i as f32, 0.2 + 0.01 * j as f32]);
        }
    }
    let q: Vec<Vec<f64>> = (0..300).map(|i| start.iter().map(|v| v + 0.004 * (i as f64) - 0.6).collect()).collect();
    let check = pb::CheckConfigurationsRequest {
        robot_id: robot_id.clone(),
        scene_id: scene.clone(),
        configurations: columns(&q),
        ..Default::default()
    };
    let alone = c.update_point_cloud(update("wall", packed(&wall))).await.unwrap().into_inner();
    let near = c.check_configurations(check.clone()).await.unwrap().into_inner().collides;
    let mut far = wall.clone();
    far.extend([[9.9e5, 9.9e5, 9.9e5], [-9.9e5, -9.9e5, -9.9e5]]);
    let stretched = c.update_point_cloud(update("wall", packed(&far))).await.unwrap().into_inner();
    assert_eq!(stretched.counts.unwrap().kept, alone.counts.unwrap().kept + 2);
    assert!(
        stretched.memory_bytes < 2 * alone.memory_bytes,
        "{} bytes with the far points, {} without",
        stretched.memory_bytes,
        alone.memory_bytes
    );
    let with_far = c.check_configurations(check).await.unwrap().into_inner().collides;
    assert_eq!(with_far, near);
    assert!(near.iter().any(|&c| c) && near.iter().any(|&c| !c), "the wall decides some configurations either way");
}

/// 48 plans at once on the default planning slots: every one answered with a status (no error),
/// none later than its 1 s timeout plus 50 ms by the server's clock, those that waited past their
/// deadline for a slot TIMED_OUT saying so.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn forty_eight_concurrent_plans_are_each_answered_by_their_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (robot, scene, text, _, _) = setup(&mut c, "cage").await;
    let mut calls = Vec::new();
    for _ in 0..48 {
        let (mut pc, req) = (c.clone(), yaml(&robot, &scene, &text, slow(1.0)));
        calls.push(tokio::spawn(async move { pc.plan(req).await }));
    }
    let (mut waited, mut planned) = (0, 0);
    for call in calls {
        let r = call.await.unwrap().expect("a plan answered with an error").into_inner();
        let total = r.timing.unwrap().total;
        assert!(total <= 1.05, "answered {:.1} ms past its timeout", (total - 1.0) * 1e3);
        if r.message.contains("--max-concurrent-plans") {
            assert_eq!(r.status(), pb::PlanStatus::TimedOut);
            waited += 1;
        } else {
            planned += 1;
        }
    }
    assert_eq!(waited + planned, 48);
    assert!(planned >= 1 && waited >= 1, "{planned} planned, {waited} waited past their deadline");
}
