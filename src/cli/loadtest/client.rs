//! The client side of the load test: connecting, setting up and tearing down the server's
//! scene, and the client tasks that send the requests and time them.

use super::report::{code_name, micros, Tally};
use super::scene::{chair_pose, proto_pose, Layout, Op, OpPicker, Parts, CHAIR_HOME, CHAIR_JSON, HUMAN_JSON};
use super::{Scenario, StreamQuery, REQUEST_TIMEOUT};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Barrier, OnceLock};
use std::time::{Duration, Instant};
use sublevel::service::pb::{self, sublevel_client::SublevelClient};
use sublevel::service::scene_request;
use sublevel::{Error, Result};
use tonic::transport::{Channel, Endpoint};

/// Ids of what the load test created on the server.
#[derive(Clone, Debug, Default)]
pub(super) struct Remote {
    pub(super) bodies: Vec<String>,
    pub(super) scene: Option<String>,
    pub(super) chair: String,
    pub(super) humans: Vec<String>,
}

/// `addr` as a URI (`http://` added when it has no scheme).
fn uri(addr: &str) -> String {
    if addr.starts_with("http://") || addr.starts_with("https://") {
        addr.to_owned()
    } else {
        format!("http://{addr}")
    }
}

/// The endpoint of `--addr` (TCP_NODELAY, 5 s connect timeout).
pub(crate) fn endpoint(addr: &str) -> Result<Endpoint> {
    let e = Endpoint::from_shared(uri(addr)).map_err(|e| Error::invalid("--addr", e.to_string()))?;
    Ok(e.tcp_nodelay(true).connect_timeout(Duration::from_secs(5)))
}

/// A client-side failure as the crate's [`Error::Io`].
fn io_error(what: &str, e: impl std::fmt::Display) -> Error {
    Error::Io(std::io::Error::other(format!("{what}: {e}")))
}

/// Connects to `endpoint`; the error names every cause.
pub(crate) async fn connect(endpoint: &Endpoint) -> Result<Channel> {
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

/// One set-up or tear-down call with the request timeout; the error names the call.
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
pub(super) async fn setup(client: &mut SublevelClient<Channel>, layout: &Layout, remote: &mut Remote) -> Result<()> {
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
    remote.chair = call("AddInstance", client.add_instance(scene_request(&scene, add(&body_ids[0], &CHAIR_HOME))))
        .await?
        .into_inner()
        .instance_id;
    for h in &layout.humans {
        let id = call("AddInstance", client.add_instance(scene_request(&scene, add(&body_ids[1], h))))
            .await?
            .into_inner()
            .instance_id;
        remote.humans.push(id);
    }
    Ok(())
}

/// Deletes the scene, then the bodies; failures are printed on stderr (the run's figures stand).
pub(super) async fn teardown(client: &mut SublevelClient<Channel>, remote: &Remote) {
    if let Some(scene) = &remote.scene {
        let req = scene_request(scene, pb::DeleteSceneRequest { scene_id: scene.clone() });
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

/// One answered request, kept for checking (tests).
#[derive(Clone, Debug)]
pub(super) struct Record {
    /// The chair's pose in the request's view (stream steps); `None`: the stored pose.
    pub(super) chair: Option<Parts>,
    /// Pair indices asked, in order.
    pub(super) pairs: Vec<usize>,
    /// The distances answered, in order (for COLLIDE: the CollideAnswer's distance).
    pub(super) distances: Vec<f64>,
}

/// What every task shares (read-only but for the request counter).
pub(super) struct Plan {
    pub(super) scenario: Scenario,
    pub(super) tasks: usize,
    pub(super) pairs: usize,
    pub(super) rate: Option<f64>,
    pub(super) cap: Option<u64>,
    pub(super) duration: Duration,
    pub(super) stream_query: StreamQuery,
    pub(super) margin: f64,
    pub(super) record: bool,
    pub(super) columns: bool,
    pub(super) scene: String,
    pub(super) chair: String,
    /// The second instance of every pair.
    pub(super) seconds: Vec<String>,
    pub(super) endpoint: Endpoint,
    pub(super) shared: Option<Channel>,
    /// Next request slot (over all tasks).
    pub(super) next: AtomicU64,
    pub(super) start: OnceLock<Instant>,
    pub(super) ready: Barrier,
}

/// Why a request failed: a gRPC status, or an answer that does not match the request.
enum Failure {
    /// The server's (or the transport's) status.
    Status(tonic::Status),
    /// An answer count or request id that does not match the request.
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
            cold: false,
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
                let answer = self
                    .client
                    .distance(scene_request(&plan.scene, req))
                    .await?
                    .into_inner()
                    .answer
                    .ok_or(Failure::BadResponse)?;
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
                    let c = self
                        .client
                        .batch_query(scene_request(&plan.scene, req))
                        .await?
                        .into_inner()
                        .columns
                        .ok_or(Failure::BadResponse)?;
                    return self.check_columns(&c, record);
                }
                let req =
                    pb::BatchQueryRequest { scene_id: plan.scene.clone(), pairs: self.batch.clone(), columns: None };
                let answers = self.client.batch_query(scene_request(&plan.scene, req)).await?.into_inner().answers;
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
                    ..Default::default()
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
        let outbound = scene_request(&self.plan.scene, tokio_stream::wrappers::ReceiverStream::new(rx));
        let mut inbound = self.client.query_stream(outbound).await?.into_inner();
        let first =
            inbound.message().await?.ok_or(Failure::Status(tonic::Status::aborted("the server ended the stream")))?;
        self.stream = Some(OpenStream { tx, rx: inbound });
        Ok(first)
    }
}

/// One client task's thread: connects, waits for every task, then sends until the end.
pub(super) fn worker(plan: &Plan, task: usize) -> Result<Tally> {
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

/// Sends the task's requests until the end (duration, request cap or timetable) and tallies them.
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
