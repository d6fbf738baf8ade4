//! Integration tests: what a hostile-but-fair client can make the server hold. Stalled request
//! messages cost the bytes really sent, not their claimed length; a length over the method's limit
//! is refused before anything is buffered; half-open handshakes are closed; connections beyond
//! the cap are closed at once, so clients fail fast instead of hanging (`sublevel_server::admission`).

use crate::util::{add, at, config, demo_bodies, upload_body, ChildServer, Server};
use bytes::Bytes;
use std::time::{Duration, Instant};
use sublevel::service::pb;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tonic::codegen::http;

/// Resident memory of process `pid`, bytes (Linux `/proc/PID/status`).
fn rss_bytes(pid: u32) -> usize {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<usize>().unwrap() * 1024
}

/// The 5-byte gRPC prefix of an uncompressed message claiming `len` bytes.
fn prefix(len: u32) -> Vec<u8> {
    let mut p = vec![0u8];
    p.extend_from_slice(&len.to_be_bytes());
    p
}

/// One raw HTTP/2 connection (a client that sends what it likes).
async fn h2_connection(addr: std::net::SocketAddr) -> h2::client::SendRequest<Bytes> {
    let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let (client, connection) = h2::client::handshake(tcp).await.unwrap();
    tokio::spawn(async move {
        let _ = connection.await;
    });
    client
}

/// Opens a `sublevel.v1` call to `method` and sends `bytes` without ending the stream.
async fn open_call(
    client: &h2::client::SendRequest<Bytes>,
    addr: std::net::SocketAddr,
    method: &str,
    bytes: Vec<u8>,
) -> (h2::client::ResponseFuture, h2::SendStream<Bytes>) {
    let mut ready = client.clone().ready().await.unwrap();
    let request = http::Request::builder()
        .method("POST")
        .uri(format!("http://{addr}/sublevel.v1.Sublevel/{method}"))
        .header("content-type", "application/grpc")
        .header("te", "trailers")
        .body(())
        .unwrap();
    let (response, mut send) = ready.send_request(request, false).unwrap();
    send.send_data(Bytes::from(bytes), false).unwrap();
    (response, send)
}

/// The gRPC status (code, message) of a raw response: from its headers (trailers-only) or its
/// trailers.
async fn grpc_status(response: h2::client::ResponseFuture) -> (i32, String) {
    let response = response.await.unwrap();
    let read = |h: &http::HeaderMap| {
        h.get("grpc-status").map(|s| {
            let message = h.get("grpc-message").map(|m| String::from_utf8_lossy(m.as_bytes()).into_owned());
            (s.to_str().unwrap().parse::<i32>().unwrap(), message.unwrap_or_default())
        })
    };
    if let Some(status) = read(response.headers()) {
        return status;
    }
    let mut body = response.into_body();
    while let Some(chunk) = body.data().await {
        chunk.unwrap();
    }
    let trailers = body.trailers().await.unwrap().expect("trailers");
    read(&trailers).expect("grpc-status trailer")
}

/// The two demo bodies side by side in a new scene; returns a probe `Distance` request.
async fn probe_scene(c: &mut pb::sublevel_client::SublevelClient<tonic::transport::Channel>) -> pb::DistanceRequest {
    let (chair, human) = demo_bodies();
    let b_chair = upload_body(c, "chair", &chair).await;
    let b_human = upload_body(c, "human", &human).await;
    let scene = c.create_scene(pb::CreateSceneRequest { name: "probe".into() }).await.unwrap().into_inner().scene_id;
    let a = add(c, &scene, &b_chair, at([0.0; 3])).await;
    let b = add(c, &scene, &b_human, at([2.9, 0.0, 0.0])).await;
    pb::DistanceRequest { scene_id: scene, instance_a: a, instance_b: b, ..Default::default() }
}

/// A probe call answers within 1 s; returns its distance (meters).
async fn probe(
    c: &mut pb::sublevel_client::SublevelClient<tonic::transport::Channel>,
    req: &pb::DistanceRequest,
) -> f64 {
    let t = Instant::now();
    let r = tokio::time::timeout(Duration::from_secs(1), c.distance(req.clone())).await;
    let r = r.expect("the probe answered within 1 s").expect("the probe succeeded").into_inner();
    assert!(t.elapsed() < Duration::from_secs(1));
    r.answer.expect("an answer").distance
}

/// 300 stalled streams on 10 connections, each claiming a 1 MiB message and sending 1 KiB of it,
/// against a `sublevel serve` process (its allocator, its RSS). tonic alone answered such a prefix
/// by reserving the claimed length: ~2.2 MB of RSS per stream, 660 MB here. Now the server holds
/// what was sent: its RSS grows by less than 64 MiB, a probe answers within 1 s after every
/// connection's streams are open, and each stalled call ends DEADLINE_EXCEEDED at the message
/// timeout (2 s here) naming its flag.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stalled_streams_cost_what_was_sent_and_probes_still_answer() {
    let dir = tempfile::tempdir().unwrap();
    let server = ChildServer::spawn_with(dir.path(), &["--message-timeout-ms", "2000"]);
    let addr: std::net::SocketAddr = server.addr.parse().unwrap();
    let pid = server.child.id();
    let mut c = server.client().await;
    let req = probe_scene(&mut c).await;
    let reference = probe(&mut c, &req).await;
    assert!(reference > 0.1 && reference < 2.9, "{reference}");
    for _ in 0..20 {
        probe(&mut c, &req).await;
    }
    let before = rss_bytes(pid);
    let mut stalled = Vec::new();
    let mut connections = Vec::new();
    let claimed: Vec<u8> = prefix(1 << 20).into_iter().chain(std::iter::repeat_n(0u8, 1024)).collect();
    for _ in 0..10 {
        let conn = h2_connection(addr).await;
        for _ in 0..30 {
            stalled.push(open_call(&conn, addr, "Distance", claimed.clone()).await);
        }
        connections.push(conn);
        assert_eq!(probe(&mut c, &req).await, reference);
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let grown = rss_bytes(pid).saturating_sub(before);
    println!("300 stalled 1 MiB claims: RSS grew {:.1} MiB", grown as f64 / (1 << 20) as f64);
    assert!(grown < 64 << 20, "RSS grew {grown} bytes with 300 stalled streams");
    probe(&mut c, &req).await;

    let t = Instant::now();
    for (response, _send) in stalled {
        let (code, message) = tokio::time::timeout(Duration::from_secs(10), grpc_status(response)).await.unwrap();
        assert_eq!(code, tonic::Code::DeadlineExceeded as i32, "{message}");
        assert!(message.contains("--message-timeout-ms"), "{message}");
    }
    assert!(t.elapsed() < Duration::from_secs(10));
    assert_eq!(probe(&mut c, &req).await, reference);
}

/// A query whose prefix claims more than `--max-request-bytes` (16 MiB) is OUT_OF_RANGE at once,
/// naming the flag, without a byte of it buffered; the same claim is admitted for an upload
/// (its limit is `--max-message-bytes`, 64 MiB): that call waits for its bytes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_method_has_its_message_limit() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(config(dir.path())).await;
    let conn = h2_connection(server.addr()).await;
    let (response, _send) = open_call(&conn, server.addr(), "Distance", prefix(17 << 20)).await;
    let (code, message) = tokio::time::timeout(Duration::from_secs(2), grpc_status(response)).await.unwrap();
    assert_eq!(code, tonic::Code::OutOfRange as i32, "{message}");
    assert!(message.contains("--max-request-bytes") && message.contains("17825792"), "{message}");

    let (response, send) = open_call(&conn, server.addr(), "UploadBody", prefix(17 << 20)).await;
    let waiting = tokio::time::timeout(Duration::from_millis(300), grpc_status(response)).await;
    assert!(waiting.is_err(), "an upload may claim 17 MiB: it waits for its bytes");
    drop(send);
    server.stop().await;
}

/// Eight connections that send half of the HTTP/2 preface and stop fill `--max-connections 8`:
/// a ninth client is closed at once, so its call fails fast instead of waiting in the backlog;
/// the half-open connections are closed at the handshake timeout (300 ms here; they used to be
/// held forever), and then clients are served again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn half_open_handshakes_are_closed_and_connections_are_capped() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.admission.max_connections = 8;
    cfg.admission.handshake_timeout = Duration::from_millis(300);
    let server = Server::start(cfg).await;
    let mut half_open = Vec::new();
    for _ in 0..8 {
        let mut tcp = tokio::net::TcpStream::connect(server.addr()).await.unwrap();
        tcp.write_all(b"PRI * HTTP/2.0\r\n").await.unwrap();
        half_open.push(tcp);
    }
    tokio::time::sleep(Duration::from_millis(50)).await;
    let t = Instant::now();
    let refused = tokio::time::timeout(Duration::from_secs(2), async {
        let channel = tonic::transport::Channel::from_shared(format!("http://{}", server.addr())).unwrap();
        let mut c = pb::sublevel_client::SublevelClient::new(channel.connect().await?);
        c.list_bodies(pb::ListBodiesRequest::default()).await.map_err(|e| e.into())
            as Result<_, Box<dyn std::error::Error + Send + Sync>>
    })
    .await;
    match refused {
        Ok(Err(_)) => {}
        Ok(Ok(_)) => panic!("a ninth connection was served past --max-connections 8"),
        Err(_) => panic!("the ninth client hung instead of failing fast"),
    }
    println!("the ninth client failed after {:?}", t.elapsed());

    for mut tcp in half_open {
        let closed = tokio::time::timeout(Duration::from_secs(3), async {
            let mut buf = [0u8; 256];
            loop {
                match tcp.read(&mut buf).await {
                    Ok(0) | Err(_) => return,
                    Ok(_) => {} // the server's SETTINGS frame
                }
            }
        })
        .await;
        assert!(closed.is_ok(), "a half-open connection was still open 3 s later");
    }
    let mut c = server.client().await;
    let listed = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner();
    assert!(listed.bodies.is_empty());
    server.stop().await;
}
