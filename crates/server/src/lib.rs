//! # sublevel-server
//!
//! The gRPC API `sublevel.v1` (tonic): the only crate of the engine that knows tonic, prost and tokio.
//!
//! Handlers follow one recipe: **validate → call the core → convert**. Validation and every
//! proto ↔ core conversion (including the single `Error → tonic::Status` mapping) live in
//! [`convert`]; the handlers (`handlers/`, one module per domain: jobs, bodies, scenes, queries)
//! stay short. The math core ([`sublevel_scene`],
//! [`sublevel_query`], [`sublevel_fit`]) never sees a proto type.
//!
//! Work placement:
//!
//! - queries (microseconds) and pose updates (no fsync) run inline on the async threads;
//! - structural writes (uploads, scenes, instances: one fsync'd redb transaction each) and mesh
//!   parsing run on tokio's blocking pool;
//! - fits (seconds to minutes of SDP solving, paper §III) run on the blocking pool too, at most
//!   [`ServerConfig::max_concurrent_fits`] at a time, reporting progress through one
//!   `tokio::sync::watch` channel per job that `WatchFitJob` streams from.
//!
//! The server also serves `grpc.health.v1` (tonic-health; `""` and `sublevel.v1.Sublevel` report
//! SERVING until shutdown begins, then NOT_SERVING; [`STORE_HEALTH_NAME`] reports NOT_SERVING
//! while the store's quarantine holds records, see [`sublevel_scene::store`]) and server reflection
//! v1 and v1alpha (tonic-reflection), so `grpcurl`, evans, Postman and Python's
//! grpcio-reflection work without the proto.
//!
//! Transport: every accepted socket has TCP_NODELAY (a small response is never held back by
//! Nagle's algorithm waiting for the client's delayed ACK) and TCP keepalive; HTTP/2 keepalive
//! pings close connections whose peer vanished ([`KEEPALIVE_INTERVAL`], [`KEEPALIVE_TIMEOUT`]).
//! [`admission`] bounds connections, streams per connection, handshake time and the memory held
//! by incomplete request messages.
//! [`status_layer`] turns undecodable requests into INVALID_ARGUMENT and names unknown methods.
//!
//! Security (both off by default): TLS, optionally mutual, from PEM files ([`tls`]); bearer
//! tokens with a read and an admin role ([`auth`]), checked by a tower layer before any handler
//! runs; health and reflection stay open without a token.
//!
//! Operations: the operator's limits ([`ServerConfig`]; counts answer RESOURCE_EXHAUSTED naming
//! their `serve` flag, blocking query solves wait for one of `max_concurrent_sdp` slots) and
//! [`metrics`] (Prometheus counters and histograms, a span and an `x-request-id` per RPC).
//!
//! Deadlines: a call past the client's `grpc-timeout` (or the operator's `--max-request-ms`)
//! answers DEADLINE_EXCEEDED, and the blocking query work it waited for is cancelled at the next
//! Clarabel iteration or batch pair, freeing its SDP slot ([`deadline`]).
//!
//! # Adding an RPC
//!
//! 1. declare it in `proto/sublevel/v1/sublevel.proto` and its commented messages in its domain's
//!    file beside it (`bodies`, `scenes`, `queries`, `robots`; `geometry` for shared types);
//! 2. add its conversions (and field validation) to [`convert`];
//! 3. implement it in its domain's module under `handlers/` as validate → core call → convert,
//!    and delegate to it from the `Sublevel` impl in `handlers/mod.rs`;
//! 4. add a round-trip and an error test to `tests/it/service.rs` (server harness: `tests/it/util.rs`).

#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub use sublevel_core::{Error, Result};

pub mod admission;
pub mod auth;
pub mod convert;
pub mod deadline;
mod handlers;
mod jobs;
mod limits;
pub mod metrics;
mod runtime;
mod shutdown;
pub mod status_layer;
pub mod tls;

use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use sublevel_fit::FitSettings;
use sublevel_query::NewtonParams;
use sublevel_scene::store::RedbStore;
use sublevel_scene::Catalog;

pub use handlers::SublevelService;
pub use shutdown::DEFAULT_SHUTDOWN_GRACE;

/// The gRPC metadata key a scene-sharding proxy routes on: every call about a scene carries
/// `x-scene-id: <scene id>` (nginx consistent hash, `deploy/SCALING.md`).
pub const SCENE_ID_HEADER: &str = "x-scene-id";

/// A request for `message` carrying the routing metadata [`SCENE_ID_HEADER`] of `scene_id`
/// ([`with_scene_id`]).
pub fn scene_request<T>(scene_id: &str, message: T) -> tonic::Request<T> {
    with_scene_id(tonic::Request::new(message), scene_id)
}

/// `request` with the metadata [`SCENE_ID_HEADER`] set to `scene_id` (replacing any). A scene id
/// that is not a valid metadata value (never one the server issues) is left out: the request then
/// goes to any replica, which answers it (or rejects the id) like a single server.
pub fn with_scene_id<T>(mut request: tonic::Request<T>, scene_id: &str) -> tonic::Request<T> {
    if let Ok(value) = scene_id.parse() {
        request.metadata_mut().insert(SCENE_ID_HEADER, value);
    }
    request
}

/// Code generated from `proto/sublevel/v1/` (the service in `sublevel.proto`, its messages in the
/// files it imports): messages, client and server.
#[allow(missing_docs, clippy::all, clippy::pedantic)]
pub mod pb {
    tonic::include_proto!("sublevel.v1");

    /// The encoded `FileDescriptorSet` of `sublevel.v1`, for server reflection.
    pub const FILE_DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/sublevel_descriptor.bin"));
}

/// Fully qualified gRPC name of the service (`sublevel.v1.Sublevel`).
pub const SERVICE_NAME: &str = "sublevel.v1.Sublevel";

/// Health-check name of the store: SERVING when every stored record loaded, NOT_SERVING while the
/// quarantine holds records that could not be (the server still serves everything else). The
/// server listens once the store is open and its records are read; stored bodies are then built
/// in the background ([`serve_catalog`]), and a body found invalid there turns this NOT_SERVING
/// when the warm-up ends.
pub const STORE_HEALTH_NAME: &str = "sublevel.v1.Store";

/// Interval of HTTP/2 keepalive pings and of TCP keepalive probes on every connection.
pub const KEEPALIVE_INTERVAL: std::time::Duration = std::time::Duration::from_secs(30);

/// How long an HTTP/2 keepalive ping may go unanswered before the connection is closed.
pub const KEEPALIVE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// The default most points of one sensor frame ([`ServerConfig::max_frame_points`]): 2²² =
/// 4 194 304, a 2048 × 2048 depth image, whose float32 pixels (16 MiB) pass the default
/// `--max-message-bytes` (64 MiB) with room to spare, as does a PointCloud2 of as many 12-byte
/// points (48 MiB).
pub const DEFAULT_MAX_FRAME_POINTS: usize = 1 << 22;

/// The default most points of frames decoded at once
/// ([`ServerConfig::max_frame_points_in_flight`]): two frames of the largest size.
pub const DEFAULT_MAX_FRAME_POINTS_IN_FLIGHT: usize = 2 * DEFAULT_MAX_FRAME_POINTS;

/// Bytes of server memory a frame's decoding and filtering takes per point at its peak, at most
/// (an upper estimate, checked by the tests): its float32 points (12), the float64 world points
/// the filters keep (24, and as much again while that vector grows), a 16-bit or 32-bit copy of
/// the pixels (4), the voxel grid's map when every point has its own voxel; the k-d tree comes
/// after the point limit (1 000 000 kept). `--max-frame-points-in-flight` × this bounds the
/// frames' working memory.
pub const FRAME_BYTES_PER_POINT: usize = 160;

/// Server settings and request limits.
#[derive(Clone, Debug)]
pub struct ServerConfig {
    /// Directory of the redb database (created if missing); unused with [`Self::store_url`].
    pub data_dir: PathBuf,
    /// `postgres://…` URL of a PostgreSQL store shared by several replicas (`--store`, feature
    /// `postgres`; see `deploy/SCALING.md`); `None` keeps the embedded redb store in `data_dir`.
    pub store_url: Option<String>,
    /// Largest encoded response, and largest request of the uploads (`UploadBody`,
    /// `StartFitJob`, `StartGroupJob`, `ImportScene`, `UploadRobot`, `StartRobotFitJob`,
    /// `UpdatePointCloud`: a sensor frame), in bytes; other requests are limited by
    /// [`admission::AdmissionSettings::max_request_bytes`]. Larger messages are OUT_OF_RANGE
    /// before a handler runs.
    pub max_message_bytes: usize,
    /// Bounds on connections, handshakes and request-message memory ([`admission`]).
    pub admission: admission::AdmissionSettings,
    /// Most points one fit may use (after mesh parsing).
    pub max_fit_points: usize,
    /// Most pairs in one `BatchQuery`.
    pub max_batch_pairs: usize,
    /// Most poses in one `SetPoses`.
    pub max_poses_per_call: usize,
    /// Fits running at the same time (each is CPU-heavy; the rest queue). Default: a quarter of
    /// the CPUs, at least 1.
    pub max_concurrent_fits: usize,
    /// Most fit and group jobs queued or running at once; one more is RESOURCE_EXHAUSTED.
    pub max_fit_queue: usize,
    /// Most scenes the server holds; creating one more is RESOURCE_EXHAUSTED.
    pub max_scenes: usize,
    /// Most bodies the server holds; uploading (or starting a fit of) one more is
    /// RESOURCE_EXHAUSTED.
    pub max_bodies: usize,
    /// Most instances in one scene; adding one more is RESOURCE_EXHAUSTED.
    pub max_instances_per_scene: usize,
    /// Most bytes held by the point clouds of every scene together (`--max-cloud-bytes`); an
    /// `UpdatePointCloud` that would pass it is RESOURCE_EXHAUSTED. Default 2 GiB.
    pub max_cloud_bytes: usize,
    /// Most points of one `UpdatePointCloud` frame (`--max-frame-points`): a depth image's
    /// width × height, a PointCloud2's records. Checked before the frame is decoded; a larger one
    /// is RESOURCE_EXHAUSTED naming the field. Default [`DEFAULT_MAX_FRAME_POINTS`].
    pub max_frame_points: usize,
    /// Most points of frames decoded and filtered at once, all calls together
    /// (`--max-frame-points-in-flight`): a frame takes one unit per point (at most all of them)
    /// until its cloud is built, and the others wait, holding no thread. Bounds the server's
    /// frame memory near [`FRAME_BYTES_PER_POINT`] bytes per unit. Default
    /// [`DEFAULT_MAX_FRAME_POINTS_IN_FLIGHT`].
    pub max_frame_points_in_flight: usize,
    /// Blocking SDP solves of queries (certificates, nonconvex scenes, answers Newton could not
    /// settle) running at once; the rest wait for a slot. Default: half the CPUs, at least 2.
    pub max_concurrent_sdp: usize,
    /// Blocking Newton-only query work running at once (batches and planner requests too large
    /// for an async worker, CheckScene); the rest wait for a slot. Default: the CPUs.
    pub batch_workers: usize,
    /// `Plan` calls running at once, on slots of their own (`--max-concurrent-plans`): the rest
    /// wait, their timeouts running, and never take the batch slots the checks use. Default: half
    /// the CPUs, at least 1.
    pub max_concurrent_plans: usize,
    /// Longest time a `sublevel.v1` call may take (`--max-request-ms`); the shorter of it and the
    /// client's `grpc-timeout` applies, and a call past it answers DEADLINE_EXCEEDED with its
    /// blocking query work cancelled ([`deadline`]). `None`: only client deadlines apply.
    pub max_request_time: Option<std::time::Duration>,
    /// Tolerances of every query.
    pub newton: NewtonParams,
    /// Settings of every fit (the degree comes from each request).
    pub fit: FitSettings,
    /// After the shutdown signal, how long the server waits for in-flight requests and for
    /// cancelled fit jobs to record their end before it returns anyway (`--shutdown-grace`).
    pub shutdown_grace: std::time::Duration,
    /// Bearer tokens every `sublevel.v1` call must carry (`--auth-tokens`; see [`auth`]); `None`
    /// serves without authentication.
    pub auth: Option<std::sync::Arc<auth::AuthTokens>>,
    /// TLS certificate, key and optional client CA (`--tls-cert`, `--tls-key`,
    /// `--tls-client-ca`; see [`tls`]); `None` serves plaintext.
    pub tls: Option<tls::TlsConfig>,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            data_dir: PathBuf::from("./sublevel-data"),
            store_url: None,
            max_message_bytes: 64 * 1024 * 1024,
            admission: admission::AdmissionSettings::default(),
            max_fit_points: 2_000_000,
            max_batch_pairs: 10_000,
            max_poses_per_call: 100_000,
            max_concurrent_fits: limits::default_fit_slots(),
            max_fit_queue: 16,
            max_scenes: 10_000,
            max_bodies: 10_000,
            max_instances_per_scene: 100_000,
            max_cloud_bytes: sublevel_scene::DEFAULT_MAX_CLOUD_BYTES,
            max_frame_points: DEFAULT_MAX_FRAME_POINTS,
            max_frame_points_in_flight: DEFAULT_MAX_FRAME_POINTS_IN_FLIGHT,
            max_concurrent_sdp: limits::default_sdp_slots(),
            batch_workers: limits::default_batch_workers(),
            max_concurrent_plans: limits::default_plan_slots(),
            max_request_time: None,
            newton: NewtonParams::default(),
            fit: FitSettings::default(),
            shutdown_grace: DEFAULT_SHUTDOWN_GRACE,
            auth: None,
            tls: None,
        }
    }
}

/// Opens the catalog stored in `config.data_dir` (redb), creating it if missing, or in the
/// PostgreSQL database of `config.store_url`.
///
/// # Errors
/// [`Error::Io`] / [`Error::Storage`] when the database cannot be opened (e.g. another server
/// holds it, PostgreSQL is unreachable); [`Error::InvalidArgument`] naming `--store` for a bad
/// URL or a build without the `postgres` feature.
pub fn open_catalog(config: &ServerConfig) -> Result<Arc<Catalog>> {
    let store: Box<dyn sublevel_scene::store::Store> = match &config.store_url {
        None => Box::new(RedbStore::open_dir(&config.data_dir)?),
        #[cfg(feature = "postgres")]
        Some(url) => Box::new(sublevel_scene::store::PostgresStore::connect(url)?),
        #[cfg(not(feature = "postgres"))]
        Some(_) => return Err(Error::invalid("--store", "this build has no PostgreSQL store (feature `postgres`)")),
    };
    let store = metrics::TimedStore::new(store);
    Ok(Arc::new(Catalog::open(Box::new(store), config.newton)?))
}

/// Serves `sublevel.v1`, health and reflection on `listener` until `shutdown` completes, with the
/// catalog stored in `config.data_dir`.
///
/// Tests pass a throwaway `127.0.0.1:0` listener and a oneshot receiver; the binary passes
/// Ctrl-C. See [`serve_catalog`] for what shutdown does.
///
/// # Errors
/// Those of [`open_catalog`]; [`Error::Io`] when the transport fails.
pub async fn serve(
    listener: tokio::net::TcpListener,
    config: ServerConfig,
    shutdown: impl Future<Output = ()> + Send,
) -> Result<()> {
    let catalog = open_catalog(&config)?;
    serve_catalog(listener, catalog, config, shutdown).await
}

/// Like [`serve`], with an already opened catalog (e.g. one the caller preloaded with demo data).
///
/// Once it listens, the stored bodies not built yet are built in the background
/// ([`Catalog::warm_up`] on the blocking pool, logging `bodies built` with the count and the
/// seconds); queries meanwhile build the bodies they need first. When the warm-up ends,
/// [`STORE_HEALTH_NAME`] turns NOT_SERVING if it quarantined bodies that no longer validate.
///
/// When `shutdown` completes, health turns NOT_SERVING, every queued and running fit job is
/// cancelled (a running SDP stops at its next Clarabel iteration and the job is recorded
/// CANCELLED, no body stored), the listener closes, and this returns once in-flight requests
/// have finished and every job recorded its end, or when [`ServerConfig::shutdown_grace`] has
/// passed, whichever comes first — and once the body warm-up has stopped (before its next body;
/// at most another grace), so that the store can be reopened.
///
/// # Errors
/// [`Error::Io`] when reflection cannot be built or the transport fails.
pub async fn serve_catalog(
    listener: tokio::net::TcpListener,
    catalog: Arc<Catalog>,
    config: ServerConfig,
    shutdown: impl Future<Output = ()> + Send,
) -> Result<()> {
    use pb::sublevel_server::SublevelServer;
    use tonic_health::ServingStatus;
    let (reporter, health) = tonic_health::server::health_reporter();
    reporter.set_serving::<SublevelServer<SublevelService>>().await;
    let store_status = if catalog.quarantined() == 0 { ServingStatus::Serving } else { ServingStatus::NotServing };
    reporter.set_service_status(STORE_HEALTH_NAME, store_status).await;
    let reflection_error =
        |e: tonic_reflection::server::Error| Error::Io(std::io::Error::other(format!("reflection: {e}")));
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .map_err(reflection_error)?;
    let reflection_v1alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(pb::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1alpha()
        .map_err(reflection_error)?;
    let max = config.max_message_bytes;
    let grace = config.shutdown_grace;
    let tls_mode = match &config.tls {
        None => "off",
        Some(t) if t.mutual() => "mutual",
        Some(_) => "on",
    };
    let auth_on = config.auth.is_some();
    let auth = auth::AuthLayer::new(config.auth.clone());
    let deadlines = deadline::DeadlineLayer::new(config.max_request_time);
    let admission = config.admission.clone();
    let messages = admission::messages::MessageLayer::new(&admission, max);
    let builder = match &config.tls {
        None => tonic::transport::Server::builder(),
        Some(tls) => tonic::transport::Server::builder()
            .tls_config(tls.server_tls().timeout(admission.handshake_timeout))
            .map_err(|e| Error::invalid("tls", format!("unusable certificate, key or client CA: {e}")))?,
    };
    let (warm_up, warm_up_task) = warm_up_in_background(catalog.clone(), reporter.clone());
    let warm_up_stop = warm_up.clone();
    let handlers = SublevelService::new(catalog, config);
    let jobs = handlers.jobs.clone();
    let jobs_idle = handlers.jobs.clone();
    let (shutdown, deadline) = shutdown::graced(shutdown, grace);
    let service = SublevelServer::new(handlers).max_decoding_message_size(max).max_encoding_message_size(max);
    let addr = listener.local_addr().ok();
    tracing::info!(?addr, tls = tls_mode, auth = auth_on, "serving {SERVICE_NAME}");
    let incoming = admission::admit(listener, &admission, KEEPALIVE_INTERVAL);
    let stopping = async move {
        shutdown.await;
        tracing::info!(?grace, "shutting down: health NOT_SERVING, fit jobs cancelled, draining requests");
        warm_up.store(true, std::sync::atomic::Ordering::Relaxed);
        jobs.stop();
        reporter.set_not_serving::<SublevelServer<SublevelService>>().await;
        reporter.set_service_status("", ServingStatus::NotServing).await;
    };
    let serving = builder
        .http2_keepalive_interval(Some(KEEPALIVE_INTERVAL))
        .http2_keepalive_timeout(Some(KEEPALIVE_TIMEOUT))
        .max_concurrent_streams(admission.max_streams_per_connection)
        .initial_stream_window_size(admission.stream_window_bytes)
        .initial_connection_window_size(admission.connection_window_bytes)
        .http2_adaptive_window(Some(false))
        .layer(metrics::RpcLayer)
        .layer(messages)
        .layer(status_layer::StatusLayer)
        .layer(auth)
        .layer(deadlines)
        .add_service(health)
        .add_service(reflection)
        .add_service(reflection_v1alpha)
        .add_service(service)
        .serve_with_incoming_shutdown(incoming, stopping);
    let serving = async move {
        serving.await.map_err(|e| Error::Io(std::io::Error::other(format!("transport: {e}"))))?;
        jobs_idle.wait_idle().await;
        Ok(())
    };
    let outcome = shutdown::within(serving, deadline, grace).await;
    // The warm-up holds the catalog (and so the store): stop it and wait for it, so a caller can
    // reopen the store once this returns. It stops before its next body.
    warm_up_stop.store(true, std::sync::atomic::Ordering::Relaxed);
    if let Some(task) = warm_up_task {
        if tokio::time::timeout(grace, task).await.is_err() {
            tracing::warn!(?grace, "the body warm-up did not stop within the grace");
        }
    }
    outcome?;
    tracing::info!("server stopped");
    Ok(())
}

/// Starts [`Catalog::warm_up_until`] on the blocking pool, then sets [`STORE_HEALTH_NAME`] from
/// the catalog's quarantine count; returns the flag that stops it early (set at shutdown) and the
/// task (`None` when no body waited for its build).
fn warm_up_in_background(
    catalog: Arc<Catalog>,
    reporter: tonic_health::server::HealthReporter,
) -> (Arc<std::sync::atomic::AtomicBool>, Option<tokio::task::JoinHandle<()>>) {
    use tonic_health::ServingStatus;
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (_, total) = catalog.bodies_built();
    if catalog.bodies_pending() == 0 {
        tracing::info!(bodies = total, "bodies built: none waited for a build");
        return (stop, None);
    }
    let flag = stop.clone();
    let task = tokio::spawn(async move {
        let work = catalog.clone();
        let done = tokio::task::spawn_blocking(move || work.warm_up_until(&flag)).await;
        match done {
            Ok(w) => tracing::info!(
                built = w.built,
                quarantined = w.quarantined,
                bodies = total,
                seconds = w.seconds,
                stopped = w.stopped,
                "bodies built"
            ),
            Err(e) => tracing::error!(error = %e, "the body warm-up failed; bodies build on first use"),
        }
        if catalog.quarantined() > 0 {
            tracing::warn!(records = catalog.quarantined(), "the store's quarantine holds records");
            reporter.set_service_status(STORE_HEALTH_NAME, ServingStatus::NotServing).await;
        }
    });
    (stop, Some(task))
}

#[cfg(test)]
mod startup_tests;

#[cfg(test)]
mod routing_tests {
    use super::*;

    /// The routing header carries the scene id; an unusable id leaves the request without it.
    #[test]
    fn scene_requests_carry_the_scene_id_header() {
        let r = scene_request("s-0123abcd", pb::DistanceRequest::default());
        assert_eq!(r.metadata().get(SCENE_ID_HEADER).unwrap().to_str().unwrap(), "s-0123abcd");
        let mut r = tonic::Request::new(());
        r.metadata_mut().insert(SCENE_ID_HEADER, "old".parse().unwrap());
        let r = with_scene_id(r, "s-2");
        let values: Vec<_> =
            r.metadata().get_all(SCENE_ID_HEADER).iter().map(|v| v.to_str().unwrap().to_owned()).collect();
        assert_eq!(values, ["s-2"]);
        let r = scene_request("bad\nid", ());
        assert!(r.metadata().get(SCENE_ID_HEADER).is_none());
    }
}
