//! Fitting a robot: every link mesh of a URDF becomes a compound sos-convex body (paper §V) that
//! contains it, every URDF primitive stays exact.
//!
//! ```text
//! URDF ──► links' <collision> ──► box / cylinder / sphere / capsule  →  Primitive (exact)
//!                              └► mesh (package://…, relative)      →  read (OBJ, STL, PLY, OFF, DAE), scaled,
//!                                                                      fitted once per distinct content:
//!                                                                      fit_compound(--parts auto), cached
//! SRDF ──► disable_collisions ──► allowed pairs (the robot's allowed-collision matrix)
//! ```
//!
//! The SRDF is read as MoveIt reads it: entries naming links the URDF lacks are skipped, each with
//! a warning in the report ([`Semantics::known_to`]). Pairs of links on one rigid body (joined by
//! fixed joints) are never checked, and the report lists those the SRDF did not already allow.
//!
//! Distinct meshes (by SHA-256 of the file, scale and fit settings) are fitted once, in parallel
//! (one per core), and cached in `cache_dir` as `KEY.json` compound files, so a re-fit of the same
//! robot reads them back at once. Every leaf contains its triangles (the fit checks it); a leaf
//! above the tolerance is reported in the robot's notes, not refused: the checks resolve the
//! configurations the model cannot decide against the mesh itself ([`crate::check`]).

use crate::clearance::{build_clearance_tables, ClearanceFile, ClearanceSettings};
use crate::fitted::{FittedRobot, GeometryFile, MeshFile, PoseFile, RobotFile, RobotFitReport, ROBOT_FORMAT};
use crate::model::{resolve_mesh_path, CollisionGeometry, RobotModel};
use crate::srdf::Semantics;
use crate::{Error, Result};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::{Point3, Real};
use sublevel_core::primitive::PrimitiveFile;
use sublevel_fit::compound::{fit_compound, CompoundSettings, PartCount};
use sublevel_fit::mesh::{load_triangle_mesh, MeshFormat, TriangleMesh, DEFAULT_MAX_MESH_POINTS};

/// Settings of [`fit_robot`]; the default fits every mesh with `CompoundSettings::default()`, no
/// cache, one mesh per core, and builds no clearance tables (the CLI and the server build them).
#[derive(Clone, Debug, Default)]
pub struct RobotFitSettings {
    /// Directories that hold ROS packages: `package://NAME/PATH` is `DIR/NAME/PATH`.
    pub package_dirs: Vec<PathBuf>,
    /// Settings of each mesh's compound fit (`--parts auto`; its `excess_tolerance` is the leaf
    /// tolerance T in meters, `None` for 1 % of each mesh's bounding-box diagonal).
    pub compound: CompoundSettings,
    /// Where fitted meshes are cached (`None`: no cache).
    pub cache_dir: Option<PathBuf>,
    /// Fit every mesh again instead of reading the cache (the entries are rewritten).
    pub refresh_cache: bool,
    /// Meshes fitted at once (0: one per available core).
    pub threads: usize,
    /// Clearance tables of the self pairs moved by one or two joints ([`crate::clearance`]);
    /// `None` builds none (the checks are the same, slower on those pairs).
    pub clearance: Option<ClearanceSettings>,
    /// Fit each mesh's compound tree, its leaves under a root (`--leaves`, `--parts auto` within
    /// `compound.max_parts`). Default `false`: one sos-convex body per mesh, what the checks read
    /// (the root), fitted in about a second where a tree takes a minute.
    pub leaves: bool,
}

/// Progress of [`fit_robot`]: one message per mesh started or finished.
#[derive(Clone, Debug)]
pub struct RobotFitProgress {
    /// Distinct meshes done (fitted or cached).
    pub done: usize,
    /// Distinct meshes in all.
    pub total: usize,
    /// What happened (`link1.obj: fitted, 32 leaves, worst leaf excess 0.0231 m, 44.1 s`).
    pub message: String,
}

/// A mesh to fit: its key, name and triangles (geometry frame, scaled).
struct MeshJob {
    key: String,
    name: String,
    mesh: TriangleMesh,
}

/// Where a robot fit reads the mesh files its URDF names.
///
/// A URDF names meshes as `package://NAME/PATH`, `file:///ABS`, absolute or relative paths
/// (ROS conventions). The command line resolves them on its own disk ([`MeshSource::Files`]); the
/// service never does: it reads only the bytes the request carried, looked up by the exact name the
/// URDF writes ([`MeshSource::Memory`]), after [`check_mesh_name`] has refused every name that is
/// not `package://NAME/PATH` or a plain relative path.
#[derive(Clone, Copy, Debug)]
pub enum MeshSource<'a> {
    /// Files resolved as ROS and pinocchio do ([`resolve_mesh_path`]): relative names against
    /// `urdf_dir`, `package://` against `package_dirs` (from [`RobotFitSettings::package_dirs`]).
    Files {
        /// The URDF's directory (`None`: the working directory).
        urdf_dir: Option<&'a Path>,
    },
    /// The mesh files' bytes by the name the URDF gives them; nothing is read from disk.
    Memory(&'a std::collections::HashMap<String, Vec<u8>>),
}

/// Checks a mesh name a client sends for the service to read from its request: `package://NAME/PATH`
/// (a package name and a path inside it) or a relative path, each made of plain components (no
/// `..`, no `.`, no root, no drive, no backslash, no URL scheme such as `file://`), at most 1024
/// bytes. The format comes from the name's extension (OBJ, STL, PLY, OFF, DAE).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field`, saying what a mesh name may be.
pub fn check_mesh_name(field: &str, name: &str) -> Result<()> {
    const MAX_MESH_NAME_BYTES: usize = 1024;
    let refuse = |why: &str| {
        Err(Error::invalid(
            field,
            format!(
                "mesh `{}` {why}: a mesh name must be `package://NAME/PATH` or a relative path without `..`",
                sublevel_core::error::clip(name)
            ),
        ))
    };
    if name.len() > MAX_MESH_NAME_BYTES {
        return refuse(&format!("is longer than {MAX_MESH_NAME_BYTES} bytes"));
    }
    let (package, rest) = match name.strip_prefix("package://") {
        Some(rest) => (true, rest),
        None => (false, name),
    };
    if rest.is_empty() || rest.contains('\\') || rest.contains('\0') {
        return refuse("is empty or holds a backslash or NUL");
    }
    if !package && rest.contains(':') {
        return refuse("names a URL scheme or a drive (the service reads no file of its own disk)");
    }
    let parts: Vec<&str> = rest.split('/').collect();
    if parts.iter().any(|c| c.is_empty() || *c == "." || *c == "..") {
        return refuse("is absolute or holds an empty, `.` or `..` component");
    }
    if package && parts.len() < 2 {
        return refuse("names a package without a path inside it");
    }
    MeshFormat::of_path(Path::new(rest)).map_err(|e| Error::invalid(field, e.to_string()))?;
    Ok(())
}

/// Fits the robot of `urdf_path` (module docs); `srdf_path` gives the allowed pairs; meshes are
/// files resolved from the URDF's directory and [`RobotFitSettings::package_dirs`].
///
/// # Errors
/// [`Error::Io`] for an unreadable URDF or SRDF; as [`fit_robot_text`].
pub fn fit_robot(
    urdf_path: &Path,
    srdf_path: Option<&Path>,
    settings: &RobotFitSettings,
    progress: &(dyn Fn(&RobotFitProgress) + Sync),
) -> Result<FittedRobot> {
    let urdf = std::fs::read_to_string(urdf_path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", urdf_path.display())))?;
    let srdf = match srdf_path {
        Some(p) => Some(
            std::fs::read_to_string(p)
                .map_err(|e| std::io::Error::new(e.kind(), format!("cannot read {}: {e}", p.display())))?,
        ),
        None => None,
    };
    fit_robot_text(urdf, srdf.as_deref(), MeshSource::Files { urdf_dir: urdf_path.parent() }, settings, progress)
}

/// Fits the robot of URDF text `urdf` (module docs); `srdf` (SRDF text) gives the allowed pairs,
/// `meshes` where the link meshes are read. Cancellable: every stage (mesh fits, on their own
/// threads, and clearance tables) stops at its next check once this thread's
/// [`sublevel_core::cancel`] scope is cancelled.
///
/// # Errors
/// As [`RobotModel::from_urdf_str`] and [`Semantics::from_srdf_str`] (naming the element);
/// [`Error::InvalidArgument`] naming `urdf.link[NAME].collision[k].mesh` when a mesh is not
/// found (for files, the places searched listed; for [`MeshSource::Memory`], only its name) or
/// cannot be read as a triangle mesh; [`Error::Io`] for an unreadable file;
/// [`Error::ResourceExhausted`] when the robot exceeds a [`crate::limits`] limit; [`Error::Cancelled`]; the
/// fit's errors naming the mesh.
pub fn fit_robot_text(
    urdf: String,
    srdf: Option<&str>,
    meshes: MeshSource<'_>,
    settings: &RobotFitSettings,
    progress: &(dyn Fn(&RobotFitProgress) + Sync),
) -> Result<FittedRobot> {
    let start = Instant::now();
    let model = RobotModel::from_urdf_str(&urdf)?;
    let (allowed_pairs, warnings): (Vec<[String; 2]>, Vec<String>) = match srdf {
        Some(text) => {
            let (srdf, warnings) = Semantics::from_srdf_str(text)?.known_to(&model);
            (srdf.disabled_pairs.iter().map(|d| [d.link1.clone(), d.link2.clone()]).collect(), warnings)
        }
        None => (Vec::new(), Vec::new()),
    };
    let rigid_pairs = model.rigid_pairs_not_in(&allowed_pairs);
    crate::limits::check_self_pairs(&model, &allowed_pairs)?;
    let tag = settings_tag(&settings.compound, settings.leaves);
    let mut geometries = Vec::new();
    let mut jobs: Vec<MeshJob> = Vec::new();
    for link in model.links() {
        for (k, c) in link.collision.iter().enumerate() {
            let field = format!("urdf.link[{}].collision[{k}]", link.name);
            let (origin, primitive, mesh) = match c {
                CollisionGeometry::Box { origin, size } => (origin, Some(PrimitiveFile::Box { size: *size }), None),
                CollisionGeometry::Sphere { origin, radius } => {
                    (origin, Some(PrimitiveFile::Sphere { radius: *radius }), None)
                }
                CollisionGeometry::Cylinder { origin, radius, length } => {
                    (origin, Some(PrimitiveFile::Cylinder { radius: *radius, height: *length }), None)
                }
                CollisionGeometry::Capsule { origin, radius, length } => {
                    (origin, Some(PrimitiveFile::Capsule { radius: *radius, height: *length }), None)
                }
                CollisionGeometry::Mesh { origin, filename, scale } => {
                    let field = format!("{field}.mesh");
                    let (bytes, shown, format) = match meshes {
                        MeshSource::Files { urdf_dir } => {
                            let path = resolve_mesh_path(&field, filename, urdf_dir, &settings.package_dirs)?;
                            let bytes = std::fs::read(&path).map_err(|e| {
                                std::io::Error::new(e.kind(), format!("cannot read {}: {e}", path.display()))
                            })?;
                            let format =
                                MeshFormat::of_path(&path).map_err(|e| Error::invalid(&field, e.to_string()))?;
                            (std::borrow::Cow::Owned(bytes), path.display().to_string(), format)
                        }
                        MeshSource::Memory(map) => {
                            check_mesh_name(&field, filename)?;
                            let bytes = map.get(filename).ok_or_else(|| {
                                Error::invalid(
                                    &field,
                                    format!("mesh `{}` was not sent", sublevel_core::error::clip(filename)),
                                )
                            })?;
                            let format = MeshFormat::of_path(Path::new(filename))
                                .map_err(|e| Error::invalid(&field, e.to_string()))?;
                            (std::borrow::Cow::Borrowed(bytes.as_slice()), filename.clone(), format)
                        }
                    };
                    let (file, job) = read_mesh(&field, &bytes, format, &shown, filename, *scale, &tag)?;
                    if !jobs.iter().any(|j| j.key == job.key) {
                        jobs.push(job);
                    }
                    (origin, None, Some(file))
                }
            };
            geometries.push(GeometryFile {
                link: link.name.clone(),
                index: k,
                origin: PoseFile::of(origin),
                primitive,
                mesh,
                compound: None,
            });
        }
    }
    let (bodies, report) = fit_meshes(jobs, settings, progress)?;
    for g in &mut geometries {
        if let Some(m) = &g.mesh {
            let key = mesh_key(&m.sha256, m.scale, &tag);
            let body = bodies.iter().find(|(k, _)| *k == key).map(|(_, b)| b.to_file());
            g.compound = body;
        }
    }
    let report = RobotFitReport { seconds: start.elapsed().as_secs_f64(), warnings, rigid_pairs, ..report };
    let mut file = RobotFile {
        format: ROBOT_FORMAT.to_owned(),
        name: model.name.clone(),
        urdf,
        allowed_pairs,
        geometries,
        report,
        clearance: Vec::new(),
        integrity: String::new(),
    };
    file.seal()?;
    let robot = FittedRobot::from_file(file)?;
    let Some(clearance) = &settings.clearance else { return Ok(robot) };
    let meshes = robot.file.report.fitted + robot.file.report.cached;
    let tables = cached_tables(&robot, clearance, settings, &|message: &str| {
        progress(&RobotFitProgress { done: meshes, total: meshes, message: message.to_owned() });
    })?;
    let mut robot = robot.with_clearance(tables)?;
    robot.file.report.seconds = start.elapsed().as_secs_f64();
    robot.file.seal()?;
    Ok(robot)
}

/// The robot's clearance tables, read from `cache_dir` when the same robot was fitted before
/// (keyed by the robot's geometry, joints and the table settings), else built and cached.
fn cached_tables(
    robot: &FittedRobot,
    clearance: &ClearanceSettings,
    settings: &RobotFitSettings,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<ClearanceFile>> {
    let mut h = Sha256::new();
    h.update(robot.file.urdf.as_bytes());
    h.update(serde_json::to_string(&robot.file.geometries)?.as_bytes());
    h.update(format!("{:?} {}", clearance.max_loss, clearance.max_cells).as_bytes());
    let path = settings.cache_dir.as_ref().map(|d| d.join(format!("clearance-{}.json", hex(&h.finalize()))));
    if let (Some(path), false) = (&path, settings.refresh_cache) {
        let cached: Option<Vec<ClearanceFile>> =
            std::fs::read_to_string(path).ok().and_then(|t| serde_json::from_str(&t).ok());
        if let Some(tables) = cached {
            progress("clearance tables: cached");
            return Ok(tables);
        }
    }
    let tables = build_clearance_tables(robot, clearance, progress)?;
    if let Some(path) = &path {
        let tmp = path.with_extension("json.tmp");
        // A cache that cannot be written only costs the next fit the build.
        let _ = std::fs::create_dir_all(path.parent().unwrap_or(Path::new(".")))
            .and_then(|()| std::fs::write(&tmp, serde_json::to_string(&tables).unwrap_or_default()))
            .and_then(|()| std::fs::rename(&tmp, path));
    }
    Ok(tables)
}

/// The fit settings that change a mesh's compound body, as text for the cache key.
fn settings_tag(s: &CompoundSettings, leaves: bool) -> String {
    format!(
        "parts={} tol={:?} rel={} weld={:?} degrees={:?} parent={} res={} samples={} max_parts={} vtol={}",
        if leaves { "auto" } else { "1" },
        s.excess_tolerance,
        s.relative_tolerance,
        s.weld_tolerance,
        s.degrees,
        s.parent_degree,
        s.resolution,
        s.excess_samples,
        s.max_parts,
        s.volume_tolerance
    )
}

/// The cache key of a mesh: SHA-256 of its file's hash, its scale and the settings tag.
fn mesh_key(sha256: &str, scale: [Real; 3], tag: &str) -> String {
    let mut h = Sha256::new();
    h.update(sha256.as_bytes());
    h.update(format!("{scale:?}").as_bytes());
    h.update(tag.as_bytes());
    hex(&h.finalize())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Reads a link mesh from its bytes (`shown`: its path or name, for messages): its stored form and
/// its fit job.
fn read_mesh(
    field: &str,
    bytes: &[u8],
    format: MeshFormat,
    shown: &str,
    source: &str,
    scale: [Real; 3],
    tag: &str,
) -> Result<(MeshFile, MeshJob)> {
    let mut mesh = load_triangle_mesh(bytes, format, DEFAULT_MAX_MESH_POINTS)
        .map_err(|e| Error::invalid(field, format!("{shown}: {e}")))?;
    if mesh.triangles.is_empty() {
        return Err(Error::invalid(field, format!("{shown} holds no triangles")));
    }
    if scale.iter().any(|s| !(s.is_finite() && *s != 0.0)) {
        return Err(Error::invalid(format!("{field}.scale"), format!("must be finite and nonzero, got {scale:?}")));
    }
    for v in &mut mesh.vertices {
        *v = Point3::new(v.x * scale[0], v.y * scale[1], v.z * scale[2]);
    }
    // A mirror (an odd number of negative entries, as URDFs give one side of a symmetric robot)
    // turns the triangles inside out: their order is reversed so that they face out again.
    if scale.iter().filter(|s| **s < 0.0).count() % 2 == 1 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
    let sha256 = hex(&Sha256::digest(bytes));
    let key = mesh_key(&sha256, scale, tag);
    let name = Path::new(shown).file_name().map_or_else(|| source.to_owned(), |n| n.to_string_lossy().into_owned());
    let file = MeshFile {
        source: source.to_owned(),
        sha256,
        scale,
        vertices: mesh.vertices.iter().map(|p| [p.x, p.y, p.z]).collect(),
        triangles: mesh.triangles.clone(),
    };
    Ok((file, MeshJob { key, name, mesh }))
}

/// One mesh's outcome: its job index, cache key, and body, whether it came from the cache, and its
/// name with any note of the fit.
type MeshOutcome = (usize, String, Result<(CompoundBody, bool, String)>);

/// Fits (or reads from the cache) every distinct mesh, `threads` at once.
fn fit_meshes(
    jobs: Vec<MeshJob>,
    settings: &RobotFitSettings,
    progress: &(dyn Fn(&RobotFitProgress) + Sync),
) -> Result<(Vec<(String, CompoundBody)>, RobotFitReport)> {
    let total = jobs.len();
    let threads = match settings.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
    .clamp(1, total.max(1));
    let queue = Mutex::new(jobs.into_iter().enumerate().collect::<Vec<_>>());
    let results: Mutex<Vec<MeshOutcome>> = Mutex::new(Vec::new());
    let done = Mutex::new(0usize);
    let started = Instant::now();
    let flag = sublevel_core::cancel::current();
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                sublevel_core::cancel::within(flag.clone(), || loop {
                    if sublevel_core::cancel::is_cancelled() {
                        break;
                    }
                    let Some((i, job)) = queue.lock().ok().and_then(|mut q| q.pop()) else { break };
                    let t = Instant::now();
                    let outcome = fit_one(&job, settings);
                    let message = match &outcome {
                        Ok((body, cached, note)) => format!(
                            "{}: {}, {} leaves, worst leaf excess {:.4} m{}, {:.1} s",
                            job.name,
                            if *cached { "cached" } else { "fitted" },
                            body.leaf_count(),
                            body.max_leaf_excess(),
                            note,
                            t.elapsed().as_secs_f64()
                        ),
                        Err(e) => format!("{}: failed: {e}", job.name),
                    };
                    let n = done
                        .lock()
                        .map(|mut d| {
                            *d += 1;
                            *d
                        })
                        .unwrap_or(0);
                    // The time left, from the mean time per mesh so far over the threads.
                    let elapsed = started.elapsed().as_secs_f64();
                    let left = elapsed / n.max(1) as Real * total.saturating_sub(n) as Real;
                    let message = format!("{message} — {elapsed:.0} s so far, about {left:.0} s of meshes left");
                    progress(&RobotFitProgress { done: n, total, message });
                    if let Ok(mut r) = results.lock() {
                        r.push((i, job.key.clone(), outcome.map(|(b, c, note)| (b, c, format!("{}{note}", job.name)))));
                    }
                });
            });
        }
    });
    sublevel_core::cancel::check()?;
    let mut results = results.into_inner().map_err(|_| Error::Numerical("a mesh fit panicked".into()))?;
    results.sort_by_key(|r| r.0);
    let mut report = RobotFitReport::default();
    let mut bodies = Vec::new();
    for (_, key, outcome) in results {
        let (body, cached, name) = outcome?;
        if cached {
            report.cached += 1;
        } else {
            report.fitted += 1;
        }
        if let Some(k) = name.find(" (fallback:") {
            report.fallbacks.push(format!("{}:{}", &name[..k], &name[k..]));
        }
        let tol = body.report.tolerance.map_or_else(|| "none".to_owned(), |t| format!("{t:.4} m"));
        report.notes.push(format!(
            "{name}: {} leaves, worst leaf excess {:.4} m (tolerance {tol}){}",
            body.leaf_count(),
            body.max_leaf_excess(),
            if body.report.met == Some(false) { ", some leaves above it" } else { "" }
        ));
        bodies.push((key, body));
    }
    if bodies.len() != total {
        return Err(Error::Numerical("a mesh fit did not finish".into()));
    }
    Ok((bodies, report))
}

/// The fits tried for one mesh, in order, until one succeeds (the fallback path; the robot's report
/// names each mesh that needed more than the first in [`RobotFitReport::fallbacks`]).
///
/// One body per mesh (the default): the settings as given (leaf degrees 2, 4, 6 by volume), then
/// degrees 2 and 4 with the default solver settings, then degree 2 alone — the minimum-volume
/// ellipsoid, a well-conditioned SDP that always contains the mesh. With `leaves`: the tree at
/// `--max-parts`, then with at most 16 and 8 leaves, then one body (no tree to certify).
fn fallback_ladder(settings: &RobotFitSettings) -> Vec<(PartCount, CompoundSettings)> {
    let given = settings.compound.clone();
    if settings.leaves {
        let mut ladder = vec![(PartCount::Auto, given.clone())];
        for m in [16, 8] {
            if m < given.max_parts {
                ladder.push((PartCount::Auto, CompoundSettings { max_parts: m, ..given.clone() }));
            }
        }
        ladder.push((PartCount::Fixed(1), given));
        return ladder;
    }
    let plain =
        |degrees: Vec<usize>| CompoundSettings { degrees, fit: CompoundSettings::default().fit, ..given.clone() };
    vec![
        (PartCount::Fixed(1), given.clone()),
        (PartCount::Fixed(1), plain(vec![2, 4])),
        (PartCount::Fixed(1), plain(vec![2])),
    ]
}

/// One mesh: from the cache when there, else fitted (and cached).
fn fit_one(job: &MeshJob, settings: &RobotFitSettings) -> Result<(CompoundBody, bool, String)> {
    let cached = settings.cache_dir.as_ref().map(|d| d.join(format!("{}.json", job.key)));
    if let (Some(path), false) = (&cached, settings.refresh_cache) {
        if let Ok(body) = CompoundBody::load(path) {
            return Ok((body, true, String::new()));
        }
    }
    let mut no_progress = |_: &sublevel_fit::FitProgress| {};
    let mut note = String::new();
    let mut body = None;
    let mut last_error = None;
    for (parts, s) in fallback_ladder(settings) {
        match fit_compound(&job.mesh, Some(&job.name), parts, &s, &mut no_progress) {
            Ok(b) => {
                body = Some(b);
                break;
            }
            Err(e @ Error::Cancelled(_)) => return Err(e),
            Err(e) => {
                note.push_str(&format!(
                    " (fallback: at {parts:?}, degrees {:?}, --max-parts {}: {e}; fitted again with the next rung)",
                    s.degrees, s.max_parts
                ));
                last_error = Some(e);
            }
        }
    }
    let body = match (body, last_error) {
        (Some(b), _) => b,
        (None, Some(e)) => {
            return Err(match e {
                Error::InvalidArgument { field, reason } => {
                    Error::InvalidArgument { field, reason: format!("{}: {reason}", job.name) }
                }
                other => other,
            })
        }
        (None, None) => return Err(Error::Numerical(format!("{}: no fit was tried", job.name))),
    };
    if let Some(path) = &cached {
        let saved = std::fs::create_dir_all(path.parent().unwrap_or(Path::new("."))).and_then(|()| {
            let tmp = path.with_extension("json.tmp");
            std::fs::write(&tmp, serde_json::to_string(&body.to_file()).unwrap_or_default())?;
            std::fs::rename(&tmp, path)
        });
        if let Err(e) = saved {
            note = format!(" (not cached: {e})");
        }
    }
    Ok((body, false, note))
}
