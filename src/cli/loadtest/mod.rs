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
//! [`QueryView`](sublevel::scene::planner::QueryView) like the server's stream) on one thread for `--in-process-seconds` (default 1;
//! 0 skips it), and the ratio gRPC / in-process of pair queries per second is printed beside it
//! (the gRPC figure uses all client tasks and the server's threads, the in-process one a single
//! thread). `--json PATH` writes the same figures: `scenario`, `p50_us`, `p90_us`, `p99_us`,
//! `p999_us`, `max_us`, `mean_us`, `requests`, `requests_per_s`, `pair_queries`,
//! `pair_queries_per_s`, `errors` (status code → count), `concurrency`, `duration_s` (measured),
//! `pairs_per_request`, `rate` (null: closed loop), `shared_channel`, `columns`, `stream_query`,
//! `in_process_pair_queries_per_s`, `grpc_over_in_process`, and for the open loop `send_lag_p50_us`,
//! `send_lag_p99_us`, `unsent`; for `mixed` also `by_operation` (the same latency and count fields
//! per kind).
//!
//! # Files
//!
//! `scene.rs` where the bodies stand, the chair's path, the operation of each request; `client.rs`
//! connecting, set-up / tear-down and the client tasks; `report.rs` histograms, counts and the
//! report (text, JSON); `in_process.rs` the in-process comparison; `tests.rs` the tests against a
//! real server; this file the arguments and the run.

pub(crate) use client::{connect, endpoint};
use client::{setup, teardown, worker, Plan, Remote};
use in_process::in_process;
use report::{Figures, Outcome, Report, Tally};
use scene::{Layout, OPS};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicU64;
use std::sync::{Barrier, OnceLock};
use std::time::{Duration, Instant};
use sublevel::service::pb::sublevel_client::SublevelClient;
use sublevel::{Error, Result};
use tonic::transport::{Channel, Endpoint};

mod client;
mod in_process;
mod report;
mod scene;
#[cfg(test)]
mod tests;

/// Every request (and the set-up calls) time out after this long.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(30);

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
