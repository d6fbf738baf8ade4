//! Integration tests of `serve`'s security: bearer tokens (UNAUTHENTICATED without one,
//! PERMISSION_DENIED for a read token on a write, admin and read tokens where they belong, health
//! open) and TLS with certificates generated at test time (rcgen): the happy path, a client
//! trusting another CA fails the handshake, mTLS refuses a client without a certificate or with
//! one from another CA.

use crate::util::{config, Server};
use std::sync::Arc;
use sublevel::service::auth::AuthTokens;
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::tls::TlsConfig;
use tonic::metadata::MetadataValue;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Identity};
use tonic::Code;

const ADMIN: &str = "admin-token-0123456789abcdef";
const READ: &str = "read-token-0123456789abcdef";

/// A client whose every call carries `authorization: Bearer <token>` (none when `token` is None).
fn with_token(
    channel: Channel,
    token: Option<&str>,
) -> SublevelClient<tonic::service::interceptor::InterceptedService<Channel, impl tonic::service::Interceptor>> {
    let value: Option<MetadataValue<_>> = token.map(|t| format!("Bearer {t}").parse().unwrap());
    SublevelClient::with_interceptor(channel, move |mut req: tonic::Request<()>| {
        if let Some(v) = &value {
            req.metadata_mut().insert("authorization", v.clone());
        }
        Ok(req)
    })
}

/// No token or an unknown one: UNAUTHENTICATED; a read token on a write: PERMISSION_DENIED; an
/// admin token writes; a read token queries (the distance of two spheres is 1 m); health is open.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_decide_who_may_read_and_write() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("tokens");
    std::fs::write(&file, format!("# test tokens\nadmin {ADMIN}\nread  {READ}\n")).unwrap();
    let mut cfg = config(&dir.path().join("data"));
    cfg.auth = Some(Arc::new(AuthTokens::load(&file).unwrap()));
    let server = Server::start(cfg).await;
    let channel = server.channel().await;
    let (mut anonymous, mut reader, mut admin, mut stranger) = (
        with_token(channel.clone(), None),
        with_token(channel.clone(), Some(READ)),
        with_token(channel.clone(), Some(ADMIN)),
        with_token(channel.clone(), Some("someone-else-0123456789abcdef")),
    );

    let e = anonymous.list_bodies(pb::ListBodiesRequest::default()).await.unwrap_err();
    assert_eq!(e.code(), Code::Unauthenticated, "{e:?}");
    let e = stranger.list_bodies(pb::ListBodiesRequest::default()).await.unwrap_err();
    assert_eq!(e.code(), Code::Unauthenticated, "{e:?}");
    let e = reader.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap_err();
    assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");
    assert!(e.message().contains("CreateScene"), "{e:?}");
    let e = reader.cancel_fit_job(pb::CancelFitJobRequest { job_id: "j-x".into() }).await.unwrap_err();
    assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");

    // Admin writes: two spheres of radius 0.5 m, centers 2 m apart.
    let scene = admin.create_scene(pb::CreateSceneRequest { name: "s".into() }).await.unwrap().into_inner().scene_id;
    let mut ids = Vec::new();
    for (name, x) in [("a", 0.0), ("b", 2.0)] {
        let body = sublevel::body::ellipsoid([0.0; 3], [0.5; 3]).unwrap();
        let json = serde_json::to_string(&body.to_file()).unwrap();
        let req =
            pb::UploadBodyRequest { name: name.into(), body: Some(pb::upload_body_request::Body::BodyJson(json)) };
        let body_id = admin.upload_body(req).await.unwrap().into_inner().body_id;
        let req =
            pb::AddInstanceRequest { scene_id: scene.clone(), body_id, pose: Some(crate::util::at([x, 0.0, 0.0])) };
        ids.push(admin.add_instance(req).await.unwrap().into_inner().instance_id);
    }
    // A read token queries and lists.
    let req = pb::DistanceRequest {
        scene_id: scene.clone(),
        instance_a: ids[0].clone(),
        instance_b: ids[1].clone(),
        ..Default::default()
    };
    let d = reader.distance(req).await.unwrap().into_inner().answer.unwrap().distance;
    assert!((d - 1.0).abs() < 1e-6, "distance {d}");
    let bodies = reader.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies;
    assert_eq!(bodies.len(), 2);
    // Health needs no token.
    let mut health = tonic_health::pb::health_client::HealthClient::new(channel.clone());
    let status = health.check(tonic_health::pb::HealthCheckRequest { service: String::new() }).await.unwrap();
    assert_eq!(status.into_inner().status, tonic_health::pb::health_check_response::ServingStatus::Serving as i32);
    // A deleted scene is an admin's business.
    let e = reader.delete_scene(pb::DeleteSceneRequest { scene_id: scene.clone() }).await.unwrap_err();
    assert_eq!(e.code(), Code::PermissionDenied, "{e:?}");
    admin.delete_scene(pb::DeleteSceneRequest { scene_id: scene }).await.unwrap();
    server.stop().await;
}

/// A certificate authority made at test time.
struct Ca {
    issuer: rcgen::Issuer<'static, rcgen::KeyPair>,
    pem: String,
}

impl Ca {
    fn new(name: &str) -> Ca {
        let key = rcgen::KeyPair::generate().unwrap();
        let mut params = rcgen::CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
        params.distinguished_name.push(rcgen::DnType::CommonName, name);
        params.key_usages = vec![rcgen::KeyUsagePurpose::KeyCertSign, rcgen::KeyUsagePurpose::CrlSign];
        let pem = params.self_signed(&key).unwrap().pem();
        Ca { issuer: rcgen::Issuer::new(params, key), pem }
    }

    /// A leaf certificate for `localhost` signed by this CA: (certificate PEM, key PEM).
    fn leaf(&self, client: bool) -> (String, String) {
        let key = rcgen::KeyPair::generate().unwrap();
        let mut params = rcgen::CertificateParams::new(vec!["localhost".to_owned()]).unwrap();
        params.extended_key_usages = vec![if client {
            rcgen::ExtendedKeyUsagePurpose::ClientAuth
        } else {
            rcgen::ExtendedKeyUsagePurpose::ServerAuth
        }];
        (params.signed_by(&key, &self.issuer).unwrap().pem(), key.serialize_pem())
    }
}

/// A TLS client of `server` trusting `ca`, presenting `identity` if any; the error of the
/// connection or of the first call.
async fn tls_call(server: &Server, ca: &str, identity: Option<&(String, String)>) -> Result<usize, String> {
    let mut tls = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(ca)).domain_name("localhost");
    if let Some((cert, key)) = identity {
        tls = tls.identity(Identity::from_pem(cert, key));
    }
    let endpoint = Channel::from_shared(format!("https://{}", server.addr())).unwrap().tls_config(tls).unwrap();
    let channel = endpoint.connect().await.map_err(|e| format!("connect: {e:?}"))?;
    let mut c = SublevelClient::new(channel);
    let r = c.list_bodies(pb::ListBodiesRequest::default()).await.map_err(|e| format!("call: {e:?}"))?;
    Ok(r.into_inner().bodies.len())
}

/// TLS with a CA made at test time: a client trusting it lists bodies; a client trusting another
/// CA fails the handshake; plaintext gets no answer; a bad key is refused up front.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_serves_clients_that_trust_its_ca_only() {
    let dir = tempfile::tempdir().unwrap();
    let (ca, other) = (Ca::new("sublevel test CA"), Ca::new("some other CA"));
    let (cert, key) = ca.leaf(false);
    let mut cfg = config(dir.path());
    cfg.tls = Some(TlsConfig::from_pem(cert.into_bytes(), key.into_bytes(), None).unwrap());
    let server = Server::start(cfg).await;
    assert_eq!(tls_call(&server, &ca.pem, None).await, Ok(0));
    let wrong = tls_call(&server, &other.pem, None).await.unwrap_err();
    assert!(wrong.to_lowercase().contains("certificate") || wrong.contains("UnknownIssuer"), "{wrong}");
    // Plaintext HTTP/2 to a TLS port gets no answer.
    let plain = Channel::from_shared(format!("http://{}", server.addr())).unwrap().connect().await;
    if let Ok(channel) = plain {
        assert!(SublevelClient::new(channel).list_bodies(pb::ListBodiesRequest::default()).await.is_err());
    }
    // A key file that holds no key is refused when the config is built.
    let (cert2, _) = ca.leaf(false);
    let e = TlsConfig::from_pem(cert2.into_bytes(), b"not a key".to_vec(), None).unwrap_err();
    assert!(e.to_string().contains("tls"), "{e}");
    server.stop().await;
}

/// mTLS: a client certificate from the client CA is served; none, or one from another CA, fails.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mtls_requires_a_client_certificate_from_its_ca() {
    let dir = tempfile::tempdir().unwrap();
    let (ca, clients, other) = (Ca::new("server CA"), Ca::new("client CA"), Ca::new("other CA"));
    let (cert, key) = ca.leaf(false);
    let mut cfg = config(dir.path());
    let tls = TlsConfig::from_pem(cert.into_bytes(), key.into_bytes(), Some(clients.pem.clone().into_bytes())).unwrap();
    assert!(tls.mutual());
    cfg.tls = Some(tls);
    let server = Server::start(cfg).await;
    assert_eq!(tls_call(&server, &ca.pem, Some(&clients.leaf(true))).await, Ok(0));
    let none = tls_call(&server, &ca.pem, None).await.unwrap_err();
    assert!(!none.is_empty());
    let foreign = tls_call(&server, &ca.pem, Some(&other.leaf(true))).await.unwrap_err();
    assert!(!foreign.is_empty());
    eprintln!("mTLS without a client certificate: {none}\nmTLS with a foreign certificate: {foreign}");
    server.stop().await;
}
