//! Integration tests: service. A real server on 127.0.0.1:0 with a shutdown channel, a real
//! client, a throwaway data directory (the fixture is `crate::util::Server`): bodies, scenes,
//! poses and queries round-trip, survive a restart, and bad input gets the right code naming the
//! field. Fit jobs and the end-to-end runs are in `service_jobs.rs`.

use crate::util::{
    add, assert_status, at, config, demo_bodies, distance, growth, pose, set_pose, upload_body, upload_sphere, v,
    Server,
};
use sublevel::body::ellipsoid;
use sublevel::math::{pose_from_parts, Isometry3, Vector3};
use sublevel::service::pb;
use sublevel::service::ServerConfig;
use tonic::Code;

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
    // A forged token (not an id of this list's form: a scene id, a truncated id) is refused
    // rather than answered with a wrong page.
    for forged in ["s-0123456789abcdef", "b-0123", "b-0123456789ABCDEF", "zzz"] {
        let req = pb::ListBodiesRequest { page_size: 1, page_token: forged.into() };
        assert_status(c.list_bodies(req).await, Code::InvalidArgument, "page_token");
    }

    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    // Instance 1: rotated 90° about z and moved; its sphere center (0.1, 0, 0) lands at (1, 2.1, 0).
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let i1 = add(&mut c, &scene, &b1, pose([h, 0.0, 0.0, h], [1.0, 2.0, 0.0])).await;
    let i2 = add(&mut c, &scene, &b2, at([4.0, 6.1, 0.0])).await;
    let c1 = Vector3::new(1.0, 2.1, 0.0);
    let view = c.get_scene(pb::GetSceneRequest { scene_id: scene.clone() }).await.unwrap().into_inner();
    assert_eq!(view.instances.len(), 2);

    let mut warm_seen = 0;
    // Steps of 0.3 m: within the warm start's reach (half the summed scales, 0.4 m).
    for (k, c2) in [[4.0, 6.1, 0.0], [3.8, 5.9, 0.1], [3.6, 5.7, 0.2], [3.4, 5.5, 0.3]].into_iter().enumerate() {
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
    let c2 = Vector3::new(3.4, 5.5, 0.3);
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
    assert_status(c.set_poses(req).await, Code::NotFound, "poses[0].instance_id");
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
    let compound = sublevel::compound::CompoundBody::single(ellipsoid([0.0; 3], [1.0; 3]).unwrap()).to_file();
    // A compound file is taken; a one-node tree is stored as the single body it is.
    let r = c.upload_body(up(pb::upload_body_request::Body::BodyJson(serde_json::to_string(&compound).unwrap()))).await;
    assert_eq!(r.unwrap().into_inner().nodes, 1);
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
        // The text form (deprecated beside `mesh_format`, still accepted): what older clients send.
        #[allow(deprecated)]
        source: Some(pb::start_fit_job_request::Source::Mesh(pb::Mesh {
            data: data.to_vec(),
            format: format.into(),
            ..Default::default()
        })),
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

/// Invalid arguments carry machine-readable details: a `google.rpc.BadRequest` with the offending
/// field's path and the reason, decoded here with tonic-types (any gRPC client's rich-error
/// support reads the same `grpc-status-details-bin`); the human-readable message is unchanged.
#[tokio::test]
async fn invalid_arguments_carry_bad_request_details_naming_the_field() {
    use tonic_types::StatusExt;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let mut c = server.client().await;
    let b = upload_sphere(&mut c, "s", [0.0; 3], 0.5).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let i1 = add(&mut c, &scene, &b, at([0.0; 3])).await;

    // SetPoses: the second entry's quaternion has norm √2.
    let poses = vec![
        pb::InstancePose { instance_id: i1.clone(), pose: Some(at([1.0, 0.0, 0.0])) },
        pb::InstancePose { instance_id: i1.clone(), pose: Some(pose([1.0, 1.0, 0.0, 0.0], [0.0; 3])) },
    ];
    let e = c.set_poses(pb::SetPosesRequest { scene_id: scene.clone(), poses }).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument);
    let bad = e.get_details_bad_request().expect("BadRequest details");
    assert_eq!(bad.field_violations.len(), 1, "{bad:?}");
    let violation = &bad.field_violations[0];
    assert_eq!(violation.field, "poses[1].pose.rotation");
    assert!(violation.description.contains("unit norm"), "{violation:?}");
    // The message is the error's text as before: field and reason.
    assert_eq!(e.message(), format!("invalid argument `{}`: {}", violation.field, violation.description));

    // AddInstance: the same check on its `pose`.
    let req = pb::AddInstanceRequest {
        scene_id: scene.clone(),
        body_id: b.clone(),
        pose: Some(pose([0.5, 0.5, 0.5, 0.0], [0.0; 3])),
    };
    let e = c.add_instance(req).await.unwrap_err();
    let bad = e.get_details_bad_request().expect("BadRequest details");
    assert_eq!(bad.field_violations[0].field, "pose.rotation", "{bad:?}");
    assert!(bad.field_violations[0].description.contains("unit norm"), "{bad:?}");

    // A NOT_FOUND carries no BadRequest.
    let e = c.get_scene(pb::GetSceneRequest { scene_id: "s-nope".into() }).await.unwrap_err();
    assert_eq!(e.code(), Code::NotFound);
    assert!(e.get_details_bad_request().is_none());
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

    // A message of a domain's file resolves to that file (with its imports), as grpcurl's
    // `describe` asks for it.
    let req = ServerReflectionRequest {
        host: String::new(),
        message_request: Some(MessageRequest::FileContainingSymbol("sublevel.v1.CheckConfigurationsRequest".into())),
    };
    let mut stream = refl.server_reflection_info(tokio_stream::iter(vec![req])).await.unwrap().into_inner();
    let resp = stream.message().await.unwrap().unwrap();
    let Some(MessageResponse::FileDescriptorResponse(files)) = resp.message_response else { panic!("{resp:?}") };
    let has =
        |name: &str| files.file_descriptor_proto.iter().any(|f| f.windows(name.len()).any(|w| w == name.as_bytes()));
    assert!(
        has("sublevel/v1/robots.proto") && has("sublevel/v1/geometry.proto"),
        "{} files",
        files.file_descriptor_proto.len()
    );
    server.stop().await;
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
            tolerance: 0.0,
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
            tolerance: 0.0,
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
        tolerance: 0.0,
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
