//! `sublevel loadtest`: a gRPC load generator for a running server (loopback), with latency
//! histograms, throughput, errors by status code, and the in-process throughput of the same
//! queries beside it.
//!
//! ```text
//! cargo run --release -- serve --demo --addr 127.0.0.1:50051 --data-dir /tmp/lt-data   # terminal 1
//! cargo run --release -- loadtest --scenario stream --concurrency 2 --duration 10         # terminal 2
//! cargo run --release -- loadtest --scenario stream --rate 2000 --json out/stream.json
//! ```
//!
//! # Set-up and tear-down
//!
//! The load test never touches the server's other data: it uploads the demo bodies (chair_101 and
//! human_10, embedded in the binary like `serve --demo` does) as two new bodies named
//! `loadtest-chair_101` / `loadtest-human_10`, creates its own fresh scene `loadtest-…` with one
//! chair at the origin and `min(K, 32)` humans on a ring around it (three radii, each human turned
//! towards the chair), and deletes the scene and both bodies at the end, also after a failed run.
//! The K pairs of a request are (chair, human `j mod humans`) for j = 0..K: K distinct pairs up to
//! 32, repeated pairs beyond. Every pair stays separated throughout, by 0.1 m to about a meter
//! (typical planner queries near obstacles, no contact).
//!
//! # Scenarios
//!
//! - `unary`: one `Distance` call per request (one pair, cycling through the K pairs).
//! - `batch`: one `BatchQuery` of the K DISTANCE pairs per request (stored poses); with
//!   `--columns` in columns (`PairColumns` → `AnswerColumns`: no message per pair; the stream
//!   scenario too).
//! - `stream`: planner-like. Each client task holds one `QueryStream`; each request is one planner
//!   state: it moves the chair a small step (≈ 0.5 mm and ≤ 0.5 mrad) along a smooth closed path
//!   (a Lissajous figure of 0.3 m amplitude, turning ±0.3 rad about z) through `QueryRequest.poses`
//!   and asks the K pairs as `PlannerQuery`s, DISTANCE by default or COLLIDE with
//!   `--stream-query collide --margin M`. The tasks start at evenly spaced points of the path. The
//!   pose lives in the stream's private view only (no store write), so tasks never race.
//! - `mixed`: every request draws its kind (a fixed pseudo-random sequence per task): 20 % unary,
//!   30 % batch, 50 % stream steps (each task keeps its stream open between its stream steps).
//!   Latencies are reported overall and per kind.
//!
//! # Load model
//!
//! `--concurrency N` client tasks, each an OS thread with its own single-threaded tokio runtime and,
//! by default, its own channel (HTTP/2 connection); `--shared-channel` multiplexes all tasks over
//! one connection. Without `--rate` the load is a closed loop: each task sends its next request as
//! soon as the previous one answered, and latency is send → answer. With `--rate R` the load is an
//! open loop: request n (counted over all tasks) is scheduled at `start + n / R`, taken by the next
//! free task, and its latency is measured from that scheduled time, so a slow answer that delays
//! later requests counts against them too (no coordinated omission). The open loop also reports
//! how late the client itself woke up to send (the "send lag"; thread sleeps wake ~50–100 µs late on
//! Linux, which is included in the latencies) and how many scheduled requests were never sent
//! before the end.
//!
//! The run is bounded: requests are sent for `--duration` seconds (default 10, at most 3600) or
//! until `--requests N` were sent, whichever comes first; every request times out after 30 s.
//!
//! # Output
//!
//! Latency histograms (`hdrhistogram`, µs, 3 significant digits) give p50 / p90 / p99 / p99.9 /
//! max; throughput is answered requests per second and pair queries (pairs answered) per second;
//! failed requests are counted by gRPC status code (`BAD_RESPONSE`: an answer count or request id
//! that does not match the request). Then the same queries run in this process on a
//! [`sublevel::scene::Catalog`] (same bodies, same poses; the stream scenario through a
//! [`QueryView`] like the server's stream) on one thread for `--in-process-seconds` (default 1;
//! 0 skips it), and the ratio gRPC / in-process of pair queries per second is printed beside it
//! (the gRPC figure uses all client tasks and the server's threads, the in-process one a single
//! thread). `--json PATH` writes the same figures: `scenario`, `p50_us`, `p90_us`, `p99_us`,
//! `p999_us`, `max_us`, `mean_us`, `requests`, `requests_per_s`, `pair_queries`,
//! `pair_queries_per_s`, `errors` (status code → count), `concurrency`, `duration_s` (measured),
//! `pairs_per_request`, `rate` (null: closed loop), `shared_channel`, `columns`, `stream_query`,
//! `in_process_pair_queries_per_s`, `grpc_over_in_process`, and for the open loop `send_lag_p50_us`,
//! `send_lag_p99_us`, `unsent`; for `mixed` also `by_operation` (the same latency and count fields
//! per kind).

use hdrhistogram::Histogram;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Barrier, OnceLock};
use std::time::{Duration, Instant};
use sublevel::body::BodyFile;
use sublevel::math::{pose_from_parts, Isometry3};
use sublevel::query::NewtonParams;
use sublevel::scene::planner::{PlannerRequest, QueryView};
use sublevel::scene::store::RedbStore;
use sublevel::scene::{Catalog, QueryKind, QueryOptions, QueryPair};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::{Body, Error, Result};
use tonic::transport::{Channel, Endpoint};

/// The demo chair (a degree-4 fit of `chair_101.off`, in body-file JSON).
const CHAIR_JSON: &str = include_str!("../../data/demo/chair_101.json");
/// The demo human (a degree-4 fit of `human_10.off`, in body-file JSON).
const HUMAN_JSON: &str = include_str!("../../data/demo/human_10.json");
/// Most humans placed around the chair (more pairs repeat them).
const MAX_HUMANS: usize = 32;
/// Steps of one lap of the chair's path.
const PATH_STEPS: u64 = 4000;
/// Amplitude of the chair's path (meters).
const PATH_AMPLITUDE: f64 = 0.3;
/// Amplitude of the chair's turn about z along its path (radians).
const PATH_TURN: f64 = 0.3;
/// Ring radius of the humans, in units of the sum of the two bodies' normalization scales.
const RING: f64 = 0.9;
/// Every request (and the set-up calls) time out after this long.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(30);
/// Share of unary / batch requests in the mixed scenario, in percent (the rest are stream steps).
const MIXED_UNARY_PERCENT: u64 = 20;
/// See [`MIXED_UNARY_PERCENT`].
const MIXED_BATCH_PERCENT: u64 = 30;

/// What the client tasks send (see the module docs).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scenario {
    /// One `Distance` call per request.
    Unary,
    /// One `BatchQuery` of K pairs per request.
    Batch,
    /// One `QueryStream` per task; each request moves the chair one step and asks K pairs.
    Stream,
    /// 20 % unary, 30 % batch, 50 % stream steps.
    Mixed,
}

impl Scenario {
    fn name(self) -> &'static str {
        match self {
            Scenario::Unary => "unary",
            Scenario::Batch => "batch",
            Scenario::Stream => "stream",
            Scenario::Mixed => "mixed",
        }
    }
}

/// The query kind of the stream scenario's planner queries.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamQuery {
    /// `QUERY_KIND_DISTANCE`: the Euclidean distance with witnesses.
    Distance,
    /// `QUERY_KIND_COLLIDE` with `--margin`: bounding spheres first, the distance solve if needed.
    Collide,
}

/// Arguments of `sublevel loadtest`.
#[derive(clap::Args, Clone, Debug)]
pub struct LoadtestArgs {
    /// Server address, `host:port` (or an `http://` URI).
    #[arg(long, default_value = "127.0.0.1:50051")]
    pub addr: String,
    /// What to send: unary (Distance), batch (BatchQuery), stream (QueryStream), mixed.
    #[arg(long, value_enum, default_value_t = Scenario::Stream)]
    pub scenario: Scenario,
    /// Client tasks (threads), each with its own connection unless --shared-channel.
    #[arg(long, default_value_t = 1)]
    pub concurrency: usize,
    /// Seconds to send requests for (the run stops by itself).
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// Stop after this many requests in all (also bounded by --duration).
    #[arg(long)]
    pub requests: Option<u64>,
    /// Open loop: total requests per second on a fixed timetable (latency from the scheduled send
    /// time); closed loop when absent.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Pairs per request (batch and stream), K.
    #[arg(long, default_value_t = 20)]
    pub pairs: usize,
    /// Kind of the stream scenario's planner queries.
    #[arg(long, value_enum, default_value_t = StreamQuery::Distance)]
    pub stream_query: StreamQuery,
    /// Margin of COLLIDE queries, meters.
    #[arg(long, default_value_t = 0.05)]
    pub margin: f64,
    /// All client tasks share one channel (one HTTP/2 connection).
    #[arg(long)]
    pub shared_channel: bool,
    /// Batch and stream requests in columns (`BatchQueryRequest.columns`,
    /// `QueryRequest.columns`, answered in `AnswerColumns`) instead of one message per pair.
    #[arg(long)]
    pub columns: bool,
    /// Seconds of the single-threaded in-process comparison run (0 skips it).
    #[arg(long, default_value_t = 1.0)]
    pub in_process_seconds: f64,
    /// Write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs `sublevel loadtest`.
///
/// # Errors
/// Invalid arguments, a server that cannot be reached or refuses the set-up, a JSON file that
/// cannot be written. Failed load requests are not errors: they are counted by status code.
pub fn run(args: LoadtestArgs) -> Result<()> {
    let outcome = execute(&args, false)?;
    print!("{}", outcome.report.text());
    if let Some(path) = &args.json {
        write_json(path, &outcome.report.json())?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, serde_json::to_string_pretty(value)? + "\n")?;
    Ok(())
}

fn check_args(args: &LoadtestArgs) -> Result<()> {
    if !(1..=256).contains(&args.concurrency) {
        return Err(Error::invalid("--concurrency", format!("must be in 1..=256, got {}", args.concurrency)));
    }
    if !(args.duration.is_finite() && args.duration > 0.0 && args.duration <= 3600.0) {
        return Err(Error::invalid("--duration", format!("must be in (0, 3600] seconds, got {}", args.duration)));
    }
    if args.requests == Some(0) {
        return Err(Error::invalid("--requests", "must be at least 1"));
    }
    if let Some(r) = args.rate {
        if !(r.is_finite() && r > 0.0 && r <= 1e7) {
            return Err(Error::invalid("--rate", format!("must be in (0, 1e7] requests per second, got {r}")));
        }
    }
    if !(1..=10_000).contains(&args.pairs) {
        return Err(Error::invalid("--pairs", format!("must be in 1..=10000, got {}", args.pairs)));
    }
    if !(args.margin.is_finite() && args.margin >= 0.0) {
        return Err(Error::invalid("--margin", format!("must be finite and >= 0 meters, got {}", args.margin)));
    }
    if !(args.in_process_seconds.is_finite() && (0.0..=600.0).contains(&args.in_process_seconds)) {
        return Err(Error::invalid(
            "--in-process-seconds",
            format!("must be in [0, 600], got {}", args.in_process_seconds),
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The scene: poses of the humans and of the chair along its path
// ---------------------------------------------------------------------------------------------

/// A pose as a unit quaternion `(w, x, y, z)` and a translation (meters).
type Parts = ([f64; 4], [f64; 3]);

/// The bodies and where they stand.
#[derive(Clone, Debug)]
struct Layout {
    /// Pose of every human.
    humans: Vec<Parts>,
    /// Human index of the second instance of pair j (the first is always the chair).
    pair_humans: Vec<usize>,
}

fn turn_z(angle: f64) -> [f64; 4] {
    [(0.5 * angle).cos(), 0.0, 0.0, (0.5 * angle).sin()]
}

fn demo_body(name: &str, json: &str) -> Result<Body> {
    let file: BodyFile = serde_json::from_str(json)?;
    Body::from_file(file).map_err(|e| Error::invalid(format!("embedded demo body {name}"), e.to_string()))
}

impl Layout {
    /// `min(pairs, 32)` humans on a ring around the chair (radius [`RING`] × the sum of the scales,
    /// ± 15 % in turn), each turned towards the chair.
    fn new(pairs: usize) -> Result<Self> {
        let ring = RING * (demo_body("chair_101", CHAIR_JSON)?.scale() + demo_body("human_10", HUMAN_JSON)?.scale());
        let n = pairs.clamp(1, MAX_HUMANS);
        let humans = (0..n)
            .map(|j| {
                let phi = std::f64::consts::TAU * j as f64 / n as f64;
                let r = ring * (1.0 + 0.15 * ((j % 3) as f64 - 1.0));
                (turn_z(phi + std::f64::consts::PI), [r * phi.cos(), r * phi.sin(), 0.0])
            })
            .collect();
        Ok(Self { humans, pair_humans: (0..pairs).map(|j| j % n).collect() })
    }
}

/// The chair's stored pose (unary, batch): the identity.
const CHAIR_HOME: Parts = ([1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0]);

/// The chair's pose at step `step` of task `task` of `tasks`: a smooth closed path, the tasks
/// starting at evenly spaced points of it.
fn chair_pose(task: usize, tasks: usize, step: u64) -> Parts {
    let s = step + (task as u64 * PATH_STEPS) / tasks.max(1) as u64;
    let phi = std::f64::consts::TAU * (s % PATH_STEPS) as f64 / PATH_STEPS as f64;
    let t = [PATH_AMPLITUDE * phi.cos(), 0.5 * PATH_AMPLITUDE * (2.0 * phi).sin(), 0.0];
    (turn_z(PATH_TURN * phi.sin()), t)
}

fn proto_pose(p: &Parts) -> pb::Pose {
    let (q, t) = p;
    pb::Pose {
        rotation: Some(pb::Quaternion { w: q[0], x: q[1], y: q[2], z: q[3] }),
        translation: Some(pb::Vec3 { x: t[0], y: t[1], z: t[2] }),
    }
}

fn isometry(p: &Parts) -> Result<Isometry3> {
    pose_from_parts("pose", p.0, p.1)
}

// ---------------------------------------------------------------------------------------------
// Set-up and tear-down on the server
// ---------------------------------------------------------------------------------------------

/// Ids of what the load test created on the server.
#[derive(Clone, Debug, Default)]
struct Remote {
    bodies: Vec<String>,
    scene: Option<String>,
    chair: String,
    humans: Vec<String>,
}

fn uri(addr: &str) -> String {
    if addr.starts_with("http://") || addr.starts_with("https://") {
        addr.to_owned()
    } else {
        format!("http://{addr}")
    }
}

fn endpoint(addr: &str) -> Result<Endpoint> {
    let e = Endpoint::from_shared(uri(addr)).map_err(|e| Error::invalid("--addr", e.to_string()))?;
    Ok(e.tcp_nodelay(true).connect_timeout(Duration::from_secs(5)))
}

fn io_error(what: &str, e: impl std::fmt::Display) -> Error {
    Error::Io(std::io::Error::other(format!("{what}: {e}")))
}

async fn connect(endpoint: &Endpoint) -> Result<Channel> {
    endpoint.connect().await.map_err(|e| {
        // tonic's transport error says only "transport error": append its causes.
        let mut text = e.to_string();
        let mut cause = std::error::Error::source(&e);
        while let Some(c) = cause {
            text.push_str(&format!(": {c}"));
            cause = c.source();
        }
        io_error(&format!("cannot connect to {}", endpoint.uri()), text)
    })
}

async fn call<T>(
    what: &str,
    fut: impl std::future::Future<Output = std::result::Result<T, tonic::Status>>,
) -> Result<T> {
    match tokio::time::timeout(REQUEST_TIMEOUT, fut).await {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(s)) => Err(io_error(what, format!("{} ({})", s.message(), code_name(s.code())))),
        Err(_) => Err(io_error(what, "timed out")),
    }
}

/// Uploads the bodies, creates the scene and its instances; `remote` records every id as soon as
/// it exists, so that [`teardown`] removes what was made even when a later step fails.
async fn setup(client: &mut SublevelClient<Channel>, layout: &Layout, remote: &mut Remote) -> Result<()> {
    let mut body_ids = Vec::new();
    for (name, json) in [("loadtest-chair_101", CHAIR_JSON), ("loadtest-human_10", HUMAN_JSON)] {
        let req = pb::UploadBodyRequest {
            name: name.into(),
            body: Some(pb::upload_body_request::Body::BodyJson(json.into())),
        };
        let id = call("UploadBody", client.upload_body(req)).await?.into_inner().body_id;
        remote.bodies.push(id.clone());
        body_ids.push(id);
    }
    let name = format!("loadtest-{:08x}", rand::random::<u32>());
    let scene = call("CreateScene", client.create_scene(pb::CreateSceneRequest { name })).await?.into_inner().scene_id;
    remote.scene = Some(scene.clone());
    let add = |body: &str, pose: &Parts| pb::AddInstanceRequest {
        scene_id: scene.clone(),
        body_id: body.to_owned(),
        pose: Some(proto_pose(pose)),
    };
    remote.chair =
        call("AddInstance", client.add_instance(add(&body_ids[0], &CHAIR_HOME))).await?.into_inner().instance_id;
    for h in &layout.humans {
        let id = call("AddInstance", client.add_instance(add(&body_ids[1], h))).await?.into_inner().instance_id;
        remote.humans.push(id);
    }
    Ok(())
}

/// Deletes the scene, then the bodies; failures are printed on stderr (the run's figures stand).
async fn teardown(client: &mut SublevelClient<Channel>, remote: &Remote) {
    if let Some(scene) = &remote.scene {
        let req = pb::DeleteSceneRequest { scene_id: scene.clone() };
        if let Err(e) = call("DeleteScene", client.delete_scene(req)).await {
            eprintln!("warning: could not delete the load-test scene {scene}: {e}");
        }
    }
    for body in &remote.bodies {
        let req = pb::DeleteBodyRequest { body_id: body.clone() };
        if let Err(e) = call("DeleteBody", client.delete_body(req)).await {
            eprintln!("warning: could not delete the load-test body {body}: {e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Client tasks
// ---------------------------------------------------------------------------------------------

/// The kind of one request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    Unary = 0,
    Batch = 1,
    Stream = 2,
}

const OPS: [Op; 3] = [Op::Unary, Op::Batch, Op::Stream];

impl Op {
    fn name(self) -> &'static str {
        match self {
            Op::Unary => "unary",
            Op::Batch => "batch",
            Op::Stream => "stream",
        }
    }
}

/// A small deterministic generator (splitmix64) for the mixed scenario's choices.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Picks the operations of one task, and what each asks.
struct OpPicker {
    scenario: Scenario,
    rng: SplitMix,
    unary: u64,
    step: u64,
    task: usize,
}

impl OpPicker {
    fn new(scenario: Scenario, task: usize) -> Self {
        Self { scenario, rng: SplitMix(0x5EED_0000 + task as u64), unary: 0, step: 0, task }
    }

    fn next(&mut self) -> Op {
        match self.scenario {
            Scenario::Unary => Op::Unary,
            Scenario::Batch => Op::Batch,
            Scenario::Stream => Op::Stream,
            Scenario::Mixed => match self.rng.next() % 100 {
                x if x < MIXED_UNARY_PERCENT => Op::Unary,
                x if x < MIXED_UNARY_PERCENT + MIXED_BATCH_PERCENT => Op::Batch,
                _ => Op::Stream,
            },
        }
    }

    /// The pair of the next unary request.
    fn next_unary_pair(&mut self, pairs: usize) -> usize {
        let j = (self.task as u64 + self.unary) % pairs as u64;
        self.unary += 1;
        j as usize
    }

    /// The step of the next stream request.
    fn next_step(&mut self) -> u64 {
        self.step += 1;
        self.step - 1
    }
}

/// One answered request, kept for checking (tests).
#[derive(Clone, Debug)]
struct Record {
    /// The chair's pose in the request's view (stream steps); `None`: the stored pose.
    chair: Option<Parts>,
    /// Pair indices asked, in order.
    pairs: Vec<usize>,
    /// The distances answered, in order (for COLLIDE: the CollideAnswer's distance).
    distances: Vec<f64>,
}

/// What every task shares (read-only but for the request counter).
struct Plan {
    scenario: Scenario,
    tasks: usize,
    pairs: usize,
    rate: Option<f64>,
    cap: Option<u64>,
    duration: Duration,
    stream_query: StreamQuery,
    margin: f64,
    record: bool,
    columns: bool,
    scene: String,
    chair: String,
    /// The second instance of every pair.
    seconds: Vec<String>,
    endpoint: Endpoint,
    shared: Option<Channel>,
    /// Next request slot (over all tasks).
    next: AtomicU64,
    start: OnceLock<Instant>,
    ready: Barrier,
}

fn new_histogram() -> Histogram<u64> {
    // 1 µs .. 1 h, 3 significant digits; larger values saturate.
    Histogram::new_with_bounds(1, 3_600_000_000, 3).expect("valid histogram bounds")
}

fn micros(d: Duration) -> u64 {
    (d.as_nanos().div_ceil(1000)).max(1) as u64
}

/// Counts and latencies of one task (merged over tasks afterwards).
struct Tally {
    all: Histogram<u64>,
    by_op: [Histogram<u64>; 3],
    lag: Histogram<u64>,
    requests: [u64; 3],
    pair_queries: [u64; 3],
    errors: BTreeMap<String, u64>,
    /// Open loop: requests scheduled before the end but never sent (set after the merge).
    unsent: u64,
    last: Option<Instant>,
    records: Vec<Record>,
}

impl Tally {
    fn new() -> Self {
        Self {
            all: new_histogram(),
            by_op: [new_histogram(), new_histogram(), new_histogram()],
            lag: new_histogram(),
            requests: [0; 3],
            pair_queries: [0; 3],
            errors: BTreeMap::new(),
            unsent: 0,
            last: None,
            records: Vec::new(),
        }
    }

    fn error(&mut self, code: &str) {
        *self.errors.entry(code.to_owned()).or_default() += 1;
    }

    fn merge(&mut self, o: Tally) {
        self.all.add(&o.all).expect("same histogram bounds");
        for (a, b) in self.by_op.iter_mut().zip(o.by_op.iter()) {
            a.add(b).expect("same histogram bounds");
        }
        self.lag.add(&o.lag).expect("same histogram bounds");
        for k in 0..3 {
            self.requests[k] += o.requests[k];
            self.pair_queries[k] += o.pair_queries[k];
        }
        for (code, n) in o.errors {
            *self.errors.entry(code).or_default() += n;
        }
        self.last = self.last.max(o.last);
        self.records.extend(o.records);
    }
}

/// The name of a gRPC status code as in the gRPC spec (`UNIMPLEMENTED`, ...).
fn code_name(code: tonic::Code) -> &'static str {
    use tonic::Code;
    match code {
        Code::Ok => "OK",
        Code::Cancelled => "CANCELLED",
        Code::Unknown => "UNKNOWN",
        Code::InvalidArgument => "INVALID_ARGUMENT",
        Code::DeadlineExceeded => "DEADLINE_EXCEEDED",
        Code::NotFound => "NOT_FOUND",
        Code::AlreadyExists => "ALREADY_EXISTS",
        Code::PermissionDenied => "PERMISSION_DENIED",
        Code::ResourceExhausted => "RESOURCE_EXHAUSTED",
        Code::FailedPrecondition => "FAILED_PRECONDITION",
        Code::Aborted => "ABORTED",
        Code::OutOfRange => "OUT_OF_RANGE",
        Code::Unimplemented => "UNIMPLEMENTED",
        Code::Internal => "INTERNAL",
        Code::Unavailable => "UNAVAILABLE",
        Code::DataLoss => "DATA_LOSS",
        Code::Unauthenticated => "UNAUTHENTICATED",
    }
}

/// Why a request failed: a gRPC status, or an answer that does not match the request.
enum Failure {
    Status(tonic::Status),
    BadResponse,
}

impl From<tonic::Status> for Failure {
    fn from(s: tonic::Status) -> Self {
        Failure::Status(s)
    }
}

/// A task's open QueryStream.
struct OpenStream {
    tx: tokio::sync::mpsc::Sender<pb::QueryRequest>,
    rx: tonic::Streaming<pb::QueryResponse>,
}

/// One client task: its client, its stream and what it asks.
struct Task<'a> {
    plan: &'a Plan,
    client: SublevelClient<Channel>,
    stream: Option<OpenStream>,
    picker: OpPicker,
    /// The K DISTANCE pairs of a batch.
    batch: Vec<pb::QueryPair>,
    /// The same K pairs in columns.
    columns: pb::PairColumns,
    /// The K planner queries in columns.
    stream_columns: pb::PairColumns,
    /// The K planner queries of a stream step.
    queries: Vec<pb::PlannerQuery>,
}

/// The distance of an answer (0 for an empty oneof, flagged by the caller's count check).
fn answer_distance(a: &pb::QueryAnswer) -> Option<f64> {
    match a.answer.as_ref()? {
        pb::query_answer::Answer::Distance(d) => Some(d.distance),
        pb::query_answer::Answer::Collide(c) => Some(c.distance),
        pb::query_answer::Answer::Growth(_) => None,
    }
}

impl<'a> Task<'a> {
    fn new(plan: &'a Plan, channel: Channel, task: usize) -> Self {
        let kind = match plan.stream_query {
            StreamQuery::Distance => pb::QueryKind::Distance,
            StreamQuery::Collide => pb::QueryKind::Collide,
        };
        let margin = if plan.stream_query == StreamQuery::Collide { plan.margin } else { 0.0 };
        let batch = plan
            .seconds
            .iter()
            .map(|h| pb::QueryPair {
                kind: pb::QueryKind::Distance as i32,
                first: plan.chair.clone(),
                second: h.clone(),
                ..Default::default()
            })
            .collect();
        // Columns: instance 0 is the chair, then each distinct second instance once.
        let mut instance_ids = vec![plan.chair.clone()];
        let mut second = Vec::with_capacity(plan.seconds.len());
        for h in &plan.seconds {
            let index = match instance_ids.iter().position(|id| id == h) {
                Some(i) => i,
                None => {
                    instance_ids.push(h.clone());
                    instance_ids.len() - 1
                }
            };
            second.push(index as u32);
        }
        let columns = pb::PairColumns {
            kind: pb::QueryKind::Distance as i32,
            instance_ids,
            first: vec![0; second.len()],
            second,
            margin: 0.0,
        };
        let stream_columns = pb::PairColumns { kind: kind as i32, margin, ..columns.clone() };
        let queries = plan
            .seconds
            .iter()
            .map(|h| pb::PlannerQuery {
                kind: kind as i32,
                first: plan.chair.clone(),
                second: h.clone(),
                margin,
                ..Default::default()
            })
            .collect();
        Self {
            plan,
            client: SublevelClient::new(channel),
            stream: None,
            picker: OpPicker::new(plan.scenario, task),
            batch,
            columns,
            stream_columns,
            queries,
        }
    }

    /// Sends one request of kind `op`; returns the distances answered (one per pair asked) and,
    /// when recording, the record.
    async fn request(&mut self, op: Op, record: Option<&mut Record>) -> std::result::Result<usize, Failure> {
        let plan = self.plan;
        match op {
            Op::Unary => {
                let j = self.picker.next_unary_pair(plan.pairs);
                let req = pb::DistanceRequest {
                    scene_id: plan.scene.clone(),
                    instance_a: plan.chair.clone(),
                    instance_b: plan.seconds[j].clone(),
                    ..Default::default()
                };
                let answer = self.client.distance(req).await?.into_inner().answer.ok_or(Failure::BadResponse)?;
                if let Some(r) = record {
                    r.pairs.push(j);
                    r.distances.push(answer.distance);
                }
                Ok(1)
            }
            Op::Batch => {
                if plan.columns {
                    let req = pb::BatchQueryRequest {
                        scene_id: plan.scene.clone(),
                        pairs: Vec::new(),
                        columns: Some(self.columns.clone()),
                    };
                    let c = self.client.batch_query(req).await?.into_inner().columns.ok_or(Failure::BadResponse)?;
                    return self.check_columns(&c, record);
                }
                let req =
                    pb::BatchQueryRequest { scene_id: plan.scene.clone(), pairs: self.batch.clone(), columns: None };
                let answers = self.client.batch_query(req).await?.into_inner().answers;
                self.check(&answers, record)
            }
            Op::Stream => {
                let step = self.picker.next_step();
                let chair = chair_pose(self.picker.task, plan.tasks, step);
                let req = pb::QueryRequest {
                    scene_id: plan.scene.clone(),
                    poses: vec![pb::InstancePose { instance_id: plan.chair.clone(), pose: Some(proto_pose(&chair)) }],
                    queries: if plan.columns { Vec::new() } else { self.queries.clone() },
                    states: Vec::new(),
                    request_id: step,
                    columns: plan.columns.then(|| self.stream_columns.clone()),
                };
                let resp = self.stream_step(req).await?;
                if resp.request_id != step || !resp.states.is_empty() {
                    return Err(Failure::BadResponse);
                }
                let mut record = record;
                if let Some(r) = record.as_mut() {
                    r.chair = Some(chair);
                }
                if plan.columns {
                    return self.check_columns(resp.columns.as_ref().ok_or(Failure::BadResponse)?, record);
                }
                self.check(&resp.answers, record)
            }
        }
    }

    /// Checks that one answer came per pair (and records the distances).
    fn check(&self, answers: &[pb::QueryAnswer], record: Option<&mut Record>) -> std::result::Result<usize, Failure> {
        if answers.len() != self.plan.pairs {
            return Err(Failure::BadResponse);
        }
        if let Some(r) = record {
            for (j, a) in answers.iter().enumerate() {
                r.pairs.push(j);
                r.distances.push(answer_distance(a).ok_or(Failure::BadResponse)?);
            }
        }
        Ok(answers.len())
    }

    /// Checks that every column has one entry per pair, every answer converged (and records the
    /// distances).
    fn check_columns(&self, c: &pb::AnswerColumns, record: Option<&mut Record>) -> std::result::Result<usize, Failure> {
        let k = self.plan.pairs;
        let lengths = [c.value.len(), c.converged.len(), c.overlapping.len(), c.lower_bound.len()];
        if lengths.iter().any(|&n| n != k) || c.point_a.len() != 3 * k || c.point_b.len() != 3 * k {
            return Err(Failure::BadResponse);
        }
        if let Some(r) = record {
            r.pairs.extend(0..k);
            r.distances.extend_from_slice(&c.value);
        }
        Ok(k)
    }

    /// Sends one request on the task's stream (opening it first if needed) and waits for its
    /// answer. A failed stream is dropped; the next step opens a new one.
    async fn stream_step(&mut self, req: pb::QueryRequest) -> std::result::Result<pb::QueryResponse, Failure> {
        if let Some(s) = self.stream.as_mut() {
            if s.tx.send(req).await.is_err() {
                self.stream = None;
                return Err(Failure::Status(tonic::Status::unavailable("the request stream closed")));
            }
            return match s.rx.message().await {
                Ok(Some(m)) => Ok(m),
                Ok(None) => {
                    self.stream = None;
                    Err(Failure::Status(tonic::Status::aborted("the server ended the stream")))
                }
                Err(e) => {
                    self.stream = None;
                    Err(Failure::Status(e))
                }
            };
        }
        // The first request is queued before the call, so a server that waits for it before
        // sending its headers is served too.
        let (tx, rx) = tokio::sync::mpsc::channel(4);
        tx.send(req).await.map_err(|_| Failure::BadResponse)?;
        let mut inbound = self.client.query_stream(tokio_stream::wrappers::ReceiverStream::new(rx)).await?.into_inner();
        let first =
            inbound.message().await?.ok_or(Failure::Status(tonic::Status::aborted("the server ended the stream")))?;
        self.stream = Some(OpenStream { tx, rx: inbound });
        Ok(first)
    }
}

/// One client task's thread: connects, waits for every task, then sends until the end.
fn worker(plan: &Plan, task: usize) -> Result<Tally> {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    runtime.block_on(async {
        let channel = match &plan.shared {
            Some(c) => Ok(c.clone()),
            None => connect(&plan.endpoint).await,
        };
        // Every task passes the barrier, connected or not, so that none waits forever.
        plan.ready.wait();
        let start = *plan.start.get_or_init(Instant::now);
        let mut t = Task::new(plan, channel?, task);
        Ok(drive(&mut t, start).await)
    })
}

async fn drive(t: &mut Task<'_>, start: Instant) -> Tally {
    let plan = t.plan;
    let end = start + plan.duration;
    let mut tally = Tally::new();
    loop {
        let now = Instant::now();
        if now >= end {
            break;
        }
        let n = plan.next.fetch_add(1, Ordering::Relaxed);
        if plan.cap.is_some_and(|cap| n >= cap) {
            break;
        }
        let sent_from = match plan.rate {
            None => now,
            Some(rate) => {
                let scheduled = start + Duration::from_secs_f64(n as f64 / rate);
                if scheduled >= end {
                    break;
                }
                let now = Instant::now();
                if scheduled > now {
                    // A blocking sleep: this thread runs nothing else meanwhile, and a thread sleep
                    // is finer than tokio's millisecond timer.
                    std::thread::sleep(scheduled - now);
                }
                tally.lag.saturating_record(micros(Instant::now().saturating_duration_since(scheduled)));
                scheduled
            }
        };
        let op = t.picker.next();
        let mut record = plan.record.then(|| Record { chair: None, pairs: Vec::new(), distances: Vec::new() });
        let outcome = tokio::time::timeout(REQUEST_TIMEOUT, t.request(op, record.as_mut())).await;
        let done = Instant::now();
        tally.last = Some(done);
        match outcome {
            Ok(Ok(answered)) => {
                let us = micros(done.saturating_duration_since(sent_from));
                tally.all.saturating_record(us);
                tally.by_op[op as usize].saturating_record(us);
                tally.requests[op as usize] += 1;
                tally.pair_queries[op as usize] += answered as u64;
                tally.records.extend(record);
            }
            Ok(Err(Failure::Status(s))) => tally.error(code_name(s.code())),
            Ok(Err(Failure::BadResponse)) => tally.error("BAD_RESPONSE"),
            Err(_) => {
                t.stream = None;
                tally.error("DEADLINE_EXCEEDED");
            }
        }
    }
    tally
}

// ---------------------------------------------------------------------------------------------
// The run
// ---------------------------------------------------------------------------------------------

/// Latency and counts of a set of requests.
#[derive(Clone, Debug)]
struct Figures {
    requests: u64,
    pair_queries: u64,
    p50_us: u64,
    p90_us: u64,
    p99_us: u64,
    p999_us: u64,
    max_us: u64,
    mean_us: f64,
}

impl Figures {
    fn new(h: &Histogram<u64>, requests: u64, pair_queries: u64) -> Self {
        let q = |x: f64| if h.is_empty() { 0 } else { h.value_at_quantile(x) };
        Self {
            requests,
            pair_queries,
            p50_us: q(0.5),
            p90_us: q(0.9),
            p99_us: q(0.99),
            p999_us: q(0.999),
            max_us: if h.is_empty() { 0 } else { h.max() },
            mean_us: if h.is_empty() { 0.0 } else { h.mean() },
        }
    }
}

/// The figures of one run.
#[derive(Clone, Debug)]
struct Report {
    scenario: Scenario,
    addr: String,
    concurrency: usize,
    shared_channel: bool,
    pairs_per_request: usize,
    rate: Option<f64>,
    stream_query: StreamQuery,
    columns: bool,
    duration_s: f64,
    overall: Figures,
    /// Requests of each kind (mixed), in [`OPS`] order.
    by_op: Vec<(Op, Figures)>,
    histogram_count: u64,
    errors: BTreeMap<String, u64>,
    send_lag: Option<(u64, u64)>,
    unsent: u64,
    in_process: Option<InProcess>,
}

/// The single-threaded in-process throughput of the same queries.
#[derive(Clone, Copy, Debug)]
struct InProcess {
    pair_queries_per_s: f64,
    seconds: f64,
}

/// A run's report and, when asked for, every answer.
#[derive(Debug)]
struct Outcome {
    report: Report,
    /// Every answered request when recording (the tests check them against a local catalog).
    #[cfg_attr(not(test), allow(dead_code))]
    records: Vec<Record>,
    /// Where the bodies stood.
    #[cfg_attr(not(test), allow(dead_code))]
    layout: Layout,
}

impl Report {
    fn requests_per_s(&self) -> f64 {
        self.overall.requests as f64 / self.duration_s.max(1e-9)
    }

    fn pair_queries_per_s(&self) -> f64 {
        self.overall.pair_queries as f64 / self.duration_s.max(1e-9)
    }

    fn ratio(&self) -> Option<f64> {
        self.in_process.map(|p| self.pair_queries_per_s() / p.pair_queries_per_s)
    }

    fn text(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let lane = if self.shared_channel { "one shared connection" } else { "one connection per task" };
        let mode = match self.rate {
            Some(r) => format!("open loop at {r} requests/s"),
            None => "closed loop".to_owned(),
        };
        let mut kind = match (self.scenario, self.stream_query) {
            (Scenario::Stream | Scenario::Mixed, StreamQuery::Collide) => ", stream queries COLLIDE",
            _ => "",
        }
        .to_owned();
        if self.columns && self.scenario != Scenario::Unary {
            kind.push_str(", in columns");
        }
        let _ = writeln!(
            s,
            "loadtest {}: {}, concurrency {} ({lane}), {} pairs/request{kind}, {:.2} s, {}",
            self.scenario.name(),
            mode,
            self.concurrency,
            self.pairs_per_request,
            self.duration_s,
            self.addr
        );
        let f = &self.overall;
        let _ = writeln!(
            s,
            "  requests      {:>10}  {:>12.1} /s\n  pair queries  {:>10}  {:>12.1} /s",
            f.requests,
            self.requests_per_s(),
            f.pair_queries,
            self.pair_queries_per_s()
        );
        let _ = writeln!(s, "  latency [µs]  {}", latency_line(f));
        for (op, f) in &self.by_op {
            let _ = writeln!(s, "    {:<9}   {}  ({} requests)", op.name(), latency_line(f), f.requests);
        }
        if let Some((p50, p99)) = self.send_lag {
            let _ = writeln!(
                s,
                "  send lag [µs] p50 {p50}  p99 {p99}  (included in the latencies); unsent {}",
                self.unsent
            );
        }
        let errors = if self.errors.is_empty() {
            "none".to_owned()
        } else {
            self.errors.iter().map(|(c, n)| format!("{c} {n}")).collect::<Vec<_>>().join(", ")
        };
        let _ = writeln!(s, "  errors        {errors}");
        match (self.in_process, self.ratio()) {
            (Some(p), Some(r)) => {
                let _ = writeln!(
                    s,
                    "  in-process    {:.1} pair queries/s (Catalog, one thread, {:.1} s); gRPC / in-process = {:.3}",
                    p.pair_queries_per_s, p.seconds, r
                );
            }
            _ => {
                let _ = writeln!(s, "  in-process    skipped");
            }
        }
        s
    }

    fn json(&self) -> serde_json::Value {
        let fig = |f: &Figures| {
            serde_json::json!({
                "requests": f.requests,
                "pair_queries": f.pair_queries,
                "p50_us": f.p50_us,
                "p90_us": f.p90_us,
                "p99_us": f.p99_us,
                "p999_us": f.p999_us,
                "max_us": f.max_us,
                "mean_us": f.mean_us,
            })
        };
        let mut v = fig(&self.overall);
        let o = v.as_object_mut().expect("an object");
        o.insert("scenario".into(), self.scenario.name().into());
        o.insert("requests_per_s".into(), self.requests_per_s().into());
        o.insert("pair_queries_per_s".into(), self.pair_queries_per_s().into());
        o.insert("errors".into(), serde_json::to_value(&self.errors).unwrap_or_default());
        o.insert("concurrency".into(), self.concurrency.into());
        o.insert("duration_s".into(), self.duration_s.into());
        o.insert("pairs_per_request".into(), self.pairs_per_request.into());
        o.insert("histogram_count".into(), self.histogram_count.into());
        o.insert("rate".into(), self.rate.into());
        o.insert("shared_channel".into(), self.shared_channel.into());
        o.insert("columns".into(), self.columns.into());
        o.insert(
            "stream_query".into(),
            match self.stream_query {
                StreamQuery::Distance => "distance",
                StreamQuery::Collide => "collide",
            }
            .into(),
        );
        o.insert("in_process_pair_queries_per_s".into(), self.in_process.map(|p| p.pair_queries_per_s).into());
        o.insert("grpc_over_in_process".into(), self.ratio().into());
        if let Some((p50, p99)) = self.send_lag {
            o.insert("send_lag_p50_us".into(), p50.into());
            o.insert("send_lag_p99_us".into(), p99.into());
            o.insert("unsent".into(), self.unsent.into());
        }
        if !self.by_op.is_empty() {
            let by: serde_json::Map<String, serde_json::Value> =
                self.by_op.iter().map(|(op, f)| (op.name().to_owned(), fig(f))).collect();
            o.insert("by_operation".into(), by.into());
        }
        v
    }
}

fn latency_line(f: &Figures) -> String {
    format!(
        "p50 {}  p90 {}  p99 {}  p99.9 {}  max {}  (mean {:.1})",
        f.p50_us, f.p90_us, f.p99_us, f.p999_us, f.max_us, f.mean_us
    )
}

/// Sets up, runs the load, tears down, then measures in process. With `record`, every answer
/// is kept in [`Outcome::records`].
fn execute(args: &LoadtestArgs, record: bool) -> Result<Outcome> {
    check_args(args)?;
    let layout = Layout::new(args.pairs)?;
    let endpoint = endpoint(&args.addr)?;
    // Drives the set-up client and, with --shared-channel, the shared connection while the
    // tasks run on their own threads.
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build()?;
    let channel = runtime.block_on(connect(&endpoint))?;
    let mut admin = SublevelClient::new(channel.clone());
    let mut remote = Remote::default();
    let loaded = match runtime.block_on(setup(&mut admin, &layout, &mut remote)) {
        Ok(()) => Ok(load(args, &layout, &remote, endpoint, args.shared_channel.then(|| channel.clone()), record)),
        Err(e) => Err(e),
    };
    runtime.block_on(teardown(&mut admin, &remote));
    let (mut tally, duration_s) = loaded??;
    drop(runtime);

    let in_process = if args.in_process_seconds > 0.0 {
        Some(in_process(args, &layout, Duration::from_secs_f64(args.in_process_seconds))?)
    } else {
        None
    };
    let requests: u64 = tally.requests.iter().sum();
    let pair_queries: u64 = tally.pair_queries.iter().sum();
    let by_op = if args.scenario == Scenario::Mixed {
        OPS.iter()
            .map(|&op| {
                (
                    op,
                    Figures::new(
                        &tally.by_op[op as usize],
                        tally.requests[op as usize],
                        tally.pair_queries[op as usize],
                    ),
                )
            })
            .collect()
    } else {
        Vec::new()
    };
    let report = Report {
        scenario: args.scenario,
        addr: args.addr.clone(),
        concurrency: args.concurrency,
        shared_channel: args.shared_channel,
        pairs_per_request: args.pairs,
        rate: args.rate,
        stream_query: args.stream_query,
        columns: args.columns,
        duration_s,
        overall: Figures::new(&tally.all, requests, pair_queries),
        by_op,
        histogram_count: tally.all.len(),
        errors: std::mem::take(&mut tally.errors),
        send_lag: args.rate.map(|_| {
            let f = Figures::new(&tally.lag, 0, 0);
            (f.p50_us, f.p99_us)
        }),
        unsent: tally.unsent,
        in_process,
    };
    Ok(Outcome { report, records: tally.records, layout })
}

/// Runs the client tasks on their threads; returns their merged tally and the measured duration
/// (seconds from the common start to the last answer).
fn load(
    args: &LoadtestArgs,
    layout: &Layout,
    remote: &Remote,
    endpoint: Endpoint,
    shared: Option<Channel>,
    record: bool,
) -> Result<(Tally, f64)> {
    let plan = Plan {
        scenario: args.scenario,
        tasks: args.concurrency,
        pairs: args.pairs,
        rate: args.rate,
        cap: args.requests,
        duration: Duration::from_secs_f64(args.duration),
        stream_query: args.stream_query,
        margin: args.margin,
        record,
        columns: args.columns,
        scene: remote.scene.clone().unwrap_or_default(),
        chair: remote.chair.clone(),
        seconds: layout.pair_humans.iter().map(|&h| remote.humans[h].clone()).collect(),
        endpoint,
        shared,
        next: AtomicU64::new(0),
        start: OnceLock::new(),
        ready: Barrier::new(args.concurrency),
    };
    let results: Vec<Result<Tally>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..args.concurrency)
            .map(|task| {
                let plan = &plan;
                std::thread::Builder::new()
                    .name(format!("loadtest-{task}"))
                    .spawn_scoped(scope, move || worker(plan, task))
                    .map_err(Error::Io)
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h?.join().unwrap_or_else(|_| Err(Error::Numerical("a load-test task panicked".into()))))
            .collect()
    });
    let mut tally = Tally::new();
    for r in results {
        tally.merge(r?);
    }
    let start = plan.start.get().copied().unwrap_or_else(Instant::now);
    let duration_s = tally.last.map_or(0.0, |l| l.saturating_duration_since(start).as_secs_f64());
    if let Some(rate) = args.rate {
        // Scheduled before the end (and within the cap) but never sent: the load was more than
        // the client and server could carry.
        let scheduled = ((args.duration * rate).ceil() as u64).min(args.requests.unwrap_or(u64::MAX));
        let sent = tally.requests.iter().sum::<u64>() + tally.errors.values().sum::<u64>();
        tally.unsent = scheduled.saturating_sub(sent);
    }
    Ok((tally, duration_s))
}

// ---------------------------------------------------------------------------------------------
// The same queries in process
// ---------------------------------------------------------------------------------------------

/// A catalog in a temporary directory holding the load test's scene, deleted on drop.
struct LocalScene {
    catalog: Option<Catalog>,
    dir: PathBuf,
    scene: String,
    chair: String,
    humans: Vec<String>,
}

impl Drop for LocalScene {
    fn drop(&mut self) {
        self.catalog = None;
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

impl LocalScene {
    fn new(layout: &Layout) -> Result<Self> {
        let dir = std::env::temp_dir().join(format!(
            "sublevel-loadtest-{}-{:016x}",
            std::process::id(),
            rand::random::<u64>()
        ));
        std::fs::create_dir_all(&dir)?;
        let mut local = LocalScene {
            catalog: None,
            dir: dir.clone(),
            scene: String::new(),
            chair: String::new(),
            humans: Vec::new(),
        };
        let catalog = Catalog::open(Box::new(RedbStore::open_dir(&dir)?), NewtonParams::default())?;
        let chair_body = catalog.add_body("chair_101", demo_body("chair_101", CHAIR_JSON)?)?;
        let human_body = catalog.add_body("human_10", demo_body("human_10", HUMAN_JSON)?)?;
        local.scene = catalog.create_scene("loadtest")?;
        local.chair = catalog.add_instance(&local.scene, &chair_body, isometry(&CHAIR_HOME)?)?;
        for h in &layout.humans {
            local.humans.push(catalog.add_instance(&local.scene, &human_body, isometry(h)?)?);
        }
        local.catalog = Some(catalog);
        Ok(local)
    }

    fn catalog(&self) -> &Catalog {
        self.catalog.as_ref().expect("open until dropped")
    }

    fn pair(&self, layout: &Layout, j: usize, kind: QueryKind, margin: f64) -> QueryPair {
        QueryPair {
            kind,
            first: self.chair.clone(),
            second: self.humans[layout.pair_humans[j]].clone(),
            options: QueryOptions::default(),
            margin,
        }
    }
}

/// Pair queries per second of the scenario's requests run on a [`Catalog`] in this process, on
/// this thread, for about `seconds`.
fn in_process(args: &LoadtestArgs, layout: &Layout, seconds: Duration) -> Result<InProcess> {
    let local = LocalScene::new(layout)?;
    let catalog = local.catalog();
    let k = args.pairs;
    let batch: Vec<QueryPair> = (0..k).map(|j| local.pair(layout, j, QueryKind::Distance, 0.0)).collect();
    let (kind, margin) = match args.stream_query {
        StreamQuery::Distance => (QueryKind::Distance, 0.0),
        StreamQuery::Collide => (QueryKind::Collide, args.margin),
    };
    let queries: Vec<QueryPair> = (0..k).map(|j| local.pair(layout, j, kind, margin)).collect();
    // The columns form (distinct ids, repeats allowed: the in-process cost does not depend on it).
    let column_ids: Vec<String> =
        std::iter::once(batch[0].first.clone()).chain(batch.iter().map(|q| q.second.clone())).collect();
    let mut view = QueryView::new(&local.scene);
    let mut picker = OpPicker::new(args.scenario, 0);
    let mut pairs = 0u64;
    let start = Instant::now();
    while start.elapsed() < seconds {
        match picker.next() {
            Op::Unary => {
                let j = picker.next_unary_pair(k);
                let q = &batch[j];
                catalog.distance(&local.scene, &q.first, &q.second)?;
                pairs += 1;
            }
            Op::Batch if args.columns => {
                let (first, second): (Vec<u32>, Vec<u32>) = (0..k as u32).map(|j| (0, j + 1)).unzip();
                let answers = catalog.batch_columns(
                    &local.scene,
                    &column_ids,
                    (&first, &second),
                    QueryKind::Distance,
                    Default::default(),
                    0.0,
                )?;
                pairs += answers.len() as u64;
            }
            Op::Batch => pairs += catalog.batch(&local.scene, &batch)?.len() as u64,
            Op::Stream => {
                let step = picker.next_step();
                let request = PlannerRequest {
                    poses: vec![(local.chair.clone(), isometry(&chair_pose(0, 1, step))?)],
                    queries: queries.clone(),
                    states: Vec::new(),
                };
                pairs += match view.run(catalog, &request)? {
                    sublevel::scene::planner::PlannerAnswers::Single(a) => a.len() as u64,
                    sublevel::scene::planner::PlannerAnswers::PerState(s) => {
                        s.iter().map(Vec::len).sum::<usize>() as u64
                    }
                };
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    Ok(InProcess { pair_queries_per_s: pairs as f64 / seconds, seconds })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(addr: &str, scenario: Scenario) -> LoadtestArgs {
        LoadtestArgs {
            addr: addr.to_owned(),
            scenario,
            concurrency: 2,
            duration: 1.0,
            requests: None,
            rate: None,
            pairs: 20,
            stream_query: StreamQuery::Distance,
            margin: 0.05,
            shared_channel: false,
            columns: false,
            in_process_seconds: 0.1,
            json: None,
        }
    }

    /// The largest |gRPC distance − in-process Catalog distance| and the smallest distance, over
    /// every recorded answer at the stored pose (unary, batch: K local answers, computed once) and
    /// the answers of at least 1000 stream states (all of them when fewer; each state's chair pose
    /// set on a fresh local catalog, an independent path from the server's stream view).
    fn max_deviation(outcome: &Outcome) -> (f64, f64) {
        let local = LocalScene::new(&outcome.layout).unwrap();
        let catalog = local.catalog();
        let distance = |j: usize| {
            let q = local.pair(&outcome.layout, j, QueryKind::Distance, 0.0);
            catalog.distance(&local.scene, &q.first, &q.second).unwrap().distance
        };
        let home: Vec<f64> = (0..outcome.layout.pair_humans.len()).map(distance).collect();
        let states = outcome.records.iter().filter(|r| r.chair.is_some()).count();
        let stride = (states / 1000).max(1);
        let (mut worst, mut nearest) = (0.0f64, f64::INFINITY);
        let mut compare = |d: f64, expected: f64| {
            nearest = nearest.min(expected);
            worst = worst.max((d - expected).abs());
        };
        for r in &outcome.records {
            assert_eq!(r.pairs.len(), r.distances.len());
            if r.chair.is_none() {
                r.pairs.iter().zip(&r.distances).for_each(|(&j, &d)| compare(d, home[j]));
            }
        }
        for r in outcome.records.iter().filter(|r| r.chair.is_some()).step_by(stride) {
            let chair = isometry(r.chair.as_ref().unwrap()).unwrap();
            catalog.set_poses(&local.scene, &[(local.chair.clone(), chair)]).unwrap();
            r.pairs.iter().zip(&r.distances).for_each(|(&j, &d)| compare(d, distance(j)));
        }
        (worst, nearest)
    }

    #[test]
    fn every_scenario_answers_every_pair_like_the_catalog() {
        let dir = tempfile::tempdir().unwrap();
        let server = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
        let listener = server.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let config = sublevel::service::ServerConfig { data_dir: dir.path().to_path_buf(), ..Default::default() };
        let handle = server.spawn(sublevel::service::serve(listener, config, async move {
            let _ = stopped.await;
        }));

        for scenario in [Scenario::Unary, Scenario::Batch, Scenario::Stream, Scenario::Mixed] {
            let t0 = Instant::now();
            let outcome = execute(&args(&addr, scenario), true).unwrap();
            let ran = t0.elapsed();
            let r = &outcome.report;
            let name = scenario.name();
            assert!(r.errors.is_empty(), "{name}: errors {:?}", r.errors);
            let f = &r.overall;
            assert!(f.requests > 10, "{name}: only {} requests", f.requests);
            // One pair per unary request, K per batch or stream request.
            let by_kind = |op: Op| {
                outcome.records.iter().filter(|x| x.pairs.len() == if op == Op::Unary { 1 } else { 20 }).count() as u64
            };
            assert_eq!(outcome.records.len() as u64, f.requests, "{name}");
            assert_eq!(f.pair_queries, by_kind(Op::Unary) + 20 * by_kind(Op::Batch), "{name}");
            if scenario != Scenario::Unary && scenario != Scenario::Mixed {
                assert_eq!(f.pair_queries, 20 * f.requests, "{name}");
            }
            assert_eq!(r.histogram_count, f.requests, "{name}");
            assert!(f.p50_us <= f.p90_us && f.p90_us <= f.p99_us && f.p99_us <= f.p999_us && f.p999_us <= f.max_us);
            assert!(f.p50_us > 0);
            assert!(r.duration_s > 0.9 && r.duration_s < 2.5, "{name}: {} s", r.duration_s);
            assert!(r.in_process.is_some_and(|p| p.pair_queries_per_s > 0.0));
            let (worst, nearest) = max_deviation(&outcome);
            assert!(nearest > 0.05, "{name}: every pair should stay separated, nearest {nearest} m");
            assert!(worst <= 1e-9, "{name}: a gRPC distance differs from the Catalog's by {worst:e}");
            let json = r.json();
            for key in [
                "scenario",
                "p50_us",
                "p90_us",
                "p99_us",
                "p999_us",
                "max_us",
                "requests_per_s",
                "pair_queries_per_s",
                "errors",
                "concurrency",
                "duration_s",
                "pairs_per_request",
            ] {
                assert!(json.get(key).is_some(), "{name}: JSON lacks {key}");
            }
            eprintln!(
                "{name}: {} requests, {} pairs, nearest pair {nearest:.3} m, largest deviation {worst:.1e} m, run {:.2} s, checked in {:.2} s",
                f.requests,
                f.pair_queries,
                ran.as_secs_f64(),
                t0.elapsed().as_secs_f64()
            );
        }

        // Open loop: a bounded timetable, every request sent and answered.
        let mut open = args(&addr, Scenario::Stream);
        open.rate = Some(200.0);
        open.duration = 0.5;
        open.requests = Some(60);
        open.in_process_seconds = 0.0;
        let outcome = execute(&open, false).unwrap();
        let r = &outcome.report;
        assert!(r.errors.is_empty(), "open loop: {:?}", r.errors);
        assert_eq!(r.overall.requests, 60);
        assert_eq!(r.unsent, 0);
        assert!(r.send_lag.is_some() && r.in_process.is_none());
        // 60 requests at 200/s take 0.3 s of timetable.
        assert!(r.duration_s > 0.25 && r.duration_s < 1.0, "{} s", r.duration_s);

        // Nothing of the load test is left on the server.
        let left = server.block_on(async {
            let mut c = SublevelClient::connect(format!("http://{addr}")).await.unwrap();
            let scenes = c.list_scenes(pb::ListScenesRequest::default()).await.unwrap().into_inner().scenes.len();
            let bodies = c.list_bodies(pb::ListBodiesRequest::default()).await.unwrap().into_inner().bodies.len();
            (scenes, bodies)
        });
        assert_eq!(left, (0, 0));
        stop.send(()).unwrap();
        server.block_on(handle).unwrap().unwrap();
    }

    #[test]
    fn arguments_are_checked() {
        let mut a = args("127.0.0.1:1", Scenario::Unary);
        a.concurrency = 0;
        assert!(execute(&a, false).unwrap_err().to_string().contains("--concurrency"));
        let mut a = args("127.0.0.1:1", Scenario::Unary);
        a.rate = Some(0.0);
        assert!(execute(&a, false).unwrap_err().to_string().contains("--rate"));
        // Nothing listens on port 1: a connection error, not a hang.
        let a = args("127.0.0.1:1", Scenario::Unary);
        assert!(execute(&a, false).is_err());
    }

    #[test]
    fn the_chair_path_is_smooth_and_closed() {
        let a = chair_pose(0, 1, 0);
        let b = chair_pose(0, 1, PATH_STEPS);
        assert!((a.1[0] - b.1[0]).abs() < 1e-12);
        for step in 0..PATH_STEPS {
            let (p, q) = (chair_pose(1, 3, step), chair_pose(1, 3, step + 1));
            let dt = ((p.1[0] - q.1[0]).powi(2) + (p.1[1] - q.1[1]).powi(2)).sqrt();
            assert!(dt < 1e-3, "step {step}: {dt} m");
            let norm: f64 = p.0.iter().map(|x| x * x).sum();
            assert!((norm - 1.0).abs() < 1e-12);
        }
    }
}
