//! The operator's settings of `sublevel serve`: limits, metrics and log format, each a flag with
//! an environment variable and a key of the optional TOML file `--config FILE`.
//!
//! Precedence, highest first: the flag, its environment variable, the config file, the default.
//! The file is a flat table whose keys are the flag names without `--` (`max-scenes = 100`; `_`
//! works too); an unknown key is an error, so a typo never passes silently. The address, data
//! directory, demo and worker flags are flags and variables only.
//!
//! The "Configuration" table of docs/operations.md is [`config_table`] (printed by
//! `sublevel serve --print-config-table`), built from the same clap definitions as `--help`; a
//! unit test fails when that copy differs.

use super::serve::ServeArgs;
use clap::parser::ValueSource;
use clap::{ArgMatches, Args, CommandFactory};
use std::net::SocketAddr;
use std::path::PathBuf;
use sublevel::service::ServerConfig;
use sublevel::{Error, Result};

/// The library defaults the flags show and fall back to.
fn defaults() -> ServerConfig {
    ServerConfig::default()
}

/// A duration in whole milliseconds (for the `*-ms` flags' defaults).
fn millis(d: std::time::Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

/// Log line format on stderr.
#[derive(clap::ValueEnum, serde::Serialize, serde::Deserialize, Clone, Copy, Debug, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Human-readable lines.
    Text,
    /// One JSON object per line (with the span fields, e.g. `request_id`), for log collectors.
    Json,
}

/// Limits, metrics and logging of `sublevel serve` (flattened into its arguments).
#[derive(Args, serde::Serialize, serde::Deserialize, Clone, Debug)]
pub struct OpsArgs {
    /// TOML file of settings below the flags and environment (keys: flag names without `--`).
    #[arg(long, env = "SUBLEVEL_CONFIG")]
    pub config: Option<PathBuf>,
    /// Print the Markdown table of every `serve` setting (docs/operations.md's) and exit.
    #[arg(long)]
    #[serde(skip)]
    pub print_config_table: bool,
    /// Serve Prometheus metrics at http://ADDR/metrics (off when unset).
    #[arg(long, env = "SUBLEVEL_METRICS_ADDR")]
    pub metrics_addr: Option<SocketAddr>,
    /// Log format on stderr: `text` or `json` (one object per line, with the RPC span's `request_id`).
    #[arg(long, env = "SUBLEVEL_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
    /// Largest response, and largest request of the uploads (UploadBody, StartFitJob, StartGroupJob,
    /// ImportScene, UploadRobot, StartRobotFitJob, UpdatePointCloud), in bytes (larger ones are
    /// OUT_OF_RANGE).
    #[arg(long, env = "SUBLEVEL_MAX_MESSAGE_BYTES", default_value_t = defaults().max_message_bytes)]
    pub max_message_bytes: usize,
    /// Largest request message of every other method, in bytes (larger ones are OUT_OF_RANGE
    /// before any byte is buffered).
    #[arg(long, env = "SUBLEVEL_MAX_REQUEST_BYTES", default_value_t = defaults().admission.max_request_bytes)]
    pub max_request_bytes: usize,
    /// Most bytes of incomplete request messages the server holds, all connections together (a
    /// call that would pass it is RESOURCE_EXHAUSTED; its last eighth is kept for messages of at
    /// most 64 KiB).
    #[arg(long, env = "SUBLEVEL_REQUEST_MEMORY_BYTES", default_value_t = defaults().admission.request_memory_bytes)]
    pub request_memory_bytes: usize,
    /// Most bytes of incomplete request messages held for one connection (at least the largest
    /// upload, --max-message-bytes).
    #[arg(long, env = "SUBLEVEL_CONNECTION_MEMORY_BYTES", default_value_t = defaults().admission.connection_memory_bytes)]
    pub connection_memory_bytes: usize,
    /// Longest time in milliseconds one request message may take to arrive once its first byte
    /// has (past it: DEADLINE_EXCEEDED, its bytes freed).
    #[arg(long, env = "SUBLEVEL_MESSAGE_TIMEOUT_MS", default_value_t = millis(defaults().admission.message_timeout))]
    pub message_timeout_ms: u64,
    /// Most connections open at once; one more is accepted and closed at once.
    #[arg(long, env = "SUBLEVEL_MAX_CONNECTIONS", default_value_t = defaults().admission.max_connections)]
    pub max_connections: usize,
    /// Most concurrent calls (HTTP/2 streams) per connection; clients queue calls beyond it.
    #[arg(long, env = "SUBLEVEL_MAX_STREAMS_PER_CONNECTION", default_value_t = defaults().admission.max_streams_per_connection)]
    pub max_streams_per_connection: u32,
    /// Longest time in milliseconds from accepting a connection to its first request (TLS
    /// handshake, HTTP/2 preface, headers); past it the connection is closed.
    #[arg(long, env = "SUBLEVEL_HANDSHAKE_TIMEOUT_MS", default_value_t = millis(defaults().admission.handshake_timeout))]
    pub handshake_timeout_ms: u64,
    /// HTTP/2 flow-control window of one stream, in bytes.
    #[arg(long, env = "SUBLEVEL_STREAM_WINDOW_BYTES", default_value_t = defaults().admission.stream_window_bytes)]
    pub stream_window_bytes: u32,
    /// HTTP/2 flow-control window of one connection, in bytes.
    #[arg(long, env = "SUBLEVEL_CONNECTION_WINDOW_BYTES", default_value_t = defaults().admission.connection_window_bytes)]
    pub connection_window_bytes: u32,
    /// Most points of one fit, after mesh parsing.
    #[arg(long, env = "SUBLEVEL_MAX_FIT_POINTS", default_value_t = defaults().max_fit_points)]
    pub max_fit_points: usize,
    /// Most pairs of one BatchQuery or Query request.
    #[arg(long, env = "SUBLEVEL_MAX_BATCH_PAIRS", default_value_t = defaults().max_batch_pairs)]
    pub max_batch_pairs: usize,
    /// Most poses of one SetPoses (or Query) request.
    #[arg(long, env = "SUBLEVEL_MAX_POSES_PER_CALL", default_value_t = defaults().max_poses_per_call)]
    pub max_poses_per_call: usize,
    /// Most instances in one scene (AddInstance beyond it is RESOURCE_EXHAUSTED).
    #[arg(long, env = "SUBLEVEL_MAX_INSTANCES_PER_SCENE", default_value_t = defaults().max_instances_per_scene)]
    pub max_instances_per_scene: usize,
    /// Most scenes (CreateScene beyond it is RESOURCE_EXHAUSTED).
    #[arg(long, env = "SUBLEVEL_MAX_SCENES", default_value_t = defaults().max_scenes)]
    pub max_scenes: usize,
    /// Most bodies (UploadBody or StartFitJob beyond it is RESOURCE_EXHAUSTED).
    #[arg(long, env = "SUBLEVEL_MAX_BODIES", default_value_t = defaults().max_bodies)]
    pub max_bodies: usize,
    /// Most bytes held by the point clouds of every scene together, in memory (an
    /// UpdatePointCloud beyond it is RESOURCE_EXHAUSTED).
    #[arg(long, env = "SUBLEVEL_MAX_CLOUD_BYTES", default_value_t = defaults().max_cloud_bytes)]
    pub max_cloud_bytes: usize,
    /// Most points of one UpdatePointCloud frame: a depth image's width × height, a PointCloud2's
    /// points (checked before the frame is decoded; a larger one is RESOURCE_EXHAUSTED).
    #[arg(long, env = "SUBLEVEL_MAX_FRAME_POINTS", default_value_t = defaults().max_frame_points)]
    pub max_frame_points: usize,
    /// Most points of UpdatePointCloud frames decoded and filtered at once, all calls together
    /// (at most 160 bytes of memory each; frames past it wait, holding no thread).
    #[arg(long, env = "SUBLEVEL_MAX_FRAME_POINTS_IN_FLIGHT", default_value_t = defaults().max_frame_points_in_flight)]
    pub max_frame_points_in_flight: usize,
    /// Fits running at once (each is CPU-heavy; the others wait in the queue). Default: a quarter
    /// of the CPUs, at least 1.
    #[arg(long, env = "SUBLEVEL_MAX_CONCURRENT_FITS")]
    pub max_concurrent_fits: Option<usize>,
    /// Most fit and group jobs queued or running (one more is RESOURCE_EXHAUSTED).
    #[arg(long, env = "SUBLEVEL_MAX_FIT_QUEUE", default_value_t = defaults().max_fit_queue)]
    pub max_fit_queue: usize,
    /// SDP query solves (certificates, nonconvex scenes) running at once. Default: half the CPUs,
    /// at least 2.
    #[arg(long, env = "SUBLEVEL_MAX_CONCURRENT_SDP")]
    pub max_concurrent_sdp: Option<usize>,
    /// Newton-only query work too large for an async worker (large batches, planner requests,
    /// CheckScene) running at once, each on its own thread. Default: the CPUs.
    #[arg(long, env = "SUBLEVEL_BATCH_WORKERS")]
    pub batch_workers: Option<usize>,
    /// Plan calls running at once, on slots of their own (the rest wait, their timeouts running;
    /// the checks' batch slots are never theirs). Default: half the CPUs, at least 1.
    #[arg(long, env = "SUBLEVEL_MAX_CONCURRENT_PLANS")]
    pub max_concurrent_plans: Option<usize>,
    /// Longest time of one call in milliseconds, whatever the client's deadline (past it:
    /// DEADLINE_EXCEEDED, its query solves cancelled); 0 = only client deadlines apply.
    #[arg(long, env = "SUBLEVEL_MAX_REQUEST_MS", default_value_t = 0)]
    pub max_request_ms: u64,
    /// Store: unset keeps the embedded redb database in --data-dir; `postgres://USER@HOST:PORT/DB`
    /// shares bodies, scenes and jobs with other replicas (deploy/SCALING.md).
    #[arg(long, env = "SUBLEVEL_STORE")]
    pub store: Option<String>,
}

impl OpsArgs {
    /// Copies the limits into `config`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the flag when a limit is 0.
    pub fn apply(&self, config: &mut ServerConfig) -> Result<()> {
        let limits = [
            ("--max-message-bytes", self.max_message_bytes),
            ("--max-fit-points", self.max_fit_points),
            ("--max-batch-pairs", self.max_batch_pairs),
            ("--max-poses-per-call", self.max_poses_per_call),
            ("--max-instances-per-scene", self.max_instances_per_scene),
            ("--max-scenes", self.max_scenes),
            ("--max-bodies", self.max_bodies),
            ("--max-cloud-bytes", self.max_cloud_bytes),
            ("--max-frame-points", self.max_frame_points),
            ("--max-frame-points-in-flight", self.max_frame_points_in_flight),
            ("--max-concurrent-fits", self.max_concurrent_fits.unwrap_or(1)),
            ("--max-fit-queue", self.max_fit_queue),
            ("--max-concurrent-sdp", self.max_concurrent_sdp.unwrap_or(1)),
            ("--batch-workers", self.batch_workers.unwrap_or(1)),
            ("--max-concurrent-plans", self.max_concurrent_plans.unwrap_or(1)),
            ("--max-request-bytes", self.max_request_bytes),
            ("--request-memory-bytes", self.request_memory_bytes),
            ("--connection-memory-bytes", self.connection_memory_bytes),
            ("--max-connections", self.max_connections),
            ("--max-streams-per-connection", self.max_streams_per_connection as usize),
            ("--message-timeout-ms", usize::try_from(self.message_timeout_ms).unwrap_or(usize::MAX)),
            ("--handshake-timeout-ms", usize::try_from(self.handshake_timeout_ms).unwrap_or(usize::MAX)),
        ];
        if let Some((flag, _)) = limits.iter().find(|(_, v)| *v == 0) {
            return Err(Error::invalid(*flag, "must be at least 1"));
        }
        // An upload must fit in its connection's budget, and that in the server's.
        let upload = self.max_message_bytes.saturating_add(5);
        if self.connection_memory_bytes < upload {
            return Err(Error::invalid(
                "--connection-memory-bytes",
                format!("must hold the largest upload: at least --max-message-bytes + 5 = {upload}"),
            ));
        }
        if self.request_memory_bytes - self.request_memory_bytes / 8 < self.connection_memory_bytes {
            return Err(Error::invalid(
                "--request-memory-bytes",
                format!(
                    "its first seven eighths must hold one connection's budget (--connection-memory-bytes {}): at \
                     least {}",
                    self.connection_memory_bytes,
                    self.connection_memory_bytes.div_ceil(7) * 8
                ),
            ));
        }
        for (flag, v) in [
            ("--stream-window-bytes", self.stream_window_bytes),
            ("--connection-window-bytes", self.connection_window_bytes),
        ] {
            // HTTP/2 (RFC 9113 §6.9.2): a window is at least the 65 535-byte default and below 2³¹.
            if !(65_535..=0x7fff_ffff).contains(&v) {
                return Err(Error::invalid(flag, format!("must be between 65535 and 2147483647 bytes, got {v}")));
            }
        }
        config.max_message_bytes = self.max_message_bytes;
        config.max_fit_points = self.max_fit_points;
        config.max_batch_pairs = self.max_batch_pairs;
        config.max_poses_per_call = self.max_poses_per_call;
        config.max_instances_per_scene = self.max_instances_per_scene;
        config.max_scenes = self.max_scenes;
        config.max_bodies = self.max_bodies;
        config.max_cloud_bytes = self.max_cloud_bytes;
        config.max_frame_points = self.max_frame_points;
        config.max_frame_points_in_flight = self.max_frame_points_in_flight;
        config.max_concurrent_fits = self.max_concurrent_fits.unwrap_or(config.max_concurrent_fits);
        config.max_fit_queue = self.max_fit_queue;
        config.max_concurrent_sdp = self.max_concurrent_sdp.unwrap_or(config.max_concurrent_sdp);
        config.batch_workers = self.batch_workers.unwrap_or(config.batch_workers);
        config.max_concurrent_plans = self.max_concurrent_plans.unwrap_or(config.max_concurrent_plans);
        config.admission = sublevel::service::admission::AdmissionSettings {
            max_connections: self.max_connections,
            max_streams_per_connection: self.max_streams_per_connection,
            handshake_timeout: std::time::Duration::from_millis(self.handshake_timeout_ms),
            max_request_bytes: self.max_request_bytes,
            request_memory_bytes: self.request_memory_bytes,
            connection_memory_bytes: self.connection_memory_bytes,
            message_timeout: std::time::Duration::from_millis(self.message_timeout_ms),
            stream_window_bytes: self.stream_window_bytes,
            connection_window_bytes: self.connection_window_bytes,
        };
        config.store_url = self.store.clone();
        config.max_request_time =
            (self.max_request_ms > 0).then(|| std::time::Duration::from_millis(self.max_request_ms));
        Ok(())
    }
}

/// Applies `--config` (when given) under the flags and environment of `matches` (the `serve`
/// subcommand's matches). Returns `None` after printing the table for `--print-config-table`.
///
/// # Errors
/// [`Error::InvalidArgument`] (field `--config`) when the file cannot be read or parsed, has an
/// unknown key or a value of the wrong type.
pub fn prepare(mut args: ServeArgs, matches: Option<&ArgMatches>) -> Result<Option<ServeArgs>> {
    if args.ops.print_config_table {
        print!("{}", config_table());
        return Ok(None);
    }
    if let (Some(path), Some(matches)) = (args.ops.config.clone(), matches) {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| Error::invalid("--config", format!("cannot read {}: {e}", path.display())))?;
        args.ops = merge_file(&args.ops, matches, &text)?;
    }
    Ok(Some(args))
}

/// `ops` with every setting of the TOML `text` that `matches` did not take from a flag or an
/// environment variable.
///
/// # Errors
/// As [`prepare`].
pub fn merge_file(ops: &OpsArgs, matches: &ArgMatches, text: &str) -> Result<OpsArgs> {
    let bad = |reason: String| Error::invalid("--config", reason);
    let table: toml::Table = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
    let mut merged = serde_json::to_value(ops)?;
    let fields = merged.as_object_mut().ok_or_else(|| bad("settings are not a table".into()))?;
    for (key, value) in table {
        let id = key.replace('-', "_");
        if id == "config" || !fields.contains_key(&id) {
            let known: Vec<String> = fields.keys().filter(|k| *k != "config").map(|k| k.replace('_', "-")).collect();
            return Err(bad(format!("unknown setting `{key}`; the file may set {}", known.join(", "))));
        }
        let explicit = matches!(matches.value_source(&id), Some(ValueSource::CommandLine | ValueSource::EnvVariable));
        if !explicit {
            fields.insert(id, serde_json::to_value(value)?);
        }
    }
    serde_json::from_value(merged).map_err(|e| bad(e.to_string()))
}

/// The Markdown table of every `sublevel serve` setting: flag, environment variable, config-file
/// key, default and meaning, from the clap definitions (plus `RUST_LOG` and
/// `OPENBLAS_NUM_THREADS`).
pub fn config_table() -> String {
    let file_keys: Vec<String> = OpsArgs::augment_args(clap::Command::new("ops"))
        .get_arguments()
        .map(|a| a.get_id().to_string())
        .filter(|id| id != "config" && id != "print_config_table")
        .collect();
    let serve = super::super::Cli::command();
    let mut out = String::from("| flag | environment | config file | default | meaning |\n|---|---|---|---|---|\n");
    let Some(serve) = serve.find_subcommand("serve") else {
        return out;
    };
    for arg in serve.get_arguments() {
        let Some(long) = arg.get_long() else { continue };
        if long == "help" {
            continue;
        }
        let env = arg.get_env().map_or(String::new(), |e| format!("`{}`", e.to_string_lossy()));
        let id = arg.get_id().to_string();
        let key = if file_keys.contains(&id) { format!("`{long}`") } else { String::new() };
        let defaults: Vec<String> = arg.get_default_values().iter().map(|v| v.to_string_lossy().into_owned()).collect();
        let default = match defaults.join(",").as_str() {
            "" if arg.get_action().takes_values() => "unset".to_owned(),
            "" | "false" => "off".to_owned(),
            d => format!("`{d}`"),
        };
        let help = arg.get_help().map_or(String::new(), |h| h.to_string());
        let meaning = help.replace('\n', " ").replace('|', "\\|");
        out.push_str(&format!("| `--{long}` | {env} | {key} | {default} | {meaning} |\n"));
    }
    out.push_str(
        "| | `RUST_LOG` | | `info` | log filter (tracing); `sublevel=debug` logs every RPC with its code and time |\n",
    );
    out.push_str(
        "| | `OPENBLAS_NUM_THREADS` | | `1` | BLAS threads of each SDP solve (the binary sets 1 at start-up when the variable is unset) |\n",
    );
    out
}

/// Installs the `tracing` subscriber on stderr in `format`, filtered by `RUST_LOG` (default
/// `info`). A subscriber already set by an embedding program is kept.
pub fn init_logging(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    // Ignore the error of a second init (a subscriber already set by an embedding program).
    let _ = match format {
        LogFormat::Text => builder.try_init(),
        LogFormat::Json => builder.json().with_current_span(true).with_span_list(false).try_init(),
    };
}

/// Starts the Prometheus endpoint when `--metrics-addr` is set and prints `metrics on ADDR` on
/// stdout (for scripts and tests that bind port 0). Call inside the runtime.
///
/// # Errors
/// [`Error::Io`] when the address cannot be bound.
pub async fn start_metrics(ops: &OpsArgs) -> Result<()> {
    if let Some(addr) = ops.metrics_addr {
        let listener = tokio::net::TcpListener::bind(addr).await?;
        let bound = sublevel::service::metrics::install_prometheus(listener)?;
        println!("metrics on {bound}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn command() -> clap::Command {
        OpsArgs::augment_args(clap::Command::new("serve"))
    }

    /// file < env < flag, and the default below them all.
    #[test]
    fn the_file_sits_under_the_environment_and_the_flags() {
        // Only this test reads SUBLEVEL_MAX_BODIES.
        std::env::set_var("SUBLEVEL_MAX_BODIES", "7");
        let matches = command().try_get_matches_from(["serve", "--max-scenes", "5"]).unwrap();
        std::env::remove_var("SUBLEVEL_MAX_BODIES");
        let ops = <OpsArgs as clap::FromArgMatches>::from_arg_matches(&matches).unwrap();
        let file = "max-scenes = 3\nmax-bodies = 4\nmax_fit_queue = 9\nlog-format = \"json\"\n\
                    metrics-addr = \"127.0.0.1:9100\"\n";
        let merged = merge_file(&ops, &matches, file).unwrap();
        assert_eq!(merged.max_scenes, 5, "flag beats file");
        assert_eq!(merged.max_bodies, 7, "env beats file");
        assert_eq!(merged.max_fit_queue, 9, "file beats default");
        assert_eq!(merged.log_format, LogFormat::Json);
        assert_eq!(merged.metrics_addr, Some("127.0.0.1:9100".parse().unwrap()));
        assert_eq!(merged.max_batch_pairs, 10_000, "default");
        let mut config = ServerConfig::default();
        merged.apply(&mut config).unwrap();
        assert_eq!((config.max_scenes, config.max_bodies, config.max_fit_queue), (5, 7, 9));

        let e = merge_file(&ops, &matches, "max-scene = 3").unwrap_err().to_string();
        assert!(e.contains("unknown setting `max-scene`") && e.contains("max-scenes"), "{e}");
        let e = merge_file(&ops, &matches, "max-fit-queue = \"many\"").unwrap_err().to_string();
        assert!(e.contains("--config"), "{e}");
        let zero = merge_file(&ops, &matches, "max-fit-queue = 0").unwrap();
        let e = zero.apply(&mut config).unwrap_err().to_string();
        assert!(e.contains("--max-fit-queue") && e.contains("at least 1"), "{e}");
    }

    /// docs/operations.md's Configuration table is exactly `sublevel serve --print-config-table`.
    #[test]
    fn the_readme_holds_the_generated_table() {
        let table = config_table();
        assert!(table.contains(
            "| `--max-scenes` | `SUBLEVEL_MAX_SCENES` | `max-scenes` | `10000` | Most scenes (CreateScene beyond it is \
             RESOURCE_EXHAUSTED) |"
        ));
        assert!(table.contains("| `--addr` | `SUBLEVEL_ADDR` |  | `127.0.0.1:50051` |"), "{table}");
        let readme = include_str!("../../docs/operations.md");
        assert!(
            readme.contains(&table),
            "docs/operations.md's table differs from `sublevel serve --print-config-table`:\n{table}"
        );
    }
}
