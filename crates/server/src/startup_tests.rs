//! A server started on a store with a body that no longer validates: bodies are built in the
//! background after the server listens, the invalid one is quarantined, and health says so.

use super::*;
use sublevel_core::body::ellipsoid;
use sublevel_core::math::pose_from_parts;
use sublevel_scene::store::{RedbStore, Store};
use sublevel_scene::{BodyRecord, InstanceRecord, StoredPose};
use tonic_health::pb::{health_check_response::ServingStatus, health_client::HealthClient, HealthCheckRequest};

/// Two spheres (r = 0.3 at x = 0, r = 0.4 at x = 3) and an instance of a stored body `b-bad`
/// whose polynomial is negated (no minimizer: it does not validate); returns the scene and the
/// instance ids (sphere 1, sphere 2, `i-bad`).
fn store_with_an_invalid_body(dir: &std::path::Path) -> (String, String, String) {
    let at = |x: f64| pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, 0.0]).unwrap();
    let (scene, a, b) = {
        let c = Catalog::open(Box::new(RedbStore::open_dir(dir).unwrap()), NewtonParams::default()).unwrap();
        let b1 = c.add_body("r1", ellipsoid([0.0; 3], [0.3; 3]).unwrap()).unwrap();
        let b2 = c.add_body("r2", ellipsoid([0.0; 3], [0.4; 3]).unwrap()).unwrap();
        let scene = c.create_scene("s").unwrap();
        let a = c.add_instance(&scene, &b1, at(0.0)).unwrap();
        let b = c.add_instance(&scene, &b2, at(3.0)).unwrap();
        (scene, a, b)
    };
    let store = RedbStore::open_dir(dir).unwrap();
    let mut file = ellipsoid([0.0; 3], [0.5; 3]).unwrap().to_file();
    file.coefficients.iter_mut().for_each(|c| *c = -*c);
    store.put_body("b-bad", &BodyRecord::single("bad", file)).unwrap();
    let rec = InstanceRecord { body_id: "b-bad".into(), pose: StoredPose::from_isometry(&at(6.0)) };
    store.put_instances(&scene, &[("i-bad", &rec)], false).unwrap();
    (scene, a, b)
}

/// The server listens with no body built; its warm-up builds the valid ones and quarantines the
/// invalid one (the record kept: see the catalog's tests), the store's health turns NOT_SERVING, the invalid body's queries
/// answer FAILED_PRECONDITION naming it, and the others answer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_warm_up_quarantines_an_invalid_body_and_health_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, a, b) = store_with_an_invalid_body(dir.path());
    let catalog =
        Arc::new(Catalog::open(Box::new(RedbStore::open_dir(dir.path()).unwrap()), NewtonParams::default()).unwrap());
    assert_eq!((catalog.bodies_built(), catalog.quarantined()), ((0, 3), 0));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let config = ServerConfig { data_dir: dir.path().to_owned(), ..ServerConfig::default() };
    let server = tokio::spawn(serve_catalog(listener, catalog.clone(), config, async move {
        let _ = stopped.await;
    }));
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}")).unwrap().connect().await.unwrap();
    let mut health = HealthClient::new(channel.clone());
    let started = std::time::Instant::now();
    loop {
        let check = HealthCheckRequest { service: STORE_HEALTH_NAME.into() };
        let status = health.check(check).await.unwrap().into_inner().status;
        if status == ServingStatus::NotServing as i32 {
            break;
        }
        assert!(started.elapsed().as_secs() < 60, "the store never turned NOT_SERVING");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    assert_eq!((catalog.bodies_built(), catalog.quarantined(), catalog.bodies_pending()), ((2, 3), 1, 0));
    let all = health.check(HealthCheckRequest { service: String::new() }).await.unwrap().into_inner();
    assert_eq!(all.status, ServingStatus::Serving as i32, "the rest is served");
    let mut client = pb::sublevel_client::SublevelClient::new(channel);
    let ask = |x: &str, y: &str| pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: x.to_owned(),
        instance_b: y.to_owned(),
        ..Default::default()
    };
    let err = client.distance(ask(&a, "i-bad")).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::FailedPrecondition, "{err:?}");
    assert!(err.message().contains("b-bad") && err.message().contains("quarantine"), "{}", err.message());
    let err = client.get_body(pb::GetBodyRequest { body_id: "b-bad".into() }).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::FailedPrecondition, "{err:?}");
    let d = client.distance(ask(&a, &b)).await.unwrap().into_inner().answer.unwrap();
    assert!((d.distance - 2.3).abs() < 1e-9, "{}", d.distance);
    stop.send(()).unwrap();
    server.await.unwrap().unwrap();
}
