//! Stored bodies, built on first use.
//!
//! Building a [`Body`] from its file is most of the cost of holding it: the minimizer, the
//! radial and support tables, the bounding box and its support bound take ~20 ms for 2d = 8, and
//! a compound body builds every node. Opening a store therefore only parses the records; each
//! [`BodyEntry`] builds its body the first time something needs it, once:
//!
//! ```text
//! Catalog::open     record parsed, facts read (degree, nodes, nonconvex)      no body built
//! first use         BodyEntry::built → OnceLock::get_or_init → Body::from_file / CompoundBody::from_file
//! later uses        OnceLock::get (one atomic load)
//! warm-up           Catalog::warm_up: every body not built yet, on all cores, in the background
//! ```
//!
//! Concurrent first users wait for the one build. A stored body that no longer validates is
//! found when it is built: its record is moved to the store's quarantine (kept, never deleted),
//! the catalog's quarantine count grows, and every use of it answers
//! [`Error::FailedPrecondition`] naming the body.

use super::{lock, read, Catalog};
use crate::store::Store;
use crate::{BodyRecord, Error, MeshRecord, Result};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use sublevel_core::body::{Body, BodyFile};
use sublevel_core::compound::CompoundBody;
use sublevel_core::math::Real;
use sublevel_core::primitive::{Primitive, PrimitiveFile};

/// A built body: what queries read.
#[derive(Clone, Debug)]
pub struct BuiltBody {
    /// The validated body; for a compound body its root node's body (which contains every other
    /// node's body, paper §V), so bounding boxes, spheres and grouping see the whole model. For a
    /// primitive its bounding ellipsoid ([`bounding_body`]; grouping contains that), and for a
    /// halfspace, which no body contains, a unit ball that no query reads (see
    /// [`sublevel_query::dispatch::PosedRef::body`]).
    pub body: Arc<Body>,
    /// The containment tree of a compound body; `None` for a single body, which stays on the
    /// single-body query path.
    pub tree: Option<Arc<CompoundBody>>,
    /// The exact primitive this body stands for; its queries take the primitive path
    /// ([`sublevel_query::dispatch::primitive_pair_distance`]). `None` for a fitted body.
    pub primitive: Option<Primitive>,
}

impl BuiltBody {
    /// A built primitive: the primitive with its bounding ellipsoid (a unit-ball stand-in for a
    /// halfspace).
    ///
    /// # Errors
    /// As [`bounding_body`].
    pub fn of_primitive(primitive: Primitive) -> Result<Self> {
        Self::of_bound(primitive, bounding_body(&primitive)?)
    }

    /// [`BuiltBody::of_primitive`] with the primitive's bounding body already built
    /// ([`bounding_body`]'s answer).
    ///
    /// # Errors
    /// As [`BuiltBody::of_primitive`].
    pub(crate) fn of_bound(primitive: Primitive, bound: Option<Body>) -> Result<Self> {
        let body = match bound {
            Some(b) => b,
            None => sublevel_core::body::ellipsoid([0.0; 3], [1.0; 3])?,
        };
        Ok(Self { body: Arc::new(body), tree: None, primitive: Some(primitive) })
    }
}

/// The degree-2 body that contains a bounded primitive (own frame; `None` for a halfspace): the
/// smallest axis-aligned ellipsoid about the origin holding a box (semi-axes √3·h), a cylinder
/// (√(3/2)·r, √(3/2)·r, √3·h) or a capsule's enclosing cylinder (height + 2r), and the sphere
/// itself. Grouping jobs contain it; broad phases use the primitive's own bounds.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `primitive` when the primitive is smaller than the smallest
/// body scale (1 µm), or so flat that its ellipsoid does not build (it then falls back to the
/// bounding sphere first).
pub fn bounding_body(primitive: &Primitive) -> Result<Option<Body>> {
    const S3: Real = 1.732_050_807_568_877_2;
    const S32: Real = 1.224_744_871_391_589;
    let radii = match *primitive {
        Primitive::Box { half_extents: h } => [S3 * h.x, S3 * h.y, S3 * h.z],
        Primitive::Sphere { radius } => [radius; 3],
        Primitive::Cylinder { radius, half_height } => [S32 * radius, S32 * radius, S3 * half_height],
        Primitive::Capsule { radius, half_height } => [S32 * radius, S32 * radius, S3 * (half_height + radius)],
        Primitive::Halfspace { .. } => return Ok(None),
    };
    let refused = |e: Error| Error::invalid("primitive", format!("its bounding ellipsoid does not build: {e}"));
    let body = sublevel_core::body::ellipsoid([0.0; 3], radii)
        .or_else(|_| sublevel_core::body::ellipsoid([0.0; 3], [primitive.bounding_radius(); 3]))
        .map_err(refused)?;
    let mut body = body;
    body.report.method = "primitive_bound".into();
    body.report.notes =
        vec![format!("the bounding ellipsoid of a {}; the record's `primitive` is exact", primitive.kind())];
    Ok(Some(body))
}

/// A primitive's volume in cubic meters (+∞ for a halfspace).
pub(crate) fn primitive_volume(p: &PrimitiveFile) -> Real {
    use std::f64::consts::PI;
    match *p {
        PrimitiveFile::Box { size } => size.iter().product(),
        PrimitiveFile::Sphere { radius } => 4.0 / 3.0 * PI * radius.powi(3),
        PrimitiveFile::Cylinder { radius, height } => PI * radius * radius * height,
        PrimitiveFile::Capsule { radius, height } => PI * radius * radius * height + 4.0 / 3.0 * PI * radius.powi(3),
        PrimitiveFile::Halfspace { .. } => Real::INFINITY,
    }
}

/// A primitive file's kind (`box`, `sphere`, `cylinder`, `capsule`, `halfspace`).
pub(crate) fn primitive_kind(p: &PrimitiveFile) -> &'static str {
    match p {
        PrimitiveFile::Box { .. } => "box",
        PrimitiveFile::Sphere { .. } => "sphere",
        PrimitiveFile::Cylinder { .. } => "cylinder",
        PrimitiveFile::Capsule { .. } => "capsule",
        PrimitiveFile::Halfspace { .. } => "halfspace",
    }
}

/// What is known of a body without building it: read from its record (or from the body itself
/// when it was stored by this catalog).
#[derive(Clone, Debug, PartialEq)]
pub struct BodyFacts {
    /// Total degree 2d of the (root) body's polynomial.
    pub degree: usize,
    /// The fit method of the (root) body's report.
    pub method: String,
    /// The (root) body's volume from its fit report, in cubic mesh units.
    pub volume: Real,
    /// Whether the body, or any node of its tree, is nonconvex (its queries solve SDP lower
    /// bounds).
    pub nonconvex: bool,
    /// Number of nodes of the containment tree (1 for a single body).
    pub nodes: usize,
    /// Whether it is a compound body (its queries run the tree queries).
    pub compound: bool,
    /// The kind of an exact primitive (`box`, `sphere`, `cylinder`, `capsule`, `halfspace`);
    /// `None` for a fitted body. A primitive has degree 0 (no polynomial), method `primitive` and
    /// its exact volume (+∞ for a halfspace).
    pub primitive: Option<&'static str>,
}

impl BodyFacts {
    fn of_file(root: &BodyFile, nonconvex: bool, nodes: usize, compound: bool) -> Self {
        Self {
            degree: root.degree,
            method: root.report.method.clone(),
            volume: root.report.volume,
            nonconvex,
            nodes,
            compound,
            primitive: None,
        }
    }

    fn of_primitive(p: &PrimitiveFile) -> Self {
        Self {
            degree: 0,
            method: "primitive".into(),
            volume: primitive_volume(p),
            nonconvex: false,
            nodes: 1,
            compound: false,
            primitive: Some(primitive_kind(p)),
        }
    }

    fn of_record(rec: &BodyRecord) -> Self {
        if let Some(p) = &rec.primitive {
            return Self::of_primitive(p);
        }
        match &rec.compound {
            None => Self::of_file(&rec.body, rec.body.report.nonconvex, 1, false),
            Some(file) => {
                let root = file.nodes.get(file.root).map_or(&rec.body, |n| &n.body);
                let nonconvex = root.report.nonconvex || file.nodes.iter().any(|n| n.body.report.nonconvex);
                Self::of_file(root, nonconvex, file.nodes.len(), true)
            }
        }
    }

    fn of_built(b: &BuiltBody) -> Self {
        if let Some(p) = &b.primitive {
            return Self::of_primitive(&p.to_file());
        }
        let nonconvex = b.body.report.nonconvex
            || b.tree.as_ref().is_some_and(|t| t.nodes().iter().any(|n| n.body.report.nonconvex));
        Self {
            degree: b.body.degree(),
            method: b.body.report.method.clone(),
            volume: b.body.report.volume,
            nonconvex,
            nodes: b.tree.as_ref().map_or(1, |t| t.node_count()),
            compound: b.tree.is_some(),
            primitive: None,
        }
    }
}

/// The catalog's account of lazily built bodies, shared with every entry: where a body that
/// fails to build goes (the store's quarantine), how many records the quarantine holds, and how
/// many bodies still wait for their build.
pub(super) struct Builds {
    store: Arc<dyn Store>,
    quarantined: AtomicUsize,
    pending: AtomicUsize,
}

impl Builds {
    pub(super) fn new(store: Arc<dyn Store>) -> Self {
        Self { store, quarantined: AtomicUsize::new(0), pending: AtomicUsize::new(0) }
    }

    /// Counts `n` more records in the quarantine.
    pub(super) fn add_quarantined(&self, n: usize) {
        self.quarantined.fetch_add(n, Ordering::Relaxed);
    }

    pub(super) fn quarantined(&self) -> usize {
        self.quarantined.load(Ordering::Relaxed)
    }

    pub(super) fn pending(&self) -> usize {
        self.pending.load(Ordering::Relaxed)
    }

    /// Moves body `id`'s record to the quarantine; the message every use of the body answers.
    fn quarantine(&self, id: &str, reason: &str) -> String {
        tracing::warn!(body_id = %id, %reason, "quarantining stored body that does not validate");
        match self.store.quarantine("bodies", id, &format!("does not validate: {reason}")) {
            Ok(()) => {
                self.add_quarantined(1);
                format!("body `{id}` does not validate ({reason}); its record was moved to the store's quarantine")
            }
            Err(e) => {
                tracing::error!(body_id = %id, error = %e, "cannot move the body's record to the quarantine");
                format!("body `{id}` does not validate ({reason}); its record stays in the store ({e})")
            }
        }
    }
}

/// A stored body: parsed when the catalog opens, built once on first use (see the module docs)
/// and shared with every query that uses it.
pub struct BodyEntry {
    /// The body's id.
    pub id: String,
    /// Its name.
    pub name: String,
    facts: BodyFacts,
    /// The record until the body is built (taken by the build).
    record: Mutex<Option<BodyRecord>>,
    /// The built body, or the message of a body that does not validate.
    built: OnceLock<std::result::Result<BuiltBody, String>>,
    /// `None` for an entry built when it was created.
    builds: Option<Arc<Builds>>,
    /// The mesh the body was fitted to, kept apart from the record (the build takes the record
    /// and does not need it).
    mesh: Option<Arc<MeshRecord>>,
    /// `mesh` as a robot-check obstacle (its BVH and the body's root), built on first use.
    world_mesh: OnceLock<std::result::Result<Arc<sublevel_robot::WorldMesh>, String>>,
}

impl std::fmt::Debug for BodyEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BodyEntry")
            .field("id", &self.id)
            .field("name", &self.name)
            .field("facts", &self.facts)
            .field("built", &self.built.get().map(|r| r.is_ok()))
            .finish_non_exhaustive()
    }
}

impl BodyEntry {
    /// An entry whose body is already built (one just stored).
    pub(super) fn of_built(id: &str, name: &str, built: BuiltBody) -> Self {
        Self {
            id: id.to_owned(),
            name: name.to_owned(),
            facts: BodyFacts::of_built(&built),
            record: Mutex::new(None),
            built: OnceLock::from(Ok(built)),
            builds: None,
            mesh: None,
            world_mesh: OnceLock::new(),
        }
    }

    /// The entry with `mesh` as the mesh its body was fitted to ([`BodyEntry::mesh`]).
    pub(super) fn with_mesh(mut self, mesh: Option<Arc<MeshRecord>>) -> Self {
        self.mesh = mesh;
        self
    }

    /// An entry of a stored record, built on first use; a body that then fails to validate is
    /// quarantined through `builds`.
    pub(super) fn of_record(id: &str, mut rec: BodyRecord, builds: &Arc<Builds>) -> Self {
        builds.pending.fetch_add(1, Ordering::Relaxed);
        let mesh = rec.mesh.take().map(Arc::new);
        Self {
            id: id.to_owned(),
            name: rec.name.clone(),
            facts: BodyFacts::of_record(&rec),
            record: Mutex::new(Some(rec)),
            built: OnceLock::new(),
            builds: Some(builds.clone()),
            mesh,
            world_mesh: OnceLock::new(),
        }
    }

    /// The triangle mesh the body was fitted to, when it was kept with it
    /// ([`BodyRecord::mesh`]: a mesh of an imported planning scene), in the body's frame
    /// (meters); `None` for other bodies. Needs no build.
    pub fn mesh(&self) -> Option<&Arc<MeshRecord>> {
        self.mesh.as_ref()
    }

    /// The kept mesh ([`BodyEntry::mesh`]) as an obstacle of the robot checks: its triangles,
    /// with the built body's root (which contains them) for the sos bound; built once, on first
    /// use (the BVH of a large mesh takes milliseconds). `None` for a body without a kept mesh.
    ///
    /// # Errors
    /// As [`BodyEntry::built`]; [`Error::FailedPrecondition`] when the mesh does not validate
    /// against the body ([`sublevel_robot::WorldMesh::new`]: a vertex outside the root body).
    pub fn world_mesh(&self) -> Option<Result<Arc<sublevel_robot::WorldMesh>>> {
        let mesh = self.mesh.as_ref()?;
        let built = match self.built() {
            Ok(b) => b,
            Err(e) => return Some(Err(e)),
        };
        let made = self.world_mesh.get_or_init(|| {
            let vertices = mesh.vertices.iter().map(|v| sublevel_core::math::Point3::new(v[0], v[1], v[2])).collect();
            sublevel_robot::WorldMesh::new(vertices, mesh.triangles.clone(), Some((*built.body).clone()))
                .map(Arc::new)
                .map_err(|e| format!("the mesh kept with body `{}` is not a valid obstacle: {e}", self.id))
        });
        Some(made.clone().map_err(Error::FailedPrecondition))
    }

    /// The built body, building it now if this is its first use (concurrent first users wait
    /// for one build; later calls are one atomic load).
    ///
    /// # Errors
    /// [`Error::FailedPrecondition`] naming the body when its stored record does not validate
    /// (the record was then moved to the store's quarantine).
    pub fn built(&self) -> Result<&BuiltBody> {
        self.built.get_or_init(|| self.build()).as_ref().map_err(|m| Error::FailedPrecondition(m.clone()))
    }

    /// Runs the build if it has not run; `Some(valid)` when this call ran it, `None` when
    /// another did (or it ran before).
    fn build_once(&self) -> Option<bool> {
        let mut ran = false;
        let outcome = self.built.get_or_init(|| {
            ran = true;
            self.build()
        });
        ran.then_some(outcome.is_ok())
    }

    /// The built body when it is built and valid; `None` before its build (nothing is built
    /// here) and for a body that does not validate.
    pub fn ready(&self) -> Option<&BuiltBody> {
        self.built.get().and_then(|r| r.as_ref().ok())
    }

    /// Whether the build has run (successfully or not).
    pub fn is_settled(&self) -> bool {
        self.built.get().is_some()
    }

    /// The body (a compound body's root body), built on first use as by [`BodyEntry::built`].
    ///
    /// # Errors
    /// As [`BodyEntry::built`].
    pub fn body(&self) -> Result<&Arc<Body>> {
        Ok(&self.built()?.body)
    }

    /// What is known without building the body (degree, method, volume, nodes, convexity).
    pub fn facts(&self) -> &BodyFacts {
        &self.facts
    }

    /// Number of nodes of the body's containment tree (1 for a single body).
    pub fn node_count(&self) -> usize {
        self.facts.nodes
    }

    /// Builds the body from its record; quarantines it when it does not validate (or its build
    /// panics). Runs once, inside the `OnceLock`'s initialization.
    fn build(&self) -> std::result::Result<BuiltBody, String> {
        let record = lock(&self.record).take();
        if let Some(builds) = &self.builds {
            builds.pending.fetch_sub(1, Ordering::Relaxed);
        }
        let Some(rec) = record else {
            return Err(format!("body `{}` has no record to build from", self.id));
        };
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| build_record(rec)));
        let reason = match outcome {
            Ok(Ok(built)) => return Ok(built),
            Ok(Err(e)) => e.to_string(),
            Err(_) => "its build panicked".to_owned(),
        };
        Err(match &self.builds {
            Some(builds) => builds.quarantine(&self.id, &reason),
            None => format!("body `{}` does not validate ({reason})", self.id),
        })
    }
}

impl Drop for BodyEntry {
    fn drop(&mut self) {
        // A body deleted before its build no longer waits for it.
        if let (Some(builds), None) = (&self.builds, self.built.get()) {
            builds.pending.fetch_sub(1, Ordering::Relaxed);
        }
    }
}

/// Validates and builds a stored record: a single body, a compound body when the record holds a
/// compound file, a primitive when it holds one (see [`BodyRecord`]).
///
/// # Errors
/// The validation errors of [`Body::from_file`] / [`CompoundBody::from_file`], naming the field.
fn build_record(rec: BodyRecord) -> Result<BuiltBody> {
    if let Some(file) = &rec.primitive {
        // The record's `body` is for readers that ignore `primitive`: the bounds are rebuilt.
        return BuiltBody::of_primitive(Primitive::from_file(file)?);
    }
    Ok(match rec.compound {
        None => BuiltBody { body: Arc::new(Body::from_file(rec.body)?), tree: None, primitive: None },
        Some(file) => {
            let tree = CompoundBody::from_file(file)?;
            BuiltBody { body: Arc::new(tree.body(tree.root()).clone()), tree: Some(Arc::new(tree)), primitive: None }
        }
    })
}

/// What one [`Catalog::warm_up`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WarmUp {
    /// Bodies this warm-up built.
    pub built: usize,
    /// Bodies this warm-up found invalid and quarantined.
    pub quarantined: usize,
    /// Wall-clock seconds it took.
    pub seconds: f64,
    /// Whether it stopped early on request (some bodies are then still unbuilt).
    pub stopped: bool,
}

impl Catalog {
    /// Builds every body not built yet, in parallel on
    /// [`std::thread::available_parallelism`] threads, and returns what it did; the server runs
    /// it in the background once it listens. Bodies that do not validate are quarantined (see
    /// [`BodyEntry::built`]). Queries may run meanwhile: a body a query needs first is built by
    /// that query, and neither builds it twice.
    pub fn warm_up(&self) -> WarmUp {
        self.warm_up_until(&AtomicBool::new(false))
    }

    /// [`Catalog::warm_up`] that stops before the next body once `stop` is set (e.g. when the
    /// server shuts down).
    pub fn warm_up_until(&self, stop: &AtomicBool) -> WarmUp {
        let start = std::time::Instant::now();
        let todo: Vec<Arc<BodyEntry>> = read(&self.bodies).values().filter(|e| !e.is_settled()).cloned().collect();
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(todo.len()).max(1);
        let next = AtomicUsize::new(0);
        let (built, quarantined) = (AtomicUsize::new(0), AtomicUsize::new(0));
        std::thread::scope(|scope| {
            for _ in 0..threads {
                scope.spawn(|| {
                    while !stop.load(Ordering::Relaxed) {
                        let Some(entry) = todo.get(next.fetch_add(1, Ordering::Relaxed)) else { break };
                        // `None`: built meanwhile by a query.
                        match entry.build_once() {
                            Some(true) => _ = built.fetch_add(1, Ordering::Relaxed),
                            Some(false) => _ = quarantined.fetch_add(1, Ordering::Relaxed),
                            None => {}
                        }
                    }
                });
            }
        });
        WarmUp {
            built: built.into_inner(),
            quarantined: quarantined.into_inner(),
            seconds: start.elapsed().as_secs_f64(),
            stopped: stop.load(Ordering::Relaxed),
        }
    }

    /// `(built, total)`: how many bodies of the catalog are built (valid and ready for queries)
    /// and how many it holds.
    pub fn bodies_built(&self) -> (usize, usize) {
        let bodies = read(&self.bodies);
        (bodies.values().filter(|e| e.ready().is_some()).count(), bodies.len())
    }

    /// Number of bodies whose build has not run yet (O(1)); the service answers queries off its
    /// async workers while it is not 0, so that a first-use build never holds one up.
    pub fn bodies_pending(&self) -> usize {
        self.builds.pending()
    }
}
