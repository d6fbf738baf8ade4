//! Latency histograms (`hdrhistogram`, µs), counts and errors of a run, and its report as text
//! and JSON.

use super::client::Record;
use super::scene::{Layout, Op};
use super::{Scenario, StreamQuery};
use hdrhistogram::Histogram;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// An empty latency histogram.
fn new_histogram() -> Histogram<u64> {
    // 1 µs .. 1 h, 3 significant digits; larger values saturate.
    Histogram::new_with_bounds(1, 3_600_000_000, 3).expect("valid histogram bounds")
}

/// A duration in whole microseconds, at least 1.
pub(super) fn micros(d: Duration) -> u64 {
    (d.as_nanos().div_ceil(1000)).max(1) as u64
}

/// Counts and latencies of one task (merged over tasks afterwards).
pub(super) struct Tally {
    pub(super) all: Histogram<u64>,
    pub(super) by_op: [Histogram<u64>; 3],
    pub(super) lag: Histogram<u64>,
    pub(super) requests: [u64; 3],
    pub(super) pair_queries: [u64; 3],
    pub(super) errors: BTreeMap<String, u64>,
    /// Open loop: requests scheduled before the end but never sent (set after the merge).
    pub(super) unsent: u64,
    pub(super) last: Option<Instant>,
    pub(super) records: Vec<Record>,
}

impl Tally {
    /// An empty tally.
    pub(super) fn new() -> Self {
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

    /// Counts a failed request under `code`.
    pub(super) fn error(&mut self, code: &str) {
        *self.errors.entry(code.to_owned()).or_default() += 1;
    }

    /// Adds another task's tally to this one.
    pub(super) fn merge(&mut self, o: Tally) {
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
pub(super) fn code_name(code: tonic::Code) -> &'static str {
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

/// Latency and counts of a set of requests.
#[derive(Clone, Debug)]
pub(super) struct Figures {
    pub(super) requests: u64,
    pub(super) pair_queries: u64,
    pub(super) p50_us: u64,
    pub(super) p90_us: u64,
    pub(super) p99_us: u64,
    pub(super) p999_us: u64,
    pub(super) max_us: u64,
    pub(super) mean_us: f64,
}

impl Figures {
    /// The figures of histogram `h` with these counts.
    pub(super) fn new(h: &Histogram<u64>, requests: u64, pair_queries: u64) -> Self {
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
pub(super) struct Report {
    pub(super) scenario: Scenario,
    pub(super) addr: String,
    pub(super) concurrency: usize,
    pub(super) shared_channel: bool,
    pub(super) pairs_per_request: usize,
    pub(super) rate: Option<f64>,
    pub(super) stream_query: StreamQuery,
    pub(super) columns: bool,
    pub(super) duration_s: f64,
    pub(super) overall: Figures,
    /// Requests of each kind (mixed), in [`OPS`] order.
    pub(super) by_op: Vec<(Op, Figures)>,
    pub(super) histogram_count: u64,
    pub(super) errors: BTreeMap<String, u64>,
    pub(super) send_lag: Option<(u64, u64)>,
    pub(super) unsent: u64,
    pub(super) in_process: Option<InProcess>,
}

/// The single-threaded in-process throughput of the same queries.
#[derive(Clone, Copy, Debug)]
pub(super) struct InProcess {
    pub(super) pair_queries_per_s: f64,
    pub(super) seconds: f64,
}

/// A run's report and, when asked for, every answer.
#[derive(Debug)]
pub(super) struct Outcome {
    pub(super) report: Report,
    /// Every answered request when recording (the tests check them against a local catalog).
    #[cfg_attr(not(test), allow(dead_code))]
    pub(super) records: Vec<Record>,
    /// Where the bodies stood.
    #[cfg_attr(not(test), allow(dead_code))]
    pub(super) layout: Layout,
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

    /// The report as printed.
    pub(super) fn text(&self) -> String {
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

    /// The report as `--json` writes it (see the module docs for the keys).
    pub(super) fn json(&self) -> serde_json::Value {
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

/// One line of latency figures (µs).
fn latency_line(f: &Figures) -> String {
    format!(
        "p50 {}  p90 {}  p99 {}  p99.9 {}  max {}  (mean {:.1})",
        f.p50_us, f.p90_us, f.p99_us, f.p999_us, f.max_us, f.mean_us
    )
}
