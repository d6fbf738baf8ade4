//! Integration tests: one request never takes the service down. Each numbered repro of
//! the issue is a test here; plus the store's quarantine, status codes of malformed requests, a
//! kill -9 test on a child server process (loopback, bounded); the SIGTERM-during-fit test is in
//! `jobs_api.rs`.

use crate::util::{
    add, assert_status, at, config, demo_bodies, sphere_points, upload_body, upload_sphere, ChildServer, Server,
};
use std::time::{Duration, Instant};
use sublevel::service::pb;
use tonic::transport::Channel;
use tonic::Code;

fn upload_data(name: &str, data: pb::BodyData) -> pb::UploadBodyRequest {
    pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::Data(data)) }
}

fn points_job(name: &str, degree: u32, xyz: Vec<f64>) -> pb::StartFitJobRequest {
    pb::StartFitJobRequest {
        name: name.into(),
        degree,
        source: Some(pb::start_fit_job_request::Source::Points(pb::PointCloud { xyz })),
        ..Default::default()
    }
}

fn cube(side: f64) -> Vec<f64> {
    (0..8).flat_map(|i| [(i & 1) as f64 * side, ((i >> 1) & 1) as f64 * side, ((i >> 2) & 1) as f64 * side]).collect()
}

/// Repro 1: a NaN or infinity in an uploaded report is refused naming the field (it used to be
/// stored as JSON `null` and brick the store at the next start); a fit of a cube of side 1e110 is
/// refused before a job exists (its volume overflowed to inf and the job SUCCEEDED); GetBody's
/// JSON is accepted back by UploadBody; the store reopens with everything accepted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn repro_1_non_finite_reports_are_refused_and_the_store_reopens() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (chair, _) = demo_bodies();
    let good = sublevel::service::convert::body_file_to_proto(&chair.to_file());
    for (field, value) in [("volume", f64::NAN), ("volume", f64::INFINITY), ("total_seconds", f64::NEG_INFINITY)] {
        let mut data = good.clone();
        let report = data.report.as_mut().unwrap();
        match field {
            "volume" => report.volume = value,
            _ => report.total_seconds = value,
        }
        assert_status(
            c.upload_body(upload_data("chair", data)).await,
            Code::InvalidArgument,
            &format!("data.report.{field}"),
        );
    }
    let mut data = good.clone();
    data.report.as_mut().unwrap().solver_certificate =
        Some(pb::SolverCertificate { primal_objective: 1.0, dual_objective: f64::NAN, ..Default::default() });
    assert_status(
        c.upload_body(upload_data("chair", data)).await,
        Code::InvalidArgument,
        "data.report.solver_certificate.dual_objective",
    );
    let id = c.upload_body(upload_data("chair", good)).await.unwrap().into_inner().body_id;
    // GetBody's JSON goes back in unchanged.
    let json = c.get_body(pb::GetBodyRequest { body_id: id.clone() }).await.unwrap().into_inner().body_json;
    let req = pb::UploadBodyRequest { name: "again".into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
    let again = c.upload_body(req).await.unwrap().into_inner();
    assert!(!again.nonconvex && again.convexity_margin.is_finite(), "certified within its tolerance: {again:?}");
    for side in [1e110, 1e200] {
        assert_status(c.start_fit_job(points_job("huge", 2, cube(side))).await, Code::InvalidArgument, "range");
    }
    server.stop().await;

    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    assert_eq!(bodies.len(), 2, "{bodies:?}");
    server.stop().await;
}

/// Repro 2: a 64-byte PLY whose header promises 10¹⁵ vertices is refused at once (it used to grow
/// memory until the process aborted), ASCII and binary; the server keeps answering.
#[tokio::test]
async fn repro_2_a_lying_ply_header_is_refused_before_allocation() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    for format in ["ascii", "binary_little_endian"] {
        let data = format!("ply\nformat {format} 1.0\nelement vertex 1000000000000000\nend_header\n").into_bytes();
        let req = pb::StartFitJobRequest {
            name: "ply".into(),
            degree: 2,
            source: Some(pb::start_fit_job_request::Source::Mesh(pb::Mesh {
                mesh_format: pb::MeshFormat::Ply as i32,
                data,
                ..Default::default()
            })),
            ..Default::default()
        };
        let t = Instant::now();
        let e = c.start_fit_job(req).await.expect_err("a lying header must be refused");
        assert!(matches!(e.code(), Code::InvalidArgument | Code::ResourceExhausted), "{e:?}");
        assert!(e.message().contains("mesh"), "{e:?}");
        assert!(t.elapsed() < Duration::from_secs(5), "took {:?}", t.elapsed());
    }
    // Still serving.
    upload_sphere(&mut c, "alive", [0.0; 3], 0.5).await;
    server.stop().await;
}

/// Repro 3: p = ‖u‖² − u⁴ (nonconvex and unbounded) is refused; a bounded body that is not
/// sos-convex but claims to be (a "jack") is stored as nonconvex, so its answers are SDP lower
/// bounds and never CONVERGED Newton optima; a sphere's certificate margin is the closed form 2.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn repro_3_uploaded_bodies_are_certified_or_stored_as_nonconvex() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let bad = pb::BodyData {
        degree: 4,
        exponents: vec![2, 0, 0, 0, 2, 0, 0, 0, 2, 4, 0, 0],
        coefficients: vec![1.0, 1.0, 1.0, -1.0],
        center: None,
        scale: 1.0,
        report: None,
    };
    assert_status(c.upload_body(upload_data("bad", bad)).await, Code::InvalidArgument, "unbounded");

    let k = 30.0;
    let jack = pb::BodyData {
        degree: 4,
        exponents: vec![2, 0, 0, 0, 2, 0, 0, 0, 2, 2, 2, 0, 0, 2, 2, 2, 0, 2],
        coefficients: vec![1.0, 1.0, 1.0, k, k, k],
        center: None,
        scale: 0.5,
        report: None,
    };
    let r = c.upload_body(upload_data("jack", jack)).await.unwrap().into_inner();
    assert!(r.nonconvex && r.convexity_margin < 0.0, "{r:?}");
    let ball = pb::UploadBodyRequest {
        name: "ball".into(),
        body: Some(pb::upload_body_request::Body::BodyJson(
            serde_json::to_string(&sublevel::body::ellipsoid([0.0; 3], [0.3; 3]).unwrap().to_file()).unwrap(),
        )),
    };
    let b = c.upload_body(ball).await.unwrap().into_inner();
    assert!(!b.nonconvex && (b.convexity_margin - 2.0).abs() < 1e-5, "‖u‖² has margin 2: {b:?}");
    let scene = c.create_scene(pb::CreateSceneRequest { name: "nc".into() }).await.unwrap().into_inner().scene_id;
    let i_jack = add(&mut c, &scene, &r.body_id, at([0.0; 3])).await;
    let i_ball = add(&mut c, &scene, &b.body_id, at([0.9, 0.7, 0.1])).await;
    for certify in [false, true] {
        let req = pb::DistanceRequest {
            scene_id: scene.clone(),
            instance_a: i_jack.clone(),
            instance_b: i_ball.clone(),
            certify,
            with_gradient: false,
            signed: false,
            tolerance: 0.0,
        };
        let d = c.distance(req).await.unwrap().into_inner().answer.unwrap();
        assert_eq!(d.source, pb::AnswerSource::SdpLowerBound as i32, "{d:?}");
        assert!(d.lower_bound, "{d:?}");
    }
    server.stop().await;
}

/// Repro 4: translations beyond ±1e6 m are refused (chair at 1e154 and human at 1e154 + 3 used to
/// answer distance 0, CONVERGED); an answer whose inputs limit its precision says so.
#[tokio::test]
async fn repro_4_absurd_coordinates_are_refused_and_precision_is_flagged() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let big = upload_sphere(&mut c, "big", [0.0; 3], 0.5).await;
    let tiny = upload_sphere(&mut c, "tiny", [0.0; 3], 1e-3).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "far".into() }).await.unwrap().into_inner().scene_id;
    for x in [1e308, 1e154, 1.5e6] {
        let req =
            pb::AddInstanceRequest { scene_id: scene.clone(), body_id: big.clone(), pose: Some(at([x, 0.0, 0.0])) };
        assert_status(c.add_instance(req).await, Code::InvalidArgument, "pose.translation");
    }
    let a = add(&mut c, &scene, &tiny, at([5e5, 0.0, 0.0])).await;
    let b = add(&mut c, &scene, &tiny, at([5e5 + 0.01, 0.0, 0.0])).await;
    let poses = vec![pb::InstancePose { instance_id: b.clone(), pose: Some(at([0.0, 1e7, 0.0])) }];
    assert_status(
        c.set_poses(pb::SetPosesRequest { scene_id: scene.clone(), poses }).await,
        Code::InvalidArgument,
        "poses[0].pose.translation",
    );
    let d = crate::util::distance(&mut c, &scene, &a, &b).await;
    // Two 1 mm spheres 1 cm apart: 8 mm, to the precision the inputs allow (ulp(5e5) ≈ 1.2e-10 m).
    assert!((d.distance - 0.008).abs() < 1e-6, "{d:?}");
    assert!(d.solve.as_ref().unwrap().precision_limited, "{d:?}");
    let scene2 = c.create_scene(pb::CreateSceneRequest { name: "near".into() }).await.unwrap().into_inner().scene_id;
    let a = add(&mut c, &scene2, &tiny, at([0.0; 3])).await;
    let b = add(&mut c, &scene2, &tiny, at([0.01, 0.0, 0.0])).await;
    let d = crate::util::distance(&mut c, &scene2, &a, &b).await;
    assert!(!d.solve.as_ref().unwrap().precision_limited && (d.distance - 0.008).abs() < 1e-9, "{d:?}");
    server.stop().await;
}

/// A codec that sends and receives raw bytes, to send what no generated client would.
#[derive(Clone, Copy, Default)]
struct RawCodec;
struct RawEncoder;
struct RawDecoder;

impl tonic::codec::Encoder for RawEncoder {
    type Item = Vec<u8>;
    type Error = tonic::Status;
    fn encode(&mut self, item: Vec<u8>, dst: &mut tonic::codec::EncodeBuf<'_>) -> Result<(), tonic::Status> {
        prost::bytes::BufMut::put_slice(dst, &item);
        Ok(())
    }
}

impl tonic::codec::Decoder for RawDecoder {
    type Item = Vec<u8>;
    type Error = tonic::Status;
    fn decode(&mut self, src: &mut tonic::codec::DecodeBuf<'_>) -> Result<Option<Vec<u8>>, tonic::Status> {
        let n = prost::bytes::Buf::remaining(src);
        let mut v = vec![0; n];
        prost::bytes::Buf::copy_to_slice(src, &mut v);
        Ok(Some(v))
    }
}

impl tonic::codec::Codec for RawCodec {
    type Encode = Vec<u8>;
    type Decode = Vec<u8>;
    type Encoder = RawEncoder;
    type Decoder = RawDecoder;
    fn encoder(&mut self) -> RawEncoder {
        RawEncoder
    }
    fn decoder(&mut self) -> RawDecoder {
        RawDecoder
    }
}

async fn raw_call(channel: Channel, path: &'static str, bytes: Vec<u8>) -> Result<Vec<u8>, tonic::Status> {
    let mut grpc = tonic::client::Grpc::new(channel);
    grpc.ready().await.unwrap();
    let path = tonic::codegen::http::uri::PathAndQuery::from_static(path);
    grpc.unary(tonic::Request::new(bytes), path, RawCodec).await.map(tonic::Response::into_inner)
}

/// Repro 5: undecodable bytes are INVALID_ARGUMENT (not INTERNAL); an unknown method's
/// UNIMPLEMENTED says which; a 16 KB id is refused without being echoed; logdet_h with a
/// relaxation is refused before a job exists; reflection v1alpha lists the service.
#[tokio::test]
async fn repro_5_statuses_and_messages_of_malformed_requests() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let e = raw_call(server.channel().await, "/sublevel.v1.Sublevel/Distance", vec![0xff; 7]).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
    assert!(e.message().contains("Distance") && e.message().contains("decode"), "{e:?}");
    let e = raw_call(server.channel().await, "/sublevel.v1.Sublevel/Teleport", vec![]).await.unwrap_err();
    assert_eq!(e.code(), Code::Unimplemented, "{e:?}");
    assert!(e.message().contains("Teleport") && e.message().contains("sublevel.v1.Sublevel"), "{e:?}");

    let mut c = server.client().await;
    let long = "s".repeat(16 * 1024);
    let e = c.get_scene(pb::GetSceneRequest { scene_id: long }).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);
    assert!(e.message().contains("scene_id") && e.message().len() < 400, "{} bytes", e.message().len());
    let e = c.get_scene(pb::GetSceneRequest { scene_id: "x".repeat(100) }).await.unwrap_err();
    assert_eq!(e.code(), Code::NotFound);
    assert!(e.message().len() < 200 && e.message().contains('…'), "{}", e.message());

    let mut req = points_job("h", 4, sphere_points([0.0; 3], 1.0, 200));
    req.method = "logdet_h".into();
    req.convexity_relaxation = 10.0;
    assert_status(c.start_fit_job(req).await, Code::InvalidArgument, "convexity_relaxation");
    // A needle 2 m long and 2 mm thick, and a sheet 2 m × 2 m × 2 mm, are refused before a job
    // exists at 2d = 4 (the SDP ends NumericalError there), accepted at 2d = 2.
    let wobble = |i: usize, k: usize| ((i * k) % 7) as f64 / 3.0 - 1.0;
    let needle: Vec<f64> =
        (0..200).flat_map(|i| [i as f64 * 0.01 - 1.0, 1e-3 * wobble(i, 3), 1e-3 * wobble(i, 5)]).collect();
    let sheet: Vec<f64> = (0..400).flat_map(|i| [wobble(i, 3), wobble(i / 7, 5), 1e-3 * wobble(i, 11)]).collect();
    for (name, cloud) in [("needle", needle), ("sheet", sheet)] {
        assert_status(c.start_fit_job(points_job(name, 4, cloud.clone())).await, Code::InvalidArgument, "degree-4 fit");
        c.start_fit_job(points_job(name, 2, cloud)).await.unwrap();
    }

    use tonic_reflection::pb::v1alpha::{
        server_reflection_client::ServerReflectionClient, server_reflection_request::MessageRequest,
        server_reflection_response::MessageResponse, ServerReflectionRequest,
    };
    let mut refl = ServerReflectionClient::new(server.channel().await);
    let req = ServerReflectionRequest {
        host: String::new(),
        message_request: Some(MessageRequest::ListServices(String::new())),
    };
    let mut stream = refl.server_reflection_info(tokio_stream::iter(vec![req])).await.unwrap().into_inner();
    let resp = stream.message().await.unwrap().unwrap();
    let Some(MessageResponse::ListServicesResponse(list)) = resp.message_response else { panic!("{resp:?}") };
    assert!(list.service.iter().any(|s| s.name == "sublevel.v1.Sublevel"), "{list:?}");
    server.stop().await;
}

/// The store always opens: a record written directly with garbage, and a body whose JSON has a
/// `null` volume (what a NaN used to become), are moved to the quarantine at the next start; the
/// rest is served, and health reports the store NOT_SERVING while the quarantine is not empty.
#[tokio::test]
async fn unreadable_records_are_quarantined_and_the_store_opens() {
    use tonic_health::pb::{health_check_response::ServingStatus, health_client::HealthClient, HealthCheckRequest};
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let keep = upload_sphere(&mut c, "keep", [0.0; 3], 0.5).await;
    let json = c.get_body(pb::GetBodyRequest { body_id: keep.clone() }).await.unwrap().into_inner().body_json;
    server.stop().await;

    {
        let db = redb::Database::open(dir.path().join(sublevel::scene::store::DATABASE_FILE)).unwrap();
        let txn = db.begin_write().unwrap();
        {
            let mut t = txn.open_table(redb::TableDefinition::<&str, &str>::new("bodies")).unwrap();
            t.insert("b-garbage", "{not json").unwrap();
            let nulled = json.replacen("\"volume\":", "\"volume\":null,\"was\":", 1);
            let record = format!("{{\"name\":\"nulled\",\"body\":{nulled}}}");
            t.insert("b-nulled", record.as_str()).unwrap();
        }
        txn.commit().unwrap();
    }

    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    assert_eq!(bodies.iter().map(|b| b.body_id.as_str()).collect::<Vec<_>>(), [keep.as_str()]);
    let mut health = HealthClient::new(server.channel().await);
    let check = |s: &str| HealthCheckRequest { service: s.into() };
    let store = health.check(check(sublevel::service::STORE_HEALTH_NAME)).await.unwrap().into_inner();
    assert_eq!(store.status, ServingStatus::NotServing as i32);
    let all = health.check(check("")).await.unwrap().into_inner();
    assert_eq!(all.status, ServingStatus::Serving as i32);
    server.stop().await;
    // Kept aside, not deleted.
    let store = sublevel::scene::store::RedbStore::open_dir(dir.path()).unwrap();
    let q = sublevel::scene::store::Store::quarantined(&store).unwrap();
    let keys: Vec<_> = q.iter().map(|r| r.key.as_str()).collect();
    assert_eq!(keys, ["b-garbage", "b-nulled"]);
    assert!(q[0].text == "{not json" && q[1].reason.contains("null"), "{q:?}");
}

/// kill -9 at random points during acknowledged writes (bodies, scenes, instances, pose
/// updates), three rounds, each followed by a restart: every acknowledged write is there, and
/// every pose is the last acknowledged one or one sent after it (never older, never torn).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_during_acknowledged_writes_loses_nothing() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    // (body id, scene id, instance id, last acknowledged x, largest x sent)
    let mut acked: Vec<(String, String, String, f64, f64)> = Vec::new();
    for round in 0..3 {
        let server = ChildServer::spawn(dir.path());
        let mut c = server.client().await;
        // Everything acknowledged before is there.
        for (body, scene, inst, x_ack, x_sent) in &acked {
            c.get_body(pb::GetBodyRequest { body_id: body.clone() }).await.unwrap();
            let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
            let i = view.instances.iter().find(|i| &i.instance_id == inst).expect("acknowledged instance lost");
            let x = i.pose.as_ref().unwrap().translation.as_ref().unwrap().x;
            assert!(
                x >= *x_ack && x <= *x_sent,
                "round {round}: pose x = {x}, acknowledged {x_ack}, sent up to {x_sent}"
            );
        }
        let kill_after = Duration::from_millis(rng.random_range(150..600));
        let writer = tokio::spawn(async move {
            let mut done: Vec<(String, String, String, f64, f64)> = Vec::new();
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(10) {
                let Ok(b) = c
                    .upload_body(pb::UploadBodyRequest {
                        name: "w".into(),
                        body: Some(pb::upload_body_request::Body::BodyJson(
                            serde_json::to_string(&sublevel::body::ellipsoid([0.0; 3], [0.2; 3]).unwrap().to_file())
                                .unwrap(),
                        )),
                    })
                    .await
                else {
                    break;
                };
                let body = b.into_inner().body_id;
                let Ok(s) = c.create_scene(pb::CreateSceneRequest { name: "w".into() }).await else { break };
                let scene = s.into_inner().scene_id;
                let req =
                    pb::AddInstanceRequest { scene_id: scene.clone(), body_id: body.clone(), pose: Some(at([0.0; 3])) };
                let Ok(i) = c.add_instance(req).await else { break };
                let inst = i.into_inner().instance_id;
                let mut entry = (body, scene.clone(), inst.clone(), 0.0, 0.0);
                for step in 1..=20 {
                    let x = step as f64;
                    entry.4 = x;
                    let poses = vec![pb::InstancePose { instance_id: inst.clone(), pose: Some(at([x, 0.0, 0.0])) }];
                    if c.set_poses(pb::SetPosesRequest { scene_id: scene.clone(), poses }).await.is_err() {
                        done.push(entry);
                        return done;
                    }
                    entry.3 = x;
                }
                done.push(entry);
            }
            done
        });
        tokio::time::sleep(kill_after).await;
        server.signal("-KILL");
        drop(server);
        let done = writer.await.unwrap();
        assert!(!done.is_empty() || round > 0, "no write was acknowledged before the kill");
        acked.extend(done);
    }
    let server = ChildServer::spawn(dir.path());
    let mut c = server.client().await;
    let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    for (body, ..) in &acked {
        assert!(bodies.iter().any(|b| &b.body_id == body), "acknowledged body {body} lost");
    }
}

/// The demo bodies still upload (their certificates pass) — a guard against the sos-convexity
/// check refusing real fits.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fitted_bodies_pass_the_upload_certificate() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let (chair, human) = demo_bodies();
    for (name, body) in [("chair", &chair), ("human", &human)] {
        let id = upload_body(&mut c, name, body).await;
        let got = c.get_body(pb::GetBodyRequest { body_id: id }).await.unwrap().into_inner();
        let report = got.data.unwrap().report.unwrap();
        assert!(!report.nonconvex, "{name}: {:?}", report.notes);
    }
    server.stop().await;
}
