//! Integration tests: service. A real server on 127.0.0.1:0 with a shutdown channel, a real
//! client, a throwaway data directory.

use std::path::Path;
use sublevel::body::ellipsoid;
use sublevel::math::{pose_from_parts, Isometry3, Point3, Vector3};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::{serve, ServerConfig};
use tonic::transport::Channel;
use tonic::Code;

pub(crate) struct Server {
    addr: std::net::SocketAddr,
    shutdown: tokio::sync::oneshot::Sender<()>,
    handle: tokio::task::JoinHandle<sublevel::Result<()>>,
}

impl Server {
    pub(crate) async fn start(config: ServerConfig) -> Server {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (shutdown, rx) = tokio::sync::oneshot::channel::<()>();
        let handle = tokio::spawn(serve(listener, config, async move {
            let _ = rx.await;
        }));
        Server { addr, shutdown, handle }
    }

    pub(crate) async fn client(&self) -> SublevelClient<Channel> {
        let channel = Channel::from_shared(format!("http://{}", self.addr)).unwrap().connect().await.unwrap();
        SublevelClient::new(channel).max_decoding_message_size(usize::MAX)
    }

    pub(crate) async fn channel(&self) -> Channel {
        Channel::from_shared(format!("http://{}", self.addr)).unwrap().connect().await.unwrap()
    }

    pub(crate) async fn stop(self) {
        self.shutdown.send(()).unwrap();
        self.handle.await.unwrap().unwrap();
    }
}

pub(crate) fn config(dir: &Path) -> ServerConfig {
    ServerConfig { data_dir: dir.to_path_buf(), ..ServerConfig::default() }
}

pub(crate) fn pose(q: [f64; 4], t: [f64; 3]) -> pb::Pose {
    pb::Pose {
        rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
        translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
    }
}

pub(crate) fn at(t: [f64; 3]) -> pb::Pose {
    pose([1.0, 0.0, 0.0, 0.0], t)
}

fn v(p: &Option<pb::Vec3>) -> Vector3 {
    let p = p.as_ref().unwrap();
    Vector3::new(p.x, p.y, p.z)
}

pub(crate) async fn upload_sphere(c: &mut SublevelClient<Channel>, name: &str, center: [f64; 3], r: f64) -> String {
    let json = serde_json::to_string(&ellipsoid(center, [r; 3]).unwrap().to_file()).unwrap();
    let req = pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
    c.upload_body(req).await.unwrap().into_inner().body_id
}

pub(crate) async fn add(c: &mut SublevelClient<Channel>, scene: &str, body: &str, p: pb::Pose) -> String {
    let req = pb::AddInstanceRequest { scene_id: scene.into(), body_id: body.into(), pose: Some(p) };
    c.add_instance(req).await.unwrap().into_inner().instance_id
}

pub(crate) async fn distance(c: &mut SublevelClient<Channel>, scene: &str, a: &str, b: &str) -> pb::DistanceAnswer {
    let req = pb::DistanceRequest {
        scene_id: scene.into(),
        instance_a: a.into(),
        instance_b: b.into(),
        ..Default::default()
    };
    c.distance(req).await.unwrap().into_inner().answer.unwrap()
}

async fn growth(c: &mut SublevelClient<Channel>, scene: &str, a: &str, b: &str) -> pb::GrowthAnswer {
    let req =
        pb::GrowthRequest { scene_id: scene.into(), instance_1: a.into(), instance_2: b.into(), ..Default::default() };
    c.growth(req).await.unwrap().into_inner().answer.unwrap()
}

async fn set_pose(c: &mut SublevelClient<Channel>, scene: &str, inst: &str, p: pb::Pose) {
    let poses = vec![pb::InstancePose { instance_id: inst.into(), pose: Some(p) }];
    let r = c.set_poses(pb::SetPosesRequest { scene_id: scene.into(), poses }).await.unwrap();
    assert_eq!(r.into_inner().updated, 1);
}

/// Spheres: distance = ‖c₁ − c₂‖ − r₁ − r₂ (closed form); growth d(p₁‖p₂) = (‖c₁ − c₂‖ − r₂)² / r₁².
#[tokio::test]
async fn round_trip_spheres_match_closed_forms_and_warm_start() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;

    // Body 1 by JSON, off-center in its own frame; body 2 by structured fields.
    let b1 = upload_sphere(&mut c, "one", [0.1, 0.0, 0.0], 0.5).await;
    let file2 = ellipsoid([0.0; 3], [0.3; 3]).unwrap().to_file();
    let data = sublevel::service::convert::body_file_to_proto(&file2);
    let req = pb::UploadBodyRequest { name: "two".into(), body: Some(pb::upload_body_request::Body::Data(data)) };
    let b2 = c.upload_body(req).await.unwrap().into_inner().body_id;
    let got = c.get_body(pb::GetBodyRequest { body_id: b2.clone() }).await.unwrap().into_inner();
    assert_eq!(got.name, "two");
    assert_eq!(got.data.unwrap().coefficients, file2.coefficients);
    let listed = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner();
    assert_eq!((listed.bodies.len(), listed.next_page_token.as_str()), (2, ""));
    // Pages of one: the first body, a token, then the second body and no token.
    let first = c.list_bodies(pb::ListBodiesRequest { page_size: 1, ..Default::default() }).await.unwrap().into_inner();
    assert_eq!(first.bodies.len(), 1);
    assert_eq!(first.next_page_token, first.bodies[0].body_id);
    let req = pb::ListBodiesRequest { page_size: 1, page_token: first.next_page_token.clone() };
    let second = c.list_bodies(req).await.unwrap().into_inner();
    assert_eq!(second.bodies.len(), 1);
    assert!(second.bodies[0].body_id > first.bodies[0].body_id, "ordered by id");
    assert_eq!(second.next_page_token, "");
    let long = pb::ListBodiesRequest { page_size: 1, page_token: "x".repeat(200) };
    assert_status(c.list_bodies(long).await, Code::InvalidArgument, "page_token");

    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    // Instance 1: rotated 90° about z and moved; its sphere center (0.1, 0, 0) lands at (1, 2.1, 0).
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let i1 = add(&mut c, &scene, &b1, pose([h, 0.0, 0.0, h], [1.0, 2.0, 0.0])).await;
    let i2 = add(&mut c, &scene, &b2, at([4.0, 6.1, 0.0])).await;
    let c1 = Vector3::new(1.0, 2.1, 0.0);
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    assert_eq!(view.instances.len(), 2);

    let mut warm_seen = 0;
    for (k, c2) in [[4.0, 6.1, 0.0], [3.8, 5.9, 0.1], [3.5, 5.5, 0.2], [3.0, 5.0, 0.3]].into_iter().enumerate() {
        let c2 = Vector3::from(c2);
        if k > 0 {
            set_pose(&mut c, &scene, &i2, at([c2.x, c2.y, c2.z])).await;
        }
        let d = distance(&mut c, &scene, &i1, &i2).await;
        let expected = (c2 - c1).norm() - 0.5 - 0.3;
        assert!((d.distance - expected).abs() < 1e-8, "k = {k}: {} vs {expected}", d.distance);
        let n = (c2 - c1).normalize();
        assert!((v(&d.witness_a) - (c1 + n * 0.5)).norm() < 1e-6);
        assert!((v(&d.witness_b) - (c2 - n * 0.3)).norm() < 1e-6);
        assert!((v(&d.normal) - n).norm() < 1e-6);
        let solve = d.solve.unwrap();
        assert!(solve.converged && solve.status == pb::SolveStatus::Converged as i32);
        assert!(!d.overlapping);
        assert_eq!(solve.warm_started, k > 0, "k = {k}");
        warm_seen += usize::from(solve.warm_started);

        let g = growth(&mut c, &scene, &i1, &i2).await;
        let expected = ((c2 - c1).norm() - 0.3).powi(2) / 0.25;
        assert!((g.value - expected).abs() < 1e-8 * expected, "k = {k}: {} vs {expected}", g.value);
        assert!(g.separated && g.solve.unwrap().converged);
    }
    assert_eq!(warm_seen, 3);

    // Batch: both kinds, both orders, against the same closed forms.
    let c2 = Vector3::new(3.0, 5.0, 0.3);
    let pair = |kind: pb::QueryKind, a: &str, b: &str| pb::QueryPair {
        kind: kind as i32,
        first: a.into(),
        second: b.into(),
        ..Default::default()
    };
    let pairs = vec![
        pair(pb::QueryKind::Distance, &i1, &i2),
        pair(pb::QueryKind::Growth, &i2, &i1),
        pair(pb::QueryKind::Distance, &i2, &i1),
    ];
    let answers = c
        .batch_query(pb::BatchQueryRequest { scene_id: scene.clone(), pairs, columns: None })
        .await
        .unwrap()
        .into_inner()
        .answers;
    assert_eq!(answers.len(), 3);
    let dist = (c2 - c1).norm();
    match (&answers[0].answer, &answers[1].answer, &answers[2].answer) {
        (
            Some(pb::query_answer::Answer::Distance(d0)),
            Some(pb::query_answer::Answer::Growth(g1)),
            Some(pb::query_answer::Answer::Distance(d2)),
        ) => {
            assert!((d0.distance - (dist - 0.8)).abs() < 1e-8);
            assert!(d0.solve.as_ref().unwrap().warm_started, "same pair as the single queries");
            let expected = (dist - 0.5).powi(2) / 0.09;
            assert!((g1.value - expected).abs() < 1e-8 * expected, "{} vs {expected}", g1.value);
            assert!((d2.distance - (dist - 0.8)).abs() < 1e-8);
        }
        other => panic!("wrong answer kinds: {other:?}"),
    }

    // Overlap: move sphere 2 onto sphere 1.
    set_pose(&mut c, &scene, &i2, at([1.2, 2.1, 0.0])).await;
    let d = distance(&mut c, &scene, &i1, &i2).await;
    assert!(d.overlapping && d.distance == 0.0);
    let g = growth(&mut c, &scene, &i1, &i2).await;
    assert!(!g.separated && g.value <= 1.0);

    // Removing an instance works and queries on it are NOT_FOUND.
    c.remove_instance(pb::RemoveInstanceRequest { scene_id: scene.clone(), instance_id: i2.clone() }).await.unwrap();
    let req = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: i1.clone(),
        instance_b: i2.clone(),
        ..Default::default()
    };
    assert_eq!(c.distance(req).await.unwrap_err().code(), Code::NotFound);
    server.stop().await;
}

#[tokio::test]
async fn bodies_scenes_and_poses_survive_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let b1 = upload_sphere(&mut c, "big", [0.0; 3], 1.0).await;
    let b2 = upload_sphere(&mut c, "small", [0.0; 3], 0.25).await;
    let doomed = upload_sphere(&mut c, "doomed", [0.0; 3], 0.1).await;
    c.delete_body(pb::DeleteBodyRequest { body_id: doomed.clone() }).await.unwrap();
    let scene = c.create_scene(pb::CreateSceneRequest { name: "kept".into() }).await.unwrap().into_inner().scene_id;
    let gone = c.create_scene(pb::CreateSceneRequest { name: "gone".into() }).await.unwrap().into_inner().scene_id;
    c.delete_scene(pb::DeleteSceneRequest { scene_id: gone.clone() }).await.unwrap();
    let i1 = add(&mut c, &scene, &b1, at([0.0; 3])).await;
    let i2 = add(&mut c, &scene, &b2, at([5.0, 0.0, 0.0])).await;
    let q = [0.5, 0.5, 0.5, 0.5];
    set_pose(&mut c, &scene, &i2, pose(q, [0.0, 3.0, 0.0])).await;
    server.stop().await;

    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    let mut names: Vec<_> = bodies.iter().map(|b| b.name.as_str()).collect();
    names.sort();
    assert_eq!(names, ["big", "small"]);
    let err = c.get_body(pb::GetBodyRequest { body_id: doomed }).await.unwrap_err();
    assert_eq!(err.code(), Code::NotFound);
    let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes;
    assert_eq!(scenes.len(), 1);
    assert_eq!((scenes[0].scene_id.as_str(), scenes[0].num_instances), (scene.as_str(), 2));
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    let inst = view.instances.iter().find(|i| i.instance_id == i2).unwrap();
    assert_eq!(inst.body_id, b2);
    let p = inst.pose.as_ref().unwrap();
    let r = p.rotation.as_ref().unwrap();
    assert_eq!([r.w, r.x, r.y, r.z], q);
    assert_eq!(v(&p.translation), Vector3::new(0.0, 3.0, 0.0));
    // Queries work on the reloaded scene: ‖(0,3,0)‖ − 1 − 0.25.
    let d = distance(&mut c, &scene, &i1, &i2).await;
    assert!((d.distance - 1.75).abs() < 1e-8, "{}", d.distance);
    assert!(!d.solve.unwrap().warm_started, "warm starts are not persisted");
    server.stop().await;
}

pub(crate) fn assert_status(r: Result<impl std::fmt::Debug, tonic::Status>, code: Code, needle: &str) {
    let e = r.expect_err("request should fail");
    assert_eq!(e.code(), code, "{e:?}");
    assert!(e.message().contains(needle), "`{}` should mention `{needle}`", e.message());
}

#[tokio::test]
async fn bad_input_gets_the_right_code_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let cfg =
        ServerConfig { max_fit_points: 1000, max_batch_pairs: 4, max_message_bytes: 1 << 20, ..config(dir.path()) };
    let server = Server::start(cfg).await;
    let mut c = server.client().await;
    let b = upload_sphere(&mut c, "s", [0.0; 3], 0.5).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let i1 = add(&mut c, &scene, &b, at([0.0; 3])).await;
    let i2 = add(&mut c, &scene, &b, at([2.0, 0.0, 0.0])).await;

    // Poses.
    let req = pb::AddInstanceRequest {
        scene_id: scene.clone(),
        body_id: b.clone(),
        pose: Some(pose([1.0, 1.0, 0.0, 0.0], [0.0; 3])),
    };
    assert_status(c.add_instance(req).await, Code::InvalidArgument, "pose.rotation");
    let poses = vec![
        pb::InstancePose { instance_id: i2.clone(), pose: Some(at([9.0, 0.0, 0.0])) },
        pb::InstancePose { instance_id: i1.clone(), pose: Some(at([0.0; 3])) },
        pb::InstancePose { instance_id: i1.clone(), pose: Some(at([0.0; 3])) },
        pb::InstancePose { instance_id: i1.clone(), pose: Some(pose([f64::NAN, 0.0, 0.0, 0.0], [0.0; 3])) },
    ];
    let req = pb::SetPosesRequest { scene_id: scene.clone(), poses: poses.clone() };
    assert_status(c.set_poses(req).await, Code::InvalidArgument, "poses[3].pose.rotation");
    let req = pb::SetPosesRequest { scene_id: scene.clone(), poses: poses[..3].to_vec() };
    assert_status(c.set_poses(req).await, Code::InvalidArgument, "poses[2].instance_id");
    let mut bad_t = poses[..1].to_vec();
    bad_t[0].pose = Some(at([f64::INFINITY, 0.0, 0.0]));
    let req = pb::SetPosesRequest { scene_id: scene.clone(), poses: bad_t };
    assert_status(c.set_poses(req).await, Code::InvalidArgument, "poses[0].pose.translation");
    let unknown = vec![pb::InstancePose { instance_id: "i-nope".into(), pose: None }];
    let req = pb::SetPosesRequest { scene_id: scene.clone(), poses: unknown };
    assert_status(c.set_poses(req).await, Code::InvalidArgument, "poses[0].instance_id");
    // None of the failed batches moved i2: the distance is still 2 − 0.5 − 0.5.
    assert!((distance(&mut c, &scene, &i1, &i2).await.distance - 1.0).abs() < 1e-9);

    // Unknown ids.
    let req = pb::AddInstanceRequest { scene_id: scene.clone(), body_id: "b-nope".into(), pose: None };
    assert_status(c.add_instance(req).await, Code::NotFound, "b-nope");
    let req = pb::GetSceneRequest { scene_id: "s-nope".into() };
    assert_status(c.get_scene(req).await, Code::NotFound, "s-nope");
    let req = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: i1.clone(),
        instance_b: "i-nope".into(),
        ..Default::default()
    };
    assert_status(c.distance(req).await, Code::NotFound, "i-nope");
    let req = pb::GrowthRequest {
        scene_id: scene.clone(),
        instance_1: String::new(),
        instance_2: i1.clone(),
        ..Default::default()
    };
    assert_status(c.growth(req).await, Code::InvalidArgument, "instance_1");
    assert_status(c.watch_fit_job(pb::WatchFitJobRequest { job_id: "j-nope".into() }).await, Code::NotFound, "j-nope");
    assert_status(
        c.delete_body(pb::DeleteBodyRequest { body_id: b.clone() }).await,
        Code::FailedPrecondition,
        "remove the instance first",
    );

    // Batches.
    let pair = |kind: i32| pb::QueryPair { kind, first: i1.clone(), second: i2.clone(), ..Default::default() };
    let req = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: vec![pair(1), pair(0)], columns: None };
    assert_status(c.batch_query(req).await, Code::InvalidArgument, "pairs[1].kind");
    let req = pb::BatchQueryRequest { scene_id: scene.clone(), pairs: vec![pair(1); 5], columns: None };
    assert_status(c.batch_query(req).await, Code::ResourceExhausted, "pairs");

    // Uploads.
    let up = |body| pb::UploadBodyRequest { name: "x".into(), body: Some(body) };
    let r = c.upload_body(up(pb::upload_body_request::Body::BodyJson("{not json".into()))).await;
    assert_status(r, Code::InvalidArgument, "body_json");
    let mut data = sublevel::service::convert::body_file_to_proto(&ellipsoid([0.0; 3], [1.0; 3]).unwrap().to_file());
    data.coefficients.iter_mut().for_each(|x| *x = -*x);
    let r = c.upload_body(up(pb::upload_body_request::Body::Data(data.clone()))).await;
    assert_status(r, Code::InvalidArgument, "data.coefficients");
    data.degree = 3;
    let r = c.upload_body(up(pb::upload_body_request::Body::Data(data.clone()))).await;
    assert_status(r, Code::InvalidArgument, "data.degree");
    data.exponents.pop();
    let r = c.upload_body(up(pb::upload_body_request::Body::Data(data))).await;
    assert_status(r, Code::InvalidArgument, "data.exponents");

    // Fits: validated before a job exists.
    let fit = |degree: u32, xyz: Vec<f64>| pb::StartFitJobRequest {
        name: "f".into(),
        degree,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud { xyz })),
        ..Default::default()
    };
    let cube: Vec<f64> = (0..8).flat_map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]).collect();
    assert_status(c.start_fit_job(fit(3, cube.clone())).await, Code::InvalidArgument, "degree");
    assert_status(c.start_fit_job(fit(4, vec![])).await, Code::InvalidArgument, "points");
    assert_status(c.start_fit_job(fit(4, cube[..7].to_vec())).await, Code::InvalidArgument, "points.xyz");
    let flat: Vec<f64> = cube.chunks(3).flat_map(|p| [p[0], p[1], 0.0]).collect();
    assert_status(c.start_fit_job(fit(4, flat)).await, Code::InvalidArgument, "degenerate");
    let mut nan = cube.clone();
    nan[4] = f64::NAN;
    assert_status(c.start_fit_job(fit(4, nan)).await, Code::InvalidArgument, "points.xyz");
    let many: Vec<f64> = (0..3003).map(|i| (i as f64 * 0.37).sin()).collect();
    assert_status(c.start_fit_job(fit(4, many)).await, Code::ResourceExhausted, "1000");
    let mesh = |data: &[u8], format: &str| pb::StartFitJobRequest {
        name: "m".into(),
        degree: 4,
        source: Some(pb::start_fit_job_request::Source::Mesh(pb::Mesh { data: data.to_vec(), format: format.into() })),
        ..Default::default()
    };
    assert_status(c.start_fit_job(mesh(b"OFF\nthis is not a mesh", "off")).await, Code::InvalidArgument, "mesh");
    assert_status(c.start_fit_job(mesh(b"", "off")).await, Code::InvalidArgument, "mesh.data");
    let r = c
        .start_fit_job(pb::StartFitJobRequest { name: "n".into(), degree: 4, source: None, ..Default::default() })
        .await;
    assert_status(r, Code::InvalidArgument, "source");

    // Oversized message: refused by the transport before any handler (tonic says OUT_OF_RANGE).
    let huge: Vec<f64> = vec![0.5; 200_000];
    let e = c.start_fit_job(fit(4, huge)).await.unwrap_err();
    assert!(matches!(e.code(), Code::OutOfRange | Code::ResourceExhausted), "{e:?}");

    // The server still works.
    let g = growth(&mut c, &scene, &i1, &i2).await;
    assert!((g.value - (1.5f64 / 0.5).powi(2)).abs() < 1e-8, "{}", g.value);
    server.stop().await;
}

#[tokio::test]
async fn health_is_serving_and_reflection_lists_the_service() {
    use tonic_health::pb::{health_check_response::ServingStatus, health_client::HealthClient, HealthCheckRequest};
    use tonic_reflection::pb::v1::{
        server_reflection_client::ServerReflectionClient, server_reflection_request::MessageRequest,
        server_reflection_response::MessageResponse, ServerReflectionRequest,
    };
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut health = HealthClient::new(server.channel().await);
    for service in ["", "sublevel.v1.Sublevel"] {
        let r = health.check(HealthCheckRequest { service: service.into() }).await.unwrap().into_inner();
        assert_eq!(r.status, ServingStatus::Serving as i32, "service `{service}`");
    }
    let e = health.check(HealthCheckRequest { service: "nope.v1.Nope".into() }).await.unwrap_err();
    assert_eq!(e.code(), Code::NotFound);

    let mut refl = ServerReflectionClient::new(server.channel().await);
    let req = ServerReflectionRequest {
        host: String::new(),
        message_request: Some(MessageRequest::ListServices(String::new())),
    };
    let mut stream = refl.server_reflection_info(tokio_stream::iter(vec![req])).await.unwrap().into_inner();
    let resp = stream.message().await.unwrap().unwrap();
    let Some(MessageResponse::ListServicesResponse(list)) = resp.message_response else { panic!("{resp:?}") };
    let names: Vec<_> = list.service.iter().map(|s| s.name.as_str()).collect();
    assert!(names.contains(&"sublevel.v1.Sublevel"), "{names:?}");
    assert!(names.contains(&"grpc.health.v1.Health"), "{names:?}");
    server.stop().await;
}

/// Points on a sphere of radius r around c (Fibonacci lattice).
pub(crate) fn sphere_points(c: [f64; 3], r: f64, n: usize) -> Vec<f64> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .flat_map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - z * z).sqrt();
            let th = golden * i as f64;
            [c[0] + r * rho * th.cos(), c[1] + r * rho * th.sin(), c[2] + r * z]
        })
        .collect()
}

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

/// `sublevel serve --demo` seeds the demo bodies and scene once, across restarts.
///
/// Multi-threaded: the test blocks a thread on the child process while the client's connection
/// task must stay alive to answer the server's graceful-shutdown GOAWAY.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn demo_seeding_is_idempotent_across_restarts() {
    use std::io::BufRead;
    let dir = tempfile::tempdir().unwrap();
    let mut seen = Vec::new();
    for _ in 0..2 {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sublevel"))
            .args(["serve", "--addr", "127.0.0.1:0", "--demo", "--data-dir"])
            .arg(dir.path())
            .env("RUST_LOG", "warn")
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
        let mut out = Vec::new();
        let addr = loop {
            let line = lines.next().expect("server exited early").unwrap();
            if let Some(a) = line.strip_prefix("listening on ") {
                break a.to_owned();
            }
            out.push(line);
        };
        let channel = Channel::from_shared(format!("http://{addr}")).unwrap().connect().await.unwrap();
        let mut c = SublevelClient::new(channel);
        let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
        let mut names: Vec<_> = bodies.iter().map(|b| b.name.clone()).collect();
        names.sort();
        assert_eq!(names, ["chair_101", "human_10"]);
        let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes;
        assert_eq!(scenes.len(), 1);
        assert_eq!((scenes[0].name.as_str(), scenes[0].num_instances), ("demo", 2));
        // The demo pair starts apart.
        let view =
            c.get_scene(pb::GetSceneRequest { scene_id: scenes[0].scene_id.clone() }).await.unwrap().into_inner();
        let d = distance(&mut c, &view.scene_id, &view.instances[0].instance_id, &view.instances[1].instance_id).await;
        assert!(d.distance > 0.0 && !d.overlapping, "{d:?}");
        seen.push(out);
        drop(c);
        // Graceful stop by SIGTERM to the child we started.
        let status = std::process::Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
        assert!(status.success());
        let exit = child.wait().unwrap();
        assert!(exit.success(), "the server must exit 0 on SIGTERM: {exit:?}");
    }
    assert_eq!(seen[0], seen[1], "a restart must report the same ids");
    assert!(seen[0].iter().any(|l| l.contains("chair_101")));
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
            source: Some(pb::start_fit_job_request::Source::Mesh(pb::Mesh { data, format: "off".into() })),
            ..Default::default()
        };
        let job_id = c.start_fit_job(req).await.unwrap().into_inner().job_id;
        let mut stream = c.watch_fit_job(pb::WatchFitJobRequest { job_id }).await.unwrap().into_inner();
        let mut last = None;
        while let Some(u) = stream.message().await.unwrap() {
            last = Some(u);
        }
        let last = last.unwrap();
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

/// Uploads a body given as a `Body` (its JSON file form) and returns its id.
pub(crate) async fn upload_body(c: &mut SublevelClient<Channel>, name: &str, body: &sublevel::Body) -> String {
    let json = serde_json::to_string(&body.to_file()).unwrap();
    let req = pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
    c.upload_body(req).await.unwrap().into_inner().body_id
}

pub(crate) fn demo_bodies() -> (sublevel::Body, sublevel::Body) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/demo");
    (
        sublevel::Body::load(&dir.join("chair_101.json")).unwrap(),
        sublevel::Body::load(&dir.join("human_10.json")).unwrap(),
    )
}

fn twist(g: &Option<pb::PoseGradient>) -> [f64; 6] {
    let g = g.as_ref().unwrap();
    let (l, a) = (v(&g.linear), v(&g.angular));
    [l.x, l.y, l.z, a.x, a.y, a.z]
}

/// The demo scene (chair at the origin, human beside it, then moved closer and turned): `certify`
/// attaches a certificate that agrees with a direct `certify_distance` / `certify_growth` (1e-6
/// relative on the squared distance and on d), `with_gradient` returns gradients that match
/// central finite differences of direct Newton solves (1e-5 relative), in single and batch queries.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn certified_queries_and_gradients_on_the_demo_scene() {
    use sublevel::query::gradient::perturb_pose;
    use sublevel::query::sdp_certificate::{certify_distance, certify_growth};
    use sublevel::query::{distance as newton_distance, growth as newton_growth, NewtonParams};
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (chair, human) = demo_bodies();
    let (b_chair, b_human) =
        (upload_body(&mut c, "chair_101", &chair).await, upload_body(&mut c, "human_10", &human).await);
    let scene = c.create_scene(pb::CreateSceneRequest { name: "demo".into() }).await.unwrap().into_inner().scene_id;
    let gap = 1.5 * (chair.scale() + human.scale());
    let i_chair = add(&mut c, &scene, &b_chair, at([0.0; 3])).await;
    let pose_chair = Isometry3::identity();
    let i_human = add(&mut c, &scene, &b_human, at([gap, 0.0, 0.0])).await;
    let h = (0.3f64 / 2.0).sin_cos();
    for pose_human in [
        pose_from_parts("h", [1.0, 0.0, 0.0, 0.0], [gap, 0.0, 0.0]).unwrap(),
        pose_from_parts("h", [h.1, 0.0, 0.0, h.0], [0.55 * gap, 0.1, 0.0]).unwrap(),
    ] {
        set_pose(&mut c, &scene, &i_human, sublevel::service::convert::pose_to_proto(&pose_human)).await;
        let req = pb::DistanceRequest {
            scene_id: scene.clone(),
            instance_a: i_chair.clone(),
            instance_b: i_human.clone(),
            certify: true,
            with_gradient: true,
            signed: false,
        };
        let d = c.distance(req).await.unwrap().into_inner().answer.unwrap();
        assert_eq!(d.source, pb::AnswerSource::Newton as i32, "{d:?}");
        assert!(d.solve.as_ref().unwrap().converged && !d.lower_bound);
        let cert = d.certificate.unwrap();
        let direct = certify_distance(&chair, &pose_chair, &human, &pose_human).unwrap();
        assert!(
            (cert.bound - direct.squared_distance).abs() <= 1e-6 * direct.squared_distance.abs().max(1e-3),
            "{cert:?} vs {direct:?}"
        );
        assert!(cert.agrees && cert.verified, "{cert:?}");
        let sq = d.distance * d.distance;
        assert!((sq - direct.squared_distance.max(0.0)).abs() <= 1e-6 * sq.max(1e-3));
        assert!(cert.solve_seconds > 0.0);

        let greq = pb::GrowthRequest {
            scene_id: scene.clone(),
            instance_1: i_chair.clone(),
            instance_2: i_human.clone(),
            certify: true,
            with_gradient: true,
        };
        let g = c.growth(greq).await.unwrap().into_inner().answer.unwrap();
        let gc = g.certificate.unwrap();
        let direct_g = certify_growth(&chair, &pose_chair, &human, &pose_human).unwrap();
        assert!((gc.bound - direct_g.value).abs() <= 1e-6 * direct_g.value.abs().max(1.0), "{gc:?} vs {direct_g:?}");
        assert!(gc.agrees && g.source == pb::AnswerSource::Newton as i32, "{g:?}");

        // Gradients against central finite differences (h = 1e-5) of direct solves.
        let params = NewtonParams::default();
        let fd = |f: &dyn Fn(&Isometry3, &Isometry3) -> f64, which: usize| -> [f64; 6] {
            let mut out = [0.0; 6];
            for (k, o) in out.iter_mut().enumerate() {
                let eval = |s: f64| {
                    let mut xi = [0.0; 6];
                    xi[k] = s * 1e-5;
                    let (lin, ang) = (Vector3::new(xi[0], xi[1], xi[2]), Vector3::new(xi[3], xi[4], xi[5]));
                    if which == 0 {
                        f(&perturb_pose(&pose_chair, &lin, &ang), &pose_human)
                    } else {
                        f(&pose_chair, &perturb_pose(&pose_human, &lin, &ang))
                    }
                };
                *o = (eval(1.0) - eval(-1.0)) / 2e-5;
            }
            out
        };
        let close = |what: &str, a: [f64; 6], b: [f64; 6]| {
            let scale = a.iter().chain(b.iter()).fold(1.0f64, |m, x| m.max(x.abs()));
            for k in 0..6 {
                assert!((a[k] - b[k]).abs() <= 1e-5 * scale, "{what}: {a:?} vs finite differences {b:?}");
            }
        };
        let fd_d = |x: &Isometry3, y: &Isometry3| newton_distance(&chair, x, &human, y, None, &params).distance;
        let fd_g = |x: &Isometry3, y: &Isometry3| newton_growth(&chair, x, &human, y, None, &params).value;
        close("distance / chair", twist(&d.gradient_a), fd(&fd_d, 0));
        close("distance / human", twist(&d.gradient_b), fd(&fd_d, 1));
        close("growth / chair", twist(&g.gradient_1), fd(&fd_g, 0));
        close("growth / human", twist(&g.gradient_2), fd(&fd_g, 1));

        // The same through BatchQuery.
        let pair = |kind: pb::QueryKind| pb::QueryPair {
            kind: kind as i32,
            first: i_chair.clone(),
            second: i_human.clone(),
            certify: true,
            with_gradient: true,
            signed: false,
        };
        let req = pb::BatchQueryRequest {
            scene_id: scene.clone(),
            pairs: vec![pair(pb::QueryKind::Distance), pair(pb::QueryKind::Growth)],
            columns: None,
        };
        let answers = c.batch_query(req).await.unwrap().into_inner().answers;
        let Some(pb::query_answer::Answer::Distance(bd)) = &answers[0].answer else { panic!("{answers:?}") };
        assert!((bd.distance - d.distance).abs() < 1e-9 && bd.certificate.as_ref().unwrap().agrees);
        close("batch distance / chair", twist(&bd.gradient_a), twist(&d.gradient_a));
        let Some(pb::query_answer::Answer::Growth(bg)) = &answers[1].answer else { panic!("{answers:?}") };
        assert!(bg.certificate.as_ref().unwrap().agrees && bg.gradient_1.is_some());
    }
    // Without the flags: no certificate, no gradients, source NEWTON.
    let d = distance(&mut c, &scene, &i_chair, &i_human).await;
    assert!(d.certificate.is_none() && d.gradient_a.is_none() && d.source == pb::AnswerSource::Newton as i32);
    server.stop().await;
}

/// A nonconvex body (flagged `report.nonconvex`: the "jack" p = ‖u‖² + 30 Σ uᵢ²uⱼ²) uploaded as
/// JSON answers with the SDP lower bound: source SDP_LOWER_BOUND, lower_bound, no gradients, and a
/// distance no larger than the brute-force distance over exact boundary samples.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nonconvex_body_answers_with_an_sdp_lower_bound() {
    use sublevel::body::FitReport;
    use sublevel::poly::Polynomial;
    let k = 30.0;
    let terms = [([2, 0, 0], 1.0), ([0, 2, 0], 1.0), ([0, 0, 2], 1.0), ([2, 2, 0], k), ([0, 2, 2], k), ([2, 0, 2], k)];
    let report = FitReport { method: "uploaded".into(), nonconvex: true, ..FitReport::default() };
    let jack = sublevel::Body::new(Polynomial::from_terms(4, &terms).unwrap(), [0.0; 3], 0.5, report).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let b_jack = upload_body(&mut c, "jack", &jack).await;
    let b_ball = upload_sphere(&mut c, "ball", [0.0; 3], 0.3).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "nc".into() }).await.unwrap().into_inner().scene_id;
    let i_jack = add(&mut c, &scene, &b_jack, at([0.0; 3])).await;
    let ball_center = Vector3::new(0.9, 0.7, 0.1);
    let i_ball = add(&mut c, &scene, &b_ball, at([ball_center.x, ball_center.y, ball_center.z])).await;
    let req = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: i_jack.clone(),
        instance_b: i_ball.clone(),
        certify: false,
        with_gradient: true,
        signed: false,
    };
    let d = c.distance(req).await.unwrap().into_inner().answer.unwrap();
    assert_eq!(d.source, pb::AnswerSource::SdpLowerBound as i32, "{d:?}");
    assert!(d.lower_bound && d.certificate.is_some() && d.gradient_a.is_none(), "{d:?}");
    // Brute force: the jack's boundary along 20 000 directions (closed-form radius), minus r.
    let golden = std::f64::consts::PI * (3.0 - 5.0f64.sqrt());
    let n = 20_000;
    let mut brute = f64::INFINITY;
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let u = Vector3::new(r * (golden * i as f64).cos(), r * (golden * i as f64).sin(), z);
        let q = k * (u.x * u.x * u.y * u.y + u.y * u.y * u.z * u.z + u.x * u.x * u.z * u.z);
        let rho = if q < 1e-15 { 1.0 } else { ((-1.0 + (1.0 + 4.0 * q).sqrt()) / (2.0 * q)).sqrt() };
        brute = brute.min((u * rho * 0.5 - ball_center).norm() - 0.3);
    }
    assert!(brute > 0.1, "{brute}");
    assert!(d.distance >= 0.0 && d.distance <= brute + 1e-9, "lower bound {} vs brute force {brute}", d.distance);
    let g = growth(&mut c, &scene, &i_ball, &i_jack).await;
    assert_eq!(g.source, pb::AnswerSource::SdpLowerBound as i32);
    assert!(g.lower_bound);
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
