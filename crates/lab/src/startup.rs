//! `sublevel-lab startup --bodies N [--dir DIR]`: how long a server takes to start on a store of N
//! bodies.
//!
//! Writes a redb store (the `sublevel serve --data-dir` layout) of N bodies — the test bodies of
//! degree 2, 4, 6 and 8 (`tests/data`), and a share of compound bodies cut from the bundled
//! compound files (`data/compound`, the nodes down to `--compound-depth`) — with scenes of a few
//! instances each, then measures:
//!
//! ```text
//! open          RedbStore::open_dir (which parses every record once to quarantine unreadable
//!               ones), then Catalog::open (records read and parsed), in this process
//! listening     spawn `sublevel serve --addr 127.0.0.1:0` → its `listening on ADDR` line
//! health        spawn → the first `sublevel health --addr ADDR` that answers SERVING (includes
//!               starting the `sublevel health` process, a few ms)
//! warm-up       spawn → the server's `bodies built` log line (every body built in the background),
//!               and the seconds that line reports
//! ```
//!
//! Run it from the repository root after `cargo build --release -p sublevel` (the server binary
//! is looked for next to this one unless `--server` names it).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use sublevel_core::body::BodyFile;
use sublevel_core::compound::CompoundFile;
use sublevel_core::math::pose_from_parts;
use sublevel_core::{Error, Result};
use sublevel_query::NewtonParams;
use sublevel_scene::store::{RedbStore, Store};
use sublevel_scene::{BodyRecord, Catalog, InstanceRecord, SceneMeta, StoredPose};

/// Arguments of `sublevel-lab startup`.
#[derive(clap::Args, Debug)]
pub struct StartupArgs {
    /// Bodies in the store.
    #[arg(long, default_value_t = 10_000)]
    pub bodies: usize,
    /// Scenes (default: one per 10 bodies).
    #[arg(long)]
    pub scenes: Option<usize>,
    /// Instances per scene (bodies taken in turn).
    #[arg(long, default_value_t = 2)]
    pub instances_per_scene: usize,
    /// Share of compound bodies, in [0, 1].
    #[arg(long, default_value_t = 0.05)]
    pub compound_share: f64,
    /// Deepest node kept of the bundled compound trees (0: the root only; 2: up to 7 nodes;
    /// the bundled files have 127 nodes, depth 6).
    #[arg(long, default_value_t = 2)]
    pub compound_depth: usize,
    /// Store directory: reused when it already holds a store (nothing is written then), else
    /// written and kept. Default: a temporary directory, removed at the end.
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// The `sublevel` binary (default: next to this one).
    #[arg(long)]
    pub server: Option<PathBuf>,
    /// Folder of the single-body files `*.deg{2,4,6,8}.json`.
    #[arg(long, default_value = "tests/data")]
    pub body_data: PathBuf,
    /// Folder of the compound files.
    #[arg(long, default_value = "data/compound")]
    pub compound_data: PathBuf,
    /// Longest wait for the server's warm-up, in seconds.
    #[arg(long, default_value_t = 1800.0)]
    pub timeout: f64,
}

fn io(what: impl std::fmt::Display) -> Error {
    Error::Io(std::io::Error::other(what.to_string()))
}

/// Runs `sublevel-lab startup`.
///
/// # Errors
/// [`Error::Io`] / [`Error::Json`] for unreadable data files, a server that does not start,
/// listen or finish its warm-up within `--timeout`; [`Error::Storage`] when the store cannot be
/// written.
pub fn run(args: StartupArgs) -> Result<()> {
    let server = match &args.server {
        Some(p) => p.clone(),
        None => std::env::current_exe()?.with_file_name("sublevel"),
    };
    if !server.is_file() {
        return Err(io(format!(
            "no server binary at {} (cargo build --release -p sublevel, or --server)",
            server.display()
        )));
    }
    let temp;
    let dir = match &args.dir {
        Some(d) => d.clone(),
        None => {
            temp = TempDir::new()?;
            temp.0.clone()
        }
    };
    let db = dir.join(sublevel_scene::store::DATABASE_FILE);
    if db.exists() {
        println!("store: reusing {}", db.display());
    } else {
        let t = Instant::now();
        let (bodies, compound, scenes, instances) = write_store(&args, &dir)?;
        println!(
            "store: wrote {bodies} bodies ({compound} compound), {scenes} scenes, {instances} instances in {:.1} s",
            t.elapsed().as_secs_f64()
        );
    }
    let size = std::fs::metadata(&db)?.len();
    let t = Instant::now();
    let store = RedbStore::open_dir(&dir)?;
    let store_open = t.elapsed().as_secs_f64();
    let catalog = Catalog::open(Box::new(store), NewtonParams::default())?;
    let open = t.elapsed().as_secs_f64();
    let (built, total) = catalog.bodies_built();
    let scenes = catalog.scenes().len();
    drop(catalog);
    println!("store: {total} bodies ({built} built after open), {scenes} scenes, {:.1} MB", size as f64 / 1e6);
    let served = time_server(&server, &dir, Duration::from_secs_f64(args.timeout.max(1.0)))?;
    println!();
    println!("| stage                                         | seconds |");
    println!("|-----------------------------------------------|--------:|");
    println!("| RedbStore::open_dir (unreadable-record pass)  | {store_open:7.3} |");
    println!("| + Catalog::open (in-process: read + parse)    | {open:7.3} |");
    println!("| spawn → `listening on` (process)              | {:7.3} |", served.listening);
    println!("| spawn → health SERVING (`sublevel health`)    | {:7.3} |", served.health);
    println!("| spawn → `bodies built` (background warm-up)   | {:7.3} |", served.warm);
    match served.warm_logged {
        Some(s) => println!("| warm-up alone (as the server logs it)         | {s:7.3} |"),
        None => println!("| warm-up alone (as the server logs it)         |       ? |"),
    }
    println!();
    println!("server: {}; store health {}", server.display(), served.store_health);
    println!("machine: {} CPUs seen by the process", std::thread::available_parallelism().map_or(1, |n| n.get()));
    Ok(())
}

/// A directory removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new() -> Result<Self> {
        let path = std::env::temp_dir().join(format!("sublevel-startup-{:016x}", rand::random::<u64>()));
        std::fs::create_dir_all(&path)?;
        Ok(Self(path))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The single-body files of every degree in `folder` (`*.deg{2,4,6,8}.json`), sorted by name.
fn single_bodies(folder: &Path) -> Result<Vec<BodyFile>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(folder)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.contains(".deg") && n.ends_with(".json")))
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(io(format!("no *.degN.json body files in {}", folder.display())));
    }
    paths.iter().map(|p| Ok(serde_json::from_str(&std::fs::read_to_string(p)?)?)).collect()
}

/// The compound files of `folder`, each cut to its nodes of depth ≤ `depth` (a subtree of a
/// valid tree is a valid tree: every kept parent still contains its kept children).
fn compound_bodies(folder: &Path, depth: usize) -> Result<Vec<CompoundFile>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(folder)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for p in paths {
        let file: CompoundFile = serde_json::from_str(&std::fs::read_to_string(&p)?)?;
        let keep: Vec<usize> = (0..file.nodes.len()).filter(|&i| file.nodes[i].depth <= depth).collect();
        let mut index = vec![usize::MAX; file.nodes.len()];
        for (k, &i) in keep.iter().enumerate() {
            index[i] = k;
        }
        let nodes = keep
            .iter()
            .map(|&i| {
                let mut n = file.nodes[i].clone();
                n.children = n.children.iter().map(|&c| index[c]).filter(|&c| c != usize::MAX).collect();
                n
            })
            .collect();
        out.push(CompoundFile { root: index[file.root], nodes, ..file });
    }
    Ok(out)
}

/// Writes the store; returns (bodies, compound bodies, scenes, instances).
fn write_store(args: &StartupArgs, dir: &Path) -> Result<(usize, usize, usize, usize)> {
    let singles = single_bodies(&args.body_data)?;
    let compounds =
        if args.compound_share > 0.0 { compound_bodies(&args.compound_data, args.compound_depth)? } else { Vec::new() };
    let every = if compounds.is_empty() || args.compound_share <= 0.0 {
        usize::MAX
    } else {
        (1.0 / args.compound_share.min(1.0)).round().max(1.0) as usize
    };
    std::fs::create_dir_all(dir)?;
    let store = RedbStore::open_dir(dir)?;
    let mut ids = Vec::with_capacity(args.bodies);
    let mut compound = 0;
    for k in 0..args.bodies {
        let id = format!("b-{k:016x}");
        let rec = if k % every == every - 1 {
            let file = compounds[compound % compounds.len()].clone();
            compound += 1;
            BodyRecord {
                name: format!("compound-{k}"),
                body: file.nodes[file.root].body.clone(),
                compound: Some(file),
                primitive: None,
                mesh: None,
            }
        } else {
            BodyRecord::single(&format!("body-{k}"), singles[k % singles.len()].clone())
        };
        store.put_body(&id, &rec)?;
        ids.push(id);
    }
    let scenes = args.scenes.unwrap_or(args.bodies / 10);
    let mut instances = 0;
    for s in 0..scenes {
        let scene = format!("s-{s:016x}");
        store.put_scene(&scene, &SceneMeta::named(&format!("scene-{s}")))?;
        let mut rows = Vec::new();
        for j in 0..args.instances_per_scene {
            let body = &ids[(s * args.instances_per_scene + j) % ids.len().max(1)];
            let pose = pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [3.0 * j as f64, 0.0, 0.0])?;
            rows.push((
                format!("i-{instances:016x}"),
                InstanceRecord { body_id: body.clone(), pose: StoredPose::from_isometry(&pose) },
            ));
            instances += 1;
        }
        let refs: Vec<(&str, &InstanceRecord)> = rows.iter().map(|(i, r)| (i.as_str(), r)).collect();
        store.put_instances(&scene, &refs, false)?;
    }
    Ok((args.bodies, compound, scenes, instances))
}

/// `line` without ANSI colour sequences (`ESC [ … m`).
fn strip_ansi(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// What the server's start took, seconds from its spawn.
struct Served {
    listening: f64,
    health: f64,
    warm: f64,
    /// The seconds of the `bodies built` line, as logged.
    warm_logged: Option<f64>,
    /// The answer of `sublevel health --service sublevel.v1.Store` after the warm-up.
    store_health: String,
}

/// Starts the server on the store, times it (see the module docs) and stops it with SIGTERM.
fn time_server(server: &Path, dir: &Path, timeout: Duration) -> Result<Served> {
    let start = Instant::now();
    let mut child = Command::new(server)
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(dir)
        .env("RUST_LOG", "info")
        .env("NO_COLOR", "1")
        .env_remove("SUBLEVEL_ADDR")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    let result = watch(server, &mut child, start, timeout);
    // SIGTERM for a clean stop; SIGKILL if it does not stop in 10 s.
    let _ = Command::new("kill").args(["-TERM", &child.id().to_string()]).status();
    let stop = Instant::now();
    while child.try_wait()?.is_none() {
        if stop.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.wait();
    result
}

fn watch(server: &Path, child: &mut Child, start: Instant, timeout: Duration) -> Result<Served> {
    let (tx, rx) = mpsc::channel::<(bool, String, f64)>();
    let stdout = child.stdout.take().ok_or_else(|| io("no stdout"))?;
    let stderr = child.stderr.take().ok_or_else(|| io("no stderr"))?;
    for (is_log, pipe) in [(false, Box::new(stdout) as Box<dyn std::io::Read + Send>), (true, Box::new(stderr))] {
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(pipe).lines().map_while(std::result::Result::ok) {
                let line = strip_ansi(&line);
                if tx.send((is_log, line, start.elapsed().as_secs_f64())).is_err() {
                    break;
                }
            }
        });
    }
    let next = |what: &str| -> Result<(bool, String, f64)> {
        let left = timeout.checked_sub(start.elapsed()).unwrap_or_default();
        rx.recv_timeout(left).map_err(|_| io(format!("the server did not log {what} within {timeout:?}")))
    };
    let mut warm: Option<(f64, String)> = None;
    let (addr, listening) = loop {
        let (is_log, line, at) = next("`listening on`")?;
        if is_log && line.contains("bodies built") {
            warm = Some((at, line));
        } else if let Some(addr) = line.strip_prefix("listening on ") {
            break (addr.trim().to_owned(), at);
        } else if is_log && line.contains("ERROR") {
            eprintln!("server: {line}");
        }
    };
    let health = loop {
        if start.elapsed() > timeout {
            return Err(io("the server never answered SERVING"));
        }
        let ok = std::net::TcpStream::connect(&addr).is_ok()
            && Command::new(server)
                .args(["health", "--addr", &addr, "--timeout", "1"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()?
                .success();
        if ok {
            break start.elapsed().as_secs_f64();
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let (warm, line) = match warm {
        Some(w) => w,
        None => loop {
            let (is_log, line, at) = next("`bodies built`")?;
            if is_log && line.contains("bodies built") {
                break (at, line);
            }
        },
    };
    let warm_logged = line.split_whitespace().find_map(|w| w.strip_prefix("seconds=")?.parse().ok());
    let out = Command::new(server)
        .args(["health", "--addr", &addr, "--service", "sublevel.v1.Store", "--timeout", "2"])
        .stderr(Stdio::null())
        .output()?;
    let store_health = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    Ok(Served { listening, health, warm, warm_logged, store_health })
}
